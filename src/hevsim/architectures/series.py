"""Series hybrid-electric vehicle (thesis Fig. 2.3): engine-generator genset on a DC bus with
the battery, the traction motor through the final drive to the wheels.

Its model is :class:`hevsim.sim.model.SeriesHEV` (built by
:func:`hevsim.sim.model.build_series_hev`); its forward step is the compiled kernel
:func:`hevsim.sim.kernel.run_series` (driver -> genset supervisor -> genset shaft -> bus
balance :mod:`hevsim.components.bus` -> vehicle), and its DP formulation
:class:`hevsim.optimal._series_dp.SeriesFormulation` calls the same bus balance
(:func:`hevsim.optimal._hev_common.electric_flow`) over the grid. Controls: genset state and
engine throttle (forward), genset electrical power on the engine's optimal line (DP).
Controllers: ``"thermostat"`` (rule-based) and ``"schedule"`` (replay, e.g. of a DP optimum).
"""

from __future__ import annotations

from hevsim.sim.kernel import run_series, run_series_batch
from hevsim.sim.model import SeriesHEV, build_series_hev

ARCHITECTURE = "series"
CONTROLS: tuple[str, ...] = ("genset_state", "engine_throttle")

__all__ = ["ARCHITECTURE", "CONTROLS", "SeriesHEV", "build_series_hev", "run_series", "run_series_batch"]
