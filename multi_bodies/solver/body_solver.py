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
"""
from collections import namedtuple

import numpy as np
import scipy.sparse.linalg as spla

from body.body import K_dense, K_matrices

GMRES_RESTART = 60
GMRES_MAXITER = 1000

SolveResult = namedtuple('SolveResult', ['lambda_blobs', 'velocities', 'iterations', 'converged', 'info',
                                         'residual'])
SolveResult.__doc__ = """Result of an iterative mobility solve.

lambda_blobs : ndarray (N, 3), blob constraint forces.
velocities : ndarray (Nb, 6), ``[v, w]`` per body.
iterations : int, GMRES inner iterations (callbacks).
converged : bool.
info : int, SciPy's GMRES flag (0 converged, > 0 iterations done without convergence).
residual : float, ``|b - A x| / |b|`` of the returned solution (true residual).
"""


def saddle_point_operator(body_arrays, r_vectors, mobility_product, eta, blob_radius,
                          periodic_length=(0.0, 0.0, 0.0), locations=None):
    """The saddle-point matrix ``A`` as a SciPy LinearOperator of size 3N + 6Nb.

    Parameters
    ----------
    body_arrays : body.body.BodyArrays
    r_vectors : ndarray, shape (N, 3)
        Blob positions.
    mobility_product : callable
        ``f(r_vectors, force (3N,), eta, a, periodic_length) -> (3N,)``, the
        matrix-free ``M f`` of a backend (``mobility.mobility_vector_product``).
    eta, blob_radius : float
    periodic_length : sequence of 3 floats
        Passed to the product (pseudo-periodic boxes, SPEC decision 5).
    locations : ndarray (Nb, 3) or None
        Body locations of the configuration (default: ``body_arrays.locations``).

    ``A [lambda; U] = [M lambda - K U; -K^T lambda]``.  The operator is a
    value: it copies the blob positions and locations it is built at, so a
    later change of the bodies does not change its product.
    """
    locations = body_arrays.locations if locations is None else locations
    return MobilityProblem(body_arrays, np.array(locations, dtype=float), None, mobility_product, eta, blob_radius,
                           periodic_length, r_vectors=r_vectors).operator


class MobilityProblem:
    """The saddle-point problem of all bodies at one configuration (a value: it copies what it is built at).

    Parameters
    ----------
    body_arrays : body.body.BodyArrays
        Only its fixed structure is used (reference blobs, blob-body index,
        offsets); its live locations and orientations are not read later.
    locations : (Nb, 3); orientations : (Nb, 4) or None (then ``r_vectors`` must be given)
    mobility_product : callable ``f(r_vectors, force (3N,), eta, a, periodic_length) -> (3N,)``
    eta, blob_radius : float; periodic_length : (3,) floats
    r_vectors : (N, 3) or None, blob positions (computed from the configuration when None)

    Attributes: ``locations``, ``orientations``, ``r_vectors`` (copies),
    ``operator`` (SciPy LinearOperator of size 3N + 6Nb), ``size``.
    """

    def __init__(self, body_arrays, locations, orientations, mobility_product, eta, blob_radius,
                 periodic_length=(0.0, 0.0, 0.0), r_vectors=None):
        from body.body import blob_positions
        self.body_arrays = body_arrays
        self.locations = np.array(locations, dtype=float).reshape(-1, 3)
        self.orientations = None if orientations is None else np.array(orientations, dtype=float).reshape(-1, 4)
        if r_vectors is None:
            r_vectors = blob_positions(self.locations, self.orientations, body_arrays.reference_blobs,
                                       body_arrays.blob_body_index)
        self.r_vectors = np.array(r_vectors, dtype=float).reshape(-1, 3)
        self.mobility_product = mobility_product
        self.eta, self.blob_radius = float(eta), float(blob_radius)
        self.periodic_length = np.asarray(periodic_length, dtype=float).reshape(3).copy()
        self.num_blobs = self.r_vectors.shape[0]
        self.num_bodies = self.locations.shape[0]
        self.size = 3 * self.num_blobs + 6 * self.num_bodies
        self.operator = spla.LinearOperator((self.size, self.size), matvec=self.matvec, dtype=float)

    def project_forces(self, force_torque):
        """Remove from force-torque (Nb, 6) the part that no blob force can balance.

        A body whose blobs cannot resist every rigid motion (a single blob: any
        rotation about its location; blobs on a line: rotation about that line)
        has a rank-deficient ``K``; its velocity along the null space of ``K``
        is undetermined and the body mobility ``pinv(K^T M^{-1} K)`` gives it
        zero.  A torque along that null space (random finite differences draw
        such torques) would make the saddle-point system inconsistent, so it
        is projected out, which gives the iterative solve the ``pinv`` answer.
        Full-rank bodies are returned unchanged.
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
        if getattr(self, '_projectors', None) is None:
            from body.body import K_matrices
            self._projectors = []
            for (bodies, blobs), n_blobs in zip(self.body_arrays.type_slices, self.body_arrays.type_blobs):
                nb = bodies.stop - bodies.start
                if nb == 0:
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

    def M_dot(self, blob_forces):
        """``M lambda``: blob velocities (3N,) of blob forces (3N,) or (N, 3)."""
        return np.asarray(self.mobility_product(self.r_vectors, np.asarray(blob_forces, dtype=float).reshape(-1),
                                                self.eta, self.blob_radius, self.periodic_length)).reshape(-1)

    def K_dot(self, body_velocities):
        """``K U``: blob velocities (N, 3) of body velocities (Nb, 6) or (6Nb,)."""
        from body.body import K_dot
        return K_dot(self.r_vectors, self.locations, self.body_arrays.blob_body_index, body_velocities)

    def KT_dot(self, blob_forces):
        """``K^T lambda``: force-torque (Nb, 6) of blob forces (N, 3) or (3N,)."""
        from body.body import KT_dot
        return KT_dot(self.r_vectors, self.locations, self.body_arrays.blob_offsets,
                      self.body_arrays.blob_body_index, blob_forces)

    def matvec(self, x):
        """``A [lambda; U] = [M lambda - K U; -K^T lambda]``."""
        x = np.asarray(x, dtype=float).reshape(-1)
        n3 = 3 * self.num_blobs
        lambda_blobs, velocities = x[:n3], x[n3:]
        slip_part = self.M_dot(lambda_blobs) - self.K_dot(velocities).reshape(-1)
        force_part = -self.KT_dot(lambda_blobs).reshape(-1)
        return np.concatenate((slip_part, force_part))


class BlockDiagonalPreconditioner:
    """Exact inverse of the saddle-point system of each body alone.

    For body k with dense blob mobility ``M_k`` (wall included, no periodic
    images) and ``K_k``: ``N_k = pinv(K_k^T M_k^{-1} K_k)``; applied to
    ``[s; f]`` it returns ``U_k = -N_k (f_k + K_k^T M_k^{-1} s_k)`` and
    ``lambda_k = M_k^{-1} (s_k + K_k U_k)``.

    Attributes (one entry per structure type; ``nb`` bodies of ``n`` blobs)
    -----------------------------------------------------------------------
    cholesky_factors : list of ndarray (nb, 3n, 3n) or None
        Lower Cholesky factors ``M_k = L_k L_k^T`` (None where Cholesky
        failed and a plain inverse was used).
    inverse_mobilities : list of ndarray (nb, 3n, 3n)
    body_mobilities : list of ndarray (nb, 6, 6)
    """

    def __init__(self, body_arrays, r_vectors, blob_mobility_matrix, eta, blob_radius, stacked_mobility=None,
                 locations=None):
        """``stacked_mobility`` (optional): ``f(r (nb, n, 3), eta, a) -> (nb, 3n, 3n)`` that builds the
        dense blocks of many bodies at once (``mobility.blob_mobility_matrix(name)`` accepts stacks).
        ``locations`` (Nb, 3): body locations of the configuration (default ``body_arrays.locations``);
        the preconditioner copies what it needs, so it stays valid when the bodies move."""
        self.body_arrays = body_arrays
        locations = np.array(body_arrays.locations if locations is None else locations, dtype=float)
        self.locations = locations
        self.inverse_cholesky_factors = []
        self.cholesky_factors = []
        self.inverse_mobilities = []
        self.inverse_mobility_times_K = []
        self.K = []
        self.body_mobilities = []
        for (bodies, blobs), n_blobs in zip(body_arrays.type_slices, body_arrays.type_blobs):
            nb = bodies.stop - bodies.start
            r_type = r_vectors[blobs].reshape(nb, n_blobs, 3)
            # Building the dense blocks calls the backend once per body (set-up only).
            if stacked_mobility is not None:
                M_blocks = stacked_mobility(r_type, eta, blob_radius)
            else:
                M_blocks = np.stack([blob_mobility_matrix(r_body, eta, blob_radius) for r_body in r_type])
            try:
                L = np.linalg.cholesky(M_blocks)
                L_inv = np.linalg.solve(L, np.broadcast_to(np.eye(3 * n_blobs), L.shape))
                M_inv = np.matmul(np.swapaxes(L_inv, 1, 2), L_inv)
            except np.linalg.LinAlgError:
                L = L_inv = None
                M_inv = np.linalg.inv(M_blocks)
            self.inverse_cholesky_factors.append(L_inv)
            K = K_matrices(r_type, locations[bodies])
            M_inv_K = np.matmul(M_inv, K)
            resistance = np.matmul(np.swapaxes(K, 1, 2), M_inv_K)
            self.cholesky_factors.append(L)
            self.inverse_mobilities.append(M_inv)
            self.inverse_mobility_times_K.append(M_inv_K)
            self.K.append(K)
            self.body_mobilities.append(np.linalg.pinv(resistance))
        n_blob_unknowns = 3 * body_arrays.num_blobs
        size = n_blob_unknowns + 6 * body_arrays.num_bodies
        self.operator = spla.LinearOperator((size, size), matvec=self.apply, dtype=float)

    def _blockwise(self, vector, factors):
        """Apply per-body dense blocks ``factors`` (list per type, (nb, 3n, 3n) or None = identity) to (3N,)."""
        vector = np.asarray(vector, dtype=float).reshape(-1, 3)
        out = vector.copy()
        for (bodies, blobs), F in zip(self.body_arrays.type_slices, factors):
            if F is None:
                continue
            nb = bodies.stop - bodies.start
            out[blobs] = np.matmul(F, vector[blobs].reshape(nb, -1, 1)).reshape(-1, 3)
        return out.reshape(-1)

    def L_dot(self, vector):
        """``L v`` with the block lower Cholesky factors ``M_k = L_k L_k^T``; vector (3N,)."""
        return self._blockwise(vector, self.cholesky_factors)

    def L_inv_dot(self, vector):
        """``L^{-1} v``; vector (3N,)."""
        return self._blockwise(vector, self.inverse_cholesky_factors)

    def L_inv_T_dot(self, vector):
        """``L^{-T} v``; vector (3N,)."""
        return self._blockwise(vector, [None if F is None else np.swapaxes(F, 1, 2)
                                        for F in self.inverse_cholesky_factors])

    def apply(self, x):
        """Apply the preconditioner to ``x = [s (3N); f (6 Nb)]``; returns the same layout."""
        x = np.asarray(x, dtype=float).reshape(-1)
        n_blob_unknowns = 3 * self.body_arrays.num_blobs
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


def mobility_rhs(force_torque, slip):
    """Right-hand side ``[slip (3N); -F (6 Nb)]`` from force-torque (Nb, 6) or (2Nb, 3) and slip (N, 3)."""
    return np.concatenate((np.asarray(slip, dtype=float).reshape(-1),
                           -np.asarray(force_torque, dtype=float).reshape(-1)))


def solve_mobility_problem(operator, preconditioner, rhs, num_blobs, tolerance, x0=None,
                           restart=GMRES_RESTART, maxiter=GMRES_MAXITER, print_residual=False,
                           true_residual=True):
    """Solve ``A x = rhs`` by preconditioned GMRES (relative tolerance, ``atol = 0``).

    Parameters
    ----------
    operator : LinearOperator from ``saddle_point_operator``
    preconditioner : BlockDiagonalPreconditioner or LinearOperator or None
    rhs : ndarray, shape (3N + 6Nb,)
    num_blobs : int
        N, to split the solution into ``lambda`` and ``U``.
    tolerance : float
        GMRES stops when ``|r| <= tolerance |rhs|`` (SciPy's ``rtol``).
    x0 : ndarray or None
        Initial guess (zeros by default).
    true_residual : bool
        Compute ``residual`` of the result (one more product) even when GMRES converged.

    Returns
    -------
    SolveResult
    """
    rhs = np.asarray(rhs, dtype=float).reshape(-1)
    if isinstance(preconditioner, BlockDiagonalPreconditioner):
        preconditioner = preconditioner.operator
    iterations = [0]

    def count(residual_norm):
        iterations[0] += 1
        if print_residual:
            print('gmres = %d %s' % (iterations[0], residual_norm))

    rhs_norm = np.linalg.norm(rhs)
    if rhs_norm == 0.0:
        solution, info = np.zeros_like(rhs), 0
    else:
        solution, info = spla.gmres(operator, rhs, x0=x0, rtol=tolerance, atol=0.0, restart=restart,
                                    maxiter=maxiter, M=preconditioner, callback=count,
                                    callback_type='legacy')
    # The true residual costs one more product M f; without ``true_residual`` it is computed only on failure.
    if rhs_norm == 0.0 or (not true_residual and info == 0):
        residual = 0.0 if rhs_norm == 0.0 else float('nan')
    else:
        residual = float(np.linalg.norm(rhs - operator.matvec(solution)) / rhs_norm)
    n_blob_unknowns = 3 * num_blobs
    return SolveResult(solution[:n_blob_unknowns].reshape(-1, 3),
                       solution[n_blob_unknowns:].reshape(-1, 6),
                       iterations[0], info == 0, int(info), residual)


def dense_blob_mobility(r_vectors, blob_mobility_matrix, eta, blob_radius):
    """Dense blob mobility of all blobs, shape (3N, 3N)."""
    return blob_mobility_matrix(np.asarray(r_vectors, dtype=float).reshape(-1, 3), eta, blob_radius)


def dense_body_mobility(body_arrays, r_vectors, blob_mobility_matrix, eta, blob_radius):
    """Body mobility of the whole system by dense algebra.

    Returns
    -------
    body_mobility : ndarray, shape (6 Nb, 6 Nb)
        ``N = pinv(K^T M^{-1} K)``: maps ``[F_0, T_0, F_1, ...]`` to ``[v_0, w_0, v_1, ...]``
        (torques and angular velocities about each body's location).
    slip_mobility : ndarray, shape (6 Nb, 3N)
        ``N K^T M^{-1}`` (body velocities are ``-slip_mobility @ slip`` for slip alone).
    """
    M = dense_blob_mobility(r_vectors, blob_mobility_matrix, eta, blob_radius)
    K = K_dense(r_vectors, body_arrays.locations, body_arrays.blob_body_index)
    M_inv = np.linalg.inv(M)
    body_mobility = np.linalg.pinv(K.T @ M_inv @ K)
    return body_mobility, body_mobility @ K.T @ M_inv


def dense_mobility_velocities(body_arrays, r_vectors, force_torque, slip, blob_mobility_matrix, eta,
                              blob_radius):
    """Body velocities (Nb, 6) by dense algebra: ``U = N (F - K^T M^{-1} slip)``."""
    body_mobility, slip_mobility = dense_body_mobility(body_arrays, r_vectors, blob_mobility_matrix, eta,
                                                       blob_radius)
    U = body_mobility @ np.asarray(force_torque, dtype=float).reshape(-1) \
        - slip_mobility @ np.asarray(slip, dtype=float).reshape(-1)
    return U.reshape(-1, 6)


def solve_resistance_problem(body_arrays, r_vectors, body_velocities, slip, blob_mobility_matrix, eta,
                             blob_radius):
    """Forces and torques that move the bodies with the given velocities (SPEC 4.4).

    ``lambda = M^{-1} (slip + K U)`` by a dense solve, ``[F; T] = K^T lambda``.

    Returns (force_torque (Nb, 6), lambda_blobs (N, 3)).
    """
    M = dense_blob_mobility(r_vectors, blob_mobility_matrix, eta, blob_radius)
    blob_velocities = np.asarray(slip, dtype=float).reshape(-1, 3) + body_arrays.K_dot(r_vectors, body_velocities)
    lambda_blobs = np.linalg.solve(M, blob_velocities.reshape(-1)).reshape(-1, 3)
    return body_arrays.KT_dot(r_vectors, lambda_blobs), lambda_blobs
