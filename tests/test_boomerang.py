"""The boomerang of Delong et al. 2015 (boomerang/): geometry, forces, mobility laws, files, Gibbs-Boltzmann."""
import os

import numpy as np
import pytest

import mobility
import utils
from body.body import Body
from boomerang import boomerang_model as bm
from quaternion_integrator.quaternion import Quaternion
from sphere.rigid_msd import lagged_msd, msd_statistics
from sphere.single_body_integrators import SingleBodyIntegrator, move

BACKEND = 'C++' if mobility.backends.is_usable('C++') else 'python'


def random_orientations(rng, n):
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1)[:, None]


# ------------------------------------------------------------------ geometry and constants
def test_constants_are_those_of_the_paper():
    assert bm.A == pytest.approx(0.324557, abs=1e-6)                       # VALIDATION T4
    assert bm.KT == pytest.approx(0.0041419464, rel=1e-12)
    assert bm.TOTAL_WEIGHT / 15 == pytest.approx(1.539384e-4, rel=1e-6)
    assert bm.REPULSION_STRENGTH == pytest.approx(7.5 * 0.0041419464)
    assert bm.DEBYE_LENGTH == pytest.approx(0.5 * bm.A)


def test_geometry_laws():
    ref = bm.reference_configuration()
    assert ref.shape == (15, 3)
    assert np.sum(np.all(ref == 0.0, axis=1)) == 1                          # one blob at the apex
    x_arm = ref[(ref[:, 0] > 0)]
    y_arm = ref[(ref[:, 1] > 0)]
    assert len(x_arm) == len(y_arm) == 7 and np.all(ref[:, 2] == 0.0)
    np.testing.assert_allclose(np.sort(x_arm[:, 0]), 0.3 * np.arange(1, 8), atol=1e-14)
    np.testing.assert_allclose(np.sort(y_arm[:, 1]), 0.3 * np.arange(1, 8), atol=1e-14)
    # A quarter turn about z maps the x arm onto the y arm; about x it lifts the y arm to +z.
    quarter_z = Quaternion.from_rotation([0.0, 0.0, np.pi / 2]).rotation_matrix()
    np.testing.assert_allclose(np.sort((x_arm @ quarter_z.T)[:, 1]), np.sort(y_arm[:, 1]), atol=1e-14)
    quarter_x = Quaternion.from_rotation([np.pi / 2, 0.0, 0.0]).rotation_matrix()
    np.testing.assert_allclose((y_arm @ quarter_x.T)[:, 2], y_arm[:, 1], atol=1e-14)
    quarter_y = Quaternion.from_rotation([0.0, np.pi / 2, 0.0]).rotation_matrix()
    np.testing.assert_allclose((x_arm @ quarter_y.T)[:, 2], -x_arm[:, 0], atol=1e-14)
    # Stacked blob positions agree with Body, and pairwise distances do not depend on the orientation.
    model = bm.BoomerangModel(1.0, 'python')
    rng = np.random.default_rng(1)
    locations = rng.normal(size=(4, 3)) + [0.0, 0.0, 3.0]
    orientations = random_orientations(rng, 4)
    r = model.blob_positions(locations, orientations)
    distances = np.linalg.norm(ref[:, None] - ref[None], axis=2)
    for k in range(4):
        body = Body(locations[k], orientations[k], ref, bm.A)
        np.testing.assert_allclose(r[k], body.get_r_vectors(), atol=1e-14)
        np.testing.assert_allclose(np.linalg.norm(r[k][:, None] - r[k][None], axis=2), distances, atol=1e-13)


def potential_independent(locations, orientations, gfactor):
    """U = sum_i [w z_i + eps exp(-(z_i - A)/b) / (z_i - A)], written here from the paper's constants."""
    ref = bm.reference_configuration()
    z = np.empty((len(locations), 15))
    for k, (x, q) in enumerate(zip(locations, orientations)):
        z[k] = (x + ref @ Quaternion(q).rotation_matrix().T)[:, 2]
    gap = z - bm.A
    w = 1.1781 * 0.0000000002 * (9.8 * 1.e6) / 15 * gfactor
    return np.sum(w * z + 7.5 * bm.KT * np.exp(-gap / (0.5 * bm.A)) / gap, axis=1)


def test_force_and_torque_are_minus_the_gradient_of_the_potential():
    gfactor = 3.0
    model = bm.BoomerangModel(gfactor, 'python')
    rng = np.random.default_rng(2)
    locations = np.array([[0.1, -0.2, 1.9], [0.0, 0.3, 2.4]])
    orientations = random_orientations(rng, 2)
    assert np.all(model.is_valid(locations, orientations))
    np.testing.assert_allclose(model.potential(locations, orientations),
                               potential_independent(locations, orientations, gfactor), rtol=1e-13)
    ft = model.force_torque(locations, orientations)
    h = 1e-6
    for j in range(6):
        e = np.zeros((2, 6))
        e[:, j] = h
        plus = potential_independent(*move(locations, orientations, e), gfactor)
        minus = potential_independent(*move(locations, orientations, -e), gfactor)
        np.testing.assert_allclose(ft[:, j], -(plus - minus) / (2 * h), rtol=1e-6, atol=1e-9)


# ------------------------------------------------------------------ mobility laws
def test_body_mobility_symmetric_positive_definite_and_same_on_every_path():
    rng = np.random.default_rng(3)
    locations = np.array([[0.0, 0.0, 2.0], [1.0, -1.0, 2.8], [0.0, 0.5, 3.5]])
    orientations = np.array([[1.0, 0.0, 0.0, 0.0]] + list(random_orientations(rng, 2)))
    python = bm.BoomerangModel(1.0, 'python')
    assert np.all(python.is_valid(locations, orientations))
    stacked = python.mobility(locations, orientations)
    for k in range(3):
        single = python.mobility(locations[k:k + 1], orientations[k:k + 1])[0]   # dense_body_mobility path
        np.testing.assert_allclose(stacked[k], single, rtol=1e-10, atol=1e-10 * np.abs(single).max())
        np.testing.assert_allclose(single, single.T, rtol=0, atol=1e-10 * np.abs(single).max())
        assert np.all(np.linalg.eigvalsh(0.5 * (single + single.T)) > 0.0)
    if mobility.backends.is_usable('C++'):
        cpp = bm.BoomerangModel(1.0, 'C++').mobility(locations, orientations)
        np.testing.assert_allclose(cpp, stacked, rtol=1e-9, atol=1e-10 * np.abs(stacked).max())


def test_transfer_mobility_to_another_tracking_point():
    """Tracking the body at a point p (body frame) gives J N J^T with the lever arm R p."""
    model = bm.BoomerangModel(1.0, 'python')
    location = np.array([[0.2, 0.1, 2.2]])
    orientation = random_orientations(np.random.default_rng(4), 1)
    N_apex = model.mobility(location, orientation)[0]
    p = np.array([0.6, 0.45, 0.0])
    arm = Quaternion(orientation[0]).rotation_matrix() @ p
    shifted = bm.BoomerangModel(1.0, 'python')
    shifted.reference = model.reference - p                  # the body location is now the point p
    N_p = shifted.mobility(location + arm, orientation)[0]
    np.testing.assert_allclose(bm.transfer_mobility(N_apex, arm), N_p, rtol=1e-9, atol=1e-10 * np.abs(N_p).max())


# ------------------------------------------------------------------ the script and its files
def test_boomerang_script_writes_the_published_trajectory_format(tmp_path, monkeypatch):
    from boomerang import boomerang as script
    monkeypatch.chdir(tmp_path)
    (tmp_path / 'config_local.py').write_text('DATA_DIR = %r\n' % str(tmp_path / 'local_data'))
    assert script.main(['-dt', '0.01', '-N', '6', '-scheme', 'FIXMAN', '--data-name', 'x', '--seed', '7']) == 0
    path = tmp_path / 'local_data' / 'boomerang' / 'boomerang-trajectory-dt-0.01-N-6-scheme-FIXMAN-g-1.0-x.txt'
    text = path.read_text().splitlines()
    assert text[0] == 'Parameters:' and 'Trajectory data:' in text and 'Location, Orientation:' in text
    assert text[-1].endswith(' ') and text[-1].count(',') == 6
    parameters, locations, orientations = utils.read_trajectory_file(str(path))
    assert utils.trajectory_parameter(parameters, 'dt') == 0.01 and parameters['scheme'] == 'FIXMAN'
    assert utils.trajectory_parameter(parameters, 'A') == bm.A
    assert locations.shape == (7, 3) and orientations.shape == (7, 4)
    np.testing.assert_array_equal(locations[0], [0.0, 0.0, 2.0])
    np.testing.assert_allclose(np.linalg.norm(orientations, axis=1), 1.0, atol=1e-12)
    assert np.all(bm.BoomerangModel().is_valid(locations, orientations))
    assert os.path.isfile(tmp_path / 'logs' / 'boomerang-trajectory-dt-0.01-N-6-scheme-FIXMAN-g-1.0-x.log')
    # The same seed gives the same trajectory; --data-dir wins over config_local.py.
    assert script.main(['-dt', '0.01', '-N', '6', '-scheme', 'FIXMAN', '--data-name', 'x', '--seed', '7',
                        '--data-dir', str(tmp_path / 'other')]) == 0
    again = tmp_path / 'other' / 'boomerang' / path.name
    np.testing.assert_array_equal(utils.read_trajectory_file(str(again))[1], locations)
    with pytest.raises(utils.UserInputError, match='-dt must be a positive'):
        script.main(['-dt', '0', '-N', '6'])


def test_trajectory_reader_accepts_published_multiline_parameters_and_rejects_bad_lines(tmp_path):
    path = tmp_path / 'published.txt'
    path.write_text('Parameters:\nA: 0.324557390919 \nM: [ 0.00015394  0.00015394\n  0.00015394] \n'
                    'Trajectory data:\nLocation, Orientation:\n'
                    '-0.01, 0.02, 1.88, 0.9995, 0.0307, -0.0034, -0.0039 \n'
                    '-0.07, 0.06, 1.68, 0.9961, 0.0608, -0.0571, -0.0258 \n')
    parameters, locations, orientations = utils.read_trajectory_file(str(path))
    assert parameters['M'] == '[ 0.00015394  0.00015394 0.00015394]'
    assert locations.shape == (2, 3) and orientations[1, 0] == 0.9961
    path.write_text(path.read_text() + '1.0, 2.0\n')
    with pytest.raises(utils.UserInputError, match='line 9: expected 7'):
        utils.read_trajectory_file(str(path))


def test_msd_laws_and_the_analysis_script(tmp_path, monkeypatch):
    # Uniform translation v and rotation about z at rate w: MSD_xx = (v t)^2, rotational u_z = sin(w t).
    n, v, w = 50, 0.3, 0.1
    t = np.arange(n)
    locations = np.column_stack((v * t, 0 * t, 1.0 + 0 * t))
    orientations = np.array([Quaternion.from_rotation([0.0, 0.0, w * k]).entries for k in t])
    msd = lagged_msd(locations, orientations, [0, 1, 5, 20])
    np.testing.assert_allclose(msd[:, 0, 0], (v * np.array([0, 1, 5, 20])) ** 2, rtol=1e-12)
    np.testing.assert_allclose(msd[:, 5, 5], np.sin(w * np.array([0, 1, 5, 20])) ** 2, rtol=1e-12)
    # A tracking point p off the axis: its displacement adds the rotation of p.
    msd_p = lagged_msd(locations, orientations, [5], point=(1.0, 0.0, 0.0))
    t0 = np.arange(n - 5)
    dx = v * 5 + np.cos(w * (t0 + 5)) - np.cos(w * t0)
    dy = np.sin(w * (t0 + 5)) - np.sin(w * t0)
    assert msd_p[0, 0, 0] == pytest.approx(np.mean(dx ** 2), rel=1e-12)
    assert msd_p[0, 1, 1] == pytest.approx(np.mean(dy ** 2), rel=1e-12)
    mean, error = msd_statistics([(locations, orientations), (2 * locations, orientations)], [3])
    assert mean[0, 0, 0] == pytest.approx(0.5 * ((3 * v) ** 2 + (6 * v) ** 2))
    assert error[0, 0, 0] == pytest.approx(np.std([(3 * v) ** 2, (6 * v) ** 2], ddof=1) / np.sqrt(2))

    from boomerang import boomerang as script
    from boomerang import calculate_boomerang_msd_from_trajectories as msd_script
    monkeypatch.chdir(tmp_path)
    for k in range(3):
        script.main(['-dt', '0.01', '-N', '40', '--data-name', 'r%d' % k, '--seed', str(k),
                     '--data-dir', str(tmp_path), '--implementation', BACKEND])
    files = sorted(str(p) for p in (tmp_path / 'boomerang').glob('*.txt'))
    output = tmp_path / 'msd'
    assert msd_script.main(files + ['--end', '0.2', '--output', str(output)]) == 0
    table = np.loadtxt(str(output) + '.txt')
    data = np.load(str(output) + '.npz')
    assert table.shape == (21, 13) and data['msd'].shape == (21, 6, 6)
    np.testing.assert_allclose(table[:, 0], 0.01 * np.arange(21))
    assert np.all(table[1:, 1:7] > 0) and np.all(table[1:, 7:] > 0)      # error bars from the 3 runs
    from boomerang import plot_boomerang_msd, plot_boomerang_trajectory
    assert plot_boomerang_msd.main([str(output) + '.npz', '--slope-mu', '20', '--output', str(tmp_path / 'm.png')]) == 0
    assert plot_boomerang_trajectory.main([files[0], '--output', str(tmp_path / 't.png')]) == 0
    assert (tmp_path / 'm.png').stat().st_size > 0 and (tmp_path / 't.png').stat().st_size > 0


# ------------------------------------------------------------------ Gibbs-Boltzmann
GFACTOR, DT, N_STEPS, N_BODIES = 10.0, 0.01, 80, 400
MOTION_EVERY = 8  # steps between the one-step displacement checks


def exact_height_statistics(gfactor):
    """Quadrature of exp(-U/kT) over the apex height z and the lab-frame direction u = R^T e_z.

    A blob at body-frame position r has height z + r . u and u is uniform on
    the sphere when the orientation is uniform, so the density of (z, u) is
    exp(-U(z, u)/kT) dz du.  Gauss-Legendre in cos(theta) (40 nodes),
    trapezoid in phi (80), midpoint in z (300 points on (A, A + 4)); changing
    to 128 x 192 x 400 moves the means by less than 1e-6 um.  Returns (mean
    apex height, mean blob height, quartiles of the mean blob height, min of U
    over the grid).
    """
    ref = bm.reference_configuration()
    w = 1.1781 * 2e-10 * 9.8e6 / 15 * gfactor

    def U(z, ux, uy):
        zi = z[..., None] + ref[:, 0] * ux[..., None] + ref[:, 1] * uy[..., None]
        gap = zi - bm.A
        with np.errstate(all='ignore'):
            wall = np.where(gap > 0, 7.5 * bm.KT * np.exp(-gap / (0.5 * bm.A)) / gap, np.inf)
        return np.sum(w * zi + wall, axis=-1)

    c, c_weights = np.polynomial.legendre.leggauss(40)
    phi = (np.arange(80) + 0.5) * 2.0 * np.pi / 80
    C, PHI = np.meshgrid(c, phi, indexing='ij')
    ux, uy = (np.sqrt(1 - C ** 2) * np.cos(PHI)).ravel(), (np.sqrt(1 - C ** 2) * np.sin(PHI)).ravel()
    zg = bm.A + (np.arange(300) + 0.5) * 4.0 / 300
    energy = np.array([U(np.full(ux.shape, z), ux, uy) for z in zg])
    u_min = energy.min()
    weight = np.exp(-(energy - u_min) / bm.KT) * np.repeat(c_weights, 80)
    blob_height = zg[:, None] + ref.sum(axis=0)[0] * ux / 15.0 + ref.sum(axis=0)[1] * uy / 15.0
    order = np.argsort(blob_height, axis=None)
    cumulative = np.cumsum(weight.ravel()[order]) / weight.sum()
    quartiles = np.interp([0.25, 0.5, 0.75], cumulative, blob_height.ravel()[order])
    return (np.sum(zg[:, None] * weight) / weight.sum(), np.sum(blob_height * weight) / weight.sum(), quartiles,
            u_min)


def equilibrium_boomerangs(model, u_min, n, rng):
    """Rejection sampling from exp(-U/kT): z uniform on (A, A + 4), orientation uniform (Haar)."""
    bound = u_min - bm.KT            # safely below the minimum of U, so that the acceptance is <= 1
    locations, orientations = [], []
    while sum(len(x) for x in locations) < n:
        m = 100000
        q = random_orientations(rng, m)
        loc = np.zeros((m, 3))
        loc[:, 2] = rng.uniform(bm.A, bm.A + 4.0, m)
        ratio = np.exp(-(model.potential(loc, q) - bound) / bm.KT)
        assert ratio.max() <= 1.0
        accept = rng.uniform(size=m) < ratio
        locations.append(loc[accept])
        orientations.append(q[accept])
    return np.concatenate(locations)[:n], np.concatenate(orientations)[:n]


@pytest.fixture(scope='module')
def equilibrium_ensemble():
    model = bm.BoomerangModel(GFACTOR, BACKEND)
    mean_apex, mean_blob, quartiles, u_min = exact_height_statistics(GFACTOR)
    locations, orientations = equilibrium_boomerangs(model, u_min, N_BODIES, np.random.default_rng(5))
    exact = np.array([mean_apex, mean_blob, 0.25, 0.5, 0.75])
    return model, exact, quartiles, locations, orientations


def observables(model, locations, orientations, quartiles):
    """Per body, shape (nb, 5): apex height, mean blob height, and whether the latter is below each exact quartile."""
    blob_height = model.blob_positions(locations, orientations)[:, :, 2].mean(axis=1)
    return np.column_stack((locations[:, 2], blob_height, blob_height[:, None] < quartiles))


def test_equilibrium_samples_match_the_quadrature(equilibrium_ensemble):
    model, exact, quartiles, locations, orientations = equilibrium_ensemble
    h = observables(model, locations, orientations, quartiles)
    standard_error = h.std(axis=0, ddof=1) / np.sqrt(len(h))
    assert np.all(np.abs(h.mean(axis=0) - exact) < 4.0 * standard_error)


@pytest.mark.parametrize('scheme', ['RFD', 'FIXMAN', 'EM'])
def test_height_distribution_stays_gibbs_boltzmann(scheme, equilibrium_ensemble):
    """400 boomerangs (gfactor 10) from exact equilibrium samples, 80 steps of dt = 0.01 s.

    Observables h per body: apex height, mean blob height, and the indicators
    of the mean blob height being below its three exact quartiles (so the
    distribution, not only the mean, is checked).  For each: the change
    c = (time average of h over the run) - h(0).  At equilibrium E[c] = 0.
    Its spread is reduced with the exact mean m of the quadrature as a
    control variate: s = c - beta (h(0) - m), with beta the regression
    coefficient of c on h(0) over the bodies (E[h(0)] = m, so E[s] = E[c]).
    The standard error of the mean of s (about 0.006 um for the blob height)
    comes from its spread over the independent bodies.  RFD and FIXMAN must
    keep |mean s| < 3 SE, and the time-averaged heights within 3 SE of m.
    EM lacks the drift kT div N, drifts towards the wall and must fail: mean
    s < -3 SE for the mean blob height and > +3 SE for the fraction below the
    median (about -4 and +4 SE here; RFD and FIXMAN stay within 1.7 SE on all five).  dt = 0.02 is
    too large for this stiff wall potential (a blob that reaches a gap of
    0.06 um is thrown further down by the repulsion on every retry).
    """
    model, exact, quartiles, locations, orientations = equilibrium_ensemble
    integrator = SingleBodyIntegrator(scheme, model.mobility, model.force_torque, bm.KT, model.is_valid,
                                      np.random.default_rng(6))
    start = observables(model, locations, orientations, quartiles)
    total = np.zeros_like(start)
    squared, predicted = np.zeros(N_BODIES), np.zeros(N_BODIES)
    loc, orient = locations, orientations
    for step in range(N_STEPS):
        if step % MOTION_EVERY == 0:
            predicted += 2.0 * bm.KT * DT * np.trace(model.mobility(loc, orient)[:, :3, :3], axis1=1, axis2=2)
            before = loc
        loc, orient = integrator.step(loc, orient, DT)
        if step % MOTION_EVERY == 0:
            squared += np.sum((loc - before) ** 2, axis=1)
        total += observables(model, loc, orient, quartiles)
    # An integrator that never moves keeps the exact start and passes the checks below: the apex must also
    # move at the rate of the fluctuation-dissipation law, E[|dr|^2 | state] = 2 kT dt tr N_tt(state) +
    # O(dt^2), on every MOTION_EVERY-th step (all three schemes have this noise); the ratio of the sums
    # per body within 4 SE of 1 (SE from the spread over the bodies), and 25 % off (a wrong kT) rejected.
    ratio = squared / predicted
    motion_z = (ratio.mean() - np.array([1.0, 1.25])) / (ratio.std(ddof=1) / np.sqrt(N_BODIES))
    print(scheme, 'motion ratio %.4f, z-scores against 1 and 1.25: %s' % (ratio.mean(), np.round(motion_z, 2)))
    assert abs(motion_z[0]) < 4.0 and abs(motion_z[1]) > 4.0, (scheme, ratio.mean(), motion_z)
    average = total / N_STEPS
    change = average - start
    deviation = start - exact
    beta = np.array([np.cov(change[:, j], deviation[:, j])[0, 1] / np.var(deviation[:, j], ddof=1)
                     for j in range(start.shape[1])])
    statistic = change - beta * deviation
    change_z = statistic.mean(axis=0) / (statistic.std(axis=0, ddof=1) / np.sqrt(N_BODIES))
    absolute_z = (average.mean(axis=0) - exact) / (average.std(axis=0, ddof=1) / np.sqrt(N_BODIES))
    print(scheme, 'control-variate z', np.round(change_z, 2), 'absolute z', np.round(absolute_z, 2))
    if scheme == 'EM':
        assert change_z[1] < -3.0 and change_z[3] > 3.0, (change_z, absolute_z)
    else:
        assert np.all(np.abs(change_z) < 3.0) and np.all(np.abs(absolute_z) < 3.0), (change_z, absolute_z)
