"""hevsim and FASTSim against the EPA label figures of FASTSim's vehicle database.

Every light-duty vehicle of ``FASTSim_py_veh_db.csv`` with EPA figures in its ``val*`` columns is
imported with :func:`hevsim.vehicle_import.import_vehicle` (no per-vehicle tuning) and labelled by
:func:`hevsim.sim.label.label`; FASTSim 3 (the ``bench`` extra) labels the same fastsim-2 vehicle in
the same run with its ``get_label_fe``. Both models' *unadjusted* UDDS and HWFET figures go through
the same label equations (the derived 5-cycle set of the vehicle's model year, hevsim's
:mod:`hevsim.sim.label`), and the adjusted combined figure is compared with the database's
``val_comb_mpgge`` (engine vehicles) or ``val_comb_kwh_per_mile`` (BEVs, from the wall: both
models' battery energy over the file's charger efficiency ``chg_eff``).

Plug-in hybrids (the PHEV rows): the row's main figure is the charge-sustaining (CS) combined mpg
against ``val_comb_mpgge`` (the label's CS figure); two more figures are compared in
:attr:`Row.extra`: the charge-depleting (CD) electricity from the wall against
``val_comb_kwh_per_mile`` (both models' CD battery kWh/mi per cycle through the BEV equations and
``chg_eff``) and the CD range against ``val_cd_range_mi`` (0.7 x the 55/45 combination of the
unadjusted CD ranges: hevsim's SAE J1711 actual range, FASTSim's ``total_cd_miles``). Fuel-cell
vehicles (``fc_eff_type = H2FC``, typed ``HEV`` by FASTSim): combined MPGe against
``val_comb_mpgge``, which is the EPA's miles per kg of hydrogen: both models count hydrogen in
FASTSim's gallons of 33.7 kWh, so their figures are converted to miles per kg (120 MJ/kg =
33.33 kWh: x 0.989) before the label equations.

Units: FASTSim and the import count fuel in gallons of gasoline equivalent (33.7 kWh); the EPA
label of a diesel car counts gallons of diesel, so a diesel's unadjusted mpgge is multiplied by
(diesel LHV x density x gallon, hevsim's fuel table) / 33.7 kWh before the label equations, and a
fuel-cell car's by 33.33 kWh (a kg of hydrogen) / 33.7 kWh.

Vehicles left out, with the reason in the table: rows without EPA figures (trucks, non-US cars),
and the rows of ``hevsim/data/validation/fastsim_db_not_epa.toml`` whose ``val*`` figures are
not an EPA label.
"""

from __future__ import annotations

import json
import math
import re
import tempfile
import time
import tomllib
import warnings
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from hevsim.errors import ConfigError

DATABASE = "data/vehicles/fastsim/FASTSim_py_veh_db.csv"
"""FASTSim's vehicle database, relative to the installed ``hevsim`` package."""
NOT_EPA_FILE = "data/validation/fastsim_db_not_epa.toml"
"""Database rows whose ``val*`` figures are not an EPA label (scenario name -> reason)."""
FASTSIM_KWH_PER_GGE = 33.7
"""FASTSim's gallon of gasoline equivalent [kWh] (``kwh_per_gge``), the gallon of the import's fuel."""
DEFAULT_MODEL_YEAR = 2016
"""Model year of a row that gives none (in ``veh_year`` or its name) [-]."""
EV_RANGE_FACTOR = 0.7
"""The label's adjustment of an electric range (adjusted = 0.7 x unadjusted) [-]."""
FASTSIM_TEMPLATE = "2016_TOYOTA_Prius_Two.yaml"
"""fastsim-2 YAML whose layout carries a database row into FASTSim 3 (``Vehicle.from_f2_file``)."""


@dataclass
class Row:
    """One vehicle of the database: its figures and the two models' labels."""

    row: int
    name: str
    powertrain: str
    model_year: int
    unit: str
    epa: float | None
    skipped: str = ""
    hevsim: float = math.nan
    fastsim: float = math.nan
    hevsim_unadjusted: tuple[float, float] = (math.nan, math.nan)
    fastsim_unadjusted: tuple[float, float] = (math.nan, math.nan)
    hevsim_s: float = 0.0
    fastsim_s: float = 0.0
    notes: list[str] = field(default_factory=list)
    extra_unadjusted: dict[str, tuple[tuple[float, float], tuple[float, float]]] = field(default_factory=dict)
    """A PHEV's unadjusted CD figures by model: ((city, highway) battery kWh/mi, (city, highway)
    range [mi])."""
    fastsim_own: dict[str, float] = field(default_factory=dict)
    """A PHEV's adjusted figures by FASTSim's own label equations (``adj_cs_comb_mpgge``,
    ``adj_comb_kwh_per_mi``, ``net_phev_cd_miles``), for reference."""
    extra: dict[str, list[float]] = field(default_factory=dict)
    """A PHEV's further figures: name -> [EPA, hevsim, FASTSim] ("cd_kwh_per_mi" from the wall,
    "cd_range_mi" adjusted)."""

    def error(self, which: str) -> float:
        """``which`` ("hevsim"/"fastsim") / EPA - 1 [-] (NaN when either is missing)."""
        x = getattr(self, which)
        return x / self.epa - 1.0 if self.epa and math.isfinite(x) else math.nan

    def extra_error(self, name: str, which: str) -> float:
        """The error of the further figure ``name`` of :attr:`extra` [-] (NaN when missing)."""
        epa, h, f = self.extra.get(name, [math.nan] * 3)
        x = h if which == "hevsim" else f
        return x / epa - 1.0 if epa > 0 and math.isfinite(x) else math.nan


def database_path() -> Path:
    """The shipped FASTSim vehicle database."""
    return Path(str(resources.files("hevsim") / DATABASE))


def _not_epa_tables() -> tuple[Path, dict[str, Any]]:
    """The path and the parsed tables of :data:`NOT_EPA_FILE`."""
    p = Path(str(resources.files("hevsim") / NOT_EPA_FILE))
    return p, tomllib.loads(p.read_text(encoding="utf-8"))


def carried_over(tables: tuple[Path, dict[str, Any]] | None = None) -> dict[str, tuple[str, str]]:
    """Scenario name -> (the scenario name of the row whose ``val*`` figures it carries, the
    vehicle's fastsim-2 file in ``hevsim/data/vehicles/fastsim/vehdb/``): the ``[carried_over]``
    table of :data:`NOT_EPA_FILE` (``tables``: that file already read, :func:`_not_epa_tables`)."""
    p, data = tables or _not_epa_tables()
    out = {}
    for k, v in data.get("carried_over", {}).items():
        if (
            not isinstance(v, dict)
            or not isinstance(v.get("from"), str)
            or not isinstance(v.get("file"), str)
        ):
            raise ConfigError(
                f'{p}: [carried_over] {k!r} = {v!r}: expected {{ from = "scenario name", file = "X.csv" }}'
            )
        out[str(k)] = (v["from"], v["file"])
    return out


def not_epa() -> dict[str, str]:
    """Scenario name -> why its ``val*`` figures are not an EPA label (the ``[not_epa]`` table of
    :data:`NOT_EPA_FILE`, and its ``[carried_over]`` rows: another row's figures)."""
    tables = _not_epa_tables()
    out = {str(k): str(v) for k, v in tables[1].get("not_epa", {}).items()}
    for name, (src, file) in carried_over(tables).items():
        out[name] = (
            f"its val_* figures are the {src} row's, carried over when its file was made from that row's "
            f"(vehdb/{file}: every sourced value carries a comment, its val_* lines none)"
        )
    return out


def model_year(v: dict[str, Any]) -> int:
    """The vehicle's model year: ``veh_year``, else a year opening its name, else
    :data:`DEFAULT_MODEL_YEAR`."""
    y = v.get("veh_year")
    if isinstance(y, float) and y > 1900:
        return int(y)
    m = re.match(r"\s*((?:19|20)\d\d)\b", str(v.get("scenario_name") or ""))
    return int(m.group(1)) if m else DEFAULT_MODEL_YEAR


def rows(path: Path | None = None) -> list[tuple[Row, dict[str, Any]]]:
    """Every vehicle of the database as a :class:`Row` (with ``skipped`` set when left out) and its keys."""
    from hevsim.vehicle_import import list_vehicles, read_vehicle

    p = path or database_path()
    bad = not_epa()
    out = []
    for i, name, pt in list_vehicles(p):
        v = read_vehicle(p, row=i)
        fcev = str(v.get("fc_eff_type", "")).strip() == "H2FC"
        kind = "FCEV" if fcev else pt
        unit = {"BEV": "kWh/mi", "FCEV": "MPGe", "PHEV": "CS mpg"}.get(kind, "mpg")
        epa = v.get("val_comb_kwh_per_mile") if pt == "BEV" else v.get("val_comb_mpgge")
        epa = float(epa) if isinstance(epa, float) and epa > 0 else None
        r = Row(i, name.strip(), kind, model_year(v), unit, epa)
        if kind == "PHEV":
            for key, col in (("cd_kwh_per_mi", "val_comb_kwh_per_mile"), ("cd_range_mi", "val_cd_range_mi")):
                x = v.get(col)
                r.extra[key] = [float(x) if isinstance(x, float) and x > 0 else math.nan, math.nan, math.nan]
        if epa is None:
            r.skipped = "no EPA figure in val_comb_*"
        elif name.strip() in bad:
            r.skipped = f"not an EPA label: {bad[name.strip()]}"
        out.append((r, v))
    return out


def _label_gallon_factor(v: dict[str, Any]) -> float:
    """FASTSim's gallons (33.7 kWh, :data:`FASTSIM_KWH_PER_GGE`) per unit of the vehicle's fuel as
    its EPA label counts it [-]: a gallon of diesel (its LHV x density x gallon), a kilogram of
    hydrogen (the EPA labels a fuel-cell car's miles per kg as its MPGe: 120 MJ/kg = 33.33 kWh, so
    0.989 of FASTSim's gallon), else 1 (gasoline, and the BEVs' kWh)."""
    kind = str(v.get("fc_eff_type", "")).strip()
    if kind not in ("Diesel", "HD_Diesel", "H2FC"):
        return 1.0
    from hevsim.fuels import get_fuel
    from hevsim.units import M3_PER_US_GALLON

    if kind == "H2FC":
        return FASTSIM_KWH_PER_GGE * 3.6e6 / get_fuel("hydrogen").lower_heating_value_j_per_kg
    d = get_fuel("diesel")
    return (
        FASTSIM_KWH_PER_GGE
        * 3.6e6
        / (d.lower_heating_value_j_per_kg * d.density_kg_per_m3 * M3_PER_US_GALLON)
    )


def combined_label(city: float, highway: float, year: int, bev: bool, charger_efficiency: float) -> float:
    """The adjusted combined figure of unadjusted city / highway figures (mpg, or battery
    kWh/mi for a BEV, then returned from the wall) with hevsim's label equations."""
    from hevsim.sim import label as L

    k = L.constants()
    c = k.for_model_year(year)
    if bev:
        adj = [
            k.kwh_per_gallon_equivalent
            / L.adjusted_electric_mpge(k.kwh_per_gallon_equivalent / x, t, c, k.electric_adjustment_factor)
            for x, t in ((city, "city"), (highway, "highway"))
        ]  # fmt: skip
        return (k.city_weight * adj[0] + (1 - k.city_weight) * adj[1]) / charger_efficiency
    return L.combined(L.adjusted_city(city, c), L.adjusted_highway(highway, c), k.city_weight)


def hevsim_unadjusted(row: Row, v: dict[str, Any], path: Path, work: Path) -> tuple[float, float]:
    """hevsim's unadjusted (city, highway) of database row ``row`` (its keys ``v``, read from
    ``path``): mpg in the label's gallons, or battery kWh/mi for a BEV."""
    from hevsim.sim.label import label
    from hevsim.vehicle_import import import_vehicle

    toml = import_vehicle(path, work / f"row{row.row}.toml", row=row.row, force=True)
    lab = label(toml, model_year=row.model_year)
    f = lab.figures
    if row.powertrain == "BEV":
        return f["unadjusted_kwh_per_100mi"]["city"] / 100, f["unadjusted_kwh_per_100mi"]["highway"] / 100
    if row.powertrain == "PHEV":  # CD battery (DC) kWh/mi over the actual range, and that range
        eff = f["charger_efficiency"]
        cd = f["charge_depleting_kwh_per_100mi"]["unadjusted"]
        rng = f["charge_depleting_range_mi"]["actual_unadjusted"]
        row.extra_unadjusted["hevsim"] = (
            (cd["city"] * eff / 100, cd["highway"] * eff / 100),
            (rng["city"], rng["highway"]),
        )
    k = 1.0 / _label_gallon_factor(v)
    return f["unadjusted_mpg"]["city"] * k, f["unadjusted_mpg"]["highway"] * k


def fastsim_yaml(v: dict[str, Any], out: Path) -> Path:
    """A fastsim-2 YAML of database vehicle ``v`` for FASTSim 3 (the keys of ``v`` on the layout of
    FASTSim's bundled 2016 Prius file; lists as fastsim-2 arrays)."""
    import yaml

    tpl_path = Path(
        str(resources.files("hevsim") / "data" / "vehicles" / "fastsim" / "vehdb" / FASTSIM_TEMPLATE)
    )
    if tpl_path.is_file():
        template = yaml.safe_load(tpl_path.read_text(encoding="utf-8"))
    else:
        import fastsim

        template = yaml.safe_load(
            Path(fastsim.__file__).parent.joinpath("resources", "vehdb", FASTSIM_TEMPLATE).read_text()
        )
    for k, val in v.items():
        if k not in template:
            continue
        if isinstance(val, list):
            template[k] = {"v": 1, "dim": [len(val)], "data": val}
        elif val is None:
            template[k] = None if k.endswith("override") or k == "veh_override_kg" else template[k]
        elif k == "veh_year":
            template[k] = int(val)
        else:
            template[k] = val
    if not isinstance(
        v.get("fc_eff_map"), list
    ):  # fastsim-2's default curve of fc_eff_type (FASTSim 3 has none)
        from hevsim.vehicle_import import FC_EFF_MAPS

        curve = list(FC_EFF_MAPS.get(str(v.get("fc_eff_type", "")).strip(), FC_EFF_MAPS["SI"]))
        template["fc_eff_map"] = {"v": 1, "dim": [len(curve)], "data": curve}
    if not isinstance(v.get("mc_eff_map"), list):
        template["mc_eff_map"] = {"v": 1, "dim": [11], "data": [0.0] * 11}
    if v.get("fc_pwr_out_perc") is None:
        from hevsim.vehicle_import import FC_PWR_OUT_PERC

        template["fc_pwr_out_perc"] = {"v": 1, "dim": [12], "data": list(FC_PWR_OUT_PERC)}
    out.write_text(yaml.safe_dump(template), encoding="utf-8")
    return out


def fastsim_unadjusted(row: Row, v: dict[str, Any], work: Path) -> tuple[float, float]:
    """FASTSim 3's unadjusted (city, highway) from its ``get_label_fe`` (``lab_*``), in the units of
    :func:`hevsim_unadjusted`. Raises ImportError without fastsim."""
    import fastsim as fs

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        veh = fs.Vehicle.from_f2_file(str(fastsim_yaml(v, work / f"row{row.row}_f2.yaml")))
        out = json.loads(fs.get_label_fe(veh).to_json())
    if row.powertrain == "BEV":
        return float(out["lab_udds_kwh_per_mi"]), float(out["lab_hwy_kwh_per_mi"])
    if row.powertrain == "PHEV":  # get_label_fe's lab_* are UF-weighted: its CS and CD figures instead
        u, h = out["phev_calcs"]["udds"], out["phev_calcs"]["hwy"]
        row.extra_unadjusted["fastsim"] = (
            (float(u["cd_ess_kwh_per_mi"]), float(h["cd_ess_kwh_per_mi"])),
            (float(u["total_cd_miles"]), float(h["total_cd_miles"])),
        )
        row.fastsim_own = {
            "cs_mpg": float(out["adj_cs_comb_mpgge"]),
            "cd_kwh_per_mi": float(out["adj_comb_kwh_per_mi"]),
            "cd_range_mi": float(out["net_phev_cd_miles"]),
        }
        return float(u["cs_mpg"]), float(h["cs_mpg"])
    k = 1.0 / _label_gallon_factor(v)
    return float(out["lab_udds_mpgge"]) * k, float(out["lab_hwy_mpgge"]) * k


def _plugin_extra(r: Row, which: str, charger_efficiency: float) -> None:
    """A PHEV's adjusted CD kWh/mi (from the wall) and CD range of model ``which`` into
    :attr:`Row.extra`, by the same equations for both models: the BEV label equations on the
    unadjusted CD battery kWh/mi, and 0.7 x the 55/45 combination of the unadjusted ranges."""
    if which not in r.extra_unadjusted:
        return
    from hevsim.sim.label import constants

    w = constants().city_weight
    (kc, kh), (rc, rh) = r.extra_unadjusted[which]
    i = 1 if which == "hevsim" else 2
    r.extra["cd_kwh_per_mi"][i] = combined_label(kc, kh, r.model_year, True, charger_efficiency)
    r.extra["cd_range_mi"][i] = EV_RANGE_FACTOR * (w * rc + (1 - w) * rh)


def validate(only: list[int] | None = None, with_fastsim: bool = True, path: Path | None = None) -> list[Row]:
    """Label every vehicle with EPA figures (``only``: these database rows) by hevsim and, if
    installed and ``with_fastsim``, by FASTSim 3; return the rows (skipped ones included)."""
    out = []
    p = path or database_path()
    with tempfile.TemporaryDirectory(prefix="hevsim-epa-") as tmp:
        work = Path(tmp)
        for r, v in rows(p):
            if only is not None and r.row not in only:
                continue
            out.append(r)
            if r.skipped:
                continue
            bev = r.powertrain == "BEV"
            chg = float(v.get("chg_eff") or 1.0) if r.powertrain in ("BEV", "PHEV") else 1.0
            t0 = time.perf_counter()
            try:
                r.hevsim_unadjusted = hevsim_unadjusted(r, v, p, work)
                r.hevsim = combined_label(*r.hevsim_unadjusted, r.model_year, bev, chg)
                _plugin_extra(r, "hevsim", chg)
            except ConfigError as exc:
                r.notes.append(f"hevsim: {str(exc).splitlines()[0][:120]}")
            r.hevsim_s = time.perf_counter() - t0
            if with_fastsim:
                t0 = time.perf_counter()
                try:
                    r.fastsim_unadjusted = fastsim_unadjusted(r, v, work)
                    r.fastsim = combined_label(*r.fastsim_unadjusted, r.model_year, bev, chg)
                    _plugin_extra(r, "fastsim", chg)
                except ImportError:
                    with_fastsim = False
                except Exception as exc:  # FASTSim refuses some vehicles: say so in the table
                    r.notes.append(f"FASTSim: {str(exc).splitlines()[0][:120]}")
                r.fastsim_s = time.perf_counter() - t0
    return out


def summary(rows_: list[Row]) -> dict[str, dict[str, float]]:
    """Per powertrain class and "all": count, median and 90th percentile of |error| [%], hevsim
    and FASTSim, on each row's main figure; then "PHEV <figure>" for each further PHEV figure
    (:attr:`Row.extra`)."""
    done = [r for r in rows_ if not r.skipped]
    out: dict[str, dict[str, float]] = {}
    extras = sorted({k for r in done for k in r.extra})
    for cls in [*sorted({r.powertrain for r in done}), "all", *(f"PHEV {k}" for k in extras)]:
        key = cls.split()[1] if cls.startswith("PHEV ") else ""
        sel = [r for r in done if cls in ("all", r.powertrain) or (key and key in r.extra)]
        d: dict[str, float] = {"n": float(len(sel))}
        for which in ("hevsim", "fastsim"):
            e = np.abs([r.extra_error(key, which) if key else r.error(which) for r in sel])
            e = e[np.isfinite(e)]
            d[f"{which}_n"] = float(e.size)
            d[f"{which}_median_pct"] = 100 * float(np.median(e)) if e.size else math.nan
            d[f"{which}_p90_pct"] = 100 * float(np.percentile(e, 90)) if e.size else math.nan
        out[cls] = d
    return out
