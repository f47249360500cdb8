"""Speed options of the stochastic schemes (doc/dynamics.md, speed options)."""
import os
import sys

import numpy as np
import pytest

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), 'benchmarks'))

from multi_bodies.files.input_options import options_with  # noqa: E402
from quaternion_integrator.schemes import make_scheme  # noqa: E402
from utils import UserInputError  # noqa: E402


def options(tolerance):
    return options_with(kT=1.0, rf_delta=1e-3, update_PC=1, noise_solver_tolerance=tolerance)


@pytest.mark.parametrize('tolerance', [0.0, 1.0, -1e-3])
def test_noise_tolerance_out_of_range_is_refused(tolerance):
    with pytest.raises(UserInputError, match='noise_solver_tolerance'):
        make_scheme('stochastic_Slip_Trapz', 0.01, options(tolerance))


def test_noise_tolerance_changes_the_step_by_its_size_and_costs_fewer_products():
    """One Slip_Trapz step of 4 boomerangs with the same random numbers: a looser noise tolerance costs fewer
    Lanczos iterations, and the velocities differ from the default's by about the tolerance times their
    size (the sub-solves and the noise are accurate to it), not more."""
    import bench_dynamics
    results = {}
    for tolerance in (None, 1e-4):
        system = bench_dynamics.boomerang_system(4, 'python')
        scheme = make_scheme('stochastic_Slip_Trapz', 0.01, options(tolerance))
        state = scheme.step(system, scheme.init(system, system.start_configuration), np.random.default_rng(5))
        results[tolerance] = (state.velocities, state.counters.info()['stochastic_iterations_count'])
    (exact, lanczos_exact), (loose, lanczos_loose) = results[None], results[1e-4]
    assert lanczos_loose < lanczos_exact
    difference = np.linalg.norm(loose - exact) / np.linalg.norm(exact)
    assert 1e-9 < difference < 1e-2, difference


def test_paired_products_give_the_products_of_the_single_kernel():
    """One pass over the pairs for two vectors (C++) equals the established one-vector product, wall and no wall."""
    cpp = pytest.importorskip('mobility.cpp_backend')
    if not cpp.has_product_two():
        pytest.skip('the C++ extension was built before product_two (python3 setup.py build_ext --inplace)')
    import mobility
    rng = np.random.default_rng(11)
    r = rng.random((300, 3)) * [20.0, 20.0, 3.0] + [0.0, 0.0, 0.3]  # some blobs closer than a to the wall
    v1, v2 = rng.normal(size=900), rng.normal(size=900)
    for name, wall in (('C++', True), ('C++_no_wall', False)):
        single = mobility.mobility_vector_product(name)
        m1, m2 = cpp.trans_times_force_two(r, v1, v2, 1.3, 0.5, wall)
        for got, v in ((m1, v1), (m2, v2)):
            expected = single(r, v, 1.3, 0.5)
            np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12 * np.abs(expected).max())


@pytest.mark.parametrize('scheme_name', ['stochastic_Slip_Trapz', 'stochastic_adams_bashforth',
                                         'stochastic_traction_EM', 'stochastic_traction_AB', 'stochastic_Slip_Mid'])
def test_paired_step_equals_the_unpaired_step(scheme_name):
    """The Lanczos call and an independent solve at the same configuration sharing passes over the pairs
    (side by side in two threads) give the step of the same random numbers computed one after the other,
    to rounding."""
    cpp = pytest.importorskip('mobility.cpp_backend')
    if not cpp.has_product_two():
        pytest.skip('the C++ extension was built before product_two (python3 setup.py build_ext --inplace)')
    import bench_dynamics
    steps = {}
    for pair in (False, True):
        system = bench_dynamics.boomerang_system(9, 'C++')
        assert system.paired_mobility_product is not None
        scheme = make_scheme(scheme_name, 0.01, options(None))
        scheme.pair_products = pair
        steps[pair] = scheme.step(system, scheme.init(system, system.start_configuration),
                                  np.random.default_rng(5)).velocities
    np.testing.assert_allclose(steps[True], steps[False], rtol=1e-9, atol=1e-12)


def test_noise_tolerance_is_an_input_file_option():
    """The option reaches the scheme from the input file, and an out-of-range value names its line."""
    from multi_bodies.files.input_options import parse_input_text
    text = 'scheme stochastic_Slip_Trapz\ndt 0.01\nnoise_solver_tolerance 1e-4\n'
    parsed = parse_input_text(text, 'in.dat', program='dynamic')
    assert make_scheme(parsed.scheme, parsed.dt, parsed).noise_tolerance == 1e-4
    assert make_scheme(parsed.scheme, parsed.dt, parse_input_text('scheme stochastic_Slip_Trapz\ndt 0.01\n', 'in.dat',
                                                                  program='dynamic')).noise_tolerance is None
    with pytest.raises(UserInputError, match='in.dat, line 3: noise_solver_tolerance'):
        parse_input_text(text.replace('1e-4', '2'), 'in.dat', program='dynamic')


# ---------------------------------------------------------------------------------------------- GMRES, Lanczos
def saddle_like_system(n=240, seed=3):
    """A nonsymmetric, well-conditioned (n, n) matrix, a block-diagonal (Jacobi-like) preconditioner of it and a
    right-hand side."""
    rng = np.random.default_rng(seed)
    A = np.eye(n) * 3.0 + rng.normal(size=(n, n)) / np.sqrt(n)
    blocks = [np.linalg.inv(A[k:k + 8, k:k + 8]) for k in range(0, n, 8)]
    P = np.zeros((n, n))
    for k, block in zip(range(0, n, 8), blocks):
        P[k:k + 8, k:k + 8] = block
    return A, P, rng.normal(size=n)


@pytest.mark.parametrize('restart, warm, tolerance', [(60, False, 1e-8), (60, True, 1e-12), (4, False, 1e-10),
                                                      (60, False, 1e-14)])
def test_gmres_meets_scipys_rule_with_fewer_products(restart, warm, tolerance):
    """krylov.gmres keeps SciPy's rules (left preconditioning, converged when the true residual is at most
    rtol |b|, SciPy's inner tolerance control) and SciPy's answer to within the tolerance, in no more
    iterations.  Above the rounding guard a solve makes no product beyond its Krylov ones and a warm start's
    residual (SciPy makes one per cycle, and restarts when its inner estimate passes before the true
    residual does); below it, SciPy's products exactly."""
    import scipy.sparse.linalg as spla
    from multi_bodies.solver import krylov
    from stochastic_forcing import compat
    A, P, b = saddle_like_system()
    x0 = np.linalg.solve(A, b) + 1e-3 * np.random.default_rng(1).normal(size=b.size) if warm else None
    counts = {'scipy': 0, 'ours': 0}

    def counted(key):
        def matvec(v):
            counts[key] += 1
            return A @ v
        return matvec
    iterations = [0]
    expected, info = compat.gmres(spla.LinearOperator(A.shape, matvec=counted('scipy'), dtype=float), b,
                                  tolerance, x0=x0, atol=0.0, restart=restart, maxiter=1000,
                                  M=spla.aslinearoperator(P),
                                  callback=lambda _: iterations.__setitem__(0, iterations[0] + 1),
                                  callback_type='legacy')
    x, our_info, our_iterations, residual = krylov.gmres(counted('ours'), b, tolerance, psolve=lambda v: P @ v,
                                                         x0=x0, restart=restart)
    assert info == our_info == 0
    assert our_iterations <= iterations[0]
    true = b - A @ x
    assert np.linalg.norm(true) <= tolerance * np.linalg.norm(b)
    np.testing.assert_allclose(residual, true, rtol=0, atol=1e-13 * np.linalg.norm(b))
    # both answers are as close to the exact one as their residuals allow: |x - x*| <= |A^-1| |b - A x|
    exact = np.linalg.solve(A, b)
    bound = np.linalg.norm(np.linalg.inv(A), 2) * tolerance * np.linalg.norm(b)
    for answer in (x, expected):
        assert np.linalg.norm(answer - exact) <= bound + 1e-14 * np.linalg.norm(exact)
    above_rounding = tolerance >= krylov.ROUNDING_GUARD * np.finfo(float).eps
    if above_rounding and our_iterations <= restart:
        assert counts['ours'] == our_iterations + (1 if warm else 0), counts
    if above_rounding:
        assert counts['ours'] < counts['scipy'], counts
    else:
        assert (counts['ours'], our_iterations) == (counts['scipy'], iterations[0]), counts


def first_iteration_of_least_residual(A, P, b, x0, tolerance, most=80):
    """The first j at which some x in x0 + span{P r0, (P A) P r0, ..., (P A)^(j-1) P r0} has
    |b - A x| <= tolerance |b|, from the Krylov basis built and orthonormalised by numpy's QR and a dense least
    squares (the definition, independent of krylov.gmres)."""
    r0 = b - A @ x0
    vectors = [P @ r0]
    for j in range(1, most + 1):
        Q, _ = np.linalg.qr(np.array(vectors).T)
        y = np.linalg.lstsq(A @ Q, r0, rcond=None)[0]
        if np.linalg.norm(r0 - A @ Q @ y) <= tolerance * np.linalg.norm(b):
            return j
        vectors.append(P @ (A @ Q[:, -1]))
    raise AssertionError('no convergence in %d iterations' % most)


@pytest.mark.parametrize('scale, warm', [(1.0, False), (30.0, False), (30.0, True), (0.02, False)])
def test_least_true_residual_gmres_stops_where_its_krylov_space_first_holds_the_tolerance(scale, warm):
    """krylov.gmres(minimal_residual=True) stops at the first iteration whose Krylov space (the
    left-preconditioned one) holds a point within the tolerance, and returns that point and its true residual:
    the count equals the one found by a dense least squares over the same space and is never more than the
    left-preconditioned rule's; rows scaled as the velocity and force rows of a mobility problem may be."""
    from multi_bodies.solver import krylov
    A, P, b = saddle_like_system()
    rows = np.ones(b.size)
    rows[-60:] = scale  # the "constraint" rows in other units; P is their inverse blocks, so P A is unchanged
    A, b, P = rows[:, None] * A, rows * b, P / rows[None, :]
    x0 = (np.linalg.solve(A, b) + 1e-3 * np.random.default_rng(1).normal(size=b.size)) if warm else np.zeros(b.size)
    tolerance = 1e-8
    counts = []

    def matvec(v):
        counts.append(1)
        return A @ v
    x, info, least_iterations, residual = krylov.gmres(matvec, b, tolerance, psolve=lambda v: P @ v,
                                                       x0=x0 if warm else None, minimal_residual=True)
    assert info == 0
    assert least_iterations == first_iteration_of_least_residual(A, P, b, x0, tolerance)
    assert len(counts) == least_iterations + (1 if warm else 0)  # no product beyond the Krylov ones
    true = b - A @ x
    assert np.linalg.norm(true) <= tolerance * np.linalg.norm(b)
    np.testing.assert_allclose(residual, true, rtol=0, atol=1e-13 * np.linalg.norm(b))
    _, _, left_iterations, _ = krylov.gmres(lambda v: A @ v, b, tolerance, psolve=lambda v: P @ v,
                                            x0=x0 if warm else None)
    assert least_iterations <= left_iterations


def test_least_true_residual_gmres_saves_iterations_on_a_mobility_problem():
    """On the mobility problem of 16 boomerangs packed at spacing 2 (gravity, block-diagonal preconditioner)
    the left-preconditioned rule passes the true tolerance an iteration after the space first holds it
    (measured: 11 against 10); the least-residual solve stops there, with the same velocities within the
    tolerance, and its count is the dense least squares' over the same Krylov space."""
    import bench_preconditioner
    from multi_bodies.solver import body_solver
    model = bench_preconditioner.packed_boomerangs(num=16).replace(preconditioner='block_diagonal')
    q = model.start_configuration
    problem, preconditioner = model.mobility_problem(q), model.build_preconditioner(q)
    _, force_torque, slip = model.forces_and_slip(q)
    rhs = problem.rhs(slip=slip, force_torque=force_torque)
    least, left = (body_solver.solve(problem, rhs, preconditioner, minimal_residual=m) for m in (True, False))
    assert least.converged and left.converged and least.iterations < left.iterations
    A = np.column_stack([problem.operator.matvec(e) for e in np.eye(problem.size)])
    P = np.column_stack([preconditioner.operator.matvec(e) for e in np.eye(problem.size)])
    b = problem.prepare_rhs(rhs) / np.linalg.norm(problem.prepare_rhs(rhs))
    assert least.iterations == first_iteration_of_least_residual(A, P, b, np.zeros(b.size), 1e-8)
    scale = np.abs(left.velocities).max()
    assert np.abs(least.velocities - left.velocities).max() <= 1e-6 * scale


def test_least_true_residual_gmres_restarts_and_stays_exact_below_the_rounding_guard():
    """With restarts every 4 vectors and at a tolerance below the rounding guard (2.2e-13), the least-residual
    GMRES still converges and its returned residual is the true one (checked by a product there)."""
    from multi_bodies.solver import krylov
    A, P, b = saddle_like_system()
    for restart, tolerance in ((4, 1e-10), (60, 1e-14)):
        x, info, iterations, residual = krylov.gmres(lambda v: A @ v, b, tolerance, psolve=lambda v: P @ v,
                                                     restart=restart, minimal_residual=True)
        assert info == 0
        assert np.linalg.norm(b - A @ x) <= tolerance * np.linalg.norm(b)
        np.testing.assert_allclose(residual, b - A @ x, rtol=0, atol=1e-14 * np.linalg.norm(b))


def test_gmres_below_rounding_reports_failure_not_a_false_convergence():
    """Asked for a relative residual of 1e-300 the true residual stagnates near rounding: GMRES must say it did
    not converge (the updated residual alone would shrink to zero and claim convergence)."""
    from multi_bodies.solver import krylov
    A, P, b = saddle_like_system()
    x, info, iterations, residual = krylov.gmres(lambda v: A @ v, b, 1e-300, psolve=lambda v: P @ v, maxiter=200)
    assert info != 0 and iterations == 200
    assert np.linalg.norm(residual) > 0.0
    np.testing.assert_allclose(residual, b - A @ x, rtol=0, atol=1e-14 * np.linalg.norm(b))


def published_lanczos_iterations(M, z, tolerance):
    """Iterations of the Lanczos square root when the change |y_i - y_(i-1)| / |y_(i-1)| is taken from the
    vectors y_i themselves (the form of the published code)."""
    from scipy.linalg import eigh_tridiagonal
    n = z.size
    V = [z / np.linalg.norm(z)]
    alphas, betas, previous = [], [], None
    for i in range(n):
        w = M @ V[i] - (betas[-1] * V[i - 1] if i else 0.0)
        alphas.append(w @ V[i])
        w = w - alphas[-1] * V[i]
        B = np.array(V)
        w = w - B.T @ (B @ w)
        w = w - B.T @ (B @ w)
        values, Q = (np.array(alphas), np.ones((1, 1))) if i == 0 else eigh_tridiagonal(np.array(alphas),
                                                                                      np.array(betas))
        y = np.linalg.norm(z) * (B.T @ (Q @ (np.sqrt(np.maximum(values, 0)) * Q[0])))
        if previous is not None and np.linalg.norm(y - previous) / np.linalg.norm(previous) < tolerance:
            return i + 1, y
        previous = y
        betas.append(np.linalg.norm(w))
        V.append(w / betas[-1])
    return n, y


@pytest.mark.parametrize('tolerance', [1e-4, 1e-8, 1e-12])
def test_lanczos_stops_where_the_published_form_stops(tolerance):
    """The relative change of the Lanczos approximation is taken from its coefficients in the orthonormal Krylov
    basis (no 3N-vector per iteration): the same stopping iteration and the same noise as when it is taken from
    the vectors, on a blob mobility of 60 blobs above a wall."""
    import mobility
    from stochastic_forcing import lanczos_square_root
    rng = np.random.default_rng(8)
    r = rng.random((60, 3)) * [6.0, 6.0, 2.0] + [0.0, 0.0, 1.0]
    M = mobility.blob_mobility_matrix('python')(r, 1.0, 0.5)
    z = rng.standard_normal(180)
    result = lanczos_square_root(lambda v: M @ v, z, tolerance)
    iterations, expected = published_lanczos_iterations(M, z, tolerance)
    assert result.iterations == iterations
    np.testing.assert_allclose(result.noise, expected, rtol=0, atol=1e-12 * np.abs(expected).max())


def test_compiled_preconditioner_blocks_equal_numpy():
    """The compiled block products of the preconditioner (its application, L, L^-1, L^-T) equal the NumPy
    versions on boomerangs and single blobs together, and L^-1 undoes L."""
    from multi_bodies.solver import body_solver
    if body_solver._preconditioner_cpp is None:
        pytest.skip('multi_bodies.solver._preconditioner_cpp is not built (python3 setup.py build_ext --inplace)')
    import bench_dynamics
    from body.body import Body, bodies_to_arrays
    system = bench_dynamics.boomerang_system(6, 'python')
    bodies = list(system.bodies) + [Body([20.0 + 3 * k, 0.0, 2.0], [1, 0, 0, 0], np.zeros((1, 3)), 0.25)
                                    for k in range(3)]
    arrays = bodies_to_arrays(bodies)
    import mobility
    pc = body_solver.BlockDiagonalPreconditioner(arrays, arrays.configuration,
                                                 mobility.blob_mobility_matrix('python'), 1.0, 0.25)
    rng = np.random.default_rng(2)
    x = rng.normal(size=3 * arrays.num_blobs + 6 * arrays.num_bodies)
    v = rng.normal(size=3 * arrays.num_blobs)
    compiled = [pc.apply(x), pc.L_dot(v), pc.L_inv_dot(v), pc.L_inv_T_dot(v)]
    saved, body_solver._preconditioner_cpp = body_solver._preconditioner_cpp, None
    try:
        plain = [pc.apply(x), pc.L_dot(v), pc.L_inv_dot(v), pc.L_inv_T_dot(v)]
    finally:
        body_solver._preconditioner_cpp = saved
    for got, expected in zip(compiled, plain):
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12 * np.abs(expected).max())
    np.testing.assert_allclose(pc.L_inv_dot(pc.L_dot(v)), v, rtol=0, atol=1e-10)


def test_fresh_noise_solve_from_zero_gives_the_warm_started_step_with_fewer_products():
    """The Slip_Trapz predictor, whose right-hand side holds this step's noise, starts from zero instead of the
    last solution: the same step to the solver tolerance, and one residual product fewer per step."""
    import bench_dynamics
    from quaternion_integrator import stochastic_schemes
    results = {}
    for cold in (False, True):
        system, counter = bench_dynamics.count_products(bench_dynamics.boomerang_system(9, 'C++'))
        scheme = make_scheme('stochastic_Slip_Trapz', 0.01, options(None))
        scheme.cold_start_fresh_noise = cold
        rng = np.random.default_rng(5)
        state = scheme.init(system, system.start_configuration)
        for _ in range(3):
            state = scheme.step(system, state, rng)
        results[cold] = (state.velocities, counter.counts['residual'])
    assert stochastic_schemes.StochasticScheme.cold_start_fresh_noise
    (warm, warm_residuals), (cold, cold_residuals) = results[False], results[True]
    np.testing.assert_allclose(cold, warm, rtol=0, atol=1e-6 * np.abs(warm).max())
    assert cold_residuals <= warm_residuals - 2  # at least one each in steps 1 and 2 (step 0 has no earlier solution)


def test_compiled_triangular_inverse_and_stacked_blocks():
    """The compiled L^-1 of Cholesky factors equals the general solve against the identity, and the stacked dense
    blocks of many bodies equal the blocks of each body alone (wall, blobs below a, and free space)."""
    from multi_bodies.solver import body_solver
    cpp = pytest.importorskip('mobility.cpp_backend')
    if body_solver._preconditioner_cpp is None or not hasattr(cpp._ext, 'dense_trans_trans_stack'):
        pytest.skip('the extensions were built before these functions (python3 setup.py build_ext --inplace)')
    rng = np.random.default_rng(6)
    r = rng.random((7, 12, 3)) * [4.0, 4.0, 2.0]  # some blobs below the radius 0.5 (the wall regularisation)
    for wall in (True, False):
        stack = cpp._ext.dense_trans_trans_stack(r.reshape(-1, 3), 7, 1.1, 0.5, np.zeros(3), wall)
        each = np.stack([cpp._ext.dense_trans_trans(body, 1.1, 0.5, np.zeros(3), wall) for body in r])
        np.testing.assert_array_equal(stack, each)
    L = np.linalg.cholesky(stack)
    L_inv = body_solver._preconditioner_cpp.lower_triangular_inverse(L)
    expected = np.linalg.solve(L, np.broadcast_to(np.eye(36), L.shape))
    np.testing.assert_allclose(L_inv, expected, rtol=0, atol=1e-12 * np.abs(expected).max())
    assert np.all(np.triu(L_inv, 1) == 0.0)
    with pytest.raises(ValueError, match='not positive'):
        body_solver._preconditioner_cpp.lower_triangular_inverse(-L)
