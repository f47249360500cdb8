"""Two checkouts of this package side by side on the same input files: is a restructuring free? (issue 43)

Each checkout runs ``multi_bodies/multi_bodies.py`` on the same input file in its own process (``PYTHONPATH``
set to the checkout, its compiled extensions built in place), once with ``--short`` steps and once with
``--long`` steps; the difference of the two runs is the time of ``long - short`` steps, without the set-up,
the imports and the output of the first steps.  Rounds alternate the checkouts (old short, new short, old long,
new long, ...), so a drift in the machine's speed touches both alike.  Printed per scene: the median over
``--rounds`` of the CPU seconds (the child processes' user + system) and wall seconds per step of each
checkout, and the ratio new / old with the spread of the per-round ratios.

Scenes (the scenes of ``benchmarks/bench_dynamics.py``): ``--bodies`` boomerangs of 15 blobs (blob radius
0.25; the package's boomerang, arms of 2.1) on a square grid of spacing 4 at z = 2.5 with random orientations (seed 1), gravity and the default soft
repulsions, ``solver_tolerance 1e-8``, kT = 1, the C++ backends; schemes ``deterministic_adams_bashforth``
and ``stochastic_Slip_Trapz``.

    python3 benchmarks/bench_versions.py --old /path/to/old/checkout [--new .] [--bodies 100] [--rounds 5]

Threads: one each (``OMP_NUM_THREADS=1`` and the BLAS variables) unless ``--threads default``.
"""
import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
THREAD_VARIABLES = ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS', 'NUMBA_NUM_THREADS')


def boomerang_blobs():
    """(15, 3) blob positions of the benchmark boomerang (``multi_bodies.files.structure_generators.boomerang``,
    the scenes of bench_dynamics.py and trace_step.py), made once by the new checkout and read by both."""
    sys.path.insert(0, REPO)
    from multi_bodies.files.structure_generators import boomerang
    return np.asarray(boomerang(), dtype=float)


def write_scene(folder, bodies, scheme, steps):
    """The input file (path) of one scene in ``folder``; the structure files are shared by every run."""
    vertex = os.path.join(folder, 'boomerang.vertex')
    clones = os.path.join(folder, 'boomerang.clones')
    if not os.path.exists(vertex):
        blobs = boomerang_blobs()
        with open(vertex, 'w') as f:
            f.write('%d\n' % len(blobs) + ''.join('%.16g %.16g %.16g\n' % tuple(b) for b in blobs))
        rng = np.random.default_rng(1)
        side = int(np.ceil(np.sqrt(bodies)))
        q = rng.normal(size=(bodies, 4))
        q /= np.linalg.norm(q, axis=1)[:, None]
        with open(clones, 'w') as f:
            f.write('%d\n' % bodies)
            for k in range(bodies):
                f.write('%.16g %.16g %.16g %.16g %.16g %.16g %.16g\n'
                        % (4.0 * (k % side), 4.0 * (k // side), 2.5, *q[k]))
    name = '%s_%d' % (scheme, steps)
    os.makedirs(os.path.join(folder, name), exist_ok=True)
    lines = ['scheme %s' % scheme, 'dt 0.01', 'n_steps %d' % steps, 'n_save %d' % steps, 'eta 1.0', 'g 1.0',
             'kT 1.0', 'blob_radius 0.25', 'solver_tolerance 1e-8', 'seed 1',
             'mobility_blobs_implementation C++', 'mobility_vector_prod_implementation C++',
             'blob_blob_force_implementation None', 'body_body_force_torque_implementation None',
             'repulsion_strength_wall 1.0', 'debye_length_wall 0.5', 'output_name %s/run' % name,
             'structure boomerang.vertex boomerang.clones']
    path = os.path.join(folder, name + '.dat')
    with open(path, 'w') as f:
        f.write('\n'.join(lines) + '\n')
    return path


def run_once(checkout, input_file, folder, environment):
    """(CPU seconds of the child, wall seconds) of one run of ``checkout``'s multi_bodies.py."""
    env = dict(environment, PYTHONPATH=checkout)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    done = subprocess.run([sys.executable, os.path.join(checkout, 'multi_bodies', 'multi_bodies.py'),
                           '--input-file', os.path.basename(input_file)], cwd=folder, env=env,
                          stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        sys.exit('%s failed on %s:\n%s' % (checkout, input_file, done.stderr[-2000:]))
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime), wall


def cpu_name():
    try:
        with open('/proc/cpuinfo') as f:
            lines = f.read().splitlines()
    except OSError:
        return '?'
    model = next((line.split(':', 1)[1].strip() for line in lines if line.startswith('model name')), '?')
    flags = next((line.split(':', 1)[1].split() for line in lines if line.startswith('flags')), [])
    vector = [name for name in ('avx512f', 'avx2', 'fma', 'sve', 'asimd') if name in flags]
    return '%s (%s), %d cores' % (model, ' '.join(vector) or 'no vector flags', os.cpu_count() or 1)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--old', required=True, help='the other checkout (extensions built in place)')
    parser.add_argument('--new', default=REPO)
    parser.add_argument('--bodies', type=int, default=100)
    parser.add_argument('--short', type=int, default=1)
    parser.add_argument('--long', type=int, default=6)
    parser.add_argument('--rounds', type=int, default=5)
    parser.add_argument('--schemes', nargs='+', default=['deterministic_adams_bashforth', 'stochastic_Slip_Trapz'])
    parser.add_argument('--threads', default='1', help="'1' (each run one thread) or 'default'")
    args = parser.parse_args()
    environment = dict(os.environ)
    if args.threads != 'default':
        environment.update({name: args.threads for name in THREAD_VARIABLES})
    checkouts = {'old': os.path.abspath(args.old), 'new': os.path.abspath(args.new)}
    print('CPU %s; threads %s; old %s, new %s' % (cpu_name(), args.threads, checkouts['old'], checkouts['new']))
    print('%32s %10s %10s %10s %10s %10s %16s' % ('scheme', 'old CPU s', 'new CPU s', 'old wall', 'new wall',
                                                  'new/old CPU', 'ratio range'))
    steps = args.long - args.short
    with tempfile.TemporaryDirectory() as folder:
        for scheme in args.schemes:
            short_input = write_scene(folder, args.bodies, scheme, args.short)
            long_input = write_scene(folder, args.bodies, scheme, args.long)
            per_step = {name: [] for name in checkouts}
            for _ in range(args.rounds):
                short = {name: run_once(path, short_input, folder, environment) for name, path in checkouts.items()}
                long = {name: run_once(path, long_input, folder, environment) for name, path in checkouts.items()}
                for name in checkouts:
                    per_step[name].append(((long[name][0] - short[name][0]) / steps,
                                           (long[name][1] - short[name][1]) / steps))
            old_cpu = statistics.median(c for c, _ in per_step['old'])
            new_cpu = statistics.median(c for c, _ in per_step['new'])
            ratios = [n[0] / o[0] for o, n in zip(per_step['old'], per_step['new'])]
            print('%32s %10.4f %10.4f %10.4f %10.4f %10.3f %8.3f-%.3f' % (
                scheme, old_cpu, new_cpu, statistics.median(w for _, w in per_step['old']),
                statistics.median(w for _, w in per_step['new']), new_cpu / old_cpu, min(ratios), max(ratios)))


if __name__ == '__main__':
    main()
