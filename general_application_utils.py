"""``general_application_utils``: the published module of small helpers, as a face for users' files (top floor).

Drivers, force files and override files written for the published package import it (``import
general_application_utils as utils``); the package itself never does.  It offers the names those files use
(``tests/test_published_faces.py`` lists them):

* ``static_var(name, value)``: a decorator that sets the attribute ``name`` of the function to ``value`` (the
  published force files keep neighbour lists and caches on their functions this way);
* ``timer(name, print_one=False, print_all=False, clean_all=False)``: named wall-clock accumulators; each call with
  a name alternately starts and stops its clock, ``timer.timers[name]`` holds (seconds so far, start or None);
* ``gmres(A, b, x0=None, tol=1e-5, restart=None, maxiter=None, M=None, callback=None, PC_side='right')``: GMRES
  with the relative tolerance ``tol``; with a preconditioner ``M`` (the inverse of P), ``PC_side`` 'right' solves
  ``A M y = b`` and returns ``x = M y`` (the residual is the true one), 'left' hands ``M`` to SciPy, 'left_res'
  solves ``M A x = M b``; returns ``(x, info)``;
* ``transfer_mobility(mobility_1, point_1, point_2)``: the 6x6 force-torque mobility of a rigid body about
  ``point_2`` from the one about ``point_1`` (Bernal and Garcia de la Torre, Biopolymers 19, 751, 1980, eqs. 10
  and 11), with ``tensor_cross_vector`` and ``vector_cross_tensor``; as published, the cross products take
  r = point_1 - point_2, so the coupling blocks have the sign of the mobility about 2 point_1 - point_2;
* ``log_time_progress(elapsed_time, time_units, total_time_units)``: elapsed and expected time to the
  ``progress_logger`` logger;
* ``Timer``: a context manager that measures wall-clock seconds (``elapsed``; this package's).
"""
import logging
import time

import numpy as np
import scipy.sparse.linalg as spla

from stochastic_forcing import compat
from utils import Timer  # noqa: F401  (re-exported for users' files)


def static_var(name, value):
    """Decorator: ``function.<name> = value`` (a value kept between calls)."""
    def decorate(function):
        setattr(function, name, value)
        return function
    return decorate


@static_var('timers', {})
def timer(name, print_one=False, print_all=False, clean_all=False):
    """Start (odd calls) or stop (even calls) the named clock; ``print_one`` prints its total when it stops,
    ``print_all`` every total, ``clean_all`` forgets them all."""
    total, started = timer.timers.get(name, (0.0, None))
    if name not in timer.timers or started is None:
        timer.timers[name] = (total, time.time())
    else:
        timer.timers[name] = (total + time.time() - started, None)
        if print_one:
            print(name, ' = ', timer.timers[name][0])
    if print_all:
        width = max(len(key) for key in timer.timers)
        print('\n')
        for key in sorted(timer.timers):
            print(key.ljust(width), ' = ', timer.timers[key][0])
    if clean_all:
        timer.timers = {}


def gmres(A, b, x0=None, tol=1e-05, restart=None, maxiter=None, xtype=None, M=None, callback=None, restrt=None,
          PC_side='right', **kwargs):
    """GMRES of ``A x = b`` to the relative tolerance ``tol`` with the preconditioner ``M`` applied on
    ``PC_side`` (see the module docstring); ``xtype`` and ``restrt`` are accepted and unused.  Returns (x, info)."""
    restart = restart if restart is not None else restrt
    if M is None or PC_side == 'left':
        return compat.gmres(A, b, tol, x0=x0, restart=restart, maxiter=maxiter, M=M, callback=callback, **kwargs)
    if PC_side not in ('right', 'left_res'):
        raise ValueError("PC_side must be 'right', 'left' or 'left_res', got %r" % (PC_side,))
    A_op, M_op = spla.aslinearoperator(A), spla.aslinearoperator(M)
    b = np.asarray(b, dtype=float).reshape(-1)
    if PC_side == 'right':
        operator = spla.LinearOperator((b.size, b.size), matvec=lambda y: A_op.matvec(M_op.matvec(y)), dtype=float)
        y, info = compat.gmres(operator, b, tol, restart=restart, maxiter=maxiter, callback=callback, **kwargs)
        return M_op.matvec(y), info
    operator = spla.LinearOperator((b.size, b.size), matvec=lambda x: M_op.matvec(A_op.matvec(x)), dtype=float)
    return compat.gmres(operator, M_op.matvec(b), tol, x0=x0, restart=restart, maxiter=maxiter, callback=callback,
                        **kwargs)


def tensor_cross_vector(T, v):
    """``T x v`` of a 3x3 tensor and a vector, column by column: result[:, l] = sum over the cyclic (l+1, l-1)."""
    T, v = np.asarray(T, dtype=float), np.asarray(v, dtype=float)
    result = np.zeros((3, 3))
    for l in range(3):
        result[:, l] = T[:, (l + 1) % 3] * v[(l - 1) % 3] - T[:, (l - 1) % 3] * v[(l + 1) % 3]
    return result


def vector_cross_tensor(v, T):
    """``v x T`` of a vector and a 3x3 tensor, row by row."""
    T, v = np.asarray(T, dtype=float), np.asarray(v, dtype=float)
    result = np.zeros((3, 3))
    for k in range(3):
        result[k, :] = T[(k - 1) % 3, :] * v[(k + 1) % 3] - T[(k + 1) % 3, :] * v[(k - 1) % 3]
    return result


def transfer_mobility(mobility_1, point_1, point_2):
    """The 6x6 mobility (force, torque) -> (velocity, angular velocity) about ``point_2`` from ``mobility_1``
    about ``point_1`` (3,): rotation block unchanged, couplings and translation moved by r = point_1 - point_2."""
    m1 = np.asarray(mobility_1, dtype=float)
    r = np.asarray(point_1, dtype=float) - np.asarray(point_2, dtype=float)
    m2 = np.zeros((6, 6))
    m2[3:, 3:] = m1[3:, 3:]
    m2[3:, :3] = m1[3:, :3] + tensor_cross_vector(m1[3:, 3:], r)
    m2[:3, 3:] = m2[3:, :3].T
    m2[:3, :3] = (m1[:3, :3] + tensor_cross_vector(m1[:3, 3:], r) - vector_cross_tensor(r, m1[3:, :3])
                  - vector_cross_tensor(r, tensor_cross_vector(m1[3:, 3:], r)))
    return m2


def log_time_progress(elapsed_time, time_units, total_time_units):
    """Log the elapsed time and the expected duration (after ``time_units`` of ``total_time_units``)."""
    logger = logging.getLogger('progress_logger')

    def say(what, seconds):
        logger.info('%s: %.2f %s' % (what, seconds / 60.0 if seconds > 60.0 else seconds,
                                     'Minutes.' if seconds > 60.0 else 'Seconds'))
    say('Elapsed Time', float(elapsed_time))
    if time_units > 0:
        say('Expected Duration', float(elapsed_time) * total_time_units / time_units)
