"""The pack of a ``[battery] model = "pack"`` vehicle (:mod:`hevsim.sim.pack_vehicle`): its
configuration at the vehicle's step and ambient (:func:`vehicle_pack_config`), a fresh run
(:func:`make_pack_run`) and the pack's channels, metrics and events on the vehicle's result
(:func:`_attach`). Below both the forward loop (:func:`hevsim.sim.forward.simulate_architecture`
makes a pack vehicle's run with these) and :mod:`hevsim.sim.pack_vehicle`, which re-exports them."""

from __future__ import annotations

import copy
import logging
import math
from collections.abc import Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from hevsim.architectures._build import pack_file
from hevsim.battery.bms import LIMIT_NAMES, PackRun
from hevsim.battery.pack import Pack, PackConfig, load_pack_config, pack_config_from_dict
from hevsim.errors import ConfigError
from hevsim.schema import read_toml, with_changes
from hevsim.sim.metrics import metric

LOG = logging.getLogger("hevsim")


def vehicle_pack_config(
    cfg: Any,
    dt_s: float,
    ambient_temp_c: float | None = None,
    soak: bool = False,
    cooling_off: bool = False,
    pack_changes: Mapping[str, Any] | None = None,
) -> tuple[PackConfig, Path]:
    """The pack configuration of a vehicle configuration for a run at step ``dt_s`` [s]:
    ``ambient_temp_c`` [degC] replaces the pack file's ambient; ``soak`` also starts the cells
    and the coolant at it (a car parked long enough); ``cooling_off`` stops the pump, the
    radiator fan and the chiller (the stagnant coolant still takes heat); ``pack_changes``:
    dotted keys of the pack file and their values (``{"cooling.chiller": 0,
    "cooling.flow_l_min": 15.0}``: another cooling design), validated as the file is (an
    unknown key or a value out of range: :class:`~hevsim.errors.ConfigError` naming the
    file, the key and the value)."""
    path = pack_file(cfg.battery, Path(cfg.base_dir))
    pc = load_pack_config(path) if not pack_changes else changed_pack_config(path, pack_changes)
    pk = replace(pc.pack, dt_s=float(dt_s))
    cooling = pc.cooling
    if cooling_off:
        cooling = replace(cooling, flow_l_min=0.0, chiller=0, fan_power_w=0.0)
        pc = replace(pc, controller=replace(pc.controller, kind="off"))
    if ambient_temp_c is not None:
        pk = replace(pk, ambient_temp_c=float(ambient_temp_c))
        if soak:
            pk = replace(pk, initial_temp_c=float(ambient_temp_c))
            cooling = replace(cooling, supply_temp_c=float(ambient_temp_c))
    return replace(pc, pack=pk, cooling=cooling), path


def changed_pack_config(path: Path, changes: Mapping[str, Any]) -> PackConfig:
    """The pack file ``path`` with the dotted ``section.key`` values of ``changes`` set, then
    validated as a file is (the error names the file with its changes, the key and the value)."""
    data = copy.deepcopy(read_toml(path))
    for dotted, value in changes.items():
        section, _, key = str(dotted).partition(".")
        if not section or not key or "." in key:
            raise ConfigError(
                f"{path}: pack change {dotted!r} = {value!r}; expected a key 'section.key' of the pack file "
                "(e.g. 'cooling.chiller' or 'cooling.flow_l_min')."
            )
        if not isinstance(data.get(section, {}), dict):
            raise ConfigError(
                f"{path}: pack change {dotted!r}: '{section}' is not a section of the pack file."
            )
    with_changes(data, changes)
    shown = ", ".join(f"{k} = {v!r}" for k, v in changes.items())
    return pack_config_from_dict(data, f"{path} (with {shown})", path.parent)


def check_voltage_window(pack: Pack, cfg: Any, path: Path) -> None:
    """ConfigError when the pack's voltage window (all series cells between the cells'
    ``[limits] v_min_v`` and ``v_max_v``) is not inside the motor inverter's DC window
    (``[battery] bus_min_v`` .. ``bus_max_v`` of the vehicle file)."""
    lim = pack.params.limits
    n_s = pack.cfg.pack.n_modules * pack.cfg.module.n_series
    lo, hi = n_s * lim.v_min_v, n_s * lim.v_max_v
    b = cfg.battery
    if lo < b.bus_min_v or hi > b.bus_max_v:
        raise ConfigError(
            f"{path}: keys 'pack.n_modules' = {pack.cfg.pack.n_modules} x 'module.n_series' = "
            f"{pack.cfg.module.n_series} cells in series give a pack window of {lo:g} to {hi:g} V "
            f"({lim.v_min_v:g} to {lim.v_max_v:g} V per cell, '{pack.params.name}'); the motor inverter of "
            f"{cfg.name} accepts [battery] bus_min_v = {b.bus_min_v:g} to bus_max_v = {b.bus_max_v:g} V; "
            "expected the pack's window inside the inverter's."
        )


def make_pack_run(
    cfg: Any,
    dt_s: float,
    soc_initial: float,
    *,
    ambient_temp_c: float | None = None,
    soak: bool = False,
    cooling_off: bool = False,
    age_state: Any = None,
    pack_changes: Mapping[str, Any] | None = None,
) -> PackRun:
    """A fresh :class:`~hevsim.battery.bms.PackRun` for one vehicle run (``age_state``: a
    :class:`hevsim.battery.life.PackAgeState` applied to the cells and tracked over the run;
    ``pack_changes``: as :func:`vehicle_pack_config`)."""
    pcfg, path = vehicle_pack_config(cfg, dt_s, ambient_temp_c, soak, cooling_off, pack_changes)
    try:
        pack = Pack(pcfg)
    except ConfigError as exc:  # name the pack file (Pack names the pack)
        raise ConfigError(f"{path}: {exc}") from exc
    check_voltage_window(pack, cfg, path)
    if age_state is not None:
        age_state.apply(pack)
    return PackRun(pack, soc_initial)


def _limited_column(ts: pd.DataFrame) -> np.ndarray:
    """Steps where the car was held back by its battery (series: ``battery_limited``; forward
    architectures: ``traction_limited``)."""
    for col in ("battery_limited", "traction_limited"):
        if col in ts:
            return ts[col].to_numpy() > 0
    return np.zeros(len(ts), dtype=bool)


def _attach(res: Any, run: PackRun, cfg: Any) -> None:
    """Add the pack's channels, metrics, events and energy terms to a vehicle result (after
    the cells' domain check, :func:`hevsim.battery.cell.check_cell_domain`)."""
    from hevsim.battery.cell import check_cell_domain

    pf = run.frame(len(res.timeseries))
    res.timeseries = ts = pd.concat([res.timeseries, pf.set_index(res.timeseries.index)], axis=1)
    e = run.energy()
    res.extra["pack_energy"] = e
    t = ts["time_s"].to_numpy()
    dt = float(t[1] - t[0])
    steps = len(run.rows["derating_factor"])
    rows = run.rows
    check_cell_domain(  # every cell of the pack (the vehicle's own check sees the mean SOC)
        f"{cfg.name}: pack",
        t[:steps],
        rows["pack_current_a"],
        rows["pack_voltage_v"],
        rows["hottest_cell_temp_k"],
        soc=np.column_stack([rows["cell_soc_min"], rows["cell_soc_max"]]),
        cell_names=["the lowest cell", "the highest cell"],
        remedy="the BMS limits the pack current by the lowest/highest cell SOC ([derating] soc, "
        "discharge_soc_factor, charge_soc_factor of the pack file) and the cells' voltage limits.",
    )
    factor = np.asarray(run.rows["derating_factor"])
    derated = factor < 1.0
    lim_d = np.asarray(run.rows["bms_discharge_limit_a"])
    lim_c = np.asarray(run.rows["bms_charge_limit_a"])
    i_max = run.pack.cfg.pack.max_current_a
    bms_low = (lim_d < i_max * (1 - 1e-9)) | (lim_c < i_max * (1 - 1e-9))
    held = _limited_column(ts)[:steps] & bms_low
    hot = np.asarray(run.rows["hottest_cell_temp_k"])
    cooling_j = e["pump_work_j"] + e["chiller_electric_j"] + e["fan_electric_j"]
    first = float(t[:steps][derated][0]) if derated.any() else math.nan
    new = {
        "pack_peak_cell_temp_c": metric(hot.max() - 273.15, "degC", "hottest cell core temperature"),
        "pack_peak_hot_spot_temp_c": metric(
            max(run.rows["hot_spot_temp_k"]) - 273.15, "degC", "hottest point of any module (thermal model)"
        ),
        "pack_hot_spot_error_estimate_k": metric(
            run.pack.hot_spot_error()["estimate_k"],
            "K",
            "error estimate of the module hot spots vs the full FEM: ROM estimate + screening slack "
            "([module] hot_spot_slack_k; NaN without module ROMs)",
        ),
        "pack_derated_s": metric(derated.sum() * dt, "s", "time the BMS derated the pack for temperature"),
        "pack_first_derating_s": metric(first, "s", "first time the BMS derated the pack (NaN: never)"),
        "pack_bms_limited_s": metric(
            held.sum() * dt, "s", "time the car could not follow the trace while the BMS limited the pack"
        ),
        "pack_cooling_energy_j": metric(cooling_j, "J", "electrical energy of pump, fan and chiller"),
        "pack_final_soc_spread": metric(run.rows["cell_soc_spread"][-1], "-", "final cell SOC max - min"),
        "pack_energy_balance_relative": metric(
            e["residual_relative"], "-", "pack energy-balance residual / electrical throughput"
        ),
    }
    res.metrics.update(new)
    pc = run.pack.cfg
    res.metadata["pack"] = {
        "name": pc.name, "n_cells": run.pack.n_cells, "thermal": pc.module.thermal,
        "ambient_temp_c": pc.pack.ambient_temp_c, "initial_temp_c": pc.pack.initial_temp_c,
        "cooling_controller": pc.controller.kind,
    }  # fmt: skip
    ev = _pack_events(t[:steps], factor, hot, lim_d, lim_c, run, held)
    if len(ev):
        res.events = (
            pd.concat([res.events, ev], ignore_index=True)
            .sort_values(["time_s", "kind"], kind="stable")
            .reset_index(drop=True)
        )
    if held.any() or derated.any():
        LOG.warning(
            "%s on %s: pack derated for %.0f s (first at t = %.0f s, hottest cell %.1f degC); the car could "
            "not follow the trace for %.0f s while the BMS limited the pack",
            cfg.name, res.metadata.get("cycle"), derated.sum() * dt, first, hot.max() - 273.15,
            held.sum() * dt,
        )  # fmt: skip


def _pack_events(
    t: np.ndarray, factor: np.ndarray, hot: np.ndarray, lim_d: np.ndarray, lim_c: np.ndarray, run: PackRun,
    held: np.ndarray,
) -> pd.DataFrame:  # fmt: skip
    """``derating`` on/off events (temperature factor < 1) and ``bms_limit`` events (the car
    held back while the BMS limited the pack), each with its reason."""
    rows: list[dict[str, Any]] = []
    reasons = np.asarray(run.rows["bms_discharge_reason"], dtype=int)
    for flag, kind in ((factor < 1.0, "derating"), (held, "bms_limit")):
        edges = np.flatnonzero(np.diff(np.r_[False, flag, False].astype(np.int8)))
        for j, k in enumerate(edges):
            if k >= t.size:
                break
            on = j % 2 == 0
            if kind == "derating":
                why = (
                    f"hottest cell {hot[k] - 273.15:.1f} degC: BMS current factor {factor[k]:.2f} "
                    f"(discharge limit {lim_d[k]:.1f} A, charge limit {lim_c[k]:.1f} A)"
                    if on else f"hottest cell {hot[k] - 273.15:.1f} degC: full current again"
                )  # fmt: skip
            else:
                why = (
                    f"the car cannot follow the trace: BMS discharge limit {lim_d[k]:.1f} A "
                    f"({LIMIT_NAMES[reasons[k]]}), charge limit {lim_c[k]:.1f} A"
                    if on else "the car follows the trace again"
                )  # fmt: skip
            rows.append({"time_s": float(t[k]), "kind": kind, "from_state": "off" if on else "on",
                         "to_state": "on" if on else "off", "reason": why})  # fmt: skip
    return pd.DataFrame(rows, columns=["time_s", "kind", "from_state", "to_state", "reason"])
