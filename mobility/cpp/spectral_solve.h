// The Stokes solves of the spectral product in Fourier(-Chebyshev) space, in place on the transformed grid
// (mobility._spectral_cpp).  The matrices, bands and wavenumbers come from mobility/spectral/chebyshev.py
// and fourier.py; mobility/spectral/reference.py is the NumPy statement of the same steps.
//
// Doubly periodic geometries.  The grid holds, for every Fourier mode (kx, ky) of the real transforms, the
// node values of the three force-density components along the Chebyshev z grid; it receives the velocity
// node values.  Modes are processed in tiles of consecutive kx (one ky): the node values of a tile are
// copied out, transformed to Chebyshev coefficients (a matrix product over the tile), the pressure and
// the three velocity boundary-value problems solved for every mode of the tile (two tridiagonal chains
// plus a 2 x 2 Schur complement each, vectorised across the tile), transformed back, the wall correction
// added at the nodes, and written back.  The k = 0 mode is left to the caller.
//
// Triply periodic: the Fourier solve mode by mode.
#pragma once

#include <algorithm>
#include <cmath>
#include <complex>
#include <cstdint>
#include <cstring>
#include <vector>

#include "openmp_threads.h"

namespace rmb_spectral {

using cplx = std::complex<double>;

enum Geometry { OPEN = 0, BOTTOM_WALL = 1, SLIT = 2 };

struct Chebyshev {
  int N = 0;
  double H = 0.0, Lz = 0.0, eta = 1.0;
  int geometry = OPEN;
  // Rules (DoublyPeriodicStokes: both false): the z-derivative of the pressure in the w equation by the
  // Chebyshev recurrence of its coefficients instead of the integration matrix F x_p (UAMMD); the wall
  // correction of an unpaired mode without the average with its conjugate partner (UAMMD's real inverse).
  bool pressure_derivative_by_recurrence = false;
  bool unpaired_correction_as_is = false;
  const double *forward = nullptr, *backward = nullptr;               // (N, N): values -> coefficients, back
  const double *s_low = nullptr, *s_diag = nullptr, *s_up = nullptr;  // S1[j, j-2], S1[j, j], S1[j, j+2]
  const double *s_c0 = nullptr, *s_d0 = nullptr;                      // S1[:, N], S1[:, N+1]
  const double *f_low = nullptr, *f_up = nullptr, *f_d0 = nullptr;    // F1[j, j-1], F1[j, j+1], F1[:, N+1]
  const double *R2 = nullptr, *L2 = nullptr, *R1 = nullptr, *L1 = nullptr;  // boundary rows (N + 2)
  const double *z = nullptr;                                          // node heights (N), top first
};

struct Modes {
  std::int64_t Ny = 0, Nxh = 0;
  const double *kx = nullptr, *ky = nullptr;    // raw wavenumbers (Nxh), (Ny)
  const double *dx = nullptr, *dy = nullptr;    // derivative factors / i (0 for unpaired modes)
  const double *kx_partner = nullptr, *ky_partner = nullptr;  // raw wavenumbers of the conjugate partner
  const std::uint8_t *unpaired_x = nullptr, *unpaired_y = nullptr;
};

// ------------------------------------------------------------------ small dense complex solve
// Gaussian elimination with partial pivoting of an 8 x 8 complex system (the slit's wall correction).
inline void solve8(cplx M[8][8], cplx r[8]) {
  for (int col = 0; col < 8; ++col) {
    int best = col;
    for (int i = col + 1; i < 8; ++i)
      if (std::abs(M[i][col]) > std::abs(M[best][col])) best = i;
    if (best != col) {
      for (int j = 0; j < 8; ++j) std::swap(M[col][j], M[best][j]);
      std::swap(r[col], r[best]);
    }
    for (int i = col + 1; i < 8; ++i) {
      const cplx m = M[i][col] / M[col][col];
      if (m == cplx(0.0)) continue;
      for (int j = col; j < 8; ++j) M[i][j] -= m * M[col][j];
      r[i] -= m * r[col];
    }
  }
  for (int i = 7; i >= 0; --i) {
    cplx s = r[i];
    for (int j = i + 1; j < 8; ++j) s -= M[i][j] * r[j];
    r[i] = s / M[i][i];
  }
}

// Wall correction at the N nodes (added to u, v, w: each N complex values, stride `stride` in cplx).
// b, t: the velocity to impose at z = 0 and z = Lz (3 each).  Bottom wall: decaying solution equal to b at
// z = 0; slit: the solution equal to b and t.
inline void add_wall_correction(const Chebyshev &c, double kx, double ky, double K, const cplx b[3],
                                const cplx t[3], double weight, cplx *u, cplx *v, cplx *w, std::int64_t stride) {
  const int N = c.N;
  const cplx I(0.0, 1.0);
  if (c.geometry == BOTTOM_WALL) {
    const cplx A = kx * b[0] + ky * b[1] + I * K * b[2];
    for (int k = 0; k < N; ++k) {
      const double zk = c.z[k];
      const double decay = std::exp(-K * zk);
      u[k * stride] += weight * ((-kx * A * zk / K + b[0]) * decay);
      v[k * stride] += weight * ((-ky * A * zk / K + b[1]) * decay);
      w[k * stride] += weight * ((-I * A * zk + b[2]) * decay);
    }
    return;
  }
  const double Lz = c.Lz, E = std::exp(-K * Lz), q = 1.0 / (2.0 * c.eta);
  cplx M[8][8];
  cplx r[8];
  for (auto &rowM : M)
    for (auto &e : rowM) e = 0.0;
  M[0][0] = q, M[0][1] = E * q, M[0][6] = -K, M[0][7] = K * E;
  r[0] = -I * kx * b[0] - I * ky * b[1];
  M[1][0] = (1 - K * Lz) * E * q, M[1][1] = (1 + K * Lz) * q, M[1][6] = -K * E, M[1][7] = K;
  r[1] = -I * kx * t[0] - I * ky * t[1];
  M[2][2] = 1.0, M[2][3] = E, r[2] = b[0];
  M[3][4] = 1.0, M[3][5] = E, r[3] = b[1];
  M[4][6] = 1.0, M[4][7] = E, r[4] = b[2];
  M[5][0] = -I * kx * Lz * E * q / K, M[5][1] = I * kx * Lz * q / K, M[5][2] = E, M[5][3] = 1.0, r[5] = t[0];
  M[6][0] = -I * ky * Lz * E * q / K, M[6][1] = I * ky * Lz * q / K, M[6][4] = E, M[6][5] = 1.0, r[6] = t[1];
  M[7][0] = Lz * E * q, M[7][1] = Lz * q, M[7][6] = E, M[7][7] = 1.0, r[7] = t[2];
  solve8(M, r);
  for (int k = 0; k < N; ++k) {
    const double zk = c.z[k];
    const double down = std::exp(-K * zk), up = std::exp(K * (zk - Lz));
    u[k * stride] += weight * (-I * r[0] * kx * q * zk * down / K + I * r[1] * kx * q * zk * up / K + r[2] * down +
                               r[3] * up);
    v[k * stride] += weight * (-I * r[0] * ky * q * zk * down / K + I * r[1] * ky * q * zk * up / K + r[4] * down +
                               r[5] * up);
    w[k * stride] += weight * (r[0] * q * zk * down + r[1] * q * zk * up + r[6] * down + r[7] * up);
  }
}

// ------------------------------------------------------------------ one tile of modes
// Work arrays of one thread: complex arrays laid out [j][t] (t = mode in the tile, fastest).
class TileSolver {
 public:
  static constexpr int T = 16;       // modes per tile
  static constexpr int T2 = 2 * T;   // doubles per tile row

  explicit TileSolver(const Chebyshev &c) : c_(c) {
    const std::size_t n = static_cast<std::size_t>(c.N) * T;
    values_.assign(3 * n, cplx(0.0));
    coef_.assign(3 * n, cplx(0.0));
    pressure_.assign(n, cplx(0.0));
    dpressure_.assign(n, cplx(0.0));
    work_.assign(n, cplx(0.0));
    pivot_.assign(n, 0.0), mult_.assign(n, 0.0), upper_.assign(n, 0.0), z0_.assign(n, 0.0), z1_.assign(n, 0.0);
    for (auto *a : {&K_, &q_, &kx_, &ky_, &dx_, &dy_, &g_t0_, &g_t1_, &g_b0_, &g_b1_, &det_}) a->assign(T, 0.0);
    for (auto *a : {&c0_, &d0_, &top_, &bottom_}) a->assign(T, cplx(0.0));
    scratch_a_.assign(static_cast<std::size_t>(c.N / 2 + 1) * 2 * T, 0.0);
    scratch_b_.assign(static_cast<std::size_t>(c.N / 2 + 1) * 2 * T, 0.0);
  }

  // Solve the modes iy, ix0 .. ix0 + count - 1 (count <= T) of the grid (3, N, Ny, Nxh) complex, in place.
  void run(cplx *grid, const Modes &m, std::int64_t iy, std::int64_t ix0, int count) {
    const int N = c_.N;
    const std::int64_t plane = m.Ny * m.Nxh, comp = N * plane;
    // load node values
    for (int a = 0; a < 3; ++a)
      for (int k = 0; k < N; ++k) {
        const cplx *src = grid + a * comp + k * plane + iy * m.Nxh + ix0;
        cplx *dst = values_.data() + (static_cast<std::size_t>(a) * N + k) * T;
        for (int t = 0; t < count; ++t) dst[t] = src[t];
        for (int t = count; t < T; ++t) dst[t] = 0.0;
      }
    // values -> coefficients (matrix product over the tile)
    transform(c_.forward, values_.data(), coef_.data(), true);
    // modes of the tile
    for (int t = 0; t < T; ++t) {
      const std::int64_t ix = ix0 + std::min<std::int64_t>(t, count - 1);
      kx_[t] = m.kx[ix], ky_[t] = m.ky[iy], dx_[t] = m.dx[ix], dy_[t] = m.dy[iy];
      K_[t] = std::sqrt(kx_[t] * kx_[t] + ky_[t] * ky_[t]);
      if (K_[t] == 0.0) K_[t] = 1.0;  // the k = 0 mode is the caller's; any finite numbers here
      q_[t] = (K_[t] * c_.H) * (K_[t] * c_.H);
    }
    factor();
    cplx *fx = coef_.data(), *fy = fx + N * T, *fz = fy + N * T;
    // pressure: (D^2 - K^2) p = i kx fx + i ky fy + D fz; p' + K p = 0 (top), p' - K p = 0 (bottom)
    cplx *rhs = work_.data();
    derivative(fz, rhs);
    for (int j = 0; j < N; ++j)
      for (int t = 0; t < T; ++t) rhs[j * T + t] += cplx(0.0, dx_[t]) * fx[j * T + t] + cplx(0.0, dy_[t]) * fy[j * T + t];
    for (int t = 0; t < T; ++t) top_[t] = 0.0, bottom_[t] = 0.0;
    solve(rhs, pressure_.data(), dpressure_.data());
    if (c_.pressure_derivative_by_recurrence) derivative(pressure_.data(), dpressure_.data());
    std::vector<cplx> p_top(T, 0.0), p_bottom(T, 0.0);
    for (int j = 0; j < N; ++j) {
      const double sign = (j % 2) ? -1.0 : 1.0;
      for (int t = 0; t < T; ++t) p_top[t] += pressure_[j * T + t], p_bottom[t] += sign * pressure_[j * T + t];
    }
    const double eta = c_.eta;
    // velocity: eta (D^2 - K^2) u = i kx p - fx (v alike), eta (D^2 - K^2) w = p' - fz; Robin conditions
    for (int a = 0; a < 3; ++a) {
      cplx *f = coef_.data() + a * N * T;
      for (int j = 0; j < N; ++j)
        for (int t = 0; t < T; ++t) {
          const cplx source = a == 2 ? dpressure_[j * T + t] : cplx(0.0, a == 0 ? dx_[t] : dy_[t]) * pressure_[j * T + t];
          rhs[j * T + t] = (source - f[j * T + t]) / eta;
        }
      for (int t = 0; t < T; ++t) {
        if (a == 2) {
          top_[t] = p_top[t] / (2.0 * eta);
          bottom_[t] = p_bottom[t] / (2.0 * eta);
        } else {
          const cplx d(0.0, a == 0 ? dx_[t] : dy_[t]);
          top_[t] = -d * p_top[t] / (2.0 * eta * K_[t]);
          bottom_[t] = d * p_bottom[t] / (2.0 * eta * K_[t]);
        }
      }
      solve(rhs, f, nullptr);  // the coefficients of this velocity component replace those of the force
    }
    // wall values of the open-fluid solution (before the transform back)
    std::vector<cplx> wall_b(3 * T, 0.0), wall_t(3 * T, 0.0);
    if (c_.geometry != OPEN)
      for (int a = 0; a < 3; ++a)
        for (int j = 0; j < N; ++j) {
          const double sign = (j % 2) ? -1.0 : 1.0;
          for (int t = 0; t < T; ++t) {
            wall_b[a * T + t] -= sign * coef_[(a * N + j) * T + t];
            wall_t[a * T + t] -= coef_[(a * N + j) * T + t];
          }
        }
    // coefficients -> node values
    transform(c_.backward, coef_.data(), values_.data(), false);
    if (c_.geometry != OPEN) {
      for (int t = 0; t < count; ++t) {
        if (kx_[t] == 0.0 && ky_[t] == 0.0) continue;  // k = 0: the caller's
        const std::int64_t ix = ix0 + t;
        const cplx b[3] = {wall_b[t], wall_b[T + t], wall_b[2 * T + t]};
        const cplx top[3] = {wall_t[t], wall_t[T + t], wall_t[2 * T + t]};
        cplx *u = values_.data() + t, *v = u + N * T, *w = v + N * T;
        const bool partner = (m.unpaired_x[ix] || m.unpaired_y[iy]) && !c_.unpaired_correction_as_is;
        if (!partner) {
          add_wall_correction(c_, kx_[t], ky_[t], K_[t], b, top, 1.0, u, v, w, T);
        } else {
          // the library keeps the real part of a complex inverse transform: average this mode's correction
          // with the conjugate of its partner's (whose raw wavenumbers are not minus these)
          add_wall_correction(c_, kx_[t], ky_[t], K_[t], b, top, 0.5, u, v, w, T);
          const cplx bc[3] = {std::conj(b[0]), std::conj(b[1]), std::conj(b[2])};
          const cplx tc[3] = {std::conj(top[0]), std::conj(top[1]), std::conj(top[2])};
          std::vector<cplx> pu(N, 0.0), pv(N, 0.0), pw(N, 0.0);
          add_wall_correction(c_, m.kx_partner[ix], m.ky_partner[iy], K_[t], bc, tc, 1.0, pu.data(), pv.data(),
                              pw.data(), 1);
          for (int k = 0; k < N; ++k) {
            u[k * T] += 0.5 * std::conj(pu[k]);
            v[k * T] += 0.5 * std::conj(pv[k]);
            w[k * T] += 0.5 * std::conj(pw[k]);
          }
        }
      }
    }
    // store
    for (int a = 0; a < 3; ++a)
      for (int k = 0; k < N; ++k) {
        cplx *dst = grid + a * comp + k * plane + iy * m.Nxh + ix0;
        const cplx *src = values_.data() + (static_cast<std::size_t>(a) * N + k) * T;
        for (int t = 0; t < count; ++t) dst[t] = src[t];
      }
  }

 private:
  // out[a][j][t] = sum_k matrix[j][k] in[a][k][t] for the three components, using the parity of the
  // Chebyshev-node transforms: matrix[j][N-1-k] = (-1)^j matrix[j][k] (forward, rows j) and
  // matrix[N-1-k][j] = (-1)^j matrix[k][j] (backward), which halves the work.  One tile row (2T doubles)
  // is accumulated in four 8-double vectors (GCC vector extensions: SIMD registers where the target has
  // them, plain code elsewhere).
#if (defined(__GNUC__) || defined(__clang__)) && !defined(RMB_PLAIN_VECTORS)
  typedef double v8 __attribute__((vector_size(64), aligned(8)));
#else
  struct v8 {  // the same arithmetic, element by element, for compilers without vector extensions
    double d[8];
    v8 &operator+=(const v8 &o) {
      for (int i = 0; i < 8; ++i) d[i] += o.d[i];
      return *this;
    }
    friend v8 operator+(v8 a, const v8 &b) { return a += b; }
    friend v8 operator-(v8 a, const v8 &b) {
      for (int i = 0; i < 8; ++i) a.d[i] -= b.d[i];
      return a;
    }
    friend v8 operator*(double m, v8 a) {
      for (int i = 0; i < 8; ++i) a.d[i] *= m;
      return a;
    }
  };
#endif
  static constexpr int V = T2 / 8;

  static void load(v8 *acc, const double *row) {
    for (int v = 0; v < V; ++v) std::memcpy(&acc[v], row + 8 * v, sizeof(v8));
  }
  static void store(double *row, const v8 *acc) {
    for (int v = 0; v < V; ++v) std::memcpy(row + 8 * v, &acc[v], sizeof(v8));
  }
  static void fma_row(v8 *acc, double m, const double *row) {
    v8 x[V];
    load(x, row);
    for (int v = 0; v < V; ++v) acc[v] += m * x[v];
  }

  void transform(const double *matrix, const cplx *in, cplx *out, bool forward) const {
    const int N = c_.N, half = N / 2, mid = N % 2 ? N / 2 : -1;
    double *sum = scratch_a_.data();
    double *dif = scratch_b_.data();
    for (int a = 0; a < 3; ++a) {
      const double *src = reinterpret_cast<const double *>(in + static_cast<std::size_t>(a) * N * T);
      double *dst = reinterpret_cast<double *>(out + static_cast<std::size_t>(a) * N * T);
      if (forward) {
        // sums and differences of mirrored node values; even rows from the sums, odd rows from the differences
        for (int k = 0; k < half; ++k) {
          v8 lo[V], hi[V], x[V];
          load(lo, src + k * T2);
          load(hi, src + (N - 1 - k) * T2);
          for (int v = 0; v < V; ++v) x[v] = lo[v] + hi[v];
          store(sum + k * T2, x);
          for (int v = 0; v < V; ++v) x[v] = lo[v] - hi[v];
          store(dif + k * T2, x);
        }
        for (int j = 0; j < N; ++j) {
          v8 acc[V] = {};
          const double *s = (j % 2) ? dif : sum;
          const double *row = matrix + j * N;
          for (int k = 0; k < half; ++k) fma_row(acc, row[k], s + k * T2);
          if (mid >= 0 && j % 2 == 0) fma_row(acc, row[mid], src + mid * T2);
          store(dst + j * T2, acc);
        }
      } else {
        // even and odd coefficient sums at the upper half of the nodes, mirrored to the lower half
        for (int k = 0; k < half + (mid >= 0); ++k) {
          v8 even[V] = {}, odd[V] = {};
          const double *row = matrix + k * N;
          for (int j = 0; j < N; ++j) fma_row(j % 2 ? odd : even, row[j], src + j * T2);
          v8 x[V];
          for (int v = 0; v < V; ++v) x[v] = even[v] + odd[v];
          store(dst + k * T2, x);
          if (k != mid) {
            for (int v = 0; v < V; ++v) x[v] = even[v] - odd[v];
            store(dst + (N - 1 - k) * T2, x);
          }
        }
      }
    }
  }

  // Chebyshev coefficients of d/dz: d_{N-1} = 0, d_{N-2} = 2(N-1) c_{N-1}/H, d_{j-1} = d_{j+1} + 2 j c_j/H, d_0 /= 2
  void derivative(const cplx *cf, cplx *d) const {
    const int N = c_.N;
    const double H = c_.H;
    for (int t = 0; t < T; ++t) d[(N - 1) * T + t] = 0.0;
    for (int t = 0; t < T; ++t) d[(N - 2) * T + t] = 2.0 * (N - 1) * cf[(N - 1) * T + t] / H;
    for (int j = N - 2; j >= 1; --j)
      for (int t = 0; t < T; ++t) d[(j - 1) * T + t] = d[(j + 1) * T + t] + 2.0 * j * cf[j * T + t] / H;
    for (int t = 0; t < T; ++t) d[t] = d[t] / 2.0;
  }

  // Elimination of the two chains of I - q S1[:, :N] (q = K^2 H^2), the responses z0 = A^-1 e0,
  // z1 = A^-1 e1 and the 2 x 2 Schur complement of the boundary rows.
  void factor() {
    const int N = c_.N;
    const double H = c_.H;
    for (int j = 0; j < N; ++j)
      for (int t = 0; t < T; ++t) {
        const double diag = 1.0 - q_[t] * c_.s_diag[j];
        upper_[j * T + t] = -q_[t] * c_.s_up[j];
        if (j < 2) {
          mult_[j * T + t] = 0.0;
          pivot_[j * T + t] = diag;
        } else {
          const double low = -q_[t] * c_.s_low[j];
          mult_[j * T + t] = low / pivot_[(j - 2) * T + t];
          pivot_[j * T + t] = diag - mult_[j * T + t] * upper_[(j - 2) * T + t];
        }
      }
    for (int j = 0; j < N; ++j)
      for (int t = 0; t < T; ++t) z0_[j * T + t] = (j == 0), z1_[j * T + t] = (j == 1);
    chain_solve(z0_.data());
    chain_solve(z1_.data());
    for (int t = 0; t < T; ++t) {
      double t0 = 0.0, t1 = 0.0, b0 = 0.0, b1 = 0.0;
      const double hk = H * H * K_[t];
      for (int j = 0; j < N; ++j) {
        const double ct = hk * c_.R2[j] + H * c_.R1[j], cb = hk * c_.L2[j] + H * c_.L1[j];
        t0 += ct * z0_[j * T + t], t1 += ct * z1_[j * T + t];
        b0 += cb * z0_[j * T + t], b1 += cb * z1_[j * T + t];
      }
      g_t0_[t] = q_[t] * t0 + (hk * c_.R2[N] + H * c_.R1[N]);
      g_t1_[t] = q_[t] * t1 + (hk * c_.R2[N + 1] + H * c_.R1[N + 1]);
      g_b0_[t] = q_[t] * b0 + (hk * c_.L2[N] + H * c_.L1[N]);
      g_b1_[t] = q_[t] * b1 + (hk * c_.L2[N + 1] + H * c_.L1[N + 1]);
      det_[t] = g_t0_[t] * g_b1_[t] - g_t1_[t] * g_b0_[t];
    }
  }

  template <class V>
  void chain_solve(V *y) const {
    const int N = c_.N;
    for (int j = 2; j < N; ++j)
      for (int t = 0; t < T; ++t) y[j * T + t] -= mult_[j * T + t] * y[(j - 2) * T + t];
    for (int t = 0; t < T; ++t) {
      y[(N - 1) * T + t] /= pivot_[(N - 1) * T + t];
      y[(N - 2) * T + t] /= pivot_[(N - 2) * T + t];
    }
    for (int j = N - 3; j >= 0; --j)
      for (int t = 0; t < T; ++t) y[j * T + t] = (y[j * T + t] - upper_[j * T + t] * y[(j + 2) * T + t]) / pivot_[j * T + t];
  }

  // Solve for the right-hand side coefficients rhs (overwritten) with the boundary values top_, bottom_;
  // writes the coefficients of the solution (H^2 S1 x) to sol and, if given, of its derivative (H F1 x).
  void solve(cplx *rhs, cplx *sol, cplx *dsol) {
    const int N = c_.N;
    const double H = c_.H;
    chain_solve(rhs);
    for (int t = 0; t < T; ++t) {
      cplx st = 0.0, sb = 0.0;
      const double hk = H * H * K_[t];
      for (int j = 0; j < N; ++j) {
        st += (hk * c_.R2[j] + H * c_.R1[j]) * rhs[j * T + t];
        sb += (hk * c_.L2[j] + H * c_.L1[j]) * rhs[j * T + t];
      }
      const cplx r_t = top_[t] - st, r_b = bottom_[t] - sb;
      c0_[t] = (r_t * g_b1_[t] - g_t1_[t] * r_b) / det_[t];
      d0_[t] = (g_t0_[t] * r_b - g_b0_[t] * r_t) / det_[t];
    }
    for (int j = 0; j < N; ++j)
      for (int t = 0; t < T; ++t)
        rhs[j * T + t] += q_[t] * (c0_[t] * z0_[j * T + t] + d0_[t] * z1_[j * T + t]);
    const double H2 = H * H;
    for (int j = 0; j < N; ++j)
      for (int t = 0; t < T; ++t) {
        cplx s = c_.s_diag[j] * rhs[j * T + t] + c_.s_c0[j] * c0_[t] + c_.s_d0[j] * d0_[t];
        if (j >= 2) s += c_.s_low[j] * rhs[(j - 2) * T + t];
        if (j + 2 < N) s += c_.s_up[j] * rhs[(j + 2) * T + t];
        sol[j * T + t] = H2 * s;
      }
    if (dsol)
      for (int j = 0; j < N; ++j)
        for (int t = 0; t < T; ++t) {
          cplx s = c_.f_d0[j] * d0_[t];
          if (j >= 1) s += c_.f_low[j] * rhs[(j - 1) * T + t];
          if (j + 1 < N) s += c_.f_up[j] * rhs[(j + 1) * T + t];
          dsol[j * T + t] = H * s;
        }
  }

  const Chebyshev &c_;
  std::vector<cplx> values_, coef_, pressure_, dpressure_, work_;
  std::vector<double> pivot_, mult_, upper_, z0_, z1_;
  std::vector<double> K_, q_, kx_, ky_, dx_, dy_, g_t0_, g_t1_, g_b0_, g_b1_, det_;
  std::vector<cplx> c0_, d0_, top_, bottom_;
  mutable std::vector<double> scratch_a_, scratch_b_;
};

// All modes but k = 0 of a grid (3, N, Ny, Nxh) complex, in place; tiles of TileSolver::T modes along kx.
inline void solve_doubly_periodic(const Chebyshev &c, const Modes &m, cplx *grid) {
  const int tile = TileSolver::T;
  const std::int64_t tiles_per_row = (m.Nxh + tile - 1) / tile;
  const std::int64_t n_tiles = tiles_per_row * m.Ny;
#pragma omp parallel
  {
    TileSolver solver(c);
#pragma omp for schedule(dynamic, 4)
    for (std::int64_t i = 0; i < n_tiles; ++i) {
      const std::int64_t iy = i / tiles_per_row, ix0 = (i % tiles_per_row) * tile;
      const int count = static_cast<int>(std::min<std::int64_t>(tile, m.Nxh - ix0));
      solver.run(grid, m, iy, ix0, count);
    }
  }
}

// Triply periodic: p = -(i k . f)/k^2, u = (f - i k p)/(eta k^2) mode by mode; k = 0 gives 0.
// grid (3, Nz, Ny, Nxh) complex; dz (Nz), dy (Ny), dx (Nxh) derivative factors / i; kz, ky, kx raw.
inline void solve_triply_periodic(cplx *grid, std::int64_t Nz, std::int64_t Ny, std::int64_t Nxh, const double *kz,
                                  const double *ky, const double *kx, const double *dz, const double *dy,
                                  const double *dx, double eta) {
  const std::int64_t comp = Nz * Ny * Nxh;
#pragma omp parallel for schedule(static)
  for (std::int64_t r = 0; r < Nz * Ny; ++r) {
    const std::int64_t iz = r / Ny, iy = r % Ny;
    cplx *g0 = grid + r * Nxh, *g1 = g0 + comp, *g2 = g1 + comp;
    for (std::int64_t ix = 0; ix < Nxh; ++ix) {
      const double k2 = kx[ix] * kx[ix] + ky[iy] * ky[iy] + kz[iz] * kz[iz];
      if (k2 == 0.0) {
        g0[ix] = g1[ix] = g2[ix] = 0.0;
        continue;
      }
      const cplx ikx(0.0, dx[ix]), iky(0.0, dy[iy]), ikz(0.0, dz[iz]);
      const cplx f0 = g0[ix], f1 = g1[ix], f2 = g2[ix];
      const cplx p = -(ikx * f0 + iky * f1 + ikz * f2) / k2;
      const double scale = 1.0 / (eta * k2);
      g0[ix] = (f0 - ikx * p) * scale;
      g1[ix] = (f1 - iky * p) * scale;
      g2[ix] = (f2 - ikz * p) * scale;
    }
  }
}

}  // namespace rmb_spectral
