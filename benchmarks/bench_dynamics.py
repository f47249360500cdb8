"""Time one deterministic Adams-Bashforth step of many boomerangs, python vs C++ backends.

Boomerangs of 15 blobs (blob radius 0.25) on a square grid of spacing 4 at
height z = 2.5 with random orientations, gravity and the default soft
repulsions (blob-blob on the same backend as M f).  Prints, per number of
bodies and backend, the seconds per step (best of ``--repeats`` steps after
one warm-up step) and the GMRES iterations of the timed step.

    python benchmarks/bench_dynamics.py [--bodies 10 100 1000] [--repeats 3]
"""
import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from body.body import Body, bodies_to_arrays  # noqa: E402
from multi_bodies import multi_bodies_functions as mbf  # noqa: E402
from multi_bodies.structure_generators import boomerang  # noqa: E402
from multi_bodies.system import System  # noqa: E402
from quaternion_integrator.schemes import make_scheme  # noqa: E402

PYTHON_LIMIT = 100  # bodies; above this the dense-chunked python M f takes minutes per step


def boomerang_system(num_bodies, backend, seed=1):
    rng = np.random.default_rng(seed)
    side = int(np.ceil(np.sqrt(num_bodies)))
    reference = boomerang()
    bodies = []
    for k in range(num_bodies):
        q = rng.normal(size=4)
        body = Body([4.0 * (k % side), 4.0 * (k // side), 2.5], q / np.linalg.norm(q), reference, 0.25)
        body.ID = 'boomerang'
        bodies.append(body)
    physics = dict(g=1.0, repulsion_strength_wall=1.0, debye_length_wall=1.0, repulsion_strength=1.0,
                   debye_length=1.0, periodic_length=np.zeros(3), blob_radius=0.25, blob_mass=1.0)
    return System(bodies, bodies_to_arrays(bodies), mbf.load_user_hooks('/nonexistent'), physics, 1.0, 0.25, 1e-8,
                  vector_product_name=backend, blobs_name='python', blob_blob_name=backend)


def time_step(num_bodies, backend, repeats):
    system = boomerang_system(num_bodies, backend)
    scheme = make_scheme('deterministic_adams_bashforth', 0.01)
    scheme.step(system, 0)  # warm-up (and the Euler start of Adams-Bashforth)
    best = np.inf
    for step in range(1, repeats + 1):
        start = time.perf_counter()
        scheme.step(system, step)
        best = min(best, time.perf_counter() - start)
    return best, system.last_iterations


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--bodies', type=int, nargs='+', default=[10, 100, 1000])
    parser.add_argument('--backends', nargs='+', default=['python', 'C++'])
    parser.add_argument('--repeats', type=int, default=3)
    args = parser.parse_args(argv)
    print('OMP_NUM_THREADS = %s' % os.environ.get('OMP_NUM_THREADS', '(unset)'))
    print('%8s %8s %8s %14s %8s' % ('bodies', 'blobs', 'backend', 's per step', 'GMRES'))
    for n in args.bodies:
        for backend in args.backends:
            if backend == 'python' and n > PYTHON_LIMIT:
                print('%8d %8d %8s %14s %8s' % (n, 15 * n, backend, 'skipped', '-'))
                continue
            seconds, iterations = time_step(n, backend, args.repeats)
            print('%8d %8d %8s %14.4g %8d' % (n, 15 * n, backend, seconds, iterations), flush=True)


if __name__ == '__main__':
    main()
