"""The advisor's geometry topic (multi_bodies/advice/advisor_geometry.py): pseudo-periodic direct sums against the
spectral product on scenes whose answer follows from the errors the advisor measures.

The references it measures against are tested in tests/test_periodic_accuracy.py (the analytic mean flow of a
periodic force, agreement with the refined spectral product); here the choice is checked against the rows: the
recommendation is the cheapest product whose measured error meets the target, a dense monolayer of rollers in a
small box (whose first ring of images misses much of the mean flow) gets the spectral product, a few rollers in a
huge box keep the direct wall product, and the recommended input runs.
"""
import os
import subprocess
import sys

import numpy as np

from multi_bodies.advice import advisor
from multi_bodies.files.snapshots import write_clones_file
from multi_bodies.files.structure_files import write_vertex_file
from multi_bodies.files.structure_generators import calibrated_shell

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def write_scene(folder, scheme, locations, box, blob_radius=1.0, blobs=None, extra=()):
    """An input file of one structure (``blobs``, default one blob) at ``locations`` in ``periodic_length box
    box 0``; returns its name."""
    blobs = np.zeros((1, 3)) if blobs is None else blobs
    write_vertex_file(os.path.join(folder, 'body.vertex'), blobs)
    write_clones_file(os.path.join(folder, 'body.clones'), np.asarray(locations, dtype=float),
                      np.tile([1.0, 0, 0, 0], (len(locations), 1)))
    lines = ['scheme %s' % scheme, 'blob_radius %r' % blob_radius, 'eta 1.0', 'g 0.1', 'dt 0.01', 'n_steps 1',
             'n_save 1', 'mobility_blobs_implementation C++', 'mobility_vector_prod_implementation C++',
             'repulsion_strength_wall 1.0', 'debye_length_wall 0.1', 'periodic_length %r %r 0' % (box, box),
             'output_name out/run', 'structure body.vertex body.clones'] + list(extra)
    with open(os.path.join(folder, 'input.dat'), 'w') as f:
        f.write('\n'.join(lines) + '\n')
    return 'input.dat'


def lattice(count, spacing, height):
    g = (np.arange(count) + 0.5) * spacing
    X, Y = np.meshgrid(g, g)
    return np.column_stack([X.ravel(), Y.ravel(), np.full(X.size, height)])


def geometry_rows(result):
    return [c for c in result.choices if c.topic == 'geometry']


def expected_choice(result):
    """The row the measured errors imply: the cheapest one that meets the target."""
    meeting = [c for c in geometry_rows(result) if c.meets_target and c.cost_s is not None]
    assert all(c.estimated_error <= result.accuracy for c in meeting)
    return min(meeting, key=lambda c: c.cost_s) if meeting else None


def spectral_kernel_of(row):
    return row.candidate.split()[1]


def partial_advice(input_file, accuracy=0.01):
    """The solver, backend and geometry topics only (what the geometry topic reads)."""
    result = advisor.Advisor(advisor.Scene(input_file), accuracy, quick=True)
    result.measure_solver()
    result.measure_backends()
    result.measure_geometry()
    return result


def test_dense_monolayer_of_rollers_gets_the_spectral_product(tmp_path, monkeypatch):
    """64 rollers 2.5 radii apart, 1.5 radii above the wall in a 20 x 20 box: the first ring of images misses
    much of the periodic mean flow of a uniform load, so the measured error of the pseudo-periodic sum exceeds
    1%, and the cheapest product that meets it is a spectral one.  The recommended input runs a step."""
    monkeypatch.chdir(tmp_path)
    name = write_scene(str(tmp_path), 'deterministic_adams_bashforth_rollers', lattice(8, 2.5, 1.5), 20.0,
                       extra=['omega_one_roller 0 1 0'])
    result = advisor.advise(name, accuracy=0.01, quick=True)
    rows = geometry_rows(result)
    direct = rows[0]
    assert direct.candidate.startswith('pseudo-periodic') and direct.candidate.endswith('(current)')
    assert direct.estimated_error > 0.01 and not direct.meets_target
    chosen = expected_choice(result)
    assert chosen is not None and chosen.candidate.startswith('spectral')
    assert result.recommendation['mobility_vector_prod_implementation'] == 'spectral'
    assert result.recommendation.get('spectral_kernel', 'w6') == spectral_kernel_of(chosen)
    assert result.recommendation['spectral_reading'] == 'package'   # blob_radius read as measured, not published
    assert result.check['holds']
    assert '## geometry' in result.report()
    with open('applied.dat', 'w') as f:
        f.write(advisor.apply_recommendation(open(name).read(), result.recommendation, ['body']))
    run = subprocess.run([sys.executable, os.path.join(REPO, 'multi_bodies', 'multi_bodies.py'), '--input-file',
                          'applied.dat'], capture_output=True, text=True, env=dict(os.environ, PYTHONPATH=REPO))
    assert run.returncode == 0, run.stderr
    assert 'spectral product: doubly_periodic_wall' in run.stdout + run.stderr


def test_few_rollers_in_a_huge_box_keep_the_direct_wall_product(tmp_path, monkeypatch):
    """Three rollers in a 200 x 200 box: their images are far, the pseudo-periodic sum meets the target and one
    product of three blobs costs microseconds against the spectral grid of the whole box: nothing changes."""
    monkeypatch.chdir(tmp_path)
    name = write_scene(str(tmp_path), 'deterministic_adams_bashforth_rollers',
                       [[10.0, 10.0, 3.0], [30.0, 20.0, 3.0], [20.0, 40.0, 3.5]], 200.0)
    result = partial_advice(name)
    rows = geometry_rows(result)
    assert rows[0].meets_target
    assert expected_choice(result) is rows[0]
    assert all(row.cost_s > 10 * rows[0].cost_s for row in rows[1:] if row.cost_s is not None)
    assert result.recommendation.get('mobility_vector_prod_implementation', 'C++') == 'C++'
    assert 'spectral_kernel' not in result.recommendation


def test_rigid_monolayer_measured_through_the_compiled_reference(tmp_path, monkeypatch):
    """Nine 12-blob spheres 3 radii apart in a 9 x 9 box (force-only kernels; the periodic reference from tiles of
    the compiled source-target product): the recommendation is the cheapest row that meets the target, and the
    errors of the spectral kernels shrink from w4 to w6."""
    monkeypatch.chdir(tmp_path)
    blobs, blob_radius, _ = calibrated_shell(12)
    name = write_scene(str(tmp_path), 'deterministic_adams_bashforth', lattice(3, 3.0, 2.0), 9.0,
                       blob_radius=blob_radius, blobs=blobs)
    result = partial_advice(name)
    rows = {row.candidate.split(' (')[0]: row for row in geometry_rows(result)}
    assert set(rows) == {'pseudo-periodic direct sum, first ring of images', 'spectral w6', 'spectral w5',
                         'spectral w4'}
    assert rows['spectral w6'].estimated_error < rows['spectral w4'].estimated_error
    chosen = expected_choice(result)
    if chosen is None or chosen.candidate.startswith('pseudo-periodic'):
        assert result.recommendation.get('mobility_vector_prod_implementation', 'C++') != 'spectral'
    else:
        assert result.recommendation['mobility_vector_prod_implementation'] == 'spectral'
        assert result.recommendation.get('spectral_kernel', 'w6') == spectral_kernel_of(chosen)


def test_a_spectral_input_in_the_published_form_is_not_measured(tmp_path, monkeypatch):
    """An input naming the spectral product over a wall and no other spectral_* line is read as the published
    folder reads it (blob_radius the particle radius): the advisor, which reads the scene as the manual does, says
    so instead of measuring other blobs, and the backend topic's direct sums do not replace the product."""
    monkeypatch.chdir(tmp_path)
    name = write_scene(str(tmp_path), 'deterministic_adams_bashforth_rollers', lattice(4, 5.0, 2.0), 20.0)
    with open(name) as f:
        text = f.read().replace('mobility_vector_prod_implementation C++', 'mobility_vector_prod_implementation '
                                                                          'spectral')
    with open(name, 'w') as f:
        f.write(text)
    result = partial_advice(name)
    rows = geometry_rows(result)
    assert len(rows) == 1 and rows[0].candidate == 'not measured' and 'spectral_reading package' in rows[0].note
    assert 'mobility_vector_prod_implementation' not in result.recommendation


def test_a_slit_has_no_direct_sum_to_compare(tmp_path, monkeypatch):
    """The spectral product in a slit is the only product of that geometry: the topic says so and the backend
    topic's direct sums do not replace it."""
    monkeypatch.chdir(tmp_path)
    name = write_scene(str(tmp_path), 'deterministic_adams_bashforth_rollers', lattice(4, 5.0, 2.0), 20.0,
                       extra=['spectral_geometry doubly_periodic_slit', 'spectral_z_bounds 0 6'])
    with open(name) as f:
        text = f.read().replace('mobility_vector_prod_implementation C++', 'mobility_vector_prod_implementation '
                                                                          'spectral')
    with open(name, 'w') as f:
        f.write(text)
    result = partial_advice(name)
    rows = geometry_rows(result)
    assert len(rows) == 1 and rows[0].candidate == 'not measured' and 'slit' in rows[0].note
    assert 'mobility_vector_prod_implementation' not in result.recommendation
