"""Time one step of many boomerangs: deterministic Adams-Bashforth and the stochastic schemes.

Boomerangs of 15 blobs (blob radius 0.25) on a square grid of spacing 4 at
height z = 2.5 with random orientations, gravity and the default soft
repulsions (blob-blob on the same backend as M f), solver_tolerance 1e-8,
kT = 1, rf_delta 1e-3.  Prints, per number of bodies, backend and scheme,
the seconds per step (median of ``--repeats`` steps after one warm-up step),
the GMRES iterations per step of the deterministic solves and of the noise
and RFD solves, the solves per step, the Lanczos iterations per step, and
the ratio to the Adams-Bashforth step measured in the same run.

    python benchmarks/bench_dynamics.py [--bodies 10 100 1000] [--repeats 5]
        [--schemes deterministic_adams_bashforth stochastic_Slip_Trapz ...] [--backends C++ python]

The published code's figures on the same kind of 2-core machine (numba
backends, 100 boomerangs): stochastic_Slip_Trapz 2.0 s per step,
deterministic_adams_bashforth 1.35 s per step.
"""
import argparse
import os
import sys
import time
from types import SimpleNamespace

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from body.body import Body, bodies_to_arrays  # noqa: E402
from multi_bodies.solver import physics as mbf  # noqa: E402
from multi_bodies.solver import user_hooks  # noqa: E402
from multi_bodies.files.structure_generators import boomerang  # noqa: E402
from multi_bodies.solver.system import System  # noqa: E402
from quaternion_integrator.schemes import make_scheme  # noqa: E402

PYTHON_LIMIT = 100  # bodies; above this the dense-chunked python M f takes minutes per step
DENSE_LIMIT = 10    # bodies; dense-algebra schemes above this take minutes per step
DEFAULT_SCHEMES = ['deterministic_adams_bashforth', 'stochastic_Slip_Trapz', 'stochastic_first_order_RFD',
                   'stochastic_traction_EM', 'stochastic_adams_bashforth']
PUBLISHED_100 = {'stochastic_Slip_Trapz': 2.0, 'deterministic_adams_bashforth': 1.35}


def boomerang_system(num_bodies, backend, seed=1):
    rng = np.random.default_rng(seed)
    side = int(np.ceil(np.sqrt(num_bodies)))
    reference = boomerang()
    bodies = []
    for k in range(num_bodies):
        q = rng.normal(size=4)
        body = Body([4.0 * (k % side), 4.0 * (k // side), 2.5], q / np.linalg.norm(q), reference, 0.25)
        body.ID = 'boomerang'
        body.body_length = body.calc_body_length()
        bodies.append(body)
    physics = dict(g=1.0, repulsion_strength_wall=1.0, debye_length_wall=1.0, repulsion_strength=1.0,
                   debye_length=1.0, periodic_length=np.zeros(3), blob_radius=0.25, blob_mass=1.0)
    return System(bodies, bodies_to_arrays(bodies), user_hooks.load_user_hooks('/nonexistent'), physics, 1.0, 0.25, 1e-8,
                  vector_product_name=backend, blobs_name=backend, blob_blob_name=backend)


def time_steps(num_bodies, backend, scheme_name, repeats):
    """(median seconds per step, counters per step) over ``repeats`` steps after one warm-up step."""
    system = boomerang_system(num_bodies, backend)
    options = SimpleNamespace(kT=1.0, rf_delta=1e-3, update_PC=1)
    scheme = make_scheme(scheme_name, 0.01, options)
    rng = np.random.default_rng(3)
    scheme.step(system, 0, rng)  # warm-up (and the Euler start of the multistep schemes)
    before = system.counters(scheme)
    times = []
    for step in range(1, repeats + 1):
        start = time.perf_counter()
        scheme.step(system, step, rng)
        times.append(time.perf_counter() - start)
    after = system.counters(scheme)
    per_step = {key: (after[key] - before[key]) / repeats for key in after}
    return float(np.median(times)), per_step


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--bodies', type=int, nargs='+', default=[10, 100, 1000])
    parser.add_argument('--backends', nargs='+', default=['C++'])
    parser.add_argument('--schemes', nargs='+', default=DEFAULT_SCHEMES)
    parser.add_argument('--repeats', type=int, default=5)
    args = parser.parse_args(argv)
    print('OMP_NUM_THREADS = %s' % os.environ.get('OMP_NUM_THREADS', '(unset)'))
    header = ('bodies', 'backend', 'scheme', 's/step', 'x AB', 'GMRES det', 'GMRES noise', 'solves', 'Lanczos',
              'published')
    print('%7s %7s %42s %9s %6s %9s %11s %7s %8s %9s' % header)
    for n in args.bodies:
        for backend in args.backends:
            if backend == 'python' and n > PYTHON_LIMIT:
                continue
            reference = None
            for scheme_name in args.schemes:
                dense = 'dense' in scheme_name or scheme_name in ('Fixman', 'stochastic_Slip_Mid_DLA')
                if dense and n > DENSE_LIMIT:
                    continue
                seconds, per = time_steps(n, backend, scheme_name, args.repeats)
                if scheme_name == 'deterministic_adams_bashforth':
                    reference = seconds
                published = PUBLISHED_100.get(scheme_name) if n == 100 else None
                print('%7d %7s %42s %9.4g %6s %9.1f %11.1f %7.1f %8.1f %9s'
                      % (n, backend, scheme_name, seconds, '%.2f' % (seconds / reference) if reference else '-',
                         per['gmres_iterations_deterministic_solves'], per['gmres_iterations_noise_and_rfd_solves'],
                         per['deterministic_solves_count'] + per['noise_and_rfd_solves_count'],
                         per['stochastic_iterations_count'], '%.2f s' % published if published else '-'),
                      flush=True)


if __name__ == '__main__':
    main()
