"""``read_clones_file.read_clones_file(path)``: the published reader of a ``.clones`` file (a face).

Returns ``(number of bodies, locations (Nb, 3), orientations)`` with ``orientations`` a list of published
``Quaternion`` objects (scalar first, normalised as the published reader does).
"""
from body.geometry import Quaternion
from multi_bodies.files.snapshots import read_clones_file as _read_clones_file


def read_clones_file(name_file):
    """(Nb, locations (Nb, 3), list of Nb Quaternion) of the ``.clones`` file ``name_file``."""
    locations, orientations = _read_clones_file(name_file)
    return locations.shape[0], locations, [Quaternion(q) for q in orientations]
