"""In-plane g(r) of Brownian runs of the published Radial_Dist_Test folder against its shipped Monte Carlo g(r).

Runs (made with ``multi_bodies.py`` in a copy of the folder, ``pycuda`` replaced by ``numba``, see
doc/analysis.md): each argument is ``LABEL=PATH/run.G_of_R.config:DT:N_SAVE:DISCARD`` (the time step, the save
interval and the number of saved frames to leave out as equilibration).  The g(r) of every run is the analysis
room's (``multi_bodies.analysis``: minimum image of the 402.75 x 161.25 box, bins of 0.40275, four of the shipped
file's), with error bars from 10 blocks of consecutive frames; the shipped Monte Carlo g(r) is averaged over the
same bins.  Writes ``doc/charts/radial_dist_test_gr.png`` and prints, per run, the chi-square against Monte Carlo
over r = 3.5 ... 40 with the block errors (and with the one-frame Poisson errors).

    python doc/charts/radial_dist_test_gr.py MC_FOLDER 'dt 0.25=/tmp/a/run.G_of_R.config:0.25:5:2' ...
"""
import os
import sys

import numpy as np

from multi_bodies.analysis.pair_correlation import PairCorrelation
from multi_bodies.analysis.trajectories import ConfigSeries, analyse

BOX = (402.75, 161.25, 0.0)
HERE = os.path.dirname(os.path.abspath(__file__))


def monte_carlo(folder):
    """(r (B,), g (B,)) of the shipped MCMC_G_of_R_data.dat averaged (area weights) over bins of four."""
    published = np.loadtxt(os.path.join(folder, 'MCMC_G_of_R_data.dat'))
    width, merge = published[1, 0] - published[0, 0], 4
    bins = int(80.6 // (width * merge))
    radii = published[:bins * merge, 0].reshape(bins, merge)
    g = (published[:bins * merge, 1].reshape(bins, merge) * radii).sum(1) / radii.sum(1)
    return radii.mean(1), g, bins * width * merge, bins


def brownian(path, dt, n_save, discard, r_max, bins):
    """g(r) table (dict of the analysis room) of one run's saved frames after ``discard``."""
    output = path[:-len('.G_of_R.config')]
    series = ConfigSeries(output, ['G_of_R'], dt, n_save, BOX, label=os.path.basename(output))
    accumulator = PairCorrelation(BOX, r_max, bins, 2)
    analyse([series], [accumulator], blocks=min(10, series.n_frames - discard), discard=discard)
    result = accumulator.result()
    result['frames_used'] = series.n_frames - discard
    return result


def main(argv):
    folder, runs = argv[0], argv[1:]
    r, g_mc, r_max, bins = monte_carlo(folder)
    used = (r > 3.5) & (r < 40)
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7, 4.2))
    ax.plot(r, g_mc, 'k-', lw=1.5, label='Monte Carlo (shipped MCMC_G_of_R_data.dat)')
    for k, run in enumerate(runs):
        label, spec = run.split('=', 1)
        path, dt, n_save, discard = spec.rsplit(':', 3)
        result = brownian(path, float(dt), int(n_save), int(discard), r_max, bins)
        error = np.maximum(result['g_error'], 1e-12)
        poisson = np.sqrt(np.maximum(g_mc, 1e-3) / result['pairs_per_frame_ideal'] / result['frames_used'])
        chi_blocks = np.sum((((result['g'] - g_mc) / error)[used]) ** 2)
        chi_poisson = np.sum((((result['g'] - g_mc) / poisson)[used]) ** 2)
        print('%s: %d frames, chi-square over %d bins: %.0f (block errors), %.0f (Poisson errors of the mean)'
              % (label, result['frames_used'], used.sum(), chi_blocks, chi_poisson))
        ax.errorbar(r, result['g'], yerr=result['g_error'], fmt='o', ms=2.5, capsize=1.5,
                    label='Brownian, %s (%d frames)' % (label, result['frames_used']), color='C%d' % k)
    ax.set_xlim(0, 30)
    ax.set_xlabel('r (um)')
    ax.set_ylabel('g(r), in the plane')
    ax.set_title('Radial_Dist_Test: 1,875 rollers at height 3, box 402.75 x 161.25')
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(HERE, 'radial_dist_test_gr.png'), dpi=120)


if __name__ == '__main__':
    main(sys.argv[1:])
