"""Compute the table of sphere-wall mobilities that ``sphere.py`` interpolates for the rotational terms.

Run from the repository root (or from inside ``sphere/``)::

    python sphere/make_mobility_table.py --blobs 162 --output sphere/mobility.162-blob.dat

The sphere is the package's calibrated icosahedral shell
(``multi_bodies.files.structure_generators.calibrated_shell``: hydrodynamic radius
R = 1, blob radius half the nearest-neighbour distance) with its centre at
height ``h`` above the wall.  Its 6x6 body mobility about the centre is
``pinv(K^T M^-1 K)`` with the Rotne-Prager-Blake blob mobility
(``multi_bodies.solver.body_solver.dense_body_mobility``).  Columns of the table:

``h/R, par, perp, rot_par, rot_perp, coupling``

par, perp: translational mobility parallel / perpendicular to the wall times
``6 pi eta R``; rot_par, rot_perp: rotational mobilities divided by the
shell's own free-space rotational mobility (this removes the shell's bulk
discretisation error, 1.7% for 162 blobs, so that they tend to 1 far from
the wall); coupling: ``w_y / F_x`` times ``6 pi eta R^2`` (rolling sense,
positive).  Parallel entries average x and y (the shell is not exactly
axisymmetric).  The header of the file records the command and the shell.
"""
import argparse
import datetime
import os
import sys

import numpy as np

# The one path prelude of the scripts: the repository root first, then utils.prepare_script_path.
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import utils  # noqa: E402
utils.prepare_script_path(__file__)

from mobility.interface import Geometry, make_mobility, registered_backends  # noqa: E402
from body.body import BodyArrays  # noqa: E402
from multi_bodies.solver.body_solver import dense_body_mobility  # noqa: E402
from multi_bodies.files.structure_generators import calibrated_shell  # noqa: E402

DEFAULT_HEIGHTS = np.concatenate((1.0 + np.geomspace(0.002, 1.0, 40), np.arange(2.25, 10.01, 0.25),
                                  np.arange(11.0, 20.01, 1.0), [25.0, 30.0, 40.0, 50.0]))


def shell_mobility(blobs, height, blob_mobility):
    """6x6 body mobility of the shell (blobs (n, 3) about its centre) with its centre at ``height``;
    ``blob_mobility`` the ``mobility.interface.BlobMobility`` of its blobs (radius, viscosity, wall or not)."""
    location = np.array([[0.0, 0.0, height]])
    bodies = BodyArrays(location, [[1.0, 0.0, 0.0, 0.0]], [blobs], [1], blob_mobility.blob_radius)
    N, _ = dense_body_mobility(bodies, bodies.configuration, blob_mobility)
    return N


def table_rows(num_blobs=162, heights=DEFAULT_HEIGHTS, implementation='python'):
    """Rows ``h, par, perp, rot_par, rot_perp, coupling`` (shape (len(heights), 6)) and the shell's data."""
    blobs, blob_radius, shell_radius = calibrated_shell(num_blobs)
    wall = make_mobility(implementation, Geometry('single_wall'), 1.0, blob_radius, dense_matrices=True)
    free = make_mobility(implementation, Geometry('free_space'), 1.0, blob_radius, dense_matrices=True)
    N_free = shell_mobility(blobs, 0.0, free)
    rot_free = np.trace(N_free[3:, 3:]) / 3.0
    rows = []
    for h in heights:
        N = shell_mobility(blobs, h, wall)
        par = 0.5 * (N[0, 0] + N[1, 1]) * 6.0 * np.pi
        perp = N[2, 2] * 6.0 * np.pi
        rot_par = 0.5 * (N[3, 3] + N[4, 4]) / rot_free
        rot_perp = N[5, 5] / rot_free
        coupling = 0.5 * (N[4, 0] - N[3, 1]) * 6.0 * np.pi
        rows.append((h, par, perp, rot_par, rot_perp, coupling))
    return np.array(rows), {'blob_radius': blob_radius, 'shell_radius': shell_radius,
                            'free_rotational_mobility_times_8pi': rot_free * 8.0 * np.pi}


def main(argv=None):
    parser = argparse.ArgumentParser(description='Tabulate the wall mobilities of a blob-shell sphere.')
    parser.add_argument('--blobs', type=int, default=162, help='blobs of the icosahedral shell (default 162)')
    parser.add_argument('--implementation', default='python',
                        choices=registered_backends('single_wall', dense_matrices=True),
                        help='dense blob mobility backend (same numbers; C++ is faster)')
    parser.add_argument('--output', default=None, help='output file (default mobility.<blobs>-blob.dat here)')
    args = parser.parse_args(argv)
    output = args.output or os.path.join(os.path.dirname(os.path.abspath(__file__)),
                                         'mobility.%d-blob.dat' % args.blobs)
    try:
        rows, shell = table_rows(args.blobs, implementation=args.implementation)
    except ValueError as err:
        raise utils.UserInputError('--blobs %d: %s' % (args.blobs, err))
    command = 'python sphere/make_mobility_table.py ' + ' '.join(sys.argv[1:] if argv is None else argv)
    with open(output, 'w') as f:
        f.write('# Wall mobilities of a rigid multiblob sphere (hydrodynamic radius R = 1) above a no-slip wall.\n')
        f.write('# made by: %s (%s UTC)\n' % (command.strip(), datetime.datetime.utcnow().strftime('%Y-%m-%d %H:%M')))
        f.write('# shell: %d blobs (multi_bodies.files.structure_generators.calibrated_shell), shell radius %.12g, '
                'blob radius %.12g\n' % (args.blobs, shell['shell_radius'], shell['blob_radius']))
        f.write('# body mobility pinv(K^T M^-1 K), Rotne-Prager-Blake blobs, tracking point the centre\n')
        f.write('# rot_par, rot_perp divided by the free-space value of the shell (8 pi eta R^3 mu_rr = %.12g)\n'
                % shell['free_rotational_mobility_times_8pi'])
        f.write('# coupling = w_y/F_x * 6 pi eta R^2 (rolling sense); par, perp times 6 pi eta R\n')
        f.write('# h/R par perp rot_par rot_perp coupling\n')
        for row in rows:
            f.write(' '.join('%.12e' % v for v in row) + '\n')
    print('wrote %s (%d heights)' % (output, rows.shape[0]))
    return 0


if __name__ == '__main__':
    sys.exit(utils.fail_cleanly(main))
