"""Messages about the published code's later features and module paths, the default install, and the slow
dense-mobility warning (issue 30).

Expected texts are the issue's requirements: one form for every later-version feature (the feature, and where
it is covered or why not); no ``pip install`` hint for a published module path; the "usable here" list of the
backends that really load (free-surface forms included); a warning for a ``python`` dense mobility of more than
about 1,000 blobs that names C++ and the advisor (the published Pillars folder's obstacle has 1,684 blobs, read
from its vertex file).  Each check has a negative control (an ordinary missing package keeps its pip hint, a
small body gets no warning).
"""
import re
import tomllib
from pathlib import Path

import pytest

import mobility
from multi_bodies.files.input_options import (FEATURE_STATUS, UNSUPPORTED_FEATURES, UNSUPPORTED_LATER_OPTIONS,
                                              parse_input_text)
from multi_bodies.run.run_setup import DENSE_PYTHON_BLOBS, slow_dense_warning
from multi_bodies.solver.user_hooks import load_user_hooks
from utils import UserInputError

REPO = Path(__file__).resolve().parents[1]


def test_numexpr_is_a_dependency_of_the_default_install():
    project = tomllib.loads((REPO / 'pyproject.toml').read_text())['project']
    assert any(re.match(r'numexpr\b', requirement) for requirement in project['dependencies'])
    assert 'numexpr' in (REPO / 'README.md').read_text()


@pytest.mark.parametrize('name', UNSUPPORTED_LATER_OPTIONS)
def test_every_later_option_is_refused_in_one_form_with_its_status(name):
    with pytest.raises(UserInputError) as refusal:
        parse_input_text('%s 1\n' % name, 'in.dat')
    message = str(refusal.value)
    feature = next(f for f, names in UNSUPPORTED_FEATURES.items() if name in names)
    assert message.startswith("in.dat, line 1: option '%s'" % name)
    assert 'belongs to %s, a feature of a later version of the published code' % feature in message
    assert '(%s)' % FEATURE_STATUS[feature] in message and message.endswith('remove it')


@pytest.mark.parametrize('line', ['from mobility import not_here as mob', 'import articulated.not_a_published_module',
                                  'from Lubrication import Lubrication_Class'])
def test_a_published_module_path_is_not_sent_to_pip(tmp_path, line):
    (tmp_path / 'user_defined_functions.py').write_text(line + '\n')
    with pytest.raises(UserInputError) as refusal:
        load_user_hooks(str(tmp_path))
    message = str(refusal.value)
    assert 'pip install' not in message and "published code's own tree" in message, message
    assert 'line 1' in message


def test_an_ordinary_missing_package_keeps_its_pip_hint(tmp_path):
    (tmp_path / 'user_defined_functions.py').write_text('import not_a_package_here_xyz\n')
    with pytest.raises(UserInputError, match='pip install not_a_package_here_xyz'):
        load_user_hooks(str(tmp_path))


def test_usable_list_has_every_domain_of_the_backends_that_load():
    usable = mobility.backends.usable_names()
    assert {'python', 'python_no_wall', 'python_free_surface'} <= set(usable)
    if mobility.backends.is_usable('C++'):
        assert {'C++_free_surface', 'numba', 'numba_no_wall', 'numba_free_surface'} <= set(usable)
    for name in usable:  # every name listed really gives a product here
        mobility.mobility_vector_product(name)
    if not mobility.backends.is_usable('pycuda'):
        assert 'pycuda' not in usable
        with pytest.raises(UserInputError, match='usable here: ' + re.escape(', '.join(usable))):
            mobility.backends.load_backend('pycuda')


def test_python_dense_mobility_of_a_large_body_warns_naming_cpp_and_the_advisor(reference_dir):
    pillars = reference_dir / 'published_2025' / 'multi_bodies' / 'examples' / 'Pillars'
    lines = [line for line in (pillars / 'pillar_R_2_h_2_Ntheta_96_Nz_17_caps_4.vertex').read_text().splitlines()
             if line.strip() and not line.lstrip().startswith('#')]
    blobs = int(lines[0].split()[0])
    assert blobs == 1684
    options = parse_input_text('mobility_blobs_implementation python\n', str(pillars / 'inputfile.dat'))
    warning = slow_dense_warning(options, 'python', [0, 16, 16 + blobs])
    assert warning.startswith('warning:') and '1684 blobs' in warning and 'C++' in warning
    assert 'advise.py' in warning
    assert slow_dense_warning(options, 'python', [0, DENSE_PYTHON_BLOBS]) is None  # negative control
    assert slow_dense_warning(options, 'C++', [0, 16, 16 + blobs]) is None
