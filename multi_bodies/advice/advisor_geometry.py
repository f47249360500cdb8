"""The advisor's geometry topic: the published pseudo-periodic sums against the truly periodic spectral product.

Helpers of ``multi_bodies/advice/advisor.py`` (floor 7); ``GeometryMeasurements`` is a part of
``advisor.Advisor``.  For a scene in a box periodic in x and y above the wall (``periodic_length Lx Ly 0`` with a
direct ``mobility_vector_prod_implementation``, or ``spectral`` over the wall), on the scene's own blobs:

* the **pseudo-periodic direct sum** (each blob sees the minimum image and the first ring of images of every
  other blob, as published): its error against the truly periodic mobility of the same blobs, the limit of
  the image sums over growing squares of rings (Richardson in 1/n, ``mobility.image_sums``; above a wall the far
  field decays like 1/rho^3 and the sums converge), at a sample of target blobs from every source blob;
* the **spectral product** with each kernel (``spectral_kernel``: force-only ``w6``, ``w5``, ``w4``; rollers the
  monopole/dipole pairs): its error against the converged spectral product (the finest kernel, ``w6``, on a
  grid twice as fine: ``mobility.spectral.parameters.refined_parameters``), and how far the converged spectral
  product is from the direct sum's periodic limit: the difference of the two blob models (the kernel's blob
  against Rotne-Prager-Blake's, largest near the wall and between overlapping blobs), which no setting of
  either product removes and which the report states separately;
* the cost of one product of the whole scene with each, measured here (times the GMRES iterations of the scene
  for rigid bodies, one product per step for rollers).

Each product is applied to seeded random blob forces and, apart, to a uniform force along and towards the wall
(sedimentation: its periodic mean flow is what the first ring of images truncates most); for rollers also to
random torques and to a uniform torque about y (the rollers' drive).  The error of a candidate is the largest of
``|U - U_ref| / |U_ref|`` over the sampled targets among its responses: velocities (and, for rollers, angular
velocities) of each of these loads.  The cheapest candidate
that meets the target accuracy is recommended; where none does, the input is kept and the note names the most
accurate one.
"""
import warnings

import numpy as np

from mobility import choose
from mobility.image_sums import periodic_limit, relative_error, ring_sums, tiled_velocities
from mobility.interface import Geometry, implementation_geometry, make_mobility
from mobility.spectral.parameters import refined_parameters
from mobility.spectral_mobility import SpectralMobility, spectral_parameters_for
from multi_bodies.files.scheme_table import moves_rollers
from multi_bodies.solver import body_solver
from multi_bodies.solver.periodic import (PUBLISHED_ZMAX, SPECTRAL_OPTIONS, SpectralDomain, check_grid_periods,
                                          spectral_geometry_kind)
from multi_bodies.solver.published_spectral import reading_kind
from utils import UserInputError

SPECTRAL = 'spectral'
FORCE_KERNELS = ('w6', 'w5', 'w4')
ROLLER_KERNELS = ('w6', 'w5', 'w6w5', 'w6w4', 'w5w4')
GEOMETRY_TARGETS = 32             # sampled target blobs of the periodic reference (fewer when the scene is large)
REFERENCE_BUDGET_S = 20.0         # seconds the direct periodic reference may take (--quick: a fifth)
GRID_POINTS_LIMIT = 4e7           # spectral grids above this many points (about 1 GB) are not built here
QUICK_REFERENCE_POINTS = 1e7      # --quick: the converged spectral product only on grids up to this size
# seconds per pair evaluation, to size the reference: a compiled source-target product, NumPy ring sums (per
# coupling); measured on the development machine, only used to choose the number of rings and targets
SECONDS_PER_PAIR = {'compiled': 2e-8, 'numpy': 4e-7}
RELATIVE_Z_HEADROOM = 1.5         # spectral_z_bounds proposed as 1.5 times the highest blob when it is needed


def spectral_kernel_label(kernel, rollers):
    return 'spectral %s%s' % (kernel, ' (monopole/dipole pair)' if rollers and len(kernel) > 2 else '')


class GeometryMeasurements:
    """The geometry topic of ``advisor.Advisor`` (see the module docstring)."""

    def measure_geometry(self):
        scene = self.scene
        options = scene.options
        vector_option = 'mobility_vector_prod_implementation'
        current_spectral = options.mobility_vector_prod_implementation == SPECTRAL
        reason = self._geometry_not_applicable()
        if reason is not None:
            self.add('geometry', None, 'not measured', scene.num_blobs, None, None, True, reason)
            if current_spectral and self.recommendation.get(vector_option, SPECTRAL) != SPECTRAL:
                # the backend and wall topics compare direct sums: they cannot replace a periodic product
                self.recommendation.pop(vector_option)
            return
        rollers = moves_rollers(options.scheme)
        r = scene.r_vectors
        n = scene.num_blobs
        Lx, Ly, _ = options.periodic_length
        rng = np.random.default_rng(5)
        forces = rng.standard_normal((n, 3))
        cases = [(forces, None), (np.tile([0.5, 0.0, -1.0], (n, 1)), None)]   # each load measured apart
        torques = None
        if rollers:
            torques = rng.standard_normal((n, 3))
            cases += [(None, torques), (None, np.tile([0.0, 1.0, 0.0], (n, 1)))]
        targets, limit, how = self._geometry_reference(r, cases, rollers)
        self.geometry_reference = how
        rows = []   # (label, error, cost seconds, note, recommendation lines)

        # ---------------------------------------------------------- the pseudo-periodic direct sum
        direct_name = self.recommendation.get(vector_option, options.mobility_vector_prod_implementation)
        if direct_name.startswith(SPECTRAL) or direct_name.startswith('auto') or direct_name.endswith('_no_wall'):
            direct_name = self.backend      # the fastest CPU backend (auto measures the same at run time)
        direct_backend = implementation_geometry(direct_name)[0]
        direct = make_mobility(direct_backend, Geometry('single_wall', (Lx, Ly, 0.0)), scene.eta, scene.a)
        seconds = choose.time_call(self._one_product(direct, r, forces, torques), repeats=2)
        error = self._geometry_error(self._responses(direct, r, cases), targets, limit)
        rows.append(('pseudo-periodic direct sum, first ring of images (%s)' % direct_backend, error, seconds,
                     'against the periodic limit of the direct sum (%s)' % how, {vector_option: direct_name},
                     not current_spectral))

        # ---------------------------------------------------------- the spectral product, each kernel
        kind = 'doubly_periodic_wall'
        if current_spectral and options.spectral_z_bounds is not None:
            z_bounds, z_line = tuple(options.spectral_z_bounds), None
        else:
            top = float(np.max(r[:, 2]))
            if top <= PUBLISHED_ZMAX / RELATIVE_Z_HEADROOM:
                z_bounds, z_line = (0.0, PUBLISHED_ZMAX), None
            else:
                zmax = float(np.ceil(RELATIVE_Z_HEADROOM * top))
                z_bounds, z_line = (0.0, zmax), '0 %g' % zmax
        geometry = Geometry(kind, (Lx, Ly, 0.0), z_bounds)
        current_kernel = options.spectral_kernel if current_spectral else None
        converged, converged_note = self._converged_spectral(geometry, r, cases, rollers, targets)
        model_difference = None if converged is None else self._geometry_error(converged, targets, limit)
        for kernel in (ROLLER_KERNELS if rollers else FORCE_KERNELS):
            label = spectral_kernel_label(kernel, rollers)
            # the manual's reading of blob_radius, which the advisor measured (an input naming the spectral product
            # and no other spectral_* line would otherwise be read as the published folder reads it)
            lines = {vector_option: SPECTRAL, 'spectral_reading': 'package'}
            if kernel != 'w6':
                lines['spectral_kernel'] = kernel
            if z_line is not None:
                lines['spectral_z_bounds'] = z_line
            domain = SpectralDomain(geometry, kernel)
            try:
                check_grid_periods(domain, options, rollers, scene.a)
                p = self._spectral_parameters(geometry, kernel, rollers)
            except UserInputError as err:
                rows.append((label, None, None, 'not usable with this box: %s' % str(err).split(': ', 1)[-1],
                             lines, current_spectral and kernel == current_kernel))
                continue
            points = p.Nx * p.Ny * p.Nz
            if points > GRID_POINTS_LIMIT:
                rows.append((label, None, None, 'not measured: a grid of %d x %d x %d points (%.3g GB)'
                             % (p.Nx, p.Ny, p.Nz, 24 * points / 1e9), lines,
                             current_spectral and kernel == current_kernel))
                continue
            mobility = domain.mobility(scene.eta, scene.a, rotation=rollers)
            seconds = choose.time_call(self._one_product(mobility, r, forces, torques), repeats=2)
            responses = self._responses(mobility, r, cases)
            if converged is not None:
                error = self._geometry_error(responses, targets, converged)
                note = 'grid %d x %d x %d; against the converged spectral product (%s); blob model %s from the ' \
                       'direct sum\'s periodic limit' % (p.Nx, p.Ny, p.Nz, converged_note, _percent(model_difference))
            else:   # the direct sum's periodic limit: the kernel's error and the difference of the blob models
                error = self._geometry_error(responses, targets, limit)
                note = 'grid %d x %d x %d; against the periodic limit of the direct sum, blob model difference ' \
                       'included (the converged spectral product: %s)' % (p.Nx, p.Ny, p.Nz, converged_note)
            rows.append((label, error, seconds, note, lines, current_spectral and kernel == current_kernel))

        # ---------------------------------------------------------- rows and the choice
        for label, error, seconds, note, _, current in rows:
            cost = None if seconds is None else (seconds if rollers else self.cost_per_step(seconds))
            self.add('geometry', None, label + (' (current)' if current else ''), n, error, cost,
                     error is not None and error <= self.accuracy, note)
        if model_difference is not None:
            self.notes.append(
                'geometry: the converged spectral product and the periodic limit of the direct sum differ by %s on '
                'this scene: the blob of the spectral kernel is not the Rotne-Prager-Blake blob (they differ most '
                'near the wall and between overlapping blobs); neither product setting removes it, and neither blob '
                'is the exact body (see the resolution topic). The geometry errors above leave it out'
                % _percent(model_difference))
        self.geometry_model_difference = model_difference
        meeting = [row for row in rows if row[1] is not None and row[1] <= self.accuracy and row[2] is not None]
        current_row = next((row for row in rows if row[5]), None)
        if not meeting:
            known = [row for row in rows if row[1] is not None]
            best = min(known, key=lambda row: row[1]) if known else None
            self.notes.append('geometry: no periodic product meets %s here%s; the input\'s is kept'
                              % (_percent(self.accuracy), '' if best is None else
                                 ' (the most accurate: %s, %s)' % (best[0], _percent(best[1]))))
            chosen = current_row
        else:
            chosen = min(meeting, key=lambda row: row[2])
        self.geometry_choice = None if chosen is None else chosen[0]
        for key in ('spectral_kernel', 'spectral_z_bounds', 'spectral_reading'):
            self.recommendation.pop(key, None)
        if chosen is None:
            return
        lines = dict(chosen[4])
        if lines.get(vector_option) == SPECTRAL:
            if current_spectral:   # read as the manual says already (else not measured), and its spectral_* lines stay
                lines.pop(vector_option)
                lines.pop('spectral_reading')
                if lines.get('spectral_kernel', 'w6') == options.spectral_kernel:
                    lines.pop('spectral_kernel', None)
                elif 'spectral_kernel' not in lines:
                    lines['spectral_kernel'] = 'w6'
                self.recommendation.pop(vector_option, None)
            self.recommendation.update(lines)
            if chosen is not current_row:
                self.notes.append('geometry: %s: error %s against %s for the pseudo-periodic sum, at %s per product '
                                  'here' % (chosen[0], _percent(chosen[1]), _percent(rows[0][1]),
                                            _seconds(chosen[2])))
        elif current_spectral:
            # a direct input may not keep the spectral_* lines, which a recommendation cannot remove: said, not set
            self.recommendation.pop(vector_option, None)
            given = [name for name in SPECTRAL_OPTIONS if options.is_set(name)]
            self.notes.append('geometry: the pseudo-periodic direct sum meets %s here (%s) and is the cheapest: the '
                              'spectral product is not needed; to use it, set mobility_vector_prod_implementation %s '
                              'and remove the line%s %s' % (_percent(self.accuracy), _percent(chosen[1]),
                                                            lines[vector_option], 's' if len(given) > 1 else '',
                                                            ', '.join(given)))

    def geometry_allowance(self):
        """How much a recommended change of the periodic product may change the velocities of the check: the
        current product's geometry error plus the difference of the blob models (0 when not measured)."""
        current = [c.estimated_error for c in self.choices if c.topic == 'geometry'
                   and c.candidate.endswith('(current)') and c.estimated_error is not None]
        return max(current, default=0.0) + (getattr(self, 'geometry_model_difference', None) or 0.0)

    # -------------------------------------------------------------- helpers
    def _geometry_not_applicable(self):
        """None when the topic applies, else why not (a line for the table)."""
        scene = self.scene
        options = scene.options
        if self.program == 'mcmc':
            return 'a Monte Carlo input has no hydrodynamics'
        Lx, Ly, Lz = options.periodic_length
        spectral = options.mobility_vector_prod_implementation == SPECTRAL
        if spectral and reading_kind(options) == 'published':
            return ('the input is read in the published form of a spectral input (blob_radius the particle radius, '
                    'doc/periodic.md); the advisor reads the scene as the manual does: add spectral_reading package '
                    'to the input (and the blob radius it means) to measure it')
        if spectral and spectral_geometry_kind(options) != 'doubly_periodic_wall':
            return ('spectral_geometry %s has no direct sum to compare with (the pseudo-periodic sums exist over a '
                    'single wall and in free space): the spectral product is the only product of this geometry'
                    % spectral_geometry_kind(options))
        if not (Lx > 0 and Ly > 0):
            return 'no box periodic in x and y (periodic_length %s): nothing to choose' % ' '.join(
                '%g' % v for v in options.periodic_length)
        if Lz > 0 or not scene.wall:
            return ('a pseudo-periodic box without a wall (free space%s): the Stokeslet decays like 1/r and its image '
                    'sums diverge, so they have no periodic limit to measure against' %
                    (', periodic in z' if Lz > 0 else ''))
        if np.ndim(body_solver.blob_radius_argument(scene.arrays, scene.a)):
            return 'blobs of different radii: the spectral kernel has one width'
        if options.scheme in ('body_mobility', 'resistance'):
            return 'scheme %s builds dense blocks and uses no blob vector product' % options.scheme
        return None

    @staticmethod
    def _one_product(mobility, r, forces, torques):
        """The product a step makes (rollers: forces and torques together), for timing."""
        if torques is None:
            return lambda: mobility.velocities(r, forces.ravel())
        return lambda: mobility.product(r, forces.ravel(), torques.ravel())

    @staticmethod
    def _responses(mobility, r, cases):
        """[(U (N, 3), W (N, 3) or None)] of ``mobility`` to each (forces, torques) of ``cases``."""
        out = []
        for F, T in cases:
            if T is None and not mobility.has_rotation:
                out.append((mobility.velocities(r, F.ravel()), None))
            else:
                U, W = mobility.product(r, None if F is None else F.ravel(), None if T is None else T.ravel())
                out.append((U, W))
        return out

    def _geometry_reference(self, r, cases, rollers):
        """(target indices (T,), [(U (T, 3), W or None)] the direct sum's periodic limit for each case of forces
        and torques, a description)."""
        n = r.shape[0]
        budget = REFERENCE_BUDGET_S / (5.0 if self.quick else 1.0)
        compiled = not rollers and self.backend != 'python'
        per_pair = SECONDS_PER_PAIR['compiled' if compiled else 'numpy'] * (4 if rollers else 1)
        for rings in (32, 16, 8):
            count = min(n, GEOMETRY_TARGETS)
            while count > 8 and count * n * (2 * rings + 1) ** 2 * per_pair > budget:
                count //= 2
            if count * n * (2 * rings + 1) ** 2 * per_pair <= budget or rings == 8:
                break
        targets = np.unique(np.linspace(0, n - 1, count).round().astype(int))
        counts = [rings // 4, rings // 2, rings]
        L = self.scene.options.periodic_length
        limits, estimate = [], 0.0
        for forces, torques in cases:
            if compiled:
                mobility = make_mobility(self.backend, Geometry('single_wall'), self.scene.eta, self.scene.a)
                sums = tiled_velocities(mobility, r, forces, L, counts, targets)
            else:
                sums = ring_sums(r, self.scene.eta, self.scene.a, L, counts, forces, torques, targets,
                                 rotation=rollers)
            U, W, case_estimate = periodic_limit(sums)
            limits.append((U, W))
            estimate = max(estimate, case_estimate)
        how = ('%d target blobs, image sums over %d, %d and %d rings extrapolated in 1/n, estimated within %s'
               % (targets.size, counts[0], counts[1], counts[2], _percent(estimate)))
        return targets, limits, how

    @staticmethod
    def _geometry_error(responses, targets, reference):
        """The largest relative error of the responses [(U, W)] (of every blob, or of the targets only) against the
        reference [(U, W)] at the targets."""
        error = 0.0
        for values, expected in zip(responses, reference):
            for value, wanted in zip(values, expected):
                if value is None or wanted is None:
                    continue
                value = np.asarray(value).reshape(-1, 3)
                value = value[targets] if value.shape[0] != wanted.shape[0] else value
                error = max(error, relative_error(value, wanted))
        return error

    def _spectral_parameters(self, geometry, kernel, rollers):
        with warnings.catch_warnings():
            warnings.simplefilter('ignore')
            return spectral_parameters_for(geometry, self.scene.a, kernel if rollers else kernel[:2], rotation=rollers)

    def _converged_spectral(self, geometry, r, cases, rollers, targets):
        """([(U, W)] at the targets for each case, of the finest kernel on a grid twice as fine, or None; a
        description)."""
        scene = self.scene
        try:
            base = self._spectral_parameters(geometry, 'w6', rollers)
        except UserInputError as err:
            return None, 'not made: %s' % err
        results = {}
        limit = QUICK_REFERENCE_POINTS if self.quick else GRID_POINTS_LIMIT
        for factor in ((2,) if self.quick else (2, 3)):
            p = refined_parameters(base, factor)
            if p.Nx * p.Ny * p.Nz > limit:
                break
            mobility = SpectralMobility(geometry, scene.eta, scene.a, parameters=p, near_wall='published')
            results[factor] = [(np.asarray(U).reshape(-1, 3)[targets],
                                None if W is None else np.asarray(W).reshape(-1, 3)[targets])
                               for U, W in self._responses(mobility, r, cases)]
        if 2 not in results:
            return None, 'not made: the grid twice as fine would exceed %.3g points%s' % (
                limit, ' with --quick' if self.quick else '')
        if 3 in results:
            change = self._geometry_error(results[3], np.arange(targets.size), results[2])
            return results[2], 'w6 on a grid twice as fine; %s from three times as fine' % _percent(change)
        return results[2], 'w6 on a grid twice as fine'


def _percent(value):
    return '-' if value is None else '%.3g%%' % (100.0 * value)


def _seconds(value):
    if value is None:
        return '-'
    return '%.3g ms' % (1e3 * value) if value < 1.0 else '%.3g s' % value
