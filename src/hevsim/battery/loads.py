"""Loads and battery management for a cell (issue 4, item 4; EES ``Cycling`` and CCCV charger).

* A load profile ("power cycle look-up table"): current [A] or power [W] samples, repeated,
  see :class:`LoadProfile` (and :func:`pulse_train` for high-frequency high-load pulses).
* A CCCV charger: constant current until the terminal voltage reaches ``v_max``, then the
  current that holds the step-average voltage at ``v_max`` exactly, until it falls below
  ``i_end_a``.
* Cycling: the load runs until the terminal voltage falls below ``v_min``; the charger then
  charges (CCCV) and hands back to the load; discharge current is limited to
  ``i_discharge_max_a``.
* A temperature cut-off stops the run (the thesis's tests stop at 80 °C).

All of it runs in one compiled loop (:func:`run_cycling`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pandas as pd
from numba import njit

from hevsim.battery import kernel as K
from hevsim.battery.cell import Cell, CellResult, check_dt
from hevsim.components.battery import current_for_power
from hevsim.errors import InputError
from hevsim.tables import FloatArray, read_csv_columns

MODES = ("load", "charge_cc", "charge_cv", "stopped")
M_LOAD, M_CC, M_CV, M_STOP = range(len(MODES))
STOP_REASONS = ("end of run", "temperature cut-off")


@dataclass(frozen=True, eq=False)
class LoadProfile:
    """Load samples on a uniform step (repeated when the run is longer).

    ``values``: current [A] (``kind="current"``) or terminal power [W] (``kind="power"``),
    discharge positive, one per step of ``dt_s`` [s].
    """

    values: FloatArray
    dt_s: float
    kind: str = "current"

    def __post_init__(self) -> None:
        if self.kind not in ("current", "power"):
            raise InputError(f"load profile kind {self.kind!r} is not known; expected current or power.")
        v = np.asarray(self.values, float)
        if v.ndim != 1 or v.size == 0 or not np.all(np.isfinite(v)):
            raise InputError("load profile: expected a non-empty list of finite values.")
        check_dt(self.dt_s)

    @classmethod
    def from_csv(cls, path: str | Path, dt_s: float, kind: str = "current") -> LoadProfile:
        """Read columns ``time_s`` and ``current_a`` (or ``power_w``) and sample them at ``dt_s``.

        Times must be increasing without gaps longer than 10 x the median sample spacing.
        """
        col = "current_a" if kind == "current" else "power_w"
        data = read_csv_columns(path, ["time_s", col])
        t, y = data["time_s"], data[col]
        if t.size < 2 or np.any(np.diff(t) <= 0):
            raise InputError(f"{path}: column 'time_s' must hold at least two strictly increasing times.")
        gaps = np.diff(t)
        k = int(np.argmax(gaps))
        if gaps[k] > 10 * np.median(gaps):
            raise InputError(
                f"{path}: gap of {gaps[k]} s in 'time_s' after {t[k]} s "
                f"(median spacing {np.median(gaps)} s); "
                "expected evenly sampled data without gaps."
            )
        ts = np.arange(t[0], t[-1], dt_s)
        return cls(np.interp(ts, t, y), dt_s, kind)


def pulse_train(
    high: float,
    low: float,
    period_s: float,
    duty: float,
    duration_s: float,
    dt_s: float,
    kind: str = "current",
) -> LoadProfile:
    """High-frequency high-load pulses: ``high`` for ``duty`` of each period, else ``low``."""
    if not 0.0 < duty < 1.0 or period_s <= 0:
        raise InputError(f"pulse_train: duty {duty!r} must be in (0, 1) and period {period_s!r} s > 0.")
    t = np.arange(round(duration_s / dt_s)) * dt_s
    return LoadProfile(np.where((t % period_s) < duty * period_s, high, low), dt_s, kind)


@njit(cache=True)
def run_cycling(
    prm,
    soc_ax,
    t_ax,
    ocv_c,
    ocv_d,
    rs_c,
    rs_d,
    capf,
    rc_d,
    rc_c,
    x,
    load,
    is_power,
    n_steps,
    dt,
    t_port,
    v_min,
    v_max,
    i_chg,
    i_dis_max,
    i_end,
    t_cut,
    start_mode,
    out,
):
    """Cycle a cell: load until V < v_min, CCCV charge to v_max until ``|I| < i_end``, repeat.

    ``out[k]`` = (current [A], voltage [V], average voltage [V], SOC, temperature [K], mode).
    Returns (steps done, stop reason index).
    """
    rec = np.empty(len(K.RECORD))
    mode = start_mode
    n_load = load.shape[0]
    for k in range(n_steps):
        if mode == M_LOAD:
            demand = load[k % n_load]
            if is_power:
                d = 1.0 if demand > 0.0 else -1.0
                e, z = K.branch_affine(
                    prm, soc_ax, t_ax, ocv_c, ocv_d, rs_c, rs_d, capf, rc_d, rc_c, x, dt, d
                )
                i = current_for_power(demand, e, z)
            else:
                i = demand
            i = min(max(i, -i_chg), i_dis_max)
        else:
            e, z = K.branch_affine(prm, soc_ax, t_ax, ocv_c, ocv_d, rs_c, rs_d, capf, rc_d, rc_c, x, dt, -1.0)
            i_cv = (e - v_max) / z
            i = min(max(-i_chg, i_cv), 0.0)
            mode = M_CV if i_cv > -i_chg else M_CC
        K.cell_step(prm, soc_ax, t_ax, ocv_c, ocv_d, rs_c, rs_d, capf, rc_d, rc_c, x, i, dt, t_port, rec)
        out[k, 0] = i
        out[k, 1] = rec[K.RV]
        out[k, 2] = rec[K.RVAVG]
        out[k, 3] = rec[K.RSOC]
        out[k, 4] = rec[K.RTEMP]
        out[k, 5] = mode
        if rec[K.RTEMP] >= t_cut:
            return k + 1, 1
        if mode == M_LOAD and rec[K.RV] < v_min:
            mode = M_CC
        elif mode == M_CV and -i <= i_end:
            mode = M_LOAD
    return n_steps, 0


def cycle_cell(
    cell: Cell,
    load: LoadProfile,
    duration_s: float,
    v_min: float,
    v_max: float,
    i_charge_a: float,
    i_end_a: float,
    i_discharge_max_a: float = np.inf,
    port_temperature: float = 298.15,
    temp_cutoff_k: float = np.inf,
    start_with: str = "load",
) -> CellResult:
    """Run the EES-style cycling of ``cell`` (its state advances); returns a :class:`CellResult`.

    ``start_with``: ``"load"`` or ``"charge"``. Columns: time_s, current_a, voltage_v,
    voltage_avg_v, soc, temp_k, mode (:data:`MODES`); metrics include ``stop_reason``
    (0 end of run, 1 temperature cut-off) and ``stop_time_s``.
    """
    t0 = time.perf_counter()
    if start_with not in ("load", "charge"):
        raise InputError(f"start_with {start_with!r} is not known; expected load or charge.")
    if not v_min < v_max:
        raise InputError(f"cycling: v_min {v_min!r} V must be below v_max {v_max!r} V.")
    if not (i_charge_a > 0 and i_end_a > 0 and i_discharge_max_a > 0):
        raise InputError("cycling: i_charge_a, i_end_a and i_discharge_max_a must be > 0 A.")
    dt = load.dt_s
    n = round(duration_s / dt)
    out = np.zeros((n, 6))
    x = cell.state
    tabs = cell.params.tables()
    done, reason = run_cycling(  # type: ignore[call-arg]
        cell.p,
        *tabs,
        x,
        np.asarray(load.values, float),
        load.kind == "power",
        n,
        dt,
        port_temperature,
        v_min,
        v_max,
        i_charge_a,
        i_discharge_max_a,
        i_end_a,
        temp_cutoff_k,
        M_LOAD if start_with == "load" else M_CC,
        out,
    )
    out = out[:done]
    ts = pd.DataFrame(
        {
            "time_s": dt * np.arange(1, done + 1),
            "current_a": out[:, 0],
            "voltage_v": out[:, 1],
            "voltage_avg_v": out[:, 2],
            "soc": out[:, 3],
            "temp_k": out[:, 4],
            "mode": np.array(MODES)[out[:, 5].astype(int)],
        }
    )
    modes = out[:, 5].astype(int)
    metrics = {
        "stop_reason": float(reason),
        "stop_time_s": float(done * dt),
        "charges_started": float(np.sum((modes[1:] != M_LOAD) & (modes[:-1] == M_LOAD))),
        "max_temp_k": float(out[:, 4].max()) if done else float(x[K.STEMP]),
        "min_voltage_v": float(out[:, 1].min()) if done else float("nan"),
        "max_voltage_v": float(out[:, 1].max()) if done else float("nan"),
    }
    meta = {
        "cell": cell.params.name,
        "stop_reason": STOP_REASONS[reason],
        "elapsed_s": time.perf_counter() - t0,
    }
    return CellResult(ts, metrics, meta, x.copy())


def profile_from_array(values: npt.ArrayLike, dt_s: float, kind: str = "current") -> LoadProfile:
    """A :class:`LoadProfile` from an array."""
    return LoadProfile(np.ascontiguousarray(np.asarray(values, float)), dt_s, kind)
