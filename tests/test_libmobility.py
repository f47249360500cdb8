"""libMobility's Python interface on the CPU (``mobility.libmobility``): SelfMobility, NBody, DPStokes.

What the numbers are checked against (never the face's own output):

* the conventions of libMobility's interface (``../shared/manual/libmobility_interface.md``): constructor
  periodicities, shapes, errors (RuntimeError with libMobility's message fragments);
* analytic laws: the self-mobility of a sphere, ``1/(6 pi eta a)`` and ``1/(8 pi eta a^3)``; above a no-slip
  wall the Rotne-Prager-Blake self-mobility at RPY level (Swan and Brady, Phys. Fluids 19, 113306, 2007,
  eqs. for the self terms: translation parallel ``1 - 9/16 x + 1/8 x^3 - 1/16 x^5``, perpendicular
  ``1 - 9/8 x + 1/2 x^3 - 1/8 x^5``, rotation parallel ``1 - 5/16 x^3``, perpendicular ``1 - 1/8 x^3``,
  x = a/h) and its divergence (below);
* the package's own products through another backend (NBody must equal them to round-off);
* statistics with a tolerance from the standard error, each with a negative control that must fail.
"""
import json
import os
from pathlib import Path

import numpy as np
import pytest

from conftest import REFERENCE_DIR
from mobility import interface
from mobility.libmobility import DPStokes, LibMobilityError, NBody, SelfMobility

ETA = 0.7
RADIUS = 0.9


def _python_mobility(kind):
    """The package's NumPy backend (the readable reference; NBody runs the compiled one where built)."""
    return interface.make_mobility('python', interface.Geometry(kind), ETA, RADIUS)


def _wall_self_mobility(h, a=RADIUS, eta=ETA):
    """Rotne-Prager-Blake self-mobility (6, 6) of one sphere at height h >= a above a no-slip wall
    (Swan and Brady 2007): diagonal translation and rotation terms; the coupling is not asserted here."""
    x = a / h
    mu_t, mu_r = 1 / (6 * np.pi * eta * a), 1 / (8 * np.pi * eta * a ** 3)
    parallel = mu_t * (1 - 9 / 16 * x + 1 / 8 * x ** 3 - 1 / 16 * x ** 5)
    perpendicular = mu_t * (1 - 9 / 8 * x + 1 / 2 * x ** 3 - 1 / 8 * x ** 5)
    rot_parallel = mu_r * (1 - 5 / 16 * x ** 3)
    rot_perpendicular = mu_r * (1 - 1 / 8 * x ** 3)
    return np.array([parallel, parallel, perpendicular, rot_parallel, rot_parallel, rot_perpendicular])


def _grand_matrix(solver, n, include_angular):
    """The grand mobility (3n or 6n square) column by column through Mdot (libMobility's compute_M)."""
    size = 6 * n if include_angular else 3 * n
    M = np.zeros((size, size))
    for column in range(size):
        unit = np.zeros(size)
        unit[column] = 1.0
        if include_angular:
            U, W = solver.Mdot(unit[:3 * n].reshape(n, 3), unit[3 * n:].reshape(n, 3))
            M[:, column] = np.concatenate((U.reshape(-1), W.reshape(-1)))
        else:
            U, W = solver.Mdot(unit.reshape(n, 3))
            assert W is None
            M[:, column] = U.reshape(-1)
    return M


def _nbody(z='single_wall', include_angular=False, seed=1, wall_height=0.0, **parameters):
    solver = NBody('open', 'open', z)
    if z == 'single_wall':
        parameters.setdefault('wallHeight', wall_height)
    if parameters:
        solver.setParameters(**parameters)
    solver.initialize(viscosity=ETA, hydrodynamicRadius=RADIUS, includeAngular=include_angular, seed=seed)
    return solver


def _self(include_angular=False, seed=1):
    solver = SelfMobility('open', 'open', 'open')
    solver.setParameters(5.0)
    solver.initialize(viscosity=ETA, hydrodynamicRadius=RADIUS, includeAngular=include_angular, seed=seed)
    return solver


def _blobs(n, seed=0, low=1.2, high=4.0):
    rng = np.random.default_rng(seed)
    positions = rng.uniform(-3, 3, (n, 3))
    positions[:, 2] = rng.uniform(low, high, n)
    return positions


# ------------------------------------------------------------------ the common interface
def test_precision_is_a_class_attribute():
    assert SelfMobility.precision == 'double' and NBody.precision == 'double'


@pytest.mark.parametrize('periodicity', [('open', 'open', 'wall'), ('Open', 'open', 'open'), ('open', 'open', 3)])
def test_invalid_periodicity_string(periodicity):
    for Solver in (SelfMobility, NBody):
        with pytest.raises(RuntimeError, match='Invalid periodicity'):
            Solver(*periodicity)


def test_each_solver_refuses_combinations_it_does_not_support():
    with pytest.raises(RuntimeError, match='open boundary'):
        SelfMobility('open', 'open', 'single_wall')
    with pytest.raises(RuntimeError, match='open in the plane'):
        NBody('periodic', 'open', 'open')
    with pytest.raises(RuntimeError, match='Invalid periodicity'):
        NBody('open', 'open', 'two_walls')


def test_errors_are_runtime_errors_and_user_input_errors():
    from utils import UserInputError
    assert issubclass(LibMobilityError, RuntimeError) and issubclass(LibMobilityError, UserInputError)


@pytest.mark.parametrize('shape', [(4, 6), (3, 1), (1, 4), (2, 3, 3), (4,)])
def test_bad_positions_shape(shape):
    for solver in (_self(), _nbody('open')):
        with pytest.raises(RuntimeError, match='shape|size'):
            solver.setPositions(np.random.default_rng(0).random(shape))


@pytest.mark.parametrize('dtype', [np.float32, np.float64, np.int64])
def test_any_real_dtype_and_non_contiguous_views(dtype):
    positions = _blobs(3)
    forces = np.random.default_rng(1).standard_normal((3, 3))
    solver = _nbody('single_wall')
    solver.setPositions(positions)
    expected, _ = solver.Mdot(forces)
    # a non-contiguous view of a larger array, in another dtype, flat
    big = np.zeros((9, 5), dtype=dtype)
    big[:, 2] = positions.reshape(-1).astype(dtype)
    solver.setPositions(big[:, 2])
    forces_view = np.zeros((3, 6))
    forces_view[:, ::2] = forces
    U, W = solver.Mdot(forces_view[:, ::2])
    assert U.dtype == np.float64 and U.shape == (3, 3) and W is None
    if dtype == np.float64:
        np.testing.assert_array_equal(U, expected)
    else:
        rounded = _nbody('single_wall')
        rounded.setPositions(positions.astype(dtype).astype(np.float64))
        np.testing.assert_array_equal(U, rounded.Mdot(forces)[0])


def test_output_shapes_follow_the_inputs():
    solver = _nbody('single_wall', include_angular=True)
    positions = _blobs(1)
    for p_shape in [(1, 3), (3,)]:
        solver.setPositions(positions.reshape(p_shape))
        for f_shape, t_shape in [((3,), (1, 3)), ((1, 3), (3,)), ((1, 3), (1, 3)), ((3,), (3,))]:
            F, T = np.ones(f_shape), np.ones(t_shape)
            U, W = solver.Mdot(F, T)
            assert U.shape == f_shape and W.shape == t_shape
            U, W = solver.Mdot(forces=F)
            assert U.shape == f_shape and W.shape == f_shape
            U, W = solver.Mdot(torques=T)
            assert U.shape == t_shape and W.shape == t_shape
        for output in solver.sqrtMdotW() + solver.divM() + solver.LangevinVelocities(1.0, 1.0):
            assert output.shape == p_shape
    plain = _nbody('open')
    plain.setPositions(positions.reshape(3))
    U, W = plain.Mdot(np.ones((1, 3)))
    assert U.shape == (1, 3) and W is None
    U, W = plain.sqrtMdotW()
    assert U.shape == (3,) and W is None


def test_inputs_of_the_wrong_size_and_torques_without_angular():
    solver = _nbody('open')
    solver.setPositions(_blobs(2))
    with pytest.raises(RuntimeError, match='size 3\\*N'):
        solver.Mdot(np.ones(9))
    with pytest.raises(RuntimeError, match='includeAngular'):
        solver.Mdot(np.ones(6), np.ones(6))
    angular = _nbody('open', include_angular=True)
    angular.setPositions(_blobs(2))
    with pytest.raises(RuntimeError, match='size 3\\*N'):
        angular.Mdot(np.ones(6), np.ones(3))
    with pytest.raises(RuntimeError, match='NaN'):
        angular.Mdot(np.full(6, np.nan))


def test_calls_before_set_positions_or_initialize():
    solver = _nbody('single_wall')
    with pytest.raises(RuntimeError, match='setPositions'):
        solver.Mdot(np.ones(3))
    with pytest.raises(RuntimeError, match='setPositions'):
        solver.sqrtMdotW()
    with pytest.raises(RuntimeError, match='setPositions'):
        solver.LangevinVelocities(1.0, 1.0)
    fresh = NBody('open', 'open', 'open')
    with pytest.raises(RuntimeError, match='initialize'):
        fresh.setPositions(_blobs(1))
    # clean() frees the solver: it must be initialized (and given positions) again
    solver.setPositions(_blobs(1))
    solver.clean()
    with pytest.raises(RuntimeError, match='initialize'):
        solver.Mdot(np.ones(3))


def test_self_mobility_mdot_needs_no_positions():
    solver = _self(include_angular=True)
    F = np.random.default_rng(2).standard_normal((4, 3))
    T = np.random.default_rng(3).standard_normal((4, 3))
    U, W = solver.Mdot(F, T)
    np.testing.assert_allclose(U, F / (6 * np.pi * ETA * RADIUS), rtol=1e-14)
    np.testing.assert_allclose(W, T / (8 * np.pi * ETA * RADIUS ** 3), rtol=1e-14)


# ------------------------------------------------------------------ NBody
def test_nbody_parameters():
    with pytest.raises(RuntimeError, match='wallHeight'):
        NBody('open', 'open', 'single_wall').setParameters('advise', -1, -1)          # a wall needs wallHeight
    with pytest.raises(RuntimeError, match='wallHeight'):
        NBody('open', 'open', 'open').setParameters(wallHeight=0.0)                  # open z forbids it
    with pytest.raises(RuntimeError, match='algorithm'):
        NBody('open', 'open', 'open').setParameters(algorithm='fastest')
    with pytest.raises(RuntimeError, match='wallHeight'):
        NBody('open', 'open', 'single_wall').initialize(viscosity=1.0, hydrodynamicRadius=1.0)
    # open z: initialize without setParameters is fine; the three first parameters positionally
    NBody('open', 'open', 'open').initialize(viscosity=1.0, hydrodynamicRadius=1.0)
    solver = NBody('open', 'open', 'open')
    solver.setParameters('naive', 2, 3)
    solver.initialize(viscosity=1.0, hydrodynamicRadius=1.0)
    solver.setPositions(_blobs(6))
    with pytest.raises(RuntimeError, match='batch'):
        solver.setPositions(_blobs(5))


@pytest.mark.parametrize('wall_height', [0.0, 5.4, -10.0])
def test_nbody_wall_at_wall_height_equals_the_package_product(wall_height):
    positions = _blobs(5, seed=4)
    F = np.random.default_rng(5).standard_normal((5, 3))
    T = np.random.default_rng(6).standard_normal((5, 3))
    solver = _nbody('single_wall', include_angular=True, wall_height=wall_height)
    solver.setPositions(positions + [0.0, 0.0, wall_height])
    U, W = solver.Mdot(F, T)
    U_ref, W_ref = _python_mobility('single_wall').product(positions, F.reshape(-1), T.reshape(-1))
    np.testing.assert_allclose(U.reshape(-1), U_ref, rtol=1e-12, atol=1e-15 * np.abs(U_ref).max())
    np.testing.assert_allclose(W.reshape(-1), W_ref, rtol=1e-12, atol=1e-15 * np.abs(W_ref).max())
    linear = _nbody('single_wall', wall_height=wall_height)
    linear.setPositions(positions + [0.0, 0.0, wall_height])
    U_only, _ = linear.Mdot(F)
    np.testing.assert_allclose(U_only.reshape(-1), _python_mobility('single_wall').velocities(positions, F.reshape(-1)),
                               rtol=1e-12, atol=1e-15 * np.abs(U_ref).max())


def test_nbody_free_space_equals_the_package_product():
    positions = _blobs(6, seed=7, low=-3, high=3)
    F = np.random.default_rng(8).standard_normal(18)
    T = np.random.default_rng(9).standard_normal(18)
    solver = _nbody('open', include_angular=True)
    solver.setPositions(positions)
    U, W = solver.Mdot(F, T)
    U_ref, W_ref = _python_mobility('free_space').product(positions, F, T)
    np.testing.assert_allclose(U.reshape(-1), U_ref, rtol=1e-12, atol=1e-15 * np.abs(U_ref).max())
    np.testing.assert_allclose(W.reshape(-1), W_ref, rtol=1e-12, atol=1e-15 * np.abs(W_ref).max())


@pytest.mark.parametrize('include_angular', [False, True])
def test_nbody_batches_do_not_interact(include_angular):
    batches, per_batch = 4, 3
    positions = _blobs(batches * per_batch, seed=10)
    F = np.random.default_rng(11).standard_normal((batches * per_batch, 3))
    T = np.random.default_rng(12).standard_normal((batches * per_batch, 3)) if include_angular else None
    solver = _nbody('single_wall', include_angular=include_angular, wall_height=1.0, Nbatch=batches,
                    NperBatch=per_batch)
    solver.setPositions(positions + [0, 0, 1.0])
    U, W = solver.Mdot(F, T)
    reference = _python_mobility('single_wall')
    for b in range(batches):
        part = slice(b * per_batch, (b + 1) * per_batch)
        U_ref, W_ref = reference.product(positions[part], F[part].reshape(-1),
                                         None if T is None else T[part].reshape(-1))
        np.testing.assert_allclose(U[part].reshape(-1), U_ref, rtol=1e-12, atol=1e-15 * np.abs(U_ref).max())
        if include_angular:
            np.testing.assert_allclose(W[part].reshape(-1), W_ref, rtol=1e-12, atol=1e-15 * np.abs(W_ref).max())


@pytest.mark.parametrize('wall_height', [0.0, 5.4, -10.0])
def test_nbody_self_mobility_above_the_wall_is_swan_brady(wall_height):
    """The face's wall (height, shift, prefactors, angular layout) against the analytic self terms."""
    solver = _nbody('single_wall', include_angular=True, wall_height=wall_height)
    for h in (RADIUS, 1.5, 3.7, 20.0):
        solver.setPositions([[0.3, -1.0, h + wall_height]])
        M = _grand_matrix(solver, 1, True)
        np.testing.assert_allclose(np.diag(M), _wall_self_mobility(h), rtol=1e-13)
        np.testing.assert_allclose(M, M.T, atol=1e-15 * np.abs(M).max())


def test_nbody_below_the_wall():
    solver = _nbody('single_wall', wall_height=2.0)
    solver.setPositions([[0.0, 0.0, 2.0]])        # a centre on the wall is accepted
    with pytest.raises(RuntimeError, match='fallen below the wall'):
        solver.setPositions([[0.0, 0.0, 3.0], [1.0, 0.0, 1.999]])


# ------------------------------------------------------------------ noise and drift
def _covariance_check(samples, M, factor):
    """max over entries of |sample covariance - factor^2 M| / its standard error (Gaussian samples:
    var(x_i x_j) = M_ii M_jj + M_ij^2 per sample)."""
    n = samples.shape[0]
    C = samples.T @ samples / n
    expected = factor ** 2 * M
    d = np.diag(expected)
    standard_error = np.sqrt((np.outer(d, d) + expected ** 2) / n)
    return np.max(np.abs(C - expected) / standard_error)


@pytest.mark.parametrize('include_angular', [False, True])
def test_sqrtMdotW_covariance_is_the_mobility(include_angular):
    """Batches of the same two-blob configuration give independent samples of M^{1/2} z in one call."""
    copies, prefactor = 400, 1.7
    pair = np.array([[0.0, 0.0, 1.3], [1.9, 0.4, 2.2]])
    solver = _nbody('single_wall', include_angular=include_angular, seed=21, Nbatch=copies, NperBatch=2)
    solver.setPositions(np.tile(pair, (copies, 1)))
    one = _nbody('single_wall', include_angular=include_angular)
    one.setPositions(pair)
    M = _grand_matrix(one, 2, include_angular)
    samples = []
    for _ in range(10):
        U, W = solver.sqrtMdotW(prefactor)
        U = U.reshape(copies, 6)
        samples.append(U if W is None else np.hstack((U, W.reshape(copies, 6))))
    samples = np.vstack(samples)              # 4,000 independent samples of prefactor M^{1/2} z
    # 4.5 standard errors over 21 or 78 distinct entries: a false alarm below 1e-3
    assert _covariance_check(samples, M, prefactor) < 4.5
    # negative control: a prefactor 10% off (21% in the covariance, about 9 standard errors) must fail
    assert _covariance_check(samples, M, 1.1 * prefactor) > 4.5


def test_self_mobility_noise_is_exact():
    solver = _self(include_angular=True, seed=5)
    solver.setPositions(np.zeros((2000, 3)))
    U, W = solver.sqrtMdotW(2.0)
    samples = np.hstack((U, W))
    expected = np.array([1 / (6 * np.pi * ETA * RADIUS)] * 3 + [1 / (8 * np.pi * ETA * RADIUS ** 3)] * 3)
    assert _covariance_check(samples, np.diag(expected), 2.0) < 4.5
    assert _covariance_check(samples, np.diag(expected), 2.2) > 4.5


def _exact_wall_divergence(h, a=RADIUS, eta=ETA):
    """z component of div M for one sphere above the wall: d/dh of the perpendicular self-mobility.

    M_zz(h) = mu (1 - 9/8 x + 1/2 x^3 - 1/8 x^5), x = a/h (Swan and Brady 2007); the self-mobility depends
    on h only and M_xz = M_yz = 0, so (div M)_i = sum_j dM_ij/dr_j = (0, 0, dM_zz/dh) with
    dM_zz/dh = mu (9/8 a/h^2 - 3/2 a^3/h^4 + 5/8 a^5/h^6).  The angular block's divergence
    (sum_j dM^WF_ij / dr_j) vanishes: M^WF of one sphere has only xy and yx entries.
    """
    mu = 1 / (6 * np.pi * eta * a)
    return mu * (9 / 8 * a / h ** 2 - 3 / 2 * a ** 3 / h ** 4 + 5 / 8 * a ** 5 / h ** 6)


@pytest.mark.parametrize('include_angular', [False, True])
def test_divM_mean_is_the_exact_wall_divergence(include_angular):
    """Batches of single blobs (each its own system) at two heights: the mean of many RFD samples."""
    heights = np.array([1.3, 3.0]) * RADIUS
    copies, calls = 2000, 3
    positions = np.zeros((2 * copies, 3))
    positions[:copies, 2], positions[copies:, 2] = heights
    solver = _nbody('single_wall', include_angular=include_angular, seed=33, wall_height=-2.0,
                    Nbatch=2 * copies, NperBatch=1)
    solver.setPositions(positions - [0, 0, 2.0])
    kbt = 0.8
    linear, angular = [], []
    for _ in range(calls):
        U, W = solver.divM(kbt)
        linear.append(U)
        angular.append(W)
    np.testing.assert_array_equal(solver._positions, positions - [0, 0, 2.0])   # positions restored
    for k, h in enumerate(heights):
        rows = slice(k * copies, (k + 1) * copies)
        samples = np.vstack([U[rows] for U in linear])
        mean = samples.mean(axis=0)
        standard_error = samples.std(axis=0, ddof=1) / np.sqrt(samples.shape[0])
        expected = kbt * np.array([0.0, 0.0, _exact_wall_divergence(h)])
        assert np.all(np.abs(mean - expected) < 4.5 * standard_error), (h, mean, expected, standard_error)
        # negative control: the divergence 15% larger (about 7 standard errors in z) must be rejected
        assert abs(mean[2] - 1.15 * expected[2]) > 4.5 * standard_error[2]
        if include_angular:
            rotation = np.vstack([W[rows] for W in angular])
            assert np.all(np.abs(rotation.mean(axis=0)) <= 4.5 * rotation.std(axis=0, ddof=1)
                          / np.sqrt(rotation.shape[0]))
        else:
            assert angular[0] is None


def test_divM_is_zero_without_a_wall():
    for solver in (_nbody('open', include_angular=True), _self(include_angular=True)):
        solver.setPositions(_blobs(3))
        U, W = solver.divM(1.0)
        assert not U.any() and not W.any()


@pytest.mark.parametrize('make', [lambda: _nbody('single_wall', include_angular=True, seed=0),
                                  lambda: _self(include_angular=True, seed=0)])
def test_langevin_velocities_at_zero_temperature_are_mdot(make):
    solver = make()
    solver.setPositions(_blobs(4))
    F = np.random.default_rng(13).standard_normal((4, 3))
    T = np.random.default_rng(14).standard_normal((4, 3))
    U, W = solver.LangevinVelocities(0.01, 0.0, F, T)
    U_ref, W_ref = solver.Mdot(F, T)
    np.testing.assert_array_equal(U, U_ref)
    np.testing.assert_array_equal(W, W_ref)
    U, W = solver.LangevinVelocities(0.01, 0.0)
    assert not U.any() and not W.any()


def test_langevin_velocities_add_noise_and_drift_from_the_seeded_streams():
    positions = _blobs(3)
    F = np.random.default_rng(15).standard_normal((3, 3))
    dt, kbt = 0.01, 0.5
    first = _nbody('single_wall', include_angular=True, seed=77)
    first.setPositions(positions)
    U, W = first.LangevinVelocities(dt, kbt, F)
    # the same seed, the parts one by one
    parts = _nbody('single_wall', include_angular=True, seed=77)
    parts.setPositions(positions)
    M_U, M_W = parts.Mdot(F)
    noise_U, noise_W = parts.sqrtMdotW(np.sqrt(2 * kbt / dt))
    drift_U, drift_W = parts.divM(kbt)
    np.testing.assert_allclose(U, M_U + noise_U + drift_U, rtol=1e-14, atol=1e-16)
    np.testing.assert_allclose(W, M_W + noise_W + drift_W, rtol=1e-14, atol=1e-16)


@pytest.mark.parametrize('make', [lambda seed: _nbody('single_wall', include_angular=True, seed=seed),
                                  lambda seed: _nbody('open', seed=seed),
                                  lambda seed: _self(include_angular=True, seed=seed)])
def test_seeded_calls_repeat_exactly(make):
    positions = _blobs(3)

    def run(seed):
        solver = make(seed)
        solver.setPositions(positions)
        outputs = []
        for call in (lambda: solver.sqrtMdotW(1.0), lambda: solver.divM(2.0), lambda: solver.sqrtMdotW(0.5),
                     lambda: solver.LangevinVelocities(0.1, 1.0, np.ones((3, 3)))):
            outputs += [x for x in call() if x is not None]
        return outputs

    first, again, other = run(123), run(123), run(124)
    for a, b in zip(first, again):
        np.testing.assert_array_equal(a, b)
    assert any(not np.array_equal(a, b) for a, b in zip(first, other))


def test_reinitialize_restarts_the_seeded_streams_and_scales_with_the_prefactor():
    solver = _nbody('single_wall', seed=9)
    solver.setPositions(_blobs(2))
    once, _ = solver.sqrtMdotW(1.0)
    solver.initialize(viscosity=ETA, hydrodynamicRadius=RADIUS, seed=9)
    solver.setPositions(_blobs(2))
    twice, _ = solver.sqrtMdotW(2.0)
    np.testing.assert_allclose(twice, 2 * once, rtol=1e-12)


# ------------------------------------------------------------------ DPStokes: DoublyPeriodicStokes' selection
DPSTOKES_DIR = REFERENCE_DIR / 'dpstokes'
Z_OF_GEOMETRY = {'TP': 'periodic', 'DP': 'open', 'DPBW': 'single_wall', 'DPSC': 'two_walls'}
KERNEL_OF_TYPE = {False: {0: 'w6', 1: 'w5', 2: 'w4'}, True: {0: 'w6', 1: 'w5', 3: 'w6w5', 4: 'w6w4', 5: 'w5w4'}}


def _dpstokes_cases():
    found = []
    for name in ('random', 'pair', 'roller'):
        for path in sorted((DPSTOKES_DIR / name).glob('*.json')):
            if path.with_suffix('.npz').exists():
                found.append((name, path))
    return found


DPSTOKES_CASES = _dpstokes_cases()


def _dpstokes_solver(run):
    """The README's call sequence of ``DPStokes`` for one run block of a reference JSON."""
    solver = DPStokes('periodic', 'periodic', Z_OF_GEOMETRY[run['geometry']])
    solver.setParameters(Lx=run['Lx_requested'], Ly=run['Ly_requested'], zmin=run['zmin'], zmax=run['zmax_requested'],
                         allowChangingBoxSize=True, allowUnsafeForces=True, parameter_selection='dpstokes',
                         kernel=KERNEL_OF_TYPE[run['has_torque']][run['kernType']])
    solver.initialize(viscosity=run['eta'], hydrodynamicRadius=run['radius'], includeAngular=run['has_torque'])
    return solver


def test_dpstokes_reference_folder_present():
    if not DPSTOKES_DIR.is_dir():
        pytest.skip('DoublyPeriodicStokes reference data not found at %s' % DPSTOKES_DIR)
    assert DPSTOKES_CASES, 'no reference files under %s' % DPSTOKES_DIR


@pytest.mark.parametrize('case', DPSTOKES_CASES, ids=[path.stem for _, path in DPSTOKES_CASES])
def test_dpstokes_selection_reproduces_every_reference_file(case):
    """Every file of ../shared/reference/dpstokes (held-back files dropped there too) through the face, by the
    README's call sequence; every output array to 1e-10 relative (max |ours - ref| / max |ref|)."""
    kind, path = case
    meta = json.loads(path.read_text())
    with np.load(path.with_suffix('.npz')) as archive:
        data = {key: archive[key] for key in archive.files}
    compared = []
    if kind in ('random', 'roller'):
        run = meta['force_only_run' if kind == 'random' else 'run']
        solver = _dpstokes_solver(run)
        solver.setPositions(data['positions'])
        U, W = solver.Mdot(data['forces'])
        assert W is None and U.shape == data['positions'].shape
        compared.append(('U_F', U, data['U_F']))
    if kind == 'random':
        solver = _dpstokes_solver(meta['force_torque_run'])
        solver.setPositions(data['positions'])
        for suffix, (U, W) in (('FT', solver.Mdot(data['forces'], data['torques'])),
                               ('Fonly', solver.Mdot(data['forces'])),
                               ('Tonly', solver.Mdot(torques=data['torques']))):
            compared += [('U_' + suffix, U, data['U_' + suffix]), ('W_' + suffix, W, data['W_' + suffix])]
    if kind == 'pair':
        run = meta['run']
        solver = _dpstokes_solver(run)
        M = data['M']
        columns = np.asarray(data['columns']).astype(int)
        for i_s in range(M.shape[0]):
            for i_z in range(M.shape[1]):
                solver.setPositions(data['positions'][i_s, i_z])
                ours = np.zeros_like(M[i_s, i_z])
                for j, column in enumerate(columns):
                    unit = np.zeros(12)
                    unit[column] = 1.0
                    if run['has_torque']:
                        U, W = solver.Mdot(unit[:6].reshape(2, 3), unit[6:].reshape(2, 3))
                        ours[:, j] = np.concatenate((U.ravel(), W.ravel()))
                    else:
                        U, _ = solver.Mdot(unit[:6].reshape(2, 3))
                        ours[:, j] = U.ravel()
                compared.append(('M[%d, %d]' % (i_s, i_z), ours, M[i_s, i_z]))
    errors = {name: np.max(np.abs(ours - ref)) / np.max(np.abs(ref)) for name, ours, ref in compared}
    worst = max(errors, key=errors.get)
    assert errors[worst] < 1e-10, '%s: %s off by %.3g relative' % (path.stem, worst, errors[worst])


def _small_dpstokes(z='single_wall', include_angular=False, selection='dpstokes', seed=3, **options):
    solver = DPStokes('periodic', 'periodic', z)
    parameters = dict(Lx=16.0, Ly=16.0, zmin=0.0, zmax=6.0)
    if selection == 'dpstokes':
        parameters.update(parameter_selection='dpstokes')
    parameters.update(options)
    solver.setParameters(**parameters)
    solver.initialize(viscosity=ETA, hydrodynamicRadius=RADIUS, includeAngular=include_angular, seed=seed)
    return solver


def test_dpstokes_constructor_and_parameters():
    for periodicity in [('open', 'periodic', 'open'), ('periodic', 'periodic', 'unspecified'),
                        ('periodic', 'open', 'single_wall')]:
        with pytest.raises(RuntimeError, match='doubly periodic solver'):
            DPStokes(*periodicity)
    with pytest.raises(RuntimeError, match='doubly periodic solver'):       # the extension needs the dpstokes tables
        DPStokes('periodic', 'periodic', 'periodic').setParameters(16.0, 16.0, 0.0, 8.0)
    with pytest.raises(RuntimeError, match='kernel'):
        DPStokes('periodic', 'periodic', 'open').setParameters(16.0, 16.0, 0.0, 8.0, kernel='w6')
    with pytest.raises(RuntimeError, match='parameter_selection'):
        DPStokes('periodic', 'periodic', 'open').setParameters(16.0, 16.0, 0.0, 8.0, parameter_selection='uammd')
    with pytest.raises(RuntimeError, match='setParameters'):
        DPStokes('periodic', 'periodic', 'open').initialize(viscosity=1.0, hydrodynamicRadius=1.0)
    with pytest.raises(RuntimeError, match='kernel'):
        _small_dpstokes(include_angular=True, kernel='w4')                 # w4 has no torque pair
    with pytest.raises(RuntimeError, match='whole number of cells'):     # 16.3 is not whole cells of the w6 grid
        _small_dpstokes(Ly=16.3)
    assert DPStokes.precision == 'double'


def test_dpstokes_wall_checks():
    bottom = _small_dpstokes('single_wall')
    bottom.setPositions([[1.0, 2.0, 0.0]])                  # on the wall: accepted
    with pytest.raises(RuntimeError, match='passed through a wall'):
        bottom.setPositions([[1.0, 2.0, 3.0], [0.0, 0.0, -1e-9]])
    slit = _small_dpstokes('two_walls')
    with pytest.raises(RuntimeError, match='passed through a wall'):
        slit.setPositions([[1.0, 2.0, 6.0 + 1e-9]])
    with pytest.raises(RuntimeError, match='passed through a wall'):
        slit.setPositions([[1.0, 2.0, -0.1]])


def test_dpstokes_open_net_force_check():
    solver = _small_dpstokes('open')
    solver.setPositions([[1.0, 2.0, 3.0], [5.0, 1.0, 2.0]])
    with pytest.raises(RuntimeError, match='DPStokes'):
        solver.Mdot([[1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    U, _ = solver.Mdot([[1.0, 0.5, 0.0], [-1.0, -0.5, 0.0]])          # zero net force: fine
    assert U.shape == (2, 3)
    with pytest.raises(RuntimeError, match='DPStokes'):                 # the Lanczos vectors have a net force
        solver.sqrtMdotW()
    unsafe = _small_dpstokes('open', allowUnsafeForces=True)
    unsafe.setPositions([[1.0, 2.0, 3.0], [5.0, 1.0, 2.0]])
    unsafe.Mdot([[1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    assert unsafe.sqrtMdotW()[0].shape == (2, 3)


@pytest.mark.parametrize('selection', ['dpstokes', 'libmobility'])
def test_dpstokes_langevin_at_zero_temperature_and_seeds(selection):
    positions = [[1.0, 2.0, 3.0], [5.0, 1.0, 2.0]]
    F = np.array([[0.3, -1.0, 0.2], [1.0, 0.4, -0.7]])
    T = np.array([[0.1, 0.2, -0.3], [0.0, 0.5, 0.1]])

    def run(seed):
        solver = _small_dpstokes('single_wall', include_angular=True, selection=selection, seed=seed)
        solver.setPositions(positions)
        U, W = solver.LangevinVelocities(0.1, 0.0, F, T)
        U_ref, W_ref = solver.Mdot(F, T)
        np.testing.assert_array_equal(U, U_ref)
        np.testing.assert_array_equal(W, W_ref)
        return solver.sqrtMdotW(0.7) + solver.divM(0.5)

    first, again, other = run(11), run(11), run(12)
    for a, b in zip(first, again):
        np.testing.assert_array_equal(a, b)
    assert not np.array_equal(first[0], other[0])


# ------------------------------------------------------------------ DPStokes: libMobility's own selection
LIBMOBILITY_DIR = REFERENCE_DIR / 'libmobility'
EPS_100 = 100 * np.finfo(np.float64).eps          # libMobility's tolerance for a module declaring "double"
WALL_ETA = 1 / 4 / np.sqrt(np.pi)                 # libMobility's test_wall_mobility: eta, a = 1, box 76.8
# Heights checked: every one with RMB_LIBMOBILITY_FULL=1 (3,888 products, many minutes; all passed
# when written); by default a spread subset near the wall and in the bulk (about 300 products).
FULL_SWEEP = bool(os.environ.get('RMB_LIBMOBILITY_FULL'))
SUBSET = {('self', True): [1, 5, 10, 17, 25, 35, 47, 59], ('self', False): [2, 20, 59],
          ('pair', True): [1, 6, 13, 25], ('pair', False): [3, 25]}


def _wall_solver(z_mode, shift, include_angular=False):
    """libMobility's test_wall_mobility set-up: DPStokes over [0, 19.2] + shift in a 76.8 box, default selection."""
    solver = DPStokes('periodic', 'periodic', z_mode)
    solver.setParameters(Lx=76.8, Ly=76.8, zmin=0 + shift, zmax=19.2 + shift, allowChangingBoxSize=False)
    solver.initialize(viscosity=WALL_ETA, hydrodynamicRadius=1.0, includeAngular=include_angular)
    return solver


def _compute_M(solver, n):
    """Column i = Mdot(e_i), forces only (libMobility's tests/utils compute_M)."""
    M = np.zeros((3 * n, 3 * n))
    for i in range(3 * n):
        unit = np.zeros(3 * n)
        unit[i] = 1.0
        M[:, i] = solver.Mdot(unit.reshape(n, 3))[0].reshape(-1)
    return M


def _load_libmobility(name):
    path = LIBMOBILITY_DIR / (name + '.npz')
    if not path.exists():
        pytest.skip('libMobility reference matrices not found at %s' % LIBMOBILITY_DIR)
    with np.load(path) as archive:
        return archive['M'], archive['heights'].ravel()


def _indices(kind, count, shift):
    return list(range(count)) if FULL_SWEEP else SUBSET[(kind, shift == 0)]


@pytest.mark.parametrize('shift', [0, 5.4, -10])
@pytest.mark.parametrize('z_mode, tag', [('single_wall', 'bw'), ('two_walls', 'sc')])
def test_libmobility_self_mobility_linear(z_mode, tag, shift):
    """libMobility's self-mobility files (w = 4, bottom wall / slit) at 100 eps, as its test compares them: the
    diagonal of M / (1/(6 pi eta a)) with rtol = atol = 100 eps.  (The xy entries of the stored matrices, 1e-8
    to 1e-7, which libMobility's test does not compare, differ from ours by a factor 0.376; see
    doc/libmobility.md.)"""
    M_ref, heights = _load_libmobility('self_mobility_%s_w4' % tag)
    solver = _wall_solver(z_mode, shift)
    for i in _indices('self', heights.size, shift):
        solver.setPositions(np.array([[76.8 / 2, 76.8 / 2, heights[i] + shift]]))
        M = _compute_M(solver, 1) / (1 / (6 * np.pi * WALL_ETA * 1.0))
        assert np.allclose(np.diag(M), np.diag(M_ref[i]), rtol=EPS_100, atol=EPS_100), \
            (i, heights[i], np.abs(np.diag(M) - np.diag(M_ref[i])).max())


@pytest.mark.parametrize('shift', [0, 5.4, -10])
@pytest.mark.parametrize('z_mode, tag', [('single_wall', 'bw'), ('two_walls', 'sc')])
def test_libmobility_pair_mobility_linear(z_mode, tag, shift):
    """libMobility's pair-mobility files: every entry of M / (1/(6 pi eta)) within 100 eps (absolute)."""
    M_ref, heights = _load_libmobility('pair_mobility_%s_w4' % tag)
    solver = _wall_solver(z_mode, shift)
    separations = [3.0, 4.0, 8.0] if (FULL_SWEEP or shift == 0) else [4.0]
    for d in separations:
        i = [3.0, 4.0, 8.0].index(d)
        for k in _indices('pair', heights.size, shift):
            x = 76.8 / 2
            solver.setPositions(np.array([[x + d / 2, x, heights[k] + shift], [x - d / 2, x, heights[k] + shift]]))
            M = _compute_M(solver, 2) / (1 / (6 * np.pi * WALL_ETA))
            difference = np.abs(M - M_ref[i, k][0:6, 0:6])
            assert np.all(difference < EPS_100), (d, k, heights[k], difference.max())


def test_libmobility_selection_check_values():
    """The numbers of libMobility's selection for a = 1 (interface note, section 4)."""
    from mobility.spectral.libmobility_parameters import libmobility_parameters
    p, _ = libmobility_parameters(1.0, 'single_wall', 16.0, 16.0, -6.0, 6.0)
    assert (p.Nx, p.Ny) == (20, 20) and p.hx == pytest.approx(0.8, rel=1e-15)
    assert p.monopole.beta == pytest.approx((6.4875,) * 3, abs=1e-4)
    p, _ = libmobility_parameters(1.0, 'single_wall', 76.8, 76.8, 0.0, 19.2)
    assert (p.Nx, p.Ny) == (92, 92) and p.hx == pytest.approx(0.834783, abs=1e-6)
    assert p.monopole.beta[0] == pytest.approx(7.2377, abs=1e-4)
    p, _ = libmobility_parameters(1.0, 'single_wall', 76.8, 76.8, 0.0, 19.2, include_angular=True)
    assert (p.Nx, p.Ny) == (132, 132) and p.hx == pytest.approx(0.581818, abs=1e-6)
    assert p.monopole.beta[0] == pytest.approx(8.0822, abs=1e-4)
    assert p.dipole.beta[0] == pytest.approx(13.5060, abs=1e-4)
    assert p.monopole.width[0] == 6 and p.dipole.width[0] == 6
    # the z extents and Nz of the 16 x 16, z in [-6, 6] example (force only)
    for z_mode, extent, nz in (('open', (-8.4, 8.4), 33), ('single_wall', (-6.0, 8.4), 29),
                               ('two_walls', (-6.0, 6.0), None)):
        p, stored = libmobility_parameters(1.0, z_mode, 16.0, 16.0, -6.0, 6.0)
        assert (p.z0, p.z0 + p.Lz) == pytest.approx(extent, abs=1e-12)
        assert (stored['zmin'], stored['zmax']) == pytest.approx(extent, abs=1e-12)
        if nz is not None:
            assert p.Nz == nz
        assert p.Nz % 2 == 1
    # allowChangingBoxSize: the box becomes whole nominal cells and the nominal beta stays
    p, stored = libmobility_parameters(1.0, 'single_wall', 16.0, 15.0, 0.0, 6.0, allow_changing_box_size=True)
    h = 1.0 / 1.205
    assert (p.Nx, p.Ny) == (20, 18) and (stored['Lx'], stored['Ly']) == pytest.approx((20 * h, 18 * h), rel=1e-15)
    assert p.monopole.beta == pytest.approx((1.785 * 4,) * 3, rel=1e-15)
    # the grid is centred on x = y = 0
    assert (p.x0, p.y0) == pytest.approx((-10 * h, -9 * h), rel=1e-15)


def test_libmobility_selection_non_square_refits_per_direction():
    from mobility.spectral.libmobility_parameters import libmobility_parameters
    p, _ = libmobility_parameters(1.0, 'two_walls', 16.0, 19.0, 0.0, 8.0)
    assert p.hx != p.hy
    assert p.monopole.beta[0] != p.monopole.beta[1]
    assert p.monopole.beta[2] == min(p.monopole.beta[:2])
    assert p.monopole.alpha[2] == pytest.approx(2.0 * min(p.hx, p.hy), rel=1e-15)
    with pytest.raises(RuntimeError, match='Could not find'):
        solver = DPStokes('periodic', 'periodic', 'single_wall')
        solver.setParameters(Lx=16.0, Ly=2.68, zmin=0.0, zmax=8.0)      # Ny = 4: hy = 0.67, beta(a/(4 hy)) < 4
        solver.initialize(viscosity=1.0, hydrodynamicRadius=1.0)
    with pytest.raises(RuntimeError, match='DPStokes.*too small'):
        solver = DPStokes('periodic', 'periodic', 'two_walls')
        solver.setParameters(Lx=16.0, Ly=16.0, zmin=0.0, zmax=1.5)
        solver.initialize(viscosity=1.0, hydrodynamicRadius=1.0)


def test_libmobility_initialize_keeps_the_widened_extent():
    """libMobility stores the widened z extent: a second initialize without setParameters widens it again."""
    solver = DPStokes('periodic', 'periodic', 'single_wall')
    solver.setParameters(Lx=16.0, Ly=16.0, zmin=-6.0, zmax=6.0)
    solver.initialize(viscosity=1.0, hydrodynamicRadius=1.0)
    first = solver.parameters.z0 + solver.parameters.Lz
    solver.initialize(viscosity=1.0, hydrodynamicRadius=1.0)
    assert first == pytest.approx(8.4, abs=1e-12)
    assert solver.parameters.z0 + solver.parameters.Lz == pytest.approx(8.4 + 2.4, abs=1e-12)
    solver.setParameters(Lx=16.0, Ly=16.0, zmin=-6.0, zmax=6.0)
    solver.initialize(viscosity=1.0, hydrodynamicRadius=1.0)
    assert solver.parameters.z0 + solver.parameters.Lz == pytest.approx(8.4, abs=1e-12)


def test_libmobility_single_wall_accepts_blobs_above_zmax():
    """libMobility's DPStokes with one wall refuses only z < zmin (its test passes z = 5.5 with zmax = 5)."""
    solver = DPStokes('periodic', 'periodic', 'single_wall')
    solver.setParameters(Lx=16.0, Ly=16.0, zmin=0.0, zmax=5.0)
    solver.initialize(viscosity=1.0, hydrodynamicRadius=1.0)
    solver.setPositions([[0.0, 0.0, 5.5]])
    assert np.all(np.isfinite(solver.Mdot([[1.0, 0.0, 0.0]])[0]))
    with pytest.raises(RuntimeError, match='passed through a wall'):
        solver.setPositions([[0.0, 0.0, -0.01]])


def _grand_M(solver, n):
    size = 6 * n
    M = np.zeros((size, size))
    for c in range(size):
        unit = np.zeros(size)
        unit[c] = 1.0
        U, W = solver.Mdot(unit[:3 * n].reshape(n, 3), unit[3 * n:].reshape(n, 3))
        M[:, c] = np.concatenate((U.ravel(), W.ravel()))
    return M


def test_libmobility_angular_path_by_laws():
    """With torques (w = 6 kernels, spectral curl; libMobility's angular files are not shipped): the grand
    mobility is symmetric to the discretisation's level (measured 1e-7 to 5e-6 relative; the Chebyshev
    geometries' spreading and Clenshaw-Curtis-weighted interpolation are not exact adjoints) and positive
    definite, and the rotational self-mobility far from the box's periodic images agrees with the
    Rotne-Prager-Blake one (Swan and Brady 2007) to the kernel's accuracy (measured <= 0.32% in a 16 box at
    heights 1.5 to 5; periodic images of a torque enter at O((a/L)^3)).  A wrong factor 2 in the curl, a
    lost image or a transposed coupling fails one of these."""
    solver = DPStokes('periodic', 'periodic', 'single_wall')
    solver.setParameters(Lx=16.0, Ly=16.0, zmin=0.0, zmax=10.0)
    solver.initialize(viscosity=ETA, hydrodynamicRadius=RADIUS, includeAngular=True)
    for h in (1.5, 3.0, 5.0):
        solver.setPositions([[0.3, -0.2, h]])
        M = _grand_M(solver, 1)
        scale = np.abs(M).max()
        assert np.abs(M - M.T).max() < 2e-5 * scale
        assert np.linalg.eigvalsh(0.5 * (M + M.T)).min() > 0
        np.testing.assert_allclose(np.diag(M)[3:], _wall_self_mobility(h)[3:], rtol=1e-2)
        assert np.abs(np.diag(M)[3:] / _wall_self_mobility(h)[3:] - 1).max() > 1e-5   # not the wall product itself
    solver.setPositions([[0.3, -0.2, 2.0], [2.9, 1.1, 3.1]])
    M = _grand_M(solver, 2)
    assert np.abs(M - M.T).max() < 2e-5 * np.abs(M).max()
    assert np.linalg.eigvalsh(0.5 * (M + M.T)).min() > 0
    # forces and torques superpose, and W has the shape of the torques
    F = np.array([[0.2, -1.0, 0.5], [0.1, 0.3, -0.2]])
    T = np.array([[1.0, 0.4, -0.3], [-0.5, 0.2, 0.7]])
    U, W = solver.Mdot(F, T)
    U_F, W_F = solver.Mdot(F)
    U_T, W_T = solver.Mdot(torques=T.reshape(-1))
    assert W_T.shape == (6,)
    np.testing.assert_allclose(U, U_F + U_T.reshape(2, 3), rtol=1e-12, atol=1e-15 * np.abs(U).max())
    np.testing.assert_allclose(W, W_F + W_T.reshape(2, 3), rtol=1e-12, atol=1e-15 * np.abs(W).max())


# ------------------------------------------------------------------ the manual's script
def test_the_libmobility_script_of_the_manual_runs(tmp_path, monkeypatch, capsys):
    """doc/libmobility.md's libMobility-style script (setParameters, initialize, setPositions, Mdot, sqrtMdotW,
    divM, LangevinVelocities) runs as written; its only line naming this package is the import, which is
    libMobility's import with the module changed."""
    text = (Path(__file__).resolve().parents[1] / 'doc' / 'libmobility.md').read_text()
    script = text.split('<!-- libmobility-script -->', 1)[1].split('```python', 1)[1].split('```', 1)[0]
    lines = script.splitlines()
    assert [line for line in lines if line.startswith(('import ', 'from '))] == [
        'import numpy as np', 'from mobility.libmobility import DPStokes']
    assert sum('mobility.' in line for line in lines) == 1
    for call in ('setParameters', 'initialize', 'setPositions', 'Mdot', 'sqrtMdotW', 'LangevinVelocities'):
        assert '.%s(' % call in script
    monkeypatch.chdir(tmp_path)
    exec(compile(script, 'doc/libmobility.md', 'exec'), {'__name__': '__main__'})
    out = capsys.readouterr().out
    assert 'sedimentation speed of blob 0' in out and 'heights after 3 steps' in out


def test_dpstokes_selection_whole_cells_up_to_round_off():
    """DoublyPeriodicStokes' selection with a box of whole cells up to round-off (radius 0.9, L = 26: h = 26/45
    and 26 / h = 45.00000000000001, where the library adds a cell): no extra cell, even with
    allowChangingBoxSize=False; a genuine fraction is enlarged with allowChangingBoxSize=True only."""
    from mobility.spectral import dpstokes_parameters
    exact = dpstokes_parameters(RADIUS, 'DPBW', 26.0, 26.0, 0.0, 6.0, whole_cells_tolerance=0.0, warn=False)
    assert (exact.Nx, exact.Ny) == (45, 46)                      # the library's own rule adds a cell here
    solver = _small_dpstokes(Lx=26.0, Ly=26.0)
    assert (solver.parameters.Nx, solver.parameters.Ny) == (45, 45)
    assert solver.parameters.Ly == pytest.approx(26.0, rel=1e-15)
    enlarged = _small_dpstokes(Lx=32.0, Ly=31.5, allowChangingBoxSize=True)
    h = enlarged.parameters.hx
    assert enlarged.parameters.Ny == int(np.ceil(31.5 / h)) and enlarged.parameters.Ly == pytest.approx(
        enlarged.parameters.Ny * h, rel=1e-15)
    with pytest.raises(RuntimeError, match='allowChangingBoxSize'):
        _small_dpstokes(Lx=32.0, Ly=31.5)
    with pytest.raises(RuntimeError, match='kernel'):
        _small_dpstokes(kernel='w3')


@pytest.mark.parametrize('z_mode', ['open', 'single_wall', 'two_walls'])
def test_libmobility_selection_compiled_path_equals_numpy_path(z_mode):
    """Force-only products of libMobility's selection run on the core's compiled engine with this package's
    UAMMD stencils; the NumPy path (mobility.spectral.uammd) gives the same numbers to round-off."""
    from mobility.spectral import SpectralStokes, compiled_available
    from mobility.spectral.libmobility_parameters import libmobility_parameters
    if not compiled_available():
        pytest.skip('the compiled spectral extension is not built')
    p, _ = libmobility_parameters(RADIUS, z_mode, 16.0, 19.0, 0.0, 7.0)
    rng = np.random.default_rng(5)
    r = np.column_stack((rng.uniform(-20, 20, 12), rng.uniform(-20, 20, 12), rng.uniform(0.0, 7.0, 12)))
    F = rng.standard_normal((12, 3))
    F -= F.mean(axis=0)
    results = []
    for path in ('compiled', 'numpy'):
        stokes = SpectralStokes(p, ETA, path=path)
        assert stokes.path == path
        stokes.set_positions(r)
        results.append(stokes.product(F)[0])
    np.testing.assert_allclose(results[0], results[1], rtol=0, atol=1e-13 * np.abs(results[1]).max())
