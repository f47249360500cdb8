"""The raw CUDA kernels of the spectral product's spreading and interpolation, through CuPy.

Same functions and signatures as the NumPy stand-ins of ``mobility.spectral.grid_kernels`` (``spread_forces``,
``spread_torques``, ``interpolate_velocities``, ``interpolate_rotations``), on CuPy arrays; the kernels
(``mobility/cuda/spectral_grid_kernels.cu``) are compiled once per process by NVRTC.  CuPy is imported when this
module is imported, which happens only when the GPU backend (``spectral_gpu``) is made or checked.
"""
import os

import cupy as cp
import numpy as np

_SOURCE = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), 'cuda',
                       'spectral_grid_kernels.cu')
_NAMES = ('spread_forces', 'spread_torques', 'interpolate_velocities', 'interpolate_rotations')
SPREAD_THREADS = 256
INTERPOLATE_THREADS = 128          # a power of two (the reduction halves it)
_module = None


def kernels():
    """The compiled kernels {name: RawKernel} (compiled on first use)."""
    global _module
    if _module is None:
        with open(_SOURCE) as f:
            source = f.read()
        module = cp.RawModule(code=source, options=('-std=c++14',))
        _module = {name: module.get_function(name) for name in _NAMES}
    return _module


def _blocks(total, threads):
    sms = cp.cuda.Device().attributes['MultiProcessorCount']
    return int(max(1, min(-(-total // threads), 64 * sms)))


def _shape(grid, st):
    _, Nz, Ny, Nx = grid.shape
    return (np.int32(st.n), np.int32(st.iz.shape[1]), np.int32(st.iy.shape[1]), np.int32(st.ix.shape[1])), \
        (np.int32(Nx), np.int32(Ny), np.int32(Nz))


def _vectors(values, n):
    return cp.ascontiguousarray(cp.asarray(values, dtype=cp.float64).reshape(n, 3))


def spread_forces(grid, st, forces):
    """grid (3, Nz, Ny, Nx) += the forces (n, 3) spread with the monopole stencil ``st`` (CuPy arrays)."""
    sizes, dims = _shape(grid, st)
    total = st.n * st.iz.shape[1] * st.iy.shape[1] * st.ix.shape[1]
    if total == 0:
        return
    kernels()['spread_forces']((_blocks(total, SPREAD_THREADS),), (SPREAD_THREADS,),
                               (grid,) + sizes + (st.ix, st.iy, st.iz, st.phi_x, st.phi_y, st.phi_z,
                                                  _vectors(forces, st.n)) + dims)


def spread_torques(grid, st, torques):
    """grid += half the curl of the torques (n, 3) spread with the derivative stencil ``st``."""
    sizes, dims = _shape(grid, st)
    total = st.n * st.iz.shape[1] * st.iy.shape[1] * st.ix.shape[1]
    if total == 0:
        return
    kernels()['spread_torques']((_blocks(total, SPREAD_THREADS),), (SPREAD_THREADS,),
                                (grid,) + sizes + (st.ix, st.iy, st.iz, st.phi_x, st.phi_y, st.phi_z, st.dphi_x,
                                                   st.dphi_y, st.dphi_z, _vectors(torques, st.n)) + dims)


def interpolate_velocities(grid, st):
    """U (n, 3), CuPy: the grid velocity averaged with the monopole stencil."""
    sizes, dims = _shape(grid, st)
    out = cp.empty((st.n, 3), dtype=cp.float64)
    if st.n:
        kernels()['interpolate_velocities']((_blocks(st.n, 1),), (INTERPOLATE_THREADS,),
                                            (grid,) + sizes + (st.ix, st.iy, st.iz, st.phi_x, st.phi_y, st.qz, out)
                                            + dims, shared_mem=3 * INTERPOLATE_THREADS * 8)
    return out


def interpolate_rotations(grid, st):
    """W (n, 3), CuPy: minus half the curl of the grid velocity averaged with the derivative stencil."""
    sizes, dims = _shape(grid, st)
    out = cp.empty((st.n, 3), dtype=cp.float64)
    if st.n:
        kernels()['interpolate_rotations']((_blocks(st.n, 1),), (INTERPOLATE_THREADS,),
                                           (grid,) + sizes + (st.ix, st.iy, st.iz, st.phi_x, st.phi_y, st.qz,
                                                              st.dphi_x, st.dphi_y, st.dqz, out) + dims,
                                           shared_mem=6 * INTERPOLATE_THREADS * 8)
    return out
