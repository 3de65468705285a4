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

from hevsim.threads import ThreadChoice, apply_threads

STAGE_LINES_MIN_PAIRS = 2_000_000
"""Steps x input combinations from which :func:`hevsim.optimal.hev.optimize` prints its
stage lines (unless ``progress=False``): about a second of table building [-]."""


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
    """Check memory (:func:`hevsim.guards.check_dp_memory`), apply the thread policy and,
    for large problems unless ``progress`` is False, print the problem line and the
    first-compile notice. Raises :class:`~hevsim.errors.DPSetupError` (memory) or
    :class:`~hevsim.errors.ConfigError` (a bad ``threads`` value) before any heavy work."""
    from hevsim.guards import check_dp_memory

    name = getattr(getattr(hev, "config", None), "name", None) or getattr(hev, "name", "vehicle")
    label = f"{name} on {getattr(cycle, 'name', cycle)}"
    mem = check_dp_memory(form, final_constraint, forward, store_cost_to_go, label)
    pairs = int(form.steps.n_steps) * int(np.prod(form.input_shape))
    choice = apply_threads(threads, work=float(pairs) * form.soc_grid.size)
    talk = progress is not False and pairs >= STAGE_LINES_MIN_PAIRS
    if talk:
        from hevsim.progress import stage
        from hevsim.warmup import compile_notice_for, group

        stage(
            f"DP of {label}: {form.steps.n_steps} steps x {form.soc_grid.size} SOC points x "
            f"{form.input_description()} inputs, about {mem['total'] / 1e6:,.0f} MB; {choice.describe()}"
        )
        # probed without importing the kernels (importing them compiles them at once)
        compile_notice_for([group("dp")])
    return DPFeedback(choice, talk, mem)
