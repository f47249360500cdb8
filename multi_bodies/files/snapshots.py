"""Every read and write of a body configuration: ``.clones`` snapshots and ``.config`` series (floor 3).

Formats (the manual's sections 1.3 and 5.1):

* ``.clones``: the number of bodies ``Nb``, then one line ``x y z s p1 p2 p3``
  per body (location, scalar-first quaternion).  ``#`` starts a comment and
  blank lines are skipped.  Written with round-trip precision (``repr``),
  so a snapshot read back gives the same doubles.
* ``output_name.ID.<step, 8 digits>.clones``: one snapshot per structure and
  saved step (``save_clones one_file_per_step``).
* ``output_name.ID.config``: the snapshots of one structure one after the
  other, each a count line and its body lines (``save_clones one_file``).
  A snapshot cut short at the end (a run killed while writing) is dropped.

Readers that return locations and orientations renormalise the quaternions
(``normalise_quaternions``), as the published readers do; the ``*_frame*``
readers return the raw numbers, shape (n, 7), for statistics.

Only this module opens these files; ``run_output`` (restart records,
``.info``) and the scripts call it.
"""
import glob
import os
import re

import numpy as np

from utils import UserInputError, describe_steps
from multi_bodies.files.structure_files import _read_counted_table


# ------------------------------------------------------------------ names
def clones_name(output_name, structure_id, step):
    """Name of a saved snapshot: ``output_name.ID.<step, 8 digits>.clones``."""
    return '%s.%s.%s.clones' % (output_name, structure_id, str(step).zfill(8))


def config_name(output_name, structure_id):
    """Name of the ``save_clones one_file`` series of one structure: ``output_name.ID.config``."""
    return '%s.%s.config' % (output_name, structure_id)


# ------------------------------------------------------------------ quaternions
def normalise_quaternions(quaternions, path):
    """Unit quaternions (Nb, 4) from the rows read in ``path``; a zero row is a UserInputError.

    Rows so small that their squares would underflow are rescaled first;
    every other row is divided by its norm, as the published readers do.
    """
    quaternions = np.array(quaternions, dtype=float).reshape(-1, 4)
    scale = np.max(np.abs(quaternions), axis=1) if len(quaternions) else np.zeros(0)
    if np.any(scale == 0.0):
        raise UserInputError("%s: body %d has a zero quaternion; give a unit quaternion s p1 p2 p3"
                             % (path, int(np.argmax(scale == 0.0))))
    tiny = scale < 1e-100
    quaternions[tiny] /= scale[tiny, None]
    return quaternions / np.linalg.norm(quaternions, axis=1)[:, None]


# ------------------------------------------------------------------ writing
def format_clones(locations, orientations, comment=None):
    """Text of one snapshot: ``# comment`` lines, the count line, ``x y z s p1 p2 p3`` per body (repr).

    locations: (Nb, 3); orientations: (Nb, 4) scalar-first quaternions.
    """
    rows = np.concatenate((np.asarray(locations, dtype=float).reshape(-1, 3),
                           np.asarray(orientations, dtype=float).reshape(-1, 4)), axis=1)
    lines = ['# %s' % line for line in comment.splitlines()] if comment else []
    lines.append('%d' % rows.shape[0])
    lines.extend(' '.join(repr(float(v)) for v in row) for row in rows)
    return '\n'.join(lines) + '\n'


def write_clones_file(path, locations, orientations, comment=None):
    """Write locations (Nb, 3) and quaternions (Nb, 4) as a ``.clones`` file (round-trip precision).

    The text goes to ``path + '.part'`` first and then replaces ``path``, so a
    stop never leaves a truncated snapshot.  ``comment``: text written first,
    each line behind ``# ``.
    """
    path = os.fspath(path)
    part = path + '.part'
    try:
        with open(part, 'w') as f:
            f.write(format_clones(locations, orientations, comment))
        os.replace(part, path)
    except BaseException as err:  # a full disk or a file-size limit: no empty or half-written .part is left
        try:
            os.remove(part)
        except OSError:
            pass
        if isinstance(err, OSError) and err.filename is None:  # a write on a full disk names no file
            err.filename = path
        raise


def append_config_snapshot(path, locations, orientations, new_file=False):
    """Append one snapshot to the ``.config`` series ``path`` (``new_file``: start the file afresh).

    Returns the byte offset where the snapshot starts (kept in the restart
    record, so a restart can find it and cut the series there).
    """
    with open(path, 'w' if new_file else 'a') as f:
        offset = 0 if new_file else f.tell()
        f.write(format_clones(locations, orientations))
        f.flush()
    return offset


def truncate_config(path, offset):
    """Cut the ``.config`` series ``path`` where the snapshot at byte ``offset`` starts (if it is longer)."""
    if os.path.isfile(path) and os.path.getsize(path) > offset:
        os.truncate(path, offset)


# ------------------------------------------------------------------ reading one snapshot
def read_clones_file(path, referenced_from=None):
    """A ``.clones`` file: body locations (Nb, 3) and normalised quaternions (Nb, 4).

    Raises UserInputError naming the file and line (missing file, count line,
    too few or non-numeric rows, nan/inf, zero quaternion); extra values on a
    line are ignored with a warning.
    """
    table = _read_counted_table(os.fspath(path), 'clones', 7, 'body location and quaternion x y z s p1 p2 p3',
                                referenced_from, exact_count=False)
    return table[:, :3].copy(), normalise_quaternions(table[:, 3:], path)


SHORTEST_BODY_LINE = 14  # '0 0 0 1 0 0 0' and its end of line: a body line is never shorter


def read_config_snapshot(path, offset):
    """The snapshot starting at byte ``offset`` of a ``.config``: locations (n, 3), unit quaternions (n, 4).

    Raises UserInputError naming the file and byte when there is no complete snapshot there (a count line
    announcing more bodies than the rest of the file can hold is refused before anything is read), and when a
    number is NaN or infinite."""
    with open(path, 'rb') as f:
        size = os.fstat(f.fileno()).st_size
        try:
            if not 0 <= int(offset) < size:  # (a forged record's 2**70 cannot even be seeked to)
                raise ValueError('byte %d is not inside the file' % offset)
            f.seek(int(offset))
            count = int(f.readline().split()[0])
            if count < 0 or count * SHORTEST_BODY_LINE > size - offset:
                raise ValueError('the count line announces more bodies than the file holds')
            rows = [f.readline().split() for _ in range(count)]
            data = np.array(rows, dtype=float).reshape(count, 7)
        except (ValueError, IndexError):
            raise UserInputError('%s: no complete snapshot at byte %d (the file was changed after the run?); '
                                 'restart from another saved step' % (path, offset))
    if not np.all(np.isfinite(data)):
        raise UserInputError('%s: the snapshot at byte %d holds a NaN or infinite number (body %d); the file was '
                             'changed after the run, or the run wrote it while it failed'
                             % (path, offset, int(np.argmin(np.all(np.isfinite(data), axis=1)))))
    return data[:, :3].copy(), normalise_quaternions(data[:, 3:], path)


# ------------------------------------------------------------------ series
def _numeric_rows(path):
    """(line number, list of float) of the lines of ``path`` that hold numbers (comments removed)."""
    rows = []
    with open(path, 'rb') as f:  # bytes: a byte that is not UTF-8 is a word that is not a number, not a traceback
        for number, raw in enumerate(f, start=1):
            tokens = raw.split(b'#', 1)[0].split()
            if not tokens:
                continue
            try:
                rows.append((number, [float(t) for t in tokens]))
            except ValueError:
                raise UserInputError("%s, line %d: cannot read '%s' as numbers"
                                     % (path, number, raw.strip().decode('utf-8', 'replace')))
    return rows


def _config_blocks(path):
    """The complete snapshots of a ``.config`` file: list of (n, 7) arrays (a cut last one is dropped)."""
    rows = _numeric_rows(path)
    blocks, index = [], 0
    while index < len(rows):
        number, values = rows[index]
        if len(values) != 1 or values[0] != int(values[0]) or values[0] < 1:
            raise UserInputError('%s, line %d: expected the count line of a snapshot (one positive integer)'
                                 % (path, number))
        count = int(values[0])
        body_rows = rows[index + 1:index + 1 + count]
        if len(body_rows) < count or any(len(v) < 7 for _, v in body_rows):
            break  # incomplete last snapshot
        blocks.append(np.array([v[:7] for _, v in body_rows], dtype=float).reshape(count, 7))
        index += 1 + count
    return blocks


def clones_series_steps(output_name, structure_id):
    """Saved steps (sorted ints) of ``output_name.ID.<step>.clones`` and their paths."""
    prefix = '%s.%s.' % (output_name, structure_id)
    pattern = re.compile(r'^(\d{8,})\.clones$')
    found = {}
    for path in glob.glob(glob.escape(prefix) + '*.clones'):
        match = pattern.match(path[len(prefix):])
        if match:
            found[int(match.group(1))] = path
    steps = sorted(found)
    return steps, [found[s] for s in steps]


def read_clones_series(output_name, structure_id, steps=None):
    """Trajectory of one structure saved with ``save_clones one_file_per_step``.

    Parameters
    ----------
    output_name : str, the run's ``output_name`` (relative to the working directory).
    structure_id : str, the structure ID (clones file name without ``.clones``).
    steps : list of int or None, the steps to read (default: every saved step).

    Returns
    -------
    steps : ndarray of int, shape (S,)
    locations : ndarray, shape (S, Nb, 3)
    orientations : ndarray, shape (S, Nb, 4), unit scalar-first quaternions.
    """
    saved, paths = clones_series_steps(output_name, structure_id)
    if steps is not None:
        by_step = dict(zip(saved, paths))
        missing = [s for s in steps if s not in by_step]
        if missing:
            raise UserInputError('no snapshot %s; saved steps are %s'
                                 % (clones_name(output_name, structure_id, missing[0]), describe_steps(saved)))
        saved, paths = list(steps), [by_step[s] for s in steps]
    if not saved:
        raise UserInputError('no snapshot %s.%s.<step>.clones found (save_clones one_file_per_step); check '
                             'output_name and that the run has saved a step' % (output_name, structure_id))
    configurations = [read_clones_file(path) for path in paths]
    counts = {c[0].shape[0] for c in configurations}
    if len(counts) != 1:
        raise UserInputError('%s.%s.*.clones: the snapshots hold different numbers of bodies %s'
                             % (output_name, structure_id, sorted(counts)))
    return (np.array(saved, dtype=int), np.stack([c[0] for c in configurations]),
            np.stack([c[1] for c in configurations]))


def read_config_series(path):
    """Trajectory of one structure saved with ``save_clones one_file`` (``output_name.ID.config``).

    Returns locations (S, Nb, 3) and unit quaternions (S, Nb, 4); an
    incomplete last snapshot is left out.
    """
    if not os.path.isfile(path):
        raise UserInputError("snapshot file '%s' not found (save_clones one_file)" % path)
    blocks = _config_blocks(path)
    if not blocks:
        raise UserInputError('%s holds no complete snapshot' % path)
    if len({len(b) for b in blocks}) != 1:
        raise UserInputError('%s: the snapshots hold different numbers of bodies' % path)
    _finite_frames(np.concatenate(blocks), path)
    return (np.stack([b[:, :3] for b in blocks]),
            np.stack([normalise_quaternions(b[:, 3:], path) for b in blocks]))


# ------------------------------------------------------------------ raw (n, 7) frames (ensemble statistics)
def _finite_frames(frames, path):
    """``frames`` (..., 7) when every number is finite; else UserInputError naming ``path``."""
    if not np.all(np.isfinite(frames)):
        raise UserInputError('%s holds a NaN or infinite number; the file was changed after the run, or the run '
                             'wrote it while it failed' % path)
    return frames


def read_clones_frame(path):
    """One ``.clones`` snapshot as written: array (n, 7) of ``x y z s p1 p2 p3`` (not renormalised).

    Raises UserInputError (a ValueError) naming the file when it is empty, has fewer rows than its count line
    says, rows of another length, words that are not numbers, or NaN and infinite numbers.
    """
    with open(path, 'rb') as f:
        rows = [line.split(b'#', 1)[0].split() for line in f]
    rows = [row for row in rows if row]
    if not rows:
        raise UserInputError('%s: empty clones file' % path)
    try:
        count = int(rows[0][0])
        if count < 0 or len(rows) - 1 < count:
            raise UserInputError('%s: the count line says %d bodies but %d rows follow' % (path, count, len(rows) - 1))
        frame = np.array(rows[1:count + 1], dtype=float).reshape(count, 7)
    except (ValueError, TypeError) as err:
        if isinstance(err, UserInputError):
            raise
        raise UserInputError('%s: not a snapshot of x y z s p1 p2 p3 rows after a count line (%s)' % (path, err))
    return _finite_frames(frame, path)


def clones_frame_steps(output_name, structure_id):
    """Sorted saved steps of the ``one_file_per_step`` series ``output_name.<ID>.<step>.clones``."""
    folder, base = os.path.split(output_name)
    pattern = re.compile(re.escape('%s.%s.' % (base, structure_id)) + r'(\d{8,})\.clones$')
    try:
        names = os.listdir(folder or os.curdir)
    except FileNotFoundError:
        return []
    return sorted(int(match.group(1)) for match in map(pattern.match, names) if match)


def read_clones_frames(output_name, structure_id):
    """All snapshots of one structure saved with ``save_clones one_file_per_step``, as written.

    Returns (steps (F,) int, frames (F, n, 7) float) in step order;
    (empty, (0, 0, 7)) when there is none.  Raises ValueError when the body
    count changes between snapshots.
    """
    steps = clones_frame_steps(output_name, structure_id)
    frames = [read_clones_frame(clones_name(output_name, structure_id, step)) for step in steps]
    if not frames:
        return np.zeros(0, dtype=int), np.zeros((0, 0, 7))
    if len({frame.shape for frame in frames}) != 1:
        raise UserInputError('%s.%s: the number of bodies changes between snapshots' % (output_name, structure_id))
    return np.array(steps, dtype=int), np.stack(frames)


def read_config_frames(path):
    """All complete snapshots of a ``save_clones one_file`` series as written: (F, n, 7) (not renormalised).

    Raises UserInputError naming the file when the snapshots hold different numbers of bodies or a NaN or
    infinite number."""
    frames = _config_blocks(path)
    if not frames:
        return np.zeros((0, 0, 7))
    if len({len(frame) for frame in frames}) != 1:
        raise UserInputError('%s: the snapshots hold different numbers of bodies' % path)
    return _finite_frames(np.stack(frames), path)
