"""Study throughput on Dask against ``simulate_batch`` in one process (issue 17).

Run from the repository root; the full-size benchmarks of issue 17 are::

    .venv/bin/python benchmarks/bench_study.py --cases 100000 --workers 2
    .venv/bin/python benchmarks/bench_study.py --cases 0 --dp-cases 200 --dp-grid 400

(on a loaded 2-core machine the 200-case DP study at 400 x 400 takes about 1 h on one worker:
``--dp-cases 16`` runs 16 cases and prints the 200-case figures EXTRAPOLATED from them, marked
as such; ``--dp-workers 2`` runs the 2-worker study only).

What is timed (``time.perf_counter``; the numba cache is warmed first):

(a) baseline: ``simulate_batch`` of the series HEV (rule-based) on UDDS with ``--cases``
    variants (body mass x final-drive ratio from a Latin hypercube) in this process, numba at
    its default thread count (every core);
(b) the same cases as a study (``run_study``, ``simulate`` solver) on a ``--workers`` Dask
    LocalCluster writing its Parquet dataset to a temporary folder: cluster start, planning,
    batches, writing. Reported: throughput ratio (b)/(a) (target >= 0.8), and the overhead
    per case ``(t_b - t_a) / cases`` (target <= 1 ms at 100 000 cases);
(b0) the fixed cost of (b): a 4-case study on the same cluster (start, worker imports, stop);
(c) the same study in process (no Dask), to separate Dask's cost from the study's own
    (``--no-in-process`` skips it);
(d) optional DP scaling: ``--dp-cases`` DP cases (parallel HEV, UDDS, ``--dp-grid`` SOC and
    throttle points, the issue's study is 200 cases at 400 x 400) on 1 and on 2 workers: the
    speed-up, and the time per case; with fewer cases than ``--dp-full-cases`` the full
    study's time is extrapolated (cases x time per case) and printed as EXTRAPOLATED.

The 1-minute load average before and after, and the other processes' load during each
timing, are printed: on a shared machine the ratios, not the absolute figures, are the result.
The script only reports: it always exits 0.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from _machine import OtherLoad

REPO = Path(__file__).resolve().parents[1]
SERIES = REPO / "examples" / "series_hev.toml"
PARALLEL = REPO / "examples" / "parallel_hev.toml"


def _load() -> str:
    one, five, _ = os.getloadavg()
    return f"load average {one:.2f} (1 min), {five:.2f} (5 min) on {os.cpu_count()} cores"


def _study(cases: int) -> object:
    from hevsim.studies.spec import study_from_dict

    return study_from_dict({
        "name": "bench", "vehicle": str(SERIES), "cycles": ["udds"], "metrics": ["mpgge", "soc_final"],
        "sampling": {"method": "lhs", "samples": cases, "seed": 1},
        "parameters": {"body.mass_kg": {"min": 1100.0, "max": 1500.0},
                       "final_drive.ratio": {"min": 3.0, "max": 5.0}},
        "solvers": [{"name": "simulate"}],
    })  # fmt: skip


def bench_simulate(cases: int, workers: int, in_process: bool = True) -> None:
    from hevsim.config import load_vehicle_config
    from hevsim.sim.model import build_series_hev
    from hevsim.sim.simulator import simulate_batch
    from hevsim.studies.runner import run_study

    study = _study(cases)
    cfg = load_vehicle_config(SERIES)
    hev = build_series_hev(cfg)
    values = study.values  # type: ignore[attr-defined]
    # the kernel parameters a body mass and a final drive set (brake force = max decel x mass)
    variants = {"mass_kg": values[:, 0], "max_brake_force_n": cfg.brakes.max_decel_mps2 * values[:, 0],
                "gear_ratio": values[:, 1]}  # fmt: skip
    simulate_batch(hev, {k: v[:4] for k, v in variants.items()}, cycle="udds")  # warm-up
    print(f"(a) simulate_batch, {cases} UDDS variants in one process ...", flush=True)
    with OtherLoad() as la:
        t0 = time.perf_counter()
        base = simulate_batch(hev, variants, cycle="udds")
        t_a = time.perf_counter() - t0
    print(f"    {t_a:.2f} s, {cases / t_a:,.0f} cases/s ({la.text()})")
    with tempfile.TemporaryDirectory() as tmp:
        print(
            f"(b0) fixed cost: a 4-case study on a {workers}-worker LocalCluster (start, imports, stop) ..."
        )
        with OtherLoad() as l0:
            t0 = time.perf_counter()
            run_study(_study(4), Path(tmp) / "fixed", workers=workers, progress=False)  # type: ignore[arg-type]
            t_b0 = time.perf_counter() - t0
        print(f"    {t_b0:.2f} s ({l0.text()})")
        print(
            f"(b) run_study on a {workers}-worker LocalCluster, Parquet to a temporary folder ...", flush=True
        )
        with OtherLoad() as lb:
            t0 = time.perf_counter()
            rows = run_study(study, Path(tmp) / "dask", workers=workers, progress=False)  # type: ignore[arg-type]
            t_b = time.perf_counter() - t0
        print(f"    {t_b:.2f} s, {cases / t_b:,.0f} cases/s ({lb.text()})")
        t_c = float("nan")
        if in_process:
            print("(c) run_study in process (no Dask) ...", flush=True)
            with OtherLoad() as lc:
                t0 = time.perf_counter()
                run_study(study, Path(tmp) / "inproc", scheduler="in-process", progress=False)  # type: ignore[arg-type]
                t_c = time.perf_counter() - t0
            print(f"    {t_c:.2f} s, {cases / t_c:,.0f} cases/s ({lc.text()})")
    same = np.array_equal(rows["mpgge"].to_numpy(), base.table["mpgge"].to_numpy())
    print(f"    study rows equal simulate_batch's: {same}")
    print(f"throughput ratio (b)/(a) = {t_a / t_b:.2f}  (target >= 0.80)")
    print(
        f"overhead per case (b) - (a) = {(t_b - t_a) / cases * 1e3:.3f} ms  (target <= 1 ms at 100 000 cases)"
    )
    print(
        f"overhead per case without the fixed cost (b)-(b0)-(a) = {(t_b - t_b0 - t_a) / cases * 1e3:.3f} ms"
    )
    if in_process:
        print(f"in-process study (c)/(a) = {t_a / t_c:.2f}")


def bench_dp(cases: int, grid: int, full_cases: int = 200, workers: tuple[int, ...] = (1, 2)) -> None:
    from hevsim.studies.runner import run_study
    from hevsim.studies.spec import study_from_dict

    study = study_from_dict({
        "name": "bench_dp", "vehicle": str(PARALLEL), "cycles": ["udds"], "metrics": ["mpgge"],
        "sampling": {"method": "lhs", "samples": cases, "seed": 2},
        "parameters": {"motor.torque_scale": {"min": 0.7, "max": 1.0},
                       "battery.capacity_ah": {"min": 4.0, "max": 6.0}},
        "solvers": [{"name": "optimize", "soc_grid_points": grid, "input_grid_points": grid}],
    })  # fmt: skip
    times = {}
    for w in workers:
        print(f"(d) {cases} DP cases ({grid} x {grid}, UDDS) on {w} worker(s) ...", flush=True)
        with OtherLoad() as ld:
            t0 = time.perf_counter()
            rows = run_study(study, workers=w, progress=True)
            times[w] = time.perf_counter() - t0
        print(f"    {times[w]:.1f} s ({times[w] / cases:.1f} s per case), "
              f"{int((rows['status'] == 'ok').sum())} ok ({ld.text()})")  # fmt: skip
    if 1 in times and 2 in times:
        print(f"DP speed-up 1 -> 2 workers: {times[1] / times[2]:.2f}x ({cases} cases)")
    if cases < full_cases:
        print(f"EXTRAPOLATED (not measured) to the {full_cases}-case study at {grid} x {grid}: "
              + ", ".join(f"{times[w] / cases * full_cases / 3600:.2f} h on {w} worker(s)" for w in times)
              + " (time per case x cases; the cluster start-up, paid once in the measured run, is "
              "scaled with the cases: an upper bound)")  # fmt: skip


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=100_000)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--dp-cases", type=int, default=0, help="DP cases for the scaling run (0: skip)")
    ap.add_argument("--dp-grid", type=int, default=400)
    ap.add_argument("--dp-full-cases", type=int, default=200, help="DP study size to extrapolate to")
    ap.add_argument("--no-in-process", action="store_true", help="skip the in-process study (c)")
    ap.add_argument("--dp-workers", default="1,2", help="worker counts of the DP runs, e.g. 1,2 or 2")
    a = ap.parse_args()
    print(f"python {sys.version.split()[0]}; {_load()}")
    if a.cases:
        bench_simulate(a.cases, a.workers, not a.no_in_process)
    if a.dp_cases:
        bench_dp(a.dp_cases, a.dp_grid, a.dp_full_cases, tuple(int(w) for w in a.dp_workers.split(",")))
    print(f"after: {_load()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
