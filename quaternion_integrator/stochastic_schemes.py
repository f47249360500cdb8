"""Brownian time-stepping schemes of the manual (SPEC §5.1 and §5.2), floor 5; the rollers' in roller_schemes.py.

Each scheme integrates the overdamped Langevin equation of rigid bodies
above a wall (Delong, Balboa Usabiaga and Donev, J. Chem. Phys. 143, 144107,
2015; Sprinkle, Balboa Usabiaga, Patankar and Donev, J. Chem. Phys. 147,
244103, 2017; rollers: Balboa Usabiaga et al., J. Chem. Phys. 146, 134104,
2017)::

    dq = N F dt + kT (div_q N) dt + sqrt(2 kT) N^{1/2} dW

(for active bodies the slip adds ``-N K^T M^{-1} slip``).  The schemes
differ in how the noise ``N^{1/2} W`` and the thermal drift ``kT div N`` are
produced: by Lanczos on the blob mobility and random finite differences
(iterative schemes), or by dense algebra (``*_dense_algebra``, ``Fixman``,
``*_DLA``).

A scheme is made by ``make_scheme(name, dt, options)``;
``scheme.advance(context, state, configuration)`` returns the next
configuration, the velocities used and the history (``scheme.step`` makes
the next run state of them).  Predictors and
midpoints are configurations of their own (``body.body.Configuration``
values): forces, slip and solves are evaluated at them without touching the
step's start.  The random numbers come only from the step's
generator ``context.rng``, through its ``standard_normal(n)`` (the one draw
of every scheme): numpy's
``Generator`` or the published code's legacy ``RandomState``
(:class:`stochastic_forcing.generators.PublishedGenerator`, which repeats
a published run's numbers), drawn in a fixed order stated in each scheme,
so a run is a function of its input and its generator state.  Random finite
differences go through :func:`stochastic_forcing.rfd` with the rigid-body
displacement :func:`quaternion_integrator.scheme_base.displace_bodies` (or
:func:`stochastic_forcing.displace_positions` for rollers).

Invalid configurations: a step (or predictor, or midpoint) that puts a blob
centre below the wall is rejected, the rejection counted and printed, and
the step retried from the same start with fresh noise.  More than
``max_consecutive_rejections`` rejections in a row stop the run with a
message naming the step and the bodies.

Shapes: body velocities (Nb, 6) ``[v, w]``; locations (Nb, 3); quaternions
(Nb, 4); blob vectors flat (3N,) or (N, 3); roller velocities (N, 3).
"""
from dataclasses import replace

import numpy as np

from body.body import Configuration
from multi_bodies.files.input_options import check_value, options_with
from multi_bodies.solver.body_solver import DenseMobilityProblem
from quaternion_integrator.scheme_base import Scheme, displace_bodies
from stochastic_forcing import rfd, symmetric_root_matrix
from utils import SimulationStopped, UserInputError

MAX_CONSECUTIVE_REJECTIONS = 100


class TooManyRejections(SimulationStopped):
    """Too many invalid configurations in a row."""

    def __init__(self, step, bodies, scheme, count):
        self.step, self.bodies = step, [int(b) for b in bodies]
        shown = ', '.join(str(b) for b in self.bodies[:10]) + (' ...' if len(self.bodies) > 10 else '')
        super().__init__('step %d of %s: %d trial configurations in a row put a blob centre below the wall '
                         '(last: body %s); lower dt, or strengthen the wall repulsion (repulsion_strength_wall, '
                         'debye_length_wall)' % (step, scheme, count, shown))


class _Rejected(Exception):
    """Internal: the trial configuration of an attempt is invalid; ``bodies`` are the culprits, ``state`` the step's
    history when it was found (the next attempt continues from it: its solves' guesses and preconditioner)."""

    def __init__(self, bodies, state):
        super().__init__()
        self.bodies, self.state = bodies, state


class StochasticScheme(Scheme):
    """Common machinery: parameters, retry loop, cached preconditioner, RFD drift, history for restarts.

    Parameters (from the input options): ``kT``, ``rf_delta`` (delta of the
    random finite differences), ``update_PC`` (rebuild the preconditioner
    every ``update_PC`` steps, SPEC §4.3).
    """
    pair_products = True  # share passes over the blob pairs between independent products (C++ backend)
    # GMRES solves a step makes with the step's preconditioner (at least two in every scheme here: the noise or
    # RFD solves and the deterministic one); ``preconditioner auto`` weighs the neighbour correction's build
    # against them
    solves_at_preconditioner = 2
    # A solve whose right-hand side holds this step's Brownian slip starts from zero, not from the last solution:
    # the noise, sqrt(2 kT / dt) M^{1/2} W with a fresh W, dominates the right-hand side, so the last solution
    # is a worse start than zero (100 boomerangs, Slip_Trapz: |b - A x0| = 1.25 |b|) and its residual costs
    # a product.  Iterates differ from a warm start only within solver_tolerance.
    cold_start_fresh_noise = True
    thermal_drift = True  # False switches every drift term off (a negative control for the tests; wrong physics)

    def __init__(self, dt, options=None):
        """options : the validated input ``Options`` (None: the option table's defaults, ``options_with()``)."""
        super().__init__(dt)
        options = options_with() if options is None else options
        self.kT = float(options.kT)
        self.delta = float(options.rf_delta)
        self.update_PC = int(options.update_PC)
        # The ranges are the option table's (declared once); checked here too for schemes made directly.
        for name, value in (('kT', self.kT), ('rf_delta', self.delta), ('update_PC', self.update_PC)):
            check_value(name, value, options.where(name))
        # relative tolerance of the noise and RFD sub-solves and of Lanczos (None: solver_tolerance); a speed
        # option, off by default (doc/dynamics.md, speed options)
        self.noise_tolerance = options.noise_solver_tolerance
        if self.noise_tolerance is not None:
            self.noise_tolerance = float(self.noise_tolerance)
            check_value('noise_solver_tolerance', self.noise_tolerance, options.where('noise_solver_tolerance'))
        self.max_consecutive_rejections = MAX_CONSECUTIVE_REJECTIONS

    # -------------------------------------------------------------- helpers
    def problem_at(self, context, configuration):
        """The mobility problem at ``configuration`` that the step's solves, products and noise use
        (``Model.mobility_problem``; a dense twin's: :class:`DenseTwin`)."""
        return context.model.mobility_problem(configuration)

    def preconditioner_at(self, context, configuration):
        """A preconditioner built at ``configuration`` for one solve (``Model.build_preconditioner``)."""
        return context.model.build_preconditioner(configuration)

    def preconditioner(self, context, state, problem):
        """(the block-diagonal preconditioner, state): rebuilt at ``problem`` every ``update_PC`` steps (kept in
        the run state with the step and configuration it was built at).  It serves ``solves_at_preconditioner``
        solves a step for ``update_PC`` steps, which ``preconditioner auto`` weighs its build against."""
        step_index = context.step
        rebuild = state.preconditioner_step is None or (
            step_index % self.update_PC == 0 and state.preconditioner_step != step_index)
        solves = self.solves_at_preconditioner * self.update_PC
        if rebuild:
            state = replace(state, preconditioner=context.model.build_preconditioner(problem.configuration,
                                                                                     solves=solves),
                            preconditioner_step=step_index, preconditioner_configuration=problem.configuration)
        elif state.preconditioner is None:  # after a restart: the configuration it was built at
            state = replace(state, preconditioner=context.model.build_preconditioner(
                state.preconditioner_configuration, solves=solves))
        return state.preconditioner, state

    @staticmethod
    def body_lengths(context):
        """The bodies' length scales (Nb,), structure the model holds (``Model.body_lengths``)."""
        return context.model.body_lengths

    def check(self, context, state, configuration):
        """Raise _Rejected (with the step's history ``state``) when ``configuration`` has a blob centre below the
        wall."""
        invalid = context.model.invalid_bodies(configuration)
        if invalid.size:
            raise _Rejected(invalid, state)

    def noise_solve(self, context, problem, preconditioner, noise_slip=None, noise_force=None, rhs=None):
        """A counted noise or RFD solve (no warm start); returns body_solver.SolveResult."""
        if rhs is None:
            rhs = problem.rhs(noise_slip=noise_slip, noise_force=noise_force)
        result = context.solve(problem, rhs, preconditioner, kind='stochastic', tolerance=self.noise_tolerance)
        # bodies of prescribed kinematics are not moved by noise or RFD solves
        return result._replace(velocities=problem.without_prescribed_motion(result.velocities))

    def lanczos_noise(self, context, problem, z, factor, preconditioner):
        """``factor M^{1/2} z`` at ``problem`` (Model.lanczos_noise, counted) at the scheme's ``noise_tolerance``."""
        return context.lanczos_noise(problem, z, factor, preconditioner, tolerance=self.noise_tolerance)

    def rfd_drift(self, context, configuration, W, preconditioner):
        """``kT/delta [N(q + delta/2 W) - N(q - delta/2 W)] W~`` by two solves (SPEC §5.1, first-order RFD).

        W (Nb, 6) ~ N(0, 1); translations are displaced by ``delta * body_length * W_t``
        and ``W~`` has the translational part divided by the body length.
        The second solve is for the difference (right-hand side
        ``b - A+ y-``), so the solver tolerance applies to the drift itself.
        Returns (Nb, 6).
        """
        lengths = self.body_lengths(context)
        W = np.asarray(W, dtype=float).reshape(-1, 6)
        if not self.thermal_drift:
            return np.zeros_like(W)
        W_tilde = W.copy()
        W_tilde[:, :3] /= lengths[:, None]

        def difference(q_plus, q_minus):
            minus, plus = self.problem_at(context, q_minus), self.problem_at(context, q_plus)
            y_minus = self.noise_solve(context, minus, preconditioner, noise_force=W_tilde)
            x_minus = np.concatenate((y_minus.lambda_blobs.reshape(-1), y_minus.velocities.reshape(-1)))
            rhs = minus.rhs(force_torque=W_tilde) - plus.matvec(x_minus)
            return self.noise_solve(context, plus, preconditioner, rhs=rhs).velocities

        def displace(q, scale, direction):
            return displace_bodies(q, scale, direction, lengths)
        return self.kT * rfd(None, configuration, W, self.delta, displace, difference=difference)

    def slip_rfd(self, context, configuration, problem, W_s, preconditioner, factor, W_R=None, at_configuration=None):
        """Drift terms of the slip schemes (Sprinkle et al. 2017): extra slip (3N,) and force (Nb, 6).

        ``W_R = N K^T M^{-1} W_s`` by one solve (right-hand side ``[-W_s; 0]``); at the configuration moved
        by ``delta W_R`` (no body-length scaling) the slip is ``factor delta (M' W_s - M W_s) / delta`` and
        the force ``-factor delta (K'^T W_s - K^T W_s) / delta``, with ``factor = 2 kT / delta``
        (trapezoidal) or ``kT / delta`` (midpoint).  Zero when ``thermal_drift`` is off.
        ``W_R`` (Nb, 6): the solve's velocities when the caller made it (``slip_rfd_solve``);
        ``at_configuration``: ``(M W_s, K^T W_s)`` at ``problem`` when the caller has them
        (:meth:`slip_rfd_products_at`).
        """
        if W_R is None:
            W_R = self.slip_rfd_solve(context, problem, W_s, preconditioner)
        if at_configuration is None:
            at_configuration = self.slip_rfd_products_at(problem, W_s)

        def products(q):
            moved = self.problem_at(context, q)
            return moved.M_dot(W_s), moved.KT_dot(W_s)
        D_M, D_KT = rfd(products, configuration, W_R, self.delta, displace_bodies, centred=False,
                        at_configuration=at_configuration)
        scale = factor * self.delta if self.thermal_drift else 0.0
        return scale * D_M, -scale * D_KT

    @staticmethod
    def slip_rfd_products_at(problem, W_s):
        """``(M W_s (3N,), K^T W_s (Nb, 6))`` at ``problem``: the unmoved end of the slip RFD."""
        return problem.M_dot(W_s), problem.KT_dot(W_s)

    def slip_rfd_solve(self, context, problem, W_s, preconditioner):
        """``W_R = N K^T M^{-1} W_s`` (Nb, 6) by one noise solve (right-hand side ``[-W_s; 0]``)."""
        return self.noise_solve(context, problem, preconditioner,
                                rhs=np.concatenate((-W_s, np.zeros(6 * context.num_bodies)))).velocities

    def side_by_side(self, context, problem, first, second):
        """``(first(problem), second(problem))`` for two computations at one configuration that do not
        depend on each other (each a callable of a problem).

        With a paired product (``Model.paired_mobility_product``, the C++ backend) they run side by side
        in two threads and share each pass over the blob pairs (one product of two vectors instead of
        two: the problem's mobility wrapped in ``model.PairedProducts``); otherwise one after the other.
        The same numbers either way, to rounding; ``pair_products = False`` switches the pairing off.
        """
        paired = context.model.paired_mobility_product if self.pair_products else None
        if paired is None or not hasattr(problem, 'with_mobility'):
            return first(problem), second(problem)
        from concurrent.futures import ThreadPoolExecutor
        from multi_bodies.solver.model import PairedProducts
        pairer = PairedProducts(problem.mobility)
        shared = problem.with_mobility(pairer)

        def run_first():
            try:
                return first(shared)
            finally:
                pairer.leave()
        with ThreadPoolExecutor(1) as pool:
            future = pool.submit(run_first)
            try:
                result = second(shared)
            finally:
                pairer.leave()
            return future.result(), result

    def corrector_velocities(self, context, state, old, velocities, dt, noise_slip, noise_force, preconditioner):
        """Velocities at ``old`` moved by ``velocities * dt`` (predictor or midpoint), solved there: (velocities
        (Nb, 6), state).

        The solve uses the forces and slip of the moved configuration, the given noise slip (3N,) and
        force (Nb, 6), the preconditioner (None: one built at the moved configuration) and the
        deterministic warm start.  Raises _Rejected when the moved configuration is invalid.
        """
        moved = self.move(old, velocities, dt)
        self.check(context, state, moved)
        (_, force_torque, slip), state = context.forces_and_slip(state, moved)
        problem = self.problem_at(context, moved)
        if preconditioner is None:
            preconditioner = self.preconditioner_at(context, moved)
        rhs = problem.rhs(slip=slip, force_torque=force_torque, noise_slip=noise_slip, noise_force=noise_force)
        result, state = self.deterministic_solve(context, state, problem, rhs, preconditioner)
        return result.velocities, state

    def noise_factor(self, dt_fraction=1.0):
        """``sqrt(2 kT / (dt_fraction dt))``."""
        return np.sqrt(2.0 * self.kT / (dt_fraction * self.dt))

    # -------------------------------------------------------------- the step
    def attempt(self, context, state, old):
        """One try of the step from the Configuration ``old``: (new Configuration, velocities used, state).

        Velocities (Nb, 6) (rollers (N, 3)).  Draws from ``context.rng``.  Raises _Rejected when a trial
        configuration is invalid.
        """
        raise NotImplementedError

    def advance(self, context, state, configuration):
        """One step from ``configuration``, retried with fresh noise while a trial configuration is invalid.

        Returns (the new Configuration, the velocities used, state).  A rejected attempt's history (its solves'
        guesses, the preconditioner built) carries on into the next one, except the multistep velocities, which
        only an accepted step keeps.
        """
        if context.rng is None:
            raise UserInputError('%s needs a random generator' % self.name)
        start = state
        rejections = 0
        while True:
            context.model.preprocess(configuration)
            try:
                new, used, state = self.attempt(context, state, configuration)
                if not np.all(np.isfinite(used)):
                    raise SimulationStopped('step %d of %s: the velocities are not finite (NaN or inf); check the '
                                            'forces (user-defined functions), the time step and the configuration'
                                            % (context.step, self.name))
                new = context.model.postprocess(new)
                self.check(context, state, new)
            except _Rejected as rejected:
                state = replace(rejected.state, previous_velocities=start.previous_velocities)
                context.count(invalid_configurations=1)
                rejections += 1
                print('Invalid configuration number %d (step %d, bodies %s)'
                      % (context.total(start, 'invalid_configurations'), context.step,
                         ', '.join(str(int(b)) for b in rejected.bodies[:5])))
                if rejections >= self.max_consecutive_rejections:
                    raise TooManyRejections(context.step, rejected.bodies, self.name, rejections)
                continue
            return new, used, state

    @staticmethod
    def multistep(state, current, noise_part):
        """(Adams-Bashforth combination, state keeping ``current`` as the next step's previous velocities): first
        step ``current + noise``, later ``1.5 current - 0.5 previous + noise``."""
        previous = state.previous_velocities
        state = replace(state, previous_velocities=np.array(current, copy=True))
        if previous is None:
            return current + noise_part, state
        return 1.5 * current - 0.5 * previous + noise_part, state

    def deterministic_part(self, context, state, problem, old, preconditioner, noise_slip=None, noise_force=None,
                           fresh_noise=False):
        """The solve at ``old`` of its forces and slip plus the given noise terms: (velocities (Nb, 6), state).

        Warm started from the last deterministic solve, except with ``fresh_noise`` (the right-hand side holds
        this step's Brownian slip, which the last solution knows nothing of): then from zero, see
        :attr:`cold_start_fresh_noise`.
        """
        (_, force_torque, slip), state = context.forces_and_slip(state, old)
        rhs = problem.rhs(slip=slip, force_torque=force_torque, noise_slip=noise_slip, noise_force=noise_force)
        warm = not (fresh_noise and self.cold_start_fresh_noise)
        result, state = self.deterministic_solve(context, state, problem, rhs, preconditioner, warm_start=warm)
        return result.velocities, state


# ====================================================================== rigid multiblob, iterative
class StochasticFirstOrderRFD(StochasticScheme):
    """Euler-Maruyama with Lanczos noise and a two-solve RFD drift (three solves, one Lanczos per step).

    Draws: W_rfd (6 Nb), then z (3N).
    """
    name = 'stochastic_first_order_RFD'

    def attempt(self, context, state, old):
        rng = context.rng
        W_rfd = rng.standard_normal(6 * context.num_bodies)
        z = rng.standard_normal(3 * context.num_blobs)
        problem = self.problem_at(context, old)
        pc, state = self.preconditioner(context, state, problem)
        noise = self.lanczos_noise(context, problem, z, self.noise_factor(), pc)
        U, state = self.deterministic_part(context, state, problem, old, pc, noise_slip=noise, fresh_noise=True)
        U = U + self.rfd_drift(context, old, W_rfd, pc)
        return self.move(old, U, self.dt), U, state


class StochasticAdamsBashforth(StochasticScheme):
    """Adams-Bashforth for the deterministic velocity plus Euler-Maruyama noise and RFD drift.

    Draws: W_rfd (6 Nb), then z (3N).
    """
    name = 'stochastic_adams_bashforth'

    def attempt(self, context, state, old):
        rng = context.rng
        W_rfd = rng.standard_normal(6 * context.num_bodies)
        z = rng.standard_normal(3 * context.num_blobs)
        problem = self.problem_at(context, old)
        pc, state = self.preconditioner(context, state, problem)
        noise, (U_d, state) = self.side_by_side(
            context, problem, lambda shared: self.lanczos_noise(context, shared, z, self.noise_factor(), pc),
            lambda shared: self.deterministic_part(context, state, shared, old, pc))
        U_s = self.noise_solve(context, problem, pc, noise_slip=noise).velocities
        U_s = U_s + self.rfd_drift(context, old, W_rfd, pc)
        U, state = self.multistep(state, U_d, U_s)
        return self.move(old, U, self.dt), U, state


class StochasticTractionEM(StochasticScheme):
    """Traction Euler-Maruyama (Sprinkle et al. 2017): RFD on the traction, two solves and one Lanczos.

    Draws: W_rfd (6 Nb), then z (3N).
    """
    name = 'stochastic_traction_EM'

    def traction_terms(self, context, state, old):
        """(problem, preconditioner, noise slip, drift slip, drift force, state) of the traction schemes at ``old``."""
        rng = context.rng
        W_rfd = rng.standard_normal(6 * context.num_bodies).reshape(-1, 6)
        lengths = self.body_lengths(context)
        W_s = np.concatenate((W_rfd[:, :3] * (self.kT / lengths[:, None]), W_rfd[:, 3:] * self.kT), axis=1)
        problem = self.problem_at(context, old)
        pc, state = self.preconditioner(context, state, problem)
        z = rng.standard_normal(3 * context.num_blobs)  # drawn after W_rfd, as before
        noise, R = self.side_by_side(context, problem,
                                     lambda shared: self.lanczos_noise(context, shared, z, self.noise_factor(), pc),
                                     lambda shared: self.noise_solve(context, shared, pc,
                                                                     rhs=shared.rhs(force_torque=W_s)))
        lam, U_R = R.lambda_blobs.reshape(-1), R.velocities

        def products(q):
            moved = self.problem_at(context, q)
            return moved.M_dot(lam), moved.KT_dot(lam), moved.K_dot(U_R).reshape(-1)

        def displace(q, scale, direction):
            return displace_bodies(q, scale, direction, lengths)
        D_M, D_KT, D_K = rfd(products, old, W_rfd, self.delta, displace, centred=False,
                             at_configuration=products_at(problem, lam, U_R))
        if not self.thermal_drift:
            return problem, pc, noise, np.zeros_like(D_M), np.zeros_like(D_KT), state
        return problem, pc, noise, D_M - D_K, -D_KT, state

    def attempt(self, context, state, old):
        problem, pc, noise, drift_slip, drift_force, state = self.traction_terms(context, state, old)
        U, state = self.deterministic_part(context, state, problem, old, pc, noise_slip=noise + drift_slip,
                                           noise_force=drift_force, fresh_noise=True)
        return self.move(old, U, self.dt), U, state


def products_at(problem, lam, U_R):
    """``(M lam, K^T lam, K U_R)`` at ``problem`` (the unmoved side of the traction schemes' RFD)."""
    return problem.M_dot(lam), problem.KT_dot(lam), problem.K_dot(U_R).reshape(-1)


class StochasticTractionAB(StochasticTractionEM):
    """Traction scheme with Adams-Bashforth for the deterministic part (untested in the published code).

    Draws: W_rfd (6 Nb), then z (3N).
    """
    name = 'stochastic_traction_AB'

    def attempt(self, context, state, old):
        problem, pc, noise, drift_slip, drift_force, state = self.traction_terms(context, state, old)
        U_new, state = self.deterministic_part(context, state, problem, old, pc, noise_slip=drift_slip,
                                               noise_force=drift_force)
        U_n = self.noise_solve(context, problem, pc, noise_slip=noise).velocities
        U, state = self.multistep(state, U_new, U_n)
        return self.move(old, U, self.dt), U, state


class StochasticSlipTrapz(StochasticScheme):
    """Trapezoidal slip scheme (Sprinkle et al. 2017), the manual's recommendation for many bodies.

    Deterministically second order, weakly first order; three solves and one
    Lanczos call per step.  Draws: W1 (3N), then W_s (3N).  The predictor
    solve reuses the preconditioner built at q^n (``reuse_preconditioner``,
    default True; the published code rebuilt it at the predictor, which
    changes only the GMRES iterates, within the solver tolerance).
    """
    name = 'stochastic_Slip_Trapz'
    reuse_preconditioner = True
    solves_at_preconditioner = 3  # the slip RFD's, the predictor's and (reused) the corrector's

    def attempt(self, context, state, old):
        rng = context.rng
        n3 = 3 * context.num_blobs
        W1 = rng.standard_normal(n3)
        W_s = rng.standard_normal(n3)
        problem = self.problem_at(context, old)
        pc, state = self.preconditioner(context, state, problem)

        def rfd_solve_and_products(shared):  # W_R and the slip RFD's products at q, beside the Lanczos call
            return self.slip_rfd_solve(context, shared, W_s, pc), self.slip_rfd_products_at(shared, W_s)
        n1, (W_R, at_q) = self.side_by_side(
            context, problem, lambda shared: self.lanczos_noise(context, shared, W1, self.noise_factor(), pc),
            rfd_solve_and_products)
        drift_slip, drift_force = self.slip_rfd(context, old, problem, W_s, pc, 2.0 * self.kT / self.delta,
                                                W_R=W_R, at_configuration=at_q)
        U1, state = self.deterministic_part(context, state, problem, old, pc, noise_slip=n1, fresh_noise=True)
        U2, state = self.corrector_velocities(context, state, old, U1, self.dt, n1 + drift_slip, drift_force,
                                              pc if self.reuse_preconditioner else None)  # at the predictor
        U = 0.5 * (U1 + U2)
        return self.move(old, U, self.dt), U, state


class StochasticSlipMid(StochasticScheme):
    """Midpoint slip scheme (untested in the published code): three solves and two Lanczos calls.

    Draws: W1, W_s, W3 (3N each); W_c = W1 + W3.
    """
    name = 'stochastic_Slip_Mid'

    def attempt(self, context, state, old):
        rng = context.rng
        n3 = 3 * context.num_blobs
        W1 = rng.standard_normal(n3)
        W_s = rng.standard_normal(n3)
        W3 = rng.standard_normal(n3)
        problem = self.problem_at(context, old)
        pc, state = self.preconditioner(context, state, problem)

        def second_noise_and_rfd(shared):  # beside the first Lanczos call: the second one, W_R and M W_s at q
            return (self.lanczos_noise(context, shared, W1 + W3, np.sqrt(self.kT / self.dt), pc),
                    self.slip_rfd_solve(context, shared, W_s, pc), self.slip_rfd_products_at(shared, W_s))
        n1, (n_c, W_R, at_q) = self.side_by_side(
            context, problem,
            lambda shared: self.lanczos_noise(context, shared, W1, np.sqrt(4.0 * self.kT / self.dt), pc),
            second_noise_and_rfd)
        U_m, state = self.deterministic_part(context, state, problem, old, pc, noise_slip=n1, fresh_noise=True)
        drift_slip, drift_force = self.slip_rfd(context, old, problem, W_s, pc, self.kT / self.delta, W_R=W_R,
                                                at_configuration=at_q)
        U, state = self.corrector_velocities(context, state, old, U_m, 0.5 * self.dt, n_c + drift_slip, drift_force,
                                             pc)  # at the midpoint
        return self.move(old, U, self.dt), U, state


class StochasticEM(StochasticScheme):
    """Euler-Maruyama without a drift term: ``U = N F + sqrt(2 kT/dt) N K^T M^{-1} M^{1/2} W`` (as published).

    One Lanczos call (``M^{1/2} W`` at q^n) and one constrained solve per
    step.  It has no thermal drift, so it samples the Gibbs-Boltzmann
    distribution only where ``div_q N = 0`` (bodies far from any wall, e.g.
    ``mobility_vector_prod_implementation`` ``*_no_wall`` or periodic
    boxes); above a wall use ``stochastic_Slip_Trapz`` or
    ``stochastic_GDC_RFD``.  Draws: W (3N).
    """
    name = 'stochastic_EM'

    def attempt(self, context, state, old):
        W = context.rng.standard_normal(3 * context.num_blobs)
        problem = self.problem_at(context, old)
        pc, state = self.preconditioner(context, state, problem)
        noise = self.lanczos_noise(context, problem, W, self.noise_factor(), pc)
        U, state = self.deterministic_part(context, state, problem, old, pc, noise_slip=noise, fresh_noise=True)
        return self.move(old, U, self.dt), U, state


def rigid_projection(model, configuration, blob_velocities):
    """The unconstrained solve: ``(K^T K)^+ K^T v`` at ``configuration``, body velocities (Nb, 6).

    blob_velocities v (3N,) or (N, 3).  It is the solve of the saddle-point
    work ``[I -K; -K^T 0] [lambda; U] = [-v; 0]`` (the constrained one with
    the blob mobility replaced by the identity): the least-squares rigid
    motion of the blob velocities.  ``K^T K`` is block diagonal (one 6x6
    block per body, built from six products), so the cost is O(N); the
    pseudo-inverse handles single-blob bodies (no rotational block).
    """
    arrays = model.arrays
    nb = model.num_bodies
    r = arrays.blob_positions(configuration)
    gram = np.empty((nb, 6, 6))
    for k in range(6):
        unit = np.zeros((nb, 6))
        unit[:, k] = 1.0
        gram[:, :, k] = np.asarray(arrays.KT_dot(configuration, arrays.K_dot(configuration, unit, r), r)).reshape(nb, 6)
    scale = np.maximum(np.abs(gram).max(axis=(1, 2)), np.finfo(float).tiny)[:, None, None]
    inverse = np.linalg.pinv(gram / scale, rcond=1e-12) / scale
    rhs = np.asarray(arrays.KT_dot(configuration, np.asarray(blob_velocities, dtype=float).reshape(-1, 3), r))
    return np.einsum('bij,bj->bi', inverse, rhs.reshape(nb, 6))


class StochasticGDCRFD(StochasticScheme):
    """Generalised drifter-corrector (Sprinkle, Balboa Usabiaga, Patankar and Donev 2017, and the group's
    later roller work): one constrained solve, three Lanczos calls and two unconstrained solves per step.

    With ``B(q) = sqrt(2kT/dt) N K^T M^{-1} M^{1/2}`` (the noise of the
    constrained solve) and ``B~(q) = sqrt(2kT/dt) (K^T K)^+ K^T M^{1/2}``
    (the same blob noise projected on rigid motions, no hydrodynamic solve),
    one step with one W ~ N(0, I) (3N) is::

        U~   = B~(q^n) W                       Lanczos 1 at q^n, unconstrained solve 1
        div  = W_rfd . (B~(q^n + delta W_rfd) W - U~) / delta
                                               Lanczos 2 and unconstrained solve 2 at the RFD configuration
        q*   = q^n + U~ dt/2                   the drifter (predictor)
        U*   = N F(q*) + B(q*) W               Lanczos 3 at q*, the one constrained solve (at q*)
        q^{n+1} = q^n + U* dt (1 + div dt/2)

    (translations of the RFD displacement are scaled by the body length and
    the divergence divides them back).  Every Lanczos call uses the
    preconditioner of the step (built at q^n), so the three factors are one
    function ``M^{1/2}(q)``.  Why it is right: the noise covariance is
    ``B B^T = (2kT/dt) N``; expanding ``B(q*)`` about q^n gives the mean
    ``(dt/2) d_j B_ik B~_jk`` and the correction factor gives
    ``(dt/2) B_ik d_j B~_jk``; together ``(dt/2) d_j (B B~^T)_ij`` and
    ``B B~^T = (2kT/dt) N K^T M^{-1} M K (K^T K)^+ = (2kT/dt) N`` (``K^T K
    (K^T K)^+`` is the identity on the range of N), so the drift is exactly
    ``kT div N``: weakly first order with the right equilibrium.
    ``thermal_drift = False`` drops the correction factor (div = 0), which
    leaves the drift ``kT div N - kT B div B~`` (wrong; a negative control).
    Draws: W (3N), then W_rfd (6 Nb).
    """
    name = 'stochastic_GDC_RFD'

    def attempt(self, context, state, old):
        rng, model = context.rng, context.model
        W = rng.standard_normal(3 * context.num_blobs)
        W_rfd = rng.standard_normal(6 * context.num_bodies).reshape(-1, 6)
        problem = self.problem_at(context, old)
        pc, state = self.preconditioner(context, state, problem)
        factor = self.noise_factor()
        U_tilde = rigid_projection(model, old, self.lanczos_noise(context, problem, W, factor, pc))
        divergence = 0.0
        if self.thermal_drift and self.kT > 0:
            lengths = self.body_lengths(context)
            q_rfd = displace_bodies(old, self.delta, W_rfd, lengths)
            noise_rfd = self.lanczos_noise(context, self.problem_at(context, q_rfd), W, factor, pc)
            U_rfd = rigid_projection(model, q_rfd, noise_rfd)
            W_tilde = W_rfd.copy()
            W_tilde[:, :3] /= lengths[:, None]
            divergence = float(np.sum((U_rfd - U_tilde) * W_tilde)) / self.delta
        mid = self.move(old, U_tilde, 0.5 * self.dt)
        self.check(context, state, mid)
        problem_mid = self.problem_at(context, mid)
        noise_mid = self.lanczos_noise(context, problem_mid, W, factor, pc)
        U, state = self.deterministic_part(context, state, problem_mid, mid, pc, noise_slip=noise_mid, fresh_noise=True)
        U = U * (1.0 + 0.5 * self.dt * divergence)
        return self.move(old, U, self.dt), U, state


# ====================================================================== rigid multiblob, dense algebra
class DenseScheme(StochasticScheme):
    """Helpers of the dense-algebra schemes (cost O(N^3) per step; best for small systems)."""
    dense = True

    @staticmethod
    def dense_velocity(context, state, configuration, matrices):
        """(``N (F - K^T M^{-1} slip)`` at ``configuration`` with the given dense matrices (built there), state)."""
        M, M_inv, K, N = matrices
        (_, force_torque, slip), state = context.forces_and_slip(state, configuration)
        return (N @ (force_torque.reshape(-1) - K.T @ (M_inv @ slip.reshape(-1)))).reshape(-1, 6), state


class StochasticFirstOrderRFDDense(DenseScheme):
    """Euler-Maruyama with dense noise ``N^{1/2} z`` and a one-sided dense RFD drift.

    Draws: W_rfd (6 Nb), then z (6 Nb).
    """
    name = 'stochastic_first_order_RFD_dense_algebra'

    def attempt(self, context, state, old):
        rng, model = context.rng, context.model
        nb6 = 6 * context.num_bodies
        W_rfd = rng.standard_normal(nb6)
        z = rng.standard_normal(nb6)
        matrices = model.dense_matrices(old)
        N = matrices[3]
        U, state = self.dense_velocity(context, state, old, matrices)
        U = U.reshape(-1) + self.noise_factor() * (symmetric_root_matrix(N) @ z)
        lengths = self.body_lengths(context)
        W_tilde = W_rfd.reshape(-1, 6).copy()
        W_tilde[:, :3] /= lengths[:, None]
        W_tilde = W_tilde.reshape(-1)

        def displace(q, scale, direction):
            return displace_bodies(q, scale, direction, lengths)
        drift = rfd(lambda q: model.dense_matrices(q)[3] @ W_tilde, old, W_rfd, self.delta, displace,
                    centred=False, at_configuration=N @ W_tilde)
        c = self.kT if self.thermal_drift else 0.0
        U = (U + c * drift).reshape(-1, 6)
        return self.move(old, U, self.dt), U, state


def root_and_pseudo_inverse_root(N, rcond=1e-14):
    """``N^{1/2}`` and ``pinv(N) N^{1/2}`` of a symmetric positive semi-definite N (n, n), from one ``eigh``.

    ``N^{1/2} = V sqrt(max(lambda, 0)) V^T`` (as ``symmetric_root_matrix``); ``pinv(N) N^{1/2} =
    V diag(1 / sqrt(lambda)) V^T`` over the eigenvalues above ``rcond`` times the largest (the
    eigenvalues are the singular values of N, so this is ``np.linalg.pinv(N, rcond)`` times the root:
    one decomposition instead of an eigendecomposition and an SVD).
    """
    eigenvalues, vectors = np.linalg.eigh(0.5 * (N + N.T))
    positive = np.maximum(eigenvalues, 0.0)
    root = (vectors * np.sqrt(positive)) @ vectors.T
    kept = np.abs(eigenvalues) > rcond * np.max(np.abs(eigenvalues), initial=0.0)
    scale = np.zeros_like(eigenvalues)
    scale[kept & (eigenvalues > 0)] = 1.0 / np.sqrt(eigenvalues[kept & (eigenvalues > 0)])
    return root, (vectors * scale) @ vectors.T


class Fixman(DenseScheme):
    """Fixman's midpoint scheme with dense algebra (Delong et al. 2015).

    Draws: W1 (6 Nb), then W2 (6 Nb); W_c = W1 + W2.

    The thermal drift kT div N comes from evaluating the corrector's mobility at the midpoint: the
    noise velocity is ``N(mid) N(start)^{-1} N(start)^{1/2} W_c``.  With ``thermal_drift = False`` (a
    negative control for the tests; wrong physics) the corrector uses the mobility at the start point,
    so the noise is ``N(start)^{1/2} W_c`` with the right covariance and no drift (Euler-Maruyama noise);
    the deterministic velocity is still taken at the midpoint.
    """
    name = 'Fixman'

    def attempt(self, context, state, old):
        rng, model = context.rng, context.model
        nb6 = 6 * context.num_bodies
        W1 = rng.standard_normal(nb6)
        W2 = rng.standard_normal(nb6)
        matrices = model.dense_matrices(old)
        N = matrices[3]
        root, inverse_root = root_and_pseudo_inverse_root(N)
        U_p, state = self.dense_velocity(context, state, old, matrices)
        U_p = U_p.reshape(-1) + np.sqrt(4.0 * self.kT / self.dt) * (root @ W1)
        corrector = np.sqrt(self.kT / self.dt) * (inverse_root @ (W1 + W2))  # pinv(N) N^{1/2} (W1 + W2)
        mid = self.move(old, U_p, 0.5 * self.dt)
        self.check(context, state, mid)
        matrices_mid = model.dense_matrices(mid)
        N_corrector = matrices_mid[3] if self.thermal_drift else N
        U, state = self.dense_velocity(context, state, mid, matrices_mid)
        U = (U.reshape(-1) + N_corrector @ corrector).reshape(-1, 6)
        return self.move(old, U, self.dt), U, state


class DenseTwin:
    """Mixin: an iterative scheme's own step with dense products and exact solves (its dense twin).

    The step of the iterative scheme builds its problems with :meth:`problem_at` and reaches the mobility only
    through the operations overridden here: the problem is a ``body_solver.DenseMobilityProblem`` (the blob matrix
    ``M`` and ``K`` built at the configuration), the noise ``factor M^{1/2} z`` is the symmetric root's (not
    Lanczos), the solves are exact (``N (F - K^T M^{-1} s)``, no GMRES: nothing is counted), and no preconditioner
    is built.  The draws and the formulas are the iterative scheme's, so the two agree to the solver tolerance.
    """
    pair_products = False

    def problem_at(self, context, configuration):
        model = context.model
        M, _, K, _ = model.dense_matrices(configuration, inverse=False)
        return DenseMobilityProblem(model.arrays, configuration, model.vector_mobility, M, K)

    def preconditioner(self, context, state, problem):
        return None, state

    def preconditioner_at(self, context, configuration):
        return None

    def lanczos_noise(self, context, problem, z, factor, preconditioner):
        return factor * (problem.root() @ np.asarray(z, dtype=float).reshape(-1))

    def noise_solve(self, context, problem, preconditioner, noise_slip=None, noise_force=None, rhs=None):
        if rhs is None:
            rhs = problem.rhs(noise_slip=noise_slip, noise_force=noise_force)
        return problem.exact_solution(rhs)

    def deterministic_solve(self, context, state, problem, rhs, preconditioner, warm_start=True):
        return problem.exact_solution(rhs), state


class StochasticSlipMidDLA(DenseTwin, StochasticSlipMid):
    """Dense-algebra version of the midpoint slip scheme: :class:`StochasticSlipMid`'s step with dense products
    (:class:`DenseTwin`); the slip enters with the same sign as in the other dense schemes (SPEC decision 1).

    Draws: W1, W_s, W3 (3N each); W_c = W1 + W3.
    """
    name = 'stochastic_Slip_Mid_DLA'


# the roller schemes are in quaternion_integrator/roller_schemes.py
RIGID_STOCHASTIC_SCHEME_CLASSES = (StochasticFirstOrderRFD, StochasticAdamsBashforth, StochasticFirstOrderRFDDense,
                                   StochasticTractionEM, Fixman, StochasticSlipTrapz, StochasticTractionAB,
                                   StochasticSlipMid, StochasticSlipMidDLA, StochasticEM, StochasticGDCRFD)
