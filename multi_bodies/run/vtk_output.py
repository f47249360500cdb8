"""VTK files of rigid multiblob runs for ParaView: one blob file and one body file per saved step.

Floor 6 (multi_bodies.run, see multi_bodies/__init__.py).  Used by ``clones_to_vtk.py`` (to
convert the ``.clones`` series of a finished or stopped run) and by
``multi_bodies.py`` when the input says ``save_vtk True``.  Files, all
prefixed by ``output_name`` (see doc/visualisation.md):

* ``output_name.blobs.<step, 8 digits>.vtp``: PolyData with one vertex per
  blob at its lab-frame position, and point arrays ``radius`` (the radius
  of each blob: the fourth column of its vertex file, else ``blob_radius``;
  for true-size sphere glyphs), ``body_index`` (0-based, over
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

The files are written with numpy alone, in VTK's XML PolyData format
(binary appended data), which ParaView, VisIt and pyvista read: the option
``save_vtk`` then costs no extra import (pyvista takes most of a second to
import, longer than the whole example run of the manual).
"""
import os
import re
from xml.sax.saxutils import escape

import numpy as np

import utils
from body.body import Configuration, K_dot, bodies_to_arrays
from multi_bodies.files.scheme_table import scheme_names
from multi_bodies.solver import user_hooks
from multi_bodies.run.run_setup import read_bodies
from multi_bodies.run import run_output
from multi_bodies.run.writers import Writer
from multi_bodies.files import snapshots as snapshot_files
from multi_bodies.files.structure_files import read_body_table
from body.geometry import rotation_matrices

BLOBS = 'blobs'
BODIES = 'bodies'
_PVD_HEAD = ('<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">\n'
             '  <Collection>\n')
_PVD_TAIL = '  </Collection>\n</VTKFile>\n'
_PVD_ENTRY = '    <DataSet timestep="%s" group="" part="0" file="%s"/>\n'


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


class StringArray:
    """A string point array, encoded once for the VTK XML ``ascii`` format (character codes, 0 after each string).

    ``names``: list of str; ``index``: (n,) int, the name of each point.
    The structure of each blob never changes during a run, so a series
    encodes it once and writes the same text at every step.
    """

    def __init__(self, names, index):
        codes = [' '.join(str(c) for c in name.encode('utf-8')) + ' 0' for name in names]
        index = np.asarray(index, dtype=int).reshape(-1)
        self.count = index.shape[0]
        self.text = ' '.join(codes[i] for i in index)


def write_vtp(path, points, point_arrays):
    """Write a VTK XML PolyData file: one vertex cell per point, and point arrays.

    Parameters
    ----------
    path : str
    points : (n, 3) float coordinates.
    point_arrays : list of (name, values): values of shape (n,) or (n, k),
        stored as Float64 (floats) or Int64 (integers), or a ``StringArray``.

    Numbers go in raw binary appended data (little-endian, UInt64 block
    headers), strings inline as ``ascii``; this is the format that ParaView's
    and VTK's ``vtkXMLPolyDataReader`` read.  Only numpy is needed to write.
    """
    points = np.ascontiguousarray(points, dtype='<f8').reshape(-1, 3)
    count = points.shape[0]
    vertices = np.arange(count, dtype='<i8')
    blocks, xml, offset = [], [], 0

    def appended(values, name, components):
        nonlocal offset
        values = np.ascontiguousarray(values)
        vtk_type = 'Float64' if values.dtype.kind == 'f' else 'Int64'
        values = values.astype('<f8' if vtk_type == 'Float64' else '<i8', copy=False)
        data = values.tobytes()
        blocks.append(np.uint64(len(data)).astype('<u8').tobytes())
        blocks.append(data)
        text = '<DataArray type="%s" Name="%s" NumberOfComponents="%d" format="appended" offset="%d"/>' % (
            vtk_type, name, components, offset)
        offset += 8 + len(data)
        return text

    xml.append('<PointData>')
    for name, values in point_arrays:
        if isinstance(values, StringArray):
            if values.count != count:
                raise ValueError('string array %s has %d values for %d points' % (name, values.count, count))
            xml.append('<Array type="String" Name="%s" NumberOfTuples="%d" format="ascii">\n%s\n</Array>'
                       % (name, count, values.text))
        else:
            values = np.asarray(values)
            if values.shape[0] != count:
                raise ValueError('array %s has %d values for %d points' % (name, values.shape[0], count))
            xml.append(appended(values, name, 1 if values.ndim == 1 else values.shape[1]))
    xml.append('</PointData>')
    xml.append('<Points>%s</Points>' % appended(points, 'Points', 3))
    xml.append('<Verts>%s%s</Verts>' % (appended(vertices, 'connectivity', 1), appended(vertices + 1, 'offsets', 1)))
    head = ('<?xml version="1.0"?>\n<VTKFile type="PolyData" version="1.0" byte_order="LittleEndian" '
            'header_type="UInt64">\n<PolyData>\n<Piece NumberOfPoints="%d" NumberOfVerts="%d" NumberOfLines="0" '
            'NumberOfStrips="0" NumberOfPolys="0">\n' % (count, count))
    tail = '</Piece>\n</PolyData>\n<AppendedData encoding="raw">\n_'
    with open(path, 'wb') as f:
        f.write((head + '\n'.join(xml) + '\n' + tail).encode('ascii'))
        f.write(b''.join(blocks))
        f.write(b'\n</AppendedData>\n</VTKFile>\n')
    return path


def blob_point_arrays(blob_radius, blob_body_index, blob_structure, blob_velocities=None, blob_slip=None, extra=()):
    """Point arrays of the blob file (see the module docstring).

    Parameters
    ----------
    blob_radius : float or (N,) blob radius ``a`` (length).
    blob_body_index : (N,) int, body of each blob (0-based, all structures).
    blob_structure : pair ``(structure_index (N,) int, StringArray of the structure IDs)``.
    blob_velocities : (N, 3) or None, blob velocities (length/time).
    blob_slip : (N, 3) or None, lab-frame active slip (length/time).
    extra : more (name, values (N,) or (N, 3)) point arrays (the concentration of phoretic runs).
    """
    structure_index, structure_names = blob_structure
    count = np.asarray(blob_body_index).shape[0]
    arrays = [('radius', np.broadcast_to(np.asarray(blob_radius, dtype=float), (count,))),
              ('body_index', np.asarray(blob_body_index, dtype=np.int64)),
              ('structure_index', np.asarray(structure_index, dtype=np.int64)),
              ('structure', structure_names)]
    if blob_velocities is not None:
        arrays.append(('velocity', np.asarray(blob_velocities, dtype=float).reshape(-1, 3)))
    if blob_slip is not None:
        arrays.append(('slip', np.asarray(blob_slip, dtype=float).reshape(-1, 3)))
    return arrays + list(extra)


def body_point_arrays(orientations, body_structure, body_velocities=None):
    """Point arrays of the body file: frame axes, quaternion, indices, structure, velocities.

    ``orientations``: (Nb, 4) scalar-first unit quaternions; ``body_structure``:
    pair ``(structure_index (Nb,), StringArray)``; ``body_velocities``: (Nb, 6)
    ``[v, w]`` (length/time, radians/time) or None.
    """
    orientations = np.asarray(orientations, dtype=float).reshape(-1, 4)
    rotations = rotation_matrices(orientations)
    structure_index, structure_names = body_structure
    arrays = [('axis_%d' % (axis + 1), rotations[:, :, axis]) for axis in range(3)]
    arrays += [('quaternion', orientations), ('body_index', np.arange(orientations.shape[0], dtype=np.int64)),
               ('structure_index', np.asarray(structure_index, dtype=np.int64)), ('structure', structure_names)]
    if body_velocities is not None:
        body_velocities = np.asarray(body_velocities, dtype=float).reshape(-1, 6)
        arrays += [('velocity', body_velocities[:, :3]), ('angular_velocity', body_velocities[:, 3:])]
    return arrays


def write_blob_file(path, r_vectors, blob_radius, blob_body_index, blob_structure_index, structure_names,
                    blob_velocities=None, blob_slip=None):
    """The blob ``.vtp`` of one step: r_vectors (N, 3), radius, body index, structure; optional velocity, slip."""
    structure = (blob_structure_index, StringArray(structure_names, blob_structure_index))
    return write_vtp(path, r_vectors, blob_point_arrays(blob_radius, blob_body_index, structure, blob_velocities,
                                                        blob_slip))


def write_body_file(path, locations, orientations, body_structure_index, structure_names, body_velocities=None):
    """The body ``.vtp`` of one step: locations (Nb, 3), orientations (Nb, 4); optional velocities (Nb, 6)."""
    structure = (body_structure_index, StringArray(structure_names, body_structure_index))
    return write_vtp(path, locations, body_point_arrays(orientations, structure, body_velocities))


class PvdCollection:
    """A ``.pvd`` file that stays valid after every added step (a stopped run leaves a readable file).

    The file stays open; each ``add`` writes one entry in place of the
    closing tags, writes them again after it and flushes, so adding costs the
    same at any length of the run.  ``keep_before_step``: on opening an
    existing file, keep its entries of steps before this one (a restart) and
    drop the rest; None starts a new file.
    """

    def __init__(self, path, keep_before_step=None):
        self.path = path
        self.folder = os.path.dirname(os.path.abspath(path))
        entries = []
        if keep_before_step is not None and os.path.isfile(path):
            with open(path, 'r') as f:
                for line in f:
                    found = re.search(r'timestep="([^"]*)".*file="([^"]*)"', line)
                    step = re.search(r'\.(\d{8,})\.vtp$', found.group(2)) if found else None
                    if step and int(step.group(1)) < keep_before_step:
                        entries.append(line)
        head = (_PVD_HEAD + ''.join(entries)).encode('utf-8')
        self.file = open(path, 'wb')
        self.file.write(head + _PVD_TAIL.encode('ascii'))
        self.file.flush()
        self.tail_at = len(head)

    def add(self, time, file_path):
        """Add the file ``file_path`` (stored relative to the ``.pvd``'s folder) at simulation ``time``."""
        absolute = os.path.abspath(file_path)
        if os.path.dirname(absolute) == self.folder:
            relative = os.path.basename(absolute)
        else:
            relative = os.path.relpath(absolute, self.folder).replace(os.sep, '/')
        entry = (_PVD_ENTRY % (repr(float(time)), escape(relative, {'"': '&quot;'}))).encode('utf-8')
        self.file.seek(self.tail_at)
        self.file.write(entry + _PVD_TAIL.encode('ascii'))
        self.file.truncate()
        self.file.flush()
        self.tail_at += len(entry)

    def close(self):
        self.file.close()

    def __del__(self):
        file = getattr(self, 'file', None)
        if file is not None:
            file.close()


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
        self._body_structure = (self.body_structure_index,
                                StringArray(self.structure_names, self.body_structure_index))
        self._blob_structure = None
        self.collections = {kind: PvdCollection(collection_name(output_name, kind), keep) for kind in (BLOBS, BODIES)}

    def write(self, step, body_arrays, configuration, body_velocities=None, blob_slip=None, blob_arrays=()):
        """Write the files of ``step``: bodies of ``body_arrays`` (a ``BodyArrays``) at ``configuration``.

        ``body_velocities``: (Nb, 6) or None.  ``blob_slip``: (N, 3) lab-frame
        slip or None; by default the slip of the slip files, rotated with the
        bodies, when any blob has one.  Returns the two paths written.
        """
        locations = configuration.locations
        r_vectors = body_arrays.blob_positions(configuration)
        blob_velocities = None
        if body_velocities is not None:
            body_velocities = np.asarray(body_velocities, dtype=float).reshape(-1, 6)
            blob_velocities = K_dot(r_vectors, locations, body_arrays.blob_body_index, body_velocities)
        if blob_slip is None and np.any(body_arrays.reference_slip):
            blob_slip = body_arrays.lab_frame_slip(configuration)
        if self.wrap_periodic:
            shifts = periodic_shifts(locations, self.periodic_length)
            locations = locations + shifts
            r_vectors = r_vectors + shifts[body_arrays.blob_body_index]
        blob_index = body_arrays.blob_body_index
        if self._blob_structure is None or self._blob_structure[0].shape[0] != blob_index.shape[0]:
            blob_structure_index = self.body_structure_index[blob_index]
            self._blob_structure = (blob_structure_index, StringArray(self.structure_names, blob_structure_index))
        radii = getattr(body_arrays, 'blob_radii', body_arrays.blob_radius)  # the radius of each blob
        files = ((BLOBS, r_vectors, blob_point_arrays(radii, blob_index, self._blob_structure,
                                                      blob_velocities, blob_slip, blob_arrays)),
                 (BODIES, locations, body_point_arrays(configuration.orientations, self._body_structure,
                                                       body_velocities)))
        time = step_time(step, self.dt)
        paths = []
        for kind, points, arrays in files:
            path = step_file_name(self.output_name, kind, step)
            write_vtp(path, points, arrays)
            self.collections[kind].add(time, path)
            paths.append(path)
        return paths

    def close(self):
        """Close the ``.pvd`` files (they are complete after every step already)."""
        for collection in self.collections.values():
            collection.close()


class VtkWriter(Writer):
    """The VTK files of every save (``save_vtk True``, doc/visualisation.md): blob and body ``.vtp`` files and
    their ``.pvd`` collections, and the joints of articulated bodies; a writer of ``multi_bodies.run.writers``.

    ``options``: the run's Options; ``types``: list of (structure ID, bodies); ``system``: the run's model (its
    ``arrays``, a ``BodyArrays``, and its joints).  The files are opened by ``open`` (a restart keeps the
    collections' entries of the steps before its first).
    """
    suffixes = ('blobs.pvd', 'bodies.pvd', 'joints.pvd')

    def __init__(self, options, types, system):
        self.options, self.types, self.system = options, list(types), system
        self.series, self.joint_collection = None, None
        self.joints = system.articulated

    def open(self, run):
        options, types = self.options, self.types
        self.series = VtkSeries(options.output_name, [name for name, _ in types], [count for _, count in types],
                                options.dt, options.periodic_length, wrap_periodic=False,
                                first_step=options.initial_step)
        # articulated bodies: the joints too, output_name.joints.<step>.vtp (doc/articulated.md)
        if self.joints is not None:
            self.output_name, self.dt = options.output_name, options.dt
            self.joint_collection = PvdCollection(collection_name(options.output_name, 'joints'),
                                                  options.initial_step if options.initial_step > 0 else None)

    def write(self, frame):
        """The VTK files of ``frame.step`` at the frame's configuration."""
        configuration = Configuration(frame.locations, frame.orientations)
        from multi_bodies.run.concentration_output import surface_point_data  # phoretic runs: c and slip
        slip, extra = surface_point_data(self.system, configuration)
        self.series.write(frame.step, self.system.arrays, configuration, blob_slip=slip, blob_arrays=extra)
        if self.joints is not None:
            self.write_joints(frame.step, configuration)

    def close(self):
        if self.series is not None:
            self.series.close()
        if self.joint_collection is not None:
            self.joint_collection.close()

    def write_joints(self, step, configuration):
        """``output_name.joints.<step>.vtp``: each joint at ``q_p + R_p l_p`` with its residual and bodies."""
        time = step_time(step, self.dt)
        a, _ = self.joints.lab_links(configuration, time)
        points = configuration.locations[self.joints.bodies[:, 0]] + a[:, :3]
        residual = np.linalg.norm(self.joints.violation(configuration, time), axis=1)
        path = step_file_name(self.output_name, 'joints', step)
        write_vtp(path, points, [('residual', residual), ('body_p', self.joints.bodies[:, 0].astype(np.int64)),
                                 ('body_q', self.joints.bodies[:, 1].astype(np.int64))])
        self.joint_collection.add(time, path)


# ------------------------------------------------------------------ a saved run, read back (clones_to_vtk, render)
STATIC_SCHEMES = scheme_names(kind='static')  # the scheme registry's


def load_run(options):
    """Bodies of the input file: (BodyArrays with the slip of the slip files and hooks, types)."""
    hooks = user_hooks.load_user_hooks(os.getcwd(), load_pycuda=False)
    bodies, types, _ = read_bodies(options, hooks.set_slip_by_ID)
    # articulated lines mix vertex files: the array types are the runs of bodies sharing one reference
    from multi_bodies.run.run_setup import array_runs
    body_arrays = bodies_to_arrays(bodies, array_runs(bodies) if options.articulated
                                   else [count for _, count in types])
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
            path = snapshot_files.config_name(options.output_name, structure_id)
            series.append(snapshot_files.read_config_series(path))
        snapshots = min(s[0].shape[0] for s in series)
        recorded = [run_output.recorded_snapshots(options.output_name, 'one_file', structure_id)
                    for structure_id, _ in types]
        recorded = [n for n in recorded if n is not None]
        if recorded and min(recorded) < snapshots:  # frames written without their record: not the run's
            print('skipping %d snapshot(s) without a restart record (a run stopped between a snapshot and its '
                  'record)' % (snapshots - min(recorded)))
            snapshots = min(recorded)
        steps = np.arange(snapshots) * options.n_save
        series = [(loc[:snapshots], ori[:snapshots]) for loc, ori in series]
    elif options.save_clones == 'one_file_per_step':
        saved = [set(snapshot_files.clones_series_steps(options.output_name, structure_id)[0])
                 for structure_id, _ in types]
        recorded = run_output.recorded_snapshots(options.output_name, 'one_file_per_step', None)
        if recorded is not None:  # the current run's steps: those with a restart record
            lone = set.union(*saved) - recorded
            if lone:
                print('skipping %d step(s) without a restart record (%s; a run stopped between a snapshot and its '
                      'record, or files of another run)' % (len(lone), utils.describe_steps(sorted(lone))))
            saved = [steps & recorded for steps in saved]
        common = sorted(set.intersection(*saved))
        if not common:
            raise utils.UserInputError(
                'no saved step with a snapshot %s.<ID>.<step>.clones of every structure (%s); check output_name '
                'in %s and run from the folder the run was started in'
                % (options.output_name, ', '.join(name for name, _ in types), options.input_file))
        dropped = set.union(*saved) - set(common)
        if dropped:
            print('skipping %d step(s) not saved for every structure (a run stopped while saving?)' % len(dropped))
        series = [snapshot_files.read_clones_series(options.output_name, structure_id, common)[1:]
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
