"""Registry of mobility backends, keyed by the manual's implementation names.

``python``, ``C++`` and ``pycuda`` select the NumPy, C++ (OpenMP) and CUDA
(CuPy) backends; the suffix ``_no_wall`` selects the free-space RPY tensor
instead of the Rotne-Prager-Blake tensor.  ``numba`` and ``numba_no_wall``
(names of the later published code) are aliases of the C++ backend
(SPEC.md decision 9).  ``pycuda`` is the manual's name for the GPU backend;
ours runs through CuPy, not PyCUDA.

Backends are imported on first use.  An unknown name, or a backend that
cannot run here (extension not built, no CuPy, no GPU), raises
``utils.UserInputError`` naming the available implementations.
"""
import importlib

from utils import UserInputError

from .product_names import PRODUCT_KINDS as _PRODUCT_KINDS

_BACKEND_MODULES = {'python': 'mobility.python_backend',
                    'C++': 'mobility.cpp_backend',
                    'pycuda': 'mobility.cuda_backend'}
_ALIASES = {'numba': 'C++'}
_loaded = {}
_failures = {}


def split_implementation_name(name):
    """Return ``(backend, wall)`` for an implementation name such as ``C++_no_wall``."""
    if not isinstance(name, str):
        raise UserInputError('mobility implementation must be a name such as python or C++_no_wall, got %r' % (name,))
    base, wall = (name[:-len('_no_wall')], False) if name.endswith('_no_wall') else (name, True)
    base = _ALIASES.get(base, base)
    if base not in _BACKEND_MODULES:
        raise UserInputError('unknown mobility implementation %r; known names: %s' % (name, ', '.join(all_names())))
    return base, wall


def all_names():
    """Every implementation name the registry accepts (aliases included)."""
    names = []
    for base in list(_BACKEND_MODULES) + list(_ALIASES):
        names += [base, base + '_no_wall']
    return names


def load_backend(backend):
    """Import and return the module of ``backend`` ('python', 'C++' or 'pycuda')."""
    if backend in _loaded:
        return _loaded[backend]
    if backend not in _failures:
        try:
            module = importlib.import_module(_BACKEND_MODULES[backend])
            if hasattr(module, 'check_usable'):
                module.check_usable()
            _loaded[backend] = module
            return module
        except Exception as err:  # ImportError, CUDA driver errors, ...
            _failures[backend] = '%s: %s' % (type(err).__name__, err)
    raise UserInputError('mobility implementation %r cannot run on this machine (%s); usable here: %s'
                         % (backend, _failures[backend], ', '.join(usable_names()) or 'none'))


def is_usable(backend):
    """True when ``backend`` imports and runs here."""
    try:
        load_backend(backend)
        return True
    except UserInputError:
        return False


def usable_names():
    """Implementation names (with and without _no_wall) that can run on this machine."""
    names = []
    for backend in _BACKEND_MODULES:
        if backend in _loaded or (backend not in _failures and is_usable(backend)):
            names += [backend, backend + '_no_wall']
    return names


def available_implementations():
    """Dict backend -> 'usable' or the reason it cannot run here."""
    return {b: ('usable' if is_usable(b) else _failures.get(b, 'unknown failure')) for b in _BACKEND_MODULES}


def _product(name, kind):
    backend, wall = split_implementation_name(name)
    module = load_backend(backend)
    return getattr(module, '%s_mobility_%s' % ('single_wall' if wall else 'no_wall', kind))


def mobility_vector_product(name, precision='double'):
    """Return ``f(r_vectors (N,3), force (3N,), eta, a, periodic_length=(0,0,0)) -> (3N,)`` for ``name``.

    ``precision='single'`` (C++ and pycuda only) evaluates the pair formulas in
    single precision, with positions subtracted and sums kept in double:
    faster, with relative errors near 1e-6 instead of 1e-15.
    """
    product = _product(name, 'trans_times_force')
    if precision == 'double':
        return product
    backend, _ = split_implementation_name(name)
    if precision != 'single':
        raise UserInputError("precision must be 'double' or 'single', got %r" % (precision,))
    if backend == 'python':
        raise UserInputError('single precision is offered by the compiled backends (C++, pycuda), not by %r' % name)

    def single_precision_product(r_vectors, force, eta, a, periodic_length=(0, 0, 0)):
        return product(r_vectors, force, eta, a, periodic_length, precision='single')
    single_precision_product.__name__ = product.__name__ + '_single'
    single_precision_product.__doc__ = product.__doc__ + ' Single-precision pair formulas.'
    return single_precision_product


def blob_product(name, kind):
    """Return the roller coupling ``kind`` (one of trans_times_force, trans_times_torque,
    rot_times_force, rot_times_torque) of implementation ``name``; same signature as
    :func:`mobility_vector_product`."""
    if kind not in _PRODUCT_KINDS:
        raise UserInputError('unknown blob product %r; known: %s' % (kind, ', '.join(_PRODUCT_KINDS)))
    return _product(name, kind)


def blob_mobility_matrix(name):
    """Return ``f(r_vectors (N,3), eta, a, periodic_length=(0,0,0)) -> (3N, 3N)`` for ``name``.

    The function also takes a stack of bodies ``(nb, n, 3)`` and returns their
    blocks ``(nb, 3n, 3n)`` (each body alone; used by the preconditioner).

    Dense matrices are built by the CPU backends only (manual option
    ``mobility_blobs_implementation``: python, C++, and their _no_wall forms).
    """
    backend, wall = split_implementation_name(name)
    if backend == 'pycuda':
        raise UserInputError('mobility_blobs_implementation %r: dense blob matrices are built on the CPU; '
                             'use python, C++, python_no_wall or C++_no_wall' % name)
    module = load_backend(backend)
    return module.single_wall_fluid_mobility if wall else module.rotne_prager_tensor


def source_target_product(name):
    """Return ``f(source (Ns,3), target (Nt,3), force (3Ns,), radius_source, radius_target, eta,
    periodic_length=(0,0,0)) -> (3Nt,)`` (velocity at targets) for ``name``."""
    backend, wall = split_implementation_name(name)
    module = load_backend(backend)
    return module.single_wall_mobility_source_target if wall else module.no_wall_mobility_source_target
