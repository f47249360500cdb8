"""The published resistance and mobility tables of the lubrication model (package data, ``lubrication/tables/``).

Five text tables of the published RigidMultiblobsWall ``Lubrication/Resistance_Coefs`` (Sprinkle, van der
Wee, Luo, Driscoll and Donev, Soft Matter 16, 7982, 2020), shipped unchanged; ``tables/README.md`` says
what each holds.  Distances are in units of the sphere radius ``a``; the scalars are normalised by
``6 pi eta a^n`` (resistances) or divided by it (mobilities).

Two layouts:

* pair tables (``res_scalars_JO.txt``, ``mob_scalars_WS.txt``, ``res_scalars_MB_1.txt``): rows in pairs
  with the same centre distance ``r/a``, first the self ("11") scalars, then the pair ("12") scalars;
  columns ``r, X^A, Y^A, Y^B, X^C, Y^C``;
* wall tables (``mob_scalars_wall_MB_2562_eig_thresh.txt``, stored in descending height, and
  ``res_scalars_wall_MB.txt``): one row per height ``h/a``, columns ``h, X^a, Y^a, Y^b, X^c, Y^c``.

Each table is read once per process and kept (read-only arrays, ascending abscissae).
"""
from collections import namedtuple
from functools import lru_cache
from pathlib import Path

import numpy as np

from utils import UserInputError

TABLE_DIRECTORY = Path(__file__).resolve().parent / 'tables'

PAIR_TABLES = {
    'JO': 'res_scalars_JO.txt',      # two-sphere resistance scalars, Jeffrey and Onishi (1984), r/a 2.099..5.001
    'WS': 'mob_scalars_WS.txt',      # two-sphere MOBILITY scalars, r/a 2.002..2.2 (used inverted)
    'MB': 'res_scalars_MB_1.txt',    # resistance of two single RPY blobs, r/a 2.0001..5.0005
}
WALL_TABLES = {
    'sup': 'mob_scalars_wall_MB_2562_eig_thresh.txt',  # sphere-wall MOBILITY of a 2562-blob sphere, h/a 1.0001..10.018
    'MB': 'res_scalars_wall_MB.txt',                     # sphere-wall resistance of one RPB blob, h/a 1.0001..13.4996
}

PairTable = namedtuple('PairTable', ['x', 'self_scalars', 'pair_scalars'])
PairTable.__doc__ = """A two-sphere table: x (n,) ascending r/a; self_scalars, pair_scalars (n, 5) in the column order
X^A, Y^A, Y^B, X^C, Y^C (the "11" and the "12" scalars)."""

WallTable = namedtuple('WallTable', ['x', 'scalars'])
WallTable.__doc__ = """A sphere-wall table: x (n,) ascending h/a; scalars (n, 5) in the column order
X^a (normal), Y^a (parallel), Y^b (coupling), X^c (normal rotation), Y^c (parallel rotation)."""


def _read(file_name):
    path = TABLE_DIRECTORY / file_name
    if not path.is_file():
        raise UserInputError('lubrication table %s is missing; it ships with the package (lubrication/tables/): '
                             'reinstall the package with pip install .' % path)
    try:
        data = np.loadtxt(path, dtype=float, ndmin=2)
    except ValueError as error:
        raise UserInputError('lubrication table %s is not a table of numbers (%s); reinstall the package'
                             % (path, error)) from None
    if data.shape[1] != 6:
        raise UserInputError('lubrication table %s has %d columns, expected 6 (x and five scalars); reinstall the '
                             'package' % (path, data.shape[1]))
    return data


def _frozen(array):
    array = np.ascontiguousarray(array)
    array.setflags(write=False)
    return array


@lru_cache(maxsize=None)
def pair_table(name):
    """The two-sphere table ``name`` ('JO', 'WS' or 'MB') as a :data:`PairTable`."""
    data = _read(PAIR_TABLES[name])
    if data.shape[0] % 2:
        raise UserInputError('lubrication table %s has an odd number of rows; its rows come in pairs (self, pair) '
                             '- reinstall the package' % PAIR_TABLES[name])
    self_rows, pair_rows = data[0::2], data[1::2]
    x = self_rows[:, 0]
    if np.any(np.diff(x) <= 0) or np.any(pair_rows[:, 0] != x):
        raise UserInputError('lubrication table %s: the distances are not ascending in pairs; reinstall the package'
                             % PAIR_TABLES[name])
    return PairTable(_frozen(x), _frozen(self_rows[:, 1:]), _frozen(pair_rows[:, 1:]))


@lru_cache(maxsize=None)
def wall_table(name):
    """The sphere-wall table ``name`` ('sup' or 'MB') as a :data:`WallTable` (heights ascending)."""
    data = _read(WALL_TABLES[name])
    if data[0, 0] > data[-1, 0]:  # the 2562-blob table is stored from the top down
        data = data[::-1]
    if np.any(np.diff(data[:, 0]) <= 0):
        raise UserInputError('lubrication table %s: the heights are not monotonic; reinstall the package'
                             % WALL_TABLES[name])
    return WallTable(_frozen(data[:, 0]), _frozen(data[:, 1:]))


def interpolate(x, values, points):
    """Linear interpolation in a table, the published way (``Lubrication_Class.cc``).

    x : (n,) ascending abscissae; values : (n, k) table columns; points : (m,) where to evaluate.
    Returns (values_at_points (m, k), below (m,) bool, above (m,) bool).

    A point at or below ``x[0]`` gets the first row and ``below`` True; a point beyond ``x[-1]`` gets the
    last row and ``above`` True (the caller may replace it by a far-field form); a point ``p`` in between
    gets ``y_L + (y_R - y_L) / (x_R - x_L) * (p - x_L)`` with ``x_L < p <= x_R`` the bracketing abscissae.
    """
    points = np.asarray(points, dtype=float).reshape(-1)
    upper = np.searchsorted(x, points, side='left')  # first abscissa >= point
    below = upper == 0
    above = upper == x.shape[0]
    left = np.clip(upper - 1, 0, x.shape[0] - 2)
    xL, xR = x[left], x[left + 1]
    yL, yR = values[left], values[left + 1]
    slope = (yR - yL) / (xR - xL)[:, None]
    out = yL + slope * (points - xL)[:, None]
    out[below] = values[0]
    out[above] = values[-1]
    return out, below, above
