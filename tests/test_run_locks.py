"""One writer per output name, and a new run never mixes with an earlier one (issues 27 and 48).

A second run (a new run or a restart; the dynamic, Monte Carlo or static script) into the output name of a
live run is refused in one line naming the live run's process, and the live run's files are exactly those
of a run alone (law: a deterministic program with the same input gives the same bytes).  A lock path that
is not a file, a lock removed or replaced while its run lives, a stale lock, a process that lives on after
its run: none lets a second writer in or refuses a lawful restart.  A new run sets aside every file of the
earlier run it would overwrite, and leaves alone an output name that merely starts the same.
"""
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from multi_bodies.run import run_output  # noqa: E402
from run_scenes import REPO_ROOT, child_environment, set_options  # noqa: E402
from safety_scenes import (DYNAMIC, MCMC, dynamic_scene, edit, last_pair_step, mcmc_scene, outputs, run,  # noqa: E402
                           snapshot_tree, start, wait_for_record)


# ------------------------------------------------------------------ one writer per output name (issue 27)
def wait_for_lock(process, folder, timeout=60.0):
    lock = Path(folder) / 'data' / 'run.lock'
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and process.poll() is None:
        if lock.exists() and lock.read_text():
            return True
        time.sleep(0.005)
    return False


@pytest.mark.parametrize('second', ['new run', 'restart'])
def test_a_second_run_into_a_live_output_name_is_refused(tmp_path, second):
    """The same input started twice: the second is refused in one line naming the first run's process; the first
    run's files are exactly those of a run alone (law: a deterministic program with the same input gives the same
    bytes)."""
    alone = dynamic_scene(tmp_path / 'alone', n_steps=120, n_save=10)
    assert run(DYNAMIC, alone)[0] == 0
    folder = dynamic_scene(tmp_path / 'run', n_steps=120, n_save=10)
    first = start(DYNAMIC, folder)
    assert wait_for_lock(first, folder) and wait_for_record(first, folder, 10)
    twin = dynamic_scene(tmp_path / 'twin', n_steps=120, n_save=10)
    text = (twin / 'input.dat').read_text().replace('data/run', str(folder / 'data' / 'run'))
    (twin / 'input.dat').write_text(text if second == 'new run' else set_options(text, initial_step=10))
    first.send_signal(signal.SIGSTOP)  # the first run lives (paused) while the second one starts
    try:
        status, _, err = run(DYNAMIC, twin)
    finally:
        first.send_signal(signal.SIGCONT)
    assert first.wait(timeout=120) == 0
    assert status == 2 and 'Traceback' not in err and len(err.strip().splitlines()) == 1, err
    assert 'is in use by another run (pid %d' % first.pid in err, err
    assert outputs(folder) == outputs(alone)
    assert not (folder / 'data' / 'run.set_aside').exists() and not (folder / 'data' / 'run.lock').exists()


def test_a_second_monte_carlo_chain_into_a_live_output_name_is_refused(tmp_path):
    folder = mcmc_scene(tmp_path / 'run', n_steps=4000, n_save=40)
    first = start(MCMC, folder)
    assert wait_for_lock(first, folder)
    first.send_signal(signal.SIGSTOP)
    try:
        status, _, err = run(MCMC, folder)
    finally:
        first.send_signal(signal.SIGCONT)
    assert first.wait(timeout=120) == 0
    assert status == 2 and 'Traceback' not in err and 'is in use by another run (pid %d' % first.pid in err, err
    assert not (folder / 'data' / 'run.set_aside').exists()


def test_a_stale_run_lock_is_taken_over_and_logged(tmp_path):
    import json
    import socket
    folder = dynamic_scene(tmp_path / 'run', n_steps=4, n_save=2)
    (folder / 'data').mkdir()
    gone = subprocess.run([sys.executable, '-c', 'import os; print(os.getpid())'], capture_output=True, text=True)
    (folder / 'data' / 'run.lock').write_text(json.dumps({'host': socket.gethostname(), 'pid': int(gone.stdout)}))
    status, out, err = run(DYNAMIC, folder)
    assert status == 0, err
    assert 'pid %d on %s' % (int(gone.stdout), socket.gethostname()) in out and 'taken over' in out, out
    assert not (folder / 'data' / 'run.lock').exists()


def test_a_refused_run_leaves_no_folder_for_its_lock(tmp_path):
    folder = dynamic_scene(tmp_path / 'run', n_steps=4, n_save=2, dt=-1)
    status, _, err = run(DYNAMIC, folder)
    assert status == 2 and 'dt' in err
    assert not (folder / 'data').exists()


# ------------------------------------------------------------------ issue 48: locks that cannot be fooled, nothing mixed
@pytest.mark.parametrize('kind', ['symlink', 'dangling symlink', 'folder', 'fifo'])
def test_a_lock_path_that_is_not_a_file_is_one_line(tmp_path, kind):
    """run.lock as a link (to a file, or dangling), a folder or a FIFO: refused in one line naming it; a link's
    target is never written (before: overwritten with the holder's record), a FIFO never blocks."""
    folder = dynamic_scene(tmp_path / 'run', n_steps=4, n_save=2)
    (folder / 'data').mkdir()
    lock = folder / 'data' / 'run.lock'
    target = tmp_path / 'precious.txt'
    if kind == 'symlink':
        target.write_text('keep me\n')
        lock.symlink_to(target)
    elif kind == 'dangling symlink':
        lock.symlink_to(tmp_path / 'nowhere')
    elif kind == 'folder':
        lock.mkdir()
    else:
        os.mkfifo(str(lock))
    status, out, err = run(DYNAMIC, folder)
    assert status == 2 and 'Traceback' not in err and len(err.strip().splitlines()) == 1, err
    assert 'run.lock' in err and {'symlink': 'symbolic link', 'dangling symlink': 'symbolic link', 'folder': 'folder',
                                  'fifo': 'FIFO'}[kind] in err, err
    if kind == 'symlink':
        assert target.read_text() == 'keep me\n'
    if kind == 'dangling symlink':
        assert not (tmp_path / 'nowhere').exists()
    assert not list((folder / 'data').glob('run.*.clones'))


def test_removing_a_live_runs_lock_lets_no_second_writer_in(tmp_path):
    """The refusal once suggested removing run.lock; removed while its run lives, a second run got in and .restart
    held records of two runs.  Now the second run is refused (the live run is named in run.run), the first takes
    its lock back at its next save, and its files are exactly those of a run alone (law: same input, same bytes)."""
    alone = dynamic_scene(tmp_path / 'alone', n_steps=120, n_save=10)
    assert run(DYNAMIC, alone)[0] == 0
    folder = dynamic_scene(tmp_path / 'run', n_steps=120, n_save=10)
    first = start(DYNAMIC, folder)
    assert wait_for_lock(first, folder) and wait_for_record(first, folder, 10)
    first.send_signal(signal.SIGSTOP)
    try:
        (folder / 'data' / 'run.lock').unlink()
        status, _, err = run(DYNAMIC, folder)  # the same input: a new run into the live output name
    finally:
        first.send_signal(signal.SIGCONT)
    assert first.wait(timeout=120) == 0, first.stderr.read()
    assert status == 2 and 'Traceback' not in err and len(err.strip().splitlines()) == 1, err
    assert 'in use by another run (pid %d' % first.pid in err and 'run.run' in err, err
    assert outputs(folder) == outputs(alone)
    records = run_output.read_restart_records(str(folder / 'data' / 'run'))
    assert len({record['run_id'] for record in records}) == 1 and len(records) == 13
    assert not (folder / 'data' / 'run.set_aside').exists() and not (folder / 'data' / 'run.lock').exists()


def test_a_run_whose_lock_is_taken_stops_in_one_line(tmp_path):
    """Another program replacing a live run's lock file (and so taking the outputs): the run stops at its next
    save with one line naming the lock file, exit 1; what it saved before is complete."""
    folder = dynamic_scene(tmp_path / 'run', n_steps=100000, n_save=10)
    first = start(DYNAMIC, folder)
    assert wait_for_lock(first, folder) and wait_for_record(first, folder, 10)
    first.send_signal(signal.SIGSTOP)
    lock = folder / 'data' / 'run.lock'
    lock.unlink()
    lock.write_text('{"host": "elsewhere", "pid": 1}')
    first.send_signal(signal.SIGCONT)
    out, err = first.communicate(timeout=120)
    assert first.returncode == 1 and 'Traceback' not in err, err
    assert len([line for line in err.splitlines() if line.startswith('error:')]) == 1, err
    assert 'run.lock' in err and 'Another program writes the same outputs' in err, err
    assert last_pair_step(folder, 'one_file_per_step', ['a', 'b']) is not None
    assert lock.read_text() == '{"host": "elsewhere", "pid": 1}'  # not the run's to remove


def test_the_static_script_holds_the_lock(tmp_path):
    """multi_bodies_utilities.py into the output name of a live dynamic run: refused (before, it overwrote the
    run's .inputfile and .bodies_info); the dynamic run's files are those of a run alone."""
    alone = dynamic_scene(tmp_path / 'alone', n_steps=120, n_save=10)
    assert run(DYNAMIC, alone)[0] == 0
    folder = dynamic_scene(tmp_path / 'run', n_steps=120, n_save=10)
    (folder / 'static.dat').write_text(set_options((folder / 'input.dat').read_text(), scheme='mobility'))
    first = start(DYNAMIC, folder)
    assert wait_for_lock(first, folder) and wait_for_record(first, folder, 10)
    first.send_signal(signal.SIGSTOP)
    try:
        static = subprocess.run([sys.executable, str(REPO_ROOT / 'multi_bodies' / 'multi_bodies_utilities.py'),
                                 '--input-file', 'static.dat'], cwd=str(folder), env=child_environment(),
                                capture_output=True, text=True, timeout=120)
    finally:
        first.send_signal(signal.SIGCONT)
    assert first.wait(timeout=120) == 0
    assert static.returncode == 2 and 'in use by another run (pid %d' % first.pid in static.stderr, static.stderr
    assert outputs(folder) == outputs(alone)
    for suffix in ('inputfile', 'bodies_info'):
        assert (folder / 'data' / ('run.' + suffix)).read_bytes() == (alone / 'data' / ('run.' + suffix)).read_bytes()


def test_a_new_run_leaves_an_output_name_that_starts_the_same_alone(tmp_path):
    """data/run.b beside data/run: a new run into data/run once moved run.b's snapshots aside (names matched by
    prefix), so run.b could no longer restart.  Now run.b keeps every file and restarts exactly."""
    whole = dynamic_scene(tmp_path / 'whole', n_steps=8, n_save=4, output_name='data/run.b')
    assert run(DYNAMIC, whole)[0] == 0
    folder = dynamic_scene(tmp_path / 'run', n_steps=8, n_save=4, output_name='data/run.b')
    edit(folder, n_steps=4)
    assert run(DYNAMIC, folder)[0] == 0
    before = snapshot_tree(folder / 'data')
    edit(folder, output_name='data/run', n_steps=4)
    assert run(DYNAMIC, folder)[0] == 0  # a new run into data/run, twice (the second sets the first aside)
    status, out, err = run(DYNAMIC, folder)
    assert status == 0 and 'moved to' in out, err
    after = snapshot_tree(folder / 'data')
    assert all(after.get(name) == data for name, data in before.items())  # (run's own run.b.<step>.clones too)

    def series_of_run_b(folder):
        return {n: d for n, d in snapshot_tree(folder / 'data').items() if n.startswith(('run.b.a.', 'run.b.b.'))}
    edit(folder, output_name='data/run.b', initial_step=4, n_steps=8)
    assert run(DYNAMIC, folder)[0] == 0
    assert series_of_run_b(folder) == series_of_run_b(whole) and len(series_of_run_b(whole)) == 6


@pytest.mark.parametrize('program', ['dynamic', 'static'])
def test_a_new_run_sets_aside_every_file_it_would_overwrite(tmp_path, program):
    """.inputfile and .random_state (and .info, .time, .bodies_info, ...) of an earlier run were overwritten by a
    new run into the same output name; now every one is in the set-aside folder, byte for byte."""
    folder = dynamic_scene(tmp_path / 'run', n_steps=4, n_save=2)
    assert run(DYNAMIC, folder)[0] == 0
    earlier = snapshot_tree(folder / 'data')
    if program == 'dynamic':
        edit(folder, seed=11, dt=0.02)
        status, out, err = run(DYNAMIC, folder)
    else:
        edit(folder, scheme='mobility')
        static = subprocess.run([sys.executable, str(REPO_ROOT / 'multi_bodies' / 'multi_bodies_utilities.py'),
                                 '--input-file', 'input.dat'], cwd=str(folder), env=child_environment(),
                                capture_output=True, text=True, timeout=120)
        status, out, err = static.returncode, static.stdout, static.stderr
    assert status == 0, err
    aside = list((folder / 'data' / 'run.set_aside').iterdir())
    assert len(aside) == 1
    assert snapshot_tree(aside[0]) == earlier
    assert {'run.inputfile', 'run.random_state', 'run.info', 'run.time', 'run.bodies_info'} <= set(earlier)


def test_a_process_that_lives_on_after_its_run_is_not_taken_for_a_writer(tmp_path):
    """run.run names the process of the last segment so that a removed lock lets no second writer in; a process
    that lives on after its run (a notebook, an ensemble worker: here this test's own process) marks its segment
    ended when it lets the lock go, so a restart from another process is not refused."""
    import json
    from safety_scenes import run_dynamic
    folder = dynamic_scene(tmp_path / 'run', n_steps=8, n_save=4)
    assert run_dynamic(folder)[0] == 0  # in this process, which lives on
    segment = json.loads((folder / 'data' / 'run.run').read_text())['segments'][-1]
    assert segment['pid'] == os.getpid() and segment.get('ended')
    before = (folder / 'data' / 'run.run').read_bytes()
    edit(folder, dt=-1)
    assert run_dynamic(folder)[0] == 2  # refused in this same process: run.run is left as it was (found by the
    assert (folder / 'data' / 'run.run').read_bytes() == before  # fuzzer: it was marked ended a second time)
    edit(folder, initial_step=4, n_steps=12, dt=0.01)
    status, _, err = run(DYNAMIC, folder)
    assert status == 0, err
