"""Time one step of many boomerangs: deterministic Adams-Bashforth and the stochastic schemes.

Boomerangs of 15 blobs (blob radius 0.25) on a square grid of spacing 4 at
height z = 2.5 with random orientations, gravity and the default soft
repulsions (blob-blob on the same backend as M f), solver_tolerance 1e-8,
kT = 1, rf_delta 1e-3.  Prints, per number of bodies, backend and scheme,
the seconds per step (median of ``--repeats`` steps after one warm-up step;
the schemes' steps are taken in turn, one of each per round, so that a
drift in the machine's speed touches all of them alike), the ratio to the
Adams-Bashforth step measured in the same run, the products ``M f`` per step by where they go
(GMRES Krylov products, true residuals, Lanczos, random finite differences),
the preconditioner applications per step and the share of the step spent in
``M f``.  The counts and the share come from a second, instrumented run of
the same steps (the counting itself costs time, so it is not timed).

    python benchmarks/bench_dynamics.py [--bodies 10 100 1000] [--repeats 5]
        [--schemes deterministic_adams_bashforth stochastic_Slip_Trapz ...] [--backends C++ python]
        [--loaded] [--large]

``--loaded``: one busy background process (started here, killed at the end)
shares the cores; ``--large``: also one step of 1,000 boomerangs under
Slip_Trapz and of 10,000 rollers under stochastic_adams_bashforth_rollers.

The published code is not run here, and no ratio to it is printed: its steps are timed side by side with
this package's, on one machine, by ``bench_published_steps.py``.
"""
import argparse
import multiprocessing
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from body.body import Body, bodies_to_arrays  # noqa: E402
from mobility.interface import BlobMobility  # noqa: E402
from multi_bodies.solver import user_hooks  # noqa: E402
from multi_bodies.files.structure_generators import boomerang  # noqa: E402
from multi_bodies.solver.model import Model  # noqa: E402
from multi_bodies.files.input_options import options_with  # noqa: E402
from quaternion_integrator.schemes import make_scheme  # noqa: E402

PYTHON_LIMIT = 100  # bodies; above this the dense-chunked python M f takes minutes per step
DENSE_LIMIT = 10    # bodies; dense-algebra schemes above this take minutes per step
DEFAULT_SCHEMES = ['deterministic_adams_bashforth', 'stochastic_Slip_Trapz', 'stochastic_first_order_RFD',
                   'stochastic_traction_EM', 'stochastic_adams_bashforth']


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
    return Model(bodies, bodies_to_arrays(bodies), user_hooks.load_user_hooks('/nonexistent'), physics, 1.0, 0.25, 1e-8,
                  vector_product_name=backend, blobs_name=backend, blob_blob_name=backend)


PRODUCT_KINDS = ('gmres', 'residual', 'lanczos', 'rfd', 'other', 'paired')


def product_kind(frame):
    """Where a product of ``M f`` called from ``frame`` goes: one of PRODUCT_KINDS.

    GMRES: the Krylov products of ``krylov.gmres``; residual: a warm start's ``b - A x0``
    (``krylov.initial_residual``; the residual of each cycle costs no product); Lanczos; RFD
    (products at displaced configurations and at the configuration itself).  'paired': passes over the
    pairs that gave two products at once (one GMRES and one Lanczos product), counted once.
    """
    while frame is not None:
        name, code = frame.f_code.co_name, frame.f_code.co_filename
        if name == 'initial_residual':  # a warm start's b - A x0
            return 'residual'
        if name == 'gmres' and code.endswith('krylov.py'):
            return 'gmres'
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


class CountedMobility(BlobMobility):
    """A ``BlobMobility`` whose products (``velocities``, couplings, ``paired_velocities``) a ProductCounter counts."""

    def __init__(self, mobility, counter):
        self.mobility, self.counter = mobility, counter
        for name in ('backend', 'geometry', 'eta', 'blob_radius', 'periodic_length', 'has_rotation',
                     'pairs_in_one_pass', 'near_field_domain'):
            setattr(self, name, getattr(mobility, name))
        self._velocities = counter.wrap(mobility.velocities)
        self._coupling = counter.wrap(mobility.coupling)

    def velocities(self, r_vectors, forces):
        return self._velocities(r_vectors, forces)

    def coupling(self, kind, r_vectors, vector):
        return self._coupling(kind, r_vectors, vector)

    def check_coupling(self, kind):
        self.mobility.check_coupling(kind)

    def paired_velocities(self, r_vectors, forces_1, forces_2):
        self.counter.counts['paired'] += 1
        start = time.perf_counter()
        try:
            return self.mobility.paired_velocities(r_vectors, forces_1, forces_2)
        finally:
            self.counter.seconds += time.perf_counter() - start


def count_products(model):
    """(a Model like ``model`` whose M f products and preconditioners are counted, its ProductCounter)."""
    counter = ProductCounter()

    class CountedModel(Model):
        @property
        def roller_mobility(self):
            return CountedMobility(Model.roller_mobility.fget(self), counter)

        def build_preconditioner(self, configuration, solves=1):
            pc = Model.build_preconditioner(self, configuration, solves=solves)
            apply = pc.apply

            def counted_apply(x):
                counter.preconditioner += 1
                return apply(x)
            pc.apply = counted_apply  # its operator (linear_map.LinearMap) applies it
            return pc
    arguments = dict(model.arguments, vector_mobility=CountedMobility(model.vector_mobility, counter))
    return CountedModel(**arguments), counter


def busy_loop():  # pragma: no cover - runs in the background process of --loaded
    while True:
        pass


def boomerang_run(num_bodies, backend, scheme_name, noise_tolerance=None, counted=False):
    """A fresh (model, scheme, state, rng, counter or None) for ``scheme_name`` on ``num_bodies`` boomerangs."""
    model, counter = boomerang_system(num_bodies, backend), None
    if counted:
        model, counter = count_products(model)
    scheme = make_scheme(scheme_name, 0.01, options_with(kT=1.0, rf_delta=1e-3, update_PC=1,
                                                         noise_solver_tolerance=noise_tolerance))
    return model, scheme, scheme.init(model, model.start_configuration), np.random.default_rng(3), counter


def roller_run(num_rollers, counted=False):
    """A fresh (model, scheme, state, rng, counter or None): stochastic_adams_bashforth_rollers, rollers on a grid."""
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
    model = Model(bodies, bodies_to_arrays(bodies), user_hooks.load_user_hooks('/nonexistent'), physics, 1.0, 0.5,
                  1e-8, vector_product_name='C++', blobs_name='C++', blob_blob_name='C++',
                  omega_one_roller=np.array([0.0, 1.0, 0.0]), free_kinematics=False)
    counter = None
    if counted:
        model, counter = count_products(model)
    scheme = make_scheme('stochastic_adams_bashforth_rollers', 0.01, options_with(kT=1.0, rf_delta=1e-3, update_PC=1))
    return model, scheme, scheme.init(model, model.start_configuration), rng, counter


def interleaved_seconds(makers, repeats):
    """Median seconds per step of each run, the runs' steps taken in turn (one step of each per round).

    ``makers``: callables returning (model, scheme, state, rng, None), uninstrumented.  Every run first takes
    one warm-up step (the Euler start of the multistep schemes).  Taking the steps in turn puts every run
    under the same machine conditions, so the ratios of one call are fair even when the machine's speed drifts.
    """
    runs = [list(maker()) for maker in makers]
    for run in runs:
        model, scheme, state, rng, _ = run
        run[2] = scheme.step(model, state, rng)
    times = [[] for _ in runs]
    for _ in range(repeats):
        for k, run in enumerate(runs):
            model, scheme, state, rng, _ = run
            start = time.perf_counter()
            run[2] = scheme.step(model, state, rng)
            times[k].append(time.perf_counter() - start)
    return [float(np.median(t)) for t in times]


def counted_steps(maker, repeats):
    """Counters per step over ``repeats`` steps after the warm-up step, and the seconds of those steps, from
    an instrumented run (``maker`` returns a counter); the counting slows a step, so these seconds give only
    the kernel's share."""
    model, scheme, state, rng, counter = maker()
    state = scheme.step(model, state, rng)
    before = dict(state.counters.info(), **counter.snapshot())
    start = time.perf_counter()
    for _ in range(repeats):
        state = scheme.step(model, state, rng)
    seconds = (time.perf_counter() - start) / repeats
    after = dict(state.counters.info(), **counter.snapshot())
    per = {key: (after[key] - before[key]) / repeats for key in after}
    per['kernel_share'] = per['kernel_seconds'] / max(seconds, 1e-300)
    return per


ROW = '%7d %7s %36s %9.4g %6s %6.1f %6.1f %5.1f %5.1f %5.1f %6.1f %6.1f %5.0f%%'


def print_row(n, backend, scheme_name, seconds, reference, per):
    total = sum(per[k] for k in PRODUCT_KINDS)
    ratio = '%.2f' % (seconds / reference) if reference else '-'
    print(ROW % (n, backend, scheme_name, seconds, ratio, total, per['gmres'], per['residual'],
                 per['lanczos'], per['rfd'], per['paired'], per['pc'], 100.0 * per['kernel_share']), flush=True)


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
          'GMRES (Krylov), in residuals, in Lanczos, in RFD, the paired passes; pc = preconditioner applications; kernel = share of the step in M f')
    header = ('bodies', 'backend', 'scheme', 's/step', 'x AB', 'passes', 'gmres', 'resid', 'lancz', 'rfd',
              'paired', 'pc', 'kernel')
    print('%7s %7s %36s %9s %6s %6s %6s %5s %5s %5s %6s %6s %6s' % header)
    for n in args.bodies:
        for backend in args.backends:
            if backend == 'python' and n > PYTHON_LIMIT:
                continue
            names = [name for name in args.schemes
                     if not (('dense' in name or name in ('Fixman', 'stochastic_Slip_Mid_DLA')) and n > DENSE_LIMIT)]

            def maker(name, counted=False):
                tolerance = None if name.startswith('deterministic') else args.noise_tolerance
                return lambda: boomerang_run(n, backend, name, tolerance, counted)
            seconds = interleaved_seconds([maker(name) for name in names], args.repeats)
            reference = seconds[names.index('deterministic_adams_bashforth')] \
                if 'deterministic_adams_bashforth' in names else None
            for name, step_seconds in zip(names, seconds):
                per = counted_steps(maker(name, counted=True), args.repeats)
                print_row(n, backend, name, step_seconds, reference, per)
    if args.large:
        large = (('stochastic_Slip_Trapz', 1000, lambda counted=False: boomerang_run(
                      1000, 'C++', 'stochastic_Slip_Trapz', args.noise_tolerance, counted)),
                 ('stochastic_adams_bashforth_rollers', 10000, lambda counted=False: roller_run(10000, counted)))
        for name, n, make in large:
            seconds, = interleaved_seconds([make], 1)
            print_row(n, 'C++', name, seconds, None, counted_steps(lambda: make(counted=True), 1), None)

if __name__ == '__main__':
    main()
