// Rigid-body kinematics of many bodies (pybind11 module body._rigid_cpp).
//
// K maps body velocities U_k = [v_k; w_k] to blob velocities v_k + w_k x (r_i - x_k);
// K^T sums blob forces f_i into [sum f_i; sum (r_i - x_k) x f_i] per body (body/body.py
// has the NumPy versions of the same formulas, used when this module is not built).
// Inside GMRES these run once per iteration on O(N) numbers; the NumPy versions spend
// most of their time in array temporaries, these in one pass over the blobs.  No OpenMP:
// the work per call (a few microseconds for 10^4 blobs) is below a parallel region's cost.
// Arrays: r (N, 3), locations (Nb, 3), blob_body_index (N,) int64 (body of each blob),
// body velocities (Nb, 6), blob forces (N, 3); all C-contiguous doubles.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cstdint>
#include <stdexcept>
#include <string>

namespace py = pybind11;
using Array = py::array_t<double, py::array::c_style | py::array::forcecast>;
using Index = py::array_t<std::int64_t, py::array::c_style | py::array::forcecast>;

namespace {

struct Blobs {
  long n, nb;
  const double *r, *x;
  const std::int64_t *body;
};

Blobs check_blobs(const Array &r_vectors, const Array &locations, const Index &blob_body_index) {
  if (r_vectors.size() % 3 != 0) throw std::invalid_argument("r_vectors must have shape (N, 3)");
  if (locations.size() % 3 != 0) throw std::invalid_argument("locations must have shape (Nb, 3)");
  Blobs b{static_cast<long>(r_vectors.size() / 3), static_cast<long>(locations.size() / 3), r_vectors.data(),
          locations.data(), blob_body_index.data()};
  if (blob_body_index.size() != b.n)
    throw std::invalid_argument("blob_body_index must hold one body index per blob (" + std::to_string(b.n) + ")");
  for (long i = 0; i < b.n; ++i)
    if (b.body[i] < 0 || b.body[i] >= b.nb)
      throw std::invalid_argument("blob_body_index[" + std::to_string(i) + "] is not a body index");
  return b;
}

// out (3N) = K U
void apply_K(const Blobs &b, const double *U, double *out) {
  for (long i = 0; i < b.n; ++i) {
    const double *u = U + 6 * b.body[i], *x = b.x + 3 * b.body[i], *r = b.r + 3 * i;
    const double d0 = r[0] - x[0], d1 = r[1] - x[1], d2 = r[2] - x[2];
    out[3 * i] = u[0] + (u[4] * d2 - u[5] * d1);
    out[3 * i + 1] = u[1] + (u[5] * d0 - u[3] * d2);
    out[3 * i + 2] = u[2] + (u[3] * d1 - u[4] * d0);
  }
}

// out (6 Nb) = scale * K^T f (out zeroed here)
void apply_KT(const Blobs &b, const double *f, double scale, double *out) {
  for (long k = 0; k < 6 * b.nb; ++k) out[k] = 0.0;
  for (long i = 0; i < b.n; ++i) {
    double *o = out + 6 * b.body[i];
    const double *x = b.x + 3 * b.body[i], *r = b.r + 3 * i, *g = f + 3 * i;
    const double d0 = r[0] - x[0], d1 = r[1] - x[1], d2 = r[2] - x[2];
    o[0] += g[0];
    o[1] += g[1];
    o[2] += g[2];
    o[3] += d1 * g[2] - d2 * g[1];
    o[4] += d2 * g[0] - d0 * g[2];
    o[5] += d0 * g[1] - d1 * g[0];
  }
  if (scale != 1.0)
    for (long k = 0; k < 6 * b.nb; ++k) out[k] *= scale;
}

Array K_dot(const Array &r_vectors, const Array &locations, const Index &blob_body_index, const Array &velocities) {
  const Blobs b = check_blobs(r_vectors, locations, blob_body_index);
  if (velocities.size() != 6 * b.nb) throw std::invalid_argument("body_velocities must have shape (Nb, 6)");
  Array out({static_cast<py::ssize_t>(b.n), static_cast<py::ssize_t>(3)});
  apply_K(b, velocities.data(), out.mutable_data());
  return out;
}

Array KT_dot(const Array &r_vectors, const Array &locations, const Index &blob_body_index, const Array &forces) {
  const Blobs b = check_blobs(r_vectors, locations, blob_body_index);
  if (forces.size() != 3 * b.n) throw std::invalid_argument("blob_forces must have shape (N, 3)");
  Array out({static_cast<py::ssize_t>(b.nb), static_cast<py::ssize_t>(6)});
  apply_KT(b, forces.data(), 1.0, out.mutable_data());
  return out;
}

// The rigid part of the saddle-point product: [M lambda - K U; -K^T lambda] (3N + 6Nb,),
// given M lambda (3N,), lambda (3N,) and U (6Nb,).
Array saddle_point_product(const Array &r_vectors, const Array &locations, const Index &blob_body_index,
                           const Array &M_lambda, const Array &lambda, const Array &velocities) {
  const Blobs b = check_blobs(r_vectors, locations, blob_body_index);
  if (M_lambda.size() != 3 * b.n || lambda.size() != 3 * b.n)
    throw std::invalid_argument("M_lambda and lambda must have 3N entries");
  if (velocities.size() != 6 * b.nb) throw std::invalid_argument("body_velocities must have 6 Nb entries");
  Array out(static_cast<py::ssize_t>(3 * b.n + 6 * b.nb));
  double *o = out.mutable_data();
  apply_K(b, velocities.data(), o);
  const double *m = M_lambda.data();
  for (long k = 0; k < 3 * b.n; ++k) o[k] = m[k] - o[k];
  apply_KT(b, lambda.data(), -1.0, o + 3 * b.n);
  return out;
}

}  // namespace

PYBIND11_MODULE(_rigid_cpp, m) {
  m.doc() = "K and K^T of many rigid bodies (body/cpp/rigid_module.cpp)";
  m.def("K_dot", &K_dot, py::arg("r_vectors"), py::arg("locations"), py::arg("blob_body_index"),
        py::arg("body_velocities"), "K U: blob velocities (N, 3) of body velocities (Nb, 6)");
  m.def("KT_dot", &KT_dot, py::arg("r_vectors"), py::arg("locations"), py::arg("blob_body_index"),
        py::arg("blob_forces"), "K^T f: body forces and torques (Nb, 6) of blob forces (N, 3)");
  m.def("saddle_point_product", &saddle_point_product, py::arg("r_vectors"), py::arg("locations"),
        py::arg("blob_body_index"), py::arg("M_lambda"), py::arg("lambda_blobs"), py::arg("body_velocities"),
        "[M lambda - K U; -K^T lambda] (3N + 6Nb,) from M lambda, lambda and U");
}
