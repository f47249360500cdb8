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
