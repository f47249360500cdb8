"""CUDA backend (manual name ``pycuda``): the blob products on an NVIDIA GPU through CuPy.

CuPy is imported when this module is imported, which the registry does only
when a ``pycuda`` implementation is asked for; the package itself never
needs CuPy.  The kernels (``cuda/mobility_kernels.cu``) include the same
pair-formula header as the C++ backend and are compiled once per process by
NVRTC.

Inputs may be NumPy arrays (copied to the device and back) or CuPy arrays
(kept on the device; the result is then a CuPy array), so a solver that
holds its vectors on the GPU pays no host-device transfer per product.
Computation is in double precision; ``precision='single'`` runs the pair
formulas of ``M f`` in float (positions are subtracted and sums kept in
double), about twice as fast on the GPU with errors near 1e-6.
"""
import os

import numpy as np
import cupy as cp

from .periodic import wall_regularisation
from .product_names import product_functions, source_target_functions
from .python_backend import blob_radii

_KERNEL_SOURCE = os.path.join(os.path.dirname(__file__), 'cuda', 'mobility_kernels.cu')
_HEADER_DIR = os.path.join(os.path.dirname(__file__), 'cpp')
_KINDS = {'trans_times_force': 0, 'trans_times_torque': 1, 'rot_times_force': 2, 'rot_times_torque': 3,
          'source_target': 4, 'free_surface': 5, 'free_surface_source_target': 6}
_POWERS = {'trans_times_force': 1, 'trans_times_torque': 2, 'rot_times_force': 2, 'rot_times_torque': 3}
THREADS_PER_BLOCK = 128
_module = None


def _kernel_name(kind, wall, periodic, precision='double'):
    return 'blob_product_kernel<%d, %s, %s, %s>' % (_KINDS[kind], 'true' if wall else 'false',
                                                    'true' if periodic else 'false',
                                                    'float' if precision == 'single' else 'double')


def _compiled_module():
    global _module
    if _module is None:
        with open(_KERNEL_SOURCE) as f:
            source = f.read()
        names = [_kernel_name(k, w, p) for k in _KINDS for w in (True, False) for p in (True, False)]
        names += [_kernel_name('trans_times_force', w, p, 'single') for w in (True, False) for p in (True, False)]
        _module = cp.RawModule(code=source, options=('-std=c++17', '-I' + _HEADER_DIR), name_expressions=names)
        _module.compile()
    return _module


def check_usable():
    """Raise RuntimeError unless a CUDA device is present and the kernels compile."""
    if cp.cuda.runtime.getDeviceCount() < 1:
        raise RuntimeError('no CUDA device found')
    _compiled_module()


def _split_count(n_target_blocks, n_sources):
    """How many source ranges to split the sum into so that the GPU has enough blocks."""
    sms = cp.cuda.Device().attributes['MultiProcessorCount']
    wanted = max(1, -(-4 * sms // max(1, n_target_blocks)))
    return int(min(wanted, max(1, -(-n_sources // THREADS_PER_BLOCK))))


def _packed(r, radius, wall, scale):
    """Device array (N, 4): x, y, z_eff (in units of scale) and radius; and the damping (N,)."""
    r = cp.asarray(r, dtype=cp.float64).reshape(-1, 3)
    radius = cp.broadcast_to(cp.asarray(radius, dtype=cp.float64), (r.shape[0],))
    packed = cp.empty((r.shape[0], 4), dtype=cp.float64)
    packed[:, :2] = r[:, :2] / scale
    z = r[:, 2]
    if wall:
        z, damping = wall_regularisation(z, radius, xp=cp)
    else:
        damping = cp.ones(r.shape[0])
    packed[:, 2] = z / scale
    packed[:, 3] = radius / scale
    return packed, damping


def _launch(kind, wall, targets, sources, vectors, L_scaled, precision='double'):
    nt, ns = targets.shape[0], sources.shape[0]
    periodic = bool(np.any(L_scaled > 0))
    if wall and L_scaled[2] > 0:
        raise ValueError('periodic_length along z must be 0 with a wall at z = 0')
    blocks_x = max(1, -(-nt // THREADS_PER_BLOCK))
    splits = _split_count(blocks_x, ns)
    out = cp.zeros((nt, 3), dtype=cp.float64)
    if precision not in ('double', 'single'):
        raise ValueError("precision must be 'double' or 'single', got %r" % (precision,))
    if precision == 'single' and kind != 'trans_times_force':
        raise ValueError('single precision is available for trans_times_force only')
    kernel = _compiled_module().get_function(_kernel_name(kind, wall, periodic, precision))
    kernel((blocks_x, splits), (THREADS_PER_BLOCK,),
           (targets, np.int32(nt), sources, vectors, np.int32(ns), np.float64(L_scaled[0]),
            np.float64(L_scaled[1]), np.float64(L_scaled[2]), out),
           shared_mem=2 * THREADS_PER_BLOCK * 32)
    return out


def _periodic(periodic_length):
    L = np.asarray((0, 0, 0) if periodic_length is None else periodic_length, dtype=np.float64).reshape(3)
    if np.any(L < 0):
        raise ValueError('periodic_length entries must be >= 0')
    return L


def _to_caller(result, like):
    return result if isinstance(like, cp.ndarray) else cp.asnumpy(result)


def _make_product(kind, wall):
    def product(r_vectors, vector, eta, a, periodic_length=(0, 0, 0), precision='double'):
        radius = blob_radii(cp.asnumpy(a) if isinstance(a, cp.ndarray) else a, r_vectors, kind)
        if radius.ndim:  # different radii: the source-target kernel with sources = targets
            return _source_target(r_vectors, r_vectors, vector, radius, radius, eta, periodic_length, wall)
        a = float(radius)
        positions, damping = _packed(r_vectors, a, wall, a)
        v = cp.zeros((positions.shape[0], 4), dtype=cp.float64)
        v[:, :3] = cp.asarray(vector, dtype=cp.float64).reshape(-1, 3) * damping[:, None]
        u = _launch(kind, wall, positions, positions, v, _periodic(periodic_length) / a, precision)
        u *= damping[:, None] / (8.0 * np.pi * eta * a ** _POWERS[kind])
        return _to_caller(u.reshape(-1), r_vectors)
    return product


def _source_target(source, target, force, radius_source, radius_target, eta, periodic_length, wall):
    """``wall``: True, False or 'free_surface' (no regularisation, kernel kind 6)."""
    free_surface = wall == 'free_surface'
    wall = wall is True
    sources, damping_s = _packed(source, radius_source, wall, 1.0)
    targets, damping_t = _packed(target, radius_target, wall, 1.0)
    v = cp.empty((sources.shape[0], 4), dtype=cp.float64)
    v[:, :3] = cp.asarray(force, dtype=cp.float64).reshape(-1, 3) * damping_s[:, None]
    v[:, 3] = sources[:, 3]
    kind = 'free_surface_source_target' if free_surface else 'source_target'
    L = _periodic(periodic_length)
    if free_surface and L[2] > 0:
        raise ValueError('periodic_length along z must be 0 with a free surface at z = 0')
    u = _launch(kind, wall, targets, sources, v, L)
    u *= damping_t[:, None] / (8.0 * np.pi * eta)
    return _to_caller(u.reshape(-1), target)


globals().update(product_functions(_make_product, 'CUDA'))
globals().update(source_target_functions(_source_target, 'CUDA'))


def free_surface_mobility_trans_times_force(r_vectors, vector, eta, a, periodic_length=(0, 0, 0)):
    """``M f`` (3N,) above a free-slip surface at z = 0 on the GPU; ``a`` a number or per-blob radii (N,)."""
    radius = blob_radii(cp.asnumpy(a) if isinstance(a, cp.ndarray) else a, r_vectors)
    if radius.ndim:
        return _source_target(r_vectors, r_vectors, vector, radius, radius, eta, periodic_length, 'free_surface')
    a = float(radius)
    positions, _ = _packed(r_vectors, a, False, a)
    v = cp.zeros((positions.shape[0], 4), dtype=cp.float64)
    v[:, :3] = cp.asarray(vector, dtype=cp.float64).reshape(-1, 3)
    L = _periodic(periodic_length)
    if L[2] > 0:
        raise ValueError('periodic_length along z must be 0 with a free surface at z = 0')
    u = _launch('free_surface', False, positions, positions, v, L / a)
    u /= 8.0 * np.pi * eta * a
    return _to_caller(u.reshape(-1), r_vectors)


def free_surface_mobility_source_target(source, target, force, radius_source, radius_target, eta,
                                        periodic_length=(0, 0, 0)):
    """Velocity (3Nt,) at targets above a free-slip surface, per-blob radii (GPU)."""
    return _source_target(source, target, force, radius_source, radius_target, eta, periodic_length, 'free_surface')
