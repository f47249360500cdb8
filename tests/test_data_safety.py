"""Data files never run code (issue 17).

A pickle can run any callable while it is read (``__reduce__``).  Each file
kind a run reads back (``.random_state``, ``.restart`` of a dynamic run, of a
Monte Carlo run and of an ensemble replica) is planted with a pickle whose
``__reduce__`` would create a marker folder; the run must refuse the file
with a clear message (exit status 2, no traceback) and the marker must never
appear.  A negative control shows that the payload is live (plain
``pickle.loads`` does create the marker).  The published code's pickled
``numpy.random.RandomState().get_state()`` is still accepted, by a reader
that admits only numpy arrays and dtypes; that reader stays within a memory
bound on hostile pickles, and degenerate generator states are refused
(issue 27).

The restart's fingerprint and forged records are tested in
``test_restart_checks.py``, hostile inputs in ``test_hostile_inputs.py``, the
ensemble's folders in ``test_ensemble_safety.py``.
"""
import hashlib
import importlib
import io
import os
import pickle
import shutil
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import utils  # noqa: E402
from multi_bodies.ensembles import ensemble_runner as runner  # noqa: E402
from multi_bodies.files.snapshots import write_clones_file  # noqa: E402
from multi_bodies.files.structure_files import write_vertex_file  # noqa: E402
from multi_bodies.run import run_output  # noqa: E402
from run_scenes import REPO_ROOT, copy_scene, edit_input, run_in_process  # noqa: E402
from safety_scenes import driven_scene, run_dynamic, set_options_text  # noqa: E402

MCMC_SCRIPT = importlib.import_module('many_bodyMCMC.many_body_MCMC')


class Payload:
    """Unpickling this calls ``os.mkdir(marker)``: the stand-in for any code a crafted file would run."""

    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        return (os.mkdir, (self.marker,))


def payload_bytes(marker, protocol=pickle.HIGHEST_PROTOCOL):
    return pickle.dumps({'step': 5, 'state': Payload(marker)}, protocol=protocol)


def assert_refused(status, out, err, marker, *words):
    assert not os.path.exists(marker), 'the payload ran'
    assert status == 2, (status, out[-2000:], err[-2000:])
    assert 'Traceback' not in err and 'Traceback' not in out
    for word in words:
        assert word in err, err


def test_negative_control_the_payload_is_live(tmp_path):
    """Without the safe readers the payload runs: plain pickle.loads creates the marker."""
    marker = tmp_path / 'marker'
    pickle.loads(payload_bytes(marker))
    assert marker.is_dir()


# ------------------------------------------------------------------ .random_state
def dynamic_scene(folder, **options):
    copy_scene(folder)
    edit_input(Path(folder) / 'inputfile_dynamic.dat', **options)
    return Path(folder)


@pytest.mark.parametrize('protocol', [0, 2, pickle.HIGHEST_PROTOCOL])
def test_random_state_payload_never_runs(tmp_path, protocol):
    folder = dynamic_scene(tmp_path / 'run', n_steps=2)
    marker = tmp_path / 'marker'
    (folder / 'evil.random_state').write_bytes(pickle.dumps(Payload(marker), protocol=protocol))
    edit_input(folder / 'inputfile_dynamic.dat', random_state='evil.random_state')
    status, out, err = run_in_process('dynamic', folder, 'inputfile_dynamic.dat')
    assert_refused(status, out, err, marker, 'random_state', 'evil.random_state', 'posix.mkdir')
    assert not (folder / 'data').exists()


def test_random_state_payload_inside_a_published_looking_tuple_never_runs(tmp_path):
    marker = tmp_path / 'marker'
    state = np.random.RandomState(1).get_state()
    path = tmp_path / 'evil.random_state'
    path.write_bytes(pickle.dumps((state[0], state[1], state[2], state[3], Payload(marker))))
    with pytest.raises(utils.UserInputError, match='nothing in it was run'):
        run_output.load_random_state(str(path))
    assert not marker.exists()


@pytest.mark.parametrize('protocol', [0, 2, pickle.HIGHEST_PROTOCOL])
def test_published_random_state_pickle_is_accepted(tmp_path, protocol):
    """The published file: a pickle of RandomState().get_state(); the same state gives the same MT19937 stream."""
    published = np.random.RandomState(2026)
    published.standard_normal(3)  # a state with has_gauss = 1 and pos != 624
    state = published.get_state()
    path = tmp_path / 'published.random_state'
    path.write_bytes(pickle.dumps(state, protocol=protocol))
    read = run_output.read_random_state(str(path))
    assert read[0] == 'MT19937' and read[2:4] == state[2:4] and read[4] == state[4]
    np.testing.assert_array_equal(read[1], state[1])
    generator = run_output.load_random_state(str(path))
    assert isinstance(generator.bit_generator, np.random.MT19937)
    # numpy's law: a RandomState on the bit generator of that state draws what RandomState(2026) draws next
    # (raw 32-bit words do not depend on the cached Gaussian)
    np.testing.assert_array_equal(np.random.RandomState(generator.bit_generator).randint(0, 2 ** 31, 20),
                                  published.randint(0, 2 ** 31, 20))


def test_random_state_file_is_json_and_restores_the_generator(tmp_path):
    rng = np.random.default_rng(11)
    rng.standard_normal(7)
    path = str(tmp_path / 'run.random_state')
    run_output.save_random_state(path, rng)
    assert open(path, 'rb').read().lstrip()[:1] == b'{'  # text, not a pickle
    restored = run_output.load_random_state(path)
    np.testing.assert_array_equal(restored.standard_normal(50), rng.standard_normal(50))
    mt = np.random.Generator(np.random.MT19937(3))
    run_output.save_random_state(path, mt)
    np.testing.assert_array_equal(run_output.load_random_state(path).random(20), mt.random(20))


# ------------------------------------------------------------------ .restart of a dynamic run
@pytest.fixture
def dynamic_run(tmp_path):
    folder = dynamic_scene(tmp_path / 'run', n_steps=5, n_save=5)
    status, _, err = run_in_process('dynamic', folder, 'inputfile_dynamic.dat')
    assert status == 0, err
    edit_input(folder / 'inputfile_dynamic.dat', n_steps=6, initial_step=5)
    return folder


def test_dynamic_restart_payload_never_runs(dynamic_run, tmp_path):
    marker = tmp_path / 'marker'
    (dynamic_run / 'data' / 'run.restart').write_bytes(payload_bytes(marker))
    status, out, err = run_in_process('dynamic', dynamic_run, 'inputfile_dynamic.dat')
    assert_refused(status, out, err, marker, 'run.restart', 'not a restart file')


def test_dynamic_restart_record_with_a_flipped_bit_is_refused(dynamic_run):
    path = dynamic_run / 'data' / 'run.restart'
    data = bytearray(path.read_bytes())
    step, start, end = run_output.restart_index(str(path))[-1]
    assert step == 5
    data[(start + end) // 2] ^= 0x04
    path.write_bytes(bytes(data))
    status, out, err = run_in_process('dynamic', dynamic_run, 'inputfile_dynamic.dat')
    assert status == 2 and 'Traceback' not in err and 'checksum' in err and 'step 5' in err, err


def test_dynamic_restart_record_cut_by_a_hard_stop_is_skipped_with_a_message(dynamic_run):
    """With restart_inexact (issue 17: without it the restart is refused, see test_crash_safety.py)."""
    path = dynamic_run / 'data' / 'run.restart'
    _, start, end = run_output.restart_index(str(path))[-1]
    path.write_bytes(path.read_bytes()[:(start + end) // 2])
    edit_input(dynamic_run / 'inputfile_dynamic.dat', restart_inexact='True')
    status, out, err = run_in_process('dynamic', dynamic_run, 'inputfile_dynamic.dat')
    assert status == 0, err
    assert 'cut short' in err and 'no restart record' in out + err


def test_restart_records_round_trip_exactly(tmp_path):
    """Arrays (any dtype, shape), tuples, big ints, nan and non-string keys come back as they went in."""
    state = {'rng': np.random.default_rng(3).bit_generator.state, 'a': np.arange(12.0).reshape(3, 4) / 7,
             'b': (1, 2.5, None, 'x', np.float64(np.pi), np.int32(-4)), 'c': [np.nan, float('inf'), True],
             'd': {1: 'one', (2, 3): np.zeros(0, dtype=np.uint32)}, '__e': 2 ** 130}
    writer = run_output.SnapshotWriter(str(tmp_path / 'run'), 'one_file', [('a', 1)])
    writer.save(0, np.zeros((1, 3)), np.array([[1.0, 0, 0, 0]]), state)
    record = run_output.restart_record(str(tmp_path / 'run'), 0)['state']
    assert record['rng'] == state['rng'] and record['__e'] == state['__e']
    assert record['a'].dtype == np.float64 and np.array_equal(record['a'], state['a'])
    assert record['b'][:4] == state['b'][:4] and type(record['b'][4]) is np.float64 and record['b'][4] == np.pi
    assert type(record['b'][5]) is np.int32 and record['b'][5] == -4
    assert np.isnan(record['c'][0]) and record['c'][1:] == [float('inf'), True]
    assert record['d'][1] == 'one' and record['d'][(2, 3)].dtype == np.uint32


def test_finding_one_record_reads_headers_only(tmp_path):
    """10,000 records: the index holds every step, and one record is found without reading the others."""
    path = tmp_path / 'run.restart'
    payload = b'x' * 1000
    header = run_output.RECORD_HEADER
    with open(path, 'wb') as f:
        f.write(run_output.RESTART_MAGIC)
        for step in range(10000):
            f.write(header.pack(run_output.RECORD_TAG, step, len(payload), hashlib.sha256(payload).digest()))
            f.write(payload)
    entries = run_output.restart_index(str(path))
    assert [e[0] for e in entries] == list(range(10000))
    assert entries[-1][2] == os.path.getsize(path)


# ------------------------------------------------------------------ .restart of a Monte Carlo run
def test_mcmc_restart_payload_never_runs(tmp_path, monkeypatch, capsys):
    write_vertex_file(tmp_path / 'blob.vertex', np.zeros((1, 3)))
    write_clones_file(tmp_path / 'blob.clones', [[0.0, 0.0, 1000.0]], [[1.0, 0, 0, 0]])
    options = {'n_steps': 10, 'n_save': 5, 'kT': 1.0, 'g': 1.0, 'blob_radius': 0.5, 'repulsion_strength_wall': 0.0,
               'max_translation': 1.0, 'seed': 5, 'output_name': 'data/run'}
    text = '\n'.join('%s %s' % item for item in options.items()) + '\nstructure blob.vertex blob.clones\n'
    (tmp_path / 'input.dat').write_text(text)
    monkeypatch.chdir(tmp_path)
    assert MCMC_SCRIPT.main(['input.dat']) == 0
    marker = tmp_path / 'marker'
    (tmp_path / 'data' / 'run.restart').write_bytes(payload_bytes(marker))
    (tmp_path / 'input.dat').write_text(text.replace('n_steps 10', 'n_steps 15') + 'initial_step 10\n')
    capsys.readouterr()
    with pytest.raises(SystemExit) as stop:
        utils.fail_cleanly(MCMC_SCRIPT.main, ['input.dat'])
    captured = capsys.readouterr()
    assert_refused(stop.value.code, captured.out, captured.err, marker, 'run.restart', 'not a restart file')


# ------------------------------------------------------------------ .restart of an ensemble replica
def test_ensemble_replica_restart_payload_never_runs(tmp_path):
    folder = tmp_path / 'scene'
    folder.mkdir()
    shutil.copy(os.path.join(REPO_ROOT, 'multi_bodies', 'Structures', 'shell_N_12_Rg_1.vertex'), folder)
    (folder / 'spheres.clones').write_text('1\n0 0 3 1 0 0 0\n')
    (folder / 'input.dat').write_text(textwrap.dedent('''\
        scheme deterministic_forward_euler
        mobility_blobs_implementation python
        mobility_vector_prod_implementation python
        blob_blob_force_implementation python
        dt 0.05
        n_steps 4
        n_save 2
        eta 1.0
        blob_radius 0.25
        output_name data/run
        structure shell_N_12_Rg_1.vertex spheres.clones
        '''))
    plan = runner.build_plan(str(folder / 'input.dat'), 1, (), str(tmp_path / 'ensemble'), 7)
    runner.write_plan(plan)
    spec = runner.replica_specs(plan)[0]
    marker = tmp_path / 'marker'
    Path(spec['path'], 'run.restart').write_bytes(payload_bytes(marker))  # as a kill would leave it to resume
    result = runner.run_replica(spec)
    assert not marker.exists(), 'the payload ran'
    assert result['status'] == 'failed' and result['exit_status'] == 2, result
    assert 'not a restart file' in result['message']
    assert 'Traceback' not in Path(spec['path'], runner.LOG_NAME).read_text()


def test_no_pickle_reader_outside_the_restricted_one():
    """``git grep`` law of the issue: no pickle.load(s) or allow_pickle=True in the package, tests aside."""
    found = []
    for root, _, names in os.walk(REPO_ROOT):
        parts = os.path.relpath(root, REPO_ROOT).split(os.sep)
        # the package's own files: not hidden folders (.git, the CI's .venv and .venv-oldest), tests or builds
        if any(part.startswith('.') and part != '.' or part in ('tests', 'build', '__pycache__', 'site-packages')
               for part in parts):
            continue
        for name in names:
            if name.endswith('.py'):
                text = io.open(os.path.join(root, name), encoding='utf-8', errors='replace').read()
                for bad in ('pickle.load(', 'pickle.loads(', 'allow_pickle=True'):
                    if bad in text:
                        found.append((name, bad))
    assert found == []


# ------------------------------------------------------------------ bounded published pickles (issue 27)
HOSTILE_PICKLES = [
    b'\x80\x02cnumpy\nndarray\nJ\x80\xb2\xe6\x0e\x85cnumpy\ndtype\nX\x02\x00\x00\x00O8\x85R\x86R.',  # 2.5e8 objects
    b'\x80\x02cnumpy\nndarray\nJ\x00\xca\x9a;\x85R.',                                               # 1e9 doubles
    b'\x80\x02cnumpy.core.multiarray\n_reconstruct\ncnumpy\nndarray\nK\x00\x85C\x01b\x87R'             # BUILD 2**30
    b'(K\x01J\x00\x00\x00@\x85cnumpy\ndtype\nX\x02\x00\x00\x00f8\x85R\x89C\x00tb.',
    b'\x80\x02N\x94r\xff\xff\xff\x07.',                                                             # memo 2**27
    b'\x80\x02Np99999999\n.',                                                                       # memo 1e8
    b'\x80\x02cnumpy.core.numeric\n_frombuffer\nC\x00cnumpy\ndtype\nX\x02\x00\x00\x00f8\x85R'
    b'J\x00\xca\x9a;\x85X\x01\x00\x00\x00C\x94R.',                                                  # frombuffer 1e9
    b'\x80\x02cnumpy\ndtype\nX\x0b\x00\x00\x00V1000000000\x85R.',                                   # 1 GB void dtype
    b'\x80\x02X\xff\xff\xff\x7fabc.',                                                               # 2 GB string
    b'\x80\x04\x95\xff\xff\xff\xff\xff\xff\x00\x00N.',                                              # 2**48 frame
    b'(' * 900 + b'.',
]

MEMORY_PROBE = '''
import random, resource, sys
sys.path.insert(0, sys.argv[1])
import numpy as np, pickle
from multi_bodies.run.run_state import read_published_state
cases = eval(sys.argv[2])
rng = random.Random(27)
valid = [pickle.dumps(np.random.RandomState(1).get_state(), protocol=p)[:1000] for p in range(6)]
for _ in range(3000):  # byte mutations of the hostile and of cut valid pickles, all under 1 kB
    data = bytearray(rng.choice(cases + valid))
    for _ in range(rng.randint(1, 6)):
        data[rng.randrange(len(data))] = rng.randrange(256)
    cases.append(bytes(data))
base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
accepted = 0
for data in cases:
    assert len(data) < 1024
    try:
        read_published_state(data)
        accepted += 1
    except Exception:
        pass
print(len(cases), accepted, (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - base) / 1024.0)
'''


def test_published_pickle_reader_stays_under_100_MB_on_hostile_inputs_under_1_kB():
    """Issue 27: shapes, dtypes, memo indices and sizes beyond a published state are refused before any allocation
    (the 42-byte pickle of 2.5e8 objects once took 2 GB).  Measured: peak resident growth of a child process."""
    import subprocess
    result = subprocess.run([sys.executable, '-c', MEMORY_PROBE, str(REPO_ROOT), repr(HOSTILE_PICKLES)],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    count, accepted, growth_mib = result.stdout.split()
    assert int(count) > 3000 and int(accepted) == 0 and float(growth_mib) < 100, result.stdout


@pytest.mark.parametrize('data', HOSTILE_PICKLES)
def test_hostile_published_pickles_are_one_line_refusals(tmp_path, data):
    path = tmp_path / 'hostile.random_state'
    path.write_bytes(data)
    with pytest.raises(utils.UserInputError, match='nothing in it was run or used'):
        run_output.read_random_state(str(path))


@pytest.mark.parametrize('change, words', [
    (lambda s: (s[0], np.zeros(624, np.uint32)) + s[2:], 'every bit of the MT19937 state is 0'),
    (lambda s: (s[0], np.eye(1, 624, 0, np.uint32)[0]) + s[2:], 'every bit of the MT19937 state is 0'),
    (lambda s: (s[0], np.eye(1, 624, 7, np.uint32)[0]) + s[2:], 'has 1 of its 19937 bits set'),
    (lambda s: (s[0], np.full(624, 0xFFFFFFFF, np.uint32)) + s[2:], 'has 19937 of its 19937 bits set'),
    (lambda s: (s[0], np.full(624, 2 ** 40, np.int64)) + s[2:], 'outside 0 .. 2**32 - 1'),
    (lambda s: s[:3] + (1, float('nan')), 'cached Gaussian'),
    (lambda s: s[:3] + (2, 0.0), 'has_gauss'),
    (lambda s: s[:2] + (625,) + s[3:], 'position'),
])
def test_degenerate_published_states_are_refused(tmp_path, change, words):
    """A generator whose every draw is 0.0 (all-zero key, keys cast to zeros; keys [1, 0, ...], whose only set bit
    is one MT19937 never uses), a state of a single bit set or every bit set (far from random for thousands of
    draws), or a NaN cached Gaussian is refused (Matsumoto and Nishimura 1998: the state is the top bit of key 0
    and keys 1 to 623)."""
    path = tmp_path / 'degenerate.random_state'
    path.write_bytes(pickle.dumps(change(np.random.RandomState(3).get_state()), protocol=2))
    with pytest.raises(utils.UserInputError, match=words.replace('*', r'\*')):
        run_output.read_random_state(str(path))


def test_seeded_mt19937_states_pass_the_degenerate_state_check():
    """The bound (a quarter to three quarters of the 19,937 state bits set) passes every seeded state: a binomial
    count of fair bits is 9,968 +- 71, seventy standard deviations inside it."""
    from multi_bodies.run.run_state import mt19937_key_problem
    for seed in range(200):
        legacy = np.random.RandomState(seed)
        legacy.random_sample(seed * 7)
        state = legacy.get_state()
        assert mt19937_key_problem(state[1], state[2]) is None, seed
        state = np.random.MT19937(seed).state['state']
        assert mt19937_key_problem(state['key'], state['pos']) is None, seed


@pytest.mark.parametrize('key, words', [(np.zeros(624, np.uint32), 'every bit of the MT19937 state is 0'),
                                        (np.eye(1, 624, 0, np.uint32)[0], 'every bit of the MT19937 state is 0'),
                                        (np.eye(1, 624, 300, np.uint32)[0], 'has 1 of its 19937 bits set')])
@pytest.mark.parametrize('published', [False, True])
def test_a_degenerate_json_random_state_refuses_the_run(tmp_path, key, words, published):
    """A JSON .random_state with an all-zero MT19937 key was accepted, and a kT = 1 run was byte-identical to
    kT = 0; keys [1, 0, ...] of the published generator hung the first step for ever (the Gaussian's loop never
    ends on zeros), deaf to SIGTERM.  Now both are one-line refusals before any file is written."""
    import json
    state = {'bit_generator': 'MT19937', 'state': {'key': key, 'pos': 624}}
    if published:
        state.update(has_gauss=0, gauss=0.0)
    document = {'format': run_output.STATE_FORMAT, 'version': 1, 'kind': 'random_state',
                'state': run_output.encode_state(state)}
    folder = driven_scene(tmp_path / 'run', kT=1.0,
                          random_generator='published' if published else 'default')
    (folder / 'zero.random_state').write_text(json.dumps(document))
    (folder / 'input.dat').write_text(set_options_text(folder, random_state='zero.random_state'))
    status, out, err = run_dynamic(folder)
    assert status == 2 and 'Traceback' not in out + err and len(err.strip().splitlines()) == 1, err
    assert 'zero.random_state' in err and words in err, err
    assert not (folder / 'data').exists()
