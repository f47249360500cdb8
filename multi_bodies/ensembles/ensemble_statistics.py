"""Statistics of a finished ensemble: heights, mean-square displacements, ``.info`` counts (floor 7).

:func:`aggregate` reads the manifest ``D/ensemble.json`` written by
:mod:`multi_bodies.ensembles.ensemble_runner` and, for every parameter point, every
replica whose ``status.json`` says done.  Paths are taken relative to ``D``,
so an ensemble run on a cluster can be copied elsewhere and aggregated
there.  Per replica it computes

* the density of body heights z (all saved frames from ``discard`` on, all
  bodies of a structure type), on bins of each structure type common to
  every point and replica;
* the mean-square displacement of the body locations against the lag time
  ``lag * n_save * dt``: parallel to the wall (``msd_xy``), normal to it
  (``msd_z``) and their sum (``msd_location``), averaged over bodies and
  time origins;
* the mean-square rotational displacement (``msd_orientation``) of
  Delong et al., J. Chem. Phys. 143, 144107 (2015):
  ``Δu = 1/2 Σ_i u_i(t) × u_i(t + τ)``, u_i the body axes (columns of the
  rotation matrix); for small rotations Δu is the rotation vector;
* the counters of its ``.info`` file.

Each quantity is then averaged over the replicas of the point, with the
standard error ``std(ddof=1) / sqrt(R)`` as error bar (NaN for one
replica), since replicas are independent.  Outputs: ``D/<point>/statistics.csv``
(one table per point, columns ``quantity, structure, x, mean, stderr,
replicas``), ``D/summary.csv`` (one row per point) and, with matplotlib,
``D/heights.png`` and ``D/msd.png``.
"""
import csv
import io
import os

import numpy as np

from body.geometry import rotation_matrices as _rotation_matrices
from multi_bodies.ensembles import ensemble_runner
from multi_bodies.files import snapshots
from multi_bodies.run import run_output
from multi_bodies.files.input_options import parse_input_text
import utils
from utils import UserInputError, read_text_file

MSD_QUANTITIES = ('msd_xy', 'msd_z', 'msd_location', 'msd_orientation')


# ------------------------------------------------------------------ per replica
def rotation_matrices(quaternions):
    """Rotation matrices of scalar-first quaternions (..., 4) -> (..., 3, 3): the package's one formula."""
    return _rotation_matrices(quaternions)


def mean_square_displacements(frames, max_lag):
    """MSDs of one structure's trajectory, averaged over bodies and time origins.

    frames : (F, n, 7) saved snapshots (``x y z s p1 p2 p3`` per body)
    max_lag : largest lag in saved frames (clipped to F - 1)
    Returns a dict quantity -> (max_lag,) array for lags 1..max_lag (lengths
    squared, and dimensionless for ``msd_orientation``).
    """
    frames = np.asarray(frames, dtype=float)
    max_lag = min(int(max_lag), frames.shape[0] - 1)
    locations = frames[:, :, :3]
    axes = rotation_matrices(frames[:, :, 3:])  # (F, n, 3, 3), column i = body axis u_i
    out = {name: np.zeros(max(max_lag, 0)) for name in MSD_QUANTITIES}
    for lag in range(1, max_lag + 1):
        displacement = locations[lag:] - locations[:-lag]
        out['msd_xy'][lag - 1] = np.mean(displacement[..., 0] ** 2 + displacement[..., 1] ** 2)
        out['msd_z'][lag - 1] = np.mean(displacement[..., 2] ** 2)
        rotation = 0.5 * np.cross(axes[:-lag], axes[lag:], axis=-2).sum(axis=-1)  # (F - lag, n, 3)
        out['msd_orientation'][lag - 1] = np.mean(np.sum(rotation ** 2, axis=-1))
    out['msd_location'] = out['msd_xy'] + out['msd_z']
    return out


def replica_trajectories(output_dir, replica):
    """Snapshots of a finished replica: (options, {structure ID: frames (F, n, 7)}).

    The replica's ``input.dat`` gives the structures, ``save_clones``,
    ``dt`` and ``n_save``; outputs are read from the replica folder under
    ``output_dir`` whatever absolute ``output_name`` the run had.
    """
    folder = os.path.join(output_dir, replica['folder'])
    input_path = os.path.join(folder, ensemble_runner.REPLICA_INPUT_NAME)
    options = parse_input_text(read_text_file(input_path, 'replica input file', 'run the ensemble again to write '
                                              'it'), input_path)
    output_name = os.path.join(folder, replica.get('output_basename') or os.path.basename(options.output_name))
    trajectories = {}
    for structure_id in dict.fromkeys(spec.ID for spec in options.structures):
        if options.save_clones == 'one_file':
            frames = snapshots.read_config_frames(snapshots.config_name(output_name, structure_id))
        else:
            frames = snapshots.read_clones_frames(output_name, structure_id)[1]
        trajectories[structure_id] = frames
    return options, output_name, trajectories


def mean_and_error(values):
    """Mean over axis 0 and its standard error std(ddof=1)/sqrt(R) (NaN for R = 1)."""
    values = np.asarray(values, dtype=float)
    mean = values.mean(axis=0)
    if values.shape[0] < 2:
        return mean, np.full_like(mean, np.nan)
    return mean, values.std(axis=0, ddof=1) / np.sqrt(values.shape[0])


# ------------------------------------------------------------------ the ensemble
def _finished_replicas(manifest):
    by_point = {index: [] for index in range(len(manifest['points']))}
    missing = []
    for replica in manifest['replicas']:
        status = ensemble_runner.read_status(os.path.join(manifest['output_dir'], replica['folder']))
        if status and status.get('status') == 'done':
            by_point[replica['point']].append(replica)
        else:
            missing.append((replica['folder'], (status or {}).get('status', 'not run')))
    return by_point, missing


def aggregate(output_dir, bins=40, height_range=None, max_lag=None, discard=0, charts=True, log=print):
    """Statistics of the ensemble in ``output_dir``; writes the CSV tables (and charts); returns them.

    bins : number of height bins; height_range : (low, high) or None for the
        range of the heights of each structure type over all points (one
        more pass over the files)
    max_lag : largest MSD lag in saved frames (default: half the frames)
    discard : saved frames dropped at the start of every replica
    Returns ``{point name: {'overrides', 'replicas', 'height': {ID: (edges,
    mean, stderr)}, 'msd': {ID: {'lag_time', quantity: (mean, stderr)}},
    'info': {counter: (mean, stderr)}}}``.
    """
    if int(bins) < 1:
        raise UserInputError('--bins %d: the height histogram needs at least one bin' % bins)
    # per bin and replica: the counts and the density (a row of the table), twice while they are averaged
    utils.refuse_if_too_big(32 * int(bins) * 4, 'the height histogram of %d bins' % int(bins), '--bins %d' % bins,
                            'ask for fewer bins')
    if max_lag is not None and int(max_lag) < 1:
        raise UserInputError('--max-lag %d: the largest lag must be at least 1 saved frame' % max_lag)
    if int(discard) < 0:
        raise UserInputError('--discard %d: it must be 0 or more saved frames' % discard)
    if height_range is not None and not (np.all(np.isfinite(height_range)) and height_range[1] > height_range[0]):
        raise UserInputError('--height-range %s: give two finite heights LOW < HIGH'
                             % ' '.join('%r' % float(v) for v in height_range))
    manifest = ensemble_runner.read_manifest(output_dir)
    output_dir = manifest['output_dir']
    by_point, missing = _finished_replicas(manifest)
    if not any(by_point.values()):
        raise UserInputError('%s: no replica has finished yet (%d planned); run the ensemble first'
                             % (output_dir, len(manifest['replicas'])))
    if missing:
        log('aggregating the %d finished replicas; left out: %s' % (
            sum(len(v) for v in by_point.values()),
            ', '.join('%s (%s)' % item for item in missing[:10]) + (' ...' if len(missing) > 10 else '')))

    def load(replica):
        options, output_name, trajectories = replica_trajectories(output_dir, replica)
        return options, output_name, {sid: frames[discard:] for sid, frames in trajectories.items()}

    ranges = {}  # structure ID -> (lowest, highest) height over every point and replica
    if height_range is None:  # pass 1: the height range of every structure type
        for replicas in by_point.values():
            for replica in replicas:
                for sid, frames in load(replica)[2].items():
                    if frames.size:
                        low, high = ranges.get(sid, (np.inf, -np.inf))
                        ranges[sid] = (min(low, frames[:, :, 2].min()), max(high, frames[:, :, 2].max()))
        if not ranges:
            raise UserInputError('%s: the finished replicas have no saved frames to aggregate' % output_dir)
    edges_of = {}

    def edges_for(sid):
        if sid not in edges_of:
            low, high = height_range if height_range is not None else ranges.get(sid, (0.0, 1.0))
            edges_of[sid] = np.linspace(low, high if high > low else low + 1.0, int(bins) + 1)
        return edges_of[sid]

    statistics = {}
    for index, point in enumerate(manifest['points']):
        replicas = by_point[index]
        if not replicas:
            log('point %s: no finished replica' % point['name'])
            continue
        heights, msds, infos, lag_time = {}, {}, [], {}
        for replica in replicas:
            options, output_name, trajectories = load(replica)
            for sid, frames in trajectories.items():
                z = frames[:, :, 2].ravel()
                edges = edges_for(sid)
                counts = np.histogram(z, bins=edges)[0]
                heights.setdefault(sid, []).append(counts / (max(z.size, 1) * np.diff(edges)))
                lags = (frames.shape[0] // 2) if max_lag is None else max_lag
                msd = mean_square_displacements(frames, lags)
                msds.setdefault(sid, []).append(msd)
                lag_time[sid] = np.arange(1, len(msd['msd_xy']) + 1) * options.n_save * options.dt
            infos.append(run_output.read_info(output_name + '.info'))
        point_stats = {'overrides': point['overrides'], 'replicas': len(replicas), 'height': {}, 'msd': {},
                       'info': {}}
        for sid, densities in heights.items():
            point_stats['height'][sid] = (edges_for(sid),) + mean_and_error(densities)
        for sid, per_replica in msds.items():
            length = min(len(m['msd_xy']) for m in per_replica)
            entry = {'lag_time': lag_time[sid][:length]}
            for quantity in MSD_QUANTITIES:
                entry[quantity] = mean_and_error([m[quantity][:length] for m in per_replica])
            point_stats['msd'][sid] = entry
        counters = [key for key in infos[0] if all(isinstance(info.get(key), (int, float)) for info in infos)]
        for key in counters:
            point_stats['info'][key] = mean_and_error([float(info[key]) for info in infos])
        statistics[point['name']] = point_stats
        path = os.path.join(output_dir, point['name'], 'statistics.csv')
        run_output.atomic_write(path, point_table(point_stats))
        log('point %s: %d replicas -> %s' % (point['name'], len(replicas), path))
    summary = os.path.join(output_dir, 'summary.csv')
    run_output.atomic_write(summary, summary_table(manifest, statistics))
    log('summary of %d points -> %s' % (len(statistics), summary))
    if charts:
        draw_charts(output_dir, statistics, log=log)
    return statistics


def _number(value):
    return repr(float(value))


def point_table(point_stats):
    """CSV text of one point: ``quantity, structure, x, mean, stderr, replicas`` (numbers round-trip)."""
    out = io.StringIO()
    writer = csv.writer(out, lineterminator='\n')
    writer.writerow(['quantity', 'structure', 'x', 'mean', 'stderr', 'replicas'])
    replicas = point_stats['replicas']
    for sid, (edges, mean, error) in point_stats['height'].items():
        centres = 0.5 * (edges[1:] + edges[:-1])
        for x, m, e in zip(centres, mean, error):
            writer.writerow(['height_density', sid, _number(x), _number(m), _number(e), replicas])
    for sid, entry in point_stats['msd'].items():
        for quantity in MSD_QUANTITIES:
            mean, error = entry[quantity]
            for x, m, e in zip(entry['lag_time'], mean, error):
                writer.writerow([quantity, sid, _number(x), _number(m), _number(e), replicas])
    for key, (mean, error) in point_stats['info'].items():
        writer.writerow(['info', '', key, _number(mean), _number(error), replicas])
    return out.getvalue()


def summary_table(manifest, statistics):
    """CSV text: one row per point with its varied values, finished replicas and mean ``.info`` counters."""
    names = [one for name, _ in manifest['vary'] for one in name.split(':')]  # 'dt:n_steps' is two columns
    counters = []
    for point_stats in statistics.values():
        counters.extend(key for key in point_stats['info'] if key not in counters)
    out = io.StringIO()
    writer = csv.writer(out, lineterminator='\n')
    writer.writerow(['point'] + names + ['replicas'] + ['mean_' + key for key in counters])
    for point in manifest['points']:
        point_stats = statistics.get(point['name'])
        values = dict(point['overrides'])
        row = [point['name']] + [values.get(name, '') for name in names]
        if point_stats is None:
            writer.writerow(row + [0] + [''] * len(counters))
            continue
        info = point_stats['info']
        writer.writerow(row + [point_stats['replicas']]
                        + [_number(info[key][0]) if key in info else '' for key in counters])
    return out.getvalue()


def draw_charts(output_dir, statistics, log=print):
    """``heights.png`` and ``msd.png`` in ``output_dir``: every point, with its error bars (needs matplotlib)."""
    try:
        import matplotlib
        matplotlib.use('Agg')
        import matplotlib.pyplot as plt
    except ImportError:
        log('charts skipped: matplotlib is not installed (%s)' % ensemble_runner.INSTALL_HINT)
        return []
    structures = list(dict.fromkeys(sid for s in statistics.values() for sid in s['height']))
    written = []
    fig, axes = plt.subplots(1, len(structures), figsize=(5 * len(structures), 4), squeeze=False)
    for ax, sid in zip(axes[0], structures):
        for name, point_stats in statistics.items():
            if sid in point_stats['height']:
                edges, mean, error = point_stats['height'][sid]
                centres = 0.5 * (edges[1:] + edges[:-1])
                ax.errorbar(centres, mean, yerr=np.nan_to_num(error), label=name, capsize=2)
        ax.set_xlabel('height z')
        ax.set_ylabel('probability density')
        ax.set_title(sid)
        ax.legend(fontsize='small')
    fig.tight_layout()
    path = os.path.join(output_dir, 'heights.png')
    fig.savefig(path, dpi=100)
    plt.close(fig)
    written.append(path)
    fig, axes = plt.subplots(2, len(structures), figsize=(5 * len(structures), 8), squeeze=False)
    for column, sid in enumerate(structures):
        for row, (quantity, label) in enumerate((('msd_location', 'MSD of locations'),
                                                 ('msd_orientation', 'MSD of orientations'))):
            ax = axes[row][column]
            for name, point_stats in statistics.items():
                if sid in point_stats['msd'] and len(point_stats['msd'][sid]['lag_time']):
                    entry = point_stats['msd'][sid]
                    mean, error = entry[quantity]
                    ax.errorbar(entry['lag_time'], mean, yerr=np.nan_to_num(error), label=name, capsize=2)
            ax.set_xlabel('lag time')
            ax.set_ylabel(label)
            ax.set_title(sid)
            ax.legend(fontsize='small')
    fig.tight_layout()
    path = os.path.join(output_dir, 'msd.png')
    fig.savefig(path, dpi=100)
    plt.close(fig)
    written.append(path)
    log('charts -> %s' % ', '.join(written))
    return written
