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

and the load of the other processes while it ran. The script only reports: it always exits 0.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--config", default=str(REPO / "examples" / "high_performance_parallel_hev.toml"))
    ap.add_argument("--track", default="monza")
    a = ap.parse_args()
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
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
