"""Small helpers shared by every room: the user-error type, logging, timers.

This module sits on the lowest floor (see ARCHITECTURE.md): it imports
nothing from the package.
"""
import logging
import os
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
