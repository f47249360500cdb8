// C++ backend of the blob mobility products (pybind11 module mobility._mobility_cpp).
//
// Thin loops over blob pairs around the formulas of blob_pair_kernels.h:
// positions are scaled by 1/a and stored as separate x, y, z arrays so the
// inner loop over sources vectorises; OpenMP splits targets across threads.
// The trans-trans product visits each unordered pair once and adds both
// M_ij f_j and M_ji f_i = M_ij^T f_i (the mobility is symmetric), into
// per-thread accumulators that are summed at the end.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

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

#if defined(__AVX512F__)
using rmb::load8;
using rmb::store8;

inline double horizontal_sum(rmb::double8 v) {
  double sum = 0.0;
  for (int k = 0; k < 8; ++k) sum += v[k];
  return sum;
}
#endif

// Trans-trans product, each unordered pair once.
// Sum of the per-thread accumulators acc (threads blocks of [ux; uy; uz], each n long) into ux, uy, uz.
void reduce_thread_accumulators(const std::vector<double> &acc, int threads, std::size_t n, std::vector<double> &ux,
                                std::vector<double> &uy, std::vector<double> &uz) {
  ux.assign(n, 0.0), uy.assign(n, 0.0), uz.assign(n, 0.0);
  for (int t = 0; t < threads; ++t) {
    const double *ax = acc.data() + static_cast<std::size_t>(t) * 3 * n;
    for (std::size_t i = 0; i < n; ++i) ux[i] += ax[i], uy[i] += ax[n + i], uz[i] += ax[2 * n + i];
  }
}

template <bool Wall, bool Periodic, class Real>
void trans_times_force_symmetric(const Blobs &b, const std::vector<double> &L, std::vector<double> &ux,
                                 std::vector<double> &uy, std::vector<double> &uz) {
  const std::size_t n = b.n;
  const std::vector<double> shifts = image_shifts(L);
  const std::size_t n_shifts = shifts.size() / 3;
  const int threads = rmb::max_threads();
  std::vector<double> acc(static_cast<std::size_t>(threads) * 3 * n, 0.0);
  const double *x = b.x.data(), *y = b.y.data(), *z = b.z.data();
  const double *fx = b.vx.data(), *fy = b.vy.data(), *fz = b.vz.data();
  const double Lx = L[0], Ly = L[1], Lz = L[2];
#pragma omp parallel if (worth_threads(n, n / 2 * n_shifts))
  {
    double *ax = acc.data() + static_cast<std::size_t>(rmb::thread_index()) * 3 * n;
    double *ay = ax + n, *az = ay + n;
#pragma omp for schedule(dynamic, 16)
    for (std::size_t i = 0; i < n; ++i) {
      const double xi = x[i], yi = y[i], zi = z[i], fxi = fx[i], fyi = fy[i], fzi = fz[i];
      double uxi = 0.0, uyi = 0.0, uzi = 0.0;
      // the blob with itself and with its own periodic images
      for (std::size_t s = 0; s < n_shifts; ++s)
        rmb::trans_times_force_pair<Wall>(shifts[3 * s], shifts[3 * s + 1], shifts[3 * s + 2], zi, zi, fxi, fyi, fzi,
                                          uxi, uyi, uzi);
      std::size_t j_first = i + 1;
#if defined(__AVX512F__)
      if (!Periodic && std::is_same<Real, double>::value) {
        // eight sources at a time in explicit vectors (see blob_pair_kernels.h)
        using V = rmb::double8;
        const V vxi = V{} + xi, vyi = V{} + yi, vzi = V{} + zi, vfxi = V{} + fxi, vfyi = V{} + fyi,
                vfzi = V{} + fzi;
        V vux{}, vuy{}, vuz{};
        for (; j_first + 8 <= n; j_first += 8) {
          const std::size_t j = j_first;
          V usx{}, usy{}, usz{};
          rmb::trans_times_force_pair_both<Wall, V>(vxi - load8(x + j), vyi - load8(y + j), vzi - load8(z + j), vzi,
                                                    load8(z + j), load8(fx + j), load8(fy + j), load8(fz + j), vfxi,
                                                    vfyi, vfzi, vux, vuy, vuz, usx, usy, usz);
          store8(ax + j, load8(ax + j) + usx);
          store8(ay + j, load8(ay + j) + usy);
          store8(az + j, load8(az + j) + usz);
        }
        uxi += horizontal_sum(vux);
        uyi += horizontal_sum(vuy);
        uzi += horizontal_sum(vuz);
      }
#endif
      for (std::size_t s = 0; s < n_shifts; ++s) {
        const double sx = shifts[3 * s], sy = shifts[3 * s + 1], sz = shifts[3 * s + 2];
#pragma omp simd reduction(+ : uxi, uyi, uzi)
        for (std::size_t j = j_first; j < n; ++j) {
          double rx = xi - x[j], ry = yi - y[j], rz = zi - z[j];
          if (Periodic) {
            rx = rmb::minimum_image(rx, Lx) + sx;
            ry = rmb::minimum_image(ry, Ly) + sy;
            rz = rmb::minimum_image(rz, Lz) + sz;
          }
          // positions are subtracted in double; the pair formula runs in Real
          Real utx{}, uty{}, utz{}, usx{}, usy{}, usz{};
          rmb::trans_times_force_pair_both<Wall, Real>(Real(rx), Real(ry), Real(rz), Real(zi), Real(z[j]), Real(fx[j]),
                                                       Real(fy[j]), Real(fz[j]), Real(fxi), Real(fyi), Real(fzi), utx,
                                                       uty, utz, usx, usy, usz);
          uxi += utx;
          uyi += uty;
          uzi += utz;
          ax[j] += usx;
          ay[j] += usy;
          az[j] += usz;
        }
      }
      ax[i] += uxi;
      ay[i] += uyi;
      az[i] += uzi;
    }
  }
  reduce_thread_accumulators(acc, threads, n, ux, uy, uz);
}

using PairFunction = void (*)(double, double, double, double, double, double, double, double, double &, double &,
                              double &);

// Generic target-by-target sum for the roller couplings.
template <PairFunction Pair, bool Periodic>
void one_sided_sum(const Blobs &t, const Blobs &s, const std::vector<double> &L, std::vector<double> &ux,
                   std::vector<double> &uy, std::vector<double> &uz) {
  const std::vector<double> shifts = image_shifts(L);
  const std::size_t n_shifts = shifts.size() / 3, ns = s.n;
  ux.assign(t.n, 0.0), uy.assign(t.n, 0.0), uz.assign(t.n, 0.0);
  const double *x = s.x.data(), *y = s.y.data(), *z = s.z.data();
  const double *vx = s.vx.data(), *vy = s.vy.data(), *vz = s.vz.data();
  const double Lx = L[0], Ly = L[1], Lz = L[2];
#pragma omp parallel for schedule(static) if (worth_threads(t.n, ns * n_shifts))
  for (std::size_t i = 0; i < t.n; ++i) {
    const double xi = t.x[i], yi = t.y[i], zi = t.z[i];
    double a = 0.0, b = 0.0, c = 0.0;
    for (std::size_t k = 0; k < n_shifts; ++k) {
      const double sx = shifts[3 * k], sy = shifts[3 * k + 1], sz = shifts[3 * k + 2];
#pragma omp simd reduction(+ : a, b, c)
      for (std::size_t j = 0; j < ns; ++j) {
        double rx = xi - x[j], ry = yi - y[j], rz = zi - z[j];
        if (Periodic) {
          rx = rmb::minimum_image(rx, Lx) + sx;
          ry = rmb::minimum_image(ry, Ly) + sy;
          rz = rmb::minimum_image(rz, Lz) + sz;
        }
        Pair(rx, ry, rz, zi, z[j], vx[j], vy[j], vz[j], a, b, c);
      }
    }
    ux[i] = a, uy[i] = b, uz[i] = c;
  }
}

// The roller couplings of blobs with themselves, with or without periodic images.
template <PairFunction Pair>
void one_sided_sum_any_box(bool periodic, const Blobs &b, const std::vector<double> &L, std::vector<double> &ux,
                           std::vector<double> &uy, std::vector<double> &uz) {
  if (periodic)
    one_sided_sum<Pair, true>(b, b, L, ux, uy, uz);
  else
    one_sided_sum<Pair, false>(b, b, L, ux, uy, uz);
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
        periodic ? trans_times_force_symmetric<Wall, true, float>(b, L, ux, uy, uz)
                 : trans_times_force_symmetric<Wall, false, float>(b, L, ux, uy, uz);
      else
        periodic ? trans_times_force_symmetric<Wall, true, double>(b, L, ux, uy, uz)
                 : trans_times_force_symmetric<Wall, false, double>(b, L, ux, uy, uz);
    } else if (kind == "trans_times_torque") {
      power = 2.0;
      one_sided_sum_any_box<rmb::trans_times_torque_pair<Wall>>(periodic, b, L, ux, uy, uz);
    } else if (kind == "rot_times_force") {
      power = 2.0;
      one_sided_sum_any_box<rmb::rot_times_force_pair<Wall>>(periodic, b, L, ux, uy, uz);
    } else if (kind == "rot_times_torque") {
      power = 3.0;
      one_sided_sum_any_box<rmb::rot_times_torque_pair<Wall>>(periodic, b, L, ux, uy, uz);
    } else {
      throw std::invalid_argument("unknown product " + kind);
    }
  }
  return flat_result(ux, uy, uz, b.damping, 1.0 / (8.0 * M_PI * eta * std::pow(a, power)));
}

// Trans-trans product of two vectors in one pass over the unordered pairs (no periodic images):
// the pair coefficients are computed once and applied to both vectors.
template <bool Wall>
void trans_times_force_symmetric_two(const Blobs &b, const Blobs &c, std::vector<double> &out) {
  const std::size_t n = b.n;
  const int threads = rmb::max_threads();
  std::vector<double> acc(static_cast<std::size_t>(threads) * 6 * n, 0.0);
  const double *x = b.x.data(), *y = b.y.data(), *z = b.z.data();
  const double *fx = b.vx.data(), *fy = b.vy.data(), *fz = b.vz.data();
  const double *gx = c.vx.data(), *gy = c.vy.data(), *gz = c.vz.data();
#pragma omp parallel if (worth_threads(n, n / 2))
  {
    double *ax = acc.data() + static_cast<std::size_t>(rmb::thread_index()) * 6 * n;
    double *ay = ax + n, *az = ay + n, *bx = az + n, *by = bx + n, *bz = by + n;
#pragma omp for schedule(dynamic, 16)
    for (std::size_t i = 0; i < n; ++i) {
      const double xi = x[i], yi = y[i], zi = z[i], fxi = fx[i], fyi = fy[i], fzi = fz[i], gxi = gx[i], gyi = gy[i],
                   gzi = gz[i];
      double uxi = 0.0, uyi = 0.0, uzi = 0.0, vxi = 0.0, vyi = 0.0, vzi = 0.0;
      rmb::trans_times_force_pair<Wall>(0.0, 0.0, 0.0, zi, zi, fxi, fyi, fzi, uxi, uyi, uzi);
      rmb::trans_times_force_pair<Wall>(0.0, 0.0, 0.0, zi, zi, gxi, gyi, gzi, vxi, vyi, vzi);
      std::size_t j_first = i + 1;
#if defined(__AVX512F__)
      {
        using V = rmb::double8;
        const V pxi = V{} + xi, pyi = V{} + yi, pzi = V{} + zi, vfx = V{} + fxi, vfy = V{} + fyi, vfz = V{} + fzi,
                vgx = V{} + gxi, vgy = V{} + gyi, vgz = V{} + gzi;
        V sux{}, suy{}, suz{}, svx{}, svy{}, svz{};
        for (; j_first + 8 <= n; j_first += 8) {
          const std::size_t j = j_first;
          const V rx = pxi - load8(x + j), ry = pyi - load8(y + j), rz = pzi - load8(z + j);
          const rmb::TransTransBlock<V> k = rmb::trans_trans_coefficients<Wall, V>(rx, ry, rz, pzi, load8(z + j));
          V usx{}, usy{}, usz{}, wsx{}, wsy{}, wsz{};
          rmb::apply_trans_trans<Wall, false, V>(k, rx, ry, rz, load8(fx + j), load8(fy + j), load8(fz + j), sux, suy,
                                                 suz);
          rmb::apply_trans_trans<Wall, true, V>(k, rx, ry, rz, vfx, vfy, vfz, usx, usy, usz);
          rmb::apply_trans_trans<Wall, false, V>(k, rx, ry, rz, load8(gx + j), load8(gy + j), load8(gz + j), svx, svy,
                                                 svz);
          rmb::apply_trans_trans<Wall, true, V>(k, rx, ry, rz, vgx, vgy, vgz, wsx, wsy, wsz);
          store8(ax + j, load8(ax + j) + usx), store8(ay + j, load8(ay + j) + usy), store8(az + j, load8(az + j) + usz);
          store8(bx + j, load8(bx + j) + wsx), store8(by + j, load8(by + j) + wsy), store8(bz + j, load8(bz + j) + wsz);
        }
        uxi += horizontal_sum(sux), uyi += horizontal_sum(suy), uzi += horizontal_sum(suz);
        vxi += horizontal_sum(svx), vyi += horizontal_sum(svy), vzi += horizontal_sum(svz);
      }
#endif
#pragma omp simd reduction(+ : uxi, uyi, uzi, vxi, vyi, vzi)
      for (std::size_t j = j_first; j < n; ++j) {
        const double rx = xi - x[j], ry = yi - y[j], rz = zi - z[j];
        const rmb::TransTransBlock<double> k = rmb::trans_trans_coefficients<Wall>(rx, ry, rz, zi, z[j]);
        double utx = 0.0, uty = 0.0, utz = 0.0, usx = 0.0, usy = 0.0, usz = 0.0;
        double wtx = 0.0, wty = 0.0, wtz = 0.0, wsx = 0.0, wsy = 0.0, wsz = 0.0;
        rmb::apply_trans_trans<Wall, false>(k, rx, ry, rz, fx[j], fy[j], fz[j], utx, uty, utz);
        rmb::apply_trans_trans<Wall, true>(k, rx, ry, rz, fxi, fyi, fzi, usx, usy, usz);
        rmb::apply_trans_trans<Wall, false>(k, rx, ry, rz, gx[j], gy[j], gz[j], wtx, wty, wtz);
        rmb::apply_trans_trans<Wall, true>(k, rx, ry, rz, gxi, gyi, gzi, wsx, wsy, wsz);
        uxi += utx, uyi += uty, uzi += utz, vxi += wtx, vyi += wty, vzi += wtz;
        ax[j] += usx, ay[j] += usy, az[j] += usz, bx[j] += wsx, by[j] += wsy, bz[j] += wsz;
      }
      ax[i] += uxi, ay[i] += uyi, az[i] += uzi, bx[i] += vxi, by[i] += vyi, bz[i] += vzi;
    }
  }
  out.assign(6 * n, 0.0);
  for (int t = 0; t < threads; ++t) {
    const double *a = acc.data() + static_cast<std::size_t>(t) * 6 * n;
    for (std::size_t i = 0; i < 6 * n; ++i) out[i] += a[i];
  }
}

py::tuple product_two(const Array &r, const Array &v1, const Array &v2, double eta, double a, bool wall) {
  if (!(a > 0.0) || !(eta > 0.0)) throw std::invalid_argument("blob radius and viscosity must be positive");
  const std::size_t n = count_rows(r, "r_vectors");
  Blobs b = make_blobs(r, &v1, std::vector<double>(n, a), a, wall, "r_vectors");
  Blobs c = make_blobs(r, &v2, std::vector<double>(n, a), a, wall, "r_vectors");
  std::vector<double> out;
  {
    py::gil_scoped_release release;
    wall ? trans_times_force_symmetric_two<true>(b, c, out) : trans_times_force_symmetric_two<false>(b, c, out);
  }
  const double factor = 1.0 / (8.0 * M_PI * eta * a);
  std::vector<double> ux(out.begin(), out.begin() + n), uy(out.begin() + n, out.begin() + 2 * n),
      uz(out.begin() + 2 * n, out.begin() + 3 * n), wx(out.begin() + 3 * n, out.begin() + 4 * n),
      wy(out.begin() + 4 * n, out.begin() + 5 * n), wz(out.begin() + 5 * n, out.end());
  return py::make_tuple(flat_result(ux, uy, uz, b.damping, factor), flat_result(wx, wy, wz, c.damping, factor));
}

Array product(const std::string &kind, const Array &r, const Array &vector, double eta, double a,
              const Array &periodic_length, bool wall, const std::string &precision) {
  return wall ? blob_product<true>(kind, r, vector, eta, a, periodic_length, precision)
              : blob_product<false>(kind, r, vector, eta, a, periodic_length, precision);
}


template <int D, bool Periodic>
void source_target_sum(const Blobs &t, const Blobs &s, const std::vector<double> &L, std::vector<double> &ux,
                       std::vector<double> &uy, std::vector<double> &uz) {
  const std::vector<double> shifts = image_shifts(L);
  const std::size_t n_shifts = shifts.size() / 3;
  ux.assign(t.n, 0.0), uy.assign(t.n, 0.0), uz.assign(t.n, 0.0);
  const double *x = s.x.data(), *y = s.y.data(), *z = s.z.data(), *rad = s.radius.data();
  const double *vx = s.vx.data(), *vy = s.vy.data(), *vz = s.vz.data();
  const double Lx = L[0], Ly = L[1], Lz = L[2];
#pragma omp parallel for schedule(static) if (worth_threads(t.n, s.n * n_shifts))
  for (std::size_t i = 0; i < t.n; ++i) {
    const double xi = t.x[i], yi = t.y[i], zi = t.z[i], bi = t.radius[i];
    double a = 0.0, b = 0.0, c = 0.0;
    for (std::size_t k = 0; k < n_shifts; ++k) {
      const double sx = shifts[3 * k], sy = shifts[3 * k + 1], sz = shifts[3 * k + 2];
#pragma omp simd reduction(+ : a, b, c)
      for (std::size_t j = 0; j < s.n; ++j) {
        double rx = xi - x[j], ry = yi - y[j], rz = zi - z[j];
        if (Periodic) {
          rx = rmb::minimum_image(rx, Lx) + sx;
          ry = rmb::minimum_image(ry, Ly) + sy;
          rz = rmb::minimum_image(rz, Lz) + sz;
        }
        radii_pair<D>(rx, ry, rz, zi, z[j], bi, rad[j], vx[j], vy[j], vz[j], a, b, c);
      }
    }
    ux[i] = a, uy[i] = b, uz[i] = c;
  }
}

template <int D>
void source_target_any_box(bool periodic, const Blobs &t, const Blobs &s, const std::vector<double> &L,
                           std::vector<double> &ux, std::vector<double> &uy, std::vector<double> &uz) {
  if (periodic)
    source_target_sum<D, true>(t, s, L, ux, uy, uz);
  else
    source_target_sum<D, false>(t, s, L, ux, uy, uz);
}

// M f with per-blob radii, sources = targets (wall or free space): each unordered pair once,
// adding M_ij f_j to i and M_ij^T f_i = M_ji f_i to j (the mobility is symmetric), into
// per-thread accumulators; the blob with itself and its own images as in the one-sided sum.
template <bool Wall, bool Periodic>
void radii_symmetric_sum(const Blobs &b, const std::vector<double> &L, std::vector<double> &ux,
                         std::vector<double> &uy, std::vector<double> &uz) {
  const std::size_t n = b.n;
  const std::vector<double> shifts = image_shifts(L);
  const std::size_t n_shifts = shifts.size() / 3;
  const int threads = rmb::max_threads();
  std::vector<double> acc(static_cast<std::size_t>(threads) * 3 * n, 0.0);
  const double *x = b.x.data(), *y = b.y.data(), *z = b.z.data(), *rad = b.radius.data();
  const double *fx = b.vx.data(), *fy = b.vy.data(), *fz = b.vz.data();
  const double Lx = L[0], Ly = L[1], Lz = L[2];
#pragma omp parallel if (worth_threads(n, n / 2 * n_shifts))
  {
    double *ax = acc.data() + static_cast<std::size_t>(rmb::thread_index()) * 3 * n;
    double *ay = ax + n, *az = ay + n;
#pragma omp for schedule(dynamic, 16)
    for (std::size_t i = 0; i < n; ++i) {
      const double xi = x[i], yi = y[i], zi = z[i], bi = rad[i], fxi = fx[i], fyi = fy[i], fzi = fz[i];
      double uxi = 0.0, uyi = 0.0, uzi = 0.0;
      for (std::size_t s = 0; s < n_shifts; ++s)
        rmb::source_target_pair<Wall>(shifts[3 * s], shifts[3 * s + 1], shifts[3 * s + 2], zi, zi, bi, bi, fxi, fyi,
                                      fzi, uxi, uyi, uzi);
      for (std::size_t s = 0; s < n_shifts; ++s) {
        const double sx = shifts[3 * s], sy = shifts[3 * s + 1], sz = shifts[3 * s + 2];
#pragma omp simd reduction(+ : uxi, uyi, uzi)
        for (std::size_t j = i + 1; j < n; ++j) {
          double rx = xi - x[j], ry = yi - y[j], rz = zi - z[j];
          if (Periodic) {
            rx = rmb::minimum_image(rx, Lx) + sx;
            ry = rmb::minimum_image(ry, Ly) + sy;
            rz = rmb::minimum_image(rz, Lz) + sz;
          }
          double utx = 0.0, uty = 0.0, utz = 0.0, usx = 0.0, usy = 0.0, usz = 0.0;
          rmb::source_target_pair_both<Wall>(rx, ry, rz, zi, z[j], bi, rad[j], fx[j], fy[j], fz[j], fxi, fyi, fzi,
                                             utx, uty, utz, usx, usy, usz);
          uxi += utx;
          uyi += uty;
          uzi += utz;
          ax[j] += usx;
          ay[j] += usy;
          az[j] += usz;
        }
      }
      ax[i] += uxi;
      ay[i] += uyi;
      az[i] += uzi;
    }
  }
  reduce_thread_accumulators(acc, threads, n, ux, uy, uz);
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
    if (wall)
      periodic ? radii_symmetric_sum<true, true>(b, L, ux, uy, uz) : radii_symmetric_sum<true, false>(b, L, ux, uy, uz);
    else
      periodic ? radii_symmetric_sum<false, true>(b, L, ux, uy, uz)
               : radii_symmetric_sum<false, false>(b, L, ux, uy, uz);
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
    one_sided_sum_any_box<rmb::free_surface_pair>(periodic, b, L, ux, uy, uz);
  }
  return flat_result(ux, uy, uz, b.damping, 1.0 / (8.0 * M_PI * eta * a));
}

}  // namespace
PYBIND11_MODULE(_mobility_cpp, m) {
  m.doc() = "C++ (OpenMP) blob mobility products; formulas in blob_pair_kernels.h";
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
  register_dense_matrices(m);
  m.def("max_threads", &rmb::max_threads, "Number of OpenMP threads the kernels use.");
}
