"""Small helpers shared by every room: the user-error type, logging, timers, trajectory readers.

This module sits on the lowest floor (see ARCHITECTURE.md): it imports
nothing from the package.
"""
import logging
import os
import sys
import time


# A word of a message longer than this (a 100 MB token of a file, echoed by "cannot read '...'") is shown by its
# first and last characters and its length: the message stays one readable line, whatever the file held.
MESSAGE_WORD_CHARACTERS = 400


def shorten_words(text, longest=MESSAGE_WORD_CHARACTERS):
    """``text`` with every run of more than ``longest`` non-blank characters cut to its ends and its length."""
    import re
    if len(text) <= longest:
        return text
    return re.sub(r'\S{%d,}' % (longest + 1),
                  lambda m: '%s...[%d characters]...%s' % (m.group()[:longest // 2], len(m.group()),
                                                          m.group()[-longest // 4:]), text)


class UserInputError(ValueError):
    """A mistake in what the user gave us (option, file, line, value).

    The message names the file, the line or option, what was expected and
    how to fix it.  The scripts catch this type, print the message and exit
    with a non-zero status, without a traceback.  A word of the message
    longer than ``MESSAGE_WORD_CHARACTERS`` (a huge token echoed from a file)
    is shortened to its ends and its length (:func:`shorten_words`).
    """

    def __init__(self, message='', *args):
        super().__init__(shorten_words(message) if isinstance(message, str) else message, *args)


class SimulationStopped(RuntimeError):
    """A run cannot go on (invalid configuration, NaN, solver failure).

    The scripts catch it after the files written so far are complete, print
    the message (which names the step and what to change) and exit with
    status 1.  ``state``: the run state reached when a scheme's step stopped
    (its counts included; set by ``Scheme.step``), else None.
    """
    state = None


def _interrupted_while_starting(signal_number, frame):
    print('interrupted (SIGINT) while starting; nothing was written', file=sys.stderr, flush=True)
    os._exit(130)


def fail_cleanly(main, *args, **kwargs):
    """Run ``main``; a UserInputError becomes its message and exit status 2, Ctrl-C one line and 130."""
    import signal
    if signal.getsignal(signal.SIGINT) is _interrupted_while_starting:
        signal.signal(signal.SIGINT, signal.default_int_handler)
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


# The readers and writers of ``.clones`` snapshots and ``.config`` series live in
# multi_bodies/files/snapshots.py (floor 3); this floor only keeps generic helpers.

def describe_steps(steps):
    """Short text of a sorted list of steps: '0, 1, ..., 10' style."""
    steps = list(steps)
    if len(steps) <= 6:
        return ', '.join(str(s) for s in steps) or 'none'
    return '%d, %d, ..., %d (%d steps)' % (steps[0], steps[1], steps[-1], len(steps))


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


# ------------------------------------------------------------------ memory an input or option asks for
def format_bytes(n):
    """'1.5 GiB' style text of a byte count."""
    n = float(n)
    for unit in ('B', 'KiB', 'MiB', 'GiB', 'TiB', 'PiB'):
        if n < 1024 or unit == 'PiB':
            return ('%d %s' % (n, unit)) if unit == 'B' else ('%.3g %s' % (n, unit))
        n /= 1024.0


def available_memory():
    """Bytes of memory this process can still get (MemAvailable of /proc/meminfo, else the physical memory);
    None when unknown."""
    try:
        with open('/proc/meminfo') as f:
            for line in f:
                if line.startswith('MemAvailable:'):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf('SC_PHYS_PAGES') * os.sysconf('SC_PAGE_SIZE')
    except (ValueError, OSError, AttributeError):
        return None


def refuse_if_too_big(need, what, where, fix, have=None):
    """Raise UserInputError before anything is allocated or written when ``need`` bytes exceed the memory
    available (``have``, default :func:`available_memory`); ``what`` says what needs it, ``where`` names the
    option (file and line) or file, ``fix`` how to ask for less."""
    have = available_memory() if have is None else have
    if have is not None and need > have:
        raise UserInputError('%s: %s needs about %s of memory, but %s are available; %s'
                             % (where, what, format_bytes(need), format_bytes(have), fix))


NPY_HEADER_BYTES = 65536  # numpy's own limit of a .npy header it reads without allow_pickle (max_header_size)
# Numbers a program wrote compress a few times at most; a member that inflates more than ZIP_BOMB_RATIO times, to
# more than ZIP_BOMB_BYTES, is a zip bomb (refused before it is inflated).
ZIP_BOMB_RATIO, ZIP_BOMB_BYTES = 1000, 1 << 26


def read_npz(path, names, what):
    """The arrays ``names`` of the ``.npz`` file ``path`` (dict name -> array), each read only after what the file
    declares was checked: a member ``<name>.npy`` of a zip archive, a numeric dtype (no object arrays: nothing is
    unpickled), a declared shape whose bytes are exactly the member's declared size, all of them within the memory
    available (``refuse_if_too_big``), no member inflating ``ZIP_BOMB_RATIO`` times beyond ``ZIP_BOMB_BYTES``;
    then exactly that many bytes are inflated, so an archive that declares a small member and inflates to
    gigabytes, or a header declaring 10^12 values, costs no more than the header.

    ``what`` names the kind of file in the refusals (UserInputError naming ``path``).
    """
    import io
    import zipfile
    import numpy as np

    def refuse(text):
        return UserInputError('%s is not %s (%s); nothing in it was used' % (path, what, text))
    kind = special_file_kind(path)
    if kind is not None:
        raise refuse('it is %s' % kind)
    try:
        archive = zipfile.ZipFile(path)
    except FileNotFoundError:
        raise UserInputError('%s: no such file; give %s' % (path, what))
    except (OSError, zipfile.BadZipFile, ValueError, EOFError) as err:
        raise refuse('not a .npz archive: %s' % err)
    found, total = {}, 0
    with archive:
        for name in names:
            try:
                info = archive.getinfo(name + '.npy')
                with archive.open(info) as member:
                    head = io.BytesIO(member.read(NPY_HEADER_BYTES))
                version = np.lib.format.read_magic(head)
                readers = {(1, 0): np.lib.format.read_array_header_1_0, (2, 0): np.lib.format.read_array_header_2_0}
                if version not in readers:
                    raise ValueError('.npy version %s' % (version,))
                shape, fortran, dtype = readers[version](head, max_header_size=NPY_HEADER_BYTES)
            except KeyError:
                raise refuse('it holds no array %r' % name)
            except (ValueError, OSError, zipfile.BadZipFile, EOFError, NotImplementedError, SyntaxError,
                    TypeError) as err:
                raise refuse('the header of %r cannot be read: %s' % (name, err))
            if dtype.hasobject or dtype.fields is not None or dtype.kind not in 'biuf':
                raise refuse('%r holds %s values, not numbers' % (name, dtype))
            count = 1
            for n in shape:
                count *= int(n)
            need = count * dtype.itemsize
            if info.file_size > ZIP_BOMB_BYTES and info.file_size > ZIP_BOMB_RATIO * max(info.compress_size, 1):
                raise refuse('%r inflates from %d to %d bytes, more than %d times: a zip bomb, not data'
                             % (name, info.compress_size, info.file_size, ZIP_BOMB_RATIO))
            if info.file_size != head.tell() + need:
                raise refuse('%r declares %d values of shape %s (%d bytes), but its member holds %d bytes'
                             % (name, count, tuple(shape), need, info.file_size - head.tell()))
            total += need
            found[name] = (info, head.tell(), shape, fortran, dtype, need)
        refuse_if_too_big(total, 'reading %s' % ', '.join(names), path, 'give %s' % what)
        arrays = {}
        for name, (info, start, shape, fortran, dtype, need) in found.items():
            try:
                with archive.open(info) as member:
                    member.read(start)
                    data = member.read(need)
            except (OSError, zipfile.BadZipFile, EOFError, ValueError) as err:
                raise refuse('%r cannot be read: %s' % (name, err))
            if len(data) != need:
                raise refuse('%r is cut short' % name)
            arrays[name] = np.frombuffer(data, dtype=dtype).reshape(shape, order='F' if fortran else 'C').copy()
    return arrays


def special_file_kind(path):
    """What is at ``path`` when it is there but is not a regular file (links followed): 'a folder', 'a FIFO',
    'a socket', 'a character device', 'a block device', 'a symbolic link to a missing file'; None for a regular
    file or when nothing is there."""
    import stat
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        return 'a symbolic link to a missing file' if os.path.islink(path) else None
    except (OSError, ValueError):  # ValueError: a NUL byte, which no path holds (the caller says it is missing)
        return None
    for test, kind in ((stat.S_ISREG, None), (stat.S_ISDIR, 'a folder'), (stat.S_ISFIFO, 'a FIFO'),
                       (stat.S_ISSOCK, 'a socket'), (stat.S_ISCHR, 'a character device'),
                       (stat.S_ISBLK, 'a block device')):
        if test(mode):
            return kind
    return 'not a regular file'


def read_text_file(path, what, hint):
    """Text of the UTF-8 file ``path`` (a byte-order mark is allowed), or UserInputError.

    ``what`` names the file in messages ("input file", "vertex file", ...);
    ``hint`` says how to give another one.  A folder, a FIFO or device (never read: it could block for ever), a
    dangling link, a missing file, an unreadable file and bytes that are not UTF-8 each get their own message.
    """
    if '\x00' in str(path):
        raise UserInputError("%s %r holds a NUL byte, which no file name can hold; %s" % (what, str(path), hint))
    kind = special_file_kind(path)
    if kind is not None:
        raise UserInputError("%s '%s' is %s, not a file; %s" % (what, path, kind, hint))
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
    import signal
    import sys
    main_file = getattr(sys.modules.get('__main__'), '__file__', None)
    if main_file and os.path.abspath(main_file) == os.path.abspath(script_file) \
            and signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        # Ctrl-C while the script still imports (numpy, scipy, the backends): one line, no traceback;
        # fail_cleanly puts Python's own handler back when main starts.
        signal.signal(signal.SIGINT, _interrupted_while_starting)
        if hasattr(signal, 'pthread_sigmask'):  # a Ctrl-C held back until the handler exists is answered now
            signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    folder = os.path.dirname(os.path.abspath(script_file))
    sys.path[:] = [p for p in sys.path if os.path.abspath(p or os.curdir) != folder]
    package = os.path.basename(folder)
    module = sys.modules.get(package)
    if module is not None and not hasattr(module, '__path__'):
        del sys.modules[package]


def terminal_progress_bar(stream, total, unit, **options):
    """A tqdm bar of ``total`` ``unit``s on ``stream`` when it is a terminal and tqdm is installed, else None
    (progress then goes to ``stream`` as plain lines: :func:`write_progress_line`)."""
    if not getattr(stream, 'isatty', lambda: False)():
        return None
    try:
        from tqdm import tqdm
    except ImportError:
        return None
    return tqdm(total=total, unit=unit, file=stream, dynamic_ncols=True, **options)


def write_progress_line(bar, stream, text):
    """One line of progress: through the bar (kept below the line) when there is one, else printed."""
    if bar is not None:
        bar.write(text, file=stream)
    else:
        print(text, file=stream, flush=True)
