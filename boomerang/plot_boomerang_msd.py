"""Plot the MSD written by ``calculate_boomerang_msd_from_trajectories.py`` (matplotlib).

Run from inside ``boomerang/``::

    python plot_boomerang_msd.py data/boomerang/boomerang-msd-dt-0.01-runs-8.npz --output msd.png

Left: translational entries (x, y, z) of the tracking point; right:
rotational entries (u_x, u_y, u_z); error bars are two standard errors over
the trajectories.  ``--slope-mu MU`` adds the line ``4 kT MU t`` to the
left panel for the in-plane MSD ``x + y`` (e.g. the long-time parallel
mobility of the paper).
"""
import argparse
import os
import sys

# The one path prelude of the scripts: the repository root first, then utils.prepare_script_path.
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import utils  # noqa: E402
utils.prepare_script_path(__file__)

import numpy as np  # noqa: E402

from boomerang.boomerang_model import KT  # noqa: E402


def main(argv=None):
    parser = argparse.ArgumentParser(description='Plot a boomerang MSD (.npz from '
                                                 'calculate_boomerang_msd_from_trajectories.py).')
    parser.add_argument('msd_file', help='.npz file with times, msd, msd_error')
    parser.add_argument('--output', default=None, help='figure file (default: the .npz name with .png)')
    parser.add_argument('--slope-mu', type=float, default=None,
                        help='draw 4 kT mu t for the in-plane MSD x + y with this mobility')
    args = parser.parse_args(argv)
    what = 'an MSD file of calculate_boomerang_msd_from_trajectories.py'
    # sizes, shapes and dtypes checked as declared, before anything is inflated (a zip bomb, a header of 10^12
    # values): utils.read_npz
    data = utils.read_npz(args.msd_file, ('times', 'msd', 'msd_error'), what)
    times, msd, error = data['times'], data['msd'], data['msd_error']
    lags = times.shape[0] if times.ndim == 1 else -1
    if lags < 1 or msd.shape != (lags, 6, 6) or error.shape != (lags, 6, 6):
        raise utils.UserInputError('%s is not %s: times %s, msd %s and msd_error %s, where (L,), (L, 6, 6) and '
                                   '(L, 6, 6) with L >= 1 lags were expected'
                                   % (args.msd_file, what, times.shape, msd.shape, error.shape))
    if not all(np.all(np.isfinite(a)) for a in (times, msd, error)):
        raise utils.UserInputError('%s is not %s: it holds NaN or infinite values' % (args.msd_file, what))
    import matplotlib
    matplotlib.use('Agg')
    from matplotlib import pyplot
    figure, axes = pyplot.subplots(1, 2, figsize=(10, 4))
    labels = ['x', 'y', 'z', 'u_x', 'u_y', 'u_z']
    every = max(1, len(times) // 12)
    for k in range(6):
        ax = axes[0] if k < 3 else axes[1]
        ax.errorbar(times, msd[:, k, k], yerr=2.0 * error[:, k, k], errorevery=every, label=labels[k])
    if args.slope_mu is not None:
        axes[0].errorbar(times, msd[:, 0, 0] + msd[:, 1, 1], yerr=2.0 * (error[:, 0, 0] + error[:, 1, 1]),
                         errorevery=every, label='x + y')
        axes[0].plot(times, 4.0 * KT * args.slope_mu * times, 'k--', label='4 kT mu t')
    axes[0].set_title('translational MSD (um^2)', fontsize=9)
    axes[1].set_title('rotational MSD', fontsize=9)
    for ax in axes:
        ax.set_xlabel('time (s)')
        ax.legend(fontsize=8)
    figure.tight_layout()
    output = args.output or os.path.splitext(args.msd_file)[0] + '.png'
    figure.savefig(output, dpi=120)
    print('wrote %s' % output)
    return 0


if __name__ == '__main__':
    sys.exit(utils.fail_cleanly(main))
