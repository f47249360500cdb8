"""Shipped errors and costs of sphere models near contact: the numbers of ``doc/lubrication_accuracy.md``.

Printed by ``python doc/charts/lubrication_accuracy_vs_cost.py`` (the chart of that page; models, scalars
and error measures in ``multi_bodies.advice.lubrication_models``) and pasted here; the advisor's
``lubrication`` topic reads them (``model_error``), and ``tests/test_advisor_lubrication.py`` recomputes
some with the chart's functions and compares.

``ERRORS[kind][model]``: the largest relative error of the mobility scalars (see
``lubrication_models.pair_error`` / ``wall_error``) against the exact answer, at the gaps
``PAIR_GAPS`` (two spheres in free space, surface gap / a) or ``WALL_GAPS`` (one sphere above the wall,
``h/a - 1``); None where not known.  The row ``'shell 2562 (published)'`` is the published resolved
spheres of Sprinkle et al. 2020 (their tables, 2562 blobs), not a model this package builds here.

``COSTS[model]``: (seconds of one far-field ``M f``, seconds of one mobility solve, GMRES iterations,
'measured' or 'modelled') for 64 spheres (8 x 8 lattice, gap 0.2 a, 1.2 a above the wall), C++ backend,
2 shared cores, GMRES tolerance 1e-8.
"""
import numpy as np

from multi_bodies.advice.lubrication_models import MODELS, PAIR_GAPS, SHELLS, TABLE_MODEL, WALL_GAPS

RESOLVED_NOTE = 'errors of the published 2562-blob spheres of Sprinkle et al. 2020 (their tables)'
ADVISED_MODELS = MODELS + (TABLE_MODEL,)
FAR_FIELD_DECAY_MODELS = ('1 blob', '1 blob + lubrication')

# printed by doc/charts/lubrication_accuracy_vs_cost.py on 2026-12-02 (2 shared cores)
ERRORS = {
    'pair': {
        '1 blob':
            (18.82, 9.615, 3.884, 1.918, 0.9062, 0.2864, 0.09483, 0.02287, 0.009133),
        '1 blob + lubrication':
            (3.792e-08, 4.009e-08, 3.997e-08, 3.441e-08, 2.174e-08, 6.693e-15, 9.508e-09, 8.996e-09, 0.009133),
        'shell 12':
            (9.501, 4.687, 1.707, 0.7108, 0.2389, 0.08797, 0.081, 0.07892, 0.07837),
        'shell 42':
            (6.232, 2.97, 0.9638, 0.3174, 0.06239, 0.0599, 0.05799, 0.05667, 0.05626),
        'shell 162':
            (4.128, 1.859, 0.4856, 0.0854, 0.01872, 0.01785, 0.01727, 0.01688, 0.01676),
        'shell 642':
            (2.938, 1.24, 0.2479, 0.02949, 0.004234, 0.004048, 0.003918, 0.003829, 0.003801),
        'shell 2562 (published)':
            (1.961, 0.7568, 0.1324, 0.02301, 0.004011, 0.0006533, None, None, None),
    },
    'wall': {
        '1 blob':
            (24.74, 4.667, 2.155, 0.9125, 0.2235, 0.05446, 0.008998, 0.001028),
        '1 blob + lubrication':
            (0.002185, 0.008478, 0.004238, 0.008343, 0.001066, 0.0002716, 9.158e-05, 0.0003037),
        'shell 12':
            (8.194, 1.466, 0.645, 0.2528, 0.08721, 0.08105, 0.07863, 0.0779),
        'shell 42':
            (5.21, 0.7811, 0.2646, 0.07685, 0.06218, 0.05812, 0.05644, 0.05592),
        'shell 162':
            (3.164, 0.476, 0.1149, 0.02247, 0.01847, 0.01731, 0.01681, 0.01665),
        'shell 642':
            (2.316, 0.3025, 0.0626, 0.01021, 0.004197, 0.003933, 0.003818, 0.003777),
        'shell 2562 (published)':
            (1.927, 0.1785, 0.04101, 0.008343, 0.001066, 0.0006428, 0.000622, 0.0006125),
    },
}
COSTS = {
    '1 blob': (8.42e-05, 8.42e-05, 0, 'measured'),
    '1 blob + lubrication': (6.99e-05, 0.00565, 11, 'measured'),
    'shell 12': (0.000972, 0.0244, 20, 'measured'),
    'shell 42': (0.0104, 0.352, 27, 'measured'),
    'shell 162': (0.157, 8.55, 29, 'measured'),
    'shell 642': (2.69, 230, 29, 'modelled'),
}


def model_blobs(model):
    """Blobs per sphere of a model label."""
    if model.startswith('shell'):
        return int(model.split()[1])
    return 1


def shell_blobs(num_blobs, radius):
    """(blobs (n, 3) about 0, blob radius) of the calibrated shell of ``num_blobs`` blobs and radius ``radius``."""
    from multi_bodies.advice.advisor_models import calibrated_model
    return calibrated_model(num_blobs, radius)


COST_SCALING = ('the 64-sphere solve of the chart x (n/64)^2, or x n/64 below 64 spheres, where the work of each '
                'sphere alone dominates')


def modelled_solve_seconds(model, num_spheres):
    """Seconds of one mobility solve of ``num_spheres`` spheres of ``model``, from the chart's 64-sphere solve."""
    ratio = num_spheres / 64.0
    return COSTS[model][1] * (ratio ** 2 if ratio >= 1.0 else ratio)


def error_at(model, kind, gap):
    """(error at ``gap`` (units of a) of ``model`` in geometry ``kind`` ('pair' or 'wall'), note).

    Linear in log(gap) between the tabulated gaps.  Below the smallest gap the value there, flagged (the
    errors of single blobs and shells grow as the gap closes: a lower bound); above the largest the value
    there (errors fall with the gap: an upper bound), except for the pair error of single blobs (with or
    without lubrication: beyond the cutoff they are the same model), which falls like ``r^-4`` (the
    leading far-field error of the RPY pair, ``15 / (4 r^4)`` in the self term ``x11^a`` of Jeffrey and
    Onishi 1984).  None when the model has no value there.
    """
    gaps = np.array(PAIR_GAPS if kind == 'pair' else WALL_GAPS)
    values = ERRORS[kind][model]
    known = [(g, e) for g, e in zip(gaps, values) if e is not None]
    if not known:
        return None, '%s: no %s error' % (model, kind)
    g, e = np.array(known).T
    if gap < g[0] * (1.0 - 1e-9):
        return float(e[0]), '%s gap %.3g below the smallest charted (%g): error there, a lower bound' % (
            kind, gap, g[0])
    if gap > g[-1]:
        if kind == 'pair' and model in FAR_FIELD_DECAY_MODELS:
            return float(e[-1]) * ((2.0 + g[-1]) / (2.0 + gap)) ** 4, 'pair gap %.3g beyond the chart: r^-4 decay' % gap
        return float(e[-1]), ''
    return float(np.interp(np.log(gap), np.log(g), e)), ''


def model_error(model, pair_gap, wall_gap):
    """(largest of the pair error at ``pair_gap`` and the wall error at ``wall_gap``, note); a gap None: none."""
    errors, notes = [], []
    for kind, gap in (('pair', pair_gap), ('wall', wall_gap)):
        if gap is None:
            continue
        error, note = error_at(model, kind, max(gap, 1e-6))
        if error is None:
            return None, note
        errors.append(error)
        if note:
            notes.append(note)
    return (max(errors) if errors else 0.0), '; '.join(notes)


__all__ = ['ADVISED_MODELS', 'COSTS', 'ERRORS', 'SHELLS', 'error_at', 'model_blobs', 'model_error', 'shell_blobs']
