"""Plot one boomerang trajectory file (matplotlib): path in the plane, heights and tilt against time.

Run from inside ``boomerang/``::

    python plot_boomerang_trajectory.py data/boomerang/boomerang-trajectory-dt-0.01-N-1000-scheme-RFD-g-1.0.txt

Panels: the (x, y) path of the apex; the height of the apex and the mean
height of the 15 blobs; the cosine of the angle between the boomerang's
plane normal and the wall normal.  Written to ``--output`` (default: the
trajectory name with ``.png``).
"""
import argparse
import os
import sys

# The one path prelude of the scripts: the repository root first, then utils.prepare_script_path.
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import utils  # noqa: E402
utils.prepare_script_path(__file__)

import numpy as np  # noqa: E402

from boomerang.boomerang_model import BoomerangModel  # noqa: E402
from body.geometry import rotation_matrices  # noqa: E402


def main(argv=None):
    parser = argparse.ArgumentParser(description='Plot a boomerang trajectory file.')
    parser.add_argument('trajectory', help='file written by boomerang.py')
    parser.add_argument('--output', default=None, help='figure file (default: trajectory name with .png)')
    args = parser.parse_args(argv)
    parameters, locations, orientations = utils.read_trajectory_file(args.trajectory)
    dt = utils.trajectory_parameter(parameters, 'dt', args.trajectory)
    times = dt * np.arange(len(locations))
    blob_heights = BoomerangModel().blob_positions(locations, orientations)[:, :, 2].mean(axis=1)
    normal_z = rotation_matrices(orientations)[:, 2, 2]     # z component of the body's z axis

    import matplotlib
    matplotlib.use('Agg')
    from matplotlib import pyplot
    figure, axes = pyplot.subplots(1, 3, figsize=(13, 4))
    axes[0].plot(locations[:, 0], locations[:, 1], lw=0.6)
    axes[0].set_xlabel('x (um)')
    axes[0].set_ylabel('y (um)')
    axes[0].set_aspect('equal', adjustable='datalim')
    axes[0].set_title('apex path', fontsize=9)
    axes[1].plot(times, locations[:, 2], lw=0.6, label='apex')
    axes[1].plot(times, blob_heights, lw=0.6, label='mean blob height')
    axes[1].set_xlabel('time (s)')
    axes[1].set_ylabel('height (um)')
    axes[1].legend(fontsize=8)
    axes[2].plot(times, normal_z, lw=0.6)
    axes[2].set_xlabel('time (s)')
    axes[2].set_ylabel('cos(tilt) of the plane normal')
    figure.suptitle(os.path.basename(args.trajectory), fontsize=8)
    figure.tight_layout()
    output = args.output or os.path.splitext(args.trajectory)[0] + '.png'
    figure.savefig(output, dpi=120)
    print('wrote %s' % output)
    return 0


if __name__ == '__main__':
    sys.exit(utils.fail_cleanly(main))
