"""Shared test fixtures: where the reference data lives, which backends run here."""
import os
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
REFERENCE_DIR = Path(os.environ.get('RMB_REFERENCE_DIR', REPO_ROOT.parent / 'shared' / 'reference'))


@pytest.fixture(scope='session')
def reference_dir():
    """Path of ../shared/reference (published-code outputs); skips when it is absent."""
    if not REFERENCE_DIR.is_dir():
        pytest.skip('reference data not found at %s (set RMB_REFERENCE_DIR or check out ../shared)' % REFERENCE_DIR)
    return REFERENCE_DIR
