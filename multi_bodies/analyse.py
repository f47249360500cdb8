"""Pair correlation g(r), structure factor S(k), F(k, t) and mean-square displacements of saved runs.

Run from the folder the run was started in (as the other scripts)::

    python analyse.py --input-file inputfile.dat --gr --sk --fkt --msd
    python analyse.py --ensemble sweep --msd            # replicas of an ensemble: error bars across replicas
    python analyse.py --input-file inputfile.dat --hydrogrid   # the published HydroGrid options, after the run

It reads the snapshots the run saved (``.clones`` per step or the ``.config``
series) and writes text tables ``O.gr.dat``, ``O.sk.dat``, ``O.sk_radial.dat``,
``O.fkt.dat``, ``O.msd.dat`` and PNG charts (with matplotlib), ``O`` being
``--output-name`` (default: the run's ``output_name``; an ensemble's
``D/analysis``).  Every option and column: doc/analysis.md.
"""
import argparse
import math
import os
import sys

# The one path prelude of the scripts: the repository root first, then utils.prepare_script_path.
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import utils  # noqa: E402
utils.prepare_script_path(__file__)

import numpy as np  # noqa: E402

from multi_bodies.analysis import tables  # noqa: E402
from multi_bodies.analysis.hydrogrid import HydroGridPlan, write_hydrogrid_tables  # noqa: E402
from multi_bodies.analysis.pair_correlation import PairCorrelation  # noqa: E402
from multi_bodies.analysis.structure_factor import StructureFactor  # noqa: E402
from multi_bodies.analysis.time_correlations import TimeCorrelations, lag_list, shell_wavevectors  # noqa: E402
from multi_bodies.analysis.trajectories import ConfigSeries, analyse, check_same_box, run_trajectory  # noqa: E402
from multi_bodies.files.input_options import parse_input_text  # noqa: E402
from utils import UserInputError  # noqa: E402


def ensemble_sources(folder, structure_ids=None):
    """One source per finished replica of the ensemble in ``folder`` (status ``done``)."""
    from multi_bodies.ensembles.ensemble_plan import REPLICA_INPUT_NAME, read_manifest, read_status
    manifest = read_manifest(folder)
    sources, options = [], None
    for replica in manifest['replicas']:
        path = os.path.join(manifest['output_dir'], replica['folder'])
        if (read_status(path) or {}).get('status') != 'done':
            continue
        input_file = os.path.join(path, REPLICA_INPUT_NAME)
        options = parse_input_text(utils.read_text_file(input_file, 'replica input file', 'rerun the ensemble'),
                                   input_file)
        # the outputs are inside the replica folder, whatever absolute output_name the run had
        name = os.path.join(path, replica.get('output_basename') or os.path.basename(options.output_name))
        source, options = run_trajectory(input_file, structure_ids, output_name=name)
        sources.append(source)
    if not sources:
        raise UserInputError('%s: no finished replica (status done) to analyse' % folder)
    return sources, options


def parse_arguments(argv):
    parser = argparse.ArgumentParser(description='g(r), S(k), F(k,t) and MSD of saved runs (doc/analysis.md).')
    where = parser.add_mutually_exclusive_group(required=True)
    where.add_argument('--input-file', help='input file of the run (run from the folder the run was started in)')
    where.add_argument('--ensemble', help='output folder of multi_bodies/ensemble.py: every finished replica')
    where.add_argument('--config', help='a .config file (save_clones one_file) without its input file')
    parser.add_argument('--structure', action='append', help='structure ID to analyse (repeat; default: all)')
    parser.add_argument('--periodic-length', type=float, nargs=3, metavar=('LX', 'LY', 'LZ'),
                        help='periodic box (default: periodic_length of the input file)')
    parser.add_argument('--frame-interval', type=float, help='time between frames (default dt * n_save)')
    parser.add_argument('--output-name', help='prefix of the tables and charts (default: the run\'s output_name)')
    parser.add_argument('--gr', action='store_true', help='pair correlation g(r)')
    parser.add_argument('--sk', action='store_true', help='static structure factor S(k)')
    parser.add_argument('--fkt', action='store_true', help='intermediate scattering function F(k,t)')
    parser.add_argument('--msd', action='store_true', help='mean-square displacements')
    parser.add_argument('--hydrogrid', action='store_true', help='the HydroGrid options of the input file')
    parser.add_argument('--dimension', type=int, default=2, choices=(2, 3), help='2: in the plane x, y (default)')
    parser.add_argument('--r-max', type=float, help='largest r of g(r) (default: half the shortest periodic length)')
    parser.add_argument('--bins', type=int, default=100, help='bins of g(r) (default 100)')
    parser.add_argument('--k-index-max', type=int, default=16, help='S(k): |n| <= this on every axis (default 16)')
    parser.add_argument('--green', type=int, nargs=2, metavar=('I0', 'I1'), help='S(k) per species: green i0..i1-1')
    parser.add_argument('--k-values', help='F(k,t): wavenumbers, comma separated (default 2 pi/L x 1, 2, 4, 8)')
    parser.add_argument('--max-lag', type=int, help='largest lag in frames (default min(100, frames / 2))')
    parser.add_argument('--discard', type=int, default=0, help='frames left out at the start (default 0)')
    parser.add_argument('--stride', type=int, default=1, help='use every stride-th frame (default 1)')
    parser.add_argument('--blocks', type=int, default=10, help='blocks of frames for the error bars of one run')
    parser.add_argument('--origin-every', type=int, help='F(k,t)/MSD: frames between time origins (default 1, or '
                        'the smallest spacing that keeps the buffer under 1 GiB)')
    parser.add_argument('--unwrap', action='store_true', help='undo periodic jumps (trajectories saved in the box)')
    parser.add_argument('--no-charts', action='store_true', help='write the tables only')
    return check_arguments(parser.parse_args(argv))


def check_arguments(args):
    """Refuse, naming the flag, a count or length that cannot be meant (zero, negative, NaN, infinite) before
    anything is read; the memory the accumulators need is checked where they are made."""
    def flag(name):
        return '--' + name.replace('_', '-')
    for name, low in (('bins', 1), ('k_index_max', 1), ('stride', 1), ('blocks', 1), ('discard', 0),
                      ('max_lag', 1), ('origin_every', 1)):
        value = getattr(args, name)
        if value is not None and value < low:
            raise UserInputError('%s %d: it must be an integer >= %d' % (flag(name), value, low))
    for name in ('r_max', 'frame_interval'):
        value = getattr(args, name)
        if value is not None and not (np.isfinite(value) and value > 0):
            raise UserInputError('%s %r: it must be a positive finite number' % (flag(name), value))
    if args.periodic_length is not None and not all(np.isfinite(v) and v >= 0 for v in args.periodic_length):
        raise UserInputError('--periodic-length %s: each length must be 0 (not periodic) or a positive finite number'
                             % ' '.join('%r' % v for v in args.periodic_length))
    if args.green is not None and not 0 <= args.green[0] <= args.green[1]:
        raise UserInputError('--green %d %d: it needs 0 <= i0 <= i1' % tuple(args.green))
    return args


def load_sources(args):
    """(sources, options or None, default output name)."""
    options = None
    if args.ensemble:
        sources, options = ensemble_sources(args.ensemble, args.structure)
        default_name = os.path.join(args.ensemble, 'analysis')
    elif args.input_file:
        source, options = run_trajectory(args.input_file, args.structure)
        sources, default_name = [source], options.output_name
    else:
        if args.frame_interval is None:
            raise UserInputError('--config needs --frame-interval (the time between its snapshots)')
        if not os.path.isfile(args.config):
            raise UserInputError('--config %s: %s; give the .config file of a save_clones one_file run '
                                 '(<output_name>.<structure>.config)'
                                 % (args.config, 'is not a file' if os.path.exists(args.config) else 'no such file'))
        path = args.config[:-len('.config')] if args.config.endswith('.config') else args.config
        folder, base = os.path.split(path)
        stem, _, structure_id = base.rpartition('.')
        if not stem:
            raise UserInputError('--config %s: the name does not say the run and the structure; a save_clones one_file '
                                 'run writes <output_name>.<structure>.config' % args.config)
        source = ConfigSeries(os.path.join(folder, stem), [structure_id], args.frame_interval, 1,
                              args.periodic_length or (0, 0, 0), label=args.config)
        sources, default_name = [source], os.path.join(folder, stem)
    for source in sources:
        if args.periodic_length is not None:
            source.periodic_length = np.asarray(args.periodic_length, dtype=float)
        if args.frame_interval is not None:
            source.frame_interval = float(args.frame_interval)
    return sources, options, args.output_name or default_name


def chart(path, *arguments, **keywords):
    message = tables.draw_chart(path, *arguments, **keywords)
    print(message if message else 'wrote %s' % path)


def run_hydrogrid(args, sources, options, output_name):
    if options is None:
        raise UserInputError('--hydrogrid needs the input file (or ensemble) whose HydroGrid options to use')
    plan = HydroGridPlan(options, folder=os.path.dirname(os.path.abspath(args.input_file or args.ensemble)))
    steps_between = getattr(sources[0], 'steps', None)
    spacing = (steps_between[1] - steps_between[0]) if steps_between and len(steps_between) > 1 else options.n_save
    stride = (spacing * plan.sample_every // math.gcd(spacing, plan.sample_every)) // spacing
    structure, correlations = plan.accumulators(options, sources[0].frame_interval * stride)
    analyse(sources, [a for a in (structure, correlations) if a is not None], blocks=args.blocks,
            discard=args.discard, stride=stride, log=print)
    for path in write_hydrogrid_tables(output_name, structure, correlations):
        print('wrote %s' % path)


def main(argv=None):
    args = parse_arguments(argv)
    if not (args.gr or args.sk or args.fkt or args.msd or args.hydrogrid):
        raise UserInputError('nothing to compute: give one or more of --gr, --sk, --fkt, --msd, --hydrogrid')
    sources, options, output_name = load_sources(args)
    box, interval = check_same_box(sources)
    folder = os.path.dirname(output_name)
    if folder:
        os.makedirs(folder, exist_ok=True)
    if args.hydrogrid:
        run_hydrogrid(args, sources, options, output_name)
    accumulators = {}
    if args.gr:
        periodic = box[:args.dimension][box[:args.dimension] > 0]
        r_max = args.r_max or (0.5 * periodic.min() if len(periodic) else None)
        if r_max is None:
            raise UserInputError('g(r) in a box without periodic axes needs --r-max')
        accumulators['gr'] = PairCorrelation(box, r_max, args.bins, args.dimension, where='--bins %d' % args.bins,
                                             blocks=args.blocks)
    if args.sk:
        accumulators['sk'] = StructureFactor(box, args.k_index_max, args.dimension, green=args.green,
                                             where='--k-index-max %d' % args.k_index_max, blocks=args.blocks)
    shell_k = None
    if args.fkt or args.msd:
        frames = min((s.n_frames - args.discard + args.stride - 1) // args.stride for s in sources)
        max_lag = args.max_lag or max(1, min(100, frames // 2))
        wavevectors = groups = None
        collective = False
        if args.fkt:
            lengths = box[:args.dimension][box[:args.dimension] > 0]
            base = 2.0 * np.pi / (lengths.min() if len(lengths) else 1.0)
            try:
                k_values = ([float(v) for v in args.k_values.split(',')] if args.k_values
                            else [base * n for n in (1, 2, 4, 8)])
            except ValueError:
                raise UserInputError('--k-values expects numbers separated by commas, got %r' % args.k_values)
            wavevectors, groups, shell_k, collective = shell_wavevectors(box, k_values, args.dimension,
                                                                         where='--k-values')
        accumulators['time'] = TimeCorrelations(interval * args.stride, lag_list(max_lag), box, wavevectors,
                                                groups, args.dimension, collective=collective, msd=args.msd,
                                                unwrap=args.unwrap, origin_every=args.origin_every)
    if accumulators:
        analyse(sources, list(accumulators.values()), blocks=args.blocks, discard=args.discard, stride=args.stride,
                log=print)
    charts = not args.no_charts
    if 'gr' in accumulators:
        result = accumulators['gr'].result()
        print('wrote %s' % tables.write_pair_correlation(output_name + '.gr.dat', result, box))
        if charts:
            chart(output_name + '.gr.png', 'pair correlation (%d-d)' % args.dimension, 'r', 'g(r)',
                  [('g(r)', result['r'], result['g'], result['g_error'])],
                  reference=('ideal gas', [0, result['r'][-1]], [1, 1]))
    if 'sk' in accumulators:
        result = accumulators['sk'].result()
        for path in tables.write_structure_factor(output_name + '.sk.dat', output_name + '.sk_radial.dat', result):
            print('wrote %s' % path)
        if charts:
            radial = result['radial']
            chart(output_name + '.sk.png', 'static structure factor (%d-d, radially binned)' % args.dimension,
                  'k', 'S(k)', [('S %s-%s' % pair, radial['k'], radial['S'][i], radial['S_error'][i])
                                for i, pair in enumerate(result['pairs'])],
                  reference=('ideal gas', [0, radial['k'][-1]], [1, 1]))
    if 'time' in accumulators:
        result = accumulators['time'].result()
        if args.msd:
            print('wrote %s' % tables.write_msd(output_name + '.msd.dat', result))
            if charts:
                chart(output_name + '.msd.png', 'mean-square displacement', 'time', 'MSD',
                      [('xy', result['time'][1:], result['msd_xy'][1:], result['msd_xy_error'][1:]),
                       ('z', result['time'][1:], result['msd_z'][1:], result['msd_z_error'][1:])], log_x=True)
        if args.fkt:
            print('wrote %s' % tables.write_fkt(output_name + '.fkt.dat', result, shell_k))
            if charts:
                curves = []
                for shell, k in enumerate(shell_k):
                    curves.append(('self, k=%.3g' % k, result['time'][1:], result['Fs'][1:, shell],
                                   result['Fs_error'][1:, shell]))
                    if 'F' in result:
                        curves.append(('collective, k=%.3g' % k, result['time'][1:], result['F'][1:, shell],
                                       result['F_error'][1:, shell]))
                chart(output_name + '.fkt.png', 'intermediate scattering function', 'time', 'F(k,t)', curves,
                      log_x=True)
    return 0


if __name__ == '__main__':
    sys.exit(utils.fail_cleanly(main))
