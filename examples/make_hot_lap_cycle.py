"""Make the shipped hot-lap drive cycle ``hotlap_0_200`` (issue 12 item 5, high-performance
scenario) from the high-performance HEV's own full-power envelope.

    .venv/bin/python examples/make_hot_lap_cycle.py            # print the cycle's figures
    .venv/bin/python examples/make_hot_lap_cycle.py --out FILE  # write the CSV (1 Hz)

How it is made (every number is a named constant below):

1. The standing-start run of :func:`hevsim.sim.performance.performance` on
   ``examples/high_performance_parallel_hev.toml`` (step ``ENVELOPE_DT_S``, SOC
   ``ENVELOPE_SOC``): the fastest the car can accelerate, speed against time, with its tire,
   engine, machine and battery limits.
2. One lap: ``STOP_S`` s at rest; a launch along that envelope slowed in time by
   ``ENVELOPE_SHARE`` (v(t) = v_env(share x t), so a fresh pack follows it at 1 s steps) up to
   ``TOP_KMH``; ``HOLD_S`` s at that speed; hard braking at ``BRAKE_MPS2`` to rest.
3. ``LAPS`` laps end to end, sampled at 1 Hz, speeds rounded to 1e-4 m/s; a final rest.

A hot pack or an empty battery makes the car fall behind the trace (``traction_limited``),
which is what the scenario is for. tests/test_hot_lap_cycle.py re-runs this script and checks
that the shipped ``src/hevsim/data/cycles/hotlap_0_200.csv`` is what it makes.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
VEHICLE = HERE / "high_performance_parallel_hev.toml"
SHIPPED = HERE.parent / "src" / "hevsim" / "data" / "cycles" / "hotlap_0_200.csv"
ENVELOPE_DT_S = 0.1
"""Step of the full-power standing-start run [s]."""
ENVELOPE_SOC = 0.6
"""Battery SOC of the envelope run [-] (the vehicle's initial SOC)."""
ENVELOPE_SHARE = 0.95
"""Time scale of the launch against the envelope [-]: v(t) = v_env(0.95 t)."""
TOP_KMH = 200.0
"""Launch end speed [km/h]."""
HOLD_S = 3
"""Time at the top speed before braking [s]."""
BRAKE_MPS2 = 8.0
"""Hard-braking deceleration [m/s^2] (0.82 g, within the tires' mu = 1)."""
STOP_S = 8
"""Time at rest before each launch [s]."""
LAPS = 20
"""Number of launch-and-brake laps [-]."""


def hot_lap_speeds() -> np.ndarray:
    """Speed [m/s] at t = 0, 1, 2, ... s of the hot-lap cycle."""
    from hevsim.sim.performance import performance

    run = performance(VEHICLE, dt_s=ENVELOPE_DT_S, soc=ENVELOPE_SOC, duration_s=30.0).runs["standing_start"]
    t_env, v_env = run["time_s"].to_numpy(), run["speed_mps"].to_numpy()
    v_top = TOP_KMH / 3.6
    if v_env[-1] < v_top:
        raise SystemExit(f"{VEHICLE.name}: reaches only {v_env[-1] * 3.6:.1f} km/h in 30 s")
    launch = [0.0]
    while launch[-1] < v_top:
        launch.append(min(float(np.interp(ENVELOPE_SHARE * len(launch), t_env, v_env)), v_top))
    n_brake = int(np.ceil(v_top / BRAKE_MPS2))
    brake = [max(v_top - BRAKE_MPS2 * k, 0.0) for k in range(1, n_brake + 1)]
    lap = [0.0] * STOP_S + launch + [v_top] * HOLD_S + brake
    return np.round(np.array(lap * LAPS + [0.0] * STOP_S), 4)


def write_csv(path: Path, speed_mps: np.ndarray) -> None:
    """Write the cycle CSV (time_s, speed_m_per_s, speed_kmh) atomically."""
    from hevsim.io import write_text_atomic

    rows = ["time_s,speed_m_per_s,speed_kmh"]
    rows += [f"{k},{v:.4f},{v * 3.6:.4f}" for k, v in enumerate(speed_mps)]
    write_text_atomic(path, "\n".join(rows) + "\n")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, help=f"CSV to write (the shipped one is {SHIPPED})")
    a = ap.parse_args(argv)
    v = hot_lap_speeds()
    a_mps2 = np.diff(v)
    dist = float(np.sum(0.5 * (v[1:] + v[:-1])))
    print(f"hot lap: {v.size} samples, {v.size - 1} s, {dist / 1e3:.3f} km, max {v.max() * 3.6:.1f} km/h, "
          f"accel {a_mps2.max():.3f} / {a_mps2.min():.3f} m/s^2")  # fmt: skip
    if a.out is not None:
        write_csv(a.out, v)
        print(f"written to {a.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
