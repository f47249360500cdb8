"""Error against cost of periodic blob products above a wall: a monolayer of rollers (doc/periodic_accuracy_vs_cost.md).

The scene: ``--rollers`` single-blob rollers of radius a = 1 (default 512) at random positions (seeded, centres
at least 2.2 a apart, heights uniform in [1.1, 1.8] a) in a square box periodic in x and y above the no-slip
wall at z = 0, area fraction ``--area-fraction`` (default 0.3).  The products, each applied to four loads
measured apart (seeded random forces; a uniform force (0.5, 0, -1), sedimentation; random torques; a uniform
torque about y, the rollers' drive):

* ``rings 1, 2, 3``: the pseudo-periodic direct sums of Rotne-Prager-Blake blobs with 1 (the published
  product), 2 and 3 rings of images about each minimum image (``mobility.image_sums.ring_sums``);
* ``spectral <kernel>``: the truly periodic spectral product, the rollers' monopole/dipole kernel pairs
  (``w6``, ``w5``, ``w6w5``, ``w6w4``, ``w5w4``) for the grand product, the force-only kernels (``w6``, ``w5``,
  ``w4``) for the translational product of rigid bodies (``M_UF``).

Errors: the largest relative error ``|U - U_ref| / |U_ref|`` over ``--targets`` sampled rollers among the
responses (velocities and angular velocities) to the loads.  References, each the converged truly periodic
answer of its own blob model:

* for the ring sums, the limit of the image sums of the same blobs over 4, 8, 16 rings (``--reference-rings``)
  extrapolated in 1/n (``mobility.image_sums.periodic_limit``, with its estimated error);
* for the spectral kernels, the w6 pair (force-only: w6) with the same continuous kernels on a grid twice as fine
  (``refined_parameters``), checked against the grid three times as fine.

The two references differ by the difference of the blob models (the spectral kernel's blob is not the
Rotne-Prager-Blake blob), printed and drawn as a dotted line: no setting of either product removes it.

Costs, measured by this script on this machine: the seconds of one product of the whole scene with the loads
of a step (forces and torques together; the translational panel: forces): the package's compiled one-ring
pseudo-periodic product (``C++``) for ring 1 and, for rings 2 and 3, that time times (2n + 1)^2 / 9 (a
compiled pair loop over (2n + 1)^2 images costs in proportion: modelled, marked so); the spectral product with
the kernel weights of the configuration kept (as within a solve; the preparation is printed apart).  Run it
alone on a quiet machine.

    python3 doc/charts/periodic_accuracy_vs_cost.py                   # the chart's numbers, the PNG, the JSON
    python3 doc/charts/periodic_accuracy_vs_cost.py --rollers 64 --targets 8 --reference-rings 8 --png /tmp/t.png

Writes ``--png`` (default ``doc/charts/periodic_accuracy_vs_cost.png``) and ``--json`` (default the PNG's name
with ``.json``), and prints the two tables in markdown.
"""
import argparse
import json
import os
import sys
import time
import warnings

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', '..'))

from mobility.image_sums import periodic_limit, relative_error, ring_sums  # noqa: E402
from mobility.interface import Geometry, make_mobility, usable_backends  # noqa: E402
from mobility.spectral.parameters import refined_parameters  # noqa: E402
from mobility.spectral_mobility import SpectralMobility, spectral_parameters_for  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
ETA, RADIUS = 1.0, 1.0
Z_BOUNDS = (0.0, 4.0)             # the spectral domain over the wall: heights up to 4 a
ROLLER_KERNELS = ('w6', 'w5', 'w6w5', 'w6w4', 'w5w4')
FORCE_KERNELS = ('w6', 'w5', 'w4')
RINGS = (1, 2, 3)


def monolayer(count, area_fraction, seed=0, min_distance=2.2):
    """Roller centres (count, 3) and the box side: random sequential addition in a periodic square box."""
    side = float(np.sqrt(count * np.pi * RADIUS ** 2 / area_fraction))
    rng = np.random.default_rng(seed)
    centres = np.empty((0, 3))
    tries = 0
    while len(centres) < count:
        tries += 1
        if tries > 1000 * count:
            raise SystemExit('cannot place %d rollers at area fraction %g with centres %g apart'
                             % (count, area_fraction, min_distance))
        candidate = np.array([rng.uniform(0, side), rng.uniform(0, side), rng.uniform(1.1, 1.8)])
        d = centres - candidate
        d[:, :2] -= side * np.round(d[:, :2] / side)
        if len(centres) == 0 or np.min(np.linalg.norm(d, axis=1)) >= min_distance:
            centres = np.vstack([centres, candidate])
    return centres, side


def loads(count, rotation, seed=1):
    """The loads measured apart: [(forces (N, 3) or None, torques (N, 3) or None)]."""
    rng = np.random.default_rng(seed)
    out = [(rng.standard_normal((count, 3)), None), (np.tile([0.5, 0.0, -1.0], (count, 1)), None)]
    if rotation:
        out += [(None, rng.standard_normal((count, 3))), (None, np.tile([0.0, 1.0, 0.0], (count, 1)))]
    return out


def responses(mobility, r, cases, rotation):
    out = []
    for F, T in cases:
        if not rotation:
            out.append((np.asarray(mobility.velocities(r, F.ravel())).reshape(-1, 3), None))
            continue
        U, W = mobility.product(r, None if F is None else F.ravel(), None if T is None else T.ravel())
        out.append((np.asarray(U).reshape(-1, 3), np.asarray(W).reshape(-1, 3)))
    return out


def error(values, reference, targets):
    """Largest relative error over the loads and the outputs (values of every roller or of the targets)."""
    worst = 0.0
    for got, want in zip(values, reference):
        for g, w in zip(got, want):
            if g is None or w is None:
                continue
            g = g[targets] if g.shape[0] != w.shape[0] else g
            worst = max(worst, relative_error(g, w))
    return worst


def seconds_of(call, repeats=3):
    call()
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        call()
        best = min(best, time.perf_counter() - start)
    return best


def panel(r, side, rotation, targets, reference_rings, log):
    """Rows (label, error, seconds, how the cost was found) and the notes of one panel."""
    n = r.shape[0]
    cases = loads(n, rotation)
    L = (side, side, 0.0)
    # the direct sums: partial sums at rings 1, 2, 3 and the periodic limit, at the targets
    counts = sorted(set(RINGS) | {reference_rings // 4, reference_rings // 2, reference_rings})
    direct, limits, estimate = {k: [] for k in RINGS}, [], 0.0
    start = time.perf_counter()
    for F, T in cases:
        sums = ring_sums(r, ETA, RADIUS, L, counts, F, T, targets, rotation=rotation)
        for k in RINGS:
            direct[k].append(sums[k])
        U, W, e = periodic_limit({c: sums[c] for c in (reference_rings // 4, reference_rings // 2, reference_rings)})
        limits.append((U, W))
        estimate = max(estimate, e)
    log('  direct sums and their periodic limit (%d rings): %.1f s, estimated error of the limit %.2g'
        % (reference_rings, time.perf_counter() - start, estimate))
    backend = 'C++' if 'C++' in usable_backends(Geometry('single_wall')) else 'python'
    one_ring = make_mobility(backend, Geometry('single_wall', L), ETA, RADIUS)
    F0, T0 = cases[0][0], (cases[2][1] if rotation else None)
    if rotation:
        t1 = seconds_of(lambda: one_ring.product(r, F0.ravel(), T0.ravel()))
    else:
        t1 = seconds_of(lambda: one_ring.velocities(r, F0.ravel()))
    rows = []
    for k in RINGS:
        rows.append(('rings %d' % k, error(direct[k], limits, targets), t1 * (2 * k + 1) ** 2 / 9.0,
                     'measured (%s)' % backend if k == 1 else 'modelled: ring 1 x %d/9' % (2 * k + 1) ** 2))
    # the converged spectral product
    geometry = Geometry('doubly_periodic_wall', L, Z_BOUNDS)
    with warnings.catch_warnings():
        warnings.simplefilter('ignore')
        base = spectral_parameters_for(geometry, RADIUS, 'w6', rotation=rotation)
    converged = {}
    for factor in (2, 3):
        start = time.perf_counter()
        mobility = SpectralMobility(geometry, ETA, RADIUS, parameters=refined_parameters(base, factor),
                                    near_wall='published')
        converged[factor] = [(U[targets], None if W is None else W[targets])
                             for U, W in responses(mobility, r, cases, rotation)]
        log('  spectral w6 on a grid %d times as fine: %.1f s' % (factor, time.perf_counter() - start))
    refinement = error(converged[2], converged[3], np.arange(len(targets)))
    model_difference = error(converged[2], limits, np.arange(len(targets)))
    for kernel in (ROLLER_KERNELS if rotation else FORCE_KERNELS):
        with warnings.catch_warnings():
            warnings.simplefilter('ignore')
            mobility = make_mobility('spectral', geometry, ETA, RADIUS, kernel=kernel, rotation=rotation,
                                     near_wall='published')
        values = responses(mobility, r, cases, rotation)
        if rotation:
            seconds = seconds_of(lambda: mobility.product(r, F0.ravel(), T0.ravel()))
        else:
            seconds = seconds_of(lambda: mobility.velocities(r, F0.ravel()))
        p = mobility.parameters
        rows.append(('spectral %s' % kernel, error(values, converged[2], targets), seconds,
                     'measured; grid %d x %d x %d; preparation %.3g s' % (p.Nx, p.Ny, p.Nz,
                                                                          mobility.timings.get('prepare', 0.0))))
    notes = dict(reference_estimate=estimate, refinement_change=refinement, model_difference=model_difference)
    return rows, notes


def draw(results, path):
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    from matplotlib.ticker import NullFormatter
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.8))
    for ax, (title, result) in zip(axes, results.items()):
        for label, err, seconds, how in result['rows']:
            ring = label.startswith('rings')
            ax.loglog(seconds, max(err, 1e-7), 'o' if ring else 's', color='C0' if ring else 'C1',
                      mfc='none' if 'modelled' in how else None)
            ax.annotate(label.replace('spectral ', ''), (seconds, max(err, 1e-7)), textcoords='offset points',
                        xytext=(5, 3), fontsize=8)
        ax.axhline(result['notes']['model_difference'], color='grey', ls=':', lw=1)
        ax.text(ax.get_xlim()[1], result['notes']['model_difference'], 'blob models differ ', fontsize=7,
                va='bottom', ha='right', color='grey')  # at the right end: the ring-1 point sits near the left
        ax.set_xlabel('seconds per product (this machine)')
        ax.set_ylabel('relative error against the periodic limit')
        ax.set_title(title, fontsize=10)
        ax.grid(True, which='both', alpha=0.3)
        ax.xaxis.set_minor_formatter(NullFormatter())   # decade labels only: minor labels overlap
    handles = [axes[0].plot([], [], 'o', color='C0')[0], axes[0].plot([], [], 'o', color='C0', mfc='none')[0],
               axes[0].plot([], [], 's', color='C1')[0]]
    fig.legend(handles, ['pseudo-periodic sum, n rings of images (cost measured)', 'the same, cost modelled',
                         'spectral product, kernel'], loc='lower center', ncol=3, fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0.06, 1, 1))
    fig.savefig(path, dpi=120)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--rollers', type=int, default=512)
    parser.add_argument('--area-fraction', type=float, default=0.3)
    parser.add_argument('--targets', type=int, default=32, help='sampled rollers of the error measure')
    parser.add_argument('--reference-rings', type=int, default=16, help='rings of the direct reference (n/4, n/2, n)')
    parser.add_argument('--png', default=os.path.join(HERE, 'periodic_accuracy_vs_cost.png'))
    parser.add_argument('--json', default=None)
    args = parser.parse_args(argv)
    if args.reference_rings % 4 or args.reference_rings < 8:
        parser.error('--reference-rings must be a multiple of 4, at least 8')

    def log(line):
        print(line, file=sys.stderr, flush=True)
    r, side = monolayer(args.rollers, args.area_fraction)
    targets = np.unique(np.linspace(0, len(r) - 1, min(args.targets, len(r))).round().astype(int))
    log('%d rollers in a %.4g x %.4g box, %d targets' % (len(r), side, side, len(targets)))
    results = {}
    for title, rotation in (('rollers: forces and torques (grand product)', True),
                            ('translation from forces (M_UF, rigid bodies)', False)):
        log(title)
        rows, notes = panel(r, side, rotation, targets, args.reference_rings, log)
        results[title] = dict(rows=rows, notes=notes)
        print('\n### %s\n' % title)
        print('| product | error | seconds per product | cost |')
        print('|---|---|---|---|')
        for label, err, seconds, how in rows:
            print('| %s | %.3g%% | %.3g | %s |' % (label, 100 * err, seconds, how))
        print('\nreference of the direct sums estimated within %.2g; converged spectral product: change %.2g from '
              'the grid three times as fine; the two references (blob models) differ by %.3g%%'
              % (notes['reference_estimate'], notes['refinement_change'], 100 * notes['model_difference']))
    draw(results, args.png)
    path = args.json or os.path.splitext(args.png)[0] + '.json'
    with open(path, 'w') as f:
        json.dump(dict(rollers=len(r), box=side, area_fraction=args.area_fraction, targets=len(targets),
                       reference_rings=args.reference_rings, panels=results), f, indent=1)
    log('wrote %s and %s' % (args.png, path))
    return 0


if __name__ == '__main__':
    sys.exit(main())
