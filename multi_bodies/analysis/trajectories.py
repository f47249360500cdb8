"""Frame sources read in chunks, and the one pass that feeds the analyses (doc/analysis.md).

A *source* is one trajectory of ``N`` particles (body locations): ``n_frames``,
``n_particles``, ``frame_interval`` (time between two frames, ``dt * n_save``
for a run), ``periodic_length`` (3,) (0 on an axis that is not periodic) and
``read(first, stop)`` -> positions (stop - first, N, 3) in length units.  The
sources read only the frames asked for, so memory stays bounded by the chunk:

* :class:`ArrayTrajectory`: positions already in memory (or a ``numpy.memmap``);
* :class:`ClonesSeries`: a run saved with ``save_clones one_file_per_step``
  (``output_name.ID.<step>.clones``; read with ``snapshots.read_clones_file``);
* :class:`ConfigSeries`: a run saved with ``save_clones one_file``
  (``output_name.ID.config``; an index of where each snapshot starts, then
  ``snapshots.read_config_snapshot`` for the frames of a chunk).

Several structures of one run are one source: the bodies of every structure
line, in input order, side by side.  :func:`analyse` reads each source once, in
chunks, and hands every chunk to every accumulator with the block each frame
belongs to: with two or more sources (replicas of an ensemble) the block is the
replica; with one source the frames are cut into ``blocks`` contiguous blocks.
The error bars are the standard errors of the block means,
``std(ddof=1) / sqrt(B)`` (:func:`block_mean_and_error`).
"""
import os

import numpy as np

from multi_bodies.files import snapshots
from multi_bodies.files.input_options import parse_input_text
from utils import UserInputError, read_text_file

# Bytes of positions one chunk may hold (float64): bounds the memory of a pass whatever the trajectory.
CHUNK_BYTES = 64 * 2 ** 20


class ArrayTrajectory:
    """Positions in memory: ``positions`` (F, N, 3) (any array that slices, e.g. a memmap), lengths.

    frame_interval : time between frames; periodic_length : (3,), 0 = not periodic.
    """

    def __init__(self, positions, frame_interval=1.0, periodic_length=(0.0, 0.0, 0.0), label='array'):
        if np.ndim(positions) != 3 or np.shape(positions)[2] != 3:
            raise UserInputError('positions must have shape (frames, particles, 3), got %s' % (np.shape(positions),))
        self.positions, self.label = positions, label
        self.n_frames, self.n_particles = int(np.shape(positions)[0]), int(np.shape(positions)[1])
        self.frame_interval = float(frame_interval)
        self.periodic_length = np.asarray(periodic_length, dtype=float).reshape(3)

    def read(self, first, stop):
        return np.asarray(self.positions[first:stop], dtype=float)


class ClonesSeries:
    """A ``save_clones one_file_per_step`` run: ``output_name.ID.<step>.clones`` of every structure ID.

    Frames are the steps saved for every ID (sorted); ``frame_interval``: time
    between the first two saved steps (``step difference * dt``).
    """

    def __init__(self, output_name, structure_ids, dt, periodic_length, label=None):
        self.output_name, self.structure_ids = output_name, list(structure_ids)
        self.label = label or output_name
        common = None
        self.paths = {}
        for structure_id in self.structure_ids:
            steps, paths = snapshots.clones_series_steps(output_name, structure_id)
            self.paths[structure_id] = dict(zip(steps, paths))
            common = set(steps) if common is None else common & set(steps)
        self.steps = sorted(common or ())
        if not self.steps:
            raise UserInputError('no snapshot %s.%s.<step>.clones found (save_clones one_file_per_step); run the '
                                 'analysis from the folder the run was started in, or check output_name'
                                 % (output_name, self.structure_ids[0]))
        self.n_frames = len(self.steps)
        self.n_particles = self.read(0, 1).shape[1]
        spacing = np.diff(self.steps)
        if len(spacing) and np.any(spacing != spacing[0]):
            raise UserInputError('%s: the saved steps are not equally spaced (%s ...); the time lags need equal '
                                 'spacing: analyse one stretch of the run' % (self.label, self.steps[:4]))
        self.frame_interval = float(dt) * (int(spacing[0]) if len(spacing) else 1)
        self.periodic_length = np.asarray(periodic_length, dtype=float).reshape(3)

    def read(self, first, stop):
        frames = []
        for step in self.steps[first:stop]:
            frames.append(np.concatenate([snapshots.read_clones_file(self.paths[i][step])[0]
                                          for i in self.structure_ids]))
        if len({f.shape for f in frames}) > 1:
            raise UserInputError('%s: the number of bodies changes between snapshots' % self.label)
        return np.stack(frames)


def config_offsets(path):
    """Byte offsets (list of int) where the complete snapshots of a ``.config`` file start.

    Only the count lines are interpreted (the body lines are skipped by
    counting them); the numbers are read by ``snapshots.read_config_snapshot``.
    A snapshot cut short at the end of the file is left out, as the readers do.
    """
    if not os.path.isfile(path):
        raise UserInputError("snapshot file '%s' not found (save_clones one_file)" % path)
    offsets, position, remaining, start = [], 0, 0, None
    with open(path, 'rb') as f:
        for line in f:
            if remaining == 0:
                words = line.split(b'#', 1)[0].split()
                if words:
                    try:
                        remaining = int(words[0])
                    except ValueError:
                        raise UserInputError('%s, byte %d: expected the count line of a snapshot' % (path, position))
                    start = position
            elif line.split(b'#', 1)[0].strip():
                remaining -= 1
                if remaining == 0:
                    offsets.append(start)
            position += len(line)
    return offsets


class ConfigSeries:
    """A ``save_clones one_file`` run: ``output_name.ID.config`` of every structure ID.

    Frame ``i`` is step ``initial_step + i n_save`` (``frame_interval = dt n_save``).
    """

    def __init__(self, output_name, structure_ids, dt, n_save, periodic_length, label=None):
        self.paths = [snapshots.config_name(output_name, i) for i in structure_ids]
        self.label = label or output_name
        self.offsets = [config_offsets(p) for p in self.paths]
        self.n_frames = min(len(o) for o in self.offsets)
        if self.n_frames == 0:
            raise UserInputError('%s holds no complete snapshot' % self.paths[0])
        self.n_particles = self.read(0, 1).shape[1]
        self.frame_interval = float(dt) * int(n_save)
        self.periodic_length = np.asarray(periodic_length, dtype=float).reshape(3)

    def read(self, first, stop):
        frames = [np.concatenate([snapshots.read_config_snapshot(p, o[i])[0] for p, o in zip(self.paths, self.offsets)])
                  for i in range(first, min(stop, self.n_frames))]
        if len({f.shape for f in frames}) > 1:
            raise UserInputError('%s: the number of bodies changes between snapshots' % self.label)
        return np.stack(frames)


def run_trajectory(input_file, structure_ids=None, output_name=None):
    """The saved trajectory of the run of ``input_file`` (relative paths from the working directory).

    structure_ids : the structures to analyse (default: every ``structure`` line's ID, in input order).
    output_name : where the run's outputs are (default: the input file's ``output_name``).
    Returns a ClonesSeries or ConfigSeries of the body locations, and the parsed Options.
    """
    text = read_text_file(input_file, 'input file', 'give the input file of the run with --input-file')
    options = parse_input_text(text, input_file)
    known = list(dict.fromkeys(spec.ID for spec in options.structures))
    ids = list(structure_ids) if structure_ids else known
    unknown = [i for i in ids if i not in known]
    if unknown or not ids:
        raise UserInputError("%s: no structure '%s'; the structures are %s" % (
            input_file, unknown[0] if unknown else '', ', '.join(known) or 'none'))
    name = output_name or options.output_name
    if options.save_clones == 'one_file':
        source = ConfigSeries(name, ids, options.dt, options.n_save, options.periodic_length, label=name)
    else:
        source = ClonesSeries(name, ids, options.dt, options.periodic_length, label=name)
    return source, options


# ------------------------------------------------------------------ the pass
def block_mean_and_error(sums, weights):
    """Weighted mean over blocks and the standard error of the block means.

    sums : (B, ...) per-block sums; weights : (B,) or (B, ...) what each sum is a sum of (frames, pairs).
    Blocks with zero weight are left out.  Returns mean (...), standard error (...)
    ``std(ddof=1)/sqrt(B)`` of the block means (NaN with fewer than two blocks).
    """
    sums = np.asarray(sums, dtype=float)
    weights = np.broadcast_to(np.asarray(weights, dtype=float).reshape(
        np.shape(weights) + (1,) * (sums.ndim - np.ndim(weights))), sums.shape)
    total = weights.sum(axis=0)
    with np.errstate(invalid='ignore', divide='ignore'):
        mean = sums.sum(axis=0) / total
        block_means = sums / weights
    used = weights > 0
    count = used.sum(axis=0)
    deviations = np.where(used, block_means - mean, 0.0)
    with np.errstate(invalid='ignore', divide='ignore'):
        error = np.sqrt((deviations ** 2).sum(axis=0) / (count - 1) / count)
    error = np.where(count >= 2, error, np.nan)
    return mean, error


def check_same_box(sources):
    """The one periodic box and frame interval of all sources (replicas must agree)."""
    box, interval = sources[0].periodic_length, sources[0].frame_interval
    for source in sources[1:]:
        if not np.allclose(source.periodic_length, box) or not np.isclose(source.frame_interval, interval):
            raise UserInputError('%s and %s differ in periodic_length or time between frames; analyse them apart'
                                 % (sources[0].label, source.label))
        if source.n_particles != sources[0].n_particles:
            raise UserInputError('%s has %d particles, %s %d; analyse them apart' % (
                sources[0].label, sources[0].n_particles, source.label, source.n_particles))
    return box, interval


def analyse(sources, accumulators, blocks=10, discard=0, stride=1, chunk_frames=None, log=None):
    """One pass over every source: each chunk of frames goes to every accumulator.

    sources : list of frame sources (one run, or the replicas of an ensemble).
    accumulators : objects with ``start_source()`` and ``add(positions (f, N, 3), frames (f,), blocks (f,))``
        (``frames``: index of each frame among those used in its source, after ``discard`` and ``stride``).
    blocks : blocks of frames per source when there is one source; with several, one block per source.
    discard : frames left out at the start of each source; stride : use every stride-th frame after.
    Returns the number of frames used per source.
    """
    if discard < 0 or stride < 1:
        raise UserInputError('--discard must be >= 0 and --stride >= 1')
    used_counts = []
    for index, source in enumerate(sources):
        used = np.arange(discard, source.n_frames, stride)
        if len(used) == 0:
            raise UserInputError('%s has %d frames; nothing is left after discarding %d' % (
                source.label, source.n_frames, discard))
        if len(sources) > 1:
            block_of = np.full(len(used), index)
        else:
            count = max(1, min(int(blocks), len(used)))
            block_of = np.arange(len(used)) * count // len(used)
        per_chunk = chunk_frames or max(1, int(CHUNK_BYTES // (24 * max(source.n_particles, 1))))
        for accumulator in accumulators:
            accumulator.start_source()
        for first in range(0, len(used), per_chunk):
            frames = used[first:first + per_chunk]
            if stride == 1:
                positions = source.read(int(frames[0]), int(frames[-1]) + 1)
            else:
                positions = np.stack([source.read(int(f), int(f) + 1)[0] for f in frames])
            indices = np.arange(first, first + len(frames))
            for accumulator in accumulators:
                accumulator.add(positions, indices, block_of[indices])
        if log is not None:
            log('%s: %d frames of %d particles analysed' % (source.label, len(used), source.n_particles))
        used_counts.append(len(used))
    return used_counts


class BlockSums:
    """Per-block sums of an array of fixed shape, grown as new blocks appear."""

    def __init__(self, shape):
        self.shape = tuple(shape)
        self.sums = np.zeros((0,) + self.shape)
        self.weights = np.zeros((0,) + self.shape)

    def add(self, block, values, weight=1.0, index=Ellipsis):
        """Add ``values`` (and ``weight``) to block ``block`` (at ``index`` of the array, default all of it)."""
        block = int(block)
        if block >= len(self.sums):
            grow = block + 1 - len(self.sums)
            self.sums = np.concatenate([self.sums, np.zeros((grow,) + self.shape)])
            self.weights = np.concatenate([self.weights, np.zeros((grow,) + self.shape)])
        self.sums[block][index] += values
        self.weights[block][index] += weight

    def mean_and_error(self):
        return block_mean_and_error(self.sums, self.weights)
