"""Lubrication schemes of ``multi_bodies.py`` (floor 5): spheres of one radius with the near-field
corrections of :mod:`lubrication` (doc/lubrication.md).

* ``lubrication_trapezoidal`` - the published stochastic trapezoidal predictor-corrector
  (:func:`lubrication.integrators.trapezoidal_step`: same noise in predictor and corrector, far-field RFD
  in the corrector; Heun's method at kT = 0);
* ``lubrication_EM`` - Euler-Maruyama with the random finite difference of M_lub
  (:func:`lubrication.integrators.euler_maruyama_step`);
* ``lubrication_trapezoidal_rollers`` - the trapezoidal scheme for rollers driven about
  ``omega_one_roller``: with ``free_kinematics False`` every sphere spins at that rate (the torques of
  :func:`lubrication.integrators.torque_from_omega`, recomputed at the predictor), with ``True`` every
  sphere feels the torque ``8 pi eta a^3 omega_one_roller`` (as the package's roller schemes); the wall
  or not from ``domain`` (``single_wall`` or ``no_wall``), as for the other roller schemes.

Every body must be one blob (a sphere of radius ``blob_radius``, e.g. a ``.vertex`` file with the single
line ``0 0 0``), without slip.  Options: ``Lub_Cut`` (pair cutoff, units of a), ``firm_delta`` (gap clamp,
units of a), ``repulsion_strength_firm`` (the examples' firm pair repulsion, added to the forces when
not 0; :mod:`lubrication.firm_repulsion`), ``lubrication_handover`` (``published`` or ``smooth``,
:mod:`lubrication.resistance`), ``kT``, ``rf_delta`` (the RFD step, absolute as published),
``solver_tolerance``; the wall or not from ``mobility_vector_prod_implementation`` (``*_no_wall``).
Forces and torques are the run's (``multi_bodies_functions`` and the user's hooks).  Every solve goes through the
step context's solver: counted, and a solve that does not converge stops the run with one line (the published
code used it as if it had converged).

A step that would put a sphere below the wall or move one more than ``2a`` is rejected as published:
the configuration stays, the step counts (the time advances), the rejection is counted in
``invalid_configurations`` and printed; it is not retried.  Draws per step (kT > 0): the near-field W
(6N), the far-field W (6N), the RFD direction (6N).
"""
from dataclasses import replace

import numpy as np

from body.body import Configuration
from lubrication import brownian, integrators
from lubrication.firm_repulsion import firm_repulsion_forces
from multi_bodies.files.input_options import options_with
from quaternion_integrator.stochastic_schemes import StochasticScheme
from utils import UserInputError


class LubricationScheme(StochasticScheme):
    """Common part of the lubrication schemes: settings from the model and the options, forces, counts."""
    step_function = None

    def __init__(self, dt, options=None):
        super().__init__(dt, options)
        options = options_with() if options is None else options
        self.cutoff = float(options.Lub_Cut)
        self.firm_delta = float(options.firm_delta)
        self.firm_strength = float(options.repulsion_strength_firm)
        self.handover = options.lubrication_handover

    def wall_and_backend(self, model):
        """(wall, far-field backend name) of the run: from ``mobility_vector_prod_implementation``."""
        name = model.vector_product_name
        return not name.endswith('_no_wall'), name

    def settings(self, model):
        """:class:`lubrication.brownian.LubricationSettings` of the run (radius, viscosity, wall, box)."""
        wall, name = self.wall_and_backend(model)
        return brownian.lubrication_settings(model.blob_radius, model.eta, wall=wall,
                                             cutoff=self.cutoff, periodic_length=model.periodic_length,
                                             firm_delta=self.firm_delta, implementation=name,
                                             handover=self.handover, rfd_delta=self.delta)

    def init(self, model, configuration, step=0, history=None, counters=None, rng_state=None):
        """As :meth:`Scheme.init`, after :meth:`check_spheres` of the model: a run refused here has written nothing."""
        self.check_spheres(model)
        return super().init(model, configuration, step=step, history=history, counters=counters,
                            rng_state=rng_state)

    def check_spheres(self, model):
        """UserInputError unless every body is one blob, all of radius ``blob_radius``, without slip."""
        if model.num_blobs != model.num_bodies:
            raise UserInputError('scheme %s: every body must be a single blob (a sphere; .vertex file with one '
                                 'blob at 0 0 0); the structures have %d blobs for %d bodies'
                                 % (self.name, model.num_blobs, model.num_bodies))
        if model.has_slip:
            raise UserInputError('scheme %s: the spheres cannot have slip (remove the .slip files and slip '
                                 'functions)' % self.name)

    def attempt(self, context, state, old):
        model = context.model
        self.check_spheres(model)
        settings = self.settings(model)
        start = state

        def force_torque_at(locations, orientations):
            nonlocal state
            (_, force_torque, _), state = context.forces_and_slip(state, Configuration(locations, orientations))
            force_torque = np.array(force_torque, dtype=float).reshape(-1, 6)
            if self.firm_strength != 0:
                force_torque[:, :3] += firm_repulsion_forces(locations, model.blob_radius, self.firm_strength,
                                                             self.firm_delta, model.periodic_length)
            return self.add_torques(model, force_torque)
        kept = self.kept_solves(model, state, settings)
        step = type(self).step_function(settings, old.locations, old.orientations, force_torque_at, self.kT,
                                        self.dt, context.rng, model.tolerance, kept=kept, solver=context.solver,
                                        **self.prescribed_rotation(model))
        state = self.keep(state, kept)
        counts = step.counts  # the GMRES iterations are counted by the solver
        context.count(lanczos_iterations=counts['lanczos_iterations'])
        context.tally.last_iterations = counts['gmres_iterations']  # the progress line: all of the step's
        if step.rejected_wall or step.rejected_jump:
            context.count(invalid_configurations=1)
            print('Rejected step %d (%s): %s; the configuration is kept (invalid configuration number %d)'
                  % (context.step, self.name, 'a sphere below the wall' if step.rejected_wall
                     else 'a sphere would move more than 2 blob_radius', context.total(start, 'invalid_configurations')))
            return old, np.zeros((context.num_bodies, 6)), state
        return Configuration(step.locations, step.orientations), step.velocities, state


    @staticmethod
    def kept_solves(model, state, settings):
        """The :class:`lubrication.integrators.KeptSolves` of the run state (``preconditioner auto`` or
        ``neighbours``), or None: under ``block_diagonal`` every solve is the published one (its preconditioner
        built at its configuration, from zero).  The run state's fields of the kept preconditioner (where it was
        built, its solves and fewest iterations, the object as a cache) and its first guesses (``first_guess``:
        velocities at kT = 0; ``roller_torque_guess``: the torque problem's unknowns) hold them between steps."""
        if model.published_solves:
            return None
        where = state.preconditioner_configuration
        return integrators.KeptSolves(
            settings, model.tolerance, None if where is None else (where.locations, where.orientations),
            state.preconditioner_solves, state.preconditioner_fewest, state.preconditioner, state.first_guess,
            state.roller_torque_guess)

    @staticmethod
    def keep(state, kept):
        """``state`` holding what ``kept`` (a KeptSolves or None) holds after a step."""
        if kept is None:
            return state
        return replace(state, preconditioner_configuration=None if kept.built_at is None
                       else Configuration(*kept.built_at),
                       preconditioner_solves=kept.solves, preconditioner_fewest=kept.fewest,
                       preconditioner=kept.built or None, first_guess=kept.velocity_guess,
                       roller_torque_guess=kept.torque_guess)

    def add_torques(self, model, force_torque):
        """Extra torques of the scheme (N, 6) -> (N, 6): none here."""
        return force_torque

    def prescribed_rotation(self, model):
        """Keywords of the step function for a prescribed rotation rate: none here."""
        return {}


class LubricationTrapezoidal(LubricationScheme):
    """The published stochastic trapezoidal predictor-corrector with lubrication (``Update_Bodies_Trap``)."""
    name = 'lubrication_trapezoidal'
    step_function = staticmethod(integrators.trapezoidal_step)


class LubricationEulerMaruyama(LubricationScheme):
    """Euler-Maruyama with lubrication and the random finite difference of M_lub."""
    name = 'lubrication_EM'
    step_function = staticmethod(integrators.euler_maruyama_step)


class LubricationTrapezoidalRollers(LubricationTrapezoidal):
    """The trapezoidal scheme for rollers spun about ``omega_one_roller`` (see the module note)."""
    name = 'lubrication_trapezoidal_rollers'

    def wall_and_backend(self, model):
        name = model.vector_product_name
        base = name[:-len('_no_wall')] if name.endswith('_no_wall') else name
        wall = model.domain != 'no_wall'
        return wall, base + ('' if wall else '_no_wall')

    def check_spheres(self, model):
        super().check_spheres(model)
        if model.domain not in ('single_wall', 'no_wall'):
            raise UserInputError('scheme %s: domain %s is not available with lubrication; use single_wall or '
                                 'no_wall' % (self.name, model.domain))

    def add_torques(self, model, force_torque):
        if model.free_kinematics:
            force_torque[:, 3:] += 8.0 * np.pi * model.eta * model.blob_radius ** 3 * model.omega_one_roller
        return force_torque

    def prescribed_rotation(self, model):
        return {} if model.free_kinematics else {'omega': np.array(model.omega_one_roller, dtype=float)}


LUBRICATION_SCHEME_CLASSES = (LubricationTrapezoidal, LubricationEulerMaruyama, LubricationTrapezoidalRollers)
