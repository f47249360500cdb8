"""Thread policy of the OpenMP kernels, chosen before the compiled extensions load.

libgomp's default wait policy lets idle threads spin (about 300,000 spins,
roughly a millisecond) at the end of every parallel region before they sleep.
A product of ``M f`` for a few thousand blobs takes a millisecond or two, so
on a machine whose cores are shared with other jobs the spinning threads of
one product steal the cores that the other jobs (and the descheduled thread
of the next product) need; the whole step then waits for time slices.  The
package therefore sets, unless the user set them:

* ``OMP_WAIT_POLICY=PASSIVE``: threads that wait sleep at once;
* ``GOMP_SPINCOUNT=0`` (the same for libgomp, explicit).

Both are read when libgomp loads, so they are set in ``os.environ`` with
``setdefault`` on the first import of :mod:`mobility` (before any compiled
kernel loads).  ``RMB_ACTIVE_WAIT=1`` in the environment keeps libgomp's
spinning default (a quiet machine reserved for one run gains a few per cent).

The number of threads is OpenMP's (``OMP_NUM_THREADS``; unset: the cores
this process may run on).  The ensemble runner gives each replica process
its own count (``--omp-threads``).
"""
import importlib
import os

POLICY_VARIABLES = {'OMP_WAIT_POLICY': 'PASSIVE', 'GOMP_SPINCOUNT': '0'}


def apply_wait_policy(environ=os.environ):
    """Set the passive wait policy in ``environ`` where the user did not choose one; returns what was set."""
    if environ.get('RMB_ACTIVE_WAIT', '0') == '1':
        return {}
    chosen = {}
    for name, value in POLICY_VARIABLES.items():
        if name not in environ:
            environ[name] = value
            chosen[name] = value
    return chosen


def available_cores():
    """Cores this process may run on (``os.sched_getaffinity``, else ``os.cpu_count``)."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def describe():
    """One line: the kernel threads and the wait policy in force."""
    try:
        threads = importlib.import_module(__package__ + '._mobility_cpp').max_threads()
    except ImportError:
        threads = 'no C++ extension'
    return '%s (wait policy %s, spin count %s)' % (threads, os.environ.get('OMP_WAIT_POLICY', 'default'),
                                                   os.environ.get('GOMP_SPINCOUNT', 'default'))
