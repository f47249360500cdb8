// Dense blob mobility matrices of mobility._mobility_cpp: the whole matrix of a set of blobs, the blocks of
// a stack of bodies (the preconditioner's), the cross blocks of pairs of bodies (the neighbour
// preconditioner's), per-blob radii and the free surface.  Each 3x3 block comes from the same pair formulas
// (blob_pair_kernels.h) as the products in mobility_module.cpp.
#include "dense_matrices.h"

#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

#include "blob_arrays.h"
#include "blob_pair_kernels.h"

using namespace rmb_blobs;

namespace {

template <bool Wall>
void fill_dense(const Blobs &b, const std::vector<double> &L, double factor, double *M) {
  const std::size_t n = b.n, cols = 3 * n;
  const std::vector<double> shifts = image_shifts(L);
  const std::size_t n_shifts = shifts.size() / 3;
#pragma omp parallel for schedule(static) if (worth_threads(n, n * n_shifts))
  for (std::size_t i = 0; i < n; ++i) {
    double block[9], sum[9];
    for (std::size_t j = 0; j < n; ++j) {
      for (int k = 0; k < 9; ++k) sum[k] = 0.0;
      for (std::size_t s = 0; s < n_shifts; ++s) {
        const double rx = rmb::minimum_image(b.x[i] - b.x[j], L[0]) + shifts[3 * s];
        const double ry = rmb::minimum_image(b.y[i] - b.y[j], L[1]) + shifts[3 * s + 1];
        const double rz = rmb::minimum_image(b.z[i] - b.z[j], L[2]) + shifts[3 * s + 2];
        rmb::trans_trans_block<Wall>(rx, ry, rz, b.z[i], b.z[j], block);
        for (int k = 0; k < 9; ++k) sum[k] += block[k];
      }
      const double f = factor * b.damping[i] * b.damping[j];
      for (int p = 0; p < 3; ++p)
        for (int q = 0; q < 3; ++q) M[(3 * i + p) * cols + 3 * j + q] = sum[3 * p + q] * f;
    }
  }
}

Array dense_trans_trans(const Array &r, double eta, double a, const Array &periodic_length, bool wall) {
  if (!(a > 0.0) || !(eta > 0.0)) throw std::invalid_argument("blob radius and viscosity must be positive");
  const std::size_t n = count_rows(r, "r_vectors");
  const Blobs b = make_blobs(r, nullptr, std::vector<double>(n, a), a, wall, "r_vectors");
  const std::vector<double> L = periodic_lengths(periodic_length, a, wall);
  Array M({static_cast<py::ssize_t>(3 * n), static_cast<py::ssize_t>(3 * n)});
  double *m = M.mutable_data();
  const double factor = 1.0 / (8.0 * M_PI * eta * a);
  {
    py::gil_scoped_release release;
    wall ? fill_dense<true>(b, L, factor, m) : fill_dense<false>(b, L, factor, m);
  }
  return M;
}

// Dense trans-trans blocks of nb bodies of n blobs each (the preconditioner's blocks): r (nb n, 3), bodies
// one after the other -> (nb, 3n, 3n), each block as dense_trans_trans of that body alone.  The bodies
// are split between the threads (one block is too small to share).
Array dense_trans_trans_stack(const Array &r, long bodies, double eta, double a, const Array &periodic_length,
                              bool wall) {
  if (!(a > 0.0) || !(eta > 0.0)) throw std::invalid_argument("blob radius and viscosity must be positive");
  const std::size_t total = count_rows(r, "r_vectors");
  if (bodies <= 0 || total % static_cast<std::size_t>(bodies) != 0)
    throw std::invalid_argument("r_vectors must hold the same number of blobs for every body");
  const std::size_t nb = static_cast<std::size_t>(bodies), n = total / nb;
  const Blobs all = make_blobs(r, nullptr, std::vector<double>(total, a), a, wall, "r_vectors");
  const std::vector<double> L = periodic_lengths(periodic_length, a, wall);
  Array M({static_cast<py::ssize_t>(nb), static_cast<py::ssize_t>(3 * n), static_cast<py::ssize_t>(3 * n)});
  double *m = M.mutable_data();
  const double factor = 1.0 / (8.0 * M_PI * eta * a);
  {
    py::gil_scoped_release release;
#pragma omp parallel for schedule(static) if (worth_threads(nb, 9 * n * n))
    for (std::size_t k = 0; k < nb; ++k) {
      Blobs b;
      b.n = n;
      const std::size_t first = k * n, last = first + n;
      b.x.assign(all.x.begin() + first, all.x.begin() + last);
      b.y.assign(all.y.begin() + first, all.y.begin() + last);
      b.z.assign(all.z.begin() + first, all.z.begin() + last);
      b.damping.assign(all.damping.begin() + first, all.damping.begin() + last);
      b.radius.assign(all.radius.begin() + first, all.radius.begin() + last);
      wall ? fill_dense<true>(b, L, factor, m + k * 9 * n * n) : fill_dense<false>(b, L, factor, m + k * 9 * n * n);
    }
  }
  return M;
}

// The cross blocks of pairs of bodies: block p (3 ni, 3 nj) couples the ni blobs of r_i[p] (rows) with the nj
// blobs of r_j[p] (columns), one radius a, free space or wall, no periodic images (the neighbour preconditioner
// places the partner at its minimum image).  They are the off-diagonal blocks of dense_trans_trans_stack of the
// pairs, at a quarter of its work (half when ni << nj).
template <bool Wall>
void fill_cross(const Blobs &bi, const Blobs &bj, std::size_t pairs, std::size_t ni, std::size_t nj, double factor,
                double *M) {
  const std::size_t cols = 3 * nj, size = 9 * ni * nj;
#pragma omp parallel for schedule(static) if (worth_threads(pairs, size))
  for (std::size_t p = 0; p < pairs; ++p) {
    double block[9];
    double *out = M + p * size;
    for (std::size_t i = 0; i < ni; ++i) {
      const std::size_t I = p * ni + i;
      for (std::size_t j = 0; j < nj; ++j) {
        const std::size_t J = p * nj + j;
        rmb::trans_trans_block<Wall>(bi.x[I] - bj.x[J], bi.y[I] - bj.y[J], bi.z[I] - bj.z[J], bi.z[I], bj.z[J],
                                     block);
        const double f = factor * bi.damping[I] * bj.damping[J];
        for (int r = 0; r < 3; ++r)
          for (int q = 0; q < 3; ++q) out[(3 * i + r) * cols + 3 * j + q] = block[3 * r + q] * f;
      }
    }
  }
}

Array dense_trans_trans_cross(const Array &r_i, const Array &r_j, long pairs, double eta, double a, bool wall) {
  if (!(a > 0.0) || !(eta > 0.0)) throw std::invalid_argument("blob radius and viscosity must be positive");
  const std::size_t rows_i = count_rows(r_i, "r_i"), rows_j = count_rows(r_j, "r_j");
  if (pairs <= 0 || rows_i % static_cast<std::size_t>(pairs) != 0 || rows_j % static_cast<std::size_t>(pairs) != 0)
    throw std::invalid_argument("r_i and r_j must hold the same number of blobs for every pair");
  const std::size_t P = static_cast<std::size_t>(pairs), ni = rows_i / P, nj = rows_j / P;
  const Blobs bi = make_blobs(r_i, nullptr, std::vector<double>(rows_i, a), a, wall, "r_i");
  const Blobs bj = make_blobs(r_j, nullptr, std::vector<double>(rows_j, a), a, wall, "r_j");
  Array M({static_cast<py::ssize_t>(P), static_cast<py::ssize_t>(3 * ni), static_cast<py::ssize_t>(3 * nj)});
  double *m = M.mutable_data();
  const double factor = 1.0 / (8.0 * M_PI * eta * a);
  {
    py::gil_scoped_release release;
    wall ? fill_cross<true>(bi, bj, P, ni, nj, factor, m) : fill_cross<false>(bi, bj, P, ni, nj, factor, m);
  }
  return M;
}

// Dense (3N, 3N) matrix of a product whose pair formula is `pair(i, j, shift, e, u)` (u += B_ij e): each
// 3x3 block from the pair formula applied to the three unit vectors, so that the matrix and the product
// share one formula.  Periodic images are summed as in the products.
template <class Pair>
void fill_dense_from_pairs(std::size_t n, const std::vector<double> &shifts, const Pair &pair,
                           const std::vector<double> &factor, double *M) {
  const std::size_t cols = 3 * n, n_shifts = shifts.size() / 3;
#pragma omp parallel for schedule(static) if (worth_threads(n, n * n_shifts))
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t j = 0; j < n; ++j)
      for (int q = 0; q < 3; ++q) {
        const double e[3] = {q == 0 ? 1.0 : 0.0, q == 1 ? 1.0 : 0.0, q == 2 ? 1.0 : 0.0};
        double u[3] = {0.0, 0.0, 0.0};
        for (std::size_t k = 0; k < n_shifts; ++k) pair(i, j, &shifts[3 * k], e, u);
        const double f = factor[i] * factor[j];
        for (int p = 0; p < 3; ++p) M[(3 * i + p) * cols + 3 * j + q] = u[p] * f;
      }
}

// Dense blob mobility with one radius per blob (wall, free space or free surface), physical units.
Array dense_radii(const Array &r, const Array &radius, double eta, const Array &periodic_length,
                  const std::string &domain) {
  if (!(eta > 0.0)) throw std::invalid_argument("viscosity must be positive");
  const int d = domain_code(domain);
  const std::size_t n = count_rows(r, "r_vectors");
  const Blobs b = make_blobs(r, nullptr, radii_vector(radius, n, "radius"), 1.0, d == kWall, "r_vectors");
  const std::vector<double> L = periodic_lengths(periodic_length, 1.0, d != kNoWall);
  const std::vector<double> shifts = image_shifts(L);
  Array M({static_cast<py::ssize_t>(3 * n), static_cast<py::ssize_t>(3 * n)});
  std::vector<double> factor(b.damping);
  for (double &f : factor) f *= std::sqrt(1.0 / (8.0 * M_PI * eta));
  double *m = M.mutable_data();
  {
    py::gil_scoped_release release;
    auto pair = [&](std::size_t i, std::size_t j, const double *shift, const double *e, double *u) {
      const double rx = rmb::minimum_image(b.x[i] - b.x[j], L[0]) + shift[0];
      const double ry = rmb::minimum_image(b.y[i] - b.y[j], L[1]) + shift[1];
      const double rz = rmb::minimum_image(b.z[i] - b.z[j], L[2]) + shift[2];
      if (d == kWall)
        radii_pair<kWall>(rx, ry, rz, b.z[i], b.z[j], b.radius[i], b.radius[j], e[0], e[1], e[2], u[0], u[1], u[2]);
      else if (d == kNoWall)
        radii_pair<kNoWall>(rx, ry, rz, b.z[i], b.z[j], b.radius[i], b.radius[j], e[0], e[1], e[2], u[0], u[1],
                            u[2]);
      else
        radii_pair<kFreeSurface>(rx, ry, rz, b.z[i], b.z[j], b.radius[i], b.radius[j], e[0], e[1], e[2], u[0],
                                 u[1], u[2]);
    };
    fill_dense_from_pairs(n, shifts, pair, factor, m);
  }
  return M;
}

// Dense free-surface blob mobility, one radius a (free_surface_pair).
Array dense_free_surface(const Array &r, double eta, double a, const Array &periodic_length) {
  if (!(a > 0.0) || !(eta > 0.0)) throw std::invalid_argument("blob radius and viscosity must be positive");
  const std::size_t n = count_rows(r, "r_vectors");
  const Blobs b = make_blobs(r, nullptr, std::vector<double>(n, a), a, false, "r_vectors");
  const std::vector<double> L = periodic_lengths(periodic_length, a, true);
  const std::vector<double> shifts = image_shifts(L);
  Array M({static_cast<py::ssize_t>(3 * n), static_cast<py::ssize_t>(3 * n)});
  const std::vector<double> factor(n, std::sqrt(1.0 / (8.0 * M_PI * eta * a)));
  double *m = M.mutable_data();
  {
    py::gil_scoped_release release;
    auto pair = [&](std::size_t i, std::size_t j, const double *shift, const double *e, double *u) {
      const double rx = rmb::minimum_image(b.x[i] - b.x[j], L[0]) + shift[0];
      const double ry = rmb::minimum_image(b.y[i] - b.y[j], L[1]) + shift[1];
      rmb::free_surface_pair(rx, ry, b.z[i] - b.z[j], b.z[i], b.z[j], e[0], e[1], e[2], u[0], u[1], u[2]);
    };
    fill_dense_from_pairs(n, shifts, pair, factor, m);
  }
  return M;
}

}  // namespace

void register_dense_matrices(py::module_ &m) {
  m.def("dense_trans_trans_stack", &dense_trans_trans_stack, py::arg("r_vectors"), py::arg("bodies"),
        py::arg("eta"), py::arg("a"), py::arg("periodic_length"), py::arg("wall"),
        "Dense trans-trans blocks (nb, 3n, 3n) of nb bodies of n blobs each, r (nb n, 3)");
  m.def("dense_trans_trans_cross", &dense_trans_trans_cross, py::arg("r_i"), py::arg("r_j"), py::arg("pairs"),
        py::arg("eta"), py::arg("a"), py::arg("wall"),
        "Cross blocks (P, 3ni, 3nj) of the blob mobility between the blobs r_i (P ni, 3) and r_j (P nj, 3) of P pairs");
  m.def("dense_trans_trans", &dense_trans_trans, py::arg("r_vectors"), py::arg("eta"), py::arg("a"),
        py::arg("periodic_length"), py::arg("wall"), "Dense (3N, 3N) blob mobility.");
  m.def("dense_radii", &dense_radii, py::arg("r_vectors"), py::arg("radius"), py::arg("eta"),
        py::arg("periodic_length"), py::arg("domain"), "Dense (3N, 3N) blob mobility with per-blob radii (N,).");
  m.def("dense_free_surface", &dense_free_surface, py::arg("r_vectors"), py::arg("eta"), py::arg("a"),
        py::arg("periodic_length"), "Dense (3N, 3N) free-surface blob mobility, one radius a.");
}
