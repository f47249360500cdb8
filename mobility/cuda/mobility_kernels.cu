// CUDA kernels of the blob mobility products, compiled at run time by NVRTC
// through CuPy's RawModule.  The pair formulas come from the same header as
// the C++ backend (mobility/cpp/blob_pair_kernels.h); this file adds only
// the tiling and the launch shape.
//
// Layout: one thread per target; sources are staged through shared memory
// in tiles of blockDim.x blobs, packed as Packed4 (x, y, z, radius) for
// positions and (vx, vy, vz, source radius) for vectors.  When there are too few
// targets to fill the GPU, gridDim.y > 1 splits the source range and the
// partial sums are added with atomicAdd (double atomics need sm_60+).
//
// Inputs are already scaled and regularised by the host wrapper: positions
// in units of a with z raised to max(z, a), vectors multiplied by the
// damping factors; the wrapper also applies the output damping and the
// 1/(8 pi eta a^k) factor.
#include "blob_pair_kernels.h"

// Four doubles per blob, 32-byte aligned (our own type: CUDA 13 deprecates double4).
struct __align__(32) Packed4 {
  double x, y, z, w;
};

template <int Kind, bool Wall, class Real>
__device__ __forceinline__ void pair_dispatch(double rx, double ry, double rz, double zt, double zs, double bt,
                                              Packed4 v, double &ux, double &uy, double &uz) {
  if (Kind == 0) {
    // Real = float: the pair formula in single precision, sums in double
    Real a = 0, b = 0, c = 0;
    rmb::trans_times_force_pair<Wall, Real>(Real(rx), Real(ry), Real(rz), Real(zt), Real(zs), Real(v.x), Real(v.y),
                                            Real(v.z), a, b, c);
    ux += a;
    uy += b;
    uz += c;
  }
  if (Kind == 1) rmb::trans_times_torque_pair<Wall>(rx, ry, rz, zt, zs, v.x, v.y, v.z, ux, uy, uz);
  if (Kind == 2) rmb::rot_times_force_pair<Wall>(rx, ry, rz, zt, zs, v.x, v.y, v.z, ux, uy, uz);
  if (Kind == 3) rmb::rot_times_torque_pair<Wall>(rx, ry, rz, zt, zs, v.x, v.y, v.z, ux, uy, uz);
  if (Kind == 4) rmb::source_target_pair<Wall>(rx, ry, rz, zt, zs, bt, v.w, v.x, v.y, v.z, ux, uy, uz);
  if (Kind == 5) rmb::free_surface_pair(rx, ry, rz, zt, zs, v.x, v.y, v.z, ux, uy, uz);
  if (Kind == 6) rmb::source_target_free_surface_pair(rx, ry, rz, zt, zs, bt, v.w, v.x, v.y, v.z, ux, uy, uz);
}

// Kind: 0 trans_times_force, 1 trans_times_torque, 2 rot_times_force,
// 3 rot_times_torque, 4 source_target (unequal radii; target radius in
// targets[i].w, source radius in vectors[j].w), 5 free surface (one radius),
// 6 free surface with unequal radii (as 4; Wall unused for 5 and 6).  Real: the precision of the
// pair formula of kind 0 (double, or float); the others are double only.
template <int Kind, bool Wall, bool Periodic, class Real>
__global__ void blob_product_kernel(const Packed4 *__restrict__ targets, int n_targets,
                                    const Packed4 *__restrict__ sources, const Packed4 *__restrict__ vectors,
                                    int n_sources, double Lx, double Ly, double Lz, double *__restrict__ out) {
  extern __shared__ Packed4 tile[];
  Packed4 *tile_pos = tile;
  Packed4 *tile_vec = tile + blockDim.x;
  const int i = blockIdx.x * blockDim.x + threadIdx.x;
  const int per_split = (n_sources + gridDim.y - 1) / gridDim.y;
  const int j_begin = blockIdx.y * per_split;
  const int j_end = min(n_sources, j_begin + per_split);
  Packed4 t = {0.0, 0.0, 0.0, 0.0};
  if (i < n_targets) t = targets[i];
  double ux = 0.0, uy = 0.0, uz = 0.0;
  const int nx = (Periodic && Lx > 0.0) ? 1 : 0, ny = (Periodic && Ly > 0.0) ? 1 : 0,
            nz = (Periodic && Lz > 0.0) ? 1 : 0;
  for (int base = j_begin; base < j_end; base += blockDim.x) {
    const int j_load = base + threadIdx.x;
    if (j_load < j_end) {
      tile_pos[threadIdx.x] = sources[j_load];
      tile_vec[threadIdx.x] = vectors[j_load];
    }
    __syncthreads();
    const int count = min((int)blockDim.x, j_end - base);
    if (i < n_targets) {
      for (int k = 0; k < count; ++k) {
        const Packed4 s = tile_pos[k];
        const Packed4 v = tile_vec[k];
        double rx = t.x - s.x, ry = t.y - s.y, rz = t.z - s.z;
        if (Periodic) {
          rx = rmb::minimum_image(rx, Lx);
          ry = rmb::minimum_image(ry, Ly);
          rz = rmb::minimum_image(rz, Lz);
          for (int bx = -nx; bx <= nx; ++bx)
            for (int by = -ny; by <= ny; ++by)
              for (int bz = -nz; bz <= nz; ++bz)
                pair_dispatch<Kind, Wall, Real>(rx + bx * Lx, ry + by * Ly, rz + bz * Lz, t.z, s.z, t.w, v, ux, uy, uz);
        } else {
          pair_dispatch<Kind, Wall, Real>(rx, ry, rz, t.z, s.z, t.w, v, ux, uy, uz);
        }
      }
    }
    __syncthreads();
  }
  if (i < n_targets) {
    if (gridDim.y == 1) {
      out[3 * i] = ux;
      out[3 * i + 1] = uy;
      out[3 * i + 2] = uz;
    } else {
      atomicAdd(out + 3 * i, ux);
      atomicAdd(out + 3 * i + 1, uy);
      atomicAdd(out + 3 * i + 2, uz);
    }
  }
}
