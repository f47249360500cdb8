"""Benchmark of the blob mobility product u = M f on every usable backend.

Prints, for each number of blobs N and backend, the time of one product
(median of repeats, inputs already prepared; for the GPU, inputs already on
the device), pair interactions per second (N^2 / time) and the speed-up over
the python backend, for the wall (Rotne-Prager-Blake) and free-space (RPY)
products.  The published figures recorded on another machine (PERFORMANCE.md,
timings_original.json) are printed beside ours for orientation only, never as a
ratio: a ratio to the published code is measured side by side on one machine
(the published tree's ``bench_published_mf.py`` alternated with this script, as
``doc/performance.md`` describes).

    python benchmarks/bench_mobility.py                      # N = 1000, 4000, 16000
    python benchmarks/bench_mobility.py --sizes 1000 4000 --repeats 5
    python benchmarks/bench_mobility.py --gpu-sizes 100000 300000   # adds GPU-only sizes
    python benchmarks/bench_mobility.py --radii-sizes 1000 4000      # radii product only (default sizes)

After the equal-radius table, the product with per-blob radii (radii uniform
in [0.15, 0.35], the formulas for different radii) is timed at the
``--radii-sizes`` (default 1000 and 4000) on the CPU backends, and its
ratio to the equal-radius product of the same backend and domain printed.

Blob positions: uniform in [0, L]^2 x [a, 5] with L = sqrt(N / 0.5), a = 0.25,
eta = 1 (the set-up of the published timings).
"""
import argparse
import resource
import statistics
import time

import numpy as np

from mobility.interface import Geometry, is_usable, make_mobility, registered_backends, unusable_reason

# Published M f (wall) on a 2-core machine, seconds (reference/timings_original.json).
PUBLISHED_CPU = {1000: {'python': 0.46, 'numba': 0.0024, 'C++': 0.0073},
                 4000: {'python': 9.5, 'numba': 0.039, 'C++': 0.113},
                 16000: {'numba': 0.66, 'C++': 2.06}}
PUBLISHED_CPU_NO_WALL = {1000: 0.0050, 4000: 0.083, 16000: 1.47}  # published numba, no wall
# Published GPU kernel on one H100, milliseconds (PERFORMANCE.md).
PUBLISHED_GPU_MS = {1000: (1.34, 0.56), 10000: (13.2, 5.5), 30000: (41.6, 16.9), 100000: (230, 72),
                    300000: (2435, 636)}


def published_seconds(n, wall_name, backend):
    """The published figure to compare with: its python (dense) for python, its fastest
    CPU kernel (numba or C++) for C++, its GPU kernel for pycuda; None where none was measured."""
    if backend == 'pycuda':
        return PUBLISHED_GPU_MS[n][0 if wall_name == 'wall' else 1] / 1000.0 if n in PUBLISHED_GPU_MS else None
    if wall_name != 'wall':
        return PUBLISHED_CPU_NO_WALL.get(n) if backend == 'C++' else None
    if n not in PUBLISHED_CPU:
        return None
    published = PUBLISHED_CPU[n]
    if backend == 'python':
        return published.get('python')
    return min(published.values()) if backend == 'C++' else None


def configuration(n, a=0.25, seed=0):
    rng = np.random.default_rng(seed)
    side = np.sqrt(n / 0.5)
    r = np.column_stack([rng.uniform(0, side, n), rng.uniform(0, side, n), rng.uniform(a, 5.0, n)])
    return r, rng.standard_normal(3 * n), a


def time_product(blob_mobility, r, f, repeats, synchronize=None):
    """Median seconds of ``blob_mobility.velocities(r, f)`` (a ``mobility.interface.BlobMobility``)."""
    blob_mobility.velocities(r, f)  # warm-up (compilation, caches)
    if synchronize:
        synchronize()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        blob_mobility.velocities(r, f)
        if synchronize:
            synchronize()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--sizes', type=int, nargs='+', default=[1000, 4000, 16000])
    parser.add_argument('--gpu-sizes', type=int, nargs='*', default=[],
                        help='extra sizes run on the GPU backend only (e.g. 100000 300000)')
    parser.add_argument('--backends', nargs='+', default=registered_backends(Geometry('single_wall')))
    parser.add_argument('--repeats', type=int, default=3)
    parser.add_argument('--python-max', type=int, default=16000, help='largest N for the python backend')
    parser.add_argument('--radii-sizes', type=int, nargs='*', default=[1000, 4000],
                        help='sizes of the per-blob radii comparison (empty: skip it)')
    parser.add_argument('--radii-only', action='store_true', help='time only the radii comparison')
    args = parser.parse_args()

    usable = [b for b in args.backends if is_usable(b)]
    for b in args.backends:
        if b not in usable:
            print('# %s: not usable here (%s)' % (b, unusable_reason(b)))
    if 'C++' in usable:
        from mobility import cpp_backend, simd
        print('# C++ backend: %d OpenMP threads, kernel path %s' % (cpp_backend.max_threads(), simd.describe()))

    rows = []
    for n in ([] if args.radii_only else sorted(set(args.sizes) | set(args.gpu_sizes))):
        r, f, a = configuration(n)
        for wall_name, geometry in (('wall', 'single_wall'), ('no wall', 'free_space')):
            timings = {}
            for b in usable:
                if n in args.gpu_sizes and n not in args.sizes and b != 'pycuda':
                    continue
                if b == 'python' and n > args.python_max:
                    continue
                blob_mobility = make_mobility(b, Geometry(geometry), 1.0, a)
                inputs, sync = (r, f), None
                if b == 'pycuda':
                    import cupy as cp
                    inputs, sync = (cp.asarray(r), cp.asarray(f)), cp.cuda.Device().synchronize
                rss_before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
                repeats = 1 if (b == 'python' and n > 4000) else args.repeats
                timings[b] = time_product(blob_mobility, inputs[0], inputs[1], repeats, sync)
                rss_growth_mb = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - rss_before) / 1024.0
                rows.append((n, wall_name, b, timings[b], rss_growth_mb))
            for b, t in timings.items():
                ratio = timings['python'] / t if 'python' in timings else float('nan')
                published = published_seconds(n, wall_name, b)
                print('%8d  %-8s %-8s %12.3f ms  %10.3e pairs/s  x%-8.1f vs python  %s' % (
                    n, wall_name, b, 1e3 * t, n * n / t, ratio,
                    '' if published is None else 'published, recorded on another machine: %.3f ms' % (
                        1e3 * published)))
    if rows:
        print('# peak resident-memory growth of the python backend runs: %.0f MB' % max(
            [row[4] for row in rows if row[2] == 'python'] or [0.0]))
    radii_comparison(args.radii_sizes, [b for b in usable if b in registered_backends(device='cpu')], args.repeats)


def radii_comparison(sizes, cpu_backends, repeats):
    """Time M f with per-blob radii against the equal-radius product (same backend, domain, positions)."""
    if not sizes:
        return
    print('# per-blob radii (uniform in [0.15, 0.35]) vs one radius a = 0.25')
    for n in sizes:
        r, f, a = configuration(n)
        radii = np.random.default_rng(1).uniform(0.15, 0.35, n)
        for wall_name, geometry in (('wall', 'single_wall'), ('no wall', 'free_space')):
            for b in cpu_backends:
                equal_mobility = make_mobility(b, Geometry(geometry), 1.0, a)
                equal = time_product(equal_mobility, r, f, repeats if n <= 4000 or b != 'python' else 1)
                different = time_product(equal_mobility.replace(blob_radius=radii), r, f,
                                         repeats if n <= 4000 or b != 'python' else 1)
                print('%8d  %-8s %-8s radii %10.3f ms  one radius %10.3f ms  ratio %.2f' % (
                    n, wall_name, b, 1e3 * different, 1e3 * equal, different / equal))


if __name__ == '__main__':
    main()
