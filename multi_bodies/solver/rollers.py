"""Single-blob rollers (SPEC 5.2; Balboa Usabiaga et al., J. Chem. Phys. 146, 134104, 2017): their problem and velocities.

A roller is one blob whose position alone moves.  Its linear velocity is
``v = M_UF F + M_UT T``; with ``free_kinematics`` the torque is
``8 pi eta a^3 omega_one_roller`` per blob, otherwise it is the torque that
makes every blob spin at ``omega_one_roller``: the solution of
``M_WT T = omega - M_WF F``, a problem of the package's problem protocol
(:class:`RollerSpinProblem`, solved by the one ``body_solver.solve``).

Everything here is a function of the model (``multi_bodies.solver.model.Model``)
and a configuration; nothing is counted or stored.  The couplings are those of
the model's ``roller_mobility`` (a ``mobility.interface.BlobMobility``: the
vector-product backend in the geometry of ``domain``, one blob radius;
:class:`InPlaneMobility` for ``domain in_plane``).
"""
from collections import namedtuple

import numpy as np

from mobility.interface import BlobMobility
from multi_bodies.solver import noise_factor
from multi_bodies.solver.body_solver import SolutionParts, check_finite
from multi_bodies.solver.linear_map import LinearProblem
from stochastic_forcing import displace_positions, lanczos_square_root, rfd
from utils import UserInputError

RollerVelocities = namedtuple('RollerVelocities', ['velocities', 'torque_guess', 'iterations'])
RollerVelocities.__doc__ = """Roller velocities (N, 3), the normalised torque solution to start the next
prescribed-spin solve from (None with ``free_kinematics``) and the GMRES iterations of that solve (0 without)."""

# GMRES restart length of the prescribed-spin solve (as before its move into the one solve)
SPIN_GMRES_RESTART = 20


class RollerSpinProblem(LinearProblem):
    """Torques (3N,) that make every roller spin at ``omega``: ``M_WT T = omega - M_WF F`` at blob positions r.

    Problem protocol of ``body_solver.solve``: ``size`` 3N, ``operator`` ``M_WT``, ``rhs()``,
    ``solution(T)`` -> SolutionParts(None, None, torques (N, 3)).
    """

    def __init__(self, model, r_vectors, forces):
        self.r_vectors, self.forces = r_vectors, forces
        self.omega = np.tile(model.omega_one_roller, r_vectors.shape[0])
        self.mobility = model.roller_mobility
        for kind in ('rot_times_force', 'rot_times_torque'):  # refused now (domain in_plane), not in the solve
            self.mobility.check_coupling(kind)
        self.size = forces.size

    def matvec(self, torques):
        return self.mobility.coupling('rot_times_torque', self.r_vectors, torques)

    def rhs(self):
        """``omega - M_WF F`` (3N,)."""
        return self.omega - self.mobility.coupling('rot_times_force', self.r_vectors, self.forces)

    def prepare_rhs(self, rhs):
        return rhs

    def solution(self, torques):
        return SolutionParts(None, None, np.asarray(torques).reshape(-1, 3))


def _check_in_plane(kind):
    if kind not in ('trans_times_force', 'trans_times_torque'):
        raise UserInputError('domain in_plane: the published in-plane roller mobility has translational couplings '
                             'only, so the rollers need free_kinematics True (a constant torque), not a prescribed '
                             'spin; or use domain single_wall')


def _projected(apply, vector):
    """``P apply(P v)`` with ``P`` the projection on the plane of the wall (z components set to zero); (3N,)."""
    projected = np.array(vector, dtype=float).reshape(-1, 3)
    projected[:, 2] = 0.0
    velocity = np.array(apply(projected.reshape(-1)), dtype=float).reshape(-1, 3)
    velocity[:, 2] = 0.0
    return velocity.reshape(-1)


def in_plane_product(product, kind):
    """The ``domain in_plane`` coupling of a single-wall roller ``product`` (published manual, section 6.2).

    ``P M P`` with ``P`` the projection on the plane of the wall (x, y): the x, y components of the force (or
    torque) of every blob act through the x, y rows of the single-wall coupling and the z component of every
    velocity is zero, so heights never change.  Only the translational couplings exist (``trans_times_force``,
    ``trans_times_torque``), as in the published code; the prescribed-spin couplings are refused.
    ``product(r_vectors (N, 3), vector (3N,), eta, a, L) -> (3N,)``, the same signature returned (the function
    form of :class:`InPlaneMobility`).
    """
    _check_in_plane(kind)

    def in_plane(r_vectors, vector, eta, a, L):
        return _projected(lambda v: product(r_vectors, v, eta, a, L), vector)
    in_plane.__name__ = 'in_plane_' + getattr(product, '__name__', kind)
    return in_plane


class InPlaneMobility(BlobMobility):
    """The ``domain in_plane`` roller mobility (:func:`in_plane_product`) over a single-wall ``BlobMobility``:
    ``P M P`` for the translational couplings; the rotational ones are refused with the published reason."""
    has_rotation = True

    def __init__(self, wall_mobility):
        self.wall_mobility = wall_mobility
        self.backend, self.geometry = wall_mobility.backend, wall_mobility.geometry
        self.eta, self.blob_radius = wall_mobility.eta, wall_mobility.blob_radius
        self.periodic_length = wall_mobility.periodic_length

    def replace(self, eta=None, blob_radius=None, periodic_length=None):
        inner = self.wall_mobility.replace(eta, blob_radius, periodic_length)
        return self if inner is self.wall_mobility else InPlaneMobility(inner)

    def check_coupling(self, kind):
        _check_in_plane(kind)

    def velocities(self, r_vectors, forces):
        return self.coupling('trans_times_force', r_vectors, forces)

    def coupling(self, kind, r_vectors, vector):
        _check_in_plane(kind)
        return _projected(lambda v: self.wall_mobility.coupling(kind, r_vectors, v), vector)


def roller_velocities(model, configuration, torque_guess=None, solver=None):
    """Linear velocities of single-blob rollers at ``configuration``: :data:`RollerVelocities`.

    Forces: one-blob plus blob-blob.  ``free_kinematics``: torque ``8 pi eta a^3 omega_one_roller`` per
    blob; otherwise the torque of :class:`RollerSpinProblem` (GMRES started from ``torque_guess``, the
    normalised torque of the last solve, by ``solver``: a ``solves.Solver``, None: the model's).  Then ``v = M_UF F + M_UT T``, shape (N, 3): one product where the
    mobility gives U and W of forces and torques together (``product_in_one_pass``: the spectral product), else
    the two couplings.
    """
    r_vectors = model.blob_positions(configuration)
    forces = model.blob_forces(r_vectors).reshape(-1)
    check_finite(forces, 'blob forces')
    a, eta = model.blob_radius, model.eta
    roller = model.roller_mobility
    iterations = 0
    if model.free_kinematics:
        torques = np.tile(8.0 * np.pi * eta * a ** 3 * model.omega_one_roller, model.num_blobs)
    else:
        problem = RollerSpinProblem(model, r_vectors, forces)
        solver = model.solver() if solver is None else solver
        result = solver.solve(problem, problem.rhs(), None, x0=torque_guess, restart=SPIN_GMRES_RESTART,
                              kind='roller_torques', what='the roller torques')
        torques, iterations = result.constraint_force_torque.reshape(-1), result.iterations
        if result.normalised_solution is not None:
            torque_guess = result.normalised_solution
    if roller.product_in_one_pass and np.any(torques != 0):  # the spectral product: U of (F, T) in one product
        velocity = roller.product(r_vectors, forces, torques)[0]
    else:
        velocity = roller.coupling('trans_times_force', r_vectors, forces)
        if np.any(torques != 0):
            velocity = velocity + roller.coupling('trans_times_torque', r_vectors, torques)
    return RollerVelocities(np.asarray(velocity).reshape(-1, 3), torque_guess, iterations)


def roller_noise(model, r_vectors, z, factor):
    """``factor * M_UF^{1/2} z`` of rollers at blob positions (N, 3) by Lanczos.

    No preconditioner, as published; under ``lanczos_preconditioner incomplete_cholesky`` Lanczos runs on
    ``L^{-1} M_UF L^{-T}`` with ``L`` the block IC(0) factor of the blobs that nearly touch
    (``noise_factor.single_blob_factor``): the same covariance, another sample, fewer iterations.
    Returns the ``stochastic_forcing.LanczosResult`` with ``noise`` (N, 3) (its count is the caller's).
    The spectral product's exact noise (``spectral_noise fluctuating``, triply periodic) replaces Lanczos.
    """
    roller = model.roller_mobility
    if getattr(roller, 'noise_method', None) == 'fluctuating':
        result = roller.noise(r_vectors, z, factor=factor)
        return result._replace(noise=result.noise.reshape(-1, 3))

    def plain(v):
        return np.asarray(roller.velocities(r_vectors, v)).reshape(-1)
    matvec, L_mult = plain, None
    if model.lanczos_preconditioner == 'incomplete_cholesky':
        # the blocks of the blobs backend with the rollers' one radius
        lower, _ = noise_factor.single_blob_factor(r_vectors, model.blobs_mobility.replace(
            blob_radius=model.blob_radius))

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
    roller = model.roller_mobility
    W = np.asarray(W, dtype=float).reshape(-1)
    difference = rfd(lambda r: np.asarray(roller.velocities(r, W)).reshape(-1, 3), r_vectors, W,
                     delta * model.blob_radius, displace_positions)
    return kT * difference
