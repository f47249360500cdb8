"""Small helpers shared by every room: the user-error type, logging, timers.

This module sits on the lowest floor (see ARCHITECTURE.md): it imports
nothing from the package.
"""
import logging
import sys
import time


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
    """Run ``main``; turn a UserInputError into a message and exit status 2."""
    try:
        return main(*args, **kwargs)
    except UserInputError as err:
        print('error: %s' % err, file=sys.stderr)
        sys.exit(2)


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


# ------------------------------------------------------------------ readers of .clones series (ensembles)
# Self-contained (numpy, os, re only): the ensemble aggregation reads the
# snapshots a run wrote with these functions.

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


def clones_series_steps(output_name, structure_id):
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


def read_clones_series(output_name, structure_id):
    """All snapshots of one structure saved with ``save_clones one_file_per_step``.

    Returns (steps (F,) int, frames (F, n, 7) float), frames in step order;
    (empty, (0, 0, 7)) when there is none.  Raises ValueError when the body
    count changes between snapshots.
    """
    import numpy as np
    steps = clones_series_steps(output_name, structure_id)
    frames = [read_clones_frame('%s.%s.%s.clones' % (output_name, structure_id, str(step).zfill(8)))
              for step in steps]
    if not frames:
        return np.zeros(0, dtype=int), np.zeros((0, 0, 7))
    if len({frame.shape for frame in frames}) != 1:
        raise ValueError('%s.%s: the number of bodies changes between snapshots' % (output_name, structure_id))
    return np.array(steps, dtype=int), np.stack(frames)


def read_config_series(path):
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
