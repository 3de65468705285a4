"""The ``[battery] model = "cell"`` battery in the forward simulation of every architecture.

One representative electro-thermal cell (:mod:`hevsim.battery.kernel`, thesis eqs 33-41: OCV
and series-resistance tables, RC pairs, lumped thermal with a skin resistance to a heat port at
the ambient) scaled to the pack's ``n_series`` x ``n_parallel`` identical cells, exactly as the
``"cell"`` battery of :mod:`hevsim.battery.vehicle` (section 2), for every architecture. Each
vehicle step:

1. :meth:`CellRun.vehicle_step` (compiled: :func:`hevsim.battery.vehicle.cell_bus_state`): the
   pack's step Thevenin pairs ``V_avg = E - Z I`` of each direction (exact over the step for the
   thesis's cell, :func:`hevsim.battery.kernel.branch_affine`), handed to the vehicle's bus
   balance as its OCV (the discharge ``E``) and resistances, with the ``[battery]`` section's
   current limits;
2. the vehicle solves its bus and hands back the terminal power;
3. :meth:`CellRun.finish_power` (compiled: :func:`~hevsim.battery.vehicle.cell_finish_power`):
   the pack current from the direction's own pair, the cell's step at its share
   (:func:`~hevsim.battery.kernel.cell_step`) and one record row.

The compiled forward loops of :mod:`hevsim.sim` call the same two compiled functions on
:attr:`CellRun.arrays` (no Python per step); the Python reference loop calls these methods.
This is the pack kind's protocol (:class:`hevsim.battery.bms.PackRun`) with one cell and
no BMS, cooling or module thermal model.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from hevsim.battery import kernel as K
from hevsim.battery.params import CellParameters, load_cell_parameters
from hevsim.battery.vehicle import (
    A_NP,
    A_NS,
    A_REXT,
    A_TPORT,
    CELL_RECORD,
    CF_SOC,
    CF_STEP,
    cell_bus_state,
    cell_bus_tables,
    cell_finish_power,
)

CHANNELS: tuple[str, ...] = (
    "cell_current_a", "cell_voltage_v", "cell_voltage_avg_v", "cell_ocv_v", "cell_soc", "cell_temp_k",
    "cell_heat_w", "cell_port_heat_w", "cell_capacity_c", "cell_rs_ohm",
)  # fmt: skip
"""Per-step channels of a run (step k's row: the current over step k, the voltages, SOC and
temperature at its end, heat flows over it; :data:`hevsim.battery.kernel.RECORD`)."""
_COLUMNS = [CELL_RECORD.index(c.removeprefix("cell_")) for c in CHANNELS]
_ENERGY = [CELL_RECORD.index(c) for c in ("e_elec_j", "e_chem_j", "e_heat_j", "e_port_j")]


class CellRun:
    """One vehicle run of a ``[battery] model = "cell"`` pack (module docstring).

    ``params``: the cell (a :class:`~hevsim.battery.params.CellParameters` or a shipped name /
    path); ``n_series`` x ``n_parallel`` identical cells and ``r_extra_ohm`` [ohm] of wiring;
    the cells start at ``soc_initial`` [-] and ``temp_k`` [K]; their heat port is at
    ``port_temp_k`` [K] (the ambient; default ``temp_k``); ``steps`` steps of ``dt_s`` [s].
    """

    def __init__(
        self,
        params: CellParameters | str | Path,
        n_series: int,
        n_parallel: int,
        soc_initial: float,
        temp_k: float,
        dt_s: float,
        steps: int,
        port_temp_k: float | None = None,
        r_extra_ohm: float = 0.0,
    ) -> None:
        self.params = params if isinstance(params, CellParameters) else load_cell_parameters(params)
        self.soc_initial = float(soc_initial)
        self.temp_initial_k = float(temp_k)
        self.dt_s = float(dt_s)
        self.arrays = cell_bus_tables(
            self.params, n_series, n_parallel, soc_initial, temp_k, dt_s, steps, port_temp_k, r_extra_ohm
        )
        self.base_aux_w: float | None = None
        self._rc0 = self._rc_energy()

    @property
    def n_series(self) -> int:
        return int(self.arrays.aux[A_NS])

    @property
    def n_parallel(self) -> int:
        return int(self.arrays.aux[A_NP])

    @property
    def port_temp_k(self) -> float:
        """The heat-port (ambient) temperature [K]."""
        return float(self.arrays.aux[A_TPORT])

    @property
    def steps(self) -> int:
        """Steps taken so far."""
        return int(self.arrays.f[CF_STEP])

    @property
    def soc(self) -> float:
        """The cells' SOC [-] at the end of the last step (the vehicle's SOC)."""
        return float(self.arrays.f[CF_SOC])

    def reserve(self, steps: int) -> None:
        """Room for ``steps`` more record rows."""
        s = self.arrays
        need = self.steps + steps
        if s.rec.shape[0] < need:
            rec = np.zeros((need, s.rec.shape[1]))
            rec[: s.rec.shape[0]] = s.rec
            self.arrays = s._replace(rec=rec)

    def loop_arrays(self, base_aux_w: float, steps: int) -> Any:
        """The battery argument of the compiled forward loops (room for ``steps`` rows;
        ``base_aux_w`` [W] is the bus's own load, unchanged by a cell pack)."""
        if self.base_aux_w is None:
            self.base_aux_w = float(base_aux_w)
        self.reserve(steps)
        return self.arrays

    def vehicle_step(
        self,
        model: Any,
        soc: float,
        soc_max: float,
        discharge_rtol: float | None = None,
        charge_rtol: float | None = None,
    ) -> tuple[Any, Any]:
        """Begin a step of the Python forward loop (:mod:`hevsim.sim.forward`): (the model, as
        it is: the ``[battery]`` current limits and the bus load hold for every step; the
        :class:`~hevsim.components.flow.BatteryState` of the step: OCV = the discharge pair's
        ``E``, resistances = each direction's ``Z``, no charging at ``soc_max``). The numbers
        are :func:`~hevsim.battery.vehicle.cell_bus_state`'s, the compiled loops' own; the
        tolerances are those of the pack's protocol (a cell pack's limits are the section's,
        as the table battery's)."""
        from hevsim.components.flow import BatteryState

        b = model.battery
        ocv, z_dis, z_chg, p_chg = cell_bus_state(
            self.arrays, float(soc), float(soc_max), float(b.max_discharge_current_a),
            float(b.max_charge_current_a),
        )  # fmt: skip
        bs = BatteryState(
            np.asarray(soc), np.asarray(ocv), np.asarray(z_dis), np.asarray(z_chg), np.asarray(p_chg)
        )
        return model, bs

    def finish_power(self, power_w: float) -> float:
        """End the step at the bus's terminal power ``power_w`` [W]; returns the new SOC [-]."""
        self.reserve(1)
        return float(cell_finish_power(self.arrays, float(power_w)))

    # -- results -----------------------------------------------------------------------------
    def _rc_energy(self) -> float:
        s = self.arrays
        return float(K.rc_energy(s.params, s.rc_discharge, s.rc_charge, s.state))

    def records(self) -> np.ndarray:
        """The record rows of the steps taken (steps x :data:`~hevsim.battery.vehicle.CELL_RECORD`)."""
        return self.arrays.rec[: self.steps]

    def frame(self, n_rows: int) -> pd.DataFrame:
        """The cell channels (:data:`CHANNELS`) as ``n_rows`` rows (one per vehicle sample: the
        last step's values repeated on the final sample, as the vehicle's own channels)."""
        rec = self.records()[:n_rows, _COLUMNS]
        if 0 < rec.shape[0] < n_rows:
            rec = np.concatenate([rec, np.repeat(rec[-1:], n_rows - rec.shape[0], axis=0)])
        cols = {name: rec[:, j] for j, name in enumerate(CHANNELS)}
        cols["battery_heat_w"] = cols["cell_heat_w"] * (self.n_series * self.n_parallel)  # identical cells
        return pd.DataFrame(cols)

    def energy(self) -> dict[str, float]:
        """The pack's energy terms since the run began [J] (every cell's, times the number of
        cells): electrical out, chemical change, heat, heat to the port, RC energy change, the
        residual ``electrical + chemical + heat + RC`` (0 to round-off), its size relative to
        the electrical throughput, and the wiring's loss ``r_extra I^2 dt``."""
        rec = self.records()
        n = self.n_series * self.n_parallel
        e_el, e_chem, e_heat, e_port = (float(rec[:, j].sum()) * n for j in _ENERGY)
        d_rc = (self._rc_energy() - self._rc0) * n
        throughput = float(np.abs(rec[:, _COLUMNS[2]] * rec[:, 0]).sum()) * n * self.dt_s
        residual = e_el + e_chem + e_heat + d_rc
        i_pack = rec[:, 0] * self.n_parallel
        wiring = float(np.sum(self.arrays.aux[A_REXT] * i_pack**2)) * self.dt_s
        return {
            "electrical_out_j": e_el, "chemical_change_j": e_chem, "heat_j": e_heat, "heat_to_port_j": e_port,
            "rc_energy_change_j": d_rc, "residual_j": residual,
            "residual_relative": residual / throughput if throughput > 0 else 0.0, "throughput_j": throughput,
            "wiring_loss_j": wiring,
        }  # fmt: skip


__all__ = ["CHANNELS", "CellRun"]
