"""Instructions of the lubrication preconditioners' sparse factorisations (SuperLU against the block LDL^T).

Counts with valgrind's callgrind (instruction counts are repeatable on a loaded machine, unlike times) what one
build of each preconditioner costs on the lattices of ``bench_lubrication.py`` (its scene: radius 1.0155, spacing
2.3 a, height 1.2 a, jitter 0.1 a; the shift ``6 pi eta a * 1e-4``, the rollers example's tolerance): the
published preconditioner ``LubricationPreconditioner`` (``R_sup + s I``, 6 x 6 blocks) and the torque problem's
``torque_preconditioner`` (``Delta_R_tt + 6 pi eta a I``, 3 x 3 blocks), each built as the step builds it (the
Python around the factorisation included; the block LDL^T's ordered anew and with the ordering of the last
factorisation kept, see :func:`run_phases`), and one application of each (its solve).  Run::

    python benchmarks/count_lubrication_factor.py --sides 8 16 32

It runs itself under ``valgrind --tool=callgrind --dump-before=getppid`` (one child per lattice side) and marks the
phases by calling ``os.getppid`` before each: a phase's instructions are the total of its dump part divided by the
repeats.  With ``--phases`` (what the child runs) it runs the phases and prints nothing.
"""
import argparse
import os
import shutil
import subprocess
import sys
import tempfile

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from callgrind_parts import part_totals  # noqa: E402
from bench_lubrication import ETA, RADIUS, STEP_TOLERANCE, lattice  # noqa: E402
from lubrication import assembly, integrators, problem as lub_problem, sparse_factor  # noqa: E402

METHODS = [m for m in sparse_factor.METHODS if m != 'block_ldlt' or sparse_factor.available()]
MATRICES = ('R_sup + sI', 'torques')


def labels():
    """The phase each dump part after the first marker holds, in order (warm-ups are counted and not shown)."""
    out = []
    for method in METHODS:
        out.append('warm-up')
        for what in MATRICES:
            if method == 'block_ldlt':
                out += ['%s %s factor, ordered anew' % (method, what), '%s %s factor, ordering kept' % (method, what)]
            else:
                out.append('%s %s factor' % (method, what))
            out.append('%s %s solve' % (method, what))
    return out


def run_phases(side, repeats):
    """The phases of :func:`labels` in order, ``repeats`` times each (the warm-ups once), each after an
    ``os.getppid()`` (the dump marker).  Every factorisation phase alternates between the lattice and the lattice
    moved by up to 1e-4 a (the same neighbour pairs, other values and exact zeros: a step's next factorisation);
    the block LDL^T's are counted twice: ordered anew (its kept orderings dropped before each) and with the
    ordering of the last factorisation kept."""
    locations = lattice(side)
    moved = locations + 1e-4 * RADIUS * np.random.default_rng(6).uniform(-1, 1, locations.shape)
    configurations = [assembly.resistance_matrices(where, RADIUS, ETA) for where in (locations, moved)]
    assert np.array_equal(configurations[0].neighbours.pairs, configurations[1].neighbours.pairs)
    shift = 6.0 * np.pi * ETA * RADIUS * STEP_TOLERANCE
    x = np.random.default_rng(5).standard_normal(6 * locations.shape[0])

    def build(what, matrices):
        return (lub_problem.LubricationPreconditioner(matrices, shift) if what == 'R_sup + sI'
                else integrators.torque_preconditioner(matrices.Delta_R, ETA, RADIUS))
    for method in METHODS:
        os.getppid()
        sparse_factor.use_method(method)
        built = {what: build(what, configurations[0]) for what in MATRICES}
        for what in MATRICES:
            built[what].apply(x)
            if method == 'block_ldlt':
                os.getppid()
                for repeat in range(repeats):
                    sparse_factor.forget_orderings()
                    built[what] = build(what, configurations[(repeat + 1) % 2])
            os.getppid()
            for repeat in range(repeats):
                built[what] = build(what, configurations[(repeat + 1) % 2])
            os.getppid()
            for _ in range(repeats):
                built[what].apply(x)
    os.getppid()


def count(side, repeats):
    """{phase: instructions per repeat} of one lattice side, from callgrind's dump parts."""
    with tempfile.TemporaryDirectory() as folder:
        out = os.path.join(folder, 'callgrind.out')
        subprocess.run(['valgrind', '--tool=callgrind', '--dump-before=getppid', '--callgrind-out-file=' + out,
                        sys.executable, os.path.abspath(__file__), '--phases', '--sides', str(side),
                        '--repeats', str(repeats)], check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        ordered = part_totals(out)  # the start-up, then one part per label, then the end
    return {label: ordered[1 + k] / repeats for k, label in enumerate(labels()) if label != 'warm-up'}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--sides', type=int, nargs='+', default=[8, 16, 32])
    parser.add_argument('--repeats', type=int, default=2)
    parser.add_argument('--phases', action='store_true', help='run the phases (under valgrind: by this script)')
    args = parser.parse_args()
    if args.phases:
        for side in args.sides:
            run_phases(side, args.repeats)
        return
    if shutil.which('valgrind') is None:
        sys.exit('count_lubrication_factor: valgrind is not installed (apt-get install valgrind)')
    print('instructions per call (callgrind, %d repeats; the Python around each call included)' % args.repeats)
    print('%6s  %-45s %14s' % ('N', 'phase', 'instructions'))
    for side in args.sides:
        for phase, value in count(side, args.repeats).items():
            print('%6d  %-45s %14.4g' % (side * side, phase, value), flush=True)


if __name__ == '__main__':
    main()
