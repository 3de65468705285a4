"""A vehicle with a whole battery pack (``[battery] model = "pack"``): cells, module thermal
model, cooling loop and BMS inside the forward simulation (issue 12 item 3).

The vehicle file names a pack file (``[battery] pack = "vehicle_pack.toml"``, a pack TOML as
``examples/pack.toml``). Every vehicle step the pack's :class:`~hevsim.battery.bms.PackRun`
gives the bus its exact step Thevenin pair, the BMS's current limits (hot, empty, full or
voltage-limited cells lower them, so the supervisory controller sees the available power) and
the cooling loop's electrical load; after the step the pack advances with the actual current
and the ambient temperature.

* **Every architecture** (the series HEV's kernel supervisors through its plug-in,
  :func:`hevsim.sim._compiled_series.run_compiled`; parallel HEV, power split, BEV, FCEV): the
  one compiled forward loop (:func:`hevsim.sim._loop.run_loop`, the architecture's plug-in)
  with the same compiled
  pack step inside (``battery_begin``/``battery_end`` of :mod:`hevsim.sim._loop`:
  :func:`~hevsim.battery.pack_run.pack_begin`, :func:`~hevsim.battery.pack_run.pack_bus_state`,
  :func:`~hevsim.battery.pack_run.pack_finish_power`), no Python per step. Controllers without a
  compiled form (and ``HEVSIM_FORWARD=python``) run the Python loop of
  :mod:`hevsim.sim.forward`, which asks the run for the step's model (battery limits, bus
  load) and battery state (:meth:`~hevsim.battery.bms.PackRun.vehicle_step`, the same compiled
  numbers) and hands back the terminal power; the pack solves its current with the
  direction's own pair.

The result is the vehicle's :class:`~hevsim.sim.simulator.SimulationResult` with the pack's
channels (:data:`hevsim.battery.bms.CHANNELS`, one ``module<j>_hottest_cell_temp_k`` per
module) added to its time series, pack metrics (peak cell temperature, derated time, cooling
energy, the pack's energy-balance residual, SOC spread) and ``derating`` / ``bms_limit``
events saying when and why the BMS limited the car. The pack step is the vehicle step (the
pack file's ``pack.dt_s`` is replaced by it).
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

from hevsim.architectures._build import nominal_battery, pack_file  # re-exported
from hevsim.battery.bms import PackRun
from hevsim.cycles import DriveCycle
from hevsim.errors import ConfigError
from hevsim.sim.pack_setup import (
    _attach,
    changed_pack_config,  # noqa: F401 (re-exported)
    check_voltage_window,
    make_pack_run,
    vehicle_pack_config,
)

LOG = logging.getLogger("hevsim")


def simulate_pack_vehicle(
    model: Any,
    cycle: DriveCycle | str | None = None,
    dt_s: float | None = None,
    soc_initial: float | None = None,
    *,
    controller: Any = None,
    ambient_temp_c: float | None = None,
    soak: bool = False,
    cooling_off: bool = False,
    age_state: Any = None,
    schedule: Any = None,
) -> Any:
    """Simulate a ``[battery] model = "pack"`` vehicle (a file, configuration or built model)
    over ``cycle`` (module docstring). ``ambient_temp_c``/``soak``/``cooling_off``: see
    :func:`vehicle_pack_config`; ``age_state``: a :class:`hevsim.battery.life.PackAgeState`
    (applied to the cells, advanced by the run in place); ``controller`` (non-series) and
    ``schedule`` (series) as in the architecture's own simulate. Returns the vehicle's
    :class:`~hevsim.sim.simulator.SimulationResult` with the pack's channels, metrics and
    events; ``result.extra["pack_energy"]`` holds the pack's energy terms [J]."""
    from hevsim.config import load_vehicle_config
    from hevsim.sim.forward import cycle_and_step

    if isinstance(model, str | Path):
        model = load_vehicle_config(model)
    cfg = getattr(model, "config", model)
    if cfg.battery.model != "pack":
        raise ConfigError(f"{cfg.name}: key 'battery.model' = {cfg.battery.model!r}; expected 'pack' here.")
    cyc, dt = cycle_and_step(cycle, dt_s, cfg.simulation)
    soc0 = float(cfg.simulation.soc_initial if soc_initial is None else soc_initial)
    run = make_pack_run(
        cfg, dt, soc0, ambient_temp_c=ambient_temp_c, soak=soak, cooling_off=cooling_off, age_state=age_state
    )
    if age_state is not None:
        age_state.begin(run.pack)
    from threadpoolctl import threadpool_limits

    # one BLAS thread: the per-step ROM products are small (100 modules x order 159), and BLAS
    # threads spinning for them cost 25x on a busy 2-core machine (105 ms -> 4 ms per step)
    with threadpool_limits(1, user_api="blas"):
        if cfg.architecture == "series" and _series_kernel_supervisor(controller, cfg):
            res = _simulate_series(model, cyc, dt, soc0, run, schedule)
        else:
            from hevsim.sim.forward import simulate_architecture

            res = simulate_architecture(cfg.architecture, model, cyc, dt, soc0, controller, pack_run=run)
    _attach(res, run, cfg)
    if age_state is not None:
        age_state.end(run.pack, res)
    return res


def _series_kernel_supervisor(controller: Any, cfg: Any) -> bool:
    """Whether a series HEV's run with ``controller`` (None: the configuration's kind) is one of
    its compiled kernel's supervisors; the online controllers and controller objects (ECMS,
    A-ECMS, a DP schedule replay) run on its quasi-static power flow in the forward loop."""
    from hevsim.config import SERIES_CONTROLLER_KEYS

    kind = cfg.controller.kind if controller is None else controller
    return isinstance(kind, str) and kind in SERIES_CONTROLLER_KEYS


def _simulate_series(model: Any, cyc: DriveCycle, dt: float, soc0: float, run: PackRun, schedule: Any) -> Any:
    import time

    from hevsim.sim._compiled_series import run_compiled
    from hevsim.sim.checks import check_domain, check_metrics
    from hevsim.sim.series_run import _assemble, kernel_inputs

    t0 = time.perf_counter()
    hev, cyc, dt, args = kernel_inputs(model, cyc, dt, soc0, schedule)
    p = args[0]
    args = (*args[:4], (args[4][0], run), *args[5:])  # the loop steps the pack (its battery hooks)
    t1 = time.perf_counter()
    run_compiled(*args)  # the series plug-in of the one loop, the pack's compiled step in the loop
    t2 = time.perf_counter()
    out, energy, summary = args[-3], args[-2], args[-1]
    label = f"{hev.name} on {cyc.name}"
    check_domain(label, args[6], out, energy, summary, p)
    res = _assemble(hev, cyc, dt, p, out, energy, summary, t2 - t1, t2 - t0)
    check_metrics(label, res.metrics)
    return res


__all__ = [
    "check_voltage_window",
    "make_pack_run",
    "nominal_battery",
    "pack_file",
    "simulate_pack_vehicle",
    "vehicle_pack_config",
]
