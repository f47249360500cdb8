"""The minimum image (re-exported from the ground floor, ``body.geometry``) and the wall regularisation.

One Python source of each formula (the compiled backends use their twin in
``mobility/cpp/pair_laws.h``):

* :func:`minimum_image` (and its one-axis form :func:`wrap_axis`), defined in
  :mod:`body.geometry`; ``multi_bodies.solver.physics`` re-exports it too.
* :func:`wall_regularisation`, defined in :mod:`mobility.pair_formulas`:
  blobs closer to the wall than their radius are raised to ``z_eff = radius``
  and damped by ``z / radius`` (Balboa, Delmotte and Donev 2017); works on
  NumPy or CuPy arrays (``xp``).
"""
from body.geometry import minimum_image, wrap_axis  # noqa: F401  (their one source: the ground floor)

from .pair_formulas import wall_regularisation  # noqa: F401  (its one source: beside the pair formulas it feeds)
