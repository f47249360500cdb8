"""CUDA backend of the blob-blob forces (manual name ``pycuda``), through CuPy.

Imported only when ``blob_blob_force_implementation pycuda`` is asked for;
CuPy is then required and the kernel is compiled once per process by NVRTC.
One GPU thread per target blob sums the default soft repulsion over every
other blob (minimum image on periodic axes), in double precision, the same
law as ``multi_bodies.solver.physics.blob_blob_force``
(the device code of ``mobility/cpp/pair_laws.h``, prepended to the kernel).

A file ``forces_pycuda_user_defined.py`` in the run directory that defines
``calc_blob_blob_forces_pycuda(r_vectors, **kwargs)`` replaces
:func:`calc_blob_blob_forces_pycuda` (see ``multi_bodies.solver.user_hooks.load_user_hooks``).
"""
import numpy as np
import cupy as cp

from mobility.compiled_laws import pair_laws_source
from multi_bodies.files.input_options import DEFAULTS  # the keyword defaults below are the option table's

THREADS_PER_BLOCK = 128

# The law and the minimum image are those of mobility/cpp/pair_laws.h (prepended here), as in the C++ backend.
KERNEL_SOURCE = pair_laws_source() + r'''
extern "C" __global__
void blob_blob_forces(const double *r, const int n, const double Lx, const double Ly, const double Lz,
                      const double eps, const double b, const double contact, double *force) {
  const int i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= n) return;
  const rmb::SoftRepulsion law = rmb::soft_repulsion(eps, b, contact);
  const double xi = r[3 * i], yi = r[3 * i + 1], zi = r[3 * i + 2];
  double fx = 0.0, fy = 0.0, fz = 0.0;
  for (int j = 0; j < n; ++j) {
    if (j == i) continue;
    const double rx = rmb::minimum_image(r[3 * j] - xi, Lx);
    const double ry = rmb::minimum_image(r[3 * j + 1] - yi, Ly);
    const double rz = rmb::minimum_image(r[3 * j + 2] - zi, Lz);
    const double m = rmb::blob_blob_force_factor(sqrt(rx * rx + ry * ry + rz * rz), law);
    fx -= m * rx; fy -= m * ry; fz -= m * rz;
  }
  force[3 * i] = fx; force[3 * i + 1] = fy; force[3 * i + 2] = fz;
}
'''

_module = None


def _kernel():
    global _module
    if _module is None:
        _module = cp.RawModule(code=KERNEL_SOURCE)
    return _module.get_function('blob_blob_forces')


def check_usable():
    """Raise RuntimeError unless a CUDA device is present and the kernel compiles."""
    if cp.cuda.runtime.getDeviceCount() < 1:
        raise RuntimeError('no CUDA device found')
    _kernel()


def calc_blob_blob_forces_pycuda(r_vectors, periodic_length=(0.0, 0.0, 0.0),
                                 repulsion_strength=DEFAULTS.repulsion_strength, debye_length=DEFAULTS.debye_length,
                                 blob_radius=DEFAULTS.blob_radius, **kwargs):
    """Default soft repulsion of all blob pairs on the GPU.

    r_vectors : (N, 3) positions; returns the forces, NumPy array (N, 3).
    """
    r = cp.asarray(np.asarray(r_vectors, dtype=np.float64).reshape(-1, 3))
    n = r.shape[0]
    L = np.asarray(periodic_length, dtype=np.float64).reshape(3)
    out = cp.zeros((n, 3), dtype=cp.float64)
    blocks = max(1, -(-n // THREADS_PER_BLOCK))
    _kernel()((blocks,), (THREADS_PER_BLOCK,),
              (r, np.int32(n), np.float64(L[0]), np.float64(L[1]), np.float64(L[2]),
               np.float64(repulsion_strength), np.float64(debye_length), np.float64(2.0 * blob_radius), out))
    return cp.asnumpy(out)
