"""Cost of writing VTK files (save_vtk True) against the run time of the manual's dynamic example.

The example is ``multi_bodies/inputfile_dynamic.dat`` (a boomerang and two
spheres of 12 blobs, Adams-Bashforth, 10 steps) with ``n_save 1``: 11 saved
steps.  It is run ``--repeats`` times with ``save_vtk False`` and with
``save_vtk True``; the figures are the loop times that the script writes to
``.time`` (best of the repeats) and the wall time of the whole command.  The VTK cost is also timed directly
(``VtkSeries.write`` of the same 11 configurations), and for larger
suspensions of boomerangs to show how it grows with the number of blobs.

    python benchmarks/bench_vtk.py [--repeats 5] [--bodies 100 1000]
"""
import argparse
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, REPO)

from body.body import Body, Configuration, bodies_to_arrays  # noqa: E402
from multi_bodies.files.structure_generators import boomerang  # noqa: E402
from multi_bodies.run.vtk_output import VtkSeries  # noqa: E402

SCRIPT_DIR = os.path.join(REPO, 'multi_bodies')


def example_input(folder, save_vtk):
    """The manual's dynamic example with n_save 1 and output in ``folder``; returns the input path."""
    with open(os.path.join(SCRIPT_DIR, 'inputfile_dynamic.dat')) as f:
        lines = f.read().splitlines()
    kept = [line for line in lines if line.split()[:1] not in (['n_save'], ['output_name'], ['save_vtk'])]
    kept += ['n_save 1', 'output_name %s' % os.path.join(folder, 'run'), 'save_vtk %s' % save_vtk]
    path = os.path.join(folder, 'input.dat')
    with open(path, 'w') as f:
        f.write('\n'.join(kept) + '\n')
    return path


def run_example(save_vtk):
    """(loop time from the run's ``.time`` file, wall time of the whole command) in seconds."""
    with tempfile.TemporaryDirectory() as folder:
        path = example_input(folder, save_vtk)
        env = dict(os.environ, PYTHONPATH=REPO + os.pathsep + os.environ.get('PYTHONPATH', ''))
        start = time.perf_counter()
        subprocess.run([sys.executable, 'multi_bodies.py', '--input-file', path], cwd=SCRIPT_DIR, env=env,
                       check=True, stdout=subprocess.DEVNULL)
        wall = time.perf_counter() - start
        with open(os.path.join(folder, 'run.time')) as f:
            return float(f.read()), wall


def new_file_cost(count=200):
    """Seconds to create and write one new 4 kB file here: the floor of any per-step output file."""
    with tempfile.TemporaryDirectory() as folder:
        data = b'x' * 4096
        start = time.perf_counter()
        for k in range(count):
            with open(os.path.join(folder, '%d.dat' % k), 'wb') as f:
                f.write(data)
        return (time.perf_counter() - start) / count


def write_cost(body_arrays, names, counts, steps, rng):
    """Seconds to write ``steps`` steps of blob and body files for ``body_arrays`` (random moves between)."""
    with tempfile.TemporaryDirectory() as folder:
        series = VtkSeries(os.path.join(folder, 'run'), names, counts, 0.1)
        start = time.perf_counter()
        configuration = body_arrays.configuration
        for step in range(steps):
            configuration = Configuration(configuration.locations + 0.01 * rng.normal(
                size=configuration.locations.shape), configuration.orientations)
            series.write(step, body_arrays, configuration)
        return time.perf_counter() - start


def boomerangs(num_bodies, rng):
    reference = boomerang()
    side = int(np.ceil(np.sqrt(num_bodies)))
    bodies = []
    for k in range(num_bodies):
        q = rng.normal(size=4)
        body = Body([4.0 * (k % side), 4.0 * (k // side), 2.5], q / np.linalg.norm(q), reference, 0.25)
        body.ID = 'boomerang'
        bodies.append(body)
    return bodies_to_arrays(bodies)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--repeats', type=int, default=5)
    parser.add_argument('--bodies', type=int, nargs='*', default=[100, 1000],
                        help='boomerang suspensions for the direct write cost')
    args = parser.parse_args(argv)
    rng = np.random.default_rng(1)

    plain, with_vtk = [], []
    for _ in range(args.repeats):  # alternate, so that a change of load on the machine hits both alike
        plain.append(run_example('False'))
        with_vtk.append(run_example('True'))
    print('manual dynamic example, n_save 1 (11 saved steps, 39 blobs), best of %d runs' % args.repeats)
    print('%28s %12s %12s' % ('', 'loop (.time)', 'whole run'))
    for label, runs in (('save_vtk False', plain), ('save_vtk True', with_vtk)):
        print('%28s %10.3f s %10.3f s' % (label, min(r[0] for r in runs), min(r[1] for r in runs)))
    loop_extra = min(r[0] for r in with_vtk) - min(r[0] for r in plain)
    wall_extra = min(r[1] for r in with_vtk) - min(r[1] for r in plain)
    print('%28s %10.3f s %10.3f s' % ('difference', loop_extra, wall_extra))
    print('%28s %11.1f%% %11.1f%%' % ('VTK cost / run without VTK', 100.0 * loop_extra / min(r[0] for r in plain),
                                        100.0 * wall_extra / min(r[1] for r in plain)))
    plain = min(r[0] for r in plain)
    sys.path.insert(0, SCRIPT_DIR)
    from multi_bodies.files.input_options import read_input_file
    from multi_bodies.run.run_setup import read_bodies
    cwd = os.getcwd()
    os.chdir(SCRIPT_DIR)
    try:
        options = read_input_file('inputfile_dynamic.dat')
        import contextlib
        import io
        with contextlib.redirect_stdout(io.StringIO()):
            bodies, types, _ = read_bodies(options, lambda body, slip: None)
    finally:
        os.chdir(cwd)
    arrays = bodies_to_arrays(bodies, [count for _, count in types])
    direct = min(write_cost(arrays, [n for n, _ in types], [c for _, c in types], 11, rng)
                 for _ in range(args.repeats))
    print('  VtkSeries.write of 11 steps, timed directly: %.3f s = %.1f%% of the save_vtk False run (%.2f ms a step)'
          % (direct, 100.0 * direct / plain, 1e3 * direct / 11))
    print('  creating one new 4 kB file costs %.2f ms on this disk (each saved step creates two .vtp files, '
          'and the run itself one .clones file per structure)' % (1e3 * new_file_cost()))
    print()
    print('direct write cost per saved step (blob .vtp + body .vtp + two .pvd entries)')
    print('%8s %8s %12s %14s' % ('bodies', 'blobs', 'ms / step', 'us / blob'))
    for num_bodies in args.bodies:
        arrays = boomerangs(num_bodies, rng)
        steps = 5
        seconds = min(write_cost(arrays, ['boomerang'], [num_bodies], steps, rng) for _ in range(args.repeats))
        print('%8d %8d %12.2f %14.3f' % (num_bodies, arrays.num_blobs, 1e3 * seconds / steps,
                                         1e6 * seconds / steps / arrays.num_blobs))


if __name__ == '__main__':
    main()
