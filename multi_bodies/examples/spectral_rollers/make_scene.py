"""Write the scene of the published Spectral_Multiblob_Roller folder, built the same way (doc/periodic.md).

The published folder's own multi_bodies.py multiplies the 12-blob shell of hydrodynamic radius 1 by the input's
blob_radius (1.0155, the particle radius) and takes half the smallest blob distance as the blob radius
(0.42287520345118434); its 2,048 rollers live in a doubly periodic box of side 128.7923 above the wall.  This
script writes that shell (``shell_N_12_Rh_1_0155.vertex``) and ``rollers.clones``: ``--rollers`` rollers at the
published density (box side 128.7923 sqrt(n / 2048)), random orientations, heights uniform in [1.1, 4.5], no two
closer than 2.2 particle radii (our own configuration: the published clones file is not shipped).

    python3 make_scene.py                  # 2,048 rollers, box 128.7923
    python3 make_scene.py --rollers 32     # box 16.099...
"""
import argparse
import os

import numpy as np

PARTICLE_RADIUS = 1.0155          # the published input's blob_radius, which its script uses as the particle radius
PUBLISHED_ROLLERS, PUBLISHED_BOX = 2048, 128.7923
HERE = os.path.dirname(os.path.abspath(__file__))
SHELL = os.path.join(HERE, '..', '..', 'Structures', 'shell_N_12_Rg_0_7921_Rh_1.vertex')


def box_side(n_rollers):
    """Side of the square box that keeps the published area per roller."""
    return PUBLISHED_BOX * np.sqrt(n_rollers / PUBLISHED_ROLLERS)


def scaled_shell():
    """The 12 blob positions (12, 3) of the shell of hydrodynamic radius PARTICLE_RADIUS and the blob radius (half
    the smallest blob distance), as the published folder's script makes them."""
    shell = np.loadtxt(SHELL, skiprows=4) * PARTICLE_RADIUS
    distances = np.linalg.norm(shell[:, None] - shell[None], axis=2)
    return shell, 0.5 * distances[np.triu_indices(len(shell), 1)].min()


def rollers(n_rollers, seed=2048):
    """Locations (n, 3) and unit quaternions (n, 4) (scalar first) of the rollers."""
    rng = np.random.default_rng(seed)
    L = box_side(n_rollers)
    locations = np.empty((0, 3))
    while len(locations) < n_rollers:
        trial = np.array([rng.uniform(0, L), rng.uniform(0, L), rng.uniform(1.1, 4.5)])
        d = locations - trial
        d[:, :2] -= L * np.round(d[:, :2] / L)
        if not len(locations) or np.min(np.linalg.norm(d, axis=1)) > 2.2 * PARTICLE_RADIUS:
            locations = np.vstack([locations, trial])
    quaternions = rng.standard_normal((n_rollers, 4))
    quaternions /= np.linalg.norm(quaternions, axis=1)[:, None]
    return locations, quaternions


def write_scene(folder, n_rollers=PUBLISHED_ROLLERS, seed=2048):
    """Write ``shell_N_12_Rh_1_0155.vertex`` and ``rollers.clones`` into ``folder``; returns (box side, blob radius)."""
    shell, blob_radius = scaled_shell()
    with open(os.path.join(folder, 'shell_N_12_Rh_1_0155.vertex'), 'w') as f:
        f.write('# the 12-blob shell of hydrodynamic radius 1 scaled by 1.0155 (the published Spectral_Multiblob_Roller '
                'folder); blob radius %.17g\n%d\n' % (blob_radius, len(shell)))
        for blob in shell:
            f.write('%.17g %.17g %.17g\n' % tuple(blob))
    locations, quaternions = rollers(n_rollers, seed)
    with open(os.path.join(folder, 'rollers.clones'), 'w') as f:
        f.write('%d\n' % n_rollers)
        for location, q in zip(locations, quaternions):
            f.write('%.12g %.12g %.12g %.12g %.12g %.12g %.12g\n' % (tuple(location) + tuple(q)))
    return box_side(n_rollers), blob_radius


if __name__ == '__main__':
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--rollers', type=int, default=PUBLISHED_ROLLERS)
    parser.add_argument('--seed', type=int, default=2048)
    args = parser.parse_args()
    L, a = write_scene(HERE if os.getcwd() == HERE else os.getcwd(), args.rollers, args.seed)
    print('wrote shell_N_12_Rh_1_0155.vertex (blob radius %.17g) and rollers.clones (%d rollers); '
          'periodic_length %.10g %.10g 0' % (a, args.rollers, L, L))
