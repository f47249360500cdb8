"""Benchmark of the lubrication core (lubrication/): Delta_R assembly, the factor of the preconditioner and
one solve of (I + M Delta_R) U = M F through the one solve, for spheres on a lattice near the wall.

Prints, for each lattice side, the number of spheres and of pairs within the cutoff, the median times of the
assembly of R_sup, R_MB and Delta_R, of the sparse LU of R_sup + s I, of the GMRES solve, and its iterations,
for each far-field backend asked.

    python benchmarks/bench_lubrication.py                          # 8 x 8 and 16 x 16, C++ far field
    python benchmarks/bench_lubrication.py --sides 8 16 32 --implementations python C++

Scene: radius a = 1.0155 (the published rollers), eta = 1e-3, a square lattice of spacing 2.3 a at height
1.2 a, jittered by 0.1 a in x and y (seed 1); random forces and torques (seed 2); tolerance 1e-8.
"""
import argparse
import statistics
import time

import numpy as np

from lubrication import assembly, problem as lub_problem
from multi_bodies.solver.body_solver import solve

RADIUS, ETA, TOLERANCE = 1.0155, 1e-3, 1e-8


def median_time(function, repeats):
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        result = function()
        times.append(time.perf_counter() - start)
    return statistics.median(times), result


def lattice(side, spacing=2.3, height=1.2):
    """side^2 sphere centres (side^2, 3) on a jittered square lattice, in length units."""
    x, y = np.meshgrid(np.arange(side) * spacing, np.arange(side) * spacing)
    locations = np.column_stack((x.ravel(), y.ravel(), np.full(side * side, height)))
    locations[:, :2] += 0.1 * np.random.default_rng(1).uniform(-1, 1, (side * side, 2))
    return RADIUS * locations


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--sides', type=int, nargs='+', default=[8, 16])
    parser.add_argument('--implementations', nargs='+', default=['C++'])
    parser.add_argument('--repeats', type=int, default=5)
    args = parser.parse_args()
    print('%6s %6s %10s %12s %10s %10s %5s %s' % ('N', 'pairs', 'far field', 'assembly ms', 'factor ms',
                                                  'solve ms', 'its', 'residual'))
    for side in args.sides:
        locations = lattice(side)
        n = locations.shape[0]
        force_torque = np.random.default_rng(2).standard_normal((n, 6))
        t_assembly, matrices = median_time(lambda: assembly.resistance_matrices(locations, RADIUS, ETA), args.repeats)
        for implementation in args.implementations:
            problem = lub_problem.LubricationProblem(locations, RADIUS, ETA, implementation=implementation,
                                                     matrices=matrices)
            t_factor, preconditioner = median_time(lambda: problem.preconditioner(TOLERANCE), args.repeats)
            rhs = problem.rhs(force_torque)
            t_solve, result = median_time(lambda: solve(problem, rhs, preconditioner, tolerance=TOLERANCE),
                                          args.repeats)
            print('%6d %6d %10s %12.1f %10.1f %10.1f %5d %.1e' % (
                n, matrices.neighbours.pairs.shape[0], implementation, 1e3 * t_assembly, 1e3 * t_factor,
                1e3 * t_solve, result.iterations, result.residual))


if __name__ == '__main__':
    main()
