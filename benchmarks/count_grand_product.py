"""Instructions of the grand mobility product in one pass against the four coupling products (issue 46).

Counts with valgrind's callgrind (instruction counts are repeatable on a loaded machine, unlike times) what one
``_mobility_cpp.grand_product`` (U and W of forces and torques, every pair once) costs against the four calls it
replaces (``product`` of trans_times_force, rot_times_force, trans_times_torque and rot_times_torque, each
counted alone), and against the two a roller's velocity needs (trans_times_force + trans_times_torque), above the
wall and in free space, at N blobs of radius 1 scattered over a square of side 2.5 sqrt(N) at heights 1 to 4 (one
thread).  Run::

    python benchmarks/count_grand_product.py --blobs 2000

It runs itself under ``valgrind --tool=callgrind --dump-before=getppid`` and marks the phases by calling
``os.getppid`` before each: a phase's instructions are its dump part's total.  The vector path is the one the
dispatch chooses under valgrind (valgrind runs no AVX-512: avx2 on an x86-64 with AVX2), printed with the
counts.  With ``--phases`` (what the child runs) it runs the phases and prints nothing.
"""
import argparse
import glob
import os
import re
import shutil
import subprocess
import sys
import tempfile

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

KINDS = ('trans_times_force', 'rot_times_force', 'trans_times_torque', 'rot_times_torque')
LABELS = [label for wall in ('wall', 'free space')
          for label in ['%s: grand product (one pass)' % wall] + ['%s: %s' % (wall, kind) for kind in KINDS]]


def scene(n):
    """Blob positions (n, 3), forces and torques (3n,) each: a fixed random scene."""
    rng = np.random.default_rng(11)
    side = 2.5 * np.sqrt(n)
    r = np.column_stack([rng.uniform(0, side, n), rng.uniform(0, side, n), rng.uniform(1.0, 4.0, n)])
    return r, rng.standard_normal(3 * n), rng.standard_normal(3 * n)


def run_phases(n):
    """Each phase of :data:`LABELS` after an ``os.getppid()`` (the dump marker); a warm-up first."""
    from mobility import _mobility_cpp as m
    r, F, T = scene(n)
    L = np.zeros(3)
    m.grand_product(r[:16], F[:48], T[:48], 1.0, 1.0, L, True)  # warm-up (first calls, imports)
    for wall in (True, False):
        os.getppid()
        m.grand_product(r, F, T, 1.0, 1.0, L, wall)
        for kind in KINDS:
            os.getppid()
            m.product(kind, r, F if kind.endswith('force') else T, 1.0, 1.0, L, wall)
    os.getppid()


def count(n):
    """{label: instructions} of one run under callgrind, and the vector path it ran."""
    workdir = tempfile.mkdtemp(prefix='count_grand_')
    try:
        env = dict(os.environ, OMP_NUM_THREADS='1')
        path = subprocess.run([sys.executable, '-c', 'from mobility import _mobility_cpp as m; print(m.simd_path())'],
                              cwd=ROOT, env=env, capture_output=True, text=True)
        cmd = ['valgrind', '--tool=callgrind', '--dump-before=getppid',
               '--callgrind-out-file=%s/callgrind.out' % workdir, sys.executable, os.path.abspath(__file__),
               '--phases', '--blobs', str(n)]
        run = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True)
        if run.returncode != 0:
            sys.exit('callgrind run failed:\n' + run.stderr[-2000:])
        under = re.findall(r'simd path under valgrind: (\w+)', run.stdout)
        # callgrind.out.1, .2, ...: the parts ended by each marker; callgrind.out: the rest (at exit)
        parts = sorted(glob.glob('%s/callgrind.out.*' % workdir), key=lambda p: int(p.rsplit('.', 1)[1]))
        parts.append('%s/callgrind.out' % workdir)
        totals = []
        for part in parts:
            with open(part) as f:
                match = re.search(r'^(?:summary|totals): (\d+)', f.read(), re.M)
            totals.append(int(match.group(1)) if match else 0)
        # parts: [before the first marker (imports, warm-up), the phases..., after the last marker]
        phases = totals[1:1 + len(LABELS)]
        return dict(zip(LABELS, phases)), (under[0] if under else path.stdout.strip())
    finally:
        shutil.rmtree(workdir, ignore_errors=True)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--blobs', type=int, default=2000)
    parser.add_argument('--phases', action='store_true', help='run the phases (the child under callgrind)')
    args = parser.parse_args()
    if args.phases:
        from mobility import _mobility_cpp as m
        print('simd path under valgrind: %s' % m.simd_path())
        run_phases(args.blobs)
        return
    if shutil.which('valgrind') is None:
        sys.exit('valgrind is not installed')
    counts, path = count(args.blobs)
    print('%d blobs, one thread, vector path %s: instructions (callgrind)' % (args.blobs, path))
    for label, value in counts.items():
        print('  %-62s %.4g' % (label, value))
    for wall in ('wall', 'free space'):
        grand = counts['%s: grand product (one pass)' % wall]
        four = sum(counts['%s: %s' % (wall, kind)] for kind in KINDS)
        roller = counts['%s: trans_times_force' % wall] + counts['%s: trans_times_torque' % wall]
        print('  %s: the four products %.4g = %.2f x the grand product; grand product = %.2f x trans_times_force; '
              'a roller\'s U (trans_times_force + trans_times_torque) %.4g = %.2f x the grand product'
              % (wall, four, four / grand, grand / counts['%s: trans_times_force' % wall], roller, roller / grand))


if __name__ == '__main__':
    main()
