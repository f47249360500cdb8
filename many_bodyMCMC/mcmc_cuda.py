"""CUDA backend (manual name ``pycuda``) of the Monte Carlo blob-blob energies, through CuPy.

Imported only when ``mcmc_energy_implementation pycuda`` is asked for (or
``auto`` finds ``potential_pycuda_user_defined.py``); CuPy is then required
and the kernels are compiled once per process by NVRTC, in double precision.

Two kernels, one thread per blob: ``pair_energy_rows`` (thread i sums the
pairs i < j of the whole system) and ``pair_energy_cross`` (thread j sums a
moved body's blobs against source j, skipping the body's own rows); the
per-thread sums are added with ``cupy.sum``.  The pair law is the device
function ``blob_blob_potential``: the default soft repulsion below, or the
text ``BLOB_BLOB_POTENTIAL_SOURCE`` of ``potential_pycuda_user_defined.py``.
"""
import numpy as np
import cupy as cp

from mobility.compiled_laws import pair_laws_source

THREADS_PER_BLOCK = 128

# The default law and the minimum image come from mobility/cpp/pair_laws.h, whose text is prepended
# to every module (namespace rmb, so a user's source may define its own helpers by other names).
DEFAULT_BLOB_BLOB_SOURCE = r'''
__device__ double blob_blob_potential(double rx, double ry, double rz, double eps, double b, double a) {
  return rmb::blob_blob_energy(sqrt(rx * rx + ry * ry + rz * rz), rmb::soft_repulsion(eps, b, 2.0 * a));
}
'''

KERNELS = r'''
extern "C" __global__ void pair_energy_rows(const double *r, const int n, const double Lx, const double Ly,
                                            const double Lz, const double eps, const double b, const double a,
                                            double *out) {
  const int i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= n) return;
  const double xi = r[3 * i], yi = r[3 * i + 1], zi = r[3 * i + 2];
  double sum = 0.0;
  for (int j = i + 1; j < n; ++j)
    sum += blob_blob_potential(rmb::minimum_image(r[3 * j] - xi, Lx), rmb::minimum_image(r[3 * j + 1] - yi, Ly),
                               rmb::minimum_image(r[3 * j + 2] - zi, Lz), eps, b, a);
  out[i] = sum;
}

extern "C" __global__ void pair_energy_cross(const double *t, const int m, const double *r, const int n,
                                             const int exclude_start, const int exclude_stop, const double Lx,
                                             const double Ly, const double Lz, const double eps, const double b,
                                             const double a, double *out) {
  const int j = blockIdx.x * blockDim.x + threadIdx.x;
  if (j >= n) return;
  double sum = 0.0;
  if (j < exclude_start || j >= exclude_stop) {
    const double xj = r[3 * j], yj = r[3 * j + 1], zj = r[3 * j + 2];
    for (int k = 0; k < m; ++k)
      sum += blob_blob_potential(rmb::minimum_image(xj - t[3 * k], Lx), rmb::minimum_image(yj - t[3 * k + 1], Ly),
                                 rmb::minimum_image(zj - t[3 * k + 2], Lz), eps, b, a);
  }
  out[j] = sum;
}
'''

_modules = {}


def _module(source):
    if source not in _modules:
        _modules[source] = cp.RawModule(code=pair_laws_source() + source + KERNELS)
    return _modules[source]


def check_usable():
    """Raise RuntimeError unless a CUDA device is present and the default kernels compile."""
    if cp.cuda.runtime.getDeviceCount() < 1:
        raise RuntimeError('no CUDA device found')
    _module(DEFAULT_BLOB_BLOB_SOURCE).get_function('pair_energy_rows')


class CudaPairSums:
    """Blob-blob sums on the GPU; the same interface as ``mcmc_energy.PythonPairSums``."""

    name = 'pycuda'

    def __init__(self, keywords, blob_blob_source=None):
        module = _module(blob_blob_source or DEFAULT_BLOB_BLOB_SOURCE)
        self._rows = module.get_function('pair_energy_rows')
        self._cross = module.get_function('pair_energy_cross')
        L = np.asarray(keywords.get('periodic_length', (0.0, 0.0, 0.0)), dtype=np.float64).reshape(3)
        self.law = (np.float64(L[0]), np.float64(L[1]), np.float64(L[2]),
                    np.float64(keywords['repulsion_strength']), np.float64(keywords['debye_length']),
                    np.float64(keywords['blob_radius']))

    def total(self, r_vectors):
        """Sum over blob pairs i < j; r_vectors (N, 3) (NumPy or CuPy)."""
        r = cp.ascontiguousarray(cp.asarray(r_vectors, dtype=cp.float64).reshape(-1, 3))
        n = r.shape[0]
        out = cp.zeros(n, dtype=cp.float64)
        self._rows((max(1, -(-n // THREADS_PER_BLOCK)),), (THREADS_PER_BLOCK,), (r, np.int32(n)) + self.law + (out,))
        return float(cp.sum(out))

    def cross(self, targets, sources, exclude_start, exclude_stop):
        """Sum over targets (m, 3) and the sources (N, 3) outside rows [exclude_start, exclude_stop)."""
        t = cp.ascontiguousarray(cp.asarray(targets, dtype=cp.float64).reshape(-1, 3))
        r = cp.ascontiguousarray(cp.asarray(sources, dtype=cp.float64).reshape(-1, 3))
        n = r.shape[0]
        out = cp.zeros(n, dtype=cp.float64)
        self._cross((max(1, -(-n // THREADS_PER_BLOCK)),), (THREADS_PER_BLOCK,),
                    (t, np.int32(t.shape[0]), r, np.int32(n), np.int32(exclude_start), np.int32(exclude_stop))
                    + self.law + (out,))
        return float(cp.sum(out))
