"""Which model does a scene need?  Measure the cheapest adequate model for an input file.

Run from the folder the input file is meant to run in (as the other scripts)::

    python advise.py --input-file inputfile_dynamic.dat [--accuracy 0.01] [--quick] [--coarsen] [--quiet]

It reads the scene as ``multi_bodies.py`` and ``multi_bodies_utilities.py``
do and measures, on this machine: the resolution of each structure type, wall
against no wall, multiblob against single-blob rollers, dense against GMRES,
the mobility backends, and the stability of the time step (see
doc/advisor.md).  It prints a table per choice, the recommendation and the
input lines to change, and writes ``output_name.advice.json`` (plus the
``.vertex`` files of the models it recommends, ``output_name.advice.*.vertex``).

A recommended model keeps the physics: per-blob parameters (``g``, the wall
and pair repulsion strengths) are rescaled so that every body keeps its
total force, driven rollers stay rollers, and the recommended input is set
up and solved once against the user's before it is printed (the
``check:`` note).  Only options of the input's program are recommended,
and the time step is bounded by stability, no crossing of the wall or of
bodies and its measured error (the bound that binds is named).  One
progress line per measurement goes to standard error (``--quiet``: none).

``--quick`` skips what grows with the scene (pair errors, the dense solve,
timings of other models) and says which numbers then come from the shipped
tables.  Mistakes in the input stop with one message (exit status 2).
"""
import argparse
import os
import sys

# The one path prelude of the scripts: the repository root first, then utils.prepare_script_path.
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import utils  # noqa: E402
utils.prepare_script_path(__file__)

from multi_bodies.advice import advisor  # noqa: E402


def main(argv=None):
    """Advise on an input file; returns the exit status."""
    parser = argparse.ArgumentParser(description='Measure the cheapest model that meets an accuracy target for '
                                                 'the scene of an input file (see doc/advisor.md).')
    parser.add_argument('--input-file', required=True,
                        help='input file of multi_bodies.py or multi_bodies_utilities.py')
    parser.add_argument('--accuracy', type=float, default=0.01,
                        help='target relative error of the body self mobilities (default 0.01)')
    parser.add_argument('--quick', action='store_true',
                        help='skip measurements that grow with the scene; use the shipped tables instead')
    parser.add_argument('--coarsen', action='store_true',
                        help='also offer coarsened models (every other blob) of bodies that are not spheres')
    parser.add_argument('--quiet', action='store_true',
                        help='no progress lines on stderr (by default one line per measurement)')
    parser.add_argument('--verbose', action='store_true', help='accepted for old command lines: progress lines '
                                                               'are printed by default')
    args = parser.parse_args(argv)
    if not 0.0 < args.accuracy < 1.0:
        raise utils.UserInputError('--accuracy is a relative error between 0 and 1 (e.g. 0.01), got %g'
                                   % args.accuracy)
    def progress(line):
        print(line, file=sys.stderr, flush=True)
    log = None if args.quiet else progress
    result = advisor.advise(args.input_file, accuracy=args.accuracy, quick=args.quick, coarsen=args.coarsen,
                            log=log)
    sys.stdout.write(result.report())
    path = result.write()
    print('\nwrote %s' % path)
    for name in result.files:
        if result.recommends_file(name):
            print('wrote %s' % name)
    return 0


if __name__ == '__main__':
    sys.exit(utils.fail_cleanly(main))
