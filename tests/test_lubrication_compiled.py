"""The compiled near-field kernels (lubrication/cpp/, module lubrication._lubrication_cpp) against the NumPy
reference (lubrication.resistance and the NumPy assembly), and the published numbers through the compiled
path.

Every branch on random pairs and heights: the near-contact forms (gap clamp included), the inverted
two-sphere mobility table, the Jeffrey-Onishi table and its edge rows, the blob-model table, the wall
lubrication forms, the 2562-blob table and its far forms above the table, both hand-overs (the smooth
windows and the cutoff taper); then whole matrices with and without the wall and in a periodic box, and
``standalone_public.json`` (the published code) through the compiled path.
"""
import json
from pathlib import Path

import numpy as np
import pytest

from lubrication import assembly, compiled, problem as lub_problem, resistance

pytestmark = pytest.mark.skipif(not compiled.available(), reason='lubrication._lubrication_cpp is not built: '
                                'the NumPy path is used (pip install -e . builds it)')

STANDALONE = Path(__file__).resolve().parents[1] / '..' / 'shared' / 'reference' / 'lubrication' / 'standalone_public.json'
ETA_UNIT = 1.0 / (6.0 * np.pi)
EQUAL = 1e-14   # relative to the largest entry of each block (the 12 x 12 inverse is the only rounding that differs)


@pytest.fixture
def numpy_path():
    previous = compiled.use_compiled(False)
    yield
    compiled.use_compiled(previous)


def block_errors(value, expected):
    """Per block: max |value - expected| / max |expected| (blocks that are exactly zero must be zero)."""
    difference = np.abs(value - expected).max(axis=(1, 2))
    scale = np.abs(expected).max(axis=(1, 2))
    assert np.all(difference[scale == 0] == 0)
    return difference[scale > 0] / scale[scale > 0]


def random_pairs(rng):
    windows = resistance.SMOOTH_WINDOWS
    r = np.concatenate((
        2.0 + 10.0 ** rng.uniform(-6, -1, 200),           # near contact, some gaps below firm_delta
        rng.uniform(1.5, 2.0, 20),                        # overlapping (clamped)
        rng.uniform(2.0, 2.2, 200),                       # the mobility table, both switches
        rng.uniform(2.2, 5.5, 200),                       # the JO table and its edge row beyond 5.001
        rng.uniform(*windows['near_contact'], 50), rng.uniform(*windows['mobility_table'], 50),
        rng.uniform(4.5 - resistance.CUTOFF_WINDOW, 4.5, 50),
        [resistance.NEAR_CONTACT_END, resistance.NEAR_CONTACT_END + 1e-12, resistance.MOBILITY_TABLE_END,
         resistance.MOBILITY_TABLE_END + 1e-12, 2.002, 2.2, 2.099, 5.001, 5.0005]))
    r_hat = rng.standard_normal((r.size, 3))
    return r, r_hat / np.linalg.norm(r_hat, axis=1)[:, None]


def random_heights(rng):
    windows = resistance.SMOOTH_WINDOWS
    return np.concatenate((1.0 + 10.0 ** rng.uniform(-6, 0, 200), rng.uniform(0.5, 1.0, 20),
                           rng.uniform(1.0, 1.2, 200), rng.uniform(1.2, 16.0, 200),
                           rng.uniform(*windows['wall_near'], 50), rng.uniform(*windows['wall_far'], 50),
                           [1.01, 1.1, 10.018, 13.4996, 1.0001]))


@pytest.mark.parametrize('handover', resistance.HANDOVERS)
def test_pair_and_wall_blocks_equal_the_numpy_reference(handover):
    rng = np.random.default_rng(28)
    factors = resistance.resistance_factors(0.7, 1.3)
    r, r_hat = random_pairs(rng)
    sup, mb = compiled.pair_blocks(r, r_hat, factors, 1e-4, handover, cutoff=4.5)
    taper = resistance.cutoff_taper(r, 4.5, handover)[:, None, None]
    expected_sup = taper * resistance.pair_resistance_sup(r, r_hat, factors, 1e-4, handover)
    expected_mb = taper * resistance.pair_resistance_blob_model(r, r_hat, factors, 1e-4)
    assert block_errors(sup, expected_sup).max() <= EQUAL
    assert block_errors(mb, expected_mb).max() <= EQUAL
    h = random_heights(rng)
    sup, mb = compiled.wall_blocks(h, factors, 1e-4, handover)
    assert block_errors(sup, resistance.wall_resistance_sup(h, factors, 1e-4, handover)).max() <= EQUAL
    assert block_errors(mb, resistance.wall_resistance_blob_model(h, factors, 1e-4)).max() <= EQUAL


def scenes():
    rng = np.random.default_rng(9)
    cluster = rng.uniform(0.0, 8.0, (60, 3))
    cluster[:, 2] += 1.0005
    x, y = np.meshgrid(np.arange(6) * 2.05, np.arange(6) * 2.05)
    monolayer = np.column_stack((x.ravel(), y.ravel(), np.full(36, 1.02))) * 0.5
    return [('cluster above the wall', cluster, 1.3, True, (0.0, 0.0, 0.0)),
            ('cluster in free space', cluster, 1.3, False, (0.0, 0.0, 0.0)),
            ('periodic monolayer a = 0.5', monolayer, 0.5, True, (6 * 2.05 * 0.5, 6 * 2.05 * 0.5, 0.0)),
            ('one sphere', cluster[:1], 1.0, True, (0.0, 0.0, 0.0))]


@pytest.mark.parametrize('handover', resistance.HANDOVERS)
@pytest.mark.parametrize('name, locations, a, wall, periodic_length', scenes(), ids=[s[0] for s in scenes()])
def test_assembled_matrices_equal_the_numpy_assembly(name, locations, a, wall, periodic_length, handover):
    kwargs = dict(periodic_length=periodic_length, wall=wall, handover=handover)
    fast = assembly.resistance_matrices(locations, a, 0.7, **kwargs)
    previous = compiled.use_compiled(False)
    try:
        reference = assembly.resistance_matrices(locations, a, 0.7, **kwargs)
    finally:
        compiled.use_compiled(previous)
    for matrix in ('R_sup', 'R_MB', 'Delta_R'):
        value, expected = getattr(fast, matrix), getattr(reference, matrix)
        assert value.shape == expected.shape and value.has_sorted_indices
        assert (value != value.T).nnz == 0, (name, matrix)          # exactly symmetric
        scale = abs(expected).max()
        error = abs(value - expected).max() / scale if scale else abs(value).max()
        assert error <= EQUAL, (name, matrix, error)
    assert np.array_equal(fast.isolated, reference.isolated)


def test_empty_and_wall_only_scenes():
    assert assembly.resistance_matrices(np.zeros((0, 3)), 1.0, 1.0).Delta_R.shape == (0, 0)
    far_apart = np.array([[0.0, 0.0, 1.5], [50.0, 0.0, 1.5]])
    free = assembly.resistance_matrices(far_apart, 1.0, 1.0, wall=False)
    assert free.Delta_R.nnz == 0 and free.R_sup.nnz == 0
    wall = assembly.resistance_matrices(far_apart, 1.0, 1.0)
    assert wall.Delta_R.nnz == 2 * 10   # per sphere: six diagonal entries and the four couplings U_x-T_y, U_y-T_x


def test_unsorted_pairs_are_refused_by_the_kernel():
    factors = resistance.resistance_factors(1.0, 1.0)
    with pytest.raises(ValueError, match='sorted'):
        compiled.matrices(3, np.array([[1, 2], [0, 1]]), np.array([2.5, 2.5]), np.eye(3)[:2], None, factors, 1e-4,
                          'published', 4.5)


@pytest.mark.parametrize('path', ['compiled', 'numpy'])
def test_the_published_numbers_through_each_path(path):
    if not STANDALONE.is_file():
        pytest.skip('reference data of the published lubrication code not found at %s' % STANDALONE)
    reference = json.loads(STANDALONE.read_text())
    previous = compiled.use_compiled(path == 'compiled')
    try:
        for entry in reference['pair_no_wall']:
            matrices = assembly.resistance_matrices(np.array([entry['r1'], entry['r2']]), 1.0, ETA_UNIT, wall=False)
            for name in ('R_sup', 'R_MB', 'Delta_R'):
                expected = np.array(entry[name])
                if np.any(expected):
                    error = np.abs(getattr(matrices, name).toarray() - expected).max() / np.abs(expected).max()
                    assert error <= 1e-10, (entry['gap_over_a'], name, error)
        for entry in reference['single_sphere_wall']:
            lub = lub_problem.LubricationProblem(np.array([[0.0, 0.0, entry['h_over_a']]]), 1.0, ETA_UNIT)
            expected = np.array(entry['Delta_R'])
            assert np.abs(lub.Delta_R.toarray() - expected).max() <= 1e-10 * np.abs(expected).max()
            M_lub = lub_problem.dense_lubricated_mobility(lub)
            assert np.abs(M_lub - entry['M_lub']).max() <= 1e-8 * np.abs(entry['M_lub']).max()
        for entry in reference['two_spheres_wall']:
            lub = lub_problem.LubricationProblem(np.array(entry['r']), 1.0, ETA_UNIT)
            expected = np.array(entry['Delta_R'])
            assert np.abs(lub.Delta_R.toarray() - expected).max() <= 1e-10 * np.abs(expected).max()
            M_lub = lub_problem.dense_lubricated_mobility(lub)
            assert np.abs(M_lub - entry['M_lub_dense']).max() <= 1e-8 * np.abs(entry['M_lub_dense']).max()
    finally:
        compiled.use_compiled(previous)
