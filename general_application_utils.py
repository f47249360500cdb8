"""``general_application_utils``: the published module of small helpers, as a face for users' files (top floor).

Drivers and override files written for the published package import it (``import general_application_utils``);
the package itself never does.  It offers the helpers those files use:

* ``gmres(A, b, x0=None, tol=1e-5, restart=None, maxiter=None, M=None, callback=None, ...)``: SciPy's GMRES
  with the published keyword ``tol`` (the relative tolerance) on every supported SciPy (a user's own solves;
  the package's problems go through its one solve, ``multi_bodies.solver.body_solver.solve``);
* ``Timer``: a context manager that measures wall-clock seconds (``elapsed``).
"""
from stochastic_forcing import compat
from utils import Timer  # noqa: F401  (re-exported for users' files)


def gmres(A, b, x0=None, tol=1e-05, restart=None, maxiter=None, M=None, callback=None, **kwargs):
    """``scipy.sparse.linalg.gmres(A, b, ...)`` with the relative tolerance ``tol``: returns ``(x, info)``."""
    return compat.gmres(A, b, tol, x0=x0, restart=restart, maxiter=maxiter, M=M, callback=callback, **kwargs)
