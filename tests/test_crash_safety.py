"""No lost or mixed frames; restarts exact or refused (issue 17).

The crash test kills small runs of 19 kinds (``CHAIN_KINDS``: dynamic runs of the deterministic, Brownian,
roller, articulated, obstacle and dense schemes, a phoretic run with its ``.concentration`` file, a slip-length
surface, VTK output, Monte Carlo, an ensemble replica; both ``save_clones`` modes) with SIGKILL, SIGTERM and SIGINT at moments drawn from a
fixed seed, including between a snapshot and its record (the test hook
``RMB_TEST_KILL_BETWEEN_SNAPSHOT_AND_RECORD=<step>`` makes the writer SIGKILL
itself there).  Each chain is continued as a user would (``initial_step`` =
the step the stop message names, or the last complete snapshot and record
after SIGKILL; the ensemble runner resumes by itself) and compared with the
uninterrupted run: every continuation equals it bit for bit (snapshots and
counters) or was refused with a message.  Law: a deterministic program with
the same state gives the same bytes.

The CI version runs ``CHAINS`` chains, one of each kind of scene (about a minute).  The longer run::

    RMB_CRASH_CHAINS=200 PYTHONPATH=. OMP_NUM_THREADS=1 python3 -m pytest -q -p no:cacheprovider \
        tests/test_crash_safety.py -k crash_chains -s

prints the counts (chains, signals, exact, refused, lost) at the end.

The crash test's findings (a cut record, a lone snapshot, file-size limits, signals, a slow step stopped
at once, the ``.concentration`` file kept like the snapshots) have a test each below.  One writer per
output name is tested in ``test_run_locks.py``, resource bounds and other one-line refusals in
``test_resources_and_refusals.py``; the scenes are in ``safety_scenes.py``.
"""
import os
import resource
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from multi_bodies.ensembles import ensemble_runner as runner  # noqa: E402
from multi_bodies.files.snapshots import read_config_frames  # noqa: E402
from multi_bodies.run import run_loop, run_output  # noqa: E402
from run_scenes import REPO_ROOT, child_environment, set_options  # noqa: E402
from safety_scenes import (DYNAMIC, MCMC, dynamic_scene, edit, last_pair_step, mcmc_scene, outputs,  # noqa: E402
                           phoretic_scene, run, snapshot_tree, start, wait_for_record)

CHAINS = int(os.environ.get('RMB_CRASH_CHAINS', '19'))


# ------------------------------------------------------------------ the crash test
# The kinds of scene the chains cycle through (issue 48: every kind of state a record carries): Brownian
# Adams-Bashforth, Monte Carlo, an ensemble replica, a phoretic run with .concentration, an articulated chain,
# a slip and a prescribed velocity, rollers, VTK output, a slip-length surface, the midpoint scheme.
CHAIN_KINDS = ('dynamic', 'mcmc', 'replica', 'phoretic', 'articulated', 'driven', 'rollers', 'vtk', 'slip_length',
               'midpoint', 'obstacle', 'stochastic_first_order_RFD', 'Fixman', 'stochastic_traction_AB',
               'stochastic_Slip_Mid', 'stochastic_GDC_RFD', 'stochastic_trapezoidal_rollers',
               'articulated_deterministic_midpoint', 'deterministic_forward_euler_dense_algebra')


def obstacle_scene(folder, **options):
    """A free one-blob body with an active slip beside an obstacle (deterministic Adams-Bashforth)."""
    from safety_scenes import driven_scene
    folder = driven_scene(folder, scheme='deterministic_adams_bashforth', kT=0, **options)
    text = (folder / 'input.dat').read_text().replace('structure blob.vertex b.clones None b.velocity',
                                                      'obstacle blob.vertex b.clones')
    (folder / 'input.dat').write_text(text)
    return folder


def chain_scene(program):
    """(scene maker (folder, n_steps, n_save, save_clones), script, structure IDs) of a kind of chain."""
    from safety_scenes import articulated_scene, driven_scene, surface_scene
    return {'dynamic': (dynamic_scene, DYNAMIC, ('a', 'b')),
            'mcmc': (mcmc_scene, MCMC, ('a',)),
            'phoretic': (phoretic_scene, DYNAMIC, ('a',)),
            'articulated': (articulated_scene, DYNAMIC, ('chain',)),
            'driven': (driven_scene, DYNAMIC, ('a', 'b')),
            'rollers': (lambda folder, **o: dynamic_scene(folder, scheme='stochastic_adams_bashforth_rollers', **o),
                        DYNAMIC, ('a', 'b')),
            'vtk': (lambda folder, **o: dynamic_scene(folder, save_vtk=True, **o), DYNAMIC, ('a', 'b')),
            'slip_length': (lambda folder, **o: surface_scene(folder, 'slip_length', **o), DYNAMIC, ('a',)),
            'midpoint': (lambda folder, **o: dynamic_scene(folder, scheme='deterministic_midpoint', kT=0, **o),
                         DYNAMIC, ('a', 'b')),
            'obstacle': (obstacle_scene, DYNAMIC, ('a', 'b')),
            'articulated_deterministic_midpoint': (lambda folder, **o: articulated_scene(
                folder, scheme='articulated_deterministic_midpoint', **o), DYNAMIC, ('chain',))}.get(
        program, (lambda folder, **o: dynamic_scene(folder, scheme=program, **o), DYNAMIC, ('a', 'b')))


def one_chain(tmp_path, rng, index, counts):
    """One chain: a run killed at a drawn moment, continued, compared with the uninterrupted run."""
    how = ['SIGKILL', 'SIGTERM', 'SIGINT', 'between'][int(rng.integers(4))]
    program = CHAIN_KINDS[index % len(CHAIN_KINDS)]
    if program == 'replica':
        return replica_chain(tmp_path, rng, index, counts, how)
    save_clones = ['one_file_per_step', 'one_file'][(index // len(CHAIN_KINDS)) % 2]
    scene, script, ids = chain_scene(program)
    n_steps, n_save = (4000, 40) if program == 'mcmc' else (40, 4)
    reference = scene(tmp_path / ('reference_%d' % index), n_steps=n_steps, n_save=n_save, save_clones=save_clones)
    assert run(script, reference)[0] == 0
    folder = scene(tmp_path / ('chain_%d' % index), n_steps=n_steps, n_save=n_save, save_clones=save_clones)
    moment = n_save * int(rng.integers(1, n_steps // n_save - 1))
    counts['chains'] += 1
    if how == 'between':
        status, _, _ = run(script, folder, {run_output.KILL_HOOK: str(moment)})
        assert status == -signal.SIGKILL
        # the lone snapshot of `moment` must be refused, the last complete pair taken
        edit(folder, initial_step=moment)
        status, _, err = run(script, folder)
        assert status == 2 and 'record of step %d' % moment in err and 'Traceback' not in err, err
        counts['refused'] += 1
        restart = last_pair_step(folder, save_clones, ids)
    else:
        process = start(script, folder)
        interrupted = wait_for_record(process, folder, moment)
        if interrupted:
            process.send_signal(getattr(signal, how))
        out, err = process.communicate(timeout=120)
        if process.returncode == 0:  # it finished before the signal came
            restart = None
            counts['finished first'] += 1
        elif how == 'SIGKILL':
            restart = last_pair_step(folder, save_clones, ids)
        else:
            assert process.returncode == {'SIGTERM': 143, 'SIGINT': 130}[how], err
            assert 'Traceback' not in err, err
            restart = int(err.rsplit('restart with initial_step', 1)[1].split()[0])
    counts['signals'] += 1
    if restart is not None:
        edit(folder, initial_step=restart)
        status, out, err = run(script, folder)
        if status == 2:
            counts['refused'] += 1
            return
        assert status == 0, err
    ours, theirs = outputs(folder, program == 'mcmc'), outputs(reference, program == 'mcmc')
    if ours == theirs:
        counts['exact'] += 1
    else:
        counts['lost'] += 1
        different = sorted(k for k in set(ours) | set(theirs) if ours.get(k) != theirs.get(k))
        pytest.fail('chain %d (%s, %s, %s at %d, restart %s): %s differ' % (index, program, save_clones, how,
                                                                         moment, restart, different))


def replica_outputs(spec):
    folder = Path(spec['path'])
    found = {p.name: p.read_bytes() for p in folder.iterdir() if p.suffix in ('.clones', '.config')}
    found['info'] = b'\n'.join((folder / 'run.info').read_bytes().splitlines()[:3])
    return found


def replica_chain(tmp_path, rng, index, counts, how):
    """A replica killed (child process) at a drawn moment; the runner resumes it by itself."""
    save_clones = ['one_file_per_step', 'one_file'][(index // len(CHAIN_KINDS)) % 2]
    reference = replica_scene(tmp_path / ('reference_%d' % index), save_clones, n_steps=40, n_save=4)
    assert runner.run_replica(reference)['status'] == 'done'
    killed = replica_scene(tmp_path / ('chain_%d' % index), save_clones, n_steps=40, n_save=4)
    moment = 4 * int(rng.integers(1, 9))
    code = ('import sys; sys.path.insert(0, %r); from multi_bodies.ensembles import ensemble_runner as r; '
            'r.run_replica(%r)' % (str(REPO_ROOT), killed))
    environment = child_environment()
    if how == 'between':
        environment[run_output.KILL_HOOK] = str(moment)
    process = subprocess.Popen([sys.executable, '-c', code], env=environment, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
    if how != 'between' and wait_for_record(process, None, moment, path=Path(killed['path']) / 'run.restart'):
        process.send_signal(getattr(signal, how))
    out, err = process.communicate(timeout=120)
    assert 'Traceback' not in err, err
    counts['chains'] += 1
    counts['signals'] += 1
    result = runner.run_replica(killed)
    assert result['status'] == 'done', result
    if replica_outputs(killed) == replica_outputs(reference):
        counts['exact'] += 1
    else:
        counts['lost'] += 1
        pytest.fail('replica chain %d (%s, %s at %d) differs' % (index, save_clones, how, moment))


def test_crash_chains(tmp_path):
    """CHAINS chains (fixed seed): each continuation equals the uninterrupted run bit for bit or was refused."""
    rng = np.random.default_rng(17)
    counts = {'chains': 0, 'signals': 0, 'exact': 0, 'refused': 0, 'lost': 0, 'finished first': 0}
    for index in range(CHAINS):
        one_chain(tmp_path, rng, index, counts)
    print('crash test:', counts)
    assert counts['lost'] == 0 and counts['exact'] == counts['chains']


def replica_scene(tmp_path, save_clones, n_steps=12, n_save=2):
    folder = tmp_path / 'scene'
    dynamic_scene(folder, n_steps=n_steps, n_save=n_save, save_clones=save_clones, output_name='data/run')
    plan = runner.build_plan(str(folder / 'input.dat'), 1, (), str(tmp_path / 'ensemble'), 7)
    runner.write_plan(plan)
    return runner.replica_specs(plan)[0]


@pytest.mark.parametrize('save_clones', ['one_file_per_step', 'one_file'])
def test_ensemble_replica_killed_between_snapshot_and_record_resumes_exactly(tmp_path, save_clones):
    """L1 and W1 for a replica: killed after snapshot 6 and before its record; the resume uses step 4 and
    ends as the undisturbed replica (before: IndexError with one_file, a frame cut per attempt)."""
    spec = replica_scene(tmp_path / 'ref', save_clones)
    assert runner.run_replica(spec)['status'] == 'done'
    killed = replica_scene(tmp_path / 'killed', save_clones)
    code = ('import sys; sys.path.insert(0, %r); from multi_bodies.ensembles import ensemble_runner as r; '
            'r.run_replica(%r)' % (str(REPO_ROOT), killed))
    environment = child_environment()
    environment[run_output.KILL_HOOK] = '6'
    process = subprocess.run([sys.executable, '-c', code], env=environment, capture_output=True, text=True,
                             timeout=120)
    assert process.returncode == -signal.SIGKILL, process.stderr
    for attempt in range(2):  # a second attempt after a success changes nothing
        result = runner.run_replica(killed)
        assert result['status'] == 'done', result
    assert result['skipped']
    log = Path(killed['path'], runner.LOG_NAME).read_text()
    assert 'last complete snapshot and record is step 4' in log
    mine = {p.name: p.read_bytes() for p in Path(killed['path']).iterdir() if p.suffix in ('.clones', '.config')}
    ref = {p.name: p.read_bytes() for p in Path(spec['path']).iterdir() if p.suffix in ('.clones', '.config')}
    assert mine == ref


# ------------------------------------------------------------------ one test per finding
def test_L2_nothing_to_do_keeps_every_frame(tmp_path):
    folder = dynamic_scene(tmp_path / 'run', n_steps=10, n_save=1, save_clones='one_file')
    assert run(DYNAMIC, folder)[0] == 0
    before = outputs(folder)
    assert read_config_frames(str(folder / 'data' / 'run.a.config')).shape[0] == 11
    edit(folder, initial_step=10)
    status, out, err = run(DYNAMIC, folder)
    assert status == 0 and 'nothing to do' in out, err
    assert read_config_frames(str(folder / 'data' / 'run.a.config')).shape[0] == 11
    assert outputs(folder) == before


def test_L3_a_cut_record_is_set_aside_before_later_appends(tmp_path):
    folder = dynamic_scene(tmp_path / 'run', n_steps=12, n_save=4)
    assert run(DYNAMIC, folder)[0] == 0
    path = folder / 'data' / 'run.restart'
    _, start_, end = run_output.restart_index(str(path))[-1]
    path.write_bytes(path.read_bytes()[:(start_ + end) // 2])  # the record of step 12 cut by a hard stop
    edit(folder, initial_step=8, n_steps=16)
    status, _, err = run(DYNAMIC, folder)
    assert status == 0, err
    messages = []
    steps = [s for s, _, _ in run_output.restart_index(str(path), report=messages.append)]
    assert messages == [] and steps == [0, 4, 8, 8, 12, 16]  # before: the appended records hid behind the cut one
    aside = list((folder / 'data' / ('run' + run_output.ASIDE_SUFFIX)).rglob('run.restart.after_byte_*'))
    assert len(aside) == 1 and aside[0].stat().st_size > 0


@pytest.mark.parametrize('program', ['dynamic', 'mcmc'])
def test_L4_file_size_limit_ends_in_one_line_without_part_files(tmp_path, program):
    scene, script = (dynamic_scene, DYNAMIC) if program == 'dynamic' else (mcmc_scene, MCMC)
    folder = scene(tmp_path / 'run', n_steps=4000 if program == 'mcmc' else 400, n_save=1 if program == 'dynamic'
                   else 10, save_clones='one_file')
    limit = 20000

    def limited():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    arguments = [sys.executable, script] + (['--input-file', 'input.dat'] if program == 'dynamic' else ['input.dat'])
    process = subprocess.run(arguments, cwd=str(folder), env=child_environment(), capture_output=True, text=True,
                             preexec_fn=limited, timeout=120)
    err = process.stderr
    assert process.returncode == 1, err
    assert 'Traceback' not in err and 'cannot write' in err and 'restart with initial_step' in err, err
    data = folder / 'data'
    assert not list(data.rglob('*.part'))
    assert (data / 'run.time').exists() and (data / ('run.MCMC_info' if program == 'mcmc' else 'run.info')).exists()
    messages = []
    run_output.restart_index(str(data / 'run.restart'), report=messages.append)
    assert messages == []  # no partial record
    saved = int(err.rsplit('restart with initial_step', 1)[1].split()[0])
    assert last_pair_step(folder, 'one_file', ['a']) == saved


def test_W1_lone_snapshot_is_refused_and_forcing_says_so(tmp_path):
    folder = dynamic_scene(tmp_path / 'run', n_steps=40, n_save=4)
    status, _, _ = run(DYNAMIC, folder, {run_output.KILL_HOOK: '8'})
    assert status == -signal.SIGKILL and (folder / 'data' / 'run.a.00000008.clones').exists()
    edit(folder, initial_step=8)
    status, _, err = run(DYNAMIC, folder)
    assert status == 2 and 'no restart record of step 8' in err and 'restart_inexact True' in err, err
    assert 'last step with a complete snapshot and record is 4' in err
    edit(folder, restart_inexact='True')
    status, out, err = run(DYNAMIC, folder)
    assert status == 0 and 'inexact restart from step 8' in err, err


def test_W2_mcmc_one_file_restart_cuts_the_abandoned_frames(tmp_path):
    whole = mcmc_scene(tmp_path / 'whole', n_steps=400, n_save=40, save_clones='one_file')
    assert run(MCMC, whole)[0] == 0
    split = tmp_path / 'split'
    shutil.copytree(whole, split)
    edit(split, initial_step=200)
    status, _, err = run(MCMC, split)
    assert status == 0, err
    assert outputs(split, mcmc=True) == outputs(whole, mcmc=True)  # before: frame 200 twice, later ones shifted


def test_a_new_run_sets_the_earlier_run_aside(tmp_path):
    folder = dynamic_scene(tmp_path / 'run', n_steps=20, n_save=2)
    assert run(DYNAMIC, folder)[0] == 0
    edit(folder, n_steps=10, seed=4)
    status, out, err = run(DYNAMIC, folder)
    assert status == 0 and 'earlier run' in out, err
    steps = sorted(int(p.name.split('.')[-2]) for p in (folder / 'data').glob('run.a.*.clones'))
    assert steps == list(range(0, 11, 2))
    aside = list((folder / 'data' / 'run.set_aside').glob('*/run.a.00000020.clones'))
    assert len(aside) == 1
    edit(folder, initial_step=10, n_steps=20)  # continues the new run, not the old one
    assert run(DYNAMIC, folder)[0] == 0
    record = run_output.restart_record(str(folder / 'data' / 'run'), 20)
    assert record['run_id'] == run_output.read_run_id(str(folder / 'data' / 'run'))


@pytest.mark.parametrize('signal_name', ['SIGTERM', 'SIGINT'])
def test_a_signal_saves_the_step_reached(tmp_path, signal_name):
    """n_save 100000: before, a stop kept only step 0; now the step reached is saved and continues exactly."""
    reference = dynamic_scene(tmp_path / 'reference', n_steps=3000, n_save=100000)
    folder = dynamic_scene(tmp_path / 'run', n_steps=3000, n_save=100000)
    process = start(DYNAMIC, folder)
    assert wait_for_record(process, folder, 0)
    time.sleep(0.3)
    process.send_signal(getattr(signal, signal_name))
    out, err = process.communicate(timeout=120)
    assert process.returncode in (130, 143), err
    step = int(err.rsplit('restart with initial_step', 1)[1].split()[0])
    assert step > 0 and (folder / 'data' / 'run.stopped' / ('run.a.%08d.clones' % step)).exists()
    edit(folder, initial_step=step, n_steps=step + 6, n_save=step + 6)
    edit(reference, n_steps=step + 6, n_save=step + 6)
    assert run(DYNAMIC, folder)[0] == 0 and run(DYNAMIC, reference)[0] == 0
    assert outputs(folder) == outputs(reference)


@pytest.mark.parametrize('change, words', [
    ('order', 'structures: was a x 1, b x 1, now b x 1, a x 1'),
    ('radius', 'blob_radius'),
    ('vertex', 'blobs of a'),
    ('removed', 'structures'),
    ('snapshot', 'differs from the one its record'),
])
def test_restart_consistency_changes_are_refused(tmp_path, change, words):
    folder = dynamic_scene(tmp_path / 'run', n_steps=8, n_save=4)
    assert run(DYNAMIC, folder)[0] == 0
    edit(folder, initial_step=4, n_steps=8)
    text = (folder / 'input.dat').read_text()
    if change == 'order':
        text = text.replace('structure blob.vertex a.clones\nstructure blob.vertex b.clones',
                            'structure blob.vertex b.clones\nstructure blob.vertex a.clones')
    elif change == 'radius':
        text = set_options(text, blob_radius=0.51)
    elif change == 'vertex':
        (folder / 'blob2.vertex').write_text('2\n0 0 0\n0 0 0.5\n')
        text = text.replace('structure blob.vertex a.clones', 'structure blob2.vertex a.clones')
    elif change == 'removed':
        text = text.replace('structure blob.vertex b.clones\n', '')
    else:
        path = folder / 'data' / 'run.a.00000004.clones'
        path.write_text(path.read_text().replace('1.0 0.0 0.0 0.0', '1.0 0.0 0.0 0.0 ').replace('\n', ' \n', 1))
    (folder / 'input.dat').write_text(text)
    status, _, err = run(DYNAMIC, folder)
    assert status == 2 and words in err and 'restart_inexact' in err and 'Traceback' not in err, err


# ------------------------------------------------------------------ readers take the current run's steps only
@pytest.mark.parametrize('save_clones', ['one_file_per_step', 'one_file'])
def test_readers_leave_out_snapshots_without_a_record(tmp_path, save_clones, capsys):
    """A kill between snapshot 8 and its record, and (per step) a file of another run at step 40: the reader
    of render.py / clones_to_vtk.py and the ensemble statistics take steps 0 and 4 only."""
    from multi_bodies.files.input_options import read_input_file
    from multi_bodies.run.vtk_output import saved_snapshots
    folder = dynamic_scene(tmp_path / 'run', n_steps=40, n_save=4, save_clones=save_clones)
    assert run(DYNAMIC, folder, {run_output.KILL_HOOK: '8'})[0] == -signal.SIGKILL
    if save_clones == 'one_file_per_step':
        for name in ('a', 'b'):
            shutil.copy(folder / 'data' / ('run.%s.00000004.clones' % name),
                        folder / 'data' / ('run.%s.00000040.clones' % name))
    previous = os.getcwd()
    os.chdir(str(folder))
    try:
        options = read_input_file('input.dat')
        steps, locations, _ = saved_snapshots(options, [('a', 1), ('b', 1)])
    finally:
        os.chdir(previous)
    assert steps.tolist() == [0, 4] and locations.shape == (2, 2, 3)
    assert 'without a restart record' in capsys.readouterr().out
    from multi_bodies.ensembles import ensemble_statistics
    output_name = str(folder / 'data' / 'run')
    recorded = run_output.recorded_snapshots(output_name, save_clones, 'a')
    assert recorded == ({0, 4} if save_clones == 'one_file_per_step' else 2)
    assert ensemble_statistics is not None


# ------------------------------------------------------------------ issue 48: .concentration kept like the snapshots
@pytest.mark.parametrize('restart_step', [3, 6])
def test_a_restart_keeps_one_concentration_block_per_saved_step(tmp_path, restart_step):
    """A finished 0..9 run (n_save 3) restarted from step 3 once left 7 blocks (the continuation's 6 and 9, then
    3, 6, 9 again); now the file is byte for byte the uninterrupted run's (4 blocks), the replaced blocks set
    aside (law: a deterministic program with the same state gives the same bytes)."""
    from multi_bodies.run.concentration_output import read_concentration_file
    whole = phoretic_scene(tmp_path / 'whole', n_steps=9, n_save=3)
    assert run(DYNAMIC, whole)[0] == 0
    folder = phoretic_scene(tmp_path / 'run', n_steps=9, n_save=3)
    assert run(DYNAMIC, folder)[0] == 0
    edit(folder, initial_step=restart_step)
    status, out, err = run(DYNAMIC, folder)
    assert status == 0, err
    name = 'run.concentration'
    assert read_concentration_file(str(whole / 'data' / name)).shape[0] == 4
    assert (folder / 'data' / name).read_bytes() == (whole / 'data' / name).read_bytes()
    assert outputs(folder) == outputs(whole)
    aside = list((folder / 'data' / 'run.set_aside').glob('*/run.concentration.after_byte_*'))
    assert len(aside) == 1 and aside[0].stat().st_size > 0


def test_a_new_phoretic_run_sets_the_earlier_concentration_aside(tmp_path):
    folder = phoretic_scene(tmp_path / 'run', n_steps=3, n_save=3)
    assert run(DYNAMIC, folder)[0] == 0
    earlier = (folder / 'data' / 'run.concentration').read_bytes()
    edit(folder, dt=0.02)
    assert run(DYNAMIC, folder)[0] == 0
    aside = list((folder / 'data' / 'run.set_aside').glob('*/run.concentration'))
    assert len(aside) == 1 and aside[0].read_bytes() == earlier
    assert (folder / 'data' / 'run.concentration').read_bytes() != earlier


def test_a_cut_concentration_file_refuses_the_restart(tmp_path):
    folder = phoretic_scene(tmp_path / 'run', n_steps=9, n_save=3)
    assert run(DYNAMIC, folder)[0] == 0
    path = folder / 'data' / 'run.concentration'
    path.write_bytes(path.read_bytes()[:100])
    before = snapshot_tree(folder / 'data')
    edit(folder, initial_step=6)
    status, _, err = run(DYNAMIC, folder)
    assert status == 2 and 'run.concentration' in err and len(err.strip().splitlines()) == 1, err
    assert snapshot_tree(folder / 'data') == before


# ------------------------------------------------------------------ issues 47 and 48: SIGTERM stops a slow step at once
SLOW_STEP_OVERRIDE = '''import os
import time

_steps = [0]


def preprocess(bodies):
    """The physics is the default; with RMB_TEST_SLOW_STEP=k the k-th step of the process sleeps ten minutes."""
    _steps[0] += 1
    if os.environ.get('RMB_TEST_SLOW_STEP') == str(_steps[0]):
        open('sleeping', 'w').close()
        time.sleep(600)
'''


def slow_step_chain(tmp_path, n_steps, n_save, slow_call, signal_name='SIGTERM'):
    """A run whose ``slow_call``-th step sleeps ten minutes, signalled while it sleeps: (reference folder, stopped
    folder, exit status, stderr)."""
    reference = dynamic_scene(tmp_path / 'reference', n_steps=n_steps, n_save=n_save)
    folder = dynamic_scene(tmp_path / 'run', n_steps=n_steps, n_save=n_save)
    for scene in (reference, folder):
        (scene / 'user_defined_functions.py').write_text(SLOW_STEP_OVERRIDE)
    assert run(DYNAMIC, reference)[0] == 0
    process = start(DYNAMIC, folder, {'RMB_TEST_SLOW_STEP': str(slow_call)})
    deadline = time.monotonic() + 120
    while not (folder / 'sleeping').exists() and process.poll() is None and time.monotonic() < deadline:
        time.sleep(0.01)
    assert (folder / 'sleeping').exists(), process.communicate(timeout=10)
    process.send_signal(getattr(signal, signal_name))
    try:  # the step sleeps 600 s: an exit before then is the step abandoned (a generous bound, not a timing)
        out, err = process.communicate(timeout=300)
    except subprocess.TimeoutExpired:
        process.kill()
        pytest.fail('the signal did not stop the slow step')
    return reference, folder, process.returncode, err


@pytest.mark.parametrize('signal_name', ['SIGTERM', 'SIGINT'])
def test_a_signal_abandons_a_slow_step_and_keeps_the_last_completed_one(tmp_path, signal_name):
    """Issue 47: a run finished its current step before exiting (248 s for a slow step).  Now the step in
    progress is abandoned; the last completed step (5, off the n_save grid) is saved with its record, and the
    restart from it equals the uninterrupted run bit for bit."""
    reference, folder, status, err = slow_step_chain(tmp_path, 12, 4, slow_call=6, signal_name=signal_name)
    assert status == {'SIGTERM': 143, 'SIGINT': 130}[signal_name] and 'Traceback' not in err, err
    assert len(err.strip().splitlines()) == 1 and 'restart with initial_step 5' in err, err
    assert (folder / 'data' / 'run.stopped' / 'run.a.00000005.clones').exists()
    assert run_output.restart_record(str(folder / 'data' / 'run'), 5)['stop'] is True
    edit(folder, initial_step=5)
    status, _, err = run(DYNAMIC, folder)
    assert status == 0, err
    assert outputs(folder) == outputs(reference)


def test_sigterm_in_the_last_step_leaves_the_last_frame_in_the_series(tmp_path):
    """Issue 48: a SIGTERM in the last step said 'restart with initial_step n_steps' (which does nothing) and
    left the final frame in run.stopped/ only.  Now the last completed step is named, and the restart writes the
    final frame into the series, as the uninterrupted run has it."""
    reference, folder, status, err = slow_step_chain(tmp_path, 8, 4, slow_call=8)
    assert status == 143 and 'restart with initial_step 7' in err, err
    edit(folder, initial_step=7)
    status, _, err = run(DYNAMIC, folder)
    assert status == 0, err
    assert (folder / 'data' / 'run.a.00000008.clones').exists()
    assert outputs(folder) == outputs(reference)


class _Stop:
    signal_number = None


@pytest.mark.parametrize('first, last, n_save, signal_after, saved, stop_saved, complete', [
    (0, 8, 4, 7, [0, 4, 8], None, True),    # the signal after the last step: the final save on the grid, complete
    (0, 9, 4, 8, [0, 4, 8], None, True),    # ... off the grid: nothing more to save, as an uninterrupted run
    (0, 12, 4, 3, [0, 4], None, False),     # a step reached on the grid is saved in the series
    (0, 12, 4, 4, [0, 4], 5, False),        # off the grid: beside the series
    (4, 12, 4, 4, [4], 5, False),           # a restart
])
def test_the_time_loop_keeps_the_step_a_signal_stops_at(first, last, n_save, signal_after, saved, stop_saved,
                                                        complete):
    """The loop's rule, without processes: the step reached is saved where an uninterrupted run has it."""
    stop, grid, beside = _Stop(), [], []

    def advance(step):
        if step == signal_after:
            stop.signal_number = signal.SIGTERM

    loop = run_loop.TimeLoop(first, last, n_save)
    loop.run(grid.append, advance, stop, beside.append)
    assert grid == saved and beside == ([stop_saved] if stop_saved else []) and loop.complete == complete
    assert loop.stopped


def test_an_interrupted_step_is_kept_as_the_step_before_it():
    stop, grid, beside = _Stop(), [], []

    def advance(step):
        if step == 6:
            raise run_loop.StepInterrupted(completed=False)
    loop = run_loop.TimeLoop(0, 12, 4)
    loop.run(grid.append, advance, stop, beside.append)
    assert grid == [0, 4] and beside == [6] and loop.step == 6 and not loop.complete


# ------------------------------------------------------------------ issue 48: refusals that name the way on, at once
@pytest.mark.parametrize('save_clones', ['one_file_per_step', 'one_file'])
def test_a_lone_snapshot_refusal_names_the_last_complete_step(tmp_path, save_clones):
    """The docs promise it; in one_file mode the refusal after a kill between snapshot and record did not."""
    folder = dynamic_scene(tmp_path / 'run', n_steps=40, n_save=4, save_clones=save_clones)
    assert run(DYNAMIC, folder, {run_output.KILL_HOOK: '16'})[0] == -signal.SIGKILL
    edit(folder, initial_step=16)
    status, _, err = run(DYNAMIC, folder)
    assert status == 2 and 'record of step 16' in err and 'Traceback' not in err, err
    assert 'the last step with a complete snapshot and record is 12' in err, err


def test_a_restart_file_of_a_million_tiny_records_is_refused_at_the_first(tmp_path):
    """A .restart of 10^6 forged tiny records took 53-186 s to refuse; a record shorter than any this package
    writes now ends the walk through the file (the refusal reads one header, whatever follows)."""
    import hashlib
    from multi_bodies.run.restart_records import RECORD_HEADER, RECORD_TAG, RESTART_MAGIC, restart_index
    folder = dynamic_scene(tmp_path / 'run', n_steps=8, n_save=4)
    assert run(DYNAMIC, folder)[0] == 0
    payload = b'{}'
    record = RECORD_HEADER.pack(RECORD_TAG, 4, len(payload), hashlib.sha256(payload).digest()) + payload
    path = folder / 'data' / 'run.restart'
    path.write_bytes(RESTART_MAGIC + record * 10 ** 6)
    reports = []
    assert restart_index(str(path), reports.append) == []
    assert len(reports) == 1 and 'fewer than any record' in reports[0], reports
    edit(folder, initial_step=4)
    status, _, err = run(DYNAMIC, folder)
    assert status == 2 and 'no restart record of step 4' in err and 'Traceback' not in err, err
