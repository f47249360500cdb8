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

// The loops are in spectral_spread.inc, compiled once per vector path (spectral_kernels.inc, simd_targets.h).

}  // namespace rmb_spectral
