"""The published form of a spectral input: how the Spectral_Multiblob_Roller folder's own script reads its inputs.

The published code reaches the spectral product through one example folder only, ``Spectral_Multiblob_Roller``,
whose own copy of ``multi_bodies.py`` reads ``blob_radius`` differently from the manual (doc/periodic.md):

* ``blob_radius`` is the radius of the *particle* ``R``: every vertex file is multiplied by it, and the blob
  radius of the hydrodynamics is half the smallest blob distance of the scaled vertex file (``R`` itself for a
  one-blob structure);
* a body whose location is below ``R`` starts at ``1.01 R``; x and y of the locations are wrapped into
  ``[0, L]`` (the product wraps the blobs itself);
* the product is doubly periodic above the wall at z = 0, kernel ``w6`` (its kernel type 0, force only), heights
  0 to 9.1740639106166668 (the defaults of ``multi_bodies.solver.periodic``);
* the forces come from the folder's ``multi_bodies_functions.py`` (``multi_bodies.solver.user_hooks``), called
  with the keywords the folder's script passes: :func:`folder_script_keywords`.

``spectral_reading`` chooses: ``auto`` (default) is this form when the input names the spectral product over a
wall (``periodic_length Lx Ly 0``) and no other ``spectral_*`` option, so the folder's inputs run unchanged;
``published`` asks for it explicitly (then other ``spectral_*`` lines may choose the kernel or heights);
``package`` keeps the manual's reading (``blob_radius`` is the blob radius, the vertex file as written).

Floor 4 (``multi_bodies.solver``): no simulation state, only the reading rules.
"""
from dataclasses import dataclass

import numpy as np

from body.geometry import smallest_distance
from multi_bodies.files.scheme_table import moves_rollers, scheme_has
from multi_bodies.files.structure_files import read_vertex_file
from multi_bodies.solver.periodic import SPECTRAL, SPECTRAL_OPTIONS
from utils import UserInputError

PUBLISHED = 'published'
PACKAGE = 'package'
# A body that starts below the particle radius is raised to this many particle radii (the folder's script).
RAISED_HEIGHT = 1.01
# The frequency (Hz) the folder's multi_bodies.py passes to its force module as the keyword f (hard-coded there;
# its bodies_external_force_torque turns it into the torque 2 pi f 8 pi eta R^3 about y).
FOLDER_SCRIPT_FREQUENCY = 9.0
# The relative difference of two structures' derived blob radii that counts as one radius (one kernel width).
SAME_RADIUS = 1e-12


def reading_kind(options):
    """How a validated input is read: 'published', 'package', or None without the spectral product.

    ``spectral_reading auto`` is 'published' when the input gives ``periodic_length Lx Ly 0`` (the folder's box
    above the wall) and no other ``spectral_*`` option, else 'package'."""
    if options.mobility_vector_prod_implementation != SPECTRAL:
        return None
    if options.spectral_reading != 'auto':
        return options.spectral_reading
    others = [name for name in SPECTRAL_OPTIONS if name != 'spectral_reading' and options.is_set(name)]
    return PACKAGE if others or options.periodic_length[2] > 0 else PUBLISHED


@dataclass(frozen=True)
class PublishedReading:
    """The published reading of one input.

    particle_radius : the input's ``blob_radius`` ``R`` (length): the vertex files are multiplied by it.
    blob_radius : the blob radius of the hydrodynamics ``a`` (length): half the smallest blob distance of the
        scaled vertex files (``R`` when every structure has one blob).
    structures : ((vertex file, number of blobs, a of that file), ...) in the order of the input's lines.
    """
    particle_radius: float
    blob_radius: float
    structures: tuple

    @property
    def vertex_scale(self):
        """The factor of every vertex file (the particle radius)."""
        return self.particle_radius

    def log_line(self):
        """The set-up line saying that the published reading is used and what it did to the input."""
        files = ', '.join('%s (%d blobs)' % (name, n) for name, n, _ in self.structures)
        return ('spectral_reading published (the Spectral_Multiblob_Roller folder\'s script; doc/periodic.md): '
                'blob_radius %.10g is the particle radius, the vertex files %s are multiplied by it, blob radius '
                '%.10g (half the smallest blob distance); spectral_reading package reads blob_radius as the blob '
                'radius' % (self.particle_radius, files, self.blob_radius))


def published_options(options):
    """``(options, reading)``: the options the run uses and the :class:`PublishedReading`, or ``(options, None)``
    when the input is not in the published form.

    In the published form the returned options are a copy with ``blob_radius`` the derived blob radius ``a`` and
    ``particle_radius`` the input's ``blob_radius`` (the hooks' keyword ``particle_radius``); the input's own
    options are not changed.  Raises UserInputError (one line naming the line) for what the published form cannot
    read: another geometry than the folder's, articulated lines, a fourth column of radii, structures whose
    derived blob radii differ (the spectral kernel has one width), a ``particle_radius`` line that disagrees.
    """
    if reading_kind(options) != PUBLISHED:
        return options, None
    where = options.where
    fix = 'or add spectral_reading package to read the input as the manual says (doc/periodic.md)'
    if options.spectral_geometry not in ('auto', 'doubly_periodic_wall') or options.periodic_length[2] > 0:
        raise UserInputError('%s: spectral_reading published is the folder\'s box, doubly periodic above the wall '
                             '(periodic_length Lx Ly 0, spectral_geometry doubly_periodic_wall); use that box %s'
                             % (where('spectral_reading' if options.is_set('spectral_reading') else
                                      'mobility_vector_prod_implementation'), fix))
    if options.articulated:
        raise UserInputError('%s: an input in the published spectral form has no articulated bodies (the folder\'s '
                             'script reads structure lines only); %s' % (options.articulated[0].where, fix))
    particle_radius = float(options.blob_radius)
    if options.is_set('particle_radius') and options.particle_radius != particle_radius:
        raise UserInputError('%s: particle_radius %g, but in the published spectral form the particle radius is '
                             'blob_radius (%g); remove the line %s' % (where('particle_radius'),
                                                                      options.particle_radius, particle_radius, fix))
    structures = []
    for spec in list(options.structures) + list(options.obstacles):
        if any(name == spec.vertex_file for name, _, _ in structures):
            continue
        reference, radii = read_vertex_file(spec.vertex_file, spec.where, return_radii=True)
        if radii is not None:
            raise UserInputError('%s: %s gives blob radii (fourth column); in the published spectral form the blob '
                                 'radius is half the smallest blob distance of the scaled file; remove the column %s'
                                 % (spec.where, spec.vertex_file, fix))
        scaled = reference * particle_radius
        a = 0.5 * smallest_distance(scaled) if len(scaled) > 1 else particle_radius
        structures.append((spec.vertex_file, len(scaled), a))
    if not structures:
        return options, None  # no structure line: the set-up refuses the input in its own words
    radii = [a for _, _, a in structures]
    if max(radii) - min(radii) > SAME_RADIUS * max(radii):
        first, other = structures[int(np.argmin(radii))], structures[int(np.argmax(radii))]
        raise UserInputError('%s: in the published spectral form each vertex file gets half its smallest blob '
                             'distance as blob radius, %s %.10g and %s %.10g, but the spectral kernel has one width; '
                             'use vertex files of one blob spacing %s' % (where('blob_radius'), first[0], first[2],
                                                                         other[0], other[2], fix))
    reading = PublishedReading(particle_radius, radii[0], tuple(structures))
    return options.replace(blob_radius=reading.blob_radius, particle_radius=particle_radius), reading


def wrap_into_box(x, period):
    """``x`` moved by whole periods into ``[0, period]`` as the folder's script moves it (a coordinate below 0 is
    raised, one above ``period`` lowered, one inside left as it is)."""
    if x < 0.0:
        x += np.ceil(-x / period) * period
        while x < 0.0:  # round-off of the product above
            x += period
    elif x > period:
        x -= np.floor(x / period) * period
        if x == 0.0:  # the folder's loop stops at the period itself
            x = period
        while x > period:
            x -= period
    return x


def apply_start_rules(bodies, reading, periodic_length):
    """The folder's rules for the start of a run, applied to the ``Body`` objects in place.

    A body whose location is below the particle radius starts at ``RAISED_HEIGHT`` particle radii; x and y of every
    location are wrapped into ``[0, L]`` (:func:`wrap_into_box`).  Returns (bodies raised, bodies wrapped)."""
    particle_radius = reading.particle_radius
    raised = wrapped = 0
    for body in bodies:
        location = body.location
        if location[2] < particle_radius:
            location[2] = RAISED_HEIGHT * particle_radius
            raised += 1
        moved = False
        for axis in (0, 1):
            period = float(periodic_length[axis])
            if period <= 0:  # not periodic along this axis (the spectral product refuses such a box)
                continue
            new = wrap_into_box(float(location[axis]), period)
            moved |= new != location[axis]
            location[axis] = new
        wrapped += moved
    return raised, wrapped


def folder_script_keywords(options):
    """The keywords the folder's ``multi_bodies.py`` passes to its ``force_torque_calculator_sort_by_bodies``.

    ``options``: the run's options (:func:`published_options`: ``particle_radius`` is the input's
    ``blob_radius``).  ``g``, ``f`` (``FOLDER_SCRIPT_FREQUENCY``, hard-coded by that script), ``eta``,
    ``particle_radius``, the wall and body repulsion parameters and ``periodic_length`` (3,)."""
    return dict(g=options.g, f=FOLDER_SCRIPT_FREQUENCY, eta=options.eta, particle_radius=options.particle_radius,
                repulsion_strength_wall=options.repulsion_strength_wall, debye_length_wall=options.debye_length_wall,
                repulsion_strength=options.repulsion_strength, debye_length=options.debye_length,
                periodic_length=np.array(options.periodic_length, dtype=float))


def folder_module_call(options, script):
    """How the folder's script calls its ``multi_bodies_functions.py`` (``user_hooks.FolderModuleCall``) for a run of
    ``options`` (:func:`published_options`), or None where a folder module is not read: the static problems, the
    roller and articulated schemes (the folder's script is a copy of ``multi_bodies.py`` that moves rigid bodies).
    """
    from multi_bodies.solver.user_hooks import FolderModuleCall
    scheme = options.scheme
    if script != 'dynamics' or moves_rollers(scheme) or scheme_has(scheme, 'articulated'):
        return None
    return FolderModuleCall(folder_script_keywords(options), options.blob_blob_force_implementation,
                            options.body_body_force_torque_implementation)
