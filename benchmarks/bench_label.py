"""Time ``hevsim label`` on a charge-sustaining hybrid against FASTSim 3's label of its 2016 Prius.

Run from the repository root (or anywhere; paths are resolved from this file)::

    .venv/bin/python benchmarks/bench_label.py [--repeats 10] \
        [--config examples/prius_2016_like_power_split.toml]

What is timed (``time.perf_counter``, medians of ``--repeats`` after one warm-up call):

(a) ``hevsim.sim.label.label(CONFIG)`` warm, in-process: read and validate the vehicle file,
    build the model, UDDS and HWFET runs with the SAE J1711 SOC balance (every run a full
    ``simulate`` with its pandas result), the label figures. Target (issue 25): <= 0.5 s.
(b) FASTSim 3 (the ``bench`` extra), if installed: ``run_once()`` of its bundled 2016 Prius on
    UDDS plus HWFET (fresh ``SimDrive`` each, construction untimed), and its whole
    ``get_label_fe`` (its own SOC iteration, UDDS, HWFET and a 0-60 mph run).

The ratios are hevsim's time over FASTSim's. The script only reports: it always exits 0.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
import warnings
from pathlib import Path
from typing import Any

from _machine import OtherLoad, median_time

ROOT = Path(__file__).resolve().parents[1]
FASTSIM_VEHICLE = "2016_TOYOTA_Prius_Two.yaml"


def bench_fastsim(repeats: int) -> dict[str, float] | None:
    try:
        import fastsim as fsim
    except ImportError:
        return None
    veh = fsim.Vehicle.from_resource(FASTSIM_VEHICLE)
    cycles = [fsim.Cycle.from_resource(c) for c in ("udds.csv", "hwfet.csv")]

    def once(sd: Any) -> None:
        (sd.run_once if hasattr(sd, "run_once") else sd.walk_once)()

    def both() -> float:
        sds = [fsim.SimDrive(veh, cyc) for cyc in cycles]
        t0 = time.perf_counter()
        for sd in sds:
            once(sd)
        return time.perf_counter() - t0

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        both()
        run_once = statistics.median(both() for _ in range(repeats))
        fsim.get_label_fe(veh)
        label_s = median_time(lambda: fsim.get_label_fe(veh), repeats)
        out = json.loads(fsim.get_label_fe(veh).to_json())
    return {"run_once_s": run_once, "label_s": label_s, "udds_mpg": out["lab_udds_mpgge"],
            "hwy_mpg": out["lab_hwy_mpgge"]}  # fmt: skip


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=10)
    ap.add_argument("--config", default=str(ROOT / "examples" / "prius_2016_like_power_split.toml"))
    a = ap.parse_args()
    t0 = time.perf_counter()
    from hevsim.sim.label import label

    first = label(a.config)
    first_s = time.perf_counter() - t0
    with OtherLoad() as load:
        warm = median_time(lambda: label(a.config), a.repeats)
        fs = bench_fastsim(a.repeats)
    runs = sum(len(t.runs) for t in first.tests.values())
    name = Path(a.config).name
    print(f"hevsim label {name}: first call in this process {first_s:.2f} s (imports, numba cache)")
    print(f"  warm: {warm * 1e3:.1f} ms median of {a.repeats} ({runs} simulate runs incl. SOC balance)")
    print("  target (issue 25): 500 ms")
    print("  " + first.text().replace("\n", "\n  "))
    if fs is None:
        print("FASTSim not installed (pip install -e '.[bench]'): no ratio")
    else:
        print(f"FASTSim 3 2016 Prius: run_once() UDDS + HWFET {fs['run_once_s'] * 1e3:.1f} ms, "
              f"get_label_fe {fs['label_s'] * 1e3:.1f} ms "
              f"(unadjusted {fs['udds_mpg']:.1f} / {fs['hwy_mpg']:.1f} mpg)")  # fmt: skip
        print(f"ratio hevsim label / FASTSim run_once() x2: {warm / fs['run_once_s']:.2f}; "
              f"/ FASTSim get_label_fe: {warm / fs['label_s']:.2f}")  # fmt: skip
    print(load.text())
    return 0


if __name__ == "__main__":
    sys.exit(main())
