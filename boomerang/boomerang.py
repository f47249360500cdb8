"""Brownian dynamics of one boomerang above a wall (Delong, Balboa Usabiaga and Donev, J. Chem. Phys. 2015).

Run from inside ``boomerang/``::

    python boomerang.py -dt 0.01 -N 1000 -gfactor 1.0 -scheme RFD --data-name run-1

Options (the published ones, plus ``--data-dir``, ``--seed`` and ``--implementation``):

* ``-dt`` time step (s), ``-N`` number of steps, ``-gfactor`` multiplies gravity
  (default 1), ``-scheme`` ``RFD`` (default), ``FIXMAN`` or ``EM``;
* ``--data-name`` text appended to the trajectory file name;
* ``--profile`` (or ``--profile True`` / ``--profile 1``, the published form) runs under cProfile and
  prints the 25 most expensive calls;
* ``--data-dir`` folder for the data (default: ``DATA_DIR`` of a
  ``config_local.py`` in the current folder, this folder or the repository
  root, as the published code read it; else ``./data``);
* ``--seed`` seed of the run's random generator; ``--implementation``
  dense blob mobility, ``python`` (default) or ``C++``.

The body starts at (0, 0, 2) um with the identity orientation.  A step that
puts a blob below ``z = A`` is repeated with new noise (the count is logged).
Output: ``<data dir>/boomerang/boomerang-trajectory-dt-<dt>-N-<N>-scheme-<scheme>-g-<gfactor>[-<name>].txt``
with a ``Parameters:`` block (``key: value`` lines), then ``Trajectory data:``,
``Location, Orientation:`` and one line ``x, y, z, s, p1, p2, p3`` per
configuration (the initial one and one after each step: N + 1 lines).  A log
is written to ``./logs/``.  See ``doc/boomerang.md``.
"""
import argparse
import cProfile
import logging
import os
import pstats
import runpy
import sys
import time

# The one path prelude of the scripts: the repository root first, then utils.prepare_script_path.
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import utils  # noqa: E402
utils.prepare_script_path(__file__)

import numpy as np  # noqa: E402

from body.body import Body  # noqa: E402
from boomerang import boomerang_model as bm  # noqa: E402
from mobility.interface import registered_backends  # noqa: E402
from sphere.single_body_integrators import SCHEMES, SingleBodyIntegrator  # noqa: E402


def find_data_dir(data_dir=None):
    """Folder for the data: ``data_dir`` if given, else ``DATA_DIR`` of ``config_local.py``, else ``./data``.

    ``config_local.py`` is looked for in the current folder, the folder of
    this script and the repository root (in that order).
    """
    if data_dir:
        return data_dir
    script_dir = os.path.dirname(os.path.abspath(__file__))
    for folder in (os.getcwd(), script_dir, os.path.dirname(script_dir)):
        path = os.path.join(folder, 'config_local.py')
        if os.path.isfile(path):
            namespace = runpy.run_path(path)
            if 'DATA_DIR' not in namespace:
                raise utils.UserInputError('%s does not define DATA_DIR; add a line DATA_DIR = "path/to/data" '
                                           'or pass --data-dir' % path)
            return str(namespace['DATA_DIR'])
    return os.path.join(os.getcwd(), 'data')


def profile_flag(text):
    """The value of ``--profile``: the published scripts took ``--profile True`` (or ``1``).

    ``True``/``1``/``yes``/``on`` profile, ``False``/``0``/``no``/``off`` do
    not (case-insensitive); a bare ``--profile`` profiles.  (The published
    ``type=bool`` turned any non-empty word, ``False`` included, into True;
    here the word is read as written.)
    """
    word = str(text).strip().lower()
    if word in ('true', '1', 'yes', 'on'):
        return True
    if word in ('false', '0', 'no', 'off'):
        return False
    raise argparse.ArgumentTypeError("--profile takes True or False (or 1 / 0), got '%s'" % text)


def add_profile_option(parser):
    """``--profile [True|False]``: run under cProfile and print the 25 most expensive calls."""
    parser.add_argument('--profile', nargs='?', const=True, default=False, type=profile_flag, metavar='True|False',
                        help='run under cProfile and print the 25 most expensive calls (--profile, --profile True '
                             'or --profile 1 as in the published scripts)')


def run_profiled(function, *args, **kwargs):
    """``function(*args, **kwargs)`` under cProfile; prints the 25 most expensive calls (cumulative) and
    returns the function's result."""
    profiler = cProfile.Profile()
    try:
        return profiler.runcall(function, *args, **kwargs)
    finally:
        pstats.Stats(profiler, stream=sys.stdout).sort_stats('cumulative').print_stats(25)


def trajectory_name(dt, n_steps, scheme, gfactor, data_name=''):
    """File name of a trajectory, as the published code named it."""
    name = 'boomerang-trajectory-dt-%s-N-%s-scheme-%s-g-%s' % (dt, n_steps, scheme, gfactor)
    if data_name:
        name += '-' + data_name
    return name + '.txt'


def write_header(f, parameters):
    """``Parameters:`` block, ``key: value`` lines, then the two lines that open the trajectory."""
    f.write('Parameters:\n')
    for key, value in parameters.items():
        f.write('%s: %s \n' % (key, value))
    f.write('Trajectory data:\n')
    f.write('Location, Orientation:\n')


def format_configuration(location, orientation):
    """One trajectory line: ``x, y, z, s, p1, p2, p3 `` (round-trip precision)."""
    return ', '.join(repr(float(v)) for v in np.concatenate((location, orientation))) + ' \n'


def run(dt, n_steps, gfactor=1.0, scheme='RFD', data_name='', data_dir=None, seed=None,
        implementation='python', logger=None):
    """Integrate one boomerang and write its trajectory; returns the trajectory path."""
    if not dt > 0.0:
        raise utils.UserInputError('-dt must be a positive time step (seconds), got %s' % dt)
    if n_steps < 1:
        raise utils.UserInputError('-N must be a positive number of steps, got %s' % n_steps)
    if not gfactor > 0.0:
        raise utils.UserInputError('-gfactor must be positive, got %s' % gfactor)
    logger = logger or utils.get_logger('boomerang')
    model = bm.BoomerangModel(gfactor, implementation)
    body = Body(bm.INITIAL_LOCATION, bm.INITIAL_ORIENTATION, model.reference, bm.A)
    body.ID = 'boomerang'
    rng = np.random.default_rng(seed)
    integrator = SingleBodyIntegrator(scheme, model.mobility, model.force_torque, bm.KT, model.is_valid, rng)

    folder = os.path.join(find_data_dir(data_dir), 'boomerang')
    os.makedirs(folder, exist_ok=True)
    path = os.path.join(folder, trajectory_name(dt, n_steps, scheme, gfactor, data_name))
    parameters = {'A': repr(float(bm.A)), 'REPULSION_STRENGTH': repr(float(bm.REPULSION_STRENGTH)),
                  'ETA': repr(float(bm.ETA)), 'gfactor': gfactor, 'KT': repr(float(bm.KT)), 'n_steps': n_steps, 'dt': dt, 'scheme': scheme,
                  'M': '[' + ', '.join(repr(float(w)) for w in model.blob_weights) + ']',
                  'DEBYE_LENGTH': repr(float(bm.DEBYE_LENGTH)), 'seed': seed, 'implementation': implementation}
    start = time.perf_counter()
    report_every = max(1, n_steps // 20)
    with open(path, 'w') as f:
        write_header(f, parameters)
        f.write(format_configuration(body.location, body.orientation.entries))
        location = body.location[None, :]
        orientation = body.orientation.entries[None, :]
        for step in range(1, n_steps + 1):
            location, orientation = integrator.step(location, orientation, dt)
            f.write(format_configuration(location[0], orientation[0]))
            if step % report_every == 0 or step == n_steps:
                logger.info('scheme = %s, step = %d of %d, invalid configurations = %d, wallclock time = %.3f s'
                            % (scheme, step, n_steps, integrator.rejections, time.perf_counter() - start))
    body.location = location[0]
    body.orientation = type(body.orientation)(orientation[0])
    logger.info('wrote %s (%d configurations, %d rejected trial steps, %.3f s)'
                % (path, n_steps + 1, integrator.rejections, time.perf_counter() - start))
    return path


def main(argv=None):
    parser = argparse.ArgumentParser(description='Brownian dynamics of one boomerang (15 blobs) above a wall; '
                                                 'see doc/boomerang.md.')
    parser.add_argument('-dt', dest='dt', type=float, required=True, help='time step (s)')
    parser.add_argument('-N', dest='n_steps', type=int, required=True, help='number of steps')
    parser.add_argument('-gfactor', dest='gfactor', type=float, default=1.0,
                        help='factor multiplying gravity (default 1)')
    parser.add_argument('-scheme', dest='scheme', choices=SCHEMES, default='RFD',
                        help='RFD (default), FIXMAN or EM (no drift: wrong equilibrium near the wall)')
    parser.add_argument('--data-name', dest='data_name', default='',
                        help='text appended to the trajectory file name (e.g. run-1)')
    add_profile_option(parser)
    parser.add_argument('--data-dir', dest='data_dir', default=None,
                        help='data folder (default: DATA_DIR of config_local.py, else ./data)')
    parser.add_argument('--seed', type=int, default=None, help='seed of the random generator')
    parser.add_argument('--implementation', default='python',
                        choices=registered_backends('single_wall', dense_matrices=True),
                        help='dense blob mobility backend (default python)')
    args = parser.parse_args(argv)

    os.makedirs('logs', exist_ok=True)
    log_name = os.path.join('logs', os.path.basename(trajectory_name(args.dt, args.n_steps, args.scheme,
                                                                     args.gfactor, args.data_name))[:-4] + '.log')
    logger = utils.get_logger('boomerang')
    handler = logging.FileHandler(log_name, mode='w')
    handler.setFormatter(logging.Formatter('%(message)s'))
    logger.addHandler(handler)
    try:
        kwargs = dict(dt=args.dt, n_steps=args.n_steps, gfactor=args.gfactor, scheme=args.scheme,
                      data_name=args.data_name, data_dir=args.data_dir, seed=args.seed,
                      implementation=args.implementation, logger=logger)
        if args.profile:
            run_profiled(run, **kwargs)
        else:
            run(**kwargs)
    except utils.SimulationStopped as err:
        logger.info('stopped: %s' % err)
        print('stopped: %s' % err, file=sys.stderr)
        return 1
    finally:
        logger.removeHandler(handler)
        handler.close()
    return 0


if __name__ == '__main__':
    sys.exit(utils.fail_cleanly(main))
