"""The package's one mobility interface (mobility/interface.py): every registered backend in every geometry it serves.

The backends and geometries are read from the registry (``registered_backends``), so a backend added with one
registry line is tested here without touching this file (doc/adding_a_backend.md).  Each check holds to the
backend's own ``relative_accuracy`` (rounding for the pair sums; a grid method states its discretisation's).

* against the published code's numbers (``../shared/reference/blob``; skipped with the reason when absent):
  ``M f``, the four roller couplings, the dense matrix, per-blob radii and the single-blob 6 x 6 grand mobility,
  for every backend that serves the wall or free space;
* against laws that need no stored data: ``x . M y = y . M x`` and ``x . M x > 0`` (the grand mobility too),
  ``product`` equal to the four couplings, the dense matrix equal to the products and positive definite, the wall
  product tending to the free-space product far from the wall (first order in ``a/h``), the pseudo-periodic box
  equal to the explicit sum over images, ``noise`` with covariance ``M`` within its standard error (a wrong factor
  rejected), ``divergence`` whose mean is the exact divergence of the wall self-mobility (half of it rejected);
* the registry: unknown backends, geometries a backend does not serve, dense matrices of a backend without them,
  backends that cannot run here, a backend registered with one line, and the preference order written only in
  the registry.
"""
import ast
import re
from pathlib import Path

import numpy as np
import pytest

from mobility import choose, interface
from mobility.interface import (GEOMETRIES, BlobMobility, FunctionMobility, Geometry, as_blob_mobility,
                                from_implementation_name, make_mobility, preferred_backend, published_function,
                                register_backend, registered_backends, unusable_reason, usable_backends)
from mobility.product_names import PRODUCT_KINDS
from utils import UserInputError

REPO = Path(__file__).resolve().parents[1]
PERIODIC_BOX = 12.0        # periods (x, y; and z for triply_periodic) of the periodic geometries, in blob radii
Z_BOUNDS = (0.0, 6.0)      # z extent of the doubly periodic geometries
ETA = 1.3


def scene_geometry(kind):
    """The Geometry of a law scene: the direct ones without a box, the periodic ones in a 12 x 12 (x 12) box."""
    if kind in interface.DIRECT_GEOMETRIES:
        return Geometry(kind)
    if kind == 'triply_periodic':
        return Geometry(kind, (PERIODIC_BOX,) * 3)
    return Geometry(kind, (PERIODIC_BOX, PERIODIC_BOX, 0.0), Z_BOUNDS)


def scene_positions(kind, n, seed=0):
    """(blob radius, positions (n, 3)) of a law scene in geometry ``kind``: blobs that overlap their neighbours
    and, above a wall, one blob closer to it than its radius (the regularised mobility)."""
    rng = np.random.default_rng(seed)
    if kind in interface.DIRECT_GEOMETRIES:
        a = 0.5
        r = rng.uniform(0.0, 3.0, (n, 3))
        r[:, 2] = rng.uniform(0.7 * a, 3.0, n) if kind != 'free_space' else r[:, 2]
        if kind == 'single_wall':
            r[0, 2] = 0.7 * a
        return a, r
    a = 1.0
    r = np.column_stack([rng.uniform(0.0, PERIODIC_BOX, n), rng.uniform(0.0, PERIODIC_BOX, n),
                         rng.uniform(1.5, 4.5, n)])
    return a, r


def served_pairs():
    """(backend, geometry kind) for every registered backend and every geometry it serves."""
    return [(backend, kind) for kind in GEOMETRIES for backend in registered_backends(kind)]


def usable_or_skip(backend):
    reason = unusable_reason(backend)
    if reason is not None:
        pytest.skip('%s backend not usable here: %s' % (backend, reason))


@pytest.fixture(params=served_pairs(), ids=lambda pair: '%s-%s' % pair)
def scene(request):
    """(mobility, positions (6, 3)) of one backend in one geometry it serves."""
    backend, kind = request.param
    usable_or_skip(backend)
    a, r = scene_positions(kind, 6)
    return make_mobility(backend, scene_geometry(kind), ETA, a), r


def matrix_of(apply, size):
    """The matrix whose columns are ``apply`` of the unit vectors of R^size."""
    return np.column_stack([np.asarray(apply(e), dtype=float).reshape(-1) for e in np.eye(size)])


def tolerance(mobility):
    return 10.0 * mobility.relative_accuracy


# ------------------------------------------------------------------ laws without stored data
def test_blob_mobility_is_symmetric_and_positive_definite(scene):
    """``x . M y = y . M x`` and ``x . M x > 0``: M from the products of the unit vectors."""
    mobility, r = scene
    M = matrix_of(lambda e: mobility.velocities(r, e), r.size)
    scale = np.abs(M).max()
    assert np.abs(M - M.T).max() <= tolerance(mobility) * scale
    assert np.linalg.eigvalsh(0.5 * (M + M.T)).min() > 0.0
    x, y = np.random.default_rng(1).normal(size=(2, r.size))
    assert abs(x @ mobility.velocities(r, y) - y @ mobility.velocities(r, x)) <= \
        tolerance(mobility) * scale * np.linalg.norm(x) * np.linalg.norm(y)


def test_grand_mobility_is_the_four_couplings_and_symmetric(scene):
    """``product(F, T)`` = ``(M_UF F + M_UT T, M_WF F + M_WT T)`` of the couplings; the grand mobility is
    symmetric and positive definite; without rotation, torques are refused and W is None."""
    mobility, r = scene
    n3 = r.size
    F, T = np.random.default_rng(2).normal(size=(2, n3))
    if not mobility.has_rotation:
        U, W = mobility.product(r, F)
        assert W is None and np.array_equal(U, mobility.velocities(r, F))
        with pytest.raises(UserInputError):
            mobility.product(r, F, T)
        with pytest.raises(UserInputError, match='rot_times_torque'):
            mobility.check_coupling('rot_times_torque')
        return
    U, W = mobility.product(r, F, T)
    couplings = {kind: mobility.coupling(kind, r, F if kind.endswith('force') else T) for kind in PRODUCT_KINDS}
    scale = max(np.abs(U).max(), np.abs(W).max())
    assert np.abs(U - couplings['trans_times_force'] - couplings['trans_times_torque']).max() <= \
        tolerance(mobility) * scale
    assert np.abs(W - couplings['rot_times_force'] - couplings['rot_times_torque']).max() <= \
        tolerance(mobility) * scale

    def grand(x):
        U, W = mobility.product(r, x[:n3], x[n3:])
        return np.concatenate((U, W))
    G = matrix_of(grand, 2 * n3)
    assert np.abs(G - G.T).max() <= tolerance(mobility) * np.abs(G).max()
    assert np.linalg.eigvalsh(0.5 * (G + G.T)).min() > 0.0


def test_dense_matrix_is_the_product_and_its_stack_the_bodies(scene):
    """``dense_matrix``, where a backend builds it, equals the products and is symmetric positive definite; the
    backends registered with dense matrices (those of ``mobility_blobs_implementation``) build it and give each
    body's own matrix for a stack of bodies; a backend that builds none refuses with one line."""
    mobility, r = scene
    dense_backend = mobility.backend in registered_backends(mobility.geometry.kind, dense_matrices=True)
    try:
        M = mobility.dense_matrix(r)
    except UserInputError as refused:
        assert not dense_backend and '\n' not in str(refused)
        return
    product = matrix_of(lambda e: mobility.velocities(r, e), r.size)
    assert np.abs(M - product).max() <= tolerance(mobility) * np.abs(M).max()
    assert np.abs(M - M.T).max() <= tolerance(mobility) * np.abs(M).max()
    assert np.linalg.eigvalsh(M).min() > 0.0
    if not dense_backend:
        return
    stack = mobility.dense_matrix(r.reshape(2, 3, 3))
    for body, block in zip(r.reshape(2, 3, 3), stack):
        np.testing.assert_allclose(block, mobility.dense_matrix(body), rtol=0, atol=tolerance(mobility) * np.abs(M).max())


def wall_and_free_backends():
    return [b for b in registered_backends('single_wall') if b in registered_backends('free_space')]


@pytest.mark.parametrize('backend', wall_and_free_backends())
def test_wall_product_tends_to_the_free_space_product_far_from_the_wall(backend):
    """Blobs at height h: the wall changes M f by O(a/h) (the image system's leading term), so the relative
    difference from free space shrinks tenfold from h = 100 a to h = 1000 a."""
    usable_or_skip(backend)
    a = 0.5
    wall = make_mobility(backend, Geometry('single_wall'), ETA, a)
    free = make_mobility(backend, Geometry('free_space'), ETA, a)
    rng = np.random.default_rng(3)
    plane = np.column_stack([rng.uniform(0, 6.0, 8), rng.uniform(0, 6.0, 8), rng.uniform(-0.5, 0.5, 8)])
    f = rng.normal(size=plane.size)
    differences = []
    for h in (100.0 * a, 1000.0 * a):
        r = plane + [0.0, 0.0, h]
        u_free = free.velocities(r, f)
        differences.append(np.linalg.norm(wall.velocities(r, f) - u_free) / np.linalg.norm(u_free))
    assert differences[0] < 0.05
    assert 0.05 < differences[1] / differences[0] < 0.2, differences


def minimum_image(d, L):
    """The published minimum-image displacement ``d - L trunc(d/L + sign(d)/2)`` along the periodic axes."""
    out = np.array(d, dtype=float)
    for axis in range(3):
        if L[axis] > 0:
            out[axis] = d[axis] - L[axis] * np.trunc(d[axis] / L[axis] + 0.5 * np.sign(d[axis]))
    return out


@pytest.mark.parametrize('backend, kind', [(b, k) for b, k in served_pairs() if k in interface.DIRECT_GEOMETRIES])
def test_pseudo_periodic_box_is_the_sum_over_explicit_images(backend, kind):
    """``periodic_length (5, 4, 0)``: every blob sees each other blob at its minimum image and in the eight
    neighbour boxes, and its own eight images; the sum is made here from products of one and two blobs
    without a box."""
    usable_or_skip(backend)
    a, r = scene_positions(kind, 5, seed=4)
    L = np.array([5.0, 4.0, 0.0])
    r[1, :2] += [6.0, -5.0]  # a blob outside the primary box
    boxed = make_mobility(backend, Geometry(kind, L), ETA, a)
    alone = make_mobility(backend, Geometry(kind), ETA, a)
    f = np.random.default_rng(5).normal(size=r.size).reshape(-1, 3)
    shifts = [np.array([i * L[0], j * L[1], 0.0]) for i in (-1, 0, 1) for j in (-1, 0, 1)]
    expected = np.zeros_like(f)
    for i in range(len(r)):
        for j in range(len(r)):
            d = minimum_image(r[j] - r[i], L)
            for s in shifts:
                if i == j and not np.any(s):
                    expected[i] += alone.velocities(r[i:i + 1], f[i])
                else:
                    pair = np.array([r[i], r[i] + d + s])
                    expected[i] += alone.velocities(pair, np.concatenate((np.zeros(3), f[j])))[:3]
    got = boxed.velocities(r, f.reshape(-1)).reshape(-1, 3)
    assert np.abs(got - expected).max() <= max(1e-12, tolerance(boxed)) * np.abs(expected).max()


NOISE_SAMPLES = 400
NOISE_Z_LIMIT = 4.5  # largest |z-score| of the 21 entries of a 6 x 6 covariance accepted (p ~ 1e-4 if right)


def covariance_z_scores(mobility, r, factor, samples=NOISE_SAMPLES, seed=6):
    """(S - M) / se(S) entrywise: S the sample covariance of ``mobility.noise`` of standard normal z, M the
    mobility, se(S_ij) = sqrt((M_ii M_jj + M_ij^2) / samples) the standard error of a Gaussian sample covariance."""
    rng = np.random.default_rng(seed)
    noise = np.array([mobility.noise(r, z, tolerance=1e-12, factor=factor).noise
                      for z in rng.standard_normal((samples, r.size))])
    S = noise.T @ noise / samples
    M = matrix_of(lambda e: mobility.velocities(r, e), r.size)
    M = 0.5 * (M + M.T)
    se = np.sqrt((np.outer(np.diag(M), np.diag(M)) + M ** 2) / samples)
    return (S - M) / se


def test_noise_has_covariance_m_within_its_standard_error(scene):
    """Two blobs: the sample covariance of ``noise`` (Lanczos by default) is M within 4.5 standard errors in
    every entry; the same test rejects noise scaled by sqrt(1.5) (covariance 1.5 M: the control)."""
    mobility, r = scene
    r = r[:2]
    assert np.abs(covariance_z_scores(mobility, r, 1.0)).max() < NOISE_Z_LIMIT
    assert np.abs(covariance_z_scores(mobility, r, np.sqrt(1.5))).max() > NOISE_Z_LIMIT


def wall_self_divergence(h, a, eta):
    """d/dh of the self-mobility normal to the wall of a blob at height h >= a (Swan and Brady, Phys. Fluids 19,
    113306, 2007): mu_perp = (1 - 9/8 (a/h) + 1/2 (a/h)^3 - 1/8 (a/h)^5) / (6 pi eta a); the divergence of M of
    one blob is (0, 0, d mu_perp / dh)."""
    return (9.0 / 8.0 * a / h ** 2 - 1.5 * a ** 3 / h ** 4 + 5.0 / 8.0 * a ** 5 / h ** 6) / (6.0 * np.pi * eta * a)


@pytest.mark.parametrize('backend', registered_backends('single_wall'))
@pytest.mark.parametrize('height_in_radii', [1.5, 3.0])
def test_divergence_mean_is_the_exact_divergence_of_the_wall_self_mobility(backend, height_in_radii):
    """``divergence`` samples of 40 blobs 10^4 radii apart at one height (each sees the wall alone): the mean of
    4,000 samples is (0, 0, d mu_perp/dh) within 4 standard errors (sd of one sample: sqrt(2) dmu/dh along z, the
    parallel slope across); half of it, the drift of a factor-two error, lies many standard errors away."""
    usable_or_skip(backend)
    a = 0.5
    mobility = make_mobility(backend, Geometry('single_wall'), ETA, a)
    h = height_in_radii * a
    spacing = 1e4 * a
    blobs = np.column_stack([spacing * np.arange(40), np.zeros(40), np.full(40, h)])
    rng = np.random.default_rng(7)
    samples = np.concatenate([mobility.divergence(blobs, rng.standard_normal(blobs.size), 1e-4 * a).reshape(-1, 3)
                              for _ in range(100)])
    exact = wall_self_divergence(h, a, ETA)
    mean, se = samples.mean(axis=0), samples.std(axis=0, ddof=1) / np.sqrt(len(samples))
    assert abs(mean[2] - exact) < 4.0 * se[2], (mean, exact, se)
    assert np.all(np.abs(mean[:2]) < 4.0 * se[:2])
    assert abs(mean[2] - 0.5 * exact) > 8.0 * se[2]


@pytest.mark.parametrize('backend', registered_backends('free_space'))
def test_divergence_vanishes_in_free_space(backend):
    """One blob in free space: M = I / (6 pi eta a) everywhere, so every RFD sample is zero to rounding."""
    usable_or_skip(backend)
    mobility = make_mobility(backend, Geometry('free_space'), ETA, 0.5)
    W = np.random.default_rng(8).standard_normal(3)
    sample = mobility.divergence(np.array([[0.3, 0.1, 0.7]]), W, 1e-4)
    assert np.abs(sample).max() <= 1e-8 / (6 * np.pi * ETA * 0.5)


# ------------------------------------------------------------------ the published numbers
REFERENCE_FILES = ['rand50_a0.25', 'rand50_a1.0', 'overlap40_a0.5', 'edge_coincident3_a0.5', 'periodic50_a0.25',
                   'periodic_overlap40_a0.5']
DIRECT_PAIRS = [(b, k) for b, k in served_pairs() if k in ('single_wall', 'free_space')]
REFERENCE_KEY = {'single_wall': ('wall', 'single_wall'), 'free_space': ('nowall', 'no_wall')}


def relative_error(value, reference):
    return np.linalg.norm(np.asarray(value) - reference) / np.linalg.norm(reference)


@pytest.mark.parametrize('name', REFERENCE_FILES)
@pytest.mark.parametrize('backend, kind', DIRECT_PAIRS, ids=lambda value: str(value))
def test_products_match_the_published_numbers(backend, kind, name, reference_dir):
    """``velocities``, the couplings and the dense matrix against the published code (its dense python, its
    numba kernels, its explicit periodic images); where the published kernel gave NaN (two blobs raised to one
    point) ours is finite and equal to the published dense matrix times f."""
    usable_or_skip(backend)
    case = np.load(reference_dir / 'blob' / ('blob_%s.npz' % name))
    r, force, torque = case['r_vectors'], case['force'], case['torque']
    L = case['periodic_length']
    mobility = make_mobility(backend, Geometry(kind, L), float(case['eta']), float(case['blob_radius']))
    limit = max(1e-12, mobility.relative_accuracy)
    short, domain = REFERENCE_KEY[kind]
    periodic = bool(np.any(L > 0))
    reference = case['U_%s_periodic_python_explicit_images' % short] if periodic else case['U_%s_python' % short]
    assert relative_error(mobility.velocities(r, force), reference) < limit
    if mobility.has_rotation:
        for coupling in PRODUCT_KINDS:
            value = mobility.coupling(coupling, r, force if coupling.endswith('force') else torque)
            published = case['%s_%s_numba' % (domain, coupling)]
            assert np.all(np.isfinite(value))
            if np.all(np.isfinite(published)):
                assert relative_error(value, published) < limit, coupling
    if not periodic and backend in registered_backends(kind, dense_matrices=True):
        assert relative_error(mobility.dense_matrix(r), case['M_%s_python' % short]) < limit


@pytest.mark.parametrize('backend, kind', DIRECT_PAIRS, ids=lambda value: str(value))
def test_per_blob_radii_match_the_published_numbers(backend, kind, reference_dir):
    """A mobility configured with per-blob radii (N,) gives the published radii product, by ``velocities`` and
    by ``source_target`` of the blobs onto themselves."""
    usable_or_skip(backend)
    case = np.load(reference_dir / 'blob' / 'blob_radii50.npz')
    short = REFERENCE_KEY[kind][0]
    r, force, radii = case['r_vectors'], case['force'], case['radii']
    mobility = make_mobility(backend, Geometry(kind, case['periodic_length']), float(case['eta']), radii)
    limit = max(1e-12, mobility.relative_accuracy)
    assert relative_error(mobility.velocities(r, force), case['U_%s_radii_python' % short]) < limit
    assert relative_error(mobility.source_target(r, r, force, radii, radii), case['U_%s_radii_python' % short]) < \
        limit


@pytest.mark.parametrize('backend, kind', DIRECT_PAIRS, ids=lambda value: str(value))
def test_single_blob_grand_mobility_matches_the_published_numbers(backend, kind, reference_dir):
    """The 6 x 6 grand mobility of one blob at heights 0.1 a to 100 a (rows [U; W], columns [F; T]) from
    ``product`` of the unit vectors, against the published numba kernels (the physical rolling sign)."""
    usable_or_skip(backend)
    case = np.load(reference_dir / 'blob' / 'blob_single_roller_self_6x6.npz')
    mobility = make_mobility(backend, Geometry(kind), float(case['eta']), float(case['blob_radius']))
    if not mobility.has_rotation:
        pytest.skip('%s in %s has no rotation' % (backend, kind))
    published = case['M6_%s_numba' % REFERENCE_KEY[kind][1]]
    for h, expected in zip(case['heights'], published):
        r = np.array([[0.0, 0.0, h]])
        G = matrix_of(lambda x: np.concatenate(mobility.product(r, x[:3], x[3:])), 6)
        assert relative_error(G, expected) < max(1e-12, mobility.relative_accuracy), h


# ------------------------------------------------------------------ the registry
def one_line(error):
    text = str(error.value)
    assert '\n' not in text
    return text


def test_unknown_backend_is_one_line_naming_the_registered_ones():
    with pytest.raises(UserInputError) as error:
        make_mobility('fortran', Geometry('single_wall'), 1.0, 0.5)
    text = one_line(error)
    assert 'fortran' in text and all(name in text for name in registered_backends())
    with pytest.raises(UserInputError) as error:
        unusable_reason('fortran')
    assert all(name in one_line(error) for name in registered_backends())
    with pytest.raises(UserInputError, match='C\\+\\+_no_wall'):
        from_implementation_name('fortran_no_wall', 1.0, 0.5)


@pytest.mark.parametrize('backend', registered_backends())
def test_geometry_a_backend_does_not_serve_is_one_line_naming_those_that_do(backend):
    for kind in GEOMETRIES:
        if backend in registered_backends(kind):
            continue
        with pytest.raises(UserInputError) as error:
            make_mobility(backend, scene_geometry(kind), 1.0, 0.5)
        text = one_line(error)
        serving = registered_backends(kind)
        assert kind in text and backend in text
        assert all(name in text for name in serving) and (serving or 'none' in text)


def test_dense_matrices_of_a_backend_without_them_are_refused_naming_those_with():
    geometry = Geometry('single_wall')
    without = [b for b in registered_backends(geometry) if b not in registered_backends(geometry, dense_matrices=True)]
    if not without:
        pytest.skip('every backend serving the wall builds dense matrices')
    with pytest.raises(UserInputError) as error:
        make_mobility(without[0], geometry, 1.0, 0.5, dense_matrices=True)
    text = one_line(error)
    assert all(name in text for name in registered_backends(geometry, dense_matrices=True))


def test_a_backend_that_cannot_run_here_says_why_and_the_choices_skip_it():
    unusable = [b for b in registered_backends() if unusable_reason(b) is not None]
    usable = usable_backends()
    assert [b for b in registered_backends() if b not in unusable] == usable  # the registry's order kept
    if not unusable:
        pytest.skip('every registered backend runs here')
    backend = unusable[0]
    kind = next(k for k in GEOMETRIES if backend in registered_backends(k))
    with pytest.raises(UserInputError) as error:
        make_mobility(backend, scene_geometry(kind), 1.0, 0.5)
    assert backend in one_line(error)
    assert preferred_backend(kind) == next(b for b in registered_backends(kind) if b in usable)


class StokesDrag(BlobMobility):
    """A backend of a few lines: every blob alone (``M = I / (6 pi eta a)``), for the registry test."""
    backend = 'stokes_drag'

    def velocities(self, r_vectors, forces):
        return np.asarray(forces, dtype=float).reshape(-1) / (6.0 * np.pi * self.eta * self.blob_radius)


@pytest.fixture
def scratch_registry(monkeypatch):
    """The registry's tables as copies, so that a test may register a backend without keeping it."""
    for name in ('_FACTORIES', '_GEOMETRIES_OF', '_DENSE', '_DEVICE', '_CHECKS'):
        monkeypatch.setattr(interface, name, dict(getattr(interface, name)))
    monkeypatch.setattr(interface, 'PREFERENCE', list(interface.PREFERENCE))


def test_one_registry_line_adds_a_backend_everywhere(scratch_registry):
    """Registered first in the order, a new backend is made by make_mobility, chosen by preferred_backend and
    by auto's candidates (mobility.choose reads the registry), listed in the errors of the geometries it does not
    serve, and its noise is the Lanczos default (here the exact root of a diagonal M)."""
    register_backend('stokes_drag', lambda geometry, eta, a: StokesDrag(geometry, eta, a), ['free_space'], rank=0)
    assert registered_backends()[0] == 'stokes_drag'
    assert preferred_backend('free_space') == 'stokes_drag'
    assert choose.candidate_backends('vector_product', wall=False)[0] == 'stokes_drag'
    assert 'stokes_drag' not in choose.candidate_backends('vector_product', wall=True)
    assert 'stokes_drag' not in choose.candidate_backends('blobs', wall=False)  # no dense matrices
    mobility = make_mobility('stokes_drag', Geometry('free_space'), 2.0, 0.25)
    r = np.zeros((2, 3))
    z = np.random.default_rng(9).standard_normal(6)
    assert np.allclose(mobility.noise(r, z).noise, z / np.sqrt(6 * np.pi * 2.0 * 0.25), rtol=1e-12, atol=0)
    with pytest.raises(UserInputError) as error:
        make_mobility('stokes_drag', Geometry('single_wall'), 1.0, 0.5)
    assert 'stokes_drag' in one_line(error)
    register_backend('boxed_drag', lambda geometry, eta, a: StokesDrag(geometry, eta, a), ['triply_periodic'])
    with pytest.raises(UserInputError) as error:
        make_mobility('boxed_drag', Geometry('free_space'), 1.0, 0.5)
    assert 'backends that do: stokes_drag, ' in one_line(error)  # first in the order
    # its implementation names (the geometry's suffix) are read by the input files and the model
    from multi_bodies.files.input_options import mobility_implementation_names
    assert 'stokes_drag_no_wall' in mobility_implementation_names()
    assert 'boxed_drag' not in ''.join(mobility_implementation_names())  # no direct geometry: no name
    named = from_implementation_name('stokes_drag_no_wall', 2.0, 0.25)
    assert isinstance(named, StokesDrag) and named.geometry.kind == 'free_space'


def test_the_preference_order_is_written_only_in_the_registry():
    """No module of the package but mobility/interface.py writes a sequence of backend names (an order) or picks
    one of two backends by whether it runs here: every choice reads the registry."""
    from test_layout import package_modules
    names = set(registered_backends())
    found = []
    for module, path in package_modules().items():
        if module == 'mobility.interface':
            continue
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, (ast.Tuple, ast.List)):
                values = [e.value for e in node.elts if isinstance(e, ast.Constant)]
                if len(values) == len(node.elts) >= 2 and all(isinstance(v, str) for v in values) \
                        and set(values) <= names:
                    found.append('%s:%d %s' % (module, node.lineno, values))
            if isinstance(node, ast.IfExp) and re.search(r'is_usable|available_implementations|usable_names', ast.unparse(node.test)) and \
                    {getattr(node.body, 'value', None), getattr(node.orelse, 'value', None)} <= names:
                found.append('%s:%d %s' % (module, node.lineno, ast.unparse(node)))
    assert not found, found


# ------------------------------------------------------------------ the forms around the interface
def test_replace_and_the_published_function_forms_give_the_backends_numbers():
    """``replace`` returns the same object when nothing changes and the numbers of a mobility made with the new
    values otherwise; ``published_function`` and ``FunctionMobility`` (the forms of the published functions)
    give the interface's numbers."""
    backend = preferred_backend('single_wall', dense_matrices=True)
    a, r = scene_positions('single_wall', 6)
    mobility = make_mobility(backend, Geometry('single_wall'), ETA, a)
    f = np.random.default_rng(10).normal(size=r.size)
    assert mobility.replace(eta=ETA, blob_radius=a) is mobility
    radii = np.linspace(0.3, 0.6, 6)
    np.testing.assert_array_equal(mobility.replace(blob_radius=radii).velocities(r, f),
                                  make_mobility(backend, Geometry('single_wall'), ETA, radii).velocities(r, f))
    boxed = mobility.replace(periodic_length=(5.0, 5.0, 0.0))
    assert boxed.geometry.kind == 'single_wall' and tuple(boxed.periodic_length) == (5.0, 5.0, 0.0)
    matrix = published_function(mobility, 'dense_matrix')
    np.testing.assert_array_equal(matrix(r, ETA, a), mobility.dense_matrix(r))
    product = published_function(mobility, 'rot_times_torque')
    np.testing.assert_array_equal(product(r, f, 2.0 * ETA, a), mobility.replace(eta=2.0 * ETA).coupling(
        'rot_times_torque', r, f))
    wrapped = as_blob_mobility(published_function(mobility), ETA, a)
    assert isinstance(wrapped, FunctionMobility)
    np.testing.assert_array_equal(wrapped.velocities(r, f), mobility.velocities(r, f))
    assert as_blob_mobility(mobility) is mobility
    with pytest.raises(TypeError):
        as_blob_mobility(mobility, eta=ETA)


def test_the_model_holds_registry_mobilities_that_its_problems_use():
    """A model's vector and blobs mobilities are BlobMobility objects of its implementation names (the box for
    M f only, as the dense blocks never had it), and its problems apply the vector one."""
    from body.body import Body, bodies_to_arrays
    from multi_bodies.solver import user_hooks
    from multi_bodies.solver.model import Model
    bodies = [Body([3.0 * k, 0.0, 2.0], [1.0, 0.0, 0.0, 0.0], np.array([[0.0, 0.0, 0.0], [0.6, 0.0, 0.0]]), 0.25)
              for k in range(2)]
    for body in bodies:
        body.ID = 'dimer'
    physics = dict(g=1.0, repulsion_strength_wall=1.0, debye_length_wall=1.0, repulsion_strength=1.0,
                   debye_length=1.0, periodic_length=np.array([10.0, 10.0, 0.0]), blob_radius=0.25, blob_mass=1.0)
    backend = preferred_backend('free_space', dense_matrices=True)
    model = Model(bodies, bodies_to_arrays(bodies), user_hooks.load_user_hooks('/nonexistent'), physics, 1.1, 0.25,
                  1e-8, vector_product_name=backend + '_no_wall', blobs_name='python_no_wall',
                  periodic_length=(10.0, 10.0, 0.0))
    assert isinstance(model.vector_mobility, BlobMobility) and isinstance(model.blobs_mobility, BlobMobility)
    assert (model.vector_mobility.backend, model.vector_mobility.geometry.kind) == (backend, 'free_space')
    assert tuple(model.vector_mobility.periodic_length) == (10.0, 10.0, 0.0)
    assert not np.any(model.blobs_mobility.periodic_length) and model.blobs_mobility.backend == 'python'
    assert model.vector_mobility.eta == 1.1 and model.vector_mobility.blob_radius == 0.25
    problem = model.mobility_problem(model.start_configuration)
    assert problem.mobility is model.vector_mobility
    f = np.random.default_rng(11).normal(size=3 * model.num_blobs)
    np.testing.assert_array_equal(problem.M_dot(f), model.vector_mobility.velocities(problem.r_vectors, f))


# ------------------------------------------------------------------ the worked examples of the docs
def test_worked_example_of_the_interface_in_the_docs_runs():
    """The Python example of doc/mobility.md, section 'The mobility interface' (its assert: the dense matrix is
    the operator of M f)."""
    text = (REPO / 'doc' / 'mobility.md').read_text(encoding='utf-8')
    section = text[text.index('## The mobility interface'):text.index('## Speed')]
    code = section[section.index('```python\n') + len('```python\n'):]
    exec(compile(code[:code.index('```')], 'doc/mobility.md', 'exec'), {})


def test_worked_example_of_adding_a_backend_runs(tmp_path):
    """doc/adding_a_backend.md's example, in a process of its own (it registers a backend): it runs as written
    and the new backend comes last in the order printed."""
    import subprocess
    import sys
    text = (REPO / 'doc' / 'adding_a_backend.md').read_text(encoding='utf-8')
    code = text[text.index('```python\n') + len('```python\n'):]
    (tmp_path / 'example.py').write_text(code[:code.index('```')])
    done = subprocess.run([sys.executable, 'example.py'], cwd=tmp_path, capture_output=True, text=True, timeout=300,
                          env=dict(__import__('os').environ, PYTHONPATH=str(REPO)))
    assert done.returncode == 0, done.stderr
    assert "'stokes_drag']" in done.stdout
