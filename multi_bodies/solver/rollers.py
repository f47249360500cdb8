"""Single-blob rollers (SPEC 5.2; Balboa Usabiaga et al., J. Chem. Phys. 146, 134104, 2017): their problem and velocities.

A roller is one blob whose position alone moves.  Its linear velocity is
``v = M_UF F + M_UT T``; with ``free_kinematics`` the torque is
``8 pi eta a^3 omega_one_roller`` per blob, otherwise it is the torque that
makes every blob spin at ``omega_one_roller``: the solution of
``M_WT T = omega - M_WF F``, a problem of the package's problem protocol
(:class:`RollerSpinProblem`, solved by the one ``body_solver.solve``).

Everything here is a function of the model (``multi_bodies.solver.model.Model``)
and a configuration; nothing is counted or stored.
"""
from collections import namedtuple

import numpy as np
import scipy.sparse.linalg as spla

import mobility
from multi_bodies.solver import noise_factor
from multi_bodies.solver.body_solver import SolutionParts, check_finite
from stochastic_forcing import displace_positions, lanczos_square_root, rfd
from utils import UserInputError

RollerVelocities = namedtuple('RollerVelocities', ['velocities', 'torque_guess', 'iterations'])
RollerVelocities.__doc__ = """Roller velocities (N, 3), the normalised torque solution to start the next
prescribed-spin solve from (None with ``free_kinematics``) and the GMRES iterations of that solve (0 without)."""

# GMRES restart length of the prescribed-spin solve (as before its move into the one solve)
SPIN_GMRES_RESTART = 20


class RollerSpinProblem:
    """Torques (3N,) that make every roller spin at ``omega``: ``M_WT T = omega - M_WF F`` at blob positions r.

    Problem protocol of ``body_solver.solve``: ``size`` 3N, ``operator`` ``M_WT``, ``rhs()``,
    ``solution(T)`` -> SolutionParts(None, None, torques (N, 3)).
    """

    def __init__(self, model, r_vectors, forces):
        self.r_vectors, self.forces = r_vectors, forces
        self.eta, self.a, self.periodic_length = model.eta, model.blob_radius, model.periodic_length
        self.omega = np.tile(model.omega_one_roller, r_vectors.shape[0])
        self.rot_times_force = model.roller_product('rot_times_force')
        self.rot_times_torque = model.roller_product('rot_times_torque')
        self.size = forces.size
        self.operator = spla.LinearOperator((self.size, self.size), matvec=self.matvec, dtype=float)

    def matvec(self, torques):
        return self.rot_times_torque(self.r_vectors, torques, self.eta, self.a, self.periodic_length)

    def rhs(self):
        """``omega - M_WF F`` (3N,)."""
        return self.omega - self.rot_times_force(self.r_vectors, self.forces, self.eta, self.a, self.periodic_length)

    def prepare_rhs(self, rhs):
        return rhs

    def solution(self, torques):
        return SolutionParts(None, None, np.asarray(torques).reshape(-1, 3))


def in_plane_product(product, kind):
    """The ``domain in_plane`` coupling of a single-wall roller ``product`` (published manual, section 6.2).

    ``P M P`` with ``P`` the projection on the plane of the wall (x, y): the x, y components of the force (or
    torque) of every blob act through the x, y rows of the single-wall coupling and the z component of every
    velocity is zero, so heights never change.  Only the translational couplings exist (``trans_times_force``,
    ``trans_times_torque``), as in the published code; the prescribed-spin couplings are refused.
    ``product(r_vectors (N, 3), vector (3N,), eta, a, L) -> (3N,)``, the same signature returned.
    """
    if kind not in ('trans_times_force', 'trans_times_torque'):
        raise UserInputError('domain in_plane: the published in-plane roller mobility has translational couplings '
                             'only, so the rollers need free_kinematics True (a constant torque), not a prescribed '
                             'spin; or use domain single_wall')

    def in_plane(r_vectors, vector, eta, a, L):
        projected = np.array(vector, dtype=float).reshape(-1, 3)
        projected[:, 2] = 0.0
        velocity = np.array(product(r_vectors, projected.reshape(-1), eta, a, L), dtype=float).reshape(-1, 3)
        velocity[:, 2] = 0.0
        return velocity.reshape(-1)
    in_plane.__name__ = 'in_plane_' + getattr(product, '__name__', kind)
    return in_plane


def roller_velocities(model, configuration, torque_guess=None):
    """Linear velocities of single-blob rollers at ``configuration``: :data:`RollerVelocities`.

    Forces: one-blob plus blob-blob.  ``free_kinematics``: torque ``8 pi eta a^3 omega_one_roller`` per
    blob; otherwise the torque of :class:`RollerSpinProblem` (GMRES started from ``torque_guess``, the
    normalised torque of the last solve).  Then ``v = M_UF F + M_UT T``, shape (N, 3).
    """
    r_vectors = model.blob_positions(configuration)
    forces = model.blob_forces(r_vectors).reshape(-1)
    check_finite(forces, 'blob forces')
    a, eta, L = model.blob_radius, model.eta, model.periodic_length
    iterations = 0
    if model.free_kinematics:
        torques = np.tile(8.0 * np.pi * eta * a ** 3 * model.omega_one_roller, model.num_blobs)
    else:
        problem = RollerSpinProblem(model, r_vectors, forces)
        result = model.solve(problem, problem.rhs(), None, x0=torque_guess, restart=SPIN_GMRES_RESTART,
                             what='the roller torques')
        torques, iterations = result.constraint_force_torque.reshape(-1), result.iterations
        if result.normalised_solution is not None:
            torque_guess = result.normalised_solution
    velocity = model.roller_product('trans_times_force')(r_vectors, forces, eta, a, L)
    if np.any(torques != 0):
        velocity = velocity + model.roller_product('trans_times_torque')(r_vectors, torques, eta, a, L)
    return RollerVelocities(np.asarray(velocity).reshape(-1, 3), torque_guess, iterations)


def roller_noise(model, r_vectors, z, factor):
    """``factor * M_UF^{1/2} z`` of rollers at blob positions (N, 3) by Lanczos.

    No preconditioner, as published; under ``lanczos_preconditioner incomplete_cholesky`` Lanczos runs on
    ``L^{-1} M_UF L^{-T}`` with ``L`` the block IC(0) factor of the blobs that nearly touch
    (``noise_factor.single_blob_factor``): the same covariance, another sample, fewer iterations.
    Returns the ``stochastic_forcing.LanczosResult`` with ``noise`` (N, 3) (its count is the caller's).
    """
    product = model.roller_product('trans_times_force')
    a, eta, L = model.blob_radius, model.eta, model.periodic_length

    def plain(v):
        return np.asarray(product(r_vectors, v, eta, a, L)).reshape(-1)
    matvec, L_mult = plain, None
    if getattr(model, 'lanczos_preconditioner', 'block_diagonal') == 'incomplete_cholesky':
        lower, _ = noise_factor.single_blob_factor(r_vectors, eta, a, model.stacked_mobility,
                                                   mobility.blob_cross_blocks(model.blobs_name))

        def matvec(v):
            return lower.L_inv_dot(plain(lower.L_inv_T_dot(v)))
        L_mult = lower.L_dot
    result = lanczos_square_root(matvec, z, model.tolerance, max_iterations=model.lanczos_max_iterations,
                                 factor=factor, L_mult=L_mult, print_residual=model.print_residual)
    model.warn_if_not_converged(result)
    noise = result.noise.reshape(-1, 3)
    if model.domain == 'in_plane':  # the square root of P M P has zero z rows; Lanczos leaves round-off there
        noise = noise.copy()
        noise[:, 2] = 0.0
    return result._replace(noise=noise)


def roller_drift(model, r_vectors, W, kT, delta):
    """Thermal drift ``kT div M_UF`` of rollers by a random finite difference (SPEC 5.2), shape (N, 3).

    ``(kT/(delta a)) [M_UF(r + delta a W/2) W - M_UF(r - delta a W/2) W]`` with W (3N,) ~ N(0, 1);
    zero without a wall (the free-space RPY tensor is divergence free).
    """
    if model.domain == 'no_wall' or kT == 0:
        return np.zeros_like(r_vectors)
    product = model.roller_product('trans_times_force')
    a, eta, L = model.blob_radius, model.eta, model.periodic_length
    W = np.asarray(W, dtype=float).reshape(-1)
    difference = rfd(lambda r: np.asarray(product(r, W, eta, a, L)).reshape(-1, 3), r_vectors, W, delta * a,
                     displace_positions)
    return kT * difference
