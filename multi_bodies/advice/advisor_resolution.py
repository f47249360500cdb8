"""The advisor's resolution measurements: how many blobs a body needs (floor 7).

A mixin of :class:`multi_bodies.advice.advisor.Advisor`: for each structure
type recognised as a sphere, the error and cost of the roller model and of
the 12- to 642-blob shells at the scene's smallest gaps (against the exact
sphere-wall mobility, or a Richardson extrapolation); for other bodies the
blob spacing against the blob radius, and on request a coarsened model.
The methods use the Advisor's scene, backend, accuracy and ``add``.
"""
import numpy as np

from multi_bodies.advice import sphere_tables
from body.geometry import smallest_distance
from multi_bodies.advice.advisor_report import _percent
from multi_bodies.advice.advisor_models import (DENSE_BLOB_LIMIT, RICHARDSON_LEVELS, SHELL_SIZES, bodies_mobility,
                                                bulk_radius, calibrated_model, exact_diagonal, fixed_radius_model,
                                                normalised_diagonal, richardson, worst_error)


class ResolutionMeasurements:
    """The ``resolution`` topic of the advisor (mixin; see the module docstring)."""

    # -------------------------------------------------------------- resolution
    def sphere_models(self, structure):
        """Candidate models of a sphere structure.

        List of (label, blobs (n, 3) about 0, blob radius, applicable): the
        1-blob roller model, the calibrated shells (blob radius scaled with
        R; applicable when this is the only structure type, since
        ``blob_radius`` is one value for every structure) and, with several
        structure types, shells that keep the scene's blob radius.
        """
        R = structure['sphere']['radius']
        single_type = len(self.scene.structures) == 1
        models = [('1 blob (roller model)', np.zeros((1, 3)), R, False)]
        for n in SHELL_SIZES:
            blobs, a = calibrated_model(n, R)
            models.append(('shell %d' % n, blobs, a, single_type))
        if not single_type:
            for n in SHELL_SIZES:
                model = fixed_radius_model(n, R, self.scene.a)
                if model is not None:
                    models.append(('shell %d (a = %.4g)' % (n, self.scene.a), model[0], model[1], True))
        return models

    def model_errors(self, structure, models):
        """Per model: (wall-gap diagonal (6,), pair diagonal (6,) or None), normalised by the sphere's bulk values."""
        scene = self.scene
        R = structure['sphere']['radius']
        centre = structure['centres'][structure['lowest']]
        pair = structure['nearest_pair']
        results = []
        for label, blobs, a, _ in models:
            wall_diag = normalised_diagonal(bodies_mobility([blobs + centre], [centre], a, scene.eta, scene.wall,
                                                            self.backend), R, scene.eta)
            pair_diag = None
            if pair is not None and not self.quick:
                c0, c1 = structure['centres'][pair[0]], structure['centres'][pair[1]]
                pair_diag = normalised_diagonal(bodies_mobility([blobs + c0, blobs + c1], [c0, c1], a, scene.eta,
                                                                scene.wall, self.backend), R, scene.eta)
            results.append((wall_diag, pair_diag))
        return results

    def current_model_diagonals(self, structure):
        scene = self.scene
        R = structure['sphere']['radius']
        r_type, centres = structure['r_type'], structure['centres']
        low = structure['lowest']
        n = structure['num_blobs']
        if n > DENSE_BLOB_LIMIT:
            self.notes.append('%s: %d blobs per body is too many for a dense body mobility here; the current model '
                              'is not measured' % (structure['ID'], n))
            return None, None
        wall_diag = normalised_diagonal(bodies_mobility([r_type[low]], [centres[low]], scene.a, scene.eta, scene.wall,
                                                        self.backend), R, scene.eta)
        pair_diag = None
        if structure['nearest_pair'] is not None and not self.quick and 2 * n <= DENSE_BLOB_LIMIT:
            i, j = structure['nearest_pair']
            pair_diag = normalised_diagonal(bodies_mobility([r_type[i], r_type[j]], [centres[i], centres[j]], scene.a,
                                                            scene.eta, scene.wall, self.backend), R, scene.eta)
        return wall_diag, pair_diag

    def measure_resolution(self):
        self.resolution_details = {}
        for structure in self.scene.structures:
            if structure['sphere'] is None:
                self.measure_other_body(structure)
            else:
                self.measure_sphere(structure)

    def measure_sphere(self, structure):
        scene = self.scene
        sid, R = structure['ID'], structure['sphere']['radius']
        h = structure['centres'][structure['lowest']][2] / R
        models = self.sphere_models(structure)
        labels = [m[0] for m in models]
        diagonals = self.model_errors(structure, models)
        current_wall, current_pair = self.current_model_diagonals(structure)
        exact = exact_diagonal(h) if scene.wall else np.ones(6)  # free space: the bulk values are exact
        # Richardson reference: the calibrated shells converge to the sphere.
        levels = [diagonals[labels.index('shell %d' % n)] for n in RICHARDSON_LEVELS]
        wall_reference = richardson([d[0] for d in levels])
        pair_reference = None
        if structure['nearest_pair'] is not None and not self.quick:
            pair_reference = richardson([d[1] for d in levels])
        reference = exact if exact is not None else wall_reference
        finest_spacing = smallest_distance(models[labels.index('shell %d' % RICHARDSON_LEVELS[-1])][1])
        gaps = [('wall gap', (h - 1.0) * R)]
        if structure['nearest_gap'] is not None:
            gaps.append(('pair gap', structure['nearest_gap'] - 2.0 * R))
        for what, gap in gaps:
            if gap < finest_spacing:
                self.notes.append('%s: the %s (%.3g) is smaller than the blob spacing of the finest shell (%.3g): '
                                  'convergence slows there and the Richardson estimates are lower bounds (at h/R = '
                                  '1.1 they are up to 2.3 times too small, doc/advisor.md)'
                                  % (sid, what, gap, finest_spacing))
        source = 'exact sphere-wall table' if exact is not None else 'Richardson extrapolation of shells 42-162-642'
        self.sources.append('%s: wall-gap errors against the %s (h/R = %.4g)' % (sid, source, h))
        if pair_reference is not None:
            self.sources.append('%s: pair errors against the Richardson extrapolation of shells 42-162-642 '
                                '(centre distance %.4g R)' % (sid, structure['nearest_gap'] / R))
        elif structure['nearest_pair'] is not None:
            self.sources.append('%s: pair errors not measured (--quick)' % sid)
        current_label = 'current (%d blobs, a = %.4g)' % (structure['num_blobs'], scene.a)
        rows = [(current_label, structure['num_blobs'], current_wall, current_pair, None)]
        rows += [(label, len(blobs), d[0], d[1], (label, blobs, a, applicable))
                 for (label, blobs, a, applicable), d in zip(models, diagonals)]
        details, candidates = [], []
        for label, n, wall_diag, pair_diag, model in rows:
            wall_error = worst_error(wall_diag, reference) if (reference is not None and
                                                                wall_diag is not None) else None
            calibrated = model is not None and n > 1 and '(' not in label
            from_table = False
            if self.quick and calibrated and scene.wall:
                shipped = sphere_tables.shipped_shell_errors(n, h)
                if shipped is not None:
                    wall_error, from_table = float(np.max(np.abs(shipped))), True
            richardson_error = worst_error(wall_diag, wall_reference) if wall_diag is not None else None
            pair_error = worst_error(pair_diag, pair_reference) if (pair_diag is not None and
                                                                    pair_reference is not None) else None
            errors = [e for e in (wall_error, pair_error) if e is not None]
            error = max(errors) if errors else None
            if model is None:
                seconds, how = self.product_time(scene.r_vectors, scene.wall)
                cost = self.cost_per_step(seconds)
            elif n == 1:
                others = [s['r_type'].reshape(-1, 3) for s in scene.structures if s is not structure]
                seconds, how = self.product_time(np.concatenate([structure['centres']] + others), scene.wall)
                cost = seconds
            else:
                seconds, how = self.product_time(self.replaced_scene_blobs(structure, model[1]), scene.wall)
                cost = self.cost_per_step(seconds)
            meets = error is not None and error <= self.accuracy
            note = 'wall gap %s%s; Richardson estimate %s; pair %s; cost %s' % (
                _percent(wall_error), ' (shipped table)' if from_table else '',
                _percent(richardson_error), _percent(pair_error), how)
            if calibrated and len(scene.structures) > 1:
                note += '; needs blob_radius %.4g for every structure' % model[2]
            self.add('resolution', sid, label, n, error, cost, meets, note)
            details.append(dict(candidate=label, blobs=n, wall_error=wall_error, richardson_error=richardson_error,
                                pair_error=pair_error, cost_s=cost))
            if model is not None and model[3]:
                candidates.append((model, cost, error, meets))
        self.resolution_details[sid] = dict(h_over_R=h, radius=R, rows=details, wall_reference=wall_reference,
                                            exact=exact)
        current = [c for c in self.choices if c.topic == 'resolution' and c.structure == sid][0]
        adequate = [c for c in candidates if c[3]]
        if adequate:
            best = min(adequate, key=lambda c: c[1])
            if current.meets_target and current.cost_s <= best[1]:
                return  # the scene's own model meets the target and costs no more
        else:
            known = [c for c in candidates if c[2] is not None]
            best = min(known, key=lambda c: c[2]) if known else None
            if best is None or (current.estimated_error is not None and best[2] > 0.9 * current.estimated_error):
                self.notes.append('%s: no %smodel up to 642 blobs meets %s at h/R = %.3g; the current model is kept%s'
                                  % (sid, '' if len(scene.structures) == 1 else 'applicable ', _percent(self.accuracy),
                                     h, '' if len(scene.structures) == 1 else
                                     ' (the calibrated shells need their own blob_radius, which every structure '
                                     'shares)'))
                return
            self.notes.append('%s: no model up to 642 blobs meets %s at h/R = %.3g; recommended: the most accurate '
                              '(%s, %s)' % (sid, _percent(self.accuracy), h, best[0][0], _percent(best[2])))
        label, blobs, a, _ = best[0]
        vertex = self.write_vertex(sid, label, blobs)
        spec = structure['spec']
        if spec.slip_file:
            self.notes.append('%s has a slip file for %d blobs, so its model is not changed automatically: the %s '
                              'model (written to %s%s) needs its own slip file, e.g. for squirmers python -m '
                              'multi_bodies.files.structure_generators squirmer-slip --blobs %d (radius 1)'
                              % (sid, structure['num_blobs'], label, vertex,
                                 ', blob_radius %.12g' % a if abs(a - scene.a) > 1e-9 * a else '', len(blobs)))
            return
        self.recommendation['structure:%s' % sid] = '%s %s' % (vertex, spec.clones_file)
        if abs(a - scene.a) > 1e-9 * a:
            self.recommendation['blob_radius'] = '%.12g' % a

    def write_vertex(self, sid, label, blobs):
        """Write the recommended model next to the output (``output_name.advice.<ID>.<model>.vertex``)."""
        name = '%s.advice.%s.%s.vertex' % (self.scene.options.output_name, sid,
                                           label.split(' (')[0].replace(' ', '_'))
        self.files[name] = (blobs, 'model recommended by multi_bodies/advise.py for structure %s: %s' % (sid, label))
        return name

    def measure_other_body(self, structure):
        """Bodies that are not spheres: spacing and gaps against the blob radius, coarsened model on request."""
        scene = self.scene
        sid, a = structure['ID'], scene.a
        reference = structure['reference']
        spacing = smallest_distance(reference) if len(reference) > 1 else float('nan')
        lowest_blob = float(np.min(structure['r_type'][:, :, 2]))
        gaps = self.blob_gaps()[structure['blobs']]
        body_gap = float(np.min(gaps)) if np.isfinite(np.min(gaps)) else None
        consequences = []
        ratio = spacing / a
        if ratio > 2.2:
            consequences.append('spacing/a = %.2f > 2: blobs do not touch, fluid leaks through the surface and the '
                                'drag is underestimated' % ratio)
        elif ratio < 1.0:
            consequences.append('spacing/a = %.2f < 1: each blob centre lies inside its neighbour; the surface is '
                                'smooth but the blob mobility is worse conditioned (more GMRES iterations)' % ratio)
        else:
            consequences.append('spacing/a = %.2f: the usual range (about 2 for touching blobs)' % ratio)
        if scene.wall and lowest_blob / a < 1.0:
            consequences.append('lowest blob at z/a = %.2f < 1: its mobility is regularised (damped like (z/a)^2); '
                                'lubrication with the wall is not resolved' % (lowest_blob / a))
        elif scene.wall and lowest_blob / a < 2.0:
            consequences.append('wall gap z/a = %.2f: gap comparable to a blob; near-wall mobilities are resolved only '
                                'to the blob size' % (lowest_blob / a))
        if body_gap is not None and body_gap / a < 2.0:
            consequences.append('nearest blobs of two bodies at %.2f a (< 2a): the bodies overlap hydrodynamically; '
                                'close-range interactions are not resolved' % (body_gap / a))
        note = '; '.join(consequences)
        seconds, how = self.product_time(scene.r_vectors, scene.wall)
        self.add('resolution', sid, 'current (%d blobs, spacing/a %.3g, wall gap/a %.3g%s)' % (
            structure['num_blobs'], ratio, lowest_blob / a,
            '' if body_gap is None else ', body gap/a %.3g' % (body_gap / a)),
            structure['num_blobs'], None, self.cost_per_step(seconds), True, note)
        if self.coarsen and 4 <= len(reference) <= DENSE_BLOB_LIMIT:
            self.measure_coarsened(structure, seconds)

    def measure_coarsened(self, structure, current_seconds):
        """Every other blob, blob radius rescaled to keep the bulk translational drag.

        Its error is measured against the current model at the wall gap of the lowest body.
        """
        scene = self.scene
        sid, a = structure['ID'], scene.a
        reference = structure['reference']
        coarse = reference[::2]
        target = bulk_radius(reference, a)
        low, high = 0.1 * a, 10.0 * a
        for _ in range(50):
            middle = np.sqrt(low * high)
            if bulk_radius(coarse, middle) < target:
                low = middle
            else:
                high = middle
        a_coarse = np.sqrt(low * high)
        low_index = structure['lowest']
        rotation = scene.arrays.rotation_matrices(scene.arrays.configuration)[structure['bodies']][low_index]
        location = scene.arrays.configuration.locations[structure['bodies']][low_index]
        centre = structure['centres'][low_index]
        fine = bodies_mobility([structure['r_type'][low_index]], [centre], a, scene.eta, scene.wall, self.backend)
        coarse_blobs = location + coarse @ rotation.T
        if np.min(coarse_blobs[:, 2]) <= 0 and scene.wall:
            return
        rough = bodies_mobility([coarse_blobs], [centre], a_coarse, scene.eta, scene.wall, self.backend)
        error = worst_error(np.diag(rough), np.diag(fine))
        replaced = self.replaced_scene_blobs(structure, (coarse @ np.eye(3)) - (reference.mean(axis=0)))
        seconds, how = self.product_time(replaced, scene.wall)
        self.add('resolution', sid, 'coarsened (every other blob, a = %.4g)' % a_coarse, len(coarse), error,
                 self.cost_per_step(seconds), error <= self.accuracy,
                 'error against the current model at its wall gap; blob_radius is shared by all structures; cost %s'
                 % how)
        vertex = self.write_vertex(sid, 'coarsened', coarse)
        spec = structure['spec']
        if error <= self.accuracy and len(scene.structures) == 1 and not spec.slip_file:
            self.recommendation['structure:%s' % sid] = '%s %s' % (vertex, spec.clones_file)
            self.recommendation['blob_radius'] = '%.12g' % a_coarse

