"""The model advisor (multi_bodies/advice/advisor.py, multi_bodies/advise.py) on scenes whose answer is known.

Outside numbers used here: the exact self mobilities of a sphere above a
wall and the shell errors of VALIDATION.md §2.1 and §2.2 (typed below), the
far-field expansions of VALIDATION §2.1, and the published one-blob
Rotne-Prager-Blake self terms (VALIDATION §1.2).
"""
import json
import os
import subprocess
import sys

import numpy as np
import pytest

import mobility
from body.body import K_matrices
from multi_bodies.advice import advisor, sphere_tables
from multi_bodies.files.input_options import read_input_file
from multi_bodies.files.snapshots import write_clones_file
from multi_bodies.files.structure_files import read_vertex_file, write_vertex_file
from multi_bodies.files.structure_generators import calibrated_shell as _calibrated_shell

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCRIPT = os.path.join(REPO, 'multi_bodies', 'advise.py')

# VALIDATION.md §2.1: h/R -> (mu_par, mu_perp, rot_par, rot_perp), exact (Brenner, O'Neill, Dean-O'Neill, Jeffery).
EXACT = {1.1: (0.44305, 0.08727, 0.68955, 0.89520), 1.2: (0.51279, 0.15771, 0.78434, 0.92318),
         1.5: (0.62681, 0.31197, 0.90069, 0.96237), 2.0: (0.72321, 0.47047, 0.95991, 0.98432),
         5.0: (0.88821, 0.77816, 0.99750, 0.99900)}


_SHELLS = {}


def calibrated_shell(num_blobs):
    """The package's calibrated shell (blobs, blob radius, shell radius), made once per test session."""
    if num_blobs not in _SHELLS:
        _SHELLS[num_blobs] = _calibrated_shell(num_blobs)
    return _SHELLS[num_blobs]


def write_scene(folder, structures, blob_radius, scheme='body_mobility', extra=None):
    """Input file with one structure line per (name, blobs (n, 3), locations (nb, 3)); returns its name."""
    lines = ['scheme %s' % scheme, 'blob_radius %r' % blob_radius, 'eta 1.0', 'g 0.1', 'dt 0.01', 'n_steps 1',
             'mobility_blobs_implementation C++', 'mobility_vector_prod_implementation C++',
             'repulsion_strength_wall 1.0', 'debye_length_wall 0.1', 'output_name out/run']
    lines += ['%s %s' % item for item in (extra or {}).items()]
    for name, blobs, locations in structures:
        write_vertex_file(os.path.join(folder, name + '.vertex'), blobs)
        write_clones_file(os.path.join(folder, name + '.clones'), locations,
                          np.tile([1.0, 0, 0, 0], (len(locations), 1)))
        lines.append('structure %s.vertex %s.clones' % (name, name))
    with open(os.path.join(folder, 'input.dat'), 'w') as f:
        f.write('\n'.join(lines) + '\n')
    return 'input.dat'


def shell_errors(blobs, blob_radius, h):
    """Errors of (xx, yy, zz, rxx, ryy, rzz) of a rigid blob sphere (R = 1) at height h against EXACT[h]."""
    r = blobs - blobs.mean(axis=0) + [0.0, 0.0, h]
    M = mobility.blob_mobility_matrix('C++')(r, 1.0, blob_radius)
    K = K_matrices(r[None], np.array([[0.0, 0.0, h]]))[0]
    N = np.linalg.inv(K.T @ np.linalg.solve(M, K))
    d = np.diag(N) / np.array([1 / (6 * np.pi)] * 3 + [1 / (8 * np.pi)] * 3)
    par, perp, rot_par, rot_perp = EXACT[h]
    return d / np.array([par, par, perp, rot_par, rot_par, rot_perp]) - 1.0


def rows(result, topic, structure=None):
    return [c for c in result.choices if c.topic == topic and (structure is None or c.structure == structure)]


def test_series_reproduce_the_exact_table():
    """Brenner's and Jeffery's series give the perpendicular columns of VALIDATION §2.1 to its 5 digits."""
    for h, (_, perp, _, rot_perp) in EXACT.items():
        assert sphere_tables.brenner_perpendicular(h) == pytest.approx(perp, abs=6e-6)
        assert sphere_tables.jeffery_rotation_perpendicular(h) == pytest.approx(rot_perp, abs=6e-6)
    # Beyond the table: the far-field series of VALIDATION §2.1 (within 1e-4 of Brenner everywhere).
    x = 1 / 20.0
    far_perp = 1 - 9 * x / 8 + x ** 3 / 2 - 57 * x ** 4 / 100 + x ** 5 / 5
    assert sphere_tables.exact_self_mobilities(20.0)[1] == pytest.approx(far_perp, abs=1e-4)
    assert sphere_tables.exact_self_mobilities(1.0) is None


def test_12_blob_shell_at_h_1_1_needs_finer_resolution(tmp_path, monkeypatch):
    blobs, a, _ = calibrated_shell(12)
    monkeypatch.chdir(tmp_path)
    name = write_scene(str(tmp_path), [('sphere', blobs, [[0.0, 0.0, 1.1]])], a)
    result = advisor.advise(name, accuracy=0.01)
    current = rows(result, 'resolution', 'sphere')[0]
    # VALIDATION §2.2: the 12-blob shell is 65% off in perpendicular translation at h/R = 1.1.
    assert current.estimated_error == pytest.approx(0.645, abs=0.01)
    assert not current.meets_target
    key = 'structure:sphere'
    assert key in result.recommendation
    result.write()
    recommended = read_vertex_file(result.recommendation[key].split()[0])
    assert len(recommended) > 12
    # Nothing up to 642 blobs meets 1% there (VALIDATION §2.2: 6.2% at 642): the advisor says so.
    assert any('no model up to 642 blobs meets' in note for note in result.notes)

    # --quick takes the shell errors from the shipped chart table: the same errors within the table's digits.
    quick = advisor.advise(name, accuracy=0.1, quick=True)
    for full_row, quick_row in zip(rows(result, 'resolution'), rows(quick, 'resolution')):
        assert quick_row.estimated_error == pytest.approx(full_row.estimated_error, rel=0.05, abs=0.002)
    # At 10% the cheapest adequate shell is 642 blobs; applied, it meets the target against the exact table.
    quick.write()
    text = advisor.apply_recommendation(open(name).read(), quick.recommendation, ['sphere'])
    with open('applied.dat', 'w') as f:
        f.write(text)
    options = read_input_file('applied.dat')
    vertex = read_vertex_file(options.structures[0].vertex_file)
    assert len(vertex) == 642
    assert np.max(np.abs(shell_errors(vertex, options.blob_radius, 1.1))) <= 0.1


def test_spheres_far_from_the_wall_one_blob_meets_one_percent(tmp_path, monkeypatch):
    blobs, a, _ = calibrated_shell(12)
    monkeypatch.chdir(tmp_path)
    centres = [[0.0, 0.0, 20.0], [10.0, 0.0, 20.0], [0.0, 10.0, 20.0]]
    name = write_scene(str(tmp_path), [('spheres', blobs, centres)], a, scheme='deterministic_adams_bashforth')
    result = advisor.advise(name, accuracy=0.01)
    roller = [c for c in rows(result, 'resolution', 'spheres') if c.candidate.startswith('1 blob')][0]
    assert roller.meets_target and roller.estimated_error < 0.01
    assert rows(result, 'rollers')[-1].meets_target
    # The wall still changes the perpendicular mobility by 1/mu_perp - 1 = 6% at h/R = 20 (far-field series).
    x = 1 / 20.0
    far_perp = 1 - 9 * x / 8 + x ** 3 / 2 - 57 * x ** 4 / 100 + x ** 5 / 5
    no_wall = [c for c in rows(result, 'wall') if c.candidate.startswith('no wall (')][0]
    assert 0.5 < no_wall.estimated_error / (1 / far_perp - 1) < 2.0
    assert not no_wall.meets_target

    assert result.recommendation['scheme'] == 'deterministic_adams_bashforth_rollers'
    json_path = result.write()
    with open(json_path) as f:
        advice = json.load(f)
    assert advice['target_accuracy'] == 0.01
    assert {'topic', 'structure', 'candidate', 'blobs', 'estimated_error', 'cost_s', 'meets_target'} == \
        set(advice['choices'][0])
    # Applied: the scene reads and runs as rollers, and one blob of the recommended radius meets 1% at h = 20
    # (one-blob self terms of VALIDATION §1.2 against the far-field sphere values of §2.1).
    text = advisor.apply_recommendation(open(name).read(), result.recommendation, ['spheres'])
    with open('applied.dat', 'w') as f:
        f.write(text)
    options = read_input_file('applied.dat')
    assert len(read_vertex_file(options.structures[0].vertex_file)) == 1
    R, h = 1.0, 20.0 / options.blob_radius
    assert options.blob_radius == pytest.approx(R, rel=1e-9)
    blob_par = 1 - (9 / h - 2 / h ** 3 + 1 / h ** 5) / 16
    blob_perp = 1 - (9 / h - 4 / h ** 3 + 1 / h ** 5) / 8
    sphere_par = 1 - 9 * x / 16 + x ** 3 / 8 - 45 * x ** 4 / 256 - x ** 5 / 16
    assert abs(blob_par / sphere_par - 1) < 0.01 and abs(blob_perp / far_perp - 1) < 0.01
    run = subprocess.run([sys.executable, os.path.join(REPO, 'multi_bodies', 'multi_bodies.py'), '--input-file',
                          'applied.dat'], capture_output=True, text=True, env=dict(os.environ, PYTHONPATH=REPO))
    assert run.returncode == 0, run.stderr


def lattice_scene(folder, distance):
    blobs, a, _ = calibrated_shell(12)
    centres = [[i * distance, j * distance, 1.05 + k * distance] for i in range(3) for j in range(3) for k in range(3)]
    return write_scene(folder, [('packed', blobs, centres)], a, extra={'solver_tolerance': 1e-10})


@pytest.mark.parametrize('distance, warned', [(0.7, True), (2.5, False)])
def test_dense_packing_gives_the_gmres_warning(distance, warned, tmp_path, monkeypatch):
    """Overlapping spheres (centres 0.7 R apart) need more than 100 iterations; spread out (2.5 R) they do not."""
    monkeypatch.chdir(tmp_path)
    scene = advisor.Scene(lattice_scene(str(tmp_path), distance))
    result = advisor.Advisor(scene, 0.01)
    result.measure_solver()
    gmres = [c for c in rows(result, 'solver') if 'GMRES' in c.candidate][0]
    assert (result.iterations > advisor.GMRES_WARNING_ITERATIONS) == warned
    assert any('WARNING: GMRES' in note for note in result.notes) == warned
    assert gmres.meets_target == (not warned)


@pytest.mark.parametrize('h', [1.2, 2.0, 5.0])
def test_richardson_estimates_agree_with_the_exact_table(h, tmp_path, monkeypatch):
    """The advisor's estimate without the exact table is within a factor 2 of the exact error, 12 to 642 blobs."""
    blobs, a, _ = calibrated_shell(42)
    monkeypatch.chdir(tmp_path)
    scene = advisor.Scene(write_scene(str(tmp_path), [('sphere', blobs, [[0.0, 0.0, h]])], a))
    result = advisor.Advisor(scene, 0.01)
    result.measure_resolution()
    details = {row['candidate']: row for row in result.resolution_details['sphere']['rows']}
    for n in (12, 42, 162, 642):
        shell, shell_a, _ = calibrated_shell(n)
        exact_error = np.max(np.abs(shell_errors(shell, shell_a, h)))
        estimate = details['shell %d' % n]['richardson_error']
        assert 0.5 < estimate / exact_error < 2.0, (n, estimate, exact_error)
        # Where the exact table applies, the advisor uses it.
        assert details['shell %d' % n]['wall_error'] == pytest.approx(exact_error, rel=1e-3, abs=2e-5)


def test_near_contact_richardson_is_flagged_as_a_lower_bound(tmp_path, monkeypatch):
    blobs, a, _ = calibrated_shell(42)
    monkeypatch.chdir(tmp_path)
    result = advisor.Advisor(advisor.Scene(write_scene(str(tmp_path), [('sphere', blobs, [[0, 0, 1.1]])], a)), 0.01)
    result.measure_resolution()
    assert any('lower bounds' in note for note in result.notes)


def test_auto_backend_is_the_cheapest_measured():
    from mobility import choose
    from multi_bodies.solver.model import resolve_implementation
    messages = []
    chosen = resolve_implementation('auto', 'vector_product', log=messages.append, num_blobs=1000)
    costs = choose.backend_costs('vector_product', 1000)
    assert chosen in costs
    assert costs[chosen][0] <= (1 + choose.TIE_MARGIN) * min(s for s, _ in costs.values())
    assert any('auto chose %s' % chosen in m for m in messages)
    assert resolve_implementation('auto_no_wall', 'blobs', num_blobs=20).endswith('_no_wall')


@pytest.mark.parametrize('python_ms, cpp_ms, expected', [(1.0, 5.0, 'python'), (5.0, 1.0, 'C++'),
                                                          (1.0, 1.15, 'C++'), (1.0, 1.3, 'python')])
def test_auto_backend_follows_planted_costs(monkeypatch, python_ms, cpp_ms, expected):
    """With a planted cache of known costs, auto picks by the documented rule (mobility/choose.py): the
    cheapest, except that a backend within TIE_MARGIN (20 %) of it and earlier in the preference order
    (pycuda, C++, python) is kept; 100 blobs are below every probe size, so every cost is a cache entry."""
    from mobility import backends, choose
    from multi_bodies.solver.model import resolve_implementation
    if not (backends.is_usable('C++') and backends.is_usable('python')):
        pytest.skip('needs the C++ and python backends')
    planted = {('python', 'vector_product', True, 100): 1e-3 * python_ms,
               ('C++', 'vector_product', True, 100): 1e-3 * cpp_ms,
               ('pycuda', 'vector_product', True, 100): 1.0}  # 1 s: never the cheapest, if usable
    monkeypatch.setattr(choose, '_cache', dict(planted))
    messages = []
    assert resolve_implementation('auto', 'vector_product', log=messages.append, num_blobs=100) == expected
    assert any('auto chose %s' % expected in m for m in messages)
    assert resolve_implementation('auto_no_wall', 'vector_product', num_blobs=100).endswith('_no_wall')


def test_auto_backend_measures_when_nothing_is_cached(monkeypatch):
    """Without a cache the choice times every usable backend (best of repeats) and follows those times."""
    from mobility import backends, choose
    from multi_bodies.solver.model import resolve_implementation
    monkeypatch.setattr(choose, '_cache', {})
    calls = []
    real_time_call = choose.time_call

    def counting_time_call(function, *args, **kwargs):
        calls.append(function)
        return real_time_call(function, *args, **kwargs)

    monkeypatch.setattr(choose, 'time_call', counting_time_call)
    chosen = resolve_implementation('auto', 'vector_product', num_blobs=100)
    usable = [b for b in choose.PREFERENCE['vector_product'] if backends.is_usable(b)]
    measured = {key[0]: seconds for key, seconds in choose._cache.items()}
    assert sorted(measured) == sorted(usable) and len(calls) == len(usable)
    assert all(0 < seconds < 10 for seconds in measured.values())
    best = min(measured.values())
    assert chosen == next(b for b in choose.PREFERENCE['vector_product']
                          if b in measured and measured[b] <= (1 + choose.TIE_MARGIN) * best)


def test_script_on_the_manual_example_and_bad_input(tmp_path):
    source = os.path.join(REPO, 'multi_bodies')
    os.symlink(os.path.join(source, 'Structures'), tmp_path / 'Structures')
    with open(os.path.join(source, 'inputfile_body_mobility.dat')) as f:
        (tmp_path / 'in.dat').write_text(f.read())
    env = dict(os.environ, PYTHONPATH=REPO)
    run = subprocess.run([sys.executable, SCRIPT, '--input-file', 'in.dat', '--quick'], cwd=tmp_path,
                         capture_output=True, text=True, env=env)
    assert run.returncode == 0, run.stderr
    assert '## recommendation' in run.stdout and '## backend' in run.stdout
    assert (tmp_path / 'data' / 'run.body_mobility.advice.json').is_file()
    bad = subprocess.run([sys.executable, SCRIPT, '--input-file', 'in.dat', '--accuracy', '2'], cwd=tmp_path,
                         capture_output=True, text=True, env=env)
    assert bad.returncode == 2 and 'Traceback' not in bad.stderr and '--accuracy' in bad.stderr


def test_coarsened_rod_keeps_its_drag_and_reports_its_error(tmp_path, monkeypatch):
    """--coarsen: every other blob with a radius that keeps the bulk drag (checked with the RPY matrix directly)."""
    from multi_bodies.files.structure_generators import rod
    monkeypatch.chdir(tmp_path)
    blobs = rod(10, 0.5)
    scene = advisor.Scene(write_scene(str(tmp_path), [('rod', blobs, [[0.0, 0.0, 1.0]])], 0.25))
    result = advisor.Advisor(scene, 0.01, coarsen=True)
    result.measure_resolution()
    coarse = [c for c in rows(result, 'resolution', 'rod') if c.candidate.startswith('coarsened')][0]
    assert coarse.blobs == 5
    a_coarse = float(coarse.candidate.split('a = ')[1].rstrip(')'))

    def drag(points, a):
        M = mobility.rotne_prager_tensor(points, 1.0, a)
        K = K_matrices(points[None], points.mean(axis=0)[None])[0]
        return np.trace(np.linalg.pinv(K.T @ np.linalg.solve(M, K))[:3, :3])
    assert drag(blobs[::2], a_coarse) == pytest.approx(drag(blobs, 0.25), rel=1e-3)
    # Five blobs cannot represent ten near the wall exactly: a finite error, reported against the target.
    assert 0 < coarse.estimated_error < 1 and coarse.meets_target == (coarse.estimated_error <= 0.01)


def test_a_shipped_weak_error_table_ranks_schemes_by_cost_per_unit_time():
    """With error = C dt^p, the dt for a target e is (e/C)^(1/p); cost per unit time = solves / dt."""
    table = {'first': {'solves_per_step': 1, 'weak_error': (0.1, 1.0)},
             'second': {'solves_per_step': 3, 'weak_error': (0.1, 2.0)}}
    ranked = advisor.cheapest_scheme(table, 0.001, 1.0)
    # first: dt = 0.01 -> 100 solves per unit time; second: dt = 0.1 -> 30 solves per unit time.
    assert [name for _, name, _ in ranked] == ['second', 'first']
    assert ranked[0][0] == pytest.approx(30.0) and ranked[1][2] == pytest.approx(0.01)
    assert advisor.cheapest_scheme({}, 0.01, 1.0) == []
