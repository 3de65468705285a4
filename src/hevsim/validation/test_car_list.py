"""hevsim against the EPA Test Car List (model year 2022): every measured conventional gasoline
FTP and HWY certification test, the vehicle built from the list's own fields plus generic
component models (``hevsim/data/validation/epa_test_car_generic.toml``).

**The vehicle of a test** (:func:`vehicle_config`): a conventional car whose road load is the
list's *target* coefficients A [lbf], B [lbf/mph], C [lbf/mph^2] (converted to N, N/(m/s),
N/(m/s)^2) at the *equivalent test weight* (the body's coast-down form), a gearbox of the listed
number of gears (a CVT: a many-step box) whose top gear gives the listed *N/V ratio* (engine rpm
per mph in top gear) with the listed *axle ratio* as final drive, the listed drive axle, and a
generic gasoline engine (:func:`write_engine`) sized by the listed *displacement* and *rated
power*, shifted by the rule of its transmission class (:attr:`Generic.shift_rules`, fitted on
the training half by :func:`search_shift_rules`); a vehicle the list tested with a four-bag FTP
(:attr:`TestVehicle.four_bag`: the procedure of vehicles with a rechargeable energy storage
system, in this list's conventional cars the 48 V mild hybrids) stops its engine when there is
no traction demand (:attr:`Generic.four_bag_stop_start`). The measured figure is ``RND_ADJ_FE`` [mpg]:
the test's fuel economy as certified, before the label's 5-cycle adjustment (the FTP's is the
3-bag composite: its ``FE Bag 1..3`` columns combine to it with the FTP weights 0.43 cold /
0.57 hot).

**The generic engine** is a Willans-type map (fuel power linear in brake power with a
speed-dependent friction and a load-dependent pumping term)::

    P_fuel = [w T + w V_d / (4 pi) (fmep0 + fmep1 s + fmep2 s^2 + pmep (1 - T / T_max(w)))] / eta_i

with ``s`` = rpm / reference rpm (and a few more terms: :data:`POINT_TERMS`). Its weights, the
brake-work weight ``1 / eta_i`` by transmission class (the class's gearbox loss in proportion to
the work it passes: a gearbox efficiency by class relative to the generic one) and the FTP term
by class (``cold_start`` x V_d, added to the cold UDDS that weighs 0.43 in the composite; the
bag figures, :func:`ftp_bags`, show that a quarter of it is the cold start, the rest a city
penalty the model lacks) are fitted, all together, by non-negative least squares on the
relative fuel error of a *training half* of the test vehicles (:func:`split`: by a hash of
the Test Vehicle ID). The fit is linear: the operating points of a test do not depend on the
fuel map (the shift rule reads engine speed, the kick-down the torque curve, the fuel-cut drag
its own fixed constant), so
one simulation per test with any map gives the energy integrals (:data:`FEATURES`) the fuel of
every map is a linear combination of; :func:`fit` solves for the weights and the figures
reported are then full simulations with the fitted map.
"""

from __future__ import annotations

import csv
import functools
import hashlib
import itertools
import math
import re
import tomllib
from dataclasses import dataclass, field, replace
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from hevsim.errors import ConfigError
from hevsim.units import M3_PER_US_GALLON, M_PER_MILE, MPS_PER_MPH, RADPS_PER_RPM

TEST_CAR_LIST = "data/vehicles/epa/22-tstcar.csv"
"""The EPA Test Car List MY2022, relative to the installed ``hevsim`` package."""
GENERIC_FILE = "data/validation/epa_test_car_generic.toml"
"""The generic component models and the fitted engine parameters."""

N_PER_LBF = 4.4482216152605
"""Newtons in one pound-force [N/lbf] (exact)."""
KG_PER_LB = 0.45359237
"""Kilograms in one pound [kg/lb] (exact)."""
W_PER_HP = 745.69987158227022
"""Watts in one mechanical horsepower (550 ft lbf/s) [W/hp]."""
FTP_COLD_WEIGHT = 0.43
"""Weight of the cold-start UDDS (bags 1+2) in the FTP composite (40 CFR 600.114-08); the hot one is 0.57."""

GASOLINE_FUELS = ("Tier 2 Cert Gasoline",)
"""Test fuels counted as gasoline (the list's ``Test Fuel Type Description``)."""
PROCEDURES = {
    "FTP": (
        "Federal fuel 2-day exhaust (w/can load)", "Federal fuel 3-day exhaust",
        "CVS 75 and later (w/o can. load)",
    ),
    "HWY": ("HWFE",),
}  # fmt: skip
"""The tests kept, by category: the FTP's 75 °F exhaust tests and the highway test (the Cold CO
test at 20 °F is left out)."""
CYCLE_OF = {"FTP": "udds", "HWY": "hwfet"}
HYBRID_WORDS = (
    "hybrid", "hev", "phev", "plug-in", "prius", "insight", "ioniq", "niro", "sienna", "venza", "e-hybrid",
)  # fmt: skip
"""Words of a model name that mark a hybrid (lower case; ``Sienna`` and ``Venza`` are hybrid-only in
MY2022); so does a Lexus-style number ending in h (``ES 300h``, ``LC 500h``: :data:`HYBRID_PATTERN`)."""
HYBRID_PATTERN = re.compile(r"\b\d{3}h\+?(\s|$)")
HYBRID_FTP_HWY_RATIO = 0.95
"""A test vehicle whose measured FTP mpg is at least this share of its HWY mpg is taken for a hybrid
(regenerative braking: a conventional car's city figure is well below its highway one)."""
REPEAT_SPREAD_MAX = 1.10
"""Tests of one configuration on one cycle whose highest / lowest mpg exceeds this are not repeats
of one car: repeats of an FTP or HWY agree within a few per cent (in the list, 188 of the 244
groups of repeats within 8 %), while a second cluster, 51 groups 15 to 55 % apart, is cars tested
in different driver-selectable modes (sport / track / stop-start off) that the list's fields do
not tell apart (5 groups lie between, 8.4 to 14.3 %). Such a configuration is left out whole, in
both halves."""
FOUR_BAG_COLUMN = "FE Bag 4"
"""A Test Vehicle ID with a figure above 0 in this column on any row was tested with a four-bag FTP
(bag 4 repeats the stabilised phase to bound the change of a rechargeable battery's charge, SAE
J1711): a vehicle with a rechargeable energy storage system. In the list every hybrid and plug-in
so tested, and of the cars left after the other rules only known mild hybrids (48 V belt or
integrated starter-generators: BMW's 3.0 L sixes, Mercedes-Benz EQ Boost, Audi, Volvo B5 / B6, Land
Rover MHEV, RAM and Wagoneer eTorque) and the 2022 Tundra. Only the presence of the bag is read,
never its figure."""
BAG_TOLERANCE = 0.05
"""An FTP test whose ``RND_ADJ_FE`` differs from the composite of its own ``FE Bag 1..3`` figures by
more than this share is a data error (they agree within 0.3 % in the median) and is left out."""

POINT_TERMS = (
    "brake_work",
    "friction_vd",
    "friction_vd_speed",
    "friction_vd_speed2",
    "pumping_vd",
    "friction_peak",
    "friction_peak_speed",
    "brake_work_speed",
    "constant",
)
"""The fuel power of the generic map is ``sum(weight_k x term_k(w, T))`` [W] over these terms (per
unit weight: ``w T``; ``w V_d/(4 pi) s^k`` for k = 0, 1, 2, weights in Pa; ``w V_d/(4 pi) (1 -
T/T_max(w))`` (throttling), in Pa; ``w T_peak s^k`` for k = 0, 1 (friction scaling with the rated
torque); ``w T s``; 1 W); :func:`point_terms`."""
FEATURES = (*POINT_TERMS, "cold_start")
"""The energy integrals of a test (each point term over the fuelled steps, and for an FTP the
cold start's ``0.43 V_d`` [m^3]) whose weighted sum is the fuel energy [J]."""


@dataclass(frozen=True)
class EngineParams:
    """The generic engine's fitted weights, one per :data:`FEATURES` name (module docstring), and
    by transmission class (:attr:`Generic.shift_rules` name) the FTP term (``cold_start`` for a
    class not given) and the brake-work weight (``brake_work`` for a class not given: the
    transmission's loss in proportion to the work it passes, :func:`fit`)."""

    weights_by_name: tuple[tuple[str, float], ...]
    cold_start_by_class: tuple[tuple[str, float], ...] = ()
    brake_work_by_class: tuple[tuple[str, float], ...] = ()

    def weights(self) -> np.ndarray:
        """The weights in the order of :data:`FEATURES` (0 for a name not given)."""
        d = dict(self.weights_by_name)
        return np.array([float(d.get(k, 0.0)) for k in FEATURES])

    def cold_start(self, shift_class: str) -> float:
        """The FTP term [J/m^3] of a car of transmission class ``shift_class``."""
        return float(dict(self.cold_start_by_class).get(shift_class, self.weights()[-1]))

    def brake_work(self, shift_class: str) -> float:
        """The brake-work weight [-] (1 / indicated efficiency / the class's transmission
        efficiency relative to the generic one) of a car of transmission class ``shift_class``."""
        return float(dict(self.brake_work_by_class).get(shift_class, self.weights()[0]))

    def weights_for(self, shift_class: str) -> np.ndarray:
        """:meth:`weights` with the FTP term and the brake-work weight of ``shift_class``."""
        w = self.weights()
        w[0] = self.brake_work(shift_class)
        w[-1] = self.cold_start(shift_class)
        return w

    @classmethod
    def from_weights(cls, w: np.ndarray) -> EngineParams:
        """Parameters of weights ``w`` in the order of :data:`FEATURES`."""
        return cls(tuple((k, float(x)) for k, x in zip(FEATURES, w, strict=True)))

    @property
    def indicated_efficiency(self) -> float:
        """1 / the brake-work weight [-]."""
        return 1.0 / self.weights()[0]


@dataclass(frozen=True)
class ShiftRule:
    """The shift schedule of one transmission class: the list's ``Tested Transmission Type Code``
    in ``codes`` and ``# of Gears`` in ``min_gears`` .. ``max_gears``; up above ``upshift_rpm``,
    down below ``downshift_rpm`` [rpm]."""

    name: str
    codes: tuple[str, ...]
    min_gears: int
    max_gears: int
    upshift_rpm: float
    downshift_rpm: float

    def matches(self, v: TestVehicle) -> bool:
        """Whether test vehicle ``v`` is of this class."""
        return v.transmission_code in self.codes and self.min_gears <= v.gears <= self.max_gears


@dataclass(frozen=True)
class Generic:
    """The generic models of :data:`GENERIC_FILE` (units in the names)."""

    idle_rpm: float
    redline_rpm: float
    knee_rpm: float
    full_torque_rpm: float
    idle_torque_fraction: float
    reference_rpm: float
    closed_throttle_mep_pa: float
    inertia_kgm2_per_l: float
    speed_points: int
    torque_points: int
    spread: dict[int, float]
    cvt_steps: int
    gearbox_efficiency: float
    final_drive_efficiency: float
    upshift_rpm: float
    downshift_rpm: float
    tire_radius_m: float
    shift_rules: tuple[ShiftRule, ...]
    """By transmission class, the first that matches a vehicle; :attr:`upshift_rpm` /
    :attr:`downshift_rpm` for a vehicle no rule matches."""
    fitted: EngineParams
    source: str = ""
    four_bag_stop_start: bool = False
    """Whether a vehicle tested with a four-bag FTP (:attr:`TestVehicle.four_bag`) is simulated
    with stop-start (the engine off when there is no traction demand; ``[controller] stop_start``)."""

    def shift_rule(self, v: TestVehicle) -> tuple[str, float, float]:
        """(class name, upshift, downshift [rpm]) of test vehicle ``v``."""
        for r in self.shift_rules:
            if r.matches(v):
                return r.name, r.upshift_rpm, r.downshift_rpm
        return "other", self.upshift_rpm, self.downshift_rpm

    def with_shift(self, name: str, upshift_rpm: float, downshift_rpm: float) -> Generic:
        """These models with the rule of class ``name`` changed."""
        rules = tuple(
            replace(r, upshift_rpm=upshift_rpm, downshift_rpm=downshift_rpm) if r.name == name else r
            for r in self.shift_rules
        )
        return replace(self, shift_rules=rules)


def _num(d: dict[str, Any], key: str, where: str) -> float:
    v = d.get(key)
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v) or v < 0:
        raise ConfigError(f"{where}: key '{key}' = {v!r}; expected a number >= 0.")
    return float(v)


@functools.lru_cache(maxsize=4)
def generic(path: str | None = None) -> Generic:
    """The generic models (``path``: another TOML of the same layout; None: the shipped one)."""
    p = Path(path) if path else Path(str(resources.files("hevsim") / GENERIC_FILE))
    try:
        data = tomllib.loads(p.read_text(encoding="utf-8"))
    except (OSError, tomllib.TOMLDecodeError) as exc:
        raise ConfigError(f"{p}: cannot read the generic models ({exc}).") from exc
    e, t = data.get("engine", {}), data.get("transmission", {})
    f = e.get("fitted", {})
    w = str(p)
    spread = {int(k): _num(t.get("spread", {}), k, f"{w} [transmission.spread]") for k in t.get("spread", {})}
    unknown = sorted(set(f) - set(FEATURES) - {"cold_start_by_class", "brake_work_by_class"})
    if unknown:
        raise ConfigError(
            f"{w} [engine.fitted]: key(s) {unknown} unknown; expected some of {', '.join(FEATURES)}."
        )
    by_class = f.get("cold_start_by_class", {})
    bw_class = f.get("brake_work_by_class", {})
    for key, table, what in (
        ("cold_start_by_class", by_class, "FTP term [J/m^3]"),
        ("brake_work_by_class", bw_class, "brake-work weight [-]"),
    ):
        if not isinstance(table, dict):
            raise ConfigError(
                f"{w} [engine.fitted]: key '{key}' = {table!r}; expected a table of "
                f"transmission class name = {what}."
            )
    fitted = EngineParams(
        tuple((k, _num(f, k, f"{w} [engine.fitted]")) for k in FEATURES if k in f),
        tuple((k, _num(by_class, k, f"{w} [engine.fitted.cold_start_by_class]")) for k in by_class),
        tuple((k, _num(bw_class, k, f"{w} [engine.fitted.brake_work_by_class]")) for k in bw_class),
    )
    if fitted.weights()[0] <= 0 or any(x <= 0 for _, x in fitted.brake_work_by_class):
        raise ConfigError(
            f"{w} [engine.fitted]: key 'brake_work' (or a brake_work_by_class entry) = 0; expected "
            "1 / indicated efficiency > 1."
        )
    eng = ("idle_rpm", "redline_rpm", "knee_rpm", "full_torque_rpm", "idle_torque_fraction", "reference_rpm",
           "closed_throttle_mep_pa", "inertia_kgm2_per_l")  # fmt: skip
    trans = ("gearbox_efficiency", "final_drive_efficiency", "upshift_rpm", "downshift_rpm", "tire_radius_m")
    kw: dict[str, Any] = {k: _num(e, k, f"{w} [engine]") for k in eng}
    kw.update({k: _num(t, k, f"{w} [transmission]") for k in trans})
    kw.update({k: int(_num(e, k, f"{w} [engine]")) for k in ("speed_points", "torque_points")})
    kw["cvt_steps"] = int(_num(t, "cvt_steps", f"{w} [transmission]"))
    electrified = data.get("electrified", {})
    stop_start = electrified.get("four_bag_stop_start", False) if isinstance(electrified, dict) else None
    if not isinstance(stop_start, bool):
        raise ConfigError(
            f"{w} [electrified]: key 'four_bag_stop_start' = {stop_start!r}; expected true or false."
        )
    kw["four_bag_stop_start"] = stop_start
    rules = []
    shift = t.get("shift", [])
    if not isinstance(shift, list) or not all(isinstance(r, dict) for r in shift):
        raise ConfigError(
            f"{w} [transmission]: key 'shift' = {shift!r}; expected an array of tables "
            "[[transmission.shift]]."
        )
    for i, r in enumerate(shift):
        where = f"{w} [[transmission.shift]] #{i + 1}"
        codes = r.get("codes")
        if not isinstance(codes, list) or not codes or not all(isinstance(c, str) for c in codes):
            raise ConfigError(
                f"{where}: key 'codes' = {codes!r}; expected a list of transmission type codes."
            )
        rules.append(
            ShiftRule(
                str(r.get("name", f"rule {i + 1}")), tuple(codes), int(_num(r, "min_gears", where)),
                int(_num(r, "max_gears", where)), _num(r, "upshift_rpm", where),
                _num(r, "downshift_rpm", where),
            )
        )  # fmt: skip
    names = {r.name for r in rules} | {"other"}
    for key, table in (("cold_start_by_class", by_class), ("brake_work_by_class", bw_class)):
        stray = sorted(set(table) - names)
        if stray:
            raise ConfigError(
                f"{w} [engine.fitted.{key}]: key(s) {stray} name no transmission class; "
                f"expected some of {sorted(names)} (the [[transmission.shift]] names, or other)."
            )
    return Generic(**kw, spread=spread, shift_rules=tuple(rules), fitted=fitted, source=w)


# ============================================================================ the list
@dataclass
class TestVehicle:
    """One vehicle configuration of the list and its measured tests (SI)."""

    __test__ = False  # not a pytest class

    vehicle_id: str
    make: str
    model: str
    displacement_m3: float
    rated_power_w: float
    transmission: str
    transmission_code: str
    gears: int
    drive: str
    test_mass_kg: float
    axle_ratio: float
    nv_rpm_per_mph: float
    a_n: float
    b_n_per_mps: float
    c_n_per_mps2: float
    tests: list[tuple[str, str, float]] = field(default_factory=list)
    """(category "FTP"/"HWY", test number, measured RND_ADJ_FE [mpg])."""
    four_bag: bool = False
    """The list tested this vehicle with a four-bag FTP (:data:`FOUR_BAG_COLUMN`): it has a
    rechargeable energy storage system (a mild hybrid among the cars kept)."""

    @property
    def key(self) -> str:
        """The configuration's identity: vehicle ID, test weight, road load A, N/V, axle ratio."""
        return (
            f"{self.vehicle_id}|{self.test_mass_kg:.1f}|{self.a_n:.3f}|{self.nv_rpm_per_mph:g}|"
            f"{self.axle_ratio:g}"
        )

    @property
    def name(self) -> str:
        return f"{self.make} {self.model}".strip()


def _float(row: dict[str, str], col: str, where: str) -> float:
    try:
        v = float(row[col])
    except (KeyError, ValueError):
        raise ConfigError(f"{where}: column {col!r} = {row.get(col)!r}; expected a number.") from None
    return v


def _positive(text: str | None) -> bool:
    """Whether a list cell holds a number above 0."""
    try:
        return float(text or "") > 0
    except ValueError:
        return False


def split(vehicle_id: str) -> str:
    """``"train"`` or ``"test"``: the half of a Test Vehicle ID (the first byte of its SHA-256 even/odd)."""
    return "train" if hashlib.sha256(vehicle_id.encode()).digest()[0] % 2 == 0 else "test"


def is_hybrid_name(model: str) -> bool:
    """Whether a model name marks a hybrid (:data:`HYBRID_WORDS`)."""
    m = f" {model.lower()}"
    return any(w in m for w in HYBRID_WORDS) or HYBRID_PATTERN.search(m) is not None


def read_test_cars(path: str | Path | None = None) -> tuple[list[TestVehicle], dict[str, int]]:
    """The conventional gasoline test vehicles of the list with their measured FTP and HWY
    tests, and the count of tests left out per reason. A test counts once (the list repeats some
    rows: same test number, another averaging group); a test whose figure disagrees with its own
    bags (:data:`BAG_TOLERANCE`) and a configuration tested in several modes
    (:data:`REPEAT_SPREAD_MAX`) are left out. A vehicle with a four-bag FTP on any row is marked
    :attr:`TestVehicle.four_bag`."""
    p = Path(path) if path else Path(str(resources.files("hevsim") / TEST_CAR_LIST))
    try:
        with p.open(newline="", encoding="utf-8-sig") as f:
            rows = list(csv.DictReader(f))
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{p}: cannot read the EPA Test Car List ({exc}).") from exc
    skipped: dict[str, int] = {}

    def skip(reason: str) -> None:
        skipped[reason] = skipped.get(reason, 0) + 1

    cd_ids = {r["Test Vehicle ID"] for r in rows if r.get("Test Category") == "CD"}
    four_bag_ids = {r["Test Vehicle ID"] for r in rows if _positive(r.get(FOUR_BAG_COLUMN, ""))}
    vehicles: dict[str, TestVehicle] = {}
    counted: set[str] = set()
    for n, r in enumerate(rows, start=2):
        where = f"{p}, line {n}"
        cat = r.get("Test Category", "")
        if cat not in PROCEDURES:
            skip(f"category {cat} (not FTP/HWY)")
            continue
        if r.get("Test Procedure Description") not in PROCEDURES[cat]:
            skip(f"procedure {r.get('Test Procedure Description')}")
            continue
        if r.get("Test Fuel Type Description") not in GASOLINE_FUELS:
            skip(f"fuel {r.get('Test Fuel Type Description')}")
            continue
        if r.get("Analytically Derived FE?") != "No":
            skip("analytically derived (not measured)")
            continue
        if r["Test Vehicle ID"] in cd_ids:
            skip("plug-in hybrid (has a charge-depleting test)")
            continue
        if is_hybrid_name(r.get("Represented Test Veh Model", "")):
            skip("hybrid (model name)")
            continue
        try:
            mpg = _float(r, "RND_ADJ_FE", where)
            v = TestVehicle(
                r["Test Vehicle ID"], r["Represented Test Veh Make"], r["Represented Test Veh Model"],
                _float(r, "Test Veh Displacement (L)", where) * 1e-3,
                _float(r, "Rated Horsepower", where) * W_PER_HP,
                r["Tested Transmission Type"], r["Tested Transmission Type Code"],
                int(_float(r, "# of Gears", where)), r["Drive System Code"],
                _float(r, "Equivalent Test Weight (lbs.)", where) * KG_PER_LB,
                _float(r, "Axle Ratio", where), _float(r, "N/V Ratio", where),
                _float(r, "Target Coef A (lbf)", where) * N_PER_LBF,
                _float(r, "Target Coef B (lbf/mph)", where) * N_PER_LBF / MPS_PER_MPH,
                _float(r, "Target Coef C (lbf/mph**2)", where) * N_PER_LBF / MPS_PER_MPH**2,
            )  # fmt: skip
        except ConfigError:
            skip("a field empty or not a number")
            continue
        if min(v.displacement_m3, v.rated_power_w, v.test_mass_kg, v.axle_ratio, v.nv_rpm_per_mph, mpg) <= 0:
            skip("a field zero")
            continue
        number = r.get("Test Number", "")
        if number in counted:
            skip("a repeated row of a test already counted (same test number)")
            continue
        counted.add(number)
        bags = _bag_composite(r) if cat == "FTP" else None
        if bags is not None and abs(mpg / bags - 1) > BAG_TOLERANCE:
            skip(f"FTP figure off its own bags' composite by more than {100 * BAG_TOLERANCE:g} %")
            continue
        v.four_bag = v.vehicle_id in four_bag_ids
        v = vehicles.setdefault(v.key, v)
        v.tests.append((cat, number, mpg))
    out = []
    for v in vehicles.values():
        spread = [max(m) / min(m) for c in PROCEDURES if (m := [x for k, _, x in v.tests if k == c])]
        if max(spread) > REPEAT_SPREAD_MAX:
            for _ in v.tests:
                skip(
                    f"tested in several modes (repeats of one cycle more than "
                    f"{100 * (REPEAT_SPREAD_MAX - 1):.0f} % apart)"
                )
            continue
        ftp = [m for c, _, m in v.tests if c == "FTP"]
        hwy = [m for c, _, m in v.tests if c == "HWY"]
        if ftp and hwy and np.mean(ftp) >= HYBRID_FTP_HWY_RATIO * np.mean(hwy):
            for _ in v.tests:
                skip(f"hybrid (measured FTP >= {HYBRID_FTP_HWY_RATIO:g} x HWY)")
            continue
        out.append(v)
    return out, skipped


BAG_MILES = (3.59, 3.91, 3.59)
"""Distances of the FTP's three bags [mi]: bag 1 the cold-start transient (UDDS 0-505 s), bag 2
the stabilised phase (505-1372 s), bag 3 the hot-start repeat of bag 1 (40 CFR 86.144)."""


def _bag_composite(r: dict[str, str]) -> float | None:
    """The FTP composite [mpg] of a row's ``FE Bag 1..3`` (None without all three above 0)."""
    try:
        b = tuple(float(r[f"FE Bag {i}"]) for i in (1, 2, 3))
    except (KeyError, ValueError):
        return None
    if not min(b) > 0:  # also NaN
        return None
    hot, cold_gal = bag_split((b[0], b[1], b[2]))
    cold = (BAG_MILES[0] + BAG_MILES[1]) / ((BAG_MILES[2] + BAG_MILES[1]) / hot + cold_gal)
    return 1.0 / (FTP_COLD_WEIGHT / cold + (1 - FTP_COLD_WEIGHT) / hot)


def ftp_bags(path: str | Path | None = None) -> dict[str, tuple[float, float, float]]:
    """``FE Bag 1..3`` [mpg] of every FTP test of the list with all three, by test number."""
    p = Path(path) if path else Path(str(resources.files("hevsim") / TEST_CAR_LIST))
    out = {}
    with p.open(newline="", encoding="utf-8-sig") as f:
        for r in csv.DictReader(f):
            try:
                b = tuple(float(r[f"FE Bag {i}"]) for i in (1, 2, 3))
            except (KeyError, ValueError):
                continue
            if r.get("Test Category") == "FTP" and min(b) > 0:
                out[r.get("Test Number", "")] = (b[0], b[1], b[2])
    return out


def bag_split(bags: tuple[float, float, float]) -> tuple[float, float]:
    """(hot UDDS fuel economy [mpg] = bags 3 + 2, cold-start excess fuel [US gal] = bag 1's fuel
    less bag 3's) of one FTP test's bag figures [mpg]."""
    d1, d2, d3 = BAG_MILES
    b1, b2, b3 = bags
    return (d3 + d2) / (d3 / b3 + d2 / b2), d1 / b1 - d3 / b3


# ============================================================================ the vehicle
def gear_ratios(v: TestVehicle, g: Generic) -> list[float]:
    """Gearbox ratios [-], first gear first: top gear from N/V and the axle ratio, the others
    spaced geometrically over the generic spread of the listed number of gears."""
    overall = v.nv_rpm_per_mph * 2 * math.pi * g.tire_radius_m / (MPS_PER_MPH * 60.0)
    top = overall / v.axle_ratio
    n = g.cvt_steps if v.gears <= 1 else v.gears
    spread = g.spread.get(max(v.gears, 1))
    if spread is None:
        raise ConfigError(
            f"{g.source}: [transmission] spread has no value for {v.gears} gears (vehicle {v.vehicle_id})."
        )
    if n == 1:
        return [top]
    return [top * spread ** ((n - 1 - i) / (n - 1)) for i in range(n)]


def _max_torque(w_radps: np.ndarray, v: TestVehicle, g: Generic) -> np.ndarray:
    peak = v.rated_power_w / (g.knee_rpm * RADPS_PER_RPM)
    rpm = w_radps / RADPS_PER_RPM
    low = g.idle_torque_fraction + (1 - g.idle_torque_fraction) * np.clip(
        (rpm - g.idle_rpm) / max(g.full_torque_rpm - g.idle_rpm, 1.0), 0.0, 1.0
    )
    return np.minimum(peak * low, v.rated_power_w / np.maximum(w_radps, 1e-9))


def point_terms(t_nm: np.ndarray, w_radps: np.ndarray, v: TestVehicle, g: Generic) -> np.ndarray:
    """The :data:`POINT_TERMS` at torque [N m] and speed [rad/s] (arrays of one shape), stacked
    on a last axis [W per unit weight]."""
    t_nm, w_radps = np.broadcast_arrays(np.asarray(t_nm, float), np.asarray(w_radps, float))
    s = w_radps / (g.reference_rpm * RADPS_PER_RPM)
    vd = w_radps * v.displacement_m3 / (4 * math.pi)
    peak = w_radps * v.rated_power_w / (g.knee_rpm * RADPS_PER_RPM)
    load = np.clip(1.0 - t_nm / _max_torque(w_radps, v, g), 0.0, 1.0)
    wt = w_radps * t_nm
    return np.stack(
        [wt, vd, vd * s, vd * s * s, vd * load, peak, peak * s, wt * s, np.ones_like(wt)], axis=-1
    )


def fuel_power_w(
    t_nm: np.ndarray, w_radps: np.ndarray, v: TestVehicle, g: Generic, p: EngineParams
) -> np.ndarray:
    """Fuel power [W] of the generic engine of ``v`` (the weights of its transmission class) at
    torque [N m] and speed [rad/s] (module docstring)."""
    return point_terms(t_nm, w_radps, v, g) @ p.weights_for(g.shift_rule(v)[0])[: len(POINT_TERMS)]


def write_engine(folder: Path, v: TestVehicle, g: Generic, p: EngineParams, lhv_j_per_kg: float) -> None:
    """Write the generic engine of ``v`` (hevsim engine folder: meta.toml + CSV maps) into ``folder``."""
    folder.mkdir(parents=True, exist_ok=True)
    w = np.linspace(0.9 * g.idle_rpm, g.redline_rpm, g.speed_points) * RADPS_PER_RPM
    tmax = _max_torque(w, v, g)
    torque = np.linspace(0.0, float(tmax.max()), g.torque_points)
    ww, tt = np.meshgrid(w, torque, indexing="ij")
    rate = fuel_power_w(tt, ww, v, g, p) / lhv_j_per_kg * 1e3
    lines = ["speed_rad_per_s,torque_N_m,fuel_rate_g_per_s"]
    lines += [
        f"{a!r},{b!r},{c!r}"
        for a, b, c in zip(ww.ravel().tolist(), tt.ravel().tolist(), rate.ravel().tolist(), strict=True)
    ]
    (folder / "fuel_rate_map.csv").write_text("\n".join(lines) + "\n", encoding="utf-8")
    (folder / "max_torque.csv").write_text(
        "speed_rad_per_s,max_torque_N_m\n"
        + "".join(f"{a!r},{b!r}\n" for a, b in zip(w.tolist(), tmax.tolist(), strict=True)),
        encoding="utf-8",
    )
    drag = -g.closed_throttle_mep_pa * v.displacement_m3 / (4 * math.pi)
    (folder / "closed_throttle_torque.csv").write_text(
        "speed_rad_per_s,closed_throttle_torque_N_m\n" + "".join(f"{a!r},{drag!r}\n" for a in w.tolist()),
        encoding="utf-8",
    )
    (folder / "meta.toml").write_text(
        f'name = "{folder.name}"\n'
        'description = "generic gasoline engine (hevsim.validation.test_car_list): '
        f"{v.displacement_m3 * 1e3:.2f} L, "
        f'{v.rated_power_w / 1e3:.0f} kW"\n'
        'fuel = "gasoline"\n'
        'notes = "Not a measured map: the generic Willans-type gasoline map of '
        "hevsim.validation.test_car_list (fuel power = fitted weights x terms in speed, torque, "
        "displacement and rated torque; weights fitted on the training half of the EPA Test Car List "
        "MY2022, hevsim/data/validation/epa_test_car_generic.toml), "
        'sized by displacement and rated power."\n'
        "fitted_weights = { "
        + ", ".join(
            f"{k} = {float(x)!r}"
            for k, x in zip(FEATURES, p.weights_for(g.shift_rule(v)[0]), strict=True)
            if x
        )
        + " }\n"
        f"[parameters]\ndisplacement_L = {v.displacement_m3 * 1e3!r}\n"
        f"max_power_kW = {v.rated_power_w / 1e3!r}\n"
        f"rotational_inertia_kg_m2 = {g.inertia_kgm2_per_l * v.displacement_m3 * 1e3!r}\n"
        '[source]\nupstream = "hevsim (generic map); sizes from the US EPA Test Car List MY2022 '
        '(public domain)"\n',
        encoding="utf-8",
    )


def vehicle_config(v: TestVehicle, engine_dir: Path, g: Generic) -> Any:
    """The validated hevsim configuration of test vehicle ``v`` with its engine in ``engine_dir``."""
    from hevsim.config import config_from_dict

    axle = {"F": "front", "R": "rear"}.get(v.drive, "all")
    _, up, down = g.shift_rule(v)
    data = {
        "name": f"tcl_{v.vehicle_id}",
        "description": f"{v.name} (EPA Test Car List MY2022, test vehicle {v.vehicle_id})",
        "powertrain": {"architecture": "conventional"},
        "body": {
            "road_load_a_n": v.a_n, "road_load_b_n_per_m_s": v.b_n_per_mps,
            "road_load_c_n_per_m2_s2": v.c_n_per_mps2, "test_mass_kg": v.test_mass_kg,
        },
        "tire": {"radius_m": g.tire_radius_m, "driven_axle": axle},
        "final_drive": {"ratio": v.axle_ratio, "efficiency": g.final_drive_efficiency},
        "gearbox": {"ratios": gear_ratios(v, g), "efficiency": g.gearbox_efficiency},
        "engine": {
            "model": "map", "data": str(engine_dir), "stall_speed_rpm": g.idle_rpm,
            "redline_rpm": g.redline_rpm,
        },
        "simulation": {"cycle": "udds", "dt_s": 1.0},
        "controller": {
            "kind": "shift_schedule", "upshift_rpm": up, "downshift_rpm": down,
            "stop_start": "on" if v.four_bag and g.four_bag_stop_start else "off",
        },
    }  # fmt: skip
    return config_from_dict(data, f"test vehicle {v.vehicle_id}", engine_dir.parent)


# ============================================================================ running
@dataclass
class TestRun:
    """A simulated test: measured and predicted mpg, and the fuel's energy integrals."""

    __test__ = False

    vehicle: TestVehicle
    category: str
    test_number: str
    measured_mpg: float
    predicted_mpg: float
    features: np.ndarray
    distance_m: float
    half: str
    shift_class: str = "other"
    """The vehicle's transmission class (:meth:`Generic.shift_rule`): its FTP term."""

    @property
    def error(self) -> float:
        """predicted / measured - 1 [-]."""
        return self.predicted_mpg / self.measured_mpg - 1.0


def gallon_energy_j() -> float:
    """Energy of one US gallon of gasoline [J] (LHV x density of hevsim's gasoline)."""
    from hevsim.fuels import get_fuel

    f = get_fuel("gasoline")
    return f.lower_heating_value_j_per_kg * f.density_kg_per_m3 * M3_PER_US_GALLON


def features(res: Any, v: TestVehicle, category: str, g: Generic) -> np.ndarray:
    """The :data:`FEATURES` integrals of one simulation result (fuelled steps)."""
    ts = res.timeseries
    t = ts["time_s"].to_numpy()
    dt = np.diff(t, append=t[-1] + (t[-1] - t[-2] if t.size > 1 else 1.0))
    fuelled = (
        (ts["engine_on"].to_numpy() > 0)
        & (ts["fuel_cut"].to_numpy() == 0)
        & (ts["fuel_rate_gps"].to_numpy() > 0)
    )
    terms = point_terms(ts["engine_torque_nm"].to_numpy(), ts["engine_speed_radps"].to_numpy(), v, g)
    cold = FTP_COLD_WEIGHT * v.displacement_m3 if category == "FTP" else 0.0
    return np.append((fuelled * dt) @ terms, cold)


def run_vehicle(v: TestVehicle, work: Path, g: Generic, p: EngineParams) -> list[TestRun]:
    """Simulate test vehicle ``v`` (maps written under ``work``) on the cycles of its tests."""
    from hevsim.architectures import build_vehicle
    from hevsim.fuels import get_fuel
    from hevsim.sim.simulator import simulate

    folder = work / f"e_{hashlib.sha1(v.key.encode()).hexdigest()[:12]}"
    write_engine(folder, v, g, p, get_fuel("gasoline").lower_heating_value_j_per_kg)
    model = build_vehicle(vehicle_config(v, folder, g))
    gal_j = gallon_energy_j()
    shift_class = g.shift_rule(v)[0]
    cold = p.cold_start(shift_class)
    out = []
    cache: dict[str, tuple[float, np.ndarray, float]] = {}
    for cat, number, mpg in v.tests:
        if cat not in cache:
            res = simulate(model, CYCLE_OF[cat], tracking=None)
            f = features(res, v, cat, g)
            fuel_j = (
                float(res.metrics["fuel_kg"]["value"]) * get_fuel("gasoline").lower_heating_value_j_per_kg
            )
            fuel_j += cold * f[-1]
            dist = float(res.metrics["distance_m"]["value"])
            cache[cat] = (dist / M_PER_MILE / (fuel_j / gal_j), f, dist)
        pred, f, dist = cache[cat]
        out.append(TestRun(v, cat, number, mpg, pred, f, dist, split(v.vehicle_id), shift_class))
    return out


def run_all(
    vehicles: list[TestVehicle], work: Path, g: Generic, p: EngineParams | None = None
) -> list[TestRun]:
    """:func:`run_vehicle` for every vehicle (``p`` None: the shipped fitted parameters)."""
    p = p or g.fitted
    runs: list[TestRun] = []
    for v in vehicles:
        runs.extend(run_vehicle(v, work, g, p))
    return runs


BRAKE_WORK_MIN_RUNS = 20
"""A transmission class with fewer training runs than this gets no brake-work weight of its own in
:func:`fit`: its runs share one (a handful of runs cannot separate a gearbox loss from the map)."""


def fit(runs: list[TestRun]) -> EngineParams:
    """Non-negative least squares of the relative fuel error over ``runs`` (the training half):
    weights ``x`` >= 0 minimising sum((features . x) / measured fuel energy - 1)^2, with one FTP
    term and one brake-work weight per transmission class of the runs (``cold_start_by_class``,
    ``brake_work_by_class``: the brake-work weight is 1 / indicated efficiency over the class's
    transmission efficiency relative to the generic one, so the transmission loss in proportion
    to the work passed is the class's; classes of fewer than :data:`BRAKE_WORK_MIN_RUNS` runs
    share one). ``cold_start`` and ``brake_work``, for a class not fitted: their means weighted
    by the class's FTP runs and runs."""
    from scipy.optimize import nnls

    gal_j = gallon_energy_j()
    classes = sorted({r.shift_class for r in runs})
    runs_of = {c: sum(1 for r in runs if r.shift_class == c) for c in classes}
    own = [c for c in classes if runs_of[c] >= BRAKE_WORK_MIN_RUNS]
    column = {c: own.index(c) if c in own else len(own) for c in classes}
    n, k, kb = len(POINT_TERMS), len(classes), len(own) + (len(own) < len(classes))
    a = np.zeros((len(runs), n - 1 + kb + k))
    for i, r in enumerate(runs):
        a[i, : n - 1] = r.features[1:n]
        a[i, n - 1 + column[r.shift_class]] = r.features[0]
        a[i, n - 1 + kb + classes.index(r.shift_class)] = r.features[n]
        a[i] /= r.distance_m / M_PER_MILE / r.measured_mpg * gal_j
    scale = np.maximum(np.abs(a).max(axis=0), 1e-30)
    x, _ = nnls(a / scale, np.ones(len(runs)))
    x = x / scale
    brake = np.array([x[n - 1 + column[c]] for c in classes])
    cold = x[n - 1 + kb :]
    if np.any(brake <= 0):
        raise ConfigError(
            "the engine fit gave no brake-work weight (1 / indicated efficiency = 0) for a transmission "
            f"class ({', '.join(c for c, b in zip(classes, brake, strict=True) if b <= 0)}); check the data."
        )
    every = np.array([runs_of[c] for c in classes])
    ftp = np.array([sum(1 for r in runs if r.shift_class == c and r.features[n] > 0) for c in classes])
    mean_cold = float(ftp @ cold / ftp.sum()) if ftp.sum() else 0.0
    mean_brake = float(every @ brake / every.sum())
    return EngineParams(
        EngineParams.from_weights(np.concatenate(([mean_brake], x[: n - 1], [mean_cold]))).weights_by_name,
        tuple((c, float(w)) for c, w in zip(classes, cold, strict=True)),
        tuple((c, float(w)) for c, w in zip(classes, brake, strict=True)),
    )


def fit_loss(runs: list[TestRun], p: EngineParams) -> float:
    """Root mean square of the relative fuel error of ``runs`` with weights ``p`` [-] (what
    :func:`fit` minimises)."""
    gal_j = gallon_energy_j()
    rel = [
        float(r.features @ p.weights_for(r.shift_class))
        / (r.distance_m / M_PER_MILE / r.measured_mpg * gal_j)
        - 1
        for r in runs
    ]
    return float(np.sqrt(np.mean(np.square(rel))))


SHIFT_GRID = tuple(
    (u, d)
    for u in (1300.0, 1500.0, 1600.0, 1800.0, 1900.0, 2200.0, 2600.0, 3000.0)
    for d in (800.0, 1000.0, 1150.0, 1300.0, 1500.0)
    if u >= 1.3 * d
)
"""Upshift / downshift pairs [rpm] :func:`search_shift_rules` tries for each transmission class."""


def shift_feasible(v: TestVehicle, g: Generic, upshift_rpm: float, downshift_rpm: float) -> bool:
    """Whether the pair keeps ``v``'s gearbox from hunting: after every upshift the engine stays
    above the downshift speed (the configuration's own check)."""
    r = gear_ratios(v, g)
    return all(upshift_rpm * b / a > downshift_rpm for a, b in itertools.pairwise(r))


def search_shift_rules(
    vehicles: list[TestVehicle],
    work: Path,
    g: Generic,
    grid: tuple[tuple[float, float], ...] = SHIFT_GRID,
    rounds: int = 2,
) -> tuple[Generic, list[str]]:
    """Fit the shift rule of every transmission class (:attr:`Generic.shift_rules`) on the
    training half of ``vehicles``: each class's vehicles are simulated with every pair of
    ``grid`` that no vehicle of the class (either half: only its gear ratios are read) would
    hunt with; then, class after class for ``rounds`` rounds, the pair is kept whose runs give
    the engine fit (:func:`fit`, all training runs) the least :func:`fit_loss`. Returns the
    models with the chosen rules and a log of the search. The held-out half is not simulated."""
    train = [v for v in vehicles if split(v.vehicle_id) == "train"]
    names = [r.name for r in g.shift_rules]
    of_class = {n: [v for v in train if g.shift_rule(v)[0] == n] for n in names}
    every = {n: [v for v in vehicles if g.shift_rule(v)[0] == n] for n in names}
    fixed = run_all([v for v in train if g.shift_rule(v)[0] not in names], work, g)
    runs_of: dict[tuple[str, tuple[float, float]], list[TestRun]] = {}
    choice = {r.name: (r.upshift_rpm, r.downshift_rpm) for r in g.shift_rules}
    for n in names:
        for pair in sorted(set(grid) | {choice[n]}):
            if all(shift_feasible(v, g, *pair) for v in every[n]):
                runs_of[n, pair] = run_all(of_class[n], work, g.with_shift(n, *pair))

    def loss(c: dict[str, tuple[float, float]]) -> float:
        runs = fixed + [r for n in names for r in runs_of[n, c[n]]]
        return fit_loss(runs, fit(runs))

    log = [f"start {choice}: loss {loss(choice):.5f}"]
    for _ in range(rounds):
        for n in names:
            tried = {pair: loss({**choice, n: pair}) for (m, pair) in runs_of if m == n}
            choice[n] = min(tried, key=lambda pair: tried[pair])
            log.append(
                f"{n}: {choice[n][0]:g} / {choice[n][1]:g} rpm "
                f"(loss {tried[choice[n]]:.5f}, {len(tried)} pairs)"
            )
    for n, (u, d) in choice.items():
        g = g.with_shift(n, u, d)
    return g, log


def linear_mpg(r: TestRun, p: EngineParams) -> float:
    """The mpg the fitted weights predict from a run's integrals (the fit's own prediction) [mpg]."""
    return r.distance_m / M_PER_MILE / (float(r.features @ p.weights_for(r.shift_class)) / gallon_energy_j())


def summary(runs: list[TestRun]) -> dict[str, dict[str, float]]:
    """Median and 90th percentile of |error| [%], mean error [%] and count per (half, category)."""
    out: dict[str, dict[str, float]] = {}
    for half in ("train", "test"):
        for cat in ("FTP", "HWY"):
            e = np.array([r.error for r in runs if r.half == half and r.category == cat])
            if e.size:
                out[f"{half} {cat}"] = {
                    "n": float(e.size),
                    "median_abs_pct": 100 * float(np.median(np.abs(e))),
                    "p90_abs_pct": 100 * float(np.percentile(np.abs(e), 90)),
                    "mean_pct": 100 * float(np.mean(e)),
                }
    return out


def with_params(g: Generic, p: EngineParams) -> Generic:
    """``g`` with other fitted engine parameters."""
    return replace(g, fitted=p)
