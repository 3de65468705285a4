"""A stint with the pack over cooling designs and ambient temperatures (issue 29 item 4).

The shipped high-performance parallel HEV with its whole pack
(``examples/high_performance_parallel_hev_pack.toml``: 108s3p Saft 6 Ah cells, coolant ports,
cooling loop with a chiller, BMS derating from 45 degC) runs ``--laps`` laps of ``--track``
(default 10 laps of Monza) at two ambients (``--ambients``, default 20 and 35 degC; the pack
and the coolant soaked at the ambient) with three cooling designs: the shipped loop (pump 30
L/min, radiator, 6 kW chiller switched on at 35 degC), the same loop without its chiller
(radiator only: ``pack_changes={"cooling.chiller": 0}``) and the cooling off (no pump, fan nor
chiller). Each case is :func:`hevsim.sim.stint.simulate_stint`; the car's envelope is built
once and shared.

Writes into ``--out`` (default results/stint_study), atomically: ``stint_table.csv`` (one row
per case and lap: lap time, peak cell temperature, time derated, time the lap's deployment
bound, cooling energy, SOC at start and end), ``summary.csv`` (one row per case),
``report.md`` (the tables as markdown) and ``stint.png`` (lap time and peak cell temperature vs
lap for every case).

Re-optimising the deployment (with ``--optimize convex`` or ``dp``, default convex; ``none``
skips it): at the hotter ambient with the cooling off, the same stint driving the optimal
charge-sustaining deployment of :mod:`hevsim.optimal.stint_deploy`, solved once before the
first lap and held (``reoptimize_rtol = inf``), and re-solved with the BMS's power limits at
the start of each lap whenever they changed by more than 2 %
(:func:`~hevsim.optimal.stint_deploy.simulate_stint_optimized`): ``reoptimize_table.csv`` (per
lap: both lap times, the gain, the lap-start discharge limit, the limit the held map was solved
for, peak cell temperature, time derated, SOC, re-optimised or not) and its section in
``report.md``.

    python examples/stint_study/run_stint_study.py [--laps 10] [--track monza] [--out results/stint_study]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import pandas as pd

from hevsim.config import load_vehicle_config
from hevsim.io import atomic_directory, save_png
from hevsim.sim.stint import simulate_stint, stint_vehicle
from hevsim.tracks import load_track

HERE = Path(__file__).resolve().parent
CAR = HERE.parent / "high_performance_parallel_hev_pack.toml"
DESIGNS: dict[str, dict[str, object]] = {
    "loop + chiller": {},
    "loop, no chiller": {"pack_changes": {"cooling.chiller": 0}},
    "cooling off": {"cooling_off": True},
}
"""Cooling design label -> the stint's options that make it (the pack file's loop as shipped,
without its chiller, or everything off)."""


def run(laps: int, track_name: str, ambients: list[float]) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(per-lap table, per-case summary) of every ambient x cooling design."""
    cfg = load_vehicle_config(CAR)
    track = load_track(track_name, step_m=1.0)
    vehicle = stint_vehicle(cfg, cfg.simulation.soc_initial)
    rows, cases = [], []
    for amb in ambients:
        for design, design_opts in DESIGNS.items():
            t0 = time.perf_counter()
            opts = {"ambient_temp_c": amb, "soak": True, **design_opts}
            res = simulate_stint(cfg, track, laps, vehicle=vehicle, **opts)
            s = res.summary
            print(
                f"{amb:5.1f} degC, {design:<15} {time.perf_counter() - t0:6.1f} s: laps "
                f"{s['fastest_lap_s']:.2f} .. {s['slowest_lap_s']:.2f} s, "
                f"peak cell {s['peak_cell_temp_c']:.1f} degC"
            )
            lp = res.laps
            rows.append(
                pd.DataFrame(
                    {
                        "ambient_c": amb,
                        "cooling": design,
                        "lap": lp["lap"],
                        "lap_time_s": lp["lap_time_s"].round(3),
                        "time_loss_s": lp["time_loss_s"].round(3),
                        "peak_cell_temp_c": lp["peak_cell_temp_c"].round(2),
                        "derated_s": lp["derated_s"],
                        "deployment_bound_s": lp["limited_s"].round(2),
                        "cooling_energy_kj": (lp["cooling_energy_j"] / 1e3).round(1),
                        "soc_start": lp["soc_start"].round(4),
                        "soc_end": lp["soc_end"].round(4),
                        "fuel_kg": lp["fuel_kg"].round(4),
                        "energy_balance_relative": lp["energy_balance_relative"],
                    }
                )
            )
            cases.append(
                {
                    "ambient_c": amb,
                    "cooling": design,
                    "laps": laps,
                    "free_lap_s": round(s["free_lap_time_s"], 3),
                    "total_time_s": round(s["total_time_s"], 3),
                    "fastest_lap_s": round(s["fastest_lap_s"], 3),
                    "slowest_lap_s": round(s["slowest_lap_s"], 3),
                    "peak_cell_temp_c": round(s["peak_cell_temp_c"], 2),
                    "first_derating_s": s["first_derating_s"],
                    "derated_s": s["derated_s"],
                    "cooling_energy_kj": round(s["cooling_energy_j"] / 1e3, 1),
                    "fuel_kg": round(s["fuel_kg"], 3),
                    "clamped_s": s["clamped_s"],
                    "clamped_energy_kj": round(s["clamped_energy_j"] / 1e3, 1),
                    "of_it_cooling_kj": round(s["clamped_cooling_j"] / 1e3, 1),
                    "soc_end": round(s["soc_end"], 4),
                    "max_energy_balance_relative": s["max_energy_balance_relative"],
                }
            )
    return pd.concat(rows, ignore_index=True), pd.DataFrame(cases)


def reoptimize(laps: int, track_name: str, ambient: float, method: str) -> pd.DataFrame:
    """Per-lap table of the optimal deployment held and re-solved (module docstring), at
    ``ambient`` [degC] with the cooling off."""
    import math

    from hevsim.optimal.lap_deploy import build_problem
    from hevsim.optimal.stint_deploy import DEPLOY_STEP_M, simulate_stint_optimized

    cfg = load_vehicle_config(CAR)
    track = load_track(track_name, step_m=1.0)
    soc0 = cfg.simulation.soc_initial
    vehicle = stint_vehicle(cfg, soc0)
    prob, _ = build_problem(cfg, track.resampled(DEPLOY_STEP_M), step_m=DEPLOY_STEP_M, soc=soc0)
    opts = {"ambient_temp_c": ambient, "soak": True, "cooling_off": True, "method": method}
    out = {}
    for label, rtol in (("held", math.inf), ("re-solved", 0.02)):
        t0 = time.perf_counter()
        res = simulate_stint_optimized(
            cfg, track, laps, problem=prob, vehicle=vehicle, reoptimize_rtol=rtol, **opts
        )
        s = res.summary
        print(
            f"{ambient:5.1f} degC, cooling off, optimal deployment {label:<9} "
            f"{time.perf_counter() - t0:6.1f} s: total {s['total_time_s']:.2f} s, "
            f"{s['deploy_solves']} solves, peak cell {s['peak_cell_temp_c']:.1f} degC"
        )
        out[label] = res.laps
    held, again = out["held"], out["re-solved"]
    return pd.DataFrame(
        {
            "lap": again["lap"],
            "lap_time_held_s": held["lap_time_s"].round(3),
            "lap_time_resolved_s": again["lap_time_s"].round(3),
            "gain_s": (held["lap_time_s"] - again["lap_time_s"]).round(3),
            "lap_start_limit_kw": again["lap_start_discharge_limit_kw"].round(1),
            "held_map_limit_kw": held["deploy_discharge_limit_kw"].round(1),
            "reoptimized": again["reoptimized"],
            "peak_cell_held_c": held["peak_cell_temp_c"].round(2),
            "peak_cell_resolved_c": again["peak_cell_temp_c"].round(2),
            "derated_resolved_s": again["derated_s"],
            "soc_end_held": held["soc_end"].round(4),
            "soc_end_resolved": again["soc_end"].round(4),
            "max_energy_balance_relative": np.maximum(
                held["energy_balance_relative"].abs(), again["energy_balance_relative"].abs()
            ),
        }
    )


def markdown(df: pd.DataFrame) -> str:
    """A data frame as a markdown table (no extra dependency)."""
    rows = df.itertuples(index=False)
    cells = [[f"{v:.4g}" if isinstance(v, float) else str(v) for v in row] for row in rows]
    head = "| " + " | ".join(df.columns) + " |"
    rule = "|" + "|".join("---" for _ in df.columns) + "|"
    return "\n".join([head, rule, *("| " + " | ".join(r) + " |" for r in cells)])


def plot(table: pd.DataFrame, path: Path) -> None:
    """Lap time and peak cell temperature vs lap, one line per case."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4))
    for (amb, design), g in table.groupby(["ambient_c", "cooling"], sort=False):
        style = {"loop + chiller": "-", "loop, no chiller": "-."}.get(design, "--")
        label = f"{amb:g} degC, {design}"
        a1.plot(g["lap"], g["lap_time_s"], style, marker="o", label=label)
        a2.plot(g["lap"], g["peak_cell_temp_c"], style, marker="s", label=label)
    a1.set_xlabel("lap")
    a1.set_ylabel("lap time [s]")
    a2.set_xlabel("lap")
    a2.set_ylabel("peak cell temperature [degC]")
    for ax in (a1, a2):
        ax.grid(True)
    a1.legend(fontsize=8)
    fig.tight_layout()
    save_png(fig, path, 100)
    plt.close(fig)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--laps", type=int, default=10)
    ap.add_argument("--track", default="monza")
    ap.add_argument("--ambients", type=float, nargs=2, default=[20.0, 35.0])
    ap.add_argument("--out", default="results/stint_study")
    ap.add_argument("--force", action="store_true", help="replace a folder at --out hevsim did not write")
    ap.add_argument("--optimize", choices=("convex", "dp", "none"), default="convex")
    a = ap.parse_args()
    table, summary = run(a.laps, a.track, list(a.ambients))
    reopt = None if a.optimize == "none" else reoptimize(a.laps, a.track, max(a.ambients), a.optimize)
    with atomic_directory(a.out, force=a.force) as tmp:
        table.to_csv(tmp / "stint_table.csv", index=False)
        summary.to_csv(tmp / "summary.csv", index=False)
        text = [
            f"# Stint of {a.laps} laps of {a.track}: {CAR.stem}",
            "",
            markdown(summary),
            "",
            markdown(table.drop(columns=["energy_balance_relative"])),
            "",
        ]
        if reopt is not None:
            reopt.to_csv(tmp / "reoptimize_table.csv", index=False)
            text += [
                f"## Optimal deployment ({a.optimize}) held vs re-solved: "
                f"{max(a.ambients):g} degC, cooling off",
                "",
                markdown(reopt.drop(columns=["max_energy_balance_relative"])),
                "",
            ]
        (tmp / "report.md").write_text("\n".join(text))
        plot(table, tmp / "stint.png")
    extra = "" if reopt is None else ", reoptimize_table.csv"
    print(f"results written to {a.out}/ (stint_table.csv, summary.csv{extra}, report.md, stint.png)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
