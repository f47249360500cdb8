"""Lubrication corrections (lubrication/, issue 28): the published numbers, physical laws, the solve.

Numbers from outside the code under test:

* ``../shared/reference/lubrication/standalone_public.json``: Delta_R, R_sup, R_MB, M_RPB and M_lub
  computed by the published code (its a-scaling bug fixed; a = 1, eta = 1 / (6 pi));
* the published 2562-blob sphere-wall mobility table (``tables/`` of the reference folder, read here with
  ``numpy.interp``): for h >= 1.2 a the corrected one-sphere mobility equals it;
* physical laws: Delta_R symmetric positive semidefinite; the resistances of spheres of radius a equal
  those of radius 1 rescaled by a^n (dimensional analysis), which the published per-direction scaling
  breaks (negative control); translation invariance across a periodic boundary;
* dense linear algebra: the GMRES solve equals ``(M^-1 + Delta_R)^-1 F``.

The reference tests skip, saying why, when the reference folder is absent.
"""
import json
from pathlib import Path

import numpy as np
import pytest

from lubrication import assembly, problem as lub_problem, resistance
from multi_bodies.solver.body_solver import solve
from utils import UserInputError

REFERENCE = Path(__file__).resolve().parents[1] / '..' / 'shared' / 'reference' / 'lubrication'
STANDALONE = REFERENCE / 'standalone_public.json'
TABLE_2562 = REFERENCE / 'tables' / 'mob_scalars_wall_MB_2562_eig_thresh.txt'
ETA_UNIT = 1.0 / (6.0 * np.pi)   # 6 pi eta a^n = 1 at a = 1 (the units of the reference file)
RESISTANCE_TOLERANCE = 1e-10
MOBILITY_TOLERANCE = 1e-8


@pytest.fixture(scope='module')
def reference():
    if not STANDALONE.is_file():
        pytest.skip('reference data of the published lubrication code not found at %s '
                    '(../shared/reference/lubrication/ beside the repository)' % STANDALONE)
    return json.loads(STANDALONE.read_text())


def relative_error(value, expected):
    """max |value - expected| / max |expected| (entrywise, relative to the largest entry)."""
    value, expected = np.asarray(value, dtype=float), np.asarray(expected, dtype=float)
    return np.max(np.abs(value - expected)) / np.max(np.abs(expected))


def lattice_near_wall(side, spacing=2.2, height=1.1, a=1.0, jitter=0.0, seed=0):
    """side x side spheres on a square lattice (spacing, height in units of a), optionally jittered."""
    x, y = np.meshgrid(np.arange(side) * spacing, np.arange(side) * spacing)
    locations = np.column_stack((x.ravel(), y.ravel(), np.full(side * side, height)))
    if jitter:
        locations[:, :2] += jitter * np.random.default_rng(seed).uniform(-1, 1, (side * side, 2))
    return a * locations


# ------------------------------------------------------------------------------- the published numbers
def test_pair_resistances_equal_the_published_code(reference):
    assert len(reference['pair_no_wall']) == 14
    for entry in reference['pair_no_wall']:
        matrices = assembly.resistance_matrices(np.array([entry['r1'], entry['r2']]), 1.0, ETA_UNIT, wall=False)
        for name in ('R_sup', 'R_MB', 'Delta_R'):
            expected = np.array(entry[name])
            if not np.any(expected):  # beyond the cutoff (gap 2.51 a): nothing at all
                assert matrices.Delta_R.nnz == 0 and entry['gap_over_a'] > 2.5
                continue
            error = relative_error(getattr(matrices, name).toarray(), expected)
            assert error <= RESISTANCE_TOLERANCE, (entry['gap_over_a'], name, error)


def test_wall_resistances_and_one_sphere_mobility_equal_the_published_code(reference):
    for entry in reference['single_sphere_wall']:
        lub = lub_problem.LubricationProblem(np.array([[0.0, 0.0, entry['h_over_a']]]), 1.0, ETA_UNIT)
        for name, key in (('R_sup', 'R_sup_wall_minus_bulk'), ('R_MB', 'R_MB_wall_minus_bulk'),
                          ('Delta_R', 'Delta_R')):
            error = relative_error(getattr(lub.matrices, name).toarray(), entry[key])
            assert error <= RESISTANCE_TOLERANCE, (entry['h_over_a'], name, error)
        assert relative_error(lub_problem.dense_far_field_mobility(lub), entry['M_RPB']) <= MOBILITY_TOLERANCE
        M_lub = lub_problem.dense_lubricated_mobility(lub)
        assert relative_error(M_lub, entry['M_lub']) <= MOBILITY_TOLERANCE, entry['h_over_a']
        # the same matrix column by column through the one solve
        columns = [solve(lub, lub.rhs(force), lub.preconditioner(1e-12), tolerance=1e-12).velocities.ravel()
                   for force in np.eye(6)]
        assert relative_error(np.column_stack(columns), entry['M_lub']) <= MOBILITY_TOLERANCE, entry['h_over_a']


def test_two_spheres_near_the_wall_equal_the_published_code(reference):
    rng = np.random.default_rng(28)
    for entry in reference['two_spheres_wall']:
        lub = lub_problem.LubricationProblem(np.array(entry['r']), 1.0, ETA_UNIT)
        assert relative_error(lub.Delta_R.toarray(), entry['Delta_R']) <= RESISTANCE_TOLERANCE
        assert relative_error(lub_problem.dense_lubricated_mobility(lub), entry['M_lub_dense']) <= MOBILITY_TOLERANCE
        columns = [solve(lub, lub.rhs(force), lub.preconditioner(1e-12), tolerance=1e-12).velocities.ravel()
                   for force in np.eye(12)]
        assert relative_error(np.column_stack(columns), entry['M_lub_gmres']) <= MOBILITY_TOLERANCE
        # velocities of one force-torque: the published M_lub times it
        force_torque = rng.standard_normal((2, 6))
        velocities = lub_problem.lubricated_velocities(np.array(entry['r']), force_torque, 1.0, ETA_UNIT,
                                                       tolerance=1e-12).velocities
        expected = np.array(entry['M_lub_gmres']) @ force_torque.ravel()
        assert relative_error(velocities.ravel(), expected) <= MOBILITY_TOLERANCE


def test_one_sphere_corrected_mobility_equals_the_2562_blob_table():
    """For h >= 1.2 a, M_lub of one sphere is the resolved sphere's (the table the model inverts)."""
    if not TABLE_2562.is_file():
        pytest.skip('published 2562-blob wall table not found at %s' % TABLE_2562)
    table = np.loadtxt(TABLE_2562)[::-1]
    for h in (1.2, 1.37, 1.5, 2.0, 3.3, 5.0, 8.0):
        expected = np.array([np.interp(h, table[:, 0], table[:, k]) for k in range(1, 6)])
        lub = lub_problem.LubricationProblem(np.array([[0.0, 0.0, h]]), 1.0, ETA_UNIT)
        M = lub_problem.dense_lubricated_mobility(lub)
        scalars = np.array([M[2, 2], M[0, 0], M[0, 4], M[5, 5], M[3, 3]])  # Xa, Ya, Yb, Xc, Yc
        assert np.max(np.abs(scalars - expected)) <= 1e-5, (h, scalars - expected)
        # and the plain single-blob mobility does not (the correction matters at these heights)
        M_RPB = lub_problem.dense_far_field_mobility(lub)
        if h <= 2.0:
            assert abs(M_RPB[2, 2] - expected[0]) > 1e-3


# ------------------------------------------------------------------------------------------- physical laws
def scenes():
    """(name, locations, a, wall, periodic_length) of the test scenes."""
    rng = np.random.default_rng(7)
    cluster = rng.uniform(0.0, 6.0, (30, 3))
    cluster[:, 2] += 1.0005
    return [
        ('lattice near the wall', lattice_near_wall(4, jitter=0.3), 1.0, True, (0.0, 0.0, 0.0)),
        ('touching chain', np.column_stack((np.arange(8) * 2.0005, np.zeros(8), np.full(8, 1.01))), 1.0, True,
         (0.0, 0.0, 0.0)),
        ('random cluster with overlaps', cluster, 1.0, True, (0.0, 0.0, 0.0)),
        ('free-space cluster', cluster + 20.0, 1.0, False, (0.0, 0.0, 0.0)),
        ('periodic monolayer a = 0.5', lattice_near_wall(5, spacing=2.05, height=1.02, a=0.5, jitter=0.02),
         0.5, True, (5 * 2.05 * 0.5, 5 * 2.05 * 0.5, 0.0)),
    ]


@pytest.mark.parametrize('name, locations, a, wall, periodic_length', scenes(), ids=[s[0] for s in scenes()])
def test_delta_R_is_symmetric_positive_semidefinite(name, locations, a, wall, periodic_length):
    matrices = assembly.resistance_matrices(locations, a, 0.7, periodic_length=periodic_length, wall=wall)
    D = matrices.Delta_R.toarray()
    assert np.array_equal(D, D.T), name
    eigenvalues = np.linalg.eigvalsh(D)
    assert eigenvalues[0] >= -1e-12 * eigenvalues[-1], (name, eigenvalues[0], eigenvalues[-1])
    assert matrices.neighbours.pairs.shape[0] > 0


def rescaling(a, n_spheres):
    """S with R(a) = a S R(1) S and M(a) = S^-1 M(1) S^-1 / a: S = diag(1, 1, 1, a, a, a) per sphere."""
    return np.tile(np.array([1.0, 1.0, 1.0, a, a, a]), n_spheres)


@pytest.mark.parametrize('a', [0.5, 2.25, 1.0155])
def test_radius_a_equals_radius_one_rescaled(a):
    """Dimensional analysis: lengths in units of a, resistances by a^n; it holds with the pair vector scaled by
    a in every direction (the published code scales it only along periodic axes).  The radii of the published
    examples: chain and sheets 0.5, quasicrystal 2.25, rollers 1.0155."""
    eta = 0.9
    unit = lattice_near_wall(4, spacing=2.1, height=1.05, jitter=0.08)
    one = lub_problem.LubricationProblem(unit, 1.0, eta)
    scaled = lub_problem.LubricationProblem(a * unit, a, eta)
    S = rescaling(a, unit.shape[0])
    for name in ('R_sup', 'R_MB', 'Delta_R'):
        expected = a * S[:, None] * getattr(one.matrices, name).toarray() * S[None, :]
        assert relative_error(getattr(scaled.matrices, name).toarray(), expected) <= 1e-12, name
    M_lub_one = lub_problem.dense_lubricated_mobility(one)
    expected = M_lub_one / (a * S[:, None] * S[None, :])
    assert relative_error(lub_problem.dense_lubricated_mobility(scaled), expected) <= 1e-10
    force_torque = np.random.default_rng(3).standard_normal(6 * unit.shape[0])
    velocities = lub_problem.lubricated_velocities(a * unit, force_torque, a, eta, tolerance=1e-12).velocities
    assert relative_error(velocities.ravel(), expected @ force_torque) <= MOBILITY_TOLERANCE


def test_published_per_direction_scaling_breaks_the_rescaling():
    """Negative control: with the pair distance left in length units along non-periodic axes (the published
    ResistCOO), a = 0.5 spheres a tenth of a radius apart are treated as touching."""
    a, gap = 0.5, 0.1
    locations = np.array([[0.0, 0.0, 5.0], [(2.0 + gap) * a, 0.0, 5.0]])
    factors = resistance.resistance_factors(ETA_UNIT, a)
    x_hat = np.array([[1.0, 0.0, 0.0]])
    fixed = assembly.resistance_matrices(locations, a, ETA_UNIT, wall=False).Delta_R.toarray()
    published_distance = np.linalg.norm(locations[1] - locations[0])   # not divided by a: 1.05
    published = (resistance.pair_resistance_sup(published_distance, x_hat, factors)
                 - resistance.pair_resistance_blob_model(published_distance, x_hat, factors))[0]
    unit = assembly.resistance_matrices(locations / a, 1.0, ETA_UNIT, wall=False).Delta_R.toarray()
    S = rescaling(a, 2)
    rescaled = a * S[:, None] * unit * S[None, :]
    assert relative_error(fixed, rescaled) <= 1e-12
    assert relative_error(published, rescaled) > 100.0
    # the published README's numbers at gap 0.1 a (a = 1 units): Delta_R_xx 2.45 right, 2501 with the bug
    assert fixed[0, 0] / a == pytest.approx(2.45, abs=0.01)
    assert published[0, 0] / a == pytest.approx(2501, rel=1e-3)


def test_periodic_pair_across_the_boundary_equals_the_pair_inside():
    L = np.array([10.0, 12.0, 0.0])
    across = np.array([[0.3, 5.0, 1.5], [9.2, 5.4, 1.7]])            # 1.1 apart through x = 0
    inside = across + np.array([[5.0, 0.0, 0.0]])
    inside[1, 0] -= 10.0
    m_across = assembly.resistance_matrices(across, 0.5, 1.0, periodic_length=L)
    m_inside = assembly.resistance_matrices(inside, 0.5, 1.0, periodic_length=L)
    assert m_across.neighbours.pairs.shape[0] == 1
    assert relative_error(m_across.Delta_R.toarray(), m_inside.Delta_R.toarray()) <= 1e-13
    # without the box the two are far apart: wall terms only
    assert assembly.resistance_matrices(across, 0.5, 1.0).neighbours.pairs.shape[0] == 0


def test_free_space_has_no_wall_term_and_the_wall_has_one():
    one = np.array([[0.0, 0.0, 1.3]])
    assert assembly.resistance_matrices(one, 1.0, 1.0, wall=False).Delta_R.nnz == 0
    assert assembly.resistance_matrices(one, 1.0, 1.0, wall=True).Delta_R.nnz > 0


# --------------------------------------------------------------------------------------------- the solve
def test_gmres_solve_equals_the_dense_inverse():
    locations = lattice_near_wall(3, spacing=2.05, height=1.02, jitter=0.02, seed=5)
    lub = lub_problem.LubricationProblem(locations, 1.0, 1.0)
    force_torque = np.random.default_rng(11).standard_normal(lub.size)
    expected = lub_problem.dense_lubricated_mobility(lub) @ force_torque
    for tolerance in (1e-6, 1e-10):
        result = solve(lub, lub.rhs(force_torque), lub.preconditioner(tolerance), tolerance=tolerance)
        assert result.converged and result.residual <= tolerance
        assert relative_error(result.velocities.ravel(), expected) <= 100 * tolerance, tolerance
    plain = solve(lub, lub.rhs(force_torque), None, tolerance=1e-10)
    assert result.iterations < plain.iterations  # the published preconditioner pays


def test_isolated_spheres_are_left_to_the_far_field():
    """A sphere far from the wall and from the others moves as the far field says (Delta_R ~ 0 there)."""
    locations = np.array([[0.0, 0.0, 1.1], [2.3, 0.0, 1.1], [40.0, 0.0, 30.0]])
    lub = lub_problem.LubricationProblem(locations, 1.0, 1.0)
    assert list(lub.matrices.isolated) == [False, False, True]
    force_torque = np.zeros((3, 6))
    force_torque[2, 2] = 1.0
    result = solve(lub, lub.rhs(force_torque), lub.preconditioner(1e-10), tolerance=1e-10)
    expected = lub_problem.dense_lubricated_mobility(lub) @ force_torque.ravel()
    assert relative_error(result.velocities.ravel(), expected) <= 1e-8


# ------------------------------------------------------------------------------------------------ bad input
@pytest.mark.parametrize('options, words', [
    ({'firm_delta': -1e-3}, 'firm_delta'),
    ({'firm_delta': 'small'}, 'firm_delta'),
    ({'cutoff': 0.0}, 'Lub_Cut'),
    ({'handover': 'blended'}, 'handover'),
    ({'periodic_length': (1.0, 2.0)}, 'periodic_length'),
])
def test_bad_options_are_refused_with_their_name(options, words):
    with pytest.raises(UserInputError, match=words):
        assembly.resistance_matrices(np.array([[0.0, 0.0, 2.0], [2.5, 0.0, 2.0]]), 1.0, 1.0, **options)


def test_spheres_below_the_wall_and_bad_shapes_are_refused():
    with pytest.raises(UserInputError, match='below the wall'):
        lub_problem.LubricationProblem(np.array([[0.0, 0.0, -0.5]]), 1.0, 1.0)
    with pytest.raises(UserInputError, match='shape'):
        assembly.resistance_matrices(np.zeros((2, 2)), 1.0, 1.0)
    with pytest.raises(UserInputError, match='periodic box'):
        assembly.resistance_matrices(np.array([[0.0, 0.0, 2.0], [2.5, 0.0, 2.0]]), 1.0, 1.0,
                                     periodic_length=(6.0, 6.0, 0.0))


def test_the_worked_example_of_the_doc_runs_and_prints_what_it_says(capsys):
    """doc/lubrication.md: its Python block runs as written and prints the numbers the text quotes."""
    import re
    text = (Path(__file__).resolve().parents[1] / 'doc' / 'lubrication.md').read_text()
    code = re.findall(r'```python\n(.*?)```', text, re.S)[0]
    exec(compile(code, 'doc/lubrication.md', 'exec'), {})
    printed = capsys.readouterr().out
    assert 'approach speed with lubrication: 0.01330' in printed
    assert 'approach speed, single blobs:     0.03513' in printed
    assert '0.0133 with lubrication' in text and '0.0351 with single blobs' in text


def test_the_shipped_tables_are_the_published_ones_and_install_as_package_data():
    """lubrication/tables/ holds the five published tables unchanged, and setup.py installs them."""
    import ast
    import fnmatch
    from lubrication import tables
    names = sorted(set(tables.PAIR_TABLES.values()) | set(tables.WALL_TABLES.values()))
    assert len(names) == 5
    setup = (Path(__file__).resolve().parents[1] / 'setup.py').read_text()
    call = next(node for node in ast.walk(ast.parse(setup)) if isinstance(node, ast.Call)
                and getattr(node.func, 'id', None) == 'setup')
    keywords = {k.arg: ast.literal_eval(k.value) for k in call.keywords if k.arg in ('packages', 'package_data')}
    assert 'lubrication' in keywords['packages']
    patterns = keywords['package_data']['lubrication']
    for name in names:
        assert any(fnmatch.fnmatch('tables/' + name, pattern) for pattern in patterns), name
        if (REFERENCE / 'tables' / name).is_file():
            assert (tables.TABLE_DIRECTORY / name).read_bytes() == (REFERENCE / 'tables' / name).read_bytes(), name


def test_gmres_solve_equals_the_dense_inverse_in_a_periodic_box_and_in_free_space():
    """The same check with the pseudo-periodic far field (minimum image in the pairs) and without the wall."""
    locations = lattice_near_wall(5, spacing=2.1, height=1.05, a=0.5, jitter=0.02, seed=9)
    force_torque = np.random.default_rng(12).standard_normal(6 * locations.shape[0])
    box = 5 * 2.1 * 0.5
    for options in ({'periodic_length': (box, box, 0.0)}, {'wall': False}):
        lub = lub_problem.LubricationProblem(locations, 0.5, 1.0, **options)
        if 'periodic_length' in options:  # every pair within 4.5 a, across the box edges too (brute force)
            d = locations[:, None, :] - locations[None, :, :]
            d[..., :2] -= box * np.round(d[..., :2] / box)
            assert lub.matrices.neighbours.pairs.shape[0] == np.count_nonzero(np.triu(
                np.linalg.norm(d, axis=2) < 4.5 * 0.5, k=1))
        expected = lub_problem.dense_lubricated_mobility(lub) @ force_torque
        result = solve(lub, lub.rhs(force_torque), lub.preconditioner(1e-10), tolerance=1e-10)
        assert relative_error(result.velocities.ravel(), expected) <= 1e-8, options
