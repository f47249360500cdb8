// Per-body dense blocks of the block-diagonal preconditioner (pybind11 module
// multi_bodies.solver._preconditioner_cpp).
//
// GMRES applies the preconditioner once per iteration and the preconditioned Lanczos
// iteration applies L^{-1} and L^{-T} once each; for 100 bodies of 15 blobs that is
// 100 dense 45x45 blocks per application.  NumPy's stacked matmul spends half of its
// time per block in call overhead; these loops read each block once, in order.
// body_solver.BlockDiagonalPreconditioner has the NumPy versions of the same
// formulas (used when this module is not built).  The block loops have no OpenMP: one application reads
// about 2 MB of blocks, a few tens of microseconds on one core.
//
// Layouts (C-contiguous doubles): blocks (nb, m, m); a vector of a structure type's
// unknowns is x[start + k m : start + (k + 1) m] for body k.
//
// rigid_near_field: the near-field product of the neighbour preconditioner computed from the blob
// positions instead of stored pair blocks (neighbour_preconditioner.NeighbourPreconditioner; the stored
// path there is its reference):
//   out_i = sum over the partners q of body(i), over the blobs j of body partners[q], of M(x_i, x_j + shift_q) f_j,
//   out_j += M(x_i, x_j + shift_q)^T f_i  (each pair listed once, for its two directions: M is symmetric),
// M the blob mobility of one radius a of the mobility backends (RPY, and with `wall` the Swan-Brady image
// terms, heights below a raised to a and the blob's vectors damped by z / a, pair_laws.h), with no periodic
// images: the shift places the partner.  offsets (Nb + 1,) the bodies' first blobs; target_start (Nb + 1,)
// each body's range of partners (partners (Q,), shifts (Q, 3)).  OpenMP over the target blobs, each
// thread writing its own rows.  It reads only positions, so one application costs the near pairs' share of
// an M f product instead of a pass over stored blocks (9 doubles per blob pair).
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <stdexcept>
#include <string>
#include <vector>

#include "blob_pair_kernels.h"  // the blob mobility of the mobility backends (mobility/cpp)
#include "openmp_threads.h"

// near_field_loop, compiled once per vector path (the chosen one runs: mobility/cpp/simd_dispatch.h)
#define RMB_SIMD_KERNELS "near_field_kernels.inc"
#include "simd_targets.h"

namespace py = pybind11;
using Array = py::array_t<double, py::array::c_style | py::array::forcecast>;
using Out = py::array_t<double, py::array::c_style>;

namespace {

void check_blocks(const Array &blocks, long rows, long cols, const char *name) {
  if (blocks.ndim() != 3 || blocks.shape(1) != rows || blocks.shape(2) != cols)
    throw std::invalid_argument(std::string(name) + " must have shape (nb, " + std::to_string(rows) + ", " +
                                std::to_string(cols) + ")");
}

void check_range(long start, long length, long size, const char *name) {
  if (start < 0 || start + length > size) throw std::invalid_argument(std::string(name) + " runs past the vector");
}

// y = B x (transpose false) or B^T x, for an (m, m) block; lower: B is lower triangular with zeros above
// the diagonal, which the loops skip (all but the few of each group of four rows).
inline void block_times(const double *B, long m, const double *x, double *y, bool transpose, bool lower) {
  if (!transpose) {
    // four rows at a time: four independent sums instead of one dependency chain
    long i = 0;
    for (; i + 4 <= m; i += 4) {
      const double *r0 = B + i * m, *r1 = r0 + m, *r2 = r1 + m, *r3 = r2 + m;
      const long end = lower ? i + 4 : m;
      double s0 = 0.0, s1 = 0.0, s2 = 0.0, s3 = 0.0;
#pragma omp simd reduction(+ : s0, s1, s2, s3)
      for (long j = 0; j < end; ++j) {
        s0 += r0[j] * x[j];
        s1 += r1[j] * x[j];
        s2 += r2[j] * x[j];
        s3 += r3[j] * x[j];
      }
      y[i] = s0, y[i + 1] = s1, y[i + 2] = s2, y[i + 3] = s3;
    }
    for (; i < m; ++i) {
      const double *row = B + i * m;
      const long end = lower ? i + 1 : m;
      double s = 0.0;
      for (long j = 0; j < end; ++j) s += row[j] * x[j];
      y[i] = s;
    }
  } else {
    for (long j = 0; j < m; ++j) y[j] = 0.0;
    for (long i = 0; i < m; ++i) {
      const double *row = B + i * m;
      const double xi = x[i];
      const long end = lower ? i + 1 : m;
#pragma omp simd
      for (long j = 0; j < end; ++j) y[j] += row[j] * xi;
    }
  }
}

// out[start + k m : ...] = B_k x[start + k m : ...] (or B_k^T) for the nb blocks of one structure type.
void block_product(const Array &blocks, const Array &x, Out &out, long start, bool transpose, bool lower) {
  if (blocks.ndim() != 3 || blocks.shape(1) != blocks.shape(2))
    throw std::invalid_argument("blocks must have shape (nb, m, m)");
  const long nb = blocks.shape(0), m = blocks.shape(1);
  if (out.size() != x.size()) throw std::invalid_argument("out and x must have the same size");
  check_range(start, nb * m, x.size(), "the blocks' unknowns");
  const double *B = blocks.data(), *xp = x.data() + start;
  double *yp = out.mutable_data() + start;
  if (xp == yp) throw std::invalid_argument("out must not be x");
  py::gil_scoped_release release;
  for (long k = 0; k < nb; ++k) block_times(B + k * m * m, m, xp + k * m, yp + k * m, transpose, lower);
}

// The coupling of pairs of bodies: for pair p, out[i_p : i_p + mi] += O_p x[j_p : j_p + mj] and
// out[j_p : j_p + mj] += O_p^T x[i_p : i_p + mi] (O (P, mi, mj); i, j the pairs' first unknowns).  Each
// block is read once for both products (the neighbour preconditioner's near-field product).
void pair_product(const Array &O, const py::array_t<long long, py::array::c_style | py::array::forcecast> &first,
                  const py::array_t<long long, py::array::c_style | py::array::forcecast> &second, const Array &x,
                  Out &out) {
  if (O.ndim() != 3) throw std::invalid_argument("O must have shape (P, mi, mj)");
  const long P = O.shape(0), mi = O.shape(1), mj = O.shape(2);
  if (first.size() != P || second.size() != P) throw std::invalid_argument("one first unknown per pair");
  if (out.size() != x.size()) throw std::invalid_argument("out and x must have the same size");
  const long long *fi = first.data(), *fj = second.data();
  for (long p = 0; p < P; ++p) {
    check_range(static_cast<long>(fi[p]), mi, x.size(), "a pair's first body");
    check_range(static_cast<long>(fj[p]), mj, x.size(), "a pair's second body");
  }
  const double *Op = O.data(), *xp = x.data();
  double *yp = out.mutable_data();
  if (xp == yp) throw std::invalid_argument("out must not be x");
  py::gil_scoped_release release;
  for (long p = 0; p < P; ++p) {
    const double *B = Op + p * mi * mj, *xi = xp + fi[p], *xj = xp + fj[p];
    double *yi = yp + fi[p], *yj = yp + fj[p];
    for (long r = 0; r < mi; ++r) {
      const double *row = B + r * mj;
      double sum = 0.0;
      const double xr = xi[r];
      for (long c = 0; c < mj; ++c) {
        sum += row[c] * xj[c];
        yj[c] += row[c] * xr;
      }
      yi[r] += sum;
    }
  }
}

// The exact inverse of each body's saddle-point block [[M_k, -K_k], [-K_k^T, 0]] applied to
// [s_k; f_k] (s_k at blob_start + k 3n, f_k at body_start + 6 k):
//   lambda~ = M_k^{-1} s_k,  U_k = -N_k (f_k + K_k^T lambda~),  lambda_k = lambda~ + (M_k^{-1} K_k) U_k.
void saddle_block_inverse(const Array &M_inv, const Array &M_inv_K, const Array &K, const Array &N, const Array &x,
                          Out &out, long blob_start, long body_start) {
  if (M_inv.ndim() != 3 || M_inv.shape(1) != M_inv.shape(2)) throw std::invalid_argument("M_inv must be (nb, 3n, 3n)");
  const long nb = M_inv.shape(0), m = M_inv.shape(1);
  check_blocks(M_inv_K, m, 6, "M_inv_K");
  check_blocks(K, m, 6, "K");
  check_blocks(N, 6, 6, "N");
  if (M_inv_K.shape(0) != nb || K.shape(0) != nb || N.shape(0) != nb)
    throw std::invalid_argument("M_inv, M_inv_K, K and N must hold the same bodies");
  if (out.size() != x.size()) throw std::invalid_argument("out and x must have the same size");
  check_range(blob_start, nb * m, x.size(), "the blob unknowns");
  check_range(body_start, nb * 6, x.size(), "the body unknowns");
  const double *Mi = M_inv.data(), *MiK = M_inv_K.data(), *Kp = K.data(), *Np = N.data(), *xp = x.data();
  double *yp = out.mutable_data();
  if (xp == yp) throw std::invalid_argument("out must not be x");
  py::gil_scoped_release release;
  for (long k = 0; k < nb; ++k) {
    const double *s = xp + blob_start + k * m, *f = xp + body_start + 6 * k;
    double *lam = yp + blob_start + k * m, *U = yp + body_start + 6 * k;
    block_times(Mi + k * m * m, m, s, lam, false, false);  // lambda~
    double t[6];
    for (int c = 0; c < 6; ++c) t[c] = f[c];
    const double *Kk = Kp + k * m * 6;
    for (long i = 0; i < m; ++i)
      for (int c = 0; c < 6; ++c) t[c] += Kk[6 * i + c] * lam[i];
    const double *Nk = Np + 36 * k;
    for (int r = 0; r < 6; ++r) {
      double s6 = 0.0;
      for (int c = 0; c < 6; ++c) s6 += Nk[6 * r + c] * t[c];
      U[r] = -s6;
    }
    const double *MiKk = MiK + k * m * 6;
    for (long i = 0; i < m; ++i) {
      double s6 = 0.0;
      for (int c = 0; c < 6; ++c) s6 += MiKk[6 * i + c] * U[c];
      lam[i] += s6;
    }
  }
}

// L^{-1} of each lower-triangular block L_k with a positive diagonal (Cholesky factors), by forward
// substitution column by column: (nb, m, m) -> (nb, m, m), lower triangular with exact zeros above the
// diagonal.  m^3 / 6 multiply-adds per block, a third of a general solve against the identity.
Array lower_triangular_inverse(const Array &blocks) {
  if (blocks.ndim() != 3 || blocks.shape(1) != blocks.shape(2))
    throw std::invalid_argument("blocks must have shape (nb, m, m)");
  const long nb = blocks.shape(0), m = blocks.shape(1);
  Array result({static_cast<py::ssize_t>(nb), static_cast<py::ssize_t>(m), static_cast<py::ssize_t>(m)});
  const double *L = blocks.data();
  double *X = result.mutable_data();
  for (long k = 0; k < nb; ++k)
    for (long i = 0; i < m; ++i)
      if (!(L[k * m * m + i * m + i] > 0.0))
        throw std::invalid_argument("block " + std::to_string(k) + " has a diagonal entry that is not positive");
  py::gil_scoped_release release;
  std::vector<double> column(static_cast<std::size_t>(m));
  for (long k = 0; k < nb; ++k) {
    const double *Lk = L + k * m * m;
    double *Xk = X + k * m * m;
    for (long e = 0; e < m * m; ++e) Xk[e] = 0.0;
    for (long j = 0; j < m; ++j) {  // column j of L^{-1}: L x = e_j, x_i = 0 for i < j
      column[j] = 1.0 / Lk[j * m + j];
      for (long i = j + 1; i < m; ++i) {
        const double *row = Lk + i * m;
        double s = 0.0;
#pragma omp simd reduction(+ : s)
        for (long c = j; c < i; ++c) s += row[c] * column[c];
        column[i] = -s / row[i];
      }
      for (long i = j; i < m; ++i) Xk[i * m + j] = column[i];
    }
  }
  return result;
}


// A block lower-triangular matrix L over the bodies (the incomplete Cholesky factor of the noise,
// multi_bodies/solver/noise_factor.py) applied to a vector: mode 0 out = L x, mode 1 out = L^{-1} x,
// mode 2 out = L^{-T} x.  Body b's unknowns are x[starts[b] : starts[b + 1]] (m_b of them); its diagonal
// block is diag[diag_offsets[b] : + m_b m_b] (row-major; L_bb for mode 0, L_bb^{-1} for modes 1 and 2,
// both lower triangular); the strictly lower blocks of block row i are p = row_ptr[i] .. row_ptr[i + 1] - 1,
// in block column cols[p] < i, (m_i, m_cols[p]) row-major at blocks[block_offsets[p]].
using Index = py::array_t<long long, py::array::c_style | py::array::forcecast>;

inline void general_times(const double *B, long rows, long cols, const double *x, double *y, double sign,
                          bool transpose) {
  // y += sign B x (B (rows, cols)) or y += sign B^T x (x of rows, y of cols)
  if (!transpose) {
    for (long r = 0; r < rows; ++r) {
      const double *row = B + r * cols;
      double s = 0.0;
#pragma omp simd reduction(+ : s)
      for (long c = 0; c < cols; ++c) s += row[c] * x[c];
      y[r] += sign * s;
    }
  } else {
    for (long r = 0; r < rows; ++r) {
      const double *row = B + r * cols;
      const double xr = sign * x[r];
#pragma omp simd
      for (long c = 0; c < cols; ++c) y[c] += row[c] * xr;
    }
  }
}

void block_lower_apply(int mode, const Index &starts, const Index &diag_offsets, const Array &diag,
                       const Index &row_ptr, const Index &cols, const Index &block_offsets, const Array &blocks,
                       const Array &x, Out &out) {
  if (mode < 0 || mode > 2) throw std::invalid_argument("mode is 0 (L x), 1 (L^-1 x) or 2 (L^-T x)");
  const long nb = static_cast<long>(starts.size()) - 1;
  if (nb < 0 || diag_offsets.size() != nb || row_ptr.size() != nb + 1)
    throw std::invalid_argument("starts (nb + 1), diag_offsets (nb) and row_ptr (nb + 1) disagree");
  if (cols.size() != block_offsets.size()) throw std::invalid_argument("one column per lower block");
  if (out.size() != x.size()) throw std::invalid_argument("out and x must have the same size");
  const long long *st = starts.data(), *dof = diag_offsets.data(), *rp = row_ptr.data(), *cl = cols.data(),
                  *bof = block_offsets.data();
  if (st[0] != 0 || st[nb] != x.size()) throw std::invalid_argument("starts must run from 0 to the vector's size");
  if (rp[0] != 0 || rp[nb] != cols.size()) throw std::invalid_argument("row_ptr must run from 0 to len(cols)");
  for (long b = 0; b < nb; ++b) {
    const long m = static_cast<long>(st[b + 1] - st[b]);
    if (m < 0 || dof[b] < 0 || dof[b] + m * m > diag.size()) throw std::invalid_argument("a diagonal block runs past diag");
    for (long long p = rp[b]; p < rp[b + 1]; ++p) {
      if (cl[p] < 0 || cl[p] >= b) throw std::invalid_argument("a lower block is not left of the diagonal");
      const long mk = static_cast<long>(st[cl[p] + 1] - st[cl[p]]);
      if (bof[p] < 0 || bof[p] + m * mk > blocks.size()) throw std::invalid_argument("a lower block runs past blocks");
    }
  }
  const double *D = diag.data(), *B = blocks.data(), *xp = x.data();
  double *yp = out.mutable_data();
  if (xp == yp) throw std::invalid_argument("out must not be x");
  py::gil_scoped_release release;
  long largest = 0;
  for (long b = 0; b < nb; ++b) largest = std::max(largest, static_cast<long>(st[b + 1] - st[b]));
  std::vector<double> scratch(static_cast<std::size_t>(largest));
  if (mode == 0) {  // y_i = L_ii x_i + sum_k L_ik x_k
    for (long i = 0; i < nb; ++i) {
      const long m = static_cast<long>(st[i + 1] - st[i]);
      block_times(D + dof[i], m, xp + st[i], yp + st[i], false, true);
      for (long long p = rp[i]; p < rp[i + 1]; ++p)
        general_times(B + bof[p], m, static_cast<long>(st[cl[p] + 1] - st[cl[p]]), xp + st[cl[p]], yp + st[i], 1.0,
                      false);
    }
  } else if (mode == 1) {  // forward: y_i = L_ii^{-1} (x_i - sum_k L_ik y_k)
    for (long i = 0; i < nb; ++i) {
      const long m = static_cast<long>(st[i + 1] - st[i]);
      for (long r = 0; r < m; ++r) scratch[r] = xp[st[i] + r];
      for (long long p = rp[i]; p < rp[i + 1]; ++p)
        general_times(B + bof[p], m, static_cast<long>(st[cl[p] + 1] - st[cl[p]]), yp + st[cl[p]], scratch.data(),
                      -1.0, false);
      block_times(D + dof[i], m, scratch.data(), yp + st[i], false, true);
    }
  } else {  // backward: y_i = L_ii^{-T} (x_i - sum_{j > i} L_ji^T y_j), the rows j pushing their terms left
    for (long e = 0; e < x.size(); ++e) yp[e] = xp[e];
    for (long i = nb - 1; i >= 0; --i) {
      const long m = static_cast<long>(st[i + 1] - st[i]);
      for (long r = 0; r < m; ++r) scratch[r] = yp[st[i] + r];
      block_times(D + dof[i], m, scratch.data(), yp + st[i], true, true);
      for (long long p = rp[i]; p < rp[i + 1]; ++p)
        general_times(B + bof[p], m, static_cast<long>(st[cl[p] + 1] - st[cl[p]]), yp + st[i], yp + st[cl[p]], -1.0,
                      true);
    }
  }
}


// Lower Cholesky factor of a dense symmetric (m, m) matrix A (row-major, its lower triangle read) into L
// (zeros above the diagonal); false when a pivot is not positive (A not positive definite to rounding).
bool dense_cholesky(const double *A, long m, double *L) {
  for (long e = 0; e < m * m; ++e) L[e] = 0.0;
  for (long j = 0; j < m; ++j) {
    double d = A[j * m + j];
    for (long c = 0; c < j; ++c) d -= L[j * m + c] * L[j * m + c];
    if (!(d > 0.0)) return false;
    const double root = std::sqrt(d);
    L[j * m + j] = root;
    for (long i = j + 1; i < m; ++i) {
      double s = A[i * m + j];
      for (long c = 0; c < j; ++c) s -= L[i * m + c] * L[j * m + c];
      L[i * m + j] = s / root;
    }
  }
  return true;
}

// X = L^{-1} of a lower-triangular (m, m) L with a positive diagonal (column by column forward substitution).
void dense_lower_inverse(const double *L, long m, double *X) {
  for (long e = 0; e < m * m; ++e) X[e] = 0.0;
  for (long j = 0; j < m; ++j) {
    X[j * m + j] = 1.0 / L[j * m + j];
    for (long i = j + 1; i < m; ++i) {
      double s = 0.0;
      for (long c = j; c < i; ++c) s += L[i * m + c] * X[c * m + j];
      X[i * m + j] = -s / L[i * m + i];
    }
  }
}

// Block IC(0) (no fill) over the bodies of a symmetric positive definite matrix M given by the Cholesky factors
// of its diagonal blocks (own, at diag_offsets, C_b C_b^T = M_bb) and its blocks M_ij of the pattern's pairs
// i < j (pair_i, pair_j, sorted by (i, j); (m_i, m_j) row-major at pair_offsets in pair_blocks), as
// noise_factor.incomplete_cholesky does in NumPy:
//   L_kk L_kk^T = M_kk - sum_l L_kl L_kl^T,  L_ik = (M_ik - sum_l L_il L_kl^T) L_kk^{-T},
// the sums over the l < k in both rows.  A row whose Schur complement is not positive definite keeps C_k and no
// lower blocks (zeros).  Returns (diag L_bb, diag_inverse L_bb^{-1}, row_ptr, cols, block_offsets, blocks,
// breakdowns) in the layout of block_lower_apply.
py::tuple incomplete_cholesky_blocks(const Index &starts, const Index &diag_offsets, const Array &own,
                                     const Index &pair_i, const Index &pair_j, const Index &pair_offsets,
                                     const Array &pair_blocks) {
  const long nb = static_cast<long>(starts.size()) - 1;
  if (nb < 0 || diag_offsets.size() != nb) throw std::invalid_argument("starts (nb + 1) and diag_offsets (nb) disagree");
  const long P = static_cast<long>(pair_i.size());
  if (pair_j.size() != P || pair_offsets.size() != P) throw std::invalid_argument("one i, j and offset per pair");
  const long long *st = starts.data(), *dof = diag_offsets.data(), *pi = pair_i.data(), *pj = pair_j.data(),
                  *po = pair_offsets.data();
  for (long b = 0; b < nb; ++b) {
    const long m = static_cast<long>(st[b + 1] - st[b]);
    if (m < 0 || dof[b] < 0 || dof[b] + m * m > own.size()) throw std::invalid_argument("a diagonal block runs past own");
  }
  for (long p = 0; p < P; ++p) {
    if (pi[p] < 0 || pj[p] >= nb || pi[p] >= pj[p]) throw std::invalid_argument("pairs must be 0 <= i < j < nb");
    if (p && (pi[p] < pi[p - 1] || (pi[p] == pi[p - 1] && pj[p] <= pj[p - 1])))
      throw std::invalid_argument("pairs must be sorted by (i, j) without repeats");
    const long mi = static_cast<long>(st[pi[p] + 1] - st[pi[p]]), mj = static_cast<long>(st[pj[p] + 1] - st[pj[p]]);
    if (po[p] < 0 || po[p] + mi * mj > pair_blocks.size()) throw std::invalid_argument("a pair block runs past pair_blocks");
  }
  // rows: the pairs (k, i) give block (i, k) of row i; cols sorted within a row
  std::vector<long long> row_ptr(static_cast<std::size_t>(nb + 1), 0);
  for (long p = 0; p < P; ++p) ++row_ptr[pj[p] + 1];
  for (long b = 0; b < nb; ++b) row_ptr[b + 1] += row_ptr[b];
  std::vector<long long> cols(static_cast<std::size_t>(P)), source(static_cast<std::size_t>(P)), fill(row_ptr);
  for (long p = 0; p < P; ++p) {  // pairs sorted by (i, j): within row j the columns i come in increasing order
    const long long slot = fill[pj[p]]++;
    cols[slot] = pi[p];
    source[slot] = p;
  }
  std::vector<long long> block_offsets(static_cast<std::size_t>(P)), diag_off(static_cast<std::size_t>(nb));
  long long position = 0, diag_size = 0;
  for (long i = 0; i < nb; ++i) {
    const long mi = static_cast<long>(st[i + 1] - st[i]);
    diag_off[i] = diag_size;
    diag_size += mi * mi;
    for (long long q = row_ptr[i]; q < row_ptr[i + 1]; ++q) {
      block_offsets[q] = position;
      position += mi * static_cast<long>(st[cols[q] + 1] - st[cols[q]]);
    }
  }
  Array diag(diag_size), diag_inv(diag_size), blocks(position);
  double *D = diag.mutable_data(), *Dinv = diag_inv.mutable_data(), *B = blocks.mutable_data();
  const double *C = own.data(), *PB = pair_blocks.data();
  // later[k]: the slots (row i > k, column k), in increasing i
  std::vector<std::vector<long long>> later(static_cast<std::size_t>(nb));
  for (long i = 0; i < nb; ++i)
    for (long long q = row_ptr[i]; q < row_ptr[i + 1]; ++q) later[cols[q]].push_back(q);
  std::vector<long long> row_of(static_cast<std::size_t>(P));
  for (long i = 0; i < nb; ++i)
    for (long long q = row_ptr[i]; q < row_ptr[i + 1]; ++q) row_of[q] = i;
  long breakdowns = 0;
  {
    py::gil_scoped_release release;
    long largest = 0;
    for (long b = 0; b < nb; ++b) largest = std::max(largest, static_cast<long>(st[b + 1] - st[b]));
    std::vector<double> S(static_cast<std::size_t>(largest * largest)), T(static_cast<std::size_t>(largest * largest));
    for (long k = 0; k < nb; ++k) {
      const long m = static_cast<long>(st[k + 1] - st[k]);
      const double *Ck = C + dof[k];
      double *Lk = D + diag_off[k], *Xk = Dinv + diag_off[k];
      bool own_factor = row_ptr[k] == row_ptr[k + 1];
      if (!own_factor) {  // S = C_k C_k^T - sum_l L_kl L_kl^T (lower triangle)
        for (long r = 0; r < m; ++r)
          for (long c = 0; c <= r; ++c) {
            double s = 0.0;
            for (long e = 0; e <= c; ++e) s += Ck[r * m + e] * Ck[c * m + e];
            S[r * m + c] = s;
          }
        for (long long q = row_ptr[k]; q < row_ptr[k + 1]; ++q) {
          const long ml = static_cast<long>(st[cols[q] + 1] - st[cols[q]]);
          const double *Lkl = B + block_offsets[q];
          for (long r = 0; r < m; ++r)
            for (long c = 0; c <= r; ++c) {
              double s = 0.0;
              for (long e = 0; e < ml; ++e) s += Lkl[r * ml + e] * Lkl[c * ml + e];
              S[r * m + c] -= s;
            }
        }
        if (!dense_cholesky(S.data(), m, Lk)) {
          own_factor = true;
          ++breakdowns;
          for (long long q = row_ptr[k]; q < row_ptr[k + 1]; ++q) {
            const long ml = static_cast<long>(st[cols[q] + 1] - st[cols[q]]);
            for (long e = 0; e < m * ml; ++e) B[block_offsets[q] + e] = 0.0;
          }
        }
      }
      if (own_factor)
        for (long e = 0; e < m * m; ++e) Lk[e] = Ck[e];
      dense_lower_inverse(Lk, m, Xk);
      for (long long q : later[k]) {  // block (i, k): T = M_ik - sum_l L_il L_kl^T; L_ik = T L_kk^{-T}
        const long i = static_cast<long>(row_of[q]);
        const long mi = static_cast<long>(st[i + 1] - st[i]);
        const double *Mki = PB + po[source[q]];  // (m, mi): M_ki, so M_ik = its transpose
        for (long r = 0; r < mi; ++r)
          for (long c = 0; c < m; ++c) T[r * m + c] = Mki[c * mi + r];
        long long a = row_ptr[i], b = row_ptr[k];
        while (a < row_ptr[i + 1] && b < row_ptr[k + 1] && cols[a] < k) {  // l in both rows, l < k
          if (cols[a] < cols[b]) {
            ++a;
          } else if (cols[b] < cols[a]) {
            ++b;
          } else {
            const long ml = static_cast<long>(st[cols[a] + 1] - st[cols[a]]);
            const double *Lil = B + block_offsets[a], *Lkl = B + block_offsets[b];
            for (long r = 0; r < mi; ++r)
              for (long c = 0; c < m; ++c) {
                double s = 0.0;
                for (long e = 0; e < ml; ++e) s += Lil[r * ml + e] * Lkl[c * ml + e];
                T[r * m + c] -= s;
              }
            ++a;
            ++b;
          }
        }
        double *Lik = B + block_offsets[q];
        for (long r = 0; r < mi; ++r)  // (T X^T)_rc = sum_e T_re X_ce, X lower triangular: e <= c
          for (long c = 0; c < m; ++c) {
            double s = 0.0;
            for (long e = 0; e <= c; ++e) s += T[r * m + e] * Xk[c * m + e];
            Lik[r * m + c] = s;
          }
      }
    }
  }
  Index row_ptr_out(nb + 1), cols_out(P), offsets_out(P);
  std::copy(row_ptr.begin(), row_ptr.end(), row_ptr_out.mutable_data());
  std::copy(cols.begin(), cols.end(), cols_out.mutable_data());
  std::copy(block_offsets.begin(), block_offsets.end(), offsets_out.mutable_data());
  return py::make_tuple(diag, diag_inv, row_ptr_out, cols_out, offsets_out, blocks, breakdowns);
}

}  // namespace

py::array_t<double> rigid_near_field(const Array &x, double a, double eta, bool wall, const Index &offsets,
                                     const Index &target_start, const Index &partners, const Array &shifts,
                                     const Array &forces) {
  if (x.ndim() != 2 || x.shape(1) != 3) throw std::invalid_argument("x must be (N, 3)");
  if (!(a > 0.0) || !(eta > 0.0)) throw std::invalid_argument("blob radius and viscosity must be positive");
  const long N = x.shape(0);
  if (forces.size() != 3 * N) throw std::invalid_argument("forces must be (N, 3)");
  const long B = offsets.size() - 1;
  if (B < 0 || target_start.size() != B + 1) throw std::invalid_argument("offsets and target_start: (Nb + 1,)");
  const long long *off = offsets.data(), *start = target_start.data(), *partner = partners.data();
  const long Q = partners.size();
  if (off[0] != 0 || off[B] != N || start[0] != 0 || start[B] != Q || shifts.size() != 3 * Q)
    throw std::invalid_argument("offsets must span the blobs, target_start the partners; shifts (Q, 3)");
  for (long b = 0; b < B; ++b)
    if (off[b + 1] < off[b] || start[b + 1] < start[b]) throw std::invalid_argument("offsets must not decrease");
  for (long q = 0; q < Q; ++q)
    if (partner[q] < 0 || partner[q] >= B) throw std::invalid_argument("partners must be body indices");
  if (wall)
    for (long q = 0; q < Q; ++q)
      if (shifts.data()[3 * q + 2] != 0.0) throw std::invalid_argument("with a wall the shifts must be in x and y");
  // positions in units of a (heights raised to a above a wall) and damped forces, as the backends' blobs
  std::vector<double> X(N), Y(N), Z(N), damping(N, 1.0), F(3 * N), S(3 * Q);
  const double *xp = x.data(), *fp = forces.data(), inv_a = 1.0 / a;
  for (long i = 0; i < N; ++i) {
    double z = xp[3 * i + 2];
    if (wall) rmb::wall_regularisation(xp[3 * i + 2], a, z, damping[i]);
    X[i] = xp[3 * i] * inv_a, Y[i] = xp[3 * i + 1] * inv_a, Z[i] = z * inv_a;
    for (int k = 0; k < 3; ++k) F[3 * i + k] = fp[3 * i + k] * damping[i];
  }
  for (long k = 0; k < 3 * Q; ++k) S[k] = shifts.data()[k] * inv_a;
  py::array_t<double> out({N, 3L});
  double *o = out.mutable_data();
  const double factor = 1.0 / (8.0 * M_PI * eta * a);
  {
    py::gil_scoped_release release;
    if (wall)
      RMB_SIMD_DISPATCH(near_field_loop<true>(B, X.data(), Y.data(), Z.data(), damping.data(), F.data(), off, start,
                                              partner, S.data(), factor, o));
    else
      RMB_SIMD_DISPATCH(near_field_loop<false>(B, X.data(), Y.data(), Z.data(), damping.data(), F.data(), off, start,
                                               partner, S.data(), factor, o));
  }
  return out;
}

PYBIND11_MODULE(_preconditioner_cpp, m) {
  m.doc() = "Per-body dense blocks of the block-diagonal preconditioner (multi_bodies/solver/cpp)";
  try {
    rmb_simd::chosen();  // RMB_SIMD naming a path that cannot run here stops the import with its one line
  } catch (const std::invalid_argument &err) {
    throw py::import_error(err.what());
  }
  m.def("simd_path", []() { return std::string(rmb_simd::path_name(rmb_simd::chosen())); },
        "The vector path of the near-field loop (mobility/cpp/simd_dispatch.h).");
  m.def("block_product", &block_product, py::arg("blocks"), py::arg("x"), py::arg("out"), py::arg("start"),
        py::arg("transpose") = false, py::arg("lower") = false,
        "out[start + k m : start + (k + 1) m] = B_k x[...] (B_k^T with transpose; lower: read the lower triangle)");
  m.def("rigid_near_field", &rigid_near_field, py::arg("x"), py::arg("a"), py::arg("eta"), py::arg("wall"),
        py::arg("offsets"), py::arg("target_start"), py::arg("partners"), py::arg("shifts"), py::arg("forces"),
        "Blob velocities (N, 3) of the neighbour pairs' mobility (each pair listed once, under its first body) "
        "applied to forces (N, 3), from the positions");
  m.def("pair_product", &pair_product, py::arg("O"), py::arg("first"), py::arg("second"), py::arg("x"),
        py::arg("out"), "out[i_p:] += O_p x[j_p:], out[j_p:] += O_p^T x[i_p:] for every pair p (added to out).");
  m.def("saddle_block_inverse", &saddle_block_inverse, py::arg("M_inv"), py::arg("M_inv_K"), py::arg("K"),
        py::arg("N"), py::arg("x"), py::arg("out"), py::arg("blob_start"), py::arg("body_start"),
        "Each body's exact saddle-point inverse applied to [s; f] of x, written into out");
  m.def("lower_triangular_inverse", &lower_triangular_inverse, py::arg("blocks"),
        "L^{-1} (nb, m, m) of lower-triangular blocks with a positive diagonal");
  m.def("block_lower_apply", &block_lower_apply, py::arg("mode"), py::arg("starts"), py::arg("diag_offsets"),
        py::arg("diag"), py::arg("row_ptr"), py::arg("cols"), py::arg("block_offsets"), py::arg("blocks"), py::arg("x"),
        py::arg("out"), "A block lower-triangular L over the bodies applied to x: mode 0 L x, 1 L^-1 x, 2 L^-T x");
  m.def("incomplete_cholesky_blocks", &incomplete_cholesky_blocks, py::arg("starts"), py::arg("diag_offsets"),
        py::arg("own"), py::arg("pair_i"), py::arg("pair_j"), py::arg("pair_offsets"), py::arg("pair_blocks"),
        "Block IC(0) over the bodies: (diag, diag_inverse, row_ptr, cols, block_offsets, blocks, breakdowns)");
}
