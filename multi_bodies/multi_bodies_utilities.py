"""Static problems of rigid multiblob bodies above a wall (the manual's section 4).

Run from inside ``multi_bodies/``::

    python multi_bodies_utilities.py --input-file inputfile_body_mobility.dat

Schemes (option ``scheme``):

* ``body_mobility``: dense body mobility ``pinv(K^T M^{-1} K)`` of all bodies
  -> ``output_name.body_mobility.dat`` (6Nb x 6Nb) and
  ``output_name.body_slip_mobility.dat`` (``N K^T M^{-1}``, 6Nb x 3N).
* ``mobility``: body velocities under given forces (``force_file``, or the
  default physics of ``multi_bodies_functions``) by preconditioned GMRES
  -> ``output_name.velocities.dat`` and ``output_name.force.dat`` (forces used).
* ``resistance``: forces and torques for given velocities (``velocity_file``,
  zero by default) by a dense solve -> ``output_name.force.dat``.

Every run writes ``output_name.inputfile`` and ``output_name.bodies_info``;
``plot_velocity_field`` adds ``output_name.velocity_field.vtk``.  Mistakes in
the input stop the run with one message naming file and line (exit status 2);
a GMRES solve that does not converge writes its results, says so and exits
with status 1.
"""
import argparse
import os
import shutil
import sys

_SCRIPT_DIR = os.path.dirname(os.path.abspath(__file__))
# The script's own folder holds multi_bodies.py, which would hide the package of the same name.
sys.path[:] = [p for p in sys.path if os.path.abspath(p or os.curdir) != _SCRIPT_DIR]
try:
    import multi_bodies.input_options  # noqa: F401
except ImportError:
    sys.path.insert(0, os.path.dirname(_SCRIPT_DIR))

import numpy as np  # noqa: E402

import mobility  # noqa: E402
import utils  # noqa: E402
from body.body import bodies_to_arrays  # noqa: E402
from multi_bodies import body_solver  # noqa: E402
from multi_bodies import multi_bodies_functions  # noqa: E402
from multi_bodies.input_options import read_input_file  # noqa: E402
from multi_bodies.run_setup import read_bodies, write_bodies_info  # noqa: E402
from multi_bodies.structure_files import read_body_table  # noqa: E402

SCHEMES = ('body_mobility', 'mobility', 'resistance')
WALL_FREE_SUFFIX = '_no_wall'


def backend(options, option_name, registry):
    """The function that ``registry`` (a mobility factory) gives for an option, with file and line on error."""
    name = getattr(options, option_name)
    try:
        return registry(name)
    except utils.UserInputError as err:
        raise utils.UserInputError('%s: %s: %s' % (options.where(option_name), option_name, err))


def check_above_wall(options, body_arrays, r_vectors, implementations):
    """Refuse configurations with a blob centre below the wall when a wall mobility is used."""
    if all(name.endswith(WALL_FREE_SUFFIX) for name in implementations):
        return
    below = body_arrays.check_positions(r_vectors)
    if below.size:
        first = int(below[0])
        spec_index = next(i for i, (bodies, _) in enumerate(body_arrays.type_slices)
                          if bodies.start <= first < bodies.stop)
        spec = options.structures[spec_index]
        raise utils.UserInputError(
            '%s: body %d of %s has a blob centre below the wall (z < 0); %d bodies are affected. '
            'Move the bodies up in the clones file.' % (spec.where, first - body_arrays.type_slices[spec_index][0].start,
                                                       spec.clones_file, below.size))


def physics_keywords(options):
    """Keyword arguments of the physics hooks (SPEC section 7)."""
    return dict(g=options.g, repulsion_strength_wall=options.repulsion_strength_wall,
                debye_length_wall=options.debye_length_wall, repulsion_strength=options.repulsion_strength,
                debye_length=options.debye_length, periodic_length=np.array(options.periodic_length),
                blob_radius=options.blob_radius, blob_mass=1.0)


def save_table(path, table):
    np.savetxt(path, table, delimiter='  ')


def run_body_mobility(options, body_arrays, r_vectors):
    blob_matrix = backend(options, 'mobility_blobs_implementation', mobility.blob_mobility_matrix)
    check_above_wall(options, body_arrays, r_vectors, [options.mobility_blobs_implementation])
    with utils.Timer() as timer:
        body_mobility, slip_mobility = body_solver.dense_body_mobility(
            body_arrays, r_vectors, blob_matrix, options.eta, options.blob_radius)
    print('Time to compute body mobility = %s' % timer.elapsed)
    save_table(options.output_name + '.body_mobility.dat', body_mobility)
    save_table(options.output_name + '.body_slip_mobility.dat', slip_mobility)
    return 0


def run_mobility(options, bodies, body_arrays, r_vectors):
    product = backend(options, 'mobility_vector_prod_implementation', mobility.mobility_vector_product)
    blob_matrix = backend(options, 'mobility_blobs_implementation', mobility.blob_mobility_matrix)
    check_above_wall(options, body_arrays, r_vectors, [options.mobility_vector_prod_implementation,
                                                       options.mobility_blobs_implementation])
    if options.force_file is not None:
        force_torque = read_body_table(options.force_file, body_arrays.num_bodies, 'force',
                                       options.where('force_file'))
    else:
        blob_blob = multi_bodies_functions.blob_blob_force_calculator(options.blob_blob_force_implementation)
        body_body = multi_bodies_functions.body_body_force_calculator(
            options.body_body_force_torque_implementation)
        force_torque = multi_bodies_functions.force_torque_calculator_sort_by_bodies(
            bodies, body_arrays, r_vectors, blob_blob_forces=blob_blob, body_body_forces=body_body,
            **physics_keywords(options)).reshape(-1, 6)
    slip = body_arrays.lab_frame_slip()
    with utils.Timer() as timer:
        operator = body_solver.saddle_point_operator(body_arrays, r_vectors, product, options.eta,
                                                     options.blob_radius, options.periodic_length)
        preconditioner = body_solver.BlockDiagonalPreconditioner(body_arrays, r_vectors, blob_matrix,
                                                                 options.eta, options.blob_radius)
        result = body_solver.solve_mobility_problem(operator, preconditioner,
                                                    body_solver.mobility_rhs(force_torque, slip),
                                                    body_arrays.num_blobs, options.solver_tolerance)
    print('Time to solve mobility problem = %s' % timer.elapsed)
    print('GMRES iterations = %d, converged = %s, relative residual = %.3e'
          % (result.iterations, result.converged, result.residual))
    save_table(options.output_name + '.velocities.dat', result.velocities)
    save_table(options.output_name + '.force.dat', force_torque.reshape(-1, 6))
    write_velocity_field(options, r_vectors, result.lambda_blobs)
    if not result.converged:
        print('error: GMRES did not converge to solver_tolerance %g in %d iterations (relative residual '
              '%.3e); the velocities written to %s are not converged'
              % (options.solver_tolerance, result.iterations, result.residual,
                 options.output_name + '.velocities.dat'), file=sys.stderr)
        return 1
    return 0


def run_resistance(options, body_arrays, r_vectors):
    blob_matrix = backend(options, 'mobility_blobs_implementation', mobility.blob_mobility_matrix)
    check_above_wall(options, body_arrays, r_vectors, [options.mobility_blobs_implementation])
    if options.velocity_file is not None:
        velocities = read_body_table(options.velocity_file, body_arrays.num_bodies, 'velocity',
                                     options.where('velocity_file'))
    else:
        velocities = np.zeros((body_arrays.num_bodies, 6))
    slip = body_arrays.lab_frame_slip()
    with utils.Timer() as timer:
        force_torque, lambda_blobs = body_solver.solve_resistance_problem(
            body_arrays, r_vectors, velocities, slip, blob_matrix, options.eta, options.blob_radius)
    print('Time to solve resistance problem = %s' % timer.elapsed)
    save_table(options.output_name + '.force.dat', force_torque)
    write_velocity_field(options, r_vectors, lambda_blobs)
    return 0


def write_velocity_field(options, r_vectors, lambda_blobs):
    """Write ``.velocity_field.vtk`` when ``plot_velocity_field`` is given."""
    if options.plot_velocity_field is None:
        return
    from multi_bodies import velocity_field
    product = backend(options, 'mobility_vector_prod_implementation', mobility.source_target_product)
    velocity = velocity_field.velocity_field(options.plot_velocity_field, r_vectors, lambda_blobs,
                                             options.blob_radius, options.tracer_radius, options.eta, product,
                                             options.periodic_length)
    path = velocity_field.write_velocity_field_vtk(options.output_name + '.velocity_field.vtk',
                                                   options.plot_velocity_field, velocity)
    print('plot_velocity_field: wrote %s' % path)


def main(argv=None):
    """Run the static problem of an input file; returns the exit status."""
    parser = argparse.ArgumentParser(description='Static problems (body_mobility, mobility, resistance) '
                                                 'of rigid multiblob bodies above a wall.')
    parser.add_argument('--input-file', required=True, help='input file (see doc/static_problems.md)')
    args = parser.parse_args(argv)

    options = read_input_file(args.input_file)
    if options.scheme not in SCHEMES:
        raise utils.UserInputError("%s: scheme '%s' is not a static problem; use one of %s"
                                   % (options.where('scheme'), options.scheme, ', '.join(SCHEMES)))
    if options.blob_radius <= 0 or options.eta <= 0:
        raise utils.UserInputError('%s: blob_radius and eta must be positive' % options.input_file)
    if options.tracer_radius < 0:
        raise utils.UserInputError('%s: tracer_radius must be >= 0' % options.where('tracer_radius'))
    bodies, types = read_bodies(options, multi_bodies_functions.set_slip_by_ID)

    output_dir = os.path.dirname(options.output_name)
    if output_dir:
        os.makedirs(output_dir, exist_ok=True)
    shutil.copyfile(args.input_file, options.output_name + '.inputfile')
    body_arrays = bodies_to_arrays(bodies, [count for _, count in types])
    r_vectors = body_arrays.blob_positions()
    write_bodies_info(options.output_name + '.bodies_info', types, body_arrays.num_blobs)

    if options.scheme == 'body_mobility':
        status = run_body_mobility(options, body_arrays, r_vectors)
    elif options.scheme == 'mobility':
        status = run_mobility(options, bodies, body_arrays, r_vectors)
    else:
        status = run_resistance(options, body_arrays, r_vectors)
    print('\n\n\n# End')
    return status


if __name__ == '__main__':
    sys.exit(utils.fail_cleanly(main))
