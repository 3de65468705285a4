"""Ambient study of the pack in a BEV and a power split (issue 24 item 7).

Reads ``pack_architectures.toml`` next to this file and runs, every case soaked at its ambient:

* the BEV (``bev_pack.toml``) on each cycle at each ambient: consumption over one cycle
  (kWh/100 km of DC energy at the pack terminals, the cooling loop and the auxiliaries
  included, net of regeneration; and the cells' chemical energy per distance, which adds the
  pack's own losses), and the range driven to empty: the cycle repeated until the
  car first falls behind the trace by more than ``range_speed_tolerance_mph`` (the battery at
  its SOC floor ``battery.soc_min``, from the file's ``soc_initial``); the one-cycle SOC
  extrapolation ``distance x (soc_initial - soc_min) / (soc_initial - soc_final)`` is listed
  beside it;
* the Prius-like power split (``prius_like_power_split_pack.toml``) on its cycle at its
  ambient with the cooling loop on and off: peak cell temperature, derated time, time held
  back by the BMS, MPGGE (SOC-corrected).

Writes ``bev.csv``, ``power_split.csv`` and ``report.md`` into the results folder
(atomically, :mod:`hevsim.io`), on ``--workers`` processes (default 2). ``--seconds``,
``--ambient``, ``--cycles`` and ``--soc-initial`` shorten the study (the test runs it on 60 s
cycles from a nearly empty battery).

    python examples/ambient_study/run_pack_architectures.py [--out results/ambient_pack_architectures]
"""

from __future__ import annotations

import argparse
import math
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from hevsim.config import load_vehicle_config
from hevsim.cycles import DriveCycle, load_cycle
from hevsim.errors import DomainError
from hevsim.io import atomic_directory
from hevsim.schema import read_toml
from hevsim.sim.pack_vehicle import simulate_pack_vehicle
from hevsim.units import MPS_PER_MPH

HERE = Path(__file__).resolve().parent


def _cycle(name: str, seconds: float | None, repeats: int = 1) -> DriveCycle:
    """Cycle ``name`` (its first ``seconds`` when given) driven ``repeats`` times end to end
    (the joining standstill shared)."""
    c = load_cycle(name)
    t, v, g = (np.asarray(a, dtype=float) for a in (c.time_s, c.speed_mps, c.grade))
    if seconds is not None:
        keep = t <= seconds
        t, v, g = t[keep], v[keep], g[keep]
    if repeats > 1:
        span = t[-1] - t[0]
        t = np.concatenate([t] + [t[1:] + k * span for k in range(1, repeats)])
        v = np.concatenate([v] + [v[1:]] * (repeats - 1))
        g = np.concatenate([g] + [g[1:]] * (repeats - 1))
    label = c.name if seconds is None else f"{c.name}_{seconds:g}s"
    return DriveCycle(label if repeats == 1 else f"{label}x{repeats}", t, v, g)


def _common(res: Any) -> dict[str, float]:
    m = res.metrics
    return {
        "peak_cell_temp_c": m["pack_peak_cell_temp_c"]["value"],
        "cooling_energy_wh": m["pack_cooling_energy_j"]["value"] / 3600.0,
        "derated_s": m["pack_derated_s"]["value"], "first_derating_s": m["pack_first_derating_s"]["value"],
        "bms_limited_s": m["pack_bms_limited_s"]["value"],
        "pack_energy_balance_relative": m["pack_energy_balance_relative"]["value"],
    }  # fmt: skip


def run_bev(case: dict[str, Any]) -> dict[str, Any]:
    """One BEV row: one cycle (consumption), then the cycle repeated until the car is empty."""
    cfg = load_vehicle_config(case["vehicle"])
    t0 = time.process_time()
    one = _cycle(case["cycle"], case.get("seconds"))
    kw = {"ambient_temp_c": case["ambient_c"], "soak": True, "soc_initial": case.get("soc_initial")}
    res = simulate_pack_vehicle(cfg, one, case["dt_s"], **kw)
    m = res.metrics
    dist_km = m["distance_m"]["value"] / 1000.0
    e_out_j = res.extra["pack_energy"]["electrical_out_j"]
    soc0, soc1, floor = m["soc_initial"]["value"], m["soc_final"]["value"], cfg.battery.soc_min
    est_km = dist_km * (soc0 - floor) / (soc0 - soc1) if soc0 > soc1 else math.inf
    row = {
        "vehicle": cfg.name, "cycle": case["cycle"], "ambient_c": case["ambient_c"],
        "kwh_per_100km": e_out_j / 3.6e6 / dist_km * 100.0,
        "cells_kwh_per_100km": -res.extra["pack_energy"]["chemical_change_j"] / 3.6e6 / dist_km * 100.0,
        "mpgge": m["mpgge"]["value"],
        "soc_final": soc1, **_common(res), "range_1cycle_km": est_km,
    }  # fmt: skip
    tol = case["range_speed_tolerance_mph"] * MPS_PER_MPH
    # repetitions: the one-cycle estimate first (the car empties in the last one); one more when it
    # did not run out (a warmer pack goes further), one fewer when it sat empty so long that the
    # pack could no longer feed the auxiliaries (DomainError: no feasible control)
    reps = max(2, math.ceil(est_km / dist_km)) if math.isfinite(est_km) else 2
    row["range_km"] = math.nan  # never ran out within the attempts (reported as such)
    tried: set[int] = set()
    while reps not in tried and len(tried) < 8:
        tried.add(reps)
        try:
            long = simulate_pack_vehicle(
                cfg, _cycle(case["cycle"], case.get("seconds"), reps), case["dt_s"], **kw
            )
        except DomainError:
            reps -= 1
            continue
        ts = long.timeseries
        behind = np.flatnonzero((ts["speed_desired_mps"] - ts["speed_mps"]).to_numpy() > tol)
        if behind.size:
            k = int(behind[0])
            v = ts["speed_mps"].to_numpy()
            row["range_km"] = float(np.sum(0.5 * (v[:k] + v[1 : k + 1])) * case["dt_s"]) / 1000.0
            row["soc_at_empty"] = float(ts["soc"].iloc[k])
            row["range_repetitions"] = reps
            break
        reps += 1
    row["cpu_s"] = time.process_time() - t0
    return row


def run_split(case: dict[str, Any]) -> dict[str, Any]:
    """One power-split row: the cycle at the ambient, cooling on or off."""
    cfg = load_vehicle_config(case["vehicle"])
    t0 = time.process_time()
    off = case["cooling"] == "off"
    res = simulate_pack_vehicle(cfg, _cycle(case["cycle"], case.get("seconds")), case["dt_s"],
                                ambient_temp_c=case["ambient_c"], soak=True, cooling_off=off)  # fmt: skip
    m = res.metrics
    return {
        "vehicle": cfg.name, "cycle": case["cycle"], "ambient_c": case["ambient_c"],
        "cooling": case["cooling"],
        "mpgge": m["mpgge"]["value"], "mpg": m["mpg"]["value"], "soc_final": m["soc_final"]["value"],
        **_common(res), "traction_limited_s": m["traction_limited_s"]["value"],
        "cpu_s": time.process_time() - t0,
    }  # fmt: skip


def cases(
    study: dict[str, Any], args: argparse.Namespace
) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """(BEV cases, power-split cases) of the study file, shortened by the options."""
    dt = float(study.get("dt_s", 1.0))
    b, s = study["bev"], study["power_split"]
    ambients = args.ambient if args.ambient else b["ambient_c"]
    cycles = args.cycles if args.cycles else b["cycles"]
    extra = {"dt_s": dt, "seconds": args.seconds}
    bev = [{"vehicle": str((HERE / b["vehicle"]).resolve()), "cycle": c, "ambient_c": float(t),
            "range_speed_tolerance_mph": float(b["range_speed_tolerance_mph"]),
            "soc_initial": args.soc_initial, **extra}
           for c in cycles for t in ambients]  # fmt: skip
    split = [{"vehicle": str((HERE / s["vehicle"]).resolve()), "cycle": s["cycle"],
              "ambient_c": float(s["ambient_c"]), "cooling": c, **extra} for c in s["cooling"]]  # fmt: skip
    return bev, split


def _md(df: pd.DataFrame) -> str:
    """A Markdown table (numbers to 4 significant digits)."""
    from hevsim.report.markdown import _table, format_number

    rows = (
        [format_number(v, 4) if isinstance(v, float) else v for v in row]
        for row in df.itertuples(index=False)
    )
    return "\n".join(_table(list(df.columns), rows))


BEV_COLUMNS = ["cycle", "ambient_c", "kwh_per_100km", "cells_kwh_per_100km", "range_km", "range_1cycle_km",
               "peak_cell_temp_c", "cooling_energy_wh", "derated_s", "bms_limited_s"]  # fmt: skip
SPLIT_COLUMNS = ["cycle", "ambient_c", "cooling", "mpgge", "soc_final", "peak_cell_temp_c", "derated_s",
                 "first_derating_s", "bms_limited_s", "cooling_energy_wh"]  # fmt: skip


def report(bev: pd.DataFrame, split: pd.DataFrame, wall_s: float, workers: int) -> str:
    """The study's report (Markdown)."""
    return "\n".join([
        "# Pack in a BEV and a power split: ambient study",
        "",
        f"{bev['vehicle'].iloc[0]}: soaked at the ambient, cooling loop on; kWh/100 km = DC energy at the "
        "pack terminals over one cycle (auxiliaries and cooling loop included, regeneration netted) per "
        "distance; cells_kwh_per_100km = the cells' chemical energy per distance (the pack's own "
        "losses added); range_km = distance driven with the cycle repeated until the car first fell "
        "behind the trace by more than 2 mph (the battery at its SOC floor); range_1cycle_km = the "
        "one-cycle SOC extrapolation; derated = time the BMS's temperature factor was below 1 (cold or "
        "hot); no cabin climate control.",
        "",
        _md(bev[BEV_COLUMNS]),
        "",
        f"{split['vehicle'].iloc[0]}: soaked at the ambient; MPGGE with the SOC correction; BMS-limited = "
        "time the car could not follow the trace while the BMS limited the pack.",
        "",
        _md(split[SPLIT_COLUMNS]),
        "",
        f"{len(bev) + len(split)} cases in {wall_s:.0f} s on {workers} processes.",
    ])  # fmt: skip


def _run(case: dict[str, Any]) -> dict[str, Any]:
    return run_split(case) if "cooling" in case else run_bev(case)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--study", default=str(HERE / "pack_architectures.toml"))
    ap.add_argument("--out", default="results/ambient_pack_architectures")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument(
        "--seconds", type=float, help="drive only the first SECONDS of each cycle (a quick check)"
    )
    ap.add_argument("--ambient", type=float, action="append", help="BEV ambient [degC] (repeatable)")
    ap.add_argument("--cycles", nargs="+", help="BEV cycles (default the study file's)")
    ap.add_argument(
        "--soc-initial", type=float, help="BEV initial SOC (default the vehicle file's; a quick check)"
    )
    args = ap.parse_args(argv)
    bev_cases, split_cases = cases(read_toml(Path(args.study)), args)
    t0 = time.perf_counter()
    todo = split_cases + bev_cases
    if args.workers > 1:
        with ProcessPoolExecutor(max_workers=args.workers) as pool:
            done = list(pool.map(_run, todo))
    else:
        done = [_run(c) for c in todo]
    wall = time.perf_counter() - t0
    split = pd.DataFrame(done[: len(split_cases)])
    bev = pd.DataFrame(done[len(split_cases) :])
    text = report(bev, split, wall, args.workers)
    with atomic_directory(args.out) as tmp:
        bev.to_csv(tmp / "bev.csv", index=False, float_format="%.6g")
        split.to_csv(tmp / "power_split.csv", index=False, float_format="%.6g")
        (tmp / "report.md").write_text(text + "\n", encoding="utf-8")
    print(text)
    print(f"results written to {args.out}/ ({wall:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
