"""Data files never run code (issue 17).

A pickle can run any callable while it is read (``__reduce__``).  Each file
kind a run reads back (``.random_state``, ``.restart`` of a dynamic run, of a
Monte Carlo run and of an ensemble replica) is planted with a pickle whose
``__reduce__`` would create a marker folder; the run must refuse the file
with a clear message (exit status 2, no traceback) and the marker must never
appear.  A negative control shows that the payload is live (plain
``pickle.loads`` does create the marker).  The published code's pickled
``numpy.random.RandomState().get_state()`` is still accepted, by a reader
that admits only numpy arrays and dtypes.
"""
import hashlib
import importlib
import json
import io
import os
import pickle
import shutil
import subprocess
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
from run_scenes import REPO_ROOT, copy_scene, edit_input, run_in_process, set_options  # noqa: E402

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


# ------------------------------------------------------------------ the ensemble's folders and dashboard
def small_plan(tmp_path):
    folder = tmp_path / 'scene'
    folder.mkdir()
    shutil.copy(os.path.join(REPO_ROOT, 'multi_bodies', 'Structures', 'shell_N_12_Rg_1.vertex'), folder)
    (folder / 'spheres.clones').write_text('1\n0 0 3 1 0 0 0\n')
    (folder / 'input.dat').write_text('scheme deterministic_forward_euler\ndt 0.05\nn_steps 2\nn_save 1\neta 1.0\n'
                                      'blob_radius 0.25\noutput_name data/run\n'
                                      'structure shell_N_12_Rg_1.vertex spheres.clones\n')
    plan = runner.build_plan(str(folder / 'input.dat'), 1, [('g', ['1'])], str(tmp_path / 'deep' / 'er' / 'ens'), 7)
    runner.write_plan(plan)
    return plan


@pytest.mark.parametrize('field', ['points', 'replicas'])
def test_aggregate_refuses_manifest_names_outside_the_ensemble_folder(tmp_path, field):
    from multi_bodies.ensembles import ensemble_statistics
    plan = small_plan(tmp_path)
    manifest_path = Path(plan['output_dir']) / runner.MANIFEST_NAME
    manifest = json.loads(manifest_path.read_text())
    key = 'name' if field == 'points' else 'folder'
    manifest[field][0][key] = '../../..'
    manifest_path.write_text(json.dumps(manifest))
    before = sorted(p.name for p in tmp_path.iterdir())
    with pytest.raises(utils.UserInputError, match=r"'\.\./\.\./\.\.' is not a folder inside the ensemble folder"):
        ensemble_statistics.aggregate(plan['output_dir'], charts=False, log=lambda *a: None)
    assert sorted(p.name for p in tmp_path.iterdir()) == before and not (tmp_path / 'statistics.csv').exists()


def test_local_dashboard_on_localhost_and_scratch_in_the_run_folder(tmp_path):
    assert runner.local_address(':8787') == '127.0.0.1:8787'
    assert runner.local_address('0.0.0.0:8787') == '0.0.0.0:8787' and runner.local_address(None) is None
    distributed = pytest.importorskip('distributed')
    scratch = runner.scratch_directory(str(tmp_path / 'ens'))
    assert scratch.startswith(str(tmp_path / 'ens'))
    cluster = runner.make_local_cluster(1, omp_threads=1, dashboard_address=':0', local_directory=scratch)
    try:
        with distributed.Client(cluster) as client:
            assert client.submit(sum, [1, 2]).result() == 3
            assert cluster.scheduler_address.startswith('tcp://127.0.0.1:')
            if cluster.dashboard_link:
                assert '127.0.0.1' in cluster.dashboard_link, cluster.dashboard_link
            assert os.path.isdir(scratch) and os.listdir(scratch)  # the workers' space is there
    finally:
        cluster.close()


@pytest.mark.parametrize('basename', ['/tmp/planted', '../../..', '../r0000/run', '..', 'a/b', 7])
def test_aggregate_refuses_an_output_basename_outside_the_replica_folder(tmp_path, basename):
    """Issue 27: a replica's output_basename edited to an absolute path or ``..`` is refused, nothing read."""
    from multi_bodies.ensembles import ensemble_statistics
    plan = small_plan(tmp_path)
    manifest_path = Path(plan['output_dir']) / runner.MANIFEST_NAME
    manifest = json.loads(manifest_path.read_text())
    manifest['replicas'][0]['output_basename'] = basename
    manifest_path.write_text(json.dumps(manifest))
    with pytest.raises(utils.UserInputError, match='output_basename .* is not a file name inside the replica'):
        ensemble_statistics.aggregate(plan['output_dir'], charts=False, log=lambda *a: None)
    assert not (Path(plan['output_dir']) / 'statistics.csv').exists()


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


# ------------------------------------------------------------------ scenes that read every kind of file (issue 27)
COMMON = dict(dt=0.01, n_steps=6, n_save=3, eta=1.0, blob_radius=0.25, g=1.0, solver_tolerance=1e-10,
              mobility_blobs_implementation='python', mobility_vector_prod_implementation='python',
              blob_blob_force_implementation='python', repulsion_strength_wall=1.0, debye_length_wall=0.2,
              output_name='data/run')


def articulated_scene(folder, **options):
    """Two one-blob bodies joined by one active joint (a .const with expressions of t), above the wall."""
    from run_scenes import set_options
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / 'blob.vertex').write_text('1\n0 0 0\n')
    (folder / 'chain.list_vertex').write_text('blob.vertex\nblob.vertex\n')
    (folder / 'chain.const').write_text('2\n1\n0 1 0.5 0 0 -0.5 0 0 0.5 0 0 -0.5 0 0.1*sin(t) 0 0 0 0 0 0.1*cos(t)\n')
    (folder / 'chain.clones').write_text('2\n0 0 3 1 0 0 0\n1 0 3 1 0 0 0\n')
    values = dict(COMMON, scheme='articulated_deterministic_forward_euler')
    values.update(options)
    (folder / 'input.dat').write_text(set_options('articulated chain.list_vertex chain.clones chain.const', **values))
    return folder


def driven_scene(folder, **options):
    """A free one-blob body with an active slip, a body of prescribed velocity, Brownian: slip and velocity files."""
    from run_scenes import set_options
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / 'blob.vertex').write_text('1\n0 0 0\n')
    (folder / 'a.slip').write_text('1\n0.1 0 0\n')
    (folder / 'a.clones').write_text('1\n0 0 2.0 1 0 0 0\n')
    (folder / 'b.clones').write_text('1\n2.5 0 2.5 1 0 0 0\n')
    (folder / 'b.velocity').write_text('0.2 0 0 0 0 0\n')
    values = dict(COMMON, scheme='stochastic_Slip_Trapz', kT=1.0, seed=3)
    values.update(options)
    (folder / 'input.dat').write_text(set_options('structure blob.vertex a.clones a.slip\n'
                                                  'structure blob.vertex b.clones None b.velocity', **values))
    return folder


def surface_scene(folder, kind, **options):
    """A 12-blob sphere in free space with a surface file: ``kind`` 'Laplace' (a Janus sphere in a background
    gradient, forward Euler) or 'slip_length' (slip length 0.5, sedimenting, forward Euler)."""
    from multi_bodies.files import structure_generators as gen
    from run_scenes import set_options
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    blobs, radius, _ = gen.calibrated_shell(12)
    np.savetxt(folder / 'shell.vertex', blobs, header=str(len(blobs)), comments='')
    (folder / 'a.clones').write_text('1\n0 0 5.0 1 0 0 0\n')
    if kind == 'Laplace':
        table = gen.janus_laplace_table(blobs, front=(1.0, 1.0, 1.0), back=(1.0, 0.0, 2.0))
        values = dict(background_Laplace='0 1 0 0', g=0.0)
    else:
        table = gen.slip_length_table(blobs, 0.5)
        values = {}
    gen.write_surface_table(folder / ('shell.' + kind), table, 'surface file of the fingerprint test')
    values = dict(COMMON, scheme='deterministic_forward_euler', blob_radius=radius,
                  mobility_blobs_implementation='python_no_wall', mobility_vector_prod_implementation='python_no_wall',
                  blob_blob_force_implementation='None', domain='no_wall', **values)
    values.update(options)
    (folder / 'input.dat').write_text(set_options('structure shell.vertex a.clones shell.%s' % kind, **values))
    return folder


def run_dynamic(folder):
    from run_scenes import run_in_process
    return run_in_process('dynamic', folder, 'input.dat')


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


# ------------------------------------------------------------------ the fingerprint covers every option and file
# Law: a deterministic program given the same state and inputs writes the same bytes, so a restart from step 6 of a
# 12-step run either writes the uninterrupted run's step 12 exactly or is refused; an input that changes the
# trajectory must be refused with the change named.
NEUTRAL_REFUSED = {'output_name': 'other.a.00000006.clones, which does not exist',  # another name: no step 6
                   'call_HydroGrid': 'call_HydroGrid needs a periodic box'}  # refused as input: this scene has none


def changed_value(name, option, value):
    """Text of another valid value of option ``name`` (current ``value``); None: not changed by this test."""
    from multi_bodies.files.input_options import Choice
    special = {'initial_step': None, 'n_steps': '15', 'n_save': '6', 'output_name': 'data/other',
               'random_state': 'other.random_state', 'seed': '4', 'random_generator': 'default',
               'force_file': 'b.velocity', 'velocity_file': 'b.velocity', 'slip_file': 'a.slip',
               'structure_names': 'a', 'plot_velocity_field': '0 1 2 0 1 2 1 2 2', 'periodic_length': '40 40 0',
               'omega_one_roller': '1 0 0', 'cells': '2 2', 'green_particles': '0 1', 'tracer_radius': '0.5',
               'noise_solver_tolerance': '1e-6', 'scheme': 'stochastic_Slip_Mid', 'kT': '0.5',
               'background_Laplace': '1', 'spectral_z_bounds': '0 10'}
    if name in special:
        return special[name]
    if isinstance(option.rule, Choice):
        others = [choice for choice in option.rule.names if choice != value and choice not in ('auto', 'pycuda')
                  and 'gpu' not in choice.lower() and 'cuda' not in choice.lower()]
        return others[0]
    if option.kind == 'bool':
        return str(not value)
    if option.kind in ('int', 'optional_int'):
        return str((value or 0) + 1)
    if option.kind == 'float':
        return repr(value * 1.01 if value else 0.01)
    raise AssertionError('no changed value for option %s (kind %s): add one' % (name, option.kind))


@pytest.fixture(scope='module')
def twelve_steps(tmp_path_factory):
    """The driven scene run straight to step 12 (n_save 3), with a random_state file it started from."""
    folder = driven_scene(tmp_path_factory.mktemp('twelve') / 'run', n_steps=12)
    for seed, name in ((5, 'start.random_state'), (6, 'other.random_state')):
        run_output.save_random_state(str(folder / name), np.random.Generator(np.random.PCG64(seed)))
    (folder / 'input.dat').write_text(set_options_text(folder, random_state='start.random_state', seed=None))
    assert run_dynamic(folder)[0] == 0
    return folder


def set_options_text(folder, **values):
    from run_scenes import set_options
    return set_options((Path(folder) / 'input.dat').read_text(), **values)


def restart_from_6(base, folder, edit=None, **values):
    """Copy of ``base`` restarted from step 6 with ``values`` (option texts) and ``edit(folder)`` applied."""
    shutil.copytree(base, folder)
    if edit is not None:
        edit(folder)
    (folder / 'input.dat').write_text(set_options_text(folder, initial_step=6, **values))
    return run_dynamic(folder)


def assert_exact_or_refused(base, folder, status, out, err, named=None, refused=False):
    """Refused in one line (naming ``named``), or (not ``refused``) continued to the uninterrupted step 12."""
    assert 'Traceback' not in err + out, err
    if status == 2:  # one line of refusal (after the warnings about lines the scheme ignores)
        assert len([line for line in err.strip().splitlines() if not line.startswith('warning:')]) == 1, err
        assert named is None or named in err, (named, err)
        return 'refused'
    assert status == 0 and not refused, (status, err[-3000:])
    names = sorted(p.name for p in (base / 'data').glob('run.*.00000012.clones'))
    assert names, 'the uninterrupted run saved no step 12'
    for name in names:
        assert (folder / 'data' / name).read_bytes() == (base / 'data' / name).read_bytes(), name
    return 'exact'


def test_the_restart_fingerprint_covers_every_option_of_the_table(twelve_steps, tmp_path):
    """Walk OPTION_TABLE: a restart with an option of the dynamics column changed is refused naming it; with any
    other option changed it continues exactly (or is refused: output_name, which then holds no record)."""
    from multi_bodies.files.input_options import OPTION_TABLE, parse_input_text
    options = parse_input_text((twelve_steps / 'input.dat').read_text(), 'input.dat')
    outcomes = {}
    for name, option in OPTION_TABLE.items():
        value = changed_value(name, option, getattr(options, name))
        if value is None:
            continue
        status, out, err = restart_from_6(twelve_steps, tmp_path / name, **{name: value})
        outcomes[name] = assert_exact_or_refused(twelve_steps, tmp_path / name, status, out, err,
                                                 named=name if option.dynamics else NEUTRAL_REFUSED.get(name),
                                                 refused=option.dynamics)
        assert outcomes[name] == ('refused' if option.dynamics or name in NEUTRAL_REFUSED else 'exact'), \
            (name, err)
        shutil.rmtree(tmp_path / name)
    assert len(outcomes) == len(OPTION_TABLE) - 1  # every option but initial_step, the restart itself
    print('options covered: %d (%d refused, %d exact)' % (len(outcomes), list(outcomes.values()).count('refused'),
                                                          list(outcomes.values()).count('exact')))


def _edit(name, old, new):
    def edit(folder):
        path = folder / name
        text = path.read_text()
        assert old in text, (name, text)
        path.write_text(text.replace(old, new))
    return edit


def _override(folder):
    (folder / 'user_defined_functions.py').write_text('# an override source that overrides nothing\n')


DATA_FILES_OVERRIDE = '''"""Reads the strength of a constant force on every blob from parameters.dat."""
import numpy as np

data_files = ['parameters.dat']


def blob_external_forces(r_vectors, g=1.0, **kw):
    push = float(open('parameters.dat').read())
    forces = np.zeros_like(r_vectors)
    forces[:, 0] = push
    forces[:, 2] = -g
    return forces
'''


def _data_files_scene(folder, **options):
    """The driven scene with an override that declares the data file it reads."""
    folder = driven_scene(folder, **options)
    (folder / 'user_defined_functions.py').write_text(DATA_FILES_OVERRIDE)
    (folder / 'parameters.dat').write_text('0.5\n')
    return folder


FILE_EDITS = {  # kind -> (scene, edit before the restart)
    'vertex': ('driven', _edit('blob.vertex', '0 0 0', '0 0 0.0')),    # same numbers, other text: refused too
    'slip': ('driven', _edit('a.slip', '0.1 0 0', '0.2 0 0')),
    'velocity': ('driven', _edit('b.velocity', '0.2 0 0', '0.3 0 0')),
    'list_vertex': ('articulated', _edit('chain.list_vertex', 'blob.vertex\n', 'blob.vertex  # first\n')),
    'const': ('articulated', _edit('chain.const', '0.1*sin(t)', '0.2*sin(t)')),
    'override': ('driven', _override),
    'override data': ('data_files', _edit('parameters.dat', '0.5', '0.7')),
    'clones': ('driven', _edit('a.clones', '0 0 2.0', '0 0 2.2')),
    'force': ('driven', _edit('b.velocity', '0.2 0 0', '0.3 0 0')),  # placeholder, replaced below
    'random_state': ('driven', None),
    'Laplace': ('Laplace', _edit('shell.Laplace', 'surface file of the fingerprint test', 'an edited header')),
    'slip_length': ('slip_length', _edit('shell.slip_length', 'surface file of the fingerprint test',
                                         'an edited header')),
}


def test_the_restart_fingerprint_covers_every_file_kind(twelve_steps, tmp_path):
    """Every kind of file a program reads: edited before a restart, it is refused with the file named (kinds a
    restart reads) or the run continues exactly (kinds it does not read: FILE_KINDS says why)."""
    from multi_bodies.files.run_inputs import FILE_KINDS
    chain = articulated_scene(tmp_path / 'chain', n_steps=12)
    assert run_dynamic(chain)[0] == 0
    bases = {'driven': twelve_steps, 'articulated': chain,
             'data_files': _data_files_scene(tmp_path / 'data_files', n_steps=12)}
    assert run_dynamic(bases['data_files'])[0] == 0
    for kind in ('Laplace', 'slip_length'):
        bases[kind] = surface_scene(tmp_path / ('base_' + kind), kind, n_steps=12)
        assert run_dynamic(bases[kind])[0] == 0, kind
    edits = dict(FILE_EDITS)
    edits['force'] = ('driven', lambda folder: (folder / 'forces.dat').write_text('1 0 0 0 0 0\n2 0 0 0 0 0\n'))
    edits['random_state'] = ('driven', lambda folder: shutil.copy(folder / 'other.random_state',
                                                                  folder / 'start.random_state'))
    assert set(edits) == set(FILE_KINDS)
    for kind, (scene, edit) in edits.items():
        folder = tmp_path / kind
        values = {'force_file': 'forces.dat'} if kind == 'force' else {}
        if kind == 'force':  # the file named by the run that wrote the records, then edited
            shutil.copytree(bases[scene], tmp_path / 'with_forces')
            (tmp_path / 'with_forces' / 'forces.dat').write_text('0 0 0 0 0 0\n0 0 0 0 0 0\n')
            base = tmp_path / 'with_forces'
        else:
            base = bases[scene]
        status, out, err = restart_from_6(base, folder, edit, **values)
        reads = FILE_KINDS[kind] is True
        named = None
        if reads:
            named = '%s file ' % kind
        outcome = assert_exact_or_refused(base, folder, status, out, err, named=named, refused=reads)
        assert outcome == ('refused' if reads else 'exact'), (kind, err)
    print('file kinds covered: %d' % len(edits))


@pytest.mark.parametrize('line', ["data_files = 'parameters.dat'", 'data_files = [name for name in ("a",)]',
                                  'data_files = [1, 2]'])
def test_data_files_must_be_a_list_of_names_written_as_text(tmp_path, line):
    folder = _data_files_scene(tmp_path / 'run')
    path = folder / 'user_defined_functions.py'
    path.write_text(path.read_text().replace("data_files = ['parameters.dat']", line))
    status, out, err = run_dynamic(folder)
    assert status == 2 and 'Traceback' not in out + err and len(err.strip().splitlines()) == 1, err
    assert 'user_defined_functions.py, line 4: data_files must be a list of file names' in err, err
    assert not (folder / 'data').exists()


def test_an_obstacle_made_a_structure_refuses_the_restart(tmp_path):
    """Changing the last obstacle line to structure between a run and its restart was not refused (4 of 15
    snapshots differed); the fingerprint now holds the kind of every line."""
    base = driven_scene(tmp_path / 'run', n_steps=12)
    text = (base / 'input.dat').read_text().replace('structure blob.vertex b.clones None b.velocity',
                                                    'obstacle blob.vertex b.clones')
    (base / 'input.dat').write_text(set_options(text, scheme='deterministic_adams_bashforth', kT=0))
    assert run_dynamic(base)[0] == 0
    status, out, err = restart_from_6(base, tmp_path / 'changed', _edit('input.dat', 'obstacle blob.vertex',
                                                                          'structure blob.vertex'))
    assert assert_exact_or_refused(base, tmp_path / 'changed', status, out, err, refused=True,
                                   named='structures: was a x 1, b x 1 (obstacle), now a x 1, b x 1') == 'refused'


def test_the_override_sources_covered_are_those_the_programs_import():
    from many_bodyMCMC import mcmc_energy
    from multi_bodies.files.run_inputs import OVERRIDE_FILES
    from multi_bodies.solver import physics
    assert OVERRIDE_FILES == (physics.USER_FILE, physics.USER_PYCUDA_FILE, mcmc_energy.USER_POTENTIAL_FILE,
                              mcmc_energy.GPU_POTENTIAL_FILE)


def test_a_changed_generator_kind_is_a_one_line_refusal(tmp_path):
    """Issue 27, row 4: random_generator published on a restart of a run of the default generator (seed 3)."""
    base = driven_scene(tmp_path / 'run', n_steps=12)
    assert run_dynamic(base)[0] == 0
    status, out, err = restart_from_6(base, tmp_path / 'published', random_generator='published')
    assert assert_exact_or_refused(base, tmp_path / 'published', status, out, err, refused=True,
                                   named='state.rng is the state of the default (PCG64) generator, but this run '
                                         'makes the published generator (random_generator published)') == 'refused'


# ------------------------------------------------------------------ forged records (checksum recomputed)
def forge_record(output_name, step, change):
    """Rewrite the record of ``step`` in ``output_name.restart`` with ``change(record)`` and a valid checksum."""
    import hashlib
    from multi_bodies.run.run_state import state_from_bytes, state_to_bytes
    from multi_bodies.run.restart_records import RECORD_HEADER, RECORD_TAG, RESTART_MAGIC, restart_index
    path = output_name + '.restart'
    data = Path(path).read_bytes()
    out = bytearray(RESTART_MAGIC)
    for entry_step, start, end in restart_index(path):
        payload = data[start:end]
        if entry_step == step:
            record = state_from_bytes(payload)
            change(record)
            payload = state_to_bytes(record)
        out += RECORD_HEADER.pack(RECORD_TAG, entry_step, len(payload), hashlib.sha256(payload).digest()) + payload
    Path(path).write_bytes(bytes(out))


def _set(*keys_and_value):
    *keys, value = keys_and_value

    def change(record):
        target = record
        for key in keys[:-1]:
            target = target[key]
        target[keys[-1]] = value(target[keys[-1]]) if callable(value) else value
    return change


FORGERIES = [  # (save_clones, change of the record of step 6, words of the refusal)
    ('one_file', _set('snapshots', 'a', lambda entry: [entry[0], 2 ** 40]), 'differs from the one its record'),
    ('one_file', _set('config_offsets', 'a', -5), 'config_offsets of a is -5'),
    ('one_file_per_step', _set('snapshots', 'a', lambda entry: [entry[0], str(entry[1])]), 'snapshots of a is'),
    ('one_file_per_step', _set('snapshots', lambda table: list(table.values())), 'snapshots is a list'),
    ('one_file_per_step', _set('state', 'rng', {'bit_generator': 'PCG64', 'state': 'x'}), 'holds no state table'),
    ('one_file_per_step', _set('state', 'rng', 'bit_generator', 'os.system'), 'not one of numpy'),
    ('one_file_per_step', _set('state', 'rng', 'state', 'state', 'seven'), 'does not fit the default (PCG64)'),
    ('one_file_per_step', _set('state', 'rng', {'bit_generator': 'MT19937', 'state': {
        'key': np.eye(1, 624, 0, np.uint32)[0], 'pos': 624}, 'has_gauss': 0, 'gauss': 0.0}),
     'every bit of the MT19937 state is 0'),
    ('one_file_per_step', _set('state', 'locations', np.zeros((3, 3))), 'state.locations holds 3 bodies'),
    ('one_file_per_step', _set('state', 'orientations', np.zeros((2, 5))), 'state.orientations has shape (2, 5)'),
    ('one_file_per_step', _set('state', 'counters', {'steps': -1}), 'state.counters'),
    ('one_file_per_step', _set('state', 'scheme', [[[[[[[[1]]]]]]]]), 'nested more than'),
    ('one_file_per_step', _set('step', 7), 'step is 7, the header says 6'),
    ('one_file_per_step', _set('stop_files', {'a': '../../../etc/passwd'}), 'not a file of the run folder'),
]


@pytest.mark.parametrize('save_clones, change, words', FORGERIES)
def test_a_forged_record_is_a_one_line_refusal_naming_it(tmp_path, save_clones, change, words):
    """Issue 27, row 6: a record rewritten with its checksum recomputed is checked field by field before anything
    is allocated or seeked (once: MemoryError, ValueError, TypeError, AttributeError tracebacks)."""
    folder = driven_scene(tmp_path / 'run', n_steps=12, save_clones=save_clones)
    assert run_dynamic(folder)[0] == 0
    forge_record(str(folder / 'data' / 'run'), 6, change)
    (folder / 'input.dat').write_text(set_options_text(folder, initial_step=6))
    status, out, err = run_dynamic(folder)
    assert status == 2 and 'Traceback' not in out + err and len(err.strip().splitlines()) == 1, err
    assert 'step 6' in err and words in err, err


def test_an_output_name_with_a_nul_byte_is_a_one_line_refusal(tmp_path):
    """Found by the fuzzer (issue 27): a NUL byte in output_name made open() raise ValueError (a traceback)."""
    folder = driven_scene(tmp_path / 'run')
    (folder / 'input.dat').write_text(set_options_text(folder, output_name='data/r\x00un'))
    status, out, err = run_dynamic(folder)
    assert status == 2 and 'Traceback' not in out + err and 'holds a NUL byte' in err, err
    assert not (folder / 'data').exists()


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
    from test_crash_safety import mcmc_scene
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


# ------------------------------------------------------------------ every field against the run (issue 48)
def _zero_first_quaternion(orientations):
    orientations = orientations.copy()
    orientations[0] = 0.0
    return orientations


RUN_FORGERIES = [  # (scene, change of the record of step 6, words of the refusal)
    ('adams_bashforth', _set('state', 'scheme', 'previous_velocities', np.zeros((2, 3))),
     'previous_velocities is a float64 array of shape (2, 3), not the body velocities (2, 6)'),
    ('adams_bashforth', _set('state', 'scheme', 'previous_velocities', np.zeros(12)),
     'previous_velocities is a float64 array of shape (12,)'),
    ('rollers', _set('state', 'scheme', 'previous_velocities', np.zeros((2, 6))), 'roller velocities (2, 3)'),
    ('adams_bashforth', _set('state', 'scheme', 'concentration_guess', {'a': 1}), 'concentration_guess'),
    ('adams_bashforth', _set('state', 'scheme', 'first_guess', np.zeros((3, 6))), 'first_guess is not a flat'),
    ('adams_bashforth', _set('state', 'orientations', _zero_first_quaternion),
     'state.orientations holds a quaternion of norm 0.0'),
    ('adams_bashforth', _set('state', 'scheme', 'preconditioner_configuration',
                             lambda saved: (saved[0], np.zeros_like(saved[1]))) , 'not a unit quaternion'),
    ('adams_bashforth', _set('state', 'locations', lambda locations: locations + 0.1),
     'state.locations are not the positions of the snapshot'),
    ('adams_bashforth', _set('state', 'rng', None), 'state.rng is absent'),
    ('adams_bashforth', _set('fingerprint', None), 'holds no fingerprint'),
    ('adams_bashforth', _set('snapshots', {}), 'snapshots holds no checksum of a, b'),
    ('adams_bashforth', _set('state', 'scheme', None), 'state.scheme is absent'),
]


@pytest.mark.parametrize('scene, change, words', RUN_FORGERIES)
def test_a_record_that_does_not_fit_the_run_is_a_one_line_refusal(tmp_path, scene, change, words):
    """Every field checked against what the run needs before it is used: Adams-Bashforth velocities of another
    shape (a ValueError traceback in every Adams-Bashforth scene), zero quaternions (once used, and written to the
    snapshots), a configuration that is not the snapshot's (once silently replaced by it), required fields
    absent (a record without fingerprint, state or checksums was taken as exact)."""
    from test_crash_safety import dynamic_scene
    folder = dynamic_scene(tmp_path / 'run', n_steps=12, n_save=6,
                           **({'scheme': 'stochastic_adams_bashforth_rollers'} if scene == 'rollers' else {}))
    assert run_dynamic(folder)[0] == 0
    before = snapshot_tree(folder / 'data')
    forge_record(str(folder / 'data' / 'run'), 6, change)
    (folder / 'input.dat').write_text(set_options_text(folder, initial_step=6))
    status, out, err = run_dynamic(folder)
    assert status == 2 and 'Traceback' not in out + err and len(err.strip().splitlines()) == 1, err
    assert 'step 6' in err and words in err, err
    after = snapshot_tree(folder / 'data')
    assert {k: v for k, v in after.items() if k != 'run.restart'} == {k: v for k, v in before.items()
                                                                      if k != 'run.restart'}


def snapshot_tree(folder):
    return {str(p.relative_to(folder)): p.read_bytes() for p in Path(folder).rglob('*') if p.is_file()}


# ------------------------------------------------------------------ ensemble.py --aggregate on hostile folders (issue 48)
@pytest.fixture(scope='module')
def finished_ensemble(tmp_path_factory):
    """A small ensemble (one point, two replicas) run to the end: the aggregate's input."""
    root = tmp_path_factory.mktemp('ensemble')
    plan = small_plan(root)
    for spec in runner.replica_specs(plan):
        assert runner.run_replica(spec)['status'] == 'done'
    return Path(plan['output_dir'])


def _manifest_edit(change):
    def edit(folder):
        path = folder / runner.MANIFEST_NAME
        manifest = json.loads(path.read_text())
        change(manifest)
        path.write_text(json.dumps(manifest))
    return edit


def _corrupt_snapshot(data):
    def edit(folder):
        path = sorted(folder.rglob('*.clones'))[-1]
        path.write_bytes(data(path.read_bytes()))
    return edit


AGGREGATE_CASES = {
    'snapshot NaN': (_corrupt_snapshot(lambda b: b.replace(b'0.0', b'nan', 1) if b'0.0' in b else b'1\nnan 0 1 1 0 0 0\n'),
                     'holds a NaN or infinite number'),
    'snapshot garbage': (_corrupt_snapshot(lambda b: b'\xff\xfe garbage\n'), 'not a snapshot'),
    'snapshot short': (_corrupt_snapshot(lambda b: b'3\n0 0 1 1 0 0 0\n'), 'the count line says 3 bodies'),
    'point out of range': (_manifest_edit(lambda m: m['replicas'][0].update(point=7)), 'has point 7, not one of'),
    'point not a number': (_manifest_edit(lambda m: m['replicas'][0].update(point='x')), "has point 'x'"),
    'junk vary': (_manifest_edit(lambda m: m.update(vary=[['g', 1, 2, 3]])), 'vary is not a list'),
    'junk vary name': (_manifest_edit(lambda m: m.update(vary=[[7, ['1']]])), 'vary is not a list'),
    'junk overrides': (_manifest_edit(lambda m: m['points'][0].update(overrides={'g': 1})), 'overrides of point'),
    'deeply nested': (lambda folder: (folder / runner.MANIFEST_NAME).write_text('[' * 100000 + ']' * 100000),
                      'is not a valid ensemble manifest'),
    'not UTF-8': (lambda folder: (folder / runner.MANIFEST_NAME).write_bytes(b'{"replicas": "\xff"}'),
                  'is not a valid ensemble manifest'),
}


@pytest.mark.parametrize('case', sorted(AGGREGATE_CASES))
def test_aggregate_of_a_damaged_ensemble_is_a_one_line_refusal(finished_ensemble, tmp_path, case):
    """ensemble.py --aggregate with a corrupt replica snapshot, a manifest point out of range, a junk vary or
    deeply nested JSON once ended in a traceback; now each is one line naming the file (exit 2)."""
    edit, words = AGGREGATE_CASES[case]
    folder = tmp_path / 'ens'
    shutil.copytree(finished_ensemble, folder)
    edit(folder)
    script = importlib.import_module('multi_bodies.ensemble')
    err = io.StringIO()
    import contextlib
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        with pytest.raises(SystemExit) as stop:
            utils.fail_cleanly(script.main, ['--aggregate', str(folder), '--no-charts'])
    assert stop.value.code == 2, err.getvalue()
    lines = [line for line in err.getvalue().splitlines() if line.strip()]
    assert len(lines) == 1 and words in lines[0] and 'Traceback' not in lines[0], err.getvalue()
    assert not (folder / 'summary.csv').exists()


def test_aggregate_of_the_finished_ensemble_runs(finished_ensemble, tmp_path):
    """Control: the undamaged copy aggregates."""
    from multi_bodies.ensembles import ensemble_statistics
    folder = tmp_path / 'ens'
    shutil.copytree(finished_ensemble, folder)
    statistics = ensemble_statistics.aggregate(str(folder), charts=False, log=lambda *a: None)
    assert len(statistics) == 1 and (folder / 'summary.csv').exists()


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
    from test_crash_safety import mcmc_scene
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


@pytest.mark.parametrize('offset', [2 ** 70, 2 ** 40, 10 ** 6])
def test_a_forged_config_offset_beyond_the_file_is_one_line(tmp_path, offset):
    """Found by the 30-minute fuzz run (issue 48): a record's config_offsets of 2**70 made the .config reader's
    seek raise ValueError (a traceback); an offset outside the file is now the reader's one-line refusal."""
    folder = driven_scene(tmp_path / 'run', n_steps=12, save_clones='one_file')
    assert run_dynamic(folder)[0] == 0
    forge_record(str(folder / 'data' / 'run'), 6, _set('config_offsets', 'a', offset))
    (folder / 'input.dat').write_text(set_options_text(folder, initial_step=6))
    status, out, err = run_dynamic(folder)
    assert status == 2 and 'Traceback' not in out + err and len(err.strip().splitlines()) == 1, err
    assert 'run.a.config' in err, err
