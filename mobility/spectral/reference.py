"""The NumPy path of the spectral Stokes product: readable, vectorised over blobs (in chunks, so memory stays
bounded) and over wavenumbers (loops run only over the z index).  The compiled path
(``mobility.spectral.compiled``) computes the same numbers to round-off; tests compare the two.

Grids are real arrays (3, Nz, Ny, Nx) (component, z, y, x), z index 0 at the top of a Chebyshev grid.

The Stokes solves (:func:`solve`) take an array namespace ``xp``: NumPy here (transforms by ``scipy.fft``), or
CuPy for the GPU product (``mobility.spectral.array_product``: ``cupy.fft``), the same statements either way.
"""
import numpy as np
from scipy import fft

from .chebyshev import ChebyshevSystem
from .fourier import (bottom_wall_correction, derivative_factors, partner_wavenumbers, slit_correction, unpaired,
                      wavenumbers)

BLOB_CHUNK = 4096  # blobs per vectorised block: (chunk, nz, wy, wx) weights stay a few tens of MB


def _blocks(n, size=BLOB_CHUNK):
    for start in range(0, n, size):
        yield slice(start, min(start + size, n))


def _flat_index(p, st):
    """(n, nz, wy, wx) flat grid indices of a stencil."""
    return (st.iz[:, :, None, None] * p.Ny + st.iy[:, None, :, None]) * p.Nx + st.ix[:, None, None, :]


def _outer(wz, wy, wx):
    return wz[:, :, None, None] * wy[:, None, :, None] * wx[:, None, None, :]


# ------------------------------------------------------------------ spreading and interpolation
def spread_forces(p, stencil, forces, grid):
    """grid (3, Nz, Ny, Nx) += the forces (n, 3) spread with the monopole stencil."""
    flat = grid.reshape(3, -1)
    for rows in _blocks(stencil.n):
        st = stencil.take(rows)
        index = _flat_index(p, st).ravel()
        weight = _outer(st.phi_z, st.phi_y, st.phi_x)
        for c in range(3):
            np.add.at(flat[c], index, (weight * forces[rows, c, None, None, None]).ravel())


def _dipole_weights(st):
    """The three derivative-kernel weights (Dx, Dy, Dz), each (n, nz, wy, wx)."""
    return (_outer(st.phi_z, st.phi_y, st.dphi_x), _outer(st.phi_z, st.dphi_y, st.phi_x),
            _outer(st.dphi_z, st.phi_y, st.phi_x))


def spread_torques(p, stencil, torques, grid):
    """grid += (1/2) curl of the torques (n, 3) spread with the dipole stencil."""
    flat = grid.reshape(3, -1)
    for rows in _blocks(stencil.n):
        st = stencil.take(rows)
        index = _flat_index(p, st).ravel()
        Dx, Dy, Dz = _dipole_weights(st)
        T = [torques[rows, c, None, None, None] for c in range(3)]
        np.add.at(flat[0], index, (0.5 * (T[2] * Dy - T[1] * Dz)).ravel())
        np.add.at(flat[1], index, (0.5 * (T[0] * Dz - T[2] * Dx)).ravel())
        np.add.at(flat[2], index, (0.5 * (T[1] * Dx - T[0] * Dy)).ravel())


def _quadrature(p, st):
    """z factors times the quadrature weights hx hy wz of the nodes, (n, nz) each for phi_z and dphi_z."""
    wz = p.z_weights()[st.iz] * (p.hx * p.hy)
    return st.phi_z * wz, (None if st.dphi_z is None else st.dphi_z * wz)


def interpolate_velocities(p, stencil, grid):
    """U (n, 3): the grid velocity averaged with the monopole kernel."""
    flat = grid.reshape(3, -1)
    U = np.empty((stencil.n, 3))
    for rows in _blocks(stencil.n):
        st = stencil.take(rows)
        index = _flat_index(p, st)
        qz, _ = _quadrature(p, st)
        weight = _outer(qz, st.phi_y, st.phi_x)
        for c in range(3):
            U[rows, c] = np.sum(flat[c][index] * weight, axis=(1, 2, 3))
    return U


def interpolate_rotations(p, stencil, grid):
    """W (n, 3): half the vorticity averaged with the dipole kernel (minus the curl of the derivative spread)."""
    flat = grid.reshape(3, -1)
    W = np.empty((stencil.n, 3))
    for rows in _blocks(stencil.n):
        st = stencil.take(rows)
        index = _flat_index(p, st)
        qz, dqz = _quadrature(p, st)
        Dx = _outer(qz, st.phi_y, st.dphi_x)
        Dy = _outer(qz, st.dphi_y, st.phi_x)
        Dz = _outer(dqz, st.phi_y, st.phi_x)
        u = [flat[c][index] for c in range(3)]

        def g(D, c):
            return np.sum(u[c] * D, axis=(1, 2, 3))
        W[rows, 0] = -0.5 * (g(Dy, 2) - g(Dz, 1))
        W[rows, 1] = -0.5 * (g(Dz, 0) - g(Dx, 2))
        W[rows, 2] = -0.5 * (g(Dx, 1) - g(Dy, 0))
    return W


# ------------------------------------------------------------------ the Stokes solves
def _transforms(xp):
    """The FFT module of an array namespace: scipy.fft for NumPy, ``xp.fft`` otherwise (cupy.fft)."""
    return fft if xp is np else xp.fft


def solve_triply_periodic(p, eta, grid, xp=np):
    """Velocity grid (3, Nz, Ny, Nx) from the force density grid on the triply periodic grid."""
    transforms = _transforms(xp)
    fhat = transforms.rfftn(grid, axes=(1, 2, 3))
    kz = xp.asarray(wavenumbers(p.Nz, p.Lz))[:, None, None]
    ky = xp.asarray(wavenumbers(p.Ny, p.Ly))[None, :, None]
    kx = xp.asarray(wavenumbers(p.Nx, p.Lx)[:p.Nx // 2 + 1])[None, None, :]
    ik = [xp.asarray(derivative_factors(p.Nx, p.Lx)[:p.Nx // 2 + 1])[None, None, :],
          xp.asarray(derivative_factors(p.Ny, p.Ly))[None, :, None],
          xp.asarray(derivative_factors(p.Nz, p.Lz))[:, None, None]]
    k2 = kx * kx + ky * ky + kz * kz
    k2[0, 0, 0] = 1.0
    # fhat is ordered (x, y, z) components; ik in the same order
    pressure = -(ik[0] * fhat[0] + ik[1] * fhat[1] + ik[2] * fhat[2]) / k2
    uhat = xp.empty_like(fhat)
    for c in range(3):
        uhat[c] = (fhat[c] - ik[c] * pressure) / (eta * k2)
        uhat[c][0, 0, 0] = 0.0
    return transforms.irfftn(uhat, s=(p.Nz, p.Ny, p.Nx), axes=(1, 2, 3))


def solve_doubly_periodic(p, eta, grid, xp=np):
    """Velocity grid (3, Nz, Ny, Nx) from the force density grid in the DP, DPBW and DPSC geometries."""
    N = p.Nz
    transforms = _transforms(xp)
    cheb = ChebyshevSystem(N, p.Lz, xp)
    Nxh = p.Nx // 2 + 1
    coefficients = transforms.rfftn(cheb.to_coefficients(grid.transpose(1, 0, 2, 3)), axes=(2, 3))  # (Nz, 3, Ny, Nxh)
    kx = np.broadcast_to(wavenumbers(p.Nx, p.Lx)[:Nxh][None, :], (p.Ny, Nxh)).ravel()
    ky = np.broadcast_to(wavenumbers(p.Ny, p.Ly)[:, None], (p.Ny, Nxh)).ravel()
    dx = np.broadcast_to(derivative_factors(p.Nx, p.Lx)[:Nxh][None, :], (p.Ny, Nxh)).ravel()
    dy = np.broadcast_to(derivative_factors(p.Ny, p.Ly)[:, None], (p.Ny, Nxh)).ravel()
    K = np.sqrt(kx * kx + ky * ky)
    f = coefficients.reshape(N, 3, -1)
    u = xp.zeros_like(f)
    live = np.flatnonzero(K > 0)                   # every mode but k = 0 (indices: the same in every namespace)
    still = np.flatnonzero(K == 0)
    partner = _needs_partner(p)[live]
    kx_partner, ky_partner = (v[live] for v in _partner(p))
    kx, ky, K, dx, dy = (xp.asarray(v[live]) for v in (kx, ky, K, dx, dy))
    live, still = xp.asarray(live), xp.asarray(still)
    fx, fy, fz = (f[:, c, live] for c in range(3))
    Kl, dxl, dyl = K, dx, dy
    factors = cheb.factor(Kl)
    # pressure: (D^2 - K^2) p = Dx fx + Dy fy + D fz, p' + K p = 0 (top), p' - K p = 0 (bottom)
    zero = xp.zeros(Kl.size, dtype=complex)
    x_pressure = cheb.solve(Kl, factors, dxl * fx + dyl * fy + cheb.derivative(fz), zero, zero)
    pc = cheb.values_of(x_pressure)
    # p' in the w equation: DoublyPeriodicStokes takes F x_p, UAMMD the Chebyshev recurrence of p
    dpc = cheb.derivative(pc) if p.rules == 'uammd' else cheb.derivatives_of(x_pressure)
    p_top = pc.sum(axis=0)
    p_bottom = xp.asarray((-1.0) ** np.arange(N)) @ pc
    # velocity: eta (D^2 - K^2) u = Dx p - fx (v, w alike) with the Robin conditions of the open fluid
    for c, (rhs, top, bottom) in enumerate((
            ((dxl * pc - fx) / eta, -dxl * p_top / (2 * eta * Kl), dxl * p_bottom / (2 * eta * Kl)),
            ((dyl * pc - fy) / eta, -dyl * p_top / (2 * eta * Kl), dyl * p_bottom / (2 * eta * Kl)),
            ((dpc - fz) / eta, p_top / (2 * eta), p_bottom / (2 * eta)))):
        u[:, c, live] = cheb.values_of(cheb.solve(Kl, factors, rhs, top, bottom))
    if p.geometry != 'DP':                         # k = 0: the mean flow between walls
        u[:, 0, still] = cheb.mean_flow(-f[:, 0, still] / eta, p.geometry)
        u[:, 1, still] = cheb.mean_flow(-f[:, 1, still] / eta, p.geometry)
    values = cheb.to_values(u)                     # (Nz, 3, nk): node values, Fourier in x and y
    if p.geometry != 'DP':
        values[:, :, live] += _wall_correction(p, eta, cheb, u[:, :, live], kx, ky, Kl, partner, kx_partner,
                                               ky_partner, xp)
    values = values.reshape(N, 3, p.Ny, Nxh)
    out = transforms.irfftn(values, s=(p.Ny, p.Nx), axes=(2, 3))
    return xp.ascontiguousarray(out.transpose(1, 0, 2, 3))


def _needs_partner(p):
    """(Ny * Nxh,) bool: modes whose conjugate partner has a raw wavenumber that is not minus theirs (none
    under UAMMD's rules, whose real inverse transform takes each stored mode's correction as it is)."""
    Nxh = p.Nx // 2 + 1
    if p.rules == 'uammd':
        return np.zeros(p.Ny * Nxh, dtype=bool)
    return (unpaired(p.Nx)[:Nxh][None, :] | unpaired(p.Ny)[:, None]).ravel()


def _partner(p):
    """Raw wavenumbers (kx, ky), each (Ny * Nxh,), of every stored mode's conjugate partner."""
    Nxh = p.Nx // 2 + 1
    kxp = np.broadcast_to(partner_wavenumbers(p.Nx, p.Lx)[:Nxh][None, :], (p.Ny, Nxh)).ravel()
    kyp = np.broadcast_to(partner_wavenumbers(p.Ny, p.Ly)[:, None], (p.Ny, Nxh)).ravel()
    return kxp, kyp


def _wall_correction(p, eta, cheb, u, kx, ky, K, needs_partner, kxp, kyp, xp=np):
    """Node values (Nz, 3, m) of the homogeneous Stokes flow that cancels the DP solution on the walls.

    u (Nz, 3, m), kx, ky, K (m,): arrays of ``xp``; needs_partner (m,) bool and the partners' raw wavenumbers
    kxp, kyp (m,): NumPy.

    The library transforms back with a complex inverse FFT and keeps the real part, so where a mode's
    conjugate partner has its own raw wavenumbers (unpaired modes) the correction is the average of the
    mode's and the conjugate of its partner's (what the real part of the full inverse transform sees).
    """
    N = cheb.N
    z = p.z_nodes()
    alternating = xp.asarray((-1.0) ** np.arange(N))
    b = -xp.einsum('j,jcm->cm', alternating, u)
    t = -u.sum(axis=0)

    def correction(kx_, ky_, K_, b_, t_):
        if p.geometry == 'DPBW':
            return bottom_wall_correction(kx_, ky_, K_, b_, z, xp)
        return slit_correction(kx_, ky_, K_, b_, t_, z, p.Lz, eta, xp)
    values = correction(kx, ky, K, b, t)
    if np.any(needs_partner):
        m = xp.asarray(np.flatnonzero(needs_partner))
        partner = correction(xp.asarray(kxp[needs_partner]), xp.asarray(kyp[needs_partner]), K[m],
                             xp.conj(b[:, m]), xp.conj(t[:, m]))
        values[:, :, m] = 0.5 * (values[:, :, m] + xp.conj(partner))
    return values.transpose(1, 0, 2)


def solve(p, eta, grid, xp=np):
    """Velocity grid from force density grid, (3, Nz, Ny, Nx) each, in the geometry of ``p``; ``xp`` the grid's
    array namespace (numpy or cupy)."""
    if p.geometry == 'TP':
        return solve_triply_periodic(p, eta, grid, xp)
    return solve_doubly_periodic(p, eta, grid, xp)
