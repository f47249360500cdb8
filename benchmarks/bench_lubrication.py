"""Benchmark of the lubrication core (lubrication/): Delta_R assembly, the factor of the preconditioner and
one solve of (I + M Delta_R) U = M F through the one solve, for spheres on a lattice near the wall.

Prints, for each lattice side, the number of spheres and of pairs within the cutoff, the median times of the
assembly of R_sup, R_MB and Delta_R, of the sparse LU of R_sup + s I, of the GMRES solve, and its iterations,
for each far-field backend asked.

    python benchmarks/bench_lubrication.py                          # 8 x 8 and 16 x 16, C++ far field
    python benchmarks/bench_lubrication.py --sides 8 16 32 --implementations python C++
    python benchmarks/bench_lubrication.py --steps --sides 8 16       # trapezoidal steps, near-field roots
    python benchmarks/bench_lubrication.py --breakdown --sides 8 16   # where a step's time goes, both assemblies
    python benchmarks/bench_lubrication.py --breakdown --sides 64 --repeats 1 --assembly compiled
    python benchmarks/bench_lubrication.py --kept --sides 8 16      # published solves against kept ones

With ``--breakdown``: one trapezoidal step (Lanczos root) timed, under cProfile, split into the assembly of
R_sup, R_MB and Delta_R (``assembly.resistance_matrices``), the sparse LU of the preconditioner (SuperLU),
the far-field products (the compiled blob products), the sparse products and triangular solves, and the
rest (Python: GMRES and Lanczos bookkeeping, array copies).  ``--assembly`` picks the assembly path
(``compiled``: the C++ kernels of ``lubrication/cpp/`` when built, ``python``: the NumPy fallback,
``both``: one after the other, each with the assembly alone timed too).

With ``--steps``: the median wall time of one stochastic trapezoidal step
(``lubrication.integrators.trapezoidal_step``: forces, noise, predictor, far-field RFD, corrector) with the
work counted (far-field products, GMRES and Lanczos iterations, sparse LU factorisations, Delta_R
assemblies), for both near-field roots, and the cost of one ``Delta_R^1/2 W`` by each root (published
step, measured on 2 cores with its numba far field: 1.38 s for 64 spheres, 2.09 s for 256).

With ``--kept``: 20 trapezoidal steps (``--kept-steps``) from the lattice with the published solves (a sparse LU
and a zero first guess at every solve) and with the kept ones (``lubrication.integrators.KeptSolves``, what
``preconditioner auto`` does in ``multi_bodies.py``), the two runs stepping in turn, at tolerances 1e-4 and 1e-8,
dt 1e-3 and 1e-2, with and without a spin of 12 held by the torques: median seconds per step and the ratio,
GMRES iterations per solve, sparse LUs per step.

With ``--versus-published``: the published trapezoidal step side by side with this package's, through the same
driver API (``Lub_Solver(...).Update_Bodies_Trap``), each code in its own process (the published one in its own
interpreter, ``--published-python``, from a rebuilt published checkout, ``--published-tree``), the steps of the two
interleaved (which goes first alternates), with one thread each and then with default threads each, CPU seconds
(all threads of the process) and wall seconds per step, 64 to 4096 spheres by default, and the ratios published /
package.  The scene and the worker are in ``benchmarks/lubrication_step_worker.py`` (radius 1, so that the
published pair distance is right).  ``--deterministic`` sets kT = 0 (Heun's method) and also prints how far
apart the two codes' spheres end (the same physics: within the GMRES tolerance).  Without
``--published-python`` it prints the published figures measured for issue 46 with their conditions instead::

    python benchmarks/bench_lubrication.py --versus-published --published-python /work/published_venv/bin/python \
        --published-tree /work/published_tree/RigidMultiblobsWall --sides 8 16 32 64 --versus-steps 3

Scene: radius a = 1.0155 (the published rollers), eta = 1e-3, a square lattice of spacing 2.3 a at height
1.2 a, jittered by 0.1 a in x and y (seed 1); random forces and torques (seed 2); tolerance 1e-8.
"""
import argparse
import json
import os
import subprocess
import sys
import time

import numpy as np

from bench_forces import median_time  # the benchmarks' one timer (median of repeats)
from lubrication import assembly, brownian, compiled, integrators, problem as lub_problem
from multi_bodies.solver.body_solver import solve

RADIUS, ETA, TOLERANCE = 1.0155, 1e-3, 1e-8


def lattice(side, spacing=2.3, height=1.2):
    """side^2 sphere centres (side^2, 3) on a jittered square lattice, in length units."""
    x, y = np.meshgrid(np.arange(side) * spacing, np.arange(side) * spacing)
    locations = np.column_stack((x.ravel(), y.ravel(), np.full(side * side, height)))
    locations[:, :2] += 0.1 * np.random.default_rng(1).uniform(-1, 1, (side * side, 2))
    return RADIUS * locations


KT, DT, STEP_TOLERANCE = 0.0040749841, 1e-3, 1e-4  # the rollers example's kT and solver tolerance


def settle(locations, orientations):
    """Forces (N, 6): buoyant weight of the rollers example (g = 0.0225 per sphere, down) and no torque."""
    force_torque = np.zeros((locations.shape[0], 6))
    force_torque[:, 2] = -0.0225
    return force_torque


def step_rows(side, implementation, repeats):
    """Median step times and counts of the trapezoidal step for both near-field roots."""
    locations = lattice(side)
    orientations = np.tile([1.0, 0.0, 0.0, 0.0], (locations.shape[0], 1))
    rows = []
    for root in brownian.NEAR_FIELD_ROOTS:
        settings = brownian.lubrication_settings(RADIUS, ETA, implementation=implementation, near_field_root=root)
        rng = np.random.default_rng(3)
        t_step, step = median_time(lambda: integrators.trapezoidal_step(settings, locations, orientations, settle,
                                                                        KT, DT, rng, STEP_TOLERANCE), repeats)
        matrices = settings.matrices(locations)
        W = np.random.default_rng(4).standard_normal(6 * locations.shape[0])
        t_root, near = median_time(lambda: brownian.NearFieldRoot(matrices.Delta_R, root,
                                                                  settings.shift(STEP_TOLERANCE), STEP_TOLERANCE),
                                   repeats)
        t_apply, _ = median_time(lambda: near.apply(W), repeats)
        rows.append((locations.shape[0], root, t_step, step.counts, t_root + t_apply, near.products))
    return rows


def main_steps(args):
    print('%6s %9s %8s %9s %6s %9s %7s %6s %12s %8s' % ('N', 'root', 'far', 'step s', 'M x', 'gmres its',
                                                        'lanczos', 'LU', 'root ms', 'root Mx'))
    for side in args.sides:
        for implementation in args.implementations:
            for n, root, t_step, counts, t_root, products in step_rows(side, implementation, args.repeats):
                print('%6d %9s %8s %9.3f %6d %9d %7d %6d %12.2f %8d' % (
                    n, root, implementation, t_step, counts['far_field_products'], counts['gmres_iterations'],
                    counts['lanczos_iterations'], counts['factorisations'], 1e3 * t_root, products))


def breakdown_rows(side, repeats):
    """(N, step seconds (median of the un-profiled runs), {part: seconds per step under cProfile})."""
    import cProfile
    import pstats
    locations = lattice(side)
    orientations = np.tile([1.0, 0.0, 0.0, 0.0], (locations.shape[0], 1))
    settings = brownian.lubrication_settings(RADIUS, ETA)
    rng = np.random.default_rng(3)

    def step():
        return integrators.trapezoidal_step(settings, locations, orientations, settle, KT, DT, rng, STEP_TOLERANCE)
    step()
    t_step, _ = median_time(step, repeats)
    profiler = cProfile.Profile()
    profiler.enable()
    for _ in range(repeats):
        step()
    profiler.disable()
    stats = pstats.Stats(profiler).stats
    total = sum(value[3] for key, value in stats.items() if key[2] == 'trapezoidal_step')

    def builtin(*names):  # own time of compiled functions whose name holds one of names
        return sum(value[2] for key, value in stats.items() if key[0] == '~' and any(n in key[2] for n in names))
    seconds = {'assembly': sum(value[3] for key, value in stats.items() if key[2] == 'resistance_matrices'),
               # the factorisations: the block LDL^T (factor, refactor, ordering) or SuperLU's gstrf where not built
               'sparse LU': builtin('gstrf', '_block_ldlt_cpp.factorise', '_block_ldlt_cpp.ordering_only'),
               # the far field: the one-pass grand product, or the coupling products where it is not built
               'far field': builtin('_mobility_cpp.product', '_mobility_cpp.grand_product'),
               'sparse products, solves': builtin('csr_matvec', 'bsr_matvec', "'solve' of 'SuperLU'",
                                                  '_block_ldlt_cpp.solve')}
    seconds['rest (Python)'] = total - sum(seconds.values())
    return locations.shape[0], t_step, {part: value / repeats for part, value in seconds.items()}


def main_breakdown(args):
    """For each side and each assembly path (one after the other): the assembly alone (median of 10 or more
    calls, unprofiled), the median step, and the step's parts under cProfile (seconds per step)."""
    paths = ('python', 'compiled') if args.assembly == 'both' else (args.assembly,)
    print('%6s %9s %12s %9s %10s %10s %10s %12s %14s' % ('N', 'assembly', 'assembly ms', 'step ms', 'assembly',
                                                         'sparse LU', 'far field', 'sparse/solves', 'rest (Python)'))
    print('(the parts: milliseconds per step under cProfile, which slows the Python parts)')
    for side in args.sides:
        locations = lattice(side)
        for path in paths:
            compiled.use_compiled(path == 'compiled')
            if path == 'compiled' and not compiled.in_use():
                print('%6d %9s (not built)' % (side * side, path))
                continue
            t_assembly, _ = median_time(lambda: assembly.resistance_matrices(locations, RADIUS, ETA),
                                        max(10, args.repeats))
            n, t_step, parts = breakdown_rows(side, args.repeats)
            print('%6d %9s %12.2f %9.2f %10.2f %10.2f %10.2f %12.2f %14.2f' % (
                n, path, 1e3 * t_assembly, 1e3 * t_step, 1e3 * parts['assembly'], 1e3 * parts['sparse LU'],
                1e3 * parts['far field'], 1e3 * parts['sparse products, solves'], 1e3 * parts['rest (Python)']))


def kept_rows(side, tolerance, dt, omega, steps):
    """{'published': .., 'kept': ..} of (s/step median, GMRES its/solve, LU/step) over ``steps`` trapezoidal
    steps from the lattice, the two runs stepping in turn (same seed), after one warm-up step."""
    settings = brownian.lubrication_settings(RADIUS, ETA)
    runs = {}
    for name in ('published', 'kept'):
        kept = integrators.KeptSolves(settings, tolerance) if name == 'kept' else None
        runs[name] = dict(locations=lattice(side), orientations=np.tile([1.0, 0.0, 0.0, 0.0], (side * side, 1)),
                          rng=np.random.default_rng(3), kept=kept, seconds=[], its=0, solves=0, lu=0)
    for step in range(steps + 1):
        for name, run in runs.items():
            start = time.perf_counter()
            result = integrators.trapezoidal_step(settings, run['locations'], run['orientations'], settle, KT, dt,
                                                  run['rng'], tolerance, omega=omega, kept=run['kept'])
            elapsed = time.perf_counter() - start
            run['locations'], run['orientations'] = result.locations, result.orientations
            if step:  # the first step builds what the kept run keeps
                run['seconds'].append(elapsed)
                run['its'] += result.counts['gmres_iterations']
                run['solves'] += 2 + (2 if omega is not None else 0)
                run['lu'] += result.counts['factorisations']
    return {name: (float(np.median(run['seconds'])), run['its'] / run['solves'], run['lu'] / steps)
            for name, run in runs.items()}


def main_kept(args):
    """The published solves against the kept ones (lubrication.integrators.KeptSolves): rollers of the lattice
    settling (kT of the rollers example) with and without a prescribed spin, at two time steps and tolerances."""
    print('%6s %8s %7s %6s %10s %9s %7s %7s %7s' % ('N', 'tol', 'dt', 'omega', 'solves', 's/step', 'ratio',
                                                    'its/sv', 'LU/step'))
    for side in args.sides:
        for tolerance in (1e-4, 1e-8):
            for dt in (1e-3, 1e-2):
                for omega in (None, 12.0):
                    rows = kept_rows(side, tolerance, dt, omega, args.kept_steps)
                    for name in ('published', 'kept'):
                        seconds, its, lu = rows[name]
                        print('%6d %8.0e %7.0e %6s %10s %9.4f %7.2f %7.2f %7.2f' % (
                            side * side, tolerance, dt, '-' if omega is None else '%g' % omega, name, seconds,
                            seconds / rows['published'][0], its, lu), flush=True)


# The published step measured for issue 46 (side by side, each code one process, steps interleaved, one thread each,
# CPU seconds per trapezoidal step, the lattice scene of this benchmark near the wall, kT > 0): printed with its
# conditions when the published code cannot be run here.
ISSUE_46_FIGURES = (
    'published figures of issue 46 (not measured now): CPU seconds per trapezoidal step, one thread each, each code '
    'one process, steps interleaved, lattice of spheres near the wall (this benchmark\'s scene), kT > 0',
    (('spheres', 'published', 'package then', 'ratio'),
     (64, 0.198, 0.051, 3.9), (256, 1.02, 0.309, 3.3), (1024, 8.35, 3.13, 2.7), (4096, 127.8, 46.1, 2.8)),
    'kT = 0: ratios 4.9, 4.3, 3.6 at 64, 256, 1024 spheres.  Run with --published-python and --published-tree '
    'to measure both codes now.')

THREAD_VARIABLES = ('OMP_NUM_THREADS', 'NUMBA_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS',
                    'NUMEXPR_NUM_THREADS')


def worker_environment(threads):
    """The environment of a worker: every thread count 1 (``threads == 'one'``) or none set ('default')."""
    env = {k: v for k, v in os.environ.items() if k not in THREAD_VARIABLES}
    if threads == 'one':
        env.update({k: '1' for k in THREAD_VARIABLES})
    return env


class Worker:
    """A ``lubrication_step_worker.py`` process (one code, one lattice) and its line protocol."""

    def __init__(self, python, code, side, threads, args):
        worker = os.path.join(os.path.dirname(os.path.abspath(__file__)), 'lubrication_step_worker.py')
        command = [python, worker, '--code', code, '--side', str(side), '--kT', repr(args.versus_kT),
                   '--dt', repr(args.versus_dt), '--tolerance', repr(args.versus_tolerance)]
        if code == 'published':
            command += ['--published-tree', args.published_tree]
        self.code = code
        self.process = subprocess.Popen(command, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                                        env=worker_environment(threads), cwd=os.path.dirname(worker))
        self.ready = self.read()

    def read(self):
        line = self.process.stdout.readline()
        if not line:
            raise RuntimeError('the %s worker stopped (exit %s); run it alone to see why' %
                               (self.code, self.process.wait()))
        return json.loads(line)

    def ask(self, command):
        self.process.stdin.write(command + '\n')
        self.process.stdin.flush()
        return self.read()

    def close(self):
        self.process.stdin.write('quit\n')
        self.process.stdin.flush()
        self.process.wait()


def versus_rows(side, threads, args):
    """Both codes' steps at one size and thread setting, interleaved: {code: {'cpu': [...], 'wall': [...],
    'rejected': n, 'threads': str}}, and the largest distance between the codes' spheres at the end (or None)."""
    workers = [Worker(args.published_python, 'published', side, threads, args), Worker(sys.executable, 'package',
                                                                                      side, threads, args)]
    rows = {w.code: {'cpu': [], 'wall': [], 'rejected': 0, 'threads': w.ready['threads']} for w in workers}
    for step in range(args.versus_steps):
        for worker in (workers if step % 2 == 0 else workers[::-1]):
            answer = worker.ask('step')
            row = rows[worker.code]
            row['cpu'].append(answer['cpu'])
            row['wall'].append(answer['wall'])
            row['rejected'] += sum(answer['rejected'])
    apart = None
    if args.deterministic:
        ends = [np.array(w.ask('locations')['locations']) for w in workers]
        apart = float(np.max(np.linalg.norm(ends[0] - ends[1], axis=1)))
    for worker in workers:
        worker.close()
    return rows, apart


def main_versus_published(args):
    """The published step side by side with the package's (see the module note)."""
    if args.published_python is None or args.published_tree is None:
        title, table, note = ISSUE_46_FIGURES
        print(title)
        print('%8s %10s %13s %6s' % table[0])
        for row in table[1:]:
            print('%8d %10.3f %13.3f %6.1f' % row)
        print(note)
        return
    print('trapezoidal steps through Lub_Solver.Update_Bodies_Trap, a = 1, kT = %g, dt = %g, tolerance = %g, '
          '%d steps each after one warm-up, interleaved; medians; ratio = published / package' % (
              args.versus_kT, args.versus_dt, args.versus_tolerance, args.versus_steps))
    print('%6s %8s %11s %11s %7s %11s %11s %7s %9s %s' % (
        'N', 'threads', 'pub CPU s', 'pkg CPU s', 'ratio', 'pub wall s', 'pkg wall s', 'ratio', 'rejected',
        'apart' if args.deterministic else ''))
    for threads in ('one', 'default'):
        for side in args.sides:
            rows, apart = versus_rows(side, threads, args)
            pub, pkg = rows['published'], rows['package']
            medians = [float(np.median(rows[c][k])) for k in ('cpu', 'wall') for c in ('published', 'package')]
            print('%6d %8s %11.4f %11.4f %7.2f %11.4f %11.4f %7.2f %4d %4d %s' % (
                side * side, threads, medians[0], medians[1], medians[0] / medians[1], medians[2], medians[3],
                medians[2] / medians[3], pub['rejected'], pkg['rejected'],
                '' if apart is None else '%.1e' % apart), flush=True)
        print('  threads (%s): published %s; package %s' % (threads, pub['threads'], pkg['threads']))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--sides', type=int, nargs='+', default=[8, 16])
    parser.add_argument('--implementations', nargs='+', default=['C++'])
    parser.add_argument('--repeats', type=int, default=5)
    parser.add_argument('--steps', action='store_true', help='time trapezoidal steps and near-field roots')
    parser.add_argument('--breakdown', action='store_true', help="where a trapezoidal step's time goes")
    parser.add_argument('--kept', action='store_true',
                        help='trapezoidal steps with the published solves and with the kept ones (KeptSolves)')
    parser.add_argument('--kept-steps', type=int, default=20, help='steps of each run of --kept')
    parser.add_argument('--versus-published', action='store_true',
                        help='the published trapezoidal step side by side with the package\'s (see the module note)')
    parser.add_argument('--published-python', default=None, help='the interpreter of the published code')
    parser.add_argument('--published-tree', default=None, help='the rebuilt published RigidMultiblobsWall folder')
    parser.add_argument('--versus-steps', type=int, default=3, help='timed steps of each code per size')
    parser.add_argument('--deterministic', action='store_true', help='kT = 0 in --versus-published')
    parser.add_argument('--versus-kT', type=float, default=KT)
    parser.add_argument('--versus-dt', type=float, default=DT)
    parser.add_argument('--versus-tolerance', type=float, default=STEP_TOLERANCE)
    parser.add_argument('--assembly', choices=('compiled', 'python', 'both'), default=None,
                        help='the C++ assembly when built (compiled), the NumPy fallback (python), or both one after '
                             'the other (the default of --breakdown)')
    args = parser.parse_args()
    if args.assembly is None:
        args.assembly = 'both' if args.breakdown else 'compiled'
    compiled.use_compiled(args.assembly != 'python')
    print('assembly:', args.assembly if args.assembly == 'both' else
          'compiled (C++)' if compiled.in_use() else 'NumPy')
    if args.versus_published:
        if args.deterministic:
            args.versus_kT = 0.0
        if args.sides == [8, 16]:  # the default sizes of the other modes
            args.sides = [8, 16, 32, 64]
        return main_versus_published(args)
    if args.breakdown:
        return main_breakdown(args)
    if args.steps:
        return main_steps(args)
    if args.kept:
        return main_kept(args)
    print('%6s %6s %10s %12s %10s %10s %5s %s' % ('N', 'pairs', 'far field', 'assembly ms', 'factor ms',
                                                  'solve ms', 'its', 'residual'))
    for side in args.sides:
        locations = lattice(side)
        n = locations.shape[0]
        force_torque = np.random.default_rng(2).standard_normal((n, 6))
        t_assembly, matrices = median_time(lambda: assembly.resistance_matrices(locations, RADIUS, ETA), args.repeats)
        for implementation in args.implementations:
            problem = lub_problem.LubricationProblem(locations, RADIUS, ETA, implementation=implementation,
                                                     matrices=matrices)
            t_factor, preconditioner = median_time(lambda: problem.preconditioner(TOLERANCE), args.repeats)
            rhs = problem.rhs(force_torque)
            t_solve, result = median_time(lambda: solve(problem, rhs, preconditioner, tolerance=TOLERANCE),
                                          args.repeats)
            print('%6d %6d %10s %12.1f %10.1f %10.1f %5d %.1e' % (
                n, matrices.neighbours.pairs.shape[0], implementation, 1e3 * t_assembly, 1e3 * t_factor,
                1e3 * t_solve, result.iterations, result.residual))


if __name__ == '__main__':
    main()
