"""One writer per output: an exclusive lock file beside the outputs (floor 6).

A run holds ``output_name.lock`` from before it reads its restart record or
touches, sets aside or writes any file until it ends; the ensemble runner
holds ``ensemble.lock`` in its folder the same way (:func:`hold_lock` is the
one mechanism of both).  The lock is an ``flock`` on the file, so the
operating system drops it when the holding process dies, however it dies;
the file names the holder (host, process id, start time) for the message
that refuses a second writer.  A lock file left by a process that has gone
is taken over, and the log says so.  A file naming a process of another host
is refused (its lock may not be visible from here): the message says how to
remove it.
"""
import contextlib
import json
import os
import socket
import time

from utils import UserInputError

try:
    import fcntl
except ImportError:  # not a POSIX system: the lock file alone (created exclusively) keeps writers apart
    fcntl = None

LOCK_SUFFIX = '.lock'


def _holder(descriptor):
    """The holder a lock file names (dict; empty when it is empty or not a holder's record)."""
    os.lseek(descriptor, 0, os.SEEK_SET)
    data = os.read(descriptor, 4096)
    try:
        holder = json.loads(data.decode('utf-8'))
    except (ValueError, UnicodeDecodeError):
        return {}
    return holder if isinstance(holder, dict) else {}


def _describe(holder):
    return 'pid %s on %s, started %s' % (holder.get('pid', '?'), holder.get('host', '?'), holder.get('started', '?'))


def _try_flock(descriptor):
    """True when this descriptor now holds the exclusive lock (False: another open file holds it)."""
    if fcntl is None:
        return True
    try:
        fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
        return True
    except BlockingIOError:
        return False


def _same_file(descriptor, path):
    """True while ``path`` is still the file open at ``descriptor`` (not removed and replaced by a releaser)."""
    try:
        return os.path.samestat(os.fstat(descriptor), os.stat(path))
    except OSError:
        return False


def _open(path):
    flags = os.O_RDWR | os.O_CREAT | (os.O_EXCL if fcntl is None else 0)
    try:
        return os.open(path, flags, 0o666)
    except FileExistsError:
        return None


def acquire(path, refusal, log=None):
    """Take the lock file ``path``; returns its open descriptor.

    ``refusal(holder_text)`` builds the UserInputError raised when another live
    process holds it; ``log`` gets one line when a stale lock is taken over.
    """
    host = socket.gethostname()
    for _ in range(5):
        descriptor = _open(path)
        if descriptor is None:
            raise refusal('named in %s' % path)
        if not _try_flock(descriptor):
            holder = _holder(descriptor)
            os.close(descriptor)
            raise refusal(_describe(holder))
        if not _same_file(descriptor, path):  # released and removed between our open and our lock: again
            os.close(descriptor)
            continue
        holder = _holder(descriptor)
        if holder.get('host') not in (None, host):
            os.close(descriptor)
            raise refusal(_describe(holder))
        if holder and log is not None:
            log('%s: the lock of %s, which no longer runs, is taken over' % (path, _describe(holder)))
        record = {'host': host, 'pid': os.getpid(), 'started': time.strftime('%Y-%m-%dT%H:%M:%SZ', time.gmtime())}
        os.ftruncate(descriptor, 0)
        os.lseek(descriptor, 0, os.SEEK_SET)
        os.write(descriptor, json.dumps(record).encode('utf-8'))
        return descriptor
    raise refusal('the lock file %s keeps being replaced' % path)


def release(path, descriptor):
    """Remove the lock file (still holding it, so no one takes a file about to vanish), then let it go."""
    try:
        if _same_file(descriptor, path):
            os.remove(path)
    except OSError:
        pass
    os.close(descriptor)


@contextlib.contextmanager
def hold_lock(path, refusal, log=None):
    """Hold the lock file ``path`` for the ``with`` block (see :func:`acquire`)."""
    descriptor = acquire(path, refusal, log)
    try:
        yield path
    finally:
        release(path, descriptor)


def _new_folders(folder):
    """The folders of ``folder`` that do not exist yet, deepest first."""
    missing = []
    while folder and not os.path.isdir(folder):
        missing.append(folder)
        parent = os.path.dirname(folder)
        if parent == folder:
            break
        folder = parent
    return missing


@contextlib.contextmanager
def output_lock(options, log=print):
    """Hold ``output_name.lock`` for a run of ``options``: one writer per output name.

    Created before anything of the run is read or written; a second run
    into the same ``output_name`` (or a restart while the first run lives)
    raises UserInputError naming the process that holds it.  Folders made
    for the lock alone are removed again when the run is refused and left
    them empty.
    """
    from multi_bodies.run.run_output import prepare_output_directory
    name = options.output_name
    created = _new_folders(os.path.dirname(os.path.abspath(name)))
    prepare_output_directory(name, options.where('output_name'))

    def refusal(holder):
        return UserInputError('%s: output_name %s is in use by another run (%s); wait for it to end or choose '
                              'another output_name (if that run no longer exists, remove %s%s)'
                              % (options.where('output_name'), name, holder, name, LOCK_SUFFIX))
    try:
        with hold_lock(name + LOCK_SUFFIX, refusal, log):
            yield
    finally:
        for folder in created:  # deepest first; a folder that holds outputs is kept
            try:
                os.rmdir(folder)
            except OSError:
                break
