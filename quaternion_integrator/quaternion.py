"""The published import path of the quaternion code (``from quaternion_integrator.quaternion import Quaternion``).

The geometry lives on the ground floor, in :mod:`body.geometry`; this module
re-exports it for users' override files and drivers written for the
published package.  The package itself never imports this module.
"""
from body.geometry import (Quaternion, quaternion_products, quaternions_from_rotations,  # noqa: F401
                           rotate_quaternions, rotation_matrices)
