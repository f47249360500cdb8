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
