"""Tell a person what long work is doing: a bar on a terminal, one line per stage otherwise.

Everything goes to standard error, so standard output keeps only results.

* :func:`stage` prints one line (``hevsim: meshing ...``).
* :func:`task` wraps a loop of known length: on a terminal a tqdm bar with rate and ETA; on a
  pipe or a log file one line at the start, at most one line per :data:`LOG_EVERY_S` with the
  ETA while it runs, and one line with the elapsed time at the end. Short loops stay silent
  until the end line.
* :func:`compile_notice` warns once per process before numba compiles kernels whose on-disk
  cache is missing or older than their source ("compiling kernels, once: about 20 s");
  :mod:`hevsim.warmup` says which kernels a run needs and how long they take.

``HEVSIM_PROGRESS=0`` silences all of it (``1`` forces lines even where they would be
skipped); the library stays quiet unless a caller asks for progress.
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from typing import IO, Any

PROGRESS_ENV = "HEVSIM_PROGRESS"
"""Environment variable: ``0`` silences progress output."""

LOG_EVERY_S = 30.0
"""Shortest interval between two progress lines of one task when not on a terminal [s]."""

PREFIX = "hevsim: "

_noticed: set[str] = set()


def enabled() -> bool:
    """False when ``HEVSIM_PROGRESS=0``."""
    return os.environ.get(PROGRESS_ENV, "1").strip() not in ("0", "false", "no", "off")


def _stream(stream: IO[str] | None) -> IO[str]:
    return sys.stderr if stream is None else stream


def is_terminal(stream: IO[str] | None = None) -> bool:
    """True when ``stream`` (default stderr) is a terminal."""
    isatty = getattr(_stream(stream), "isatty", None)
    return bool(isatty and isatty())


def stage(message: str, stream: IO[str] | None = None) -> None:
    """Print one stage line to stderr (unless silenced)."""
    if enabled():
        out = _stream(stream)
        print(PREFIX + message, file=out, flush=True)


def format_duration(seconds: float) -> str:
    """``"42 s"``, ``"3 min 05 s"`` or ``"1 h 02 min"``."""
    s = max(0.0, float(seconds))
    if s < 60.0:
        return f"{s:.0f} s" if s >= 10.0 else f"{s:.1f} s"
    if s < 3600.0:
        return f"{int(s // 60)} min {int(s % 60):02d} s"
    return f"{int(s // 3600)} h {int(s % 3600 // 60):02d} min"


class Task:
    """Progress of one loop of ``total`` units; call :meth:`update` after each unit."""

    def __init__(
        self, label: str, total: int, unit: str, stream: IO[str] | None, bar: bool | None, show: bool = True
    ) -> None:
        self.label = label
        self.total = max(0, int(total))
        self.unit = unit
        self.stream = _stream(stream)
        self.on = enabled() and show
        self.done = 0
        self.t0 = time.perf_counter()
        self._last_line = self.t0
        self._bar: Any = None
        use_bar = is_terminal(self.stream) if bar is None else bar
        if self.on and use_bar:
            from tqdm import tqdm

            self._bar = tqdm(total=self.total, desc=PREFIX + label, unit=unit, file=self.stream, leave=False)
        elif self.on:
            stage(f"{label}: {self.total} {unit}s ...", self.stream)

    def eta_s(self) -> float | None:
        """Seconds left at the average rate so far (None before the first unit)."""
        if self.done <= 0:
            return None
        spent = time.perf_counter() - self.t0
        return spent / self.done * (self.total - self.done)

    def update(self, n: int = 1) -> None:
        """Count ``n`` more units done."""
        self.done += n
        if not self.on:
            return
        if self._bar is not None:
            self._bar.update(n)
            return
        now = time.perf_counter()
        if now - self._last_line >= LOG_EVERY_S and self.done < self.total:
            self._last_line = now
            eta = self.eta_s()
            pct = 100.0 * self.done / self.total if self.total else 100.0
            left = f", about {format_duration(eta)} left" if eta is not None else ""
            stage(f"{self.label}: {self.done}/{self.total} {self.unit}s ({pct:.0f} %){left}", self.stream)

    def close(self) -> None:
        """Finish: close the bar and print the end line."""
        if self._bar is not None:
            self._bar.close()
            self._bar = None
        if self.on:
            took = format_duration(time.perf_counter() - self.t0)
            stage(f"{self.label}: done, {self.done} {self.unit}s in {took}", self.stream)
        self.on = False


@contextmanager
def task(
    label: str,
    total: int,
    unit: str = "step",
    stream: IO[str] | None = None,
    bar: bool | None = None,
    show: bool = True,
) -> Iterator[Task]:
    """A :class:`Task` closed on exit (also on an exception, without the end line); ``bar``
    None = a bar only on a terminal; ``show`` False = silent (counting only)."""
    t = Task(label, total, unit, stream, bar, show)
    try:
        yield t
    except BaseException:
        if t._bar is not None:
            t._bar.close()
        t.on = False
        raise
    t.close()


@contextmanager
def timed_stage(label: str, stream: IO[str] | None = None) -> Iterator[None]:
    """A stage line before the block and ``label: done in X s`` after it."""
    stage(f"{label} ...", stream)
    t0 = time.perf_counter()
    yield
    stage(f"{label}: done in {format_duration(time.perf_counter() - t0)}", stream)


def cache_is_cold(dispatchers: Sequence[Any]) -> bool:
    """True when the next calls of these numba dispatchers (``cache=True``) will compile
    rather than load: an on-disk index written for another version of its source (or
    damaged), or no index at all for any of them (a fresh install). A dispatcher that alone
    has no index file was never compiled on its own (an ``inline="always"`` helper, or a
    kernel no run has needed yet) and says nothing about the others. Unknown cases (no
    cache, a numba without this layout) count as warm."""
    known = usable = 0
    for d in dispatchers:
        cache_file = getattr(getattr(d, "_cache", None), "_cache_file", None)
        load_index = getattr(cache_file, "_load_index", None)
        if load_index is None:
            continue
        known += 1
        index_path = getattr(cache_file, "_index_path", None)
        if index_path is not None and not os.path.exists(index_path):
            continue
        try:
            if not load_index():
                return True
        except Exception:  # a damaged index: numba recompiles too
            return True
        usable += 1
    return known > 0 and usable == 0


def compile_notice(
    what: str,
    dispatchers: Sequence[Any],
    seconds: float = 20.0,
    stream: IO[str] | None = None,
    hint: str = "",
) -> bool:
    """Print ``compiling <what> kernels, once: about <seconds>`` (:func:`format_duration`)
    when the numba cache of ``dispatchers`` is cold, once per process and ``what``; ``hint``
    ends the parenthesis. Return whether it printed."""
    if what in _noticed or not cache_is_cold(dispatchers):
        return False
    _noticed.add(what)
    stage(
        f"compiling {what} kernels, once: about {format_duration(seconds)} "
        f"(later runs load them from the cache{hint})",
        stream,
    )
    return True


def module_dispatchers(module: Any, names: Sequence[str] | None = None) -> list[Any]:
    """The numba dispatchers among ``module``'s attributes (or the ``names`` given)."""
    from numba.core.dispatcher import Dispatcher

    keys = names if names is not None else sorted(vars(module))
    return [getattr(module, k) for k in keys if isinstance(getattr(module, k, None), Dispatcher)]
