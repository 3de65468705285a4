"""A stint with the pack: N laps of a QSS lap with ``[battery] model = "pack"`` (issue 29 item 4).

Each lap is the QSS lap of :mod:`hevsim.sim.lap` (grip, apex speeds, forward and backward
integration, operating points), limited by the power the pack can give *now*, and the pack
(cells ECM + module thermal model or coolant ports + cooling loop + BMS, the
:class:`~hevsim.battery.bms.PackRun` of :mod:`hevsim.sim.pack_vehicle`) is stepped along the
lap in time:

1. **Limit at the start of the lap.** The BMS's discharge current limit ``I_lim`` (temperature
   derating at the hottest cell, SOC factors, the cells' voltage limits) becomes the lap's
   deployment, the
   largest battery chemical power ``P = OCV I_lim`` (``OCV`` of the vehicle's nominal view of
   the pack at the envelope's SOC, :func:`hevsim.sim.pack_vehicle.nominal_battery`). A limit at
   or above the nominal battery's own current limit is no limit: that lap *is* the single QSS
   lap (``simulate_lap`` with no deployment).
2. **The lap**: :func:`hevsim.sim.lap.simulate_lap` with that deployment (the envelope is built
   once for the stint for :data:`ENVELOPE_LEVELS` battery power limits plus the unlimited row
   and interpolated between them), giving the speed profile, each step's time ``ds / v`` and
   the battery terminal power of the power flow.
3. **The pack along the lap.** The pack steps at its own fixed step ``dt_s`` on the stint's
   clock (the laps back to back); each pack step takes the mean of the lap's piecewise-constant
   battery terminal power over its time window (the cumulative energy interpolated at the
   step's ends, so the energy is exact; a step that straddles two laps takes the end of one
   and the start of the next) plus the cooling loop's electrical power (pump, fan, chiller: a
   bus load the pack carries). At each step the BMS's limits of *that* step apply, and no
   discharge while the pack's mean SOC is at or below the vehicle's ``[battery] soc_min`` (nor
   charge at ``soc_max``): a stint that empties the pack goes on charge-sustaining, deploying
   only what it harvests.
4. **Recomputing the lap when the limits change.** Where a pack step asks for more current
   than that step's BMS discharge limit (the pack heated, or its SOC fell, during the lap), the
   lap is recomputed from the pack's state at the start of the lap with the deployment at the
   samples of that step's window scaled by ``I_lim / I_asked`` (at most ``iterations``
   passes; a lap's deployment only ever decreases). Currents still above a limit after the
   last pass, and charge currents above the BMS's charge limit (regeneration beyond it goes to
   the friction brakes), are clamped to the limit and reported (``clamped_s``, the discharge
   energy asked but not given ``clamped_energy_j``, ``regen_clamped_s``): the lap's time is
   then a little optimistic. Most clamps come at the SOC floor, where the SOC hovers about
   ``soc_min``: there the cooling loop's own load (pump, fan, chiller) is refused by the pack
   and is carried by the engine through the machine (``clamped_cooling_j``, the part of the
   clamped energy that is cooling load; it is not in the lap's fuel).
5. **Trial passes.** With module ROMs, a pass that may not be the lap's last one steps the
   pack without the ROMs' hot-spot search (records only: it drives neither the BMS nor the
   cells; :meth:`~hevsim.battery.bms.PackRun.skip_hot_spots`); the pass that turns out to be
   the last is stepped again from the lap's start with it, so the kept run is the same bit for
   bit. A further pass keeps the previous pass's operating-point search at the samples that
   are the same (``simulate_lap(..., reuse=)``).

An optimal deployment over the lap (issue 29 item 3) can replace step 1's constant limit: the
lap takes any ``battery_power_max_w`` profile (``deployment=`` of :func:`simulate_stint`, a
function of the lap's start state returning the profile or a :class:`DeploymentPlan`);
:func:`hevsim.optimal.stint_deploy.simulate_stint_optimized` re-solves the optimal deployment
with the BMS's power limits and the pack's SOC at the start of a lap when they changed.

Outputs per lap: lap time (and its loss against the unlimited lap), SOC at start and end, peak
cell temperature, time derated by the BMS (temperature factor < 1), time the lap's deployment
limit bound, cooling energy, energy by source (fuel, battery chemical energy of the lap's
power flow, the pack's terminal energy), and the pack's own energy balance over the lap
(residual / throughput, :meth:`hevsim.battery.pack.Pack.energy`).

Limits of the method: the envelope and the lap's operating points hold the nominal battery's
OCV at the stint's initial SOC (the pack's own SOC, voltages and currents are the ones that
count: its BMS limits are checked at every pack step); the cooling power is drawn from the pack
on top of the lap's battery power (it does not change the engine's operating point).
"""

from __future__ import annotations

import copy
import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from hevsim.errors import ConfigError
from hevsim.sim.lap import DEPLOYMENT_LEVELS, LapResult, LapVehicle, lap_vehicle, simulate_lap
from hevsim.tracks import DEFAULT_STEP_M, Track, load_track

STINT_DT_S = 1.0
"""Default pack step of a stint [s]."""
ITERATIONS = 3
"""Default largest number of passes of a lap (module docstring, item 4) [-]."""
ENVELOPE_LEVELS = DEPLOYMENT_LEVELS
"""Finite battery power limits (evenly from 0 to the nominal battery's ``OCV x I_max``) of the
stint's envelope; an unlimited row is added on top [-]."""
LIMIT_RTOL = 1e-3
"""Relative excess of a pack step's current over its BMS discharge limit that triggers a new
pass of the lap [-]; the recomputed deployment keeps this margin below the limit."""
DT_RANGE_S = (0.01, 10.0)
"""Accepted pack steps [s]."""


@dataclass
class StintResult:
    """A stint: ``laps`` (one row per lap, units in the column names), ``timeseries`` (one
    row per pack step: stint time, lap, the lap's asked power and the pack's channels),
    ``summary`` (scalars), ``metadata`` and the last pass of every lap (``lap_results``)."""

    laps: pd.DataFrame
    timeseries: pd.DataFrame
    summary: dict[str, Any]
    lap_results: list[LapResult]
    metadata: dict[str, Any] = field(default_factory=dict)

    def format(self) -> str:
        """The per-lap table and the summary as text."""
        cols = {
            "lap": "{:d}",
            "lap_time_s": "{:.3f}",
            "time_loss_s": "{:.3f}",
            "soc_start": "{:.3f}",
            "soc_end": "{:.3f}",
            "peak_cell_temp_c": "{:.1f}",
            "derated_s": "{:.0f}",
            "limited_s": "{:.1f}",
            "cooling_energy_kj": "{:.1f}",
            "fuel_kg": "{:.3f}",
            "passes": "{:d}",
        }
        if "reoptimized" in self.laps:
            cols["reoptimized"] = "{:d}"
        t = self.laps.assign(cooling_energy_kj=self.laps["cooling_energy_j"] / 1e3)
        head = "".join(f"{c:>18}" for c in cols)
        rows = [
            "".join(f"{f.format(int(r[c]) if f == '{:d}' else r[c]):>18}" for c, f in cols.items())
            for r in t.to_dict("records")
        ]
        s = self.summary
        tail = [
            f"total time {s['total_time_s']:.3f} s over {s['laps']} laps; peak cell "
            f"{s['peak_cell_temp_c']:.1f} degC; derated {s['derated_s']:.0f} s; cooling "
            f"{s['cooling_energy_j'] / 1e3:.1f} kJ; worst lap energy balance "
            f"{s['max_energy_balance_relative']:.1e} of the throughput"
        ]
        return "\n".join([head, *rows, *tail])

    def save(self, out_dir: str | Path, plots: bool = True, force: bool = False) -> Path:
        """Write laps.csv, pack.csv, summary.json, metadata.json and, with ``plots``,
        lap_time.png, cell_temperature.png and speed.png, atomically."""
        from hevsim.io import atomic_directory, write_json

        with atomic_directory(out_dir, force=force) as tmp:
            self.laps.to_csv(tmp / "laps.csv", index=False, float_format="%.9g")
            self.timeseries.to_csv(tmp / "pack.csv", index=False, float_format="%.6g")
            write_json(tmp / "summary.json", self.summary)
            write_json(tmp / "metadata.json", self.metadata)
            if plots:
                self.plot(tmp)
        return Path(out_dir)

    def plot(self, folder: str | Path) -> None:
        """lap_time.png (lap time and peak cell temperature vs lap), cell_temperature.png
        (hottest cell, coolant and derating factor vs stint time) and speed.png (each lap's
        speed vs distance)."""
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        from hevsim.io import save_png

        folder = Path(folder)
        lp = self.laps
        fig, ax = plt.subplots(figsize=(7, 4))
        ax.plot(lp["lap"], lp["lap_time_s"], "o-", color="C0", label="lap time")
        ax.set_xlabel("lap")
        ax.set_ylabel("lap time [s]", color="C0")
        ax.grid(True)
        ax2 = ax.twinx()
        ax2.plot(lp["lap"], lp["peak_cell_temp_c"], "s--", color="C3", label="peak cell temperature")
        ax2.set_ylabel("peak cell temperature [degC]", color="C3")
        ax.set_title(f"{self.summary['vehicle']} on {self.summary['track']}: stint of {len(lp)} laps")
        fig.tight_layout()
        save_png(fig, folder / "lap_time.png", 100)
        plt.close(fig)
        ts = self.timeseries
        fig, ax = plt.subplots(figsize=(9, 4))
        ax.plot(ts["stint_time_s"], ts["hottest_cell_temp_k"] - 273.15, label="hottest cell")
        ax.plot(ts["stint_time_s"], ts["coolant_loop_temp_k"] - 273.15, label="coolant loop")
        ax.set_xlabel("stint time [s]")
        ax.set_ylabel("temperature [degC]")
        ax.grid(True)
        ax2 = ax.twinx()
        ax2.plot(ts["stint_time_s"], ts["derating_factor"], ":", color="k", lw=0.8, label="BMS factor")
        ax2.set_ylabel("BMS temperature factor [-]")
        ax2.set_ylim(-0.05, 1.05)
        ax.legend(loc="lower right")
        fig.tight_layout()
        save_png(fig, folder / "cell_temperature.png", 100)
        plt.close(fig)
        fig, ax = plt.subplots(figsize=(10, 4))
        cmap = plt.get_cmap("viridis")
        n = max(len(self.lap_results) - 1, 1)
        for k, lap in enumerate(self.lap_results):
            t = lap.timeseries
            ax.plot(t["distance_m"], t["speed_mps"] * 3.6, color=cmap(k / n), lw=0.8, label=f"lap {k + 1}")
        ax.set_xlabel("distance [m]")
        ax.set_ylabel("speed [km/h]")
        ax.grid(True)
        if len(self.lap_results) <= 12:
            ax.legend(fontsize=7, ncol=2)
        fig.tight_layout()
        save_png(fig, folder / "speed.png", 100)
        plt.close(fig)


@dataclass
class DeploymentPlan:
    """What a ``deployment`` callable of :func:`simulate_stint` may return instead of a bare
    power: the lap's deployment ``battery_power_max_w`` (the largest battery chemical power [W]
    at each sample or everywhere) and ``info``, scalars added to the lap's row of the per-lap
    table (e.g. whether the deployment was re-optimised and the limits it was solved for)."""

    battery_power_max_w: Any
    info: dict[str, Any] = field(default_factory=dict)


@dataclass
class _Carry:
    """The part of a pack step already driven at the end of the previous lap: time [s] and
    terminal energy [J] (the pack step that straddles two laps)."""

    time_s: float = 0.0
    energy_j: float = 0.0


def check_laps(laps: Any) -> int:
    """The number of laps of a stint, checked (a whole number >= 1)."""
    if isinstance(laps, bool) or not isinstance(laps, int | np.integer) or laps < 1:
        raise ConfigError(f"option --laps = {laps!r}: expected a whole number of laps >= 1.")
    return int(laps)


def _check_options(cfg: Any, dt_s: float, iterations: int, soc: float | None) -> None:
    if cfg.battery.model != "pack":
        raise ConfigError(
            f"{cfg.name}: key 'battery.model' = {cfg.battery.model!r}; a stint steps the whole pack "
            "(cells, thermal model, cooling loop, BMS) lap after lap, so it needs [battery] model = "
            "'pack' and pack = '<pack file>' (e.g. examples/high_performance_parallel_hev_pack.toml); "
            "for one lap at a held SOC use `hevsim lap`."
        )
    lo, hi = DT_RANGE_S
    if not (math.isfinite(dt_s) and lo <= dt_s <= hi):
        raise ConfigError(f"option --dt = {dt_s!r} s: expected a pack step between {lo:g} and {hi:g} s.")
    if isinstance(iterations, bool) or not isinstance(iterations, int | np.integer) or iterations < 1:
        raise ConfigError(f"option iterations = {iterations!r}: expected a whole number >= 1.")
    if soc is not None and not (math.isfinite(soc) and 0.0 < soc < 1.0):
        raise ConfigError(f"option --soc = {soc!r}: expected an initial SOC between 0 and 1.")


def stint_vehicle(model: Any, soc: float, levels: int = ENVELOPE_LEVELS) -> tuple[LapVehicle, float, float]:
    """(the :class:`~hevsim.sim.lap.LapVehicle` of a stint with one envelope row per battery
    chemical power limit ``0 .. OCV x I_max`` in ``levels`` steps plus the unlimited row, the
    nominal battery's OCV [V] at ``soc`` and its discharge current limit [A])."""
    from hevsim.sim.performance import wheel_force_envelope

    env = wheel_force_envelope(model, np.array([1.0]), soc)
    bat = env.model.battery
    ocv = float(np.asarray(bat.ocv(soc)))
    i_max = float(bat.max_discharge_current_a)
    p_top = ocv * i_max
    lv = lap_vehicle(model, soc=soc, battery_levels_w=np.r_[np.linspace(0.0, p_top, levels), np.inf])
    return lv, ocv, i_max


def _lap_power(lap: LapResult) -> tuple[np.ndarray, np.ndarray]:
    """(sample start times with the lap's end appended [s], cumulative battery terminal energy
    at those times [J]) of a lap."""
    ts = lap.timeseries
    dt = ts["dt_s"].to_numpy()
    p = ts["battery_power_w"].to_numpy() if "battery_power_w" in ts else np.zeros(dt.size)
    return np.r_[0.0, np.cumsum(dt)], np.r_[0.0, np.cumsum(p * dt)]


def _drive_pack(
    run: Any,
    lap: LapResult,
    carry: _Carry,
    begun: bool,
    dt_s: float,
    soc_min: float,
    soc_max: float,
) -> tuple[list[dict[str, float]], _Carry]:
    """Step ``run`` along ``lap`` (module docstring, item 3). Returns one dict per pack step
    completed during the lap (the window's start and end in lap time [s], the asked terminal
    power [W] (the lap's mean battery power over the window + the cooling power [W]) and
    current [A], the BMS's available discharge/charge current [A], the current
    used [A]) and the carry into the next lap."""
    t_nodes, e_nodes = _lap_power(lap)
    tau = float(t_nodes[-1])
    first = dt_s - carry.time_s
    n = math.floor((tau - first) / dt_s + 1e-9) + 1 if tau >= first - 1e-12 else 0
    ends = first + dt_s * np.arange(n)
    e_ends = np.interp(ends, t_nodes, e_nodes)
    energy = np.diff(np.r_[0.0, e_ends])
    if n:
        energy[0] += carry.energy_j
    steps = []
    for j in range(n):
        if not (begun and j == 0):
            run.begin()
        lim = run.limits
        soc = run.soc
        cooling_w = run.cooling_w
        p_ask = float(energy[j] / dt_s) + cooling_w
        i_ask = run.current_for_power(p_ask)
        i_dis = lim.discharge_a if soc > soc_min else 0.0
        i_chg = lim.charge_a if soc < soc_max else 0.0
        i_use = min(max(i_ask, -i_chg), i_dis)
        run.finish_current(i_use)
        steps.append(
            {
                "t0": float(ends[j] - dt_s),
                "t1": float(ends[j]),
                "power_asked_w": p_ask,
                "cooling_asked_w": cooling_w,
                "current_asked_a": i_ask,
                "discharge_available_a": i_dis,
                "charge_available_a": i_chg,
                "current_a": i_use,
            }
        )
    if n:
        new = _Carry(tau - float(ends[-1]), float(e_nodes[-1] - e_ends[-1]))
    else:
        new = _Carry(carry.time_s + tau, carry.energy_j + float(e_nodes[-1]))
    return steps, new


def _lower_deployment(limit: np.ndarray, lap: LapResult, steps: list[dict[str, float]]) -> bool:
    """Lower the deployment ``limit`` [W] in place where a pack step asked for more than its
    BMS discharge current (module docstring, item 4); True when it changed."""
    ts = lap.timeseries
    t = ts["time_s"].to_numpy()
    t_end = t + ts["dt_s"].to_numpy()
    chem = np.maximum(ts["battery_chemical_power_w"].to_numpy(), 0.0)
    changed = False
    for s in steps:
        ask, avail = s["current_asked_a"], s["discharge_available_a"]
        if ask <= avail * (1.0 + LIMIT_RTOL) + 1e-9:
            continue
        ratio = max(avail, 0.0) / ask * (1.0 - LIMIT_RTOL)
        win = (t_end > s["t0"]) & (t < s["t1"])
        win &= chem > 0.0  # the discharging samples of the window
        new = np.minimum(limit[win], chem[win] * ratio)
        if np.any(new < limit[win]):
            limit[win] = new
            changed = True
    return changed


def simulate_stint(
    model: Any,
    track: Track | str | Path,
    laps: int,
    *,
    step_m: float = DEFAULT_STEP_M,
    dt_s: float = STINT_DT_S,
    soc_initial: float | None = None,
    ambient_temp_c: float | None = None,
    soak: bool = False,
    cooling_off: bool = False,
    iterations: int = ITERATIONS,
    levels: int = ENVELOPE_LEVELS,
    deployment: Callable[[Any, Track], Any] | None = None,
    vehicle: tuple[LapVehicle, float, float] | None = None,
    full_passes: bool = False,
    pack_changes: Mapping[str, Any] | None = None,
) -> StintResult:
    """A stint of ``laps`` laps of a ``[battery] model = "pack"`` vehicle (file, configuration
    or built model) on ``track`` (module docstring).

    ``step_m`` [m]: the lap's distance step; ``dt_s`` [s]: the pack's step; ``soc_initial``
    [-]: the pack's initial SOC (default ``[simulation] soc_initial``); ``ambient_temp_c``
    [degC], ``soak``, ``cooling_off``: as :func:`hevsim.sim.pack_vehicle.vehicle_pack_config`;
    ``iterations``: passes of a lap at most; ``levels``: finite envelope rows;
    ``deployment``: optional ``f(pack_run, track) -> battery_power_max_w`` (a number or one
    power [W] per sample) taking the place of the BMS's limit at the start of each lap (the
    pack's limits along the lap still apply); ``vehicle``: a :func:`stint_vehicle` already
    built for ``model`` (several stints of one car share it); ``full_passes``: step every pass
    in full, without item 5's shortcuts (the module ROMs' hot-spot search in every pass, each
    pass's operating points computed afresh: the same results, slower; the reference of
    ``benchmarks/bench_lap.py``); ``pack_changes``: dotted keys of the pack file set for this
    stint (another cooling design: ``{"cooling.chiller": 0}``; see
    :func:`hevsim.sim.pack_vehicle.vehicle_pack_config`)."""
    from threadpoolctl import threadpool_limits

    from hevsim.config import load_vehicle_config
    from hevsim.sim.pack_vehicle import make_pack_run

    t_start = time.perf_counter()
    n_laps = check_laps(laps)
    if isinstance(model, str | Path):
        model = load_vehicle_config(model)
    cfg = getattr(model, "config", model)
    _check_options(cfg, float(dt_s), iterations, soc_initial)
    trk = track if isinstance(track, Track) else load_track(track, step_m=step_m)
    soc0 = float(cfg.simulation.soc_initial if soc_initial is None else soc_initial)
    run = make_pack_run(
        cfg, float(dt_s), soc0, ambient_temp_c=ambient_temp_c, soak=soak, cooling_off=cooling_off,
        pack_changes=pack_changes,
    )  # fmt: skip
    soc_min, soc_max = float(cfg.battery.soc_min), float(cfg.battery.soc_max)
    lv, ocv, i_max = vehicle if vehicle is not None else stint_vehicle(model, soc0, levels)
    with threadpool_limits(1, user_api="blas"):
        free = simulate_lap(model, trk, step_m=trk.step_m, vehicle=lv, battery_power_max_w=np.inf)
        if free.lap_time_s < 2.0 * dt_s:
            raise ConfigError(
                f"option --dt = {dt_s!r} s: the pack's step is longer than half a lap of '{trk.name}' "
                f"({free.lap_time_s:.2f} s); expected a step of at most {0.5 * free.lap_time_s:.3g} s."
            )
        rows, records, results = [], [], []
        carry, clock = _Carry(), 0.0
        e_prev = run.energy()
        rom = bool(run.has_rom) and not full_passes
        for k in range(n_laps):
            start = run
            probe = copy.deepcopy(start)
            probe.begin()
            lim = probe.limits
            soc_lap0 = start.soc
            info: dict[str, Any] = {}
            if deployment is not None:
                plan = deployment(probe, trk)
                if isinstance(plan, DeploymentPlan):
                    info, plan = dict(plan.info), plan.battery_power_max_w
                limit = np.array(np.broadcast_to(np.asarray(plan, np.float64), trk.distance_m.shape))
            else:
                i_avail = lim.discharge_a
                p0 = math.inf if i_avail >= i_max * (1.0 - 1e-12) else ocv * i_avail
                limit = np.full(trk.distance_m.size, p0)
            passes = 0
            lap: LapResult | None = None
            while True:
                passes += 1
                work = probe if passes == 1 else copy.deepcopy(start)
                trial = rom and passes < iterations  # maybe not the last pass (item 5)
                if trial:
                    work.skip_hot_spots()
                lap = (
                    free
                    if np.all(np.isinf(limit))
                    else simulate_lap(
                        model,
                        trk,
                        step_m=trk.step_m,
                        vehicle=lv,
                        battery_power_max_w=limit,
                        reuse=None if full_passes else lap,
                    )
                )  # a further pass keeps the previous one's operating points where its samples are the same
                steps, new_carry = _drive_pack(work, lap, carry, passes == 1, float(dt_s), soc_min, soc_max)
                if passes >= iterations or not _lower_deployment(limit, lap, steps):
                    if trial:  # the last pass after all: its records count, so again with the hot spots
                        work = copy.deepcopy(start)
                        steps, new_carry = _drive_pack(work, lap, carry, False, float(dt_s), soc_min, soc_max)
                    break
            run, carry = work, new_carry
            e_now = run.energy()
            e_lap = {key: e_now[key] - e_prev[key] for key in e_now if key != "residual_relative"}
            e_prev = e_now
            rows.append(
                {**_lap_row(k, lap, free, steps, e_lap, run, soc_lap0, limit, passes, float(dt_s)), **info}
            )
            for s in steps:
                records.append({"stint_time_s": clock + s["t1"], "lap": k + 1, **s})
            clock += lap.lap_time_s
            results.append(lap)
    laps_df = pd.DataFrame(rows)
    n_rec = len(records)
    rec = pd.DataFrame(records).drop(columns=["t0", "t1"]) if n_rec else pd.DataFrame()
    pack_ts = run.frame(n_rec) if n_rec else pd.DataFrame()
    timeseries = pd.concat([rec.reset_index(drop=True), pack_ts.reset_index(drop=True)], axis=1)
    summary = _summary(cfg, trk, laps_df, free, run, timeseries, float(dt_s))
    summary["wall_time_s"] = time.perf_counter() - t_start
    pc = run.pack.cfg
    meta = {
        "config": cfg.name,
        "track_source": trk.source,
        "pack": pc.name,
        "n_cells": run.pack.n_cells,
        "thermal": pc.module.thermal,
        "ambient_temp_c": pc.pack.ambient_temp_c,
        "initial_temp_c": pc.pack.initial_temp_c,
        "cooling_controller": pc.controller.kind,
        "cooling_off": bool(cooling_off),
        "pack_changes": dict(pack_changes or {}),
        "soak": bool(soak),
        "pack_dt_s": float(dt_s),
        "lap_step_m": trk.step_m,
        "envelope_soc": float(lv.envelope.soc),
        "nominal_ocv_v": ocv,
        "nominal_max_current_a": i_max,
        "iterations": int(iterations),
        "deployment": str(getattr(deployment, "label", "custom"))
        if deployment is not None
        else "BMS limit at the start of each lap",
    }
    return StintResult(laps_df, timeseries, summary, results, meta)


def _lap_row(
    k: int, lap: LapResult, free: LapResult, steps: list[dict[str, float]], e: dict[str, float], run: Any,
    soc0: float, limit: np.ndarray, passes: int, dt_s: float,
) -> dict[str, Any]:  # fmt: skip
    """One row of the per-lap table."""
    n = len(steps)
    rows = run.rows
    sl = slice(len(rows["derating_factor"]) - n, None)
    hot = np.asarray(rows["hottest_cell_temp_k"][sl])
    factor = np.asarray(rows["derating_factor"][sl])
    ts = lap.timeseries
    dt = ts["dt_s"].to_numpy()
    chem = ts["battery_chemical_power_w"].to_numpy()
    fin = np.isfinite(limit)
    bound = fin & (chem >= np.where(fin, limit, 0.0) * (1.0 - 1e-3) - 1.0)
    i_ask = np.array([s["current_asked_a"] for s in steps])
    i_use = np.array([s["current_a"] for s in steps])
    clamp = np.abs(i_use - i_ask) > 1e-9 * np.maximum(1.0, np.abs(i_ask))
    p_ask = np.array([s["power_asked_w"] for s in steps])
    p_out = np.asarray(rows["pack_power_w"][sl])
    short = np.where(clamp & (i_ask > 0.0), p_ask - p_out, 0.0)
    cool = np.array([s["cooling_asked_w"] for s in steps])
    short_j = float(np.sum(short) * dt_s)
    short_cooling_j = float(np.sum(np.minimum(short, cool)) * dt_s)
    cooling = e["pump_work_j"] + e["chiller_electric_j"] + e["fan_electric_j"]
    s = lap.summary
    return {
        "lap": k + 1,
        "lap_time_s": lap.lap_time_s,
        "time_loss_s": lap.lap_time_s - free.lap_time_s,
        "soc_start": soc0,
        "soc_end": run.soc,
        "peak_cell_temp_c": float(hot.max() - 273.15) if n else math.nan,
        "end_cell_temp_c": float(hot[-1] - 273.15) if n else math.nan,
        "derated_s": float(np.sum(factor < 1.0) * dt_s),
        "limited_s": float(dt[bound].sum()),
        "min_deployment_kw": float(limit.min() / 1e3) if np.isfinite(limit.min()) else math.inf,
        "clamped_s": float(np.sum(clamp & (i_ask > 0.0)) * dt_s),
        "clamped_energy_j": short_j,
        "clamped_cooling_j": short_cooling_j,
        "regen_clamped_s": float(np.sum(clamp & (i_ask < 0.0)) * dt_s),
        "cooling_energy_j": float(cooling),
        "fuel_kg": float(s.get("fuel_kg", 0.0)),
        "fuel_energy_j": float(s.get("fuel_energy_j", 0.0)),
        "battery_chemical_energy_j": float(s.get("battery_chemical_energy_j", 0.0)),
        "pack_terminal_energy_j": float(e["electrical_out_j"]),
        "pack_throughput_j": float(e["throughput_j"]),
        "pack_heat_stored_j": float(e["heat_stored_j"]),
        "pack_heat_removed_j": float(e["heat_to_ambient_j"] + e["heat_removed_j"]),
        "energy_balance_relative": float(e["residual_j"] / max(e["throughput_j"], 1e-300)),
        "max_speed_kmh": float(s["max_speed_kmh"]),
        "pack_steps": n,
        "passes": passes,
    }


def _summary(
    cfg: Any, trk: Track, laps: pd.DataFrame, free: LapResult, run: Any, ts: pd.DataFrame, dt_s: float
) -> dict[str, Any]:
    """Scalars of a stint."""
    first = laps.index[laps["derated_s"] > 0]
    return {
        "vehicle": cfg.name,
        "architecture": cfg.architecture,
        "track": trk.name,
        "track_length_m": trk.length_m,
        "laps": len(laps),
        "free_lap_time_s": free.lap_time_s,
        "total_time_s": float(laps["lap_time_s"].sum()),
        "fastest_lap_s": float(laps["lap_time_s"].min()),
        "slowest_lap_s": float(laps["lap_time_s"].max()),
        "peak_cell_temp_c": float(laps["peak_cell_temp_c"].max()),
        "derated_s": float(laps["derated_s"].sum()),
        "first_derated_lap": int(laps["lap"].iloc[first[0]]) if len(first) else 0,
        "first_derating_s": float(ts["stint_time_s"][ts["derating_factor"] < 1.0].min())
        if len(ts) and bool((ts["derating_factor"] < 1.0).any())
        else math.nan,
        "cooling_energy_j": float(laps["cooling_energy_j"].sum()),
        "fuel_kg": float(laps["fuel_kg"].sum()),
        "soc_start": float(laps["soc_start"].iloc[0]),
        "soc_end": float(laps["soc_end"].iloc[-1]),
        "clamped_s": float(laps["clamped_s"].sum()),
        "clamped_energy_j": float(laps["clamped_energy_j"].sum()),
        "clamped_cooling_j": float(laps["clamped_cooling_j"].sum()),
        "regen_clamped_s": float(laps["regen_clamped_s"].sum()),
        "max_energy_balance_relative": float(laps["energy_balance_relative"].abs().max()),
        "stint_energy_balance_relative": float(run.energy()["residual_relative"]),
        "pack_dt_s": dt_s,
    }


__all__ = ["DeploymentPlan", "StintResult", "check_laps", "simulate_stint", "stint_vehicle"]
