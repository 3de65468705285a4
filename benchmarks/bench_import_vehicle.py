"""Imported FASTSim vehicles (``hevsim import-vehicle``) on UDDS and HWFET: hevsim vs FASTSim
(fastsim 3, reading the same fastsim-2 file, in the same run) vs the EPA values (``val*``
columns of FASTSim's vehicle database, where the vehicle is in it).

Fuel economy is unadjusted miles per gallon of gasoline equivalent at 33.7 kWh/gal (FASTSim's
``kwh_per_gge``; the import writes that gallon into the vehicle's [fuel]) for engine
vehicles, SOC-corrected for hybrids (hevsim: its SOC correction; FASTSim 3: its SOC-balance
iteration); battery kWh per mile for BEVs (both at the battery terminals; the EPA figure is
adjusted and from the wall). The EPA ``val_udds_mpgge`` / ``val_hwy_mpgge`` of the database are
label (adjusted) city / highway values, so they sit below both models' unadjusted figures.

Run: ``python benchmarks/bench_import_vehicle.py`` (fastsim optional: ``pip install
'hevsim[bench]'``). Prints a Markdown table and the median |hevsim / FASTSim - 1|.
"""

from __future__ import annotations

import sys
import tempfile
import time
import warnings
from importlib import resources
from pathlib import Path

import numpy as np

from hevsim.sim.simulator import simulate
from hevsim.vehicle_import import ARCHITECTURE_OF, import_vehicle, list_vehicles, read_vehicle

DATA = Path(str(resources.files("hevsim") / "data" / "vehicles" / "fastsim"))
KWH_PER_GGE = 33.7
M_PER_MI = 1609.344


def _fastsim_yaml(src: Path, tmp: Path) -> Path:
    """A fastsim-2 YAML of ``src`` for fastsim 3 (a CSV becomes YAML on a template's schema,
    :func:`hevsim.validation.fastsim_db.fastsim_yaml`: fastsim-2's default efficiency curve
    where the file has none, which fastsim 3 would refuse)."""
    if src.suffix == ".yaml":
        return src
    from hevsim.validation.fastsim_db import fastsim_yaml

    return fastsim_yaml(read_vehicle(src), tmp / (src.stem + ".yaml"))


def fastsim_figures(src: Path, tmp: Path, pt: str) -> dict[str, float]:
    """FASTSim 3's unadjusted mpgge (or battery kWh/mi) on UDDS and HWFET; {} without fastsim."""
    try:
        import fastsim as fs
    except ImportError:
        return {}
    out: dict[str, float] = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for cyc in ("udds", "hwfet"):
            try:
                veh = fs.Vehicle.from_f2_file(str(_fastsim_yaml(src, tmp)))
                sd = fs.SimDrive(veh, fs.Cycle.from_resource(f"{cyc}.csv"))
                sd.walk()
            except Exception as exc:  # fastsim refuses some files; say so in the table
                out[cyc] = float("nan")
                print(f"  fastsim: {src.name} {cyc}: {str(exc).splitlines()[0][:100]}", file=sys.stderr)
                continue
            d = sd.to_dict()
            miles = d["veh"]["state"]["dist_meters"] / M_PER_MI
            inner = next(iter(d["veh"]["pt_type"].values()))
            if pt == "BEV":
                res = inner["res"]["state"]
                e = res.get("energy_out_chemical_joules", res.get("energy_out_electrical_joules", np.nan))
                out[cyc] = e / 3.6e6 / miles
            else:
                out[cyc] = miles / (inner["fc"]["state"]["energy_fuel_joules"] / 3.6e6 / KWH_PER_GGE)
    return out


SOC_BALANCE_TOLERANCE = 0.005
"""|final - initial SOC| [-] at which a hybrid's run counts as charge-sustaining (FASTSim's
``ess_to_fuel_ok_error`` is the same 0.005 in its files)."""


def hevsim_figures(toml: Path, pt: str) -> dict[str, float]:
    """hevsim's figure per cycle: BEV battery kWh/mi; engine vehicles mpgge; hybrids the mpg of a
    SOC-balanced run (initial SOC set to the previous run's final SOC until they agree within
    :data:`SOC_BALANCE_TOLERANCE`, as FASTSim 3 balances its HEVs), else the SOC-corrected mpgge."""
    out = {}
    for cyc in ("udds", "hwfet"):
        m = simulate(toml, cyc, tracking=None).metrics
        if pt == "BEV":
            out[cyc] = m["battery_energy_wh"]["value"] / 1e3 / m["distance_mi"]["value"]
            continue
        out[cyc] = m["mpgge"]["value"]
        if pt == "HEV":
            for _ in range(20):
                soc0, soc1 = m["soc_initial"]["value"], m["soc_final"]["value"]
                if abs(soc1 - soc0) <= SOC_BALANCE_TOLERANCE:
                    out[cyc] = m["mpg"]["value"]
                    break
                m = simulate(toml, cyc, soc_initial=soc1, tracking=None).metrics
    return out


def main() -> None:
    db = {
        name.strip().lower(): read_vehicle(DATA / "FASTSim_py_veh_db.csv", row=i)
        for i, name, _ in list_vehicles(DATA / "FASTSim_py_veh_db.csv")
    }
    files = sorted(p for p in (DATA / "vehdb").iterdir() if p.suffix in (".yaml", ".csv"))
    rows = []
    t0 = time.perf_counter()
    t_fs = 0.0
    with tempfile.TemporaryDirectory() as tmp_s:
        tmp = Path(tmp_s)
        for i, src in enumerate(files):
            v = read_vehicle(src)
            pt = str(v["veh_pt_type"])
            if pt not in ARCHITECTURE_OF:
                continue
            toml = import_vehicle(src, tmp / f"v{i}.toml")
            ours = hevsim_figures(toml, pt)
            t1 = time.perf_counter()
            theirs = fastsim_figures(src, tmp, pt)
            t_fs += time.perf_counter() - t1
            ref = db.get(str(v.get("scenario_name", "")).strip().lower(), {})
            unit = "kWh/mi" if pt == "BEV" else "mpgge"
            epa = (
                (ref.get("val_udds_kwh_per_mile"), ref.get("val_hwy_kwh_per_mile"))
                if pt == "BEV"
                else (ref.get("val_udds_mpgge"), ref.get("val_hwy_mpgge"))
            )
            rows.append((src.name, pt, unit, ours, theirs, epa))
    t_all = time.perf_counter() - t0

    def f(x: object) -> str:
        return "-" if x is None or (isinstance(x, float) and (not np.isfinite(x) or x == 0.0)) else f"{x:.3g}"

    print(
        "| file | type | unit | hevsim UDDS | FASTSim UDDS | EPA city (label) | hevsim HWFET | FASTSim HWFET "
        "| EPA hwy (label) |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    ratios = []
    for name, pt, unit, ours, theirs, epa in rows:
        print(
            f"| {name} | {pt} | {unit} | {f(ours['udds'])} | {f(theirs.get('udds'))} | {f(epa[0])} | "
            f"{f(ours['hwfet'])} | {f(theirs.get('hwfet'))} | {f(epa[1])} |"
        )
        for c in ("udds", "hwfet"):
            if np.isfinite(theirs.get(c, np.nan)):
                ratios.append((pt, ours[c] / theirs[c] - 1.0))
    for pt in sorted({p for p, _ in ratios}):
        r = np.abs([x for p, x in ratios if p == pt])
        print(
            f"{pt}: median |hevsim / FASTSim - 1| = {100 * np.median(r):.1f} % over {r.size} runs "
            f"(max {100 * r.max():.1f} %)"
        )
    print(f"time: {t_all:.1f} s in all, of which FASTSim {t_fs:.1f} s ({len(rows)} vehicles x 2 cycles)")


if __name__ == "__main__":
    main()
