"""One side of ``bench_lubrication.py --versus-published``: a process that holds one lattice of spheres and
makes trapezoidal lubrication steps through the published driver API (``Lub_Solver(...).Update_Bodies_Trap``)
when asked, timing each.

    python lubrication_step_worker.py --code package --side 8 [--kT 0.004 --dt 1e-3 --tolerance 1e-4 --seed 3]
    /path/to/published/python lubrication_step_worker.py --code published --published-tree TREE --side 8

``--code package`` imports this package's ``Lub_Solver`` face; ``--code published`` imports the published
``Lubrication/Lub_Solver.py`` from ``TREE`` (a rebuilt RigidMultiblobsWall checkout with its compiled
``Lubrication_Class`` and scikit-sparse installed in that interpreter), with its far-field products set, on the
instance, to the published numba functions of ``mobility/mobility.py`` (the published class names the pycuda ones,
which need a GPU).  This file imports nothing of the package on the published side.

Protocol (one JSON object per line on stdout; the steps' own prints go to /dev/null): after setting up and one
warm-up step (numba compiles its kernels there) it writes ``{"ready": ..., "threads": ...}``; then for each line
read from stdin: ``step`` -> ``{"cpu": s, "wall": s, "rejected": [wall, jump]}`` (CPU seconds of the whole process,
all its threads, and wall seconds of one ``Update_Bodies_Trap``), ``locations`` -> ``{"locations": (N, 3)}``,
``quit`` -> exits.

Scene (both sides): spheres of radius 1 (so the published code's pair distance, divided by a only along periodic
axes, is right), eta = 1e-3, a square lattice of spacing 2.3 a at height 1.2 a jittered by 0.1 a (seed 1, as in
``bench_lubrication.py``), gap clamp 1e-4 a, pair cutoff 4.5 a, no periodic box; the only force is the published
rollers' weight 0.0225 down on each sphere; numpy.random seeded with ``--seed`` (the published drivers' way).
"""
import argparse
import contextlib
import json
import os
import sys
import time

import numpy as np

RADIUS, ETA, WEIGHT, CUTOFF, GAP_CLAMP = 1.0, 1e-3, 0.0225, 4.5, 1e-4


def lattice(side, spacing=2.3, height=1.2):
    """side^2 sphere centres (side^2, 3) on the jittered square lattice (length units, a = 1)."""
    x, y = np.meshgrid(np.arange(side) * spacing, np.arange(side) * spacing)
    locations = np.column_stack((x.ravel(), y.ravel(), np.full(side * side, height)))
    locations[:, :2] += 0.1 * np.random.default_rng(1).uniform(-1, 1, (side * side, 2))
    return RADIUS * locations


def weight(bodies, r_vectors):
    """FT_calc of the published drivers: (2N, 3) rows [f_1, t_1, f_2, ...], the weight only."""
    force_torque = np.zeros((2 * len(bodies), 3))
    force_torque[0::2, 2] = -WEIGHT
    return force_torque


class Sphere:
    """What the published ``Lub_Solver`` reads of a body: location, location_old, orientation (a Quaternion)."""

    def __init__(self, location, quaternion_class):
        self.location = np.array(location, dtype=float)
        self.location_old = np.copy(self.location)
        self.orientation = quaternion_class(np.array([1.0, 0.0, 0.0, 0.0]))


def published_solver(tree, locations):
    sys.path[:0] = [os.path.join(tree, 'Lubrication'), tree]
    from Lub_Solver import Lub_Solver
    from mobility import mobility as mb
    from quaternion_integrator.quaternion import Quaternion
    import numba
    solver = Lub_Solver([Sphere(r, Quaternion) for r in locations], RADIUS, ETA, CUTOFF, np.zeros(3),
                        debye_length=GAP_CLAMP)
    solver.mobility_trans_times_force_wall = mb.single_wall_mobility_trans_times_force_numba
    solver.mobility_trans_times_torque_wall = mb.single_wall_mobility_trans_times_torque_numba
    solver.mobility_rot_times_force_wall = mb.single_wall_mobility_rot_times_force_numba
    solver.mobility_rot_times_torque_wall = mb.single_wall_mobility_rot_times_torque_numba
    return solver, 'numba %s, %d threads' % (numba.__version__, numba.get_num_threads())


def package_solver(locations):
    from body.body import Body
    from Lub_Solver import Lub_Solver
    import mobility.threads
    bodies = [Body(r, [1.0, 0.0, 0.0, 0.0], np.zeros((1, 3)), RADIUS) for r in locations]
    solver = Lub_Solver(bodies, RADIUS, ETA, CUTOFF, np.zeros(3), debye_length=GAP_CLAMP)
    return solver, mobility.threads.describe()


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--code', choices=('package', 'published'), required=True)
    parser.add_argument('--published-tree', default=None)
    parser.add_argument('--side', type=int, required=True)
    parser.add_argument('--kT', type=float, default=0.0040749841)
    parser.add_argument('--dt', type=float, default=1e-3)
    parser.add_argument('--tolerance', type=float, default=1e-4)
    parser.add_argument('--seed', type=int, default=3)
    args = parser.parse_args()
    out = sys.stdout
    quiet = open(os.devnull, 'w')
    locations = lattice(args.side)
    with contextlib.redirect_stdout(quiet):
        if args.code == 'published':
            solver, threads = published_solver(args.published_tree, locations)
        else:
            solver, threads = package_solver(locations)
        solver.kT, solver.dt, solver.tolerance = args.kT, args.dt, args.tolerance
        np.random.seed(args.seed)
        solver.Set_R_Mats()
        solver.Update_Bodies_Trap(weight)  # warm-up: numba compiles here
    out.write(json.dumps({'ready': args.code, 'spheres': len(solver.bodies), 'threads': threads}) + '\n')
    out.flush()
    for line in sys.stdin:
        command = line.strip()
        if command == 'step':
            with contextlib.redirect_stdout(quiet):
                cpu, wall = time.process_time(), time.perf_counter()
                rejected = solver.Update_Bodies_Trap(weight)
                cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
            out.write(json.dumps({'cpu': cpu, 'wall': wall, 'rejected': [int(r) for r in rejected[:2]]}) + '\n')
        elif command == 'locations':
            out.write(json.dumps({'locations': [list(map(float, b.location)) for b in solver.bodies]}) + '\n')
        elif command == 'quit':
            break
        out.flush()


if __name__ == '__main__':
    main()
