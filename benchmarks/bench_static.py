"""GMRES iterations and wall time of the static mobility problem for 1, 10 and 100 boomerangs.

Usage (from the repository root)::

    python benchmarks/bench_static.py [--implementation C++] [--tolerance 1e-8]

Each boomerang has 15 blobs (a = 0.25); bodies sit on a square lattice of
spacing 3 at heights 2 to 2.3 with random orientations, and feel a unit
downward force.  The time covers the preconditioner set-up (dense blocks and
their Cholesky factors) and the GMRES solve, as in the ``mobility`` scheme.
"""
import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from body.body import Body, bodies_to_arrays  # noqa: E402
from mobility.interface import from_implementation_name  # noqa: E402
from multi_bodies.solver import body_solver  # noqa: E402
from multi_bodies.files.structure_generators import boomerang  # noqa: E402


def boomerang_suspension(count, seed=0):
    rng = np.random.default_rng(seed)
    side = int(np.ceil(np.sqrt(count)))
    bodies = []
    for k in range(count):
        q = rng.normal(size=4)
        body = Body([3.0 * (k % side), 3.0 * (k // side), 2.0 + 0.3 * rng.random()], q / np.linalg.norm(q),
                    boomerang(7, 0.3), 0.25)
        body.ID = 'boomerang_N_15'
        bodies.append(body)
    return bodies_to_arrays(bodies)


def solve(count, implementation, tolerance):
    arrays = boomerang_suspension(count)
    configuration = arrays.configuration
    forces = np.tile([0.0, 0.0, -1.0, 0.0, 0.0, 0.0], (count, 1))
    start = time.perf_counter()
    blob_mobility = from_implementation_name(implementation, 1.0, 0.25, dense_matrices=True)
    problem = body_solver.MobilityProblem(arrays, configuration, blob_mobility)
    preconditioner = body_solver.BlockDiagonalPreconditioner(arrays, configuration, blob_mobility)
    set_up = time.perf_counter() - start
    result = body_solver.solve(problem, body_solver.mobility_rhs(forces, np.zeros((arrays.num_blobs, 3))),
                               preconditioner, tolerance=tolerance)
    total = time.perf_counter() - start
    return result, set_up, total


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--implementation', default='C++')
    parser.add_argument('--tolerance', type=float, default=1e-8)
    parser.add_argument('--bodies', type=int, nargs='+', default=[1, 10, 100])
    args = parser.parse_args()
    solve(1, args.implementation, args.tolerance)          # warm-up (imports, first calls)
    print('implementation %s, tolerance %g' % (args.implementation, args.tolerance))
    print('%8s %8s %11s %10s %14s %10s' % ('bodies', 'blobs', 'iterations', 'converged', 'preconditioner', 'total'))
    for count in args.bodies:
        result, set_up, total = solve(count, args.implementation, args.tolerance)
        print('%8d %8d %11d %10s %13.4fs %9.4fs' % (count, 15 * count, result.iterations, result.converged,
                                                    set_up, total))


if __name__ == '__main__':
    main()
