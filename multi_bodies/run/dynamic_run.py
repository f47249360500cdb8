"""One dynamic run from validated options: the library half of ``multi_bodies.py`` (top floor, with the scripts).

``run_dynamics(options)`` is what the dynamic script, the ensemble runner
and the tests call.  It wires the rooms together as the scripts do (set-up,
the scheme registry of ``quaternion_integrator``, the writers of
``run_output``), so it sits on the scripts' floor and only scripts and the
ensemble runner import it.  It sets the run up, writes every output through
``multi_bodies.run.run_output`` and returns the exit status (0 done, 1 stopped
by the simulation, 130/143 stopped by SIGINT/SIGTERM).  User mistakes raise
``utils.UserInputError`` before the first byte is written.

Exact restarts (SPEC decision 11): every save appends a record to
``output_name.restart`` with the generator state, the scheme history and the
counters; ``initial_step k`` picks the record of step k up, so the restarted
run continues bit for bit the trajectory of an uninterrupted one.
"""
import time

import numpy as np

import utils
from multi_bodies.files.input_options import check_options
from multi_bodies.run import run_output
from multi_bodies.run.output_lock import output_lock
from multi_bodies.run.run_setup import prepare, start_output, write_articulated_copies, write_run_start
from quaternion_integrator.schemes import make_scheme

class DynamicRun:
    """Everything a dynamic run holds once it is set up (no file written yet).

    Attributes: options, hooks, bodies, types, system, scheme, rng,
    restart (the record of ``initial_step`` or None).
    """

    def __init__(self, options, print_residual=False, log=print):
        self.options, self.log = options, log
        check_options(options, 'dynamic')  # the table's rules (dt > 0, n_save >= 1, ...) before the scheme is made
        try:
            self.scheme = make_scheme(options.scheme, options.dt, options)
        except utils.UserInputError as err:  # name the line of the scheme option (unless the message names one)
            if str(err).startswith(options.input_file):
                raise
            raise utils.UserInputError('%s: %s' % (options.where('scheme'), err))
        self.restart, self.restart_end = None, None
        if options.initial_step > 0:
            self.restart, self.restart_end = run_output.find_restart_record(options.output_name,
                                                                            options.initial_step)
        # Shared with the static and Monte Carlo scripts: checks, hooks, bodies, arrays, backends, System, start check.
        setup = prepare(options, 'dynamics', print_residual=print_residual, log=log, restart_record=self.restart)
        self.hooks, self.bodies, self.types, self.system = setup.hooks, setup.bodies, setup.types, setup.system
        arrays = setup.body_arrays
        dense = getattr(self.scheme, 'dense', False) or 'dense' in options.scheme  # Fixman, *_DLA, *_dense_algebra
        if dense or options.save_blobs_mobility or options.save_body_mobility:
            run_output.refuse_if_too_big(
                run_output.dense_memory(arrays.num_blobs, arrays.num_bodies),
                'the dense mobility of %d blobs (%s%s)' % (arrays.num_blobs, options.scheme,
                                                          ', save_*_mobility' if options.save_blobs_mobility or
                                                          options.save_body_mobility else ''),
                options.where('scheme'), 'choose an iterative scheme (without _dense_algebra) and leave '
                'save_blobs_mobility and save_body_mobility False, or fewer blobs')
        self.fingerprint = run_output.run_fingerprint(options, self.types, self.bodies)
        use_record = True
        if options.initial_step > 0:  # exact, or refused (restart_inexact forces it, with a warning)
            use_record = run_output.check_restart(options, self.restart, self.types, self.fingerprint,
                                                  report=self.log_error)
        self.rng = run_output.make_generator(options)
        self.rng_from_restart = False
        if self.restart is not None and self.restart.get('state') and use_record:
            state = self.restart['state']
            if state.get('rng') is not None:
                self.rng.bit_generator.state = state['rng']
                self.rng_from_restart = True
            self.scheme.set_history(state.get('scheme'))
            self.system.set_counters(state.get('counters') or {})
            if getattr(self.system, 'articulated', None) is not None:
                self.system.articulated.nonlinear_iterations = int(
                    (state.get('counters') or {}).get('nonlinear_iterations_count', 0))
            saved = state.get('locations'), state.get('orientations')
            # The snapshot files hold the same numbers, but their quaternions are renormalised when read
            # (SPEC 1.3); the record keeps them exactly as the uninterrupted run has them.
            current = self.system.configuration.locations
            if saved[0] is not None and np.shape(saved[0]) == current.shape and \
                    np.allclose(saved[0], current, rtol=0, atol=1e-12 * (1 + np.max(np.abs(saved[0])))):
                self.system.set_state(saved[0], saved[1])
        elif options.initial_step > 0:
            log('initial_step %d: no restart record in %s%s; the generator starts from seed/random_state and '
                'multistep schemes restart with one first-order step (as the published code does)'
                % (options.initial_step, options.output_name, run_output.RESTART_SUFFIX))
        run_output.warn_if_large_output(options, self.types, len(run_output.state_to_bytes(self.restart_state())),
                                        self.log)
        start_output(options)

    # -------------------------------------------------------------- output helpers
    def restart_state(self):
        locations, orientations = self.system.configuration.copy_arrays()
        return {'locations': locations, 'orientations': orientations,
                'rng': self.rng.bit_generator.state, 'scheme': self.scheme.get_history(),
                'counters': self.counters()}

    def counters(self):
        """The run's counters for ``.info`` and the restart records (articulated: the nonlinear count too)."""
        counters = self.system.counters(self.scheme)
        if getattr(self.system, 'articulated', None) is not None:  # the published count of the nonlinear solver
            counters['nonlinear_iterations_count'] = self.system.articulated.nonlinear_iterations
        return counters

    def write_info(self, extra_lines=()):
        run_output.write_info(self.options.output_name + '.info', self.counters(), extra_lines)

    def run(self):
        """The time loop; returns the exit status."""
        options, system, scheme = self.options, self.system, self.scheme
        restart = options.initial_step > 0
        write_run_start(options, self.types, system.num_blobs, self.rng, restart=restart)
        write_articulated_copies(options)
        writer = run_output.SnapshotWriter(options.output_name, options.save_clones, self.types,
                                           options.where('save_clones'), restart=restart,
                                           restart_from=(self.restart, self.restart_end),
                                           fingerprint=self.fingerprint, log=self.log)
        self.writer = writer
        if options.save_vtk:  # blob and body .vtp files and .pvd collections (doc/visualisation.md)
            from multi_bodies.run.vtk_output import AlsoWriteVtk
            writer = AlsoWriteVtk(writer, options, self.types, system)
        first, last = options.initial_step, options.n_steps
        progress = run_output.Progress(options.scheme, first, last)
        status, stopped_line = 0, None
        start = time.perf_counter()

        def save(index):
            writer.save(index, system.configuration.locations, system.configuration.orientations,
                        self.restart_state())
            if options.save_blobs_mobility or options.save_body_mobility:
                self.save_mobilities(index)
            self.write_info()
            progress.at_save(index, scheme.invalid_configurations)

        def save_stop(index):  # a signal stopped the run off the n_save grid: keep the step just finished
            self.writer.save(index, system.configuration.locations, system.configuration.orientations,
                             self.restart_state(), stop=True)
            self.write_info()
            self.log('stopped by a signal: the snapshot of step %d is in %s%s and its restart record in %s%s '
                     '(restart with initial_step %d)' % (index, options.output_name, run_output.STOP_SUFFIX,
                                                         options.output_name, run_output.RESTART_SUFFIX, index))

        loop = run_output.TimeLoop(first, last, options.n_save)

        def advance(step):
            scheme.step(system, step, self.rng)
            progress.after_step(step, system.last_iterations, scheme.invalid_configurations)

        with run_output.StopRequest() as stop:
            try:
                loop.run(save, advance, stop, save_stop)
                if stop.signal_number is not None:
                    stopped_line = stop.stopped_line(loop.step, loop.last_saved)
                    status = stop.exit_status
                if last <= first:
                    self.log('nothing to do: initial_step %d >= n_steps %d' % (first, last))
            except (utils.SimulationStopped, np.linalg.LinAlgError) as err:
                if isinstance(err, np.linalg.LinAlgError):  # a singular blob mobility: blobs of a body merged
                    err = utils.SimulationStopped('step %d of %s: the linear algebra failed (%s); the blobs of a '
                                                  'body are too close to each other for their distance to the '
                                                  'origin (check the positions and forces)'
                                                  % (loop.step, options.scheme, err))
                progress.close()
                self.log_error('error: run stopped: %s. Snapshots up to the last saved step are complete; .info '
                               'and .time are written.' % str(err).rstrip('.'))
                stopped_line = 'run stopped at step %d: %s' % (loop.step, str(err).rstrip('.'))
                status = 1
            except OSError as err:  # a full disk or a file-size limit: one line, what was appended taken back
                progress.close()
                line = run_output.write_error_line(err, 'the outputs', loop.step, loop.saved)
                self.log_error('error: run stopped: %s' % line)
                stopped_line = 'run stopped at step %d: %s' % (loop.step, line)
                status = 1
            except KeyboardInterrupt:
                stopped_line = 'run interrupted at step %d' % loop.step
                status = 130
            finally:
                progress.close()
                if not run_output.finish_run(options.output_name, start, first, loop.step, restart,
                                             self.write_info, stopped_line) and status == 0:
                    status = 1
        if stopped_line and status != 1:
            if loop.stop_saved is not None:
                self.log_error('%s; the step reached is saved too (%s%s/): restart with initial_step %d'
                               % (stopped_line, options.output_name, run_output.STOP_SUFFIX, loop.stop_saved))
            else:
                self.log_error('%s; outputs are complete up to step %d; restart with initial_step %d'
                               % (stopped_line, loop.last_saved, loop.last_saved))
        return status

    def save_mobilities(self, step):
        """``save_blobs_mobility`` / ``save_body_mobility``: dense mobilities of the saved step (SPEC 2.1)."""
        system = self.system
        stem = '%s.%%s.%s.dat' % (self.options.output_name, str(step).zfill(8))
        M, M_inv, _, N = system.dense_matrices(system.configuration, inverse=self.options.save_body_mobility)
        if self.options.save_blobs_mobility:
            np.savetxt(stem % 'blobs_mobility', M, delimiter='  ')
        if self.options.save_body_mobility:
            if system.has_fixed_bodies:  # obstacles: the free bodies' mobility with the prescribed ones held
                from multi_bodies.solver.obstacles import dense_mixed_body_mobility
                N = dense_mixed_body_mobility(M_inv, system.dense_matrices(system.configuration, inverse=False)[2],
                                              system.fixed_bodies)[0]
            np.savetxt(stem % 'body_mobility', N, delimiter='  ')

    def log_error(self, text):
        import sys
        print(text, file=sys.stderr, flush=True)


def run_dynamics(options, print_residual=False, log=print):
    """Set up and run the dynamics of validated ``options``; returns the exit status.

    ``output_name.lock`` is held from before the restart record is read until the run ends (one writer per
    output name, ``multi_bodies.run.output_lock``)."""
    with output_lock(options, log):
        return DynamicRun(options, print_residual=print_residual, log=log).run()
