"""The truly periodic limit above a wall and the errors of the periodic products (issue 45).

``mobility.image_sums``: ring sums of the pseudo-periodic products with any number of rings, their Richardson
limit, the same limit through tiles of a compiled source-target product; ``refined_parameters`` of the spectral
product.  The numbers asserted come from outside the code under test: the package's own pseudo-periodic
products (one ring), the analytic mean flow of a periodic array of point forces above a wall, the spectral
product (an independent method for the same periodic problem), and laws (first-order convergence in 1/n of
a sum of a 1/rho^3 far field; convergence of the spectral product under grid refinement).
"""
import warnings

import numpy as np
import pytest

from mobility.image_sums import periodic_limit, relative_error, ring_shifts, ring_sums, tiled_velocities
from mobility.interface import Geometry, make_mobility, usable_backends
from mobility.spectral import SpectralStokes, dpstokes_parameters
from mobility.spectral.parameters import refined_parameters


def scene(n=30, L=30.0, seed=1, low=0.7, high=4.0):
    rng = np.random.default_rng(seed)
    r = np.column_stack([rng.uniform(0, L, n), rng.uniform(0, L, n), rng.uniform(low, high, n)])
    return r, rng.standard_normal((n, 3)), rng.standard_normal((n, 3))


def test_ring_shifts_cover_the_square():
    for n in (1, 2, 5):
        shifts = np.concatenate([ring_shifts(k) for k in range(n + 1)])
        assert len(shifts) == (2 * n + 1) ** 2 == len({tuple(s) for s in shifts})
        assert np.max(np.abs(shifts)) == n


@pytest.mark.parametrize('wall', [True, False])
def test_one_ring_is_the_published_pseudo_periodic_product(wall):
    """One ring of images is the package's pseudo-periodic product (the python backend's pair sums), for the
    four couplings, blobs below their radius from the wall included."""
    L = 30.0
    r, F, T = scene(L=L)
    mobility = make_mobility('python', Geometry('single_wall' if wall else 'free_space', (L, L, 0.0)), 0.8, 1.0)
    U, W = ring_sums(r, 0.8, 1.0, (L, L, 0.0), [1], F, T, wall=wall, rotation=True)[1]
    expected_U = mobility.coupling('trans_times_force', r, F) + mobility.coupling('trans_times_torque', r, T)
    expected_W = mobility.coupling('rot_times_force', r, F) + mobility.coupling('rot_times_torque', r, T)
    assert np.max(np.abs(U.ravel() - expected_U)) < 1e-13 * np.max(np.abs(expected_U))
    assert np.max(np.abs(W.ravel() - expected_W)) < 1e-13 * np.max(np.abs(expected_W))


def test_ring_sums_converge_at_first_order_above_the_wall():
    """The images beyond ring n add c/n: the change from n to 2n halves as n doubles."""
    L = 30.0
    r, F, T = scene(L=L)
    sums = ring_sums(r, 1.0, 1.0, (L, L, 0.0), [4, 8, 16, 32], F, T, targets=np.arange(0, 30, 3), rotation=True)
    for index in (0, 1):
        changes = [np.linalg.norm(sums[2 * n][index] - sums[n][index]) for n in (4, 8, 16)]
        for coarse, fine in zip(changes, changes[1:]):
            assert 1.6 < coarse / fine < 2.4
    U, W, estimate = periodic_limit(sums)
    assert estimate < 2e-3
    # the extrapolation is closer to the limit than the sum it starts from
    assert relative_error(sums[32][0], U) > 5 * estimate


@pytest.mark.parametrize('source_height, target_height', [(2.0, 8.0), (6.0, 1.5)])
def test_periodic_limit_gives_the_mean_flow_of_a_periodic_force(source_height, target_height):
    """A periodic array of forces F above a wall drives the mean flow eta u'' = -F delta(z - h) / A with u = 0 at
    the wall and bounded above: u = F min(z, h) / (eta A) along the wall, none across it.  Its average over
    targets on a regular grid at height z (|z - h| > 2a: the blob's Faxen terms average to zero) is that mean
    flow."""
    L, eta = 20.0, 0.7
    grid = (np.arange(16) + 0.5) * L / 16
    X, Y = np.meshgrid(grid, grid)
    targets = np.column_stack([X.ravel(), Y.ravel(), np.full(X.size, target_height)])
    force = np.array([[1.5, -0.4, 0.8]])
    sums = ring_sums([[3.3, 7.1, source_height]], eta, 1.0, (L, L, 0.0), [8, 16, 32], force, targets=targets)
    U, _, estimate = periodic_limit(sums)
    mean = force[0, :2] * min(source_height, target_height) / (eta * L * L)
    assert np.allclose(U.mean(axis=0)[:2], mean, rtol=max(2e-3, 2 * estimate), atol=0)
    assert abs(U.mean(axis=0)[2]) < 1e-4 * np.linalg.norm(mean)
    # one ring misses a large part of it
    assert relative_error(sums[8][0].mean(axis=0)[:2], mean) > 0.02


def test_tiles_and_rings_reach_the_same_limit():
    """Whole tiles of the box through the compiled source-target product and rings about each target's minimum
    image differ at each n but share the limit."""
    L = 40.0
    r, F, _ = scene(n=200, L=L, seed=4, low=0.5, high=3.0)
    targets = np.arange(0, 200, 10)
    backend = 'C++' if 'C++' in usable_backends(Geometry('single_wall')) else 'python'
    tiles = tiled_velocities(make_mobility(backend, Geometry('single_wall'), 1.0, 1.0), r, F, (L, L, 0.0),
                             [4, 8, 16], targets)
    rings = ring_sums(r, 1.0, 1.0, (L, L, 0.0), [4, 8, 16], F, targets=targets)
    U_tiles, _, e_tiles = periodic_limit(tiles)
    U_rings, _, e_rings = periodic_limit(rings)
    assert relative_error(U_tiles, U_rings) < 2 * max(e_tiles, e_rings)
    assert relative_error(tiles[4][0], rings[4][0]) > 1e-6   # different partial sums


def test_periodic_limit_agrees_with_the_spectral_product():
    """Two methods for one truly periodic problem: two blobs 4 radii apart, 3 and 3.5 above the wall in a 30 x 30
    box.  The refined spectral product (the kernel's own error removed) meets the Richardson limit of the ring
    sums within the difference of the blob models (the exponential-of-semicircle kernel against Rotne-Prager at
    4 radii: about 1e-3); the refinement brings the angular velocities 10 times closer."""
    L = 30.0
    r = np.array([[10.0, 10.0, 3.0], [14.0, 11.0, 3.5]])
    F = np.array([[1.0, 0.3, -0.5], [0.2, -1.0, 0.4]])
    T = np.array([[0.3, 1.0, 0.0], [0.0, -0.5, 1.0]])
    U, W, estimate = periodic_limit(ring_sums(r, 1.0, 1.0, (L, L, 0.0), [16, 32, 64], F, T, rotation=True))
    assert estimate < 1e-4
    errors = {}
    with warnings.catch_warnings():
        warnings.simplefilter('ignore')
        base = dpstokes_parameters(1.0, 'DPBW', L, L, 0.0, 6.0, kernel='w6', has_torque=True)
    for factor in (1, 2):
        stokes = SpectralStokes(refined_parameters(base, factor), 1.0)
        stokes.set_positions(r)
        Us, Ws = stokes.product(F, T)
        errors[factor] = relative_error(Us, U), relative_error(Ws, W)
    assert errors[2][0] < 2e-3 and errors[2][1] < 5e-4
    assert errors[1][1] > 10 * errors[2][1]


def test_refined_grid_converges():
    """The same continuous kernels on grids 1, 2 and 3 times finer: the product converges (the change from 2 to 3
    is at least 10 times smaller than from 1 to 3)."""
    L = 30.0
    r, F, T = scene(n=20, L=L, seed=3, low=1.5, high=4.0)
    with warnings.catch_warnings():
        warnings.simplefilter('ignore')
        base = dpstokes_parameters(1.0, 'DPBW', L, L, 0.0, 6.0, kernel='w6', has_torque=True)
    results = {}
    for factor in (1, 2, 3):
        p = refined_parameters(base, factor)
        assert (p.Nx, p.Ny, p.hx) == (factor * base.Nx, factor * base.Ny, base.hx / factor)
        assert p.monopole.width[0] == factor * base.monopole.width[0] and p.monopole.beta == base.monopole.beta
        stokes = SpectralStokes(p, 1.0)
        stokes.set_positions(r)
        results[factor] = np.concatenate([v.ravel() for v in stokes.product(F, T)])
    assert relative_error(results[2], results[3]) < 0.1 * relative_error(results[1], results[3])


def test_bad_boxes_are_refused():
    with pytest.raises(ValueError, match='Lx Ly 0'):
        ring_sums(np.zeros((1, 3)) + 2, 1.0, 1.0, (10.0, 10.0, 10.0), [1], np.ones((1, 3)))
    with pytest.raises(ValueError, match='>= 1'):
        ring_sums(np.zeros((1, 3)) + 2, 1.0, 1.0, (10.0, 10.0, 0.0), [0], np.ones((1, 3)))
    with pytest.raises(ValueError, match='n/4'):
        periodic_limit({1: (np.ones((1, 3)), None), 3: (np.ones((1, 3)), None)})


def test_the_chart_script_runs_on_a_tiny_scene(tmp_path):
    """doc/charts/periodic_accuracy_vs_cost.py on 48 rollers: its rows obey the laws the chart shows (more rings
    of images, a smaller error; a wider force-only kernel, a smaller error) and it writes the PNG and JSON."""
    import json
    import os
    import subprocess
    import sys
    repo = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    png = str(tmp_path / 'chart.png')
    run = subprocess.run([sys.executable, os.path.join(repo, 'doc', 'charts', 'periodic_accuracy_vs_cost.py'),
                          '--rollers', '48', '--targets', '6', '--reference-rings', '8', '--png', png],
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    assert os.path.getsize(png) > 0
    with open(str(tmp_path / 'chart.json')) as f:
        panels = json.load(f)['panels']
    for rows in (panel['rows'] for panel in panels.values()):
        errors = {label: error for label, error, _, _ in rows}
        assert errors['rings 1'] > errors['rings 2'] > errors['rings 3']
    translation = {label: error for label, error, _, _ in panels['translation from forces (M_UF, rigid bodies)']
                   ['rows']}
    assert translation['spectral w6'] < translation['spectral w5'] < translation['spectral w4']
    assert '| spectral w6 |' in run.stdout
