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
(times ``step * dt``; see ``multi_bodies/run/vtk_output.py`` and
doc/visualisation.md); ``--output-name`` gives them another prefix.  ``--wrap-periodic`` draws every body in the primary
box ``[0, L)`` of the periodic axes of ``periodic_length``.
"""
import argparse
import os
import sys

# The one path prelude of the scripts: the repository root first, then utils.prepare_script_path.
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import utils  # noqa: E402
utils.prepare_script_path(__file__)

from body.body import Configuration  # noqa: E402
from multi_bodies.files.input_options import read_input_file  # noqa: E402
from multi_bodies.run.vtk_output import (STATIC_SCHEMES, VtkSeries, collection_name, load_run,  # noqa: E402
                                     run_configurations, static_velocities)

def convert(options, wrap_periodic=False, vtk_name=None):
    """Write the VTK series of the run of ``options``; returns the number of steps written.

    ``vtk_name``: prefix of the VTK files (default the run's ``output_name``).
    """
    vtk_name = options.output_name if vtk_name is None else vtk_name
    body_arrays, types = load_run(options)
    folder = os.path.dirname(vtk_name)
    if folder:
        os.makedirs(folder, exist_ok=True)
    series = VtkSeries(vtk_name, [name for name, _ in types], [count for _, count in types],
                       options.dt, options.periodic_length, wrap_periodic=wrap_periodic)
    steps, locations, orientations = run_configurations(options, body_arrays, types)
    velocities = static_velocities(options, body_arrays.num_bodies) if options.scheme in STATIC_SCHEMES else None
    for step, step_locations, step_orientations in zip(steps, locations, orientations):
        series.write(int(step), body_arrays, Configuration(step_locations, step_orientations), velocities)
    series.close()
    written = len(steps)
    print('wrote %d step(s): %s and %s (open them in ParaView, see doc/visualisation.md)'
          % (written, collection_name(vtk_name, 'blobs'), collection_name(vtk_name, 'bodies')))
    return written


def main(argv=None):
    parser = argparse.ArgumentParser(description='Write the saved steps of a run as VTK files for ParaView '
                                                 '(see doc/visualisation.md).')
    parser.add_argument('--input-file', required=True, help='input file of the run')
    parser.add_argument('--wrap-periodic', action='store_true',
                        help='draw the bodies in the primary box [0, L) of the periodic axes of periodic_length')
    parser.add_argument('--output-name', default=None,
                        help='prefix of the VTK files (default: the output_name of the input file)')
    args = parser.parse_args(argv)
    options = read_input_file(args.input_file)
    convert(options, wrap_periodic=args.wrap_periodic, vtk_name=args.output_name)
    return 0


if __name__ == '__main__':
    sys.exit(utils.fail_cleanly(main))
