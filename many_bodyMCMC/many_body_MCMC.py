"""Markov chain Monte Carlo (Metropolis) sampler of rigid bodies above a wall (the manual's section 6).

Run from inside ``many_bodyMCMC/``, with the input file as the argument::

    python many_body_MCMC.py inputMCMC.dat

The input file uses the options of the dynamic code (``n_steps``,
``n_save``, ``kT``, ``g``, ``blob_radius``, wall and blob repulsion,
``periodic_length``, ``seed``, ``random_state``, ``save_clones``,
``initial_step``, ``output_name``, ``structure`` lines) plus the sampler's
own (``mcmc_move``, ``max_translation``, ``max_angle_shift``, ``n_burn_in``,
``target_acceptance``, ``mcmc_energy_implementation``); options it does not
use (``dt``, ``scheme``, ...) give a warning.  Outputs, prefixed by
``output_name``: ``.inputfile``, ``.random_state``, ``.bodies_info``,
snapshots named as the dynamic script names them, ``.restart``, ``.time``
and ``.MCMC_info``.  ``user_defined_potentials.py`` in the run directory
replaces the potentials; see doc/mcmc.md.  Mistakes in the input stop the
run before it starts (exit status 2, no traceback).
"""
import argparse
import os
import sys

# The one path prelude of the scripts: the repository root first, then utils.prepare_script_path.
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import utils  # noqa: E402
utils.prepare_script_path(__file__)

from many_bodyMCMC.mcmc_run import run_mcmc  # noqa: E402
from multi_bodies.files.input_options import read_input_file  # noqa: E402


def main(argv=None):
    """Command line entry; returns the exit status."""
    parser = argparse.ArgumentParser(description='Metropolis Monte Carlo sampler of rigid multiblob bodies above '
                                                 'a wall (see doc/mcmc.md).')
    parser.add_argument('input_file', nargs='?', default='inputMCMC.dat',
                        help='input file (default inputMCMC.dat)')
    args = parser.parse_args(argv)
    options = read_input_file(args.input_file, program='mcmc')  # the sampler's rules and warnings
    status = run_mcmc(options)
    print('\n\n\n# End')
    return status


if __name__ == '__main__':
    sys.exit(utils.fail_cleanly(main))
