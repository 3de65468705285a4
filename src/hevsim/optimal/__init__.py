"""Optimal control: a generic dynamic-programming solver (``solve_dp``) and its problem types,
and the HEV energy-management formulations built on it (``optimize``).

See ``docs/dp.md`` for a tutorial and the choice of final-state constraint method.
"""

from typing import Any

from hevsim.optimal.dp import (
    FINAL_CONSTRAINTS,
    FORWARD_MODES,
    DPProblem,
    DPResult,
    FinalTarget,
    Increment,
    estimate_memory,
    solve_dp,
)

__all__ = [
    "ARCHITECTURES",
    "FINAL_CONSTRAINTS",
    "FORWARD_MODES",
    "DPProblem",
    "DPResult",
    "FinalTarget",
    "Increment",
    "OptimizationResult",
    "estimate_memory",
    "optimize",
    "solve_dp",
]

_HEV_NAMES = ("ARCHITECTURES", "OptimizationResult", "optimize")


def __getattr__(name: str) -> Any:
    """``optimize``, ``OptimizationResult`` and ``ARCHITECTURES`` are imported on first use
    (they pull in the vehicle models, pandas and the configuration loaders)."""
    if name in _HEV_NAMES:
        from hevsim.optimal import hev

        return getattr(hev, name)
    raise AttributeError(f"module 'hevsim.optimal' has no attribute {name!r}")
