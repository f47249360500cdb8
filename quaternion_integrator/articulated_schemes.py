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

The system must carry ``system.articulated`` (an ``ArticulatedSet``, set by
``run_setup.prepare``) and ``system.nonlinear_tolerance``.  Velocities have
shape (Nb, 6) ``[v, w]``.
"""
from multi_bodies.solver import articulated as art
from quaternion_integrator.scheme_base import InvalidConfiguration, Scheme, _check_finite, moved
from utils import SimulationStopped, UserInputError


class ArticulatedScheme(Scheme):
    """Base of the articulated schemes: the constrained solve and the restoration of the joints."""
    name = None
    single_blobs = False

    def articulated_set(self, system):
        articulated = getattr(system, 'articulated', None)
        if articulated is None:
            raise UserInputError("scheme %s needs articulated bodies: add an 'articulated <file.list_vertex> "
                                 "<file.clones> <file.const>' line" % self.name)
        return articulated

    def constrained_velocities(self, system, configuration, t):
        """Velocities (Nb, 6) with the joints at ``configuration`` and time ``t`` (counted, warm started)."""
        articulated = self.articulated_set(system)
        result = art.articulated_velocities(system, articulated, configuration, t, x0=self.first_guess,
                                            single_blobs=self.single_blobs)
        U, iterations, converged, residual, guess = result.velocities, result.iterations, result.converged, \
            result.residual, result.normalised_solution
        system.gmres_iterations += iterations
        system.solves['deterministic'] += 1
        system.last_iterations = iterations
        if not converged:
            raise SimulationStopped('GMRES of the articulated mobility problem did not converge to solver_tolerance '
                                    '%g in %d iterations (relative residual %.3e)'
                                    % (system.tolerance, iterations, residual))
        if guess is not None:
            self.first_guess = guess
        return U

    def half_or_full(self, system, start, velocities, dt, t_end, centres_from):
        """``start`` moved with ``velocities`` for ``dt``, joints restored at ``t_end`` around the moved centres."""
        articulated = system.articulated
        centres = articulated.centres(centres_from) + dt * articulated.mean_velocities(velocities)
        new = moved(start, velocities, dt)
        return articulated.restore(new, centres, t_end, system.nonlinear_tolerance, verbose=system.print_residual)

    def finish(self, system, new, velocities, step_index):
        _check_finite(velocities, step_index, self.name)
        invalid = system.invalid_bodies(new)
        if invalid.size:
            self.invalid_configurations += 1
            raise InvalidConfiguration(step_index, invalid, self.name)
        return new, velocities


class ArticulatedForwardEuler(ArticulatedScheme):
    """Forward Euler with the joint constraints (one solve per step)."""
    name = 'articulated_deterministic_forward_euler'

    def advance(self, system, configuration, step_index, rng=None):
        t = step_index * self.dt
        U = self.constrained_velocities(system, configuration, t)
        _check_finite(U, step_index, self.name)
        new = self.half_or_full(system, configuration, U, self.dt, t + self.dt, configuration)
        return self.finish(system, new, U, step_index)


class ArticulatedMidpoint(ArticulatedScheme):
    """Explicit midpoint with the joint constraints (two solves per step)."""
    name = 'articulated_deterministic_midpoint'

    def advance(self, system, configuration, step_index, rng=None):
        t = step_index * self.dt
        U = self.constrained_velocities(system, configuration, t)
        _check_finite(U, step_index, self.name)
        middle = self.half_or_full(system, configuration, U, 0.5 * self.dt, t + 0.5 * self.dt, configuration)
        U_middle = self.constrained_velocities(system, middle, t + 0.5 * self.dt)
        _check_finite(U_middle, step_index, self.name)
        new = self.half_or_full(system, configuration, U_middle, self.dt, t + self.dt, configuration)
        return self.finish(system, new, U_middle, step_index)


class ArticulatedForwardEulerRollers(ArticulatedForwardEuler):
    """Forward Euler of single-blob bodies with joints (blob translation and rotation from the roller mobilities)."""
    name = 'articulated_deterministic_forward_euler_rollers'
    single_blobs = True


ARTICULATED_SCHEME_CLASSES = (ArticulatedForwardEuler, ArticulatedMidpoint, ArticulatedForwardEulerRollers)
ARTICULATED_SCHEMES = tuple(cls.name for cls in ARTICULATED_SCHEME_CLASSES)
