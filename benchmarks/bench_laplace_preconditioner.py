"""GMRES iterations and seconds of the phoretic concentration solve with each preconditioner.

For every scene (Janus shells above the wall, tests/test_laplace_preconditioner.py's ``janus_scene``) the
concentration problem is solved at a sequence of configurations, every body moved by 0.01 and turned by 0.01 rad
between solves, each solve warm-started from the last normalised solution as a run does
(``Surface.solve_concentrations``), at ``solver_tolerance`` 1e-8, GMRES(200):

* ``none``: unpreconditioned (the published solve, and ours under ``preconditioner block_diagonal``);
* ``blocks``: every body's own block inverted (the two-level preconditioner without its coarse modes);
* ``two_level``: blocks and four coarse modes per body (the default).

Printed: iterations of the first solve (from zero) and per warm solve, seconds per warm solve (build included,
median) and their ratios to ``none``; one product with ``A`` for scale.  Scenes:

* ``janus_30``: 30 shells of 162 blobs, 2.6 radii apart (4,860 blobs);
* ``janus_30_dilute``: the same, 5 radii apart;
* ``janus_100``: 100 shells of 42 blobs, 2.6 radii apart (4,200 blobs).

    python benchmarks/bench_laplace_preconditioner.py [--scenes janus_30 ...] [--solves 6]
"""
import argparse
import os
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.join(ROOT, 'tests'))

import mobility  # noqa: E402,F401  (the run's thread policy: one BLAS thread, mobility/threads.py)
from body.geometry import rotation_matrices  # noqa: E402
from multi_bodies.solver.krylov import gmres  # noqa: E402
from multi_bodies.solver.laplace_preconditioner import LaplacePreconditioner  # noqa: E402
from multi_bodies.solver.phoretic import LaplaceProblem  # noqa: E402
from test_laplace_preconditioner import janus_scene  # noqa: E402

SCENES = {'janus_30': (30, 162, 2.6), 'janus_30_dilute': (30, 162, 5.0), 'janus_100': (100, 42, 2.6)}
TOLERANCE = 1e-8


def moved(problem, offsets, rng, step=0.01):
    """The problem with every body translated by ``step`` and turned by ``step`` rad about its centre."""
    x, n = problem.r_vectors.copy(), problem.normals.copy()
    for b in range(len(offsets) - 1):
        rows = slice(offsets[b], offsets[b + 1])
        axis = rng.normal(size=3)
        axis *= step / np.linalg.norm(axis)
        q = np.concatenate(([np.cos(0.5 * step)], np.sin(0.5 * step) * axis / step))
        R = rotation_matrices(q[None])[0]
        centre = x[rows].mean(axis=0)
        x[rows] = centre + (x[rows] - centre) @ R.T + step * rng.normal(size=3) / np.sqrt(3.0)
        n[rows] = n[rows] @ R.T
    return LaplaceProblem(x, n, problem.reaction, problem.emitting, problem.weights, problem.diffusion_coefficient,
                          problem.background, problem.wall)


def solve(problem, offsets, kind, x0):
    """(normalised solution, iterations, seconds) of one solve, the preconditioner's build included."""
    start = time.perf_counter()
    psolve = None
    if kind != 'none':
        psolve = LaplacePreconditioner(problem, offsets, modes_per_body=0 if kind == 'blocks' else 4).apply
    b = problem.rhs()
    x, info, iterations, _ = gmres(problem.matvec, b / np.linalg.norm(b), TOLERANCE, psolve=psolve, x0=x0,
                                   restart=200)
    if info != 0:
        raise RuntimeError('%s did not converge' % kind)
    return x, iterations, time.perf_counter() - start


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--scenes', nargs='+', default=list(SCENES), choices=list(SCENES))
    parser.add_argument('--solves', type=int, default=6)
    args = parser.parse_args(argv)
    print('%-16s %6s %-10s %8s %6s %9s %6s %9s %6s' % ('scene', 'blobs', 'precond', 'it/zero', 'it/warm', 'ratio',
                                                        's/solve', 'ratio', 'A x (s)'))
    for name in args.scenes:
        problem, offsets = janus_scene(*SCENES[name])
        rng = np.random.default_rng(7)
        problems = [problem]
        for _ in range(args.solves):
            problems.append(moved(problems[-1], offsets, rng))
        b = problem.rhs()
        problem.matvec(b)  # a warm-up
        start = time.perf_counter()
        problem.matvec(b)
        product = time.perf_counter() - start
        rows = {}
        guesses = {kind: None for kind in ('none', 'blocks', 'two_level')}
        counts = {kind: [] for kind in guesses}
        seconds = {kind: [] for kind in guesses}
        for p in problems:  # the kinds alternate, so that a drift of the machine's speed touches all alike
            for kind in guesses:
                guesses[kind], iterations, elapsed = solve(p, offsets, kind, guesses[kind])
                counts[kind].append(iterations)
                seconds[kind].append(elapsed)
        for kind in guesses:
            warm, time_warm = np.mean(counts[kind][1:]), float(np.median(seconds[kind][1:]))
            rows[kind] = (counts[kind][0], warm, time_warm)
        for kind, (zero, warm, time_warm) in rows.items():
            print('%-16s %6d %-10s %8d %6.1f %9.2f %6.3f %9.2f %6.4f' % (
                name, problem.size, kind, zero, warm, warm / rows['none'][1], time_warm,
                time_warm / rows['none'][2], product))


if __name__ == '__main__':
    main()
