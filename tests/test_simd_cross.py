"""The kernel paths without Python, natively and for 64-bit ARM under an emulator (tests/cpp/simd_paths_check.cpp,
tests/cpp/forces_paths_check.cpp).

The first check program runs the mobility kernels of every path its CPU runs against the scalar path on the same
blobs (45 of them, an overlapping pair, periodic boxes, the couplings, per-blob radii, source-target sums, the
paired and grand products) and measures the vector 1/sqrt against long double; the second runs the blob-blob
forces (free and periodic, one radius and per-blob radii, a coincident pair) the same way.  Natively it checks the x86-64 (or ARM) paths of this
machine; cross-compiled for AArch64 (aarch64-linux-gnu-g++) and run under qemu-aarch64 with 256-bit SVE
vectors, it checks the NEON and SVE paths, which no x86-64 CPU runs.  Each test skips, saying which, when
its compiler or emulator is not installed.
"""
import os
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SOURCES = [ROOT / 'tests' / 'cpp' / 'simd_paths_check.cpp', ROOT / 'tests' / 'cpp' / 'forces_paths_check.cpp']
FLAGS = ['-O3', '-std=c++17', '-fno-math-errno', '-fno-trapping-math', '-ffp-contract=fast',
         '-I' + str(ROOT / 'mobility' / 'cpp'), '-I' + str(ROOT / 'multi_bodies' / 'solver' / 'cpp')]

pytestmark = pytest.mark.slow


def _results(output):
    """{path: (relative difference to scalar, 1/sqrt error in ulp)} from the program's lines."""
    rows = {}
    for line in output.strip().splitlines():
        name, difference, ulps = line.split()
        rows[name] = (float(difference), float(ulps))
    return rows


def _check(rows, expected):
    assert 'scalar' in rows and set(expected) <= set(rows), rows
    for name, (difference, ulps) in rows.items():
        assert difference < 1e-12, '%s differs from scalar by %g' % (name, difference)
        assert ulps <= 2.0, '%s: 1/sqrt off by %g ulp' % (name, ulps)
    assert any(difference > 0.0 for name, (difference, _) in rows.items() if name != 'scalar') or len(rows) == 1


@pytest.mark.parametrize('source', SOURCES, ids=lambda path: path.stem)
def test_native_paths(tmp_path, source):
    compiler = os.environ.get('CXX') or shutil.which('c++') or shutil.which('g++')
    if compiler is None:
        pytest.skip('no C++ compiler')
    program = tmp_path / 'check'
    subprocess.run([compiler] + FLAGS + [str(source), '-o', str(program)], check=True, capture_output=True,
                   timeout=600)
    result = subprocess.run([str(program)], capture_output=True, text=True, timeout=300, check=True)
    expected = []
    if os.uname().machine == 'x86_64':
        import mobility._mobility_cpp as m
        expected = list(m.simd_paths()) if hasattr(m, 'simd_paths') else []
    _check(_results(result.stdout), expected)


@pytest.mark.parametrize('source', SOURCES, ids=lambda path: path.stem)
def test_aarch64_paths_under_emulator(tmp_path, source):
    compiler, emulator = shutil.which('aarch64-linux-gnu-g++'), shutil.which('qemu-aarch64')
    if compiler is None or emulator is None:
        pytest.skip('needs aarch64-linux-gnu-g++ and qemu-aarch64 (apt-get install g++-aarch64-linux-gnu qemu-user)')
    program = tmp_path / 'check_aarch64'
    subprocess.run([compiler] + FLAGS + ['-static', str(source), '-o', str(program)], check=True,
                   capture_output=True, timeout=600)
    result = subprocess.run([emulator, '-cpu', 'max,sve256=on', str(program)], capture_output=True, text=True,
                            timeout=300, check=True)
    rows = _results(result.stdout)
    version = subprocess.run([compiler, '-dumpversion'], capture_output=True, text=True).stdout.strip()
    expected = ['neon', 'scalar'] + (['sve'] if int(version.split('.')[0]) >= 11 else [])
    _check(rows, expected)
    assert list(rows)[0] == ('sve' if 'sve' in expected else 'neon')  # 256-bit SVE comes before NEON
