"""Calls whose names changed across the supported numpy and scipy versions (numpy >= 1.26, scipy >= 1.10).

* ``trapezoid(y, x, axis)``: ``numpy.trapezoid`` (numpy >= 2.0), else ``numpy.trapz`` (the same rule).
* ``gmres(A, b, tolerance, **kwargs)``: ``scipy.sparse.linalg.gmres`` with the relative tolerance passed as
  ``rtol=`` (scipy >= 1.12) or as ``tol=`` (older scipy, where ``tol`` is the same relative tolerance);
  ``atol`` and the other keywords are passed unchanged.
"""
import inspect

import numpy as np
import scipy.sparse.linalg as spla

trapezoid = getattr(np, 'trapezoid', None) or getattr(np, 'trapz')

_GMRES_TOLERANCE = 'rtol' if 'rtol' in inspect.signature(spla.gmres).parameters else 'tol'


def gmres(operator, rhs, tolerance, **kwargs):
    """``scipy.sparse.linalg.gmres(operator, rhs, rtol=tolerance, **kwargs)`` on every supported scipy."""
    kwargs[_GMRES_TOLERANCE] = tolerance
    return spla.gmres(operator, rhs, **kwargs)
