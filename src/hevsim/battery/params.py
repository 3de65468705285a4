"""Cell parameter sets: loading and validation of the TOML data files in ``hevsim/data/cells``.

A parameter file holds scalar sections (validated through :mod:`hevsim.schema`) and the
tables (OCV for charge and discharge, series resistance for charge and discharge, all over
SOC [-] x temperature [K]; optional capacity factor over temperature) and the RC elements.
See ``docs/battery.md`` for the file format.
"""

from __future__ import annotations

import dataclasses
import warnings
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from hevsim.battery import kernel as K
from hevsim.errors import ConfigError, InputError
from hevsim.schema import build_section, read_toml
from hevsim.tables import FloatArray


@dataclass(frozen=True)
class CapacitySection:
    """Eq (35): ``C = (C0 + K_CQabs Q_abs)(1 + alphaC (T - T_ref))`` [C]."""

    c0_c: float
    t_ref_k: float = 293.15
    alpha_c_per_k: float = 0.0
    k_cqabs: float = 0.0


@dataclass(frozen=True)
class ResistanceSection:
    """Eq (36): ``R_s = R_table(SOC, T) (1 + alphaRs (T - T_ref))`` [ohm], times the Arrhenius
    factor ``exp(Ea/R_gas (1/T - 1/T_ref))`` of ``ea_j_per_mol`` (0: none; issue 27).

    ``switch_band_a`` [A]: dead band of the charge/discharge switch (see
    :mod:`hevsim.battery.kernel`).
    """

    alpha_rs_per_k: float = 0.0
    switch_band_a: float = 0.01
    ea_j_per_mol: float = field(default=0.0, metadata={"bounds": (-2e5, 2e5), "unit": "J/mol"})


@dataclass(frozen=True)
class ThermalSection:
    """Lumped thermal model, eq (41): heat capacity and skin resistance to the heat port.

    ``reversible_heat``: ``"off"`` (thesis: Joule and polarisation heat only) or
    ``"ocv_table"``: the entropic heat ``-i T dU/dT`` with ``dU/dT`` the temperature slope of
    the OCV tables (which then need two temperature columns or more; issue 27).
    """

    c_heat_j_per_k: float
    r_skin_k_per_w: float
    reversible_heat: str = field(default="off", metadata={"choices": ("off", "ocv_table")})


@dataclass(frozen=True)
class LimitsSection:
    """Discharge (SOC = 0) and charge (SOC = 1) voltage limits [V] bounding the OCV."""

    v_min_v: float
    v_max_v: float


@dataclass(frozen=True)
class AgeingSection:
    """SOH calibration factors of eqs (43)-(44) [-]."""

    x_c: float = 0.8
    x_z: float = 2.0


@dataclass(frozen=True)
class ModelSection:
    """Cell model options (:mod:`hevsim.battery.kernel`, "Model options"); the defaults are the
    thesis's model (``rc_mode = "switched"``, ``ocv_mode = "step_start"``).

    ``rc_mode``: ``"switched"`` (thesis: charge and discharge RC sets switched with the current
    direction; the disconnected set relaxes) or ``"persistent"`` (one set, always connected,
    parameters of the current direction's set). ``ocv_mode``: ``"step_start"`` (thesis: OCV at
    the start-of-step SOC) or ``"step_consistent"`` (end-of-step OCV for the end voltage, the
    step mean for the average; second order in the step).
    """

    rc_mode: str = field(default="switched", metadata={"choices": ("switched", "persistent")})
    ocv_mode: str = field(default="step_start", metadata={"choices": ("step_start", "step_consistent")})


@dataclass(frozen=True)
class ChargeTransferSection:
    """Butler-Volmer charge-transfer overpotential ``eta = scale (2RT/F) asinh(i / (2 i0))``.

    ``i0_a`` [A]: exchange current at ``capacity.t_ref_k`` (0 = no term, the thesis's model);
    ``scale`` [-]: lumped factor (1 for one electrode with alpha = 1/2, about 2 for two similar
    electrodes); ``ea_j_per_mol`` [J/mol]: Arrhenius activation energy of ``i0``.
    """

    i0_a: float = field(default=0.0, metadata={"bounds": (0.0, float("inf")), "unit": "A"})
    scale: float = field(default=1.0, metadata={"bounds": (1e-6, 100.0)})
    ea_j_per_mol: float = field(default=0.0, metadata={"bounds": (0.0, 2e5), "unit": "J/mol"})


@dataclass(frozen=True)
class HysteresisSection:
    """One-state hysteresis (off by default): ``dh/dt = -gamma |i| / C (h + max_v sign(i))``.

    ``max_v`` [V]: the hysteresis amplitude M (0 = off); ``gamma`` [-]: its rate per unit of
    charge throughput relative to the capacity.
    """

    max_v: float = field(default=0.0, metadata={"bounds": (0.0, 1.0), "unit": "V"})
    gamma: float = field(default=0.0, metadata={"bounds": (0.0, 1e6)})
    ea_j_per_mol: float = field(default=0.0, metadata={"bounds": (-2e5, 2e5), "unit": "J/mol"})


_BOUNDS = {
    "capacity.c0_c": (0.0, float("inf")),
    "capacity.t_ref_k": (0.0, float("inf")),
    "resistance.switch_band_a": (0.0, float("inf")),
    "thermal.c_heat_j_per_k": (0.0, float("inf")),
    "thermal.r_skin_k_per_w": (0.0, float("inf")),
    "limits.v_min_v": (0.0, float("inf")),
    "limits.v_max_v": (0.0, float("inf")),
}
_TOP_KEYS = (
    "name",
    "description",
    "source",
    "capacity",
    "resistance",
    "thermal",
    "limits",
    "ageing",
    "model",
    "charge_transfer",
    "hysteresis",
    "tables",
    "rc_discharge",
    "rc_charge",
)


@dataclass(frozen=True, eq=False)
class CellParameters:
    """A validated cell parameter set (SI units).

    Tables are stored as ``[soc index, temperature index]`` over ``soc`` [-] and
    ``temperature_k`` [K]; ``rc_discharge`` / ``rc_charge`` are ``(n_rc, 2)`` arrays of
    (R [ohm], tau [s]) at ``capacity.t_ref_k``, or ``(n_rc, 4)`` with the activation energies
    (Ea_R, Ea_tau) [J/mol] of their Arrhenius laws (:func:`hevsim.battery.kernel.rc_values`).
    """

    name: str
    capacity: CapacitySection
    resistance: ResistanceSection
    thermal: ThermalSection
    limits: LimitsSection
    ageing: AgeingSection
    soc: FloatArray
    temperature_k: FloatArray
    ocv_charge_v: FloatArray
    ocv_discharge_v: FloatArray
    rs_charge_ohm: FloatArray
    rs_discharge_ohm: FloatArray
    capacity_factor: FloatArray
    rc_discharge: FloatArray
    rc_charge: FloatArray
    description: str = ""
    source: str = "<in memory>"
    model: ModelSection = ModelSection()
    charge_transfer: ChargeTransferSection = ChargeTransferSection()
    hysteresis: HysteresisSection = HysteresisSection()

    def __post_init__(self) -> None:
        validate(self)

    @property
    def n_rc(self) -> int:
        """Number of RC elements per direction."""
        return int(self.rc_discharge.shape[0])

    @property
    def nominal_capacity_ah(self) -> float:
        """C0 in A·h."""
        return self.capacity.c0_c / 3600.0

    def replace(self, **changes: Any) -> CellParameters:
        """Copy with changed fields (re-validated)."""
        return dataclasses.replace(self, **changes)

    def vector(self, soc_initial: float, r_scale: float = 1.0, c0_scale: float = 1.0) -> FloatArray:
        """Kernel parameter vector (:data:`hevsim.battery.kernel.PARAMS`)."""
        p = np.empty(len(K.PARAMS))
        p[K.C0] = self.capacity.c0_c * c0_scale
        p[K.KCQ] = self.capacity.k_cqabs
        p[K.ALPHAC] = self.capacity.alpha_c_per_k
        p[K.TREF] = self.capacity.t_ref_k
        p[K.ALPHARS] = self.resistance.alpha_rs_per_k
        p[K.CHEAT] = self.thermal.c_heat_j_per_k
        p[K.RSKIN] = self.thermal.r_skin_k_per_w
        p[K.VMIN] = self.limits.v_min_v
        p[K.VMAX] = self.limits.v_max_v
        p[K.SOCINI] = soc_initial
        p[K.RSCALE] = r_scale
        p[K.NRC] = self.n_rc
        p[K.IBAND] = self.resistance.switch_band_a
        p[K.RCPERS] = 1.0 if self.model.rc_mode == "persistent" else 0.0
        p[K.OCVSTEP] = 1.0 if self.model.ocv_mode == "step_consistent" else 0.0
        p[K.CTI0] = self.charge_transfer.i0_a
        p[K.CTM] = self.charge_transfer.scale
        p[K.CTEA] = self.charge_transfer.ea_j_per_mol
        p[K.HMAX] = self.hysteresis.max_v
        p[K.HGAMMA] = self.hysteresis.gamma
        p[K.EARS] = self.resistance.ea_j_per_mol
        p[K.HEA] = self.hysteresis.ea_j_per_mol
        p[K.ENTROPIC] = 1.0 if self.thermal.reversible_heat == "ocv_table" else 0.0
        return p

    @property
    def has_temperature_laws(self) -> bool:
        """Whether any Arrhenius law or the entropic heat is on (issue 27)."""
        rc_ea = self.rc_discharge.shape[1] > 2 and bool(
            np.any(self.rc_discharge[:, 2:] != 0) or np.any(self.rc_charge[:, 2:] != 0)
        )
        return (
            rc_ea
            or self.resistance.ea_j_per_mol != 0.0
            or self.hysteresis.ea_j_per_mol != 0.0
            or (self.thermal.reversible_heat != "off")
        )

    def check_temperature_coverage(self, temps_k: Any, what: str) -> None:
        """Warn (:class:`TemperatureRangeWarning`) when ``temps_k`` [K] leave the tables'
        temperature axis: beyond it the tables are clamped (held at the edge column) and the
        entropic coefficient is zero; the Arrhenius laws hold at any temperature."""
        t = np.asarray(temps_k, dtype=float)
        ax = self.temperature_k
        if ax.size < 2 or t.size == 0:
            return
        lo, hi = float(np.min(t)), float(np.max(t))
        if lo < ax[0] or hi > ax[-1]:
            bad = lo if lo < ax[0] else hi
            key = (self.source, float(ax[0]), float(ax[-1]), what, bad < ax[0])
            if key in _WARNED:  # once per set, axis and side (a run repeated in a loop)
                return
            _WARNED.add(key)
            warnings.warn(
                f"{self.source}: key 'tables.temperature_k' covers {ax[0]:g}..{ax[-1]:g} K but {what} "
                f"reaches {bad:g} K; the tables are clamped there (held at the {ax[0]:g} or {ax[-1]:g} K "
                "column, no entropic heat); give a column at that temperature to model it.",
                TemperatureRangeWarning,
                stacklevel=3,
            )

    def tables(self) -> tuple[FloatArray, ...]:
        """Kernel table tuple: (soc, T, ocv_chg, ocv_dis, rs_chg, rs_dis, cap factor, rc_dis, rc_chg)."""
        rc_d = self.rc_discharge if self.n_rc else np.ones((1, 2))
        rc_c = self.rc_charge if self.n_rc else np.ones((1, 2))
        return (
            self.soc,
            self.temperature_k,
            self.ocv_charge_v,
            self.ocv_discharge_v,
            self.rs_charge_ohm,
            self.rs_discharge_ohm,
            self.capacity_factor,
            rc_d,
            rc_c,
        )

    def initial_state(self, temp_k: float, q_ini_c: float = 0.0) -> FloatArray:
        """Kernel state vector: Q = 0, Q_abs = Q_ini, cycles per eq (39), RC voltages 0."""
        x = np.zeros(K.N_FIXED_STATES + 2 * self.n_rc)
        x[K.SQABS] = q_ini_c
        x[K.STEMP] = temp_k
        x[K.SDIR] = 1.0
        p = self.vector(1.0)
        c = K.cell_capacity(p, self.temperature_k, self.capacity_factor, q_ini_c, temp_k)
        x[K.SCYC] = q_ini_c / (self.capacity.c0_c + c)  # eq (39)
        return x


class TemperatureRangeWarning(UserWarning):
    """A simulation runs at temperatures outside a parameter set's temperature axis (clamped)."""


_WARNED: set[tuple[str, float, float, str, bool]] = set()
"""Temperature-coverage warnings given (:meth:`CellParameters.check_temperature_coverage`)."""


def _err(src: str, key: str, msg: str) -> InputError:
    return InputError(f"{src}: key '{key}': {msg}")


def validate(c: CellParameters) -> None:
    """Check a parameter set; raises :class:`InputError` naming the key, value and expectation."""
    src = c.source
    for name in ("soc", "temperature_k"):
        ax = np.asarray(getattr(c, name))
        if ax.ndim != 1 or ax.size == 0 or not np.all(np.isfinite(ax)):
            raise _err(src, f"tables.{name}", f"expected a non-empty list of finite numbers, got {ax!r}.")
        bad = np.flatnonzero(np.diff(ax) <= 0)
        if bad.size:
            i = int(bad[0])
            raise _err(
                src,
                f"tables.{name}",
                f"not strictly increasing: {ax[i + 1]!r} at position {i + 1} "
                f"follows {ax[i]!r}; expected sorted, distinct breakpoints.",
            )
    shape = (c.soc.size, c.temperature_k.size)
    lim = c.limits
    if not lim.v_min_v < lim.v_max_v:
        raise _err(
            src, "limits.v_min_v", f"{lim.v_min_v!r} V must be below limits.v_max_v = {lim.v_max_v!r} V."
        )
    for name in ("ocv_charge_v", "ocv_discharge_v", "rs_charge_ohm", "rs_discharge_ohm"):
        z = getattr(c, name)
        if z.shape != shape:
            raise _err(
                src,
                f"tables.{name}",
                f"has shape {z.shape[::-1]} (temperature rows x SOC columns); "
                f"expected {shape[::-1]} to match tables.temperature_k and tables.soc.",
            )
        if not np.all(np.isfinite(z)):
            raise _err(src, f"tables.{name}", "has a non-finite value; expected finite numbers.")
        if name.startswith("ocv"):
            flat = int(np.argmax((z < lim.v_min_v) | (z > lim.v_max_v)))
            i, j = flat // z.shape[1], flat % z.shape[1]
            if z[i, j] < lim.v_min_v or z[i, j] > lim.v_max_v:
                raise _err(
                    src,
                    f"tables.{name}",
                    f"value {z[i, j]!r} V at SOC {c.soc[i]!r}, T {c.temperature_k[j]!r} K "
                    f"is outside the voltage limits [{lim.v_min_v}, {lim.v_max_v}] V.",
                )
            d = np.diff(z, axis=0)
            if np.any(d < 0):
                i, j = np.argwhere(d < 0)[0]
                raise _err(
                    src,
                    f"tables.{name}",
                    f"OCV decreases with SOC: {z[i + 1, j]!r} V at SOC "
                    f"{c.soc[i + 1]!r} after {z[i, j]!r} V at SOC {c.soc[i]!r} (T {c.temperature_k[j]!r} K); "
                    "expected OCV non-decreasing in SOC (rows sorted by SOC).",
                )
        elif np.any(z <= 0):
            i, j = np.argwhere(z <= 0)[0]
            raise _err(
                src,
                f"tables.{name}",
                f"resistance {z[i, j]!r} ohm at SOC {c.soc[i]!r}, T {c.temperature_k[j]!r} K must be > 0.",
            )
    if c.capacity_factor.shape != (c.temperature_k.size,) or np.any(c.capacity_factor <= 0):
        raise _err(
            src,
            "tables.capacity_factor",
            f"{c.capacity_factor!r}: expected one positive factor per temperature breakpoint.",
        )
    if c.capacity.c0_c <= 0:
        raise _err(src, "capacity.c0_c", f"capacity {c.capacity.c0_c!r} C must be > 0.")
    t_lo, t_hi = float(c.temperature_k[0]), float(c.temperature_k[-1])
    for t in (min(t_lo, 233.15), max(t_hi, 353.15)):
        if 1.0 + c.capacity.alpha_c_per_k * (t - c.capacity.t_ref_k) <= 0:
            raise _err(
                src,
                "capacity.alpha_c_per_k",
                f"{c.capacity.alpha_c_per_k!r} 1/K makes the capacity "
                f"negative at {t} K (eq 35); expected |alphaC| well below 1/|T - T_ref|.",
            )
    for t in (233.15, 353.15):
        if 1.0 + c.resistance.alpha_rs_per_k * (t - c.capacity.t_ref_k) <= 0:
            raise _err(
                src,
                "resistance.alpha_rs_per_k",
                f"{c.resistance.alpha_rs_per_k!r} 1/K makes R_s negative at {t} K (eq 36).",
            )
    for name in ("c_heat_j_per_k", "r_skin_k_per_w"):
        v = getattr(c.thermal, name)
        if not v > 0:
            raise _err(src, f"thermal.{name}", f"{v!r} must be > 0.")
    for name in ("rc_discharge", "rc_charge"):
        rc = getattr(c, name)
        if rc.ndim != 2 or rc.shape[1] not in (2, 4):
            raise _err(src, name, f"expected a list of {{r_ohm, tau_s}} elements, got shape {rc.shape}.")
        bad = (rc[:, :2] <= 0).any(axis=1) | ~np.isfinite(rc).all(axis=1)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            ea = f", activation energies {rc[i, 2]!r}, {rc[i, 3]!r} J/mol" if rc.shape[1] > 2 else ""
            raise _err(
                src,
                f"{name}[{i}]",
                f"r_ohm = {rc[i, 0]!r}, tau_s = {rc[i, 1]!r}{ea}: both must be finite and > 0"
                + (" (the activation energies finite)." if ea else "."),
            )
        if rc.shape[1] > 2 and np.any(np.abs(rc[:, 2:]) > 2e5):
            i, j = (int(v) for v in np.argwhere(np.abs(rc[:, 2:]) > 2e5)[0])
            key = ("ea_r_j_per_mol", "ea_tau_j_per_mol")[j]
            raise _err(
                src,
                f"{name}[{i}].{key}",
                f"value {rc[i, 2 + j]!r} J/mol is outside [-200000, 200000] J/mol (an activation energy).",
            )
    if c.thermal.reversible_heat != "off" and c.temperature_k.size < 2:
        raise _err(
            src,
            "thermal.reversible_heat",
            f"{c.thermal.reversible_heat!r} takes dU/dT from the OCV tables' temperature slope, but "
            f"tables.temperature_k has one column ({c.temperature_k[0]!r} K); expected two or more.",
        )
    if c.rc_discharge.shape != c.rc_charge.shape:
        raise _err(
            src,
            "rc_charge",
            f"has {c.rc_charge.shape[0]} elements but rc_discharge has "
            f"{c.rc_discharge.shape[0]}; expected the same number in both sets.",
        )


def _table(tables: dict[str, Any], key: str, src: str, n_t: int, n_soc: int) -> FloatArray:
    if key not in tables:
        raise _err(src, f"tables.{key}", "is missing.")
    try:
        z = np.array(tables[key], dtype=float)
    except (TypeError, ValueError) as exc:
        raise _err(src, f"tables.{key}", f"expected a list of rows of numbers ({exc}).") from exc
    if z.ndim == 1 and n_t == 1:
        z = z[None, :]
    if z.shape != (n_t, n_soc):
        raise _err(
            src,
            f"tables.{key}",
            f"has shape {z.shape}; expected {n_t} temperature rows of {n_soc} SOC values.",
        )
    return np.ascontiguousarray(z.T)


RC_KEYS = ("r_ohm", "tau_s", "ea_r_j_per_mol", "ea_tau_j_per_mol")
"""Keys of an RC element: R [ohm] and tau [s] at ``capacity.t_ref_k``, optional activation
energies [J/mol] of their Arrhenius laws (issue 27; 0 = constant)."""


def _rc(data: Any, key: str, src: str) -> FloatArray:
    if data is None:
        return np.zeros((0, 2))
    if not isinstance(data, list):
        raise _err(src, key, f"expected an array of tables [[{key}]], got {data!r}.")
    rows = []
    for i, el in enumerate(data):
        if not isinstance(el, dict) or not {"r_ohm", "tau_s"} <= set(el) or not set(el) <= set(RC_KEYS):
            raise _err(
                src,
                f"{key}[{i}]",
                f"{el!r}: expected the keys r_ohm and tau_s, optionally ea_r_j_per_mol and ea_tau_j_per_mol.",
            )
        row = []
        for k in RC_KEYS:
            v = el.get(k, 0.0)
            if isinstance(v, bool) or not isinstance(v, int | float):
                raise _err(src, f"{key}[{i}].{k}", f"value {v!r} has the wrong type; expected a number.")
            row.append(float(v))
        rows.append(row)
    arr = np.array(rows, dtype=float).reshape(-1, 4)
    return arr if np.any(arr[:, 2:] != 0.0) else np.ascontiguousarray(arr[:, :2])


def parameters_from_dict(data: dict[str, Any], source: str) -> CellParameters:
    """Validate a parsed parameter file into :class:`CellParameters`."""
    for key in data:
        if key not in _TOP_KEYS:
            raise ConfigError(f"{source}: key '{key}' is not known; valid keys are: {', '.join(_TOP_KEYS)}.")
    for key in ("capacity", "thermal", "limits", "tables"):
        if key not in data:
            raise ConfigError(f"{source}: section [{key}] is missing.")

    def section(cls: Any, key: str) -> Any:
        return build_section(cls, data.get(key, {}), source, key, {}, _BOUNDS)

    tables = data["tables"]
    for key in ("soc", "temperature_k"):
        if key not in tables:
            raise _err(source, f"tables.{key}", "is missing.")
    soc = np.array(tables["soc"], dtype=float)
    temp = np.array(tables["temperature_k"], dtype=float)
    if soc.ndim != 1 or temp.ndim != 1:
        raise _err(source, "tables.soc", "tables.soc and tables.temperature_k must be lists of numbers.")
    n_t, n_soc = temp.size, soc.size
    try:
        capf = np.array(tables.get("capacity_factor", [1.0] * n_t), dtype=float)
    except (TypeError, ValueError) as exc:
        raise _err(source, "tables.capacity_factor", f"expected numbers ({exc}).") from exc
    # sort check before shape handling so an unsorted axis reports as such
    ocv_c = _table(tables, "ocv_charge_v", source, n_t, n_soc)
    ocv_d = _table(tables, "ocv_discharge_v", source, n_t, n_soc)
    rs_c = _table(tables, "rs_charge_ohm", source, n_t, n_soc)
    rs_d = _table(tables, "rs_discharge_ohm", source, n_t, n_soc)
    rc_d = _rc(data.get("rc_discharge"), "rc_discharge", source)
    rc_c = _rc(data.get("rc_charge"), "rc_charge", source)
    if rc_d.shape[1] != rc_c.shape[1]:  # Arrhenius columns in one set only: both get them
        rc_d, rc_c = (np.c_[a, np.zeros((a.shape[0], 2))] if a.shape[1] == 2 else a for a in (rc_d, rc_c))
    return CellParameters(
        name=str(data.get("name", "cell")),
        description=str(data.get("description", "")),
        capacity=section(CapacitySection, "capacity"),
        resistance=section(ResistanceSection, "resistance"),
        thermal=section(ThermalSection, "thermal"),
        limits=section(LimitsSection, "limits"),
        ageing=section(AgeingSection, "ageing"),
        soc=soc,
        temperature_k=temp,
        ocv_charge_v=ocv_c,
        ocv_discharge_v=ocv_d,
        rs_charge_ohm=rs_c,
        rs_discharge_ohm=rs_d,
        capacity_factor=capf,
        rc_discharge=rc_d,
        rc_charge=rc_c,
        source=source,
        model=section(ModelSection, "model"),
        charge_transfer=section(ChargeTransferSection, "charge_transfer"),
        hysteresis=section(HysteresisSection, "hysteresis"),
    )


def shipped_cells() -> tuple[str, ...]:
    """Names of the shipped parameter sets (files in ``hevsim/data/cells``)."""
    folder = resources.files("hevsim") / "data" / "cells"
    return tuple(sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".toml")))


def load_cell_parameters(name_or_path: str | Path) -> CellParameters:
    """Load a shipped parameter set by name (see :func:`shipped_cells`) or a TOML file path."""
    p = Path(name_or_path)
    if not p.suffix:
        names = shipped_cells()
        if str(name_or_path) not in names:
            raise ConfigError(
                f"cell parameter set {str(name_or_path)!r} is not known; shipped sets are: "
                f"{', '.join(names)} (or give a path to a .toml file)."
            )
        p = Path(str(resources.files("hevsim") / "data" / "cells" / f"{name_or_path}.toml"))
    data = read_toml(p)
    return parameters_from_dict(data, str(p))
