"""The incomplete Cholesky factor of the Lanczos noise (``lanczos_preconditioner incomplete_cholesky``).

The noise ``L (L^{-1} M L^{-T})^{1/2} z`` has covariance ``M`` for any invertible ``L`` (linear algebra); the
tests check that law on the production path (``Model.lanczos_noise`` with the preconditioner the model builds),
the defining property of the factor (``L L^T = M`` on the diagonal and the neighbour blocks, zero elsewhere),
the three products against dense algebra, the fall-back where the factorisation breaks down, and the option.
Every covariance test has a control that must fail it (the factor left out, or transposed).
"""
import numpy as np
import pytest
import scipy.linalg as sla

from multi_bodies.files.input_options import options_with
from multi_bodies.solver import noise_factor
from quaternion_integrator.scheme_state import StepContext
from quaternion_integrator.schemes import make_scheme
from multi_bodies.solver.neighbour_preconditioner import neighbour_pairs
from test_neighbour_preconditioner import boomerang_model
from test_stochastic import covariance_z_scores, frobenius_statistic, probe_directions
from utils import UserInputError


def close_cluster(lanczos_preconditioner='incomplete_cholesky', preconditioner='block_diagonal'):
    """Six boomerangs 1.6 apart above the wall: several pairs whose blobs come within 2 blob radii."""
    centres = [[1.6 * (k % 3), 1.6 * (k // 3), 2.0 + 0.3 * k] for k in range(6)]
    return boomerang_model(centres, seed=4, preconditioner=preconditioner).replace(
        lanczos_preconditioner=lanczos_preconditioner)


def dense_blocks(factor):
    """The dense ``L`` of a BlockLowerFactor."""
    s = factor.starts
    L = np.zeros((s[-1], s[-1]))
    for i in range(s.size - 1):
        L[s[i]:s[i + 1], s[i]:s[i + 1]] = factor._diagonal(i, False)
        for p in range(factor.row_ptr[i], factor.row_ptr[i + 1]):
            k, block = factor._lower(p, i)
            L[s[i]:s[i + 1], s[k]:s[k + 1]] = block
    return L


def random_block_factor(rng):
    """A BlockLowerFactor of bodies of 2, 5 and 3 unknowns and random lower blocks (some absent)."""
    sizes = [6, 15, 9, 6, 15]
    starts = np.concatenate(([0], np.cumsum(sizes)))
    factors = [np.tril(rng.normal(size=(m, m))) + 4.0 * np.eye(m) for m in sizes]
    for f in factors:
        np.fill_diagonal(f, np.abs(np.diag(f)) + 1.0)
    rows = [dict() for _ in sizes]
    for i, k in ((1, 0), (2, 1), (3, 0), (3, 2), (4, 1), (4, 3)):
        rows[i][k] = rng.normal(size=(sizes[i], sizes[k]))
    return noise_factor.BlockLowerFactor.from_blocks(starts, factors, rows)


def test_block_products_equal_dense_algebra_compiled_and_numpy():
    """L x, L^{-1} x and L^{-T} x of the compiled loop and of the NumPy loop equal dense triangular algebra."""
    rng = np.random.default_rng(0)
    factor = random_block_factor(rng)
    L = dense_blocks(factor)
    x = rng.normal(size=L.shape[0])
    expected = (L @ x, sla.solve_triangular(L, x, lower=True), sla.solve_triangular(L, x, lower=True, trans='T'))
    for mode, want in enumerate(expected):
        numpy_loop = factor._apply_numpy(mode, x, np.zeros_like(x))
        assert np.allclose(numpy_loop, want, rtol=1e-12, atol=1e-12)
        assert np.allclose(factor._apply(mode, x), want, rtol=1e-12, atol=1e-12)
    assert np.allclose(factor.L_inv_dot(factor.L_dot(x)), x, atol=1e-12)
    with pytest.raises(ValueError, match='unknowns'):
        factor.L_dot(x[:-1])


@pytest.mark.parametrize('preconditioner', ['block_diagonal', 'neighbours'])
def test_factor_matches_the_mobility_on_the_diagonal_and_neighbour_blocks(preconditioner):
    """IC(0): ``L L^T = M`` on every diagonal block and every neighbour block; L is zero off the pattern.
    Under ``neighbours`` the factor takes its pairs and blocks from the GMRES preconditioner, which computes
    its near field from the positions and stores the blocks of its strongly coupled pairs only."""
    model = close_cluster(preconditioner=preconditioner)
    configuration = model.start_configuration
    built = model.build_preconditioner(configuration)
    if preconditioner == 'neighbours':
        assert built.on_the_fly and built.stored_gap >= 2.0 * model.blob_radius
    factor = built.noise_factor
    assert factor.pairs.shape[0] >= 3 and factor.breakdowns == 0
    # every pair of bodies whose blobs come within the noise gap, and no other
    r = model.arrays.blob_positions(configuration)
    expected = neighbour_pairs(r, model.arrays.blob_body_index, model.blob_radius, configuration.locations,
                               noise_factor.NOISE_GAP_IN_RADII * model.blob_radius)[0]
    assert [tuple(p) for p in factor.pairs] == [tuple(p) for p in expected]
    M = model.dense_matrices(configuration, inverse=False)[0]
    L = dense_blocks(factor)
    product = L @ L.T
    s = factor.starts
    pattern = np.eye(model.num_bodies, dtype=bool)
    pattern[factor.pairs[:, 0], factor.pairs[:, 1]] = pattern[factor.pairs[:, 1], factor.pairs[:, 0]] = True
    scale = np.abs(M).max()
    for i in range(model.num_bodies):
        for k in range(model.num_bodies):
            block = (slice(s[i], s[i + 1]), slice(s[k], s[k + 1]))
            if pattern[i, k]:
                assert np.abs(product[block] - M[block]).max() < 1e-12 * scale, (i, k)
            elif k < i:
                assert not np.any(L[block]), (i, k)
    # the block-diagonal factor does not see the neighbour blocks (a control of the check above)
    pair = factor.pairs[0]
    block = (slice(s[pair[1]], s[pair[1] + 1]), slice(s[pair[0]], s[pair[0] + 1]))
    own = np.zeros_like(L)
    for i in range(model.num_bodies):
        own[s[i]:s[i + 1], s[i]:s[i + 1]] = np.linalg.cholesky(M[s[i]:s[i + 1], s[i]:s[i + 1]])
    assert np.abs((own @ own.T)[block] - M[block]).max() > 1e-3 * scale


def dense_noise_map(model, built, problem, with_factor=True):
    """The noise of every unit vector z = e_j by ``Model.lanczos_noise`` (tolerance 1e-12): the matrix G of
    z -> noise, whose G G^T is the covariance of the noise of Gaussian z."""
    n = 3 * model.num_blobs
    if with_factor:
        columns = [model.lanczos_noise(problem, e, 1.0, built, tolerance=1e-12).noise for e in np.eye(n)]
    else:  # the control: the square root of L^{-1} M L^{-T} without the factor L
        class Unmultiplied:
            L_inv_dot = built.noise_factor.L_inv_dot
            L_inv_T_dot = built.noise_factor.L_inv_T_dot

            @staticmethod
            def L_dot(v):
                return v
        columns = [model.lanczos_noise(problem, e, 1.0, Unmultiplied, tolerance=1e-12).noise for e in np.eye(n)]
    return np.column_stack(columns)


def test_noise_covariance_is_the_mobility_and_lanczos_takes_fewer_iterations():
    """G G^T = M to 1e-8 (relative) with the incomplete Cholesky factor, through ``Model.lanczos_noise``;
    without the factor L the same iteration gives L^{-1} M L^{-T}, off by more than 1e-2 (control).  Lanczos
    needs fewer iterations than with the block-diagonal factor on the same z."""
    model = close_cluster()
    configuration = model.start_configuration
    problem = model.mobility_problem(configuration)
    built = model.build_preconditioner(configuration)
    M = model.dense_matrices(configuration, inverse=False)[0]
    G = dense_noise_map(model, built, problem)
    assert np.abs(G @ G.T - M).max() < 1e-8 * np.abs(M).max()
    wrong = dense_noise_map(model, built, problem, with_factor=False)
    assert np.abs(wrong @ wrong.T - M).max() > 1e-2 * np.abs(M).max()
    block = close_cluster('block_diagonal')
    block_built = block.build_preconditioner(configuration)
    assert getattr(block_built, 'noise_factor', None) is None
    z = np.random.default_rng(3).normal(size=3 * model.num_blobs)
    ours = model.lanczos_noise(problem, z, 1.0, built).iterations
    published = block.lanczos_noise(problem, z, 1.0, block_built).iterations
    assert ours < published, (ours, published)


def test_a_factor_built_elsewhere_still_gives_the_covariance():
    """Any invertible L gives covariance M: the factor of another configuration (as with update_PC > 1)."""
    model = close_cluster()
    configuration = model.start_configuration
    moved = type(configuration)(configuration.locations + np.array([0.0, 0.0, 0.4]) * np.arange(6)[:, None] / 6,
                                configuration.orientations)
    built = model.build_preconditioner(moved)
    problem = model.mobility_problem(configuration)
    M = model.dense_matrices(configuration, inverse=False)[0]
    G = dense_noise_map(model, built, problem)
    assert np.abs(G @ G.T - M).max() < 1e-8 * np.abs(M).max()


def test_breakdown_keeps_the_row_alone_and_the_covariance():
    """A positive definite matrix whose IC(0) breaks down (the classic 3 x 3 with the (0, 2) entry left out of
    the pattern): that row keeps its own block, L stays invertible, and L (L^-1 M L^-T)^1/2 still has
    covariance M."""
    M = np.array([[1.0, 0.8, 0.56], [0.8, 1.0, 0.7], [0.56, 0.7, 1.0]])
    assert np.all(np.linalg.eigvalsh(M) > 0)
    own = [np.sqrt(M[k:k + 1, k:k + 1]) for k in range(3)]
    factors, inverses, rows, breakdowns = noise_factor.incomplete_cholesky(
        own, [1.0 / f for f in own], {(0, 1): M[0:1, 1:2], (1, 2): M[1:2, 2:3]})
    assert breakdowns == 1 and rows[2] == {}
    factor = noise_factor.BlockLowerFactor.from_blocks(np.arange(4), factors, rows, inverses)
    L = dense_blocks(factor)
    assert np.all(np.diag(L) > 0)
    S = sla.solve_triangular(L, sla.solve_triangular(L, M, lower=True).T, lower=True)  # L^-1 M L^-T
    G = L @ np.real(sla.sqrtm(0.5 * (S + S.T)))
    assert np.allclose(G @ G.T, M, atol=1e-12)


def test_compiled_factorisation_equals_the_numpy_one_with_and_without_breakdown():
    """The compiled IC(0) (``_preconditioner_cpp.incomplete_cholesky_blocks``) gives the NumPy loop's factor to
    rounding: on the close cluster's blocks, and on the 3 x 3 matrix whose factorisation breaks down."""
    if not noise_factor._compiled():
        pytest.skip('the compiled preconditioner module is not built (a build without a C++ compiler)')
    model = close_cluster()
    base = model.replace(lanczos_preconditioner='block_diagonal').build_preconditioner(model.start_configuration)
    own = [L for stack in base.cholesky_factors for L in stack]
    inverses = [L for stack in base.inverse_cholesky_factors for L in stack]
    factor = model.build_preconditioner(model.start_configuration).noise_factor
    r = model.arrays.blob_positions(model.start_configuration)
    offsets = model.arrays.blob_offsets
    by_pair = {}
    for i, j in factor.pairs:
        both = np.concatenate((r[offsets[i]:offsets[i + 1]], r[offsets[j]:offsets[j + 1]]))
        n_i = offsets[i + 1] - offsets[i]
        by_pair[(int(i), int(j))] = model.stacked_mobility(both[None], model.eta, model.blob_radius)[0][
            :3 * n_i, 3 * n_i:]
    starts = 3 * np.asarray(offsets)
    compiled, _ = noise_factor.incomplete_cholesky_factor(starts, own, inverses, by_pair)
    numpy_loop, _ = noise_factor.incomplete_cholesky_factor(starts, own, inverses, by_pair, compiled=False)
    assert np.allclose(dense_blocks(compiled), dense_blocks(numpy_loop), rtol=1e-12, atol=1e-14)
    M = np.array([[1.0, 0.8, 0.56], [0.8, 1.0, 0.7], [0.56, 0.7, 1.0]])
    own = [np.sqrt(M[k:k + 1, k:k + 1]) for k in range(3)]
    pairs = {(0, 1): M[0:1, 1:2], (1, 2): M[1:2, 2:3]}
    compiled, broken = noise_factor.incomplete_cholesky_factor(np.arange(4), own, [1.0 / f for f in own], pairs)
    numpy_loop, broken_too = noise_factor.incomplete_cholesky_factor(np.arange(4), own, [1.0 / f for f in own], pairs,
                                                                     compiled=False)
    assert broken == broken_too == 1
    assert np.allclose(dense_blocks(compiled), dense_blocks(numpy_loop), atol=1e-15)


def roller_model(lanczos_preconditioner):
    """40 rollers (a = 0.5) on a jittered grid of spacing 1.3 at z ~ 0.75: most neighbours within 4 radii."""
    from body.body import Body, bodies_to_arrays
    from multi_bodies.solver import user_hooks
    from multi_bodies.solver.model import Model
    rng = np.random.default_rng(11)
    bodies = []
    for k in range(40):
        body = Body([1.3 * (k % 8) + 0.1 * rng.random(), 1.3 * (k // 8), 0.75 + 0.1 * rng.random()],
                    [1.0, 0.0, 0.0, 0.0], np.zeros((1, 3)), 0.5)
        body.ID = 'roller'
        body.body_length = 1.0
        bodies.append(body)
    physics = dict(g=1.0, repulsion_strength_wall=1.0, debye_length_wall=0.1, repulsion_strength=1.0,
                   debye_length=0.1, periodic_length=np.zeros(3), blob_radius=0.5, blob_mass=1.0)
    return Model(bodies, bodies_to_arrays(bodies), user_hooks.load_user_hooks('/nonexistent'), physics, 1.0, 0.5,
                 1e-8, vector_product_name='C++', blobs_name='C++', omega_one_roller=np.array([0.0, 1.0, 0.0]),
                 free_kinematics=False, lanczos_preconditioner=lanczos_preconditioner)


def test_roller_noise_with_the_factor_has_covariance_m_in_fewer_iterations():
    """Rollers: ``Model.roller_noise`` of every unit vector with the incomplete Cholesky factor gives G with
    G G^T = M_UF to 1e-8 (relative; M_UF from the rollers' own product); the published unpreconditioned Lanczos
    needs more iterations on the same z; without the factor's final multiplication the covariance is off by more
    than 1e-2 (the control)."""
    from multi_bodies.solver import noise_factor as nf
    model = roller_model('incomplete_cholesky')
    r = model.arrays.blob_positions(model.start_configuration)
    n = 3 * model.num_bodies
    product = model.roller_product('trans_times_force')
    M = np.column_stack([np.asarray(product(r, e, model.eta, 0.5, model.periodic_length)).reshape(-1)
                         for e in np.eye(n)])
    tight = model.replace(solver_tolerance=1e-12)
    G = np.column_stack([tight.roller_noise(r, e, 1.0).noise.reshape(-1) for e in np.eye(n)])
    assert np.abs(G @ G.T - M).max() < 1e-8 * np.abs(M).max()
    factor, pairs = nf.single_blob_factor(r, model.eta, 0.5, model.stacked_mobility)
    assert pairs.shape[0] >= 40
    L = dense_blocks(factor)
    S = sla.solve_triangular(L, sla.solve_triangular(L, M, lower=True).T, lower=True)
    root = np.real(sla.sqrtm(0.5 * (S + S.T)))
    assert np.abs(root @ root.T - M).max() > 1e-2 * np.abs(M).max()  # no L: the covariance of L^-1 M L^-T
    z = np.random.default_rng(2).normal(size=n)
    ours = model.roller_noise(r, z, 1.0).iterations
    published = roller_model('block_diagonal').roller_noise(r, z, 1.0).iterations
    assert ours < published, (ours, published)


def test_sampled_noise_of_a_step_has_covariance_m_and_the_transposed_factor_fails():
    """The noise a scheme draws (``scheme.lanczos_noise`` over a StepContext, the preconditioner the scheme builds):
    1000 samples on six close boomerangs (90 blobs) at ``noise_solver_tolerance`` 1e-4; probe z-scores below
    4.5 (relative SE sqrt(2/1000)) and the Frobenius statistic below 1.25 (1 for exact noise, see
    test_stochastic); the same Lanczos multiplied by ``L^T`` instead of ``L`` gives a statistic above 1.6."""
    model = close_cluster()
    scheme = make_scheme('stochastic_Slip_Trapz', 0.01,
                         options_with(noise_solver_tolerance=1e-4, lanczos_preconditioner='incomplete_cholesky'))
    state = scheme.init(model, model.start_configuration)
    context = StepContext(model, state.step)
    problem = model.mobility_problem(state.configuration)
    built, _ = scheme.preconditioner(context, state, problem)
    assert built.noise_factor.pairs.size
    M = model.dense_matrices(state.configuration, inverse=False)[0]
    probes = probe_directions(M, 7)
    rng = np.random.default_rng(8)
    n = 3 * model.num_blobs
    ours = np.array([scheme.lanczos_noise(context, problem, rng.standard_normal(n), 1.0, built)
                     for _ in range(1000)])
    assert np.max(np.abs(covariance_z_scores(ours, M, probes))) < 4.5
    assert frobenius_statistic(ours, M) < 1.25
    L = dense_blocks(built.noise_factor)

    class Transposed:  # L^T in place of L: covariance L^T S L, not M
        L_inv_dot = built.noise_factor.L_inv_dot
        L_inv_T_dot = built.noise_factor.L_inv_T_dot

        @staticmethod
        def L_dot(v):
            return L.T @ v
    rng = np.random.default_rng(8)
    wrong = np.array([model.lanczos_noise(problem, rng.standard_normal(n), 1.0, Transposed, tolerance=1e-4).noise
                      for _ in range(1000)])
    assert frobenius_statistic(wrong, M) > 1.6


def test_the_option_is_read_and_checked():
    """``lanczos_preconditioner`` takes block_diagonal (default) or incomplete_cholesky; anything else is a
    clear error naming the option."""
    assert options_with().lanczos_preconditioner == 'block_diagonal'
    assert options_with(lanczos_preconditioner='incomplete_cholesky').lanczos_preconditioner == 'incomplete_cholesky'
    with pytest.raises(UserInputError, match='lanczos_preconditioner'):
        options_with(lanczos_preconditioner='cholesky')
    with pytest.raises(ValueError, match='lanczos_preconditioner'):
        close_cluster('exact')


@pytest.fixture(scope='module')
def clustered_boomerangs():
    return clustered_run('incomplete_cholesky')


def clustered_run(lanczos_preconditioner, n_steps=250, seed=501):
    """10 clusters of 3 boomerangs (15 blobs, a = 0.15) whose blobs come within 2 radii of each other, under
    stochastic_Slip_Trapz with the given ``lanczos_preconditioner``: ``n_steps`` steps of dt 0.01 from an
    exact equilibrium sample (``seed``).  No body-body potential, so the stationary density is the product of every
    body's own Gibbs-Boltzmann density whatever the hydrodynamic coupling.  Returns the per-cluster time
    averages of (h, cos theta, cos^2 theta) (averaged over the cluster's bodies), their exact values, the
    per-cluster ratio of squared one-step displacements to 2 kT dt tr N_tt, and the neighbour pairs of the
    first factor."""
    from body.body import Body, bodies_to_arrays
    from multi_bodies import multi_bodies_functions as mbf
    from multi_bodies.files import structure_generators as gen
    from multi_bodies.solver.model import Model
    from brownian_scene import ETA, Opts
    from test_boomerang_equilibrium import BOOM_A, boomerang_keywords, boomerang_quadrature, brownian_averages
    clusters, per_cluster, every = 10, 3, 10
    reference = gen.boomerang(spacing=2 * BOOM_A)
    pool, weights, h_grid, cdf, exact = boomerang_quadrature(reference)
    rng = np.random.default_rng(seed)
    chosen = rng.choice(pool.shape[0], size=clusters * per_cluster, p=weights)
    offsets = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, 0.9]])
    bodies = []
    for k, index in enumerate(chosen):
        c, member = divmod(k, per_cluster)
        xy = 14.0 * np.array([c % 5, c // 5]) + offsets[member]
        body = Body(np.array([xy[0], xy[1], np.interp(rng.random(), cdf[index], h_grid)]), pool[index], reference,
                    BOOM_A)
        body.ID = 'boomerang'
        body.body_length = body.calc_body_length()
        bodies.append(body)
    n = len(bodies)
    system = Model(bodies, bodies_to_arrays(bodies, [n]), mbf.load_user_hooks('/nonexistent'), boomerang_keywords(),
                   ETA, BOOM_A, 1e-4, vector_product_name='C++', blobs_name='C++',
                   lanczos_preconditioner=lanczos_preconditioner)
    first_pairs = noise_factor.neighbour_noise_factor(
        system.build_preconditioner(system.start_configuration), system.stacked_mobility, ETA, BOOM_A).pairs
    scheme = make_scheme('stochastic_Slip_Trapz', 0.01, Opts())
    per_body, motion = brownian_averages(system, scheme, np.random.default_rng(seed + 1), n_steps, every)
    by_cluster = per_body.reshape(clusters, per_cluster, 3).mean(axis=1)
    motion = motion.reshape(clusters, per_cluster).mean(axis=1)
    return by_cluster, np.array(exact), motion, first_pairs


@pytest.mark.slow
def test_coupled_boomerangs_keep_gibbs_boltzmann_with_the_incomplete_cholesky_noise(clustered_boomerangs):
    """Per-cluster time averages of h, cos theta and cos^2 theta within 4 standard errors of the quadrature
    values (the clusters, 14 apart, are the independent samples: SE from the spread of their 10 averages), and
    the bodies move at the fluctuation-dissipation rate (ratio within 4 SE of 1), a rate that a 25 % wrong kT
    fails (the control: an integrator that never moves would keep the exact start)."""
    from brownian_scene import z_score
    by_cluster, exact, motion, first_pairs = clustered_boomerangs
    assert first_pairs.shape[0] >= 10  # the factor couples the bodies of every cluster
    scores = z_score(by_cluster, exact)
    assert np.max(np.abs(scores)) < 4.0, (by_cluster.mean(axis=0), exact, scores)
    assert abs(z_score(motion, 1.0)) < 4.0, (motion.mean(), z_score(motion, 1.0))
    assert abs(z_score(motion, 1.25)) > 4.0, (motion.mean(), z_score(motion, 1.25))


def test_a_restart_with_the_factor_repeats_the_run_bit_for_bit():
    """stochastic_Slip_Trapz with the incomplete Cholesky factor and ``update_PC 3``: a run restarted at step 2
    from the saved history (the factor then built again where the step-0 preconditioner was built) and the same
    generator state ends where the uninterrupted run ends, to the bit; restarted with the preconditioner built
    at the restart's configuration instead (the control), its noise is another sample and the run leaves."""
    import copy
    model = close_cluster()
    scheme = make_scheme('stochastic_Slip_Trapz', 0.01, options_with(update_PC=3))
    rng = np.random.default_rng(5)
    state = scheme.init(model, model.start_configuration)
    for _ in range(2):
        state = scheme.step(model, state, rng)
    half, generator, history = state, copy.deepcopy(rng), state.history()
    for _ in range(2):
        state = scheme.step(model, state, rng)

    def continued(saved):
        restarted = scheme.init(model, half.configuration, half.step, history=saved)
        assert restarted.preconditioner is None
        stream = copy.deepcopy(generator)
        for _ in range(2):
            restarted = scheme.step(model, restarted, stream)
        return restarted.configuration
    same = continued(history)
    np.testing.assert_array_equal(same.locations, state.configuration.locations)
    np.testing.assert_array_equal(same.orientations, state.configuration.orientations)
    elsewhere = continued(dict(history, preconditioner_configuration=None, preconditioner_step=None))
    assert np.abs(elsewhere.locations - state.configuration.locations).max() > 1e-6, \
        np.abs(elsewhere.locations - state.configuration.locations).max()
