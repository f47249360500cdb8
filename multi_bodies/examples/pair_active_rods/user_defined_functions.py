"""Active slip of the pair of rods: set_slip_by_ID gives each body a slip function.

The slip of a rod blob has speed 20 along the rod axis and points away from
the nearest end of the rod (the published example's "-20 towards the nearest
end"); it turns with the rod.  The function receives the body with its
current location and orientation, so it could also depend on time, height, ...
"""
import numpy as np

SLIP_SPEED = -20.0


def active_rod_slip(body):
    """Lab-frame slip of every blob of ``body``, shape (n, 3)."""
    towards_nearest_end = np.sign(body.reference_configuration[:, 0])[:, None] * np.array([1.0, 0.0, 0.0])
    return (SLIP_SPEED * towards_nearest_end) @ body.rotation_matrix().T


def set_slip_by_ID(body, slip, **kwargs):
    """Rods (structure ID 'rods') get the active slip; other bodies keep a slip file's slip, or none."""
    if body.ID == 'rods':
        body.function_slip = active_rod_slip
    else:
        body.slip_reference = None if slip is None else np.asarray(slip, dtype=float).reshape(-1, 3)
