"""The neighbour preconditioner (multi_bodies/solver/neighbour_preconditioner.py, doc/preconditioners.md).

Laws checked: the solution of GMRES does not depend on the preconditioner (dense algebra decides); two
bodies alone are preconditioned by the exact inverse when ``T_i`` is applied exactly (the star of each body
is the whole system); the neighbour search equals a brute-force minimum-image search, across periodic
boundaries too; the Lanczos noise is the block-diagonal one to round-off (SPEC decision 1); and the
iteration count of a dense scene is at most half the block-diagonal one (the issue's target, measured
against the published preconditioner on the same scene).
"""
import numpy as np
import pytest

from body.body import Body, Configuration, bodies_to_arrays
from multi_bodies.files.structure_generators import boomerang
from multi_bodies.solver import body_solver, user_hooks
from multi_bodies.solver.model import Model
from multi_bodies.solver.neighbour_preconditioner import NeighbourPreconditioner, neighbour_pairs


def boomerang_model(centres, seed=1, periodic_length=(0.0, 0.0, 0.0), preconditioner='neighbours', blobs_name='C++'):
    rng = np.random.default_rng(seed)
    bodies = []
    for centre in centres:
        q = rng.normal(size=4)
        body = Body(centre, q / np.linalg.norm(q), boomerang(), 0.25)
        body.ID = 'boomerang'
        body.body_length = body.calc_body_length()
        bodies.append(body)
    physics = dict(g=1.0, repulsion_strength_wall=1.0, debye_length_wall=1.0, repulsion_strength=1.0,
                   debye_length=1.0, periodic_length=np.asarray(periodic_length, dtype=float), blob_radius=0.25,
                   blob_mass=1.0)
    return Model(bodies, bodies_to_arrays(bodies), user_hooks.load_user_hooks('/nonexistent'), physics, 1.0, 0.25,
                 1e-8, vector_product_name=blobs_name, blobs_name=blobs_name, blob_blob_name='None',
                 periodic_length=periodic_length, preconditioner=preconditioner)


def grid(num, spacing, height=2.5):
    side = int(np.ceil(np.sqrt(num)))
    return [[spacing * (k % side), spacing * (k // side), height] for k in range(num)]


def count_builds(monkeypatch):
    """The ``solves`` of every ``Model.build_preconditioner`` call from now on (a list that fills as they come)."""
    asked = []
    build = Model.build_preconditioner

    def spy(self, configuration, solves=1):
        asked.append(solves)
        return build(self, configuration, solves=solves)
    monkeypatch.setattr(Model, 'build_preconditioner', spy)
    return asked


def dense_saddle_matrix(model, configuration):
    M, _, K, _ = body_solver.dense_matrices(model.arrays, configuration, model.blob_mobility_matrix, model.eta,
                                             model.blob_radius, inverse=False)
    n3, m = M.shape[0], K.shape[1]
    A = np.zeros((n3 + m, n3 + m))
    A[:n3, :n3], A[:n3, n3:], A[n3:, :n3] = M, -K, -K.T
    return A


def matrix_of(apply, size):
    return np.column_stack([apply(e) for e in np.eye(size)])


def test_two_bodies_alone_are_preconditioned_exactly():
    """Two close boomerangs: with T_i applied exactly, B = A^{-1} (to round-off); the first-order default is
    a good approximation but not exact (so the test can tell the two apart)."""
    model = boomerang_model([[0.0, 0.0, 2.5], [1.2, 0.4, 2.7]])
    configuration = model.start_configuration
    base = model.replace(preconditioner='block_diagonal').build_preconditioner(configuration)
    A = dense_saddle_matrix(model, configuration)
    exact = NeighbourPreconditioner(base, model.stacked_mobility, model.eta, model.blob_radius, gap=10.0,
                                    strong_gap=10.0, exact_woodbury=True)
    assert exact.pairs.tolist() == [[0, 1]]
    B = matrix_of(exact.apply, A.shape[0])
    assert np.abs(B @ A - np.eye(A.shape[0])).max() < 1e-8
    # negative controls: the base alone, and the first-order T_i^{-1}, are not the inverse
    first_order = NeighbourPreconditioner(base, model.stacked_mobility, model.eta, model.blob_radius, gap=10.0,
                                          strong_gap=10.0)
    assert np.abs(matrix_of(base.apply, A.shape[0]) @ A - np.eye(A.shape[0])).max() > 1e-3
    assert np.abs(matrix_of(first_order.apply, A.shape[0]) @ A - np.eye(A.shape[0])).max() > 1e-6


def gmres_iterations(model, configuration, rhs):
    problem = model.mobility_problem(configuration)
    preconditioner = model.build_preconditioner(configuration)
    result = body_solver.solve(problem, rhs, preconditioner, tolerance=1e-8)
    assert result.converged
    return result


def test_solution_does_not_depend_on_the_preconditioner_and_iterations_halve():
    """25 boomerangs at 2.6 apart (nearly touching, random orientations): both preconditioners give the dense
    solution within the solver tolerance; the neighbour one takes at most half the iterations."""
    model = boomerang_model(grid(25, 2.6), seed=4)
    configuration = model.start_configuration
    A = dense_saddle_matrix(model, configuration)
    rng = np.random.default_rng(0)
    problem = model.mobility_problem(configuration)
    force = np.zeros((25, 6))
    force[:, 2] = -1.0
    rhs = problem.rhs(force_torque=force, noise_slip=rng.standard_normal(3 * model.num_blobs))
    exact = np.linalg.solve(A, rhs)
    block = gmres_iterations(model.replace(preconditioner='block_diagonal'), configuration, rhs)
    neighbours = gmres_iterations(model, configuration, rhs)
    n3 = 3 * model.num_blobs
    scale = np.abs(exact[n3:]).max()
    for result in (block, neighbours):
        # GMRES stops at |r| <= 1e-8 |b|; the body velocities then agree to ~cond(A) 1e-8 (measured 1e-9)
        assert np.abs(result.velocities.reshape(-1) - exact[n3:]).max() < 1e-6 * scale
    assert block.iterations >= 10  # the scene is hard for the block-diagonal preconditioner
    assert 2 * neighbours.iterations <= block.iterations, (neighbours.iterations, block.iterations)


def brute_force_pairs(r_vectors, body_index, radius, gap, L):
    pairs = set()
    periodic = L > 0
    for a in range(len(r_vectors)):
        d = r_vectors - r_vectors[a]
        d[:, periodic] -= L[periodic] * np.round(d[:, periodic] / L[periodic])
        close = np.linalg.norm(d, axis=1) - 2 * radius < gap
        for b in np.flatnonzero(close):
            if body_index[a] != body_index[b]:
                pairs.add((min(body_index[a], body_index[b]), max(body_index[a], body_index[b])))
    return sorted(pairs)


@pytest.mark.parametrize('periodic_length', [(0.0, 0.0, 0.0), (12.0, 12.0, 0.0)])
def test_neighbour_search_equals_brute_force(periodic_length):
    """Bodies near opposite edges of a periodic box are neighbours through the boundary, with the image
    shift of the minimum image; without the box they are not."""
    centres = grid(16, 3.0) + [[11.5, 1.0, 2.5]]  # the last body sits across the x boundary from body 0
    model = boomerang_model(centres, seed=2, periodic_length=periodic_length)
    configuration = model.start_configuration
    r_vectors = model.arrays.blob_positions(configuration)
    L = np.asarray(periodic_length)
    pairs, shifts, gaps = neighbour_pairs(r_vectors, model.arrays.blob_body_index, 0.25, configuration.locations,
                                          2.0, L)
    expected = brute_force_pairs(r_vectors, model.arrays.blob_body_index, 0.25, 2.0, L)
    assert [tuple(p) for p in pairs] == expected
    across = [k for k, (i, j) in enumerate(pairs) if (i, j) == (0, 16)]
    assert bool(across) == bool(L[0] > 0)
    if across:
        assert np.allclose(shifts[across[0]], [-12.0, 0.0, 0.0])
    assert np.all(gaps < 2.0)


def test_lanczos_noise_is_the_block_diagonal_one():
    """The neighbour preconditioner changes GMRES only: Lanczos runs with the same Cholesky factors."""
    model = boomerang_model(grid(9, 3.0), seed=5)
    configuration = model.start_configuration
    problem = model.mobility_problem(configuration)
    z = np.random.default_rng(1).standard_normal(3 * model.num_blobs)
    block_model = model.replace(preconditioner='block_diagonal')
    neighbours_pc = model.build_preconditioner(configuration)
    assert isinstance(neighbours_pc, NeighbourPreconditioner) and neighbours_pc.pairs.size
    ours = model.lanczos_noise(problem, z, 1.0, neighbours_pc).noise
    published = block_model.lanczos_noise(problem, z, 1.0, block_model.build_preconditioner(configuration)).noise
    assert np.array_equal(ours, published)


def test_krylov_iterations_of_the_obstacle_problem_halve():
    """Bodies with prescribed kinematics (obstacles) are preconditioned by their own blocks too."""
    model = boomerang_model(grid(16, 2.6), seed=6)
    bodies = model.bodies
    for body in bodies[::3]:
        body.prescribed_velocity = np.zeros(6)  # obstacles held still
    fixed = Model(bodies, bodies_to_arrays(bodies), model.hooks, model.physics, 1.0, 0.25, 1e-8,
                  vector_product_name='C++', blobs_name='C++', preconditioner='neighbours')
    assert fixed.has_fixed_bodies
    configuration = fixed.start_configuration
    problem = fixed.mobility_problem(configuration)
    force = np.zeros((16, 6))
    force[:, 2] = -1.0
    rhs = problem.rhs(force_torque=force)
    block = body_solver.solve(problem, rhs, fixed.replace(preconditioner='block_diagonal').build_preconditioner(
        configuration))
    neighbours = body_solver.solve(problem, rhs, fixed.build_preconditioner(configuration))
    assert np.abs(block.velocities - neighbours.velocities).max() < 1e-6 * np.abs(block.velocities).max()
    assert neighbours.iterations < block.iterations



def test_neighbour_product_is_the_dense_mobility_of_the_neighbour_pairs():
    """The near-field product equals the dense blob mobility restricted to the blocks of the neighbour pairs
    (both orders of each pair), and nothing else (the stored-block paths: the next test)."""
    model = boomerang_model(grid(9, 2.8), seed=7)
    configuration = model.start_configuration
    pc = model.build_preconditioner(configuration)
    assert pc.pairs.size
    M = dense_saddle_matrix(model, configuration)[:3 * model.num_blobs, :3 * model.num_blobs]
    blob_body = np.repeat(model.arrays.blob_body_index, 3)
    near = np.zeros((model.num_bodies, model.num_bodies), dtype=bool)
    near[pc.pairs[:, 0], pc.pairs[:, 1]] = near[pc.pairs[:, 1], pc.pairs[:, 0]] = True
    expected_matrix = np.where(near[np.ix_(blob_body, blob_body)], M, 0.0)
    forces = np.random.default_rng(2).standard_normal(3 * model.num_blobs)
    compiled = pc.neighbour_product(forces)
    assert np.abs(compiled - expected_matrix @ forces).max() < 1e-12 * np.abs(M).max() * np.abs(forces).sum()


@pytest.mark.parametrize('blobs_name', ['C++', 'C++_no_wall'])
@pytest.mark.parametrize('periodic_length', [(0.0, 0.0, 0.0), (8.4, 8.4, 0.0)])
@pytest.mark.parametrize('height', [2.5, 2.1])
def test_near_field_from_positions_is_the_mobility_of_the_pairs(blobs_name, periodic_length, height, monkeypatch):
    """The compiled near field computed from the blob positions (the default with the C++ blob mobility)
    equals the NumPy backend's dense mobility of every neighbour pair (both orders, the partner at its image
    shift), above a wall and in free space, across periodic boundaries, and with blobs below their radius
    (height 2.1: the wall regularisation raises and damps them).  The stored-block path, compiled and NumPy,
    gives the same product and the same preconditioner."""
    import mobility
    import multi_bodies.solver.neighbour_preconditioner as neighbour_module
    model = boomerang_model(grid(9, 2.8, height), seed=7, periodic_length=periodic_length, blobs_name=blobs_name)
    configuration = model.start_configuration
    pc = model.build_preconditioner(configuration)
    assert pc.on_the_fly and pc.pairs.size and not pc.groups
    r = model.arrays.blob_positions(configuration)
    assert (height < 2.5) == bool(0.0 < r[:, 2].min() < 0.25)  # the low scene has blobs below their radius
    pairs, shifts, _ = neighbour_pairs(r, model.arrays.blob_body_index, 0.25, configuration.locations, 2.0,
                                       np.asarray(periodic_length))
    assert [tuple(p) for p in pairs] == [tuple(p) for p in pc.pairs]
    assert bool(np.any(shifts)) == bool(periodic_length[0] > 0)
    dense = mobility.blob_mobility_matrix('python' + blobs_name[len('C++'):])
    offsets = model.arrays.blob_offsets
    forces = np.random.default_rng(2).standard_normal(3 * model.num_blobs)
    expected = np.zeros_like(forces)
    for (i, j), shift in zip(pairs, shifts):
        rows, cols = slice(3 * offsets[i], 3 * offsets[i + 1]), slice(3 * offsets[j], 3 * offsets[j + 1])
        both = np.concatenate((r[offsets[i]:offsets[i + 1]], r[offsets[j]:offsets[j + 1]] + shift))
        block = dense(both, model.eta, 0.25)[:rows.stop - rows.start, rows.stop - rows.start:]
        expected[rows] += block @ forces[cols]
        expected[cols] += block.T @ forces[rows]
    scale = np.abs(expected).max()
    assert np.abs(pc.neighbour_product(forces) - expected).max() < 1e-12 * scale
    stored = NeighbourPreconditioner(pc.base, model.stacked_mobility, model.eta, model.blob_radius,
                                     periodic_length=model.periodic_length, body_lengths=model.body_lengths,
                                     cross_blocks=mobility.blob_cross_blocks(blobs_name))
    assert not stored.on_the_fly and stored.groups
    assert np.abs(stored.neighbour_product(forces) - expected).max() < 1e-12 * scale
    x = np.random.default_rng(3).standard_normal(pc.operator.shape[0])
    assert np.abs(pc.apply(x) - stored.apply(x)).max() < 1e-12 * np.abs(stored.apply(x)).max()
    monkeypatch.setattr(neighbour_module, '_preconditioner_cpp', None)  # the NumPy pair product
    assert np.abs(stored.neighbour_product(forces) - expected).max() < 1e-12 * scale


def test_near_field_kernel_refuses_bad_arguments():
    """The compiled near field checks its arguments (a clear error, not a crash or a wrong sum)."""
    from multi_bodies.solver import _preconditioner_cpp
    x, f = np.zeros((4, 3)), np.zeros((4, 3))
    offsets, starts = np.array([0, 2, 4]), np.array([0, 1, 2])
    good = dict(x=x, a=0.25, eta=1.0, wall=True, offsets=offsets, target_start=starts, partners=np.array([1, 0]),
                shifts=np.zeros((2, 3)), forces=f)
    assert _preconditioner_cpp.rigid_near_field(**good).shape == (4, 3)
    for change, message in ((dict(partners=np.array([1, 2])), 'body indices'),
                            (dict(offsets=np.array([0, 2, 3])), 'span the blobs'),
                            (dict(shifts=np.array([[0, 0, 1.0], [0, 0, -1.0]])), 'x and y'),
                            (dict(forces=np.zeros((3, 3))), 'forces'), (dict(a=0.0), 'positive')):
        with pytest.raises(ValueError, match=message):
            _preconditioner_cpp.rigid_near_field(**dict(good, **change))


def test_small_bodies_are_neighbours_only_when_they_nearly_touch():
    """The gap of a pair is also bounded by the smaller body length: single blobs (rollers, body length 2a)
    1.2 radii apart are neighbours, 2.4 radii apart are not (8 radii would make them all neighbours)."""
    def rollers(gap_in_radii):
        bodies = []
        for k in range(4):
            body = Body([k * (2.0 + gap_in_radii) * 0.5, 0.0, 2.0], [1.0, 0, 0, 0], np.zeros((1, 3)), 0.5)
            body.ID = 'roller'
            body.body_length = 1.0
            bodies.append(body)
        return Model(bodies, bodies_to_arrays(bodies), user_hooks.load_user_hooks('/nonexistent'),
                     dict(g=1.0, repulsion_strength_wall=1.0, debye_length_wall=1.0, repulsion_strength=1.0,
                          debye_length=1.0, periodic_length=np.zeros(3), blob_radius=0.5, blob_mass=1.0),
                     1.0, 0.5, 1e-8, vector_product_name='C++', blobs_name='C++', preconditioner='neighbours')
    close, apart = rollers(1.2), rollers(2.4)
    assert close.build_preconditioner(close.start_configuration).pairs.tolist() == [[0, 1], [1, 2], [2, 3]]
    assert apart.build_preconditioner(apart.start_configuration).pairs.size == 0


def test_auto_builds_the_correction_only_where_it_is_cheap():
    """preconditioner auto: the correction where the candidate pairs' blob pairs are at most
    AUTO_MAX_COST_RATIO of all blob pairs (100 boomerangs 4 apart: 0.034), the base preconditioner where they
    are more (16 boomerangs 2.6 apart: every body has neighbours)."""
    from multi_bodies.solver.neighbour_preconditioner import AUTO_MAX_COST_RATIO
    sparse = boomerang_model(grid(100, 4.0), seed=1, preconditioner='auto')
    dense = boomerang_model(grid(16, 2.6), seed=6, preconditioner='auto')
    sparse_pc = sparse.build_preconditioner(sparse.start_configuration)
    dense_pc = dense.build_preconditioner(dense.start_configuration)
    assert sparse_pc.cost_ratio <= AUTO_MAX_COST_RATIO < dense_pc.cost_ratio
    assert sparse_pc.pairs.size and sparse_pc.has_neighbours
    assert dense_pc.pairs.size == 0 and not dense_pc.has_neighbours
    forced = dense.replace(preconditioner='neighbours').build_preconditioner(dense.start_configuration)
    assert forced.pairs.size
    # a preconditioner that serves k solves may cost k times as much: built where cost_ratio <= k * the ratio
    k = int(np.ceil(dense_pc.cost_ratio / AUTO_MAX_COST_RATIO))
    assert not dense.build_preconditioner(dense.start_configuration, solves=k - 1).pairs.size
    assert dense.build_preconditioner(dense.start_configuration, solves=k).pairs.size


def test_stochastic_schemes_weigh_the_build_against_their_solves(monkeypatch):
    """A stochastic step asks for the preconditioner with the solves it will make with it: Slip_Trapz 3 a step,
    the others 2, times update_PC."""
    from multi_bodies.files.input_options import options_with
    from quaternion_integrator.schemes import make_scheme
    model = boomerang_model(grid(4, 4.0), seed=1, preconditioner='auto')
    asked = count_builds(monkeypatch)
    for name, update, expected in (('stochastic_Slip_Trapz', 1, 3), ('stochastic_Slip_Trapz', 4, 12),
                                   ('stochastic_EM', 1, 2)):
        scheme = make_scheme(name, 0.01, options_with(kT=1.0, rf_delta=1e-3, update_PC=update))
        asked.clear()
        scheme.step(model, scheme.init(model, model.start_configuration), np.random.default_rng(0))
        assert asked and asked[0] == expected, (name, update, asked)


@pytest.mark.parametrize('backend, radii', [('C++_no_wall', False), ('C++_free_surface', False), ('python', False),
                                            ('C++', True)])
def test_other_domains_and_per_blob_radii_converge_to_the_dense_solution(backend, radii):
    """Free space, the free surface, the python backend (pair blocks from its stacked matrices) and per-blob
    radii (likewise): the neighbour preconditioner is built, GMRES reaches the dense solution, and takes fewer
    iterations than with the block-diagonal preconditioner."""
    rng = np.random.default_rng(3)
    bodies = []
    for centre in grid(9, 2.7):
        q = rng.normal(size=4)
        blobs_radius = 0.25 * (1.0 + 0.2 * rng.random(15)) if radii else None
        body = Body(centre, q / np.linalg.norm(q), boomerang(), 0.25, blobs_radius=blobs_radius)
        body.ID = 'boomerang'
        body.body_length = body.calc_body_length()
        bodies.append(body)
    physics = dict(g=1.0, repulsion_strength_wall=1.0, debye_length_wall=1.0, repulsion_strength=1.0,
                   debye_length=1.0, periodic_length=np.zeros(3), blob_radius=0.25, blob_mass=1.0)
    model = Model(bodies, bodies_to_arrays(bodies), user_hooks.load_user_hooks('/nonexistent'), physics, 1.0, 0.25,
                  1e-8, vector_product_name=backend, blobs_name=backend, preconditioner='neighbours')
    configuration = model.start_configuration
    pc = model.build_preconditioner(configuration)
    assert isinstance(pc, NeighbourPreconditioner) and pc.pairs.size
    problem = model.mobility_problem(configuration)
    force = np.zeros((9, 6))
    force[:, 2] = -1.0
    rhs = problem.rhs(force_torque=force)
    exact = np.linalg.solve(dense_saddle_matrix(model, configuration), rhs)
    result = body_solver.solve(problem, rhs, pc)
    block = body_solver.solve(problem, rhs, model.replace(preconditioner='block_diagonal').build_preconditioner(
        configuration))
    n3 = 3 * model.num_blobs
    assert np.abs(result.velocities.reshape(-1) - exact[n3:]).max() < 1e-6 * np.abs(exact[n3:]).max()
    assert result.iterations < block.iterations


def test_obstacles_rigid_modes_are_coupled_even_without_neighbours():
    """Bodies of prescribed motion have unknown net forces, which couple at long range: the coarse correction
    of their rigid modes is built under ``auto`` even where no pair is a neighbour (9 pillars 4 apart, gap 2.3
    > 8 radii), and GMRES reaches the dense solution in fewer iterations than with the block-diagonal
    preconditioner (which has no such correction: the negative control)."""
    angles = 2 * np.pi * np.arange(6) / 6
    cylinder = np.array([[0.6 * np.cos(t + 0.5 * (z % 2)), 0.6 * np.sin(t + 0.5 * (z % 2)), 0.5 * z - 1.75]
                         for z in range(8) for t in angles])
    bodies = []
    for centre in grid(9, 4.0):
        body = Body(centre, [1.0, 0, 0, 0], cylinder, 0.25)
        body.ID = 'pillar'
        body.body_length = body.calc_body_length()
        body.prescribed_velocity = np.zeros(6)
        bodies.append(body)
    physics = dict(g=1.0, repulsion_strength_wall=1.0, debye_length_wall=1.0, repulsion_strength=1.0,
                   debye_length=1.0, periodic_length=np.zeros(3), blob_radius=0.25, blob_mass=1.0)
    model = Model(bodies, bodies_to_arrays(bodies), user_hooks.load_user_hooks('/nonexistent'), physics, 1.0, 0.25,
                  1e-8, vector_product_name='C++', blobs_name='C++', preconditioner='auto')
    configuration = model.start_configuration
    pc = model.build_preconditioner(configuration)
    assert pc.pairs.size == 0 and pc.obstacles is not None
    problem = model.mobility_problem(configuration)
    # a shear flow past the pillars: blob velocities -(z, 0, 0) relative to the still pillars
    r = model.arrays.blob_positions(configuration)
    slip = np.zeros_like(r)
    slip[:, 0] = r[:, 2]
    rhs = problem.rhs(slip=slip)
    mixed_matrix = matrix_of(problem.matvec, problem.size)  # the obstacle problem's own operator
    exact = np.linalg.solve(mixed_matrix, problem.prepare_rhs(rhs.copy()))
    coarse = body_solver.solve(problem, rhs, pc)
    block = body_solver.solve(problem, rhs, model.replace(preconditioner='block_diagonal').build_preconditioner(
        configuration))
    n3 = 3 * model.num_blobs
    assert np.abs(coarse.constraint_force_torque.reshape(-1) - exact[n3:]).max() < 1e-6 * np.abs(exact[n3:]).max()
    assert np.abs(coarse.lambda_blobs.reshape(-1) - exact[:n3]).max() < 1e-6 * np.abs(exact[:n3]).max()
    assert coarse.iterations < block.iterations, (coarse.iterations, block.iterations)


@pytest.mark.parametrize('preconditioner', ['block_diagonal', 'auto'])
def test_obstacles_that_stay_put_are_factored_once_to_the_same_numbers(preconditioner, monkeypatch):
    """The model keeps the last build's blocks of its bodies of prescribed motion (keyed by their exact
    positions): a build after the free bodies moved computes the free bodies' blocks only, and its factors,
    Cholesky factors (Lanczos) and applications equal those of a fresh model's build bit for bit; an obstacle
    that moved is computed again, and the memo holds no more than one build's obstacles."""
    model = boomerang_model(grid(9, 3.0), seed=4, preconditioner=preconditioner)
    bodies = model.bodies
    for body in bodies[::2]:
        body.prescribed_velocity = np.zeros(6)
    model = Model(bodies, bodies_to_arrays(bodies), model.hooks, model.physics, 1.0, 0.25, 1e-8,
                  vector_product_name='C++', blobs_name='C++', preconditioner=preconditioner)
    stacks = []
    saddle_blocks = body_solver._saddle_blocks

    def counted(r_type, *args):
        stacks.append(r_type.shape[0])
        return saddle_blocks(r_type, *args)
    monkeypatch.setattr(body_solver, '_saddle_blocks', counted)
    start = model.start_configuration
    model.build_preconditioner(start)
    assert stacks == [9]
    locations = start.locations.copy()
    locations[1::2] += [0.05, -0.02, 0.03]  # the free bodies move
    moved = Configuration(locations, start.orientations)
    stacks.clear()
    again = model.build_preconditioner(moved)
    assert stacks == [4]  # the 5 obstacles are taken from the memo
    fresh = model.replace().build_preconditioner(moved)
    x = np.random.default_rng(0).normal(size=again.operator.shape[0])
    np.testing.assert_array_equal(again.apply(x), fresh.apply(x))
    for ours, theirs in zip(again.cholesky_factors, fresh.cholesky_factors):
        np.testing.assert_array_equal(ours, theirs)
    locations = moved.locations.copy()
    locations[0] += [0.1, 0.0, 0.0]  # an obstacle moves (a prescribed velocity)
    stacks.clear()
    model.build_preconditioner(Configuration(locations, start.orientations))
    assert stacks == [5]
    assert len(model._obstacle_memo['blocks']) == 5
