"""Import FASTSim vehicles (``hevsim import-vehicle``): fastsim-2 single-vehicle YAML and CSV
files and the fastsim-2 vehicle database CSV become a commented hevsim vehicle TOML with its
engine and motor maps (CSV folders) beside it.

The equations taken from FASTSim (NREL, Apache-2.0; read in ``rust/fastsim-core/src/
vehicle.rs`` ``set_veh_mass`` / ``set_derived``, ``simdrive/simdrive_impl.rs`` and
``python/fastsim/parameters.py`` of github.com/NREL/fastsim at bd9111bb) are re-stated here,
with the constants they use; the mapping of every key is :func:`key_treatment` (also in
docs/import_vehicle.md). Nothing of FASTSim's code is copied.

Architectures (:func:`hevsim_architecture`): ``Conv`` -> conventional, ``HEV`` -> parallel (P2:
FASTSim's engine and motor add their power at the transmission input), ``BEV`` -> bev, ``PHEV`` ->
a parallel HEV with a ``[plugin]`` section (blended: the engine starts above ``kw_demand_fc_on``
while depleting), a fuel-cell vehicle (``fc_eff_type = "H2FC"``, any ``veh_pt_type``) -> fcev.
"""

from __future__ import annotations

import ast
import csv
import functools
import math
import tempfile
import tomllib
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from hevsim.errors import ConfigError
from hevsim.units import STANDARD_GRAVITY

# ----------------------------------------------------------------------------- FASTSim constants
FASTSIM_GRAVITY_MPS2 = 9.81
"""FASTSim's gravitational acceleration [m/s^2] (``RustPhysicalProperties::a_grav_mps2``)."""
FASTSIM_AIR_DENSITY_KGPM3 = 1.2
"""FASTSim's air density [kg/m^3] (``air_density_kg_per_m3``)."""
FASTSIM_KWH_PER_GGE = 33.7
"""FASTSim's energy of one gallon of gasoline equivalent [kWh] (``kwh_per_gge``)."""
FC_PWR_OUT_PERC = (0.0, 0.005, 0.015, 0.04, 0.06, 0.10, 0.14, 0.20, 0.40, 0.60, 0.80, 1.00)
"""FASTSim's default engine power fractions [-] (``parameters.fc_pwr_out_perc``)."""
FC_EFF_MAPS = {
    "SI": (0.10, 0.12, 0.16, 0.22, 0.28, 0.33, 0.35, 0.36, 0.35, 0.34, 0.32, 0.30),
    "Atkinson": (0.10, 0.12, 0.28, 0.35, 0.375, 0.39, 0.40, 0.40, 0.38, 0.37, 0.36, 0.35),
    "Diesel": (0.10, 0.14, 0.20, 0.26, 0.32, 0.39, 0.41, 0.42, 0.41, 0.38, 0.36, 0.34),
    "HD_Diesel": (0.10, 0.14, 0.20, 0.26, 0.32, 0.39, 0.41, 0.42, 0.41, 0.38, 0.36, 0.34),
}
"""FASTSim's default engine efficiency curves by ``fc_eff_type`` [-] (``parameters.fc_eff_map_*``)."""
MC_PWR_OUT_PERC = (0.00, 0.02, 0.04, 0.06, 0.08, 0.10, 0.20, 0.40, 0.60, 0.80, 1.00)
"""FASTSim's default motor power fractions [-] (``parameters.mc_pwr_out_perc``)."""
LARGE_BASELINE_EFF = (0.83, 0.85, 0.87, 0.89, 0.90, 0.91, 0.93, 0.94, 0.94, 0.93, 0.92)
SMALL_BASELINE_EFF = (0.12, 0.16, 0.21, 0.29, 0.35, 0.42, 0.75, 0.92, 0.93, 0.93, 0.92)
"""FASTSim's baseline motor efficiency curves [-] (``params::LARGE/SMALL_BASELINE_EFF``)."""
SMALL_MOTOR_POWER_KW, LARGE_MOTOR_POWER_KW, MODERN_MAX = 7.5, 75.0, 0.95
"""FASTSim's motor sizes of the baseline curves [kW] and modern peak efficiency [-] (``params.rs``)."""
FUELS = {"SI": "gasoline", "Atkinson": "gasoline", "Diesel": "diesel", "HD_Diesel": "diesel"}
"""hevsim fuel (``hevsim/data/fuels.toml``) of each FASTSim ``fc_eff_type``."""
ARCHITECTURE_OF = {"Conv": "conventional", "HEV": "parallel", "BEV": "bev"}
"""hevsim architecture of each FASTSim ``veh_pt_type`` that can be imported."""
NOT_YET: dict[str, str] = {}
"""FASTSim powertrain types refused for now (none: PHEV and fuel-cell vehicles import since issue 25)."""
PHEV_CS_FRACTION = 0.03
"""An imported PHEV's ``plugin.cs_soc``: this share into its SOC window above ``min_soc`` [-] (assumed;
FASTSim depletes to ``min_soc`` and counts the whole window in its CD range, so the share is kept
small, with room for the charge-sustaining band below it; it was 0.1, which left a tenth of the
window unused and the four database PHEVs' CD ranges 6-19 % short, docs/validation.md)."""
PHEV_SOC_LOW_FRACTION = 0.015
"""An imported PHEV's charge-sustaining ``controller.soc_low``: this share into the window [-] (assumed;
half of :data:`PHEV_CS_FRACTION`)."""
FCEV_CHARGE_POWER_FRACTION = 0.1
"""An imported FCEV's ``controller.charge_power_w`` as a share of its fuel cell's rating [-] (assumed)."""


def is_fuel_cell(v: dict[str, Any]) -> bool:
    """Whether the fastsim-2 vehicle ``v`` is a fuel-cell vehicle (``fc_eff_type = "H2FC"``)."""
    return str(v.get("fc_eff_type", "")).strip() == "H2FC" or str(v.get("veh_pt_type", "")).strip() == "FCEV"


def hevsim_architecture(v: dict[str, Any], source: str = "FASTSim vehicle") -> str:
    """The hevsim architecture a fastsim-2 vehicle ``v`` imports as (``fcev`` for a fuel cell,
    ``parallel`` with ``[plugin]`` for a PHEV, else :data:`ARCHITECTURE_OF`); ConfigError naming
    ``veh_pt_type`` for an unknown type."""
    pt = str(v.get("veh_pt_type", "")).strip()
    if is_fuel_cell(v):
        return "fcev"
    if pt == "PHEV":
        return "parallel"
    if pt not in ARCHITECTURE_OF:
        raise ConfigError(
            f"{source}: key 'veh_pt_type' = {pt!r} is not a FASTSim powertrain type hevsim knows; "
            f"expected one of {', '.join((*ARCHITECTURE_OF, 'PHEV'))} (or fc_eff_type 'H2FC' for a "
            "fuel-cell vehicle)."
        )
    return ARCHITECTURE_OF[pt]


# ----------------------------------------------------------------------------- hevsim choices
ENGINE_IDLE_RPM = 700.0
"""Idle (lowest running) speed given to an imported engine [rpm] (assumed: FASTSim's engine has no speed)."""
ENGINE_REDLINE_RPM = 6000.0
"""Redline of an imported engine [rpm] (assumed)."""
ENGINE_KNEE_RPM = 1500.0
"""Speed from which an imported engine gives its full power [rpm] (assumed; below it the torque is
capped at full power / this speed, so FASTSim's speed-free engine becomes a constant-power curve)."""
GEAR_RATIOS = (4.0, 2.6, 1.8, 1.35, 1.05, 0.85)
"""Generic 6-speed gearbox of an imported engine vehicle [-] (assumed; FASTSim has no gears)."""
TOP_GEAR_ENGINE_RPM_AT_30_MPS = 2000.0
"""Engine speed in top gear at 30 m/s that sets the final drive [rpm] (assumed)."""
MOTOR_MAX_RPM_AT_45_MPS = 12000.0
"""Motor speed at 45 m/s (100 mph) that sets a BEV's reduction [rpm] (assumed)."""
MOTOR_BASE_FRACTION = 0.1
"""Base speed of an imported motor as a fraction of its map's top speed [-] (assumed; above it the
motor gives full power, FASTSim's motor having no speed)."""
BATTERY_OCV_V = 360.0
"""Open-circuit voltage given to an imported battery [V] (assumed; FASTSim's battery has energy only)."""
BATTERY_EFF_POWER_FRACTION = 0.5
"""Share of the motor's power at which the imported Rint battery has FASTSim's one-way efficiency [-]."""
MAP_SPEED_POINTS, MAP_TORQUE_POINTS = 31, 61

# ----------------------------------------------------------------------------- key table
KEYS_FILE = "data/vehicles/fastsim_keys.toml"
"""Every fastsim-2 vehicle key -> treatment and how (and FASTSim's old camelCase names), as data."""
TREATMENTS = ("mapped", "approximated", "recomputed", "reference", "refused")


@functools.lru_cache(maxsize=1)
def _key_table() -> tuple[dict[str, tuple[str, str]], dict[str, str]]:
    path = Path(str(resources.files("hevsim") / KEYS_FILE))
    data = tomllib.loads(path.read_text(encoding="utf-8"))
    keys: dict[str, tuple[str, str]] = {}
    for k, entry in data["keys"].items():
        if entry.get("treatment") not in TREATMENTS:
            raise ConfigError(
                f"{path}: key 'keys.{k}.treatment' = {entry.get('treatment')!r}; expected one of "
                f"{TREATMENTS}."
            )
        keys[k] = (entry["treatment"], entry["how"])
    return keys, dict(data["old_names"])


def key_treatment() -> dict[str, tuple[str, str]]:
    """Every fastsim-2 vehicle key -> (treatment, how) (:data:`KEYS_FILE`)."""
    return dict(_key_table()[0])


VAL_KEYS = (
    "val_udds_mpgge", "val_hwy_mpgge", "val_comb_mpgge", "val_udds_kwh_per_mile",
    "val_hwy_kwh_per_mile", "val_comb_kwh_per_mile", "val_cd_range_mi", "val_const65_mph_kwh_per_mile",
    "val_const60_mph_kwh_per_mile", "val_const55_mph_kwh_per_mile", "val_const45_mph_kwh_per_mile",
    "val_unadj_udds_kwh_per_mile", "val_unadj_hwy_kwh_per_mile", "val0_to60_mph", "val_ess_life_miles",
    "val_range_miles", "val_veh_base_cost", "val_msrp",
)  # fmt: skip
"""FASTSim's reference-value keys (EPA label or published figures), listed as a comment."""

_DEFAULTS: dict[str, Any] = {
    "fc_pwr_out_perc": None, "mc_pwr_out_perc": None, "mc_eff_map": None, "veh_override_kg": None,
    "stop_start": False, "force_aux_on_fc": False, "small_motor_power_kw": SMALL_MOTOR_POWER_KW,
    "large_motor_power_kw": LARGE_MOTOR_POWER_KW, "modern_max": MODERN_MAX, "regen_a": 500.0, "regen_b": 0.99,
    "charging_on": False, "max_roadway_chg_kw": None, "fc_peak_eff_override": None,
    "mc_peak_eff_override": None, "selection": None, "fastsim3_mass_kg": None,
}  # fmt: skip
"""Optional keys and FASTSim's defaults for them (``regen_a``, ``regen_b``: ``default_regen_a/b``)."""
_REQUIRED = (
    "veh_pt_type", "drag_coef", "frontal_area_m2", "glider_kg", "cargo_kg", "comp_mass_multiplier",
    "fc_max_kw", "mc_max_kw", "ess_max_kw", "ess_max_kwh", "wheel_radius_m", "wheel_rr_coef", "trans_eff",
    "aux_kw",
)  # fmt: skip

_TEXT_KEYS = ("scenario_name", "veh_pt_type", "fc_eff_type")
"""The fastsim-2 keys whose values are text."""
_MASS_ONLY = ("glider_kg", "cargo_kg", "comp_mass_multiplier")
"""Required keys that only FASTSim's mass rule reads (not needed with ``veh_override_kg``)."""


# ============================================================================ reading
def _scalar(text: str) -> Any:
    s = text.strip()
    if s == "" or s.lower() in ("nan", ".nan", "none", "~"):
        return None
    if s.upper() in ("TRUE", "FALSE"):
        return s.upper() == "TRUE"
    if s.endswith("%"):  # FASTSim's CSVs write some fractions as percentages (vehicle.clean_data)
        try:
            return float(s[:-1]) / 100.0
        except ValueError:
            return s
    if s.startswith("["):
        try:
            return [float(x) for x in ast.literal_eval(s)]
        except (ValueError, SyntaxError, TypeError):
            return s
    try:
        return float(s)
    except ValueError:
        return s


def _normalise(raw: dict[str, Any], where: str) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in raw.items():
        k = str(key).strip().replace(" ", "_")
        k = _key_table()[1].get(k, k)
        k = "scenario_name" if k.lower() == "scenario_name" else k
        if isinstance(value, dict) and "data" in value:  # fastsim-2 YAML arrays: {v, dim, data}
            value = [float(x) for x in value["data"]]
        if isinstance(value, str):
            value = (
                _scalar(value) if k not in ("scenario_name", "veh_pt_type", "fc_eff_type") else value.strip()
            )
        if isinstance(value, float) and math.isnan(value):
            value = None
        if k not in _key_table()[0]:
            raise ConfigError(
                f"{where}: key {k!r} is not a fastsim-2 vehicle key hevsim knows; expected one of the keys "
                "of "
                "docs/import_vehicle.md (a fastsim-3 file or another format?)."
            )
        out[k] = value
    return out


def _read_csv_rows(path: Path) -> list[list[str]]:
    try:
        with path.open(newline="", encoding="utf-8-sig") as f:
            return [row for row in csv.reader(f)]
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{path}: cannot read it as a CSV file ({exc}).") from exc


def list_vehicles(path: str | Path) -> list[tuple[int, str, str]]:
    """(row, name, FASTSim powertrain type) of every vehicle in ``path``."""
    return [
        (i, str(v.get("scenario_name", "")), str(v.get("veh_pt_type", ""))) for i, v in _vehicles(Path(path))
    ]


def _vehicles(path: Path) -> list[tuple[int, dict[str, Any]]]:
    if not path.is_file():
        raise ConfigError(f"{path}: no such file; expected a FASTSim vehicle file (.yaml or .csv).")
    suffix = path.suffix.lower()
    if suffix in (".yaml", ".yml"):
        import yaml

        try:
            data = yaml.safe_load(path.read_text(encoding="utf-8"))
        except (yaml.YAMLError, UnicodeDecodeError) as exc:
            raise ConfigError(f"{path}: not a readable YAML file ({exc}).") from exc
        if isinstance(data, dict) and "pt_type" in data and "chassis" in data:
            return [(0, _normalise(from_fastsim3(data, str(path)), str(path)))]
        if not isinstance(data, dict) or "veh_pt_type" not in data:
            found = sorted(data)[:5] if isinstance(data, dict) else type(data).__name__
            raise ConfigError(
                f"{path}: not a FASTSim vehicle: key 'veh_pt_type' is missing (found {found}); expected a "
                "fastsim-2 vehicle YAML."
            )
        return [(int(data.get("selection") or 0), _normalise(data, str(path)))]
    if suffix == ".csv":
        rows = _read_csv_rows(path)
        if (
            len(rows) > 1 and len(rows[0]) >= 3 and rows[0][1].strip() == "Param Name"
        ):  # one vehicle, vertical
            raw = {r[1]: r[2] for r in rows[1:] if len(r) >= 3 and r[1].strip()}
            return [(0, _normalise(raw, str(path)))]
        header = [h.strip() for h in rows[0]] if rows else []
        if "selection" in header and ("Scenario name" in header or "scenario_name" in header):
            out = []
            for n, r in enumerate(rows[1:], start=2):
                if not any(c.strip() for c in r):
                    continue
                raw = dict(zip(header, r, strict=False))
                v = _normalise(raw, f"{path}, line {n}")
                out.append((int(v["selection"]) if v.get("selection") is not None else n - 1, v))
            return out
        raise ConfigError(
            f"{path}: not a FASTSim vehicle CSV: expected a single-vehicle file (columns ',Param Name,Param "
            "Value') or the vehicle database (columns 'selection', 'Scenario name', ...)."
        )
    raise ConfigError(
        f"{path}: suffix {path.suffix!r} is not a FASTSim vehicle file; expected .yaml or .csv."
    )


def read_vehicle(path: str | Path, row: int | None = None, name: str | None = None) -> dict[str, Any]:
    """The fastsim-2 vehicle of ``path`` (for a database: ``row``, its ``selection`` number, or
    ``name``, its scenario name), with FASTSim's defaults for the optional keys."""
    p = Path(path)
    vehicles = _vehicles(p)
    if row is not None:
        chosen = [v for i, v in vehicles if i == row]
        if not chosen:
            rows = [i for i, _ in vehicles]
            raise ConfigError(
                f"{p}: --row {row} is out of range; expected one of the rows {min(rows)}..{max(rows)} "
                "(hevsim import-vehicle --list FILE lists them)."
            )
        veh = chosen[0]
    elif name is not None:
        chosen = [v for _, v in vehicles if str(v.get("scenario_name", "")).strip() == name.strip()]
        if not chosen:
            raise ConfigError(
                f"{p}: --name {name!r} names no vehicle of the file (hevsim import-vehicle --list FILE)."
            )
        veh = chosen[0]
    elif len(vehicles) == 1:
        veh = vehicles[0][1]
    else:
        raise ConfigError(
            f"{p}: {len(vehicles)} vehicles; choose one with --row N or --name NAME (see --list)."
        )
    full = {**_DEFAULTS, **{k: v for k, v in veh.items() if v is not None or k not in _DEFAULTS}}
    needed = (
        _REQUIRED
        if full.get("veh_override_kg") is None and full.get("fastsim3_mass_kg") is None
        else tuple(k for k in _REQUIRED if k not in _MASS_ONLY)
    )
    for k, val in full.items():
        if isinstance(val, str) and k not in _TEXT_KEYS:
            raise ConfigError(f"{p}: key {k!r} = {val!r}; expected a number (or a list of numbers).")
    missing = [k for k in needed if full.get(k) is None]
    if missing:
        raise ConfigError(
            f"{p}: key(s) {', '.join(repr(k) for k in missing)} missing or empty; expected numbers."
        )
    return full


# ============================================================================ fastsim 3
FASTSIM3_TYPES = {"Conv": "Conv", "HEV": "HEV", "BEV": "BEV", "PHEV": "PHEV"}
"""fastsim-3 ``pt_type`` variants -> fastsim-2 ``veh_pt_type``."""


def _f3(d: dict[str, Any], key: str, where: str, default: Any = ...) -> Any:
    if key in d and d[key] is not None:
        return d[key]
    if default is ...:
        raise ConfigError(f"{where}: key {key!r} is missing or empty; expected a value (fastsim-3 vehicle).")
    return default


def _f3_curve(interp: Any, where: str) -> tuple[list[float], list[float]]:
    """(power fractions, efficiencies) of a fastsim-3 1-D interpolator (``data.grid``, ``data.values``)."""
    try:
        grid = interp["data"]["grid"][0]
        values = interp["data"]["values"]
        return [float(x) for x in grid], [float(x) for x in values]
    except (KeyError, TypeError, IndexError) as exc:
        raise ConfigError(
            f"{where}: expected a 1-D interpolator with data.grid and data.values ({exc})."
        ) from exc


def _f3_scalar(x: Any, where: str) -> float:
    if isinstance(x, dict) and "Constant" in x:
        return float(x["Constant"])
    if isinstance(x, int | float):
        return float(x)
    raise ConfigError(f"{where} = {x!r}; expected a constant efficiency (a number or {{Constant: value}}).")


def from_fastsim3(data: dict[str, Any], where: str) -> dict[str, Any]:
    """The fastsim-2 keys of a fastsim-3 vehicle mapping (``Vehicle.to_yaml`` layout): chassis,
    powertrain components (``fc``, ``em``, ``res``, ``transmission``), controls and the
    vehicle mass fastsim 3 computed (``mass_kilograms``, taken as ``veh_override_kg``).
    Thermal, cabin and HVAC models are refused (not modelled by the import)."""
    pt = data["pt_type"]
    if not isinstance(pt, dict) or len(pt) != 1:
        raise ConfigError(f"{where}: key 'pt_type' = {pt!r}; expected one powertrain (Conv, HEV, BEV).")
    kind, parts = next(iter(pt.items()))
    if kind not in FASTSIM3_TYPES:
        raise ConfigError(
            f"{where}: key 'pt_type' = {kind!r} is not a fastsim-3 powertrain type hevsim knows; "
            "expected one "
            f"of {', '.join(FASTSIM3_TYPES)}."
        )
    for key in ("cabin", "hvac"):
        if data.get(key) not in (None, "None"):
            raise ConfigError(
                f"{where}: key {key!r} is set: cabin and HVAC models are not imported; remove it."
            )
    ch = data["chassis"]
    drive = str(ch.get("drive_type") or "FWD")
    cg = float(_f3(ch, "cg_height_meters", f"{where}: chassis"))
    v: dict[str, Any] = {
        "scenario_name": str(data.get("name") or ""),
        "veh_year": float(data["year"]) if str(data.get("year") or "").isdigit() else None,
        "veh_pt_type": FASTSIM3_TYPES[kind],
        "drag_coef": _f3(ch, "drag_coef", f"{where}: chassis"),
        "frontal_area_m2": _f3(ch, "frontal_area_square_meters", f"{where}: chassis"),
        "wheel_rr_coef": _f3(ch, "wheel_rr_coef", f"{where}: chassis"),
        "wheel_inertia_kg_m2": _f3(ch, "wheel_inertia_kilogram_square_meters", f"{where}: chassis", 0.0),
        "num_wheels": float(_f3(ch, "num_wheels", f"{where}: chassis", 4)),
        "wheel_radius_m": _f3(ch, "wheel_radius_meters", f"{where}: chassis"),
        "veh_cg_m": -cg if drive == "RWD" else cg,
        "wheel_coef_of_fric": _f3(ch, "wheel_fric_coef", f"{where}: chassis", 0.9),
        "drive_axle_weight_frac": _f3(ch, "drive_axle_weight_frac", f"{where}: chassis", 0.6),
        "wheel_base_m": _f3(ch, "wheel_base_meters", f"{where}: chassis", 2.6),
        "glider_kg": ch.get("glider_mass_kilograms"),
        "cargo_kg": ch.get("cargo_mass_kilograms"),
        "comp_mass_multiplier": 1.0,
        "fastsim3_mass_kg": float(_f3(data, "mass_kilograms", where)),
        "aux_kw": float(data.get("pwr_aux_base_watts") or 0.0) / 1e3,
        "fc_max_kw": 0.0, "mc_max_kw": 0.0, "ess_max_kw": 0.0, "ess_max_kwh": 0.0, "fs_max_kw": 0.0,
        "trans_eff": _f3_scalar(_f3(parts.get("transmission", {}), "eff_interp", f"{where}: transmission"),
                                f"{where}: key 'transmission.eff_interp'"),
        "alt_eff": float(parts.get("alt_eff") or 1.0),
        "max_regen": 1.0,
    }  # fmt: skip
    fc = parts.get("fc")
    if fc:
        if fc.get("thrml") not in (None, "None"):
            raise ConfigError(
                f"{where}: key 'fc.thrml' is set: engine thermal models are not imported; remove it."
            )
        v["fc_max_kw"] = float(_f3(fc, "pwr_out_max_watts", f"{where}: fc")) / 1e3
        v["fc_pwr_out_perc"], v["fc_eff_map"] = _f3_curve(fc.get("eff_interp_from_pwr_out"), f"{where}: fc")
        v["idle_fc_kw"] = float(fc.get("pwr_idle_fuel_watts") or 0.0) / 1e3
        fuel = str((parts.get("fs") or {}).get("fuel_type") or "")
        v["fc_eff_type"] = "Diesel" if "diesel" in fuel.lower() else "SI"
        v["fs_max_kw"] = float((parts.get("fs") or {}).get("pwr_out_max_watts") or 0.0) / 1e3
    em = parts.get("em")
    if em:
        v["mc_max_kw"] = float(_f3(em, "pwr_out_max_watts", f"{where}: em")) / 1e3
        v["mc_pwr_out_perc"], v["mc_eff_map"] = _f3_curve(em.get("eff_interp_achieved"), f"{where}: em")
    res = parts.get("res")
    if res:
        if res.get("thrml") not in (None, "None"):
            raise ConfigError(
                f"{where}: key 'res.thrml' is set: battery thermal models are not imported; remove it."
            )
        v["ess_max_kw"] = float(_f3(res, "pwr_out_max_watts", f"{where}: res")) / 1e3
        v["ess_max_kwh"] = float(_f3(res, "energy_capacity_joules", f"{where}: res")) / 3.6e6
        v["ess_round_trip_eff"] = (
            _f3_scalar(_f3(res, "eff_interp", f"{where}: res"), f"{where}: key 'res.eff_interp'") ** 2
        )
        v["min_soc"], v["max_soc"] = float(res.get("min_soc") or 0.0), float(res.get("max_soc") or 1.0)
    ctl = parts.get("pt_cntrl")
    if isinstance(ctl, dict) and "RGWDB" in ctl:
        r = ctl["RGWDB"]
        v["mph_fc_on"] = float(r.get("speed_fc_forced_on_meters_per_second") or 0.0) / 0.44704
        v["kw_demand_fc_on"] = float(r.get("frac_pwr_demand_fc_forced_on") or 0.0) * (
            v["fc_max_kw"] + v["mc_max_kw"]
        )
    v["stop_start"] = isinstance(ctl, str) and "stop" in ctl.lower()
    return v


# ============================================================================ FASTSim's rules
def fastsim_test_mass_kg(v: dict[str, Any], where: str = "FASTSim vehicle") -> float:
    """FASTSim-2's vehicle mass [kg] (``RustVehicle::set_veh_mass``): ``veh_override_kg`` when
    given, else cargo + glider + multiplier x (transmission + battery + motor + engine + fuel
    storage), each component's mass from its size."""
    if v.get("veh_override_kg") is not None:
        return float(v["veh_override_kg"])
    if v.get("fastsim3_mass_kg") is not None:
        return float(v["fastsim3_mass_kg"])
    mult = float(v["comp_mass_multiplier"])
    for size, per in (("fc_max_kw", "fc_kw_per_kg"), ("fs_max_kw", "fs_kwh_per_kg")):
        if v.get(size) and not v.get(per):
            raise ConfigError(
                f"{where}: key {per!r} = {v.get(per)!r}: FASTSim's component-mass rule divides by it "
                f"({size} = {v[size]:g}); "
                "expected a positive number, or the vehicle mass in 'veh_override_kg'."
            )
    ess = 0.0
    if v["ess_max_kwh"] and v["ess_max_kw"]:
        ess = (v["ess_max_kwh"] * v["ess_kg_per_kwh"] + v["ess_base_kg"]) * mult
    mc = (v["mc_pe_base_kg"] + v["mc_pe_kg_per_kw"] * v["mc_max_kw"]) * mult if v["mc_max_kw"] else 0.0
    fc = (v["fc_max_kw"] / v["fc_kw_per_kg"] + v["fc_base_kg"]) * mult if v["fc_max_kw"] else 0.0
    fs = (v["fs_kwh"] / v["fs_kwh_per_kg"]) * mult if v.get("fs_max_kw") else 0.0
    return float(v["cargo_kg"] + v["glider_kg"] + v["trans_kg"] * mult + ess + mc + fc + fs)


def engine_curve(v: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    """(power fraction [-], efficiency [-]) of FASTSim's engine (``fc_pwr_out_perc``, ``fc_eff_map``
    or the default curve of ``fc_eff_type``; scaled to ``fc_peak_eff_override``)."""
    x = np.asarray(v["fc_pwr_out_perc"] or FC_PWR_OUT_PERC, float)
    eff = v.get("fc_eff_map")
    eff = np.asarray(eff if isinstance(eff, list) else FC_EFF_MAPS[str(v["fc_eff_type"])], float)
    if x.size != eff.size:
        raise ConfigError(
            f"key 'fc_eff_map' has {eff.size} values and 'fc_pwr_out_perc' {x.size}; expected equal lengths."
        )
    if v.get("fc_peak_eff_override"):
        eff = eff * float(v["fc_peak_eff_override"]) / eff.max()
    return x, eff


def fc_peak_eff_power_w(v: dict[str, Any]) -> float:
    """FASTSim's engine power at its peak efficiency [W] (``fc_max_kw`` x the power fraction of
    the curve's maximum): FASTSim 3's ``pwr_for_peak_eff``, which a fired HEV engine gives at
    least (``frac_of_most_eff_pwr_to_run_fc`` = 1, its default)."""
    x, eff = engine_curve(v)
    return float(v["fc_max_kw"]) * 1e3 * float(x[int(np.argmax(eff))])


def motor_curve(v: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    """(power fraction [-], efficiency [-]) of FASTSim's motor: ``mc_eff_map`` or, when absent,
    the baseline curves blended by motor size (``set_derived``); scaled to ``mc_peak_eff_override``."""
    x = np.asarray(v["mc_pwr_out_perc"] or MC_PWR_OUT_PERC, float)
    eff = v.get("mc_eff_map")
    if not isinstance(eff, list) or not any(eff):
        large = np.asarray(LARGE_BASELINE_EFF) + (
            float(v["modern_max"] or MODERN_MAX) - max(LARGE_BASELINE_EFF)
        )
        share = min(
            max(
                (v["mc_max_kw"] - v["small_motor_power_kw"])
                / (v["large_motor_power_kw"] - v["small_motor_power_kw"]),
                0.0,
            ),
            1.0,
        )
        eff = share * large + (1.0 - share) * np.asarray(SMALL_BASELINE_EFF)
    eff = np.asarray(eff, float)
    if x.size != eff.size:
        raise ConfigError(
            f"key 'mc_eff_map' has {eff.size} values and 'mc_pwr_out_perc' {x.size}; expected equal lengths."
        )
    if v.get("mc_peak_eff_override"):
        eff = eff * float(v["mc_peak_eff_override"]) / eff.max()
    return x, eff


# ============================================================================ writing
def _fmt(x: float) -> str:
    return repr(float(x))


def _write_engine(folder: Path, v: dict[str, Any], fuel: str) -> None:
    p_max_w = float(v["fc_max_kw"]) * 1e3
    x, eff = engine_curve(v)
    w = np.linspace(ENGINE_IDLE_RPM, ENGINE_REDLINE_RPM, MAP_SPEED_POINTS) * math.pi / 30.0
    t_cap = p_max_w / (ENGINE_KNEE_RPM * math.pi / 30.0)
    t_max = np.minimum(t_cap, p_max_w / w)
    torque = np.linspace(0.0, t_cap, MAP_TORQUE_POINTS)
    from hevsim.fuels import get_fuel

    lhv = get_fuel(fuel).lower_heating_value_j_per_kg
    # FASTSim's fired engine burns at least idle_fc_kw; carried for the HEV only, whose engine runs
    # without load (aux on the battery, forced on while braking). A conventional engine always carries
    # the aux load, so FASTSim's floor hardly binds; here it moved the conventional cars up to 2 %
    # further from FASTSim (the map interpolates linearly from its zero-torque point): left out.
    hev = str(v.get("veh_pt_type", "")).strip() == "HEV"
    idle_w = max(float(v.get("idle_fc_kw") or 0.0), 0.0) * 1e3 if hev else 0.0
    lines = ["speed_rad_per_s,torque_N_m,fuel_rate_g_per_s"]
    for wi in w:
        for ti in torque:
            p = wi * ti
            frac = min(p / p_max_w, 1.0)
            e = float(np.interp(frac, x, eff))
            # HEV: FASTSim's fired engine burns max(P / eff(P), idle_fc_kw) (its pwr_idle_fuel floor)
            rate = max(0.0 if p <= 0.0 else p / e, idle_w) / lhv * 1e3
            lines.append(f"{_fmt(wi)},{_fmt(ti)},{_fmt(rate)}")
    (folder / "fuel_rate_map.csv").write_text("\n".join(lines) + "\n", encoding="utf-8")
    (folder / "max_torque.csv").write_text(
        "speed_rad_per_s,max_torque_N_m\n"
        + "".join(f"{_fmt(a)},{_fmt(b)}\n" for a, b in zip(w, t_max, strict=True)),
        encoding="utf-8",
    )
    (folder / "closed_throttle_torque.csv").write_text(
        "speed_rad_per_s,closed_throttle_torque_N_m\n" + "".join(f"{_fmt(a)},0.0\n" for a in w),
        encoding="utf-8",
    )
    curve = ", ".join(f"[{a:g}, {b:g}]" for a, b in zip(x, eff, strict=True))
    (folder / "meta.toml").write_text(
        f'name = "{folder.name}"\n'
        f'description = "FASTSim engine of {_esc(v.get("scenario_name"))}: {v["fc_max_kw"]:g} kW, '
        f'efficiency vs power fraction {_esc(v.get("fc_eff_type"))}"\n'
        f'fuel = "{fuel}"\n'
        'notes = "Written by hevsim import-vehicle: fuel rate = P / eff(P / P_max) / LHV (HEV: at least '
        f"idle_fc_kw = {idle_w / 1e3:g} kW) at every speed "
        "(FASTSim's engine has no speed dependence); max torque = min(P_max / knee speed, P_max / speed); "
        'no closed-throttle drag (FASTSim has none)."\n'
        f"fastsim_power_fraction_efficiency = [{curve}]\n"
        '[source]\nupstream = "NREL FASTSim vehicle file (Apache-2.0, Copyright 2020 '
        "Alliance for Sustainable "
        'Energy, LLC)"\n',
        encoding="utf-8",
    )


def _motor_speed_max_radps() -> float:
    return MOTOR_MAX_RPM_AT_45_MPS * math.pi / 30.0


def _write_motor(folder: Path, v: dict[str, Any]) -> None:
    p_max_w = float(v["mc_max_kw"]) * 1e3
    x, eff = motor_curve(v)
    w_top = _motor_speed_max_radps() * 1.2
    w = np.linspace(0.0, w_top, MAP_SPEED_POINTS)
    w_base = MOTOR_BASE_FRACTION * w_top
    t_cap = p_max_w / w_base
    t_lim = np.minimum(t_cap, p_max_w / np.maximum(w, 1e-9))
    torque = np.linspace(-t_cap, t_cap, 2 * MAP_TORQUE_POINTS - 1)
    lines = ["speed_rad_per_s,torque_N_m,efficiency"]
    for wi in w:
        for ti in torque:
            frac = min(abs(wi * ti) / p_max_w, 1.0)
            e = float(np.interp(frac, x, eff))
            e = max(
                e, float(eff[eff > 0].min())
            )  # FASTSim's 0 at zero power is a placeholder (no power flows)
            lines.append(f"{_fmt(wi)},{_fmt(ti)},{_fmt(e)}")
    (folder / "efficiency_map.csv").write_text("\n".join(lines) + "\n", encoding="utf-8")
    (folder / "torque_limits.csv").write_text(
        "speed_rad_per_s,max_motoring_torque_cont_N_m,max_generating_torque_cont_N_m,max_motoring_torque_peak_N_m,"
        "max_generating_torque_peak_N_m\n"
        + "".join(
            f"{_fmt(a)},{_fmt(b)},{_fmt(-b)},{_fmt(b)},{_fmt(-b)}\n" for a, b in zip(w, t_lim, strict=True)
        ),
        encoding="utf-8",
    )
    curve = ", ".join(f"[{a:g}, {b:g}]" for a, b in zip(x, eff, strict=True))
    (folder / "meta.toml").write_text(
        f'name = "{folder.name}"\n'
        f'description = "FASTSim motor of {_esc(v.get("scenario_name"))}: {v["mc_max_kw"]:g} kW"\n'
        'sign_convention = "torque > 0: motoring (efficiency = P_mech/P_elec); torque < 0: generating '
        '(efficiency = P_elec/P_mech)"\n'
        'notes = "Written by hevsim import-vehicle: efficiency = eff(|P| / P_max) at every speed, '
        "motoring and generating (FASTSim's curve over output power); torque limit = "
        'min(P_max / base speed, P_max / speed)."\n'
        f"fastsim_power_fraction_efficiency = [{curve}]\n"
        '[source]\nupstream = "NREL FASTSim vehicle file (Apache-2.0, Copyright 2020 '
        "Alliance for Sustainable "
        'Energy, LLC)"\n',
        encoding="utf-8",
    )


def _esc(s: Any) -> str:
    return str(s if s is not None else "").replace("\\", "\\\\").replace('"', '\\"')


def regen_half_speed_mps(v: dict[str, Any]) -> float:
    """Speed [m/s] at which FASTSim's regeneration limit max_regen / (1 + a exp(-b (mph + 1)))
    reaches half its top value: mph = ln(a) / b - 1 (0 when a <= 1)."""
    a, b = float(v["regen_a"]), float(v["regen_b"])
    mph = math.log(a) / b - 1.0 if a > 1.0 and b > 0.0 else 0.0
    return max(mph, 0.0) * 0.44704


def build_toml(v: dict[str, Any], source: str, stem: str) -> str:
    """The commented hevsim vehicle TOML of the fastsim-2 vehicle ``v`` (maps in ``<stem>_engine``,
    ``<stem>_motor`` beside it)."""
    pt = str(v["veh_pt_type"]).strip()
    arch = hevsim_architecture(v, source)
    plugin = pt == "PHEV" and arch == "parallel"
    if v.get("charging_on") or any(v.get("max_roadway_chg_kw") or []):
        raise ConfigError(
            f"{source}: keys 'charging_on' / 'max_roadway_chg_kw': roadway charging is not modelled; "
            "expected it off."
        )
    has_engine = arch not in ("bev", "fcev")
    fuel_type = str(v.get("fc_eff_type", "")).strip()
    if has_engine and fuel_type not in FUELS and not isinstance(v.get("fc_eff_map"), list):
        raise ConfigError(f"{source}: key 'fc_eff_type' = {fuel_type!r}; expected one of {', '.join(FUELS)}.")
    fuel = FUELS.get(fuel_type, "gasoline")
    mass = fastsim_test_mass_kg(v, source)
    r = float(v["wheel_radius_m"])
    inertia = float(v.get("wheel_inertia_kg_m2") or 0.0) * float(v.get("num_wheels") or 0.0)
    mass_factor = 1.0 + inertia / (mass * r * r)
    crr = float(v["wheel_rr_coef"]) * FASTSIM_GRAVITY_MPS2 / STANDARD_GRAVITY
    wb, drive_share = float(v.get("wheel_base_m") or 2.6), float(v.get("drive_axle_weight_frac") or 0.6)
    cg = float(v.get("veh_cg_m") or 0.5)
    rear_drive = cg < 0.0  # FASTSim: a negative veh_cg_m means rear-wheel drive
    front = 1.0 - drive_share if rear_drive else drive_share
    name = str(v.get("scenario_name") or stem)
    L: list[str] = []
    a = L.append
    a(f"# Imported from FASTSim by `hevsim import-vehicle`: {source}")
    a(
        "# (NREL FASTSim vehicle data, Apache License 2.0, Copyright 2020 Alliance for Sustainable Energy, "
        "LLC.)"
    )
    a("# Every FASTSim key is mapped, approximated or refused: docs/import_vehicle.md has the table; the")
    a("# approximations that matter for this vehicle are noted next to the keys below.")
    vals = [f"{k} = {v[k]:g}" for k in VAL_KEYS if isinstance(v.get(k), float)]
    if vals:
        a("# Reference values of the FASTSim file (EPA label or published): " + ", ".join(vals))
    a(f'name = "{_esc(stem)}"')
    year = f"{v['veh_year']:.0f}" if isinstance(v.get("veh_year"), float) else "year n/a"
    a(f'description = "{_esc(name)} ({_esc(pt)}, {year}) imported from FASTSim"')
    a("")
    a("[powertrain]")
    a(
        f'architecture = "{arch}"'
        + (
            "   # FASTSim HEV: engine and motor add power at the transmission input (P2)"
            if arch == "parallel"
            else ""
        )
    )
    a("")
    a("[body]")
    how = (
        "veh_override_kg"
        if v.get("veh_override_kg") is not None
        else "fastsim 3's vehicle mass_kilograms"
        if v.get("fastsim3_mass_kg") is not None
        else "FASTSim's component-mass rule (set_veh_mass)"
    )
    a(f"mass_kg = {_fmt(mass)}   # {how}")
    a(f"drag_coefficient = {_fmt(v['drag_coef'])}")
    a(f"frontal_area_m2 = {_fmt(v['frontal_area_m2'])}")
    a(
        f"rolling_resistance = {_fmt(crr)}   # wheel_rr_coef {v['wheel_rr_coef']:g} x FASTSim's g "
        f"{FASTSIM_GRAVITY_MPS2:g} / hevsim's {STANDARD_GRAVITY:g}"
    )
    a(f"mass_factor = {_fmt(mass_factor)}   # 1 + num_wheels x wheel_inertia_kg_m2 / (m r^2)")
    a(f"air_density_kgpm3 = {FASTSIM_AIR_DENSITY_KGPM3}   # FASTSim's")
    a(f"cg_height_m = {_fmt(abs(cg))}   # |veh_cg_m| (FASTSim: negative = rear-wheel drive)")
    a(
        f"front_axle_to_cg_m = {_fmt((1.0 - front) * wb)}   # drive_axle_weight_frac {drive_share:g} on "
        f"the driven axle, wheel_base_m {wb:g}"
    )
    a(f"rear_axle_to_cg_m = {_fmt(front * wb)}")
    a("")
    a("[tire]")
    a(f"radius_m = {_fmt(r)}")
    a(f"friction_coefficient = {_fmt(min(max(float(v.get('wheel_coef_of_fric') or 0.9), 0.05), 2.0))}")
    a(f'driven_axle = "{"rear" if rear_drive else "front"}"')
    a("")
    trans_eff = float(v["trans_eff"])
    if has_engine:
        fd = (TOP_GEAR_ENGINE_RPM_AT_30_MPS * math.pi / 30.0) * r / (30.0 * GEAR_RATIOS[-1])
        a("[final_drive]   # FASTSim has no gears: a generic 6-speed gearbox and final drive (assumed); the")
        a("                # imported engine's efficiency depends on its power only: gears change little")
        a(f"ratio = {_fmt(fd)}   # {TOP_GEAR_ENGINE_RPM_AT_30_MPS:g} rpm in top gear at 30 m/s")
        a("efficiency = 1.0")
        a("")
        a("[gearbox]")
        a(f"ratios = [{', '.join(_fmt(g) for g in GEAR_RATIOS)}]")
        a(f"efficiency = {_fmt(trans_eff)}   # trans_eff")
        a("")
        a("[engine]")
        a('model = "map"')
        a(f'data = "{stem}_engine"   # FASTSim\'s efficiency vs power fraction at every speed (meta.toml)')
        a(f"stall_speed_rpm = {ENGINE_IDLE_RPM}   # assumed idle (FASTSim's engine has no speed)")
        a(f"redline_rpm = {ENGINE_REDLINE_RPM}   # assumed")
        a("")
        a("[fuel]   # a gallon holds FASTSim's 33.7 kWh (kwh_per_gge): mpg compare with FASTSim's mpgge")
        from hevsim.fuels import get_fuel

        lhv = get_fuel(fuel).lower_heating_value_j_per_kg
        a(f'name = "{fuel}"')
        dens = FASTSIM_KWH_PER_GGE * 3.6e6 / (lhv * 3.785411784e-3)
        a(f"density_kg_per_m3 = {_fmt(dens)}")
        a(f"heating_value_btu_per_us_gal = {_fmt(FASTSIM_KWH_PER_GGE * 3.6e6 / 1055.05585262)}")
        a("")
    else:
        if arch == "fcev":
            _fuel_cell_toml(a, v, stem)
        red = _motor_speed_max_radps() * r / 45.0
        a("[final_drive]   # single reduction (assumed: FASTSim has no gears)")
        a(f"ratio = {_fmt(red)}   # {MOTOR_MAX_RPM_AT_45_MPS:g} rpm at 45 m/s")
        a(f"efficiency = {_fmt(trans_eff)}   # trans_eff")
        a("")
    electric = arch in ("parallel", "bev", "fcev")
    if electric:
        a("[motor]")
        a('model = "map"')
        a(f'data = "{stem}_motor"   # FASTSim\'s efficiency vs power fraction at every speed (meta.toml)')
        a("")
        if arch == "parallel":
            mc_ratio = _motor_speed_max_radps() / ((45.0 / r) * fd * GEAR_RATIOS[-1])
            a("[motor_coupling]   # P2: on the gearbox input, like FASTSim (mc + fc -> transmission)")
            a('position = "p2"')
            a(f"ratio = {_fmt(mc_ratio)}   # the motor map's top speed at 45 m/s in top gear (assumed)")
            a("efficiency = 1.0")
            a("")
        kwh, kw = float(v["ess_max_kwh"]), float(v["ess_max_kw"])
        rt = float(v.get("ess_round_trip_eff") or 1.0)
        eta = math.sqrt(rt)
        p_ref = BATTERY_EFF_POWER_FRACTION * float(v["mc_max_kw"]) * 1e3
        res = BATTERY_OCV_V**2 * eta * (1.0 - eta) / p_ref if p_ref > 0 else 0.0
        i_max = kw * 1e3 / BATTERY_OCV_V
        a("[battery]   # FASTSim's battery: energy, power and a round-trip efficiency; here a Rint pack")
        a('model = "rint"')
        a(f"ocv_v = {BATTERY_OCV_V}   # assumed")
        a(f"capacity_ah = {_fmt(kwh * 1e3 / BATTERY_OCV_V)}   # ess_max_kwh {kwh:g}")
        a(
            f"resistance_ohm = {_fmt(res)}   # one-way efficiency sqrt(ess_round_trip_eff {rt:g}) at "
            f"{p_ref / 1e3:g} kW (half the motor's power)"
        )
        a(f"max_discharge_current_a = {_fmt(i_max)}   # ess_max_kw {kw:g} / OCV")
        a(f"max_charge_current_a = {_fmt(i_max)}")
        a(f"soc_min = {_fmt(v.get('min_soc') or 0.0)}   # min_soc")
        a(f"soc_max = {_fmt(v.get('max_soc') or 1.0)}   # max_soc")
        a("")
    a("[simulation]")
    a('cycle = "udds"')
    a("dt_s = 1.0   # FASTSim's cycles are 1 s")
    if electric:
        lo, hi = float(v.get("min_soc") or 0.0), float(v.get("max_soc") or 1.0)
        a(f"soc_initial = {_fmt(hi if arch == 'bev' or plugin else 0.5 * (lo + hi))}")
    a("")
    a("[controller]")
    aux = float(v["aux_kw"]) * 1e3
    if arch == "conventional":
        a('kind = "shift_schedule"')
        a("upshift_rpm = 2000.0   # assumed")
        a("downshift_rpm = 1100.0   # assumed")
        a(f'stop_start = "{"on" if v.get("stop_start") else "off"}"   # stop_start')
        if aux > 0:
            a(f"aux_power_w = {_fmt(aux)}   # aux_kw (on the engine through the alternator)")
            a("")
            a("[alternator]")
            a(f"efficiency = {_fmt(v.get('alt_eff') or 1.0)}   # alt_eff")
    elif arch == "parallel":
        lo, hi = float(v.get("min_soc") or 0.0), float(v.get("max_soc") or 1.0)
        a('kind = "electric_assist"   # FASTSim HEV rules approximated (docs/import_vehicle.md)')
        a(f"ev_speed_mps = {_fmt(min(float(v.get('mph_fc_on') or 0.0) * 0.44704, 100.0))}   # mph_fc_on")
        a(f"ev_power_w = {_fmt(min(float(v.get('kw_demand_fc_on') or 0.0) * 1e3, 1e7))}   # kw_demand_fc_on")
        a("# FASTSim's speed-dependent SOC buffers (max_accel_buffer_mph, its regen buffer) approximated by")
        a("# a fixed band; min_fc_time_on and max_regen are not carried (docs/import_vehicle.md)")
        if plugin:
            cs = lo + PHEV_CS_FRACTION * (hi - lo)
            a(
                f"soc_low = {_fmt(lo + PHEV_SOC_LOW_FRACTION * (hi - lo))}"
                "   # charge sustaining below cs_soc (assumed)"
            )
            a(f"soc_high = {_fmt(cs)}   # = plugin.cs_soc")
        else:
            a(f"soc_low = {_fmt(lo + 0.25 * (hi - lo))}   # a quarter into the SOC window (assumed)")
            a(f"soc_high = {_fmt(lo + 0.5 * (hi - lo))}   # mid-window (assumed)")
        a(
            f"engine_on_speed_mps = {_fmt(min(float(v.get('mph_fc_on') or 0.0) * 0.44704, 1000.0))}   "
            "# mph_fc_on: FASTSim forces the engine on above it whatever the SOC (braking too)"
        )
        a(
            f"engine_min_power_w = {_fmt(fc_peak_eff_power_w(v))}   # a fired engine gives at least its "
            "peak-efficiency power"
        )
        a("# (FASTSim's pwr_for_peak_eff: fc_max_kw x fc_pwr_out_perc at the maximum of fc_eff_map), the")
        a("# surplus charging the battery below soc_high; idle_fc_kw is the engine map's fuel floor")
        if aux > 0:
            a(f"aux_power_w = {_fmt(aux)}   # aux_kw (on the bus)")
        if plugin:
            a("")
            a("[plugin]   # FASTSim PHEV: charge depleting, the engine on above kw_demand_fc_on (blended)")
            a('mode = "blended"')
            a(f"cs_soc = {_fmt(cs)}   # {PHEV_CS_FRACTION:g} into the SOC window above min_soc (assumed)")
            a(
                f"blended_engine_power_w = {_fmt(min(float(v.get('kw_demand_fc_on') or 0.0) * 1e3, 1e7))}"
                "   # kw_demand_fc_on (mph_fc_on is not used while depleting: approximated)"
            )
            a(
                f"charger_efficiency = {_fmt(min(max(float(v.get('chg_eff') or 0.86), 0.01), 1.0))}"
                "   # chg_eff"
            )
    elif arch == "fcev":
        lo, hi = float(v.get("min_soc") or 0.0), float(v.get("max_soc") or 1.0)
        a('kind = "load_follower"   # the fuel cell follows the bus load, SOC-corrected (FASTSim: HEV rules)')
        a(f"soc_low = {_fmt(lo + 0.25 * (hi - lo))}   # a quarter into the SOC window (assumed)")
        a(f"soc_high = {_fmt(lo + 0.75 * (hi - lo))}   # (assumed)")
        a(
            f"charge_power_w = {_fmt(FCEV_CHARGE_POWER_FRACTION * float(v['fc_max_kw']) * 1e3)}   "
            f"# {FCEV_CHARGE_POWER_FRACTION:g} x fc_max_kw (assumed)"
        )
        a(
            f"fuel_cell_on_speed_mps = {_fmt(min(float(v.get('mph_fc_on') or 0.0) * 0.44704, 1000.0))}   "
            "# mph_fc_on: FASTSim keeps the fuel converter on above it whatever the SOC (braking too)"
        )
        a(
            f"# min_fc_time_on ({float(v.get('min_fc_time_on') or 0.0):g} s) not carried, as for the HEV's "
            "engine: fuel_cell_min_on_time_s = 0 (docs/import_vehicle.md)"
        )
        if aux > 0:
            a(f"aux_power_w = {_fmt(aux)}   # aux_kw (on the bus)")
        a("")
        a("[brakes]")
        a(f"regen_fraction = {_fmt(min(max(float(v.get('max_regen') or 0.0), 0.0), 1.0))}   # max_regen")
        a(
            f"regen_min_speed_mps = {_fmt(regen_half_speed_mps(v))}   # where FASTSim's regen curve "
            "(regen_a, regen_b) reaches half"
        )
    else:
        a('kind = "direct"')
        if aux > 0:
            a(f"aux_power_w = {_fmt(aux)}   # aux_kw (on the bus)")
        a("")
        a("[brakes]")
        a(f"regen_fraction = {_fmt(min(max(float(v.get('max_regen') or 0.0), 0.0), 1.0))}   # max_regen")
        a(
            f"regen_min_speed_mps = {_fmt(regen_half_speed_mps(v))}   # where FASTSim's regen curve "
            "(regen_a, regen_b) reaches half"
        )
        a("")
        a("[metrics]")
        a("conversion_efficiency = 1.0")
    return "\n".join(L) + "\n"


def _fuel_cell_toml(a: Any, v: dict[str, Any], stem: str) -> None:
    """The ``[fuel_cell]`` and ``[fuel]`` sections of an imported fuel-cell vehicle."""
    from hevsim.fuels import get_fuel

    kw = float(v["fc_max_kw"])
    secs = float(v.get("fc_sec_to_peak_pwr") or 0.0)
    ramp = kw * 1e3 / secs if secs > 0 else 1e9
    a("[fuel_cell]   # FASTSim's fuel converter of type H2FC")
    a(f'data = "{stem}_fuel_cell"   # FASTSim\'s efficiency vs power fraction (fc_eff_map, meta.toml)')
    a(f"max_power_w = {_fmt(kw * 1e3)}   # fc_max_kw")
    a("min_power_w = 0.0   # FASTSim's fuel cell may stop")
    idle = max(float(v.get("idle_fc_kw") or 0.0), 0.0)
    a(f"idle_fuel_power_w = {_fmt(idle * 1e3)}   # idle_fc_kw: least H2 power of a running fuel cell")
    a(f"ramp_up_w_per_s = {_fmt(min(ramp, 1e9))}   # fc_max_kw / fc_sec_to_peak_pwr {secs:g} s")
    a(f"ramp_down_w_per_s = {_fmt(min(ramp, 1e9))}   # (assumed, as up)")
    a("initial_power_w = 0.0")
    a("")
    a("[fuel]   # hydrogen; a gallon holds FASTSim's 33.7 kWh (kwh_per_gge): mpg compares with its mpgge")
    lhv = get_fuel("hydrogen").lower_heating_value_j_per_kg
    a('name = "hydrogen"')
    a(f"density_kg_per_m3 = {_fmt(FASTSIM_KWH_PER_GGE * 3.6e6 / (lhv * 3.785411784e-3))}")
    a(f"heating_value_btu_per_us_gal = {_fmt(FASTSIM_KWH_PER_GGE * 3.6e6 / 1055.05585262)}")
    a("")


def _write_fuel_cell(folder: Path, v: dict[str, Any]) -> None:
    eff = v.get("fc_eff_map")
    if not isinstance(eff, list) or len(eff) != len(FC_PWR_OUT_PERC):
        raise ConfigError(
            f"FASTSim vehicle: key 'fc_eff_map' = {eff!r}; expected {len(FC_PWR_OUT_PERC)} efficiencies over "
            "fc_pwr_out_perc."
        )
    rows = "".join(f"{x:g},{float(e):g}\n" for x, e in zip(FC_PWR_OUT_PERC, eff, strict=True))
    (folder / "efficiency.csv").write_text("net_power_fraction,efficiency\n" + rows, encoding="utf-8")
    (folder / "meta.toml").write_text(
        f'name = "{folder.name}"\n'
        f'description = "FASTSim fuel cell of {_esc(v.get("scenario_name"))}: {v["fc_max_kw"]:g} kW"\n'
        'source = "NREL FASTSim vehicle file (Apache-2.0, Copyright 2020 Alliance for Sustainable Energy, '
        'LLC): fc_eff_map over fc_pwr_out_perc"\n',
        encoding="utf-8",
    )


def import_vehicle(
    path: str | Path, out: str | Path, row: int | None = None, name: str | None = None, force: bool = False
) -> Path:
    """Write the hevsim vehicle of FASTSim file ``path`` to ``out`` (TOML) with its maps in
    ``<out stem>_engine`` / ``<out stem>_motor`` beside it; check it loads. Returns ``out``."""
    from hevsim.config import config_from_dict, load_vehicle_config
    from hevsim.io import atomic_directory, prepare_output, write_text_atomic

    src = Path(path)
    v = read_vehicle(src, row, name)
    out_p = Path(out)
    stem = out_p.stem
    label = f"{src}" + (f" (row {row})" if row is not None else f" ({name})" if name else "")
    text = build_toml(v, label, stem)
    arch = hevsim_architecture(v, label)
    folders = []
    if arch == "fcev":
        folders.append((out_p.with_name(f"{stem}_fuel_cell"), lambda d: _write_fuel_cell(d, v)))
    if arch not in ("bev", "fcev"):
        folders.append(
            (
                out_p.with_name(f"{stem}_engine"),
                lambda d: _write_engine(d, v, FUELS.get(str(v.get("fc_eff_type")), "gasoline")),
            )
        )
    if arch != "conventional":
        folders.append((out_p.with_name(f"{stem}_motor"), lambda d: _write_motor(d, v)))
    prepare_output(out_p, kind="file", force=force, option="-o", protect=[src])
    for d, _ in folders:
        prepare_output(d, kind="dir", force=force, option="-o", protect=[src])
    with tempfile.TemporaryDirectory(prefix="hevsim-import-") as tmp:
        for d, write in folders:  # check the vehicle loads before anything appears at -o
            (Path(tmp) / d.name).mkdir()
            write(Path(tmp) / d.name)
        config_from_dict(tomllib.loads(text), str(out_p), Path(tmp))
    for d, write in folders:
        with atomic_directory(d, force=force) as tmp_dir:
            write(Path(tmp_dir))
    write_text_atomic(out_p, text)
    load_vehicle_config(out_p)
    return out_p


def run_command(args: Any) -> int:
    """``hevsim import-vehicle`` (arguments of :func:`hevsim.cli.build_parser`): list the
    vehicles of ``args.file`` or import one to ``args.out``."""
    if args.list:
        rows = list_vehicles(args.file)
        print(f"{'row':>4}  {'type':<5} name")
        for i, name, pt in rows:
            print(f"{i:>4}  {pt:<5} {name}")
        return 0
    if not args.out:
        raise ConfigError(f"{args.file}: no output: give -o vehicle.toml (or --list to list the vehicles).")
    out = import_vehicle(args.file, args.out, args.row, args.name, force=bool(getattr(args, "force", False)))
    print(f"wrote {out}")
    return 0
