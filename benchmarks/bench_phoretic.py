"""Cost of a Laplace (solute) solve and of a slip-length solve against a plain mobility solve, 1 to 100 bodies.

Usage (from the repository root)::

    python benchmarks/bench_phoretic.py [--implementation python_no_wall] [--blobs 42] [--counts 1 10 100]

Bodies: icosahedral unit shells (``--blobs`` blobs, a = half the blob
spacing, outward unit normals, weights 4 pi / n) on a square lattice of
spacing 3 at height 5 with random orientations, no wall.  Each body emits
(alpha = 1), reacts (k = 0.5) and has surface mobility 1; for the slip-length
solve every blob has slip length ``--slip-length`` (1e3, the published FreeSlip
value).  Columns (seconds, wall time, one core of a shared machine; GMRES
iterations in brackets):

* ``mobility``: preconditioner set-up and GMRES of the rigid problem under a unit force (no slip);
* ``laplace``: the concentration solve (unpreconditioned GMRES(200), no set-up: the published solve);
* ``laplace_pc``: the same preconditioned as the runs do by default (laplace_preconditioner.py, set-up included);
* ``laplace+slip``: the concentration solve, its gradient and the phoretic slip;
* ``slip_length``: preconditioner set-up and GMRES of the slip-length problem under the same force (every body
  alone, ``preconditioner block_diagonal``, as published);
* ``slip_length_nb``: the same with the neighbour correction (``SlipLengthNeighbourPreconditioner``, what
  ``preconditioner neighbours`` builds, and ``auto`` where the near pairs hold at most a fifth of the blob pairs).

``--spacing`` sets the lattice spacing (default 3: shells 1 apart, surface to surface).
"""
import argparse
import os
import sys
import time

import numpy as np
import scipy.spatial  # noqa: F401  (the neighbour search's; imported once per run, so not timed)

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from body.body import Body, bodies_to_arrays  # noqa: E402
from mobility.interface import from_implementation_name  # noqa: E402
from multi_bodies.files.structure_generators import icosahedral_shell, smallest_distance  # noqa: E402
from multi_bodies.solver import body_solver, slip_length  # noqa: E402
from multi_bodies.solver.laplace_preconditioner import LaplacePreconditioner  # noqa: E402
from multi_bodies.solver.phoretic import LAPLACE_RESTART, PhoreticSurface, lab_normals  # noqa: E402


def suspension(count, blobs, seed=0, spacing=3.0):
    """(BodyArrays, blob radius, body-frame normals (N, 3), weights (N,)) of ``count`` shells ``spacing`` apart."""
    rng = np.random.default_rng(seed)
    shell = icosahedral_shell(blobs)
    a = 0.5 * smallest_distance(shell)
    side = int(np.ceil(np.sqrt(count)))
    bodies = []
    for k in range(count):
        q = rng.normal(size=4)
        body = Body([spacing * (k % side), spacing * (k // side), 5.0], q / np.linalg.norm(q), shell, a)
        body.ID = 'shell'
        bodies.append(body)
    arrays = bodies_to_arrays(bodies)
    return arrays, a, np.tile(shell, (count, 1)), np.full(count * blobs, 4 * np.pi / blobs)


def timed(function):
    start = time.perf_counter()
    result = function()
    return time.perf_counter() - start, result


def measure(count, blobs, implementation, tolerance, slip_length_value=1e3, spacing=3.0):
    arrays, a, normals, weights = suspension(count, blobs, spacing=spacing)
    q = arrays.configuration
    blob_mobility = from_implementation_name(implementation, 1.0, a, dense_matrices=True)  # M f and dense blocks
    force = np.zeros((count, 6))
    force[:, 2] = -1.0
    row = {}

    def plain():
        problem = body_solver.MobilityProblem(arrays, q, blob_mobility)
        pc = body_solver.BlockDiagonalPreconditioner(arrays, q, blob_mobility)
        return body_solver.solve(problem, problem.rhs(None, force), pc, tolerance=tolerance)
    seconds, result = timed(plain)
    row['mobility'] = (seconds, result.iterations)

    surface = PhoreticSurface(normals, np.full(len(weights), 0.5), np.ones(len(weights)), np.ones(len(weights)),
                              weights, (0.0,), 1.0, False)
    laplace = surface.problem(arrays, q)
    seconds, result = timed(lambda: body_solver.solve(laplace, laplace.rhs(), None, tolerance=tolerance,
                                                      restart=LAPLACE_RESTART))
    row['laplace'] = (seconds, result.iterations)
    seconds, result = timed(lambda: body_solver.solve(laplace, laplace.rhs(),
                                                      LaplacePreconditioner(laplace, arrays.blob_offsets),
                                                      tolerance=tolerance, restart=LAPLACE_RESTART))
    row['laplace_pc'] = (seconds, result.iterations)
    solved = []

    def solve_and_slip():
        solved.append(body_solver.solve(laplace, laplace.rhs(), None, tolerance=tolerance, restart=LAPLACE_RESTART))
        return surface.slip(laplace, solved[-1].constraint_force_torque)
    seconds, _ = timed(solve_and_slip)
    row['laplace+slip'] = (seconds, solved[-1].iterations)

    lengths = np.full(len(weights), slip_length_value)

    def with_slip_length(corrected):
        problem = slip_length.slip_length_problem(arrays, q, blob_mobility, reference_normals=normals,
                                                  slip_lengths=lengths, weights=weights)
        pc = slip_length.SlipLengthPreconditioner(arrays, q, blob_mobility, normals=normals, slip_lengths=lengths,
                                                  weights=weights)
        if corrected:
            pc = slip_length.SlipLengthNeighbourPreconditioner(pc, blob_mobility)
        return body_solver.solve(problem, problem.rhs(None, force), pc, tolerance=tolerance, restart=300)
    for name, corrected in (('slip_length', False), ('slip_length_nb', True)):
        seconds, result = timed(lambda: with_slip_length(corrected))
        row[name] = (seconds, result.iterations)
    assert lab_normals(arrays, q, normals).shape == normals.shape
    return row


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--implementation', default='python_no_wall')
    parser.add_argument('--blobs', type=int, default=42)
    parser.add_argument('--counts', type=int, nargs='+', default=[1, 10, 100])
    parser.add_argument('--tolerance', type=float, default=1e-8)
    parser.add_argument('--slip-length', type=float, default=1e3, help='slip length of every blob (default 1e3)')
    parser.add_argument('--spacing', type=float, default=3.0, help='lattice spacing of the unit shells (default 3)')
    args = parser.parse_args(argv)
    columns = ('mobility', 'laplace', 'laplace_pc', 'laplace+slip', 'slip_length', 'slip_length_nb')
    print('| bodies | blobs | ' + ' | '.join(columns) + ' |')
    print('|---|---|' + '---|' * len(columns))
    for count in args.counts:
        row = measure(count, args.blobs, args.implementation, args.tolerance, args.slip_length, args.spacing)
        print('| %d | %d | ' % (count, count * args.blobs)
              + ' | '.join('%.3g s (%d)' % row[c] for c in columns) + ' |', flush=True)


if __name__ == '__main__':
    main()
