"""Convert the saved snapshots of a run into VTK files that ParaView plays as an animation.

Run from the folder the run was started in (as the other scripts)::

    python clones_to_vtk.py --input-file inputfile_dynamic.dat [--wrap-periodic]

It reads the input file and the bodies as the scripts do, then the snapshots
that the run left (finished or stopped):

* dynamic and Monte Carlo runs, ``save_clones one_file_per_step``: every
  ``output_name.ID.<step>.clones`` saved for all structures;
* ``save_clones one_file``: the snapshots of ``output_name.ID.config``, at
  steps ``0, n_save, 2 n_save, ...``;
* static problems (schemes ``mobility``, ``resistance``, ``body_mobility``):
  the configuration of the input ``.clones`` files as step 0, with the body
  velocities of ``output_name.velocities.dat`` (scheme ``mobility``) or of
  ``velocity_file`` (``resistance``) when there are any.

It writes ``output_name.blobs.<step>.vtp``, ``output_name.bodies.<step>.vtp``
and the collections ``output_name.blobs.pvd`` and ``output_name.bodies.pvd``
(times ``step * dt``; see ``multi_bodies/vtk_output.py`` and
doc/visualisation.md).  ``--wrap-periodic`` draws every body in the primary
box ``[0, L)`` of the periodic axes of ``periodic_length``.
"""
import argparse
import os
import sys

_SCRIPT_DIR = os.path.dirname(os.path.abspath(__file__))
# The script's own folder holds multi_bodies.py, which would hide the package of the same name.
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
from multi_bodies.run_setup import read_bodies  # noqa: E402
from multi_bodies.structure_files import read_body_table  # noqa: E402

STATIC_SCHEMES = ('body_mobility', 'mobility', 'resistance')


def load_run(options):
    """Bodies of the input file: (BodyArrays with the slip of the slip files and hooks, types)."""
    hooks = multi_bodies_functions.load_user_hooks(os.getcwd(), load_pycuda=False)
    bodies, types = read_bodies(options, hooks.set_slip_by_ID)
    body_arrays = bodies_to_arrays(bodies, [count for _, count in types])
    slips = [np.zeros((b.Nblobs, 3)) if b.slip_reference is None else b.slip_reference for b in bodies]
    body_arrays.reference_slip = np.concatenate(slips).reshape(-1, 3)
    return body_arrays, types


def saved_snapshots(options, types):
    """Saved configurations of a dynamic or Monte Carlo run.

    Returns steps (S,) and, for all bodies in input order, locations
    (S, Nb, 3) and orientations (S, Nb, 4).
    """
    if options.save_clones == 'one_file':
        series = []
        for structure_id, count in types:
            path = '%s.%s.config' % (options.output_name, structure_id)
            series.append(utils.read_config_series(path))
        snapshots = min(s[0].shape[0] for s in series)
        steps = np.arange(snapshots) * options.n_save
        series = [(loc[:snapshots], ori[:snapshots]) for loc, ori in series]
    elif options.save_clones == 'one_file_per_step':
        saved = [set(utils.clones_series_steps(options.output_name, structure_id)[0]) for structure_id, _ in types]
        common = sorted(set.intersection(*saved))
        if not common:
            raise utils.UserInputError(
                'no saved step with a snapshot %s.<ID>.<step>.clones of every structure (%s); check output_name '
                'in %s and run from the folder the run was started in'
                % (options.output_name, ', '.join(name for name, _ in types), options.input_file))
        dropped = set.union(*saved) - set(common)
        if dropped:
            print('skipping %d step(s) not saved for every structure (a run stopped while saving?)' % len(dropped))
        series = [utils.read_clones_series(options.output_name, structure_id, common)[1:]
                  for structure_id, _ in types]
        steps = np.array(common, dtype=int)
    else:
        raise utils.UserInputError("%s: save_clones must be one_file_per_step or one_file, got '%s'"
                                   % (options.where('save_clones'), options.save_clones))
    for (structure_id, count), (locations, _) in zip(types, series):
        if locations.shape[1] != count:
            raise utils.UserInputError('the snapshots of %s hold %d bodies but its clones file in %s has %d; '
                                       'is this the input file of that run?'
                                       % (structure_id, locations.shape[1], options.input_file, count))
    return (steps, np.concatenate([s[0] for s in series], axis=1), np.concatenate([s[1] for s in series], axis=1))


def static_velocities(options, num_bodies):
    """Body velocities (Nb, 6) of a static problem, or None when the run has none to show."""
    if options.scheme == 'mobility':
        path = options.output_name + '.velocities.dat'
        if os.path.isfile(path):
            return read_body_table(path, num_bodies, 'velocity')
        print('%s not found: the body files carry no velocities (run multi_bodies_utilities.py first)' % path)
    if options.scheme == 'resistance' and options.velocity_file is not None:
        return read_body_table(options.velocity_file, num_bodies, 'velocity', options.where('velocity_file'))
    return None


def convert(options, wrap_periodic=False):
    """Write the VTK series of the run of ``options``; returns the number of steps written."""
    from multi_bodies.vtk_output import VtkSeries, collection_name, require_pyvista
    require_pyvista('clones_to_vtk.py')
    body_arrays, types = load_run(options)
    series = VtkSeries(options.output_name, [name for name, _ in types], [count for _, count in types],
                       options.dt, options.periodic_length, wrap_periodic=wrap_periodic)
    if options.scheme in STATIC_SCHEMES:
        series.write(0, body_arrays, static_velocities(options, body_arrays.num_bodies))
        written = 1
    else:
        steps, locations, orientations = saved_snapshots(options, types)
        for step, step_locations, step_orientations in zip(steps, locations, orientations):
            body_arrays.locations, body_arrays.orientations = step_locations, step_orientations
            series.write(int(step), body_arrays)
        written = len(steps)
    print('wrote %d step(s): %s and %s (open them in ParaView, see doc/visualisation.md)'
          % (written, collection_name(options.output_name, 'blobs'), collection_name(options.output_name, 'bodies')))
    return written


def main(argv=None):
    parser = argparse.ArgumentParser(description='Write the saved steps of a run as VTK files for ParaView '
                                                 '(see doc/visualisation.md).')
    parser.add_argument('--input-file', required=True, help='input file of the run')
    parser.add_argument('--wrap-periodic', action='store_true',
                        help='draw the bodies in the primary box [0, L) of the periodic axes of periodic_length')
    args = parser.parse_args(argv)
    options = read_input_file(args.input_file)
    convert(options, wrap_periodic=args.wrap_periodic)
    return 0


if __name__ == '__main__':
    sys.exit(utils.fail_cleanly(main))
