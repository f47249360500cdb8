"""Rigid bodies made of blobs: one ``Body`` and the stacked arrays of many.

Kinematics (SPEC section 3).  A body has a ``location`` (the origin of its
reference frame, about which torques and angular velocities are taken), an
``orientation`` quaternion ``q`` and the blob positions of its reference
configuration ``r_ref`` (shape (n, 3)).  Blob ``i`` sits at
``r_i = location + R(q) r_ref_i``.

The geometric matrix ``K`` of one body (shape (3n, 6)) maps the body velocity
``U = [v; w]`` to blob velocities ``v + w x (r_i - location)``; its transpose
sums blob forces ``lambda_i`` into ``[sum lambda_i; sum (r_i - location) x
lambda_i]``.

For many bodies, ``BodyArrays`` holds every body in contiguous arrays (bodies
in the order of the structure lines, blobs of a body next to each other) and
the module functions ``K_dot`` and ``KT_dot`` apply ``K`` and ``K^T`` to all
bodies at once with array operations, without a Python loop over bodies.

A body kind is fixed structure plus a configuration value: ``BodyArrays``
holds what never changes during a run (reference blobs, offsets, slip in the
body frame, blob radius), a :class:`Configuration` holds where the bodies
are (locations and quaternions, read-only).  Every method that depends on
where the bodies are (blob positions, K, K^T, lab-frame slip, the wall
check) takes the configuration as an argument, so two configurations can be
used side by side (a step's start and its predictor) without one overwriting
the other.  ``BodyArrays.configuration`` is the configuration the arrays were
built at (the input files), a convenience for set-up and viewers only.
"""
import numpy as np

try:  # the compiled K and K^T (body/cpp/rigid_module.cpp); NumPy below when it was not built
    from . import _rigid_cpp
except ImportError:  # pragma: no cover - a build without a C++ compiler
    _rigid_cpp = None

from body.geometry import Quaternion, rotation_matrices


class Body:
    """One rigid body.

    Parameters
    ----------
    location : array_like, shape (3,)
        Origin of the body frame in the lab frame.
    orientation : Quaternion or array_like, shape (4,)
        Scalar-first orientation quaternion.
    reference_configuration : array_like, shape (n, 3)
        Blob positions in the body frame (location 0, quaternion (1,0,0,0)).
    blob_radius : float
        Hydrodynamic radius ``a`` of the blobs (the input file's default).
    blobs_radius : array_like, shape (n,), or None
        Radius of each blob (the fourth column of a ``.vertex`` file; the
        published attribute name); None gives every blob ``blob_radius``.

    Attributes
    ----------
    ID : str
        Name of the structure type (from the ``.clones`` file name).
    slip_reference : ndarray, shape (n, 3) or None
        Active slip on each blob in the body frame (None means no slip).
    function_slip : callable ``f(body) -> (n, 3)``
        Lab-frame slip of the blobs (published attribute; ``calc_slip()``
        calls it).  The default, :func:`reference_slip_in_lab_frame`, turns
        ``slip_reference`` with the body; a user's ``set_slip_by_ID`` may set
        another function.
    body_length : float
        Largest distance between two reference blobs plus ``2a``; the length
        scale of random finite differences.  ``a`` is ``blob_radius`` even
        when the blobs have their own radii (the published definition).
    blobs_radius : ndarray, shape (n,)
        Radius of each blob; ``radii_given`` says whether a file gave them.

    The attributes that published override files read exist with the
    published meaning: ``location``, ``orientation`` (a Quaternion with
    ``rotation_matrix()``), ``Nblobs``, ``blob_radius``, ``ID``,
    ``reference_configuration``, ``function_slip``, ``get_r_vectors()``,
    ``calc_rot_matrix()``, ``calc_K_matrix()``, ``calc_slip()``.
    """

    def __init__(self, location, orientation, reference_configuration, blob_radius, blobs_radius=None):
        self.location = np.array(location, dtype=float).reshape(3)
        if not isinstance(orientation, Quaternion):
            orientation = Quaternion(orientation)
        self.orientation = orientation
        self.reference_configuration = np.array(reference_configuration, dtype=float).reshape(-1, 3)
        self.Nblobs = self.reference_configuration.shape[0]
        self.blob_radius = float(blob_radius)
        self.radii_given = blobs_radius is not None
        self.blobs_radius = (np.full(self.Nblobs, self.blob_radius) if blobs_radius is None
                             else np.array(blobs_radius, dtype=float).reshape(self.Nblobs))
        self.ID = None
        self.slip_reference = None
        self.function_slip = reference_slip_in_lab_frame
        self.body_length = None

    def rotation_matrix(self, orientation=None):
        """``R(q)``, shape (3, 3), of ``orientation`` (default: the body's)."""
        orientation = self.orientation if orientation is None else orientation
        return orientation.rotation_matrix()

    def get_r_vectors(self, location=None, orientation=None):
        """Blob positions in the lab frame, shape (n, 3).

        ``location`` and ``orientation`` default to the body's own; passing
        them gives the blobs of a displaced copy without changing the body.
        """
        location = self.location if location is None else np.asarray(location, dtype=float)
        rotation = self.rotation_matrix(orientation)
        return location + self.reference_configuration @ rotation.T

    def calc_rot_matrix(self, location=None, orientation=None):
        """The rotational block column of ``K``, shape (3n, 3) (published layout).

        Block ``i`` is ``-[d_i]_x`` with the lever arm ``d_i = r_i - location``,
        so that ``block_i w = w x d_i`` and ``block_i^T f = d_i x f`` (the
        torque of a blob force about the location).
        """
        return self.calc_K_matrix(location, orientation)[:, 3:]

    def calc_K_matrix(self, location=None, orientation=None):
        """Geometric matrix ``K``, shape (3n, 6): block row ``[I | -[r_i - location]_x]``."""
        location = self.location if location is None else np.asarray(location, dtype=float)
        r_vectors = self.get_r_vectors(location, orientation)
        return K_matrices(r_vectors[None, :, :], location[None, :])[0]

    def calc_body_length(self):
        """Largest distance between two reference blobs plus ``2a`` (``2a`` for one blob)."""
        self.body_length = reference_body_length(self.reference_configuration, self.blob_radius)
        return self.body_length

    def check_function(self, location=None, orientation=None):
        """True when the configuration is valid: no blob centre below the wall ``z = 0``."""
        return bool(np.all(self.get_r_vectors(location, orientation)[:, 2] >= 0.0))

    def calc_slip(self):
        """Active slip on the blobs in the lab frame, shape (n, 3): ``function_slip(self)`` (zeros without slip)."""
        return self.function_slip(self)


def reference_slip_in_lab_frame(body):
    """Default ``function_slip``: the body-frame ``slip_reference`` turned by ``R(q)``, shape (n, 3); zeros if None."""
    if body.slip_reference is None:
        return np.zeros((body.Nblobs, 3))
    return np.asarray(body.slip_reference, dtype=float).reshape(-1, 3) @ body.rotation_matrix().T


def _max_squared_distance(points, block_bytes=1 << 25):
    """Largest squared distance between two rows of ``points`` (m, 3), in blocks of rows: O(m) memory."""
    m = points.shape[0]
    rows = max(1, block_bytes // (24 * m))
    best = 0.0
    for start in range(0, m, rows):
        diff = points[start:start + rows, None, :] - points[None, :, :]
        best = max(best, float(np.max(np.einsum('ijk,ijk->ij', diff, diff))))
    return best


def reference_body_length(reference_configuration, blob_radius):
    """Largest pairwise distance of the reference blobs (shape (n, 3)) plus ``2 a`` (length units).

    The farthest pair lies on the convex hull, so for many blobs only the hull
    vertices are compared (scipy's ConvexHull, O(n log n)); each distance is
    computed as in the all-pairs formula, so the result is the same double.
    Flat or tiny sets fall back to all pairs, in blocks (O(n) memory).
    """
    ref = np.asarray(reference_configuration, dtype=float).reshape(-1, 3)
    if ref.shape[0] < 2:
        return 2.0 * blob_radius
    points = ref
    if ref.shape[0] > 64:
        try:
            from scipy.spatial import ConvexHull
            points = ref[np.unique(ConvexHull(ref).vertices)]
        except Exception:  # coplanar or collinear blobs (QhullError): every pair
            points = ref
    return float(np.sqrt(_max_squared_distance(points))) + 2.0 * blob_radius


class Configuration:
    """Where the bodies are: a value (read-only arrays, never changed after it is made).

    Parameters
    ----------
    locations : array_like, shape (Nb, 3)
        Body locations (tracking points), length units of the input.  For
        single-blob rollers, the blob positions.
    orientations : array_like, shape (Nb, 4)
        Scalar-first quaternions (not renormalised: SPEC section 3).

    The arrays are copied when the configuration is made and marked
    read-only, so a configuration handed to a solver stays what it was.
    """
    __slots__ = ('locations', 'orientations')

    def __init__(self, locations, orientations):
        locations = np.array(locations, dtype=float).reshape(-1, 3)
        orientations = np.array(orientations, dtype=float).reshape(-1, 4)
        if locations.shape[0] != orientations.shape[0]:
            raise ValueError('a configuration needs one quaternion per location, got %d locations and %d '
                             'quaternions' % (locations.shape[0], orientations.shape[0]))
        locations.setflags(write=False)
        orientations.setflags(write=False)
        object.__setattr__(self, 'locations', locations)
        object.__setattr__(self, 'orientations', orientations)

    def __setattr__(self, name, value):
        raise AttributeError('a Configuration is a value: make a new one instead of setting %s' % name)

    def __iter__(self):
        """``locations, orientations = configuration``."""
        return iter((self.locations, self.orientations))

    def __repr__(self):
        return 'Configuration(%d bodies)' % self.num_bodies

    @property
    def num_bodies(self):
        return self.locations.shape[0]

    def copy_arrays(self):
        """Writable copies (locations (Nb, 3), orientations (Nb, 4))."""
        return self.locations.copy(), self.orientations.copy()


def as_configuration(configuration_or_locations, orientations=None):
    """A :class:`Configuration` from one, or from ``(locations, orientations)`` arrays."""
    if isinstance(configuration_or_locations, Configuration):
        return configuration_or_locations
    if orientations is None:
        locations, orientations = configuration_or_locations
        return Configuration(locations, orientations)
    return Configuration(configuration_or_locations, orientations)


class BodyArrays:
    """All bodies of a problem as contiguous arrays.

    Bodies are grouped by structure type (one ``structure`` line of the input
    file), in input order; inside a type they follow the ``.clones`` file.
    All bodies of one type share their reference configuration.

    Attributes
    ----------
    configuration : Configuration
        Where the bodies were when the arrays were made (the input files).
    locations, orientations : (Nb, 3), (Nb, 4)
        Read-only views of ``configuration``.
    reference_blobs : ndarray, shape (N, 3)
        Body-frame position of every blob, blobs of body 0 first.
    blob_body_index : ndarray of int, shape (N,)
        Body that owns each blob.
    blob_offsets : ndarray of int, shape (Nb + 1,)
        Blobs of body ``k`` are ``blob_offsets[k]:blob_offsets[k+1]``.
    type_slices : list of (slice, slice)
        For each structure type, the slice of its bodies and of its blobs.
    type_blobs : list of int
        Blobs per body of each structure type.
    reference_slip : ndarray, shape (N, 3)
        Body-frame slip of every blob (zeros where no slip file was given): per type, or the
        ``reference_slip`` (N, 3) argument when given.
    blob_radius : float
        The input file's blob radius (the default of every blob).
    blob_radii : ndarray, shape (N,)
        Radius of every blob (``blob_radius`` where no vertex file gave radii).
    radii_given : bool
        True when some vertex file gave per-blob radii (then the products use ``blob_radii``).
    """

    def __init__(self, locations, orientations, reference_per_type, bodies_per_type,
                 blob_radius, reference_slip_per_type=None, radii_per_type=None, reference_slip=None):
        self.configuration = Configuration(locations, orientations)
        self.blob_radius = float(blob_radius)
        reference_per_type = [np.asarray(r, dtype=float).reshape(-1, 3) for r in reference_per_type]
        bodies_per_type = [int(n) for n in bodies_per_type]
        if sum(bodies_per_type) != self.configuration.num_bodies:
            raise ValueError('bodies_per_type does not add up to the number of locations')
        if reference_slip_per_type is None:
            reference_slip_per_type = [None] * len(reference_per_type)
        self.type_blobs = [r.shape[0] for r in reference_per_type]
        blobs_per_body = np.repeat(self.type_blobs, bodies_per_type)
        self.blob_offsets = np.concatenate(([0], np.cumsum(blobs_per_body))).astype(int)
        self.blob_body_index = np.repeat(np.arange(self.configuration.num_bodies), blobs_per_body)
        self.reference_blobs = np.concatenate(
            [np.tile(r, (n, 1)) for r, n in zip(reference_per_type, bodies_per_type)]) \
            if bodies_per_type else np.zeros((0, 3))
        slips = []
        for ref, slip, n in zip(reference_per_type, reference_slip_per_type, bodies_per_type):
            slip = np.zeros_like(ref) if slip is None else np.asarray(slip, dtype=float).reshape(-1, 3)
            slips.append(np.tile(slip, (n, 1)))
        self.reference_slip = np.concatenate(slips) if slips else np.zeros((0, 3))
        if reference_slip is not None:  # per body (bodies of one type with slips of their own)
            self.reference_slip = np.asarray(reference_slip, dtype=float).reshape(self.reference_blobs.shape)
        if radii_per_type is None:
            radii_per_type = [None] * len(reference_per_type)
        self.radii_given = any(radii is not None for radii in radii_per_type)
        radii = [np.tile(np.full(ref.shape[0], self.blob_radius) if rad is None
                         else np.asarray(rad, dtype=float).reshape(ref.shape[0]), n)
                 for ref, rad, n in zip(reference_per_type, radii_per_type, bodies_per_type)]
        self.blob_radii = np.concatenate(radii) if radii else np.zeros(0)
        self.type_slices = []
        body_start = 0
        for n_blobs, n_bodies in zip(self.type_blobs, bodies_per_type):
            blob_start = self.blob_offsets[body_start]
            self.type_slices.append((slice(body_start, body_start + n_bodies),
                                     slice(blob_start, blob_start + n_blobs * n_bodies)))
            body_start += n_bodies

    @property
    def num_bodies(self):
        return self.blob_offsets.shape[0] - 1

    @property
    def num_blobs(self):
        return self.reference_blobs.shape[0]

    @property
    def locations(self):
        """Locations (Nb, 3) of ``configuration`` (read-only)."""
        return self.configuration.locations

    @property
    def orientations(self):
        """Quaternions (Nb, 4) of ``configuration`` (read-only)."""
        return self.configuration.orientations

    def rotation_matrices(self, configuration):
        """``R(q_k)`` of every body, shape (Nb, 3, 3)."""
        return rotation_matrices(configuration.orientations)

    def blob_positions(self, configuration):
        """Lab-frame positions of all blobs at ``configuration``, shape (N, 3)."""
        return blob_positions(configuration.locations, configuration.orientations, self.reference_blobs,
                              self.blob_body_index)

    def lab_frame_slip(self, configuration):
        """Reference slip rotated into the lab frame at ``configuration``, shape (N, 3)."""
        rot = self.rotation_matrices(configuration)[self.blob_body_index]
        return np.einsum('nij,nj->ni', rot, self.reference_slip)

    def K_dot(self, configuration, body_velocities, r_vectors=None):
        """``K U`` at ``configuration``: blob velocities, shape (N, 3); see ``K_dot``.

        ``r_vectors`` (N, 3): the blob positions of that configuration when the caller has them.
        """
        r_vectors = self.blob_positions(configuration) if r_vectors is None else r_vectors
        return K_dot(r_vectors, configuration.locations, self.blob_body_index, body_velocities)

    def KT_dot(self, configuration, blob_forces, r_vectors=None):
        """``K^T lambda`` at ``configuration``, shape (Nb, 6); see ``KT_dot``.

        ``r_vectors`` (N, 3): the blob positions of that configuration when the caller has them.
        """
        r_vectors = self.blob_positions(configuration) if r_vectors is None else r_vectors
        return KT_dot(r_vectors, configuration.locations, self.blob_offsets, self.blob_body_index, blob_forces)

    def K_dense(self, configuration, r_vectors=None):
        """Dense block-diagonal ``K`` at ``configuration``, shape (3N, 6 Nb)."""
        r_vectors = self.blob_positions(configuration) if r_vectors is None else r_vectors
        return K_dense(r_vectors, configuration.locations, self.blob_body_index)

    def check_positions(self, r_vectors):
        """Indices of the bodies with a blob centre below the wall (empty when valid); r_vectors (N, 3)."""
        return np.unique(self.blob_body_index[np.asarray(r_vectors)[:, 2] < 0.0])


def blob_positions(locations, orientations, reference_blobs, blob_body_index):
    """Lab-frame blob positions of many bodies.

    Parameters
    ----------
    locations : ndarray, shape (Nb, 3)
    orientations : ndarray, shape (Nb, 4)
    reference_blobs : ndarray, shape (N, 3)
        Body-frame position of each blob.
    blob_body_index : ndarray of int, shape (N,)

    Returns
    -------
    ndarray, shape (N, 3): ``location_k + R(q_k) r_ref_i`` for the body ``k`` of blob ``i``.
    """
    rot = rotation_matrices(orientations)[blob_body_index]
    return np.asarray(locations)[blob_body_index] + np.einsum('nij,nj->ni', rot, reference_blobs)


def K_dot(r_vectors, locations, blob_body_index, body_velocities):
    """Apply the block-diagonal ``K`` of all bodies to their velocities.

    Parameters
    ----------
    r_vectors : ndarray, shape (N, 3)
        Blob positions.
    locations : ndarray, shape (Nb, 3)
        Body locations (tracking points).
    blob_body_index : ndarray of int, shape (N,)
    body_velocities : ndarray, shape (Nb, 6) or (6 Nb,)
        ``[v_x v_y v_z w_x w_y w_z]`` per body.

    Returns
    -------
    ndarray, shape (N, 3): ``v_k + w_k x (r_i - location_k)`` for every blob.
    The compiled kernel (``body/cpp/rigid_module.cpp``) when it is built, else NumPy.
    """
    if _rigid_cpp is not None:
        return _rigid_cpp.K_dot(r_vectors, locations, blob_body_index, body_velocities)
    return K_dot_numpy(r_vectors, locations, blob_body_index, body_velocities)


def K_dot_numpy(r_vectors, locations, blob_body_index, body_velocities):
    """:func:`K_dot` in NumPy (the fallback without the compiled module, and its test)."""
    velocities = np.asarray(body_velocities, dtype=float).reshape(-1, 6)[blob_body_index]
    arms = np.asarray(r_vectors, dtype=float).reshape(-1, 3) - np.asarray(locations, dtype=float)[blob_body_index]
    return velocities[:, :3] + _cross(velocities[:, 3:], arms)


def KT_dot(r_vectors, locations, blob_offsets, blob_body_index, blob_forces):
    """Apply ``K^T`` of all bodies: sum blob forces into body forces and torques.

    Parameters
    ----------
    r_vectors : ndarray, shape (N, 3)
    locations : ndarray, shape (Nb, 3)
    blob_offsets : ndarray of int, shape (Nb + 1,)
        Blobs of body ``k`` are ``blob_offsets[k]:blob_offsets[k+1]`` (every
        body has at least one blob).
    blob_body_index : ndarray of int, shape (N,)
    blob_forces : ndarray, shape (N, 3) or (3N,)

    Returns
    -------
    ndarray, shape (Nb, 6): ``[sum_i f_i, sum_i (r_i - location_k) x f_i]`` per body.
    The compiled kernel (``body/cpp/rigid_module.cpp``) when it is built, else NumPy.
    """
    if _rigid_cpp is not None:
        return _rigid_cpp.KT_dot(r_vectors, locations, blob_body_index, blob_forces)
    return KT_dot_numpy(r_vectors, locations, blob_offsets, blob_body_index, blob_forces)


def KT_dot_numpy(r_vectors, locations, blob_offsets, blob_body_index, blob_forces):
    """:func:`KT_dot` in NumPy (the fallback without the compiled module, and its test)."""
    forces = np.asarray(blob_forces, dtype=float).reshape(-1, 3)
    arms = np.asarray(r_vectors, dtype=float).reshape(-1, 3) - np.asarray(locations, dtype=float)[blob_body_index]
    per_blob = np.empty((forces.shape[0], 6))
    per_blob[:, :3] = forces
    per_blob[:, 3:] = _cross(arms, forces)
    return np.add.reduceat(per_blob, np.asarray(blob_offsets)[:-1], axis=0)


def saddle_point_product(r_vectors, locations, blob_offsets, blob_body_index, M_lambda, lambda_blobs,
                         body_velocities):
    """The rigid part of the saddle-point product: ``[M lambda - K U; -K^T lambda]`` (3N + 6 Nb,).

    M_lambda, lambda_blobs : (3N,) (``M lambda`` computed by the caller); body_velocities : (6 Nb,).
    One compiled call when ``body/cpp/rigid_module.cpp`` is built, else :func:`K_dot` and :func:`KT_dot`.
    """
    if _rigid_cpp is not None:
        return _rigid_cpp.saddle_point_product(r_vectors, locations, blob_body_index, M_lambda, lambda_blobs,
                                               body_velocities)
    slip_part = np.asarray(M_lambda, dtype=float).reshape(-1) - K_dot_numpy(
        r_vectors, locations, blob_body_index, body_velocities).reshape(-1)
    force_part = -KT_dot_numpy(r_vectors, locations, blob_offsets, blob_body_index, lambda_blobs).reshape(-1)
    return np.concatenate((slip_part, force_part))


def _cross(a, b):
    """Row-wise ``a x b`` of two (n, 3) arrays (``np.cross`` without its axis handling, 2-3x faster here)."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[:, 0] = a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1]
    out[:, 1] = a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2]
    out[:, 2] = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    return out


def K_blocks(arms):
    """Blocks ``[I | -[d]_x]`` of ``K`` for lever arms ``d`` (shape (..., 3)); returns shape (..., 3, 6)."""
    arms = np.asarray(arms, dtype=float)
    K = np.zeros(arms.shape[:-1] + (3, 6))
    K[..., 0, 0] = K[..., 1, 1] = K[..., 2, 2] = 1.0
    # w x d = -d x w: the block is minus the cross-product matrix of d.
    K[..., 0, 4] = arms[..., 2]
    K[..., 0, 5] = -arms[..., 1]
    K[..., 1, 3] = -arms[..., 2]
    K[..., 1, 5] = arms[..., 0]
    K[..., 2, 3] = arms[..., 1]
    K[..., 2, 4] = -arms[..., 0]
    return K


def K_matrices(r_vectors, locations):
    """Dense ``K`` of several bodies with the same number of blobs.

    Parameters
    ----------
    r_vectors : ndarray, shape (nb, n, 3)
        Blob positions of each body.
    locations : ndarray, shape (nb, 3)

    Returns
    -------
    ndarray, shape (nb, 3n, 6): block row ``i`` is ``[I | -[r_i - location]_x]``.
    """
    r_vectors = np.asarray(r_vectors, dtype=float)
    nb, n, _ = r_vectors.shape
    arms = r_vectors - np.asarray(locations, dtype=float)[:, None, :]
    return K_blocks(arms).reshape(nb, 3 * n, 6)


def K_dense(r_vectors, locations, blob_body_index):
    """Global block-diagonal ``K`` of all bodies as a dense matrix, shape (3N, 6 Nb)."""
    r_vectors = np.asarray(r_vectors, dtype=float).reshape(-1, 3)
    locations = np.asarray(locations, dtype=float).reshape(-1, 3)
    n, nb = r_vectors.shape[0], locations.shape[0]
    blocks = K_blocks(r_vectors - locations[blob_body_index])
    K = np.zeros((n, 3, nb, 6))
    K[np.arange(n), :, blob_body_index, :] = blocks
    return K.reshape(3 * n, 6 * nb)


def bodies_to_arrays(bodies, types_of_bodies=None, per_body_slip=False):
    """Build ``BodyArrays`` from a list of ``Body`` objects.

    ``per_body_slip``: the reference slip of every body is its own ``slip_reference`` (zero where None),
    not its type's first body's.

    Bodies of one structure type must be consecutive and share the same
    reference configuration object (as the input readers create them).
    ``types_of_bodies`` (list of int per type) gives the number of bodies of
    each type; by default consecutive bodies with the same ``ID`` form a type.
    """
    if types_of_bodies is None:
        types_of_bodies = []
        previous = object()
        for b in bodies:
            if b.ID != previous or not types_of_bodies:
                types_of_bodies.append(0)
                previous = b.ID
            types_of_bodies[-1] += 1
    starts = np.concatenate(([0], np.cumsum(types_of_bodies)))[:-1].astype(int)
    references = [bodies[s].reference_configuration for s in starts]
    slips = [bodies[s].slip_reference for s in starts]
    radii = [bodies[s].blobs_radius if getattr(bodies[s], 'radii_given', False) else None for s in starts]
    reference_slip = None
    if per_body_slip and bodies:
        reference_slip = np.concatenate([np.zeros((b.Nblobs, 3)) if b.slip_reference is None
                                         else np.asarray(b.slip_reference, dtype=float).reshape(-1, 3)
                                         for b in bodies])
    return BodyArrays([b.location for b in bodies], [b.orientation.entries for b in bodies],
                      references, types_of_bodies, bodies[0].blob_radius if bodies else 1.0, slips, radii,
                      reference_slip=reference_slip)
