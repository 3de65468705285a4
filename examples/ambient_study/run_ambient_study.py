"""Ambient-temperature and hot-lap scenarios of the pack in the vehicle (issue 12 item 5).

Reads ``study.toml`` next to this file: every ambient x cycle of the pack vehicle (soaked at
the ambient, cooling loop on), the extra cases (40 degC US06 with the cooling off), and the
hot-lap scenario (high-performance P2 HEV, 20 launches 0-200 km/h) at its ambients. Writes
``ambient.csv``, ``hot_lap.csv``, ``hot_lap_modules.csv`` (hottest cell of every module over
time), ``hot_lap.png`` and ``report.md`` into the results folder (atomically, via
:mod:`hevsim.io`). Runs the cases on ``--workers`` processes (default 2).

    python examples/ambient_study/run_ambient_study.py [--out results/ambient_study] [--workers 2]
"""

from __future__ import annotations

import argparse
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from hevsim.config import load_vehicle_config
from hevsim.io import atomic_directory
from hevsim.schema import read_toml
from hevsim.sim.pack_vehicle import simulate_pack_vehicle

HERE = Path(__file__).resolve().parent


def run_case(case: dict[str, Any]) -> dict[str, Any]:
    """One run: the table row, and for the hot lap the per-module hottest cell over time."""
    cfg = load_vehicle_config(case["vehicle"])
    off = case.get("cooling", "on") == "off"
    t0 = time.process_time()
    res = simulate_pack_vehicle(cfg, case["cycle"], case["dt_s"], ambient_temp_c=case["ambient_c"], soak=True,
                                cooling_off=off)  # fmt: skip
    m = res.metrics
    ts = res.timeseries
    mod_cols = [c for c in ts if c.startswith("module") and c.endswith("_hottest_cell_temp_k")]
    peak_by_module = ts[mod_cols].max().to_numpy()
    hottest = int(np.argmax(peak_by_module))
    row = {
        "vehicle": cfg.name, "cycle": case["cycle"], "ambient_c": case["ambient_c"],
        "cooling": "off" if off else "on", "mpgge": m["mpgge"]["value"], "mpg": m["mpg"]["value"],
        "l_per_100km": m["l_per_100km"]["value"], "soc_final": m["soc_final"]["value"],
        "peak_cell_temp_c": m["pack_peak_cell_temp_c"]["value"],
        "cooling_energy_wh": m["pack_cooling_energy_j"]["value"] / 3600.0,
        "derated_s": m["pack_derated_s"]["value"], "first_derating_s": m["pack_first_derating_s"]["value"],
        "bms_limited_s": m["pack_bms_limited_s"]["value"],
        "hottest_module": hottest, "module_peak_spread_k": float(np.ptp(peak_by_module)),
        "max_cell_soc_spread": float(ts["cell_soc_spread"].max()),
        "pack_energy_balance_relative": m["pack_energy_balance_relative"]["value"],
        "cpu_s": time.process_time() - t0,
    }  # fmt: skip
    out: dict[str, Any] = {"row": row}
    if case.get("hot_lap"):
        out["modules"] = ts[["time_s", *mod_cols]].assign(ambient_c=case["ambient_c"])
    return out


def cases(study: dict[str, Any]) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """(ambient cases, hot-lap cases) of the study file."""
    veh = str((HERE / study["vehicle"]).resolve())
    dt = float(study.get("dt_s", 1.0))
    amb = [{"vehicle": veh, "cycle": c, "ambient_c": float(t), "dt_s": dt} for c in study["cycles"]
           for t in study["ambient_c"]]  # fmt: skip
    amb += [{"vehicle": veh, "dt_s": dt, **{k: v for k, v in e.items()}} for e in study.get("extra", [])]
    hl = study.get("hot_lap")
    hot = []
    if hl and (HERE / hl["vehicle"]).is_file():
        hv = str((HERE / hl["vehicle"]).resolve())
        hot = [{"vehicle": hv, "cycle": hl["cycle"], "ambient_c": float(t), "dt_s": dt, "hot_lap": True}
               for t in hl["ambient_c"]]  # fmt: skip
    return amb, hot


def _md(df: pd.DataFrame) -> str:
    """A Markdown table (numbers to 4 significant digits)."""
    from hevsim.report.markdown import _table, format_number

    rows = (
        [format_number(v, 4) if isinstance(v, float) else v for v in row]
        for row in df.itertuples(index=False)
    )
    return "\n".join(_table(list(df.columns), rows))


AMBIENT_COLUMNS = ["cycle", "ambient_c", "cooling", "mpgge", "peak_cell_temp_c", "cooling_energy_wh",
                   "derated_s", "first_derating_s", "bms_limited_s"]  # fmt: skip
HOT_LAP_COLUMNS = ["ambient_c", "mpgge", "peak_cell_temp_c", "hottest_module", "module_peak_spread_k",
                   "max_cell_soc_spread", "cooling_energy_wh", "derated_s", "first_derating_s",
                   "bms_limited_s"]  # fmt: skip


def report(amb: pd.DataFrame, hot: pd.DataFrame, wall_s: float, workers: int) -> str:
    """The study's report (Markdown)."""
    lines = [
        "# Ambient-temperature study of the pack in the vehicle",
        "",
        f"{amb['vehicle'].iloc[0]}: the car soaked at the ambient (cells and coolant start there), cooling "
        "loop on unless stated; fuel economy MPGGE with the SOC correction; cooling energy = pump + fan + "
        "chiller (electrical, a bus load); derated = time the BMS's temperature factor was below 1 (hot or "
        "cold); BMS-limited = time the car could not follow the trace while the BMS limited the pack. "
        f"{len(amb) + len(hot)} runs in {wall_s:.0f} s on {workers} processes.",
        "",
        _md(amb[AMBIENT_COLUMNS]),
        "",
    ]
    if len(hot):
        lines += [
            "## Hot lap",
            "",
            f"{hot['vehicle'].iloc[0]} on {hot['cycle'].iloc[0]}: where (hottest module), when (first "
            "derating) and how far the cells spread (peak temperature spread between modules, largest cell "
            "SOC spread).",
            "",
            _md(hot[HOT_LAP_COLUMNS]),
            "",
        ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--study", default=str(HERE / "study.toml"))
    ap.add_argument("--out", default="results/ambient_study")
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args(argv)
    amb_cases, hot_cases = cases(read_toml(Path(args.study)))
    t0 = time.perf_counter()
    with ProcessPoolExecutor(max_workers=args.workers) as pool:
        done = list(pool.map(run_case, hot_cases + amb_cases))
    wall = time.perf_counter() - t0
    hot = pd.DataFrame([d["row"] for d in done[: len(hot_cases)]])
    amb = pd.DataFrame([d["row"] for d in done[len(hot_cases) :]])
    text = report(amb, hot, wall, args.workers)
    with atomic_directory(args.out) as tmp:
        amb.to_csv(tmp / "ambient.csv", index=False, float_format="%.6g")
        (tmp / "report.md").write_text(text + "\n", encoding="utf-8")
        if len(hot):
            hot.to_csv(tmp / "hot_lap.csv", index=False, float_format="%.6g")
            mods = pd.concat([d["modules"] for d in done[: len(hot_cases)]], ignore_index=True)
            mods.to_csv(tmp / "hot_lap_modules.csv", index=False, float_format="%.6g")
            _plot_hot_lap(mods, tmp / "hot_lap.png")
    print(text)
    print(f"results written to {args.out}/ ({wall:.0f} s)")
    return 0


def _plot_hot_lap(mods: pd.DataFrame, path: Path) -> None:
    from hevsim.figures import figure, grid, save

    fig, axes = figure(1, 2, figsize=(12.0, 4.5), sharey=True)
    for ax, (amb, grp) in zip(np.atleast_1d(axes), mods.groupby("ambient_c"), strict=False):
        cols = [c for c in grp if c.startswith("module")]
        temps = grp[cols].to_numpy() - 273.15
        ax.fill_between(grp["time_s"], temps.min(axis=1), temps.max(axis=1), alpha=0.3, label="module range")
        ax.plot(grp["time_s"], temps.max(axis=1), color="tab:red", label="hottest cell")
        ax.axhline(45.0, color="k", ls=":", lw=0.8, label="derating starts (45 degC)")
        ax.set_title(f"hot lap at {amb:g} degC ambient")
        ax.set_xlabel("time [s]")
        grid(ax)
    np.atleast_1d(axes)[0].set_ylabel("cell temperature [degC]")
    np.atleast_1d(axes)[0].legend()
    save(fig, path)


if __name__ == "__main__":
    raise SystemExit(main())
