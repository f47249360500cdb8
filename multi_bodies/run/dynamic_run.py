"""One dynamic run from validated options: the library half of ``multi_bodies.py`` (top floor, with the scripts).

``run_dynamics(options)`` is what the dynamic script, the ensemble runner
and the tests call.  It wires the rooms together as the scripts do (set-up,
the scheme registry of ``quaternion_integrator``, the writers of
``multi_bodies.run.writers``), so it sits on the scripts' floor and only scripts and the
ensemble runner import it.  It sets the run up, runs the loop of
``multi_bodies.run.run_loop`` (Monte Carlo's too), writes every output through
the writers of ``multi_bodies.run.writers`` (the caller's own after the run's)
and returns the exit status (0 done, 1 stopped by the simulation, 130/143
stopped by SIGINT/SIGTERM).  User mistakes raise ``utils.UserInputError``
before the first byte is written.

Exact restarts (SPEC decision 11): every save appends a record to
``output_name.restart`` with the generator state, the scheme history and the
counters; ``initial_step k`` picks the record of step k up, so the restarted
run continues bit for bit the trajectory of an uninterrupted one.
"""
import numpy as np

import utils
from body.body import Configuration
from multi_bodies.files.input_options import check_options
from multi_bodies.solver.counters import Counters
from multi_bodies.run import run_output
from multi_bodies.run.output_lock import output_lock
from multi_bodies.run.run_loop import log_error, run_loop
from multi_bodies.run.run_setup import prepare, start_output, write_articulated_copies
from multi_bodies.run.writers import CallbackWriter, InfoWriter, RecordWriter, RunInfo, WriterSet
from quaternion_integrator.schemes import make_scheme

class DynamicRun:
    """Everything a dynamic run holds once it is set up (no file written yet).

    Attributes: options, hooks, bodies, types, system, scheme, rng,
    restart (the record of ``initial_step`` or None).
    """

    def __init__(self, options, print_residual=False, log=print, lock=None, writers=()):
        self.options, self.log, self.lock = options, log, lock
        self.user_writers = list(writers)  # the caller's own writers (multi_bodies.run.writers), after the run's
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
        self.writers = self.make_writers()
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

    # -------------------------------------------------------------- the run loop's program (run_loop)
    progress_name = property(lambda self: self.options.scheme)
    noun, info_name, interruptible, save_first = 'run', '.info', True, True
    model = property(lambda self: self.system)

    def arrays(self, state):
        return state.configuration.locations, state.configuration.orientations

    def invalid(self, state):
        return state.counters.invalid_configurations

    def iterations(self, state):
        return state.last_iterations

    def save_note(self, state):
        return ''

    def run(self):
        """The time loop (``multi_bodies.run.run_loop``); returns the exit status."""
        return run_loop(self, self.start_state)

    def make_writers(self):
        """The run's writers (``multi_bodies.run.writers``), in the order a save writes them: the
        ``.concentration`` block (it feeds the record), the snapshots and restart record, the VTK files, the
        HydroGrid samples, the dense mobilities, ``.info``, then the user's writers."""
        options, model = self.options, self.system
        snapshots = run_output.SnapshotWriter(options.output_name, options.save_clones, self.types,
                                              options.where('save_clones'), restart=options.initial_step > 0,
                                              restart_from=(self.restart, self.restart_end),
                                              fingerprint=self.fingerprint, log=self.log)
        self.writer = snapshots
        writers = []
        if options.save_concentration:  # phoretic runs: output_name.concentration (doc/phoretic.md)
            from multi_bodies.run.concentration_output import ConcentrationWriter
            writers.append(ConcentrationWriter(options, model, keep=self.concentration_keep, log=self.log))
        if options.save_vtk:  # blob and body .vtp files and .pvd collections (doc/visualisation.md)
            from multi_bodies.run.vtk_output import VtkWriter
            writers.append(VtkWriter(options, self.types, model))
        if options.call_HydroGrid:  # the published HydroGrid options, computed by the package (doc/analysis.md)
            from multi_bodies.analysis.hydrogrid import StructureFactorWriter
            writers.append(StructureFactorWriter(options, log=self.log, plan=self.hydrogrid_plan))
        if options.save_blobs_mobility or options.save_body_mobility:
            writers.append(CallbackWriter(lambda frame: self.save_mobilities(frame.step, frame.state.configuration)))
        writers.append(InfoWriter(self.write_info))
        return WriterSet(RecordWriter(snapshots, self.restart_state), writers + list(self.user_writers),
                         lock=self.lock)

    def start_files(self):
        """The files a run writes before its time loop, and every writer's ``open``.  Raises OSError when a file
        cannot be written."""
        self.writers.start(RunInfo(self.options, self.system, self.types, 'dynamics', log=self.log),
                           self.system.num_blobs, self.rng)
        write_articulated_copies(self.options)

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
        log_error(text)


def run_dynamics(options, print_residual=False, log=print, writers=()):
    """Set up and run the dynamics of validated ``options``; returns the exit status.

    ``writers``: the caller's own writers (``multi_bodies.run.writers.Writer``), written after the run's.
    ``output_name.lock`` is held from before the restart record is read until the run ends (one writer per
    output name, ``multi_bodies.run.output_lock``), and checked before every save."""
    with output_lock(options, log) as lock:
        return DynamicRun(options, print_residual=print_residual, log=log, lock=lock, writers=writers).run()
