// Spreading of blob forces and torques onto the spectral grid and interpolation of the grid velocity back
// (mobility._spectral_cpp).  The stencils (node indices and 1-D kernel factors per blob) come from
// mobility/spectral/stencil.py, so the node rules live in one place; these loops only accumulate.
//
// Grid: three component arrays (force density or velocity), each Nz planes of Ny rows of `row` doubles
// (row >= Nx: the compiled path keeps rows padded for the in-place real FFT).
// Spreading is parallel without atomics: blobs are grouped in stripes of grid rows in y at least as wide
// as the kernel, so a blob of stripe s writes only rows of stripes s and s+1; even stripes run
// concurrently, then odd ones, then (odd stripe count) the last one, which wraps onto stripe 0.
#pragma once

#include <cstdint>

#include "openmp_threads.h"

namespace rmb_spectral {

// One kernel's stencils of n blobs: indices (n, w) and factors (n, w) per direction; z has `wz` slots
// (unused slots carry factor 0).  The d* factors (derivative kernel) are null for a monopole stencil.
struct Stencil {
  std::int64_t n = 0, wx = 0, wy = 0, wz = 0;
  const std::int32_t *ix = nullptr, *iy = nullptr, *iz = nullptr;
  const double *phi_x = nullptr, *phi_y = nullptr, *phi_z = nullptr;
  const double *dphi_x = nullptr, *dphi_y = nullptr, *dphi_z = nullptr;
};

struct Grid {
  double *c[3] = {nullptr, nullptr, nullptr};
  std::int64_t Nz = 0, Ny = 0, row = 0;
  std::int64_t plane() const { return Ny * row; }
};

// Blobs grouped by stripe: order (n,) blob indices, start (stripes + 1,) offsets into order.
struct Stripes {
  const std::int64_t *order = nullptr, *start = nullptr;
  std::int64_t count = 0;
};

template <class Body>
void for_each_blob_by_stripes(const Stripes &s, Body body) {
  if (s.count < 2) {
    for (std::int64_t k = 0; k < s.start[s.count]; ++k) body(s.order[k]);
    return;
  }
  const bool odd_count = s.count % 2 == 1;
  // pass 0: even stripes (without the last one when the count is odd); pass 1: odd stripes; pass 2: the last
  for (int pass = 0; pass < 3; ++pass) {
    std::int64_t first = pass == 1 ? 1 : (pass == 0 ? 0 : s.count - 1);
    std::int64_t last = pass == 2 ? (odd_count ? s.count : 0) : (odd_count && pass == 0 ? s.count - 1 : s.count);
    std::int64_t step = pass == 2 ? 1 : 2;
    if (first >= last) continue;
    const std::int64_t n_stripes = (last - first + step - 1) / step;
#pragma omp parallel for schedule(dynamic, 1)
    for (std::int64_t m = 0; m < n_stripes; ++m) {
      const std::int64_t stripe = first + m * step;
      for (std::int64_t k = s.start[stripe]; k < s.start[stripe + 1]; ++k) body(s.order[k]);
    }
  }
}

// grid += forces (n, 3) spread with the monopole stencil.
inline void spread_forces(const Stencil &st, const Stripes &stripes, const double *forces, Grid &g) {
  const std::int64_t plane = g.plane(), row = g.row;
  for_each_blob_by_stripes(stripes, [&](std::int64_t b) {
    const std::int32_t *ix = st.ix + b * st.wx, *iy = st.iy + b * st.wy, *iz = st.iz + b * st.wz;
    const double *px = st.phi_x + b * st.wx, *py = st.phi_y + b * st.wy, *pz = st.phi_z + b * st.wz;
    const double F0 = forces[3 * b], F1 = forces[3 * b + 1], F2 = forces[3 * b + 2];
    for (std::int64_t k = 0; k < st.wz; ++k) {
      if (pz[k] == 0.0) continue;
      for (std::int64_t j = 0; j < st.wy; ++j) {
        const double wyz = py[j] * pz[k];
        const std::int64_t base = iz[k] * plane + iy[j] * row;
        double *g0 = g.c[0] + base, *g1 = g.c[1] + base, *g2 = g.c[2] + base;
        for (std::int64_t i = 0; i < st.wx; ++i) {
          const double w = px[i] * wyz;
          g0[ix[i]] += w * F0;
          g1[ix[i]] += w * F1;
          g2[ix[i]] += w * F2;
        }
      }
    }
  });
}

// grid += (1/2) curl of the torques (n, 3) spread with the derivative kernels of the dipole stencil:
// g_x += (Tz Dy - Ty Dz)/2, g_y += (Tx Dz - Tz Dx)/2, g_z += (Ty Dx - Tx Dy)/2.
inline void spread_torques(const Stencil &st, const Stripes &stripes, const double *torques, Grid &g) {
  const std::int64_t plane = g.plane(), row = g.row;
  for_each_blob_by_stripes(stripes, [&](std::int64_t b) {
    const std::int32_t *ix = st.ix + b * st.wx, *iy = st.iy + b * st.wy, *iz = st.iz + b * st.wz;
    const double *px = st.phi_x + b * st.wx, *py = st.phi_y + b * st.wy, *pz = st.phi_z + b * st.wz;
    const double *dx = st.dphi_x + b * st.wx, *dy = st.dphi_y + b * st.wy, *dz = st.dphi_z + b * st.wz;
    const double Tx = 0.5 * torques[3 * b], Ty = 0.5 * torques[3 * b + 1], Tz = 0.5 * torques[3 * b + 2];
    for (std::int64_t k = 0; k < st.wz; ++k) {
      if (pz[k] == 0.0 && dz[k] == 0.0) continue;
      for (std::int64_t j = 0; j < st.wy; ++j) {
        const double yz = py[j] * pz[k], dyz = dy[j] * pz[k], ydz = py[j] * dz[k];
        const std::int64_t base = iz[k] * plane + iy[j] * row;
        double *g0 = g.c[0] + base, *g1 = g.c[1] + base, *g2 = g.c[2] + base;
        for (std::int64_t i = 0; i < st.wx; ++i) {
          const double Dx = dx[i] * yz, Dy = px[i] * dyz, Dz = px[i] * ydz;
          g0[ix[i]] += Tz * Dy - Ty * Dz;
          g1[ix[i]] += Tx * Dz - Tz * Dx;
          g2[ix[i]] += Ty * Dx - Tx * Dy;
        }
      }
    }
  });
}

// U (n, 3) = sum over each blob's nodes of u(node) phi_x phi_y qz, qz (n, wz) = phi_z times the quadrature
// weight of the node.
inline void interpolate_velocities(const Stencil &st, const double *qz_all, const Grid &g, double *U) {
  const std::int64_t plane = g.plane(), row = g.row;
#pragma omp parallel for schedule(static)
  for (std::int64_t b = 0; b < st.n; ++b) {
    const std::int32_t *ix = st.ix + b * st.wx, *iy = st.iy + b * st.wy, *iz = st.iz + b * st.wz;
    const double *px = st.phi_x + b * st.wx, *py = st.phi_y + b * st.wy, *qz = qz_all + b * st.wz;
    double u0 = 0.0, u1 = 0.0, u2 = 0.0;
    for (std::int64_t k = 0; k < st.wz; ++k) {
      if (qz[k] == 0.0) continue;
      for (std::int64_t j = 0; j < st.wy; ++j) {
        const double wyz = py[j] * qz[k];
        const std::int64_t base = iz[k] * plane + iy[j] * row;
        const double *g0 = g.c[0] + base, *g1 = g.c[1] + base, *g2 = g.c[2] + base;
        double s0 = 0.0, s1 = 0.0, s2 = 0.0;
        for (std::int64_t i = 0; i < st.wx; ++i) {
          s0 += px[i] * g0[ix[i]];
          s1 += px[i] * g1[ix[i]];
          s2 += px[i] * g2[ix[i]];
        }
        u0 += wyz * s0;
        u1 += wyz * s1;
        u2 += wyz * s2;
      }
    }
    U[3 * b] = u0;
    U[3 * b + 1] = u1;
    U[3 * b + 2] = u2;
  }
}

// W (n, 3) = -(1/2) curl of the velocity averaged with the derivative kernels: with G_c,a = sum u_a Dc q,
// W_x = -(G_y,z - G_z,y)/2, W_y = -(G_z,x - G_x,z)/2, W_z = -(G_x,y - G_y,x)/2.  qz and dqz (n, wz): phi_z
// and dphi_z times the quadrature weights.
inline void interpolate_rotations(const Stencil &st, const double *qz_all, const double *dqz_all, const Grid &g,
                                  double *W) {
  const std::int64_t plane = g.plane(), row = g.row;
#pragma omp parallel for schedule(static)
  for (std::int64_t b = 0; b < st.n; ++b) {
    const std::int32_t *ix = st.ix + b * st.wx, *iy = st.iy + b * st.wy, *iz = st.iz + b * st.wz;
    const double *px = st.phi_x + b * st.wx, *py = st.phi_y + b * st.wy;
    const double *dx = st.dphi_x + b * st.wx, *dy = st.dphi_y + b * st.wy;
    const double *qz = qz_all + b * st.wz, *dqz = dqz_all + b * st.wz;
    double G[3][3] = {{0.0, 0.0, 0.0}, {0.0, 0.0, 0.0}, {0.0, 0.0, 0.0}};  // G[derivative axis][component]
    for (std::int64_t k = 0; k < st.wz; ++k) {
      if (qz[k] == 0.0 && dqz[k] == 0.0) continue;
      for (std::int64_t j = 0; j < st.wy; ++j) {
        const std::int64_t base = iz[k] * plane + iy[j] * row;
        const double yz = py[j] * qz[k], dyz = dy[j] * qz[k], ydz = py[j] * dqz[k];
        for (int a = 0; a < 3; ++a) {
          const double *ga = g.c[a] + base;
          double sx = 0.0, sp = 0.0;
          for (std::int64_t i = 0; i < st.wx; ++i) {
            const double u = ga[ix[i]];
            sx += dx[i] * u;
            sp += px[i] * u;
          }
          G[0][a] += yz * sx;
          G[1][a] += dyz * sp;
          G[2][a] += ydz * sp;
        }
      }
    }
    W[3 * b] = -0.5 * (G[1][2] - G[2][1]);
    W[3 * b + 1] = -0.5 * (G[2][0] - G[0][2]);
    W[3 * b + 2] = -0.5 * (G[0][1] - G[1][0]);
  }
}

}  // namespace rmb_spectral
