"""Physics overrides (user_defined_functions.py) in both scripts and both styles (SPEC section 7, decision 10).

Every override is written twice: in this package's style (functions with the
hook names, vectorised) and in the published style (``import
multi_bodies_functions``, ``from multi_bodies_functions import *``, a new
function of one blob / one pair, rebinding the module attribute).  Both are
run through ``multi_bodies_utilities.py`` (scheme ``mobility``, whose
``.force.dat`` holds the forces used) and ``multi_bodies.py`` (one forward
Euler step), and checked against values computed here from the formula:

* forces and torques: the law summed over blobs / pairs with numpy in this
  file (blob positions from the quaternion formula written here);
* velocities: ``U = N F`` with the body mobility ``N`` of the static
  ``body_mobility`` scheme (itself checked against the published code in
  test_static_problems.py);
* slip: a uniform slip ``s`` on every blob of a force-free body moves it at
  ``U = -s`` exactly (``lambda = 0`` solves the mobility problem, SPEC 4.2).

The pair of active rods is the published example (Balboa Usabiaga et al.
2016, section V.C, lowest resolution), whose published output gives the
angular velocity about the wall normal 3.88202665409 for both rods.
"""
import importlib
import os
import shutil

import numpy as np
import pytest

import mobility
import utils

STATIC = importlib.import_module('multi_bodies.multi_bodies_utilities')
DYNAMIC = importlib.import_module('multi_bodies.multi_bodies')
PACKAGE = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), 'multi_bodies')

A = 0.2                                    # blob radius
VERTEX = np.array([[0.0, 0.0, 0.0], [0.6, 0.0, 0.0], [0.0, 0.5, 0.1], [0.2, 0.1, 0.55]])
LOCATIONS = np.array([[0.0, 0.0, 1.5], [1.4, 0.3, 1.8]])
QUATERNIONS = np.array([[0.9, 0.3, 0.2, 0.1], [0.5, -0.4, 0.6, 0.2]])
QUATERNIONS /= np.linalg.norm(QUATERNIONS, axis=1)[:, None]
DT = 1e-3
BASE_OPTIONS = {'eta': 1.0, 'blob_radius': A, 'g': 0.0, 'repulsion_strength_wall': 0.0, 'debye_length_wall': 1.0,
                'repulsion_strength': 0.0, 'debye_length': 1.0, 'solver_tolerance': 1e-12,
                'mobility_blobs_implementation': 'python', 'mobility_vector_prod_implementation': 'python',
                'output_name': 'run', 'dt': DT, 'n_steps': 1, 'n_save': 1}


def rotation(q):
    """R(q) of a unit quaternion (s, p): (s^2 - p.p) I + 2 p p^T + 2 s [p]_x."""
    s, p = q[0], np.asarray(q[1:])
    cross = np.array([[0, -p[2], p[1]], [p[2], 0, -p[0]], [-p[1], p[0], 0]])
    return (s * s - p @ p) * np.eye(3) + 2 * np.outer(p, p) + 2 * s * cross


def blob_positions():
    """(bodies, blobs, 3) lab-frame blob positions of the scene."""
    return np.array([loc + VERTEX @ rotation(q).T for loc, q in zip(LOCATIONS, QUATERNIONS)])


def sum_to_bodies(blob_forces):
    """(Nb, 6) [F, T about the location] from blob forces (bodies, blobs, 3)."""
    r = blob_positions()
    force = blob_forces.sum(axis=1)
    torque = np.cross(r - LOCATIONS[:, None, :], blob_forces).sum(axis=1)
    return np.concatenate((force, torque), axis=1)


# ------------------------------------------------------------------ the five laws, as formulas
WALL_K, WALL_HEIGHT, G = 0.7, 1.6, 0.3


def expected_wall():
    """Per blob: gravity -g and a spring towards the height 1.6: f_z = -g + k (1.6 - z)."""
    z = blob_positions()[..., 2]
    f = np.zeros(z.shape + (3,))
    f[..., 2] = -G + WALL_K * (WALL_HEIGHT - z)
    return sum_to_bodies(f)


PAIR_C = 0.05


def expected_pairs():
    """Per blob pair: Coulomb-like repulsion, force on i = -c (r_j - r_i) / |r_j - r_i|^3."""
    r = blob_positions().reshape(-1, 3)
    d = r[None, :, :] - r[:, None, :]
    dist = np.linalg.norm(d, axis=-1)
    np.fill_diagonal(dist, np.inf)
    f = -(PAIR_C / dist ** 3)[..., None] * d
    return sum_to_bodies(f.sum(axis=1).reshape(2, -1, 3))


SPRING_K, SPRING_L, TWIST = 0.4, 1.0, 0.02


def expected_spring():
    """Body pair: force on i k (|r| - l0) r/|r|, torque on i c e_z x r; body j gets the opposite."""
    r = LOCATIONS[1] - LOCATIONS[0]
    force = SPRING_K * (np.linalg.norm(r) - SPRING_L) * r / np.linalg.norm(r)
    torque = TWIST * np.cross([0, 0, 1.0], r)
    return np.array([np.concatenate((force, torque)), -np.concatenate((force, torque))])


EXT_C, EXT_TORQUE = 0.25, 0.1


def expected_external():
    """Per body: F = -c (x, y, z - 1) of its location, T = (0, 0, 0.1 (k + 1)) for body k."""
    force = -EXT_C * (LOCATIONS - [0, 0, 1.0])
    torque = np.zeros((2, 3))
    torque[:, 2] = EXT_TORQUE * np.arange(1, 3)
    return np.concatenate((force, torque), axis=1)


def expected_slip_velocity():
    """A uniform slip s = (0.3 z, -0.2 x, 0.1) of the location on every blob moves the body at U = -s, W = 0."""
    s = np.column_stack((0.3 * LOCATIONS[:, 2], -0.2 * LOCATIONS[:, 0], np.full(2, 0.1)))
    return np.concatenate((-s, np.zeros((2, 3))), axis=1)


STYLES = ('package', 'published')
PUBLISHED_HEADER = 'import multi_bodies_functions\nfrom multi_bodies_functions import *\n\n'
PACKAGE_HEADER = 'import numpy as np\n\n'

CASES = {
    'wall': dict(
        options={},
        expected=expected_wall,
        package='''
def blob_external_forces(r_vectors, g=1.0, blob_mass=1.0, **kwargs):
    f = np.zeros_like(r_vectors)
    f[:, 2] = -g * blob_mass + %(k)r * (%(h)r - r_vectors[:, 2])
    return f
''',
        published='''
def blob_external_force_new(r_vectors, *args, **kwargs):
  f = np.zeros(3)
  f[2] = -kwargs.get('g') * kwargs.get('blob_mass') + %(k)r * (%(h)r - r_vectors[2])
  return f
multi_bodies_functions.blob_external_force = blob_external_force_new
''', values=dict(k=WALL_K, h=WALL_HEIGHT), extra={'g': G},
        hooks={'package': 'blob_external_forces', 'published': 'blob_external_force'}),
    'pairs': dict(
        options={'blob_blob_force_implementation': 'python'},
        expected=expected_pairs,
        package='''
def blob_blob_force(r, **kwargs):
    distance = np.linalg.norm(r, axis=-1)
    return -(%(c)r / distance ** 3)[..., None] * r
''',
        published='''
def blob_blob_force_new(r, *args, **kwargs):
  project_to_periodic_image(r, kwargs.get('periodic_length'))
  distance = np.linalg.norm(r)
  return -%(c)r * r / distance**3
multi_bodies_functions.blob_blob_force = blob_blob_force_new
''', values=dict(c=PAIR_C), extra={}, hooks=dict.fromkeys(STYLES, 'blob_blob_force')),
    'spring': dict(
        options={'body_body_force_torque_implementation': 'python'},
        expected=expected_spring,
        package='''
def body_body_force_torque(r, **kwargs):
    distance = np.linalg.norm(r, axis=-1)
    force = (%(k)r * (distance - %(l)r) / distance)[..., None] * r
    return force, %(t)r * np.cross([0.0, 0.0, 1.0], r)
''',
        published='''
def body_body_force_torque_new(r, quaternion_i, quaternion_j, *args, **kwargs):
  force_torque = np.zeros((2, 3))
  distance = np.linalg.norm(r)
  force_torque[0] = %(k)r * (distance - %(l)r) * r / distance
  force_torque[1] = %(t)r * np.cross(np.array([0.0, 0.0, 1.0]), r)
  return force_torque
multi_bodies_functions.body_body_force_torque = body_body_force_torque_new
''', values=dict(k=SPRING_K, l=SPRING_L, t=TWIST), extra={}, hooks=dict.fromkeys(STYLES, 'body_body_force_torque')),
    'external': dict(
        options={},
        expected=expected_external,
        package='''
def bodies_external_force_torque(bodies, r_vectors, **kwargs):
    locations = np.array([b.location for b in bodies])
    force_torque = np.zeros((len(bodies), 2, 3))
    force_torque[:, 0] = -%(c)r * (locations - [0.0, 0.0, 1.0])
    force_torque[:, 1, 2] = %(t)r * np.arange(1, len(bodies) + 1)
    return force_torque.reshape(-1, 3)
''',
        published='''
def bodies_external_force_torque_new(bodies, r_vectors, *args, **kwargs):
  force_torque = np.zeros((2 * len(bodies), 3))
  for k, b in enumerate(bodies):
    force_torque[2 * k] = -%(c)r * (b.location - np.array([0.0, 0.0, 1.0]))
    force_torque[2 * k + 1, 2] = %(t)r * (k + 1)
  return force_torque
multi_bodies_functions.bodies_external_force_torque = bodies_external_force_torque_new
''', values=dict(c=EXT_C, t=EXT_TORQUE), extra={}, hooks=dict.fromkeys(STYLES, 'bodies_external_force_torque')),
    'slip': dict(
        options={},
        expected=None,
        package='''
def uniform_slip(body):
    s = [0.3 * body.location[2], -0.2 * body.location[0], 0.1]
    return np.tile(s, (body.Nblobs, 1))


def set_slip_by_ID(body, slip):
    body.function_slip = uniform_slip
''',
        published='''
def uniform_slip(body):
  slip = np.empty((body.Nblobs, 3))
  for i in range(body.Nblobs):
    slip[i] = np.array([0.3 * body.location[2], -0.2 * body.location[0], 0.1])
  return slip


def set_slip_by_ID_new(body):
  body.function_slip = uniform_slip
  return
multi_bodies_functions.set_slip_by_ID = set_slip_by_ID_new
''', values={}, extra={}, hooks=dict.fromkeys(STYLES, 'set_slip_by_ID')),
}


def write_scene(folder, options, user_text=None):
    folder.mkdir(parents=True, exist_ok=True)
    with open(folder / 'body.vertex', 'w') as f:
        f.write('%d\n' % len(VERTEX) + ''.join('%r %r %r\n' % tuple(map(float, v)) for v in VERTEX))
    with open(folder / 'body.clones', 'w') as f:
        f.write('2\n' + ''.join(' '.join(repr(float(x)) for x in np.concatenate((loc, q))) + '\n'
                                for loc, q in zip(LOCATIONS, QUATERNIONS)))
    lines = ['%s %s' % item for item in options.items()] + ['structure body.vertex body.clones']
    (folder / 'input.dat').write_text('\n'.join(lines) + '\n')
    if user_text is not None:
        (folder / 'user_defined_functions.py').write_text(user_text)


def run_static(folder, monkeypatch):
    monkeypatch.chdir(folder)
    return utils.fail_cleanly(STATIC.main, ['--input-file', 'input.dat'])


def run_dynamic(folder, monkeypatch):
    monkeypatch.chdir(folder)
    return utils.fail_cleanly(DYNAMIC.main, ['--input-file', 'input.dat'])


@pytest.fixture(scope='module')
def body_mobility(tmp_path_factory):
    """N (12 x 12) of the scene from the static body_mobility scheme."""
    folder = tmp_path_factory.mktemp('body_mobility')
    write_scene(folder, dict(BASE_OPTIONS, scheme='body_mobility'))
    cwd = os.getcwd()
    try:
        os.chdir(folder)
        assert STATIC.main(['--input-file', 'input.dat']) == 0
    finally:
        os.chdir(cwd)
    return np.loadtxt(folder / 'run.body_mobility.dat')


def user_file(case, style):
    spec = CASES[case]
    header = PUBLISHED_HEADER if style == 'published' else PACKAGE_HEADER
    return header + spec[style] % spec['values']


@pytest.mark.parametrize('style', ['package', 'published'])
@pytest.mark.parametrize('case', sorted(CASES))
def test_override_in_both_scripts_matches_the_formula(case, style, body_mobility, tmp_path, monkeypatch, capsys):
    spec = CASES[case]
    options = dict(BASE_OPTIONS, **spec['options'])
    options.update(spec['extra'])
    if spec['expected'] is not None:
        force_torque = spec['expected']()
        velocity = (body_mobility @ force_torque.reshape(-1)).reshape(-1, 6)
    else:
        force_torque = np.zeros((2, 6))
        velocity = expected_slip_velocity()
    scale = np.abs(velocity).max()

    static = tmp_path / 'static'
    write_scene(static, dict(options, scheme='mobility'), user_file(case, style))
    assert run_static(static, monkeypatch) == 0
    log = capsys.readouterr().out
    assert '%s replaced by' % spec['hooks'][style] in log, log
    np.testing.assert_allclose(np.loadtxt(static / 'run.force.dat'), force_torque, rtol=1e-12,
                               atol=1e-14 * max(1.0, np.abs(force_torque).max()))
    np.testing.assert_allclose(np.loadtxt(static / 'run.velocities.dat'), velocity, rtol=0, atol=1e-8 * scale)

    dynamic = tmp_path / 'dynamic'
    write_scene(dynamic, dict(options, scheme='deterministic_forward_euler'), user_file(case, style))
    assert run_dynamic(dynamic, monkeypatch) == 0
    start = np.loadtxt(dynamic / 'run.body.00000000.clones', skiprows=1)
    end = np.loadtxt(dynamic / 'run.body.00000001.clones', skiprows=1)
    np.testing.assert_allclose((end[:, :3] - start[:, :3]) / DT, velocity[:, :3], rtol=0, atol=1e-8 * scale)


def test_per_blob_and_per_pair_functions_are_logged_as_slow(tmp_path, monkeypatch, capsys):
    text = PUBLISHED_HEADER + CASES['wall']['published'] % CASES['wall']['values'] + \
        CASES['pairs']['published'] % CASES['pairs']['values']
    write_scene(tmp_path, dict(BASE_OPTIONS, scheme='mobility', blob_blob_force_implementation='python'), text)
    assert run_static(tmp_path, monkeypatch) == 0
    log = capsys.readouterr().out
    assert 'blob_external_force replaced by blob_external_force_new' in log
    assert 'per blob' in log and 'per pair' in log and log.count('slow') == 2


def test_an_override_that_cannot_take_effect_is_logged(tmp_path, monkeypatch, capsys):
    """A python blob_blob_force with the C++ kernel is not used: the log says so, and the forces are the default."""
    write_scene(tmp_path, dict(BASE_OPTIONS, scheme='mobility', blob_blob_force_implementation='C++'),
                user_file('pairs', 'published'))
    assert run_static(tmp_path, monkeypatch) == 0
    log = capsys.readouterr().out
    assert 'blob_blob_force' in log and 'cannot take effect' in log and 'C++' in log
    assert not np.allclose(np.loadtxt(tmp_path / 'run.force.dat'), expected_pairs())


def test_published_rebinding_does_not_leak_into_later_runs(tmp_path, monkeypatch):
    from multi_bodies import multi_bodies_functions as mbf
    defaults = {name: getattr(mbf, name) for name in mbf.HOOK_NAMES}
    text = 'import multi_bodies.multi_bodies_functions as m\n' + \
        (CASES['external']['published'] % CASES['external']['values']).replace(
            'multi_bodies_functions.bodies_external_force_torque', 'm.bodies_external_force_torque')
    write_scene(tmp_path, dict(BASE_OPTIONS, scheme='mobility'), 'import numpy as np\n' + text)
    assert run_static(tmp_path, monkeypatch) == 0
    np.testing.assert_allclose(np.loadtxt(tmp_path / 'run.force.dat'), expected_external(), rtol=1e-12)
    assert {name: getattr(mbf, name) for name in mbf.HOOK_NAMES} == defaults
    assert 'multi_bodies_functions' not in __import__('sys').modules


# ------------------------------------------------------------------ clear errors in both scripts
ERRORS = {
    'syntax': ('import numpy as np\n\ndef blob_external_forces(r_vectors, **kwargs)\n    return r_vectors\n',
               2, ['user_defined_functions.py', 'line 3', 'syntax error']),
    'shape': ('import numpy as np\n\ndef blob_external_forces(r_vectors, **kwargs):\n'
              '    return np.zeros((len(r_vectors), 2))\n',
              1, ['blob_external_forces', 'user_defined_functions.py', 'shape (8, 2)', '(8, 3)']),
    'raises': (PUBLISHED_HEADER + 'def bodies_external_force_torque_new(bodies, r_vectors, *args, **kwargs):\n'
               '  raise ValueError("no forces today")\n'
               'multi_bodies_functions.bodies_external_force_torque = bodies_external_force_torque_new\n',
               1, ['bodies_external_force_torque_new', 'replacing bodies_external_force_torque',
                   'user_defined_functions.py', 'line 5', 'ValueError', 'no forces today']),
    'not_finite': ('import numpy as np\n\ndef set_slip_by_ID(body, slip):\n'
                   '    body.function_slip = lambda b: np.full((b.Nblobs, 3), np.nan)\n',
                   1, ['function_slip', 'user_defined_functions.py', 'not finite']),
}


@pytest.mark.parametrize('script', ['static', 'dynamic'])
@pytest.mark.parametrize('kind', sorted(ERRORS))
def test_faulty_user_file_gives_a_clear_error(kind, script, tmp_path, monkeypatch, capsys):
    text, status, words = ERRORS[kind]
    scheme = 'mobility' if script == 'static' else 'deterministic_forward_euler'
    write_scene(tmp_path, dict(BASE_OPTIONS, scheme=scheme), text)
    run = run_static if script == 'static' else run_dynamic
    if status == 2:
        with pytest.raises(SystemExit) as exit_info:
            run(tmp_path, monkeypatch)
        assert exit_info.value.code == 2
    else:
        assert run(tmp_path, monkeypatch) == 1
    message = capsys.readouterr().err
    for word in words:
        assert word in message, (word, message)
    assert 'Traceback' not in message


def test_pycuda_user_file_without_gpu_is_a_clear_set_up_error(tmp_path, monkeypatch, capsys):
    from multi_bodies import multi_bodies_functions as mbf
    try:
        mbf.blob_blob_force_calculator('pycuda')
        pytest.skip('a GPU is usable here: the error case cannot be produced')
    except utils.UserInputError:
        pass
    write_scene(tmp_path, dict(BASE_OPTIONS, scheme='deterministic_forward_euler',
                               blob_blob_force_implementation='pycuda'))
    shutil.copy(os.path.join(PACKAGE, 'examples', 'boomerang_suspension', 'forces_pycuda_user_defined.py'), tmp_path)
    with pytest.raises(SystemExit) as exit_info:
        run_dynamic(tmp_path, monkeypatch)
    assert exit_info.value.code == 2
    message = capsys.readouterr().err
    assert 'forces_pycuda_user_defined.py' in message and 'GPU' in message
    assert not os.path.exists(tmp_path / 'run.body.00000000.clones')  # refused at set-up, before step 0


# ------------------------------------------------------------------ the pair of active rods (published example)
PUBLISHED_ROD_ANGULAR_VELOCITY = 3.88202665409   # published output of this configuration, both rods


def rods_run(tmp_path, style, implementation, monkeypatch):
    example = os.path.join(PACKAGE, 'examples', 'pair_active_rods')
    folder = tmp_path / ('%s_%s' % (style, implementation.replace('+', 'p')))
    shutil.copytree(example, folder)
    run_dir = folder if style == 'package' else folder / 'published_style'
    text = (run_dir / 'inputfile_pair_active_rods_mobility.dat').read_text()
    text = text.replace('mobility_blobs_implementation            python',
                        'mobility_blobs_implementation            %s' % implementation)
    text = text.replace('mobility_vector_prod_implementation      auto',
                        'mobility_vector_prod_implementation      %s' % implementation)
    (run_dir / 'inputfile_pair_active_rods_mobility.dat').write_text(text)
    monkeypatch.chdir(run_dir)
    assert STATIC.main(['--input-file', 'inputfile_pair_active_rods_mobility.dat']) == 0
    return np.loadtxt(run_dir / 'data' / 'pair_active_rods.velocities.dat')


def test_active_rods_turn_counterclockwise_on_python_and_cpp(tmp_path, monkeypatch):
    if not mobility.backends.is_usable('C++'):
        pytest.skip('C++ backend not built')
    results = {(style, backend): rods_run(tmp_path, style, backend, monkeypatch)
               for style in ('package', 'published') for backend in ('python', 'C++')}
    for velocities in results.values():
        omega_z = velocities[:, 5]
        assert np.all(omega_z > 0)                                          # counterclockwise seen from above
        np.testing.assert_allclose(omega_z, PUBLISHED_ROD_ANGULAR_VELOCITY, rtol=1e-6)
        # The pair is symmetric under a half turn about the vertical axis through its midpoint.
        np.testing.assert_allclose(velocities[1, [0, 1, 3, 4]], -velocities[0, [0, 1, 3, 4]], atol=1e-7)
        np.testing.assert_allclose(velocities[1, [2, 5]], velocities[0, [2, 5]], rtol=1e-7)
    reference = results[('package', 'python')]
    for velocities in results.values():
        np.testing.assert_allclose(velocities, reference, rtol=0, atol=1e-7 * np.abs(reference).max())


def test_active_rods_example_runs_in_the_dynamics_in_both_styles(tmp_path, monkeypatch):
    trajectories = []
    for style in ('package', 'published'):
        folder = tmp_path / style
        shutil.copytree(os.path.join(PACKAGE, 'examples', 'pair_active_rods'), folder)
        run_dir = folder if style == 'package' else folder / 'published_style'
        text = (run_dir / 'inputfile_pair_active_rods.dat').read_text()
        text = text.replace('n_steps                                  20', 'n_steps 5')
        (run_dir / 'inputfile_pair_active_rods.dat').write_text(text)
        monkeypatch.chdir(run_dir)
        assert DYNAMIC.main(['--input-file', 'inputfile_pair_active_rods.dat']) == 0
        trajectories.append(np.loadtxt(run_dir / 'data' / 'pair_active_rods.rods.00000005.clones', skiprows=1))
    np.testing.assert_allclose(trajectories[1], trajectories[0], rtol=0, atol=1e-9)
    # Both rods turned counterclockwise about the wall normal: quaternion (cos t/2, 0, 0, sin t/2), t > 0.
    assert np.all(trajectories[0][:, 6] > 0)


# ------------------------------------------------------------------ the manual's examples, both scripts and styles
@pytest.mark.parametrize('script, input_name', [('static', 'inputfile_boomerang_suspension_mobility.dat'),
                                                ('dynamic', 'inputfile_boomerang_suspension.dat')])
def test_boomerang_suspension_example_gives_the_same_numbers_in_both_styles(script, input_name, tmp_path,
                                                                            monkeypatch, capsys):
    results = []
    for style in ('package', 'published'):
        folder = tmp_path / style
        shutil.copytree(os.path.join(PACKAGE, 'examples', 'boomerang_suspension'), folder / 'examples' / 'x')
        shutil.copytree(os.path.join(PACKAGE, 'Structures'), folder / 'Structures')
        run_dir = folder / 'examples' / 'x' / ('' if style == 'package' else 'published_style')
        text = (run_dir / input_name).read_text().replace('n_steps                                  200', 'n_steps 2')
        text = text.replace('n_save                                   10', 'n_save 2')
        (run_dir / input_name).write_text(text)
        monkeypatch.chdir(run_dir)
        main = STATIC.main if script == 'static' else DYNAMIC.main
        assert main(['--input-file', input_name]) == 0
        log = capsys.readouterr().out
        for hook in ('blob_blob_force', 'body_body_force_torque'):
            assert '%s replaced by' % hook in log
        name = 'boomerang_suspension.velocities.dat' if script == 'static' else \
            'boomerang_suspension.boomerang_suspension.00000002.clones'
        results.append(np.loadtxt(run_dir / 'data' / name, skiprows=0 if script == 'static' else 1))
    np.testing.assert_allclose(results[1], results[0], rtol=0, atol=1e-9 * np.abs(results[0]).max())


def test_squirmer_example_runs_in_the_static_script(tmp_path, monkeypatch):
    """The squirmer's slip file is used and turned with the body: in free space, without gravity, it swims along
    its body axis R(q) e_x (the slip is axisymmetric about that axis, up to the icosahedral discretisation)."""
    shutil.copytree(os.path.join(PACKAGE, 'examples', 'squirmer'), tmp_path / 'examples' / 'squirmer')
    shutil.copytree(os.path.join(PACKAGE, 'Structures'), tmp_path / 'Structures')
    monkeypatch.chdir(tmp_path / 'examples' / 'squirmer')
    assert STATIC.main(['--input-file', 'inputfile_squirmer_mobility.dat']) == 0   # as shipped: wall and gravity
    text = open('inputfile_squirmer_mobility.dat').read()
    text = text.replace('g                                        0.5', 'g 0.0')
    text = text.replace('implementation            python', 'implementation python_no_wall')
    text = text.replace('implementation      auto', 'implementation python_no_wall')
    open('free.dat', 'w').write(text)
    assert STATIC.main(['--input-file', 'free.dat']) == 0
    velocity = np.loadtxt('data/squirmer.velocities.dat')
    rows = [line.split() for line in open('squirmer.clones') if line.strip() and not line.startswith('#')]
    axis = rotation(np.array(rows[1][3:7], dtype=float))[:, 0]
    angle = np.degrees(np.arccos(velocity[:3] @ axis / np.linalg.norm(velocity[:3])))
    assert angle < 2.0 and np.linalg.norm(velocity[:3]) > 0.5, (angle, velocity)
    assert np.linalg.norm(velocity[3:]) < 1e-3 * np.linalg.norm(velocity[:3])


def doc_examples():
    """The two python blocks of the section 'The same override in both styles' of doc/overrides.md."""
    text = open(os.path.join(os.path.dirname(PACKAGE), 'doc', 'overrides.md')).read()
    section = text.split('## The same override in both styles')[1].split('\n## ')[0]
    blocks = [block.split('```')[0] for block in section.split('```python\n')[1:]]
    assert len(blocks) == 2
    return blocks


@pytest.mark.parametrize('style', [0, 1], ids=['package', 'published'])
def test_the_documented_examples_run_and_agree_with_the_formula(style, body_mobility, tmp_path, monkeypatch):
    """doc/overrides.md: wall spring plus location slip; U = N F - s by linearity (SPEC 4.2)."""
    options = dict(BASE_OPTIONS, g=G)
    velocity = (body_mobility @ expected_wall().reshape(-1)).reshape(-1, 6) + expected_slip_velocity()
    scale = np.abs(velocity).max()
    static, dynamic = tmp_path / 'static', tmp_path / 'dynamic'
    write_scene(static, dict(options, scheme='mobility'), doc_examples()[style])
    assert run_static(static, monkeypatch) == 0
    np.testing.assert_allclose(np.loadtxt(static / 'run.force.dat'), expected_wall(), rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(np.loadtxt(static / 'run.velocities.dat'), velocity, rtol=0, atol=1e-8 * scale)
    write_scene(dynamic, dict(options, scheme='deterministic_forward_euler'), doc_examples()[style])
    assert run_dynamic(dynamic, monkeypatch) == 0
    start = np.loadtxt(dynamic / 'run.body.00000000.clones', skiprows=1)
    end = np.loadtxt(dynamic / 'run.body.00000001.clones', skiprows=1)
    np.testing.assert_allclose((end[:, :3] - start[:, :3]) / DT, velocity[:, :3], rtol=0, atol=1e-8 * scale)


@pytest.mark.parametrize('script', ['static', 'dynamic'])
def test_failing_set_slip_by_ID_stops_before_the_run(script, tmp_path, monkeypatch, capsys):
    text = 'def set_slip_by_ID(body, slip):\n    return body.no_such_attribute\n'
    write_scene(tmp_path, dict(BASE_OPTIONS, scheme='mobility' if script == 'static' else
                               'deterministic_forward_euler'), text)
    with pytest.raises(SystemExit) as exit_info:
        (run_static if script == 'static' else run_dynamic)(tmp_path, monkeypatch)
    assert exit_info.value.code == 2
    message = capsys.readouterr().err
    for word in ('set_slip_by_ID', 'user_defined_functions.py', 'line 2', 'AttributeError', 'no_such_attribute'):
        assert word in message, (word, message)
    assert not os.path.exists(tmp_path / 'run.inputfile')


def test_published_default_slip_functions_give_the_slip_file(tmp_path, monkeypatch):
    """partial(active_body_slip, slip=slip) and default_zero_blobs (the published default) equal a slip file."""
    slip = np.array([[0.1, 0.0, 0.2], [0.0, -0.3, 0.0], [0.2, 0.1, 0.0], [0.0, 0.0, -0.1]])
    text = PUBLISHED_HEADER + '''
def set_slip_by_ID_new(body, slip):
  if slip is not None:
    body.function_slip = partial(active_body_slip, slip = slip)
  else:
    body.function_slip = default_zero_blobs
multi_bodies_functions.set_slip_by_ID = set_slip_by_ID_new
'''
    results = []
    for name, user in (('plain', None), ('published', text)):
        folder = tmp_path / name
        write_scene(folder, dict(BASE_OPTIONS, scheme='mobility'), user)
        np.savetxt(folder / 'body.slip', slip, header='%d' % len(slip), comments='')
        scene = (folder / 'input.dat').read_text().replace('body.clones\n', 'body.clones body.slip\n')
        (folder / 'input.dat').write_text(scene)
        assert run_static(folder, monkeypatch) == 0
        results.append(np.loadtxt(folder / 'run.velocities.dat'))
    assert np.abs(results[0]).max() > 0.01
    np.testing.assert_allclose(results[1], results[0], rtol=1e-12, atol=1e-15)


def test_bodies_have_the_published_attributes(tmp_path, monkeypatch):
    """A published-style file reads location, orientation, Nblobs, blob_radius, ID, get_r_vectors, calc_rot_matrix:
    the torque of blob forces f_i = (0, 0, 0.2 z_i) through calc_rot_matrix().T equals the sum of (r_i - loc) x f_i."""
    text = PUBLISHED_HEADER + '''
def bodies_external_force_torque_new(bodies, r_vectors, *args, **kwargs):
  force_torque = np.zeros((2 * len(bodies), 3))
  for k, b in enumerate(bodies):
    assert b.ID == 'body' and b.Nblobs == 4 and b.blob_radius == kwargs.get('blob_radius')
    r = b.get_r_vectors()
    assert np.allclose(r, b.location + np.dot(b.reference_configuration, b.orientation.rotation_matrix().T))
    f = np.zeros((b.Nblobs, 3))
    f[:, 2] = 0.2 * r[:, 2]
    force_torque[2 * k] = f.sum(axis=0)
    force_torque[2 * k + 1] = np.dot(b.calc_rot_matrix().T, f.flatten())
  return force_torque
multi_bodies_functions.bodies_external_force_torque = bodies_external_force_torque_new
'''
    write_scene(tmp_path, dict(BASE_OPTIONS, scheme='mobility'), text)
    assert run_static(tmp_path, monkeypatch) == 0
    f = np.zeros(blob_positions().shape)
    f[..., 2] = 0.2 * blob_positions()[..., 2]
    np.testing.assert_allclose(np.loadtxt(tmp_path / 'run.force.dat'), sum_to_bodies(f), rtol=1e-12, atol=1e-15)


def test_pycuda_user_file_with_auto_and_no_gpu_is_logged_as_unused(tmp_path, monkeypatch, capsys):
    from multi_bodies import multi_bodies_functions as mbf
    try:
        mbf.blob_blob_force_calculator('pycuda')
        pytest.skip('a GPU is usable here: auto would use the file')
    except utils.UserInputError:
        pass
    write_scene(tmp_path, dict(BASE_OPTIONS, scheme='mobility', blob_blob_force_implementation='auto'))
    shutil.copy(os.path.join(PACKAGE, 'examples', 'boomerang_suspension', 'forces_pycuda_user_defined.py'), tmp_path)
    assert run_static(tmp_path, monkeypatch) == 0
    log = capsys.readouterr().out
    assert 'forces_pycuda_user_defined.py is not used: no GPU is usable here' in log
