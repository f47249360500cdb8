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
Forces and torques are the run's (``multi_bodies_functions`` and the user's hooks).

A step that would put a sphere below the wall or move one more than ``2a`` is rejected as published:
the configuration stays, the step counts (the time advances), the rejection is counted in
``invalid_configurations`` and printed; it is not retried.  Draws per step (kT > 0): the near-field W
(6N), the far-field W (6N), the RFD direction (6N).
"""
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

    def wall_and_backend(self, work):
        """(wall, far-field backend name) of the run: from ``mobility_vector_prod_implementation``."""
        name = work.vector_product_name
        return not name.endswith('_no_wall'), name

    def settings(self, work):
        """:class:`lubrication.brownian.LubricationSettings` of the run (radius, viscosity, wall, box)."""
        wall, name = self.wall_and_backend(work)
        return brownian.lubrication_settings(work.blob_radius, work.eta, wall=wall,
                                             cutoff=self.cutoff, periodic_length=work.periodic_length,
                                             firm_delta=self.firm_delta, implementation=name,
                                             handover=self.handover, rfd_delta=self.delta)

    def init(self, model, configuration, step=0, history=None, counters=None):
        """As :meth:`Scheme.init`, after :meth:`check_spheres` of the model: a run refused here has written nothing."""
        self.check_spheres(model)
        return super().init(model, configuration, step=step, history=history, counters=counters)

    def check_spheres(self, work):
        """UserInputError unless every body is one blob, all of radius ``blob_radius``, without slip (``work``: the
        step's work or the model, which both have ``num_blobs``, ``num_bodies``, ``has_slip`` and ``domain``)."""
        if work.num_blobs != work.num_bodies:
            raise UserInputError('scheme %s: every body must be a single blob (a sphere; .vertex file with one '
                                 'blob at 0 0 0); the structures have %d blobs for %d bodies'
                                 % (self.name, work.num_blobs, work.num_bodies))
        if work.has_slip:
            raise UserInputError('scheme %s: the spheres cannot have slip (remove the .slip files and slip '
                                 'functions)' % self.name)

    def attempt(self, work, step_index, rng, old):
        self.check_spheres(work)
        settings = self.settings(work)

        def force_torque_at(locations, orientations):
            _, force_torque, _ = work.forces_and_slip(Configuration(locations, orientations))
            force_torque = np.array(force_torque, dtype=float).reshape(-1, 6)
            if self.firm_strength != 0:
                force_torque[:, :3] += firm_repulsion_forces(locations, work.blob_radius, self.firm_strength,
                                                             self.firm_delta, work.periodic_length)
            return self.add_torques(work, force_torque)
        kept = self.kept_solves(work, settings)
        step = type(self).step_function(settings, old.locations, old.orientations, force_torque_at, self.kT,
                                        self.dt, rng, work.tolerance, kept=kept, **self.prescribed_rotation(work))
        self.keep(work, kept)
        counts = step.counts
        work.count(gmres_iterations=counts['gmres_iterations'], lanczos_iterations=counts['lanczos_iterations'])
        work.last_iterations = counts['gmres_iterations']
        if step.rejected_wall or step.rejected_jump:
            work.count(invalid_configurations=1)
            print('Rejected step %d (%s): %s; the configuration is kept (invalid configuration number %d)'
                  % (step_index, self.name, 'a sphere below the wall' if step.rejected_wall
                     else 'a sphere would move more than 2 blob_radius', work.total('invalid_configurations')))
            return old, np.zeros((work.num_bodies, 6))
        return Configuration(step.locations, step.orientations), step.velocities


    @staticmethod
    def kept_solves(work, settings):
        """The :class:`lubrication.integrators.KeptSolves` of the run state (``preconditioner auto`` or
        ``neighbours``), or None: under ``block_diagonal`` every solve is the published one (its preconditioner
        built at its configuration, from zero).  The run state's fields of the kept preconditioner (where it was
        built, its solves and fewest iterations, the object as a cache) and its first guesses (``first_guess``:
        velocities at kT = 0; ``roller_torque_guess``: the torque problem's unknowns) hold them between steps."""
        if getattr(work.model, 'published_solves', True):
            return None
        where = work.preconditioner_configuration
        return integrators.KeptSolves(
            settings, work.tolerance, None if where is None else (where.locations, where.orientations),
            work.preconditioner_solves, work.preconditioner_fewest, work.preconditioner, work.first_guess,
            work.roller_torque_guess)

    @staticmethod
    def keep(work, kept):
        """Put what ``kept`` (a KeptSolves or None) holds after a step back into the step's run state."""
        if kept is None:
            return
        work.preconditioner_configuration = None if kept.built_at is None else Configuration(*kept.built_at)
        work.preconditioner_solves, work.preconditioner_fewest = kept.solves, kept.fewest
        work.preconditioner = kept.built or None
        work.first_guess, work.roller_torque_guess = kept.velocity_guess, kept.torque_guess

    def add_torques(self, work, force_torque):
        """Extra torques of the scheme (N, 6) -> (N, 6): none here."""
        return force_torque

    def prescribed_rotation(self, work):
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

    def wall_and_backend(self, work):
        name = work.vector_product_name
        base = name[:-len('_no_wall')] if name.endswith('_no_wall') else name
        wall = work.domain != 'no_wall'
        return wall, base + ('' if wall else '_no_wall')

    def check_spheres(self, work):
        super().check_spheres(work)
        if work.domain not in ('single_wall', 'no_wall'):
            raise UserInputError('scheme %s: domain %s is not available with lubrication; use single_wall or '
                                 'no_wall' % (self.name, work.domain))

    def add_torques(self, work, force_torque):
        if work.free_kinematics:
            force_torque[:, 3:] += 8.0 * np.pi * work.eta * work.blob_radius ** 3 * work.omega_one_roller
        return force_torque

    def prescribed_rotation(self, work):
        return {} if work.free_kinematics else {'omega': np.array(work.omega_one_roller, dtype=float)}


LUBRICATION_SCHEME_CLASSES = (LubricationTrapezoidal, LubricationEulerMaruyama, LubricationTrapezoidalRollers)
