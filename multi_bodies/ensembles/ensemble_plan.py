"""The plan of an ensemble: replicas and parameter points, their seeds and inputs, the manifest (floor 7).

``build_plan`` turns an input file, a replica count and ``--vary`` items into
the replicas' input texts (each with its own seed and output folder) and
``write_plan`` writes them with the manifest ``ensemble.json``; the manifest
is read back with its names checked to stay inside the ensemble folder, and
a lock keeps two drivers off one folder.  Running the replicas is
:mod:`multi_bodies.ensembles.ensemble_runner`.
"""
import contextlib
import hashlib
import itertools
import json
import os
import re
import sys
import time

import numpy as np

from utils import UserInputError
from multi_bodies.run.output_lock import hold_lock

MANIFEST_NAME = 'ensemble.json'
REPLICA_INPUT_NAME = 'input.dat'
STATUS_NAME = 'status.json'
LOG_NAME = 'replica.log'
MANIFEST_VERSION = 1
# Options the ensemble sets in every replica's input; they cannot be varied.
ENSEMBLE_OWNED_OPTIONS = ('output_name', 'seed', 'random_state', 'initial_step')

# ------------------------------------------------------------------ the plan
def parse_vary(items):
    """``['kT=0.5,1,2', 'dt=0.01,0.02']`` -> ``[('kT', ['0.5', '1', '2']), ('dt', [...])]``.

    Options that change together are one axis: ``'dt:n_steps=0.01:400,0.02:200'``
    -> ``('dt:n_steps', ['0.01:400', '0.02:200'])`` gives the two points
    (dt 0.01, n_steps 400) and (dt 0.02, n_steps 200), e.g. the same
    simulated time at every time step.  Values stay text: each replica's input
    file is checked by the input reader, so a value of the wrong type fails
    that point's replicas with the reader's message.  Raises UserInputError for
    a malformed item, an unknown option, an option the ensemble owns, or a name
    given twice.
    """
    from multi_bodies.files.input_options import OPTION_TABLE
    import difflib
    parsed, seen = [], set()
    for item in items or ():
        name, sep, values_text = item.partition('=')
        name = name.strip()
        values = [value.strip() for value in values_text.split(',')]
        if not sep or not name or not values_text.strip() or any(not value for value in values):
            raise UserInputError("--vary %s: write NAME=V1,V2,... (e.g. --vary kT=0.5,1,2), or "
                                 "NAME1:NAME2=V1:W1,V2:W2,... for options that change together" % item)
        names = [part.strip() for part in name.split(':')]
        for value in values:
            if len(value.split(':')) != len(names):
                raise UserInputError("--vary %s: the value '%s' has %d part(s) for the %d option(s) %s; write one "
                                     "value per option, separated by ':'" % (item, value, len(value.split(':')),
                                                                             len(names), ', '.join(names)))
        for one in names:
            if one in ENSEMBLE_OWNED_OPTIONS:
                raise UserInputError('--vary %s: %s is set by the ensemble for every replica and cannot be varied'
                                     % (item, one))
            if one == 'structure':
                raise UserInputError('--vary %s: structure lines cannot be varied; make one input file per set of '
                                     'structures' % item)
            if one not in OPTION_TABLE:
                close = [option for option in OPTION_TABLE if option.lower() == one.lower()]
                close = close or difflib.get_close_matches(one, list(OPTION_TABLE), n=1)
                raise UserInputError("--vary %s: unknown option '%s'%s" % (item, one,
                                     " (did you mean '%s'?)" % close[0] if close else ''))
            if one in seen:
                raise UserInputError('--vary %s: %s is varied twice; give all its values in one --vary' % (item, one))
            seen.add(one)
        parsed.append((':'.join(names), [':'.join(part.strip() for part in value.split(':')) for value in values]))
    return parsed


def point_name(overrides):
    """Folder name of a parameter point, e.g. ``kT-0.5_dt-0.01`` (``base`` without overrides)."""
    if not overrides:
        return 'base'
    return '_'.join('%s-%s' % (name, re.sub(r'[^A-Za-z0-9.+-]', '_', value)) for name, value in overrides)


def parameter_points(vary):
    """Cartesian product of the varied axes: list of lists of (name, value), first axis slowest."""
    points = []
    for combination in itertools.product(*[values for _, values in vary]):
        overrides = []
        for (name, _), value in zip(vary, combination):  # an axis 'dt:n_steps' sets both options
            overrides.extend(zip(name.split(':'), value.split(':')))
        points.append(overrides)
    return points


def replica_seeds(master_seed, num_points, num_replicas):
    """Seeds of every replica: ``seeds[p][r]`` = (seed, spawn_key).

    ``SeedSequence(master_seed).spawn(num_points)[p].spawn(num_replicas)[r]``
    gives the stream of replica r at point p (spawn key ``(p, r)``); its first
    64-bit word is the ``seed`` written in the replica's input file (the run
    seeds ``numpy.random.default_rng(seed)`` with it, SPEC decision 7).  More
    replicas or points later keep the seeds of the earlier ones.
    """
    seeds = []
    for point_sequence in np.random.SeedSequence(master_seed).spawn(num_points):
        row = []
        for sequence in point_sequence.spawn(num_replicas):
            row.append((int(sequence.generate_state(1, dtype=np.uint64)[0]), [int(k) for k in sequence.spawn_key]))
        seeds.append(row)
    return seeds


def replica_input_text(original_text, source_dir, overrides, output_name, seed, header=''):
    """Input file of one replica: the user's lines, structure paths made absolute, then the overrides.

    Lines setting an option that the replica overrides (``output_name``,
    ``seed``, ``random_state``, ``initial_step`` and the varied options) are
    kept as comments, so the file says what it replaced.
    """
    replaced = set(ENSEMBLE_OWNED_OPTIONS) | {name for name, _ in overrides}
    lines = []
    for raw in original_text.splitlines():
        words = raw.split('#', 1)[0].split()
        if words and words[0] in replaced:
            lines.append('# (set by the ensemble below) ' + raw)
        elif words and words[0] == 'structure':
            paths = [w if os.path.isabs(w) else os.path.normpath(os.path.join(source_dir, w)) for w in words[1:]]
            lines.append('structure ' + ' '.join(paths))
        else:
            lines.append(raw)
    lines.append('')
    lines.append('# ---- ensemble overrides%s ----' % (': ' + header if header else ''))
    lines.append('output_name %s' % output_name)
    lines.append('seed %d' % seed)
    lines.append('initial_step 0')
    for name, value in overrides:
        lines.append('%s %s' % (name, value))
    return '\n'.join(lines) + '\n'


def _sha256(text):
    return hashlib.sha256(text.encode()).hexdigest()


def build_plan(input_file, replicas, vary=(), output_dir='ensemble', master_seed=None):
    """The manifest of an ensemble (a dict, JSON-ready); nothing is written.

    input_file : the user's input file (read here; structure paths are taken
        relative to its folder, where the replicas also run)
    replicas : replicas per parameter point (>= 1)
    vary : output of :func:`parse_vary`
    master_seed : int >= 0, or None for one drawn from the operating system
        (recorded in the manifest, so the ensemble can be repeated)

    Keys: ``input_file``, ``input_sha256``, ``run_directory``, ``master_seed``,
    ``replicas_per_point``, ``vary``, ``points`` (name, overrides),
    ``replicas`` (point index and name, replica index, ``folder`` relative to
    the output folder, ``output_basename``, ``seed``, ``spawn_key``,
    ``input_sha256`` of the replica's input), ``output_dir`` (absolute), and
    ``_inputs`` (folder -> input text; not saved).
    """
    from multi_bodies.files.input_options import parse_input_text
    if replicas < 1:
        raise UserInputError('--replicas must be at least 1, got %d' % replicas)
    if master_seed is not None and master_seed < 0:
        raise UserInputError('--seed must be a non-negative integer, got %d' % master_seed)
    if not os.path.isfile(input_file):
        raise UserInputError("input file '%s' not found (give it with --input-file)" % input_file)
    with open(input_file) as f:
        original_text = f.read()
    base_options = parse_input_text(original_text, input_file)  # the user's file itself must be valid
    if master_seed is None:
        master_seed = int(np.random.SeedSequence().entropy)
    input_path = os.path.abspath(input_file)
    source_dir = os.path.dirname(input_path)
    output_dir = os.path.abspath(output_dir)
    basename = os.path.basename(base_options.output_name) or 'run'
    points = parameter_points(list(vary)) if vary else [[]]
    seeds = replica_seeds(master_seed, len(points), replicas)
    plan = {'version': MANIFEST_VERSION, 'input_file': input_path, 'input_sha256': _sha256(original_text),
            'run_directory': source_dir, 'master_seed': int(master_seed), 'replicas_per_point': int(replicas),
            'vary': [[name, list(values)] for name, values in vary], 'output_dir': output_dir,
            'points': [], 'replicas': [], '_inputs': {}}
    for p, overrides in enumerate(points):
        name = point_name(overrides)
        plan['points'].append({'name': name, 'overrides': [[k, v] for k, v in overrides]})
        for r in range(replicas):
            folder = '%s/r%04d' % (name, r)
            seed, spawn_key = seeds[p][r]
            text = replica_input_text(original_text, source_dir, overrides,
                                      os.path.join(output_dir, folder, basename), seed,
                                      header='replica %d of point %s, master seed %d, spawn key %s'
                                             % (r, name, master_seed, spawn_key))
            plan['replicas'].append({'point': p, 'point_name': name, 'replica': r, 'folder': folder,
                                     'output_basename': basename, 'seed': seed, 'spawn_key': spawn_key,
                                     'input_sha256': _sha256(text)})
            plan['_inputs'][folder] = text
    if replicas > 1:  # a deterministic scheme ignores the seed: its replicas would all be the same run
        from multi_bodies.files.input_options import DETERMINISTIC_SCHEMES, STATIC_SCHEMES
        same = sorted({dict(o).get('scheme', base_options.scheme) for o in points} &
                      set(DETERMINISTIC_SCHEMES + STATIC_SCHEMES))
        if same:
            print('warning: scheme %s is deterministic: the %d replicas of each parameter point are identical runs '
                  '(the seed has no effect); use --replicas 1, or a stochastic scheme for independent replicas'
                  % (', '.join(same), replicas), file=sys.stderr)
    if len({point['name'] for point in plan['points']}) != len(plan['points']):
        raise UserInputError('--vary: two parameter points get the same folder name (%s); give distinct values'
                             % ', '.join(point['name'] for point in plan['points']))
    return plan


def _atomic_write_text(path, text):
    part = path + '.part'
    with open(part, 'w') as f:
        f.write(text)
    os.replace(part, path)


MANIFEST_BYTES = 1 << 26  # a manifest lists points and replicas in a few hundred bytes each


def read_manifest(output_dir):
    """The manifest ``output_dir/ensemble.json`` as a dict; UserInputError when missing or unreadable.

    Every field the runner, ``--aggregate`` and ``analyse.py`` use is checked before any is used: ``points`` a
    list of {name inside the folder, overrides: list of [option, value]}, ``vary`` a list of [option(s), values],
    ``replicas`` a list of {folder inside the folder, point: an index of ``points``, output_basename a file name}.
    A manifest larger than ``MANIFEST_BYTES`` or nested too deeply to read is refused before it is parsed."""
    path = os.path.join(output_dir, MANIFEST_NAME)
    try:
        if os.path.getsize(path) > MANIFEST_BYTES:
            raise UserInputError('%s holds %d bytes, more than an ensemble manifest (%d at most); it is not this '
                                 "package's manifest" % (path, os.path.getsize(path), MANIFEST_BYTES))
        with open(path, 'rb') as f:
            manifest = json.loads(f.read().decode('utf-8'))
    except FileNotFoundError:
        raise UserInputError('%s not found: %s is not the output folder of an ensemble (run ensemble.py '
                             '--input-file ... --output-dir %s first)' % (path, output_dir, output_dir))
    except (ValueError, RecursionError) as err:  # JSON, UTF-8, or a document nested too deeply to read
        raise UserInputError('%s is not a valid ensemble manifest (%s)' % (path, type(err).__name__ if
                                                                          isinstance(err, RecursionError) else err))
    except OSError as err:
        raise UserInputError('%s cannot be read (%s)' % (path, err.strerror or err))
    if not isinstance(manifest, dict) or 'replicas' not in manifest:
        raise UserInputError('%s is not an ensemble manifest (no replica list)' % path)
    manifest['output_dir'] = os.path.abspath(output_dir)

    def refuse(text):
        return UserInputError('%s: %s; the manifest was changed by hand or is not this ensemble\'s, so nothing is '
                              'read or written' % (path, text))
    points = manifest.get('points')
    if points is None:
        points = manifest['points'] = []
    if not isinstance(points, list):
        raise refuse('points is not a list')
    for index, point in enumerate(points):
        if not isinstance(point, dict):
            raise refuse('point %d is not a table' % index)
        _check_inside(manifest['output_dir'], point.get('name'), 'point name', path)
        overrides = point.get('overrides', [])
        if not (isinstance(overrides, list) and all(isinstance(o, list) and len(o) == 2 and isinstance(o[0], str)
                                                    and isinstance(o[1], (str, int, float)) for o in overrides)):
            raise refuse('the overrides of point %s are not a list of [option, value] pairs' % point.get('name'))
        point.setdefault('overrides', overrides)
    vary = manifest.get('vary', [])
    if not (isinstance(vary, list) and all(isinstance(v, list) and len(v) == 2 and isinstance(v[0], str)
                                           and isinstance(v[1], list) for v in vary)):
        raise refuse('vary is not a list of [option, values] pairs')
    manifest['vary'] = vary
    if not isinstance(manifest['replicas'], list):
        raise refuse('the replica list is not a list')
    for index, replica in enumerate(manifest['replicas']):
        if not isinstance(replica, dict):
            raise refuse('replica %d is not a table' % index)
        folder = replica.get('folder')
        _check_inside(manifest['output_dir'], folder, 'replica folder', path)
        _check_basename(os.path.join(manifest['output_dir'], folder), replica.get('output_basename'), path)
        point = replica.get('point', 0 if len(points) == 1 else None)
        if not (isinstance(point, int) and not isinstance(point, bool) and 0 <= point < len(points)):
            raise refuse('replica %s has point %r, not one of the %d points' % (folder, point, len(points)))
        replica['point'] = point
    return manifest


def _check_basename(folder, basename, manifest_path):
    """Refuse an ``output_basename`` that is not a plain file name of the replica's ``folder`` (None: absent)."""
    if basename is None:
        return
    ok = isinstance(basename, str) and basename not in ('', '.', '..') and '/' not in basename \
        and '\\' not in basename and not os.path.isabs(basename)
    if ok:
        target = os.path.realpath(os.path.join(folder, basename))
        ok = os.path.commonpath([os.path.realpath(folder), target]) == os.path.realpath(folder)
    if not ok:
        raise UserInputError('%s: the output_basename %r is not a file name inside the replica folder %s; the '
                             'manifest was changed by hand or is not this ensemble\'s, so nothing is read'
                             % (manifest_path, basename, folder))


def _check_inside(output_dir, name, what, manifest_path):
    """Refuse a ``name`` from the manifest that is not a relative path inside ``output_dir`` (``../..``, ``/x``,
    any ``..`` component even when it leads back inside).

    The manifest is data: a name that would make the runner or ``--aggregate``
    read or write outside the ensemble folder is a UserInputError.
    """
    root = os.path.realpath(output_dir)
    ok = isinstance(name, str) and name and not os.path.isabs(name) and \
        '..' not in name.replace('\\', '/').split('/')
    if ok:
        target = os.path.realpath(os.path.join(root, name))
        ok = target != root and os.path.commonpath([root, target]) == root
    if not ok:
        raise UserInputError('%s: the %s %r is not a folder inside the ensemble folder %s; the manifest was '
                             'changed by hand or is not this ensemble\'s, so nothing is read or written'
                             % (manifest_path, what, name, output_dir))


def write_plan(plan):
    """Create the folders, write every replica's ``input.dat`` and the manifest.

    A folder that already holds an ``input.dat`` with other content (another
    input file, seed or override in the same output folder) raises
    UserInputError: choose another --output-dir.  Same content: the folder is
    kept as it is (a rerun resumes or skips it).
    """
    output_dir = plan['output_dir']
    try:
        os.makedirs(output_dir, exist_ok=True)
    except OSError as err:
        raise UserInputError('--output-dir %s: cannot create it (%s)' % (output_dir, err.strerror or err))
    for replica in plan['replicas']:
        folder = os.path.join(output_dir, replica['folder'])
        path = os.path.join(folder, REPLICA_INPUT_NAME)
        text = plan['_inputs'][replica['folder']]
        if os.path.isfile(path):
            with open(path) as f:
                if f.read() != text:
                    raise UserInputError(
                        '--output-dir %s: %s holds a replica of another ensemble (other input file, master seed '
                        'or overrides); choose another --output-dir, or remove that folder to start afresh'
                        % (output_dir, path))
            continue
        os.makedirs(folder, exist_ok=True)
        _atomic_write_text(path, text)
    manifest = {key: value for key, value in plan.items() if not key.startswith('_') and key != 'output_dir'}
    manifest['created'] = time.strftime('%Y-%m-%dT%H:%M:%SZ', time.gmtime())
    _atomic_write_text(os.path.join(output_dir, MANIFEST_NAME), json.dumps(manifest, indent=1) + '\n')


def existing_master_seed(output_dir):
    """The master seed of the manifest in ``output_dir``, or None when there is none."""
    try:
        with open(os.path.join(output_dir, MANIFEST_NAME)) as f:
            return int(json.load(f)['master_seed'])
    except (OSError, ValueError, KeyError, TypeError):
        return None


LOCK_NAME = 'ensemble.lock'


@contextlib.contextmanager
def ensemble_lock(output_dir, log=print):
    """Hold ``output_dir/ensemble.lock`` while an ensemble runs there, so that two drivers never share a folder.

    The lock of the runs (:func:`multi_bodies.run.output_lock.hold_lock`): the file names the host and
    process; one left by a process that no longer runs is taken over (logged); one held by a live process,
    or naming a process of another host, raises UserInputError.
    """
    try:
        os.makedirs(output_dir, exist_ok=True)
    except OSError as err:
        raise UserInputError('--output-dir %s: cannot create it (%s)' % (output_dir, err.strerror or err))
    path = os.path.join(output_dir, LOCK_NAME)

    def refusal(holder):
        return UserInputError('%s: another ensemble.py (%s) is running in this folder; wait for it or stop it'
                              % (output_dir, holder))
    with hold_lock(path, refusal, log):
        yield path


LOCK_WRITE_SECONDS = 5.0  # kept for callers of earlier versions: the flock of hold_lock needs no age rule


def replica_specs(plan):
    """The task argument of every replica (small JSON-ready dicts)."""
    return [{'folder': replica['folder'],
             'path': os.path.join(plan['output_dir'], replica['folder']),
             'input_file': os.path.join(plan['output_dir'], replica['folder'], REPLICA_INPUT_NAME),
             'run_directory': plan['run_directory'],
             'input_sha256': replica['input_sha256']} for replica in plan['replicas']]


def read_status(path):
    """``status.json`` of a replica folder as a dict, or None when absent or unreadable."""
    try:
        with open(os.path.join(path, STATUS_NAME)) as f:
            return json.load(f)
    except (OSError, ValueError):
        return None


def is_finished(spec):
    """True when the replica finished earlier with the same input (a rerun skips it)."""
    status = read_status(spec['path'])
    return bool(status) and status.get('status') == 'done' and status.get('input_sha256') == spec['input_sha256']


