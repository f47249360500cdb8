"""Resources bounded, and mistakes and interruptions answered in one line (issue 17).

Memory: the reference body length in O(N) memory (equal to the all-pairs value on every shipped structure),
a dense scheme or a velocity grid too big for the machine refused before any file is written, a warning
before a run writes more than 10,000 files.  One-line refusals: a periodic box that is negative or too
small, a FIFO as ``random_state``, a restart file that is a folder, bad movie options of ``render.py``.
Interruptions: an empty stale ensemble lock is taken over, ``ensemble.py --workers 0`` stopped by SIGTERM
exits 143 and can resume, Ctrl-C while the script imports is one line and exit 130.
"""
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from multi_bodies.ensembles import ensemble_runner as runner  # noqa: E402
from multi_bodies.run import run_output  # noqa: E402
from run_scenes import REPO_ROOT, child_environment  # noqa: E402
from safety_scenes import DYNAMIC, dynamic_scene, edit, run  # noqa: E402


# ------------------------------------------------------------------ resources and one-line refusals
def test_reference_body_length_is_the_all_pairs_value_in_o_n_memory():
    """Law: the body length is the largest pairwise blob distance + 2a, computed here by all pairs; the hull
    path gives the same double on every shipped structure, and 1e6 blobs need far less than 1 GB."""
    import tracemalloc
    from body.body import reference_body_length
    from multi_bodies.files.structure_files import read_vertex_file
    checked = 0
    for path in sorted((REPO_ROOT / 'multi_bodies' / 'Structures').glob('*.vertex')):
        blobs = read_vertex_file(str(path))
        if len(blobs) > 3000:
            continue
        diff = blobs[:, None, :] - blobs[None, :, :]
        expected = float(np.sqrt(np.max(np.einsum('ijk,ijk->ij', diff, diff)))) + 2 * 0.3 if len(blobs) > 1 else 0.6
        assert reference_body_length(blobs, 0.3) == expected, path.name
        checked += 1
    assert checked >= 3
    many = np.random.default_rng(2).standard_normal((1000000, 3))
    tracemalloc.start()
    length = reference_body_length(many, 0.1)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 300e6 and 8.0 < length < 14.0


@pytest.mark.parametrize('box', ['-5 -5 0', '1e-10 1e-10 0'])
def test_bad_periodic_length_is_one_line(tmp_path, box):
    folder = dynamic_scene(tmp_path / 'run', n_steps=2, periodic_length=box)
    status, _, err = run(DYNAMIC, folder)
    assert status == 2 and 'periodic_length' in err and 'Traceback' not in err, err


def test_random_state_fifo_is_refused_not_read_forever(tmp_path):
    folder = dynamic_scene(tmp_path / 'run', n_steps=2)
    os.mkfifo(str(folder / 'pipe.random_state'))
    edit(folder, random_state='pipe.random_state', seed=None)
    status, _, err = run(DYNAMIC, folder)
    assert status == 2 and 'not a regular file' in err, err


def test_restart_file_that_is_a_folder_is_one_line(tmp_path):
    folder = dynamic_scene(tmp_path / 'run', n_steps=4, n_save=2)
    assert run(DYNAMIC, folder)[0] == 0
    (folder / 'data' / 'run.restart').rename(folder / 'data' / 'kept')
    (folder / 'data' / 'run.restart').mkdir()
    edit(folder, initial_step=2)
    status, _, err = run(DYNAMIC, folder)
    assert status == 2 and 'is a folder' in err and 'Traceback' not in err, err


def test_an_empty_stale_ensemble_lock_is_taken_over(tmp_path):
    folder = tmp_path / 'ens'
    folder.mkdir()
    lock = folder / runner.LOCK_NAME
    lock.write_text('')  # a driver killed between creating the lock and writing its name
    old = time.time() - 60
    os.utime(str(lock), (old, old))
    with runner.ensemble_lock(str(folder)):
        assert lock.read_text()
    assert not lock.exists()


@pytest.mark.parametrize('arguments, words', [(['--fps', '0'], '--fps'), (['--movie', 'x.mp4'], '.gif')])
def test_render_refuses_bad_movie_options_in_one_line(tmp_path, arguments, words):
    folder = dynamic_scene(tmp_path / 'run', n_steps=2)
    process = subprocess.run([sys.executable, str(REPO_ROOT / 'multi_bodies' / 'render.py'), '--input-file',
                              'input.dat'] + arguments, cwd=str(folder), env=child_environment(),
                             capture_output=True, text=True, timeout=120)
    assert process.returncode == 2 and words in process.stderr and 'Traceback' not in process.stderr, \
        process.stderr


def test_ensemble_workers_0_interrupted_exits_with_the_signal_status(tmp_path):
    """Before: exit 1 and '1 failed'; now 143 for SIGTERM, and a rerun resumes from the step reached."""
    scene = dynamic_scene(tmp_path / 'scene', n_steps=3000, n_save=1000)
    output = tmp_path / 'ens'
    process = subprocess.Popen([sys.executable, str(REPO_ROOT / 'multi_bodies' / 'ensemble.py'), '--input-file',
                                str(scene / 'input.dat'), '--replicas', '1', '--workers', '0', '--output-dir',
                                str(output), '--seed', '3'], cwd=str(scene), env=child_environment(),
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while not list(output.rglob('run.restart')) and time.monotonic() < deadline and process.poll() is None:
        time.sleep(0.01)
    time.sleep(0.3)
    process.send_signal(signal.SIGTERM)
    out, err = process.communicate(timeout=120)
    assert process.returncode == 143, (out, err)
    assert '1 failed' not in out and 'did not finish' not in out and 'Traceback' not in err, (out, err)
    status = runner.read_status(str(list(output.rglob('run.restart'))[0].parent))
    assert status['status'] == 'stopped'


def test_a_dense_scheme_too_big_is_refused_before_any_file(tmp_path, monkeypatch):
    from multi_bodies.files.input_options import read_input_file
    from multi_bodies.run.dynamic_run import DynamicRun
    folder = dynamic_scene(tmp_path / 'run', n_steps=2, scheme='deterministic_forward_euler_dense_algebra', kT=0)
    monkeypatch.chdir(folder)
    monkeypatch.setattr(run_output, 'available_memory', lambda: 1000)  # a machine with 1000 bytes
    options = read_input_file('input.dat')
    with pytest.raises(run_output.UserInputError, match='needs about .* of memory, but 1000 B are available'):
        DynamicRun(options, log=lambda text: None)
    assert not (folder / 'data').exists()


def test_a_velocity_grid_too_big_is_refused_with_its_memory():
    from multi_bodies.run import velocity_field
    grid = ((0.0, 1.0, 100000), (0.0, 1.0, 100000), (0.0, 1.0, 1000))
    with pytest.raises(run_output.UserInputError, match='velocity field on 10000000000000 cells .* needs about'):
        velocity_field.check_grid(grid, 10)
    velocity_field.check_grid(((0.0, 1.0, 4),) * 3, 10)  # a small grid passes


def test_a_run_writing_more_than_10000_files_is_warned_about(tmp_path, monkeypatch):
    from multi_bodies.files.input_options import read_input_file
    from multi_bodies.run.dynamic_run import DynamicRun
    folder = dynamic_scene(tmp_path / 'run', n_steps=6000, n_save=1)
    monkeypatch.chdir(folder)
    lines = []
    DynamicRun(read_input_file('input.dat'), log=lines.append)
    warned = [line for line in lines if 'will write about' in line]
    assert warned and '(6001 saves)' in warned[0], lines
    assert int(warned[0].split('will write about')[1].split()[0]) >= 2 * 6001  # a snapshot per structure and save
    lines.clear()
    edit(folder, save_clones='one_file')
    DynamicRun(read_input_file('input.dat'), log=lines.append)
    assert not any('will write' in line for line in lines), lines


def test_ctrl_c_while_the_script_imports_is_one_line(tmp_path):
    """SIGINT before main starts (while numpy, scipy and the backends import): one line and 130.

    No timing: the child starts with SIGINT blocked, the Ctrl-C is sent at once and stays pending, and the script
    unblocks it when its start-up handler exists (utils.prepare_script_path), before the package's imports; so the
    signal always lands during the imports, however loaded the machine (a sleep before the signal made it land
    before the handler under load, or after main had started)."""
    folder = dynamic_scene(tmp_path / 'run', n_steps=2)
    environment = child_environment()
    process = subprocess.Popen([sys.executable, DYNAMIC, '--input-file', 'input.dat'], cwd=str(folder),
                               env=environment, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               preexec_fn=lambda: signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT}))
    process.send_signal(signal.SIGINT)
    out, err = process.communicate(timeout=120)
    assert 'Traceback' not in err, err
    assert process.returncode == 130 and err.strip() == 'interrupted (SIGINT) while starting; nothing was written', err
    assert not (folder / 'data').exists() or not list((folder / 'data').iterdir())
