"""Run state as data, never code: the encoding of saved state, the random generator, file primitives (floor 6).

Everything a run saves to continue exactly (the generator's state, scheme
histories, counters) is written as JSON text with arrays as base64 of their
bytes (:func:`encode_state`), so reading a ``.random_state`` or a restart
record never runs code.  A published ``.random_state`` (a pickled numpy
``RandomState`` state tuple) is read by a restricted unpickler that admits
only arrays and dtypes.  Also here: the output suffixes and the atomic file
write that the restart records and the run output share.
"""
import base64
import io
import json
import os
import pickle

import numpy as np

from stochastic_forcing import generators
from utils import UserInputError, warn_user


RESTART_SUFFIX = '.restart'
RUN_SUFFIX = '.run'
STOP_SUFFIX = '.stopped'
ASIDE_SUFFIX = '.set_aside'


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
# What a published state holds at most: 624 key words of 8 bytes (int64 on some platforms), a few scalars.
PUBLISHED_STATE_WORDS = 624
PUBLISHED_STATE_BYTES = 64 * 1024      # a pickle of protocol 0 writes the 2,496 key bytes as text: a few KiB
PUBLISHED_MEMO_ENTRIES = 64            # the state pickle memoises a handful of objects
_SAFE_KINDS = 'uifb'                   # array dtypes of a state: integers, floats, booleans (never objects)


# The state of MT19937 is 19,937 bits: the top bit of key word 0 and the 32 bits of words 1 .. 623 (the other 31
# bits of word 0 never reach an output; Matsumoto and Nishimura, ACM TOMACS 8, 3, 1998).  All of them 0 is the
# fixed point of the recurrence: the generator draws zeros for ever (the legacy Gaussian then loops for ever in
# compiled code, deaf to signals).  A state with few bits set (or few unset) leaves that point only slowly, drawing
# far from random numbers for thousands of draws; a seeded generator's state has about half its bits set
# (19,937 fair bits: 9,968 +- 71), so a state outside a quarter to three quarters set was made by hand.
MT19937_STATE_BITS = 19937
MT19937_BIT_FRACTION = (0.25, 0.75)


def mt19937_key_problem(key, pos):
    """None when ``key`` (624 words) and ``pos`` are a state a seeded MT19937 can be in; else one line saying why
    not (a degenerate state: all state bits 0, or far too few or too many set; words or position out of range)."""
    if not (isinstance(key, np.ndarray) and key.shape == (PUBLISHED_STATE_WORDS,) and key.dtype.kind in 'ui'):
        return 'the MT19937 key is not 624 integers'
    if int(key.min()) < 0 or int(key.max()) > 0xFFFFFFFF:
        return 'an MT19937 key word is outside 0 .. 2**32 - 1'
    if not (isinstance(pos, (int, np.integer)) and not isinstance(pos, bool) and 0 <= int(pos) <= 624):
        return 'the position of the MT19937 state is not an integer between 0 and 624'
    words = key.astype(np.uint32)
    bits = int(np.unpackbits(words[1:].view(np.uint8)).sum()) + int(words[0] >> np.uint32(31))
    if bits == 0:
        return ('every bit of the MT19937 state is 0 (the top bit of key 0 and keys 1 .. 623): a generator that '
                'draws only zeros')
    low, high = (int(f * MT19937_STATE_BITS) for f in MT19937_BIT_FRACTION)
    if not low <= bits <= high:
        return ('the MT19937 state has %d of its %d bits set, where a seeded generator has about half (%d to %d '
                'accepted): a degenerate state whose draws are far from random'
                % (bits, MT19937_STATE_BITS, low, high))
    return None


def generator_state_problem(state):
    """None for a ``bit_generator.state`` dict that numpy's bit generator may take as a run's generator; else one
    line (an MT19937 state is checked by :func:`mt19937_key_problem`)."""
    if not isinstance(state, dict):
        return 'the generator state is not a table'
    if state.get('bit_generator') == 'MT19937':
        inner = state.get('state')
        if not isinstance(inner, dict):
            return 'the MT19937 state holds no key and position'
        return mt19937_key_problem(inner.get('key'), inner.get('pos'))
    return None


def _check_pickle_opcodes(data):
    """Read the opcodes of ``data`` without running any: refuse sizes a published state never has.

    The memo index of PUT/BINPUT/LONG_BINPUT sizes a table the unpickler allocates, so it is bounded here,
    before the unpickler sees the bytes.
    """
    import pickletools
    if len(data) > PUBLISHED_STATE_BYTES:
        raise ValueError('%d bytes, more than a published random state pickle holds (at most %d)'
                         % (len(data), PUBLISHED_STATE_BYTES))
    for opcode, argument, _ in pickletools.genops(data):
        if opcode.name in ('PUT', 'BINPUT', 'LONG_BINPUT', 'GET', 'BINGET', 'LONG_BINGET') and \
                not (isinstance(argument, int) and 0 <= argument < PUBLISHED_MEMO_ENTRIES):
            raise ValueError('memo index %r, beyond what a random state pickle uses' % (argument,))
        if opcode.name in ('PERSID', 'BINPERSID', 'EXT1', 'EXT2', 'EXT4', 'INST', 'OBJ', 'NEWOBJ', 'NEWOBJ_EX'):
            raise ValueError('opcode %s is not part of a numpy random state' % opcode.name)


def _checked_dtype(dtype):
    """``dtype`` when an array of a random state may have it: integers, floats or booleans of at most 8 bytes."""
    dtype = np.dtype(dtype)
    if dtype.hasobject or dtype.fields is not None or dtype.subdtype is not None or dtype.kind not in _SAFE_KINDS \
            or dtype.itemsize > 8:
        raise pickle.UnpicklingError('an array of dtype %s is not part of a numpy random state' % dtype)
    return dtype


def _checked_shape(shape):
    """``shape`` (a tuple of non-negative ints) when it holds at most PUBLISHED_STATE_WORDS values."""
    shape = (shape,) if isinstance(shape, (int, np.integer)) else shape
    if not (isinstance(shape, tuple) and len(shape) <= 1 and
            all(isinstance(n, (int, np.integer)) and 0 <= n <= PUBLISHED_STATE_WORDS for n in shape)):
        raise pickle.UnpicklingError('an array of shape %r is not part of a numpy random state' % (shape,))
    return tuple(int(n) for n in shape)


class _StateArray(np.ndarray):
    """The array the restricted unpickler builds: its pickled state is checked before numpy allocates."""

    def __setstate__(self, state):
        if not (isinstance(state, tuple) and len(state) == 5):
            raise pickle.UnpicklingError('malformed array state in a random state pickle')
        version, shape, dtype, fortran, data = state
        shape, dtype = _checked_shape(shape), _checked_dtype(dtype)
        count = int(np.prod(shape)) if shape else 1
        if isinstance(data, str):  # a Python 2 pickle read with encoding latin1
            data = data.encode('latin1') if len(data) <= count * dtype.itemsize else None
        if not isinstance(data, (bytes, bytearray)) or len(data) != count * dtype.itemsize \
                or not isinstance(version, int):
            raise pickle.UnpicklingError('the array data of a random state pickle does not match its shape')
        super().__setstate__((version, shape, dtype, bool(fortran), bytes(data)))


def _reconstruct(cls, shape, dtype):
    """numpy's ``_reconstruct`` for an ndarray of a random state (any other class, shape or dtype refused)."""
    if cls not in (np.ndarray, _StateArray, _ndarray):
        raise pickle.UnpicklingError('%r is not part of a numpy random state' % (cls,))
    return _StateArray(_checked_shape(shape), _checked_dtype(dtype) if not isinstance(dtype, bytes) else 'b')


def _frombuffer(buffer, dtype, shape, order):
    """numpy's ``_frombuffer`` (protocol 5) for the bytes of one random-state array, checked first."""
    shape, dtype = _checked_shape(shape), _checked_dtype(dtype)
    count = int(np.prod(shape)) if shape else 1
    data = bytes(memoryview(buffer)) if isinstance(buffer, (bytes, bytearray, memoryview, pickle.PickleBuffer)) \
        else None
    if data is None or len(data) != count * dtype.itemsize:
        raise pickle.UnpicklingError('the array data of a random state pickle does not match its shape')
    return np.frombuffer(data, dtype=dtype).reshape(shape, order='F' if order == 'F' else 'C').copy()


def _ndarray(shape, dtype=float, *args, **kwargs):
    """``numpy.ndarray(shape, dtype)`` as a pickle may call it, bounded (no buffer, no object dtype)."""
    if args or kwargs:
        raise pickle.UnpicklingError('numpy.ndarray with a buffer is not part of a numpy random state')
    return _StateArray(_checked_shape(shape), _checked_dtype(dtype))


def _dtype(name, align=False, copy=False):
    """``numpy.dtype`` as a pickle calls it; only integer, float and boolean dtypes."""
    if not isinstance(name, str) or not isinstance(align, bool) or not isinstance(copy, bool):
        raise pickle.UnpicklingError('numpy.dtype(%r) is not part of a numpy random state' % (name,))
    return _checked_dtype(name)


class _PublishedStateUnpickler(pickle.Unpickler):
    """Unpickler for the published ``numpy.random.RandomState().get_state()`` pickle, and nothing else.

    ``find_class`` admits only numpy's array reconstruction (``_reconstruct``,
    ``_frombuffer``, ``ndarray``), ``dtype`` and the latin-1 bytes of Python 3
    pickles, each replaced by a bounded version: a pickle that names any
    other callable (the way a pickle runs code) is refused before anything is
    called, and arrays of more than 624 values, of object or structured dtype,
    or whose data does not match their shape are refused before numpy
    allocates them.  ``read_published_state`` checks the opcodes (memo
    indices, total size) before this class reads them.
    """

    @staticmethod
    def _latin1_bytes(text, encoding):
        """``_codecs.encode`` as Python 3 pickles (protocols 0-2) use it for bytes: latin-1 only."""
        if encoding not in ('latin1', 'latin-1') or not isinstance(text, str):
            raise pickle.UnpicklingError('_codecs.encode with %r is not part of a numpy random state' % encoding)
        if len(text) > PUBLISHED_STATE_WORDS * 8:
            raise pickle.UnpicklingError('a byte string of %d characters is not part of a numpy random state'
                                         % len(text))
        return text.encode('latin1')

    ALLOWED = {('numpy.core.multiarray', '_reconstruct'): _reconstruct,
               ('numpy._core.multiarray', '_reconstruct'): _reconstruct,
               ('numpy.core.numeric', '_frombuffer'): _frombuffer,
               ('numpy._core.numeric', '_frombuffer'): _frombuffer,
               ('numpy', 'ndarray'): _ndarray,
               ('numpy', 'dtype'): _dtype,
               ('_codecs', 'encode'): _latin1_bytes}

    def find_class(self, module, name):
        try:
            return self.ALLOWED[(module, name)]
        except KeyError:
            raise pickle.UnpicklingError('%s.%s is not part of a numpy random state' % (module, name))


def _plain(value):
    """A state entry as a plain value: a 0-d or one-element array becomes its number."""
    if isinstance(value, np.ndarray) and value.size == 1 and value.ndim <= 1:
        return value.reshape(()).item()
    return value.item() if isinstance(value, np.generic) else value


def read_published_state(data):
    """The published legacy state from pickle bytes: ('MT19937', keys uint32 (624,), pos, has_gauss, gauss).

    Raises ValueError when ``data`` is not exactly such a tuple (or names
    anything but numpy arrays and dtypes), and for a degenerate state: keys
    all zero or outside 0 .. 2**32 - 1, ``pos`` outside 0 .. 624,
    ``has_gauss`` not 0 or 1, a cached Gaussian that is not finite.
    """
    _check_pickle_opcodes(data)
    state = _PublishedStateUnpickler(io.BytesIO(data), encoding='latin1').load()
    if not (isinstance(state, tuple) and len(state) == 5 and state[0] in ('MT19937', b'MT19937')):
        raise ValueError('not a numpy RandomState state (MT19937, keys, pos, has_gauss, cached_gaussian)')
    keys = state[1]
    pos, has_gauss, gauss = (_plain(v) for v in state[2:])
    problem = mt19937_key_problem(keys, pos)
    if problem is not None:
        raise ValueError(problem)
    if not (isinstance(has_gauss, int) and has_gauss in (0, 1)):
        raise ValueError('has_gauss of the MT19937 state is not 0 or 1')
    if not (isinstance(gauss, (float, int)) and np.isfinite(gauss)):
        raise ValueError('the cached Gaussian of the MT19937 state is not a finite number')
    return ('MT19937', np.array(keys, dtype=np.uint32), int(pos), int(has_gauss), float(gauss))


def read_random_state(path, where='random_state'):
    """The generator state in ``path`` as a dict (``bit_generator.state``), or the published tuple.

    A file of this package is JSON text (``save_random_state``); a file of
    the published code is a pickle of ``RandomState().get_state()``, read by
    the restricted ``_PublishedStateUnpickler`` and returned as that 5-tuple.
    Raises UserInputError (naming ``where``) for a missing file or anything else.
    """
    import stat
    try:
        if os.path.exists(path) and not stat.S_ISREG(os.stat(path).st_mode) and not os.path.isdir(path):
            raise UserInputError('%s: %s is not a regular file (a pipe or device would be read forever); give a '
                                 '.random_state file' % (where, path))
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
    problem = generator_state_problem(state)
    if problem is not None:
        raise UserInputError('%s: %s holds a degenerate random state (%s); nothing in it was used. Give a '
                             '.random_state file a run wrote, or use seed instead' % (where, path, problem))
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
    kind = options.random_generator or 'auto'
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
    try:
        with open(part, 'wb' if binary else 'w') as f:
            f.write(data)
        os.replace(part, path)
    except BaseException as err:
        _remove_quietly(part)
        if isinstance(err, OSError) and err.filename is None:  # a write on a full disk names no file
            err.filename = path
        raise


def _remove_quietly(path):
    try:
        os.remove(path)
    except OSError:
        pass
