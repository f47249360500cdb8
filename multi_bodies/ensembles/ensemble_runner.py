"""Ensembles of dynamic runs: replicas and parameter sweeps, run on Dask (floor 7).

An ensemble is one input file run ``R`` times at every point of a parameter
grid (``--vary kT=0.5,1,2 --vary dt=...``: the Cartesian product), each run
with its own seed.  This module

* plans it (:func:`build_plan`, in :mod:`multi_bodies.ensembles.ensemble_plan`): one folder per parameter point and replica
  under the output folder ``D``, ``D/<point>/r<replica>/input.dat`` (the
  user's input with the structure paths made absolute and the overrides
  appended), seeds from ``numpy.random.SeedSequence(master)`` spawned once
  per point and once per replica in the point (spawn key ``(point, replica)``),
  and the manifest ``D/ensemble.json``;
* runs one replica in the calling process (:func:`run_replica`, the Dask
  task) through :func:`multi_bodies.run.dynamic_run.run_dynamics`, in the folder
  of the user's input file (relative structure paths and
  ``user_defined_functions.py`` are found there), resuming from the last
  complete restart record when an earlier attempt was killed, and writing
  ``status.json`` and ``replica.log`` beside the run's outputs;
* drives the whole ensemble on a ``distributed.Client``
  (:func:`run_on_client`) or one replica after another in this process
  (:func:`run_serially`), with one progress line, skipping replicas that
  finished before.

Dask (``distributed``, ``dask_jobqueue``) is imported only by the functions
that need it; without it :func:`require_distributed` raises a UserInputError
that names the extra to install.  The statistics of a finished ensemble are
in :mod:`multi_bodies.ensembles.ensemble_statistics`.
"""
import contextlib
import json
import os
import socket
import sys
import threading
import time
import traceback


from mobility.threads import available_cores
import utils
from utils import UserInputError
# The plan and manifest (ensemble_plan); re-exported here for the callers of the runner.
from multi_bodies.ensembles.ensemble_plan import LOCK_NAME, LOCK_WRITE_SECONDS  # noqa: F401
from multi_bodies.ensembles.ensemble_plan import (MANIFEST_NAME, REPLICA_INPUT_NAME, STATUS_NAME, LOG_NAME,
                                                  MANIFEST_VERSION, ENSEMBLE_OWNED_OPTIONS, parse_vary,
                                                  point_name, parameter_points, replica_seeds, replica_input_text,
                                                  _sha256, build_plan, _atomic_write_text, read_manifest,
                                                  _check_inside, write_plan, existing_master_seed, ensemble_lock,
                                                  replica_specs, read_status,
                                                  is_finished)  # noqa: F401

INSTALL_HINT = "pip install -e '.[ensemble]' (or: pip install 'dask[distributed]' dask-jobqueue)"

# One replica at a time per process: a run reads its hooks and relative paths from the working directory.
_RUN_LOCK = threading.Lock()


# ------------------------------------------------------------------ optional dependencies
def require_distributed():
    """Import and return the ``distributed`` module, or raise UserInputError naming the extra."""
    try:
        import distributed
    except ImportError as err:
        raise UserInputError('running an ensemble on Dask needs dask.distributed, which is not installed (%s); '
                             'install the ensemble extra: %s, or run the replicas in this process with '
                             '--workers 0' % (err, INSTALL_HINT))
    return distributed


def require_jobqueue():
    """Import and return ``dask_jobqueue``, or raise UserInputError naming the extra."""
    try:
        import dask_jobqueue
    except ImportError as err:
        raise UserInputError('--jobqueue needs dask-jobqueue, which is not installed (%s); install the ensemble '
                             'extra: %s' % (err, INSTALL_HINT))
    return dask_jobqueue


# ------------------------------------------------------------------ one replica (the task)
def prepare_resume(options, log=print):
    """Step to resume a killed replica from (0: start afresh); changes no file.

    The step is that of the last record of ``output_name.restart`` whose
    snapshot is complete and unchanged (its checksum): a record cut by the
    kill, or a snapshot written without its record, is passed over, with a
    line saying so.  The resumed run (through ``initial_step``) moves what
    the kill left after that pair aside at its first save, once the
    replacement is being written, so the resumed outputs equal those of an
    undisturbed run and a resume that fails loses nothing.
    """
    from multi_bodies.run import run_output
    path = options.output_name + run_output.RESTART_SUFFIX
    if not os.path.isfile(path):
        return 0
    types = [(spec.ID, 0) for spec in options.structures]
    last, _ = run_output.last_complete_pair(options.output_name, options.save_clones, types, report=log)
    if last is None or not isinstance(last.get('step'), int) or last['step'] <= 0:
        return 0
    log('# ensemble: the last complete snapshot and record is step %d%s' % (
        last['step'], ' (saved when a signal stopped the run)' if last.get('stop') else ''))
    return int(last['step'])


def _write_status(spec, status):
    status = dict(status, input_sha256=spec['input_sha256'],
                  finished_at=time.strftime('%Y-%m-%dT%H:%M:%SZ', time.gmtime()))
    _atomic_write_text(os.path.join(spec['path'], STATUS_NAME), json.dumps(status, indent=1) + '\n')
    return status


@contextlib.contextmanager
def _in_directory(path):
    previous = os.getcwd()
    os.chdir(path)
    try:
        yield
    finally:
        os.chdir(previous)


def _last_error_line(log_path):
    try:
        with open(log_path) as f:
            lines = [line.strip() for line in f if line.strip()]
    except OSError:
        return ''
    errors = [line for line in lines if line.startswith('error')]
    return errors[-1] if errors else (lines[-1] if lines else '')


def run_replica(spec, make_writers=None):
    """Run one replica in this process; the Dask task.  Returns a result dict.

    ``make_writers``: None, or a callable ``make_writers(options) -> list`` of the caller's own writers
    (``multi_bodies.run.writers.Writer``) for this replica's run (each replica needs its own: a writer is opened
    and closed by one run); they write beside the replica's outputs as in any dynamic run.

    ``spec``: one entry of :func:`replica_specs`.  The run reads
    ``spec['input_file']`` with the working directory set to
    ``spec['run_directory']`` (the folder of the user's input); its printed
    output goes to ``replica.log`` in the replica folder.  A replica that
    finished before (``status.json`` done, same input) is not run again; one
    whose earlier attempt was killed resumes from its last saved step
    (:func:`prepare_resume`) with ``initial_step`` set to it, which continues
    the trajectory exactly (SPEC decision 11).

    Result keys: ``folder``, ``status`` ('done', 'failed': user error or run
    stopped, 'stopped': interrupted), ``exit_status``, ``message``,
    ``resumed_from`` (step, 0 for a fresh start), ``seconds``, ``host``,
    ``pid``, ``skipped`` (finished before).  Exceptions other than user
    errors are raised (Dask retries them) after being logged.
    """
    from multi_bodies.run.dynamic_run import run_dynamics
    from multi_bodies.files.input_options import read_input_file
    if is_finished(spec):
        return dict(read_status(spec['path']), folder=spec['folder'], skipped=True)
    log_path = os.path.join(spec['path'], LOG_NAME)
    result = {'folder': spec['folder'], 'host': socket.gethostname(), 'pid': os.getpid(), 'resumed_from': 0,
              'skipped': False}
    start = time.perf_counter()
    with _RUN_LOCK, open(log_path, 'a') as log, _in_directory(spec['run_directory']), \
            contextlib.redirect_stdout(log), contextlib.redirect_stderr(log):
        try:
            options = read_input_file(spec['input_file'])
            resume = prepare_resume(options)
            print('# ensemble: %s on %s (pid %d), %s' % (
                spec['folder'], result['host'], result['pid'],
                'resuming from step %d' % resume if resume else 'fresh start'), flush=True)
            if resume:
                options = options.replace(initial_step=resume)
            result['resumed_from'] = resume
            exit_status = run_dynamics(options, log=print,
                                       writers=make_writers(options) if make_writers is not None else ())
        except UserInputError as err:
            print('error: %s' % err, flush=True)
            result.update(status='failed', exit_status=2, message=str(err))
        except Exception:
            traceback.print_exc(file=log)
            log.flush()
            raise
        else:
            result['exit_status'] = exit_status
            if exit_status == 0:
                result.update(status='done', message='')
            elif exit_status == 1:
                result.update(status='failed', message='run stopped: %s' % _last_error_line(log_path))
            else:
                result.update(status='stopped', message='interrupted (exit status %d); a rerun resumes it from '
                                                        'its last saved step' % exit_status)
    result['seconds'] = time.perf_counter() - start
    return _write_status(spec, result)


# ------------------------------------------------------------------ progress of the ensemble
class EnsembleProgress:
    """One line for the whole ensemble: replicas done, failed, running, and the time left.

    A tqdm bar when ``stream`` is a terminal and tqdm is installed, else a
    plain line whenever the counts change (at most every ``interval``
    seconds) and at the end.
    """

    def __init__(self, total, skipped=0, stream=None, interval=10.0):
        self.total, self.skipped = total, skipped
        self.stream = sys.stdout if stream is None else stream
        self.interval = float(interval)
        self.start = time.perf_counter()
        self.last_line = -float('inf')
        self.counts = (0, 0, 0)
        self.bar = utils.terminal_progress_bar(self.stream, total, 'replica')

    def write(self, text):
        utils.write_progress_line(self.bar, self.stream, text)

    def line(self):
        if self.total == 0:
            return 'ensemble: nothing to run (%d replicas finished before, skipped)' % self.skipped
        done, failed, running = self.counts
        finished = done + failed
        elapsed = time.perf_counter() - self.start
        eta = ('about %.0f s left' % (elapsed / finished * (self.total - finished))) if finished else 'ETA unknown'
        return ('ensemble: %d of %d replicas done, %d failed, %d running%s, elapsed %.0f s, %s'
                % (done, self.total, failed, running,
                   ' (%d finished before, skipped)' % self.skipped if self.skipped else '', elapsed, eta))

    def update(self, done, failed, running, force=False):
        changed = (done, failed, running) != self.counts
        self.counts = (done, failed, running)
        if self.bar is not None:
            self.bar.n = done + failed
            self.bar.set_postfix_str('done %d, failed %d, running %d' % self.counts, refresh=True)
            return
        now = time.perf_counter()
        if force or (changed and now - self.last_line >= self.interval):
            self.write(self.line())
            self.last_line = now

    def close(self):
        if self.bar is not None:
            self.bar.close()
            self.bar = None
        self.write(self.line())


# ------------------------------------------------------------------ running the ensemble
def _failure_result(spec, exc):
    message = '%s: %s' % (type(exc).__name__, exc)
    return {'folder': spec['folder'], 'status': 'failed', 'exit_status': None, 'message': message,
            'resumed_from': None, 'seconds': None, 'skipped': False}


def _report(progress, result, output_dir):
    if result['status'] != 'done':
        progress.write('replica %s %s: %s' % (os.path.join(output_dir, result['folder']), result['status'],
                                             result.get('message', '')))


def split_finished(plan):
    """(specs still to run, number finished before) of a plan."""
    specs = replica_specs(plan)
    todo = [spec for spec in specs if not is_finished(spec)]
    return todo, len(specs) - len(todo)


def run_serially(plan, stream=None):
    """Run every unfinished replica in this process, one after another; returns the result dicts.

    An interrupted replica (SIGINT/SIGTERM: it stops after the step in
    progress, outputs complete) stops the ensemble; a rerun resumes it.
    """
    todo, skipped = split_finished(plan)
    progress = EnsembleProgress(len(todo), skipped, stream)
    results, done, failed = [], 0, 0
    for spec in todo:
        progress.update(done, failed, 1)
        result = run_replica(spec)
        results.append(result)
        done += result['status'] == 'done'
        failed += result['status'] == 'failed'  # a stopped replica is not a failure: a rerun resumes it
        _report(progress, result, plan['output_dir'])
        if result['status'] == 'stopped':
            break
    progress.update(done, failed, 0)
    progress.close()
    return results


def run_on_client(plan, client, retries=3, refresh=1.0, stream=None):
    """Submit every unfinished replica to a ``distributed.Client``; wait, reporting progress; return results.

    Tasks that raise are retried ``retries`` times by Dask; a task whose
    worker dies is rescheduled by the scheduler (up to its
    ``distributed.scheduler.allowed-failures``), and the new attempt resumes
    the replica from its last saved step.  A replica that fails for good is
    reported with its folder and message, and the others go on.
    """
    distributed = require_distributed()
    todo, skipped = split_finished(plan)
    progress = EnsembleProgress(len(todo), skipped, stream)
    futures = client.map(run_replica, todo, retries=retries, pure=False) if todo else []
    spec_of = {future.key: spec for future, spec in zip(futures, todo)}
    pending, results, done, failed = set(futures), [], 0, 0
    try:
        while pending:
            try:
                finished, pending = distributed.wait(list(pending), timeout=refresh, return_when='FIRST_COMPLETED')
                pending = set(pending)
            except (TimeoutError, distributed.TimeoutError):
                finished = set()
            for future in finished:
                spec = spec_of[future.key]
                if future.status == 'finished':
                    result = future.result()
                else:  # raised after its retries, lost its worker too often (KilledWorker), or cancelled
                    try:
                        exception = future.exception()
                    except Exception as err:  # a cancelled future raises instead
                        exception = err
                    result = _failure_result(spec, exception)
                    _write_status(spec, result)
                results.append(result)
                done += result['status'] == 'done'
                failed += result['status'] != 'done'
                _report(progress, result, plan['output_dir'])
                future.release()
            progress.update(done, failed, _running(client, pending))
    finally:
        progress.close()
    return results


def _running(client, pending):
    """Tasks of ``pending`` that workers are processing now (at most one per worker thread)."""
    if not pending:
        return 0
    try:
        keys = {future.key for future in pending}
        processing = client.processing()
        threads = sum(client.nthreads().values())
    except Exception:  # the scheduler is busy or gone: the count is only for display
        return 0
    return min(threads, sum(1 for tasks in processing.values() for key in tasks if key in keys))


def thread_environment(threads, environ=os.environ):
    """Variables that give each worker process ``threads`` OpenMP threads and the package's BLAS policy.

    BLAS gets one thread (``mobility.threads``: OpenBLAS's spinning workers slowed the kernels), or
    ``RMB_BLAS_THREADS`` threads when that is set (``0``: as many as OpenMP).
    """
    value = str(int(threads))
    blas = environ.get('RMB_BLAS_THREADS', '1').strip()
    blas = value if blas == '0' else blas
    return {'OMP_NUM_THREADS': value, 'OPENBLAS_NUM_THREADS': blas, 'MKL_NUM_THREADS': blas}


SCRATCH_NAME = 'dask-scratch'


def scratch_directory(output_dir):
    """Dask's scratch space of a local cluster: ``output_dir/dask-scratch`` (not a shared /tmp folder)."""
    return os.path.join(os.path.abspath(output_dir), SCRATCH_NAME)


def local_address(address):
    """``address`` of a local dashboard bound to this machine only: ':8787' -> '127.0.0.1:8787' (None stays None).

    A bare port (Dask's ':8787') would listen on every interface, so anyone
    on the network could watch and drive the cluster; give a host
    explicitly (``--dashboard-address 0.0.0.0:8787``) to serve it wider.
    """
    if address is None:
        return None
    address = str(address)
    return '127.0.0.1' + address if address.startswith(':') else address


def make_local_cluster(workers, omp_threads=None, retries=3, dashboard_address=':8787', local_directory=None):
    """A ``distributed.LocalCluster`` of ``workers`` processes, one task thread each.

    The scheduler and the dashboard listen on 127.0.0.1 only (a bare port
    ``:8787`` becomes ``127.0.0.1:8787``; see ``local_address``).  Dask's
    scratch space goes to ``local_directory`` (the ensemble passes a folder
    inside its output folder; None: Dask's default under the temporary folder).

    Every worker gets ``omp_threads`` OpenMP/BLAS threads (default: the
    cores this process may run on divided by ``workers``, at least 1; ``mobility.threads``), set before the
    worker process starts, so the workers do not oversubscribe the cores.
    ``retries``: how often a task may lose its worker before it fails.
    """
    distributed = require_distributed()
    import dask
    if workers < 1:
        raise UserInputError('--workers must be at least 1 for a Dask cluster, got %d (0 runs in this process)'
                             % workers)
    threads = omp_threads or max(1, available_cores() // workers)
    environment = dict(dask.config.get('distributed.nanny.pre-spawn-environ', {}), **thread_environment(threads))
    with dask.config.set({'distributed.scheduler.allowed-failures': int(retries),
                          'distributed.nanny.pre-spawn-environ': environment}):
        return distributed.LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                        host='127.0.0.1', dashboard_address=local_address(dashboard_address),
                                        local_directory=local_directory)


JOBQUEUE_CLASSES = {'slurm': 'SLURMCluster', 'pbs': 'PBSCluster', 'lsf': 'LSFCluster'}


def jobqueue_arguments(kind, cores, memory, walltime=None, queue=None, account=None, omp_threads=1,
                       interface=None, extra_directives=(), log_directory=None, local_directory=None,
                       python=None, lifetime=None):
    """Keyword arguments of the dask-jobqueue cluster class for one batch job of ``cores`` cores.

    Each job runs ``cores // omp_threads`` worker processes of one task
    thread each; every worker's replica gets ``omp_threads`` OpenMP threads.
    ``lifetime`` (e.g. '3h50m', a little under the wall time) retires the
    workers of a job before the queue kills it (``--lifetime`` of dask-worker,
    staggered by 4 minutes), and a new job replaces it.
    """
    if kind not in JOBQUEUE_CLASSES:
        raise UserInputError('--jobqueue %s: choose one of %s' % (kind, ', '.join(sorted(JOBQUEUE_CLASSES))))
    if cores < 1 or omp_threads < 1 or cores % omp_threads:
        raise UserInputError('--job-cores %d must be a positive multiple of --omp-threads %d'
                             % (cores, omp_threads))
    if not memory:
        raise UserInputError('--jobqueue %s needs --job-memory (memory of one job, e.g. 64GB)' % kind)
    processes = cores // omp_threads
    package_root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    prologue = ['export %s=%s' % item for item in thread_environment(omp_threads).items()]
    prologue.append('export PYTHONPATH=%s${PYTHONPATH:+:$PYTHONPATH}' % package_root)  # the workers import us
    kwargs = {'cores': processes, 'processes': processes, 'memory': memory, 'job_script_prologue': prologue,
              'job_extra_directives': list(extra_directives)}
    if kind == 'slurm':
        kwargs['job_cpu'] = cores
    if lifetime:
        kwargs['worker_extra_args'] = ['--lifetime', lifetime, '--lifetime-stagger', '4m']
    for key, value in (('walltime', walltime), ('queue', queue), ('account', account), ('interface', interface),
                       ('log_directory', log_directory), ('local_directory', local_directory),
                       ('python', python)):
        if value:
            kwargs[key] = value
    return kwargs


def make_jobqueue_cluster(kind, jobs, retries=3, dashboard_address=':8787', **arguments):
    """A dask-jobqueue cluster (Slurm, PBS or LSF) scaled to ``jobs`` batch jobs (see :func:`jobqueue_arguments`).

    The scheduler runs in this process (on the login node); its dashboard is
    served at ``dashboard_address`` (None: on any free port).
    """
    dask_jobqueue = require_jobqueue()
    require_distributed()
    import dask
    kwargs = jobqueue_arguments(kind, **arguments)
    kwargs['scheduler_options'] = {'dashboard_address': dashboard_address or ':0'}  # None: any free port
    with dask.config.set({'distributed.scheduler.allowed-failures': int(retries)}):
        cluster = getattr(dask_jobqueue, JOBQUEUE_CLASSES[kind])(**kwargs)
    if jobs:
        # adaptive with a fixed size: a job that ends (wall time, node failure) is replaced by a new one
        cluster.adapt(minimum_jobs=jobs, maximum_jobs=jobs)
    return cluster
