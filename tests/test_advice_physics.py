"""The advisor's recommendations keep the physics of the user's run (issue 20, "Advice that keeps the physics").

Outside numbers used here: the exact perpendicular mobility of a sphere above a wall at h/R = 1.5,
mu_perp / mu_bulk = 0.31197 (Brenner 1961, VALIDATION.md section 2.1); the default laws' total weight of
a body, ``n_blobs * g`` (gravity acts per blob with blob_mass 1); for the time step, a run at dt/8 as the
reference trajectory (the schemes converge, so the difference estimates the error of the run at dt).
Everything runs with ``--quick`` on small scenes (a few seconds each).
"""
import contextlib
import io
import os
import shutil
import subprocess
import sys

import numpy as np
import pytest

from multi_bodies.advice import advisor
from multi_bodies.files.input_options import parse_input_text, read_input_file
from multi_bodies.files.snapshots import write_clones_file
from multi_bodies.files.structure_files import read_vertex_file
from multi_bodies.run.run_setup import prepare
from quaternion_integrator.schemes import make_scheme
import utils

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
MULTI_BODIES = os.path.join(REPO, 'multi_bodies')
ENV = dict(os.environ, PYTHONPATH=REPO, OMP_NUM_THREADS='1')
MU_PERP_1_5 = 0.31197  # VALIDATION §2.1: exact mu_perp / mu_bulk of a sphere at h/R = 1.5


def set_up(options, script='dynamics'):
    with contextlib.redirect_stdout(io.StringIO()):
        return prepare(options, script, log=lambda line: None).system


def applied_options(result, name):
    """Options of the input ``name`` with the advisor's recommendation applied (written to applied.dat)."""
    result.write()
    ids = [s['ID'] for s in result.scene.structures]
    text = advisor.apply_recommendation(open(name).read(), result.recommendation, ids)
    with open('applied.dat', 'w') as f:
        f.write(text)
    return read_input_file('applied.dat')


def one_sphere(folder, height=1.5, g=0.05, scheme='deterministic_adams_bashforth', extra=()):
    folder = os.path.abspath(folder)
    """One 12-blob shell of hydrodynamic radius 1 (made by the structure generator) at ``height``."""
    run = subprocess.run([sys.executable, '-m', 'multi_bodies.files.structure_generators', 'shell', '--blobs', '12',
                          '--output', folder], capture_output=True, text=True, env=ENV, cwd=REPO)
    assert run.returncode == 0, run.stderr
    vertex = [n for n in os.listdir(folder) if n.endswith('.vertex')][0]
    blob_radius = [line.split()[-1] for line in open(os.path.join(folder, vertex)) if 'blob_radius' in line][0]
    write_clones_file(os.path.join(folder, 'one.clones'), np.array([[0.0, 0.0, height]]), np.array([[1.0, 0, 0, 0]]))
    lines = ['scheme %s' % scheme, 'mobility_blobs_implementation C++', 'mobility_vector_prod_implementation C++',
             'blob_blob_force_implementation None', 'dt 0.01', 'n_steps 4', 'n_save 1', 'eta 1.0', 'g %r' % g,
             'blob_radius %s' % blob_radius, 'repulsion_strength_wall 0.1', 'debye_length_wall 0.1',
             'output_name out/run', 'structure %s one.clones' % vertex] + list(extra)
    with open(os.path.join(folder, 'input.dat'), 'w') as f:
        f.write('\n'.join(lines) + '\n')
    return 'input.dat'


def test_refined_sphere_keeps_its_weight_and_moves_as_the_exact_sphere(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    name = one_sphere(str(tmp_path))
    result = advisor.advise(name, accuracy=0.01, quick=True)
    assert 'structure:one' in result.recommendation, result.report()
    options = applied_options(result, name)
    blobs = len(read_vertex_file(options.structures[0].vertex_file))
    assert blobs > 12
    user, recommended = set_up(read_input_file(name)), set_up(options)
    # The law: gravity acts per blob (blob_mass 1), so the body weighs n g; the recommended run keeps 12 g.
    assert blobs * options.g == pytest.approx(12 * 0.05, rel=1e-9)
    user_force = user.forces_torques(user.start_configuration)
    new_force = recommended.forces_torques(recommended.start_configuration)
    assert np.max(np.abs(new_force - user_force)) <= 0.01 * np.max(np.abs(user_force))
    # One mobility problem of the recommended run: the sinking speed of the exact sphere under the user's force
    # (mu_perp / (6 pi eta R) F_z, R = 1), within the target.
    u = recommended.deterministic_velocities(recommended.start_configuration).velocities[0]
    exact = MU_PERP_1_5 / (6 * np.pi) * user_force[0, 2]
    assert u[2] == pytest.approx(exact, rel=0.01)
    assert np.max(np.abs(u[[0, 1, 3, 4, 5]])) <= 1e-6 * abs(exact)  # no sideways motion or spin by symmetry
    # The recommended input runs (two steps of its scheme, no blob through the wall).
    assert isinstance(run_for(options, options.dt, 2 * options.dt), np.ndarray)
    # The advisor's own check ran and says so.
    assert result.check is not None and result.check['holds']
    assert any(note.startswith('check: holds') for note in result.notes)
    assert any('rescaled' in note for note in result.notes)


def test_per_blob_override_without_g_blocks_a_silent_resolution_change(tmp_path, monkeypatch):
    """A user hook whose body total grows with the blob count (a fixed force per blob) cannot be rescaled."""
    monkeypatch.chdir(tmp_path)
    name = one_sphere(str(tmp_path))
    with open('user_defined_functions.py', 'w') as f:
        f.write('import numpy as np\n\n\n'
                'def blob_external_forces(r_vectors, *args, **kwargs):\n'
                '    f = np.zeros((len(r_vectors), 3))\n'
                '    f[:, 2] = -0.05  # a fixed weight per blob, independent of g\n'
                '    return f\n')
    result = advisor.advise(name, accuracy=0.01, quick=True)
    assert 'structure:one' not in result.recommendation
    assert 'blob_radius' not in result.recommendation
    assert any('blob_external_forces' in note and 'per blob' in note for note in result.notes)
    assert any(note.startswith('check: FAILED') for note in result.notes)


def test_rollers_keep_their_drive(tmp_path, monkeypatch):
    for name in ('inputfile_rollers.dat',):
        shutil.copy(os.path.join(MULTI_BODIES, name), str(tmp_path))
    shutil.copytree(os.path.join(MULTI_BODIES, 'Structures'), str(tmp_path / 'Structures'))
    monkeypatch.chdir(tmp_path)
    result = advisor.advise('inputfile_rollers.dat', accuracy=0.01, quick=True)
    recommendation = result.recommendation
    assert not [k for k in recommendation if k.startswith('structure:')]
    assert 'rollers' in recommendation.get('scheme', 'deterministic_adams_bashforth_rollers')
    assert 'free_kinematics' not in recommendation and 'omega_one_roller' not in recommendation
    assert any('drive' in note for note in result.notes)
    options = applied_options(result, 'inputfile_rollers.dat')
    user, recommended = set_up(read_input_file('inputfile_rollers.dat')), set_up(options)
    assert recommended.invalid_bodies(recommended.start_configuration).size == 0
    v_user = user.roller_velocities(user.start_configuration).velocities
    v_new = recommended.roller_velocities(recommended.start_configuration).velocities
    # The drive dominates the motion: without the torque the rollers hardly move sideways.
    undriven = user.replace(omega_one_roller=np.zeros(3))
    v_undriven = undriven.roller_velocities(user.start_configuration).velocities
    speed = np.max(np.linalg.norm(v_user, axis=1))
    assert np.max(np.linalg.norm(v_undriven - v_user, axis=1)) > 0.5 * speed
    assert np.max(np.linalg.norm(v_new - v_user, axis=1)) <= 0.01 * speed
    # The recommended input runs with its dt: over its whole run it stays within the target of a run at a
    # step 16 times smaller (relative to the displacement), and it costs no more steps than the user's.
    assert options.n_steps * options.dt == pytest.approx(50 * 0.016, rel=1e-9)  # the same simulated time
    assert options.n_steps <= 50
    user_options = read_input_file('inputfile_rollers.dat')
    start = np.array(set_up(user_options).start_configuration.locations)
    horizon = options.n_steps * options.dt
    reference = run_for(user_options, options.dt / 16, horizon)
    recommended_run = run_for(options, options.dt, horizon)
    assert isinstance(recommended_run, np.ndarray), recommended_run
    displacement = np.max(np.linalg.norm(reference - start, axis=1))
    assert np.max(np.linalg.norm(recommended_run - reference, axis=1)) <= 0.01 * displacement


def run_for(options, dt, time):
    """Body locations after ``time`` at ``dt`` (the input's scheme), or the SimulationStopped raised."""
    system = set_up(options)
    scheme = make_scheme(options.scheme, dt, options)
    state = scheme.init(system, system.start_configuration)
    try:
        for _ in range(int(round(time / dt))):
            state = scheme.step(system, state, None)
    except utils.SimulationStopped as err:
        return err
    return np.array(state.configuration.locations)


def test_dt_of_the_dynamic_example_is_adequate_and_ten_times_it_is_not(tmp_path, monkeypatch):
    shutil.copy(os.path.join(MULTI_BODIES, 'inputfile_dynamic.dat'), str(tmp_path))
    shutil.copytree(os.path.join(MULTI_BODIES, 'Structures'), str(tmp_path / 'Structures'))
    monkeypatch.chdir(tmp_path)
    accuracy = 0.01
    result = advisor.advise('inputfile_dynamic.dat', accuracy=accuracy, quick=True)
    bound = result.dt_bound
    dt = bound['dt']
    assert bound['binds'] != 'stability' and dt < bound['bounds']['stability']
    options = read_input_file('inputfile_dynamic.dat')
    start = np.array(set_up(options).start_configuration.locations)
    horizon = 10 * dt
    reference = run_for(options, dt / 8, horizon)
    assert isinstance(reference, np.ndarray)
    displacement = np.max(np.linalg.norm(reference - start, axis=1))
    at_dt = run_for(options, dt, horizon)
    assert isinstance(at_dt, np.ndarray), 'the recommended dt stops the run: %s' % at_dt
    assert np.max(np.linalg.norm(at_dt - reference, axis=1)) <= accuracy * displacement
    # Negative control: ten times the recommendation stops (bodies through the wall) or misses the target.
    big = run_for(options, 10 * dt, horizon)
    if isinstance(big, np.ndarray):
        assert np.max(np.linalg.norm(big - reference, axis=1)) > accuracy * displacement
    else:
        assert 'wall' in str(big) or 'below' in str(big)


def test_recommendations_stay_within_the_program(tmp_path, monkeypatch):
    shutil.copytree(os.path.join(MULTI_BODIES, 'Structures'), str(tmp_path / 'Structures'))
    shutil.copy(os.path.join(MULTI_BODIES, 'inputfile_body_mobility.dat'), str(tmp_path))
    monkeypatch.chdir(tmp_path)
    static = advisor.advise('inputfile_body_mobility.dat', quick=True)
    assert static.program == 'static'
    assert 'mobility_vector_prod_implementation' not in static.recommendation
    assert 'scheme' not in static.recommendation
    # The Monte Carlo input: the sampler has no solver, backend or time step.
    mcmc_dir = tmp_path / 'mc'
    mcmc_dir.mkdir()
    text = open(os.path.join(REPO, 'many_bodyMCMC', 'inputMCMC.dat')).read().replace('../multi_bodies/', '../')
    (mcmc_dir / 'inputMCMC.dat').write_text(text)
    monkeypatch.chdir(mcmc_dir)
    mcmc = advisor.advise('inputMCMC.dat', quick=True)
    assert mcmc.program == 'mcmc'
    for key in mcmc.recommendation:
        assert key in ('mcmc_energy_implementation',), key
    assert parse_input_text(text, 'inputMCMC.dat', 'mcmc').scheme not in ('deterministic_forward_euler_dense_algebra',)


def test_script_shows_progress(tmp_path):
    name = one_sphere(str(tmp_path))
    run = subprocess.run([sys.executable, os.path.join(MULTI_BODIES, 'advise.py'), '--input-file', name, '--quick'],
                         capture_output=True, text=True, env=ENV, cwd=str(tmp_path))
    assert run.returncode == 0, run.stderr
    progress = [line for line in run.stderr.splitlines() if line.startswith('advise: [')]
    assert len(progress) >= 2 * 9
    assert 'check: holds' in run.stdout


class _Log:
    """Collects the lines a script logs (info and warning)."""

    def __init__(self):
        self.lines, self.warnings = [], []

    def info(self, text):
        self.lines.append(text)

    def warning(self, text):
        self.warnings.append(text)


def test_sphere_msd_quick_start_ends_at_end_and_samples_equilibrium(tmp_path):
    """The manual's quick start: lags end at -end, heights at the Gibbs-Boltzmann mean (3 standard errors).

    The standard error is that of the mean over the 8 independent spheres; the negative control starts them
    at H = 3.5 with a short burn-in (the published start), which must be warned about.
    """
    from sphere import sphere_rotational_msd as script
    log = _Log()
    stem = script.run(0.01, 2000, 1.0, runs=8, seed=1, data_dir=str(tmp_path), logger=log)
    times = np.loadtxt(stem + '.txt')[:, 0]
    assert times[-1] == pytest.approx(1.0, rel=1e-12) and times[0] == 0.0
    heights = np.loadtxt(stem + '.heights.txt')
    centres, exact = heights[:, 0], heights[:, 2]
    gibbs_mean = np.trapezoid(centres * exact, centres) / np.trapezoid(exact, centres)
    line = [x for x in log.lines if x.startswith('mean height')][0]
    sampled, error = float(line.split()[3]), float(line.split()[5])
    assert abs(sampled - gibbs_mean) <= 3 * error
    assert not [w for w in log.warnings if 'equilibrium' in w]
    late = _Log()
    script.run(0.01, 2000, 1.0, runs=8, seed=1, data_dir=str(tmp_path), data_name='late', logger=late,
               start_height=3.5)
    assert [w for w in late.warnings if 'not at equilibrium' in w]


def test_ensemble_of_a_deterministic_scheme_warns_that_replicas_are_identical(tmp_path, capsys):
    from multi_bodies.ensembles import ensemble_runner
    name = os.path.join(MULTI_BODIES, 'inputfile_dynamic.dat')
    ensemble_runner.build_plan(name, 2, master_seed=1, output_dir=str(tmp_path / 'ensemble'))
    assert 'replicas of each parameter point are identical' in capsys.readouterr().err
    # A stochastic scheme draws from the replica's seed: no warning.
    ensemble_runner.build_plan(name, 2, vary=[('scheme', ['stochastic_first_order_RFD'])], master_seed=1,
                               output_dir=str(tmp_path / 'ensemble2'))
    assert 'identical' not in capsys.readouterr().err
