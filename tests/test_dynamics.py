"""Dynamic runs (multi_bodies/multi_bodies.py): published trajectories, restart, physical laws, faults.

Numbers asserted come from the published code (../shared/reference/dynamics,
body_mobility_table.json), from analytic results (Stokes drag of a sphere,
convergence orders), or from linearity of Stokes flow.
"""
import importlib
import json
import os
import re
import shutil

import numpy as np
import pytest

import mobility
from body.body import Body, bodies_to_arrays
from multi_bodies import multi_bodies_functions as mbf
from multi_bodies.files import structure_generators as gen
from multi_bodies.files.snapshots import write_clones_file
from multi_bodies.files.structure_files import write_vertex_file
from multi_bodies.solver.model import Model
from quaternion_integrator.schemes import make_scheme
from utils import UserInputError

SCRIPT = importlib.import_module('multi_bodies.multi_bodies')
BACKENDS = ['python', 'C++', 'pycuda']
REFERENCE_CASES = ['dyn_deterministic_forward_euler_python', 'dyn_deterministic_adams_bashforth_python',
                   'rollers_AB_free_kinematics_True_blobforce_python']


def require_backend(name):
    if not mobility.backends.is_usable(name):
        pytest.skip('%s backend not usable here: %s' % (name, mobility.available_implementations()[name]))
    if name == 'pycuda':
        try:
            mbf.blob_blob_force_calculator('pycuda')
        except UserInputError as err:
            pytest.skip(str(err))


def run_script(run_dir, input_name, monkeypatch, extra=()):
    monkeypatch.chdir(run_dir)
    return SCRIPT.main(['--input-file', input_name] + list(extra))


def read_trajectory(run_dir, output_name, structure_id):
    """All one_file_per_step snapshots of a structure, shape (frames, bodies, 7)."""
    prefix = '%s.%s.' % (output_name, structure_id)
    names = sorted(f for f in os.listdir(run_dir) if f.startswith(prefix) and f.endswith('.clones'))
    return np.array([np.loadtxt(os.path.join(run_dir, f), skiprows=1).reshape(-1, 7) for f in names])


def write_input(path, options, structures):
    lines = ['%s %s' % item for item in options.items()]
    lines += ['structure ' + ' '.join(s) for s in structures]
    path.write_text('\n'.join(lines) + '\n')


# ------------------------------------------------------------------ published trajectories
@pytest.mark.parametrize('backend', BACKENDS)
@pytest.mark.parametrize('case', REFERENCE_CASES)
def test_trajectories_match_published(case, backend, reference_dir, tmp_path, monkeypatch):
    """VALIDATION: trajectories of the published deterministic runs to 1e-8 on every backend."""
    require_backend(backend)
    folder = reference_dir / 'dynamics' / case
    text = (folder / 'run.inputfile').read_text()
    text = re.sub(r'(?<=\s)(structures/|dynamics/)', lambda m: str(reference_dir) + '/' + m.group(1), text)
    for option in ('mobility_vector_prod_implementation', 'blob_blob_force_implementation',
                   'mobility_blobs_implementation'):
        text = re.sub(r'%s \S+' % option, '%s %s' % (option, backend), text)
    (tmp_path / 'input.dat').write_text(text)
    assert run_script(tmp_path, 'input.dat', monkeypatch) == 0
    reference = np.load(folder / 'trajectory.npz')
    for key in (k for k in reference.files if not k.endswith('__steps')):
        ours = read_trajectory(tmp_path, 'run', key)
        assert ours.shape == reference[key].shape
        np.testing.assert_allclose(ours, reference[key], rtol=0, atol=1e-8)
    info = (tmp_path / 'run.info').read_text().splitlines()
    assert info[0].split() == ['invalid_configuration_count', '=', '0']
    assert (tmp_path / 'run.bodies_info').read_text().splitlines()[:4] == \
        (folder / 'run.bodies_info').read_text().splitlines()[:4]


# ------------------------------------------------------------------ scene helpers
def boomerang_scene(tmp_path, scheme='deterministic_forward_euler', n_steps=4, extra=None, z=3.0,
                    orientation=(0.9, 0.3, 0.2, 0.1)):
    write_vertex_file(tmp_path / 'boomerang.vertex', gen.boomerang())
    write_clones_file(tmp_path / 'boomerang.clones', [[0.0, 0.0, z]], [orientation])
    options = {'scheme': scheme, 'dt': 0.05, 'n_steps': n_steps, 'n_save': 1, 'eta': 1.0, 'g': 1.0,
               'blob_radius': 0.25, 'solver_tolerance': 1e-12, 'repulsion_strength_wall': 1.0,
               'debye_length_wall': 1.0, 'mobility_vector_prod_implementation': 'C++',
               'blob_blob_force_implementation': 'None', 'output_name': 'run'}
    options.update(extra or {})
    write_input(tmp_path / 'input.dat', options, [('boomerang.vertex', 'boomerang.clones')])
    return tmp_path / 'input.dat'


@pytest.mark.parametrize('scheme', ['deterministic_forward_euler', 'deterministic_adams_bashforth'])
def test_restart_continues_exactly(tmp_path, monkeypatch, scheme):
    """20 steps at once equal 10 + 10 steps through initial_step (SPEC decision 4); Adams-Bashforth
    continues from the previous velocities saved with the snapshot."""
    whole, split = tmp_path / 'whole', tmp_path / 'split'
    whole.mkdir(), split.mkdir()
    boomerang_scene(whole, scheme=scheme, n_steps=20)
    boomerang_scene(split, scheme=scheme, n_steps=10)
    assert run_script(whole, 'input.dat', monkeypatch) == 0
    assert run_script(split, 'input.dat', monkeypatch) == 0
    boomerang_scene(split, scheme=scheme, n_steps=20, extra={'initial_step': 10})
    assert run_script(split, 'input.dat', monkeypatch) == 0
    a = read_trajectory(whole, 'run', 'boomerang')
    b = read_trajectory(split, 'run', 'boomerang')
    assert a.shape == b.shape == (21, 1, 7)
    np.testing.assert_allclose(b, a, rtol=0, atol=1e-12)


def test_output_files(tmp_path, monkeypatch):
    """Every output of the manual's section 5.1, in one_file mode, with the random state restorable."""
    boomerang_scene(tmp_path, n_steps=4, extra={'save_clones': 'one_file', 'n_save': 2, 'seed': 7})
    assert run_script(tmp_path, 'input.dat', monkeypatch) == 0
    config = (tmp_path / 'run.boomerang.config').read_text().split('\n')
    assert config[0] == '1' and config[2] == '1' and config[4] == '1' and len(config) == 7  # steps 0, 2, 4
    info = (tmp_path / 'run.info').read_text().splitlines()
    assert [line.split('=')[0].strip() for line in info[:3]] == ['invalid_configuration_count',
                                                            'deterministic_iterations_count',
                                                            'stochastic_iterations_count']
    assert int(info[1].split('=')[1]) > 0
    assert float((tmp_path / 'run.time').read_text()) > 0
    assert (tmp_path / 'run.inputfile').read_text() == (tmp_path / 'input.dat').read_text()
    assert (tmp_path / 'run.bodies_info').read_text().splitlines()[3].split() == ['num_bodies', '1']
    state = np.random.default_rng(7).bit_generator.state
    from multi_bodies.run.run_output import read_random_state
    assert read_random_state(str(tmp_path / 'run.random_state')) == state


# ------------------------------------------------------------------ laws
def sphere_system(vertex, location, blob_radius, implementation, g=1.0):
    body = Body(location, [1.0, 0.0, 0.0, 0.0], vertex, blob_radius)
    body.ID = 'sphere'
    hooks = mbf.load_user_hooks('/nonexistent')
    physics = dict(g=g, repulsion_strength_wall=0.0, debye_length_wall=1.0, repulsion_strength=0.0,
                   debye_length=1.0, periodic_length=np.zeros(3), blob_radius=blob_radius, blob_mass=1.0)
    return Model([body], bodies_to_arrays([body]), hooks, physics, 1.0, blob_radius, 1e-12,
                 vector_product_name=implementation, blobs_name=implementation.replace('C++', 'python'))


def as_list(value):
    return json.loads(value) if isinstance(value, str) else value


@pytest.mark.parametrize('height', ['h2', 'h5'])
def test_sphere_sediments_at_published_body_mobility(height, reference_dir):
    """A shell sphere sediments at N_zz F_z, N from the published body_mobility table."""
    entry = json.load(open(reference_dir / 'body_mobility_table.json'))['entries'][
        'shell_N_12_Rg_0_7921_Rh_1_' + height]
    vertex = np.loadtxt(reference_dir / 'structures' / entry['vertex_file'], skiprows=1)
    location = np.array(as_list(entry['location']), dtype=float)
    N = np.array(as_list(entry['body_mobility_6x6']), dtype=float)
    system = sphere_system(vertex, location, float(entry['blob_radius']), 'C++')
    scheme = make_scheme('deterministic_forward_euler', 0.01)
    state = scheme.step(system, scheme.init(system, system.start_configuration))
    velocity = state.velocities[0]
    force = np.array([0, 0, -12.0, 0, 0, 0])
    np.testing.assert_allclose(velocity, N @ force, rtol=0, atol=1e-9 * abs(N[2, 2] * 12))
    np.testing.assert_allclose(state.configuration.locations[0], np.array(location) + 0.01 * (N @ force)[:3],
                               atol=1e-12)


def test_sphere_far_from_walls_follows_stokes_drag():
    """Without a wall, a calibrated shell of hydrodynamic radius 1 falls at F / (6 pi eta)."""
    blobs, a, _ = gen.calibrated_shell(42)
    system = sphere_system(blobs, [0.0, 0.0, 50.0], a, 'C++_no_wall', g=0.5)
    scheme = make_scheme('deterministic_forward_euler', 0.1)
    velocity = scheme.step(system, scheme.init(system, system.start_configuration)).velocities[0]
    np.testing.assert_allclose(velocity, [0, 0, -0.5 * 42 / (6 * np.pi), 0, 0, 0], atol=1e-10)


def test_force_free_body_without_slip_does_not_move(tmp_path, monkeypatch):
    boomerang_scene(tmp_path, n_steps=3, extra={'g': 0.0, 'repulsion_strength_wall': 0.0})
    assert run_script(tmp_path, 'input.dat', monkeypatch) == 0
    trajectory = read_trajectory(tmp_path, 'run', 'boomerang')
    np.testing.assert_array_equal(trajectory, np.repeat(trajectory[:1], 4, axis=0))


def boomerang_final_state(scheme_name, dt, t_end):
    reference = gen.boomerang()
    body = Body([0.0, 0.0, 2.0], np.array([0.9, 0.3, 0.2, 0.1]) / np.linalg.norm([0.9, 0.3, 0.2, 0.1]),
                reference, 0.25)
    body.ID = 'boomerang'
    physics = dict(g=1.0, repulsion_strength_wall=1.0, debye_length_wall=0.5, repulsion_strength=0.0,
                   debye_length=1.0, periodic_length=np.zeros(3), blob_radius=0.25, blob_mass=1.0)
    system = Model([body], bodies_to_arrays([body]), mbf.load_user_hooks('/nonexistent'), physics, 1.0, 0.25,
                   1e-12, vector_product_name='python')
    scheme = make_scheme(scheme_name, dt)
    state = scheme.init(system, system.start_configuration)
    for _ in range(int(round(t_end / dt))):
        state = scheme.step(system, state)
    return np.concatenate((state.configuration.locations[0], state.configuration.orientations[0]))


@pytest.mark.parametrize('scheme_name, order', [('deterministic_forward_euler', 1),
                                                ('deterministic_adams_bashforth', 2)])
def test_convergence_order(scheme_name, order):
    """Error against a dt/16 run falls like dt^order on a sedimenting, rotating boomerang."""
    dt, t_end = 0.1, 1.0
    fine = boomerang_final_state(scheme_name, dt / 16, t_end)
    errors = [np.linalg.norm(boomerang_final_state(scheme_name, dt / k, t_end) - fine) for k in (1, 2, 4)]
    rates = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all(np.abs(rates - order) < 0.3), (errors, rates)


def test_dense_algebra_agrees_with_iterative(tmp_path, monkeypatch):
    a, b = tmp_path / 'a', tmp_path / 'b'
    a.mkdir(), b.mkdir()
    boomerang_scene(a, scheme='deterministic_forward_euler', n_steps=2)
    boomerang_scene(b, scheme='deterministic_forward_euler_dense_algebra', n_steps=2)
    assert run_script(a, 'input.dat', monkeypatch) == 0 and run_script(b, 'input.dat', monkeypatch) == 0
    np.testing.assert_allclose(read_trajectory(b, 'run', 'boomerang'), read_trajectory(a, 'run', 'boomerang'),
                               atol=1e-10)


# ------------------------------------------------------------------ overrides
USER_FUNCTIONS = '''
import numpy as np

def blob_external_forces(r_vectors, g=1.0, blob_mass=1.0, **kwargs):
    """Gravity three times stronger and no wall repulsion."""
    forces = np.zeros_like(r_vectors)
    forces[:, 2] = -3.0 * g * blob_mass
    return forces
'''


def test_user_defined_functions_change_the_trajectory(tmp_path, monkeypatch):
    """Stokes flow is linear: three times the gravity gives three times the first displacement."""
    plain, user = tmp_path / 'plain', tmp_path / 'user'
    plain.mkdir(), user.mkdir()
    for folder in (plain, user):
        boomerang_scene(folder, n_steps=1, extra={'repulsion_strength_wall': 0.0})
    (user / 'user_defined_functions.py').write_text(USER_FUNCTIONS)
    assert run_script(plain, 'input.dat', monkeypatch) == 0
    assert run_script(user, 'input.dat', monkeypatch) == 0
    move_plain = np.diff(read_trajectory(plain, 'run', 'boomerang')[:, 0, :3], axis=0)
    move_user = np.diff(read_trajectory(user, 'run', 'boomerang')[:, 0, :3], axis=0)
    np.testing.assert_allclose(move_user, 3.0 * move_plain, rtol=1e-9)


def test_rollers_with_prescribed_spin(tmp_path, monkeypatch):
    """free_kinematics False: the solved torques make every roller spin at omega_one_roller."""
    (tmp_path / 'blob.vertex').write_text('1\n0 0 0\n')
    write_clones_file(tmp_path / 'rollers.clones', [[0, 0, 1.0], [2.0, 0.3, 1.2], [-1.5, 1.8, 1.5]],
                      [[1, 0, 0, 0]] * 3)
    options = {'scheme': 'deterministic_forward_euler_rollers', 'dt': 0.01, 'n_steps': 1, 'eta': 1.0,
               'g': 0.0, 'blob_radius': 0.5, 'free_kinematics': 'False', 'omega_one_roller': '0 1 0',
               'repulsion_strength_wall': 0.0, 'solver_tolerance': 1e-12,
               'mobility_vector_prod_implementation': 'C++', 'output_name': 'run'}
    write_input(tmp_path / 'input.dat', options, [('blob.vertex', 'rollers.clones')])
    assert run_script(tmp_path, 'input.dat', monkeypatch) == 0
    r0, r1 = read_trajectory(tmp_path, 'run', 'rollers')[:, :, :3]
    # Independent check with the python backend: find the torques from the dense 3x3-block rot-rot matrix.
    eye = np.eye(9)
    M_WT = np.column_stack([mobility.single_wall_mobility_rot_times_torque(r0, e, 1.0, 0.5) for e in eye])
    M_UT = np.column_stack([mobility.single_wall_mobility_trans_times_torque(r0, e, 1.0, 0.5) for e in eye])
    torques = np.linalg.solve(M_WT, np.tile([0, 1.0, 0], 3))
    np.testing.assert_allclose((r1 - r0).reshape(-1) / 0.01, M_UT @ torques, atol=1e-9)


# ------------------------------------------------------------------ faults and bad input
def test_blob_below_the_wall_stops_the_run_with_files_intact(tmp_path, monkeypatch, capsys):
    boomerang_scene(tmp_path, n_steps=50, z=0.6, orientation=(1, 0, 0, 0), extra={'g': 30.0, 'repulsion_strength_wall': 0.0, 'dt': 0.2})
    assert run_script(tmp_path, 'input.dat', monkeypatch) == 1
    message = capsys.readouterr().err
    assert 'below the wall' in message and 'step ' in message and 'body 0' in message
    trajectory = read_trajectory(tmp_path, 'run', 'boomerang')
    assert 1 <= trajectory.shape[0] < 51
    assert not any(name.endswith('.part') for name in os.listdir(tmp_path))
    assert (tmp_path / 'run.info').read_text().splitlines()[0].split() == ['invalid_configuration_count', '=', '1']
    assert float((tmp_path / 'run.time').read_text()) >= 0


def test_nan_forces_stop_the_run(tmp_path, monkeypatch, capsys):
    boomerang_scene(tmp_path, n_steps=3)
    (tmp_path / 'user_defined_functions.py').write_text(
        'import numpy as np\n\ndef bodies_external_force_torque(bodies, r_vectors, **kw):\n'
        '    return np.full((2 * len(bodies), 3), np.nan)\n')
    assert run_script(tmp_path, 'input.dat', monkeypatch) == 1
    assert 'not finite' in capsys.readouterr().err
    assert read_trajectory(tmp_path, 'run', 'boomerang').shape[0] == 1
    assert (tmp_path / 'run.info').exists()


def test_non_converged_solve_stops_the_run(tmp_path, monkeypatch, capsys):
    from multi_bodies.solver import body_solver
    monkeypatch.setattr(body_solver, 'GMRES_MAXITER', 1)
    boomerang_scene(tmp_path, n_steps=3, extra={'solver_tolerance': 1e-300})
    assert run_script(tmp_path, 'input.dat', monkeypatch) == 1
    assert 'did not converge' in capsys.readouterr().err


@pytest.mark.parametrize('scheme, expected', [('stochastic_Slip_Trapzz', 'unknown scheme'),
                                              ('deterministic_forward_eler', 'unknown scheme')])
def test_unknown_scheme_is_a_clear_error(scheme, expected, tmp_path, monkeypatch, capsys):
    boomerang_scene(tmp_path, scheme=scheme)
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as exit_info:
        __import__('utils').fail_cleanly(SCRIPT.main, ['--input-file', 'input.dat'])
    assert exit_info.value.code == 2
    assert expected in capsys.readouterr().err


def test_auto_picks_a_usable_backend(tmp_path, monkeypatch, capsys):
    boomerang_scene(tmp_path, n_steps=1, extra={'mobility_vector_prod_implementation': 'auto'})
    assert run_script(tmp_path, 'input.dat', monkeypatch) == 0
    out = capsys.readouterr().out
    expected = next(b for b in ('pycuda', 'C++', 'python') if mobility.backends.is_usable(b))
    assert 'auto chose %s' % expected in out


# ------------------------------------------------------------------ the shipped examples
EXAMPLES = [('', 'inputfile_dynamic.dat'), ('examples/boomerang_suspension', 'inputfile_boomerang_suspension.dat'),
            ('examples/pair_active_rods', 'inputfile_pair_active_rods.dat'),
            ('examples/squirmer', 'inputfile_squirmer.dat')]


@pytest.mark.parametrize('folder, input_name', EXAMPLES)
def test_shipped_examples_run(folder, input_name, tmp_path, monkeypatch):
    source = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), 'multi_bodies')
    shutil.copytree(os.path.join(source, 'Structures'), tmp_path / 'Structures')
    run_dir = tmp_path / folder if folder else tmp_path
    if folder:
        shutil.copytree(os.path.join(source, folder), run_dir)
    else:
        shutil.copy(os.path.join(source, input_name), run_dir / input_name)
    text = (run_dir / input_name).read_text()
    text = re.sub(r'(?m)^n_steps\s+\d+', 'n_steps 2', text)
    (run_dir / input_name).write_text(text)
    assert run_script(run_dir, input_name, monkeypatch) == 0
    assert '# End' not in (run_dir / 'data').name
    assert any(name.endswith('.clones') or name.endswith('.config') for name in os.listdir(run_dir / 'data'))
