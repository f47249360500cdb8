"""Trajectory analysis (multi_bodies/analysis, doc/analysis.md) against exact answers, each with a negative control.

Laws used (none computed by the code under test):

* ideal gas (N independent uniform points in a periodic box): g(r) = 1, and the
  pair count of a distance bin has variance ``M p (1 - p)`` per frame exactly
  (M = N(N-1)/2 pairs, p the bin's share of the box; pairs sharing a point are
  independent when the box is periodic), so g has the standard error
  ``sqrt((1 - p) / (M p F))`` over F independent frames;
* ideal gas: S(k) = 1 at every box wavevector k != 0, per-frame variance
  ``1 - 1/N``, so standard error ``sqrt((1 - 1/N) / F)``; S_green_red = 0 with
  per-frame variance 1/2;
* a perfect lattice of N points: S = N at its reciprocal lattice vectors, 0 at
  every other box wavevector (to rounding);
* free Brownian particles (diffusion coefficient D): msd_xy = 4 D t, msd_z = 2 D t,
  F_s(k, t) = F(k, t) = exp(-D k^2 t).

Statistical checks use fixed seeds, chi-square sums over bins
``chi2 = sum ((value - law) / se)^2`` compared with the chi-square bound
``n + 5 sqrt(2 n)`` (n bins: 5 standard deviations of the chi-square
distribution), or single values within 4 standard errors; each is paired with a
negative control (a wrong box length, a wrong D, the naive normalisation) that
must fail the same criterion.
"""
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from multi_bodies.analysis.hydrogrid import HydroGridPlan, read_namelist, selected_wavevector_indices
from multi_bodies.analysis.pair_correlation import PairCorrelation, ideal_pair_fraction
from multi_bodies.analysis.structure_factor import StructureFactor
from multi_bodies.analysis.time_correlations import TimeCorrelations, lag_list, shell_wavevectors
from multi_bodies.analysis.trajectories import ArrayTrajectory, ClonesSeries, ConfigSeries, analyse
from multi_bodies.files import snapshots
from multi_bodies.files.input_options import parse_input_text

REPO = Path(__file__).resolve().parents[1]


def chi_square_bound(n):
    """Upper bound on a chi-square sum of n terms: its mean n plus 5 of its standard deviations sqrt(2 n)."""
    return n + 5.0 * np.sqrt(2.0 * n)


def ideal_gas(frames, particles, box, seed):
    rng = np.random.default_rng(seed)
    return rng.random((frames, particles, 3)) * np.asarray(box, dtype=float)


# ------------------------------------------------------------------ g(r)
def pair_correlation(positions, box, r_max, bins, dimension, blocks=10):
    accumulator = PairCorrelation(box, r_max, bins, dimension)
    analyse([ArrayTrajectory(positions, 1.0, box)], [accumulator], blocks=blocks)
    return accumulator.result()


def test_ideal_gas_pair_correlation_is_one_in_a_periodic_plane_and_a_wrong_box_is_caught():
    L, N, F = 20.0, 400, 20
    positions = ideal_gas(F, N, (L, L, 1.0), seed=11)
    result = pair_correlation(positions, (L, L, 0), 5.0, 25, 2)
    edges = np.linspace(0, 5.0, 26)
    p = np.pi * np.diff(edges ** 2) / L ** 2
    M = N * (N - 1) / 2
    se = np.sqrt((1 - p) / (M * p * F))
    chi2 = np.sum(((result['g'] - 1) / se) ** 2)
    assert chi2 < chi_square_bound(25), chi2
    # the reported block error bars estimate the same standard error (10 blocks: within 40 % in the mean)
    assert 0.6 < np.mean(result['g_error'] / se) < 1.4
    # negative control: the same points analysed in a box 10 % too long
    wrong = pair_correlation(positions, (1.1 * L, 1.1 * L, 0), 5.0, 25, 2)
    assert np.sum(((wrong['g'] - 1) / se) ** 2) > chi_square_bound(25)


def test_pair_correlation_of_a_known_finite_configuration_is_exact():
    """Three points in a periodic plane, at separations 1, 2 and sqrt(5) (one frame): each of the bins holding one of
    them has g = 1 / (M P_k) exactly, with M = N (N - 1) / 2 = 3 the pairs and P_k = pi (r2^2 - r1^2) / L^2 the
    ideal fraction of the bin (the normalisation N^2 / 2 would give two thirds of it); every other bin is 0."""
    L = 20.0
    points = np.array([[[5.0, 5.0, 0.0], [6.0, 5.0, 0.0], [5.0, 7.0, 0.0]]])
    edges = np.linspace(0.0, 3.0, 11)  # bins of 0.3: 1, 2 and sqrt(5) fall inside bins 3, 6 and 7
    result = pair_correlation(points, (L, L, 0), 3.0, 10, 2, blocks=1)
    expected = np.zeros(10)
    for distance in (1.0, 2.0, np.sqrt(5.0)):
        k = int(distance // 0.3)
        assert edges[k] < distance < edges[k + 1]
        expected[k] = 1.0 / (3.0 * np.pi * (edges[k + 1] ** 2 - edges[k] ** 2) / L ** 2)
    np.testing.assert_allclose(result['g'], expected, rtol=1e-12, atol=0)
    assert result['particles'] == 3 and result['frames'] == 1


def test_ideal_gas_pair_correlation_in_3d_above_a_wall_uses_the_sampled_slab():
    """x, y periodic, z open (uniform in [0, 4]): g = 1 once the slab's height density is used.

    Pairs that share a particle are nearly independent here (the share p_i of a particle
    varies little with its height), so the periodic standard error is used.
    """
    L, H, N, F = 12.0, 4.0, 400, 15
    positions = ideal_gas(F, N, (L, L, H), seed=12)
    result = pair_correlation(positions, (L, L, 0), 3.0, 15, 3)
    edges = np.linspace(0, 3.0, 16)
    M = N * (N - 1) / 2
    p = ideal_pair_fraction(edges, np.array([L, L, 0.0]), {2: _uniform_separation(H)})
    se = np.sqrt((1 - p) / (M * p * F))
    chi2 = np.sum(((result['g'] - 1) / se) ** 2)
    assert chi2 < chi_square_bound(15), chi2
    assert 'open axes z' in result['normalisation']
    # negative control: the naive normalisation by the slab volume L^2 H (edges of the slab ignored)
    naive = 4.0 / 3.0 * np.pi * np.diff(edges ** 3) / (L * L * H)
    g_naive = result['g'] * p / naive
    assert np.sum(((g_naive - 1) / se) ** 2) > chi_square_bound(15)


def _uniform_separation(H):
    """Exact separation density of two uniform points on [0, H]: (H - d) / H^2."""
    d = np.linspace(0, H, 401)
    return d, (H - d) / H ** 2


def test_exact_slab_fraction_matches_the_quadrature():
    """The shell probability with the slab's exact separation density equals a direct Monte Carlo count."""
    L, H = 12.0, 4.0
    edges = np.array([0.0, 1.0, 2.0, 3.0])
    p = ideal_pair_fraction(edges, np.array([L, L, 0.0]), {2: _uniform_separation(H)})
    rng = np.random.default_rng(5)
    n = 2_000_000
    d = rng.random((n, 3)) * [L, L, H] - rng.random((n, 3)) * [L, L, H]
    d[:, :2] -= np.round(d[:, :2] / L) * L
    counts = np.histogram(np.linalg.norm(d, axis=1), edges)[0] / n
    assert np.all(np.abs(counts - p) < 4 * np.sqrt(p / n)), (counts, p)


def test_open_square_pair_correlation_is_one_and_the_box_normalisation_is_not():
    """No periodic axis: the normalisation by the observed marginal densities removes the edge deficit."""
    side, N, F = 10.0, 300, 20
    positions = ideal_gas(F, N, (side, side, 1.0), seed=13)
    result = pair_correlation(positions, (0, 0, 0), 3.0, 15, 2)
    edges = np.linspace(0, 3.0, 16)
    M = N * (N - 1) / 2
    exact = ideal_pair_fraction(edges, np.zeros(2), {0: _uniform_separation(side), 1: _uniform_separation(side)})
    se = np.sqrt(1.0 / (M * exact * F))  # Poisson estimate (pairs sharing a point add little at this size)
    assert np.sum(((result['g'] - 1) / se) ** 2) < chi_square_bound(15)
    box_normalised = result['g'] * exact / (np.pi * np.diff(edges ** 2) / side ** 2)
    assert np.sum(((box_normalised - 1) / se) ** 2) > chi_square_bound(15)


# ------------------------------------------------------------------ S(k)
def structure_factor(positions, box, n_max, dimension=2, green=None, blocks=10):
    accumulator = StructureFactor(box, n_max, dimension, green=green)
    analyse([ArrayTrajectory(positions, 1.0, box)], [accumulator], blocks=blocks)
    return accumulator.result()


def test_ideal_gas_structure_factor_is_one_per_species_and_a_wrong_box_is_caught():
    L, N, F = 20.0, 400, 40
    positions = ideal_gas(F, N, (L, L, 1.0), seed=21)
    result = structure_factor(positions, (L, L, 0), 6, green=(0, 100))
    n = result['S'].shape[1]
    assert [tuple(p) for p in result['pairs']] == [('all', 'all'), ('green', 'green'), ('red', 'red'),
                                                   ('green', 'red')]
    for row, (law, variance) in enumerate([(1, 1 - 1 / 400), (1, 1 - 1 / 100), (1, 1 - 1 / 300), (0, 0.5)]):
        chi2 = np.sum((result['S'][row] - law) ** 2 / (variance / F))
        assert chi2 < chi_square_bound(n), (row, chi2)
    radial = result['radial']
    se_radial = np.sqrt((1 - 1 / N) / (F * radial['count']))
    assert np.sum(((radial['S'][0] - 1) / se_radial) ** 2) < chi_square_bound(len(se_radial))
    # negative control: the box 5 % too long; its wavevectors are no longer the box's
    wrong = structure_factor(positions, (1.05 * L, 1.05 * L, 0), 6)
    assert np.sum((wrong['S'][0] - 1) ** 2 / ((1 - 1 / N) / F)) > chi_square_bound(n)


def square_lattice(cells, spacing):
    grid = np.stack(np.meshgrid(np.arange(cells), np.arange(cells), indexing='ij'), -1).reshape(-1, 2) * spacing
    return np.column_stack([grid + 0.25 * spacing, np.ones(len(grid))])


def test_square_lattice_has_bragg_peaks_of_height_n_and_nothing_elsewhere():
    cells, spacing = 8, 1.3
    L = cells * spacing
    positions = square_lattice(cells, spacing)[None]
    result = structure_factor(positions, (L, L, 0), 16, blocks=1)
    bragg = np.all(result['indices'] % cells == 0, axis=1)
    assert bragg.sum() == 12  # (8,0), (16,0), (0..±16, 8), (0..±16, 16) in the half plane: 2 + 5 + 5
    assert np.allclose(result['S'][0][bragg], cells ** 2, rtol=1e-12, atol=0)
    assert np.max(result['S'][0][~bragg]) < 1e-20
    # negative control: the same lattice read in a box 3 % too long has no peak of height N there
    wrong = structure_factor(positions, (1.03 * L, 1.03 * L, 0), 16, blocks=1)
    assert np.max(np.abs(wrong['S'][0][bragg] - cells ** 2)) > 1.0


def test_simple_cubic_lattice_in_3d():
    cells, spacing = 4, 1.0
    grid = np.stack(np.meshgrid(*[np.arange(cells)] * 3, indexing='ij'), -1).reshape(-1, 3) * spacing + 0.1
    result = structure_factor(grid[None], (cells * spacing,) * 3, 8, dimension=3, blocks=1)
    bragg = np.all(result['indices'] % cells == 0, axis=1)
    assert np.allclose(result['S'][0][bragg], cells ** 3, rtol=1e-12)
    assert np.max(result['S'][0][~bragg]) < 1e-20
    wrong = structure_factor(grid[None], (1.05 * cells * spacing,) * 3, 8, dimension=3, blocks=1)
    assert np.max(np.abs(wrong['S'][0][bragg] - cells ** 3)) > 1.0


# ------------------------------------------------------------------ F(k, t) and MSD of free Brownian particles
def brownian(frames, particles, box, D, tau, seed):
    rng = np.random.default_rng(seed)
    start = rng.random((particles, 3)) * np.asarray(box, dtype=float)
    steps = rng.normal(0.0, np.sqrt(2 * D * tau), (frames - 1, particles, 3))
    return np.concatenate([start[None], start[None] + np.cumsum(steps, axis=0)])


def test_free_brownian_scattering_functions_and_msd_decay_as_exp_minus_d_k2_t():
    """F_s = F = exp(-D k^2 t), msd_xy = 4 D t, msd_z = 2 D t; a 30 % (MSD: 10 %) wrong D is caught.

    Standard errors (conservative): only non-overlapping time windows counted as
    independent, n = N floor((F - 1) / lag) samples for the self part and MSD;
    the collective part has one sample per window of lag + 3 correlation times
    1/(D k^2) and per wavevector of the shell (distinct k are uncorrelated in an
    ideal gas), each of variance (1 + c^2)/2, c = exp(-D k^2 t).
    """
    L, N, F, D, tau = 20.0, 200, 1000, 0.5, 1.0
    positions = brownian(F, N, (L, L, 5.0), D, tau, seed=31)
    wavevectors, groups, shell_k, periodic = shell_wavevectors((L, L, 0), [2 * np.pi * 2 / L, 2 * np.pi * 3 / L])
    assert periodic
    lags = lag_list(10)
    accumulator = TimeCorrelations(tau, lags, (L, L, 0), wavevectors, groups, 2)
    analyse([ArrayTrajectory(positions, tau, (L, L, 0))], [accumulator], blocks=10)
    result = accumulator.result()
    t = result['time'][1:]
    windows = (F - 1) // lags[1:]
    failures = {(part, name): 0 for part in ('self', 'collective') for name in ('right', 'wrong')}
    for shell in range(len(shell_k)):
        k2 = np.sum(wavevectors[groups == shell] ** 2, axis=1)
        for name, diffusion in (('right', D), ('wrong', 1.3 * D)):
            law = np.mean(np.exp(-diffusion * np.outer(t, k2)), axis=1)  # mean over the shell's wavevectors
            s2 = 2 * D * np.outer(t, k2)  # the variance of k.dr of the data
            variance = np.mean((1 + np.exp(-2 * s2)) / 2 - np.exp(-s2), axis=1)
            se_self = np.sqrt(variance / (N * windows))
            failures['self', name] += np.sum(np.abs(result['Fs'][1:, shell] - law) > 4 * se_self)
            c = law
            independent = np.floor(F / (lags[1:] + 3.0 / (D * k2.min() * tau)))
            se_collective = np.sqrt((1 + c ** 2) / 2 / (np.sum(groups == shell) * independent))
            failures['collective', name] += np.sum(np.abs(result['F'][1:, shell] - law) > 4 * se_collective)
    assert failures['self', 'right'] == 0 and failures['collective', 'right'] == 0
    # negative control: a wrong D leaves the error bars (the self part by 85 standard errors; the collective
    # part, whose conservative error bar is 10 times wider, at the larger k only: measured 4.6)
    assert failures['self', 'wrong'] > 0 and failures['collective', 'wrong'] > 0
    samples = N * windows
    for name, law, relative in (('msd_xy', 4 * D * t, 1.0), ('msd_z', 2 * D * t, np.sqrt(2))):
        se = law * relative / np.sqrt(samples)  # std of |dr_xy|^2 is 4 D t, of dz^2 is sqrt(2) 2 D t
        assert np.all(np.abs(result[name][1:] - law) < 4 * se), name
        assert np.any(np.abs(result[name][1:] - 1.1 * law) > 4 * se), name  # D 10 % too large is caught


def test_replicas_are_the_blocks_and_unwrap_undoes_periodic_jumps():
    L, N, D = 10.0, 50, 0.3
    replicas = [ArrayTrajectory(brownian(60, N, (L, L, 3), D, 1.0, seed=40 + i), 1.0, (L, L, 0)) for i in range(4)]
    plain = TimeCorrelations(1.0, lag_list(5), (L, L, 0), dimension=2)
    analyse(replicas, [plain])
    assert plain.result()['blocks'] == 4
    wrapped = [ArrayTrajectory(np.concatenate([np.mod(r.positions[..., :2], L), r.positions[..., 2:]], axis=2), 1.0,
                               (L, L, 0)) for r in replicas]
    unwrapped = TimeCorrelations(1.0, lag_list(5), (L, L, 0), dimension=2, unwrap=True)
    analyse(wrapped, [unwrapped])
    assert np.allclose(unwrapped.result()['msd_xy'], plain.result()['msd_xy'], rtol=1e-12)
    raw = TimeCorrelations(1.0, lag_list(5), (L, L, 0), dimension=2)  # negative control: wrapped, not unwrapped
    analyse(wrapped, [raw])
    assert not np.allclose(raw.result()['msd_xy'], plain.result()['msd_xy'], rtol=1e-3)


# ------------------------------------------------------------------ readers, the script, HydroGrid
def write_run(folder, frames, one_file):
    """A run's outputs as the package writes them: .clones per step or a .config series."""
    quaternions = np.tile([1.0, 0, 0, 0], (frames.shape[1], 1))
    for index, frame in enumerate(frames):
        if one_file:
            snapshots.append_config_snapshot(str(folder / 'run.blobs.config'), frame, quaternions, new_file=index == 0)
        else:
            snapshots.write_clones_file(str(folder / snapshots.clones_name('run', 'blobs', 5 * index)), frame,
                                        quaternions)


@pytest.mark.parametrize('one_file', [False, True])
def test_saved_runs_are_read_back_exactly_in_chunks(tmp_path, monkeypatch, one_file):
    frames = ideal_gas(7, 5, (3, 3, 3), seed=50)
    monkeypatch.chdir(tmp_path)
    write_run(tmp_path, frames, one_file)
    source = (ConfigSeries('run', ['blobs'], 0.1, 5, (3, 3, 0)) if one_file
              else ClonesSeries('run', ['blobs'], 0.1, (3, 3, 0)))
    assert source.n_frames == 7 and source.n_particles == 5 and np.isclose(source.frame_interval, 0.5)
    seen = []

    class Collect:
        def start_source(self):
            pass

        def add(self, positions, frames_used, blocks):
            seen.append(positions)

    analyse([source], [Collect()], chunk_frames=3)
    assert [len(s) for s in seen] == [3, 3, 1]
    assert np.array_equal(np.concatenate(seen), frames)  # repr precision: the same doubles


INPUT = """scheme stochastic_adams_bashforth_rollers
mobility_vector_prod_implementation python
eta 1.0e-3
g 0.0024892
blob_radius 0.656
kT 0.0041419464
dt 0.01
n_steps {steps}
n_save 1
repulsion_strength_wall 0.0165677856
debye_length_wall 0.0656
periodic_length 30 30 0
call_HydroGrid True
sample_HydroGrid 1
green_particles 0 4
cells 8 8
seed 3
output_name data/run
save_clones one_file
structure blob.vertex rollers.clones
"""

# The published HydroGrid example's namelist (RigidMultiblobsWall, multi_bodies/examples/HydroGrid), shortened.
NAMELIST = """! 1=rho (total density), 2-4 (unused = vx, vy, temperature), 5=rho_green, 6=rho_red
&hydroAnalysisOptions ! This first namelist corresponds to the whole 2D grid
   writeSnapshotVTK=T ! Save snapshots of the instantaneous fields
   nStructureFactors = 4 ! Set to zer to turn off
   structureFactorPairs = "0 1 0 1, 0 5 0 5, 0 6 0 6, 0 5 0 6" ! The zeros have to be here
   nWavenumbers=-1 ! Negative value means specify a range of wavenumbers
   selectedWavenumbers="-1 1, 0 1"
   nSavedSnapshots=4
   outputFolder = "./"
   filePrefix = "run" ! Prefix for all file names
/
&hydroAnalysisOptions ! projection along y
   nStructureFactors = 4
   structureFactorPairs = "0 1 0 1, 0 5 0 5, 0 6 0 6, 0 5 0 6"
   nWavenumbers=0
   axisToPrint = 1
/
"""


def make_hydrogrid_run(folder, steps=4, rollers=12):
    rng = np.random.default_rng(60)
    xy = rng.random((rollers, 2)) * 30
    (folder / 'rollers.clones').write_text('%d\n' % rollers + ''.join('%.15g %.15g 1.0 1 0 0 0\n' % tuple(p)
                                                                      for p in xy))
    (folder / 'blob.vertex').write_text('1\n0 0 0\n')
    (folder / 'inputfile.dat').write_text(INPUT.format(steps=steps))
    (folder / 'hydroGridOptions.nml').write_text(NAMELIST)


def test_namelist_of_the_published_example_maps_onto_the_analyses(tmp_path):
    (tmp_path / 'h.nml').write_text(NAMELIST)
    groups = read_namelist(str(tmp_path / 'h.nml'))
    assert [name for name, _ in groups] == ['hydroAnalysisOptions'] * 2
    assert groups[0][1]['writesnapshotvtk'] is True and groups[0][1]['nsavedsnapshots'] == 4
    assert groups[0][1]['structurefactorpairs'] == '0 1 0 1, 0 5 0 5, 0 6 0 6, 0 5 0 6'
    # kx in -1..1, ky in 0..1, one of each +-k pair, k = 0 left out
    assert selected_wavevector_indices(groups[0][1], 'g').tolist() == [[-1, 1], [0, 1], [1, 0], [1, 1]]
    make_hydrogrid_run(tmp_path)
    options = parse_input_text((tmp_path / 'inputfile.dat').read_text(), str(tmp_path / 'inputfile.dat'))
    notes = []
    plan = HydroGridPlan(options, folder=str(tmp_path), log=notes.append)
    assert plan.n_max.tolist() == [4, 4] and plan.green == (0, 4) and plan.max_lag == 3
    assert any('not mapped' in n and 'writesnapshotvtk' in n for n in notes)


def test_hydrogrid_run_writes_the_structure_factor_of_its_frames(tmp_path):
    """A HydroGrid input runs; its S(k) equals S(k) computed from the frames it saved (negative: another frame)."""
    make_hydrogrid_run(tmp_path)
    run = subprocess.run([sys.executable, str(REPO / 'multi_bodies' / 'multi_bodies.py'), '--input-file',
                          'inputfile.dat'], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    assert 'not mapped' in run.stdout
    table = np.loadtxt(tmp_path / 'data' / 'run.hydrogrid.sk.dat')
    frames = snapshots.read_config_series(str(tmp_path / 'data' / 'run.rollers.config'))[0]
    assert frames.shape[0] == 5
    direct = structure_factor(frames, (30, 30, 0), 4, green=(0, 4))
    assert np.allclose(table[:, 5], direct['S'][0], rtol=1e-9, atol=1e-12)
    assert np.allclose(table[:, 11], direct['S'][3], rtol=1e-9, atol=1e-12)
    first_only = structure_factor(frames[:1], (30, 30, 0), 4, blocks=1)
    assert not np.allclose(table[:, 5], first_only['S'][0], rtol=1e-3)
    post = subprocess.run([sys.executable, str(REPO / 'multi_bodies' / 'analyse.py'), '--input-file',
                           'inputfile.dat', '--hydrogrid', '--output-name', 'post/run'], cwd=tmp_path,
                          capture_output=True, text=True, timeout=300)
    assert post.returncode == 0, post.stderr
    assert np.allclose(np.loadtxt(tmp_path / 'post' / 'run.hydrogrid.sk.dat')[:, 5], table[:, 5], rtol=1e-12)
    assert (tmp_path / 'data' / 'run.hydrogrid.fkt.dat').exists()


def run_script(folder, *arguments):
    return subprocess.run([sys.executable, str(REPO / 'multi_bodies' / 'analyse.py')] + list(arguments),
                          cwd=folder, capture_output=True, text=True, timeout=120,
                          env=dict(os.environ, OPENBLAS_NUM_THREADS='1'))


def test_script_writes_the_tables_and_refuses_bad_input_in_one_line(tmp_path):
    frames = ideal_gas(12, 40, (8, 8, 2), seed=70)
    (tmp_path / 'data').mkdir()
    write_run(tmp_path / 'data', frames, one_file=True)
    (tmp_path / 'in.dat').write_text('scheme stochastic_first_order_RFD\ndt 0.1\nn_save 5\nperiodic_length 8 8 0\n'
                                     'output_name data/run\nsave_clones one_file\nstructure b.vertex blobs.clones\n')
    done = run_script(tmp_path, '--input-file', 'in.dat', '--gr', '--sk', '--fkt', '--msd', '--k-index-max', '3',
                      '--max-lag', '4', '--no-charts')
    assert done.returncode == 0, done.stderr
    for suffix in ('gr', 'sk', 'sk_radial', 'fkt', 'msd'):
        table = np.loadtxt(tmp_path / 'data' / ('run.%s.dat' % suffix))
        assert np.all(np.isfinite(table[:, :3]))
    msd = np.loadtxt(tmp_path / 'data' / 'run.msd.dat')
    assert np.isclose(msd[1, 1], 0.5)  # lag 1 = dt * n_save
    for arguments, fragment in [(('--input-file', 'missing.dat', '--gr'), "input file 'missing.dat' not found"),
                                (('--input-file', 'in.dat'), 'nothing to compute'),
                                (('--input-file', 'in.dat', '--gr', '--r-max', '5'), 'more than half'),
                                (('--input-file', 'in.dat', '--sk', '--dimension', '3'), 'needs periodic_length'),
                                (('--input-file', 'in.dat', '--msd', '--discard', '50'), 'nothing is left')]:
        failed = run_script(tmp_path, *arguments)
        assert failed.returncode == 2, (arguments, failed.stderr)
        assert fragment in failed.stderr and 'Traceback' not in failed.stderr, failed.stderr
        assert len(failed.stderr.strip().splitlines()) == 1, failed.stderr


def test_radial_dist_test_configuration_has_the_published_monte_carlo_pair_correlation(reference_dir):
    """The published Radial_Dist_Test: g(r) of its 1,875 rollers (the shipped start configuration, an
    equilibrium sample) against the shipped Monte Carlo g(r) (MCMC_G_of_R_data.dat: r, g, pair count).

    Bins of 4 published bins (0.40275); standard error of a one-frame g: Poisson, sqrt(g / (M p)) (the
    chi-square of the right box, 95 over 90 bins, says it is the right size).  r from 3.5 (contact) to 40.
    Negative control: the box 10 % longer along x (chi-square 530).
    """
    folder = reference_dir / 'published_2025' / 'multi_bodies' / 'examples' / 'Radial_Dist_Test'
    locations = snapshots.read_clones_file(str(folder / 'G_of_R.clones'))[0]
    published = np.loadtxt(folder / 'MCMC_G_of_R_data.dat')
    width, merge = published[1, 0] - published[0, 0], 4
    bins = int(80.6 // (width * merge))  # up to half the shorter side, 161.25 / 2
    radii = published[:bins * merge, 0].reshape(bins, merge)
    g_published = (published[:bins * merge, 1].reshape(bins, merge) * radii).sum(1) / radii.sum(1)  # area weights
    chi2 = {}
    for name, Lx in (('right', 402.75), ('wrong', 1.1 * 402.75)):
        box = (Lx, 161.25, 0)
        result = pair_correlation(locations[None], box, bins * width * merge, bins, 2, blocks=1)
        assert np.allclose(result['r'], radii.mean(1), atol=1e-5)
        se = np.sqrt(np.maximum(g_published, 1e-3) / result['pairs_per_frame_ideal'])
        used = (result['r'] > 3.5) & (result['r'] < 40)
        chi2[name] = np.sum((((result['g'] - g_published) / se)[used]) ** 2)
    n = int(used.sum())
    assert chi2['right'] < chi_square_bound(n), chi2
    assert chi2['wrong'] > chi_square_bound(n), chi2


def test_ensemble_replicas_are_read_by_the_script_and_give_the_error_bars(tmp_path):
    """A folder laid out as multi_bodies/ensemble.py leaves it: the finished replicas are the blocks."""
    import json
    D, L = 0.2, 10.0
    replicas = []
    for index in range(3):
        folder = tmp_path / 'ens' / 'base' / ('r%04d' % index)
        folder.mkdir(parents=True)
        write_run(folder, brownian(30, 20, (L, L, 3), D, 1.0, seed=80 + index), one_file=True)
        (folder / 'input.dat').write_text('scheme stochastic_first_order_RFD\ndt 0.2\nn_save 5\nperiodic_length '
                                          '10 10 0\noutput_name /elsewhere/run\nsave_clones one_file\n'
                                          'structure b.vertex blobs.clones\n')
        status = 'done' if index < 2 else 'failed'
        (folder / 'status.json').write_text(json.dumps({'status': status}))
        replicas.append({'folder': 'base/r%04d' % index, 'point': 0, 'seed': index})
    (tmp_path / 'ens' / 'ensemble.json').write_text(json.dumps({'points': [{'name': 'base'}],
                                                                'replicas': replicas}))
    done = run_script(tmp_path, '--ensemble', 'ens', '--msd', '--max-lag', '5', '--no-charts')
    assert done.returncode == 0, done.stderr
    table = np.loadtxt(tmp_path / 'ens' / 'analysis.msd.dat')
    assert 'blocks 2' in (tmp_path / 'ens' / 'analysis.msd.dat').read_text()  # the failed replica is left out
    assert np.isclose(table[1, 1], 1.0) and np.all(np.isfinite(table[1:, 3]))


@pytest.mark.parametrize('change, fragment', [('periodic_length 30 0 0', 'needs a periodic box in the xy plane'),
                                              ('cells 0 8', 'cells must be two integers >= 1'),
                                              ('green_particles 5 2', 'needs 0 <= i0 <= i1'),
                                              ('cells 8', "'cells' expects two integers"),
                                              ('save_HydroGrid_cells True', 'unsupported')])
def test_hydrogrid_options_are_checked_before_the_run_with_their_line(change, fragment):
    from utils import UserInputError
    text = INPUT.format(steps=2)
    accepted = parse_input_text(text, 'in.dat', 'dynamic')  # control: the published options as given
    assert accepted.call_HydroGrid and accepted.cells == (8, 8) and accepted.green_particles == (0, 4)
    with pytest.raises(UserInputError) as err:
        parse_input_text(text + change + '\n', 'in.dat', 'dynamic')
    assert fragment in str(err.value) and str(err.value).startswith('in.dat, line'), str(err.value)
