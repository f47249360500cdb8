"""Speed options of the stochastic schemes (doc/dynamics.md, speed options)."""
import os
import sys
from types import SimpleNamespace

import numpy as np
import pytest

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), 'benchmarks'))

from quaternion_integrator.schemes import make_scheme  # noqa: E402
from utils import UserInputError  # noqa: E402


def options(tolerance):
    return SimpleNamespace(kT=1.0, rf_delta=1e-3, update_PC=1, noise_solver_tolerance=tolerance)


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
        _, velocities = scheme.advance(system, system.configuration, 0, np.random.default_rng(5))
        results[tolerance] = (velocities, system.counters(scheme)['stochastic_iterations_count'])
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
                                         'stochastic_traction_EM', 'stochastic_traction_AB'])
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
        steps[pair] = scheme.advance(system, system.configuration, 0, np.random.default_rng(5))[1]
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
