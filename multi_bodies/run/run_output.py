"""Output of a run, shared by every script that writes one (library floor 3).

The dynamic script (``multi_bodies.py``), the Monte Carlo script
(``many_body_MCMC.py``), the ensemble runner and the single-body codes write
the same files with the same names (the manual's section 5.1):

* ``output_name.inputfile``: a copy of the input file (a restart appends the
  new input below a separator line, so both segments are kept);
* ``output_name.random_state``: the pickled state of the run's generator
  at the start of the run (or of the restart segment);
* ``output_name.<ID>.<step, 8 digits>.clones`` per structure and saved step
  (``save_clones one_file_per_step``), or ``output_name.<ID>.config`` with all
  snapshots of a structure one after another (``save_clones one_file``);
  numbers with round-trip precision (SPEC decision 4);
* ``output_name.restart``: one file per run holding, for every saved step,
  what an exact restart needs besides the snapshot: the generator state, the
  scheme history (Adams-Bashforth previous velocities, the configuration the
  preconditioner was built at, ...) and where the snapshot starts inside the
  ``.config`` files (restart from ``save_clones one_file``).  Records are
  appended, so what was saved before a hard stop stays readable;
* ``output_name.info``: counters (invalid configurations, iterations of the
  deterministic solves and of the noise), rewritten at every save, so even a
  killed run loses at most one save interval;
* ``output_name.time``: wall-clock seconds of the time loop (a restart
  appends one line per segment).

Nothing here knows about physics: the caller passes arrays and counters.
"""
import io
import os
import pickle
import shutil
import signal
import sys
import threading
import time

import numpy as np

from utils import UserInputError

RESTART_SUFFIX = '.restart'


# ------------------------------------------------------------------ names
def clones_name(output_name, structure_id, step):
    """Name of a saved snapshot: ``output_name.ID.<step, 8 digits>.clones`` (SPEC §2.1)."""
    return '%s.%s.%s.clones' % (output_name, structure_id, str(step).zfill(8))


def config_name(output_name, structure_id):
    """Name of the ``save_clones one_file`` series of one structure: ``output_name.ID.config``."""
    return '%s.%s.config' % (output_name, structure_id)


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


# ------------------------------------------------------------------ random generator
def load_random_state(path, where='random_state'):
    """The generator state in ``path``: the dict this package writes, or the published legacy tuple.

    Returns a ``numpy.random.Generator``.  Raises UserInputError (naming
    ``where``) when the file is missing or does not hold a numpy state.
    """
    try:
        with open(path, 'rb') as f:
            state = pickle.load(f)
    except FileNotFoundError:
        raise UserInputError('%s: the random state file %s does not exist' % (where, path))
    except IsADirectoryError:
        raise UserInputError('%s: the random state file %s is a folder' % (where, path))
    except Exception as err:  # not a pickle: any unpickling error
        raise UserInputError('%s: %s is not a random state file written by this package or the published code '
                             '(%s: %s); give a .random_state file, or use seed instead'
                             % (where, path, type(err).__name__, err))
    if isinstance(state, tuple) and state and state[0] == 'MT19937':
        # numpy.random.get_state() of the published code: ('MT19937', keys, pos, has_gauss, cached_gaussian)
        state = {'bit_generator': 'MT19937', 'state': {'key': np.asarray(state[1]), 'pos': int(state[2])}}
    name = state.get('bit_generator') if isinstance(state, dict) else None
    if not (isinstance(name, str) and isinstance(getattr(np.random, name, None), type)):
        raise UserInputError('%s: %s does not hold a numpy random state; give a .random_state file, or use seed '
                             'instead' % (where, path))
    try:
        bit_generator = getattr(np.random, name)()
        bit_generator.state = state
    except Exception as err:
        raise UserInputError('%s: %s holds a damaged random state (%s)' % (where, path, err))
    return np.random.Generator(bit_generator)


def make_generator(options):
    """The run's generator (SPEC decision 7): from ``random_state`` if given, else seeded by ``seed``.

    Without either, numpy seeds from the operating system (the state is
    still saved in ``.random_state``, so the run can be repeated).
    """
    if options.random_state is not None:
        return load_random_state(options.random_state, options.where('random_state'))
    if options.seed is not None and options.seed < 0:
        raise UserInputError('%s: seed must be a non-negative integer, got %d'
                             % (options.where('seed'), options.seed))
    return np.random.default_rng(options.seed)


def save_random_state(path, rng):
    """Pickle ``rng.bit_generator.state`` to ``path`` (readable by ``load_random_state``)."""
    atomic_write(path, pickle.dumps(rng.bit_generator.state), binary=True)


# ------------------------------------------------------------------ files
def atomic_write(path, data, binary=False):
    """Write ``data`` to ``path`` through a temporary file, so a stop never leaves a truncated file."""
    part = path + '.part'
    with open(part, 'wb' if binary else 'w') as f:
        f.write(data)
    os.replace(part, path)


def format_clones(locations, orientations):
    """Text of one snapshot: the count line, then ``x y z s p1 p2 p3`` per body with repr precision.

    locations: (n, 3); orientations: (n, 4) scalar-first quaternions.
    """
    rows = np.concatenate((np.asarray(locations, dtype=float).reshape(-1, 3),
                           np.asarray(orientations, dtype=float).reshape(-1, 4)), axis=1)
    out = io.StringIO()
    out.write('%d\n' % rows.shape[0])
    for row in rows:
        out.write(' '.join(repr(float(v)) for v in row))
        out.write('\n')
    return out.getvalue()


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
                path = config_name(output_name, structure_id)
                if os.path.isfile(path) and os.path.getsize(path) > offset:
                    os.truncate(path, offset)

    def save(self, step, locations, orientations, restart_state=None):
        """Write snapshot ``step`` of all structures; then append its restart record.

        locations (Nb, 3), orientations (Nb, 4); ``restart_state``: any
        picklable object the run needs to continue exactly from this step
        (generator state, scheme history).
        """
        offsets = {}
        start = 0
        for structure_id, count in self.types:
            text = format_clones(locations[start:start + count], orientations[start:start + count])
            start += count
            if self.save_clones == 'one_file_per_step':
                atomic_write(clones_name(self.output_name, structure_id, step), text)
            else:
                path = config_name(self.output_name, structure_id)
                mode = 'a' if self._started else 'w'
                with open(path, mode) as f:
                    offsets[structure_id] = f.tell() if mode == 'a' else 0
                    f.write(text)
                    f.flush()
        self._started = True
        record = {'step': int(step), 'config_offsets': offsets, 'state': restart_state}
        with open(self.restart_path, 'ab') as f:
            pickle.dump(record, f, protocol=pickle.HIGHEST_PROTOCOL)
            f.flush()


def read_restart_records(output_name):
    """All complete records of ``output_name.restart`` in the order written (a truncated tail is ignored)."""
    path = output_name + RESTART_SUFFIX
    records = []
    if not os.path.isfile(path):
        return records
    with open(path, 'rb') as f:
        while True:
            try:
                records.append(pickle.load(f))
            except EOFError:
                break
            except Exception:  # a record cut by a hard stop: everything before it is complete
                break
    return records


def restart_record(output_name, step):
    """The last restart record saved at ``step``, or None."""
    found = None
    for record in read_restart_records(output_name):
        if isinstance(record, dict) and record.get('step') == step:
            found = record
    return found


def read_config_snapshot(path, offset):
    """(locations (n, 3), orientations (n, 4)) of the snapshot starting at byte ``offset`` of a ``.config``."""
    with open(path) as f:
        f.seek(offset)
        count = int(f.readline().split()[0])
        rows = [f.readline().split() for _ in range(count)]
    data = np.array(rows, dtype=float).reshape(count, 7)
    return data[:, :3], data[:, 3:]


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
