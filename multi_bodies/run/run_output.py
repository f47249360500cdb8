"""Output of a run, shared by every script that writes one (floor 6).

The dynamic script (``multi_bodies.py``), the Monte Carlo script
(``many_body_MCMC.py``), the ensemble runner and the single-body codes write
the same files with the same names (the manual's section 5.1):

* ``output_name.inputfile``: a copy of the input file (a restart appends the
  new input below a separator line, so both segments are kept);
* ``output_name.random_state``: the state of the run's generator at the
  start of the run (or of the restart segment), as JSON text
  (``write_state_text``; arrays as base64 of their bytes): reading it never
  runs code.  A pickled numpy ``RandomState`` state of the published code is
  read with a restricted unpickler that admits only arrays and dtypes;
* ``output_name.<ID>.<step, 8 digits>.clones`` per structure and saved step
  (``save_clones one_file_per_step``), or ``output_name.<ID>.config`` with all
  snapshots of a structure one after another (``save_clones one_file``);
  numbers with round-trip precision (SPEC decision 4);
* ``output_name.restart``: one file per run holding, for every saved step,
  what an exact restart needs besides the snapshot: the generator state, the
  scheme history (Adams-Bashforth previous velocities, the configuration the
  preconditioner was built at, ...) and where the snapshot starts inside the
  ``.config`` files (restart from ``save_clones one_file``).  Records are
  appended, each a fixed header (step, length, SHA-256 of the payload) and
  a JSON payload, so what was saved before a hard stop stays readable, one
  record is found by reading the headers only, and a record cut by a hard
  stop or with flipped bits is refused or skipped with a message;
* ``output_name.info``: counters (invalid configurations, iterations of the
  deterministic solves and of the noise), rewritten at every save, so even a
  killed run loses at most one save interval;
* ``output_name.time``: wall-clock seconds of the time loop (a restart
  appends one line per segment).

Nothing here knows about physics: the caller passes arrays and counters.
This module writes the snapshots with their records and the counters; the
time loop, the stop on a signal and the end of a run are in
:mod:`multi_bodies.run.run_loop`; the encoding of saved state and the generator are in
:mod:`multi_bodies.run.run_state`, the format and checks of restart records
in :mod:`multi_bodies.run.restart_records` (their names are re-exported here).
"""
import errno
import hashlib
import os
import shutil
import signal
import time
import re

import numpy as np

import utils
from utils import UserInputError, available_memory, format_bytes  # noqa: F401 (re-exported)
from multi_bodies.run.output_lock import LockLost, prepare_output_directory  # noqa: F401 (re-exported)
from multi_bodies.files.snapshots import (append_config_snapshot, clones_name, config_name,  # noqa: F401
                                          format_clones, read_config_snapshot, truncate_config,
                                          write_clones_file)

# Moved to run_state and restart_records; re-exported here for the callers of run_output.
from multi_bodies.run.run_state import (RESTART_SUFFIX, RUN_SUFFIX, STOP_SUFFIX, ASIDE_SUFFIX, STATE_FORMAT,
                                        STATE_VERSION, encode_state, decode_state, state_to_bytes,
                                        state_from_bytes, _PublishedStateUnpickler, read_published_state,
                                        read_random_state, load_random_state, make_generator, save_random_state,
                                        atomic_write, _remove_quietly)  # noqa: F401,E402
from multi_bodies.run.restart_records import (RESTART_MAGIC, RECORD_HEADER, RECORD_TAG, RestartFileError,
                                              _not_a_restart_file, restart_index, read_restart_entry,
                                              last_valid_restart_record, DYNAMICS_OPTIONS, FORCE_OPTION,
                                              FORCE_HINT, KILL_HOOK, _digest, run_fingerprint,
                                              fingerprint_changes, new_run_id, write_run_file, read_run_id,
                                              stop_snapshot_path, snapshot_bytes, snapshot_mismatches,
                                              last_complete_pair, check_restart, recorded_snapshots,
                                              find_restart_record, read_restart_records,
                                              restart_record)  # noqa: F401,E402


# ------------------------------------------------------------------ set-up of the output folder
def copy_input_file(input_file, output_name, restart=False):
    """Write ``output_name.inputfile``: a copy, or (restart) the earlier copy followed by the new input."""
    copy = output_name + '.inputfile'
    if os.path.exists(copy) and os.path.samefile(input_file, copy):
        return copy
    if restart and os.path.isfile(copy):
        with open(input_file, 'rb') as source, open(copy, 'ab') as target:
            target.write(b'\n# ---- restart segment: input file %s ----\n' % os.fsencode(input_file))
            shutil.copyfileobj(source, target)
    else:
        shutil.copyfile(input_file, copy)
    return copy


# ------------------------------------------------------------------ checks before a run
SMALLEST_BOX = 1e-6


def check_periodic_length(options):
    """Refuse a negative, infinite or vanishing periodic_length (each entry 0 or at least SMALLEST_BOX)."""
    box = options.periodic_length
    if not all(np.isfinite(v) and (v == 0 or v >= SMALLEST_BOX) for v in box):
        raise UserInputError('%s: periodic_length %s: each length must be 0 (that axis is not periodic) or a box '
                             'length of at least %g, in the units of the blob radius'
                             % (options.where('periodic_length'), ' '.join('%g' % v for v in box), SMALLEST_BOX))


# ------------------------------------------------------------------ resources
def refuse_if_too_big(need, what, where, fix):
    """``utils.refuse_if_too_big`` with the memory :func:`available_memory` of this module gives."""
    utils.refuse_if_too_big(need, what, where, fix, have=available_memory())


def dense_memory(num_blobs, num_bodies):
    """Bytes of the dense matrices of one dense solve: the blob mobility (3N)^2 three times (the matrix, its
    inverse or factor, a work copy) and the body blocks (6 Nb)^2 twice, doubles."""
    return 8 * (3 * (3 * num_blobs) ** 2 + 2 * (6 * num_bodies) ** 2 + 6 * (3 * num_blobs) * (6 * num_bodies))


FILES_WARNING, BYTES_WARNING = 10000, 10 ** 9


def output_estimate(n_saves, types, save_clones, record_bytes):
    """(files, bytes) a run with ``n_saves`` saves will write (snapshots and restart records)."""
    bodies = sum(count for _, count in types)
    files = n_saves * len(types) if save_clones == 'one_file_per_step' else len(types)
    return files + 8, n_saves * (bodies * 140 + record_bytes + 60)


def warn_if_large_output(options, types, record_bytes, log):
    """A line when the run will write more than 10,000 files or 1 GB (``n_save`` and ``save_clones`` say how many)."""
    first = options.initial_step
    saves = max(0, options.n_steps // options.n_save - (first - 1) // options.n_save) if options.n_steps > first \
        else 0
    files, size = output_estimate(saves, types, options.save_clones, record_bytes)
    if files > FILES_WARNING or size > BYTES_WARNING:
        log('warning: %s: this run will write about %d files and %s (%d saves); raise n_save or use save_clones '
            'one_file to write fewer' % (options.where('n_save'), files, format_bytes(size), saves))


def save_table(path, table):
    """``np.savetxt`` of ``table`` (two spaces between numbers) to ``path``; an OSError names ``path`` (a write that
    fails on a full disk names no file by itself)."""
    try:
        np.savetxt(path, table, delimiter='  ')
    except OSError as err:
        if err.filename is None:
            err.filename = path
        raise


def write_bodies_info(path, types, num_blobs):
    """``.bodies_info``: number of body types, their names, bodies per type, bodies, blobs."""
    text = ('num_of_body_types  %d\n' % len(types)
            + 'body_names         %s\n' % str([name for name, _ in types])
            + 'body_types         %s\n' % str([count for _, count in types])
            + 'num_bodies         %d\n' % sum(count for _, count in types)
            + 'num_blobs          %d\n' % num_blobs)
    atomic_write(path, text)


INFO_KEYS = (
    ('invalid_configuration_count', 'invalid configurations rejected (a blob centre crossed the wall)'),
    ('deterministic_iterations_count', 'GMRES iterations of the deterministic mobility solves'),
    ('stochastic_iterations_count', 'Lanczos iterations of the Brownian noise'),
)


def write_info(path, counters, extra_lines=()):
    """``.info``: the manual's three counters first (published names), then any further counters.

    counters: dict name -> int.  The first three lines are always
    ``invalid_configuration_count``, ``deterministic_iterations_count`` and
    ``stochastic_iterations_count`` (0 when absent), padded as the published
    code pads them, so readers of published ``.info`` files keep working.
    Further counters follow in the same ``name = value`` form, then
    ``cpu_kernels``, the vector path of the compiled kernels
    (:func:`mobility.simd.describe`); ``extra_lines`` are written last, as they are.
    """
    from mobility import simd
    known = [key for key, _ in INFO_KEYS]
    lines = ['%-30s = %d' % (key, int(counters.get(key, 0))) for key in known]
    for key, value in counters.items():
        if key not in known:
            lines.append('%-30s = %s' % (key, value))
    lines.append('%-30s = %s' % ('cpu_kernels', simd.describe()))
    lines.extend(extra_lines)
    atomic_write(path, '\n'.join(lines) + '\n')


def read_info(path):
    """The ``name = value`` lines of an ``.info`` file as a dict (values as int or float where they parse)."""
    values = {}
    with open(path) as f:
        for line in f:
            if '=' not in line:
                continue
            key, value = (part.strip() for part in line.split('=', 1))
            for kind in (int, float):
                try:
                    value = kind(value)
                    break
                except ValueError:
                    pass
            values[key] = value
    return values


def append_time(path, elapsed, restart=False, note=None):
    """``.time``: wall-clock seconds of the loop; a restart appends a line, so every segment is kept."""
    line = repr(float(elapsed)) + ('  # %s' % note if note else '') + '\n'
    if restart and os.path.isfile(path):
        with open(path, 'a') as f:
            f.write(line)
    else:
        atomic_write(path, line)


# ------------------------------------------------------------------ moving earlier outputs aside
_SNAPSHOT_SUFFIX = re.compile(r'^\.(?P<id>.+?)\.(?:(?P<step>\d{8,})(?:\.stop)?\.clones|config)$')

# What the programs write beside the snapshots, by the part of the name after ``output_name.`` (a new run into
# the same output_name sets these aside first): the dynamic, Monte Carlo and static programs, the phoretic
# blocks, the VTK collections, the HydroGrid tables, the dense mobilities of the saved steps.
RUN_FILE_SUFFIXES = frozenset((
    'inputfile', 'random_state', 'bodies_info', 'info', 'MCMC_info', 'time', 'restart', 'run', 'concentration',
    'velocities.dat', 'force.dat', 'body_mobility.dat', 'body_slip_mobility.dat', 'joint_forces.dat',
    'velocity_field.vtk', 'blobs.pvd', 'bodies.pvd', 'joints.pvd', 'hydrogrid.sk.dat', 'hydrogrid.sk_radial.dat',
    'hydrogrid.fkt.dat', STOP_SUFFIX[1:]))
_RUN_FILE_PATTERN = re.compile(r'^(?:(?:blobs|bodies|joints)\.\d{8,}\.vtp|hydrogrid\.\d{8,}\.(?:sk|sk_radial|fkt)\.dat'
                               r'|(?:blobs|body)_mobility\.\d{8,}\.dat)$')
BODIES_INFO_BYTES = 1 << 20  # a .bodies_info is five short lines


def recorded_structure_ids(output_name):
    """The structure IDs the ``.bodies_info`` of ``output_name`` names (an earlier run's), or [] without one."""
    import ast
    path = output_name + '.bodies_info'
    try:
        if os.path.getsize(path) > BODIES_INFO_BYTES:
            return []
        with open(path, encoding='utf-8', errors='replace') as f:
            for line in f:
                if line.startswith('body_names'):
                    names = ast.literal_eval(line.split(None, 1)[1].strip())
                    return [name for name in names if isinstance(name, str)] if isinstance(names, list) else []
    except (OSError, ValueError, SyntaxError, IndexError, MemoryError, RecursionError):
        pass
    return []


def run_snapshot_files(output_name, ids):
    """Snapshot files of ``output_name`` of the structures ``ids``: list of (path, ID, step or None for a ``.config``).

    Names are matched exactly: ``output_name.<ID>.<step>.clones`` and ``output_name.<ID>.config`` with ``<ID>`` one
    of ``ids``, so the files of another output name that starts the same way (``run.b`` beside ``run``) are never
    taken."""
    folder, base = os.path.split(output_name)
    try:
        names = sorted(os.listdir(folder or os.curdir))
    except OSError:
        return []
    ids = set(ids)
    found = []
    for name in names:
        if not name.startswith(base + '.'):
            continue
        match = _SNAPSHOT_SUFFIX.match(name[len(base):])
        path = os.path.join(folder, name)
        if match and match.group('id') in ids and os.path.isfile(path):
            found.append((path, match.group('id'), int(match.group('step')) if match.group('step') else None))
    return found


def earlier_run_files(output_name, ids, copies=()):
    """Every file (and the ``.stopped`` folder) of an earlier run with ``output_name`` that a new run would
    overwrite or mix with: the names of :data:`RUN_FILE_SUFFIXES` and its patterns, the snapshots of ``ids`` and
    of the structures the earlier ``.bodies_info`` names, and ``copies`` (the names after ``output_name.`` of the
    input files a run copies beside its outputs).  Matched exactly, never by prefix."""
    folder, base = os.path.split(output_name)
    ids = set(ids) | set(recorded_structure_ids(output_name))
    found = [path for path, _, _ in run_snapshot_files(output_name, ids)]
    try:
        names = sorted(os.listdir(folder or os.curdir))
    except OSError:
        return found
    for name in names:
        if not name.startswith(base + '.'):
            continue
        rest = name[len(base) + 1:]
        path = os.path.join(folder, name)
        if (rest in RUN_FILE_SUFFIXES or _RUN_FILE_PATTERN.match(rest) or rest in copies) and path not in found \
                and (os.path.isfile(path) or (rest == STOP_SUFFIX[1:] and os.path.isdir(path))):
            found.append(path)
    return found


def _same_as_any(path, others):
    for other in others:
        try:
            if os.path.samefile(path, other):
                return True
        except OSError:
            pass
    return False


def set_aside_earlier_run(output_name, ids, copies=(), log=print, why=None, keep=()):
    """Move every file of an earlier run with ``output_name`` (:func:`earlier_run_files`) to
    ``output_name.set_aside/<time>_earlier_run_<id>/`` before a new run writes any; returns that folder or None.

    ``keep``: files left in place (the input file of the new run, when it is the earlier run's ``.inputfile``)."""
    files = [path for path in earlier_run_files(output_name, ids, copies) if not _same_as_any(path, keep)]
    if not files:
        return None
    folder = aside_folder(output_name, why or 'earlier_run_%s' % (read_run_id(output_name) or 'unknown'))
    for path in files:
        os.replace(path, os.path.join(folder, os.path.basename(path)))
    log('%d files of an earlier run with output_name %s moved to %s' % (len(files), output_name, folder))
    return folder


def aside_folder(output_name, why):
    """A new folder ``output_name.set_aside/<time>_<why>/`` for outputs that a new run or restart replaces."""
    stamp = time.strftime('%Y%m%dT%H%M%S', time.gmtime())
    base = os.path.join(output_name + ASIDE_SUFFIX, '%s_%s' % (stamp, why))
    folder, n = base, 1
    while os.path.exists(folder):
        n += 1
        folder = '%s_%d' % (base, n)
    os.makedirs(folder)
    return folder


def _save_tail(path, keep, folder):
    """Copy the bytes of ``path`` after ``keep`` into ``folder`` (synced), then cut ``path`` at ``keep``.

    The cut happens only once the copy is on disk, so nothing is lost.
    """
    with open(path, 'rb') as source:
        source.seek(keep)
        tail = source.read()
    target = os.path.join(folder, os.path.basename(path) + '.after_byte_%d' % keep)
    with open(target, 'wb') as f:
        f.write(tail)
        f.flush()
        os.fsync(f.fileno())
    with open(path, 'r+b') as f:
        f.truncate(keep)
        f.flush()
        os.fsync(f.fileno())


class SnapshotWriter:
    """Writes the configuration of every structure type at the saved steps, and the restart records.

    Parameters
    ----------
    output_name : str
    save_clones : 'one_file_per_step' or 'one_file'
    types : list of (structure ID, number of bodies), in body order
    where : str, location of the save_clones option for messages
    restart : bool, this run continues an earlier one (``one_file`` series are appended to)
    restart_from : (record, end) or record or None: the restart record of the step the run continues from and
        the byte where it ends in ``.restart``
    run_id : str, the run identifier written in every record (a restart passes the record's)
    fingerprint : dict, ``run_fingerprint`` of the run, written in every record
    log : callable(str) for the lines saying what was moved aside
    lock : the ``output_lock.HeldLock`` of the run or None: checked before every save, and ``.restart`` must
        have the size this writer left it at (else another program writes the same outputs: LockLost)

    Nothing is changed before the first save (a restart refused or with nothing to do leaves every file as it
    was).  At the first save, a new run moves the snapshots and ``.restart`` of an earlier run with the same
    ``output_name`` into ``output_name.set_aside/``; a restart from step k moves there what belongs to the
    abandoned continuation after k (later ``.clones`` files, the ``.config`` bytes after snapshot k, the
    ``.restart`` bytes after record k, including a record cut by a hard stop), each copied and synced before
    the original is cut.  A snapshot is written before its record; a record holds the SHA-256 of every
    snapshot it belongs to, so a restart can tell a complete pair from a lone snapshot or an edited one.
    """

    def __init__(self, output_name, save_clones, types, where='save_clones', restart=False, restart_from=None,
                 run_id=None, fingerprint=None, log=None, lock=None):
        if save_clones not in ('one_file_per_step', 'one_file'):
            raise UserInputError("%s: save_clones must be one_file_per_step or one_file, got '%s'"
                                 % (where, save_clones))
        self.output_name, self.save_clones, self.types = output_name, save_clones, list(types)
        self.restart_path = output_name + RESTART_SUFFIX
        self.restart = restart
        if isinstance(restart_from, tuple):
            self.record, self.record_end = restart_from
        else:
            self.record, self.record_end = restart_from, None
        self.run_id = run_id or (self.record or {}).get('run_id') or new_run_id()
        self.fingerprint = fingerprint
        self.log = log or (lambda text: print(text, flush=True))
        self._begun = False
        self.last_saved = None
        self.lock = lock
        self._restart_size = None  # the size of .restart after this writer's last record

    # -------------------------------------------------------------- the first save
    def _begin(self, step):
        self._begun = True
        if not self.restart:
            self._set_aside_earlier_run()
        else:
            self._set_aside_abandoned(step)
        write_run_file(self.output_name, self.run_id, step)
        self._restart_size = os.path.getsize(self.restart_path) if os.path.isfile(self.restart_path) else 0

    def _set_aside_earlier_run(self):
        ids = {name for name, _ in self.types} | set(recorded_structure_ids(self.output_name))
        files = [path for path, _, _ in run_snapshot_files(self.output_name, ids)]
        for suffix in (RESTART_SUFFIX, RUN_SUFFIX):
            if os.path.isfile(self.output_name + suffix):
                files.append(self.output_name + suffix)
        if not files:
            return
        folder = aside_folder(self.output_name, 'earlier_run_%s' % (read_run_id(self.output_name) or 'unknown'))
        for path in files:
            os.replace(path, os.path.join(folder, os.path.basename(path)))
        self.log('new run %s: %d files of an earlier run with output_name %s (snapshots, .restart) moved to %s'
                 % (self.run_id, len(files), self.output_name, folder))

    def _set_aside_abandoned(self, step):
        record = self.record or {}
        k = record.get('step', step)
        moves, cuts = [], []
        ids = {name for name, _ in self.types}
        if self.save_clones == 'one_file_per_step':
            moves = [path for path, name, s in run_snapshot_files(self.output_name, ids) if s is not None and s > k]
        else:
            for name, _ in self.types:
                path = config_name(self.output_name, name)
                if not os.path.isfile(path):
                    continue
                keep = self._config_keep(name, path)
                if keep is not None and os.path.getsize(path) > keep:
                    cuts.append((path, keep))
        if self.record_end is not None and os.path.isfile(self.restart_path) \
                and os.path.getsize(self.restart_path) > self.record_end:
            cuts.append((self.restart_path, self.record_end))
        if not moves and not cuts:
            return
        folder = aside_folder(self.output_name, 'after_step_%d' % k)
        for path in moves:
            os.replace(path, os.path.join(folder, os.path.basename(path)))
        for path, keep in cuts:
            _save_tail(path, keep, folder)
        self.log('restart from step %d: %d snapshot files and %d file ends of the continuation after step %d '
                 '(or cut by a hard stop) moved to %s' % (k, len(moves), len(cuts), k, folder))

    def _config_keep(self, name, path):
        """Bytes of the ``.config`` of ``name`` that the continuation keeps: up to the end of snapshot k."""
        record = self.record or {}
        ends = record.get('config_ends') or {}
        if name in ends:
            return int(ends[name])
        offsets = record.get('config_offsets') or {}
        if name not in offsets:
            return None
        offset = int(offsets[name])
        snapshot = (record.get('snapshots') or {}).get(name)
        if snapshot:
            return offset + int(snapshot[1])
        return config_snapshot_end(path, offset)

    # -------------------------------------------------------------- one save
    def save(self, step, locations, orientations, restart_state=None, stop=False, side_offsets=None):
        """Write snapshot ``step`` of all structures; then append its restart record.

        locations (Nb, 3), orientations (Nb, 4); ``restart_state``: what the
        run needs to continue exactly from this step (generator state, scheme
        history), nested dicts/lists/tuples of numbers, strings and arrays
        (``encode_state``).  ``stop``: a save outside the ``n_save`` grid (a
        signal stopped the run): the snapshot goes to ``.clones`` files in ``output_name.stopped/`` (the
        series keep the grid steps only), named in the record.  ``side_offsets``: {file kind: [start, end]}, the
        bytes of this step's block in a side file (``.concentration``), kept in the record so that a restart
        from this step cuts the side file where the uninterrupted run had it.
        Raises OSError when a file cannot be written (what this save appended is taken back first), LockLost
        when another program took the outputs.
        """
        if self.lock is not None:
            self.lock.check()
        if not self._begun:
            self._begin(step)
        elif self._restart_size is not None and self._size_of_restart() != self._restart_size:
            raise LockLost(errno.EBUSY, 'records of another run were appended after step %s of this one'
                           % self.last_saved, self.restart_path)
        offsets, digests, stop_files = {}, {}, {}
        start = 0
        for structure_id, count in self.types:
            block = slice(start, start + count)
            start += count
            text = format_clones(locations[block], orientations[block]).encode()
            digests[structure_id] = [_digest(text), len(text)]
            if stop:  # off the grid: beside the series, so that the series keep the n_save steps only
                folder = self.output_name + STOP_SUFFIX
                os.makedirs(folder, exist_ok=True)
                path = os.path.join(folder, os.path.basename(clones_name(self.output_name, structure_id, step)))
                write_clones_file(path, locations[block], orientations[block])
                stop_files[structure_id] = os.path.relpath(path, os.path.dirname(self.output_name) or os.curdir)
            elif self.save_clones == 'one_file_per_step':
                write_clones_file(clones_name(self.output_name, structure_id, step), locations[block],
                                  orientations[block])
            else:
                offsets[structure_id] = self._append_config(structure_id, step, text)
        if os.environ.get(KILL_HOOK) == str(step):
            os.kill(os.getpid(), signal.SIGKILL)
        record = {'step': int(step), 'run_id': self.run_id, 'config_offsets': offsets, 'snapshots': digests,
                  'fingerprint': self.fingerprint, 'state': restart_state}
        if self.save_clones == 'one_file':
            record['config_ends'] = {name: os.path.getsize(config_name(self.output_name, name))
                                     for name, _ in self.types if os.path.isfile(config_name(self.output_name, name))}
        if stop:
            record['stop'] = True
            if stop_files:
                record['stop_files'] = stop_files
        if side_offsets:
            record['side_files'] = {name: [int(start), int(end)] for name, (start, end) in side_offsets.items()}
        payload = state_to_bytes(record)
        header = RECORD_HEADER.pack(RECORD_TAG, int(step), len(payload), hashlib.sha256(payload).digest())
        new = not os.path.isfile(self.restart_path) or os.path.getsize(self.restart_path) == 0
        _append_or_take_back(self.restart_path, (RESTART_MAGIC if new else b'') + header + payload)
        self._restart_size = self._size_of_restart()
        self.last_saved = step

    def _size_of_restart(self):
        try:
            return os.path.getsize(self.restart_path)
        except OSError:
            return -1

    def _append_config(self, structure_id, step, text):
        path = config_name(self.output_name, structure_id)
        offset = os.path.getsize(path) if os.path.isfile(path) else 0  # an earlier run's was set aside
        if self.restart and self.record and step == self.record.get('step') and \
                structure_id in (self.record.get('config_offsets') or {}):
            # the continuation saves step k again: the series already ends with that snapshot (kept at the
            # first save); keep it when it is the same text, else cut it (it was edited: an inexact restart)
            old = int(self.record['config_offsets'][structure_id])
            with open(path, 'rb') as f:
                f.seek(old)
                present = f.read()
            if present == text:
                return old
            _save_tail(path, old, aside_folder(self.output_name, 'replaced_step_%d' % step))
            offset = old
        _append_or_take_back(path, text)
        return offset


def _append_or_take_back(path, data):
    """Append ``data`` to ``path``; when that fails (full disk, file-size limit), cut off what was appended."""
    descriptor = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o666)
    try:
        start = os.fstat(descriptor).st_size
        view = memoryview(data)
        try:
            while view:  # unbuffered: nothing is left in a buffer to be written later
                view = view[os.write(descriptor, view):]
        except OSError as err:
            try:
                os.ftruncate(descriptor, start)
            except OSError:
                pass
            if err.filename is None:
                err.filename = path
            raise
    finally:
        os.close(descriptor)


def config_snapshot_end(path, offset):
    """Byte where the ``.config`` snapshot starting at ``offset`` ends (None when it is incomplete)."""
    with open(path, 'rb') as f:
        f.seek(offset)
        line = f.readline()
        try:
            count = int(line.split()[0])
        except (ValueError, IndexError):
            return None
        for _ in range(count):
            if not f.readline().endswith(b'\n'):
                return None
        return f.tell()
