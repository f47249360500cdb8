"""The base of every time-stepping scheme: one step, its retry rules, the Euler update (floor 5).

``Scheme.step(model, state) -> state`` is a function of the frozen model
(``multi_bodies.solver.model.Model``) and the run state
(``quaternion_integrator.scheme_state.RunState``: configuration, history,
counters, the generator's state): it returns the next state and changes
neither the model nor the state it was given.  ``Scheme.init(model,
configuration)`` makes the first state.  Inside the step the scheme works
with a ``StepContext`` (``context``: the model, the one solve, the counts)
and passes the history along as the ``RunState`` value its operations take
and return.  The base holds what every scheme shares (forces and
velocities from the model, the update of locations and quaternions, the
validity check, the warm starts of the solves, carried in the state so that
restarts are exact); the deterministic schemes
(:mod:`quaternion_integrator.schemes`) and the stochastic ones
(:mod:`quaternion_integrator.stochastic_schemes`) both build on it, and the
registry in ``schemes`` imports both, so neither imports the other.

Shapes: body velocities (Nb, 6) ``[v, w]``; locations (Nb, 3); scalar-first
quaternions (Nb, 4), updated by ``q_new = from_rotation(w dt) q_old`` and not
renormalised (SPEC section 3).
"""
from dataclasses import replace

import numpy as np

from body.body import Configuration, as_configuration
from body.geometry import rotate_quaternions as _rotate_quaternions
from multi_bodies.files.scheme_table import SCHEME_TABLE
from multi_bodies.solver.body_solver import kept_fewest
from multi_bodies.solver.counters import Counters
from quaternion_integrator.scheme_state import RunState, StepContext, generator_of
from utils import SimulationStopped, UserInputError


# A kept preconditioner (Scheme.kept_preconditioner) is built anew after a solve that took this many GMRES
# iterations more than the fewest since its build (measured, doc/preconditioners.md: 1 instead of 2 took packed
# boomerangs from 5.0 to 4.25 iterations per Adams-Bashforth solve and changed no other scene at dt 0.01).
KEPT_WEAR_ITERATIONS = 1
# ``preconditioner auto`` weighs a kept preconditioner's build against the solves the last one served before it
# wore, at most this many: the neighbour pairs' memory grows with the weight, what they save does not.
KEPT_SOLVES_WEIGHED = 4


class InvalidConfiguration(SimulationStopped):
    """A step put a blob centre below the wall; ``step`` and ``bodies`` (indices) say where."""

    def __init__(self, step, bodies, scheme):
        self.step, self.bodies = step, [int(b) for b in bodies]
        shown = ', '.join(str(b) for b in self.bodies[:10]) + (' ...' if len(self.bodies) > 10 else '')
        super().__init__('step %d of %s: body %s would have a blob centre below the wall (z < 0); the run '
                         'stops here (a deterministic step would give the same result again). Lower dt or '
                         'strengthen the wall repulsion (repulsion_strength_wall, debye_length_wall).'
                         % (step, scheme, shown))


def rotate_quaternions(orientations, rotation_vectors):
    """``from_rotation(phi_k) * q_k`` for every body; orientations (Nb, 4), rotation_vectors (Nb, 3)."""
    return _rotate_quaternions(orientations, rotation_vectors)


def euler_update(locations, orientations, velocities, dt):
    """New (locations (Nb, 3), orientations (Nb, 4)) after moving with velocities (Nb, 6) for dt."""
    velocities = np.asarray(velocities, dtype=float).reshape(-1, 6)
    return locations + dt * velocities[:, :3], rotate_quaternions(orientations, dt * velocities[:, 3:])


def displace_bodies(configuration, scale, displacement, body_lengths=None):
    """Rigid bodies moved by ``scale * displacement`` (random finite differences), a new Configuration.

    displacement : (Nb, 6) ``[W_t, W_r]`` per body; body_lengths : (Nb,) or None.  Translations are
    ``scale * body_length * W_t`` when lengths are given (SPEC decision 6), else ``scale * W_t``;
    rotations ``from_rotation(scale W_r) q``.  The ``displace`` of :func:`stochastic_forcing.rfd` for bodies.
    """
    displacement = np.asarray(displacement, dtype=float).reshape(-1, 6)
    translation = displacement[:, :3] * scale
    if body_lengths is not None:
        translation = translation * np.asarray(body_lengths, dtype=float).reshape(-1, 1)
    return Configuration(configuration.locations + translation,
                         rotate_quaternions(configuration.orientations, scale * displacement[:, 3:]))


def moved(configuration, velocities, dt, rollers=False):
    """The configuration after moving with ``velocities`` for ``dt`` (a new Configuration).

    Bodies: velocities (Nb, 6), the Euler update of locations and quaternions; rollers: velocities
    (N, 3) of the single blobs, orientations unchanged.
    """
    if rollers:
        return Configuration(configuration.locations + dt * np.asarray(velocities, dtype=float).reshape(-1, 3),
                             configuration.orientations)
    return Configuration(*euler_update(configuration.locations, configuration.orientations, velocities, dt))


def _check_finite(velocities, step, scheme):
    if not np.all(np.isfinite(velocities)):
        raise SimulationStopped('step %d of %s: the velocities are not finite (NaN or inf); check the forces '
                                '(user-defined functions), the time step and the configuration' % (step, scheme))


class Scheme:
    """Base of all schemes: the rule of one step, with its parameters ``name``, ``dt`` (and the stochastic
    schemes' kT, rf_delta, ...); it holds no state.

    ``init(model, configuration, step)`` makes the first RunState and ``step(model, state)`` the next one; the
    history the step carries (the warm starts of the deterministic solves, SPEC 4.2, the previous velocities,
    the preconditioner's step) is in the state (``scheme_state.RunState``), and so is the generator's state.
    Inside a step the scheme's methods take the step's ``StepContext`` (``context``: the model, the one solve,
    the counts) and the step's ``RunState`` (``state``: the history so far), and those that advance the history
    return the state with it advanced.
    """
    name = None
    # The deterministic solves of the scheme are equally spaced in time (forward Euler, Adams-Bashforth: dt;
    # midpoint: dt/2), so their first guess may be extrapolated from the last three solutions (first_guess)
    extrapolate_guesses = False
    # The scheme's deterministic solves (rigid_velocities) keep their preconditioner from solve to solve while it
    # serves, under preconditioner auto and neighbours (kept_preconditioner); the published solves rebuild it
    keep_preconditioner = False

    def __init__(self, dt):
        if not dt > 0:
            raise UserInputError('dt must be positive for a dynamic run, got %r' % dt)
        self.dt = float(dt)

    # -------------------------------------------------------------- what the registry says of the scheme
    @property
    def entry(self):
        """The scheme's ``multi_bodies.files.scheme_table.SchemeEntry`` (kind and needs, declared once there)."""
        return SCHEME_TABLE[self.name]

    @property
    def rollers(self):
        """The scheme moves single-blob rollers by their positions alone (velocities (N, 3)): a roller scheme of
        the registry that is neither a lubrication scheme nor an articulated one (those move spheres and bodies
        with their orientations)."""
        entry = self.entry
        return entry.rollers and not entry.lubrication and not entry.articulated

    @property
    def dense(self):
        """Dense algebra (O(N^3) a step): the dense memory check of the run applies."""
        return self.entry.algebra == 'dense'

    # -------------------------------------------------------------- the state
    def init(self, model, configuration, step=0, history=None, counters=None, rng_state=None):
        """The RunState of a run at ``configuration`` before step ``step`` (continued from a restart record's
        scheme ``history`` and ``counters`` (Counters) when given); ``rng_state``: the state of the run's generator
        (``rng.bit_generator.state``; None: none, the steps are then given one)."""
        state = RunState(as_configuration(configuration), int(step), Counters() if counters is None else counters,
                         rng_state=rng_state)
        return state.with_history(history)

    def step(self, model, state, rng=None):
        """One step of ``model`` from ``state``: the next RunState (its ``velocities`` are those the step used).

        The step draws from ``rng`` when one is given (anything with ``standard_normal(n)``), else from a
        generator continuing ``state.rng_state``; the next state holds the generator's state where the step left
        it.  A step that stops the run (``utils.SimulationStopped``, e.g. InvalidConfiguration) carries the state
        with the step's counts and the start configuration in the exception's ``state``.
        """
        context = StepContext(model, state.step, generator_of(state) if rng is None else rng)
        try:
            new, used, after = self.advance(context, state, state.configuration)
        except SimulationStopped as err:
            err.state = context.next_state(state, state, state.configuration, state.step, None)
            raise
        return context.next_state(state, after, new, state.step + 1, used)

    # -------------------------------------------------------------- velocities with the warm starts
    def deterministic_solve(self, context, state, problem, rhs, preconditioner, warm_start=True):
        """The counted deterministic solve of ``rhs`` at ``problem``, from and into ``state.first_guess``:
        (SolveResult, state).

        ``warm_start=False`` starts from zero (the solution is still kept as the next ``first_guess``).
        """
        result = context.solve(problem, rhs, preconditioner,
                               x0=self.warm_guess(context, state) if warm_start else None)
        return result, self.keep_guess(context, state, result.normalised_solution)

    def rigid_velocities(self, context, state, configuration, preconditioner=None):
        """Velocities (Nb, 6) at ``configuration`` under its forces and slip (iterative, warm started; with the
        kept preconditioner where the scheme keeps one, else one built at ``configuration``): (velocities, state)."""
        kept = preconditioner is None and self.keeps_preconditioner(context)
        if kept:
            preconditioner, state = self.kept_preconditioner(context, state, configuration)
        result, state = context.deterministic_velocities(state, configuration, preconditioner=preconditioner,
                                                         x0=self.warm_guess(context, state))
        state = self.keep_guess(context, state, result.normalised_solution)
        if kept:
            state = self.served(state, result.iterations)
        return result.velocities, state

    def keeps_preconditioner(self, context):
        """True when this step's deterministic solves keep their preconditioner (``keep_preconditioner``) and the
        model does not make the published solves (``preconditioner block_diagonal`` rebuilds it at every solve)."""
        return self.keep_preconditioner and not context.model.published_solves

    def kept_preconditioner(self, context, state, configuration):
        """(the preconditioner the deterministic solves keep: the one in the run state, else one built here, state).

        A preconditioner built at one configuration serves the next solves too, turned with the bodies
        (``multi_bodies.solver.corotated_preconditioner``), until :meth:`served` finds that it has worn (doc
        preconditioners.md, kept preconditioners).  The build is weighed (``preconditioner auto``) against the
        solves the last kept one served before it wore (at least 1, at most ``KEPT_SOLVES_WEIGHED``; that many
        for the first one), averaged with the weight before (:meth:`served`).  After a
        restart the preconditioner is built again at the configuration it was built at, with the same weight, so
        the run repeats bit for bit.
        """
        solves = KEPT_SOLVES_WEIGHED if state.preconditioner_lifetime is None else \
            min(state.preconditioner_lifetime, KEPT_SOLVES_WEIGHED)
        if state.preconditioner_configuration is None or state.preconditioner_solves is None:
            state = replace(state, preconditioner=context.model.build_preconditioner(configuration, solves=solves),
                            preconditioner_configuration=configuration, preconditioner_solves=0,
                            preconditioner_fewest=None)
        elif state.preconditioner is None:  # a restart: the run state holds where it was built, not the object
            state = replace(state, preconditioner=context.model.build_preconditioner(
                state.preconditioner_configuration, solves=solves))
        return state.preconditioner, state

    @staticmethod
    def served(state, iterations):
        """``state`` after a solve of ``iterations`` GMRES iterations with the kept preconditioner; when it took
        ``KEPT_WEAR_ITERATIONS`` more than the fewest since the build, the next solve builds a new one, weighed
        against the solves before this one (``preconditioner_lifetime``)."""
        solves = state.preconditioner_solves + 1
        fewest = kept_fewest(state.preconditioner_fewest, iterations, KEPT_WEAR_ITERATIONS)
        if fewest is None:
            # the solves it served before it wore, averaged with the last estimate (rounded up): a wear that came
            # early by the noise of one iteration does not by itself cost the next build its correction
            lived = min(max(1, solves - 1), KEPT_SOLVES_WEIGHED)
            last = state.preconditioner_lifetime
            lifetime = lived if last is None else -(-(min(last, KEPT_SOLVES_WEIGHED) + lived) // 2)
            return replace(state, preconditioner_lifetime=lifetime, preconditioner=None,
                           preconditioner_configuration=None, preconditioner_solves=None, preconditioner_fewest=None)
        return replace(state, preconditioner_solves=solves, preconditioner_fewest=fewest)

    def extrapolates(self, context):
        """True when this step's deterministic solves start from extrapolated guesses: a scheme of equally spaced
        solves (``extrapolate_guesses``) and a model without ``published_solves`` (``preconditioner
        block_diagonal``: the published solves start from the last solution)."""
        return self.extrapolate_guesses and not context.model.published_solves

    def warm_guess(self, context, state):
        """The first guess of the next deterministic solve (normalised, or None for zeros).

        The last solution ``g0`` (SPEC 4.2), or where the scheme extrapolates, the polynomial through the last
        solutions at their equally spaced times: ``2 g0 - g1`` with two, ``3 g0 - 3 g1 + g2`` with three.
        Measured on 100 boomerangs at dt 0.01 (Adams-Bashforth, doc/preconditioners.md): 5 GMRES iterations per
        solve from ``g0``, 3.8 and 3.0 from the linear and quadratic ones; at dt 0.1, 5 and 4.6.
        """
        guess, earlier = state.first_guess, state.earlier_guesses
        if guess is None or earlier is None or not self.extrapolates(context) or earlier.shape[1:] != guess.shape:
            return guess
        if earlier.shape[0] >= 2:
            return 3.0 * guess - 3.0 * earlier[0] + earlier[1]
        return 2.0 * guess - earlier[0]

    def keep_guess(self, context, state, solution):
        """``state`` keeping a deterministic solve's normalised solution (None: nothing to keep) as the next first
        guess, and where the scheme extrapolates, the two before it in ``earlier_guesses``."""
        if solution is None:
            return state
        previous = state.first_guess
        earlier = None
        if self.extrapolates(context) and previous is not None and previous.shape == solution.shape:
            kept = [previous]
            if state.earlier_guesses is not None and state.earlier_guesses.shape[1:] == solution.shape:
                kept.append(state.earlier_guesses[0])
            earlier = np.stack(kept)
        return replace(state, first_guess=solution, earlier_guesses=earlier)

    def roller_velocities(self, context, state, configuration):
        """Roller velocities (N, 3) at ``configuration`` (prescribed spin warm started): (velocities, state)."""
        return context.roller_velocities(state, configuration)

    def move(self, configuration, velocities, dt):
        """``configuration`` moved with ``velocities`` for ``dt`` (bodies or rollers), a new Configuration."""
        return moved(configuration, velocities, dt, rollers=self.rollers)

    # -------------------------------------------------------------- the step
    def velocities(self, context, state, configuration):
        """(velocities at ``configuration``: (Nb, 6), rollers (N, 3), state)."""
        raise NotImplementedError

    def combine(self, state, velocities):
        """Velocity used for the update (forward Euler: the current one)."""
        return velocities

    def accept(self, state, velocities):
        """``state`` after a step is accepted with the velocities the scheme computed (unchanged here)."""
        return state

    def advance(self, context, state, configuration):
        """One step from ``configuration``: (the new Configuration, the velocities used, state).

        Velocities (Nb, 6) (rollers: (N, 3)).  Raises InvalidConfiguration (counted) when the step would
        put a blob centre below the wall.
        """
        model = context.model
        model.preprocess(configuration)
        velocities, state = self.velocities(context, state, configuration)
        _check_finite(velocities, context.step, self.name)
        used = self.combine(state, velocities)
        new = model.postprocess(self.move(configuration, used, self.dt))
        invalid = model.invalid_bodies(new)
        if invalid.size:
            context.count(invalid_configurations=1)
            raise InvalidConfiguration(context.step, invalid, self.name)
        return new, used, self.accept(state, velocities)
