"""Blobs of different radii and the free-slip surface (manual sections 2 and 6.1).

Numbers asserted come from the published code (../shared/reference/published_2025: the numba
kernels' products in mobility/radii_*.npz and free_surface_*.npz, and the published example run
multi_bodies/examples/radii), or from laws: symmetry and positive definiteness of a mobility,
the single-radius products as the limit of equal radii, the manual's soft-repulsion law.
"""
import importlib
import shutil

import numpy as np
import pytest

import mobility
from mobility import backends
from multi_bodies.files.snapshots import read_config_series
from multi_bodies.files.structure_files import read_vertex_file
from multi_bodies.solver import physics
from utils import UserInputError

PUBLISHED = 'published_2025'
CPU_BACKENDS = ['python', 'C++']
# Published products are sums of O(N) terms of size O(1) in double precision: 1e-12 relative is
# three orders above their rounding (measured 1e-15) and far below any formula difference.
TOLERANCE = 1e-12
RADII_CASES = ['radii_sparse', 'radii_dense', 'radii_near_wall']
FREE_SURFACE_CASES = ['free_surface_sparse', 'free_surface_dense']
SCRIPT = importlib.import_module('multi_bodies.multi_bodies')


def relative_error(value, reference):
    return float(np.max(np.abs(np.asarray(value) - reference)) / np.max(np.abs(reference)))


@pytest.fixture(params=CPU_BACKENDS)
def backend(request):
    if not backends.is_usable(request.param):
        pytest.skip('%s backend not usable here: %s' % (request.param,
                                                        backends.available_implementations()[request.param]))
    return request.param


@pytest.fixture(scope='module')
def published(reference_dir):
    folder = reference_dir / PUBLISHED
    if not folder.is_dir():
        pytest.skip('published_2025 reference data not found at %s' % folder)
    return folder


def load_case(published, name):
    data = np.load(published / 'mobility' / (name + '.npz'))
    return {k: data[k] for k in data.files}


# ------------------------------------------------------------------ products against the published kernels
@pytest.mark.parametrize('case', RADII_CASES)
def test_radii_products_match_published(case, backend, published):
    """radii_numba and radii_numba_no_wall of the published code, blobs below their radius included."""
    d = load_case(published, case)
    r, f, radius, eta = d['r'], d['force'], d['radius'], float(d['eta'])
    for suffix, key in (('', 'u_single_wall'), ('_no_wall', 'u_no_wall')):
        u = mobility.mobility_vector_product(backend + suffix)(r, f, eta, radius)
        assert relative_error(u, d[key]) < TOLERANCE, (backend + suffix, relative_error(u, d[key]))


@pytest.mark.parametrize('name, backend_name', [('radii_python', 'python'), ('radii_python_no_wall', 'python'),
                                                ('radii_numba', 'C++'), ('radii_numba_no_wall', 'C++'),
                                                ('radii_numba_free_surface', 'C++')])
def test_published_radii_names_are_aliases(name, backend_name):
    if not backends.is_usable(backend_name):
        pytest.skip('%s backend not usable here' % backend_name)
    plain = name[len('radii_'):].replace('numba', 'C++')
    assert mobility.mobility_vector_product(name) is mobility.mobility_vector_product(plain)


@pytest.mark.parametrize('case', FREE_SURFACE_CASES)
def test_free_surface_products_match_published(case, backend, published):
    """numba_free_surface of the published code; the dense matrix gives the same product."""
    d = load_case(published, case)
    r, f, a, eta = d['r'], d['force'], float(d['radius']), float(d['eta'])
    reference = d['u_free_surface']
    u = mobility.mobility_vector_product(backend + '_free_surface')(r, f, eta, a)
    assert relative_error(u, reference) < TOLERANCE
    M = mobility.blob_mobility_matrix(backend + '_free_surface')(r, eta, a)
    assert relative_error(M @ f, reference) < TOLERANCE
    # the per-blob radii form with equal radii is the same operator
    u_radii = mobility.source_target_product(backend + '_free_surface')(r, r, f, np.full(len(r), a),
                                                                         np.full(len(r), a), eta)
    assert relative_error(u_radii, reference) < TOLERANCE


def test_free_surface_names_of_the_manual():
    names = backends.all_names()
    for name in ('C++_free_surface', 'numba_free_surface', 'pycuda_free_surface', 'python_free_surface'):
        assert name in names
    if backends.is_usable('C++'):
        assert mobility.mobility_vector_product('numba_free_surface') is \
            mobility.mobility_vector_product('C++_free_surface')
    with pytest.raises(UserInputError, match='free surface has the product M f only'):
        mobility.blob_product('python_free_surface', 'rot_times_force')


# ------------------------------------------------------------------ dense matrices and laws
def separated_blobs(n, seed, wall_gap=1.2):
    """n blobs of radii in [0.1, 0.5] at least a_i + a_j apart and above z = wall_gap * a_i."""
    rng = np.random.default_rng(seed)
    r, radii = [], []
    while len(r) < n:
        a = rng.uniform(0.1, 0.5)
        x = rng.uniform(0.0, 6.0, 3)
        x[2] = rng.uniform(wall_gap * a, 4.0)
        if all(np.linalg.norm(x - y) > a + b for y, b in zip(r, radii)):
            r.append(x)
            radii.append(a)
    return np.array(r), np.array(radii)


@pytest.mark.parametrize('domain', ['', '_no_wall', '_free_surface'])
def test_dense_radii_matrix_is_the_product_and_spd(domain, backend):
    """The dense matrix with per-blob radii is the matrix of M f, symmetric and positive definite."""
    r, radii = separated_blobs(40, seed=3)
    f = np.random.default_rng(4).standard_normal(r.size)
    M = mobility.blob_mobility_matrix(backend + domain)(r, 0.7, radii)
    u = mobility.mobility_vector_product(backend + domain)(r, f, 0.7, radii)
    assert relative_error(M @ f, u) < 1e-13
    assert np.max(np.abs(M - M.T)) < 1e-13 * np.max(np.abs(M))
    assert np.min(np.linalg.eigvalsh(0.5 * (M + M.T))) > 0
    # a stack of bodies (preconditioner blocks) gives each body alone
    stack = mobility.blob_mobility_matrix(backend + domain)(r.reshape(4, 10, 3), 0.7, radii.reshape(4, 10))
    for k in range(4):
        alone = mobility.blob_mobility_matrix(backend + domain)(r[10 * k:10 * k + 10], 0.7, radii[10 * k:10 * k + 10])
        np.testing.assert_allclose(stack[k], alone, rtol=0, atol=1e-15 * np.max(np.abs(alone)))


def test_blobs_below_their_radius_keep_an_spd_wall_mobility(backend, published):
    """radii_near_wall: blobs below their own radius (height shift and damping); dense = published product."""
    d = load_case(published, 'radii_near_wall')
    r, radius, eta = d['r'], d['radius'], float(d['eta'])
    assert np.any(r[:, 2] < radius)
    M = mobility.blob_mobility_matrix(backend)(r, eta, radius)
    assert relative_error(M @ d['force'], d['u_single_wall']) < TOLERANCE
    assert np.max(np.abs(M - M.T)) < 1e-13 * np.max(np.abs(M))


@pytest.mark.parametrize('periodic_length', [(0.0, 0.0, 0.0), (7.0, 5.0, 0.0)])
def test_equal_radii_reproduce_the_single_radius_products(backend, periodic_length):
    """Per-blob radii that are all equal give the single-radius numbers exactly; the formula for
    different radii at equal radii (source-target form) equals them to rounding."""
    rng = np.random.default_rng(11)
    r = rng.uniform(0.0, 5.0, (60, 3))
    r[:, 2] = rng.uniform(0.1, 3.0, 60)  # some blobs below the radius 0.35
    f = rng.standard_normal(r.size)
    a = 0.35
    for domain in ('', '_no_wall', '_free_surface'):
        name = backend + domain
        single = mobility.mobility_vector_product(name)(r, f, 1.3, a, periodic_length)
        np.testing.assert_array_equal(mobility.mobility_vector_product(name)(r, f, 1.3, np.full(60, a),
                                                                             periodic_length), single)
        general = mobility.source_target_product(name)(r, r, f, np.full(60, a), np.full(60, a), 1.3, periodic_length)
        assert relative_error(general, single) < 1e-13, (name, relative_error(general, single))
        M_single = mobility.blob_mobility_matrix(name)(r, 1.3, a, periodic_length)
        np.testing.assert_array_equal(mobility.blob_mobility_matrix(name)(r, 1.3, np.full(60, a), periodic_length),
                                      M_single)


@pytest.mark.parametrize('periodic_length', [(0.0, 0.0, 0.0), (6.0, 6.0, 0.0)])
def test_radii_products_agree_between_backends(periodic_length):
    if not backends.is_usable('C++'):
        pytest.skip('C++ backend not built')
    r, radii = separated_blobs(50, seed=8, wall_gap=0.5)
    f = np.random.default_rng(9).standard_normal(r.size)
    for domain in ('', '_no_wall', '_free_surface'):
        u_py = mobility.mobility_vector_product('python' + domain)(r, f, 1.0, radii, periodic_length)
        u_cpp = mobility.mobility_vector_product('C++' + domain)(r, f, 1.0, radii, periodic_length)
        assert relative_error(u_cpp, u_py) < 1e-13
        M_py = mobility.blob_mobility_matrix('python' + domain)(r, 1.0, radii, periodic_length)
        assert relative_error(M_py @ f, u_py) < 1e-13


def test_gpu_radii_and_free_surface_match_published(published):
    if not backends.is_usable('pycuda'):
        pytest.skip('pycuda backend not usable here: %s' % backends.available_implementations()['pycuda'])
    for case in RADII_CASES:
        d = load_case(published, case)
        for suffix, key in (('', 'u_single_wall'), ('_no_wall', 'u_no_wall')):
            u = mobility.mobility_vector_product('pycuda' + suffix)(d['r'], d['force'], float(d['eta']), d['radius'])
            assert relative_error(u, d[key]) < 1e-10
    for case in FREE_SURFACE_CASES:
        d = load_case(published, case)
        u = mobility.mobility_vector_product('pycuda_free_surface')(d['r'], d['force'], float(d['eta']),
                                                                    float(d['radius']))
        assert relative_error(u, d['u_free_surface']) < 1e-10


def test_roller_couplings_refuse_different_radii():
    r, radii = separated_blobs(5, seed=1)
    with pytest.raises(UserInputError, match='no form for blobs of different radii'):
        mobility.blob_product('python', 'rot_times_force')(r, np.ones(r.size), 1.0, radii)


# ------------------------------------------------------------------ forces
@pytest.mark.parametrize('implementation', ['python', 'C++', 'radii_numba'])
def test_blob_blob_contact_distance_is_the_sum_of_the_radii(implementation):
    """The manual's soft repulsion with d = a_i + a_j (published radii forces), evaluated pair by pair."""
    rng = np.random.default_rng(0)
    r = rng.uniform(0.0, 3.0, (25, 3))
    radii = rng.uniform(0.1, 0.5, 25)
    eps, b, L = 2.0, 0.3, np.array([2.5, 0.0, 0.0])
    try:
        forces = physics.blob_blob_force_calculator(implementation)
    except UserInputError as err:
        pytest.skip(str(err))
    got = forces(r, periodic_length=L, repulsion_strength=eps, debye_length=b, blob_radius=0.25, blob_radii=radii)
    expected = np.zeros_like(r)
    for i in range(25):
        for j in range(25):
            if i != j:
                d = r[j] - r[i]
                d[0] -= np.trunc(d[0] / L[0] + 0.5 * np.sign(d[0])) * L[0]
                distance = np.linalg.norm(d)
                expected[i] -= (eps / b) * np.exp(-max(distance - radii[i] - radii[j], 0.0) / b) * d / distance
    assert relative_error(got, expected) < 1e-13


# ------------------------------------------------------------------ files and runs
def test_vertex_file_fourth_column(tmp_path):
    path = tmp_path / 'x.vertex'
    path.write_text('2 0.3\n0 0 1 0.2\n0 0 -1 0.4\n')
    blobs, radii = read_vertex_file(str(path), return_radii=True)
    np.testing.assert_array_equal(blobs, [[0, 0, 1], [0, 0, -1]])
    np.testing.assert_array_equal(radii, [0.2, 0.4])
    with pytest.raises(UserInputError, match='does not use'):
        read_vertex_file(str(path))
    path.write_text('2\n0 0 1\n0 0 -1\n')
    assert read_vertex_file(str(path), return_radii=True)[1] is None
    for text, fragment in (('2\n0 0 1 0.2\n0 0 -1\n', 'line 2: a blob radius in a fourth column, but line 3 has none'),
                           ('2\n0 0 1 0.2\n0 0 -1 -0.1\n', 'line 3: blob radius -0.1'),
                           ('2\n0 0 1 0.2 5\n0 0 -1 0.1\n', 'line 2: 5 values')):
        path.write_text(text)
        with pytest.raises(UserInputError, match=fragment):
            read_vertex_file(str(path), return_radii=True)


def copy_radii_example(published, tmp_path):
    """The published example folder with its ../../Structures relative paths, as published."""
    root = tmp_path / 'multi_bodies'
    shutil.copytree(published / 'multi_bodies' / 'Structures', root / 'Structures')
    folder = root / 'examples' / 'radii'
    shutil.copytree(published / 'multi_bodies' / 'examples' / 'radii', folder)
    for produced in list(folder.glob('run.*')) + list(folder.glob('run_wall.*')):
        produced.unlink()
    return folder


@pytest.mark.parametrize('input_name, output_name, ids', [('inputfile.dat', 'run', ('shell_1', 'shell_2')),
                                                          ('inputfile_wall.dat', 'run_wall', ('shell_1w', 'shell_2w'))])
def test_published_radii_example_runs_unchanged(input_name, output_name, ids, published, tmp_path, monkeypatch):
    """The example runs from a copy of its folder and its trajectory equals the published one.

    solver_tolerance 1e-12 bounds the relative error of the velocities (about 1, dt = 1) near 1e-12
    times the conditioning of the saddle-point system; 1e-9 in lengths and quaternions leaves a
    margin of that conditioning while any formula difference (radii ignored: a factor 2 in the
    small shell's velocity) is far above it.
    """
    if not backends.is_usable('C++'):
        pytest.skip('C++ backend not built (radii_numba is its alias)')
    folder = copy_radii_example(published, tmp_path)
    monkeypatch.chdir(folder)
    assert SCRIPT.main(['--input-file', input_name]) == 0
    reference = published / 'multi_bodies' / 'examples' / 'radii'
    for structure_id in ids:
        name = '%s.%s.config' % (output_name, structure_id)
        ours, theirs = read_config_series(str(folder / name)), read_config_series(str(reference / name))
        np.testing.assert_allclose(ours[0], theirs[0], rtol=0, atol=1e-9)
        np.testing.assert_allclose(ours[1], theirs[1], rtol=0, atol=1e-9)
    # the small shell (Rh = 0.5) sediments twice as fast as the large one (Rh = 1): Stokes drag
    shell_1, shell_2 = (read_config_series(str(folder / ('%s.%s.config' % (output_name, i))))[0] for i in ids)
    if output_name == 'run':
        drop_1, drop_2 = shell_1[0, 0, 2] - shell_1[1, 0, 2], shell_2[0, 0, 2] - shell_2[1, 0, 2]
        assert drop_2 / drop_1 == pytest.approx(2.0, rel=2e-3)


def write_radii_run(folder, scheme, extra=''):
    (folder / 'a.vertex').write_text('2\n0 0 0.5 0.2\n0 0 -0.5 0.3\n')
    (folder / 'a.clones').write_text('1\n0 0 5 1 0 0 0\n')
    (folder / 'in.dat').write_text('scheme %s\ndt 0.1\nn_steps 1\nn_save 1\neta 1\nblob_radius 0.25\n'
                                   'output_name out\n%sstructure a.vertex a.clones\n' % (scheme, extra))


@pytest.mark.parametrize('scheme, extra, fragment', [
    ('deterministic_forward_euler_rollers', '', 'roller schemes use the one blob_radius'),
    ('deterministic_forward_euler', 'blob_blob_force_implementation pycuda\n', 'pycuda'),
])
def test_radii_file_with_an_implementation_that_cannot_use_them_is_refused(scheme, extra, fragment, tmp_path,
                                                                          monkeypatch):
    """Refused before the run starts, naming the input line; never run with the radii ignored."""
    write_radii_run(tmp_path, scheme, extra)
    if 'rollers' in scheme:
        (tmp_path / 'a.vertex').write_text('1\n0 0 0 0.2\n')
    monkeypatch.chdir(tmp_path)
    with pytest.raises(UserInputError, match='in.dat, line 8: .*' + fragment):
        SCRIPT.main(['--input-file', 'in.dat'])
    assert not (tmp_path / 'out.info').exists()


def test_worked_example_of_the_docs_runs():
    """The Python example of doc/mobility.md, section 'Blobs of different radii' (its asserts: the dense
    matrix is the operator of M f, and a lone sphere has the Stokes mobility 1/(6 pi eta a))."""
    from conftest import REPO_ROOT
    if not backends.is_usable('C++'):
        pytest.skip('C++ backend not built')
    text = (REPO_ROOT / 'doc' / 'mobility.md').read_text(encoding='utf-8')
    section = text[text.index('## Blobs of different radii'):text.index('## Python API')]
    code = section[section.index('```python\n') + len('```python\n'):]
    exec(compile(code[:code.index('```')], 'doc/mobility.md', 'exec'), {})


def test_vtk_blobs_carry_the_radius_of_each_blob(published, tmp_path, monkeypatch):
    """save_vtk: the blobs' 'radius' point array is blob_radius for the shell without radii and the
    fourth column of the other shell's vertex file."""
    try:
        import pyvista
    except ImportError:
        pytest.skip('pyvista is not installed: the VTK files cannot be read back')
    if not backends.is_usable('C++'):
        pytest.skip('C++ backend not built (radii_numba is its alias)')
    folder = copy_radii_example(published, tmp_path)
    text = (folder / 'inputfile.dat').read_text() + '\nsave_vtk True\n'
    (folder / 'inputfile_vtk.dat').write_text(text)
    monkeypatch.chdir(folder)
    assert SCRIPT.main(['--input-file', 'inputfile_vtk.dat']) == 0
    blobs = pyvista.read(str(folder / 'run.blobs.00000000.vtp'))
    _, radii = read_vertex_file(str(folder / '../../Structures/shell_N_12_Rg_0.3960_Rh_0.5.vertex'),
                                return_radii=True)
    np.testing.assert_array_equal(blobs.point_data['radius'], np.concatenate((np.full(12, 0.416420683), radii)))


@pytest.mark.parametrize('domain', ['', '_no_wall', '_free_surface'])
def test_pseudo_periodic_radii_product_is_the_sum_over_neighbour_boxes(domain, backend):
    """With every pair closer than half a box, the pseudo-periodic product (minimum image, then the boxes
    -L, 0, +L along x and y) is the plain product from the sources copied into the nine boxes."""
    rng = np.random.default_rng(21)
    L = np.array([8.0, 9.0, 0.0])
    r = np.column_stack((rng.uniform(0, 3.5, 30), rng.uniform(0, 4.0, 30), rng.uniform(0.05, 3.0, 30)))
    radii = rng.uniform(0.1, 0.45, 30)
    f = rng.standard_normal(r.size)
    periodic = mobility.mobility_vector_product(backend + domain)(r, f, 0.9, radii, L)
    shifts = [(i * L[0], j * L[1], 0.0) for i in (-1, 0, 1) for j in (-1, 0, 1)]
    sources = np.concatenate([r + s for s in shifts])
    images = mobility.source_target_product(backend + domain)(sources, r, np.tile(f, 9), np.tile(radii, 9), radii,
                                                               0.9)
    assert relative_error(periodic, images) < 1e-13


def test_monte_carlo_and_free_surface_rollers_refuse(tmp_path, monkeypatch):
    """The Monte Carlo energies have one radius; the rollers have no free-surface couplings."""
    from multi_bodies.files.input_options import read_input_file
    from multi_bodies.run.run_setup import prepare
    write_radii_run(tmp_path, 'deterministic_forward_euler')
    (tmp_path / 'mc.dat').write_text('n_steps 1\nblob_radius 0.25\noutput_name mc\nstructure a.vertex a.clones\n')
    monkeypatch.chdir(tmp_path)
    with pytest.raises(UserInputError, match='Monte Carlo energies use the one blob_radius'):
        prepare(read_input_file('mc.dat', 'mcmc'), 'mcmc', log=lambda text: None)
    (tmp_path / 'a.vertex').write_text('1\n0 0 0\n')
    (tmp_path / 'in.dat').write_text('scheme deterministic_forward_euler_rollers\ndt 0.1\nn_steps 1\nn_save 1\n'
                                     'blob_radius 0.25\noutput_name out\n'
                                     'mobility_vector_prod_implementation python_free_surface\n'
                                     'structure a.vertex a.clones\n')
    with pytest.raises(UserInputError, match='no free-surface couplings'):
        SCRIPT.main(['--input-file', 'in.dat'])


def test_published_function_names(published):
    """mobility_radii_trans_times_force (the published entry point of the radii products) and
    free_surface_mobility_trans_times_force reproduce the published numbers."""
    d = load_case(published, 'radii_dense')
    u = mobility.mobility_radii_trans_times_force(d['r'], d['force'], float(d['eta']), 0.3, d['radius'],
                                                  mobility.single_wall_mobility_source_target)
    assert relative_error(u, d['u_single_wall']) < TOLERANCE
    d = load_case(published, 'free_surface_dense')
    u = mobility.free_surface_mobility_trans_times_force(d['r'], d['force'], float(d['eta']), float(d['radius']))
    assert relative_error(u, d['u_free_surface']) < TOLERANCE
    M = mobility.free_surface_fluid_mobility(d['r'], float(d['eta']), float(d['radius']))
    assert relative_error(M @ d['force'], d['u_free_surface']) < TOLERANCE


def test_body_mobility_of_the_half_size_shell_scales_as_stokes_flow(published, tmp_path, monkeypatch):
    """multi_bodies_utilities.py body_mobility: the small shell is the large one scaled by 1/2 (blob positions
    and radii), so in free space its translational mobility is exactly twice, its rotational mobility eight
    times the large one's (Stokes scaling), and the large one's is 1/(6 pi eta Rh) with Rh = 1 to the
    accuracy of its 12-blob discretisation (the shells' file names give Rh; 1e-3).  The two vertex files
    agree with the factor 1/2 to the 13-16 digits they are printed with; through the inverse of the blob
    mobility that leaves about 3e-10 in the body mobility, so 1e-8."""
    folder = copy_radii_example(published, tmp_path)
    (folder / 'bm.dat').write_text(
        'scheme body_mobility\nmobility_blobs_implementation python_no_wall\n'
        'mobility_vector_prod_implementation radii_python_no_wall\neta 0.0530516476972984\n'
        'blob_radius 0.416420683\noutput_name bm\n'
        'structure ../../Structures/shell_N_12_Rg_0_7921_Rh_1.vertex shell_1.clones\n'
        'structure ../../Structures/shell_N_12_Rg_0.3960_Rh_0.5.vertex shell_2.clones\n')
    monkeypatch.chdir(folder)
    static = importlib.import_module('multi_bodies.multi_bodies_utilities')
    assert static.main(['--input-file', 'bm.dat']) == 0
    N = np.loadtxt(folder / 'bm.body_mobility.dat')
    large, small = N[:6, :6], N[6:, 6:]
    np.testing.assert_allclose(small[:3, :3], 2.0 * large[:3, :3], rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(small[3:, 3:], 8.0 * large[3:, 3:], rtol=1e-8, atol=1e-10)
    assert large[0, 0] == pytest.approx(1.0 / (6.0 * np.pi * 0.0530516476972984), rel=1e-3)
