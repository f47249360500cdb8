"""Published-style hooks receive every keyword the published code passes to any of them (issue 30).

``PUBLISHED_KEYWORDS`` lists, per hook, the keywords that the published main programs pass (``multi_bodies.py``:
``calc_one_blob_forces`` g, repulsion_strength_wall, debye_length_wall; ``calc_blob_blob_forces`` and
``force_torque_calculator_sort_by_bodies`` also repulsion_strength, debye_length, periodic_length; the articulated
branch omega_one_roller; the lubrication branch eta, a; the program of ``Multi_Blob_Two_Rollers`` eta,
particle_radius, omega_one_roller) and that the published example overrides read (``Radial_Dist_Test``:
blob_mass, blob_radius, tilt_angle).  These lists are read from the published code, not from this package.
A run with recording overrides shows that every hook gets them all; the negative control: a lubrication-only
keyword (``mu``) is not passed, so the recorder does tell present from absent.
"""
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from run_scenes import SCRIPT_DIR, run_in_process

from multi_bodies.solver import physics

COMMON = {'g', 'repulsion_strength_wall', 'debye_length_wall', 'repulsion_strength', 'debye_length',
          'periodic_length'}
PUBLISHED_KEYWORDS = {
    'blob_external_force': {'g', 'repulsion_strength_wall', 'debye_length_wall', 'blob_mass', 'blob_radius',
                            'tilt_angle'},
    'blob_blob_force': COMMON | {'blob_radius'},
    'bodies_external_force_torque': COMMON | {'eta', 'a', 'particle_radius', 'omega_one_roller'},
    'body_body_force_torque': COMMON | {'eta', 'a', 'particle_radius', 'omega_one_roller'},
    'calc_body_body_forces_torques_python': COMMON | {'omega_one_roller'},
}

RECORDER = '''
import json
import numpy as np
import multi_bodies_functions
from multi_bodies_functions import *

def record(hook, kwargs):
    with open('keywords.%s.json' % hook, 'w') as f:
        json.dump(sorted(kwargs), f)

def blob_external_force_new(r_vectors, *args, **kwargs):
    record('blob_external_force', kwargs)
    return np.zeros(3)
multi_bodies_functions.blob_external_force = blob_external_force_new

def blob_blob_force_new(r, *args, **kwargs):
    record('blob_blob_force', kwargs)
    return 0 * r
multi_bodies_functions.blob_blob_force = blob_blob_force_new

def bodies_external_force_torque_new(bodies, r_vectors, *args, **kwargs):
    record('bodies_external_force_torque', kwargs)
    return np.zeros((2 * len(bodies), 3))
multi_bodies_functions.bodies_external_force_torque = bodies_external_force_torque_new
'''
PAIR_LAW = '''
def body_body_force_torque_new(r, quaternion_i, quaternion_j, *args, **kwargs):
    record('body_body_force_torque', kwargs)
    return np.zeros((2, 3))
multi_bodies_functions.body_body_force_torque = body_body_force_torque_new
'''
BODIES_LAW = '''
def calc_body_body_forces_torques_python_new(bodies, r_vectors, *args, **kwargs):
    record('calc_body_body_forces_torques_python', kwargs)
    return np.zeros((2 * len(bodies), 3))
multi_bodies_functions.calc_body_body_forces_torques_python = calc_body_body_forces_torques_python_new
'''

TWO_SHELLS = '2\n-1.5 0 1.2 1 0 0 0\n1.5 0 1.2 1 0 0 0\n'


def two_shell_scene(folder, override, **options):
    """Two 12-blob shells of hydrodynamic radius 1 at height 1.2, the given override file and options."""
    folder.mkdir(parents=True)
    (folder / 'Structures').mkdir()
    shutil.copyfile(SCRIPT_DIR / 'Structures' / 'shell_N_12_Rg_0_7921_Rh_1.vertex',
                    folder / 'Structures' / 'shell.vertex')
    (folder / 'two_rollers.clones').write_text(TWO_SHELLS)
    (folder / 'user_defined_functions.py').write_text(override)
    values = dict(scheme='deterministic_forward_euler', mobility_vector_prod_implementation='numba',
                  mobility_blobs_implementation='python', blob_blob_force_implementation='python',
                  body_body_force_torque_implementation='python', dt=0.01, n_steps=1, n_save=1, eta=1e-3,
                  g=0.0024892, blob_radius=0.41642068, repulsion_strength=0.0165677856, debye_length=0.1,
                  repulsion_strength_wall=0.0165677856, debye_length_wall=0.1, solver_tolerance=1e-6,
                  output_name='run_two_rollers/data', save_clones='one_file')
    values.update(options)
    text = ''.join('%s %s\n' % item for item in values.items())
    (folder / 'inputfile_rollers.dat').write_text(text + 'structure Structures/shell.vertex two_rollers.clones\n')
    (folder / 'run_two_rollers').mkdir()
    return folder


@pytest.mark.parametrize('laws', ['pair', 'bodies'])
def test_every_hook_gets_every_published_keyword(tmp_path, laws):
    folder = two_shell_scene(tmp_path / 'scene', RECORDER + (PAIR_LAW if laws == 'pair' else BODIES_LAW))
    status, _, err = run_in_process('dynamic', folder, 'inputfile_rollers.dat')
    assert status == 0, err
    hooks = ['blob_external_force', 'blob_blob_force', 'bodies_external_force_torque',
             'body_body_force_torque' if laws == 'pair' else 'calc_body_body_forces_torques_python']
    for hook in hooks:
        received = set(json.loads((folder / ('keywords.%s.json' % hook)).read_text()))
        missing = PUBLISHED_KEYWORDS[hook] - received
        assert not missing, (hook, missing)
        assert 'mu' not in received  # negative control: a keyword of the lubrication program only
    assert set().union(*PUBLISHED_KEYWORDS.values()) <= set(physics.PUBLISHED_HOOK_KEYWORDS)


# The published Multi_Blob_Two_Rollers override, as its README and the issue describe it: gravity, the wall
# repulsion of a sphere of particle_radius, and the torque 8 pi eta R^3 omega on every body, read from the keywords.
TWO_ROLLERS_OVERRIDE = '''
import multi_bodies_functions
from multi_bodies_functions import *

def bodies_external_force_torque_new(bodies, r_vectors, *args, **kwargs):
    FT = np.zeros((2 * len(bodies), 3))
    R = kwargs['particle_radius']
    for k, b in enumerate(bodies):
        FT[2 * k, 2] -= kwargs['g']
        FT[2 * k + 1] += 8.0 * np.pi * kwargs['eta'] * R ** 3 * kwargs['omega_one_roller']
        h = b.location[2]
        FT[2 * k, 2] += (kwargs['repulsion_strength_wall'] / kwargs['debye_length_wall']) * \\
            np.exp(-max(h - R, 0.0) / kwargs['debye_length_wall'])
    return FT
multi_bodies_functions.bodies_external_force_torque = bodies_external_force_torque_new

def blob_external_force_new(r_vectors, *args, **kwargs):
    return np.zeros(3)
multi_bodies_functions.blob_external_force = blob_external_force_new
'''


def test_multi_blob_two_rollers_scene_runs_and_rolls(tmp_path):
    """Both shells, driven by the torque 8 pi eta R^3 omega (omega 0 62.8 0, R 1), roll along +x; the step's
    displacement equals dt times the velocity of the torque alone within 20 % (the torque dominates gravity).
    Negative control: omega 0 gives no rolling (|dx| 100 times smaller)."""
    moved = {}
    for name, omega in (('driven', '0 62.8 0'), ('undriven', '0 0 0')):
        folder = two_shell_scene(tmp_path / name, TWO_ROLLERS_OVERRIDE, scheme='deterministic_adams_bashforth',
                                 omega_one_roller=omega, n_steps=2, blob_blob_force_implementation='None',
                                 body_body_force_torque_implementation='None')
        status, _, err = run_in_process('dynamic', folder, 'inputfile_rollers.dat')
        assert status == 0, err
        lines = (folder / 'run_two_rollers' / 'data.two_rollers.config').read_text().split('\n')
        last = np.array([[float(w) for w in line.split()] for line in lines[-3:-1]])
        moved[name] = last[:, 0] - np.array([-1.5, 1.5])
    assert np.all(moved['driven'] > 0), moved
    assert np.abs(moved['undriven']).max() < 1e-2 * moved['driven'].min(), moved
