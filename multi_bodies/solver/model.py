"""The model of a run: everything fixed for the run, frozen (floor 4).

A ``Model`` holds every body's structure as contiguous arrays (``BodyArrays``),
the backends chosen once at set-up (the blob mobilities, each a
``mobility.interface.BlobMobility``: ``vector_mobility`` for matrix-free
``M f`` and the roller couplings, ``blobs_mobility`` for the dense blocks of
the preconditioner and the dense schemes; blob-blob and body-body forces), the
physics hooks of the run (defaults of ``multi_bodies_functions`` or the
user's overrides), the tolerances, the joints of articulated bodies and
whether the wall is seen.  It can

* compute blob positions, forces and torques (SPEC section 7) and slip;
* build the problems of the package at a configuration (rigid, mixed,
  articulated, rollers: one protocol, ``body_solver.solve``) and solve them
  (SPEC 4.2, GMRES with the block-diagonal preconditioner of 4.3), or their
  dense variants;
* give roller velocities (SPEC 5.2);
* say which bodies have a blob centre below the wall.

Every one of these takes the configuration it is about
(``body.body.Configuration``) as an argument and returns what it computed,
with its counts (GMRES and Lanczos iterations): the model holds no
configuration, no counter and no history.  The run's state (configuration,
scheme history, counters) is a value the time loop passes along
(``quaternion_integrator.scheme_state.RunState``).  Nothing can be assigned
to a model after its construction; :meth:`Model.replace` builds a variant
(the advisor compares models built this way).

Units: the user's; lengths as the input file, velocities length/time,
forces force units, ``eta`` viscosity.
"""
import copy

import numpy as np

from body.body import Configuration, as_configuration, reference_slip_in_lab_frame
from body.geometry import Quaternion
from mobility.interface import (BlobMobility, Geometry, from_implementation_name, implementation_geometry,
                                make_mobility, published_function, registered_backends)
from multi_bodies.files.input_options import DEFAULTS  # Model's keyword defaults are the option table's
from multi_bodies.files.scheme_table import moves_rollers
from multi_bodies.solver import body_solver, noise_factor, obstacles, periodic, rollers
from multi_bodies.solver import user_hooks
from multi_bodies.solver import physics as mbf
from multi_bodies.solver.body_solver import check_finite  # noqa: F401  (re-exported: its callers' name)
from multi_bodies.solver.neighbour_preconditioner import AUTO_MAX_COST_RATIO, NeighbourPreconditioner
from multi_bodies.solver.solves import LANCZOS_MAX_ITERATIONS, Solver, warn_if_not_converged
from utils import UserInputError, warn_user

# the GMRES preconditioners (option ``preconditioner``; doc/preconditioners.md)
PRECONDITIONERS = ('auto', 'neighbours', 'block_diagonal')

NO_WALL = '_no_wall'

# ------------------------------------------------------------------ backend choice
def resolve_implementation(name, kind='vector_product', log=None, num_blobs=None):
    """Turn ``auto`` / ``auto_no_wall`` into the fastest backend usable here.

    kinds 'vector_product' and 'blobs' (dense matrices, CPU only): the backend
    of smallest cost measured on this machine at ``num_blobs`` blobs
    (``mobility.choose``); 'forces': the first backend of the mobility
    registry's preference order (``mobility.interface.PREFERENCE``: the same
    devices, pycuda, C++, python) whose blob-blob forces run here.  Other
    names are returned unchanged.  ``log`` (callable) is told the choice.
    """
    if name not in ('auto', 'auto' + NO_WALL):
        return name
    suffix = name[len('auto'):]
    if kind != 'forces':
        from mobility import choose
        chosen = choose.choose_backend(kind, num_blobs, wall=not suffix, log=log) + suffix
        if log is not None:
            log('%s: auto chose %s (smallest measured cost here)' % (kind, chosen))
        return chosen
    order = registered_backends()
    for backend in order:
        try:
            mbf.blob_blob_force_calculator(backend)
        except UserInputError:
            continue
        chosen = backend + suffix
        if log is not None:
            log('%s: auto chose %s (fastest usable here; order %s)' % (kind, chosen, ', '.join(order)))
        return chosen
    raise UserInputError('no usable backend for %s' % name)


# ------------------------------------------------------------------ the model
class Model:
    """Bodies as arrays, backends, physics and tolerances of one run: frozen (see module docstring).

    Parameters
    ----------
    bodies : list of body.body.Body
        In input order; only the hooks that take bodies use them (``Body`` objects are the published
        API's; the run's configuration is never read from them).
    body_arrays : body.body.BodyArrays
        The fixed structure of the bodies (its ``configuration`` is the one read from the input files).
    hooks : multi_bodies.solver.user_hooks.PhysicsHooks
    physics : dict
        Keywords of the hooks: g, repulsion_strength_wall, debye_length_wall, repulsion_strength,
        debye_length, periodic_length, blob_radius, blob_mass.
    eta, blob_radius, solver_tolerance : float
    vector_product_name, blobs_name, blob_blob_name, body_body_name : str
        Implementation names (``auto`` already resolved).  Every keyword that is an option of the input file
        defaults to the option table's default (``DEFAULTS``).
    periodic_length : (3,) floats
    omega_one_roller : (3,) floats, free_kinematics : bool, domain : str
        Roller parameters (SPEC 5.2).
    print_residual : bool
        Print every GMRES residual.
    articulated : multi_bodies.solver.articulated.ArticulatedSet or None
        The joints of articulated bodies (None without ``articulated`` lines).
    nonlinear_tolerance : float
        ``nonlinear_solver_tolerance`` of the joints' restoration.
    check_wall : bool
        Whether a blob centre below ``z = 0`` is invalid (False without a wall).
    lanczos_max_iterations : int
    vector_mobility, blobs_mobility : mobility.interface.BlobMobility or None
        Replace the mobilities of ``vector_product_name`` and ``blobs_name`` (benchmarks count products or
        change a mobility's capabilities this way); None is the backend's.
    pycuda_blob_blob_forces : callable or None
        The user's ``calc_blob_blob_forces_pycuda`` of a ``forces_pycuda_user_defined.py`` (None: the hooks').
    surface : multi_bodies.solver.surface.Surface or None
        Phoretic and slip-length data of the blobs (``.Laplace``, ``.slip_length`` files; doc/phoretic.md).
    spectral : multi_bodies.solver.periodic.SpectralDomain or None
        The periodic or confined domain of ``vector_product_name`` ``spectral`` (doc/periodic.md): it makes
        ``vector_mobility`` (force-only kernel), ``roller_mobility`` (kernel pair) and ``blobs_mobility`` (the
        preconditioners' blocks: ``blobs_name``'s backend in the domain's direct geometry), and says which
        configurations are invalid; None for the direct products.

    The blob mobilities (``mobility.interface.BlobMobility``, configured once with ``eta``, the blob radius or
    the vertex files' per-blob radii, and the box) are ``vector_mobility`` (``vector_product_name`` with
    ``periodic_length``: ``M f`` of the problems), ``blobs_mobility`` (``blobs_name``: the dense blocks of the
    preconditioners and the dense schemes, without periodic images, as they have always been built) and
    ``roller_mobility`` (the couplings of single-blob rollers: the vector-product backend in the geometry of
    ``domain``, one radius).  ``paired_mobility_product`` is ``vector_mobility.paired_velocities`` where the
    products of two threads are paired in one pass (C++ by its own name, one radius, no box), else None.

    Every attribute is set here; assigning one afterwards raises ``AttributeError`` (a model is a value:
    build another with :meth:`replace`).
    """

    def __init__(self, bodies, body_arrays, hooks, physics, eta, blob_radius, solver_tolerance,
                 vector_product_name=DEFAULTS.mobility_vector_prod_implementation,
                 blobs_name=DEFAULTS.mobility_blobs_implementation,
                 blob_blob_name=DEFAULTS.blob_blob_force_implementation,
                 body_body_name=DEFAULTS.body_body_force_torque_implementation,
                 periodic_length=DEFAULTS.periodic_length, omega_one_roller=DEFAULTS.omega_one_roller,
                 free_kinematics=DEFAULTS.free_kinematics, domain=DEFAULTS.domain, print_residual=False,
                 articulated=None, nonlinear_tolerance=DEFAULTS.nonlinear_solver_tolerance, check_wall=True,
                 lanczos_max_iterations=LANCZOS_MAX_ITERATIONS,
                 vector_mobility=None, blobs_mobility=None, pycuda_blob_blob_forces=None, surface=None,
                 preconditioner=DEFAULTS.preconditioner, lanczos_preconditioner=DEFAULTS.lanczos_preconditioner,
                 spectral=None):
        arguments = dict(locals())
        del arguments['self']
        set_ = object.__setattr__
        set_(self, '_arguments', arguments)
        set_(self, 'bodies', bodies)
        set_(self, 'arrays', body_arrays)
        set_(self, 'hooks', hooks)
        set_(self, 'physics', dict(physics))
        set_(self, 'eta', float(eta))
        set_(self, 'blob_radius', float(blob_radius))
        set_(self, 'tolerance', float(solver_tolerance))
        set_(self, 'periodic_length', np.asarray(periodic_length, dtype=float).reshape(3))
        set_(self, 'omega_one_roller', np.asarray(omega_one_roller, dtype=float).reshape(3))
        set_(self, 'free_kinematics', bool(free_kinematics))
        set_(self, 'domain', domain)
        set_(self, 'print_residual', print_residual)
        set_(self, 'articulated', articulated)
        set_(self, 'nonlinear_tolerance', float(nonlinear_tolerance))
        set_(self, 'check_wall', bool(check_wall))
        set_(self, 'lanczos_max_iterations', int(lanczos_max_iterations))
        set_(self, 'vector_product_name', vector_product_name)
        set_(self, 'blobs_name', blobs_name)
        radius = body_solver.blob_radius_argument(body_arrays, self.blob_radius)  # one number, or per-blob radii
        set_(self, 'spectral', spectral)
        if spectral is not None and np.ndim(radius):
            raise UserInputError('the spectral product has one kernel width: every blob needs the radius '
                                 'blob_radius (remove the fourth column of the vertex files)')
        if vector_mobility is None:
            vector_mobility = (spectral.mobility(self.eta, radius) if spectral is not None
                               else from_implementation_name(vector_product_name, self.eta, radius, self.periodic_length))
        if blobs_mobility is None:
            blobs_mobility = (spectral.block_mobility(blobs_name, self.eta, radius) if spectral is not None
                              else from_implementation_name(blobs_name, self.eta, radius, dense_matrices=True))
        set_(self, 'vector_mobility', vector_mobility)
        set_(self, 'blobs_mobility', blobs_mobility)
        # (M v1, M v2) in one pass over the pairs where the backend offers it under its own name (C++, C++_no_wall:
        # the aliases keep their products unpaired, so their runs repeat to the bit), else None
        set_(self, 'paired_mobility_product', self.vector_mobility.paired_velocities
             if vector_product_name in ('C++', 'C++' + NO_WALL) and self.vector_mobility.pairs_in_one_pass else None)
        set_(self, '_roller_mobility', None)  # made on first use (rollers.py): roller_mobility
        set_(self, 'blob_blob_name', blob_blob_name)
        set_(self, 'body_body_name', body_body_name)
        radii_given = bool(body_arrays.radii_given)
        set_(self, 'blob_blob_forces', mbf.blob_blob_force_calculator(
            blob_blob_name, pair_force=hooks.blob_blob_force,
            pycuda_forces=hooks.calc_blob_blob_forces_pycuda if pycuda_blob_blob_forces is None
            else pycuda_blob_blob_forces,
            python_forces=hooks.blob_blob_forces_python, radii_given=radii_given))
        # Per-blob radii reach the default blob-blob laws (contact a_i + a_j); a user's law gets blob_radius.
        blob_blob_physics = self.physics
        if radii_given and hooks.blob_blob_forces_python is None:
            blob_blob_physics = dict(self.physics, blob_radii=body_arrays.blob_radii)
        set_(self, 'blob_blob_physics', blob_blob_physics)
        set_(self, 'body_body_forces', mbf.body_body_force_calculator(
            body_body_name, pair_force_torque=hooks.body_body_force_torque,
            python_forces_torques=hooks.body_body_forces_python))
        # Bodies whose slip is a user function (set by set_slip_by_ID); the others use the vectorised slip.
        slip_function_bodies = [k for k, b in enumerate(bodies)
                                if b.function_slip is not reference_slip_in_lab_frame]
        set_(self, 'slip_function_bodies', slip_function_bodies)
        set_(self, 'slip_functions', bool(slip_function_bodies))
        set_(self, 'surface', surface)
        if preconditioner not in PRECONDITIONERS:
            raise ValueError('preconditioner %r: one of %s' % (preconditioner, ', '.join(PRECONDITIONERS)))
        set_(self, 'preconditioner', preconditioner)
        if lanczos_preconditioner not in noise_factor.LANCZOS_PRECONDITIONERS:
            raise ValueError('lanczos_preconditioner %r: one of %s'
                             % (lanczos_preconditioner, ', '.join(noise_factor.LANCZOS_PRECONDITIONERS)))
        set_(self, 'lanczos_preconditioner', lanczos_preconditioner)
        set_(self, 'has_slip', self.slip_functions or bool(np.any(body_arrays.reference_slip))
             or (surface is not None and surface.phoretic is not None))
        # Length scale of every body (Nb,) (largest blob distance plus 2a; the RFD scale), fixed structure.
        set_(self, 'body_lengths', np.array([1.0 if b.body_length is None else b.body_length for b in bodies],
                                            dtype=float))
        # Bodies of prescribed kinematics (obstacles, velocity files): (Nb,) bool and (Nb, 6) lab-frame [v, w].
        if any(getattr(b, 'prescribed_velocity', None) is not None for b in bodies):
            fixed_bodies, prescribed_velocities = obstacles.fixed_bodies_of(bodies)
        else:  # every body free
            fixed_bodies, prescribed_velocities = np.zeros(len(bodies), dtype=bool), np.zeros((len(bodies), 6))
        set_(self, 'fixed_bodies', fixed_bodies)
        set_(self, 'prescribed_velocities', prescribed_velocities)
        # The last preconditioner build's blocks of the bodies of prescribed kinematics, keyed by their exact blob
        # positions (obstacles.MixedPreconditioner): a memo of numbers that depend on those positions alone, so
        # obstacles that stay put are factored once; it changes no result, and each model has its own.
        set_(self, '_obstacle_memo', {})

    def __setattr__(self, name, value):
        raise AttributeError('a Model is frozen: %s cannot be assigned after construction (build another with '
                             'model.replace(%s=...))' % (name, name))

    def __delattr__(self, name):
        raise AttributeError('a Model is frozen: %s cannot be deleted' % name)

    @property
    def blob_mobility_matrix(self):
        """The published function form ``f(r (N, 3), eta, a) -> (3N, 3N)`` of ``blobs_mobility.dense_matrix`` (also
        stacks (nb, n, 3)), for scripts written against the functions."""
        return published_function(self.blobs_mobility, 'dense_matrix')

    stacked_mobility = blob_mobility_matrix

    @property
    def roller_mobility(self):
        """The couplings of single-blob rollers: the ``mobility_vector_prod_implementation`` backend in the
        geometry of ``domain`` (``in_plane``: :class:`rollers.InPlaneMobility` over the wall's), one blob radius,
        the run's box (made on first use: a free-surface name is refused only by the roller schemes)."""
        if self._roller_mobility is None and self.spectral is not None:  # the kernel pair: U and W in one product
            roller = self.spectral.mobility(self.eta, self.blob_radius, rotation=True)
            object.__setattr__(self, '_roller_mobility', rollers.InPlaneMobility(roller) if self.domain == 'in_plane'
                               else roller)
        if self._roller_mobility is None:
            backend, geometry = implementation_geometry(self.vector_product_name, self.periodic_length)
            if geometry.kind == 'free_surface':
                raise UserInputError('mobility_vector_prod_implementation %s: the roller schemes have no free-surface '
                                     'couplings; use a wall or _no_wall implementation' % self.vector_product_name)
            geometry = Geometry('free_space' if self.domain == 'no_wall' else 'single_wall', self.periodic_length)
            roller = make_mobility(backend, geometry, self.eta, self.blob_radius)
            object.__setattr__(self, '_roller_mobility', rollers.InPlaneMobility(roller) if self.domain == 'in_plane'
                               else roller)
        return self._roller_mobility

    @property
    def arguments(self):
        """The constructor arguments of this model (a new dict: name -> value)."""
        return dict(self._arguments)

    def replace(self, **changes):
        """A new model (of this one's class) with the constructor arguments ``changes`` (name -> value) and the
        others of this one."""
        unknown = set(changes) - set(self._arguments)
        if unknown:
            raise TypeError('Model has no argument %s' % ', '.join(sorted(unknown)))
        return type(self)(**dict(self._arguments, **changes))

    # -------------------------------------------------------------- structure
    @property
    def num_bodies(self):
        return self.arrays.num_bodies

    @property
    def num_blobs(self):
        return self.arrays.num_blobs

    @property
    def start_configuration(self):
        """The configuration read from the input files (a value; the run state holds the current one)."""
        return self.arrays.configuration

    def blob_positions(self, configuration):
        """Lab-frame blob positions at ``configuration``, shape (N, 3)."""
        return self.arrays.blob_positions(configuration)

    def bodies_at(self, configuration, writable=False):
        """The bodies as the published API's ``Body`` objects placed at ``configuration`` (for the user hooks).

        Fresh copies of the run's bodies (the model's are never moved): their ``location`` (3,) and
        ``orientation`` (a Quaternion) are those of ``configuration``, read-only unless ``writable`` (a hook
        that writes to them gets a clear error instead of a change the run would ignore).  Only
        ``postprocess``, which may move the bodies, gets writable copies.
        """
        views = []
        for template, location, orientation in zip(self.bodies, configuration.locations, configuration.orientations):
            body = copy.copy(template)
            body.location = np.array(location, dtype=float)
            body.orientation = Quaternion(orientation)
            if not writable:
                body.location.flags.writeable = False
                body.orientation.entries.flags.writeable = False
            views.append(body)
        return views

    def preprocess(self, configuration):
        """The user's ``preprocess(bodies)`` at ``configuration``, on read-only views (nothing with the default)."""
        if 'preprocess' in self.hooks.overridden:
            self.hooks.preprocess(self.bodies_at(configuration))

    def postprocess(self, configuration):
        """The configuration after the user's ``postprocess(bodies)`` on writable copies of the bodies at
        ``configuration`` (``configuration`` itself with the default)."""
        if 'postprocess' not in self.hooks.overridden:
            return configuration
        bodies = self.bodies_at(configuration, writable=True)
        self.hooks.postprocess(bodies)
        return Configuration(np.array([b.location for b in bodies]), np.array([b.orientation.entries for b in bodies]))

    def invalid_bodies(self, configuration, r_vectors=None):
        """Indices of bodies with a blob centre below the wall (z < 0) at ``configuration`` (empty without a wall).

        With the spectral product, the domain's walls (also the top wall of a slit); a blob leaving the heights of
        the spectral grid stops the run (``SpectralDomain.invalid_bodies``)."""
        if not self.check_wall:
            return np.zeros(0, dtype=int)
        r_vectors = self.blob_positions(configuration) if r_vectors is None else r_vectors
        if self.spectral is not None:
            return self.spectral.invalid_bodies(self.arrays, r_vectors)
        return self.arrays.check_positions(r_vectors)

    # -------------------------------------------------------------- physics
    def blob_forces(self, r_vectors):
        """One-blob plus blob-blob forces at blob positions (N, 3), shape (N, 3)."""
        forces = np.asarray(self.hooks.blob_external_forces(r_vectors, **self.physics), dtype=float).reshape(-1, 3)
        if self.blob_blob_forces is not None:
            forces = forces + np.asarray(self.blob_blob_forces(r_vectors, **self.blob_blob_physics)).reshape(-1, 3)
        return forces

    def forces_torques(self, configuration, r_vectors=None):
        """Force and torque on every body at ``configuration``, shape (Nb, 6) = ``[F, T]`` (SPEC section 7).

        ``r_vectors`` (N, 3): the blob positions of that configuration when the caller has them.  A folder's own
        ``multi_bodies_functions.py`` (``hooks.force_torque_calculator``, doc/periodic.md) gives them all instead.
        """
        r_vectors = self.blob_positions(configuration) if r_vectors is None else r_vectors
        folder_calculator = getattr(self.hooks, 'force_torque_calculator', None)
        if folder_calculator is not None:
            return folder_calculator(self.bodies_at(configuration), r_vectors).reshape(-1, 6)
        force_torque = self.arrays.KT_dot(configuration, self.blob_forces(r_vectors), r_vectors)
        bodies_law = self.hooks.body_body_of_bodies
        if bodies_law is not None and self.body_body_name != 'python':
            bodies_law = None
        views = None
        if 'bodies_external_force_torque' in self.hooks.overridden or bodies_law is not None:
            views = self.bodies_at(configuration)
        if 'bodies_external_force_torque' in self.hooks.overridden:
            extra = self.hooks.bodies_external_force_torque(views, r_vectors, **self.physics)
            force_torque = force_torque + np.asarray(extra, dtype=float).reshape(-1, 6)
        if bodies_law is not None:  # published style: takes the bodies
            extra = bodies_law(views, r_vectors, **self.physics)  # physics holds omega_one_roller
            force_torque = force_torque + np.asarray(extra, dtype=float).reshape(-1, 6)
        elif self.body_body_forces is not None:
            force_torque = force_torque + np.asarray(self.body_body_forces(
                configuration.locations, configuration.orientations, **self.physics)).reshape(-1, 6)
        return force_torque

    def slip(self, configuration, solute=None):
        """Active slip of every blob in the lab frame at ``configuration``, shape (N, 3).

        With phoretic bodies the slip of the solute field is added (``solute``: the (problem, SolveResult) of
        ``surface.solve_concentrations`` at ``configuration``, warm started by the step; None solves it here).

        Bodies with the default slip use the vectorised rotation of the
        reference slip; a body whose ``function_slip`` was set by the user's
        ``set_slip_by_ID`` gets ``function_slip(body)`` (checked: shape
        (Nblobs, 3), finite).
        """
        slip = self.arrays.lab_frame_slip(configuration)
        if self.surface is not None and self.surface.phoretic is not None:  # the solute's active slip
            slip = slip + self.surface.phoretic_slip(self, configuration, solute)
        if not self.slip_functions:
            return slip
        bodies = self.bodies_at(configuration)
        offsets = self.arrays.blob_offsets
        for k in self.slip_function_bodies:
            body = bodies[k]
            function = body.function_slip
            value = user_hooks.call_user_function(function, 'function_slip', body)
            slip[offsets[k]:offsets[k + 1]] = user_hooks.checked_array(
                value, [(body.Nblobs, 3), (3 * body.Nblobs,)], function, 'function_slip',
                'the lab-frame slip of the %d blobs of body %d (%s)' % (body.Nblobs, k, body.ID))
        return slip

    def forces_and_slip(self, configuration, solute=None):
        """(r_vectors (N, 3), force_torque (Nb, 6), slip (N, 3)) at ``configuration``, checked finite."""
        r_vectors = self.blob_positions(configuration)
        force_torque = self.forces_torques(configuration, r_vectors)
        slip = self.slip(configuration, solute) if self.has_slip else np.zeros_like(r_vectors)
        check_finite(force_torque, 'forces and torques')
        check_finite(slip, 'slip')
        return r_vectors, force_torque, slip

    # -------------------------------------------------------------- mobility problem
    @property
    def has_fixed_bodies(self):
        """True when some bodies have prescribed kinematics (obstacles or a velocity file)."""
        return bool(np.any(self.fixed_bodies))

    def mobility_problem(self, configuration):
        """The saddle-point problem at ``configuration`` (a value; body_solver.MobilityProblem, or
        obstacles.MixedMobilityProblem when some bodies have prescribed kinematics; the slip-length problem
        of multi_bodies.solver.slip_length with .slip_length files)."""
        if self.surface is not None and self.surface.has_slip_length:
            return self.surface.slip_length_problem(self, configuration)
        if self.has_fixed_bodies:
            return obstacles.MixedMobilityProblem(self.arrays, configuration, self.vector_mobility,
                                                  fixed=self.fixed_bodies,
                                                  prescribed_velocities=self.prescribed_velocities)
        return body_solver.MobilityProblem(self.arrays, configuration, self.vector_mobility)

    @property
    def published_solves(self):
        """True under ``preconditioner block_diagonal``: every solve as published (block-diagonal and articulated
        Schur preconditioners, the concentration problem unpreconditioned, warm starts from the last solution);
        False under ``auto`` and ``neighbours`` (doc/preconditioners.md)."""
        return self.preconditioner == 'block_diagonal'

    def build_preconditioner(self, configuration, solves=1):
        """The GMRES preconditioner (and the Lanczos factors) at ``configuration``.

        Slip-length bodies: every body's own system inverted, corrected for neighbouring bodies under ``auto``
        and ``neighbours`` (:meth:`Surface.slip_length_preconditioner`).  Other bodies: ``preconditioner``
        ``neighbours``: the block-diagonal one corrected for the couplings of neighbouring
        bodies (:class:`NeighbourPreconditioner`); ``auto`` (the default): the same where its build costs at
        most ``solves * AUTO_MAX_COST_RATIO`` of an ``M f`` product (``solves``: how many solves the caller
        will make with it), else the block-diagonal one; ``block_diagonal``: every body alone (the published
        one).  The Lanczos factors are the block-diagonal ones either way.
        """
        if self.surface is not None and self.surface.has_slip_length:
            return self.surface.slip_length_preconditioner(self, configuration)
        if self.has_fixed_bodies:
            base = obstacles.MixedPreconditioner(self.arrays, configuration, self.blobs_mobility,
                                                 fixed=self.fixed_bodies, memo=self._obstacle_memo)
        else:
            base = body_solver.BlockDiagonalPreconditioner(self.arrays, configuration, self.blobs_mobility)
        built = base
        if not self.published_solves and self.num_bodies >= 2:
            built = NeighbourPreconditioner(base, self.blobs_mobility, periodic_length=self.periodic_length,
                                            body_lengths=self.body_lengths,
                                            max_cost_ratio=AUTO_MAX_COST_RATIO * max(1, int(solves))
                                            if self.preconditioner == 'auto' else None)
        if self.lanczos_preconditioner == 'incomplete_cholesky' and self.num_bodies >= 2:
            # Lanczos runs on L^{-1} M L^{-T} with this factor instead of the block-diagonal one (noise_factor)
            built.noise_factor = noise_factor.neighbour_noise_factor(
                base, self.blobs_mobility, periodic_length=self.periodic_length, body_lengths=self.body_lengths,
                neighbours=built if built is not base else None)
        return built

    def solver(self, not_converged='stop', tally=None):
        """The :class:`multi_bodies.solver.solves.Solver` of this model's solves (the one way into the one solve):
        ``solver_tolerance``, ``print_residual``, and under ``preconditioner auto`` and ``neighbours`` the
        least-residual GMRES iterate and preconditioners turned with the bodies; ``not_converged`` 'stop' (a
        solve that does not converge raises SimulationStopped) or 'flag'; ``tally``: counts the solves."""
        return Solver.of_model(self, not_converged=not_converged, tally=tally)

    def solve(self, problem, rhs, preconditioner, x0=None, tolerance=None, restart=body_solver.GMRES_RESTART,
              what='the mobility problem'):
        """``self.solver().solve(...)``: the one solve of any problem of its protocol at ``solver_tolerance``.

        rhs (problem.size,); preconditioner as body_solver.solve (None: unpreconditioned); x0: first guess
        of the normalised system (``SolveResult.normalised_solution`` of an earlier solve); tolerance: None
        is ``solver_tolerance``; what: the problem's name in the message of a failure.
        Returns body_solver.SolveResult (with its ``iterations``: nothing is counted here); raises
        SimulationStopped when GMRES does not converge.

        A preconditioner built where the bodies were oriented otherwise is applied turned with them
        (``corotated_preconditioner``), and GMRES takes the point of least true residual of its Krylov space
        (``krylov.gmres(minimal_residual=True)``), except under ``published_solves``.
        """
        return self.solver().solve(problem, rhs, preconditioner, x0=x0, tolerance=tolerance, restart=restart,
                                   what=what)

    def lanczos_noise(self, problem, z, factor, preconditioner=None, tolerance=None):
        """``self.solver().noise(...)``: ``factor * M^{1/2} z`` at the configuration of ``problem``, a
        ``stochastic_forcing.LanczosResult`` (``multi_bodies.solver.solves.Solver.noise``; nothing is counted here).
        tolerance : relative change at which Lanczos stops; None is ``solver_tolerance``."""
        return self.solver().noise(problem, z, factor, preconditioner, tolerance=tolerance)

    def warn_if_not_converged(self, result, tolerance=None):
        """Warn (RuntimeWarning) when a Lanczos result did not converge (``solves.warn_if_not_converged``)."""
        warn_if_not_converged(result, self.tolerance if tolerance is None else tolerance)

    def dense_matrices(self, configuration, inverse=True):
        """Dense algebra at ``configuration``: (M (3N, 3N), M^{-1} or None, K (3N, 6Nb), N (6Nb, 6Nb) or None).

        ``M`` from :attr:`dense_mobility`, ``N = pinv(K^T M^{-1} K)`` (body_solver.dense_matrices).
        """
        return body_solver.dense_matrices(self.arrays, as_configuration(configuration), self.dense_mobility,
                                          inverse=inverse)

    @property
    def dense_mobility(self):
        """The mobility whose dense matrix of all blobs the dense schemes and static problems use: the blobs
        backend, or with the spectral product the product itself (its matrix built from 3N products, the
        symmetric part: ``SpectralMobility.dense_matrix``)."""
        return self.blobs_mobility if self.spectral is None else self.vector_mobility

    def deterministic_velocities(self, configuration, preconditioner=None, x0=None, solute=None, solver=None):
        """Velocities at ``configuration`` under its forces and slip, by the iterative solve (SPEC 4.2).

        preconditioner : one built at ``configuration`` when None (the published solves rebuild it at
        every solve; under ``auto`` and ``neighbours`` the deterministic schemes pass the one they keep);
        x0 : normalised first guess; solver : the :class:`Solver` that solves (and counts) it (None:
        :meth:`solver`).
        Returns body_solver.SolveResult (``velocities`` (Nb, 6), ``normalised_solution`` for the next guess).
        """
        _, force_torque, slip = self.forces_and_slip(configuration, solute)
        problem = self.mobility_problem(configuration)
        if preconditioner is None:
            preconditioner = self.build_preconditioner(configuration)
        solver = self.solver() if solver is None else solver
        return solver.solve(problem, problem.rhs(slip=slip, force_torque=force_torque), preconditioner, x0=x0)

    def dense_velocities(self, configuration):
        """Velocities (Nb, 6) at ``configuration`` by dense algebra: ``N (F - K^T M^{-1} slip)``."""
        _, force_torque, slip = self.forces_and_slip(configuration)
        if self.has_fixed_bodies:
            M, _, K, _ = body_solver.dense_matrices(self.arrays, as_configuration(configuration),
                                                    self.dense_mobility, inverse=False)
            return obstacles.dense_mixed_solution(M, K, self.fixed_bodies, self.prescribed_velocities,
                                                  force_torque, slip)[0]
        return body_solver.dense_mobility_velocities(self.arrays, configuration, force_torque, slip,
                                                     self.dense_mobility)

    # -------------------------------------------------------------- rollers (multi_bodies.solver.rollers)
    def roller_product(self, kind):
        """The published function form ``f(r_vectors, vector, eta, a, periodic_length) -> (3N,)`` of the roller
        coupling ``kind`` (:attr:`roller_mobility`), for scripts written against the functions."""
        self.roller_mobility.check_coupling(kind)
        return published_function(self.roller_mobility, kind)

    def roller_velocities(self, configuration, torque_guess=None, solver=None):
        """``rollers.roller_velocities``: RollerVelocities (velocities (N, 3), torque_guess, iterations)."""
        return rollers.roller_velocities(self, configuration, torque_guess, solver=solver)

    def roller_noise(self, r_vectors, z, factor):
        """``rollers.roller_noise``: a LanczosResult with ``noise`` (N, 3)."""
        return rollers.roller_noise(self, r_vectors, z, factor)

    def roller_drift(self, r_vectors, W, kT, delta):
        """``rollers.roller_drift``: ``kT div M_UF`` by a random finite difference, (N, 3)."""
        return rollers.roller_drift(self, r_vectors, W, kT, delta)


class PairedProducts(BlobMobility):
    """Pairs the products ``M v`` of two threads at one configuration into one pass over the blob pairs.

    A ``BlobMobility`` over ``mobility`` (one whose ``pairs_in_one_pass``): a call of :meth:`velocities` waits
    until the other participant asks for a product too (then one of them computes both with
    ``mobility.paired_velocities``) or has left (then it computes its own with ``mobility.velocities``).  Each
    participant calls ``leave()`` when it needs no more products.
    """

    def __init__(self, mobility, participants=2):
        import threading
        self.mobility = mobility
        self.backend, self.geometry, self.eta = mobility.backend, mobility.geometry, mobility.eta
        self.blob_radius, self.periodic_length = mobility.blob_radius, mobility.periodic_length
        self._condition = threading.Condition()
        self._pending = None
        self._active = participants
        self.pairs = 0

    def velocities(self, r_vectors, vector):
        with self._condition:
            other = self._pending
            if other is None and self._active > 1:
                mine = {'vector': vector, 'r': r_vectors, 'result': None}
                self._pending = mine
                self._condition.wait_for(lambda: mine['result'] is not None or self._active < 2)
                if mine['result'] is not None:
                    return mine['result']
                self._pending = None  # the other left: compute it alone
                other = None
            elif other is not None:
                self._pending = None
        if other is None or other['r'] is not r_vectors and not np.array_equal(other['r'], r_vectors):
            result = self.mobility.velocities(r_vectors, vector)
            if other is not None:  # different configurations: the other one alone too
                other_result = self.mobility.velocities(other['r'], other['vector'])
                with self._condition:
                    other['result'] = other_result
                    self._condition.notify_all()
            return result
        mine_result, other_result = self.mobility.paired_velocities(r_vectors, vector, other['vector'])
        with self._condition:
            self.pairs += 1
            other['result'] = other_result
            self._condition.notify_all()
        return mine_result

    def leave(self):
        with self._condition:
            self._active -= 1
            self._condition.notify_all()


def resolve_blob_blob_implementation(name, hooks, log=None):
    """The ``blob_blob_force_implementation`` to use, given the user's overrides (``auto`` resolved).

    ``auto`` honours the overrides: a ``forces_pycuda_user_defined.py`` with a
    usable GPU gives pycuda; a replaced python ``blob_blob_force`` gives python
    (the compiled kernels have their own law); otherwise the fastest usable
    backend.  Overrides that cannot take effect with the chosen name are
    logged.
    """
    pycuda_file = getattr(hooks, 'pycuda_file', None)
    python_law = not hooks.is_default('blob_blob_force')
    say = log if log is not None else (lambda text: None)
    if name == 'auto':
        if pycuda_file is not None:
            try:
                mbf.blob_blob_force_calculator('pycuda')
                say('blob_blob_force_implementation: auto chose pycuda, to use %s' % pycuda_file)
                return 'pycuda'
            except UserInputError as err:
                say('  %s is not used: no GPU is usable here (%s)' % (pycuda_file, err))
        if python_law:
            say('blob_blob_force_implementation: auto chose python, the only one that uses the replaced '
                'blob_blob_force')
            return 'python'
        return resolve_implementation(name, 'forces', log)
    if python_law and name != 'python':
        say('  blob_blob_force from %s cannot take effect: blob_blob_force_implementation is %s%s; set '
            'blob_blob_force_implementation python to use it'
            % (', '.join(hooks.sources[:1]), name,
               ' (no blob-blob forces)' if name == 'None' else ' (a compiled kernel with the default law)'))
    if pycuda_file is not None and name != 'pycuda':
        say('  %s is not used: blob_blob_force_implementation is %s' % (pycuda_file, name))
    return name


def wall_is_seen(options, vector_product_name, blobs_name, script='dynamics'):
    """Whether the hydrodynamics of a run sees the wall (then no blob centre may be below it).

    script : 'dynamics' or 'static' (body_mobility and resistance use the dense blocks only).
    """
    if moves_rollers(options.scheme):
        return options.domain != 'no_wall'
    names = [blobs_name]
    if script == 'dynamics' or options.scheme == 'mobility':
        names.append(vector_product_name)
    return not all(name.endswith('_no_wall') for name in names)


def make_model(options, bodies, body_arrays, hooks, script='dynamics', articulated=None, print_residual=False,
               log=None, surface=None):
    """The Model of validated input ``Options`` (``auto`` backends resolved and logged).

    script : 'dynamics' or 'static' (which backends decide whether the wall is seen); articulated : the
    ``ArticulatedSet`` of the run's joints or None.

    The user's ``forces_pycuda_user_defined.py`` is imported here when the
    blob-blob forces run on pycuda (a clear error without a GPU), and the
    overrides that cannot take effect with the chosen implementations are
    logged (``log``, a callable taking one line).
    """
    product = resolve_implementation(options.mobility_vector_prod_implementation, 'vector_product', log,
                                     num_blobs=body_arrays.num_blobs)
    blobs = resolve_implementation(options.mobility_blobs_implementation, 'blobs', log,
                                   num_blobs=max(body_arrays.type_blobs or [1]))
    forces = resolve_blob_blob_implementation(options.blob_blob_force_implementation, hooks, log)
    if forces == 'pycuda' and options.blob_blob_force_implementation == 'auto' and body_arrays.radii_given:
        forces = 'C++'  # the GPU kernel has one contact distance
        if log is not None:
            log('blob_blob_force_implementation: auto chose C++ instead of pycuda (per-blob radii)')
    body_body = options.body_body_force_torque_implementation
    if not hooks.is_default('body_body_force_torque') and body_body != 'python' and log is not None:
        log('  body_body_force_torque from %s cannot take effect: body_body_force_torque_implementation is %s; '
            'set it to python to use it' % (', '.join(hooks.sources[:1]), body_body))
    physics = mbf.physics_keywords(options)

    def checked(option_name, build):
        try:
            return build()
        except UserInputError as err:
            raise UserInputError('%s: %s: %s' % (options.where(option_name), option_name, err))
    pycuda_forces = hooks.calc_blob_blob_forces_pycuda
    if forces == 'pycuda' and hooks.pycuda_file is not None and pycuda_forces is None:
        pycuda_forces = checked('blob_blob_force_implementation',
                                lambda: user_hooks.load_user_pycuda_forces(hooks.pycuda_file))
        if log is not None:
            log('  calc_blob_blob_forces_pycuda replaced by %s (the GPU blob-blob forces)' % hooks.pycuda_file)
    if any(options.is_set(name) for name in periodic.SPECTRAL_OPTIONS):
        periodic.check_spectral_options(options)  # refuses them without the spectral product
    spectral = None
    check_wall = wall_is_seen(options, product, blobs, script)
    if product == periodic.SPECTRAL:  # doc/periodic.md
        spectral = periodic.spectral_domain(options, rollers=script == 'dynamics' and moves_rollers(options.scheme))
        check_wall = spectral.checks_heights
        checked('mobility_blobs_implementation', lambda: spectral.block_mobility(blobs, options.eta,
                                                                                 options.blob_radius))
        if log is not None:
            log('spectral product: %s, periods %s, z bounds %s, kernel %s, noise %s; preconditioner blocks: %s in %s'
                % (spectral.kind, ' '.join('%g' % v for v in spectral.periodic_length),
                   'none' if spectral.z_bounds is None else '%g %g' % spectral.z_bounds, spectral.kernel,
                   spectral.noise, implementation_geometry(blobs)[0], spectral.block_geometry().kind))
            if spectral.kind in ('triply_periodic', 'doubly_periodic_open') and options.g != 0:
                log('  note: %s has no mean flow (a net force on the suspension, as gravity g = %g, moves nothing on '
                    'average); doc/periodic.md' % (spectral.kind, options.g))
        crowded = periodic.overlap_warning(options, bodies, options.blob_radius)
        if crowded is not None:
            warn_user(crowded)
    else:
        checked('mobility_vector_prod_implementation', lambda: from_implementation_name(
            product, options.eta, options.blob_radius, options.periodic_length))
        checked('mobility_blobs_implementation', lambda: from_implementation_name(
            blobs, options.eta, options.blob_radius, dense_matrices=True))
    checked('blob_blob_force_implementation', lambda: mbf.blob_blob_force_calculator(
        forces, pycuda_forces=pycuda_forces, radii_given=body_arrays.radii_given))
    checked('body_body_force_torque_implementation', lambda: mbf.body_body_force_calculator(body_body))
    return Model(bodies, body_arrays, hooks, physics, options.eta, options.blob_radius, options.solver_tolerance,
                 vector_product_name=product, blobs_name=blobs, blob_blob_name=forces, body_body_name=body_body,
                 periodic_length=options.periodic_length, omega_one_roller=options.omega_one_roller,
                 free_kinematics=options.free_kinematics, domain=options.domain, print_residual=print_residual,
                 articulated=articulated, nonlinear_tolerance=options.nonlinear_solver_tolerance,
                 check_wall=check_wall, pycuda_blob_blob_forces=pycuda_forces,
                 surface=surface, preconditioner=options.preconditioner,
                 lanczos_preconditioner=options.lanczos_preconditioner, spectral=spectral)
