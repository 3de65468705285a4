"""Time of a calibration over three ambients (issue 27: target <= 60 s on 2 cores).

Run from the repository root::

    .venv/bin/python benchmarks/bench_calibrate_ambients.py

The data are the shipped PyBaMM Thevenin-ECM pulse tests with Arrhenius R0 and R1 at 10, 25
and 40 degC (``examples/validation/arrhenius_*.csv``, 3780 rows each). Timed in the same run
(numba cache warmed first): the baseline, the single-ambient identification of the 25 degC
test (``hevsim calibrate ... `` without ``--data``), and the calibration over the three
ambients as ``hevsim calibrate ... --data ... --data ...`` runs it (the identification, the
step-resistance Arrhenius fit and the joint fit of the temperature laws,
:func:`hevsim.battery.identify.fit_temperature_laws`); wall time (``time.perf_counter``) and
this process's CPU time, their ratio to the baseline, and the other processes' load. The
script only reports: it always exits 0.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

from _machine import OtherLoad
from hevsim.battery.calibrate import CellTestRecord
from hevsim.battery.identify import fit_temperature, fit_temperature_laws, identify

DATA = Path(__file__).resolve().parents[1] / "examples" / "validation"
KW = {"soc_initial": 0.9, "capacity_ah": 5.0, "n_rc": 1}


def main() -> None:
    recs = {c: CellTestRecord.from_csv(DATA / f"arrhenius_{c}c.csv") for c in (10, 25, 40)}
    others = [recs[10], recs[40]]
    short = CellTestRecord(
        *(getattr(recs[25], k)[:1200] for k in ("time_s", "current_a", "voltage_v", "temp_k"))
    )
    warm = identify("thesis_table_4_1", short, min_rest_s=100.0, **KW)  # numba cache, imports
    shifted = CellTestRecord(short.time_s, short.current_a, short.voltage_v, short.temp_k + 10.0)
    fit_temperature_laws(warm, [shifted], min_rest_s=100.0)
    print(f"calibration over three ambients (10, 25, 40 degC; 3 x {recs[25].time_s.size} rows), "
          f"{os.cpu_count()} cores, load average before {os.getloadavg()[0]:.2f}")  # fmt: skip
    with OtherLoad() as load:
        t0, c0 = time.perf_counter(), time.process_time()
        ref = identify("thesis_table_4_1", recs[25], **KW)
        t1, c1 = time.perf_counter(), time.process_time()
        res = fit_temperature_laws(fit_temperature(ref, others), others)
        t2, c2 = time.perf_counter(), time.process_time()
    w_single, c_single = t1 - t0, c1 - c0
    w_all, c_all = t2 - t0, c2 - c0
    print(f"  single ambient (baseline)  wall {w_single:7.2f} s  cpu {c_single:7.2f} s")
    print(f"  three ambients             wall {w_all:7.2f} s  cpu {c_all:7.2f} s  "
          f"(laws: {res.metadata['temperature_laws_nfev']} evaluations, {t2 - t1:.2f} s wall)")  # fmt: skip
    met = {k: "met" if v <= 60.0 else "NOT met" for k, v in (("wall", w_all), ("cpu", c_all))}
    print(f"  three / single: wall {w_all / w_single:.2f}, cpu {c_all / c_single:.2f}   target <= 60 s: "
          f"{met['wall']} (wall), {met['cpu']} (cpu)")  # fmt: skip
    print(f"  {load.text()}")


if __name__ == "__main__":
    main()
