"""Optimal control: a generic dynamic-programming solver (``solve_dp``) and its problem types.

See ``docs/dp.md`` for a tutorial and the choice of final-state constraint method.
"""

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
    "FINAL_CONSTRAINTS",
    "FORWARD_MODES",
    "DPProblem",
    "DPResult",
    "FinalTarget",
    "Increment",
    "estimate_memory",
    "solve_dp",
]
