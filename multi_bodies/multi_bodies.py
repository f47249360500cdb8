"""Deterministic dynamics of many rigid multiblob bodies, or of single-blob rollers, above a wall.

Run from inside ``multi_bodies/`` (the manual's sections 5.1 to 5.3)::

    python multi_bodies.py --input-file inputfile_dynamic.dat [--print-residual]

The input file names the scheme (``deterministic_forward_euler``,
``deterministic_forward_euler_dense_algebra``, ``deterministic_adams_bashforth``,
``deterministic_forward_euler_rollers``, ``deterministic_adams_bashforth_rollers``),
the time step and the bodies; see doc/dynamics.md.  Outputs, all prefixed by
``output_name``:

* ``.inputfile`` (copy of the input), ``.bodies_info``, ``.random_state``
  (pickled state of the run's ``numpy.random.Generator``);
* per saved step and structure ``.<ID>.<step, 8 digits>.clones``
  (``save_clones one_file_per_step``) or one ``.<ID>.config`` per structure
  (``save_clones one_file``), numbers with round-trip precision;
* ``.info`` (invalid configurations, GMRES and Lanczos iteration counts) and
  ``.time`` (wall-clock seconds of the time loop), also when a run stops early.

``user_defined_functions.py`` (and ``forces_pycuda_user_defined.py``) in the
run directory override the physics hooks.  Mistakes in the input stop the
run before it starts (exit status 2, no traceback); a run that cannot go on
(blob below the wall, NaN, GMRES failure) stops with a message after writing
complete files (exit status 1).
"""
import argparse
import os
import pickle
import shutil
import sys
import time

_SCRIPT_DIR = os.path.dirname(os.path.abspath(__file__))
# This script is called multi_bodies.py, like its package: keep its folder off sys.path.
sys.path[:] = [p for p in sys.path if os.path.abspath(p or os.curdir) != _SCRIPT_DIR]
if 'multi_bodies' in sys.modules and not hasattr(sys.modules['multi_bodies'], '__path__'):
    del sys.modules['multi_bodies']
try:
    import multi_bodies.input_options  # noqa: F401
except ImportError:
    sys.path.insert(0, os.path.dirname(_SCRIPT_DIR))

import numpy as np  # noqa: E402

import utils  # noqa: E402
from body.body import bodies_to_arrays  # noqa: E402
from multi_bodies import multi_bodies_functions  # noqa: E402
from multi_bodies.input_options import read_input_file  # noqa: E402
from multi_bodies.run_setup import clones_name, read_bodies, write_bodies_info  # noqa: E402
from multi_bodies.system import make_system  # noqa: E402
from quaternion_integrator.schemes import make_scheme  # noqa: E402


# ------------------------------------------------------------------ set-up
def make_generator(options):
    """The run's random generator (SPEC decision 7): restored from ``random_state``, else seeded by ``seed``.

    ``random_state`` may hold the pickled ``bit_generator.state`` dict this
    script writes, or the legacy tuple ('MT19937', keys, pos, ...) of
    ``numpy.random.get_state()`` written by the published code.
    """
    if options.random_state is not None:
        try:
            with open(options.random_state, 'rb') as f:
                state = pickle.load(f)
        except (OSError, pickle.UnpicklingError, EOFError) as err:
            raise utils.UserInputError('%s: cannot read the random state file %s (%s)'
                                       % (options.where('random_state'), options.random_state, err))
        if isinstance(state, tuple) and state and state[0] == 'MT19937':
            state = {'bit_generator': 'MT19937', 'state': {'key': np.asarray(state[1]), 'pos': int(state[2])}}
        if not (isinstance(state, dict) and hasattr(np.random, str(state.get('bit_generator')))):
            raise utils.UserInputError('%s: %s does not hold a numpy random state'
                                       % (options.where('random_state'), options.random_state))
        bit_generator = getattr(np.random, state['bit_generator'])()
        bit_generator.state = state
        return np.random.Generator(bit_generator)
    return np.random.default_rng(options.seed)


# ------------------------------------------------------------------ output while running
def format_clones(locations, orientations):
    """Text of one snapshot: the count line, then ``x y z s p1 p2 p3`` per body with repr precision."""
    rows = np.concatenate((locations, orientations), axis=1)
    return '%d\n' % rows.shape[0] + ''.join(' '.join(repr(float(v)) for v in row) + '\n' for row in rows)


def multistep_state_name(output_name, step):
    """File with the previous velocities of Adams-Bashforth at a saved step (for exact restarts)."""
    return '%s.previous_velocities.%s.dat' % (output_name, str(step).zfill(8))


def restore_multistep_state(options, scheme):
    """On a restart, give a two-step scheme the velocities of the step before ``initial_step``.

    Without that file (runs saved by the published code, or ``one_file``
    mode) the first step after the restart is a forward Euler step, as in
    the published code.
    """
    if options.initial_step <= 0 or not hasattr(scheme, 'previous_velocities'):
        return
    path = multistep_state_name(options.output_name, options.initial_step)
    if os.path.isfile(path):
        scheme.previous_velocities = np.loadtxt(path, ndmin=2)
        print('%s continues from the velocities saved in %s' % (options.scheme, path))
    else:
        print('%s restarts with one forward Euler step (%s not found)' % (options.scheme, path))


class SnapshotWriter:
    """Writes the configuration of every structure type at the saved steps."""

    def __init__(self, options, types, system, scheme=None):
        self.scheme = scheme
        if options.save_clones not in ('one_file_per_step', 'one_file'):
            raise utils.UserInputError("%s: save_clones must be one_file_per_step or one_file, got '%s'"
                                       % (options.where('save_clones'), options.save_clones))
        self.options, self.types, self.system = options, types, system

    def save(self, step):
        arrays = self.system.arrays
        start = 0
        for structure_id, count in self.types:
            text = format_clones(arrays.locations[start:start + count], arrays.orientations[start:start + count])
            start += count
            if self.options.save_clones == 'one_file_per_step':
                path = clones_name(self.options.output_name, structure_id, step)
                with open(path + '.part', 'w') as f:  # a stop mid-write never leaves a truncated .clones
                    f.write(text)
                os.replace(path + '.part', path)
            else:
                path = '%s.%s.config' % (self.options.output_name, structure_id)
                with open(path, 'w' if step == 0 else 'a') as f:
                    f.write(text)
        if self.options.save_blobs_mobility or self.options.save_body_mobility:
            self.save_mobilities(step)
        previous = getattr(self.scheme, 'previous_velocities', None)
        if previous is not None:  # what a two-step scheme needs to continue exactly from this step
            path = multistep_state_name(self.options.output_name, step)
            np.savetxt(path + '.part', np.asarray(previous).reshape(len(previous), -1), fmt='%.17g')
            os.replace(path + '.part', path)

    def save_mobilities(self, step):
        from multi_bodies import body_solver
        system = self.system
        r_vectors = system.blob_positions()
        stem = '%s.%%s.%s.dat' % (self.options.output_name, str(step).zfill(8))
        if self.options.save_blobs_mobility:
            np.savetxt(stem % 'blobs_mobility', system.blob_mobility_matrix(r_vectors, system.eta, system.blob_radius),
                       delimiter='  ')
        if self.options.save_body_mobility:
            body_mobility, _ = body_solver.dense_body_mobility(system.arrays, r_vectors, system.blob_mobility_matrix,
                                                               system.eta, system.blob_radius)
            np.savetxt(stem % 'body_mobility', body_mobility, delimiter='  ')


def write_info(path, invalid, deterministic, stochastic=0):
    with open(path, 'w') as f:
        f.write('invalid_configuration_count    = %d\n' % invalid)
        f.write('deterministic_iterations_count = %d\n' % deterministic)
        f.write('stochastic_iterations_count    = %d\n' % stochastic)


class Progress:
    """A line per save (step, time per step, GMRES iterations) and a bar on a terminal."""

    def __init__(self, scheme_name, first_step, last_step):
        self.scheme_name, self.first_step, self.last_step = scheme_name, first_step, last_step
        self.bar = sys.stdout.isatty()
        self.start = self.mark = time.perf_counter()
        self.steps_since, self.iterations_since = 0, 0

    def after_step(self, step, iterations):
        self.steps_since += 1
        self.iterations_since += iterations
        if self.bar:
            done = step + 1 - self.first_step
            total = max(1, self.last_step - self.first_step)
            width = 40
            filled = int(width * done / total)
            sys.stdout.write('\r[%s%s] %d/%d steps' % ('#' * filled, '.' * (width - filled), step + 1, self.last_step))
            sys.stdout.flush()

    def at_save(self, step, invalid):
        now = time.perf_counter()
        per_step = (now - self.mark) / self.steps_since if self.steps_since else 0.0
        if self.bar:
            sys.stdout.write('\r')
        print('Integrator = %s, step = %d, invalid configurations %d, wallclock time = %.6g s, '
              'time per step = %.4g s, GMRES iterations per step = %.3g'
              % (self.scheme_name, step, invalid, now - self.start, per_step,
                 self.iterations_since / self.steps_since if self.steps_since else 0.0), flush=True)
        self.mark, self.steps_since, self.iterations_since = now, 0, 0


# ------------------------------------------------------------------ the run
def has_wall(options, system):
    """False when no hydrodynamics sees a wall (``*_no_wall`` backends, or rollers in ``domain no_wall``)."""
    if 'rollers' in options.scheme:
        return options.domain != 'no_wall'
    return not (system.vector_product_name.endswith('_no_wall') and system.blobs_name.endswith('_no_wall'))


def check_start(options, system, types):
    """Refuse a start with a blob centre below the wall (runs with a wall only)."""
    if not system.check_wall:
        return
    invalid = system.invalid_bodies()
    if invalid.size:
        first = int(invalid[0])
        start = 0
        for (structure_id, count), spec in zip(types, options.structures):
            if first < start + count:
                raise utils.UserInputError('%s: body %d of %s starts with a blob centre below the wall (z < 0); '
                                           '%d bodies are affected. Move the bodies up in the clones file.'
                                           % (spec.where, first - start, structure_id, invalid.size))
            start += count


def run(options, print_residual=False):
    """Run the dynamics of validated ``options``; returns the exit status (0, or 1 when stopped)."""
    scheme = make_scheme(options.scheme, options.dt)
    for name in ('blob_radius', 'eta'):
        if not getattr(options, name) > 0:
            raise utils.UserInputError('%s: %s must be positive' % (options.where(name), name))
    if options.n_save < 1:
        raise utils.UserInputError('%s: n_save must be at least 1' % options.where('n_save'))
    if options.domain not in ('single_wall', 'no_wall'):
        raise utils.UserInputError("%s: domain must be single_wall or no_wall" % options.where('domain'))
    hooks = multi_bodies_functions.load_user_hooks(
        os.getcwd(), load_pycuda=options.blob_blob_force_implementation in ('pycuda', 'auto'))
    if hooks.overridden:
        print('user-defined physics from %s: %s' % (', '.join(hooks.sources), ', '.join(hooks.overridden)))
    bodies, types = read_bodies(options, hooks.set_slip_by_ID, single_blob_bodies='rollers' in options.scheme)
    body_arrays = bodies_to_arrays(bodies, [count for _, count in types])
    slips = [np.zeros((b.Nblobs, 3)) if b.slip_reference is None else b.slip_reference for b in bodies]
    body_arrays.reference_slip = np.concatenate(slips).reshape(-1, 3)
    system = make_system(options, bodies, body_arrays, hooks, print_residual=print_residual, log=print)
    print('mobility_vector_prod_implementation = %s, mobility_blobs_implementation = %s, '
          'blob_blob_force_implementation = %s' % (system.vector_product_name, system.blobs_name,
                                                   options.blob_blob_force_implementation))
    system.check_wall = has_wall(options, system)
    check_start(options, system, types)

    output_dir = os.path.dirname(options.output_name)
    if output_dir:
        os.makedirs(output_dir, exist_ok=True)
    copy = options.output_name + '.inputfile'
    if not (os.path.exists(copy) and os.path.samefile(options.input_file, copy)):
        shutil.copyfile(options.input_file, copy)
    rng = make_generator(options)
    with open(options.output_name + '.random_state', 'wb') as f:
        pickle.dump(rng.bit_generator.state, f)
    write_bodies_info(options.output_name + '.bodies_info', types, body_arrays.num_blobs)
    writer = SnapshotWriter(options, types, system, scheme)
    if options.save_vtk:  # blob and body .vtp files and .pvd collections beside the snapshots (doc/visualisation.md)
        from multi_bodies.vtk_output import AlsoWriteVtk
        writer = AlsoWriteVtk(writer, options, types, system)
    restore_multistep_state(options, scheme)

    first, last = options.initial_step, options.n_steps
    progress = Progress(options.scheme, first, last)
    status, step = 0, first
    start = time.perf_counter()
    try:
        for step in range(first, last):
            if step % options.n_save == 0:
                writer.save(step)
                progress.at_save(step, scheme.invalid_configurations)
            scheme.step(system, step, rng)
            progress.after_step(step, system.last_iterations)
        if last > first and last % options.n_save == 0:
            writer.save(last)
            progress.at_save(last, scheme.invalid_configurations)
        if last <= first:
            print('nothing to do: initial_step %d >= n_steps %d' % (first, last))
    except utils.SimulationStopped as err:
        if progress.bar:
            sys.stdout.write('\n')
        print('error: run stopped: %s%s Snapshots up to the last saved step are complete; .info and .time '
              'are written.' % (str(err).rstrip('.'), '.'), file=sys.stderr)
        status = 1
    finally:
        elapsed = time.perf_counter() - start
        with open(options.output_name + '.time', 'w') as f:
            f.write(str(elapsed) + '\n')
        write_info(options.output_name + '.info', scheme.invalid_configurations, system.gmres_iterations)
    return status


def main(argv=None):
    """Command line entry; returns the exit status."""
    parser = argparse.ArgumentParser(description='Deterministic dynamics of rigid multiblob bodies and rollers '
                                                 'above a wall (see doc/dynamics.md).')
    parser.add_argument('--input-file', default='data.main', help='input file (default data.main)')
    parser.add_argument('--print-residual', action='store_true', help='print every GMRES residual')
    args = parser.parse_args(argv)
    options = read_input_file(args.input_file)
    status = run(options, print_residual=args.print_residual)
    print('\n\n\n# End')
    return status


if __name__ == '__main__':
    sys.exit(utils.fail_cleanly(main))
