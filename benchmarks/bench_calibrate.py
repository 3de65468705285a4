"""Time of a whole-set identification on a 12-hour HPPC-like test (issue 14: target <= 30 s).

Run from the repository root::

    .venv/bin/python benchmarks/bench_calibrate.py [--hours 12] [--repeats 1]

The test record is made by hevsim's own cell (the shipped ``thesis_table_4_1`` set, 0.8 A h,
25 degC, from SOC 0.95) over the pulse pattern of ``examples/validation/make_dfn_data.py``
(1C/2C/3C discharge and charge pulses of 10 s with 40 s rests at each SOC level, a 1C
discharge of 0.1 SOC between levels) with the rests stretched so the test lasts ``--hours``.
``hevsim.battery.identify.identify`` then fits OCV, R0, two RC pairs, the charge-transfer
term and the thermal pair, as ``hevsim calibrate PARAMS TEST.csv`` without ``--fit`` does.

Timed (``time.perf_counter``, numba cache warmed on a short record first): the identification
with the Jacobian's columns on 1 thread (the baseline) and on the threads
``hevsim.threads`` chooses (``HEVSIM_THREADS`` sets them), and the ratio. The fitted
parameters of the two runs are compared (they must be equal: the same evaluations, only mapped
over threads). The script only reports: it always exits 0.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from _machine import OtherLoad
from hevsim.battery import Cell, load_cell_parameters
from hevsim.battery.calibrate import CellTestRecord
from hevsim.battery.identify import identify

CELL = "thesis_table_4_1"
SOC_START = 0.95
AMBIENT_K = 298.15
LEVELS = 8


def hppc_current(capacity_ah: float, hours: float) -> np.ndarray:
    """Cell current [A] at 1 s of the pulse pattern, rests stretched to last ``hours`` [h]."""
    pulses = [
        (r * s * capacity_ah, d) for r in (1.0, 2.0, 3.0) for s, d in ((1, 10), (0, 40), (-1, 10), (0, 40))
    ]
    level_s = sum(d for _, d in pulses) + 360
    rest_s = max(300, int((hours * 3600 - 600) / LEVELS) - level_s)
    segments = [(0.0, 600)]
    for _ in range(LEVELS):
        segments += [*pulses, (capacity_ah, 360), (0.0, rest_s)]
    return np.concatenate([np.full(d, i) for i, d in segments])


def record(hours: float) -> CellTestRecord:
    params = load_cell_parameters(CELL)
    current = hppc_current(params.capacity.c0_c / 3600.0, hours)
    ts = Cell(params, soc_initial=SOC_START, temp_k=AMBIENT_K).simulate(current, 1.0, AMBIENT_K).timeseries
    t = np.arange(1.0, current.size + 1.0)
    return CellTestRecord(
        t, current, ts["voltage_v"].to_numpy(), ts["temp_k"].to_numpy(), source="synthetic HPPC"
    )


def run(rec: CellTestRecord, threads: int) -> tuple[float, np.ndarray]:
    os.environ["HEVSIM_THREADS"] = str(threads)
    t0 = time.perf_counter()
    res = identify(CELL, rec, soc_initial=SOC_START, port_temp_k=AMBIENT_K)
    return time.perf_counter() - t0, res.parameters["value"].to_numpy(dtype=float)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hours", type=float, default=12.0, help="test length [h] (default 12)")
    args = ap.parse_args()
    from hevsim.threads import choose_threads

    chosen = choose_threads(os.environ.get("HEVSIM_THREADS") or None).threads
    run(record(1.0), 1)  # numba cache, imports
    rec = record(args.hours)
    print(
        f"identification on a {rec.time_s.size / 3600:.1f} h HPPC-like test ({rec.time_s.size} rows, {CELL})"
    )
    with OtherLoad() as load:
        t1, p1 = run(rec, 1)
        tn, pn = run(rec, chosen)
    same = np.array_equal(p1, pn, equal_nan=True)
    print(f"  1 thread:            {t1:7.2f} s")
    print(f"  {chosen} thread(s) (chosen): {tn:7.2f} s   ratio {tn / t1:.2f}   target <= 30 s: "
          f"{'met' if tn <= 30.0 else 'NOT met'}")  # fmt: skip
    print(f"  fitted parameters identical: {same}")
    print(f"  {load.text()}")


if __name__ == "__main__":
    main()
