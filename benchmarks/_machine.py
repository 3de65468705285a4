"""Shared helpers of the benchmark scripts: how busy the rest of the machine was, and the
median time of repeated calls."""

from __future__ import annotations

import os
import statistics
import time
from collections.abc import Callable
from pathlib import Path


def median_time(fn: Callable[[], object], repeats: int, warm: bool = False) -> float:
    """Median wall time [s] of ``repeats`` calls of ``fn`` (``warm``: one uncounted call first)."""
    if warm:
        fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def machine_busy_s() -> float | None:
    """CPU seconds all processes on this machine have been busy (Linux /proc/stat)."""
    try:
        vals = [int(x) for x in Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:9]]
    except (OSError, ValueError):
        return None
    return (sum(vals) - vals[3] - vals[4]) / os.sysconf("SC_CLK_TCK")


class OtherLoad:
    """Average number of cores used by *other* processes while the block runs."""

    def __enter__(self) -> OtherLoad:
        self.busy0, self.cpu0, self.t0 = machine_busy_s(), time.process_time(), time.perf_counter()
        self.cores: float | None = None
        return self

    def __exit__(self, *exc: object) -> None:
        busy1, cpu1, t1 = machine_busy_s(), time.process_time(), time.perf_counter()
        if self.busy0 is not None and busy1 is not None and t1 > self.t0:
            others = (busy1 - self.busy0) - (cpu1 - self.cpu0)
            self.cores = max(0.0, others / (t1 - self.t0))

    def text(self) -> str:
        if self.cores is None:
            return "other processes' load: n/a"
        warn = " - timings are skewed, rerun on an idle machine" if self.cores > 0.25 else ""
        return f"other processes used {self.cores:.2f} cores meanwhile{warn}"
