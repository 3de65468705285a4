"""A vehicle with a ``[battery] model = "cell"`` battery on the forward loop of every
architecture (parallel P2/P3, power split, BEV, fuel-cell vehicle; issue 24 item 3).

The pack is ``n_series`` x ``n_parallel`` identical electro-thermal cells of
:mod:`hevsim.battery` (``[battery] data``: a shipped cell or a cell TOML), one representative
cell scaled to the pack (:mod:`hevsim.battery.vehicle`, section 2),
with its RC and lumped thermal dynamics; its heat port is at the ambient (``[battery]
temperature_c``, or ``ambient_temp_c`` of a run). The vehicle's forward loop
(:func:`hevsim.sim.forward.simulate_architecture`, compiled or Python; a run at another ambient:
:func:`hevsim.sim.forward.simulate_cell_architecture`) steps it through the
battery protocol the pack uses (:class:`hevsim.battery.cell_run.CellRun`): every step the
cell's exact step Thevenin pairs feed the bus balance, and the cell advances at the solved
terminal power. The vehicle's SOC is the cell's (eq 37).

The result is the vehicle's :class:`~hevsim.sim.simulator.SimulationResult` with the cell
channels (:data:`hevsim.battery.cell_run.CHANNELS` and ``battery_heat_w``), metrics (peak and
final cell temperature, the cells' energy-balance residual) and ``result.extra["cell_energy"]``.
The series HEV's kernel supervisors step the same :class:`~hevsim.battery.cell_run.CellRun` in
the one loop (:func:`hevsim.sim.simulator.simulate`, then :func:`attach_cells`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from hevsim.architectures._build import cell_parameters
from hevsim.battery.cell_run import CellRun
from hevsim.sim.metrics import metric
from hevsim.units import KELVIN_OFFSET, c_to_k


def make_cell_run(
    cfg: Any, dt_s: float, soc_initial: float, steps: int, *, ambient_temp_c: float | None = None
) -> CellRun:
    """A fresh :class:`~hevsim.battery.cell_run.CellRun` of the configuration ``cfg``'s
    ``[battery]`` for ``steps`` steps of ``dt_s`` [s] from ``soc_initial`` [-]: the cells start
    at ``battery.temperature_c``; the heat port is at ``ambient_temp_c`` [degC] (default the
    same)."""
    b = cfg.battery
    t0 = c_to_k(b.temperature_c)
    port = t0 if ambient_temp_c is None else c_to_k(float(ambient_temp_c))
    return CellRun(
        cell_parameters(b, Path(cfg.base_dir)), b.n_series, b.n_parallel, soc_initial, t0, dt_s, steps,
        port_temp_k=port, r_extra_ohm=b.r_extra_ohm,
    )  # fmt: skip


def soaked(cfg: Any, ambient_temp_c: float) -> Any:
    """``cfg`` with its cells starting at the ambient ``ambient_temp_c`` [degC] (a car parked
    long enough: ``battery.temperature_c`` becomes the ambient)."""
    return cfg.replace(**{"battery.temperature_c": float(ambient_temp_c)})


def attach_cells(res: Any, run: CellRun, cfg: Any) -> None:
    """Add the cell channels, metrics and energy terms of ``run`` to the vehicle result ``res``
    (after the cells' domain check, :func:`hevsim.battery.cell.check_cell_domain`)."""
    from hevsim.battery.cell import check_cell_domain

    cf = run.frame(len(res.timeseries))
    res.timeseries = ts = pd.concat([res.timeseries, cf.set_index(res.timeseries.index)], axis=1)
    rec = run.records()
    t = ts["time_s"].to_numpy()
    steps = rec.shape[0]
    check_cell_domain(
        f"{cfg.name}: battery cells",
        t[:steps] + run.dt_s,
        np.asarray(ts["cell_current_a"])[:steps],
        np.asarray(ts["cell_voltage_v"])[:steps],
        np.asarray(ts["cell_temp_k"])[:steps],
        np.asarray(ts["cell_capacity_c"])[:steps],
        soc=np.asarray(ts["cell_soc"])[:steps],
    )
    temp = np.asarray(ts["cell_temp_k"])[:steps]
    # beyond the cell tables' temperature axis they are held at its edge: a warning, as a Cell's
    run.params.check_temperature_coverage(np.r_[run.port_temp_k, run.temp_initial_k, temp],
                                          "the vehicle's cell temperature")  # fmt: skip
    e = run.energy()
    res.extra["cell_energy"] = e
    peak, final = float(temp.max()) - KELVIN_OFFSET, float(temp[-1]) - KELVIN_OFFSET
    res.metrics.update({
        "battery_peak_cell_temp_c": metric(peak, "degC", "hottest cell core temperature"),
        "battery_final_cell_temp_c": metric(final, "degC", "cell core temperature at the end"),
        "battery_cell_energy_balance_relative": metric(
            e["residual_relative"], "-", "cells' energy-balance residual / electrical throughput"
        ),
    })  # fmt: skip
    res.metadata["cell"] = {
        "name": run.params.name, "n_series": run.n_series, "n_parallel": run.n_parallel,
        "initial_temp_c": run.temp_initial_k - KELVIN_OFFSET,
        "ambient_temp_c": run.port_temp_k - KELVIN_OFFSET,
    }  # fmt: skip


__all__ = ["attach_cells", "make_cell_run", "soaked"]
