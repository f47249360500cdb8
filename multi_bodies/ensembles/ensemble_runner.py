"""Ensembles of dynamic runs: replicas and parameter sweeps, run on Dask (floor 7).

An ensemble is one input file run ``R`` times at every point of a parameter
grid (``--vary kT=0.5,1,2 --vary dt=...``: the Cartesian product), each run
with its own seed.  This module

* plans it (:func:`build_plan`): one folder per parameter point and replica
  under the output folder ``D``, ``D/<point>/r<replica>/input.dat`` (the
  user's input with the structure paths made absolute and the overrides
  appended), seeds from ``numpy.random.SeedSequence(master)`` spawned once
  per point and once per replica in the point (spawn key ``(point, replica)``),
  and the manifest ``D/ensemble.json``;
* runs one replica in the calling process (:func:`run_replica`, the Dask
  task) through :func:`multi_bodies.run.dynamic_run.run_dynamics`, in the folder
  of the user's input file (relative structure paths and
  ``user_defined_functions.py`` are found there), resuming from the last
  complete restart record when an earlier attempt was killed, and writing
  ``status.json`` and ``replica.log`` beside the run's outputs;
* drives the whole ensemble on a ``distributed.Client``
  (:func:`run_on_client`) or one replica after another in this process
  (:func:`run_serially`), with one progress line, skipping replicas that
  finished before.

Dask (``distributed``, ``dask_jobqueue``) is imported only by the functions
that need it; without it :func:`require_distributed` raises a UserInputError
that names the extra to install.  The statistics of a finished ensemble are
in :mod:`multi_bodies.ensembles.ensemble_statistics`.
"""
import contextlib
import hashlib
import itertools
import json
import os
import re
import socket
import sys
import threading
import time
import traceback

import numpy as np

from mobility.threads import available_cores
from utils import UserInputError

MANIFEST_NAME = 'ensemble.json'
REPLICA_INPUT_NAME = 'input.dat'
STATUS_NAME = 'status.json'
LOG_NAME = 'replica.log'
MANIFEST_VERSION = 1
# Options the ensemble sets in every replica's input; they cannot be varied.
ENSEMBLE_OWNED_OPTIONS = ('output_name', 'seed', 'random_state', 'initial_step')
INSTALL_HINT = "pip install -e '.[ensemble]' (or: pip install 'dask[distributed]' dask-jobqueue)"

# One replica at a time per process: a run reads its hooks and relative paths from the working directory.
_RUN_LOCK = threading.Lock()


# ------------------------------------------------------------------ optional dependencies
def require_distributed():
    """Import and return the ``distributed`` module, or raise UserInputError naming the extra."""
    try:
        import distributed
    except ImportError as err:
        raise UserInputError('running an ensemble on Dask needs dask.distributed, which is not installed (%s); '
                             'install the ensemble extra: %s, or run the replicas in this process with '
                             '--workers 0' % (err, INSTALL_HINT))
    return distributed


def require_jobqueue():
    """Import and return ``dask_jobqueue``, or raise UserInputError naming the extra."""
    try:
        import dask_jobqueue
    except ImportError as err:
        raise UserInputError('--jobqueue needs dask-jobqueue, which is not installed (%s); install the ensemble '
                             'extra: %s' % (err, INSTALL_HINT))
    return dask_jobqueue


# ------------------------------------------------------------------ the plan
def parse_vary(items):
    """``['kT=0.5,1,2', 'dt=0.01,0.02']`` -> ``[('kT', ['0.5', '1', '2']), ('dt', [...])]``.

    Values stay text: each replica's input file is checked by the input
    reader, so a value of the wrong type fails that point's replicas with the
    reader's message.  Raises UserInputError for a malformed item, an unknown
    option, an option the ensemble owns, or a name given twice.
    """
    from multi_bodies.files.input_options import OPTION_TABLE
    import difflib
    parsed, seen = [], set()
    for item in items or ():
        name, sep, values_text = item.partition('=')
        name = name.strip()
        values = [value.strip() for value in values_text.split(',')]
        if not sep or not name or not values_text.strip() or any(not value for value in values):
            raise UserInputError("--vary %s: write NAME=V1,V2,... (e.g. --vary kT=0.5,1,2)" % item)
        if name in ENSEMBLE_OWNED_OPTIONS:
            raise UserInputError('--vary %s: %s is set by the ensemble for every replica and cannot be varied'
                                 % (item, name))
        if name == 'structure':
            raise UserInputError('--vary %s: structure lines cannot be varied; make one input file per set of '
                                 'structures' % item)
        if name not in OPTION_TABLE:
            close = [option for option in OPTION_TABLE if option.lower() == name.lower()]
            close = close or difflib.get_close_matches(name, list(OPTION_TABLE), n=1)
            raise UserInputError("--vary %s: unknown option '%s'%s" % (item, name,
                                 " (did you mean '%s'?)" % close[0] if close else ''))
        if name in seen:
            raise UserInputError('--vary %s: %s is varied twice; give all its values in one --vary' % (item, name))
        seen.add(name)
        parsed.append((name, values))
    return parsed


def point_name(overrides):
    """Folder name of a parameter point, e.g. ``kT-0.5_dt-0.01`` (``base`` without overrides)."""
    if not overrides:
        return 'base'
    return '_'.join('%s-%s' % (name, re.sub(r'[^A-Za-z0-9.+-]', '_', value)) for name, value in overrides)


def parameter_points(vary):
    """Cartesian product of the varied values: list of lists of (name, value), first option slowest."""
    names = [name for name, _ in vary]
    return [list(zip(names, combination)) for combination in itertools.product(*[values for _, values in vary])]


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


def read_manifest(output_dir):
    """The manifest ``output_dir/ensemble.json`` as a dict; UserInputError when missing or unreadable."""
    path = os.path.join(output_dir, MANIFEST_NAME)
    try:
        with open(path) as f:
            manifest = json.load(f)
    except FileNotFoundError:
        raise UserInputError('%s not found: %s is not the output folder of an ensemble (run ensemble.py '
                             '--input-file ... --output-dir %s first)' % (path, output_dir, output_dir))
    except ValueError as err:
        raise UserInputError('%s is not a valid ensemble manifest (%s)' % (path, err))
    if not isinstance(manifest, dict) or 'replicas' not in manifest:
        raise UserInputError('%s is not an ensemble manifest (no replica list)' % path)
    manifest['output_dir'] = os.path.abspath(output_dir)
    for point in manifest.get('points') or []:
        _check_inside(manifest['output_dir'], point.get('name') if isinstance(point, dict) else None,
                      'point name', path)
    for replica in manifest['replicas']:
        _check_inside(manifest['output_dir'], replica.get('folder') if isinstance(replica, dict) else None,
                      'replica folder', path)
    return manifest


def _check_inside(output_dir, name, what, manifest_path):
    """Refuse a ``name`` from the manifest that is not a relative path inside ``output_dir`` (``../..``, ``/x``).

    The manifest is data: a name that would make the runner or ``--aggregate``
    read or write outside the ensemble folder is a UserInputError.
    """
    root = os.path.realpath(output_dir)
    ok = isinstance(name, str) and name and not os.path.isabs(name)
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
def ensemble_lock(output_dir):
    """Hold ``output_dir/ensemble.lock`` while an ensemble runs there, so that two drivers never share a folder.

    The lock file names the host and process.  One left by a process of this
    host that no longer runs is taken over; one held by a live process, or
    by a process of another host, raises UserInputError.
    """
    try:
        os.makedirs(output_dir, exist_ok=True)
    except OSError as err:
        raise UserInputError('--output-dir %s: cannot create it (%s)' % (output_dir, err.strerror or err))
    path = os.path.join(output_dir, LOCK_NAME)
    host, pid = socket.gethostname(), os.getpid()
    for _ in range(2):
        try:
            descriptor = os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
        except FileExistsError:
            try:
                with open(path) as f:
                    holder = json.load(f)
            except (OSError, ValueError):
                holder = {}
            if holder.get('host') == host and isinstance(holder.get('pid'), int) and not _alive(holder['pid']):
                os.remove(path)  # stale: its process has gone
                continue
            if not holder and _age(path) > LOCK_WRITE_SECONDS:
                # empty or unreadable: a driver killed between creating the lock and writing its name in it
                os.remove(path)
                continue
            raise UserInputError('%s: another ensemble.py (pid %s on %s, started %s) is running in this folder; '
                                 'wait for it or stop it (if it no longer runs, remove %s)'
                                 % (output_dir, holder.get('pid', '?'), holder.get('host', '?'),
                                    holder.get('started', '?'), path))
        with os.fdopen(descriptor, 'w') as f:
            json.dump({'host': host, 'pid': pid, 'started': time.strftime('%Y-%m-%dT%H:%M:%SZ', time.gmtime())}, f)
        break
    try:
        yield path
    finally:
        try:
            os.remove(path)
        except FileNotFoundError:
            pass


LOCK_WRITE_SECONDS = 5.0  # a live driver writes its name into the lock at once; an empty older one is stale


def _age(path):
    try:
        return time.time() - os.path.getmtime(path)
    except OSError:
        return 0.0


def _alive(pid):
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


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


# ------------------------------------------------------------------ one replica (the task)
def prepare_resume(options, log=print):
    """Step to resume a killed replica from (0: start afresh); changes no file.

    The step is that of the last record of ``output_name.restart`` whose
    snapshot is complete and unchanged (its checksum): a record cut by the
    kill, or a snapshot written without its record, is passed over, with a
    line saying so.  The resumed run (through ``initial_step``) moves what
    the kill left after that pair aside at its first save, once the
    replacement is being written, so the resumed outputs equal those of an
    undisturbed run and a resume that fails loses nothing.
    """
    from multi_bodies.run import run_output
    path = options.output_name + run_output.RESTART_SUFFIX
    if not os.path.isfile(path):
        return 0
    types = [(spec.ID, 0) for spec in options.structures]
    last, _ = run_output.last_complete_pair(options.output_name, options.save_clones, types, report=log)
    if last is None or not isinstance(last.get('step'), int) or last['step'] <= 0:
        return 0
    log('# ensemble: the last complete snapshot and record is step %d%s' % (
        last['step'], ' (saved when a signal stopped the run)' if last.get('stop') else ''))
    return int(last['step'])


def _write_status(spec, status):
    status = dict(status, input_sha256=spec['input_sha256'],
                  finished_at=time.strftime('%Y-%m-%dT%H:%M:%SZ', time.gmtime()))
    _atomic_write_text(os.path.join(spec['path'], STATUS_NAME), json.dumps(status, indent=1) + '\n')
    return status


@contextlib.contextmanager
def _in_directory(path):
    previous = os.getcwd()
    os.chdir(path)
    try:
        yield
    finally:
        os.chdir(previous)


def _last_error_line(log_path):
    try:
        with open(log_path) as f:
            lines = [line.strip() for line in f if line.strip()]
    except OSError:
        return ''
    errors = [line for line in lines if line.startswith('error')]
    return errors[-1] if errors else (lines[-1] if lines else '')


def run_replica(spec):
    """Run one replica in this process; the Dask task.  Returns a result dict.

    ``spec``: one entry of :func:`replica_specs`.  The run reads
    ``spec['input_file']`` with the working directory set to
    ``spec['run_directory']`` (the folder of the user's input); its printed
    output goes to ``replica.log`` in the replica folder.  A replica that
    finished before (``status.json`` done, same input) is not run again; one
    whose earlier attempt was killed resumes from its last saved step
    (:func:`prepare_resume`) with ``initial_step`` set to it, which continues
    the trajectory exactly (SPEC decision 11).

    Result keys: ``folder``, ``status`` ('done', 'failed': user error or run
    stopped, 'stopped': interrupted), ``exit_status``, ``message``,
    ``resumed_from`` (step, 0 for a fresh start), ``seconds``, ``host``,
    ``pid``, ``skipped`` (finished before).  Exceptions other than user
    errors are raised (Dask retries them) after being logged.
    """
    from multi_bodies.run.dynamic_run import run_dynamics
    from multi_bodies.files.input_options import read_input_file
    if is_finished(spec):
        return dict(read_status(spec['path']), folder=spec['folder'], skipped=True)
    log_path = os.path.join(spec['path'], LOG_NAME)
    result = {'folder': spec['folder'], 'host': socket.gethostname(), 'pid': os.getpid(), 'resumed_from': 0,
              'skipped': False}
    start = time.perf_counter()
    with _RUN_LOCK, open(log_path, 'a') as log, _in_directory(spec['run_directory']), \
            contextlib.redirect_stdout(log), contextlib.redirect_stderr(log):
        try:
            options = read_input_file(spec['input_file'])
            resume = prepare_resume(options)
            print('# ensemble: %s on %s (pid %d), %s' % (
                spec['folder'], result['host'], result['pid'],
                'resuming from step %d' % resume if resume else 'fresh start'), flush=True)
            if resume:
                options.initial_step = resume
            result['resumed_from'] = resume
            exit_status = run_dynamics(options, log=print)
        except UserInputError as err:
            print('error: %s' % err, flush=True)
            result.update(status='failed', exit_status=2, message=str(err))
        except Exception:
            traceback.print_exc(file=log)
            log.flush()
            raise
        else:
            result['exit_status'] = exit_status
            if exit_status == 0:
                result.update(status='done', message='')
            elif exit_status == 1:
                result.update(status='failed', message='run stopped: %s' % _last_error_line(log_path))
            else:
                result.update(status='stopped', message='interrupted (exit status %d); a rerun resumes it from '
                                                        'its last saved step' % exit_status)
    result['seconds'] = time.perf_counter() - start
    return _write_status(spec, result)


# ------------------------------------------------------------------ progress of the ensemble
class EnsembleProgress:
    """One line for the whole ensemble: replicas done, failed, running, and the time left.

    A tqdm bar when ``stream`` is a terminal and tqdm is installed, else a
    plain line whenever the counts change (at most every ``interval``
    seconds) and at the end.
    """

    def __init__(self, total, skipped=0, stream=None, interval=10.0):
        self.total, self.skipped = total, skipped
        self.stream = sys.stdout if stream is None else stream
        self.interval = float(interval)
        self.start = time.perf_counter()
        self.last_line = -float('inf')
        self.counts = (0, 0, 0)
        self.bar = None
        if getattr(self.stream, 'isatty', lambda: False)():
            try:
                from tqdm import tqdm
                self.bar = tqdm(total=total, unit='replica', file=self.stream, dynamic_ncols=True)
            except ImportError:
                self.bar = None

    def write(self, text):
        if self.bar is not None:
            self.bar.write(text, file=self.stream)
        else:
            print(text, file=self.stream, flush=True)

    def line(self):
        if self.total == 0:
            return 'ensemble: nothing to run (%d replicas finished before, skipped)' % self.skipped
        done, failed, running = self.counts
        finished = done + failed
        elapsed = time.perf_counter() - self.start
        eta = ('about %.0f s left' % (elapsed / finished * (self.total - finished))) if finished else 'ETA unknown'
        return ('ensemble: %d of %d replicas done, %d failed, %d running%s, elapsed %.0f s, %s'
                % (done, self.total, failed, running,
                   ' (%d finished before, skipped)' % self.skipped if self.skipped else '', elapsed, eta))

    def update(self, done, failed, running, force=False):
        changed = (done, failed, running) != self.counts
        self.counts = (done, failed, running)
        if self.bar is not None:
            self.bar.n = done + failed
            self.bar.set_postfix_str('done %d, failed %d, running %d' % self.counts, refresh=True)
            return
        now = time.perf_counter()
        if force or (changed and now - self.last_line >= self.interval):
            self.write(self.line())
            self.last_line = now

    def close(self):
        if self.bar is not None:
            self.bar.close()
            self.bar = None
        self.write(self.line())


# ------------------------------------------------------------------ running the ensemble
def _failure_result(spec, exc):
    message = '%s: %s' % (type(exc).__name__, exc)
    return {'folder': spec['folder'], 'status': 'failed', 'exit_status': None, 'message': message,
            'resumed_from': None, 'seconds': None, 'skipped': False}


def _report(progress, result, output_dir):
    if result['status'] != 'done':
        progress.write('replica %s %s: %s' % (os.path.join(output_dir, result['folder']), result['status'],
                                             result.get('message', '')))


def split_finished(plan):
    """(specs still to run, number finished before) of a plan."""
    specs = replica_specs(plan)
    todo = [spec for spec in specs if not is_finished(spec)]
    return todo, len(specs) - len(todo)


def run_serially(plan, stream=None):
    """Run every unfinished replica in this process, one after another; returns the result dicts.

    An interrupted replica (SIGINT/SIGTERM: it stops after the step in
    progress, outputs complete) stops the ensemble; a rerun resumes it.
    """
    todo, skipped = split_finished(plan)
    progress = EnsembleProgress(len(todo), skipped, stream)
    results, done, failed = [], 0, 0
    for spec in todo:
        progress.update(done, failed, 1)
        result = run_replica(spec)
        results.append(result)
        done += result['status'] == 'done'
        failed += result['status'] == 'failed'  # a stopped replica is not a failure: a rerun resumes it
        _report(progress, result, plan['output_dir'])
        if result['status'] == 'stopped':
            break
    progress.update(done, failed, 0)
    progress.close()
    return results


def run_on_client(plan, client, retries=3, refresh=1.0, stream=None):
    """Submit every unfinished replica to a ``distributed.Client``; wait, reporting progress; return results.

    Tasks that raise are retried ``retries`` times by Dask; a task whose
    worker dies is rescheduled by the scheduler (up to its
    ``distributed.scheduler.allowed-failures``), and the new attempt resumes
    the replica from its last saved step.  A replica that fails for good is
    reported with its folder and message, and the others go on.
    """
    distributed = require_distributed()
    todo, skipped = split_finished(plan)
    progress = EnsembleProgress(len(todo), skipped, stream)
    futures = client.map(run_replica, todo, retries=retries, pure=False) if todo else []
    spec_of = {future.key: spec for future, spec in zip(futures, todo)}
    pending, results, done, failed = set(futures), [], 0, 0
    try:
        while pending:
            try:
                finished, pending = distributed.wait(list(pending), timeout=refresh, return_when='FIRST_COMPLETED')
                pending = set(pending)
            except (TimeoutError, distributed.TimeoutError):
                finished = set()
            for future in finished:
                spec = spec_of[future.key]
                if future.status == 'finished':
                    result = future.result()
                else:  # raised after its retries, lost its worker too often (KilledWorker), or cancelled
                    try:
                        exception = future.exception()
                    except Exception as err:  # a cancelled future raises instead
                        exception = err
                    result = _failure_result(spec, exception)
                    _write_status(spec, result)
                results.append(result)
                done += result['status'] == 'done'
                failed += result['status'] != 'done'
                _report(progress, result, plan['output_dir'])
                future.release()
            progress.update(done, failed, _running(client, pending))
    finally:
        progress.close()
    return results


def _running(client, pending):
    """Tasks of ``pending`` that workers are processing now (at most one per worker thread)."""
    if not pending:
        return 0
    try:
        keys = {future.key for future in pending}
        processing = client.processing()
        threads = sum(client.nthreads().values())
    except Exception:  # the scheduler is busy or gone: the count is only for display
        return 0
    return min(threads, sum(1 for tasks in processing.values() for key in tasks if key in keys))


def thread_environment(threads):
    """Variables that give each worker process ``threads`` OpenMP/BLAS threads."""
    value = str(int(threads))
    return {'OMP_NUM_THREADS': value, 'OPENBLAS_NUM_THREADS': value, 'MKL_NUM_THREADS': value}


SCRATCH_NAME = 'dask-scratch'


def scratch_directory(output_dir):
    """Dask's scratch space of a local cluster: ``output_dir/dask-scratch`` (not a shared /tmp folder)."""
    return os.path.join(os.path.abspath(output_dir), SCRATCH_NAME)


def local_address(address):
    """``address`` of a local dashboard bound to this machine only: ':8787' -> '127.0.0.1:8787' (None stays None).

    A bare port (Dask's ':8787') would listen on every interface, so anyone
    on the network could watch and drive the cluster; give a host
    explicitly (``--dashboard-address 0.0.0.0:8787``) to serve it wider.
    """
    if address is None:
        return None
    address = str(address)
    return '127.0.0.1' + address if address.startswith(':') else address


def make_local_cluster(workers, omp_threads=None, retries=3, dashboard_address=':8787', local_directory=None):
    """A ``distributed.LocalCluster`` of ``workers`` processes, one task thread each.

    The scheduler and the dashboard listen on 127.0.0.1 only (a bare port
    ``:8787`` becomes ``127.0.0.1:8787``; see ``local_address``).  Dask's
    scratch space goes to ``local_directory`` (the ensemble passes a folder
    inside its output folder; None: Dask's default under the temporary folder).

    Every worker gets ``omp_threads`` OpenMP/BLAS threads (default: the
    cores this process may run on divided by ``workers``, at least 1; ``mobility.threads``), set before the
    worker process starts, so the workers do not oversubscribe the cores.
    ``retries``: how often a task may lose its worker before it fails.
    """
    distributed = require_distributed()
    import dask
    if workers < 1:
        raise UserInputError('--workers must be at least 1 for a Dask cluster, got %d (0 runs in this process)'
                             % workers)
    threads = omp_threads or max(1, available_cores() // workers)
    environment = dict(dask.config.get('distributed.nanny.pre-spawn-environ', {}), **thread_environment(threads))
    with dask.config.set({'distributed.scheduler.allowed-failures': int(retries),
                          'distributed.nanny.pre-spawn-environ': environment}):
        return distributed.LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                        host='127.0.0.1', dashboard_address=local_address(dashboard_address),
                                        local_directory=local_directory)


JOBQUEUE_CLASSES = {'slurm': 'SLURMCluster', 'pbs': 'PBSCluster', 'lsf': 'LSFCluster'}


def jobqueue_arguments(kind, cores, memory, walltime=None, queue=None, account=None, omp_threads=1,
                       interface=None, extra_directives=(), log_directory=None, local_directory=None,
                       python=None, lifetime=None):
    """Keyword arguments of the dask-jobqueue cluster class for one batch job of ``cores`` cores.

    Each job runs ``cores // omp_threads`` worker processes of one task
    thread each; every worker's replica gets ``omp_threads`` OpenMP threads.
    ``lifetime`` (e.g. '3h50m', a little under the wall time) retires the
    workers of a job before the queue kills it (``--lifetime`` of dask-worker,
    staggered by 4 minutes), and a new job replaces it.
    """
    if kind not in JOBQUEUE_CLASSES:
        raise UserInputError('--jobqueue %s: choose one of %s' % (kind, ', '.join(sorted(JOBQUEUE_CLASSES))))
    if cores < 1 or omp_threads < 1 or cores % omp_threads:
        raise UserInputError('--job-cores %d must be a positive multiple of --omp-threads %d'
                             % (cores, omp_threads))
    if not memory:
        raise UserInputError('--jobqueue %s needs --job-memory (memory of one job, e.g. 64GB)' % kind)
    processes = cores // omp_threads
    package_root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    prologue = ['export %s=%s' % item for item in thread_environment(omp_threads).items()]
    prologue.append('export PYTHONPATH=%s${PYTHONPATH:+:$PYTHONPATH}' % package_root)  # the workers import us
    kwargs = {'cores': processes, 'processes': processes, 'memory': memory, 'job_script_prologue': prologue,
              'job_extra_directives': list(extra_directives)}
    if kind == 'slurm':
        kwargs['job_cpu'] = cores
    if lifetime:
        kwargs['worker_extra_args'] = ['--lifetime', lifetime, '--lifetime-stagger', '4m']
    for key, value in (('walltime', walltime), ('queue', queue), ('account', account), ('interface', interface),
                       ('log_directory', log_directory), ('local_directory', local_directory),
                       ('python', python)):
        if value:
            kwargs[key] = value
    return kwargs


def make_jobqueue_cluster(kind, jobs, retries=3, dashboard_address=':8787', **arguments):
    """A dask-jobqueue cluster (Slurm, PBS or LSF) scaled to ``jobs`` batch jobs (see :func:`jobqueue_arguments`).

    The scheduler runs in this process (on the login node); its dashboard is
    served at ``dashboard_address`` (None: on any free port).
    """
    dask_jobqueue = require_jobqueue()
    require_distributed()
    import dask
    kwargs = jobqueue_arguments(kind, **arguments)
    kwargs['scheduler_options'] = {'dashboard_address': dashboard_address or ':0'}  # None: any free port
    with dask.config.set({'distributed.scheduler.allowed-failures': int(retries)}):
        cluster = getattr(dask_jobqueue, JOBQUEUE_CLASSES[kind])(**kwargs)
    if jobs:
        # adaptive with a fixed size: a job that ends (wall time, node failure) is replaced by a new one
        cluster.adapt(minimum_jobs=jobs, maximum_jobs=jobs)
    return cluster
