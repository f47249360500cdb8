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

BLAS runs on one thread.  OpenBLAS (numpy's and SciPy's) lets its worker
threads spin after every call it parallelised; in an iterative step the
calls are small (the Gram-Schmidt products of GMRES and Lanczos, the
preconditioner's blocks) and the spinning workers take the cores the next
product of ``M f`` needs: one Slip_Trapz step of 1,000 boomerangs took
18.0 s with OpenBLAS's default threads and 15.8 s with one (the product
itself 229 ms against 199 ms), and several BLAS threads made a dense
Brownian step of the tests 8 times slower.  So :func:`apply_blas_policy`
(on the first import of :mod:`mobility`) sets the OpenBLAS and MKL thread
counts of the libraries already loaded to one, and ``OPENBLAS_NUM_THREADS``
/ ``MKL_NUM_THREADS`` to 1 for those loaded later, unless the user set one
of them or ``RMB_BLAS_THREADS``: ``RMB_BLAS_THREADS=k`` asks for k BLAS
threads, ``RMB_BLAS_THREADS=0`` leaves BLAS as it was (large dense
problems, ``save_blobs_mobility`` of thousands of blobs, gain from BLAS
threads).
"""
import ctypes
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
    """One line: the kernel threads, the wait policy, the BLAS threads in force and the kernels' vector path."""
    try:
        threads = importlib.import_module(__package__ + '._mobility_cpp').max_threads()
    except ImportError:
        threads = 'no C++ extension'
    blas = sorted(set(blas_threads().values()))
    from . import simd
    return '%s (wait policy %s, spin count %s), BLAS threads %s, kernel path %s' % (
        threads, os.environ.get('OMP_WAIT_POLICY', 'default'), os.environ.get('GOMP_SPINCOUNT', 'default'),
        '/'.join(str(count) for count in blas) if blas else 'unknown', simd.describe())


# set-thread-count functions of the BLAS libraries numpy and SciPy ship or link (OpenBLAS with and without
# the scipy-openblas prefix and 64-bit-integer suffix, MKL)
BLAS_THREAD_SETTERS = ('openblas_set_num_threads', 'scipy_openblas_set_num_threads',
                       'scipy_openblas_set_num_threads64_', 'openblas_set_num_threads64_', 'MKL_Set_Num_Threads')
BLAS_THREAD_GETTERS = ('openblas_get_num_threads', 'scipy_openblas_get_num_threads',
                       'scipy_openblas_get_num_threads64_', 'openblas_get_num_threads64_', 'MKL_Get_Max_Threads')
BLAS_VARIABLES = ('OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS')


def loaded_blas_libraries():
    """Paths (list) of the loaded shared libraries that are BLAS (OpenBLAS or MKL) on Linux; [] elsewhere."""
    paths = []
    try:
        with open('/proc/self/maps') as maps:
            for line in maps:
                path = line.split()[-1]
                name = os.path.basename(path).lower()
                if path.startswith('/') and ('openblas' in name or 'mkl_rt' in name) and path not in paths:
                    paths.append(path)
    except OSError:
        return []
    return paths


def _blas_functions(names):
    found = []
    for path in loaded_blas_libraries():
        try:
            library = ctypes.CDLL(path)
        except OSError:
            continue
        for name in names:
            function = getattr(library, name, None)
            if function is not None:
                found.append((os.path.basename(path), function))
                break
    return found


def set_blas_threads(count):
    """Set the thread count of every loaded OpenBLAS/MKL library to ``count``; returns the libraries set."""
    done = []
    for library, function in _blas_functions(BLAS_THREAD_SETTERS):
        function.argtypes = [ctypes.c_int]
        function.restype = None
        function(int(count))
        done.append(library)
    return done


def blas_threads():
    """{library: threads} of the loaded OpenBLAS/MKL libraries (empty where none is found)."""
    counts = {}
    for library, function in _blas_functions(BLAS_THREAD_GETTERS):
        function.restype = ctypes.c_int
        counts[library] = int(function())
    return counts


def apply_blas_policy(environ=os.environ):
    """One BLAS thread unless the user chose (module docstring); returns the count set, or None if left alone."""
    requested = environ.get('RMB_BLAS_THREADS')
    if requested is None:
        if any(name in environ for name in BLAS_VARIABLES):
            return None
        count = 1
    else:
        try:
            count = int(requested)
        except ValueError:
            return None
        if count <= 0:
            return None
    for name in BLAS_VARIABLES:
        environ.setdefault(name, str(count))
    set_blas_threads(count)
    return count
