"""The advisor's lubrication topic and the chart of doc/lubrication_accuracy.md (issue 28).

Outside numbers used here: the exact sphere-wall mobilities (Brenner 1961 perpendicular translation,
O'Neill 1964 parallel translation, typed from VALIDATION.md §2.1, as in tests/test_advisor.py), the
textbook Rotne-Prager-Yamakawa pair mobility of two blobs (``1 - ...`` forms typed below), and, when
the reference folder is present, the published two-sphere tables of resolved spheres (Sprinkle et al.
2020).  The shipped error table (multi_bodies/advice/lubrication_tables.py) is checked against the
chart's own functions (one source: what the chart prints is what the advisor reads).
"""
import os
import subprocess
import sys

import numpy as np
import pytest

from multi_bodies.advice import advisor, advisor_lubrication, lubrication_models, lubrication_tables
from multi_bodies.files.input_options import read_input_file
from multi_bodies.files.snapshots import write_clones_file
from multi_bodies.files.structure_files import write_vertex_file

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
REFERENCE_TABLES = os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', '..', 'shared', 'reference',
                                'lubrication', 'tables')
# VALIDATION.md §2.1: exact sphere-wall mobilities at h/R = 1.01 and 1.2: (mu_par, mu_perp), 1/(6 pi eta R).
EXACT_WALL = {1.01: (0.29612, 0.00981), 1.2: (0.51279, 0.15771)}


def rpy_pair_xa12(r):
    """RPY pair mobility along the line of centres, r >= 2 (a = 1), in units of 1/(6 pi eta a): 3/(2r) - 1/r^3."""
    return 1.5 / r - 1.0 / r ** 3


# ------------------------------------------------------------------ the model scalars against outside numbers
def test_single_blob_pair_scalars_are_rpy():
    scalars = lubrication_models.pair_scalars('1 blob', 0.5)
    assert scalars[0] == pytest.approx(1.0, rel=1e-12)
    assert scalars[5] == pytest.approx(rpy_pair_xa12(2.5), rel=1e-12)          # 0.536
    assert scalars[6] == pytest.approx(0.75 / 2.5 + 0.5 / 2.5 ** 3, rel=1e-12)  # Y^A_12 = 0.332


@pytest.mark.parametrize('h,tolerance', [(1.01, 3e-3), (1.2, 1e-2)])
def test_lubricated_sphere_at_the_wall_is_exact(h, tolerance):
    """1 blob + lubrication at the wall: the exact sphere-wall mobility; at h = 1.01 from the lubrication
    forms (0.2 % here), at h = 1.2 from the published 2562-blob table, itself 0.83 % from exact."""
    scalars = lubrication_models.wall_scalars('1 blob + lubrication', h - 1.0)
    par, perp = EXACT_WALL[h]
    assert scalars[1] == pytest.approx(par, rel=tolerance)
    assert scalars[0] == pytest.approx(perp, rel=tolerance)


@pytest.mark.skipif(not os.path.isdir(REFERENCE_TABLES), reason='reference tables not present')
def test_exact_pair_agrees_with_the_resolved_table_where_it_is_resolved():
    """At a gap of 0.5 a the exact two-sphere scalars equal the published 2562-blob table to 0.1 %;
    at 0.01 a the table's approach mobility is 3 times the exact one (the 2562-blob sphere is not resolved)."""
    r, values = lubrication_models.read_pair_table(os.path.join(REFERENCE_TABLES, 'mob_scalars_MB_2562.txt'))
    far = lubrication_models.interpolate(r, values, 2.5)
    exact = lubrication_models.exact_pair_scalars(0.5)
    assert lubrication_models.pair_error(exact, far) < 1e-3
    near = lubrication_models.interpolate(r, values, 2.01)
    exact = lubrication_models.exact_pair_scalars(0.01)
    approach_table, approach_exact = near[0] - near[5], exact[0] - exact[5]
    assert 2.5 < approach_table / approach_exact < 3.5
    # the single-blob table is the RPY pair (a check of the layout read)
    r1, values1 = lubrication_models.read_pair_table(os.path.join(REFERENCE_TABLES, 'mob_scalars_MB_1.txt'))
    assert np.allclose(lubrication_models.interpolate(r1, values1, 2.5), lubrication_models.pair_scalars('1 blob', 0.5),
                       rtol=1e-5, atol=1e-7)


# ------------------------------------------------------------------ one source: the shipped table = the chart
@pytest.mark.parametrize('model,kind,gap', [('1 blob', 'pair', 0.01), ('1 blob', 'pair', 2.0),
                                            ('1 blob', 'wall', 0.5), ('1 blob + lubrication', 'wall', 0.05),
                                            ('shell 12', 'pair', 0.1), ('shell 12', 'wall', 0.01),
                                            ('shell 42', 'wall', 0.2)])
def test_shipped_errors_are_the_chart_numbers(model, kind, gap):
    if kind == 'pair':
        error = lubrication_models.pair_error(lubrication_models.pair_scalars(model, gap),
                                              lubrication_models.exact_pair_scalars(gap))
        gaps = lubrication_models.PAIR_GAPS
    else:
        error = lubrication_models.wall_error(lubrication_models.wall_scalars(model, gap),
                                              lubrication_models.exact_wall_scalars(gap))
        gaps = lubrication_models.WALL_GAPS
    shipped = lubrication_tables.ERRORS[kind][model][gaps.index(gap)]
    assert shipped == pytest.approx(error, rel=1e-3)   # printed to 4 digits
    assert lubrication_tables.error_at(model, kind, gap)[0] == pytest.approx(shipped, rel=1e-12)


def test_shipped_costs_rank_the_models():
    costs = {model: lubrication_tables.COSTS[model][1] for model in lubrication_models.MODELS}
    assert costs['1 blob'] < costs['1 blob + lubrication'] < costs['shell 12'] < costs['shell 42'] \
        < costs['shell 162'] < costs['shell 642']


# ------------------------------------------------------------------ the decision on user scenes
def _write(folder, scheme, blobs, blob_radius, centres, extra=()):
    write_vertex_file(os.path.join(folder, 'sphere.vertex'), blobs)
    write_clones_file(os.path.join(folder, 'spheres.clones'), np.asarray(centres, dtype=float),
                      np.tile([1.0, 0, 0, 0], (len(centres), 1)))
    lines = ['scheme %s' % scheme, 'blob_radius %r' % blob_radius, 'eta 1.0', 'g 1.0', 'kT 0.05', 'dt 0.01',
             'n_steps 1', 'solver_tolerance 1e-6', 'mobility_blobs_implementation C++',
             'mobility_vector_prod_implementation C++', 'repulsion_strength_wall 0.5', 'debye_length_wall 0.1',
             'output_name out/run'] + list(extra) + ['structure sphere.vertex spheres.clones']
    with open(os.path.join(folder, 'input.dat'), 'w') as f:
        f.write('\n'.join(lines) + '\n')
    return 'input.dat'


def _rows(result):
    return {c.candidate.replace(' (current)', ''): c for c in result.choices if c.topic == 'lubrication'}


def test_dense_pair_of_shells_gets_lubrication(tmp_path, monkeypatch):
    """Two 12-blob spheres 0.01 a apart, 3 a above the wall, 1 %: 1 blob + lubrication, not a 642-blob shell."""
    monkeypatch.chdir(tmp_path)
    blobs, blob_radius = lubrication_tables.shell_blobs(12, 1.0)
    name = _write(str(tmp_path), 'stochastic_Slip_Trapz', blobs, blob_radius, [[0, 0, 3.0], [2.01, 0, 3.0]])
    result = advisor.advise(name, accuracy=0.01, quick=True)
    rows = _rows(result)
    assert rows['1 blob + lubrication'].meets_target
    assert rows['1 blob + lubrication'].estimated_error < 1e-3
    assert not rows['shell 642'].meets_target and rows['shell 642'].estimated_error > 2.0   # 294 % at 0.01 a
    assert not rows['1 blob'].meets_target
    lines = result.lubrication_lines
    assert any(line.split() == ['scheme', 'lubrication_trapezoidal'] for line in lines)
    assert any(line.split()[:1] == ['blob_radius'] and float(line.split()[1]) == pytest.approx(1.0) for line in lines)
    assert any(line.startswith('structure') and line.split()[1].endswith('single_blob.vertex') for line in lines)
    assert 'lubrication_lines' in result.as_json()
    report = result.report()
    assert 'Sphere model (lubrication topic' in report
    # the resolution topic's shell (pair errors are skipped by --quick) is not recommended alongside
    assert not any(key.startswith('structure') or key == 'blob_radius' for key in result.recommendation)
    # applied, the input runs with the lubrication scheme
    result.write()
    text = advisor_lubrication.apply_lubrication_lines(open(name).read(), lines)
    with open('applied.dat', 'w') as f:
        f.write(text)
    options = read_input_file('applied.dat')
    assert options.scheme == 'lubrication_trapezoidal' and options.g == pytest.approx(12.0)
    run = subprocess.run([sys.executable, os.path.join(REPO, 'multi_bodies', 'multi_bodies.py'), '--input-file',
                          'applied.dat'], capture_output=True, text=True, env=dict(os.environ, PYTHONPATH=REPO),
                         timeout=300)
    assert run.returncode == 0, run.stderr


def test_lubrication_input_at_contact_keeps_its_model(tmp_path, monkeypatch):
    """A lubrication input of two spheres 0.01 a apart: its own model is the cheapest adequate, no change."""
    monkeypatch.chdir(tmp_path)
    name = _write(str(tmp_path), 'lubrication_trapezoidal', np.zeros((1, 3)), 1.0, [[0, 0, 3.0], [2.01, 0, 3.0]],
                  ['Lub_Cut 4.5', 'firm_delta 1e-2'])
    result = advisor.advise(name, accuracy=0.01, quick=True)
    rows = _rows(result)
    assert rows['1 blob + lubrication'].meets_target
    assert not rows['shell 642'].meets_target
    assert result.lubrication_lines == []


def test_dilute_lubrication_scene_gets_single_blobs(tmp_path, monkeypatch):
    """Spheres 10 a apart (centres), 10 a above the wall, 1 %: 1 blob without lubrication.

    Its error is the wall error at h = 5 a (0.1028 %, the chart's last wall gap, an upper bound); the pair
    error 0.9133 % at r = 4.9 a decays as r^-4 to 0.053 % at r = 10 a.
    """
    monkeypatch.chdir(tmp_path)
    name = _write(str(tmp_path), 'lubrication_trapezoidal', np.zeros((1, 3)), 1.0,
                  [[0, 0, 10.0], [10.0, 0, 10.0], [0, 10.0, 10.0]], ['Lub_Cut 4.5', 'firm_delta 1e-2'])
    result = advisor.advise(name, accuracy=0.01, quick=True)
    rows = _rows(result)
    assert rows['1 blob'].meets_target
    assert rows['1 blob'].estimated_error == pytest.approx(0.001028, rel=1e-3)
    assert lubrication_tables.error_at('1 blob', 'pair', 8.0)[0] == pytest.approx(0.009133 * (4.9 / 10) ** 4,
                                                                                rel=1e-3)
    lines = result.lubrication_lines
    assert any(line.split() == ['scheme', 'stochastic_trapezoidal_rollers'] for line in lines)
    assert any(line.startswith('remove the line Lub_Cut') for line in lines)
    applied = advisor_lubrication.apply_lubrication_lines(open(name).read(), lines)
    assert 'Lub_Cut' not in applied and 'free_kinematics True' in applied
    # negative control: at 0.1 % the single blob no longer meets the target (wall 0.1028 %), lubrication
    # (wall 0.03 %) does and is the input's own model: no change
    strict = advisor.advise(name, accuracy=0.001, quick=True)
    assert not _rows(strict)['1 blob'].meets_target
    assert _rows(strict)['1 blob + lubrication'].meets_target
    assert strict.lubrication_lines == []


def test_driven_rollers_are_not_offered_shells():
    scheme, reason = advisor_lubrication.scheme_for('shell 162', 'lubrication_trapezoidal_rollers', 0.0)
    assert scheme is None and 'omega_one_roller' in reason
    assert advisor_lubrication.scheme_for('shell 162', 'lubrication_trapezoidal', 0.01)[0] == 'stochastic_Slip_Trapz'
    assert advisor_lubrication.scheme_for('1 blob + lubrication', 'stochastic_Slip_Trapz', 0.01)[0] == \
        'lubrication_trapezoidal'


def test_gaps_of_a_scene():
    pair, wall = advisor_lubrication.sphere_gaps([[0, 0, 1.5], [2.2, 0, 1.5], [0, 5, 3]], 1.0, True)
    assert pair == pytest.approx(0.2) and wall == pytest.approx(0.5)
    assert advisor_lubrication.sphere_gaps([[0, 0, 1.5]], 1.0, False) == (None, None)
