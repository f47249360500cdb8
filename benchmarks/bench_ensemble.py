"""Throughput of an ensemble on a local Dask cluster: 16 replicas of 100 boomerangs, 1 worker against 2.

Each replica is a deterministic Adams-Bashforth run of ``--bodies``
boomerangs (15 blobs, blob radius 0.25, a square grid of spacing 4 at
z = 2.5, random orientations, gravity and the default soft repulsions) with
the C++ backend.  For every cluster configuration (worker processes x
OpenMP threads per worker) the benchmark starts a ``LocalCluster``, runs
all replicas through ``multi_bodies.ensembles.ensemble_runner.run_on_client`` and
prints

* the wall time of the ensemble and the replicas per minute;
* the speed-up over the first configuration;
* the mean run time of one task (measured inside the task, from reading the
  input to the last file written) and the overhead per task, i.e.
  ``(workers x wall - sum of task times) / tasks``: scheduling,
  serialisation, the first import in a fresh worker, idle workers at the end;
* the Dask round trip of an empty task (200 no-op tasks, submitted at once).

Cluster start-up is timed apart and not counted in the wall time.

    python benchmarks/bench_ensemble.py [--replicas 16] [--bodies 100] [--steps 10] [--configs 1x1 2x1 1x2]
"""
import argparse
import os
import shutil
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from multi_bodies.ensembles import ensemble_runner as runner  # noqa: E402
from multi_bodies.files.snapshots import write_clones_file  # noqa: E402
from multi_bodies.files.structure_files import write_vertex_file  # noqa: E402
from multi_bodies.files.structure_generators import boomerang  # noqa: E402


def write_scene(folder, num_bodies, steps, backend):
    rng = np.random.default_rng(1)
    side = int(np.ceil(np.sqrt(num_bodies)))
    locations = np.array([[4.0 * (k % side), 4.0 * (k // side), 2.5] for k in range(num_bodies)])
    orientations = rng.normal(size=(num_bodies, 4))
    orientations /= np.linalg.norm(orientations, axis=1)[:, None]
    write_vertex_file(os.path.join(folder, 'boomerang.vertex'), boomerang())
    write_clones_file(os.path.join(folder, 'boomerang.clones'), locations, orientations)
    path = os.path.join(folder, 'input.dat')
    with open(path, 'w') as f:
        f.write('scheme deterministic_adams_bashforth\n'
                'mobility_blobs_implementation python\n'
                'mobility_vector_prod_implementation %s\n'
                'blob_blob_force_implementation %s\n'
                'dt 0.01\nn_steps %d\nn_save %d\nblob_radius 0.25\noutput_name data/run\n'
                'structure boomerang.vertex boomerang.clones\n' % (backend, backend, steps, max(1, steps // 4)))
    return path


def empty_task_round_trip(client, count=200):
    client.gather(client.map(int, range(20), pure=False))  # warm
    start = time.perf_counter()
    client.gather(client.map(int, range(count), pure=False))
    return (time.perf_counter() - start) / count


def run_config(input_file, replicas, workers, threads, folder):
    import distributed
    start = time.perf_counter()
    cluster = runner.make_local_cluster(workers, omp_threads=threads, dashboard_address=None)
    client = distributed.Client(cluster)
    startup = time.perf_counter() - start
    try:
        plan = runner.build_plan(input_file, replicas, [], os.path.join(folder, '%dx%d' % (workers, threads)), 1)
        runner.write_plan(plan)
        start = time.perf_counter()
        with open(os.devnull, 'w') as quiet:
            results = runner.run_on_client(plan, client, stream=quiet)
        wall = time.perf_counter() - start
        round_trip = empty_task_round_trip(client)
    finally:
        client.close()
        cluster.close()
    failed = [r for r in results if r['status'] != 'done']
    if failed:
        raise SystemExit('replicas failed: %s' % failed[:3])
    task_seconds = np.array([r['seconds'] for r in results])
    return {'startup': startup, 'wall': wall, 'task': task_seconds.mean(),
            'overhead': (workers * wall - task_seconds.sum()) / len(results), 'round_trip': round_trip}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--replicas', type=int, default=16)
    parser.add_argument('--bodies', type=int, default=100)
    parser.add_argument('--steps', type=int, default=10, help='time steps per replica (default 10)')
    parser.add_argument('--backend', default='C++')
    parser.add_argument('--configs', nargs='+', default=['1x1', '2x1', '1x2'],
                        help='WORKERSxTHREADS: worker processes x OpenMP threads per worker')
    parser.add_argument('--keep', action='store_true', help='keep the replica folders (printed)')
    args = parser.parse_args(argv)
    folder = tempfile.mkdtemp(prefix='bench_ensemble_')
    input_file = write_scene(folder, args.bodies, args.steps, args.backend)
    print('%d replicas of %d boomerangs (%d blobs), %d Adams-Bashforth steps each, %s backend, %d cores'
          % (args.replicas, args.bodies, 15 * args.bodies, args.steps, args.backend, os.cpu_count() or 1))
    print('%8s %8s %10s %10s %12s %9s %11s %13s %13s' % ('workers', 'threads', 'start s', 'wall s',
                                                          'replicas/min', 'speed-up', 'task s', 'overhead/task',
                                                          'empty task'))
    first = None
    try:
        for config in args.configs:
            workers, threads = (int(v) for v in config.lower().split('x'))
            row = run_config(input_file, args.replicas, workers, threads, folder)
            first = first or row['wall']
            print('%8d %8d %10.2f %10.2f %12.1f %9.2f %11.3f %11.3f s %10.2f ms'
                  % (workers, threads, row['startup'], row['wall'], 60 * args.replicas / row['wall'],
                     first / row['wall'], row['task'], row['overhead'], 1e3 * row['round_trip']), flush=True)
    finally:
        if args.keep:
            print('replica folders in %s' % folder)
        else:
            shutil.rmtree(folder, ignore_errors=True)


if __name__ == '__main__':
    main()
