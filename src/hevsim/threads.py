"""How many threads the numba-parallel kernels may use.

A parallel kernel on a busy machine is slower than a serial one: with two other processes
busy on this 2-core machine, the 2-thread Bellman kernels took 5.5 s against 1.6 s with one
thread (issue 15.8), because each parallel region waits for its slowest thread and a thread
that shares its core with another process is the slowest. The policy, in order:

1. ``--threads N`` on the command line (``option``), if given;
2. the environment variable ``HEVSIM_THREADS``, if set;
3. otherwise the cores actually free: ``os.cpu_count()`` minus the 1-minute load average of
   the other processes (:func:`os.getloadavg` less this process's own share), rounded to the
   nearest integer, at least 1; and one thread whatever the cores when the work is below
   :data:`SERIAL_BELOW_WORK`.

``N`` must be a whole number from 1 to numba's thread pool size (the number of cores unless
``NUMBA_NUM_THREADS`` says otherwise) or ``auto`` (the load-based choice).
:func:`apply_threads` hands the count to :func:`numba.set_num_threads`; the DP solver also
runs its serial kernels when the count is 1.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path

from hevsim.errors import ConfigError

THREADS_ENV = "HEVSIM_THREADS"
"""Environment variable that sets the thread count when ``--threads`` is not given."""

SERIAL_BELOW_WORK = 2_000_000
"""Work [state x input evaluations, or kernel steps x variants] below which the load-based
policy runs one thread: a parallel region costs tens of microseconds to launch per step, which
small problems never earn back [-]."""

AUTO = "auto"
"""Value of ``--threads`` / ``HEVSIM_THREADS`` asking for the load-based choice."""


@dataclass(frozen=True)
class ThreadChoice:
    """A thread count and why it was chosen (for the log line and the run's metadata)."""

    threads: int
    reason: str

    def describe(self) -> str:
        """One line such as ``"numba threads: 1 (HEVSIM_THREADS=1)"``."""
        return f"numba threads: {self.threads} ({self.reason})"


def max_threads() -> int:
    """The largest count :func:`numba.set_num_threads` accepts: numba's pool size, which is
    ``NUMBA_NUM_THREADS`` or the number of cores."""
    env = os.environ.get("NUMBA_NUM_THREADS", "").strip()
    if env.isdigit() and int(env) > 0:
        return int(env)
    return max(1, os.cpu_count() or 1)


def parse_threads(value: object, source: str, limit: int | None = None) -> int | None:
    """Validate a thread setting from ``source`` (``"--threads"`` or ``"HEVSIM_THREADS"``).

    Returns the count, or None for ``auto``. Raises :class:`~hevsim.errors.ConfigError`
    naming the source, the value and what is expected.
    """
    top = max_threads() if limit is None else limit
    text = str(value).strip()
    if text.lower() == AUTO:
        return None
    n = int(text) if text.isascii() and text.isdigit() else 0
    if not 1 <= n <= top:
        raise ConfigError(
            f"{source} = {value!r}: expected a whole number of threads from 1 to {top} "
            f"(the cores numba may use) or '{AUTO}'."
        )
    return n


LOAD_WINDOW_S = 60.0
"""Time constant of the 1-minute load average [s]."""


def own_load() -> float:
    """This process's share of the 1-minute load average [cores], estimated as its CPU time
    over the last minute: ``min(CPU seconds, 60) / 60``, at most its average CPU rate since
    it started. A fresh command (a second or two of imports) counts about 0.03; a process
    that has solved on one core for minutes counts 1. 0 where ``/proc`` is missing."""
    cpu_s = time.process_time()
    try:
        start_ticks = float(Path("/proc/self/stat").read_text().rsplit(")", 1)[1].split()[19])
        uptime_s = float(Path("/proc/uptime").read_text().split()[0])
        wall_s = uptime_s - start_ticks / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError):
        return 0.0
    if wall_s <= 0.0:
        return 0.0
    return min(min(cpu_s, LOAD_WINDOW_S) / LOAD_WINDOW_S, cpu_s / wall_s)


def free_cores(
    cpu_count: int | None = None,
    loadavg: Callable[[], tuple[float, float, float]] | None = None,
    own: float | None = None,
) -> tuple[int, float]:
    """(cores free now, load of the other processes): ``cpu_count`` minus the 1-minute load
    average less this process's own share (:func:`own_load`, or ``own``), rounded to the
    nearest integer, at least 1. Where the load average is unknown (not Unix) every core
    counts as free."""
    n = max(1, os.cpu_count() or 1) if cpu_count is None else cpu_count
    get = os.getloadavg if loadavg is None else loadavg
    try:
        load1 = float(get()[0])
    except (OSError, AttributeError):
        return n, 0.0
    others = max(0.0, load1 - (own_load() if own is None else own))
    return max(1, min(n, int(n - others + 0.5))), others


def choose_threads(
    option: object = None,
    work: float | None = None,
    env: Mapping[str, str] | None = None,
    cpu_count: int | None = None,
    loadavg: Callable[[], tuple[float, float, float]] | None = None,
    own: float | None = None,
) -> ThreadChoice:
    """The thread count by the policy of this module (see the module docstring).

    ``option`` is the ``--threads`` value (None when not given), ``work`` the size of the
    coming parallel work in :data:`SERIAL_BELOW_WORK` units (None when unknown: no serial
    threshold), ``env`` the environment (default :data:`os.environ`). ``cpu_count`` and
    ``loadavg`` replace :func:`os.cpu_count` and :func:`os.getloadavg`, ``own`` this
    process's share of the load (for tests).
    """
    environ = os.environ if env is None else env
    limit = max_threads() if cpu_count is None else cpu_count
    if option is not None:
        n = parse_threads(option, "--threads", limit)
        if n is not None:
            return ThreadChoice(n, "--threads")
    elif environ.get(THREADS_ENV, "").strip():
        n = parse_threads(environ[THREADS_ENV], THREADS_ENV, limit)
        if n is not None:
            return ThreadChoice(n, f"{THREADS_ENV}={n}")
    if work is not None and work < SERIAL_BELOW_WORK:
        return ThreadChoice(1, f"small problem: {work:.3g} < {SERIAL_BELOW_WORK:.3g} evaluations")
    free, others = free_cores(limit, loadavg, own)
    return ThreadChoice(free, f"{limit} cores, load of other processes {others:.2f}")


def apply_threads(option: object = None, work: float | None = None) -> ThreadChoice:
    """Choose the thread count (:func:`choose_threads`) and hand it to numba."""
    choice = choose_threads(option, work)
    import numba

    numba.set_num_threads(min(choice.threads, int(numba.config.NUMBA_NUM_THREADS)))  # type: ignore[attr-defined]
    return choice


def current_threads() -> int:
    """The thread count numba's parallel kernels use now."""
    import numba

    return int(numba.get_num_threads())
