"""The base of every time-stepping scheme: one step, its retry rules, the Euler update (floor 5).

``Scheme.advance(system, configuration, step_index, rng)`` is a function of
a configuration (``body.body.Configuration``, a value), the scheme's history
and the generator: it returns the next configuration and never changes the
system's current one; ``Scheme.step(system, step_index, rng)`` advances the
system's configuration by one step with it.  The base holds what every
scheme shares (forces and velocities from the system, the update of
locations and quaternions, the validity check, the warm starts of the
solves, kept in the scheme's history so that restarts are exact); the
deterministic schemes
(:mod:`quaternion_integrator.schemes`) and the stochastic ones
(:mod:`quaternion_integrator.stochastic_schemes`) both build on it, and the
registry in ``schemes`` imports both, so neither imports the other.

Shapes: body velocities (Nb, 6) ``[v, w]``; locations (Nb, 3); scalar-first
quaternions (Nb, 4), updated by ``q_new = from_rotation(w dt) q_old`` and not
renormalised (SPEC section 3).
"""
import numpy as np

from body.body import Configuration
from body.geometry import rotate_quaternions as _rotate_quaternions
from utils import SimulationStopped, UserInputError


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
    """Base of all schemes: ``name``, ``dt``, ``invalid_configurations`` (count for ``.info``).

    History (``get_history``): the invalid-configuration count and the warm
    starts of the deterministic solves: ``first_guess`` (the normalised
    solution of the last deterministic mobility solve, SPEC 4.2) and
    ``roller_torque_guess`` (of the prescribed-spin roller solve).
    """
    name = None
    rollers = False

    def __init__(self, dt):
        if not dt > 0:
            raise UserInputError('dt must be positive for a dynamic run, got %r' % dt)
        self.dt = float(dt)
        self.invalid_configurations = 0
        self.first_guess = None
        self.roller_torque_guess = None

    # -------------------------------------------------------------- velocities with the warm starts
    def deterministic_solve(self, system, problem, rhs, preconditioner, warm_start=True):
        """The counted deterministic solve of ``rhs`` at ``problem``, from and into ``first_guess``.

        ``warm_start=False`` starts from zero (the solution is still kept as the next ``first_guess``).
        """
        result = system.solve(problem, rhs, preconditioner, x0=self.first_guess if warm_start else None)
        if result.normalised_solution is not None:
            self.first_guess = result.normalised_solution
        return result

    def rigid_velocities(self, system, configuration, preconditioner=None):
        """Velocities (Nb, 6) at ``configuration`` under its forces and slip (iterative, warm started)."""
        result = system.deterministic_velocities(configuration, preconditioner=preconditioner, x0=self.first_guess)
        if result.normalised_solution is not None:
            self.first_guess = result.normalised_solution
        return result.velocities

    def roller_velocities(self, system, configuration):
        """Roller velocities (N, 3) at ``configuration`` (prescribed spin warm started)."""
        result = system.roller_velocities(configuration, self.roller_torque_guess)
        self.roller_torque_guess = result.torque_guess
        return result.velocities

    def move(self, configuration, velocities, dt):
        """``configuration`` moved with ``velocities`` for ``dt`` (bodies or rollers), a new Configuration."""
        return moved(configuration, velocities, dt, rollers=self.rollers)

    # -------------------------------------------------------------- the step
    def velocities(self, system, configuration):
        raise NotImplementedError

    def combine(self, velocities):
        """Velocity used for the update (forward Euler: the current one)."""
        return velocities

    def accept(self, velocities):
        """Called when a step is accepted, with the velocities the scheme computed."""

    def get_history(self):
        """What the scheme carries from step to step (saved with each snapshot for exact restarts)."""
        return {'invalid_configurations': self.invalid_configurations,
                'first_guess': None if self.first_guess is None else np.array(self.first_guess, copy=True),
                'roller_torque_guess': None if self.roller_torque_guess is None
                else np.array(self.roller_torque_guess, copy=True)}

    def set_history(self, history):
        """Continue from ``get_history()`` of an earlier run (None: start afresh)."""
        if history:
            self.invalid_configurations = int(history.get('invalid_configurations', 0))
            for name in ('first_guess', 'roller_torque_guess'):
                value = history.get(name)
                setattr(self, name, None if value is None else np.array(value, dtype=float, copy=True))

    def advance(self, system, configuration, step_index, rng=None):
        """One step from ``configuration``: returns (the new Configuration, the velocities used).

        Velocities (Nb, 6) (rollers: (N, 3)).  Raises InvalidConfiguration (counted) when the step would
        put a blob centre below the wall; the system's current configuration is never changed here.
        """
        system.preprocess(configuration)
        velocities = self.velocities(system, configuration)
        _check_finite(velocities, step_index, self.name)
        used = self.combine(velocities)
        new = system.postprocess(self.move(configuration, used, self.dt))
        invalid = system.invalid_bodies(new)
        if invalid.size:
            self.invalid_configurations += 1
            raise InvalidConfiguration(step_index, invalid, self.name)
        self.accept(velocities)
        return new, used

    def step(self, system, step_index, rng=None):
        """Advance the system's configuration by one step; returns the velocities used."""
        new, used = self.advance(system, system.configuration, step_index, rng)
        system.set_configuration(new)
        return used
