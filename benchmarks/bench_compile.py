"""Cold compile time of each kernel group (hevsim.warmup.GROUPS), for its ``cold_compile_s``.

Each group's warm-up runs in a fresh process on its own empty numba cache (so no group
profits from another's kernels), then once more on the now-filled cache (the load time).
Prints wall and CPU seconds of the child process [s] and the registry's figure; the CPU time
is the figure to keep (the wall time grows with the machine's load, printed too).

    .venv/bin/python benchmarks/bench_compile.py [GROUP ...]
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
import tempfile
import time

from _machine import machine_busy_s
from hevsim.warmup import GROUPS, examples_dir, group


def _child(name: str, cache: str) -> tuple[float, float, float]:
    """(wall [s], CPU [s], cores the other processes used meanwhile) of one warm-up of group
    ``name`` in a fresh process on ``cache``."""
    env = {**os.environ, "NUMBA_CACHE_DIR": cache, "HEVSIM_PROGRESS": "0"}
    code = (
        f"from hevsim.warmup import warm_group; r = warm_group({name!r}, {str(examples_dir())!r}); "
        "assert not r.error, r"
    )
    before, busy0 = resource.getrusage(resource.RUSAGE_CHILDREN), machine_busy_s()
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-c", code], env=env, check=True)
    wall = time.perf_counter() - t0
    after, busy1 = resource.getrusage(resource.RUSAGE_CHILDREN), machine_busy_s()
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    others = (busy1 - busy0 - cpu) / wall if busy0 is not None and busy1 is not None else float("nan")
    return wall, cpu, max(0.0, others)


def main(names: list[str]) -> None:
    print(f"load average {os.getloadavg()[0]:.2f}")
    print(
        f"{'group':<13}{'cold wall':>10}{'cold CPU':>10}{'warm wall':>10}{'warm CPU':>10}{'registry':>10}"
        f"{'others':>8}  [s, others: cores used by other processes]"
    )
    for g in [group(n) for n in names] if names else GROUPS:
        with tempfile.TemporaryDirectory(prefix="hevsim-bench-compile-") as cache:
            cold = _child(g.name, cache)
            warm = _child(g.name, cache)
        print(
            f"{g.name:<13}{cold[0]:>10.1f}{cold[1]:>10.1f}{warm[0]:>10.1f}{warm[1]:>10.1f}"
            f"{g.cold_compile_s:>10.0f}{cold[2]:>8.2f}",
            flush=True,
        )
    print(f"load average {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main(sys.argv[1:])
