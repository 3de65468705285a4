"""Design-space studies: sample a vehicle's parameters, run every case on Dask, analyse.

``run_study(path_or_study, out)`` runs a study file (``docs/studies.md``) and returns one row
per case; ``study_report(out)`` writes Pareto fronts, a sensitivity ranking, scatter matrices
and a Markdown report. Nothing here knows physics: cases go through the solvers of
:mod:`hevsim.studies.solvers` (``simulate``, ``optimize``; :func:`register_solver` adds more).
Dask is imported only when a study runs on it.
"""

from __future__ import annotations

from typing import Any

__all__ = [
    "SOLVERS",
    "Study",
    "StudyError",
    "load_study",
    "read_results",
    "register_solver",
    "run_study",
    "study_report",
]

_WHERE = {
    "SOLVERS": "hevsim.studies.solvers",
    "register_solver": "hevsim.studies.solvers",
    "Study": "hevsim.studies.spec",
    "StudyError": "hevsim.studies.spec",
    "load_study": "hevsim.studies.spec",
    "read_results": "hevsim.studies.runner",
    "run_study": "hevsim.studies.runner",
    "study_report": "hevsim.studies.report",
}


def __getattr__(name: str) -> Any:
    """Import the public names on first use (no work at import time)."""
    if name in _WHERE:
        import importlib

        return getattr(importlib.import_module(_WHERE[name]), name)
    raise AttributeError(f"module 'hevsim.studies' has no attribute {name!r}")
