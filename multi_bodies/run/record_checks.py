"""Every field of a restart record checked before it is used (floor 6).

A record's checksum catches damage, not an edit: a record rewritten with
its checksum recomputed must still not make a restart allocate, seek or
crash.  :func:`record_problem` checks each field of a decoded record for
type, sign and range (offsets and lengths non-negative integers, the
snapshot table a table of checksums and lengths, the generator state a
state of a numpy bit generator, arrays numeric, finite and of the run's
shape); :func:`run_problem` checks it against the run it is to continue
(the structures, the number of bodies).  Each returns None or one line
naming the field, which the caller turns into a refusal naming the record.
"""
import math
import numbers

import numpy as np

MAX_NESTING = 6        # scheme histories are dicts of arrays and numbers: a few levels at most
MAX_NAME_LENGTH = 4096


class _Bad(Exception):
    """One field of a record is not what a record of this package holds."""


def _require(condition, text):
    if not condition:
        raise _Bad(text)


def _is_int(value, low=0):
    return isinstance(value, numbers.Integral) and not isinstance(value, bool) and int(value) >= low


def _finite(value):
    """True for a real number (not a bool) that is finite as a double."""
    if not isinstance(value, numbers.Real) or isinstance(value, bool):
        return False
    try:
        return math.isfinite(float(value))
    except OverflowError:
        return False


def _is_name(value):
    return isinstance(value, str) and 0 < len(value) <= MAX_NAME_LENGTH


def _table(record, key, check_value, what):
    """Check ``record[key]`` (absent or None allowed): a dict of names to values passing ``check_value``."""
    table = record.get(key)
    if table is None:
        return
    _require(isinstance(table, dict), '%s is a %s, not a table of structures' % (key, type(table).__name__))
    for name, value in table.items():
        _require(_is_name(name), '%s has the key %r, not a structure name' % (key, name))
        _require(check_value(value), '%s of %s is %s, not %s' % (key, name, _short(value), what))


def _short(value):
    """A field's value in at most 60 characters of one line (an array by its dtype and shape)."""
    if isinstance(value, np.ndarray):
        return 'a %s array of shape %s' % (value.dtype, value.shape)
    text = ' '.join(repr(value).split())
    return text if len(text) <= 60 else text[:57] + '...'


def _is_checksum_entry(value):
    """[SHA-256 hex digest, length in bytes]."""
    return (isinstance(value, (list, tuple)) and len(value) == 2 and isinstance(value[0], str)
            and len(value[0]) == 64 and all(c in '0123456789abcdef' for c in value[0]) and _is_int(value[1]))


def _is_byte_range(value):
    """[start, end] of a block in a side file: integers, 0 <= start <= end."""
    return isinstance(value, (list, tuple)) and len(value) == 2 and _is_int(value[0]) and _is_int(value[1]) \
        and value[0] <= value[1]


QUATERNION_NORM_TOLERANCE = 1e-6  # a run's quaternions are unit to round-off


def _check_array(value, where, columns=None):
    _require(isinstance(value, np.ndarray) and value.dtype.kind in 'fiub',
             '%s is %s, not an array of numbers' % (where, type(value).__name__))
    _require(value.dtype.kind != 'f' or bool(np.all(np.isfinite(value))), '%s holds NaN or infinite values' % where)
    if columns is not None:
        _require(value.ndim == 2 and value.shape[1] == columns, '%s has shape %s, not (bodies, %d)'
                 % (where, value.shape, columns))
    if columns == 4:  # orientations: unit quaternions (a zero quaternion is no rotation at all)
        norms = np.linalg.norm(np.asarray(value, dtype=float), axis=1)
        _require(bool(np.all(np.abs(norms - 1.0) <= QUATERNION_NORM_TOLERANCE)),
                 '%s holds a quaternion of norm %r, not a unit quaternion (a rotation)'
                 % (where, float(norms[np.argmax(np.abs(norms - 1.0))]) if norms.size else 0.0))


def _check_data(value, where, depth=0):
    """Scheme history and sampler state: None, numbers, words, numeric arrays, and lists/dicts of them."""
    _require(depth <= MAX_NESTING, '%s is nested more than %d levels deep' % (where, MAX_NESTING))
    if value is None or isinstance(value, (bool, str)):
        return
    if isinstance(value, numbers.Number):
        _require(isinstance(value, numbers.Integral) or _finite(value), '%s is %r' % (where, value))
        return
    if isinstance(value, (np.ndarray, np.generic)):
        _check_array(np.asarray(value), where)
        return
    if isinstance(value, (list, tuple)):
        for k, item in enumerate(value):
            _check_data(item, '%s[%d]' % (where, k), depth + 1)
        return
    _require(isinstance(value, dict), '%s is a %s' % (where, type(value).__name__))
    for key, item in value.items():
        _check_data(item, '%s.%s' % (where, key), depth + 1)


def _check_generator(state):
    """``bit_generator.state`` of a numpy bit generator (or of the published generator: MT19937 plus the
    cached Gaussian)."""
    _require(isinstance(state, dict), 'state.rng is a %s, not a generator state' % type(state).__name__)
    name = state.get('bit_generator')
    _require(isinstance(name, str) and isinstance(getattr(np.random, name, None), type)
             and issubclass(getattr(np.random, name), np.random.BitGenerator),
             'state.rng names the bit generator %s, not one of numpy' % _short(name))
    _require(isinstance(state.get('state'), dict), 'state.rng of %s holds no state table' % name)
    if 'has_gauss' in state:
        _require(state['has_gauss'] in (0, 1) and _finite(state.get('gauss')),
                 'state.rng has a cached Gaussian that is not a finite number')
    if name == 'MT19937':
        from multi_bodies.run.run_state import mt19937_key_problem
        problem = mt19937_key_problem(state['state'].get('key'), state['state'].get('pos'))
        _require(problem is None, 'state.rng: %s' % problem)
    _check_data(state, 'state.rng')


def _check_state(state):
    if state is None:
        return
    _require(isinstance(state, dict), 'state is a %s, not a table' % type(state).__name__)
    if state.get('rng') is not None:
        _check_generator(state['rng'])
    counters = state.get('counters')
    _require(counters is None or (isinstance(counters, dict) and all(_is_int(v) for v in counters.values())),
             'state.counters is not a table of non-negative integers')
    _require((state.get('locations') is None) == (state.get('orientations') is None),
             'state holds locations without orientations, or orientations without locations')
    for key, columns in (('locations', 3), ('orientations', 4)):
        if state.get(key) is not None:
            _check_array(state[key], 'state.' + key, columns)
    for key in ('scheme', 'sampler'):
        _check_data(state.get(key), 'state.' + key)


def record_problem(record, step):
    """None when every field of the decoded ``record`` (of header step ``step``) is of the right kind; else one
    line naming the first field that is not."""
    try:
        _require(isinstance(record, dict), 'the record is a %s, not a table' % type(record).__name__)
        _require(_is_int(record.get('step')) and record['step'] == step,
                 'step is %s, the header says %d' % (_short(record.get('step')), step))
        _require(record.get('run_id') is None or _is_name(record['run_id']), 'run_id is not a word')
        _table(record, 'config_offsets', _is_int, 'a byte offset (an integer >= 0)')
        _table(record, 'config_ends', _is_int, 'a byte offset (an integer >= 0)')
        _table(record, 'snapshots', _is_checksum_entry, '[SHA-256 digest, length >= 0]')
        _table(record, 'stop_files', _is_name, 'a file name')
        _table(record, 'side_files', _is_byte_range, '[start, end], byte offsets with start <= end')
        _require(isinstance(record.get('stop', False), bool), 'stop is not True or False')
        fingerprint = record.get('fingerprint')
        _require(fingerprint is None or (isinstance(fingerprint, dict) and
                                         all(isinstance(k, str) and isinstance(v, str) for k, v in fingerprint.items())),
                 'fingerprint is not a table of words')
        _check_state(record.get('state'))
    except _Bad as bad:
        return str(bad)
    return None


# What a record must hold to continue a run exactly, by program: the snapshot checksums and the fingerprint
# (every record this package writes has them), and the run state the program restores.
REQUIRED_STATE = {'dynamics': ('rng', 'locations', 'orientations', 'scheme', 'counters'),
                  'mcmc': ('rng', 'sampler')}


def missing_fields(record, types, program='dynamics'):
    """The first field an exact restart of ``program`` ('dynamics' or 'mcmc') needs that ``record`` lacks, as one
    line, or None."""
    snapshots = record.get('snapshots') or {}
    absent = [name for name, _ in types if name not in snapshots]
    if absent:
        return 'snapshots holds no checksum of %s' % ', '.join(absent)
    if not record.get('fingerprint'):
        return 'the record holds no fingerprint of the run (fingerprint: was (absent))'
    state = record.get('state')
    if not isinstance(state, dict):
        return 'the record holds no run state'
    for key in REQUIRED_STATE.get(program, ()):
        if state.get(key) is None:
            return 'state.%s is absent' % key
    if program == 'dynamics' and not isinstance(state.get('scheme'), dict):
        return 'state.scheme is not a table'
    return None


def configuration_problem(record, locations, orientations):
    """None when the configuration of ``record``'s state (when it holds one) is the snapshot's ``locations``
    (Nb, 3) and ``orientations`` (Nb, 4) as read (quaternions renormalised by the reader: they agree to 1e-10);
    else one line.  The record's exact numbers continue the run; a record whose numbers are another
    configuration belongs to another snapshot."""
    state = record.get('state') or {}
    saved = state.get('locations'), state.get('orientations')
    if saved[0] is None:
        return None
    scale = 1.0 + float(np.max(np.abs(locations))) if locations.size else 1.0
    if saved[0].shape != locations.shape or not np.allclose(saved[0], locations, rtol=0, atol=1e-12 * scale):
        return 'state.locations are not the positions of the snapshot'
    if saved[1].shape != orientations.shape or not np.allclose(saved[1], orientations, rtol=0, atol=1e-10):
        return 'state.orientations are not the orientations of the snapshot'
    return None


def run_problem(record, types, num_blobs=None, rollers=False):
    """None when ``record`` (already passed by :func:`record_problem`) fits a run of ``types`` ((ID, bodies) per
    structure) with ``num_blobs`` blobs (None: not checked) whose scheme moves rollers (``rollers``: the
    Adams-Bashforth velocities are then per blob, (N, 3), else per body, (Nb, 6)); else one line naming the
    field."""
    names = {name for name, _ in types}
    bodies = sum(count for _, count in types)
    for key in ('config_offsets', 'snapshots', 'stop_files'):
        unknown = sorted(set(record.get(key) or {}) - names)
        if unknown:
            return '%s names %s, not a structure of this run' % (key, ', '.join(unknown))
    state = record.get('state') or {}
    for key in ('locations', 'orientations'):
        value = state.get(key)
        if value is not None and value.shape[0] != bodies:
            return 'state.%s holds %d bodies, this run has %d' % (key, value.shape[0], bodies)
    try:
        _check_history(state.get('scheme'), bodies, num_blobs, rollers)
        _check_sampler(state, bodies)
    except _Bad as bad:
        return str(bad)
    return None


def _check_sampler(state, bodies):
    """The Monte Carlo chain's state (``MetropolisSampler.get_state``), when present, with its generator."""
    sampler = state.get('sampler')
    if sampler is None:
        return
    _require(isinstance(sampler, dict), 'state.sampler is a %s, not a table' % type(sampler).__name__)
    _require(state.get('rng') is not None, 'state.sampler without state.rng')
    for key, columns in (('locations', 3), ('orientations', 4)):
        _require(key in sampler, 'state.sampler has no %s' % key)
        _check_array(sampler[key], 'state.sampler.' + key, columns)
        _require(sampler[key].shape[0] == bodies, 'state.sampler.%s holds %d bodies, this run has %d'
                 % (key, sampler[key].shape[0], bodies))
    for key in ('max_translation', 'max_angle_shift'):
        value = sampler.get(key)
        _require(_finite(value) and value > 0,
                 'state.sampler.%s is %s, not a positive number' % (key, _short(value)))
    counters = sampler.get('counters')
    _require(isinstance(counters, (list, tuple)) and len(counters) == 7 and all(_is_int(c) for c in counters),
             'state.sampler.counters is %s, not seven integers >= 0' % _short(counters))


def _is_float_array(value, ndim):
    return isinstance(value, np.ndarray) and value.dtype.kind == 'f' and value.ndim == ndim


def _check_history(history, bodies, blobs=None, rollers=False):
    """The scheme history fields this package writes (``RunState.history``), when present: counts are integers
    >= 0; the preconditioner's configuration (locations, orientations) of this run's bodies; the Adams-Bashforth
    velocities ``previous_velocities`` of exactly the shape the scheme combines them with ((N, 3) for rollers,
    (Nb, 6) else); the blob concentrations (N,); the warm starts flat float arrays (``first_guess``,
    ``roller_torque_guess``; a warm start of another length is ignored by the solve) and ``earlier_guesses`` one or
    two of them."""
    if history is None:
        return
    _require(isinstance(history, dict), 'state.scheme is a %s, not a table' % type(history).__name__)
    for key, optional in (('invalid_configurations', False), ('preconditioner_step', True),
                          ('preconditioner_solves', True), ('preconditioner_fewest', True),
                          ('preconditioner_lifetime', True), ('concentration_preconditioner_solves', True),
                          ('concentration_preconditioner_fewest', True)):
        _require(key not in history or (optional and history[key] is None) or _is_int(history[key]),
                 'state.scheme.%s is %s, not an integer >= 0' % (key, _short(history.get(key))))
    for key in ('preconditioner_configuration', 'concentration_preconditioner_configuration'):
        saved = history.get(key)
        _require(saved is None or (isinstance(saved, (list, tuple)) and len(saved) == 2
                                   and all(isinstance(a, np.ndarray) and a.dtype.kind == 'f' for a in saved)
                                   and saved[0].shape == (bodies, 3) and saved[1].shape == (bodies, 4)),
                 'state.scheme.%s is not the locations (%d, 3) and orientations (%d, 4) of this run'
                 % (key, bodies, bodies))
        if saved is not None:
            _check_array(saved[0], 'state.scheme.%s[0]' % key, 3)
            _check_array(saved[1], 'state.scheme.%s[1]' % key, 4)
    for key in ('first_guess', 'roller_torque_guess'):
        value = history.get(key)
        _require(value is None or _is_float_array(value, 1),
                 'state.scheme.%s is not a flat float array (%s)' % (key, _short(value)))
    velocities = history.get('previous_velocities')
    if velocities is not None:
        shape = (blobs, 3) if rollers else (bodies, 6)
        _require(_is_float_array(velocities, 2) and (velocities.shape == shape or (rollers and blobs is None and
                                                                                      velocities.shape[1] == 3)),
                 'state.scheme.previous_velocities is %s, not the %s velocities %s of this run'
                 % (_short(velocities), 'roller' if rollers else 'body', shape))
    value = history.get('concentration_guess')
    _require(value is None or (_is_float_array(value, 1) and (blobs is None or value.shape == (blobs,))),
             'state.scheme.concentration_guess is not the %s blob concentrations of this run (%s)'
             % (blobs if blobs is not None else 'N', _short(value)))
    value = history.get('earlier_guesses')
    _require(value is None or (_is_float_array(value, 2) and 1 <= value.shape[0] <= 2),
             'state.scheme.earlier_guesses is not one or two flat float arrays (%s)' % _short(value))
    for key, value in history.items():
        if isinstance(value, np.ndarray):
            _require(value.dtype.kind != 'f' or bool(np.all(np.isfinite(value))),
                     'state.scheme.%s holds NaN or infinite values' % key)


def _kind(state_or_rng):
    """'published' or 'default (<bit generator>)' of a generator state (dict) or of a generator."""
    from stochastic_forcing import generators
    if isinstance(state_or_rng, dict):
        if generators.is_legacy_state(state_or_rng):
            return 'published'
        return 'default (%s)' % state_or_rng.get('bit_generator')
    if isinstance(state_or_rng, generators.PublishedGenerator):
        return 'published'
    return 'default (%s)' % type(state_or_rng.bit_generator).__name__


def generator_problem(options, rng_state):
    """None when the generator this run makes (``random_generator``, ``seed``, ``random_state``) takes the
    record's generator state ``rng_state``; else one line saying which generator each holds."""
    if rng_state is None:
        return None
    from multi_bodies.run.run_state import make_generator
    rng = make_generator(options)
    recorded, current = _kind(rng_state), _kind(rng)
    if recorded != current:
        return ('state.rng is the state of the %s generator, but this run makes the %s generator (random_generator '
                '%s); give random_generator the value the run that wrote the record had'
                % (recorded, current, options.random_generator))
    try:
        rng.bit_generator.state = rng_state
    except Exception as err:  # a state numpy refuses: one line, not its traceback
        return 'state.rng does not fit the %s generator (%s)' % (current, err)
    return None
