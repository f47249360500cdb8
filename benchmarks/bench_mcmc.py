"""Monte Carlo steps per second for a boomerang suspension, python vs C++ (and pycuda on a GPU).

100 boomerangs of 15 blobs (1,500 blobs; the T4 parameters: a = 0.324557,
kT = 0.0041419464, g = 1.539384e-4, soft wall and blob-blob repulsion of
strength 0.0957137 and length 0.1622787) on a square grid of spacing 3 at
height 1.2, random orientations about z.  For each backend it prints:

* all-bodies steps per second (the published move: one full energy, about
  1.1e6 blob pairs, per step) and the pair rate;
* one-body moves per second and one-body sweeps (every body once) per second;
* the CPU seconds (all threads) of one all-bodies step, a figure that other
  jobs on the machine change less than the wall clock;
* the cost of one one-body move relative to one all-bodies step, next to the
  pair ratio 2 n_k (N - n_k) / (N (N - 1) / 2), which is what it costs in
  pair terms (a one-body move computes the moved body's pairs before and after).

Each figure is the best of ``--repeats`` timed runs of ``--steps`` steps,
after a warm-up.  The OpenMP threads of the C++ backend follow OMP_NUM_THREADS.

    python benchmarks/bench_mcmc.py [--bodies 100] [--steps 200] [--repeats 3] [--backends python C++ pycuda]
"""
import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from body.body import Body, bodies_to_arrays  # noqa: E402
from many_bodyMCMC import mcmc_energy as me  # noqa: E402
from many_bodyMCMC.sampler import MetropolisSampler  # noqa: E402
from multi_bodies.files.structure_generators import boomerang  # noqa: E402
from utils import UserInputError  # noqa: E402

PHYSICS = dict(g=1.539384e-4, repulsion_strength_wall=0.0957137, debye_length_wall=0.1622787,
               repulsion_strength=0.0957137, debye_length=0.1622787, periodic_length=(0.0, 0.0, 0.0),
               blob_radius=0.324557, blob_mass=1.0)
KT = 0.0041419464


def suspension(num_bodies, backend, move, seed=1):
    rng = np.random.default_rng(seed)
    side = int(np.ceil(np.sqrt(num_bodies)))
    bodies = []
    for k in range(num_bodies):
        angle = rng.uniform(0, 2 * np.pi)
        body = Body([3.0 * (k % side), 3.0 * (k // side), 1.2], [np.cos(angle / 2), 0, 0, np.sin(angle / 2)],
                    boomerang(), PHYSICS['blob_radius'])
        body.ID = 'boomerang'
        bodies.append(body)
    arrays = bodies_to_arrays(bodies)
    hooks = me.load_user_potentials('/nonexistent')
    pair_sums, _ = me.make_pair_sums(backend, PHYSICS, hooks)
    energy = me.MCMCEnergy(arrays, PHYSICS, hooks, pair_sums)
    max_translation = 0.1 * PHYSICS['blob_radius']
    return MetropolisSampler(energy, arrays.locations, arrays.orientations, KT, max_translation,
                             max_translation / bodies[0].calc_body_length(), move), arrays.num_blobs


def steps_per_second(sampler, steps, repeats, seed=2):
    """(steps per wall-clock second, CPU seconds of all threads per step), best of ``repeats``."""
    rng = np.random.default_rng(seed)
    sampler.step(0, rng)
    best, cpu = np.inf, np.inf
    for _ in range(repeats):
        start, start_cpu = time.perf_counter(), time.process_time()
        for step in range(steps):
            sampler.step(step, rng)
        best = min(best, (time.perf_counter() - start) / steps)
        cpu = min(cpu, (time.process_time() - start_cpu) / steps)
    return 1.0 / best, cpu


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--bodies', type=int, default=100)
    parser.add_argument('--steps', type=int, default=200, help='all-bodies steps per timed run')
    parser.add_argument('--repeats', type=int, default=3)
    parser.add_argument('--backends', nargs='+', default=['python', 'C++', 'pycuda'])
    args = parser.parse_args(argv)
    threads = os.environ.get('OMP_NUM_THREADS', 'all cores')
    load = os.getloadavg()[0] if hasattr(os, 'getloadavg') else float('nan')
    print('Monte Carlo, %d boomerangs (OMP_NUM_THREADS = %s; %d cores, load average %.1f: figures scale down '
          'when other jobs share the cores)' % (args.bodies, threads, os.cpu_count() or 0, load))
    print('%-8s %8s %14s %12s %12s %14s %12s %16s %12s' % ('backend', 'blobs', 'all-bodies/s', 'pairs/s',
                                                          'cpu s/step', 'one-body/s', 'sweeps/s', 'one-body/all',
                                                          'pair ratio'))
    for backend in args.backends:
        try:
            sampler, num_blobs = suspension(args.bodies, backend, 'all_bodies')
        except UserInputError as err:
            print('%-8s skipped: %s' % (backend, err))
            continue
        steps = args.steps if backend != 'python' else max(5, args.steps // 20)
        all_rate, cpu_per_step = steps_per_second(sampler, steps, args.repeats)
        sweeper, _ = suspension(args.bodies, backend, 'one_body')
        sweeps = max(2, steps // args.bodies) if backend != 'python' else 1
        sweep_rate, _ = steps_per_second(sweeper, sweeps, args.repeats)
        one_body_rate = sweep_rate * args.bodies
        n_k = num_blobs // args.bodies
        pairs = num_blobs * (num_blobs - 1) / 2
        print('%-8s %8d %14.1f %12.3g %12.3g %14.1f %12.2f %16.4f %12.4f'
              % (backend, num_blobs, all_rate, all_rate * pairs, cpu_per_step, one_body_rate, sweep_rate,
                 all_rate / one_body_rate, 2 * n_k * (num_blobs - n_k) / pairs))
    print('target (issue 9): at least 300 all-bodies steps per second with C++ on 2 cores')


if __name__ == '__main__':
    main()
