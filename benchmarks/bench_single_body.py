"""Steps per second of the single-body codes (boomerang/ and sphere/), one body and ensembles.

Boomerang (15 blobs, gfactor 10, at rest height) with the python and C++
dense blob mobilities; sphere with the best-known analytic mobility.  For
each scheme and ensemble size: seconds per step (best of ``--repeats`` runs
of ``--steps`` steps) and body-steps per second; the ratio of C++ to python.

    python benchmarks/bench_single_body.py [--bodies 1 100 400] [--steps 20] [--repeats 2]
"""
import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from boomerang import boomerang_model as bm  # noqa: E402
from mobility.interface import Geometry, usable_backends  # noqa: E402
from sphere import sphere as sph  # noqa: E402
from sphere.single_body_integrators import SCHEMES, SingleBodyIntegrator  # noqa: E402


def seconds_per_step(model, kT, locations, orientations, scheme, steps, repeats, dt):
    best = np.inf
    for _ in range(repeats):
        integrator = SingleBodyIntegrator(scheme, model.mobility, model.force_torque, kT, model.is_valid,
                                          np.random.default_rng(1))
        loc, orient = locations, orientations
        start = time.perf_counter()
        for _ in range(steps):
            loc, orient = integrator.step(loc, orient, dt)
        best = min(best, (time.perf_counter() - start) / steps)
    return best


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--bodies', type=int, nargs='+', default=[1, 100, 400])
    parser.add_argument('--steps', type=int, default=20)
    parser.add_argument('--repeats', type=int, default=2)
    args = parser.parse_args(argv)
    backends = usable_backends(Geometry('single_wall'), dense_matrices=True)  # the dense backends, registry order
    print('boomerang, gfactor 10, dt 0.01 s (seconds per step, body-steps per second)')
    for nb in args.bodies:
        locations = np.tile([0.0, 0.0, 1.25], (nb, 1))
        orientations = np.tile([1.0, 0.0, 0.0, 0.0], (nb, 1))
        for scheme in SCHEMES:
            times = {}
            for backend in backends:
                model = bm.BoomerangModel(10.0, backend)
                times[backend] = seconds_per_step(model, bm.KT, locations, orientations, scheme, args.steps,
                                                  args.repeats, 0.01)
            line = '  bodies %4d  %-6s ' % (nb, scheme) + '  '.join(
                '%s %.2e s (%.0f/s)' % (b, t, nb / t) for b, t in times.items())
            if len(times) == 2:
                line += '  python/C++ %.1f' % (times['python'] / times['C++'])
            print(line)
    print('sphere, best-known mobility, dt 0.01')
    model = sph.SphereModel('best')
    for nb in args.bodies:
        locations = np.tile([0.0, 0.0, 1.5], (nb, 1))
        orientations = np.tile([1.0, 0.0, 0.0, 0.0], (nb, 1))
        for scheme in SCHEMES:
            t = seconds_per_step(model, sph.KT, locations, orientations, scheme, args.steps, args.repeats, 0.01)
            print('  bodies %4d  %-6s %.2e s (%.0f body-steps/s)' % (nb, scheme, t, nb / t))


if __name__ == '__main__':
    main()
