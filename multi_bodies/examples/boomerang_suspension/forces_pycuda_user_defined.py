"""GPU version of this example's blob-blob Yukawa force (used with blob_blob_force_implementation pycuda).

The framework imports this file only for pycuda runs; CuPy is imported inside the function.
"""
import numpy as np

KERNEL = r'''
extern "C" __global__ void yukawa(const double *r, int n, double eps, double b, double d, double *f) {
  int i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= n) return;
  double fx = 0, fy = 0, fz = 0;
  for (int j = 0; j < n; ++j) {
    if (j == i) continue;
    double rx = r[3*j] - r[3*i], ry = r[3*j+1] - r[3*i+1], rz = r[3*j+2] - r[3*i+2];
    double dist = fmax(sqrt(rx*rx + ry*ry + rz*rz), 1e-12);
    double dU = -eps * d * exp(-(dist - d) / b) * (1.0 / (b * dist) + 1.0 / (dist * dist));
    fx += dU * rx / dist; fy += dU * ry / dist; fz += dU * rz / dist;
  }
  f[3*i] = fx; f[3*i+1] = fy; f[3*i+2] = fz;
}
'''


def calc_blob_blob_forces_pycuda(r_vectors, repulsion_strength=1.0, debye_length=1.0, blob_radius=1.0, **kwargs):
    """Yukawa forces of all blob pairs on the GPU (no periodic images); r_vectors (N, 3) -> (N, 3)."""
    import cupy as cp
    r = cp.asarray(np.asarray(r_vectors, dtype=np.float64).reshape(-1, 3))
    n = r.shape[0]
    out = cp.zeros((n, 3), dtype=cp.float64)
    kernel = cp.RawKernel(KERNEL, 'yukawa')
    kernel(((n + 127) // 128,), (128,), (r, np.int32(n), np.float64(repulsion_strength), np.float64(debye_length),
                                        np.float64(2.0 * blob_radius), out))
    return cp.asnumpy(out)
