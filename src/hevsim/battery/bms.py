"""The pack inside the vehicle: battery management (BMS) limits and one vehicle run of a pack.

Each vehicle step ``dt`` (the pack's ``pack.dt_s``):

1. :meth:`PackRun.begin`: the pack's state at the start of the step gives

   * its Thevenin equivalent for each current direction, ``V_avg = E - Z I`` with ``V_avg``
     the step-average terminal voltage (:func:`hevsim.battery.pack.pack_thevenin`; exact over
     the step, as the single-cell ``"cell"`` battery of :mod:`hevsim.battery.vehicle`, while every cell
     carries the pack's direction), which the vehicle's bus balance uses as its OCV and
     resistance. *Limit*: at small pack currents the cells of a parallel group with
     capacity/resistance spread circulate current (a cell whose OCV is above its neighbours'
     keeps discharging into them while the group charges, or the reverse); a cell in the other
     direction follows its other pair (charge or discharge OCV table and RC set), so the
     group's voltage is piecewise affine in the current and the direction's pair is not exact
     there. Worse, the thesis cell's step-average charge pair lies ~30 mV above its discharge
     pair (its charge OCV table is above the discharge one): a group voltage between the two
     leaves such a cell no consistent direction (discharge would need ``V < E_dis``, charge
     ``V > E_chg``; the dead band only holds ``|i| <= switch_band_a``), so the split's
     fixed-point iteration (:func:`hevsim.battery.kernel.share_current`, the same in
     :func:`hevsim.battery.pack_kernels._share_affine`) ends after ``n_parallel + 2`` passes with
     directions still changing and the group's cells do not share one voltage exactly (61 mV
     apart in a measured group at 0.1 A, its cells circulating +-0.9 A). A fix needs a
     zero-current state for a cell inside its OCV gap (a cell-model change, not made here).
     The pack's energy terms still close (every cell's step is consistent with its own
     current); the vehicle's bus power differs from the pack's terminal power on those steps
     only. Measured
     on ``examples/series_hev_pack.toml`` (600 cells, 2 % / 5 % spread): UDDS 269 of 1369
     steps, all at ``|I| < 2.8 A``, voltage off by at most 0.58 % (1.2 W), 72 J in total
     (1e-5 of the 7.7 MJ throughput); US06 105 of 600 steps, ``|I| < 2.8 A``, at most 0.94 %
     (2.3 W), 27 J (2.6e-6 of 10.4 MJ) (``tests/test_pack_run.py`` bounds it);
   * the BMS current limits (:func:`hevsim.battery.pack_run.pack_begin`, compiled):
     ``pack.max_current_a`` times the smallest of
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

from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import pandas as pd

from hevsim.battery.kernel import SOCINI
from hevsim.battery.pack import Pack, PackStepStart
from hevsim.battery.pack_run import LIMIT_NAMES, VEHICLE_CHANNELS

CHANNELS = VEHICLE_CHANNELS
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


class PackRun:
    """One vehicle run of a :class:`~hevsim.battery.pack.Pack` (module docstring).

    ``soc_initial`` [-] replaces every cell's initial SOC (the vehicle's ``soc_initial``).
    After :meth:`begin`: ``e_dis``/``z_dis``, ``e_chg``/``z_chg`` [V, ohm], ``limits``
    (:class:`BmsLimits`) and ``cooling_w`` [W] hold for the step (the pack's step vector,
    :data:`hevsim.battery.pack_run.SV_NAMES`). The compiled series kernel steps the same
    arrays without this class (:mod:`hevsim.battery.vehicle`, section 3).
    """

    def __init__(self, pack: Pack, soc_initial: float) -> None:
        from hevsim.battery.pack_run import F_SOC, F_SOCMAX, F_SOCMIN

        self.pack = pack
        pack.prm[:, SOCINI] = soc_initial
        pack.state_changed()
        pack._f[[F_SOC, F_SOCMIN, F_SOCMAX]] = soc_initial
        self.start: PackStepStart | None = None
        self.stored0 = pack.stored_energy_j()
        self.error: BaseException | None = None
        self.base_aux_w: float | None = None

    def _sv(self, name: str) -> float:
        from hevsim.battery.pack_run import SV_NAMES

        return float(self.pack._sv[SV_NAMES.index(name)])

    @property
    def e_dis(self) -> float:
        return self._sv("e_dis_v")

    @property
    def z_dis(self) -> float:
        return self._sv("z_dis_ohm")

    @property
    def e_chg(self) -> float:
        return self._sv("e_chg_v")

    @property
    def z_chg(self) -> float:
        return self._sv("z_chg_ohm")

    @property
    def cooling_w(self) -> float:
        """Electrical power of pump, fan and chiller this step [W]."""
        return self._sv("cooling_w")

    @property
    def limits(self) -> BmsLimits:
        """The BMS's limits of the step (:func:`hevsim.battery.pack_run.pack_begin`)."""
        sv = self._sv
        return BmsLimits(sv("limit_dis_a"), sv("limit_chg_a"), int(sv("reason_dis")), int(sv("reason_chg")),
                         sv("factor"))  # fmt: skip

    @property
    def soc(self) -> float:
        """Mean cell SOC [-] at the end of the last step (the vehicle's SOC)."""
        from hevsim.battery.pack_run import F_SOC

        return float(self.pack._f[F_SOC])

    @property
    def rows(self) -> dict[str, np.ndarray]:
        """The pack channels (:data:`CHANNELS`) of the steps so far."""
        rec = self.pack.records[0]
        return {name: rec[:, j] for j, name in enumerate(CHANNELS)}

    @property
    def module_hot(self) -> np.ndarray:
        """Per step and module the hot spot [K] (steps, n_modules)."""
        return self.pack.records[1]

    def group_pairs(self, direction: float) -> tuple[np.ndarray, np.ndarray]:
        """The series groups' step pairs ``(E_g, Z_g)`` [V, ohm] of the present step for a pack
        current of ``direction`` (+1 discharge, -1 charge) (:meth:`hevsim.battery.pack.Pack.thevenin`)."""
        e, z = np.empty(self.pack.n_groups_sim), np.empty(self.pack.n_groups_sim)
        self.pack.thevenin(direction, e, z)
        return e, z

    @property
    def has_rom(self) -> bool:
        """Whether the modules' thermal model is a reduced-order model (with a hot-spot search)."""
        from hevsim.battery.pack_run import F_ROM

        return bool(self.pack.arrays.f[F_ROM] > 0.0)

    def skip_hot_spots(self, skip: bool = True) -> None:
        """Skip (``skip``) or not the module ROMs' hot-spot search in the following steps: for a
        trial run whose records are discarded (:mod:`hevsim.sim.stint`'s passes of a lap). The
        hot spots are records only (the BMS derates on the hottest cell core, the ROM's ports
        feed the cells): the run's state evolves the same; its recorded hot spots are NaN and
        its search state is left as it was (so a run that skipped it must not be kept)."""
        from hevsim.battery.pack_run import F_HSSKIP

        self.pack.arrays.f[F_HSSKIP] = 1.0 if skip else 0.0

    def begin(self) -> None:
        """Start a step: Thevenin pair per direction, BMS limits, cooling power."""
        self.start = self.pack.begin_step()

    def vehicle_step(
        self,
        model: Any,
        soc: float,
        soc_max: float,
        discharge_rtol: float | None = None,
        charge_rtol: float | None = None,
    ) -> tuple[Any, Any]:
        """Begin a step of the forward simulator (:mod:`hevsim.sim.forward`): returns the
        model with this step's battery limits and bus load (``battery`` current limits =
        the BMS's, ``aux_power_w`` = the model's own + the cooling) and the
        :class:`~hevsim.components.flow.BatteryState` (OCV = ``E`` of discharge,
        resistances = ``Z`` of each direction; no charging at ``soc_max``). The flow's
        terminal power then goes to :meth:`finish_power`, which solves the current with the
        direction's own pair.

        ``discharge_rtol``/``charge_rtol`` [-]: the relative excess over a current limit the
        simulator's feasibility test accepts (default
        :data:`hevsim.components.flow.LIMIT_RTOL`, the round-off of its regeneration scaling),
        and a controller that searches the largest feasible point lands there: the limits
        handed to the vehicle are the BMS's divided by ``1 + rtol``, so that no accepted step
        exceeds the BMS's own limit (issue 24 item 4). The numbers are those of
        :func:`hevsim.battery.pack_run.pack_bus_state`, the compiled forward loops' own."""
        from hevsim.battery.pack_run import F_BASEAUX, pack_bus_state
        from hevsim.components.flow import LIMIT_RTOL, BatteryState

        if self.base_aux_w is None:
            self.base_aux_w = float(getattr(model, "aux_power_w", 0.0))
        self.begin()
        r_dis = LIMIT_RTOL if discharge_rtol is None else discharge_rtol
        r_chg = LIMIT_RTOL if charge_rtol is None else charge_rtol
        s = self.pack.arrays
        s.f[F_BASEAUX] = self.base_aux_w
        ocv, z_dis, z_chg, p_chg, i_dis, i_chg, aux_w = pack_bus_state(
            s, float(soc), float(soc_max), r_dis, r_chg
        )
        bs = BatteryState(
            np.asarray(soc), np.asarray(ocv), np.asarray(z_dis), np.asarray(z_chg), np.asarray(p_chg)
        )
        battery = replace(model.battery, max_discharge_current_a=i_dis, max_charge_current_a=i_chg)
        return replace(model, battery=battery, aux_power_w=aux_w), bs

    def current_for_power(self, power_w: float) -> float:
        """Pack current [A] whose step-average terminal power is ``power_w`` [W] (> 0
        discharging), from the direction's ``E I - Z I^2 = P`` (the root nearer zero; the
        maximum-power current when ``P`` exceeds ``E^2 / 4Z``)."""
        from hevsim.battery.pack_run import pack_current_for_power

        return float(pack_current_for_power(self.pack.arrays, float(power_w)))

    def finish_power(self, power_w: float) -> float:
        """End the step at terminal power ``power_w`` [W]; returns the new SOC [-]."""
        return self.finish_current(self.current_for_power(power_w))

    def finish_current(self, current_a: float) -> float:
        """End the step at pack current ``current_a`` [A]; records the channels; returns the
        new SOC [-]."""
        assert self.start is not None, "PackRun.begin() first"
        self.pack.finish_step(self.start, current_a)
        self.start = None
        return self.soc

    # -- results -----------------------------------------------------------------------------
    def frame(self, n_rows: int) -> pd.DataFrame:
        """The pack channels as ``n_rows`` rows (one per vehicle sample: the last step's values
        repeated on the final sample, as the vehicle's own channels)."""
        rec, hot = self.pack.records
        cols = [pd.DataFrame(rec[:, : len(CHANNELS)], columns=list(CHANNELS))]
        cols.append(
            pd.DataFrame(hot, columns=[f"module{j}_hottest_cell_temp_k" for j in range(hot.shape[1])])
        )
        ts = pd.concat(cols, axis=1)
        if len(ts) < n_rows:
            ts = pd.concat([ts, ts.iloc[[-1] * (n_rows - len(ts))]], ignore_index=True)
        return ts.iloc[:n_rows].reset_index(drop=True)

    def energy(self) -> dict[str, float]:
        """The pack's energy terms since the run began (:meth:`hevsim.battery.pack.Pack.energy`)."""
        return self.pack.energy(self.stored0)


__all__ = ["CHANNELS", "LIMIT_NAMES", "BmsLimits", "PackRun"]
