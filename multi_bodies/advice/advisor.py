"""The model advisor: measure, on the user's own scene, the cheapest model that meets an accuracy target.

Library of ``multi_bodies/advise.py`` (floor 7, see multi_bodies/__init__.py); its tables, models and scene are in
``advisor_models``, its output in ``advisor_report``, the resolution measurements in
``advisor_resolution``, the physics-keeping rules (scope, rescaled
per-blob parameters, the check run, the time-step bounds) in ``advisor_physics``.  It reads
the scene as the scripts do (``read_input_file``, ``read_bodies``,
``bodies_to_arrays``, the user's hooks from the run directory) and measures,
for each choice a user makes in the input file, the error of each option and
its cost per step on this machine:

* ``resolution``: for each structure type recognised as a sphere (an
  icosahedral shell, or a single blob), the 1-blob roller model and the
  shells of 12, 42, 162 and 642 blobs; for other bodies the blob spacing and
  the gaps against the blob radius (and, on request, a coarsened model);
* ``wall``: the body mobility with and without the wall;
* ``rollers``: multiblob against single-blob roller spheres;
* ``lubrication``: on scenes of spheres of one radius, 1 blob, 1 blob with lubrication and resolved
  shells at the smallest pair and wall gaps, from the chart of doc/lubrication_accuracy.md
  (``advisor_lubrication``);
* ``solver``: one dense solve against one preconditioned GMRES solve;
* ``backend``: one ``M f`` on every usable backend;
* ``geometry``: in a box periodic in x and y above the wall, the pseudo-periodic direct sum (first ring of
  images) against the truly periodic spectral product with each kernel (``advisor_geometry``);
* ``dt``: the time step: stability, no crossing of the wall or of bodies, and its error measured
  on the scene by step doubling (``recommend_dt``; the bound that binds is named).

After the measurements the recommendation is limited to the options of the
input's program (``keep_to_program``), a model change gets rescaled per-blob
parameters and is checked by one mobility problem against the user's model
(``keep_physics``; dropped when the check fails), and the time step is bounded.

Error, everywhere: the largest relative error among a body's six
self-mobility diagonal entries (translation along x, y (parallel to the
wall) and z (perpendicular); rotation about x, y and z), at the scene's
smallest gap: the wall gap of the lowest body of the type, and, separately,
the nearest pair of bodies of the type.  For a sphere at the wall gap the
reference is exact (``multi_bodies.advice.sphere_tables``, for h/R >= 1.01);
otherwise it is the Richardson extrapolation of the 42-, 162- and 642-blob
shells, whose own error is estimated by the same extrapolation.

Mobilities here are dense (one body or one pair, or the whole scene for the
dense solve): shapes (6, 6) per body, torques about the body centre; lengths
and times in the user's units.
"""
import time

import numpy as np

import utils

from mobility import choose
from mobility.interface import Geometry, preferred_backend, registered_backends, unusable_reason
from multi_bodies.files.scheme_table import moves_rollers, scheme_entry, scheme_has
from multi_bodies.solver import body_solver
from multi_bodies.solver.solves import Solver

from multi_bodies.advice import advisor_physics
from multi_bodies.advice.advisor_resolution import ResolutionMeasurements
from multi_bodies.advice.advisor_lubrication import LubricationMeasurements
from multi_bodies.advice.advisor_geometry import GeometryMeasurements
from multi_bodies.advice.advisor_report import (AdvisorReport, _percent, _seconds,  # noqa: F401
                                        apply_recommendation, recommendation_lines)
from multi_bodies.advice.advisor_models import (  # noqa: F401  (also re-exported)
    blob_mobility,
    Choice,
    Scene,
    DENSE_BLOB_LIMIT,
    DENSE_SCHEMES,
    GMRES_WARNING_ITERATIONS,
    MEASURE_BUDGET_S,
    NO_WALL,
    RICHARDSON_LEVELS,
    ROLLER_SCHEMES,
    SCHEME_TABLE,
    SHELL_SIZES,
    STATIC_SCHEMES,
    STOCHASTIC_SCHEME_TABLE,
    bodies_mobility,
    bulk_radius,
    calibrated_model,
    cheapest_scheme,
    distance_to_other_bodies,
    exact_diagonal,
    fixed_radius_model,
    normalised_diagonal,
    richardson,
    worst_error)


# ------------------------------------------------------------------ the advisor
class Advisor(ResolutionMeasurements, LubricationMeasurements, GeometryMeasurements, AdvisorReport):
    """Measures every choice for one scene; see the module docstring.

    Parameters: ``scene`` (Scene), ``accuracy`` (target relative error),
    ``quick`` (skip measurements that grow with the scene: shells' errors
    from the shipped table, pair errors skipped, costs modelled from one
    measured ``M f``, the dense solve modelled above 600 blobs), ``coarsen`` (also offer coarsened
    models of non-spherical bodies), ``log`` (callable for progress lines).
    """

    def __init__(self, scene, accuracy=0.01, quick=False, coarsen=False, log=None):
        self.scene, self.accuracy, self.quick, self.coarsen = scene, float(accuracy), quick, coarsen
        self.log = log or (lambda text: None)
        self.program = advisor_physics.program_of(scene.options)
        self.hooks_per_blob = [name for name in advisor_physics.PER_BLOB_HOOKS if not scene.hooks.is_default(name)]
        self.check = None
        self._physics_check = None
        self.choices = []
        self.notes = []
        self.recommendation = {}
        self.files = {}
        self.sources = []
        # the registry's first usable backend that builds dense matrices: the fastest CPU one (C++, else python)
        self.backend = preferred_backend(Geometry('single_wall'), dense_matrices=True)
        self.iterations = None
        self.product_seconds = {}  # (backend, wall) -> (seconds of one M f of the scene, blobs)
        self.lubrication_lines = []  # input lines of the lubrication topic's model change (advisor_lubrication)
        self.lubrication_files = []  # vertex files those lines name
        self.lubrication_alternative = False  # True: those lines are a cheaper alternative to the model lines

    def blob_gaps(self):
        """Distance of every blob to the closest blob of another body, (N,), computed once."""
        if getattr(self, '_blob_gaps', None) is None:
            self._blob_gaps = distance_to_other_bodies(self.scene.r_vectors, self.scene.arrays.blob_body_index)
        return self._blob_gaps

    # -------------------------------------------------------------- costs
    def product_time(self, r_vectors, wall=True, backend=None):
        """(seconds of one M f on these blobs, 'measured' or 'modelled') with ``backend`` (default: the fastest CPU)."""
        backend = backend or self.backend
        n = len(r_vectors)
        base = self.product_seconds.get((backend, wall)) if self.product_seconds else None
        if base is not None:
            base_seconds, base_n = base
            predicted = base_seconds * (n / base_n) ** 2
            if n == base_n:
                return base_seconds, 'measured'
            if self.quick or predicted > MEASURE_BUDGET_S:
                return predicted, 'modelled'
        mobility = blob_mobility(backend, self.scene.eta, self.scene.a, wall, self.scene.options.periodic_length)
        force = np.random.default_rng(2).standard_normal(3 * n)
        seconds = choose.time_call(lambda: mobility.velocities(r_vectors, force), repeats=2)
        if n == self.scene.num_blobs:
            self.product_seconds = self.product_seconds or {}
            self.product_seconds[(backend, wall)] = (seconds, n)
        return seconds, 'measured'

    def cost_per_step(self, seconds):
        """Cost of one mobility solve: ``M f`` time x GMRES iterations of the scene (at least one)."""
        return seconds * max(1, self.iterations or 1)

    def replaced_scene_blobs(self, structure, model_blobs):
        """Blob positions (N', 3) of the scene with every body of ``structure`` replaced by ``model_blobs``."""
        parts = []
        for other in self.scene.structures:
            if other is structure:
                rotations = self.scene.arrays.rotation_matrices(self.scene.arrays.configuration)[other['bodies']]
                parts.append((other['centres'][:, None, :] + np.einsum('kij,nj->kni', rotations, model_blobs)
                              ).reshape(-1, 3))
            else:
                parts.append(other['r_type'].reshape(-1, 3))
        return np.concatenate(parts)

    # -------------------------------------------------------------- run everything
    def run(self):
        """Measure every choice, keep to the program's options, check the physics; returns self.

        Progress: one line per measurement through ``log`` (the script sends them to stderr).
        """
        steps = [('solver', self.measure_solver), ('backend', self.measure_backends),
                 ('resolution', self.measure_resolution), ('wall', self.measure_wall),
                 ('rollers', self.measure_rollers), ('lubrication', self.measure_lubrication),
                 ('geometry', self.measure_geometry), ('dt', self.measure_dt),
                 ('scope', self.keep_to_program), ('check', self.keep_physics), ('dt bounds', self.recommend_dt)]
        if not self.lubrication_applies():
            steps = [step for step in steps if step[0] != 'lubrication']
        for index, (name, step) in enumerate(steps):
            self.log('advise: [%d/%d] %s ...' % (index + 1, len(steps), name))
            start = time.perf_counter()
            step()
            self.log('advise: [%d/%d] %s done in %.2f s' % (index + 1, len(steps), name,
                                                            time.perf_counter() - start))
        return self

    def lubrication_applies(self):
        """Whether the lubrication topic (advisor_lubrication) has anything to say: a dynamic run whose bodies are
        all spheres (the models it compares), or one with a lubrication scheme (its note then says why the bodies
        are not compared).  Other inputs skip the topic, as they skip the files of features they do not use."""
        if self.program != 'dynamic':
            return False
        structures = self.scene.structures
        spheres = bool(structures) and all(s['sphere'] is not None for s in structures)
        return spheres or scheme_has(self.scene.options.scheme, 'lubrication')

    def keep_to_program(self):
        """Recommend only options the input's program uses (advisor_physics.scope)."""
        self.notes += advisor_physics.scope(self.recommendation, self.scene.options, self.program)

    def keep_physics(self):
        advisor_physics.keep_physics(self)

    def physics_check(self):
        """The user's model set up as the program does, with its forces and velocities (made once)."""
        if self._physics_check is None:
            self._physics_check = advisor_physics.PhysicsCheck(self)
        return self._physics_check

    def write_files(self):
        """Write the vertex files of the recommended models (those of ``self.files`` a structure line names)."""
        import os
        from multi_bodies.files.structure_files import write_vertex_file
        for path, (blobs, comment) in self.files.items():
            if not self.recommends_file(path):
                continue
            folder = os.path.dirname(path)
            if folder:
                os.makedirs(folder, exist_ok=True)
            write_vertex_file(path, blobs, comment=comment)

    def current_model_error(self):
        """Largest estimated error of the user's own models (resolution rows 'current'; rollers), 0 if unknown."""
        errors = [c.estimated_error for c in self.choices if c.estimated_error is not None and (
            (c.topic == 'resolution' and c.candidate.startswith('current')) or
            (c.topic == 'rollers' and c.candidate.endswith('(current)')))]
        return max(errors, default=0.0)

    def add(self, topic, structure, candidate, blobs, error, cost, meets, note=''):
        if error is not None and not np.isfinite(error):
            error = None  # unknown (JSON has no infinity)
        self.choices.append(Choice(topic, structure, candidate, None if blobs is None else int(blobs),
                                   None if error is None else float(error), None if cost is None else float(cost),
                                   bool(meets), note))

    # -------------------------------------------------------------- solver
    def scene_rhs(self):
        """Force-torque (Nb, 6) and slip (N, 3) of the scene (seeded random forces when they vanish)."""
        scene = self.scene
        from multi_bodies.solver.model import Model
        system = Model(scene.bodies, scene.arrays, scene.hooks, scene.physics(), scene.eta, scene.a,
                       scene.options.solver_tolerance, vector_product_name=self.backend, blobs_name=self.backend,
                       blob_blob_name=self._forces_backend(), periodic_length=scene.options.periodic_length)
        force_torque = system.forces_torques(scene.arrays.configuration, scene.r_vectors)
        slip = system.slip(scene.arrays.configuration) if system.has_slip else np.zeros_like(scene.r_vectors)
        if not np.any(force_torque) and not np.any(slip):
            force_torque = np.random.default_rng(3).standard_normal((scene.arrays.num_bodies, 6))
        return force_torque, slip

    def _forces_backend(self):
        name = self.scene.options.blob_blob_force_implementation
        if name in ('auto', 'pycuda'):
            return 'C++' if self.backend == 'C++' else 'python'
        return name

    def measure_solver(self):
        scene = self.scene
        wall = scene.wall
        # the model's two mobilities: M f with the box, the dense blocks without periodic images (per-blob radii
        # where the vertex files give them)
        radius = body_solver.blob_radius_argument(scene.arrays, scene.a)
        vector = blob_mobility(self.backend, scene.eta, radius, wall, scene.options.periodic_length)
        blobs = blob_mobility(self.backend, scene.eta, radius, wall)
        force_torque, slip = self.scene_rhs()
        tolerance = scene.options.solver_tolerance
        results = []

        def gmres_solve():
            # The same solve as the scripts and schemes (a solves.Solver, flagging), from a zero guess.
            configuration = scene.arrays.configuration
            problem = body_solver.MobilityProblem(scene.arrays, configuration, vector)
            preconditioner = body_solver.BlockDiagonalPreconditioner(scene.arrays, configuration, blobs)
            results.append(Solver(tolerance, not_converged='flag').solve(
                problem, problem.rhs(slip=slip, force_torque=force_torque), preconditioner))
        # One solve (preconditioner built, GMRES from a zero guess); repeated when short, best time kept.
        gmres_seconds = choose.time_call(gmres_solve, repeats=2)
        result = results[-1]
        self.iterations = result.iterations
        note = '%d GMRES iterations at solver_tolerance %g' % (result.iterations, tolerance)
        if not result.converged:
            note += ', NOT converged'
        if result.iterations > GMRES_WARNING_ITERATIONS:
            warning = ('WARNING: GMRES needed %d iterations (more than %d) at solver_tolerance %g: the packing is '
                       'dense or the problem ill-conditioned (blobs overlapping the wall or each other, blob radius '
                       'large against the spacing); check the configuration' %
                       (result.iterations, GMRES_WARNING_ITERATIONS, tolerance))
            self.notes.append(warning)
            note += ' (above %d: warning)' % GMRES_WARNING_ITERATIONS
        if moves_rollers(scene.options.scheme):
            note += ' (of the multiblob problem; rollers need none)'
            seconds = self.product_time(scene.r_vectors, wall)[0]
            self.add('solver', None, 'rollers: one M f per step%s' % (
                '' if scene.options.free_kinematics else ' plus GMRES for the prescribed spins'),
                scene.num_blobs, None, seconds, True, 'free_kinematics %s' % scene.options.free_kinematics)
        self.add('solver', None, 'preconditioned GMRES', scene.num_blobs, tolerance, gmres_seconds,
                 result.converged and result.iterations <= GMRES_WARNING_ITERATIONS, note)
        if moves_rollers(scene.options.scheme):
            return
        # Dense: measured on the scene when small, modelled as (N / n)^3 from a measured smaller dense solve.
        n = scene.num_blobs
        if n <= DENSE_BLOB_LIMIT and (not self.quick or n <= 600):
            dense_seconds = choose.time_call(lambda: body_solver.dense_mobility_velocities(
                scene.arrays, scene.arrays.configuration, force_torque, slip, blobs), repeats=2)
            how = 'measured'
        else:
            probe = min(n, 600)
            r = scene.r_vectors[:probe]
            start = time.perf_counter()
            M = blobs.replace(blob_radius=scene.a).dense_matrix(r)
            np.linalg.inv(M)
            dense_seconds, how = (time.perf_counter() - start) * 2.0 * (n / probe) ** 3, 'modelled'
        self.add('solver', None, 'dense solve', n, None, dense_seconds, True,
                 '%s; memory %.3g GB for the %d x %d blob matrix' % (how, 8 * 2 * (3 * n) ** 2 / 1e9, 3 * n, 3 * n))
        dense_scheme = DENSE_SCHEMES.get(scene.options.scheme)
        if dense_seconds < gmres_seconds and dense_scheme:
            self.recommendation['scheme'] = dense_scheme
        elif dense_seconds < gmres_seconds:
            self.notes.append('a dense solve (%.3g s) is faster than GMRES (%.3g s) here, but scheme %s has no '
                              'dense-algebra variant' % (dense_seconds, gmres_seconds, scene.options.scheme))

    # -------------------------------------------------------------- backends
    def measure_backends(self):
        scene = self.scene
        wall = scene.wall
        costs = {}
        geometry = Geometry('single_wall' if wall else 'free_space')
        for backend in registered_backends(geometry):  # the registry's preference order
            reason = unusable_reason(backend)
            if reason is not None:
                self.add('backend', None, backend + ('' if wall else NO_WALL), scene.num_blobs, None, None, False,
                         'not usable here: %s' % reason)
                continue
            if backend == 'python' and scene.num_blobs > 4000:
                seconds, how = choose.modelled_seconds('python', 'vector_product', scene.num_blobs, wall)
            else:
                seconds, how = self.product_time(scene.r_vectors, wall, backend)
            costs[backend] = seconds
            self.add('backend', None, backend + ('' if wall else NO_WALL), scene.num_blobs, 0.0, seconds, True,
                     'one M f, %s' % how)
        fastest = min(costs, key=costs.get)
        suffix = '' if wall else NO_WALL
        cpu = next(b for b in registered_backends(geometry, dense_matrices=True) if b in costs)
        for option, best in (('mobility_vector_prod_implementation', fastest), ('mobility_blobs_implementation', cpu)):
            current = getattr(scene.options, option)
            if current not in (best + suffix, 'auto' + suffix):  # auto measures the same costs at run time
                self.recommendation[option] = best + suffix

    # -------------------------------------------------------------- wall
    def measure_wall(self):
        scene = self.scene
        if not scene.wall:
            self.add('wall', None, 'no wall (current)', scene.num_blobs, None, None, True, 'the scene has no wall')
            return
        worst = 0.0
        for structure in scene.structures:
            low = structure['lowest']
            blobs, centre = structure['r_type'][low], structure['centres'][low]
            if len(blobs) > DENSE_BLOB_LIMIT:
                worst = np.inf
                self.add('wall', structure['ID'], 'no wall, lowest body', len(blobs), None, None, False,
                         'too many blobs per body for a dense body mobility here')
                continue
            with_wall = bodies_mobility([blobs], [centre], scene.a, scene.eta, True, self.backend)
            without = bodies_mobility([blobs], [centre], scene.a, scene.eta, False, self.backend)
            difference = worst_error(np.diag(without), np.diag(with_wall))
            worst = max(worst, difference)
            self.add('wall', structure['ID'], 'no wall, lowest body (centre z = %.4g)' % centre[2],
                     structure['num_blobs'], difference, None, difference <= self.accuracy,
                     'largest relative change of the self-mobility diagonal when the wall is removed')
        wall_seconds, how_wall = self.product_time(scene.r_vectors, True)
        free_seconds, how_free = self.product_time(scene.r_vectors, False)
        self.add('wall', None, 'with wall (current)', scene.num_blobs, 0.0, self.cost_per_step(wall_seconds), True,
                 'M f %s' % how_wall)
        meets = worst <= self.accuracy
        self.add('wall', None, 'no wall (_no_wall backends)', scene.num_blobs, worst,
                 self.cost_per_step(free_seconds), meets,
                 'M f %s; %.2fx faster than with the wall' % (how_free, wall_seconds / max(free_seconds, 1e-12)))
        if meets:
            if moves_rollers(scene.options.scheme):
                self.recommendation['domain'] = 'no_wall'
            else:
                for option in ('mobility_vector_prod_implementation', 'mobility_blobs_implementation'):
                    base = self.recommendation.get(option, getattr(scene.options, option))
                    self.recommendation[option] = base if base.endswith(NO_WALL) else base + NO_WALL

    # -------------------------------------------------------------- rollers
    def measure_rollers(self):
        scene = self.scene
        spheres = [s for s in scene.structures if s['sphere'] is not None]
        if len(spheres) != len(scene.structures) or any(s['spec'].slip_file for s in spheres):
            self.add('rollers', None, 'single-blob rollers', None, None, None, False,
                     'not applicable: not every structure is a passive sphere (rollers carry no slip)')
            return
        roller_error, multiblob_error, roller_cost, multiblob_cost = 0.0, 0.0, 0.0, 0.0
        known = True
        for s in spheres:
            rows = [c for c in self.choices if c.topic == 'resolution' and c.structure == s['ID']]
            current = rows[0]
            roller = [c for c in rows if c.blobs == 1 and c.candidate.startswith('1 blob')][0]
            if roller.estimated_error is None or current.estimated_error is None:
                known = False
                continue
            roller_error = max(roller_error, roller.estimated_error)
            multiblob_error = max(multiblob_error, current.estimated_error)
            roller_cost, multiblob_cost = roller.cost_s, current.cost_s
        radii = {round(s['sphere']['radius'], 9) for s in spheres}
        dynamic = scene.options.scheme not in STATIC_SCHEMES
        if moves_rollers(scene.options.scheme):
            self.rollers_scene(spheres, roller_error if known else None)
            return
        self.add('rollers', None, 'multiblob (current)', scene.num_blobs, multiblob_error if known else None,
                 multiblob_cost, known and multiblob_error <= self.accuracy)
        meets = known and roller_error <= self.accuracy
        applicable = dynamic and len(radii) == 1
        self.add('rollers', None, 'single-blob rollers', scene.arrays.num_bodies, roller_error if known else None,
                 roller_cost, meets, '' if applicable else 'rollers need a dynamic scheme and spheres of one radius')
        if meets and applicable and not moves_rollers(scene.options.scheme):
            roller_scheme = ROLLER_SCHEMES.get(scene.options.scheme)
            if roller_scheme is None:
                return
            for key in [k for k in self.recommendation if k.startswith('structure:') or k == 'blob_radius']:
                del self.recommendation[key]
            self.recommendation.pop('scheme', None)
            self.recommendation['scheme'] = roller_scheme
            self.recommendation['blob_radius'] = '%.12g' % radii.pop()
            # Torque-free rollers: the rigid spheres of the input carry no drive.
            self.recommendation['free_kinematics'] = 'True'
            self.recommendation['omega_one_roller'] = '0 0 0'
            for s in spheres:
                vertex = self.write_vertex(s['ID'], 'blob', np.zeros((1, 3)))
                self.recommendation['structure:%s' % s['ID']] = '%s %s' % (vertex, s['spec'].clones_file)
                if np.linalg.norm(s['sphere']['offset']) > 1e-9 * s['sphere']['radius']:
                    self.notes.append('%s: the shell centre is not the body location; move the clones locations '
                                      'by the centre offset %s for the roller model' % (s['ID'], s['sphere']['offset']))

    def rollers_scene(self, spheres, roller_error):
        """A roller scheme already: compare with the multiblob model the resolution section recommends."""
        scene = self.scene
        roller_cost = self.product_time(scene.r_vectors, scene.wall)[0]
        self.add('rollers', None, 'single-blob rollers (current)', scene.num_blobs, roller_error, roller_cost,
                 roller_error is not None and roller_error <= self.accuracy, 'one M f per step (free kinematics)')
        shells = [k for k in self.recommendation if k.startswith('structure:')]
        if not shells:
            return
        chosen = [c for s in spheres for c in self.choices if c.topic == 'resolution' and c.structure == s['ID']
                  and self.recommendation.get('structure:%s' % s['ID'], '').split()[0].endswith(
                      '.%s.vertex' % c.candidate.split(' (')[0].replace(' ', '_'))]
        error = max((c.estimated_error for c in chosen if c.estimated_error is not None), default=None)
        self.add('rollers', None, 'multiblob (%s)' % ', '.join(c.candidate for c in chosen), None, error,
                 max((c.cost_s for c in chosen if c.cost_s is not None), default=None),
                 error is not None and error <= self.accuracy, 'cost assumes the GMRES iterations measured here')
        multiblob = {v: k for k, v in ROLLER_SCHEMES.items()}.get(scene.options.scheme)
        options = scene.options
        driven = not options.free_kinematics or np.any(np.asarray(options.omega_one_roller) != 0)
        if driven:
            # The rigid schemes have no omega_one_roller or free_kinematics: the drive would be dropped.
            for key in shells + ['blob_radius']:
                self.recommendation.pop(key, None)
            self.notes.append('rollers: the rollers are driven (free_kinematics %s, omega_one_roller %s); the rigid '
                              'multiblob schemes ignore both options, so a multiblob model would drop the drive: the '
                              'roller model is kept' % (options.free_kinematics,
                                                        ' '.join('%g' % w for w in options.omega_one_roller)))
            return
        if multiblob is None:
            for key in shells + ['blob_radius']:
                self.recommendation.pop(key, None)
            self.notes.append('scheme %s has no multiblob counterpart here: the shell models are not put in the input'
                              % scene.options.scheme)
            return
        self.recommendation['scheme'] = multiblob
        if scene.options.domain == 'no_wall':
            self.notes.append('domain no_wall applies to rollers only: with multiblob bodies use the _no_wall '
                              'mobility implementations')

    # -------------------------------------------------------------- time step
    def measure_dt(self):
        scene = self.scene
        options = scene.options
        if self.program == 'mcmc':
            self.add('dt', None, 'no time step (Monte Carlo)', None, None, None, True)
            return
        if options.scheme in STATIC_SCHEMES:
            self.add('dt', None, 'no time step (static problem %s)' % options.scheme, None, None, None, True)
            return
        physics = scene.physics()
        hooks = scene.hooks
        # The body with the lowest blob; its stiffness against a vertical displacement of the whole body.
        lowest_blob = int(np.argmin(scene.r_vectors[:, 2]))
        body = int(scene.arrays.blob_body_index[lowest_blob])
        start, stop = scene.arrays.blob_offsets[body], scene.arrays.blob_offsets[body + 1]
        blobs = scene.r_vectors[start:stop]
        centre = blobs.mean(axis=0)
        if len(blobs) > DENSE_BLOB_LIMIT:
            self.add('dt', None, 'no estimate: the lowest body has %d blobs, too many for a dense mobility here'
                     % len(blobs), None, None, None, False)
            return

        def vertical_force(shift):
            moved = blobs + np.array([0.0, 0.0, shift])
            return float(np.sum(np.asarray(hooks.blob_external_forces(moved, **physics)).reshape(-1, 3)[:, 2]))

        delta = 1e-4 * max(scene.a, 1e-12)
        stiffness_now = -(vertical_force(delta) - vertical_force(-delta)) / (2 * delta)
        mobility_now = bodies_mobility([blobs], [centre], scene.a, scene.eta, scene.wall, self.backend)[2, 2]
        # Resting height: where gravity and the wall repulsion balance (found by bisection on the shift).
        rest_shift, rest_note = None, ''
        low_shift, high_shift = -float(np.min(blobs[:, 2])) + 1e-6 * scene.a, 0.0
        if vertical_force(0.0) < 0 and vertical_force(low_shift) > 1e-9 * abs(vertical_force(0.0)):
            for _ in range(80):
                middle = 0.5 * (low_shift + high_shift)
                if vertical_force(middle) > 0:
                    low_shift = middle
                else:
                    high_shift = middle
            rest_shift = 0.5 * (low_shift + high_shift)
        elif vertical_force(0.0) < 0:
            rest_note = ('the wall repulsion cannot balance gravity on this body: it sinks until its lowest blob '
                         'nearly touches z = 0, slowed only by the regularised mobility (damped like (z/a)^2); '
                         'no resting-state stiffness estimate')
        estimates = [('at the start', stiffness_now + 0.0, mobility_now, float(np.min(blobs[:, 2])))]
        if rest_shift is not None:
            rested = blobs + np.array([0.0, 0.0, rest_shift])
            stiffness_rest = -(vertical_force(rest_shift + delta) - vertical_force(rest_shift - delta)) / (2 * delta)
            mobility_rest = bodies_mobility([rested], [centre + [0, 0, rest_shift]], scene.a, scene.eta, scene.wall,
                                            self.backend)[2, 2]
            estimates.append(('resting on the wall', stiffness_rest + 0.0, mobility_rest, float(np.min(rested[:, 2]))))
        rate = max(k * mu for _, k, mu, _ in estimates if k > 0) if any(k > 0 for _, k, _, _ in estimates) else 0.0
        # Blob-blob repulsion between the nearest blobs of two bodies (relative mobility ~ twice one body's).
        pair_note = ''
        best = float(np.min(self.blob_gaps()))
        if options.blob_blob_force_implementation != 'None' and np.isfinite(best):

            def pair_force(x):
                return float(np.asarray(hooks.blob_blob_force(np.array([x, 0.0, 0.0]), **physics)).reshape(3)[0])
            k_pair = abs((pair_force(best + delta) - pair_force(best - delta)) / (2 * delta))
            pair_rate = k_pair * 2.0 * mobility_now
            pair_note = ('nearest blobs of two bodies at %.4g: pair stiffness %.3g, rate (relative mobility taken as '
                         'twice mu_zz) %.3g' % (best, k_pair, pair_rate))
            rate = max(rate, pair_rate)
        dt = options.dt
        for where, k, mu, z in estimates:
            self.notes.append('dt: %s, lowest blob z = %.4g: wall+gravity stiffness %.4g, mobility mu_zz %.4g, '
                              'mu k = %.4g per unit time' % (where, z, k, mu, mu * k))
        if pair_note:
            self.notes.append('dt: ' + pair_note)
        if rest_note:
            self.notes.append('dt: ' + rest_note)
        solve_cost = next((c.cost_s for c in self.choices if c.topic == 'solver' and c.candidate.endswith('GMRES')),
                          None)
        safe = []
        for scheme, row in SCHEME_TABLE.items():
            limit = row['stability'] / rate if rate > 0 else np.inf
            stable = dt > 0 and dt < limit
            if stable:
                safe.append(scheme)
            self.add('dt', None, '%s: linearly stable below dt = %.4g (input dt %g; stability only, see the dt '
                     'bounds)' % (scheme, limit, dt), None, None,
                     None if solve_cost is None else solve_cost * row['solves_per_step'], stable,
                     'order %d; %s; dt mu k < %g' % (row['order'], row['source'], row['stability']))
        # Stochastic: the rms Brownian step of the lowest body against the Debye lengths.
        kT = options.kT
        mu = estimates[-1][2]
        lengths = [options.debye_length_wall] + ([options.debye_length]
                                                 if options.blob_blob_force_implementation != 'None' else [])
        b = min(lengths)
        dt_brownian = b ** 2 / (2.0 * kT * mu) if kT > 0 and mu > 0 else np.inf
        step = np.sqrt(2.0 * kT * mu * dt) if dt > 0 else 0.0
        self.add('dt', None, 'stochastic: Brownian step sqrt(2 kT mu dt) = %.4g (kT %g) against Debye length %g; '
                 'equal at dt = %.4g' % (step, kT, b, dt_brownian), None, None, None, step <= b,
                 'Brownian step against the potential range; the weak-error table ranks the schemes below')
        self.notes.append('dt: schemes stable at the input dt = %g: %s. Of these, deterministic_adams_bashforth costs '
                          'one solve per step like forward Euler and is second order, so it is the cheaper for a given '
                          'accuracy wherever it is stable. The limits are linear-stability estimates; '
                          'doc/integrators_accuracy_vs_dt.md measured on its stiff scene (mu k = 5.6 by this estimate) '
                          'Adams-Bashforth crossing the wall at dt mu k = 4.5 and inaccurate at 2.2, forward Euler '
                          'bounded but off by 0.4 at 4.5' % (dt, ', '.join(safe) or 'none'))
        # Roller schemes move single blobs only; the rigid schemes are for the other runs.
        rollers = moves_rollers(options.scheme)
        applicable = {name: row for name, row in STOCHASTIC_SCHEME_TABLE.items() if moves_rollers(name) == rollers
                      and not (name == 'stochastic_EM' and self.scene.wall)}  # no drift: wrong above a wall
        # The table's dt are in units of the relaxation time tau = 1/(mu k) of the stiffest mode (its scene:
        # blobs in a stiff trap near the wall); here tau = 1/rate of the estimates above.
        ranked = cheapest_scheme(applicable, self.accuracy, solve_cost or 0.0, 1.0 / rate) if rate > 0 else []
        for cost, scheme, dt_target in ranked:
            row = applicable[scheme]
            self.add('dt', None, '%s: weak error %s at dt = %.4g (%.3g tau, tau = 1/(mu k) = %.4g)'
                     % (scheme, _percent(self.accuracy), dt_target, dt_target * rate, 1.0 / rate), None,
                     self.accuracy, cost, True, 'cost per unit time; %s' % row['source'])
        if ranked:
            self.notes.append('dt: cheapest stochastic scheme for %s: %s' % (_percent(self.accuracy), ranked[0][1]))
        else:
            self.notes.append('dt: no stochastic scheme of the shipped weak-error table applies; only the '
                              'Brownian-step estimate above is given')
        self.dt_summary = dict(rate=rate, safe=safe, dt_brownian=dt_brownian, mu=mu)

    def recommend_dt(self):
        """The adequate time step: the smallest of the stability, no-crossing, accuracy and weak-error bounds.

        Speeds come from one mobility problem of the user's model (``physics_check``); the bound that binds is
        named, and a smaller dt than the input's is recommended with n_steps and n_save that keep the
        simulated time and the save interval.
        """
        options, scene = self.scene.options, self.scene
        if self.program != 'dynamic' or getattr(self, 'dt_summary', None) is None:
            return
        try:
            checker = self.physics_check()
        except (utils.UserInputError, utils.SimulationStopped, np.linalg.LinAlgError):
            return  # said by the check
        scheme = self.recommendation.get('scheme', options.scheme)
        speeds = advisor_physics.blob_speeds(checker.user_system, checker.user_velocities, options.scheme)
        speed = float(np.max(speeds)) if len(speeds) else 0.0
        wall_gap = float(np.min(scene.r_vectors[:, 2])) if scene.wall else np.inf
        pair_gap = float(np.min(self.blob_gaps()))
        lengths = []
        if scene.wall and options.repulsion_strength_wall != 0:
            lengths.append(options.debye_length_wall)
        if options.blob_blob_force_implementation != 'None' and options.repulsion_strength != 0:
            lengths.append(options.debye_length)
        entry = scheme_entry(scheme)
        base = entry.rollers_of or entry.dense_of or scheme  # the rigid iterative scheme it stands in for
        if base not in SCHEME_TABLE:  # stochastic: the explicit deterministic part (Adams-Bashforth or Euler)
            base = 'deterministic_adams_bashforth' if 'adams_bashforth' in base else 'deterministic_forward_euler'
        rate = self.dt_summary['rate']
        stability = SCHEME_TABLE[base]['stability'] / rate if base in SCHEME_TABLE and rate > 0 else np.inf
        stochastic = entry.kind == 'stochastic'
        bounds = advisor_physics.dt_bounds(stability, speed, wall_gap, pair_gap)
        mu = self.dt_summary.get('mu', 0.0)
        if stochastic and options.kT > 0 and mu > 0 and np.isfinite(wall_gap):
            bounds.append(('Brownian no crossing', (0.5 * wall_gap) ** 2 / (2 * options.kT * mu),
                           'the rms Brownian step sqrt(2 kT mu dt) stays below half the wall gap'))
        if stochastic and scheme in STOCHASTIC_SCHEME_TABLE and options.kT > 0 and rate > 0:
            constant, power = STOCHASTIC_SCHEME_TABLE[scheme]['weak_error']
            bounds.append(('weak error', (self.accuracy / abs(constant)) ** (1.0 / power) / rate,
                           'the measured weak-error table of %s gives the target: relative bias of the variance '
                           'of the stiffest coordinate %.3g (dt/tau)^%.2f, tau = 1/(mu k) = %.4g'
                           % (scheme, abs(constant), power, 1.0 / rate)))
        # Accuracy of the drift, measured on this scene by step doubling from the hard bounds.
        hard = min(value for _, value, _ in bounds)
        if np.isfinite(hard) and speed > 0:
            measured_scheme = scheme if not stochastic else (
                'deterministic_adams_bashforth_rollers' if moves_rollers(scheme) else 'deterministic_forward_euler')
            measured = advisor_physics.measured_dt(checker.options_for_dt(self.recommendation), measured_scheme,
                                                   hard, self.accuracy, steps=2 if self.quick else 4)
            self.dt_measurement = measured
            bounds.append(('accuracy (measured)', measured['dt'],
                           'error per unit time within the target: %s, step doubling over %d steps of %s%s; %s' % (
                               _percent(self.accuracy), 2 if self.quick else 4, measured_scheme,
                               ' (the drift of the stochastic scheme)' if stochastic else '',
                               '; '.join('dt %.3g: %s' % t for t in measured['tries'])) +
                           ('' if measured['verified'] else '; NOT verified: the last value is extrapolated')))
        name, limit, _ = min(bounds, key=lambda b: b[1])
        for bound, value, reason in bounds:
            self.add('dt', None, 'bound %s: dt <= %.4g' % (bound, value), None, None, None, options.dt <= value,
                     reason + ('; BINDS' if bound == name else ''))
        self.dt_bound = dict(dt=float(limit), binds=name, bounds={b: float(v) for b, v, _ in bounds}, speed=speed)
        if entry.lubrication:
            self.notes.append('dt: the bounds above are those of the far-field model (one blob per sphere without '
                              'lubrication, which moves the spheres faster near contact); no dt is recommended for '
                              'a lubrication scheme (the input dt = %g is kept)' % options.dt)
            return
        if not np.isfinite(limit):
            self.notes.append('dt: no bound applies (no force moves the bodies and no stiffness was found)')
            return
        if options.dt <= limit:
            self.notes.append('dt: the input dt = %g is within every bound (the %s bound, dt <= %.3g, binds)'
                              % (options.dt, name, limit))
            # A larger step that keeps the saved times: dt m with m a divisor of n_save, within the bounds.
            factor = max([m for m in range(1, options.n_save + 1) if options.n_save % m == 0 and
                          options.dt * m <= limit], default=1)
            if factor > 1 and options.n_steps % factor == 0:
                self.recommendation['dt'] = '%.12g' % (options.dt * factor)
                self.recommendation['n_steps'] = '%d' % (options.n_steps // factor)
                self.recommendation['n_save'] = '%d' % (options.n_save // factor)
                self.notes.append('dt: a step %d times longer (dt %s) is still within every bound and saves the '
                                  'same times (n_save %d -> %s): %d times fewer solves'
                                  % (factor, self.recommendation['dt'], options.n_save,
                                     self.recommendation['n_save'], factor))
            return
        digits = 10 ** np.floor(np.log10(limit))
        new_dt = float(np.floor(limit / digits * 10) / 10 * digits)
        self.recommendation['dt'] = '%.3g' % new_dt
        if options.n_steps:
            self.recommendation['n_steps'] = '%d' % int(np.ceil(options.n_steps * options.dt / new_dt))
            self.recommendation['n_save'] = '%d' % max(1, int(round(options.n_save * options.dt / new_dt)))
        self.notes.append('dt: the input dt = %g exceeds the %s bound (dt <= %.3g, speed %.3g at the start): '
                          'recommended dt %s%s' % (options.dt, name, limit, speed, self.recommendation['dt'],
                                                   ', with n_steps and n_save that keep the simulated time and '
                                                   'the save interval' if options.n_steps else ''))


def advise(input_file, accuracy=0.01, quick=False, coarsen=False, log=None):
    """Read the scene of ``input_file`` (run directory = current directory) and return the finished Advisor."""
    return Advisor(Scene(input_file), accuracy, quick, coarsen, log).run()
