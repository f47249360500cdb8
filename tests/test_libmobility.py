"""libMobility's Python interface on the CPU (``mobility.libmobility``): SelfMobility, NBody, and the
calls every solver shares.

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

DPStokes, under both parameter selections, is tested in ``test_libmobility_dpstokes.py``.
"""
from pathlib import Path

import numpy as np
import pytest

from libmobility_helpers import ETA, RADIUS, _wall_self_mobility
from mobility import interface
from mobility.libmobility import LibMobilityError, NBody, SelfMobility


def _python_mobility(kind):
    """The package's NumPy backend (the readable reference; NBody runs the compiled one where built)."""
    return interface.make_mobility('python', interface.Geometry(kind), ETA, RADIUS)


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
