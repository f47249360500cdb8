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
    try:
        with open(part, 'wb' if binary else 'w') as f:
            f.write(data)
        os.replace(part, path)
    except BaseException:
        _remove_quietly(part)
        raise


def _remove_quietly(path):
    try:
        os.remove(path)
    except OSError:
        pass
