"""Periodic and confined suspensions on the spectral product (issue 45, doc/periodic.md).

Numbers asserted come from outside the code under test:
* the published folder's near-wall rule (its ``FCMJoint_MB.py``: heights below a raised to a, forces and
  velocities multiplied by z/a), applied here by hand to the plain spectral product;
* the covariance law of the noise (the sample covariance against the product's own matrix, tolerance from its
  standard error, with a control that must fail), and the exact symmetric square root (eigendecomposition) of
  the product's symmetric part for the Lanczos noise of the Chebyshev geometries;
* the agreement of two algorithms on one problem (GMRES against the dense solve of the same matrix);
* the Gibbs-Boltzmann height density by quadrature, and the wall geometry's own trajectories in a large box;
* one-line refusals naming the file, line and option.
"""
import os
import warnings

import numpy as np
import pytest

from mobility.interface import Geometry, make_mobility
from mobility.spectral.fluctuations import generator_from_normals, triply_periodic_noise
from utils import SimulationStopped, UserInputError

REPO_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def spectral(kind, L=16.0, z_bounds=(0.0, 6.0), kernel='w4', **options):
    geometry = Geometry(kind, (L, L, L if kind == 'triply_periodic' else 0.0),
                        None if kind == 'triply_periodic' else z_bounds)
    with warnings.catch_warnings():
        warnings.simplefilter('ignore')  # the whole-cells note of square boxes
        return make_mobility('spectral', geometry, eta=1.0, blob_radius=1.0, kernel=kernel, **options)


def blobs(n, seed, L=16.0, low=1.2, high=4.8):
    rng = np.random.default_rng(seed)
    return np.column_stack([rng.uniform(0, L, n), rng.uniform(0, L, n), rng.uniform(low, high, n)])


def matrix_of(mobility, r):
    """The product's matrix, column by column (3N products), not symmetrised."""
    n = 3 * len(r)
    return np.column_stack([mobility.velocities(r, e) for e in np.eye(n)])


# ====================================================================== the near-wall rule
@pytest.mark.parametrize('kind', ['doubly_periodic_wall', 'doubly_periodic_slit'])
def test_near_wall_rule_is_the_published_shift_and_damping(kind):
    """Blobs closer than a to a wall: the product at heights raised to a (lowered to H - a at a slit's top),
    forces and velocities multiplied by distance/a (the published FCMJoint_MB), computed by hand here."""
    plain = spectral(kind)
    rule = spectral(kind, near_wall='published')
    r = blobs(5, 1)
    r[0, 2], r[1, 2] = 0.3, 0.999  # within a of the bottom wall
    if kind == 'doubly_periodic_slit':
        r[2, 2] = 5.6                  # within a of the top wall at 6
    r_eff = r.copy()
    r_eff[:2, 2] = 1.0
    damping = np.ones(5)
    damping[:2] = r[:2, 2]
    if kind == 'doubly_periodic_slit':
        r_eff[2, 2] = 5.0
        damping[2] = 0.4
    F = np.random.default_rng(2).standard_normal(15)
    expected = plain.velocities(r_eff, F * np.repeat(damping, 3)) * np.repeat(damping, 3)
    assert np.allclose(rule.velocities(r, F), expected, rtol=0, atol=1e-14 * np.abs(expected).max())
    # far from the walls the rule changes nothing
    far = blobs(5, 3)
    assert np.array_equal(rule.velocities(far, F), plain.velocities(far, F))
    # a blob on the wall does not move and moves nothing
    on_wall = r.copy()
    on_wall[0, 2] = 0.0
    U = rule.velocities(on_wall, F)
    assert np.all(U[:3] == 0.0)
    F0 = np.zeros(15)
    F0[:3] = 1.0
    assert np.all(rule.velocities(on_wall, F0) == 0.0)


# ====================================================================== noise
def covariance_z(samples, M):
    """Entry-wise z-scores of the sample covariance of ``samples`` (n, d) against M (d, d): the standard error of
    entry (i, j) of the mean of x_i x_j is sqrt((M_ii M_jj + M_ij^2)/n) for Gaussian x."""
    n = samples.shape[0]
    C = samples.T @ samples / n
    se = np.sqrt((np.outer(np.diag(M), np.diag(M)) + M ** 2) / n)
    return (C - M) / se


def test_fluctuating_noise_has_the_covariance_of_the_product():
    """Triply periodic box: 12,000 samples of the fluctuating-force noise of 3 blobs against the product's
    matrix M (symmetric to round-off); the 45 distinct entries' z-scores are below 4.5 (about p = 3e-4 for the
    largest of 45 normals); the control M * 1.1 (a 5 % error in the noise amplitude) is seen at more than 6."""
    mobility = spectral('triply_periodic', L=12.0, noise='fluctuating')
    r = np.array([[1.0, 2.0, 3.0], [3.2, 2.5, 3.7], [8.0, 9.0, 1.0]])
    M = matrix_of(mobility, r)
    assert np.abs(M - M.T).max() < 1e-12 * np.abs(M).max()
    rng = np.random.default_rng(11)
    samples = np.array([triply_periodic_noise(mobility.parameters, 1.0, r, rng).ravel() for _ in range(12000)])
    upper = np.triu_indices(9)
    assert np.abs(covariance_z(samples, M)[upper]).max() < 4.5
    assert np.abs(covariance_z(samples, 1.1 * M)[upper]).max() > 6.0


def test_fluctuating_noise_through_the_interface_is_seeded_by_z():
    """``noise`` of the fluctuating backend: linear in factor, a function of z (same z, same noise; another z,
    another noise), no Krylov iterations."""
    mobility = spectral('triply_periodic', L=12.0, noise='fluctuating')
    r = blobs(4, 5, L=12.0)
    z = np.random.default_rng(1).standard_normal(12)
    first = mobility.noise(r, z, factor=2.0)
    assert first.iterations == 0 and first.converged
    again = mobility.noise(r, z, factor=1.0).noise
    assert np.allclose(first.noise, 2.0 * again, rtol=1e-14, atol=0)
    assert not np.allclose(mobility.noise(r, -z).noise, again)
    direct = triply_periodic_noise(mobility.parameters, 1.0, r, generator_from_normals(z)).ravel()
    assert np.array_equal(direct, again)


@pytest.mark.parametrize('kind', ['doubly_periodic_wall', 'doubly_periodic_slit', 'doubly_periodic_open'])
def test_lanczos_noise_of_the_chebyshev_product_is_the_root_of_its_symmetric_part(kind):
    """The Chebyshev geometries' product is symmetric only to its discretisation (~1e-5 to 1e-4 of |M|): Lanczos
    over it gives, for every z, the exact symmetric root of the symmetric part S (eigendecomposition) times z to
    within that asymmetry, so its covariance is S to that accuracy; the root of the direct wall mobility (another
    matrix) is 10 to 100 times farther."""
    mobility = spectral(kind)
    r = blobs(6, 2)
    M = matrix_of(mobility, r)
    asymmetry = np.abs(M - M.T).max() / np.abs(M).max()
    assert asymmetry < mobility.relative_accuracy
    S = 0.5 * (M + M.T)
    w, V = np.linalg.eigh(S)
    assert w.min() > 0
    root = (V * np.sqrt(w)) @ V.T
    wall = make_mobility('python', Geometry('single_wall'), 1.0, 1.0).dense_matrix(r)
    w_wall, V_wall = np.linalg.eigh(wall)
    wall_root = (V_wall * np.sqrt(w_wall)) @ V_wall.T
    rng = np.random.default_rng(3)
    for _ in range(4):
        z = rng.standard_normal(r.size)
        noise = mobility.noise(r, z, tolerance=1e-12).noise
        error = np.linalg.norm(noise - root @ z) / np.linalg.norm(root @ z)
        assert error < max(2.0 * asymmetry, 1e-12), (error, asymmetry)
        assert np.linalg.norm(noise - wall_root @ z) / np.linalg.norm(root @ z) > 10 * asymmetry


def test_dense_matrix_is_the_symmetric_part_of_the_products():
    """``dense_matrix`` of the spectral backend: (M + M^T)/2 of its own products (in TP M itself, to round-off);
    per-body stacks are refused in one line."""
    for kind in ('triply_periodic', 'doubly_periodic_wall'):
        mobility = spectral(kind)
        r = blobs(3, 4)
        M = matrix_of(mobility, r)
        assert np.allclose(mobility.dense_matrix(r), 0.5 * (M + M.T), rtol=0, atol=1e-14 * np.abs(M).max())
    with pytest.raises(UserInputError, match='per-body dense blocks'):
        mobility.dense_matrix(r[None])


# ====================================================================== input files
def write_rollers(folder, locations, options, structure='blob.vertex rollers.clones'):
    from multi_bodies.files.snapshots import write_clones_file
    from multi_bodies.files.structure_files import write_vertex_file
    write_vertex_file(folder / 'blob.vertex', np.zeros((1, 3)))
    locations = np.asarray(locations, dtype=float).reshape(-1, 3)
    write_clones_file(folder / 'rollers.clones', locations, np.tile([1.0, 0, 0, 0], (len(locations), 1)))
    base = {'scheme': 'deterministic_forward_euler_rollers', 'dt': 0.01, 'n_steps': 2, 'n_save': 1, 'eta': 1.0,
            'g': 1.0, 'blob_radius': 1.0, 'repulsion_strength_wall': 1.0, 'debye_length_wall': 0.25,
            'omega_one_roller': '0 1 0', 'mobility_vector_prod_implementation': 'spectral',
            'periodic_length': '16 16 0', 'spectral_kernel': 'w5w4', 'output_name': 'run', 'seed': 1}
    base.update(options)
    text = ''.join('%s %s\n' % (name, value) for name, value in base.items() if value is not None)
    (folder / 'input.dat').write_text(text + 'structure %s\n' % structure)


def run_script(folder, monkeypatch, script='multi_bodies'):
    import importlib
    module = importlib.import_module('multi_bodies.' + script)
    monkeypatch.chdir(folder)
    return module.main(['--input-file', 'input.dat'])


TWO_ROLLERS = [[4.0, 4.0, 1.6], [9.0, 5.0, 2.1]]


@pytest.mark.parametrize('options, fragment', [
    ({'mobility_vector_prod_implementation': 'C++', 'spectral_kernel': None, 'spectral_geometry': 'triply_periodic'},
     'spectral_geometry is an option of the spectral product'),
    ({'spectral_geometry': 'doubly_periodic_slit'}, 'needs spectral_z_bounds'),
    ({'spectral_geometry': 'doubly_periodic_open'}, 'needs spectral_z_bounds'),
    ({'spectral_z_bounds': '0.5 8'}, 'the bottom wall is at z = 0'),
    ({'spectral_z_bounds': '3 2'}, 'zmin < zmax'),
    ({'periodic_length': '16 13 0'}, 'whole number of cells'),
    ({'periodic_length': '16 16 16', 'spectral_geometry': 'doubly_periodic_wall'}, 'not periodic in z'),
    ({'periodic_length': '0 16 0'}, 'periodic in x and y'),
    ({'spectral_geometry': 'triply_periodic'}, 'needs periodic_length Lx Ly Lz'),
    ({'spectral_noise': 'fluctuating', 'scheme': 'stochastic_first_order_rollers', 'kT': 0.1},
     'triply periodic box only'),
    ({'spectral_kernel': 'w4'}, "no dipole kernel for the rollers"),
    ({'domain': 'no_wall'}, 'the walls are those of spectral_geometry'),
    ({'mobility_blobs_implementation': 'spectral'}, "unknown mobility_blobs_implementation 'spectral'"),
])
def test_refusals_are_one_line_naming_file_and_line(tmp_path, monkeypatch, options, fragment):
    write_rollers(tmp_path, TWO_ROLLERS, options)
    with pytest.raises(UserInputError) as refused:
        run_script(tmp_path, monkeypatch)
    message = str(refused.value)
    assert fragment in message and message.startswith('input.dat, line') and '\n' not in message, message
    assert not (tmp_path / 'run.info').exists()


def test_rigid_bodies_refuse_a_kernel_pair_and_periodic_z_over_the_wall(tmp_path, monkeypatch):
    write_rollers(tmp_path, TWO_ROLLERS, {'scheme': 'deterministic_forward_euler', 'spectral_kernel': 'w6w4'})
    with pytest.raises(UserInputError, match='rigid bodies use the force-only kernels'):
        run_script(tmp_path, monkeypatch)


def test_whole_cells_refusal_names_the_period_that_fits(tmp_path, monkeypatch):
    """The grid of blob_radius 1, kernel w5w4 has h = 16/Nx; Ly = 13 is not whole cells: the message gives the
    box that is, and that box runs."""
    write_rollers(tmp_path, TWO_ROLLERS, {'periodic_length': '16 13 0'})
    with pytest.raises(UserInputError) as refused:
        run_script(tmp_path, monkeypatch)
    fitted = str(refused.value).split('Use periodic_length ')[1].split(' (')[0]
    Lx, Ly, _ = (float(v) for v in fitted.split())
    assert Lx == 16.0 and abs(Ly - 13.0) < 0.7
    write_rollers(tmp_path, TWO_ROLLERS, {'periodic_length': fitted})
    assert run_script(tmp_path, monkeypatch) == 0


def test_a_restart_with_another_geometry_is_refused(tmp_path, monkeypatch):
    """The spectral options are in the restart fingerprint: the same run restarted with another top wall stops."""
    write_rollers(tmp_path, TWO_ROLLERS, {'spectral_geometry': 'doubly_periodic_slit', 'spectral_z_bounds': '0 8',
                                          'n_steps': 4, 'n_save': 2})
    assert run_script(tmp_path, monkeypatch) == 0
    write_rollers(tmp_path, TWO_ROLLERS, {'spectral_geometry': 'doubly_periodic_slit', 'spectral_z_bounds': '0 9',
                                          'n_steps': 4, 'n_save': 2, 'initial_step': 2})
    with pytest.raises(UserInputError, match='spectral_z_bounds: was'):
        run_script(tmp_path, monkeypatch)


def test_a_record_older_than_an_option_counts_it_at_its_default():
    from multi_bodies.run.restart_records import fingerprint_changes
    current = {'scheme': "'x'", 'spectral_geometry': "'auto'", 'spectral_z_bounds': 'None'}
    assert fingerprint_changes({'scheme': "'x'"}, current) == []
    assert fingerprint_changes({'scheme': "'x'"}, dict(current, spectral_geometry="'triply_periodic'"))


def test_slit_top_wall_invalidates_and_the_open_box_stops_the_run(tmp_path, monkeypatch):
    """A roller through the top wall of a slit is an invalid configuration (the step is redone); a roller that
    leaves the heights of an open box stops the run with one line, its .info written (exit status 1)."""
    from multi_bodies.files.input_options import parse_input_text
    from multi_bodies.run.run_setup import prepare
    from body.body import Configuration
    write_rollers(tmp_path, TWO_ROLLERS, {'spectral_geometry': 'doubly_periodic_slit', 'spectral_z_bounds': '0 8'})
    monkeypatch.chdir(tmp_path)
    options = parse_input_text((tmp_path / 'input.dat').read_text(), 'input.dat', 'dynamic')
    model = prepare(options, 'dynamics', log=lambda line: None).system
    up = Configuration(np.array([[4.0, 4.0, 8.2], [9.0, 5.0, 2.1]]), np.tile([1.0, 0, 0, 0], (2, 1)))
    assert list(model.invalid_bodies(up)) == [0]
    # the default physics pushes down from the top wall as up from the bottom one
    r = np.array([[0, 0, 1.5], [0, 0, 6.5]])
    f = model.blob_forces(r)[:, 2]
    assert np.isclose(f[0] + f[1], -2 * 1.0) and f[1] < -1.0
    write_rollers(tmp_path, [[4.0, 4.0, 7.9], [9.0, 5.0, 4.0]],
                  {'spectral_geometry': 'doubly_periodic_open', 'spectral_z_bounds': '0 8', 'g': -100.0,
                   'n_steps': 20})
    assert run_script(tmp_path, monkeypatch) == 1
    assert 'outside the heights [0, 8]' in (tmp_path / 'run.info').read_text()


def test_worked_example_runs_as_written():
    """doc/periodic.md's rollers in a slit: the commands of its block, run from the repository root as written;
    every saved height lies between the walls, and the run logged the slit it made."""
    import re
    import shutil
    import subprocess
    import sys
    text = open(os.path.join(REPO_ROOT, 'doc', 'periodic.md'), encoding='utf-8').read()
    section = text[text.index('## A worked example'):]
    block = re.search(r'```\n(.*?)```', section, re.S).group(1)
    assert 'inputfile_slit.dat' in block
    folder = os.path.join(REPO_ROOT, 'multi_bodies', 'examples', 'slit_rollers')
    shutil.rmtree(os.path.join(folder, 'data'), ignore_errors=True)
    try:
        done = subprocess.run(['bash', '-e', '-c', block.replace('python3 ', sys.executable + ' ')], cwd=REPO_ROOT,
                              capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, done.stderr[-2000:]
        assert 'spectral product: doubly_periodic_slit, periods 30 30 0, z bounds 0 5' in done.stdout
        snapshots = sorted(name for name in os.listdir(os.path.join(folder, 'data')) if name.endswith('.clones'))
        assert len(snapshots) == 6
        for name in snapshots:
            z = np.loadtxt(os.path.join(folder, 'data', name), skiprows=1)[:, 2]
            assert np.all((z > 0) & (z < 5)), name
    finally:
        shutil.rmtree(os.path.join(folder, 'data'), ignore_errors=True)


# ====================================================================== runs on the spectral product
def spectral_model(bodies, kind, L, z_bounds, kernel, tolerance=1e-10, blobs='C++', physics=None, **extra):
    """A Model of ``bodies`` with the spectral product in ``kind`` (blob radius 1, eta 1, the default physics with
    g = 1 per blob unless ``physics`` says otherwise)."""
    from body.body import bodies_to_arrays
    from multi_bodies import multi_bodies_functions as mbf
    from multi_bodies.solver.model import Model
    from multi_bodies.solver.periodic import SpectralDomain
    Lz = L if kind == 'triply_periodic' else 0.0
    values = dict(g=1.0, repulsion_strength_wall=1.0, debye_length_wall=0.25, repulsion_strength=1.0,
                  debye_length=1.0, periodic_length=np.array([L, L, Lz]), blob_radius=1.0, blob_mass=1.0,
                  top_wall=z_bounds[1] if kind == 'doubly_periodic_slit' else None)
    values.update(physics or {})
    domain = SpectralDomain(Geometry(kind, (L, L, Lz), None if kind == 'triply_periodic' else z_bounds), kernel)
    with warnings.catch_warnings():
        warnings.simplefilter('ignore')
        return Model(bodies, bodies_to_arrays(bodies, [len(bodies)]), mbf.load_user_hooks('/nonexistent'), values,
                     1.0, 1.0, tolerance, vector_product_name='spectral', blobs_name=blobs,
                     periodic_length=(L, L, Lz), spectral=domain, **extra)


def direct_model(bodies, L, tolerance=1e-10, **extra):
    """The same bodies with the C++ wall product and the published pseudo-periodic box (L, L, 0)."""
    from body.body import bodies_to_arrays
    from multi_bodies import multi_bodies_functions as mbf
    from multi_bodies.solver.model import Model
    values = dict(g=1.0, repulsion_strength_wall=1.0, debye_length_wall=0.25, repulsion_strength=1.0,
                  debye_length=1.0, periodic_length=np.array([L, L, 0.0]), blob_radius=1.0, blob_mass=1.0)
    return Model(bodies, bodies_to_arrays(bodies, [len(bodies)]), mbf.load_user_hooks('/nonexistent'), values, 1.0,
                 1.0, tolerance, vector_product_name='C++', blobs_name='C++', periodic_length=(L, L, 0.0), **extra)


def roller_bodies(locations):
    from body.body import Body
    bodies = [Body(np.array(l, dtype=float), np.array([1.0, 0, 0, 0]), np.zeros((1, 3)), 1.0) for l in locations]
    for body in bodies:
        body.ID, body.body_length = 'roller', 2.0
    return bodies


def tetrahedra(locations, seed=0):
    """Rigid bodies of 4 blobs of radius 1 at the corners of a tetrahedron of edge 3.25 (random orientations)."""
    from body.body import Body
    reference = 1.15 * np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1.0]])
    rng = np.random.default_rng(seed)
    bodies = []
    for location in locations:
        q = rng.standard_normal(4)
        body = Body(np.array(location, dtype=float), q / np.linalg.norm(q), reference, 1.0)
        body.ID, body.body_length = 'tetrahedron', 5.0
        bodies.append(body)
    return bodies


def run_steps(model, scheme_name, steps, dt=0.05):
    from multi_bodies.files.input_options import options_with
    from quaternion_integrator.schemes import make_scheme
    scheme = make_scheme(scheme_name, dt, options_with(kT=0.0, rf_delta=1e-3, update_PC=1))
    state = scheme.init(model, model.start_configuration)
    for _ in range(steps):
        state = scheme.step(model, state, np.random.default_rng(0))
    return state.configuration


ROLLERS = [[10.0, 10.0, 3.0], [14.0, 11.0, 4.0], [12.0, 15.0, 3.5], [30.0, 31.0, 5.0]]
TETRAHEDRA = [[10.0, 10.0, 4.0], [15.0, 11.0, 5.0], [30.0, 31.0, 4.5]]


def test_roller_trajectories_above_the_wall_follow_the_wall_geometry():
    """4 rollers (torque about y, gravity) in a doubly periodic box of side 128 above the wall: 3 steps of
    deterministic_forward_euler_rollers agree with the pseudo-periodic wall product's to 3e-3 of the displacement
    (doc/periodic.md: 2.1e-3 at L = 128 with the w6 pair, the far periodic images that the first ring of the
    pseudo-periodic sum lacks; 1.2e-2 at L = 64); each roller step pays one spectral product."""
    bodies = roller_bodies(ROLLERS)
    spectral_run = spectral_model(bodies, 'doubly_periodic_wall', 128.0, (0.0, 9.1740639106166668), 'w6',
                                  omega_one_roller=(0.0, 1.0, 0.0))
    direct_run = direct_model(bodies, 128.0, omega_one_roller=(0.0, 1.0, 0.0))
    start = spectral_run.start_configuration.locations
    moved_s = run_steps(spectral_run, 'deterministic_forward_euler_rollers', 3).locations - start
    moved_d = run_steps(direct_run, 'deterministic_forward_euler_rollers', 3).locations - start
    assert np.abs(moved_d).max() > 5e-3
    assert np.abs(moved_s - moved_d).max() < 3e-3 * np.abs(moved_d).max()
    stokes = spectral_run.roller_mobility.stokes
    calls = []
    product = stokes.product
    stokes.product = lambda *args: calls.append(1) or product(*args)
    spectral_run.roller_velocities(spectral_run.start_configuration)
    assert len(calls) == 1


@pytest.mark.parametrize('kernel, accuracy', [('w6', 5e-3), ('w4', 5e-3)])
def test_rigid_body_trajectories_above_the_wall_follow_the_wall_geometry(kernel, accuracy):
    """3 rigid tetrahedra of 4 blobs (blobs at 2.66 a from each other) in a box of side 64 above the wall: 2 steps of
    deterministic_forward_euler agree with the pseudo-periodic wall product's to 5e-3 of the displacement
    (doc/periodic.md: 3.5e-3 for w6, 3.8e-3 for w4, the kernel's pair mobility at near contact against
    Rotne-Prager's; not a box effect: the same at L = 128)."""
    bodies = tetrahedra(TETRAHEDRA)
    spectral_run = spectral_model(bodies, 'doubly_periodic_wall', 64.0, (0.0, 9.1740639106166668), kernel)
    direct_run = direct_model(bodies, 64.0)
    start = spectral_run.start_configuration
    end_s, end_d = run_steps(spectral_run, 'deterministic_forward_euler', 2), run_steps(direct_run,
                                                                                      'deterministic_forward_euler', 2)
    moved_d = end_d.locations - start.locations
    assert np.abs(moved_d).max() > 1e-3
    assert np.abs(end_s.locations - end_d.locations).max() < accuracy * np.abs(moved_d).max()


@pytest.mark.parametrize('kind', ['triply_periodic', 'doubly_periodic_open', 'doubly_periodic_wall',
                                  'doubly_periodic_slit'])
def test_static_problems_agree_with_the_dense_solve(kind):
    """The mobility problem of 3 tetrahedra solved by GMRES over the spectral product equals the dense solve
    N (K^T M^-1 ...) of the same product's matrix: to the solver tolerance in the triply periodic box (M symmetric
    to round-off), to the product's asymmetry elsewhere (the dense matrix is its symmetric part); and the
    resistance problem of those velocities gives back the forces."""
    bodies = tetrahedra([[6.0, 6.0, 4.0], [11.0, 7.0, 5.0], [8.0, 12.0, 4.5]], seed=3)
    model = spectral_model(bodies, kind, 24.0, (0.0, 9.0), 'w4', tolerance=1e-12)
    configuration = model.start_configuration
    iterative = model.deterministic_velocities(configuration).velocities
    dense = model.dense_velocities(configuration)
    scale = np.abs(dense).max()
    accuracy = 1e-9 if kind == 'triply_periodic' else model.vector_mobility.relative_accuracy
    assert np.abs(iterative - dense).max() < accuracy * scale, np.abs(iterative - dense).max() / scale
    from multi_bodies.solver import body_solver
    force_torque = model.forces_torques(configuration)
    back, _ = body_solver.solve_resistance_problem(model.arrays, configuration, dense,
                                                   np.zeros((model.num_blobs, 3)), model.dense_mobility)
    assert np.allclose(back, force_torque, rtol=0, atol=1e-8 * np.abs(force_torque).max())


# ====================================================================== Gibbs-Boltzmann
# Scene of the equilibrium tests (the one of tests/test_stochastic.py): a = 1, eta = 1/(6 pi) (so mu0 = 1), kT = 1,
# weight 2 per blob, wall repulsion eps = 2, b = 0.25; in the slit the same repulsion from the top wall at 5.
# Rollers without torque, 100 in a 40 x 40 box (4 apart: the heights of independent blobs, the bodies' time averages
# nearly independent), w5w4 kernel pair, stochastic_trapezoidal_rollers, dt 0.01, 250 steps (four relaxation
# times of the heights), Lanczos to 1e-3.
GB_G, GB_EPS, GB_B, GB_ETA = 2.0, 2.0, 0.25, 1.0 / (6.0 * np.pi)


def gb_energy(z, top):
    def wall(gap):
        return np.where(gap < 1.0, GB_EPS + GB_EPS * (1.0 - gap) / GB_B, GB_EPS * np.exp(-(gap - 1.0) / GB_B))
    energy = GB_G * z + wall(z)
    return energy if top is None else energy + wall(top - z)


def gb_quadrature(top, upper=12.0):
    """The exact height density exp(-U/kT) on a fine grid: (grid, cdf, mean, 8 equiprobable bin edges)."""
    grid = np.linspace(1e-4, upper if top is None else top, 200001)
    density = np.exp(-gb_energy(grid, top))
    cdf = np.cumsum(density)
    cdf /= cdf[-1]
    mean = np.trapezoid(grid * density, grid) / np.trapezoid(density, grid)
    edges = np.concatenate(([-np.inf], np.interp(np.arange(1, 8) / 8.0, cdf, grid), [np.inf]))
    return grid, cdf, mean, edges


def gb_run(kind, top_or_zmax, drift=True, n=100, L=40.0, steps=250, dt=0.01, seed=3):
    """Per-body time averages of z and of the 8 bins, the in-plane displacements over windows of 10 steps, and
    the model (single-blob rollers started from an exact equilibrium sample)."""
    from multi_bodies.files.input_options import options_with
    from quaternion_integrator.schemes import make_scheme
    top = top_or_zmax if kind == 'doubly_periodic_slit' else None
    grid, cdf, _, edges = gb_quadrature(top)
    rng = np.random.default_rng(100 + seed)
    side = int(np.ceil(np.sqrt(n)))
    locations = [[(k // side + 0.5) * L / side, (k % side + 0.5) * L / side, np.interp(rng.random(), cdf, grid)]
                 for k in range(n)]
    from body.body import bodies_to_arrays
    from multi_bodies import multi_bodies_functions as mbf
    from multi_bodies.solver.model import Model
    from multi_bodies.solver.periodic import SpectralDomain
    bodies = roller_bodies(locations)
    physics = dict(g=GB_G, repulsion_strength_wall=GB_EPS, debye_length_wall=GB_B, repulsion_strength=1.0,
                   debye_length=1.0, periodic_length=np.array([L, L, 0.0]), blob_radius=1.0, blob_mass=1.0,
                   top_wall=top)
    domain = SpectralDomain(Geometry(kind, (L, L, 0.0), (0.0, top_or_zmax)), 'w5w4')
    with warnings.catch_warnings():
        warnings.simplefilter('ignore')
        model = Model(bodies, bodies_to_arrays(bodies, [n]), mbf.load_user_hooks('/nonexistent'), physics, GB_ETA,
                      1.0, 1e-3, vector_product_name='spectral', blobs_name='python', periodic_length=(L, L, 0.0),
                      spectral=domain)
    scheme = make_scheme('stochastic_trapezoidal_rollers', dt, options_with(kT=1.0, rf_delta=1e-3, update_PC=1))
    scheme.thermal_drift = drift
    state = scheme.init(model, model.start_configuration)
    generator = np.random.default_rng(seed)
    z_sum, bins, windows = np.zeros(n), np.zeros((n, 8)), []
    window_start = state.configuration.locations[:, :2].copy()
    for step in range(steps):
        state = scheme.step(model, state, generator)
        z = state.configuration.locations[:, 2]
        z_sum += z
        bins[np.arange(n), np.clip(np.searchsorted(edges, z) - 1, 0, 7)] += 1
        if (step + 1) % 10 == 0:
            windows.append(state.configuration.locations[:, :2] - window_start)
            window_start = state.configuration.locations[:, :2].copy()
    return z_sum / steps, bins / steps, np.array(windows), model


def z_scores(per_body, exact):
    per_body = np.asarray(per_body)
    return (per_body.mean(axis=0) - exact) / (per_body.std(axis=0, ddof=1) / np.sqrt(per_body.shape[0]))


def assert_gibbs_boltzmann(z_means, bins, exact_mean, label):
    """Mean height within 4 standard errors and the 8-bin chi^2 below 24 (chi^2 with 7 degrees of freedom,
    p = 0.001); standard errors from the spread of the bodies' time averages."""
    score = z_scores(z_means, exact_mean)
    chi2 = float(np.sum(z_scores(bins, 1.0 / 8.0) ** 2))
    assert abs(score) < 4.0, '%s: <z> %.4f, exact %.4f, z-score %.2f' % (label, z_means.mean(), exact_mean, score)
    assert chi2 < 24.0, '%s: histogram chi^2 %.1f' % (label, chi2)


def mean_parallel_self_mobility(model, top):
    """<M_xx> of one blob alone in the model's box, averaged over the exact height density (quadrature over 101
    heights of the spectral product itself: the rate of in-plane diffusion at equilibrium, kT <M_xx>)."""
    grid, cdf, _, _ = gb_quadrature(top)
    heights = np.interp((np.arange(101) + 0.5) / 101, cdf, grid)
    mobility = model.roller_mobility
    M_xx = np.array([mobility.velocities(np.array([[1.0, 1.0, h]]), np.array([1.0, 0, 0]))[0] for h in heights])
    return M_xx.mean()  # the heights are equiprobable quantiles: the mean is the average over the density


@pytest.mark.slow
@pytest.mark.parametrize('kind, height', [('doubly_periodic_slit', 5.0), ('doubly_periodic_wall', 8.0)])
def test_brownian_rollers_keep_the_gibbs_boltzmann_heights(kind, height):
    """Heights of Brownian blobs in the doubly periodic box above the wall and in the slit (both walls felt: the
    density has the top wall's repulsion, quadrature) keep the exact equilibrium, and the blobs diffuse in the
    plane at the equilibrium rate kT <M_xx> (4 standard errors; a frozen integrator would keep the heights of
    its exact start)."""
    top = height if kind == 'doubly_periodic_slit' else None
    z_means, bins, windows, model = gb_run(kind, height)
    assert_gibbs_boltzmann(z_means, bins, gb_quadrature(top)[2], kind)
    per_body = np.mean(np.sum(windows ** 2, axis=2), axis=0) / (4.0 * 10 * 0.01)
    expected = mean_parallel_self_mobility(model, top)
    score = (per_body.mean() - expected) / (per_body.std(ddof=1) / np.sqrt(per_body.size))
    assert abs(score) < 4.0, (per_body.mean(), expected, score)


@pytest.mark.slow
def test_dropping_the_drift_leaves_the_equilibrium_of_the_slit():
    """Negative control: the slit run without the random-finite-difference drift fails the same check."""
    z_means, bins, _, _ = gb_run('doubly_periodic_slit', 5.0, drift=False)
    with pytest.raises(AssertionError):
        assert_gibbs_boltzmann(z_means, bins, gb_quadrature(5.0)[2], 'slit without drift')


def test_published_roller_scene_shortened_runs(tmp_path, monkeypatch):
    """multi_bodies/examples/spectral_rollers (the published Spectral_Multiblob_Roller scene built the same way:
    32 rollers of 12 blobs at the published density, the folder's forces, stochastic_Slip_Trapz, the published
    domain height): 4 steps run, every solve and Lanczos converged, and the rollers roll along +x (a torque about
    +y above a wall)."""
    import shutil
    example = os.path.join(REPO_ROOT, 'multi_bodies', 'examples', 'spectral_rollers')
    for name in ('inputfile_spectral_rollers.dat', 'rollers.clones', 'shell_N_12_Rh_1_0155.vertex',
                 'user_defined_functions.py'):
        shutil.copy(os.path.join(example, name), tmp_path / name)
    (tmp_path / 'input.dat').write_text((tmp_path / 'inputfile_spectral_rollers.dat').read_text())
    assert run_script(tmp_path, monkeypatch) == 0
    info = (tmp_path / 'data' / 'run.info').read_text()
    assert 'lanczos_not_converged_count    = 0' in info and 'invalid_configuration_count    = 0' in info
    lines = (tmp_path / 'data' / 'run.rollers.config').read_text().splitlines()
    frames = []
    while lines:
        count = int(lines[0])
        frames.append(np.array([line.split() for line in lines[1:count + 1]], dtype=float))
        lines = lines[count + 1:]
    assert len(frames) == 3 and np.mean(frames[-1][:, 0] - frames[0][:, 0]) > 0.0


# ====================================================================== every scheme, the static script
def write_bodies(folder, options, rollers=False):
    """Two tetrahedra (or three rollers) in a 16 x 16 box above the wall, an input with ``options``."""
    from multi_bodies.files.snapshots import write_clones_file
    from multi_bodies.files.structure_files import write_vertex_file
    if rollers:
        write_vertex_file(folder / 'body.vertex', np.zeros((1, 3)))
        locations = np.array([[4.0, 4.0, 1.6], [9.0, 5.0, 2.1], [6.0, 11.0, 1.8]])
    else:
        write_vertex_file(folder / 'body.vertex', 1.15 * np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1],
                                                                   [-1, -1, 1.0]]))
        locations = np.array([[4.0, 4.0, 2.6], [10.0, 9.0, 3.1]])
    write_clones_file(folder / 'bodies.clones', locations, np.tile([1.0, 0, 0, 0], (len(locations), 1)))
    base = {'dt': 0.01, 'n_steps': 2, 'n_save': 1, 'eta': 1.0, 'g': 1.0, 'blob_radius': 1.0, 'kT': 0.05,
            'repulsion_strength_wall': 1.0, 'debye_length_wall': 0.25, 'mobility_vector_prod_implementation':
            'spectral', 'mobility_blobs_implementation': 'C++', 'periodic_length': '16 16 0',
            'spectral_z_bounds': '0 8', 'spectral_kernel': 'w5w4' if rollers else 'w4', 'solver_tolerance': 1e-6,
            'output_name': 'run', 'seed': 2, 'omega_one_roller': '0 1 0' if rollers else None}
    base.update(options)
    text = ''.join('%s %s\n' % item for item in base.items() if item[1] is not None)
    (folder / 'input.dat').write_text(text + 'structure body.vertex bodies.clones\n')


def every_scheme():
    from multi_bodies.files.input_options import DYNAMIC_SCHEMES
    return [name for name in DYNAMIC_SCHEMES if not name.startswith('lubrication')]


@pytest.mark.parametrize('scheme', every_scheme())
def test_every_scheme_runs_on_the_spectral_product(scheme, tmp_path, monkeypatch):
    """Every dynamic scheme (rigid, dense, roller, articulated; the lubrication schemes are refused) runs two steps
    over a wall on the spectral product, the deterministic and stochastic ones, keeping every blob above the wall."""
    rollers = 'rollers' in scheme
    kT = None if scheme.startswith('deterministic') or scheme.startswith('articulated') else 0.05
    write_bodies(tmp_path, {'scheme': scheme, 'kT': kT, 'free_kinematics': None if not rollers else 'True'},
                 rollers=rollers)
    with warnings.catch_warnings():
        warnings.simplefilter('ignore')
        assert run_script(tmp_path, monkeypatch) == 0
    final = np.loadtxt(tmp_path / 'run.bodies.00000002.clones', skiprows=1, ndmin=2)
    assert np.all(np.isfinite(final)) and np.all(final[:, 2] > 1.0)


def test_the_lubrication_schemes_are_refused(tmp_path, monkeypatch):
    write_bodies(tmp_path, {'scheme': 'lubrication_EM'}, rollers=True)
    with pytest.raises(UserInputError, match='lubrication schemes take their far field'):
        run_script(tmp_path, monkeypatch)


@pytest.mark.parametrize('kind', ['triply_periodic', 'doubly_periodic_slit'])
def test_the_static_script_on_the_spectral_product(kind, tmp_path, monkeypatch):
    """multi_bodies_utilities.py: the mobility problem (GMRES) and the body mobility (dense, from the products)
    give the same velocities for the same forces; the resistance problem of those velocities gives back the forces;
    the velocity field is refused in one line (no source-target product)."""
    options = {'scheme': 'mobility', 'kT': None, 'dt': None, 'n_steps': None, 'n_save': None, 'seed': None,
               'solver_tolerance': 1e-10}
    if kind == 'triply_periodic':
        options.update(periodic_length='16 16 16', spectral_z_bounds=None)
    else:
        options.update(spectral_geometry='doubly_periodic_slit')
    write_bodies(tmp_path, options)
    forces = np.array([[0.1, 0.0, -1.0, 0.0, 0.2, 0.0], [0.0, -0.3, -1.0, 0.1, 0.0, 0.0]])
    np.savetxt(tmp_path / 'force.dat', forces)
    (tmp_path / 'input.dat').write_text((tmp_path / 'input.dat').read_text() + 'force_file force.dat\n')
    assert run_script(tmp_path, monkeypatch, 'multi_bodies_utilities') == 0
    velocities = np.loadtxt(tmp_path / 'run.velocities.dat')
    text = (tmp_path / 'input.dat').read_text().replace('scheme mobility', 'scheme body_mobility')
    (tmp_path / 'input.dat').write_text(text)
    assert run_script(tmp_path, monkeypatch, 'multi_bodies_utilities') == 0
    N = np.loadtxt(tmp_path / 'run.body_mobility.dat')
    accuracy = 1e-8 if kind == 'triply_periodic' else 5e-4
    assert np.abs(N @ forces.ravel() - velocities.ravel()).max() < accuracy * np.abs(velocities).max()
    np.savetxt(tmp_path / 'velocity.dat', velocities)
    (tmp_path / 'input.dat').write_text(text.replace('scheme body_mobility', 'scheme resistance').replace(
        'force_file force.dat', 'velocity_file velocity.dat'))
    assert run_script(tmp_path, monkeypatch, 'multi_bodies_utilities') == 0
    back = np.loadtxt(tmp_path / 'run.force.dat')
    assert np.abs(back - forces).max() < (1e-7 if kind == 'triply_periodic' else 2e-3) * np.abs(forces).max()
    (tmp_path / 'input.dat').write_text(text.replace('scheme body_mobility', 'scheme mobility')
                                        + 'plot_velocity_field 0 16 4 0 16 4 2 2 1\n')
    with pytest.raises(UserInputError) as refused:
        run_script(tmp_path, monkeypatch, 'multi_bodies_utilities')
    assert 'source-target' in str(refused.value) and '\n' not in str(refused.value)


def test_fluctuating_noise_in_a_run(tmp_path, monkeypatch):
    """spectral_noise fluctuating in a triply periodic run: the Brownian slip without Lanczos iterations, the same
    run twice with one seed gives the same trajectory."""
    options = {'scheme': 'stochastic_Slip_Trapz', 'periodic_length': '16 16 16', 'spectral_z_bounds': None,
               'spectral_noise': 'fluctuating', 'g': 0.0, 'n_steps': 3}
    runs = []
    for k in range(2):
        folder = tmp_path / str(k)
        folder.mkdir()
        write_bodies(folder, options)
        assert run_script(folder, monkeypatch) == 0
        runs.append((folder / 'run.bodies.00000003.clones').read_text())
        info = (folder / 'run.info').read_text()
        assert 'stochastic_iterations_count    = 0' in info
    assert runs[0] == runs[1]


def test_obstacles_and_prescribed_kinematics_on_the_spectral_product(tmp_path, monkeypatch):
    """An obstacle (held) and a free body above the wall on the spectral product: the obstacle never moves, the free
    body falls; the mixed problem's GMRES and the dense mixed solve of the static script agree."""
    from multi_bodies.files.snapshots import write_clones_file
    write_bodies(tmp_path, {'scheme': 'deterministic_forward_euler', 'kT': None})
    write_clones_file(tmp_path / 'fixed.clones', np.array([[7.0, 6.0, 2.5]]), np.array([[1.0, 0, 0, 0]]))
    (tmp_path / 'input.dat').write_text((tmp_path / 'input.dat').read_text() + 'obstacle body.vertex fixed.clones\n')
    assert run_script(tmp_path, monkeypatch) == 0
    start = np.loadtxt(tmp_path / 'run.fixed.00000000.clones', skiprows=1)
    end = np.loadtxt(tmp_path / 'run.fixed.00000002.clones', skiprows=1)
    assert np.array_equal(start, end)
    free_start = np.loadtxt(tmp_path / 'run.bodies.00000000.clones', skiprows=1)
    free_end = np.loadtxt(tmp_path / 'run.bodies.00000002.clones', skiprows=1)
    assert np.all(free_end[:, 2] < free_start[:, 2])
    from multi_bodies.files.input_options import parse_input_text
    from multi_bodies.run.run_setup import prepare
    text = (tmp_path / 'input.dat').read_text().replace('solver_tolerance 1e-06', 'solver_tolerance 1e-12')
    model = prepare(parse_input_text(text, 'input.dat', 'dynamic'), 'dynamics', log=lambda line: None).system
    configuration = model.start_configuration
    iterative = model.deterministic_velocities(configuration).velocities
    dense = model.dense_velocities(configuration)
    assert np.all(iterative[2] == 0) and np.all(dense[2] == 0)
    assert np.abs(iterative - dense).max() < model.vector_mobility.relative_accuracy * np.abs(dense).max()


@pytest.mark.parametrize('options, fragment', [
    ({'spectral_geometry': 'doubly_periodic_open', 'spectral_z_bounds': '1.8 8'},
     'outside the heights [1.8, 8] of the spectral grid'),
    ({'spectral_geometry': 'doubly_periodic_slit', 'spectral_z_bounds': '0 2'},
     'through a wall (below z = 0 or above the top wall at z = 2)'),
])
def test_a_start_outside_the_domain_is_refused_in_one_line(tmp_path, monkeypatch, options, fragment):
    write_rollers(tmp_path, TWO_ROLLERS, options)
    with pytest.raises(UserInputError) as refused:
        run_script(tmp_path, monkeypatch)
    message = str(refused.value)
    assert fragment in message and message.startswith('input.dat, line') and '\n' not in message, message


def test_blobs_overlapping_within_a_body_are_warned_about(tmp_path, monkeypatch, capsys):
    """Blobs of one body closer than blob_radius (the published Spectral_Multiblob_Roller input read as the manual
    says) make the spectral mobility nearly singular: a warning naming the blob_radius line and the folder's
    convention; half the distance (the published scene) gives none."""
    from multi_bodies.files.input_options import parse_input_text
    from multi_bodies.run.run_setup import prepare
    write_bodies(tmp_path, {'scheme': 'deterministic_forward_euler', 'kT': None, 'blob_radius': 3.5,
                            'spectral_kernel': 'w6', 'periodic_length': '64 64 0', 'spectral_z_bounds': '0 12'})
    (tmp_path / 'bodies.clones').write_text('1\n20 20 5 1 0 0 0\n')
    monkeypatch.chdir(tmp_path)
    options = parse_input_text((tmp_path / 'input.dat').read_text(), 'input.dat', 'dynamic')
    prepare(options, 'dynamics', log=lambda line: None)
    warning = capsys.readouterr().err
    assert 'input.dat, line 6: blob_radius 3.5 is larger than the smallest blob distance 3.25269' in warning
    options = parse_input_text((tmp_path / 'input.dat').read_text().replace('blob_radius 3.5', 'blob_radius 1.6'),
                               'input.dat', 'dynamic')
    prepare(options, 'dynamics', log=lambda line: None)
    assert 'smallest blob distance' not in capsys.readouterr().err


def test_fluctuating_noise_of_rollers(tmp_path, monkeypatch):
    """Rollers in a triply periodic box with spectral_noise fluctuating take the exact noise too (no Lanczos)."""
    write_bodies(tmp_path, {'scheme': 'stochastic_adams_bashforth_rollers', 'periodic_length': '16 16 16',
                            'spectral_z_bounds': None, 'spectral_noise': 'fluctuating', 'g': 0.0,
                            'free_kinematics': 'True'}, rollers=True)
    assert run_script(tmp_path, monkeypatch) == 0
    assert 'stochastic_iterations_count    = 0' in (tmp_path / 'run.info').read_text()
