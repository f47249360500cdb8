"""The two-level preconditioner of the phoretic concentration problem (multi_bodies/solver/laplace_preconditioner.py).

Its pieces are checked against the dense matrix of the problem's own product (``LaplaceProblem.matvec``, itself
checked against the published runs in test_phoretic.py), its effect against the dense solution."""
import numpy as np
import pytest

from body.geometry import rotation_matrices
from multi_bodies.files.structure_generators import icosahedral_shell
from multi_bodies.solver import laplace_preconditioner as lp
from multi_bodies.solver.krylov import gmres
from multi_bodies.solver.phoretic import LaplaceProblem


def janus_scene(num_bodies, blobs, spacing, wall=True, seed=0, diffusion=1.0, extra_bodies=()):
    """(LaplaceProblem, blob offsets): unit Janus shells (reacting and emitting on their upper halves in the body
    frame) on a square grid of ``spacing`` at heights in [1.3, 3], random orientations; ``extra_bodies``: more
    bodies given as (blob positions (n, 3), unit normals (n, 3)) in the lab frame."""
    rng = np.random.default_rng(seed)
    reference = icosahedral_shell(blobs)
    reference = reference / np.linalg.norm(reference, axis=1)[:, None]
    side = int(np.ceil(np.sqrt(num_bodies)))
    xs, ns, janus = [], [], []
    for b in range(num_bodies):
        q = rng.normal(size=4)
        R = rotation_matrices((q / np.linalg.norm(q))[None])[0]
        centre = np.array([spacing * (b % side), spacing * (b // side), rng.uniform(1.3, 3.0)])
        xs.append(centre + reference @ R.T)
        ns.append(reference @ R.T)
        janus.append(reference[:, 2] > 0)
    for x, n in extra_bodies:
        xs.append(x)
        ns.append(n)
        janus.append(np.ones(len(x), dtype=bool))
    x, n, janus = np.concatenate(xs), np.concatenate(ns), np.concatenate(janus).astype(float)
    weights = np.full(len(x), 4 * np.pi / blobs)
    offsets = np.concatenate(([0], np.cumsum([len(b) for b in xs])))
    return LaplaceProblem(x, n, 1.5 * janus, janus, weights, diffusion, [1.0, 0.1, 0.0, 0.0], wall), offsets


def dense(problem):
    """The problem's matrix (N, N), column by column from its own product."""
    return np.column_stack([problem.matvec(e) for e in np.eye(problem.size)])


def placed_modes(Z, offsets):
    """Z (N, m) of every body placed in its own columns: (N, B m)."""
    m = Z.shape[1]
    out = np.zeros((Z.shape[0], (len(offsets) - 1) * m))
    for b in range(len(offsets) - 1):
        out[offsets[b]:offsets[b + 1], b * m:(b + 1) * m] = Z[offsets[b]:offsets[b + 1]]
    return out


@pytest.mark.parametrize('wall', [True, False])
@pytest.mark.parametrize('backend', ['C++', 'python'])
def test_blocks_and_coarse_matrix_are_those_of_the_dense_problem(wall, backend):
    """The inverted blocks are the inverses of the diagonal blocks of A, and A Z its product with the modes, for
    bodies of different sizes; a body of one blob has only the constant mode, one of two blobs no third."""
    if backend == 'C++' and lp._surface_cpp is None:
        pytest.skip('the C++ surface kernels are not built')
    single = (np.array([[5.0, 0.5, 2.0]]), np.array([[0.0, 0.0, 1.0]]))
    pair = (np.array([[0.0, 5.0, 2.0], [0.0, 5.6, 2.0]]), np.array([[0.0, -1.0, 0.0], [0.0, 1.0, 0.0]]))
    problem, offsets = janus_scene(3, 42, 2.6, wall=wall, diffusion=0.7, extra_bodies=(single, pair))
    A = dense(problem)
    pc = lp.LaplacePreconditioner(problem, offsets, backend=backend)
    assert pc.modes_per_body == 4
    for bodies, inverses in pc.inverses:
        for b, inverse in zip(bodies, inverses):
            rows = slice(offsets[b], offsets[b + 1])
            np.testing.assert_allclose(inverse @ A[rows, rows], np.eye(inverse.shape[0]), atol=1e-12)
    Z, active, AZ, _, _ = pc.coarse
    np.testing.assert_array_equal(active.sum(axis=1), [4, 4, 4, 1, 2])
    used = placed_modes(Z, offsets)[:, active.reshape(-1)]
    np.testing.assert_allclose(used.T @ used, np.eye(used.shape[1]), atol=1e-12)  # orthonormal
    np.testing.assert_allclose(AZ, A @ used, atol=1e-13 * np.abs(A).max())


def test_one_body_is_solved_in_one_iteration_and_the_images_are_needed():
    """One Janus sphere near the wall: its block is the whole matrix, so one GMRES iteration; blocks built without
    the wall's images (the negative control) need more."""
    problem, offsets = janus_scene(1, 162, 0.0)
    b = problem.rhs() / np.linalg.norm(problem.rhs())
    exact = np.linalg.solve(dense(problem), b)
    x, info, iterations, _ = gmres(problem.matvec, b, 1e-10, psolve=lp.LaplacePreconditioner(problem, offsets).apply)
    assert info == 0 and iterations == 1
    assert np.linalg.norm(x - exact) < 1e-9 * np.linalg.norm(exact)
    problem.wall = False
    no_images = lp.LaplacePreconditioner(problem, offsets)
    problem.wall = True
    _, info, iterations, _ = gmres(problem.matvec, b, 1e-10, psolve=no_images.apply)
    assert info == 0 and iterations >= 3


def test_suspension_converges_to_the_dense_solution_in_half_the_iterations():
    """12 Janus spheres 2.6 radii apart above the wall, tolerance 1e-10: GMRES reaches the dense solution in at most
    half the unpreconditioned iterations (measured 18 -> 7), and the coarse modes do better than the blocks alone
    (measured 13) and the constant modes alone (9)."""
    problem, offsets = janus_scene(12, 42, 2.6)
    b = problem.rhs() / np.linalg.norm(problem.rhs())
    A = dense(problem)
    exact = np.linalg.solve(A, b)
    _, info, plain, _ = gmres(problem.matvec, b, 1e-10, restart=200)
    assert info == 0
    counts = {}
    for modes in (0, 1, 4):
        pc = lp.LaplacePreconditioner(problem, offsets, modes_per_body=modes)
        x, info, counts[modes], _ = gmres(problem.matvec, b, 1e-10, psolve=pc.apply, restart=200)
        assert info == 0
        assert np.linalg.norm(A @ x - b) <= 1e-10 * 1.01
        assert np.linalg.norm(x - exact) < 1e-8 * np.linalg.norm(exact)
    assert 2 * counts[4] <= plain, (plain, counts)
    assert counts[4] < counts[1] < counts[0] < plain, (plain, counts)


def test_too_many_coarse_numbers_drop_the_linear_modes_then_the_coarse_space():
    problem, offsets = janus_scene(4, 42, 2.6)
    N, B = problem.size, 4
    assert lp.LaplacePreconditioner(problem, offsets, max_coarse_entries=4 * N * B).modes_per_body == 4
    assert lp.LaplacePreconditioner(problem, offsets, max_coarse_entries=4 * N * B - 1).modes_per_body == 1
    pc = lp.LaplacePreconditioner(problem, offsets, max_coarse_entries=N * B - 1)
    assert pc.modes_per_body == 0 and pc.coarse is None
    with pytest.raises(ValueError, match='blob_offsets'):
        lp.LaplacePreconditioner(problem, offsets[:-1])


def test_the_published_preconditioner_keeps_the_published_unpreconditioned_solve(tmp_path, monkeypatch):
    """``preconditioner block_diagonal`` gives the concentration solve no preconditioner (as published);
    ``neighbours`` gives it this one, which needs fewer iterations for the same concentrations; ``auto`` gives
    it this one from AUTO_MIN_BLOBS blobs on (here 126 blobs: none, then the threshold lowered: this one)."""
    from multi_bodies.solver import surface as surface_module
    from multi_bodies.solver.model import Model
    from multi_bodies.solver.solves import Solver
    seen = []
    original = Solver.solve

    def spy(self, problem, rhs, preconditioner, **kwargs):
        seen.append(preconditioner)
        return original(self, problem, rhs, preconditioner, **kwargs)
    monkeypatch.setattr(Solver, 'solve', spy)
    problem, offsets = janus_scene(3, 42, 2.6)

    class Arrays:
        blob_offsets = offsets

    class FakeModel:  # what Surface.solve_concentrations reads of a Model
        arrays = Arrays()
        solver = Model.solver
        tolerance, print_residual = 1e-10, False
        lanczos_max_iterations = 1000  # read by Solver.of_model; the concentration solve draws no noise

        def __init__(self, preconditioner):
            self.preconditioner = preconditioner
            self.published_solves = preconditioner == 'block_diagonal'  # read by Model.solver
    surface = surface_module.Surface()
    monkeypatch.setattr(surface, 'laplace_problem', lambda model, configuration: problem)
    _, published = surface.solve_concentrations(FakeModel('block_diagonal'), None)
    _, ours = surface.solve_concentrations(FakeModel('neighbours'), None)
    assert seen[0] is None and isinstance(seen[1], lp.LaplacePreconditioner)
    surface.solve_concentrations(FakeModel('auto'), None)
    monkeypatch.setattr(lp, 'AUTO_MIN_BLOBS', problem.size)
    surface.solve_concentrations(FakeModel('auto'), None)
    assert seen[2] is None and isinstance(seen[3], lp.LaplacePreconditioner)
    assert ours.iterations < published.iterations
    c, c_published = ours.constraint_force_torque, published.constraint_force_torque
    assert np.linalg.norm(c - c_published) < 1e-8 * np.linalg.norm(c_published)
