"""Weak order of every Brownian scheme: the bias of an exact equilibrium average against dt and against cost.

Scene (chosen for a large, smooth dt bias and a small variance): single-blob
bodies of radius a = 1 (eta = 1/(6 pi), so mu0 = 1/(6 pi eta a) = 1, kT = 1),
each held by a harmonic trap to its own site of a square lattice of spacing
20 a: stiffness k_z = 100 kT/a^2 towards the height z0 = 1.5 a, where the
wall changes the normal mobility fast (mu_perp = 0.38 mu0, d mu_perp/dz =
0.26 mu0/a, so the noise is multiplicative and the drift kT div M matters),
and k_xy = 10 kT/a^2 in the plane.  No gravity, no wall or pair potential:
the Gibbs-Boltzmann density is the product of the traps' Gaussians whatever
the hydrodynamic interactions, so

    observable  O = < (z - z0)^2 > k_z / kT,   exact value 1 (the Gaussian is cut at z = 0, 15 standard
                                               deviations below z0).

The height relaxes in tau = 1/(mu_perp k_z) = 0.026; dt runs from tau/20 to
1.5 tau.  Every run starts from an exact sample of the traps' Gaussians, so
there is no burn-in.  The replicas are run by the package's ensemble runner
(`multi_bodies/ensemble.py`, one `--vary dt:n_steps:n_save=...` axis per
scheme), from an input file and a `user_defined_functions.py` written into the
work folder; the standard error of O is the spread of the replicas' averages
(independent streams) over sqrt(replicas).

    python doc/charts/brownian_weak_order.py --work /tmp/weak_order run [--quick] [--schemes ...] [--workers 2]
    python doc/charts/brownian_weak_order.py --work /tmp/weak_order report [--out doc/charts]

``run`` skips the replicas already done (the runner's restart), so it can be
stopped and started again; ``report`` prints the tables (markdown) and draws
``brownian_weak_error.png``.  ``--quick`` (a quarter of the simulated time)
keeps its runs apart in the same work folder (``ensemble_quick``); give it to
``report`` as well.  ``stochastic_EM`` has no drift term and runs in free space
(``*_no_wall``), where it is valid; the dense schemes run 16 bodies per replica.  Cost on a 2-core machine: see doc/brownian_validation.md.
"""
import argparse
import csv
import json
import os
import re
import subprocess
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, ROOT)

from multi_bodies.files.snapshots import config_name, read_config_frames  # noqa: E402

SPACING, Z0, K_Z, K_XY = 20.0, 1.5, 100.0, 10.0
ETA = 1.0 / (6.0 * np.pi)
TAU = 1.0 / (0.3822 * K_Z)   # mu_perp(1.5 a) = 1 - 9/(8 h) + 1/(2 h^3) - 1/(8 h^5) = 0.3822
TAU_FREE = 1.0 / K_Z         # free space: mu = mu0 = 1


def tau(scheme):
    """Relaxation time of the height in the scheme's scene: 1/(mu_perp k_z), in free space 1/(mu0 k_z)."""
    return TAU_FREE if scheme in FREE_SPACE else TAU

# scheme -> (claimed weak order, dt ladder, bodies per replica); the papers (Sprinkle et al., J. Chem. Phys. 147,
# 244103, 2017; Balboa Usabiaga et al., J. Chem. Phys. 146, 134104, 2017) claim weak order 1 for all of them.
FIRST = (0.00125, 0.0025, 0.005, 0.01, 0.02)
SECOND = (0.01, 0.014, 0.02, 0.028, 0.04)
SCHEMES = {
    'stochastic_first_order_RFD': (1, FIRST, 100),
    'stochastic_traction_EM': (1, FIRST, 100),
    'stochastic_adams_bashforth': (1, FIRST, 100),
    'stochastic_traction_AB': (1, FIRST, 100),
    'stochastic_Slip_Trapz': (1, SECOND, 100),
    'stochastic_Slip_Mid': (1, SECOND, 100),
    'stochastic_GDC_RFD': (1, FIRST, 100),
    'stochastic_EM': (1, tuple(round(dt * TAU_FREE / TAU, 6) for dt in FIRST), 100),  # no drift: valid only where div N = 0, so it runs in free space (no wall)
    'stochastic_first_order_RFD_dense_algebra': (1, FIRST, 16),
    'Fixman': (1, SECOND, 16),
    'stochastic_Slip_Mid_DLA': (1, SECOND, 16),
    'stochastic_first_order_rollers': (1, FIRST, 100),
    'stochastic_adams_bashforth_rollers': (1, FIRST, 100),
    'stochastic_mid_point_rollers': (1, SECOND, 100),
    'stochastic_trapezoidal_rollers': (1, SECOND, 100),
}
DENSE = ('stochastic_first_order_RFD_dense_algebra', 'Fixman', 'stochastic_Slip_Mid_DLA')
FREE_SPACE = ('stochastic_EM',)
# A second ladder where the first one resolved too few points: the Adams-Bashforth
# schemes, whose bias falls faster than dt and below the standard error at dt <= 0.0025 (they are unstable
# above dt/tau = 1).  Run into <scheme>/ensemble_extra and merged with the first.
# The midpoint schemes' bias falls so fast (slope 3 between dt/tau 0.4 and 1) that it is below the standard
# error under dt/tau = 0.4; their second ladder fills in the resolved range.
EXTRA = {name: (0.004, 0.0057, 0.008, 0.0113, 0.016)
         for name in ('stochastic_adams_bashforth', 'stochastic_traction_AB', 'stochastic_adams_bashforth_rollers')}
EXTRA.update({name: (0.012, 0.017, 0.024) for name in ('stochastic_Slip_Mid', 'Fixman', 'stochastic_Slip_Mid_DLA',
                                                         'stochastic_mid_point_rollers')})

USER_FUNCTIONS = '''"""Harmonic traps of the weak-order study: every blob is pulled to the nearest lattice site (x, y) and to z0."""
import numpy as np

SPACING, Z0 = {spacing!r}, {z0!r}
STIFFNESS = np.array([{kxy!r}, {kxy!r}, {kz!r}])


def blob_external_forces(r_vectors, **kwargs):
    """Trap force on every blob, r_vectors (N, 3) -> (N, 3); no gravity, no wall repulsion."""
    r_vectors = np.asarray(r_vectors, dtype=float).reshape(-1, 3)
    site = np.empty_like(r_vectors)
    site[:, :2] = np.round(r_vectors[:, :2] / SPACING) * SPACING
    site[:, 2] = Z0
    return -STIFFNESS * (r_vectors - site)
'''


def input_text(scheme, n_bodies, tolerance):
    dense = scheme in DENSE
    space = '_no_wall' if scheme in FREE_SPACE else ''
    return '\n'.join([
        '# weak-order study (doc/charts/brownian_weak_order.py): %d trapped blobs' % n_bodies,
        'scheme %s' % scheme,
        'mobility_blobs_implementation C++' + space,
        'mobility_vector_prod_implementation %s' % (('python' if dense else 'C++') + space),
        'blob_blob_force_implementation None',
        'body_body_force_torque_implementation None',
        'eta %r' % ETA, 'blob_radius 1.0', 'kT 1.0', 'g 0.0',
        'repulsion_strength_wall 0.0', 'debye_length_wall 1.0', 'repulsion_strength 0.0', 'debye_length 1.0',
        'solver_tolerance %g' % tolerance, 'rf_delta 1e-3', 'update_PC 1',
        'dt 0.01', 'n_steps 10', 'n_save 1', 'save_clones one_file',
        'output_name run',
        'structure blob.vertex start.clones', ''])


def write_scene(folder, scheme, n_bodies, seed, tolerance):
    """The input file, the traps and an exact equilibrium start in ``folder``; returns the input path."""
    os.makedirs(folder, exist_ok=True)
    rng = np.random.default_rng(seed)
    side = int(np.ceil(np.sqrt(n_bodies)))
    sites = np.array([[SPACING * (k % side), SPACING * (k // side), Z0] for k in range(n_bodies)])
    start = sites + rng.standard_normal(sites.shape) / np.sqrt([K_XY, K_XY, K_Z])
    with open(os.path.join(folder, 'blob.vertex'), 'w') as f:
        f.write('1\n0 0 0\n')
    with open(os.path.join(folder, 'start.clones'), 'w') as f:
        f.write('%d\n' % n_bodies)
        for x, y, z in start:
            f.write('%.16g %.16g %.16g 1 0 0 0\n' % (x, y, z))
    with open(os.path.join(folder, 'user_defined_functions.py'), 'w') as f:
        f.write(USER_FUNCTIONS.format(spacing=SPACING, z0=Z0, kxy=K_XY, kz=K_Z))
    path = os.path.join(folder, 'weak.dat')
    with open(path, 'w') as f:
        f.write(input_text(scheme, n_bodies, tolerance))
    return path


def simulated_time(dt, dts, n_bodies, scale=1.0):
    """Simulated time of one replica at ``dt``: long enough for a standard error about 6 times below the bias.

    Measured on this scene: one replica of 100 bodies averages O to 0.016/sqrt(T), so 8 replicas reach
    0.0058/sqrt(T); the smallest biases are about 0.024 (Euler-Maruyama at dt = 0.00125), 0.014
    (Adams-Bashforth at dt = 0.004, second ladder) and 0.012 (the midpoint schemes at dt = 0.01).  16-body
    replicas (dense schemes) run 2 times longer on the first ladder and 4 times on the second.
    """
    if scale != 1.0:  # free space: the same ladder in dt/tau, the same simulated time in units of tau
        return simulated_time(dt / scale, FIRST, n_bodies) * scale
    if dts == FIRST:
        time = max(3.0, 0.0125 / dt) * (2.0 if n_bodies < 50 else 1.0)
    elif dts == SECOND or dts[0] >= 0.01:
        time = max(3.0, 12.0 * (0.01 / dt) ** 2) * (4.0 if n_bodies < 50 else 1.0)
    else:
        time = max(3.0, 6.4 * (0.004 / dt) ** 2)
    return time


def ladder(dts, n_bodies, quick, relaxation=TAU):
    """--vary axis 'dt:n_steps:n_save' of one scheme; frames are saved every ~tau/4 (the correlation time of O)."""
    items = []
    for dt in dts:
        n_save = max(1, int(round(0.25 * relaxation / dt)))
        simulated = simulated_time(dt, dts, n_bodies, relaxation / TAU)
        n_steps = int(np.ceil(simulated * (0.25 if quick else 1.0) / dt / n_save)) * n_save
        items.append('%g:%d:%d' % (dt, n_steps, n_save))
    return 'dt:n_steps:n_save=' + ','.join(items)


def run(args):
    for scheme in args.schemes:
        _, dts, n_bodies = SCHEMES[scheme]
        folder = os.path.join(args.work, scheme)
        path = write_scene(os.path.join(folder, 'scene'), scheme, n_bodies, seed=11, tolerance=args.tolerance)
        ladders = [('ensemble', dts)] + ([('ensemble_extra', EXTRA[scheme])] if scheme in EXTRA else [])
        for name, values in ladders:
            name += '_quick' if args.quick else ''
            command = [sys.executable, os.path.join(ROOT, 'multi_bodies', 'ensemble.py'), '--input-file', path,
                       '--replicas', str(args.replicas), '--vary', ladder(values, n_bodies, args.quick, tau(scheme)),
                       '--output-dir', os.path.join(folder, name), '--seed', '2026', '--workers', str(args.workers)]
            print('$ ' + ' '.join(command), flush=True)
            code = subprocess.call(command)
            if code not in (0, 1):  # 1: some replicas failed (a scheme that breaks down at a large dt); reported
                return code
    return 0


def replica_observable(folder):
    """(O averaged over bodies and frames, (seconds, resumed-from step)) of one finished replica, or
    (None, message)."""
    with open(os.path.join(folder, 'status.json')) as f:
        status = json.load(f)
    if status.get('status') != 'done':
        return None, status.get('message', status.get('status'))
    frames = read_config_frames(config_name(os.path.join(folder, 'run'), 'start'))
    z = frames[1:, :, 2]  # frame 0 is the start
    return float(np.mean((z - Z0) ** 2) * K_Z), (status.get('seconds'), status.get('resumed_from') or 0)


def collect(work, scheme, quick=False):
    """Rows (dt, mean O - 1, standard error, replicas, seconds per unit time, failures) of one scheme, by dt."""
    rows = []
    for name in ('ensemble_quick', 'ensemble_extra_quick') if quick else ('ensemble', 'ensemble_extra'):
        if os.path.isfile(os.path.join(work, scheme, name, 'ensemble.json')):
            rows.extend(collect_ensemble(os.path.join(work, scheme, name)))
    return sorted(rows, key=lambda row: row[0])


def collect_ensemble(root):
    """The rows of :func:`collect` from one ensemble folder."""
    with open(os.path.join(root, 'ensemble.json')) as f:
        manifest = json.load(f)
    rows = []
    for point in manifest['points']:
        values = dict(point['overrides'])
        dt, n_steps = float(values['dt']), int(values['n_steps'])
        samples, seconds, failures = [], [], []
        for replica in manifest['replicas']:
            if replica['point_name'] != point['name']:
                continue
            value, extra = replica_observable(os.path.join(root, replica['folder']))
            if value is None:
                failures.append(str(extra))
            else:
                samples.append(value)
                spent, resumed_from = extra  # a resumed replica timed only the steps after its restart
                seconds.append(spent / ((n_steps - resumed_from) * dt))
        samples = np.array(samples)
        if samples.size >= 2:
            rows.append((dt, samples.mean() - 1.0, samples.std(ddof=1) / np.sqrt(samples.size), samples.size,
                         float(np.mean(seconds)), failures))
        else:
            rows.append((dt, np.nan, np.nan, samples.size, np.nan, failures))
    return rows


def fit_order(rows, resolve=4.0, points=3, relaxation=TAU):
    """Weighted least-squares slope of log|bias| on log dt over the ``points`` smallest dt with |bias| >= resolve * SE.

    The smallest time steps are where the leading term of the bias dominates (at dt ~ tau the next terms add
    to the slope).  Returns (order, standard error of the order, dt values used); the error of log|bias| is
    SE/|bias|.  The points must share the sign of the bias (a sign change means the leading term is not yet
    dominant there).
    """
    use = sorted((dt, b, e) for dt, b, e, *_ in rows if np.isfinite(b) and abs(b) >= resolve * e)[:points]
    if len(use) < 3:
        return np.nan, np.nan, [dt for dt, _, _ in use], np.nan
    signs = np.sign([b for _, b, _ in use])
    if not np.all(signs == signs[0]):
        return np.nan, np.nan, [dt for dt, _, _ in use], np.nan
    x = np.log([dt / relaxation for dt, _, _ in use])
    y = np.log([abs(b) for _, b, _ in use])
    w = 1.0 / np.array([e / abs(b) for _, b, e in use]) ** 2
    design = np.vstack([x, np.ones_like(x)]).T
    normal = design.T @ (w[:, None] * design)
    coefficients = np.linalg.solve(normal, design.T @ (w * y))
    residual = y - design @ coefficients
    chi2 = float(np.sum(w * residual ** 2)) / max(1, len(use) - 2)
    covariance = np.linalg.inv(normal) * max(1.0, chi2)  # inflate by the misfit when the points scatter more
    return (float(coefficients[0]), float(np.sqrt(covariance[0, 0])), [dt for dt, _, _ in use],
            float(signs[0] * np.exp(coefficients[1])))


def dt_for_bias(rows, target, law=None, resolve=4.0):
    """(dt, seconds per unit time, how) where |bias| crosses ``target``.

    Log-log interpolation between the resolved points around it (how = 'measured'); below the smallest
    resolved bias, the fitted power law ``law = (C, order, tau)`` gives dt and the cost grows like 1/dt from
    the first point (how = 'extrapolated'); above the largest, the largest dt resolved (how = 'at most').
    (nan, nan, '') when nothing is resolved.
    """
    use = sorted((dt, abs(b), c) for dt, b, e, _, c, _ in rows if np.isfinite(b) and abs(b) >= resolve * e)
    if not use:
        return np.nan, np.nan, ''
    if use[0][1] > target:
        if law is None or not np.all(np.isfinite(law)):
            return np.nan, np.nan, ''
        constant, order, relaxation = law
        dt = relaxation * (target / abs(constant)) ** (1.0 / order)
        return dt, use[0][2] * use[0][0] / dt, 'extrapolated'
    for (d0, b0, c0), (d1, b1, c1) in zip(use, use[1:]):
        if b0 <= target <= b1:
            w = np.log(target / b0) / np.log(b1 / b0)
            return (float(np.exp((1 - w) * np.log(d0) + w * np.log(d1))),
                    float(np.exp((1 - w) * np.log(c0) + w * np.log(c1))), 'measured')
    return use[-1][0], use[-1][2], 'at most'


def report(args):
    curves = {}
    print('| scheme | dt | dt/tau | <O> - 1 | SE | bias / SE | replicas | s per unit time |')
    print('|---|---|---|---|---|---|---|---|')
    for scheme in args.schemes:
        if not os.path.isfile(os.path.join(args.work, scheme, 'ensemble_quick' if args.quick else 'ensemble',
                                           'ensemble.json')):
            continue
        rows = collect(args.work, scheme, args.quick)
        curves[scheme] = rows
        for dt, bias, error, replicas, seconds, failures in rows:
            if not np.isfinite(bias):
                steps = sorted(int(m) for m in re.findall(r'step (\d+) of', ' '.join(failures)))
                what = ('%d of %d replicas stopped (100 rejected steps in a row), the first at step %d'
                        % (len(failures), len(failures) + replicas, steps[0]) if steps
                        else 'failed: %s' % (failures or ['?'])[0][:80])
                print('| %s | %g | %.2f | %s | | | %d | |' % (scheme, dt, dt / tau(scheme), what, replicas))
                continue
            print('| %s | %g | %.2f | %+.4f | %.4f | %.1f | %d | %.3g |'
                  % (scheme, dt, dt / tau(scheme), bias, error, abs(bias) / error, replicas, seconds))
    print('\n| scheme | fitted weak order | C of bias = C (dt/tau)^order | dt of the fit (the 3 smallest resolved: bias ≥ 4 SE) '
          '| claimed |')
    print('|---|---|---|---|---|')
    fits, laws = {}, {}
    for scheme, rows in curves.items():
        order, error, used, constant = fit_order(rows, relaxation=tau(scheme))
        fits[scheme] = (order, error)
        laws[scheme] = (constant, order, tau(scheme))
        text = 'not resolved' if not np.isfinite(order) else '%.2f ± %.2f' % (order, error)
        print('| %s | %s | %s | %s | %d |' % (scheme, text, '%+.3g' % constant if np.isfinite(constant) else '',
                                              ', '.join('%g' % dt for dt in used) or 'none', SCHEMES[scheme][0]))
    print('\n| scheme | dt/tau at a bias of 1% | s per unit time there | dt/tau at 5% | s per unit time there |')
    print('|---|---|---|---|---|')
    for scheme, rows in curves.items():
        cells = []
        for target in (0.01, 0.05):
            dt, seconds, how = dt_for_bias(rows, target, laws.get(scheme))
            note = {'extrapolated': ' (fit)', 'at most': ' (bias below it at every dt)'}.get(how, '')
            cells.append('%.3g%s | %.3g' % (dt / tau(scheme), note, seconds) if np.isfinite(dt) else 'n/a | ')
        print('| %s | %s |' % (scheme, ' | '.join(cells)))
    with open(os.path.join(args.work, 'weak_order.csv'), 'w', newline='') as f:
        writer = csv.writer(f)
        writer.writerow(['scheme', 'dt', 'bias', 'stderr', 'replicas', 'seconds_per_unit_time'])
        for scheme, rows in curves.items():
            for dt, bias, error, replicas, seconds, _ in rows:
                writer.writerow([scheme, dt, bias, error, replicas, seconds])
    draw(curves, fits, args.out)
    return 0


def draw(curves, fits, out):
    try:
        import matplotlib
        matplotlib.use('Agg')
        import matplotlib.pyplot as plt
    except ImportError:
        print('chart skipped: matplotlib is not installed')
        return
    styles = ['-', '--', '-.', ':']
    markers = ['o', 's', '^', 'v', 'D', 'P', 'X', '*', 'h', '<', '>', 'p', 'd']
    colours = plt.get_cmap('tab20').colors
    from matplotlib.ticker import LogLocator, NullFormatter
    fig, axes = plt.subplots(1, 2, figsize=(14, 8))
    for k, (scheme, rows) in enumerate(curves.items()):
        rows = [r for r in rows if np.isfinite(r[1]) and abs(r[1]) >= 4 * r[2]]  # drawn: resolved points only
        if not rows:
            continue
        dt = np.array([r[0] for r in rows])
        bias, error, seconds = (np.array([r[i] for r in rows]) for i in (1, 2, 4))
        order, order_error = fits[scheme]
        label = scheme.replace('stochastic_', '') + (' [16 bodies]' if scheme in DENSE else '')
        label += ' [free space]' if scheme in FREE_SPACE else ''
        label += ' (%.2f ± %.2f)' % (order, order_error) if np.isfinite(order) else ' (not resolved)'
        style = dict(color=colours[(2 * k) % 20 + (2 * k) // 20], marker=markers[k % len(markers)],
                     linestyle=styles[k % len(styles)], markersize=5, capsize=2, linewidth=1.0)
        axes[0].errorbar(dt / tau(scheme), np.abs(bias), yerr=error, label=label, **style)
        axes[1].errorbar(seconds, np.abs(bias), yerr=error, **style)
    x = np.geomspace(0.04, 1.6, 50)
    axes[0].plot(x, 1.0 / (1.0 - 0.5 * x) - 1.0, color='k', linewidth=2.5, alpha=0.25,
                 label='Euler-Maruyama on the OU process: 1/(1 - x/2) - 1')
    for slope, anchor in ((1, 0.05), (2, 0.004)):
        xs = np.array([0.05, 1.5])
        axes[0].plot(xs, anchor * (xs / 0.1) ** slope, color='0.5', linewidth=0.8, linestyle=':')
        axes[0].annotate('slope %d' % slope, (xs[0], anchor * (xs[0] / 0.1) ** slope), color='0.4', fontsize=8,
                         va='bottom')
    axes[0].set(xscale='log', yscale='log', xlabel='dt / tau  (tau = 1/(mu_perp k_z) = %.4f; free space 1/(mu0 k_z) = %.2f)' % (TAU, TAU_FREE),
                ylabel='|<(z - z0)^2> k_z/kT - 1|  (Gibbs-Boltzmann: 0)',
                title='weak error against dt; legend: fitted order ± SE (claimed: 1)')
    axes[1].set(xscale='log', yscale='log',
                xlabel='wall-clock seconds per unit of simulated time (100 bodies unless marked; 1 core each)',
                title='weak error against cost')
    for ax in axes:
        ax.grid(True, which='both', alpha=0.3)
        ax.xaxis.set_minor_locator(LogLocator(subs=np.arange(2, 10)))
        ax.xaxis.set_minor_formatter(NullFormatter())
    handles, labels = axes[0].get_legend_handles_labels()
    fig.tight_layout(rect=(0, 0.2, 1, 1))
    fig.legend(handles, labels, loc='lower center', ncol=4, fontsize=8, frameon=False)
    os.makedirs(out, exist_ok=True)
    path = os.path.join(out, 'brownian_weak_error.png')
    fig.savefig(path, dpi=110)
    print('wrote %s' % path)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('part', choices=['run', 'report'])
    parser.add_argument('--work', required=True, help='folder of the runs (several GB at most)')
    parser.add_argument('--schemes', nargs='+', default=list(SCHEMES), choices=list(SCHEMES), metavar='SCHEME')
    parser.add_argument('--replicas', type=int, default=8, help='replicas per dt (default 8)')
    parser.add_argument('--workers', type=int, default=2, help='worker processes of the ensemble (default 2)')
    parser.add_argument('--tolerance', type=float, default=1e-6, help='solver_tolerance of the runs (default 1e-6)')
    parser.add_argument('--quick', action='store_true', help='a quarter of the simulated time (errors 2x larger)')
    parser.add_argument('--out', default=os.path.join(ROOT, 'doc', 'charts'), help='folder of the chart')
    args = parser.parse_args(argv)
    return run(args) if args.part == 'run' else report(args)


if __name__ == '__main__':
    sys.exit(main())
