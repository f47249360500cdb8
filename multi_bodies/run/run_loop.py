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
import sys
import time

import numpy as np

import utils
from multi_bodies.run import run_output


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
                  % run_output.write_error_line(err, 'the first files of the run', options.initial_step,
                                                None, again=options.initial_step))
        return 1
    first, last, n_save = options.initial_step, options.n_steps, options.n_save
    progress = run_output.Progress(program.progress_name, first, last)
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

    loop = run_output.TimeLoop(first, last, n_save, save_first=program.save_first)
    watch_steps = writers.watches_steps

    def advance(step):
        nonlocal state
        assert state.step == step, 'the run state is at step %d, the loop at %d' % (state.step, step)
        if program.interruptible:
            try:
                with stop.interrupting():
                    state = scheme.step(model, state)  # draws from a generator of the state's rng_state
            except run_output.StepInterrupted:
                if state.step == step:  # abandoned: the state (and its generator's) is the one before the step
                    raise run_output.StepInterrupted(completed=False)
                raise run_output.StepInterrupted(completed=True)
            except utils.SimulationStopped as err:  # the counts of the stopped step reach the counters file
                if err.state is not None:
                    state = err.state
                raise
        else:
            state = scheme.step(model, state)
        progress.after_step(step, program.iterations(state), program.invalid(state))
        if watch_steps and (step + 1) % n_save != 0:  # the grid's boundaries are offered by save
            offer(step + 1, 'step')

    with run_output.StopRequest() as stop:
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
            line = run_output.write_error_line(err, 'the outputs', loop.step, loop.saved)
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
            if not run_output.finish_run(options.output_name, start, first, loop.step, restart,
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
