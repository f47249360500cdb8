"""Wavenumbers and the wall corrections of the doubly periodic solves (shared by both paths).

Fourier convention: ``fhat(k) = sum_x f(x) e^{-ikx}``, ``f(x) = (1/N) sum_k fhat(k) e^{ikx}``, so d/dx -> ik.
Grid index i along an axis of N points has the integer mode ``m = i`` for ``i <= N//2`` and ``i - N`` above;
the wavenumber is ``2 pi m / L``.  For even N the unpaired mode ``m = N/2`` keeps its raw wavenumber
``+pi/h`` in ``k^2``, ``|k|`` and the wall corrections, but its derivative factor ``ik`` is zero (the rule of
DoublyPeriodicStokes).  The real transforms store x modes 0..Nx//2 only.

The wavenumbers are NumPy arrays (small, made on the host); the wall corrections take an array namespace ``xp``
(numpy, or cupy for the GPU product) for the per-mode arrays they receive and return.
"""
import numpy as np


def modes(n):
    """Integer modes of the n grid indices, (n,)."""
    i = np.arange(n)
    return np.where(i <= n // 2, i, i - n)


def wavenumbers(n, length):
    """Raw wavenumbers (n,) of the grid indices along an axis of n points and period ``length``."""
    return 2.0 * np.pi * modes(n) / length


def derivative_factors(n, length):
    """The factors ``i k`` (n,) complex, zero for the unpaired mode of even n."""
    k = 1j * wavenumbers(n, length)
    if n % 2 == 0:
        k[n // 2] = 0.0
    return k


def partner_wavenumbers(n, length):
    """Raw wavenumbers of the index -i mod n (the conjugate partner of index i), (n,)."""
    return wavenumbers(n, length)[(n - np.arange(n)) % n]


def unpaired(n):
    """Boolean (n,): the unpaired (Nyquist) index of an even n."""
    out = np.zeros(n, dtype=bool)
    if n % 2 == 0:
        out[n // 2] = True
    return out


# ------------------------------------------------------------------ wall corrections
def bottom_wall_correction(kx, ky, K, b, z, xp=np):
    """Homogeneous Stokes velocity in z > 0, decaying upwards, equal to ``b`` (3, m) at z = 0.

    kx, ky, K (m,): raw wavenumbers and |k| > 0; z (Nz,) heights above the wall.  Returns (3, Nz, m):
    ``A = kx b_x + ky b_y + i K b_z``, ``u = (-kx A z/K + b_x) e^{-Kz}``, ``v = (-ky A z/K + b_y) e^{-Kz}``,
    ``w = (-i A z + b_z) e^{-Kz}`` (pressure ``-2 i eta A e^{-Kz}``).  ``xp``: the arrays' namespace.
    """
    A = kx * b[0] + ky * b[1] + 1j * K * b[2]
    zz = xp.asarray(z)[:, None]
    decay = xp.exp(-K[None, :] * zz)
    u = (-kx * A * zz / K + b[0]) * decay
    v = (-ky * A * zz / K + b[1]) * decay
    w = (-1j * A * zz + b[2]) * decay
    return xp.stack([u, v, w])


def slit_coefficients(kx, ky, K, b, t, Lz, eta, xp=np):
    """The eight coefficients (8, m) of the homogeneous Stokes solution in 0 < z < Lz equal to ``b`` (3, m) at
    z = 0 and ``t`` (3, m) at z = Lz (pressure ``a1 e^{-Kz} + a2 e^{K(z-Lz)}``; see :func:`slit_correction`)."""
    m = K.size
    E = xp.exp(-K * Lz)
    q = 1.0 / (2.0 * eta)
    M = xp.zeros((m, 8, 8), dtype=complex)
    rhs = xp.zeros((m, 8), dtype=complex)
    M[:, 0, 0] = q
    M[:, 0, 1] = E * q
    M[:, 0, 6] = -K
    M[:, 0, 7] = K * E
    rhs[:, 0] = -1j * kx * b[0] - 1j * ky * b[1]
    M[:, 1, 0] = (1 - K * Lz) * E * q
    M[:, 1, 1] = (1 + K * Lz) * q
    M[:, 1, 6] = -K * E
    M[:, 1, 7] = K
    rhs[:, 1] = -1j * kx * t[0] - 1j * ky * t[1]
    for row, (i, j), value in ((2, (2, 3), b[0]), (3, (4, 5), b[1]), (4, (6, 7), b[2])):
        M[:, row, i] = 1.0
        M[:, row, j] = E
        rhs[:, row] = value
    M[:, 5, 0] = -1j * kx * Lz * E * q / K
    M[:, 5, 1] = 1j * kx * Lz * q / K
    M[:, 5, 2] = E
    M[:, 5, 3] = 1.0
    rhs[:, 5] = t[0]
    M[:, 6, 0] = -1j * ky * Lz * E * q / K
    M[:, 6, 1] = 1j * ky * Lz * q / K
    M[:, 6, 4] = E
    M[:, 6, 5] = 1.0
    rhs[:, 6] = t[1]
    M[:, 7, 0] = Lz * E * q
    M[:, 7, 1] = Lz * q
    M[:, 7, 6] = E
    M[:, 7, 7] = 1.0
    rhs[:, 7] = t[2]
    return xp.linalg.solve(M, rhs[..., None])[..., 0].T


def slit_correction(kx, ky, K, b, t, z, Lz, eta, xp=np):
    """Homogeneous Stokes velocity in 0 < z < Lz equal to ``b`` at z = 0 and ``t`` at z = Lz; (3, Nz, m).

    ``u = -i a1 kx q z e^{-Kz}/K + i a2 kx q z e^{K(z-Lz)}/K + a3 e^{-Kz} + a4 e^{K(z-Lz)}`` (v alike with ky,
    a5, a6), ``w = a1 q z e^{-Kz} + a2 q z e^{K(z-Lz)} + a7 e^{-Kz} + a8 e^{K(z-Lz)}``, ``q = 1/(2 eta)``.
    """
    a = slit_coefficients(kx, ky, K, b, t, Lz, eta, xp)
    q = 1.0 / (2.0 * eta)
    zz = xp.asarray(z)[:, None]
    down = xp.exp(-K[None, :] * zz)
    up = xp.exp(K[None, :] * (zz - Lz))
    u = -1j * a[0] * kx * q * zz * down / K + 1j * a[1] * kx * q * zz * up / K + a[2] * down + a[3] * up
    v = -1j * a[0] * ky * q * zz * down / K + 1j * a[1] * ky * q * zz * up / K + a[4] * down + a[5] * up
    w = a[0] * q * zz * down + a[1] * q * zz * up + a[6] * down + a[7] * up
    return xp.stack([u, v, w])
