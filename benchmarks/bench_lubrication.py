"""Benchmark of the lubrication core (lubrication/): Delta_R assembly, the factor of the preconditioner and
one solve of (I + M Delta_R) U = M F through the one solve, for spheres on a lattice near the wall.

Prints, for each lattice side, the number of spheres and of pairs within the cutoff, the median times of the
assembly of R_sup, R_MB and Delta_R, of the sparse LU of R_sup + s I, of the GMRES solve, and its iterations,
for each far-field backend asked.

    python benchmarks/bench_lubrication.py                          # 8 x 8 and 16 x 16, C++ far field
    python benchmarks/bench_lubrication.py --sides 8 16 32 --implementations python C++
    python benchmarks/bench_lubrication.py --steps --sides 8 16       # trapezoidal steps, near-field roots

With ``--steps``: the median wall time of one stochastic trapezoidal step
(``lubrication.integrators.trapezoidal_step``: forces, noise, predictor, far-field RFD, corrector) with the
work counted (far-field products, GMRES and Lanczos iterations, sparse LU factorisations, Delta_R
assemblies), for both near-field roots, and the cost of one ``Delta_R^1/2 W`` by each root (published
step, measured on 2 cores with its numba far field: 1.38 s for 64 spheres, 2.09 s for 256).

Scene: radius a = 1.0155 (the published rollers), eta = 1e-3, a square lattice of spacing 2.3 a at height
1.2 a, jittered by 0.1 a in x and y (seed 1); random forces and torques (seed 2); tolerance 1e-8.
"""
import argparse
import statistics
import time

import numpy as np

from lubrication import assembly, brownian, integrators, problem as lub_problem
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


KT, DT, STEP_TOLERANCE = 0.0040749841, 1e-3, 1e-4  # the rollers example's kT and solver tolerance


def settle(locations, orientations):
    """Forces (N, 6): buoyant weight of the rollers example (g = 0.0225 per sphere, down) and no torque."""
    force_torque = np.zeros((locations.shape[0], 6))
    force_torque[:, 2] = -0.0225
    return force_torque


def step_rows(side, implementation, repeats):
    """Median step times and counts of the trapezoidal step for both near-field roots."""
    locations = lattice(side)
    orientations = np.tile([1.0, 0.0, 0.0, 0.0], (locations.shape[0], 1))
    rows = []
    for root in brownian.NEAR_FIELD_ROOTS:
        settings = brownian.lubrication_settings(RADIUS, ETA, implementation=implementation, near_field_root=root)
        rng = np.random.default_rng(3)
        t_step, step = median_time(lambda: integrators.trapezoidal_step(settings, locations, orientations, settle,
                                                                        KT, DT, rng, STEP_TOLERANCE), repeats)
        matrices = settings.matrices(locations)
        W = np.random.default_rng(4).standard_normal(6 * locations.shape[0])
        t_root, near = median_time(lambda: brownian.NearFieldRoot(matrices.Delta_R, root,
                                                                  settings.shift(STEP_TOLERANCE), STEP_TOLERANCE),
                                   repeats)
        t_apply, _ = median_time(lambda: near.apply(W), repeats)
        rows.append((locations.shape[0], root, t_step, step.counts, t_root + t_apply, near.products))
    return rows


def main_steps(args):
    print('%6s %9s %8s %9s %6s %9s %7s %6s %12s %8s' % ('N', 'root', 'far', 'step s', 'M x', 'gmres its',
                                                        'lanczos', 'LU', 'root ms', 'root Mx'))
    for side in args.sides:
        for implementation in args.implementations:
            for n, root, t_step, counts, t_root, products in step_rows(side, implementation, args.repeats):
                print('%6d %9s %8s %9.3f %6d %9d %7d %6d %12.2f %8d' % (
                    n, root, implementation, t_step, counts['far_field_products'], counts['gmres_iterations'],
                    counts['lanczos_iterations'], counts['factorisations'], 1e3 * t_root, products))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--sides', type=int, nargs='+', default=[8, 16])
    parser.add_argument('--implementations', nargs='+', default=['C++'])
    parser.add_argument('--repeats', type=int, default=5)
    parser.add_argument('--steps', action='store_true', help='time trapezoidal steps and near-field roots')
    args = parser.parse_args()
    if args.steps:
        return main_steps(args)
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
