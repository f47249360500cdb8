"""Output of a run, shared by every script that writes one (library floor 3).

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
"""
import base64
import hashlib
import io
import json
import os
import pickle
import shutil
import signal
import struct
import sys
import threading
import time

import numpy as np

from stochastic_forcing import generators
from utils import UserInputError, warn_user
from multi_bodies.files.snapshots import (append_config_snapshot, clones_name, config_name,  # noqa: F401
                                          format_clones, read_config_snapshot, truncate_config,
                                          write_clones_file)

RESTART_SUFFIX = '.restart'


# ------------------------------------------------------------------ set-up of the output folder
def prepare_output_directory(output_name, where='output_name'):
    """Create the folder of ``output_name`` and check that files can be written there.

    Raises UserInputError naming ``where`` (the option's file and line) when
    the folder cannot be created, is a file, or is read-only.
    """
    folder = os.path.dirname(output_name) or os.curdir
    if os.path.exists(folder) and not os.path.isdir(folder):
        raise UserInputError('%s: output_name %s needs the folder %s, but that is a file; choose another '
                             'output_name or remove the file' % (where, output_name, folder))
    try:
        os.makedirs(folder, exist_ok=True)
    except OSError as err:
        raise UserInputError('%s: cannot create the output folder %s (%s); choose another output_name'
                             % (where, folder, err.strerror or err))
    if not os.access(folder, os.W_OK | os.X_OK):
        raise UserInputError('%s: the output folder %s is not writable; choose another output_name or change '
                             'its permissions' % (where, folder))


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


# ------------------------------------------------------------------ run state as data (never code)
# The generator state and the restart records are written as JSON: dicts,
# lists, strings, ints (any size: PCG64 state words) and floats (repr, so they
# round-trip exactly); a numpy array or scalar becomes {"__ndarray__": dtype,
# shape, base64 of its bytes}, a tuple {"__tuple__": [...]}, a dict whose keys
# are not all strings {"__dict__": [[key, value], ...]}.  Reading them builds
# only these types: no file can make the reader run code.

STATE_FORMAT = 'rigid_multiblob run state'
STATE_VERSION = 1


def encode_state(value):
    """``value`` (nested dict/list/tuple of None, bool, int, float, str, numpy arrays and scalars) as JSON data.

    Raises TypeError for anything else (an object the restart cannot hold as data).
    """
    if value is None or isinstance(value, (bool, str)):
        return value
    if isinstance(value, (np.ndarray, np.generic)):
        array = np.asarray(value)
        if array.dtype.hasobject or array.dtype.fields is not None:
            raise TypeError('cannot save an array of dtype %s as run state' % array.dtype)
        return {'__ndarray__': {'dtype': array.dtype.str, 'shape': list(array.shape),
                                'scalar': isinstance(value, np.generic),
                                'data': base64.b64encode(np.ascontiguousarray(array).tobytes()).decode('ascii')}}
    if isinstance(value, int):  # also subclasses (IntEnum): their plain value
        return int(value)
    if isinstance(value, float):
        return float(value)
    if isinstance(value, tuple):
        return {'__tuple__': [encode_state(v) for v in value]}
    if isinstance(value, list):
        return [encode_state(v) for v in value]
    if isinstance(value, dict):
        if all(isinstance(k, str) and not k.startswith('__') for k in value):
            return {k: encode_state(v) for k, v in value.items()}
        return {'__dict__': [[encode_state(k), encode_state(v)] for k, v in value.items()]}
    raise TypeError('cannot save %s as run state (only numbers, strings, arrays, lists, tuples and dicts)'
                    % type(value).__name__)


def decode_state(data):
    """Inverse of ``encode_state`` (arrays come back writable, with their dtype and shape)."""
    if isinstance(data, list):
        return [decode_state(v) for v in data]
    if not isinstance(data, dict):
        return data
    if len(data) == 1:
        (key, inner), = data.items()
        if key == '__ndarray__':
            dtype = np.dtype(str(inner['dtype']))
            if dtype.hasobject or dtype.fields is not None:
                raise ValueError('run state holds an array of dtype %s' % dtype)
            shape = tuple(int(n) for n in inner['shape'])
            array = np.frombuffer(base64.b64decode(inner['data']), dtype=dtype).reshape(shape).copy()
            return array[()] if inner.get('scalar') else array
        if key == '__tuple__':
            return tuple(decode_state(v) for v in inner)
        if key == '__dict__':
            return {decode_state(k): decode_state(v) for k, v in inner}
    return {k: decode_state(v) for k, v in data.items()}


def state_to_bytes(value):
    """UTF-8 JSON text of ``encode_state(value)``."""
    return json.dumps(encode_state(value), separators=(',', ':')).encode('utf-8')


def state_from_bytes(data):
    """Inverse of ``state_to_bytes``; raises ValueError for text that is not such JSON."""
    return decode_state(json.loads(data.decode('utf-8')))


# ------------------------------------------------------------------ random generator
class _PublishedStateUnpickler(pickle.Unpickler):
    """Unpickler for the published ``numpy.random.RandomState().get_state()`` pickle, and nothing else.

    ``find_class`` admits only numpy's array reconstruction (``_reconstruct``,
    ``_frombuffer``, ``ndarray``), ``dtype`` and the latin-1 bytes of Python 3
    pickles: a pickle that names any other callable (the way a pickle runs
    code) is refused before anything is called.
    """

    _RECONSTRUCT = np.zeros(1).__reduce__()[0]        # numpy's _reconstruct (protocols 0 to 4)
    _FROMBUFFER = np.zeros(1).__reduce_ex__(5)[0]     # numpy's _frombuffer (protocol 5)

    @staticmethod
    def _latin1_bytes(text, encoding):
        """``_codecs.encode`` as Python 3 pickles (protocols 0-2) use it for bytes: latin-1 only."""
        if encoding not in ('latin1', 'latin-1') or not isinstance(text, str):
            raise pickle.UnpicklingError('_codecs.encode with %r is not part of a numpy random state' % encoding)
        return text.encode('latin1')

    ALLOWED = {('numpy.core.multiarray', '_reconstruct'): _RECONSTRUCT,
               ('numpy._core.multiarray', '_reconstruct'): _RECONSTRUCT,
               ('numpy.core.numeric', '_frombuffer'): _FROMBUFFER,
               ('numpy._core.numeric', '_frombuffer'): _FROMBUFFER,
               ('numpy', 'ndarray'): np.ndarray,
               ('numpy', 'dtype'): np.dtype,
               ('_codecs', 'encode'): _latin1_bytes}

    def find_class(self, module, name):
        try:
            return self.ALLOWED[(module, name)]
        except KeyError:
            raise pickle.UnpicklingError('%s.%s is not part of a numpy random state' % (module, name))


def read_published_state(data):
    """The published legacy state from pickle bytes: ('MT19937', keys uint32 (624,), pos, has_gauss, gauss).

    Raises ValueError when ``data`` is not exactly such a tuple (or names
    anything but numpy arrays and dtypes).
    """
    state = _PublishedStateUnpickler(io.BytesIO(data), encoding='latin1').load()
    if not (isinstance(state, tuple) and len(state) == 5 and state[0] in ('MT19937', b'MT19937')):
        raise ValueError('not a numpy RandomState state (MT19937, keys, pos, has_gauss, cached_gaussian)')
    keys = state[1]
    if not (isinstance(keys, np.ndarray) and keys.shape == (624,) and keys.dtype.kind in 'ui'):
        raise ValueError('the MT19937 keys are not 624 unsigned 32-bit integers')
    pos, has_gauss, gauss = state[2], state[3], state[4]
    if not (isinstance(pos, (int, np.integer)) and 0 <= int(pos) <= 624 and isinstance(has_gauss, (int, np.integer))
            and isinstance(gauss, (float, int, np.floating))):
        raise ValueError('pos, has_gauss or cached_gaussian of the MT19937 state is not a number in range')
    return ('MT19937', keys.astype(np.uint32), int(pos), int(has_gauss), float(gauss))


def read_random_state(path, where='random_state'):
    """The generator state in ``path`` as a dict (``bit_generator.state``), or the published tuple.

    A file of this package is JSON text (``save_random_state``); a file of
    the published code is a pickle of ``RandomState().get_state()``, read by
    the restricted ``_PublishedStateUnpickler`` and returned as that 5-tuple.
    Raises UserInputError (naming ``where``) for a missing file or anything else.
    """
    try:
        with open(path, 'rb') as f:
            data = f.read()
    except FileNotFoundError:
        raise UserInputError('%s: the random state file %s does not exist' % (where, path))
    except IsADirectoryError:
        raise UserInputError('%s: the random state file %s is a folder' % (where, path))
    except OSError as err:
        raise UserInputError('%s: cannot read the random state file %s (%s)' % (where, path, err.strerror or err))
    try:
        if data.lstrip()[:1] == b'{':
            document = json.loads(data.decode('utf-8'))
            if not (isinstance(document, dict) and document.get('format') == STATE_FORMAT):
                raise ValueError('JSON without "format": "%s"' % STATE_FORMAT)
            return decode_state(document['state'])
        return read_published_state(data)
    except Exception as err:  # any parse error: the file is refused, nothing in it was run
        raise UserInputError('%s: %s is not a random state file written by this package or the published code '
                             '(%s: %s); nothing in it was run or used. Give a .random_state file, or use seed '
                             'instead' % (where, path, type(err).__name__, err))


def load_random_state(path, where='random_state', generator='auto'):
    """The generator continuing the state in ``path`` (see ``read_random_state``).

    ``generator`` (the ``random_generator`` option): 'auto' gives the
    published generator (numpy's legacy ``RandomState`` on MT19937,
    :class:`stochastic_forcing.generators.PublishedGenerator`) for a
    published state or a saved state of that generator, so a published run
    repeats its draws, and a ``numpy.random.Generator`` otherwise;
    'published' and 'default' force one.  A published state loaded into the
    default generator draws other numbers than the published code (a notice
    says so).  Raises UserInputError (naming ``where``) for a file that holds
    no valid state.
    """
    state = read_random_state(path, where)
    if isinstance(state, tuple):
        if generator != 'default':
            return generators.PublishedGenerator.from_legacy_state(state)
        warn_user('%s: %s holds a published numpy RandomState state (MT19937, position %d); with random_generator '
                  'default the run uses an MT19937 Generator started at that state, whose draws differ from those '
                  'of the published code (random_generator published repeats them)' % (where, path, state[2]))
        state = {'bit_generator': 'MT19937', 'state': {'key': state[1], 'pos': state[2]}}
    name = state.get('bit_generator') if isinstance(state, dict) else None
    if not (isinstance(name, str) and isinstance(getattr(np.random, name, None), type)
            and issubclass(getattr(np.random, name), np.random.BitGenerator)):
        raise UserInputError('%s: %s does not hold a numpy random state; give a .random_state file, or use seed '
                             'instead' % (where, path))
    legacy = generator == 'published' or (generator == 'auto' and generators.is_legacy_state(state))
    try:
        if legacy:
            if name != 'MT19937':
                raise ValueError('the published generator runs on MT19937, the file holds a %s state' % name)
            rng = generators.PublishedGenerator()
            rng.bit_generator.state = state
            return rng
        bit_generator = getattr(np.random, name)()
        bit_generator.state = {'bit_generator': name, 'state': state['state']} if 'has_gauss' in state else state
    except Exception as err:
        raise UserInputError('%s: %s holds a damaged random state (%s)' % (where, path, err))
    return np.random.Generator(bit_generator)


def make_generator(options):
    """The run's generator (SPEC decision 7): from ``random_state`` if given, else seeded by ``seed``.

    ``random_generator`` chooses numpy's ``Generator`` ('default', PCG64) or
    the published code's legacy ``RandomState`` ('published'); 'auto' (the
    default) is 'published' for a published ``random_state`` and 'default'
    otherwise.  Without ``seed`` or ``random_state``, numpy seeds from the
    operating system (the state is still saved in ``.random_state``, so the
    run can be repeated).
    """
    kind = getattr(options, 'random_generator', 'auto') or 'auto'
    if options.random_state is not None:
        return load_random_state(options.random_state, options.where('random_state'), kind)
    if options.seed is not None and options.seed < 0:
        raise UserInputError('%s: seed must be a non-negative integer, got %d'
                             % (options.where('seed'), options.seed))
    return generators.make('published' if kind == 'published' else 'default', options.seed)


def save_random_state(path, rng):
    """Write ``rng.bit_generator.state`` to ``path`` as JSON (readable by ``load_random_state``)."""
    document = {'format': STATE_FORMAT, 'version': STATE_VERSION, 'kind': 'random_state',
                'state': encode_state(rng.bit_generator.state)}
    atomic_write(path, json.dumps(document, indent=1) + '\n')


# ------------------------------------------------------------------ files
def atomic_write(path, data, binary=False):
    """Write ``data`` to ``path`` through a temporary file, so a stop never leaves a truncated file."""
    part = path + '.part'
    with open(part, 'wb' if binary else 'w') as f:
        f.write(data)
    os.replace(part, path)


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
    Further counters follow in the same ``name = value`` form; ``extra_lines``
    are written last, as they are.
    """
    known = [key for key, _ in INFO_KEYS]
    lines = ['%-30s = %d' % (key, int(counters.get(key, 0))) for key in known]
    for key, value in counters.items():
        if key not in known:
            lines.append('%-30s = %s' % (key, value))
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


def restart_index(path, report=warn_user):
    """Headers of the records of ``path``: list of (step, payload start, record end) in file order.

    Reads only the headers.  A record cut by a hard stop, or bytes that are
    not a record header, end the list; ``report`` gets one message saying
    where.  Raises RestartFileError when ``path`` does not start with RESTART_MAGIC.
    """
    entries = []
    size = os.path.getsize(path)
    with open(path, 'rb') as f:
        if f.read(len(RESTART_MAGIC)) != RESTART_MAGIC:
            raise _not_a_restart_file(path)
        position = len(RESTART_MAGIC)
        while position < size:
            header = f.read(RECORD_HEADER.size)
            if len(header) < RECORD_HEADER.size:
                report('%s: the record at byte %d is cut short (a hard stop while saving?); it is ignored'
                       % (path, position))
                break
            tag, step, length, _ = RECORD_HEADER.unpack(header)
            start = position + RECORD_HEADER.size
            if tag != RECORD_TAG:
                report('%s: byte %d does not start a record (the file is damaged); it and what follows are '
                       'ignored' % (path, position))
                break
            if start + length > size:
                report('%s: the record of step %d at byte %d is cut short (a hard stop while saving?); it is '
                       'ignored' % (path, step, position))
                break
            entries.append((int(step), start, start + int(length)))
            position = start + int(length)
            f.seek(position)
    return entries


def read_restart_entry(path, entry):
    """The record of ``entry`` (from ``restart_index``) as a dict, or None when its checksum does not match."""
    step, start, end = entry
    with open(path, 'rb') as f:
        f.seek(start - RECORD_HEADER.size)
        _, _, _, digest = RECORD_HEADER.unpack(f.read(RECORD_HEADER.size))
        payload = f.read(end - start)
    if hashlib.sha256(payload).digest() != digest:
        return None
    record = state_from_bytes(payload)
    if not (isinstance(record, dict) and record.get('step') == step):
        return None
    return record


def last_valid_restart_record(path, report=warn_user):
    """(record, end offset) of the last record of ``path`` whose checksum matches; (None, start of records).

    Damaged records after it are reported and left out.
    """
    entries = restart_index(path, report)
    for entry in reversed(entries):
        record = read_restart_entry(path, entry)
        if record is not None:
            return record, entry[2]
        report('%s: the record of step %d fails its checksum (damaged); it is skipped' % (path, entry[0]))
    return None, len(RESTART_MAGIC)


class SnapshotWriter:
    """Writes the configuration of every structure type at the saved steps, and the restart records.

    Parameters
    ----------
    output_name : str
    save_clones : 'one_file_per_step' or 'one_file'
    types : list of (structure ID, number of bodies), in body order
    where : str, location of the save_clones option for messages
    restart : bool, this run continues an earlier one (``one_file`` series are appended to)
    restart_from : dict or None, the restart record of the step the run continues from; ``one_file``
        series are cut where that step's snapshot starts (it is written again, and later snapshots belong
        to the abandoned continuation), so the files equal those of an uninterrupted run
    """

    def __init__(self, output_name, save_clones, types, where='save_clones', restart=False, restart_from=None):
        if save_clones not in ('one_file_per_step', 'one_file'):
            raise UserInputError("%s: save_clones must be one_file_per_step or one_file, got '%s'"
                                 % (where, save_clones))
        self.output_name, self.save_clones, self.types = output_name, save_clones, list(types)
        self.restart_path = output_name + RESTART_SUFFIX
        self._started = restart
        if not restart and os.path.exists(self.restart_path):
            os.remove(self.restart_path)
        if restart and restart_from and save_clones == 'one_file':
            for structure_id, offset in (restart_from.get('config_offsets') or {}).items():
                truncate_config(config_name(output_name, structure_id), offset)

    def save(self, step, locations, orientations, restart_state=None):
        """Write snapshot ``step`` of all structures; then append its restart record.

        locations (Nb, 3), orientations (Nb, 4); ``restart_state``: what the
        run needs to continue exactly from this step (generator state, scheme
        history), nested dicts/lists/tuples of numbers, strings and arrays
        (``encode_state``).
        """
        offsets = {}
        start = 0
        for structure_id, count in self.types:
            block = slice(start, start + count)
            start += count
            if self.save_clones == 'one_file_per_step':
                write_clones_file(clones_name(self.output_name, structure_id, step), locations[block],
                                  orientations[block])
            else:
                offsets[structure_id] = append_config_snapshot(config_name(self.output_name, structure_id),
                                                               locations[block], orientations[block],
                                                               new_file=not self._started)
        self._started = True
        payload = state_to_bytes({'step': int(step), 'config_offsets': offsets, 'state': restart_state})
        header = RECORD_HEADER.pack(RECORD_TAG, int(step), len(payload), hashlib.sha256(payload).digest())
        new = not os.path.isfile(self.restart_path) or os.path.getsize(self.restart_path) == 0
        with open(self.restart_path, 'ab') as f:
            f.write((RESTART_MAGIC if new else b'') + header + payload)
            f.flush()


def read_restart_records(output_name):
    """All records of ``output_name.restart`` whose checksum matches, in the order written.

    A record cut by a hard stop ends the list; damaged ones are skipped; both with a message.
    """
    path = output_name + RESTART_SUFFIX
    if not os.path.isfile(path):
        return []
    records = []
    for entry in restart_index(path):
        record = read_restart_entry(path, entry)
        if record is None:
            warn_user('%s: the record of step %d fails its checksum (damaged); it is skipped' % (path, entry[0]))
        else:
            records.append(record)
    return records


def restart_record(output_name, step):
    """The last restart record saved at ``step``, or None when there is none.

    Only the headers are read, then that one record.  Raises UserInputError
    when the record of ``step`` fails its checksum (flipped bits) or the
    file is not a restart file of this package: a damaged record is never used.
    """
    path = output_name + RESTART_SUFFIX
    if not os.path.isfile(path):
        return None
    entries = [entry for entry in restart_index(path) if entry[0] == step]
    if not entries:
        return None
    record = read_restart_entry(path, entries[-1])
    if record is None:
        raise UserInputError('%s: the record of step %d fails its checksum (the file is damaged); restart from '
                             'another saved step, or remove the file to restart from the snapshot alone'
                             % (path, step))
    return record


# ------------------------------------------------------------------ ending a run
SIGNAL_EXIT_STATUS = {signal.SIGINT: 130, signal.SIGTERM: 143}


class StopRequest:
    """Context manager: SIGINT/SIGTERM set ``signal_number``; the loop stops after the step in progress.

    A second signal raises KeyboardInterrupt at once.  Handlers are only
    installed in the main thread (Dask workers run tasks in other threads).
    """

    def __init__(self):
        self.signal_number = None
        self._previous = {}

    def __enter__(self):
        if threading.current_thread() is threading.main_thread():
            for sig in SIGNAL_EXIT_STATUS:
                self._previous[sig] = signal.signal(sig, self._handle)
        return self

    def _handle(self, signal_number, frame):
        if self.signal_number is not None:  # a second signal: stop at once
            raise KeyboardInterrupt
        self.signal_number = signal_number

    def __exit__(self, *exc):
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)
        return False

    @property
    def exit_status(self):
        return SIGNAL_EXIT_STATUS.get(self.signal_number, 0)

    def stopped_line(self, step, last_saved=None):
        """'run stopped by SIGTERM at step k (last saved step s)'."""
        text = 'run stopped by %s at step %d' % (signal.Signals(self.signal_number).name, step)
        return text + (' (last saved step %d)' % last_saved if last_saved is not None else '')


class TimeLoop:
    """The loop over steps ``first .. last - 1`` of a dynamic or Monte Carlo run.

    ``run(save, advance, stop)`` calls ``save(k)`` before step k when k is a
    multiple of ``n_save`` (and after the last step when ``last`` is one),
    ``advance(k)`` for every step, and stops after the step in progress once
    ``stop.signal_number`` is set.  ``step`` is always the index of the step
    being (or next to be) run, so an error handler can name it.
    ``save_first=False`` skips the save at ``first`` (a restart whose
    snapshot the earlier run wrote).
    """

    def __init__(self, first, last, n_save, save_first=True):
        self.first, self.last, self.n_save, self.save_first = first, last, n_save, save_first
        self.step = first

    def run(self, save, advance, stop):
        for self.step in range(self.first, self.last):
            if self.step % self.n_save == 0 and (self.save_first or self.step != self.first):
                save(self.step)
            advance(self.step)
            if stop.signal_number is not None:
                self.step += 1
                return
        self.step = self.last
        if self.last > self.first and self.last % self.n_save == 0:
            save(self.last)

    @property
    def last_saved(self):
        """The last step saved before ``step`` (for the stop message)."""
        return ((self.step - 1) // self.n_save) * self.n_save if self.step > self.first else self.first


def finish_run(output_name, start, first, step, restart, write_info_lines, stopped_line=None):
    """End of a time loop, however it ended: ``.time`` (appended on a restart) and the last ``.info``.

    ``write_info_lines(extra_lines)`` writes the script's info file (``.info``,
    ``.MCMC_info``) with the given extra lines.
    """
    elapsed = time.perf_counter() - start
    append_time(output_name + '.time', elapsed, restart=restart,
                note=('restart segment, steps %d to %d' % (first, step)) if restart else None)
    write_info_lines([stopped_line] if stopped_line else [])


# ------------------------------------------------------------------ progress
class Progress:
    """Progress of a time loop: a tqdm bar on a terminal, plain lines in a log.

    A line is printed at every save (step, elapsed time, time per step,
    iterations per step, invalid configurations) and, in a log, at least
    every ``log_interval`` seconds between saves, with the estimated time
    left.  tqdm is used when it is installed and stdout is a terminal.
    """

    def __init__(self, scheme_name, first_step, last_step, log_interval=60.0, stream=None):
        self.scheme_name, self.first_step, self.last_step = scheme_name, first_step, last_step
        self.stream = sys.stdout if stream is None else stream
        self.log_interval = float(log_interval)
        self.start = self.mark = self.last_line = time.perf_counter()
        self.steps_since, self.iterations_since = 0, 0
        self.bar = None
        if getattr(self.stream, 'isatty', lambda: False)():
            try:
                from tqdm import tqdm
                self.bar = tqdm(total=max(0, last_step - first_step), unit='step', file=self.stream,
                                dynamic_ncols=True, leave=False)
            except ImportError:
                self.bar = None

    def _write(self, text):
        if self.bar is not None:
            self.bar.write(text, file=self.stream)
        else:
            print(text, file=self.stream, flush=True)

    def after_step(self, step, iterations=0, invalid=0):
        """Called after every step ``step`` (0-based index of the step just done)."""
        self.steps_since += 1
        self.iterations_since += iterations
        now = time.perf_counter()
        if self.bar is not None:
            self.bar.update(1)
            self.bar.set_postfix(invalid=invalid, refresh=False)
        elif now - self.last_line >= self.log_interval:
            done = step + 1 - self.first_step
            left = self.last_step - step - 1
            rate = done / max(now - self.start, 1e-12)
            self._write('step = %d of %d, elapsed %.1f s, %.3g steps/s, about %.0f s left, invalid configurations %d'
                        % (step + 1, self.last_step, now - self.start, rate, left / rate if rate > 0 else 0.0,
                           invalid))
            self.last_line = now

    def at_save(self, step, invalid, extra=''):
        """The published line at every save, with time per step and iterations per step."""
        now = time.perf_counter()
        per_step = (now - self.mark) / self.steps_since if self.steps_since else 0.0
        self._write('Integrator = %s, step = %d, invalid configurations %d, wallclock time = %.6g s, '
                    'time per step = %.4g s, iterations per step = %.3g%s'
                    % (self.scheme_name, step, invalid, now - self.start, per_step,
                       self.iterations_since / self.steps_since if self.steps_since else 0.0, extra))
        self.mark = self.last_line = now
        self.steps_since, self.iterations_since = 0, 0

    def close(self):
        if self.bar is not None:
            self.bar.close()
            self.bar = None
