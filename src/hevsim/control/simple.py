"""Controllers of the conventional vehicle (shift schedule), the BEV (direct drive) and the
fuel-cell vehicle (load follower)."""

from __future__ import annotations

from typing import Any

import numpy as np
from numba import njit

from hevsim.units import rpm_to_radps


@njit(cache=True)
def shift_gear(
    gear: int, w_fd_radps: float, ratios: np.ndarray, w_up_radps: float, w_down_radps: float
) -> int:
    """The shift schedule: from ``gear`` (1..G) at final-drive speed ``w_fd_radps`` [rad/s],
    shift up while the engine-side speed is above ``w_up_radps`` and down while below
    ``w_down_radps`` [rad/s]; first gear at a standstill."""
    g = int(gear)
    if w_fd_radps <= 0.0:
        return 1
    while g < ratios.size and w_fd_radps * ratios[g - 1] > w_up_radps:
        g += 1
    while g > 1 and w_fd_radps * ratios[g - 1] < w_down_radps:
        g -= 1
    return g


@njit(cache=True, inline="always")
def kickdown_gear(j, gear):
    """The ``j``-th gear (``j`` = 0, 1, ...) a shift schedule tries from the scheduled
    ``gear``: ``gear`` itself, then each lower gear down to first (kick-down), then the higher
    gears."""
    if j == 0:
        return gear
    return gear - j if j < gear else j + 1


@njit(cache=True)
def kickdown_order(gear, n_gears):
    """The gears (1..``n_gears``) of :func:`kickdown_gear` in order, as floats."""
    order = np.empty(n_gears)
    for j in range(n_gears):
        order[j] = kickdown_gear(j, gear)
    return order


class ShiftSchedule:
    """Automatic gearbox: the gear of the ``upshift_rpm``/``downshift_rpm`` schedule; if the
    engine cannot give the torque in it, kick down to the highest lower gear that can (then
    any gear that can); None when no gear can."""

    name = "shift_schedule"

    def __init__(self, model: Any, upshift_rpm: float, downshift_rpm: float) -> None:
        self.model = model
        self.w_up, self.w_down = rpm_to_radps(upshift_rpm), rpm_to_radps(downshift_rpm)
        self.ratios = model.gear_ratios
        self.gear = 1

    def reset(self, soc_initial: float) -> None:
        """Start in first gear."""
        self.gear = 1

    def update(self, step: Any, stage: Any) -> None:
        """Remember the gear applied."""
        self.gear = int(np.ravel(stage.mech["gi"])[0]) + 1

    def choose(self, step: Any) -> tuple[float] | None:
        """The scheduled gear, or a kick-down."""
        w_fd = step.wheel_speed_radps * self.model.final_drive.ratio
        g = shift_gear(self.gear, w_fd, self.ratios, self.w_up, self.w_down)
        gears = kickdown_order(g, self.ratios.size)
        _, feasible = step.evaluate(gears)
        ok = np.flatnonzero(feasible)
        return None if ok.size == 0 else (float(gears[ok[0]]),)


class Direct:
    """No choice to make (BEV): the empty control when the power flow is feasible, else None."""

    name = "direct"

    def __init__(self, model: Any) -> None:
        self.model = model

    def reset(self, soc_initial: float) -> None:
        """Nothing to reset."""

    def update(self, step: Any, stage: Any) -> None:
        """Nothing to remember."""

    def choose(self, step: Any) -> tuple[()] | None:
        """() if the machine and battery can give the demand."""
        _, feasible = step.evaluate()
        return () if bool(np.ravel(feasible)[0]) else None


@njit(cache=True, inline="always")
def forced_on(v_mid_mps, on_time_s, dt_s, on_speed_mps, min_on_time_s):
    """Whether FASTSim's rules keep a fuel converter running this step: the vehicle's mid-step
    speed ``v_mid_mps`` [m/s] above ``on_speed_mps`` (``mph_fc_on``), or a converter that has run
    ``on_time_s`` [s] (0: off) less than ``min_on_time_s - dt_s`` [s] (``min_fc_time_on``, as
    fastsim-2's ``set_fc_forced_state`` tests it). The load follower's rule; its compiled plug-in
    (:mod:`hevsim.sim._compiled_fcev`) calls it compiled."""
    return v_mid_mps > on_speed_mps or (on_time_s > 0.0 and on_time_s < min_on_time_s - dt_s)


class LoadFollower:
    """Fuel-cell vehicle: the fuel cell follows the bus load with a SOC correction, within its
    ramp limits.

    Target net power [W] = the bus load with the fuel cell off (machine electrical power plus
    the auxiliaries) + ``charge_power_w`` x ``clip((SOC_mid - SOC) / (half band), -1, 1)``, with
    ``SOC_mid`` and the half band from ``soc_low`` .. ``soc_high`` (above ``soc_high`` it gives
    ``charge_power_w`` less than the load, below ``soc_low`` that much more). The target is
    clipped to what the system reaches in one step from its previous power (ramp limits
    ``fuel_cell.ramp_up_w_per_s`` / ``ramp_down_w_per_s``, never below idle ``min_power_w`` nor
    above ``max_power_w``); when the battery cannot take or give the difference, the feasible
    power of that window nearest to the target is taken (``WINDOW_POINTS`` candidates).

    FASTSim's fuel-converter rules (:func:`forced_on`): above the vehicle speed
    ``fuel_cell_on_speed_mps`` [m/s] (mid-step speed, as the electric assist's
    ``engine_on_speed_mps``), and while a started fuel cell has run less than
    ``fuel_cell_min_on_time_s`` [s] less one step, the fuel cell does not stop: every candidate is
    at least :data:`~hevsim.components.fuel_cell.RUNNING_ZERO_W` (running with no net output, its
    idle hydrogen ``fuel_cell.idle_fuel_power_w`` drawn).
    """

    name = "load_follower"
    WINDOW_POINTS = 41
    """Candidate powers across the ramp window when the clipped target is infeasible."""

    def __init__(
        self, model: Any, soc_low: float, soc_high: float, charge_power_w: float,
        fuel_cell_on_speed_mps: float = 1000.0, fuel_cell_min_on_time_s: float = 0.0,
    ) -> None:  # fmt: skip
        self.model = model
        self.soc_mid = 0.5 * (float(soc_low) + float(soc_high))
        self.half_band = 0.5 * (float(soc_high) - float(soc_low))
        self.charge_power = float(charge_power_w)
        self.on_speed = float(fuel_cell_on_speed_mps)
        self.min_on_time = float(fuel_cell_min_on_time_s)
        self.initial_w = float(model.config.fuel_cell.initial_power_w)
        self.previous_w = self.initial_w
        self.on_time_s = 0.0
        self.ramp_down_overrides = 0
        self._shedding: dict[int, bool] = {}

    def reset(self, soc_initial: float) -> None:
        """The fuel cell at its configured initial power (clipped to idle and rating)."""
        fc = self.model.fuel_cell
        self.previous_w = min(max(self.initial_w, fc.min_power_w), fc.max_power_w)
        self.on_time_s = 0.0
        self.ramp_down_overrides = 0
        self._shedding = {}

    def update(self, step: Any, stage: Any) -> None:
        """Remember the net power applied [W] (the ramp limits start from it) and how long the
        fuel cell has run [s] (0 when off)."""
        self.previous_w = float(np.ravel(stage.details["fuel_cell_power_w"])[0])
        self.on_time_s = self.on_time_s + step.dt_s if self.previous_w > 0.0 else 0.0
        self.ramp_down_overrides += int(self._shedding.get(id(step), False))
        self._shedding.clear()

    def floor_w(self, step: Any) -> float:
        """The lowest net power [W] of ``step``'s candidates: :data:`RUNNING_ZERO_W
        <hevsim.components.fuel_cell.RUNNING_ZERO_W>` where :func:`forced_on`, else 0."""
        from hevsim.components.fuel_cell import RUNNING_ZERO_W

        forced = forced_on(step.v_mid_mps, self.on_time_s, step.dt_s, self.on_speed, self.min_on_time)
        return RUNNING_ZERO_W if forced else 0.0

    def target_w(self, step: Any) -> float:
        """The load-following target [W] of ``step`` before the ramp limits."""
        st, _ = step.evaluate(np.array([0.0]))
        load = float(np.ravel(st.flow.power_elec_w)[0]) + self.model.aux_power_w
        corr = (
            float(np.clip((self.soc_mid - step.soc) / self.half_band, -1.0, 1.0))
            if self.half_band > 0
            else 0.0
        )
        return load + self.charge_power * corr

    def choose(self, step: Any) -> tuple[float] | None:
        """The target within the ramp window, else the window's feasible power nearest to it."""
        self._shedding[id(step)] = False  # (ids of steps gone are reused)
        lo, hi = self.model.fuel_cell.ramp_window(self.previous_w, step.dt_s)
        floor = self.floor_w(step)
        lo, hi = max(lo, floor), max(hi, floor)
        target = min(max(self.target_w(step), lo), hi)
        _, feasible = step.evaluate(np.array([target]))
        if bool(np.ravel(feasible)[0]):
            return (target,)
        cands = np.linspace(lo, hi, self.WINDOW_POINTS)
        _, feasible = step.evaluate(cands)
        ok = np.ravel(feasible)
        if not ok.any():
            return self.shed(step)
        i = int(np.argmin(np.where(ok, np.abs(cands - target), np.inf)))
        return (float(cands[i]),)

    def shed(self, step: Any) -> tuple[float] | None:
        """No power of the ramp window feasible: the highest feasible of
        :func:`hevsim.architectures.fcev.shed_controls` (faster than the ramp-down limit; counted
        in ``ramp_down_overrides``), else None."""
        from hevsim.architectures.fcev import shed_controls

        (cands,) = shed_controls(self.model, self.previous_w, step.dt_s)
        cands = np.maximum(cands, self.floor_w(step))
        _, feasible = step.evaluate(cands)
        ok = np.flatnonzero(np.ravel(feasible))
        if ok.size == 0:
            return None
        p = float(cands[ok[-1]])  # off may be reachable (the ramp window holds none)
        self._shedding[id(step)] = not bool(self.model.fuel_cell.reachable(self.previous_w, step.dt_s, p))
        return (p,)
