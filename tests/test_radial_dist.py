"""The published Radial_Dist_Test folder run unchanged (pycuda replaced by numba): ``tilt_angle``, ``domain in_plane``
and the in-plane g(r) of the Brownian rollers against the shipped Monte Carlo g(r) (issue 30).

Numbers from outside the code under test: the in-plane coupling is compared with the dense single-wall mobility
matrix of the python backend (another implementation), the heights with the shipped ``.clones`` file, and g(r)
with the shipped ``MCMC_G_of_R_data.dat`` (the published Monte Carlo).  The g(r) criterion is the chi-square of
tests/test_analysis.py: ``sum ((g - g_MC) / se)^2 < n + 5 sqrt(2 n)`` over the n bins from r = 3.5 (contact) to
40, bins of four published bins (0.40275), ``se`` the one-frame Poisson error ``sqrt(g_MC / pairs)``.
Negative controls: the single-wall coupling (velocities with z components, heights that move) and the same run
ten times hotter (kT x 10: the rollers overlap, g(r) at contact is no longer 0).
"""
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from run_scenes import edit_input, run_in_process

import mobility
from multi_bodies.analysis.pair_correlation import PairCorrelation
from multi_bodies.analysis.trajectories import ArrayTrajectory, analyse, config_offsets
from multi_bodies.files import snapshots
from multi_bodies.files.input_options import parse_input_text
from multi_bodies.solver import physics, rollers

BOX = (402.75, 161.25, 0.0)
HEIGHT = 3.0  # every roller of G_of_R.clones


def chi_square_bound(n):
    """Mean of a chi-square of n terms plus 5 of its standard deviations."""
    return n + 5.0 * np.sqrt(2.0 * n)


def published_folder(reference_dir):
    return reference_dir / 'published_2025' / 'multi_bodies' / 'examples' / 'Radial_Dist_Test'


def copy_radial_dist_test(reference_dir, destination, **options):
    """The published folder and its ``../../Structures`` under ``destination``, pycuda replaced by numba and
    ``options`` (name -> value) set; returns the example folder."""
    root = reference_dir / 'published_2025' / 'multi_bodies'
    shutil.copytree(root / 'Structures', destination / 'multi_bodies' / 'Structures')
    folder = destination / 'multi_bodies' / 'examples' / 'Radial_Dist_Test'
    shutil.copytree(published_folder(reference_dir), folder)
    for path in folder.iterdir():
        path.chmod(0o644)
    text = (folder / 'G_of_R.inputfile').read_text()
    published_line = re.compile(r'^(mobility_vector_prod_implementation\s+)pycuda$', re.M)
    assert len(published_line.findall(text)) == 1
    (folder / 'G_of_R.inputfile').write_text(published_line.sub(r'\g<1>numba', text))
    edit_input(folder / 'G_of_R.inputfile', **options)
    return folder


def monte_carlo_comparison(reference_dir, locations):
    """Chi-square of the in-plane g(r) of ``locations`` (N, 3) against the shipped Monte Carlo g(r), and n."""
    published = np.loadtxt(published_folder(reference_dir) / 'MCMC_G_of_R_data.dat')
    width, merge = published[1, 0] - published[0, 0], 4
    bins = int(80.6 // (width * merge))
    radii = published[:bins * merge, 0].reshape(bins, merge)
    g_published = (published[:bins * merge, 1].reshape(bins, merge) * radii).sum(1) / radii.sum(1)
    accumulator = PairCorrelation(BOX, bins * width * merge, bins, 2)
    analyse([ArrayTrajectory(np.asarray(locations)[None], 1.0, BOX)], [accumulator], blocks=1)
    result = accumulator.result()
    se = np.sqrt(np.maximum(g_published, 1e-3) / result['pairs_per_frame_ideal'])
    used = (result['r'] > 3.5) & (result['r'] < 40)
    return float(np.sum((((result['g'] - g_published) / se)[used]) ** 2)), int(used.sum())


def final_locations(folder, steps, n_save=5):
    """Locations (N, 3) of the last saved frame of ``run.G_of_R.config``; checks that it is step ``steps``."""
    path = folder / 'run.G_of_R.config'
    offsets = config_offsets(str(path))
    assert len(offsets) == steps // n_save + 1  # the step-0 frame included
    return snapshots.read_config_snapshot(str(path), offsets[-1])[0]


# ------------------------------------------------------------------ the options
def test_tilt_angle_is_a_general_option_that_reaches_the_hooks():
    options = parse_input_text('tilt_angle 0.3\ndomain in_plane\nparticle_radius 2\n', 'in.dat')
    keywords = physics.physics_keywords(options)
    assert keywords['tilt_angle'] == 0.3 and keywords['particle_radius'] == 2.0 and options.domain == 'in_plane'
    assert physics.physics_keywords(parse_input_text('', 'in.dat'))['tilt_angle'] == 0.0


def test_in_plane_coupling_is_the_in_plane_block_of_the_wall_mobility():
    """``P M P f`` (P: projection on x, y) of the dense python single-wall mobility, 6 blobs at several heights."""
    rng = np.random.default_rng(4)
    r = np.column_stack([rng.uniform(-4, 4, (6, 2)), rng.uniform(1.2, 3.0, 6)])
    force = rng.normal(size=18)
    M = mobility.single_wall_fluid_mobility(r, 1.0, 0.5)
    P = np.diag(np.tile([1.0, 1.0, 0.0], 6))
    expected = P @ M @ P @ force
    for backend in ('python', 'numba') + (('C++',) if mobility.backends.is_usable('C++') else ()):
        product = rollers.in_plane_product(mobility.blob_product(backend, 'trans_times_force'),
                                           'trans_times_force')
        np.testing.assert_allclose(product(r, force, 1.0, 0.5, np.zeros(3)), expected, rtol=0,
                                   atol=1e-12 * np.abs(expected).max())
    wall = mobility.blob_product('python', 'trans_times_force')(r, force, 1.0, 0.5, np.zeros(3))
    assert np.abs(wall - expected).max() > 1e-2 * np.abs(expected).max()  # negative control: the full coupling
    with pytest.raises(Exception, match='free_kinematics True'):
        rollers.in_plane_product(mobility.blob_product('python', 'rot_times_torque'), 'rot_times_torque')


# ------------------------------------------------------------------ the published folder, run unchanged
def test_radial_dist_test_runs_unchanged_and_keeps_its_heights(tmp_path, reference_dir):
    """Smoke test: the folder as shipped (dt 1), 2 steps: every height stays exactly 3 (the .clones value) while
    the rollers move in the plane.  (The negative control of in_plane, the single-wall coupling, is above.)"""
    folder = copy_radial_dist_test(reference_dir, tmp_path, n_steps=2, n_save=1)
    status, _, err = run_in_process('dynamic', folder, 'G_of_R.inputfile')
    assert status == 0, err
    locations = final_locations(folder, 2, n_save=1)
    start = snapshots.read_clones_file(str(folder / 'G_of_R.clones'))[0]
    assert locations.shape == (1875, 3) and np.all(locations[:, 2] == HEIGHT)
    assert np.abs(locations[:, :2] - start[:, :2]).max() > 0.1


@pytest.mark.slow
def test_radial_dist_test_brownian_pair_correlation_equals_the_monte_carlo_one(tmp_path, reference_dir):
    """dt 0.25 (the value the published input's comment gives beside the shipped dt 1), 8 steps (2 s: a
    roller diffuses about 0.9 um, four Debye lengths): the g(r) of the last frame against the shipped Monte
    Carlo g(r), chi-square over 90 bins below the bound 157 (20 steps gave 110).  Negative control: kT ten
    times larger, 4 steps (20 steps gave 150,595).  Shortened to keep the suite's time (a step of these 1,875
    rollers in their periodic box costs seconds here); doc/analysis.md has the 400-step chart.  (At the shipped dt 1 the step is too large for the repulsion:
    pairs overlap and the chi-square is 1,250 after 5 steps; see doc/analysis.md.)"""
    chi2 = {}
    for name, kT, steps in (('published', 0.0041419464, 8), ('hot', 0.041419464, 4)):
        folder = copy_radial_dist_test(reference_dir, tmp_path / name, n_steps=steps, n_save=steps, dt=0.25, kT=kT)
        status, _, err = run_in_process('dynamic', folder, 'G_of_R.inputfile')
        assert status == 0, err
        locations = final_locations(folder, steps, n_save=steps)
        assert np.all(locations[:, 2] == HEIGHT)
        chi2[name], n = monte_carlo_comparison(reference_dir, locations)
    print('chi-square: %s over %d bins (bound %.0f)' % (chi2, n, chi_square_bound(n)))
    assert chi2['published'] < chi_square_bound(n), (chi2, n)
    assert chi2['hot'] > chi_square_bound(n), (chi2, n)
