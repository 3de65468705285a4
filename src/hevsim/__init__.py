"""hevsim: an open Python toolkit for hybrid-electric vehicle engineering.

SI units inside (s, m, kg, N, N·m, rad/s, W, J, V, A, Ω, K); conversions to mph, rpm,
gallons and BTU happen only at the edges (input files and reports).
"""

__version__ = "0.1.0"

__all__ = ["__version__"]
