"""The compiled path of the spectral Stokes product: ``mobility._spectral_cpp`` spreads, solves and
interpolates; ``scipy.fft`` transforms in place on one grid.

Memory.  One real grid of three components, (3, Nz, Ny, 2(Nx//2 + 1)) float64 (rows padded by one or two
values so the real-to-complex transform along x fits in place: about 24 bytes per grid node), kept between
products.  Its complex view (3, Nz, Ny, Nx//2 + 1) holds the transformed field; the transforms along y (and z
in TP) run in place, the real transform along x row block by row block (blocks of about 32 MB).  The
per-wavenumber solves work on tiles of 16 modes in per-thread buffers.  Besides the grid: the blobs'
stencils (about 0.3 to 0.6 kB per blob) and scipy's per-call buffers.

Importing this module fails with ImportError when the extension is not built (the product then uses the
NumPy path).
"""
import os
import time

import numpy as np
from scipy import fft

from .. import _spectral_cpp as _ext
from .chebyshev import ChebyshevSystem
from .fourier import derivative_factors, partner_wavenumbers, unpaired, wavenumbers

BLOCK_BYTES = 8 << 20    # row blocks of the real transforms along x
GEOMETRY_CODE = {'DP': 0, 'DPBW': 1, 'DPSC': 2}


def default_workers():
    """Threads for the FFTs: OMP_NUM_THREADS if set, else the OpenMP default of the extension."""
    value = os.environ.get('OMP_NUM_THREADS', '')
    try:
        return max(1, int(value.split(',')[0]))
    except ValueError:
        return max(1, _ext.max_threads())


class _PreparedStencil:
    """A stencil in the compiled layout: int32 indices, contiguous factors, quadrature-weighted z factors,
    and the blobs grouped in stripes of grid rows (for spreading without write conflicts)."""

    def __init__(self, p, stencil, z_quadrature):
        self.ix = np.ascontiguousarray(stencil.ix, dtype=np.int32)
        self.iy = np.ascontiguousarray(stencil.iy, dtype=np.int32)
        self.iz = np.ascontiguousarray(stencil.iz, dtype=np.int32)
        self.phi_x = np.ascontiguousarray(stencil.phi_x)
        self.phi_y = np.ascontiguousarray(stencil.phi_y)
        self.phi_z = np.ascontiguousarray(stencil.phi_z)
        weights = z_quadrature[stencil.iz] * (p.hx * p.hy)
        self.qz = np.ascontiguousarray(stencil.phi_z * weights)
        self.derivative = stencil.dphi_x is not None
        if self.derivative:
            self.dphi_x = np.ascontiguousarray(stencil.dphi_x)
            self.dphi_y = np.ascontiguousarray(stencil.dphi_y)
            self.dphi_z = np.ascontiguousarray(stencil.dphi_z)
            self.dqz = np.ascontiguousarray(stencil.dphi_z * weights)
        width = self.iy.shape[1]
        count = max(p.Ny // width, 1)
        stripe = np.minimum(self.iy[:, 0] // width, count - 1)
        self.order = np.argsort(stripe, kind='stable').astype(np.int64)
        self.start = np.searchsorted(stripe[self.order], np.arange(count + 1)).astype(np.int64)


class CompiledEngine:
    """Grid, transforms and compiled steps of one discretisation (used by ``SpectralStokes``)."""

    def __init__(self, parameters, eta, workers=None):
        p = parameters
        self.p = p
        self.eta = eta
        self.workers = default_workers() if workers is None else int(workers)
        self.Nxh = p.Nx // 2 + 1
        self.row = 2 * self.Nxh
        self._grid = None
        self._monopole = None
        self._dipole = None
        self._planes = slice(0, parameters.Nz)   # the z planes the transforms cover (prepare narrows it)
        self.z_quadrature = p.z_weights()
        Nxh = self.Nxh
        if p.geometry == 'TP':
            self.tp = dict(kz=wavenumbers(p.Nz, p.Lz), ky=wavenumbers(p.Ny, p.Ly), kx=wavenumbers(p.Nx, p.Lx)[:Nxh],
                           dz=derivative_factors(p.Nz, p.Lz).imag.copy(),
                           dy=derivative_factors(p.Ny, p.Ly).imag.copy(),
                           dx=derivative_factors(p.Nx, p.Lx)[:Nxh].imag.copy())
        else:
            cheb = ChebyshevSystem(p.Nz, p.Lz)
            self.cheb = cheb
            N = p.Nz
            j = np.arange(N)
            f_low = np.zeros(N)
            f_low[1:] = cheb.F1[j[1:], j[1:] - 1]
            f_up = np.zeros(N)
            f_up[:N - 1] = cheb.F1[j[:N - 1], j[:N - 1] + 1]
            assert not np.any(cheb.F1[:, N])  # the c0 column of F1 is zero
            uammd = p.rules == 'uammd'
            self.cheb_data = dict(N=N, H=cheb.H, Lz=p.Lz, eta=eta, geometry=GEOMETRY_CODE[p.geometry],
                                  pressure_derivative_by_recurrence=uammd, unpaired_correction_as_is=uammd,
                                  forward=np.ascontiguousarray(cheb.forward),
                                  backward=np.ascontiguousarray(cheb.backward),
                                  s_low=cheb.s_low, s_diag=cheb.s_diag, s_up=cheb.s_up,
                                  s_c0=np.ascontiguousarray(cheb.S1[:, N]), s_d0=np.ascontiguousarray(cheb.S1[:, N + 1]),
                                  f_low=f_low, f_up=f_up, f_d0=np.ascontiguousarray(cheb.F1[:, N + 1]),
                                  R2=cheb.R2, L2=cheb.L2, R1=cheb.R1, L1=cheb.L1, z=p.z_nodes())
            self.modes = dict(Ny=p.Ny, Nxh=Nxh, kx=wavenumbers(p.Nx, p.Lx)[:Nxh].copy(), ky=wavenumbers(p.Ny, p.Ly),
                              dx=derivative_factors(p.Nx, p.Lx)[:Nxh].imag.copy(),
                              dy=derivative_factors(p.Ny, p.Ly).imag.copy(),
                              kx_partner=partner_wavenumbers(p.Nx, p.Lx)[:Nxh].copy(),
                              ky_partner=partner_wavenumbers(p.Ny, p.Ly),
                              unpaired_x=unpaired(p.Nx)[:Nxh].astype(np.uint8),
                              unpaired_y=unpaired(p.Ny).astype(np.uint8))

    # -------------------------------------------------------------- state
    def prepare(self, monopole, dipole):
        """Keep the stencils of the current positions in the compiled layout, and the z planes they touch."""
        self._monopole = _PreparedStencil(self.p, monopole, self.z_quadrature)
        self._dipole = None if dipole is None else _PreparedStencil(self.p, dipole, self.z_quadrature)
        self._planes = slice(0, self.p.Nz)
        if self.p.geometry != 'TP' and self._monopole.iz.size:
            # Doubly periodic: the z planes are not transformed, so a plane no blob spreads to is zero before the
            # forward transform (it stays zero), and a plane no blob interpolates from is not read after the
            # backward one: both transforms skip the planes outside the stencils' band of nodes.
            touched = [self._monopole.iz] + ([] if self._dipole is None else [self._dipole.iz])
            self._planes = slice(int(min(t.min() for t in touched)), int(max(t.max() for t in touched)) + 1)

    def release(self):
        """Free the grid (it is made again by the next product)."""
        self._grid = None

    def grid_bytes(self):
        p = self.p
        return 3 * p.Nz * p.Ny * self.row * 8

    def _zeroed_grid(self):
        p = self.p
        if self._grid is None:
            self._grid = np.zeros((3, p.Nz, p.Ny, self.row))
        else:
            self._grid.fill(0.0)
        return self._grid

    # -------------------------------------------------------------- transforms
    def _rows(self, component):
        """The rows along x of the planes that are transformed, (planes * Ny, row) real."""
        p = self.p
        planes = self._grid[component][self._planes]
        return planes.reshape(planes.shape[0] * p.Ny, self.row)

    def _row_blocks(self, total):
        per_block = max(1, BLOCK_BYTES // (16 * self.Nxh))
        return [slice(start, min(start + per_block, total)) for start in range(0, total, per_block)]

    def forward(self):
        """Real grid -> its Fourier transform in x and y (TP: also z), in place (DP geometries: the planes of
        ``_planes``; the others are zero and stay zero)."""
        p = self.p
        spectrum = self._grid.view(np.complex128)
        for c in range(3):
            rows = self._rows(c)
            crows = rows.view(np.complex128)
            for block in self._row_blocks(rows.shape[0]):
                crows[block] = fft.rfft(rows[block, :p.Nx], axis=-1, workers=self.workers)
            axes = (0, 1) if p.geometry == 'TP' else (1,)
            planes = spectrum[c][self._planes]
            out = fft.fftn(planes, axes=axes, overwrite_x=True, workers=self.workers)
            if not np.shares_memory(out, planes):
                planes[...] = out
        return spectrum

    def backward(self):
        """Inverse of :meth:`forward`, in place (the real grid then holds the field; DP geometries: in the planes
        of ``_planes`` only, the ones the interpolation reads; the others keep spectral values)."""
        p = self.p
        spectrum = self._grid.view(np.complex128)
        for c in range(3):
            axes = (0, 1) if p.geometry == 'TP' else (1,)
            planes = spectrum[c][self._planes]
            out = fft.ifftn(planes, axes=axes, overwrite_x=True, workers=self.workers)
            if not np.shares_memory(out, planes):
                planes[...] = out
            rows = self._rows(c)
            crows = rows.view(np.complex128)
            for block in self._row_blocks(rows.shape[0]):
                rows[block, :p.Nx] = fft.irfft(crows[block], n=p.Nx, axis=-1, workers=self.workers)

    # -------------------------------------------------------------- solves
    def solve(self, spectrum):
        p = self.p
        if p.geometry == 'TP':
            t = self.tp
            _ext.solve_triply_periodic(spectrum, t['kz'], t['ky'], t['kx'], t['dz'], t['dy'], t['dx'], self.eta)
            return
        k0 = None
        if p.geometry != 'DP':
            k0 = spectrum[:, :, 0, 0].T.copy()            # (Nz, 3) node values of the xy-mean force density
        _ext.solve_doubly_periodic(spectrum, self.cheb_data, self.modes)
        if p.geometry == 'DP':
            spectrum[:, :, 0, 0] = 0.0                    # no mean flow in the open geometry (as the library)
            return
        cheb = self.cheb
        coefficients = cheb.to_coefficients(k0)
        mean = np.zeros_like(coefficients)
        mean[:, :2] = cheb.mean_flow(-coefficients[:, :2] / self.eta, p.geometry)
        spectrum[:, :, 0, 0] = cheb.to_values(mean).T

    # -------------------------------------------------------------- the product
    def product(self, forces, torques, want_rotation):
        """``(U, W, timings)`` for forces and torques ((n, 3) or None)."""
        p = self.p
        clock = time.perf_counter
        t0 = clock()
        grid = self._zeroed_grid()
        m = self._monopole
        if forces is not None:
            _ext.spread_forces(grid, p.Nx, m.ix, m.iy, m.iz, m.phi_x, m.phi_y, m.phi_z,
                               np.ascontiguousarray(forces), m.order, m.start)
        if torques is not None:
            d = self._dipole
            _ext.spread_torques(grid, p.Nx, d.ix, d.iy, d.iz, d.phi_x, d.phi_y, d.phi_z, d.dphi_x, d.dphi_y, d.dphi_z,
                                np.ascontiguousarray(torques), d.order, d.start)
        t1 = clock()
        spectrum = self.forward()
        t2 = clock()
        self.solve(spectrum)
        t3 = clock()
        self.backward()
        t4 = clock()
        U = _ext.interpolate_velocities(grid, p.Nx, m.ix, m.iy, m.iz, m.phi_x, m.phi_y, m.qz)
        W = None
        if want_rotation:
            d = self._dipole
            W = _ext.interpolate_rotations(grid, p.Nx, d.ix, d.iy, d.iz, d.phi_x, d.phi_y, d.qz, d.dphi_x, d.dphi_y,
                                           d.dqz)
        t5 = clock()
        return U, W, dict(spread=t1 - t0, fft=(t2 - t1) + (t4 - t3), solve=t3 - t2, interpolate=t5 - t4)
