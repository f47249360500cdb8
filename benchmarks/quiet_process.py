"""Wait until a process has stopped using the CPU: for the side-by-side benchmarks, between one code's step and
the other's.

Why: the published code's numba kernels run in GNU OpenMP threads (numba's ``omp`` threading layer), and with
``OMP_WAIT_POLICY`` unset those threads keep spinning for a while after a parallel loop ends (measured here:
about 20 ms of CPU after each published Adams-Bashforth step of 100 boomerangs, while the process waits for its
next order).  A step of the other code that starts at once shares the cores with that spin, and with two cores
its second thread gets none: the package's two-thread Adams-Bashforth step measured 22 ms side by side against
13 ms alone.  Waiting until the process that just stepped is idle gives each step the machine to itself, which
is what each code has in a run of its own (there the spinning threads pick up the next step's work).

    from quiet_process import wait_until_idle
    wait_until_idle(worker.process.pid)

Linux only (``/proc/<pid>/task/*/stat``); elsewhere it sleeps ``fallback`` seconds.
"""
import os
import time


def process_cpu_seconds(pid):
    """CPU seconds (user + system, all threads) used so far by process ``pid``, or None where /proc is absent."""
    try:
        with open('/proc/%d/stat' % pid) as f:
            fields = f.read().rsplit(')', 1)[1].split()
    except OSError:
        return None
    # fields after the command name: state is field 3 of stat(5), utime 14 and stime 15
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def wait_until_idle(pid, interval=0.03, limit=2.0, fallback=0.2, cpu_seconds=process_cpu_seconds):
    """Return once process ``pid`` used no CPU over one ``interval`` (s), or after ``limit`` s.

    The kernel counts CPU time in clock ticks (10 ms on most systems), so an interval of a few ticks with no
    increase means the process's threads are asleep.  ``cpu_seconds(pid)``: the reading of the process's CPU
    time (None: unknown).  Returns (seconds waited, whether the process was seen idle).
    """
    start = time.perf_counter()
    before = cpu_seconds(pid)
    if before is None:
        time.sleep(fallback)
        return fallback, False
    while time.perf_counter() - start < limit:
        time.sleep(interval)
        now = cpu_seconds(pid)
        if now is None:
            break
        if now == before:
            return time.perf_counter() - start, True
        before = now
    return time.perf_counter() - start, False
