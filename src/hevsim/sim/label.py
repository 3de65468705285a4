"""The EPA fuel-economy label: a procedure over :func:`~hevsim.sim.simulator.simulate`.

:func:`label` runs the city (UDDS, the FTP's cycle) and highway (HWFET) tests and turns their
unadjusted results into the label's adjusted figures with the EPA's *derived 5-cycle*
equations (40 CFR 600.210-12(a)(2)(i), (b)(2)(i))::

    adjusted city    = 1 / (city intercept    + city slope    / unadjusted city)
    adjusted highway = 1 / (highway intercept + highway slope / unadjusted highway)
    combined         = 1 / (0.55 / city + 0.45 / highway)                (600.210-12(c))

with the Administrator's intercepts and slopes for the vehicle's model year (the 2008 set,
printed in 40 CFR 600.210-08, or the set for model year 2017 on; ``hevsim/data/epa_label.toml``
cites both). Fuel economy is in US gallons of the fuel the vehicle burns: a diesel car's mpg
is miles per gallon of diesel, as on its EPA label.

**Charge-sustaining hybrids** (a battery and a fuel) are SOC-balanced over each test as SAE
J1711 requires: a test counts as it is when the battery's net energy change ``NEC`` (eq 15 of
:mod:`hevsim.sim.metrics`: charge drawn x open-circuit voltage, positive when discharged) is at
most ``soc_balance_tolerance`` (1 %) of the fuel energy burnt. Otherwise the initial SOC is
iterated (the first retry starts at the previous run's final SOC, as a preparation cycle would
leave the battery; later ones take the secant step on ``final SOC - initial SOC``). When no run
lands within the tolerance (a thermostat controller's on/off genset makes the final SOC jump),
the J1711 regression is used: the fuel of the runs is fitted linearly against their NEC and
read at NEC = 0. The label records the method, the runs and the balance achieved.

**Battery-electric vehicles**: energy at the battery terminals per distance (kWh/100 mi, the
audit's ``battery_chemical`` term over the distance driven), MPGe = 33.705 kWh/gal / (kWh/mi),
adjusted as FASTSim's ``simdrivelabel`` does: the larger of the derived 5-cycle MPGe and
0.7 x the unadjusted MPGe, divided by a charger efficiency (1 = battery terminals, the default;
the EPA's label counts energy from the wall, which hevsim does not model). Range = usable
battery energy (capacity x OCV integrated from ``soc_min`` to ``soc_max``) over the combined
kWh/mi, unadjusted and adjusted.
"""

from __future__ import annotations

import functools
import math
import time
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from hevsim.errors import ConfigError, InputError, TrackingError
from hevsim.fuels import config_fuel
from hevsim.io import atomic_directory, write_json
from hevsim.sim.checks import TRACKING_BOUND, tracking_violation
from hevsim.sim.plugin_label import (
    CD_MAX_CYCLES,
    DepletingRun,
    DepletingTest,
    distance_to_soc,
    plugin_figures,
)
from hevsim.units import J_PER_WH, M3_PER_US_GALLON, M_PER_MILE, MPS_PER_MPH

TABLE_PATH = "data/epa_label.toml"
"""The label's constants, relative to the installed ``hevsim`` package."""

CITY_CYCLE = "udds"
"""The city test's cycle (the FTP's driving schedule, 40 CFR 86 App. I)."""
HIGHWAY_CYCLE = "hwfet"
"""The highway test's cycle (40 CFR 600 App. I)."""
TESTS = (("city", CITY_CYCLE), ("highway", HIGHWAY_CYCLE))


@dataclass(frozen=True)
class Coefficients:
    """One set of derived 5-cycle intercepts [gal/mi] and slopes [-], valid from ``first_model_year``."""

    name: str
    first_model_year: int
    city_intercept_gal_per_mi: float
    city_slope: float
    highway_intercept_gal_per_mi: float
    highway_slope: float


@dataclass(frozen=True)
class LabelConstants:
    """The constants of ``hevsim/data/epa_label.toml`` (units in the names)."""

    city_weight: float
    kwh_per_gallon_equivalent: float
    electric_adjustment_factor: float
    soc_balance_tolerance: float
    soc_balance_max_runs: int
    coefficients: tuple[Coefficients, ...]

    def for_model_year(self, model_year: int | None) -> Coefficients:
        """The coefficient set of ``model_year`` (None: the newest set)."""
        sets = sorted(self.coefficients, key=lambda c: c.first_model_year)
        if model_year is None:
            return sets[-1]
        valid = [c for c in sets if c.first_model_year <= model_year]
        if not valid:
            raise ConfigError(
                f"model year = {model_year}; the derived 5-cycle label applies from model year "
                f"{sets[0].first_model_year} on (expected a year >= {sets[0].first_model_year})."
            )
        return valid[-1]


def _number(data: dict[str, Any], key: str, where: str, lo: float = 0.0, hi: float = math.inf) -> float:
    v = data.get(key)
    if isinstance(v, bool) or not isinstance(v, int | float) or not (lo < v <= hi):
        raise InputError(f"{where}: key '{key}' = {v!r}; expected a number in ({lo:g}, {hi:g}].")
    return float(v)


@functools.lru_cache(maxsize=1)
def constants() -> LabelConstants:
    """The label's constants, read and checked once from :data:`TABLE_PATH`."""
    import tomllib

    path = Path(str(resources.files("hevsim") / TABLE_PATH))
    data = tomllib.loads(path.read_text(encoding="utf-8"))
    where = str(path)
    sets = []
    for name, entry in data.get("coefficients", {}).items():
        w = f"{where} [coefficients.{name}]"
        sets.append(
            Coefficients(
                name,
                int(_number(entry, "first_model_year", w, 1900, 3000)),
                _number(entry, "city_intercept_gal_per_mi", w, 0, 1),
                _number(entry, "city_slope", w, 0, 10),
                _number(entry, "highway_intercept_gal_per_mi", w, 0, 1),
                _number(entry, "highway_slope", w, 0, 10),
            )
        )
    if not sets:
        raise InputError(f"{where}: no [coefficients.*] set; expected at least one.")
    return LabelConstants(
        _number(data, "city_weight", where, 0, 1),
        _number(data, "kwh_per_gallon_equivalent", where),
        _number(data, "electric_adjustment_factor", where, 0, 1),
        _number(data, "soc_balance_tolerance", where, 0, 1),
        int(_number(data, "soc_balance_max_runs", where, 1, 100)),
        tuple(sets),
    )


# --- the label's equations (pure functions; inputs in mi/gal or kWh/mi) ---------------------


def adjusted_city(unadjusted_mpg: float, c: Coefficients) -> float:
    """Derived 5-cycle city fuel economy [mi/gal] from the unadjusted city (FTP) value [mi/gal]."""
    return 1.0 / (c.city_intercept_gal_per_mi + c.city_slope / unadjusted_mpg)


def adjusted_highway(unadjusted_mpg: float, c: Coefficients) -> float:
    """Derived 5-cycle highway fuel economy [mi/gal] from the unadjusted highway (HFET) value [mi/gal]."""
    return 1.0 / (c.highway_intercept_gal_per_mi + c.highway_slope / unadjusted_mpg)


def unadjusted_city(adjusted_mpg: float, c: Coefficients) -> float:
    """The unadjusted city (FTP) fuel economy [mi/gal] behind a label's city value [mi/gal]
    (the inverse of :func:`adjusted_city`)."""
    return c.city_slope / (1.0 / adjusted_mpg - c.city_intercept_gal_per_mi)


def unadjusted_highway(adjusted_mpg: float, c: Coefficients) -> float:
    """The unadjusted highway (HFET) fuel economy [mi/gal] behind a label's highway value
    [mi/gal] (the inverse of :func:`adjusted_highway`)."""
    return c.highway_slope / (1.0 / adjusted_mpg - c.highway_intercept_gal_per_mi)


def combined(city_mpg: float, highway_mpg: float, city_weight: float = 0.55) -> float:
    """Combined fuel economy [mi/gal]: the city-weighted harmonic mean (600.210-12(c))."""
    return 1.0 / (city_weight / city_mpg + (1.0 - city_weight) / highway_mpg)


def adjusted_electric_mpge(unadjusted_mpge: float, test: str, c: Coefficients, factor: float = 0.7) -> float:
    """Adjusted MPGe [mi/gal-equivalent] of an electric vehicle's ``test`` ("city"/"highway"):
    the larger of the derived 5-cycle value and ``factor`` x the unadjusted MPGe (FASTSim
    ``simdrivelabel.py`` lines 132-139)."""
    derived = adjusted_city(unadjusted_mpge, c) if test == "city" else adjusted_highway(unadjusted_mpge, c)
    return max(derived, factor * unadjusted_mpge)


# --- SOC balance (SAE J1711) ------------------------------------------------------------------


@dataclass
class Run:
    """One simulated test run, as the SOC balance sees it."""

    soc_initial: float
    soc_final: float
    fuel_kg: float
    fuel_energy_j: float
    net_energy_change_j: float
    distance_m: float
    result: Any = field(repr=False)

    @property
    def balance(self) -> float:
        """NEC / fuel energy [-] (positive: the battery was discharged)."""
        return self.net_energy_change_j / self.fuel_energy_j if self.fuel_energy_j > 0 else math.inf


@dataclass
class LabelTest:
    """One label test (city or highway) and how it was balanced."""

    name: str
    cycle: str
    distance_m: float
    fuel_kg: float | None
    battery_energy_j: float
    method: str
    runs: list[Run]
    balance: float | None
    result: Any = field(repr=False)


def _fuel_energy_j(res: Any) -> float:
    audit = res.energy_audit
    return float(audit.get("fuel", 0.0) + audit.get("genset_source", 0.0))


def _run(model: Any, cycle: Any, soc: float | None) -> Run:
    from hevsim.sim.simulator import simulate

    res = simulate(model, cycle, soc_initial=soc, tracking=TRACKING_BOUND)
    _check_tracking(res)
    m = res.metrics
    return Run(
        float(m["soc_initial"]["value"]),
        float(m["soc_final"]["value"]),
        float(m["fuel_kg"]["value"]),
        _fuel_energy_j(res),
        float(m["battery_energy_wh"]["value"]) * J_PER_WH,
        float(m["distance_m"]["value"]),
        res,
    )


def _check_tracking(res: Any) -> None:
    """TrackingError when the car did not drive the test's trace (the bound of ``simulate``)."""
    ts = res.timeseries
    t = ts["time_s"].to_numpy()
    error = ts["speed_desired_mps"].to_numpy() - ts["speed_mps"].to_numpy()
    hit = tracking_violation(t, error, TRACKING_BOUND)
    if hit is not None:
        start, stop = hit
        raise TrackingError(
            f"{res.metadata['config']} on {res.cycle.name}: could not follow the label test's cycle: the "
            f"speed error exceeded {TRACKING_BOUND.error_mps / MPS_PER_MPH:.3g} mph from t = {t[start]:g} s "
            f"for {t[min(stop, t.size - 1)] - t[start]:g} s (allowed {TRACKING_BOUND.duration_s:g} s); a "
            "label needs a vehicle that drives the UDDS and HWFET traces.",
            res,
        )


def _next_soc(runs: list[Run], lo: float, hi: float) -> float:
    """The next initial SOC: the last final SOC (a preparation cycle), then secant steps on
    ``g(soc0) = final - initial``; kept inside ``[lo, hi]``."""
    last = runs[-1]
    soc = last.soc_final
    if len(runs) >= 2:
        a, b = runs[-2], runs[-1]
        ga, gb = a.soc_final - a.soc_initial, b.soc_final - b.soc_initial
        if gb != ga and b.soc_initial != a.soc_initial:
            soc = b.soc_initial - gb * (b.soc_initial - a.soc_initial) / (gb - ga)
    return float(min(max(soc, lo), hi))


def balance_soc(
    model: Any, cycle: str, name: str, tolerance: float, max_runs: int, soc_start: float | None = None,
    soc_cap: float | None = None,
) -> LabelTest:  # fmt: skip
    """Run ``cycle`` until ``|NEC| / fuel energy <= tolerance`` (SAE J1711), else regress.

    The first run starts at ``soc_start`` (None: the configuration's initial SOC); no run starts
    above ``soc_cap`` (a plug-in hybrid's charge-sustaining test: its ``plugin.cs_soc``).

    Returns the :class:`LabelTest` with the accepted run (method ``"within tolerance"``) or, when
    ``max_runs`` runs never balanced, the fuel read at NEC = 0 from a linear fit of fuel
    against NEC over the runs (method ``"J1711 regression"``; needs runs on both sides of 0).
    """
    b = model.config.battery
    margin = 1e-6
    lo, hi = b.soc_min + margin, (b.soc_max if soc_cap is None else soc_cap) - margin
    runs: list[Run] = []
    soc: float | None = soc_start
    for _ in range(max_runs):
        run = _run(model, cycle, soc)
        runs.append(run)
        if abs(run.balance) <= tolerance:
            return LabelTest(
                name,
                cycle,
                run.distance_m,
                run.fuel_kg,
                run.net_energy_change_j,
                "within tolerance",
                runs,
                run.balance,
                run.result,
            )
        nxt = _next_soc(runs, lo, hi)
        if any(abs(nxt - r.soc_initial) < 1e-9 for r in runs):
            nxt = 0.5 * (nxt + runs[-1].soc_initial) if abs(nxt - runs[-1].soc_initial) > 1e-9 else nxt
            if any(abs(nxt - r.soc_initial) < 1e-9 for r in runs):
                break
        soc = nxt
    nec = np.array([r.net_energy_change_j for r in runs])
    if not (nec.min() < 0.0 < nec.max()):
        worst = min(runs, key=lambda r: abs(r.balance))
        raise ConfigError(
            f"{model.name} on {cycle}: the SOC could not be balanced (SAE J1711): over {len(runs)} runs with "
            f"initial SOC {', '.join(f'{r.soc_initial:.4f}' for r in runs)} the net battery energy change "
            f"was never within {100 * tolerance:g} % of the fuel energy (best {100 * worst.balance:+.2f} %) "
            "and "
            "always of one sign, so no run brackets a balanced test; expected a charge-sustaining "
            "controller (check [controller] and the battery.soc_min/soc_max window)."
        )
    fuel = np.array([r.fuel_kg for r in runs])
    _slope, intercept = np.polyfit(nec, fuel, 1)
    best = min(runs, key=lambda r: abs(r.balance))
    distance = float(np.mean([r.distance_m for r in runs]))
    return LabelTest(name, cycle, distance, float(intercept), 0.0, "J1711 regression", runs, 0.0, best.result)


# --- the plug-in hybrid's charge-depleting test (SAE J1711; hevsim.sim.plugin_label) ------------


def charge_depleting_test(model: Any, cycle: str, max_cycles: int = CD_MAX_CYCLES) -> DepletingTest:
    """Repeat ``cycle`` from ``battery.soc_max`` until the SOC reaches ``plugin.cs_soc`` in a run
    (SAE J1711's charge-depleting test). Raises ConfigError when the battery does not deplete."""
    from hevsim.sim.simulator import simulate

    cfg = model.config
    cs = float(cfg.plugin.cs_soc)
    soc = float(cfg.battery.soc_max)
    runs: list[DepletingRun] = []
    before = 0.0
    for _ in range(max_cycles):
        res = simulate(model, cycle, soc_initial=soc, tracking=TRACKING_BOUND)
        _check_tracking(res)
        m = res.metrics
        run = DepletingRun(
            float(m["soc_initial"]["value"]),
            float(m["soc_final"]["value"]),
            float(m["distance_m"]["value"]),
            float(m["fuel_kg"]["value"]),
            float(m["battery_energy_wh"]["value"]) * J_PER_WH,
            res,
        )
        runs.append(run)
        if run.soc_final <= cs or float(res.timeseries["soc"].min()) <= cs:
            cda = before + distance_to_soc(res, cs)
            return DepletingTest(cycle, cs, runs, cda, before + run.distance_m)
        if run.soc_final >= run.soc_initial - 1e-9:
            raise ConfigError(
                f"{model.name} on {cycle}: the charge-depleting test does not deplete the battery (run "
                f"{len(runs)}: SOC {run.soc_initial:.4f} -> {run.soc_final:.4f}); expected the SOC to fall "
                f"to 'plugin.cs_soc' = {cs} (check [plugin] and [controller])."
            )
        before += run.distance_m
        soc = run.soc_final
    raise ConfigError(
        f"{model.name} on {cycle}: the SOC did not reach 'plugin.cs_soc' = {cs} in {max_cycles} cycles "
        f"(last {runs[-1].soc_final:.4f}); expected a plug-in hybrid that depletes its battery."
    )


# --- the label -------------------------------------------------------------------------------


@dataclass
class Label:
    """An EPA label: the tests, their figures (``figures``, JSON-ready) and a text report."""

    name: str
    architecture: str
    kind: str
    fuel: str
    coefficients: Coefficients
    tests: dict[str, LabelTest]
    figures: dict[str, Any]
    elapsed_s: float

    def to_dict(self) -> dict[str, Any]:
        """What ``label.json`` holds."""
        c = self.coefficients
        k = constants()
        tests = {}
        for key, t in self.tests.items():
            tests[key] = {
                "cycle": t.cycle,
                "distance_mi": t.distance_m / M_PER_MILE,
                "method": t.method,
                "balance_nec_over_fuel_energy": t.balance,
                "runs": [
                    {
                        "soc_initial": r.soc_initial,
                        "soc_final": r.soc_final,
                        "fuel_kg": r.fuel_kg,
                        "fuel_energy_j": r.fuel_energy_j,
                        "net_energy_change_j": r.net_energy_change_j,
                        "nec_over_fuel_energy": r.balance if math.isfinite(r.balance) else None,
                    }
                    for r in t.runs
                ],
            }
        return {
            "vehicle": self.name,
            "architecture": self.architecture,
            "kind": self.kind,
            "fuel": self.fuel,
            "method": "EPA derived 5-cycle label (40 CFR 600.210-12) from UDDS and HWFET",
            "coefficients": {
                "set": c.name,
                "first_model_year": c.first_model_year,
                "city_intercept_gal_per_mi": c.city_intercept_gal_per_mi,
                "city_slope": c.city_slope,
                "highway_intercept_gal_per_mi": c.highway_intercept_gal_per_mi,
                "highway_slope": c.highway_slope,
            },
            "city_weight": k.city_weight,
            "soc_balance_tolerance": (
                k.soc_balance_tolerance
                if self.kind in ("charge_sustaining", "plug_in", "fuel_cell")
                else None
            ),
            "figures": self.figures,
            "tests": tests,
            "elapsed_s": self.elapsed_s,
        }

    def text(self) -> str:
        """A short plain-text report."""
        f = self.figures
        c = self.coefficients
        w = constants().city_weight
        lines = [
            f"EPA label: {self.name} ("
            + ", ".join(dict.fromkeys([self.architecture, self.kind.replace("_", "-")]))
            + (f", {self.fuel})" if self.kind != "electric" else ")"),
            f"derived 5-cycle coefficients: set {c.name} (model year {c.first_model_year} on), "
            f"combined = {100 * w:g}/{100 - 100 * w:g} city/highway",
            f"{'':<26}{'city':>10}{'highway':>10}{'combined':>10}",
        ]

        def row(label: str, key: str, sub: str = "", fmt: str = "{:>10.1f}") -> None:
            table = f[key][sub] if sub else f[key]
            vals = [table[t] for t in ("city", "highway", "combined")]
            lines.append(f"{label:<26}" + "".join(fmt.format(v) for v in vals))

        if self.kind == "electric":
            row("unadjusted kWh/100 mi", "unadjusted_kwh_per_100mi")
            row("unadjusted MPGe", "unadjusted_mpge")
            row("adjusted kWh/100 mi", "adjusted_kwh_per_100mi")
            row("adjusted MPGe", "adjusted_mpge")
            lines.append(
                f"range: {f['range_mi']['unadjusted']:.0f} mi unadjusted, {f['range_mi']['adjusted']:.0f} mi "
                f"adjusted (usable battery energy {f['usable_battery_energy_kwh']:.2f} kWh); energy at the "
                f"battery terminals / charger efficiency {f['charger_efficiency']:g}, "
                f"{constants().kwh_per_gallon_equivalent:g} kWh per gallon equivalent"
            )
        elif self.kind == "fuel_cell":
            row("unadjusted MPGe", "unadjusted_mpge")
            row("adjusted MPGe", "adjusted_mpge")
            row("adjusted kg H2/100 mi", "hydrogen_kg_per_100mi", fmt="{:>10.2f}")
            lines.append(
                "MPGe = miles per gallon of hydrogen as [fuel] counts it: 1 kg by default, the EPA's "
                "gallon of gasoline equivalent (LHV 120 MJ/kg)"
            )
        else:
            row("unadjusted mpg", "unadjusted_mpg")
            row("adjusted mpg", "adjusted_mpg")
            lines.append(
                f"mpg in US gallons of {self.fuel}"
                + (" (the EPA label of a diesel car counts its own gallons)" if "diesel" in self.fuel else "")
            )
        if self.kind == "plug_in":
            lines[-1] = lines[-1].replace("mpg in US gallons", "charge-sustaining mpg in US gallons")
            r = f["charge_depleting_range_mi"]
            ra, rc = r["actual_unadjusted"], r["cycle_unadjusted"]
            lines.append(
                "charge-depleting range (SAE J1711, actual): "
                + ", ".join(f"{t} {ra[t]:.1f} mi" for t in ("city", "highway", "combined"))
                + f" unadjusted, {r['actual_adjusted']['combined']:.1f} mi adjusted combined "
                f"(cycle range {rc['city']:.1f} / {rc['highway']:.1f} mi); {f['mode']} to SOC {f['cs_soc']:g}"
            )
            row("CD kWh/100 mi (wall)", "charge_depleting_kwh_per_100mi", "unadjusted")
            row("CD kWh/100 mi adjusted", "charge_depleting_kwh_per_100mi", "adjusted")
            row("CD MPGe", "charge_depleting_mpge", "unadjusted")
            u = f["uf_weighted"]
            uf = u["utility_factor"]
            row("UF-weighted mpg", "uf_weighted", "mpg")
            row("UF-weighted kWh/100 mi", "uf_weighted", "kwh_per_100mi")
            row("UF-weighted MPGe", "uf_weighted", "mpge")
            lines.append(
                f"utility factors ({u['curve']}) at the CD cycle range: city {uf['city']:.3f}, "
                f"highway {uf['highway']:.3f}; charger efficiency {f['charger_efficiency']:g}"
            )
        if self.kind in ("charge_sustaining", "plug_in", "fuel_cell"):
            tol = constants().soc_balance_tolerance
            for key, t in self.tests.items():
                r = t.runs[-1]
                lines.append(
                    f"SOC balance {key}: |NEC|/fuel energy = {100 * abs(t.balance or 0.0):.2f} % "
                    f"(tolerance {100 * tol:g} %, SAE J1711), {t.method}, {len(t.runs)} run(s), "
                    f"initial SOC {r.soc_initial:.4f} -> final {r.soc_final:.4f}"
                )
        return "\n".join(lines)

    def save(self, out_dir: str | Path) -> Path:
        """Write ``label.json`` and ``label.txt`` into the folder ``out_dir`` atomically."""
        with atomic_directory(out_dir) as tmp:
            write_json(tmp / "label.json", self.to_dict())
            (tmp / "label.txt").write_text(self.text() + "\n", encoding="utf-8")
        return Path(out_dir)


def _gallons(fuel_kg: float, density_kg_per_m3: float) -> float:
    return fuel_kg / density_kg_per_m3 / M3_PER_US_GALLON


def usable_energy_j(battery: Any, soc_min: float, soc_max: float, points: int = 201) -> float:
    """Battery energy between ``soc_min`` and ``soc_max`` [J]: capacity x OCV integrated over SOC."""
    soc = np.linspace(soc_min, soc_max, points)
    ocv = np.asarray(battery.ocv(soc), dtype=float)
    return float(battery.capacity_ah * 3600.0 * np.trapezoid(ocv, soc))


def _kind(model: Any) -> str:
    from hevsim.config import is_plugin

    if model.config.architecture == "bev":
        return "electric"
    if is_plugin(model.config):
        return "plug_in"
    if model.config.architecture == "fcev":
        return "fuel_cell"
    return "charge_sustaining" if getattr(model, "battery", None) is not None else "conventional"


def _build(config: Any) -> Any:
    """The built vehicle model of ``config`` (path, configuration or model)."""
    from hevsim.config import load_vehicle_config

    if isinstance(config, str | Path):
        if not Path(config).is_file():
            raise ConfigError(f"{config}: vehicle file not found; expected a vehicle configuration (TOML).")
        config = load_vehicle_config(config)
    if hasattr(config, "config"):
        return config
    from hevsim.architectures import build_vehicle

    return build_vehicle(config)


def label(config: Any, model_year: int | None = None, charger_efficiency: float = 1.0) -> Label:
    """The EPA label of a vehicle (file path, configuration or built model).

    ``model_year`` picks the derived 5-cycle coefficient set (None: the newest);
    ``charger_efficiency`` [-] divides an electric vehicle's battery energy (1: energy at the
    battery terminals). Raises :class:`~hevsim.errors.TrackingError` when the vehicle cannot
    drive a test's trace and :class:`~hevsim.errors.ConfigError` for a hybrid whose SOC cannot
    be balanced.
    """
    if not (isinstance(charger_efficiency, int | float) and 0.0 < charger_efficiency <= 1.0):
        raise ConfigError(f"charger efficiency = {charger_efficiency!r}; expected a number in (0, 1].")
    t0 = time.perf_counter()
    k = constants()
    coef = k.for_model_year(model_year)
    model = _build(config)
    kind = _kind(model)
    fuel = config_fuel(model.config, getattr(model, "engine", None))
    tests: dict[str, LabelTest] = {}
    depleting: dict[str, Any] = {}
    for name, cycle in TESTS:
        if kind == "plug_in":
            cs = float(model.config.plugin.cs_soc)
            depleting[name] = charge_depleting_test(model, cycle)
            tests[name] = balance_soc(
                model, cycle, name, k.soc_balance_tolerance, k.soc_balance_max_runs, soc_start=cs
            )
        elif kind in ("charge_sustaining", "fuel_cell"):
            tests[name] = balance_soc(model, cycle, name, k.soc_balance_tolerance, k.soc_balance_max_runs)
        else:
            r = _run(model, cycle, None)
            battery_j = float(r.result.energy_audit.get("battery_chemical", 0.0))
            tests[name] = LabelTest(
                name, cycle, r.distance_m, r.fuel_kg, battery_j, "single run", [r], None, r.result
            )
    figures: dict[str, Any] = {}
    w = k.city_weight
    miles = {n: t.distance_m / M_PER_MILE for n, t in tests.items()}
    if kind == "electric":
        kwh_mi = {
            n: t.battery_energy_j / J_PER_WH / 1000.0 / miles[n] / charger_efficiency
            for n, t in tests.items()
        }
        if min(kwh_mi.values()) <= 0.0:
            raise ConfigError(
                f"{model.name}: the battery supplied no energy over a label test; expected > 0."
            )
        mpge = {n: k.kwh_per_gallon_equivalent / v for n, v in kwh_mi.items()}
        adj_mpge = {n: adjusted_electric_mpge(mpge[n], n, coef, k.electric_adjustment_factor) for n in mpge}
        adj_kwh_mi = {n: k.kwh_per_gallon_equivalent / v for n, v in adj_mpge.items()}
        kwh_mi["combined"] = w * kwh_mi["city"] + (1 - w) * kwh_mi["highway"]
        adj_kwh_mi["combined"] = w * adj_kwh_mi["city"] + (1 - w) * adj_kwh_mi["highway"]
        mpge["combined"] = k.kwh_per_gallon_equivalent / kwh_mi["combined"]
        adj_mpge["combined"] = k.kwh_per_gallon_equivalent / adj_kwh_mi["combined"]
        b = model.config.battery
        usable = usable_energy_j(model.battery, b.soc_min, b.soc_max) / J_PER_WH / 1000.0
        figures = {
            "unadjusted_kwh_per_100mi": {n: 100 * v for n, v in kwh_mi.items()},
            "adjusted_kwh_per_100mi": {n: 100 * v for n, v in adj_kwh_mi.items()},
            "unadjusted_mpge": mpge,
            "adjusted_mpge": adj_mpge,
            "usable_battery_energy_kwh": usable,
            "charger_efficiency": float(charger_efficiency),
            "range_mi": {
                "unadjusted": usable * charger_efficiency / kwh_mi["combined"],
                "adjusted": usable * charger_efficiency / adj_kwh_mi["combined"],
            },
            "units": {
                "kwh_per_100mi": "kWh/100 mi",
                "mpge": "mi/gal-equivalent",
                "range_mi": "mi",
                "usable_battery_energy_kwh": "kWh",
            },
        }
    else:
        mpg = {}
        for n, t in tests.items():
            assert t.fuel_kg is not None
            gal = _gallons(t.fuel_kg, fuel.density_kg_per_m3)
            if not gal > 0.0:
                raise ConfigError(
                    f"{model.name} on {t.cycle}: no fuel burnt; expected a fuel-burning vehicle."
                )
            mpg[n] = miles[n] / gal
        adj = {"city": adjusted_city(mpg["city"], coef), "highway": adjusted_highway(mpg["highway"], coef)}
        mpg["combined"] = combined(mpg["city"], mpg["highway"], w)
        adj["combined"] = combined(adj["city"], adj["highway"], w)
        figures = {
            "unadjusted_mpg": mpg,
            "adjusted_mpg": adj,
            "l_per_100km": {
                n: 100.0 * 1000.0 * M3_PER_US_GALLON / (v * M_PER_MILE / 1000.0) for n, v in adj.items()
            },
            "units": {"mpg": f"mi per US gallon of {fuel.name}", "l_per_100km": "L/100 km (adjusted)"},
        }
        if kind == "fuel_cell":  # hydrogen's "gallon" is 1 kg (fuels.toml): mpg = mi/kg = MPGe
            figures["unadjusted_mpge"] = dict(mpg)
            figures["adjusted_mpge"] = dict(adj)
            figures["hydrogen_kg_per_100mi"] = {n: 100.0 / v for n, v in adj.items()}
            figures["units"].update({"mpge": "mi per kg of hydrogen (1 kg = 1 gallon equivalent)",
                                     "hydrogen_kg_per_100mi": "kg/100 mi (adjusted)"})  # fmt: skip
        if kind == "plug_in":
            figures.update(
                plugin_figures(
                    model,
                    depleting,
                    mpg,
                    lambda kg: _gallons(kg, fuel.density_kg_per_m3),
                    k,
                    coef,
                    adjusted_electric_mpge,
                )
            )
            figures["units"].update({
                "charge_depleting_range_mi": "mi", "kwh_per_100mi": "kWh/100 mi from the wall",
                "mpge": "mi/gal-equivalent", "charge_depleting_fuel_gal": "US gal",
            })  # fmt: skip
    return Label(
        model.name,
        model.config.architecture,
        kind,
        fuel.label,
        coef,
        tests,
        figures,
        time.perf_counter() - t0,
    )
