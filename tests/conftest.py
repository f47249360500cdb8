"""Shared test fixtures: where the reference data lives, which backends run here."""
import os

# The tests' dense algebra is on small matrices (preconditioner blocks, dense schemes of a few bodies):
# several BLAS threads on 2 shared cores made a dense Brownian step 8 times slower (measured), so the
# tests use one BLAS thread.  Set before numpy is imported; the C++ kernels keep their OpenMP threads.
os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')
os.environ.setdefault('MKL_NUM_THREADS', '1')
from pathlib import Path

import numpy as np
import pytest

# numpy < 2.0 (the oldest supported numpy is 1.26) names numpy.trapezoid trapz; the tests use the new name.
if not hasattr(np, 'trapezoid'):
    np.trapezoid = np.trapz

REPO_ROOT = Path(__file__).resolve().parents[1]
REFERENCE_DIR = Path(os.environ.get('RMB_REFERENCE_DIR', REPO_ROOT.parent / 'shared' / 'reference'))


@pytest.fixture(scope='session')
def reference_dir():
    """Path of ../shared/reference (published-code outputs); skips when it is absent."""
    if not REFERENCE_DIR.is_dir():
        pytest.skip('reference data not found at %s (set RMB_REFERENCE_DIR or check out ../shared)' % REFERENCE_DIR)
    return REFERENCE_DIR
