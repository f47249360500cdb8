"""Instructions of one stochastic trapezoidal lubrication step of 64 spheres (or any lattice side), counted by
callgrind, and which Python functions a step calls how often.

Instruction counts are repeatable on a loaded machine, unlike times: they decide whether a change to the Python
around the compiled parts (the Krylov loops, the placing of the spheres, the per-step objects) made a step cheaper.
Two ways through the step (``--path``):

* ``face`` (default): ``Lub_Solver(...).Update_Bodies_Trap``, the published driver API, on the scene of
  ``lubrication_step_worker.py`` (what ``bench_lubrication.py --versus-published`` times: radius 1, the rollers'
  weight, kT > 0, dt 1e-3, tolerance 1e-4, numpy.random seeded with 3);
* ``step``: ``lubrication.integrators.trapezoidal_step`` with the published solves, on the scene of
  ``bench_lubrication.py --breakdown`` (radius 1.0155, Lanczos root, kT > 0, tolerance 1e-4).

Run::

    python benchmarks/count_lubrication_step.py                      # 8 x 8 spheres, face, 3 warm-up + 5 steps
    python benchmarks/count_lubrication_step.py --path step --sides 8 16
    python benchmarks/count_lubrication_step.py --keep /tmp/cg       # also keeps the callgrind files of the steps
    callgrind_annotate /tmp/cg/callgrind.out.8.2 | head -40          #   ... to see where the instructions go
    python benchmarks/count_lubrication_step.py --calls              # cProfile call counts per step (no valgrind)

It runs itself under ``valgrind --tool=callgrind --dump-before=getppid`` (one child per lattice side) and marks
the phases by calling ``os.getppid``: the warm-up steps (a first step builds what later ones keep), then the
counted steps; the count per step is the total of the second part divided by the steps.  The work of the counted
steps (far-field products, GMRES and Lanczos iterations, factorisations) is printed beside it: a change that
keeps it equal changed only the instructions around it.  With ``--phases`` (what the child runs) it runs the
phases and prints the work.
"""
import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path[:0] = [HERE, os.path.dirname(HERE)]
import bench_lubrication  # noqa: E402
from callgrind_parts import part_totals  # noqa: E402
import lubrication_step_worker  # noqa: E402
from lubrication import brownian, integrators  # noqa: E402


def stepper(path, side):
    """A function making one step of ``path`` ('face' or 'step') on the lattice of ``side`` x ``side`` spheres
    and returning that step's work counts (a dict)."""
    if path == 'face':
        locations = lubrication_step_worker.lattice(side)
        solver, _ = lubrication_step_worker.package_solver(locations)
        solver.kT, solver.dt, solver.tolerance = bench_lubrication.KT, bench_lubrication.DT, \
            bench_lubrication.STEP_TOLERANCE
        np.random.seed(3)
        solver.Set_R_Mats()

        def step():
            solver.Update_Bodies_Trap(lubrication_step_worker.weight)
            return solver.counts
        return step
    state = {'locations': bench_lubrication.lattice(side)}
    state['orientations'] = np.tile([1.0, 0.0, 0.0, 0.0], (side * side, 1))
    settings = brownian.lubrication_settings(bench_lubrication.RADIUS, bench_lubrication.ETA)
    rng = np.random.default_rng(3)

    def step():
        result = integrators.trapezoidal_step(settings, state['locations'], state['orientations'],
                                              bench_lubrication.settle, bench_lubrication.KT, bench_lubrication.DT,
                                              rng, bench_lubrication.STEP_TOLERANCE)
        state['locations'], state['orientations'] = result.locations, result.orientations
        return result.counts
    return step


def run_phases(path, side, warm_up, steps):
    """Warm-up steps, then ``steps`` counted ones, each phase after an ``os.getppid()`` (the dump marker);
    returns the summed work counts of the counted steps."""
    step = stepper(path, side)
    os.getppid()
    for _ in range(warm_up):
        step()
    os.getppid()
    work = integrators.new_counts()
    for _ in range(steps):
        for key, value in step().items():
            work[key] += value
    os.getppid()
    return work


def count(path, side, warm_up, steps, keep=None):
    """(instructions per counted step, work counts of the counted steps) from callgrind's dump parts."""
    with tempfile.TemporaryDirectory() as folder:
        out = os.path.join(keep or folder, 'callgrind.out.%d' % side)
        run = subprocess.run(['valgrind', '--tool=callgrind', '--dump-before=getppid', '--callgrind-out-file=' + out,
                              sys.executable, os.path.abspath(__file__), '--phases', '--path', path, '--sides',
                              str(side), '--warm-up', str(warm_up), '--steps', str(steps)],
                             check=True, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
        ordered = part_totals(out)  # start-up and set-up, warm-up, counted steps, the end
    return ordered[2] / steps, json.loads(run.stdout.strip().splitlines()[-1])


def call_counts(path, side, warm_up, steps, top):
    """The ``top`` Python and compiled functions by calls per counted step (cProfile; no times)."""
    import cProfile
    import pstats
    step = stepper(path, side)
    for _ in range(warm_up):
        step()
    profiler = cProfile.Profile()
    profiler.enable()
    for _ in range(steps):
        step()
    profiler.disable()
    stats = pstats.Stats(profiler).stats
    rows = sorted(((value[1] / steps, '%s:%d(%s)' % key) for key, value in stats.items()), reverse=True)
    total = sum(calls for calls, _ in rows)
    print('%d spheres, %s: %.0f function calls per step' % (side * side, path, total))
    for calls, name in rows[:top]:
        print('%10.1f  %s' % (calls, name))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--path', choices=('face', 'step'), default='face')
    parser.add_argument('--sides', type=int, nargs='+', default=[8])
    parser.add_argument('--warm-up', type=int, default=3)
    parser.add_argument('--steps', type=int, default=5)
    parser.add_argument('--keep', default=None, help='a folder to keep the callgrind files in')
    parser.add_argument('--calls', action='store_true', help='cProfile call counts per step instead')
    parser.add_argument('--top', type=int, default=40, help='functions shown by --calls')
    parser.add_argument('--phases', action='store_true', help='run the phases (under valgrind: by this script)')
    args = parser.parse_args()
    if args.phases:
        for side in args.sides:
            print(json.dumps(run_phases(args.path, side, args.warm_up, args.steps)))
        return
    if args.calls:
        for side in args.sides:
            call_counts(args.path, side, args.warm_up, args.steps, args.top)
        return
    if shutil.which('valgrind') is None:
        sys.exit('count_lubrication_step: valgrind is not installed (apt-get install valgrind)')
    print('instructions per trapezoidal step (callgrind; path %s, %d warm-up and %d counted steps)' % (
        args.path, args.warm_up, args.steps))
    print('%6s %14s  %s' % ('N', 'instructions', 'work of the counted steps'))
    for side in args.sides:
        instructions, work = count(args.path, side, args.warm_up, args.steps, args.keep)
        print('%6d %14.4g  %s' % (side * side, instructions, work), flush=True)


if __name__ == '__main__':
    main()
