"""Hostile inputs are refused in one line, within a bound on memory, before anything is written (issues 27, 48).

A byte that is not UTF-8 in any text file, ``.const`` expressions too long, too deep or not finite, a joint
of a body with itself, override sources and data files that are not files (FIFOs, folders, dangling links),
options and files that would make allocations of many gigabytes (``--bins 1e9``, a zip bomb, a header that
declares 10^12 values), output names the file system cannot hold, huge tokens, a full disk, numbers a solver
cannot take: each is one error line naming the file, line or option (exit 2; 1 for a failed write), never a
traceback.  The memory a refusal costs is measured in a child process against the same script's peak when
it does nothing.
"""
import importlib
import io
import os
import subprocess
import sys

import numpy as np
import pytest

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import utils  # noqa: E402
from run_scenes import REPO_ROOT, run_in_process  # noqa: E402
from safety_scenes import articulated_scene, driven_scene, run_dynamic, set_options_text  # noqa: E402

MCMC_SCRIPT = importlib.import_module('many_bodyMCMC.many_body_MCMC')


# ------------------------------------------------------------------ text files of every kind (issue 27)
@pytest.mark.parametrize('scene, name', [(articulated_scene, 'chain.const'), (articulated_scene, 'chain.list_vertex'),
                                         (articulated_scene, 'blob.vertex'), (articulated_scene, 'chain.clones'),
                                         (driven_scene, 'a.slip'), (driven_scene, 'b.velocity'),
                                         (driven_scene, 'a.clones'), (driven_scene, 'input.dat')])
def test_a_non_utf8_byte_in_any_text_file_is_the_same_one_line_refusal(tmp_path, scene, name):
    folder = scene(tmp_path / 'run')
    path = folder / name
    path.write_bytes(path.read_bytes().replace(b'\n', b' \xe9\n', 1))  # a Latin-1 e at the end of line 1
    status, out, err = run_dynamic(folder)
    assert status == 2 and 'Traceback' not in err + out and len(err.strip().splitlines()) == 1, err
    assert "%s', line 1: byte 0xe9 is not UTF-8 text; save the file as plain UTF-8 (or ASCII) text" % name in err, err


@pytest.mark.parametrize('expression, words', [('t+' * 200000 + 't', 'an expression of 400001 characters'),
                                               ('+'.join(['t'] * 80), 'nested more than 50 levels deep'),
                                               ('-' * 900 + 't', 'nested more than 50 levels deep')])
def test_const_expressions_have_a_size_and_depth_limit(tmp_path, expression, words):
    folder = articulated_scene(tmp_path / 'run')
    (folder / 'chain.const').write_text('2\n1\n0 1 0.5 0 0 -0.5 0 0 %s 0 0 -0.5 0 0 0 0 0 0 0 0\n' % expression)
    status, out, err = run_dynamic(folder)
    assert status == 2 and 'Traceback' not in err + out and len(err.strip().splitlines()) == 1, err
    assert 'chain.const, line 3: ' in err and words in err, err


# ------------------------------------------------------------------ .const joints (issue 48)
def test_a_joint_of_a_body_with_itself_is_refused(tmp_path):
    """A .const joint of body 0 with body 0 ran to the end with the joint never satisfied."""
    folder = articulated_scene(tmp_path / 'run')
    (folder / 'chain.const').write_text('2\n2\n0 1 0.5 0 0 -0.5 0 0\n1 1 0.5 0 0 -0.5 0 0\n')
    status, out, err = run_dynamic(folder)
    assert status == 2 and 'Traceback' not in out + err and len(err.strip().splitlines()) == 1, err
    assert 'chain.const, line 4: a joint of body 1 with itself' in err, err
    assert not (folder / 'data').exists()


@pytest.mark.parametrize('expression, status, words', [
    ('0.1*log(t)', 2, "chain.const, line 3: the expression '0.1*log(t)' is -inf at t = 0.0"),
    ('sqrt(0.025-t)', 1, "chain.const, line 3: the expression 'sqrt(0.025-t)' is nan at t = 0.03"),
    ('1e308', 2, "chain.const, line 3: the expression '1e308' is 1e+308 at t = 0.0, not a finite number of magnitude "
                 "at most 1e+150"),  # found by the fuzzer: the joint algebra overflowed (a ValueError traceback)
])
def test_a_non_finite_const_expression_is_named(tmp_path, expression, status, words):
    """A joint vector that is not finite (at the start: refused; later: the run stops) was blamed on the blob
    spacing ('the blobs of a body are too close'); now the message names the file, the line and the expression."""
    folder = articulated_scene(tmp_path / 'run', n_steps=6, n_save=1)
    (folder / 'chain.const').write_text('2\n1\n0 1 0.5 0 0 -0.5 0 0 0.5 0 0 -0.5 0 %s 0 0 0 0 0 0\n' % expression)
    code, out, err = run_dynamic(folder)
    assert code == status and 'Traceback' not in out + err, err
    assert words in err and 'too close' not in err, err
    assert len([line for line in err.splitlines() if line.startswith('error:')]) == 1, err


# ------------------------------------------------------------------ override sources that are not files (issue 48)
@pytest.mark.parametrize('kind', ['dangling symlink', 'fifo', 'folder'])
@pytest.mark.parametrize('program', ['dynamic', 'static'])
def test_an_override_source_that_is_not_a_file_is_refused(tmp_path, kind, program):
    """A user_defined_functions.py that is a dangling link, a FIFO or a folder was skipped without a word and the
    default physics used; now it is a one-line refusal naming it, before any file is written."""
    folder = driven_scene(tmp_path / 'run')
    if program == 'static':
        (folder / 'input.dat').write_text(set_options_text(folder, scheme='mobility'))
    path = folder / 'user_defined_functions.py'
    if kind == 'dangling symlink':
        path.symlink_to(folder / 'moved_away.py')
    elif kind == 'fifo':
        os.mkfifo(str(path))
    else:
        path.mkdir()
    status, out, err = run_in_process(program, folder, 'input.dat')
    assert status == 2 and 'Traceback' not in out + err, err
    assert len([line for line in err.splitlines() if not line.startswith('warning:')]) == 1, err
    assert 'user_defined_functions.py is %s' % {'dangling symlink': 'a symbolic link to a missing file',
                                               'fifo': 'a FIFO', 'folder': 'a folder'}[kind] in err, err
    assert not (folder / 'data').exists()


def test_a_potential_source_that_is_not_a_file_is_refused(tmp_path, monkeypatch, capsys):
    from safety_scenes import mcmc_scene
    folder = mcmc_scene(tmp_path / 'run')
    os.mkfifo(str(folder / 'user_defined_potentials.py'))
    monkeypatch.chdir(folder)
    with pytest.raises(SystemExit) as stop:
        utils.fail_cleanly(MCMC_SCRIPT.main, ['input.dat'])
    err = capsys.readouterr().err
    assert stop.value.code == 2 and 'user_defined_potentials.py is a FIFO' in err, err


@pytest.mark.parametrize('kind, words', [('fifo', 'is a FIFO, not a file'), ('dangling symlink', 'is a symbolic link '
                                                                                      'to a missing file')])
def test_a_data_file_that_is_a_fifo_or_a_dangling_link_is_named_as_such(tmp_path, kind, words):
    """A vertex file that is a FIFO (or a device) was reported 'not found'; it is now named for what it is, and
    never read (a FIFO read blocks for ever)."""
    folder = driven_scene(tmp_path / 'run')
    (folder / 'blob.vertex').unlink()
    if kind == 'fifo':
        os.mkfifo(str(folder / 'blob.vertex'))
    else:
        (folder / 'blob.vertex').symlink_to(folder / 'elsewhere.vertex')
    status, out, err = run_dynamic(folder)
    assert status == 2 and 'Traceback' not in out + err and 'blob.vertex' in err and words in err, err


# ------------------------------------------------------------------ hostile inputs bounded up front (issue 48)
PEAK_MARGIN_KIB = 100 * 1024  # a refused hostile input costs less than 100 MB above the interpreter's own peak


def peak_kib(arguments, cwd):
    """(exit status, stderr, peak resident KiB) of ``arguments`` run as a grandchild, its peak measured alone."""
    probe = ('import resource, subprocess, sys; p = subprocess.run(sys.argv[1:], capture_output=True, text=True); '
             'sys.stderr.write(p.stderr); print(p.returncode, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)')
    from run_scenes import child_environment
    done = subprocess.run([sys.executable, '-c', probe] + list(arguments), cwd=str(cwd), capture_output=True,
                          text=True, timeout=300, env=child_environment())
    status, peak = done.stdout.split()[-2:]
    return int(status), done.stderr, int(peak)


def npy_member(shape, data=b''):
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {'descr': '<f8', 'fortran_order': False, 'shape': shape})
    return header.getvalue() + data


def _msd_file(kind, path):
    import zipfile
    if kind == 'header of 10^12 values':  # 884 bytes that declare 8 TB
        with zipfile.ZipFile(path, 'w') as archive:
            for name, shape in (('times', (10 ** 12,)), ('msd', (10 ** 12, 6, 6)), ('msd_error', (10 ** 12, 6, 6))):
                archive.writestr(name + '.npy', npy_member(shape))
    elif kind == 'zip bomb':  # a few hundred kB that inflate to 300 MB (honest headers)
        lags = 10 ** 6
        with zipfile.ZipFile(path, 'w', compression=zipfile.ZIP_DEFLATED) as archive:
            for name, shape in (('times', (lags,)), ('msd', (lags, 6, 6)), ('msd_error', (lags, 6, 6))):
                with archive.open(name + '.npy', 'w', force_zip64=True) as member:
                    member.write(npy_member(shape))
                    left = int(np.prod(shape)) * 8
                    zeros = bytes(1 << 22)
                    while left > 0:
                        member.write(zeros[:min(left, len(zeros))])
                        left -= len(zeros)
    else:  # 'wrong msd shape'
        np.savez(path, times=np.arange(5.0), msd=np.ones((5, 6)), msd_error=np.ones((5, 6, 6)))


def _analysis_run(folder):
    from test_analysis import ideal_gas, write_run
    (folder / 'data').mkdir(parents=True)
    write_run(folder / 'data', ideal_gas(12, 40, (8, 8, 2), seed=70), one_file=True)
    (folder / 'in.dat').write_text('scheme stochastic_first_order_RFD\ndt 0.1\nn_save 5\nperiodic_length 8 8 0\n'
                                   'output_name data/run\nsave_clones one_file\nstructure b.vertex blobs.clones\n')


ANALYSE = str(REPO_ROOT / 'multi_bodies' / 'analyse.py')
HOSTILE = {  # case: (script, its arguments, words of the one error line)
    'msd header of 10^12 values': ('plot', ['msd.npz'], 'declares 1000000000000 values'),
    'msd zip bomb': ('plot', ['msd.npz'], 'a zip bomb'),
    'msd wrong msd shape': ('plot', ['msd.npz'], 'msd (5, 6)'),
    'analyse bins 10^9': ('analyse', ['--gr', '--bins', '1000000000'], '--bins 1000000000: g(r) in'),
    'analyse k-index-max 10^5': ('analyse', ['--sk', '--k-index-max', '100000'], '--k-index-max 100000: S(k)'),
    'analyse k-values 10^6': ('analyse', ['--fkt', '--k-values', '1e6'], '--k-values: the box of wavevectors'),
    'analyse stride 0': ('analyse', ['--msd', '--stride', '0'], '--stride 0: it must be an integer >= 1'),
    'analyse NaN positions': ('analyse', ['--msd'], 'run.blobs.config: the snapshot at byte'),
    'HydroGrid cells 100000 100000': ('dynamic', ['--input-file', 'inputfile.dat'], 'cells 100000 100000: S(k)'),
}


@pytest.mark.parametrize('case', sorted(HOSTILE))
def test_a_hostile_input_is_refused_in_one_line_within_its_memory_bound(tmp_path, case):
    """An allocation that data or options size is bounded before it is made: --bins 1e9 once grew to 19 GB, a
    HydroGrid cells 100000 100000 asked for 37 GiB, an 884-byte .npz declared 10^12 floats, a 2.3 MB zip bomb
    inflated to 2.35 GB before its refusal, --stride 0 divided by zero, NaN positions gave a NaN MSD and exit 0.
    Each is now one line naming the option or file (exit 2), and costs under 100 MB above the same script's peak
    when it does nothing (--help: the imports)."""
    script, arguments, words = HOSTILE[case]
    folder = tmp_path / 'case'
    folder.mkdir()
    if script == 'plot':
        _msd_file(case[4:], folder / 'msd.npz')
        command = [str(REPO_ROOT / 'boomerang' / 'plot_boomerang_msd.py')]
        arguments = arguments + ['--output', str(folder / 'msd.png')]
    elif script == 'analyse':
        _analysis_run(folder)
        if 'NaN' in case:
            path = folder / 'data' / 'run.blobs.config'
            lines = path.read_text().splitlines()
            lines[3] = 'nan ' + lines[3].split(None, 1)[1]
            path.write_text('\n'.join(lines) + '\n')
        command = [ANALYSE]
        arguments = ['--input-file', 'in.dat', '--no-charts'] + arguments
    else:
        from test_analysis import make_hydrogrid_run
        make_hydrogrid_run(folder)
        path = folder / 'inputfile.dat'
        path.write_text(path.read_text().replace('cells 8 8', 'cells 100000 100000'))
        command = [str(REPO_ROOT / 'multi_bodies' / 'multi_bodies.py')]
    status, err, peak = peak_kib([sys.executable] + command + arguments, folder)
    _, _, idle = peak_kib([sys.executable] + command + ['--help'], folder)
    lines = [line for line in err.splitlines() if line.startswith('error:')]
    assert status == 2 and 'Traceback' not in err and len(lines) == 1 and words in lines[0], err
    assert peak < idle + PEAK_MARGIN_KIB, (peak, idle)
    if script == 'dynamic':
        assert not (folder / 'data').exists()


@pytest.mark.parametrize('output_name, words', [
    ('/proc/run', '/proc/run.lock: cannot create the lock file'),
    ('data/' + 'x' * 300, 'output_name is'),
    ('/'.join(['d'] * 2000) + '/run', 'choose a shorter output_name'),
    ('x' * 10 ** 7, 'choose a shorter output_name'),
], ids=['proc', '300 characters', '2000 folders deep', '10 MB'])
def test_an_output_name_the_file_system_cannot_hold_is_one_line(tmp_path, output_name, words):
    """/proc/run, a 300-character name, 2,000 folders deep (a RecursionError in makedirs) and a 10 MB name: one
    line naming output_name, short (a huge word of a message is cut to its ends), nothing written."""
    folder = driven_scene(tmp_path / 'run')
    (folder / 'input.dat').write_text(set_options_text(folder, output_name=output_name))
    status, out, err = run_dynamic(folder)
    assert status == 2 and 'Traceback' not in out + err and len(err.strip().splitlines()) == 1, err[:2000]
    assert 'input.dat, line' in err and words in err and len(err) < 2000, err[:2000]
    assert not (folder / 'd').exists() and not (folder / 'data').exists()


@pytest.mark.parametrize('where', ['option value', 'option name', 'clones token'])
def test_an_error_line_never_echoes_a_huge_token(tmp_path, where):
    """A 100 MB token was echoed whole in the error line; now a word of a message longer than 400 characters is
    shown by its ends and its length (10 MB here, the same rule)."""
    folder = driven_scene(tmp_path / 'run')
    token = 'x' * 10 ** 7
    if where == 'option value':
        (folder / 'input.dat').write_text(set_options_text(folder, dt=token))
    elif where == 'option name':
        (folder / 'input.dat').write_text(set_options_text(folder) + token + ' 1\n')
    else:
        (folder / 'a.clones').write_text('1\n%s 0 2 1 0 0 0\n' % token)
    status, out, err = run_dynamic(folder)
    assert status == 2 and 'Traceback' not in out + err and len(err.strip().splitlines()) == 1, err[:2000]
    assert len(err) < 2000 and ' characters]...' in err, err[:2000]


@pytest.mark.parametrize('program', ['dynamic', 'static', 'mcmc'])
def test_a_full_disk_before_the_first_save_is_one_line_naming_the_file(tmp_path, program):
    """A disk full before the first save (here a 100-byte file-size limit: the .inputfile copy fails) gave a
    traceback; now one line names the file (exit 1)."""
    import resource
    import signal
    from safety_scenes import mcmc_scene
    from run_scenes import child_environment
    folder = (mcmc_scene if program == 'mcmc' else driven_scene)(tmp_path / 'run')
    if program == 'static':
        (folder / 'input.dat').write_text(set_options_text(folder, scheme='mobility'))
    script = {'dynamic': ['multi_bodies', 'multi_bodies.py'], 'static': ['multi_bodies', 'multi_bodies_utilities.py'],
              'mcmc': ['many_bodyMCMC', 'many_body_MCMC.py']}[program]

    def limited():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (100, 100))
    arguments = [sys.executable, str(REPO_ROOT.joinpath(*script))] + \
        (['input.dat'] if program == 'mcmc' else ['--input-file', 'input.dat'])
    done = subprocess.run(arguments, cwd=str(folder), env=child_environment(), capture_output=True, text=True,
                          preexec_fn=limited, timeout=300)
    lines = [line for line in done.stderr.splitlines() if line.startswith('error:')]
    assert done.returncode == 1 and 'Traceback' not in done.stderr and len(lines) == 1, done.stderr
    assert 'cannot write data/run.inputfile' in lines[0] and 'File too large' in lines[0], done.stderr


@pytest.mark.parametrize('edit, words', [
    (lambda folder: (folder / 'input.dat').write_text(set_options_text(folder, nonlinear_solver_tolerance='1e-17')),
     'nonlinear_solver_tolerance must be at least 2.2205e-16'),
    (lambda folder: (folder / 'blob.vertex').write_text('1\n0 0 0 1e-300\n'),
     'blob.vertex, line 2: blob radius 1e-300 in the fourth column; a radius must lie between 1e-50 and 1e+50'),
])
def test_numbers_a_solver_cannot_take_are_refused(tmp_path, edit, words):
    """nonlinear_solver_tolerance 1e-17 (SciPy's least squares raised) and a blob radius of 1e-300 (NaN in the
    Lanczos noise) gave tracebacks; now one line each, before anything is written."""
    folder = articulated_scene(tmp_path / 'run') if 'nonlinear' in words else driven_scene(tmp_path / 'run')
    edit(folder)
    status, out, err = run_dynamic(folder)
    assert status == 2 and 'Traceback' not in out + err and len(err.strip().splitlines()) == 1, err
    assert words in err, err
    assert not (folder / 'data').exists()


def test_a_nul_byte_in_a_file_name_of_the_input_is_one_line(tmp_path):
    """Found by the fuzzer (issue 48): a NUL byte in a slip file's name made os.stat raise ValueError (a
    traceback) when the reader asked what the path was."""
    folder = driven_scene(tmp_path / 'run')
    text = (folder / 'input.dat').read_text().replace('a.slip', 'a.s\x00lip')
    (folder / 'input.dat').write_text(text)
    status, out, err = run_dynamic(folder)
    assert status == 2 and 'Traceback' not in out + err and len(err.strip().splitlines()) == 1, err
    assert 'holds a NUL byte' in err, err
