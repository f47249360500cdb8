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

// The solves are in spectral_solve.inc, compiled once per vector path (spectral_kernels.inc, simd_targets.h).

}  // namespace rmb_spectral
