"""Speed of the module co-simulation with the 3-D coolant (issue 19: "the 300 s module
co-simulation with the 3D coolant (frozen flow) <= 60 s").

Run from the repository root::

    .venv/bin/python benchmarks/bench_cht.py [--duration 300] [--flow-l-min 0.25]
    .venv/bin/python benchmarks/bench_cht.py --flow-l-min 10    # the thesis's rate: RANS + wall function

At 10 L/min (above the laminar limit) the 3-D coolant's flow is a RANS solution from OpenFOAM
(setup: about a minute of CPU) on the example's :data:`TURBULENT_MESH` coolant mesh, with the
thermal wall function.

Runs the system of ``examples/cosim_module/run_module_cht.py`` (load, in-process 2s6p module,
3-D FEM module, coolant; Gauss-Seidel, 1 s exchange) twice in this process: first with the 1-D
coolant channel (the baseline), then with the 3-D coolant
(:class:`hevsim.cosim.coolant_cht.CoolantCHTParticipant`). Reports for each the wall and CPU
time of the whole run and, for the 3-D coolant, its setup (the flow solve and the heat-transfer
assembly and steady response, done once: the flow is frozen) apart from the stepping, with
the ratios to the baseline. The script only reports: it always exits 0.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(ROOT / "examples" / "cosim_module"))
from _machine import OtherLoad  # noqa: E402

TARGET_S = 60.0


def _children_cpu_s() -> float:
    """CPU time [s] of this process's finished child processes (OpenFOAM for a RANS flow)."""
    import resource

    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return float(r.ru_utime + r.ru_stime)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--duration", type=float, default=300.0, help="simulated time [s]")
    ap.add_argument(
        "--flow-l-min", type=float, default=0.25, help="flow rate [L/min] (0.25: Re 86; 10: Re 3451, RANS)"
    )
    args = ap.parse_args()

    from run_module_cht import module_cht_system

    from hevsim.cosim.system import run_cosim

    times: dict[str, tuple[float, float]] = {}
    with OtherLoad() as load, tempfile.TemporaryDirectory() as tmp:
        for model in ("1d", "cht"):
            desc = module_cht_system(args.duration, model, "inprocess", args.flow_l_min)
            w0, c0, k0 = time.perf_counter(), time.process_time(), _children_cpu_s()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # the coarse-mesh warning is reported by the example
                res = run_cosim(desc, Path(tmp) / model)
            times[model] = (time.perf_counter() - w0, time.process_time() - c0)
            times[f"{model} children"] = (_children_cpu_s() - k0, float("nan"))
            print(
                f"{model:4s}: outlet {res['coolant.outlet_temp_k'][-1] - 273.15:.3f} degC, hottest cell "
                f"{res['fem.cell_max_temp_k'][-1] - 273.15:.3f} degC, "
                f"stepping wall {res.stats['wall_s']:.1f} s"
            )
            times[f"{model} stepping"] = (float(res.stats["wall_s"]), float("nan"))
    (w1, c1), (w3, c3) = times["1d"], times["cht"]
    step1, step3 = times["1d stepping"][0], times["cht stepping"][0]
    print(f"1-D coolant, whole run      : wall {w1:7.1f} s, CPU {c1:7.1f} s (baseline)")
    print(
        f"3-D coolant, whole run      : wall {w3:7.1f} s, CPU {c3:7.1f} s "
        f"({w3 / w1:.2f} x wall, {c3 / c1:.2f} x CPU); OpenFOAM (child processes) CPU "
        f"{times['cht children'][0]:.1f} s"
    )
    print(f"1-D coolant, stepping only  : wall {step1:7.1f} s (baseline)")
    print(
        f"3-D coolant, stepping only  : wall {step3:7.1f} s ({step3 / step1:.2f} x; frozen flow; "
        f"setup {w3 - step3:.1f} s)"
    )
    print(f"target: {args.duration:g} s co-simulation with the 3-D coolant <= {TARGET_S:g} s")
    print(load.text())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
