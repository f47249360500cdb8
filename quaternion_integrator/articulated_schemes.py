"""Time-stepping schemes of articulated rigid bodies (floor 5; doc/articulated.md).

Each step solves the mobility problem with the joint constraints
(:mod:`multi_bodies.solver.articulated`), moves every body, then restores
the joints (:meth:`ArticulatedSet.restore`): locations solved from the new
orientations, each articulated body's geometric centre advanced with the
mean linear velocity of its bodies, and a nonlinear least-squares correction
to ``nonlinear_solver_tolerance``.  Time-dependent joints are evaluated at
``t = step dt`` (start of the step), ``(step + 1/2) dt`` and ``(step + 1) dt``
as the published code does.

* ``articulated_deterministic_forward_euler``: one solve per step.
* ``articulated_deterministic_midpoint``: a half step, joints restored, a
  second solve there, the full step from the start with those velocities.
* ``articulated_deterministic_forward_euler_rollers``: single-blob bodies
  (translation and rotation of each blob from the roller mobilities, so the
  joint torques turn the blobs), forward Euler.

The model carries the joints (``model.articulated``, an ``ArticulatedSet``
made by ``run_setup.prepare``) and ``model.nonlinear_tolerance``; the solves
go through the step context's solver and the restoration's residual
evaluations are counted by it (``StepContext.restore_joints``).
Velocities have shape (Nb, 6) ``[v, w]``.
"""
from multi_bodies.solver import articulated as art
from quaternion_integrator.scheme_base import InvalidConfiguration, Scheme, _check_finite, moved
from stochastic_forcing import generators
from utils import UserInputError


class ArticulatedScheme(Scheme):
    """Base of the articulated schemes: the constrained solve and the restoration of the joints."""
    name = None
    single_blobs = False
    extrapolate_guesses = True  # forward Euler: one solve per step; midpoint: two, dt/2 apart

    def step_event(self, context, t):
        """The published ``Constraint.tumbling_event(t)`` of a user's override, at the start of every step.

        Its draws from numpy's global stream come from the run's generator when that is the published one
        (``random_generator published``), as the published code seeds the global stream with ``seed``."""
        articulated = context.model.articulated
        if articulated is not None and articulated.step_event is not None:
            with generators.drawn_by_numpy_global(context.rng):
                articulated.step_event(t)

    def articulated_set(self, context):
        if context.model.articulated is None:
            raise UserInputError("scheme %s needs articulated bodies: add an 'articulated <file.list_vertex> "
                                 "<file.clones> <file.const>' line" % self.name)
        return context.model.articulated

    def constrained_velocities(self, context, state, configuration, t):
        """Velocities (Nb, 6) with the joints at ``configuration`` and time ``t`` (counted, warm started):
        (velocities, state)."""
        result = art.articulated_velocities(context.model, self.articulated_set(context), configuration, t,
                                            x0=self.warm_guess(context, state), single_blobs=self.single_blobs,
                                            solver=context.solver)
        return result.velocities, self.keep_guess(context, state, result.normalised_solution)

    def half_or_full(self, context, start, velocities, dt, t_end, centres_from):
        """``start`` moved with ``velocities`` for ``dt``, joints restored at ``t_end`` around the moved centres."""
        articulated = context.model.articulated
        centres = articulated.centres(centres_from) + dt * articulated.mean_velocities(velocities)
        return context.restore_joints(moved(start, velocities, dt), centres, t_end)

    def finish(self, context, state, new, velocities):
        _check_finite(velocities, context.step, self.name)
        invalid = context.model.invalid_bodies(new)
        if invalid.size:
            context.count(invalid_configurations=1)
            raise InvalidConfiguration(context.step, invalid, self.name)
        return new, velocities, state


class ArticulatedForwardEuler(ArticulatedScheme):
    """Forward Euler with the joint constraints (one solve per step)."""
    name = 'articulated_deterministic_forward_euler'

    def advance(self, context, state, configuration):
        t = context.step * self.dt
        self.step_event(context, t)
        U, state = self.constrained_velocities(context, state, configuration, t)
        _check_finite(U, context.step, self.name)
        new = self.half_or_full(context, configuration, U, self.dt, t + self.dt, configuration)
        return self.finish(context, state, new, U)


class ArticulatedMidpoint(ArticulatedScheme):
    """Explicit midpoint with the joint constraints (two solves per step)."""
    name = 'articulated_deterministic_midpoint'

    def advance(self, context, state, configuration):
        t = context.step * self.dt
        self.step_event(context, t)
        U, state = self.constrained_velocities(context, state, configuration, t)
        _check_finite(U, context.step, self.name)
        middle = self.half_or_full(context, configuration, U, 0.5 * self.dt, t + 0.5 * self.dt, configuration)
        U_middle, state = self.constrained_velocities(context, state, middle, t + 0.5 * self.dt)
        _check_finite(U_middle, context.step, self.name)
        new = self.half_or_full(context, configuration, U_middle, self.dt, t + self.dt, configuration)
        return self.finish(context, state, new, U_middle)


class ArticulatedForwardEulerRollers(ArticulatedForwardEuler):
    """Forward Euler of single-blob bodies with joints (blob translation and rotation from the roller mobilities)."""
    name = 'articulated_deterministic_forward_euler_rollers'
    single_blobs = True


ARTICULATED_SCHEME_CLASSES = (ArticulatedForwardEuler, ArticulatedMidpoint, ArticulatedForwardEulerRollers)
