"""Exact Brownian velocities of the triply periodic spectral product at the cost of about half a product.

Fluctuating force coupling (Keaveny, "Fluctuating force-coupling method for simulations of colloidal
suspensions", J. Comput. Phys. 269, 61, 2014; the same idea underlies the wave-space part of positively split
Ewald, Fiore, Balboa Usabiaga, Donev and Swan, J. Chem. Phys. 146, 124116, 2017): a white-noise fluid stress
drives the periodic Stokes flow, and the flow averaged over each blob's kernel has exactly the covariance of
the blob mobility.  On the grid of the triply periodic product (:mod:`mobility.spectral.reference`):

* the product is ``M = J G S``: ``S`` spreads forces with the kernel weights ``phi`` (1/length^3),
  ``J = dV S^T`` interpolates with the quadrature weight ``dV = hx hy hz``, and ``G`` is the Stokes solve,
  diagonal in Fourier space: ``G(k) = P(k) / (eta |k|^2)``, ``P(k) = I - k~ k~^T / |k|^2`` (``k~`` is ``k``
  with the unpaired Nyquist component set to zero, as the product's derivative factors are), and
  ``G(0) = 0``;
* ``u = G^{1/2} xi`` with ``xi`` independent normal grid values of variance ``1/dV`` has covariance
  ``G / dV``, so ``U = J u`` has covariance ``J G J^T / dV = J G S = M``, the product's own mobility, to
  round-off.  ``G^{1/2}(k) = P(k)^{1/2} / sqrt(eta |k|^2)``, with ``P^{1/2} = I + (sqrt(1 - s) - 1)
  k~ k~^T / |k~|^2``, ``s = |k~|^2 / |k|^2`` (``P`` is a projector except at Nyquist modes, where ``s < 1``).

One real FFT of the noise, one inverse and one interpolation: no Krylov iteration, no tolerance.  Only the
triply periodic geometry has a diagonal Stokes solve; in the Chebyshev geometries the square root would need
the wall solves' factorisation, which is not offered (Lanczos is used there).

Floor 1 (numpy, scipy and this package's spectral modules).
"""
import hashlib

import numpy as np
from scipy import fft

from utils import UserInputError

from . import reference
from .fourier import derivative_factors, wavenumbers
from .stencil import make_stencil, wrap_positions


def root_stokes_factors(p, eta):
    """The Fourier factors of ``G^{1/2}`` on the real-transform grid of a TP discretisation ``p``.

    Returns ``(scale, kt, c)``: ``scale`` (Nz, Ny, Nx//2+1) = ``1/sqrt(eta |k|^2)`` (0 at k = 0), ``kt`` the
    three components of ``k~`` (each broadcastable to that shape) and ``c`` = ``(sqrt(1 - s) - 1)/|k~|^2``
    (0 where ``k~ = 0``), so that ``G^{1/2} x = scale (x + c k~ (k~ . x))``.
    """
    kx = wavenumbers(p.Nx, p.Lx)[:p.Nx // 2 + 1][None, None, :]
    ky = wavenumbers(p.Ny, p.Ly)[None, :, None]
    kz = wavenumbers(p.Nz, p.Lz)[:, None, None]
    kt = (derivative_factors(p.Nx, p.Lx)[:p.Nx // 2 + 1].imag[None, None, :],
          derivative_factors(p.Ny, p.Ly).imag[None, :, None],
          derivative_factors(p.Nz, p.Lz).imag[:, None, None])
    k2 = kx * kx + ky * ky + kz * kz
    kt2 = kt[0] ** 2 + kt[1] ** 2 + kt[2] ** 2
    zero = k2 == 0
    k2_safe = np.where(zero, 1.0, k2)
    scale = np.where(zero, 0.0, 1.0 / np.sqrt(eta * k2_safe))
    s = np.where(zero, 0.0, kt2 / k2_safe)
    kt2_safe = np.where(kt2 == 0, 1.0, kt2)
    c = np.where(kt2 == 0, 0.0, (np.sqrt(np.maximum(1.0 - s, 0.0)) - 1.0) / kt2_safe)
    return scale, kt, c


def triply_periodic_noise(p, eta, r_vectors, rng, factor=1.0):
    """``factor`` times blob velocities (N, 3) with covariance the TP spectral mobility at ``r_vectors`` (N, 3).

    p : SpectralParameters of geometry ``TP`` (force-only or the monopole of a torque discretisation);
    eta : viscosity; rng : ``numpy.random.Generator`` drawing the ``3 Nx Ny Nz`` grid normals.
    """
    if p.geometry != 'TP':
        raise UserInputError('the fluctuating (exact) spectral noise exists in the triply periodic geometry only, '
                             'not in %s; use the Lanczos noise there' % p.geometry)
    r = np.asarray(r_vectors, dtype=float).reshape(-1, 3)
    stencil = make_stencil(p, p.monopole, wrap_positions(p, r))
    dV = p.hx * p.hy * p.hz
    xi = rng.standard_normal((3, p.Nz, p.Ny, p.Nx)) / np.sqrt(dV)
    xhat = fft.rfftn(xi, axes=(1, 2, 3))
    del xi
    scale, kt, c = root_stokes_factors(p, eta)
    projection = c * (kt[0] * xhat[0] + kt[1] * xhat[1] + kt[2] * xhat[2])
    for component in range(3):
        xhat[component] = scale * (xhat[component] + kt[component] * projection)
    del projection
    velocity = fft.irfftn(xhat, s=(p.Nz, p.Ny, p.Nx), axes=(1, 2, 3))
    return factor * reference.interpolate_velocities(p, stencil, velocity)


def generator_from_normals(z):
    """A ``numpy.random.Generator`` seeded with the bits of the normal vector ``z`` (any shape).

    The schemes draw one standard normal vector per noise; the fluctuating noise needs grid normals instead, so
    it draws them from a generator seeded with the SHA-256 digest of ``z``'s bits: a run stays a function of its seed (and a restart repeats
    it), and different ``z`` give independent grid noise.
    """
    digest = hashlib.sha256(np.ascontiguousarray(z, dtype=np.float64).tobytes()).digest()
    return np.random.default_rng(np.random.SeedSequence(np.frombuffer(digest, dtype=np.uint32).tolist()))
