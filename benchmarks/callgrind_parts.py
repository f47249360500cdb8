"""The instruction totals of the parts of a callgrind run (shared by the ``count_*`` benchmarks).

A benchmark run under ``valgrind --tool=callgrind --dump-before=getppid --callgrind-out-file=OUT`` calls
``os.getppid()`` between its phases, so callgrind writes one file per phase (``OUT``, ``OUT.1``, ...), each
headed ``part: k`` and closed by ``summary:`` (or ``totals:``) with its instruction count.
"""
import glob
import re


def part_totals(out):
    """The instruction totals of the parts written under the prefix ``out``, in part order (list of int)."""
    parts = {}
    for name in glob.glob(out + '*'):
        with open(name) as f:
            text = f.read()
        part = re.search(r'^part: (\d+)', text, re.M)
        total = re.search(r'^(?:summary|totals): (\d+)', text, re.M)
        parts[int(part.group(1)) if part else 0] = int(total.group(1))
    return [parts[k] for k in sorted(parts)]
