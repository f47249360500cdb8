"""The spectral (force-coupling) Stokes mobility of blobs in periodic and confined boxes, on the CPU.

The method of Hashemi, Pelaez, Natesh, Sprinkle, Maxian, Gan and Donev (J. Chem. Phys. 158, 154101,
2023), as the DoublyPeriodicStokes CPU library discretises it, in four geometries: triply periodic (TP),
doubly periodic with z open (DP), above a bottom wall (DPBW) and in a slit between two walls (DPSC).

* :class:`SpectralParameters` (frozen): the grid and the kernels; :func:`dpstokes_parameters` makes it as
  DoublyPeriodicStokes does from a blob radius and a box.
* :class:`SpectralStokes`: ``set_positions(r (N, 3))``, ``product(F, T) -> (U, W)``.

Floor 1 of the house (imports numpy, scipy and ``utils`` only).  ``doc/spectral.md`` is the manual.
"""
from .parameters import (FORCE_ONLY_KERNELS, GEOMETRIES, TORQUE_KERNELS, KernelParameters, SpectralParameters,
                         dpstokes_parameters, nearest_smooth)
from .product import PATHS, SpectralStokes, compiled_available

__all__ = ['FORCE_ONLY_KERNELS', 'GEOMETRIES', 'TORQUE_KERNELS', 'KernelParameters', 'SpectralParameters',
           'dpstokes_parameters', 'nearest_smooth', 'PATHS', 'SpectralStokes', 'compiled_available']
