"""Roofline of the compiled pair kernels: pairs per second, floating-point rate and fraction of the peak.

The peak is the machine's double-precision rate measured by a short loop of fused multiply-adds on the
vectors of the kernel path in use (``_mobility_cpp.fma_peak``: 12 independent chains per thread, so that the
FMA units never wait).  Each kernel is timed on the C++ extension directly (inputs prepared, best of
``--repeats``), on one core and on all cores (a child process per thread count, OMP_NUM_THREADS set), and
its floating-point rate is the count of its formula's operations (FLOPS_PER_PAIR, below) times the pairs
it evaluates per second.  The CPU, its vector extensions and the kernel path are printed first.

    python benchmarks/roofline.py                      # N = 4000 blobs
    python benchmarks/roofline.py --sizes 16000 --repeats 3
    RMB_SIMD=avx2 python benchmarks/roofline.py        # another kernel path (mobility/simd.py)

Operation counts (doc/performance.md explains them): each +, - and x of the formula once, a fused
multiply-add as the two operations it does, 1/sqrt as two (a square root and a division, whatever the
path computes it with); the regime of pairs farther apart than two radii (the regime almost every pair of
a large suspension is in); the work of the symmetric products per *unordered* pair (the pair's block is
computed once and applied in both directions), of the one-sided products per ordered pair.  Kernels
marked '-' are timed but not counted.
"""
import argparse
import json
import os
import platform
import subprocess
import sys
import time

import numpy as np

# operations per pair evaluation (see the module docstring); symmetric products count unordered pairs
FLOPS_PER_PAIR = {
    'wall M f': 147,           # 3 differences, 8 distances, 2 x 1/sqrt (4), RPY 8, Swan-Brady P1..P5 57, block 7,
                               # two applications 2 x 30
    'free-space M f': 54,      # 3 differences, 5 distance, 1/sqrt (2), RPY 8, two applications 2 x 18
    'wall rot x force': 99,    # free part 27 (distance, 1/sqrt, |r|^-3, cross product), wall part 72
    'wall trans x torque': 95,
    'wall rot x torque': 87,
    'free-space rot x force': 27,
    'free-space rot x torque': 34,
    'wall M f, radii': None,
    'free-surface M f': None,
    'blob-blob forces': None,
}
SYMMETRIC = {'wall M f', 'free-space M f', 'wall M f, radii', 'blob-blob forces'}


def cpu_description():
    """(model name, the vector extensions the CPU reports among those the kernels use)."""
    model, flags = platform.processor() or platform.machine(), set()
    try:
        with open('/proc/cpuinfo') as f:
            for line in f:
                key = line.split(':', 1)[0].strip()
                if key in ('model name', 'Model', 'CPU part') and model in ('', platform.machine(), 'x86_64'):
                    model = line.split(':', 1)[1].strip()
                if key in ('flags', 'Features') and not flags:
                    flags = set(line.split(':', 1)[1].split())
    except OSError:
        pass
    wanted = ('sse2', 'avx', 'avx2', 'fma', 'avx512f', 'avx512dq', 'asimd', 'sve', 'sve2')
    return model, [name for name in wanted if name in flags]


def configuration(n, a=0.25, seed=0):
    """The bench_mobility.py set-up: uniform in [0, L]^2 x [a, 5], L = sqrt(n / 0.5)."""
    rng = np.random.default_rng(seed)
    side = np.sqrt(n / 0.5)
    r = np.column_stack([rng.uniform(0, side, n), rng.uniform(0, side, n), rng.uniform(a, 5.0, n)])
    return r, rng.standard_normal(3 * n), a, rng.uniform(0.15, 0.35, n)


def kernels(n):
    """{name: (callable, pair evaluations per call)} on n blobs."""
    from mobility import _mobility_cpp as m
    from multi_bodies.solver import _forces_cpp
    r, f, a, radii = configuration(n)
    L0 = np.zeros(3)
    unordered, ordered = n * (n - 1) / 2.0, float(n) * n
    return {
        'wall M f': (lambda: m.product('trans_times_force', r, f, 1.0, a, L0, True), unordered),
        'free-space M f': (lambda: m.product('trans_times_force', r, f, 1.0, a, L0, False), unordered),
        'wall rot x force': (lambda: m.product('rot_times_force', r, f, 1.0, a, L0, True), ordered),
        'wall trans x torque': (lambda: m.product('trans_times_torque', r, f, 1.0, a, L0, True), ordered),
        'wall rot x torque': (lambda: m.product('rot_times_torque', r, f, 1.0, a, L0, True), ordered),
        'free-space rot x force': (lambda: m.product('rot_times_force', r, f, 1.0, a, L0, False), ordered),
        'free-space rot x torque': (lambda: m.product('rot_times_torque', r, f, 1.0, a, L0, False), ordered),
        'wall M f, radii': (lambda: m.radii_product(r, f, radii, 1.0, L0, True), unordered),
        'free-surface M f': (lambda: m.free_surface_product(r, f, 1.0, a, L0), ordered),
        'blob-blob forces': (lambda: _forces_cpp.blob_blob_forces(r, L0, 1.0, 0.1, a), unordered),
    }


def measure(sizes, repeats, seconds):
    """This process's numbers (its OpenMP threads): the peak and, per size and kernel, the best time."""
    from mobility import _mobility_cpp as m, simd
    threads = m.max_threads()
    result = {'threads': threads, 'path': simd.kernel_path(), 'peak': m.fma_peak(threads, seconds), 'kernels': {}}
    for n in sizes:
        for name, (call, pairs) in kernels(n).items():
            call()  # warm-up
            best = float('inf')
            for _ in range(repeats):
                start = time.perf_counter()
                call()
                best = min(best, time.perf_counter() - start)
            result['kernels']['%s|%d' % (name, n)] = (best, pairs)
    return result


def child(threads, sizes, repeats, seconds):
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env = dict(os.environ, OMP_NUM_THREADS=str(threads),
               PYTHONPATH=os.pathsep.join([root] + [p for p in [os.environ.get('PYTHONPATH')] if p]))
    command = [sys.executable, os.path.abspath(__file__), '--child', '--repeats', str(repeats), '--peak-seconds',
               str(seconds), '--sizes'] + [str(n) for n in sizes]
    out = subprocess.run(command, env=env, capture_output=True, text=True, cwd=root)
    if out.returncode != 0:
        sys.exit('roofline: the %d-thread measurement failed:\n%s' % (threads, out.stderr[-3000:]))
    return json.loads(out.stdout.strip().splitlines()[-1])


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--sizes', type=int, nargs='+', default=[4000])
    parser.add_argument('--repeats', type=int, default=3)
    parser.add_argument('--peak-seconds', type=float, default=0.3)
    parser.add_argument('--threads', type=int, nargs='+', default=None,
                        help='thread counts to measure (default: 1 and every core this process may use)')
    parser.add_argument('--child', action='store_true', help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(measure(args.sizes, args.repeats, args.peak_seconds)))
        return
    from mobility import simd
    from mobility.threads import available_cores
    model, extensions = cpu_description()
    print('# CPU: %s; vector extensions: %s' % (model, ' '.join(extensions) or 'unknown'))
    print('# kernel path: %s' % simd.describe())
    counts = args.threads or sorted({1, available_cores()})
    for threads in counts:
        data = child(threads, args.sizes, args.repeats, args.peak_seconds)
        peak = data['peak']
        print('# %d thread%s: measured peak %.3g GFLOP/s (FMA loop, %s path)'
              % (data['threads'], '' if data['threads'] == 1 else 's', peak / 1e9, data['path']))
        print('%-24s %7s %11s %14s %10s %8s' % ('kernel', 'N', 'time (ms)', 'pairs/s', 'GFLOP/s', 'of peak'))
        for key, (seconds, pairs) in data['kernels'].items():
            name, n = key.split('|')
            flops = FLOPS_PER_PAIR.get(name)
            rate = pairs / seconds
            print('%-24s %7s %11.3f %14.4g %10s %8s' % (
                name, n, 1e3 * seconds, rate, '-' if flops is None else '%.2f' % (flops * rate / 1e9),
                '-' if flops is None else '%.0f%%' % (100.0 * flops * rate / peak)))


if __name__ == '__main__':
    main()
