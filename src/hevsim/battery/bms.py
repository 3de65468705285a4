"""The pack inside the vehicle: battery management (BMS) limits and one vehicle run of a pack.

Each vehicle step ``dt`` (the pack's ``pack.dt_s``):

1. :meth:`PackRun.begin`: the pack's state at the start of the step gives

   * its Thevenin equivalent for each current direction, ``V_avg = E - Z I`` with ``V_avg``
     the step-average terminal voltage (:func:`hevsim.battery.pack.pack_thevenin`; exact over
     the step, as the single-cell ECM kind of :mod:`hevsim.battery.vehicle`), which the
     vehicle's bus balance uses as its OCV and resistance;
   * the BMS current limits (:func:`bms_limits`): ``pack.max_current_a`` times the smallest of
     the temperature factor (hottest cell core, ``[derating] temp_c``/``current_factor``) and
     the SOC factor (``[derating] soc`` with ``discharge_soc_factor`` at the lowest cell SOC,
     ``charge_soc_factor`` at the highest), and the current that keeps every series group's
     step-average voltage within the cells' ``[limits] v_min_v``/``v_max_v``; the vehicle's
     power limits follow from those currents and ``(E, Z)``;
   * the cooling loop's decision for the step (pump, radiator fan, chiller), whose electrical
     power is an auxiliary load on the vehicle's bus (it shows in fuel economy and range).

2. The vehicle solves its bus with those (the supervisory controller sees the available
   power) and hands back the pack current or terminal power.

3. :meth:`PackRun.finish_current` / :meth:`PackRun.finish_power` step the cells, the module
   thermal model and the cooling loop (:meth:`hevsim.battery.pack.Pack.finish_step`) and record
   the pack's channels (:data:`CHANNELS`, plus the hottest cell of every module).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import pandas as pd

from hevsim.battery.kernel import SOCINI, VMAX, VMIN
from hevsim.battery.pack import Pack, PackStepStart

LIMIT_NAMES = ("none", "temperature", "soc", "voltage")
"""What binds a BMS current limit (the ``bms_*_limit_reason`` channel codes)."""
CHANNELS = (
    "pack_current_a", "pack_voltage_v", "pack_power_w", "pack_ocv_v", "pack_resistance_ohm",
    "bms_discharge_limit_a", "bms_charge_limit_a", "bms_discharge_reason", "bms_charge_reason",
    "derating_factor", "hottest_cell_temp_k", "hot_spot_temp_k", "cell_soc_min", "cell_soc_max",
    "cell_soc_spread", "coolant_loop_temp_k", "coolant_supply_temp_k", "pump_power_w", "fan_power_w",
    "chiller_power_w", "chiller_heat_w", "cooling_power_w", "plate_heat_w",
)  # fmt: skip
"""Per-step pack channels of a vehicle run (step k's row: the values over/at the end of step k)."""


@dataclass(frozen=True)
class BmsLimits:
    """The BMS's pack current limits for one step [A] (> 0 both) and what binds them
    (:data:`LIMIT_NAMES` index); ``temp_factor`` [-] the temperature derating factor."""

    discharge_a: float
    charge_a: float
    discharge_reason: int
    charge_reason: int
    temp_factor: float


def _binding(candidates: tuple[float, ...]) -> tuple[float, int]:
    """(smallest limit, index in LIMIT_NAMES): the unconstrained entry 0 wins ties."""
    best = min(range(len(candidates)), key=candidates.__getitem__)  # the first smallest (np.argmin)
    return max(float(candidates[best]), 0.0), best


def bms_limits(
    pack: Pack,
    start: PackStepStart,
    dis: tuple[np.ndarray, np.ndarray],
    chg: tuple[np.ndarray, np.ndarray],
    soc_min: float,
    soc_max: float,
) -> BmsLimits:
    """The step's limits (module docstring): ``dis``/``chg`` the series groups' ``(E_g, Z_g)``
    [V, ohm] for each direction; ``soc_min``/``soc_max`` the lowest and highest cell SOC."""
    d = pack.cfg.derating
    i_max = pack.cfg.pack.max_current_a
    f_dis = float(np.interp(soc_min, d.soc, d.discharge_soc_factor))
    f_chg = float(np.interp(soc_max, d.soc, d.charge_soc_factor))
    v_lo, v_hi = float(pack.prm[0, VMIN]), float(pack.prm[0, VMAX])
    i_v_dis = float(np.min((dis[0] - v_lo) / dis[1]))
    i_v_chg = float(np.min((v_hi - chg[0]) / chg[1]))
    lim_d, why_d = _binding((i_max, start.factor * i_max, f_dis * i_max, i_v_dis))
    lim_c, why_c = _binding((i_max, start.factor * i_max, f_chg * i_max, i_v_chg))
    return BmsLimits(lim_d, lim_c, why_d, why_c, start.factor)


class PackRun:
    """One vehicle run of a :class:`~hevsim.battery.pack.Pack` (module docstring).

    ``soc_initial`` [-] replaces every cell's initial SOC (the vehicle's ``soc_initial``).
    After :meth:`begin`: ``e_dis``/``z_dis``, ``e_chg``/``z_chg`` [V, ohm], ``limits``
    (:class:`BmsLimits`) and ``cooling_w`` [W] hold for the step.
    """

    def __init__(self, pack: Pack, soc_initial: float) -> None:
        self.pack = pack
        pack.prm[:, SOCINI] = soc_initial
        pack.state_changed()
        self._cells = np.empty((pack.n_cells, 5))
        self._soc = soc_initial
        self._g = [np.empty(pack.n_groups_sim) for _ in range(4)]
        self.start: PackStepStart | None = None
        self.e_dis = self.z_dis = self.e_chg = self.z_chg = math.nan
        self.limits = BmsLimits(math.inf, math.inf, 0, 0, 1.0)
        self.cooling_w = 0.0
        self.rows: dict[str, list[float]] = {name: [] for name in CHANNELS}
        self.module_hot: list[np.ndarray] = []
        self.stored0 = pack.stored_energy_j()
        self.soc_min = self.soc_max = soc_initial
        self.error: BaseException | None = None
        self.base_aux_w: float | None = None
        self.kernel_arrays: tuple[np.ndarray, np.ndarray] | None = None

    @property
    def soc(self) -> float:
        """Mean cell SOC [-] at the end of the last step (the vehicle's SOC)."""
        return self._soc

    def begin(self) -> None:
        """Start a step: Thevenin pair per direction, BMS limits, cooling power."""
        pack = self.pack
        self.start = start = pack.begin_step()
        ed, zd, ec, zc = self._g
        self.e_dis, self.z_dis = pack.thevenin(1.0, ed, zd)
        self.e_chg, self.z_chg = pack.thevenin(-1.0, ec, zc)
        self.limits = bms_limits(pack, start, (ed, zd), (ec, zc), self.soc_min, self.soc_max)
        ls = start.loop_step
        self.cooling_w = ls.pump_power_w + ls.fan_power_w + ls.chiller_power_w

    def vehicle_step(self, model: Any, soc: float, soc_max: float) -> tuple[Any, Any]:
        """Begin a step of the forward simulator (:mod:`hevsim.sim.forward`): returns the
        model with this step's battery limits and bus load (``battery`` current limits =
        the BMS's, ``aux_power_w`` = the model's own + the cooling) and the
        :class:`~hevsim.optimal._hev_common.BatteryState` (OCV = ``E`` of discharge,
        resistances = ``Z`` of each direction; no charging at ``soc_max``). The flow's
        terminal power then goes to :meth:`finish_power`, which solves the current with the
        direction's own pair."""
        from hevsim.components.bus import battery_power_limits_many
        from hevsim.optimal._hev_common import BatteryState

        if self.base_aux_w is None:
            self.base_aux_w = float(getattr(model, "aux_power_w", 0.0))
        self.begin()
        lim = self.limits
        o, rd, rc = np.array([self.e_dis]), np.array([self.z_dis]), np.array([self.z_chg])
        _, p_chg = battery_power_limits_many(o, rd, rc, lim.discharge_a, lim.charge_a)
        if soc >= soc_max:
            p_chg[:] = 0.0
        bs = BatteryState(np.asarray(soc), o.reshape(()), rd.reshape(()), rc.reshape(()), p_chg.reshape(()))
        battery = replace(
            model.battery, max_discharge_current_a=lim.discharge_a, max_charge_current_a=lim.charge_a
        )
        return replace(model, battery=battery, aux_power_w=self.base_aux_w + self.cooling_w), bs

    def kernel_begin(self) -> None:
        """Begin a step of the compiled series kernel (:func:`hevsim.battery.vehicle.battery_pack_begin`):
        writes the Thevenin pairs into its aux vector and the BMS limits and the bus load
        (the model's own auxiliary load + the cooling) into its parameter vector."""
        from hevsim.battery import vehicle as V
        from hevsim.sim import kernel as K

        assert self.kernel_arrays is not None
        p, aux = self.kernel_arrays
        if self.base_aux_w is None:
            self.base_aux_w = float(p[K.PAUX])
        self.begin()
        p[K.BIDIS], p[K.BICHG] = self.limits.discharge_a, self.limits.charge_a
        p[K.PAUX] = self.base_aux_w + self.cooling_w
        aux[V.A_EDIS], aux[V.A_ZDIS], aux[V.A_ECHG], aux[V.A_ZCHG] = (
            self.e_dis,
            self.z_dis,
            self.e_chg,
            self.z_chg,
        )

    def current_for_power(self, power_w: float) -> float:
        """Pack current [A] whose step-average terminal power is ``power_w`` [W] (> 0
        discharging), from the direction's ``E I - Z I^2 = P`` (the root nearer zero; the
        maximum-power current when ``P`` exceeds ``E^2 / 4Z``)."""
        if power_w == 0.0:
            return 0.0
        e, z = (self.e_dis, self.z_dis) if power_w > 0.0 else (self.e_chg, self.z_chg)
        disc = e * e - 4.0 * z * power_w
        return 2.0 * power_w / (e + math.sqrt(disc)) if disc > 0.0 else e / (2.0 * z)

    def finish_power(self, power_w: float) -> float:
        """End the step at terminal power ``power_w`` [W]; returns the new SOC [-]."""
        return self.finish_current(self.current_for_power(power_w))

    def finish_current(self, current_a: float) -> float:
        """End the step at pack current ``current_a`` [A]; records the channels; returns the
        new SOC [-]."""
        assert self.start is not None, "PackRun.begin() first"
        row, hot = self.pack.finish_step(self.start, current_a, cells_out=self._cells)
        self._soc = float(self._cells[:, 1].mean())
        lim, ls = self.limits, self.start.loop_step
        e, z = (self.e_dis, self.z_dis) if current_a >= 0.0 else (self.e_chg, self.z_chg)
        self.soc_min, self.soc_max = row["min_soc"], row["max_soc"]
        values = {
            "pack_current_a": current_a, "pack_voltage_v": row["voltage_avg_v"],
            "pack_power_w": row["power_w"], "pack_ocv_v": e, "pack_resistance_ohm": z,
            "bms_discharge_limit_a": lim.discharge_a,
            "bms_charge_limit_a": lim.charge_a, "bms_discharge_reason": lim.discharge_reason,
            "bms_charge_reason": lim.charge_reason, "derating_factor": lim.temp_factor,
            "hottest_cell_temp_k": row["hottest_cell_temp_k"], "hot_spot_temp_k": row["hot_spot_temp_k"],
            "cell_soc_min": row["min_soc"], "cell_soc_max": row["max_soc"],
            "cell_soc_spread": row["max_soc"] - row["min_soc"], "coolant_loop_temp_k": row["loop_temp_k"],
            "coolant_supply_temp_k": row["supply_temp_k"], "pump_power_w": ls.pump_power_w,
            "fan_power_w": ls.fan_power_w, "chiller_power_w": ls.chiller_power_w,
            "chiller_heat_w": ls.chiller_w,
            "cooling_power_w": self.cooling_w, "plate_heat_w": row["plate_heat_w"],
        }  # fmt: skip
        for name, val in values.items():
            self.rows[name].append(float(val))
        self.module_hot.append(hot.copy())
        self.start = None
        return self.soc

    # -- results -----------------------------------------------------------------------------
    def frame(self, n_rows: int) -> pd.DataFrame:
        """The pack channels as ``n_rows`` rows (one per vehicle sample: the last step's values
        repeated on the final sample, as the vehicle's own channels)."""
        cols: dict[str, Any] = {name: np.asarray(vals) for name, vals in self.rows.items()}
        hot = np.asarray(self.module_hot)
        for j in range(hot.shape[1] if hot.ndim == 2 else 0):
            cols[f"module{j}_hottest_cell_temp_k"] = hot[:, j]
        ts = pd.DataFrame(cols)
        if len(ts) < n_rows:
            ts = pd.concat([ts, ts.iloc[[-1] * (n_rows - len(ts))]], ignore_index=True)
        return ts.iloc[:n_rows].reset_index(drop=True)

    def energy(self) -> dict[str, float]:
        """The pack's energy terms since the run began (:meth:`hevsim.battery.pack.Pack.energy`)."""
        return self.pack.energy(self.stored0)


__all__ = ["CHANNELS", "LIMIT_NAMES", "BmsLimits", "PackRun", "bms_limits"]
