"""The run state, a value the time loop passes from step to step, and the context of one step (floor 5).

``RunState`` holds what changes during a run: the configuration, the index
of the next step, the counters (``multi_bodies.solver.counters.Counters``),
the state of the random generator, and the scheme's history (the warm starts
of the solves, the previous velocities of the multistep schemes, the step and
configuration the preconditioner was built at).  It is frozen; a step returns
a new one (``scheme.step(model, state) -> state``).  Its
:meth:`RunState.history` and ``rng_state`` are what the restart records
save, so a restart continues bit for bit.

``StepContext`` is what one step works with: the frozen model (read as
``context.model``: nothing is forwarded), the step's index, the generator
the step draws from, the one solve (:meth:`StepContext.solve`, the only way
a scheme reaches ``body_solver.solve``) and the counts the step adds.  It
holds no history: inside a step the history is a ``RunState`` value that
the counted operations which use it take and return (``velocities, state =
context.roller_velocities(state, configuration)``), and at the end
:meth:`StepContext.next_state` makes the next ``RunState`` of it, with the
counts added and the generator's state.  It lives for one step only.
"""
from dataclasses import dataclass, replace
from typing import Any, Optional

import numpy as np

from body.body import Configuration
from multi_bodies.solver.body_solver import kept_fewest
from multi_bodies.solver.counters import Counters, Tally
from stochastic_forcing import generators

# The history fields (saved in restart records, SPEC decision 11).
HISTORY_FIELDS = ('first_guess', 'earlier_guesses', 'roller_torque_guess', 'previous_velocities',
                  'concentration_guess')
# The counts of the preconditioner the deterministic schemes keep (ints or None, saved in restart records too).
KEPT_PRECONDITIONER_COUNTS = ('preconditioner_solves', 'preconditioner_fewest', 'preconditioner_lifetime')
# The same of the concentration problem's preconditioner that phoretic runs keep (StepWork.solute).
KEPT_CONCENTRATION_COUNTS = ('concentration_preconditioner_solves', 'concentration_preconditioner_fewest')
# A kept concentration preconditioner is built anew after a solve that took this many GMRES iterations more than the
# fewest since its build (measured, doc/preconditioners.md: the same iterations as a fresh one, 25 % less time).
CONCENTRATION_WEAR_ITERATIONS = 1


def _copy(array):
    return None if array is None else np.array(array, dtype=float, copy=True)


@dataclass(frozen=True)
class RunState:
    """The state of a run between two steps (a value).

    configuration : body.body.Configuration
    step : int, index of the next step (the first step of a run is ``initial_step``)
    counters : Counters
    first_guess : (3N + 6Nb,) or None, normalised solution of the last deterministic solve (SPEC 4.2)
    earlier_guesses : (k, 3N + 6Nb) or None, k <= 2: those of the solves before it, the latest first (kept by
        the deterministic schemes whose first guesses are extrapolated, ``Scheme.extrapolate_guesses``)
    roller_torque_guess : (3N,) or None, normalised torque of the last prescribed-spin roller solve
    previous_velocities : (Nb, 6) / (N, 3) or None, the deterministic velocities of the last accepted step
        (Adams-Bashforth schemes)
    concentration_guess : (N,) or None, normalised blob concentrations of the last solute solve (phoretic bodies)
    preconditioner_step : int or None, the step at which the preconditioner of the stochastic schemes
        was built; preconditioner_configuration : the Configuration it was built at (the stochastic schemes', or
        the one the deterministic schemes keep, ``Scheme.kept_preconditioner``)
    preconditioner_solves : int or None, solves the kept deterministic preconditioner has served (None: none kept);
        preconditioner_fewest : int or None, the fewest GMRES iterations of those solves;
        preconditioner_lifetime : int or None, solves the ones kept before it served, the last two averaged
        (``auto`` weighs the next build against them)
    concentration_preconditioner_configuration : the Configuration where the concentration problem's kept
        preconditioner was built (phoretic runs under ``preconditioner auto`` or ``neighbours``), or None;
        concentration_preconditioner_solves, concentration_preconditioner_fewest : its solves and fewest GMRES
        iterations, as for the deterministic one; concentration_preconditioner : the object (a cache: not saved)
    preconditioner : the preconditioner object built there (a cache: not saved, rebuilt after a restart)
    velocities : the velocities the last step used (not saved)
    last_iterations : GMRES iterations of the last step's last deterministic solve (the progress line)
    rng_state : the state of the run's random generator before the next step (``rng.bit_generator.state``: a
        dict; None for a run without one): a step draws from a generator made from it
        (``stochastic_forcing.generators.from_state``) and the next state holds where it left off

    The lubrication schemes keep their solves' preconditioners in the same fields
    (``lubrication.integrators.KeptSolves``: where they were built, their predictor solves and fewest
    iterations), ``first_guess`` holds their last corrector's velocities (6N,) at kT = 0 and
    ``roller_torque_guess`` the torque problem's last unknowns ``[V T]`` (6N,), both un-normalised.
    """
    configuration: Configuration
    step: int = 0
    counters: Counters = Counters()
    first_guess: Optional[np.ndarray] = None
    earlier_guesses: Optional[np.ndarray] = None
    roller_torque_guess: Optional[np.ndarray] = None
    previous_velocities: Optional[np.ndarray] = None
    concentration_guess: Optional[np.ndarray] = None
    preconditioner_step: Optional[int] = None
    preconditioner_configuration: Optional[Configuration] = None
    preconditioner_solves: Optional[int] = None
    preconditioner_fewest: Optional[int] = None
    preconditioner_lifetime: Optional[int] = None
    preconditioner: Any = None
    concentration_preconditioner_configuration: Optional[Configuration] = None
    concentration_preconditioner_solves: Optional[int] = None
    concentration_preconditioner_fewest: Optional[int] = None
    concentration_preconditioner: Any = None
    velocities: Optional[np.ndarray] = None
    last_iterations: int = 0
    rng_state: Optional[dict] = None

    def history(self):
        """What a restart record saves of the scheme (copies): a dict of arrays, ints and None."""
        history = {name: _copy(getattr(self, name)) for name in HISTORY_FIELDS}
        history['invalid_configurations'] = self.counters.invalid_configurations
        for name in KEPT_PRECONDITIONER_COUNTS + KEPT_CONCENTRATION_COUNTS + ('preconditioner_step',):
            history[name] = getattr(self, name)
        for name in ('preconditioner_configuration', 'concentration_preconditioner_configuration'):
            where = getattr(self, name)
            history[name] = None if where is None else where.copy_arrays()
        return history

    def with_history(self, history):
        """This state continued from a saved :meth:`history` (None or empty: unchanged)."""
        if not history:
            return self
        changes = {name: _copy(history.get(name)) for name in HISTORY_FIELDS}
        for name in KEPT_PRECONDITIONER_COUNTS + KEPT_CONCENTRATION_COUNTS + ('preconditioner_step',):
            changes[name] = None if history.get(name) is None else int(history[name])
        for name in ('preconditioner_configuration', 'concentration_preconditioner_configuration'):
            saved = history.get(name)
            changes[name] = None if saved is None else Configuration(*saved)
        changes.update(preconditioner=None, concentration_preconditioner=None,
                       counters=replace(self.counters,
                                        invalid_configurations=int(history.get('invalid_configurations', 0))))
        return replace(self, **changes)


class StepContext:
    """What one step of a scheme works with (see the module docstring); frozen after construction.

    Attributes: ``model`` (the frozen ``multi_bodies.solver.model.Model``), ``step`` (the index of the step),
    ``rng`` (the generator it draws from, or None), ``tally`` (the counts the step adds,
    ``multi_bodies.solver.counters.Tally``), ``solver`` (the model's ``multi_bodies.solver.solves.Solver`` with
    that tally: a solve that does not converge stops the run), ``num_bodies``, ``num_blobs``.

    Its counted operations count what they do in the tally; those that use the history take the step's
    ``RunState`` and return it with the history advanced, beside what they computed.
    """

    def __init__(self, model, step=0, rng=None):
        set_ = object.__setattr__
        set_(self, 'model', model)
        set_(self, 'step', int(step))
        set_(self, 'rng', rng)
        set_(self, 'tally', Tally())
        set_(self, 'solver', model.solver(tally=self.tally))
        set_(self, 'num_bodies', model.num_bodies)
        set_(self, 'num_blobs', model.num_blobs)

    def __setattr__(self, name, value):
        raise AttributeError('a StepContext is not changed after it is made (%s); the history is the RunState '
                             'its operations return' % name)

    # -------------------------------------------------------------- counts
    def count(self, **increments):
        """Add ``increments`` (Counters field name -> int) to the step's counts."""
        self.tally.add(**increments)

    def total(self, state, name):
        """The run's count ``name`` (a Counters field) including this step's so far (``state``: the step's start)."""
        return getattr(state.counters, name) + self.tally.count(name)

    # -------------------------------------------------------------- the one solve and the noise
    def solve(self, problem, rhs, preconditioner, x0=None, kind='deterministic', tolerance=None,
              restart=None, what='the mobility problem'):
        """The one solve (``multi_bodies.solver.solves.Solver.solve``) at the model's settings, counted as a solve
        of ``kind`` (``counters.SOLVE_KINDS``: 'deterministic', 'stochastic', ...); a solve that does not converge
        stops the run (``utils.SimulationStopped``, one line).  Returns body_solver.SolveResult."""
        if restart is None:
            return self.solver.solve(problem, rhs, preconditioner, x0=x0, tolerance=tolerance, kind=kind, what=what)
        return self.solver.solve(problem, rhs, preconditioner, x0=x0, tolerance=tolerance, restart=restart,
                                 kind=kind, what=what)

    def lanczos_noise(self, problem, z, factor, preconditioner=None, tolerance=None):
        """The noise ``factor M^{1/2} z`` (3N,) of the step's solver (``Solver.noise``: Lanczos, or exact where the
        product can), counted (a call that did not converge is warned about and counted in
        ``lanczos_not_converged``)."""
        result = self.solver.noise(problem, z, factor, preconditioner, tolerance=tolerance)
        self._count_lanczos(result)
        return result.noise

    def roller_noise(self, r_vectors, z, factor):
        """``model.roller_noise(...).noise`` (N, 3), counted."""
        result = self.model.roller_noise(r_vectors, z, factor)
        self._count_lanczos(result)
        return result.noise

    def _count_lanczos(self, result):
        self.count(lanczos_iterations=result.iterations, lanczos_not_converged=0 if result.converged else 1)

    def roller_drift(self, r_vectors, W, kT, delta):
        """``model.roller_drift``: ``kT div M_UF`` of rollers by a random finite difference, (N, 3)."""
        return self.model.roller_drift(r_vectors, W, kT, delta)

    def restore_joints(self, configuration, centres, t):
        """``articulated.restore`` at the model's ``nonlinear_tolerance``: the Configuration; its evaluations counted."""
        model = self.model
        restored = model.articulated.restore(configuration, centres, t, model.nonlinear_tolerance,
                                             verbose=model.print_residual)
        self.count(nonlinear_iterations=restored.nonlinear_iterations)
        return restored.configuration

    # -------------------------------------------------------------- operations that use the history
    def deterministic_velocities(self, state, configuration, preconditioner=None, x0=None):
        """``model.deterministic_velocities`` by this step's solver, with the warm-started solute of phoretic runs:
        (SolveResult, state)."""
        solved, state = self.solute(state, configuration)
        result = self.model.deterministic_velocities(configuration, preconditioner=preconditioner, x0=x0,
                                                     solute=solved, solver=self.solver)
        return result, state

    def forces_and_slip(self, state, configuration):
        """``((r_vectors, force_torque, slip), state)``: ``model.forces_and_slip`` with the warm-started solute."""
        solved, state = self.solute(state, configuration)
        return self.model.forces_and_slip(configuration, solved), state

    def roller_velocities(self, state, configuration):
        """Roller velocities (N, 3) at ``configuration``, the prescribed spin warm started from and into
        ``state.roller_torque_guess``: (velocities, state)."""
        result = self.model.roller_velocities(configuration, state.roller_torque_guess, solver=self.solver)
        return result.velocities, replace(state, roller_torque_guess=result.torque_guess)

    def solute(self, state, configuration):
        """Phoretic runs: the concentration solve at ``configuration`` warm started from (and into)
        ``state.concentration_guess`` (``multi_bodies.solver.surface``): (solved, state); solved is None for other
        runs."""
        model = self.model
        if model.surface is None or model.surface.phoretic is None:
            return None, state
        from multi_bodies.solver.surface import warm_solute
        kept, state = self.kept_concentration_preconditioner(state, configuration)
        solved, guess = warm_solute(model, configuration, state.concentration_guess, preconditioner=kept,
                                    solver=self.solver)
        state = replace(state, concentration_guess=guess)
        if solved is not None and kept is not None:
            state = concentration_served(state, solved[1].iterations)
        return solved, state

    def kept_concentration_preconditioner(self, state, configuration):
        """(the concentration problem's preconditioner that phoretic runs keep between solves, or None, state).

        None without phoretic bodies, under ``preconditioner block_diagonal``, or where the solves are left
        unpreconditioned.  Built at the first solve and after a solve that wore it (``CONCENTRATION_WEAR_ITERATIONS``
        more than the fewest since its build); after a restart it is built again where the saved one was built, so
        the run repeats bit for bit.  It is applied as built (not turned).
        """
        model = self.model
        surface = model.surface
        if surface is None or surface.phoretic is None or model.published_solves \
                or not surface.preconditions_concentrations(model, model.num_blobs):
            return None, state
        if state.concentration_preconditioner_configuration is None:
            state = replace(state, concentration_preconditioner=surface.concentration_preconditioner(model,
                                                                                                   configuration),
                            concentration_preconditioner_configuration=configuration,
                            concentration_preconditioner_solves=0, concentration_preconditioner_fewest=None)
        elif state.concentration_preconditioner is None:  # a restart: rebuilt where it was built
            state = replace(state, concentration_preconditioner=surface.concentration_preconditioner(
                model, state.concentration_preconditioner_configuration))
        return state.concentration_preconditioner, state

    # -------------------------------------------------------------- the next state
    def next_state(self, start, state, configuration, step, velocities):
        """The RunState after this step: ``state`` (the history the step returned) at ``configuration`` and index
        ``step``, the counts of ``start`` (the step's start) plus the tally, ``velocities`` (those the step used, or
        None), the last deterministic solve's iterations and the generator's state where the step left it."""
        last = self.tally.last_iterations
        rng_state = start.rng_state
        bit_generator = getattr(self.rng, 'bit_generator', None)
        if bit_generator is not None:
            rng_state = bit_generator.state
        return replace(state, configuration=configuration, step=int(step), counters=self.tally.after(start.counters),
                       velocities=velocities, last_iterations=start.last_iterations if last is None else last,
                       rng_state=rng_state)


def concentration_served(state, iterations):
    """``state`` after a concentration solve of ``iterations`` GMRES iterations with the kept preconditioner; one
    that took ``CONCENTRATION_WEAR_ITERATIONS`` more than the fewest since the build ends it."""
    fewest = kept_fewest(state.concentration_preconditioner_fewest, iterations, CONCENTRATION_WEAR_ITERATIONS)
    if fewest is None:
        return replace(state, concentration_preconditioner=None, concentration_preconditioner_configuration=None,
                       concentration_preconditioner_solves=None, concentration_preconditioner_fewest=None)
    return replace(state, concentration_preconditioner_solves=state.concentration_preconditioner_solves + 1,
                   concentration_preconditioner_fewest=fewest)


def generator_of(state):
    """The generator a step from ``state`` draws from: made from ``state.rng_state`` (None without one)."""
    return None if state.rng_state is None else generators.from_state(state.rng_state)
