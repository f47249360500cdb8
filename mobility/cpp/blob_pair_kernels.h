// Blob-pair mobility formulas shared by the C++ extension and the CUDA kernels.
//
// One source of truth for the compiled backends: every function here is an
// inline __host__ __device__ function of plain doubles, so the same text is
// compiled by g++ into mobility/_mobility_cpp and by NVRTC (through CuPy)
// into the GPU kernels.  The NumPy reference of the same equations is
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

// 1/sqrt(x).  The trans-trans formulas below are templates on the number type
// `Real`: double everywhere, and on CPUs with AVX-512 also a vector of eight
// doubles (GCC vector extension), which the C++ backend uses for its hottest
// loop.  For that type the reciprocal square root is the hardware estimate
// (relative error < 2^-14) refined by two Newton steps y <- y (3 - x y^2)/2,
// which square the error each time (2^-14 -> 2^-27 -> rounding): no vector
// division or square root, which would otherwise take a quarter of the time.
RMB_HD double reciprocal_sqrt(double x) { return RMB_RSQRT(x); }

// Single precision (an option of the compiled backends; differences of
// positions are still taken in double before the pair formula).
#ifdef __CUDACC__
RMB_HD float reciprocal_sqrt(float x) { return rsqrtf(x); }
#else
inline float reciprocal_sqrt(float x) { return 1.0f / std::sqrt(x); }
#endif

// A constant in the working precision `Real` (double, float or double8), so
// that single-precision formulas are not promoted to double.
template <class Real>
RMB_HD Real lit(double x) {
  return static_cast<Real>(Real{} + x);
}

#if defined(__AVX512F__) && !defined(__CUDACC__)
}  // namespace rmb
#include <immintrin.h>
namespace rmb {
typedef double double8 __attribute__((vector_size(64)));
inline double8 reciprocal_sqrt(double8 x) {
  double8 y = reinterpret_cast<double8>(_mm512_rsqrt14_pd(reinterpret_cast<__m512d>(x)));
  const double8 half_x = 0.5 * x;
  y = y * (1.5 - half_x * y * y);
  y = y * (1.5 - half_x * y * y);
  return y;
}

// Eight doubles from / to memory of any alignment.
inline double8 load8(const double *p) {
  double8 v;
  __builtin_memcpy(&v, p, sizeof v);
  return v;
}

inline void store8(double *p, double8 v) { __builtin_memcpy(p, &v, sizeof v); }
#endif

// 1/sqrt(r2) (0 when r2 == 0) and 1/sqrt(R2) (R2 > 0, the image distance).
template <class Real>
RMB_HD void two_reciprocal_sqrts(Real r2, Real R2, Real &rinv, Real &Rinv) {
  rinv = r2 > lit<Real>(0.0) ? reciprocal_sqrt(r2) : Real{};
  Rinv = reciprocal_sqrt(R2);
}

// Free RPY trans-trans: M = c_iso I + c_rr r r^T (r unnormalised), given
// r2 = |r|^2 and rinv = 1/|r| (0 at r = 0).
template <class Real>
RMB_HD void rpy_trans_trans_coefficients(Real r2, Real rinv, Real &c_iso, Real &c_rr) {
  const Real one = lit<Real>(1.0);
  const Real rinv2 = rinv * rinv;
  const Real r = r2 * rinv;
  const auto far = r2 >= lit<Real>(4.0);
  c_iso = far ? rinv * (one + lit<Real>(2.0 / 3.0) * rinv2) : lit<Real>(4.0 / 3.0) * (one - lit<Real>(9.0 / 32.0) * r);
  c_rr = far ? rinv * rinv2 * (one - lit<Real>(2.0) * rinv2) : lit<Real>(0.125) * rinv;
}

RMB_HD void rpy_trans_trans(double rx, double ry, double rz, double &c_iso, double &c_rr) {
  const double r2 = rx * rx + ry * ry + rz * rz;
  rpy_trans_trans_coefficients(r2, r2 > 0.0 ? reciprocal_sqrt(r2) : 0.0, c_iso, c_rr);
}

// Swan-Brady wall correction to trans-trans,
//   dM_ab = f1 d_ab + f2 e_a e_b + f3 e_a d_bz + f4 d_az e_b + f5 d_az d_bz,
// e the unit vector from the source's image to the target, rewritten in the
// unnormalised image vector R = (rx, ry, zt + zs) with u = 1/|R|^2,
// w = Rz^2 u, q = zt zs u, h = zs (PERFORMANCE.md, design rule 2):
//   f1 = -P1/|R|, f2 e e^T = -u P2 R R^T/|R|, f3 e = u P3 R/|R|,
//   f4 e = u P4 R/|R|, f5 = -P5/|R|, so that
//   dM f = (1/|R|) [ -P1 f + u (P3 f_z - P2 R.f) R + (u P4 R.f - P5 f_z) z ].
// One reciprocal square root is the only division.
template <class Real>
struct WallTT {
  Real Rz, Rinv, u, P1, P2, P3, P4, P5;
};

// Given the image vector's z component Rz = zt + zs and Rinv = 1/|R|.
template <class Real>
RMB_HD WallTT<Real> wall_trans_trans_coefficients(Real Rz, Real Rinv, Real zt, Real zs) {
  WallTT<Real> c;
  c.Rz = Rz;
  c.Rinv = Rinv;
  const Real u = Rinv * Rinv;
  const Real w = Rz * Rz * u;
  const Real q = zt * zs * u;
  const Real h = zs;
  c.u = u;
  const Real one = lit<Real>(1.0), two = lit<Real>(2.0);
  const Real one_5w = one - lit<Real>(5.0) * w;
  c.P1 = one + two * q + lit<Real>(2.0 / 3.0) * u * ((one - lit<Real>(3.0) * w) - u * one_5w);
  c.P2 = one - lit<Real>(6.0) * q + u * (-two * one_5w + lit<Real>(10.0 / 3.0) * u * (one - lit<Real>(7.0) * w));
  c.P3 = two * h * (one - lit<Real>(6.0) * w + lit<Real>(6.0) * h * Rz * u) +
         Rz * u * (lit<Real>(-4.0) * one_5w + lit<Real>(20.0 / 3.0) * u * (two - lit<Real>(7.0) * w));
  c.P4 = two * h - lit<Real>(20.0 / 3.0) * Rz * u * u;
  c.P5 = u * (lit<Real>(4.0) * (h * h + w) + lit<Real>(4.0 / 3.0) * u * (two - lit<Real>(15.0) * w));
  return c;
}

RMB_HD WallTT<double> wall_trans_trans(double rx, double ry, double zt, double zs) {
  const double Rz = zt + zs;
  return wall_trans_trans_coefficients(Rz, reciprocal_sqrt(rx * rx + ry * ry + Rz * Rz), zt, zs);
}

// The trans-trans block applied to a vector, free part and wall part merged:
// with A = c_iso - P1/|R|, a_k = u P_k/|R| (k = 2, 3, 4), a5 = P5/|R|, the
// x and y components of M f are A f + (c_rr r.f + a3 f_z - a2 R.f) r, and
// the z component adds (c_rr r.f) r_z + (a3 f_z - a2 R.f) R_z + a4 R.f - a5 f_z.
// The transpose swaps a3 and a4.
template <class Real>
struct TransTransBlock {
  Real A, c_rr, a2, a3, a4, a5, Rz;
};

template <bool Wall, class Real>
RMB_HD TransTransBlock<Real> trans_trans_coefficients(Real rx, Real ry, Real rz, Real zt, Real zs) {
  const Real rxy2 = rx * rx + ry * ry;
  const Real r2 = rxy2 + rz * rz;
  TransTransBlock<Real> b;
  Real rinv, c_iso;
  if (Wall) {
    b.Rz = zt + zs;
    Real Rinv;
    two_reciprocal_sqrts(r2, rxy2 + b.Rz * b.Rz, rinv, Rinv);
    rpy_trans_trans_coefficients(r2, rinv, c_iso, b.c_rr);
    const WallTT<Real> w = wall_trans_trans_coefficients(b.Rz, Rinv, zt, zs);
    const Real Rinv_u = Rinv * w.u;
    b.A = c_iso - Rinv * w.P1;
    b.a2 = Rinv_u * w.P2;
    b.a3 = Rinv_u * w.P3;
    b.a4 = Rinv_u * w.P4;
    b.a5 = Rinv * w.P5;
  } else {
    rinv = r2 > lit<Real>(0.0) ? reciprocal_sqrt(r2) : Real{};
    rpy_trans_trans_coefficients(r2, rinv, b.A, b.c_rr);
  }
  return b;
}

// u += B f (Transposed = false) or u += B^T f (Transposed = true).
template <bool Wall, bool Transposed, class Real>
RMB_HD void apply_trans_trans(const TransTransBlock<Real> &b, Real rx, Real ry, Real rz, Real fx, Real fy, Real fz,
                              Real &ux, Real &uy, Real &uz) {
  const Real xy = rx * fx + ry * fy;
  const Real free_along = b.c_rr * (xy + rz * fz);
  if (Wall) {
    const Real Rf = xy + b.Rz * fz;
    const Real wall_along = (Transposed ? b.a4 : b.a3) * fz - b.a2 * Rf;
    const Real along = free_along + wall_along;
    ux += b.A * fx + along * rx;
    uy += b.A * fy + along * ry;
    uz += b.A * fz + free_along * rz + wall_along * b.Rz + (Transposed ? b.a3 : b.a4) * Rf - b.a5 * fz;
  } else {
    ux += b.A * fx + free_along * rx;
    uy += b.A * fy + free_along * ry;
    uz += b.A * fz + free_along * rz;
  }
}

// u += M_tt(target, source) f.
template <bool Wall, class Real = double>
RMB_HD void trans_times_force_pair(Real rx, Real ry, Real rz, Real zt, Real zs, Real fx, Real fy, Real fz, Real &ux,
                                   Real &uy, Real &uz) {
  const TransTransBlock<Real> b = trans_trans_coefficients<Wall>(rx, ry, rz, zt, zs);
  apply_trans_trans<Wall, false>(b, rx, ry, rz, fx, fy, fz, ux, uy, uz);
}

// Both halves of a pair at once, using the symmetry of the mobility:
// u_t += M_ts f_s and u_s += M_ts^T f_t.
template <bool Wall, class Real = double>
RMB_HD void trans_times_force_pair_both(Real rx, Real ry, Real rz, Real zt, Real zs, Real fsx, Real fsy, Real fsz,
                                        Real ftx, Real fty, Real ftz, Real &utx, Real &uty, Real &utz, Real &usx,
                                        Real &usy, Real &usz) {
  const TransTransBlock<Real> b = trans_trans_coefficients<Wall>(rx, ry, rz, zt, zs);
  apply_trans_trans<Wall, false>(b, rx, ry, rz, fsx, fsy, fsz, utx, uty, utz);
  apply_trans_trans<Wall, true>(b, rx, ry, rz, ftx, fty, ftz, usx, usy, usz);
}

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

// Free RPY rot-trans: omega_t = c (F_s x r).
RMB_HD double rpy_rot_trans(double rx, double ry, double rz) {
  const double r2 = rx * rx + ry * ry + rz * rz;
  const double rinv = r2 > 0.0 ? RMB_RSQRT(r2) : 0.0;
  return r2 >= 4.0 ? rinv * rinv * rinv : 0.5 * (1.0 - 0.375 * r2 * rinv);
}

// Wall correction to rot-trans (omega_t from F_s):
//   omega = -k1 (F x e) - (k2 F_z + k3 e.F) (z x e) - k4 (F_y, -F_x, 0).
struct WallRT {
  double ex, ey, ez, k1, k2, k3, k4;
};

RMB_HD WallRT wall_rot_trans(double rx, double ry, double zt, double zs) {
  WallRT w;
  const double Rz = zt + zs;
  const double Rinv = RMB_RSQRT(rx * rx + ry * ry + Rz * Rz);
  const double Rinv2 = Rinv * Rinv;
  const double Rinv4 = Rinv2 * Rinv2;
  w.ex = rx * Rinv;
  w.ey = ry * Rinv;
  w.ez = Rz * Rinv;
  const double ez2 = w.ez * w.ez;
  const double p = zs * Rinv;  // h_hat e_z
  w.k1 = Rinv2;
  w.k2 = 2.0 * (6.0 * p * w.ez * Rinv2 + (1.0 - 10.0 * ez2) * Rinv4);
  w.k3 = -2.0 * (3.0 * p * Rinv2 - 5.0 * w.ez * Rinv4);
  w.k4 = -2.0 * (p * Rinv2 - w.ez * Rinv4);
  return w;
}

template <bool Wall>
RMB_HD void rot_times_force_pair(double rx, double ry, double rz, double zt, double zs, double fx, double fy,
                                 double fz, double &wx, double &wy, double &wz) {
  const double c = rpy_rot_trans(rx, ry, rz);
  wx += c * (fy * rz - fz * ry);
  wy += c * (fz * rx - fx * rz);
  wz += c * (fx * ry - fy * rx);
  if (Wall) {
    const WallRT w = wall_rot_trans(rx, ry, zt, zs);
    const double along = w.k2 * fz + w.k3 * (w.ex * fx + w.ey * fy + w.ez * fz);
    wx -= w.k1 * (fy * w.ez - fz * w.ey) - along * w.ey + w.k4 * fy;
    wy -= w.k1 * (fz * w.ex - fx * w.ez) + along * w.ex - w.k4 * fx;
    wz -= w.k1 * (fx * w.ey - fy * w.ex);
  }
}

// u_t += M_UT(t, s) T_s = M_WF(s, t)^T T_s: the rot-trans geometry seen from
// the source (displacement -r, heights swapped), applied transposed.
template <bool Wall>
RMB_HD void trans_times_torque_pair(double rx, double ry, double rz, double zt, double zs, double tx, double ty,
                                    double tz, double &ux, double &uy, double &uz) {
  const double c = rpy_rot_trans(rx, ry, rz);
  ux += c * (ty * rz - tz * ry);
  uy += c * (tz * rx - tx * rz);
  uz += c * (tx * ry - ty * rx);
  if (Wall) {
    const WallRT w = wall_rot_trans(-rx, -ry, zs, zt);
    const double zxe_t = -w.ey * tx + w.ex * ty;
    ux += w.k1 * (ty * w.ez - tz * w.ey) - w.k3 * zxe_t * w.ex + w.k4 * ty;
    uy += w.k1 * (tz * w.ex - tx * w.ez) - w.k3 * zxe_t * w.ey - w.k4 * tx;
    uz += w.k1 * (tx * w.ey - ty * w.ex) - (w.k2 + w.k3 * w.ez) * zxe_t;
  }
}

// Rot-rot: free RPY d_iso I + d_rr r r^T, plus the wall correction
//   g [ (1 - 6 e_z^2)/2 I - (3/2) e e^T + 3 e_z z e^T + 3 (z x e)(z x e)^T ], g = |R|^-3.
template <bool Wall>
RMB_HD void rot_times_torque_pair(double rx, double ry, double rz, double zt, double zs, double tx, double ty,
                                  double tz, double &wx, double &wy, double &wz) {
  const double r2 = rx * rx + ry * ry + rz * rz;
  const double rinv = r2 > 0.0 ? RMB_RSQRT(r2) : 0.0;
  const double rinv2 = rinv * rinv;
  const double r = r2 * rinv;
  const bool far = r2 >= 4.0;
  const double d_iso = far ? -0.5 * rinv * rinv2 : 1.0 - (27.0 / 32.0) * r + (5.0 / 64.0) * r * r2;
  const double d_rr = far ? 1.5 * rinv * rinv2 * rinv2 : (9.0 / 32.0) * rinv - (3.0 / 64.0) * r;
  const double rt = d_rr * (rx * tx + ry * ty + rz * tz);
  wx += d_iso * tx + rt * rx;
  wy += d_iso * ty + rt * ry;
  wz += d_iso * tz + rt * rz;
  if (Wall) {
    const double Rz = zt + zs;
    const double Rinv = RMB_RSQRT(rx * rx + ry * ry + Rz * Rz);
    const double ex = rx * Rinv, ey = ry * Rinv, ez = Rz * Rinv;
    const double g = Rinv * Rinv * Rinv;
    const double et = ex * tx + ey * ty + ez * tz;
    const double zxe_t = -ey * tx + ex * ty;
    const double iso = 0.5 * (1.0 - 6.0 * ez * ez);
    wx += g * (iso * tx - 1.5 * et * ex - 3.0 * zxe_t * ey);
    wy += g * (iso * ty - 1.5 * et * ey + 3.0 * zxe_t * ex);
    wz += g * (iso * tz - 1.5 * et * ez + 3.0 * ez * et);
  }
}

// Free part of the RPY tensor for unequal spheres (Zuk, Wajnryb, Mizerski and
// Szymczak, J. Fluid Mech. 741, R5, 2014), physical units, result in units of
// 1/(8 pi eta): M = c_iso I + c_rr r r^T for a target of radius b and a
// source of radius as at distance^2 r2, with its overlap and containment
// branches (equal radii: the standard RPY tensor, self term 4/(3a) I).
RMB_HD void unequal_rpy_coefficients(double r2, double b, double as, double &c_iso, double &c_rr) {
  const double rinv = r2 > 0.0 ? RMB_RSQRT(r2) : 0.0;
  const double rinv2 = rinv * rinv;
  const double r = r2 * rinv;
  const double s = b * b + as * as;
  const double diff = b - as;
  if (r >= b + as) {
    c_iso = rinv * (1.0 + s * rinv2 / 3.0);
    c_rr = rinv * rinv2 * (1.0 - s * rinv2);
  } else if (r > (diff > 0.0 ? diff : -diff)) {
    const double pref = (4.0 / 3.0) / (b * as);
    const double rinv3 = rinv2 * rinv;
    const double q = diff * diff + 3.0 * r2;
    const double t = diff * diff - r2;
    c_iso = pref * (16.0 * (b + as) * r * r2 - q * q) * rinv3 / 32.0;
    c_rr = pref * 3.0 * t * t * rinv3 * rinv2 / 32.0;
  } else {
    c_iso = (4.0 / 3.0) / (b > as ? b : as);
    c_rr = 0.0;
  }
}

// Velocity of a target of radius b from a force on a source of radius as, in
// physical units (result in units of 1/(8 pi eta)); heights already raised to
// max(z, radius).  Free part: unequal_rpy_coefficients.  Wall part: the
// image system with Faxen corrections for both radii, block -W P with
// P = diag(1, 1, -1); see mobility/pair_formulas.py for W term by term.
// Image-system coefficients of the unequal-radii wall correction:
//   W = w_I I + w_RR R R^T + w_J z z^T + w_Rz R z^T + w_zR z R^T,  block -W P,
// R = (rx, ry, zt + zs), target radius b, source radius as.
struct RadiiWall {
  double Rz, w_I, w_RR, w_J, w_Rz, w_zR;
};

RMB_HD RadiiWall radii_wall_coefficients(double rx, double ry, double zt, double zs, double b, double as) {
  RadiiWall c;
  const double s = b * b + as * as;
  const double Rz = zt + zs;
  c.Rz = Rz;
  const double Rinv = RMB_RSQRT(rx * rx + ry * ry + Rz * Rz);
  const double Rinv2 = Rinv * Rinv, Rinv3 = Rinv2 * Rinv, Rinv5 = Rinv3 * Rinv2;
  const double Rinv7 = Rinv5 * Rinv2, Rinv9 = Rinv7 * Rinv2;
  const double b2 = b * b, a2 = as * as, ab = a2 * b2;
  const double cb = 2.0 * b2 / 3.0, ca = 2.0 * a2 / 3.0, cab = 2.0 * ab / 3.0;
  c.w_I = Rinv * (1.0 + s * Rinv2 / 3.0) + 2.0 * zt * zs * Rinv3 - cb * zs * 3.0 * Rz * Rinv5 -
          ca * zt * 3.0 * Rz * Rinv5 + cab * (-Rinv5 + 5.0 * Rz * Rz * Rinv7);
  c.w_RR = Rinv3 * (1.0 - s * Rinv2) - 6.0 * zt * zs * Rinv5 + cb * zs * 15.0 * Rz * Rinv7 +
           ca * zt * 15.0 * Rz * Rinv7 + cab * (5.0 * Rinv7 - 35.0 * Rz * Rz * Rinv9);
  c.w_J = -2.0 * Rinv - cb * Rinv3 - ca * Rinv3 - 2.0 * cab * Rinv5;
  c.w_Rz = -2.0 * zt * Rinv3 + cb * 3.0 * (Rz - zs) * Rinv5 - ca * zt * 3.0 * Rinv5 + cab * 10.0 * Rz * Rinv7;
  c.w_zR = -2.0 * zs * Rinv3 - cb * zs * 3.0 * Rinv5 + ca * 3.0 * (Rz - zt) * Rinv5 + cab * 10.0 * Rz * Rinv7;
  return c;
}

// u += -W P f (Transposed = false) or u += (-W P)^T f = -P W^T f (Transposed = true).
template <bool Transposed>
RMB_HD void apply_radii_wall(const RadiiWall &c, double rx, double ry, double fx, double fy, double fz, double &ux,
                             double &uy, double &uz) {
  if (!Transposed) {
    const double gz = -fz;
    const double Rg = rx * fx + ry * fy + c.Rz * gz;
    const double along = c.w_RR * Rg + c.w_Rz * gz;
    ux -= c.w_I * fx + along * rx;
    uy -= c.w_I * fy + along * ry;
    uz -= c.w_I * gz + along * c.Rz + c.w_J * gz + c.w_zR * Rg;
  } else {
    const double Rf = rx * fx + ry * fy + c.Rz * fz;
    const double along = c.w_RR * Rf + c.w_zR * fz;
    ux -= c.w_I * fx + along * rx;
    uy -= c.w_I * fy + along * ry;
    uz += c.w_I * fz + along * c.Rz + c.w_J * fz + c.w_Rz * Rf;
  }
}

// Velocity of a target of radius b from a force on a source of radius as, in
// physical units (result in units of 1/(8 pi eta)); heights already raised to
// max(z, radius).  Free part: unequal_rpy_coefficients.  Wall part: the
// image system with Faxen corrections for both radii, block -W P with
// P = diag(1, 1, -1) (radii_wall_coefficients; see mobility/pair_formulas.py
// for W term by term).
template <bool Wall>
RMB_HD void source_target_pair(double rx, double ry, double rz, double zt, double zs, double b, double as,
                               double fx, double fy, double fz, double &ux, double &uy, double &uz) {
  double c_iso, c_rr;
  unequal_rpy_coefficients(rx * rx + ry * ry + rz * rz, b, as, c_iso, c_rr);
  const double rf = c_rr * (rx * fx + ry * fy + rz * fz);
  ux += c_iso * fx + rf * rx;
  uy += c_iso * fy + rf * ry;
  uz += c_iso * fz + rf * rz;
  if (Wall) apply_radii_wall<false>(radii_wall_coefficients(rx, ry, zt, zs, b, as), rx, ry, fx, fy, fz, ux, uy, uz);
}

// Both halves of a pair of blobs of radii b (target t) and as (source s), using the
// symmetry of the mobility: u_t += M_ts f_s and u_s += M_ts^T f_t (= M_st f_t).
template <bool Wall>
RMB_HD void source_target_pair_both(double rx, double ry, double rz, double zt, double zs, double b, double as,
                                    double fsx, double fsy, double fsz, double ftx, double fty, double ftz,
                                    double &utx, double &uty, double &utz, double &usx, double &usy, double &usz) {
  double c_iso, c_rr;
  unequal_rpy_coefficients(rx * rx + ry * ry + rz * rz, b, as, c_iso, c_rr);
  const double rfs = c_rr * (rx * fsx + ry * fsy + rz * fsz);
  const double rft = c_rr * (rx * ftx + ry * fty + rz * ftz);
  utx += c_iso * fsx + rfs * rx;
  uty += c_iso * fsy + rfs * ry;
  utz += c_iso * fsz + rfs * rz;
  usx += c_iso * ftx + rft * rx;
  usy += c_iso * fty + rft * ry;
  usz += c_iso * ftz + rft * rz;
  if (Wall) {
    const RadiiWall c = radii_wall_coefficients(rx, ry, zt, zs, b, as);
    apply_radii_wall<false>(c, rx, ry, fsx, fsy, fsz, utx, uty, utz);
    apply_radii_wall<true>(c, rx, ry, ftx, fty, ftz, usx, usy, usz);
  }
}

// Free-slip (free) surface at z = 0, blobs in z > 0: the RPY tensor of the
// pair plus that of the target with the mirror image of the source, applied
// to the mirrored force (fx, fy, -fz).  The image vector is
// R = (rx, ry, zt + zs).  No height regularisation: the sum is a congruence
// of the RPY tensor of blobs and images, positive definite at any height.
// Equal radii (units of a, result 1/(8 pi eta a)):
RMB_HD void free_surface_pair(double rx, double ry, double rz, double zt, double zs, double fx, double fy,
                              double fz, double &ux, double &uy, double &uz) {
  double c_iso, c_rr;
  rpy_trans_trans(rx, ry, rz, c_iso, c_rr);
  double rf = c_rr * (rx * fx + ry * fy + rz * fz);
  ux += c_iso * fx + rf * rx;
  uy += c_iso * fy + rf * ry;
  uz += c_iso * fz + rf * rz;
  const double Rz = zt + zs;
  rpy_trans_trans(rx, ry, Rz, c_iso, c_rr);
  rf = c_rr * (rx * fx + ry * fy - Rz * fz);
  ux += c_iso * fx + rf * rx;
  uy += c_iso * fy + rf * ry;
  uz += -c_iso * fz + rf * Rz;
}

// Unequal radii (physical units, result 1/(8 pi eta)): target radius b, source radius as.
RMB_HD void source_target_free_surface_pair(double rx, double ry, double rz, double zt, double zs, double b,
                                            double as, double fx, double fy, double fz, double &ux, double &uy,
                                            double &uz) {
  double c_iso, c_rr;
  unequal_rpy_coefficients(rx * rx + ry * ry + rz * rz, b, as, c_iso, c_rr);
  double rf = c_rr * (rx * fx + ry * fy + rz * fz);
  ux += c_iso * fx + rf * rx;
  uy += c_iso * fy + rf * ry;
  uz += c_iso * fz + rf * rz;
  const double Rz = zt + zs;
  unequal_rpy_coefficients(rx * rx + ry * ry + Rz * Rz, b, as, c_iso, c_rr);
  rf = c_rr * (rx * fx + ry * fy - Rz * fz);
  ux += c_iso * fx + rf * rx;
  uy += c_iso * fy + rf * ry;
  uz += -c_iso * fz + rf * Rz;
}

}  // namespace rmb
