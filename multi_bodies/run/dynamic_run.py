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
from body.body import Configuration
from multi_bodies.files.input_options import check_options
from multi_bodies.solver.counters import Counters
from multi_bodies.run import run_output
from multi_bodies.run.output_lock import output_lock
from multi_bodies.run.run_setup import prepare, start_output, write_articulated_copies, write_run_start
from quaternion_integrator.schemes import make_scheme

class DynamicRun:
    """Everything a dynamic run holds once it is set up (no file written yet).

    Attributes: options, hooks, bodies, types, system, scheme, rng,
    restart (the record of ``initial_step`` or None).
    """

    def __init__(self, options, print_residual=False, log=print, lock=None):
        self.options, self.log, self.lock = options, log, lock
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
        # Shared with the static and Monte Carlo scripts: checks, hooks, bodies, arrays, backends, Model, start check.
        setup = prepare(options, 'dynamics', print_residual=print_residual, log=log, restart_record=self.restart)
        self.hooks, self.bodies, self.types, self.system = setup.hooks, setup.bodies, setup.types, setup.system
        arrays = setup.body_arrays
        if self.scheme.dense or options.save_blobs_mobility or options.save_body_mobility:
            run_output.refuse_if_too_big(
                run_output.dense_memory(arrays.num_blobs, arrays.num_bodies),
                'the dense mobility of %d blobs (%s%s)' % (arrays.num_blobs, options.scheme,
                                                          ', save_*_mobility' if options.save_blobs_mobility or
                                                          options.save_body_mobility else ''),
                options.where('scheme'), 'choose an iterative scheme (without _dense_algebra) and leave '
                'save_blobs_mobility and save_body_mobility False, or fewer blobs')
        self.hydrogrid_plan = None
        if options.call_HydroGrid:  # its namelist read and its memory checked before anything is written
            from multi_bodies.analysis.hydrogrid import HydroGridPlan
            self.hydrogrid_plan = HydroGridPlan(options, log=log)
        self.fingerprint = run_output.run_fingerprint(options, self.types, self.bodies)
        use_record = True
        if options.initial_step > 0:  # exact, or refused (restart_inexact forces it, with a warning)
            start = self.system.start_configuration  # the snapshot as read
            use_record = run_output.check_restart(options, self.restart, self.types, self.fingerprint,
                                                  report=self.log_error,
                                                  configuration=(start.locations, start.orientations),
                                                  num_blobs=self.system.num_blobs)
        self.concentration_keep = None  # a restart keeps the .concentration blocks before its step
        if options.save_concentration and options.initial_step > 0 and self.restart is not None:
            from multi_bodies.run.concentration_output import is_phoretic, kept_bytes
            if is_phoretic(self.system):
                self.concentration_keep = kept_bytes(options, self.restart)
        self.rng = run_output.make_generator(options)  # its state goes into the run state (RunState.rng_state)
        self.rng_from_restart = False
        model = self.system
        start = self.scheme.init(model, model.start_configuration, step=options.initial_step,
                                 rng_state=self.rng.bit_generator.state)
        if self.restart is not None and self.restart.get('state') and use_record:
            state = self.restart['state']
            if state.get('rng') is not None:
                self.rng.bit_generator.state = state['rng']
                self.rng_from_restart = True
            configuration = model.start_configuration
            saved = state.get('locations'), state.get('orientations')
            # The snapshot files hold the same numbers, but their quaternions are renormalised when read
            # (SPEC 1.3); the record keeps them exactly as the uninterrupted run has them.
            current = configuration.locations
            if saved[0] is not None and np.shape(saved[0]) == current.shape and \
                    np.allclose(saved[0], current, rtol=0, atol=1e-12 * (1 + np.max(np.abs(saved[0])))):
                configuration = Configuration(saved[0], saved[1])
            start = self.scheme.init(model, configuration, step=options.initial_step, history=state.get('scheme'),
                                     counters=Counters.from_info(state.get('counters')),
                                     rng_state=self.rng.bit_generator.state)
        elif options.initial_step > 0:
            log('initial_step %d: no restart record in %s%s; the generator starts from seed/random_state and '
                'multistep schemes restart with one first-order step (as the published code does)'
                % (options.initial_step, options.output_name, run_output.RESTART_SUFFIX))
        self.start_state = start  # the run state before the first step (RunState, a value)
        run_output.warn_if_large_output(options, self.types, len(run_output.state_to_bytes(self.restart_state(start))),
                                        self.log)
        start_output(options)

    # -------------------------------------------------------------- output helpers
    def restart_state(self, state):
        """The restart record's state of RunState ``state`` (configuration, generator, history, counters)."""
        locations, orientations = state.configuration.copy_arrays()
        return {'locations': locations, 'orientations': orientations,
                'rng': state.rng_state, 'scheme': state.history(),
                'counters': self.counters(state)}

    def counters(self, state):
        """The run's counters for ``.info`` and the restart records (articulated: the nonlinear count too;
        phoretic bodies: the concentration solves' GMRES iterations)."""
        surface = self.system.surface
        return state.counters.info(articulated=self.system.articulated is not None,
                                   phoretic=surface is not None and surface.phoretic is not None)

    def write_info(self, state, extra_lines=()):
        run_output.write_info(self.options.output_name + '.info', self.counters(state), extra_lines)

    def run(self):
        """The time loop; returns the exit status."""
        options, model, scheme = self.options, self.system, self.scheme
        state = self.start_state
        restart = options.initial_step > 0
        try:
            writer, concentration = self.start_files(restart)
        except OSError as err:  # a full disk or a file-size limit before the first save: one line, the file named
            self.log_error('error: run stopped before its first step: %s'
                           % run_output.write_error_line(err, 'the first files of the run', options.initial_step,
                                                         None, again=options.initial_step))
            return 1
        first, last = options.initial_step, options.n_steps
        progress = run_output.Progress(options.scheme, first, last)
        status, stopped_line = 0, None
        start = time.perf_counter()

        def save(index):
            writer.save(index, state.configuration.locations, state.configuration.orientations,
                        self.restart_state(state))
            if options.save_blobs_mobility or options.save_body_mobility:
                self.save_mobilities(index, state.configuration)
            self.write_info(state)
            progress.at_save(index, state.counters.invalid_configurations)

        def save_stop(index):  # a signal stopped the run off the n_save grid: keep the last step completed
            self.writer.save(index, state.configuration.locations, state.configuration.orientations,
                             self.restart_state(state), stop=True,
                             side_offsets=concentration.offsets_at_stop() if concentration is not None else None)
            self.write_info(state)
            self.log('stopped by a signal: the snapshot of step %d is in %s%s and its restart record in %s%s '
                     '(restart with initial_step %d)' % (index, options.output_name, run_output.STOP_SUFFIX,
                                                         options.output_name, run_output.RESTART_SUFFIX, index))

        loop = run_output.TimeLoop(first, last, options.n_save)

        def advance(step):
            nonlocal state
            assert state.step == step, 'the run state is at step %d, the loop at %d' % (state.step, step)
            try:
                with stop.interrupting():
                    state = scheme.step(model, state)  # draws from a generator of state.rng_state
            except run_output.StepInterrupted:
                if state.step == step:  # abandoned: the state (and its generator's) is the one before the step
                    raise run_output.StepInterrupted(completed=False)
                raise run_output.StepInterrupted(completed=True)
            except utils.SimulationStopped as err:  # the counts of the stopped step reach .info
                if err.state is not None:
                    state = err.state
                raise
            progress.after_step(step, state.last_iterations, state.counters.invalid_configurations)

        with run_output.StopRequest() as stop:
            try:
                loop.run(save, advance, stop, save_stop)
                if loop.stopped and loop.complete:  # the signal came as the last step ended: nothing is lost
                    self.log('%s came after the last step: the run is complete' % stop.signal_name)
                elif loop.stopped:
                    stopped_line = stop.stopped_line(loop.step, loop.saved)
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
                                             lambda *lines: self.write_info(state, *lines),
                                             stopped_line) and status == 0:
                    status = 1
        if stopped_line and status != 1:
            if loop.stop_saved is not None:
                self.log_error('%s; the last step completed, %d, is saved (%s%s/): restart with initial_step %d'
                               % (stopped_line, loop.stop_saved, options.output_name, run_output.STOP_SUFFIX,
                                  loop.stop_saved))
            elif loop.stopped:
                self.log_error('%s; outputs are complete up to step %d, which is saved; restart with initial_step %d'
                               % (stopped_line, loop.step, loop.step))
            else:
                self.log_error('%s; outputs are complete up to step %d; restart with initial_step %d'
                               % (stopped_line, loop.last_saved, loop.last_saved))
        return status

    def start_files(self, restart):
        """The files a run writes before its time loop, and its writer: (writer, the ``.concentration`` writer or
        None).  Raises OSError when a file cannot be written."""
        options, model = self.options, self.system
        write_run_start(options, self.types, model.num_blobs, self.rng, restart=restart, log=self.log)
        write_articulated_copies(options)
        writer = run_output.SnapshotWriter(options.output_name, options.save_clones, self.types,
                                           options.where('save_clones'), restart=restart,
                                           restart_from=(self.restart, self.restart_end),
                                           fingerprint=self.fingerprint, log=self.log, lock=self.lock)
        self.writer = writer
        if options.save_vtk:  # blob and body .vtp files and .pvd collections (doc/visualisation.md)
            from multi_bodies.run.vtk_output import AlsoWriteVtk
            writer = AlsoWriteVtk(writer, options, self.types, model)
        concentration = None
        if options.save_concentration:  # phoretic runs: output_name.concentration (doc/phoretic.md)
            from multi_bodies.run.concentration_output import AlsoWriteConcentration
            writer = concentration = AlsoWriteConcentration(writer, options, model, keep=self.concentration_keep,
                                                            log=self.log)
        if options.call_HydroGrid:  # the published HydroGrid options, computed by the package (doc/analysis.md)
            from multi_bodies.analysis.hydrogrid import AlsoSampleStructureFactors
            writer = AlsoSampleStructureFactors(writer, options, log=self.log, plan=self.hydrogrid_plan)
        return writer, concentration

    def save_mobilities(self, step, configuration):
        """``save_blobs_mobility`` / ``save_body_mobility``: dense mobilities at the saved step's ``configuration``
        (SPEC 2.1)."""
        system = self.system
        stem = '%s.%%s.%s.dat' % (self.options.output_name, str(step).zfill(8))
        M, M_inv, _, N = system.dense_matrices(configuration, inverse=self.options.save_body_mobility)
        if self.options.save_blobs_mobility:
            run_output.save_table(stem % 'blobs_mobility', M)
        if self.options.save_body_mobility:
            if system.has_fixed_bodies:  # obstacles: the free bodies' mobility with the prescribed ones held
                from multi_bodies.solver.obstacles import dense_mixed_body_mobility
                N = dense_mixed_body_mobility(M_inv, system.dense_matrices(configuration, inverse=False)[2],
                                              system.fixed_bodies)[0]
            run_output.save_table(stem % 'body_mobility', N)

    def log_error(self, text):
        import sys
        print(text, file=sys.stderr, flush=True)


def run_dynamics(options, print_residual=False, log=print):
    """Set up and run the dynamics of validated ``options``; returns the exit status.

    ``output_name.lock`` is held from before the restart record is read until the run ends (one writer per
    output name, ``multi_bodies.run.output_lock``), and checked before every save."""
    with output_lock(options, log) as lock:
        return DynamicRun(options, print_residual=print_residual, log=log, lock=lock).run()
