"""Figures (ground layer): the Agg figure helpers every picture of the package uses, and the
registry of the plotters that draw a saved result's figures.

:func:`figure`, :func:`grid` and :func:`save` build a matplotlib figure without pyplot (no
global backend, no figure registry: safe on headless machines and inside interactive
sessions), draw major grid lines and write the PNG atomically. They know no physics, so any
layer may draw with them (the vehicle reports, the life of a pack, the ageing of a cell, the
co-simulation pictures).

A result of a lower layer saves its figures through a **plotter**, a function ``(result,
folder) -> paths`` looked up by kind (:func:`plotter`): ``SimulationResult.save(plots=True)``
asks for ``"simulation"``, ``OptimizationResult.save(plots=True)`` for ``"optimum"``. The
report layer (:mod:`hevsim.report`, above ``sim/`` and ``optimal/``) registers them with
:func:`register_plotter` when it is imported, and the package root names it as the module
that provides plotters (:func:`provide_plotters`), imported on the first look-up: so
``sim/`` and ``optimal/`` save plots without importing ``report/`` (the layers contract in
``pyproject.toml``), and ``import hevsim`` imports neither.

This module imports only the standard library (matplotlib inside the functions).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

DPI = 120
"""Resolution of every PNG [dots per inch]."""

Plotter = Callable[[Any, Path], Sequence[Path]]
"""Draws a result's figures (and report) into a folder; returns the files written."""

_PLOTTERS: dict[str, Plotter] = {}
_PROVIDERS: list[str] = []


def figure(
    nrows: int = 1,
    ncols: int = 1,
    margins_in: tuple[float, float, float, float] | None = None,
    **kwargs: Any,
) -> tuple[Figure, Any]:
    """A new Agg-backed figure and its axes (no pyplot).

    With ``margins_in`` = (left, bottom, right, top) [in] the axes get fixed margins and
    ``wspace``/``hspace`` from ``kwargs`` (default 0.25): no layout engine runs at save time.
    Without it the figure uses matplotlib's constrained layout, which fits any labels but
    measures every text twice (about half the drawing time of a simple figure).
    Titles sit at a fixed height above the axes (no tick labels on top), which spares
    matplotlib a bounding-box pass per axes. ``figsize`` [in] defaults to (10, 6); the other
    ``kwargs`` go to ``Figure.subplots`` (``sharex``, ``squeeze``, ``height_ratios``...).
    """
    import matplotlib as mpl
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    figsize = kwargs.pop("figsize", (10.0, 6.0))
    wspace = kwargs.pop("wspace", 0.25)
    hspace = kwargs.pop("hspace", 0.25)
    with mpl.rc_context({"axes.titley": 1.0}):
        if margins_in is None:
            fig = Figure(figsize=figsize, dpi=DPI, layout="constrained")
        else:
            w, h = figsize
            left, bottom, right, top = margins_in
            fig = Figure(figsize=figsize, dpi=DPI)
            fig.subplots_adjust(
                left=left / w, bottom=bottom / h, right=1.0 - right / w, top=1.0 - top / h,
                wspace=wspace, hspace=hspace,
            )  # fmt: skip
        FigureCanvasAgg(fig)
        axes = fig.subplots(nrows, ncols, **kwargs)
    return fig, axes


def grid(ax: Axes) -> None:
    """Major grid lines only: minor ticks cost matplotlib a tick object each, about a fifth
    of the drawing time of a time-series figure."""
    ax.grid(True, which="major", alpha=0.4)


def save(fig: Figure, path: str | Path) -> Path:
    """Write ``fig`` to ``path`` as PNG at :data:`DPI` atomically and release it
    (:func:`hevsim.io.save_png`); return the path."""
    from hevsim.io import save_png

    return save_png(fig, path, DPI)


def register_plotter(kind: str, fn: Plotter) -> None:
    """Make ``fn`` the plotter of results of ``kind`` (a later registration replaces it)."""
    _PLOTTERS[kind] = fn


def provide_plotters(module: str) -> None:
    """Name ``module`` as one that registers plotters when imported; :func:`plotter` imports it
    on the first look-up of a kind not registered yet."""
    if module not in _PROVIDERS:
        _PROVIDERS.append(module)


def plotter(kind: str) -> Plotter:
    """The plotter registered for ``kind``, importing the providing modules first if needed.

    Raises ``LookupError`` naming the kinds known when none provides ``kind``."""
    if kind not in _PLOTTERS:
        for module in _PROVIDERS:
            importlib.import_module(module)
    try:
        return _PLOTTERS[kind]
    except KeyError:
        raise LookupError(
            f"no plotter registered for results of kind {kind!r}; known: {sorted(_PLOTTERS)} "
            f"(modules providing plotters: {_PROVIDERS})"
        ) from None


__all__ = ["DPI", "Plotter", "figure", "grid", "plotter", "provide_plotters", "register_plotter", "save"]
