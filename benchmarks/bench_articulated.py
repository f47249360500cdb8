"""Time a step of articulated bacteria against the same bodies without joints.

A bacterium is a shell of ``--shell-blobs`` blobs (radius 0.95) and a helical flagellum of 40 blobs (length 10, from its location)
joined by two passive joints on the flagellum axis and one active joint turning the flagellum at 100 rad/s
(the ``bacteria_active.const`` of the published example), gravity on every blob (g = 1, so that the
free bodies have a problem to solve), blob radius 0.131, eta 1e-3, free space
(``numba_no_wall``, the backend of the published example), solver_tolerance 1e-10, nonlinear_solver_tolerance
1e-10, dt 0.0025.  Suspensions: bacteria on a square grid of spacing 15 in the plane z = 0.  Prints, per number
of bacteria, the seconds per step (median of ``--repeats`` steps after one warm-up step) and the GMRES
iterations per step of

* ``articulated_deterministic_midpoint`` (two solves per step, the published example's scheme),
* ``articulated_deterministic_forward_euler`` (one solve per step),
* ``deterministic_forward_euler`` on the same bodies as free rigid bodies (no joints, one solve per step),

and the ratios articulated / free.

    python benchmarks/bench_articulated.py [--bacteria 1 100] [--shell-blobs 162] [--repeats 3]
"""
import argparse
import os
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from multi_bodies.files.input_options import parse_input_text  # noqa: E402
from multi_bodies.files.structure_generators import icosahedral_shell  # noqa: E402
from multi_bodies.run.run_setup import prepare  # noqa: E402
from quaternion_integrator.schemes import make_scheme  # noqa: E402

ACTIVE = ('0 1   0 0 1.1310     0 0 -0.1310\n0 1   0 0 2.1310     0 0  0.869\n'
          '0 1   0 1 1.1310     0 1 -0.1310     1 0 1.1310   cos(-100*t) -sin(-100*t) -0.1310       0 0 0   '
          '100*sin(-100*t) 100*cos(-100*t) 0\n')


def write_files(folder, n_bacteria, shell_blobs):
    shell = icosahedral_shell(shell_blobs)
    shell = 0.9497 * shell / np.max(np.linalg.norm(shell, axis=1))
    s = np.linspace(0, 10.0, 40)
    flagellum = np.stack((0.35 * np.cos(2 * np.pi * s / 2.5), 0.35 * np.sin(2 * np.pi * s / 2.5), s), axis=1)
    np.savetxt(os.path.join(folder, 'shell.vertex'), shell, header=str(len(shell)), comments='')
    np.savetxt(os.path.join(folder, 'flagellum.vertex'), flagellum, header=str(len(flagellum)), comments='')
    with open(os.path.join(folder, 'bacteria.list_vertex'), 'w') as f:
        f.write('shell.vertex\nflagellum.vertex\n')
    with open(os.path.join(folder, 'bacteria.const'), 'w') as f:
        f.write('2\n3\n' + ACTIVE)
    side = int(np.ceil(np.sqrt(n_bacteria)))
    rows = []
    for k in range(n_bacteria):
        x, y = 15.0 * (k % side), 15.0 * (k // side)
        rows += ['%g %g 0 1 0 0 0' % (x, y), '%g %g 1.262 1 0 0 0' % (x, y)]
    with open(os.path.join(folder, 'bacteria.clones'), 'w') as f:
        f.write('%d\n%s\n' % (len(rows), '\n'.join(rows)))
    # the same bodies as free rigid bodies, in the same order: one structure line per body would be slow to
    # read, so the free bodies are two types (all shells, then all flagella)
    with open(os.path.join(folder, 'shells.clones'), 'w') as f:
        f.write('%d\n%s\n' % (n_bacteria, '\n'.join(rows[0::2])))
    with open(os.path.join(folder, 'flagella.clones'), 'w') as f:
        f.write('%d\n%s\n' % (n_bacteria, '\n'.join(rows[1::2])))


COMMON = """mobility_blobs_implementation python_no_wall
mobility_vector_prod_implementation numba_no_wall
blob_blob_force_implementation None
dt 0.0025
n_steps 10
solver_tolerance 1e-10
nonlinear_solver_tolerance 1e-10
eta 1e-3
g 1
blob_radius 0.1310
repulsion_strength_wall 0
"""


def time_scheme(folder, scheme_name, bodies_line, repeats):
    text = 'scheme %s\n%s%s\n' % (scheme_name, COMMON, bodies_line)
    options = parse_input_text(text, 'bench.dat', 'dynamic')
    setup = prepare(options, 'dynamics', log=lambda *a: None)
    system = setup.system
    scheme = make_scheme(scheme_name, options.dt, options)
    state = scheme.init(system, system.start_configuration)
    times, iterations = [], []
    for _ in range(repeats + 1):
        before = state.counters.gmres_iterations
        start = time.perf_counter()
        state = scheme.step(system, state)
        times.append(time.perf_counter() - start)
        iterations.append(state.counters.gmres_iterations - before)
    return float(np.median(times[1:])), float(np.mean(iterations[1:])), system.num_blobs


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--bacteria', type=int, nargs='+', default=[1, 100])
    parser.add_argument('--shell-blobs', type=int, default=162)
    parser.add_argument('--repeats', type=int, default=3)
    args = parser.parse_args(argv)
    here = os.getcwd()
    print('%9s %7s %-42s %10s %10s %9s' % ('bacteria', 'blobs', 'scheme', 's/step', 'GMRES/step', 'vs free'))
    for n in args.bacteria:
        with tempfile.TemporaryDirectory() as folder:
            write_files(folder, n, args.shell_blobs)
            os.chdir(folder)
            try:
                articulated = 'articulated bacteria.list_vertex bacteria.clones bacteria.const'
                free_line = 'structure shell.vertex shells.clones\nstructure flagellum.vertex flagella.clones'
                free, free_it, blobs = time_scheme(folder, 'deterministic_forward_euler', free_line, args.repeats)
                for scheme in ('articulated_deterministic_midpoint', 'articulated_deterministic_forward_euler'):
                    seconds, its, _ = time_scheme(folder, scheme, articulated, args.repeats)
                    print('%9d %7d %-42s %10.4f %10.1f %9.2f' % (n, blobs, scheme, seconds, its, seconds / free))
                print('%9d %7d %-42s %10.4f %10.1f %9.2f' % (n, blobs, 'deterministic_forward_euler (free)', free,
                                                             free_it, 1.0))
            finally:
                os.chdir(here)
    return 0


if __name__ == '__main__':
    sys.exit(main())
