"""Accuracy against cost of sphere models above a wall: which resolution does a scene need?

A sphere of radius R = 1 at centre height h is modelled by one blob (the
minimally resolved model of the microroller papers, blob radius R) or by an
icosahedral shell of 12, 42, 162 or 642 blobs (blob radius calibrated so that
the bulk translational radius is 1, as made by
``multi_bodies.files.structure_generators``).  For each model and height the script
computes the 6x6 mobility and compares five scalars with the exact values of
a sphere above a wall (Brenner, O'Neill, Dean-O'Neill,
Jeffery series): parallel and perpendicular translation, parallel and
perpendicular rotation, and the translation-rotation coupling.  Cost: the
time of one blob mobility product M f for a suspension of 100 such spheres
with the C++ backend (what each GMRES iteration costs), and the number of
blobs.

    python doc/charts/sphere_accuracy_vs_cost.py            # prints the markdown table
    python doc/charts/sphere_accuracy_vs_cost.py --png chart.png   # also draws it (needs matplotlib)
"""
import argparse
import time

import numpy as np

from mobility.interface import Geometry, make_mobility
from multi_bodies.files.structure_generators import calibrated_shell

# Exact values (Brenner 1961, O'Neill 1964, Dean and O'Neill 1963, Jeffery 1915): h/R -> (mu_par, mu_perp, rot_par, rot_perp, coupling), exact.
EXACT = {1.1: (0.44305, 0.08727, 0.68955, 0.89520, 2.703e-2),
         1.5: (0.62681, 0.31197, 0.90069, 0.96237, 9.355e-3),
         2.0: (0.72321, 0.47047, 0.95991, 0.98432, 3.488e-3),
         5.0: (0.88821, 0.77816, 0.99750, 0.99900, 1.227e-4)}
NAMES = ('par', 'perp', 'rot par', 'rot perp', 'coupling')


def shell_scalars(num_blobs, h, eta=1.0):
    """The five normalised mobilities of a calibrated shell with centre at height h."""
    blobs, a, _ = calibrated_shell(num_blobs)
    r = blobs + np.array([0.0, 0.0, h])
    M = make_mobility('python', Geometry('single_wall'), eta, a).dense_matrix(r)
    n = r.shape[0]
    K = np.zeros((3 * n, 6))
    for i, arm in enumerate(blobs):
        K[3 * i:3 * i + 3, 0:3] = np.eye(3)
        K[3 * i:3 * i + 3, 3:6] = -np.array([[0, -arm[2], arm[1]], [arm[2], 0, -arm[0]], [-arm[1], arm[0], 0]])
    N = np.linalg.inv(K.T @ np.linalg.solve(M, K))
    return normalised(N, eta)


def single_blob_scalars(h, eta=1.0):
    """The same scalars for one blob of radius 1 (grand mobility of the roller model)."""
    r = np.array([[0.0, 0.0, h]])
    blob = make_mobility('C++', Geometry('single_wall'), eta, 1.0)
    N = np.zeros((6, 6))
    for col, (kind_t, kind_r) in enumerate([('trans_times_force', 'rot_times_force')] * 3
                                           + [('trans_times_torque', 'rot_times_torque')] * 3):
        e = np.zeros(3)
        e[col % 3] = 1.0
        N[0:3, col] = blob.coupling(kind_t, r, e)
        N[3:6, col] = blob.coupling(kind_r, r, e)
    return normalised(N, eta)


def normalised(N, eta):
    mu_t, mu_r, mu_c = 1 / (6 * np.pi * eta), 1 / (8 * np.pi * eta), 1 / (6 * np.pi * eta)
    return np.array([N[0, 0] / mu_t, N[2, 2] / mu_t, N[3, 3] / mu_r, N[5, 5] / mu_r, N[4, 0] / mu_c])


def product_seconds(blobs_per_sphere, spheres=100, repeats=3):
    """Time of one wall M f (C++) for `spheres` spheres of this resolution on a square lattice."""
    rng = np.random.default_rng(0)
    n = blobs_per_sphere * spheres
    side = int(np.ceil(np.sqrt(spheres)))
    centres = np.array([[3.0 * (k % side), 3.0 * (k // side), 1.5] for k in range(spheres)])
    r = np.repeat(centres, blobs_per_sphere, axis=0) + rng.uniform(-1, 1, (n, 3)) * 0.9
    r[:, 2] = np.abs(r[:, 2]) + 0.1
    f = rng.standard_normal(3 * n)
    blobs = make_mobility('C++', Geometry('single_wall'), 1.0, 0.1)
    blobs.velocities(r, f)
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        blobs.velocities(r, f)
        best = min(best, time.perf_counter() - start)
    return best


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--png', help='also draw the chart into this PNG file (needs matplotlib)')
    args = parser.parse_args()
    models = [('1 blob', 1, single_blob_scalars)] + [
        ('shell %d' % n, n, (lambda h, n=n: shell_scalars(n, h))) for n in (12, 42, 162, 642)]
    rows = []
    print('| model | blobs | M f, 100 spheres (C++) | h/R | ' + ' | '.join('err %s' % name for name in NAMES)
          + ' | worst |')
    print('|---|---|---|---|' + '---|' * (len(NAMES) + 1))
    for label, blobs, scalars in models:
        seconds = product_seconds(blobs)
        for h, exact in EXACT.items():
            error = scalars(h) / np.array(exact) - 1.0
            rows.append((label, blobs, seconds, h, error))
            print('| %s | %d | %.3g ms | %g | %s | %.1f%% |' % (
                label, blobs, 1e3 * seconds, h, ' | '.join('%+.1f%%' % (100 * e) for e in error),
                100 * np.max(np.abs(error))))
    if args.png:
        import matplotlib
        matplotlib.use('Agg')
        import matplotlib.pyplot as plt
        fig, ax = plt.subplots(figsize=(6.5, 4.5))
        for h in EXACT:
            points = [(r[2], np.max(np.abs(r[4][:4]))) for r in rows if r[3] == h]
            ax.loglog([1e3 * p[0] for p in points], [100 * p[1] for p in points], 'o-', label='h/R = %g' % h)
        for label, blobs, seconds, h, error in rows:
            if h == 2.0:
                ax.annotate(label, (1e3 * seconds, 100 * np.max(np.abs(error[:4]))), fontsize=8,
                            textcoords='offset points', xytext=(4, 4))
        ax.set_xlabel('one M f for 100 spheres, C++ on 2 cores [ms]')
        ax.set_ylabel('worst error of the 4 self mobilities [%]')
        ax.set_title('Sphere above a wall: accuracy against cost')
        ax.grid(True, which='both', alpha=0.3)
        ax.legend()
        fig.tight_layout()
        fig.savefig(args.png, dpi=120)
        print('chart written to %s' % args.png)


if __name__ == '__main__':
    main()
