"""Boomerangs (15-blob bodies) keep their Gibbs-Boltzmann equilibrium (issue: Brownian dynamics).

Brownian boomerangs above a wall under ``stochastic_Slip_Trapz`` (preconditioned Lanczos noise) keep the
exact averages of their height and tilt, computed here by quadrature over the exact density, and move at
the equilibrium rate (one-step displacements against ``2 kT dt tr N``); a Metropolis Monte Carlo chain of
the same bodies gives the same averages.  Tolerances come from the spread of per-body means.
"""
import numpy as np
import pytest

from body.body import Body, bodies_to_arrays, rotation_matrices
from brownian_scene import CPP, ETA, KT, Opts, physics, z_score
from multi_bodies import multi_bodies_functions as mbf
from multi_bodies.files import structure_generators as gen
from multi_bodies.solver.model import Model
from quaternion_integrator.schemes import make_scheme


# ====================================================================== multi-blob equilibrium (preconditioned noise)
BOOM_A, BOOM_G, BOOM_EPS, BOOM_B = 0.15, 1.0 / 15.0, 1.0, 0.2  # blob radius, weight per blob, wall eps and b
BOOM_MOTION_EVERY = 10  # steps between the one-step displacement checks of the Brownian boomerangs


def boomerang_blob_energy(z):
    """Energy of one boomerang blob at height z (gravity + soft wall), kT = 1."""
    return BOOM_G * z + np.where(z < BOOM_A, BOOM_EPS + BOOM_EPS * (BOOM_A - z) / BOOM_B,
                                 BOOM_EPS * np.exp(-(z - BOOM_A) / BOOM_B))


def boomerang_quadrature(reference, samples=20000, seed=400):
    """Exact marginals of a boomerang's height h and tilt cos(theta) by quadrature over (h, q).

    P(h, q) ~ exp(-sum_i U(h + (R(q) r_i)_z)) with q uniform on the sphere of unit quaternions
    (sampled with ``samples`` orientations) and h on a fine grid.  Returns (orientation pool, their
    weights, the h grid, conditional cumulative densities, <h>, <cos theta>, <cos^2 theta>).
    """
    rng = np.random.default_rng(seed)
    q = rng.standard_normal((samples, 4))
    q /= np.linalg.norm(q, axis=1)[:, None]
    R = rotation_matrices(q)
    dz = np.einsum('sj,ij->si', R[:, 2, :], reference)  # (samples, blobs)
    h = np.linspace(-0.5, 12.0, 2500)
    energy = np.zeros((samples, h.size))
    for i in range(reference.shape[0]):
        energy += boomerang_blob_energy(h[None, :] + dz[:, i:i + 1])
    density = np.exp(-(energy - energy.min()))
    weights = np.trapezoid(density, h, axis=1)
    total = weights.sum()
    mean_h = np.sum(np.trapezoid(density * h[None, :], h, axis=1)) / total
    cos_theta = R[:, 2, 2]
    moments = (mean_h, np.sum(weights * cos_theta) / total, np.sum(weights * cos_theta ** 2) / total)
    cdf = np.cumsum(density, axis=1)
    cdf /= cdf[:, -1:]
    return q, weights / total, h, cdf, moments


def boomerang_start(n_bodies, seed):
    """Exact equilibrium sample of ``n_bodies`` boomerangs 12 apart: (reference, locations, orientations, exact)."""
    reference = gen.boomerang(spacing=2 * BOOM_A)
    pool, weights, h_grid, cdf, exact = boomerang_quadrature(reference)
    rng = np.random.default_rng(seed)
    chosen = rng.choice(pool.shape[0], size=n_bodies, p=weights)
    heights = np.array([np.interp(rng.random(), cdf[index], h_grid) for index in chosen])
    locations = np.column_stack((12.0 * (np.arange(n_bodies) % 6), 12.0 * (np.arange(n_bodies) // 6), heights))
    return reference, locations, pool[chosen], np.array(exact)


def boomerang_keywords():
    return physics(g=BOOM_G, repulsion_strength_wall=BOOM_EPS, debye_length_wall=BOOM_B, blob_radius=BOOM_A)


@pytest.fixture(scope='module')
def boomerang_brownian():
    """Per-body time averages of (h, cos theta, cos^2 theta) of 30 boomerangs, 250 steps of Slip_Trapz; the
    exact values; per body, the squared one-step displacements of the tracking point summed over every
    BOOM_MOTION_EVERY-th step, over their expectation 2 kT dt tr N_tt at the step's start (N dense, here)."""
    n_bodies, n_steps = 30, 250
    reference, locations, orientations, exact = boomerang_start(n_bodies, 401)
    bodies = []
    for location, orientation in zip(locations, orientations):
        body = Body(location, orientation, reference, BOOM_A)
        body.ID = 'boomerang'
        body.body_length = body.calc_body_length()
        bodies.append(body)
    system = Model(bodies, bodies_to_arrays(bodies, [n_bodies]), mbf.load_user_hooks('/nonexistent'),
                   boomerang_keywords(), ETA, BOOM_A, 1e-4, vector_product_name=CPP, blobs_name=CPP)
    scheme = make_scheme('stochastic_Slip_Trapz', 0.01, Opts())
    per_body, motion = brownian_averages(system, scheme, np.random.default_rng(402), n_steps)
    return per_body, exact, motion


def brownian_averages(system, scheme, rng, n_steps, every=BOOM_MOTION_EVERY):
    """Run ``n_steps`` of ``scheme`` from the model's start; returns per-body time averages of (h, cos theta,
    cos^2 theta) (Nb, 3) and, per body, the squared one-step displacements of every ``every``-th step summed
    over their expectation ``2 kT dt tr N_tt`` at the step's start (N dense)."""
    n_bodies = system.num_bodies
    sums = np.zeros((n_bodies, 3))
    squared, predicted = np.zeros(n_bodies), np.zeros(n_bodies)
    state = scheme.init(system, system.start_configuration)
    for step in range(n_steps):
        if step % every == 0:  # E[|dr|^2 | state] = 2 kT dt tr N_tt(state) + O(dt^2), N from here
            N = system.dense_matrices(state.configuration)[3]
            blocks = np.array([np.trace(N[6 * b:6 * b + 3, 6 * b:6 * b + 3]) for b in range(n_bodies)])
            predicted += 2.0 * KT * scheme.dt * blocks
            before = state.configuration.locations.copy()
        state = scheme.step(system, state, rng)
        if step % every == 0:
            squared += np.sum((state.configuration.locations - before) ** 2, axis=1)
        c = rotation_matrices(state.configuration.orientations)[:, 2, 2]
        sums += np.column_stack((state.configuration.locations[:, 2], c, c ** 2))
    return sums / n_steps, squared / predicted


@pytest.mark.slow
def test_boomerang_height_and_tilt_keep_gibbs_boltzmann(boomerang_brownian):
    """30 boomerangs (15 blobs each, far apart) under stochastic_Slip_Trapz keep the exact equilibrium.

    Started from an exact sample (importance-resampled orientations, then heights from the conditional
    density); per-body time averages of h, cos(theta) and cos^2(theta) are within 4 SE of the quadrature
    values.  This exercises the block-preconditioned Lanczos noise and the slip RFD on rigid bodies.
    """
    per_body, exact, motion = boomerang_brownian
    scores = z_score(per_body, exact)
    assert np.max(np.abs(scores)) < 4.0, (per_body.mean(axis=0), exact, scores)
    # An integrator that never moves would pass the above (exact start): the bodies must also move at the
    # rate of the fluctuation-dissipation law, the ratio within 4 SE of 1 (SE from the spread over the
    # bodies; the O(dt^2) drift term is below 0.2 %) ...
    motion_score = z_score(motion, 1.0)
    assert abs(motion_score) < 4.0, (motion.mean(), motion_score)
    # ... and the check sees a wrong kT (25 % off)
    assert abs(z_score(motion, 1.25)) > 4.0, (motion.mean(), z_score(motion, 1.25))


@pytest.mark.slow
def test_boomerang_equilibrium_of_monte_carlo_and_brownian_dynamics_agree(boomerang_brownian):
    """VALIDATION T4 (short version): the Metropolis sampler of many_bodyMCMC on the same scene (same
    bodies and potentials) gives the same <h>, <cos theta>, <cos^2 theta> as the Brownian run.

    The two start from independent exact equilibrium samples (seeds 404 and 401), so two chains that never
    move do not agree by construction.  Correlation in time: each body's time average is one block, and
    the bodies are independent (far apart), so the standard error of each run's grand mean is the spread
    of its per-body time averages over sqrt(30), whatever the autocorrelation time; the difference must be
    within 4 combined standard errors.  The Monte Carlo chains must also mix: their effective sample size,
    var(instantaneous values) / SE^2, above 1.5 per body (a frozen chain gives (n - 1) / n per body), and
    the Brownian bodies must move at the fluctuation-dissipation rate (shared run, see the test above).
    """
    from many_bodyMCMC import mcmc_energy
    from many_bodyMCMC.sampler import MetropolisSampler
    n_bodies = 30
    reference, locations, orientations, _ = boomerang_start(n_bodies, 404)
    bodies = []
    for location, orientation in zip(locations, orientations):
        body = Body(location, orientation, reference, BOOM_A)
        body.ID = 'boomerang'
        bodies.append(body)
    arrays = bodies_to_arrays(bodies, [n_bodies])
    keywords = boomerang_keywords()
    hooks = mcmc_energy.load_user_potentials('/nonexistent')
    pair_sums, _ = mcmc_energy.make_pair_sums('C++' if mcmc_energy.cpp_available()[0] else 'python', keywords,
                                              hooks)
    energy = mcmc_energy.MCMCEnergy(arrays, keywords, hooks, pair_sums)
    sampler = MetropolisSampler(energy, locations, orientations, KT, max_translation=0.2, max_angle_shift=0.3,
                                move='one_body')
    rng = np.random.default_rng(403)
    n_sweeps = 1000  # about 2 s; 150 sweeps left an effective sample of about 1.3 per body for h
    series = np.empty((n_sweeps, n_bodies, 3))
    for sweep in range(n_sweeps):
        sampler.step(sweep, rng)
        c = rotation_matrices(sampler.orientations)[:, 2, 2]
        series[sweep] = np.column_stack((sampler.locations[:, 2], c, c ** 2))
    monte_carlo = series.mean(axis=0)
    brownian, _, motion = boomerang_brownian
    difference = monte_carlo.mean(axis=0) - brownian.mean(axis=0)
    se_mc = monte_carlo.std(axis=0, ddof=1) / np.sqrt(n_bodies)
    error = np.sqrt(se_mc ** 2 + brownian.var(axis=0, ddof=1) / n_bodies)
    assert np.all(np.abs(difference) < 4 * error), (monte_carlo.mean(axis=0), brownian.mean(axis=0), error)
    effective = series.reshape(-1, 3).var(axis=0) / se_mc ** 2
    assert np.all(effective > 1.5 * n_bodies), ('Monte Carlo chains do not mix', effective)
    assert 0.15 < sampler.acceptance_ratio() < 0.95, sampler.acceptance_ratio()
    assert abs(z_score(motion, 1.0)) < 4.0, ('Brownian bodies do not move at the equilibrium rate', motion.mean())
