"""The text of ``mobility/cpp/pair_laws.h`` for CUDA kernels compiled at run time.

The CuPy kernels held as Python strings (``multi_bodies.solver.forces_pycuda``,
``many_bodyMCMC.mcmc_cuda``) prepend this text to their source, so that the
GPU uses the same minimum image and soft-repulsion laws as the C++ backends
(the header guards its host-only include with ``#ifndef __CUDACC__``).
No CuPy is needed to read it.
"""
import os

PAIR_LAWS_HEADER = os.path.join(os.path.dirname(os.path.abspath(__file__)), 'cpp', 'pair_laws.h')


def pair_laws_source():
    """The header's text (str), ending with a newline."""
    with open(PAIR_LAWS_HEADER) as f:
        text = f.read()
    return text if text.endswith('\n') else text + '\n'
