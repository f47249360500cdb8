"""The base of every time-stepping scheme: one step, its retry rules, the Euler update (floor 5).

``Scheme.step(system, step_index, rng)`` is the loop body every scheme
shares (forces and velocities from the system, the update of locations and
quaternions, the validity check); the deterministic schemes
(:mod:`quaternion_integrator.schemes`) and the stochastic ones
(:mod:`quaternion_integrator.stochastic_schemes`) both build on it, and the
registry in ``schemes`` imports both, so neither imports the other.

Shapes: body velocities (Nb, 6) ``[v, w]``; locations (Nb, 3); scalar-first
quaternions (Nb, 4), updated by ``q_new = from_rotation(w dt) q_old`` and not
renormalised (SPEC section 3).
"""
import numpy as np

from quaternion_integrator.quaternion import rotate_quaternions as _rotate_quaternions
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


def _check_finite(velocities, step, scheme):
    if not np.all(np.isfinite(velocities)):
        raise SimulationStopped('step %d of %s: the velocities are not finite (NaN or inf); check the forces '
                                '(user-defined functions), the time step and the configuration' % (step, scheme))


class Scheme:
    """Base of all schemes: ``name``, ``dt``, ``invalid_configurations`` (count for ``.info``)."""
    name = None
    rollers = False

    def __init__(self, dt):
        if not dt > 0:
            raise UserInputError('dt must be positive for a dynamic run, got %r' % dt)
        self.dt = float(dt)
        self.invalid_configurations = 0

    def velocities(self, system):
        raise NotImplementedError

    def combine(self, velocities):
        """Velocity used for the update (forward Euler: the current one)."""
        return velocities

    def accept(self, velocities):
        """Called when a step is accepted, with the velocities the scheme computed."""

    def get_history(self):
        """What the scheme carries from step to step (saved with each snapshot for exact restarts)."""
        return {'invalid_configurations': self.invalid_configurations}

    def set_history(self, history):
        """Continue from ``get_history()`` of an earlier run (None: start afresh)."""
        if history:
            self.invalid_configurations = int(history.get('invalid_configurations', 0))

    def step(self, system, step_index, rng=None):
        """Advance ``system`` by one step; returns the velocities used (Nb, 6) (rollers: (Nb, 3))."""
        old_locations, old_orientations = system.get_state()
        system.preprocess()
        velocities = self.velocities(system)
        _check_finite(velocities, step_index, self.name)
        used = self.combine(velocities)
        if self.rollers:
            system.set_state(old_locations + self.dt * used, old_orientations)
        else:
            system.set_state(*euler_update(old_locations, old_orientations, used, self.dt))
        system.postprocess()
        invalid = system.invalid_bodies()
        if invalid.size:
            self.invalid_configurations += 1
            system.set_state(old_locations, old_orientations)
            raise InvalidConfiguration(step_index, invalid, self.name)
        self.accept(velocities)
        return used
