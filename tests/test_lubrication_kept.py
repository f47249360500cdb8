"""Lubrication solves that remember: kept preconditioners and first guesses (``lubrication.integrators.KeptSolves``).

Laws: every solve solves the same linear system to ``solver_tolerance`` whatever its preconditioner and first
guess, so the runs under ``preconditioner auto`` (kept) follow the published solves (``block_diagonal``) within
what the tolerance allows, with fewer sparse factorisations (the control: a looser tolerance moves the run
off by more than that bound, so the comparison can fail); a configuration whose gaps have closed wears the kept
preconditioner and the next step builds a fresh one, whose solve takes the published iterations; a restart
from the saved history repeats the run bit for bit (the control: the history without the kept preconditioner's
configuration, so that it is built at the restart, gives another run).
"""
import numpy as np
import pytest

from body.body import Body, Configuration, bodies_to_arrays
from lubrication import brownian, integrators, sparse_factor
from multi_bodies.files.input_options import options_with
from multi_bodies.run.record_checks import _check_history
from multi_bodies.solver import body_solver, user_hooks
from multi_bodies.solver.model import Model
from quaternion_integrator.schemes import make_scheme

SIDE, SPACING, HEIGHT = 4, 2.3, 1.2  # 16 spheres of radius 1, gaps of 0.3 between neighbours, 0.2 to the wall


def sphere_model(preconditioner='auto', tolerance=1e-10, spacing=SPACING, height=HEIGHT, spin=None):
    """16 unit spheres (eta 1, weight 1 each) on a jittered square lattice above the wall; ``spin``: the rate
    about y every sphere is held at (``omega_one_roller``, ``free_kinematics False``), or None."""
    jitter = np.random.default_rng(1).uniform(-0.05, 0.05, (SIDE * SIDE, 2))
    bodies = []
    for k in range(SIDE * SIDE):
        centre = [spacing * (k % SIDE) + jitter[k, 0], spacing * (k // SIDE) + jitter[k, 1], height]
        body = Body(centre, [1.0, 0.0, 0.0, 0.0], np.zeros((1, 3)), 1.0)
        body.ID, body.body_length = 'sphere', 2.0
        bodies.append(body)
    physics = dict(g=1.0, repulsion_strength_wall=0.0, debye_length_wall=1.0, repulsion_strength=0.0,
                   debye_length=1.0, periodic_length=np.zeros(3), blob_radius=1.0, blob_mass=1.0)
    return Model(bodies, bodies_to_arrays(bodies), user_hooks.load_user_hooks('/nonexistent'), physics, 1.0, 1.0,
                 tolerance, vector_product_name='C++', blobs_name='C++', blob_blob_name='None',
                 preconditioner=preconditioner, omega_one_roller=(0.0, 0.0 if spin is None else spin, 0.0),
                 free_kinematics=spin is None)


def run(model, steps, scheme_name='lubrication_trapezoidal', state=None, seed=4, rng=None, **options):
    options = options_with(**dict(dict(kT=0.05, dt=0.01), **options))
    scheme = make_scheme(scheme_name, float(options.dt), options)
    state = scheme.init(model, model.start_configuration) if state is None else state
    rng = np.random.default_rng(seed) if rng is None else rng
    for _ in range(steps):
        state = scheme.step(model, state, rng)
    return scheme, state, rng


def count_factorisations(monkeypatch):
    """Every sparse factorisation of a lubrication or torque preconditioner from now on (a list that fills)."""
    made = []
    original = sparse_factor.factorise

    def spy(*args, **kwargs):
        made.append(1)
        return original(*args, **kwargs)
    monkeypatch.setattr(sparse_factor, 'factorise', spy)
    return made


@pytest.mark.parametrize('scheme_name, spin', [('lubrication_trapezoidal', None),
                                               ('lubrication_trapezoidal_rollers', 2.0), ('lubrication_EM', None)])
def test_kept_solves_follow_the_published_solves_with_fewer_factorisations(scheme_name, spin, monkeypatch):
    """8 steps of 16 spheres settling with Brownian motion (kT 0.05, dt 0.01): the kept run ends within
    1e-8 of the distance travelled from the published one at solver_tolerance 1e-10 (each solve is exact to
    1e-10 of its right-hand side, 16-32 solves add up; measured 3-6e-11), with at most a third of its
    factorisations (measured 3-5 against 16-32).  Control: at solver_tolerance 1e-6 the kept run leaves the
    published one by more than that bound (measured 4e-7 to 1.2e-6)."""
    steps = 8
    made = count_factorisations(monkeypatch)
    _, published, _ = run(sphere_model('block_diagonal', spin=spin), steps, scheme_name)
    published_factorisations = len(made)
    made.clear()
    _, kept, _ = run(sphere_model('auto', spin=spin), steps, scheme_name)
    assert published.preconditioner_configuration is None and kept.preconditioner_configuration is not None
    assert published_factorisations >= 2 * steps and len(made) <= published_factorisations / 3, \
        (published_factorisations, len(made))
    start = sphere_model().start_configuration.locations
    travelled = np.linalg.norm(published.configuration.locations - start)
    assert travelled > 1e-2
    off = np.linalg.norm(kept.configuration.locations - published.configuration.locations)
    assert off < 1e-8 * travelled, off / travelled
    # a preconditioner built nearby costs few iterations (measured: fewer, with the first guesses)
    assert kept.counters.gmres_iterations <= 1.25 * published.counters.gmres_iterations
    # the control: a loose tolerance shows in the comparison
    _, loose, _ = run(sphere_model('auto', tolerance=1e-6, spin=spin), steps, scheme_name)
    assert np.linalg.norm(loose.configuration.locations - published.configuration.locations) > 1e-8 * travelled


def test_closed_gaps_wear_the_kept_preconditioner_and_the_next_step_builds_a_fresh_one(monkeypatch):
    """Kept at the lattice of gaps 0.3 (0.2 to the wall), the preconditioner meets the lattice of gaps 0.06
    (0.04): the predictor there takes more iterations than at the build, which ends the kept one; the next step
    builds at its start and its predictor takes exactly the iterations of the published solve there (a fresh
    preconditioner, a zero first guess, the same noise) when that solve too takes the least-true-residual
    iterate, and no more than the published solve."""
    settings = brownian.lubrication_settings(1.0, 1.0)
    near, far = sphere_model(spacing=SPACING, height=HEIGHT), sphere_model(spacing=2.06, height=1.04)
    orientations = near.start_configuration.orientations

    def weight(locations, orientations):
        force_torque = np.zeros((locations.shape[0], 6))
        force_torque[:, 2] = -1.0
        return force_torque
    kept = integrators.KeptSolves(settings, 1e-8)
    for _ in range(2):
        integrators.trapezoidal_step(settings, near.start_configuration.locations, orientations, weight, 0.05, 1e-4,
                                     np.random.default_rng(1), 1e-8, kept=kept)
    built_at, fewest = kept.built_at[0].copy(), kept.fewest
    assert kept.solves == 2 and np.array_equal(built_at, near.start_configuration.locations)
    closed = far.start_configuration.locations
    step = integrators.trapezoidal_step(settings, closed, orientations, weight, 0.05, 1e-4, np.random.default_rng(2),
                                        1e-8, kept=kept)
    assert kept.built_at is None  # worn: ended
    assert step.counts['factorisations'] == 1  # the corrector's own, not kept
    integrators.trapezoidal_step(settings, closed, orientations, weight, 0.05, 1e-4, np.random.default_rng(3), 1e-8,
                                 kept=kept)
    assert np.array_equal(kept.built_at[0], closed) and kept.solves == 1
    iterations, least_residual = [], []
    original = body_solver.solve  # the one solve, which every lubrication solve reaches through its Solver

    def spy(*args, **kwargs):
        result = original(*args, **kwargs)
        iterations.append(result.iterations)
        least_residual.append(original(*args, **dict(kwargs, minimal_residual=True)).iterations)
        return result
    monkeypatch.setattr(body_solver, 'solve', spy)
    integrators.trapezoidal_step(settings, closed, orientations, weight, 0.05, 1e-4, np.random.default_rng(3), 1e-8)
    # the kept solves take GMRES's least-true-residual iterate, which stops no later than the published one
    assert kept.fewest == least_residual[0] > fewest and least_residual[0] <= iterations[0]


def test_restart_with_kept_lubrication_solves_repeats_the_run_bit_for_bit():
    """6 steps at solver_tolerance 1e-4 (where another preconditioner or first guess shows), spinning rollers
    (torque solves and their guesses too): 3 steps, the history through the record checks, a fresh state from
    it, 3 more steps, ends where the run in one go ends, to the bit.  Control: the history without the kept
    preconditioner's configuration (built again at the restart instead) ends elsewhere."""
    model = sphere_model('auto', tolerance=1e-4, spin=2.0)
    name = 'lubrication_trapezoidal_rollers'
    _, whole, _ = run(model, 6, name)
    scheme, half, rng = run(model, 3, name)
    history = half.history()
    _check_history(history, SIDE * SIDE)
    assert history['preconditioner_configuration'] is not None and history['roller_torque_guess'] is not None
    rng_state = rng.bit_generator.state
    restarted = scheme.init(model, half.configuration, half.step, history=history)
    assert restarted.preconditioner is None
    _, rest, _ = run(model, 3, name, state=restarted, rng=rng)
    np.testing.assert_array_equal(rest.configuration.locations, whole.configuration.locations)
    np.testing.assert_array_equal(rest.configuration.orientations, whole.configuration.orientations)
    rng.bit_generator.state = rng_state
    blind = scheme.init(model, half.configuration, half.step,
                        history=dict(history, preconditioner_configuration=None, preconditioner_solves=None,
                                     preconditioner_fewest=None))
    _, other, _ = run(model, 3, name, state=blind, rng=rng)
    assert not np.array_equal(other.configuration.locations, whole.configuration.locations)
    assert np.abs(other.configuration.locations - whole.configuration.locations).max() < 1e-3
