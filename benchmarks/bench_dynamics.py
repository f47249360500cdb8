"""Time one step of many boomerangs: deterministic Adams-Bashforth and the stochastic schemes.

Boomerangs of 15 blobs (blob radius 0.25) on a square grid of spacing 4 at
height z = 2.5 with random orientations, gravity and the default soft
repulsions (blob-blob on the same backend as M f), solver_tolerance 1e-8,
kT = 1, rf_delta 1e-3.  Prints, per number of bodies, backend and scheme,
the seconds per step (median of ``--repeats`` steps after one warm-up step),
the ratio to the Adams-Bashforth step measured in the same run, the speed-up
on the published figure, the products ``M f`` per step by where they go
(GMRES Krylov products, true residuals, Lanczos, random finite differences),
the preconditioner applications per step and the share of the step spent in
``M f``.

    python benchmarks/bench_dynamics.py [--bodies 10 100 1000] [--repeats 5]
        [--schemes deterministic_adams_bashforth stochastic_Slip_Trapz ...] [--backends C++ python]
        [--loaded] [--large]

``--loaded``: one busy background process (started here, killed at the end)
shares the cores; ``--large``: also one step of 1,000 boomerangs under
Slip_Trapz and of 10,000 rollers under stochastic_adams_bashforth_rollers.

The published code's figures on the same kind of 2-core machine (numba
backends, 100 boomerangs): stochastic_Slip_Trapz 2.0 s per step,
deterministic_adams_bashforth 1.35 s per step, 2.8 s with one busy process
on the same 2 cores.  The published code is not run here.
"""
import argparse
import linecache
import multiprocessing
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
# the published Adams-Bashforth step with one busy process on the same 2 cores (measured side by side)
PUBLISHED_LOADED = {'deterministic_adams_bashforth': 2.8}


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


PRODUCT_KINDS = ('gmres', 'residual', 'lanczos', 'rfd', 'other', 'paired')


def product_kind(frame):
    """Where a product of ``M f`` called from ``frame`` goes: one of PRODUCT_KINDS.

    GMRES: SciPy's Krylov products (``matvec(v[col, :])``); residual: SciPy's
    ``b - matvec(x)`` and any true residual computed after it; Lanczos; RFD
    (products at displaced configurations and at the configuration itself).  'paired': passes over the
    pairs that gave two products at once (one GMRES and one Lanczos product), counted once.
    """
    while frame is not None:
        name, code = frame.f_code.co_name, frame.f_code.co_filename
        if name == 'gmres' and '_isolve' in code:
            line = linecache.getline(code, frame.f_lineno)
            return 'residual' if 'matvec(x)' in line else 'gmres'
        if name == 'gmres_solve':
            return 'residual'
        if 'lanczos' in name:
            return 'lanczos'
        if name in ('products', 'rfd', 'products_at', 'difference', 'roller_drift', 'slip_rfd', 'traction_terms'):
            return 'rfd'
        frame = frame.f_back
    return 'other'


class ProductCounter:
    """Counts the products of ``M f`` by kind and the preconditioner applications, and the time in ``M f``."""

    def __init__(self):
        self.counts = dict.fromkeys(PRODUCT_KINDS, 0)
        self.preconditioner = 0
        self.seconds = 0.0

    def wrap(self, product):
        def counted(*args, **kwargs):
            self.counts[product_kind(sys._getframe(1))] += 1
            start = time.perf_counter()
            try:
                return product(*args, **kwargs)
            finally:
                self.seconds += time.perf_counter() - start
        return counted

    def snapshot(self):
        return dict(self.counts, pc=self.preconditioner, kernel_seconds=self.seconds)


def count_products(system):
    """Install a ProductCounter on ``system`` (its M f product and its preconditioners); returns it."""
    counter = ProductCounter()
    system.mobility_product = counter.wrap(system.mobility_product)
    if getattr(system, 'paired_mobility_product', None) is not None:
        paired = system.paired_mobility_product

        def counted_pair(*args):
            counter.counts['paired'] += 1
            start = time.perf_counter()
            try:
                return paired(*args)
            finally:
                counter.seconds += time.perf_counter() - start
        system.paired_mobility_product = counted_pair
    roller_product = system.roller_product
    system.roller_product = lambda kind: counter.wrap(roller_product(kind))
    build = system.build_preconditioner

    def counted_build(configuration):
        pc = build(configuration)
        apply = pc.apply

        def counted_apply(x):
            counter.preconditioner += 1
            return apply(x)
        pc.apply = counted_apply
        pc.operator = type(pc.operator)(pc.operator.shape, matvec=counted_apply, dtype=float)
        return pc
    system.build_preconditioner = counted_build
    return counter


def busy_loop():  # pragma: no cover - runs in the background process of --loaded
    while True:
        pass


def time_steps(num_bodies, backend, scheme_name, repeats, noise_tolerance=None):
    """(median seconds per step, counters per step) over ``repeats`` steps after one warm-up step."""
    system = boomerang_system(num_bodies, backend)
    counter = count_products(system)
    options = SimpleNamespace(kT=1.0, rf_delta=1e-3, update_PC=1, noise_solver_tolerance=noise_tolerance)
    scheme = make_scheme(scheme_name, 0.01, options)
    rng = np.random.default_rng(3)
    return timed_steps(system, scheme, counter, rng, repeats)


def timed_steps(system, scheme, counter, rng, repeats):
    """(median seconds, counters per step) of ``repeats`` steps after one warm-up step (the Euler start of the
    multistep schemes)."""
    scheme.step(system, 0, rng)
    before = dict(system.counters(scheme), **counter.snapshot())
    times = []
    for step in range(1, repeats + 1):
        start = time.perf_counter()
        scheme.step(system, step, rng)
        times.append(time.perf_counter() - start)
    after = dict(system.counters(scheme), **counter.snapshot())
    return float(np.median(times)), {key: (after[key] - before[key]) / repeats for key in after}


def roller_step(num_rollers, repeats):
    """(median seconds, counters per step) of stochastic_adams_bashforth_rollers for rollers on a grid."""
    rng = np.random.default_rng(2)
    side = int(np.ceil(np.sqrt(num_rollers)))
    bodies = []
    for k in range(num_rollers):
        body = Body([2.0 * (k % side), 2.0 * (k // side), 1.5 + 0.1 * rng.random()], [1.0, 0.0, 0.0, 0.0],
                    np.zeros((1, 3)), 0.5)
        body.ID = 'roller'
        body.body_length = 1.0
        bodies.append(body)
    physics = dict(g=1.0, repulsion_strength_wall=1.0, debye_length_wall=0.1, repulsion_strength=1.0,
                   debye_length=0.1, periodic_length=np.zeros(3), blob_radius=0.5, blob_mass=1.0)
    system = System(bodies, bodies_to_arrays(bodies), user_hooks.load_user_hooks('/nonexistent'), physics, 1.0, 0.5,
                    1e-8, vector_product_name='C++', blobs_name='C++', blob_blob_name='C++',
                    omega_one_roller=np.array([0.0, 1.0, 0.0]), free_kinematics=False)
    counter = count_products(system)
    scheme = make_scheme('stochastic_adams_bashforth_rollers', 0.01, SimpleNamespace(kT=1.0, rf_delta=1e-3,
                                                                                      update_PC=1))
    return timed_steps(system, scheme, counter, rng, repeats)


ROW = '%7d %7s %36s %9.4g %6s %9s %6.1f %6.1f %5.1f %5.1f %5.1f %6.1f %6.1f %5.0f%%'


def print_row(n, backend, scheme_name, seconds, reference, per, published):
    total = sum(per[k] for k in PRODUCT_KINDS)
    ratio = '%.2f' % (seconds / reference) if reference else '-'
    published_text = '%.1fx' % (published / seconds) if published else '-'
    print(ROW % (n, backend, scheme_name, seconds, ratio, published_text, total, per['gmres'], per['residual'],
                 per['lanczos'], per['rfd'], per['paired'], per['pc'], 100.0 * per['kernel_seconds'] / max(seconds, 1e-300)),
          flush=True)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--bodies', type=int, nargs='+', default=[10, 100, 1000])
    parser.add_argument('--backends', nargs='+', default=['C++'])
    parser.add_argument('--schemes', nargs='+', default=DEFAULT_SCHEMES)
    parser.add_argument('--repeats', type=int, default=5)
    parser.add_argument('--loaded', action='store_true',
                        help='run with one busy background process (started here, killed at the end)')
    parser.add_argument('--noise-tolerance', type=float, default=None,
                        help='tolerance of the noise and RFD sub-solves and of Lanczos (default: the solver tolerance)')
    parser.add_argument('--large', action='store_true',
                        help='also 1,000 boomerangs Slip_Trapz and a 10,000-roller stochastic AB step (minutes)')
    args = parser.parse_args(argv)
    background = None
    if args.loaded:
        background = multiprocessing.get_context('fork').Process(target=busy_loop, daemon=True)
        background.start()
    try:
        run(args)
    finally:
        if background is not None:
            background.kill()
            background.join()


def run(args):
    from mobility import threads as mobility_threads
    print('OMP_NUM_THREADS = %s, kernel threads = %s, background load: %s, noise tolerance: %s'
          % (os.environ.get('OMP_NUM_THREADS', '(unset)'), mobility_threads.describe(),
             'one busy process' if args.loaded else 'none', args.noise_tolerance or 'solver_tolerance 1e-8'))
    print('passes over the blob pairs per step (M f products; a paired pass gives two), the single products in '
          'GMRES (Krylov), in residuals, in Lanczos, in RFD, the paired passes; pc = preconditioner applications; kernel = share of the step in M f; pub = speed-up on the published step (%s)'
          % ', '.join('%s %.2f s' % item for item in (PUBLISHED_LOADED if args.loaded else PUBLISHED_100).items()))
    header = ('bodies', 'backend', 'scheme', 's/step', 'x AB', 'pub', 'passes', 'gmres', 'resid', 'lancz', 'rfd',
              'paired', 'pc', 'kernel')
    print('%7s %7s %36s %9s %6s %9s %6s %6s %5s %5s %5s %6s %6s %6s' % header)
    published_figures = PUBLISHED_LOADED if args.loaded else PUBLISHED_100
    for n in args.bodies:
        for backend in args.backends:
            if backend == 'python' and n > PYTHON_LIMIT:
                continue
            reference = None
            for scheme_name in args.schemes:
                dense = 'dense' in scheme_name or scheme_name in ('Fixman', 'stochastic_Slip_Mid_DLA')
                if dense and n > DENSE_LIMIT:
                    continue
                seconds, per = time_steps(n, backend, scheme_name, args.repeats,
                                          None if scheme_name.startswith('deterministic') else args.noise_tolerance)
                if scheme_name == 'deterministic_adams_bashforth':
                    reference = seconds
                published = published_figures.get(scheme_name) if n == 100 else None
                print_row(n, backend, scheme_name, seconds, reference, per, published)
    if args.large:
        seconds, per = time_steps(1000, 'C++', 'stochastic_Slip_Trapz', 1, args.noise_tolerance)
        print_row(1000, 'C++', 'stochastic_Slip_Trapz', seconds, None, per, None)
        seconds, per = roller_step(10000, 1)
        print_row(10000, 'C++', 'stochastic_adams_bashforth_rollers', seconds, None, per, None)


if __name__ == '__main__':
    main()
