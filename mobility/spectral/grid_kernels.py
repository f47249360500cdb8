"""Spreading onto the grid and interpolation from it, as the GPU's raw kernels compute them, in NumPy.

The array product (``mobility.spectral.array_product``) calls four functions on a :class:`GridStencil`:
``spread_forces(grid, stencil, forces)``, ``spread_torques(grid, stencil, torques)``,
``interpolate_velocities(grid, stencil) -> (n, 3)`` and ``interpolate_rotations(grid, stencil) -> (n, 3)``.
On a GPU they are raw CUDA kernels (``mobility/cuda/spectral_grid_kernels.cu`` through
``mobility.spectral.cuda_kernels``); here they are NumPy functions of the same signatures and the same
arithmetic per stencil point (the weight of a node is ``phi_z * phi_y * phi_x`` in that order, a force adds
``weight * F``, half the curl of a torque adds ``0.5 (T_z Dy - T_y Dz)``, ...), so that the array product runs
and is tested with NumPy on any machine; ``tests/test_spectral_gpu.py`` checks them against the CPU product's
spreading and interpolation (``mobility.spectral.reference``) and, where a GPU is lent, the CUDA kernels
against them.

Grids are (3, Nz, Ny, Nx) arrays (component, z, y, x); a node (k, j, i) of component c is the flat entry
``((c Nz + k) Ny + j) Nx + i``.
"""
from collections import namedtuple

import numpy as np

BLOB_BLOCK = 4096   # blobs per vectorised block (bounds the (block, nz, wy, wx) temporaries)

GridStencil = namedtuple('GridStencil', ['n', 'ix', 'iy', 'iz', 'phi_x', 'phi_y', 'phi_z', 'qz', 'dphi_x', 'dphi_y',
                                         'dphi_z', 'dqz'])
GridStencil.__doc__ = """The kernel weights of n blobs in the layout of the raw kernels (arrays of one namespace).

ix (n, wx), iy (n, wy), iz (n, nz) int32 node indices (padded z slots: a valid index and weight 0);
phi_x (n, wx), phi_y (n, wy), phi_z (n, nz) the 1-D kernel factors (units 1/length); qz (n, nz) = phi_z times the
quadrature weight of the node, hx hy w_z (length^2); for the derivative (torque) kernels dphi_x, dphi_y, dphi_z
and dqz alike, else None."""


def grid_stencil(parameters, stencil, xp=np):
    """The :class:`GridStencil` of a ``mobility.spectral.stencil.Stencil`` (NumPy) in namespace ``xp``."""
    p = parameters
    weights = p.z_weights()[stencil.iz] * (p.hx * p.hy)

    def put(array, dtype=np.float64):
        return None if array is None else xp.asarray(np.ascontiguousarray(array, dtype=dtype))
    derivative = stencil.dphi_x is not None
    return GridStencil(int(stencil.ix.shape[0]), put(stencil.ix, np.int32), put(stencil.iy, np.int32),
                       put(stencil.iz, np.int32), put(stencil.phi_x), put(stencil.phi_y), put(stencil.phi_z),
                       put(stencil.phi_z * weights), put(stencil.dphi_x), put(stencil.dphi_y), put(stencil.dphi_z),
                       put(stencil.dphi_z * weights) if derivative else None)


def _blocks(n):
    for start in range(0, n, BLOB_BLOCK):
        yield slice(start, min(start + BLOB_BLOCK, n))


def _flat(grid, st, rows):
    """Flat node indices (b, nz, wy, wx) of the blobs ``rows`` in one component of ``grid``."""
    _, Nz, Ny, Nx = grid.shape
    return ((st.iz[rows].astype(np.int64)[:, :, None, None] * Ny + st.iy[rows][:, None, :, None]) * Nx
            + st.ix[rows][:, None, None, :])


def _weights(z, y, x):
    return z[:, :, None, None] * y[:, None, :, None] * x[:, None, None, :]


def spread_forces(grid, st, forces):
    """grid (3, Nz, Ny, Nx) += the forces (n, 3) spread with the monopole stencil ``st``."""
    flat = grid.reshape(3, -1)
    forces = np.asarray(forces, dtype=np.float64).reshape(-1, 3)
    for rows in _blocks(st.n):
        index = _flat(grid, st, rows).ravel()
        w = _weights(st.phi_z[rows], st.phi_y[rows], st.phi_x[rows])
        for c in range(3):
            np.add.at(flat[c], index, (w * forces[rows, c, None, None, None]).ravel())


def spread_torques(grid, st, torques):
    """grid += half the curl of the torques (n, 3) spread with the derivative stencil ``st``."""
    flat = grid.reshape(3, -1)
    torques = np.asarray(torques, dtype=np.float64).reshape(-1, 3)
    for rows in _blocks(st.n):
        index = _flat(grid, st, rows).ravel()
        Dx = _weights(st.phi_z[rows], st.phi_y[rows], st.dphi_x[rows])
        Dy = _weights(st.phi_z[rows], st.dphi_y[rows], st.phi_x[rows])
        Dz = _weights(st.dphi_z[rows], st.phi_y[rows], st.phi_x[rows])
        T = [torques[rows, c, None, None, None] for c in range(3)]
        np.add.at(flat[0], index, (0.5 * (T[2] * Dy - T[1] * Dz)).ravel())
        np.add.at(flat[1], index, (0.5 * (T[0] * Dz - T[2] * Dx)).ravel())
        np.add.at(flat[2], index, (0.5 * (T[1] * Dx - T[0] * Dy)).ravel())


def interpolate_velocities(grid, st):
    """U (n, 3): the grid velocity averaged with the monopole stencil (quadrature-weighted z factors)."""
    flat = grid.reshape(3, -1)
    U = np.empty((st.n, 3))
    for rows in _blocks(st.n):
        index = _flat(grid, st, rows)
        w = _weights(st.qz[rows], st.phi_y[rows], st.phi_x[rows])
        for c in range(3):
            U[rows, c] = np.sum(flat[c][index] * w, axis=(1, 2, 3))
    return U


def interpolate_rotations(grid, st):
    """W (n, 3): minus half the curl of the grid velocity averaged with the derivative stencil."""
    flat = grid.reshape(3, -1)
    W = np.empty((st.n, 3))
    for rows in _blocks(st.n):
        index = _flat(grid, st, rows)
        Dx = _weights(st.qz[rows], st.phi_y[rows], st.dphi_x[rows])
        Dy = _weights(st.qz[rows], st.dphi_y[rows], st.phi_x[rows])
        Dz = _weights(st.dqz[rows], st.phi_y[rows], st.phi_x[rows])
        u = [flat[c][index] for c in range(3)]

        def g(D, c):
            return np.sum(u[c] * D, axis=(1, 2, 3))
        W[rows, 0] = -0.5 * (g(Dy, 2) - g(Dz, 1))
        W[rows, 1] = -0.5 * (g(Dz, 0) - g(Dx, 2))
        W[rows, 2] = -0.5 * (g(Dx, 1) - g(Dy, 0))
    return W
