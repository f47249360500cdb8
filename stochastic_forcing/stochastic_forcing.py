"""Square roots of mobilities applied to Gaussian vectors, and random finite differences (floor 2).

Brownian increments need ``M^{1/2} z`` with ``z ~ N(0, I)``, so that the
noise has covariance ``M`` (fluctuation-dissipation).  Three ways:

* ``lanczos_square_root``: matrix-free Krylov approximation of
  ``M^{1/2} z`` for any symmetric positive (semi-)definite ``matvec``
  (Ando, Chow, Saad and Skolnick, J. Chem. Phys. 137, 064106, 2012; the form
  of Balboa Usabiaga et al. 2017 and Sprinkle et al. 2017).  With a
  preconditioner ``M ~ L L^T`` the iteration runs on ``L^{-1} M L^{-T}``
  and the result is multiplied by ``L``: covariance
  ``L (L^{-1} M L^{-T}) L^T = M``.  (The 2017 published code multiplied by
  ``L^T`` instead, which does not give covariance ``M``.)
* ``cholesky_root``: ``L z`` with ``M = L L^T`` (not symmetric, same covariance).
* ``symmetric_root``: ``V sqrt(max(lambda, 0)) V^T z`` from the symmetric
  eigen-decomposition (the principal root; negative round-off eigenvalues clipped).

The caller always passes ``z``: the order of random draws is the caller's.

Random finite differences (Delong et al. 2015; Sprinkle et al. 2017):
``kT/delta [N(q + delta/2 W) - N(q - delta/2 W)] W`` has mean
``kT div N + O(delta^2)`` for ``W ~ N(0, I)``; ``rfd_configuration`` moves
bodies by such a displacement, translations scaled by the body length so that
``delta`` is dimensionless.

Nothing here knows about bodies beyond locations and quaternions.
"""
from collections import namedtuple

import numpy as np
from scipy.linalg import eigh_tridiagonal

from quaternion_integrator.quaternion import rotate_quaternions

LANCZOS_MAX_ITERATIONS = 1000

LanczosResult = namedtuple('LanczosResult', ['noise', 'iterations', 'converged', 'relative_change'])
LanczosResult.__doc__ = """Result of ``lanczos_square_root``.

noise : ndarray (n,), ``factor * M^{1/2} z`` (with ``L`` applied when given).
iterations : int, Krylov vectors used (products with ``matvec``).
converged : bool, the relative change fell below the tolerance (or the Krylov space was exhausted).
relative_change : float, last ``|y_i - y_{i-1}| / |y_{i-1}|``.
"""


def lanczos_square_root(matvec, z, tolerance, max_iterations=LANCZOS_MAX_ITERATIONS, factor=1.0,
                        L_mult=None, print_residual=False):
    """``factor * L_mult(A^{1/2} z)`` by the Lanczos method with full re-orthogonalisation.

    Parameters
    ----------
    matvec : callable, (n,) -> (n,); the symmetric positive semi-definite ``A``
        (``M``, or ``L^{-1} M L^{-T}`` with a preconditioner).
    z : ndarray (n,), the Gaussian vector (drawn by the caller).
    tolerance : float
        Stop when the relative change of the approximation between two
        iterations is below it (SPEC §6; ``solver_tolerance`` of the input).
    max_iterations : int
    factor : float, e.g. ``sqrt(2 kT / dt)``; 0 gives zeros without any product.
    L_mult : callable (n,) -> (n,) or None, the factor ``L`` of the preconditioner.
    print_residual : bool, print ``lanczos = <iteration> <relative change>`` lines.

    Returns
    -------
    LanczosResult
    """
    z = np.asarray(z, dtype=float).reshape(-1)
    n = z.size
    if factor == 0.0 or n == 0:
        return LanczosResult(np.zeros(n), 0, True, 0.0)
    beta0 = float(np.linalg.norm(z))
    if beta0 == 0.0:
        return LanczosResult(np.zeros(n), 0, True, 0.0)
    size = min(max_iterations, n) + 1
    basis = np.empty((size, n))
    basis[0] = z / beta0
    alphas, betas = [], []
    previous, change = None, np.inf
    converged = False
    y = np.zeros(n)
    for i in range(min(max_iterations, n)):
        w = np.asarray(matvec(basis[i]), dtype=float).reshape(-1)
        if i > 0:
            w = w - betas[i - 1] * basis[i - 1]
        alpha = float(np.dot(w, basis[i]))
        w = w - alpha * basis[i]
        # Full re-orthogonalisation against every stored vector (twice is enough, Giraud et al. 2005).
        for _ in range(2):
            w = w - basis[:i + 1].T @ (basis[:i + 1] @ w)
        alphas.append(alpha)
        beta = float(np.linalg.norm(w))
        if i == 0:
            eigenvalues, Q = np.array([alpha]), np.ones((1, 1))
        else:
            eigenvalues, Q = eigh_tridiagonal(np.array(alphas), np.array(betas))
        coefficients = Q @ (np.sqrt(np.maximum(eigenvalues, 0.0)) * Q[0, :])
        y = beta0 * (basis[:i + 1].T @ coefficients)
        exhausted = beta <= 1e-14 * max(abs(alpha), 1e-300) or i + 1 == n
        if previous is not None:
            change = float(np.linalg.norm(y - previous) / max(np.linalg.norm(previous), np.finfo(float).eps))
            if print_residual:
                print('lanczos = %d %s' % (i + 1, change))
            if change < tolerance:
                converged = True
        if converged or exhausted:
            converged = True
            iterations = i + 1
            break
        basis[i + 1] = w / beta
        betas.append(beta)
        previous = y
    else:
        iterations = min(max_iterations, n)
    if L_mult is not None:
        y = np.asarray(L_mult(y), dtype=float).reshape(-1)
    return LanczosResult(factor * y, iterations, converged, change if np.isfinite(change) else 0.0)


def cholesky_root(matrix, z):
    """``L z`` with ``matrix = L L^T`` (lower Cholesky); matrix (n, n), z (n,) or (n, k)."""
    return np.linalg.cholesky(np.asarray(matrix, dtype=float)) @ np.asarray(z, dtype=float)


def symmetric_root_matrix(matrix):
    """Principal square root ``V sqrt(max(lambda, 0)) V^T`` of a symmetric matrix (n, n)."""
    matrix = np.asarray(matrix, dtype=float)
    eigenvalues, vectors = np.linalg.eigh(0.5 * (matrix + matrix.T))
    return (vectors * np.sqrt(np.maximum(eigenvalues, 0.0))) @ vectors.T


def symmetric_root(matrix, z):
    """``V sqrt(max(lambda, 0)) V^T z``; matrix (n, n) symmetric, z (n,) or (n, k)."""
    return symmetric_root_matrix(matrix) @ np.asarray(z, dtype=float)


def rfd_configuration(locations, orientations, displacement, delta, body_lengths=None):
    """Configuration moved by ``delta * displacement`` (random finite differences).

    Parameters
    ----------
    locations : (Nb, 3); orientations : (Nb, 4) scalar-first quaternions
    displacement : (Nb, 6), ``[W_t, W_r]`` per body
    delta : float
    body_lengths : (Nb,) or None
        Translations are ``delta * body_length * W_t`` when given (SPEC
        decision 6), else ``delta * W_t``; rotations ``from_rotation(delta W_r) q``.

    Returns new (locations (Nb, 3), orientations (Nb, 4)).
    """
    displacement = np.asarray(displacement, dtype=float).reshape(-1, 6)
    translation = displacement[:, :3] * delta
    if body_lengths is not None:
        translation = translation * np.asarray(body_lengths, dtype=float).reshape(-1, 1)
    return (np.asarray(locations, dtype=float) + translation,
            rotate_quaternions(orientations, delta * displacement[:, 3:]))
