"""Benchmark of the spectral Stokes product (``mobility.spectral``) beside DoublyPeriodicStokes and the direct
product, on the scenes of the reference README's "Timings".

Scenes (one per geometry): N blobs of radius 1.0155, eta 0.957e-3, force-only kernel w6, square box of side
L = 3.2 sqrt(N), heights uniform in [1.0155, 5], ``numpy.random.default_rng([20242, N])`` drawing x, y, z,
then the forces:

* ``DPBW``: a monolayer above the wall (wall at 0, zmax 10);
* ``DPSC``: the same blobs in a slit (walls at 0 and 10);
* ``TP``: a bulk box (z period 12, zmin 0).

Each (geometry, N) runs in its own process (so its peak memory is its own): set-up (parameters, product
object, stencils), one warm-up product, then ``--repeats`` products; printed: wall and CPU seconds per
product (median), the split spread / FFT / solve / interpolate of the last product, peak resident memory,
the grid.  Beside them: DoublyPeriodicStokes' figures from ``../shared/reference/dpstokes/timings.json``
(batch E, the quiet-machine pass, from the README's table, else C, D, B) and, up to ``--direct-max`` blobs, this package's direct
product on the same blobs (``mobility.interface``, C++ backend: the pseudo-periodic Rotne-Prager-Blake wall
product with the first ring of images for DPBW and DPSC, the pseudo-periodic free-space RPY with the 27
cells for TP).  Last, the growth exponent d log(time) / d log(N) between consecutive sizes.

The grid follows DoublyPeriodicStokes' exact rule (``whole_cells_tolerance=0``: at N = 1e4 its Ly/h is 490
up to round-off and the library adds a cell, 490 x 491), so both run the same grid; ``--round-cells`` takes
490 x 490 instead.

    python3 benchmarks/bench_spectral.py                           # N = 1e3, 1e4, 1e5, all geometries
    python3 benchmarks/bench_spectral.py --sizes 1000 --geometries DPBW --repeats 2
    python3 benchmarks/bench_spectral.py --sizes 1000000 --geometries DPBW --direct-max 0

Threads: OpenMP's (``OMP_NUM_THREADS``) for the compiled loops and the FFT workers.
"""
import argparse
import json
import math
import os
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
TIMINGS = REPO.parent / 'shared' / 'reference' / 'dpstokes' / 'timings.json'
RADIUS = 1.0155
ETA = 0.957e-3
ZMAX = {'TP': 12.0, 'DPBW': 10.0, 'DPSC': 10.0}
BATCH_ORDER = ('E', 'C', 'D', 'B', 'A')


def scene(geometry, N):
    """Positions (N, 3), forces (N, 3) and the box side of the timing scene."""
    L = 3.2 * math.sqrt(N)
    rng = np.random.default_rng([20242, N])
    x = rng.uniform(0, L, N)
    y = rng.uniform(0, L, N)
    z = rng.uniform(RADIUS, 5.0, N)
    F = rng.standard_normal((N, 3))
    return np.column_stack([x, y, z]), F, L


def run_one(geometry, N, repeats, direct_max, round_cells):
    """Measure one (geometry, N) in this process; returns a dict."""
    sys.path.insert(0, str(REPO))
    from mobility.spectral import SpectralStokes, dpstokes_parameters
    r, F, L = scene(geometry, N)
    clock, cpu = time.perf_counter, time.process_time
    t0, c0 = clock(), cpu()
    p = dpstokes_parameters(RADIUS, geometry, L, L, 0.0, ZMAX[geometry], kernel='w6',
                            whole_cells_tolerance=1e-9 if round_cells else 0.0, warn=False)
    stokes = SpectralStokes(p, ETA)
    stokes.set_positions(r)
    setup = clock() - t0, cpu() - c0
    stokes.product(F)  # warm-up (first touch of the grid, FFT plans)
    walls, cpus = [], []
    for _ in range(repeats):
        t0, c0 = clock(), cpu()
        stokes.product(F)
        walls.append(clock() - t0)
        cpus.append(cpu() - c0)
    out = dict(geometry=geometry, N=N, grid=[p.Nx, p.Ny, p.Nz], setup_s=setup[0], setup_cpu_s=setup[1],
               product_s=statistics.median(walls), product_cpu_s=statistics.median(cpus),
               phases=dict(stokes.timings), path=stokes.path,
               peak_rss_GB=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2 ** 20)
    if N <= direct_max:
        from mobility.interface import Geometry, make_mobility
        if geometry == 'TP':
            box = Geometry('free_space', periodic_length=(L, L, ZMAX['TP']))
        else:
            box = Geometry('single_wall', periodic_length=(L, L, 0.0))
        direct = make_mobility('C++', box, ETA, RADIUS)
        t0 = clock()
        direct.velocities(r, F.ravel())
        out['direct_s'] = clock() - t0
        out['direct'] = 'C++ %s, pseudo-periodic' % box.kind
    return out


def library_figures():
    """(geometry, N) -> (batch, Mdot wall median s, Mdot CPU median s, peak RSS GB, grid) from timings.json."""
    if not TIMINGS.exists():
        return {}
    runs = json.loads(TIMINGS.read_text()).get('runs', [])
    best = {}
    for run in runs:
        key = (run['geometry'], run['N'])
        batch = str(run.get('batch', '?')).split(':')[0].strip()  # 'E: quiet machine ...' -> 'E'
        rank = BATCH_ORDER.index(batch) if batch in BATCH_ORDER else len(BATCH_ORDER)
        cpu = run.get('mdot_cpu_median_s', float('nan'))
        entry = (rank, batch, run.get('mdot_median_s', float('nan')), cpu, run.get('peak_rss_GB', float('nan')),
                 '%dx%dx%d' % (run['Nx'], run['Ny'], run['Nz']))
        if key not in best or rank < best[key][0]:
            best[key] = entry
    for key, entry in quiet_pass_rows().items():  # batch E lives in the README's table only
        if key not in best or entry[0] < best[key][0]:
            best[key] = entry
    return {key: value[1:] for key, value in best.items()}


def quiet_pass_rows():
    """Batch E (the quiet-machine pass) rows of the reference README's timing table, which timings.json lacks:
    (geometry, N) -> (rank, 'E', Mdot wall median s, Mdot CPU s (lower end of a range), peak RSS GB, grid)."""
    readme = TIMINGS.parent / 'README.md'
    if not readme.exists():
        return {}
    rows = {}
    for line in readme.read_text().splitlines():
        cells = [cell.strip() for cell in line.strip().strip('|').split('|')]
        if len(cells) < 12 or cells[0] != 'E':
            continue
        try:
            geometry, N = cells[1], int(cells[2])
            wall = float(cells[7].split()[0])
            cpu_text = cells[8].split('-')[0].strip()
            cpu = float(cpu_text) if cpu_text else float('nan')
            rows[(geometry, N)] = (BATCH_ORDER.index('E'), 'E', wall, cpu, float(cells[9]),
                                   cells[4].replace(' ', ''))
        except (ValueError, IndexError):
            continue
    return rows


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--sizes', type=int, nargs='+', default=[1000, 10000, 100000])
    parser.add_argument('--geometries', nargs='+', default=['DPBW', 'DPSC', 'TP'], choices=['DPBW', 'DPSC', 'TP'])
    parser.add_argument('--repeats', type=int, default=3)
    parser.add_argument('--direct-max', type=int, default=30000, help='largest N for the direct product')
    parser.add_argument('--round-cells', action='store_true', help='a whole number of cells up to round-off is '
                        'taken as such (490 x 490 at N = 1e4) instead of the library\'s extra cell')
    parser.add_argument('--one', nargs=2, metavar=('GEOMETRY', 'N'), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        result = run_one(args.one[0], int(args.one[1]), args.repeats, args.direct_max, args.round_cells)
        print('RESULT ' + json.dumps(result))
        return
    library = library_figures()
    print('spectral product, force-only w6, %s OpenMP threads; DoublyPeriodicStokes from %s'
          % (os.environ.get('OMP_NUM_THREADS', 'default'), TIMINGS if TIMINGS.exists() else '(not found)'))
    header = ('geom', 'N', 'grid', 'wall s', 'CPU s', 'spread', 'fft', 'solve', 'interp', 'peak GB',
              'DPS batch', 'DPS wall', 'DPS CPU', 'DPS GB', 'x faster', 'direct s')
    print(' '.join('%10s' % h for h in header))
    for geometry in args.geometries:
        previous = None
        for N in args.sizes:
            command = [sys.executable, __file__, '--one', geometry, str(N), '--repeats', str(args.repeats),
                       '--direct-max', str(args.direct_max)] + (['--round-cells'] if args.round_cells else [])
            done = subprocess.run(command, capture_output=True, text=True)
            lines = [line for line in done.stdout.splitlines() if line.startswith('RESULT ')]
            if done.returncode or not lines:
                print('%10s %10d   failed: %s' % (geometry, N, (done.stderr.strip().splitlines() or ['?'])[-1]))
                continue
            res = json.loads(lines[0][7:])
            ph = res['phases']
            lib = library.get((geometry, N))
            row = [geometry, N, 'x'.join(map(str, res['grid'])), '%.3f' % res['product_s'],
                   '%.3f' % res['product_cpu_s']] + ['%.3f' % ph[k] for k in ('spread', 'fft', 'solve', 'interpolate')]
            row.append('%.2f' % res['peak_rss_GB'])
            if lib:
                row += [lib[0], '%.2f' % lib[1], '%.2f' % lib[2], '%.2f' % lib[3], '%.1f' % (lib[1] / res['product_s'])]
            else:
                row += ['-'] * 5
            row.append('%.3f' % res['direct_s'] if 'direct_s' in res else '-')
            print(' '.join('%10s' % v for v in row))
            if previous is not None:
                exponent = math.log(res['product_s'] / previous[1]) / math.log(N / previous[0])
                print('%10s growth exponent %d -> %d: %.2f (time ratio %.1f)'
                      % ('', previous[0], N, exponent, res['product_s'] / previous[1]))
            previous = (N, res['product_s'])


if __name__ == '__main__':
    main()
