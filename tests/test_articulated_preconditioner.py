"""Every articulated body solved exactly as if alone (multi_bodies/solver/articulated_preconditioner.py): one
articulated body alone is solved in one GMRES iteration, several reach the published preconditioner's solution in
fewer, and the published preconditioner stays where this one does not apply."""
import numpy as np
import pytest

from multi_bodies.solver import articulated as art
from multi_bodies.solver import articulated_preconditioner as ap
from multi_bodies.solver import body_solver
from test_articulated import setup_system, write_chain


def chain_model(tmp_path, monkeypatch, clones=None, extra_lines=()):
    """The Model of ball-jointed chains of three SHELL bodies (``write_chain``), clones as given."""
    common = write_chain(tmp_path, 3, 2.5, 3.0, locked=False)
    if clones is not None:
        (tmp_path / 'chain.clones').write_text('%d\n%s\n' % (len(clones), '\n'.join(
            ' '.join(repr(float(v)) for v in row) for row in clones)))
    text = '\n'.join(['scheme mobility', 'articulated chain.list_vertex chain.clones chain.const']
                     + list(extra_lines) + common)
    return setup_system(tmp_path, text, monkeypatch)[1].system


def solve_both(model):
    """(group solve, published solve) of the articulated mobility problem of ``model`` at its start, 1e-12."""
    q = model.start_configuration
    problem, rhs, published = art.articulated_problem(model.replace(preconditioner='block_diagonal'),
                                                      model.articulated, q, 0.0)
    assert type(published) is art.ArticulatedPreconditioner
    grouped = ap.build(problem, model, q)
    return (body_solver.solve(problem, rhs, grouped, tolerance=1e-12),
            body_solver.solve(problem, rhs, published, tolerance=1e-12), grouped)


def test_one_articulated_body_alone_is_solved_in_one_iteration(tmp_path, monkeypatch):
    """The group's matrix is the whole problem, so GMRES converges at once to the published preconditioner's answer;
    the published preconditioner (the negative control: the bodies alone, coupled through their self mobilities)
    needs more iterations."""
    model = chain_model(tmp_path, monkeypatch)
    ours, published, grouped = solve_both(model)
    assert isinstance(grouped, ap.GroupPreconditioner) and grouped.body is None
    assert ours.converged and ours.iterations == 1
    assert published.converged and published.iterations >= 4, published.iterations
    scale = np.max(np.abs(published.velocities))
    assert np.max(np.abs(ours.velocities - published.velocities)) < 1e-10 * scale
    assert np.max(np.abs(ours.constraint_force_torque - published.constraint_force_torque)) < 1e-9 * np.max(
        np.abs(published.constraint_force_torque))


def test_two_chains_and_a_free_body_converge_in_half_the_iterations(tmp_path, monkeypatch):
    """Two chains 10 apart and a free body between them above the wall: the same velocities and joint forces as the
    published preconditioner, in at most half its iterations (measured 15 -> 7); the free body goes through the
    model's body preconditioner.  (Chains 2 apart, nearly touching, took 21 -> 20: the coupling between articulated
    bodies is left to GMRES, doc/preconditioners.md.)"""
    chain = np.array([[2.5 * k, 0.0, 3.0, 1.0, 0.0, 0.0, 0.0] for k in range(3)])
    second = chain + [0.3, 10.0, 0.4, 0, 0, 0, 0]
    second[:, 3:] = [0.9, 0.3, -0.2, np.sqrt(1 - 0.94)]
    (tmp_path / 'free.clones').write_text('1\n2.5 5.0 5.0 1 0 0 0\n')
    model = chain_model(tmp_path, monkeypatch, clones=np.concatenate((chain, second)),
                        extra_lines=['structure shell.vertex free.clones'])
    ours, published, grouped = solve_both(model)
    assert isinstance(grouped, ap.GroupPreconditioner) and grouped.body is not None
    assert ours.converged and published.converged
    assert 2 * ours.iterations <= published.iterations, (ours.iterations, published.iterations)
    scale = np.max(np.abs(published.velocities))
    assert np.max(np.abs(ours.velocities - published.velocities)) < 1e-9 * scale


def test_the_published_preconditioner_where_the_groups_do_not_apply(tmp_path, monkeypatch):
    """``preconditioner block_diagonal``, articulated bodies above MAX_GROUP_BLOBS, and under ``auto`` LUs that
    would cost more than AUTO_MAX_PRODUCTS products (``neighbours`` builds them anyway) keep the published one."""
    model = chain_model(tmp_path, monkeypatch)
    q = model.start_configuration
    _, _, default = art.articulated_problem(model, model.articulated, q, 0.0)
    assert isinstance(default, ap.GroupPreconditioner)
    _, _, published = art.articulated_problem(model.replace(preconditioner='block_diagonal'), model.articulated, q,
                                              0.0)
    assert type(published) is art.ArticulatedPreconditioner
    cost = ap.lu_cost_in_products([model.num_blobs], model.num_blobs)  # one chain: (3N)^3 / 3 / (40 N^2)
    assert cost == pytest.approx(27.0 * model.num_blobs / 120.0)
    monkeypatch.setattr(ap, 'AUTO_MAX_PRODUCTS', 0.99 * cost)
    _, _, costly = art.articulated_problem(model, model.articulated, q, 0.0)
    assert type(costly) is art.ArticulatedPreconditioner
    _, _, anyway = art.articulated_problem(model.replace(preconditioner='neighbours'), model.articulated, q, 0.0)
    assert isinstance(anyway, ap.GroupPreconditioner)
    monkeypatch.setattr(ap, 'MAX_GROUP_BLOBS', 3 * len(write_chain.__defaults__[-1]) - 1)
    _, _, large = art.articulated_problem(model.replace(preconditioner='neighbours'), model.articulated, q, 0.0)
    assert type(large) is art.ArticulatedPreconditioner
