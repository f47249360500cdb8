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
