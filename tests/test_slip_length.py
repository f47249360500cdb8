"""The slip-length problem (multi_bodies/solver/slip_length.py): the published FreeSlip probes, the no-slip and
free-slip limits with their convergence orders over 42, 162 and 642 blobs (doc/phoretic.md)."""
import numpy as np
import pytest

import mobility
from body.body import Body, bodies_to_arrays
from multi_bodies.files.structure_files import read_vertex_file
from multi_bodies.files.structure_generators import icosahedral_shell, smallest_distance
from multi_bodies.solver import body_solver, slip_length as sl

PHORETIC = 'published_2025/phoretic/multi_bodies'


def _problem(reference, blob_radius, location, normals, lengths, weights):
    body = Body(np.asarray(location, float), np.array([1.0, 0, 0, 0]), reference, blob_radius)
    arrays = bodies_to_arrays([body], [1])
    q = arrays.configuration
    problem = sl.slip_length_problem(arrays, q, mobility.mobility_vector_product('python_no_wall'), 1.0, blob_radius,
                                     np.zeros(3), normals, lengths, weights)
    pc = sl.SlipLengthPreconditioner(arrays, q, mobility.blob_mobility_matrix('python_no_wall'), 1.0, blob_radius,
                                     normals, lengths, weights)
    rigid = body_solver.MobilityProblem(arrays, q, mobility.mobility_vector_product('python_no_wall'), 1.0,
                                        blob_radius)
    rigid_pc = body_solver.BlockDiagonalPreconditioner(arrays, q, mobility.blob_mobility_matrix('python_no_wall'),
                                                       1.0, blob_radius)
    return problem, pc, rigid, rigid_pc


def _solve(problem, pc, force_torque, tolerance):
    rhs = problem.rhs(None, force_torque)
    result = body_solver.solve(problem, rhs, pc, tolerance=tolerance, restart=300)
    assert result.converged
    x = result.normalised_solution * np.linalg.norm(problem.prepare_rhs(rhs.copy()))
    return result, problem.surface_slip(x)


def test_freeslip_probes(reference_dir):
    """Forces, velocities and surface slip of the published FreeSlip run (162 blobs, l = 1e3, g = 1) to 1e-8."""
    base = reference_dir / PHORETIC
    probe = np.load(base / 'examples/FreeSlip/run.probe.npz')
    reference = read_vertex_file(str(base / 'Structures/shell_N_162_Rg_1_Rh_1_0530.vertex'))
    table = np.loadtxt(base / 'Structures/shell_N_162_Rg_1_slip_length_1e+03.slip_length')
    problem, pc, _, _ = _problem(reference, 0.137952242127634, (0, 0, 10.0), table[:, :3], table[:, 3], table[:, 4])
    np.testing.assert_array_equal(problem.rigid.r_vectors, probe['step0_r_vectors'])
    force = np.zeros((1, 6))
    force[0, 2] = -162.0
    result, u = _solve(problem, pc, force, 1e-8)
    for ours, name in ((result.velocities, 'velocities'), (result.lambda_blobs, 'lambda'), (u, 'u_s')):
        published = probe['step0_' + name]
        error = np.max(np.abs(ours - published)) / np.max(np.abs(published))
        assert error < 1e-8, (name, error)   # measured: 1e-12, 7e-11, 1.3e-10
    assert abs(result.velocities[0, 2] - (-12.966122805120389)) < 1e-8 * 12.97


def _unit_shell(n):
    reference = icosahedral_shell(n)
    normals = reference / np.linalg.norm(reference, axis=1)[:, None]
    return reference, 0.5 * smallest_distance(reference), normals, np.full(n, 4 * np.pi / n)


def _sedimentation_speeds(n, lengths):
    """(U_z with each slip length in ``lengths``, U_z of the ordinary rigid problem) under F_z = 1, unit shell."""
    reference, a, normals, weights = _unit_shell(n)
    force = np.zeros((1, 6))
    force[0, 2] = 1.0
    speeds, slips = [], []
    for length in lengths:
        problem, pc, rigid, rigid_pc = _problem(reference, a, (0, 0, 0), normals, np.full(n, length), weights)
        result, u = _solve(problem, pc, force, 1e-10)
        speeds.append(result.velocities[0, 2])
        slips.append(u)
    plain = body_solver.solve(rigid, rigid.rhs(None, force), rigid_pc, tolerance=1e-10).velocities[0, 2]
    return speeds, slips, plain


def _orders(errors):
    """Convergence orders in the blob spacing h (h halves from one shell to the next)."""
    return [np.log2(errors[i] / errors[i + 1]) for i in range(len(errors) - 1)]


@pytest.fixture(scope='module')
def limits():
    return {n: _sedimentation_speeds(n, (0.0, 1e-8, 1e4)) for n in (42, 162, 642)}


def test_no_slip_limit(limits):
    """l -> 0: u = 0 exactly, continuous in l, and equal to the ordinary rigid result up to a discretisation error
    that falls at first order in the blob spacing (the published (I/2 + D) K U in place of K U)."""
    errors = []
    for n, (speeds, slips, plain) in sorted(limits.items()):
        assert np.max(np.abs(slips[0])) == 0.0
        assert abs(speeds[1] - speeds[0]) < 1e-6 * abs(speeds[0])       # l = 1e-8 vs l = 0
        errors.append(abs(speeds[0] - plain) / abs(plain))
    orders = _orders(errors)
    # measured: relative differences 0.078, 0.041, 0.021; orders 0.93, 0.96
    assert errors[0] > errors[1] > errors[2]
    assert min(orders) > 0.8 and errors[2] < 0.03
    # the sign of the double layer, from outside: D of a rigid translation on the a = 0, 642-blob unit sphere is
    # about +0.478 V (the method note's own dense check); a wrong sign would give -0.478 V
    reference, _, normals, weights = _unit_shell(642)
    moving = np.tile([0.0, 0.0, 1.0], (642, 1))
    mean = np.mean(sl.double_layer(reference, normals, weights, 0.0, moving), axis=0)
    assert np.allclose(mean, [0, 0, 0.478], atol=2e-3), mean


def test_free_slip_limit(limits):
    """l -> infinity: the drag falls from 6 pi eta a to 4 pi eta a (speed ratio 2/3), convergence order measured."""
    errors = []
    for n, (speeds, slips, plain) in sorted(limits.items()):
        ratio = speeds[0] / speeds[2]              # no-slip speed / free-slip speed = F_free / F_noslip
        errors.append(abs(ratio - 2.0 / 3.0))
        assert np.max(np.abs(np.einsum('ij,ij->i', _unit_shell(n)[2], slips[2]))) < 1e-6 * np.max(np.abs(slips[2]))
    orders = _orders(errors)
    # measured: |ratio - 2/3| = 0.0178, 0.0096, 0.0051; orders 0.89, 0.91
    assert errors[0] > errors[1] > errors[2]
    assert min(orders) > 0.7 and errors[2] < 0.01
    # the free-slip sphere moves at F / (4 pi eta R) with R the shell radius, within 1 % at 642 blobs
    assert abs(limits[642][0][2] * 4 * np.pi - 1.0) < 0.01
    # negative control: the no-slip speed is 2/3 of it, not the free-slip one
    assert abs(limits[642][0][0] * 4 * np.pi - 1.0) > 0.3
