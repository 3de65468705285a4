"""Lap times of the shipped cars on the shipped tracks (issue 29), as a markdown table.

Run from the repository root::

    .venv/bin/python examples/lap_times.py [--step 1.0] [--out lap_times.md]

Each car's powertrain envelope is built once (``hevsim.sim.lap.lap_vehicle``) and reused on
every track; the laps include the operating points along the lap (fuel and battery energy
per lap at the held initial SOC). The same run from the command line, one car and track at
a time: ``hevsim lap examples/high_performance_parallel_hev.toml monza``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from hevsim.sim.lap import lap_vehicle, simulate_lap
from hevsim.tracks import TRACK_NAMES, load_track

REPO = Path(__file__).resolve().parents[1]
CARS = (
    "high_performance_parallel_hev",
    "parallel_hev",
    "prius_2016_like_power_split",
    "prius_like_power_split",
    "series_hev",
    "conventional_sedan",
    "bev",
)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--step", type=float, default=1.0, help="distance step [m]")
    ap.add_argument("--out", help="also write the table to this markdown file")
    a = ap.parse_args()
    tracks = {name: load_track(name, step_m=a.step) for name in TRACK_NAMES}
    lines = [
        "| car | "
        + " | ".join(f"{t.name} ({t.length_m:.0f} m)" for t in tracks.values())
        + " | fuel / battery on monza |",
        "|---|" + "---:|" * len(tracks) + "---|",
    ]
    for car in CARS:
        path = REPO / "examples" / f"{car}.toml"
        veh = lap_vehicle(path)
        cells, last = [], None
        for t in tracks.values():
            last = simulate_lap(path, t, vehicle=veh)
            s = last.summary
            cells.append(f"{s['lap_time_s']:.2f} s ({s['max_speed_kmh']:.0f} km/h)")
        s = last.summary
        energy = f"{s['fuel_kg'] * 1e3:.0f} g, {s['battery_chemical_energy_j'] / 3.6e6:+.2f} kWh"
        lines.append(f"| {car} | " + " | ".join(cells) + f" | {energy} |")
        print(lines[-1], flush=True)
    text = "\n".join(lines) + "\n"
    print()
    print(text)
    if a.out:
        Path(a.out).write_text(text, encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
