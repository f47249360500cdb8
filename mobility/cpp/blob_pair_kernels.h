// Blob-pair mobility formulas shared by the C++ extension and the CUDA kernels.
//
// One source of truth for the compiled backends: the formulas are templates on
// the number type in blob_pair_formulas.inc, included here in namespace rmb
// (inline __host__ __device__ functions of doubles or floats: g++ compiles
// them into the C++ extensions' double code and NVRTC, through CuPy, into the
// GPU kernels) and again by simd_targets.h in the namespace of each vector
// path of the C++ kernels (simd_dispatch.h).  The NumPy reference of the same equations is
// mobility/pair_formulas.py; tests check the compiled code against it.
//
// Conventions (SPEC.md §4.1, §5.2; VALIDATION.md §1):
//   rx, ry, rz  target minus source, in units of the blob radius a
//   zt, zs      heights of target and source in units of a, already raised to
//               max(z, a); the wall image of the source is at -zs
//   results     trans-trans in units of 1/(8 pi eta a), rot-trans and
//               trans-rot 1/(8 pi eta a^2), rot-rot 1/(8 pi eta a^3)
// The Rotne-Prager-Yamakawa (RPY) free-space tensors are regularised for
// overlapping blobs; the wall corrections are those of Swan and Brady,
// Phys. Fluids 19, 113306 (2007), appendices B and C.  All formulas are
// branch-free: r = 0 uses a zero reciprocal distance, and the wall self term
// is the generic wall pair formula at rx = ry = 0 (they agree exactly).
#pragma once

// RMB_HD (__host__ __device__ under NVRTC, inline for g++) and the minimum image
// (rmb::minimum_image) come from pair_laws.h.
#include "pair_laws.h"

namespace rmb {

// The helpers the formulas of blob_pair_formulas.inc need in this namespace (double and float here; each
// kernel path's namespace has its own, with its vector type: simd_vector.inc).
RMB_HD double reciprocal_sqrt(double x) { return RMB_RSQRT(x); }

// Single precision (an option of the compiled backends; differences of
// positions are still taken in double before the pair formula).
#ifdef __CUDACC__
RMB_HD float reciprocal_sqrt(float x) { return rsqrtf(x); }
#else
inline float reciprocal_sqrt(float x) { return 1.0f / std::sqrt(x); }
#endif

RMB_HD double select(bool mask, double a, double b) { return mask ? a : b; }
RMB_HD float select(bool mask, float a, float b) { return mask ? a : b; }

// A constant in the working precision `Real` (double or float), so that
// single-precision formulas are not promoted to double.
template <class Real>
RMB_HD Real lit(double x) {
  return static_cast<Real>(Real{} + x);
}

#include "blob_pair_formulas.inc"

// 3x3 trans-trans block, row-major m[3 * a + b] (for dense matrices).
template <bool Wall>
RMB_HD void trans_trans_block(double rx, double ry, double rz, double zt, double zs, double *m) {
  double c_iso, c_rr;
  rpy_trans_trans(rx, ry, rz, c_iso, c_rr);
  const double r[3] = {rx, ry, rz};
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) m[3 * a + b] = (a == b ? c_iso : 0.0) + c_rr * r[a] * r[b];
  if (Wall) {
    const WallTT<double> c = wall_trans_trans(rx, ry, zt, zs);
    const double R[3] = {rx, ry, c.Rz};
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) m[3 * a + b] -= c.Rinv * ((a == b ? c.P1 : 0.0) + c.u * c.P2 * R[a] * R[b]);
    for (int a = 0; a < 3; ++a) {
      m[3 * a + 2] += c.Rinv * c.u * c.P3 * R[a];
      m[6 + a] += c.Rinv * c.u * c.P4 * R[a];
    }
    m[8] -= c.Rinv * c.P5;
  }
}

}  // namespace rmb
