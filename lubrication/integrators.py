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

Every step function takes ``kept``: None for the published solves (each builds its preconditioner, a sparse
factorisation, at its configuration; the corrector starts from the predictor's velocities, as published, the others
from zero), or a :class:`KeptSolves` that keeps the preconditioners between solves and steps and gives the solves
first guesses (the package's schemes under ``preconditioner auto``); and ``solver``: the
``multi_bodies.solver.solves.Solver`` that makes every solve (a scheme's step passes its own, which counts the solves
and stops the run at one that does not converge; None: one that stops such a solve, with the least-residual iterate
where ``kept`` is given), and ``tolerance`` (None: the solver's).
"""
from collections import namedtuple

import numpy as np

from body.geometry import rotate_quaternions
from multi_bodies.solver.body_solver import SolutionParts, kept_fewest
from multi_bodies.solver.linear_map import FunctionMap, LinearProblem
from stochastic_forcing import lanczos_square_root

from . import sparse_factor
from .brownian import NearFieldRoot, brownian_rhs, far_field_drift, thermal_drift
from .problem import LubricationPreconditioner, far_field_product, solver_and_tolerance

StepResult = namedtuple('StepResult', ['locations', 'orientations', 'rejected_wall', 'rejected_jump', 'velocities',
                                       'torques', 'counts'])
StepResult.__doc__ = """Result of a lubrication time step.

locations (N, 3), orientations (N, 4): the new configuration (the old one when rejected).
rejected_wall, rejected_jump : 0 or 1 (a sphere below z = 0; a sphere moving more than 2a).
velocities : (N, 6) the velocities used for the step ``[U W]`` (of the rejected step when rejected).
torques : (N, 3) torques from ``torque_from_omega`` (mean of the stages), or None without omega.
counts : dict of work done: ``far_field_products``, ``gmres_iterations``, ``lanczos_iterations``,
    ``factorisations`` (sparse LDL^T or LU: :mod:`lubrication.sparse_factor`), ``assemblies`` (of Delta_R)."""


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


# A kept lubrication preconditioner is built anew after a predictor solve that took this many GMRES iterations more
# than the fewest predictor solve since its build (measured, doc/lubrication.md "Solves that remember").
LUBRICATION_WEAR_ITERATIONS = 1


class KeptSolves:
    """What the lubrication solves of a run keep from solve to solve and step to step (``preconditioner auto``).

    * The preconditioners, built at one configuration and used at the next ones until they wear: the published
      ``(R_sup + s I)^-1 R_MB`` of :class:`lubrication.LubricationProblem` and the torque problem's
      :func:`torque_preconditioner`.  Any invertible preconditioner gives the same solution within the
      tolerance; one built nearby costs no sparse LU.  A predictor solve (every step's first solve of the
      velocities) that takes ``LUBRICATION_WEAR_ITERATIONS`` more GMRES iterations than the fewest predictor solve
      since the build ends them: the next solve builds new ones at its configuration.
    * First guesses: the corrector starts from the predictor's velocities; a torque solve from the last torque
      solve's solution; at kT = 0 the predictor from the last corrector's velocities.

    built_at : (locations (N, 3), orientations (N, 4)) where the preconditioners were built, or None (none kept);
    solves, fewest : predictor solves they served and their fewest GMRES iterations (None: none yet);
    velocity_guess : (6N,) the last corrector's velocities (kT = 0 only) or None;
    torque_guess : (6N,) the last torque solve's unknowns ``[V T]`` or None.
    These are what the run state saves (``RunState.preconditioner_configuration``, ``preconditioner_solves``,
    ``preconditioner_fewest``, ``first_guess``, ``roller_torque_guess``); the objects are a cache
    (``built``), built again at ``built_at`` after a restart, so a restart repeats the run bit for bit.
    """

    def __init__(self, settings, tolerance, built_at=None, solves=None, fewest=None, built=None,
                 velocity_guess=None, torque_guess=None):
        self.settings, self.tolerance = settings, float(tolerance)
        self.built_at, self.solves, self.fewest = built_at, solves, fewest
        self.built = dict(built) if built else {}
        self.velocity_guess, self.torque_guess = velocity_guess, torque_guess

    def _built(self, name, problem, orientations, counts, start):
        """The kept preconditioner ``name`` ('velocities' or 'torques'), built where the kept ones are; when none
        are kept, built at ``problem`` and kept if ``start`` (a step's start configuration, an accepted one),
        else built for this solve alone (the corrector's predicted configuration is never kept: one gap there
        closed too far would slow every later solve)."""
        if self.built_at is None and not start:
            return self._build(name, problem.matrices, counts)
        if self.built_at is None:
            self.built_at = (problem.locations.copy(), np.array(orientations, dtype=float))
            self.built, self.solves, self.fewest = {'matrices': problem.matrices}, 0, None
        elif 'matrices' not in self.built:  # a restart: assembled again where they were built
            self.built['matrices'] = self.settings.matrices(self.built_at[0])
            counts['assemblies'] += 1
        if name not in self.built:
            self.built[name] = self._build(name, self.built['matrices'], counts)
        return self.built[name]

    def _build(self, name, matrices, counts):
        """The preconditioner ``name`` from the near-field ``matrices`` of some configuration, counted."""
        if name == 'torques':
            built = torque_preconditioner(matrices.Delta_R, self.settings.eta, self.settings.a)
        else:
            built = LubricationPreconditioner(matrices, self.settings.shift(self.tolerance))
        counts['factorisations'] += name == 'torques' or built.factor is not None
        return built

    def preconditioner(self, problem, orientations, counts, start=True):
        """The kept :class:`lubrication.problem.LubricationPreconditioner` (see :meth:`_built`)."""
        return self._built('velocities', problem, orientations, counts, start)

    def torque_preconditioner(self, problem, orientations, counts, start=True):
        """The kept :func:`torque_preconditioner` (see :meth:`_built`)."""
        return self._built('torques', problem, orientations, counts, start)

    def served(self, iterations):
        """Count a predictor solve of ``iterations`` GMRES iterations; a worn one ends the kept preconditioners."""
        fewest = kept_fewest(self.fewest, iterations, LUBRICATION_WEAR_ITERATIONS)
        if fewest is None:
            self.built_at, self.built, self.solves, self.fewest = None, {}, None, None
            return
        self.solves, self.fewest = self.solves + 1, fewest


def _first_guess(guess, rhs):
    """The solution ``guess`` of ``A x = rhs`` as a first guess of the normalised system (None: zeros)."""
    norm = float(np.linalg.norm(rhs))
    return None if guess is None or norm == 0.0 else np.asarray(guess, dtype=float).reshape(-1) / norm


def _solve(solver, problem, rhs, tolerance, counts, kept=None, orientations=None, guess=None, predictor=False):
    """Velocities (N, 6) of ``problem`` for ``rhs`` by ``solver``, from the first guess ``guess`` (velocities or
    None: zeros): with ``kept`` None the published solve (a preconditioner built here; the published corrector
    starts from the predictor's velocities, the other solves from zero); else the kept preconditioner and the
    solver's iterate (the least true residual under ``preconditioner auto``); a ``predictor`` solve (at a step's
    start) may build the kept preconditioner and counts towards its wear."""
    if kept is None:
        preconditioner = problem.preconditioner(tolerance)
        counts['factorisations'] += preconditioner.factor is not None
        result = solver.solve(problem, rhs, preconditioner, x0=_first_guess(guess, rhs), tolerance=tolerance,
                              kind='lubrication', what='the lubrication problem')
    else:
        result = solver.solve(problem, rhs, kept.preconditioner(problem, orientations, counts, start=predictor),
                              x0=_first_guess(guess, rhs), tolerance=tolerance, kind='lubrication',
                              what='the lubrication problem')
        if predictor:
            kept.served(result.iterations)
    counts['gmres_iterations'] += result.iterations
    return result.velocities


def omega_vectors(omega, n):
    """Prescribed angular velocities (N, 3): a number ``w`` means ``w y_hat`` for every sphere (the published
    rollers), else an array (3,) or (N, 3)."""
    omega_array = np.asarray(omega, dtype=float)
    if omega_array.ndim == 0:
        return np.tile([0.0, float(omega_array), 0.0], (n, 1))
    return np.broadcast_to(omega_array, (n, 3)).astype(float)


class TorqueFromOmegaProblem(LinearProblem):
    """Unknowns ``x = [V_i, T_i]`` (N, 6): translational velocities and torques, given forces F and angular
    velocities Omega.  From ``(I + M Delta_R) [V; Omega] = M [F; T]``:
    ``[V; 0] + M Delta_R [V; 0] - M [0; T] = M [F; 0] - [0; Omega] - M Delta_R [0; Omega]``.
    Preconditioner: M replaced by the isolated sphere's ``1/(6 pi eta a)``, ``1/(8 pi eta a^3)``, which
    gives ``V = 6 pi eta a (6 pi eta a I + Delta_R_tt)^-1 r_t`` (one sparse factorisation, as published) and then
    T."""

    def __init__(self, problem, eta, a):
        self.problem, self.size, self.num_bodies = problem, problem.size, problem.num_bodies
        self.eta, self.a = eta, a

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
        """The preconditioner (a LinearOperator) at this problem's configuration (:func:`torque_preconditioner`)."""
        return torque_preconditioner(self.problem.Delta_R, self.eta, self.a)


def torque_preconditioner(Delta_R, eta, a):
    """The preconditioner of :class:`TorqueFromOmegaProblem` from the near field ``Delta_R`` (6N, 6N) of some
    configuration: M replaced by the isolated sphere's mobilities, one sparse factorisation of
    ``6 pi eta a I + Delta_R_tt`` (as published; :func:`lubrication.sparse_factor.factorise`, 3 x 3 blocks).
    A ``linear_map.FunctionMap`` (6N, 6N)."""
    size = Delta_R.shape[0]
    trans = (np.arange(size // 6)[:, None] * 6 + np.arange(3)).reshape(-1)
    rot = trans + 3
    friction = 6.0 * np.pi * eta * a
    rotational_mobility = 1.0 / (8.0 * np.pi * eta * a ** 3)
    Delta_R = Delta_R.tocsr()
    factor = sparse_factor.factorise(Delta_R[trans][:, trans], friction, block=3)
    coupling = Delta_R[rot][:, trans]

    def apply(r):
        r = np.asarray(r, dtype=float).reshape(-1)
        out = np.empty_like(r)
        velocity = friction * factor.solve(r[trans])
        out[trans] = velocity
        out[rot] = coupling @ velocity - r[rot] / rotational_mobility
        return out
    return FunctionMap(size, apply)


def torque_from_omega(problem, forces, omega, tolerance=None, torque_cap=None, counts=None, kept=None,
                      orientations=None, start=True, solver=None):
    """Torques (N, 3) that hold the angular velocities ``omega`` of spheres under ``forces`` (N, 3).

    problem : :class:`lubrication.LubricationProblem` at the configuration; omega : see :func:`omega_vectors`;
    torque_cap : None or a number, the largest torque magnitude per sphere (larger ones are scaled down
    to it, keeping their direction: those spheres then turn slower than omega); kept : a :class:`KeptSolves`
    (its preconditioner and its last torque solution as first guess, which this solve replaces) or None (the
    published solve: a preconditioner built here, from zero); orientations (N, 4) with ``kept``; start : the
    configuration is a step's start (where ``kept`` may build the preconditioner it keeps); solver, tolerance : see
    the module note.
    """
    solver, tolerance = solver_and_tolerance(solver, tolerance, minimal_residual=kept is not None)
    counts = new_counts() if counts is None else counts
    torque_problem = TorqueFromOmegaProblem(problem, problem.eta, problem.a)
    omega = omega_vectors(omega, problem.num_bodies)
    rhs = torque_problem.rhs(np.asarray(forces, dtype=float).reshape(-1, 3), omega)
    if kept is None:
        result = solver.solve(torque_problem, rhs, torque_problem.preconditioner(), tolerance=tolerance,
                              kind='lubrication', what='the torques of the prescribed rotation')
        counts['factorisations'] += 1
    else:
        result = solver.solve(torque_problem, rhs, kept.torque_preconditioner(problem, orientations, counts, start),
                              x0=_first_guess(kept.torque_guess, rhs), tolerance=tolerance, kind='lubrication',
                              what='the torques of the prescribed rotation')
        kept.torque_guess = result.velocities.reshape(-1).copy()
    counts['gmres_iterations'] += result.iterations
    torques = result.velocities[:, 3:].copy()
    if torque_cap is not None:
        size = np.linalg.norm(torques, axis=1)
        scale = np.where(size > torque_cap, torque_cap / np.where(size > 0, size, 1.0), 1.0)
        torques *= scale[:, None]
    return torques


def _forces(solver, force_torque_at, problem, locations, orientations, omega, tolerance, torque_cap, counts, kept,
            start=True):
    force_torque = np.array(force_torque_at(locations, orientations), dtype=float).reshape(-1, 6)
    torques = None
    if omega is not None:
        torques = torque_from_omega(problem, force_torque[:, :3], omega, tolerance, torque_cap, counts, kept,
                                    orientations, start, solver=solver)
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


def _step_start(solver, settings, locations, orientations, force_torque_at, kT, dt, rng, tolerance, omega, torque_cap,
                matrices, kept):
    """What every step computes first at the start configuration: (counts, locations (N, 3), orientations (N, 4),
    the problem there, force_torque (N, 6), torques (or None), the Brownian increment (6N,))."""
    counts = new_counts()
    locations = np.asarray(locations, dtype=float).reshape(-1, 3)
    orientations = np.asarray(orientations, dtype=float).reshape(-1, 4)
    problem = counted_problem(settings, locations, counts, matrices)
    force_torque, torques = _forces(solver, force_torque_at, problem, locations, orientations, omega, tolerance,
                                    torque_cap, counts, kept)
    noise = _noise(settings, problem, kT, dt, rng, tolerance, counts)
    return counts, locations, orientations, problem, force_torque, torques, noise


def trapezoidal_step(settings, locations, orientations, force_torque_at, kT, dt, rng, tolerance=None, omega=None,
                     torque_cap=None, matrices=None, rfd=True, kept=None, solver=None):
    """One step of the published stochastic trapezoidal scheme (module note): a :data:`StepResult`.

    settings : :class:`lubrication.brownian.LubricationSettings`; locations (N, 3), orientations (N, 4);
    force_torque_at : callable (locations, orientations) -> (N, 6); kT, dt; rng (module note);
    omega, torque_cap : prescribed rotation (see :func:`torque_from_omega`; the torques are recomputed at
    the predictor's configuration for the corrector); matrices : the near-field matrices at ``locations``
    if already built; rfd : False leaves out the far-field drift term ``D_M`` (a negative control: the
    equilibrium is then wrong); kept : a :class:`KeptSolves` (the solves keep their preconditioners and start
    from first guesses, which it updates) or None (the published solves); solver, tolerance : see the module note.
    """
    solver, tolerance = solver_and_tolerance(solver, tolerance, minimal_residual=kept is not None)
    counts, locations, orientations, problem, force_torque, torques, noise = _step_start(
        solver, settings, locations, orientations, force_torque_at, kT, dt, rng, tolerance, omega, torque_cap,
        matrices, kept)
    guess = kept.velocity_guess if kept is not None and kT <= 0 else None
    predictor = _solve(solver, problem, noise + problem.mobility_product(force_torque.reshape(-1)), tolerance, counts,
                       kept, orientations, guess, predictor=True)
    mid_locations, mid_orientations = _moved(locations, orientations, predictor, dt)
    wall, jump = _rejection(settings, locations, mid_locations)
    if settings.wall and np.any(mid_locations[:, 2] <= 0.0):
        return StepResult(locations, orientations, 1, 0, predictor, torques, counts)
    drift = np.zeros(problem.size)
    if kT > 0 and rfd:
        drift = 2.0 * far_field_drift(settings, locations, rng.standard_normal(problem.size), kT).reshape(-1)
        counts['far_field_products'] += 2
    mid_problem = counted_problem(settings, mid_locations, counts)
    mid_force_torque, mid_torques = _forces(solver, force_torque_at, mid_problem, mid_locations, mid_orientations,
                                            omega, tolerance, torque_cap, counts, kept, start=False)
    corrector = _solve(solver, mid_problem, drift + noise + mid_problem.mobility_product(mid_force_torque.reshape(-1)),
                       tolerance, counts, kept, mid_orientations, predictor)
    if kept is not None:
        kept.velocity_guess = corrector.reshape(-1).copy() if kT <= 0 else None
    velocities = 0.5 * (predictor + corrector)
    if torques is not None:
        torques = 0.5 * (torques + mid_torques)
    new_locations, new_orientations = _moved(locations, orientations, velocities, dt)
    wall, jump = _rejection(settings, locations, new_locations)
    if wall or jump:
        return StepResult(locations, orientations, wall, jump, velocities, torques, counts)
    return StepResult(new_locations, new_orientations, 0, 0, velocities, torques, counts)


def euler_maruyama_step(settings, locations, orientations, force_torque_at, kT, dt, rng, tolerance=None,
                        omega=None, torque_cap=None, matrices=None, kept=None, solver=None):
    """One Euler-Maruyama step ``q + dt (M_lub F + U_B + kT div M_lub)`` (RFD drift): a :data:`StepResult`.

    kept : a :class:`KeptSolves` or None, as for :func:`trapezoidal_step` (its preconditioner serves the drift's
    solves too; at kT = 0 the solve starts from the last step's velocities); solver, tolerance : see the module
    note."""
    solver, tolerance = solver_and_tolerance(solver, tolerance, minimal_residual=kept is not None)
    counts, locations, orientations, problem, force_torque, torques, noise = _step_start(
        solver, settings, locations, orientations, force_torque_at, kT, dt, rng, tolerance, omega, torque_cap,
        matrices, kept)
    guess = kept.velocity_guess if kept is not None and kT <= 0 else None
    velocities = _solve(solver, problem, noise + problem.mobility_product(force_torque.reshape(-1)), tolerance, counts,
                        kept, orientations, guess, predictor=True)
    if kept is not None:
        kept.velocity_guess = velocities.reshape(-1).copy() if kT <= 0 else None
    if kT > 0:
        preconditioner = None if kept is None else kept.preconditioner(problem, orientations, counts)
        velocities = velocities + thermal_drift(settings, locations, rng.standard_normal(problem.size), kT,
                                                tolerance, problem, preconditioner, solver=solver)
        counts['assemblies'] += 2
    new_locations, new_orientations = _moved(locations, orientations, velocities, dt)
    wall, jump = _rejection(settings, locations, new_locations)
    if wall or jump:
        return StepResult(locations, orientations, wall, jump, velocities, torques, counts)
    return StepResult(new_locations, new_orientations, 0, 0, velocities, torques, counts)


def rpb_step(settings, locations, orientations, force_torque_at, kT, dt, rng, tolerance=None):
    """The baseline without lubrication: ``q + dt (M F + sqrt(2kT/dt) M^1/2 W + kT div M)``, M the far field
    (Lanczos noise, RFD drift at the relative ``tolerance``, None: the option table's ``solver_tolerance``); same
    rejection rules: a :data:`StepResult`."""
    _, tolerance = solver_and_tolerance(None, tolerance)
    counts = new_counts()
    locations = np.asarray(locations, dtype=float).reshape(-1, 3)
    orientations = np.asarray(orientations, dtype=float).reshape(-1, 4)
    product = far_field_product(locations, settings.far_field())
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
