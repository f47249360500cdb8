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
``kT div N + O(delta^2)`` for ``W ~ N(0, I)``.  :func:`rfd` is that
difference for any product ``apply_at(configuration)`` and any way of
moving a configuration (``displace``): blob positions
(:func:`displace_positions`), or rigid bodies (the schemes pass their own
displacement, which turns quaternions).

Nothing here knows about bodies or imports anything of the package: every
function works on a matvec, a vector or a caller's callable.
"""
import math
from collections import namedtuple

import numpy as np
from scipy.linalg import eigh_tridiagonal
from scipy.linalg.lapack import dstev


LANCZOS_MAX_ITERATIONS = 1000
REORTHOGONALISE_AGAIN = 1.0 / np.sqrt(2.0)

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
    beta0 = math.sqrt(z.ravel(order='K').dot(z.ravel(order='K')))  # np.linalg.norm(z), bit for bit
    if beta0 == 0.0:
        return LanczosResult(np.zeros(n), 0, True, 0.0)
    size = min(max_iterations, n) + 1
    basis = np.empty((size, n))
    basis[0] = z / beta0
    alphas, betas = [], []
    previous, change = None, np.inf
    converged = False
    coefficients = np.ones(1)
    tiny = np.finfo(float).eps / beta0
    # The approximation is y_i = beta0 V_i c_i with V_i the orthonormal Krylov basis (rows of ``basis``) and
    # c_i = f(T_i) e_1, f = sqrt; so |y_i - y_{i-1}| = beta0 |c_i - (c_{i-1}, 0)| and |y_{i-1}| = beta0 |c_{i-1}|
    # (V_i^T V_i = I to rounding, by the full re-orthogonalisation), and y is formed once, at the end.
    # The vectors are 1-d and contiguous: their norms are ``sqrt(w . w)``, as np.linalg.norm computes them, without
    # its call; the loop makes as few NumPy calls as it can (it runs tens of times per step of a small system).
    for i in range(min(max_iterations, n)):
        w = np.array(matvec(basis[i]), dtype=float).reshape(-1)
        current = basis[i]
        if i > 0:
            w -= betas[i - 1] * basis[i - 1]
        alpha = float(w.dot(current))
        w -= alpha * current
        # Full re-orthogonalisation against every stored vector; a second pass only when the first removed
        # more than 1 - 1/sqrt(2) of the norm (the DGKS criterion: Daniel, Gragg, Kaufman and Stewart 1976;
        # twice is enough, Giraud et al. 2005).
        stored = basis[:i + 1]
        before = math.sqrt(w.dot(w))
        w -= stored.T @ (stored @ w)
        beta = math.sqrt(w.dot(w))
        if beta < REORTHOGONALISE_AGAIN * before:
            w -= stored.T @ (stored @ w)
            beta = math.sqrt(w.dot(w))
        alphas.append(alpha)
        if i == 0:
            eigenvalues, Q = np.array([alpha]), np.ones((1, 1))
        else:
            eigenvalues, Q = tridiagonal_eigenpairs(alphas, betas)
        coefficients = Q @ (np.sqrt(np.maximum(eigenvalues, 0.0)) * Q[0, :])
        exhausted = beta <= 1e-14 * max(abs(alpha), 1e-300) or i + 1 == n
        if previous is not None:
            step = coefficients.copy()
            step[:-1] -= previous
            change = float(math.sqrt(step.dot(step)) / max(math.sqrt(previous.dot(previous)), tiny))
            if print_residual:
                print('lanczos = %d %s' % (i + 1, change))
            if change < tolerance:
                converged = True
        if converged or exhausted:
            converged = True
            iterations = i + 1
            break
        np.divide(w, beta, out=basis[i + 1])
        betas.append(beta)
        previous = coefficients
    else:
        iterations = min(max_iterations, n)
    y = beta0 * (basis[:coefficients.size].T @ coefficients)
    if L_mult is not None:
        y = np.asarray(L_mult(y), dtype=float).reshape(-1)
    return LanczosResult(factor * y, iterations, converged, change if np.isfinite(change) else 0.0)


def tridiagonal_eigenpairs(diagonal, off_diagonal):
    """Eigenvalues (k,) ascending and eigenvectors (k, k) (columns) of a symmetric tridiagonal matrix.

    LAPACK ``dstev`` (a tenth of ``scipy.linalg.eigh_tridiagonal``'s call overhead at the sizes of a
    Lanczos iteration), ``eigh_tridiagonal`` if it fails.
    """
    d, e = np.array(diagonal, dtype=float), np.array(off_diagonal, dtype=float)
    eigenvalues, vectors, info = dstev(d, e)
    if info != 0:
        return eigh_tridiagonal(d, e)
    return eigenvalues, vectors


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


def displace_positions(positions, scale, W):
    """``positions + scale * W``: positions (N, 3), W (3N,) or (N, 3); the ``displace`` of rollers' RFD."""
    positions = np.asarray(positions, dtype=float)
    return positions + scale * np.asarray(W, dtype=float).reshape(positions.shape)


def _difference(plus, minus, delta):
    if isinstance(plus, tuple):
        return tuple(_difference(p, m, delta) for p, m in zip(plus, minus))
    return (plus - minus) / delta


def _divided(value, delta):
    if isinstance(value, tuple):
        return tuple(_divided(v, delta) for v in value)
    return value / delta


def rfd(apply_at, configuration, W, delta, displace, centred=True, at_configuration=None, difference=None):
    """Random finite difference of a product along a random direction ``W``.

    Parameters
    ----------
    apply_at : callable ``configuration -> ndarray`` (or a tuple of arrays)
        The product to differentiate, e.g. ``M(q) W`` or ``N(q) W``.
    configuration : whatever ``displace`` takes (blob positions (N, 3), a body Configuration, ...)
    W : ndarray, the random direction (drawn by the caller)
    delta : float, the size of the difference (in the units ``displace`` gives it)
    displace : callable ``(configuration, scale, W) -> configuration``, moves by ``scale * W``
    centred : True (default): ``[f(q + delta/2 W) - f(q - delta/2 W)] / delta``;
        False: one-sided ``[f(q + delta W) - f(q)] / delta``, with ``f(q)`` taken from
        ``at_configuration`` when the caller has it already.
    difference : callable ``(q_plus, q_minus) -> f(q_plus) - f(q_minus)`` or None
        For a product whose difference is better computed directly than as a
        difference of two values (two solves of which the second is for the
        difference itself, so the solver tolerance applies to the drift).

    Returns ``(f(q+) - f(q-)) / delta`` (arrays, or a tuple of arrays like ``apply_at``'s).
    """
    if centred:
        plus, minus = displace(configuration, 0.5 * delta, W), displace(configuration, -0.5 * delta, W)
    else:
        plus, minus = displace(configuration, delta, W), configuration
    if difference is not None:
        return _divided(difference(plus, minus), delta)
    value_minus = at_configuration if (not centred and at_configuration is not None) else apply_at(minus)
    return _difference(apply_at(plus), value_minus, delta)
