"""One atomic save for every picture the package writes (vehicle plots, DP plots, the module's
temperature fields, co-simulation plots): :func:`save_png`."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any


def save_png(fig: Any, path: str | Path, dpi: float, **savefig_kwargs: Any) -> Path:
    """Write the matplotlib figure ``fig`` to ``path`` as PNG at ``dpi`` [dots per inch]
    atomically (to ``<name>.tmp`` beside it, then renamed: a reader never sees a half-written
    picture, and an existing one stays as it was if drawing fails) and release the figure.

    ``savefig_kwargs`` go to :meth:`matplotlib.figure.Figure.savefig` (e.g.
    ``bbox_inches="tight"``). Returns the path written."""
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = target.with_name(target.name + ".tmp")
    try:
        fig.savefig(tmp, format="png", dpi=dpi, **savefig_kwargs)
        os.replace(tmp, target)
    finally:
        tmp.unlink(missing_ok=True)
        fig.clear()
    return target
