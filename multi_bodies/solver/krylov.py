"""Restarted GMRES with SciPy's convergence rule and no product beyond the Krylov ones (floor 3).

The published code solves every mobility problem with ``scipy.sparse.linalg.gmres``:
left preconditioning, and a solve has converged when its true residual is at most
``rtol |b|`` (``solver_tolerance``).  :func:`gmres` keeps that rule and SciPy's inner
tolerance control (gh-8400; Saad and Schultz, SIAM J. Sci. Stat. Comput. 7, 856,
1986): the Arnoldi iteration is tested when its left-preconditioned residual estimate
falls below ``ptol``, which starts at ``|P b| rtol`` and is tightened by SciPy's factors
when the true residual has not followed.

What differs is how the true residual is had and what happens when it fails:

* the residual is ``r - (A V) y``, from the products ``A v_j`` the Arnoldi iteration
  made (kept beside the basis), not from one more product ``A x``: equal to
  ``b - A x`` to rounding, because ``A`` is linear;
* when the estimate has passed and that residual has not (the preconditioned and the
  true residual converge at different rates: at 100 boomerangs this happens in most
  solves), SciPy ends the cycle, takes ``b - A x`` by a product and restarts in a new
  Krylov space; here the iteration goes on in the same space with SciPy's tighter
  ``ptol``.  So a solve makes no product beyond its Krylov ones (and a warm start's
  ``b - A x0``), in at most SciPy's iterations; the answer meets the same tolerance and
  differs from SciPy's by less than it (the tests compare them);
* a cycle that reaches ``restart`` vectors, a breakdown, the iteration limit and any
  tolerance below ``ROUNDING_GUARD`` eps take the true residual by a product, as
  SciPy does after every cycle (an updated residual keeps shrinking below rounding
  where the true one stagnates, so it is not trusted there);
* the Arnoldi vectors are orthogonalised by classical Gram-Schmidt in two matrix-vector
  products, repeated when the first pass removed more than ``1 - 1/sqrt(2)`` of the
  norm (DGKS: Daniel, Gragg, Kaufman and Stewart, Math. Comp. 30, 772, 1976), instead
  of SciPy's modified Gram-Schmidt in a Python loop; the Givens rotations run on Python
  floats.

``minimal_residual=True`` (the package's solves under ``preconditioner`` ``auto`` and
``neighbours``) keeps the Krylov space and the convergence rule and changes which point
of the space is taken: the one of least *true* residual, found at every iteration, as
right-preconditioned GMRES would (its space of iterates, ``x0 + P K_j(A P, r0)``, is
the left-preconditioned one).  Left-preconditioned GMRES minimises ``|P (b - A x)|`` and
tests the true residual only once that estimate has passed ``ptol``; the true residual
often passes an iteration earlier.  The products ``A v_j`` are kept anyway, so their
span is orthonormalised as they come (DGKS again, ``A V = Q R``) and the least residual
``r0 - Q Q^T r0`` is updated with one more vector per iteration: no product more, a
few vector operations of length n per iteration.  The solve stops at the first
iteration whose least true residual is at most ``rtol |b|``, which is never later
than the left-preconditioned rule (the same space, the least residual in it) and is
the same rule: the answer meets the same tolerance, checked on ``r0 - (A V) y`` from
the products themselves as the left rule checks it (a least-squares answer spoilt by
rounding falls back to the left rule).  Tolerances below the rounding guard keep the
left rule's stopping point (the answer is still the least-residual one, checked by a
product).

Shapes: every vector is (n,).
"""
import math

import numpy as np

def vector_norm(x):
    """``np.linalg.norm`` of a real vector (n,), bit for bit (the same ``sqrt(x . x)`` of the raveled vector),
    without its argument handling: the Krylov loops call it several times an iteration."""
    x = x.ravel(order='K')
    return math.sqrt(x.dot(x))


REORTHOGONALISE_AGAIN = 1.0 / math.sqrt(2.0)
ROUNDING_GUARD = 1e3  # tolerances below ROUNDING_GUARD * eps (2.2e-13) are checked with a true residual product


def initial_residual(matvec, b, x):
    """``b - A x`` (n,) for a warm start: the only product of a solve outside the Krylov iteration."""
    return b - np.asarray(matvec(x), dtype=float).reshape(-1)


def least_squares_solution(R, g, k):
    """``y`` (k,) of the rotated least-squares problem ``R[:k, :k] y = g[:k]`` (R upper triangular), by back
    substitution as SciPy does it: a zero last pivot leaves its unknown at zero."""
    y = np.array(g[:k])
    if R[k - 1, k - 1] == 0.0:
        y[k - 1] = 0.0
    for i in range(k - 1, -1, -1):
        if y[i] != 0.0:
            y[i] /= R[i, i]
            y[:i] -= y[i] * R[:i, i]
    return y


def residual_after(r, y, products):
    """``(r - products^T y (n,), its norm)``: the cycle's residual for the coefficients ``y`` (k,) of its kept
    products ``A v_j`` (k, n), with no new product."""
    trial = r - y @ products
    return trial, float(vector_norm(trial))


def orthonormalise_against(basis, w):
    """``(coefficients (j,), |w|, |w'|, w')``: ``w`` (n,) less its projection on the orthonormal rows of
    ``basis`` (j, n) by classical Gram-Schmidt, repeated once when the first pass removed more than
    ``1 - 1/sqrt(2)`` of its norm (DGKS); ``w`` is changed in place and returned as ``w'``."""
    h0 = math.sqrt(w.dot(w))  # vector_norm of the 1-d w, without its call (the Krylov loops call this often)
    h = basis @ w
    w -= h @ basis
    h1 = math.sqrt(w.dot(w))
    if h1 < REORTHOGONALISE_AGAIN * h0:
        again = basis @ w
        w -= again @ basis
        h += again
        h1 = math.sqrt(w.dot(w))
    return h, h0, h1, w


class LeastTrueResidual:
    """The least true residual of a GMRES cycle over its Krylov space, updated as the products come.

    With the kept products ``A v_0 .. A v_j`` orthonormalised into ``Q`` (``A V = Q R``, R upper triangular),
    the least ``|r0 - A V y|`` is at ``R y = Q r0`` and its residual is ``r0 - Q^T Q r0``, updated by one
    vector per product.  ``usable`` turns False when a product depends on the earlier ones (``A`` singular on
    the space); the caller then keeps the left-preconditioned answer.
    """

    def __init__(self, r0, restart):
        self.residual = np.array(r0, dtype=float)
        self.Q = np.empty((restart, r0.size))
        self.R = np.zeros((restart, restart))
        self.coefficients = []
        self.usable = True

    def add(self, j, product):
        """Take ``A v_j`` (n,) in; returns the least true residual's norm over ``v_0 .. v_j``."""
        h, h0, h1, q = orthonormalise_against(self.Q[:j], np.array(product, dtype=float))
        self.R[:j, j] = h
        self.R[j, j] = h1
        if h1 <= np.finfo(float).eps * h0:  # also a zero product (h0 = h1 = 0)
            self.usable = False
            return float('inf')
        direction = np.divide(q, h1, out=self.Q[j])
        c = float(direction @ self.residual)
        self.coefficients.append(c)
        self.residual -= c * direction
        return math.sqrt(self.residual.dot(self.residual))

    def solution(self, k):
        """``y`` (k,) of the least true residual over ``v_0 .. v_{k-1}``."""
        return least_squares_solution(self.R, self.coefficients, k)


def gmres(matvec, b, rtol, psolve=None, x0=None, restart=60, maxiter=1000, callback=None, minimal_residual=False):
    """Solve ``A x = b`` by left-preconditioned restarted GMRES.

    Parameters
    ----------
    matvec : callable (n,) -> (n,), ``A v``.
    b : ndarray (n,).
    rtol : float, converged when ``|b - A x| <= rtol |b|``.
    psolve : callable (n,) -> (n,) or None, the preconditioner ``P ~ A^{-1}`` (None: identity).
    x0 : ndarray (n,) or None (zeros).
    restart : int, Krylov vectors per cycle.
    maxiter : int, most inner iterations in all (SciPy's legacy count).
    callback : callable(float) or None, called after every inner iteration with the preconditioned
        residual estimate divided by ``|b|`` (SciPy's ``callback_type='legacy'``).
    minimal_residual : bool, take the point of least true residual of the Krylov space and stop as soon as
        it passes (module docstring); False: SciPy's iterate and stopping point.

    Returns
    -------
    (x (n,), info (0 converged, else ``maxiter``), inner iterations, residual ``b - A x`` (n,))
    """
    b = np.asarray(b, dtype=float).reshape(-1)
    n = b.size
    bnorm = float(vector_norm(b))
    if bnorm == 0.0:
        return np.zeros(n), 0, 0, b.copy()
    if psolve is None:
        def psolve(v):
            return np.array(v, dtype=float)  # a copy: the caller's vector is changed in place below
    atol = rtol * bnorm
    eps = np.finfo(float).eps
    if x0 is not None and np.any(x0):
        x = np.array(x0, dtype=float).reshape(-1)
        r = initial_residual(matvec, b, x)
    else:
        x = np.zeros(n)
        r = b.copy()
    rnorm = float(vector_norm(r))
    if rnorm < atol:
        return x, 0, 0, r
    ptol_max_factor = 1.0
    ptol = float(vector_norm(psolve(b))) * min(ptol_max_factor, atol / bnorm)
    trust_update = atol >= ROUNDING_GUARD * eps * bnorm  # the updated residual r - (A V) y is good to rounding
    restart = max(1, min(restart, n))
    V = np.empty((restart + 1, n))
    AV = np.empty((restart, n))
    R = np.zeros((restart, restart))  # the rotated Hessenberg matrix, upper triangular
    inner = 0
    presid = 0.0
    breakdown = False
    while True:
        z = np.asarray(psolve(r), dtype=float).reshape(-1)
        beta = float(vector_norm(z))
        V[0] = z / beta
        g = [beta]  # the rotated right-hand side of the small least-squares problem
        cosines, sines = [], []
        R[:] = 0.0
        breakdown = False
        accepted = None
        least = LeastTrueResidual(r, restart) if minimal_residual else None
        for j in range(restart):
            AV[j] = np.asarray(matvec(V[j]), dtype=float).reshape(-1)
            w = np.asarray(psolve(AV[j]), dtype=float).reshape(-1)
            if np.may_share_memory(w, AV[j]):  # (bounds only: a copy where unsure changes no number)
                w = w.copy()
            h, h0, h1, w = orthonormalise_against(V[:j + 1], w)
            if h1 <= eps * h0:
                breakdown = True
                h1 = 0.0
                V[j + 1] = 0.0
            else:
                np.divide(w, h1, out=V[j + 1])
            column = h.tolist() + [h1]
            for k in range(j):  # the earlier rotations
                c, s = cosines[k], sines[k]
                column[k], column[k + 1] = c * column[k] + s * column[k + 1], -s * column[k] + c * column[k + 1]
            f, gg = column[j], column[j + 1]
            magnitude = math.hypot(f, gg)
            c, s = (1.0, 0.0) if magnitude == 0.0 else (f / magnitude, gg / magnitude)
            cosines.append(c)
            sines.append(s)
            column[j] = magnitude
            R[:j + 1, j] = column[:j + 1]
            g.append(-s * g[j])
            g[j] = c * g[j]
            presid = abs(g[j + 1])
            inner += 1
            if callback is not None:
                callback(presid / bnorm)
            if least is not None and least.usable:
                if least.add(j, AV[j]) <= atol and trust_update:
                    # the residual from the products themselves, as the left rule takes it: a least-squares
                    # answer spoilt by rounding (a nearly singular A on the space) cannot pass unseen
                    y = least.solution(j + 1)
                    trial, trial_norm = residual_after(r, y, AV[:j + 1])
                    if trial_norm <= atol:
                        accepted = (y, trial, trial_norm)
                        break
                    least.usable = False  # the left rule's gate from here on
            if inner == maxiter or breakdown:
                break
            if least is not None and least.usable and trust_update:
                continue  # the least true residual was tested above; the estimate's gate is not needed
            if presid <= ptol:
                if not trust_update:
                    break
                # SciPy's cycle would end here and restart if the true residual failed; this one looks at the
                # residual r - (A V) y first (no product) and, if it fails, goes on with SciPy's tighter
                # inner tolerance in the same Krylov space instead of a new one.
                y = least_squares_solution(R, g, j + 1)
                trial, trial_norm = residual_after(r, y, AV[:j + 1])
                if trial_norm <= atol:
                    accepted = (y, trial, trial_norm)  # the cycle's answer: not computed again below
                    break
                ptol_max_factor = max(eps, 0.25 * ptol_max_factor)
                ptol = presid * min(ptol_max_factor, atol / trial_norm)
        k = j + 1
        if accepted is not None:
            y, r, rnorm = accepted
        else:
            y = least.solution(k) if least is not None and least.usable else least_squares_solution(R, g, k)
            r, rnorm = residual_after(r, y, AV[:k])
        x += y @ V[:k]
        if rnorm > atol or breakdown or inner == maxiter or not trust_update:
            # The true residual by a product, as SciPy takes it after every cycle: before a restart (which
            # starts from it), for the verdict after a breakdown or the last iteration, and whenever the
            # tolerance is so close to rounding that the updated residual, which keeps shrinking where the
            # true one stagnates, could pass it falsely.
            r = initial_residual(matvec, b, x)
            rnorm = float(vector_norm(r))
        if rnorm <= atol or breakdown or inner == maxiter:
            break
        if presid <= ptol:  # the inner estimate passed but the true residual did not: ask more of the next cycle
            ptol_max_factor = max(eps, 0.25 * ptol_max_factor)
        else:
            ptol_max_factor = min(1.0, 1.5 * ptol_max_factor)
        ptol = presid * min(ptol_max_factor, atol / rnorm)
    return x, (0 if rnorm <= atol else maxiter), inner, r
