"""Calibration of cell parameters to test data (issue 4, item 5; thesis section 4.2).

:func:`calibrate` fits chosen parameters (:data:`FITTABLE`) to a test record (time, current,
voltage, temperature) by weighted nonlinear least squares (``scipy.optimize.least_squares``,
bounded), and reports the fitted values with standard errors from the Jacobian, the RMSE of
each signal and the measured-vs-fitted series (with an overlay plot).

Row convention (the same as :class:`hevsim.battery.cell.CellResult`, i.e. the
``timeseries.csv`` that ``hevsim cell`` writes, so a cell's own output is a valid test record):
row k holds step k. ``time_s`` is the end of the step, ``current_a`` the constant current over
the step ``(t_k - dt, t_k]``, and ``voltage_v`` / ``temp_k`` the values at ``t_k``. The initial
state (``soc_initial``, the initial temperature) holds at ``t_0 - dt``, one step before the
first row. A lab record that starts at rest loses nothing by this: its first row is a rest step.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from hevsim.battery import kernel as K
from hevsim.battery.params import CellParameters, load_cell_parameters
from hevsim.errors import InputError
from hevsim.io import atomic_directory, write_json
from hevsim.tables import FloatArray, read_csv_columns

TEST_COLUMNS = ("time_s", "current_a", "voltage_v", "temp_k")
_SCALARS = {**K.TUNABLE_SCALARS, **K.MODEL_SCALARS}
_RC_FIELDS = ("r_ohm", "tau_s", "ea_r_j_per_mol", "ea_tau_j_per_mol")
_RC = re.compile(r"^(rc_discharge|rc_charge)\[(\d+)\]\.(" + "|".join(_RC_FIELDS) + ")$")
FITTABLE = (
    *_SCALARS,
    *(f"{s}[i].{f}" for s in ("rc_discharge", "rc_charge") for f in _RC_FIELDS),
)


@dataclass(frozen=True, eq=False)
class CellTestRecord:
    """A cell test on a uniform step: time [s], current [A, discharge > 0], voltage [V], temperature [K].

    Row k: current over ``(t_k - dt, t_k]``, voltage and temperature at ``t_k`` (module docstring).
    """

    time_s: FloatArray
    current_a: FloatArray
    voltage_v: FloatArray
    temp_k: FloatArray
    source: str = "<in memory>"
    temperature_measured: bool = True

    @property
    def dt_s(self) -> float:
        """Sample step [s]."""
        return float(self.time_s[1] - self.time_s[0])

    @classmethod
    def from_csv(cls, path: str | Path, temperature_k: float | None = None) -> CellTestRecord:
        """Read a test CSV with columns :data:`TEST_COLUMNS`; the step must be uniform (no gaps).

        Without a ``temp_k`` column the record takes the constant ``temperature_k`` [K] (the
        ambient) and is marked ``temperature_measured = False``; with ``temperature_k`` None
        the column is required.
        """
        has_temp = True
        if temperature_k is not None and Path(path).is_file():
            try:
                header = pd.read_csv(path, comment="#", skipinitialspace=True, nrows=0).columns
                has_temp = "temp_k" in [str(c).strip() for c in header]
            except Exception:  # unreadable: read_csv_columns below reports it
                has_temp = True
        names = list(TEST_COLUMNS) if has_temp else list(TEST_COLUMNS[:3])
        data = read_csv_columns(path, names)
        cols = [np.ascontiguousarray(data[c]) for c in names]
        temp = cols[3] if has_temp else np.full(cols[0].shape, float(temperature_k or 0.0))
        return cls(cols[0], cols[1], cols[2], temp, source=str(path), temperature_measured=has_temp)

    def __post_init__(self) -> None:
        t = self.time_s
        if t.size < 3:
            raise InputError(f"{self.source}: a test needs at least 3 samples, got {t.size}.")
        steps = np.diff(t)
        dt = float(np.median(steps))
        bad = np.flatnonzero(np.abs(steps - dt) > 1e-6 * max(dt, 1e-12))
        if dt <= 0 or bad.size:
            k = int(bad[0]) if bad.size else 0
            raise InputError(
                f"{self.source}: column 'time_s' is not uniformly sampled: step {float(steps[k])} s after "
                f"{float(t[k])} s (line {k + 3}) where {dt} s is expected; resample the test or fill the gap."
            )
        for name in TEST_COLUMNS[1:]:
            if getattr(self, name).shape != t.shape:
                raise InputError(f"{self.source}: column '{name}' length differs from 'time_s'.")


@dataclass
class CalibrationResult:
    """Fitted values, standard errors, RMSE per signal, and measured vs fitted series."""

    values: dict[str, float]
    std_errors: dict[str, float]
    rmse: dict[str, float]
    timeseries: pd.DataFrame
    params: CellParameters
    metadata: dict[str, Any] = field(default_factory=dict)

    def plot(self, path: str | Path) -> Path:
        """Overlay plot (voltage and temperature, measured vs fitted) as an image file."""
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        from hevsim.io import save_png

        ts = self.timeseries
        fig, ax = plt.subplots(2, 1, sharex=True, figsize=(8, 6))
        ax[0].plot(ts["time_s"], ts["voltage_measured_v"], ".", ms=2, label="measured")
        ax[0].plot(ts["time_s"], ts["voltage_fitted_v"], "-", label="fitted")
        ax[0].set_ylabel("voltage [V]")
        ax[0].legend()
        ax[1].plot(ts["time_s"], ts["temp_measured_k"] - 273.15, ".", ms=2, label="measured")
        ax[1].plot(ts["time_s"], ts["temp_fitted_k"] - 273.15, "-", label="fitted")
        ax[1].set_ylabel("temperature [°C]")
        ax[1].set_xlabel("time [s]")
        fig.tight_layout()
        out = save_png(fig, path, 100)
        plt.close(fig)
        return out

    def save(self, out_dir: str | Path) -> Path:
        """Write fit.json, timeseries.csv and overlay.png atomically."""
        with atomic_directory(out_dir) as tmp:
            write_json(
                tmp / "fit.json",
                {"values": self.values, "std_errors": self.std_errors, "rmse": self.rmse, **self.metadata},
            )
            self.timeseries.to_csv(tmp / "timeseries.csv", index=False)
            self.plot(tmp / "overlay.png")
        return Path(out_dir)


def _setter(name: str, p: CellParameters) -> tuple[str, int, int]:
    """('scalar', index, 0) or ('rc_discharge' | 'rc_charge', element, column)."""
    if name in _SCALARS:
        return ("scalar", _SCALARS[name], 0)
    m = _RC.match(name)
    if m:
        i = int(m.group(2))
        if i >= p.n_rc:
            raise InputError(
                f"calibrate: parameter {name!r}: the set has {p.n_rc} RC element(s) per direction."
            )
        return (m.group(1), i, _RC_FIELDS.index(m.group(3)))
    raise InputError(f"calibrate: parameter {name!r} is not fittable; expected one of {', '.join(FITTABLE)}.")


def simulate_record(
    p: CellParameters,
    vec: FloatArray,
    rc_d: FloatArray,
    rc_c: FloatArray,
    rec: CellTestRecord,
    port_temp_k: float,
    initial_temp_k: float | None = None,
) -> tuple[FloatArray, FloatArray]:
    """Simulated (voltage [V], temperature [K]) at the record's rows (row k = state after step k,
    step k driven by row k's current; the initial state is one step before row 0)."""
    tabs = list(p.tables())
    if p.n_rc:
        tabs[7], tabs[8] = rc_d, rc_c
    t0 = float(rec.temp_k[0]) if initial_temp_k is None else initial_temp_k
    x = p.initial_state(t0)
    n = rec.time_s.size
    out = np.empty((n, len(K.RECORD)))
    K.run_cell(vec, *tabs, x, rec.current_a, rec.dt_s, np.full(n, port_temp_k), out)  # type: ignore[call-arg]
    return out[:, K.RV], out[:, K.RTEMP]


def calibrate(
    params: CellParameters | str | Path, record: CellTestRecord,
    fit: Mapping[str, tuple[float, float, float]], soc_initial: float = 1.0,
    port_temp_k: float | None = None, weights: Mapping[str, float] | None = None,
    sigma_v: float = 0.01, sigma_t: float = 0.5, initial_temp_k: float | None = None,
) -> CalibrationResult:  # fmt: skip
    """Fit ``fit = {name: (initial, lower, upper)}`` to ``record``.

    Row k's current drives the step that ends at row k, from the initial state (``soc_initial``,
    ``initial_temp_k``) one step before row 0 (module docstring). Residuals are
    ``w_V (V_sim - V)/sigma_v`` and ``w_T (T_sim - T)/sigma_t`` (``weights`` keys
    ``"voltage"``, ``"temperature"``, default 1). ``port_temp_k`` (ambient) and
    ``initial_temp_k`` default to the first measured temperature; give the known ambient
    when the temperature signal is noisy (a noisy first sample biases the thermal fit).
    Standard errors: ``sqrt(diag((JᵀJ)⁻¹) · SSR/(m - n))``.
    """
    from scipy.optimize import least_squares

    p = params if isinstance(params, CellParameters) else load_cell_parameters(params)
    if not fit:
        raise InputError("calibrate: no parameters to fit.")
    w = {"voltage": 1.0, "temperature": 1.0, **(weights or {})}
    unknown = set(w) - {"voltage", "temperature"}
    if unknown:
        raise InputError(f"calibrate: weight(s) {sorted(unknown)} not known; expected voltage, temperature.")
    names = list(fit)
    setters = [_setter(n, p) for n in names]
    x0 = np.array([fit[n][0] for n in names], float)
    lo = np.array([fit[n][1] for n in names], float)
    hi = np.array([fit[n][2] for n in names], float)
    if np.any(lo >= hi) or np.any(x0 < lo) or np.any(x0 > hi):
        raise InputError("calibrate: each parameter needs lower < upper and lower <= initial <= upper.")
    t_port = float(record.temp_k[0]) if port_temp_k is None else port_temp_k
    t_init = t_port if initial_temp_k is None and port_temp_k is not None else initial_temp_k
    base = p.vector(soc_initial)

    def apply(theta: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        vec = base.copy()
        rc_d, rc_c = (
            np.c_[rc, np.zeros((rc.shape[0], 4 - rc.shape[1]))] for rc in (p.rc_discharge, p.rc_charge)
        )
        for (kind, i, j), val in zip(setters, theta, strict=True):
            if kind == "scalar":
                vec[i] = val
            else:
                (rc_d if kind == "rc_discharge" else rc_c)[i, j] = val
        return vec, rc_d, rc_c

    def residuals(theta: FloatArray) -> FloatArray:
        v, t = simulate_record(p, *apply(theta), record, t_port, t_init)
        return np.r_[
            w["voltage"] * (v - record.voltage_v) / sigma_v, w["temperature"] * (t - record.temp_k) / sigma_t
        ]

    sol = least_squares(residuals, x0, bounds=(lo, hi), x_scale="jac")
    m, n = sol.fun.size, len(names)
    ssr = float(sol.fun @ sol.fun)
    try:
        cov = np.linalg.inv(sol.jac.T @ sol.jac) * ssr / max(m - n, 1)
        std = np.sqrt(np.clip(np.diag(cov), 0, None))
    except np.linalg.LinAlgError:
        std = np.full(n, np.nan)
    v, t = simulate_record(p, *apply(sol.x), record, t_port, t_init)
    ts = pd.DataFrame({
        "time_s": record.time_s, "current_a": record.current_a, "voltage_measured_v": record.voltage_v,
        "voltage_fitted_v": v, "temp_measured_k": record.temp_k, "temp_fitted_k": t,
    })  # fmt: skip
    rmse = {
        "voltage_v": float(np.sqrt(np.mean((v - record.voltage_v) ** 2))),
        "temp_k": float(np.sqrt(np.mean((t - record.temp_k) ** 2))),
    }
    meta = {"source": record.source, "cell": p.name, "nfev": int(sol.nfev), "success": bool(sol.success),
            "message": str(sol.message), "port_temp_k": t_port}  # fmt: skip
    return CalibrationResult(
        dict(zip(names, map(float, sol.x), strict=True)), dict(zip(names, map(float, std), strict=True)),
        rmse, ts, p, meta,
    )  # fmt: skip
