"""Refuse heavy work the machine cannot hold, before starting it.

A refusal names the estimate, the memory the machine has free (``MemAvailable`` of
``/proc/meminfo``) and what to change. Estimates are deliberately simple formulas with
their calibration stated next to them; they only need to be right within a factor of two to
turn "runs 10 minutes then dies" into "refused in a second".
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

from hevsim.errors import HevsimError

MEMINFO = Path("/proc/meminfo")
"""Where Linux reports the memory available to new work."""

USABLE_FRACTION = 0.9
"""Share of ``MemAvailable`` a run may plan to use [-] (the rest stays for the page cache
and the other processes' growth)."""

MB = 1e6
"""Bytes in a megabyte (decimal, as printed) [B]."""


def mem_available_bytes(meminfo: Path | str = MEMINFO) -> int | None:
    """``MemAvailable`` [bytes] from ``/proc/meminfo``, or None where it is unknown."""
    try:
        text = Path(meminfo).read_text()
    except OSError:
        return None
    for line in text.splitlines():
        if line.startswith("MemAvailable:"):
            parts = line.split()
            try:
                return int(parts[1]) * (1024 if parts[-1].lower() == "kb" else 1)
            except (IndexError, ValueError):
                return None
    return None


def format_items(items: Mapping[str, float]) -> str:
    """``"cost_to_go 12.3 MB, table 4.0 MB"`` (zero items left out)."""
    return ", ".join(f"{k} {v / MB:.1f} MB" for k, v in items.items() if v)


def check_memory(
    need_bytes: float,
    what: str,
    hint: str,
    error: type[HevsimError],
    items: Mapping[str, float] | None = None,
    available_bytes: int | None = None,
    meminfo: Path | str = MEMINFO,
) -> None:
    """Raise ``error`` when ``need_bytes`` exceeds :data:`USABLE_FRACTION` of the free memory.

    ``what`` names the work (``"the thermal mesh of module.toml (mesh_size_m = 0.001)"``),
    ``hint`` says what to change, ``items`` break the estimate down. ``available_bytes``
    replaces the reading of ``meminfo`` (tests). Where free memory is unknown, nothing is
    checked.
    """
    free = mem_available_bytes(meminfo) if available_bytes is None else available_bytes
    if free is None or need_bytes <= USABLE_FRACTION * free:
        return
    detail = f" ({format_items(items)})" if items else ""
    raise error(
        f"{what} needs about {need_bytes / MB:,.0f} MB{detail}, more than the "
        f"{USABLE_FRACTION * free / MB:,.0f} MB this machine has free ({100 * USABLE_FRACTION:.0f} % of "
        f"MemAvailable {free / MB:,.0f} MB); {hint}"
    )


SIM_BYTES_PER_STEP = 1000.0
"""Memory of a forward simulation per recorded step [B]: 630 B measured (peak RSS growth
of a 1 000 000-step series-HEV run: kernel outputs, the 37-column time series, events,
metrics), with headroom."""
SIM_SECONDS_PER_STEP = 30e-6
"""Time of a forward simulation and its Parquet file per step [s]: 23 + 7 µs measured for
1 000 000 steps on the 2-core reference machine under load (about 8 busy processes)."""
SIM_TALK_STEPS = 200_000
"""Steps from which ``hevsim simulate`` prints what it is about to do [-] (about 6 s)."""


def check_simulation(n_steps: int, label: str, available_bytes: int | None = None) -> tuple[float, float]:
    """(memory [B], time [s]) of a forward simulation of ``n_steps`` steps; raises
    :class:`~hevsim.errors.SimulationError` when it would not fit in the free memory."""
    from hevsim.errors import SimulationError

    need = SIM_BYTES_PER_STEP * n_steps
    check_memory(
        need,
        f"{label}: a simulation of {n_steps:,} steps",
        "use a larger time step (--dt) or a shorter cycle.",
        SimulationError,
        available_bytes=available_bytes,
    )
    return need, SIM_SECONDS_PER_STEP * n_steps
