// The pair laws of the compiled backends, written once (SPEC sections 7, 8, 9).
//
// Every function is an inline __host__ __device__ function of plain doubles:
// g++ compiles it into the C++ extensions (mobility/_mobility_cpp,
// multi_bodies/solver/_forces_cpp, many_bodyMCMC/_energy_cpp) and NVRTC into
// the CUDA kernels (mobility/cuda/mobility_kernels.cu includes it; the CuPy
// kernels held as Python strings, multi_bodies/solver/forces_pycuda.py and
// many_bodyMCMC/mcmc_cuda.py, prepend this file's text to their source).
// The NumPy counterparts are mobility/periodic.py (minimum image, wall
// regularisation) and multi_bodies/solver/physics.py (forces and energies);
// tests/test_pair_laws.py checks force = -grad U and C++ = Python.
//
// Laws (eps strength, b Debye length, a blob radius):
//   blob-wall  U(z) = eps exp(-(z - a)/b)      z >= a,   eps + eps (a - z)/b  below;
//              f_z  = (eps/b) exp(-(z - a)/b)  z > a,    eps/b                below.
//   blob-blob  U(r) = eps exp(-(r - 2a)/b)     r >= 2a,  eps + eps (2a - r)/b below;
//              force on blob i = -m r with m = (eps/b) exp(-max(r - 2a, 0)/b) / r,
//              r = r_j - r_i (minimum image), |r| floored at machine epsilon.
//   body-body  U(r) = eps exp(-r/b) / r (Yukawa);
//              force on body i = -m r with m = (eps/b + eps/r) exp(-r/b) / r^2.
// Each function takes an exponential functor `Exp` (default: the native exp),
// so that the Monte Carlo energies can use their vectorisable exp of x <= 0.
#ifndef RMB_PAIR_LAWS_H
#define RMB_PAIR_LAWS_H

#ifdef __CUDACC__
#define RMB_HD __host__ __device__ __forceinline__
#define RMB_RSQRT(x) rsqrt(x)
#define RMB_SQRT(x) sqrt(x)
#define RMB_EXP(x) exp(x)
#define RMB_TRUNC(x) trunc(x)
#else
#include <cmath>
#define RMB_HD inline
#define RMB_RSQRT(x) (1.0 / std::sqrt(x))
#define RMB_SQRT(x) std::sqrt(x)
#define RMB_EXP(x) std::exp(x)
#define RMB_TRUNC(x) std::trunc(x)
#endif

namespace rmb {

// Machine epsilon of double: the floor of pair distances in the force laws.
#define RMB_DISTANCE_FLOOR 2.220446049250313e-16

// Minimum image of one displacement component for box length L, rounding
// half away from zero: d - trunc(d/L + sign(d)/2) L (SPEC section 8).
// L <= 0: the axis is not periodic and d is returned unchanged.
RMB_HD double minimum_image(double d, double L) {
  if (L > 0.0) d -= RMB_TRUNC(d / L + (d > 0.0 ? 0.5 : (d < 0.0 ? -0.5 : 0.0))) * L;
  return d;
}

// Wall regularisation of the blob mobility (Balboa, Delmotte and Donev 2017):
// a blob closer to the wall than its radius is raised to z_eff = radius and
// its vectors (input and output) are damped by z / radius; a point blob
// (radius 0) below the wall gets damping 0.  Above the radius: unchanged, 1.
RMB_HD void wall_regularisation(double z, double radius, double &z_eff, double &damping) {
  z_eff = z;
  damping = 1.0;
  if (z < radius) {
    damping = radius > 0.0 ? z / radius : 0.0;
    z_eff = radius;
  }
}

struct NativeExp {
  RMB_HD double operator()(double x) const { return RMB_EXP(x); }
};

// Parameters of a soft repulsion in the form the laws use.
struct SoftRepulsion {
  double eps, eps_over_b, inv_b, contact;
};

// contact: a for the wall, 2a for blob pairs (unused by the body-body law).
RMB_HD SoftRepulsion soft_repulsion(double eps, double b, double contact) {
  SoftRepulsion p;
  p.eps = eps;
  p.eps_over_b = eps / b;
  p.inv_b = 1.0 / b;
  p.contact = contact;
  return p;
}

// Blob-wall: energy U(z) and force f_z(z) = -dU/dz of a blob at height z (contact = a).
template <class Exp = NativeExp>
RMB_HD double wall_energy(double z, const SoftRepulsion &p, Exp e = Exp()) {
  const double gap = z > p.contact ? z - p.contact : 0.0;
  const double overlap = z < p.contact ? p.contact - z : 0.0;
  return p.eps * e(-gap * p.inv_b) + p.eps_over_b * overlap;
}

template <class Exp = NativeExp>
RMB_HD double wall_force(double z, const SoftRepulsion &p, Exp e = Exp()) {
  const double gap = z > p.contact ? z - p.contact : 0.0;
  return p.eps_over_b * e(-gap * p.inv_b);
}

// Blob-blob (contact = 2a): energy U(r) of a pair at distance r, and the factor
// m of the force -m r on blob i (r from blob i to blob j, |r| = distance).
template <class Exp = NativeExp>
RMB_HD double blob_blob_energy(double distance, const SoftRepulsion &p, Exp e = Exp()) {
  const double gap = distance > p.contact ? distance - p.contact : 0.0;
  const double overlap = distance < p.contact ? p.contact - distance : 0.0;
  return p.eps * e(-gap * p.inv_b) + p.eps_over_b * overlap;
}

template <class Exp = NativeExp>
RMB_HD double blob_blob_force_factor(double distance, const SoftRepulsion &p, Exp e = Exp()) {
  if (distance < RMB_DISTANCE_FLOOR) distance = RMB_DISTANCE_FLOOR;
  const double gap = distance > p.contact ? distance - p.contact : 0.0;
  return p.eps_over_b * e(-gap * p.inv_b) / distance;
}

// Body-body Yukawa: energy U(r) of a pair of body locations at distance r, and
// the factor m of the force -m r on body i.
template <class Exp = NativeExp>
RMB_HD double body_body_energy(double distance, const SoftRepulsion &p, Exp e = Exp()) {
  if (distance < RMB_DISTANCE_FLOOR) distance = RMB_DISTANCE_FLOOR;
  return p.eps * e(-distance * p.inv_b) / distance;
}

template <class Exp = NativeExp>
RMB_HD double body_body_force_factor(double distance, const SoftRepulsion &p, Exp e = Exp()) {
  if (distance < RMB_DISTANCE_FLOOR) distance = RMB_DISTANCE_FLOOR;
  return (p.eps_over_b + p.eps / distance) * e(-distance * p.inv_b) / (distance * distance);
}

}  // namespace rmb

#endif  // RMB_PAIR_LAWS_H
