"""The published ``articulated.articulated`` and ``constraint.constraint`` classes as faces over the package's joints,
patched by a run-and-tumble override as the published ``bacteria_run_and_tumble`` folder does (issue 30).

The folder is not in the reference tree; the scene is built from its README (the manual's description): the
published bacterium (body and flagellum, two joints on the flagellum axis), a constant torque between them, and
a ``.const`` line with the extra fields ``dt tau tumbling_period max_angle l00 l01 l10``.  The override (written
here from that description) patches ``Constraint.__init__`` (a ``tumbling_time``), adds
``Constraint.tumbling_event(t)`` (a tumble starts with probability ``1 - exp(-dt / tau)`` when none is active) and
patches ``Constraint.update_links`` (during a tumble the flagellum's joint moves off the axis by the angle
``max_angle pi sin^2(pi s / period)``).  Checked: the run calls ``tumbling_event`` once per step at ``t = step dt``;
the flagellum tilts during a tumble and not without one (negative control); the rate of tumbles equals 1/tau
within four standard errors, and tau twice as long fails that test (negative control).
"""
import shutil

import numpy as np
import pytest

from multi_bodies.files.input_options import read_input_file
from multi_bodies.run.dynamic_run import run_dynamics
from multi_bodies.run.run_setup import prepare
from multi_bodies.files import snapshots

OVERRIDE = '''
import numpy as np
import multi_bodies_functions
from multi_bodies_functions import *
from articulated.articulated import *
from constraint.constraint import *

CALLS = []

def torque_between_body_and_flagellum(bodies, r_vectors, *args, **kwargs):
    torque = kwargs.get('omega_one_roller')
    out = np.zeros((2 * len(bodies), 3))
    for i, b in enumerate(bodies):
        out[2 * i + 1] = (1 if i % 2 == 0 else -1) * np.dot(b.orientation.rotation_matrix(), torque)
    return out
multi_bodies_functions.calc_body_body_forces_torques_python = torque_between_body_and_flagellum

original_init = Constraint.__init__
def init_with_tumbling_time(self, bodies, ind_bodies, articulated_body, links, constraint_extra=None):
    original_init(self, bodies, ind_bodies, articulated_body, links, constraint_extra)
    self.tumbling_time = -1e3
Constraint.__init__ = init_with_tumbling_time

def tumbling_event(self, t):
    CALLS.append(t)
    with open('tumbling_calls.txt', 'a') as f:
        f.write('%r\\n' % t)
    if len(self.constraint_extra) > 0:
        dt, tau, period = (float(w) for w in self.constraint_extra[:3])
        if t - self.tumbling_time > period and np.random.rand() < 1 - np.exp(-dt / tau):
            self.tumbling_time = t
Constraint.tumbling_event = tumbling_event

def update_links(self, time=0):
    if len(self.constraint_extra) > 0:
        period, max_angle, l00, l01, l10 = (float(w) for w in self.constraint_extra[2:7])
        s = time - self.tumbling_time
        alpha = max_angle * np.pi * np.sin(np.pi * s / period) ** 2 if s <= period else 0.0
        rate = (max_angle * np.pi ** 2 / period) * np.sin(2 * np.pi * s / period) if s <= period else 0.0
        self.links[:] = [l01 * np.sin(alpha), 0, l00 + l01 * np.cos(alpha), 0, 0, l10]
        self.links_deriv[:] = [l01 * np.cos(alpha) * rate, 0, -l01 * np.sin(alpha) * rate, 0, 0, 0]
    Constraint_update_links(self, time)
Constraint_update_links = Constraint.update_links
Constraint.update_links = update_links
'''


def scene(tmp_path, reference_dir, tau, period=0.01, n_steps=6):
    """The published bacteria folder with a tumbling joint (extra fields) and the override above."""
    published = reference_dir / 'published_2025' / 'multi_bodies'
    shutil.copytree(published / 'Structures', tmp_path / 'Structures')
    folder = tmp_path / 'examples' / 'bacteria_run_and_tumble'
    folder.mkdir(parents=True)
    (tmp_path / 'Structures' / 'bacteria_tumble.const').write_text(
        '2\n2\n0 1   0 0 1.1310     0 0 -0.1310\n'
        '0 1   0 0 2.1310     0 0  0.869   0.0025  %r  %r  0.25  1.131  1  0.869\n' % (tau, period))
    text = (published / 'examples' / 'bacteria' / 'inputfile_bacteria_constant_torque.dat').read_text()
    text = text.replace('bacteria_passive.const', 'bacteria_tumble.const').replace('n_steps 8', 'n_steps %d' % n_steps)
    (folder / 'inputfile.dat').write_text(text + 'seed 3\n')
    (folder / 'user_defined_functions.py').write_text(OVERRIDE)
    return folder


def tilt(frames):
    """Angle (rad) between the body's and the flagellum's z axes in every frame (n_frames,)."""
    def axis(q):
        s, p = q[..., 0], q[..., 1:]
        return np.stack([2 * (p[..., 0] * p[..., 2] + s * p[..., 1]), 2 * (p[..., 1] * p[..., 2] - s * p[..., 0]),
                         1 - 2 * (p[..., 0] ** 2 + p[..., 1] ** 2)], axis=-1)
    a, b = axis(frames[:, 0, 3:]), axis(frames[:, 1, 3:])
    return np.arccos(np.clip(np.sum(a * b, axis=-1), -1, 1))


@pytest.mark.parametrize('tau, tumbles', [(1e-6, True), (1e6, False)])
def test_run_calls_tumbling_event_every_step_and_the_flagellum_follows_the_links(tmp_path, reference_dir,
                                                                                  monkeypatch, tau, tumbles):
    folder = scene(tmp_path, reference_dir, tau)
    monkeypatch.chdir(folder)
    options = read_input_file('inputfile.dat', 'dynamic')
    assert run_dynamics(options, log=lambda *a: None) == 0
    calls = [float(x) for x in (folder / 'tumbling_calls.txt').read_text().split()]
    # every joint's tumbling_event once per step, at the step's start (two joints)
    assert calls == pytest.approx([k * 0.0025 for k in range(6) for _ in range(2)], abs=1e-15)
    frames = snapshots.read_config_frames('run_constant_torque.bacteria_constant_torque.config')
    if tumbles:  # a tumble from t = 0: the flagellum turns off the body's axis
        assert tilt(frames)[-1] > 0.05
    else:
        assert tilt(frames).max() < 1e-6


def test_tumbling_rate_is_one_over_tau(tmp_path, reference_dir, monkeypatch):
    """Tumbles of period shorter than dt: each step one Bernoulli draw, p = 1 - exp(-dt / tau); over 20,000
    steps the count is within 4 standard errors sqrt(N p (1 - p)) of N p; with tau twice as long it is not."""
    dt, tau, steps = 0.0025, 0.025, 20000
    folder = scene(tmp_path, reference_dir, tau, period=1e-4)
    monkeypatch.chdir(folder)
    setup = prepare(read_input_file('inputfile.dat', 'dynamic'), 'dynamics', log=lambda *a: None)
    articulated = setup.system.articulated
    np.random.seed(11)
    starts = 0
    for k in range(steps):
        articulated.step_event(k * dt)
        links, _ = articulated.links(k * dt + 0.5e-4)  # inside a tumble started at this step: the joint is off axis
        starts += int(abs(links[1, 0]) > 1e-12)
    for tau_law, inside in ((tau, True), (2 * tau, False)):
        p = 1 - np.exp(-dt / tau_law)
        z = (starts - steps * p) / np.sqrt(steps * p * (1 - p))
        assert (abs(z) < 4) == inside, (tau_law, starts, steps * p, z)


@pytest.mark.parametrize('scheme', ['midpoint', 'forward_euler'])
def test_articulated_schemes_move_plain_bodies_as_the_rigid_schemes(tmp_path, monkeypatch, scheme):
    """An articulated scheme on plain ``structure`` lines (the published ``mapping/inputfile_slip.dat``): no joint,
    so the same trajectory as ``deterministic_<scheme>`` (measured: identical, 0.0).  Negative control: the two
    bodies do move (0.18 in 4 steps)."""
    from run_scenes import SCRIPT_DIR
    shutil.copyfile(SCRIPT_DIR / 'Structures' / 'shell_N_12_Rg_1.vertex', tmp_path / 'shell.vertex')
    (tmp_path / 's.clones').write_text('2\n0 0 3 1 0 0 0\n2.5 0 3.5 1 0 0 0\n')
    monkeypatch.chdir(tmp_path)
    frames = {}
    for name in ('articulated_deterministic_' + scheme, 'deterministic_' + scheme):
        (tmp_path / (name + '.dat')).write_text(
            'scheme %s\nmobility_blobs_implementation python\nmobility_vector_prod_implementation python\ndt 0.1\n'
            'n_steps 4\nn_save 4\neta 1\ng 1\nblob_radius 0.25\nsolver_tolerance 1e-12\nsave_clones one_file\n'
            'output_name %s\nstructure shell.vertex s.clones\n' % (name, name))
        assert run_dynamics(read_input_file(name + '.dat', 'dynamic'), log=lambda *a: None) == 0
        frames[name] = snapshots.read_config_frames(name + '.s.config')
    ours, rigid = frames.values()
    assert np.abs(ours - rigid).max() < 1e-12
    assert np.abs(ours[-1] - ours[0]).max() > 0.1


# ---------------------------------------------------------------------------------------------- run and tumble
# An override with the conventions of the published bacteria_run_and_tumble folder (issue 47), written here: the
# joints are restored after every move with the links of Articulated.update_links (the flagellum tilted by alpha),
# while the velocity solve takes Constraint.update_links, whose tilt differs (l01 sin^2 alpha off the axis) and
# whose rate is set in links_deriv_updated during a tumble and zeroed there afterwards, links_deriv keeping its last
# value.  Reading links_deriv, or restoring with the solve's links (two joints that no rigid pair can hold at once),
# made the published folder jump 28 to 600 length units per tumble.
# The imports and the constant torque between body and flagellum of OVERRIDE (above), then the tumbling joints.
TUMBLE_OVERRIDE = OVERRIDE[:OVERRIDE.index('CALLS = []')] + OVERRIDE[OVERRIDE.index('def torque_between'):
                                                                   OVERRIDE.index('original_init')] + '''
base_init = Constraint.__init__
def init(self, bodies, ind_bodies, articulated_body, links, constraint_extra=None):
    base_init(self, bodies, ind_bodies, articulated_body, links, constraint_extra)
    self.tumbling_time = -1000.0
Constraint.__init__ = init

def tumbling_event(self, t):
    if len(self.constraint_extra) > 0:
        dt, tau, period = (float(w) for w in self.constraint_extra[:3])
        if t - self.tumbling_time > period and np.random.rand(1) < 1 - np.exp(-dt / tau):
            self.tumbling_time = t
Constraint.tumbling_event = tumbling_event

def tilt(extra, s):
    period, max_angle = float(extra[2]), float(extra[3])
    return max_angle * np.pi * np.sin(np.pi * s / period) ** 2 if s <= period else None

def articulated_links(self, time=0):
    for i in range(self.num_constraints):
        extra = self.constraints_extra[i]
        if len(extra) > 0:
            l00, l01, l10 = (float(w) for w in extra[4:7])
            alpha = tilt(extra, time - self.constraints[i].tumbling_time)
            alpha = 0.0 if alpha is None else alpha
            self.constraints_links[i] = [l01 * np.sin(alpha), 0, l00 + l01 * np.cos(alpha), 0, 0, l10]
Articulated.update_links = articulated_links

def constraint_links(self, time=0):
    extra = self.constraint_extra
    if len(extra) > 0:
        period = float(extra[2])
        l00, l01, l10 = (float(w) for w in extra[4:7])
        alpha = tilt(extra, time - self.tumbling_time)
        R_p = self.bodies[0].orientation.rotation_matrix()
        if alpha is not None:
            self.links[:] = [l01 * np.sin(alpha) ** 2, 0, l00 + l01 * np.cos(alpha), 0, 0, l10]
            self.links_deriv[:] = [np.pi * l01 / period * np.cos(alpha), 0, -np.pi * l01 / period * np.sin(alpha),
                                   0, 0, 0]
            self.links_deriv_updated[:3] = R_p @ self.links_deriv[:3]
            self.links_deriv_updated[3:] = 0
        else:
            self.links[:] = [0, 0, l00 + l01, 0, 0, l10]
            self.links_deriv_updated[:] = 0
    self.links_updated[:3] = self.bodies[0].orientation.rotation_matrix() @ self.links[:3]
    self.links_updated[3:] = self.bodies[1].orientation.rotation_matrix() @ self.links[3:]
Constraint.update_links = constraint_links
'''
TUMBLE_PERIOD, L01, MAX_ANGLE = 0.05, 1.0, np.pi / 3


def tumble_scene(tmp_path, reference_dir, tau, n_steps):
    """The published bacterium (its flagellum's vertex file with a fourth column: every radius blob_radius) with
    the run-and-tumble joints and override above, forward Euler as the published folder; returns the folder."""
    published = reference_dir / 'published_2025' / 'multi_bodies'
    structures = tmp_path / 'Structures'
    shutil.copytree(published / 'Structures', structures)
    flagellum = snapshots_vertex_with_radii(structures / 'flagellum_L_10_alpha_0.35.vertex', 0.131)
    (structures / 'bacteria_radii.list_vertex').write_text('../../Structures/shell_N_162_Rg_0_9497_Rh_1.vertex\n'
                                                           '../../Structures/%s\n' % flagellum.name)
    (structures / 'bacteria_tumble.const').write_text(
        '2\n2\n0 1   0 0 1.1310     0 0 -0.1310\n'
        '0 1   0 0 2.1310     0 0  0.869   0.0025  %r  %r  %r  1.131  %r  0.869\n'
        % (tau, TUMBLE_PERIOD, MAX_ANGLE, L01))
    folder = tmp_path / 'examples' / 'bacteria_run_and_tumble'
    folder.mkdir(parents=True)
    text = (published / 'examples' / 'bacteria' / 'inputfile_bacteria_constant_torque.dat').read_text()
    text = (text.replace('bacteria_passive.const', 'bacteria_tumble.const')
            .replace('bacteria.list_vertex', 'bacteria_radii.list_vertex')
            .replace('articulated_deterministic_midpoint', 'articulated_deterministic_forward_euler')
            .replace('n_steps 8', 'n_steps %d' % n_steps))
    (folder / 'inputfile.dat').write_text(text + 'seed 3\n')
    (folder / 'user_defined_functions.py').write_text(TUMBLE_OVERRIDE)
    return folder


def snapshots_vertex_with_radii(path, radius):
    """A copy of the vertex file at ``path`` with a fourth column ``radius``; returns its path."""
    rows = [line.split() for line in path.read_text().splitlines() if line.strip() and not line.startswith('#')]
    out = path.with_name(path.stem + '_radii.vertex')
    out.write_text('%s\n' % rows[0][0] + ''.join('%s %s %s %r\n' % (x, y, z, radius) for x, y, z in rows[1:]))
    return out


@pytest.mark.slow
def test_run_and_tumble_keeps_its_joints_and_moves_at_the_speed_of_its_links(tmp_path, reference_dir, monkeypatch):
    """A tumble from t = 0 (tau 1e-6) over the first half of its period (the fastest tilt), against the same
    bacterium without tumbles (tau 1e6, negative control of the tilt).  Laws: at every saved step the joints hold
    the links of ``Articulated.update_links`` to ``nonlinear_solver_tolerance`` (1e-10); and no body moves in one
    step further than the untumbled bacterium's largest step plus the largest change of the tilted link in one
    step, ``l01 max_angle pi^2 dt / period`` (0.52 for a flagellum 4.3 long).  Measured: residuals 1.5e-15, largest
    step 0.44 against the bound 0.52 (0.007 untumbled); before the fix a residual of 0.15 and a step of 74."""
    from multi_bodies.solver import articulated as art
    from body.body import Configuration
    n_steps, dt = 10, 0.0025
    steps = {}
    for tau in (1e6, 1e-6):
        folder = tumble_scene(tmp_path / ('tau_%g' % tau), reference_dir, tau, n_steps)
        monkeypatch.chdir(folder)
        options = read_input_file('inputfile.dat', 'dynamic')
        assert run_dynamics(options, log=lambda *a: None) == 0
        frames = snapshots.read_config_frames('run_constant_torque.bacteria_constant_torque.config')
        assert frames.shape[0] == n_steps + 1
        steps[tau] = np.linalg.norm(np.diff(frames[:, :, :3], axis=0), axis=2).max()
        if tau < 1:  # the joints at the links the override restores them to, at every saved time
            joints = prepare(options, 'dynamics', log=lambda *a: None).system.articulated
            np.random.seed(0)
            joints.step_event(0.0)  # the tumble starts at t = 0 (probability 1 - exp(-dt / 1e-6))
            residuals = [np.abs(joints.violation(Configuration(f[:, :3], f[:, 3:]), k * dt)).max()
                         for k, f in enumerate(frames)]
            assert max(residuals) < 1e-10, residuals
            assert tilt(frames)[-1] > 0.3  # the flagellum tilted (0.5 rad measured)
    bound = steps[1e6] + L01 * MAX_ANGLE * np.pi ** 2 * dt / TUMBLE_PERIOD
    assert steps[1e-6] <= bound, (steps, bound)


def test_prescribed_joint_rates_are_read_from_links_deriv_updated(tmp_path, reference_dir, monkeypatch):
    """After a tumble the override zeroes links_deriv_updated and leaves links_deriv at its last value (pi l01 /
    period): the solve's rates are the former (zero), as published; during the tumble they are R_p links_deriv
    (identity frames here: the body-frame derivative of the override, (pi l01 / T) (cos alpha, 0, -sin alpha))."""
    folder = tumble_scene(tmp_path, reference_dir, 1e-6, 1)
    monkeypatch.chdir(folder)
    joints = prepare(read_input_file('inputfile.dat', 'dynamic'), 'dynamics', log=lambda *a: None).system.articulated
    np.random.seed(0)
    joints.step_event(0.0)
    s = 0.3 * TUMBLE_PERIOD
    alpha = MAX_ANGLE * np.pi * np.sin(np.pi * s / TUMBLE_PERIOD) ** 2
    _, rates = joints.links(s)
    speed = np.pi * L01 / TUMBLE_PERIOD
    assert rates[1] == pytest.approx([speed * np.cos(alpha), 0, -speed * np.sin(alpha), 0, 0, 0], abs=1e-12)
    _, rates = joints.links(2 * TUMBLE_PERIOD)  # the tumble is over
    assert np.all(rates == 0)
    # the restoration's links (Articulated.update_links) tilt by alpha, the solve's by sin^2 alpha
    position_links, _ = joints.links(s, positions=True)
    solve_links, _ = joints.links(s)
    assert position_links[1, 0] == pytest.approx(L01 * np.sin(alpha), abs=1e-14)
    assert solve_links[1, 0] == pytest.approx(L01 * np.sin(alpha) ** 2, abs=1e-14)


# ------------------------------------------------------------------- the published random stream of the tumbles
def test_numpy_global_stream_is_the_published_generator_inside_the_block():
    """Inside ``drawn_by_numpy_global(rng)`` numpy's global stream draws ``rng``'s numbers (the published code seeds
    the global stream with ``seed``) and ``rng`` continues after them; the global stream gets its state back.  With
    numpy's Generator (``random_generator default``) nothing is shared (control)."""
    from stochastic_forcing.generators import PublishedGenerator, drawn_by_numpy_global
    legacy = np.random.RandomState(7)
    expected = legacy.rand(3)
    np.random.seed(11)
    global_first = np.random.RandomState(11).rand()
    rng = PublishedGenerator(7)
    with drawn_by_numpy_global(rng):
        drawn = np.random.rand(3)
    assert np.array_equal(drawn, expected)
    assert rng.random() == legacy.rand()  # the run's generator continues after the block's draws
    assert np.random.rand() == global_first  # the global stream was left where it was
    other = np.random.default_rng(7)
    np.random.seed(11)
    with drawn_by_numpy_global(other):
        assert np.random.rand() == global_first


def test_tumbles_start_at_the_draws_of_the_run_generator(tmp_path, reference_dir, monkeypatch):
    """``random_generator published`` and ``seed 3``: the override's ``np.random.rand(1)`` in ``tumbling_event``
    draws numpy's legacy stream seeded 3, as the published code (which seeds the global stream) draws it, so the
    tumble starts at the first step whose draw is below 1 - exp(-dt / tau) = 1/2, and the run's generator ends after
    exactly those draws.  Control: numpy's Generator (the default) leaves the draws to the global stream (seeded
    here with 12345), whose first tumble is elsewhere."""
    from quaternion_integrator.articulated_schemes import ArticulatedScheme
    from quaternion_integrator.scheme_state import StepContext
    from stochastic_forcing.generators import PublishedGenerator
    dt, period = 0.0025, TUMBLE_PERIOD
    tau = float(dt / np.log(2.0))
    folder = tumble_scene(tmp_path, reference_dir, tau, 1)
    monkeypatch.chdir(folder)

    def first_tumble(draws):
        return next(k for k, u in enumerate(draws) if u < 1 - np.exp(-dt / tau))

    expected = {3: first_tumble(np.random.RandomState(3).rand(50)), 12345: first_tumble(np.random.RandomState(12345).rand(50))}
    assert expected[3] != expected[12345]  # the control can tell the streams apart
    for rng, seed in ((PublishedGenerator(3), 3), (np.random.default_rng(3), 12345)):
        model = prepare(read_input_file('inputfile.dat', 'dynamic'), 'dynamics', log=lambda *a: None).system
        joints = model.articulated
        np.random.seed(12345)
        started = None
        for k in range(expected[seed] + 3):
            ArticulatedScheme.step_event(None, StepContext(model, k, rng), k * dt)
            _, rates = joints.links(k * dt)
            if started is None and np.any(rates[1] != 0):
                started = k
        assert started == expected[seed], (seed, started, expected)
        if seed == 3:  # one draw a step until the tumble, none during it
            check = np.random.RandomState(3)
            check.rand(expected[3] + 1)
            assert rng.random() == check.rand()


def test_articulated_preconditioner_over_the_neighbour_preconditioner(tmp_path, reference_dir, monkeypatch):
    """Under ``preconditioner auto``, an articulated body too large for the exact group solve gets the published
    Schur complement over the model's body preconditioner, which is then the neighbour preconditioner (it crashed
    when that stopped forwarding the block-diagonal attributes: the published bacteria_run_and_tumble folder,
    570 blobs, takes this path).  The step equals the one under ``block_diagonal`` to the solver tolerance."""
    from multi_bodies.solver import articulated_preconditioner
    monkeypatch.setattr(articulated_preconditioner, 'AUTO_MAX_PRODUCTS', -1.0)  # refuse the group solve
    frames = {}
    for choice in ('auto', 'block_diagonal'):
        folder = tumble_scene(tmp_path / choice, reference_dir, 1e6, 1)
        monkeypatch.chdir(folder)
        with open('inputfile.dat', 'a') as f:
            f.write('preconditioner %s\n' % choice)
        options = read_input_file('inputfile.dat', 'dynamic')
        assert run_dynamics(options, log=lambda *a: None) == 0
        frames[choice] = snapshots.read_config_frames('run_constant_torque.bacteria_constant_torque.config')
    moved = np.abs(frames['auto'][-1, :, :3] - frames['auto'][0, :, :3]).max()
    assert moved > 1e-4
    assert np.abs(frames['auto'] - frames['block_diagonal']).max() < 1e-6 * max(moved, 1.0)


# the bodies are flung below the wall; the wall force's unused branch of np.where overflows there
@pytest.mark.filterwarnings('ignore:overflow encountered in exp:RuntimeWarning',
                            'ignore:invalid value encountered in multiply:RuntimeWarning')
def test_restoring_with_the_solve_links_makes_the_tumbling_bacterium_jump(tmp_path, reference_dir, monkeypatch):
    """Negative control of the step bound above: the same tumble with the joints restored with the solve's links
    (``Constraint.update_links``, the flagellum's joint off the axis by ``l01 sin^2 alpha``, which no rigid
    flagellum can hold together with the other joint) instead of ``Articulated.update_links`` (the mistake that
    made the published folder jump 28 to 600 units per tumble) breaks the bound: a step of 200 measured against
    the bound 0.53."""
    from multi_bodies.solver import published_joints
    attach = published_joints.attach

    def attach_without_articulated(articulated, constraint_class=None, articulated_class=None, joint_class=None):
        return attach(articulated, constraint_class, None, joint_class)
    monkeypatch.setattr(published_joints, 'attach', attach_without_articulated)
    n_steps, dt = 10, 0.0025
    folder = tumble_scene(tmp_path, reference_dir, 1e-6, n_steps)
    monkeypatch.chdir(folder)
    options = read_input_file('inputfile.dat', 'dynamic')
    assert run_dynamics(options, log=lambda *a: None) == 0
    frames = snapshots.read_config_frames('run_constant_torque.bacteria_constant_torque.config')
    largest = np.linalg.norm(np.diff(frames[:, :, :3], axis=0), axis=2).max()
    bound = 0.01 + L01 * MAX_ANGLE * np.pi ** 2 * dt / TUMBLE_PERIOD  # untumbled step (0.007) plus the link's tilt
    assert largest > bound, (largest, bound)
