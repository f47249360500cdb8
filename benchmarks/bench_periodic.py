"""A Slip_Trapz step of the published Spectral_Multiblob_Roller scene: the spectral product beside the
pseudo-periodic direct product, side by side in one run (issue 45, doc/periodic.md).

The scene is ``multi_bodies/examples/spectral_rollers`` (its ``make_scene.py``: the published folder's scene
built the same way, 12-blob rollers of particle radius 1.0155 whose blobs have half their smallest distance as
radius, at the published density; its ``user_defined_functions.py``: the folder's forces).  Default: the
published size, 2,048 rollers (24,576 blobs) in the box 128.7923 x 128.7923.

Variants, each a Model of the same input (``stochastic_Slip_Trapz``, ``solver_tolerance 1e-4``, the C++ blocks
of the wall for the preconditioner):

* ``spectral``: ``mobility_vector_prod_implementation spectral`` (doubly periodic above the wall, the published
  domain height, kernel w6);
* ``pseudo-periodic``: ``C++`` with ``periodic_length L L 0`` (the Rotne-Prager-Blake wall product with the
  first ring of image cells, the published approximation).

For each: the set-up seconds (Model, first preconditioner), then ``--steps`` steps: wall and CPU seconds per
step, blob-mobility products per step, GMRES iterations (deterministic and noise/RFD solves) and Lanczos
iterations per step, and the peak resident memory of the process.  The two variants run from the same state
and the same random numbers.

``--preconditioners``: GMRES iterations of one deterministic solve of the scene with the spectral product and
each choice of the preconditioner's blocks (the wall's, free space's, none).  ``--compare``: the deterministic
velocities of the spectral product against the pseudo-periodic product in the scene's box and in a box twice
as wide (the same rollers; the far images matter less), max relative difference.

    python3 benchmarks/bench_periodic.py                          # 2,048 rollers, 1 step each way
    python3 benchmarks/bench_periodic.py --rollers 32 --steps 2   # a check on a small scene
    python3 benchmarks/bench_periodic.py --rollers 128 --preconditioners --compare --variants

Threads: OpenMP's (``OMP_NUM_THREADS``) for the compiled products and the FFT workers.
"""
import argparse
import importlib.util
import os
import resource
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
EXAMPLE = REPO / 'multi_bodies' / 'examples' / 'spectral_rollers'

from mobility.interface import BlobMobility, Geometry, make_mobility  # noqa: E402
from multi_bodies.files.input_options import parse_input_text  # noqa: E402
from multi_bodies.run.run_setup import prepare  # noqa: E402
from quaternion_integrator.schemes import make_scheme  # noqa: E402
from utils import SimulationStopped  # noqa: E402


def example_module():
    spec = importlib.util.spec_from_file_location('spectral_rollers_scene', EXAMPLE / 'make_scene.py')
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


class CountingMobility(BlobMobility):
    """A BlobMobility over another that counts its ``velocities`` products."""

    def __init__(self, inner):
        self.inner = inner
        self.backend, self.geometry, self.eta = inner.backend, inner.geometry, inner.eta
        self.blob_radius, self.periodic_length = inner.blob_radius, inner.periodic_length
        self.relative_accuracy = inner.relative_accuracy
        self.products = 0

    def velocities(self, r_vectors, forces):
        self.products += 1
        return self.inner.velocities(r_vectors, forces)


def input_text(box, blob_radius, product, scheme='stochastic_Slip_Trapz'):
    """The example's input (its options, this scene's box and blob radius) with ``product`` as the vector product."""
    text = (EXAMPLE / 'inputfile_spectral_rollers.dat').read_text()
    lines = []
    for line in text.splitlines():
        name = line.split('#', 1)[0].split()[:1]
        if name == ['periodic_length']:
            line = 'periodic_length %.17g %.17g 0' % (box, box)
        elif name == ['blob_radius']:
            line = 'blob_radius %.17g' % blob_radius
        elif name == ['mobility_vector_prod_implementation']:
            line = 'mobility_vector_prod_implementation %s' % product
        elif name == ['scheme']:
            line = 'scheme %s' % scheme
        elif name == ['spectral_reading'] and product != 'spectral':
            continue  # an option of the spectral product only
        lines.append(line)
    return '\n'.join(lines) + '\n'


def model_in(folder, box, blob_radius, product, scheme='stochastic_Slip_Trapz'):
    """The Model of the example's input in ``folder`` (scene files and user functions there), quiet."""
    cwd = os.getcwd()
    os.chdir(folder)
    try:
        options = parse_input_text(input_text(box, blob_radius, product, scheme), 'input.dat', 'dynamic')
        with warnings.catch_warnings():
            warnings.simplefilter('ignore')
            setup = prepare(options, 'dynamics', log=lambda line: None, directory=str(folder))
    finally:
        os.chdir(cwd)
    return options, setup.system


def peak_memory_gb():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0 ** 2


def run_variant(name, folder, box, blob_radius, steps, seed):
    start = time.perf_counter()
    options, model = model_in(folder, box, blob_radius, 'spectral' if name == 'spectral' else 'C++')
    counting = CountingMobility(model.vector_mobility)
    model = model.replace(vector_mobility=counting)
    scheme = make_scheme(options.scheme, options.dt, options)
    state = scheme.init(model, model.start_configuration)
    setup = time.perf_counter() - start
    rng = np.random.default_rng(seed)
    wall = cpu = 0.0
    for _ in range(steps):
        w0, c0 = time.perf_counter(), time.process_time()
        state = scheme.step(model, state, rng)
        wall += time.perf_counter() - w0
        cpu += time.process_time() - c0
    c = state.counters
    print('%-16s set-up %7.2f s | per step: wall %8.2f s, CPU %8.2f s, products %6.1f, GMRES %5.1f deterministic + '
          '%5.1f noise/RFD, Lanczos %5.1f | peak RSS %.2f GB'
          % (name, setup, wall / steps, cpu / steps, counting.products / steps,
             (c.gmres_iterations - c.gmres_stochastic_iterations) / steps, c.gmres_stochastic_iterations / steps,
             c.lanczos_iterations / steps, peak_memory_gb()))
    sys.stdout.flush()
    return state


def preconditioner_iterations(folder, box, blob_radius):
    """GMRES iterations of one deterministic solve with the spectral product and each block choice."""
    options, model = model_in(folder, box, blob_radius, 'spectral', scheme='deterministic_forward_euler')
    configuration = model.start_configuration
    radius = model.blob_radius
    choices = {'wall blocks (default)': model.blobs_mobility,
               'free-space blocks': make_mobility('C++', Geometry('free_space'), model.eta, radius,
                                                  dense_matrices=True)}
    for label, blocks in choices.items():
        for preconditioner in ('block_diagonal', 'neighbours'):
            variant = model.replace(blobs_mobility=blocks, preconditioner=preconditioner)
            result = variant.deterministic_velocities(configuration)
            print('  %-22s %-15s GMRES iterations %3d' % (label, preconditioner, result.iterations))
    _, force_torque, slip = model.forces_and_slip(configuration)
    problem = model.mobility_problem(configuration)
    try:
        result = model.solve(problem, problem.rhs(slip=slip, force_torque=force_torque), None)
        print('  %-22s %-15s GMRES iterations %3d' % ('none', '-', result.iterations))
    except SimulationStopped as err:
        print('  %-22s %-15s %s' % ('none', '-', err))


def compare_velocities(folder, box, blob_radius, scale):
    """Max relative difference of the deterministic velocities, spectral against pseudo-periodic, in a box of side
    ``scale * box`` holding the same rollers."""
    _, spectral = model_in(folder, scale * box, blob_radius, 'spectral', scheme='deterministic_forward_euler')
    _, direct = model_in(folder, scale * box, blob_radius, 'C++', scheme='deterministic_forward_euler')
    configuration = spectral.start_configuration
    U_s = spectral.replace(solver_tolerance=1e-8).deterministic_velocities(configuration).velocities
    U_d = direct.replace(solver_tolerance=1e-8).deterministic_velocities(configuration).velocities
    for part, columns in (('linear', slice(0, 3)), ('angular', slice(3, 6))):
        difference = np.abs(U_s[:, columns] - U_d[:, columns]).max() / np.abs(U_d[:, columns]).max()
        print('  box %8.3f: %s velocities differ by %.2e of the largest' % (scale * box, part, difference))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--rollers', type=int, default=2048)
    parser.add_argument('--steps', type=int, default=1)
    parser.add_argument('--seed', type=int, default=45)
    parser.add_argument('--variants', nargs='*', default=None, help='spectral, pseudo-periodic (default both)')
    parser.add_argument('--preconditioners', action='store_true')
    parser.add_argument('--compare', action='store_true')
    args = parser.parse_args(argv)
    scene = example_module()
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        (folder / 'user_defined_functions.py').write_text((EXAMPLE / 'user_defined_functions.py').read_text())
        box, blob_radius = scene.write_scene(str(folder), args.rollers)
        print('scene: %d rollers of 12 blobs (%d blobs), box %.6g x %.6g, blob radius %.6g, OMP_NUM_THREADS=%s'
              % (args.rollers, 12 * args.rollers, box, box, blob_radius, os.environ.get('OMP_NUM_THREADS', '-')))
        if args.variants is not None or not (args.preconditioners or args.compare):
            for name in args.variants or ['spectral', 'pseudo-periodic']:
                run_variant(name, folder, box, blob_radius, args.steps, args.seed)
        if args.preconditioners:
            print('preconditioner blocks (one deterministic solve, solver_tolerance 1e-4):')
            preconditioner_iterations(folder, box, blob_radius)
        if args.compare:
            print('spectral against pseudo-periodic deterministic velocities (solver_tolerance 1e-8):')
            for scale in (1.0, 2.0):
                compare_velocities(folder, box, blob_radius, scale)


if __name__ == '__main__':
    main()
