"""Advice that keeps the physics: scope, per-blob parameters, the check run and the time-step bounds.

Helpers of ``multi_bodies/advice/advisor.py`` (floor 7).  A recommendation
that changes the blobs of a body (a new shell, or single-blob rollers)
must not change the forces on the bodies: gravity and the wall and pair
repulsions of the default laws act per blob, so their parameters
(``g``, ``repulsion_strength_wall``, ``repulsion_strength``) are rescaled
here so that every body keeps its total force and torque at the input
configuration (least squares over the bodies, one factor per parameter,
since each is one number for the whole scene).  Gravity is matched
exactly; the wall and pair factors are matched at the input positions
(the new blobs sit at other heights, so the force-height law differs a
little away from them).

Then the recommended input is checked: it is read and set up as the
program would (``run_setup.prepare``: the start check refuses blobs below
the wall), and one mobility problem is solved (``Model.deterministic_velocities``,
or the roller velocities) for the user's input and for the recommended one.
The model change is kept only if the total force per body and the body
velocities agree within the target (velocities: the target plus the
user's model's own estimated error, since a refinement corrects that
error).  Otherwise it is dropped and the report says why.

Shapes: forces and velocities (Nb, 6) per body ``[F, T]`` / ``[U, W]``;
roller velocities (N, 3).  Lengths and times in the user's units.
"""
import atexit
import contextlib
import io
import os
import shutil

import numpy as np

import utils
from multi_bodies.files.input_options import OPTION_TABLE, STATIC_SCHEMES, is_used, parse_input_text
from multi_bodies.files.scheme_table import moves_rollers, scheme_has, scheme_names
from multi_bodies.solver.physics import ONE_BLOB_NAMES

# The per-blob parameters of the default laws, rescaled when the blob count of a body changes.
PER_BLOB_PARAMETERS = ('g', 'repulsion_strength_wall', 'repulsion_strength')
# Hooks whose body total depends on the number of blobs.
PER_BLOB_HOOKS = ONE_BLOB_NAMES + ('blob_blob_force',)
# Recommendation keys that change the model of the bodies (dropped together when the check fails).
MODEL_KEYS = ('blob_radius', 'free_kinematics', 'omega_one_roller') + PER_BLOB_PARAMETERS
# Static problems that use dense blocks only (no blob vector product).
DENSE_BLOCK_SCHEMES = scheme_names(kind='static', algebra='dense')  # the scheme registry's
# Blobs (with the larger of the user's and the recommended model) beyond which the check and the time-step
# measurement run on the bodies nearest the lowest body instead of the whole scene.
CHECK_BLOB_LIMIT = 3000


def program_of(options):
    """'mcmc', 'static' or 'dynamic': the program that reads this input.

    A Monte Carlo input sets options that only ``many_body_MCMC.py`` uses (``mcmc_move``, ``n_burn_in``,
    ``mcmc_energy_implementation``, ...) and no ``scheme``.
    """
    mcmc_only = [name for name, row in OPTION_TABLE.items() if tuple(row.used_by) == ('mcmc',)]
    if not options.is_set('scheme') and any(options.is_set(name) for name in mcmc_only):
        return 'mcmc'
    return 'static' if options.scheme in STATIC_SCHEMES else 'dynamic'


def is_model_key(key):
    return key.startswith('structure:') or key in MODEL_KEYS


# Options of the spectral product that the geometry topic recommends (advisor_geometry).
GEOMETRY_KEYS = ('spectral_kernel', 'spectral_z_bounds', 'spectral_reading')


def geometry_change(recommendation, options):
    """True when the recommendation moves the blob product between the pseudo-periodic direct sums and the
    spectral product, or changes the spectral kernel or z bounds (the geometry topic): the velocities then change
    by the current product's periodic error and the difference of the blob models."""
    vector = 'mobility_vector_prod_implementation'
    spectral_now = options.mobility_vector_prod_implementation == 'spectral'
    spectral_new = recommendation.get(vector, options.mobility_vector_prod_implementation) == 'spectral'
    return spectral_now != spectral_new or any(key in recommendation for key in GEOMETRY_KEYS)


def scope(recommendation, options, program):
    """Drop recommended options the program does not use; returns the notes of what was dropped."""
    notes, mcmc_dropped = [], []
    scheme = recommendation.get('scheme', options.scheme)
    for key in list(recommendation):
        name = key.split(':')[0]
        if program == 'mcmc' and (name in ('structure', 'blob_radius') or not is_used(name, 'mcmc', scheme)):
            del recommendation[key]
            mcmc_dropped.append(name)
        elif name == 'mobility_vector_prod_implementation' and program == 'static' and scheme in DENSE_BLOCK_SCHEMES:
            del recommendation[key]
            notes.append('scope: %s dropped: scheme %s builds dense blocks and does not use the blob vector product'
                         % (name, scheme))
        elif name == 'mobility_blobs_implementation' and (moves_rollers(scheme) or scheme_has(scheme, 'lubrication')):
            del recommendation[key]
            notes.append('scope: %s dropped: the %s schemes use the blob vector product only'
                         % (name, 'lubrication' if scheme_has(scheme, 'lubrication') else 'roller'))
        elif name in OPTION_TABLE and name != 'scheme' and OPTION_TABLE[name].used_by \
                and not is_used(name, program, scheme):
            del recommendation[key]
            notes.append('scope: %s dropped: a %s run with scheme %s does not use it' % (name, program, scheme))
    if mcmc_dropped:
        notes.append('scope: %s dropped: the Monte Carlo sampler uses no hydrodynamics (no solver, no mobility '
                     'backend, no time step, no hydrodynamic resolution); its results depend on the energy only'
                     % ', '.join(mcmc_dropped))
    if program == 'static' and 'scheme' in recommendation:
        notes.append('scope: scheme %s dropped: the static problem %s is what the user asked for'
                     % (recommendation.pop('scheme'), options.scheme))
    return notes


# ------------------------------------------------------------------ set-up of an input, quietly
def read_options(text, input_file, program):
    """Options of an input text (as the program reads it), warnings silenced."""
    with contextlib.redirect_stderr(io.StringIO()):
        return parse_input_text(text, input_file, None if program == 'mcmc' else program)


def set_up(options, program):
    """The Model of ``options`` as the program sets it up (start check included); UserInputError if refused."""
    from multi_bodies.run.run_setup import prepare
    script = {'dynamic': 'dynamics', 'static': 'static'}[program]
    with contextlib.redirect_stdout(io.StringIO()):
        return prepare(options, script, log=lambda line: None).system


def force_parts(system):
    """(rest (Nb, 6), {parameter: contribution (Nb, 6)}) of the forces-torques at the model's start configuration.

    Each per-blob parameter enters the default laws linearly, so its contribution is the force with only
    that parameter on minus the force with all of them off (``rest``: what does not depend on them).  The
    models compared are built from the user's (``Model.replace``), which stays as it is.
    """
    saved = dict(system.physics)
    configuration = system.start_configuration
    off = dict(saved, **{name: 0.0 for name in PER_BLOB_PARAMETERS})
    rest = system.replace(physics=off).forces_torques(configuration)
    parts = {}
    for name in PER_BLOB_PARAMETERS:
        parts[name] = system.replace(physics=dict(off, **{name: saved[name]})).forces_torques(configuration) - rest
    return rest, parts


def velocities(system, scheme):
    """Body velocities of one mobility problem: (Nb, 6), or (N, 3) linear velocities of rollers."""
    configuration = system.start_configuration
    if moves_rollers(scheme):
        return system.roller_velocities(configuration).velocities
    return system.deterministic_velocities(configuration).velocities


def force_difference(old, new, length):
    """Largest difference of the per-body forces and torques, relative to the user's largest (Nb, 6) each.

    Torques are measured against the larger of the largest torque and the largest force times ``length``
    (the body size), so that the residual torque of a sphere made of a few blobs is not compared with zero.
    """
    old, new = np.asarray(old).reshape(-1, 6), np.asarray(new).reshape(-1, 6)
    if not len(old):
        return 0.0
    force_scale = np.max(np.linalg.norm(old[:, :3], axis=1))
    torque_scale = max(np.max(np.linalg.norm(old[:, 3:], axis=1)), force_scale * length)
    worst = 0.0
    for part, scale in ((slice(0, 3), force_scale), (slice(3, 6), torque_scale)):
        difference = np.max(np.linalg.norm(new[:, part] - old[:, part], axis=1))
        if scale > 0:
            worst = max(worst, difference / scale)
        elif difference > 0:
            worst = np.inf
    return float(worst)


def velocity_difference(old, new, length):
    """Relative difference of body velocities; rotations measured as W x ``length`` against the speeds."""
    old, new = np.asarray(old), np.asarray(new)
    if old.shape != new.shape:  # rollers against rigid bodies: compare the linear velocities
        old, new = old.reshape(old.shape[0], -1)[:, :3], new.reshape(new.shape[0], -1)[:, :3]
    speed = np.max(np.linalg.norm(old[:, :3], axis=1))
    worst = np.max(np.linalg.norm(new[:, :3] - old[:, :3], axis=1)) / speed if speed > 0 else 0.0
    if old.shape[1] == 6:
        spin = max(np.max(np.linalg.norm(old[:, 3:], axis=1)) * length, speed)
        if spin > 0:
            worst = max(worst, np.max(np.linalg.norm(new[:, 3:] - old[:, 3:], axis=1)) * length / spin)
    return float(worst)


# ------------------------------------------------------------------ keep the physics, then check
class PhysicsCheck:
    """The user's model (Model, forces, velocities) and the checks of a recommendation against it.

    ``advisor``: the Advisor (its scene, recommendation, notes, files, accuracy, log).
    """

    def __init__(self, advisor):
        self.advisor = advisor
        scene = advisor.scene
        self.scene, self.options, self.program = scene, scene.options, advisor.program
        with open(scene.options.input_file) as f:
            self.text = f.read()
        self.ids = [s['ID'] for s in scene.structures]
        self.clones_map = {}
        self.subset_note = None
        self.neighbourhood(advisor.recommendation, advisor.files)
        self.user_system = set_up(self.options, self.program)
        self.user_rest, self.user_parts = force_parts(self.user_system)
        self.user_forces = self.user_rest + sum(self.user_parts.values())
        self.user_velocities = velocities(self.user_system, self.options.scheme)
        reference = scene.arrays.reference_blobs
        self.length = float(np.max(np.linalg.norm(reference - reference.mean(axis=0), axis=1))) + scene.a

    def neighbourhood(self, recommendation, files):
        """Large scenes: check on the bodies nearest the lowest body (at most CHECK_BLOB_LIMIT blobs).

        The bodies are written to temporary clones files and the input text (``self.text``,
        ``self.options``, ``self.ids``) is rewritten to use them; ``self.subset_note`` says so.
        """
        import tempfile
        from multi_bodies.files.snapshots import write_clones_file
        scene = self.scene
        arrays = scene.arrays
        blobs = np.diff(arrays.blob_offsets).astype(float)  # per body, the user's model
        for structure in scene.structures:
            value = recommendation.get('structure:%s' % structure['ID'])
            if value and value.split()[0] in files:
                blobs[structure['bodies']] = np.maximum(blobs[structure['bodies']], len(files[value.split()[0]][0]))
        if blobs.sum() <= CHECK_BLOB_LIMIT or arrays.num_bodies <= 2:
            return
        centres = np.asarray(arrays.configuration.locations)
        lowest = int(arrays.blob_body_index[int(np.argmin(scene.r_vectors[:, 2]))])
        order = np.argsort(np.linalg.norm(centres - centres[lowest], axis=1), kind='stable')
        count = int(max(2, np.searchsorted(np.cumsum(blobs[order]), CHECK_BLOB_LIMIT, side='right')))
        chosen = np.zeros(arrays.num_bodies, dtype=bool)
        chosen[order[:count]] = True
        folder = tempfile.mkdtemp(prefix='advice_check_')
        atexit.register(shutil.rmtree, folder, True)
        locations, orientations = arrays.configuration.locations, arrays.configuration.orientations
        lines, index, kept = [], 0, []
        for raw in self.text.splitlines():
            words = raw.split('#', 1)[0].split()
            if not words or words[0] != 'structure':
                lines.append(raw)
                continue
            structure = scene.structures[index]
            index += 1
            selected = np.flatnonzero(chosen[structure['bodies']]) + structure['bodies'].start
            if selected.size == 0:
                continue
            path = '%s/%s.clones' % (folder, structure['ID'])
            write_clones_file(path, np.asarray(locations)[selected], np.asarray(orientations)[selected])
            self.clones_map[words[2]] = path
            words[2] = path
            lines.append(' '.join(words))
            kept.append(structure['ID'])
        self.text = '\n'.join(lines) + '\n'
        self.ids = kept
        self.options = read_options(self.text, self.options.input_file, self.program)
        self.subset_note = ('on the %d bodies nearest the lowest body (the whole scene would need %d blobs with the '
                            'recommended model; the check is limited to %d)' % (count, int(blobs.sum()),
                                                                               CHECK_BLOB_LIMIT))

    def options_for_dt(self, recommendation):
        """Options the time step is measured on: the user's model with the recommended scheme.

        The recommended model moves like the user's within the target (the check), so the cheaper of the
        two is stepped: the user's, unless the recommended scheme needs the recommended bodies (rollers).
        """
        scheme = recommendation.get('scheme', self.options.scheme)
        if moves_rollers(scheme) == moves_rollers(self.options.scheme):
            if scheme == self.options.scheme:
                return self.options
            return self.recommended_options({'scheme': scheme})
        return self.recommended_options({k: v for k, v in recommendation.items()
                                         if k not in ('dt', 'n_steps', 'n_save')})

    def recommended_options(self, recommendation):
        from multi_bodies.advice.advisor_report import apply_recommendation
        adapted = {}
        for key, value in recommendation.items():
            if key.startswith('structure:'):
                if key.split(':', 1)[1] not in self.ids:
                    continue  # a structure type with no body in the checked neighbourhood
                words = value.split()
                words[1] = self.clones_map.get(words[1], words[1])
                value = ' '.join(words)
            adapted[key] = value
        text = apply_recommendation(self.text, adapted, self.ids)
        return read_options(text, self.options.input_file, self.program)

    def rescale(self, recommendation):
        """Put rescaled per-blob parameters into ``recommendation``; returns a note (or None when nothing changed)."""
        advisor = self.advisor
        options = self.recommended_options(recommendation)
        system = set_up(options, self.program)
        rest, parts = force_parts(system)
        total = np.max(np.linalg.norm(self.user_forces[:, :3], axis=1))
        said = []
        for name in PER_BLOB_PARAMETERS:
            old, new = self.user_parts[name], parts[name]
            value = getattr(options, name)
            if value == 0 or np.sum(new * new) == 0.0 or np.max(np.abs(old)) <= 1e-12 * max(total, 1e-300):
                continue
            factor = float(np.sum(old * new) / np.sum(new * new))
            if abs(factor - 1.0) > 1e-9:
                recommendation[name] = '%.12g' % (getattr(self.options, name) * factor)
                said.append('%s %g -> %s (x %.4g)' % (name, getattr(self.options, name), recommendation[name],
                                                      factor))
        if self.advisor.hooks_per_blob:
            advisor.notes.append('physics: your override file replaces %s, which acts per blob: its body total '
                                 'depends on the number of blobs; the check below decides whether the new model '
                                 'keeps it' % ', '.join(advisor.hooks_per_blob))
        if said:
            return ('physics: the new model has other blobs per body; gravity and the wall and pair repulsions act '
                    'per blob, so the per-blob parameters are rescaled to keep the total force and torque on each '
                    'body at the input positions (gravity exactly; wall and pair matched at the input heights): '
                    + '; '.join(said))
        return None

    def check(self, recommendation, allowed_velocity_error):
        """(holds, message): run the recommended input for one mobility problem and compare with the user's."""
        self.last = {}
        options = self.recommended_options(recommendation)
        try:
            system = set_up(options, self.program)
        except utils.UserInputError as err:
            return False, 'the recommended input is refused at set-up: %s' % err
        try:
            rest, parts = force_parts(system)
            forces = rest + sum(parts.values())
            new_velocities = velocities(system, options.scheme)
        except (utils.SimulationStopped, np.linalg.LinAlgError) as err:
            return False, 'the recommended input fails its first mobility problem: %s' % err
        if forces.shape != self.user_forces.shape:
            return False, 'the recommended input has %d bodies, the user\'s %d' % (len(forces), len(self.user_forces))
        force_error = force_difference(self.user_forces, forces, self.length)
        velocity_error = velocity_difference(self.user_velocities, new_velocities, self.length)
        holds = force_error <= self.advisor.accuracy and velocity_error <= allowed_velocity_error
        message = ('one mobility problem of the recommended input against the user\'s%s: total force and torque '
                   'per body differ by %.3g%% (target %.3g%%), body velocities by %.3g%% (allowed %.3g%%: the target '
                   'plus the user\'s model\'s own estimated error)' % (
                       ' (%s)' % self.subset_note if self.subset_note else '',
                       100 * force_error, 100 * self.advisor.accuracy, 100 * velocity_error,
                       100 * allowed_velocity_error))
        if force_error > self.advisor.accuracy:  # which law the new model does not keep
            shares = {name: force_difference(self.user_forces, self.user_forces - self.user_parts[name] + parts[name],
                                             self.length) for name in PER_BLOB_PARAMETERS}
            shares['other forces (hooks not scaled by these parameters)'] = force_difference(
                self.user_forces, self.user_forces - self.user_rest + rest, self.length)
            worst = max(shares, key=shares.get)
            message += ('; the largest mismatch is in the forces of %s (%.3g%%): one factor per parameter cannot '
                        'keep them for every body' % (worst, 100 * shares[worst]))
        self.last = dict(force_error=force_error, velocity_error=velocity_error, allowed=allowed_velocity_error,
                         holds=holds)
        return holds, message


def keep_physics(advisor):
    """Rescale the per-blob parameters of a model change and check the recommendation; drop it if it fails.

    Adds notes and ``advisor.check`` (dict of the check's numbers, or None when there was nothing to check).
    """
    recommendation = advisor.recommendation
    advisor.check = None
    if advisor.program == 'mcmc':
        return
    model_change = any(is_model_key(k) for k in recommendation) or (
        'scheme' in recommendation and moves_rollers(recommendation['scheme']) != moves_rollers(
            advisor.scene.options.scheme))
    if not recommendation:
        return
    try:
        checker = advisor.physics_check()
    except (utils.UserInputError, utils.SimulationStopped, np.linalg.LinAlgError) as err:
        advisor.notes.append('check: the input itself cannot be set up and solved as the program would (%s); '
                             'no model change is recommended' % err)
        for key in [k for k in recommendation if is_model_key(k) or k == 'scheme']:
            recommendation.pop(key)
        return
    if model_change:
        advisor.write_files()  # the recommended vertex files: the check reads the input as the program does
        try:
            note = checker.rescale(recommendation)
        except (utils.UserInputError, utils.SimulationStopped, np.linalg.LinAlgError) as err:
            note = None
            advisor.notes.append('physics: the recommended model could not be set up (%s)' % err)
        if note:
            advisor.notes.append(note)
    geometry = geometry_change(recommendation, advisor.scene.options)
    allowed = advisor.accuracy + (advisor.current_model_error() if model_change else 0.0) + (
        advisor.geometry_allowance() if geometry else 0.0)
    holds, message = checker.check(recommendation, allowed)
    advisor.check = dict(getattr(checker, 'last', {}), message=message, holds=holds)
    if holds:
        advisor.notes.append('check: holds: ' + message)
        return
    dropped = [k for k in recommendation if is_model_key(k) or k == 'scheme' or k in GEOMETRY_KEYS or (
        geometry and k == 'mobility_vector_prod_implementation')]
    for key in dropped:
        value = recommendation.pop(key)
        if key.startswith('structure:') and value.split()[0] in advisor.files and os.path.isfile(value.split()[0]):
            os.remove(value.split()[0])  # written for the check only
    advisor.notes.append('check: FAILED, so %s %s not recommended: %s' % (
        ', '.join(k.split(':')[0] if not k.startswith('structure:') else 'structure %s' % k.split(':')[1]
                  for k in dropped) or 'nothing', 'is' if len(dropped) == 1 else 'are', message))
    if recommendation:
        holds, message = checker.check(recommendation, advisor.accuracy)
        advisor.check = dict(getattr(checker, 'last', {}), message=message, holds=holds)
        advisor.notes.append('check of the remaining lines: %s: %s' % ('holds' if holds else 'FAILED', message))
        if not holds:
            recommendation.clear()


# ------------------------------------------------------------------ time step
def blob_speeds(system, body_velocities, scheme):
    """Speed of every blob (N,) from body velocities (Nb, 6) (rigid motion) or roller velocities (N, 3)."""
    v = np.asarray(body_velocities)
    if moves_rollers(scheme):
        return np.linalg.norm(v.reshape(-1, 3), axis=1)
    blob_v = system.arrays.K_dot(system.start_configuration, v.reshape(-1, 6))
    return np.linalg.norm(np.asarray(blob_v).reshape(-1, 3), axis=1)


def trajectory(options, scheme_name, dt, steps):
    """Body locations (Nb, 3) after ``steps`` steps of ``scheme_name`` at ``dt`` from the input configuration.

    Raises utils.SimulationStopped (a blob below the wall, GMRES not converged) or LinAlgError.
    """
    from quaternion_integrator.schemes import make_scheme
    model = set_up(options, 'dynamic')
    scheme = make_scheme(scheme_name, dt, options)
    state = scheme.init(model, model.start_configuration)
    for _ in range(steps):
        state = scheme.step(model, state, None)
    return np.array(state.configuration.locations, dtype=float)


def measured_dt(options, scheme_name, dt_start, accuracy, steps=4, refinements=6):
    """The time step whose measured error per unit time meets ``accuracy`` (step doubling), and how it was found.

    From ``dt_start`` (the hard bounds: stability and no crossing), the scene is run over the horizon
    ``steps * dt`` at dt, dt/2 and dt/4; the observed order ``p = log2(|x1 - x2| / |x2 - x3|)`` and the
    Richardson estimate of the error at dt, ``e = |x1 - x2| 2^p / (2^p - 1)`` relative to the largest
    body displacement over the horizon (a relative displacement error; over a horizon of a few steps it
    is the error per unit time times the horizon over the displacement time, the same at any horizon
    for steady motion), give ``dt* = dt (accuracy / e)^(1/p)``.  When dt* is well below dt the
    measurement is repeated from dt* (at most ``refinements`` times).  A run that stops (a blob through
    the wall) divides dt by 4.

    Returns dict(dt (float, <= dt_start), error (measured at the returned dt, None if extrapolated), order,
    horizon, tries: list of (dt, outcome text), verified).
    """
    dt, tries = float(dt_start), []
    result = None
    for _ in range(refinements + 4):
        try:
            x0 = np.array(set_up(options, 'dynamic').start_configuration.locations, dtype=float)
            x1, x2, x3 = (trajectory(options, scheme_name, dt / k, steps * k) for k in (1, 2, 4))
        except (utils.SimulationStopped, np.linalg.LinAlgError) as err:
            tries.append((dt, 'stops: %s' % str(err).split(';')[0]))
            dt /= 4.0
            continue
        displacement = np.max(np.linalg.norm(x3 - x0, axis=1))
        d12, d23 = np.max(np.linalg.norm(x1 - x2, axis=1)), np.max(np.linalg.norm(x2 - x3, axis=1))
        if displacement == 0 or d12 == 0:
            tries.append((dt, 'no error measurable (displacement %.3g)' % displacement))
            return dict(dt=dt, error=0.0, order=None, horizon=steps * dt, tries=tries, verified=True)
        order = float(np.clip(np.log2(d12 / d23), 0.5, 3.0)) if d23 > 0 else 3.0
        error = d12 * 2 ** order / (2 ** order - 1) / displacement
        tries.append((dt, 'error %.3g%% over %d steps (observed order %.2f)' % (100 * error, steps, order)))
        if error <= accuracy:  # measured, not extrapolated: this dt meets the target
            return dict(dt=dt, error=error, order=order, horizon=steps * dt, tries=tries, verified=True)
        target_dt = dt * (accuracy / error) ** (1.0 / order)
        result = dict(dt=target_dt, error=None, order=order, horizon=steps * dt, tries=tries, verified=False)
        dt = min(target_dt, 0.5 * dt)
    return result or dict(dt=dt, error=None, order=None, horizon=steps * dt, tries=tries, verified=False)


def dt_bounds(stability_dt, speed, wall_gap, pair_gap):
    """Hard bounds on the time step, list of (name, dt, reason).

    stability_dt: the linear-stability limit (inf if unknown); speed: the largest blob speed at the start;
    wall_gap: the lowest blob height (distance to z = 0, where a run stops); pair_gap: the smallest
    distance between blobs of two bodies (inf with one body).
    """
    bounds = [('stability', stability_dt, 'linear stability of the scheme on the stiffest force (dt mu k)')]
    if speed > 0:
        bounds.append(('no crossing', 0.5 * wall_gap / speed,
                       'a step moves no blob more than half its height above the wall (%.3g)' % wall_gap))
        if np.isfinite(pair_gap):
            bounds.append(('no crossing of bodies', 0.25 * pair_gap / speed,
                           'two bodies close at most half their blob gap (%.3g) per step' % pair_gap))
    return bounds
