"""The spectral Stokes product with UAMMD's discretisation rules (``SpectralParameters.rules == 'uammd'``): the
numbers of libMobility's ``DPStokes`` (libMobility runs UAMMD's doubly periodic Stokes module on a GPU).

The method is that of Hashemi et al. (J. Chem. Phys. 158, 154101, 2023) as in the rest of
``mobility.spectral``; the grid and kernels come from :mod:`mobility.spectral.libmobility_parameters`.  Where
UAMMD's discretisation differs from DoublyPeriodicStokes' (``rules == 'dpstokes'``, the core's product):

1. kernel edge: a node beyond the kernel's half-width gets weight 0 (no clamping); the x (y) nodes of a blob
   are the ``w`` nodes from the cell of the blob, moved one node up when the first is beyond the half-width;
2. z kernel: ``phi_z(d) - phi_z(d_image)`` with the blob's mirror image about the nearer end of the grid, at
   every end (walls and open ends alike; with the grid's buffers it only matters at walls);
3. the right-hand side of the vertical-velocity problem uses the Chebyshev derivative recurrence of the
   pressure coefficients (not the integration matrix's first integral);
4. wall corrections of unpaired (Nyquist) modes use the stored mode's raw wavenumbers and the real inverse
   transform (no averaging with the conjugate partner); the correction is added in Chebyshev space;
5. torques: spread with the plain ES torque kernel, transformed, and half their curl taken in
   Fourier-Chebyshev space (i kx, i ky zero at unpaired modes; d/dz by the recurrence) is added to the force
   coefficients; angular velocities interpolate half the spectral curl of the velocity with that kernel.

Only doubly periodic geometries (DP, DPBW, DPSC): libMobility's solver has no triply periodic mode.  This
module makes the stencils (1-2) for both paths and computes the whole product in NumPy (vectorised over blobs
and wavenumbers); force-only products can also run on the core's compiled engine, whose solve has rules 3 and
4.  Shapes as in :mod:`mobility.spectral.reference`: grids (3, Nz, Ny, Nx), z index 0 at the top.  Floor 1 of
the house.
"""
import time

import numpy as np
from scipy import fft

from utils import UserInputError

from . import reference
from .chebyshev import ChebyshevSystem
from .fourier import bottom_wall_correction, slit_correction
from .libmobility_parameters import simpson_normalisation
from .stencil import Stencil

BLOB_CHUNK = 8192
EXPANSION_KEPT = 1 << 22   # chain factors repeated per right-hand side are kept up to this many entries each


# ------------------------------------------------------------------ kernels and stencils
class _Kernel1D:
    """One direction of a UAMMD kernel: ``E(d / a) / (n a)`` with E zero beyond the half-width (grid units)."""

    def __init__(self, beta, alpha_cells, scale):
        self.beta = float(beta)
        self.scale = float(scale)
        self.alpha = float(alpha_cells)                          # half-width in cells (w / 2)
        self.inverse_norm = 1.0 / simpson_normalisation(self.beta, self.alpha)

    def __call__(self, d):
        z = (d / self.scale) / self.alpha
        z2 = z * z
        inside = z2 <= 1.0
        value = np.exp(self.beta * (np.sqrt(np.where(inside, 1.0 - z2, 0.0)) - 1.0)) * self.inverse_norm
        return np.where(inside, value, 0.0) / self.scale


def _minimum_image(d, L):
    """UAMMD's periodic wrap of a difference: ``d + floor(-d/L + 1/2) L`` (into [-L/2, L/2])."""
    return d + np.floor(d * (-1.0 / L) + 0.5) * L


class UammdKernel:
    """The three 1-D factors of one kernel (monopole or torque) of a ``rules='uammd'`` discretisation."""

    def __init__(self, parameters, kernel):
        p = parameters
        scales = (p.hx, p.hy, min(p.hx, p.hy))
        self.width = int(kernel.width[0] + 0.5)
        self.factors = [_Kernel1D(kernel.beta[c], 0.5 * self.width, scales[c]) for c in range(3)]
        # reach of the z window: half the width times the larger spacing
        self.reach = self.width * max(p.hx, p.hy) * 0.5

    def periodic_nodes(self, X, axis, p):
        """Node indices (n, w) and weights (n, w) along x (axis 0) or y (axis 1) for coordinates X (n,)."""
        L, h, n_nodes, origin = ((p.Lx, p.hx, p.Nx, p.x0), (p.Ly, p.hy, p.Ny, p.y0))[axis]
        w = self.width
        centre = origin + 0.5 * L                          # 0 for UAMMD's centred box
        Xc = X - centre
        inside = _minimum_image(Xc, L)
        cell = ((inside + 0.5 * L) * (1.0 / h)).astype(np.int64)
        cell[cell == n_nodes] = 0
        first = cell - w // 2
        leftmost = np.abs(_minimum_image(Xc - (-0.5 * L + h * first), L))
        first = first + (leftmost > w * h / 2.0)
        index = first[:, None] + np.arange(w)
        index = np.where(index <= -1, index + n_nodes, np.where(index >= n_nodes, index - n_nodes, index))
        d = _minimum_image(Xc[:, None] - (-0.5 * L + h * index), L)
        return index, self.factors[axis](d)

    def chebyshev_nodes(self, Z, p):
        """z node indices (n, m) and weights (n, m), blob heights Z (n,) (unused slots: weight 0)."""
        Lz, nz = p.Lz, p.Nz
        bound = 0.5 * Lz
        pz = Z - (p.z0 + bound)                             # relative to the middle of the grid, as UAMMD
        top = np.minimum(pz + self.reach, bound)
        bottom = np.maximum(pz - self.reach, -bound)
        first = ((nz - 1) * (np.arccos(np.clip(top / bound, -1.0, 1.0)) / np.pi)).astype(np.int64)
        last = ((nz - 1) * (np.arccos(np.clip(bottom / bound, -1.0, 1.0)) / np.pi)).astype(np.int64)
        count = last - first + 1
        slots = np.arange(max(int(count.max()), 1))
        used = slots < count[:, None]
        k = np.where(used, first[:, None] + slots, np.minimum(first, nz - 1)[:, None])
        heights = bound * np.cos(np.pi * k / (nz - 1))
        d = pz[:, None] - heights
        image = np.minimum(np.abs(Lz - 2.0 * pz[:, None] + d), np.abs(-Lz - 2.0 * pz[:, None] + d))
        phi = self.factors[2]
        weight = phi(d) - phi(image)
        return k, np.where(used, weight, 0.0)

    def stencil(self, p, r):
        """The :class:`~mobility.spectral.stencil.Stencil` of blobs at ``r`` (n, 3) (x, y in any period)."""
        ix, phi_x = self.periodic_nodes(r[:, 0], 0, p)
        iy, phi_y = self.periodic_nodes(r[:, 1], 1, p)
        iz, phi_z = self.chebyshev_nodes(r[:, 2], p)
        return Stencil(ix, iy, iz, phi_x, phi_y, phi_z)


# ------------------------------------------------------------------ transforms and the solve
def _wavevectors(p):
    """(kx, ky, K, Dx, Dy) on the (Ny, Nx//2+1) half spectrum: UAMMD's integer modes times 2 pi / L; the
    derivative factors Dx, Dy (real, multiply by i) are zero at unpaired modes."""
    nkx = p.Nx // 2 + 1
    mx = np.arange(nkx)
    my = np.arange(p.Ny)
    my = my - p.Ny * (my >= p.Ny // 2 + 1)
    kx = (mx * (2.0 * np.pi / p.Lx))[None, :] * np.ones((p.Ny, 1))
    ky = (my * (2.0 * np.pi / p.Ly))[:, None] * np.ones((1, nkx))
    Dx = np.where((mx == p.Nx - mx)[None, :], 0.0, kx)
    Dy = np.where((my == p.Ny - my)[:, None], 0.0, ky)
    return kx, ky, np.sqrt(kx * kx + ky * ky), Dx, Dy


def to_spectrum(cheb, grid):
    """Chebyshev-Fourier coefficients (Nz, C, Ny, Nx//2+1) of real grids (C, Nz, Ny, Nx)."""
    return fft.rfftn(cheb.to_coefficients(grid.transpose(1, 0, 2, 3)), axes=(2, 3))


def to_grid(cheb, coefficients, p):
    """Real grids (C, Nz, Ny, Nx) from coefficients (Nz, C, Ny, Nx//2+1) (real inverse transform)."""
    values = fft.irfftn(cheb.to_values(coefficients), s=(p.Ny, p.Nx), axes=(2, 3))
    return np.ascontiguousarray(values.transpose(1, 0, 2, 3))


def half_curl(cheb, c, Dx, Dy):
    """Half the curl (Nz, 3, Ny, Nkx) of a field given by its coefficients c (Nz, 3, Ny, Nkx)."""
    dz = [cheb.derivative(c[:, i]) for i in (0, 1)]
    out = np.empty_like(c)
    out[:, 0] = 0.5 * (1j * Dy * c[:, 2] - dz[1])
    out[:, 1] = 0.5 * (dz[0] - 1j * Dx * c[:, 2])
    out[:, 2] = 0.5 * (1j * Dx * c[:, 1] - 1j * Dy * c[:, 0])
    return out


class UammdSolver:
    """The Fourier-Chebyshev Stokes solve of a ``rules='uammd'`` discretisation.

    The two-point problems ``(D^2 - K^2) u = r``, ``u' + K u = top`` at the top, ``u' - K u = bottom`` at the
    bottom are those of :class:`~mobility.spectral.chebyshev.ChebyshevSystem` (Greengard's integration
    discretisation), solved by its chain elimination and a 2 x 2 Schur complement for the integration
    constants; everything that depends only on the wavenumbers is computed once here.
    """

    def __init__(self, parameters, eta):
        p = parameters
        self.p = p
        self.eta = float(eta)
        cheb = ChebyshevSystem(p.Nz, p.Lz)
        self.cheb = cheb
        kx, ky, K, Dx, Dy = _wavevectors(p)
        self.kx, self.ky, self.K, self.Dx, self.Dy = kx, ky, K, Dx, Dy
        self.live = K > 0
        Kl = K[self.live]
        N, H = cheb.N, cheb.H
        self._factors = cheb.factor(Kl)
        self._expanded = {}
        q = self._factors[3]
        self._top_rows = (H * H) * Kl[None, :] * cheb.R2[:, None] + H * cheb.R1[:, None]
        self._bottom_rows = (H * H) * Kl[None, :] * cheb.L2[:, None] + H * cheb.L1[:, None]
        unit = np.zeros((N, Kl.size, 2))              # e0 and e1 per wavenumber (the layout of _solve)
        unit[0, :, 0] = unit[1, :, 1] = 1.0
        z01 = ChebyshevSystem.chain_solve(self._expand(2), unit.reshape(N, -1)).reshape(N, -1, 2)
        z01 = np.moveaxis(z01, 2, 1)                   # (N, 2, m)
        self._z01 = z01
        g = [[q * np.sum(rows[:N] * z01[:, j], axis=0) + rows[N + j] for j in (0, 1)]
             for rows in (self._top_rows, self._bottom_rows)]
        self._schur = (g[0][0], g[0][1], g[1][0], g[1][1], g[0][0] * g[1][1] - g[0][1] * g[1][0])
        self.z = p.z_nodes()

    def _expand(self, copies):
        """The chain factors repeated for ``copies`` right-hand sides per wavenumber (columns m*copies), kept."""
        if copies in self._expanded:
            return self._expanded[copies]
        expanded = tuple(np.repeat(f, copies, axis=-1) for f in self._factors)
        if expanded[0].size <= EXPANSION_KEPT:
            self._expanded[copies] = expanded
        return expanded

    def _solve(self, rhs, top, bottom):
        """Coefficients (N, c, m) of the solutions of ``c`` problems per wavenumber: rhs (N, c, m), top and
        bottom (c, m) (Robin data)."""
        cheb = self.cheb
        N, m = cheb.N, self.K[self.live].size
        copies = rhs.shape[1]
        q = self._factors[3]
        a = ChebyshevSystem.chain_solve(self._expand(copies), np.moveaxis(rhs, 1, 2).reshape(N, -1))
        a = np.moveaxis(a.reshape(N, m, copies), 2, 1)                       # (N, c, m)
        g_t0, g_t1, g_b0, g_b1, det = self._schur
        r_t = top - np.sum(self._top_rows[:N, None] * a, axis=0)
        r_b = bottom - np.sum(self._bottom_rows[:N, None] * a, axis=0)
        c0 = (r_t * g_b1 - g_t1 * r_b) / det
        d0 = (g_t0 * r_b - g_b0 * r_t) / det
        x = np.empty((N + 2,) + a.shape[1:], dtype=a.dtype)
        x[:N] = a + q * (c0[None] * self._z01[:, None, 0] + d0[None] * self._z01[:, None, 1])
        x[N], x[N + 1] = c0, d0
        return (cheb.H * cheb.H) * (cheb.S1 @ x.reshape(N + 2, -1)).reshape((N,) + x.shape[1:])

    def solve(self, f):
        """Velocity coefficients (Nz, 3, Ny, Nkx) from force coefficients f (Nz, 3, Ny, Nkx)."""
        p, cheb, eta = self.p, self.cheb, self.eta
        live = self.live
        K = self.K[live]
        Dx, Dy = self.Dx[live], self.Dy[live]
        fl = f[:, :, live]
        fx, fy, fz = fl[:, 0], fl[:, 1], fl[:, 2]
        zero = np.zeros((1, K.size), dtype=complex)
        rhs = (1j * Dx * fx + 1j * Dy * fy + cheb.derivative(fz))[:, None]
        pressure = self._solve(rhs, zero, zero)[:, 0]
        p_top = pressure.sum(axis=0)
        p_bottom = ((-1.0) ** np.arange(p.Nz)) @ pressure
        rhs = np.stack(((1j * Dx * pressure - fx) / eta, (1j * Dy * pressure - fy) / eta,
                        (cheb.derivative(pressure) - fz) / eta), axis=1)
        top = np.stack((-0.5 * Dx / (eta * K) * 1j * p_top, -0.5 * Dy / (eta * K) * 1j * p_top, 0.5 / eta * p_top))
        bottom = np.stack((0.5 * Dx / (eta * K) * 1j * p_bottom, 0.5 * Dy / (eta * K) * 1j * p_bottom,
                           0.5 / eta * p_bottom))
        u = np.zeros_like(f)
        u[:, :, live] = self._solve(rhs, top, bottom)
        if p.geometry != 'DP':
            self._correct(u, f)
        return u

    def _correct(self, u, f):
        """Add the walls' homogeneous correction (k != 0) and the mean flow (k = 0) in Chebyshev space."""
        p, cheb, live = self.p, self.cheb, self.live
        alternating = (-1.0) ** np.arange(p.Nz)
        ul = u[:, :, live]
        bottom = -np.tensordot(alternating, ul, axes=(0, 0))
        kx, ky, K = self.kx[live], self.ky[live], self.K[live]
        if p.geometry == 'DPBW':
            values = bottom_wall_correction(kx, ky, K, bottom, self.z)
        else:
            values = slit_correction(kx, ky, K, bottom, -ul.sum(axis=0), self.z, p.Lz, self.eta)
        u[:, :, live] += cheb.to_coefficients(values.transpose(1, 0, 2))
        zero = ~live
        for c in (0, 1):
            u[:, c, zero] = cheb.mean_flow(-f[:, c, zero] / self.eta, p.geometry)
        u[:, 2, zero] = 0.0


# ------------------------------------------------------------------ the product
class UammdStokes:
    """The product ``[U; W] = M [F; T]`` with UAMMD's rules, for ``SpectralStokes`` (which checks the inputs).

    parameters : SpectralParameters with ``rules == 'uammd'`` and a doubly periodic geometry; eta : viscosity;
    path : 'compiled' or 'numpy'.  ``set_positions(r (N, 3) checked floats)``; ``product(forces (N, 3) or None,
    torques (N, 3) or None) -> (U (N, 3), W (N, 3) or None)``; ``timings`` (seconds of the phases of the last
    product).  A force-only discretisation runs on the core's compiled engine where asked (its solve has the
    rules' pressure derivative and wall corrections; the stencils are made here), one with torques on NumPy
    (the spectral curl is not compiled); ``path`` says which.
    """

    def __init__(self, parameters, eta, path='numpy', workers=None):
        p = parameters
        if p.rules != 'uammd':
            raise UserInputError('UammdStokes computes the uammd rules, got parameters with rules %r' % p.rules)
        if p.geometry == 'TP':
            raise UserInputError("the uammd rules cover the doubly periodic geometries (DP, DPBW, DPSC); libMobility's "
                                 'DPStokes has no triply periodic mode')
        self.parameters = p
        self.eta = float(eta)
        self.monopole = UammdKernel(p, p.monopole)
        self.dipole = UammdKernel(p, p.dipole) if p.dipole is not None else None
        self.solver = UammdSolver(p, eta)
        self.timings = {}
        self.n_blobs = 0
        self._stencils = None
        self.path = 'compiled' if path == 'compiled' and p.dipole is None else 'numpy'
        self._engine = None
        if self.path == 'compiled':
            from .compiled import CompiledEngine
            self._engine = CompiledEngine(p, eta, workers)

    @property
    def has_torque(self):
        return self.parameters.has_torque

    def set_positions(self, r):
        """Prepare the stencils of blobs at ``r`` (N, 3) (already checked against the walls and the grid)."""
        start = time.perf_counter()
        p = self.parameters
        r = np.asarray(r, dtype=float)
        if self._engine is not None:
            self._engine.prepare(self.monopole.stencil(p, r), None)
            self._stencils = [None, None]
            self.n_blobs = r.shape[0]
            self.timings['prepare'] = time.perf_counter() - start
            return
        stencils = []
        for kernel in (self.monopole, self.dipole):
            if kernel is None:
                stencils.append(None)
                continue
            parts = [kernel.stencil(p, r[rows]) for rows in reference._blocks(r.shape[0], BLOB_CHUNK)]
            stencils.append(parts)
        self._stencils = stencils
        self.n_blobs = r.shape[0]
        self.timings['prepare'] = time.perf_counter() - start

    def _spread(self, which, values, grid):
        start = 0
        for part in self._stencils[which]:
            rows = slice(start, start + part.n)
            reference.spread_forces(self.parameters, part, values[rows], grid)
            start += part.n

    def _interpolate(self, which, grid):
        return np.concatenate([self._interpolate_part(part, grid) for part in self._stencils[which]])

    def _interpolate_part(self, part, grid):
        return reference.interpolate_velocities(self.parameters, part, grid)

    def product(self, F=None, T=None):
        """``(U, W)`` (N, 3) each (W None without a torque kernel) from forces F and torques T, (N, 3) or None."""
        if self._stencils is None:
            raise UserInputError('spectral product: call set_positions before product')
        if self._engine is not None:
            U, _, timings = self._engine.product(F, None, want_rotation=False)
            self.timings.update(timings)
            return U, None
        p = self.parameters
        clock = time.perf_counter
        t0 = clock()
        cheb = self.solver.cheb
        grid = np.zeros((3, p.Nz, p.Ny, p.Nx))
        if F is not None:
            self._spread(0, F, grid)
        torque_grid = None
        if T is not None:
            torque_grid = np.zeros_like(grid)
            self._spread(1, T, torque_grid)
        t1 = clock()
        f = to_spectrum(cheb, grid)
        if torque_grid is not None:
            f += half_curl(cheb, to_spectrum(cheb, torque_grid), self.solver.Dx, self.solver.Dy)
        t2 = clock()
        u = self.solver.solve(f)
        t3 = clock()
        velocity = to_grid(cheb, u, p)
        rotation = None
        if self.has_torque:
            rotation = to_grid(cheb, half_curl(cheb, u, self.solver.Dx, self.solver.Dy), p)
        t4 = clock()
        U = self._interpolate(0, velocity)
        W = self._interpolate(1, rotation) if rotation is not None else None
        t5 = clock()
        self.timings.update(spread=t1 - t0, fft=(t2 - t1) + (t4 - t3), solve=t3 - t2, interpolate=t5 - t4)
        return U, W
