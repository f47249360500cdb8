"""Active slip of the pair of rods (this package's style: define functions with the hook names).

Every blob within 0.8 of a rod end (the rod length counts the blob radius at
both ends) has a slip of speed 20 along the rod axis, pointing to that end;
the blobs of the middle part are passive.  This is the extensile rod of
Balboa Usabiaga et al. (2016), section V.C.  The slip turns with the rod.

``set_slip_by_ID`` is called once per body when the bodies are created; it
gives the rods (structure ID ``rods``, the clones file name) a slip function
that receives the body with its current location and orientation at every
solve, so the slip could also depend on time, height, ...
"""
import numpy as np

SLIP_SPEED = 20.0         # speed of the slip along the axis
ACTIVE_LENGTH = 0.8       # length of the active part at each end


def extensile_rod_slip(body):
    """Lab-frame slip of the blobs of a straight rod along its body-frame x axis, shape (Nblobs, 3)."""
    along_axis = body.reference_configuration[:, 0]          # signed distance from the centre along the axis
    half_length = 0.5 * (np.ptp(along_axis) + 2.0 * body.blob_radius)
    active = np.abs(along_axis) > half_length - ACTIVE_LENGTH
    axis = body.orientation.rotation_matrix()[:, 0]
    return (SLIP_SPEED * np.where(active, np.sign(along_axis), 0.0))[:, None] * axis


def set_slip_by_ID(body, slip, **kwargs):
    """Rods get the active slip; other bodies keep the slip of their slip file (or none)."""
    if body.ID == 'rods':
        body.function_slip = extensile_rod_slip
    else:
        body.slip_reference = None if slip is None else np.asarray(slip, dtype=float).reshape(-1, 3)
