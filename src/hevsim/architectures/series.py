"""Series hybrid-electric vehicle (thesis Fig. 2.3): engine-generator genset on a DC bus with
the battery, the traction motor through the final drive to the wheels.

Its model is :class:`hevsim.sim.model.SeriesHEV` (built by
:func:`hevsim.sim.model.build_series_hev`); its forward step is the compiled kernel
:func:`hevsim.sim.kernel.run_series`, one named step function per stage
(:func:`~hevsim.sim.kernel.driver_step` -> genset supervisor ->
:func:`~hevsim.sim.kernel.bus_limits` -> :func:`~hevsim.sim.kernel.genset_step` ->
:func:`~hevsim.sim.kernel.traction_step` -> :func:`~hevsim.sim.kernel.vehicle_step` ->
:func:`~hevsim.sim.kernel.bus_step`, on the bus balance of :mod:`hevsim.components.bus`),
and its DP formulation :class:`hevsim.optimal._series_dp.SeriesFormulation` calls the same
bus balance (:func:`hevsim.optimal._hev_common.electric_flow`) over the grid. Controls:
genset state and engine throttle (forward), genset electrical power on the engine's optimal
line (DP). Controllers: ``"thermostat"`` (rule-based) and ``"schedule"`` (a genset schedule
with cranking and speed loop); a :class:`~hevsim.sim.simulator.GensetSchedule` with
``quasi_static=True`` selects the kernel's ``"replay"`` supervisor, which applies a DP
optimum's decisions exactly.
"""

from __future__ import annotations

from hevsim.sim.kernel import run_series, run_series_batch
from hevsim.sim.model import SeriesHEV, build_series_hev

ARCHITECTURE = "series"
CONTROLS: tuple[str, ...] = ("genset_state", "engine_throttle")

__all__ = ["ARCHITECTURE", "CONTROLS", "SeriesHEV", "build_series_hev", "run_series", "run_series_batch"]
