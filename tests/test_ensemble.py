"""Ensembles on Dask (multi_bodies/ensemble.py, ensemble_runner, ensemble_statistics).

What is asserted comes from outside the code under test: the same replicas
run one after another in this process (bit-for-bit equality with the Dask
runs, undisturbed or with a worker killed in mid-task), the definition of
the seeds (numpy's SeedSequence), MSDs recomputed here from the raw
``.clones`` files, the rotational displacement of a known rotation
(sin θ about the axis), and the law of a random walk (MSD = 2 D τ per axis,
tolerance from the standard error across replicas, with a negative control).

The tests that start a cluster skip when dask.distributed is not installed
(``pip install -e '.[ensemble]'``).
"""
import importlib
import importlib.util
import io
import json
import os
import shutil
import textwrap

import numpy as np
import pytest

from multi_bodies.ensembles import ensemble_runner as runner
from multi_bodies.ensembles import ensemble_statistics as stats
from multi_bodies.run import run_output
from utils import UserInputError
from multi_bodies.files.snapshots import (read_clones_frame, read_clones_frames as read_clones_series,
                                          read_config_frames as read_config_series)

# The scheme of the test scene.  The stochastic schemes are not on main yet
# (kT and seed have no effect on a deterministic run); once they are, switch
# this one line to e.g. 'stochastic_adams_bashforth' and every test below
# checks the same equalities with replicas that differ by their seeds.
SCHEME = 'deterministic_adams_bashforth'

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCRIPT = importlib.import_module('multi_bodies.ensemble')
MASTER_SEED = 20261201
VARY = [('g', ['1', '2'])]  # 2 parameter points x 2 replicas = 4 replicas
REPLICAS = 2
KILL_TOKEN = 'kill_worker_token'

try:
    import distributed
except ImportError:
    distributed = None
needs_distributed = pytest.mark.skipif(distributed is None, reason="dask.distributed is not installed "
                                       "(pip install -e '.[ensemble]')")

# Called at every step.  In a Dask worker thread (never in the test process)
# the first run to reach its 4th step while the token file exists removes
# the token and kills its own worker process: a hard kill in mid-task, after
# the saves of steps 0 and 2.  Physics is untouched (preprocess does nothing).
USER_FUNCTIONS = '''
import os
import signal
import threading

_calls = [0]


def preprocess(bodies, **kwargs):
    _calls[0] += 1
    if _calls[0] != 4 or threading.current_thread() is threading.main_thread():
        return
    try:
        os.remove(os.path.join(os.path.dirname(os.path.abspath(__file__)), '%s'))
    except FileNotFoundError:
        return
    os.kill(os.getpid(), signal.SIGKILL)
''' % KILL_TOKEN


@pytest.fixture(scope='module')
def scene(tmp_path_factory):
    """Folder with two 12-blob spheres sedimenting at different heights; returns the input file path."""
    folder = tmp_path_factory.mktemp('scene')
    shutil.copy(os.path.join(REPO, 'multi_bodies', 'Structures', 'shell_N_12_Rg_1.vertex'), folder)
    (folder / 'spheres.clones').write_text('2\n0 0 3 1 0 0 0\n4 1 2.5 0.8 0.6 0 0\n')
    (folder / 'user_defined_functions.py').write_text(USER_FUNCTIONS)
    (folder / 'input.dat').write_text(textwrap.dedent('''\
        scheme %s
        mobility_blobs_implementation python
        mobility_vector_prod_implementation python
        blob_blob_force_implementation python
        dt 0.05
        n_steps 10
        n_save 2
        kT 1.0
        eta 1.0
        blob_radius 0.25
        output_name data/run
        structure shell_N_12_Rg_1.vertex spheres.clones
        ''' % SCHEME))
    return str(folder / 'input.dat')


@pytest.fixture(scope='module')
def serial(scene, tmp_path_factory):
    """The ensemble run one replica after another in this process: (plan, results)."""
    plan = runner.build_plan(scene, REPLICAS, VARY, str(tmp_path_factory.mktemp('serial')), MASTER_SEED)
    runner.write_plan(plan)
    results = runner.run_serially(plan, stream=io.StringIO())
    assert [r['status'] for r in results] == ['done'] * 4
    return plan, results


@pytest.fixture(scope='module')
def client():
    if distributed is None:
        pytest.skip("dask.distributed is not installed (pip install -e '.[ensemble]')")
    cluster = runner.make_local_cluster(2, omp_threads=1, retries=3, dashboard_address=None)
    dask_client = distributed.Client(cluster)
    yield dask_client
    dask_client.close()
    cluster.close()


def output_files(plan):
    """folder -> {name: bytes} of the snapshots and .info of every replica (what the statistics read)."""
    files = {}
    for replica in plan['replicas']:
        folder = os.path.join(plan['output_dir'], replica['folder'])
        files[replica['folder']] = {name: open(os.path.join(folder, name), 'rb').read()
                                    for name in sorted(os.listdir(folder))
                                    if name.endswith(('.clones', '.config', '.info'))}
    return files


def statistics_text(plan):
    stats.aggregate(plan['output_dir'], charts=False, log=lambda *a: None)
    texts = {name: open(os.path.join(plan['output_dir'], name, 'statistics.csv')).read()
             for name in (point['name'] for point in plan['points'])}
    texts['summary'] = open(os.path.join(plan['output_dir'], 'summary.csv')).read()
    return texts


# ------------------------------------------------------------------ seeds and manifest
def test_seeds_distinct_reproducible_and_recorded(serial, scene, tmp_path):
    plan, _ = serial
    seeds = [r['seed'] for r in plan['replicas']]
    assert len(set(seeds)) == len(seeds) == 4
    expected = [int(child.generate_state(1, dtype=np.uint64)[0])
                for point in np.random.SeedSequence(MASTER_SEED).spawn(2) for child in point.spawn(REPLICAS)]
    assert seeds == expected
    again = runner.build_plan(scene, REPLICAS, VARY, str(tmp_path / 'again'), MASTER_SEED)
    assert [r['seed'] for r in again['replicas']] == seeds
    other = runner.build_plan(scene, REPLICAS, VARY, str(tmp_path / 'other'), MASTER_SEED + 1)
    assert not set(r['seed'] for r in other['replicas']) & set(seeds)
    manifest = json.load(open(os.path.join(plan['output_dir'], runner.MANIFEST_NAME)))
    assert manifest['master_seed'] == MASTER_SEED
    assert [r['seed'] for r in manifest['replicas']] == seeds
    assert [r['spawn_key'] for r in manifest['replicas']] == [[0, 0], [0, 1], [1, 0], [1, 1]]
    for replica in plan['replicas']:
        folder = os.path.join(plan['output_dir'], replica['folder'])
        assert 'seed %d\n' % replica['seed'] in open(os.path.join(folder, 'input.dat')).read()
        # the seed reached the run: its generator starts where default_rng(seed) starts
        state = run_output.read_random_state(os.path.join(folder, 'run.random_state'))
        assert state == np.random.default_rng(replica['seed']).bit_generator.state


def test_more_replicas_keep_the_earlier_seeds(scene, tmp_path):
    two = runner.build_plan(scene, 2, VARY, str(tmp_path / 'a'), MASTER_SEED)
    three = runner.build_plan(scene, 3, VARY, str(tmp_path / 'a'), MASTER_SEED)
    by_folder = {r['folder']: r['seed'] for r in three['replicas']}
    assert all(by_folder[r['folder']] == r['seed'] for r in two['replicas'])


def test_vary_errors_name_the_option():
    with pytest.raises(UserInputError, match="unknown option 'kt'.*did you mean 'kT'"):
        runner.parse_vary(['kt=1,2'])
    with pytest.raises(UserInputError, match='seed is set by the ensemble'):
        runner.parse_vary(['seed=1,2'])
    with pytest.raises(UserInputError, match='NAME=V1,V2'):
        runner.parse_vary(['dt=0.1,,0.2'])
    assert runner.parse_vary(['kT=0.5,1', 'dt=0.01']) == [('kT', ['0.5', '1']), ('dt', ['0.01'])]


def test_linked_options_change_together(scene, tmp_path):
    """``--vary dt:n_steps=...`` gives one point per pair (not the 2 x 2 grid), and each replica's input sets both."""
    vary = runner.parse_vary(['dt:n_steps=0.01:40,0.02:20'])
    assert vary == [('dt:n_steps', ['0.01:40', '0.02:20'])]
    plan = runner.build_plan(scene, 1, vary, str(tmp_path / 'linked'), MASTER_SEED)
    assert [point['overrides'] for point in plan['points']] == [[['dt', '0.01'], ['n_steps', '40']],
                                                                [['dt', '0.02'], ['n_steps', '20']]]
    text = plan['_inputs']['dt-0.02_n_steps-20/r0000']
    from multi_bodies.files.input_options import parse_input_text
    options = parse_input_text(text, 'replica')
    assert (options.dt, options.n_steps) == (0.02, 20)
    with pytest.raises(UserInputError, match="has 1 part"):
        runner.parse_vary(['dt:n_steps=0.01:40,0.02'])
    with pytest.raises(UserInputError, match='n_steps is varied twice'):
        runner.parse_vary(['dt:n_steps=0.01:40', 'n_steps=10'])


def test_other_ensemble_in_the_same_folder_is_refused(serial, scene):
    plan, _ = serial
    other = runner.build_plan(scene, REPLICAS, VARY, plan['output_dir'], MASTER_SEED + 1)
    with pytest.raises(UserInputError, match='another ensemble'):
        runner.write_plan(other)


def test_without_distributed_the_message_names_the_extra(monkeypatch):
    import sys
    monkeypatch.setitem(sys.modules, 'distributed', None)
    with pytest.raises(UserInputError, match=r"\.\[ensemble\]"):
        runner.require_distributed()


# ------------------------------------------------------------------ statistics against independent numbers
def test_statistics_match_the_raw_snapshots(serial):
    plan, _ = serial
    statistics = stats.aggregate(plan['output_dir'], charts=False, log=lambda *a: None)
    point = statistics['g-2']
    assert point['replicas'] == 2
    # recompute the lag-1 and lag-2 MSD normal to the wall from the files, here
    per_replica = []
    for replica in plan['replicas'][2:]:
        folder = os.path.join(plan['output_dir'], replica['folder'])
        names = sorted(n for n in os.listdir(folder) if n.startswith('run.spheres.') and n.endswith('.clones'))
        z = np.array([np.loadtxt(os.path.join(folder, n), skiprows=1)[:, 2] for n in names])
        assert len(names) == 6  # steps 0, 2, ..., 10
        per_replica.append([np.mean((z[lag:] - z[:-lag]) ** 2) for lag in (1, 2)])
    mean, _ = point['msd']['spheres']['msd_z']
    np.testing.assert_allclose(mean[:2], np.mean(per_replica, axis=0), rtol=1e-13)
    np.testing.assert_allclose(point['msd']['spheres']['lag_time'][:2], [0.1, 0.2])
    # heavier spheres fall faster: the two points differ (the comparisons below are not of equal files)
    assert statistics['g-2']['msd']['spheres']['msd_z'][0][0] > 3 * statistics['g-1']['msd']['spheres']['msd_z'][0][0]
    edges, density, _ = point['height']['spheres']
    assert np.sum(density * np.diff(edges)) == pytest.approx(1.0, rel=1e-12)
    assert point['info']['invalid_configuration_count'][0] == 0


def test_rotational_displacement_of_a_known_rotation():
    theta = np.array([0.1, 0.7, 2.0])
    axis = np.array([1.0, 2.0, 2.0]) / 3.0
    frames = np.zeros((2, 3, 7))
    frames[0, :, 3] = 1.0
    frames[1, :, 3] = np.cos(theta / 2)
    frames[1, :, 4:] = np.sin(theta / 2)[:, None] * axis
    msd = stats.mean_square_displacements(frames, 1)
    assert msd['msd_orientation'][0] == pytest.approx(np.mean(np.sin(theta) ** 2), rel=1e-12)
    assert msd['msd_location'][0] == 0.0


def test_error_bars_of_a_random_walk(serial, tmp_path):
    """Replicas of an exact random walk: the mean MSD is 2 D tau per axis within 4 standard errors.

    Negative control: the law with D 20 % off is more than 4 standard errors away.
    """
    plan, _ = serial
    walk_dir = tmp_path / 'walk'
    shutil.copytree(plan['output_dir'], walk_dir)
    manifest = runner.read_manifest(str(walk_dir))
    rng = np.random.default_rng(5)
    diffusion, dt_save, frames_count = 0.3, 0.1, 40
    for replica in manifest['replicas']:
        folder = walk_dir / replica['folder']
        steps = rng.normal(0, np.sqrt(2 * diffusion * dt_save), size=(frames_count - 1, 50, 3))
        path = np.concatenate((np.zeros((1, 50, 3)), np.cumsum(steps, axis=0))) + [0, 0, 10]
        for name in os.listdir(folder):
            if name.endswith('.clones'):
                os.remove(folder / name)
        for frame in range(frames_count):
            text = run_output.format_clones(path[frame], np.tile([1.0, 0, 0, 0], (50, 1)))
            (folder / run_output.clones_name('run', 'spheres', 2 * frame)).write_text(text)
    statistics = stats.aggregate(str(walk_dir), charts=False, max_lag=5, log=lambda *a: None)
    for point in statistics.values():
        entry = point['msd']['spheres']
        mean, error = entry['msd_z']
        z_scores = (mean - 2 * diffusion * entry['lag_time']) / error
        assert np.all(np.abs(z_scores) < 4), z_scores
        wrong = (mean - 2 * 1.2 * diffusion * entry['lag_time']) / error
        assert np.any(np.abs(wrong) > 4), wrong


def test_error_bars_of_planted_replicas(serial, tmp_path):
    """Planted replica outputs with a known mean and standard error of the MSD.

    Every replica saves the same random walk B scaled by its own factor s (1 for the first replica of a
    point, 2 for the second), so its MSD is exactly s^2 MSD_B (MSD_B computed here from the walk): the
    mean over the two replicas is 2.5 MSD_B and the standard error std(ddof=1)/sqrt(R) is
    |4 - 1| / sqrt(2) / sqrt(2) = 1.5 MSD_B.  A wrong formula (ddof 0, 1/R, no square root) is off by a
    factor sqrt(2) or more.
    """
    plan, _ = serial
    walk_dir = tmp_path / 'planted'
    shutil.copytree(plan['output_dir'], walk_dir)
    manifest = runner.read_manifest(str(walk_dir))
    rng = np.random.default_rng(7)
    frames_count, max_lag = 30, 4
    base = np.concatenate((np.zeros((1, 20, 3)), np.cumsum(rng.normal(0, 0.3, (frames_count - 1, 20, 3)), axis=0)))
    scale_of = {}
    for replica in manifest['replicas']:
        scale = 1.0 + sum(1 for r in manifest['replicas'] if r['point'] == replica['point'] and r['folder'] in scale_of)
        scale_of[replica['folder']] = scale
        folder = walk_dir / replica['folder']
        for name in os.listdir(folder):
            if name.endswith('.clones'):
                os.remove(folder / name)
        for frame in range(frames_count):
            text = run_output.format_clones(scale * base[frame] + [0, 0, 10], np.tile([1.0, 0, 0, 0], (20, 1)))
            (folder / run_output.clones_name('run', 'spheres', 2 * frame)).write_text(text)
    assert sorted(scale_of.values()) == [1.0, 1.0, 2.0, 2.0]
    msd_base = {'msd_z': [], 'msd_xy': []}
    for lag in range(1, max_lag + 1):
        d = base[lag:] - base[:-lag]
        msd_base['msd_z'].append(np.mean(d[..., 2] ** 2))
        msd_base['msd_xy'].append(np.mean(d[..., 0] ** 2 + d[..., 1] ** 2))
    statistics = stats.aggregate(str(walk_dir), charts=False, max_lag=max_lag, log=lambda *a: None)
    assert len(statistics) == 2
    for point in statistics.values():
        assert point['replicas'] == 2
        for quantity, values in msd_base.items():
            mean, error = point['msd']['spheres'][quantity]
            np.testing.assert_allclose(mean, 2.5 * np.array(values), rtol=1e-9)
            np.testing.assert_allclose(error, 1.5 * np.array(values), rtol=1e-9)


def test_clones_readers(tmp_path):
    output = str(tmp_path / 'run')
    frames = np.random.default_rng(1).normal(size=(3, 2, 7))
    for step, frame in zip((0, 5, 10), frames):
        (tmp_path / run_output.clones_name('run', 'rod.a', step)).write_text(
            run_output.format_clones(frame[:, :3], frame[:, 3:]))
    steps, read = read_clones_series(output, 'rod.a')
    assert list(steps) == [0, 5, 10]
    np.testing.assert_array_equal(read, frames)  # repr precision round-trips
    config = tmp_path / 'run.rod.a.config'
    config.write_text(''.join(run_output.format_clones(f[:, :3], f[:, 3:]) for f in frames) + '2\n1 2 3\n')
    np.testing.assert_array_equal(read_config_series(str(config)), frames)  # cut last snapshot dropped
    (tmp_path / 'c.clones').write_text('# comment\n1\n1 2 3 1 0 0 0\n')
    np.testing.assert_array_equal(read_clones_frame(str(tmp_path / 'c.clones')), [[1, 2, 3, 1, 0, 0, 0]])


# ------------------------------------------------------------------ resuming a killed replica
# A resumed replica continues from its last saved step through initial_step,
# and the restart record holds the generator, the scheme history, the solver's
# initial guess and the exact configuration, so the resumed run is bit for bit
# the undisturbed one.  (RESUME_TOLERANCE is kept for compare_resumed(exact=False).)
SOLVER_TOLERANCE = 1e-8  # the default solver_tolerance of the scene
# A relative GMRES error e in the velocities moves a body by at most about
# e x (its whole path, < 1 here) over the run; 10 x that bound.
RESUME_TOLERANCE = 10 * SOLVER_TOLERANCE


def compare_resumed(folder, reference, resumed_from, exact=True):
    """Snapshots of a resumed replica against the undisturbed one (bit for bit before ``resumed_from``)."""
    names = sorted(n for n in os.listdir(reference) if n.endswith('.clones'))
    assert names == sorted(n for n in os.listdir(folder) if n.endswith('.clones'))
    for name in names:
        ours, theirs = open(os.path.join(folder, name), 'rb').read(), open(os.path.join(reference, name), 'rb').read()
        if exact or int(name.split('.')[-2]) < resumed_from:
            assert ours == theirs, name
        else:
            np.testing.assert_allclose(read_clones_frame(os.path.join(folder, name)),
                                       read_clones_frame(os.path.join(reference, name)),
                                       rtol=0, atol=RESUME_TOLERANCE, err_msg=name)
    if exact:
        assert open(os.path.join(folder, 'run.info')).read() == open(os.path.join(reference, 'run.info')).read()


def cut_replica(plan, tmp_path):
    """A copy of a finished replica as a hard kill while appending the record of step 6 leaves it; resumed."""
    copy = tmp_path / 'cut'
    shutil.copytree(plan['output_dir'], copy)
    manifest = runner.read_manifest(str(copy))
    spec = runner.replica_specs(manifest)[3]
    folder = copy / spec['folder']
    # the replica's input names the original output folder: point it at the copy
    text = (folder / 'input.dat').read_text().replace(plan['output_dir'], str(copy))
    (folder / 'input.dat').write_text(text)
    spec['input_sha256'] = runner._sha256(text)
    restart = folder / 'run.restart'
    data = restart.read_bytes()
    ends = [end for _, _, end in run_output.restart_index(str(restart))]
    restart.write_bytes(data[:ends[2] + (ends[3] - ends[2]) // 2])  # records of steps 0, 2, 4 and half of 6
    for step in (6, 8, 10):
        os.remove(folder / run_output.clones_name('run', 'spheres', step))
    os.remove(folder / 'status.json')
    result = runner.run_replica(spec)
    return result, str(folder), os.path.join(plan['output_dir'], spec['folder'])


def test_resume_after_a_cut_restart_record(serial, tmp_path):
    """A replica killed while appending a record resumes from the last complete one and ends as undisturbed."""
    result, folder, reference = cut_replica(serial[0], tmp_path)
    assert result['status'] == 'done' and result['resumed_from'] == 4
    compare_resumed(folder, reference, 4)
    assert [r['step'] for r in run_output.read_restart_records(os.path.join(folder, 'run'))] == [0, 2, 4, 4, 6, 8, 10]


def test_resume_is_bit_for_bit(serial, tmp_path):
    result, folder, reference = cut_replica(serial[0], tmp_path)
    compare_resumed(folder, reference, 4, exact=True)


# ------------------------------------------------------------------ on a real LocalCluster
@needs_distributed
def test_cluster_equals_serial_bit_for_bit(serial, scene, client, tmp_path):
    plan_serial, _ = serial
    plan = runner.build_plan(scene, REPLICAS, VARY, str(tmp_path / 'parallel'), MASTER_SEED)
    runner.write_plan(plan)
    stream = io.StringIO()
    results = runner.run_on_client(plan, client, stream=stream)
    assert sorted(r['status'] for r in results) == ['done'] * 4
    assert all(r['pid'] != os.getpid() for r in results)  # run by the worker processes
    assert output_files(plan) == output_files(plan_serial)
    assert statistics_text(plan) == statistics_text(plan_serial)
    assert '4 of 4 replicas done, 0 failed' in stream.getvalue()
    # a rerun skips them all
    again = runner.run_on_client(plan, client, stream=io.StringIO())
    assert again == [] and runner.split_finished(plan) == ([], 4)


@needs_distributed
def test_killed_worker_task_is_retried_from_its_last_save(serial, scene, client, tmp_path):
    plan_serial, _ = serial
    plan = runner.build_plan(scene, REPLICAS, VARY, str(tmp_path / 'killed'), MASTER_SEED)
    runner.write_plan(plan)
    token = os.path.join(os.path.dirname(scene), KILL_TOKEN)
    open(token, 'w').close()
    try:
        results = runner.run_on_client(plan, client, stream=io.StringIO())
        assert not os.path.exists(token), 'no worker was killed: the test did not test the retry'
    finally:
        if os.path.exists(token):
            os.remove(token)
    assert sorted(r['status'] for r in results) == ['done'] * 4
    resumed = [r for r in results if r['resumed_from']]
    assert len(resumed) == 1 and resumed[0]['resumed_from'] == 2
    killed = resumed[0]['folder']
    folder = os.path.join(plan['output_dir'], killed)
    # the killed attempt never reached its .time line; the resumed one says where it started
    assert open(os.path.join(folder, 'run.time')).read().splitlines()[-1].endswith('restart segment, steps 2 to 10')
    ours, theirs = output_files(plan), output_files(plan_serial)
    assert {k: v for k, v in ours.items() if k != killed} == {k: v for k, v in theirs.items() if k != killed}
    compare_resumed(folder, os.path.join(plan_serial['output_dir'], killed), 2)


@needs_distributed
def test_failing_replica_is_reported_and_the_others_complete(scene, client, tmp_path, capsys):
    output_dir = str(tmp_path / 'failing')
    status = SCRIPT.main(['--input-file', scene, '--replicas', '1', '--vary', 'n_save=2,0',
                          '--scheduler', client.scheduler.address, '--output-dir', output_dir,
                          '--seed', str(MASTER_SEED)])
    assert status == 1
    out = capsys.readouterr().out
    bad = os.path.join(output_dir, 'n_save-0', 'r0000')
    assert '1 replicas did not finish' in out
    assert '%s: failed: ' % bad in out and 'n_save must be at least 1' in out
    assert json.load(open(os.path.join(bad, 'status.json')))['status'] == 'failed'
    good = runner.read_status(os.path.join(output_dir, 'n_save-2', 'r0000'))
    assert good['status'] == 'done'
    assert os.path.isfile(os.path.join(output_dir, 'n_save-2', 'r0000', 'run.spheres.00000010.clones'))
    # aggregation uses the finished replica and says which it left out
    lines = []
    statistics = stats.aggregate(output_dir, charts=True, log=lines.append)
    assert list(statistics) == ['n_save-2'] and any('n_save-0/r0000 (failed)' in line for line in lines)
    assert os.path.getsize(os.path.join(output_dir, 'msd.png')) > 1000


@needs_distributed
@pytest.mark.skipif(importlib.util.find_spec('dask_jobqueue') is None, reason='dask-jobqueue is not installed')
def test_slurm_job_script_has_one_thread_per_worker():
    cluster = runner.make_jobqueue_cluster('slurm', 0, dashboard_address=None, cores=8, memory='16GB',
                                           walltime='01:00:00', omp_threads=2, queue='short',
                                           extra_directives=['--constraint=cpu'])
    try:
        script = cluster.job_script()
    finally:
        cluster.close()
    assert '#SBATCH --cpus-per-task=8' in script and '#SBATCH -p short' in script
    assert '#SBATCH --constraint=cpu' in script and 'export OMP_NUM_THREADS=2' in script
    assert '--nworkers 4' in script and '--nthreads 1' in script


def test_one_file_series_give_the_same_statistics(scene, tmp_path, capsys):
    """save_clones one_file (.config series) and one_file_per_step (.clones files) of one run aggregate alike;
    the command line without Dask (--workers 0) runs them, and a rerun skips both."""
    output_dir = str(tmp_path / 'storage')
    argv = ['--input-file', scene, '--replicas', '1', '--vary', 'save_clones=one_file_per_step,one_file',
            '--workers', '0', '--output-dir', output_dir, '--seed', str(MASTER_SEED)]
    assert SCRIPT.main(argv) == 0
    assert os.path.isfile(os.path.join(output_dir, 'save_clones-one_file', 'r0000', 'run.spheres.config'))
    statistics = stats.aggregate(output_dir, charts=False, log=lambda *a: None)
    per_step, one_file = statistics['save_clones-one_file_per_step'], statistics['save_clones-one_file']
    for quantity in stats.MSD_QUANTITIES:
        np.testing.assert_array_equal(per_step['msd']['spheres'][quantity][0], one_file['msd']['spheres'][quantity][0])
    np.testing.assert_array_equal(per_step['height']['spheres'][1], one_file['height']['spheres'][1])
    capsys.readouterr()
    assert SCRIPT.main(argv) == 0
    assert 'nothing to run (2 replicas finished before, skipped)' in capsys.readouterr().out


def test_two_drivers_never_share_a_folder(tmp_path):
    folder = str(tmp_path / 'locked')
    with runner.ensemble_lock(folder) as path:
        with pytest.raises(UserInputError, match='another ensemble.py .* is running in this folder'):
            with runner.ensemble_lock(folder):
                pass
    assert not os.path.exists(path)
    # a lock left by a process of this host that has gone is taken over
    import socket
    import subprocess
    import sys
    gone = subprocess.run([sys.executable, '-c', 'import os; print(os.getpid())'], capture_output=True, text=True)
    with open(path, 'w') as f:
        json.dump({'host': socket.gethostname(), 'pid': int(gone.stdout)}, f)
    with runner.ensemble_lock(folder):
        assert json.load(open(path))['pid'] == os.getpid()
