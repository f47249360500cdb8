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
