"""Static problems: body mobility, mobility and resistance schemes, velocity field.

Numbers come from the published code (../shared/reference), from the exact
sphere-wall mobilities of VALIDATION.md section 2.1 and from physical laws.
"""
import importlib.util
import json
import os
import shutil

import numpy as np
import pytest

import mobility
from body.body import Body, bodies_to_arrays
from multi_bodies.solver import body_solver
from multi_bodies.files import structure_generators as gen
from multi_bodies.files.structure_files import read_vertex_file

REPO_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
REFERENCE = os.path.abspath(os.environ.get('RMB_REFERENCE_DIR', os.path.join(REPO_ROOT, '..', 'shared', 'reference')))
HAVE_REFERENCE = os.path.isdir(REFERENCE)
needs_reference = pytest.mark.skipif(not HAVE_REFERENCE, reason='reference data ../shared/reference not present')


def implementation_usable(name):
    """True when the mobility registry can give a product for ``name`` (aliases included)."""
    try:
        mobility.mobility_vector_product(name)
    except Exception:
        return False
    return True


def load_script():
    spec = importlib.util.spec_from_file_location(
        'multi_bodies_utilities_under_test', os.path.join(REPO_ROOT, 'multi_bodies', 'multi_bodies_utilities.py'))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


SCRIPT = load_script()


def rewrite_reference_input(source, run_dir, replacements=()):
    """Copy a reference run.inputfile into run_dir with absolute reference paths."""
    with open(source) as f:
        text = f.read()
    for folder in ('structures/', 'mob_res/', 'body_mobility_runs/', 'dynamics/'):
        text = text.replace(' ' + folder, ' ' + os.path.join(REFERENCE, folder))
    for old, new in replacements:
        text = text.replace(old, new)
    path = os.path.join(run_dir, 'in.dat')
    with open(path, 'w') as f:
        f.write(text)
    return path


def run_script(run_dir, input_path, monkeypatch):
    monkeypatch.chdir(run_dir)
    return SCRIPT.main(['--input-file', input_path])


def relative_error(ours, reference):
    return np.max(np.abs(np.asarray(ours) - reference)) / np.max(np.abs(reference))


# ------------------------------------------------------------------ body mobility vs published
BODY_TABLE = os.path.join(REFERENCE, 'body_mobility_table.json')
BODY_CASES = sorted(json.load(open(BODY_TABLE))['entries']) if HAVE_REFERENCE else []
OTHER_IMPLEMENTATION = {'python': 'C++', 'C++': 'python', 'python_no_wall': 'C++_no_wall',
                        'C++_no_wall': 'python_no_wall'}


@needs_reference
@pytest.mark.parametrize('case', BODY_CASES)
@pytest.mark.parametrize('swap', [False, True], ids=['published_impl', 'other_impl'])
def test_body_mobility_matches_published(case, swap, tmp_path, monkeypatch):
    entry = json.load(open(BODY_TABLE))['entries'][case]
    implementation = entry['mobility_blobs_implementation']
    if swap:
        implementation = OTHER_IMPLEMENTATION[implementation]
    if not implementation_usable(implementation):
        pytest.skip('mobility implementation %s not usable here' % implementation)
    run_folder = os.path.join(REFERENCE, 'body_mobility_runs', case)
    input_path = rewrite_reference_input(
        os.path.join(run_folder, 'run.inputfile'), str(tmp_path),
        [('mobility_blobs_implementation            ' + entry['mobility_blobs_implementation'],
          'mobility_blobs_implementation            ' + implementation),
         ('mobility_blobs_implementation ' + entry['mobility_blobs_implementation'],
          'mobility_blobs_implementation ' + implementation)])
    assert implementation in open(input_path).read()
    assert run_script(str(tmp_path), input_path, monkeypatch) == 0
    ours = np.loadtxt(tmp_path / 'run.body_mobility.dat')
    assert relative_error(ours, np.array(entry['body_mobility_6x6'])) < 1e-10
    assert relative_error(ours, np.loadtxt(os.path.join(run_folder, 'run.body_mobility.dat'))) < 1e-10
    slip_reference = os.path.join(run_folder, 'run.body_slip_mobility.dat')
    if os.path.exists(slip_reference):
        assert relative_error(np.loadtxt(tmp_path / 'run.body_slip_mobility.dat'), np.loadtxt(slip_reference)) < 1e-10
    assert open(tmp_path / 'run.bodies_info').read() == open(os.path.join(run_folder, 'run.bodies_info')).read()


# ------------------------------------------------------------------ mobility / resistance vs published
MOB_RES = os.path.join(REFERENCE, 'mob_res')
FORCE_FILE = ('multi_bodies/force.dat', os.path.join(REFERENCE, 'structures', 'force.dat'))
ROUNDTRIP_VELOCITY = ('velocity_file run.velocity.dat',
                      'velocity_file ' + os.path.join(MOB_RES, 'A_mobility_python', 'run.velocity.dat'))
MOB_RES_CASES = ['A_mobility_python', 'A_mobility_C++', 'A_mobility_numba', 'A_mobility_python_blobsC++',
                 'A_mobility_python_gravity', 'A_resistance_python', 'A_resistance_C++',
                 'A_resistance_roundtrip_python', 'A_mobility_pycuda']
# Cases run with another implementation than the published run, compared with that run's outputs.
DERIVED_CASES = {'A_mobility_pycuda': ('A_mobility_python', [
    ('mobility_vector_prod_implementation python', 'mobility_vector_prod_implementation pycuda')])}


@needs_reference
@pytest.mark.parametrize('case', [pytest.param(c, marks=pytest.mark.gpu) if 'pycuda' in c else c
                                  for c in MOB_RES_CASES])
def test_mobility_and_resistance_match_published(case, tmp_path, monkeypatch):
    published_case, extra = DERIVED_CASES.get(case, (case, []))
    folder = os.path.join(MOB_RES, published_case)
    input_path = rewrite_reference_input(os.path.join(folder, 'run.inputfile'), str(tmp_path),
                                         [FORCE_FILE, ROUNDTRIP_VELOCITY] + extra)
    text = open(input_path).read()
    for line in text.splitlines():
        if line.startswith('mobility_') and not implementation_usable(line.split()[1]):
            pytest.skip('implementation %s not usable here' % line.split()[1])
    assert run_script(str(tmp_path), input_path, monkeypatch) == 0
    if 'mobility' in case:
        assert relative_error(np.loadtxt(tmp_path / 'run.velocities.dat'),
                              np.loadtxt(os.path.join(folder, 'run.velocity.dat'))) < 1e-7
    assert relative_error(np.loadtxt(tmp_path / 'run.force.dat'), np.loadtxt(os.path.join(folder, 'run.force.dat'))) < 1e-7
    assert open(tmp_path / 'run.bodies_info').read() == open(os.path.join(folder, 'run.bodies_info')).read()
    if case == 'A_resistance_roundtrip_python':
        # Resistance of the mobility velocities gives back the forces of the mobility problem.
        forces = np.loadtxt(os.path.join(REFERENCE, 'structures', 'force.dat'))
        assert relative_error(np.loadtxt(tmp_path / 'run.force.dat'), forces) < 1e-7


@needs_reference
def test_velocity_field_matches_published(tmp_path, monkeypatch):
    pyvista = pytest.importorskip('pyvista')
    folder = os.path.join(MOB_RES, 'A_mobility_python')
    input_path = rewrite_reference_input(os.path.join(folder, 'run.inputfile'), str(tmp_path), [FORCE_FILE])
    assert run_script(str(tmp_path), input_path, monkeypatch) == 0
    mesh = pyvista.read(str(tmp_path / 'run.velocity_field.vtk'))
    published = np.load(os.path.join(folder, 'velocity_field_parsed.npz'))
    np.testing.assert_allclose(mesh.x, published['x_nodes'])
    np.testing.assert_allclose(mesh.y, published['y_nodes'])
    np.testing.assert_allclose(mesh.z, published['z_nodes'])
    velocity = np.asarray(mesh.cell_data['velocity'])
    assert relative_error(velocity, published['velocity_zyx'].reshape(-1, 3)) < 1e-8


# ------------------------------------------------------------------ laws
def boomerang_bodies(count, spacing=3.0, height=2.0, seed=0):
    """``count`` boomerangs on a square lattice with random orientations."""
    rng = np.random.default_rng(seed)
    side = int(np.ceil(np.sqrt(count)))
    bodies = []
    for k in range(count):
        q = rng.normal(size=4)
        body = Body([spacing * (k % side), spacing * (k // side), height + 0.3 * rng.random()],
                    q / np.linalg.norm(q), gen.boomerang(7, 0.3), 0.25)
        body.ID = 'boomerang'
        bodies.append(body)
    return bodies


def test_body_mobility_is_symmetric_positive_definite():
    arrays = bodies_to_arrays(boomerang_bodies(3))
    N, _ = body_solver.dense_body_mobility(arrays, arrays.configuration, mobility.single_wall_fluid_mobility, 1.0,
                                           0.25)
    assert np.max(np.abs(N - N.T)) < 1e-12 * np.max(np.abs(N))
    assert np.min(np.linalg.eigvalsh(0.5 * (N + N.T))) > 0


@pytest.mark.parametrize('implementation', ['python', 'C++'])
def test_gmres_matches_dense_and_resistance_round_trip(implementation):
    if not implementation_usable(implementation):
        pytest.skip('%s not usable' % implementation)
    arrays = bodies_to_arrays(boomerang_bodies(4))
    configuration = arrays.configuration
    rng = np.random.default_rng(3)
    forces = rng.normal(size=(4, 6))
    slip = 0.1 * rng.normal(size=(arrays.num_blobs, 3))
    matrix = mobility.blob_mobility_matrix(implementation)
    problem = body_solver.MobilityProblem(arrays, configuration, mobility.mobility_vector_product(implementation),
                                          1.0, 0.25)
    preconditioner = body_solver.BlockDiagonalPreconditioner(arrays, configuration, matrix, 1.0, 0.25)
    result = body_solver.solve(problem, body_solver.mobility_rhs(forces, slip), preconditioner, tolerance=1e-10)
    assert result.converged and 0 < result.iterations < 30
    dense = body_solver.dense_mobility_velocities(arrays, configuration, forces, slip, matrix, 1.0, 0.25)
    assert relative_error(result.velocities, dense) < 1e-8
    back, _ = body_solver.solve_resistance_problem(arrays, configuration, result.velocities, slip, matrix, 1.0,
                                                   0.25)
    assert relative_error(back, forces) < 1e-8


def test_preconditioner_is_exact_for_one_body():
    arrays = bodies_to_arrays(boomerang_bodies(1))
    matrix = mobility.single_wall_fluid_mobility
    operator = body_solver.MobilityProblem(arrays, arrays.configuration, mobility.mobility_vector_product('python'),
                                           1.0, 0.25).operator
    preconditioner = body_solver.BlockDiagonalPreconditioner(arrays, arrays.configuration, matrix, 1.0, 0.25)
    x = np.random.default_rng(0).normal(size=operator.shape[0])
    np.testing.assert_allclose(operator.matvec(preconditioner.apply(x)), x, rtol=0, atol=1e-10 * np.abs(x).max())


def test_gmres_iterations_do_not_grow_with_bodies():
    counts = []
    for count in (1, 16):
        arrays = bodies_to_arrays(boomerang_bodies(count))
        problem = body_solver.MobilityProblem(arrays, arrays.configuration,
                                              mobility.mobility_vector_product('python'), 1.0, 0.25)
        pc = body_solver.BlockDiagonalPreconditioner(arrays, arrays.configuration, mobility.single_wall_fluid_mobility,
                                                     1.0, 0.25)
        forces = np.tile([0, 0, -1.0, 0, 0, 0], (count, 1))
        result = body_solver.solve(problem, body_solver.mobility_rhs(forces, np.zeros((arrays.num_blobs, 3))), pc,
                                   tolerance=1e-8)
        assert result.converged
        counts.append(result.iterations)
    assert counts[1] <= 4 * max(counts[0], 3)


def test_unconverged_solve_is_reported():
    arrays = bodies_to_arrays(boomerang_bodies(9, spacing=2.2))
    problem = body_solver.MobilityProblem(arrays, arrays.configuration, mobility.mobility_vector_product('python'),
                                          1.0, 0.25)
    forces = np.random.default_rng(1).normal(size=(9, 6))
    result = body_solver.solve(problem, body_solver.mobility_rhs(forces, np.zeros((arrays.num_blobs, 3))), None,
                               tolerance=1e-14, restart=2, maxiter=1)
    assert not result.converged and result.iterations > 0 and result.residual > 1e-14


# ------------------------------------------------------------------ spheres of blobs vs exact sphere-wall values
# VALIDATION.md section 2.1: exact (par, perp, rot_par, coupling) at h/R = 1.5 and 2, and the
# multiblob errors of section 2.2 (percent) for par, perp, rot_par.
EXACT = {1.5: (0.62681, 0.31197, 0.90069), 2.0: (0.72321, 0.47047, 0.95991)}
EXPECTED_ERROR_PERCENT = {
    ('shell_N_12_Rg_0_7921_Rh_1', 0.41642068286674966): {1.5: (-0.3, 3.9, 8.7), 2.0: (-0.1, 0.6, 8.1)},
    ('shell_N_42_Rg_0_8913_Rh_1', 0.243553056072): {1.5: (-0.2, -0.3, 6.2), 2.0: (-0.1, -0.2, 5.8)},
    ('shell_N_162_Rg_0_9497_Rh_1', 0.13100877695): {1.5: (-0.1, -0.1, 1.9), 2.0: (0.0, 0.0, 1.7)},
}
BULK_ROTATION = {12: 1.0778, 42: 1.0557, 162: 1.0167}


def sphere_mobility(vertex_name, blob_radius, height, matrix=mobility.single_wall_fluid_mobility):
    blobs = read_vertex_file(os.path.join(REFERENCE, 'structures', vertex_name + '.vertex'))
    body = Body([0, 0, height], [1, 0, 0, 0], blobs, blob_radius)
    arrays = bodies_to_arrays([body])
    N, _ = body_solver.dense_body_mobility(arrays, arrays.configuration, matrix, 1.0, blob_radius)
    return N


@needs_reference
def test_shells_approach_exact_sphere_wall_mobility():
    rot_errors = {1.5: [], 2.0: []}
    for (name, a), table in EXPECTED_ERROR_PERCENT.items():
        for height, expected in table.items():
            N = sphere_mobility(name, a, height)
            ours = (N[0, 0] * 6 * np.pi, N[2, 2] * 6 * np.pi, N[3, 3] * 8 * np.pi)
            errors = [100 * (o / e - 1) for o, e in zip(ours, EXACT[height])]
            # The table rounds to 0.1 %; the exact values carry 5 digits.
            np.testing.assert_allclose(errors, expected, atol=0.08, err_msg='%s h=%s' % (name, height))
            rot_errors[height].append(abs(errors[2]))
            assert N[4, 0] * 6 * np.pi > 0          # rolling sense: omega_y follows F_x
    for height in rot_errors:
        assert rot_errors[height] == sorted(rot_errors[height], reverse=True)


@needs_reference
def test_shells_bulk_mobility():
    for (name, a) in EXPECTED_ERROR_PERCENT:
        count = int(name.split('_')[2])
        N = sphere_mobility(name, a, 10.0, matrix=mobility.rotne_prager_tensor)
        assert N[0, 0] * 6 * np.pi == pytest.approx(1.0, abs=5e-5)
        assert N[3, 3] * 8 * np.pi == pytest.approx(BULK_ROTATION[count], abs=6e-5)


def test_generated_shell_is_calibrated():
    """VALIDATION.md 2.2: 12 blobs, a = 0.41642, Rg = 0.7921; 42 blobs, a = 0.24355, Rg = 0.8913."""
    for count, a_expected, rg_expected in ((12, 0.41642, 0.7921), (42, 0.24355, 0.8913)):
        blobs, a, rg = gen.calibrated_shell(count)
        assert gen.bulk_translational_mobility(blobs, a) * 6 * np.pi == pytest.approx(1.0, rel=1e-12)
        assert a == pytest.approx(a_expected, abs=5e-5)
        assert rg == pytest.approx(rg_expected, abs=1e-4)


# ------------------------------------------------------------------ the shipped examples run
def test_shipped_examples_run(tmp_path, monkeypatch):
    source = os.path.join(REPO_ROOT, 'multi_bodies')
    run_dir = tmp_path / 'multi_bodies'
    shutil.copytree(os.path.join(source, 'Structures'), run_dir / 'Structures')
    for name in ('inputfile_body_mobility.dat', 'inputfile.dat'):
        shutil.copy(os.path.join(source, name), run_dir / name)
    assert run_script(str(run_dir), 'inputfile_body_mobility.dat', monkeypatch) == 0
    N = np.loadtxt(run_dir / 'data' / 'run.body_mobility.body_mobility.dat')
    assert N.shape == (6, 6) and np.allclose(N, N.T, atol=1e-12 * np.abs(N).max())
    pytest.importorskip('pyvista')
    assert run_script(str(run_dir), 'inputfile.dat', monkeypatch) == 0
    assert np.loadtxt(run_dir / 'data' / 'run.velocities.dat').shape == (3, 6)
    assert (run_dir / 'data' / 'run.velocity_field.vtk').exists()
    assert (run_dir / 'data' / 'run.inputfile').read_text() == (run_dir / 'inputfile.dat').read_text()


# ------------------------------------------------------------------ default physics (SPEC section 7)
def test_default_forces_follow_the_formulas():
    from multi_bodies import multi_bodies_functions as mbf
    r = np.array([[0.0, 0.0, 0.1], [0.3, 0.0, 2.0], [0.3, 0.2, 2.0]])
    f = mbf.blob_external_forces(r, g=2.0, repulsion_strength_wall=3.0, debye_length_wall=0.5, blob_radius=0.25)
    np.testing.assert_allclose(f[:, 2], [-2 + 6.0, -2 + 6.0 * np.exp(-(2 - 0.25) / 0.5),
                                         -2 + 6.0 * np.exp(-(2 - 0.25) / 0.5)])
    pair = mbf.calc_blob_blob_forces(r, repulsion_strength=1.5, debye_length=0.7, blob_radius=0.25)
    np.testing.assert_allclose(pair.sum(axis=0), 0, atol=1e-14)           # action = reaction
    # Blobs 1 and 2 overlap (0.2 < 2a): force magnitude eps/b, pushing 2 away from 1 along +y.
    d02 = r[2] - r[0]
    expected_on_2 = 1.5 / 0.7 * np.array([0, 1.0, 0]) + 1.5 / 0.7 * np.exp(
        -(np.linalg.norm(d02) - 0.5) / 0.7) * d02 / np.linalg.norm(d02)
    np.testing.assert_allclose(pair[2], expected_on_2, rtol=1e-13)
    # Minimum image: blobs 0.2 apart through the periodic boundary of a box of 10.
    periodic = mbf.calc_blob_blob_forces(np.array([[0.1, 0, 5], [9.9, 0, 5]]), periodic_length=(10, 0, 0),
                                         repulsion_strength=1.0, debye_length=1.0, blob_radius=0.25)
    assert periodic[0, 0] > 0 and periodic[1, 0] < 0
    bb = mbf.calc_body_body_forces_torques(np.array([[0, 0, 0], [2.0, 0, 0]]), repulsion_strength=1.0,
                                           debye_length=1.0).reshape(-1, 6)
    magnitude = (1.0 + 0.5) * np.exp(-2.0) / 2.0
    np.testing.assert_allclose(bb, [[-magnitude, 0, 0, 0, 0, 0], [magnitude, 0, 0, 0, 0, 0]], rtol=1e-14)


def test_hooks_can_be_replaced():
    from multi_bodies import multi_bodies_functions as mbf
    arrays = bodies_to_arrays(boomerang_bodies(2))
    r = arrays.blob_positions(arrays.configuration)
    original = mbf.blob_external_forces
    try:
        mbf.blob_external_forces = lambda r_vectors, **kw: np.tile([1.0, 0, 0], (len(r_vectors), 1))
        ft = mbf.force_torque_calculator_sort_by_bodies([None, None], arrays, r)
    finally:
        mbf.blob_external_forces = original
    np.testing.assert_allclose(ft.reshape(-1, 6)[:, 0], [15.0, 15.0])


def test_static_mobility_with_torques_on_single_blobs_converges(tmp_path, monkeypatch, capsys):
    """A torque on single-blob bodies cannot be carried by their one blob: the static script projects it out
    (as the dynamics does) and GMRES converges to solver_tolerance; the velocities equal the dense
    ``pinv(K^T M^-1 K) F``, whose null-space part (the rotation of one blob) is zero.

    Before the one-solve rewrite, the static path skipped the projection and stopped with
    converged = False and a relative residual of about 0.45.
    """
    gen_dir = tmp_path / 'Structures'
    gen_dir.mkdir()
    (gen_dir / 'blob.vertex').write_text('1\n0.0 0.0 0.0\n')
    locations = np.array([[0.0, 0.0, 1.2], [2.0, 0.5, 1.5], [-1.0, 2.5, 2.0]])
    (gen_dir / 'blobs.clones').write_text('3\n' + ''.join('%r %r %r 1 0 0 0\n' % tuple(map(float, x))
                                                             for x in locations))
    force_torque = np.array([[0.1, -0.2, -1.0, 0.5, -0.3, 0.8],
                             [0.0, 0.3, -0.5, -0.7, 0.2, 0.1],
                             [-0.4, 0.0, 0.2, 0.3, 0.9, -0.6]])
    np.savetxt(tmp_path / 'force.dat', force_torque)
    (tmp_path / 'in.dat').write_text(
        'scheme mobility\nmobility_blobs_implementation python\nmobility_vector_prod_implementation python\n'
        'eta 1.0\nblob_radius 0.25\nsolver_tolerance 1e-10\nforce_file force.dat\noutput_name data/run\n'
        'structure Structures/blob.vertex Structures/blobs.clones\n')
    assert run_script(str(tmp_path), 'in.dat', monkeypatch) == 0
    out = capsys.readouterr().out
    assert 'converged = True' in out
    residual = float(out.split('relative residual = ')[1].split()[0])
    assert residual <= 1e-10
    velocities = np.loadtxt(tmp_path / 'data' / 'run.velocities.dat').reshape(-1, 6)
    bodies = []
    for x in locations:
        b = Body(x, [1, 0, 0, 0], np.zeros((1, 3)), 0.25)
        b.ID = 'blobs'
        bodies.append(b)
    arrays = bodies_to_arrays(bodies)
    dense = body_solver.dense_mobility_velocities(arrays, arrays.configuration, force_torque,
                                                  np.zeros((3, 3)), mobility.single_wall_fluid_mobility, 1.0, 0.25)
    np.testing.assert_allclose(velocities, dense, rtol=0, atol=1e-8 * np.abs(dense).max())
    assert np.abs(dense[:, 3:]).max() < 1e-12 * np.abs(dense).max()  # one blob: no rotation (pinv)


@pytest.mark.parametrize('scheme, extra', [('body_mobility', ''), ('resistance', ''),
                                           ('mobility', 'plot_velocity_field 0 4 40 0 4 40 0 4 40\n')])
def test_static_problem_too_big_is_refused_before_writing(scheme, extra, tmp_path, monkeypatch):
    """Dense static problems and velocity grids that need more memory than is available are refused up front,
    naming the memory they need, and nothing is written (the memory available is made tiny here)."""
    from multi_bodies.run import run_output
    gen_dir = tmp_path / 'Structures'
    gen_dir.mkdir()
    (gen_dir / 'blob.vertex').write_text('1\n0.0 0.0 0.0\n')
    (gen_dir / 'blobs.clones').write_text('2\n0 0 1.5 1 0 0 0\n2 0 1.5 1 0 0 0\n')
    (tmp_path / 'in.dat').write_text('scheme %s\neta 1.0\nblob_radius 0.25\noutput_name data/run\n%s'
                                     'structure Structures/blob.vertex Structures/blobs.clones\n' % (scheme, extra))
    monkeypatch.setattr(run_output, 'available_memory', lambda: 1000)
    with pytest.raises(Exception) as err:
        run_script(str(tmp_path), 'in.dat', monkeypatch)
    assert 'needs about' in str(err.value) and 'line' in str(err.value)
    assert not (tmp_path / 'data').exists() or not any((tmp_path / 'data').iterdir())
