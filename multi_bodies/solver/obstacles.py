"""Bodies of prescribed kinematics (obstacles and bodies with a velocity file): the mixed problem.

Free bodies move under their forces; a body of prescribed kinematics moves
with a given lab-frame velocity ``U_P`` (zero for an obstacle) and its force
is the unknown.  The saddle-point system of :mod:`body_solver` becomes
(free bodies F, prescribed bodies P)::

    [ M      -K_F   0 ] [lambda]   [ slip + K_P U_P ]
    [-K_F^T   0     0 ] [ U_F  ] = [ -F_F           ]
    [-K_P^T   0     I ] [ F_P  ]   [  0             ]

The unknowns keep the layout of the free problem: blob forces (3N), then six
numbers per body, which are the velocity of a free body and the force-torque
``F_P = K_P^T lambda`` (force units) of a prescribed one: the force and
torque (about its location) that hold it on its prescribed motion, i.e. what
it exerts on the fluid; the fluid exerts ``-F_P`` on it.  The prescribed
bodies' columns of ``K`` are dropped from the operator; their rows become
the (redundant) definition of ``F_P``.  The block-diagonal preconditioner is
exact for each body alone: the free block as before, for a prescribed body
``lambda_k = M_k^{-1} s_k``, ``F_k = f_k + K_k^T lambda_k``.

Everything else is the free problem's: the one iterative solve
(:func:`body_solver.solve`) reads the split of the body unknowns from
:meth:`MixedMobilityProblem.split_body_unknowns`.  The dense variant
(:func:`dense_mixed_velocities`) solves the same system by block elimination.

A right-hand side built with the bodies' forces (``rhs(force_torque=...)``)
carries the prescribed motion ``K_P U_P`` and its solution gives the
prescribed bodies their velocity ``U_P``; noise and random-finite-difference
right-hand sides (no ``force_torque``) do not: prescribed bodies are not
displaced by them.
"""
import numpy as np

from multi_bodies.solver.body_solver import (BlockDiagonalPreconditioner, MobilityProblem, SolutionParts,
                                           body_mobility_from_resistance)


def fixed_bodies_of(bodies):
    """(fixed (Nb,) bool, prescribed velocities (Nb, 6)) from the bodies' ``prescribed_velocity``.

    A body without the attribute, or with None, is free (velocity row zero).
    """
    fixed = np.array([getattr(b, 'prescribed_velocity', None) is not None for b in bodies], dtype=bool)
    velocities = np.zeros((len(bodies), 6))
    for k, body in enumerate(bodies):
        if fixed[k]:
            velocities[k] = np.asarray(body.prescribed_velocity, dtype=float).reshape(6)
    return fixed, velocities


class MixedMobilityProblem(MobilityProblem):
    """The saddle-point problem with bodies of prescribed kinematics (see module docstring).

    Parameters: those of :class:`body_solver.MobilityProblem`, then
    ``fixed`` (Nb,) bool (True: prescribed kinematics) and
    ``prescribed_velocities`` (Nb, 6) lab-frame ``[v, w]`` (rows of free bodies ignored).
    """

    def __init__(self, body_arrays, configuration, mobility, eta=None, blob_radius=None, periodic_length=None,
                 fixed=None, prescribed_velocities=None):
        super().__init__(body_arrays, configuration, mobility, eta, blob_radius, periodic_length)
        if fixed is None or prescribed_velocities is None:
            raise TypeError('MixedMobilityProblem needs fixed and prescribed_velocities')
        self.fixed = np.asarray(fixed, dtype=bool).reshape(-1).copy()
        if self.fixed.size != self.num_bodies:
            raise ValueError('fixed has %d entries for %d bodies' % (self.fixed.size, self.num_bodies))
        self.free = ~self.fixed
        self.prescribed_velocities = np.where(self.fixed[:, None],
                                              np.asarray(prescribed_velocities, dtype=float).reshape(-1, 6), 0.0)

    def matvec(self, x):
        """``[M lambda - K_F U_F; -K_F^T lambda; -K_P^T lambda + F_P]`` of ``x = [lambda; U_F or F_P]``."""
        x = np.asarray(x, dtype=float).reshape(-1)
        n3 = 3 * self.num_blobs
        lambda_blobs, body = x[:n3], x[n3:].reshape(-1, 6)
        velocities = np.where(self.free[:, None], body, 0.0)
        slip_part = self.M_dot(lambda_blobs) - self.K_dot(velocities).reshape(-1)
        force_part = -self.KT_dot(lambda_blobs).reshape(-1, 6)
        force_part[self.fixed] += body[self.fixed]
        return np.concatenate((slip_part, force_part.reshape(-1)))

    def rhs(self, slip=None, force_torque=None, noise_slip=None, noise_force=None, prescribed_motion=None):
        """``[slip - noise_slip + K_P U_P; -(F_F + noise_force_F); 0]`` (3N + 6Nb,).

        prescribed_motion : bool or None; None means ``force_torque is not None`` (a deterministic
        right-hand side carries the prescribed motion, a noise or RFD one does not).
        Forces given for prescribed bodies are ignored (their force is the unknown).
        """
        rhs = super().rhs(slip=slip, force_torque=force_torque, noise_slip=noise_slip, noise_force=noise_force)
        n3 = 3 * self.num_blobs
        rhs[n3:].reshape(-1, 6)[self.fixed] = 0.0
        if prescribed_motion is None:
            prescribed_motion = force_torque is not None
        if prescribed_motion and np.any(self.prescribed_velocities):
            rhs[:n3] += self.K_dot(self.prescribed_velocities).reshape(-1)
        return rhs

    def project_forces(self, force_torque):
        """As the free problem for the free bodies; rows of prescribed bodies are kept (they are zero)."""
        projected = super().project_forces(force_torque)
        projected[self.fixed] = np.asarray(force_torque, dtype=float).reshape(-1, 6)[self.fixed]
        return projected

    def solution(self, x):
        """``[lambda; body unknowns]`` split: SolutionParts(lambda (N, 3), velocities (Nb, 6), constraint
        force-torque (Nb, 6)) (:meth:`split_body_unknowns`)."""
        n3 = 3 * self.num_blobs
        velocities, constraint = self.split_body_unknowns(x[n3:])
        return SolutionParts(x[:n3].reshape(-1, 3), velocities, constraint)

    def without_prescribed_motion(self, velocities):
        """Body velocities (Nb, 6) of a solve with the prescribed bodies' rows zero (noise and RFD solves do not
        move them)."""
        return np.where(self.free[:, None], np.asarray(velocities, dtype=float).reshape(-1, 6), 0.0)

    def split_body_unknowns(self, body_unknowns, prescribed_motion=True):
        """(velocities (Nb, 6), constraint force-torque (Nb, 6)) from the body part of a solution (Nb, 6).

        Velocities: the solved ones of free bodies, ``U_P`` (or zero with ``prescribed_motion`` False)
        of prescribed bodies; force-torque: ``F_P = K_P^T lambda`` of prescribed bodies, zero for free ones.
        """
        body = np.asarray(body_unknowns, dtype=float).reshape(-1, 6)
        velocities = np.where(self.free[:, None], body, self.prescribed_velocities if prescribed_motion else 0.0)
        constraint = np.where(self.fixed[:, None], body, 0.0)
        return velocities, constraint


class MixedPreconditioner(BlockDiagonalPreconditioner):
    """Block-diagonal preconditioner of :class:`MixedMobilityProblem`: exact for each body alone.

    Parameters: those of :class:`body_solver.BlockDiagonalPreconditioner`, then ``fixed`` (Nb,) bool and
    ``memo``: a dict (the model's) in which the blocks of the prescribed bodies are kept from one build to the
    next, keyed by their exact blob positions, so that obstacles that do not move are factored once (the same
    numbers; None: no memo).  The Cholesky factors (Lanczos noise) are those of the free problem: ``M`` is the
    same.
    """

    def __init__(self, body_arrays, configuration, mobility, eta=None, blob_radius=None, stacked_mobility=None,
                 fixed=None, memo=None):
        fixed = np.zeros(body_arrays.num_bodies, dtype=bool) if fixed is None \
            else np.asarray(fixed, dtype=bool).reshape(-1).copy()
        super().__init__(body_arrays, configuration, mobility, eta, blob_radius,
                         stacked_mobility=stacked_mobility, memo=memo, memo_bodies=fixed)
        self.fixed = fixed

    def blob_blocks(self):
        """As the base class, with ``Q_k = M_k^{-1}`` for a prescribed body (its velocity is not unknown)."""
        blocks = super().blob_blocks()
        for (bodies, _), Q, M_inv in zip(self.body_arrays.type_slices, blocks, self.inverse_mobilities):
            selected = np.flatnonzero(self.fixed[bodies])
            Q[selected] = M_inv[selected]
        return blocks

    def blob_body_blocks(self):
        """As the base class, with the constraint force-torque ``K_k^T M_k^{-1}`` for a prescribed body."""
        blocks = super().blob_body_blocks()
        for (bodies, _), B, M_inv_K in zip(self.body_arrays.type_slices, blocks, self.inverse_mobility_times_K):
            selected = np.flatnonzero(self.fixed[bodies])
            B[selected] = np.swapaxes(M_inv_K[selected], 1, 2)
        return blocks

    def apply(self, x):
        """The free blocks as the base class; prescribed body k: ``lambda_k = M_k^{-1} s_k``, ``F_k = f_k + K_k^T lambda_k``."""
        out = super().apply(x)
        x = np.asarray(x, dtype=float).reshape(-1)
        n3 = 3 * self.body_arrays.num_blobs
        slip, force = x[:n3].reshape(-1, 3), x[n3:].reshape(-1, 6)
        lambda_out, body_out = out[:n3].reshape(-1, 3), out[n3:].reshape(-1, 6)
        for (bodies, blobs), M_inv, K, n_blobs in zip(self.body_arrays.type_slices, self.inverse_mobilities,
                                                     self.K, self.body_arrays.type_blobs):
            selected = np.flatnonzero(self.fixed[bodies])
            if selected.size == 0:
                continue
            nb = bodies.stop - bodies.start
            s = slip[blobs].reshape(nb, n_blobs, 3)[selected].reshape(selected.size, -1, 1)
            lambda_k = np.matmul(M_inv[selected], s)
            lambda_type = lambda_out[blobs].reshape(nb, n_blobs, 3)
            lambda_type[selected] = lambda_k.reshape(selected.size, n_blobs, 3)
            lambda_out[blobs] = lambda_type.reshape(-1, 3)
            body_index = bodies.start + selected
            body_out[body_index] = force[body_index] + np.matmul(np.swapaxes(K[selected], 1, 2), lambda_k)[:, :, 0]
        return np.concatenate((lambda_out.reshape(-1), body_out.reshape(-1)))


def dense_mixed_solution(M, K, fixed, prescribed_velocities, force_torque, slip, M_inv=None):
    """The mixed problem by dense block elimination.

    M (3N, 3N), K (3N, 6Nb), fixed (Nb,) bool, prescribed_velocities (Nb, 6), force_torque (Nb, 6),
    slip (N, 3) or (3N,).  ``lambda = M^{-1} (slip + K_P U_P + K_F U_F)`` with
    ``U_F = pinv(K_F^T M^{-1} K_F) (F_F - K_F^T M^{-1} (slip + K_P U_P))`` and ``F_P = K_P^T lambda``.

    Returns (velocities (Nb, 6) (``U_P`` for prescribed bodies), constraint force-torque (Nb, 6)
    (zero for free bodies), lambda (N, 3)).
    """
    fixed = np.asarray(fixed, dtype=bool).reshape(-1)
    num_bodies = fixed.size
    columns = np.repeat(fixed, 6)
    K_F, K_P = K[:, ~columns], K[:, columns]
    M_inv = np.linalg.inv(M) if M_inv is None else M_inv
    U_P = np.asarray(prescribed_velocities, dtype=float).reshape(-1, 6)[fixed].reshape(-1)
    blob_rhs = np.asarray(slip, dtype=float).reshape(-1) + K_P @ U_P
    velocities = np.zeros((num_bodies, 6))
    velocities[fixed] = U_P.reshape(-1, 6)
    if K_F.shape[1]:
        N_FF = body_mobility_from_resistance(K_F.T @ M_inv @ K_F)
        F_F = np.asarray(force_torque, dtype=float).reshape(-1, 6)[~fixed].reshape(-1)
        U_F = N_FF @ (F_F - K_F.T @ (M_inv @ blob_rhs))
        velocities[~fixed] = U_F.reshape(-1, 6)
        blob_rhs = blob_rhs + K_F @ U_F
    lambda_blobs = M_inv @ blob_rhs
    constraint = np.zeros((num_bodies, 6))
    constraint[fixed] = (K_P.T @ lambda_blobs).reshape(-1, 6)
    return velocities, constraint, lambda_blobs.reshape(-1, 3)


def dense_mixed_body_mobility(M_inv, K, fixed):
    """Body mobility of the free bodies with the prescribed ones held still, by dense algebra.

    Returns (body_mobility (6Nb, 6Nb), slip_mobility (6Nb, 3N)): ``N_FF = pinv(K_F^T M^{-1} K_F)``
    and ``N_FF K_F^T M^{-1}`` in the rows (and columns) of the free bodies, zero in those of the
    prescribed ones (their velocity does not respond to forces or slip).
    """
    fixed = np.asarray(fixed, dtype=bool).reshape(-1)
    free_columns = np.flatnonzero(~np.repeat(fixed, 6))
    size = K.shape[1]
    body_mobility = np.zeros((size, size))
    slip_mobility = np.zeros((size, K.shape[0]))
    if free_columns.size:
        K_F = K[:, free_columns]
        N_FF = body_mobility_from_resistance(K_F.T @ M_inv @ K_F)
        body_mobility[np.ix_(free_columns, free_columns)] = N_FF
        slip_mobility[free_columns] = N_FF @ K_F.T @ M_inv
    return body_mobility, slip_mobility
