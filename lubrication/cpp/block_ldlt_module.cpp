// Sparse LDL^T of a symmetric matrix made of small dense blocks (pybind11 module lubrication._block_ldlt_cpp).
//
// What it is for: the lubrication preconditioner factors R_sup + s I (6 x 6 blocks, one block row per
// sphere, a block per neighbour pair) twice per trapezoidal step, and the torque preconditioner
// Delta_R_tt + 6 pi eta a I (3 x 3 blocks).  SciPy's SuperLU factors them as general matrices (L and U,
// scalar graph); this factors only L (half the arithmetic), orders and does the symbolic work on the
// graph of blocks (36 times smaller), and runs dense B x B kernels that the compiler unrolls.
//
// Method (textbook sparse direct methods: George and Liu, "Computer Solution of Large Sparse Positive
// Definite Systems", 1981; Davis, "Direct Methods for Sparse Linear Systems", SIAM 2006):
//   1. Ordering: minimum degree on the graph of blocks (the elimination graph kept explicitly; ties go to
//      the lowest index, so the ordering is deterministic).  Eliminating a block-node v joins its remaining
//      neighbours into a clique; those neighbours are also the block rows of column v of L, so the ordering
//      gives the symbolic factorisation directly.
//   2. Numeric: left-looking block LDL^T without pivoting, P A P^T = L D L^T, L unit lower triangular
//      (B x B diagonal blocks unit lower, dense B x B off-diagonal blocks), D diagonal.  Column k gathers the
//      updates L_ij D_j L_kj^T of the earlier columns j whose structure holds k, then factors its diagonal
//      block (scalar LDL^T without pivoting, as SuperLU in symmetric mode with diag_pivot_thresh = 0) and
//      scales its off-diagonal blocks.  A zero (or non-finite) pivot stops it (ValueError); a negative one is
//      allowed (the matrix is then indefinite: positive_definite is False).
//   3. Solves: permute, forward with L, divide by D, backward with L^T, permute back.
// The symbolic part (ordering, structure, where each input entry goes) is reused when the scalar pattern of the
// next input is the same (the `previous` factor of factorise()); the ordering and structure alone when only its
// block graph is the same (the usual case from step to step: the neighbour pairs stay while exact zeros come and
// go in the scalar pattern).
// Only the lower triangle (in the permuted order) of the input is read: the input must be symmetric.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <memory>
#include <queue>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace py = pybind11;
using Array = py::array_t<double, py::array::c_style | py::array::forcecast>;
using IndexArray = py::array_t<std::int64_t, py::array::c_style | py::array::forcecast>;

namespace {

// The symbolic factorisation of a block pattern: ordering, the block structure of L, and where each input
// entry lands in L's storage.
struct Symbolic {
  long nb = 0;                     // block rows
  std::vector<long> perm, iperm;   // perm[k]: original block eliminated k-th; iperm its inverse
  std::vector<long> colptr;        // (nb + 1) off-diagonal blocks of column k: colptr[k] .. colptr[k + 1]
  std::vector<long> rowidx;        // their (permuted) block rows, ascending, all > k
  std::vector<long> rowptr, rowcol, rowpos;  // for each row k: the columns j < k holding it and its position
  std::vector<long> target;        // for each input entry: its offset in L's storage (diagonal blocks first), -1
  std::vector<std::int64_t> indptr, indices;  // the input's scalar pattern (to reuse this symbolic part)
  std::vector<long> graph_ptr, graph_idx;     // the block graph ordered (to reuse the ordering on another pattern)
};

// The block graph of a CSR pattern of B x B blocks, symmetrised (a block present in either triangle), without
// self loops: CSR lists (ptr (nb + 1), idx), each ascending.
void block_graph(long n, int B, const std::int64_t *indptr, const std::int64_t *indices, std::vector<long> &ptr,
                 std::vector<long> &idx) {
  const long nb = n / B;
  std::vector<std::vector<long>> adj(nb);
  std::vector<long> mark(nb, -1);  // mark[J] == I: J is already in the list of I
  for (long I = 0; I < nb; ++I)
    for (long r = I * B; r < (I + 1) * B; ++r)
      for (std::int64_t e = indptr[r]; e < indptr[r + 1]; ++e) {
        const long J = static_cast<long>(indices[e]) / B;
        if (J != I && mark[J] != I) mark[J] = I, adj[I].push_back(J);
      }
  std::vector<std::size_t> own(nb);  // the blocks of row I's own pattern are adj[I][0 .. own[I])
  for (long I = 0; I < nb; ++I) own[I] = adj[I].size();
  for (long I = 0; I < nb; ++I)  // (I, J) stored: J gets I (a repeat where its own pattern holds it: dropped below)
    for (std::size_t q = 0; q < own[I]; ++q) adj[adj[I][q]].push_back(I);
  std::fill(mark.begin(), mark.end(), -1);
  ptr.assign(nb + 1, 0);
  idx.clear();
  for (long I = 0; I < nb; ++I) {
    for (long J : adj[I])
      if (mark[J] != I) mark[J] = I, idx.push_back(J);
    std::sort(idx.begin() + ptr[I], idx.end());
    ptr[I + 1] = static_cast<long>(idx.size());
  }
}

// Minimum degree on the block graph adj (lists without self loops): (perm, structures by original node).
// Eliminating v joins its remaining neighbours (its front) into a clique: each neighbour u gains the front's other
// nodes it does not hold yet (found with a mark per node) and loses v.  The lists stay unsorted; the degrees, and
// so the ordering, do not depend on their order.
void minimum_degree(std::vector<std::vector<long>> adj, std::vector<long> &perm,
                    std::vector<std::vector<long>> &structure) {
  const long nb = static_cast<long>(adj.size());
  std::vector<char> eliminated(nb, 0);
  std::vector<long> mark(nb, -1);  // mark[w] == u: w is in adj[u] (for the neighbour u being updated)
  using Entry = std::pair<long, long>;  // (degree, node): the lowest degree, then the lowest node, first
  std::priority_queue<Entry, std::vector<Entry>, std::greater<Entry>> queue;
  for (long v = 0; v < nb; ++v) queue.push({static_cast<long>(adj[v].size()), v});
  perm.clear();
  structure.assign(nb, {});
  while (!queue.empty()) {
    const auto [degree, v] = queue.top();
    queue.pop();
    if (eliminated[v] || degree != static_cast<long>(adj[v].size())) continue;  // stale entry
    eliminated[v] = 1;
    perm.push_back(v);
    std::vector<long> &front = adj[v];
    for (long u : front) {
      // adj[u] <- (adj[u] union front) minus {u, v}
      std::vector<long> &list = adj[u];
      for (std::size_t i = 0; i < list.size();) {  // drop v, mark the others
        if (list[i] == v) {
          list[i] = list.back();
          list.pop_back();
        } else {
          mark[list[i++]] = u;
        }
      }
      for (long w : front)
        if (w != u && mark[w] != u) list.push_back(w);
      queue.push({static_cast<long>(list.size()), u});
    }
    // marks hold node ids: a later update of u re-marks its whole list, so no reset is needed
    structure[v].swap(front);
  }
}

// The ordering and the block structure of L from the block graph (graph_ptr, graph_idx), written into s.
void order(Symbolic *s, long nb, std::vector<long> graph_ptr, std::vector<long> graph_idx) {
  s->nb = nb;
  std::vector<std::vector<long>> adj(nb);
  for (long I = 0; I < nb; ++I) adj[I].assign(graph_idx.begin() + graph_ptr[I], graph_idx.begin() + graph_ptr[I + 1]);
  s->graph_ptr.swap(graph_ptr);
  s->graph_idx.swap(graph_idx);
  std::vector<std::vector<long>> structure;
  minimum_degree(std::move(adj), s->perm, structure);
  s->iperm.assign(nb, 0);
  for (long k = 0; k < nb; ++k) s->iperm[s->perm[k]] = k;
  s->colptr.assign(nb + 1, 0);
  for (long k = 0; k < nb; ++k) s->colptr[k + 1] = s->colptr[k] + static_cast<long>(structure[s->perm[k]].size());
  s->rowidx.resize(s->colptr[nb]);
  for (long k = 0; k < nb; ++k) {
    long *rows = &s->rowidx[s->colptr[k]];
    long count = 0;
    for (long u : structure[s->perm[k]]) rows[count++] = s->iperm[u];
    std::sort(rows, rows + count);
  }
  // row lists: for each row i, the columns j < i with i in their structure (ascending j) and the position
  s->rowptr.assign(nb + 1, 0);
  for (long p = 0; p < s->colptr[nb]; ++p) ++s->rowptr[s->rowidx[p] + 1];
  for (long k = 0; k < nb; ++k) s->rowptr[k + 1] += s->rowptr[k];
  s->rowcol.resize(s->colptr[nb]);
  s->rowpos.resize(s->colptr[nb]);
  std::vector<long> next(s->rowptr.begin(), s->rowptr.end() - 1);
  for (long j = 0; j < nb; ++j)
    for (long p = s->colptr[j]; p < s->colptr[j + 1]; ++p) {
      const long q = next[s->rowidx[p]]++;
      s->rowcol[q] = j, s->rowpos[q] = p;
    }
}

// Where each input entry of the scalar pattern (indptr, indices) goes in L's storage, for the ordering of s: the
// diagonal block of column k at k * B * B, the off-diagonal block at position p at (nb + p) * B * B; entries above
// the diagonal (in the permuted order) are not read.
void map_entries(Symbolic *s, long n, int B, const std::int64_t *indptr, const std::int64_t *indices) {
  const long nb = s->nb;
  s->indptr.assign(indptr, indptr + n + 1);
  s->indices.assign(indices, indices + indptr[n]);
  s->target.assign(indptr[n], -1);
  std::vector<long> position(nb, -1);  // position[j]: where block (k, j) of L is, for the block row k at hand
  for (long I = 0; I < nb; ++I) {
    const long k = s->iperm[I];  // rows of block I are rows of L's block row k; the column is J's
    for (long q = s->rowptr[k]; q < s->rowptr[k + 1]; ++q) position[s->rowcol[q]] = s->rowpos[q];
    for (int a = 0; a < B; ++a) {
      const long r = I * B + a;
      for (std::int64_t e = indptr[r]; e < indptr[r + 1]; ++e) {
        const long c = static_cast<long>(indices[e]), J = c / B, b = c % B, j = s->iperm[J];
        if (j > k) continue;  // upper triangle
        if (j == k) {
          if (b <= a) s->target[e] = (k * B + a) * B + b;
          continue;
        }
        // block (k, j) of L (in the structure of column j: I and J are neighbours and J is eliminated first)
        s->target[e] = ((nb + position[j]) * B + a) * B + b;
      }
    }
    for (long q = s->rowptr[k]; q < s->rowptr[k + 1]; ++q) position[s->rowcol[q]] = -1;
  }
}

// The symbolic part for the pattern (indptr, indices) of n x n with B x B blocks: the ordering of `previous`
// (a symbolic part of any block size, or null) when its block graph is this pattern's (then *reused is set), else a
// new one.
std::shared_ptr<Symbolic> analyse(long n, int B, const std::int64_t *indptr, const std::int64_t *indices,
                                  const Symbolic *previous, bool *reused) {
  std::vector<long> graph_ptr, graph_idx;
  block_graph(n, B, indptr, indices, graph_ptr, graph_idx);
  std::shared_ptr<Symbolic> s;
  if (previous != nullptr && previous->graph_ptr == graph_ptr && previous->graph_idx == graph_idx) {
    s = std::make_shared<Symbolic>(*previous);  // its ordering and structure (the copy is O(blocks of L))
    *reused = true;
  } else {
    s = std::make_shared<Symbolic>();
    order(s.get(), n / B, std::move(graph_ptr), std::move(graph_idx));
  }
  map_entries(s.get(), n, B, indptr, indices);
  return s;
}

bool same_pattern(const Symbolic &s, long n, const std::int64_t *indptr, const std::int64_t *indices) {
  if (static_cast<long>(s.indptr.size()) != n + 1) return false;
  if (!std::equal(s.indptr.begin(), s.indptr.end(), indptr)) return false;
  return std::equal(s.indices.begin(), s.indices.end(), indices);
}

// a NumPy array holding a copy of `values` (typed, also when empty)
template <typename T>
py::array_t<T> copied(const std::vector<T> &values) {
  py::array_t<T> out(static_cast<py::ssize_t>(values.size()));
  std::copy(values.begin(), values.end(), out.mutable_data());
  return out;
}

template <int B>
struct Kernels {
  // target -= X Y (B x B row-major each); the innermost loop runs along rows of Y and target (contiguous, no
  // reduction), so the compiler vectorises it
  static inline void subtract_product(double *__restrict target, const double *__restrict X,
                                      const double *__restrict Y) {
    for (int a = 0; a < B; ++a)
      for (int m = 0; m < B; ++m) {
        const double x = X[a * B + m];
        for (int b = 0; b < B; ++b) target[a * B + b] -= x * Y[m * B + b];
      }
  }
};

class BlockLDLT {
 public:
  BlockLDLT(long n, int B, std::shared_ptr<Symbolic> symbolic) : n_(n), B_(B), s_(std::move(symbolic)) {}

  // the numeric factorisation of the input (same pattern as the symbolic part) plus shift on the diagonal
  void factor(const double *data, double shift) {
    const long nb = s_->nb, BB = static_cast<long>(B_) * B_;
    values_.assign((nb + s_->colptr[nb]) * BB, 0.0);
    d_.assign(n_, 0.0);
    const long entries = static_cast<long>(s_->target.size());
    for (long e = 0; e < entries; ++e)
      if (s_->target[e] >= 0) values_[s_->target[e]] += data[e];
    // the shift on every diagonal entry: entry a of every diagonal block (whichever original block it holds)
    for (long k = 0; k < nb; ++k)
      for (int a = 0; a < B_; ++a) values_[k * BB + a * B_ + a] += shift;
    switch (B_) {
      case 1: numeric<1>(); break;
      case 2: numeric<2>(); break;
      case 3: numeric<3>(); break;
      case 6: numeric<6>(); break;
      default: throw std::invalid_argument("block size must be 1, 2, 3 or 6");
    }
    positive_ = std::all_of(d_.begin(), d_.end(), [](double x) { return x > 0.0; });
  }

  py::array_t<double> solve(const Array &b) const {
    if (static_cast<long>(d_.size()) != n_) throw std::invalid_argument("this factor holds an ordering only");
    if (b.ndim() < 1 || b.ndim() > 2 || b.shape(0) != n_)
      throw std::invalid_argument("right-hand side must be (n,) or (n, k) with n = " + std::to_string(n_));
    const long columns = b.ndim() == 2 ? b.shape(1) : 1;
    py::array_t<double> x(b.ndim() == 2 ? std::vector<py::ssize_t>{n_, columns} : std::vector<py::ssize_t>{n_});
    const double *in = b.data();
    double *out = x.mutable_data();
    {
      py::gil_scoped_release release;
      std::vector<double> y(n_);
      for (long c = 0; c < columns; ++c) {
        for (long i = 0; i < n_; ++i) y[i] = in[i * columns + c];
        solve_in_place(y.data());
        for (long i = 0; i < n_; ++i) out[i * columns + c] = y[i];
      }
    }
    return x;
  }

  // (perm (n,), CSR triple of the unit lower triangular L (n x n, permuted order), d (n,)):
  // A[perm[k], perm[l]] = (L D L^T)[k, l]
  py::tuple factors() const {
    if (static_cast<long>(d_.size()) != n_) throw std::invalid_argument("this factor holds an ordering only");
    const long nb = s_->nb, BB = static_cast<long>(B_) * B_;
    py::array_t<std::int64_t> perm(n_);
    for (long k = 0; k < nb; ++k)
      for (int a = 0; a < B_; ++a) perm.mutable_data()[k * B_ + a] = s_->perm[k] * B_ + a;
    // row k*B + a of L: the blocks (k, j) for j < k (row lists), then the diagonal block's row a
    std::vector<std::int64_t> indptr(n_ + 1, 0), indices;
    std::vector<double> data;
    for (long k = 0; k < nb; ++k)
      for (int a = 0; a < B_; ++a) {
        for (long q = s_->rowptr[k]; q < s_->rowptr[k + 1]; ++q) {
          const long j = s_->rowcol[q], p = s_->rowpos[q];
          for (int b = 0; b < B_; ++b)
            if (values_[((nb + p) * B_ + a) * B_ + b] != 0.0)
              indices.push_back(j * B_ + b), data.push_back(values_[((nb + p) * B_ + a) * B_ + b]);
        }
        for (int b = 0; b < a; ++b)
          if (values_[k * BB + a * B_ + b] != 0.0)
            indices.push_back(k * B_ + b), data.push_back(values_[k * BB + a * B_ + b]);
        indices.push_back(k * B_ + a), data.push_back(1.0);
        indptr[k * B_ + a + 1] = static_cast<std::int64_t>(indices.size());
      }
    return py::make_tuple(perm, py::make_tuple(copied(data), copied(indices), copied(indptr)), copied(d_));
  }

  bool positive_definite() const { return positive_; }
  bool ordering_reused() const { return ordering_reused_; }
  void set_ordering_reused(bool reused) { ordering_reused_ = reused; }
  long nonzero_blocks() const { return s_->nb + s_->colptr[s_->nb]; }
  long size() const { return n_; }
  int block_size() const { return B_; }
  std::shared_ptr<Symbolic> symbolic() const { return s_; }
  // a factor holding this one's symbolic part only (to offer its ordering to a later factorisation)
  std::unique_ptr<BlockLDLT> ordering_only() const { return std::make_unique<BlockLDLT>(n_, B_, s_); }

 private:
  template <int BS>
  void numeric() {
    constexpr long BB = static_cast<long>(BS) * BS;
    const long nb = s_->nb;
    const long *colptr = s_->colptr.data(), *rowidx = s_->rowidx.data();
    double *diag = values_.data(), *off = values_.data() + nb * BB, *d = d_.data();
    std::vector<long> slot(nb, -1);  // slot[i]: the offset of block (i, k) of the current column k
    double T[BB];
    for (long k = 0; k < nb; ++k) {
      for (long p = colptr[k]; p < colptr[k + 1]; ++p) slot[rowidx[p]] = p * BB;
      double *Dk = diag + k * BB;
      // updates from the columns j < k that hold row k: target(i, k) -= L_ij D_j L_kj^T, i >= k in column j
      for (long q = s_->rowptr[k]; q < s_->rowptr[k + 1]; ++q) {
        const long j = s_->rowcol[q], p = s_->rowpos[q];
        const double *Lkj = off + p * BB, *dj = d + j * BS;
        for (int a = 0; a < BS; ++a)  // T = D_j L_kj^T
          for (int m = 0; m < BS; ++m) T[m * BS + a] = Lkj[a * BS + m] * dj[m];
        Kernels<BS>::subtract_product(Dk, Lkj, T);
        for (long r = p + 1; r < colptr[j + 1]; ++r)
          Kernels<BS>::subtract_product(off + slot[rowidx[r]], off + r * BB, T);
      }
      // the diagonal block: scalar LDL^T without pivoting (lower triangle read; unit L stored below the diagonal)
      double *dk = d + k * BS;
      for (int c = 0; c < BS; ++c) {
        double pivot = Dk[c * BS + c];
        for (int m = 0; m < c; ++m) pivot -= Dk[c * BS + m] * Dk[c * BS + m] * dk[m];
        if (!(pivot != 0.0) || !std::isfinite(pivot))
          throw std::domain_error("zero or non-finite pivot at row " + std::to_string(s_->perm[k] * BS + c) +
                                  ": the matrix is singular or not symmetric positive definite");
        dk[c] = pivot;
        for (int r = c + 1; r < BS; ++r) {
          double v = Dk[r * BS + c];
          for (int m = 0; m < c; ++m) v -= Dk[r * BS + m] * Dk[c * BS + m] * dk[m];
          Dk[r * BS + c] = v / pivot;
        }
      }
      // off-diagonal blocks: L_ik = W_ik L_kk^-T D_k^-1, row by row
      for (long p = colptr[k]; p < colptr[k + 1]; ++p) {
        double *W = off + p * BB;
        for (int a = 0; a < BS; ++a) {
          double *row = W + a * BS;
          for (int c = 0; c < BS; ++c) {
            double v = row[c];
            for (int m = 0; m < c; ++m) v -= Dk[c * BS + m] * row[m];
            row[c] = v;
          }
          for (int c = 0; c < BS; ++c) row[c] /= dk[c];
        }
      }
      for (long p = colptr[k]; p < colptr[k + 1]; ++p) slot[rowidx[p]] = -1;
    }
  }

  void solve_in_place(double *x) const {
    switch (B_) {
      case 1: solve_blocks<1>(x); break;
      case 2: solve_blocks<2>(x); break;
      case 3: solve_blocks<3>(x); break;
      case 6: solve_blocks<6>(x); break;
      default: break;
    }
  }

  template <int BS>
  void solve_blocks(double *x) const {
    constexpr long BB = static_cast<long>(BS) * BS;
    const long nb = s_->nb;
    const long *colptr = s_->colptr.data(), *rowidx = s_->rowidx.data(), *perm = s_->perm.data();
    const double *diag = values_.data(), *off = values_.data() + nb * BB, *d = d_.data();
    std::vector<double> y(n_);
    for (long k = 0; k < nb; ++k)
      for (int a = 0; a < BS; ++a) y[k * BS + a] = x[perm[k] * BS + a];
    for (long k = 0; k < nb; ++k) {  // L y = P b
      double *yk = &y[k * BS];
      const double *Lkk = diag + k * BB;
      for (int a = 1; a < BS; ++a)
        for (int m = 0; m < a; ++m) yk[a] -= Lkk[a * BS + m] * yk[m];
      for (long p = colptr[k]; p < colptr[k + 1]; ++p) {
        const double *Lik = off + p * BB;
        double *yi = &y[rowidx[p] * BS];
        for (int a = 0; a < BS; ++a) {
          double sum = 0.0;
          for (int m = 0; m < BS; ++m) sum += Lik[a * BS + m] * yk[m];
          yi[a] -= sum;
        }
      }
    }
    for (long i = 0; i < n_; ++i) y[i] /= d[i];
    for (long k = nb - 1; k >= 0; --k) {  // L^T x = y
      double *yk = &y[k * BS];
      for (long p = colptr[k]; p < colptr[k + 1]; ++p) {
        const double *Lik = off + p * BB, *yi = &y[rowidx[p] * BS];
        for (int m = 0; m < BS; ++m) {
          double sum = 0.0;
          for (int a = 0; a < BS; ++a) sum += Lik[a * BS + m] * yi[a];
          yk[m] -= sum;
        }
      }
      const double *Lkk = diag + k * BB;
      for (int a = BS - 2; a >= 0; --a)
        for (int m = a + 1; m < BS; ++m) yk[a] -= Lkk[m * BS + a] * yk[m];
    }
    for (long k = 0; k < nb; ++k)
      for (int a = 0; a < BS; ++a) x[perm[k] * BS + a] = y[k * BS + a];
  }

  long n_;
  int B_;
  std::shared_ptr<Symbolic> s_;
  std::vector<double> values_, d_;
  bool positive_ = false;
  bool ordering_reused_ = false;  // the ordering came from `previous` (same pattern or same block graph)
};

// Factor the symmetric CSR matrix (indptr, indices, data) of size n, made of B x B blocks, plus shift I;
// the symbolic part of `previous` is reused when it has the same block size and scalar pattern.
std::unique_ptr<BlockLDLT> factorise(const IndexArray &indptr, const IndexArray &indices, const Array &data, long n,
                                     int block, double shift, const BlockLDLT *previous) {
  if (block < 1 || n < 0 || n % block != 0)
    throw std::invalid_argument("the size n = " + std::to_string(n) + " must be a multiple of the block size " +
                                std::to_string(block));
  if (indptr.ndim() != 1 || indptr.size() != n + 1) throw std::invalid_argument("indptr must have n + 1 entries");
  if (!std::isfinite(shift)) throw std::invalid_argument("the shift must be a finite number");
  const std::int64_t *ip = indptr.data(), *ix = indices.data();
  if (ip[0] != 0) throw std::invalid_argument("indptr must start at 0");
  for (long r = 0; r < n; ++r)
    if (ip[r + 1] < ip[r]) throw std::invalid_argument("indptr must not decrease (row " + std::to_string(r) + ")");
  const std::int64_t nnz = ip[n];
  if (indices.size() < nnz || data.size() < nnz) throw std::invalid_argument("indices and data shorter than indptr[n]");
  const double *values = data.data();
  for (std::int64_t e = 0; e < nnz; ++e) {
    if (ix[e] < 0 || ix[e] >= n) throw std::invalid_argument("column index out of range");
    if (!std::isfinite(values[e]))
      throw std::domain_error("non-finite entry (" + std::to_string(e) + "-th stored value): nothing to factor");
  }
  std::shared_ptr<Symbolic> symbolic;
  bool reused = false;
  {
    py::gil_scoped_release release;
    if (previous != nullptr && previous->block_size() == block && same_pattern(*previous->symbolic(), n, ip, ix))
      symbolic = previous->symbolic(), reused = true;
    else
      symbolic = analyse(n, block, ip, ix, previous != nullptr ? previous->symbolic().get() : nullptr, &reused);
  }
  auto factor = std::make_unique<BlockLDLT>(n, block, symbolic);
  factor->set_ordering_reused(reused);
  {
    py::gil_scoped_release release;
    factor->factor(data.data(), shift);
  }
  return factor;
}

}  // namespace

PYBIND11_MODULE(_block_ldlt_cpp, module) {
  module.doc() = "Sparse block LDL^T (minimum-degree ordering on blocks, left-looking): lubrication/sparse_factor.py";
  py::register_exception<std::domain_error>(module, "PivotError", PyExc_ValueError);
  py::class_<BlockLDLT>(module, "BlockLDLT")
      .def("solve", &BlockLDLT::solve, "x with A x = b for b (n,) or (n, k)", py::arg("b"))
      .def("factors", &BlockLDLT::factors, "(perm (n,), L as a CSR triple, d (n,)): A[perm][:, perm] = L D L^T")
      .def("ordering_only", &BlockLDLT::ordering_only,
           "a factor with this one's ordering and structure and no values (factorise's `previous`)")
      .def_property_readonly("positive_definite", &BlockLDLT::positive_definite)
      .def_property_readonly("ordering_reused", &BlockLDLT::ordering_reused)
      .def_property_readonly("nonzero_blocks", &BlockLDLT::nonzero_blocks)
      .def_property_readonly("size", &BlockLDLT::size)
      .def_property_readonly("block_size", &BlockLDLT::block_size);
  module.def(
      "factorise",
      [](const IndexArray &indptr, const IndexArray &indices, const Array &data, long n, int block, double shift,
         const BlockLDLT *previous) { return factorise(indptr, indices, data, n, block, shift, previous); },
      "P (A + shift I) P^T = L D L^T of the symmetric CSR matrix A (n x n, B x B blocks)", py::arg("indptr"),
      py::arg("indices"), py::arg("data"), py::arg("n"), py::arg("block"), py::arg("shift") = 0.0,
      py::arg("previous") = nullptr);
}
