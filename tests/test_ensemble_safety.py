"""The ensemble's folders, manifest and dashboard are safe to read back (issues 17, 27 and 48).

``ensemble.py --aggregate`` refuses manifest names and output basenames that point outside the ensemble
folder, and a damaged ensemble (a corrupt replica snapshot, a manifest point out of range, a junk ``vary``,
deeply nested or non-UTF-8 JSON) in one line naming the file, never a traceback; the undamaged copy
aggregates.  The local dashboard listens on localhost and the workers' scratch space lies in the run folder.
"""
import importlib
import io
import json
import os
import shutil
import sys
from pathlib import Path

import pytest

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import utils  # noqa: E402
from multi_bodies.ensembles import ensemble_runner as runner  # noqa: E402
from run_scenes import REPO_ROOT  # noqa: E402


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
