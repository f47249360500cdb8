"""Small helpers shared by every room: the user-error type, logging, timers, trajectory readers.

This module sits on the lowest floor (see ARCHITECTURE.md): it imports
nothing from the package.
"""
import logging
import os
import sys
import time

import numpy as np


class UserInputError(ValueError):
    """A mistake in what the user gave us (option, file, line, value).

    The message names the file, the line or option, what was expected and
    how to fix it.  The scripts catch this type, print the message and exit
    with a non-zero status, without a traceback.
    """


class SimulationStopped(RuntimeError):
    """A run cannot go on (invalid configuration, NaN, solver failure).

    The scripts catch it after the files written so far are complete, print
    the message (which names the step and what to change) and exit with
    status 1.
    """


def fail_cleanly(main, *args, **kwargs):
    """Run ``main``; a UserInputError becomes its message and exit status 2, Ctrl-C one line and 130."""
    try:
        return main(*args, **kwargs)
    except UserInputError as err:
        print('error: %s' % err, file=sys.stderr)
        sys.exit(2)
    except KeyboardInterrupt:
        # Ctrl-C outside the time loop (which handles it itself): one line, no traceback.
        print('interrupted (SIGINT); files written so far are complete', file=sys.stderr)
        sys.exit(130)


def get_logger(name='rigid_multiblob'):
    """Package logger that writes plain lines to stdout once configured."""
    logger = logging.getLogger(name)
    if not logger.handlers:
        handler = logging.StreamHandler(sys.stdout)
        handler.setFormatter(logging.Formatter('%(message)s'))
        logger.addHandler(handler)
        logger.setLevel(logging.INFO)
        logger.propagate = False
    return logger


class Timer:
    """Wall-clock timer usable as a context manager: ``with Timer() as t: ...; t.elapsed``."""

    def __enter__(self):
        self.start = time.perf_counter()
        self.elapsed = None
        return self

    def __exit__(self, *exc):
        self.elapsed = time.perf_counter() - self.start
        return False


# ------------------------------------------------------------------ readers of saved trajectories
# Snapshots of the dynamic and Monte Carlo scripts (SPEC sections 2.1 and 9):
# ``save_clones one_file_per_step`` writes ``output_name.ID.<step, 8 digits>.clones``
# per structure and saved step; ``save_clones one_file`` writes one
# ``output_name.ID.config`` per structure, the snapshots one after the other,
# each starting with its count line.  Lines are ``x y z s p1 p2 p3``; ``#``
# starts a comment.  Quaternions are normalised when read, as the structure
# readers of the package do.

def _snapshot_rows(text_lines, path):
    """Numbers of the non-empty lines of a snapshot file: list of (line number, list of float)."""
    rows = []
    for number, raw in enumerate(text_lines, start=1):
        tokens = raw.split('#', 1)[0].split()
        if not tokens:
            continue
        try:
            rows.append((number, [float(t) for t in tokens]))
        except ValueError:
            raise UserInputError("%s, line %d: cannot read '%s' as numbers" % (path, number, raw.strip()))
    return rows


def _normalised_configuration(table, path):
    """Split rows (Nb, 7) into locations (Nb, 3) and unit quaternions (Nb, 4)."""
    table = np.asarray(table, dtype=float).reshape(-1, 7)
    norms = np.linalg.norm(table[:, 3:], axis=1)
    if np.any(norms == 0.0):
        raise UserInputError('%s: body %d has a zero quaternion' % (path, int(np.argmax(norms == 0.0))))
    return table[:, :3].copy(), table[:, 3:] / norms[:, None]


def read_clones_snapshot(path):
    """One ``.clones`` file: locations (Nb, 3) and normalised quaternions (Nb, 4)."""
    if not os.path.isfile(path):
        raise UserInputError("snapshot file '%s' not found" % path)
    with open(path, 'r') as f:
        rows = _snapshot_rows(f, path)
    if not rows:
        raise UserInputError("%s is empty: a .clones file starts with the number of bodies" % path)
    count = int(rows[0][1][0])
    body_rows = rows[1:1 + count]
    if len(body_rows) < count or any(len(values) < 7 for _, values in body_rows):
        raise UserInputError('%s: announces %d bodies of 7 numbers (x y z s p1 p2 p3) but the file holds fewer; '
                             'the snapshot is incomplete' % (path, count))
    return _normalised_configuration([values[:7] for _, values in body_rows], path)


def clones_series_steps(output_name, structure_id):
    """Saved steps of one structure (sorted ints) and their files: ``output_name.ID.<step>.clones``."""
    import glob
    import re
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
            raise UserInputError('no snapshot %s.%s.%s.clones; saved steps are %s'
                                 % (output_name, structure_id, str(missing[0]).zfill(8), describe_steps(saved)))
        saved, paths = list(steps), [by_step[s] for s in steps]
    if not saved:
        raise UserInputError('no snapshot %s.%s.<step>.clones found (save_clones one_file_per_step); check '
                             'output_name and that the run has saved a step' % (output_name, structure_id))
    configurations = [read_clones_snapshot(path) for path in paths]
    counts = {c[0].shape[0] for c in configurations}
    if len(counts) != 1:
        raise UserInputError('%s.%s.*.clones: the snapshots hold different numbers of bodies %s'
                             % (output_name, structure_id, sorted(counts)))
    return (np.array(saved, dtype=int), np.stack([c[0] for c in configurations]),
            np.stack([c[1] for c in configurations]))


def read_config_series(path):
    """Trajectory of one structure saved with ``save_clones one_file`` (``output_name.ID.config``).

    The snapshots follow each other, each a count line and one line per body.
    An incomplete last snapshot (a run stopped while writing) is left out.

    Returns
    -------
    locations : ndarray, shape (S, Nb, 3)
    orientations : ndarray, shape (S, Nb, 4), unit scalar-first quaternions.
    """
    if not os.path.isfile(path):
        raise UserInputError("snapshot file '%s' not found (save_clones one_file)" % path)
    with open(path, 'r') as f:
        rows = _snapshot_rows(f, path)
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
        blocks.append([v[:7] for _, v in body_rows])
        index += 1 + count
    if not blocks:
        raise UserInputError('%s holds no complete snapshot' % path)
    if len({len(b) for b in blocks}) != 1:
        raise UserInputError('%s: the snapshots hold different numbers of bodies' % path)
    configurations = [_normalised_configuration(b, path) for b in blocks]
    return np.stack([c[0] for c in configurations]), np.stack([c[1] for c in configurations])


def describe_steps(steps):
    """Short text of a sorted list of steps: '0, 1, ..., 10' style."""
    steps = list(steps)
    if len(steps) <= 6:
        return ', '.join(str(s) for s in steps) or 'none'
    return '%d, %d, ..., %d (%d steps)' % (steps[0], steps[1], steps[-1], len(steps))


# ------------------------------------------------------------------ raw (n, 7) frames (ensemble statistics)
def read_clones_frame(path):
    """One ``.clones`` snapshot: array (n, 7) of ``x y z s p1 p2 p3`` per body.

    The first line that is not blank or a ``#`` comment holds the number of
    bodies n; the next n such lines hold the bodies.  Raises ValueError when
    the file has fewer rows than its count line says.
    """
    import numpy as np
    with open(path) as f:
        rows = [line.split('#', 1)[0].split() for line in f]
    rows = [row for row in rows if row]
    if not rows:
        raise ValueError('%s: empty clones file' % path)
    count = int(rows[0][0])
    if len(rows) - 1 < count:
        raise ValueError('%s: the count line says %d bodies but %d rows follow' % (path, count, len(rows) - 1))
    return np.array(rows[1:count + 1], dtype=float).reshape(count, 7)


def clones_frame_steps(output_name, structure_id):
    """Sorted saved steps of the ``one_file_per_step`` series ``output_name.<ID>.<step>.clones``."""
    import os
    import re
    folder, base = os.path.split(output_name)
    pattern = re.compile(re.escape('%s.%s.' % (base, structure_id)) + r'(\d{8,})\.clones$')
    try:
        names = os.listdir(folder or os.curdir)
    except FileNotFoundError:
        return []
    return sorted(int(match.group(1)) for match in map(pattern.match, names) if match)


def read_clones_frames(output_name, structure_id):
    """All snapshots of one structure saved with ``save_clones one_file_per_step``.

    Returns (steps (F,) int, frames (F, n, 7) float), frames in step order;
    (empty, (0, 0, 7)) when there is none.  Raises ValueError when the body
    count changes between snapshots.
    """
    import numpy as np
    steps = clones_frame_steps(output_name, structure_id)
    frames = [read_clones_frame('%s.%s.%s.clones' % (output_name, structure_id, str(step).zfill(8)))
              for step in steps]
    if not frames:
        return np.zeros(0, dtype=int), np.zeros((0, 0, 7))
    if len({frame.shape for frame in frames}) != 1:
        raise ValueError('%s.%s: the number of bodies changes between snapshots' % (output_name, structure_id))
    return np.array(steps, dtype=int), np.stack(frames)


def read_config_frames(path):
    """All snapshots of a ``save_clones one_file`` series (``output_name.<ID>.config``): (F, n, 7).

    The file is snapshots one after another, each a count line followed by
    that many body lines.  A snapshot cut short at the end of the file (a run
    killed while writing) is dropped.
    """
    import numpy as np
    with open(path) as f:
        lines = [line.split() for line in f]
    frames, index = [], 0
    while index < len(lines):
        if not lines[index]:
            index += 1
            continue
        count = int(lines[index][0])
        block = lines[index + 1:index + 1 + count]
        if len(block) < count or any(len(row) != 7 for row in block):
            break
        frames.append(np.array(block, dtype=float).reshape(count, 7))
        index += 1 + count
    if not frames:
        return np.zeros((0, 0, 7))
    return np.stack(frames)


# ------------------------------------------------------------------ single-body trajectory files (boomerang, sphere)
# ------------------------------------------------------------ trajectory readers
def read_trajectory_file(path):
    """Read a single-body trajectory file written by ``boomerang/boomerang.py`` (or the published code).

    Format: a ``Parameters:`` line, ``key: value`` lines (a line without a
    colon continues the previous value), ``Trajectory data:``,
    ``Location, Orientation:``, then one line ``x, y, z, s, p1, p2, p3`` per
    configuration.

    Returns
    -------
    parameters : dict of str -> str
    locations : ndarray, shape (n, 3)
    orientations : ndarray, shape (n, 4), scalar-first quaternions.

    Raises ``UserInputError`` naming the file and line when the file does not
    have this layout.
    """
    import numpy as np
    parameters = {}
    rows = []
    section = None
    last_key = None
    try:
        f = open(path)
    except OSError as err:
        raise UserInputError('cannot read trajectory file %s (%s)' % (path, err.strerror))
    with f:
        for number, raw in enumerate(f, start=1):
            line = raw.strip()
            if not line:
                continue
            if line == 'Parameters:':
                section = 'parameters'
            elif line == 'Trajectory data:':
                section = 'header'
            elif section == 'header' and line.startswith('Location'):
                section = 'data'
            elif section == 'parameters':
                if ':' in line:
                    last_key, value = line.split(':', 1)
                    last_key = last_key.strip()
                    parameters[last_key] = value.strip()
                elif last_key is not None:
                    parameters[last_key] += ' ' + line
            elif section == 'data':
                try:
                    values = [float(v) for v in line.split(',') if v.strip()]
                except ValueError:
                    values = []
                if len(values) != 7:
                    raise UserInputError('%s, line %d: expected 7 comma-separated numbers '
                                         '"x, y, z, s, p1, p2, p3", got %r' % (path, number, line))
                rows.append(values)
            else:
                raise UserInputError('%s, line %d: not a trajectory file (expected "Parameters:", '
                                     '"Trajectory data:" and "Location, Orientation:" before the data)'
                                     % (path, number))
    if section != 'data':
        raise UserInputError('%s: no "Location, Orientation:" line, so no trajectory data' % path)
    data = np.array(rows, dtype=float).reshape(-1, 7)
    return parameters, data[:, :3], data[:, 3:]


def trajectory_parameter(parameters, key, path='the trajectory file'):
    """Float value of ``key`` in the parameters of ``read_trajectory_file``; UserInputError when missing."""
    if key not in parameters:
        raise UserInputError('%s has no parameter %r (found: %s)' % (path, key, ', '.join(sorted(parameters))))
    try:
        return float(parameters[key])
    except ValueError:
        raise UserInputError('%s: parameter %s = %r is not a number' % (path, key, parameters[key]))


def warn_user(message, stream=None):
    """Print one ``warning: <message>`` line on standard error (or ``stream``).

    For input that is accepted but probably not what the user meant (an
    option the scheme ignores, extra fields on a line): the run goes on, the
    user is told once, with the file, line or option to change.
    """
    print('warning: %s' % message, file=sys.stderr if stream is None else stream, flush=True)


def read_text_file(path, what, hint):
    """Text of the UTF-8 file ``path`` (a byte-order mark is allowed), or UserInputError.

    ``what`` names the file in messages ("input file", "vertex file", ...);
    ``hint`` says how to give another one.  A folder, a missing file, an
    unreadable file and bytes that are not UTF-8 each get their own message.
    """
    if os.path.isdir(path):
        raise UserInputError("%s '%s' is a folder, not a file; %s" % (what, path, hint))
    if not os.path.isfile(path):
        raise UserInputError("%s '%s' not found; %s" % (what, path, hint))
    try:
        with open(path, 'rb') as f:
            data = f.read()
    except OSError as err:
        raise UserInputError("%s '%s' cannot be read (%s); %s" % (what, path, err.strerror or err, hint))
    try:
        return data.decode('utf-8-sig')
    except UnicodeDecodeError as err:
        line = data.count(b'\n', 0, err.start) + 1
        raise UserInputError("%s '%s', line %d: byte 0x%02x is not UTF-8 text; save the file as plain UTF-8 "
                             "(or ASCII) text" % (what, path, line, data[err.start]))


def prepare_script_path(script_file):
    """Make the package importable from a script run by path (``python multi_bodies.py ...``).

    The one path prelude of every script.  Each script first puts the
    repository root on ``sys.path`` (two lines: it cannot import this module
    before that), then calls this function, which takes the script's own
    folder off the path (``multi_bodies.py``, ``boomerang.py`` and
    ``sphere.py`` share their package's name, and would otherwise shadow it)
    and forgets a module that such a script left under the package's name.
    """
    import os
    import sys
    folder = os.path.dirname(os.path.abspath(script_file))
    sys.path[:] = [p for p in sys.path if os.path.abspath(p or os.curdir) != folder]
    package = os.path.basename(folder)
    module = sys.modules.get(package)
    if module is not None and not hasattr(module, '__path__'):
        del sys.modules[package]
