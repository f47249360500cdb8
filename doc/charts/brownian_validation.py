"""Validation report of the Brownian schemes: equilibrium, weak error against dt and cost, stability.

Scene (same as tests/test_stochastic.py): single-blob bodies of radius a = 1
above the wall, eta = 1/(6 pi) (so mu0 = 1/(6 pi eta a) = 1), kT = 1,
gravity g = 2 per blob, soft wall eps = 2, b = 0.25 (stiff wall: b = 0.05),
bodies 25 a apart on a square lattice, started from an exact sample of the
Gibbs-Boltzmann height density (no burn-in).  The exact <z> = 1.639 comes
from quadrature.

Charts (PNG, matplotlib) and tables (markdown, printed):

1. ``heights_<scheme>.png``: the height histogram of each scheme against the
   Gibbs-Boltzmann density.
2. ``weak_error.png``: |<z> - exact| against dt (log-log, with the standard
   error as an error bar) and against the wall-clock seconds per unit of
   simulated time, one curve per scheme; the table gives the slope of the
   fit (observed weak order).
3. ``invalid_rate.png``: invalid configurations per step against dt on the
   soft and the stiff wall; the table gives the largest dt with fewer than
   one rejection per 1000 body-steps.
4. ``boomerang_equilibrium.png``: the height and tilt histograms of 15-blob
   boomerangs under stochastic_Slip_Trapz against the exact marginals.

    python doc/charts/brownian_validation.py [--quick] [--out doc/charts] [--schemes ...]

``--quick`` uses fewer bodies and steps (a few minutes on 2 cores); without
it the statistical errors are about 3 times smaller (about an hour).
"""
import argparse
import os
import sys
import time
from types import SimpleNamespace

import numpy as np

trapezoid = getattr(np, 'trapezoid', None) or np.trapz  # numpy < 2.0 names it trapz

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))

from body.body import Body, bodies_to_arrays  # noqa: E402
from multi_bodies.solver import physics as mbf  # noqa: E402
from multi_bodies.solver import user_hooks  # noqa: E402
from multi_bodies.files import structure_generators as gen  # noqa: E402
from multi_bodies.solver.system import System  # noqa: E402
from quaternion_integrator.quaternion import rotation_matrices  # noqa: E402
from quaternion_integrator.schemes import make_scheme  # noqa: E402

A, ETA, KT, G, EPS_WALL = 1.0, 1.0 / (6.0 * np.pi), 1.0, 2.0, 2.0
SOFT, STIFF = 0.25, 0.05
ITERATIVE = ['stochastic_first_order_RFD', 'stochastic_adams_bashforth', 'stochastic_traction_EM',
             'stochastic_traction_AB', 'stochastic_Slip_Trapz', 'stochastic_Slip_Mid']
DENSE = ['stochastic_first_order_RFD_dense_algebra', 'Fixman', 'stochastic_Slip_Mid_DLA']
ROLLERS = ['stochastic_first_order_rollers', 'stochastic_adams_bashforth_rollers', 'stochastic_mid_point_rollers',
           'stochastic_trapezoidal_rollers']
CLAIMED_ORDER = {name: 1 for name in ITERATIVE + DENSE + ROLLERS}


def wall_energy(z, b):
    return np.where(z < A, EPS_WALL + EPS_WALL * (A - z) / b, EPS_WALL * np.exp(-(z - A) / b))


def height_density(z, b):
    return np.exp(-(G * z + wall_energy(z, b)) / KT)


def exact_cdf(b):
    grid = np.linspace(0.0, 25.0, 200001)
    cdf = np.cumsum(height_density(grid, b))
    return grid, cdf / cdf[-1]


def exact_mean(b):
    grid = np.linspace(0.0, 25.0, 200001)
    d = height_density(grid, b)
    return trapezoid(grid * d, grid) / trapezoid(d, grid)


def blob_system(n_bodies, b, seed, backend):
    grid, cdf = exact_cdf(b)
    rng = np.random.default_rng(seed)
    heights = np.interp(rng.random(n_bodies), cdf, grid)
    side = int(np.ceil(np.sqrt(n_bodies)))
    bodies = []
    for k, h in enumerate(heights):
        body = Body(np.array([25.0 * (k % side), 25.0 * (k // side), h]), np.array([1.0, 0, 0, 0]),
                    np.zeros((1, 3)), A)
        body.ID = 'blob'
        body.body_length = 2 * A
        bodies.append(body)
    physics = dict(g=G, repulsion_strength_wall=EPS_WALL, debye_length_wall=b, repulsion_strength=1.0,
                   debye_length=1.0, periodic_length=np.zeros(3), blob_radius=A, blob_mass=1.0)
    return System(bodies, bodies_to_arrays(bodies, [n_bodies]), user_hooks.load_user_hooks('/nonexistent'), physics, ETA,
                  A, 1e-6, vector_product_name=backend, blobs_name='python')


def run(scheme_name, n_bodies, n_steps, dt, b=SOFT, seed=1, backend='C++'):
    """Per-body mean heights, all heights (for histograms), invalid count, seconds per unit time.

    A whole step of all bodies is retried when one blob crosses the wall, so at large dt and many bodies
    the scheme stops (100 rejections in a row, utils.SimulationStopped), as a user's run would.
    """
    system = blob_system(n_bodies, b, seed, backend if scheme_name not in DENSE else 'python')
    scheme = make_scheme(scheme_name, dt, SimpleNamespace(kT=KT, rf_delta=1e-3, update_PC=1))
    rng = np.random.default_rng(seed + 1)
    sums = np.zeros(n_bodies)
    samples = []
    start = time.perf_counter()
    import contextlib
    import io
    for step in range(n_steps):
        with contextlib.redirect_stdout(io.StringIO()):  # the 'Invalid configuration number' lines
            scheme.step(system, step, rng)
        z = system.arrays.locations[:, 2]
        sums += z
        if step % 5 == 0:
            samples.append(z.copy())
    seconds = time.perf_counter() - start
    return sums / n_steps, np.concatenate(samples), scheme.invalid_configurations, seconds / (n_steps * dt)


def mean_and_error(per_body):
    return per_body.mean(), per_body.std(ddof=1) / np.sqrt(per_body.size)


def sizes(scheme, quick):
    """(bodies, simulated time) per run."""
    if scheme in DENSE:
        return (16, 10.0) if quick else (16, 40.0)
    if scheme in ROLLERS:
        return (300, 4.0) if quick else (400, 30.0)
    return (150, 3.0) if quick else (200, 15.0)


def weak_chart(curves, out, plt):
    """Table of observed orders and the chart |bias| against dt and against cost; curves: name -> (n, 4)."""
    print('\n| scheme | observed weak order (fit of log|bias| on log dt, points with |bias| > 2 SE) | claimed |')
    print('|---|---|---|')
    for name, p in curves.items():
        use = np.abs(p[:, 1]) > 2 * p[:, 2]
        slope = np.polyfit(np.log(p[use, 0]), np.log(np.abs(p[use, 1])), 1)[0] if use.sum() >= 2 else np.nan
        print('| %s | %s | %d |' % (name, 'n/a (fewer than 2 points with bias > 2 SE)' if np.isnan(slope)
                                    else '%.2f' % slope, CLAIMED_ORDER[name]))
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.2))
    for name, p in curves.items():
        label = name.replace('stochastic_', '')
        ax1.errorbar(p[:, 0], np.abs(p[:, 1]), yerr=p[:, 2], marker='o', ms=3, label=label, capsize=2)
        ax2.errorbar(p[:, 3], np.abs(p[:, 1]), yerr=p[:, 2], marker='o', ms=3, label=label, capsize=2)
    dts = np.unique(np.concatenate([p[:, 0] for p in curves.values()]))
    ax1.plot(dts, 0.1 * dts, 'k--', lw=0.8, label='slope 1')
    for ax in (ax1, ax2):
        ax.set_xscale('log')
        ax.set_yscale('log')
        ax.set_ylabel('|<z> - exact| / a (error bar: 1 SE)')
    ax1.set_xlabel('dt (units a^2 / (kT mu0))')
    ax2.set_xlabel('wall-clock seconds per unit of simulated time (this machine)')
    ax1.legend(fontsize=6)
    fig.tight_layout()
    path = os.path.join(out, 'brownian_weak_error.png')
    fig.savefig(path, dpi=80)
    plt.close(fig)
    print('\n' + path)


def chart_heights(results, out, plt):
    grid = np.linspace(0.0, 5.0, 1000)
    density = height_density(grid, SOFT)
    density /= trapezoid(density, grid)
    names = list(results)
    cols = 4
    rows = int(np.ceil(len(names) / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(4 * cols, 3 * rows), squeeze=False)
    for ax, name in zip(axes.flat, names):
        ax.hist(results[name], bins=60, range=(0, 5), density=True, alpha=0.6, label='scheme')
        ax.plot(grid, density, 'k-', lw=1.2, label='Gibbs-Boltzmann')
        ax.set_title(name.replace('stochastic_', ''), fontsize=9)
        ax.set_xlabel('z / a')
    for ax in list(axes.flat)[len(names):]:
        ax.axis('off')
    axes.flat[0].legend(fontsize=8)
    fig.tight_layout()
    path = os.path.join(out, 'brownian_heights.png')
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--quick', action='store_true')
    parser.add_argument('--out', default=os.path.dirname(os.path.abspath(__file__)))
    parser.add_argument('--schemes', nargs='+', default=ITERATIVE + DENSE + ROLLERS)
    parser.add_argument('--dts', type=float, nargs='+', default=[0.01, 0.02, 0.04, 0.08])
    parser.add_argument('--parts', nargs='+', default=['heights', 'weak', 'invalid', 'boomerang'])
    parser.add_argument('--weak-from', nargs='+', metavar='LOG',
                        help='redraw the weak-error chart from the tables printed by earlier runs (no simulation)')
    args = parser.parse_args(argv)
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    os.makedirs(args.out, exist_ok=True)
    exact = exact_mean(SOFT)
    print('exact <z> = %.5f (soft wall b = %g), %.5f (stiff wall b = %g)' % (exact, SOFT, exact_mean(STIFF), STIFF))

    if 'heights' in args.parts:
        print('\n## Equilibrium at dt = 0.01\n')
        print('| scheme | bodies | time | <z> | SE | z-score | s per unit time |')
        print('|---|---|---|---|---|---|---|')
        histograms = {}
        for name in args.schemes:
            n_bodies, t = sizes(name, args.quick)
            per_body, samples, invalid, cost = run(name, n_bodies, int(round(t / 0.01)), 0.01)
            m, se = mean_and_error(per_body)
            histograms[name] = samples
            print('| %s | %d | %g | %.4f | %.4f | %+.2f | %.3g |' % (name, n_bodies, t, m, se, (m - exact) / se, cost),
                  flush=True)
        print('\n%s' % chart_heights(histograms, args.out, plt))

    if args.weak_from:
        curves = {}
        for log in args.weak_from:  # a scheme's rows in a later log replace those of an earlier one
            rows = {}
            for line in open(log):
                cells = [c.strip() for c in line.strip().strip('|').split('|')]
                if len(cells) == 5 and cells[0] in CLAIMED_ORDER:
                    try:
                        rows.setdefault(cells[0], []).append([float(c) for c in cells[1:]])
                    except ValueError:
                        pass
            curves.update(rows)
        weak_chart({k: np.array(v) for k, v in curves.items()}, args.out, plt)
        return

    if 'weak' in args.parts:
        print('\n## Weak error of <z> against dt\n')
        print('| scheme | dt | <z> - exact | SE | s per unit time |')
        print('|---|---|---|---|---|')
        curves = {}
        for name in args.schemes:
            n_bodies, t = sizes(name, args.quick)
            points = []
            for dt in args.dts:
                try:
                    per_body, _, invalid, cost = run(name, n_bodies, int(round(2 * t / dt)), dt, seed=7)
                except Exception as err:  # 100 rejected steps in a row: the scheme fails at this dt
                    print('| %s | %g | stopped: %s | | |' % (name, dt, str(err).split(';')[0][:90]), flush=True)
                    continue
                m, se = mean_and_error(per_body)
                points.append((dt, m - exact, se, cost))
                print('| %s | %g | %+.4f | %.4f | %.3g |' % (name, dt, m - exact, se, cost), flush=True)
            curves[name] = np.array(points).reshape(-1, 4)
        weak_chart(curves, args.out, plt)

    if 'invalid' in args.parts:
        print('\n## Invalid configurations per 1000 body-steps\n')
        dts = [0.01, 0.04, 0.16, 0.64]
        print('| scheme | wall b | ' + ' | '.join('dt %g' % dt for dt in dts) + ' |')
        print('|---|---|' + '---|' * len(dts))
        fig, axes = plt.subplots(1, 2, figsize=(11, 4.2), sharey=True)
        for ax, b in zip(axes, (SOFT, STIFF)):
            for name in args.schemes:
                n_bodies = 16 if name in DENSE else 60
                rates = []
                for dt in dts:
                    n_steps = max(20, int(round(2.0 / dt)))
                    try:
                        _, _, invalid, _ = run(name, n_bodies, n_steps, dt, b=b, seed=11)
                        rates.append(1000.0 * invalid / (n_bodies * n_steps))
                    except Exception as err:  # 100 rejections in a row (or NaN, GMRES) at this dt
                        print('  %s at dt %g, b %g stopped: %s' % (name, dt, b, str(err).split(';')[0][:90]))
                        rates.append(np.nan)
                print('| %s | %g | %s |' % (name, b, ' | '.join('%.3g' % r for r in rates)), flush=True)
                ax.plot(dts, np.array(rates) + 1e-3, marker='o', ms=3, label=name.replace('stochastic_', ''))
            ax.set_xscale('log')
            ax.set_yscale('log')
            ax.set_title('wall Debye length b = %g a' % b)
            ax.set_xlabel('dt')
        axes[0].set_ylabel('invalid configurations per 1000 body-steps (+1e-3)')
        axes[0].legend(fontsize=6)
        fig.tight_layout()
        path = os.path.join(args.out, 'brownian_invalid_rate.png')
        fig.savefig(path, dpi=80)
        plt.close(fig)
        print('\n' + path)

    if 'boomerang' in args.parts:
        print('\n## Boomerang equilibrium (stochastic_Slip_Trapz)\n')
        boomerang_chart(args, plt)


def boomerang_chart(args, plt):
    a, g, eps, b = 0.15, 1.0 / 15.0, 1.0, 0.2
    reference = gen.boomerang(spacing=2 * a)

    def blob_energy(z):
        return g * z + np.where(z < a, eps + eps * (a - z) / b, eps * np.exp(-(z - a) / b))
    rng = np.random.default_rng(400)
    q = rng.standard_normal((20000, 4))
    q /= np.linalg.norm(q, axis=1)[:, None]
    R = rotation_matrices(q)
    dz = np.einsum('sj,ij->si', R[:, 2, :], reference)
    h = np.linspace(-0.5, 12.0, 2500)
    energy = sum(blob_energy(h[None, :] + dz[:, i:i + 1]) for i in range(reference.shape[0]))
    density = np.exp(-(energy - energy.min()))
    weights = trapezoid(density, h, axis=1)
    weights /= weights.sum()
    h_marginal = (weights[:, None] * density / trapezoid(density, h, axis=1)[:, None]).sum(axis=0)
    cdf = np.cumsum(density, axis=1)
    cdf /= cdf[:, -1:]
    n_bodies = 30 if args.quick else 60
    chosen = rng.choice(q.shape[0], size=n_bodies, p=weights)
    bodies = []
    for k, index in enumerate(chosen):
        body = Body(np.array([12.0 * (k % 8), 12.0 * (k // 8), np.interp(rng.random(), cdf[index], h)]), q[index],
                    reference, a)
        body.ID = 'boomerang'
        body.body_length = body.calc_body_length()
        bodies.append(body)
    physics = dict(g=g, repulsion_strength_wall=eps, debye_length_wall=b, repulsion_strength=1.0, debye_length=1.0,
                   periodic_length=np.zeros(3), blob_radius=a, blob_mass=1.0)
    system = System(bodies, bodies_to_arrays(bodies, [n_bodies]), user_hooks.load_user_hooks('/nonexistent'), physics, ETA,
                    a, 1e-4, vector_product_name='C++', blobs_name='C++')
    scheme = make_scheme('stochastic_Slip_Trapz', 0.01, SimpleNamespace(kT=KT, rf_delta=1e-3, update_PC=1))
    heights, tilts = [], []
    n_steps = 300 if args.quick else 2000
    for step in range(n_steps):
        scheme.step(system, step, rng)
        if step % 5 == 0:
            heights.append(system.arrays.locations[:, 2].copy())
            tilts.append(rotation_matrices(system.arrays.orientations)[:, 2, 2])
    heights, tilts = np.concatenate(heights), np.concatenate(tilts)
    cos_edges = np.linspace(-1, 1, 21)
    exact_cos = np.histogram(R[:, 2, 2], bins=cos_edges, weights=weights, density=True)[0]
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 3.8))
    ax1.hist(heights, bins=50, range=(0, 4), density=True, alpha=0.6, label='Slip_Trapz')
    ax1.plot(h, h_marginal / trapezoid(h_marginal, h), 'k-', label='exact')
    ax1.set_xlabel('height of the boomerang apex')
    ax1.set_xlim(0, 4)
    ax1.legend()
    ax2.hist(tilts, bins=cos_edges, density=True, alpha=0.6, label='Slip_Trapz')
    ax2.step(cos_edges[:-1], exact_cos, where='post', color='k', label='exact')
    ax2.set_xlabel('cos(tilt) of the boomerang plane normal')
    ax2.legend()
    fig.tight_layout()
    path = os.path.join(args.out, 'brownian_boomerang_equilibrium.png')
    fig.savefig(path, dpi=80)
    plt.close(fig)
    exact_h = trapezoid(h * h_marginal, h) / trapezoid(h_marginal, h)
    print('%d boomerangs x %d steps: <h> = %.4f (exact %.4f), <cos^2> = %.4f (exact %.4f)'
          % (n_bodies, n_steps, heights.mean(), exact_h, np.mean(tilts ** 2), np.sum(weights * R[:, 2, 2] ** 2)))
    print(path)


if __name__ == '__main__':
    main()
