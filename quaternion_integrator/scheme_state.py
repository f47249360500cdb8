"""The run state: a value the time loop passes from step to step, and one step's working copy of it (floor 5).

``RunState`` holds what changes during a run: the configuration, the index
of the next step, the counters (``multi_bodies.solver.counters.Counters``)
and the scheme's history (the warm starts of the solves, the previous
velocities of the multistep schemes, the step and configuration the
preconditioner was built at).  It is frozen; a step returns a new one
(``scheme.step(model, state, rng) -> state``).  Its :meth:`RunState.history`
is what the restart records save, so a restart continues bit for bit.

``StepWork`` is the working copy one step uses: it reads the model's
physics (attribute look-ups it does not define itself go to the frozen
model), advances a copy of the history as the step's solves return, adds
their counts, and at the end makes the next ``RunState``.  It lives for one
step only.
"""
from dataclasses import dataclass, replace
from typing import Any, Optional

import numpy as np

from body.body import Configuration
from multi_bodies.solver.body_solver import kept_fewest
from multi_bodies.solver.counters import Counters

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
# what a StepWork copies from its RunState and back, besides the named fields
KEPT_STATE = KEPT_PRECONDITIONER_COUNTS + KEPT_CONCENTRATION_COUNTS + ('concentration_preconditioner_configuration',
                                                                        'concentration_preconditioner')


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


class StepWork:
    """One step's working copy of a RunState, over the frozen model (see module docstring).

    Attributes: ``model``, ``step_index``, the history fields of RunState (advanced by the step), the
    step's count increments.  Any other attribute is the model's (``work.mobility_problem(q)`` is
    ``model.mobility_problem(q)``).
    """

    def __init__(self, model, state):
        self.model = model
        self.step_index = state.step
        self.first_guess = state.first_guess
        self.earlier_guesses = state.earlier_guesses
        self.roller_torque_guess = state.roller_torque_guess
        self.previous_velocities = state.previous_velocities
        self.concentration_guess = state.concentration_guess
        self.pending_previous = None
        self.preconditioner_step = state.preconditioner_step
        self.preconditioner_configuration = state.preconditioner_configuration
        for name in KEPT_STATE:
            setattr(self, name, getattr(state, name))
        self.preconditioner = state.preconditioner
        self.last_iterations = state.last_iterations
        self.start_counters = state.counters
        self.increments = {}

    def __getattr__(self, name):
        if name == 'model':  # not yet set (copying): no recursion
            raise AttributeError(name)
        return getattr(self.model, name)

    def count(self, **increments):
        """Add ``increments`` (Counters field name -> int) to the step's counts."""
        for name, value in increments.items():
            self.increments[name] = self.increments.get(name, 0) + int(value)

    def total(self, name):
        """The run's count ``name`` (a Counters field) including this step's so far."""
        return getattr(self.start_counters, name) + self.increments.get(name, 0)

    # -------------------------------------------------------------- the counted operations
    def solve(self, problem, rhs, preconditioner, x0=None, kind='deterministic', tolerance=None,
              what='the mobility problem'):
        """``model.solve`` (the one solve), counted as a ``kind`` ('deterministic' or 'stochastic') solve."""
        result = self.model.solve(problem, rhs, preconditioner, x0=x0, tolerance=tolerance, what=what)
        self.record_solve(result, kind)
        return result

    def record_solve(self, result, kind='deterministic'):
        """Count a SolveResult of ``kind`` (its GMRES iterations and the solve)."""
        if kind == 'deterministic':
            self.count(gmres_iterations=result.iterations, deterministic_solves=1)
            self.last_iterations = result.iterations
        else:
            self.count(gmres_iterations=result.iterations, gmres_stochastic_iterations=result.iterations,
                       stochastic_solves=1)

    def deterministic_velocities(self, configuration, preconditioner=None, x0=None):
        """``model.deterministic_velocities``, counted."""
        result = self.model.deterministic_velocities(configuration, preconditioner=preconditioner, x0=x0,
                                                     solute=self.solute(configuration))
        self.record_solve(result)
        return result

    def solute(self, configuration):
        """Phoretic runs: the concentration solve at ``configuration`` warm started from (and into)
        ``concentration_guess`` (``multi_bodies.solver.surface``); None for other runs."""
        from multi_bodies.solver.surface import warm_solute
        kept = self.kept_concentration_preconditioner(configuration)
        solved, self.concentration_guess = warm_solute(self.model, configuration, self.concentration_guess,
                                                       preconditioner=kept)
        if solved is not None:
            self.count(laplace_iterations=solved[1].iterations)
            if kept is not None:
                self.concentration_served(solved[1].iterations)
        return solved

    def kept_concentration_preconditioner(self, configuration):
        """The concentration problem's preconditioner that phoretic runs keep between solves, or None (no
        phoretic bodies, ``preconditioner block_diagonal``, or solves left unpreconditioned).

        Built at the first solve and after a solve that wore it (``CONCENTRATION_WEAR_ITERATIONS`` more than the
        fewest since its build); after a restart it is built again where the saved one was built, so the run
        repeats bit for bit.  It is applied as built (not turned).
        """
        surface = self.model.surface
        if surface is None or surface.phoretic is None or getattr(self.model, 'published_solves', True) \
                or not surface.preconditions_concentrations(self.model, self.model.num_blobs):
            return None
        if self.concentration_preconditioner_configuration is None:
            self.concentration_preconditioner = surface.concentration_preconditioner(self.model, configuration)
            self.concentration_preconditioner_configuration = configuration
            self.concentration_preconditioner_solves, self.concentration_preconditioner_fewest = 0, None
        elif self.concentration_preconditioner is None:  # a restart: rebuilt where it was built
            self.concentration_preconditioner = surface.concentration_preconditioner(
                self.model, self.concentration_preconditioner_configuration)
        return self.concentration_preconditioner

    def concentration_served(self, iterations):
        """Count a concentration solve of ``iterations`` GMRES iterations with the kept preconditioner; one that
        took ``CONCENTRATION_WEAR_ITERATIONS`` more than the fewest since the build ends it."""
        fewest = kept_fewest(self.concentration_preconditioner_fewest, iterations, CONCENTRATION_WEAR_ITERATIONS)
        if fewest is None:
            self.concentration_preconditioner = self.concentration_preconditioner_configuration = None
            self.concentration_preconditioner_solves = self.concentration_preconditioner_fewest = None
            return
        self.concentration_preconditioner_solves += 1
        self.concentration_preconditioner_fewest = fewest

    def forces_and_slip(self, configuration):
        """``model.forces_and_slip`` with the warm-started solute (phoretic runs)."""
        return self.model.forces_and_slip(configuration, self.solute(configuration))

    def lanczos_noise(self, problem, z, factor, preconditioner=None, tolerance=None):
        """``model.lanczos_noise(...).noise`` (3N,), counted."""
        result = self.model.lanczos_noise(problem, z, factor, preconditioner, tolerance=tolerance)
        self.record_lanczos(result)
        return result.noise

    def record_lanczos(self, result):
        self.count(lanczos_iterations=result.iterations, lanczos_not_converged=0 if result.converged else 1)

    def roller_velocities(self, configuration):
        """Roller velocities (N, 3) at ``configuration``, the prescribed spin warm started; counted."""
        result = self.model.roller_velocities(configuration, self.roller_torque_guess)
        self.roller_torque_guess = result.torque_guess
        if not self.model.free_kinematics:
            self.count(gmres_iterations=result.iterations)
            self.last_iterations = result.iterations
        return result.velocities

    def roller_noise(self, r_vectors, z, factor):
        """``model.roller_noise(...).noise`` (N, 3), counted."""
        result = self.model.roller_noise(r_vectors, z, factor)
        self.record_lanczos(result)
        return result.noise

    def restore_joints(self, configuration, centres, t):
        """``articulated.restore`` at the model's ``nonlinear_tolerance``: the Configuration; its evaluations counted."""
        restored = self.model.articulated.restore(configuration, centres, t, self.model.nonlinear_tolerance,
                                                  verbose=self.model.print_residual)
        self.count(nonlinear_iterations=restored.nonlinear_iterations)
        return restored.configuration

    # -------------------------------------------------------------- the next state
    def state(self, start, configuration, step, velocities):
        """The RunState after this work: ``start`` with the advanced history, the counts added, ``configuration``
        and ``step``, and ``velocities`` (those the step used, or None)."""
        return replace(start, configuration=configuration, step=int(step),
                       counters=start.counters.plus(**self.increments),
                       first_guess=self.first_guess, earlier_guesses=self.earlier_guesses,
                       roller_torque_guess=self.roller_torque_guess,
                       previous_velocities=self.previous_velocities,
                       concentration_guess=self.concentration_guess,
                       preconditioner_step=self.preconditioner_step,
                       preconditioner_configuration=self.preconditioner_configuration,
                       preconditioner=self.preconditioner, velocities=velocities,
                       last_iterations=self.last_iterations,
                       **{name: getattr(self, name) for name in KEPT_STATE})
