"""Which vector instruction set the compiled kernels run (the kernel path).

Every C++ extension holds its pair loops once per path (``scalar``, ``avx2``, ``avx512`` on x86-64;
``scalar``, ``neon``, ``sve`` on 64-bit ARM) and runs one, chosen when it is imported: the widest that the
build holds and the CPU reports, or the one the environment variable ``RMB_SIMD`` names (``auto`` or unset:
the widest).  A name the build or the CPU cannot run stops the import of the extensions with one line
naming ``RMB_SIMD`` and the paths that can run (the C++ backend is then reported unusable with that line).
``doc/performance.md`` says how the paths are built and how accurate their vector math is.

The run's ``.info`` records the path (:func:`describe`), and the benchmarks print it.
"""
import importlib
import os

PATH_NAMES = ('scalar', 'avx2', 'avx512', 'neon', 'sve')


def _extension():
    """The mobility extension, or the ImportError that stopped it (its message is the reason)."""
    try:
        return importlib.import_module(__package__ + '._mobility_cpp')
    except ImportError as err:
        return err


def kernel_path():
    """The path the kernels run (str), or None without a usable C++ extension."""
    module = _extension()
    if isinstance(module, ImportError) or not hasattr(module, 'simd_path'):
        return None
    return module.simd_path()


def kernel_paths():
    """The paths this build holds and this CPU runs, best first (list of str; empty without the extension)."""
    module = _extension()
    if isinstance(module, ImportError) or not hasattr(module, 'simd_paths'):
        return []
    return list(module.simd_paths())


def describe():
    """One line: the path in use, the paths this machine runs and RMB_SIMD, e.g.
    ``avx2 (this machine runs avx2, scalar; RMB_SIMD unset)``."""
    module = _extension()
    if isinstance(module, ImportError):
        return 'no C++ kernels (%s)' % str(module).splitlines()[0] if str(module) else 'no C++ kernels'
    if not hasattr(module, 'simd_path'):
        return 'unknown (the C++ extension predates the kernel paths)'
    asked = os.environ.get('RMB_SIMD')
    return '%s (this machine runs %s; RMB_SIMD %s)' % (module.simd_path(), ', '.join(module.simd_paths()),
                                                       'unset' if asked is None else '= ' + asked)
