"""Set-up shared by the three programs: input checks, hooks, bodies, backends, the Model, start checks.

``multi_bodies.py`` (dynamics), ``multi_bodies_utilities.py`` (static
problems) and ``many_bodyMCMC/many_body_MCMC.py`` (Monte Carlo) call
:func:`prepare`, in this order:

1. the options the program uses, each against its rule in
   ``input_options.OPTION_TABLE`` (``check_options(options, program)``);
2. the physics hooks (the Monte Carlo program passes its own loader): this package's defaults, replaced by the user's
   ``user_defined_functions.py`` (either style, doc/overrides.md) and
   ``forces_pycuda_user_defined.py``; the log names every replaced hook and
   every override that cannot take effect;
3. the bodies of the ``structure`` lines, each given its slip by the
   ``set_slip_by_ID`` hook;
4. the bodies as arrays, and (dynamics, static problems) the Model with
   the backends (``auto`` resolved to the fastest usable one, honouring
   overrides);
5. the start check: no blob centre below the wall when the hydrodynamics
   sees one (the Monte Carlo program checks the energy itself).

When everything is checked, :func:`start_output` creates the output folder
and :func:`write_run_start` the first files (``.inputfile``,
``.random_state``, ``.bodies_info``).

Floor 6 (multi_bodies.run, see multi_bodies/__init__.py): nothing here writes simulation
output other than the file it is asked to write.
"""
import os
from collections import namedtuple
from functools import partial

import numpy as np

import utils
from body.body import Body, bodies_to_arrays, reference_slip_in_lab_frame
from multi_bodies.solver import physics as mbf
from multi_bodies.solver import published_joints, published_spectral, user_hooks
from multi_bodies.files.input_options import STATIC_SCHEMES, check_options  # noqa: F401 (STATIC_SCHEMES re-exported)
from multi_bodies.files.scheme_table import moves_rollers, scheme_has
from multi_bodies.run import run_output
from multi_bodies.run.run_output import RESTART_SUFFIX, write_bodies_info  # noqa: F401
from multi_bodies.files.snapshots import clones_name, config_name, read_clones_file, read_config_snapshot
from multi_bodies.files.structure_files import read_body_table, read_slip_file, read_vertex_file
from multi_bodies.solver.model import make_model
from multi_bodies.solver.surface import read_surface


def read_bodies(options, set_slip_by_ID, single_blob_bodies=False, restart_record=None, vertex_scale=1.0):
    """Bodies of every ``structure`` line (restart snapshots when ``initial_step > 0``).

    Parameters
    ----------
    options : the validated input options
    set_slip_by_ID : callable ``(body, slip (n, 3) or None)``, the slip hook
        (after it, a published ``default_zero_blobs`` or
        ``partial(active_body_slip, slip=...)`` slip function becomes the
        equivalent ``slip_reference``, so that the vectorised slip path is used)
    single_blob_bodies : bool
        Refuse structures of more than one blob (roller schemes).
    restart_record : dict or None
        With ``save_clones one_file`` and ``initial_step > 0``, the record of
        ``output_name.restart`` at that step: it says where the snapshot
        starts in each ``.config`` file.
    vertex_scale : float
        Factor of the blob positions of every ``structure`` and ``obstacle`` vertex file (the particle radius of
        an input in the published spectral form, ``multi_bodies.solver.published_spectral``; 1 otherwise).

    Returns :data:`BodiesRead` (list of Body, list of (ID, number of bodies) per structure type, the
    ``ArticulatedSet`` of the ``articulated`` lines or None).  The bodies of the
    ``obstacle`` lines come after those of every ``structure`` line; each body has
    ``prescribed_velocity``: None for a free body, (6,) lab-frame ``[v, w]`` for a body of
    prescribed kinematics (zeros for an obstacle, the row of the ``structure`` line's velocity file).
    """
    if not options.structures and not options.articulated:
        raise utils.UserInputError("%s: no 'structure' line; add 'structure <file.vertex> <file.clones>'"
                                   % options.input_file)
    bodies, types = [], []
    for spec in all_structure_specs(options):
        clones, (locations, orientations) = saved_or_input_configuration(options, spec, restart_record)
        reference, radii = read_vertex_file(spec.vertex_file, spec.where, return_radii=True)
        if vertex_scale != 1.0:
            reference = reference * vertex_scale
        if radii is not None and single_blob_bodies:
            raise utils.UserInputError('%s: %s gives blob radii (fourth column), but the roller schemes use the one '
                                       'blob_radius of the input file; remove the fourth column'
                                       % (spec.where, spec.vertex_file))
        slip = None
        if spec.slip_file is not None:
            slip = read_slip_file(spec.slip_file, spec.where)
            if slip.shape[0] < reference.shape[0]:
                raise utils.UserInputError('%s: slip file %s has %d blobs but vertex file %s has %d; give one slip '
                                           'line per blob' % (spec.where, spec.slip_file, slip.shape[0],
                                                              spec.vertex_file, reference.shape[0]))
            if slip.shape[0] > reference.shape[0]:  # the published code uses the first rows and ignores the rest
                utils.warn_user('%s: slip file %s has %d rows for the %d blobs of vertex file %s; the first %d are '
                                'used and the other %d ignored, as the published code does (trim the file to '
                                'silence this)' % (spec.where, spec.slip_file, slip.shape[0], reference.shape[0],
                                                   spec.vertex_file, reference.shape[0],
                                                   slip.shape[0] - reference.shape[0]))
                slip = slip[:reference.shape[0]]
        if single_blob_bodies and reference.shape[0] != 1:
            raise utils.UserInputError('%s: roller schemes need single-blob bodies, but %s has %d blobs'
                                       % (spec.where, spec.vertex_file, reference.shape[0]))
        print('Creating %s = %s' % ('obstacles' if getattr(spec, 'obstacle', False) else 'structures', clones))
        prescribed = prescribed_velocities(spec, locations.shape[0])
        body_length = None
        for index, (location, orientation) in enumerate(zip(locations, orientations)):
            body = Body(location, orientation, reference, options.blob_radius, blobs_radius=radii)
            body.ID = spec.ID
            set_slip_by_ID(body, slip)
            simplify_slip_function(body)
            if body_length is None:
                body_length = body.calc_body_length()
            body.body_length = body_length
            body.prescribed_velocity = None if prescribed is None else prescribed[index].copy()
            bodies.append(body)
        types.append((spec.ID, locations.shape[0]))
    articulated = read_articulated_bodies(options, set_slip_by_ID, bodies, types, single_blob_bodies, restart_record)
    return BodiesRead(bodies, types, articulated)


def saved_or_input_configuration(options, spec, restart_record=None):
    """(file read, (locations (n, 3), orientations (n, 4))) of one line's bodies.

    The line's clones file at the start of a run; on a restart (``initial_step > 0``) the snapshot of
    that step: the step a signal stopped the run at, the ``.config`` record of a ``one_file`` run, or
    the step's ``.clones`` file (quaternions renormalised by the readers).
    """
    clones = spec.clones_file
    restart_step = options.initial_step
    stop_files = (restart_record or {}).get('stop_files') or {}
    if restart_step > 0 and spec.ID in stop_files:  # a step saved when a signal stopped the run
        clones = run_output.stop_snapshot_path(options.output_name, restart_record, spec.ID)
    elif restart_step > 0 and options.save_clones == 'one_file':
        clones = config_name(options.output_name, spec.ID)
        offsets = (restart_record or {}).get('config_offsets') or {}
        if spec.ID not in offsets or not os.path.isfile(clones):
            from multi_bodies.run.restart_records import last_complete_step_text
            last = last_complete_step_text(options.output_name, 'one_file',
                                           [s.ID for s in all_structure_specs(options) + list(options.articulated)])
            raise utils.UserInputError(
                '%s: initial_step %d restarts a save_clones one_file run, but %s%s has no record of step %d '
                'for %s%s; restart from a saved step' % (options.where('initial_step'), restart_step,
                                                        options.output_name, RESTART_SUFFIX, restart_step, clones,
                                                        last))
        return clones, read_config_snapshot(clones, offsets[spec.ID])
    elif restart_step > 0:
        clones = clones_name(options.output_name, spec.ID, options.initial_step)
        if not os.path.isfile(clones):
            raise utils.UserInputError(
                '%s: initial_step %d restarts from %s, which does not exist; restart from a saved step '
                '(save_clones one_file_per_step writes one file per saved step)'
                % (options.where('initial_step'), options.initial_step, clones))
    return clones, read_clones_file(clones, spec.where)


def all_structure_specs(options):
    """The StructureSpec of every ``structure`` line, then of every ``obstacle`` line (the body order)."""
    return list(options.structures) + list(options.obstacles)


def prescribed_velocities(spec, num_bodies):
    """Prescribed lab-frame velocities (num_bodies, 6) of one structure line, or None for free bodies.

    Obstacles: zeros.  A ``structure`` line with a fourth file: that velocity file, one line
    ``vx vy vz wx wy wz`` per body of the line (angular velocity about the body's location).
    """
    if getattr(spec, 'obstacle', False):
        return np.zeros((num_bodies, 6))
    if getattr(spec, 'velocity_file', None) is None:
        return None
    return read_body_table(spec.velocity_file, num_bodies, 'velocity', spec.where)


def read_articulated_bodies(options, set_slip_by_ID, bodies, types, single_blob_bodies=False, restart_record=None):
    """Append the bodies of every ``articulated`` line to ``bodies`` and ``types``; returns the ArticulatedSet or None.

    Body ``i`` of a line's clones file uses vertex file ``i % n`` of its ``.list_vertex`` file (``n`` bodies per
    articulated body, the first number of the ``.const`` file).
    With ``initial_step > 0`` the bodies start from the saved step (as :func:`read_bodies`).
    """
    from multi_bodies.solver import articulated as art
    specs = options.articulated
    if not specs:  # an articulated scheme moves plain bodies with no joint, as the published code does
        return art.ArticulatedSet() if scheme_has(options.scheme, 'articulated') else None
    articulated = art.ArticulatedSet()
    for spec in specs:
        names = art.read_list_vertex_file(spec.list_vertex_file, spec.where)
        const = art.read_const_file(spec.const_file, spec.where)
        if const.num_bodies != len(names):
            raise utils.UserInputError('%s: %s names %d vertex files but %s has %d bodies per articulated body'
                                       % (spec.where, spec.list_vertex_file, len(names), spec.const_file,
                                          const.num_bodies))
        references, radii = {}, {}  # per vertex file: blob positions (n, 3), radii (n,) of a fourth column or None
        for name in names:
            if name not in references:
                references[name], radii[name] = read_vertex_file(name, spec.where, return_radii=True)
                if single_blob_bodies and references[name].shape[0] != 1:
                    raise utils.UserInputError('%s: articulated_deterministic_forward_euler_rollers needs single-'
                                               'blob bodies, but %s has %d blobs'
                                               % (spec.where, name, references[name].shape[0]))
                if single_blob_bodies and radii[name] is not None:
                    raise utils.UserInputError('%s: %s gives blob radii (fourth column), but the roller schemes use '
                                               'the one blob_radius of the input file; remove the fourth column'
                                               % (spec.where, name))
        _, (locations, orientations) = saved_or_input_configuration(options, spec, restart_record)
        if locations.shape[0] % const.num_bodies:
            raise utils.UserInputError('%s: %s has %d bodies, not a multiple of the %d bodies of one articulated '
                                       'body (%s)' % (spec.where, spec.clones_file, locations.shape[0],
                                                      const.num_bodies, spec.const_file))
        print('Creating articulated bodies = %s' % spec.clones_file)
        first = len(bodies)
        lengths = {}
        for i, (location, orientation) in enumerate(zip(locations, orientations)):
            name = names[i % const.num_bodies]
            body = Body(location, orientation, references[name], options.blob_radius, blobs_radius=radii[name])
            body.ID = spec.ID
            set_slip_by_ID(body, None)
            simplify_slip_function(body)
            if name not in lengths:
                lengths[name] = body.calc_body_length()
            body.body_length = lengths[name]
            bodies.append(body)
        articulated.add(const, first, locations.shape[0] // const.num_bodies)
        types.append((spec.ID, locations.shape[0]))
    return articulated


def array_runs(bodies):
    """Numbers of consecutive bodies sharing one reference configuration (the types of ``BodyArrays``)."""
    runs, previous = [], None
    for b in bodies:
        r = b.reference_configuration
        if runs and r.shape == previous.shape and np.array_equal(r, previous):
            runs[-1] += 1
        else:
            runs.append(1)
            previous = r
    return runs


def write_articulated_copies(options):
    """Copies of the ``.list_vertex`` and ``.const`` files of every articulated line, and of the ``.Laplace`` and
    ``.slip_length`` files of every structure line, as published (``output_name.<file name>``)."""
    import shutil
    paths = [path for spec in options.articulated for path in (spec.list_vertex_file, spec.const_file)]
    paths += [path for spec in all_structure_specs(options) for path in (spec.laplace_file, spec.slip_length_file)
              if path]
    for path in paths:
        shutil.copyfile(path, '%s.%s' % (options.output_name, os.path.basename(path)))


def _is_default_helper(function, name):
    """True when ``function`` is this package's ``multi_bodies_functions.<name>`` (or a fresh copy's)."""
    return getattr(function, 'published_helper', None) == name


def simplify_slip_function(body):
    """Turn the published constant-slip functions into ``slip_reference`` (same slip, vectorised path).

    ``default_zero_blobs`` means no slip; ``partial(active_body_slip, slip=s)``
    means the body-frame slip ``s`` turned with the body.  Any other
    ``function_slip`` is kept and called per body at every solve.
    """
    function = body.function_slip
    if function is reference_slip_in_lab_frame:
        return
    if _is_default_helper(function, 'default_zero_blobs'):
        body.slip_reference = None
        body.function_slip = reference_slip_in_lab_frame
    elif isinstance(function, partial) and _is_default_helper(function.func, 'active_body_slip'):
        slip = function.keywords.get('slip') if not function.args else function.args[0]
        if len(function.args) + len(function.keywords) == 1 and slip is not None \
                and np.asarray(slip).size == 3 * body.Nblobs:
            body.slip_reference = np.asarray(slip, dtype=float).reshape(-1, 3)
            body.function_slip = reference_slip_in_lab_frame


BodiesRead = namedtuple('BodiesRead', ['bodies', 'types', 'articulated'])
BodiesRead.__doc__ = """What :func:`read_bodies` returns: the Body list, (ID, count) per structure type and the
``ArticulatedSet`` of the ``articulated`` lines (None without)."""

RunSetup = namedtuple('RunSetup', ['hooks', 'bodies', 'types', 'body_arrays', 'system'])
RunSetup.__doc__ = """What :func:`prepare` returns: the hooks, the Body list, (ID, count) per structure type,
the BodyArrays and the Model."""

# prepare's script names -> the program names of input_options.OPTION_TABLE
PROGRAM_OF_SCRIPT = {'dynamics': 'dynamic', 'static': 'static', 'mcmc': 'mcmc'}


def load_hooks(options, directory, log=print, folder_module=None):
    """The run's hooks from ``directory`` (see ``multi_bodies.solver.user_hooks.load_user_hooks``), logged.

    ``folder_module``: a ``user_hooks.FolderModuleCall`` where a folder's own ``multi_bodies_functions.py`` is read
    (the published spectral form, ``published_spectral.folder_module_call``), else None."""
    implementation = options.blob_blob_force_implementation
    hooks = user_hooks.load_user_hooks(directory, load_pycuda=implementation in ('pycuda', 'auto'),
                                physics=mbf.physics_keywords(options), folder_module=folder_module)
    if hooks.sources:
        log('user-defined physics from %s' % ', '.join(hooks.sources))
    for note in hooks.notes:
        log('  ' + note)
    return hooks


def apply_spectral_reading(options, published, bodies, log=print):
    """Say which reading of a spectral input is used; in the published form, apply the folder's start rules to a new
    run's ``bodies`` (raised below the particle radius, x and y wrapped into the box; a restart continues its
    snapshot as saved) and say what they moved."""
    kind = published_spectral.reading_kind(options)
    if kind is None:
        return
    if published is None:
        log('spectral_reading package: blob_radius %.10g is the blob radius and the vertex files are read as written '
            '(the manual\'s reading; doc/periodic.md)' % options.blob_radius)
        return
    log(published.log_line())
    if options.initial_step == 0:
        raised, wrapped = published_spectral.apply_start_rules(bodies, published, options.periodic_length)
        log('  the start as the folder\'s script makes it: %d of %d bodies below the particle radius raised to '
            '%.10g, %d moved by whole periods into the box' % (raised, len(bodies), published_spectral.RAISED_HEIGHT *
                                                             published.particle_radius, wrapped))


def check_start(options, model, types):
    """Refuse a start with a blob centre below the wall (when the wall is seen), naming the structure line."""
    if not model.check_wall:
        return
    try:
        invalid = model.invalid_bodies(model.start_configuration)
    except utils.SimulationStopped as err:  # the spectral grid's heights (doc/periodic.md)
        raise utils.UserInputError('%s: the start: %s' % (options.where('spectral_z_bounds'),
                                                          str(err).split('; restart')[0]))
    if invalid.size:
        first = int(invalid[0])
        start = 0
        where = ('below the wall (z < 0)' if getattr(model, 'spectral', None) is None
                 or model.spectral.top_wall is None else
                 'through a wall (below z = 0 or above the top wall at z = %g)' % model.spectral.top_wall)
        for (structure_id, count), spec in zip(types, all_structure_specs(options) +
                                               list(options.articulated)):
            if first < start + count:
                raise utils.UserInputError('%s: body %d of %s starts with a blob centre %s; '
                                           '%d bodies are affected. Move the bodies in the clones file.'
                                           % (spec.where, first - start, structure_id, where, invalid.size))
            start += count


def body_names(options, types):
    """(where, structure ID, index in its clones file) of every body, in the order of the run's bodies."""
    names = []
    for (structure_id, count), spec in zip(types, all_structure_specs(options) + list(options.articulated)):
        names.extend((spec.where, structure_id, k) for k in range(count))
    return names


def check_coincident_bodies(options, bodies, types):
    """Refuse two bodies whose blobs coincide (the same position, blobs and orientation: the blob mobility is then
    singular and GMRES stalls); warn, naming both, when two bodies of different blobs share their position.

    Positions closer than 1e-9 blob_radius count as the same (a copied line of a clones file gives 0)."""
    if len(bodies) < 2:
        return
    from scipy.spatial import cKDTree
    locations = np.array([b.location for b in bodies], dtype=float).reshape(-1, 3)
    pairs = sorted(cKDTree(locations).query_pairs(1e-9 * options.blob_radius))
    if not pairs:
        return
    names = body_names(options, types)

    def name(i):
        where, structure_id, k = names[i]
        return 'body %d of %s (%s)' % (k, structure_id, where)
    for i, j in pairs:
        a, b = bodies[i], bodies[j]
        same_blobs = a.reference_configuration.shape == b.reference_configuration.shape and np.allclose(
            a.get_r_vectors(), b.get_r_vectors(), rtol=0, atol=1e-9 * options.blob_radius)
        if same_blobs:
            raise utils.UserInputError(
                '%s and %s are at the same position %s with the same blobs, which coincide and make the mobility '
                'singular (%d such pair(s)); move or remove one of them in the clones file'
                % (name(i), name(j), ' '.join('%g' % x for x in locations[i]), len(pairs)))
    i, j = pairs[0]
    utils.warn_user('%s and %s are at the same position %s (%d such pair(s)); their blobs overlap: check the clones '
                    'files' % (name(i), name(j), ' '.join('%g' % x for x in locations[i]), len(pairs)))


def prepare(options, script, print_residual=False, log=print, directory=None, restart_record=None,
            hook_loader=None, set_slip_by_ID=None):
    """Everything a run needs before its first solve; shared by the three programs.

    Parameters
    ----------
    options : validated input options (``input_options.read_input_file``)
    script : 'dynamics' (multi_bodies.py), 'static' (multi_bodies_utilities.py)
        or 'mcmc' (many_body_MCMC.py: no Model, no hydrodynamic start check)
    print_residual : bool
        Print every GMRES residual.
    log : callable(str)
        Where the set-up lines go (the scripts pass ``print``).
    directory : str
        Run directory holding the override files (default: the current one).
    restart_record : dict or None
        The ``.restart`` record of ``initial_step`` (see :func:`read_bodies`).
    hook_loader : callable ``(options, directory, log) -> hooks`` or None
        Loader of the user's overrides (default :func:`load_hooks`, the
        physics hooks of ``user_defined_functions.py``).
    set_slip_by_ID : callable or None
        Slip hook (default ``hooks.set_slip_by_ID``).

    Returns a :data:`RunSetup` (``system`` None for 'mcmc').  Raises
    ``utils.UserInputError`` (file, line or option named) for any mistake
    found before the run starts, including an override file that does not
    import and a ``set_slip_by_ID`` that fails.
    """
    check_options(options, PROGRAM_OF_SCRIPT[script])
    if any(options.periodic_length):  # a box to check (all zeros: no periodic axis)
        run_output.check_periodic_length(options)
    if script == 'mcmc' and options.articulated:
        raise utils.UserInputError("%s: the Monte Carlo sampler has no joints; remove the 'articulated' line or run "
                                   "it with multi_bodies.py and an articulated scheme" % options.articulated[0].where)
    published = None
    # the spectral product's input: read in the published form or the package's (doc/periodic.md)
    spectral_input = script != 'mcmc' and options.mobility_vector_prod_implementation == published_spectral.SPECTRAL
    if spectral_input:  # the published spectral form: options with the derived blob radius
        options, published = published_spectral.published_options(options)
    directory = os.getcwd() if directory is None else directory
    if hook_loader is None:
        hooks = load_hooks(options, directory, log, folder_module=None if published is None else
                           published_spectral.folder_module_call(options, script))
    else:
        hooks = hook_loader(options, directory, log)
    try:
        bodies, types, articulated = read_bodies(options, hooks.set_slip_by_ID if set_slip_by_ID is None else set_slip_by_ID,
                                    single_blob_bodies=script == 'dynamics' and moves_rollers(options.scheme),
                                    restart_record=restart_record,
                                    vertex_scale=1.0 if published is None else published.vertex_scale)
    except user_hooks.UserFunctionError as err:
        raise utils.UserInputError(str(err))
    if spectral_input:
        apply_spectral_reading(options, published, bodies, log)
    if articulated is not None:
        if getattr(hooks, 'published_constraint_class', None) is not None \
                or getattr(hooks, 'published_articulated_class', None) is not None:
            try:
                published_joints.attach(articulated, hooks.published_constraint_class, hooks.published_articulated_class,
                                        hooks.published_joint_class)
            except user_hooks.UserFunctionError as err:
                raise utils.UserInputError(str(err))
        articulated.check_extras()
    check_coincident_bodies(options, bodies, types)
    body_arrays = bodies_to_arrays(bodies, array_runs(bodies) if articulated is not None
                                   else [count for _, count in types], per_body_slip=script != 'mcmc')
    fixed = [spec for spec in all_structure_specs(options) if spec.obstacle or spec.velocity_file is not None]
    if fixed and script == 'mcmc':
        raise utils.UserInputError('%s: the Monte Carlo program has no obstacles or bodies of prescribed '
                                   'velocity; remove the line (or run the dynamics, multi_bodies.py)'
                                   % fixed[0].where)
    if script == 'mcmc' and body_arrays.radii_given:
        raise utils.UserInputError('%s: a vertex file gives blob radii (fourth column), but the Monte Carlo energies '
                                   'use the one blob_radius of the input file; remove the fourth column'
                                   % options.input_file)
    if script == 'mcmc':
        return RunSetup(hooks, bodies, types, body_arrays, None)
    system = make_model(options, bodies, body_arrays, hooks, script=script, articulated=articulated,
                        print_residual=print_residual, log=log)
    specs = all_structure_specs(options)
    if options.save_concentration or any(s.laplace_file or s.slip_length_file for s in specs):
        surface = read_surface(options, specs, types, body_arrays.type_blobs,
                               options.domain == 'single_wall', system.check_wall)  # .Laplace, .slip_length files
        if surface is not None:
            system = system.replace(surface=surface)
    log('mobility_vector_prod_implementation = %s, mobility_blobs_implementation = %s, '
        'blob_blob_force_implementation = %s, body_body_force_torque_implementation = %s'
        % (system.vector_product_name, system.blobs_name, system.blob_blob_name, system.body_body_name))
    check_start(options, system, types)
    if getattr(hooks, 'force_torque_calculator', None) is not None:  # a folder's module: fails here, not at step 1
        try:
            system.forces_torques(system.start_configuration)
        except user_hooks.UserFunctionError as err:
            raise utils.UserInputError(str(err))
    warning = slow_dense_warning(options, system.blobs_name, body_arrays.blob_offsets)
    if warning:
        log(warning)
    return RunSetup(hooks, bodies, types, body_arrays, system)


# Largest body whose dense blob mobility the python backend builds in seconds (3n x 3n: n = 1,000 gives 3,000 x
# 3,000 from Python pair loops; the published Pillars folder's 1,684-blob body took 75 s per step).
DENSE_PYTHON_BLOBS = 1000


def slow_dense_warning(options, blobs_name, blob_offsets):
    """The ``warning:`` line for a ``python`` dense mobility of a body of more than DENSE_PYTHON_BLOBS blobs, or None.

    ``blob_offsets`` (Nb + 1,): the first blob of every body (the last entry: the number of blobs).
    """
    largest = int(np.max(np.diff(blob_offsets))) if len(blob_offsets) > 1 else 0
    if not blobs_name.startswith('python') or largest <= DENSE_PYTHON_BLOBS:
        return None
    return ('warning: %s: mobility_blobs_implementation %s builds the dense mobility of a body of %d blobs in Python '
            '(more than about %d blobs: minutes per build, and the preconditioner rebuilds it every step); use '
            'C++%s, or ask the advisor (python advise.py --input-file %s) for the fastest backends here'
            % (options.where('mobility_blobs_implementation'), blobs_name, largest, DENSE_PYTHON_BLOBS,
               blobs_name[len('python'):], os.path.basename(options.input_file)))


def start_output(options):
    """Create the output folder of ``output_name`` (after every check: nothing is written before)."""
    run_output.prepare_output_directory(options.output_name, options.where('output_name'))


def copied_input_names(options):
    """The names after ``output_name.`` of the input files a run copies beside its outputs
    (:func:`write_articulated_copies`)."""
    paths = [path for spec in options.articulated for path in (spec.list_vertex_file, spec.const_file)]
    paths += [path for spec in all_structure_specs(options) for path in (spec.laplace_file, spec.slip_length_file)
              if path]
    return tuple(os.path.basename(path) for path in paths)


def set_aside_earlier_run(options, types, log=print, extra_suffixes=()):
    """A new run (``initial_step 0``): move every file of an earlier run with the same ``output_name`` to
    ``output_name.set_aside/`` before anything is written (``run_output.set_aside_earlier_run``);
    ``extra_suffixes``: the names after ``output_name.`` of further files (those of the run's writers)."""
    return run_output.set_aside_earlier_run(options.output_name, [name for name, _ in types],
                                            copied_input_names(options) + tuple(extra_suffixes), log=log,
                                            keep=[options.input_file])


def write_run_start(options, types, num_blobs, rng=None, restart=False, log=print, extra_suffixes=()):
    """The first files of a run: ``.inputfile`` (appended to on a restart), ``.random_state`` (of ``rng``, new
    runs only) and ``.bodies_info`` (``types``: (ID, count) per structure; ``num_blobs``: int).

    A new run first sets the files of an earlier run with the same ``output_name`` aside (nothing of it is
    overwritten or mixed with the new one), the files named by ``extra_suffixes`` (after ``output_name.``: the
    run's writers' own) too."""
    if not restart:
        set_aside_earlier_run(options, types, log, extra_suffixes)
    run_output.copy_input_file(options.input_file, options.output_name, restart=restart)
    if rng is not None and not restart:
        run_output.save_random_state(options.output_name + '.random_state', rng)
    write_bodies_info(options.output_name + '.bodies_info', types, num_blobs)
