"""Time-stepping schemes of the manual, keyed by their names in the scheme registry.

The registry (``multi_bodies.files.scheme_table``: name, kind, what the scheme needs) says which schemes exist
and what each is; this module holds the class of each (``SCHEMES``) and makes them.

A scheme object (the rule of a step and its parameters, no state) is made
once per run by ``make_scheme(name, dt)``; ``scheme.init(model,
configuration)`` makes the run state and ``scheme.step(model, state)``
returns the state one step of length ``dt`` later
(``quaternion_integrator.scheme_state.RunState``).  The *model*
(``multi_bodies.solver.model.Model``, frozen) is passed in; schemes only use
its methods, each of which takes the configuration it is about
(``dense_velocities``, ``mobility_problem``, ``preprocess``,
``postprocess``, ``invalid_bodies``, ``blob_positions``), as
``context.model`` of the step's ``StepContext``, whose counted operations
(``solve``, ``deterministic_velocities``, ``roller_velocities``,
``forces_and_slip``, ``lanczos_noise``, ...) are the only way to a solve;
they never import the scripts or any global.  The random generator
(anything with ``standard_normal(n)``: numpy's ``Generator`` or
``stochastic_forcing.generators.PublishedGenerator``) is the context's
``rng``, made from the state's ``rng_state`` or given to ``step``; the
deterministic schemes here do not draw from it.

Body velocities have shape (Nb, 6) ``[v, w]`` (length/time, radians/time);
locations (Nb, 3); scalar-first quaternions (Nb, 4), updated by
``q_new = from_rotation(w dt) q_old`` and not renormalised (SPEC section 3).

Invalid configurations (SPEC decision 2): when a deterministic step would
put a blob centre below the wall, retrying would give the same result, so
the scheme keeps the start-of-step configuration, counts the attempt in
``invalid_configurations`` and raises ``InvalidConfiguration`` naming the
step and the bodies.  NaN velocities raise ``utils.SimulationStopped``.
"""
from dataclasses import replace

import numpy as np

from multi_bodies.files.scheme_table import scheme_entry, scheme_names
from quaternion_integrator.scheme_base import (InvalidConfiguration, Scheme, euler_update,  # noqa: F401
                                               rotate_quaternions)
from quaternion_integrator.stochastic_schemes import RIGID_STOCHASTIC_SCHEME_CLASSES
from quaternion_integrator.roller_schemes import ROLLER_SCHEME_CLASSES
from quaternion_integrator.articulated_schemes import ARTICULATED_SCHEME_CLASSES
from quaternion_integrator.lubrication_schemes import LUBRICATION_SCHEME_CLASSES
from utils import UserInputError

__all__ = ['InvalidConfiguration', 'make_scheme', 'SCHEMES', 'STOCHASTIC_SCHEMES', 'euler_update']


class DeterministicForwardEuler(Scheme):
    """``x += U dt``, ``q = from_rotation(w dt) q`` with U from the iterative mobility solve."""
    name = 'deterministic_forward_euler'
    extrapolate_guesses = True  # one solve per step (midpoint: two, dt/2 apart)
    keep_preconditioner = True

    def velocities(self, context, state, configuration):
        return self.rigid_velocities(context, state, configuration)


class DeterministicForwardEulerDenseAlgebra(DeterministicForwardEuler):
    """Forward Euler with the dense solve ``U = N (F - K^T M^{-1} slip)`` (cost O(N^3))."""
    name = 'deterministic_forward_euler_dense_algebra'

    def velocities(self, context, state, configuration):
        return context.model.dense_velocities(configuration), state


class AdamsBashforthMixin:
    """Second order: first step forward Euler, then ``1.5 U_n - 0.5 U_{n-1}`` (U_{n-1} kept in the run state
    on acceptance; a state without it starts with an Euler step, as the published code does).
    """

    def combine(self, state, velocities):
        if state.previous_velocities is None:
            return velocities
        return 1.5 * velocities - 0.5 * state.previous_velocities

    def accept(self, state, velocities):
        return replace(state, previous_velocities=np.array(velocities, copy=True))


class DeterministicAdamsBashforth(AdamsBashforthMixin, DeterministicForwardEuler):
    name = 'deterministic_adams_bashforth'


class DeterministicMidpoint(DeterministicForwardEuler):
    """Explicit midpoint (second order): ``U1 = U(q^n)``, ``q* = q^n + U1 dt/2``, ``q^{n+1} = q^n + U(q*) dt``.

    Two iterative solves per step (each warm started from the last).  A
    midpoint with a blob centre below the wall stops the run like an
    invalid step (InvalidConfiguration naming the step and the bodies).
    """
    name = 'deterministic_midpoint'

    def velocities(self, context, state, configuration):
        U1, state = self.rigid_velocities(context, state, configuration)
        mid = self.move(configuration, U1, 0.5 * self.dt)
        invalid = context.model.invalid_bodies(mid)
        if invalid.size:
            context.count(invalid_configurations=1)
            raise InvalidConfiguration(context.step, invalid, self.name)
        return self.rigid_velocities(context, state, mid)


class DeterministicForwardEulerRollers(Scheme):
    """Single-blob rollers: ``r += v dt`` with v of ``Model.roller_velocities`` (orientation fixed)."""
    name = 'deterministic_forward_euler_rollers'

    def velocities(self, context, state, configuration):
        return self.roller_velocities(context, state, configuration)


class DeterministicAdamsBashforthRollers(AdamsBashforthMixin, DeterministicForwardEulerRollers):
    name = 'deterministic_adams_bashforth_rollers'


# The class of every dynamic scheme, keyed by its name in the scheme registry (multi_bodies.files.scheme_table),
# which says what each needs; a class without an entry or an entry without a class stops the import.
SCHEMES = {cls.name: cls for cls in (DeterministicForwardEuler, DeterministicForwardEulerDenseAlgebra,
                                     DeterministicAdamsBashforth, DeterministicMidpoint, DeterministicForwardEulerRollers,
                                     DeterministicAdamsBashforthRollers)
           + ARTICULATED_SCHEME_CLASSES  # joints: doc/articulated.md
           + RIGID_STOCHASTIC_SCHEME_CLASSES + ROLLER_SCHEME_CLASSES
           + LUBRICATION_SCHEME_CLASSES}  # lubrication: doc/lubrication.md
_unregistered = set(SCHEMES) ^ set(scheme_names(dynamic=True))
if _unregistered:
    raise ImportError('scheme classes and the scheme registry (multi_bodies/files/scheme_table.py) disagree on %s'
                      % ', '.join(sorted(_unregistered)))


def _all_schemes():
    """Name -> class of every dynamic scheme (a copy of :data:`SCHEMES`)."""
    return dict(SCHEMES)


STOCHASTIC_SCHEMES = scheme_names(kind='stochastic')
# Schemes that solve the mixed problem of bodies of prescribed kinematics (obstacles, velocity files).
SCHEMES_WITH_OBSTACLES = scheme_names(obstacles=True, dynamic=True)


def check_fixed_bodies_supported(name, options):
    """Refuse (UserInputError) obstacles or prescribed velocities with a scheme that does not solve the mixed problem."""
    if options is None or name in SCHEMES_WITH_OBSTACLES:
        return
    specs = list(options.structures) + list(options.obstacles)
    fixed = [spec for spec in specs if getattr(spec, 'obstacle', False)
             or getattr(spec, 'velocity_file', None) is not None]
    if not fixed or name not in SCHEMES:
        return
    where = options.where
    raise UserInputError(
        "%s: scheme %s does not support obstacles or bodies of prescribed velocity (%s: %s line); use "
        "stochastic_Slip_Trapz or stochastic_Slip_Mid for a stochastic run (or a deterministic scheme: %s)"
        % (where('scheme'), name, fixed[0].where, 'obstacle' if fixed[0].obstacle else 'structure',
           ', '.join(SCHEMES_WITH_OBSTACLES[:3])))


def make_scheme(name, dt, options=None):
    """The scheme object for the manual's name ``name`` with time step ``dt``.

    ``options`` (the input options) gives the stochastic schemes ``kT``,
    ``rf_delta`` and ``update_PC``.  Raises UserInputError for an unknown
    name (the message lists the known ones).
    """
    entry = scheme_entry(name)
    if entry is None or entry.kind == 'static':
        raise UserInputError("unknown scheme '%s'; known schemes: %s" % (name, ', '.join(SCHEMES)))
    check_fixed_bodies_supported(name, options)
    if entry.kind == 'stochastic':
        return SCHEMES[name](dt, options)
    return SCHEMES[name](dt)
