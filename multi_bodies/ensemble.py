"""Ensembles of dynamic runs on Dask: replicas, parameter sweeps and their statistics (see doc/ensembles.md).

Run (from anywhere; the replicas run in the folder of the input file)::

    python multi_bodies/ensemble.py --input-file F --replicas R [--vary kT=0.5,1,2 --vary dt=...]
        [--workers N | --scheduler ADDRESS | --jobqueue slurm --job-cores C --job-memory M ...]
        [--output-dir D] [--seed MASTER]
    python multi_bodies/ensemble.py --aggregate D [--bins 40] [--max-lag L] [--discard K]

The first form writes one input file per replica and parameter point under
``D/<point>/r<replica>/``, records the seeds in ``D/ensemble.json`` and runs
every replica as one Dask task; a rerun of the same command skips the
replicas that finished and resumes the others from their last saved step.
The second form writes ``D/<point>/statistics.csv``, ``D/summary.csv`` and
the charts ``D/heights.png``, ``D/msd.png``.  Needs the ``ensemble`` extra
(``pip install -e '.[ensemble]'``) except with ``--workers 0`` (in this
process, one replica after another) and for ``--aggregate``.
Exit status: 0 all replicas done, 1 some failed or stopped, 2 bad input.
"""
import argparse
import os
import signal
import sys

# The one path prelude of the scripts: the repository root first, then utils.prepare_script_path.
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import utils  # noqa: E402
utils.prepare_script_path(__file__)

from multi_bodies.ensembles import ensemble_runner as runner  # noqa: E402

REPORT_LIMIT = 20  # failed replicas listed at the end (all are reported as they fail)


def make_parser():
    parser = argparse.ArgumentParser(
        description='Replicas and parameter sweeps of a dynamic run on Dask, and their statistics '
                    '(see doc/ensembles.md).')
    parser.add_argument('--input-file', help='input file of multi_bodies.py; the replicas run in its folder')
    parser.add_argument('--replicas', type=int, default=1, help='replicas per parameter point (default 1)')
    parser.add_argument('--vary', action='append', default=[], metavar='NAME=V1,V2,...',
                        help='sweep an input-file option over these values; repeat for a grid (Cartesian product); '
                             'NAME1:NAME2=V1:W1,V2:W2 varies options together (e.g. dt:n_steps=0.01:400,0.02:200)')
    parser.add_argument('--output-dir', default='ensemble', help='folder of the ensemble (default ./ensemble)')
    parser.add_argument('--seed', type=int, default=None, metavar='MASTER',
                        help='master seed of numpy.random.SeedSequence (default: from the manifest of a rerun, '
                             'else from the operating system; recorded in ensemble.json)')
    where = parser.add_mutually_exclusive_group()
    where.add_argument('--workers', type=int, default=None,
                       help='worker processes of a local Dask cluster (default: the number of cores); '
                            '0 runs the replicas one after another in this process, without Dask')
    where.add_argument('--scheduler', metavar='ADDRESS', help='submit to a running Dask scheduler (tcp://host:8786)')
    where.add_argument('--jobqueue', choices=sorted(runner.JOBQUEUE_CLASSES),
                       help='start a dask-jobqueue cluster of batch jobs')
    parser.add_argument('--omp-threads', type=int, default=None,
                        help='OpenMP/BLAS threads per replica (default: cores / workers locally, 1 on a jobqueue)')
    parser.add_argument('--retries', type=int, default=3,
                        help='attempts a replica may lose to a dying worker or an unexpected error (default 3)')
    parser.add_argument('--dashboard-address', default=':8787',
                        help='local cluster dashboard (default :8787, served on 127.0.0.1 only)')
    jobs = parser.add_argument_group('batch jobs (--jobqueue)')
    jobs.add_argument('--jobs', type=int, default=1, help='batch jobs to start (default 1)')
    jobs.add_argument('--job-cores', type=int, default=None, help='cores of one job')
    jobs.add_argument('--job-memory', help='memory of one job, e.g. 64GB')
    jobs.add_argument('--job-walltime', help='wall time of one job, e.g. 04:00:00')
    jobs.add_argument('--job-queue', help='partition or queue')
    jobs.add_argument('--job-account', help='account to charge')
    jobs.add_argument('--job-interface', help='network interface of the workers, e.g. ib0')
    jobs.add_argument('--job-directive', action='append', default=[],
                      help='extra line of the job script header, e.g. "--constraint=cpu" (repeatable)')
    jobs.add_argument('--job-lifetime', help='retire the workers of a job after this time, a little under the '
                                             'wall time (e.g. 3h50m); a new job replaces it')
    jobs.add_argument('--job-log-directory', help='folder of the job logs')
    jobs.add_argument('--job-local-directory', help='node-local scratch folder of the workers')
    jobs.add_argument('--print-job-script', action='store_true', help='print the job script and exit')
    statistics = parser.add_argument_group('statistics (--aggregate)')
    statistics.add_argument('--aggregate', metavar='D', help='combine the outputs of the ensemble in folder D')
    statistics.add_argument('--bins', type=int, default=40, help='height histogram bins (default 40)')
    statistics.add_argument('--height-range', type=float, nargs=2, metavar=('LOW', 'HIGH'),
                            help='height histogram range (default: all heights)')
    statistics.add_argument('--max-lag', type=int, default=None,
                            help='largest MSD lag in saved frames (default: half the frames)')
    statistics.add_argument('--discard', type=int, default=0, help='saved frames to drop at the start (default 0)')
    statistics.add_argument('--no-charts', action='store_true', help='write the CSV tables only')
    return parser


def _jobqueue_cluster(args):
    if not args.job_cores:
        raise utils.UserInputError('--jobqueue %s needs --job-cores (cores of one batch job)' % args.jobqueue)
    arguments = dict(cores=args.job_cores, memory=args.job_memory, walltime=args.job_walltime,
                     queue=args.job_queue, account=args.job_account, omp_threads=args.omp_threads or 1,
                     interface=args.job_interface, extra_directives=args.job_directive,
                     log_directory=args.job_log_directory, local_directory=args.job_local_directory,
                     python=sys.executable, lifetime=args.job_lifetime)
    if args.print_job_script:
        cluster = runner.make_jobqueue_cluster(args.jobqueue, 0, retries=args.retries, dashboard_address=None,
                                               **arguments)
        print(cluster.job_script())
        cluster.close()
        return None
    return runner.make_jobqueue_cluster(args.jobqueue, args.jobs, retries=args.retries,
                                        dashboard_address=args.dashboard_address, **arguments)


def run(args):
    if not args.input_file:
        raise utils.UserInputError('give --input-file F (and --replicas R), or --aggregate D')
    vary = runner.parse_vary(args.vary)
    seed = args.seed
    if seed is None:
        seed = runner.existing_master_seed(args.output_dir)
    plan = runner.build_plan(args.input_file, args.replicas, vary, args.output_dir, seed)
    if args.jobqueue and args.print_job_script:
        _jobqueue_cluster(args)
        return 0
    if args.workers != 0:
        distributed = runner.require_distributed()
    with runner.ensemble_lock(plan['output_dir']):
        runner.write_plan(plan)
        return _run_locked(args, plan, distributed if args.workers != 0 else None)


def _stop_on_sigterm(signal_number, frame):
    raise KeyboardInterrupt


def _run_locked(args, plan, distributed):
    cluster = client = None
    previous = signal.signal(signal.SIGTERM, _stop_on_sigterm)  # scancel/kill: close the cluster, then stop
    try:
        if distributed is None:
            results = runner.run_serially(plan)
            stopped = [result for result in results if result['status'] == 'stopped']
            if stopped:  # a signal stopped the replica in progress (it saved the step reached)
                print('ensemble stopped (%s); rerun the same command to resume it (finished replicas are skipped, '
                      'the others continue from their last saved step)' % stopped[0].get('message', ''),
                      file=sys.stderr)
                return stopped[0].get('exit_status') or 130
        else:
            if args.jobqueue:
                cluster = _jobqueue_cluster(args)
            elif not args.scheduler:
                cluster = runner.make_local_cluster(args.workers or os.cpu_count() or 1, args.omp_threads,
                                                    retries=args.retries, dashboard_address=args.dashboard_address,
                                                    local_directory=runner.scratch_directory(plan['output_dir']))
            client = distributed.Client(args.scheduler if args.scheduler else cluster)
            print('ensemble of %d replicas (%d points x %d) in %s, master seed %d'
                  % (len(plan['replicas']), len(plan['points']), args.replicas, plan['output_dir'],
                     plan['master_seed']), flush=True)
            if client.dashboard_link:
                import importlib.util
                if args.scheduler or importlib.util.find_spec('bokeh') is not None:
                    print('Dask dashboard: %s' % client.dashboard_link, flush=True)
                else:
                    print('Dask dashboard: not served (it needs bokeh: pip install bokeh)', flush=True)
            results = runner.run_on_client(plan, client, retries=args.retries)
    except KeyboardInterrupt:
        import logging
        for name in ('distributed', 'tornado', 'asyncio', 'dask_jobqueue'):  # no shutdown noise after Ctrl-C
            logging.getLogger(name).setLevel(logging.CRITICAL + 1)
        print('\nensemble stopped; rerun the same command to resume it (finished replicas are skipped, the others '
              'continue from their last saved step)', file=sys.stderr)
        return 130
    finally:
        signal.signal(signal.SIGTERM, previous)
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()
    failed = [result for result in results if result['status'] != 'done']
    if failed:
        print('%d replicas did not finish:' % len(failed))
        failed.sort(key=lambda result: result['folder'])
        for result in failed[:REPORT_LIMIT]:
            print('  %s: %s: %s' % (os.path.join(plan['output_dir'], result['folder']), result['status'],
                                    result.get('message', '')))
        if len(failed) > REPORT_LIMIT:
            print('  ... and %d more (each folder\'s status.json and replica.log say why)'
                  % (len(failed) - REPORT_LIMIT))
        print('fix what the messages say and rerun the same command: finished replicas are skipped')
        return 1
    print('all %d replicas done; statistics: python %s --aggregate %s'
          % (len(plan['replicas']), os.path.relpath(os.path.abspath(__file__)), plan['output_dir']))
    return 0


def main(argv=None):
    """Command line entry; returns the exit status."""
    args = make_parser().parse_args(argv)
    if args.aggregate:
        from multi_bodies.ensembles import ensemble_statistics
        ensemble_statistics.aggregate(args.aggregate, bins=args.bins, height_range=args.height_range,
                                      max_lag=args.max_lag, discard=args.discard, charts=not args.no_charts)
        return 0
    return run(args)


if __name__ == '__main__':
    sys.exit(utils.fail_cleanly(main))
