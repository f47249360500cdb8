// C++ blob-blob soft repulsion (pybind11 module multi_bodies._forces_cpp).
//
// Force on blob i from blob j, with r = r_j - r_i (minimum image on the
// periodic axes, SPEC section 8; the image of r_i - r_j is minus that of
// r_j - r_i, so each pair is visited once) and d = 2a:
//   f_i = -(eps/b) exp(-(|r| - d)/b) r/|r|   for |r| > d,
//   f_i = -(eps/b) r/|r|                     otherwise,
// |r| floored by machine epsilon.  OpenMP splits the rows i of the pair
// triangle; every thread has its own force accumulator.  Edit blob_pair_force below to
// change the law of the C++ backend (then rebuild with pip install -e .).
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cfloat>
#include <cmath>
#include <stdexcept>
#include <vector>

#ifdef _OPENMP
#include <omp.h>
#endif

namespace py = pybind11;
using Array = py::array_t<double, py::array::c_style | py::array::forcecast>;

namespace {

// Minimum image of one displacement component for box length L (L <= 0: not periodic);
// r - trunc(r/L + 0.5 sign(r)) L, i.e. rounding half away from zero.
inline double minimum_image(double r, double L) {
  if (L <= 0.0) return r;
  const double sign = (r > 0.0) - (r < 0.0);
  return r - std::trunc(r / L + 0.5 * sign) * L;
}

// Magnitude factor m such that the force on i is -m * r (r from i to j).
inline double blob_pair_force(double distance, double eps_over_b, double inv_b, double contact) {
  const double overlap_free = distance > contact ? distance - contact : 0.0;
  return eps_over_b * std::exp(-overlap_free * inv_b) / distance;
}

int max_threads_available() {
#ifdef _OPENMP
  return omp_get_max_threads();
#else
  return 1;
#endif
}

int this_thread() {
#ifdef _OPENMP
  return omp_get_thread_num();
#else
  return 0;
#endif
}

Array blob_blob_forces(const Array &r_vectors, const Array &periodic_length, double repulsion_strength,
                       double debye_length, double blob_radius) {
  if (!(r_vectors.ndim() == 2 && r_vectors.shape(1) == 3) && !(r_vectors.ndim() == 1 && r_vectors.shape(0) % 3 == 0))
    throw std::invalid_argument("r_vectors must have shape (N, 3)");
  if (periodic_length.size() != 3) throw std::invalid_argument("periodic_length must hold 3 numbers");
  if (debye_length <= 0.0) throw std::invalid_argument("debye_length must be positive");
  const long n = static_cast<long>(r_vectors.size() / 3);
  std::vector<double> x(n), y(n), z(n);
  const double *rp = r_vectors.data();
  for (long i = 0; i < n; ++i) x[i] = rp[3 * i], y[i] = rp[3 * i + 1], z[i] = rp[3 * i + 2];
  const double Lx = periodic_length.data()[0], Ly = periodic_length.data()[1], Lz = periodic_length.data()[2];
  const double eps_over_b = repulsion_strength / debye_length, inv_b = 1.0 / debye_length;
  const double contact = 2.0 * blob_radius;
  Array result({static_cast<py::ssize_t>(n), static_cast<py::ssize_t>(3)});
  double *out = result.mutable_data();
  {
    py::gil_scoped_release release;
    const int threads = max_threads_available();
    // Each unordered pair is visited once; thread t adds into its own accumulator, summed at the end.
    std::vector<double> accumulators(static_cast<std::size_t>(threads) * 3 * n, 0.0);
    // one thread for small systems: a parallel region costs more than ~1e5 pairs
    const bool use_threads = static_cast<double>(n) * n > 2e5;
#pragma omp parallel for schedule(dynamic, 16) if (use_threads)
    for (long i = 0; i < n; ++i) {
      double *acc = accumulators.data() + static_cast<std::size_t>(this_thread()) * 3 * n;
      double fx = 0.0, fy = 0.0, fz = 0.0;
      const double xi = x[i], yi = y[i], zi = z[i];
      for (long j = i + 1; j < n; ++j) {
        const double rx = minimum_image(x[j] - xi, Lx);
        const double ry = minimum_image(y[j] - yi, Ly);
        const double rz = minimum_image(z[j] - zi, Lz);
        double distance = std::sqrt(rx * rx + ry * ry + rz * rz);
        if (distance < DBL_EPSILON) distance = DBL_EPSILON;
        const double m = blob_pair_force(distance, eps_over_b, inv_b, contact);
        fx -= m * rx, fy -= m * ry, fz -= m * rz;
        acc[3 * j] += m * rx, acc[3 * j + 1] += m * ry, acc[3 * j + 2] += m * rz;
      }
      acc[3 * i] += fx, acc[3 * i + 1] += fy, acc[3 * i + 2] += fz;
    }
#pragma omp parallel for schedule(static) if (use_threads)
    for (long k = 0; k < 3 * n; ++k) {
      double sum = 0.0;
      for (int t = 0; t < threads; ++t) sum += accumulators[static_cast<std::size_t>(t) * 3 * n + k];
      out[k] = sum;
    }
  }
  return result;
}

int max_threads() {
#ifdef _OPENMP
  return omp_get_max_threads();
#else
  return 1;
#endif
}

}  // namespace

PYBIND11_MODULE(_forces_cpp, m) {
  m.doc() = "C++ (OpenMP) blob-blob soft repulsion of all pairs";
  m.def("blob_blob_forces", &blob_blob_forces, py::arg("r_vectors"), py::arg("periodic_length"),
        py::arg("repulsion_strength"), py::arg("debye_length"), py::arg("blob_radius"),
        "Forces (N, 3) of the default soft repulsion between all blob pairs; r_vectors (N, 3).");
  m.def("max_threads", &max_threads, "Number of OpenMP threads the kernel uses.");
}
