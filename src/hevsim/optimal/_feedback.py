"""What a vehicle DP does before it works: refuse early, choose threads, say what is coming.

:func:`hevsim.optimal.hev.optimize` calls :func:`dp_feedback` right after formulating the
problem and before building its stage table, so that a DP too large for the machine is
refused in about a second (it used to be refused after 265 s of table building, issue 15.9),
the kernels follow the thread policy of :mod:`hevsim.threads` (issue 15.8) and a person
sees the problem size, the thread count, a first-compile notice and the table-building stage.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from hevsim.guards import MB, check_memory, format_items
from hevsim.threads import ThreadChoice, apply_threads

STAGE_LINES_MIN_PAIRS = 2_000_000
"""Steps x input combinations from which :func:`hevsim.optimal.hev.optimize` prints its
stage lines (unless ``progress=False``): about a second of table building [-]."""


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


@dataclass
class DPFeedback:
    """The outcome of :func:`dp_feedback`: the thread choice and whether to talk."""

    threads: ThreadChoice
    talk: bool
    memory_bytes: dict[str, int]

    @contextlib.contextmanager
    def timed(self, label: str) -> Iterator[None]:
        """A stage line before and after the block when talking; nothing otherwise."""
        if not self.talk:
            yield
            return
        from hevsim.progress import timed_stage

        with timed_stage(label):
            yield


def dp_feedback(
    form: Any,
    hev: Any,
    cycle: Any,
    final_constraint: str,
    forward: str,
    store_cost_to_go: bool,
    threads: object,
    progress: bool | None,
) -> DPFeedback:
    """Check memory (:func:`check_dp_memory`), apply the thread policy and,
    for large problems unless ``progress`` is False, print the problem line and the
    first-compile notice. Raises :class:`~hevsim.errors.DPSetupError` (memory) or
    :class:`~hevsim.errors.ConfigError` (a bad ``threads`` value) before any heavy work."""
    name = getattr(getattr(hev, "config", None), "name", None) or getattr(hev, "name", "vehicle")
    label = f"{name} on {getattr(cycle, 'name', cycle)}"
    mem = check_dp_memory(form, final_constraint, forward, store_cost_to_go, label)
    pairs = int(form.steps.n_steps) * int(np.prod(form.input_shape))
    choice = apply_threads(threads, work=float(pairs) * form.soc_grid.size)
    talk = progress is not False and pairs >= STAGE_LINES_MIN_PAIRS
    if talk:
        from hevsim.kernel_groups import compile_notice_for, group
        from hevsim.progress import stage

        stage(
            f"DP of {label}: {form.steps.n_steps} steps x {form.soc_grid.size} SOC points x "
            f"{form.input_description()} inputs, about {mem['total'] / 1e6:,.0f} MB; {choice.describe()}"
        )
        # probed without importing the kernels (importing them compiles them at once)
        compile_notice_for([group("dp")])
    return DPFeedback(choice, talk, mem)
