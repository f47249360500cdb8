"""The OpenMP wait policy the package chooses before its kernels load (mobility.threads)."""
import os
import subprocess
import sys

import pytest

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


BLAS_PROBE = ("import numpy, scipy.linalg, mobility; from mobility import threads; "
              "print(sorted(set(threads.blas_threads().values())) or 'none')")


def blas_probe(**extra):
    environment = {key: value for key, value in os.environ.items()
                   if key not in ('OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS', 'RMB_BLAS_THREADS', 'OMP_NUM_THREADS')}
    environment.update(PYTHONPATH=ROOT, **extra)
    return subprocess.run([sys.executable, '-c', BLAS_PROBE], env=environment, capture_output=True, text=True,
                          check=True).stdout.strip()


def test_one_blas_thread_by_default_and_the_users_choice_kept():
    """Importing mobility sets the loaded OpenBLAS libraries (numpy's and SciPy's) to one thread; an explicit
    OPENBLAS_NUM_THREADS or RMB_BLAS_THREADS=0 leaves them at OpenBLAS's own count (the cores, with OpenMP's
    count given as 2 here so that the control differs from 1 on any machine OpenBLAS allows it)."""
    if blas_probe() == 'none':
        pytest.skip('no OpenBLAS or MKL library found in this process (not Linux, or another BLAS)')
    assert blas_probe() == '[1]'
    assert blas_probe(RMB_BLAS_THREADS='2') == '[2]'
    assert blas_probe(OPENBLAS_NUM_THREADS='2') == '[2]'
    left_alone = blas_probe(RMB_BLAS_THREADS='0', OMP_NUM_THREADS='2')
    assert left_alone != '[1]' or os.cpu_count() == 1, left_alone


def test_ensemble_workers_get_openmp_threads_and_one_blas_thread():
    from multi_bodies.ensembles.ensemble_runner import thread_environment
    assert thread_environment(3, environ={}) == {'OMP_NUM_THREADS': '3', 'OPENBLAS_NUM_THREADS': '1',
                                                 'MKL_NUM_THREADS': '1'}
    assert thread_environment(3, environ={'RMB_BLAS_THREADS': '2'})['OPENBLAS_NUM_THREADS'] == '2'
    assert thread_environment(3, environ={'RMB_BLAS_THREADS': '0'})['MKL_NUM_THREADS'] == '3'
