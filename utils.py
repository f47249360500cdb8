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
