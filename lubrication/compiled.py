"""The compiled near-field kernels (``lubrication/cpp/lubrication_module.cpp``, pybind11) and their switch.

The C++ module computes the same pair and wall blocks as :mod:`lubrication.resistance` and the same sparse
matrices as :func:`lubrication.assembly.resistance_matrices` (the NumPy code stays the reference and the
fallback when the extension is not built; tests check them equal to rounding).  Arguments as there:
``r`` (P,) centre distances and ``h`` (N,) heights in units of a, ``r_hat`` (P, 3) unit vectors,
``factors`` ``(6 pi eta a, 6 pi eta a^2, 6 pi eta a^3)``, ``firm_delta`` the gap clamp (units of a),
``handover`` ``'published'`` or ``'smooth'``, ``cutoff`` the pair cutoff (units of a; used by the smooth
taper only).
"""
import importlib
from functools import lru_cache

import numpy as np
import scipy.sparse as sp

from multi_bodies.files.input_options import DEFAULTS

from . import resistance, tables

try:  # by importlib: the extension module is not a file of the package's import graph (tests/test_layout.py)
    _kernels = importlib.import_module('._lubrication_cpp', __package__)
    _assemble, _pair_blocks, _wall_blocks = _kernels.assemble, _kernels.pair_blocks, _kernels.wall_blocks
except ImportError:  # pragma: no cover - the extension was not built: the NumPy path is used
    _assemble = _pair_blocks = _wall_blocks = None

_USE_COMPILED = [_assemble is not None]
_WINDOW_ORDER = ('near_contact', 'mobility_table', 'wall_near', 'wall_far')


def available():
    """True when the C++ extension ``lubrication._lubrication_cpp`` is built."""
    return _assemble is not None


def in_use():
    """True when the assembly uses the compiled kernels (built, and not switched off by :func:`use_compiled`)."""
    return _USE_COMPILED[0]


def use_compiled(flag=True):
    """Use the compiled kernels (``flag`` True, when built) or the NumPy ones (False); returns the previous
    choice (benchmarks and the equality tests)."""
    previous = _USE_COMPILED[0]
    _USE_COMPILED[0] = bool(flag) and available()
    return previous


@lru_cache(maxsize=None)
def _tables():
    out = {}
    for name in ('JO', 'WS', 'MB'):
        table = tables.pair_table(name)
        out[name + '_x'] = table.x
        out[name] = np.ascontiguousarray(np.concatenate((table.self_scalars, table.pair_scalars), axis=1))
    for name in ('sup', 'MB'):
        table = tables.wall_table(name)
        out['wall_%s_x' % name], out['wall_%s' % name] = table.x, table.scalars
    return out


def _model(factors, firm_delta, handover):
    resistance.check_handover(handover)
    windows = np.array([resistance.SMOOTH_WINDOWS[key] for key in _WINDOW_ORDER], dtype=float).reshape(-1)
    return (_tables(), np.asarray(factors, dtype=float), float(firm_delta), resistance.HANDOVERS.index(handover),
            windows)


def pair_blocks(r, r_hat, factors, firm_delta=resistance.DEFAULT_FIRM_DELTA, handover=DEFAULTS.lubrication_handover,
                cutoff=DEFAULTS.Lub_Cut):
    """(R_sup, R_MB) of pairs, (P, 12, 12) each (with the smooth hand-over, the cutoff taper included)."""
    model = _model(factors, firm_delta, handover)
    return _pair_blocks(*model, resistance.CUTOFF_WINDOW, float(cutoff), np.asarray(r, dtype=float).reshape(-1),
                        np.asarray(r_hat, dtype=float).reshape(-1, 3))


def wall_blocks(h, factors, firm_delta=resistance.DEFAULT_FIRM_DELTA, handover=DEFAULTS.lubrication_handover):
    """(R_sup, R_MB) wall parts of spheres at heights h (N,): (N, 6, 6) each."""
    return _wall_blocks(*_model(factors, firm_delta, handover), np.asarray(h, dtype=float).reshape(-1))


def matrices(n, pairs, r, r_hat, h, factors, firm_delta, handover, cutoff):
    """(R_sup, R_MB, Delta_R) CSR (6N, 6N) of n spheres: pairs (P, 2) sorted (i < j), r (P,), r_hat (P, 3),
    h (N,) heights over a or None (no wall)."""
    h = np.zeros(0) if h is None else np.asarray(h, dtype=float).reshape(-1)
    triples = _assemble(*_model(factors, firm_delta, handover), resistance.CUTOFF_WINDOW, float(cutoff), int(n),
                        np.asarray(pairs, dtype=np.int64).reshape(-1, 2), np.asarray(r, dtype=float).reshape(-1),
                        np.asarray(r_hat, dtype=float).reshape(-1, 3), h)
    size = 6 * n
    return tuple(sp.csr_matrix(triple, shape=(size, size)) for triple in triples)
