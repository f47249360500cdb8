"""The slip-length problem's neighbour correction (slip_length.SlipLengthNeighbourPreconditioner): its near field
against the dense operators of the backend, the same solutions in fewer GMRES iterations, and the runs that use it
(doc/preconditioners.md, "Problems that keep their own preconditioners")."""
import numpy as np
import pytest

import mobility
from body.body import Body, bodies_to_arrays
from multi_bodies.files.structure_generators import icosahedral_shell, smallest_distance
from multi_bodies.solver import body_solver, slip_length as sl
from multi_bodies.solver import neighbour_preconditioner

BACKEND = 'C++_no_wall'
ORIGINAL_INIT = sl.SlipLengthNeighbourPreconditioner.__init__


def shells(count, spacing, blobs=42, seed=0):
    """(BodyArrays, blob radius a, body-frame normals (N, 3), weights (N,)) of ``count`` unit shells on a square
    lattice of ``spacing`` at heights 5 +- 0.3, in random orientations (free space)."""
    rng = np.random.default_rng(seed)
    shell = icosahedral_shell(blobs)
    a = 0.5 * smallest_distance(shell)
    side = int(np.ceil(np.sqrt(count)))
    rows, columns = np.divmod(np.arange(count), side)
    locations = np.column_stack((spacing * columns, spacing * rows, 5.0 + 0.3 * rng.normal(size=count)))
    turns = rng.normal(size=(count, 4))
    turns /= np.linalg.norm(turns, axis=1, keepdims=True)
    bodies = [Body(location, turn, shell, a) for location, turn in zip(locations, turns)]
    for body in bodies:
        body.ID = 'shell'
    return bodies_to_arrays(bodies), a, np.tile(shell, (count, 1)), np.full(count * blobs, 4 * np.pi / blobs)


def problem_and_preconditioners(count, spacing, slip_length=1.0, backend=None):
    arrays, a, normals, weights = shells(count, spacing)
    q = arrays.configuration
    lengths = np.full(len(weights), slip_length)
    dense = mobility.blob_mobility_matrix(BACKEND)
    problem = sl.slip_length_problem(arrays, q, mobility.mobility_vector_product(BACKEND), 1.0, a, np.zeros(3),
                                     normals, lengths, weights)
    base = sl.SlipLengthPreconditioner(arrays, q, dense, 1.0, a, normals, lengths, weights)
    corrected = sl.SlipLengthNeighbourPreconditioner(base, dense, 1.0, a, cross_blocks=mobility.blob_cross_blocks(
        BACKEND), backend=backend)
    return problem, base, corrected, a


def test_double_layer_blocks_are_the_double_layer_sums():
    """The dense blocks (compiled and NumPy) times v are the double layer's own sums (double_layer_numpy, the
    reference of the slip-length operator) over two sets of blobs, to rounding (relative 1e-12)."""
    rng = np.random.default_rng(3)
    x = rng.normal(size=(30, 3)) * 2.0
    n = rng.normal(size=(30, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    w = rng.uniform(0.1, 0.3, size=30)
    v = rng.normal(size=(30, 3))
    targets, sources = slice(0, 12), slice(12, 30)
    only_sources = np.zeros_like(v)
    only_sources[sources] = v[sources]
    expected = sl.double_layer_numpy(x, n, w, 0.2, only_sources)[targets].reshape(-1)
    for backend in ('C++', 'python'):
        if backend == 'C++' and sl._surface_cpp is None:
            continue
        blocks = sl.double_layer_blocks(x[targets][None], x[sources][None], n[sources][None], w[sources][None], 0.2,
                                        backend=backend)[0]
        assert blocks.shape == (36, 54)
        assert np.linalg.norm(blocks @ v[sources].reshape(-1) - expected) < 1e-12 * np.linalg.norm(expected)
    whole = sl.double_layer_matrix(x, n, w, 0.2)
    assert np.linalg.norm(whole @ v.reshape(-1) - sl.double_layer_numpy(x, n, w, 0.2, v).reshape(-1)) < \
        1e-12 * np.linalg.norm(whole @ v.reshape(-1))


@pytest.mark.parametrize('backend', ['C++', 'python'])
def test_near_field_is_the_dense_operator_of_the_neighbour_pairs(backend):
    """``O_near`` of 9 shells: ``M_ij lambda_j - D_ij v_j`` over the neighbour pairs (bodies whose blobs come within
    8 blob radii) equals the dense blob mobility of the backend and the dense double layer restricted to those
    pairs, to rounding (relative 1e-12); the compiled path computes it from the positions, the other from stored
    pair blocks."""
    if backend == 'C++' and sl._surface_cpp is None:
        pytest.skip('the C++ surface kernels are not built')
    problem, base, corrected, a = problem_and_preconditioners(9, 2.6, backend=backend)
    assert corrected.on_the_fly == (backend == 'C++')
    r = problem.r_vectors
    M = np.array(mobility.blob_mobility_matrix(BACKEND)(r, 1.0, a))
    D = sl.double_layer_matrix(r, problem.normals, problem.weights, a)
    body = np.repeat(np.arange(9), 42)
    near = np.zeros((9, 9), dtype=bool)
    pairs = corrected.pairs
    near[pairs[:, 0], pairs[:, 1]] = near[pairs[:, 1], pairs[:, 0]] = True
    # the pairs are those of the surface distances, found independently here
    distances = np.linalg.norm(r[:, None] - r[None], axis=2)
    for i in range(9):
        for j in range(9):
            if i != j:
                gap = distances[body == i][:, body == j].min() - 2 * a
                assert near[i, j] == (gap < 8 * a)
    assert 0 < pairs.shape[0] < 36
    mask = np.kron(near, np.ones((126, 126)))
    rng = np.random.default_rng(4)
    lam, v = rng.normal(size=(378, 3)), rng.normal(size=(378, 3))
    expected = (M * mask) @ lam.reshape(-1) - (D * mask) @ v.reshape(-1)
    got = corrected.near_field_product(lam, v)
    assert np.linalg.norm(got - expected) < 1e-12 * np.linalg.norm(expected)


@pytest.mark.parametrize('slip_length', [0.0, 1.0, 1e3])
def test_same_solution_in_fewer_iterations(slip_length):
    """25 shells 0.6 apart (surface to surface, 2.2 blob radii), sedimenting under random forces and a random slip:
    the corrected preconditioner reaches the block-diagonal one's solution (the same problem: they agree within
    the solver tolerance times the conditioning: 1e-8 of the largest velocity at tolerance 1e-10, measured 1.2e-12 to
    2.1e-10) in at most 3/4 of its GMRES iterations (measured 10 against 16 at slip lengths 1 and 1e3, 16 against
    25 at 0)."""
    problem, base, corrected, _ = problem_and_preconditioners(25, 2.6, slip_length)
    rng = np.random.default_rng(1)
    force = np.zeros((25, 6))
    force[:, 2] = -1.0
    force += 0.3 * rng.normal(size=force.shape)
    rhs = problem.rhs(rng.normal(size=(problem.num_blobs, 3)), force)
    plain = body_solver.solve(problem, rhs, base, tolerance=1e-10, restart=300)
    better = body_solver.solve(problem, rhs, corrected, tolerance=1e-10, restart=300)
    assert plain.converged and better.converged
    assert better.iterations <= 0.75 * plain.iterations, (better.iterations, plain.iterations)
    scale = np.abs(plain.velocities).max()
    assert np.abs(better.velocities - plain.velocities).max() < 1e-8 * scale


def test_auto_leaves_the_correction_out_when_the_near_field_is_most_of_the_pairs():
    """Four shells 1 apart: the near pairs are 3/8 of the blob pairs, above AUTO_MAX_COST_RATIO, so with that
    limit the preconditioner is every body alone (the same operator as the base, to the bit)."""
    problem, base, _, a = problem_and_preconditioners(4, 3.0)
    dense = mobility.blob_mobility_matrix(BACKEND)
    limited = sl.SlipLengthNeighbourPreconditioner(base, dense, 1.0, a, max_cost_ratio=sl.AUTO_MAX_COST_RATIO)
    assert limited.cost_ratio > sl.AUTO_MAX_COST_RATIO and limited.pairs.size == 0
    x = np.random.default_rng(2).normal(size=problem.size)
    np.testing.assert_array_equal(limited.apply(x), base.apply(x))


def _run(tmp_path, preconditioner, monkeypatch):
    """Three steps of forward Euler of 16 sedimenting shells 0.6 apart (slip length 0.5); (final locations (16, 3),
    preconditioner classes built)."""
    from multi_bodies.files import structure_generators as gen
    from run_scenes import run_in_process, set_options
    folder = tmp_path / preconditioner
    folder.mkdir()
    blobs = icosahedral_shell(42)
    a = 0.5 * smallest_distance(blobs)
    np.savetxt(folder / 'shell.vertex', blobs, header=str(len(blobs)), comments='')
    arrays, _, _, _ = shells(16, 2.6)
    q = arrays.configuration
    rows = np.hstack((q.locations, q.orientations))
    np.savetxt(folder / 'shells.clones', rows, header=str(len(rows)), comments='')
    gen.write_surface_table(folder / 'shell.slip_length', gen.slip_length_table(blobs, 0.5), 'slip length 0.5')
    (folder / 'input.dat').write_text(set_options(
        'structure shell.vertex shells.clones shell.slip_length', scheme='deterministic_forward_euler', dt=0.01,
        n_steps=3, n_save=3, eta=1.0, g=1.0, blob_radius=a, solver_tolerance=1e-10, domain='no_wall',
        mobility_blobs_implementation=BACKEND, mobility_vector_prod_implementation=BACKEND,
        blob_blob_force_implementation='None', preconditioner=preconditioner, output_name='data/run'))
    (folder / 'data').mkdir()
    built = []
    original = ORIGINAL_INIT

    def spy(self, *args, **kwargs):
        original(self, *args, **kwargs)
        built.append(bool(self.pairs.size))
    monkeypatch.setattr(sl.SlipLengthNeighbourPreconditioner, '__init__', spy)
    status, out, err = run_in_process('dynamic', folder, 'input.dat')
    assert status == 0, out + err
    final = np.loadtxt(folder / 'data' / 'run.shells.00000003.clones', skiprows=1)[:, :3]
    return final, built, q.locations


def test_runs_use_it_under_auto_and_neighbours_and_give_the_published_trajectory(tmp_path, monkeypatch):
    """The same run under block_diagonal (the published preconditioner, no correction built), auto and neighbours
    (corrected at every build): the final locations agree within 1e-8 of the distance travelled (solver tolerance
    1e-10; measured 1.1e-11 of 0.30)."""
    runs = {name: _run(tmp_path, name, monkeypatch) for name in ('block_diagonal', 'auto', 'neighbours')}
    assert runs['block_diagonal'][1] == []
    assert runs['auto'][1] and all(runs['auto'][1])
    assert runs['neighbours'][1] and all(runs['neighbours'][1])
    reference, _, start = runs['block_diagonal']
    travelled = np.abs(reference - start).max()
    assert travelled > 1e-3
    for name in ('auto', 'neighbours'):
        assert np.abs(runs[name][0] - reference).max() < 1e-8 * travelled, name


def test_pair_search_matches_the_rigid_preconditioner():
    """The correction's neighbour pairs are those of the rigid problem's (neighbour_preconditioner.neighbour_pairs)
    at the default gap."""
    problem, base, corrected, a = problem_and_preconditioners(16, 2.6)
    arrays = corrected.body_arrays
    pairs, _, _ = neighbour_preconditioner.neighbour_pairs(
        problem.r_vectors, arrays.blob_body_index, np.full(problem.num_blobs, a), arrays.configuration.locations,
        neighbour_preconditioner.DEFAULT_GAP_IN_RADII * a)
    np.testing.assert_array_equal(corrected.pairs, pairs)
