"""The vector paths of the compiled kernels (mobility/cpp/simd_dispatch.h, doc/performance.md).

Every path this build holds and this CPU runs (``_mobility_cpp.simd_paths()``) is run in a subprocess with
``RMB_SIMD`` naming it, on the same inputs: the blob mobility products (wall, free space, periodic boxes,
the roller couplings, per-blob radii, source-target in the three domains, the free surface, the
two-vector product, single precision), the neighbour preconditioner's near field, the blob-blob forces,
the Monte Carlo energies, the surface layers and the spectral product.  The law: each vector path gives the
scalar path's numbers to round-off (the scalar path is the portable source, one pair at a time).  Controls:
the inputs include overlapping blobs, blobs below their radius, a coincident pair and source counts that
are not multiples of any vector width, and a perturbed input must change the numbers beyond the tolerance.
The vector reciprocal square root is checked against long double to its documented ulp bound.
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
if not hasattr(_mobility_cpp, 'simd_paths'):
    pytest.skip('the C++ extensions predate the vector paths: rebuild with setup.py build_ext --inplace',
                allow_module_level=True)

PATHS = list(_mobility_cpp.simd_paths())

# Computes every kernel's output for the path in RMB_SIMD and saves them (name -> flat array) to argv[1].
CHILD = textwrap.dedent('''
    import sys
    import numpy as np
    import mobility._mobility_cpp as m
    from multi_bodies.solver import _forces_cpp, _preconditioner_cpp, _surface_cpp
    from many_bodyMCMC import _energy_cpp
    out = {'path': np.array([m.simd_path(), _forces_cpp.simd_path(), _preconditioner_cpp.simd_path(),
                             _surface_cpp.simd_path(), _energy_cpp.simd_path()])}
    rng = np.random.default_rng(7)
    scale = float(sys.argv[2])
    for n in (1, 5, 19, 44):  # 19, 44: not multiples of 2, 4 or 8
        r = np.column_stack([rng.uniform(0, 5, n), rng.uniform(0, 5, n), rng.uniform(0.1, 3, n)])
        if n > 2:
            r[1] = r[0] + [0.2, 0.1, 0.05]  # overlapping blobs
            r[2, 2] = 0.15                   # below the radius (0.3)
        r *= scale
        f = rng.standard_normal(3 * n)
        radii = rng.uniform(0.15, 0.5, n)
        for wall in (True, False):
            for L in ((0.0, 0.0, 0.0), (5.5, 4.5, 0.0) if wall else (5.5, 4.5, 6.0)):
                Lv = np.array(L)
                key = '%d %s %s' % (n, wall, L)
                for kind in ('trans_times_force', 'trans_times_torque', 'rot_times_force', 'rot_times_torque'):
                    out[kind + ' ' + key] = m.product(kind, r, f, 1.3, 0.3, Lv, wall)
                out['single ' + key] = m.product('trans_times_force', r, f, 1.3, 0.3, Lv, wall, 'single')
                out['radii ' + key] = m.radii_product(r, f, radii, 1.3, Lv, wall)
            out['two %d %s' % (n, wall)] = np.concatenate(m.product_two(r, f, f[::-1].copy(), 1.3, 0.3, wall))
        targets = r[: max(1, n // 2)] + 0.07
        for domain in ('single_wall', 'no_wall', 'free_surface'):
            out['source_target %d %s' % (n, domain)] = m.source_target_domain(
                r, targets, f, radii, radii[: len(targets)], 1.3, np.zeros(3), domain)
        out['free_surface %d' % n] = m.free_surface_product(r, f, 1.3, 0.3, np.array((5.5, 4.5, 0.0)))
        for Lv in (np.zeros(3), np.array((5.5, 4.5, 0.0))):
            out['forces %d %s' % (n, Lv[0])] = _forces_cpp.blob_blob_forces(r, Lv, 2.0, 0.4, 0.3)
            out['forces_radii %d %s' % (n, Lv[0])] = _forces_cpp.blob_blob_forces_radii(r, Lv, 2.0, 0.4, radii)
            out['energy %d %s' % (n, Lv[0])] = np.array([_energy_cpp.pair_energy_total(r, Lv, 2.0, 0.4, 0.3)])
            out['energy_cross %d %s' % (n, Lv[0])] = np.array(
                [_energy_cpp.pair_energy_cross(r[:2], r, 0, min(2, n), Lv, 2.0, 0.4, 0.3)])
        normals = rng.standard_normal((n, 3))
        w = rng.uniform(0.1, 1.0, n)
        dens = [rng.standard_normal(n) for _ in range(4)]
        for wall in (False, True):
            out['layers %d %s' % (n, wall)] = np.concatenate(
                [np.ravel(a) for a in _surface_cpp.layers(r, normals, *dens, wall)])
        out['double_layer %d' % n] = _surface_cpp.stokes_double_layer(r, normals, w, 0.3, f.reshape(n, 3))
    # the neighbour preconditioner's near field: 6 bodies of 7 blobs, every body paired with the next two
    x = rng.uniform(0, 4, (42, 3)) * scale
    x[:, 2] = np.abs(x[:, 2]) + 0.1
    offsets = np.arange(0, 43, 7, dtype=np.int64)
    partners = np.array([p for b in range(6) for p in (b + 1, b + 2) if p < 6], dtype=np.int64)
    counts = [sum(1 for p in (b + 1, b + 2) if p < 6) for b in range(6)]
    start = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    shifts = np.zeros((len(partners), 3))
    shifts[::3, 0] = 1.5
    for wall in (True, False):
        out['near_field %s' % wall] = _preconditioner_cpp.rigid_near_field(
            x, 0.3, 1.3, wall, offsets, start, partners, shifts, rng.standard_normal((42, 3)))
    # the spectral product (spreading, solve, interpolation) of 30 blobs above a wall, with torques
    from mobility.spectral import SpectralStokes, dpstokes_parameters
    stokes = SpectralStokes(dpstokes_parameters(1.0, 'DPBW', 12.0, 12.0, 0.0, 6.0, kernel='w6', has_torque=True,
                                                warn=False), 1.0, path='compiled')
    stokes.set_positions(np.column_stack([rng.uniform(0, 12, 30), rng.uniform(0, 12, 30),
                                          rng.uniform(1.0, 5.0, 30)]))
    U, W = stokes.product(rng.standard_normal((30, 3)), rng.standard_normal((30, 3)))
    out['spectral'] = np.concatenate([np.ravel(U), np.ravel(W)])
    np.savez(sys.argv[1], **{k: np.asarray(v) for k, v in out.items()})
''')


def _run_path(path, tmp_path, scale=1.0, name=None):
    target = tmp_path / ('%s.npz' % (name or path))
    env = dict(os.environ, RMB_SIMD=path, OMP_NUM_THREADS='2')
    result = subprocess.run([sys.executable, '-c', CHILD, str(target), repr(scale)], cwd=str(ROOT), env=env,
                            capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-3000:]
    with np.load(target) as data:
        return {key: data[key] for key in data.files}


def _relative_difference(a, b):
    scale = max(np.max(np.abs(a)), 1e-300)
    return float(np.max(np.abs(a - b)) / scale)


@pytest.fixture(scope='module')
def outputs(tmp_path_factory):
    tmp_path = tmp_path_factory.mktemp('simd')
    return {path: _run_path(path, tmp_path) for path in PATHS}


def test_scalar_path_is_always_there():
    assert PATHS[-1] == 'scalar'
    assert PATHS == sorted(set(PATHS), key=PATHS.index)


def test_every_vector_path_this_cpu_reports_is_built():
    """The build does not depend on the machine that compiled it: on x86-64 it holds AVX2 and AVX-512 kernels,
    and each is usable wherever the CPU reports the instructions (read from /proc/cpuinfo where it exists)."""
    cpuinfo = Path('/proc/cpuinfo')
    if not cpuinfo.exists() or os.uname().machine != 'x86_64':
        pytest.skip('the check reads the flags of /proc/cpuinfo on x86-64')
    flags = set()
    for line in cpuinfo.read_text().splitlines():
        if line.startswith('flags'):
            flags = set(line.split(':', 1)[1].split())
            break
    if {'avx2', 'fma'} <= flags:
        assert 'avx2' in PATHS
    if {'avx512f', 'avx512dq', 'avx2', 'fma'} <= flags:
        assert 'avx512' in PATHS and PATHS[0] == 'avx512'


@pytest.mark.parametrize('path', [p for p in PATHS if p != 'scalar'])
def test_vector_path_equals_scalar_path(outputs, path):
    scalar, vector = outputs['scalar'], outputs[path]
    assert list(vector['path']) == [path] * 5  # every extension runs the path asked for
    assert set(scalar) == set(vector)
    # the scale of a product: its largest entry over every input (a sum whose terms cancel, as the periodic
    # images of one blob do, is compared with the size of its terms, not with its round-off residue)
    kind_scale = {}
    for key in scalar:
        if key != 'path':
            kind_scale[key.split()[0]] = max(kind_scale.get(key.split()[0], 0.0), float(np.max(np.abs(scalar[key]))))
    worst = {}
    for key in scalar:
        if key == 'path':
            continue
        a, b = scalar[key], vector[key]
        assert np.all(np.isfinite(a)) and np.all(np.isfinite(b)), key
        # single precision: the pair formula in float on every path, fused or not
        tolerance = 1e-5 if key.startswith('single') else 1e-12
        scale = max(float(np.max(np.abs(a))), 1e-3 * kind_scale[key.split()[0]])
        difference = float(np.max(np.abs(a - b))) / scale
        assert difference < tolerance, '%s differs by %.3g relative' % (key, difference)
        worst[key.split()[0]] = max(worst.get(key.split()[0], 0.0), difference)
    assert worst['trans_times_force'] > 0.0 or worst['radii'] > 0.0 or path == 'scalar'  # really another path


def test_a_perturbed_input_is_seen(outputs, tmp_path):
    """Control: the tolerance of the comparison above separates round-off from a change of the inputs of one
    part in 1e9 (positions scaled), on the scalar path itself."""
    scaled = _run_path('scalar', tmp_path, scale=1.0 + 1e-9, name='scaled')
    differences = [_relative_difference(outputs['scalar'][key], scaled[key])
                   for key in outputs['scalar'] if key.startswith('trans_times_force 44')]
    assert max(differences) > 1e-12


@pytest.mark.parametrize('path', PATHS)
def test_vector_reciprocal_square_root_and_minimum_image(path, tmp_path):
    """1/sqrt of each path within 2 ulp of the correctly rounded value (long double reference) from 1e-300 to
    1e300, and the vector minimum image equal to the scalar rule of pair_laws.h."""
    code = textwrap.dedent('''
        import sys, numpy as np
        import mobility._mobility_cpp as m
        rng = np.random.default_rng(3)
        x = np.concatenate([10.0 ** rng.uniform(-300, 300, 4000), rng.uniform(0.5, 4.0, 4000),
                            [1.0, 4.0, 2.0 ** -1022, 1e300]])
        d = np.concatenate([rng.uniform(-20, 20, 4000), [0.0, 2.5, -2.5, 7.5, -7.5, 5.0, -5.0, 1e-300]])
        rs, _ = m.simd_math_check(x, 5.0)
        _, image = m.simd_math_check(d, 5.0)
        np.savez(sys.argv[1], x=x, rs=rs, d=d, image=image)
    ''')
    target = tmp_path / 'math.npz'
    result = subprocess.run([sys.executable, '-c', code, str(target)], cwd=str(ROOT),
                            env=dict(os.environ, RMB_SIMD=path), capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr[-2000:]
    data = np.load(target)
    x, rs = data['x'], data['rs']
    exact = 1.0 / np.sqrt(x.astype(np.longdouble))
    ulps = np.abs((rs - exact) / np.spacing(exact.astype(np.float64)).astype(np.longdouble))
    if np.finfo(np.longdouble).eps >= np.finfo(np.float64).eps:
        pytest.skip('long double is double here: no higher-precision reference')
    assert float(np.max(ulps)) <= 2.0
    d = data['d']
    rule = d - np.trunc(d / 5.0 + np.sign(d) * 0.5) * 5.0  # SPEC section 8, pair_laws.h
    assert np.array_equal(data['image'], rule)


def test_unknown_or_unusable_path_is_refused_with_one_line():
    for asked, words in (('bogus', 'is not a kernel path'), ('neon' if os.uname().machine == 'x86_64' else 'avx2',
                                                            'this build has no')):
        result = subprocess.run([sys.executable, '-c', 'import mobility._mobility_cpp'], cwd=str(ROOT),
                                env=dict(os.environ, RMB_SIMD=asked), capture_output=True, text=True, timeout=120)
        assert result.returncode != 0
        message = result.stderr.strip().splitlines()[-1]
        assert 'RMB_SIMD=%s' % asked in message and words in message and 'scalar' in message


def test_reported_path(outputs):
    for path in PATHS:
        assert list(outputs[path]['path']) == [path] * 5
    from mobility import simd
    assert simd.kernel_path() == (os.environ.get('RMB_SIMD') or PATHS[0])
    assert simd.describe().startswith(simd.kernel_path())
