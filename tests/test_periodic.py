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


def test_matrix_from_products_is_the_symmetric_part_of_the_products():
    """``matrix_from_products`` of the spectral backend: (M + M^T)/2 of its own products (in TP M itself, to
    round-off); per-body stacks are refused in one line, and ``dense_matrix`` (blocks backends) too."""
    for kind in ('triply_periodic', 'doubly_periodic_wall'):
        mobility = spectral(kind)
        r = blobs(3, 4)
        M = matrix_of(mobility, r)
        assert np.allclose(mobility.matrix_from_products(r), 0.5 * (M + M.T), rtol=0, atol=1e-14 * np.abs(M).max())
    with pytest.raises(UserInputError, match='per-body dense blocks'):
        mobility.matrix_from_products(r[None])
    with pytest.raises(UserInputError, match='builds no dense matrices'):
        mobility.dense_matrix(r)
