"""How fast this machine runs Python, so that speed figures of different machines compare.

The project's machines differ by up to twice in speed from one session to the next (a
pure-Python loop of 10 million additions 0.77 s on the forty-third session's, 1.46 s on the
thirty-third's; the chain 9.5 against 15-24 ms per 3,600 samples): a time printed without
the machine's own is not comparable to another session's. The speed benchmarks print it.
"""

from __future__ import annotations

import statistics
import time

ADDITIONS = 10_000_000


LOOP = f"total = 0\nfor i in range({ADDITIONS}):\n    total += i\n"
"""The loop as ``python -c`` runs it, in module scope (global names): the earlier sessions'
figures were read so. Inside a function, with local names, it takes about 2.5 times less."""


def additions_seconds(repeat: int = 3) -> float:
    """The median wall time (s) of ``repeat`` runs of ``LOOP``."""
    code = compile(LOOP, "<additions>", "exec")
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        exec(code, {})  # the fixed loop above: nothing read from outside
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def machine_line() -> str:
    """The line the speed benchmarks print first."""
    return (
        f"machine: a pure-Python loop of 10 million additions {additions_seconds():.2f} s "
        "(0.77 s on the forty-third session's machine, 1.46 s on the thirty-third's)"
    )
