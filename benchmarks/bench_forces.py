"""Benchmark of the blob-blob soft repulsion: all pairs (C++ / numba, O(N^2)) against the cell list
(tree_numba, O(N); pairs beyond 2a + 30b neglected).

Prints, for each number of blobs N, the time of one force evaluation (median of repeats) of each
implementation, the speed-up of the cell list and the largest difference between the two relative to the
largest force (the neglected pairs contribute below exp(-30) of the contact force each).  The all-pairs
kernel is skipped above --max-all-pairs blobs (its time grows like N^2).

    python benchmarks/bench_forces.py                         # N = 1e3, 1e4, 1e5
    python benchmarks/bench_forces.py --sizes 1000 10000 --repeats 5

Blob positions: a monolayer-like slab, uniform in [0, L]^2 x [a, 5] with L = sqrt(N / 0.5) (the set-up of
bench_mobility.py), a = 0.25, b = 0.025 (so the cutoff 2a + 30b = 1.25), eps = 1, periodic in x and y.
"""
import argparse
import statistics
import time

import numpy as np

from multi_bodies.solver import physics


def median_time(function, repeats):
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        result = function()
        times.append(time.perf_counter() - start)
    return statistics.median(times), result


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--sizes', type=int, nargs='+', default=[1000, 10000, 100000])
    parser.add_argument('--repeats', type=int, default=3)
    parser.add_argument('--max-all-pairs', type=int, default=100000)
    args = parser.parse_args(argv)
    params = dict(repulsion_strength=1.0, debye_length=0.025, blob_radius=0.25)
    all_pairs = physics.blob_blob_force_calculator('C++')
    cell_list = physics.blob_blob_force_calculator('tree_numba')
    print('%8s %14s %14s %9s %14s' % ('N', 'all pairs (s)', 'cell list (s)', 'speed-up', 'max rel. diff'))
    for n in args.sizes:
        rng = np.random.default_rng(n)
        side = np.sqrt(n / 0.5)
        r = np.column_stack((rng.uniform(0, side, n), rng.uniform(0, side, n), rng.uniform(0.25, 5.0, n)))
        L = np.array([side, side, 0.0])
        t_cell, f_cell = median_time(lambda: cell_list(r, periodic_length=L, **params), args.repeats)
        if n <= args.max_all_pairs:
            t_all, f_all = median_time(lambda: all_pairs(r, periodic_length=L, **params), max(1, args.repeats // 3))
            diff = np.max(np.abs(f_all - f_cell)) / max(np.max(np.abs(f_all)), np.finfo(float).tiny)
            print('%8d %14.4g %14.4g %9.1f %14.3g' % (n, t_all, t_cell, t_all / t_cell, diff))
        else:
            print('%8d %14s %14.4g %9s %14s' % (n, '-', t_cell, '-', '-'))


if __name__ == '__main__':
    main()
