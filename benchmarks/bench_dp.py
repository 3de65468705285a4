"""Time and memory of the appendix DP problem, and a port of the appendix's per-SOC loop.

Run from the repository root (or anywhere; paths are resolved from this file)::

    .venv/bin/python benchmarks/bench_dp.py [--repeats 3] [--port-steps 6]

What is measured (``time.perf_counter``; loading and the numba cache warm-up excluded):

(a) ``hevsim.optimal.optimize`` on the thesis appendix's parallel HEV
    (``examples/parallel_hev.toml``) over the full UDDS at the
    appendix's resolution: 400 SOC points x 400 throttle points x 5 gears, SOC 0.8 -> final
    window 0.7-0.8, boundary-line final constraint, re-optimising forward pass. End to end:
    stage tables, followability check, backward and forward passes, costate and the
    result's time series and metrics. Median and minimum of ``--repeats`` runs.
    **Target: <= 3 s.**
(b) Peak memory of one such run: the peak of traced Python/numpy allocations
    (``tracemalloc``, in a separate untimed run) and the process's peak resident set size
    (``resource.getrusage``, which includes the interpreter and imports). **Target: <= 2 GB.**
(c) A straightforward port of the appendix script's backward step: engine maps over
    throttle x gear once per step, then a Python loop over the 400 SOC points, each doing
    the "EM analysis" (machine and battery at that SOC, with the same component methods),
    one ``interp1`` of the next cost-to-go per gear (NaN outside the grid replaced by the
    appendix's NOT_ALLOW_PENALTY) and the minimum. Timed at ``--port-steps`` steps spread
    over the moving part of the UDDS and extrapolated to the cycle's 1369 steps. The ratio
    is (extrapolated port time) / (a).

The script reports and never asserts: it always exits 0.
"""

from __future__ import annotations

import argparse
import os
import platform
import resource
import statistics
import sys
import time
import tracemalloc
from pathlib import Path
from typing import Any

import numpy as np

from _machine import OtherLoad

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "src"))

TARGET_TIME_S = 3.0
TARGET_MEMORY_B = 2 * 1024**3
NOT_ALLOW_PENALTY = 1e5  # appendix script: penalty of an infeasible choice [kg of "cost"]
PLAUSIBLE_COST_KG = 10.0  # a cost-to-go above this is a leaked penalty, not fuel [kg]


def machine_info() -> None:
    import numba

    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    model = "unknown"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    print("Machine")
    print(f"  cpu            : {model}, {cores} usable cores")
    print(f"  python / numpy : {platform.python_version()} / {np.__version__}")
    print(f"  numba          : {numba.__version__} ({numba.get_num_threads()} threads)")


def port_step(form: Any, k: int, j_next: np.ndarray) -> tuple[np.ndarray, float]:
    """One backward step of the appendix script, ported as written (loop over SOC points).

    Returns the cost-to-go at step ``k`` on the SOC grid and the wall time [s].
    """
    from hevsim.optimal._hev_common import electric_flow

    hev = form.hev
    eng = hev.engine
    soc_vec = form.soc_grid
    t0 = time.perf_counter()
    # --- per step, outside the SOC loop: engine speed, torque and fuel for throttle x gear
    thr = form.input_grids[1][:, None]  # (U, 1)
    w_e = form.w_fd[k] * form.ratios[None, :]  # (1, G)
    w_e, thr = np.broadcast_arrays(w_e, thr)
    fired = thr > 0
    can_run = (w_e >= eng.stall_speed_radps) & (w_e <= eng.redline_radps)
    t_e = np.where(fired & can_run, eng.torque(thr, w_e), 0.0)
    fuel = np.where(fired & can_run, np.nan_to_num(eng.fuel_rate(t_e, w_e)), 0.0) * form.steps.dt_s[k]
    t_e_fd = np.stack([g.output_torque(t_e[:, i]) for i, g in enumerate(hev.gears)], axis=1)
    t_em_req = hev.motor_coupling.input_torque(form.t_fd[k] - t_e_fd)
    dt = form.steps.dt_s[k]
    j_out = np.empty(soc_vec.size)
    for L in range(soc_vec.size):  # the appendix's "for L = 1:SOC_grid_size"
        flow = electric_flow(  # "EM_Analysis": machine and battery at this SOC
            hev.motor, hev.battery, t_em_req, form.w_em[k], 0.0, soc_vec[L], dt, form.regen_ok[k]
        )
        not_possible = flow.infeasible | (fired & ~can_run)
        soc_next = soc_vec[L] + flow.d_soc
        j_next_choices = np.empty_like(soc_next)
        for s in range(soc_next.shape[1]):  # one interp1 per gear
            j_next_choices[:, s] = np.interp(soc_next[:, s], soc_vec, j_next, left=np.nan, right=np.nan)
        j_next_choices[np.isnan(j_next_choices)] = NOT_ALLOW_PENALTY
        cost = fuel + not_possible * NOT_ALLOW_PENALTY + j_next_choices
        col_min = cost.min(axis=0)
        j_out[L] = col_min.min()
    return j_out, time.perf_counter() - t0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=3, help="timed runs of the full problem (median)")
    ap.add_argument("--port-steps", type=int, default=6, help="steps of the per-SOC loop port to time")
    ap.add_argument("--cycle", default="udds", help="drive cycle (default udds)")
    args = ap.parse_args()

    from hevsim.architectures import build_vehicle
    from hevsim.config import load_vehicle_config
    from hevsim.optimal import optimize
    from hevsim.optimal._parallel_dp import ParallelFormulation
    from hevsim.optimal.hev import _final_target, _parallel_settings

    machine_info()
    example = Path(__file__).resolve().parents[1] / "examples" / "parallel_hev.toml"
    hev = build_vehicle(load_vehicle_config(example))
    o = hev.config.optimization
    print(
        f"\nProblem: appendix parallel HEV on {args.cycle}, {o.soc_grid_points} SOC x "
        f"{o.throttle_grid_points} throttle x {len(hev.gears)} gears, SOC {o.soc_initial} -> "
        f"[{o.final_soc_min}, {o.final_soc_max}]"
    )

    t0 = time.perf_counter()
    optimize(hev, "fu505", soc_grid_points=41, input_grid_points=21)  # numba caches, imports
    print(f"warm-up (numba cache load or compile, small problem): {time.perf_counter() - t0:.2f} s")

    # (a) time
    times = []
    res = None
    with OtherLoad() as load:
        for _ in range(max(1, args.repeats)):
            t = time.perf_counter()
            res = optimize(hev, args.cycle)
            times.append(time.perf_counter() - t)
    assert res is not None
    med = statistics.median(times)
    tm = res.metadata["timings_s"]
    n_steps = res.metadata["n_steps"]
    print(f"\n(a) optimize() end to end, {len(times)} runs: median {med:.3f} s, min {min(times):.3f} s "
          f"({load.text()})")  # fmt: skip
    print(f"    breakdown of the last run: stage tables + checks {tm['stage_table_s']:.3f} s, "
          f"backward {tm['dp_backward_s']:.3f} s ({tm['dp_backward_s'] / n_steps * 1e3:.3f} ms/step), "
          f"forward + costate {tm['dp_total_s'] - tm['dp_backward_s']:.3f} s, "
          f"results {tm['results_s']:.3f} s, setup {tm['setup_s']:.3f} s")  # fmt: skip
    print(f"    fuel {res.value('fuel_kg'):.4f} kg, {res.value('mpg'):.2f} mpg, final SOC "
          f"{res.value('soc_final'):.4f}, mpgge {res.value('mpgge'):.2f}")  # fmt: skip
    verdict = "met" if med <= TARGET_TIME_S else "NOT met"
    print(f"    target <= {TARGET_TIME_S:.0f} s: {verdict}")

    # (b) memory
    tracemalloc.start()
    optimize(hev, args.cycle)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    maxrss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024  # Linux: kB
    est = res.metadata["memory_bytes"].get("total", 0)
    print(f"\n(b) peak memory: traced allocations {peak / 1e6:.1f} MB; process peak RSS "
          f"{maxrss / 1e6:.1f} MB (interpreter and imports included); solver estimate "
          f"{est / 1e6:.1f} MB")  # fmt: skip
    print(f"    target <= 2 GB: {'met' if max(peak, maxrss) <= TARGET_MEMORY_B else 'NOT met'}")

    # (c) the appendix's per-SOC-point loop
    s = _parallel_settings(hev)
    grid = np.linspace(s.soc_min, s.soc_max, s.soc_points)
    target, _ = _final_target(s, s.soc_initial)
    from hevsim.cycles import load_cycle

    form = ParallelFormulation(hev, load_cycle(args.cycle), soc_grid=grid, throttle_points=s.input_points,
                               soc_initial=s.soc_initial, target=target)  # fmt: skip
    ctg = optimize(hev, args.cycle, store_cost_to_go=True).cost_to_go
    assert ctg is not None
    moving = np.flatnonzero(form.steps.v_mid_mps > 0)
    picks = moving[np.linspace(0, moving.size - 1, max(1, args.port_steps)).astype(int)]
    port_times = []
    agree = []
    port_step(
        form, int(picks[0]), np.where(np.isfinite(ctg[picks[0] + 1]), ctg[picks[0] + 1], NOT_ALLOW_PENALTY)
    )
    for k in picks:
        j_next = np.where(np.isfinite(ctg[k + 1]), ctg[k + 1], NOT_ALLOW_PENALTY)
        j_port, dt_s = port_step(form, int(k), j_next)
        port_times.append(dt_s)
        # nodes where neither is infeasible nor touched by the appendix's finite penalty
        inside = np.isfinite(ctg[k]) & (j_port < PLAUSIBLE_COST_KG)
        if inside.any():
            agree.extend(np.abs(j_port[inside] - ctg[k][inside]) / np.maximum(ctg[k][inside], 1e-6))
    per_step = statistics.median(port_times)
    full = per_step * n_steps
    print(f"\n(c) appendix per-SOC-point loop port: {per_step * 1e3:.1f} ms/step (median of {len(picks)} "
          f"moving steps {', '.join(str(int(k)) for k in picks)}), extrapolated to {n_steps} steps: "
          f"{full:.1f} s")  # fmt: skip
    if agree:
        a = np.array(agree)
        print(f"    port vs DP cost-to-go at those steps ({a.size} nodes where both are feasible and "
              f"below {PLAUSIBLE_COST_KG:g} kg): relative difference median {np.median(a):.1e}, "
              f"max {a.max():.1e} (the port interpolates plainly; the DP uses boundary lines)")  # fmt: skip
    print(f"    ratio port / optimize(): {full / med:.0f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
