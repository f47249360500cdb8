"""Rotational (and translational) MSD and height histogram of a sphere above a wall.

Run from inside ``sphere/``::

    python sphere_rotational_msd.py -dt 0.01 -N 20000 -end 2.0 --runs 10

``--runs`` independent spheres start from equilibrium: heights drawn from
the Gibbs-Boltzmann height density and orientations from ``exp(-w (R d)_z / kT)``
(``d`` the centre-of-mass offset), with the seeded generator (``--start H``
starts them all at height ``H`` with the identity orientation instead, as
the published script did: then the burn-in must cover the sedimentation).
They are integrated together (they do not interact) for a burn-in of
``4 end/dt`` steps (``--burn-in`` to change it) and then ``N`` steps.
From the saved configurations (200 lags from 0 to ``-end``; when ``-end``
spans fewer than 199 steps, some lags repeat and the log says so) the 6x6 MSD
(translation of the centre, rotational displacement ``u``; see
``sphere/rigid_msd.py``) is averaged over time origins for each sphere; the
mean and standard error over the spheres are written, with the
equilibrium averages ``kT <mu>`` (quadrature over the Gibbs-Boltzmann height
density) whose doubles are the short-time slopes of the diagonal entries.
The sampled height histogram is written next to the exact density; the
log compares the sampled mean height with the Gibbs-Boltzmann mean and warns
when they differ by more than 3 standard errors (of the per-sphere means).

Outputs in ``--data-dir`` (default ``./data``), ``<stem>`` =
``sphere-msd-dt-<dt>-N-<N>-scheme-<scheme>-mobility-<model>[-<name>]``:

* ``<stem>.txt``: ``t``, the 6 diagonal MSD entries (x, y, z, u_x, u_y, u_z),
  then their 6 standard errors; ``#`` header lines give the parameters and
  the equilibrium slopes ``2 kT <mu>``;
* ``<stem>.npz``: ``times``, ``msd`` (L, 6, 6), ``msd_error`` (L, 6, 6);
* ``<stem>.heights.txt``: bin centre, sampled density, Gibbs-Boltzmann density;
* with ``--plot``, ``./figures/<stem>.msd.png`` and ``<stem>.heights.png``.

See ``doc/sphere.md``.
"""
import argparse
import os
import sys
import time

# The one path prelude of the scripts: the repository root first, then utils.prepare_script_path.
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import utils  # noqa: E402
utils.prepare_script_path(__file__)

import numpy as np  # noqa: E402

from body.geometry import rotation_matrices  # noqa: E402
from stochastic_forcing import compat  # noqa: E402

from sphere import sphere as sph  # noqa: E402
from sphere.rigid_msd import msd_statistics  # noqa: E402
from sphere.single_body_integrators import SCHEMES, SingleBodyIntegrator  # noqa: E402

NUM_LAGS = 200
BIN_WIDTH = 0.05


def equilibrium_averages(model, kT, h_max=None, points=20001):
    """``<N>`` (6, 6) over the Gibbs-Boltzmann height density (trapezoidal quadrature) and the density grid."""
    h_max = h_max or model.a + 60.0 * kT / model.weight
    h = np.linspace(model.a, h_max, points)[1:]
    density = model.equilibrium_height_density(h, kT)
    density /= compat.trapezoid(density, h)
    N = model.mobility(np.column_stack((np.zeros_like(h), np.zeros_like(h), h)), None)
    return compat.trapezoid(N * density[:, None, None], h, axis=0), h, density


def equilibrium_start(model, kT, runs, rng):
    """Locations (runs, 3) and orientations (runs, 4) drawn from the Gibbs-Boltzmann distribution.

    Heights by inverse transform of the height density on a fine grid; orientations by rejection from
    uniform (Haar) quaternions with acceptance ``exp(-w ((R d)_z + |d|) / kT)`` (height and orientation
    are independent: the energy is ``w (h + (R d)_z) + U_wall(h)``).
    """
    _, h, density = equilibrium_averages(model, kT)
    cdf = np.concatenate(([0.0], np.cumsum(0.5 * (density[1:] + density[:-1]) * np.diff(h))))
    heights = np.interp(rng.uniform(0.0, cdf[-1], runs), cdf, h)
    reach = np.linalg.norm(model.com_offset)
    orientations = np.zeros((0, 4))
    while orientations.shape[0] < runs:
        q = rng.normal(size=(4 * runs, 4))
        q /= np.linalg.norm(q, axis=1)[:, None]
        arm_z = (rotation_matrices(q) @ model.com_offset)[:, 2]
        keep = rng.uniform(size=q.shape[0]) < np.exp(-model.weight * (arm_z + reach) / kT)
        orientations = np.concatenate((orientations, q[keep]))
    return np.column_stack((np.zeros(runs), np.zeros(runs), heights)), orientations[:runs]


def lag_samples(end_time, dt):
    """(saving interval in steps, lags in samples (NUM_LAGS,)): lags from 0 to ``end_time``, the last one at it."""
    interval = max(1, int(np.floor(end_time / dt / (NUM_LAGS - 1) + 1e-9)))
    last = max(1, int(round(end_time / dt / interval)))
    return interval, np.round(np.linspace(0, last, NUM_LAGS)).astype(int)


def run(dt, n_steps, end_time, runs=10, scheme='RFD', mobility_model='best', com_offset=sph.COM_OFFSET,
        burn_in=None, seed=None, data_dir='data', data_name='', plot=False, logger=None, start_height=None):
    """Integrate ``runs`` spheres, write the MSD and height files; returns the stem path."""
    if not dt > 0.0 or n_steps < 1 or runs < 1 or not end_time > 0.0:
        raise utils.UserInputError('-dt, -end must be positive and -N, --runs at least 1 (got dt %s, N %s, '
                                   'end %s, runs %s)' % (dt, n_steps, end_time, runs))
    logger = logger or utils.get_logger('sphere')
    interval, lags = lag_samples(end_time, dt)
    if lags[-1] * interval >= n_steps:
        raise utils.UserInputError('-N %d is too short for an MSD up to -end %s with dt %s: it needs more than %d '
                                   'steps' % (n_steps, end_time, dt, lags[-1] * interval))
    if len(np.unique(lags)) < NUM_LAGS:
        logger.warning('-end %s spans only %d steps of dt %s: %d distinct lags, some of the %d rows repeat a lag'
                       % (end_time, lags[-1] * interval, dt, len(np.unique(lags)), NUM_LAGS))
    burn_in = int(4 * end_time / dt) if burn_in is None else int(burn_in)
    model = sph.SphereModel(mobility_model, com_offset=com_offset)
    rng = np.random.default_rng(seed)
    integrator = SingleBodyIntegrator(scheme, model.mobility, model.force_torque, sph.KT, model.is_valid, rng)
    if start_height is None:
        locations, orientations = equilibrium_start(model, sph.KT, runs, rng)
    else:
        locations = np.tile([0.0, 0.0, float(start_height)], (runs, 1))
        orientations = np.tile([1.0, 0.0, 0.0, 0.0], (runs, 1))
    saved_locations, saved_orientations = [], []
    start = time.perf_counter()
    total = burn_in + n_steps
    for step in range(1, total + 1):
        locations, orientations = integrator.step(locations, orientations, dt)
        if step > burn_in and (step - burn_in) % interval == 0:
            saved_locations.append(locations.copy())
            saved_orientations.append(orientations.copy())
        if step % max(1, total // 10) == 0:
            logger.info('step %d of %d, rejected trial steps %d, %.1f s'
                        % (step, total, integrator.rejections, time.perf_counter() - start))
    saved_locations = np.array(saved_locations)        # (samples, runs, 3)
    saved_orientations = np.array(saved_orientations)
    trajectories = [(saved_locations[:, k], saved_orientations[:, k]) for k in range(runs)]
    msd, msd_error = msd_statistics(trajectories, lags)
    times = lags * interval * dt

    mean_mobility, h_grid, density = equilibrium_averages(model, sph.KT)
    slopes = 2.0 * sph.KT * np.diag(mean_mobility)
    heights = saved_locations[:, :, 2].ravel()
    # Bins over the sampled heights and the support of the exact density (up to its 1 - 1e-6 quantile).
    cumulative = np.cumsum(density) / np.sum(density)
    support = float(h_grid[min(np.searchsorted(cumulative, 1.0 - 1e-6), len(h_grid) - 1)])
    edges = np.arange(model.a, max(heights.max(), support, model.a + BIN_WIDTH) + BIN_WIDTH, BIN_WIDTH)
    counts, edges = np.histogram(heights, bins=edges)
    centres = 0.5 * (edges[1:] + edges[:-1])
    sampled = counts / (counts.sum() * BIN_WIDTH)
    exact = np.interp(centres, h_grid, density, left=0.0, right=0.0)
    # The sampled heights against the Gibbs-Boltzmann mean: standard error of the mean over the spheres.
    gibbs_mean = float(np.trapezoid(h_grid * density, h_grid))
    sphere_means = saved_locations[:, :, 2].mean(axis=0)
    sampled_mean = float(sphere_means.mean())
    error = float(sphere_means.std(ddof=1) / np.sqrt(runs)) if runs > 1 else float('nan')
    logger.info('mean height: sampled %.4g +- %.2g (standard error over %d spheres), Gibbs-Boltzmann %.4g'
                % (sampled_mean, error, runs, gibbs_mean))
    if runs > 1 and abs(sampled_mean - gibbs_mean) > 3 * error:
        logger.warning('the sampled heights are not at equilibrium: mean %.4g against the Gibbs-Boltzmann %.4g '
                       '(%.1f standard errors); lengthen the burn-in (--burn-in) or the run (-N), or start from '
                       'equilibrium (drop --start)' % (sampled_mean, gibbs_mean,
                                                      abs(sampled_mean - gibbs_mean) / error))

    os.makedirs(data_dir, exist_ok=True)
    stem = 'sphere-msd-dt-%s-N-%s-scheme-%s-mobility-%s' % (dt, n_steps, scheme, mobility_model)
    if data_name:
        stem += '-' + data_name
    path = os.path.join(data_dir, stem)
    header = ('sphere above a wall: a %s, eta %s, weight %s, kT %s, repulsion %s, debye length %s, '
              'centre-of-mass offset %s\nscheme %s, mobility %s, dt %s, N %s, burn-in %s, runs %s, seed %s, start %s, '
              'rejected trial steps %d\nequilibrium slopes 2 kT <mu> (x y z u_x u_y u_z): %s\n'
              'columns: t, MSD x y z u_x u_y u_z, standard errors of the same'
              % (model.a, model.eta, model.weight, sph.KT, model.repulsion_strength, model.debye_length,
                 model.com_offset.tolist(), scheme, mobility_model, dt, n_steps, burn_in, runs, seed,
                 'equilibrium' if start_height is None else 'height %s' % start_height, integrator.rejections,
                 ' '.join('%.8g' % s for s in slopes)))
    diagonal = np.arange(6)
    np.savetxt(path + '.txt', np.column_stack((times, msd[:, diagonal, diagonal], msd_error[:, diagonal, diagonal])),
               header=header)
    np.savez(path + '.npz', times=times, msd=msd, msd_error=msd_error, slopes=slopes)
    np.savetxt(path + '.heights.txt', np.column_stack((centres, sampled, exact)),
               header='height histogram (bin %s) of %d samples; columns: bin centre, sampled density, '
                      'Gibbs-Boltzmann density\nmean height: sampled %.6g +- %.3g, Gibbs-Boltzmann %.6g'
                      % (BIN_WIDTH, heights.size, sampled_mean, error, gibbs_mean))
    logger.info('kT <mu_par> = %.6g, kT <mu_rot_par> = %.6g, kT <mu_rot_perp> = %.6g'
                % tuple(sph.KT * mean_mobility[k, k] for k in (0, 3, 5)))
    if msd.shape[0] > 1:
        logger.info('first-lag slopes / (2 kT <mu>): %s'
                    % ' '.join('%.4f' % v for v in msd[1, diagonal, diagonal] / (times[1] * slopes)))
    logger.info('wrote %s.txt, .npz, .heights.txt' % path)
    if plot:
        plot_results(stem, times, msd, msd_error, slopes, centres, sampled, exact)
    return path


def plot_results(stem, times, msd, msd_error, slopes, centres, sampled, exact):
    """MSD and height figures in ./figures (matplotlib, Agg backend)."""
    import matplotlib
    matplotlib.use('Agg')
    from matplotlib import pyplot
    os.makedirs('figures', exist_ok=True)
    labels = ['x', 'y', 'z', 'u_x', 'u_y', 'u_z']
    figure, axes = pyplot.subplots(1, 2, figsize=(10, 4))
    for k in range(6):
        ax = axes[0] if k < 3 else axes[1]
        line = ax.errorbar(times, msd[:, k, k], yerr=2.0 * msd_error[:, k, k], label=labels[k], errorevery=10)
        ax.plot(times, slopes[k] * times, '--', color=line[0].get_color(), lw=0.8)
    for ax, title in zip(axes, ('translational MSD (dashed: 2 kT <mu> t)', 'rotational MSD (dashed: 2 kT <mu> t)')):
        ax.set_xlabel('time')
        ax.set_title(title, fontsize=9)
        ax.legend(fontsize=8)
    figure.tight_layout()
    figure.savefig(os.path.join('figures', stem + '.msd.png'), dpi=120)
    pyplot.close(figure)
    figure, ax = pyplot.subplots(figsize=(5, 4))
    ax.plot(centres, sampled, 'o', ms=3, label='sampled')
    ax.plot(centres, exact, '-', label='Gibbs-Boltzmann')
    ax.set_xlabel('height of the centre')
    ax.set_ylabel('density')
    ax.legend()
    figure.tight_layout()
    figure.savefig(os.path.join('figures', stem + '.heights.png'), dpi=120)
    pyplot.close(figure)


def main(argv=None):
    parser = argparse.ArgumentParser(description='MSD and height histogram of a sphere with a displaced '
                                                 'centre of mass above a wall; see doc/sphere.md.')
    parser.add_argument('-dt', dest='dt', type=float, required=True, help='time step')
    parser.add_argument('-N', dest='n_steps', type=int, required=True, help='steps after the burn-in')
    parser.add_argument('-end', dest='end_time', type=float, default=1.0, help='longest MSD lag time (default 1)')
    parser.add_argument('--runs', type=int, default=10, help='independent spheres (default 10)')
    parser.add_argument('--scheme', choices=SCHEMES, default='RFD', help='RFD (default), FIXMAN or EM')
    parser.add_argument('--mobility', choices=sorted(sph.MOBILITY_MODELS), default='best',
                        help='best (default): Huang-Breuer, Goldman/Faucheux, 162-blob splines; '
                             'swan-brady: single blob')
    parser.add_argument('--com-offset', type=float, nargs=3, default=list(sph.COM_OFFSET),
                        metavar=('X', 'Y', 'Z'), help='centre of mass in the body frame (default 0 0 -0.1)')
    parser.add_argument('--burn-in', type=int, default=None, help='steps before saving (default 4 end/dt)')
    parser.add_argument('--seed', type=int, default=None, help='seed of the random generator')
    parser.add_argument('--start', type=float, default=None, metavar='H',
                        help='start every sphere at height H, identity orientation (default: equilibrium samples)')
    parser.add_argument('--data-dir', default='data', help='output folder (default ./data)')
    parser.add_argument('--data-name', default='', help='text appended to the output names')
    parser.add_argument('--plot', action='store_true', help='also draw figures in ./figures')
    args = parser.parse_args(argv)
    try:
        run(args.dt, args.n_steps, args.end_time, args.runs, args.scheme, args.mobility, args.com_offset,
            args.burn_in, args.seed, args.data_dir, args.data_name, args.plot, start_height=args.start)
    except utils.SimulationStopped as err:
        print('stopped: %s' % err, file=sys.stderr)
        return 1
    return 0


if __name__ == '__main__':
    sys.exit(utils.fail_cleanly(main))
