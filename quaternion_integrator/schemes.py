"""Time-stepping schemes of the manual, behind one registry keyed by the scheme name.

A scheme object is made once per run by ``make_scheme(name, dt)``;
``scheme.advance(system, configuration, step_index, rng)`` returns the
configuration one step of length ``dt`` later and ``scheme.step(system,
step_index, rng)`` applies it to the system's current configuration.  The
*system* (``multi_bodies.solver.system.System``) is passed in; schemes only
use its methods, each of which takes the configuration it is about
(``deterministic_velocities``, ``dense_velocities``, ``roller_velocities``,
``forces_and_slip``, ``mobility_problem``, ``solve``, ``preprocess``,
``postprocess``, ``invalid_bodies``, ``blob_positions``) and never import
the scripts or any global.  The random generator ``rng``
(``numpy.random.Generator``) is unused by the deterministic schemes here but
is part of the signature.

Body velocities have shape (Nb, 6) ``[v, w]`` (length/time, radians/time);
locations (Nb, 3); scalar-first quaternions (Nb, 4), updated by
``q_new = from_rotation(w dt) q_old`` and not renormalised (SPEC section 3).

Invalid configurations (SPEC decision 2): when a deterministic step would
put a blob centre below the wall, retrying would give the same result, so
the scheme keeps the start-of-step configuration, counts the attempt in
``invalid_configurations`` and raises ``InvalidConfiguration`` naming the
step and the bodies.  NaN velocities raise ``utils.SimulationStopped``.
"""
import numpy as np

from quaternion_integrator.scheme_base import (InvalidConfiguration, Scheme, euler_update,  # noqa: F401
                                               rotate_quaternions)
from quaternion_integrator.stochastic_schemes import STOCHASTIC_SCHEME_CLASSES
from quaternion_integrator.articulated_schemes import ARTICULATED_SCHEME_CLASSES
from utils import UserInputError

__all__ = ['InvalidConfiguration', 'make_scheme', 'SCHEMES', 'STOCHASTIC_SCHEMES', 'euler_update']


class DeterministicForwardEuler(Scheme):
    """``x += U dt``, ``q = from_rotation(w dt) q`` with U from the iterative mobility solve."""
    name = 'deterministic_forward_euler'

    def velocities(self, system, configuration):
        return self.rigid_velocities(system, configuration)


class DeterministicForwardEulerDenseAlgebra(DeterministicForwardEuler):
    """Forward Euler with the dense solve ``U = N (F - K^T M^{-1} slip)`` (cost O(N^3))."""
    name = 'deterministic_forward_euler_dense_algebra'

    def velocities(self, system, configuration):
        return system.dense_velocities(configuration)


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

    def velocities(self, system, configuration):
        return self.roller_velocities(system, configuration)


class DeterministicAdamsBashforthRollers(AdamsBashforthMixin, DeterministicForwardEulerRollers):
    name = 'deterministic_adams_bashforth_rollers'


SCHEMES = {cls.name: cls for cls in (DeterministicForwardEuler, DeterministicForwardEulerDenseAlgebra,
                                     DeterministicAdamsBashforth, DeterministicForwardEulerRollers,
                                     DeterministicAdamsBashforthRollers)}
SCHEMES.update({cls.name: cls for cls in ARTICULATED_SCHEME_CLASSES})  # joints: doc/articulated.md

def _all_schemes():
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
