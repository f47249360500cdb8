"""Sphere above a wall (sphere/): mobilities against exact values, laws, and the short-time rotational MSD.

Exact values: VALIDATION.md section 2.1 (bispherical-coordinate series of
Brenner, Jeffery, O'Neill and Dean & O'Neill), normalised by 1/(6 pi eta R)
(translation), 1/(8 pi eta R^3) (rotation) and 1/(6 pi eta R^2) (coupling,
rolling sense).
"""
import numpy as np
import pytest

import mobility
from sphere import sphere as sph
from sphere.rigid_msd import rotational_displacements
from sphere.single_body_integrators import SingleBodyIntegrator, quaternion_products, quaternions_from_rotations
from quaternion_integrator.quaternion import Quaternion, rotation_matrices

# h/R: (mu_par, mu_perp, rot_par, rot_perp, coupling), exact.
EXACT = {1.01: (0.29612, 0.00981, 0.45228, 0.84513, 3.654e-2),
         1.05: (0.38703, 0.04633, 0.60324, 0.87326, 3.201e-2),
         1.1: (0.44305, 0.08727, 0.68955, 0.89520, 2.703e-2),
         1.2: (0.51279, 0.15771, 0.78434, 0.92318, 1.994e-2),
         1.5: (0.62681, 0.31197, 0.90069, 0.96237, 9.355e-3),
         2.0: (0.72321, 0.47047, 0.95991, 0.98432, 3.488e-3),
         3.0: (0.81489, 0.63727, 0.98834, 0.99537, 8.217e-4),
         5.0: (0.88821, 0.77816, 0.99750, 0.99900, 1.227e-4),
         10.0: (0.94386, 0.88795, 0.99969, 0.99987, 8.503e-6)}

# Stated accuracy (relative) of each formula of best_known_mobility, per height (doc/sphere.md).
# par: Goldman-Cox-Brenner at 1.01, Faucheux-Libchaber above; perp: Huang-Breuer;
# rotation and coupling: the 162-blob table.  None: not claimed (coupling near contact).
TOLERANCE = {1.01: (0.005, 0.008, 0.13, 0.005, None),
             1.05: (0.025, 0.008, 0.04, 0.005, None),
             1.1: (0.046, 0.008, 0.02, 0.005, 0.11),
             1.2: (0.040, 0.008, 0.01, 0.005, 0.015),
             1.5: (0.013, 0.008, 0.003, 0.005, 0.015),
             2.0: (0.003, 0.008, 0.003, 0.005, 0.015),
             3.0: (0.003, 0.003, 0.003, 0.005, 0.015),
             5.0: (0.003, 0.003, 0.003, 0.005, 0.015),
             10.0: (0.003, 0.003, 0.003, 0.005, 0.015)}


def normalised_entries(N, eta, a):
    """(par, perp, rot_par, rot_perp, coupling) of one 6x6 mobility, normalised."""
    t, r, c = 6 * np.pi * eta * a, 8 * np.pi * eta * a ** 3, 6 * np.pi * eta * a ** 2
    return np.array([N[0, 0] * t, N[2, 2] * t, N[3, 3] * r, N[5, 5] * r, N[4, 0] * c])


@pytest.mark.parametrize('h_over_R', sorted(EXACT))
def test_best_known_mobility_within_stated_accuracy_of_exact(h_over_R):
    eta, a = 1.3, 0.7
    got = normalised_entries(sph.best_known_mobility(h_over_R * a, eta, a)[0], eta, a)
    for name, value, exact, tol in zip(('par', 'perp', 'rot_par', 'rot_perp', 'coupling'), got,
                                       EXACT[h_over_R], TOLERANCE[h_over_R]):
        if tol is not None:
            assert abs(value / exact - 1.0) < tol, (h_over_R, name, value, exact)


def test_formula_transcriptions_match_published_approximation_values():
    """VALIDATION 2.1 lists Faucheux-Libchaber and Bevan-Prieve (Huang-Breuer) values at the table heights."""
    heights = np.array([1.1, 1.2, 1.5, 2.0, 3.0, 5.0, 10.0])
    faucheux = [0.42368, 0.49370, 0.61908, 0.72144, 0.81470, 0.88820, 0.94386]
    bevan_prieve = [0.08784, 0.15842, 0.31250, 0.47059, 0.63636, 0.77612, 0.88576]
    np.testing.assert_allclose(sph.faucheux_parallel(heights, 1.0), faucheux, atol=6e-6)
    np.testing.assert_allclose(sph.huang_breuer_perpendicular(heights, 1.0), bevan_prieve, atol=6e-6)
    # Goldman-Cox-Brenner lubrication value quoted at h/R = 1.1.
    assert sph.goldman_parallel(1.1, 1.0) == pytest.approx(0.45764, abs=6e-6)


def test_parallel_mobility_is_continuous_at_the_switch():
    h = sph.GOLDMAN_FAUCHEUX_SWITCH
    assert sph.goldman_parallel(h, 1.0) == pytest.approx(sph.faucheux_parallel(h, 1.0), rel=2e-6)
    below, above = sph.parallel_translation(np.array([h - 1e-9, h + 1e-9]), 1.0)
    assert below == pytest.approx(above, rel=1e-5)


def test_swan_brady_matches_validation_table_and_the_blob_kernels():
    heights = [1.1, 1.2, 1.5, 2.0, 3.0, 5.0, 10.0]
    table = [(0.54374, 0.27531, 0.76521, 0.90609, 6.403e-2), (0.57847, 0.30162, 0.81916, 0.92766, 4.521e-2),
             (0.65381, 0.38169, 0.90741, 0.96296, 1.852e-2), (0.73242, 0.49609, 0.96094, 0.98438, 5.859e-3),
             (0.81687, 0.64300, 0.98843, 0.99537, 1.157e-3), (0.88848, 0.77896, 0.99750, 0.99900, 1.500e-4),
             (0.94387, 0.88800, 0.99969, 0.99987, 9.375e-6)]
    eta, a = 1.3, 0.7
    for h, row in zip(heights, table):
        got = normalised_entries(sph.swan_brady_mobility(h * a, eta, a)[0], eta, a)
        np.testing.assert_allclose(got, row, rtol=1e-4, atol=6e-6)
    # The same 6x6 from the mobility package's one-blob products (heights also below a: regularised).
    for h in [0.3, 0.9, 1.0, 1.37, 4.0]:
        r = np.array([[0.2, -0.1, h * a]])
        blocks = np.zeros((6, 6))
        for j in range(3):
            e = np.zeros(3)
            e[j] = 1.0
            blocks[:3, j] = mobility.single_wall_mobility_trans_times_force(r, e, eta, a)
            blocks[:3, 3 + j] = mobility.single_wall_mobility_trans_times_torque(r, e, eta, a)
            blocks[3:, j] = mobility.single_wall_mobility_rot_times_force(r, e, eta, a)
            blocks[3:, 3 + j] = mobility.single_wall_mobility_rot_times_torque(r, e, eta, a)
        np.testing.assert_allclose(sph.swan_brady_mobility(h * a, eta, a)[0], blocks, rtol=1e-12,
                                   atol=1e-14 * np.abs(blocks).max())


@pytest.mark.parametrize('model', sorted(sph.MOBILITY_MODELS))
def test_mobilities_symmetric_positive_definite_with_rolling_coupling(model):
    a = 0.5
    h = a * np.concatenate((1.0 + np.geomspace(1e-3, 0.5, 20), np.linspace(1.6, 100.0, 40)))
    N = sph.MOBILITY_MODELS[model](h, 1.0, a)
    np.testing.assert_array_equal(N, np.swapaxes(N, 1, 2))
    assert np.all(np.linalg.eigvalsh(N) > 0.0)
    assert np.all(N[:, 4, 0] > 0.0) and np.all(N[:, 3, 1] < 0.0)      # w_y = +c F_x, w_x = -c F_y
    np.testing.assert_array_equal(N[:, 0, 0], N[:, 1, 1])
    np.testing.assert_array_equal(N[:, 3, 3], N[:, 4, 4])


def test_rotation_table_reproduces_from_the_package_shell():
    """Rows of the shipped table are recomputed by the documented generator (same shell, same kernel)."""
    from sphere.make_mobility_table import table_rows
    table = sph.rotation_table().table
    rows = table[[10, 45, 75]]
    recomputed, shell = table_rows(162, heights=rows[:, 0], implementation='python')
    np.testing.assert_allclose(recomputed, rows, rtol=1e-9, atol=1e-15)
    assert shell['blob_radius'] == pytest.approx(0.13101, abs=1e-5)       # VALIDATION 2.2


def test_rotation_table_far_field_continuation():
    table = sph.rotation_table()
    h_end = table.h[-1]
    inside = np.array(table(h_end - 1e-9))
    outside = np.array(table(h_end + 1e-9))
    np.testing.assert_allclose(inside, outside, rtol=1e-6)
    rot_par, rot_perp, coupling = table(200.0)
    x = 1.0 / 200.0
    assert 1.0 - rot_par == pytest.approx(5.0 * x ** 3 / 16.0, rel=0.02)
    assert 1.0 - rot_perp == pytest.approx(x ** 3 / 8.0, rel=0.02)
    assert coupling == pytest.approx(3.0 * x ** 4 / 32.0, rel=0.2)   # exact/far-field -> 1 slowly (VALIDATION)


def test_vectorised_quaternion_helpers_match_quaternion_class():
    rng = np.random.default_rng(5)
    phi = rng.normal(size=(6, 3))
    phi[0] = 0.0
    q = rng.normal(size=(6, 4))
    got_rot = quaternions_from_rotations(phi)
    got_prod = quaternion_products(got_rot, q)
    for k in range(6):
        ref = Quaternion.from_rotation(phi[k])
        np.testing.assert_allclose(got_rot[k], ref.entries, atol=1e-15)
        np.testing.assert_allclose(got_prod[k], (ref * Quaternion(q[k])).entries, atol=1e-14)
    # Rotational displacement of a rotation by angle t about n is sin(t) n.
    R = rotation_matrices(quaternions_from_rotations(phi))
    angle = np.linalg.norm(phi, axis=1)
    expected = np.sin(angle)[:, None] * phi / np.where(angle > 0, angle, 1.0)[:, None]
    np.testing.assert_allclose(rotational_displacements(np.tile(np.eye(3), (6, 1, 1)), R), expected, atol=1e-14)


def equilibrium_samples(model, kT, n, rng):
    """Heights and orientations drawn by rejection from exp(-U/kT) (height and orientation are independent)."""
    h_grid = np.linspace(model.a, model.a + 40.0 * kT / model.weight, 40001)[1:]
    density = np.exp(-(model.weight * h_grid + sph.wall_potential(h_grid, model.a, model.repulsion_strength,
                                                                  model.debye_length)) / kT)
    bound = density.max() * 1.01
    heights = []
    while sum(len(h) for h in heights) < n:
        h = rng.uniform(h_grid[0], h_grid[-1], 4 * n)
        p = np.exp(-(model.weight * h + sph.wall_potential(h, model.a, model.repulsion_strength,
                                                           model.debye_length)) / kT)
        assert p.max() < bound
        heights.append(h[rng.uniform(size=h.size) * bound < p])
    heights = np.concatenate(heights)[:n]
    # Orientation: exp(-w (R d)_z / kT) with d the centre-of-mass offset; proposals uniform (Haar).
    offset_z_max = np.linalg.norm(model.com_offset)
    orientations = []
    while sum(len(o) for o in orientations) < n:
        q = rng.normal(size=(4 * n, 4))
        q /= np.linalg.norm(q, axis=1)[:, None]
        arm_z = (rotation_matrices(q) @ model.com_offset)[:, 2]
        accept = rng.uniform(size=q.shape[0]) < np.exp(-model.weight * (arm_z + offset_z_max) / kT)
        orientations.append(q[accept])
    orientations = np.concatenate(orientations)[:n]
    locations = np.column_stack((np.zeros(n), np.zeros(n), heights))
    mean_density = density / np.trapezoid(density, h_grid)
    return locations, orientations, h_grid, mean_density


def test_short_time_rotational_msd_slope_is_2_kT_mu_rr():
    """MSD_u(t) / (2 kT <mu_rr> t) -> 1 at short times, for spheres started at equilibrium.

    n = 50000 spheres, t = 4 dt = 0.02 (RFD, best mobility): the standard
    error of the ratio is about sqrt(2/n) = 0.6% per component; the bias from
    the curvature of the rotational displacement (sin^2 of the angle) is
    about -0.4%.  Tolerance: 3 standard errors plus 0.5%.  The same
    measurement rejects a mobility 5% off (negative control).
    """
    rng = np.random.default_rng(11)
    model = sph.SphereModel('best')
    locations, orientations, h_grid, density = equilibrium_samples(model, sph.KT, 50000, rng)
    N_grid = model.mobility(np.column_stack((0 * h_grid, 0 * h_grid, h_grid)), None)
    mean_mu = np.trapezoid(N_grid * density[:, None, None], h_grid, axis=0)
    integrator = SingleBodyIntegrator('RFD', model.mobility, model.force_torque, sph.KT, model.is_valid, rng)
    dt, n_steps = 0.005, 4
    loc, orient = locations, orientations
    for _ in range(n_steps):
        loc, orient = integrator.step(loc, orient, dt)
    t = dt * n_steps
    u = rotational_displacements(rotation_matrices(orientations), rotation_matrices(orient))
    for k in range(3):
        samples = u[:, k] ** 2 / (2.0 * sph.KT * mean_mu[3 + k, 3 + k] * t)
        ratio, standard_error = samples.mean(), samples.std(ddof=1) / np.sqrt(samples.size)
        assert abs(ratio - 1.0) < 3.0 * standard_error + 0.005, (k, ratio, standard_error)
        assert abs(ratio / 1.05 - 1.0) > 3.0 * standard_error / 1.05 + 0.005, (k, ratio, standard_error)


def test_sphere_equilibrium_height_rfd_matches_gibbs_boltzmann_em_does_not():
    """Mean height change from an exact equilibrium sample: zero for RFD and FIXMAN, negative for EM.

    A heavy sphere held close to the wall, where the mobility changes fast
    (best mobility, weight 2, wall strength 0.2 and length 0.1: <h> = 1.53 a),
    2000 spheres, 100 steps of dt = 0.02.  Statistic: per sphere, the time
    average of h minus its initial h; its standard error comes from the
    spread over the independent spheres.  Pass: |mean| < 3 SE; EM (no kT
    div N drift) must fail with mean < -3 SE (it gives about -6.6 SE here).
    The time-averaged height is also compared with the quadrature mean of the
    exact density (3 SE), and the one-step displacements with the mobility
    (the spheres must move at the equilibrium rate).
    """
    rng = np.random.default_rng(3)
    model = sph.SphereModel('best', weight=2.0, repulsion_strength=0.2, debye_length=0.1)
    locations, orientations, h_grid, density = equilibrium_samples(model, sph.KT, 2000, rng)
    exact_mean = np.trapezoid(h_grid * density, h_grid)
    h0 = locations[:, 2]
    assert abs(h0.mean() - exact_mean) < 4.0 * h0.std() / np.sqrt(h0.size)
    results = {}
    for scheme in ('RFD', 'FIXMAN', 'EM'):
        integrator = SingleBodyIntegrator(scheme, model.mobility, model.force_torque, sph.KT, model.is_valid,
                                          np.random.default_rng(4))
        loc, orient = locations, orientations
        total = np.zeros(h0.size)
        squared, predicted = np.zeros(h0.size), np.zeros(h0.size)
        for step in range(100):
            if step % 10 == 0:  # one-step displacement against 2 kT dt tr N_tt at the step's start
                predicted += 2.0 * sph.KT * 0.02 * np.trace(model.mobility(loc, orient)[:, :3, :3], axis1=1, axis2=2)
                before = loc
            loc, orient = integrator.step(loc, orient, 0.02)
            if step % 10 == 0:
                squared += np.sum((loc - before) ** 2, axis=1)
            total += loc[:, 2]
        average = total / 100
        change = average - h0
        ratio = squared / predicted
        motion = (ratio.mean() - np.array([1.0, 1.25])) / (ratio.std(ddof=1) / np.sqrt(h0.size))
        results[scheme] = (change.mean() / (change.std(ddof=1) / np.sqrt(h0.size)),
                           (average.mean() - exact_mean) / (average.std(ddof=1) / np.sqrt(h0.size)),
                           motion[0], motion[1])
    for scheme in ('RFD', 'FIXMAN'):
        assert abs(results[scheme][0]) < 3.0 and abs(results[scheme][1]) < 3.0, (scheme, results)
    assert results['EM'][0] < -3.0, results
    # A frozen integrator keeps the exact start (change 0) and would pass the above: every scheme must also
    # move at the rate of the fluctuation-dissipation law, E[|dr|^2 | state] = 2 kT dt tr N_tt(state) +
    # O(dt^2), on every 10th step (ratio of the sums per sphere within 4 SE of 1, SE from the spread over the
    # spheres), and the same statistic must reject a rate 25 % off (a wrong kT).
    for scheme in ('RFD', 'FIXMAN', 'EM'):
        assert abs(results[scheme][2]) < 4.0 and abs(results[scheme][3]) > 4.0, (scheme, results)


def test_sphere_rotational_msd_script_writes_msd_and_heights(tmp_path, monkeypatch):
    import utils
    from sphere import sphere_rotational_msd as script
    monkeypatch.chdir(tmp_path)
    status = script.main(['-dt', '0.01', '-N', '220', '-end', '1.0', '--runs', '3', '--burn-in', '10',
                          '--seed', '2', '--data-dir', str(tmp_path / 'data'), '--data-name', 'smoke'])
    assert status == 0
    stem = tmp_path / 'data' / 'sphere-msd-dt-0.01-N-220-scheme-RFD-mobility-best-smoke'
    table = np.loadtxt(str(stem) + '.txt')
    assert table.shape == (script.NUM_LAGS, 13)
    assert np.all(table[0, 1:] == 0.0) and np.all(table[1:, 1:7] > 0.0) and np.all(table[1:, 7:] >= 0.0)
    heights = np.loadtxt(str(stem) + '.heights.txt')
    assert heights[:, 1].sum() * script.BIN_WIDTH == pytest.approx(1.0)
    assert np.trapezoid(heights[:, 2], heights[:, 0]) == pytest.approx(1.0, abs=0.02)
    with pytest.raises(utils.UserInputError, match='-N 100 is too short'):
        script.main(['-dt', '0.01', '-N', '100', '-end', '1.0', '--data-dir', str(tmp_path / 'data')])
