"""Where a plug-in hybrid's charge-sustaining (CS) label energy goes, hevsim vs FASTSim 3
(docs/validation.md, "PHEVs' charge-sustaining mpg").

For FASTSim database rows (default the four PHEVs 12, 13, 14, 16): hevsim imports the row and
runs ``hevsim label``; for the SOC-balanced CS UDDS and HWFET it prints [MJ] the fuel, the
engine's mechanical output and mean efficiency, its on-time and mean power when on, the motor
and battery losses, the SOC range and the balance (NEC / fuel energy). ``--no-hold``: the same
with the electric assist's charge-hold switched off (a diagnostic: ``ElectricAssist.holds``
returns False, Python loop). With FASTSim 3 installed (the ``bench`` extra): its
``get_label_fe`` CS figures of the same file, the charge its CS runs leave in the battery
(``phev_calcs.*.cs_ess_kwh``, negative: charged) and its CS mpg with that charge credited at
the engine's peak efficiency (``fc_eff_map`` maximum; a lower bound of the fuel it cost), all
through the same label equations (adjusted combined). Run from the repository root::

    .venv/bin/python benchmarks/phev_cs_energy_breakdown.py [--rows 12 13 14 16] [--no-hold]
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import warnings
from pathlib import Path
from typing import Any

import numpy as np

KWH_PER_GALLON = 33.7
"""FASTSim's kWh per gallon of gasoline equivalent (the import's gallon too)."""


def hevsim_side(row: int, work: Path) -> dict[str, Any]:
    """hevsim's SOC-balanced CS tests of database row ``row``: figures per test, and the adjusted
    combined CS mpg."""
    from hevsim.sim.label import label
    from hevsim.validation.fastsim_db import combined_label, database_path, rows
    from hevsim.vehicle_import import import_vehicle

    toml = import_vehicle(database_path(), work / f"row{row}.toml", row=row, force=True)
    r = next(r for r, _ in rows() if r.row == row)
    lab = label(toml, model_year=r.model_year)
    out: dict[str, Any] = {}
    for name, t in lab.tests.items():
        a, ts = t.result.energy_audit, t.result.timeseries
        dt = np.diff(ts["time_s"].to_numpy(), prepend=0.0)
        dt[0] = dt[1]
        pe = np.clip(ts["engine_power_w"].to_numpy(), 0.0, None)
        on = ts["engine_on"].to_numpy() > 0
        soc = ts["soc"].to_numpy()
        e_out = float(np.sum(pe * dt))
        out[name] = {
            "fuel": a["fuel"] / 1e6,
            "engine out": e_out / 1e6,
            "engine eff": e_out / a["fuel"],
            "engine on s": float(np.sum(dt[on])),
            "mean kW on": float(pe[on].mean() / 1e3) if on.any() else 0.0,
            "motor loss": a["motor_loss"] / 1e6,
            "battery loss": a.get("battery_loss", 0.0) / 1e6,
            "soc min": float(soc.min()),
            "soc max": float(soc.max()),
            "NEC/fuel": float(t.balance or 0.0),
        }
    u = lab.figures["unadjusted_mpg"]
    out["combined"] = combined_label(u["city"], u["highway"], r.model_year, False, 1.0)
    out["epa"] = r.epa
    return out


def fastsim_side(row: int, work: Path) -> dict[str, Any]:
    """FASTSim 3's CS figures of row ``row``: mpg, charge left in the battery, credited mpg."""
    import fastsim as fs

    from hevsim.validation.fastsim_db import combined_label, database_path, fastsim_yaml, rows
    from hevsim.vehicle_import import read_vehicle

    v = read_vehicle(database_path(), row=row)
    r = next(r for r, _ in rows() if r.row == row)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        veh = fs.Vehicle.from_f2_file(str(fastsim_yaml(v, work / f"row{row}_f2.yaml")))
        lab = json.loads(fs.get_label_fe(veh).to_json())
    curve = v.get("fc_eff_map")
    if not isinstance(curve, list):  # fastsim-2's default curve of fc_eff_type, as the import takes it
        from hevsim.vehicle_import import FC_EFF_MAPS

        curve = list(FC_EFF_MAPS.get(str(v.get("fc_eff_type", "")).strip(), FC_EFF_MAPS["SI"]))
    eta = max(float(x) for x in curve)
    out: dict[str, Any] = {"peak engine eff": eta}
    mpg, credited = [], []
    for name in ("udds", "hwy"):
        c = lab["phev_calcs"][name]
        gal, ess = float(c["cs_fs_gal"]), float(c["cs_ess_kwh"])
        miles = float(c["cs_mpg"]) * gal
        mpg.append(float(c["cs_mpg"]))
        credited.append(miles / (gal + ess / eta / KWH_PER_GALLON))
        out[f"{name} cs_ess_kwh"] = ess
    out["combined"] = combined_label(mpg[0], mpg[1], r.model_year, False, 1.0)
    out["combined, charge credited"] = combined_label(credited[0], credited[1], r.model_year, False, 1.0)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, nargs="+", default=[12, 13, 14, 16])
    ap.add_argument("--no-hold", action="store_true", help="diagnostic: the charge-hold off (Python loop)")
    args = ap.parse_args(argv)
    if args.no_hold:
        from hevsim.control import parallel as CP
        from hevsim.sim.forward import FORWARD_ENV

        os.environ[FORWARD_ENV] = "python"
        CP._RuleBased.holds = lambda self, soc: False  # type: ignore[method-assign]
    try:
        import fastsim

        with_fastsim = not str(getattr(fastsim, "__version__", "3")).startswith("2")
    except ImportError:
        with_fastsim = False
    with tempfile.TemporaryDirectory(prefix="hevsim-phev-cs-") as tmp:
        work = Path(tmp)
        for row in args.rows:
            h = hevsim_side(row, work)
            epa = h["epa"]
            tag = " (no hold)" if args.no_hold else ""
            err = 100 * (h["combined"] / epa - 1)
            print(f"row {row} hevsim{tag}: CS combined {h['combined']:.1f} mpg ({err:+.1f} % vs EPA {epa:g})")
            for name in ("city", "highway"):
                print(f"  {name}: " + ", ".join(f"{k} {x:.4g}" for k, x in h[name].items()))
            if with_fastsim:
                f = fastsim_side(row, work)
                err = 100 * (f["combined, charge credited"] / epa - 1)
                items = ", ".join(f"{k} {x:.4g}" for k, x in f.items())
                print(f"row {row} FASTSim 3: {items} (credited {err:+.1f} % vs EPA)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
