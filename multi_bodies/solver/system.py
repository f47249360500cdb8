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
from body.body import reference_slip_in_lab_frame
from multi_bodies.solver import body_solver
from multi_bodies.solver import physics as mbf
from multi_bodies.solver import user_hooks
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
    hooks : multi_bodies.solver.user_hooks.PhysicsHooks
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
        self.blob_blob_name, self.body_body_name = blob_blob_name, body_body_name
        self.blob_blob_forces = mbf.blob_blob_force_calculator(
            blob_blob_name, pair_force=hooks.blob_blob_force, pycuda_forces=hooks.calc_blob_blob_forces_pycuda,
            python_forces=hooks.blob_blob_forces_python)
        self.body_body_forces = mbf.body_body_force_calculator(
            body_body_name, pair_force_torque=hooks.body_body_force_torque,
            python_forces_torques=hooks.body_body_forces_python)
        self.uses_bodies = any(not hooks.is_default(name) for name in
                               ('bodies_external_force_torque', 'preprocess', 'postprocess'))
        # Bodies whose slip is a user function (set by set_slip_by_ID); the others use the vectorised slip.
        self.slip_function_bodies = [k for k, b in enumerate(bodies)
                                     if getattr(b, 'function_slip', reference_slip_in_lab_frame)
                                     is not reference_slip_in_lab_frame]
        self.slip_functions = bool(self.slip_function_bodies)
        self.has_slip = self.slip_functions or bool(np.any(body_arrays.reference_slip))
        self.check_wall = True
        self.gmres_iterations = 0          # every GMRES iteration (the published deterministic_iterations_count)
        self.gmres_stochastic_iterations = 0  # of those: noise and random-finite-difference solves
        self.lanczos_iterations = 0
        self.lanczos_not_converged = 0
        self.lanczos_max_iterations = 1000
        self.solves = {'deterministic': 0, 'stochastic': 0}
        self.last_iterations = 0
        self.first_guess = None
        self.roller_torque_guess = None

    # -------------------------------------------------------------- counters for .info
    def counters(self, scheme=None):
        """Counters of the run for ``.info`` (published names first), as a dict name -> int.

        ``deterministic_iterations_count``: GMRES iterations of every mobility
        solve (as the published code counts them); ``stochastic_iterations_count``:
        Lanczos iterations.  Then the split of the GMRES count, solves per
        kind and Lanczos calls that did not converge.
        """
        return {'invalid_configuration_count': getattr(scheme, 'invalid_configurations', 0),
                'deterministic_iterations_count': self.gmres_iterations,
                'stochastic_iterations_count': self.lanczos_iterations,
                'gmres_iterations_deterministic_solves': self.gmres_iterations - self.gmres_stochastic_iterations,
                'gmres_iterations_noise_and_rfd_solves': self.gmres_stochastic_iterations,
                'deterministic_solves_count': self.solves['deterministic'],
                'noise_and_rfd_solves_count': self.solves['stochastic'],
                'lanczos_not_converged_count': self.lanczos_not_converged}

    def set_counters(self, counters):
        """Continue the counts of an earlier segment of the run (restart)."""
        self.gmres_iterations = int(counters.get('deterministic_iterations_count', 0))
        self.lanczos_iterations = int(counters.get('stochastic_iterations_count', 0))
        self.gmres_stochastic_iterations = int(counters.get('gmres_iterations_noise_and_rfd_solves', 0))
        self.solves['deterministic'] = int(counters.get('deterministic_solves_count', 0))
        self.solves['stochastic'] = int(counters.get('noise_and_rfd_solves_count', 0))
        self.lanczos_not_converged = int(counters.get('lanczos_not_converged_count', 0))

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
            force_torque = force_torque + np.asarray(self.body_body_forces(
                self.arrays.locations, self.arrays.orientations, **self.physics)).reshape(-1, 6)
        return force_torque

    def slip(self):
        """Active slip of every blob in the lab frame, shape (N, 3).

        Bodies with the default slip use the vectorised rotation of the
        reference slip; a body whose ``function_slip`` was set by the user's
        ``set_slip_by_ID`` gets ``function_slip(body)`` (checked: shape
        (Nblobs, 3), finite).
        """
        slip = self.arrays.lab_frame_slip()
        if not self.slip_functions:
            return slip
        bodies = self.synced_bodies()
        offsets = self.arrays.blob_offsets
        for k in self.slip_function_bodies:
            body = bodies[k]
            function = body.function_slip
            value = user_hooks.call_user_function(function, 'function_slip', body)
            slip[offsets[k]:offsets[k + 1]] = user_hooks.checked_array(
                value, [(body.Nblobs, 3), (3 * body.Nblobs,)], function, 'function_slip',
                'the lab-frame slip of the %d blobs of body %d (%s)' % (body.Nblobs, k, body.ID))
        return slip

    # -------------------------------------------------------------- mobility problem
    def mobility_problem(self, locations=None, orientations=None):
        """The saddle-point problem at a configuration (default: the current one), a value.

        locations (Nb, 3), orientations (Nb, 4); returns body_solver.MobilityProblem.
        """
        locations = self.arrays.locations if locations is None else locations
        orientations = self.arrays.orientations if orientations is None else orientations
        return body_solver.MobilityProblem(self.arrays, locations, orientations, self.mobility_product, self.eta,
                                           self.blob_radius, self.periodic_length)

    def build_preconditioner(self, problem):
        """Block-diagonal preconditioner (and Lanczos factors) at the configuration of ``problem``."""
        return body_solver.BlockDiagonalPreconditioner(self.arrays, problem.r_vectors, self.blob_mobility_matrix,
                                                       self.eta, self.blob_radius,
                                                       stacked_mobility=self.stacked_mobility,
                                                       locations=problem.locations)

    def solve(self, problem, slip=None, force_torque=None, noise_slip=None, noise_force=None, rhs=None,
              preconditioner=None, guess=None, keep_guess=False, kind='deterministic'):
        """One mobility solve with every input explicit (SPEC §4.2).

        Right-hand side ``[slip - noise_slip; -(F + noise_force)]`` (or ``rhs``
        (3N + 6Nb,) as given); slip (N, 3), force_torque (Nb, 6), noise_slip
        (3N,), noise_force (Nb, 6), each None for zero.

        preconditioner : BlockDiagonalPreconditioner or None (then one is built at ``problem``)
        guess : None (zeros), 'deterministic' (the stored normalised solution of the last
            deterministic solve, SPEC §4.2), or an array (3N + 6Nb,) of the normalised system
        keep_guess : store the normalised solution as the next deterministic guess
        kind : 'deterministic' or 'stochastic' (noise and RFD solves), for the counters

        Returns body_solver.SolveResult with velocities (Nb, 6) and lambda (N, 3)
        of the un-normalised system; raises SimulationStopped when GMRES fails.
        """
        n3, nb6 = 3 * problem.num_blobs, 6 * problem.num_bodies
        if rhs is None:
            rhs = np.zeros(n3 + nb6)
            if slip is not None:
                rhs[:n3] += np.asarray(slip, dtype=float).reshape(-1)
            if noise_slip is not None:
                rhs[:n3] -= np.asarray(noise_slip, dtype=float).reshape(-1)
            if force_torque is not None:
                rhs[n3:] -= np.asarray(force_torque, dtype=float).reshape(-1)
            if noise_force is not None:
                rhs[n3:] -= np.asarray(noise_force, dtype=float).reshape(-1)
        else:
            rhs = np.array(rhs, dtype=float).reshape(-1)
        if problem.num_bodies:
            rhs[n3:] = problem.project_forces(rhs[n3:]).reshape(-1)
        self.solves[kind] += 1
        norm = float(np.linalg.norm(rhs))
        if self.first_guess is None or self.first_guess.shape != rhs.shape:
            self.first_guess = np.zeros_like(rhs)
        if norm == 0.0:
            if kind == 'deterministic':
                self.last_iterations = 0
            return body_solver.SolveResult(np.zeros((problem.num_blobs, 3)), np.zeros((problem.num_bodies, 6)),
                                           0, True, 0, 0.0)
        if isinstance(guess, str):
            x0 = self.first_guess
        else:
            x0 = guess
        if preconditioner is None:
            preconditioner = self.build_preconditioner(problem)
        result = body_solver.solve_mobility_problem(problem.operator, preconditioner, rhs / norm, problem.num_blobs,
                                                    self.tolerance, x0=x0, maxiter=body_solver.GMRES_MAXITER,
                                                    true_residual=False, print_residual=self.print_residual)
        self.gmres_iterations += result.iterations
        if kind == 'deterministic':
            self.last_iterations = result.iterations
        else:
            self.gmres_stochastic_iterations += result.iterations
        if keep_guess:
            self.first_guess = np.concatenate((result.lambda_blobs.reshape(-1), result.velocities.reshape(-1)))
        if not result.converged:
            raise SimulationStopped('GMRES did not converge to solver_tolerance %g in %d iterations (relative '
                                    'residual %.3e); try a larger solver_tolerance or check the configuration'
                                    % (self.tolerance, result.iterations, result.residual))
        return result._replace(lambda_blobs=result.lambda_blobs * norm, velocities=result.velocities * norm)

    def solve_mobility(self, force_torque, slip, r_vectors=None):
        """Body velocities (Nb, 6) of the current configuration from force-torque (Nb, 6) and slip (N, 3).

        The deterministic solve of SPEC 4.2: normalised right-hand side, the
        previous normalised solution as initial guess, a preconditioner built
        at the current configuration.  Raises SimulationStopped when GMRES
        does not converge.
        """
        problem = self.mobility_problem()
        return self.solve(problem, slip=slip, force_torque=force_torque, guess='deterministic',
                          keep_guess=True).velocities

    def lanczos_noise(self, problem, z, factor, preconditioner=None):
        """``factor * M^{1/2} z`` at the configuration of ``problem`` (3N,), counted for ``.info``.

        With a preconditioner the Lanczos iteration runs on ``L^{-1} M L^{-T}``
        and the result is multiplied by ``L`` (covariance ``M``; SPEC decision 1).
        A Lanczos call that does not converge is counted and warned about once per call.
        """
        from stochastic_forcing import lanczos_square_root
        if preconditioner is None:
            matvec, L_mult = problem.M_dot, None
        else:
            def matvec(v):
                return preconditioner.L_inv_dot(problem.M_dot(preconditioner.L_inv_T_dot(v)))
            L_mult = preconditioner.L_dot
        result = lanczos_square_root(matvec, z, self.tolerance, max_iterations=self.lanczos_max_iterations,
                                     factor=factor, L_mult=L_mult, print_residual=self.print_residual)
        self._count_lanczos(result)
        return result.noise

    def _count_lanczos(self, result):
        self.lanczos_iterations += result.iterations
        if not result.converged:
            self.lanczos_not_converged += 1
            import warnings
            warnings.warn('Lanczos did not converge to solver_tolerance %g in %d iterations (last relative change '
                          '%.3e); the noise is approximate (counted in .info as lanczos_not_converged_count)'
                          % (self.tolerance, result.iterations, result.relative_change), RuntimeWarning)

    def dense_matrices(self, locations, orientations, inverse=True):
        """Dense algebra at a configuration: (M (3N, 3N), M^{-1} or None, K (3N, 6Nb), N (6Nb, 6Nb) or None).

        ``M`` from the blobs backend, ``N = pinv(K^T M^{-1} K, rcond=1e-14)`` (SPEC §3).
        """
        from body.body import K_dense, blob_positions
        r = blob_positions(locations, orientations, self.arrays.reference_blobs, self.arrays.blob_body_index)
        M = body_solver.dense_blob_mobility(r, self.blob_mobility_matrix, self.eta, self.blob_radius)
        K = K_dense(r, locations, self.arrays.blob_body_index)
        if not inverse:
            return M, None, K, None
        M_inv = np.linalg.inv(M)
        N = np.linalg.pinv(K.T @ M_inv @ K, rcond=1e-14)
        return M, M_inv, K, 0.5 * (N + N.T)

    def solver_state(self):
        """Initial guesses carried between solves (saved with snapshots for exact restarts)."""
        return {'first_guess': None if self.first_guess is None else self.first_guess.copy(),
                'roller_torque_guess': None if self.roller_torque_guess is None else self.roller_torque_guess.copy()}

    def set_solver_state(self, state):
        if state:
            self.first_guess = state.get('first_guess')
            self.roller_torque_guess = state.get('roller_torque_guess')

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

    def roller_noise(self, r_vectors, z, factor):
        """``factor * M_UF^{1/2} z`` of single-blob rollers at blob positions (N, 3) (Lanczos, no preconditioner)."""
        from stochastic_forcing import lanczos_square_root
        product = self.roller_product('trans_times_force')
        a, eta, L = self.blob_radius, self.eta, self.periodic_length
        result = lanczos_square_root(lambda v: np.asarray(product(r_vectors, v, eta, a, L)).reshape(-1), z,
                                     self.tolerance, max_iterations=self.lanczos_max_iterations, factor=factor,
                                     print_residual=self.print_residual)
        self._count_lanczos(result)
        return result.noise.reshape(-1, 3)

    def roller_drift(self, r_vectors, W, kT, delta):
        """Thermal drift ``kT div M_UF`` of rollers by a random finite difference (SPEC 5.2), shape (N, 3).

        ``(kT/(delta a)) [M_UF(r + delta a W/2) W - M_UF(r - delta a W/2) W]`` with W (3N,) ~ N(0, 1);
        zero without a wall (the free-space RPY tensor is divergence free).
        """
        if self.domain == 'no_wall' or kT == 0:
            return np.zeros_like(r_vectors)
        product = self.roller_product('trans_times_force')
        a, eta, L = self.blob_radius, self.eta, self.periodic_length
        W = np.asarray(W, dtype=float).reshape(-1)
        step = (0.5 * delta * a) * W.reshape(-1, 3)
        plus = np.asarray(product(r_vectors + step, W, eta, a, L)).reshape(-1, 3)
        minus = np.asarray(product(r_vectors - step, W, eta, a, L)).reshape(-1, 3)
        return (kT / (delta * a)) * (plus - minus)

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


def make_system(options, bodies, body_arrays, hooks, print_residual=False, log=None):
    """A System from validated input ``Options`` (``auto`` backends resolved and logged).

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
    if forces == 'pycuda' and getattr(hooks, 'pycuda_file', None) is not None \
            and hooks.calc_blob_blob_forces_pycuda is None:
        hooks.calc_blob_blob_forces_pycuda = checked('blob_blob_force_implementation',
                                                     lambda: user_hooks.load_user_pycuda_forces(hooks.pycuda_file))
        hooks.overridden.append('calc_blob_blob_forces_pycuda')
        if log is not None:
            log('  calc_blob_blob_forces_pycuda replaced by %s (the GPU blob-blob forces)' % hooks.pycuda_file)
    checked('mobility_vector_prod_implementation', lambda: mobility.mobility_vector_product(product))
    checked('mobility_blobs_implementation', lambda: mobility.blob_mobility_matrix(blobs))
    checked('blob_blob_force_implementation', lambda: mbf.blob_blob_force_calculator(
        forces, pycuda_forces=hooks.calc_blob_blob_forces_pycuda))
    checked('body_body_force_torque_implementation', lambda: mbf.body_body_force_calculator(body_body))
    return System(bodies, body_arrays, hooks, physics, options.eta, options.blob_radius, options.solver_tolerance,
                  vector_product_name=product, blobs_name=blobs, blob_blob_name=forces,
                  body_body_name=body_body,
                  periodic_length=options.periodic_length, omega_one_roller=options.omega_one_roller,
                  free_kinematics=options.free_kinematics, domain=options.domain, print_residual=print_residual)
