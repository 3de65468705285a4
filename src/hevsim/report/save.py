"""One atomic save for every picture the package writes (vehicle plots, DP plots, the module's
temperature fields, co-simulation plots): :func:`save_png`, which lives in :mod:`hevsim.io`
(the ground layer: the battery and thermal modules save pictures too) and is re-exported here."""

from __future__ import annotations

from hevsim.io import save_png

__all__ = ["save_png"]
