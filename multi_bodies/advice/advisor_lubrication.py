"""The advisor's ``lubrication`` topic: 1 blob with lubrication against resolved multiblob spheres.

A mixin of :class:`multi_bodies.advice.advisor.Advisor` (floor 7).  On a scene whose bodies are all
spheres of one radius R (a lubrication input, a roller input or a multiblob-sphere input), the
smallest surface gap between two spheres and between a sphere and the wall decide the error of each
model (``lubrication_tables.model_error``: the errors of the chart of ``doc/lubrication_accuracy.md``,
one source), the cost of one mobility solve is measured (or modelled) on this scene, and the
cheapest model meeting ``--accuracy`` that the input can run is recommended with the input lines to
change (scheme, options, vertex file).  The lubrication schemes take single-blob spheres only and
the multiblob schemes refuse the lubrication options, so a change of model comes with its scheme.
"""
import time

import numpy as np

from multi_bodies.advice import lubrication_tables as tables
from multi_bodies.advice.lubrication_models import TABLE_MODEL
from multi_bodies.files.input_options import DEFAULTS
from multi_bodies.files.scheme_table import moves_rollers, scheme_names

LUBRICATION_SCHEMES = scheme_names(lubrication=True)  # the scheme registry's
LUBRICATION_OPTIONS = ('Lub_Cut', 'firm_delta', 'repulsion_strength_firm')
MEASURE_SPHERES = 2000       # above this many spheres the lubricated solve is modelled, not measured
MEASURE_FROM = 64            # below this many spheres every cost is modelled from the chart (overheads)


def sphere_gaps(centres, radius, wall):
    """(smallest sphere-sphere surface gap / R or None, smallest wall gap / R or None) of centres (n, 3)."""
    centres = np.asarray(centres, dtype=float).reshape(-1, 3)
    pair_gap = None
    if len(centres) > 1:
        from scipy.spatial import cKDTree
        distance, _ = cKDTree(centres).query(centres, k=2)
        pair_gap = float(np.min(distance[:, 1])) / radius - 2.0
    wall_gap = float(np.min(centres[:, 2])) / radius - 1.0 if wall else None
    return pair_gap, wall_gap


def model_kind(scheme):
    """'lubrication', 'rollers' or 'multiblob': what the input's scheme runs."""
    if scheme in LUBRICATION_SCHEMES:
        return 'lubrication'
    return 'rollers' if moves_rollers(scheme) else 'multiblob'


def scheme_for(model, scheme, kT, free_kinematics=DEFAULTS.free_kinematics):
    """(scheme that runs ``model`` for an input of ``scheme``, or None with the reason it is refused)."""
    kind = model_kind(scheme)
    stochastic = kT > 0
    driven = (kind == 'lubrication' and scheme == 'lubrication_trapezoidal_rollers') or (
        kind == 'rollers' and not free_kinematics)
    if model == '1 blob + lubrication':
        if kind == 'lubrication':
            return scheme, None
        return ('lubrication_trapezoidal_rollers' if kind == 'rollers' else 'lubrication_trapezoidal'), None
    if model == '1 blob':
        if kind == 'rollers':
            return scheme, None
        if kind == 'lubrication':
            if scheme == 'lubrication_EM':
                return ('stochastic_first_order_rollers' if stochastic else 'deterministic_forward_euler_rollers'), None
            return ('stochastic_trapezoidal_rollers' if stochastic else 'deterministic_adams_bashforth_rollers'), None
        from multi_bodies.advice.advisor_models import ROLLER_SCHEMES
        return ROLLER_SCHEMES.get(scheme, 'stochastic_adams_bashforth_rollers' if stochastic
                                  else 'deterministic_adams_bashforth_rollers'), None
    # resolved shells
    if driven:
        return None, 'refused: the multiblob schemes do not drive spheres at a prescribed spin (omega_one_roller)'
    if kind == 'multiblob':
        return scheme, None
    return ('stochastic_Slip_Trapz' if stochastic else 'deterministic_adams_bashforth'), None


class LubricationMeasurements:
    """The ``lubrication`` topic of the advisor (mixin; see the module docstring)."""

    def sphere_scene(self):
        """(radius R, centres (n, 3), blobs per sphere) when every body is a sphere of one radius, else None."""
        structures = self.scene.structures
        spheres = [s['sphere'] for s in structures]
        if not structures or any(s is None for s in spheres):
            return None
        radii = np.array([s['radius'] for s in spheres])
        if np.ptp(radii) > 1e-6 * radii[0]:
            return None
        blobs = {s['num_blobs'] for s in structures}
        return float(radii[0]), np.concatenate([s['centres'] for s in structures]), min(blobs)

    def lubrication_cost(self, model, centres, radius):
        """(seconds of one mobility solve of the scene's spheres with ``model``, how it was found).

        Shells, and every model on fewer than ``MEASURE_FROM`` spheres (where fixed overheads would
        decide): modelled from the chart's 64-sphere solve (``lubrication_tables.modelled_solve_seconds``).
        Otherwise 1 blob (one ``M f``) and 1 blob + lubrication (``Delta_R`` assembled and one solve) are
        measured on the scene, the latter modelled from its ``M f`` above ``MEASURE_SPHERES``.
        """
        scene = self.scene
        n = len(centres)
        if model.startswith('shell') or n < MEASURE_FROM:
            return tables.modelled_solve_seconds(model, n), 'modelled from the chart'
        if model == '1 blob':
            return self.product_time(centres, scene.wall)
        far_seconds, _ = self.product_time(centres, scene.wall)
        if n > MEASURE_SPHERES:
            product, solve_seconds, _, _ = tables.COSTS[model]
            return far_seconds * solve_seconds / product, 'modelled: M f x the ratio of the chart'
        from lubrication import LubricationProblem
        from multi_bodies.solver.solves import Solver
        force = np.zeros((n, 6))
        force[:, 2] = -1.0
        tolerance = scene.options.solver_tolerance
        start = time.perf_counter()
        problem = LubricationProblem(centres, radius, scene.eta, wall=scene.wall, implementation=self.backend,
                                     periodic_length=scene.options.periodic_length)
        Solver(tolerance, not_converged='flag').solve(problem, problem.rhs(force), problem.preconditioner(tolerance),
                                                      kind='lubrication')  # a timing: a stop at the limit counts
        return time.perf_counter() - start, 'measured'

    def measure_lubrication(self):
        """Rows of the ``lubrication`` topic and, when a cheaper adequate model runs, the input lines to change."""
        self.lubrication_lines = []
        if self.program != 'dynamic':
            return  # the lubrication schemes are dynamic schemes: static problems and Monte Carlo have none
        sphere = self.sphere_scene()
        scheme = self.scene.options.scheme
        kind = model_kind(scheme)
        if sphere is None:
            if kind == 'lubrication':
                self.notes.append('lubrication: the bodies are not all spheres of one radius; models not compared')
            return
        radius, centres, blobs_now = sphere
        pair_gap, wall_gap = sphere_gaps(centres, radius, self.scene.wall)
        current = ('1 blob + lubrication' if kind == 'lubrication' else '1 blob' if blobs_now == 1
                   else 'shell %d' % blobs_now)
        options = self.scene.options
        kT, free = float(options.kT), bool(options.free_kinematics)
        candidates = []
        for model in tables.ADVISED_MODELS:
            error, note = tables.model_error(model, pair_gap, wall_gap)
            target_scheme, refused = scheme_for(model, scheme, kT, free)
            if model == TABLE_MODEL:
                cost = tables.modelled_solve_seconds('shell 642', len(centres)) * (2562 / 642) ** 2
                how = 'modelled as the 642-blob solve x (2562/642)^2; %s' % tables.RESOLVED_NOTE
                refused = 'not offered: the package calibrates shells up to 642 blobs'
            else:
                cost, how = self.lubrication_cost(model, centres, radius)
            applicable = refused is None and model != TABLE_MODEL
            meets = error is not None and error <= self.accuracy and applicable
            label = model + (' (current)' if model == current else '')
            text = '; '.join(x for x in (note, 'cost %s' % how, refused or 'scheme %s' % target_scheme) if x)
            self.add('lubrication', None, label, tables.model_blobs(model), error, cost, meets, text)
            if meets:
                candidates.append((cost, model, target_scheme))
        self.sources.append('lubrication: errors of the chart of doc/lubrication_accuracy.md (two spheres in free '
                            'space, one sphere above the wall, against the exact answers) at the smallest pair gap '
                            '%s and wall gap %s (units of R); costs modelled from the chart: %s'
                            % (_gap(pair_gap), _gap(wall_gap), tables.COST_SCALING))
        if not candidates:
            self.notes.append('lubrication: no model that this input can run meets %g%% at pair gap %s, wall gap %s; '
                              'the current model is kept' % (100 * self.accuracy, _gap(pair_gap), _gap(wall_gap)))
            return
        cost, model, target_scheme = min(candidates)
        if kind == 'lubrication':
            self.supersede_model_lines('the lubrication schemes take single-blob spheres only')
        if kind != 'lubrication' and model != '1 blob + lubrication':
            # 1 blob or a shell for a multiblob or roller input: the resolution and rollers topics recommend
            # these models with their per-blob rescaling and check; their lines apply
            self.notes.append('lubrication: %s is the cheapest model meeting %g%% at pair gap %s, wall gap %s (no '
                              'lubrication needed)' % (model, 100 * self.accuracy, _gap(pair_gap), _gap(wall_gap)))
            return
        if model == current:
            return
        if kind != 'lubrication':
            other = self.recommended_sphere_model()
            other_error = tables.model_error(other, pair_gap, wall_gap)[0] if other in tables.ERRORS['pair'] else None
            if other is None or (other_error is not None and other_error > self.accuracy):
                self.supersede_model_lines('by the chart %s misses %g%% at these gaps (%s)' % (
                    other or 'the current model', 100 * self.accuracy, _percent(other_error)))
            else:
                self.lubrication_alternative = True
        self.lubrication_lines = self.lubrication_change(model, target_scheme, radius, blobs_now)
        self.notes.append('lubrication: %s meets %g%% at the cheapest cost (%s); input lines below' % (
            model, 100 * self.accuracy, '-' if cost is None else '%.3g s a solve' % cost))

    def recommended_sphere_model(self):
        """The sphere model ('1 blob', 'shell N') the resolution or rollers topic recommends, or None."""
        for key, value in self.recommendation.items():
            if key.startswith('structure:') and value.split()[0] in self.files:
                n = len(self.files[value.split()[0]][0])
                return '1 blob' if n == 1 else 'shell %d' % n
        return None

    def supersede_model_lines(self, reason):
        """Drop the resolution and rollers topics' model lines (``reason`` says why, in the note)."""
        from multi_bodies.advice.advisor_physics import is_model_key
        dropped = [key for key in self.recommendation if is_model_key(key) or (
            key == 'scheme' and moves_rollers(self.recommendation[key]) != moves_rollers(self.scene.options.scheme))]
        for key in dropped:
            self.recommendation.pop(key)
        if dropped:
            self.notes.append('lubrication: the lines of the resolution and rollers topics (%s) are dropped: %s'
                              % (', '.join(key.split(':')[0] for key in dropped), reason))

    def set_lubrication_options(self):
        """The lubrication options (``LUBRICATION_OPTIONS``) the input sets."""
        options = self.scene.options
        return [name for name in LUBRICATION_OPTIONS if options.is_set(name)]

    def lubrication_change(self, model, target_scheme, radius, blobs_now):
        """Input lines (strings) that switch the input to ``model`` with ``target_scheme``."""
        options = self.scene.options
        lines = []
        if target_scheme != options.scheme:
            lines.append('%-40s %s' % ('scheme', target_scheme))
        blobs = tables.model_blobs(model)
        if model_kind(target_scheme) == 'multiblob':
            for name in self.set_lubrication_options():
                lines.append('remove the line %s (the multiblob schemes refuse it)' % name)
            shell, blob_radius = tables.shell_blobs(blobs, radius)
            for structure in self.scene.structures:
                vertex = '%s.advice.%s.shell_%d.vertex' % (options.output_name, structure['ID'], blobs)
                self.files[vertex] = (shell, 'calibrated shell of %d blobs, radius %g (advisor, lubrication)'
                                      % (blobs, radius))
                self.lubrication_files = getattr(self, 'lubrication_files', []) + [vertex]
                lines.append('%-40s %s %s' % ('structure', vertex, structure['spec'].clones_file))
            lines.append('%-40s %.12g' % ('blob_radius', blob_radius))
        else:
            if model == '1 blob' and model_kind(options.scheme) == 'lubrication':
                lines += ['remove the line %s (the roller schemes do not use it)' % name
                          for name in self.set_lubrication_options()]
            if model == '1 blob' and model_kind(options.scheme) == 'lubrication' \
                    and options.scheme != 'lubrication_trapezoidal_rollers':
                lines.append('%-40s %s' % ('free_kinematics', 'True'))
            if model == '1 blob + lubrication':
                lines.append('%-40s %s' % ('Lub_Cut', '4.5'))
                lines.append('%-40s %s' % ('firm_delta', '1e-4'))
            if blobs_now != 1:
                vertex = '%s.advice.single_blob.vertex' % options.output_name
                self.files[vertex] = (np.zeros((1, 3)), 'one blob (advisor, lubrication)')
                self.lubrication_files = getattr(self, 'lubrication_files', []) + [vertex]
                for structure in self.scene.structures:
                    lines.append('%-40s %s %s' % ('structure', vertex, structure['spec'].clones_file))
                lines.append('%-40s %.12g' % ('blob_radius', radius))
        g = float(options.g)
        if g and blobs != blobs_now:
            lines.append('%-40s %.12g   # g is per blob: %d -> %d blobs a sphere; the wall and pair repulsions '
                         'act per blob too: re-tune them for the new model' % ('g', g * blobs_now / blobs, blobs_now,
                                                                               blobs))
        return lines


def apply_lubrication_lines(text, lines):
    """Input text with the lubrication topic's ``lines`` applied.

    ``name value`` lines replace the option's line (or are appended); ``structure`` lines replace the
    structure lines in order; ``remove the line NAME ...`` deletes the option's line.
    """
    removed = {line.split()[3] for line in lines if line.startswith('remove the line ')}
    options = [line.split('#', 1)[0].split(None, 1) for line in lines if not line.startswith('remove the line ')]
    structures = [' '.join(words) for words in options if words[0] == 'structure']
    values = {words[0]: words[1].strip() for words in options if words[0] != 'structure'}
    out, done, structure_index = [], set(), 0
    for raw in text.splitlines():
        words = raw.split('#', 1)[0].split()
        name = words[0] if words else None
        if name in removed:
            continue
        if name == 'structure' and structure_index < len(structures):
            raw = structures[structure_index]
            structure_index += 1
        elif name in values:
            raw = '%s %s' % (name, values[name])
            done.add(name)
        out.append(raw)
    out += ['%s %s' % (name, value) for name, value in values.items() if name not in done]
    return '\n'.join(out) + '\n'


def _percent(value):
    return '-' if value is None else '%.3g%%' % (100 * value)


def _gap(value):
    return '-' if value is None else '%.3g' % value
