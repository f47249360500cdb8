"""One Monte Carlo run from validated options: the library function behind ``many_body_MCMC.py``.

``run_mcmc(options)`` sets the run up (bodies, potentials, energy backend,
generator), writes every output through ``multi_bodies.run.run_output`` and
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
import time

import numpy as np

import utils
from body.body import bodies_to_arrays
from many_bodyMCMC import mcmc_energy
from many_bodyMCMC.sampler import MOVES, MetropolisSampler
from multi_bodies.solver import physics as multi_bodies_functions
from multi_bodies.run import run_output
from multi_bodies.files.input_options import OPTION_TABLE
from multi_bodies.run.run_setup import read_bodies

# Options the sampler reads; any other option that the input file sets is reported as unused.
USED_OPTIONS = ('n_steps', 'initial_step', 'n_save', 'g', 'blob_radius', 'kT', 'output_name', 'random_state',
                'seed', 'repulsion_strength_wall', 'debye_length_wall', 'repulsion_strength', 'debye_length',
                'body_body_force_torque_implementation', 'save_clones', 'periodic_length', 'mcmc_move',
                'mcmc_energy_implementation', 'max_translation', 'max_angle_shift', 'n_burn_in',
                'target_acceptance')
INFO_SUFFIX = '.MCMC_info'


def unused_options(options):
    """Names of options set in the input file that the sampler does not use (dt, scheme, eta, ...)."""
    return [name for name in OPTION_TABLE if options.is_set(name) and name not in USED_OPTIONS]


def check_options(options):
    """Ranges the sampler needs, checked before anything is written."""
    positive = ('blob_radius', 'kT', 'debye_length', 'debye_length_wall')
    for name in positive:
        if not getattr(options, name) > 0:
            raise utils.UserInputError('%s: %s must be positive, got %g' % (options.where(name), name,
                                                                           getattr(options, name)))
    if options.n_save < 1:
        raise utils.UserInputError('%s: n_save must be at least 1' % options.where('n_save'))
    for name in ('n_steps', 'initial_step', 'n_burn_in'):
        if getattr(options, name) < 0:
            raise utils.UserInputError('%s: %s must be >= 0, got %d' % (options.where(name), name,
                                                                        getattr(options, name)))
    for name in ('max_translation', 'max_angle_shift'):
        if getattr(options, name) < 0:
            raise utils.UserInputError('%s: %s must be >= 0 (0 selects the default), got %g'
                                       % (options.where(name), name, getattr(options, name)))
    if not 0.0 < options.target_acceptance < 1.0:
        raise utils.UserInputError('%s: target_acceptance must lie between 0 and 1, got %g'
                                   % (options.where('target_acceptance'), options.target_acceptance))
    if options.mcmc_move not in MOVES:
        raise utils.UserInputError("%s: mcmc_move must be %s, got '%s'"
                                   % (options.where('mcmc_move'), ' or '.join(MOVES), options.mcmc_move))
    if options.body_body_force_torque_implementation not in ('None', 'python'):
        raise utils.UserInputError("%s: body_body_force_torque_implementation must be None or python, got '%s'"
                                   % (options.where('body_body_force_torque_implementation'),
                                      options.body_body_force_torque_implementation))
    if options.save_clones not in ('one_file_per_step', 'one_file'):
        raise utils.UserInputError("%s: save_clones must be one_file_per_step or one_file, got '%s'"
                                   % (options.where('save_clones'), options.save_clones))


def _no_slip(body, slip, **kwargs):
    body.slip_reference = None




class MCMCRun:
    """A Monte Carlo run once set up (no file written yet).

    Attributes: options, hooks, bodies, types, energy, sampler, rng, restart.
    """

    def __init__(self, options, directory=None, log=print):
        self.options, self.log = options, log
        check_options(options)
        unused = unused_options(options)
        if unused:
            log('warning: %s: the Monte Carlo sampler does not use %s (ignored)'
                % (options.input_file, ', '.join(unused)))
        directory = os.getcwd() if directory is None else directory
        self.hooks = mcmc_energy.load_user_potentials(
            directory, default_body_body=options.body_body_force_torque_implementation == 'python')
        if os.path.isfile(os.path.join(directory, multi_bodies_functions.USER_FILE)):
            log('warning: %s holds forces for multi_bodies.py and is not read by the sampler; its potentials go '
                'in %s (doc/mcmc.md)' % (multi_bodies_functions.USER_FILE, mcmc_energy.USER_POTENTIAL_FILE))
        self.restart = None
        if options.initial_step > 0:
            self.restart = run_output.restart_record(options.output_name, options.initial_step)
        bodies, types = read_bodies(options, _no_slip, restart_record=self.restart)
        if any(spec.slip_file for spec in options.structures):
            log('warning: slip files on structure lines are ignored by the Monte Carlo sampler')
        self.bodies, self.types = bodies, types
        arrays = bodies_to_arrays(bodies, [count for _, count in types])
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
        self.rng = run_output.make_generator(options)
        if self.restart is not None and (self.restart.get('state') or {}).get('sampler') is not None:
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
        run_output.prepare_output_directory(options.output_name, options.where('output_name'))

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

    def restart_state(self):
        return {'rng': self.rng.bit_generator.state, 'sampler': self.sampler.get_state()}

    def write_info(self, extra_lines=()):
        text = '\n'.join(self.sampler.info_lines() + list(extra_lines)) + '\n'
        run_output.atomic_write(self.options.output_name + INFO_SUFFIX, text)

    def run(self):
        """The Monte Carlo loop; returns the exit status."""
        options, sampler = self.options, self.sampler
        restart = options.initial_step > 0
        run_output.copy_input_file(options.input_file, options.output_name, restart=restart)
        if not restart:
            run_output.save_random_state(options.output_name + '.random_state', self.rng)
        run_output.write_bodies_info(options.output_name + '.bodies_info', self.types,
                                     self.energy.arrays.num_blobs)
        writer = run_output.SnapshotWriter(options.output_name, options.save_clones, self.types,
                                           options.where('save_clones'), restart=restart)
        first, last = options.initial_step, options.n_steps
        name = 'MCMC_' + options.mcmc_move
        progress = run_output.Progress(name, first, last)
        status, stopped_line = 0, None
        start = time.perf_counter()

        def save(index):
            writer.save(index, sampler.locations, sampler.orientations, self.restart_state())
            self.write_info()
            progress.at_save(index, sampler.invalid, extra=', acceptance ratio = %.4g' % sampler.acceptance_ratio())

        # a restart does not write its first snapshot again (the run before wrote it)
        loop = run_output.TimeLoop(first, last, options.n_save, save_first=not restart)

        def advance(step):
            sampler.step(step, self.rng)
            progress.after_step(step, 0, sampler.invalid)

        stop = run_output.StopRequest()
        try:
            with stop:
                loop.run(save, advance, stop)
            if stop.signal_number is not None:
                stopped_line = stop.stopped_line(loop.step)
                status = stop.exit_status
            if last <= first:
                self.log('nothing to do: initial_step %d >= n_steps %d' % (first, last))
        except KeyboardInterrupt:
            stopped_line = 'run interrupted at step %d' % loop.step
            status = 130
        finally:
            progress.close()
            run_output.finish_run(options.output_name, start, first, loop.step, restart, self.write_info,
                                  stopped_line)
        if stopped_line:
            print('%s; outputs are complete up to the last saved step; restart with initial_step set to that step'
                  % stopped_line, file=sys.stderr, flush=True)
        return status


def run_mcmc(options, directory=None, log=print):
    """Set up and run the Monte Carlo chain of validated ``options``; returns the exit status."""
    return MCMCRun(options, directory=directory, log=log).run()


