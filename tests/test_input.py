"""Input file parsing, structure-file readers and their error messages."""
import os
import re
import subprocess
import sys

import numpy as np
import pytest

from multi_bodies.files.input_options import OPTION_TABLE, parse_input_text, read_input_file
from multi_bodies.files.snapshots import read_clones_file, write_clones_file
from multi_bodies.files.structure_files import read_body_table, read_slip_file, read_vertex_file, write_vertex_file
from multi_bodies.files import structure_generators as gen
from utils import UserInputError

REPO_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
REFERENCE = os.environ.get('RMB_REFERENCE_DIR', os.path.join(REPO_ROOT, '..', 'shared', 'reference'))
SCRIPT = os.path.join(REPO_ROOT, 'multi_bodies', 'multi_bodies_utilities.py')
needs_reference = pytest.mark.skipif(not os.path.isdir(REFERENCE),
                                     reason='reference data ../shared/reference not present')


def write(path, text):
    path.write_text(text)
    return str(path)


# ---------------------------------------------------------------- options
def test_comments_defaults_repeats_and_structures():
    text = """# comment line
scheme   mobility   # inline comment
eta 2.5
eta 3.0
periodic_length 1 2 0
plot_velocity_field -1 1 2 -1 1 2 0 1 1
structure a.vertex b.clones
structure c.vertex dir/d.clones e.slip
"""
    options = parse_input_text(text, 'in.dat')
    assert options.scheme == 'mobility'
    assert options.eta == 3.0                       # repeated option: the last wins
    assert options.periodic_length == (1.0, 2.0, 0.0)
    assert options.plot_velocity_field == ((-1.0, 1.0, 2), (-1.0, 1.0, 2), (0.0, 1.0, 1))
    assert [s.ID for s in options.structures] == ['b', 'd']
    assert options.structures[1].slip_file == 'e.slip'
    assert options.structures[0].where == 'in.dat, line 7'
    # Defaults of the manual / SPEC table.
    assert options.g == 1.0 and options.blob_radius == 1.0 and options.kT == 1.0
    assert options.solver_tolerance == 1e-8 and options.output_name == 'run'
    assert options.mobility_blobs_implementation == 'python'
    assert options.blob_blob_force_implementation == 'None'
    assert options.force_file is None and options.tracer_radius == 0.0
    assert options.where('eta') == 'in.dat, line 4'
    assert set(OPTION_TABLE) <= set(options.as_dict())


@pytest.mark.parametrize('text, fragments', [
    ('eta 1\nblob_radiuss 0.3\n', ['in.dat, line 2', "unknown option 'blob_radiuss'", 'blob_radius']),
    ('eta one\n', ['in.dat, line 1', "'eta'", 'a number', 'one']),
    ('n_steps 2.5\n', ['line 1', 'an integer']),
    ('eta\n', ['line 1', 'no value']),
    ('periodic_length 1 2\n', ['line 1', 'three numbers']),
    ('plot_velocity_field 0 1 2 0 1 2 0 1\n', ['line 1', 'nine values']),
    ('plot_velocity_field 0 1 0 0 1 2 0 1 2\n', ['line 1', 'positive integers']),
    ('free_kinematics yes\n', ['line 1', 'True or False']),
    ('\nstructure only_one.vertex\n', ['line 2', 'two or three file names']),
    ('stiffness_wall 4.5\n', ['line 1', 'stiffness_wall', 'unsupported']),
    ('domType RPB\n', ['line 1', 'unsupported']),
    ('eta 1\nperiodic_length 4 4 4\n', ['line 2', 'along z', 'wall at z = 0', '_no_wall']),
    ('solver_tolerance 0\n', ['line 1', 'between 0 and 1']),
    ('tracer_radius -0.5\n', ['line 1', 'tracer_radius must be >= 0']),
    ('scheme deterministic_adams_bashforth_rollers\nmobility_vector_prod_implementation C++_no_wall\n'
     'mobility_blobs_implementation python_no_wall\nperiodic_length 4 4 4\n', ['line 4', 'domain no_wall']),
])
def test_bad_options_name_file_and_line(text, fragments):
    """Each mistake gets one message naming the file, the line and the fix."""
    with pytest.raises(UserInputError) as err:
        parse_input_text(text, 'in.dat')
    for fragment in fragments:
        assert fragment in str(err.value)


def test_missing_input_file(tmp_path):
    with pytest.raises(UserInputError, match='not found'):
        read_input_file(str(tmp_path / 'nope.dat'))


# ---------------------------------------------------------------- structure files
def test_vertex_and_clones_readers(tmp_path):
    vertex = write(tmp_path / 'b.vertex', '# blobs\n2  0.5 extra\n0 0 1   # top\n\n0 0 -1\n')
    np.testing.assert_array_equal(read_vertex_file(vertex), [[0, 0, 1], [0, 0, -1]])
    clones = write(tmp_path / 'b.clones', '2\n1 2 3 2 0 0 0\n4 5 6 0 0 0 3\n7 7 7 1 0 0 0\n')
    locations, quaternions = read_clones_file(clones)
    np.testing.assert_array_equal(locations, [[1, 2, 3], [4, 5, 6]])     # only the announced count
    np.testing.assert_array_equal(quaternions, [[1, 0, 0, 0], [0, 0, 0, 1]])  # normalised
    slip = write(tmp_path / 'b.slip', '2\n1 0 0\n0 1 0\n')
    np.testing.assert_array_equal(read_slip_file(slip), [[1, 0, 0], [0, 1, 0]])
    forces = write(tmp_path / 'f.dat', '1 2 3 4 5 6\n0 0 0 0 0 1\n')
    np.testing.assert_array_equal(read_body_table(forces, 2, 'force')[1], [0, 0, 0, 0, 0, 1])


def test_writers_round_trip(tmp_path):
    blobs = np.random.default_rng(0).normal(size=(5, 3))
    write_vertex_file(str(tmp_path / 'x.vertex'), blobs, comment='test')
    np.testing.assert_array_equal(read_vertex_file(str(tmp_path / 'x.vertex')), blobs)
    q = np.random.default_rng(1).normal(size=(3, 4))
    q /= np.linalg.norm(q, axis=1)[:, None]
    write_clones_file(str(tmp_path / 'x.clones'), blobs[:3], q)
    loc, quat = read_clones_file(str(tmp_path / 'x.clones'))
    np.testing.assert_array_equal(loc, blobs[:3])
    np.testing.assert_allclose(quat, q, rtol=1e-15)


@pytest.mark.parametrize('reader, content, fragments', [
    (read_vertex_file, '2\n0 0 1\n0 x 1\n', ['line 3', 'cannot read']),
    (read_vertex_file, '2\n0 0 1\n0 0\n', ['line 3', 'found 2 value']),
    (read_vertex_file, '3\n0 0 1\n0 0 2\n', ['announces 3', 'only 2']),
    (read_vertex_file, '1\n0 0 1\n0 0 2\n', ['line 3', 'announces 1']),
    (read_vertex_file, 'two\n0 0 1\n', ['line 1', 'integer count']),
    (read_vertex_file, '# nothing\n', ['empty']),
    (read_clones_file, '1\n0 0 1 1 0 0\n', ['line 2', 'x y z s p1 p2 p3', 'found 6']),
    (read_clones_file, '1\n0 0 1 0 0 0 0\n', ['zero quaternion']),
    (lambda p: read_body_table(p, 2, 'force'), '1 2 3 4 5 6\n1 2 3 4 5\n', ['line 2', 'six numbers']),
    (lambda p: read_body_table(p, 2, 'force'), '1 2 3 4 5 6\n', ['one line per body', '2 bodies']),
    (lambda p: read_body_table(p, 1, 'velocity'), '1 2 3 4 5 a\n', ['line 1', 'vx vy vz']),
])
def test_malformed_files_name_file_and_line(tmp_path, reader, content, fragments):
    path = write(tmp_path / 'bad.file', content)
    with pytest.raises(UserInputError) as err:
        reader(path)
    assert path in str(err.value)
    for fragment in fragments:
        assert fragment in str(err.value)


def test_missing_structure_file_names_where_it_was_asked(tmp_path):
    with pytest.raises(UserInputError) as err:
        read_vertex_file(str(tmp_path / 'none.vertex'), 'in.dat, line 9')
    assert 'none.vertex' in str(err.value) and 'in.dat, line 9' in str(err.value)


# ---------------------------------------------------------------- the script on bad input
BAD_INPUTS = {
    'unknown option': ('scheme body_mobility\nblob_radius 0.25\nsolver_tol 1e-8\n', 'line 3'),
    'wrong type': ('scheme body_mobility\neta fast\n', 'line 2'),
    'missing file': ('scheme body_mobility\nstructure missing.vertex b.clones\n', 'missing.vertex'),
    'bad scheme': ('scheme deterministic_forward_euler\nstructure b.vertex b.clones\n', 'line 1'),
    'malformed vertex': ('scheme body_mobility\nstructure bad.vertex b.clones\n', 'bad.vertex, line 3'),
    'malformed clones': ('scheme body_mobility\nstructure b.vertex bad.clones\n', 'bad.clones, line 2'),
    'bad force file': ('scheme mobility\nforce_file f.dat\nstructure b.vertex b.clones\n', 'f.dat, line 1'),
    'below the wall': ('scheme body_mobility\nstructure b.vertex low.clones\n', 'below the wall'),
    'unknown implementation': ('scheme body_mobility\nmobility_blobs_implementation fortran\n'
                               'structure b.vertex b.clones\n', 'line 2'),
}


@pytest.mark.parametrize('kind', sorted(BAD_INPUTS))
def test_script_exits_cleanly_on_bad_input(tmp_path, kind):
    text, fragment = BAD_INPUTS[kind]
    write(tmp_path / 'b.vertex', '2\n0 0 0\n1 0 0\n')
    write(tmp_path / 'b.clones', '1\n0 0 3 1 0 0 0\n')
    write(tmp_path / 'low.clones', '1\n0 0 -1 1 0 0 0\n')
    write(tmp_path / 'bad.vertex', '2\n0 0 0\n1 0\n')
    write(tmp_path / 'bad.clones', '1\n0 0 3 1 0 0 zero\n')
    write(tmp_path / 'f.dat', '0 0 1\n')
    write(tmp_path / 'in.dat', text)
    result = subprocess.run([sys.executable, SCRIPT, '--input-file', 'in.dat'], cwd=str(tmp_path),
                            capture_output=True, text=True, timeout=120)
    assert result.returncode != 0
    assert 'Traceback' not in result.stderr
    assert fragment in result.stderr, result.stderr


# ---------------------------------------------------------------- generators
def test_shell_geometry():
    for n in (12, 42, 162):
        shell = gen.icosahedral_shell(n)
        assert shell.shape == (n, 3)
        np.testing.assert_allclose(np.linalg.norm(shell, axis=1), 1.0, atol=1e-15)
    # Icosahedron: all 30 edges equal to 4 / sqrt(10 + 2 sqrt 5).
    assert gen.smallest_distance(gen.icosahedral_shell(12)) == pytest.approx(4 / np.sqrt(10 + 2 * np.sqrt(5)))
    with pytest.raises(ValueError):
        gen.icosahedral_shell(50)


@needs_reference
@pytest.mark.parametrize('name, count', [('shell_N_12_Rg_0_7921_Rh_1', 12), ('shell_N_42_Rg_0_8913_Rh_1', 42),
                                         ('shell_N_162_Rg_0_9497_Rh_1', 162)])
def test_shells_match_published_geometry(name, count):
    published = read_vertex_file(os.path.join(REFERENCE, 'structures', name + '.vertex'))
    radius = np.linalg.norm(published[0])
    ours = gen.icosahedral_shell(count)
    distance = np.linalg.norm(ours[:, None, :] - published[None, :, :] / radius, axis=2)
    assert np.max(np.min(distance, axis=1)) < 1e-9        # same points, maybe another order
    with open(os.path.join(REFERENCE, 'structures', name + '.vertex')) as f:
        header_distance = float(f.readline().split()[1])
    assert gen.smallest_distance(ours) * radius == pytest.approx(header_distance, rel=1e-9)


@needs_reference
def test_boomerang_matches_published_file():
    published = read_vertex_file(os.path.join(REFERENCE, 'structures', 'boomerang_N_15.vertex'))
    np.testing.assert_allclose(gen.boomerang(7, 0.3), published, atol=1e-15)


def test_rod_and_generator_command(tmp_path):
    rod = gen.rod(4, 0.5)
    np.testing.assert_allclose(rod[:, 0], [-0.75, -0.25, 0.25, 0.75])
    path = gen.main(['rod', '--blobs', '4', '--spacing', '0.5', '--output', str(tmp_path)])
    np.testing.assert_allclose(read_vertex_file(path), rod)


def test_periodic_z_is_accepted_in_free_space():
    options = parse_input_text('mobility_vector_prod_implementation C++_no_wall\n'
                               'mobility_blobs_implementation python_no_wall\nperiodic_length 4 4 4\n', 'in.dat')
    assert tuple(options.periodic_length) == (4.0, 4.0, 4.0)


# ---------------------------------------------------------------- the option table
from multi_bodies.files import input_options as io_  # noqa: E402
from multi_bodies.files.input_options import Choice, Range  # noqa: E402

DOC_LETTERS = {'static': 'S', 'dynamic': 'D', 'stochastic': 'D', 'rollers': 'R', 'mcmc': 'M', 'lubrication': 'D'}


def doc_rows():
    """name -> the 'used by' cell of the table of doc/options.md."""
    text = open(os.path.join(REPO_ROOT, 'doc', 'options.md'), encoding='utf-8').read()
    return {m.group(1): m.group(2) for m in re.finditer(r'^\| `(\w+)` \|[^|]*\|[^|]*\|([^|]*)\|', text, flags=re.M)}


def test_the_docs_document_every_option_of_the_table_with_its_programs():
    """doc/options.md has a row for each option of OPTION_TABLE, and its 'used by' letters are the table's."""
    rows = doc_rows()
    assert sorted(set(OPTION_TABLE) - set(rows)) == []
    for name, option in OPTION_TABLE.items():
        documented = set(re.findall(r'\b([SDRM])\b', rows[name]))
        assert documented == {DOC_LETTERS[tag] for tag in option.used_by}, name
        assert bool(option.used_by) == ('no effect' not in rows[name]), name


def test_table_names_agree_with_the_registries():
    """The names the table allows are those the scheme, mobility and Monte Carlo registries know."""
    from quaternion_integrator import schemes
    from many_bodyMCMC import mcmc_energy, sampler
    import mobility.backends
    assert set(io_.DYNAMIC_SCHEMES) == set(schemes._all_schemes())
    assert set(io_.STOCHASTIC_SCHEMES) == set(schemes.STOCHASTIC_SCHEMES)
    assert not set(io_.STATIC_SCHEMES) & set(io_.DYNAMIC_SCHEMES)
    assert tuple(io_.MCMC_MOVES) == tuple(sampler.MOVES)
    assert tuple(io_.MCMC_ENERGY_IMPLEMENTATIONS) == tuple(mcmc_energy.IMPLEMENTATIONS)
    assert set(mobility.backends.all_names()) <= set(OPTION_TABLE['mobility_blobs_implementation'].rule.names)


# Options whose default a program refuses on purpose: that program needs them set (dt for the dynamics,
# a static problem as the scheme of the static script).
MUST_BE_SET = {('dt', 'dynamic'), ('scheme', 'static')}


def test_every_default_satisfies_its_rules():
    for name, option in OPTION_TABLE.items():
        if option.default is None:
            continue
        assert option.rule is None or option.rule.allows(option.default), name
        for program, rule in option.program_rules.items():
            assert rule.allows(option.default) != ((name, program) in MUST_BE_SET), (name, program)


def bad_value(rule):
    """A value the rule refuses, written as in an input file."""
    if isinstance(rule, Choice):
        return 'no_such_name'
    if rule.low is not None:
        return str(rule.low - 1) if rule.low >= 1 or not rule.low_open else str(rule.low)
    return str(rule.high * 10)


RULED = sorted(name for name, option in OPTION_TABLE.items() if option.rule is not None)


@pytest.mark.parametrize('name', RULED)
def test_each_rule_of_the_table_names_file_line_option_and_values(name):
    """The parser refuses a value outside each option's rule, naming the file, the line, the option and what
    is allowed (the table's text)."""
    rule = OPTION_TABLE[name].rule
    with pytest.raises(UserInputError) as err:
        parse_input_text('eta 1\n%s %s\n' % (name, bad_value(rule)), 'in.dat')
    message = str(err.value)
    assert message.startswith('in.dat, line 2: ') and name in message and rule.text in message, message


@pytest.mark.parametrize('name, value, program, fragment', [
    ('dt', '0', 'dynamic', 'dt must be positive'),
    ('kT', '0', 'mcmc', 'kT must be positive'),
    ('scheme', 'mobility', 'dynamic', 'run it with multi_bodies_utilities.py'),
    ('scheme', 'deterministic_forward_euler', 'static', 'not a static problem'),
])
def test_program_rules_are_stricter_only_for_their_program(name, value, program, fragment):
    text = '%s %s\n' % (name, value)
    with pytest.raises(UserInputError, match='in.dat, line 1: .*' + fragment):
        parse_input_text(text, 'in.dat', program)
    scheme = {'static': 'scheme mobility\n', 'dynamic': 'dt 0.1\n', 'mcmc': ''}
    for other in io_.PROGRAMS:
        if other != program and (name != 'scheme' or other == 'mcmc'):
            parse_input_text(text + scheme[other], 'in.dat', other)   # the same line is valid for the others


@pytest.mark.parametrize('name, value', [('kT', '-1'), ('rf_delta', '0'), ('update_PC', '0')])
def test_stochastic_scheme_options_are_checked_when_parsed(name, value):
    """kT >= 0, rf_delta > 0, update_PC >= 1 fail at parse time, with the line (not only in the scheme)."""
    with pytest.raises(UserInputError, match="in.dat, line 2: %s must be" % name):
        parse_input_text('scheme stochastic_adams_bashforth\n%s %s\n' % (name, value), 'in.dat')


def test_the_monte_carlo_quick_start_does_not_call_kT_ignored():
    """The sampler uses kT: its input gives no 'ignored' warning about kT when read for the Monte Carlo
    program; the same file read as a dynamic input (deterministic default scheme) does warn (control)."""
    text = open(os.path.join(REPO_ROOT, 'many_bodyMCMC', 'inputMCMC.dat')).read()
    assert 'kT' in text
    as_mcmc = parse_input_text(text, 'inputMCMC.dat', 'mcmc')
    assert not any("'kT'" in m for m in as_mcmc.warnings), as_mcmc.warnings
    assert io_.unused_options(as_mcmc, 'mcmc') == []
    as_dynamic = parse_input_text(text, 'inputMCMC.dat')
    assert any("option 'kT' is ignored" in m for m in as_dynamic.warnings)


def test_monte_carlo_script_does_not_print_kT_ignored(tmp_path):
    """The Monte Carlo script itself (a short run of the quick-start input): no 'kT' warning on either stream."""
    text = open(os.path.join(REPO_ROOT, 'many_bodyMCMC', 'inputMCMC.dat')).read()
    text = re.sub(r'^n_steps\s+\d+', 'n_steps 10', text, flags=re.M)
    text = text.replace('../multi_bodies/', os.path.join(REPO_ROOT, 'multi_bodies', ''))
    write(tmp_path / 'in.dat', text)
    script = os.path.join(REPO_ROOT, 'many_bodyMCMC', 'many_body_MCMC.py')
    result = subprocess.run([sys.executable, script, 'in.dat'], cwd=str(tmp_path), capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 0, result.stderr
    assert "'kT'" not in result.stderr + result.stdout and 'warning' not in result.stderr, result.stderr


@pytest.mark.parametrize('line, program, fragment', [
    ('dt 0', 'dynamic', 'dt must be positive'), ('dt -1', None, 'dt must be >= 0'),
    ('n_steps -1', None, 'n_steps must be >= 0'), ('initial_step -2', None, 'initial_step must be >= 0'),
    ('n_save 0', None, 'n_save must be at least 1'), ('kT -0.5', None, 'kT must be >= 0'),
    ('kT 0', 'mcmc', 'kT must be positive'), ('rf_delta 0', None, 'rf_delta must be positive'),
    ('update_PC 0', None, 'update_PC must be at least 1'), ('solver_tolerance 0', None, 'between 0 and 1'),
    ('blob_radius 0', None, 'blob_radius must be positive'), ('eta -1', None, 'eta must be positive'),
    ('save_clones every_step', None, 'save_clones must be one_file_per_step or one_file'),
    ('domain half_wall', None, 'domain must be one of single_wall, no_wall, in_plane'),
    ('scheme leapfrog', None, "unknown scheme 'leapfrog'"),
    ('mobility_vector_prod_implementation fortran', None, 'C++_no_wall'),
    ('blob_blob_force_implementation fortran', None, 'pycuda'),
    ('body_body_force_torque_implementation C++', None, 'None or python'),
    ('mcmc_move some_bodies', 'mcmc', 'mcmc_move must be all_bodies or one_body'),
    ('target_acceptance 1', 'mcmc', 'between 0 and 1'), ('n_burn_in -1', 'mcmc', 'n_burn_in must be >= 0'),
    ('max_translation -1', 'mcmc', '0 selects the default'), ('seed -3', None, 'non-negative integer'),
])
def test_the_ranges_of_the_manual_are_enforced(line, program, fragment):
    """The allowed values stated in doc/options.md (written here by hand, not read from the table)."""
    text = ('scheme stochastic_adams_bashforth\n' if program != 'mcmc' and not line.startswith('scheme') else '')
    with pytest.raises(UserInputError) as err:
        parse_input_text(text + line + '\n', 'in.dat', program)
    assert fragment in str(err.value) and str(err.value).startswith('in.dat, line'), str(err.value)
