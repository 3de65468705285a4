"""Sequential refinement of the series HEV, as in the thesis's tutorial (lectures 2-9).

Each level adds one refinement to the previous one. Two sets of level configurations ship
in ``hevsim/data/refinement`` (``calibration``):

* ``"public"`` (``level*.toml``): built from hevsim's shipped public data (ADVISOR engine,
  battery and motor maps, ADVISOR small-car rolling resistance, final drive 4);
* ``"thesis"`` (``thesis/level*.toml``): every parameter the thesis states
  (``thesis_parameters.toml`` cites each), and the quantities of its unavailable measured data
  files inferred from its reported figures (:func:`infer_thesis_quantities`).

:func:`run_refinement` simulates the levels over one cycle (the tutorial's FU505 by default),
:func:`format_table` prints MPG and SOC-corrected MPGGE per level beside the thesis's reported
figures (``thesis_figures.toml``), :func:`format_energy_table` the energy audit per level and
:func:`gap_bridge` how a public-data level turns into its thesis-calibrated one. Levels 1-4
have no fuel model yet (ideal components and an ideal engine whose fuel energy equals its brake
work); their energy is counted at ideal conversion, so every level that adds a loss lowers MPGGE.
"""

from __future__ import annotations

import sys
import tomllib
from collections.abc import Callable
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from hevsim.config import SeriesHEVConfig, config_from_dict, load_config
from hevsim.cycles import load_cycle
from hevsim.errors import ConfigError
from hevsim.units import BTU_PER_WH, J_PER_WH, M3_PER_US_GALLON, rpm_to_radps

CALIBRATIONS = ("public", "thesis")
"""Level-configuration sets: shipped public data, or the thesis's stated and inferred values."""
DEFAULT_CYCLE = "fu505"
"""The tutorial's cycle (lecture 3), on which the thesis reports its figures."""
J_PER_BTU = J_PER_WH / BTU_PER_WH
"""Joules per BTU as eq (16) counts them (3.412 BTU per W*h) [J/BTU]."""


def _root() -> Path:
    return Path(str(resources.files("hevsim") / "data" / "refinement"))


def _check_calibration(calibration: str) -> None:
    if calibration not in CALIBRATIONS:
        raise ConfigError(
            f"refinement calibration {calibration!r}: expected one of {', '.join(CALIBRATIONS)}."
        )


def level_files(calibration: str = "public") -> list[Path]:
    """The shipped refinement-level configurations of ``calibration``, in order."""
    _check_calibration(calibration)
    root = _root() if calibration == "public" else _root() / "thesis"
    return sorted(root.glob("level*.toml"))


def _read_toml(name: str) -> dict[str, Any]:
    with open(_root() / name, "rb") as fh:
        return tomllib.load(fh)


@dataclass(frozen=True)
class Figure:
    """A figure the thesis reports for one level (``thesis_figures.toml``)."""

    level: int
    metric: str
    value: float
    unit: str
    seed: str
    tested: bool


def thesis_figures() -> list[Figure]:
    """The thesis's reported figures, all on its FU505 cycle (:data:`DEFAULT_CYCLE`)."""
    data = _read_toml("thesis_figures.toml")
    return [
        Figure(int(f["level"]), str(f["metric"]), float(f["value"]), str(f["unit"]), str(f["seed"]),
               bool(f.get("tested", False)))
        for f in data["figure"]
    ]  # fmt: skip


def thesis_parameters() -> list[dict[str, Any]]:
    """Every parameter the thesis states, cited (``thesis_parameters.toml``)."""
    return list(_read_toml("thesis_parameters.toml")["parameter"])


def _engine_point(cfg: SeriesHEVConfig) -> tuple[float, float]:
    """(throttle [-], speed [rad/s]) of the genset's operating point."""
    return cfg.controller.throttle, rpm_to_radps(cfg.controller.engine_speed_rpm)


def parameter_value(cfg: SeriesHEVConfig | None, key: str) -> float:
    """The value ``key`` of ``thesis_parameters.toml`` has in ``cfg`` (or in hevsim).

    ``"section.key"`` reads the configuration; ``"derived.engine_torque_at_operating_point_nm"``
    is the engine's torque [N·m] at the controller's throttle and speed;
    ``"derived.engine_brake_efficiency"`` its brake efficiency [-] there (brake power over fuel
    LHV power); ``"units.NAME"`` and ``"cycles.NAME"`` are hevsim constants; ``"fuels.a.b"`` a
    value of ``hevsim/data/fuels.toml``.
    """
    head, _, rest = key.partition(".")
    if head == "units":
        import hevsim.units as units

        return float(getattr(units, rest))
    if head == "cycles":
        import hevsim.cycles as cycles

        return float(getattr(cycles, rest))
    if head == "fuels":
        with open(Path(str(resources.files("hevsim") / "data" / "fuels.toml")), "rb") as fh:
            node: Any = tomllib.load(fh)
        for part in rest.split("."):
            node = node[part]
        return float(node)
    if cfg is None:
        raise ValueError(f"parameter key {key!r} needs a configuration")
    if head == "derived":
        from hevsim.sim.model import build_engine

        engine = build_engine(cfg.engine, Path(cfg.base_dir))
        thr, w = _engine_point(cfg)
        torque = float(engine.torque(thr, w))
        if rest == "engine_torque_at_operating_point_nm":
            return torque
        if rest == "engine_brake_efficiency":
            return torque * w / (float(engine.fuel_rate(torque, w)) * engine.fuel_lhv_jpkg)
        raise ValueError(f"unknown derived parameter {key!r}")
    node = cfg.to_dict()
    for part in key.split("."):
        node = node[part]
    return float(node)


def _row(level: int, cfg: SeriesHEVConfig, r: Any) -> dict[str, Any]:
    """One level's metrics, fuel-energy terms (eqs 16-17) and energy audit [J]."""
    audit = dict(r.energy_audit)
    heating = r.model.engine.heating_value_btu_per_gal if r.model.engine is not None else 0.0
    fuel_gal = r.value("fuel_gal")
    e_elec_btu = r.value("battery_energy_wh") * BTU_PER_WH / cfg.metrics.conversion_efficiency
    brake = audit["fuel"] - audit["engine_loss"]
    ts = r.timeseries
    fired = ts["fuel_rate_gps"].to_numpy() > 0.0
    return {
        "level": level,
        "name": cfg.name,
        "description": cfg.description,
        "mpg": r.value("mpg"),
        "mpgge": r.value("mpgge"),
        "soc_final": r.value("soc_final"),
        "fuel_kg": r.value("fuel_kg"),
        "fuel_gal": fuel_gal,
        "distance_mi": r.value("distance_mi"),
        "fuel_energy_btu": fuel_gal * heating,
        "electrical_energy_btu": e_elec_btu,
        "engine_on_time_s": r.value("engine_on_time_s"),
        "engine_efficiency": brake / audit["fuel"] if audit["fuel"] > 0 else float("nan"),
        "engine_speed_rpm": float(np.mean(ts["engine_speed_rpm"].to_numpy()[fired]))
        if fired.any() else float("nan"),
        "engine_torque_nm": float(np.mean(ts["engine_torque_nm"].to_numpy()[fired]))
        if fired.any() else float("nan"),
        "speed_error_rms_mph": r.value("speed_error_rms_mph"),
        "energy_audit_residual_pct": r.value("energy_audit_residual_pct"),
        "audit": audit,
    }  # fmt: skip


def run_refinement(
    cycle: str = DEFAULT_CYCLE, progress: bool | None = None, calibration: str = "public"
) -> list[dict[str, Any]]:
    """Simulate every level of ``calibration`` over ``cycle``; one row of metrics per level."""
    from tqdm import tqdm

    from hevsim.sim.simulator import simulate

    cyc = load_cycle(cycle)
    files = level_files(calibration)
    show = sys.stderr.isatty() if progress is None else progress
    rows: list[dict[str, Any]] = []
    for i, path in enumerate(tqdm(files, desc="refinement levels", disable=not show), start=1):
        cfg = load_config(path)
        rows.append(_row(i, cfg, simulate(cfg, cyc)))
    return rows


def figure_comparison(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Each reported thesis figure beside the row's value of its metric and the difference [%]."""
    by_level = {r["level"]: r for r in rows}
    out = []
    for f in thesis_figures():
        r = by_level.get(f.level)
        if r is None or f.metric not in r:
            continue
        ours = float(r[f.metric])
        out.append({"figure": f, "hevsim": ours, "diff_pct": 100.0 * (ours / f.value - 1.0)})
    return out


def _fmt(x: float, digits: int = 1) -> str:
    if x == float("inf"):
        return "n/a (no fuel)"
    return f"{x:.{digits}f}"


def format_table(rows: list[dict[str, Any]], cycle: str, calibration: str = "public") -> str:
    """Markdown table of the refinement levels; on FU505, the thesis's figures beside them."""
    lines = [
        f"Sequential refinement on {cycle} (MPGGE with SOC correction, eqs 14-20), "
        f"{calibration} configurations",
        "",
        "| level | configuration | MPG | MPGGE | final SOC | RMS speed error [mph] | audit residual [%] |",
        "|---:|---|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(
            f"| {r['level']} | {r['name']}: {r['description']} | {_fmt(r['mpg'])} | "
            f"{_fmt(r['mpgge'])} | {r['soc_final']:.3f} | {r['speed_error_rms_mph']:.2f} | "
            f"{r['energy_audit_residual_pct']:.1e} |"
        )
    if not rows or "distance_mi" not in rows[0]:
        return "\n".join(lines)
    lines += [
        "",
        "Thesis figures (reported on FU505; seed lines in hevsim/data/refinement/thesis_figures.toml)",
        "",
    ]
    if cycle.lower() != DEFAULT_CYCLE:
        lines.append(
            f"(the thesis reports its figures on {DEFAULT_CYCLE}; run --cycle {DEFAULT_CYCLE} to compare)"
        )
        return "\n".join(lines)
    lines += ["| level | figure | thesis | hevsim | difference [%] |", "|---:|---|---:|---:|---:|"]
    for c in figure_comparison(rows):
        f = c["figure"]
        lines.append(
            f"| {f.level} | {f.metric} [{f.unit}] | {f.value:g} | {c['hevsim']:.6g} | {c['diff_pct']:+.1f} |"
        )
    return "\n".join(lines)


def _wheel_j(a: dict[str, float]) -> float:
    """Net work the powertrain does at the wheels [J]: road load, kinetic energy left, friction brakes."""
    return a["aero"] + a["rolling"] + a["grade"] + a["kinetic_vehicle"] + a["friction_brakes"]


ENERGY_COLUMNS: tuple[tuple[str, str, Callable[[dict[str, Any]], float]], ...] = (
    ("wheel", "net work at the wheels", _wheel_j),
    ("aero", "aerodynamic drag", lambda a: a["aero"]),
    ("rolling", "rolling resistance", lambda a: a["rolling"]),
    ("inertia", "kinetic energy left", lambda a: a["kinetic_vehicle"] + a["kinetic_genset"]),
    ("brakes", "friction brakes", lambda a: a["friction_brakes"]),
    ("machines", "motor, generator, gear", lambda a: a["motor_loss"] + a["generator_loss"] + a["gear_loss"]),
    ("battery", "battery losses", lambda a: a["battery_loss"]),
    ("engine loss", "fuel energy not turned into brake work", lambda a: a["engine_loss"]),
    ("fuel", "fuel energy (LHV) or ideal genset energy", lambda a: a["fuel"] + a["genset_source"]),
    ("from battery", "chemical energy drawn from the battery", lambda a: a["battery_chemical"]),
)  # fmt: skip
"""Energy-table columns: (header, meaning, audit terms [J] -> value [J])."""


def format_energy_table(rows: list[dict[str, Any]]) -> str:
    """Markdown energy breakdown per level [MJ]: sinks, sources, engine efficiency and operating
    point, SOC correction of eq (16) as energy, and the audit residual (sources - sinks)."""
    head = " | ".join(h for h, _, _ in ENERGY_COLUMNS)
    lines = [
        f"| level | {head} | engine η | engine point [rpm, N·m] | SOC corr. | residual [J] |",
        "|---:|" + "---:|" * (len(ENERGY_COLUMNS) + 4),
    ]
    for r in rows:
        a = r["audit"]
        cells = " | ".join(f"{fn(a) / 1e6:.4f}" for _, _, fn in ENERGY_COLUMNS)
        eta = r["engine_efficiency"]
        point = (
            f"{r['engine_speed_rpm']:.0f}, {r['engine_torque_nm']:.1f}"
            if np.isfinite(r["engine_speed_rpm"])
            else "-"
        )
        soc_corr = r["electrical_energy_btu"] * J_PER_BTU / 1e6
        lines.append(
            f"| {r['level']} | {cells} | {eta:.4f} | {point} | {soc_corr:.4f} | {a['residual']:.1e} |"
            if np.isfinite(eta)
            else f"| {r['level']} | {cells} | - | {point} | {soc_corr:.4f} | {a['residual']:.1e} |"
        )
    return "\n".join(lines)


# --- what the thesis's figures imply, and the inferred quantities ----------------------------------------


def thesis_implied(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per level with a thesis MPG or MPGGE figure: the fuel and total (fuel + SOC correction)
    energy [MJ, eq 17-18, the thesis's BTU per gallon] that figure implies over the thesis's
    distance (its reported distance of the level, else level 5's), beside this run's."""
    figs = {(f.level, f.metric): f.value for f in thesis_figures()}
    miles5 = figs[(5, "distance_mi")]
    out = []
    for r in rows:
        lv = r["level"]
        miles = figs.get((lv, "distance_mi"), miles5)
        heating = r["fuel_energy_btu"] / r["fuel_gal"] if r["fuel_gal"] > 0 else float("nan")
        ref = _reference_btu()
        item: dict[str, Any] = {"level": lv}
        if (lv, "mpg") in figs:
            item["thesis_fuel_mj"] = miles / figs[(lv, "mpg")] * heating * J_PER_BTU / 1e6
            item["hevsim_fuel_mj"] = r["fuel_energy_btu"] * J_PER_BTU / 1e6
        if (lv, "mpgge") in figs:
            item["thesis_total_mj"] = miles / figs[(lv, "mpgge")] * ref * J_PER_BTU / 1e6
            item["hevsim_total_mj"] = (r["fuel_energy_btu"] + r["electrical_energy_btu"]) * J_PER_BTU / 1e6
        if len(item) > 1:
            out.append(item)
    return out


def _reference_btu() -> float:
    from hevsim.fuels import mpgge_reference_btu_per_us_gal

    return float(mpgge_reference_btu_per_us_gal())


def _simulate_fu505(cfg: SeriesHEVConfig) -> Any:
    from hevsim.sim.simulator import simulate

    return simulate(cfg, DEFAULT_CYCLE)


def _bisect(fn: Callable[[float], float], target: float, lo: float, hi: float, tol: float) -> float:
    """Where the monotonic ``fn`` equals ``target`` on [lo, hi], by bisection (to ``tol``)."""

    def f(x: float) -> float:
        return fn(x) - target

    f_lo = f(lo)
    if f_lo * f(hi) > 0:
        raise ValueError(f"no sign change on [{lo}, {hi}]")
    while hi - lo > tol:
        mid = 0.5 * (lo + hi)
        f_mid = f(mid)
        if (f_mid > 0) == (f_lo > 0):
            lo, f_lo = mid, f_mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def infer_thesis_quantities() -> dict[str, dict[str, Any]]:
    """Re-derive the thesis-calibrated configurations' inferred quantities from the thesis's
    figures on FU505 (each with the figure, and the range its last reported digit allows):

    * ``engine_brake_efficiency`` [-]: brake work of thesis-calibrated level 5 over the LHV
      energy of the reported 0.0287752 gal (exact: the fuel does not act on the dynamics);
    * ``battery_resistance_ohm`` [ohm]: the Rint resistance making level 7 give 90 MPGGE;
    * ``machine_efficiency`` [-]: the common motor/generator efficiency making level 8 give
      65.4 MPGGE (with level 7's stored resistance).
    """
    figs = {(f.level, f.metric): f.value for f in thesis_figures()}
    files = level_files("thesis")
    out: dict[str, dict[str, Any]] = {}

    c5 = load_config(files[4])
    r5 = _simulate_fu505(c5)
    engine = r5.model.engine
    brake_j = r5.energy_audit["fuel"] - r5.energy_audit["engine_loss"]

    def eta_for(gal: float) -> float:
        return brake_j / (gal * M3_PER_US_GALLON * engine.fuel_density_kgpm3 * engine.fuel_lhv_jpkg)

    gal = figs[(5, "fuel_gal")]
    out["engine_brake_efficiency"] = {
        "value": eta_for(gal), "range": (eta_for(gal + 5e-8), eta_for(gal - 5e-8)),
        "figure": "level 5 fuel_gal", "brake_work_j": brake_j,
    }  # fmt: skip

    c7 = load_config(files[6])

    def mpgge7(resistance: float) -> float:
        return float(_simulate_fu505(c7.replace(**{"battery.resistance_ohm": resistance})).value("mpgge"))

    target7 = figs[(7, "mpgge")]
    out["battery_resistance_ohm"] = {
        "value": _bisect(mpgge7, target7, 0.05, 1.5, 1e-4),
        "range": tuple(_bisect(mpgge7, t, 0.05, 1.5, 1e-4) for t in (target7 + 0.5, target7 - 0.5)),
        "figure": "level 7 mpgge",
    }  # fmt: skip

    c8 = load_config(files[7])

    def mpgge8(eff: float) -> float:
        cfg = c8.replace(**{"motor.efficiency": eff, "generator.efficiency": eff})
        return float(_simulate_fu505(cfg).value("mpgge"))

    target8 = figs[(8, "mpgge")]
    out["machine_efficiency"] = {
        "value": _bisect(mpgge8, target8, 0.6, 1.0, 1e-4),
        "range": tuple(_bisect(mpgge8, t, 0.6, 1.0, 1e-4) for t in (target8 - 0.05, target8 + 0.05)),
        "figure": "level 8 mpgge",
    }  # fmt: skip
    return out


# --- from the public-data level to the thesis-calibrated one, one group of sections at a time -------------

BRIDGE_STEPS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("no rolling resistance, half-shaft inertia", ("body",)),
    ("engine at the thesis's operating point, efficiency inferred", ("engine", "genset", "controller")),
    ("battery (and SOC-correction OCV)", ("battery", "metrics")),
    ("motor and generator", ("motor", "generator")),
    (
        "final drive 2, motor-only braking, dt 0.1 s",
        ("final_drive", "brakes", "tire", "driver", "simulation"),
    ),
)
"""Gap-bridge steps: (what changes, configuration sections copied from the thesis-calibrated level)."""


def gap_bridge(level: int, cycle: str = DEFAULT_CYCLE) -> list[dict[str, Any]]:
    """MPG and MPGGE of public-data ``level`` as the sections of its thesis-calibrated
    configuration replace its own, one group at a time (:data:`BRIDGE_STEPS`); the last row
    is the thesis-calibrated level itself."""
    from hevsim.sim.simulator import simulate

    pub = load_config(level_files("public")[level - 1])
    th = load_config(level_files("thesis")[level - 1])
    th_dict = th.to_dict()
    engine = th_dict.get("engine", {})
    if engine.get("model") == "map":  # the calibrated engine's folder, relative to its own configuration
        folder = Path(th.base_dir) / str(engine["data"])
        if folder.is_dir():
            engine["data"] = str(folder)
    data = pub.to_dict()
    cyc = load_cycle(cycle)
    rows = []

    def add(step: str, cfg_data: dict[str, Any]) -> None:
        # resolved configurations mixed section by section, not a user's file: every key is there
        cfg = config_from_dict(
            cfg_data, source=f"{pub.name} ({step})", base_dir=Path(pub.base_dir), inert=False
        )
        r = simulate(cfg, cyc)
        rows.append({"step": step, "mpg": r.value("mpg"), "mpgge": r.value("mpgge"),
                     "distance_mi": r.value("distance_mi"), "soc_final": r.value("soc_final")})  # fmt: skip

    add("public-data configuration", data)
    for step, sections in BRIDGE_STEPS:
        for s in sections:
            if s in th_dict:
                data[s] = th_dict[s]
        add(step, data)
    return rows


# --- the cited parameters as a table (docs/refinement.md) ---------------------------------------------------


def _levels_text(levels: list[int]) -> str:
    if not levels:
        return ""
    if levels == list(range(levels[0], levels[-1] + 1)) and len(levels) > 1:
        return f"levels {levels[0]}-{levels[-1]}"
    return ("level " if len(levels) == 1 else "levels ") + ", ".join(str(v) for v in levels)


def _value_text(values: list[float]) -> str:
    distinct = sorted(set(values))
    return " / ".join(f"{v:.10g}" for v in distinct)


def parameter_table() -> str:
    """Markdown table of every parameter the thesis states (``thesis_parameters.toml``), with the
    value each set of level configurations actually holds (read from the configurations)."""
    thesis_cfgs = [load_config(p) for p in level_files("thesis")]
    public_cfgs = [load_config(p) for p in level_files("public")]
    lines = [
        "| parameter | thesis states | seed (line of the thesis text) | hevsim key | thesis-calibrated | "
        "public data | note |",
        "|---|---|---|---|---|---|---|",
    ]
    for p in thesis_parameters():
        key = p.get("key", "")
        levels = [int(v) for v in p.get("levels", [])]
        if not key:
            where, th, pub = "not used", "-", "-"
        elif levels:
            where = f"`{key}` ({_levels_text(levels)})"
            th = _value_text([parameter_value(thesis_cfgs[v - 1], key) for v in levels])
            if "public" in p:
                pub = _value_text([parameter_value(public_cfgs[v - 1], key) for v in levels])
            else:
                pub = "see note"
        else:
            where = f"`{key}`"
            th = pub = _value_text([parameter_value(None, key)])
        note = str(p.get("note", "")).replace("|", "/")
        lines.append(f"| {p['name']} | {p['stated']} | {p['seed']} | {where} | {th} | {pub} | {note} |")
    return "\n".join(lines)
