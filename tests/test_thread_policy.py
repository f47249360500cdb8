"""The OpenMP wait policy the package chooses before its kernels load (mobility.threads)."""
import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PROBE = "import os, mobility; print(os.environ.get('OMP_WAIT_POLICY'), os.environ.get('GOMP_SPINCOUNT'))"


def probe(**extra):
    environment = {key: value for key, value in os.environ.items()
                   if key not in ('OMP_WAIT_POLICY', 'GOMP_SPINCOUNT', 'RMB_ACTIVE_WAIT')}
    environment.update(PYTHONPATH=ROOT, **extra)
    return subprocess.run([sys.executable, '-c', PROBE], env=environment, capture_output=True, text=True,
                          check=True).stdout.split()


def test_passive_waiting_by_default():
    assert probe() == ['PASSIVE', '0']


def test_the_users_choice_is_kept():
    assert probe(OMP_WAIT_POLICY='ACTIVE') == ['ACTIVE', '0']
    assert probe(RMB_ACTIVE_WAIT='1') == ['None', 'None']
