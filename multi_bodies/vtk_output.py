"""VTK files of rigid multiblob runs for ParaView: one blob file and one body file per saved step.

Library floor (ARCHITECTURE.md floor 3).  Used by ``clones_to_vtk.py`` (to
convert the ``.clones`` series of a finished or stopped run) and by
``multi_bodies.py`` when the input says ``save_vtk True``.  Files, all
prefixed by ``output_name`` (see doc/visualisation.md):

* ``output_name.blobs.<step, 8 digits>.vtp``: PolyData with one vertex per
  blob at its lab-frame position, and point arrays ``radius`` (the blob
  radius ``a``, for true-size sphere glyphs), ``body_index`` (0-based, over
  all structures in input order), ``structure_index`` (0-based structure
  line), ``structure`` (the structure ID, a string), ``velocity``
  (``v + w x (r - location)``, only when body velocities are given) and
  ``slip`` (lab-frame active slip, only when some blob has one).
* ``output_name.bodies.<step, 8 digits>.vtp``: one vertex per body at its
  ``location``, with ``axis_1``, ``axis_2``, ``axis_3`` (the columns of the
  rotation matrix ``R(q)``: the body-frame axes in the lab frame),
  ``quaternion`` (scalar first), ``body_index``, ``structure_index``,
  ``structure``, and ``velocity``, ``angular_velocity`` when given.
* ``output_name.blobs.pvd`` and ``output_name.bodies.pvd``: the collections
  of those files with the simulation time of each step (``step * dt``; the
  step itself when ``dt`` is 0, as in Monte Carlo runs), which ParaView plays
  as an animation.

Coordinates are the simulation's own: the same length unit and origin (wall
at ``z = 0``) as the ``.clones`` files and the velocity-field ``.vtk`` of the
static script, so all of them open in one ParaView scene.

``load_run`` and ``run_configurations`` read a saved run back (bodies of the
input file, then every saved configuration) for ``clones_to_vtk.py`` and
``render.py``.

pyvista is imported only when a file is written.
"""
import os
import re

import numpy as np

import utils
from body.body import K_dot, bodies_to_arrays
from multi_bodies import multi_bodies_functions
from multi_bodies.run_setup import read_bodies
from multi_bodies.structure_files import read_body_table
from quaternion_integrator.quaternion import rotation_matrices

BLOBS = 'blobs'
BODIES = 'bodies'
_PVD_HEAD = '<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">\n  <Collection>\n'
_PVD_TAIL = '  </Collection>\n</VTKFile>\n'
_PVD_ENTRY = '    <DataSet timestep="%s" group="" part="0" file="%s"/>\n'


def require_pyvista(who):
    """Stop with one clear message when pyvista is missing (``who`` names the option or script that needs it)."""
    try:
        import pyvista  # noqa: F401
    except ImportError:
        from utils import UserInputError
        raise UserInputError('%s writes VTK files through pyvista, which is not installed; install it with '
                             '"python3 -m pip install pyvista"' % who)


def step_file_name(output_name, kind, step):
    """``output_name.<kind>.<step, 8 digits>.vtp``; ``kind`` is 'blobs' or 'bodies'."""
    return '%s.%s.%s.vtp' % (output_name, kind, str(step).zfill(8))


def collection_name(output_name, kind):
    """``output_name.<kind>.pvd``."""
    return '%s.%s.pvd' % (output_name, kind)


def step_time(step, dt):
    """Simulation time of a saved step: ``step * dt``, or ``step`` when ``dt`` is 0 (Monte Carlo)."""
    return step * dt if dt > 0 else float(step)


def periodic_shifts(locations, periodic_length):
    """Shifts (Nb, 3) that bring each body ``location`` into the primary box ``[0, L)`` of every periodic axis.

    Axes with ``L <= 0`` are not periodic and get no shift.  A whole body
    moves with its location: blobs are never cut across the box.
    """
    locations = np.asarray(locations, dtype=float).reshape(-1, 3)
    lengths = np.asarray(periodic_length, dtype=float).reshape(3)
    shifts = np.zeros_like(locations)
    periodic = lengths > 0
    if np.any(periodic):
        shifts[:, periodic] = -np.floor(locations[:, periodic] / lengths[periodic]) * lengths[periodic]
    return shifts


def _string_array(names, index):
    return np.asarray(names, dtype=str)[np.asarray(index, dtype=int)]


def blob_polydata(r_vectors, blob_radius, blob_body_index, blob_structure_index, structure_names,
                  blob_velocities=None, blob_slip=None):
    """PolyData of the blobs: one vertex per blob and the arrays of the module docstring.

    Parameters
    ----------
    r_vectors : (N, 3) lab-frame blob positions (length).
    blob_radius : float or (N,) blob radius ``a`` (length).
    blob_body_index : (N,) int, body of each blob.
    blob_structure_index : (N,) int, structure line of each blob.
    structure_names : list of str, the structure IDs.
    blob_velocities : (N, 3) or None, blob velocities (length/time).
    blob_slip : (N, 3) or None, lab-frame active slip (length/time).
    """
    import pyvista
    r_vectors = np.asarray(r_vectors, dtype=float).reshape(-1, 3)
    mesh = pyvista.PolyData(r_vectors.copy())
    mesh.point_data['radius'] = np.broadcast_to(np.asarray(blob_radius, dtype=float), (r_vectors.shape[0],)).copy()
    mesh.point_data['body_index'] = np.asarray(blob_body_index, dtype=np.int64)
    mesh.point_data['structure_index'] = np.asarray(blob_structure_index, dtype=np.int64)
    mesh.point_data['structure'] = _string_array(structure_names, blob_structure_index)
    if blob_velocities is not None:
        mesh.point_data['velocity'] = np.asarray(blob_velocities, dtype=float).reshape(-1, 3)
    if blob_slip is not None:
        mesh.point_data['slip'] = np.asarray(blob_slip, dtype=float).reshape(-1, 3)
    return mesh


def body_polydata(locations, orientations, body_structure_index, structure_names, body_velocities=None):
    """PolyData of the bodies: one vertex per body location and the arrays of the module docstring.

    Parameters
    ----------
    locations : (Nb, 3) body locations (length).
    orientations : (Nb, 4) scalar-first unit quaternions.
    body_structure_index : (Nb,) int, structure line of each body.
    structure_names : list of str.
    body_velocities : (Nb, 6) or None, ``[v, w]`` per body (length/time, radians/time).
    """
    import pyvista
    locations = np.asarray(locations, dtype=float).reshape(-1, 3)
    orientations = np.asarray(orientations, dtype=float).reshape(-1, 4)
    rotations = rotation_matrices(orientations)
    mesh = pyvista.PolyData(locations.copy())
    for axis in range(3):
        mesh.point_data['axis_%d' % (axis + 1)] = np.ascontiguousarray(rotations[:, :, axis])
    mesh.point_data['quaternion'] = orientations.copy()
    mesh.point_data['body_index'] = np.arange(locations.shape[0], dtype=np.int64)
    mesh.point_data['structure_index'] = np.asarray(body_structure_index, dtype=np.int64)
    mesh.point_data['structure'] = _string_array(structure_names, body_structure_index)
    if body_velocities is not None:
        body_velocities = np.asarray(body_velocities, dtype=float).reshape(-1, 6)
        mesh.point_data['velocity'] = body_velocities[:, :3].copy()
        mesh.point_data['angular_velocity'] = body_velocities[:, 3:].copy()
    return mesh


class PvdCollection:
    """A ``.pvd`` file that stays valid after every added step (a stopped run leaves a readable file).

    Each ``add`` writes one entry in place of the closing tags and writes them
    again after it, so adding costs the same at any length of the run.
    ``keep_before_step``: on opening an existing file, keep its entries of
    steps before this one (a restart) and drop the rest; None starts a new file.
    """

    def __init__(self, path, keep_before_step=None):
        self.path = path
        entries = []
        if keep_before_step is not None and os.path.isfile(path):
            with open(path, 'r') as f:
                for line in f:
                    found = re.search(r'timestep="([^"]*)".*file="([^"]*)"', line)
                    step = re.search(r'\.(\d{8,})\.vtp$', found.group(2)) if found else None
                    if step and int(step.group(1)) < keep_before_step:
                        entries.append(line)
        with open(path, 'w') as f:
            f.write(_PVD_HEAD + ''.join(entries) + _PVD_TAIL)

    def add(self, time, file_path):
        """Add the file ``file_path`` (stored relative to the ``.pvd``'s folder) at simulation ``time``."""
        relative = os.path.relpath(os.path.abspath(file_path), os.path.dirname(os.path.abspath(self.path)))
        with open(self.path, 'r+') as f:
            f.seek(0, os.SEEK_END)
            f.seek(f.tell() - len(_PVD_TAIL))
            f.write(_PVD_ENTRY % (repr(float(time)), relative.replace(os.sep, '/')) + _PVD_TAIL)
            f.truncate()


class VtkSeries:
    """Writes the blob and body files of saved steps of one run, and their two ``.pvd`` collections.

    Parameters
    ----------
    output_name : str, prefix of the files.
    structure_names : list of str, the structure IDs in input order.
    bodies_per_structure : list of int.
    dt : float, time step (0 for Monte Carlo: the time of a step is the step).
    periodic_length : (3,) floats; with ``wrap_periodic`` the bodies are drawn in the primary box.
    wrap_periodic : bool, shift each body (all its blobs) into ``[0, L)`` along the periodic axes.
    first_step : int; entries of existing ``.pvd`` files before this step are kept (restarts).
    """

    def __init__(self, output_name, structure_names, bodies_per_structure, dt, periodic_length=(0.0, 0.0, 0.0),
                 wrap_periodic=False, first_step=0):
        self.output_name = output_name
        self.structure_names = [str(name) for name in structure_names]
        self.body_structure_index = np.repeat(np.arange(len(bodies_per_structure)), bodies_per_structure)
        self.dt = float(dt)
        self.periodic_length = np.asarray(periodic_length, dtype=float).reshape(3)
        self.wrap_periodic = bool(wrap_periodic) and bool(np.any(self.periodic_length > 0))
        keep = first_step if first_step > 0 else None
        self.collections = {kind: PvdCollection(collection_name(output_name, kind), keep) for kind in (BLOBS, BODIES)}

    def write(self, step, body_arrays, body_velocities=None, blob_slip=None):
        """Write the files of ``step`` from the configuration in ``body_arrays`` (a ``BodyArrays``).

        ``body_velocities``: (Nb, 6) or None.  ``blob_slip``: (N, 3) lab-frame
        slip or None; by default the slip of the slip files, rotated with the
        bodies, when any blob has one.  Returns the two paths written.
        """
        locations, orientations = body_arrays.locations, body_arrays.orientations
        r_vectors = body_arrays.blob_positions()
        blob_velocities = None
        if body_velocities is not None:
            body_velocities = np.asarray(body_velocities, dtype=float).reshape(-1, 6)
            blob_velocities = K_dot(r_vectors, locations, body_arrays.blob_body_index, body_velocities)
        if blob_slip is None and np.any(body_arrays.reference_slip):
            blob_slip = body_arrays.lab_frame_slip()
        if self.wrap_periodic:
            shifts = periodic_shifts(locations, self.periodic_length)
            locations = locations + shifts
            r_vectors = r_vectors + shifts[body_arrays.blob_body_index]
        blob_index = body_arrays.blob_body_index
        blobs = blob_polydata(r_vectors, body_arrays.blob_radius, blob_index, self.body_structure_index[blob_index],
                              self.structure_names, blob_velocities, blob_slip)
        bodies = body_polydata(locations, orientations, self.body_structure_index, self.structure_names,
                               body_velocities)
        time = step_time(step, self.dt)
        paths = []
        for kind, mesh in ((BLOBS, blobs), (BODIES, bodies)):
            path = step_file_name(self.output_name, kind, step)
            mesh.save(path)
            self.collections[kind].add(time, path)
            paths.append(path)
        return paths


class AlsoWriteVtk:
    """Wraps the snapshot writer of a running script: each ``save(step)`` also writes the VTK files.

    ``snapshot_writer``: any object with ``save(step)``; ``system``: the
    running system, whose ``arrays`` (a ``BodyArrays``) hold the configuration
    at the time of the save; ``types``: list of (structure ID, bodies).
    """

    def __init__(self, snapshot_writer, options, types, system):
        require_pyvista('%s: save_vtk True' % options.where('save_vtk'))
        self.snapshot_writer, self.system = snapshot_writer, system
        self.series = VtkSeries(options.output_name, [name for name, _ in types], [count for _, count in types],
                                options.dt, options.periodic_length, wrap_periodic=False,
                                first_step=options.initial_step)

    def save(self, step):
        self.snapshot_writer.save(step)
        self.series.write(step, self.system.arrays)

    def __getattr__(self, name):
        if name in ('snapshot_writer', 'system', 'series'):
            raise AttributeError(name)
        return getattr(self.snapshot_writer, name)


# ------------------------------------------------------------------ a saved run, read back (clones_to_vtk.py, render.py)
STATIC_SCHEMES = ('body_mobility', 'mobility', 'resistance')


def load_run(options):
    """Bodies of the input file: (BodyArrays with the slip of the slip files and hooks, types)."""
    hooks = multi_bodies_functions.load_user_hooks(os.getcwd(), load_pycuda=False)
    bodies, types = read_bodies(options, hooks.set_slip_by_ID)
    body_arrays = bodies_to_arrays(bodies, [count for _, count in types])
    slips = [np.zeros((b.Nblobs, 3)) if b.slip_reference is None else b.slip_reference for b in bodies]
    body_arrays.reference_slip = np.concatenate(slips).reshape(-1, 3)
    return body_arrays, types


def saved_snapshots(options, types):
    """Saved configurations of a dynamic or Monte Carlo run.

    Returns steps (S,) and, for all bodies in input order, locations
    (S, Nb, 3) and orientations (S, Nb, 4).
    """
    if options.save_clones == 'one_file':
        series = []
        for structure_id, count in types:
            path = '%s.%s.config' % (options.output_name, structure_id)
            series.append(utils.read_config_series(path))
        snapshots = min(s[0].shape[0] for s in series)
        steps = np.arange(snapshots) * options.n_save
        series = [(loc[:snapshots], ori[:snapshots]) for loc, ori in series]
    elif options.save_clones == 'one_file_per_step':
        saved = [set(utils.clones_series_steps(options.output_name, structure_id)[0]) for structure_id, _ in types]
        common = sorted(set.intersection(*saved))
        if not common:
            raise utils.UserInputError(
                'no saved step with a snapshot %s.<ID>.<step>.clones of every structure (%s); check output_name '
                'in %s and run from the folder the run was started in'
                % (options.output_name, ', '.join(name for name, _ in types), options.input_file))
        dropped = set.union(*saved) - set(common)
        if dropped:
            print('skipping %d step(s) not saved for every structure (a run stopped while saving?)' % len(dropped))
        series = [utils.read_clones_series(options.output_name, structure_id, common)[1:]
                  for structure_id, _ in types]
        steps = np.array(common, dtype=int)
    else:
        raise utils.UserInputError("%s: save_clones must be one_file_per_step or one_file, got '%s'"
                                   % (options.where('save_clones'), options.save_clones))
    for (structure_id, count), (locations, _) in zip(types, series):
        if locations.shape[1] != count:
            raise utils.UserInputError('the snapshots of %s hold %d bodies but its clones file in %s has %d; '
                                       'is this the input file of that run?'
                                       % (structure_id, locations.shape[1], options.input_file, count))
    return (steps, np.concatenate([s[0] for s in series], axis=1), np.concatenate([s[1] for s in series], axis=1))


def static_velocities(options, num_bodies):
    """Body velocities (Nb, 6) of a static problem, or None when the run has none to show."""
    if options.scheme == 'mobility':
        path = options.output_name + '.velocities.dat'
        if os.path.isfile(path):
            return read_body_table(path, num_bodies, 'velocity')
        print('%s not found: the body files carry no velocities (run multi_bodies_utilities.py first)' % path)
    if options.scheme == 'resistance' and options.velocity_file is not None:
        return read_body_table(options.velocity_file, num_bodies, 'velocity', options.where('velocity_file'))
    return None


def run_configurations(options, body_arrays, types):
    """Every saved configuration of the run of ``options``.

    Static problems have one, step 0: the input configuration.  Returns
    steps (S,), locations (S, Nb, 3) and orientations (S, Nb, 4).
    """
    if options.scheme in STATIC_SCHEMES:
        return np.zeros(1, dtype=int), body_arrays.locations[None].copy(), body_arrays.orientations[None].copy()
    return saved_snapshots(options, types)
