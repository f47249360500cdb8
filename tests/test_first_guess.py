"""Extrapolated first guesses of the deterministic solves (Scheme.warm_guess, keep_guess).

Laws: the extrapolation reproduces solutions that are polynomials of time of its degree; the published solves
(``preconditioner block_diagonal``) and the stochastic schemes keep the last solution as the guess; a run takes
fewer GMRES iterations to the same trajectory within the solver tolerance; a restart from the saved history
repeats the uninterrupted run bit for bit."""
import numpy as np
import pytest

from quaternion_integrator.scheme_state import RunState
from quaternion_integrator.schemes import make_scheme
from test_neighbour_preconditioner import boomerang_model, grid


class _Context:
    """What keep_guess and warm_guess read of a step's context: the model's ``published_solves``."""

    def __init__(self, preconditioner):
        self.model = _Model(preconditioner)


class _Model:
    def __init__(self, preconditioner):
        self.preconditioner = preconditioner
        self.published_solves = preconditioner == 'block_diagonal'


def _kept(scheme, context, solutions):
    """The history (a RunState) after keeping ``solutions`` in turn."""
    state = RunState(None)
    for solution in solutions:
        state = scheme.keep_guess(context, state, solution)
    return state


@pytest.mark.parametrize('scheme_name', ['deterministic_forward_euler', 'deterministic_adams_bashforth',
                                         'deterministic_midpoint'])
def test_extrapolation_reproduces_polynomials_of_its_degree(scheme_name):
    """Solutions g(t) = a + b t + c t^2 at equally spaced times: after three kept solutions the guess is g at the
    next time exactly (to rounding); after two, a linear g is reproduced; the published solves take g0."""
    rng = np.random.default_rng(0)
    a, b, c = rng.normal(size=(3, 7))
    scheme = make_scheme(scheme_name, 0.1)
    auto = _Context('auto')
    state = _kept(scheme, auto, [a + b * k + c * k * k for k in range(3)])
    np.testing.assert_allclose(scheme.warm_guess(auto, state), a + 3 * b + 9 * c, rtol=0, atol=1e-12)
    linear = _kept(scheme, auto, [a + b * k for k in range(2)])
    np.testing.assert_allclose(scheme.warm_guess(auto, linear), a + 2 * b, rtol=0, atol=1e-12)
    published = _Context('block_diagonal')
    state = _kept(scheme, published, [a + b * k + c * k * k for k in range(3)])
    assert state.earlier_guesses is None
    np.testing.assert_array_equal(scheme.warm_guess(published, state), a + 2 * b + 4 * c)  # the last solution


def test_stochastic_schemes_keep_the_last_solution():
    scheme = make_scheme('stochastic_Slip_Trapz', 0.1)
    auto = _Context('auto')
    state = _kept(scheme, auto, [np.full(4, float(k)) for k in range(3)])
    assert state.earlier_guesses is None
    np.testing.assert_array_equal(scheme.warm_guess(auto, state), np.full(4, 2.0))


def _run(model, scheme_name, steps, state=None):
    scheme = make_scheme(scheme_name, 0.01)
    state = scheme.init(model, model.start_configuration) if state is None else state
    for _ in range(steps):
        state = scheme.step(model, state, None)
    return scheme, state


@pytest.mark.parametrize('scheme_name', ['deterministic_adams_bashforth', 'deterministic_midpoint'])
def test_fewer_iterations_to_the_same_trajectory(scheme_name, monkeypatch):
    """25 boomerangs under gravity, 6 steps of dt 0.01: fewer GMRES iterations with the extrapolated guesses than
    from the last solution (the scheme's flag off: the negative control; measured 21 against 33 iterations for
    Adams-Bashforth, 42 against 63 for midpoint), the same configuration within what solver_tolerance 1e-8
    allows (measured 3e-9 of the distance travelled, asserted 1e-6)."""
    model = boomerang_model(grid(25, 4.0), seed=2, preconditioner='auto')
    _, extrapolated = _run(model, scheme_name, 6)
    scheme_class = type(make_scheme(scheme_name, 0.01))
    monkeypatch.setattr(scheme_class, 'extrapolate_guesses', False)
    _, last = _run(model, scheme_name, 6)
    assert extrapolated.counters.gmres_iterations < last.counters.gmres_iterations, (
        extrapolated.counters.gmres_iterations, last.counters.gmres_iterations)
    travelled = np.abs(last.configuration.locations - model.start_configuration.locations).max()
    assert np.abs(extrapolated.configuration.locations - last.configuration.locations).max() < 1e-6 * travelled


def test_restart_from_the_history_repeats_the_run_bit_for_bit():
    """Three steps, the history saved (RunState.history, what a restart record holds), a fresh state made from it
    (Scheme.init with the history), three more steps: the same configuration and guesses as six steps at once."""
    model = boomerang_model(grid(9, 4.0), seed=3, preconditioner='auto')
    scheme, whole = _run(model, 'deterministic_adams_bashforth', 6)
    _, half = _run(model, 'deterministic_adams_bashforth', 3)
    history = half.history()
    assert history['earlier_guesses'].shape == (2, half.first_guess.size)
    restarted = scheme.init(model, half.configuration, half.step, history=history)
    assert isinstance(restarted, RunState) and isinstance(restarted.earlier_guesses, np.ndarray)
    _, rest = _run(model, 'deterministic_adams_bashforth', 3, state=restarted)
    np.testing.assert_array_equal(rest.configuration.locations, whole.configuration.locations)
    np.testing.assert_array_equal(rest.configuration.orientations, whole.configuration.orientations)
    np.testing.assert_array_equal(rest.earlier_guesses, whole.earlier_guesses)
