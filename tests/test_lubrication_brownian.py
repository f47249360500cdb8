"""Brownian increments, thermal drift and time steps of spheres with lubrication (lubrication.brownian,
lubrication.integrators).

Laws checked, each with a negative control that must fail the same test:

* the increments ``U_B = (I + M Delta_R)^-1 (X + M F_B)`` have covariance (2kT/dt) M_lub (fluctuation-
  dissipation), M_lub from the dense inverse ``(M^-1 + Delta_R)^-1``;
* the mean of the random finite difference is ``kT div M_lub``, the divergence taken by central finite
  differences of the dense M_lub, at a configuration away from the formula hand-overs (r = 2.006 a,
  2.1 a, h = 1.1 a, the cutoff);
* heights of spheres with their lubrication wall term keep the Gibbs-Boltzmann distribution under the
  trapezoidal scheme, and the spheres move at the equilibrium rate (in-plane diffusion 4 kT <mu_par> tau);
  without the corrector's far-field drift the heights leave it;
* deterministic steps (kT = 0) equal Euler and Heun steps written with dense algebra; torques from
  ``torque_from_omega`` give the prescribed angular velocity through the dense M_lub.

Tolerances of the statistical tests come from the standard error: for a zero-mean Gaussian vector the
sample covariance entry C_ij of n samples has standard error sqrt((C_ii C_jj + C_ij^2) / n); the drift's
standard error is the sample standard deviation over sqrt(n).  A test passes when every |z| < 4.5
(Bonferroni over at most 78 entries: false alarm probability below 1e-3 with fixed seeds).
"""
import numpy as np
import pytest

from lubrication import brownian, integrators
from lubrication.problem import dense_far_field_mobility, dense_lubricated_mobility

Z_LIMIT = 4.5
SETTINGS = brownian.lubrication_settings(1.0, 1.0)
# two spheres above the wall, gap 0.2 a, heights 1.5 a and 1.4 a: away from the hand-overs (r = 2.006, 2.1,
# h = 1.1, 1.01) and the cutoff
PAIR = np.array([[0.0, 0.0, 1.5], [2.2, 0.0, 1.4]])


def covariance_z(samples, expected):
    """z-scores (n_dim, n_dim) of the sample covariance of zero-mean samples (n, n_dim) against ``expected``."""
    n = samples.shape[0]
    sample = samples.T @ samples / n
    diagonal = np.diag(expected)
    error = np.sqrt((np.outer(diagonal, diagonal) + expected ** 2) / n)
    return (sample - expected) / error


def increments(problem, root, n, seed, kT=0.5, dt=1.0):
    rng = np.random.default_rng(seed)
    preconditioner = problem.preconditioner(1e-10)
    out = np.empty((n, problem.size))
    for k in range(n):
        result = brownian.brownian_velocities(problem, root, rng.standard_normal(problem.size),
                                              rng.standard_normal(problem.size), kT, dt, 1e-10, preconditioner)
        out[k] = result.velocities.reshape(-1)
    return out


def test_cholesky_root_of_the_shifted_correction_is_exact():
    locations = np.array([[0.0, 0.0, 1.5], [2.1, 0.0, 1.5], [1.0, 1.9, 1.2]])
    problem = SETTINGS.problem(locations)
    shift = SETTINGS.shift(1e-4)
    root = brownian.NearFieldRoot(problem.Delta_R, 'cholesky', shift)
    C = root.root.toarray()
    expected = problem.Delta_R.toarray() + shift * np.eye(problem.size)
    np.testing.assert_allclose(C @ C.T, expected, atol=1e-12 * np.abs(expected).max())
    lanczos = brownian.NearFieldRoot(problem.Delta_R, 'lanczos', tolerance=1e-12)
    W = np.random.default_rng(0).standard_normal(problem.size)
    values, vectors = np.linalg.eigh(problem.Delta_R.toarray())
    principal = vectors @ (np.sqrt(np.maximum(values, 0)) * (vectors.T @ W))
    np.testing.assert_allclose(lanczos.apply(W), principal, rtol=1e-9, atol=1e-9 * np.abs(principal).max())


@pytest.mark.parametrize('method, samples', [('cholesky', 2000), ('lanczos', 1500)])
def test_increments_have_covariance_2kT_over_dt_times_M_lub(method, samples):
    problem = SETTINGS.problem(PAIR)
    expected = dense_lubricated_mobility(problem)  # 2 kT / dt = 1
    root = brownian.NearFieldRoot(problem.Delta_R, method, SETTINGS.shift(1e-12), 1e-10)
    z = covariance_z(increments(problem, root, samples, seed=11), expected)
    assert np.abs(z).max() < Z_LIMIT, np.abs(z).max()


def test_negative_control_increments_without_the_near_field_noise_fail():
    problem = SETTINGS.problem(PAIR)
    expected = dense_lubricated_mobility(problem)
    no_near_field = brownian.NearFieldRoot(problem.Delta_R * 0.0, 'lanczos')
    z = covariance_z(increments(problem, no_near_field, 2000, seed=11), expected)
    assert np.abs(z).max() > Z_LIMIT, np.abs(z).max()  # measured 6.6: fails the test above


def finite_difference_divergence(mobility_at, locations, h=1e-4):
    """``sum_j d M[:, j] / d q_j`` over the translational coordinates q_j (6N,), by central differences."""
    n = locations.shape[0]
    divergence = np.zeros(6 * n)
    for body in range(n):
        for axis in range(3):
            step = np.zeros_like(locations)
            step[body, axis] = h
            column = 6 * body + axis
            plus, minus = mobility_at(locations + step), mobility_at(locations - step)
            divergence += (plus[:, column] - minus[:, column]) / (2 * h)
    return divergence


def drift_z(samples, expected):
    return (samples.mean(axis=0) - expected) / (samples.std(axis=0, ddof=1) / np.sqrt(samples.shape[0]))


def test_random_finite_difference_drift_equals_divergence_of_M_lub():
    locations = np.array([[0.0, 0.0, 1.5], [2.35, 0.4, 1.7]])  # r = 2.39 a, h = 1.5 a, 1.7 a
    expected = finite_difference_divergence(lambda q: dense_lubricated_mobility(SETTINGS.problem(q)), locations)
    rng = np.random.default_rng(2)
    samples = np.array([brownian.thermal_drift(SETTINGS, locations, rng.standard_normal(12), 1.0, 1e-10).ravel()
                        for _ in range(1500)])
    z = drift_z(samples, expected)
    assert np.abs(z).max() < Z_LIMIT, z
    # negative control: the far field's divergence alone is not the drift of M_lub
    far = finite_difference_divergence(lambda q: dense_far_field_mobility(SETTINGS.problem(q)), locations)
    assert np.abs(drift_z(samples, far)).max() > 2 * Z_LIMIT


def test_far_field_rfd_mean_is_divergence_of_M():
    locations = np.array([[0.0, 0.0, 1.5], [2.35, 0.4, 1.7]])
    expected = finite_difference_divergence(lambda q: dense_far_field_mobility(SETTINGS.problem(q)), locations)
    rng = np.random.default_rng(3)
    samples = np.array([brownian.far_field_drift(SETTINGS, locations, rng.standard_normal(12), 1.0).ravel()
                        for _ in range(3000)])
    assert np.abs(drift_z(samples, expected)).max() < Z_LIMIT
    lubricated = finite_difference_divergence(lambda q: dense_lubricated_mobility(SETTINGS.problem(q)), locations)
    assert np.abs(drift_z(samples, lubricated)).max() > 2 * Z_LIMIT  # negative control


def test_rfd_step_scaled_by_the_radius():
    scaled = brownian.lubrication_settings(0.5, 1.0, rfd_scaled_by_a=True)
    assert scaled.delta == pytest.approx(0.5e-3) and SETTINGS.delta == 1e-3


THREE = np.array([[0.0, 0.0, 1.5], [2.3, 0.0, 1.4], [1.0, 2.2, 1.3]])


def test_torque_from_omega_holds_the_rotation_rate_and_the_cap_limits_it():
    problem = SETTINGS.problem(THREE)
    forces = np.random.default_rng(0).standard_normal((3, 3))
    torques = integrators.torque_from_omega(problem, forces, 2.0, tolerance=1e-11)
    M_lub = dense_lubricated_mobility(problem)
    velocities = (M_lub @ np.hstack((forces, torques)).ravel()).reshape(3, 6)
    np.testing.assert_allclose(velocities[:, 3:], np.tile([0.0, 2.0, 0.0], (3, 1)), atol=1e-8)
    cap = 0.5 * np.linalg.norm(torques, axis=1).min()
    capped = integrators.torque_from_omega(problem, forces, 2.0, tolerance=1e-11, torque_cap=cap)
    np.testing.assert_allclose(np.linalg.norm(capped, axis=1), cap)
    np.testing.assert_allclose(capped / np.linalg.norm(capped, axis=1)[:, None],
                               torques / np.linalg.norm(torques, axis=1)[:, None], atol=1e-12)


def gravity(locations, orientations):
    force_torque = np.zeros((locations.shape[0], 6))
    force_torque[:, 2] = -1.0
    force_torque[:, 0] = 0.3 * np.sin(locations[:, 1])
    force_torque[:, 4] = 0.2
    return force_torque


def dense_velocities(locations):
    return (dense_lubricated_mobility(SETTINGS.problem(locations)) @ gravity(locations, None).ravel()).reshape(-1, 6)


def test_deterministic_trapezoidal_step_is_heun_and_euler_maruyama_is_euler():
    dt = 0.05
    orientations = np.tile([1.0, 0.0, 0.0, 0.0], (3, 1))
    first = dense_velocities(THREE)
    heun = 0.5 * (first + dense_velocities(THREE + dt * first[:, :3]))
    step = integrators.trapezoidal_step(SETTINGS, THREE, orientations, gravity, 0.0, dt, None, 1e-12)
    np.testing.assert_allclose(step.locations, THREE + dt * heun[:, :3], rtol=0, atol=1e-10)
    angle = dt * np.linalg.norm(heun[:, 3:], axis=1)
    np.testing.assert_allclose(step.orientations[:, 0], np.cos(angle / 2), atol=1e-10)
    euler = integrators.euler_maruyama_step(SETTINGS, THREE, orientations, gravity, 0.0, dt, None, 1e-12)
    np.testing.assert_allclose(euler.locations, THREE + dt * first[:, :3], rtol=0, atol=1e-10)
    assert step.counts['factorisations'] == 2 and step.counts['assemblies'] == 2


def test_steps_through_the_wall_or_too_long_are_rejected_and_counted():
    orientations = np.tile([1.0, 0.0, 0.0, 0.0], (3, 1))

    def down(locations, orientations):
        force_torque = np.zeros((3, 6))
        force_torque[:, 2] = -1e4
        return force_torque
    step = integrators.trapezoidal_step(SETTINGS, THREE, orientations, down, 0.0, 1.0, None, 1e-8)
    assert (step.rejected_wall, step.rejected_jump) == (1, 0)
    np.testing.assert_array_equal(step.locations, THREE)

    def sideways(locations, orientations):
        force_torque = np.zeros((3, 6))
        force_torque[:, 0] = 200.0  # about 5 a in one step, parallel to the wall
        return force_torque
    step = integrators.trapezoidal_step(SETTINGS, THREE, orientations, sideways, 0.0, 1.0, None, 1e-8)
    assert (step.rejected_wall, step.rejected_jump) == (0, 1)
    baseline = integrators.rpb_step(SETTINGS, THREE, orientations, sideways, 0.0, 1.0, None)
    assert baseline.rejected_jump == 1


def test_stochastic_steps_run_and_move_the_spheres():
    rng = np.random.default_rng(5)
    orientations = np.tile([1.0, 0.0, 0.0, 0.0], (3, 1))
    for step_function in (integrators.trapezoidal_step, integrators.euler_maruyama_step, integrators.rpb_step):
        step = step_function(SETTINGS, THREE, orientations, gravity, 0.01, 1e-3, rng)
        assert step.rejected_wall == step.rejected_jump == 0
        assert 0 < np.abs(step.locations - THREE).max() < 0.1


# ---------------------------------------------------------------- Gibbs-Boltzmann with lubrication
# Scene of the package's other Gibbs-Boltzmann tests (tests/test_stochastic.py): a = 1, eta = 1/(6 pi) (mu0 = 1),
# kT = 1, weight 2, soft wall eps = 2, b = 0.25; here every sphere also has its lubrication wall term.  Spheres
# 25 a apart (no pair within the cutoff), started from an exact sample of the height density, so each
# sphere's time-averaged height is an unbiased estimate of <z>; standard errors from the spread over spheres.
GB_ETA, GB_KT, GB_WEIGHT, GB_EPS, GB_B = 1.0 / (6.0 * np.pi), 1.0, 2.0, 2.0, 0.25
GB_GRID = np.linspace(1e-3, 25.0, 200001)


def gb_density(z):
    U = GB_WEIGHT * z + np.where(z < 1.0, GB_EPS + GB_EPS * (1.0 - z) / GB_B, GB_EPS * np.exp(-(z - 1.0) / GB_B))
    return np.exp(-U / GB_KT)


GB_CDF = np.cumsum(gb_density(GB_GRID))
GB_CDF /= GB_CDF[-1]
GB_MEAN = np.trapezoid(GB_GRID * gb_density(GB_GRID), GB_GRID) / np.trapezoid(gb_density(GB_GRID), GB_GRID)
GB_EDGES = np.concatenate(([0.0], np.interp(np.arange(1, 8) / 8.0, GB_CDF, GB_GRID), [25.0]))  # 8 bins of 1/8
GB_CHI2_LIMIT = 24.0  # sum of 8 squared bin z-scores: about chi^2 with 7 degrees of freedom, p = 0.001
GB_WINDOW = 10


def gb_forces(locations, orientations):
    z = locations[:, 2]
    force_torque = np.zeros((locations.shape[0], 6))
    wall = np.where(z < 1.0, GB_EPS / GB_B, GB_EPS / GB_B * np.exp(-(z - 1.0) / GB_B))
    force_torque[:, 2] = -GB_WEIGHT + wall
    return force_torque


def run_lubricated_heights(n_spheres, n_steps, dt, seed, rfd=True):
    """Per-sphere mean heights (n,), bin fractions (n, 8) and in-plane window displacements (windows, n, 2)."""
    rng = np.random.default_rng(seed)
    side = int(np.ceil(np.sqrt(n_spheres)))
    grid = np.array([(i, j) for i in range(side) for j in range(side)][:n_spheres], dtype=float) * 25.0
    locations = np.column_stack((grid, np.interp(rng.random(n_spheres), GB_CDF, GB_GRID)))
    orientations = np.tile([1.0, 0.0, 0.0, 0.0], (n_spheres, 1))
    settings = brownian.lubrication_settings(1.0, GB_ETA)
    heights, windows, start = [], [], locations[:, :2].copy()
    for n in range(n_steps):
        step = integrators.trapezoidal_step(settings, locations, orientations, gb_forces, GB_KT, dt, rng, 1e-6,
                                            rfd=rfd)
        assert step.rejected_wall == step.rejected_jump == 0
        locations, orientations = step.locations, step.orientations
        heights.append(locations[:, 2])
        if (n + 1) % GB_WINDOW == 0:
            windows.append(locations[:, :2] - start)
            start = locations[:, :2].copy()
    heights = np.array(heights)
    bins = np.stack([np.mean((heights >= lo) & (heights < hi), axis=0) for lo, hi in zip(GB_EDGES[:-1],
                                                                                          GB_EDGES[1:])], axis=1)
    return heights.mean(axis=0), bins, np.array(windows)


def mean_lubricated_parallel_mobility():
    """<mu_par> of one sphere with its lubrication wall term over the exact height density (quadrature)."""
    z = np.linspace(1.0 + 1e-3, 12.0, 600)
    mu = np.array([dense_lubricated_mobility(SETTINGS_GB.problem([[0.0, 0.0, h]]))[0, 0] for h in z])
    density = gb_density(z)
    # heights below 1 + 1e-3 carry about 1e-3 of the weight and move by the clamped (tiny) mobility: left out
    return np.trapezoid(mu * density, z) / np.trapezoid(gb_density(GB_GRID), GB_GRID)


SETTINGS_GB = brownian.lubrication_settings(1.0, GB_ETA)


def sphere_z_scores(z_means, bins):
    def z(values, expected):
        return (values.mean(axis=0) - expected) / (values.std(axis=0, ddof=1) / np.sqrt(values.shape[0]))
    return z(z_means, GB_MEAN), z(bins, np.full(8, 1.0 / 8.0))


@pytest.mark.slow
def test_gibbs_boltzmann_heights_with_lubrication_and_a_wrong_equilibrium_without_the_drift():
    z_means, bins, windows = run_lubricated_heights(150, 300, 0.01, seed=100)
    mean_score, bin_scores = sphere_z_scores(z_means, bins)
    assert abs(mean_score) < 4.0, (z_means.mean(), GB_MEAN, mean_score)
    assert np.sum(bin_scores ** 2) < GB_CHI2_LIMIT, np.round(bin_scores, 2)
    # the spheres move at the equilibrium rate: E|dx, dy|^2 = 4 kT <mu_par> tau over windows of tau
    per_sphere = np.mean(np.sum(windows ** 2, axis=2), axis=0) / (4.0 * GB_WINDOW * 0.01)
    expected = GB_KT * mean_lubricated_parallel_mobility()
    motion = (per_sphere.mean() - expected) / (per_sphere.std(ddof=1) / np.sqrt(per_sphere.size))
    assert abs(motion) < 4.0, (per_sphere.mean(), expected, motion)  # measured 0.68
    wrong_kT = (per_sphere.mean() - 1.25 * expected) / (per_sphere.std(ddof=1) / np.sqrt(per_sphere.size))
    assert abs(wrong_kT) > 4.0  # the motion check sees a 25 % wrong kT (measured -9.6)
    # negative control: without the far-field drift term of the corrector the heights leave the equilibrium
    z_means, bins, _ = run_lubricated_heights(150, 300, 0.01, seed=100, rfd=False)
    mean_score, bin_scores = sphere_z_scores(z_means, bins)
    assert abs(mean_score) > 4.0 or np.sum(bin_scores ** 2) > GB_CHI2_LIMIT  # measured chi^2 38 (6.0 with it)
