"""The many-body system that a time-stepping scheme advances.

A ``System`` holds every body as contiguous arrays (``BodyArrays``: locations
(Nb, 3), scalar-first quaternions (Nb, 4)), the backends chosen once at
set-up (matrix-free ``M f``, dense blocks for the preconditioner, blob-blob
and body-body forces, roller couplings) and the physics hooks of the run
(defaults of ``multi_bodies_functions`` or the user's overrides).  It can

* compute blob positions, forces and torques (SPEC section 7) and slip;
* solve the mobility problem (SPEC 4.2, GMRES with the block-diagonal
  preconditioner of 4.3) or its dense variant;
* give roller velocities (SPEC 5.2);
* say which bodies have a blob centre below the wall.

Schemes (``quaternion_integrator.schemes``) receive a System and never reach
into globals.  Counters for ``.info`` live here (``gmres_iterations``); the
last solve's count is ``last_iterations``.

Units: the user's; lengths as the input file, velocities length/time,
forces force units, ``eta`` viscosity.
"""
import numpy as np
import scipy.sparse.linalg as spla

import mobility
from multi_bodies import body_solver
from multi_bodies import multi_bodies_functions as mbf
from quaternion_integrator.quaternion import Quaternion
from utils import SimulationStopped, UserInputError

NO_WALL = '_no_wall'


# ------------------------------------------------------------------ backend choice
def resolve_implementation(name, kind='vector_product', log=None, num_blobs=None):
    """Turn ``auto`` / ``auto_no_wall`` into the fastest backend usable here.

    kinds 'vector_product' and 'blobs' (dense matrices, CPU only): the backend
    of smallest cost measured on this machine at ``num_blobs`` blobs
    (``mobility.choose``); 'forces': pycuda, else C++, else python.  Other
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
    order = {'vector_product': ('pycuda', 'C++', 'python'), 'blobs': ('C++', 'python'),
             'forces': ('pycuda', 'C++', 'python')}[kind]
    for backend in order:
        if kind == 'forces':
            try:
                mbf.blob_blob_force_calculator(backend)
                usable = True
            except UserInputError:
                usable = False
        else:
            usable = mobility.backends.is_usable(backend)
        if usable:
            chosen = backend + suffix
            if log is not None:
                log('%s: auto chose %s (fastest usable here; order %s)' % (kind, chosen, ', '.join(order)))
            return chosen
    raise UserInputError('no usable backend for %s' % name)


def check_finite(values, what):
    """Raise SimulationStopped when ``values`` hold NaN or inf."""
    if not np.all(np.isfinite(values)):
        raise SimulationStopped('the %s are not finite (NaN or inf); check the user-defined functions, the time '
                                'step and the configuration' % what)


# ------------------------------------------------------------------ the system
class System:
    """Bodies as arrays, backends and hooks of one run (see module docstring).

    Parameters
    ----------
    bodies : list of body.body.Body
        In input order; used by the hooks that take bodies (kept in sync with
        the arrays only when such a hook is user-defined).
    body_arrays : body.body.BodyArrays
        The state: ``locations`` (Nb, 3) and ``orientations`` (Nb, 4) are
        updated in place by the schemes through ``set_state``.
    hooks : multi_bodies_functions.PhysicsHooks
    physics : dict
        Keywords of the hooks: g, repulsion_strength_wall, debye_length_wall,
        repulsion_strength, debye_length, periodic_length, blob_radius, blob_mass.
    eta, blob_radius, solver_tolerance : float
    vector_product_name, blobs_name, blob_blob_name, body_body_name : str
        Implementation names (``auto`` already resolved).
    periodic_length : (3,) floats
    omega_one_roller : (3,) floats, free_kinematics : bool, domain : str
        Roller parameters (SPEC 5.2).
    print_residual : bool
        Print every GMRES residual.
    """

    def __init__(self, bodies, body_arrays, hooks, physics, eta, blob_radius, solver_tolerance,
                 vector_product_name='python', blobs_name='python', blob_blob_name='None', body_body_name='None',
                 periodic_length=(0.0, 0.0, 0.0), omega_one_roller=(0.0, 0.0, 0.0), free_kinematics=True,
                 domain='single_wall', print_residual=False):
        self.bodies = bodies
        self.arrays = body_arrays
        self.hooks = hooks
        self.physics = dict(physics)
        self.eta, self.blob_radius, self.tolerance = float(eta), float(blob_radius), float(solver_tolerance)
        self.periodic_length = np.asarray(periodic_length, dtype=float).reshape(3)
        self.omega_one_roller = np.asarray(omega_one_roller, dtype=float).reshape(3)
        self.free_kinematics = bool(free_kinematics)
        self.domain = domain
        self.print_residual = print_residual
        self.vector_product_name, self.blobs_name = vector_product_name, blobs_name
        self.mobility_product = mobility.mobility_vector_product(vector_product_name)
        self.blob_mobility_matrix = mobility.blob_mobility_matrix(blobs_name)
        self.stacked_mobility = mobility.blob_mobility_matrix(blobs_name)  # takes stacks of bodies
        self.blob_blob_forces = mbf.blob_blob_force_calculator(
            blob_blob_name, pair_force=hooks.blob_blob_force, pycuda_forces=hooks.calc_blob_blob_forces_pycuda)
        self.body_body_forces = mbf.body_body_force_calculator(body_body_name,
                                                               pair_force_torque=hooks.body_body_force_torque)
        self.uses_bodies = any(not hooks.is_default(name) for name in
                               ('bodies_external_force_torque', 'preprocess', 'postprocess'))
        self.slip_functions = any(callable(getattr(b, 'function_slip', None)) for b in bodies)
        self.has_slip = self.slip_functions or bool(np.any(body_arrays.reference_slip))
        self.check_wall = True
        self.gmres_iterations = 0
        self.last_iterations = 0
        self.first_guess = None
        self.roller_torque_guess = None

    # -------------------------------------------------------------- state
    @property
    def num_bodies(self):
        return self.arrays.num_bodies

    @property
    def num_blobs(self):
        return self.arrays.num_blobs

    def get_state(self):
        """Copies of (locations (Nb, 3), orientations (Nb, 4))."""
        return self.arrays.locations.copy(), self.arrays.orientations.copy()

    def set_state(self, locations, orientations):
        """Replace the configuration (arrays copied in place, so views stay valid)."""
        self.arrays.locations[...] = locations
        self.arrays.orientations[...] = orientations

    def blob_positions(self):
        """Lab-frame blob positions, shape (N, 3)."""
        return self.arrays.blob_positions()

    def synced_bodies(self):
        """The Body objects with the current locations and orientations (one loop over bodies)."""
        for body, location, orientation in zip(self.bodies, self.arrays.locations, self.arrays.orientations):
            body.location = location.copy()
            body.orientation = Quaternion(orientation)
        return self.bodies

    def preprocess(self):
        if not self.hooks.is_default('preprocess'):
            self.hooks.preprocess(self.synced_bodies())

    def postprocess(self):
        if not self.hooks.is_default('postprocess'):
            self.hooks.postprocess(self.synced_bodies())
            self.set_state(np.array([b.location for b in self.bodies]),
                           np.array([b.orientation.entries for b in self.bodies]))

    def invalid_bodies(self, r_vectors=None):
        """Indices of bodies with a blob centre below the wall (z < 0), ndarray of int (empty without a wall)."""
        if not self.check_wall:
            return np.zeros(0, dtype=int)
        return self.arrays.check_positions(r_vectors)

    # -------------------------------------------------------------- physics
    def blob_forces(self, r_vectors):
        """One-blob plus blob-blob forces, shape (N, 3)."""
        forces = np.asarray(self.hooks.blob_external_forces(r_vectors, **self.physics), dtype=float).reshape(-1, 3)
        if self.blob_blob_forces is not None:
            forces = forces + np.asarray(self.blob_blob_forces(r_vectors, **self.physics)).reshape(-1, 3)
        return forces

    def forces_torques(self, r_vectors):
        """Force and torque on every body, shape (Nb, 6) = ``[F, T]`` (SPEC section 7)."""
        force_torque = self.arrays.KT_dot(r_vectors, self.blob_forces(r_vectors))
        if not self.hooks.is_default('bodies_external_force_torque'):
            extra = self.hooks.bodies_external_force_torque(self.synced_bodies(), r_vectors, **self.physics)
            force_torque = force_torque + np.asarray(extra, dtype=float).reshape(-1, 6)
        if self.body_body_forces is not None:
            force_torque = force_torque + self.body_body_forces(self.arrays.locations, **self.physics).reshape(-1, 6)
        return force_torque

    def slip(self):
        """Active slip of every blob in the lab frame, shape (N, 3)."""
        if not self.slip_functions:
            return self.arrays.lab_frame_slip()
        slips = []
        for body in self.synced_bodies():
            function = getattr(body, 'function_slip', None)
            slips.append(function(body) if callable(function) else body.calc_slip())
        return np.concatenate([np.asarray(s, dtype=float).reshape(-1, 3) for s in slips])

    # -------------------------------------------------------------- mobility problem
    def solve_mobility(self, force_torque, slip, r_vectors=None):
        """Body velocities (Nb, 6) from force-torque (Nb, 6) and slip (N, 3) by preconditioned GMRES.

        As SPEC 4.2: the right-hand side is normalised, the previous
        normalised solution is the initial guess; raises SimulationStopped
        when GMRES does not converge.
        """
        r_vectors = self.blob_positions() if r_vectors is None else r_vectors
        operator = body_solver.saddle_point_operator(self.arrays, r_vectors, self.mobility_product, self.eta,
                                                     self.blob_radius, self.periodic_length)
        preconditioner = body_solver.BlockDiagonalPreconditioner(self.arrays, r_vectors, self.blob_mobility_matrix,
                                                                 self.eta, self.blob_radius,
                                                                 stacked_mobility=self.stacked_mobility)
        rhs = body_solver.mobility_rhs(force_torque, slip)
        norm = np.linalg.norm(rhs)
        if self.first_guess is None or self.first_guess.shape != rhs.shape:
            self.first_guess = np.zeros_like(rhs)
        if norm == 0.0:
            self.last_iterations = 0
            return np.zeros((self.num_bodies, 6))
        result = body_solver.solve_mobility_problem(operator, preconditioner, rhs / norm, self.num_blobs,
                                                    self.tolerance, x0=self.first_guess,
                                                    maxiter=body_solver.GMRES_MAXITER, true_residual=False,
                                                    print_residual=self.print_residual)
        self.last_iterations = result.iterations
        self.gmres_iterations += result.iterations
        solution = np.concatenate((result.lambda_blobs.reshape(-1), result.velocities.reshape(-1)))
        self.first_guess = solution
        if not result.converged:
            raise SimulationStopped('GMRES did not converge to solver_tolerance %g in %d iterations (relative '
                                    'residual %.3e); try a larger solver_tolerance or check the configuration'
                                    % (self.tolerance, result.iterations, result.residual))
        return result.velocities * norm

    def current_forces_and_slip(self):
        """(r_vectors (N, 3), force_torque (Nb, 6), slip (N, 3)) of the current configuration, checked finite."""
        r_vectors = self.blob_positions()
        force_torque = self.forces_torques(r_vectors)
        slip = self.slip() if self.has_slip else np.zeros_like(r_vectors)
        check_finite(force_torque, 'forces and torques')
        check_finite(slip, 'slip')
        return r_vectors, force_torque, slip

    def deterministic_velocities(self):
        """Velocities (Nb, 6) of the current configuration under its forces and slip (iterative)."""
        r_vectors, force_torque, slip = self.current_forces_and_slip()
        return self.solve_mobility(force_torque, slip, r_vectors)

    def dense_velocities(self):
        """Velocities (Nb, 6) by dense algebra: ``N (F - K^T M^{-1} slip)``, ``M`` from the blobs backend."""
        r_vectors, force_torque, slip = self.current_forces_and_slip()
        return body_solver.dense_mobility_velocities(self.arrays, r_vectors, force_torque, slip,
                                                     self.blob_mobility_matrix, self.eta, self.blob_radius)

    # -------------------------------------------------------------- rollers
    def roller_product(self, kind):
        """Roller coupling ``kind`` of the chosen vector-product backend and ``domain``."""
        base = self.vector_product_name[:-len(NO_WALL)] if self.vector_product_name.endswith(NO_WALL) \
            else self.vector_product_name
        name = base + (NO_WALL if self.domain == 'no_wall' else '')
        return mobility.blob_product(name, kind)

    def roller_velocities(self):
        """Linear velocities of single-blob rollers, shape (Nb, 3) (SPEC 5.2).

        Forces: one-blob plus blob-blob.  ``free_kinematics``: torque
        ``8 pi eta a^3 omega_one_roller`` per blob; otherwise the torque that
        makes every blob spin at ``omega_one_roller`` (GMRES on ``M_WT``).
        Then ``v = M_UF F + M_UT T``.
        """
        r_vectors = self.blob_positions()
        forces = self.blob_forces(r_vectors).reshape(-1)
        check_finite(forces, 'blob forces')
        a, eta, L = self.blob_radius, self.eta, self.periodic_length
        if self.free_kinematics:
            torques = np.tile(8.0 * np.pi * eta * a ** 3 * self.omega_one_roller, self.num_blobs)
        else:
            torques = self._prescribed_spin_torques(r_vectors, forces)
        velocity = self.roller_product('trans_times_force')(r_vectors, forces, eta, a, L)
        if np.any(torques != 0):
            velocity = velocity + self.roller_product('trans_times_torque')(r_vectors, torques, eta, a, L)
        return np.asarray(velocity).reshape(-1, 3)

    def _prescribed_spin_torques(self, r_vectors, forces):
        a, eta, L = self.blob_radius, self.eta, self.periodic_length
        n3 = forces.size
        omega = np.tile(self.omega_one_roller, self.num_blobs)
        rhs = omega - self.roller_product('rot_times_force')(r_vectors, forces, eta, a, L)
        norm = np.linalg.norm(rhs)
        if norm == 0.0:
            return np.zeros(n3)
        rot_times_torque = self.roller_product('rot_times_torque')
        operator = spla.LinearOperator((n3, n3), matvec=lambda t: rot_times_torque(r_vectors, t, eta, a, L),
                                       dtype=float)
        if self.roller_torque_guess is None or self.roller_torque_guess.shape != rhs.shape:
            self.roller_torque_guess = np.zeros(n3)
        count = [0]

        def callback(residual):
            count[0] += 1
            if self.print_residual:
                print('gmres = %d %s' % (count[0], residual))
        solution, info = spla.gmres(operator, rhs / norm, x0=self.roller_torque_guess, rtol=self.tolerance,
                                    atol=0.0, maxiter=1000, callback=callback, callback_type='legacy')
        self.last_iterations = count[0]
        self.gmres_iterations += count[0]
        self.roller_torque_guess = solution
        if info != 0:
            raise SimulationStopped('GMRES for the roller torques did not converge to solver_tolerance %g'
                                    % self.tolerance)
        return solution * norm


def make_system(options, bodies, body_arrays, hooks, print_residual=False, log=None):
    """A System from validated input ``Options`` (``auto`` backends resolved and logged)."""
    product = resolve_implementation(options.mobility_vector_prod_implementation, 'vector_product', log,
                                     num_blobs=body_arrays.num_blobs)
    blobs = resolve_implementation(options.mobility_blobs_implementation, 'blobs', log,
                                   num_blobs=max(body_arrays.type_blobs or [1]))
    forces = resolve_implementation(options.blob_blob_force_implementation, 'forces', log)
    physics = dict(g=options.g, repulsion_strength_wall=options.repulsion_strength_wall,
                   debye_length_wall=options.debye_length_wall, repulsion_strength=options.repulsion_strength,
                   debye_length=options.debye_length, periodic_length=np.array(options.periodic_length),
                   blob_radius=options.blob_radius, blob_mass=1.0)

    def checked(option_name, build):
        try:
            return build()
        except UserInputError as err:
            raise UserInputError('%s: %s: %s' % (options.where(option_name), option_name, err))
    checked('mobility_vector_prod_implementation', lambda: mobility.mobility_vector_product(product))
    checked('mobility_blobs_implementation', lambda: mobility.blob_mobility_matrix(blobs))
    checked('blob_blob_force_implementation', lambda: mbf.blob_blob_force_calculator(
        forces, pycuda_forces=hooks.calc_blob_blob_forces_pycuda))
    checked('body_body_force_torque_implementation',
            lambda: mbf.body_body_force_calculator(options.body_body_force_torque_implementation))
    return System(bodies, body_arrays, hooks, physics, options.eta, options.blob_radius, options.solver_tolerance,
                  vector_product_name=product, blobs_name=blobs, blob_blob_name=forces,
                  body_body_name=options.body_body_force_torque_implementation,
                  periodic_length=options.periodic_length, omega_one_roller=options.omega_one_roller,
                  free_kinematics=options.free_kinematics, domain=options.domain, print_residual=print_residual)
