// C++ backend of the blob mobility products (pybind11 module mobility._mobility_cpp).
//
// The pair loops (mobility_kernels.inc) are compiled once per vector path (simd_targets.h) and the path chosen
// at import (simd_dispatch.h: the widest this CPU runs, or RMB_SIMD) runs them; the formulas are those of
// blob_pair_kernels.h.  This file checks the arrays, scales and regularises the blobs (blob_arrays.h), calls
// the chosen path's loop with the GIL released, and applies the damping and the 1/(8 pi eta a^k) factor.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <chrono>
#include <cmath>
#include <cstring>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

#ifdef _OPENMP
#include <omp.h>
#endif

#include "blob_arrays.h"
#include "blob_pair_kernels.h"
#include "dense_matrices.h"
#include "openmp_threads.h"

#define RMB_SIMD_KERNELS "mobility_kernels.inc"
#include "simd_targets.h"

using namespace rmb_blobs;  // Array, Blobs and the helpers shared with dense_matrices.cpp

namespace {

Array flat_result(const std::vector<double> &ux, const std::vector<double> &uy, const std::vector<double> &uz,
                  const std::vector<double> &damping, double factor) {
  const std::size_t n = ux.size();
  Array out(static_cast<py::ssize_t>(3 * n));
  double *o = out.mutable_data();
  for (std::size_t i = 0; i < n; ++i) {
    const double f = factor * damping[i];
    o[3 * i] = ux[i] * f;
    o[3 * i + 1] = uy[i] * f;
    o[3 * i + 2] = uz[i] * f;
  }
  return out;
}

// The roller couplings and the free surface of blobs with themselves, with or without periodic images.
template <int Kind, bool Wall>
void one_sided_sum_any_box(bool periodic, const Blobs &b, const std::vector<double> &L, std::vector<double> &ux,
                           std::vector<double> &uy, std::vector<double> &uz) {
  if (periodic)
    RMB_SIMD_DISPATCH(one_sided_sum<Kind, Wall, true>(b, b, L, ux, uy, uz));
  else
    RMB_SIMD_DISPATCH(one_sided_sum<Kind, Wall, false>(b, b, L, ux, uy, uz));
}

template <bool Wall, bool Periodic, class Real>
void trans_times_force_any_path(const Blobs &b, const std::vector<double> &L, std::vector<double> &ux,
                                std::vector<double> &uy, std::vector<double> &uz) {
  RMB_SIMD_DISPATCH(trans_times_force_symmetric<Wall, Periodic, Real>(b, L, ux, uy, uz));
}

template <bool Wall>
Array blob_product(const std::string &kind, const Array &r, const Array &vector, double eta, double a,
                   const Array &periodic_length, const std::string &precision) {
  if (precision != "double" && precision != "single")
    throw std::invalid_argument("precision must be 'double' or 'single', got '" + precision + "'");
  const bool single = precision == "single";
  if (single && kind != "trans_times_force")
    throw std::invalid_argument("single precision is available for trans_times_force only");
  if (!(a > 0.0) || !(eta > 0.0)) throw std::invalid_argument("blob radius and viscosity must be positive");
  const std::size_t n = count_rows(r, "r_vectors");
  Blobs b = make_blobs(r, &vector, std::vector<double>(n, a), a, Wall, "r_vectors");
  const std::vector<double> L = periodic_lengths(periodic_length, a, Wall);
  const bool periodic = L[0] > 0.0 || L[1] > 0.0 || L[2] > 0.0;
  std::vector<double> ux, uy, uz;
  double power = 1.0;
  {
    py::gil_scoped_release release;
    if (kind == "trans_times_force") {
      if (single)
        periodic ? trans_times_force_any_path<Wall, true, float>(b, L, ux, uy, uz)
                 : trans_times_force_any_path<Wall, false, float>(b, L, ux, uy, uz);
      else
        periodic ? trans_times_force_any_path<Wall, true, double>(b, L, ux, uy, uz)
                 : trans_times_force_any_path<Wall, false, double>(b, L, ux, uy, uz);
    } else if (kind == "trans_times_torque") {
      power = 2.0;
      one_sided_sum_any_box<rmb_k_scalar::kTransTimesTorque, Wall>(periodic, b, L, ux, uy, uz);
    } else if (kind == "rot_times_force") {
      power = 2.0;
      one_sided_sum_any_box<rmb_k_scalar::kRotTimesForce, Wall>(periodic, b, L, ux, uy, uz);
    } else if (kind == "rot_times_torque") {
      power = 3.0;
      one_sided_sum_any_box<rmb_k_scalar::kRotTimesTorque, Wall>(periodic, b, L, ux, uy, uz);
    } else {
      throw std::invalid_argument("unknown product " + kind);
    }
  }
  return flat_result(ux, uy, uz, b.damping, 1.0 / (8.0 * M_PI * eta * std::pow(a, power)));
}

py::tuple product_two(const Array &r, const Array &v1, const Array &v2, double eta, double a, bool wall) {
  if (!(a > 0.0) || !(eta > 0.0)) throw std::invalid_argument("blob radius and viscosity must be positive");
  const std::size_t n = count_rows(r, "r_vectors");
  Blobs b = make_blobs(r, &v1, std::vector<double>(n, a), a, wall, "r_vectors");
  Blobs c = make_blobs(r, &v2, std::vector<double>(n, a), a, wall, "r_vectors");
  std::vector<double> out;
  {
    py::gil_scoped_release release;
    if (wall)
      RMB_SIMD_DISPATCH(trans_times_force_symmetric_two<true>(b, c, out));
    else
      RMB_SIMD_DISPATCH(trans_times_force_symmetric_two<false>(b, c, out));
  }
  const double factor = 1.0 / (8.0 * M_PI * eta * a);
  std::vector<double> ux(out.begin(), out.begin() + n), uy(out.begin() + n, out.begin() + 2 * n),
      uz(out.begin() + 2 * n, out.begin() + 3 * n), wx(out.begin() + 3 * n, out.begin() + 4 * n),
      wy(out.begin() + 4 * n, out.begin() + 5 * n), wz(out.begin() + 5 * n, out.end());
  return py::make_tuple(flat_result(ux, uy, uz, b.damping, factor), flat_result(wx, wy, wz, c.damping, factor));
}

// (U, W) = M [F; T] (3N,) each, blobs of radius a, in one pass over the pairs (grand_product_symmetric): U in
// units of 1/(8 pi eta a) and W of 1/(8 pi eta a^2) after the torques are divided by a.
py::tuple grand_product(const Array &r, const Array &forces, const Array &torques, double eta, double a,
                        const Array &periodic_length, bool wall) {
  if (!(a > 0.0) || !(eta > 0.0)) throw std::invalid_argument("blob radius and viscosity must be positive");
  const std::size_t n = count_rows(r, "r_vectors");
  const Blobs f = make_blobs(r, &forces, std::vector<double>(n, a), a, wall, "r_vectors");
  Blobs g = make_blobs(r, &torques, std::vector<double>(n, a), a, wall, "r_vectors");
  for (std::size_t i = 0; i < n; ++i) g.vx[i] /= a, g.vy[i] /= a, g.vz[i] /= a;
  const std::vector<double> L = periodic_lengths(periodic_length, a, wall);
  const bool periodic = L[0] > 0.0 || L[1] > 0.0 || L[2] > 0.0;
  std::vector<double> out;
  {
    py::gil_scoped_release release;
    if (wall && periodic)
      RMB_SIMD_DISPATCH(grand_product_symmetric<true, true>(f, g, L, out));
    else if (wall)
      RMB_SIMD_DISPATCH(grand_product_symmetric<true, false>(f, g, L, out));
    else if (periodic)
      RMB_SIMD_DISPATCH(grand_product_symmetric<false, true>(f, g, L, out));
    else
      RMB_SIMD_DISPATCH(grand_product_symmetric<false, false>(f, g, L, out));
  }
  std::vector<double> ux(out.begin(), out.begin() + n), uy(out.begin() + n, out.begin() + 2 * n),
      uz(out.begin() + 2 * n, out.begin() + 3 * n), wx(out.begin() + 3 * n, out.begin() + 4 * n),
      wy(out.begin() + 4 * n, out.begin() + 5 * n), wz(out.begin() + 5 * n, out.end());
  const double factor = 1.0 / (8.0 * M_PI * eta * a);
  return py::make_tuple(flat_result(ux, uy, uz, f.damping, factor), flat_result(wx, wy, wz, f.damping, factor / a));
}

Array product(const std::string &kind, const Array &r, const Array &vector, double eta, double a,
              const Array &periodic_length, bool wall, const std::string &precision) {
  return wall ? blob_product<true>(kind, r, vector, eta, a, periodic_length, precision)
              : blob_product<false>(kind, r, vector, eta, a, periodic_length, precision);
}


template <int D>
void source_target_any_box(bool periodic, const Blobs &t, const Blobs &s, const std::vector<double> &L,
                           std::vector<double> &ux, std::vector<double> &uy, std::vector<double> &uz) {
  if (periodic)
    RMB_SIMD_DISPATCH(source_target_sum<D, true>(t, s, L, ux, uy, uz));
  else
    RMB_SIMD_DISPATCH(source_target_sum<D, false>(t, s, L, ux, uy, uz));
}

// M f (3N,) with per-blob radii (N,), wall or free space (the published radii_numba products).
Array radii_product(const Array &r, const Array &vector, const Array &radius, double eta, const Array &periodic_length,
                    bool wall) {
  if (!(eta > 0.0)) throw std::invalid_argument("viscosity must be positive");
  const std::size_t n = count_rows(r, "r_vectors");
  const Blobs b = make_blobs(r, &vector, radii_vector(radius, n, "radius"), 1.0, wall, "r_vectors");
  const std::vector<double> L = periodic_lengths(periodic_length, 1.0, wall);
  const bool periodic = L[0] > 0.0 || L[1] > 0.0 || L[2] > 0.0;
  std::vector<double> ux, uy, uz;
  {
    py::gil_scoped_release release;
    if (wall && periodic)
      RMB_SIMD_DISPATCH(radii_symmetric_sum<true, true>(b, L, ux, uy, uz));
    else if (wall)
      RMB_SIMD_DISPATCH(radii_symmetric_sum<true, false>(b, L, ux, uy, uz));
    else if (periodic)
      RMB_SIMD_DISPATCH(radii_symmetric_sum<false, true>(b, L, ux, uy, uz));
    else
      RMB_SIMD_DISPATCH(radii_symmetric_sum<false, false>(b, L, ux, uy, uz));
  }
  return flat_result(ux, uy, uz, b.damping, 1.0 / (8.0 * M_PI * eta));
}


Array source_target_domain(const Array &source, const Array &target, const Array &force, const Array &radius_source,
                           const Array &radius_target, double eta, const Array &periodic_length,
                           const std::string &domain) {
  if (!(eta > 0.0)) throw std::invalid_argument("viscosity must be positive");
  const int d = domain_code(domain);
  const bool wall = d == kWall;  // the wall regularisation of blobs below their radius
  const std::size_t ns = count_rows(source, "source positions"), nt = count_rows(target, "target positions");
  const Blobs s = make_blobs(source, &force, radii_vector(radius_source, ns, "radius_source"), 1.0, wall, "source");
  const Blobs t = make_blobs(target, nullptr, radii_vector(radius_target, nt, "radius_target"), 1.0, wall, "target");
  const std::vector<double> L = periodic_lengths(periodic_length, 1.0, d != kNoWall);
  const bool periodic = L[0] > 0.0 || L[1] > 0.0 || L[2] > 0.0;
  std::vector<double> ux, uy, uz;
  {
    py::gil_scoped_release release;
    if (d == kWall)
      source_target_any_box<kWall>(periodic, t, s, L, ux, uy, uz);
    else if (d == kNoWall)
      source_target_any_box<kNoWall>(periodic, t, s, L, ux, uy, uz);
    else
      source_target_any_box<kFreeSurface>(periodic, t, s, L, ux, uy, uz);
  }
  return flat_result(ux, uy, uz, t.damping, 1.0 / (8.0 * M_PI * eta));
}

Array source_target(const Array &source, const Array &target, const Array &force, const Array &radius_source,
                    const Array &radius_target, double eta, const Array &periodic_length, bool wall) {
  return source_target_domain(source, target, force, radius_source, radius_target, eta, periodic_length,
                              wall ? "single_wall" : "no_wall");
}

// M f of blobs of radius a above a free-slip surface at z = 0 (free_surface_pair).
Array free_surface_product(const Array &r, const Array &vector, double eta, double a, const Array &periodic_length) {
  if (!(a > 0.0) || !(eta > 0.0)) throw std::invalid_argument("blob radius and viscosity must be positive");
  const std::size_t n = count_rows(r, "r_vectors");
  const Blobs b = make_blobs(r, &vector, std::vector<double>(n, a), a, false, "r_vectors");
  const std::vector<double> L = periodic_lengths(periodic_length, a, true);
  const bool periodic = L[0] > 0.0 || L[1] > 0.0;
  std::vector<double> ux, uy, uz;
  {
    py::gil_scoped_release release;
    one_sided_sum_any_box<rmb_k_scalar::kFreeSurface, false>(periodic, b, L, ux, uy, uz);
  }
  return flat_result(ux, uy, uz, b.damping, 1.0 / (8.0 * M_PI * eta * a));
}

// 1/sqrt(x) and minimum_image(x, L) of the vector math of the chosen path (tests/test_simd.py).
py::tuple simd_math_check(const Array &x, double L) {
  Array rsqrt(x.size()), image(x.size());
  const std::size_t n = static_cast<std::size_t>(x.size());
  const double *xp = x.data();
  double *rp = rsqrt.mutable_data(), *ip = image.mutable_data();
  RMB_SIMD_DISPATCH(math_check(xp, n, L, rp, ip));
  return py::make_tuple(rsqrt, image);
}

// Floating-point operations per second of an FMA loop on the chosen path (benchmarks/roofline.py).
double fma_peak(int threads, double seconds) {
  if (threads < 1) throw std::invalid_argument("threads must be at least 1");
  double rate = 0.0;
  {
    py::gil_scoped_release release;
    RMB_SIMD_DISPATCH(fma_peak(threads, seconds, rate));
  }
  return rate;
}

py::list simd_paths() {
  py::list names;
  for (int path : rmb_simd::usable_paths()) names.append(rmb_simd::path_name(path));
  return names;
}

}  // namespace
PYBIND11_MODULE(_mobility_cpp, m) {
  m.doc() = "C++ (OpenMP) blob mobility products; formulas in blob_pair_kernels.h";
  try {
    rmb_simd::chosen();  // RMB_SIMD naming a path that cannot run here stops the import with its one line
  } catch (const std::invalid_argument &err) {
    throw py::import_error(err.what());
  }
  m.def("simd_path", []() { return std::string(rmb_simd::path_name(rmb_simd::chosen())); },
        "The vector path the kernels run (scalar, avx2, avx512, neon or sve), chosen at import (RMB_SIMD forces one).");
  m.def("fma_peak", &fma_peak, py::arg("threads"), py::arg("seconds") = 0.2,
        "Double-precision operations per second of chains of fused multiply-adds on the chosen path's vectors, "
        "on `threads` threads (the peak of the roofline in benchmarks/roofline.py).");
  m.def("simd_paths", &simd_paths, "The vector paths this build holds and this CPU runs, best first.");
  m.def("simd_math_check", &simd_math_check, py::arg("x"), py::arg("periodic_length"),
        "(1/sqrt(x), minimum_image(x, L)) computed by the chosen path's vector math (for the tests).");
  m.def("product", &product, py::arg("kind"), py::arg("r_vectors"), py::arg("vector"), py::arg("eta"), py::arg("a"),
        py::arg("periodic_length"), py::arg("wall"), py::arg("precision") = "double",
        "Blob product of `kind` (trans_times_force, trans_times_torque, rot_times_force, rot_times_torque); "
        "r_vectors (N, 3), vector (3N,), returns (3N,). precision: double, or single (trans_times_force only; "
        "pair formulas in float, sums in double).");
  m.def("source_target", &source_target, py::arg("source"), py::arg("target"), py::arg("force"),
        py::arg("radius_source"), py::arg("radius_target"), py::arg("eta"), py::arg("periodic_length"),
        py::arg("wall"), "Velocity (3Nt,) at targets from forces on sources of given radii.");
  m.def("source_target_domain", &source_target_domain, py::arg("source"), py::arg("target"), py::arg("force"),
        py::arg("radius_source"), py::arg("radius_target"), py::arg("eta"), py::arg("periodic_length"),
        py::arg("domain"), "Velocity (3Nt,) at targets from forces on sources of given radii; domain single_wall, "
        "no_wall or free_surface.");
  m.def("radii_product", &radii_product, py::arg("r_vectors"), py::arg("vector"), py::arg("radius"), py::arg("eta"),
        py::arg("periodic_length"), py::arg("wall"),
        "M f (3N,) of blobs of radii (N,), each pair once (symmetric mobility); wall or free space.");
  m.def("free_surface_product", &free_surface_product, py::arg("r_vectors"), py::arg("vector"), py::arg("eta"),
        py::arg("a"), py::arg("periodic_length"), "M f (3N,) of blobs of radius a above a free-slip surface z = 0.");
  m.def("product_two", &product_two, py::arg("r_vectors"), py::arg("v1"), py::arg("v2"), py::arg("eta"),
        py::arg("a"), py::arg("wall"),
        "trans_times_force of two vectors (3N,) each in one pass over the pairs (no periodic images): (M v1, M v2).");
  m.def("grand_product", &grand_product, py::arg("r_vectors"), py::arg("forces"), py::arg("torques"), py::arg("eta"),
        py::arg("a"), py::arg("periodic_length"), py::arg("wall"),
        "(U, W) = grand mobility times [forces; torques] (3N,) each, blobs of one radius a, wall or free space, "
        "periodic images as product takes them: all four couplings in one pass over the pairs.");
  register_dense_matrices(m);
  m.def("max_threads", &rmb::max_threads, "Number of OpenMP threads the kernels use.");
}
