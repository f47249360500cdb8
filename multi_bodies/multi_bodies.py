"""Deterministic and Brownian dynamics of many rigid multiblob bodies, or of single-blob rollers, above a wall.

Run from inside ``multi_bodies/`` (the manual's sections 5.1 to 5.3)::

    python multi_bodies.py --input-file inputfile_dynamic.dat [--print-residual]

The input file names the scheme (the deterministic schemes of doc/dynamics.md
and the stochastic schemes of doc/brownian.md, e.g. ``stochastic_Slip_Trapz``
and ``stochastic_adams_bashforth_rollers``), the time step and the bodies.
The run itself is ``multi_bodies.run.dynamic_run.run_dynamics``.  Outputs, all
prefixed by ``output_name``:

* ``.inputfile`` (copy of the input), ``.bodies_info``, ``.random_state``
  (state of the run's ``numpy.random.Generator`` as JSON text);
* per saved step and structure ``.<ID>.<step, 8 digits>.clones``
  (``save_clones one_file_per_step``) or one ``.<ID>.config`` per structure
  (``save_clones one_file``), numbers with round-trip precision;
* ``.restart`` (generator state and scheme history of every saved step, for
  exact restarts with ``initial_step``);
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
import sys

# The one path prelude of the scripts: the repository root first, then utils.prepare_script_path.
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import utils  # noqa: E402
utils.prepare_script_path(__file__)

from multi_bodies.run.dynamic_run import run_dynamics  # noqa: E402
from multi_bodies.files.input_options import read_input_file  # noqa: E402


def main(argv=None):
    """Command line entry; returns the exit status."""
    parser = argparse.ArgumentParser(description='Deterministic and Brownian dynamics of rigid multiblob bodies '
                                                 'and rollers above a wall (see doc/dynamics.md).')
    parser.add_argument('--input-file', default='data.main', help='input file (default data.main)')
    parser.add_argument('--print-residual', action='store_true', help='print every GMRES and Lanczos residual')
    args = parser.parse_args(argv)
    options = read_input_file(args.input_file, program='dynamic')  # this program's rules first, then its warnings
    status = run_dynamics(options, print_residual=args.print_residual)
    print('\n\n\n# End')
    return status


if __name__ == '__main__':
    sys.exit(utils.fail_cleanly(main))
