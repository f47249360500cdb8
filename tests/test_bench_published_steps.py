"""benchmarks/bench_published_steps.py: the scene it gives both codes, and (when a published checkout is at hand)
that the two codes' steps it times compute the same thing.

The boomerang must be the published examples' one (the reference structure file, or the package's generated
copy of it); the scene must be a valid start (every blob above the wall by more than its radius, blobs of
different bodies more than two radii apart, unit quaternions); the input file must be read by the package without
a warning.  With ``RMB_PUBLISHED_PYTHON`` and ``RMB_PUBLISHED_TREE`` set (an interpreter with the published
code's packages and a checkout of the published RigidMultiblobsWall), a tiny side-by-side run must end with the
two codes' bodies within the solver tolerance's reach of each other for both schemes.
"""
import argparse
import os
import subprocess
import sys

import numpy as np
import pytest
from scipy.spatial.distance import cdist

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, 'benchmarks'))
import bench_published_steps as bench  # noqa: E402

REFERENCE_VERTEX = os.path.join(ROOT, '..', 'shared', 'reference', 'structures', 'boomerang_N_15.vertex')
PACKAGE_VERTEX = os.path.join(ROOT, 'multi_bodies', 'Structures', 'boomerang_N_15.vertex')
BLOB_RADIUS = 0.25


def read_vertex(path):
    rows = [line.split('#')[0].split() for line in open(path)]
    rows = [row for row in rows if row]
    assert int(rows[0][0]) == len(rows) - 1
    return np.array(rows[1:], dtype=float)


def test_boomerang_is_the_published_one():
    ours = bench.boomerang_vertices()
    np.testing.assert_allclose(ours, read_vertex(PACKAGE_VERTEX), rtol=0, atol=1e-14)
    if not os.path.isfile(REFERENCE_VERTEX):
        pytest.skip('reference structure not found at %s (the package copy was compared)' % REFERENCE_VERTEX)
    np.testing.assert_allclose(ours, read_vertex(REFERENCE_VERTEX), rtol=0, atol=1e-14)


def lab_blobs(locations, quaternions):
    """(N, 15, 3) blob positions of the scene's bodies (rotation matrix of each unit quaternion s, p)."""
    s, p = quaternions[:, 0], quaternions[:, 1:]
    eye = np.eye(3)[None]
    cross = np.zeros((len(s), 3, 3))
    cross[:, 0, 1], cross[:, 0, 2], cross[:, 1, 2] = -p[:, 2], p[:, 1], -p[:, 0]
    cross -= cross.transpose(0, 2, 1)
    rotation = 2 * (p[:, :, None] * p[:, None, :] + (s ** 2 - 0.5)[:, None, None] * eye + s[:, None, None] * cross)
    return locations[:, None, :] + np.einsum('kij,bj->kbi', rotation, bench.boomerang_vertices())


@pytest.mark.parametrize('num_bodies', [4, 100])
def test_scene_is_a_valid_start(num_bodies):
    locations, quaternions = bench.scene(num_bodies, 5.0, 3.0, 1)
    assert locations.shape == (num_bodies, 3)
    np.testing.assert_allclose(np.linalg.norm(quaternions, axis=1), 1.0, rtol=0, atol=1e-14)
    blobs = lab_blobs(locations, quaternions)
    # each body keeps its shape (the rotation is a rotation): arm blobs 0.3 apart
    np.testing.assert_allclose(np.linalg.norm(np.diff(blobs, axis=1), axis=2), 0.3, rtol=0, atol=1e-12)
    assert blobs[:, :, 2].min() > 2 * BLOB_RADIUS
    body = np.repeat(np.arange(num_bodies), 15)
    flat = blobs.reshape(-1, 3)
    distance = cdist(flat, flat)
    other = body[:, None] != body[None, :]
    assert distance[other].min() > 2 * BLOB_RADIUS


@pytest.mark.parametrize('scheme', bench.SCHEMES)
def test_input_file_is_read_by_the_package_without_warnings(tmp_path, capsys, scheme):
    from multi_bodies.files.input_options import read_input_file
    args = argparse.Namespace(bodies=4, spacing=5.0, height=3.0, scene_seed=1, seed=1, dt=0.01, kT=1.0,
                              tolerance=1e-8, max_steps=40)
    path = bench.write_input(str(tmp_path), scheme, args)
    options = read_input_file(path, program='dynamic')
    assert 'warning' not in capsys.readouterr().err
    assert options.scheme == scheme
    assert options.random_generator == 'published'
    assert options.n_steps == 40 and options.n_save == 40


PUBLISHED_PYTHON = os.environ.get('RMB_PUBLISHED_PYTHON')
PUBLISHED_TREE = os.environ.get('RMB_PUBLISHED_TREE')


@pytest.mark.slow
@pytest.mark.skipif(not (PUBLISHED_PYTHON and PUBLISHED_TREE),
                    reason='set RMB_PUBLISHED_PYTHON and RMB_PUBLISHED_TREE to run the published code side by side')
def test_tiny_side_by_side_run_computes_the_same_steps():
    run = subprocess.run([sys.executable, os.path.join(ROOT, 'benchmarks', 'bench_published_steps.py'),
                          '--published-python', PUBLISHED_PYTHON, '--published-tree', PUBLISHED_TREE,
                          '--bodies', '4', '--steps', '2', '--threads', 'one'],
                         stdout=subprocess.PIPE, stderr=subprocess.STDOUT, universal_newlines=True, timeout=900)
    assert run.returncode == 0, run.stdout[-3000:]
    apart = [line for line in run.stdout.splitlines() if line.strip().startswith('apart after')]
    assert len(apart) == 2, run.stdout
    for line in apart:
        centres = float(line.split('body centres')[1].split(',')[0])
        turns = float(line.split('quaternions')[1])
        # solver tolerance 1e-8 on displacements of order 1e-2: far below a Brownian step (about 0.1)
        assert centres < 1e-7 and turns < 1e-7, line
