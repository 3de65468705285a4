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
from typing import NamedTuple

import numpy as np
from numba import njit

from hevsim.errors import InputError
from hevsim.tables import FloatArray, Table1D, Table2D, interp2, interp2_three, read_meta
from hevsim.units import c_to_k


class PackTables(NamedTuple):
    """A pack's cell tables for compiled code, by name (a swapped array is a name error).

    ``ocv`` [V], ``r_discharge`` and ``r_charge`` [ohm] of one cell over the shared axes
    ``soc`` [-] x ``temperature_k`` [K].
    """

    soc: FloatArray
    temperature_k: FloatArray
    ocv: FloatArray
    r_discharge: FloatArray
    r_charge: FloatArray


@njit(cache=True, inline="always")
def pack_resistance(r_cell_ohm, n_series, n_parallel, r_extra_ohm):
    """Pack series resistance [ohm] of ``n_series`` x ``n_parallel`` cells of ``r_cell_ohm``
    plus the wiring resistance of eq (22) [ohm]."""
    return n_series / n_parallel * r_cell_ohm + r_extra_ohm


@njit(cache=True, inline="always")
def ocv_r_from_tables(soc, temp_k, current_sign, n_s, n_p, r_extra, soc_ax, temp_ax, ocv, r_dis, r_chg):
    """Pack open-circuit voltage [V] and series resistance [ohm] (scalar kernel).

    Cell tables over the shared axes (SOC [-], temperature [K]) as in :class:`PackTables`;
    ``current_sign`` > 0 selects discharge. Compiled loops unpack the tables once.
    """
    ocv_v = n_s * interp2(soc_ax, temp_ax, ocv, soc, temp_k, False)
    rz = r_dis if current_sign > 0 else r_chg
    r = pack_resistance(interp2(soc_ax, temp_ax, rz, soc, temp_k, False), n_s, n_p, r_extra)
    return ocv_v, r


@njit(cache=True, inline="always")
def pack_ocv_r(soc, temp_k, current_sign, n_s, n_p, r_extra, tab):
    """:func:`ocv_r_from_tables` with the pack's :class:`PackTables` (per-step code)."""
    return ocv_r_from_tables(
        soc, temp_k, current_sign, n_s, n_p, r_extra, soc_ax=tab.soc, temp_ax=tab.temperature_k,
        ocv=tab.ocv, r_dis=tab.r_discharge, r_chg=tab.r_charge,
    )  # fmt: skip


@njit(cache=True, inline="always")
def pack_ocv_r_both(soc, temp_k, n_s, n_p, r_extra, tab):
    """(OCV [V], discharge resistance [ohm], charge resistance [ohm]) of the pack at ``soc``
    [-] and ``temp_k`` [K]: :func:`pack_ocv_r` for both current signs, bit for bit, with one
    OCV lookup (a forward step needs both resistances) and one bracketing of the point for the
    three tables (:func:`~hevsim.tables.interp2_three`, inlined: as three calls of
    :func:`~hevsim.tables.interp2` the BEV's compiled run took 1.5-1.7x longer in about half
    of the processes, depending on where its machine code landed in memory)."""
    ocv, r_dis, r_chg = interp2_three(
        tab.soc, tab.temperature_k, tab.ocv, tab.r_discharge, tab.r_charge, soc, temp_k, False
    )
    return n_s * ocv, pack_resistance(r_dis, n_s, n_p, r_extra), pack_resistance(r_chg, n_s, n_p, r_extra)


@njit(cache=True, inline="always")
def charge_current(current_a, coulombic_efficiency):
    """Current [A] that changes the stored charge: the terminal current (discharge > 0),
    times the coulombic efficiency while charging (eq 13)."""
    return current_a if current_a > 0.0 else current_a * coulombic_efficiency


@njit(cache=True)
def soc_rate(current_a, coulombic_efficiency, capacity_as):
    """dSOC/dt [1/s] at current [A] (discharge > 0) for a capacity [A·s], eq (13)."""
    return -charge_current(current_a, coulombic_efficiency) / capacity_as


@njit(cache=True)
def _ocv_r_many(soc, temp_k, current_a, n_s, n_p, r_extra, tab):
    """:func:`pack_ocv_r` over flat arrays of SOC [-], temperature [K] and current [A]
    (its sign picks the resistance) -> (OCV [V], R [ohm])."""
    soc_ax, temp_ax, ocv_z, r_dis, r_chg = tab.soc, tab.temperature_k, tab.ocv, tab.r_discharge, tab.r_charge
    ocv = np.empty(soc.shape[0])
    r = np.empty(soc.shape[0])
    for i in range(soc.shape[0]):
        ocv[i], r[i] = ocv_r_from_tables(
            soc[i], temp_k[i], current_a[i], n_s, n_p, r_extra, soc_ax, temp_ax, ocv_z, r_dis, r_chg
        )
    return ocv, r


@njit(cache=True)
def _current_many(power_w, soc, temp_k, n_s, n_p, r_extra, tab):
    """Discharge-positive current [A] for terminal power [W] over flat arrays: the pack's
    OCV and R (by the sign of the power) and :func:`current_for_power`."""
    soc_ax, temp_ax, ocv_z, r_dis, r_chg = tab.soc, tab.temperature_k, tab.ocv, tab.r_discharge, tab.r_charge
    out = np.empty(power_w.shape[0])
    for i in range(power_w.shape[0]):
        ocv, r = ocv_r_from_tables(
            soc[i], temp_k[i], power_w[i], n_s, n_p, r_extra, soc_ax, temp_ax, ocv_z, r_dis, r_chg
        )
        out[i] = current_for_power(power_w[i], ocv, r)
    return out


@njit(cache=True)
def _soc_rate_many(current_a, coulombic_efficiency, capacity_as):
    """:func:`soc_rate` over a flat array of current [A] -> [1/s]."""
    out = np.empty(current_a.shape[0])
    for i in range(current_a.shape[0]):
        out[i] = soc_rate(current_a[i], coulombic_efficiency, capacity_as)
    return out


def _flat(*arrays: object) -> tuple[tuple[int, ...], list[FloatArray]]:
    """Broadcast arrays, return the shape and contiguous flat float64 copies."""
    b = np.broadcast_arrays(*(np.asarray(a, np.float64) for a in arrays))
    return b[0].shape, [np.ascontiguousarray(x.ravel()) for x in b]


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

    def kernel_tables(self) -> PackTables:
        """The cell tables for compiled code (:class:`PackTables`)."""
        o = self.ocv_cell
        return PackTables(
            soc=o.x, temperature_k=o.y, ocv=o.z, r_discharge=self.r_discharge_cell.z,
            r_charge=self.r_charge_cell.z,
        )  # fmt: skip

    def _ocv_r(self, soc, current_a, temp_k):
        t = self.temperature_k if temp_k is None else temp_k
        shape, (s, tk, i) = _flat(soc, t, current_a)
        ocv, r = _ocv_r_many(s, tk, i, self.n_series, self.n_parallel, self.r_extra_ohm, self.kernel_tables())
        return ocv.reshape(shape), r.reshape(shape)

    def ocv(self, soc, temp_k=None):
        """Pack OCV [V] at SOC [-] and temperature [K] (vectorised)."""
        return self._ocv_r(soc, 1.0, temp_k)[0]

    def resistance(self, soc, current_a, temp_k=None):
        """Pack resistance [ohm] at SOC [-], current [A] (discharge > 0), temperature [K]."""
        return self._ocv_r(soc, current_a, temp_k)[1]

    def current(self, power_w, soc, temp_k=None):
        """Discharge-positive current [A] for terminal power [W] (> 0 discharging), vectorised."""
        t = self.temperature_k if temp_k is None else temp_k
        shape, (p, s, tk) = _flat(power_w, soc, t)
        tab = self.kernel_tables()
        return _current_many(p, s, tk, self.n_series, self.n_parallel, self.r_extra_ohm, tab).reshape(shape)

    def soc_rate(self, current_a):
        """dSOC/dt [1/s] for current [A], eq (13) with coulombic efficiency on charge."""
        shape, (i,) = _flat(current_a)
        cap_as = 3600.0 * self.capacity_ah
        return _soc_rate_many(i, self.coulombic_efficiency, cap_as).reshape(shape)

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
