"""Time the QSS lap (issue 29 item 2): the compiled speed kernel on a ~5 km circuit at 1 m steps.

Run from the repository root (or anywhere; paths are resolved from this file)::

    .venv/bin/python benchmarks/bench_lap.py [--repeats 5] [--config examples/...toml] [--track monza]

Prints the median of ``--repeats`` runs (after one warm-up) of

* ``qss_speed`` — apex speeds, forward and backward integration (the issue's target: <= 50 ms
  on a 5 km circuit at 1 m steps), and, as the peer measured in the same run, the same kernel
  run as Python (numba's ``py_func``, its inner functions still compiled);
* the powertrain envelope (``lap_vehicle``: bisection of the architecture's power flow over
  220 speeds x the capability controls), built once per vehicle and SOC;
* ``simulate_lap`` with the operating points along the lap (power flow over every candidate
  at every sample) and without them;

* with ``--deploy`` (issue 29 item 3), the optimal deployment on the circuit at ``--deploy-step``
  (default 10 m, charge-sustaining): the convex program (cvxpy + Clarabel; target <= 10 s) and
  the DP (target <= 30 s), their lap times and the DP-vs-convex difference, the problem's build
  (envelope rows + the reference lap) apart; and the DP's convergence in its passes;

and the load of the other processes while it ran; then (issue 29 item 4, skipped with
``--stint-laps 0``) a stint of ``--stint-laps`` laps (default 10) of the high-performance
parallel HEV with

* a 1200-cell pack on module ROMs (100 thesis 2s6p modules, every cell simulated, the module
  ROM built once from examples/module_thermal.toml into a temporary folder or ``--rom FILE``,
  not timed; the issue's target: <= 30 s), and
* the shipped hot-lap pack (324 cells, coolant ports), the peer of the same run, and
* the 1200-cell pack again with every pass of a lap stepped in full (the code before the trial
  passes skipped the module ROMs' hot-spot search and reused the operating points,
  ``simulate_stint(..., full_passes=True)``): the baseline of the same run, its ratio, and
  that the results are the same bit for bit,
* the 1200-cell pack again with at most 2 passes of each lap instead of 3 (and how far its lap
  times move),
* the 1200-cell pack driving the optimal deployment re-solved with the BMS's limits at the
  start of each lap (``hevsim stint --optimize convex``, :mod:`hevsim.optimal.stint_deploy`;
  skipped without cvxpy), as a ratio to the plain 1200-cell stint of the same run,

against the single lap with operating points times the laps (the stint's floor without the
pack and the recomputed passes), with ``uptime``'s load. The script only reports: it always
exits 0.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--config", default=str(REPO / "examples" / "high_performance_parallel_hev.toml"))
    ap.add_argument("--track", default="monza")
    ap.add_argument("--deploy", action="store_true", help="also time the optimal deployment")
    ap.add_argument("--deploy-only", action="store_true", help="only the optimal deployment")
    ap.add_argument("--deploy-step", type=float, default=10.0)
    ap.add_argument("--stint-laps", type=int, default=10, help="laps of the stint benchmark (0: skip)")
    ap.add_argument("--rom", help="module ROM of examples/module_thermal.toml (built when omitted)")
    a = ap.parse_args()
    if a.deploy or a.deploy_only:
        bench_deploy(a)
        if a.deploy_only:
            return 0
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from _machine import OtherLoad, median_time
    from hevsim import tracks
    from hevsim.sim import lap as L

    track = tracks.load_track(a.track, step_m=1.0)
    print(
        f"track {track.name}: {track.length_m:.0f} m, {track.distance_m.size} samples at {track.step_m:.3f} m"
    )
    with OtherLoad() as load:
        t_env = median_time(lambda: L.lap_vehicle(a.config), max(1, a.repeats // 2), warm=True)
        veh = L.lap_vehicle(a.config)
        levels, table = veh.force_table
        args = (
            track.curvature_1pm,
            L.np.arctan(track.grade),
            track.banking_rad,
            float(track.step_m),
            L.np.array(veh.params()),
            veh.envelope_speed_mps,
            table,
            levels,
            L.np.full(track.distance_m.size, L.np.inf),
            veh.speed_cap_mps,
        )
        t_kernel = median_time(lambda: L._qss_speed(*args), a.repeats, warm=True)
        t_py = median_time(lambda: L._qss_speed.py_func(*args), 1, warm=True)
        t_lap = median_time(
            lambda: L.simulate_lap(a.config, track, vehicle=veh), max(1, a.repeats // 2), warm=True
        )
        t_lap0 = median_time(
            lambda: L.simulate_lap(a.config, track, vehicle=veh, operating_points=False), a.repeats, warm=True
        )
    lap = L.simulate_lap(a.config, track, vehicle=veh, operating_points=False)
    print(f"vehicle {veh.name}: lap time {lap.lap_time_s:.3f} s")
    print(f"{'qss_speed (compiled)':<40}{t_kernel * 1e3:>10.2f} ms   (target <= 50 ms)")
    print(f"{'qss_speed as Python (py_func), peer':<40}{t_py * 1e3:>10.1f} ms   ratio {t_py / t_kernel:.0f}x")
    print(f"{'envelope (lap_vehicle)':<40}{t_env * 1e3:>10.1f} ms   (once per vehicle and SOC)")
    print(f"{'simulate_lap, speed profile only':<40}{t_lap0 * 1e3:>10.1f} ms")
    print(f"{'simulate_lap with operating points':<40}{t_lap * 1e3:>10.1f} ms")
    print(load.text())
    if a.stint_laps > 0:
        bench_stint(a.track, a.stint_laps, a.rom, t_lap)
    return 0


def bench_deploy(a: argparse.Namespace) -> None:
    """Optimal deployment: convex vs DP on the same problem (issue 29 item 3)."""
    import time

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from _machine import OtherLoad, median_time
    from hevsim.optimal import lap_deploy as D

    t0 = time.perf_counter()
    prob, _ = D.build_problem(a.config, a.track, step_m=a.deploy_step, budget_kj=0.0)
    t_build = time.perf_counter() - t0
    D.solve_dp(prob, passes=1)  # compile the DP kernels
    with OtherLoad() as load:
        t_cvx = median_time(lambda: D.solve_convex(prob), max(1, a.repeats // 2), warm=True)
        t_dp = median_time(lambda: D.solve_dp(prob), 1, warm=False)
    rc = D.solve_convex(prob)
    rd = D.solve_dp(prob)
    print(f"optimal deployment on {prob.track}: {prob.n} steps of {prob.step_m:.2f} m, charge-sustaining")
    print(f"{'problem build (envelopes + ref. lap)':<40}{t_build:>10.2f} s")
    print(f"{'convex (cvxpy + Clarabel)':<40}{t_cvx:>10.2f} s   (target <= 10 s)   lap {rc.lap_time_s:.4f} s")
    print(
        f"{'DP (31 nodes, 6 passes)':<40}{t_dp:>10.2f} s   (target <= 30 s)   lap {rd.lap_time_s:.4f} s  "
        f"DP/convex - 1 = {(rd.lap_time_s / rc.lap_time_s - 1) * 100:+.4f} %"
    )
    for passes in (1, 2, 4, 6, 8):
        r = D.solve_dp(prob, passes=passes)
        print(
            f"  DP passes {passes}: speed step {r.info['speed_step_mps']:.4f} m/s  lap {r.lap_time_s:.4f} s  "
            f"vs convex {(r.lap_time_s / rc.lap_time_s - 1) * 100:+.4f} %  net battery "
            f"{r.battery_energy_j.sum() / 1e3:+.2f} kJ"
        )
    print(load.text())


def stint_car(folder: Path, rom: Path) -> Path:
    """The high-performance parallel HEV with a 1200-cell pack on module ROMs: 100 thesis 2s6p
    modules (examples/vehicle_pack.toml, as benchmarks/bench_pack_vehicle.py case (a))."""
    ex = REPO / "examples"
    pack = (ex / "vehicle_pack.toml").read_text()
    edits = {
        'thermal_config = "module_thermal.toml"': f'thermal_config = "{ex / "module_thermal.toml"}"',
        "n_modules = 50 ": "n_modules = 100 ",
        '\nthermal = "coolant"': f'\nthermal = "rom"\nrom_file = "{rom}"',
        "flow_l_min = 20.0": "flow_l_min = 1000.0",  # 10 L/min per plate: the ROM's film range
        "flow_ref_l_min = 10.0": "flow_ref_l_min = 1000.0",
        "chiller_max_w = 3000.0": "chiller_max_w = 20000.0",
    }
    for old, new in edits.items():
        assert old in pack, old
        pack = pack.replace(old, new)
    (folder / "rom_pack.toml").write_text(pack)
    car = (ex / "high_performance_parallel_hev_pack.toml").read_text()
    car = car.replace('pack = "hot_lap_pack.toml"', 'pack = "rom_pack.toml"').replace(
        "bus_max_v = 450.0", "bus_max_v = 1000.0"
    )  # 200 cells in series
    path = folder / "hp_rom_pack.toml"
    path.write_text(car)
    return path


def bench_stint(track_name: str, laps: int, rom_arg: str | None, t_lap: float) -> None:
    """Time a stint (module docstring)."""
    import os
    import tempfile
    import time

    from _machine import OtherLoad
    from hevsim import tracks
    from hevsim.config import load_vehicle_config
    from hevsim.sim.stint import ITERATIONS, simulate_stint

    track = tracks.load_track(track_name, step_m=1.0)
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        rom = Path(rom_arg).resolve() if rom_arg else tmp / "module.rom.npz"
        if not rom_arg:
            from hevsim.thermal.rom import build_rom_from_config

            t0 = time.perf_counter()
            built, _ = build_rom_from_config(REPO / "examples" / "module_thermal.toml")
            built.save(rom)
            print(f"module ROM built in {time.perf_counter() - t0:.1f} s (order {built.order}; not timed)")
        cases = {
            "1200 cells, module ROMs + cooling loop": load_vehicle_config(stint_car(tmp, rom)),
            "324 cells (shipped hot-lap pack), coolant ports": load_vehicle_config(
                REPO / "examples" / "high_performance_parallel_hev_pack.toml"
            ),
        }
        print(f"stint of {laps} laps on {track.name} at 1 m steps, pack step 1 s (wall and CPU, whole call):")
        first: dict[str, Any] = {}
        base = (float("nan"), float("nan"))
        rom_cfg = next(iter(cases.values()))
        for label, cfg, passes, every in (
            *((k, c, ITERATIONS, False) for k, c in cases.items()),
            ("1200 cells, every pass in full (before)", rom_cfg, ITERATIONS, True),
            ("1200 cells, module ROMs, at most 2 passes per lap", rom_cfg, 2, False),
        ):
            simulate_stint(cfg, track, 1)  # warm-up: compilation and caches
            with OtherLoad() as load:
                w0, c0 = time.perf_counter(), time.process_time()
                res = simulate_stint(cfg, track, laps, iterations=passes, full_passes=every)
                wall, cpu = time.perf_counter() - w0, time.process_time() - c0
            first.setdefault(str(res.metadata["n_cells"]), res)
            s = res.summary
            print(
                f"  {label:<50}{wall:8.2f} s wall {cpu:7.2f} s CPU   (target <= 30 s; {load.text()}; "
                f"uptime load {os.getloadavg()[0]:.2f})"
            )
            print(
                f"    {res.metadata['n_cells']} cells; laps {s['fastest_lap_s']:.2f} .. "
                f"{s['slowest_lap_s']:.2f} s; "
                f"peak cell {s['peak_cell_temp_c']:.1f} degC; passes {int(res.laps['passes'].sum())}; "
                f"{laps} x the single lap with operating points {laps * t_lap:.2f} s "
                f"(ratio {wall / (laps * t_lap):.1f}x)"
            )
            ref = first[str(res.metadata["n_cells"])]
            if label.startswith("1200") and passes == ITERATIONS and not every:
                base = (wall, cpu)
            if every:
                same = ref.laps.equals(res.laps) and ref.timeseries.equals(res.timeseries)
                print(
                    f"    the default (trial passes) / this: {base[0] / wall:.2f} wall, "
                    f"{base[1] / cpu:.2f} CPU; per-lap table and pack time series the same bit for bit: "
                    f"{same}"
                )
                continue
            if ref is not res:
                d = (res.laps["lap_time_s"] - ref.laps["lap_time_s"]).abs().max()
                print(
                    f"    against {ITERATIONS} passes: lap times differ by at most {d:.3f} s; clamped "
                    f"{res.summary['clamped_s']:.0f} s (against {ref.summary['clamped_s']:.0f} s)"
                )
        try:
            import cvxpy  # noqa: F401
        except ImportError:
            print("  optimal deployment re-solved per lap: skipped (no cvxpy: pip install 'hevsim[lap]')")
            return
        from hevsim.optimal.stint_deploy import simulate_stint_optimized

        cfg = next(iter(cases.values()))
        with OtherLoad() as load:
            w0, c0 = time.perf_counter(), time.process_time()
            res = simulate_stint_optimized(cfg, track, laps)
            wall, cpu = time.perf_counter() - w0, time.process_time() - c0
        s = res.summary
        print(
            f"  {'1200 cells, optimal deployment re-solved (convex)':<50}{wall:8.2f} s wall "
            f"{cpu:7.2f} s CPU   "
            f"(ratio to the plain 1200-cell stint above: {wall / base[0]:.2f} wall, {cpu / base[1]:.2f} CPU; "
            f"{load.text()}; uptime load {os.getloadavg()[0]:.2f})"
        )
        print(
            f"    {s['deploy_solves']} solves; laps {s['fastest_lap_s']:.2f} .. {s['slowest_lap_s']:.2f} s; "
            f"peak cell {s['peak_cell_temp_c']:.1f} degC; passes {int(res.laps['passes'].sum())}"
        )


if __name__ == "__main__":
    raise SystemExit(main())
