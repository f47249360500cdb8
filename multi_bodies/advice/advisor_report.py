"""The advisor's output: the table of every choice, the recommendation, the input lines and ``.advice.json``.

Helpers of ``multi_bodies/advice/advisor.py`` (floor 7).  ``AdvisorReport`` is the
output half of ``advisor.Advisor`` (it reads ``choices``, ``recommendation``,
``notes``, ``scene`` and ``accuracy``); ``apply_recommendation`` rewrites an
input file with the recommended lines.
"""
import json
import os


class AdvisorReport:
    """Text report and JSON of the choices an ``Advisor`` measured."""

    def as_json(self):
        return {'target_accuracy': self.accuracy,
                'choices': [dict(topic=c.topic, structure=c.structure, candidate=c.candidate, blobs=c.blobs,
                                 estimated_error=c.estimated_error, cost_s=c.cost_s, meets_target=c.meets_target)
                            for c in self.choices],
                'recommendation': dict(self.recommendation),
                'check': getattr(self, 'check', None),
                'dt_bound': getattr(self, 'dt_bound', None),
                'lubrication_lines': list(getattr(self, 'lubrication_lines', []))}

    def report(self):
        """Text report: a table per choice, the notes, the recommendation and the input lines to change."""
        lines = ['# Advice for %s (target accuracy %s%s)' % (self.scene.options.input_file, _percent(self.accuracy),
                                                          ', --quick' if self.quick else ''),
                 '', 'Scene: %d bodies, %d blobs, %d structure types; blob_radius %g, eta %g, %s.' % (
                     self.scene.arrays.num_bodies, self.scene.num_blobs, len(self.scene.structures), self.scene.a,
                     self.scene.eta, 'wall at z = 0' if self.scene.wall else 'no wall'),
                 'Error: the largest relative error of the six self-mobility diagonal entries of a body at the '
                 'smallest gap; cost per step: one M f (%s) x GMRES iterations of the scene (%s).' % (
                     self.backend, self.iterations)]
        for structure in self.scene.structures:
            sphere = structure['sphere']
            lines.append('- %s: %d bodies of %d blobs, %s' % (
                structure['ID'], structure['count'], structure['num_blobs'],
                'sphere of radius %.4g (%s), lowest centre h/R = %.4g%s' % (
                    sphere['radius'], sphere['kind'], structure['centres'][structure['lowest']][2] / sphere['radius'],
                    '' if structure['nearest_gap'] is None else
                    ', nearest pair at %.4g R' % (structure['nearest_gap'] / sphere['radius']))
                if sphere else 'not a sphere'))
        for topic in ('resolution', 'wall', 'rollers', 'lubrication', 'solver', 'backend', 'geometry', 'dt'):
            rows = [c for c in self.choices if c.topic == topic]
            if not rows:
                continue
            lines += ['', '## %s' % topic, '',
                      '| structure | option | blobs | estimated error | cost per step | meets target | note |',
                      '|---|---|---|---|---|---|---|']
            for c in rows:
                lines.append('| %s | %s | %s | %s | %s | %s | %s |' % (
                    c.structure or '', c.candidate, '' if c.blobs is None else c.blobs, _percent(c.estimated_error),
                    _seconds(c.cost_s), 'yes' if c.meets_target else 'no', c.note))
        if self.sources:
            lines += ['', '## where the numbers come from', ''] + ['- ' + s for s in self.sources]
            if self.quick:
                lines.append('- --quick: errors of the calibrated shells at the wall gap (h/R >= 1.1) come from '
                             'the shipped table of doc/accuracy_vs_cost.md (multi_bodies/advice/sphere_tables.py, '
                             'interpolated in h/R); pair errors are not measured; costs of other models are '
                             'modelled as M f x (N/N_scene)^2; above 600 blobs the dense solve is modelled as N^3 '
                             'from a 600-blob inversion')
        if self.notes:
            lines += ['', '## notes', ''] + ['- ' + n for n in self.notes]
        lines += ['', '## recommendation', '']
        if self.recommendation:
            lines.append('Change these input lines:')
            lines.append('')
            lines += ['    ' + line for line in recommendation_lines(self.recommendation)]
        elif not getattr(self, 'lubrication_lines', None):
            lines.append('The input already uses the cheapest adequate choices measured here: no line to change.')
        if getattr(self, 'lubrication_lines', None):
            lines += ['', 'Cheaper with lubrication (lubrication topic; instead of the model lines above, not run '
                      'through the check):' if getattr(self, 'lubrication_alternative', False)
                      else 'Sphere model (lubrication topic):', '']
            lines += ['    ' + line for line in self.lubrication_lines]
        return '\n'.join(lines) + '\n'

    def recommends_file(self, path):
        """True when a recommended structure line names the vertex file ``path``."""
        return path in getattr(self, 'lubrication_files', ()) or any(
            k.startswith('structure:') and v.split()[0] == path for k, v in self.recommendation.items())

    def write(self):
        """Write ``output_name.advice.json``, the recommended vertex files; returns the JSON path."""
        from multi_bodies.files.structure_files import write_vertex_file
        output = self.scene.options.output_name
        folder = os.path.dirname(output)
        if folder:
            os.makedirs(folder, exist_ok=True)
        for path, (blobs, comment) in self.files.items():
            if self.recommends_file(path):
                write_vertex_file(path, blobs, comment=comment)
        path = output + '.advice.json'
        with open(path, 'w') as f:
            json.dump(self.as_json(), f, indent=1)
        return path


def recommendation_lines(recommendation):
    """Input-file lines ``option value`` of a recommendation (``structure:<ID>`` keys become ``structure``)."""
    return ['%-40s %s' % (key.split(':')[0], value) for key, value in recommendation.items()]


def apply_recommendation(text, recommendation, structure_ids):
    """Input text with the recommended lines in place of the old ones.

    ``structure_ids``: the structure ID of each ``structure`` line, in order.
    Options not present are appended.
    """
    lines = text.splitlines()
    done = set()
    structure_index = 0
    for i, raw in enumerate(lines):
        words = raw.split('#', 1)[0].split()
        if not words:
            continue
        name = words[0]
        if name == 'structure':
            key = 'structure:%s' % structure_ids[structure_index]
            structure_index += 1
            if key in recommendation:
                lines[i] = 'structure %s' % recommendation[key]
                done.add(key)
        elif name in recommendation:
            lines[i] = '%s %s' % (name, recommendation[name])
            done.add(name)
    lines += ['%s %s' % (key, value) for key, value in recommendation.items() if key not in done]
    return '\n'.join(lines) + '\n'


def _percent(value):
    if value is None:
        return '-'
    return '%.3g%%' % (100.0 * value)


def _seconds(value):
    if value is None:
        return '-'
    return '%.3g ms' % (1e3 * value) if value < 1.0 else '%.3g s' % value
