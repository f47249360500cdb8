// Near-field resistance blocks and their sparse assembly (pybind11 module lubrication._lubrication_cpp).
//
// The same formulas as lubrication/resistance.py and lubrication/assembly.py (the NumPy reference and
// fallback, which cite the method: Sprinkle, van der Wee, Luo, Driscoll and Donev, Soft Matter 16, 7982,
// 2020; Townsend 2018 for the near-contact forms; Cox and Brenner 1967, Goldman, Cox and Brenner 1967
// for the wall forms), written pair by pair instead of over arrays of pairs: the NumPy version spends most
// of its time building (P, 12, 12) temporaries and scattering 6 x 6 blocks.  Tests check both equal.
//
// Units: r = centre distance / a, h = height / a; factors (f0, f1, f2) = (6 pi eta a, 6 pi eta a^2,
// 6 pi eta a^3) multiply the A, B, C parts.  A pair block (12 x 12, row-major) maps [U1 W1 U2 W2] to
// [F1 T1 F2 T2] with r_hat from sphere 1 to sphere 2; a wall block (6 x 6) maps [U W] to [F T].
// Tables as lubrication/tables.py gives them: x (n,) ascending and values (n, k) row-major, k = 10 for the
// pair tables (self scalars then pair scalars) and 5 for the wall tables.
// handover: 0 published switches, 1 smooth (the C1 blends of resistance.SMOOTH_WINDOWS, passed in).
// No OpenMP: 4096 spheres (17,000 pairs) take about 0.1 s on one core, under 1 % of a trapezoidal step
// (whose far-field products are O(N^2)), and two threads measured no faster on the shared machine.
// The per-sphere diagonal sums run in one fixed order, so the matrices are exactly symmetric.  CSR
// indices are int32 (what SciPy's SuperLU takes without a copy).
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

namespace py = pybind11;
using Array = py::array_t<double, py::array::c_style | py::array::forcecast>;
using IndexArray = py::array_t<std::int64_t, py::array::c_style | py::array::forcecast>;

namespace {

// A table read in place from the arrays of lubrication.compiled._tables (kept alive by the Array handles; the
// call that makes the Model holds them, so the data outlive the computation, GIL released or not): no copy per
// assembly.
struct Table {
  Array x_array, values_array;
  const double *x = nullptr, *values = nullptr;
  long size = 0, k = 0;
  long n() const { return size; }
};

Table make_table(const Array &x, const Array &values, long k, const char *name) {
  if (x.ndim() != 1 || values.ndim() != 2 || values.shape(0) != x.shape(0) || values.shape(1) != k || x.shape(0) < 2)
    throw std::invalid_argument(std::string("table ") + name + ": x must be (n,) and values (n, " +
                                std::to_string(k) + ") with n >= 2");
  Table t;
  t.k = k;
  t.size = static_cast<long>(x.shape(0));
  t.x_array = x, t.values_array = values;
  t.x = t.x_array.data(), t.values = t.values_array.data();
  return t;
}

// Linear interpolation, the published rule (tables.interpolate): at or below x[0] the first row, beyond
// x[-1] the last row (above = true), else y_L + (y_R - y_L) / (x_R - x_L) * (p - x_L), x_L < p <= x_R.
bool interpolate(const Table &t, double p, double *out) {
  const long n = t.n();
  const long upper = std::lower_bound(t.x, t.x + n, p) - t.x;
  if (upper == 0 || upper == n) {
    const double *row = &t.values[(upper == 0 ? 0 : n - 1) * t.k];
    for (long c = 0; c < t.k; ++c) out[c] = row[c];
    return upper == n;
  }
  const long left = upper - 1;
  const double xL = t.x[left], xR = t.x[left + 1];
  const double *yL = &t.values[left * t.k], *yR = &t.values[(left + 1) * t.k];
  for (long c = 0; c < t.k; ++c) {
    const double slope = (yR[c] - yL[c]) / (xR - xL);
    out[c] = yL[c] + slope * (p - xL);
  }
  return false;
}

struct Model {
  Table JO, WS, MB, wall_sup, wall_MB;
  double f0, f1, f2, firm_delta;
  int handover;  // 0 published, 1 smooth
  std::array<double, 8> windows;  // near_contact, mobility_table, wall_near, wall_far (lo, hi each)
  double cutoff_window;
};

double clamp_gap(double d, double contact, double firm_delta) {
  return d - contact < firm_delta ? firm_delta + contact : d;
}

double smooth_weight(double x, double lo, double hi) {
  double t = (x - lo) / (hi - lo);
  t = std::min(std::max(t, 0.0), 1.0);
  return t * t * (3.0 - 2.0 * t);
}

// Near-contact scalars (resistance.near_contact_scalars): s[0..4] self, s[5..9] pair.
void near_contact(double r, double *s) {
  const double eps = r - 2.0, log_inv = std::log(1.0 / eps), eps_log = eps * log_inv;
  s[0] = 0.995419 + 0.25 / eps + 0.225 * log_inv + 0.0267857 * eps_log;
  s[1] = 0.998317 + 0.166667 * log_inv;
  s[2] = -0.666667 * (0.23892 - 0.25 * log_inv - 0.125 * eps_log);
  s[3] = 1.33333 * (1.0518 - 0.125 * eps_log);
  s[4] = 1.33333 * (0.702834 + 0.2 * log_inv + 0.188 * eps_log);
  s[5] = -0.350153 - 0.25 / eps - 0.225 * log_inv - 0.0267857 * eps_log;
  s[6] = -0.273652 - 0.166667 * log_inv;
  s[7] = -0.666667 * (-0.00162268 + 0.25 * log_inv + 0.125 * eps_log);
  s[8] = 1.33333 * (-0.150257 + 0.125 * eps_log);
  s[9] = 1.33333 * (-0.027464 + 0.05 * log_inv + 0.062 * eps_log);
}

// 12 x 12 block from scalars (resistance.pair_blocks), R row-major.
void pair_block(const double *e, const double *s, double f0, double f1, double f2, double *R) {
  double sq[9], sh[9], cr[9];
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) {
      sq[3 * a + b] = e[a] * e[b];
      sh[3 * a + b] = (a == b ? 1.0 : 0.0) - sq[3 * a + b];
    }
  const double x = e[0], y = e[1], z = e[2];
  const double crv[9] = {0.0, -z, y, z, 0.0, -x, -y, x, 0.0};
  for (int i = 0; i < 9; ++i) cr[i] = crv[i];
  double A11[9], A12[9], B11[9], B12[9], C11[9], C12[9];
  const double b11 = f1 * s[2], b12 = f1 * s[7];
  for (int i = 0; i < 9; ++i) {
    A11[i] = f0 * (s[0] * sq[i] + s[1] * sh[i]);
    A12[i] = f0 * (s[5] * sq[i] + s[6] * sh[i]);
    C11[i] = f2 * (s[3] * sq[i] + s[4] * sh[i]);
    C12[i] = f2 * (s[8] * sq[i] + s[9] * sh[i]);
    B11[i] = b11 * cr[i];
    B12[i] = b12 * cr[i];
  }
  const double *blocks[4][4] = {{A11, B11, A12, B12}, {B11, C11, B12, C12}, {A12, B12, A11, B11},
                                {B12, C12, B11, C11}};
  const double signs[4][4] = {{1, -1, 1, 1}, {1, 1, 1, 1}, {1, -1, 1, 1}, {-1, 1, -1, 1}};
  for (int I = 0; I < 4; ++I)
    for (int J = 0; J < 4; ++J)
      for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b) {
          const double v = blocks[I][J][3 * a + b];
          R[(3 * I + a) * 12 + 3 * J + b] = signs[I][J] < 0 ? -v : v;
        }
}

// Inverse of a 12 x 12 matrix by Gauss-Jordan elimination with partial pivoting, then symmetrised.
void invert_symmetrised(const double *M, double *R) {
  double A[12][24];
  for (int i = 0; i < 12; ++i)
    for (int j = 0; j < 12; ++j) {
      A[i][j] = M[12 * i + j];
      A[i][12 + j] = i == j ? 1.0 : 0.0;
    }
  for (int c = 0; c < 12; ++c) {
    int p = c;
    for (int i = c + 1; i < 12; ++i)
      if (std::fabs(A[i][c]) > std::fabs(A[p][c])) p = i;
    if (p != c)
      for (int j = 0; j < 24; ++j) std::swap(A[p][j], A[c][j]);
    const double inv = 1.0 / A[c][c];
    for (int j = 0; j < 24; ++j) A[c][j] *= inv;
    for (int i = 0; i < 12; ++i) {
      if (i == c) continue;
      const double f = A[i][c];
      if (f == 0.0) continue;
      for (int j = 0; j < 24; ++j) A[i][j] -= f * A[c][j];
    }
  }
  for (int i = 0; i < 12; ++i)
    for (int j = 0; j < 12; ++j) R[12 * i + j] = 0.5 * (A[i][12 + j] + A[j][12 + i]);
}

void near_block(const Model &m, double r, const double *e, double *R) {
  double s[10];
  near_contact(r, s);
  pair_block(e, s, m.f0, m.f1, m.f2, R);
}

void mobility_table_block(const Model &m, double r, const double *e, double *R) {
  double s[10], M[144];
  interpolate(m.WS, r, s);
  pair_block(e, s, 1.0 / m.f0, 1.0 / m.f1, 1.0 / m.f2, M);
  invert_symmetrised(M, R);
}

void table_block(const Model &m, const Table &t, double r, const double *e, double *R) {
  double s[10];
  interpolate(t, r, s);
  pair_block(e, s, m.f0, m.f1, m.f2, R);
}

// R_sup and R_MB of one pair (resistance.pair_resistance_sup, pair_resistance_blob_model, cutoff_taper).
void pair_sup_mb(const Model &m, double r_in, const double *e, double cutoff, double *sup, double *mb) {
  const double r = clamp_gap(r_in, 2.0, m.firm_delta);
  if (m.handover == 0) {
    if (r <= 2.0 + 0.006 - 1e-8)
      near_block(m, r, e, sup);
    else if (r <= 2.0 + 0.1 + 1e-8)
      mobility_table_block(m, r, e, sup);
    else
      table_block(m, m.JO, r, e, sup);
    table_block(m, m.MB, r, e, mb);
    return;
  }
  const double w1 = smooth_weight(r, m.windows[0], m.windows[1]);
  const double w2 = smooth_weight(r, m.windows[2], m.windows[3]);
  double part[144];
  for (int i = 0; i < 144; ++i) sup[i] = 0.0;
  if (w1 < 1) {
    near_block(m, r, e, part);
    const double w = 1.0 - w1;
    for (int i = 0; i < 144; ++i) sup[i] += w * part[i];
  }
  if (w1 > 0 && w2 < 1) {
    mobility_table_block(m, r, e, part);
    const double w = w1 * (1.0 - w2);
    for (int i = 0; i < 144; ++i) sup[i] += w * part[i];
  }
  if (w2 > 0) {
    table_block(m, m.JO, r, e, part);
    for (int i = 0; i < 144; ++i) sup[i] += w2 * part[i];
  }
  table_block(m, m.MB, r, e, mb);
  // the taper uses the distance before the gap clamp (as assembly.py: neighbours.r_over_a)
  const double taper = 1.0 - smooth_weight(r_in, cutoff - m.cutoff_window, cutoff);
  for (int i = 0; i < 144; ++i) {
    sup[i] = taper * sup[i];
    mb[i] = taper * mb[i];
  }
}

void wall_block(const Model &m, const double *s, double *R) {
  for (int i = 0; i < 36; ++i) R[i] = 0.0;
  R[0 * 6 + 0] = R[1 * 6 + 1] = m.f0 * s[1];
  R[2 * 6 + 2] = m.f0 * s[0];
  R[0 * 6 + 4] = R[4 * 6 + 0] = m.f1 * s[2];
  R[1 * 6 + 3] = R[3 * 6 + 1] = -m.f1 * s[2];
  R[3 * 6 + 3] = R[4 * 6 + 4] = m.f2 * s[4];
  R[5 * 6 + 5] = m.f2 * s[3];
}

// Wall-part scalars of the resolved sphere (resistance.wall_scalars_sup) and of one blob
// (resistance.wall_scalars_blob_model), then the 6 x 6 blocks.
void wall_sup_mb(const Model &m, double h_in, double *sup, double *mb) {
  const double h = clamp_gap(h_in, 1.0, m.firm_delta), eps = h - 1.0;
  double mob[5];
  if (interpolate(m.wall_sup, h, mob)) {
    mob[0] = 1.0 - (9.0 / 8.0) / h;
    mob[1] = 1.0 - (9.0 / 16.0) / h;
    mob[2] = 0.0;
    mob[3] = mob[4] = 0.75;
  }
  const double Xa = mob[0], Ya = mob[1], Yb = mob[2], Xc = mob[3], Yc = mob[4];
  const double denominator = Ya * Yc - Yb * Yb, log_eps = std::log(eps);
  const double near_normal = 1.0 / eps - 0.2 * log_eps + 0.971280;
  const double near_parallel = -(8.0 / 15.0) * log_eps + 0.9588;
  const double near_coupling = (4.0 / 3.0) * ((0.1 * log_eps + 0.1895) - 0.4576 * eps);
  const double near_normal_rotation = (4.0 / 3.0) * (1.2020569 - 3.0 * (M_PI * M_PI / 6.0 - 1.0) * eps);
  const double near_parallel_rotation = (4.0 / 3.0) * (-0.4 * log_eps + 0.3817 + 1.4578 * eps);
  double RXa, RYa, RYb, RXc, RYc;
  if (m.handover == 0) {
    RXa = h > 1.0 + 0.1 ? 1.0 / Xa : near_normal;
    RYa = h > 1.0 + 0.01 ? Yc / denominator : near_parallel;
    RYb = h > 1.0 + 0.1 ? -Yb / denominator : near_coupling;
    RXc = h > 1.0 + 0.01 ? 1.0 / Xc : near_normal_rotation;
    RYc = h > 1.0 + 0.1 ? Ya / denominator : near_parallel_rotation;
  } else {
    const double wn = smooth_weight(h, m.windows[4], m.windows[5]), wf = smooth_weight(h, m.windows[6], m.windows[7]);
    RXa = (1.0 - wf) * near_normal + wf * (1.0 / Xa);
    RYa = (1.0 - wn) * near_parallel + wn * (Yc / denominator);
    RYb = (1.0 - wf) * near_coupling + wf * (-Yb / denominator);
    RXc = (1.0 - wn) * near_normal_rotation + wn * (1.0 / Xc);
    RYc = (1.0 - wf) * near_parallel_rotation + wf * (Ya / denominator);
  }
  const double s_sup[5] = {RXa - 1.0, RYa - 1.0, RYb, std::max(RXc - 4.0 / 3.0, 0.0), std::max(RYc - 4.0 / 3.0, 0.0)};
  wall_block(m, s_sup, sup);
  double res[5];
  if (interpolate(m.wall_MB, h, res)) {
    res[0] = 1.0 / (1.0 - (9.0 / 8.0) / h);
    res[1] = 1.0 / (1.0 - (9.0 / 16.0) / h);
    res[2] = 0.0;
    res[3] = res[4] = 1.0 / 0.75;
  }
  const double s_mb[5] = {res[0] - 1.0, res[1] - 1.0, res[2], res[3] - 4.0 / 3.0, res[4] - 4.0 / 3.0};
  wall_block(m, s_mb, mb);
}

Model make_model(py::dict tables, const Array &factors, double firm_delta, int handover, const Array &windows,
                 double cutoff_window) {
  if (factors.size() != 3 || windows.size() != 8) throw std::invalid_argument("factors (3,) and windows (8,) expected");
  if (handover != 0 && handover != 1) throw std::invalid_argument("handover must be 0 (published) or 1 (smooth)");
  auto get = [&](const char *key) { return tables[key].cast<Array>(); };
  Model m;
  m.JO = make_table(get("JO_x"), get("JO"), 10, "JO");
  m.WS = make_table(get("WS_x"), get("WS"), 10, "WS");
  m.MB = make_table(get("MB_x"), get("MB"), 10, "MB");
  m.wall_sup = make_table(get("wall_sup_x"), get("wall_sup"), 5, "wall_sup");
  m.wall_MB = make_table(get("wall_MB_x"), get("wall_MB"), 5, "wall_MB");
  m.f0 = factors.data()[0], m.f1 = factors.data()[1], m.f2 = factors.data()[2];
  m.firm_delta = firm_delta;
  m.handover = handover;
  for (int i = 0; i < 8; ++i) m.windows[i] = windows.data()[i];
  m.cutoff_window = cutoff_window;
  return m;
}

// R_sup, R_MB blocks of P pairs: (P, 12, 12) each.
py::tuple pair_blocks(py::dict tables, const Array &factors, double firm_delta, int handover, const Array &windows,
                      double cutoff_window, double cutoff, const Array &r, const Array &r_hat) {
  const Model m = make_model(tables, factors, firm_delta, handover, windows, cutoff_window);
  const long P = r.size();
  if (r_hat.size() != 3 * P) throw std::invalid_argument("r_hat must be (P, 3) for r (P,)");
  py::array_t<double> sup({P, 12L, 12L}), mb({P, 12L, 12L});
  double *S = sup.mutable_data(), *B = mb.mutable_data();
  const double *rp = r.data(), *ep = r_hat.data();
  {
    py::gil_scoped_release release;
    for (long p = 0; p < P; ++p) pair_sup_mb(m, rp[p], ep + 3 * p, cutoff, S + 144 * p, B + 144 * p);
  }
  return py::make_tuple(sup, mb);
}

// Wall blocks of N spheres at heights h (N,): (N, 6, 6) each.
py::tuple wall_blocks(py::dict tables, const Array &factors, double firm_delta, int handover, const Array &windows,
                      const Array &h) {
  const Model m = make_model(tables, factors, firm_delta, handover, windows, 0.0);
  const long N = h.size();
  py::array_t<double> sup({N, 6L, 6L}), mb({N, 6L, 6L});
  double *S = sup.mutable_data(), *B = mb.mutable_data();
  const double *hp = h.data();
  {
    py::gil_scoped_release release;
    for (long i = 0; i < N; ++i) wall_sup_mb(m, hp[i], S + 36 * i, B + 36 * i);
  }
  return py::make_tuple(sup, mb);
}

// One CSR matrix (6N x 6N) from blocks in BSR order (block_start, block_col, block data of 36), exact zeros out.
// One pass: every entry is written at the next free place and the place advances past the nonzero ones only (no
// branch, no counting pass); the arrays are made for every entry of every block and returned as views of their
// first nnz entries (the rest, the room the zeros would have taken, stays unused).
py::tuple to_csr(long n, const std::vector<long> &row_start, const std::vector<long> &block_col,
                 const std::vector<const double *> &block_data) {
  const long rows = 6 * n, capacity = 36 * row_start[n];
  py::array_t<double> data(std::max(capacity, 1L));
  py::array_t<std::int32_t> indices(std::max(capacity, 1L)), indptr(rows + 1);
  double *D = data.mutable_data();
  std::int32_t *I = indices.mutable_data(), *Q = indptr.mutable_data();
  std::int64_t c = 0;  // int64 while filling; the CSR holds int32
  for (long row = 0; row < rows; ++row) {
    if (c > 2147483647L) throw std::length_error("more than 2^31 nonzeros in a lubrication matrix");
    Q[row] = static_cast<std::int32_t>(c);
    const long i = row / 6, a = row % 6;
    for (long k = row_start[i]; k < row_start[i + 1]; ++k) {
      const double *v = block_data[k] + 6 * a;
      const std::int32_t column = static_cast<std::int32_t>(6 * block_col[k]);
      for (int b = 0; b < 6; ++b) {
        D[c] = v[b], I[c] = column + b;
        c += v[b] != 0.0;
      }
    }
  }
  if (c > 2147483647L) throw std::length_error("more than 2^31 nonzeros in a lubrication matrix");
  Q[rows] = static_cast<std::int32_t>(c);
  const py::slice used(0, static_cast<py::ssize_t>(c), 1);
  return py::make_tuple(data[used], indices[used], indptr);
}

// R_sup, R_MB and Delta_R of N spheres as CSR triples (data, indices, indptr), from the pairs (P, 2)
// (i < j, sorted by i then j, as assembly.neighbour_pairs gives them), their r (P,), r_hat (P, 3), and
// the heights h (N,) (an empty array: no wall).  As assembly._BlockPattern: a sphere's diagonal block is its
// wall block plus the "11" blocks of its pairs (pairs in order, first as sphere 1, then as sphere 2).
py::tuple assemble(py::dict tables, const Array &factors, double firm_delta, int handover, const Array &windows,
                   double cutoff_window, double cutoff, long n, const IndexArray &pairs, const Array &r,
                   const Array &r_hat, const Array &h) {
  const Model m = make_model(tables, factors, firm_delta, handover, windows, cutoff_window);
  const long P = r.size();
  if (pairs.size() != 2 * P || r_hat.size() != 3 * P) throw std::invalid_argument("pairs (P, 2), r (P,), r_hat (P, 3)");
  const bool wall = h.size() > 0;
  if (wall && h.size() != n) throw std::invalid_argument("h must be (N,) or empty (no wall)");
  const std::int64_t *pr = pairs.data();
  for (long p = 0; p < P; ++p) {
    const std::int64_t i = pr[2 * p], j = pr[2 * p + 1];
    if (!(0 <= i && i < j && j < n) ||
        (p > 0 && (pr[2 * p - 2] > i || (pr[2 * p - 2] == i && pr[2 * p - 1] >= j))))
      throw std::invalid_argument("pairs must hold i < j < N, sorted by i then j");
  }
  // storage every entry of which is written below is left uninitialised (no zero fill of ~1 MB per call)
  const auto uninitialised = [](long size) { return std::unique_ptr<double[]>(new double[std::max(size, 1L)]); };
  std::unique_ptr<double[]> pair_sup = uninitialised(144 * P), pair_mb = uninitialised(144 * P);
  std::vector<double> diag_sup(36 * n, 0.0), diag_mb(36 * n, 0.0);
  std::vector<long> row_start(n + 1, 0), block_col(n + 2 * P);
  std::vector<const double *> sup_blocks(n + 2 * P), mb_blocks(n + 2 * P), delta_blocks(n + 2 * P);
  // off-diagonal blocks copied into 6 x 6 storage: (i, j) = rows 0..5, cols 6..11 of the pair block
  std::unique_ptr<double[]> off_sup = uninitialised(72 * P), off_mb = uninitialised(72 * P),
                            off_delta = uninitialised(72 * P), diag_delta = uninitialised(36 * n);
  py::tuple result;
  {
    py::gil_scoped_release release;
    const double *rp = r.data(), *ep = r_hat.data(), *hp = h.data();
    for (long p = 0; p < P; ++p) pair_sup_mb(m, rp[p], ep + 3 * p, cutoff, &pair_sup[144 * p], &pair_mb[144 * p]);
    if (wall) {
      for (long i = 0; i < n; ++i) wall_sup_mb(m, hp[i], &diag_sup[36 * i], &diag_mb[36 * i]);
    }
    for (int side = 0; side < 2; ++side)  // np.add.at order: all pairs as sphere 1, then all as sphere 2
      for (long p = 0; p < P; ++p) {
        const long i = pr[2 * p + side], o = 6 * side;
        for (int a = 0; a < 6; ++a)
          for (int b = 0; b < 6; ++b) {
            diag_sup[36 * i + 6 * a + b] += pair_sup[144 * p + 12 * (o + a) + o + b];
            diag_mb[36 * i + 6 * a + b] += pair_mb[144 * p + 12 * (o + a) + o + b];
          }
      }
    for (long k = 0; k < 36 * n; ++k) diag_delta[k] = diag_sup[k] - diag_mb[k];
    for (long p = 0; p < P; ++p)
      for (int side = 0; side < 2; ++side)  // side 0: the (i, j) block, side 1: the (j, i) block
        for (int a = 0; a < 6; ++a)
          for (int b = 0; b < 6; ++b) {
            const long src = 144 * p + 12 * (a + 6 * side) + b + 6 * (1 - side), dst = 72 * p + 36 * side + 6 * a + b;
            off_sup[dst] = pair_sup[src];
            off_mb[dst] = pair_mb[src];
            off_delta[dst] = pair_sup[src] - pair_mb[src];
          }
    // block rows: pairs (k, i) with k < i (as the (i, k) block), then the diagonal, then pairs (i, j), j > i
    std::vector<long> lower(n, 0), upper(n, 0);
    for (long p = 0; p < P; ++p) ++upper[pr[2 * p]], ++lower[pr[2 * p + 1]];
    for (long i = 0; i < n; ++i) row_start[i + 1] = row_start[i] + lower[i] + 1 + upper[i];
    std::vector<long> next_lower(row_start.begin(), row_start.end() - 1), next_upper(n);
    for (long i = 0; i < n; ++i) {
      const long d = row_start[i] + lower[i];
      next_upper[i] = d + 1;
      block_col[d] = i;
      sup_blocks[d] = &diag_sup[36 * i], mb_blocks[d] = &diag_mb[36 * i], delta_blocks[d] = &diag_delta[36 * i];
    }
    for (long p = 0; p < P; ++p) {
      const long i = pr[2 * p], j = pr[2 * p + 1];
      const long u = next_upper[i]++, l = next_lower[j]++;
      block_col[u] = j, block_col[l] = i;
      sup_blocks[u] = &off_sup[72 * p], mb_blocks[u] = &off_mb[72 * p], delta_blocks[u] = &off_delta[72 * p];
      sup_blocks[l] = &off_sup[72 * p + 36], mb_blocks[l] = &off_mb[72 * p + 36];
      delta_blocks[l] = &off_delta[72 * p + 36];
    }
  }
  // the CSR arrays are numpy arrays: built with the GIL held
  return py::make_tuple(to_csr(n, row_start, block_col, sup_blocks), to_csr(n, row_start, block_col, mb_blocks),
                        to_csr(n, row_start, block_col, delta_blocks));
}

}  // namespace

PYBIND11_MODULE(_lubrication_cpp, module) {
  module.doc() = "Near-field resistance blocks and sparse assembly of lubrication/ (see lubrication/assembly.py)";
  module.def("pair_blocks", &pair_blocks, "R_sup, R_MB (P, 12, 12) of pairs at r (P,) along r_hat (P, 3)",
             py::arg("tables"), py::arg("factors"), py::arg("firm_delta"), py::arg("handover"), py::arg("windows"),
             py::arg("cutoff_window"), py::arg("cutoff"), py::arg("r"), py::arg("r_hat"));
  module.def("wall_blocks", &wall_blocks, "R_sup, R_MB wall parts (N, 6, 6) at heights h (N,)", py::arg("tables"),
             py::arg("factors"), py::arg("firm_delta"), py::arg("handover"), py::arg("windows"), py::arg("h"));
  module.def("assemble", &assemble, "CSR triples of R_sup, R_MB, Delta_R (6N x 6N)", py::arg("tables"),
             py::arg("factors"), py::arg("firm_delta"), py::arg("handover"), py::arg("windows"),
             py::arg("cutoff_window"), py::arg("cutoff"), py::arg("n"), py::arg("pairs"), py::arg("r"),
             py::arg("r_hat"), py::arg("h"));
}
