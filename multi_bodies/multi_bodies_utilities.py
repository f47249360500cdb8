"""Static problems of rigid multiblob bodies above a wall (the manual's section 4).

Run from inside ``multi_bodies/``::

    python multi_bodies_utilities.py --input-file inputfile_body_mobility.dat

Schemes (option ``scheme``):

* ``body_mobility``: dense body mobility ``pinv(K^T M^{-1} K)`` of all bodies
  -> ``output_name.body_mobility.dat`` (6Nb x 6Nb) and
  ``output_name.body_slip_mobility.dat`` (``N K^T M^{-1}``, 6Nb x 3N).
* ``mobility``: body velocities under given forces (``force_file``, or the
  physics hooks: defaults or the user's overrides) and the active slip, by
  preconditioned GMRES -> ``output_name.velocities.dat`` and
  ``output_name.force.dat`` (forces used).
* ``resistance``: forces and torques for given velocities (``velocity_file``,
  zero by default) and the active slip, by a dense solve -> ``output_name.force.dat``.

Obstacles (``obstacle`` lines) and bodies of prescribed velocity (a fourth
file on a ``structure`` line) keep their prescribed velocity (zero for an
obstacle) in every problem (``multi_bodies.solver.obstacles``): ``mobility``
solves the mixed problem (free bodies move, prescribed ones do not respond)
and writes, in the rows of prescribed bodies, their prescribed velocity to
``.velocities.dat`` and the force-torque that holds them to ``.force.dat``;
``body_mobility`` gives the mobility of the free bodies with the prescribed
ones held (zero rows and columns for the latter); ``resistance`` uses the
prescribed velocities for those bodies whatever ``velocity_file`` says.

The set-up (input checks, ``user_defined_functions.py`` overrides in either
style, bodies and their slip from ``set_slip_by_ID``, backends including
``auto``, start check) is ``run_setup.prepare``, shared with
``multi_bodies.py``; forces and slip come from the same ``Model`` methods
as in the dynamics.

Every run writes ``output_name.inputfile`` and ``output_name.bodies_info``;
``plot_velocity_field`` adds ``output_name.velocity_field.vtk``.  Like the
dynamic script it holds ``output_name.lock`` while it writes (one writer per
output name) and first moves the files of an earlier run with the same
``output_name`` to ``output_name.set_aside/``.  Mistakes in
the input stop the run with one message naming file and line (exit status 2);
a GMRES solve that does not converge writes its results, says so and exits
with status 1.
"""
import argparse
import os
import shutil
import sys

# The one path prelude of the scripts: the repository root first, then utils.prepare_script_path.
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import utils  # noqa: E402
utils.prepare_script_path(__file__)

import numpy as np  # noqa: E402

from multi_bodies.solver import body_solver  # noqa: E402
from multi_bodies.solver import obstacles  # noqa: E402
from multi_bodies.files.input_options import read_input_file  # noqa: E402
from multi_bodies.run import run_output  # noqa: E402
from multi_bodies.run.output_lock import output_lock  # noqa: E402
from multi_bodies.run.run_setup import STATIC_SCHEMES, prepare, set_aside_earlier_run, write_bodies_info  # noqa: E402
from multi_bodies.files.structure_files import read_body_table  # noqa: E402

SCHEMES = STATIC_SCHEMES


def save_table(path, table):
    run_output.save_table(path, table)


def run_body_mobility(options, system, configuration):
    with utils.Timer() as timer:
        if system.has_fixed_bodies:  # the free bodies' mobility with the prescribed ones held
            M, _, K, _ = system.dense_matrices(configuration, inverse=False)
            body_mobility, slip_mobility = obstacles.dense_mixed_body_mobility(np.linalg.inv(M), K,
                                                                               system.fixed_bodies)
        else:
            body_mobility, slip_mobility = body_solver.dense_body_mobility(system.arrays, configuration,
                                                                           system.dense_mobility)
    print('Time to compute body mobility = %s' % timer.elapsed)
    save_table(options.output_name + '.body_mobility.dat', body_mobility)
    save_table(options.output_name + '.body_slip_mobility.dat', slip_mobility)
    return 0


def forces_and_slip(options, system, configuration, force_table=None):
    """Force-torque (Nb, 6) from ``force_file`` (read beforehand: ``force_table``) or the hooks, and the
    slip (N, 3), at ``configuration``, as the dynamics computes them."""
    if force_table is not None:
        force_torque = force_table
    elif options.force_file is not None:
        force_torque = read_body_table(options.force_file, system.num_bodies, 'force', options.where('force_file'))
    else:
        force_torque = system.forces_torques(configuration)
    slip = system.slip(configuration) if system.has_slip else np.zeros((system.num_blobs, 3))
    return np.asarray(force_torque, dtype=float).reshape(-1, 6), slip


def run_mobility(options, system, configuration, force_table=None):
    force_torque, slip = forces_and_slip(options, system, configuration, force_table)
    with utils.Timer() as timer:
        # The same solve as every scheme, through the model's Solver (torques on single blobs and rods projected);
        # one that does not converge is flagged: its velocities are written and the script exits 1 (below).
        if system.articulated is not None:  # joints: doc/articulated.md (time t = 0)
            from multi_bodies.solver.articulated import articulated_problem
            problem, rhs, preconditioner = articulated_problem(system, system.articulated, configuration, 0.0,
                                                               force_torque, slip)
            r_vectors = problem.problem.r_vectors
        else:
            problem = system.mobility_problem(configuration)
            rhs = problem.rhs(slip=slip, force_torque=force_torque)
            preconditioner = system.build_preconditioner(configuration)
            r_vectors = problem.r_vectors
        result = system.solver(not_converged='flag').solve(problem, rhs, preconditioner,
                                                            tolerance=options.solver_tolerance)
    print('Time to solve mobility problem = %s' % timer.elapsed)
    print('GMRES iterations = %d, converged = %s, relative residual = %.3e'
          % (result.iterations, result.converged, result.residual))
    save_table(options.output_name + '.velocities.dat', result.velocities)
    if system.articulated is not None:  # joint forces (Nc, 3)
        save_table(options.output_name + '.force.dat', force_torque)
        save_table(options.output_name + '.joint_forces.dat', result.constraint_force_torque)
    else:
        if result.constraint_force_torque is not None:  # prescribed bodies: the force-torque that holds them
            force_torque = np.where(system.fixed_bodies[:, None], result.constraint_force_torque, force_torque)
        save_table(options.output_name + '.force.dat', force_torque)
    write_velocity_field(options, system, r_vectors, result.lambda_blobs)
    if not result.converged:
        print('error: GMRES did not converge to solver_tolerance %g in %d iterations (relative residual '
              '%.3e); the velocities written to %s are not converged'
              % (options.solver_tolerance, result.iterations, result.residual,
                 options.output_name + '.velocities.dat'), file=sys.stderr)
        return 1
    return 0


def run_resistance(options, system, configuration, velocity_table=None):
    if velocity_table is not None:
        velocities = velocity_table
    elif options.velocity_file is not None:
        velocities = read_body_table(options.velocity_file, system.num_bodies, 'velocity',
                                     options.where('velocity_file'))
    else:
        velocities = np.zeros((system.num_bodies, 6))
    if system.has_fixed_bodies:  # obstacles and bodies of prescribed velocity keep theirs
        velocities = np.where(system.fixed_bodies[:, None], system.prescribed_velocities, velocities)
    slip = system.slip(configuration) if system.has_slip else np.zeros((system.num_blobs, 3))
    with utils.Timer() as timer:
        force_torque, lambda_blobs = body_solver.solve_resistance_problem(
            system.arrays, configuration, velocities, slip, system.dense_mobility)
    print('Time to solve resistance problem = %s' % timer.elapsed)
    save_table(options.output_name + '.force.dat', force_torque)
    write_velocity_field(options, system, system.blob_positions(configuration), lambda_blobs)
    return 0


def write_velocity_field(options, system, r_vectors, lambda_blobs):
    """Write ``.velocity_field.vtk`` when ``plot_velocity_field`` is given."""
    if options.plot_velocity_field is None:
        return
    from multi_bodies.run import velocity_field
    check_velocity_field_mobility(options, system)
    # the source-target product of the run's vector mobility (its viscosity, box and per-blob radii if given)
    velocity = velocity_field.velocity_field(options.plot_velocity_field, r_vectors, lambda_blobs,
                                             options.tracer_radius, system.vector_mobility)
    path = velocity_field.write_velocity_field_vtk(options.output_name + '.velocity_field.vtk',
                                                   options.plot_velocity_field, velocity)
    print('plot_velocity_field: wrote %s' % path)


def check_velocity_field_mobility(options, system):
    """A UserInputError naming the option when the vector mobility has no source-target product."""
    try:
        system.vector_mobility.check_source_target()
    except utils.UserInputError as err:
        raise utils.UserInputError('%s: mobility_vector_prod_implementation: %s'
                                   % (options.where('mobility_vector_prod_implementation'), err))


def run(options):
    """Solve the static problem of validated ``options``; returns the exit status."""
    # Shared with multi_bodies.py: the option checks of the table (scheme a static problem, tracer_radius >= 0,
    # ...), hooks, bodies, arrays, backends, Model, start check.
    setup = prepare(options, 'static', log=print)
    system = setup.system
    if options.scheme != 'mobility' and getattr(system, 'articulated', None) is not None:
        raise utils.UserInputError("%s: with articulated bodies the static problem is 'mobility' (velocities "
                                   "of the joined bodies under given forces); %s ignores the joints"
                                   % (options.where('scheme'), options.scheme))
    # Everything is validated before the first byte is written: the tables the problem reads, the
    # source-target backend of the velocity field, the output folder.
    force_table = velocity_table = None
    if options.scheme == 'mobility' and options.force_file is not None:
        force_table = read_body_table(options.force_file, system.num_bodies, 'force', options.where('force_file'))
    if options.scheme == 'resistance' and options.velocity_file is not None:
        velocity_table = read_body_table(options.velocity_file, system.num_bodies, 'velocity',
                                         options.where('velocity_file'))
    if options.plot_velocity_field is not None and options.scheme != 'body_mobility':
        check_velocity_field_mobility(options, system)
        from multi_bodies.run import velocity_field
        velocity_field.check_grid(options.plot_velocity_field, system.num_blobs, options.where('plot_velocity_field'))
    if options.scheme in ('body_mobility', 'resistance'):  # dense algebra: refuse up front what cannot fit
        run_output.refuse_if_too_big(run_output.dense_memory(system.num_blobs, system.num_bodies),
                                     'the dense %s problem of %d blobs' % (options.scheme, system.num_blobs),
                                     options.where('scheme'), 'use fewer blobs (or the iterative mobility problem)')
    with output_lock(options, log=print):  # one writer per output name, as the dynamic and Monte Carlo runs
        set_aside_earlier_run(options, setup.types, log=print)
        return write_results(options, setup, force_table, velocity_table)


def write_results(options, setup, force_table=None, velocity_table=None):
    """Solve the static problem and write its files (the lock of ``output_name`` held, earlier files set aside)."""
    system = setup.system
    copy = options.output_name + '.inputfile'
    configuration = system.start_configuration
    try:
        if not (os.path.exists(copy) and os.path.samefile(options.input_file, copy)):
            shutil.copyfile(options.input_file, copy)
        write_bodies_info(options.output_name + '.bodies_info', setup.types, system.num_blobs)
        if options.scheme == 'body_mobility':
            return run_body_mobility(options, system, configuration)
        if options.scheme == 'mobility':
            return run_mobility(options, system, configuration, force_table)
        return run_resistance(options, system, configuration, velocity_table)
    except utils.SimulationStopped as err:  # a user-defined function failed, or forces/slip are not finite
        print('error: %s' % err, file=sys.stderr)
        return 1
    except np.linalg.LinAlgError as err:  # a singular blob mobility: blobs of a body merged in double precision
        print('error: the blob mobility is singular (%s): the blobs of a body coincide in double precision, '
              'for example a body very far from the origin; check the clones files' % err, file=sys.stderr)
        return 1
    except OSError as err:  # a full disk or a file-size limit: one line naming the file
        print('error: cannot write %s (%s); free space (or raise the file-size limit) and run again'
              % (getattr(err, 'filename2', None) or err.filename or 'the outputs of %s' % options.output_name,
                 err.strerror or err), file=sys.stderr)
        return 1


def main(argv=None):
    """Run the static problem of an input file; returns the exit status."""
    parser = argparse.ArgumentParser(description='Static problems (body_mobility, mobility, resistance) '
                                                 'of rigid multiblob bodies above a wall.')
    parser.add_argument('--input-file', required=True, help='input file (see doc/static_problems.md)')
    args = parser.parse_args(argv)
    options = read_input_file(args.input_file, program='static')  # this program's rules first, then its warnings
    status = run(options)
    print('\n\n\n# End')
    return status


if __name__ == '__main__':
    sys.exit(utils.fail_cleanly(main))
