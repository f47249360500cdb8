"""Restart records: their format, what they depend on, which saved step a restart can use (floor 6).

``output_name.restart`` is a magic line, then records appended one per saved
step, each a fixed header (tag, step, length, SHA-256 of the payload) and a
JSON payload (:mod:`multi_bodies.run.run_state`).  One record is found by
reading the headers only; a record cut by a hard stop or with flipped bits
is skipped or refused with a message.  A record carries the run's
identifier, the checksum of each snapshot it belongs to and a fingerprint
of what the dynamics depends on (structures in order, blobs, radii, slips,
the options of the table's ``dynamics`` column, the content of every file a
restart reads), so a restart is exact or refused with a message naming what
changed (``restart_inexact True`` forces it).  Every field of a record is
checked (``record_checks``) before anything in it is used.
"""
import hashlib
import json
import os
import struct
import time
import uuid

import numpy as np

from utils import UserInputError, warn_user
from multi_bodies.files.input_options import OPTION_TABLE
from multi_bodies.files.run_inputs import file_digest, restart_inputs
from multi_bodies.files.scheme_table import moves_rollers
from multi_bodies.files.snapshots import clones_name, config_name

from multi_bodies.run.record_checks import (configuration_problem, generator_problem, missing_fields,
                                            record_problem, run_problem)
from multi_bodies.run.run_state import RESTART_SUFFIX, RUN_SUFFIX, STATE_FORMAT, atomic_write, state_from_bytes


# ------------------------------------------------------------------ snapshots and restart records
# ``output_name.restart``: RESTART_MAGIC, then records appended one after the
# other.  A record is a header RECORD_HEADER (b'REC1', step int64, payload
# length uint64, SHA-256 of the payload) and the payload, UTF-8 JSON of
# {'step', 'config_offsets', 'state'} (``state_to_bytes``).  Finding the
# record of one step reads the headers only (seeking over payloads); a
# record's checksum is checked before it is used.
RESTART_MAGIC = b'RMB-RESTART 1\n'
RECORD_HEADER = struct.Struct('>4sqQ32s')
RECORD_TAG = b'REC1'


class RestartFileError(UserInputError):
    """A ``.restart`` file that is not one of this package (an earlier pickle-based one, or anything else)."""


def _not_a_restart_file(path):
    return RestartFileError(
        '%s is not a restart file of this version (an older .restart was a Python pickle, which is not read '
        'because loading a pickle can run code); nothing in it was used. Rename or remove it to restart from '
        'the snapshot alone (the run continues without the scheme history and generator state of that step)'
        % path)


# The payload of every record this package writes holds the step, the run identifier, the snapshot checksums,
# the fingerprint and the run state: hundreds of bytes.  A shorter one is damage or a forgery: the walk stops
# there (a file of a million tiny records is refused at its first, not after a million reads).
MIN_RECORD_PAYLOAD = 96


def restart_index(path, report=warn_user):
    """Headers of the records of ``path``: list of (step, payload start, record end) in file order.

    Reads only the headers (through a memory map, without reading the payloads).  A record cut by a hard stop,
    bytes that are not a record header, or a record shorter than any record (``MIN_RECORD_PAYLOAD``) end the list;
    ``report`` gets one message saying where.  Raises RestartFileError when ``path`` does not start with
    RESTART_MAGIC.
    """
    import mmap
    entries = []
    size = os.path.getsize(path)
    with open(path, 'rb') as f:
        if f.read(len(RESTART_MAGIC)) != RESTART_MAGIC:
            raise _not_a_restart_file(path)
        if size <= len(RESTART_MAGIC):
            return entries
        with mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as data:
            position, header_size, unpack = len(RESTART_MAGIC), RECORD_HEADER.size, RECORD_HEADER.unpack_from
            while position < size:
                if position + header_size > size:
                    report('%s: the record at byte %d is cut short (a hard stop while saving?); it is ignored'
                           % (path, position))
                    break
                tag, step, length, _ = unpack(data, position)
                start = position + header_size
                if tag != RECORD_TAG:
                    report('%s: byte %d does not start a record (the file is damaged); it and what follows are '
                           'ignored' % (path, position))
                    break
                if start + length > size:
                    report('%s: the record of step %d at byte %d is cut short (a hard stop while saving?); it is '
                           'ignored' % (path, step, position))
                    break
                if length < MIN_RECORD_PAYLOAD:
                    report('%s: the record of step %d at byte %d holds %d bytes, fewer than any record (%d): the file '
                           'is damaged or not written by this package; it and what follows are ignored'
                           % (path, step, position, length, MIN_RECORD_PAYLOAD))
                    break
                position = start + length
                entries.append((step, start, position))
    return entries


def read_restart_entry(path, entry, problems=None):
    """The record of ``entry`` (from ``restart_index``) as a dict, or None when it cannot be used.

    None when its checksum does not match (damage) or when a field is not what a record holds (an edit with the
    checksum recomputed: ``record_checks.record_problem``); then ``problems`` (a list, when given) gets the
    line saying which field.  Nothing of a record is used before every field passed.
    """
    step, start, end = entry
    with open(path, 'rb') as f:
        f.seek(start - RECORD_HEADER.size)
        _, _, _, digest = RECORD_HEADER.unpack(f.read(RECORD_HEADER.size))
        payload = f.read(end - start)
    if hashlib.sha256(payload).digest() != digest:
        return None
    try:
        record = state_from_bytes(payload)
        problem = record_problem(record, step)
    except (ValueError, TypeError, KeyError, AttributeError, RecursionError, MemoryError) as err:
        record, problem = None, 'the payload is not the data of a record (%s)' % type(err).__name__
    if problem is not None:
        if problems is not None:
            problems.append(problem)
        return None
    return record


def _unusable(path, step, problems):
    """Why the record of ``step`` is not used: its field (``problems``) or its checksum."""
    if problems:
        return ('%s: the record of step %d is not a valid record (%s: edited, or not written by this package)'
                % (path, step, problems[-1]))
    return '%s: the record of step %d fails its checksum (damaged)' % (path, step)


def last_valid_restart_record(path, report=warn_user):
    """(record, end offset) of the last record of ``path`` whose checksum matches; (None, start of records).

    Damaged records after it are reported and left out.
    """
    entries = restart_index(path, report)
    for entry in reversed(entries):
        problems = []
        record = read_restart_entry(path, entry, problems)
        if record is not None:
            return record, entry[2]
        report('%s; it is skipped' % _unusable(path, entry[0], problems))
    return None, len(RESTART_MAGIC)


# ------------------------------------------------------------------ what a record depends on
# Options whose change makes a continuation differ from the uninterrupted run: the rows of the option table whose
# ``dynamics`` column is True (the record's fingerprint holds their values; a restart with another value is
# refused unless restart_inexact is set).  The others (n_steps, n_save, outputs, seed, ...) may change.
DYNAMICS_OPTIONS = tuple(name for name, option in OPTION_TABLE.items() if option.dynamics)
FINGERPRINT_VERSION = 'the options of the table and the content of the input files (2)'
FORCE_OPTION = 'restart_inexact'
FORCE_HINT = ('set "%s True" in the input file to continue anyway (the continuation then differs from an '
              'uninterrupted run)' % FORCE_OPTION)
KILL_HOOK = 'RMB_TEST_KILL_BETWEEN_SNAPSHOT_AND_RECORD'  # test hook: SIGKILL after snapshot k, before its record


def _digest(data):
    return hashlib.sha256(data).hexdigest()


def run_fingerprint(options, types, bodies, directory=None):
    """What a restart record depends on, as {name: text}: structures in order with the kind of their line, their
    blobs, radii, slips, the options of the table that change the dynamics, the content of every file a restart
    reads (and of the data files the override sources declare, ``run_inputs.declared_data_files``).

    types: list of (structure ID, number of bodies) in body order; bodies: the Body list (``reference_configuration``
    (n, 3), ``blob_radius``, ``slip_reference`` (n, 3) or None); directory: the run directory (default the current
    one), whose override sources are covered.  Two runs with equal fingerprints compute the same trajectory from
    the same snapshot, generator and scheme history.
    """
    kinds = line_kinds(options)
    found = {'fingerprint': FINGERPRINT_VERSION,
             'structures': ', '.join('%s x %d%s' % (name, count, kind) for (name, count), kind
                                     in zip(types, kinds + [''] * (len(types) - len(kinds))))}
    start = 0
    for name, count in types:
        if count:
            found.update(_body_fingerprint(name, bodies[start]))
        start += count
    for name in DYNAMICS_OPTIONS:
        found[name] = _option_text(getattr(options, name, None))
    for kind, name, path in restart_inputs(options, os.getcwd() if directory is None else directory):
        found['%s file %s' % (kind, name)] = file_digest(path)
    return found


def line_kinds(options):
    """Per line of bodies, in body order: '' for a ``structure`` line of free bodies, ' (prescribed velocity)',
    ' (obstacle)', ' (articulated)' (the kind changes the dynamics as much as the bodies do)."""
    return ([' (prescribed velocity)' if getattr(spec, 'velocity_file', None) else '' for spec in options.structures]
            + [' (obstacle)'] * len(options.obstacles) + [' (articulated)'] * len(options.articulated))


def _body_fingerprint(name, body):
    """Blobs, radii and slip of the first body of structure ``name``."""
    found = {}
    blobs = np.ascontiguousarray(body.reference_configuration, dtype=float)
    found['blobs of %s' % name] = '%d blobs, sha256 %s' % (blobs.shape[0], _digest(blobs.tobytes())[:16])
    radii = np.ascontiguousarray(getattr(body, 'blob_radii', body.blob_radius), dtype=float)
    found['blob radius of %s' % name] = ('%r' % float(radii) if radii.ndim == 0 else
                                         'sha256 %s' % _digest(radii.tobytes())[:16])
    slip = getattr(body, 'slip_reference', None)
    if slip is not None:
        found['slip of %s' % name] = 'sha256 %s' % _digest(np.ascontiguousarray(slip, float).tobytes())[:16]
    return found


def _option_text(value):
    return repr(tuple(value) if isinstance(value, (list, np.ndarray)) else value)


def fingerprint_changes(recorded, current):
    """'what changed' lines between a record's fingerprint and this run's (empty when they agree).

    An option of the table that a record lacks (the option is newer than the record) counts as its default: the
    version that wrote the record ran as the default does."""
    changes = []
    for name in list(recorded) + [n for n in current if n not in recorded]:
        if name not in recorded and name in DYNAMICS_OPTIONS \
                and current.get(name) == _option_text(OPTION_TABLE[name].default):
            continue
        if recorded.get(name) != current.get(name):
            changes.append('%s: was %s, now %s' % (name, recorded.get(name, '(absent)'), current.get(name, '(absent)')))
    return changes


def new_run_id():
    """A fresh run identifier (16 hex digits): carried by every restart record and ``output_name.run``."""
    return uuid.uuid4().hex[:16]


def write_run_file(output_name, run_id, first_step):
    """``output_name.run``: the run identifier and its segments (JSON; a side file, the snapshot formats stay the
    published ones)."""
    path = output_name + RUN_SUFFIX
    segments = []
    try:
        with open(path) as f:
            document = json.load(f)
        if document.get('run_id') == run_id:
            segments = list(document.get('segments', []))
    except (OSError, ValueError, AttributeError):
        pass
    from multi_bodies.run.output_lock import holder_record  # host, pid, start: a new writer checks it has gone
    segments.append(dict(holder_record(), first_step=int(first_step)))
    atomic_write(path, json.dumps({'format': STATE_FORMAT, 'kind': 'run', 'run_id': run_id,
                                   'segments': segments}, indent=1) + '\n')


def read_run_id(output_name):
    """The run identifier of ``output_name.run`` (None when absent or unreadable)."""
    try:
        with open(output_name + RUN_SUFFIX) as f:
            return json.load(f).get('run_id')
    except (OSError, ValueError, AttributeError):
        return None


def stop_snapshot_path(output_name, record, structure_id):
    """Path of the ``.clones`` file a stop record (``record['stop_files']``) names for ``structure_id``."""
    name = (record.get('stop_files') or {})[structure_id]
    if os.path.isabs(name) or '..' in name.replace('\\', '/').split('/'):
        raise UserInputError('%s%s: the record of step %d names %r, not a file of the run folder'
                             % (output_name, RESTART_SUFFIX, record['step'], name))
    return os.path.join(os.path.dirname(output_name), name)


def snapshot_bytes(output_name, save_clones, structure_id, record):
    """The bytes of the snapshot of ``structure_id`` that ``record`` belongs to (None when absent)."""
    step = record['step']
    stop_files = record.get('stop_files') or {}
    if structure_id in stop_files:
        path = stop_snapshot_path(output_name, record, structure_id)
    elif save_clones == 'one_file' and not record.get('stop'):
        offsets = record.get('config_offsets') or {}
        if structure_id not in offsets:
            return None
        path = config_name(output_name, structure_id)
        length = ((record.get('snapshots') or {}).get(structure_id) or [None, None])[1]
        try:
            offset = int(offsets[structure_id])
            if length is None or offset + int(length) > os.path.getsize(path):  # beyond the file: not its snapshot
                return None
            with open(path, 'rb') as f:
                f.seek(offset)
                return f.read(int(length))
        except OSError:
            return None
    else:
        path = clones_name(output_name, structure_id, step)
    try:
        with open(path, 'rb') as f:
            return f.read()
    except OSError:
        return None


def snapshot_mismatches(output_name, save_clones, types, record):
    """IDs of ``types`` whose snapshot is missing or differs from the checksum ``record`` holds for it.

    A record of an earlier version (no checksums) gives no mismatch.
    """
    digests = record.get('snapshots')
    if not digests:
        return []
    bad = []
    for structure_id, _ in types:
        data = snapshot_bytes(output_name, save_clones, structure_id, record)
        if structure_id not in digests or data is None or _digest(data) != digests[structure_id][0]:
            bad.append(structure_id)
    return bad


LAST_PAIRS_EXAMINED = 64  # records read back from the end to find the last complete pair (a restart message)


def last_complete_pair(output_name, save_clones, types, report=warn_user):
    """(record, end) of the last record of ``output_name.restart`` whose snapshot is complete and unchanged.

    (None, None) when there is none among the last ``LAST_PAIRS_EXAMINED`` records (a run's last complete pair
    is one of its last two records; reading further back would let a file of many damaged records cost minutes).
    Records passed over are reported.
    """
    path = output_name + RESTART_SUFFIX
    if not os.path.isfile(path):
        return None, None
    for entry in reversed(restart_index(path, report)[-LAST_PAIRS_EXAMINED:]):
        problems = []
        record = read_restart_entry(path, entry, problems)
        if record is None:
            report('%s; it is skipped' % _unusable(path, entry[0], problems))
            continue
        bad = snapshot_mismatches(output_name, save_clones, types, record)
        if bad:
            report('%s: the snapshot of step %d of %s is missing or differs from its record; step %d is skipped'
                   % (path, entry[0], ', '.join(bad), entry[0]))
            continue
        return record, entry[2]
    return None, None


def last_complete_step_text(output_name, save_clones, ids):
    """' (the last step with a complete snapshot and record is k)' for a refusal, or '' when there is none."""
    pair, _ = last_complete_pair(output_name, save_clones, [(name, 0) for name in ids], report=lambda text: None)
    return ' (the last step with a complete snapshot and record is %d)' % pair['step'] if pair else ''


def check_restart(options, record, types, fingerprint, report=warn_user, program='dynamics', configuration=None,
                  num_blobs=None):
    """Decide whether a restart from ``initial_step`` is exact; returns True to use ``record``'s state.

    Refuses (UserInputError saying why and how to force) a restart without a record of that step, one whose
    snapshot differs from its record (edited, or a lone snapshot of a stop between snapshot and record), one whose
    record lacks what the restart of ``program`` ('dynamics' or 'mcmc') needs or does not fit the run (structures,
    bodies, shapes, generator; the record's configuration not that of ``configuration``, the snapshot's
    (locations, orientations) as read; ``num_blobs``: the run's blobs, for the shapes of per-blob history), and
    one whose fingerprint (structures, blobs, radii, options) differs from this run's.  With ``restart_inexact True``
    each of these is a warning instead; the record's generator and history are then used only when the
    snapshot is the record's.
    """
    k = options.initial_step
    force = bool(getattr(options, FORCE_OPTION, False))
    where = options.where('initial_step')
    path = options.output_name + RESTART_SUFFIX
    problems, use_record = [], record is not None
    if record is None:
        last = last_complete_step_text(options.output_name, options.save_clones, [name for name, _ in types])
        problems.append('%s has no restart record of step %d (none complete)%s, so the generator state and the scheme history '
                        'of that step are unknown (a run stopped between writing the snapshot and its record, or a '
                        'snapshot of another program)' % (path, k, last))
    else:
        bad = snapshot_mismatches(options.output_name, options.save_clones, types, record)
        if bad:
            problems.append('the snapshot of step %d of %s differs from the one its record in %s was written with '
                            '(the file was edited or replaced)' % (k, ', '.join(bad), path))
            use_record = False
        unfit = (missing_fields(record, types, program)
                 or run_problem(record, types, num_blobs, rollers=moves_rollers(getattr(options, 'scheme', None)))
                 or generator_problem(options, (record.get('state') or {}).get('rng'))
                 or (configuration_problem(record, *configuration) if configuration is not None and not bad
                     else None))
        if unfit:
            problems.append('the record of step %d in %s does not fit this run: %s' % (k, path, unfit))
            use_record = False
        recorded = record.get('fingerprint')
        if recorded:
            changes = fingerprint_changes(recorded, fingerprint)
            if changes:
                problems.append('the run differs from the one that wrote the record of step %d: %s'
                                % (k, '; '.join(changes)))
    if not problems:
        return use_record
    if not force:
        raise UserInputError('%s: initial_step %d cannot restart exactly: %s. Restart from another step, or %s'
                             % (where, k, ' and '.join(problems), FORCE_HINT))
    report('%s: inexact restart from step %d (%s True): %s; %s' % (
        where, k, FORCE_OPTION, ' and '.join(problems),
        'the record\'s generator and scheme history are used' if use_record else
        'the generator starts from seed/random_state and multistep schemes restart with one first-order step'))
    return use_record


def recorded_snapshots(output_name, save_clones, structure_id):
    """What of a series has restart records, for readers that take the current run's steps only.

    ``one_file_per_step``: the set of steps with a record; ``one_file``: the number of ``.config`` frames of
    ``structure_id`` that have one (frames after them were written without their record).  None when the run
    has no readable ``.restart`` (a run of the published code): then every snapshot is taken.
    """
    path = output_name + RESTART_SUFFIX
    if not os.path.isfile(path):
        return None
    quiet = lambda text: None  # noqa: E731
    try:
        entries = restart_index(path, quiet)
    except (UserInputError, OSError):
        return None
    if save_clones != 'one_file':
        return {step for step, _, _ in entries}
    offsets = set()
    for entry in entries:
        record = read_restart_entry(path, entry)
        if record is not None and structure_id in (record.get('config_offsets') or {}):
            offsets.add(int(record['config_offsets'][structure_id]))
    return len(offsets)


def find_restart_record(output_name, step):
    """(record, end byte) of the last record of ``step`` in ``output_name.restart``; (None, None) when none.

    Raises UserInputError as ``restart_record`` does.
    """
    path = output_name + RESTART_SUFFIX
    if os.path.isdir(path):
        raise UserInputError('%s is a folder, not a restart file; rename or remove it' % path)
    if not os.path.isfile(path):
        return None, None
    entries = [entry for entry in restart_index(path) if entry[0] == step]
    if not entries:
        return None, None
    problems = []
    record = read_restart_entry(path, entries[-1], problems)
    if record is None:
        raise UserInputError('%s; restart from another saved step, or remove the file to restart from the snapshot '
                             'alone' % _unusable(path, step, problems))
    return record, entries[-1][2]


def read_restart_records(output_name):
    """All records of ``output_name.restart`` whose checksum matches, in the order written.

    A record cut by a hard stop ends the list; damaged ones are skipped; both with a message.
    """
    path = output_name + RESTART_SUFFIX
    if not os.path.isfile(path):
        return []
    records = []
    for entry in restart_index(path):
        problems = []
        record = read_restart_entry(path, entry, problems)
        if record is None:
            warn_user('%s; it is skipped' % _unusable(path, entry[0], problems))
        else:
            records.append(record)
    return records


def restart_record(output_name, step):
    """The last restart record saved at ``step``, or None when there is none.

    Only the headers are read, then that one record.  Raises UserInputError
    when the record of ``step`` fails its checksum (flipped bits) or the
    file is not a restart file of this package: a damaged record is never used.
    """
    return find_restart_record(output_name, step)[0]
