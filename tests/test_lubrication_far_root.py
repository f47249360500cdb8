"""The far-field Lanczos root of the lubrication noise, preconditioned by each sphere's wall self-mobility
(``lubrication.brownian.far_field_root``, issue 46): a root of the far-field M (R R^T = M, the law that keeps
the noise's distribution), with a negative control that breaks it; the self-mobility blocks equal the far
field's own single-sphere mobility; fewer products where the spheres' heights differ."""
import numpy as np
import pytest

from lubrication import LubricationProblem
from lubrication.brownian import BlockRoot, far_field_root, wall_self_mobility_blocks
from lubrication.problem import dense_far_field_mobility
from stochastic_forcing import lanczos_square_root

A, ETA = 1.0, 1.0
SPHERES = np.array([[0.0, 0.0, 1.05], [2.3, 0.1, 1.6], [0.4, 2.4, 3.0]])


def root_matrix(problem, root):
    """The columns root(e_k) (6N, 6N) of a root computed to convergence (linear in W then)."""
    return np.column_stack([root(column) for column in np.eye(problem.size)])


@pytest.mark.parametrize('wall', [True, False])
def test_preconditioned_root_is_a_root_of_the_far_field_mobility(wall):
    problem = LubricationProblem(SPHERES, A, ETA, wall=wall)
    M = dense_far_field_mobility(problem)
    R = root_matrix(problem, lambda W: far_field_root(problem, W, 1e-14, factor=1.0).noise)
    np.testing.assert_allclose(R @ R.T, M, rtol=0, atol=1e-9 * np.abs(M).max())
    assert np.abs(R - R.T).max() > 1e-3 * np.abs(R).max()  # not the symmetric root M^1/2: another root of M
    # Negative control: L applied to the root of M itself (matvec not preconditioned) is not a root of M.
    block = BlockRoot(problem.locations, A, ETA, wall)
    wrong = root_matrix(problem, lambda W: lanczos_square_root(problem.mobility_product, W, 1e-14,
                                                               L_mult=block.apply).noise)
    assert np.abs(wrong @ wrong.T - M).max() > 1e-2 * np.abs(M).max()


@pytest.mark.parametrize('height', [1.0, 1.2, 2.0, 7.5])
def test_self_mobility_blocks_equal_the_far_field_of_one_sphere(height):
    problem = LubricationProblem(np.array([[0.3, -0.2, height]]) * 1.7, 1.7, 0.4)
    np.testing.assert_allclose(wall_self_mobility_blocks([height * 1.7], 1.7, 0.4)[0],
                               dense_far_field_mobility(problem), rtol=1e-12, atol=1e-15)


def test_preconditioned_root_takes_fewer_products_at_spread_heights():
    rng = np.random.default_rng(5)
    x, y = np.meshgrid(np.arange(6) * 2.6, np.arange(6) * 2.6)
    spheres = np.column_stack((x.ravel(), y.ravel(), rng.uniform(1.02, 4.0, 36)))
    problem = LubricationProblem(spheres, A, ETA)
    W = rng.standard_normal(problem.size)
    plain = far_field_root(problem, W, 1e-8, preconditioned=False)
    preconditioned = far_field_root(problem, W, 1e-8)
    assert preconditioned.iterations < plain.iterations


@pytest.mark.parametrize('wall', [True, False])
def test_block_root_is_the_cholesky_factor_of_the_self_mobilities(wall):
    """BlockRoot's closed-form factors: lower triangular C_i with C_i C_i^T the wall self-mobility (the law of a
    Cholesky factor, and LAPACK's factor to rounding), C_i^-1 its inverse, and the three sparse maps apply them."""
    heights = np.array([0.6, 1.0, 1.001, 1.3, 2.0, 4.5, 40.0]) * A  # below a (raised to a), near and far
    locations = np.column_stack((np.arange(heights.size) * 3.0 * A, np.zeros(heights.size), heights))
    blocks = wall_self_mobility_blocks(heights, A, ETA, wall)
    root = BlockRoot(locations, A, ETA, wall)
    scale = np.abs(blocks).max()
    assert np.all(np.triu(root.factor, 1) == 0.0)
    np.testing.assert_allclose(root.factor @ np.swapaxes(root.factor, 1, 2), blocks, rtol=0, atol=1e-14 * scale)
    np.testing.assert_allclose(root.factor, np.linalg.cholesky(blocks), rtol=0,
                               atol=1e-14 * np.abs(root.factor).max())
    np.testing.assert_allclose(root.inverse @ root.factor, np.broadcast_to(np.eye(6), blocks.shape), rtol=0, atol=1e-13)
    x = np.random.default_rng(3).standard_normal((heights.size, 6))
    for apply, matrices in ((root.apply, root.factor), (root.apply_inverse, root.inverse),
                            (root.apply_inverse_transpose, np.swapaxes(root.inverse, 1, 2))):
        expected = np.einsum('nij,nj->ni', matrices, x).reshape(-1)
        np.testing.assert_allclose(apply(x.reshape(-1)), expected, rtol=0, atol=1e-14 * np.abs(expected).max())
    with pytest.raises(ValueError):
        root.apply(np.ones(6 * heights.size + 1))
