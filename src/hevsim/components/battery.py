"""Battery pack: ideal, Rint with constants, and OCV(SOC, T) with charge/discharge R(SOC, T).

All three levels share one kernel: terminal voltage ``V = OCV - R I`` with discharge-positive
current (the thesis's eq 21 with its charging-positive sign flipped), ``R`` taken from the
discharge or charge table by the sign of the current (eq 22 adds the wiring resistance), and
SOC by Coulomb counting, eq (13), with a coulombic efficiency applied on charge. An ideal
battery is the same kernel with R = 0 and constant OCV. Cells are assembled ``n_series`` x
``n_parallel``; current limits apply to the pack.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numba import njit

from hevsim.errors import InputError
from hevsim.tables import FloatArray, Table1D, Table2D, interp2, read_meta
from hevsim.units import c_to_k


@njit(cache=True)
def pack_ocv_r(soc, temp_k, current_sign, ocv_x, ocv_y, ocv_z, rd_z, rc_z, n_s, n_p, r_extra):
    """Pack open-circuit voltage [V] and series resistance [ohm] (scalar kernel).

    Tables share the axes (SOC [-], temperature [K]); ``current_sign`` > 0 selects discharge.
    """
    ocv = n_s * interp2(ocv_x, ocv_y, ocv_z, soc, temp_k, False)
    rz = rd_z if current_sign > 0 else rc_z
    r = n_s / n_p * interp2(ocv_x, ocv_y, rz, soc, temp_k, False) + r_extra
    return ocv, r


@njit(cache=True)
def current_for_power(power_w, ocv_v, r_ohm):
    """Discharge-positive current [A] delivering terminal power [W] (scalar or array).

    Solves ``P = (OCV - R I) I`` on the physical root. Beyond the maximum deliverable power
    ``OCV^2 / (4 R)`` the result is the current at maximum power (callers check feasibility).
    """
    disc = np.maximum(ocv_v * ocv_v - 4.0 * r_ohm * power_w, 0.0)
    # conjugate form of (OCV - sqrt(disc)) / (2 R): exact for R = 0 and free of cancellation
    return 2.0 * power_w / (ocv_v + np.sqrt(disc))


@dataclass(frozen=True, eq=False)
class BatteryPack:
    """Battery pack parameters (SI). Cell tables are over SOC [-] x temperature [K].

    Attributes:
        name, kind ("ideal", "rint", "table").
        ocv_cell: cell OCV [V]; r_discharge_cell, r_charge_cell: cell resistance [ohm],
            all on the same (SOC, temperature) grid.
        capacity_cell_ah: cell capacity [A·h]; coulombic_efficiency [-] on charge.
        n_series, n_parallel: cells in series and in parallel.
        r_extra_ohm: wiring and other series resistance of eq (22) [ohm].
        max_discharge_current_a, max_charge_current_a: pack current limits (> 0) [A].
        temperature_k: pack temperature [K] (constant until the thermal model plugs in).
    """

    name: str
    kind: str
    ocv_cell: Table2D
    r_discharge_cell: Table2D
    r_charge_cell: Table2D
    capacity_cell_ah: float
    coulombic_efficiency: float = 1.0
    n_series: int = 1
    n_parallel: int = 1
    r_extra_ohm: float = 0.0
    max_discharge_current_a: float = math.inf
    max_charge_current_a: float = math.inf
    temperature_k: float = c_to_k(25.0)

    def __post_init__(self) -> None:
        for t in (self.r_discharge_cell, self.r_charge_cell):
            if not (np.array_equal(t.x, self.ocv_cell.x) and np.array_equal(t.y, self.ocv_cell.y)):
                raise InputError(
                    f"battery '{self.name}': table {t.source} must share the OCV table's SOC and "
                    "temperature axes."
                )
        if self.capacity_cell_ah <= 0:
            raise InputError(f"battery '{self.name}': capacity {self.capacity_cell_ah!r} A·h must be > 0.")
        if self.n_series < 1 or self.n_parallel < 1:
            raise InputError(f"battery '{self.name}': n_series and n_parallel must be >= 1.")

    @property
    def capacity_ah(self) -> float:
        """Pack capacity [A·h]."""
        return self.capacity_cell_ah * self.n_parallel

    def kernel_tables(self) -> tuple[FloatArray, ...]:
        """(soc axis, temperature axis, ocv, r_dis, r_chg) for compiled loops."""
        o = self.ocv_cell
        return (o.x, o.y, o.z, self.r_discharge_cell.z, self.r_charge_cell.z)

    def ocv(self, soc, temp_k=None):
        """Pack OCV [V] at SOC [-] and temperature [K] (vectorised)."""
        t = self.temperature_k if temp_k is None else temp_k
        return self.n_series * self.ocv_cell(soc, t)

    def resistance(self, soc, current_a, temp_k=None):
        """Pack resistance [ohm] at SOC [-], current [A] (discharge > 0), temperature [K]."""
        t = self.temperature_k if temp_k is None else temp_k
        r_cell = np.where(
            np.asarray(current_a) > 0, self.r_discharge_cell(soc, t), self.r_charge_cell(soc, t)
        )
        return self.n_series / self.n_parallel * r_cell + self.r_extra_ohm

    def current(self, power_w, soc, temp_k=None):
        """Discharge-positive current [A] for terminal power [W] (> 0 discharging), vectorised."""
        p = np.asarray(power_w, float)
        ocv = self.ocv(soc, temp_k)
        r = self.resistance(soc, p, temp_k)
        return current_for_power(p, ocv, r)

    def soc_rate(self, current_a):
        """dSOC/dt [1/s] for current [A], eq (13) with coulombic efficiency on charge."""
        i = np.asarray(current_a, float)
        eff = np.where(i < 0, self.coulombic_efficiency, 1.0)
        return -i * eff / (3600.0 * self.capacity_ah)

    # --- constructors for the three fidelity levels -------------------------------------
    @classmethod
    def constant(
        cls,
        name: str,
        kind: str,
        voltage_v: float,
        capacity_ah: float,
        resistance_ohm: float = 0.0,
        **kwargs: object,
    ) -> BatteryPack:
        """Ideal (R = 0) or Rint pack with constant OCV [V], capacity [A·h], R [ohm]."""
        x = np.array([0.0])
        y = np.array([c_to_k(25.0)])
        return cls(
            name=name,
            kind=kind,
            ocv_cell=Table2D(x, y, np.full((1, 1), voltage_v)),
            r_discharge_cell=Table2D(x, y, np.full((1, 1), resistance_ohm)),
            r_charge_cell=Table2D(x, y, np.full((1, 1), resistance_ohm)),
            capacity_cell_ah=capacity_ah,
            **kwargs,  # type: ignore[arg-type]
        )

    @classmethod
    def from_directory(cls, path: str | Path, **kwargs: object) -> BatteryPack:
        """Table pack from a shipped-format cell folder (meta.toml, ocv.csv, r_*.csv, capacity)."""
        d = Path(path)
        meta = read_meta(d, "battery")
        ocv = _cell_table(d / "ocv.csv", "ocv_cell_V")
        rd = _cell_table(d / "r_discharge.csv", "r_dis_cell_ohm")
        rc = _cell_table(d / "r_charge.csv", "r_chg_cell_ohm")
        cap = Table1D.from_csv(d / "capacity.csv", "temperature_degC", "max_capacity_Ah")
        eff = Table1D.from_csv(d / "capacity.csv", "temperature_degC", "coulombic_efficiency")
        temp_k = float(kwargs.get("temperature_k", c_to_k(25.0)))  # type: ignore[arg-type]
        temp_c = temp_k - c_to_k(0.0)
        args: dict[str, object] = {
            "name": str(meta.get("name", d.name)),
            "kind": "table",
            "ocv_cell": ocv,
            "r_discharge_cell": rd,
            "r_charge_cell": rc,
            "capacity_cell_ah": float(cap(temp_c)),
            "coulombic_efficiency": float(eff(temp_c)),
        }
        args.update(kwargs)
        return cls(**args)  # type: ignore[arg-type]


def _cell_table(path: Path, column: str) -> Table2D:
    """Long-format (temperature_degC, soc_fraction, value) CSV -> Table2D over (SOC, T [K])."""
    t = Table2D.from_long_csv(path, "temperature_degC", "soc_fraction", column)
    return Table2D(
        t.y, t.x + c_to_k(0.0), t.z.T.copy(), x_name="soc", y_name="temperature_k",
        z_name=column, source=str(path),
    )  # fmt: skip
