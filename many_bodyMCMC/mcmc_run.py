"""One Monte Carlo run from validated options: the library function behind ``many_body_MCMC.py``.

``run_mcmc(options)`` sets the run up (bodies, potentials, energy backend,
generator), runs the chain on the dynamic run's loop (``multi_bodies.run.run_loop``:
the step is ``sampler.MetropolisChain.step``, state in, state out, the generator's
state in the ``ChainState``), writes every output through the writers of
``multi_bodies.run.writers`` (the caller's own after the chain's) and
returns the exit status (0 done; 130 or 143 when SIGINT or SIGTERM stopped it after
the step in progress, with every file complete).  Outputs, prefixed by
``output_name``: ``.inputfile``, ``.random_state``, ``.bodies_info``,
snapshots with the names and formats of the dynamic script (``save_clones``),
``.restart`` (one record per saved step: generator, chain state), ``.time``
and ``.MCMC_info``.  A restart with ``initial_step`` equal to a saved step
continues the uninterrupted chain exactly.
"""
import os
import sys

import numpy as np

import utils
from many_bodyMCMC import mcmc_energy
from many_bodyMCMC.sampler import MetropolisChain, MetropolisSampler
from multi_bodies.solver import physics as multi_bodies_functions
from multi_bodies.run import run_output
from multi_bodies.run.output_lock import output_lock
from multi_bodies.files.input_options import check_options, unused_options
from multi_bodies.run.run_loop import run_loop
from multi_bodies.run.run_setup import prepare, start_output
from multi_bodies.run.writers import InfoWriter, RecordWriter, RunInfo, WriterSet

INFO_SUFFIX = '.MCMC_info'


def _no_slip(body, slip, **kwargs):
    body.slip_reference = None


def load_potentials(options, directory, log=print):
    """The hook loader of the sampler for ``run_setup.prepare``: ``user_defined_potentials.py`` (and the GPU
    file) of ``directory``; a ``user_defined_functions.py`` there is reported as not read."""
    hooks = mcmc_energy.load_user_potentials(
        directory, default_body_body=options.body_body_force_torque_implementation == 'python')
    if os.path.isfile(os.path.join(directory, multi_bodies_functions.USER_FILE)):
        log('warning: %s holds forces for multi_bodies.py and is not read by the sampler; its potentials go '
            'in %s (doc/mcmc.md)' % (multi_bodies_functions.USER_FILE, mcmc_energy.USER_POTENTIAL_FILE))
    return hooks


class MCMCRun:
    """A Monte Carlo run once set up (no file written yet).

    Attributes: options, hooks, bodies, types, energy, sampler, rng, restart.
    """

    def __init__(self, options, directory=None, log=print, lock=None, writers=()):
        self.options, self.log, self.lock = options, log, lock
        check_options(options, 'mcmc')  # the table's rules (kT > 0, n_save >= 1, ...) before any file is read
        unused = unused_options(options, 'mcmc')
        if unused:
            log('warning: %s: the Monte Carlo sampler does not use %s (ignored)'
                % (options.input_file, ', '.join(unused)))
        self.restart, self.restart_end = None, None
        if options.initial_step > 0:
            self.restart, self.restart_end = run_output.find_restart_record(options.output_name,
                                                                            options.initial_step)
        # Shared with the dynamic and static scripts: checks, hooks (here the potentials), bodies, arrays.
        setup = prepare(options, 'mcmc', log=log, directory=directory, restart_record=self.restart,
                        hook_loader=load_potentials, set_slip_by_ID=_no_slip)
        self.hooks, self.bodies, self.types, arrays = setup.hooks, setup.bodies, setup.types, setup.body_arrays
        bodies = self.bodies
        if any(spec.slip_file for spec in options.structures):
            log('warning: slip files on structure lines are ignored by the Monte Carlo sampler')
        keywords = mcmc_energy.physics_keywords(options)
        pair_sums, notes = mcmc_energy.make_pair_sums(options.mcmc_energy_implementation, keywords, self.hooks,
                                                      options.where('mcmc_energy_implementation'))
        for note in notes:
            log('warning: ' + note)
        self.energy = mcmc_energy.MCMCEnergy(arrays, keywords, self.hooks, pair_sums)
        if self.hooks.overridden:
            log('user-defined potentials from %s: %s' % (', '.join(self.hooks.sources),
                                                          ', '.join(self.hooks.overridden)))
        self.check_periodic_bodies(bodies)
        max_translation = options.max_translation or 0.1 * options.blob_radius
        longest = max(b.body_length for b in bodies)
        max_angle_shift = options.max_angle_shift or max_translation / longest
        self.sampler = MetropolisSampler(self.energy, arrays.locations, arrays.orientations, options.kT,
                                         max_translation, max_angle_shift, options.mcmc_move, options.n_burn_in,
                                         options.target_acceptance)
        self.fingerprint = run_output.run_fingerprint(options, self.types, bodies, directory)
        use_record = True
        if options.initial_step > 0:  # exact, or refused (restart_inexact forces it, with a warning)
            use_record = run_output.check_restart(options, self.restart, self.types, self.fingerprint,
                                                  report=lambda text: print('warning: ' + text, file=sys.stderr),
                                                  program='mcmc')
        self.rng = run_output.make_generator(options)
        if use_record and self.restart is not None and (self.restart.get('state') or {}).get('sampler') is not None:
            state = self.restart['state']
            saved = state['sampler']
            same = (np.allclose(saved['locations'], arrays.locations, rtol=0, atol=1e-10)
                    and np.allclose(saved['orientations'], arrays.orientations, rtol=0, atol=1e-10))
            if not same:
                raise utils.UserInputError(
                    '%s: the snapshot of step %d differs from the configuration recorded in %s%s; restart from an '
                    'unedited snapshot' % (options.where('initial_step'), options.initial_step, options.output_name,
                                           run_output.RESTART_SUFFIX))
            self.sampler.set_state(saved)
            self.rng.bit_generator.state = state['rng']
        elif options.initial_step > 0:
            log('initial_step %d: no restart record in %s%s; the chain continues from the snapshot with fresh '
                'counters and the generator of seed/random_state' % (options.initial_step, options.output_name,
                                                                       run_output.RESTART_SUFFIX))
        self.check_start()
        log('Monte Carlo: %d bodies, %d blobs, mcmc_move %s, blob-blob energy %s, max_translation %g, '
            'max_angle_shift %g' % (arrays.num_bodies, arrays.num_blobs, options.mcmc_move, pair_sums.name,
                                    self.sampler.max_translation, self.sampler.max_angle_shift))
        run_output.warn_if_large_output(options, self.types, len(run_output.state_to_bytes(self.restart_state())),
                                        log)
        self.model = self.energy
        self.scheme = MetropolisChain(self.sampler)  # the step of the run loop
        self.start_state = self.scheme.init(options.initial_step, self.rng.bit_generator.state)  # a value
        self.writers = self.make_writers(writers)
        start_output(options)

    def check_periodic_bodies(self, bodies):
        """One-body moves leave the pairs inside a body out; with a box they must not wrap around it."""
        L = np.asarray(self.options.periodic_length, dtype=float)
        if self.options.mcmc_move != 'one_body' or not np.any(L > 0):
            return
        shortest = np.min(L[L > 0])
        longest = max(b.body_length for b in bodies)
        if longest >= 0.5 * shortest:
            raise utils.UserInputError('%s: mcmc_move one_body needs bodies shorter than half the periodic box '
                                       '(body length %g, box %g); use mcmc_move all_bodies or a larger box'
                                       % (self.options.where('periodic_length'), longest, shortest))

    def check_start(self):
        """Refuse a start with a blob centre at or below the wall, or another infinite energy."""
        if np.isfinite(self.sampler.current_energy):
            return
        below = np.unique(self.energy.arrays.blob_body_index[self.sampler.r_vectors[:, 2] <= 0.0])
        start = 0
        for (structure_id, count), spec in zip(self.types, self.options.structures):
            if below.size and below[0] < start + count:
                raise utils.UserInputError('%s: body %d of %s starts with a blob centre at or below the wall '
                                           '(z <= 0); %d bodies are affected. Move the bodies up in the clones '
                                           'file.' % (spec.where, below[0] - start, structure_id, below.size))
            start += count
        raise utils.UserInputError('%s: the starting configuration has energy %r (check the potentials of %s and '
                                   'the clones files)' % (self.options.input_file, self.sampler.current_energy,
                                                          ', '.join(self.hooks.sources) or 'the input'))

    def restart_state(self, state=None):
        """The restart record's state of the chain state ``state`` (the chain as it is now by default)."""
        if state is None:
            return {'rng': self.rng.bit_generator.state, 'sampler': self.sampler.get_state()}
        return {'rng': state.rng_state, 'sampler': state.sampler_record()}

    def write_info(self, state=None, extra_lines=()):
        """``.MCMC_info`` of the chain state ``state`` (the chain as it is now by default)."""
        if state is not None:
            self.sampler.load(state)
        text = '\n'.join(self.sampler.info_lines() + list(extra_lines)) + '\n'
        run_output.atomic_write(self.options.output_name + INFO_SUFFIX, text)

    # -------------------------------------------------------------- the run loop's program (run_loop)
    noun, info_name, interruptible = 'chain', INFO_SUFFIX, False

    @property
    def progress_name(self):
        return 'MCMC_' + self.options.mcmc_move

    @property
    def save_first(self):
        # a restart does not write its first snapshot again (the run before wrote it), unless that step was
        # saved beside the series when a signal stopped the run
        return self.options.initial_step == 0 or bool((self.restart or {}).get('stop'))

    def arrays(self, state):
        return state.locations, state.orientations

    def invalid(self, state):
        return state.invalid

    def iterations(self, state):
        return 0

    def save_note(self, state):
        return ', acceptance ratio = %.4g' % state.acceptance_ratio()

    def make_writers(self, writers=()):
        """The chain's writers (``multi_bodies.run.writers``): the snapshots and restart record, ``.MCMC_info``,
        then the user's ``writers``."""
        options = self.options
        snapshots = run_output.SnapshotWriter(options.output_name, options.save_clones, self.types,
                                              options.where('save_clones'), restart=options.initial_step > 0,
                                              restart_from=(self.restart, self.restart_end),
                                              fingerprint=self.fingerprint, log=self.log)
        return WriterSet(RecordWriter(snapshots, self.restart_state),
                         [InfoWriter(self.write_info)] + list(writers), lock=self.lock)

    def start_files(self):
        self.writers.start(RunInfo(self.options, self.energy, self.types, 'mcmc', log=self.log, dt=0.0),
                           self.energy.arrays.num_blobs, self.rng)

    def run(self):
        """The Monte Carlo loop (``multi_bodies.run.run_loop``, as the dynamic run's); returns the exit status."""
        return run_loop(self, self.start_state)


def run_mcmc(options, directory=None, log=print, writers=()):
    """Set up and run the Monte Carlo chain of validated ``options``; returns the exit status.

    ``writers``: the caller's own writers (``multi_bodies.run.writers.Writer``), written after the chain's.
    ``output_name.lock`` is held from before the restart record is read until the chain ends."""
    with output_lock(options, log) as lock:
        return MCMCRun(options, directory=directory, log=log, lock=lock, writers=writers).run()


