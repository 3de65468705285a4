"""Speed of the electro-thermal cell model (issue 4, item 9).

Run from the repository root::

    .venv/bin/python benchmarks/bench_cell.py [--repeats 20]

Profile: one hour of UDDS repeated at 1 Hz, turned into a per-cell current by the road-load
model of :func:`hevsim.battery.profiles.cycle_cell_current` (1200-cell pack), made
charge-sustaining as in a hybrid (its mean removed) and run from SOC 0.5. (The raw profile
draws about one full charge per hour: from SOC 1 it emptied the thesis cell at 3271 s, where
the cell's domain check rightly stopped the run; the check is unchanged.) Timed with
``time.perf_counter`` after a warm-up call (numba cache load / compile reported apart):

(a) one cell, the compiled kernel ``run_cell`` alone (target <= 5 ms);
(b) one cell through ``Cell.simulate`` (kernel + pandas result);
(c) 1200 independent cells (a 100-module pack) through ``simulate_cells`` (target <= 2 s);
(d) one 2s6p module (12 cells, parallel current sharing) through ``Module.simulate``.

Medians of ``--repeats`` runs. The script only reports: it always exits 0.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from _machine import OtherLoad, median_time
from hevsim.battery import Cell, Module, load_cell_parameters, simulate_cells
from hevsim.battery import kernel as K
from hevsim.battery.params import CellParameters, ChargeTransferSection, ModelSection
from hevsim.battery.profiles import cycle_cell_current

SOC_INITIAL = 0.5  # [-] every cell starts here; the profile is charge-sustaining


def charge_sustaining(current: np.ndarray) -> np.ndarray:
    """``current`` [A] with its mean removed: zero net charge over the profile."""
    return np.ascontiguousarray(current - current.mean())


def fidelity_set(name: str) -> CellParameters:
    """``name`` with the issue-14 options: persistent RC, in-step OCV, Butler-Volmer term."""
    p = load_cell_parameters(name)
    return p.replace(
        model=ModelSection(rc_mode="persistent", ocv_mode="step_consistent"),
        charge_transfer=ChargeTransferSection(i0_a=2.0, scale=1.0),
    )


def bench_set(name: str, current: np.ndarray, repeats: int, n_cells: int, fidelity: bool = False) -> None:
    """Time one parameter set (with the issue-14 options if ``fidelity``) and print the figures."""
    p = fidelity_set(name) if fidelity else load_cell_parameters(name)
    tabs = p.tables()
    prm = p.vector(SOC_INITIAL)
    tp = np.full(current.size, 298.15)
    out = np.empty((current.size, len(K.RECORD)))

    def kernel_once() -> None:
        x = p.initial_state(298.15)
        K.run_cell(prm, *tabs, x, current, 1.0, tp, out)

    t0 = time.perf_counter()
    kernel_once()
    first = time.perf_counter() - t0
    t_kernel = median_time(kernel_once, repeats)
    t_cell = median_time(lambda: Cell(p, SOC_INITIAL).simulate(current, 1.0, 298.15), repeats)
    t0 = time.perf_counter()
    simulate_cells(
        p, current, 1.0, 298.15, soc_initial=SOC_INITIAL, n_cells=2
    )  # warm-up (compile/cache load)
    first_b = time.perf_counter() - t0
    rng = np.random.default_rng(0)
    r_scale = 1.0 + 0.05 * rng.standard_normal(n_cells)
    few = max(3, repeats // 5)
    t_batch = median_time(
        lambda: simulate_cells(p, current, 1.0, 298.15, soc_initial=SOC_INITIAL, r_scale=r_scale), few
    )
    Module(p, soc_initial=SOC_INITIAL).simulate(current[:10], 1.0)
    t_mod = median_time(lambda: Module(p, soc_initial=SOC_INITIAL).simulate(current, 1.0), few)
    label = " + persistent RC, in-step OCV, Butler-Volmer" if fidelity else ""
    print(f"\n[{name}{label}] ({p.n_rc} RC element(s) per direction)")
    print(
        f"  first call (numba cache load or compile): kernel {first * 1e3:.1f} ms, "
        f"batch {first_b * 1e3:.1f} ms"
    )
    print(
        f"  (a) one cell, 1 h at 1 Hz, kernel:      {t_kernel * 1e3:8.3f} ms  "
        f"(target 5 ms: {t_kernel / 5e-3:.3f} of it)"
    )
    print(f"  (b) one cell, Cell.simulate:            {t_cell * 1e3:8.3f} ms")
    print(
        f"  (c) {n_cells} cells, simulate_cells:       {t_batch * 1e3:8.1f} ms  "
        f"(target 2 s: {t_batch / 2.0:.3f} of it)"
    )
    print(f"  (d) 2s6p module, Module.simulate:       {t_mod * 1e3:8.3f} ms")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=20)
    ap.add_argument("--cells", type=int, default=1200)
    args = ap.parse_args()
    raw = cycle_cell_current("udds", 3600.0, 1.0)
    current = charge_sustaining(raw)
    print(
        f"profile: {current.size} steps of 1 s, cell current {current.min():.2f} .. {current.max():.2f} A "
        f"(mean {raw.mean():.3f} A removed: charge-sustaining), from SOC {SOC_INITIAL}"
    )
    with OtherLoad() as load:
        for name in ("thesis_table_4_1", "saft_li_ion_6ah"):
            bench_set(name, current, args.repeats, args.cells)
        bench_set("thesis_table_4_1", current, args.repeats, args.cells, fidelity=True)
    print(f"\n{load.text()}")


if __name__ == "__main__":
    main()
