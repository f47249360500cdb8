"""The run loop shared by the dynamic run and Monte Carlo (floor 6).

``run_loop(program, state)`` runs steps ``initial_step .. n_steps - 1`` of a program whose step is a
scheme-like step (``program.scheme.step(program.model, state) -> state``, the generator's state inside the run
state), offers every step boundary to the program's writers (``multi_bodies.run.writers.WriterSet``), stops
cleanly on SIGINT/SIGTERM, a stopped simulation, a full disk or a lost lock, and ends with ``.time`` and the
counters file.  It returns the exit status: 0 done, 1 stopped by the simulation or by a write error, 130/143
stopped by SIGINT/SIGTERM (the step reached is saved, so the restart from it is exact).

The program (``multi_bodies.run.dynamic_run.DynamicRun``, ``many_bodyMCMC.mcmc_run.MCMCRun``) gives:

* ``options``, ``model``, ``scheme``, ``writers`` (a WriterSet), ``log`` (callable(str));
* ``progress_name`` (the progress line's scheme name), ``noun`` ('run' or 'chain');
* ``interruptible``: a signal abandons the step in progress (the state before it is kept; a step must then leave
  its input state unchanged); otherwise the step in progress finishes first;
* ``save_first``: whether the first step is saved (a Monte Carlo restart does not write its snapshot again);
* ``start_files()``: the files before the first step (raises OSError);
* ``arrays(state)``: (locations (Nb, 3), orientations (Nb, 4)); ``write_info(state, extra_lines)``;
* ``invalid(state)``, ``iterations(state)`` (the progress line), ``save_note(state)`` (text after the save line).
"""
import contextlib
import signal
import sys
import threading
import time

import numpy as np

import utils
from multi_bodies.run import run_output
from multi_bodies.run.run_output import append_time


def log_error(text):
    print(text, file=sys.stderr, flush=True)


def run_loop(program, state):
    """Run ``program`` from the run state ``state``; returns the exit status (see the module docstring)."""
    options, model, scheme, writers = program.options, program.model, program.scheme, program.writers
    restart = options.initial_step > 0
    try:
        program.start_files()
    except OSError as err:  # a full disk or a file-size limit before the first save: one line, the file named
        log_error('error: run stopped before its first step: %s'
                  % write_error_line(err, 'the first files of the run', options.initial_step,
                                                None, again=options.initial_step))
        return 1
    first, last, n_save = options.initial_step, options.n_steps, options.n_save
    progress = Progress(program.progress_name, first, last)
    status, stopped_line = 0, None
    start = time.perf_counter()

    def offer(index, kind):
        locations, orientations = program.arrays(state)
        writers.write(writers.frame(index, kind, locations, orientations, state))

    def save(index):
        offer(index, 'save')
        progress.at_save(index, program.invalid(state), extra=program.save_note(state))

    def save_stop(index):  # a signal stopped the run off the n_save grid: keep the last step completed
        offer(index, 'stop')
        program.log('stopped by a signal: the snapshot of step %d is in %s%s and its restart record in %s%s '
                    '(restart with initial_step %d)' % (index, options.output_name, run_output.STOP_SUFFIX,
                                                        options.output_name, run_output.RESTART_SUFFIX, index))

    loop = TimeLoop(first, last, n_save, save_first=program.save_first)
    watch_steps = writers.watches_steps

    def advance(step):
        nonlocal state
        assert state.step == step, 'the run state is at step %d, the loop at %d' % (state.step, step)
        if program.interruptible:
            try:
                with stop.interrupting():
                    state = scheme.step(model, state)  # draws from a generator of the state's rng_state
            except StepInterrupted:
                if state.step == step:  # abandoned: the state (and its generator's) is the one before the step
                    raise StepInterrupted(completed=False)
                raise StepInterrupted(completed=True)
            except utils.SimulationStopped as err:  # the counts of the stopped step reach the counters file
                if err.state is not None:
                    state = err.state
                raise
        else:
            state = scheme.step(model, state)
        progress.after_step(step, program.iterations(state), program.invalid(state))
        if watch_steps and (step + 1) % n_save != 0:  # the grid's boundaries are offered by save
            offer(step + 1, 'step')

    with StopRequest() as stop:
        try:
            loop.run(save, advance, stop, save_stop)
            if loop.complete and last > first:
                offer(last, 'end')
            if loop.stopped and loop.complete:  # the signal came as the last step ended: nothing is lost
                program.log('%s came after the last step: the %s is complete' % (stop.signal_name, program.noun))
            elif loop.stopped:
                stopped_line = stop.stopped_line(loop.step, loop.saved)
                status = stop.exit_status
            if last <= first:
                program.log('nothing to do: initial_step %d >= n_steps %d' % (first, last))
        except (utils.SimulationStopped, np.linalg.LinAlgError) as err:
            if isinstance(err, np.linalg.LinAlgError):  # a singular blob mobility: blobs of a body merged
                err = utils.SimulationStopped('step %d of %s: the linear algebra failed (%s); the blobs of a '
                                              'body are too close to each other for their distance to the '
                                              'origin (check the positions and forces)'
                                              % (loop.step, options.scheme, err))
            progress.close()
            log_error('error: run stopped: %s. Snapshots up to the last saved step are complete; %s and .time '
                      'are written.' % (str(err).rstrip('.'), program.info_name))
            stopped_line = 'run stopped at step %d: %s' % (loop.step, str(err).rstrip('.'))
            status = 1
        except OSError as err:  # a full disk or a file-size limit: one line, what was appended taken back
            progress.close()
            line = write_error_line(err, 'the outputs', loop.step, loop.saved)
            log_error('error: run stopped: %s' % line)
            stopped_line = 'run stopped at step %d: %s' % (loop.step, line)
            status = 1
        except KeyboardInterrupt:
            stopped_line = 'run interrupted at step %d' % loop.step
            status = 130
        finally:
            progress.close()
            try:
                writers.close()
            except OSError as err:
                log_error('error: cannot close %s (%s)' % (getattr(err, 'filename', None) or 'an output file',
                                                           err.strerror or err))
                status = status or 1
            if not finish_run(options.output_name, start, first, loop.step, restart,
                                         lambda lines: program.write_info(state, lines),
                                         stopped_line) and status == 0:
                status = 1
    if stopped_line and status != 1:
        if loop.stop_saved is not None:
            log_error('%s; the last step completed, %d, is saved (%s%s/): restart with initial_step %d'
                      % (stopped_line, loop.stop_saved, options.output_name, run_output.STOP_SUFFIX,
                         loop.stop_saved))
        elif loop.stopped:
            log_error('%s; outputs are complete up to step %d, which is saved; restart with initial_step %d'
                      % (stopped_line, loop.step, loop.step))
        else:
            log_error('%s; outputs are complete up to step %d; restart with initial_step %d'
                      % (stopped_line, loop.last_saved, loop.last_saved))
    return status


# ------------------------------------------------------------------ stopping, the time loop, ending a run
SIGNAL_EXIT_STATUS = {signal.SIGINT: 130, signal.SIGTERM: 143}


class StepInterrupted(BaseException):
    """Raised by :class:`StopRequest`'s handler while a step may be interrupted (``StopRequest.interrupting``):
    the step in progress is abandoned at once (a BaseException, so that no ``except Exception`` of a scheme
    swallows it).  ``completed``: the step had ended when it was raised."""

    def __init__(self, completed=False):
        super().__init__('the step in progress was interrupted by a signal')
        self.completed = completed


class StopRequest:
    """Context manager: SIGINT/SIGTERM set ``signal_number``; the loop stops at the next step boundary.

    Inside :meth:`interrupting` (the dynamic run wraps each step in it) the first signal raises
    :class:`StepInterrupted` at once, so a slow step (a large solve) is abandoned within moments and the run keeps
    the last completed step; elsewhere (a save being written, a Monte Carlo step, which is short and is let
    finish) the signal is only noted and the loop stops after the save or step in progress.
    A second signal raises KeyboardInterrupt at once.  Handlers are only
    installed in the main thread (Dask workers run tasks in other threads).
    """

    def __init__(self):
        self.signal_number = None
        self._previous = {}
        self._interruptible = False

    def __enter__(self):
        if threading.current_thread() is threading.main_thread():
            for sig in SIGNAL_EXIT_STATUS:
                self._previous[sig] = signal.signal(sig, self._handle)
        return self

    def _handle(self, signal_number, frame):
        if self.signal_number is not None:  # a second signal: stop at once
            raise KeyboardInterrupt
        self.signal_number = signal_number
        if self._interruptible:
            self._interruptible = False
            raise StepInterrupted()

    @contextlib.contextmanager
    def interrupting(self):
        """The ``with`` block (one step) is abandoned by the first signal (StepInterrupted), also when the signal
        came before it began."""
        if self.signal_number is not None:
            raise StepInterrupted()
        self._interruptible = True
        try:
            yield
        finally:
            self._interruptible = False

    def __exit__(self, *exc):
        self._interruptible = False
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)
        return False

    @property
    def exit_status(self):
        return SIGNAL_EXIT_STATUS.get(self.signal_number, 0)

    @property
    def signal_name(self):
        return signal.Signals(self.signal_number).name

    def stopped_line(self, step, last_saved=None):
        """'run stopped by SIGTERM at step k (last saved step s)'."""
        text = 'run stopped by %s at step %d' % (self.signal_name, step)
        return text + (' (last saved step %d)' % last_saved if last_saved is not None else '')


class TimeLoop:
    """The loop over steps ``first .. last - 1`` of a dynamic or Monte Carlo run.

    ``run(save, advance, stop, save_stop)`` calls ``save(k)`` before step k when k is a
    multiple of ``n_save`` (and after the last step when ``last`` is one) and ``advance(k)`` for every step.
    When a signal is noted (``stop.signal_number``) after a step, or ``advance`` raises StepInterrupted (the step
    abandoned: the run is still at step k, or at k + 1 when the step had ended), the loop stops at the step
    reached, r, and keeps it: with ``save(r)`` when r is on the ``n_save`` grid (the series, where an
    uninterrupted run has it), else with ``save_stop(r)`` (beside the series), unless it is saved already or
    r = ``last`` off the grid (the run is complete: an uninterrupted run does not save it either).
    ``step`` is always the index of the step being (or next to be) run, so an error handler can name it;
    ``saved`` the last step saved on the grid (None before the first save), ``stop_saved`` the step saved by
    ``save_stop``, ``stopped`` whether a signal ended the loop, ``complete`` whether every step was run.
    ``save_first=False`` skips the save at ``first`` (a restart whose
    snapshot the earlier run wrote).
    """

    def __init__(self, first, last, n_save, save_first=True):
        self.first, self.last, self.n_save, self.save_first = first, last, n_save, save_first
        self.step = first
        self.saved = None  # the last step saved on the n_save grid
        self.stop_saved = None  # the step saved off the grid when a signal stopped the run
        self.stopped = False

    def _save(self, save, step):
        save(step)
        self.saved = step

    def run(self, save, advance, stop, save_stop=None):
        for self.step in range(self.first, self.last):
            if self.step % self.n_save == 0 and (self.save_first or self.step != self.first):
                self._save(save, self.step)
            try:
                advance(self.step)
            except StepInterrupted as interrupted:
                self._stop_at(self.step + (1 if interrupted.completed else 0), save, save_stop)
                return
            if stop.signal_number is not None:
                self._stop_at(self.step + 1, save, save_stop)
                return
        self.step = self.last
        if self.last > self.first and self.last % self.n_save == 0:
            self._save(save, self.last)

    def _stop_at(self, reached, save, save_stop):
        self.step, self.stopped = reached, True
        if reached == self.saved or (reached == self.first and not self.save_first):
            return  # saved already (the earlier run wrote the restart step)
        if reached % self.n_save == 0:
            self._save(save, reached)  # on the grid: in the series, as the uninterrupted run has it
        elif reached < self.last and save_stop is not None:
            save_stop(reached)
            self.stop_saved = reached

    @property
    def complete(self):
        """True when every step up to ``last`` was run."""
        return self.step >= self.last

    @property
    def last_saved(self):
        """The last step saved before ``step`` (for the stop message)."""
        if self.saved is not None:
            return self.saved
        return ((self.step - 1) // self.n_save) * self.n_save if self.step > self.first else self.first


def write_error_line(err, what, step, last_saved, again=0):
    """One line for an OSError while writing outputs (full disk, file-size limit, a lock taken, ...): the file
    (``what`` when the error names none), the step, what is complete and the ``initial_step`` to run again with
    (``last_saved``, or ``again`` when no step was saved)."""
    name = getattr(err, 'filename2', None) or getattr(err, 'filename', None)  # a copy's target, else the file
    hint = getattr(err, 'hint', 'free space (or raise the file-size limit) and restart')
    return ('cannot write %s at step %d (%s); %s. %s%s with initial_step %s'
            % (name or what, step, err.strerror or err,
               'outputs are complete up to step %s' % last_saved if last_saved is not None else 'no step was saved',
               hint[0].upper(), hint[1:], last_saved if last_saved is not None else again))


def finish_run(output_name, start, first, step, restart, write_info_lines, stopped_line=None):
    """End of a time loop, however it ended: ``.time`` (appended on a restart) and the last ``.info``.

    ``write_info_lines(extra_lines)`` writes the script's info file (``.info``,
    ``.MCMC_info``) with the given extra lines.
    """
    elapsed = time.perf_counter() - start
    failed = []
    for write in (lambda: append_time(output_name + '.time', elapsed, restart=restart,
                                      note=('restart segment, steps %d to %d' % (first, step)) if restart else None),
                  lambda: write_info_lines([stopped_line] if stopped_line else [])):
        try:  # each on its own: a full disk that refuses one still lets the other be tried
            write()
        except OSError as err:
            failed.append('%s (%s)' % (getattr(err, 'filename', None) or 'a file', err.strerror or err))
    if failed:
        print('error: cannot write %s' % ', '.join(failed), file=sys.stderr, flush=True)
    return not failed


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
        self.bar = utils.terminal_progress_bar(self.stream, max(0, last_step - first_step), 'step', leave=False)

    def _write(self, text):
        utils.write_progress_line(self.bar, self.stream, text)

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
