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
