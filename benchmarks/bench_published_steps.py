"""The published rigid-body steps side by side with this package's: Adams-Bashforth and stochastic Slip_Trapz.

    python benchmarks/bench_published_steps.py --published-python /work/published_venv/bin/python \
        --published-tree /work/published_tree/RigidMultiblobsWall [--bodies 100] [--steps 5]
        [--schemes deterministic_adams_bashforth stochastic_Slip_Trapz] [--threads one default] [--lead-in 3]
        [--keep]

What runs: one input file, written here into a temporary folder, read by both codes: the published script
``multi_bodies/multi_bodies.py`` of ``--published-tree`` under ``--published-python`` (a checkout of the
published RigidMultiblobsWall and an interpreter with its numpy, scipy and numba), and this package's dynamic
run under this interpreter, each in its own process and folder (``benchmarks/published_step_worker.py``).
Each process takes one warm-up step (numba compiles there), then the steps are interleaved: one published step,
one of the package, and so on, ``--steps`` timed steps of each; while one code steps the other waits on a pipe.
Two things keep one code's conditions from leaking into the other's timings:

* a code's turn starts only once the process that stepped before has stopped using the CPU
  (``quiet_process.wait_until_idle``): the published numba threads (GNU OpenMP, spinning by default) keep
  spinning for some 20 ms after a step, and took a core from the package's next step;
* each timed step follows ``--lead-in`` untimed steps of the same code (default 3), as steps follow each other in
  a run of its own.  A step that starts on a machine idle for a few tenths of a second is slower: on the 2-core
  virtual machine of the developers the package's two-thread Adams-Bashforth step took 24 ms after 0.3 s idle
  against 13 ms back to back, and 16 ms after 0.3 s idle with its OpenMP threads spinning (``RMB_ACTIVE_WAIT=1``)
  in place of the package's default passive wait; side by side, its median was 16.5 ms with one untimed step
  before each timed one and 11.7 ms with three.  ``--lead-in 0`` times the steps as they come.  This is done
once with one thread for each code (OMP_NUM_THREADS, NUMBA_NUM_THREADS, OPENBLAS_NUM_THREADS and MKL_NUM_THREADS
set to 1 in both processes) and once with each code's default threads (those four variables removed).

Printed: the CPU model, its logical CPUs and vector extensions (from /proc/cpuinfo), then for each thread setting
and scheme, each code's threads and kernel path (the package's ``mobility.simd.describe()``), per step and as
medians the CPU seconds (all threads of the process) and wall seconds per step of each code and their ratios
(published / package, so above 1 means the package is faster), and how far apart the two codes' bodies are after
the same number of steps (largest distance of a body centre, and of a quaternion up to its sign): small (of
the order of the solver tolerance times the distance moved) for the deterministic scheme; the stochastic scheme
draws from numpy's legacy ``RandomState`` seeded alike in both codes (``random_generator published`` for the
package), so a distance of the order of a step's Brownian displacement means the codes drew different numbers.

The scene (``--bodies`` N): the boomerang of the published examples (``Structures/boomerang_N_15.vertex``: 15
blobs, two arms of 7 blobs at spacing 0.3 along x and y joined at the origin, blob radius 0.25) on a square grid,
ceil(sqrt(N)) bodies a row, spacing ``--spacing`` (5: two arms of 2.1 and a blob diameter fit between centres) at
height ``--height`` (3: the lowest blob of any orientation stays above z = 0.9), orientations uniformly random
(normalised normal 4-vectors of ``numpy.random.default_rng(--scene-seed)``, seed 1); eta = 1, g = 1 (weight 1 a
blob), the published soft wall and blob-blob repulsions of strength 1 and Debye length 1, blob-blob forces and
``M f`` by the numba names (the published numba kernels; this package's compiled kernels), per-body mobility
blocks by the python names, solver_tolerance 1e-8, dt 0.01, seed 1; for Slip_Trapz also kT 1 and rf_delta 1e-3
(the deterministic input leaves them out, as the package warns about options a scheme does not read).

Check it on a tiny scene only (``--bodies 4 --steps 2``); timings for the docs are made on a quiet machine.
"""
import argparse
import json
import math
import os
import shutil
import statistics
import subprocess
import sys
import tempfile

import numpy as np

from quiet_process import wait_until_idle

HERE = os.path.dirname(os.path.abspath(__file__))
WORKER = os.path.join(HERE, 'published_step_worker.py')
THREAD_VARIABLES = ('OMP_NUM_THREADS', 'NUMBA_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS')
SCHEMES = ('deterministic_adams_bashforth', 'stochastic_Slip_Trapz')
VECTOR_FLAGS = ('sse4_2', 'avx', 'avx2', 'fma', 'avx512f', 'avx512dq', 'avx512bw', 'avx512vl', 'avx512_vnni',
                'asimd', 'sve', 'sve2')
ARM_BLOBS = 7        # blobs on each arm of the boomerang, besides the corner
BLOB_SPACING = 0.3   # distance of neighbouring blobs along an arm


def boomerang_vertices():
    """(15, 3) blob positions of the published examples' boomerang: the corner at the origin, arms along x and y."""
    arm = BLOB_SPACING * np.arange(ARM_BLOBS, 0, -1)
    along_x = np.column_stack((arm, np.zeros(ARM_BLOBS), np.zeros(ARM_BLOBS)))
    along_y = np.column_stack((np.zeros(ARM_BLOBS), arm[::-1], np.zeros(ARM_BLOBS)))
    return np.vstack((along_x, np.zeros((1, 3)), along_y))


def scene(num_bodies, spacing, height, seed):
    """(locations (N, 3), unit quaternions (N, 4)) of the boomerangs (see the module note)."""
    rng = np.random.default_rng(seed)
    side = int(math.ceil(math.sqrt(num_bodies)))
    k = np.arange(num_bodies)
    locations = np.column_stack((spacing * (k % side), spacing * (k // side), np.full(num_bodies, height)))
    quaternions = rng.normal(size=(num_bodies, 4))
    return locations, quaternions / np.linalg.norm(quaternions, axis=1)[:, None]


def write_input(folder, scheme, args):
    """Write the vertex, clones and input files of the scene into ``folder``; returns the input file's path."""
    vertex = os.path.join(folder, 'boomerang_N_15.vertex')
    clones = os.path.join(folder, 'boomerang_N_15.clones')
    with open(vertex, 'w') as f:
        f.write('%d\n' % len(boomerang_vertices()))
        for row in boomerang_vertices():
            f.write('%.1f %.1f %.1f\n' % tuple(row))
    locations, quaternions = scene(args.bodies, args.spacing, args.height, args.scene_seed)
    with open(clones, 'w') as f:
        f.write('%d\n' % args.bodies)
        for r, q in zip(locations, quaternions):
            f.write('%s\n' % ' '.join(repr(float(x)) for x in list(r) + list(q)))
    lines = [('scheme', scheme),
             ('mobility_blobs_implementation', 'python'),
             ('mobility_vector_prod_implementation', 'numba'),
             ('blob_blob_force_implementation', 'numba'),
             ('dt', repr(args.dt)),
             ('n_steps', str(args.max_steps)),   # more than the worker takes: the worker stops the run
             ('n_save', str(args.max_steps)),    # step 0 is the only one saved
             ('eta', '1.0'), ('g', '1.0'), ('blob_radius', '0.25'),
             ('repulsion_strength', '1.0'), ('debye_length', '1.0'),
             ('repulsion_strength_wall', '1.0'), ('debye_length_wall', '1.0'),
             ('seed', str(args.seed)), ('random_generator', 'published'),
             ('solver_tolerance', repr(args.tolerance)),
             ('output_name', 'run'),
             ('structure', '%s %s' % (vertex, clones))]
    if scheme.startswith('stochastic'):  # the deterministic scheme does not read them (the package would warn)
        lines[-2:-2] = [('kT', repr(args.kT)), ('rf_delta', '1e-3')]
    path = os.path.join(folder, 'inputfile.dat')
    with open(path, 'w') as f:
        f.write('# bench_published_steps.py: %d boomerangs, %s (read by the published code and the package)\n'
                % (args.bodies, scheme))
        for name, value in lines:
            f.write('%-40s %s\n' % (name, value))
    return path


def cpu_description():
    """(model name, logical CPUs, vector extensions present) from /proc/cpuinfo ('unknown' where it is absent)."""
    model, flags = 'unknown', set()
    try:
        with open('/proc/cpuinfo') as f:
            for line in f:
                key, _, value = line.partition(':')
                key = key.strip()
                if key in ('model name', 'Model', 'CPU part') and model == 'unknown':
                    model = value.strip()
                elif key in ('flags', 'Features'):
                    flags.update(value.split())
    except OSError:
        pass
    present = [flag for flag in VECTOR_FLAGS if flag in flags]
    return model, os.cpu_count(), present


def environment(threads):
    """The workers' environment: one thread each ('one') or each code's default ('default')."""
    env = dict(os.environ)
    for name in THREAD_VARIABLES:
        env.pop(name, None)
        if threads == 'one':
            env[name] = '1'
    return env


class Worker:
    """One code's process (``published_step_worker.py``), set up and warmed up on one input file."""

    def __init__(self, python, code, input_file, folder, env, published_tree=None):
        self.code = code
        command = [python, WORKER, '--code', code, '--input-file', input_file]
        if published_tree is not None:
            command += ['--published-tree', published_tree]
        os.makedirs(folder)
        self.log_path = os.path.join(folder, 'worker.log')
        self.log = open(self.log_path, 'w')
        self.process = subprocess.Popen(command, cwd=folder, env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                        stderr=self.log, universal_newlines=True, bufsize=1)
        self.ready = self.receive()
        if 'ready' not in self.ready:
            self.fail('did not start: %s' % self.ready)

    def receive(self):
        line = self.process.stdout.readline()
        if not line:
            self.fail('ended without answering (exit status %s)' % self.process.wait())
        return json.loads(line)

    def fail(self, what):
        self.log.flush()
        with open(self.log_path) as f:
            tail = f.read()[-3000:]
        raise SystemExit('the %s worker %s\n--- its stderr (%s):\n%s' % (self.code, what, self.log_path, tail))

    def ask(self, order):
        self.process.stdin.write(order + '\n')
        self.process.stdin.flush()
        answer = self.receive()
        if 'error' in answer:
            self.fail(answer['error'])
        return answer

    def close(self):
        try:
            self.process.stdin.write('quit\n')
            self.process.stdin.close()
        except OSError:
            pass
        self.process.wait()
        self.log.close()


def quaternion_distance(p, q):
    """Largest distance between unit quaternions of rows of p and q (N, 4), up to the sign of each."""
    return float(np.max(np.minimum(np.linalg.norm(p - q, axis=1), np.linalg.norm(p + q, axis=1))))


def side_by_side(scheme, threads, args, folder):
    """Both codes' steps of ``scheme`` interleaved; prints the rows and returns (published, package) timings."""
    run_folder = os.path.join(folder, '%s_%s' % (scheme, threads))
    os.makedirs(run_folder)
    input_file = write_input(run_folder, scheme, args)
    env = environment(threads)
    workers = [Worker(args.published_python, 'published', input_file, os.path.join(run_folder, 'published'), env,
                      published_tree=args.published_tree)]
    try:
        workers.append(Worker(sys.executable, 'package', input_file, os.path.join(run_folder, 'package'), env))
        published, package = workers
        for worker in workers:
            if worker.ready['bodies'] != args.bodies:
                worker.fail('read %d bodies, not %d' % (worker.ready['bodies'], args.bodies))
        print('\n### %s, %d boomerangs (%d blobs), threads: %s' % (scheme, args.bodies, package.ready['blobs'], threads))
        print('  published: %s; kernels: %s' % (published.ready['threads'], published.ready['kernels']))
        print('  package:   %s' % package.ready['threads'] + ('' if package.ready['kernels'] in package.ready['threads']
                                                          else '; kernels: %s' % package.ready['kernels']))
        print('  %4s  %13s %13s  %13s %13s  %9s %9s' % ('step', 'published CPU', 'wall', 'package CPU', 'wall',
                                                    'ratio CPU', 'wall'))
        times = {'published': {'cpu': [], 'wall': []}, 'package': {'cpu': [], 'wall': []}}
        for step in range(1, args.steps + 1):
            for worker in workers:  # one published step, then one of the package
                for _ in range(args.lead_in):  # as in a run of its own, the timed step follows a step
                    worker.ask('untimed')
                answer = worker.ask('step')
                wait_until_idle(worker.process.pid)  # its threads' spin must not overlap the other's steps
                times[worker.code]['cpu'].append(answer['cpu'])
                times[worker.code]['wall'].append(answer['wall'])
            row = [times[c][k][-1] for c in ('published', 'package') for k in ('cpu', 'wall')]
            print('  %4d  %13.4f %13.4f  %13.4f %13.4f  %9.2f %9.2f' % (
                step, row[0], row[1], row[2], row[3], row[0] / row[2], row[1] / row[3]), flush=True)
        medians = [statistics.median(times[c][k]) for c in ('published', 'package') for k in ('cpu', 'wall')]
        print('  %4s  %13.4f %13.4f  %13.4f %13.4f  %9.2f %9.2f' % (
            'med.', medians[0], medians[1], medians[2], medians[3], medians[0] / medians[2],
            medians[1] / medians[3]))
        ends = [worker.ask('configuration') for worker in workers]
        locations = [np.array(end['locations']) for end in ends]
        orientations = [np.array(end['orientations']) for end in ends]
        print('  apart after %d steps each (warm-up and untimed included): body centres %.3e, quaternions %.3e' % (
            args.steps * (args.lead_in + 1) + 1, float(np.max(np.linalg.norm(locations[0] - locations[1], axis=1))),
            quaternion_distance(orientations[0], orientations[1])))
        return medians
    finally:
        for worker in workers:
            worker.close()


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--published-python', required=True, help='interpreter with the published code\'s packages')
    parser.add_argument('--published-tree', required=True, help='checkout of the published RigidMultiblobsWall')
    parser.add_argument('--bodies', type=int, default=100)
    parser.add_argument('--steps', type=int, default=5, help='timed steps of each code (after one warm-up step)')
    parser.add_argument('--schemes', nargs='+', choices=SCHEMES, default=list(SCHEMES))
    parser.add_argument('--threads', nargs='+', choices=('one', 'default'), default=['one', 'default'])
    parser.add_argument('--spacing', type=float, default=5.0)
    parser.add_argument('--height', type=float, default=3.0)
    parser.add_argument('--scene-seed', type=int, default=1)
    parser.add_argument('--seed', type=int, default=1)
    parser.add_argument('--dt', type=float, default=0.01)
    parser.add_argument('--kT', type=float, default=1.0)
    parser.add_argument('--tolerance', type=float, default=1e-8)
    parser.add_argument('--lead-in', type=int, default=3,
                        help='untimed steps a code takes right before each timed one (0: none)')
    parser.add_argument('--keep', action='store_true', help='keep the folder of inputs, outputs and worker logs')
    args = parser.parse_args(argv)
    if args.bodies < 1 or args.steps < 1 or args.lead_in < 0:
        parser.error('--bodies and --steps must be at least 1, --lead-in at least 0')
    if not os.path.isfile(os.path.join(args.published_tree, 'multi_bodies', 'multi_bodies.py')):
        parser.error('--published-tree %s has no multi_bodies/multi_bodies.py' % args.published_tree)
    args.published_tree = os.path.abspath(args.published_tree)
    args.max_steps = 10 * (args.steps * (args.lead_in + 1) + 2)
    model, cpus, flags = cpu_description()
    print('# bench_published_steps: the published step and the package\'s, side by side (ratio = published / '
          'package)')
    print('# CPU: %s; %s logical CPUs; vector extensions: %s' % (model, cpus, ' '.join(flags) or 'none found'))
    print('# seconds per step, after one warm-up step of each code; %d timed steps each, interleaved, each right '
          'after %d untimed step(s) of the same code' % (args.steps, args.lead_in))
    folder = tempfile.mkdtemp(prefix='bench_published_steps_')
    summary = []
    try:
        for threads in args.threads:
            print('\n## threads: %s' % ('one each (%s = 1)' % ', '.join(THREAD_VARIABLES) if threads == 'one' else
                                        'each code\'s default (%s unset)' % ', '.join(THREAD_VARIABLES)))
            for scheme in args.schemes:
                summary.append((threads, scheme, side_by_side(scheme, threads, args, folder)))
    finally:
        if args.keep:
            print('\n# inputs, outputs and worker logs kept in %s' % folder)
        else:
            shutil.rmtree(folder, ignore_errors=True)
    print('\n## summary: medians, seconds per step')
    print('  %-8s %-30s %13s %13s  %9s %9s' % ('threads', 'scheme', 'published CPU', 'package CPU', 'ratio CPU',
                                               'wall'))
    for threads, scheme, m in summary:
        print('  %-8s %-30s %13.4f %13.4f  %9.2f %9.2f' % (threads, scheme, m[0], m[2], m[0] / m[2], m[1] / m[3]))
    return 0


if __name__ == '__main__':
    sys.exit(main())
