"""Mean-square displacement of the boomerang from trajectory files, with error bars over the trajectories.

Run from inside ``boomerang/``::

    python calculate_boomerang_msd_from_trajectories.py data/boomerang/boomerang-trajectory-dt-0.01-N-1000-*.txt \
        --end 2.0 --output data/boomerang/boomerang-msd-dt-0.01

Every file is one independent run of ``boomerang.py`` (same ``dt``).  For
each run the 6x6 MSD of the tracking point and of the rotational
displacement (``sphere/rigid_msd.py``) is averaged over all time origins,
for lags ``0, dt, ..., end``; the mean over runs and its standard error
(``std / sqrt(runs)``) are written:

* ``<output>.txt``: ``t``, the 6 diagonal entries (x, y, z, u_x, u_y, u_z),
  then their 6 standard errors (the published script pickled the same data);
* ``<output>.npz``: ``times``, ``msd`` (L, 6, 6), ``msd_error`` (L, 6, 6),
  ``point``, ``files``.

``--point X Y Z`` tracks another point fixed in the body (body frame, um),
e.g. the centre of diffusion or the centre of the arms instead of the apex
(Delong et al. 2015 compare them).  Plot with ``plot_boomerang_msd.py``.

The published options name the files instead: ``-dt 0.1 -N 100000 -scheme
RFD -gfactor 1 -n_runs 4 --data-name example`` analyses the runs of
``boomerang.py`` made with ``--data-name example-1`` ... ``example-4`` (in
``<data dir>/boomerang``, the folder ``boomerang.py`` writes to; ``-end``
is ``--end``).  ``--profile`` (or ``--profile True``) runs under cProfile.
"""
import argparse
import os
import sys

# The one path prelude of the scripts: the repository root first, then utils.prepare_script_path.
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import utils  # noqa: E402
utils.prepare_script_path(__file__)

import numpy as np  # noqa: E402

from boomerang.boomerang import add_profile_option, find_data_dir, run_profiled, trajectory_name  # noqa: E402
from sphere.rigid_msd import msd_statistics  # noqa: E402


def published_file_names(args):
    """The trajectory files the published options name: runs 1 .. n_runs of ``boomerang.py`` with
    ``--data-name <data-name>-<k>`` (or ``<k>`` without a data name), in ``<data dir>/boomerang``."""
    missing = [flag for flag, value in (('-dt', args.dt), ('-N', args.n_steps), ('-n_runs', args.n_runs))
               if value is None]
    if missing:
        raise utils.UserInputError('give trajectory files, or the published options -dt, -N and -n_runs (with '
                                   '-scheme, -gfactor and --data-name of the runs); missing: %s' % ', '.join(missing))
    if args.n_runs < 1:
        raise utils.UserInputError('-n_runs must be at least 1, got %d' % args.n_runs)
    folder = os.path.join(find_data_dir(args.data_dir), 'boomerang')
    names = []
    for k in range(1, args.n_runs + 1):
        run_name = '%s-%d' % (args.data_name, k) if args.data_name else str(k)
        names.append(os.path.join(folder, trajectory_name(args.dt, args.n_steps, args.scheme, args.gfactor, run_name)))
    return names


def main(argv=None):
    parser = argparse.ArgumentParser(description='MSD of the boomerang from trajectory files (see doc/boomerang.md).')
    parser.add_argument('files', nargs='*', help='trajectory files written by boomerang.py (or use the published '
                                                 'options -dt -N -n_runs --data-name)')
    parser.add_argument('--end', '-end', dest='end', type=float, default=None,
                        help='longest lag time (default: a quarter of the shortest trajectory)')
    # The published way to name the runs: -dt 0.1 -N 100000 -scheme RFD -gfactor 1 -n_runs 4 --data-name=example
    # analyses the runs made with --data-name example-1 ... example-4.
    parser.add_argument('-dt', dest='dt', type=float, default=None, help='time step of the runs (published naming)')
    parser.add_argument('-N', dest='n_steps', type=int, default=None, help='number of steps of the runs')
    parser.add_argument('-scheme', dest='scheme', default='RFD', help='scheme of the runs (default RFD)')
    parser.add_argument('-gfactor', dest='gfactor', type=float, default=1.0, help='gravity factor of the runs')
    parser.add_argument('-n_runs', dest='n_runs', type=int, default=None,
                        help='number of runs: --data-name NAME-1 ... NAME-n_runs')
    parser.add_argument('--data-name', dest='data_name', default='', help='data name of the runs (without -k)')
    parser.add_argument('--data-dir', dest='data_dir', default=None,
                        help='data folder (default: DATA_DIR of config_local.py, else ./data), as boomerang.py')
    add_profile_option(parser)
    parser.add_argument('--point', type=float, nargs=3, default=[0.0, 0.0, 0.0], metavar=('X', 'Y', 'Z'),
                        help='tracking point in the body frame (default 0 0 0, the apex)')
    parser.add_argument('--output', default=None,
                        help='output path without extension (default: boomerang-msd-runs-<n> next to the first file)')
    args = parser.parse_args(argv)
    if args.profile:
        return run_profiled(analyse, args)
    return analyse(args)


def analyse(args):
    """The MSD of the trajectories that ``args`` names; writes the .txt and .npz files, returns 0."""
    if not args.files:
        args.files = published_file_names(args)
    trajectories, dts = [], []
    for path in args.files:
        parameters, locations, orientations = utils.read_trajectory_file(path)
        dts.append(utils.trajectory_parameter(parameters, 'dt', path))
        trajectories.append((locations, orientations))
    if not np.allclose(dts, dts[0], rtol=1e-12):
        raise utils.UserInputError('the trajectory files have different time steps (%s); give files of one dt'
                                   % ', '.join(sorted(set('%g' % d for d in dts))))
    dt = dts[0]
    if args.dt is not None and abs(dt - args.dt) > 1e-7:
        raise utils.UserInputError('the trajectories have dt %s, not the -dt %s given' % (dt, args.dt))
    shortest = min(len(loc) for loc, _ in trajectories)
    end = args.end if args.end is not None else 0.25 * (shortest - 1) * dt
    n_lags = int(round(end / dt))
    if n_lags < 1 or n_lags >= shortest:
        raise utils.UserInputError('--end %s must be at least one time step (%s) and shorter than the shortest '
                                   'trajectory (%d configurations)' % (end, dt, shortest))
    lags = np.arange(n_lags + 1)
    msd, msd_error = msd_statistics(trajectories, lags, args.point)
    times = lags * dt
    output = args.output or os.path.join(os.path.dirname(os.path.abspath(args.files[0])),
                                         'boomerang-msd-dt-%s-runs-%d' % (dt, len(trajectories)))
    diagonal = np.arange(6)
    header = ('MSD of the boomerang from %d trajectories (dt %s), tracking point %s (body frame)\n'
              'columns: t, MSD x y z u_x u_y u_z, standard errors over the trajectories of the same'
              % (len(trajectories), dt, list(args.point)))
    np.savetxt(output + '.txt', np.column_stack((times, msd[:, diagonal, diagonal], msd_error[:, diagonal, diagonal])),
               header=header)
    np.savez(output + '.npz', times=times, msd=msd, msd_error=msd_error, point=np.array(args.point),
             files=np.array(args.files))
    print('wrote %s.txt and %s.npz (%d lags, %d trajectories)' % (output, output, len(lags), len(trajectories)))
    return 0


if __name__ == '__main__':
    sys.exit(utils.fail_cleanly(main))
