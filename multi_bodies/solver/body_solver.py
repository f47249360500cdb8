"""Mobility and resistance problems of many rigid bodies (SPEC sections 4.2 to 4.4).

Unknowns of the mobility problem: blob constraint forces ``lambda`` (3N) and
body velocities ``U`` (6 Nb).  The saddle-point system is::

    [ M   -K ] [lambda]   [ slip ]
    [-K^T  0 ] [  U   ] = [ -F   ]

with ``M`` the blob mobility (any matrix-free product ``M f``), ``K`` the
rigid-body kinematics, ``F`` the force-torque of every body (Nb, 6) flattened.
Its solution is ``U = N (F - K^T M^{-1} slip)`` with the body mobility
``N = (K^T M^{-1} K)^+``.

Iterative path: GMRES (SciPy) on the saddle-point operator, preconditioned
by the exact inverse of the single-body systems (block-diagonal over bodies).
The per-body dense blocks are built once per configuration, factorised by
Cholesky and kept; bodies of one structure type are processed together with
numpy's stacked linear algebra, so applying the preconditioner has no Python
loop over bodies.

Dense path: the full blob matrix, ``N = pinv(K^T M^{-1} K)`` and the
resistance problem ``lambda = M^{-1} (slip + K U)``, ``[F; T] = K^T lambda``.

Everything here is a function of a :class:`body.body.Configuration` passed
in: a problem, a preconditioner or a dense matrix is built at the
configuration it is given and copies what it needs, so it stays valid when
the bodies move.  There is one iterative solve, :func:`solve` (and the GMRES
wrapper :func:`gmres_solve` under it) for every problem of the package (the
problem protocol, see :func:`solve`): it
builds nothing behind the caller's back (the preconditioner and the first
guess are arguments) and returns the true residual of its answer.  The body
mobility ``pinv(K^T M^{-1} K)`` of dense blocks is computed in one place,
:func:`body_mobility_from_resistance`, for the preconditioner and the dense
schemes alike.
"""
from collections import namedtuple

import numpy as np
import scipy.linalg.lapack as _lapack

from body.body import K_dot, K_matrices, KT_dot, as_configuration, blob_positions, saddle_point_product
from mobility.interface import as_blob_mobility
from multi_bodies.files.input_options import DEFAULTS

from utils import SimulationStopped

from . import krylov
from .linear_map import LinearMap, LinearProblem

try:  # the per-body block products in C++ (multi_bodies/solver/cpp/preconditioner_module.cpp); NumPy without it
    from . import _preconditioner_cpp
except ImportError:  # pragma: no cover - a build without a C++ compiler
    _preconditioner_cpp = None

GMRES_RESTART = 60
GMRES_MAXITER = 1000
PINV_RCOND = 1e-14  # singular values below this fraction of the largest are dropped (rank-deficient bodies)

SolveResult = namedtuple('SolveResult', ['lambda_blobs', 'velocities', 'iterations', 'converged', 'residual',
                                         'normalised_solution', 'constraint_force_torque'], defaults=(None,))
SolveResult.__doc__ = """Result of :func:`solve`.

lambda_blobs : ndarray (N, 3), blob constraint forces (force units).
velocities : ndarray (Nb, 6), ``[v, w]`` per body.
iterations : int, GMRES inner iterations.
converged : bool, GMRES reached ``tolerance``.
residual : float, ``|b - A x| / |b|`` of the returned solution (the true residual; :func:`gmres_solve`).
normalised_solution : ndarray (3N + 6Nb,), the solution of the normalised system ``A y = b / |b|``:
    the first guess for the next solve of a similar right-hand side (SPEC 4.2); None for a zero
    right-hand side (nothing was solved: keep the guess you had).
constraint_force_torque : the problem's constraint forces, or None: with bodies of prescribed kinematics
    (``multi_bodies.solver.obstacles``) the force-torque (Nb, 6) that holds each such body on its
    prescribed motion (zero rows for free bodies); with joints the joint forces (Nc, 3); for rollers of
    prescribed spin the torques (N, 3); None for the free rigid problem.
"""

SolutionParts = namedtuple('SolutionParts', ['lambda_blobs', 'velocities', 'constraint'])
SolutionParts.__doc__ = """A problem's solution split (``problem.solution(x)``): blob forces (N, 3), body velocities
(Nb, 6) and constraint forces (the problem's multipliers), each None where the problem has none."""

GmresResult = namedtuple('GmresResult', ['x', 'iterations', 'converged', 'residual'])
GmresResult.__doc__ = """Result of :func:`gmres_solve`: solution ``x``, inner iterations, converged, true relative residual."""


def check_finite(values, what):
    """Raise utils.SimulationStopped when ``values`` hold NaN or inf (``what`` names them in the message)."""
    if not np.all(np.isfinite(values)):
        raise SimulationStopped('the %s are not finite (NaN or inf); check the user-defined functions, the time '
                                'step and the configuration' % what)


def blob_radius_argument(body_arrays, blob_radius, blobs=slice(None)):
    """The radius argument of the mobility functions for ``blobs`` of ``body_arrays``.

    ``blob_radius`` (a number) unless a vertex file gave per-blob radii
    (``body_arrays.radii_given``); then the radii of those blobs, shape (n,).
    """
    if getattr(body_arrays, 'radii_given', False):
        return body_arrays.blob_radii[blobs]
    return blob_radius


def blob_mobility(body_arrays, mobility, eta=None, blob_radius=None, periodic_length=None, role='velocities',
                  **functions):
    """The ``mobility.interface.BlobMobility`` of a building block's mobility argument.

    ``mobility`` a BlobMobility (what the model passes: it carries its viscosity, radii and box): itself.  Or
    a function of the published form (``role`` ``velocities``: ``f(r, v, eta, a, periodic_length)``;
    ``dense_matrix``: ``f(r, eta, a)``) with ``eta`` and the number ``blob_radius``, wrapped with the per-blob
    radii of ``body_arrays`` where a vertex file gave them (``interface.FunctionMobility``); ``functions``:
    its other functions (``stacked_dense_matrix``, ``cross_blocks``, ``near_field_domain``).
    """
    if blob_radius is not None:
        blob_radius = blob_radius_argument(body_arrays, float(blob_radius))
    return as_blob_mobility(mobility, None if eta is None else float(eta), blob_radius, periodic_length, role,
                            **functions)


def one_radius(mobility, body_arrays, blob_radius=None):
    """The blob radius as one number: ``blob_radius`` when given, else the mobility's radius when it is one number,
    else the body arrays' (the option ``blob_radius``; per-blob radii are the mobility's)."""
    if blob_radius is not None:
        return float(blob_radius)
    return mobility.blob_radius if np.ndim(mobility.blob_radius) == 0 else float(body_arrays.blob_radius)


def radius_of_blobs(mobility, blobs, shape=None):
    """The radius (a number) or radii of ``blobs`` (an index of the blobs) of ``mobility``'s blobs, reshaped to
    ``shape`` when they are radii."""
    radius = mobility.blob_radius
    if np.ndim(radius) == 0:
        return radius
    radius = radius[blobs]
    return radius if shape is None else np.reshape(radius, shape)


def body_mobility_from_resistance(resistance):
    """Body mobility ``N = pinv(R)`` of resistance matrices ``R = K^T M^{-1} K``, symmetrised.

    resistance : ndarray (..., 6n, 6n), one matrix or a stack.  Singular
    values below ``PINV_RCOND`` times the largest are dropped, so a body
    whose blobs cannot resist every rigid motion (one blob, blobs on a line)
    gets zero velocity along the null space of its ``K`` (SPEC section 3).
    """
    N = np.linalg.pinv(resistance, rcond=PINV_RCOND)
    return 0.5 * (N + np.swapaxes(N, -1, -2))


def mobility_rhs(force_torque, slip):
    """Right-hand side ``[slip (3N); -F (6 Nb)]`` from force-torque (Nb, 6) or (2Nb, 3) and slip (N, 3)."""
    return np.concatenate((np.asarray(slip, dtype=float).reshape(-1),
                           -np.asarray(force_torque, dtype=float).reshape(-1)))


class MobilityProblem(LinearProblem):
    """The saddle-point problem of all bodies at one configuration (a value: it copies what it is built at).

    Parameters
    ----------
    body_arrays : body.body.BodyArrays
        Only its fixed structure is used (reference blobs, blob-body index, offsets).
    configuration : body.body.Configuration (or (locations (Nb, 3), orientations (Nb, 4)))
    mobility : mobility.interface.BlobMobility (the model's: its viscosity, radii and box), or a function of
        the published form ``f(r_vectors, force (3N,), eta, a, periodic_length) -> (3N,)`` with
    eta, blob_radius : float; periodic_length : (3,) floats (given with a function only)

    Attributes: ``configuration``, ``locations``, ``orientations``, ``r_vectors`` (N, 3), ``mobility``,
    ``eta``, ``blob_radius`` (the number: the mobility's, or the body arrays' where it has per-blob radii),
    ``blob_radii`` (the mobility's radius or radii), ``periodic_length``, ``operator`` (SciPy LinearOperator
    of size 3N + 6Nb), ``size``.
    """

    def __init__(self, body_arrays, configuration, mobility, eta=None, blob_radius=None, periodic_length=None):
        self.body_arrays = body_arrays
        self.configuration = as_configuration(configuration)
        self.locations, self.orientations = self.configuration.locations, self.configuration.orientations
        self.r_vectors = blob_positions(self.locations, self.orientations, body_arrays.reference_blobs,
                                        body_arrays.blob_body_index)
        self.mobility = blob_mobility(body_arrays, mobility, eta, blob_radius, periodic_length)
        self.eta = self.mobility.eta
        # one number, or the per-blob radii (N,) when a vertex file gave them
        self.blob_radii = self.mobility.blob_radius
        self.blob_radius = one_radius(self.mobility, body_arrays, blob_radius)
        self.periodic_length = self.mobility.periodic_length
        self.num_blobs = self.r_vectors.shape[0]
        self.num_bodies = self.locations.shape[0]
        self.size = 3 * self.num_blobs + 6 * self.num_bodies
        self._projectors = None

    def with_mobility(self, mobility):
        """The same problem (same configuration, a shallow copy) with another ``BlobMobility`` (the paired
        products of ``model.PairedProducts``)."""
        import copy
        twin = copy.copy(self)
        twin.mobility = mobility
        return twin

    def project_forces(self, force_torque):
        """Remove from force-torque (Nb, 6) the part that no blob force can balance.

        A body whose blobs cannot resist every rigid motion (a single blob: any
        rotation about its location; blobs on a line: rotation about that line)
        has a rank-deficient ``K``; its velocity along the null space of ``K``
        is undetermined and the body mobility ``pinv(K^T M^{-1} K)`` gives it
        zero.  A torque along that null space (a torque on a single blob, or
        the random torques of random finite differences) would make the
        saddle-point system inconsistent, so it is projected out, which gives
        the iterative solve the ``pinv`` answer.  Full-rank bodies are
        returned unchanged.
        """
        force_torque = np.asarray(force_torque, dtype=float).reshape(-1, 6)
        projectors = self._range_projectors()
        if not projectors:
            return force_torque
        out = force_torque.copy()
        for bodies, P in projectors:
            out[bodies] = np.matmul(P, force_torque[bodies][:, :, None])[:, :, 0]
        return out

    def _range_projectors(self):
        if self._projectors is None:
            self._projectors = []
            full_rank = full_rank_types(self.body_arrays)
            for k, ((bodies, blobs), n_blobs) in enumerate(zip(self.body_arrays.type_slices,
                                                                self.body_arrays.type_blobs)):
                nb = bodies.stop - bodies.start
                if nb == 0 or full_rank[k]:
                    continue
                K = K_matrices(self.r_vectors[blobs].reshape(nb, n_blobs, 3), self.locations[bodies])
                _, singular, Vt = np.linalg.svd(K, full_matrices=True)
                scale = np.maximum(singular[:, :1], 1e-300)
                rank = np.sum(singular > 1e-10 * scale, axis=1)
                if np.all(rank == 6):
                    continue
                keep = (np.arange(6)[None, :] < rank[:, None]).astype(float)
                V = np.swapaxes(Vt, 1, 2)
                self._projectors.append((bodies, np.matmul(V * keep[:, None, :], Vt)))
        return self._projectors

    def prepare_rhs(self, rhs):
        """The right-hand side (3N + 6Nb,) with its force part projected (:meth:`project_forces`)."""
        n3 = 3 * self.num_blobs
        if self.num_bodies:
            rhs[n3:] = self.project_forces(rhs[n3:]).reshape(-1)
        return rhs

    def solution(self, x):
        """``[lambda; U]`` (3N + 6Nb,) split: SolutionParts(lambda (N, 3), U (Nb, 6), None)."""
        n3 = 3 * self.num_blobs
        return SolutionParts(x[:n3].reshape(-1, 3), x[n3:].reshape(-1, 6), None)

    def without_prescribed_motion(self, velocities):
        """Body velocities (Nb, 6) of a solve with the prescribed motion taken out (no body is prescribed here)."""
        return velocities

    def M_dot(self, blob_forces):
        """``M lambda``: blob velocities (3N,) of blob forces (3N,) or (N, 3)."""
        return np.asarray(self.mobility.velocities(self.r_vectors,
                                                   np.asarray(blob_forces, dtype=float).reshape(-1))).reshape(-1)

    def K_dot(self, body_velocities):
        """``K U``: blob velocities (N, 3) of body velocities (Nb, 6) or (6Nb,)."""
        return K_dot(self.r_vectors, self.locations, self.body_arrays.blob_body_index, body_velocities)

    def KT_dot(self, blob_forces):
        """``K^T lambda``: force-torque (Nb, 6) of blob forces (N, 3) or (3N,)."""
        return KT_dot(self.r_vectors, self.locations, self.body_arrays.blob_offsets,
                      self.body_arrays.blob_body_index, blob_forces)

    def matvec(self, x):
        """``A [lambda; U] = [M lambda - K U; -K^T lambda]``."""
        x = np.asarray(x, dtype=float).reshape(-1)
        n3 = 3 * self.num_blobs
        lambda_blobs, velocities = x[:n3], x[n3:]
        return saddle_point_product(self.r_vectors, self.locations, self.body_arrays.blob_offsets,
                                    self.body_arrays.blob_body_index, self.M_dot(lambda_blobs), lambda_blobs,
                                    velocities)

    def rhs(self, slip=None, force_torque=None, noise_slip=None, noise_force=None):
        """``[slip - noise_slip; -(F + noise_force)]`` (3N + 6Nb,); each argument None for zero.

        slip (N, 3) or (3N,), force_torque (Nb, 6), noise_slip (3N,), noise_force (Nb, 6).
        """
        n3 = 3 * self.num_blobs
        rhs = np.zeros(self.size)
        if slip is not None:
            rhs[:n3] += np.asarray(slip, dtype=float).reshape(-1)
        if noise_slip is not None:
            rhs[:n3] -= np.asarray(noise_slip, dtype=float).reshape(-1)
        if force_torque is not None:
            rhs[n3:] -= np.asarray(force_torque, dtype=float).reshape(-1)
        if noise_force is not None:
            rhs[n3:] -= np.asarray(noise_force, dtype=float).reshape(-1)
        return rhs


def full_rank_types(body_arrays):
    """Per structure type: True when every body's ``K`` (3n, 6) has rank 6 (list of bool, cached).

    The rank of ``K`` does not change when a body moves rigidly, so it is found once, from the reference
    blobs at the identity orientation (singular values above 1e-10 times the largest, as
    ``MobilityProblem.project_forces``), and kept on ``body_arrays``.
    """
    cached = getattr(body_arrays, '_full_rank_types', None)
    if cached is not None:
        return cached
    result = []
    for (bodies, blobs), n_blobs in zip(body_arrays.type_slices, body_arrays.type_blobs):
        nb = bodies.stop - bodies.start
        if nb == 0:
            result.append(True)
            continue
        reference = np.asarray(body_arrays.reference_blobs[blobs], dtype=float).reshape(nb, n_blobs, 3)
        singular = np.linalg.svd(K_matrices(reference, np.zeros((nb, 3))), compute_uv=False)
        result.append(singular.shape[1] == 6  # a body of one blob has 3 singular values: never rank 6
                      and bool(np.all(singular[:, -1] > 1e-6 * np.maximum(singular[:, 0], 1e-300))))
    try:
        body_arrays._full_rank_types = result
    except AttributeError:  # an object that takes no new attributes: compute again next time
        pass
    return result


def lower_triangular_inverse(L):
    """``L^{-1}`` (nb, m, m) of lower Cholesky factors (nb, m, m): lower triangular, zeros above the diagonal.

    The compiled forward substitution when built (a third of the work of a general solve), else
    ``np.linalg.solve`` against the identity (``tril`` clears the rounding it leaves above the diagonal).
    """
    if _preconditioner_cpp is not None:
        return _preconditioner_cpp.lower_triangular_inverse(L)
    return np.tril(np.linalg.solve(L, np.broadcast_to(np.eye(L.shape[-1]), L.shape)))


class BlockDiagonalPreconditioner(LinearMap):
    """Exact inverse of the saddle-point system of each body alone, at one configuration.

    For body k with dense blob mobility ``M_k`` (wall included, no periodic
    images) and ``K_k``: ``N_k = pinv(K_k^T M_k^{-1} K_k)``; applied to
    ``[s; f]`` it returns ``U_k = -N_k (f_k + K_k^T M_k^{-1} s_k)`` and
    ``lambda_k = M_k^{-1} (s_k + K_k U_k)``.

    Parameters
    ----------
    body_arrays : body.body.BodyArrays (fixed structure only)
    configuration : body.body.Configuration
    mobility : mobility.interface.BlobMobility (the model's blobs mobility: ``dense_matrix`` of a stack of
        bodies gives their blocks at once), or a function of the published form ``f(r (n, 3), eta, a) ->
        (3n, 3n)`` with
    eta, blob_radius : float, and
    stacked_mobility : callable ``f(r (nb, n, 3), eta, a) -> (nb, 3n, 3n)`` or None (given with a function
        only: the dense blocks of many bodies at once; None: the function once per body).
    memo, memo_bodies : dict and (Nb,) bool, or None
        The blocks of the bodies of ``memo_bodies`` are looked up in ``memo['blocks']`` (keyed by their exact
        blob positions, location and radii) and the ones of this build stored there in place of the last
        build's: bodies that have not moved keep their numbers without computing them again.

    Attributes (one entry per structure type; ``nb`` bodies of ``n`` blobs)
    -----------------------------------------------------------------------
    cholesky_factors : list of ndarray (nb, 3n, 3n) or None
        Lower Cholesky factors ``M_k = L_k L_k^T`` (None where Cholesky
        failed and a plain inverse was used).
    inverse_mobilities : list of ndarray (nb, 3n, 3n)
    body_mobilities : list of ndarray (nb, 6, 6)
    configuration : the configuration it was built at.
    """

    def __init__(self, body_arrays, configuration, mobility, eta=None, blob_radius=None, stacked_mobility=None,
                 memo=None, memo_bodies=None):
        self.body_arrays = body_arrays
        self.configuration = as_configuration(configuration)
        self.memo = memo
        mobility = blob_mobility(body_arrays, mobility, eta, blob_radius, role='dense_matrix',
                                 stacked_dense_matrix=stacked_mobility)
        locations = self.configuration.locations
        r_vectors = body_arrays.blob_positions(self.configuration)
        self.inverse_cholesky_factors = []
        self.cholesky_factors = []
        self.inverse_mobilities = []
        self.inverse_mobility_times_K = []
        self.K = []
        self.body_mobilities = []
        kept = {}
        for (bodies, blobs), n_blobs in zip(body_arrays.type_slices, body_arrays.type_blobs):
            nb = bodies.stop - bodies.start
            r_type = r_vectors[blobs].reshape(nb, n_blobs, 3)
            radius = radius_of_blobs(mobility, blobs, (nb, n_blobs))
            # bodies of the memo whose blobs are where they were at the last build keep their blocks (the same
            # numbers: every block depends on its own body alone); the others are computed in one stack
            keys, found = [None] * nb, {}
            blocks_memo = memo.setdefault('blocks', {}) if memo is not None and memo_bodies is not None else None
            if blocks_memo is not None:
                for k in np.flatnonzero(memo_bodies[bodies]):
                    keys[k] = (r_type[k].tobytes(), locations[bodies.start + k].tobytes(),
                               np.asarray(radius if np.ndim(radius) == 0 else radius[k]).tobytes())
                    if keys[k] in blocks_memo:
                        found[k] = blocks_memo[keys[k]]
            todo = np.array([k for k in range(nb) if k not in found], dtype=int)
            parts = _saddle_blocks(r_type[todo], locations[bodies][todo],
                                   mobility.replace(blob_radius=radius if np.ndim(radius) == 0 else radius[todo])) \
                if todo.size or not found else None
            if found:
                parts = _merged_blocks(nb, todo, parts, found)
            L, L_inv, M_inv, K, M_inv_K, N = parts
            for k, key in enumerate(keys):
                if key is not None:
                    kept[key] = tuple(None if a is None else a[k].copy() for a in parts)
            self.inverse_cholesky_factors.append(L_inv)
            self.cholesky_factors.append(L)
            self.inverse_mobilities.append(M_inv)
            self.inverse_mobility_times_K.append(M_inv_K)
            self.K.append(K)
            self.body_mobilities.append(N)
        if memo is not None and memo_bodies is not None:  # memo['blocks'] holds the last build's bodies only
            memo['blocks'] = kept
        n_blob_unknowns = 3 * body_arrays.num_blobs
        self.size = n_blob_unknowns + 6 * body_arrays.num_bodies

    @property
    def locations(self):
        return self.configuration.locations

    def _blockwise(self, vector, factors, transpose=False, lower=False):
        """Apply per-body dense blocks ``factors`` (list per type, (nb, 3n, 3n) or None = identity) to (3N,).

        ``transpose``: the blocks' transposes; ``lower``: the blocks are lower triangular (the compiled
        product then reads only their lower halves).
        """
        vector = np.ascontiguousarray(vector, dtype=float).reshape(-1)
        out = vector.copy()
        for (bodies, blobs), F in zip(self.body_arrays.type_slices, factors):
            if F is None:
                continue
            if _preconditioner_cpp is not None:
                _preconditioner_cpp.block_product(F, vector, out, 3 * blobs.start, transpose, lower)
                continue
            nb = bodies.stop - bodies.start
            block = np.swapaxes(F, 1, 2) if transpose else F
            out[3 * blobs.start:3 * blobs.stop] = np.matmul(block, vector[3 * blobs.start:3 * blobs.stop].reshape(
                nb, -1, 1)).reshape(-1)
        return out

    def L_dot(self, vector):
        """``L v`` with the block lower Cholesky factors ``M_k = L_k L_k^T``; vector (3N,)."""
        return self._blockwise(vector, self.cholesky_factors, lower=True)

    def L_inv_dot(self, vector):
        """``L^{-1} v``; vector (3N,)."""
        return self._blockwise(vector, self.inverse_cholesky_factors, lower=True)

    def L_inv_T_dot(self, vector):
        """``L^{-T} v``; vector (3N,)."""
        return self._blockwise(vector, self.inverse_cholesky_factors, transpose=True, lower=True)

    def blob_blocks(self):
        """The blob-blob blocks of the inverse, per structure type (nb, 3n, 3n).

        ``Q_k = M_k^{-1} - M_k^{-1} K_k N_k K_k^T M_k^{-1}``: the blob forces of body ``k`` alone, free of
        net force and torque, that a blob velocity field ``s_k`` gives (``apply`` of ``[s; 0]``).
        """
        return [M_inv - np.matmul(np.matmul(M_inv_K, N), np.swapaxes(M_inv_K, 1, 2))
                for M_inv, M_inv_K, N in zip(self.inverse_mobilities, self.inverse_mobility_times_K,
                                             self.body_mobilities)]

    def blob_body_blocks(self):
        """The body-row blocks of the inverse's blob columns, per structure type (nb, 6, 3n).

        ``-N_k K_k^T M_k^{-1}``: the velocities of body ``k`` alone that a blob velocity field ``s_k`` gives
        (the body part of ``apply`` of ``[s; 0]``).
        """
        return [-np.matmul(N, np.swapaxes(M_inv_K, 1, 2))
                for M_inv_K, N in zip(self.inverse_mobility_times_K, self.body_mobilities)]

    def apply(self, x):
        """Apply the preconditioner to ``x = [s (3N); f (6 Nb)]``; returns the same layout."""
        x = np.ascontiguousarray(x, dtype=float).reshape(-1)
        n_blob_unknowns = 3 * self.body_arrays.num_blobs
        if _preconditioner_cpp is not None:
            out = np.empty_like(x)
            for (bodies, blobs), M_inv, M_inv_K, K, N in zip(
                    self.body_arrays.type_slices, self.inverse_mobilities, self.inverse_mobility_times_K,
                    self.K, self.body_mobilities):
                _preconditioner_cpp.saddle_block_inverse(M_inv, M_inv_K, K, N, x, out, 3 * blobs.start,
                                                         n_blob_unknowns + 6 * bodies.start)
            return out
        slip = x[:n_blob_unknowns].reshape(-1, 3)
        force = x[n_blob_unknowns:].reshape(-1, 6)
        lambda_out = np.empty_like(slip)
        velocity_out = np.empty_like(force)
        for (bodies, blobs), M_inv, M_inv_K, K, N in zip(
                self.body_arrays.type_slices, self.inverse_mobilities, self.inverse_mobility_times_K,
                self.K, self.body_mobilities):
            nb = bodies.stop - bodies.start
            s = slip[blobs].reshape(nb, -1, 1)
            lambda_tilde = np.matmul(M_inv, s)
            U = -np.matmul(N, force[bodies][:, :, None] + np.matmul(np.swapaxes(K, 1, 2), lambda_tilde))
            lambda_out[blobs] = (lambda_tilde + np.matmul(M_inv_K, U)).reshape(-1, 3)
            velocity_out[bodies] = U[:, :, 0]
        return np.concatenate((lambda_out.reshape(-1), velocity_out.reshape(-1)))


def _saddle_blocks(r_type, locations, mobility):
    """(L, L^{-1}, M^{-1}, K, M^{-1} K, N) of a stack of bodies r_type (nb, n, 3) at locations (nb, 3): Cholesky
    factors (None where Cholesky failed, then a plain inverse), inverse mobilities, K, and body mobilities.
    ``mobility``: the BlobMobility of these blobs (its radius one number or (nb, n))."""
    M_blocks = mobility.dense_matrix(r_type)
    try:
        L = np.linalg.cholesky(M_blocks)
        L_inv = lower_triangular_inverse(L)
        M_inv = np.matmul(np.swapaxes(L_inv, 1, 2), L_inv)
    except np.linalg.LinAlgError:
        L = L_inv = None
        M_inv = np.linalg.inv(M_blocks)
    K = K_matrices(r_type, locations)
    M_inv_K = np.matmul(M_inv, K)
    resistance = np.matmul(np.swapaxes(K, 1, 2), M_inv_K)
    return L, L_inv, M_inv, K, M_inv_K, body_mobility_from_resistance(resistance)


def _merged_blocks(nb, todo, computed, found):
    """The six stacks of :func:`_saddle_blocks` of nb bodies: ``computed`` (for the bodies ``todo``, or None) and
    the memo's ``found`` (body -> its six blocks).  No Cholesky factors if any body has none (as a whole stack
    whose Cholesky failed)."""
    first = computed if computed is not None else next(iter(found.values()))
    merged = []
    for index, part in enumerate(first):
        if part is None or any(entry[index] is None for entry in found.values()):
            merged.append(None)
            continue
        shape = part.shape[1:] if computed is not None else part.shape
        out = np.empty((nb,) + shape)
        if computed is not None:
            out[todo] = computed[index]
        for k, entry in found.items():
            out[k] = entry[index]
        merged.append(out)
    if merged[0] is None or merged[1] is None:
        merged[0] = merged[1] = None
    return tuple(merged)


def gmres_solve(operator, rhs, tolerance, preconditioner=None, x0=None, restart=GMRES_RESTART,
                maxiter=GMRES_MAXITER, print_residual=False, minimal_residual=False):
    """GMRES on ``operator x = rhs`` (relative tolerance, ``atol = 0``): the one GMRES call of the package.

    operator : LinearOperator or object with ``matvec``; rhs (n,); preconditioner : LinearOperator, object
    with ``matvec`` or None; x0 (n,) or None (zeros).  :func:`krylov.gmres` (SciPy's rules, no product
    beyond the Krylov ones and the warm start's residual); ``minimal_residual``: the point of least true
    residual of each Krylov space, stopping as soon as it meets the tolerance (the same rule, never more
    iterations; False: SciPy's iterates).  Returns :data:`GmresResult` with the true relative residual
    ``|rhs - A x| / |rhs|`` (from the Arnoldi products, equal to rounding).  A zero right-hand side gives
    ``x = 0`` at once.
    """
    rhs = np.asarray(rhs, dtype=float).reshape(-1)
    rhs_norm = float(np.linalg.norm(rhs))
    if rhs_norm == 0.0:
        return GmresResult(np.zeros_like(rhs), 0, True, 0.0)

    def report(residual_norm, count=[0]):
        count[0] += 1
        print('gmres = %d %s' % (count[0], residual_norm))

    psolve = None if preconditioner is None else preconditioner.matvec
    solution, info, iterations, residual = krylov.gmres(
        operator.matvec, rhs, tolerance, psolve=psolve, x0=x0, restart=restart, maxiter=maxiter,
        callback=report if print_residual else None, minimal_residual=minimal_residual)
    return GmresResult(solution, iterations, info == 0, float(np.linalg.norm(residual) / rhs_norm))


def kept_fewest(fewest, iterations, margin):
    """The wear rule of a kept preconditioner: the fewest GMRES iterations since its build after a solve of
    ``iterations`` (``fewest`` None: the first), or None when that solve took ``margin`` or more above them (the
    preconditioner has worn: the next solve builds a new one)."""
    fewest = iterations if fewest is None else min(fewest, iterations)
    return None if iterations >= fewest + margin else fewest


def _own_product(linear_map):
    """True for a :class:`LinearMap` whose ``operator`` is the base's (a LinearOperator of its ``apply``): GMRES then
    calls its ``matvec`` itself, the same products without the LinearOperator's argument checks (a solve of a small
    system makes tens of them)."""
    return isinstance(linear_map, LinearMap) and type(linear_map).operator is LinearMap.operator


def solve(problem, rhs, preconditioner, x0=None, tolerance=None, restart=GMRES_RESTART, maxiter=GMRES_MAXITER,
          print_residual=False, minimal_residual=False):
    """Solve ``A x = rhs`` of any problem of the package by preconditioned GMRES: the one solve of the package.

    The problem protocol (``doc/adding_a_problem.md``), implemented by the rigid
    (:class:`MobilityProblem`), mixed (``obstacles.MixedMobilityProblem``), articulated
    (``articulated.ArticulatedProblem``, ``articulated.RollerJointProblem``) and roller
    (``rollers.RollerSpinProblem``) problems:

    * ``size`` (int) and ``operator`` (a SciPy LinearOperator of that size), the matrix ``A``;
    * ``prepare_rhs(rhs) -> rhs``: what the problem does to a right-hand side before the solve (the rigid
      problems project the force part on what the bodies' blobs can balance; others return it unchanged);
    * ``solution(x) -> SolutionParts``: the solution split into blob forces, body velocities and
      constraint forces (each None where the problem has none).

    Parameters
    ----------
    problem : a problem of the protocol above, built at one configuration.
    rhs : ndarray (problem.size,) (``problem.rhs(...)``).
    preconditioner : an object with ``operator`` (a LinearOperator), a LinearOperator, or None
        (explicitly unpreconditioned).  Nothing is built here: build one at the problem's configuration
        (or reuse one built nearby).
    x0 : ndarray (problem.size,) or None
        First guess of the *normalised* system ``A y = rhs / |rhs|`` (SPEC 4.2: the published code
        passes the previous normalised solution, ``SolveResult.normalised_solution``); None (or a
        guess of another size) is zeros.
    tolerance : float, GMRES stops when ``|r| <= tolerance |rhs|`` (None: the option table's ``solver_tolerance``).
    minimal_residual : bool, GMRES takes the point of least true residual of its Krylov space and stops at
        the first iteration where it meets the tolerance (:func:`gmres_solve`; False: the published iterates).

    Returns :data:`SolveResult` (the solution of ``A x = rhs``, un-normalised, its true residual and its
    iteration count).  Nothing is counted or stored here; the caller decides what a non-converged solve means.
    """
    if tolerance is None:
        tolerance = DEFAULTS.solver_tolerance
    rhs = problem.prepare_rhs(np.array(rhs, dtype=float).reshape(-1))
    norm = float(np.linalg.norm(rhs))
    if norm == 0.0:
        parts = problem.solution(np.zeros(problem.size))
        return SolveResult(parts.lambda_blobs, parts.velocities, 0, True, 0.0, None, parts.constraint)
    preconditioner = preconditioner if _own_product(preconditioner) else getattr(preconditioner, 'operator',
                                                                                 preconditioner)
    if x0 is not None and np.shape(x0) != rhs.shape:
        x0 = None
    operator = problem if _own_product(problem) else problem.operator
    result = gmres_solve(operator, rhs / norm, tolerance, preconditioner=preconditioner, x0=x0,
                         restart=restart, maxiter=maxiter, print_residual=print_residual,
                         minimal_residual=minimal_residual)
    parts = problem.solution(result.x * norm)
    return SolveResult(parts.lambda_blobs, parts.velocities, result.iterations, result.converged,
                       result.residual, result.x, parts.constraint)


# ---------------------------------------------------------------------------------------------- dense algebra
def dense_blob_mobility(r_vectors, mobility):
    """Dense blob mobility of all blobs, shape (3N, 3N), of a BlobMobility (its radius or per-blob radii (N,))."""
    return mobility.dense_matrix(np.asarray(r_vectors, dtype=float).reshape(-1, 3))


def dense_matrices(body_arrays, configuration, mobility, eta=None, blob_radius=None, inverse=True):
    """Dense algebra at a configuration: (M (3N, 3N), M^{-1} or None, K (3N, 6Nb), N (6Nb, 6Nb) or None).

    ``M`` from ``mobility`` (a BlobMobility, or a dense-matrix function of the published form with ``eta`` and
    ``blob_radius``: :func:`blob_mobility`), ``M^{-1}`` by Cholesky (:func:`spd_inverse`),
    ``N = pinv(K^T M^{-1} K)`` (:func:`body_mobility_from_resistance`).
    """
    configuration = as_configuration(configuration)
    r_vectors = body_arrays.blob_positions(configuration)
    M = dense_blob_mobility(r_vectors, blob_mobility(body_arrays, mobility, eta, blob_radius, role='dense_matrix'))
    K = body_arrays.K_dense(configuration, r_vectors)
    if not inverse:
        return M, None, K, None
    M_inv = spd_inverse(M)
    return M, M_inv, K, body_mobility_from_resistance(K.T @ M_inv @ K)


class DenseMobilityProblem(MobilityProblem):
    """The rigid problem at one configuration over its dense matrices: the products are matrix products and the
    solution is exact (no GMRES); the dense twins of the iterative schemes take their step with it
    (``quaternion_integrator.stochastic_schemes.DenseTwin``).

    M : (3N, 3N) the blob mobility and K : (3N, 6Nb) the kinematics at ``configuration`` (``dense_matrices`` with
    ``inverse=False``); ``mobility``: the model's vector mobility (the problem's ``eta``, radii and box).
    ``M^{-1}`` and ``N = pinv(K^T M^{-1} K)`` are made at the first :meth:`exact_solution`, the symmetric root
    ``M^{1/2}`` at the first :meth:`root`.
    """

    def __init__(self, body_arrays, configuration, mobility, M, K):
        super().__init__(body_arrays, configuration, mobility)
        self.M, self.K = M, K
        self._inverse = self._root = None

    def M_dot(self, blob_forces):
        return self.M @ np.asarray(blob_forces, dtype=float).reshape(-1)

    def K_dot(self, body_velocities):
        return (self.K @ np.asarray(body_velocities, dtype=float).reshape(-1)).reshape(-1, 3)

    def KT_dot(self, blob_forces):
        return (self.K.T @ np.asarray(blob_forces, dtype=float).reshape(-1)).reshape(-1, 6)

    def root(self):
        """``M^{1/2}`` (3N, 3N), the symmetric root (``stochastic_forcing.symmetric_root_matrix``)."""
        if self._root is None:
            from stochastic_forcing import symmetric_root_matrix
            self._root = symmetric_root_matrix(self.M)
        return self._root

    def exact_solution(self, rhs):
        """The exact solution of ``A [lambda; U] = rhs = [s; -F]``: ``U = N (F - K^T M^{-1} s)``,
        ``lambda = M^{-1} (s + K U)``; a SolveResult of 0 iterations."""
        if self._inverse is None:
            M_inv = spd_inverse(self.M)
            self._inverse = M_inv, body_mobility_from_resistance(self.K.T @ M_inv @ self.K)
        M_inv, N = self._inverse
        rhs = np.asarray(rhs, dtype=float).reshape(-1)
        n3 = 3 * self.num_blobs
        slip, force_torque = rhs[:n3], -rhs[n3:]
        velocities = N @ (force_torque - self.K.T @ (M_inv @ slip))
        lambda_blobs = M_inv @ (slip + self.K @ velocities)
        return SolveResult(lambda_blobs.reshape(-1, 3), velocities.reshape(-1, 6), 0, True, 0.0, None, None)


def spd_inverse(matrix):
    """Inverse of a symmetric positive definite matrix (n, n) from its Cholesky factor (LAPACK potrf/potri).

    About half the work of ``np.linalg.inv`` (LU) and symmetric by construction; a
    matrix that is not positive definite (blobs overlapping the wall can make the
    wall-corrected mobility indefinite) falls back to ``np.linalg.inv``.
    """
    matrix = np.asarray(matrix, dtype=float)
    factor, info = _lapack.dpotrf(matrix, lower=False, clean=True)
    if info == 0:
        inverse, info = _lapack.dpotri(factor, lower=False)
    if info != 0:
        return np.linalg.inv(matrix)
    upper = np.triu(inverse)
    return upper + np.triu(upper, 1).T


def dense_body_mobility(body_arrays, configuration, mobility, eta=None, blob_radius=None):
    """Body mobility of the whole system by dense algebra, at ``configuration`` (``mobility`` as
    :func:`dense_matrices` takes it).

    Returns
    -------
    body_mobility : ndarray, shape (6 Nb, 6 Nb)
        ``N = pinv(K^T M^{-1} K)``: maps ``[F_0, T_0, F_1, ...]`` to ``[v_0, w_0, v_1, ...]``
        (torques and angular velocities about each body's location).
    slip_mobility : ndarray, shape (6 Nb, 3N)
        ``N K^T M^{-1}`` (body velocities are ``-slip_mobility @ slip`` for slip alone).
    """
    _, M_inv, K, N = dense_matrices(body_arrays, configuration, mobility, eta, blob_radius)
    return N, N @ K.T @ M_inv


def dense_mobility_velocities(body_arrays, configuration, force_torque, slip, mobility, eta=None,
                              blob_radius=None):
    """Body velocities (Nb, 6) by dense algebra at ``configuration``: ``U = N (F - K^T M^{-1} slip)``
    (``mobility`` as :func:`dense_matrices` takes it)."""
    body_mobility, slip_mobility = dense_body_mobility(body_arrays, configuration, mobility, eta, blob_radius)
    U = body_mobility @ np.asarray(force_torque, dtype=float).reshape(-1) \
        - slip_mobility @ np.asarray(slip, dtype=float).reshape(-1)
    return U.reshape(-1, 6)


def solve_resistance_problem(body_arrays, configuration, body_velocities, slip, mobility, eta=None,
                             blob_radius=None):
    """Forces and torques that move the bodies at ``configuration`` with the given velocities (SPEC 4.4).

    ``lambda = M^{-1} (slip + K U)`` by a dense solve, ``[F; T] = K^T lambda`` (``mobility`` as
    :func:`dense_matrices` takes it).

    Returns (force_torque (Nb, 6), lambda_blobs (N, 3)).
    """
    configuration = as_configuration(configuration)
    r_vectors = body_arrays.blob_positions(configuration)
    M = dense_blob_mobility(r_vectors, blob_mobility(body_arrays, mobility, eta, blob_radius, role='dense_matrix'))
    blob_velocities = np.asarray(slip, dtype=float).reshape(-1, 3) + body_arrays.K_dot(configuration,
                                                                                      body_velocities, r_vectors)
    lambda_blobs = np.linalg.solve(M, blob_velocities.reshape(-1)).reshape(-1, 3)
    return body_arrays.KT_dot(configuration, lambda_blobs, r_vectors), lambda_blobs
