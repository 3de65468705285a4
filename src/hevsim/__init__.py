"""hevsim: an open Python toolkit for hybrid-electric vehicle engineering.

SI units inside (s, m, kg, N, N·m, rad/s, W, J, V, A, Ω, K); conversions to mph, rpm,
gallons and BTU happen only at the edges (input files and reports).
"""

from pathlib import Path as _Path

from hevsim._numba_cache import configure_before_numba as _configure_numba_cache

__version__ = "0.1.0"

__all__ = ["__version__"]

_configure_numba_cache(_Path(__file__).resolve().parent, __version__)
