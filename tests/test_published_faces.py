"""The published module paths that drivers and override files import, as faces over the package.

``read_input.ReadInput`` and the file readers, ``general_application_utils`` and ``mobility.mobility``: each
gives what the published module gave (checked against the input text itself, the package's own functions of
the same name, or a direct solve), so a published driver's first lines work unchanged.
"""
import os

import numpy as np
import pytest

REFERENCE = os.path.join(os.path.dirname(__file__), '..', '..', 'shared', 'reference')
CHAIN = os.path.join(REFERENCE, 'lubrication', 'examples', 'Magnetic_Chain_With_Twist')


def write(path, text):
    path.write_text(text)
    return str(path)


def test_read_input_types_the_options_keeps_unknown_ones_and_every_structure_line(tmp_path):
    from read_input.read_input import ReadInput
    text = ('eta 8.9e-04 # a comment\nblob_radius 0.5\nkT 0.0041419464\nperiodic_length 0.0\t0.0\t0.0\n'
            'firm_delta 1e-2\nrepulsion_strength_firm 0.0163\nseed 1\nB_freq 2.5\neta 1.5\n'
            'structure ./blob.vertex ./chain_60.clones\nstructure b.vertex sub/two.clones b.slip\n')
    read = ReadInput(write(tmp_path / 'in.dat', text))
    assert read.eta == 1.5  # a repeated option overrides the earlier one
    assert read.blob_radius == 0.5 and read.kT == 0.0041419464 and read.seed == 1
    assert tuple(read.periodic_length) == (0.0, 0.0, 0.0)
    assert read.firm_delta == 1e-2 and read.repulsion_strength_firm == 0.0163 and read.Lub_Cut == 4.5
    assert read.options['B_freq'] == '2.5'
    assert read.structures == [['./blob.vertex', './chain_60.clones'], ['b.vertex', 'sub/two.clones', 'b.slip']]
    assert read.structures_ID == ['chain_60', 'two']
    assert read.dt == 0.0 and read.n_save == 1 and read.output_name == 'run'  # the table's defaults


def test_read_input_names_the_line_of_a_bad_value(tmp_path):
    from read_input.read_input import ReadInput
    from utils import UserInputError
    with pytest.raises(UserInputError, match='in.dat, line 2: option .firm_delta. expects a number'):
        ReadInput(write(tmp_path / 'in.dat', 'eta 1\nfirm_delta small\n'))


@pytest.mark.skipif(not os.path.isdir(CHAIN), reason='the published lubrication examples are not in ../shared/reference')
def test_read_input_of_a_published_lubrication_input():
    from read_input.read_input import ReadInput
    read = ReadInput(os.path.join(CHAIN, 'inputfile_chain.dat'))
    assert (read.eta, read.blob_radius, read.firm_delta, read.solver_tolerance) == (8.9e-4, 0.5, 1e-2, 1e-4)
    assert read.output_name == './data/twist_helix' and read.structures_ID == ['chain_60']


def test_file_readers_give_the_published_return_values(tmp_path):
    from body.geometry import Quaternion
    from read_input.read_clones_file import read_clones_file
    from read_input.read_slip_file import read_slip_file
    from read_input.read_vertex_file import read_vertex_file
    vertex = write(tmp_path / 'b.vertex', '2\n0 0 0\n1 0 0\n')
    clones = write(tmp_path / 'b.clones', '2\n0 0 1 1 0 0 0\n1 2 3 0 2 0 0\n')
    slip = write(tmp_path / 'b.slip', '2\n0 0 1\n0 0 -1\n')
    np.testing.assert_array_equal(read_vertex_file(vertex), [[0, 0, 0], [1, 0, 0]])
    count, locations, orientations = read_clones_file(clones)
    assert count == 2 and isinstance(orientations[0], Quaternion)
    np.testing.assert_array_equal(locations, [[0, 0, 1], [1, 2, 3]])
    np.testing.assert_array_equal(orientations[1].entries, [0, 1, 0, 0])  # normalised
    np.testing.assert_array_equal(read_slip_file(slip), [[0, 0, 1], [0, 0, -1]])


def test_mobility_face_has_the_published_names_and_the_package_numbers():
    import mobility
    from mobility import mobility as mob
    rng = np.random.default_rng(3)
    r = rng.random((6, 3)) * 4 + [0, 0, 1]
    v = rng.standard_normal(18)
    for domain in ('single_wall', 'no_wall'):
        for kind in ('trans_times_force', 'trans_times_torque', 'rot_times_force', 'rot_times_torque'):
            ours = getattr(mobility, '%s_mobility_%s' % (domain, kind))(r, v, 1.0, 0.4)
            face = getattr(mob, '%s_mobility_%s_numba' % (domain, kind))(r, v, 1.0, 0.4)
            np.testing.assert_allclose(face, ours, rtol=1e-12, atol=1e-14)
    dense = mob.single_wall_fluid_mobility(r, 1.0, 0.4)
    np.testing.assert_allclose(mob.single_wall_mobility_trans_times_force_numba(r, v, 1.0, 0.4), dense @ v,
                               rtol=1e-12, atol=1e-14)
    target = mob.no_wall_mobility_trans_times_force_source_target_numba(r, r, v, np.full(6, 0.4), np.full(6, 0.4), 1.0)
    np.testing.assert_allclose(target, mob.rotne_prager_tensor(r, 1.0, 0.4) @ v, rtol=1e-10, atol=1e-14)


def test_general_application_utils_gmres_solves_with_the_published_keywords():
    import general_application_utils as gau
    rng = np.random.default_rng(4)
    A = np.eye(30) + 0.1 * rng.standard_normal((30, 30))
    b = rng.standard_normal(30)
    x, info = gau.gmres(A, b, tol=1e-12, restart=30)
    assert info == 0
    np.testing.assert_allclose(x, np.linalg.solve(A, b), rtol=0, atol=1e-9)
    with gau.Timer() as timer:
        pass
    assert timer.elapsed >= 0


# ---------------------------------------------------------------------------------------------- names (issue 47)
# Every name that the published drivers (Lubrication_Examples/*/main_*.py), force files (forces_numba, the
# examples' force and multi_bodies_functions files) and example overrides import from the module paths this package
# offers as faces, found in the published tree (July 2025): `from X import Y`, `import X as m` then `m.Y`.
FACE_NAMES = {
    'general_application_utils': ('static_var', 'timer', 'gmres', 'transfer_mobility', 'tensor_cross_vector',
                                  'vector_cross_tensor', 'log_time_progress', 'Timer'),
    'quaternion_integrator.quaternion': ('Quaternion',),
    'read_input.read_input': ('ReadInput',),
    'read_input.read_vertex_file': ('read_vertex_file',),
    'read_input.read_clones_file': ('read_clones_file',),
    'read_input.read_slip_file': ('read_slip_file',),
    'mobility.mobility': ('rotne_prager_tensor', 'single_wall_fluid_mobility'),
    'body.body': ('Body',),
    'stochastic_forcing.stochastic_forcing': (),
    'Lub_Solver': ('Lub_Solver',),
    'sksparse.cholmod': ('cholesky',),
    'articulated.articulated': ('Articulated', 'Constraint'),
    'constraint.constraint': ('Constraint',),
}


@pytest.mark.parametrize('module', sorted(FACE_NAMES))
def test_every_name_the_published_files_import_from_a_face_exists(module):
    import importlib
    face = importlib.import_module(module)
    missing = [name for name in FACE_NAMES[module] if not hasattr(face, name)]
    assert not missing, (module, missing)


def test_static_var_and_timer_keep_their_values():
    import general_application_utils as utils

    @utils.static_var('counter', 0)
    def count():
        count.counter += 1
        return count.counter
    assert [count(), count(), count()] == [1, 2, 3]
    utils.timer('x')
    assert utils.timer.timers['x'][1] is not None  # running
    utils.timer('x')
    total, running = utils.timer.timers['x']
    assert running is None and total >= 0
    utils.timer('x', clean_all=True)
    assert utils.timer.timers == {}


@pytest.mark.parametrize('side', ['right', 'left', 'left_res'])
def test_published_gmres_solves_with_the_preconditioner_on_either_side(side):
    import general_application_utils as utils
    rng = np.random.default_rng(5)
    A = np.diag(np.linspace(1, 50, 40)) + 0.05 * rng.standard_normal((40, 40))
    b = rng.standard_normal(40)
    x, info = utils.gmres(A, b, tol=1e-12, M=np.diag(1 / np.diag(A)), PC_side=side, restart=40)
    assert info == 0 and np.linalg.norm(A @ x - b) <= 1e-10 * np.linalg.norm(b)


def test_transfer_mobility_of_a_sphere_is_the_rigid_motion_law():
    """A sphere's mobility diag(mu_t I, mu_r I) about its centre, seen from a point r away: translation block
    mu_t I + mu_r (|r|^2 I - r r^T) and the way back returns the start.  The coupling block has the published
    function's sign (its cross products take r = point_1 - point_2): that of the rigid-motion law u = omega x
    (p - c) at the mirror point p = 2 point_1 - point_2; the face keeps it, so drivers get the published numbers."""
    import general_application_utils as utils
    mu_t, mu_r = 0.7, 0.3
    centre, point = np.array([0.1, -0.2, 0.5]), np.array([1.0, 0.4, -0.3])
    m1 = np.diag([mu_t] * 3 + [mu_r] * 3)
    m2 = utils.transfer_mobility(m1, centre, point)
    r = centre - point
    np.testing.assert_allclose(m2[:3, :3], mu_t * np.eye(3) + mu_r * (r @ r * np.eye(3) - np.outer(r, r)), atol=1e-14)
    torque = np.array([0.3, -1.1, 0.7])  # a pure torque about point: omega = mu_r T, u(point) = omega x (point - c)
    mirror = 2 * centre - point
    np.testing.assert_allclose(m2[:3, 3:] @ torque, np.cross(mu_r * torque, mirror - centre), atol=1e-14)
    np.testing.assert_allclose(m2, m2.T, atol=1e-14)
    np.testing.assert_allclose(utils.transfer_mobility(m2, point, centre), m1, atol=1e-13)


def test_sksparse_cholmod_face_factors_as_cholmod():
    """P (A + beta I) P^T = L L^T with L lower triangular, solves, log det; an indefinite matrix is refused."""
    import scipy.sparse as sp
    from sksparse.cholmod import cholesky, CholmodNotPositiveDefiniteError
    B = sp.random(80, 80, density=0.06, random_state=3)
    A = (B @ B.T + 0.1 * sp.identity(80)).tocsc()
    factor = cholesky(A, beta=0.4)
    M = A.toarray() + 0.4 * np.eye(80)
    L, P = factor.L(), factor.P()
    assert np.abs(sp.triu(L, 1)).max() == 0
    np.testing.assert_allclose(M[P][:, P], (L @ L.T).toarray(), atol=1e-12)
    rhs = np.random.default_rng(2).standard_normal((80, 2))
    np.testing.assert_allclose(M @ factor(rhs), rhs, atol=1e-10)
    assert factor.logdet() == pytest.approx(np.linalg.slogdet(M)[1], rel=1e-12)
    np.testing.assert_array_equal(factor.apply_Pt(factor.apply_P(rhs[:, 0])), rhs[:, 0])
    with pytest.raises(CholmodNotPositiveDefiniteError):
        cholesky(sp.diags([2.0, -1.0, 3.0]).tocsc())
