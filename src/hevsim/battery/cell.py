"""Cell object and its simulation result (thin layer over :mod:`hevsim.battery.kernel`)."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from hevsim.battery import kernel as K
from hevsim.battery.params import CellParameters, load_cell_parameters
from hevsim.errors import DomainError, InputError
from hevsim.io import atomic_directory, write_json
from hevsim.tables import FloatArray


def as_profile(values: npt.ArrayLike, n: int, what: str, unit: str) -> FloatArray:
    """A per-step array of length ``n`` from a scalar or an array (checked finite)."""
    a = np.asarray(values, dtype=float)
    if a.ndim == 0:
        a = np.full(n, float(a))
    if a.shape != (n,):
        raise InputError(f"{what}: expected a scalar or {n} values [{unit}], got shape {a.shape}.")
    if not np.all(np.isfinite(a)):
        k = int(np.flatnonzero(~np.isfinite(a))[0])
        raise InputError(f"{what}: value {a[k]:g} at step {k} is not finite; expected numbers [{unit}].")
    return np.ascontiguousarray(a)


def check_dt(dt: float) -> float:
    """A positive finite step [s]."""
    if not (np.isfinite(dt) and dt > 0):
        raise InputError(f"time step dt = {dt:g} s: expected a positive number of seconds.")
    return float(dt)


CELL_TEMP_RANGE_K = (150.0, 500.0)
"""Temperatures the lumped cell model is defined for [K] (the range accepted for
``cell.temp_k`` and ``thermal.port_temp_k`` in a cell configuration). Beyond 500 K a
Li-ion cell is in thermal runaway; the model's tables and eq (35) mean nothing there."""

SOC_TOLERANCE = 1e-6
"""How far a state of charge may stray outside [0, 1] before a run stops [-]. Covers the
round-off of the charge integral, not a battery run dry: a cell (or a vehicle's pack) below
0 or above 1 is a physically impossible state. Shared by every command that steps a battery
(:func:`check_cell_domain`, :func:`hevsim.sim.checks.check_domain`)."""


def soc_outside(soc: npt.ArrayLike) -> tuple[int, int] | None:
    """The first (row, column) where ``soc`` (a per-step vector, or per step and cell) is
    outside [0, 1] by more than :data:`SOC_TOLERANCE` (NaN counts as outside), or None."""
    a = np.asarray(soc, dtype=float)
    a2 = a.reshape(a.shape[0], -1) if a.ndim else a.reshape(1, 1)
    bad = ~((a2 >= -SOC_TOLERANCE) & (a2 <= 1.0 + SOC_TOLERANCE))
    if not bad.any():
        return None
    row = int(np.flatnonzero(bad.any(axis=1))[0])
    return row, int(np.flatnonzero(bad[row])[0])


def check_cell_domain(
    what: str,
    time_s: npt.NDArray[Any],
    current_a: npt.NDArray[Any],
    voltage_v: npt.NDArray[Any],
    temp_k: npt.NDArray[Any],
    capacity_c: npt.NDArray[Any] | None = None,
    short_circuit_a: npt.NDArray[Any] | None = None,
    soc: npt.NDArray[Any] | None = None,
    cell_names: Any = None,
    remedy: str | None = None,
) -> None:
    """Raise :class:`DomainError` at the first step where a cell left its model's domain.

    The one domain check of every command that steps a battery (cell, module, pack, the
    pack in a vehicle, co-simulation participants and the Python FMUs). The domain: every
    recorded value finite, state of charge in [0, 1] (:data:`SOC_TOLERANCE`), terminal
    voltage > 0 V (a cell is a source: at or below 0 V the current exceeds its
    short-circuit current OCV / R_s), temperature in :data:`CELL_TEMP_RANGE_K` and capacity
    (eq 35) > 0. Arguments are per step (row): times [s], currents [A], terminal voltages
    [V], temperatures [K] and SOCs [-] (one column per cell for a module or pack; the
    message names the cell as ``cell_names[column]``, default "cell <column>"), capacities
    [C] and OCV / R_s [A] when known; ``remedy`` replaces the advice of a SOC message.
    """
    t_lo, t_hi = CELL_TEMP_RANGE_K
    temps = temp_k.reshape(temp_k.shape[0], -1)
    socs = np.zeros((time_s.size, 1)) if soc is None else np.asarray(soc, float).reshape(time_s.size, -1)
    cap = np.ones(time_s.size) if capacity_c is None else capacity_c
    hot = (temps < t_lo) | (temps > t_hi)
    soc_bad = ~((socs >= -SOC_TOLERANCE) & (socs <= 1.0 + SOC_TOLERANCE))
    checks = (
        (
            ~np.isfinite(voltage_v) | ~np.isfinite(temps).all(axis=1) | ~np.isfinite(cap)
            | ~np.isfinite(socs).all(axis=1),
            "a state is not finite",
        ),
        (voltage_v <= 0.0, "terminal voltage {v:g} V <= 0"),
        (hot.any(axis=1), f"{{cell}}temperature {{T:g}} K outside {t_lo:g}..{t_hi:g} K"),
        (soc_bad.any(axis=1), "{cell}state of charge {s:.6g} outside [0, 1]"),
        (cap <= 0.0, "capacity {C:g} C <= 0 (eq 35)"),
    )  # fmt: skip
    first = [(int(np.flatnonzero(mask)[0]), j, text) for j, (mask, text) in enumerate(checks) if mask.any()]
    if not first:
        return
    k, j, text = min(first)
    multi = temps.shape[1] > 1 or socs.shape[1] > 1
    col = int(np.flatnonzero(soc_bad[k])[0]) if j == 3 else int(np.flatnonzero(hot[k])[0]) if j == 2 else 0
    name = (cell_names[col] if cell_names is not None else f"cell {col}") if multi else ""
    bad_t = temps[k][hot[k]] if hot[k].any() else temps[k]
    fault = text.format(
        v=float(voltage_v[k]), T=float(bad_t[0]), C=float(cap[k]), s=float(socs[k, col]),
        cell=f"{name}: " if name else "",
    )  # fmt: skip
    if j == 3:  # a cell run empty (or overfilled): the current is the cause, not the model
        raise DomainError(
            f"{what}: at t = {float(time_s[k]):g} s with a current of {float(current_a[k]):g} A the "
            f"cell left its model's domain: {fault}: the "
            f"{'current drained the cell' if socs[k, col] < 0 else 'current overcharged the cell'}; "
            + (remedy or "lower the current (or its scale) or the duration, or start at another SOC.")
        )
    limit = (
        f"a current below the short-circuit current OCV/R_s = {float(short_circuit_a[k]):.4g} A at that state"
        if short_circuit_a is not None
        else "a current below the cells' short-circuit current OCV/R_s"
    )
    raise DomainError(
        f"{what}: at t = {float(time_s[k]):g} s with a current of {float(current_a[k]):g} A the "
        f"cell left its model's domain: {fault}. The model holds for a positive terminal "
        f"voltage, i.e. {limit}, and {t_lo:g}..{t_hi:g} K; reduce the current (or its scale) "
        "or the duration."
    )


@dataclass
class CellResult:
    """Time series (``timeseries``, columns with units), scalar ``metrics`` and ``metadata``.

    Row k holds step k: ``time_s`` is the end of the step; the current is the step's;
    voltages, SOC and temperature are at the end of the step; heat flows are step averages.
    """

    timeseries: pd.DataFrame
    metrics: dict[str, float]
    metadata: dict[str, Any] = field(default_factory=dict)
    final_state: FloatArray = field(default_factory=lambda: np.zeros(0))

    def save(self, out_dir: str | Path) -> Path:
        """Write ``timeseries.csv``, ``metrics.json`` and ``metadata.json`` atomically."""
        with atomic_directory(out_dir) as tmp:
            self.timeseries.to_csv(tmp / "timeseries.csv", index=False)
            write_json(tmp / "metrics.json", self.metrics)
            write_json(tmp / "metadata.json", self.metadata)
        return Path(out_dir)


class Cell:
    """An electro-thermal cell (thesis eqs 33-41) with its current state.

    Args:
        params: a :class:`CellParameters` or the name/path of a parameter file.
        soc_initial: SOC_ini [-] of eq (37).
        temp_k: initial core temperature [K].
        q_ini_c: initial transferred charge Q_ini [C] (eqs 34, 39).
    """

    def __init__(
        self,
        params: CellParameters | str | Path,
        soc_initial: float = 1.0,
        temp_k: float = 298.15,
        q_ini_c: float = 0.0,
    ) -> None:
        self.params = params if isinstance(params, CellParameters) else load_cell_parameters(params)
        if not 0.0 <= soc_initial <= 1.0:
            raise InputError(f"cell {self.params.name}: soc_initial {soc_initial!r} must be between 0 and 1.")
        if not temp_k > 0:
            raise InputError(f"cell {self.params.name}: temp_k {temp_k!r} K must be > 0.")
        if q_ini_c < 0:
            raise InputError(f"cell {self.params.name}: q_ini_c {q_ini_c!r} C must be >= 0.")
        self.soc_initial = float(soc_initial)
        self.state = self.params.initial_state(temp_k, q_ini_c)
        self.p = self.params.vector(self.soc_initial)

    @property
    def soc(self) -> float:
        """Current SOC [-] (eq 37)."""
        t = self.params.temperature_k
        cap = K.cell_capacity(
            self.p, t, self.params.capacity_factor, self.state[K.SQABS], self.state[K.STEMP]
        )
        return float(self.soc_initial - self.state[K.SQ] / cap)

    def stored_energy_j(self) -> float:
        """Energy in the RC capacitors [J]."""
        tabs = self.params.tables()
        return float(K.rc_energy(self.p, tabs[7], tabs[8], self.state))

    def simulate(
        self,
        current_profile: npt.ArrayLike,
        dt: float,
        port_temperature: npt.ArrayLike = 298.15,
        advance: bool = True,
    ) -> CellResult:
        """Simulate the cell over ``current_profile`` [A] (discharge > 0), one value per step.

        ``dt`` [s] is the step; ``port_temperature`` [K] is a scalar or one value per step.
        The cell's state advances (unless ``advance`` is false). Returns a :class:`CellResult`.
        """
        t0 = time.perf_counter()
        dt = check_dt(dt)
        i = np.asarray(current_profile, dtype=float)
        if i.ndim != 1 or i.size == 0:
            raise InputError(f"current_profile: expected a non-empty 1-D array [A], got shape {i.shape}.")
        i = as_profile(i, i.size, "current_profile", "A")
        tp = as_profile(port_temperature, i.size, "port_temperature", "K")
        self.params.check_temperature_coverage(np.r_[tp, self.state[K.STEMP]], "the port temperature")
        x = self.state.copy()
        e_rc0 = self.stored_energy_j()
        out = np.empty((i.size, len(K.RECORD)))
        tabs = self.params.tables()
        K.run_cell(self.p, *tabs, x, i, dt, tp, out)  # type: ignore[call-arg]
        with np.errstate(divide="ignore", invalid="ignore"):
            i_short = out[:, K.ROCV] / out[:, K.RRS]
        check_cell_domain(
            f"cell {self.params.name}",
            dt * np.arange(1, i.size + 1),
            i,
            out[:, K.RV],
            out[:, K.RTEMP],
            out[:, K.RCAP],
            i_short,
            soc=out[:, K.RSOC],
        )
        e_rc1 = float(K.rc_energy(self.p, tabs[7], tabs[8], x))
        if advance:
            self.state = x
        elapsed = time.perf_counter() - t0
        ts = pd.DataFrame({"time_s": dt * np.arange(1, i.size + 1), "current_a": i, "port_temp_k": tp})
        for j, name in enumerate(K.RECORD):
            if not name.startswith("e_"):
                ts[name] = out[:, j]
        ts["q_c"] = np.cumsum(i) * dt + (x[K.SQ] - i.sum() * dt)
        ts["qabs_c"] = np.cumsum(np.abs(i)) * dt + (x[K.SQABS] - np.abs(i).sum() * dt)
        e = out[:, [K.REEL, K.RECH, K.REHEAT, K.REPORT]].sum(axis=0)
        metrics = {
            "duration_s": float(i.size * dt),
            "charge_out_c": float(i.sum() * dt),
            "electrical_energy_out_j": float(e[0]),
            "chemical_energy_change_j": float(e[1]),
            "heat_j": float(e[2]),
            "heat_to_port_j": float(e[3]),
            "rc_energy_change_j": e_rc1 - e_rc0,
            "energy_balance_residual_j": float(e[0] + e[1] + e[2] + (e_rc1 - e_rc0)),
            "min_voltage_v": float(out[:, K.RV].min()),
            "max_voltage_v": float(out[:, K.RV].max()),
            "max_temp_k": float(out[:, K.RTEMP].max()),
            "final_soc": float(out[-1, K.RSOC]),
            "final_cycles": float(x[K.SCYC]),
            "final_qabs_c": float(x[K.SQABS]),
        }
        meta = {
            "cell": self.params.name,
            "parameters_source": self.params.source,
            "dt_s": dt,
            "soc_initial": self.soc_initial,
            "elapsed_s": elapsed,
        }
        return CellResult(ts, metrics, meta, x)
