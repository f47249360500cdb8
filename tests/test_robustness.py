"""Runs that survive (issue 10): signals, validation before any write, clear messages, provenance.

One test (or one parametrised family) per row of the issue's lists.  What is
asserted comes from outside the code under test: the exit statuses of the
POSIX convention (128 + signal number), the bytes of files written before,
and the law that a restarted deterministic run continues the trajectory of
an uninterrupted one exactly.
"""
import io
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import utils
from multi_bodies.run import run_loop, run_output
from multi_bodies.files.input_options import OPTION_TABLE, parse_input_text
from multi_bodies.files.snapshots import read_clones_file

from run_scenes import (REPO_ROOT, SCRIPT_DIR, add_generated_inputs, copy_scene, edit_input, run_in_process,
                        snapshot_files, start_child)

BOOMERANG = 'boomerang_N_15'


def dynamic_scene(folder, **options):
    """The shipped dynamic example (Adams-Bashforth, one boomerang and two shells) with ``options`` changed."""
    copy_scene(folder)
    edit_input(Path(folder) / 'inputfile_dynamic.dat', **options)
    return Path(folder)


def saved_steps(folder, output_name='data/run', structure=BOOMERANG):
    prefix = os.path.basename(output_name) + '.' + structure + '.'
    data = Path(folder) / os.path.dirname(output_name)
    return sorted(int(p.name[len(prefix):-len('.clones')]) for p in data.glob(prefix + '*.clones'))


def snapshot(folder, step, structure=BOOMERANG):
    locations, orientations = read_clones_file(str(Path(folder) / 'data' / ('run.%s.%08d.clones' % (structure, step))))
    return np.concatenate((locations, orientations), axis=1)


# ====================================================================== ending a run
def wait_for(path, process, timeout=90.0):
    """Wait until ``path`` exists (the child has saved that step); fail if the child ends first."""
    deadline = time.monotonic() + timeout
    while not path.exists():
        if process.poll() is not None:
            out, err = process.communicate()
            pytest.fail('the child ended (status %s) before %s was written:\n%s\n%s' % (process.returncode, path,
                                                                                       out[-2000:], err[-2000:]))
        if time.monotonic() > deadline:
            process.kill()
            pytest.fail('timeout waiting for %s' % path)
        time.sleep(0.02)


def long_run(tmp_path, name):
    folder = dynamic_scene(tmp_path / name, n_steps=100000, n_save=5)
    process = start_child('dynamic', folder, 'inputfile_dynamic.dat')
    wait_for(folder / 'data' / ('run.%s.%08d.clones' % (BOOMERANG, 15)), process)
    return folder, process


def check_snapshots_readable(folder, killed=False):
    """Every snapshot written is complete; returns the saved steps of the boomerang.

    After SIGKILL the last save may have been cut between the two structures, or inside a ``.part``
    file (never inside a ``.clones`` file): the saved steps of each structure are then a prefix of the
    run's saves, at most one save apart.
    """
    per_structure = []
    for structure in (BOOMERANG, 'shell_N_12_Rg_1'):
        steps = saved_steps(folder, structure=structure)
        assert steps == list(range(0, 5 * len(steps), 5)), steps  # every save of the run, none missing
        for step in steps:
            assert np.all(np.isfinite(snapshot(folder, step, structure)))
        per_structure.append(steps)
    if killed:
        assert abs(len(per_structure[0]) - len(per_structure[1])) <= 1
    else:
        assert per_structure[0] == per_structure[1]
        assert not list((folder / 'data').glob('*.part')), 'a half-written file was left behind'
    return per_structure[0]


def restart_matches_uninterrupted(tmp_path, folder, restart_step, extra_steps=5):
    """Restart ``folder`` at ``restart_step``; the result must equal an uninterrupted run to the same step."""
    last = restart_step + extra_steps
    edit_input(folder / 'inputfile_dynamic.dat', n_steps=last, initial_step=restart_step)
    status, _, err = run_in_process('dynamic', folder, 'inputfile_dynamic.dat')
    assert status == 0, err
    reference = dynamic_scene(tmp_path / 'uninterrupted', n_steps=last, n_save=5)
    status, _, err = run_in_process('dynamic', reference, 'inputfile_dynamic.dat')
    assert status == 0, err
    for structure in (BOOMERANG, 'shell_N_12_Rg_1'):
        # Exact up to round-off: the quaternions read back from the snapshot are normalised again (as the
        # published reader does), which moves their last bit; the GMRES guess travels in the restart record.
        np.testing.assert_allclose(snapshot(folder, last, structure), snapshot(reference, last, structure),
                                   rtol=0, atol=1e-12)
    return reference


@pytest.mark.parametrize('signal_number, status', [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_signal_mid_run_writes_info_and_time_and_restarts(tmp_path, signal_number, status):
    """SIGTERM (batch schedulers) and SIGINT (Ctrl-C): finish the step, write .info/.time, exit 128+signal."""
    folder, process = long_run(tmp_path, 'run')
    process.send_signal(signal_number)
    out, err = process.communicate(timeout=60)
    name = signal.Signals(signal_number).name
    assert process.returncode == status, err
    assert 'Traceback' not in err and 'Traceback' not in out
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and ('run stopped by %s at step' % name) in lines[0], err
    info = (folder / 'data' / 'run.info').read_text()
    match = re.search(r'run stopped by %s at step (\d+) \(last saved step (\d+)\)' % name, info)
    assert match, info
    stopped, last_saved = int(match.group(1)), int(match.group(2))
    assert run_output.read_info(str(folder / 'data' / 'run.info'))['deterministic_iterations_count'] > 0
    elapsed = float((folder / 'data' / 'run.time').read_text().split()[0])
    assert elapsed > 0
    steps = check_snapshots_readable(folder)
    assert steps[-1] == last_saved and last_saved <= stopped < last_saved + 5  # a stop on the grid is in the series
    restart_matches_uninterrupted(tmp_path, folder, last_saved)


def test_sigkill_leaves_readable_files_and_restarts(tmp_path):
    """After SIGKILL: snapshots and the restart records written so far are readable; .info is current."""
    folder, process = long_run(tmp_path, 'run')
    process.kill()
    process.communicate(timeout=60)
    steps = check_snapshots_readable(folder, killed=True)
    info = run_output.read_info(str(folder / 'data' / 'run.info'))  # rewritten at every save
    for key in ('invalid_configuration_count', 'deterministic_iterations_count', 'stochastic_iterations_count'):
        assert key in info
    assert info['deterministic_iterations_count'] > 0
    records = run_output.read_restart_records(str(folder / 'data' / 'run'))
    assert records and [r['step'] for r in records] == steps[:len(records)]
    restart_matches_uninterrupted(tmp_path, folder, records[-1]['step'])


def test_second_sigint_stops_at_once_without_traceback(tmp_path):
    folder, process = long_run(tmp_path, 'run')
    process.send_signal(signal.SIGINT)
    process.send_signal(signal.SIGINT)
    out, err = process.communicate(timeout=60)
    assert process.returncode == 130, err
    assert 'Traceback' not in err
    assert (folder / 'data' / 'run.info').exists() and (folder / 'data' / 'run.time').exists()
    check_snapshots_readable(folder)


def test_info_is_current_at_every_save(tmp_path):
    """.info after n saves holds the iterations of those steps: compare a 5-step run with the 10-step one."""
    counts = []
    for n_steps in (5, 10):
        folder = dynamic_scene(tmp_path / str(n_steps), n_steps=n_steps, n_save=5)
        status, _, err = run_in_process('dynamic', folder, 'inputfile_dynamic.dat')
        assert status == 0, err
        counts.append(run_output.read_info(str(folder / 'data' / 'run.info'))['deterministic_iterations_count'])
    assert 0 < counts[0] < counts[1]


# ====================================================================== validation order
def earlier_run(tmp_path):
    folder = dynamic_scene(tmp_path / 'run', n_steps=2, seed=5)
    status, _, err = run_in_process('dynamic', folder, 'inputfile_dynamic.dat')
    assert status == 0, err
    return folder, snapshot_files(folder / 'data')


BAD_RERUNS = {
    'save_clones': ({'save_clones': 'every_step'}, 'save_clones'),
    'random_state not a pickle': ({'random_state': 'Structures/force.dat'}, 'random_state'),
    'random_state missing': ({'random_state': 'nothing.random_state'}, 'random_state'),
    'negative seed': ({'seed': -3}, 'seed'),
    'unknown backend': ({'mobility_vector_prod_implementation': 'fortran'}, 'mobility_vector_prod_implementation'),
    'unknown blob force': ({'blob_blob_force_implementation': 'fortran'}, 'blob_blob_force_implementation'),
    'stochastic scheme with a negative rf_delta': ({'scheme': 'stochastic_first_order_RFD', 'rf_delta': -1e-3},
                                                   'rf_delta'),
    'unknown scheme': ({'scheme': 'leapfrog'}, "inputfile_dynamic.dat, line"),
    'restart from a step never saved': ({'initial_step': 7, 'n_steps': 9, 'n_save': 2}, 'initial_step'),
}


@pytest.mark.parametrize('case', sorted(BAD_RERUNS))
def test_failed_validation_leaves_earlier_outputs_untouched(tmp_path, case):
    folder, before = earlier_run(tmp_path)
    changes, fragment = BAD_RERUNS[case]
    edit_input(folder / 'inputfile_dynamic.dat', **changes)
    status, out, err = run_in_process('dynamic', folder, 'inputfile_dynamic.dat')
    assert status == 2, (out, err)
    assert fragment in err and 'Traceback' not in err
    assert snapshot_files(folder / 'data') == before


def test_broken_user_functions_leave_earlier_outputs_untouched(tmp_path):
    folder, before = earlier_run(tmp_path)
    (folder / 'user_defined_functions.py').write_text('def blob_external_forces(r_vectors, **kw)\n')
    status, _, err = run_in_process('dynamic', folder, 'inputfile_dynamic.dat')
    assert status == 2 and 'user_defined_functions.py' in err
    assert snapshot_files(folder / 'data') == before


@pytest.mark.parametrize('value', ['nan', 'inf'])
def test_non_finite_clones_leaves_earlier_outputs_untouched(tmp_path, value):
    folder, before = earlier_run(tmp_path)
    clones = folder / 'Structures' / 'shell_N_12_Rg_1.clones'
    clones.write_text(clones.read_text().replace('0 5 5 1 0 0 0', '0 5 %s 1 0 0 0' % value))
    status, _, err = run_in_process('dynamic', folder, 'inputfile_dynamic.dat')
    assert status == 2 and 'shell_N_12_Rg_1.clones, line 4' in err, err
    assert snapshot_files(folder / 'data') == before


# ====================================================================== tracebacks left
def test_output_folder_is_a_file(tmp_path):
    folder = dynamic_scene(tmp_path / 'run', n_steps=2, output_name='blocker/run')
    (folder / 'blocker').write_text('not a folder\n')
    status, _, err = run_in_process('dynamic', folder, 'inputfile_dynamic.dat')
    assert status == 2 and 'output_name' in err and 'is a file' in err, err


def test_output_folder_cannot_be_created(tmp_path):
    folder = dynamic_scene(tmp_path / 'run', n_steps=2, output_name='blocker/sub/run')
    (folder / 'blocker').write_text('not a folder\n')
    status, _, err = run_in_process('dynamic', folder, 'inputfile_dynamic.dat')
    assert status == 2 and 'output_name' in err, err
    assert not (folder / 'blocker').is_dir()


@pytest.mark.skipif(os.name != 'posix' or os.geteuid() == 0,
                    reason='permissions do not stop root (or non-POSIX systems) from writing')
def test_output_folder_read_only(tmp_path):
    folder = dynamic_scene(tmp_path / 'run', n_steps=2, output_name='locked/run')
    (folder / 'locked').mkdir()
    (folder / 'locked').chmod(0o555)
    try:
        status, _, err = run_in_process('dynamic', folder, 'inputfile_dynamic.dat')
    finally:
        (folder / 'locked').chmod(0o755)
    assert status == 2 and 'not writable' in err and 'output_name' in err, err


def test_input_file_not_utf8(tmp_path):
    folder = dynamic_scene(tmp_path / 'run', n_steps=2)
    path = folder / 'inputfile_dynamic.dat'
    path.write_bytes(path.read_bytes() + '# Réglages\n'.encode('latin-1'))
    lines = path.read_bytes().count(b'\n')
    for kind in ('dynamic', 'static'):
        status, _, err = run_in_process(kind, folder, 'inputfile_dynamic.dat')
        assert status == 2 and ("inputfile_dynamic.dat', line %d" % lines) in err and 'UTF-8' in err, err


def test_input_file_with_byte_order_mark_is_read(tmp_path):
    folder = dynamic_scene(tmp_path / 'run', n_steps=1)
    path = folder / 'inputfile_dynamic.dat'
    path.write_bytes(b'\xef\xbb\xbf' + path.read_bytes())
    status, _, err = run_in_process('dynamic', folder, 'inputfile_dynamic.dat')
    assert status == 0, err


def test_input_file_is_a_folder(tmp_path):
    folder = copy_scene(tmp_path / 'run')
    for kind in ('dynamic', 'static'):
        status, _, err = run_in_process(kind, folder, 'Structures')
        assert status == 2 and "'Structures' is a folder" in err, err


def test_random_state_not_a_pickle_and_negative_seed(tmp_path):
    folder = dynamic_scene(tmp_path / 'run', n_steps=2)
    (folder / 'bad.random_state').write_bytes(b'\x00\x01garbage')
    edit_input(folder / 'inputfile_dynamic.dat', random_state='bad.random_state')
    status, _, err = run_in_process('dynamic', folder, 'inputfile_dynamic.dat')
    assert status == 2 and 'random_state' in err and 'bad.random_state' in err, err
    edit_input(folder / 'inputfile_dynamic.dat', random_state=None, seed=-1)
    status, _, err = run_in_process('dynamic', folder, 'inputfile_dynamic.dat')
    assert status == 2 and 'seed' in err and 'line' in err, err
    assert not (folder / 'data').exists()


NON_FINITE_FILES = {
    # file kind: (script, input file, file to spoil, old text, new text with {v}, line)
    'clones': ('dynamic', 'inputfile_dynamic.dat', 'Structures/boomerang_N_15.clones', '0 0 10', '0 {v} 10', 3),
    'vertex': ('dynamic', 'inputfile_dynamic.dat', 'Structures/boomerang_N_15.vertex', '2.1 0.0 0.0',
               '2.1 {v} 0.0', 4),
    'slip': ('static', 'inputfile_squirmer_mobility.dat',
             'Structures/shell_N_42_Rg_0_8912_Rh_1_squirmer_B1_1.slip', None, None, None),
    'force': ('static', 'inputfile.dat', 'Structures/force.dat', '0.5 0.0 -1.0', '0.5 {v} -1.0', 4),
    'velocity': ('static', 'inputfile_resistance.dat', 'velocity.dat', '0 0 0 0 0 1', '0 0 {v} 0 0 1', 2),
    'clones (static)': ('static', 'inputfile.dat', 'Structures/shell_N_12_Rg_1.clones', '5 0 5', '5 0 {v}', 3),
}


@pytest.mark.parametrize('kind', sorted(NON_FINITE_FILES))
@pytest.mark.parametrize('value', ['nan', '-inf', '1e400'])
def test_non_finite_numbers_refused_when_read(tmp_path, kind, value):
    folder = copy_scene(tmp_path / 'run')
    edit_input(folder / 'inputfile_dynamic.dat', n_steps=2)
    add_generated_inputs(folder)
    script, input_name, spoiled, old, new, line = NON_FINITE_FILES[kind]
    path = folder / spoiled
    text = path.read_text()
    if old is None:  # slip file: spoil the first data line
        rows = text.splitlines()
        line = next(i for i, row in enumerate(rows, start=1) if row.strip() and not row.startswith('#')) + 1
        numbers = rows[line - 1].split()
        rows[line - 1] = ' '.join([numbers[0], value, numbers[2]])
        path.write_text('\n'.join(rows) + '\n')
    else:
        assert old in text
        path.write_text(text.replace(old, new.format(v=value), 1))
    status, out, err = run_in_process(script, folder, input_name)
    assert status == 2, (out, err)
    assert '%s, line %d' % (spoiled, line) in err, err
    assert not list((folder / 'data').glob('*.clones')) if (folder / 'data').exists() else True
    assert not (folder / 'data' / 'run.velocities.dat').exists()


def test_extra_static_inputs_run_unspoiled(tmp_path):
    """Positive control of the non-finite tests: the unspoiled resistance and squirmer problems run."""
    folder = copy_scene(tmp_path / 'run')
    add_generated_inputs(folder)
    for kind, input_name in (('static', 'inputfile_resistance.dat'), ('static', 'inputfile_squirmer_mobility.dat'),
                             ('static', 'inputfile_rollers_mobility.dat'), ('dynamic', 'inputfile_squirmer.dat')):
        status, _, err = run_in_process(kind, folder, input_name)
        assert status == 0, err


# ====================================================================== silently accepted
def test_extra_fields_on_a_clones_line_warn(tmp_path):
    folder = dynamic_scene(tmp_path / 'run', n_steps=1)
    clones = folder / 'Structures' / 'shell_N_12_Rg_1.clones'
    clones.write_text(clones.read_text().replace('0 5 5 1 0 0 0', '0 5 5 1 0 0 0 0.3'))
    status, _, err = run_in_process('dynamic', folder, 'inputfile_dynamic.dat')
    assert status == 0, err
    assert re.search(r'warning: Structures/shell_N_12_Rg_1.clones, line 4: 8 values.*ignored', err), err


def test_fourth_vertex_column_is_an_error(tmp_path):
    folder = dynamic_scene(tmp_path / 'run', n_steps=1)
    vertex = folder / 'Structures' / 'boomerang_N_15.vertex'
    vertex.write_text(vertex.read_text().replace('2.1 0.0 0.0', '2.1 0.0 0.0 0.25'))
    for kind, input_name in (('dynamic', 'inputfile_dynamic.dat'), ('static', 'inputfile_body_mobility.dat')):
        status, _, err = run_in_process(kind, folder, input_name)
        assert status == 2 and 'boomerang_N_15.vertex, line 4' in err and 'radius' in err, err


def test_negative_n_steps_is_an_error():
    with pytest.raises(utils.UserInputError, match=r'in.dat, line 2: n_steps must be >= 0'):
        parse_input_text('scheme deterministic_forward_euler\nn_steps -5\n', 'in.dat')
    assert parse_input_text('n_steps 0\n').warnings == []


@pytest.mark.parametrize('scheme, warned', [('deterministic_adams_bashforth', True), ('mobility', True),
                                            ('deterministic_adams_bashforth_rollers', False)])
def test_domain_outside_a_roller_run_warns(scheme, warned):
    options = parse_input_text('scheme %s\ndomain no_wall\n' % scheme, 'in.dat')
    messages = [m for m in options.warnings if "'domain'" in m]
    assert bool(messages) == warned, options.warnings
    if warned:
        assert messages[0].startswith('in.dat, line 2')


@pytest.mark.parametrize('scheme, warned', [('deterministic_forward_euler', True), ('body_mobility', True),
                                            ('stochastic_adams_bashforth', False)])
def test_kT_with_a_deterministic_scheme_warns(scheme, warned):
    options = parse_input_text('scheme %s\nkT 0.5\n' % scheme, 'in.dat')
    messages = [m for m in options.warnings if "'kT'" in m]
    assert bool(messages) == warned, options.warnings


def test_warnings_reach_the_user(tmp_path):
    folder = dynamic_scene(tmp_path / 'run', n_steps=1, kT=1.0, domain='no_wall')
    status, _, err = run_in_process('dynamic', folder, 'inputfile_dynamic.dat')
    assert status == 0
    assert "warning: inputfile_dynamic.dat, line" in err and "'kT'" in err and "'domain'" in err, err


def test_repeated_option_warns():
    options = parse_input_text('dt 0.1\n\ndt 0.2\n', 'in.dat')
    assert options.dt == 0.2
    assert options.warnings and options.warnings[0].startswith("in.dat, line 3: option 'dt' repeats line 1")


@pytest.mark.parametrize('line', ['dt nan', 'eta inf', 'periodic_length 0 nan 0',
                                  'plot_velocity_field 0 inf 2 0 1 2 0 1 2'])
def test_non_finite_option_values_are_refused(line):
    with pytest.raises(utils.UserInputError, match='in.dat, line 1.*finite'):
        parse_input_text(line + '\n', 'in.dat')


# ====================================================================== restart keeps both segments
def test_restart_appends_inputfile_time_and_keeps_counters(tmp_path):
    folder = dynamic_scene(tmp_path / 'run', n_steps=5, n_save=5)
    status, _, _ = run_in_process('dynamic', folder, 'inputfile_dynamic.dat')
    assert status == 0
    first_input = (folder / 'data' / 'run.inputfile').read_text()
    edit_input(folder / 'inputfile_dynamic.dat', n_steps=10, initial_step=5)
    status, _, err = run_in_process('dynamic', folder, 'inputfile_dynamic.dat')
    assert status == 0, err
    both = (folder / 'data' / 'run.inputfile').read_text()
    assert both.startswith(first_input) and 'initial_step 5' in both[len(first_input):]
    times = [line for line in (folder / 'data' / 'run.time').read_text().splitlines() if line.strip()]
    assert len(times) == 2 and 'restart segment' in times[1]
    reference = dynamic_scene(tmp_path / 'whole', n_steps=10, n_save=5)
    assert run_in_process('dynamic', reference, 'inputfile_dynamic.dat')[0] == 0
    segments = run_output.read_info(str(folder / 'data' / 'run.info'))
    whole = run_output.read_info(str(reference / 'data' / 'run.info'))
    assert segments['deterministic_iterations_count'] == whole['deterministic_iterations_count']
    np.testing.assert_allclose(snapshot(folder, 10), snapshot(reference, 10), rtol=0, atol=1e-12)


# ====================================================================== output a person can use
def test_velocity_field_is_written_as_vectors(tmp_path):
    pyvista = pytest.importorskip('pyvista')
    folder = copy_scene(tmp_path / 'run')
    status, _, err = run_in_process('static', folder, 'inputfile.dat')
    assert status == 0, err
    path = folder / 'data' / 'run.velocity_field.vtk'
    assert 'VECTORS velocity' in path.read_text()
    mesh = pyvista.read(str(path))
    assert mesh.active_vectors_name == 'velocity'
    assert mesh.active_vectors.shape == (12 * 16 * 6, 3)


class _Terminal(io.StringIO):
    def isatty(self):
        return True


def test_progress_on_a_terminal_uses_tqdm_with_rate_and_eta():
    pytest.importorskip('tqdm')
    stream = _Terminal()
    progress = run_loop.Progress('deterministic_forward_euler', 0, 10, stream=stream)
    assert progress.bar is not None
    for step in range(4):
        progress.after_step(step, iterations=3)
    progress.bar.refresh()
    text = stream.getvalue()
    progress.close()
    assert re.search(r'4/10 \[\d\d:\d\d<\d\d:\d\d', text), text  # elapsed < ETA
    assert 'step/s' in text


def test_progress_in_a_log_writes_lines_between_saves():
    stream = io.StringIO()
    progress = run_loop.Progress('deterministic_forward_euler', 0, 1000, log_interval=0.0, stream=stream)
    progress.at_save(0, 0)
    for step in range(3):
        progress.after_step(step, iterations=2)
    lines = stream.getvalue().splitlines()
    assert len(lines) == 4, lines
    assert all('elapsed' in line and 'left' in line and 'steps/s' in line for line in lines[1:])


# ====================================================================== README and docs
def code_blocks(markdown):
    return re.findall(r'```[a-z]*\n(.*?)```', markdown, flags=re.S)


def test_readme_commands_work_one_after_the_other(tmp_path):
    """The README's install-and-run and install-and-test commands, typed in sequence in one shell.

    The pip installs are replaced by ``true`` (the package is importable
    through PYTHONPATH) and the test run by ``--collect-only`` of one file.
    """
    import shutil
    clone = tmp_path / 'clone'
    shutil.copytree(REPO_ROOT, clone, ignore=shutil.ignore_patterns('.git', 'data', '__pycache__', '.pytest_cache'))
    blocks = [b.strip() for b in code_blocks((REPO_ROOT / 'README.md').read_text())]
    run_block = next(b for b in blocks if 'multi_bodies.py --input-file' in b)
    test_block = next(b for b in blocks if 'pytest' in b)
    script = '\n'.join([run_block, test_block])
    script = re.sub(r"python3 -m pip install -e \S+", 'true', script)
    script = script.replace('python3 -m pytest -q', 'python3 -m pytest -q --collect-only tests/test_quaternion.py')
    env = dict(os.environ, PYTHONPATH=str(clone))
    result = subprocess.run(['bash', '-e', '-c', script], cwd=str(clone), env=env, capture_output=True, text=True,
                            timeout=300)
    assert result.returncode == 0, result.stdout[-2000:] + result.stderr[-2000:]
    assert (clone / 'multi_bodies' / 'data' / 'run.info').exists()
    assert 'test_quaternion.py' in result.stdout


def documentation_pages():
    return sorted((REPO_ROOT / 'doc').glob('*.md')) + [REPO_ROOT / 'README.md']


def test_docs_cite_nothing_outside_the_repository():
    for page in documentation_pages():
        text = page.read_text()
        for name in ('VALIDATION.md', 'ARCHITECTURE.md', 'SPEC.md', 'USAGE.txt'):
            assert name not in text, '%s cites %s' % (page.name, name)


def test_files_named_in_the_docs_are_shipped():
    for page in documentation_pages():
        for name in set(re.findall(r'Structures/[\w.]+\.(?:vertex|clones|slip|dat)', page.read_text())):
            assert (SCRIPT_DIR / name).is_file(), '%s names %s, which is not shipped' % (page.name, name)


def test_roller_example_of_the_docs_runs(tmp_path):
    text = (REPO_ROOT / 'doc' / 'dynamics.md').read_text()
    block = next(b for b in code_blocks(text) if 'rollers' in b and 'structure' in b)
    shipped = [line for line in (SCRIPT_DIR / 'inputfile_rollers.dat').read_text().splitlines()
               if line.strip() and not line.startswith('#')]
    assert [line.split() for line in block.splitlines() if line.strip()] == [line.split() for line in shipped]
    folder = copy_scene(tmp_path / 'run')
    status, _, err = run_in_process('dynamic', folder, 'inputfile_rollers.dat')
    assert status == 0, err
    assert (folder / 'data' / 'rollers.four_rollers.00000050.clones').exists()


def test_static_docs_do_not_deny_the_compiled_blob_forces():
    from multi_bodies import multi_bodies_functions
    text = (REPO_ROOT / 'doc' / 'static_problems.md').read_text()
    assert 'not in this build' not in text
    assert callable(multi_bodies_functions.blob_blob_force_calculator('C++'))


def test_every_option_is_documented():
    text = (REPO_ROOT / 'doc' / 'options.md').read_text()
    documented = set(re.findall(r'^\| `(\w+)`', text, flags=re.M))
    missing = sorted((set(OPTION_TABLE) | {'structure'}) - documented)
    assert not missing, 'options missing from doc/options.md: %s' % missing


@pytest.mark.parametrize('line, fragment', [('eta 1e60', 'eta must be positive, between'),
                                            ('blob_radius 1e-320', 'blob_radius must be positive, between'),
                                            ('g 1e200', 'magnitude at most'),
                                            ('debye_length -0', 'debye_length must be positive'),
                                            ('debye_length_wall 0', 'debye_length_wall must be positive')])
def test_option_values_that_overflow_or_divide_by_zero_are_refused(line, fragment):
    """Found by tests/test_fuzz.py: these gave a singular matrix or a ZeroDivisionError deep in a solver."""
    with pytest.raises(utils.UserInputError, match='in.dat, line 1: .*' + fragment):
        parse_input_text(line + '\n', 'in.dat')


def test_coinciding_blobs_in_a_vertex_file_are_refused(tmp_path):
    """Found by tests/test_fuzz.py (a duplicated line and a fixed count): a singular blob mobility."""
    path = tmp_path / 'b.vertex'
    path.write_text('# two blobs at one point\n3\n0 0 0\n1 0 0\n0 0 0\n')
    from multi_bodies.files.structure_files import read_vertex_file
    with pytest.raises(utils.UserInputError, match='b.vertex, lines 3 and 5: two blobs at the same position'):
        read_vertex_file(str(path))


@pytest.mark.parametrize('name, value', [('n_relaxation', '3'), ('save_velocities', 'True')])
def test_options_without_effect_warn(name, value):
    options = parse_input_text('%s %s\n' % (name, value), 'in.dat')
    assert any(m.startswith("in.dat, line 1: option '%s'" % name) and 'no effect' in m for m in options.warnings)


@pytest.mark.parametrize('name, value', [('rf_delta', '1e-3'), ('update_PC', '5'), ('kT', '0.5')])
def test_stochastic_options_with_a_deterministic_scheme_warn(name, value):
    options = parse_input_text('scheme deterministic_adams_bashforth\n%s %s\n' % (name, value), 'in.dat')
    assert any(m.startswith("in.dat, line 2: option '%s' is ignored" % name) for m in options.warnings)
    quiet = parse_input_text('scheme stochastic_Slip_Trapz\n%s %s\n' % (name, value), 'in.dat')
    assert not any("option '%s'" % name in m for m in quiet.warnings)


def test_save_mobilities_writes_the_dense_matrices(tmp_path):
    """save_blobs_mobility / save_body_mobility write M (3N x 3N, symmetric) and N (6Nb x 6Nb) per saved step."""
    folder = dynamic_scene(tmp_path / 'run', n_steps=2, n_save=2, save_blobs_mobility='True',
                           save_body_mobility='True')
    status, _, err = run_in_process('dynamic', folder, 'inputfile_dynamic.dat')
    assert status == 0, err
    M = np.loadtxt(folder / 'data' / 'run.blobs_mobility.00000002.dat')
    N = np.loadtxt(folder / 'data' / 'run.body_mobility.00000000.dat')
    assert M.shape == (3 * 39, 3 * 39) and N.shape == (18, 18)
    np.testing.assert_allclose(M, M.T, atol=1e-12 * np.abs(M).max())
    assert np.all(np.linalg.eigvalsh(0.5 * (N + N.T)) > 0)


def test_zero_time_step_names_its_line(tmp_path):
    """Found by tests/test_fuzz.py: 'dt must be positive' named no file or line."""
    folder = dynamic_scene(tmp_path / 'run', n_steps=2, dt=0)
    status, _, err = run_in_process('dynamic', folder, 'inputfile_dynamic.dat')
    assert status == 2 and re.search(r'inputfile_dynamic.dat, line \d+: dt must be positive', err), err


def test_ctrl_c_outside_the_time_loop_is_one_line():
    def interrupted_main():
        raise KeyboardInterrupt
    err = io.StringIO()
    import contextlib
    with contextlib.redirect_stderr(err), pytest.raises(SystemExit) as stop:
        utils.fail_cleanly(interrupted_main)
    assert stop.value.code == 130
    assert len(err.getvalue().splitlines()) == 1 and 'SIGINT' in err.getvalue()
