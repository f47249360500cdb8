"""Validation report of the Brownian schemes: equilibrium histograms, stability, and a multi-blob body.

Scene (same as tests/test_stochastic.py): single-blob bodies of radius a = 1
above the wall, eta = 1/(6 pi) (so mu0 = 1/(6 pi eta a) = 1), kT = 1,
gravity g = 2 per blob, soft wall eps = 2, b = 0.25 (stiff wall: b = 0.05),
bodies 25 a apart on a square lattice, started from an exact sample of the
Gibbs-Boltzmann height density (no burn-in).  The exact <z> = 1.639 comes
from quadrature.

Charts (PNG, matplotlib) and tables (markdown, printed):

1. ``brownian_heights.png``: the height histogram of each scheme with its
   standard-error band against the Gibbs-Boltzmann density.
2. ``brownian_invalid_rate.png``: invalid configurations per 1000 body-steps
   against dt on the soft and the stiff wall (zero drawn as zero, stopped
   runs marked).
3. ``brownian_boomerang_equilibrium.png``: the height and tilt histograms of
   15-blob boomerangs under stochastic_Slip_Trapz against the exact marginals.

The weak order of every scheme is measured on its own scene by
``doc/charts/brownian_weak_order.py``.

    python doc/charts/brownian_validation.py [--quick] [--parts heights invalid boomerang] [--schemes ...]

``--quick`` uses fewer bodies and steps (a few minutes on 2 cores); without
it the statistical errors are about 3 times smaller (see doc/brownian_validation.md for the cost).
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
from multi_bodies.solver import user_hooks  # noqa: E402
from multi_bodies.files import structure_generators as gen  # noqa: E402
from multi_bodies.files.input_options import options_with  # noqa: E402
from multi_bodies.solver.model import Model  # noqa: E402
from body.geometry import rotation_matrices  # noqa: E402
from quaternion_integrator.schemes import make_scheme  # noqa: E402

A, ETA, KT, G, EPS_WALL = 1.0, 1.0 / (6.0 * np.pi), 1.0, 2.0, 2.0
SOFT, STIFF = 0.25, 0.05
ITERATIVE = ['stochastic_first_order_RFD', 'stochastic_adams_bashforth', 'stochastic_traction_EM',
             'stochastic_traction_AB', 'stochastic_Slip_Trapz', 'stochastic_Slip_Mid']
DENSE = ['stochastic_first_order_RFD_dense_algebra', 'Fixman', 'stochastic_Slip_Mid_DLA']
ROLLERS = ['stochastic_first_order_rollers', 'stochastic_adams_bashforth_rollers', 'stochastic_mid_point_rollers',
           'stochastic_trapezoidal_rollers']
HEIGHT_EDGES = np.linspace(0.0, 5.0, 51)


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
    return Model(bodies, bodies_to_arrays(bodies, [n_bodies]), user_hooks.load_user_hooks('/nonexistent'), physics, ETA,
                 A, 1e-6, vector_product_name=backend, blobs_name='python')


def run(scheme_name, n_bodies, n_steps, dt, b=SOFT, seed=1, backend='C++'):
    """One run of ``n_bodies`` bodies for ``n_steps`` steps of ``dt``.

    Returns a namespace: ``per_body_mean`` (n_bodies,) time-averaged heights,
    ``per_body_histogram`` (n_bodies, bins) height densities on HEIGHT_EDGES
    (every fifth step), ``invalid`` rejected trial configurations,
    ``steps`` steps done, ``stopped`` the message when the run stopped early,
    ``seconds_per_unit_time``.  A whole step of all bodies is retried when
    one blob crosses the wall, so at large dt and many bodies the scheme
    stops (100 rejections in a row, utils.SimulationStopped), as a user's run
    would; the rate is then that of the steps it made.
    """
    import contextlib
    import io
    system = blob_system(n_bodies, b, seed, backend if scheme_name not in DENSE else 'python')
    scheme = make_scheme(scheme_name, dt, options_with(kT=KT, rf_delta=1e-3, update_PC=1))
    rng = np.random.default_rng(seed + 1)
    sums = np.zeros(n_bodies)
    counts = np.zeros((n_bodies, HEIGHT_EDGES.size - 1))
    stopped, done = None, 0
    state = scheme.init(system, system.start_configuration)
    start = time.perf_counter()
    for step in range(n_steps):
        try:
            with contextlib.redirect_stdout(io.StringIO()):  # the 'Invalid configuration number' lines
                state = scheme.step(system, state, rng)
        except Exception as err:  # utils.SimulationStopped (100 rejections in a row), or a failed solve
            stopped = str(err).split(';')[0]
            state = getattr(err, 'state', None) or state  # the counts of the stopped step
            break
        done += 1
        z = state.configuration.locations[:, 2]
        sums += z
        if step % 5 == 0:
            index = np.clip(np.searchsorted(HEIGHT_EDGES, z, side='right') - 1, 0, counts.shape[1] - 1)
            counts[np.arange(n_bodies), index] += 1
    seconds = time.perf_counter() - start
    widths = np.diff(HEIGHT_EDGES)
    histogram = counts / np.maximum(counts.sum(axis=1, keepdims=True), 1) / widths
    return SimpleNamespace(per_body_mean=sums / max(done, 1), per_body_histogram=histogram,
                           invalid=state.counters.invalid_configurations, steps=done, stopped=stopped,
                           seconds_per_unit_time=seconds / (max(done, 1) * dt))


def mean_and_error(per_body):
    return per_body.mean(), per_body.std(ddof=1) / np.sqrt(per_body.size)


def sizes(scheme, quick):
    """(bodies, simulated time) per run: about 30 height relaxation times (0.6 each) at the least."""
    if scheme in DENSE:
        return (16, 20.0) if quick else (16, 200.0)
    if scheme in ROLLERS:
        return (150, 3.0) if quick else (300, 20.0)
    return (100, 3.0) if quick else (200, 20.0)


def chart_heights(results, out, plt):
    """One panel per scheme: its height density (the mean of the bodies' histograms) with a band of 2 standard
    errors (the spread of the bodies' histograms over sqrt(bodies)), and the Gibbs-Boltzmann density."""
    grid = np.linspace(0.0, 5.0, 1000)
    density = height_density(grid, SOFT)
    density /= trapezoid(density, grid)
    centres = 0.5 * (HEIGHT_EDGES[1:] + HEIGHT_EDGES[:-1])
    cdf_grid, cdf = exact_cdf(SOFT)
    names = list(results)
    cols = 4
    rows = int(np.ceil(len(names) / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(4 * cols, 3 * rows), squeeze=False)
    for ax, name in zip(axes.flat, names):
        result = results[name]
        per_body = result.per_body_histogram
        mean = per_body.mean(axis=0)
        error = per_body.std(axis=0, ddof=1) / np.sqrt(per_body.shape[0])
        ax.fill_between(centres, mean - 2 * error, mean + 2 * error, step='mid', color='C0', alpha=0.3,
                        label='scheme ± 2 SE')
        ax.step(centres, mean, where='mid', color='C0', lw=1.0)
        ax.plot(grid, density, 'k-', lw=1.0, label='Gibbs-Boltzmann')
        exact_bins = np.diff(np.interp(HEIGHT_EDGES, cdf_grid, cdf)) / np.diff(HEIGHT_EDGES)  # bin averages
        # Counted where a bin is expected to hold at least 1% of the samples: below that most bodies never visit
        # it and the spread of the bodies' histograms is no estimate of its standard error.
        counted = exact_bins * np.diff(HEIGHT_EDGES) >= 0.01
        outside = int(np.sum(np.abs(mean - exact_bins)[counted] > 2 * error[counted]))
        ax.set_title('%s (%d bodies, T = %g)' % (name.replace('stochastic_', ''), per_body.shape[0], result.time),
                     fontsize=8)
        ax.text(0.97, 0.95, 'bins off by > 2 SE: %d of %d\n(bins holding >= 1%%)' % (outside, counted.sum()),
                transform=ax.transAxes,
                ha='right', va='top', fontsize=7)
        ax.set_xlabel('z / a')
    for ax in list(axes.flat)[len(names):]:
        ax.axis('off')
    axes.flat[0].legend(fontsize=7, loc='center right')
    fig.tight_layout()
    path = os.path.join(out, 'brownian_heights.png')
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path


def chart_invalid(rates, dts, out, plt):
    """Rejections per 1000 body-steps against dt, zero drawn at zero (symlog axis), stopped runs marked."""
    from matplotlib.lines import Line2D
    markers = ['o', 's', '^', 'v', 'D', 'P', 'X', '*', 'h', '<', '>', 'p', 'd']
    styles = ['-', '--', '-.', ':']
    colours = plt.get_cmap('tab20').colors
    fig, axes = plt.subplots(1, 2, figsize=(13, 5), sharey=True)
    names = sorted({name for name, _ in rates}, key=lambda n: (ITERATIVE + DENSE + ROLLERS).index(n))
    for ax, b in zip(axes, (SOFT, STIFF)):
        for k, name in enumerate(names):
            if (name, b) not in rates:
                continue
            values = rates[(name, b)]
            y = np.array([v[0] for v in values])
            stopped = np.array([v[1] for v in values])
            style = dict(color=colours[(2 * k) % 20 + (2 * k) // 20], marker=markers[k % len(markers)],
                         linestyle=styles[k % len(styles)], markersize=5, linewidth=1.0)
            ax.plot(dts, y, label=name.replace('stochastic_', ''), **style)
            if stopped.any():  # the rate of the steps it made, ringed in red: the run stopped there
                ax.plot(np.array(dts)[stopped], y[stopped], linestyle='none', marker='o', markersize=11,
                        markerfacecolor='none', markeredgecolor='red', markeredgewidth=1.5)
        ax.set_xscale('log')
        ax.set_yscale('symlog', linthresh=1.0)
        ax.axhline(0.0, color='0.3', lw=0.8)
        ax.set_ylim(-0.3, 2000.0)
        ax.set_title('wall Debye length b = %g a' % b)
        ax.set_xlabel('dt (units a^2 / (kT mu0))')
        ax.grid(True, which='both', alpha=0.3)
    axes[0].set_ylabel('invalid configurations per 1000 body-steps (symlog: 0 is 0)')
    handles, labels = axes[0].get_legend_handles_labels()
    handles.append(Line2D([], [], linestyle='none', marker='o', markersize=11, markerfacecolor='none',
                          markeredgecolor='red'))
    labels.append('run stopped (100 rejections in a row)')
    axes[0].legend(handles, labels, fontsize=7, loc='upper left')
    fig.tight_layout()
    path = os.path.join(out, 'brownian_invalid_rate.png')
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path


INVALID_DTS = [0.01, 0.04, 0.16, 0.2, 0.25, 0.32, 0.4, 0.5, 0.64]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--quick', action='store_true')
    parser.add_argument('--out', default=os.path.dirname(os.path.abspath(__file__)))
    parser.add_argument('--schemes', nargs='+', default=ITERATIVE + DENSE + ROLLERS)
    parser.add_argument('--parts', nargs='+', default=['heights', 'invalid', 'boomerang'],
                        choices=['heights', 'invalid', 'boomerang'])
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
        results = {}
        for name in args.schemes:
            n_bodies, t = sizes(name, args.quick)
            result = run(name, n_bodies, int(round(t / 0.01)), 0.01)
            result.time = t
            m, se = mean_and_error(result.per_body_mean)
            results[name] = result
            print('| %s | %d | %g | %.4f | %.4f | %+.2f | %.3g |' % (name, n_bodies, t, m, se, (m - exact) / se,
                                                                    result.seconds_per_unit_time), flush=True)
        print('\n%s' % chart_heights(results, args.out, plt))

    if 'invalid' in args.parts:
        print('\n## Invalid configurations per 1000 body-steps\n')
        dts = INVALID_DTS
        print('| scheme | wall b | ' + ' | '.join('dt %g' % dt for dt in dts) + ' |')
        print('|---|---|' + '---|' * len(dts))
        rates = {}
        for b in (SOFT, STIFF):
            for name in args.schemes:
                n_bodies = 16 if name in DENSE else 60
                values = []
                for dt in dts:
                    n_steps = max(20, int(round((1.0 if args.quick else 4.0) / dt)))
                    result = run(name, n_bodies, n_steps, dt, b=b, seed=11)
                    values.append((1000.0 * result.invalid / (n_bodies * max(result.steps, 1)),
                                   result.stopped is not None))
                rates[(name, b)] = values
                print('| %s | %g | %s |' % (name, b, ' | '.join('%.3g%s' % (r, ' (stopped)' if stop else '')
                                                             for r, stop in values)), flush=True)
        print('\n' + chart_invalid(rates, dts, args.out, plt))

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
    system = Model(bodies, bodies_to_arrays(bodies, [n_bodies]), user_hooks.load_user_hooks('/nonexistent'), physics, ETA,
                   a, 1e-4, vector_product_name='C++', blobs_name='C++')
    scheme = make_scheme('stochastic_Slip_Trapz', 0.01, options_with(kT=KT, rf_delta=1e-3, update_PC=1))
    heights, tilts = [], []
    n_steps = 300 if args.quick else 2000
    state = scheme.init(system, system.start_configuration)
    for step in range(n_steps):
        state = scheme.step(system, state, rng)
        if step % 5 == 0:
            heights.append(state.configuration.locations[:, 2].copy())
            tilts.append(rotation_matrices(state.configuration.orientations)[:, 2, 2])
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
