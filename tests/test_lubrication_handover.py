"""The smooth hand-over between the lubrication resistance formulas (``handover`` / ``lubrication_handover``).

Checked against laws, not against the code: continuity across each published switch (r = 2.006 a, 2.1 a,
h = 1.01 a, 1.1 a, the cutoff) where the published mode jumps (the jumps quoted by the published paper's
code review: X11A 43.81 -> 41.65 at r = 2.006, the wall normal 10.43 -> 10.00 at h = 1.1), a continuous
first derivative at the window edges, the published values unchanged outside the windows, and Delta_R
symmetric positive semidefinite with spheres inside every window.
"""
import numpy as np
import pytest

from lubrication import assembly, brownian, resistance
from multi_bodies.files.input_options import options_with, parse_input_text
from utils import UserInputError

UNIT = (1.0, 1.0, 1.0)          # 6 pi eta a^n = 1
ETA_UNIT = 1.0 / (6.0 * np.pi)
STEP = 1e-9                     # half the distance between the two sides of a switch (units of a)
CONTINUITY_BOUND = 1e-6         # smooth: |jump| / max |block| across 2 STEP (published: >= 4e-5)
R_HAT = np.array([[0.6, 0.8, 0.0]])
AXIS = np.array([[1.0, 0.0, 0.0]])


def pair_sup(r, handover, r_hat=R_HAT):
    return resistance.pair_resistance_sup(np.atleast_1d(r), np.repeat(r_hat, np.size(r), axis=0), UNIT,
                                          handover=handover)


def wall_sup(h, handover):
    return resistance.wall_scalars_sup(np.atleast_1d(h), handover=handover)


def pair_delta(r, handover, cutoff=4.5):
    locations = np.array([[0.0, 0.0, 0.0], [r, 0.0, 0.0]])
    return assembly.resistance_matrices(locations, 1.0, ETA_UNIT, cutoff=cutoff, wall=False,
                                        handover=handover).Delta_R.toarray()


def relative_jump(before, after):
    return np.max(np.abs(after - before)) / np.max(np.abs(before))


def test_the_published_jumps_are_there_and_the_smooth_handover_removes_them():
    # X11A (the squeeze resistance) at r = 2.006: 43.81 -> 41.65 published (issue 28 quotes 43.88 -> 41.65)
    below, above = resistance.NEAR_CONTACT_END - STEP, resistance.NEAR_CONTACT_END + STEP
    published = pair_sup([below, above], 'published', AXIS)[:, 0, 0]
    assert np.allclose(published, [43.81, 41.65], atol=0.01), published
    smooth = pair_sup([below, above], 'smooth', AXIS)[:, 0, 0]
    assert abs(smooth[1] - smooth[0]) <= CONTINUITY_BOUND * smooth[0], smooth
    # the wall normal resistance (X^a - 1) at h = 1.1: 10.43 -> 10.00 published
    published = wall_sup([1.1 - STEP, 1.1 + STEP], 'published')[:, 0]
    assert np.allclose(published, [10.43, 10.007], atol=0.005), published
    smooth = wall_sup([1.1 - STEP, 1.1 + STEP], 'smooth')[:, 0]
    assert abs(smooth[1] - smooth[0]) <= CONTINUITY_BOUND * smooth[0], smooth


@pytest.mark.parametrize('what, switch', [
    ('pair', resistance.NEAR_CONTACT_END), ('pair', resistance.MOBILITY_TABLE_END),
    ('wall', resistance.WALL_PARALLEL_END), ('wall', resistance.WALL_NORMAL_END),
    ('cutoff', 4.5), ('cutoff', 3.0)])
def test_every_switch_is_continuous_with_the_smooth_handover_only(what, switch):
    def value(x, handover):
        if what == 'pair':
            return pair_sup(x, handover)[0]
        if what == 'wall':
            return wall_sup(x, handover)[0]
        return pair_delta(x, handover, cutoff=switch)
    jumps = {}
    for handover in ('published', 'smooth'):
        before, after = value(switch - STEP, handover), value(switch + STEP, handover)
        if what == 'cutoff':  # beyond the cutoff there is no pair term: compare with the last one inside
            jumps[handover] = np.max(np.abs(after - before)) / np.max(np.abs(value(switch - 0.3, handover)))
        else:
            jumps[handover] = relative_jump(before, after)
    assert jumps['published'] >= 4e-5, jumps
    assert jumps['smooth'] <= CONTINUITY_BOUND, jumps


@pytest.mark.parametrize('what, window', [('pair', 'near_contact'), ('pair', 'mobility_table'),
                                          ('wall', 'wall_near'), ('wall', 'wall_far')])
def test_the_blend_has_a_continuous_slope_at_its_window_edges(what, window):
    """The blend adds no kink: at each window edge the change of slope equals the formula's own there (the
    tables are interpolated linearly, so they have kinks at their nodes, some of which are window edges;
    the published mode gives the pure formula on both sides of every edge).  A weight without a continuous
    slope (a linear ramp) would add a kink of (R_right - R_left) / (hi - lo), over 100 at r = 2.006."""
    d = 1e-6
    for edge in resistance.SMOOTH_WINDOWS[window]:
        kinks = {}
        for handover in ('published', 'smooth'):
            def f(x):
                return pair_sup(x, handover)[0] if what == 'pair' else wall_sup(x, handover)[0]
            left = (f(edge) - f(edge - d)) / d
            right = (f(edge + d) - f(edge)) / d
            kinks[handover] = right - left
            scale = np.max(np.abs(left)) + np.max(np.abs(f(edge)))
        added = np.max(np.abs(kinks['smooth'] - kinks['published']))
        assert added <= 1e-3 * scale, (window, edge, added, scale)


def test_outside_the_windows_the_smooth_values_are_the_published_ones():
    rng = np.random.default_rng(3)
    windows = resistance.SMOOTH_WINDOWS
    r = np.concatenate((rng.uniform(2.0, windows['near_contact'][0], 50),
                        rng.uniform(windows['near_contact'][1], windows['mobility_table'][0], 50),
                        rng.uniform(windows['mobility_table'][1], 4.5 - resistance.CUTOFF_WINDOW, 50)))
    r_hat = rng.standard_normal((r.size, 3))
    r_hat /= np.linalg.norm(r_hat, axis=1)[:, None]
    assert np.array_equal(resistance.pair_resistance_sup(r, r_hat, UNIT, handover='smooth'),
                          resistance.pair_resistance_sup(r, r_hat, UNIT, handover='published'))
    h = np.concatenate((rng.uniform(1.0, windows['wall_near'][0], 50),
                        rng.uniform(windows['wall_near'][1], windows['wall_far'][0], 50),
                        rng.uniform(windows['wall_far'][1], 15.0, 50)))
    assert np.array_equal(wall_sup(h, 'smooth'), wall_sup(h, 'published'))


def scene_in_the_windows():
    """Pairs at distances inside every pair window and spheres at heights inside every wall window."""
    gaps = [2.005, 2.006, 2.007, 2.1, 2.11, 2.125, 4.3, 4.4]
    heights = [1.009, 1.01, 1.011, 1.095, 1.1, 1.105, 1.2, 1.5]
    locations = []
    for k, (r, h) in enumerate(zip(gaps, heights)):
        locations += [[10.0 * k, 0.0, h], [10.0 * k + r, 0.0, heights[-1 - k]]]
    locations = np.array(locations, dtype=float)
    locations[1::2, 2] = locations[0::2, 2]  # each pair at one height: its distance is the gap above
    return locations


@pytest.mark.parametrize('wall', [True, False])
def test_delta_R_stays_symmetric_positive_semidefinite_with_the_smooth_handover(wall):
    locations = scene_in_the_windows()
    rng = np.random.default_rng(5)
    cluster = rng.uniform(0.0, 5.0, (30, 3))
    cluster[:, 2] += 1.0005
    for scene in (locations, cluster):
        D = assembly.resistance_matrices(scene, 1.0, 0.7, wall=wall, handover='smooth').Delta_R.toarray()
        assert np.array_equal(D, D.T)
        eigenvalues = np.linalg.eigvalsh(D)
        assert eigenvalues[0] >= -1e-12 * eigenvalues[-1], (eigenvalues[0], eigenvalues[-1])
    # every pair block on a fine grid through the pair windows (the wall blocks are checked in the scenes)
    r = np.concatenate([np.linspace(lo, hi, 200) for lo, hi in (resistance.SMOOTH_WINDOWS['near_contact'],
                                                               resistance.SMOOTH_WINDOWS['mobility_table'])]
                       + [np.linspace(4.5 - resistance.CUTOFF_WINDOW, 4.5 - 1e-6, 200)])
    r_hat = rng.standard_normal((r.size, 3))
    r_hat /= np.linalg.norm(r_hat, axis=1)[:, None]
    blocks = (resistance.pair_resistance_sup(r, r_hat, UNIT, handover='smooth')
              - resistance.pair_resistance_blob_model(r, r_hat, UNIT))
    blocks *= resistance.cutoff_taper(r, 4.5, 'smooth')[:, None, None]
    eigenvalues = np.linalg.eigvalsh(blocks)
    assert np.all(eigenvalues[:, 0] >= -1e-12 * eigenvalues[:, -1])


def test_the_input_option_reaches_the_lubrication_schemes():
    from quaternion_integrator.lubrication_schemes import LubricationScheme
    options = parse_input_text('scheme lubrication_trapezoidal\ndt 0.01\nlubrication_handover smooth\n',
                               'in.dat', 'dynamic')
    assert options.lubrication_handover == 'smooth' and not options.warnings
    assert options_with().lubrication_handover == 'published'   # the default reproduces the published numbers
    scheme = LubricationScheme(0.01, options)
    assert scheme.handover == 'smooth'
    settings = brownian.lubrication_settings(1.0, 1.0, handover=scheme.handover)
    locations = np.array([[0.0, 0.0, 1.1], [resistance.NEAR_CONTACT_END, 0.0, 1.1]])
    assert np.array_equal(settings.matrices(locations).Delta_R.toarray(),
                          assembly.resistance_matrices(locations, 1.0, 1.0, handover='smooth').Delta_R.toarray())
    with pytest.raises(UserInputError, match='in.dat, line 1.*lubrication_handover'):
        parse_input_text('lubrication_handover blended\n', 'in.dat')
    with pytest.raises(UserInputError, match='lubrication_handover .blended.*published.*smooth'):
        assembly.resistance_matrices(locations, 1.0, 1.0, handover='blended')


@pytest.mark.parametrize('what', ['pair', 'wall'])
def test_the_derivative_of_the_corrected_mobility_exists_across_a_switch_with_the_smooth_handover(what):
    """What the random finite difference of the drift sees: d M_lub / dx by central differences of step
    1e-3 and 1e-5 across the switch (two spheres 1.5 a above the wall, their distance x = 2.006 a; or one
    sphere at height x = 1.1 a).  Published: the difference holds the jump over the step, so the two steps
    disagree by several times the slope itself; smooth: they agree to a few per cent (a derivative exists)."""
    from lubrication import problem as lub_problem

    def M_lub(x, handover):
        if what == 'pair':
            locations = np.array([[0.0, 0.0, 1.5], [x, 0.0, 1.5]])
        else:
            locations = np.array([[0.0, 0.0, x]])
        problem = lub_problem.LubricationProblem(locations, 1.0, ETA_UNIT, handover=handover)
        return lub_problem.dense_lubricated_mobility(problem)
    switch = resistance.NEAR_CONTACT_END if what == 'pair' else resistance.WALL_NORMAL_END
    for handover in ('published', 'smooth'):
        slopes = [(M_lub(switch + step / 2, handover) - M_lub(switch - step / 2, handover)) / step
                  for step in (1e-3, 1e-5)]
        disagreement = np.max(np.abs(slopes[1] - slopes[0])) / np.max(np.abs(slopes[0]))
        if handover == 'published':
            assert disagreement > 5.0, disagreement   # measured: 6.7 (pair), 81 (wall)
        else:
            assert disagreement < 0.05, disagreement  # measured: 0.018 (pair), 0.007 (wall)
