"""hevsim: an open Python toolkit for hybrid-electric vehicle engineering.

SI units inside (s, m, kg, N, N·m, rad/s, W, J, V, A, Ω, K); conversions to mph, rpm,
gallons and BTU happen only at the edges (input files and reports).
"""

from pathlib import Path as _Path

from hevsim._numba_cache import configure_before_numba as _configure_numba_cache
from hevsim.figures import provide_plotters as _provide_plotters

__version__ = "0.1.0"

__all__ = ["__version__", "simulate", "simulate_batch"]

#: The one entry point of every forward simulation (any architecture, any battery model),
#: imported on first use so that ``import hevsim`` stays light.
_LAZY = {"simulate": "hevsim.sim.simulator", "simulate_batch": "hevsim.sim.simulator"}


def __getattr__(name: str) -> object:
    """``hevsim.simulate`` and ``hevsim.simulate_batch``
    (:func:`hevsim.sim.simulator.simulate`, :func:`hevsim.sim.simulator.simulate_batch`)."""
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'hevsim' has no attribute {name!r}")


_configure_numba_cache(_Path(__file__).resolve().parent, __version__)

# The report layer draws the figures and report.md of a saved result (``result.save(out,
# plots=True)`` in sim/ and optimal/): it registers its plotters with hevsim.figures when
# imported, which the first look-up does by this name. The results thus never import report/
# (it sits above them in the layers contract), and ``import hevsim`` stays light.
_provide_plotters("hevsim.report")
