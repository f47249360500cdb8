"""Writers: one protocol for everything a run writes while it runs (floor 6, beside the run loop).

A *writer* is an object with a *trigger* and four methods (the model is HOOMD-blue's writers and triggers,
in this package's words):

* ``open(run)``: once, before the first step; ``run`` is a :class:`RunInfo` (output name, first and last step,
  ``n_save``, ``dt``, whether the run is a restart, the model, the structure types, the log);
* ``write(frame)``: when ``trigger(frame)`` is true; ``frame`` is a :class:`Frame` (step, kind, time,
  ``locations`` (Nb, 3), ``orientations`` (Nb, 4), the run state);
* ``flush()``: after every save of the run (the files are complete at each save, as the snapshots are);
* ``close()``: once, however the run ended.

A trigger is a callable ``trigger(frame) -> bool``: :class:`Periodic` (every n steps), :class:`OnSave` (the
run's ``n_save`` grid, and the step a signal stopped the run at when asked), :class:`AtEnd` (once, after the last
step of a run that completed), :class:`AnyOf`.  The run loop (``multi_bodies.run.run_loop``) offers a frame at
every step boundary: kind ``'save'`` on the ``n_save`` grid (and after the last step when it is on it), ``'step'``
at the other boundaries (only built when a writer's trigger can fire there), ``'stop'`` at the step a signal
stopped the run at when that step is off the grid, ``'end'`` once after a complete run.

The dynamic run, Monte Carlo and the ensembles' replicas (which are dynamic runs) hand their writers to one
:class:`WriterSet`, which applies the data-safety rules of issue 48 in one place:

* the output lock (``output_lock.HeldLock``) is checked before any writer writes a save;
* a new run moves the files of an earlier run with the same ``output_name`` aside before anything is written,
  the names of every writer's ``suffixes`` included (:meth:`WriterSet.start`);
* a restart cuts what a side file holds after the restart step through :meth:`RunInfo.set_aside_tail` (copied and
  synced into ``output_name.set_aside/`` before the cut);
* the writers that come before the record writer in a save (``feeds_record``) put their byte ranges into the
  step's restart record (``frame.side_files``) and take their bytes back when the record could not be written
  (``take_back``): a step is saved with all its files or with none.
"""
import os

from multi_bodies.run import run_output
from multi_bodies.run.run_setup import write_run_start


# ------------------------------------------------------------------ triggers
class Trigger:
    """When a writer writes: ``trigger(frame) -> bool``.  ``steps``: whether it can fire at a boundary off the
    ``n_save`` grid (the loop builds those frames only when some trigger can)."""
    steps = False

    def __call__(self, frame):
        raise NotImplementedError


class Periodic(Trigger):
    """Every ``period`` steps, at the steps k with ``(k - phase) % period == 0`` (on the save grid or off it)."""
    steps = True

    def __init__(self, period, phase=0):
        if int(period) < 1:
            raise ValueError('a Periodic trigger needs a period of at least one step, got %r' % (period,))
        self.period, self.phase = int(period), int(phase)

    def __call__(self, frame):
        return frame.kind in ('save', 'step') and (frame.step - self.phase) % self.period == 0


class OnSave(Trigger):
    """At the run's saves (every ``n_save`` steps); ``stops=True``: also at the step a signal stopped the run at,
    when that step is off the grid (the snapshot, its record and the counters are kept there too)."""

    def __init__(self, stops=False):
        self.stops = bool(stops)

    def __call__(self, frame):
        return frame.kind == 'save' or (self.stops and frame.kind == 'stop')


class AtEnd(Trigger):
    """Once, after the last step of a run that ran every step (not after a stop: its restart continues)."""

    def __call__(self, frame):
        return frame.kind == 'end'


class AnyOf(Trigger):
    """Fires when any of ``triggers`` fires."""

    def __init__(self, *triggers):
        self.triggers = triggers
        self.steps = any(getattr(trigger, 'steps', True) for trigger in triggers)

    def __call__(self, frame):
        return any(trigger(frame) for trigger in self.triggers)


# ------------------------------------------------------------------ what a writer sees
class RunInfo:
    """What a writer's ``open`` is told about the run.

    Attributes: ``options`` (the run's Options), ``output_name``, ``first_step`` (``initial_step``), ``last_step``
    (``n_steps``), ``n_save``, ``dt`` (0 for Monte Carlo: a step's time is the step), ``restart`` (bool),
    ``model`` (the dynamic run's model, or the Monte Carlo energy), ``types`` (list of (structure ID, bodies)),
    ``program`` ('dynamics' or 'mcmc'), ``log`` (callable(str)).
    """

    def __init__(self, options, model, types, program, log=print, dt=None):
        self.options, self.model, self.types, self.program, self.log = options, model, list(types), program, log
        self.output_name = options.output_name
        self.first_step, self.last_step, self.n_save = options.initial_step, options.n_steps, options.n_save
        self.dt = float(options.dt if dt is None else dt)
        self.restart = options.initial_step > 0

    def set_aside_tail(self, path, keep, why):
        """A restart's rule for a file it continues: the bytes of ``path`` after ``keep`` (what the abandoned
        continuation wrote) are copied, synced, into a new ``output_name.set_aside/<time>_<why>/`` and then cut
        off; returns that folder, or None when there was nothing after ``keep``."""
        if keep is None or not os.path.isfile(path) or os.path.getsize(path) <= keep:
            return None
        folder = run_output.aside_folder(self.output_name, why)
        run_output._save_tail(path, keep, folder)
        return folder


class Frame:
    """One moment of a run offered to the writers.

    Attributes: ``step`` (int), ``kind`` ('save', 'step', 'stop' or 'end'), ``time`` (``step * dt``; the step for
    Monte Carlo), ``locations`` (Nb, 3) and ``orientations`` (Nb, 4) scalar-first quaternions (the run's arrays:
    read them, do not change them), ``state`` (the run state: ``RunState`` of a dynamic run, ``ChainState`` of
    Monte Carlo), ``run`` (the :class:`RunInfo`), ``side_files`` ({kind: [start, end]}: byte ranges that the
    writers before the record writer add to the step's restart record).
    """

    def __init__(self, step, kind, locations, orientations, state, run):
        self.step, self.kind, self.state, self.run = int(step), kind, state, run
        self.locations, self.orientations = locations, orientations
        self.time = self.step * run.dt if run.dt > 0 else float(self.step)
        self.side_files = {}

    @property
    def configuration(self):
        """The frame's configuration as a ``body.body.Configuration``."""
        from body.body import Configuration
        return Configuration(self.locations, self.orientations)


# ------------------------------------------------------------------ the protocol
class Writer:
    """Base of the writers (the protocol, with methods that do nothing).

    ``trigger``: when it writes (default: the run's saves).  ``suffixes``: the names after ``output_name.`` of
    the files it writes (a new run sets an earlier run's aside).  ``feeds_record``: it runs before the record
    writer in a save and may put byte ranges into ``frame.side_files``; then ``take_back(frame)`` is called when
    the save fails before the record is written.
    """
    trigger = OnSave()
    suffixes = ()
    feeds_record = False

    def open(self, run):
        pass

    def write(self, frame):
        pass

    def take_back(self, frame):
        pass

    def flush(self):
        pass

    def close(self):
        pass


class RecordWriter(Writer):
    """The snapshots (``.clones`` files or ``.config`` series) and the restart record of every save (and of the
    step a signal stopped the run at), through ``run_output.SnapshotWriter``, which sets aside what an earlier
    run or the abandoned continuation of a restart left.

    ``snapshot_writer``: a ``run_output.SnapshotWriter``; ``restart_state(state)``: the record's state of a run
    state (generator, scheme or chain history, counters)."""
    trigger = OnSave(stops=True)

    def __init__(self, snapshot_writer, restart_state):
        self.snapshots, self.restart_state = snapshot_writer, restart_state

    def write(self, frame):
        self.snapshots.save(frame.step, frame.locations, frame.orientations, self.restart_state(frame.state),
                            stop=frame.kind == 'stop', side_offsets=frame.side_files or None)


class InfoWriter(Writer):
    """The counters file (``.info``, ``.MCMC_info``), rewritten at every save and at a stop: ``write_info(state)``
    writes it."""
    trigger = OnSave(stops=True)

    def __init__(self, write_info):
        self.write_info = write_info

    def write(self, frame):
        self.write_info(frame.state)


class CallbackWriter(Writer):
    """A writer made of a function: ``write(frame)`` calls ``function(frame)`` when ``trigger`` fires."""

    def __init__(self, function, trigger=None):
        self.function = function
        if trigger is not None:
            self.trigger = trigger

    def write(self, frame):
        self.function(frame)


class WriterSet:
    """The writers of one run, in the order they write a save: those that feed the record, the record writer,
    then the others (the program's first, then the user's).

    ``record_writer``: the :class:`RecordWriter`; ``writers``: the other writers; ``lock``: the run's
    ``output_lock.HeldLock`` or None, checked before every save.
    """

    def __init__(self, record_writer, writers=(), lock=None):
        writers = list(writers)
        self.before = [w for w in writers if getattr(w, 'feeds_record', False)]
        self.after = [w for w in writers if not getattr(w, 'feeds_record', False)]
        self.record_writer, self.lock = record_writer, lock
        self.all = self.before + [record_writer] + self.after
        self.watches_steps = any(getattr(w.trigger, 'steps', True) for w in self.all)
        self.run = None

    @property
    def suffixes(self):
        """The names after ``output_name.`` of the writers' own files (set aside for a new run)."""
        return tuple(name for w in self.all for name in getattr(w, 'suffixes', ()))

    def start(self, run, num_blobs, rng=None):
        """The first files of the run (``run_setup.write_run_start``: a new run sets the files of an earlier run
        with the same ``output_name`` aside first, the writers' own included), then every writer's ``open``."""
        self.run = run
        write_run_start(run.options, run.types, num_blobs, rng, restart=run.restart, log=run.log,
                        extra_suffixes=self.suffixes)
        for writer in self.all:
            writer.open(run)

    def frame(self, step, kind, locations, orientations, state):
        return Frame(step, kind, locations, orientations, state, self.run)

    def due(self, frame):
        """The writers whose trigger fires at ``frame``, in writing order."""
        return [w for w in self.all if w.trigger(frame)]

    def write(self, frame):
        """Write ``frame`` with the writers whose trigger fires.  A save (or stop) first checks the lock; when a
        writer before the record writer, or the record writer, fails, the writers before it take their bytes
        back (the step is not saved) and the error is raised; after a save every writer is flushed."""
        due = self.due(frame)
        if not due:
            return
        saving = frame.kind in ('save', 'stop')
        if saving and self.lock is not None:
            self.lock.check()
        done = []
        for writer in due:
            try:
                writer.write(frame)
            except BaseException:
                if writer is self.record_writer or writer in self.before:
                    for earlier in reversed(done):
                        if earlier in self.before:
                            earlier.take_back(frame)
                raise
            done.append(writer)
        if saving:
            self.flush()

    def flush(self):
        for writer in self.all:
            writer.flush()

    def close(self):
        """Close every writer (each on its own: one that fails does not keep the others open); the first error is
        raised after all were tried."""
        error = None
        for writer in self.all:
            try:
                writer.close()
            except Exception as err:  # noqa: BLE001 (raised below, after the others are closed)
                error = error or err
        if error is not None:
            raise error
