"""One scheme registry (multi_bodies/files/scheme_table.py, issue 43): the classes, the parser, the advisor and the
manual read the same list, nothing recognises a scheme by the pattern of its name, and the dense twin takes its
iterative scheme's step.

The dense twin is checked against a law outside the code under test: ``stochastic_Slip_Mid_DLA`` and
``stochastic_Slip_Mid`` are the same formulas with exact and iterative linear algebra, so from the same state and
the same random numbers their steps agree to the solver tolerance (1e-12 here; measured 4e-13 of the distance
travelled), and a dense scheme that took another step would not.
"""
import re
from pathlib import Path

import numpy as np
import pytest

from multi_bodies.files import input_options
from multi_bodies.files.scheme_table import (SCHEME_TABLE, SchemeEntry, dense_variants, roller_variants, scheme_names)
from quaternion_integrator import schemes, stochastic_schemes
from test_layout import PUBLISHED_FACES, package_modules

REPO = Path(__file__).resolve().parents[1]


def test_every_registered_scheme_has_its_class_and_says_what_it_needs():
    dynamic = scheme_names(dynamic=True)
    assert set(schemes.SCHEMES) == set(dynamic)
    assert set(scheme_names(kind='static')) == {'body_mobility', 'mobility', 'resistance'}
    for name in dynamic:
        entry = SCHEME_TABLE[name]
        scheme = schemes.make_scheme(name, 0.01, input_options.options_with())
        assert scheme.name == name and scheme.entry is entry
        assert scheme.dense == (entry.algebra == 'dense')
        assert isinstance(scheme, stochastic_schemes.StochasticScheme) == (entry.kind == 'stochastic')
        for twin in (entry.dense_of, entry.rollers_of):
            assert twin is None or twin in dynamic
    for entry in SCHEME_TABLE.values():
        assert entry.kind in ('static', 'deterministic', 'stochastic') and entry.algebra in ('iterative', 'dense')
    assert dense_variants()['stochastic_Slip_Mid'] == 'stochastic_Slip_Mid_DLA'
    assert roller_variants()['deterministic_adams_bashforth'] == 'deterministic_adams_bashforth_rollers'


def test_the_parser_reads_the_registry():
    """The names the scheme option accepts and the options each scheme uses come from the registry."""
    option = input_options.OPTION_TABLE['scheme']
    assert tuple(option.rule.names) == tuple(SCHEME_TABLE)
    for name, entry in SCHEME_TABLE.items():
        tags = input_options.usage_tags(None, name)
        assert ('static' in tags) == (entry.kind == 'static')
        assert ('stochastic' in tags) == (entry.kind == 'stochastic')
        assert ('rollers' in tags) == entry.rollers and ('lubrication' in tags) == entry.lubrication
    assert input_options.is_used('kT', 'dynamic', 'articulated_deterministic_midpoint') is False
    assert input_options.is_used('omega_one_roller', 'dynamic', 'lubrication_trapezoidal_rollers') is True


def _backticked(text):
    return set(re.findall(r'`([A-Za-z_]+)`', text))


def test_the_manual_lists_the_registry():
    """doc/dynamics.md's table of schemes names every dynamic scheme of the registry and nothing else; doc/options.md's
    row of the scheme option names every scheme."""
    dynamics = (REPO / 'doc' / 'dynamics.md').read_text()
    table = dynamics.split('### Schemes', 1)[1].split('\n\n', 2)[1]
    first_cells = '\n'.join(line.split('|')[1] for line in table.splitlines() if line.startswith('| `'))
    assert _backticked(first_cells) == set(scheme_names(dynamic=True))
    options = (REPO / 'doc' / 'options.md').read_text()
    row = [line for line in options.splitlines() if line.startswith('| `scheme` |')][0]
    allowed = row.split('|')[5]
    assert _backticked(allowed) == set(SCHEME_TABLE)


# a scheme recognised by the pattern of its name (what the registry replaces)
NAME_PATTERNS = re.compile(r"""'(rollers|dense|_rollers|_DLA|_dense_algebra)' (not )?in |"""
                           r"""\.(startswith|endswith)\(\s*'(deterministic|stochastic|lubrication|articulated|"""
                           r"""_rollers|_no_rollers|_DLA|_dense_algebra)|\.replace\(\s*'_(rollers|dense_algebra)'""")


def test_no_scheme_is_recognised_by_its_name():
    found = []
    for module, path in sorted(package_modules().items()):
        if module in PUBLISHED_FACES or module == 'multi_bodies.files.scheme_table':
            continue
        for number, line in enumerate(Path(path).read_text().splitlines(), 1):
            if NAME_PATTERNS.search(line.split('#', 1)[0]):
                found.append('%s:%d: %s' % (module, number, line.strip()))
    assert not found, 'schemes recognised by name patterns (read multi_bodies.files.scheme_table):\n' + \
        '\n'.join(found)


def test_the_pattern_check_catches_a_pattern():
    """Negative control: the lines the registry replaced are caught."""
    for line in ("if 'rollers' in options.scheme:", "stochastic = not scheme.startswith('deterministic')",
                 "base = scheme.replace('_rollers', '')", "dense = 'dense' in options.scheme"):
        assert NAME_PATTERNS.search(line), line
    assert not NAME_PATTERNS.search("if moves_rollers(options.scheme):")


def test_the_dense_twin_takes_the_iterative_step(monkeypatch):
    """stochastic_Slip_Mid_DLA is stochastic_Slip_Mid's step with dense products: the same method, and from the same
    state and random numbers the same configuration to the solver tolerance (1e-12).  The iterative noise is taken
    by Lanczos without the preconditioner's factor here, so that both draw the symmetric root ``M^{1/2} z`` (with
    the factor L, Lanczos gives ``L (L^-1 M L^-T)^{1/2} z``: the same covariance, another sample of it)."""
    from test_neighbour_preconditioner import boomerang_model, grid
    assert stochastic_schemes.StochasticSlipMidDLA.attempt is stochastic_schemes.StochasticSlipMid.attempt
    monkeypatch.setattr(stochastic_schemes.StochasticScheme, 'lanczos_noise',
                        lambda self, context, problem, z, factor, preconditioner:
                        context.lanczos_noise(problem, z, factor, None, tolerance=1e-13))
    assert SchemeEntry._fields[0] == 'name'
    model = boomerang_model(grid(3, 3.0), seed=4, preconditioner='block_diagonal').replace(solver_tolerance=1e-12)
    options = input_options.options_with(kT=0.5)
    ends = {}
    for name in ('stochastic_Slip_Mid', 'stochastic_Slip_Mid_DLA', 'stochastic_Slip_Trapz'):
        scheme = schemes.make_scheme(name, 0.01, options)
        state = scheme.init(model, model.start_configuration)
        ends[name] = scheme.step(model, state, np.random.default_rng(11)).configuration.locations
    start = model.start_configuration.locations
    travelled = np.abs(ends['stochastic_Slip_Mid'] - start).max()
    assert travelled > 1e-3
    assert np.abs(ends['stochastic_Slip_Mid_DLA'] - ends['stochastic_Slip_Mid']).max() < 1e-9 * travelled
    # control: another scheme from the same numbers ends elsewhere
    assert np.abs(ends['stochastic_Slip_Trapz'] - ends['stochastic_Slip_Mid']).max() > 1e-3 * travelled


@pytest.mark.parametrize('field', ['rollers', 'lubrication', 'articulated', 'obstacles', 'slip_length'])
def test_scheme_names_select_by_need(field):
    chosen = scheme_names(**{field: True})
    assert chosen and all(getattr(SCHEME_TABLE[name], field) for name in chosen)
    assert set(chosen) | set(scheme_names(**{field: False})) == set(SCHEME_TABLE)
