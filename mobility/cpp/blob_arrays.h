// Blob arrays and helpers shared by the translation units of mobility._mobility_cpp (the products in
// mobility_module.cpp, the dense matrices in dense_matrices.cpp).
#pragma once

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

#include "blob_pair_kernels.h"

namespace rmb_blobs {

namespace py = pybind11;
using Array = py::array_t<double, py::array::c_style | py::array::forcecast>;


// Below this many pair evaluations a product runs on one thread: starting a
// parallel region costs more than it saves, and on a busy machine a team of
// threads waiting for a descheduled member costs milliseconds.
constexpr double kMinPairsForThreads = 1e5;

inline bool worth_threads(std::size_t targets, std::size_t sources) {
  return static_cast<double>(targets) * static_cast<double>(sources) > kMinPairsForThreads;
}


// Blobs as separate coordinate arrays, in units of `scale`, with the wall
// regularisation applied when asked: z_eff = max(z, radius), vector damped by
// min(z / radius, 1).
struct Blobs {
  std::size_t n = 0;
  std::vector<double> x, y, z, vx, vy, vz, damping, radius;
};

inline std::size_t count_rows(const Array &r, const char *name) {
  if (r.ndim() == 2 && r.shape(1) == 3) return static_cast<std::size_t>(r.shape(0));
  if (r.ndim() == 1 && r.shape(0) % 3 == 0) return static_cast<std::size_t>(r.shape(0) / 3);
  throw std::invalid_argument(std::string(name) + " must have shape (N, 3) or (3N,)");
}

inline Blobs make_blobs(const Array &r, const Array *vector, const std::vector<double> &radius, double scale,
                        bool wall, const char *name) {
  Blobs b;
  b.n = count_rows(r, name);
  if (vector != nullptr && static_cast<std::size_t>(vector->size()) != 3 * b.n)
    throw std::invalid_argument("vector size must be 3 times the number of blobs");
  const double *rp = r.data();
  const double *vp = vector ? vector->data() : nullptr;
  b.x.resize(b.n), b.y.resize(b.n), b.z.resize(b.n), b.damping.assign(b.n, 1.0), b.radius = radius;
  if (vp) b.vx.resize(b.n), b.vy.resize(b.n), b.vz.resize(b.n);
  const double inv = 1.0 / scale;
  for (std::size_t i = 0; i < b.n; ++i) {
    double zi = rp[3 * i + 2];
    if (wall) rmb::wall_regularisation(rp[3 * i + 2], radius[i], zi, b.damping[i]);
    b.x[i] = rp[3 * i] * inv;
    b.y[i] = rp[3 * i + 1] * inv;
    b.z[i] = zi * inv;
    if (vp) {
      b.vx[i] = vp[3 * i] * b.damping[i];
      b.vy[i] = vp[3 * i + 1] * b.damping[i];
      b.vz[i] = vp[3 * i + 2] * b.damping[i];
    }
  }
  return b;
}

inline std::vector<double> periodic_lengths(const Array &L, double scale, bool wall) {
  if (L.size() != 3) throw std::invalid_argument("periodic_length needs three numbers");
  std::vector<double> out(3);
  for (int k = 0; k < 3; ++k) {
    if (L.data()[k] < 0.0) throw std::invalid_argument("periodic_length entries must be >= 0");
    out[k] = L.data()[k] / scale;
  }
  if (wall && out[2] > 0.0) throw std::invalid_argument("periodic_length along z must be 0 with a wall at z = 0");
  return out;
}

// Shifts of the neighbour boxes -L, 0, +L along each periodic axis.
inline std::vector<double> image_shifts(const std::vector<double> &L) {
  std::vector<double> shifts;
  const int nx = L[0] > 0 ? 1 : 0, ny = L[1] > 0 ? 1 : 0, nz = L[2] > 0 ? 1 : 0;
  for (int i = -nx; i <= nx; ++i)
    for (int j = -ny; j <= ny; ++j)
      for (int k = -nz; k <= nz; ++k) {
        shifts.push_back(i * L[0]);
        shifts.push_back(j * L[1]);
        shifts.push_back(k * L[2]);
      }
  return shifts;
}

inline std::vector<double> radii_vector(const Array &radius, std::size_t n, const char *name) {
  if (radius.size() == 1) return std::vector<double>(n, radius.data()[0]);
  if (static_cast<std::size_t>(radius.size()) != n)
    throw std::invalid_argument(std::string(name) + " must be a number or have one entry per blob");
  return std::vector<double>(radius.data(), radius.data() + n);
}

// Domains of the source-target (per-blob radii) products.
enum Domain { kNoWall = 0, kWall = 1, kFreeSurface = 2 };

template <int D>
inline void radii_pair(double rx, double ry, double rz, double zt, double zs, double b, double as, double fx,
                       double fy, double fz, double &ux, double &uy, double &uz) {
  if (D == kFreeSurface)
    rmb::source_target_free_surface_pair(rx, ry, rz, zt, zs, b, as, fx, fy, fz, ux, uy, uz);
  else
    rmb::source_target_pair<D == kWall>(rx, ry, rz, zt, zs, b, as, fx, fy, fz, ux, uy, uz);
}
// domain: "single_wall", "no_wall" or "free_surface".
inline int domain_code(const std::string &domain) {
  if (domain == "no_wall") return kNoWall;
  if (domain == "single_wall") return kWall;
  if (domain == "free_surface") return kFreeSurface;
  throw std::invalid_argument("domain must be single_wall, no_wall or free_surface, got '" + domain + "'");
}

}  // namespace rmb_blobs
