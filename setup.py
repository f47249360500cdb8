"""Build script: compiles the C++ kernels with pybind11.

`pip install -e .` builds everything on a machine with a C++ compiler.
OpenMP is used when the compiler accepts -fopenmp; the build still succeeds
without it (the kernels then run on one thread).  The pair kernels are compiled
once for each vector instruction set (scalar, AVX2, AVX-512 on x86-64; NEON, SVE
on ARM: mobility/cpp/simd_targets.h) and the one the CPU runs is chosen at
import (mobility/cpp/simd_dispatch.h; RMB_SIMD forces one), so a build runs at
full speed on other processors.  RMB_NATIVE=1 adds -march=native (the rest of
the code then also uses every instruction of the building machine, and the
binary runs only on processors that have them).
The pair laws of all three extensions and of the CUDA kernels are in one
header, mobility/cpp/pair_laws.h (shipped as package data of ``mobility``).
"""
import os
import shutil
import subprocess
import sys
import tempfile

from setuptools import setup
from pybind11.setup_helpers import Pybind11Extension, build_ext


def compiler_accepts(flags):
    """True when the default C++ compiler builds a tiny program with `flags`."""
    cxx = os.environ.get('CXX') or shutil.which('c++') or shutil.which('g++')
    if cxx is None:
        return False
    with tempfile.TemporaryDirectory() as tmp:
        source = os.path.join(tmp, 'probe.cpp')
        with open(source, 'w') as f:
            f.write('#include <omp.h>\nint main() { return omp_get_max_threads() > 0 ? 0 : 1; }\n'
                    if '-fopenmp' in flags else 'int main() { return 0; }\n')
        result = subprocess.run([cxx, source, '-o', os.path.join(tmp, 'probe')] + flags,
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        return result.returncode == 0


compile_args = ['-O3', '-fno-math-errno', '-fno-trapping-math', '-ffp-contract=fast']
link_args = []
if sys.platform != 'win32':
    if os.environ.get('RMB_NATIVE', '0') == '1' and compiler_accepts(['-march=native']):
        compile_args.append('-march=native')
    if compiler_accepts(['-fopenmp']):
        compile_args.append('-fopenmp')
        link_args.append('-fopenmp')
    else:
        print('setup.py: the compiler does not accept -fopenmp; building the kernels single-threaded')

HEADERS = ['mobility/cpp/pair_laws.h', 'mobility/cpp/blob_pair_kernels.h', 'mobility/cpp/openmp_threads.h',
           'mobility/cpp/fast_exp.h', 'mobility/cpp/blob_arrays.h', 'mobility/cpp/dense_matrices.h',
           'mobility/cpp/blob_pair_formulas.inc', 'mobility/cpp/simd_dispatch.h', 'mobility/cpp/simd_targets.h',
           'mobility/cpp/simd_vector.inc', 'mobility/cpp/simd_tiles.inc', 'mobility/cpp/mobility_kernels.inc']


def extension(name, sources, include_dirs=(), depends=(), openmp=True, contract=True, extra_args=()):
    """One pybind11 extension with the package's flags.  Each gets its own copies of the flag lists (pybind11
    appends its own flags to the lists it is given; shared lists collected every extension's additions).
    openmp : False builds it serial; contract : False builds it without fused multiply-adds."""
    args = [arg for arg in compile_args if openmp or arg != '-fopenmp']
    if not contract:
        args = [arg for arg in args if not arg.startswith('-ffp-contract')] + ['-ffp-contract=off']
    return Pybind11Extension(name, list(sources), include_dirs=list(include_dirs), depends=list(depends),
                             extra_compile_args=args + list(extra_args),
                             extra_link_args=list(link_args) if openmp else [], cxx_std=17)


SOLVER_KERNELS = ['mobility/cpp', 'multi_bodies/solver/cpp']
extensions = [
    extension('mobility._mobility_cpp', ['mobility/cpp/mobility_module.cpp', 'mobility/cpp/dense_matrices.cpp'],
              ['mobility/cpp'], HEADERS),
    extension('multi_bodies.solver._forces_cpp', ['multi_bodies/solver/cpp/forces_module.cpp'], SOLVER_KERNELS,
              HEADERS + ['multi_bodies/solver/cpp/forces_kernels.inc']),
    extension('multi_bodies.solver._preconditioner_cpp', ['multi_bodies/solver/cpp/preconditioner_module.cpp'],
              SOLVER_KERNELS, HEADERS + ['multi_bodies/solver/cpp/near_field_kernels.inc']),
    extension('multi_bodies.solver._surface_cpp', ['multi_bodies/solver/cpp/surface_module.cpp'], SOLVER_KERNELS,
              HEADERS + ['multi_bodies/solver/cpp/surface_kernels.inc']),
    # serial (OpenMP did not pay); no fused multiply-adds, so the blocks equal the NumPy fallback's
    extension('lubrication._lubrication_cpp', ['lubrication/cpp/lubrication_module.cpp'], openmp=False,
              contract=False),
    # the sparse block LDL^T of the lubrication preconditioners (lubrication/sparse_factor.py); serial
    extension('lubrication._block_ldlt_cpp', ['lubrication/cpp/block_ldlt_module.cpp'], openmp=False),
    extension('body._rigid_cpp', ['body/cpp/rigid_module.cpp']),
    extension('many_bodyMCMC._energy_cpp', ['many_bodyMCMC/cpp/energy_module.cpp'], ['mobility/cpp',
              'many_bodyMCMC/cpp'], HEADERS + ['many_bodyMCMC/cpp/energy_kernels.inc']),
    # complex products and quotients inline (finite values only; no NaN recovery calls) where accepted
    extension('mobility._spectral_cpp', ['mobility/cpp/spectral_module.cpp'], ['mobility/cpp'],
              ['mobility/cpp/openmp_threads.h', 'mobility/cpp/spectral_spread.h', 'mobility/cpp/spectral_solve.h',
               'mobility/cpp/spectral_spread.inc', 'mobility/cpp/spectral_solve.inc',
               'mobility/cpp/spectral_kernels.inc'] + HEADERS,
              extra_args=['-fcx-limited-range'] if compiler_accepts(['-fcx-limited-range']) else []),
]

class parallel_build_ext(build_ext):
    """pybind11's build_ext that compiles the extensions side by side: ``RMB_BUILD_JOBS`` jobs (default: the number
    of CPUs), unless ``build_ext --parallel N`` (or ``-j N``) is given; ``RMB_BUILD_JOBS=1`` builds one at a time."""

    def finalize_options(self):
        super().finalize_options()
        if not self.parallel:
            self.parallel = max(1, int(os.environ.get('RMB_BUILD_JOBS') or os.cpu_count() or 1))


setup(
    packages=['body', 'mobility', 'mobility.spectral', 'multi_bodies', 'multi_bodies.solver', 'multi_bodies.files', 'multi_bodies.run',
              'multi_bodies.ensembles', 'multi_bodies.advice', 'multi_bodies.analysis', 'quaternion_integrator',
              'stochastic_forcing', 'many_bodyMCMC', 'boomerang', 'sphere', 'lubrication', 'read_input',
              'articulated', 'constraint', 'sksparse'],
    py_modules=['utils', 'general_application_utils', 'Lub_Solver'],
    package_data={'mobility': ['cpp/*.h', 'cpp/*.inc', 'cuda/*.cu'], 'lubrication': ['tables/*.txt', 'tables/README.md']},
    ext_modules=extensions,
    cmdclass={'build_ext': parallel_build_ext},
)
