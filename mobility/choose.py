"""Choose a mobility backend from its measured cost on this machine.

``auto`` (input option value of ``mobility_vector_prod_implementation`` and
``mobility_blobs_implementation``) asks for the fastest usable backend.  The
fastest depends on the machine and on the size of the problem: a GPU pays a
fixed host-device transfer per product that the C++ backend does not, and
the NumPy backend is competitive only for a handful of blobs.  So the choice
is measured, not read from a fixed order:

* each usable backend evaluates the product (``M f`` for kind
  ``vector_product``; one dense blob matrix for kind ``blobs``) on random
  blobs at the problem's size, capped at ``PROBE_BLOBS`` blobs (fewer for
  the NumPy backend, ``PYTHON_PROBE_BLOBS``); when the
  problem is larger, the time is modelled as ``t0 + c N^2`` (all-pairs work),
  with ``t0`` and ``c`` fitted from probes at two sizes;
* the backend with the smallest cost wins; a backend within
  ``TIE_MARGIN`` of the best that comes earlier in the registry's
  preference order (``mobility.interface.PREFERENCE``: pycuda, C++,
  python) is kept instead, so that timing noise on a busy machine does not
  flip the choice between equivalent backends.

The candidates are the registered backends that serve the geometry (the wall
or free space) and, for kind ``blobs``, build dense matrices, in the
registry's order (:data:`PREFERENCE` reads them from there; this module
names no backend).  Every probe goes through the interface
(``BlobMobility.velocities`` and ``dense_matrix``).

Timings are the best of a few repeats after a warm-up call (which also
compiles the GPU kernels), cached per process and problem size.

Floor 2 (it reads the registry of ``mobility.interface``): imports only ``mobility`` and ``utils``.
"""
import time
from collections.abc import Mapping

import numpy as np

from . import interface

KINDS = ('vector_product', 'blobs')


def candidate_backends(kind, wall=True):
    """Registered backends that may serve ``kind`` ('vector_product': ``M f``; 'blobs': dense matrices) with the
    wall (``wall``) or in free space, in the registry's preference order."""
    if kind not in KINDS:
        raise ValueError('kind %r is not one of %s' % (kind, ', '.join(KINDS)))
    return tuple(interface.registered_backends(_geometry(wall), dense_matrices=kind == 'blobs'))


def _geometry(wall):
    return interface.Geometry('single_wall' if wall else 'free_space')


class _RegistryOrder(Mapping):
    """kind -> :func:`candidate_backends` (with the wall), read from the registry at every look-up."""

    def __getitem__(self, kind):
        if kind not in KINDS:
            raise KeyError(kind)
        return candidate_backends(kind)

    def __iter__(self):
        return iter(KINDS)

    def __len__(self):
        return len(KINDS)


PREFERENCE = _RegistryOrder()
PROBE_BLOBS = {'vector_product': 2000, 'blobs': 300}
PYTHON_PROBE_BLOBS = 400  # the NumPy backend is timed on fewer blobs, so that probing it stays cheap
TIE_MARGIN = 0.2
_cache = {}


def random_blobs(num_blobs, blob_radius=1.0, seed=0):
    """Random blob positions above the wall, shape (num_blobs, 3): a slab of density about one blob per (4a)^3."""
    rng = np.random.default_rng(seed)
    side = 4.0 * blob_radius * max(1.0, num_blobs ** (1.0 / 3.0))
    r = rng.uniform(0.0, side, (num_blobs, 3))
    r[:, 2] += 1.5 * blob_radius
    return r


def time_call(function, repeats=3, long_call_s=0.5):
    """Best wall-clock time of ``function()`` over ``repeats`` calls, after one warm-up call (seconds).

    A warm-up call longer than ``long_call_s`` is taken as the measurement (long calls are not
    dominated by first-call effects, and repeating them would cost seconds).
    """
    start = time.perf_counter()
    function()
    warm_up = time.perf_counter() - start
    if warm_up > long_call_s:
        return warm_up
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        function()
        best = min(best, time.perf_counter() - start)
    return best


def _probe(backend, kind, wall, num_blobs):
    """Measured seconds of one evaluation of ``kind`` by ``backend`` on ``num_blobs`` random blobs."""
    key = (backend, kind, wall, int(num_blobs))
    if key not in _cache:
        mobility = interface.make_mobility(backend, _geometry(wall), 1.0, 1.0, dense_matrices=kind == 'blobs')
        r = random_blobs(int(num_blobs))
        if kind == 'vector_product':
            force = np.random.default_rng(1).standard_normal(r.size)
            _cache[key] = time_call(lambda: mobility.velocities(r, force))
        else:
            _cache[key] = time_call(lambda: mobility.dense_matrix(r))
    return _cache[key]


def modelled_seconds(backend, kind, num_blobs, wall=True):
    """Seconds of one evaluation at ``num_blobs`` blobs: measured up to the probe size, else ``t0 + c N^2``.

    Returns (seconds, 'measured' or 'modelled').
    """
    cap = PROBE_BLOBS[kind] if backend != 'python' else min(PROBE_BLOBS[kind], PYTHON_PROBE_BLOBS)
    num_blobs = max(1, int(num_blobs))
    if num_blobs <= cap:
        return _probe(backend, kind, wall, num_blobs), 'measured'
    small, large = cap // 4, cap
    t_small, t_large = _probe(backend, kind, wall, small), _probe(backend, kind, wall, large)
    c = max(t_large - t_small, 1e-12) / (large ** 2 - small ** 2)
    t0 = max(t_small - c * small ** 2, 0.0)
    return t0 + c * num_blobs ** 2, 'modelled'


def backend_costs(kind, num_blobs, wall=True, candidates=None):
    """Dict backend -> (seconds, how) for every usable backend among ``candidates`` (default: those of
    :func:`candidate_backends` for ``kind`` and ``wall``)."""
    costs = {}
    for backend in (candidates or candidate_backends(kind, wall)):
        if interface.is_usable(backend):
            costs[backend] = modelled_seconds(backend, kind, num_blobs, wall)
    return costs


def choose_backend(kind, num_blobs, wall=True, log=None):
    """Name (without ``_no_wall``) of the backend of smallest cost for ``kind`` at ``num_blobs`` blobs.

    ``num_blobs`` None means "size unknown": the probe size is used.
    ``log`` (callable) is told the measured costs.  Raises
    ``utils.UserInputError`` (through the registry) when nothing is usable.
    """
    size = PROBE_BLOBS[kind] if num_blobs is None else int(num_blobs)
    order = candidate_backends(kind, wall)
    costs = backend_costs(kind, size, wall, order)
    if not costs:
        from utils import UserInputError
        raise UserInputError('no usable backend for %s' % kind)
    best = min(seconds for seconds, _ in costs.values())
    chosen = next(b for b in order if b in costs and costs[b][0] <= (1.0 + TIE_MARGIN) * best)
    if log is not None:
        log('%s costs at %d blobs: %s' % (kind, size, ', '.join(
            '%s %.3g ms (%s)' % (b, 1e3 * s, how) for b, (s, how) in costs.items())))
    return chosen
