"""Time steps of spheres with lubrication: the published stochastic trapezoidal scheme, Euler-Maruyama with
a random finite difference, the plain RPB baseline, and torques that hold a prescribed rotation rate.

Functions of the configuration (locations (N, 3), orientations (N, 4) scalar-first quaternions) and of a
force callable ``force_torque_at(locations, orientations) -> (N, 6)`` rows ``[F T]``, so the published
``Lub_Solver`` face and the package's schemes use the same code.  Random numbers come from ``rng`` (any
object with ``standard_normal(size)``: a ``numpy.random.Generator``, a ``RandomState`` or the module
``numpy.random`` itself, as the published drivers seed it); draws per step, in this order: the near-field
W (6N), the far-field W (6N), the RFD direction (6N), only when kT > 0.

Method (Sprinkle et al., Soft Matter 16, 7982, 2020; J. Chem. Phys. 147, 244103, 2017):

* :func:`trapezoidal_step` - predictor ``U_p = (I + M Delta_R)^-1 (N + M F^n)`` at ``q^n``,
  ``q* = q^n + dt U_p``; corrector ``U_c = (I + M* Delta_R*)^-1 (D_M + N + M* F*)`` at ``q*`` with the
  SAME noise right-hand side ``N`` (:func:`lubrication.brownian.brownian_rhs` at ``q^n``) and
  ``D_M = 2 kT/delta (M(q^n + delta/2 W) - M(q^n - delta/2 W)) W`` (far-field M only: the near-field part
  of the drift comes from the predictor-corrector structure); ``q^{n+1} = q^n + dt (U_p + U_c)/2``.
  With kT = 0 it is Heun's method.  A step is rejected (the configuration stays ``q^n``) when a sphere
  centre would be below the wall (``z < 0``; also when the predictor puts one there) or a sphere would
  move more than ``2a``; rejections are returned, not retried (as published).
* :func:`euler_maruyama_step` - ``U = M_lub F + U_B + kT div M_lub`` (:func:`lubrication.brownian.thermal_drift`).
* :func:`rpb_step` - the baseline without lubrication: ``U = M F + sqrt(2kT/dt) M^1/2 W + kT div M`` (RFD).
* :func:`torque_from_omega` - the torques T that, with the given forces, make every sphere turn at the
  prescribed angular velocity (the mixed problem for T and the translational velocities), with an optional
  per-sphere cap ``|T_i| <= torque_cap`` (then those spheres turn slower).
"""
from collections import namedtuple

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from body.geometry import rotate_quaternions
from multi_bodies.solver.body_solver import SolutionParts, solve
from stochastic_forcing import lanczos_square_root

from .brownian import NearFieldRoot, brownian_rhs, far_field_drift, thermal_drift
from .problem import far_field_product

StepResult = namedtuple('StepResult', ['locations', 'orientations', 'rejected_wall', 'rejected_jump', 'velocities',
                                       'torques', 'counts'])
StepResult.__doc__ = """Result of a lubrication time step.

locations (N, 3), orientations (N, 4): the new configuration (the old one when rejected).
rejected_wall, rejected_jump : 0 or 1 (a sphere below z = 0; a sphere moving more than 2a).
velocities : (N, 6) the velocities used for the step ``[U W]`` (of the rejected step when rejected).
torques : (N, 3) torques from ``torque_from_omega`` (mean of the stages), or None without omega.
counts : dict of work done: ``far_field_products``, ``gmres_iterations``, ``lanczos_iterations``,
    ``factorisations`` (sparse LU), ``assemblies`` (of Delta_R)."""


def new_counts():
    """A dict of zero work counters (see :data:`StepResult`)."""
    return {'far_field_products': 0, 'gmres_iterations': 0, 'lanczos_iterations': 0, 'factorisations': 0,
            'assemblies': 0}


def counted_problem(settings, locations, counts, matrices=None):
    """``settings.problem(locations)`` whose far-field products are counted in ``counts``."""
    if matrices is None:
        matrices = settings.matrices(locations)
        counts['assemblies'] += 1
    problem = settings.problem(locations, matrices=matrices)
    product = problem.mobility_product

    def counted(x):
        counts['far_field_products'] += 1
        return product(x)
    problem.mobility_product = counted
    return problem


def _solve(problem, rhs, tolerance, counts):
    preconditioner = problem.preconditioner(tolerance)
    counts['factorisations'] += preconditioner.factor is not None
    result = solve(problem, rhs, preconditioner, tolerance=tolerance)
    counts['gmres_iterations'] += result.iterations
    return result.velocities


def omega_vectors(omega, n):
    """Prescribed angular velocities (N, 3): a number ``w`` means ``w y_hat`` for every sphere (the published
    rollers), else an array (3,) or (N, 3)."""
    omega_array = np.asarray(omega, dtype=float)
    if omega_array.ndim == 0:
        return np.tile([0.0, float(omega_array), 0.0], (n, 1))
    return np.broadcast_to(omega_array, (n, 3)).astype(float)


class TorqueFromOmegaProblem:
    """Unknowns ``x = [V_i, T_i]`` (N, 6): translational velocities and torques, given forces F and angular
    velocities Omega.  From ``(I + M Delta_R) [V; Omega] = M [F; T]``:
    ``[V; 0] + M Delta_R [V; 0] - M [0; T] = M [F; 0] - [0; Omega] - M Delta_R [0; Omega]``.
    Preconditioner: M replaced by the isolated sphere's ``1/(6 pi eta a)``, ``1/(8 pi eta a^3)``, which
    gives ``V = 6 pi eta a (6 pi eta a I + Delta_R_tt)^-1 r_t`` (one sparse LU, as published) and then T."""

    def __init__(self, problem, eta, a):
        self.problem, self.size, self.num_bodies = problem, problem.size, problem.num_bodies
        self.eta, self.a = eta, a
        self.operator = spla.LinearOperator((self.size, self.size), matvec=self.matvec, dtype=float)
        n = self.num_bodies
        self.trans = (np.arange(n)[:, None] * 6 + np.arange(3)).reshape(-1)
        self.rot = self.trans + 3

    def _split(self, x):
        x = np.asarray(x, dtype=float).reshape(-1, 6)
        velocity = np.zeros_like(x)
        velocity[:, :3] = x[:, :3]
        torque = np.zeros_like(x)
        torque[:, 3:] = x[:, 3:]
        return velocity.reshape(-1), torque.reshape(-1)

    def matvec(self, x):
        velocity, torque = self._split(x)
        return velocity + self.problem.mobility_product(self.problem.Delta_R @ velocity - torque)

    def rhs(self, forces, omega):
        ft = np.zeros((self.num_bodies, 6))
        ft[:, :3] = forces
        rotation = np.zeros((self.num_bodies, 6))
        rotation[:, 3:] = omega
        rotation = rotation.reshape(-1)
        return self.problem.mobility_product(ft.reshape(-1) - self.problem.Delta_R @ rotation) - rotation

    def prepare_rhs(self, rhs):
        return rhs

    def solution(self, x):
        return SolutionParts(None, np.asarray(x, dtype=float).reshape(self.num_bodies, 6), None)

    def preconditioner(self):
        friction = 6.0 * np.pi * self.eta * self.a
        rotational_mobility = 1.0 / (8.0 * np.pi * self.eta * self.a ** 3)
        Delta_R = self.problem.Delta_R.tocsr()
        block = Delta_R[self.trans][:, self.trans] + friction * sp.identity(self.trans.size, format='csr')
        self.factor = spla.splu(block.tocsc(), permc_spec='MMD_AT_PLUS_A', diag_pivot_thresh=0.0,
                                options={'SymmetricMode': True})
        coupling = Delta_R[self.rot][:, self.trans]

        def apply(r):
            r = np.asarray(r, dtype=float).reshape(-1)
            out = np.empty_like(r)
            velocity = friction * self.factor.solve(r[self.trans])
            out[self.trans] = velocity
            out[self.rot] = coupling @ velocity - r[self.rot] / rotational_mobility
            return out
        return spla.LinearOperator((self.size, self.size), matvec=apply, dtype=float)


def torque_from_omega(problem, forces, omega, tolerance=1e-8, torque_cap=None, counts=None):
    """Torques (N, 3) that hold the angular velocities ``omega`` of spheres under ``forces`` (N, 3).

    problem : :class:`lubrication.LubricationProblem` at the configuration; omega : see :func:`omega_vectors`;
    torque_cap : None or a number, the largest torque magnitude per sphere (larger ones are scaled down
    to it, keeping their direction: those spheres then turn slower than omega).
    """
    counts = new_counts() if counts is None else counts
    torque_problem = TorqueFromOmegaProblem(problem, problem.eta, problem.a)
    omega = omega_vectors(omega, problem.num_bodies)
    rhs = torque_problem.rhs(np.asarray(forces, dtype=float).reshape(-1, 3), omega)
    preconditioner = torque_problem.preconditioner()
    counts['factorisations'] += 1
    result = solve(torque_problem, rhs, preconditioner, tolerance=tolerance)
    counts['gmres_iterations'] += result.iterations
    torques = result.velocities[:, 3:].copy()
    if torque_cap is not None:
        size = np.linalg.norm(torques, axis=1)
        scale = np.where(size > torque_cap, torque_cap / np.where(size > 0, size, 1.0), 1.0)
        torques *= scale[:, None]
    return torques


def _forces(force_torque_at, problem, locations, orientations, omega, tolerance, torque_cap, counts):
    force_torque = np.array(force_torque_at(locations, orientations), dtype=float).reshape(-1, 6)
    torques = None
    if omega is not None:
        torques = torque_from_omega(problem, force_torque[:, :3], omega, tolerance, torque_cap, counts)
        force_torque[:, 3:] = torques
    return force_torque, torques


def _moved(locations, orientations, velocities, dt):
    return locations + dt * velocities[:, :3], rotate_quaternions(orientations, dt * velocities[:, 3:])


def _rejection(settings, old, new):
    wall = int(settings.wall and np.any(new[:, 2] < 0.0))
    jump = int(np.any(np.linalg.norm(new - old, axis=1) > 2.0 * settings.a))
    return wall, jump


def _noise(settings, problem, kT, dt, rng, tolerance, counts):
    size = problem.size
    if kT <= 0:
        return np.zeros(size)
    W_near = rng.standard_normal(size)
    W_far = rng.standard_normal(size)
    root = NearFieldRoot(problem.Delta_R, settings.near_field_root, settings.shift(tolerance), tolerance)
    noise, iterations = brownian_rhs(problem, root, W_far, W_near, kT, dt, tolerance)
    counts['lanczos_iterations'] += iterations
    counts['factorisations'] += root.factorisations
    return noise


def _step_start(settings, locations, orientations, force_torque_at, kT, dt, rng, tolerance, omega, torque_cap,
                matrices):
    """What every step computes first at the start configuration: (counts, locations (N, 3), orientations (N, 4),
    the problem there, force_torque (N, 6), torques (or None), the Brownian increment (6N,))."""
    counts = new_counts()
    locations = np.asarray(locations, dtype=float).reshape(-1, 3)
    orientations = np.asarray(orientations, dtype=float).reshape(-1, 4)
    problem = counted_problem(settings, locations, counts, matrices)
    force_torque, torques = _forces(force_torque_at, problem, locations, orientations, omega, tolerance, torque_cap,
                                    counts)
    noise = _noise(settings, problem, kT, dt, rng, tolerance, counts)
    return counts, locations, orientations, problem, force_torque, torques, noise


def trapezoidal_step(settings, locations, orientations, force_torque_at, kT, dt, rng, tolerance=1e-8, omega=None,
                     torque_cap=None, matrices=None, rfd=True):
    """One step of the published stochastic trapezoidal scheme (module note): a :data:`StepResult`.

    settings : :class:`lubrication.brownian.LubricationSettings`; locations (N, 3), orientations (N, 4);
    force_torque_at : callable (locations, orientations) -> (N, 6); kT, dt; rng (module note);
    omega, torque_cap : prescribed rotation (see :func:`torque_from_omega`; the torques are recomputed at
    the predictor's configuration for the corrector); matrices : the near-field matrices at ``locations``
    if already built; rfd : False leaves out the far-field drift term ``D_M`` (a negative control: the
    equilibrium is then wrong).
    """
    counts, locations, orientations, problem, force_torque, torques, noise = _step_start(
        settings, locations, orientations, force_torque_at, kT, dt, rng, tolerance, omega, torque_cap, matrices)
    predictor = _solve(problem, noise + problem.mobility_product(force_torque.reshape(-1)), tolerance, counts)
    mid_locations, mid_orientations = _moved(locations, orientations, predictor, dt)
    wall, jump = _rejection(settings, locations, mid_locations)
    if settings.wall and np.any(mid_locations[:, 2] <= 0.0):
        return StepResult(locations, orientations, 1, 0, predictor, torques, counts)
    drift = np.zeros(problem.size)
    if kT > 0 and rfd:
        drift = 2.0 * far_field_drift(settings, locations, rng.standard_normal(problem.size), kT).reshape(-1)
        counts['far_field_products'] += 2
    mid_problem = counted_problem(settings, mid_locations, counts)
    mid_force_torque, mid_torques = _forces(force_torque_at, mid_problem, mid_locations, mid_orientations, omega,
                                            tolerance, torque_cap, counts)
    corrector = _solve(mid_problem, drift + noise + mid_problem.mobility_product(mid_force_torque.reshape(-1)),
                       tolerance, counts)
    velocities = 0.5 * (predictor + corrector)
    if torques is not None:
        torques = 0.5 * (torques + mid_torques)
    new_locations, new_orientations = _moved(locations, orientations, velocities, dt)
    wall, jump = _rejection(settings, locations, new_locations)
    if wall or jump:
        return StepResult(locations, orientations, wall, jump, velocities, torques, counts)
    return StepResult(new_locations, new_orientations, 0, 0, velocities, torques, counts)


def euler_maruyama_step(settings, locations, orientations, force_torque_at, kT, dt, rng, tolerance=1e-8,
                        omega=None, torque_cap=None, matrices=None):
    """One Euler-Maruyama step ``q + dt (M_lub F + U_B + kT div M_lub)`` (RFD drift): a :data:`StepResult`."""
    counts, locations, orientations, problem, force_torque, torques, noise = _step_start(
        settings, locations, orientations, force_torque_at, kT, dt, rng, tolerance, omega, torque_cap, matrices)
    velocities = _solve(problem, noise + problem.mobility_product(force_torque.reshape(-1)), tolerance, counts)
    if kT > 0:
        velocities = velocities + thermal_drift(settings, locations, rng.standard_normal(problem.size), kT,
                                                tolerance, problem)
        counts['assemblies'] += 2
    new_locations, new_orientations = _moved(locations, orientations, velocities, dt)
    wall, jump = _rejection(settings, locations, new_locations)
    if wall or jump:
        return StepResult(locations, orientations, wall, jump, velocities, torques, counts)
    return StepResult(new_locations, new_orientations, 0, 0, velocities, torques, counts)


def rpb_step(settings, locations, orientations, force_torque_at, kT, dt, rng, tolerance=1e-8):
    """The baseline without lubrication: ``q + dt (M F + sqrt(2kT/dt) M^1/2 W + kT div M)``, M the far field
    (Lanczos noise, RFD drift); same rejection rules: a :data:`StepResult`."""
    counts = new_counts()
    locations = np.asarray(locations, dtype=float).reshape(-1, 3)
    orientations = np.asarray(orientations, dtype=float).reshape(-1, 4)
    product = far_field_product(locations, settings.eta, settings.a, settings.periodic_length, settings.wall,
                                settings.implementation)
    force_torque = np.asarray(force_torque_at(locations, orientations), dtype=float).reshape(-1)
    velocities = product(force_torque)
    counts['far_field_products'] += 1
    if kT > 0:
        W_far = rng.standard_normal(force_torque.size)
        far = lanczos_square_root(product, W_far, tolerance, factor=np.sqrt(2.0 * kT / dt))
        counts['lanczos_iterations'] += far.iterations
        drift = far_field_drift(settings, locations, rng.standard_normal(force_torque.size), kT).reshape(-1)
        counts['far_field_products'] += 2
        velocities = velocities + far.noise + drift
    velocities = velocities.reshape(-1, 6)
    new_locations, new_orientations = _moved(locations, orientations, velocities, dt)
    wall, jump = _rejection(settings, locations, new_locations)
    if wall or jump:
        return StepResult(locations, orientations, wall, jump, velocities, None, counts)
    return StepResult(new_locations, new_orientations, 0, 0, velocities, None, counts)
