"""The grand mobility product in one pass (``_mobility_cpp.grand_product``, issue 46).

``(U, W) = M [F; T]`` with every pair of blobs visited once must give the sum of the four coupling products
(trans_times_force + trans_times_torque, rot_times_force + rot_times_torque) to rounding, on every vector path
this CPU runs (``RMB_SIMD`` forces each, in a subprocess), above the wall and in free space, with and without
periodic images, for scenes with blobs close to the wall, below their radius, overlapping and coincident.
Laws that do not rest on the coupling products: the grand mobility is symmetric (``x . M y = y . M x`` for
6N-vectors), positive definite in free space, and one blob alone moves with the Stokes drag
``U = F / (6 pi eta a)``, ``W = T / (8 pi eta a^3)`` in free space.  ``BlobMobility.product`` of the C++
backend (now the one-pass product) equals the sum of its couplings.
"""
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]

_mobility_cpp = pytest.importorskip('mobility._mobility_cpp', reason='the C++ extensions are not built')
if not hasattr(_mobility_cpp, 'grand_product'):
    pytest.skip('the C++ extension predates grand_product: rebuild with setup.py build_ext --inplace',
                allow_module_level=True)

PATHS = list(_mobility_cpp.simd_paths()) if hasattr(_mobility_cpp, 'simd_paths') else ['scalar']
ETA, A = 1.3, 0.3
TOLERANCE = 1e-13
KINDS = ('trans_times_force', 'trans_times_torque', 'rot_times_force', 'rot_times_torque')

# For the path in RMB_SIMD: every scene's grand product and its four couplings, saved (name -> flat list) to
# argv[1] as JSON.
CHILD = textwrap.dedent('''
    import json, sys
    import numpy as np
    import mobility._mobility_cpp as m
    sys.path.insert(0, 'tests')
    from test_grand_product import scenes, ETA, A
    out = {'path': m.simd_path()}
    for key, (r, F, T, L, wall) in scenes().items():
        U, W = m.grand_product(r, F, T, ETA, A, L, wall)
        parts = [m.product(kind, r, F if kind.endswith('force') else T, ETA, A, L, wall)
                 for kind in ('trans_times_force', 'trans_times_torque', 'rot_times_force', 'rot_times_torque')]
        out[key] = [list(U), list(W), list(parts[0] + parts[1]), list(parts[2] + parts[3])]
    with open(sys.argv[1], 'w') as f:
        json.dump(out, f)
''')


def scenes():
    """{name: (r (N, 3), F (3N,), T (3N,), periodic_length (3,), wall)}: blob counts that are not multiples of
    the vector widths, blobs close to the wall (z = 1.05 a) and below their radius (z = 0.5 a), overlapping
    blobs and a coincident pair, in free space and above the wall, with and without periodic images; 700 blobs
    run the threaded loop (per-thread sums, OMP_NUM_THREADS=2 in the child)."""
    rng = np.random.default_rng(46)
    out = {}
    for n in (1, 2, 7, 19, 44, 97, 700):  # 700: enough pairs for the threaded loop (per-thread sums)
        r = np.column_stack([rng.uniform(0, 5, n), rng.uniform(0, 5, n), rng.uniform(0.4, 3, n)])
        if n >= 7:
            r[1] = r[0] + [0.2, 0.1, 0.05]  # overlapping
            r[2, 2] = 0.5 * A                # below the radius
            r[3, 2] = 1.05 * A               # close to the wall
            r[5] = r[4]                      # coincident pair
        F, T = rng.standard_normal(3 * n), rng.standard_normal(3 * n)
        for wall in (True, False):
            for L in ((0.0, 0.0, 0.0), (5.5, 4.5, 0.0) if wall else (5.5, 4.5, 6.0)):
                out['%d %s %s' % (n, 'wall' if wall else 'free', L)] = (r, F, T, np.array(L), wall)
    return out


def _relative(a, b):
    a, b = np.asarray(a), np.asarray(b)
    return np.abs(a - b).max() / max(np.abs(b).max(), 1e-300)


def _run_path(path, tmp_path):
    target = tmp_path / ('grand_%s.json' % path)
    env = dict(os.environ, RMB_SIMD=path, OMP_NUM_THREADS='2')
    result = subprocess.run([sys.executable, '-c', CHILD, str(target)], cwd=str(ROOT), env=env, capture_output=True,
                            text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-3000:]
    with open(target) as f:
        return json.load(f)


@pytest.fixture(scope='module')
def outputs(tmp_path_factory):
    tmp_path = tmp_path_factory.mktemp('grand')
    return {path: _run_path(path, tmp_path) for path in PATHS}


@pytest.mark.parametrize('path', PATHS)
def test_grand_product_is_the_sum_of_the_four_couplings(outputs, path):
    out = outputs[path]
    assert out['path'] == path
    for key in scenes():
        U, W, U4, W4 = out[key]
        assert _relative(U, U4) < TOLERANCE, '%s: U differs by %.3g relative on %s' % (key, _relative(U, U4), path)
        assert _relative(W, W4) < TOLERANCE, '%s: W differs by %.3g relative on %s' % (key, _relative(W, W4), path)


@pytest.mark.parametrize('path', [p for p in PATHS if p != 'scalar'])
def test_vector_path_equals_scalar_path(outputs, path):
    for key in scenes():
        for got, want in zip(outputs[path][key][:2], outputs['scalar'][key][:2]):
            assert _relative(got, want) < 1e-12, '%s differs from the scalar path on %s' % (key, path)


def test_a_wrong_torque_or_force_is_seen():
    """Control: the tolerance separates rounding from a change of one blob's torque by 1e-9 relative."""
    r, F, T, L, wall = scenes()['19 wall (5.5, 4.5, 0.0)']
    U, W = _mobility_cpp.grand_product(r, F, T, ETA, A, L, wall)
    T2 = T.copy()
    T2[7] *= 1 + 1e-9
    U2, W2 = _mobility_cpp.grand_product(r, F, T2, ETA, A, L, wall)
    assert max(_relative(U2, U), _relative(W2, W)) > 100 * TOLERANCE


def _grand_matrix(r, L, wall):
    """The dense grand mobility (6N, 6N) built column by column from the one-pass product ([U; W] rows)."""
    n = len(r)
    M = np.empty((6 * n, 6 * n))
    for k in range(6 * n):
        e = np.zeros(6 * n)
        e[k] = 1.0
        U, W = _mobility_cpp.grand_product(r, e[:3 * n], e[3 * n:], ETA, A, L, wall)
        M[:, k] = np.concatenate([U, W])
    return M


@pytest.mark.parametrize('wall', [True, False])
@pytest.mark.parametrize('periodic', [False, True])
def test_grand_mobility_is_symmetric(wall, periodic):
    """x . M y = y . M x: the couplings' transposes (M_UT = M_WF^T) and the powers of a of each block."""
    rng = np.random.default_rng(3)
    n = 9
    r = np.column_stack([rng.uniform(0, 2, n), rng.uniform(0, 2, n), rng.uniform(0.35, 1.2, n)])
    L = np.array((2.2, 2.5, 0.0)) if periodic else np.zeros(3)
    M = _grand_matrix(r, L, wall)
    scale = np.abs(M).max()
    assert np.abs(M - M.T).max() < 1e-12 * scale
    # control: the rot-trans blocks are not zero, so a wrong power of a in them would break the symmetry
    assert np.abs(M[3 * n:, :3 * n]).max() > 1e-3 * scale


def test_free_space_grand_mobility_is_positive_definite():
    rng = np.random.default_rng(5)
    n = 12
    r = rng.uniform(0, 2.0, (n, 3))  # overlapping blobs: the regularised RPY tensors stay positive definite
    M = _grand_matrix(r, np.zeros(3), False)
    assert np.linalg.eigvalsh(0.5 * (M + M.T)).min() > 0.0


def test_one_blob_in_free_space_moves_with_the_stokes_drag():
    F, T = np.array([0.3, -1.2, 0.7]), np.array([-0.4, 0.9, 2.0])
    U, W = _mobility_cpp.grand_product(np.array([[0.1, 0.2, 5.0]]), F, T, ETA, A, np.zeros(3), False)
    np.testing.assert_allclose(U, F / (6 * np.pi * ETA * A), rtol=1e-14)
    np.testing.assert_allclose(W, T / (8 * np.pi * ETA * A ** 3), rtol=1e-14)


@pytest.mark.parametrize('geometry', ['single_wall', 'free_space'])
@pytest.mark.parametrize('periodic', [False, True])
def test_interface_product_is_the_sum_of_the_couplings(geometry, periodic):
    from mobility.interface import BlobMobility, Geometry, make_mobility
    L = (5.5, 4.5, 0.0) if periodic else (0.0, 0.0, 0.0)
    mob = make_mobility('C++', Geometry(geometry, L), ETA, A)
    assert mob.grand_product_in_one_pass
    r, F, T, _, _ = scenes()['44 wall (0.0, 0.0, 0.0)']
    for forces, torques in ((F, T), (F, None), (None, T)):
        U, W = mob.product(r, forces, torques)
        U4, W4 = BlobMobility.product(mob, r, forces, torques)  # the four couplings
        assert _relative(U, U4) < TOLERANCE and _relative(W, W4) < TOLERANCE


def test_interface_falls_back_for_per_blob_radii():
    """Per-blob radii: the four couplings (which refuse rotation for different radii with one clear line)."""
    from mobility.interface import Geometry, make_mobility
    r, F, T, _, _ = scenes()['7 wall (0.0, 0.0, 0.0)']
    radii = np.full(len(r), A)
    radii[0] = 0.4
    mob = make_mobility('C++', Geometry('single_wall'), ETA, radii)
    assert not mob.grand_product_in_one_pass
    from utils import UserInputError
    with pytest.raises(UserInputError, match='different radii'):  # the couplings' refusal, as before
        mob.product(r, F, T)
