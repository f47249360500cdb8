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

#ifdef __CUDACC__
#define RMB_HD __host__ __device__ __forceinline__
#define RMB_RSQRT(x) rsqrt(x)
#define RMB_SQRT(x) sqrt(x)
#else
#include <cmath>
#define RMB_HD inline
#define RMB_RSQRT(x) (1.0 / std::sqrt(x))
#define RMB_SQRT(x) std::sqrt(x)
#endif

namespace rmb {

// 1/sqrt(r2) (0 when r2 == 0) and 1/sqrt(R2) (R2 > 0, the image distance).
// (Sharing one division between the two, or a Newton-refined single-precision
// estimate, measured no faster on the CPU: the loop is bound by arithmetic.)
RMB_HD void two_reciprocal_sqrts(double r2, double R2, double &rinv, double &Rinv) {
  rinv = r2 > 0.0 ? RMB_RSQRT(r2) : 0.0;
  Rinv = RMB_RSQRT(R2);
}

// Free RPY trans-trans: M = c_iso I + c_rr r r^T (r unnormalised), given
// r2 = |r|^2 and rinv = 1/|r| (0 at r = 0).
RMB_HD void rpy_trans_trans_coefficients(double r2, double rinv, double &c_iso, double &c_rr) {
  const double rinv2 = rinv * rinv;
  const double r = r2 * rinv;
  const bool far = r2 >= 4.0;
  c_iso = far ? rinv * (1.0 + (2.0 / 3.0) * rinv2) : (4.0 / 3.0) * (1.0 - (9.0 / 32.0) * r);
  c_rr = far ? rinv * rinv2 * (1.0 - 2.0 * rinv2) : 0.125 * rinv;
}

RMB_HD void rpy_trans_trans(double rx, double ry, double rz, double &c_iso, double &c_rr) {
  const double r2 = rx * rx + ry * ry + rz * rz;
  rpy_trans_trans_coefficients(r2, r2 > 0.0 ? RMB_RSQRT(r2) : 0.0, c_iso, c_rr);
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
struct WallTT {
  double Rz, Rinv, u, P1, P2, P3, P4, P5;
};

// Given the image vector's z component Rz = zt + zs and Rinv = 1/|R|.
RMB_HD WallTT wall_trans_trans_coefficients(double Rz, double Rinv, double zt, double zs) {
  WallTT c;
  c.Rz = Rz;
  c.Rinv = Rinv;
  const double u = c.Rinv * c.Rinv;
  const double w = c.Rz * c.Rz * u;
  const double q = zt * zs * u;
  const double h = zs;
  c.u = u;
  c.P1 = 1.0 + 2.0 * q + (2.0 / 3.0) * u * ((1.0 - 3.0 * w) - u * (1.0 - 5.0 * w));
  c.P2 = 1.0 - 6.0 * q + u * (-2.0 * (1.0 - 5.0 * w) + (10.0 / 3.0) * u * (1.0 - 7.0 * w));
  c.P3 = 2.0 * h * (1.0 - 6.0 * w + 6.0 * h * c.Rz * u) +
         c.Rz * u * (-4.0 * (1.0 - 5.0 * w) + (20.0 / 3.0) * u * (2.0 - 7.0 * w));
  c.P4 = 2.0 * h - (20.0 / 3.0) * c.Rz * u * u;
  c.P5 = u * (4.0 * (h * h + w) + (4.0 / 3.0) * u * (2.0 - 15.0 * w));
  return c;
}

RMB_HD WallTT wall_trans_trans(double rx, double ry, double zt, double zs) {
  const double Rz = zt + zs;
  return wall_trans_trans_coefficients(Rz, RMB_RSQRT(rx * rx + ry * ry + Rz * Rz), zt, zs);
}

// u += M_tt(target, source) f.
template <bool Wall>
RMB_HD void trans_times_force_pair(double rx, double ry, double rz, double zt, double zs, double fx, double fy,
                                   double fz, double &ux, double &uy, double &uz) {
  double c_iso, c_rr;
  rpy_trans_trans(rx, ry, rz, c_iso, c_rr);
  const double rf = c_rr * (rx * fx + ry * fy + rz * fz);
  ux += c_iso * fx + rf * rx;
  uy += c_iso * fy + rf * ry;
  uz += c_iso * fz + rf * rz;
  if (Wall) {
    const WallTT c = wall_trans_trans(rx, ry, zt, zs);
    const double Rf = rx * fx + ry * fy + c.Rz * fz;
    const double along = c.u * (c.P3 * fz - c.P2 * Rf);
    ux += c.Rinv * (along * rx - c.P1 * fx);
    uy += c.Rinv * (along * ry - c.P1 * fy);
    uz += c.Rinv * (along * c.Rz - c.P1 * fz + c.u * c.P4 * Rf - c.P5 * fz);
  }
}

// Both halves of a pair at once, using the symmetry of the mobility:
// u_t += M_ts f_s and u_s += M_ts^T f_t (the transpose swaps P3 and P4).
template <bool Wall>
RMB_HD void trans_times_force_pair_both(double rx, double ry, double rz, double zt, double zs, double fsx,
                                        double fsy, double fsz, double ftx, double fty, double ftz, double &utx,
                                        double &uty, double &utz, double &usx, double &usy, double &usz) {
  const double r2 = rx * rx + ry * ry + rz * rz;
  const double Rz = zt + zs;
  double rinv, Rinv;
  if (Wall)
    two_reciprocal_sqrts(r2, rx * rx + ry * ry + Rz * Rz, rinv, Rinv);
  else
    rinv = r2 > 0.0 ? RMB_RSQRT(r2) : 0.0;
  double c_iso, c_rr;
  rpy_trans_trans_coefficients(r2, rinv, c_iso, c_rr);
  const double rfs = c_rr * (rx * fsx + ry * fsy + rz * fsz);
  const double rft = c_rr * (rx * ftx + ry * fty + rz * ftz);
  utx += c_iso * fsx + rfs * rx;
  uty += c_iso * fsy + rfs * ry;
  utz += c_iso * fsz + rfs * rz;
  usx += c_iso * ftx + rft * rx;
  usy += c_iso * fty + rft * ry;
  usz += c_iso * ftz + rft * rz;
  if (Wall) {
    const WallTT c = wall_trans_trans_coefficients(Rz, Rinv, zt, zs);
    const double Rfs = rx * fsx + ry * fsy + c.Rz * fsz;
    const double Rft = rx * ftx + ry * fty + c.Rz * ftz;
    const double along_s = c.u * (c.P3 * fsz - c.P2 * Rfs);
    const double along_t = c.u * (c.P4 * ftz - c.P2 * Rft);
    utx += c.Rinv * (along_s * rx - c.P1 * fsx);
    uty += c.Rinv * (along_s * ry - c.P1 * fsy);
    utz += c.Rinv * (along_s * c.Rz - c.P1 * fsz + c.u * c.P4 * Rfs - c.P5 * fsz);
    usx += c.Rinv * (along_t * rx - c.P1 * ftx);
    usy += c.Rinv * (along_t * ry - c.P1 * fty);
    usz += c.Rinv * (along_t * c.Rz - c.P1 * ftz + c.u * c.P3 * Rft - c.P5 * ftz);
  }
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
    const WallTT c = wall_trans_trans(rx, ry, zt, zs);
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

// Velocity of a target of radius b from a force on a source of radius as, in
// physical units (result in units of 1/(8 pi eta)); heights already raised to
// max(z, radius).  Free part: RPY for unequal spheres (Zuk et al., J. Fluid
// Mech. 741, R5, 2014) with overlap and containment branches.  Wall part: the
// image system with Faxen corrections for both radii, block -W P with
// P = diag(1, 1, -1); see mobility/pair_formulas.py for W term by term.
template <bool Wall>
RMB_HD void source_target_pair(double rx, double ry, double rz, double zt, double zs, double b, double as,
                               double fx, double fy, double fz, double &ux, double &uy, double &uz) {
  const double r2 = rx * rx + ry * ry + rz * rz;
  const double rinv = r2 > 0.0 ? RMB_RSQRT(r2) : 0.0;
  const double rinv2 = rinv * rinv;
  const double r = r2 * rinv;
  const double s = b * b + as * as;
  const double diff = b - as;
  double c_iso, c_rr;
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
  const double rf = c_rr * (rx * fx + ry * fy + rz * fz);
  ux += c_iso * fx + rf * rx;
  uy += c_iso * fy + rf * ry;
  uz += c_iso * fz + rf * rz;
  if (Wall) {
    const double Rz = zt + zs;
    const double Rinv = RMB_RSQRT(rx * rx + ry * ry + Rz * Rz);
    const double Rinv2 = Rinv * Rinv, Rinv3 = Rinv2 * Rinv, Rinv5 = Rinv3 * Rinv2;
    const double Rinv7 = Rinv5 * Rinv2, Rinv9 = Rinv7 * Rinv2;
    const double b2 = b * b, a2 = as * as, ab = a2 * b2;
    const double cb = 2.0 * b2 / 3.0, ca = 2.0 * a2 / 3.0, cab = 2.0 * ab / 3.0;
    const double w_I = Rinv * (1.0 + s * Rinv2 / 3.0) + 2.0 * zt * zs * Rinv3 - cb * zs * 3.0 * Rz * Rinv5 -
                       ca * zt * 3.0 * Rz * Rinv5 + cab * (-Rinv5 + 5.0 * Rz * Rz * Rinv7);
    const double w_RR = Rinv3 * (1.0 - s * Rinv2) - 6.0 * zt * zs * Rinv5 + cb * zs * 15.0 * Rz * Rinv7 +
                        ca * zt * 15.0 * Rz * Rinv7 + cab * (5.0 * Rinv7 - 35.0 * Rz * Rz * Rinv9);
    const double w_J = -2.0 * Rinv - cb * Rinv3 - ca * Rinv3 - 2.0 * cab * Rinv5;
    const double w_Rz = -2.0 * zt * Rinv3 + cb * 3.0 * (Rz - zs) * Rinv5 - ca * zt * 3.0 * Rinv5 + cab * 10.0 * Rz * Rinv7;
    const double w_zR = -2.0 * zs * Rinv3 - cb * zs * 3.0 * Rinv5 + ca * 3.0 * (Rz - zt) * Rinv5 + cab * 10.0 * Rz * Rinv7;
    const double gz = -fz;
    const double Rg = rx * fx + ry * fy + Rz * gz;
    ux -= w_I * fx + (w_RR * Rg + w_Rz * gz) * rx;
    uy -= w_I * fy + (w_RR * Rg + w_Rz * gz) * ry;
    uz -= w_I * gz + (w_RR * Rg + w_Rz * gz) * Rz + w_J * gz + w_zR * Rg;
  }
}

// Minimum image, round half away from zero (SPEC §8); L <= 0: not periodic.
RMB_HD double minimum_image(double d, double L) {
  if (L > 0.0) {
    const double t = d / L + (d > 0.0 ? 0.5 : (d < 0.0 ? -0.5 : 0.0));
    d -= static_cast<double>(static_cast<long long>(t)) * L;
  }
  return d;
}

}  // namespace rmb
