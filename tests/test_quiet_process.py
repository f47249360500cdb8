"""benchmarks/quiet_process.py: the side-by-side benchmarks wait, between one code's step and the other's, until
the process that stepped uses no CPU.  Checked without timing anything: the loop on a scripted sequence of CPU
readings, and the /proc reading of this process."""
import os
import sys

import pytest

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), 'benchmarks'))
import quiet_process  # noqa: E402


def scripted(readings):
    """A cpu_seconds(pid) that returns ``readings`` in turn (the last one from then on); counts its calls."""
    calls = []

    def read(pid):
        calls.append(pid)
        return readings[min(len(calls) - 1, len(readings) - 1)]
    return read, calls


def test_returns_at_the_first_interval_without_cpu():
    read, calls = scripted([1.00, 1.01, 1.02, 1.02, 1.50])
    waited, idle = quiet_process.wait_until_idle(7, interval=0.0, limit=60.0, cpu_seconds=read)
    assert idle
    assert len(calls) == 4          # the first reading, two busy intervals, the idle one; not the 1.50 after it
    assert all(pid == 7 for pid in calls)


def test_a_process_that_never_rests_is_left_after_the_limit():
    counter = iter(range(10 ** 9))
    waited, idle = quiet_process.wait_until_idle(7, interval=0.001, limit=0.05,
                                                 cpu_seconds=lambda pid: float(next(counter)))
    assert not idle and waited >= 0.05


def test_unknown_cpu_time_sleeps_the_fallback():
    waited, idle = quiet_process.wait_until_idle(7, fallback=0.0, cpu_seconds=lambda pid: None)
    assert (waited, idle) == (0.0, False)


@pytest.mark.skipif(not os.path.isdir('/proc/self/task'), reason='no /proc here (Linux only)')
def test_reads_this_process_cpu_time():
    first = quiet_process.process_cpu_seconds(os.getpid())
    total = 0
    for k in range(3 * 10 ** 6):   # some CPU work: the reading must not go down
        total += k
    second = quiet_process.process_cpu_seconds(os.getpid())
    times = os.times()
    assert total > 0 and first is not None and second >= first > 0.0
    # the same clock as the process's own user + system time, to a few clock ticks
    assert abs(second - (times.user + times.system)) <= 0.05
