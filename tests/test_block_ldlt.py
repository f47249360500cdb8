"""The sparse block LDL^T of the lubrication preconditioners (``lubrication._block_ldlt_cpp`` through
``lubrication.sparse_factor``) and its SuperLU fallback.

Laws: solves of random symmetric positive definite block matrices with the lubrication sparsity (each sphere's
block row holds its neighbours within a cutoff) equal dense ``numpy.linalg.solve`` to 1e-12 relative, for 3 x 3
and 6 x 6 blocks; ``A[perm][:, perm] = L D L^T`` with L unit lower triangular; a refactorisation with new values on
the same pattern, or on another scalar pattern of the same blocks, solves the new matrix (and equals a
factorisation ordered anew bit for bit: the ordering is a function of the block graph); the
signs of the pivots count the matrix's negative eigenvalues (Sylvester's law of inertia: the indefinite flag);
a chain of blocks factors without fill (minimum degree eliminates an end first); a zero pivot and a non-finite
entry are refused; the actual lubrication matrices ``R_sup + s I`` and ``Delta_R_tt + 6 pi eta a I`` of the
scenes of ``test_lubrication.py`` solve as SuperLU solves them; without the extension the package imports and
factors with SuperLU.
"""
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

from lubrication import assembly, integrators, problem as lubrication_problem, sparse_factor
from test_lubrication import lattice_near_wall, scenes

REPO = Path(__file__).resolve().parents[1]
needs_extension = pytest.mark.skipif(not sparse_factor.available(),
                                     reason='lubrication._block_ldlt_cpp is not built (python3 setup.py build_ext '
                                            '--inplace)')


def lubrication_pattern(num_blocks, seed, cutoff=2.6):
    """The block graph (num_blocks, num_blocks) bool of random sphere centres in a slab: blocks i, j coupled when
    the centres are within ``cutoff`` (the lubrication matrices' sparsity)."""
    rng = np.random.default_rng(seed)
    side = np.sqrt(num_blocks) * 2.0
    centres = np.column_stack((rng.uniform(0, side, (num_blocks, 2)), rng.uniform(1.0, 1.5, num_blocks)))
    distance = np.linalg.norm(centres[:, None, :] - centres[None, :, :], axis=2)
    return distance < cutoff


def random_spd(num_blocks, block, seed, indefinite_shift=None):
    """A sparse symmetric (n, n) matrix of ``block`` x ``block`` blocks on :func:`lubrication_pattern`, positive
    definite (diagonally dominant) or, with ``indefinite_shift``, that minus ``indefinite_shift`` I."""
    rng = np.random.default_rng(seed + 100)
    graph = lubrication_pattern(num_blocks, seed)
    pattern = sp.kron(sp.csr_matrix(graph.astype(float)), np.ones((block, block)), format='csr')
    values = pattern.copy()
    values.data = rng.standard_normal(values.nnz)
    values = values + values.T
    dominance = np.asarray(abs(values).sum(axis=1)).ravel() + 1.0
    A = (values + sp.diags(dominance)).tocsr()
    if indefinite_shift is not None:
        A = (A - indefinite_shift * sp.identity(A.shape[0])).tocsr()
    A.sort_indices()
    return A


def relative(x, expected):
    return np.max(np.abs(x - expected)) / np.max(np.abs(expected))


@needs_extension
@pytest.mark.parametrize('block', [3, 6])
@pytest.mark.parametrize('num_blocks', [1, 7, 60])
def test_solves_equal_the_dense_solve(block, num_blocks):
    """(A + s I) x = b for b (n,) and (n, 3), to 1e-12 relative of numpy.linalg.solve; L D L^T rebuilds A."""
    A = random_spd(num_blocks, block, seed=num_blocks)
    shift = 0.37
    dense = A.toarray() + shift * np.eye(A.shape[0])
    factor = sparse_factor.factorise(A, shift, block=block, method='block_ldlt')
    assert factor.positive_definite and factor.size == A.shape[0]
    b = np.random.default_rng(1).standard_normal((A.shape[0], 3))
    assert relative(factor.solve(b), np.linalg.solve(dense, b)) < 1e-12
    assert relative(factor.solve(b[:, 0]), np.linalg.solve(dense, b[:, 0])) < 1e-12
    perm, L, d = factor.factors()
    assert np.array_equal(np.sort(perm), np.arange(A.shape[0]))
    assert sp.triu(L, 1).nnz == 0 and np.all(L.diagonal() == 1.0) and np.all(d > 0)
    assert relative((L @ sp.diags(d) @ L.T).toarray(), dense[perm][:, perm]) < 1e-13


@needs_extension
@pytest.mark.parametrize('block', [3, 6])
def test_refactor_on_new_values_with_the_same_pattern(block):
    """New values on the same pattern: the refactored factor solves the new matrix to 1e-12 and equals a fresh
    factorisation bit for bit (the kept ordering is the one the pattern gives); the old values no longer solve."""
    A = random_spd(40, block, seed=3)
    factor = sparse_factor.factorise(A, 0.1, block=block, method='block_ldlt')
    B = A.copy()
    B.data = B.data * np.random.default_rng(4).uniform(0.5, 1.5, B.nnz)
    B = (0.5 * (B + B.T)).tocsr()
    B.sort_indices()
    assert np.array_equal(B.indptr, A.indptr) and np.array_equal(B.indices, A.indices)
    b = np.random.default_rng(5).standard_normal(A.shape[0])
    expected = np.linalg.solve(B.toarray() + 0.2 * np.eye(A.shape[0]), b)
    factor.refactor(B, 0.2)
    sparse_factor.forget_orderings()  # the next factorisation orders its pattern anew
    fresh = sparse_factor.factorise(B, 0.2, block=block, method='block_ldlt')
    assert relative(factor.solve(b), expected) < 1e-12
    assert np.array_equal(factor.solve(b), fresh.solve(b))
    assert relative(np.linalg.solve(A.toarray() + 0.1 * np.eye(A.shape[0]), b), expected) > 1e-3
    # a factor given as `previous` to another matrix of the same pattern
    other = sparse_factor.factorise(A, 0.1, block=block, method='block_ldlt', previous=fresh)
    assert relative(other.solve(b), np.linalg.solve(A.toarray() + 0.1 * np.eye(A.shape[0]), b)) < 1e-12


@needs_extension
@pytest.mark.parametrize('block', [3, 6])
def test_the_ordering_is_reused_on_another_scalar_pattern_of_the_same_blocks(block):
    """Exact zeros that come and go inside the blocks (the assembly leaves them out) keep the block graph: the
    factor of the new pattern reuses the old ordering and equals a factorisation ordered anew bit for bit; a
    pattern with a block pair fewer is ordered anew and solved; the kept orderings never change an answer."""
    A = random_spd(30, block, seed=6)
    first = sparse_factor.factorise(A, 0.3, block=block, method='block_ldlt')
    B = A.tolil()
    rows, cols = A.nonzero()
    inside = [(r, c) for r, c in zip(rows, cols) if r // block != c // block and (r + c) % 3 == 0]
    for r, c in inside:  # symmetric zeros inside off-diagonal blocks (no block loses every entry: (r + c) % 3)
        B[r, c] = B[c, r] = 0.0
    B = B.tocsr()
    B.eliminate_zeros()
    assert B.nnz < A.nnz
    b = np.random.default_rng(7).standard_normal(A.shape[0])
    reused = sparse_factor.factorise(B, 0.3, block=block, method='block_ldlt', previous=first)
    sparse_factor.forget_orderings()
    fresh = sparse_factor.factorise(B, 0.3, block=block, method='block_ldlt')
    assert reused.ordering_reused and not fresh.ordering_reused
    kept = sparse_factor.factorise(A, 0.3, block=block, method='block_ldlt')  # the kept ordering of `fresh`
    assert kept.ordering_reused and np.array_equal(kept.solve(b), first.solve(b))
    assert np.array_equal(reused.factors()[0], fresh.factors()[0])
    assert np.array_equal(reused.solve(b), fresh.solve(b))
    assert relative(reused.solve(b), np.linalg.solve(B.toarray() + 0.3 * np.eye(B.shape[0]), b)) < 1e-12
    # a block pair fewer: another block graph
    pair = [(i, j) for i, j in zip(*lubrication_pattern(30, 6).nonzero()) if i < j][0]
    C = B.tolil()
    C[pair[0] * block:(pair[0] + 1) * block, pair[1] * block:(pair[1] + 1) * block] = 0.0
    C[pair[1] * block:(pair[1] + 1) * block, pair[0] * block:(pair[0] + 1) * block] = 0.0
    C = C.tocsr()
    C.eliminate_zeros()
    other = sparse_factor.factorise(C, 0.3, block=block, method='block_ldlt', previous=first)
    assert not other.ordering_reused
    assert relative(other.solve(b), np.linalg.solve(C.toarray() + 0.3 * np.eye(C.shape[0]), b)) < 1e-12


@needs_extension
@pytest.mark.parametrize('block', [3, 6])
def test_pivot_signs_count_the_negative_eigenvalues(block):
    """Sylvester's law of inertia: the negative pivots of L D L^T are the negative eigenvalues of A; an
    indefinite matrix is flagged (positive_definite False) and still solved (no pivoting needed here)."""
    A = random_spd(20, block, seed=8)
    eigenvalues = np.linalg.eigvalsh(A.toarray())
    middle = 0.5 * (eigenvalues[len(eigenvalues) // 2] + eigenvalues[len(eigenvalues) // 2 + 1])
    indefinite = (A - middle * sp.identity(A.shape[0])).tocsr()
    factor = sparse_factor.factorise(indefinite, block=block, method='block_ldlt')
    _, _, d = factor.factors()
    assert not factor.positive_definite
    assert np.sum(d < 0) == np.sum(eigenvalues < middle) > 0
    b = np.random.default_rng(2).standard_normal(A.shape[0])
    x = factor.solve(b)
    assert np.linalg.norm(indefinite @ x - b) < 1e-9 * np.linalg.norm(b)
    assert sparse_factor.factorise(A, block=block, method='block_ldlt').positive_definite


@needs_extension
def test_a_chain_of_blocks_factors_without_fill():
    """Minimum degree on a path graph eliminates from the ends: L has exactly the blocks of A's lower triangle
    (nonzero_blocks = diagonal + edges), where the natural order of a path reversed into a star would fill."""
    num_blocks, block = 30, 6
    graph = np.eye(num_blocks, k=1) + np.eye(num_blocks, k=-1)
    order = np.random.default_rng(0).permutation(num_blocks)  # the chain's blocks in a random numbering
    graph = graph[order][:, order]
    pattern = sp.kron(sp.csr_matrix(graph), np.ones((block, block)), format='csr')
    pattern.data = np.random.default_rng(1).standard_normal(pattern.nnz)
    A = pattern + pattern.T
    A = (A + sp.diags(np.asarray(abs(A).sum(axis=1)).ravel() + 1.0)).tocsr()
    factor = sparse_factor.factorise(A, block=block, method='block_ldlt')
    assert factor.nonzero_blocks == num_blocks + (num_blocks - 1)
    b = np.ones(A.shape[0])
    assert relative(factor.solve(b), np.linalg.solve(A.toarray(), b)) < 1e-12


@needs_extension
@pytest.mark.parametrize('block', [3, 6])
def test_zero_pivot_and_non_finite_entries_are_refused(block):
    """A singular matrix whose elimination meets an exact zero pivot, and a NaN or inf entry: FactorisationError
    (a ValueError) naming the row or the entry; no factor, never a silently wrong solve."""
    A = random_spd(10, block, seed=2).tolil()
    A[4 * block + 1, :] = 0.0
    A[:, 4 * block + 1] = 0.0
    with pytest.raises(sparse_factor.FactorisationError, match='zero or non-finite pivot at row %d' % (4 * block + 1)):
        sparse_factor.factorise(A.tocsr(), block=block, method='block_ldlt')
    for bad in (np.nan, np.inf):
        B = random_spd(10, block, seed=2)
        B.data[7] = bad
        with pytest.raises(sparse_factor.FactorisationError, match='non-finite entry'):
            sparse_factor.factorise(B, block=block, method='block_ldlt')
    with pytest.raises(ValueError, match='3 x 3 blocks'):
        sparse_factor.factorise(sp.identity(10, format='csr'), block=3)


def lubrication_matrices():
    """(name, R_sup + s I, Delta_R_tt + 6 pi eta a I) of the scenes of test_lubrication.py and a 144-sphere lattice
    at gaps of 1e-3 a (the shift: the published 6 pi eta a * 1e-8 for a tight tolerance)."""
    out = []
    eta = 0.7
    for name, locations, a, wall, periodic_length in scenes() + [
            ('close lattice', lattice_near_wall(12, spacing=2.002, height=1.001, jitter=0.0005), 1.0, True,
             (0.0, 0.0, 0.0))]:
        matrices = assembly.resistance_matrices(locations, a, eta, periodic_length=periodic_length, wall=wall)
        shift = 6.0 * np.pi * eta * a * 1e-8
        out.append((name, matrices, shift, eta, a))
    return out


@needs_extension
@pytest.mark.parametrize('name, matrices, shift, eta, a', lubrication_matrices(),
                         ids=[entry[0] for entry in lubrication_matrices()])
def test_lubrication_matrices_solve_as_superlu_solves_them(name, matrices, shift, eta, a):
    """R_sup + s I (6 x 6 blocks) and Delta_R_tt + 6 pi eta a I (3 x 3): the block LDL^T and SuperLU solves
    agree to 1e-10 relative and both leave residuals below 1e-13 of |A| |x|; both matrices are positive
    definite; the preconditioners built on either give the same products to 1e-10."""
    size = matrices.R_sup.shape[0]
    trans = (np.arange(size // 6)[:, None] * 6 + np.arange(3)).reshape(-1)
    friction = 6.0 * np.pi * eta * a
    cases = [(matrices.R_sup, shift, 6), (matrices.Delta_R.tocsr()[trans][:, trans], friction, 3)]
    rng = np.random.default_rng(6)
    for A, s, block in cases:
        shifted = (A + s * sp.identity(A.shape[0])).tocsr()
        b = rng.standard_normal(A.shape[0])
        ldlt = sparse_factor.factorise(A, s, block=block, method='block_ldlt')
        superlu = sparse_factor.factorise(A, s, block=block, method='superlu')
        assert ldlt.positive_definite and superlu.positive_definite
        x, y = ldlt.solve(b), superlu.solve(b)
        assert relative(x, y) < 1e-10
        scale = abs(shifted).max()
        for solution in (x, y):
            assert np.max(np.abs(shifted @ solution - b)) < 1e-13 * scale * np.max(np.abs(solution))
    previous = sparse_factor.use_method('superlu')
    try:
        by_superlu = (lubrication_problem.LubricationPreconditioner(matrices, shift),
                      integrators.torque_preconditioner(matrices.Delta_R, eta, a))
    finally:
        sparse_factor.use_method(previous)
    by_ldlt = (lubrication_problem.LubricationPreconditioner(matrices, shift),
               integrators.torque_preconditioner(matrices.Delta_R, eta, a))
    assert by_ldlt[0].factor.method == sparse_factor.default_method() == 'block_ldlt'
    x = rng.standard_normal(size)
    for new, old in zip(by_ldlt, by_superlu):
        assert relative(new.apply(x), old.apply(x)) < 1e-10


@needs_extension
def test_a_moved_configuration_reuses_the_ordering():
    """A lattice moved by up to 1e-4 a keeps its neighbour pairs while exact zeros of R_sup come and go: the
    preconditioner at the moved configuration takes the ordering of the last one (no new ordering), its products
    equal those of a preconditioner ordered anew bit for bit; the torque problem's likewise."""
    locations = lattice_near_wall(6, spacing=2.3, height=1.2, jitter=0.1, seed=3)
    moved = locations + 1e-4 * np.random.default_rng(4).uniform(-1, 1, locations.shape)
    before, after = (assembly.resistance_matrices(where, 1.0, 1.0) for where in (locations, moved))
    assert np.array_equal(before.neighbours.pairs, after.neighbours.pairs)
    assert not np.array_equal(before.R_sup.indices, after.R_sup.indices) or before.R_sup.nnz != after.R_sup.nnz
    x = np.random.default_rng(5).standard_normal(before.R_sup.shape[0])
    lubrication_problem.LubricationPreconditioner(before, 1e-6)
    kept = lubrication_problem.LubricationPreconditioner(after, 1e-6)
    torques_kept = integrators.torque_preconditioner(after.Delta_R, 1.0, 1.0)
    sparse_factor.forget_orderings()
    anew = lubrication_problem.LubricationPreconditioner(after, 1e-6)
    torques_anew = integrators.torque_preconditioner(after.Delta_R, 1.0, 1.0)
    assert kept.factor.ordering_reused and not anew.factor.ordering_reused
    assert np.array_equal(kept.apply(x), anew.apply(x))
    assert np.array_equal(torques_kept.apply(x), torques_anew.apply(x))


def test_superlu_solves_the_same_matrices():
    """The fallback on its own (no extension needed): 6 x 6 and 3 x 3 block matrices to 1e-12 of the dense solve,
    the indefinite flag, and the zero pivot refused."""
    for block in (3, 6):
        A = random_spd(15, block, seed=4)
        factor = sparse_factor.factorise(A, 0.2, block=block, method='superlu')
        b = np.random.default_rng(3).standard_normal(A.shape[0])
        assert factor.positive_definite
        assert relative(factor.solve(b), np.linalg.solve(A.toarray() + 0.2 * np.eye(A.shape[0]), b)) < 1e-12
        eigenvalues = np.linalg.eigvalsh(A.toarray())
        assert not sparse_factor.factorise(A, -np.median(eigenvalues), block=block,
                                           method='superlu').positive_definite
    singular = sp.csr_matrix(np.diag([1.0, 2.0, 0.0, 4.0, 5.0, 6.0]))
    with pytest.raises(sparse_factor.FactorisationError, match='zero or non-finite pivot'):
        sparse_factor.factorise(singular, block=6, method='superlu')
    with pytest.raises(ValueError, match='not one of'):
        sparse_factor.factorise(singular, block=6, method='cholmod')


def test_the_package_imports_and_factors_without_the_extension():
    """With lubrication._block_ldlt_cpp unimportable the package imports, SuperLU is the default and a
    lubrication preconditioner is built and applied."""
    code = '\n'.join([
        'import sys',
        "sys.modules['lubrication._block_ldlt_cpp'] = None  # an import of it raises ImportError",
        'import numpy as np',
        'from lubrication import assembly, sparse_factor',
        'from lubrication.problem import LubricationPreconditioner',
        "assert not sparse_factor.available() and sparse_factor.default_method() == 'superlu'",
        'locations = np.array([[0.0, 0.0, 1.1], [2.05, 0.0, 1.1], [4.1, 0.2, 1.2]])',
        'matrices = assembly.resistance_matrices(locations, 1.0, 1.0)',
        'preconditioner = LubricationPreconditioner(matrices, 1e-6)',
        "assert preconditioner.factor.method == 'superlu'",
        'print(np.all(np.isfinite(preconditioner.apply(np.ones(18)))))',
    ])
    result = subprocess.run([sys.executable, '-c', code], cwd=str(REPO), capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == 'True'
