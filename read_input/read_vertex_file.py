"""``read_vertex_file.read_vertex_file(path)``: the published reader of a ``.vertex`` file (a face).

Returns the body-frame blob positions (n, 3) (a fourth column of radii is read and left out, as the published
reader of one radius does); errors name the file and line (``utils.UserInputError``).
"""
from multi_bodies.files.structure_files import read_vertex_file as _read_vertex_file


def read_vertex_file(name_file):
    """Blob positions (n, 3) of the ``.vertex`` file ``name_file``."""
    return _read_vertex_file(name_file)
