"""Where a fuel-cell vehicle's UDDS energy goes, hevsim vs FASTSim 3 (docs/validation.md, the
Tucson Fuel Cell under "Honest failures").

For FASTSim's database rows 23 (2016 Hyundai Tucson Fuel Cell) and 24 (Toyota Mirai): hevsim
imports the row (``hevsim import-vehicle``), finds the SOC-balanced initial SOC of its UDDS
(``hevsim label``) and runs that UDDS (``hevsim simulate``); FASTSim 3 runs ``SimDrive.walk`` on
the same fastsim-2 vehicle (as :mod:`hevsim.validation.fastsim_db` builds it) on its UDDS. Printed
per model [MJ]: road load (aero + rolling), positive and negative wheel (tractive) energy, the
braking energy recovered electrically, the fuel cell's net output and hydrogen, the SOC range,
and for FASTSim 3 the steps its controller keeps the fuel converter on "charging for low SOC".
With fastsim 2 installed instead (``pip install "fastsim>=2.1,<3"`` in a separate environment,
which need not hold hevsim's dependencies: ``--models fastsim``), the FASTSim side is fastsim-2's
own ``RustSimDrive.sim_drive`` (SOC-balanced) on the row and its ``get_label_fe`` figures.
Run from the repository root::

    .venv/bin/python benchmarks/fcev_energy_breakdown.py [--rows 23 24] [--models hevsim fastsim]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np

DATABASE = Path(__file__).resolve().parents[1] / "src/hevsim/data/vehicles/fastsim/FASTSim_py_veh_db.csv"
"""The shipped FASTSim vehicle database (read directly by the fastsim-2 side)."""


def hevsim_side(row: int, work: Path) -> dict[str, float]:
    """hevsim's SOC-balanced UDDS of database row ``row`` [MJ, -]."""
    from hevsim.validation.fastsim_db import database_path

    toml = work / f"row{row}.toml"
    cli = [sys.executable, "-m", "hevsim.cli"]
    run = {"check": True, "capture_output": True}
    subprocess.run([*cli, "import-vehicle", str(database_path()), "--row", str(row), "-o", str(toml)], **run)
    subprocess.run([*cli, "label", str(toml), "-o", str(work / f"lab{row}")], **run)
    lab = json.loads((work / f"lab{row}" / "label.json").read_text())
    soc0 = lab["tests"]["city"]["runs"][-1]["soc_initial"]
    out = work / f"sim{row}"
    args = ["--cycle", "udds", "--soc-initial", repr(soc0), "--out", str(out), "--csv", "--no-plots"]
    subprocess.run([*cli, "simulate", str(toml), *args], **run)
    import pandas as pd

    d = pd.read_csv(out / "timeseries.csv")
    audit = {k: v["value"] / 1e6 for k, v in json.loads((out / "energy_audit.json").read_text()).items()}
    w, m = d["wheel_power_w"].to_numpy(), d["motor_power_elec_w"].to_numpy()
    return {
        "road load": audit["aero"] + audit["rolling"],
        "wheel +": w[w > 0].sum() / 1e6,
        "wheel -": -w[w < 0].sum() / 1e6,
        "recovered (motor, electric)": -m[m < 0].sum() / 1e6,
        "friction brakes": audit["friction_brakes"],
        "fuel cell out": d["fuel_cell_power_w"].sum() / 1e6,
        "hydrogen": audit["fuel"],
        "soc min": float(d["soc"].min()),
        "soc max": float(d["soc"].max()),
    }


def fastsim_side(row: int, work: Path) -> dict[str, float]:
    """FASTSim 3's UDDS (``SimDrive.walk``) of database row ``row`` [MJ, -]."""
    import fastsim as fs

    from hevsim.validation.fastsim_db import database_path, fastsim_yaml
    from hevsim.vehicle_import import read_vehicle

    v = read_vehicle(database_path(), row=row)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        veh = fs.Vehicle.from_f2_file(str(fastsim_yaml(v, work / f"row{row}_f2.yaml")))
        sd = fs.SimDrive(veh, fs.Cycle.from_resource("udds.csv"))
        sd.walk()
        out = sd.to_pydict()
    h, vh = out["veh"]["pt_type"]["HEV"], out["veh"]["history"]
    fc, em, res = h["fc"]["history"], h["em"]["history"], h["res"]["history"]
    pt = np.asarray(vh["pwr_tractive_watts"])
    em_mech = np.asarray(em["pwr_mech_prop_out_watts"])
    pres = np.asarray(res["pwr_out_electrical_watts"])
    ctl = h["pt_cntrl"]["RGWDB"]["history"]
    return {
        "road load": (vh["energy_drag_joules"][-1] + vh["energy_rr_joules"][-1]) / 1e6,
        "wheel +": pt[pt > 0].sum() / 1e6,
        "wheel -": -pt[pt < 0].sum() / 1e6,
        "motor generating (mechanical: regen + fuel-converter charging)": -em_mech[em_mech < 0].sum() / 1e6,
        "battery charged": -pres[pres < 0].sum() / 1e6,
        "fuel cell out": fc["energy_prop_joules"][-1] / 1e6,
        "hydrogen": fc["energy_fuel_joules"][-1] / 1e6,
        "soc min": float(min(res["soc"])),
        "soc max": float(max(res["soc"])),
        "soc_fc_on_buffer max": float(max(ctl["soc_fc_on_buffer"])),
        "steps 'charging for low SOC'": float(sum(ctl["charging_for_low_soc"])),
        "steps": float(len(ctl["charging_for_low_soc"])),
    }


def fastsim2_side(row: int, work: Path) -> dict[str, float]:
    """fastsim-2's SOC-balanced UDDS (``RustSimDrive.sim_drive``) of database row ``row`` and its
    label's unadjusted UDDS / HWFET mpgge [MJ, -, mpgge]."""
    import fastsim as fsim
    from fastsim import simdrivelabel

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        veh = fsim.vehicle.Vehicle.from_vehdb(row, veh_file=str(DATABASE)).to_rust()
        lab = simdrivelabel.get_label_fe(veh, use_rust=True)
        sd = fsim.simdrive.RustSimDrive(fsim.cycle.Cycle.from_file("udds").to_rust(), veh)
        sd.sim_drive()
    whl = np.asarray(sd.cyc_whl_kw_req)
    mc = np.asarray(sd.mc_mech_kw_out_ach)
    soc = np.asarray(sd.soc)
    return {
        "veh_kg": float(veh.veh_kg),
        "wheel +": whl[whl > 0].sum() / 1e3,
        "wheel -": -whl[whl < 0].sum() / 1e3,
        "motor generating (mechanical)": -mc[mc < 0].sum() / 1e3,
        "fuel cell out": float(np.sum(sd.fc_kw_out_ach)) / 1e3,
        "hydrogen": float(np.sum(sd.fs_kwh_out_ach)) * 3.6,
        "soc min": float(soc.min()),
        "soc max": float(soc.max()),
        "label udds mpgge": float(lab["labUddsMpgge"]),
        "label hwy mpgge": float(lab["labHwyMpgge"]),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, nargs="+", default=[23, 24])
    ap.add_argument("--models", nargs="+", default=["hevsim", "fastsim"], choices=["hevsim", "fastsim"])
    args = ap.parse_args(argv)
    sides = [("hevsim", hevsim_side)] if "hevsim" in args.models else []
    if "fastsim" in args.models:
        import fastsim

        v2 = str(getattr(fastsim, "__version__", "3")).startswith("2")
        sides.append(("fastsim 2", fastsim2_side) if v2 else ("FASTSim 3", fastsim_side))
    with tempfile.TemporaryDirectory(prefix="hevsim-fcev-") as tmp:
        work = Path(tmp)
        for row in args.rows:
            for name, side in sides:
                d = side(row, work)
                print(f"row {row} {name}: " + ", ".join(f"{k} {x:.4g}" for k, x in d.items()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
