"""One writer per output: an exclusive lock file beside the outputs (floor 6).

A run holds ``output_name.lock`` from before it reads its restart record or
touches, sets aside or writes any file until it ends; the static script holds
it while it writes, the ensemble runner holds ``ensemble.lock`` in its folder
the same way (:func:`hold_lock` is the one mechanism of all).  The lock is an
``flock`` on the file, so the operating system drops it when the holding
process dies, however it dies; the file names the holder (host, process id,
start time, and the process's start in clock ticks where ``/proc`` gives it)
for the message that refuses a second writer.  A lock file left by a process
that has gone is taken over, and the log says so; one that names a live
process (its lock file removed and written again, or a file system without
``flock``) is refused like a held lock.  A file naming a process of another
host is refused (its lock may not be visible from here): the message says how
to remove it.  A lock path that is a symbolic link, a folder, a FIFO or
anything but a regular file is refused in one line (it is never followed,
opened for reading or written).

Removing the lock file of a live run does not let a second writer in: a run
also names its process in ``output_name.run`` (:func:`holder_record`; the
segment is marked ended when the run lets its lock go), and a new writer
refuses an output name whose ``.run`` names another live process in a
segment that has not ended;
the live run notices at its next save that its lock file is gone
(:meth:`HeldLock.check`) and stops with one line.
"""
import contextlib
import errno
import json
import os
import socket
import stat
import time

from utils import UserInputError
from multi_bodies.run.run_state import RUN_SUFFIX

try:
    import fcntl
except ImportError:  # not a POSIX system: the lock file alone (created exclusively) keeps writers apart
    fcntl = None

LOCK_SUFFIX = '.lock'
HOLDER_BYTES = 4096  # a holder record is a short JSON line; more is not read


def process_start(pid):
    """The start of process ``pid`` in clock ticks after boot (field 22 of ``/proc/<pid>/stat``), or None where
    ``/proc`` does not say (another system, a process that has gone).  With the pid it names one process: a pid
    used again by a later process has another start."""
    try:
        with open('/proc/%d/stat' % int(pid), 'rb') as f:
            text = f.read(4096)
        return int(text[text.rindex(b')') + 2:].split()[19])
    except (OSError, ValueError, IndexError, OverflowError):
        return None


def holder_record():
    """This process as a lock file or ``.run`` segment names it: host, pid, UTC start, start in clock ticks."""
    record = {'host': socket.gethostname(), 'pid': os.getpid(),
              'started': time.strftime('%Y-%m-%dT%H:%M:%SZ', time.gmtime())}
    ticks = process_start(os.getpid())
    if ticks is not None:
        record['process_start'] = ticks
    return record


def holder_alive(holder):
    """True when ``holder`` (a dict naming host, pid and perhaps process_start) is a process of this host that
    still runs and is not this one; False when it has gone or is this process; None for another host (unknown)."""
    if not isinstance(holder, dict):
        return False
    host, pid = holder.get('host'), holder.get('pid')
    if host != socket.gethostname():
        return None if host is not None else False
    if not (isinstance(pid, int) and not isinstance(pid, bool) and 0 < pid < 2 ** 31) or pid == os.getpid():
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # it exists, under another user
        pass
    except OSError:
        return False
    recorded, now = holder.get('process_start'), process_start(pid)
    if isinstance(recorded, int) and now is not None:
        return recorded == now  # another start: the pid was given to a later process
    return True


def _holder(descriptor):
    """The holder a lock file names (dict; empty when it is empty or not a holder's record)."""
    os.lseek(descriptor, 0, os.SEEK_SET)
    data = os.read(descriptor, HOLDER_BYTES)
    try:
        holder = json.loads(data.decode('utf-8'))
    except (ValueError, UnicodeDecodeError, RecursionError):
        return {}
    return holder if isinstance(holder, dict) else {}


def _describe(holder):
    def short(value):
        text = str(value)
        return text if len(text) <= 80 else text[:77] + '...'
    return 'pid %s on %s, started %s' % tuple(short(holder.get(key, '?')) for key in ('pid', 'host', 'started'))


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
        return os.path.samestat(os.fstat(descriptor), os.lstat(path))
    except OSError:
        return False


FILE_KINDS = ((stat.S_ISLNK, 'a symbolic link'), (stat.S_ISDIR, 'a folder'), (stat.S_ISFIFO, 'a FIFO'),
              (stat.S_ISSOCK, 'a socket'), (stat.S_ISCHR, 'a character device'), (stat.S_ISBLK, 'a block device'))


def kind_of(mode):
    """'a symbolic link', 'a folder', 'a FIFO', ... of an ``lstat`` mode; None for a regular file."""
    if stat.S_ISREG(mode):
        return None
    for test, name in FILE_KINDS:
        if test(mode):
            return name
    return 'not a regular file'


def _not_a_lock_file(path, kind, where=None):
    return UserInputError('%s%s is %s, not a lock file; nothing was read or written through it. Remove it (or '
                          'choose another output name)' % ('%s: ' % where if where else '', path, kind))


def _open(path, where=None):
    """Open (creating) the lock file ``path`` without following a link or blocking on a FIFO; None when it exists
    and the system has no flock.  Raises UserInputError for a path that is not a regular file."""
    try:
        kind = kind_of(os.lstat(path).st_mode)
    except FileNotFoundError:
        kind = None
    except OSError as err:
        raise UserInputError('%s%s: cannot use it as a lock file (%s); choose another output name'
                             % ('%s: ' % where if where else '', path, err.strerror or err))
    if kind is not None:
        raise _not_a_lock_file(path, kind, where)
    flags = (os.O_RDWR | os.O_CREAT | getattr(os, 'O_NOFOLLOW', 0) | getattr(os, 'O_NONBLOCK', 0)
             | (os.O_EXCL if fcntl is None else 0))
    try:
        descriptor = os.open(path, flags, 0o666)
    except FileExistsError:
        return None
    except OSError as err:
        if err.errno == errno.ELOOP:  # made a link between the check and the open
            raise _not_a_lock_file(path, 'a symbolic link', where)
        raise UserInputError('%s%s: cannot create the lock file (%s); choose another output name or change the '
                             "folder's permissions" % ('%s: ' % where if where else '', path, err.strerror or err))
    kind = kind_of(os.fstat(descriptor).st_mode)
    if kind is not None:  # replaced by a FIFO or device between the check and the open
        os.close(descriptor)
        raise _not_a_lock_file(path, kind, where)
    return descriptor


def acquire(path, refusal, log=None, where=None):
    """Take the lock file ``path``; returns its open descriptor.

    ``refusal(holder_text)`` builds the UserInputError raised when another live
    process holds it; ``log`` gets one line when a stale lock is taken over; ``where`` (the option's file and
    line) starts the messages about a path that cannot be a lock file.
    """
    for _ in range(5):
        descriptor = _open(path, where)
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
        alive = holder_alive(holder) if holder else False
        if alive is not False:  # another host (its flock is not seen here), or a live process without the flock
            os.close(descriptor)
            raise refusal(_describe(holder) + ('' if alive else '; a process of another host: if it no longer '
                                                                'runs, remove %s' % path))
        if holder and log is not None:
            log('%s: the lock of %s, which no longer runs, is taken over' % (path, _describe(holder)))
        os.ftruncate(descriptor, 0)
        os.lseek(descriptor, 0, os.SEEK_SET)
        os.write(descriptor, json.dumps(holder_record()).encode('utf-8'))
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


class LockLost(OSError):
    """The outputs of a running writer were taken by another program (its lock file replaced, its ``.restart``
    appended to by another process): this writer stops."""
    hint = ('another program writes the same outputs (a lock file removed while its run lived?); let it end, then '
            'restart from the last complete step')


class HeldLock:
    """A lock held by this process: ``path`` and :meth:`check`, which a writer calls before each save."""

    def __init__(self, path, descriptor):
        self.path, self.descriptor = path, descriptor

    def check(self):
        """Keep the lock before a save: a lock file removed by hand is made and locked again; one replaced by
        another program's raises LockLost."""
        if _same_file(self.descriptor, self.path):
            return
        try:
            os.lstat(self.path)
            present = True
        except FileNotFoundError:
            present = False
        except OSError:
            present = True
        if not present and fcntl is not None:
            try:
                descriptor = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_EXCL | getattr(os, 'O_NOFOLLOW', 0),
                                     0o666)
            except OSError:
                descriptor = None
            if descriptor is not None:
                if _try_flock(descriptor):
                    os.write(descriptor, json.dumps(holder_record()).encode('utf-8'))
                    os.close(self.descriptor)  # the removed file's lock is of no use to anyone
                    self.descriptor = descriptor
                    return
                os.close(descriptor)
        raise LockLost(errno.EBUSY, 'the lock file was removed and replaced while this run held it', self.path)


@contextlib.contextmanager
def hold_lock(path, refusal, log=None, where=None):
    """Hold the lock file ``path`` for the ``with`` block (see :func:`acquire`); yields a :class:`HeldLock`."""
    held = HeldLock(path, acquire(path, refusal, log, where))
    try:
        yield held
    finally:
        release(path, held.descriptor)


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


RUN_FILE_BYTES = 1 << 20  # a .run file lists the segments of one run: a few hundred bytes each


def _read_run_file(path):
    if not stat.S_ISREG(os.lstat(path).st_mode) or os.path.getsize(path) > RUN_FILE_BYTES:
        raise ValueError('not a run file')
    with open(path) as f:
        document = json.load(f)
    if not (isinstance(document, dict) and isinstance(document.get('segments'), list) and document['segments']
            and isinstance(document['segments'][-1], dict)):
        raise ValueError('not a run file')
    return document


def run_file_holder(output_name):
    """The process the last segment of ``output_name.run`` names (dict) while that segment has not ended, or None
    (ended, no such file, unreadable)."""
    try:
        document = _read_run_file(output_name + RUN_SUFFIX)
    except (OSError, ValueError, RecursionError, UnicodeDecodeError):
        return None
    segment = document['segments'][-1]
    return None if segment.get('ended') else dict(segment, run_id=document.get('run_id'))


def mark_run_ended(output_name):
    """Say in ``output_name.run`` that this process's segment has ended (a process that lives on after its run, a
    notebook or an ensemble worker, is then not taken for a writer of the output name); quiet when it cannot."""
    path = output_name + RUN_SUFFIX
    try:
        document = _read_run_file(path)
        segment = document['segments'][-1]
        me = holder_record()
        if segment.get('ended') or segment.get('pid') != me['pid'] or segment.get('host') != me['host'] or \
                segment.get('process_start') != me.get('process_start'):
            return  # not a segment of this process that is still open (a refused run leaves the file as it was)
        segment['ended'] = time.strftime('%Y-%m-%dT%H:%M:%SZ', time.gmtime())
        part = path + '.part'
        with open(part, 'w') as f:
            f.write(json.dumps(document, indent=1) + '\n')
        os.replace(part, path)
    except (OSError, ValueError, RecursionError, UnicodeDecodeError):
        pass


# Room left in a path for what a run adds to output_name: '.set_aside/<time>_earlier_run_<id>/' and a snapshot
# name '.<structure ID>.<step>.clones' (an ID is a file name: up to the system's longest name).
SUFFIX_ROOM = 120


def _path_limits(folder):
    """(longest path, longest file name) in bytes where ``folder`` lies (POSIX pathconf; 4096 and 255 else)."""
    limits = []
    for name, default in (('PC_PATH_MAX', 4096), ('PC_NAME_MAX', 255)):
        try:
            limits.append(int(os.pathconf(folder, name)))
        except (OSError, ValueError, AttributeError):
            limits.append(default)
    return limits


def _existing_parent(folder):
    while folder and not os.path.isdir(folder):
        parent = os.path.dirname(folder)
        if parent == folder:
            break
        folder = parent
    return folder or os.curdir


def prepare_output_directory(output_name, where='output_name'):
    """Create the folder of ``output_name`` and check that files can be written there.

    Raises UserInputError naming ``where`` (the option's file and line) when
    the name is longer than the file system allows (with room for the suffixes a run adds), the folder cannot be
    created, is a file, or is read-only.  Missing folders are made one by one (any depth, no recursion).
    """
    if '\x00' in output_name:  # no file name can hold it (open() would raise ValueError)
        raise UserInputError('%s: output_name %r holds a NUL byte, which no file name can hold; write the output '
                             'name in plain text' % (where, output_name))
    folder = os.path.dirname(output_name) or os.curdir
    path_max, name_max = _path_limits(_existing_parent(os.path.abspath(folder)))
    full = len(os.fsencode(os.path.abspath(output_name)))
    longest = max((len(os.fsencode(part)) for part in output_name.split(os.sep)), default=0)
    if full + SUFFIX_ROOM > path_max or longest + SUFFIX_ROOM // 2 > name_max:
        raise UserInputError('%s: output_name is %d bytes long as a full path, with a name of %d bytes in it: the '
                             'file system takes paths of %d bytes and names of %d, and a run adds up to %d bytes '
                             '(.set_aside folders, .<ID>.<step>.clones); choose a shorter output_name'
                             % (where, full, longest, path_max, name_max, SUFFIX_ROOM))
    if os.path.exists(folder) and not os.path.isdir(folder):
        raise UserInputError('%s: output_name %s needs the folder %s, but that is a file; choose another '
                             'output_name or remove the file' % (where, output_name, folder))
    missing, parent = [], folder
    while parent and not os.path.isdir(parent):
        missing.append(parent)
        up = os.path.dirname(parent)
        if up == parent:
            break
        parent = up
    for path in reversed(missing):
        try:
            os.mkdir(path)
        except FileExistsError:
            if not os.path.isdir(path):
                raise UserInputError('%s: output_name %s needs the folder %s, but that is a file; choose another '
                                     'output_name or remove the file' % (where, output_name, path))
        except OSError as err:
            raise UserInputError('%s: cannot create the output folder %s (%s); choose another output_name'
                                 % (where, folder, err.strerror or err))
    if not os.access(folder, os.W_OK | os.X_OK):
        raise UserInputError('%s: the output folder %s is not writable; choose another output_name or change '
                             'its permissions' % (where, folder))


@contextlib.contextmanager
def output_lock(options, log=print):
    """Hold ``output_name.lock`` for a run of ``options``: one writer per output name; yields a HeldLock.

    Created before anything of the run is read or written; a second run
    into the same ``output_name`` (or a restart while the first run lives)
    raises UserInputError naming the process that holds it, also when the
    live run's lock file was removed (``output_name.run`` names it).  Folders
    made for the lock alone are removed again when the run is refused and
    left them empty.
    """
    name = options.output_name
    created = _new_folders(os.path.dirname(os.path.abspath(name)))
    prepare_output_directory(name, options.where('output_name'))

    def refusal(holder):
        return UserInputError('%s: output_name %s is in use by another run (%s); wait for it to end or choose '
                              'another output_name' % (options.where('output_name'), name, holder))
    try:
        with hold_lock(name + LOCK_SUFFIX, refusal, log, where=options.where('output_name')) as held:
            writer = run_file_holder(name)
            if writer is not None and holder_alive(writer):
                raise UserInputError('%s: output_name %s is in use by another run (%s, named in %s.run; its lock '
                                     'file %s%s was removed while it runs); wait for it to end or choose another '
                                     'output_name' % (options.where('output_name'), name, _describe(writer), name,
                                                      name, LOCK_SUFFIX))
            try:
                yield held
            finally:
                mark_run_ended(name)  # before the lock goes: the next writer sees an ended segment
    finally:
        for folder in created:  # deepest first; a folder that holds outputs is kept
            try:
                os.rmdir(folder)
            except OSError:
                break
