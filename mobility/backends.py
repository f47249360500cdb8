"""Registry of mobility backends, keyed by the manual's implementation names.

``python``, ``C++`` and ``pycuda`` select the NumPy, C++ (OpenMP) and CUDA
(CuPy) backends; the suffix ``_no_wall`` selects the free-space RPY tensor
instead of the Rotne-Prager-Blake tensor, the suffix ``_free_surface`` the
mobility above a flat free-slip surface at z = 0 (the RPY tensor of the
blobs and of their mirror images).  ``numba`` and ``numba_no_wall``
(names of the later published code) are aliases of the C++ backend
(SPEC.md decision 9).  ``pycuda`` is the manual's name for the GPU backend;
ours runs through CuPy, not PyCUDA.

Blobs of different radii: every product takes the blob radius ``a`` as a
number or as one radius per blob (N,), and uses the formulas for unequal
spheres when the radii differ.  The published names ``radii_python``,
``radii_python_no_wall``, ``radii_numba``, ``radii_numba_no_wall``,
``radii_pycuda`` and ``radii_numba_free_surface`` are therefore aliases of
the plain names (``radii_numba`` = ``C++``, ...).

Backends are imported on first use.  An unknown name, or a backend that
cannot run here (extension not built, no CuPy, no GPU), raises
``utils.UserInputError`` naming the available implementations.
"""
import importlib
import importlib.util
import sys

from utils import UserInputError

from .product_names import PRODUCT_KINDS as _PRODUCT_KINDS

_BACKEND_MODULES = {'python': 'mobility.python_backend',
                    'C++': 'mobility.cpp_backend',
                    'pycuda': 'mobility.cuda_backend'}
# Third-party packages a backend module imports first: where one is not installed, the backend is refused with the
# error its import would raise, without running the module (asking whether the GPU backend runs on a machine
# without CuPy enters no file of it).
_REQUIRED_PACKAGES = {'pycuda': 'cupy'}
BACKEND_NAMES = tuple(_BACKEND_MODULES)  # the backends these names select (mobility.interface registers them)
_ALIASES = {'numba': 'C++'}
# domain suffix -> domain
DOMAIN_SUFFIXES = (('_no_wall', 'no_wall'), ('_free_surface', 'free_surface'), ('', 'single_wall'))
RADII_PREFIX = 'radii_'
# The published names with the word radii (manual section 6.1; README of examples/radii), all aliases.
RADII_NAMES = ('radii_python', 'radii_python_no_wall', 'radii_numba', 'radii_numba_no_wall', 'radii_pycuda',
               'radii_numba_free_surface')
_loaded = {}
_failures = {}


def split_domain(name):
    """Return ``(backend, domain)`` for an implementation name: domain 'single_wall', 'no_wall' or 'free_surface'.

    ``radii_`` names are the published aliases (``RADII_NAMES``).
    """
    if not isinstance(name, str):
        raise UserInputError('mobility implementation must be a name such as python or C++_no_wall, got %r' % (name,))
    known = name in all_names()
    stem = name[len(RADII_PREFIX):] if name.startswith(RADII_PREFIX) else name
    for suffix, domain in DOMAIN_SUFFIXES:
        if stem.endswith(suffix):
            base = stem[:len(stem) - len(suffix)]
            break
    base = _ALIASES.get(base, base)
    if not known or base not in _BACKEND_MODULES:
        raise UserInputError('unknown mobility implementation %r; known names: %s' % (name, ', '.join(all_names())))
    return base, domain


def split_implementation_name(name):
    """Return ``(backend, wall)`` for an implementation name such as ``C++_no_wall`` (wall: not free space)."""
    backend, domain = split_domain(name)
    return backend, domain != 'no_wall'


def all_names():
    """Every implementation name the registry accepts (aliases included)."""
    names = []
    for base in list(_BACKEND_MODULES) + list(_ALIASES):
        names += [base + suffix for suffix in ('', '_no_wall', '_free_surface')]
    return names + list(RADII_NAMES)


def _not_installed(package):
    """True when the top-level ``package`` is neither imported nor found on the path (its import would fail)."""
    if package in sys.modules:
        return False
    try:
        return importlib.util.find_spec(package) is None
    except (ImportError, ValueError):
        return False  # let the import itself say what is wrong


def load_backend(backend):
    """Import and return the module of ``backend`` ('python', 'C++' or 'pycuda')."""
    if backend in _loaded:
        return _loaded[backend]
    required = _REQUIRED_PACKAGES.get(backend)
    if backend not in _failures and required is not None and _not_installed(required):
        _failures[backend] = "ModuleNotFoundError: No module named '%s'" % required
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
    """Implementation names that run on this machine: every domain form (wall, ``_no_wall``, ``_free_surface``)
    that a backend which loads here provides, and the aliases (``numba``) of those backends."""
    names = []
    for base in list(_BACKEND_MODULES) + list(_ALIASES):
        backend = _ALIASES.get(base, base)
        if not (backend in _loaded or (backend not in _failures and is_usable(backend))):
            continue
        module = _loaded[backend]
        names += [base + suffix for suffix, domain in sorted(DOMAIN_SUFFIXES, key=lambda pair: len(pair[0]))
                  if hasattr(module, '%s_mobility_trans_times_force' % domain)]
    return names


def is_radii_name(name):
    """True for the published ``radii_*`` names (aliases that say the vertex files may give radii)."""
    return isinstance(name, str) and name.startswith(RADII_PREFIX)


def available_implementations():
    """Dict backend -> 'usable' or the reason it cannot run here."""
    return {b: ('usable' if is_usable(b) else _failures.get(b, 'unknown failure')) for b in _BACKEND_MODULES}


def _product(name, kind):
    backend, domain = split_domain(name)
    module = load_backend(backend)
    if domain == 'free_surface' and kind != 'trans_times_force':
        raise UserInputError('implementation %r: the free surface has the product M f only (no roller couplings '
                             '%s); use a wall or _no_wall implementation' % (name, kind))
    return getattr(module, '%s_mobility_%s' % (domain, kind))


def mobility_vector_product(name, precision='double'):
    """Return ``f(r_vectors (N,3), force (3N,), eta, a, periodic_length=(0,0,0)) -> (3N,)`` for ``name``.

    ``a`` may be one radius or one radius per blob (N,) (blobs of different radii).
    ``precision='single'`` (C++ and pycuda only, one radius) evaluates the pair formulas in
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
    backend, domain = split_domain(name)
    if backend == 'pycuda':
        raise UserInputError('mobility_blobs_implementation %r: dense blob matrices are built on the CPU; '
                             'use python, C++, python_no_wall or C++_no_wall (or their _free_surface forms)' % name)
    module = load_backend(backend)
    return {'single_wall': module.single_wall_fluid_mobility, 'no_wall': module.rotne_prager_tensor,
            'free_surface': module.free_surface_fluid_mobility}[domain]


def blob_cross_blocks(name):
    """``f(r_i (P, ni, 3), r_j (P, nj, 3), eta, a) -> (P, 3ni, 3nj)`` (or None where it cannot) for ``name``.

    The cross blocks of the dense blob mobility of pairs of bodies (the neighbour preconditioner's); only
    the compiled backend builds them (other backends return None: take them from the stacked matrices).
    """
    backend, domain = split_domain(name)
    if backend == 'pycuda':
        return None
    module = load_backend(backend)
    function = getattr(module, 'cross_blocks', None)
    if function is None:
        return None
    return lambda r_i, r_j, eta, a: function(r_i, r_j, eta, a, domain)


def compiled_near_field_domain(name):
    """The domain ('single_wall' or 'no_wall') of blobs backend ``name`` when it is the compiled backend, whose
    blob mobility the neighbour preconditioner's compiled near-field loop reproduces; None otherwise."""
    backend, domain = split_domain(name)
    return domain if backend == 'C++' and domain in ('single_wall', 'no_wall') else None


def source_target_product(name):
    """Return ``f(source (Ns,3), target (Nt,3), force (3Ns,), radius_source, radius_target, eta,
    periodic_length=(0,0,0)) -> (3Nt,)`` (velocity at targets) for ``name``."""
    backend, domain = split_domain(name)
    module = load_backend(backend)
    return getattr(module, '%s_mobility_source_target' % domain)
