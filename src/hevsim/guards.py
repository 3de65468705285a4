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


def check_dp_memory(
    form: object,
    final_constraint: str,
    forward: str,
    store_cost_to_go: bool,
    label: str,
    available_bytes: int | None = None,
) -> dict[str, int]:
    """Refuse a vehicle DP before its stage table is built (issue 15.9).

    ``form`` is an HEV formulation (:mod:`hevsim.optimal._hev_common`). The estimate is the
    solver's (:func:`hevsim.optimal.dp.estimate_memory`: cost-to-go, level set, policy, one
    step's block) plus the SOC-invariant stage table, ``N x M x 17`` bytes (two float64
    arrays and a mask). Raises :class:`~hevsim.errors.DPSetupError` when the solver's part
    exceeds its ``memory_limit_bytes`` default (the refusal :func:`~hevsim.optimal.solve_dp`
    would give after the table) or the whole exceeds the free memory. Returns the items.
    """
    import numpy as np

    from hevsim.errors import DPSetupError
    from hevsim.optimal.dp import DEFAULT_MEMORY_LIMIT_BYTES, estimate_memory

    problem = form.dp_problem()  # type: ignore[attr-defined]
    items = estimate_memory(problem, final_constraint=final_constraint, forward=forward)
    dp_total = items.pop("total")
    n_steps = int(problem.space.n_steps)
    m_inputs = int(np.prod(form.input_shape))  # type: ignore[attr-defined]
    items["stage_table"] = n_steps * m_inputs * 17 if form.soc_invariant else 0  # type: ignore[attr-defined]
    hint = (
        "use fewer SOC or input grid points (--soc-points, --input-points) or a shorter cycle "
        f"({n_steps} steps x {int(problem.space.S)} SOC points x {m_inputs} inputs here)."
    )
    if dp_total > DEFAULT_MEMORY_LIMIT_BYTES:
        raise DPSetupError(
            f"{label}: the DP solution needs about {dp_total / MB:,.0f} MB ({format_items(items)}), "
            f"more than the solver's limit of {DEFAULT_MEMORY_LIMIT_BYTES / MB:,.0f} MB; {hint}"
        )
    total = dp_total + items["stage_table"]
    check_memory(total, f"{label}: the DP", hint, DPSetupError, items, available_bytes)
    items["total"] = total
    return items


def check_dp_size(
    label: str, n_steps: int, soc_points: int, input_points: int, available_bytes: int | None = None
) -> float:
    """A lower bound of a vehicle DP's memory [B] from its sizes alone, refused like
    :func:`check_dp_memory`: the float64 cost-to-go ``(N+1) x S x 8`` plus a stage table of
    at least ``N x input_points x 17``. For checks before anything is formulated (every
    pair of ``hevsim compare`` before the first solve)."""
    from hevsim.errors import DPSetupError
    from hevsim.optimal.dp import DEFAULT_MEMORY_LIMIT_BYTES

    items = {"cost_to_go": (n_steps + 1) * soc_points * 8.0, "stage_table": n_steps * input_points * 17.0}
    hint = (
        "use fewer SOC or input grid points (--soc-points, --input-points) or a shorter cycle "
        f"({n_steps} steps x {soc_points} SOC points x at least {input_points} inputs here)."
    )
    if items["cost_to_go"] > DEFAULT_MEMORY_LIMIT_BYTES:
        raise DPSetupError(
            f"{label}: the DP solution needs at least {items['cost_to_go'] / MB:,.0f} MB for the "
            f"cost-to-go alone, more than the solver's limit of {DEFAULT_MEMORY_LIMIT_BYTES / MB:,.0f} MB; "
            f"{hint}"
        )
    total = sum(items.values())
    check_memory(total, f"{label}: the DP", hint, DPSetupError, items, available_bytes)
    return total


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


def simulation_preflight(cfg: object, cycle: object, dt_s: float | None) -> None:
    """Before ``hevsim simulate``: refuse a run that would not fit in memory
    (:func:`check_simulation`), say what a long run will take, and warn before numba compiles
    the kernels this run uses (:func:`hevsim.warmup.run_groups`) on a cold cache."""
    from hevsim.progress import format_duration, stage

    c: object = cycle
    t = getattr(c, "time_s", None)
    dt = float(dt_s if dt_s is not None else getattr(getattr(cfg, "simulation", None), "dt_s", 0.0) or 0.0)
    if t is None or dt <= 0.0 or len(t) < 2:
        return
    n_steps = int((float(t[-1]) - float(t[0])) / dt) + 1
    label = f"{getattr(cfg, 'name', 'vehicle')} on {getattr(c, 'name', 'cycle')}"
    need, seconds = check_simulation(n_steps, label)
    if n_steps >= SIM_TALK_STEPS:
        stage(
            f"simulating {label}: {n_steps:,} steps, about {format_duration(seconds)} and {need / MB:,.0f} MB"
        )
    from hevsim.sim.forward import use_compiled
    from hevsim.warmup import compile_notice_for, run_groups

    compile_notice_for(run_groups(cfg, python_loop=not use_compiled(None)))
