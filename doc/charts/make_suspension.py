"""Write a large suspension scene for the advisor example of doc/advisor.md.

``--spheres`` spheres of radius 1 (12-blob calibrated shells,
``Structures/shell_N_12_Rg_0_7921_Rh_1.vertex``) placed at random, without
overlap (centres at least 2.2 apart), in a layer above the wall with centre
heights between 1.5 and 4, as a sedimented colloidal suspension.  Writes
``<folder>/inputfile_suspension.dat`` and ``<folder>/suspension.clones``;
the input refers to the vertex file by a path relative to the folder.

    python doc/charts/make_suspension.py --folder multi_bodies/examples/suspension --spheres 1000
"""
import argparse
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))  # the repository
from multi_bodies.files import snapshots  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
STRUCTURES = os.path.join(os.path.dirname(os.path.dirname(HERE)), 'multi_bodies', 'Structures')
VERTEX = 'shell_N_12_Rg_0_7921_Rh_1.vertex'
BLOB_RADIUS = 0.416438053447  # the value printed in that vertex file's header

INPUT = """# {spheres} spheres of radius 1 (12-blob shells) sedimented above a wall (doc/advisor.md)
scheme                                   deterministic_adams_bashforth
mobility_blobs_implementation            C++
mobility_vector_prod_implementation      C++
blob_blob_force_implementation           C++
dt                                       0.01
n_steps                                  100
n_save                                   10
eta                                      1.0
g                                        0.1
blob_radius                              {blob_radius}
solver_tolerance                         1e-6
repulsion_strength                       1.0
debye_length                             0.1
repulsion_strength_wall                  1.0
debye_length_wall                        0.1
output_name                              data/suspension
structure {vertex} suspension.clones
"""


def place(spheres, seed=1, min_distance=2.2, low=1.5, high=4.0):
    """Random non-overlapping centres (spheres, 3) in a square layer of area ~ 12 per sphere."""
    rng = np.random.default_rng(seed)
    side = np.sqrt(12.0 * spheres)
    centres = np.zeros((0, 3))
    while len(centres) < spheres:
        trial = np.array([rng.uniform(0, side), rng.uniform(0, side), rng.uniform(low, high)])
        if len(centres) == 0 or np.min(np.linalg.norm(centres - trial, axis=1)) >= min_distance:
            centres = np.vstack((centres, trial))
    return centres


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--folder', required=True)
    parser.add_argument('--spheres', type=int, default=1000)
    args = parser.parse_args()
    os.makedirs(args.folder, exist_ok=True)
    centres = place(args.spheres)
    snapshots.write_clones_file(os.path.join(args.folder, 'suspension.clones'), centres,
                                np.tile([1.0, 0.0, 0.0, 0.0], (len(centres), 1)))
    vertex = os.path.relpath(os.path.join(STRUCTURES, VERTEX), args.folder)
    with open(os.path.join(args.folder, 'inputfile_suspension.dat'), 'w') as f:
        f.write(INPUT.format(spheres=args.spheres, blob_radius=BLOB_RADIUS, vertex=vertex))
    print('wrote %s and %s' % (os.path.join(args.folder, 'inputfile_suspension.dat'),
                               os.path.join(args.folder, 'suspension.clones')))


if __name__ == '__main__':
    main()
