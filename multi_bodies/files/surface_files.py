"""Readers of the phoretic and slip-length files of a structure line (floor 3; doc/phoretic.md).

* ``.Laplace``: one row per blob of the vertex file, in its order, **7 columns**
  ``n_x n_y n_z k alpha mu w``: the outward normal in the body frame, the
  reaction rate ``k`` ([L]/[T]), the emitting rate ``alpha`` ([c][L]/[T]), the
  surface (phoretic) mobility ``mu`` ([L]^2/([T][c])) and the quadrature weight
  ``w`` ([L]^2, the surface area given to the blob).
* ``.slip_length``: one row per blob, **5 columns** ``n_x n_y n_z l w``: normal
  (body frame), slip length ``l`` ([L], 0 = no slip, >= 0) and weight ``w``.

Lines starting with ``#`` (and the rest of a line after ``#``) are comments, as
the published reader (``numpy.loadtxt``) takes them; there is no count line.
Every mistake is a ``utils.UserInputError`` naming the file, the line and the
structure line that named the file.
"""
import os

import numpy as np

from multi_bodies.files.structure_files import _check_extra_columns, _meaningful_lines, _parse_row
from utils import UserInputError

LAPLACE_COLUMNS = 'n_x n_y n_z reaction_rate emitting_rate surface_mobility weight'
SLIP_LENGTH_COLUMNS = 'n_x n_y n_z slip_length weight'


def _read_table(path, kind, columns, expected, num_blobs, vertex_file, referenced_from):
    rows = _meaningful_lines(path, kind, referenced_from)
    origin = ' (named in %s)' % referenced_from if referenced_from else ''
    if len(rows) != num_blobs:
        raise UserInputError('%s%s: %d rows, but %s has %d blobs; a %s file has one row of %s per blob, in the '
                             'order of the vertex file' % (path, origin, len(rows), vertex_file, num_blobs, kind,
                                                           expected))
    _check_extra_columns(path, rows, columns, expected, kind)
    return np.array([_parse_row(path, n, t, columns, expected) for n, t in rows], dtype=float).reshape(-1, columns)


def read_laplace_file(path, num_blobs, vertex_file, referenced_from=None):
    """The ``.Laplace`` table of one structure, shape (num_blobs, 7) (columns as the module docstring)."""
    _hint_if_missing(path, vertex_file, referenced_from, 'janus-laplace --vertex %s' % vertex_file,
                     'the published Laplace_sphere folder does not ship its .Laplace file')
    table = _read_table(path, 'Laplace', 7, LAPLACE_COLUMNS, num_blobs, vertex_file, referenced_from)
    _check_weights(path, table[:, 6], referenced_from)
    return table


def read_slip_length_file(path, num_blobs, vertex_file, referenced_from=None):
    """The ``.slip_length`` table of one structure, shape (num_blobs, 5) (columns as the module docstring)."""
    _hint_if_missing(path, vertex_file, referenced_from, 'slip-length --vertex %s --slip-length L' % vertex_file, '')
    table = _read_table(path, 'slip_length', 5, SLIP_LENGTH_COLUMNS, num_blobs, vertex_file, referenced_from)
    negative = np.flatnonzero(table[:, 3] < 0)
    if negative.size:
        raise UserInputError('%s: row %d has slip length %g; slip lengths are >= 0 (0 is no slip)'
                             % (path, negative[0] + 1, table[negative[0], 3]))
    _check_weights(path, table[:, 4], referenced_from)
    return table


def _hint_if_missing(path, vertex_file, referenced_from, command, note):
    """A missing surface file: the error names the generator command that writes one (doc/phoretic.md)."""
    if os.path.isfile(path):
        return
    raise UserInputError("%s file '%s' not found (named in %s)%s; write one with: python -m "
                         "multi_bodies.files.structure_generators %s --output %s"
                         % (os.path.splitext(path)[1][1:], path, referenced_from, ' (%s)' % note if note else '',
                            command, os.path.dirname(path) or '.'))


def _check_weights(path, weights, referenced_from):
    bad = np.flatnonzero(~(weights > 0))
    if bad.size:
        raise UserInputError('%s%s: row %d has weight %g; the quadrature weights (surface area per blob, last '
                             'column) must be positive' % (path, ' (named in %s)' % referenced_from
                                                          if referenced_from else '', bad[0] + 1, weights[bad[0]]))
