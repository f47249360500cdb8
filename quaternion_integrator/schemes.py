"""Time-stepping schemes of the manual, behind one registry keyed by the scheme name.

A scheme object is made once per run by ``make_scheme(name, dt)`` and then
``scheme.step(system, step_index, rng)`` advances the system by one step of
length ``dt``.  The *system* (``multi_bodies.system.System``) is passed in;
schemes only use its methods (``get_state``, ``set_state``,
``deterministic_velocities``, ``dense_velocities``, ``roller_velocities``,
``preprocess``, ``postprocess``, ``invalid_bodies``, ``blob_positions``) and
never import the scripts or any global.  The random generator ``rng``
(``numpy.random.Generator``) is unused by the deterministic schemes here but
is part of the signature.

Body velocities have shape (Nb, 6) ``[v, w]`` (length/time, radians/time);
locations (Nb, 3); scalar-first quaternions (Nb, 4), updated by
``q_new = from_rotation(w dt) q_old`` and not renormalised (SPEC section 3).

Invalid configurations (SPEC decision 2): when a deterministic step would
put a blob centre below the wall, retrying would give the same result, so
the scheme restores the start-of-step state, counts the attempt in
``invalid_configurations`` and raises ``InvalidConfiguration`` naming the
step and the bodies.  NaN velocities raise ``utils.SimulationStopped``.
"""
import numpy as np

from quaternion_integrator.quaternion import rotate_quaternions as _rotate_quaternions
from utils import SimulationStopped, UserInputError

__all__ = ['InvalidConfiguration', 'make_scheme', 'SCHEMES', 'STOCHASTIC_SCHEMES', 'euler_update']


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


class DeterministicForwardEuler(Scheme):
    """``x += U dt``, ``q = from_rotation(w dt) q`` with U from the iterative mobility solve."""
    name = 'deterministic_forward_euler'

    def velocities(self, system):
        return system.deterministic_velocities()


class DeterministicForwardEulerDenseAlgebra(DeterministicForwardEuler):
    """Forward Euler with the dense solve ``U = N (F - K^T M^{-1} slip)`` (cost O(N^3))."""
    name = 'deterministic_forward_euler_dense_algebra'

    def velocities(self, system):
        return system.dense_velocities()


class AdamsBashforthMixin:
    """Second order: first step forward Euler, then ``1.5 U_n - 0.5 U_{n-1}`` (U_{n-1} stored on acceptance).

    ``previous_velocities`` may be set before the first step to continue a
    run (None starts with an Euler step, as the published code does).
    """
    previous_velocities = None

    def combine(self, velocities):
        if self.previous_velocities is None:
            return velocities
        return 1.5 * velocities - 0.5 * self.previous_velocities

    def accept(self, velocities):
        self.previous_velocities = np.array(velocities, copy=True)

    def get_history(self):
        history = super().get_history()
        history['previous_velocities'] = None if self.previous_velocities is None else self.previous_velocities.copy()
        return history

    def set_history(self, history):
        super().set_history(history)
        if history and history.get('previous_velocities') is not None:
            self.previous_velocities = np.array(history['previous_velocities'], copy=True)


class DeterministicAdamsBashforth(AdamsBashforthMixin, DeterministicForwardEuler):
    name = 'deterministic_adams_bashforth'


class DeterministicForwardEulerRollers(Scheme):
    """Single-blob rollers: ``r += v dt`` with v of ``System.roller_velocities`` (orientation fixed)."""
    name = 'deterministic_forward_euler_rollers'
    rollers = True

    def velocities(self, system):
        return system.roller_velocities()


class DeterministicAdamsBashforthRollers(AdamsBashforthMixin, DeterministicForwardEulerRollers):
    name = 'deterministic_adams_bashforth_rollers'


SCHEMES = {cls.name: cls for cls in (DeterministicForwardEuler, DeterministicForwardEulerDenseAlgebra,
                                     DeterministicAdamsBashforth, DeterministicForwardEulerRollers,
                                     DeterministicAdamsBashforthRollers)}

def _all_schemes():
    from quaternion_integrator.stochastic_schemes import STOCHASTIC_SCHEME_CLASSES
    schemes = dict(SCHEMES)
    schemes.update({cls.name: cls for cls in STOCHASTIC_SCHEME_CLASSES})
    return schemes


STOCHASTIC_SCHEMES = ('stochastic_first_order_RFD', 'stochastic_adams_bashforth',
                      'stochastic_first_order_RFD_dense_algebra', 'stochastic_traction_EM', 'Fixman',
                      'stochastic_Slip_Trapz', 'stochastic_traction_AB', 'stochastic_Slip_Mid',
                      'stochastic_Slip_Mid_DLA', 'stochastic_first_order_rollers', 'stochastic_adams_bashforth_rollers',
                      'stochastic_mid_point_rollers', 'stochastic_trapezoidal_rollers')


def make_scheme(name, dt, options=None):
    """The scheme object for the manual's name ``name`` with time step ``dt``.

    ``options`` (the input options) gives the stochastic schemes ``kT``,
    ``rf_delta`` and ``update_PC``.  Raises UserInputError for an unknown
    name (the message lists the known ones).
    """
    schemes = _all_schemes()
    if name in SCHEMES:
        return SCHEMES[name](dt)
    if name in schemes:
        return schemes[name](dt, options)
    raise UserInputError("unknown scheme '%s'; known schemes: %s" % (name, ', '.join(schemes)))
