"""The battery-module co-simulation with the 3-D coolant (conjugate heat transfer on a frozen
flow) instead of the 1-D channel, side by side with the 1-D channel at the same flow rate.

By default at :data:`FLOW_L_MIN` = 0.25 L/min (Re 86, laminar: the flow solver of
:mod:`hevsim.thermal.flow`). ``--flow-l-min 10`` runs the thesis's 10 L/min (Re about 3450,
turbulent in our 8 x 4 mm channel): the flow is then a RANS solution from OpenFOAM
(:mod:`hevsim.thermal.rans`, about a minute of CPU), frozen, and the coolant's wall layer is
bridged by the thermal wall function on a :data:`TURBULENT_MESH` coolant mesh
(:mod:`hevsim.thermal.wall_function`; docs/flow.md). Everything else is ``module.ssd``'s
system (``run_module.py``): load, 2s6p battery, 3-D FEM module, with the ``coolant``
participant replaced by :class:`hevsim.cosim.coolant_cht.CoolantCHTParticipant` (frozen flow,
solved once at start).

Run:  .venv/bin/python examples/cosim_module/run_module_cht.py [OUT_DIR] [--duration 300]
          [--flow-l-min 10]
      (both coolant models, in-process battery; prints outlet and per-cell temperatures)
  or  make examples && hevsim cosim examples/cosim_module/module_cht.ssd --out OUT_DIR
Rewrite the shipped module_cht.ssd: run_module_cht.py --write-shipped
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from run_module import N_CELLS, module_system  # noqa: E402

from hevsim.cosim.ssd import SystemDescription  # noqa: E402
from hevsim.cosim.ssp_write import write_ssd  # noqa: E402
from hevsim.cosim.system import run_cosim  # noqa: E402

#: Laminar flow rate of the variant [L/min] (Re 86 with the Table 4.4 properties).
FLOW_L_MIN = 0.25
#: Grad-div stabilisation of the flow [-] (:class:`hevsim.thermal.flow.FlowSection`): a better
#: mass conservation of the Taylor-Hood flow on the default mesh (the coolant's heat balance is
#: exact either way, through the divergence correction of hevsim.thermal.cht).
GRAD_DIV = 10.0
#: Coolant mesh of the 3-D coolant above the laminar limit (``[flow]`` keys): 8 x 4 cells across
#: (1 x 1 mm wall cells, y+ about 50 at 10 L/min, inside the thermal wall function's range;
#: the default 4 x 2 puts the wall node on the channel's centre line, beyond it).
TURBULENT_MESH = {"cells_across_width": 8, "cells_across_height": 4}
#: Highest laminar flow rate of the shipped channel [L/min] (Re 2300 with Table 4.4 properties).
LAMINAR_L_MIN_MAX = 6.6
#: Coolant participants by model name.
COOLANTS = {
    "1d": "hevsim.cosim.coolant:CoolantChannelParticipant",
    "cht": "hevsim.cosim.coolant_cht:CoolantCHTParticipant",
}


def module_cht_system(
    duration_s: float = 300.0, coolant: str = "cht", battery: str = "fmu", flow_l_min: float = FLOW_L_MIN
) -> SystemDescription:
    """``module.ssd``'s system with the coolant model ``coolant`` (``1d`` or ``cht``) at
    ``flow_l_min`` [L/min]."""
    sys_ = module_system(duration_s, battery=battery)
    comps = [
        dataclasses.replace(
            c,
            source=COOLANTS[coolant],
            parameters={
                **c.parameters,
                "flow_l_min": flow_l_min,
                **({"grad_div": GRAD_DIV} if coolant == "cht" else {}),
                **(TURBULENT_MESH if coolant == "cht" and flow_l_min > LAMINAR_L_MIN_MAX else {}),
            },
        )
        if c.name == "coolant"
        else c
        for c in sys_.components
    ]
    return dataclasses.replace(sys_, components=comps)


def compare(
    out: Path, duration_s: float = 300.0, battery: str = "inprocess", flow_l_min: float = FLOW_L_MIN
) -> dict[str, dict[str, object]]:
    """Run both coolant models at ``flow_l_min`` [L/min]; return (and write
    ``out/comparison.json``) the outlet temperature, cooling power and per-cell temperatures at
    the end [degC, W], the outlet at 10 s and 60 s [degC] and the wall times [s]."""
    table: dict[str, dict[str, object]] = {}
    out.mkdir(parents=True, exist_ok=True)
    for model in COOLANTS:
        res = run_cosim(module_cht_system(duration_s, model, battery, flow_l_min), out / model)
        table[model] = {
            "outlet_temp_c": float(res["coolant.outlet_temp_k"][-1] - 273.15),
            "cooling_power_w": float(res["coolant.cooling_power_w"][-1]),
            "cell_temp_c": [float(res[f"fem.cell{c}_temp_k"][-1] - 273.15) for c in range(N_CELLS)],
            "cell_max_temp_c": float(res["fem.cell_max_temp_k"][-1] - 273.15),
            "plate_max_temp_c": float(res["fem.plate_max_temp_k"][-1] - 273.15),
            **{
                f"outlet_at_{int(ts)}s_temp_c": float(
                    np.interp(ts, res.time_s, res["coolant.outlet_temp_k"]) - 273.15
                )
                for ts in (10.0, 60.0)
                if ts <= duration_s
            },
            "wall_s": float(res.stats["wall_s"]),
        }
    (out / "comparison.json").write_text(json.dumps(table, indent=1))
    return table


def main() -> None:
    ap = argparse.ArgumentParser(description="module co-simulation: 3-D vs 1-D coolant")
    ap.add_argument("out", nargs="?", default="results/cosim_module_cht")
    ap.add_argument("--duration", type=float, default=300.0)
    ap.add_argument("--flow-l-min", type=float, default=FLOW_L_MIN, help="coolant flow rate [L/min]")
    ap.add_argument("--write-shipped", action="store_true", help="rewrite module_cht.ssd, then exit")
    a = ap.parse_args()
    if a.write_shipped:
        print(f"wrote {write_ssd(module_cht_system(), HERE / 'module_cht.ssd')}")
        return
    t = compare(Path(a.out), a.duration, flow_l_min=a.flow_l_min)
    kind = "3-D RANS" if a.flow_l_min > LAMINAR_L_MIN_MAX else "3-D laminar"
    print(f"coolant {a.flow_l_min:g} L/min, {a.duration:g} s  {'1-D channel':>12s} {kind:>12s}")
    for key, label in (
        ("outlet_temp_c", "outlet [degC]"),
        ("outlet_at_10s_temp_c", "outlet at 10 s [degC]"),
        ("outlet_at_60s_temp_c", "outlet at 60 s [degC]"),
        ("cooling_power_w", "cooling [W]"),
        ("cell_max_temp_c", "hottest cell [degC]"),
        ("plate_max_temp_c", "plate max [degC]"),
        ("wall_s", "wall time [s]"),
    ):
        if key in t["1d"]:
            print(f"{label:30s} {t['1d'][key]:12.3f} {t['cht'][key]:12.3f}")
    for c in range(N_CELLS):
        a1, a3 = t["1d"]["cell_temp_c"], t["cht"]["cell_temp_c"]
        print(f"cell {c:2d} [degC]                  {a1[c]:12.3f} {a3[c]:12.3f}")  # type: ignore[index]


if __name__ == "__main__":
    main()
