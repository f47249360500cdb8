"""Tests of the mobility room: every backend against the published code's
numbers (../shared/reference/blob), and against laws and analytic limits
(symmetry, positive definiteness, single-blob limits of VALIDATION.md)."""
import tracemalloc

import numpy as np
import pytest

import mobility
from mobility import backends
from utils import UserInputError

CPU_TOLERANCE = 1e-12
GPU_TOLERANCE = 1e-10
BACKENDS = ['python', 'C++', 'pycuda']
PRODUCT_KINDS = ['trans_times_force', 'trans_times_torque', 'rot_times_force', 'rot_times_torque']


def relative_error(value, reference):
    return np.linalg.norm(np.asarray(value) - reference) / np.linalg.norm(reference)


@pytest.fixture(params=BACKENDS)
def backend(request):
    """Each backend name; skips (with the reason) those that cannot run here."""
    name = request.param
    if not backends.is_usable(name):
        pytest.skip('%s backend not usable here: %s' % (name, backends.available_implementations()[name]))
    return name


def tolerance(backend):
    return GPU_TOLERANCE if backend == 'pycuda' else CPU_TOLERANCE


REFERENCE_FILES = ['rand50_a0.25', 'rand50_a1.0', 'overlap40_a0.5', 'edge_coincident3_a0.5',
                   'periodic50_a0.25', 'periodic_overlap40_a0.5']


@pytest.fixture(params=REFERENCE_FILES)
def blob_case(request, reference_dir):
    data = np.load(reference_dir / 'blob' / ('blob_%s.npz' % request.param))
    return request.param, {k: data[k] for k in data.files}


def case_inputs(case):
    return (case['r_vectors'], case['force'], case['torque'], float(case['eta']), float(case['blob_radius']),
            case['periodic_length'])


def test_wall_and_free_products_match_published(backend, blob_case):
    name, case = blob_case
    r, force, _, eta, a, L = case_inputs(case)
    periodic = np.any(L > 0)
    for suffix, key in (('', 'wall'), ('_no_wall', 'nowall')):
        product = mobility.mobility_vector_product(backend + suffix)
        u = product(r, force, eta, a, L)
        assert np.all(np.isfinite(u)), (name, key)
        reference_key = 'U_%s_periodic_python_explicit_images' % key if periodic else 'U_%s_python' % key
        assert relative_error(u, case[reference_key]) < tolerance(backend), (name, key)


def test_roller_couplings_match_published(backend, blob_case):
    """The four blocks of the grand mobility against the published numba kernels.

    Where the published kernel returns NaN (coincident raised blobs), ours must
    be finite; for trans_times_force it must then equal the dense python matrix.
    """
    name, case = blob_case
    r, force, torque, eta, a, L = case_inputs(case)
    for domain, suffix in (('single_wall', ''), ('no_wall', '_no_wall')):
        for kind in PRODUCT_KINDS:
            vector = force if kind.endswith('force') else torque
            value = mobility.blob_product(backend + suffix, kind)(r, vector, eta, a, L)
            assert np.all(np.isfinite(value)), (name, domain, kind)
            reference = case['%s_%s_numba' % (domain, kind)]
            if np.all(np.isfinite(reference)):
                assert relative_error(value, reference) < tolerance(backend), (name, domain, kind)
            elif kind == 'trans_times_force':
                dense = case['M_wall_python'] if domain == 'single_wall' else case['M_nowall_python']
                assert relative_error(value, dense @ force) < tolerance(backend), (name, domain, kind)


def test_dense_matrices_match_published(blob_case):
    name, case = blob_case
    if 'M_wall_python' not in case:
        pytest.skip('%s has no dense reference (periodic boxes are matrix-free only)' % name)
    r, _, _, eta, a, _ = case_inputs(case)
    for backend in ('python', 'C++'):
        if not backends.is_usable(backend):
            continue
        M_wall = mobility.blob_mobility_matrix(backend)(r, eta, a)
        M_free = mobility.blob_mobility_matrix(backend + '_no_wall')(r, eta, a)
        assert relative_error(M_wall, case['M_wall_python']) < CPU_TOLERANCE, (name, backend)
        assert relative_error(M_free, case['M_nowall_python']) < CPU_TOLERANCE, (name, backend)
    assert relative_error(mobility.single_wall_fluid_mobility(r, eta, a), case['M_wall_python']) < CPU_TOLERANCE
    assert relative_error(mobility.rotne_prager_tensor(r, eta, a), case['M_nowall_python']) < CPU_TOLERANCE


def test_source_target_with_radii_matches_published(backend, reference_dir):
    case = dict(np.load(reference_dir / 'blob' / 'blob_radii50.npz'))
    r, force, radii, eta = case['r_vectors'], case['force'], case['radii'], float(case['eta'])
    wall = mobility.source_target_product(backend)(r, r, force, radii, radii, eta)
    free = mobility.source_target_product(backend + '_no_wall')(r, r, force, radii, radii, eta)
    assert relative_error(wall, case['U_wall_radii_python']) < tolerance(backend)
    assert relative_error(free, case['U_nowall_radii_python']) < tolerance(backend)


def test_source_target_equal_radii_matches_published(backend, blob_case):
    name, case = blob_case
    if 'U_wall_radii_python_equal_radii' not in case:
        pytest.skip('%s has no python source-target reference' % name)
    r, force, _, eta, a, _ = case_inputs(case)
    wall = mobility.single_wall_mobility_source_target(r, r, force, a, a, eta, implementation=backend)
    free = mobility.no_wall_mobility_source_target(r, r, force, a, a, eta, implementation=backend)
    assert relative_error(wall, case['U_wall_radii_python_equal_radii']) < tolerance(backend), name
    assert relative_error(free, case['U_nowall_radii_python_equal_radii']) < tolerance(backend), name


def grand_mobility(r, eta, a, implementation, wall=True, periodic_length=(0, 0, 0)):
    """6N x 6N grand mobility [[UF, UT], [WF, WT]] assembled column by column from the products."""
    n = r.shape[0]
    suffix = '' if wall else '_no_wall'
    blocks = {}
    for kind in PRODUCT_KINDS:
        product = mobility.blob_product(implementation + suffix, kind)
        blocks[kind] = np.column_stack([product(r, e, eta, a, periodic_length) for e in np.eye(3 * n)])
    return np.block([[blocks['trans_times_force'], blocks['trans_times_torque']],
                     [blocks['rot_times_force'], blocks['rot_times_torque']]])


def random_configuration(rng, n, a, box=4.0, low=0.1, high=4.0):
    """Blobs in a box, heights from low*a to high*a: overlaps with each other and with the wall."""
    return np.column_stack([rng.uniform(0, box, n), rng.uniform(0, box, n), a * rng.uniform(low, high, n)])


@pytest.mark.parametrize('seed', [1, 2, 3])
def test_dense_mobility_is_symmetric_positive_definite(seed):
    rng = np.random.default_rng(seed)
    a = 0.5
    r = random_configuration(rng, 40, a)
    for M in (mobility.single_wall_fluid_mobility(r, 1.3, a), mobility.rotne_prager_tensor(r, 1.3, a)):
        assert np.max(np.abs(M - M.T)) < 1e-14 * np.max(np.abs(M))
        assert np.linalg.eigvalsh(M).min() > 0.0


def test_grand_mobility_is_symmetric_positive_definite(backend):
    """Trans/rot couplings are transposes of each other (reciprocal theorem), and
    the grand mobility is positive definite, also with blobs below a."""
    if backend == 'pycuda':
        pytest.skip('column-by-column assembly is a CPU test')
    rng = np.random.default_rng(7)
    a = 0.7
    r = random_configuration(rng, 8, a, box=5.0, low=0.3, high=4.0)
    for wall in (True, False):
        G = grand_mobility(r, 1.3, a, backend, wall)
        assert np.max(np.abs(G - G.T)) < 1e-13 * np.max(np.abs(G)), wall
        assert np.linalg.eigvalsh(0.5 * (G + G.T)).min() > 0.0, wall


def test_lone_blob_free_space_self_mobilities(backend):
    a, eta = 0.37, 1.9
    r = np.array([[0.0, 0.0, 1e7]])  # far from the wall: no_wall must be exact, wall nearly so
    e = np.array([1.0, 0.0, 0.0])
    for suffix, rtol in (('_no_wall', 1e-14), ('', 1e-6)):
        tt = mobility.blob_product(backend + suffix, 'trans_times_force')(r, e, eta, a)
        rr = mobility.blob_product(backend + suffix, 'rot_times_torque')(r, e, eta, a)
        rt = mobility.blob_product(backend + suffix, 'rot_times_force')(r, e, eta, a)
        np.testing.assert_allclose(tt, [1.0 / (6 * np.pi * eta * a), 0, 0], rtol=rtol, atol=1e-14)
        np.testing.assert_allclose(rr, [1.0 / (8 * np.pi * eta * a ** 3), 0, 0], rtol=rtol, atol=1e-14)
        assert np.max(np.abs(rt)) < 1e-12


# VALIDATION.md §2.1, "Swan-Brady single blob" rows: h/R, par, perp, rot_par, rot_perp (five digits).
SWAN_BRADY_SINGLE_BLOB = [
    (1.1, 0.54374, 0.27531, 0.76521, 0.90609), (1.2, 0.57847, 0.30162, 0.81916, 0.92766),
    (1.5, 0.65381, 0.38169, 0.90741, 0.96296), (2.0, 0.73242, 0.49609, 0.96094, 0.98438),
    (3.0, 0.81687, 0.64300, 0.98843, 0.99537), (5.0, 0.88848, 0.77896, 0.99750, 0.99900),
    (10.0, 0.94387, 0.88800, 0.99969, 0.99987)]


@pytest.mark.parametrize('row', SWAN_BRADY_SINGLE_BLOB, ids=lambda row: 'h%g' % row[0])
def test_single_blob_above_wall_matches_validation_table(backend, row):
    h, par, perp, rot_par, rot_perp = row
    a, eta = 1.0, 1.0
    r = np.array([[0.3, -0.2, h * a]])
    mu_t, mu_r = 1.0 / (6 * np.pi * eta * a), 1.0 / (8 * np.pi * eta * a ** 3)
    tt = mobility.blob_product(backend, 'trans_times_force')
    rr = mobility.blob_product(backend, 'rot_times_torque')
    rt = mobility.blob_product(backend, 'rot_times_force')
    x_dir, z_dir = np.array([1.0, 0, 0]), np.array([0, 0, 1.0])
    assert tt(r, x_dir, eta, a)[0] / mu_t == pytest.approx(par, abs=6e-6)
    assert tt(r, z_dir, eta, a)[2] / mu_t == pytest.approx(perp, abs=6e-6)
    assert rr(r, x_dir, eta, a)[0] / mu_r == pytest.approx(rot_par, abs=6e-6)
    assert rr(r, z_dir, eta, a)[2] / mu_r == pytest.approx(rot_perp, abs=6e-6)
    # coupling: omega_y = +(3/32) h^-4 F_x / (6 pi eta a^2), the rolling sense
    omega = rt(r, x_dir, eta, a)
    assert omega[1] / (1.0 / (6 * np.pi * eta * a ** 2)) == pytest.approx((3.0 / 32.0) / h ** 4, rel=1e-12)
    assert omega[1] > 0.0


def test_single_roller_grand_mobility_matches_published(backend, reference_dir):
    case = np.load(reference_dir / 'blob' / 'blob_single_roller_self_6x6.npz')
    a, eta = float(case['blob_radius']), float(case['eta'])
    for k, h in enumerate(case['heights']):
        r = np.array([[1.0, 2.0, h]])
        for wall, key in ((True, 'M6_single_wall_numba'), (False, 'M6_no_wall_numba')):
            G = grand_mobility(r, eta, a, backend, wall) if backend != 'pycuda' else None
            if G is None:
                continue
            assert relative_error(G, case[key][k]) < tolerance(backend), (h, key)


def test_wall_regularisation_limits():
    """VALIDATION.md §1.3: at z = a the self values are 0.5, 0.25 (tt par/perp) and
    0.6875, 0.875 (rr par/perp); below a the self mobility scales like (z/a)^2."""
    a, eta = 0.5, 1.0
    mu_t, mu_r = 1 / (6 * np.pi * eta * a), 1 / (8 * np.pi * eta * a ** 3)
    at_a = np.array([[0.0, 0.0, a]])
    M = mobility.single_wall_fluid_mobility(at_a, eta, a)
    np.testing.assert_allclose(np.diag(M) / mu_t, [0.5, 0.5, 0.25], rtol=1e-14)
    rr = mobility.single_wall_mobility_rot_times_torque(at_a, np.array([1.0, 0, 0]), eta, a)[0]
    assert rr / mu_r == pytest.approx(0.6875, rel=1e-14)
    for z in (0.1 * a, 0.5 * a, 0.9 * a):
        M_low = mobility.single_wall_fluid_mobility(np.array([[0.0, 0.0, z]]), eta, a)
        np.testing.assert_allclose(M_low, (z / a) ** 2 * M, rtol=1e-14)


def test_far_field_tends_to_oseen():
    """RPY -> Oseen (3/(4r))(I + r r^T/r^2) / (6 pi eta a) with an O(r^-3) error."""
    a, eta = 1.0, 1.0
    for distance in (1e2, 1e3):
        r = np.array([[0.0, 0.0, 0.0], [distance, 0.0, 0.0]])
        M = mobility.rotne_prager_tensor(r, eta, a)[0:3, 3:6] * 6 * np.pi * eta * a
        oseen = 0.75 / distance * np.diag([2.0, 1.0, 1.0])
        assert np.max(np.abs(M - oseen)) < 2.0 / distance ** 3


def large_random_system(n, periodic_length, seed):
    rng = np.random.default_rng(seed)
    a = 0.25
    box = np.sqrt(n / 0.5) if periodic_length[0] == 0 else periodic_length[0]
    r = np.column_stack([rng.uniform(0, box, n), rng.uniform(0, box, n), rng.uniform(0.2 * a, 5, n)])
    return r, rng.standard_normal(3 * n), a


@pytest.mark.parametrize('n, periodic_length, kinds', [
    (2000, (0.0, 0.0, 0.0), ['trans_times_force']),
    (2000, (40.0, 35.0, 0.0), ['trans_times_force']),
    (600, (8.0, 7.0, 0.0), PRODUCT_KINDS),
    (600, (0.0, 0.0, 0.0), PRODUCT_KINDS)])
def test_backends_agree_on_large_random_systems(n, periodic_length, kinds):
    """Python and C++ against each other on thousands of blobs, wall and free, periodic and not."""
    if not backends.is_usable('C++'):
        pytest.skip('C++ backend not built')
    r, f, a = large_random_system(n, periodic_length, 11)
    for suffix in ('', '_no_wall'):
        for kind in kinds:
            u_py = mobility.blob_product('python' + suffix, kind)(r, f, 1.0, a, periodic_length)
            u_cpp = mobility.blob_product('C++' + suffix, kind)(r, f, 1.0, a, periodic_length)
            assert relative_error(u_cpp, u_py) < 1e-12, (suffix, kind)


@pytest.mark.gpu
@pytest.mark.parametrize('periodic_length', [(0.0, 0.0, 0.0), (60.0, 50.0, 0.0)])
def test_gpu_agrees_with_cpp_on_large_systems(periodic_length):
    for name in ('pycuda', 'C++'):
        if not backends.is_usable(name):
            pytest.skip('%s backend not usable here: %s' % (name, backends.available_implementations()[name]))
    r, f, a = large_random_system(5000, periodic_length, 12)
    for suffix in ('', '_no_wall'):
        for kind in PRODUCT_KINDS:
            u_gpu = mobility.blob_product('pycuda' + suffix, kind)(r, f, 1.0, a, periodic_length)
            u_cpp = mobility.blob_product('C++' + suffix, kind)(r, f, 1.0, a, periodic_length)
            assert relative_error(u_gpu, u_cpp) < GPU_TOLERANCE, (suffix, kind)
        targets = r[::7] + 0.1
        v_gpu = mobility.source_target_product('pycuda' + suffix)(r, targets, f, a, 0.05, 1.0, periodic_length)
        v_cpp = mobility.source_target_product('C++' + suffix)(r, targets, f, a, 0.05, 1.0, periodic_length)
        assert relative_error(v_gpu, v_cpp) < GPU_TOLERANCE, suffix


def test_python_backend_memory_stays_bounded():
    """N = 3000: the dense matrix would take 648 MB; the chunked product must stay far below."""
    rng = np.random.default_rng(3)
    n, a = 3000, 0.25
    r = np.column_stack([rng.uniform(0, 70, n), rng.uniform(0, 70, n), rng.uniform(a, 5, n)])
    f = rng.standard_normal(3 * n)
    tracemalloc.start()
    mobility.single_wall_mobility_trans_times_force(r, f, 1.0, a, implementation='python')
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert peak < 120e6, 'peak %.0f MB' % (peak / 1e6)


def test_unknown_implementation_lists_the_known_names():
    with pytest.raises(UserInputError, match='C\\+\\+_no_wall'):
        mobility.mobility_vector_product('fortran')
    with pytest.raises(UserInputError, match='dense blob matrices'):
        mobility.blob_mobility_matrix('pycuda')


def test_numba_names_are_aliases_of_cpp():
    if not backends.is_usable('C++'):
        pytest.skip('C++ backend not built')
    assert mobility.mobility_vector_product('numba') is mobility.mobility_vector_product('C++')
    assert mobility.mobility_vector_product('numba_no_wall') is mobility.mobility_vector_product('C++_no_wall')


def test_unusable_backend_error_says_why_and_what_runs():
    if backends.is_usable('pycuda'):
        pytest.skip('a GPU is present: the CUDA backend is usable')
    with pytest.raises(UserInputError, match='cannot run on this machine.*usable here: python'):
        mobility.mobility_vector_product('pycuda')


def test_bad_shapes_and_box_are_rejected(backend):
    product = mobility.mobility_vector_product(backend)
    r = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 1.0]])
    with pytest.raises(ValueError):
        product(r, np.zeros(5), 1.0, 0.5)
    with pytest.raises(ValueError, match='along z'):
        product(r, np.zeros(6), 1.0, 0.5, (4.0, 4.0, 4.0))


def test_gpu_keeps_device_arrays_on_device(backend):
    if backend != 'pycuda':
        pytest.skip('device-array round trip applies to the CUDA backend')
    import cupy as cp
    rng = np.random.default_rng(5)
    r = random_configuration(rng, 300, 0.5, box=10.0)
    f = rng.standard_normal(900)
    u_device = mobility.mobility_vector_product('pycuda')(cp.asarray(r), cp.asarray(f), 1.0, 0.5)
    assert isinstance(u_device, cp.ndarray)
    u_host = mobility.mobility_vector_product('python')(r, f, 1.0, 0.5)
    assert relative_error(cp.asnumpy(u_device), u_host) < GPU_TOLERANCE


@pytest.mark.parametrize('periodic_length', [(0.0, 0.0, 0.0), (8.0, 7.0, 0.0)])
def test_source_target_backends_agree(periodic_length):
    """Velocity-field product: C++ equals python for point and finite tracers, above and below a."""
    if not backends.is_usable('C++'):
        pytest.skip('C++ backend not built')
    r, f, a = large_random_system(400, periodic_length, 13)
    rng = np.random.default_rng(14)
    targets = np.column_stack([rng.uniform(0, 8, 300), rng.uniform(0, 7, 300), rng.uniform(0.01, 3, 300)])
    for tracer_radius in (0.0, 0.1, rng.uniform(0.0, 0.5, 300)):
        for suffix in ('', '_no_wall'):
            v_py = mobility.source_target_product('python' + suffix)(r, targets, f, a, tracer_radius, 1.0,
                                                                      periodic_length)
            v_cpp = mobility.source_target_product('C++' + suffix)(r, targets, f, a, tracer_radius, 1.0,
                                                                    periodic_length)
            assert np.all(np.isfinite(v_cpp))
            assert relative_error(v_cpp, v_py) < 1e-12, (suffix, tracer_radius)


@pytest.mark.parametrize('name', ['C++', 'C++_no_wall', 'pycuda', 'pycuda_no_wall'])
def test_single_precision_product_is_accurate_to_float_rounding(name):
    """Single precision: relative error against double between 1e-9 and 1e-5
    (float rounding, eps = 6e-8, over sums of a few thousand pairs) -- and
    not zero, so the option really changes the arithmetic."""
    backend = name.split('_')[0]
    if not backends.is_usable(backend):
        pytest.skip('%s backend not usable here: %s' % (backend, backends.available_implementations()[backend]))
    for periodic_length in ((0.0, 0.0, 0.0), (40.0, 35.0, 0.0)):
        r, f, a = large_random_system(2000, periodic_length, 15)
        double = mobility.mobility_vector_product(name)(r, f, 1.0, a, periodic_length)
        single = mobility.mobility_vector_product(name, precision='single')(r, f, 1.0, a, periodic_length)
        error = relative_error(single, double)
        assert 1e-9 < error < 1e-5, (periodic_length, error)


def test_single_precision_is_refused_where_not_offered():
    with pytest.raises(UserInputError, match='compiled backends'):
        mobility.mobility_vector_product('python', precision='single')
    with pytest.raises(UserInputError, match='precision must be'):
        mobility.mobility_vector_product('python', precision='half')


@pytest.mark.parametrize('name', ['python', 'C++', 'python_no_wall', 'C++_no_wall'])
def test_dense_matrix_of_a_stack_equals_each_body_alone(name):
    """Preconditioner blocks: a stack (nb, n, 3) gives each body's own matrix."""
    backend = name.split('_')[0]
    if not backends.is_usable(backend):
        pytest.skip('%s backend not usable here' % backend)
    rng = np.random.default_rng(21)
    stack = np.stack([random_configuration(rng, 9, 0.4) for _ in range(5)])
    blocks = mobility.blob_mobility_matrix(name)(stack, 1.1, 0.4)
    for body, block in zip(stack, blocks):
        reference = (mobility.single_wall_fluid_mobility if not name.endswith('_no_wall')
                     else mobility.rotne_prager_tensor)(body, 1.1, 0.4)
        assert relative_error(block, reference) < 1e-14


def test_fluid_velocity_vanishes_on_the_wall(backend):
    """No-slip: the velocity at point tracers on z = 0 is zero whatever the forces
    (the image system of Blake 1971 cancels the free-space flow there)."""
    rng = np.random.default_rng(22)
    sources = np.column_stack([rng.uniform(0, 5, 20), rng.uniform(0, 5, 20), rng.uniform(0.5, 3, 20)])
    forces = rng.standard_normal(60)
    on_wall = np.column_stack([rng.uniform(-2, 7, 30), rng.uniform(-2, 7, 30), np.zeros(30)])
    velocity = mobility.source_target_product(backend)(sources, on_wall, forces, 0.5, 0.0, 1.0)
    near = mobility.source_target_product(backend)(sources, on_wall + [0, 0, 0.5], forces, 0.5, 0.0, 1.0)
    assert np.max(np.abs(velocity)) < 1e-12 * np.max(np.abs(near))
