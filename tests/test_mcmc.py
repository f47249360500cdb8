"""Monte Carlo sampler (many_bodyMCMC): Gibbs-Boltzmann statistics, energies on every backend, outputs, restart.

Numbers asserted come from outside the sampler: quadratures of the exact
density exp(-U/kT) computed here (VALIDATION T1 for one blob; the height
and tilt of a boomerang), the exact acceptance probability of a uniform
proposal in a linear potential, and independent transcriptions of the
potentials of SPEC section 9.  Statistical tolerances are standard errors
from the spread of independent chains (started from exact equilibrium
samples, so there is no burn-in); each statistical test has a negative
control (kT wrong by a factor) that must fail the same check.
"""
import importlib
import os
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from body.body import Body, bodies_to_arrays
from many_bodyMCMC import mcmc_energy as me
from many_bodyMCMC.sampler import MetropolisSampler
from multi_bodies.files import structure_generators as gen
from multi_bodies.multi_bodies_functions import minimum_image
from multi_bodies.files.snapshots import write_clones_file
from multi_bodies.files.structure_files import write_vertex_file
from multi_bodies.run import run_output
from quaternion_integrator.quaternion import rotation_matrices
from utils import UserInputError

SCRIPT = importlib.import_module('many_bodyMCMC.many_body_MCMC')
REPO = Path(__file__).resolve().parents[1]
Z_SCORE_LIMIT = 4.0   # every statistic within 4 standard errors (of independent chains)


# ------------------------------------------------------------------ independent transcriptions of SPEC section 9
def wall_energy(z, g, eps, b, a):
    """Gravity plus soft wall of one blob (SPEC section 9), any array shape."""
    return g * z + np.where(z < a, eps + eps * (a - z) / b, eps * np.exp(-(z - a) / b))


def pair_energy(distance, eps, b, a):
    return np.where(distance < 2 * a, eps + eps * (2 * a - distance) / b, eps * np.exp(-(distance - 2 * a) / b))


def brute_force_energy(r_vectors, locations, keywords, body_body=False):
    """Energy of SPEC section 9 by the definition (all pairs by a double loop in arrays)."""
    k = keywords
    energy = wall_energy(r_vectors[:, 2], k['g'], k['repulsion_strength_wall'], k['debye_length_wall'],
                         k['blob_radius']).sum()
    d = minimum_image(r_vectors[None, :, :] - r_vectors[:, None, :], k['periodic_length'])
    iu = np.triu_indices(len(r_vectors), k=1)
    energy += pair_energy(np.linalg.norm(d, axis=-1)[iu], k['repulsion_strength'], k['debye_length'],
                          k['blob_radius']).sum()
    if body_body:
        d = minimum_image(locations[None, :, :] - locations[:, None, :], k['periodic_length'])
        r = np.linalg.norm(d, axis=-1)[np.triu_indices(len(locations), k=1)]
        energy += (k['repulsion_strength'] * np.exp(-r / k['debye_length']) / r).sum()
    return energy


def keywords(**changes):
    k = dict(g=0.3, repulsion_strength_wall=0.8, debye_length_wall=0.2, repulsion_strength=1.3, debye_length=0.25,
             periodic_length=(0.0, 0.0, 0.0), blob_radius=0.3, blob_mass=1.0)
    k.update(changes)
    return k


def make_energy(reference, locations, orientations, kw, implementation, body_body=False, directory='/nonexistent'):
    """MCMCEnergy of bodies that share one reference configuration (n, 3)."""
    bodies = []
    for location, orientation in zip(locations, orientations):
        body = Body(location, orientation, reference, kw['blob_radius'])
        body.ID = 'body'
        bodies.append(body)
    arrays = bodies_to_arrays(bodies, [len(bodies)])
    hooks = me.load_user_potentials(directory, default_body_body=body_body)
    try:
        pair_sums, _ = me.make_pair_sums(implementation, kw, hooks)
    except UserInputError as err:
        pytest.skip('%s energy cannot run here: %s' % (implementation, err))
    return me.MCMCEnergy(arrays, kw, hooks, pair_sums), arrays


def random_orientations(rng, n):
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1)[:, None]


def crowded_scene(seed, n_bodies=12, periodic=(0.0, 0.0, 0.0)):
    """Rods of 4 blobs, overlapping each other, some blobs closer to the wall than a."""
    rng = np.random.default_rng(seed)
    reference = gen.rod(4, 0.35)
    locations = np.column_stack((rng.uniform(0, 3, n_bodies), rng.uniform(0, 3, n_bodies),
                                 rng.uniform(0.6, 1.6, n_bodies)))
    orientations = random_orientations(rng, n_bodies)
    locations[0, 2], orientations[0] = 0.2, (1.0, 0.0, 0.0, 0.0)     # a lying rod closer to the wall than a
    return reference, locations, orientations


# ------------------------------------------------------------------ energies: backends, one-body changes
@pytest.mark.parametrize('periodic', [(0.0, 0.0, 0.0), (3.1, 2.7, 0.0)])
@pytest.mark.parametrize('implementation', ['python', 'C++', 'pycuda'])
def test_energy_matches_definition_on_every_backend(implementation, periodic):
    """Total energy of overlapping rods (blobs below a, minimum image) equals the SPEC definition to 1e-13."""
    reference, locations, orientations = crowded_scene(1, periodic=periodic)
    kw = keywords(periodic_length=periodic)
    energy, arrays = make_energy(reference, locations, orientations, kw, implementation, body_body=True)
    r = energy.blob_positions(locations, orientations)
    assert np.any(r[:, 2] < kw['blob_radius'])
    expected = brute_force_energy(r, locations, kw, body_body=True)
    assert energy.total(locations, orientations) == pytest.approx(expected, rel=1e-13)


@pytest.mark.parametrize('implementation', ['python', 'C++', 'pycuda'])
def test_pair_energy_at_every_distance(implementation):
    """One blob pair from overlap to 700 Debye lengths apart: the pair energy agrees with numpy to round-off."""
    kw = keywords()
    distances = np.concatenate((np.linspace(0.0, 0.6, 7), 0.6 + 0.25 * np.geomspace(1e-6, 700, 60)))
    energy, _ = make_energy(np.zeros((1, 3)), np.array([[0.0, 0.0, 5.0], [0.0, 0.0, 5.0]]),
                            np.tile([1.0, 0, 0, 0], (2, 1)), kw, implementation)
    ours = np.array([energy.pair_sums.total(np.array([[0.0, 0.0, 5.0], [d, 0.0, 5.0]])) for d in distances])
    exact = pair_energy(distances, kw['repulsion_strength'], kw['debye_length'], kw['blob_radius'])
    # the exponent x = (r - 2a)/b carries a rounding error of about eps*x, which exp turns into a relative one
    x = np.maximum(distances - 2 * kw['blob_radius'], 0.0) / kw['debye_length']
    assert np.all(np.abs(ours - exact) <= 4 * np.finfo(float).eps * (1.0 + x) * exact)


@pytest.mark.parametrize('implementation', ['python', 'C++', 'pycuda'])
def test_one_body_change_equals_full_recomputation(implementation):
    """The O(n_k N) energy change of moving one body equals E(after) - E(before), with body-body terms and a box."""
    periodic = (3.1, 2.7, 0.0)
    reference, locations, orientations = crowded_scene(2, periodic=periodic)
    kw = keywords(periodic_length=periodic)
    energy, _ = make_energy(reference, locations, orientations, kw, implementation, body_body=True)
    rng = np.random.default_rng(3)
    r = energy.blob_positions(locations, orientations)
    before = energy.total(locations, orientations)
    for k in (0, 5, len(locations) - 1):
        location = locations[k] + rng.uniform(-0.2, 0.2, 3)
        orientation = me.quaternion_products(me.quaternions_from_rotations(rng.normal(size=3) * 0.3),
                                             orientations[k])[0]
        delta, new_r = energy.body_change(k, location, orientation, r, locations, orientations)
        moved_l, moved_q = locations.copy(), orientations.copy()
        moved_l[k], moved_q[k] = location, orientation
        np.testing.assert_allclose(new_r, energy.blob_positions(moved_l, moved_q)[4 * k:4 * k + 4], atol=1e-14)
        assert delta == pytest.approx(energy.total(moved_l, moved_q) - before, abs=1e-11 * abs(before))


def test_python_and_cpp_energies_agree_on_a_suspension():
    """100 boomerangs (1,500 blobs, the benchmark scene): python and C++ totals agree to 1e-13."""
    rng = np.random.default_rng(4)
    locations = np.column_stack((rng.uniform(0, 25, 100), rng.uniform(0, 25, 100), rng.uniform(1, 3, 100)))
    orientations = random_orientations(rng, 100)
    kw = keywords()
    python, _ = make_energy(gen.boomerang(), locations, orientations, kw, 'python')
    cpp, _ = make_energy(gen.boomerang(), locations, orientations, kw, 'C++')
    r = python.blob_positions(locations, orientations)
    assert cpp.pair_sums.total(r) == pytest.approx(python.pair_sums.total(r), rel=1e-13)


def test_blob_below_the_wall_is_rejected():
    """A configuration with a blob centre at z <= 0 has infinite energy (SPEC section 9: never accepted)."""
    kw = keywords()
    energy, _ = make_energy(gen.rod(4, 0.35), [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0, 0.0]], kw, 'python')
    tilted = me.quaternions_from_rotations([[0.0, np.pi / 2, 0.0]])   # rod along z: lowest blob at z = 0.475
    assert np.isfinite(energy.total(np.array([[0.0, 0.0, 1.0]]), tilted))
    assert energy.total(np.array([[0.0, 0.0, 0.5]]), tilted) == np.inf


# ------------------------------------------------------------------ statistics: helpers
def chain_z_scores(per_chain_means, exact):
    """(z-scores of the grand means, their standard errors) from per-chain means (chains, statistics)."""
    means = per_chain_means.mean(axis=0)
    standard_errors = per_chain_means.std(axis=0, ddof=1) / np.sqrt(per_chain_means.shape[0])
    return (means - exact) / standard_errors, standard_errors


def inverse_cdf_samples(rng, grid, density, size):
    cdf = np.concatenate(([0.0], np.cumsum(0.5 * (density[1:] + density[:-1]) * np.diff(grid))))
    return np.interp(rng.uniform(0, cdf[-1], size), cdf, grid)


# VALIDATION T1 (multi_bodies/examples/Rollers_Small_Example): one blob above the wall
T1 = dict(blob_radius=0.656, kT=0.0041419464, g=0.0024892, repulsion_strength_wall=0.0165677856,
          debye_length_wall=0.0656)


def t1_density(z):
    return np.exp(-wall_energy(z, T1['g'], T1['repulsion_strength_wall'], T1['debye_length_wall'],
                               T1['blob_radius']) / T1['kT'])


def run_t1_chains(kT_factor, n_chains=100, sweeps=200, seed=11):
    """Independent single blobs (far apart) with one-body moves; per chain: mean height and 4 bin fractions."""
    grid = np.linspace(1e-9, 40.0, 400001)
    density = t1_density(grid)
    rng = np.random.default_rng(seed)
    heights = inverse_cdf_samples(rng, grid, density, n_chains)
    locations = np.column_stack((200.0 * np.arange(n_chains), np.zeros(n_chains), heights))
    kw = keywords(g=T1['g'], repulsion_strength_wall=T1['repulsion_strength_wall'],
                  debye_length_wall=T1['debye_length_wall'], repulsion_strength=0.0, blob_radius=T1['blob_radius'])
    energy, arrays = make_energy(np.zeros((1, 3)), locations, np.tile([1.0, 0, 0, 0], (n_chains, 1)), kw, 'C++')
    sampler = MetropolisSampler(energy, arrays.locations, arrays.orientations, kT_factor * T1['kT'],
                                max_translation=2.5, max_angle_shift=0.0, move='one_body')
    z = np.empty((sweeps, n_chains))
    for step in range(sweeps):
        sampler.step(step, rng)
        z[step] = sampler.locations[:, 2]
    cdf = np.cumsum(density) / density.sum()
    edges = np.interp([0.25, 0.5, 0.75], cdf, grid)     # quartiles of the exact distribution
    bins = np.searchsorted(edges, z)
    stats = np.column_stack([z.mean(axis=0)] + [(bins == b).mean(axis=0) for b in range(4)])
    exact_mean = np.trapezoid(grid * density, grid) / np.trapezoid(density, grid)
    return stats, np.array([exact_mean, 0.25, 0.25, 0.25, 0.25]), sampler


def test_t1_quadrature_is_the_validation_value():
    """The test's own quadrature reproduces VALIDATION T1 (<z> = 2.44457, std 1.66598)."""
    grid = np.linspace(1e-9, 40.0, 400001)
    p = t1_density(grid)
    p /= np.trapezoid(p, grid)
    mean = np.trapezoid(grid * p, grid)
    assert mean == pytest.approx(2.44457, abs=2e-5)
    assert np.sqrt(np.trapezoid((grid - mean) ** 2 * p, grid)) == pytest.approx(1.66598, abs=2e-5)


def test_t1_single_blob_heights_follow_gibbs_boltzmann():
    """VALIDATION T1: mean height and quartile occupations of 100 independent chains within 4 standard errors."""
    stats, exact, sampler = run_t1_chains(1.0)
    z_scores, errors = chain_z_scores(stats, exact)
    assert errors[0] < 0.05 * exact[0]   # the test has power: 2 % of <z>
    assert np.all(np.abs(z_scores) < Z_SCORE_LIMIT), z_scores
    assert 0.2 < sampler.acceptance_ratio() < 0.9


def test_t1_negative_control_wrong_temperature_fails():
    """The same chains at 1.25 kT must fail the same check (else the test could not detect a wrong density)."""
    stats, exact, _ = run_t1_chains(1.25)
    z_scores, _ = chain_z_scores(stats, exact)
    assert np.max(np.abs(z_scores)) > Z_SCORE_LIMIT


# ------------------------------------------------------------------ boomerang height and tilt
# Boomerang of the manual (planar, in the body's x-y plane) with the T4 physical parameters, but four
# times the weight, so that the wall constrains the tilt (gravitational height kT/(15 g) = 0.45)
BOOM = dict(blob_radius=0.324557, kT=0.0041419464, g=10 * 1.539384e-4, repulsion_strength_wall=0.0957137,
            debye_length_wall=0.1622787)


def boomerang_density_grid():
    """exp(-U/kT) on (z, c = cos tilt >= 0, phi); U depends on the orientation through m = R^T e_z only.

    m = (sqrt(1 - c^2) cos phi, sqrt(1 - c^2) sin phi, c) is uniform on the sphere for a uniform
    orientation, and blob i sits at height z + r_i . m.  The tilt of the plane normal is c.
    """
    reference = gen.boomerang()
    z = np.linspace(0.0, 12.0, 1201)
    nodes, weights = np.polynomial.legendre.leggauss(24)
    c, c_weights = 0.5 * (nodes + 1.0), 0.5 * weights
    phi = np.linspace(0.0, 2 * np.pi, 48, endpoint=False)
    s = np.sqrt(1.0 - c ** 2)
    offsets = s[:, None, None] * (reference[None, None, :, 0] * np.cos(phi)[None, :, None]
                                  + reference[None, None, :, 1] * np.sin(phi)[None, :, None])   # (c, phi, blob)
    heights = z[:, None, None, None] + offsets[None]
    with np.errstate(over='ignore'):
        energy = wall_energy(heights, BOOM['g'], BOOM['repulsion_strength_wall'], BOOM['debye_length_wall'],
                             BOOM['blob_radius']).sum(axis=-1)
    density = np.where(np.all(heights > 0, axis=-1), np.exp(-(energy - energy.min()) / BOOM['kT']), 0.0)
    return z, c, c_weights, phi, density            # density (z, c, phi)


def boomerang_exact_statistics(z, c, c_weights, density):
    marginal = density.sum(axis=2) * c_weights[None, :]          # (z, c)
    p_z = marginal.sum(axis=1)
    p_z /= np.trapezoid(p_z, z)
    cdf = np.concatenate(([0.0], np.cumsum(0.5 * (p_z[1:] + p_z[:-1]) * np.diff(z))))
    z_edges = np.interp([0.25, 0.5, 0.75], cdf, z)
    p_c = marginal.sum(axis=0) * (z[1] - z[0])
    p_c /= p_c.sum()
    mean_z = np.trapezoid(z * p_z, z)
    mean_c = np.sum(c * p_c)
    mean_c2 = np.sum(c ** 2 * p_c)
    return z_edges, np.array([mean_z, mean_c, mean_c2, 0.25, 0.25, 0.25, 0.25])


def orientation_from_lab_z(rng, m):
    """A quaternion whose R^T e_z is the unit vector m (3,), with a uniform turn about the lab z axis."""
    helper = np.array([1.0, 0.0, 0.0]) if abs(m[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(m, helper)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(m, e1)
    turn = rng.uniform(0, 2 * np.pi)
    rows = np.array([np.cos(turn) * e1 + np.sin(turn) * e2, -np.sin(turn) * e1 + np.cos(turn) * e2, m])
    R = rows if np.linalg.det(rows) > 0 else rows[[1, 0, 2]]
    s = 0.5 * np.sqrt(max(1.0 + np.trace(R), 1e-300))
    if s > 0.1:
        return np.array([s, R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]]) / np.array([1, 4 * s, 4 * s, 4 * s])
    i = int(np.argmax(np.diag(R)))
    j, k = (i + 1) % 3, (i + 2) % 3
    v = np.zeros(3)
    v[i] = 0.5 * np.sqrt(1.0 + R[i, i] - R[j, j] - R[k, k])
    v[j] = (R[j, i] + R[i, j]) / (4 * v[i])
    v[k] = (R[k, i] + R[i, k]) / (4 * v[i])
    return np.concatenate(([(R[k, j] - R[j, k]) / (4 * v[i])], v))


def exact_boomerang_samples(rng, n, z, c, c_weights, phi, density):
    """Draws of (location, quaternion) from the gridded exact density, jittered uniformly inside the cells."""
    weights = (density * c_weights[None, :, None]).ravel()
    cells = rng.choice(weights.size, size=n, p=weights / weights.sum())
    iz, ic, ip = np.unravel_index(cells, density.shape)
    heights = np.clip(z[iz] + rng.uniform(-0.5, 0.5, n) * (z[1] - z[0]), 1e-3, None)
    angles = phi[ip] + rng.uniform(-0.5, 0.5, n) * (phi[1] - phi[0])
    tilt = np.clip(c[ic] + rng.uniform(-0.5, 0.5, n) * c_weights[ic], 0.0, 1.0) * rng.choice([-1.0, 1.0], n)
    orientations = []
    for cosine, angle in zip(tilt, angles):
        sine = np.sqrt(1.0 - cosine ** 2)
        q = orientation_from_lab_z(rng, np.array([sine * np.cos(angle), sine * np.sin(angle), cosine]))
        orientations.append(q)
    orientations = np.array(orientations)
    assert np.allclose(rotation_matrices(orientations)[:, 2, 2], tilt)
    return np.column_stack((np.zeros(n), np.zeros(n), heights)), orientations


def run_boomerang_chains(kT_factor, n_chains=48, steps=200, seed=21, max_translation=0.2, max_angle_shift=0.25):
    """Independent single-boomerang chains, all-bodies moves (the published algorithm), default potentials."""
    z, c, c_weights, phi, density = boomerang_density_grid()
    z_edges, exact = boomerang_exact_statistics(z, c, c_weights, density)
    rng = np.random.default_rng(seed)
    starts = exact_boomerang_samples(rng, n_chains, z, c, c_weights, phi, density)
    kw = keywords(g=BOOM['g'], repulsion_strength_wall=BOOM['repulsion_strength_wall'],
                  debye_length_wall=BOOM['debye_length_wall'], repulsion_strength=0.0957137,
                  debye_length=0.1622787, blob_radius=BOOM['blob_radius'])
    stats, acceptance = [], []
    for chain in range(n_chains):
        energy, arrays = make_energy(gen.boomerang(), starts[0][chain:chain + 1], starts[1][chain:chain + 1], kw,
                                     'C++')
        sampler = MetropolisSampler(energy, arrays.locations, arrays.orientations, kT_factor * BOOM['kT'],
                                    max_translation=max_translation, max_angle_shift=max_angle_shift)
        heights, tilts = np.empty(steps), np.empty(steps)
        for step in range(steps):
            sampler.step(step, rng)
            heights[step] = sampler.locations[0, 2]
            tilts[step] = abs(rotation_matrices(sampler.orientations)[0, 2, 2])
        bins = np.searchsorted(z_edges, heights)
        stats.append([heights.mean(), tilts.mean(), (tilts ** 2).mean()] + [(bins == b).mean() for b in range(4)])
        acceptance.append(sampler.acceptance_ratio())
    return np.array(stats), exact, np.mean(acceptance)


def test_boomerang_height_and_tilt_follow_gibbs_boltzmann():
    """Height quartiles, <z>, <|cos tilt|>, <cos^2 tilt> of 48 independent chains within 4 standard errors
    of the quadrature over the exact density (uniform orientations weighted by exp(-U/kT))."""
    stats, exact, acceptance = run_boomerang_chains(1.0)
    z_scores, errors = chain_z_scores(stats, exact)
    assert errors[0] < 0.08 * exact[0] and errors[1] < 0.08 * exact[1]   # the test has power
    assert np.all(np.abs(z_scores) < Z_SCORE_LIMIT), z_scores
    assert 0.15 < acceptance < 0.85


def test_boomerang_negative_control_wrong_temperature_fails():
    """The same chains at 2 kT must fail the same check (the tilt moves by about 7 standard errors)."""
    stats, exact, _ = run_boomerang_chains(2.0)
    z_scores, _ = chain_z_scores(stats, exact)
    assert np.max(np.abs(z_scores)) > Z_SCORE_LIMIT


# ------------------------------------------------------------------ the script: outputs, acceptance, restart
def write_scene(folder, options, n_blobs=1, height=1000.0, spacing=50.0):
    """Single-blob bodies in a row at ``height``, and the input file ``input.dat``."""
    write_vertex_file(folder / 'blob.vertex', np.zeros((1, 3)))
    locations = np.column_stack((spacing * np.arange(n_blobs), np.zeros(n_blobs), np.full(n_blobs, height)))
    write_clones_file(folder / 'blob.clones', locations, np.tile([1.0, 0, 0, 0], (n_blobs, 1)))
    lines = ['%s %s' % item for item in options.items()] + ['structure blob.vertex blob.clones']
    (folder / 'input.dat').write_text('\n'.join(lines) + '\n')


def run_script(folder, monkeypatch, input_name='input.dat'):
    monkeypatch.chdir(folder)
    return SCRIPT.main([input_name])


def read_mcmc_info(path):
    values = {}
    for line in Path(path).read_text().splitlines():
        if '=' not in line:
            continue
        key, value = (part.strip() for part in line.split('=', 1))
        values[key] = value
    return values


def test_acceptance_ratio_in_a_linear_potential(tmp_path, monkeypatch, capsys):
    """One blob far above the wall in U = g z: each proposal is accepted with the exact probability
    1/2 + (kT/(2 g D))(1 - exp(-g D/kT)) independently of the state, so the acceptance ratio of
    .MCMC_info is binomial around it.  Also: the manual's outputs, and unused options warn."""
    n_steps = 4000
    options = {'n_steps': n_steps, 'n_save': 1000, 'kT': 1.0, 'g': 1.0, 'blob_radius': 0.5,
               'repulsion_strength_wall': 0.0, 'max_translation': 1.0, 'seed': 5, 'output_name': 'data/run',
               'dt': 0.01, 'scheme': 'deterministic_forward_euler'}
    write_scene(tmp_path, options)
    assert run_script(tmp_path, monkeypatch) == 0
    warning = [line for line in capsys.readouterr().out.splitlines() if 'does not use' in line]
    assert len(warning) == 1 and 'dt' in warning[0] and 'scheme' in warning[0]
    info = read_mcmc_info(tmp_path / 'data/run.MCMC_info')
    assert list(info)[:4] == ['acceptance ratio', 'accepted_moves', 'final max_translation', 'final max_angle_shift']
    exact = 0.5 + 0.5 * (1.0 - np.exp(-1.0))
    ratio = float(info['acceptance ratio'])
    assert abs(ratio - exact) < Z_SCORE_LIMIT * np.sqrt(exact * (1 - exact) / n_steps)
    assert int(info['accepted_moves']) == round(ratio * n_steps)
    assert float(info['final max_translation']) == 1.0
    assert float(info['final max_angle_shift']) == 1.0 / (2 * 0.5)   # max_translation / body length 2a
    names = sorted(os.listdir(tmp_path / 'data'))
    for suffix in ('inputfile', 'random_state', 'bodies_info', 'time', 'MCMC_info', 'restart'):
        assert 'run.' + suffix in names
    assert [n for n in names if n.endswith('.clones')] == ['run.blob.%08d.clones' % s for s in range(0, 4001, 1000)]
    assert (tmp_path / 'data/run.inputfile').read_text() == (tmp_path / 'input.dat').read_text()
    assert run_output.read_random_state(str(tmp_path / 'data/run.random_state')) == \
        np.random.default_rng(5).bit_generator.state
    assert float((tmp_path / 'data/run.time').read_text()) > 0


def test_acceptance_negative_control_broken_rule(tmp_path, monkeypatch):
    """Accepting with exp(-dU/(2 kT)) (a broken rule) fails the same binomial check."""
    from many_bodyMCMC import sampler as sampler_module
    options = {'n_steps': 4000, 'n_save': 4000, 'kT': 1.0, 'g': 1.0, 'blob_radius': 0.5,
               'repulsion_strength_wall': 0.0, 'max_translation': 1.0, 'seed': 5, 'output_name': 'run'}
    write_scene(tmp_path, options)
    broken = lambda self, delta, uniform: delta <= 0 or uniform < np.exp(-delta / (2 * self.kT))  # noqa: E731
    monkeypatch.setattr(sampler_module.MetropolisSampler, '_accept', broken)
    assert run_script(tmp_path, monkeypatch) == 0
    exact = 0.5 + 0.5 * (1.0 - np.exp(-1.0))
    ratio = float(read_mcmc_info(tmp_path / 'run.MCMC_info')['acceptance ratio'])
    assert abs(ratio - exact) > Z_SCORE_LIMIT * np.sqrt(exact * (1 - exact) / 4000)


@pytest.mark.parametrize('move,save_clones', [('one_body', 'one_file_per_step'), ('all_bodies', 'one_file')])
def test_restart_continues_exactly(tmp_path, monkeypatch, move, save_clones):
    """120 steps at once equal 60 + 60 through initial_step, bit for bit, also while step sizes adapt."""
    whole, split = tmp_path / 'whole', tmp_path / 'split'
    whole.mkdir(), split.mkdir()
    options = {'n_steps': 120, 'n_save': 30, 'kT': 1.0, 'g': 1.0, 'blob_radius': 0.5, 'repulsion_strength': 2.0,
               'debye_length': 0.5, 'mcmc_move': move, 'n_burn_in': 100, 'seed': 9, 'output_name': 'run',
               'save_clones': save_clones, 'mcmc_energy_implementation': 'python'}
    write_scene(whole, options, n_blobs=25, height=1.5, spacing=0.8)
    assert run_script(whole, monkeypatch) == 0
    write_scene(split, dict(options, n_steps=60), n_blobs=25, height=1.5, spacing=0.8)
    assert run_script(split, monkeypatch) == 0
    write_scene(split, dict(options, initial_step=60), n_blobs=25, height=1.5, spacing=0.8)
    assert run_script(split, monkeypatch) == 0
    if save_clones == 'one_file':
        assert (split / 'run.blob.config').read_text() == (whole / 'run.blob.config').read_text()
    else:
        for step in (60, 90, 120):
            name = 'run.blob.%08d.clones' % step
            assert (split / name).read_text() == (whole / name).read_text()
    assert (split / 'run.MCMC_info').read_text() == (whole / 'run.MCMC_info').read_text()
    assert len((split / 'run.time').read_text().splitlines()) == 2
    info = read_mcmc_info(whole / 'run.MCMC_info')
    assert float(info['final max_translation']) != 0.05   # the burn-in adapted the step (started at 0.1 a)


def test_bad_option_exits_with_status_2(tmp_path, monkeypatch, capsys):
    write_scene(tmp_path, {'n_steps': 5, 'mcmc_move': 'some_bodies'})
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as stop:
        import utils
        utils.fail_cleanly(SCRIPT.main, ['input.dat'])
    assert stop.value.code == 2
    assert 'mcmc_move must be all_bodies or one_body' in capsys.readouterr().err


def test_start_below_the_wall_is_refused(tmp_path, monkeypatch):
    write_scene(tmp_path, {'n_steps': 5}, height=-0.1)
    with pytest.raises(UserInputError, match='at or below the wall'):
        run_script(tmp_path, monkeypatch)


# ------------------------------------------------------------------ overrides and the example
def test_user_potentials_replace_the_defaults(tmp_path):
    """user_defined_potentials.py in the run directory replaces the three potentials; auto then picks python."""
    (tmp_path / me.USER_POTENTIAL_FILE).write_text(
        'import numpy as np\n'
        'def blob_potential(r, g=1.0, **kw):\n    return 2.0 * g * r[:, 2]\n'
        'def blob_blob_potential(r, **kw):\n    return np.einsum("...k,...k->...", r, r)\n'
        'def body_body_potential(r, qi, qj, **kw):\n    return 10.0 * qi[..., 0] * qj[..., 0]\n')
    kw = keywords()
    locations = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 2.0], [0.0, 3.0, 4.0]])
    orientations = np.tile([1.0, 0, 0, 0], (3, 1))
    energy, _ = make_energy(np.zeros((1, 3)), locations, orientations, kw, 'auto', directory=str(tmp_path))
    assert energy.pair_sums.name == 'python'
    d2 = [np.sum((locations[i] - locations[j]) ** 2) for i, j in ((0, 1), (0, 2), (1, 2))]
    expected = 2.0 * kw['g'] * locations[:, 2].sum() + sum(d2) + 3 * 10.0
    assert energy.total(locations, orientations) == pytest.approx(expected, rel=1e-14)
    with pytest.raises(UserInputError, match='default blob-blob law'):
        me.make_pair_sums('C++', kw, energy.hooks)


def gpu_usable():
    try:
        from many_bodyMCMC import mcmc_cuda
        mcmc_cuda.check_usable()
        return True
    except Exception:
        return False


def test_gpu_potential_file_without_gpu_gives_a_clear_error(tmp_path):
    if gpu_usable():
        pytest.skip('a GPU is usable here: the no-GPU error cannot be exercised')
    (tmp_path / me.GPU_POTENTIAL_FILE).write_text('BLOB_BLOB_POTENTIAL_SOURCE = ""\n')
    hooks = me.load_user_potentials(str(tmp_path))
    with pytest.raises(UserInputError, match='potential_pycuda_user_defined.py is for the GPU energy'):
        me.make_pair_sums('auto', keywords(), hooks)


def test_example_boomerang_suspension_runs(tmp_path, monkeypatch):
    """The shipped example (Yukawa-like wall, user potentials) runs as documented, shortened to 30 steps."""
    example = REPO / 'many_bodyMCMC' / 'examples' / 'boomerang_suspension'
    folder = tmp_path / 'many_bodyMCMC' / 'examples' / 'boomerang_suspension'
    shutil.copytree(example, folder, ignore=shutil.ignore_patterns('data', '__pycache__'))
    structures = tmp_path / 'multi_bodies' / 'Structures'
    structures.mkdir(parents=True)
    shutil.copy(REPO / 'multi_bodies' / 'Structures' / 'boomerang_N_15.vertex', structures)
    text = (folder / 'inputMCMC_boomerang_suspension.dat').read_text()
    for name, value in (('n_steps', 30), ('n_burn_in', 20), ('n_save', 10)):
        text, count = re.subn(r'^%s\s+\d+' % name, '%s %d' % (name, value), text, flags=re.M)
        assert count == 1
    (folder / 'short.dat').write_text(text)
    assert run_script(folder, monkeypatch, 'short.dat') == 0
    info = read_mcmc_info(folder / 'data' / 'boomerang_suspension.MCMC_info')
    assert int(info['proposals']) == 30 and info['invalid_proposals'] == '0'
    config = (folder / 'data' / 'boomerang_suspension.boomerang_suspension.config').read_text().splitlines()
    assert len(config) == 4 * 17   # steps 0, 10, 20, 30 of 16 boomerangs


def test_sigterm_stops_after_the_step_with_complete_files(tmp_path, monkeypatch):
    """SIGTERM during a run: the step in progress finishes, status 143, .time and .MCMC_info are written."""
    import signal
    from many_bodyMCMC import sampler as sampler_module
    write_scene(tmp_path, {'n_steps': 1000, 'n_save': 10, 'seed': 3, 'output_name': 'run',
                           'mcmc_energy_implementation': 'python'}, height=2.0)
    original = sampler_module.MetropolisSampler.step

    def step(self, index, rng):
        original(self, index, rng)
        if index == 25:
            os.kill(os.getpid(), signal.SIGTERM)
    monkeypatch.setattr(sampler_module.MetropolisSampler, 'step', step)
    assert run_script(tmp_path, monkeypatch) == 143
    info = read_mcmc_info(tmp_path / 'run.MCMC_info')
    assert info['proposals'] == '26' and 'stopped by SIGTERM at step 26' in (tmp_path / 'run.MCMC_info').read_text()
    assert (tmp_path / 'run.time').is_file() and (tmp_path / 'run.blob.00000020.clones').is_file()
