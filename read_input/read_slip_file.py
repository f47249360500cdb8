"""``read_slip_file.read_slip_file(path)``: the published reader of a ``.slip`` file (a face).

Returns the body-frame slip of every blob, (n, 3).
"""
from multi_bodies.files.structure_files import read_slip_file as _read_slip_file


def read_slip_file(name_file):
    """Body-frame slip (n, 3) of the ``.slip`` file ``name_file``."""
    return _read_slip_file(name_file)
