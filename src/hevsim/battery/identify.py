"""End-to-end cell identification from a pulse / HPPC test (issue 14; ``hevsim calibrate``
without ``--fit``).

Order of the steps (each feeds the next as its initial guess):

1. **OCV(SOC) from the rests.** SOC by coulomb counting from ``soc_initial`` and the capacity
   of the base set; every rest (``|i| <= rest_band_a`` for at least ``min_rest_s``) gives one
   OCV point, extrapolated to full relaxation with ``V(t) = OCV - d exp(-t/tau)`` fitted to the
   rest's last three quarters (the correction is capped at the voltage change over that part).
2. **R_s(SOC) from the instantaneous steps**: ``-dV/dI`` over one sample at every current step.
3. **Least squares** on the voltage (``scipy.optimize.least_squares``): the OCV and R_s
   values at the tested SOC breakpoints, ``n_rc`` persistent RC pairs (same in both
   directions), and the Butler-Volmer charge-transfer term (``i0``, ``scale``); the model
   options are ``rc_mode = "persistent"`` and ``ocv_mode = "step_consistent"``. The Jacobian
   is analytic: the kernel's forward sensitivities
   (:func:`hevsim.battery.kernel.run_cell_sensitivity`, one extended run instead of one run
   per parameter) mapped through the table construction by the chain rule.
4. **Thermal**: the heat capacity and skin resistance on the temperature, with the electrical
   parameters fixed.
5. Optionally (:func:`fit_temperature`, ``hevsim calibrate --data``): R0(SOC, T) and an
   Arrhenius activation energy from tests at other ambients.

Every fitted parameter is reported with its standard error and 95 % interval (from the
Jacobian at the optimum; log-parameters give asymmetric intervals) and flagged when the test
cannot identify it: a time constant longer than the longest constant-current segment, a
correlation above 0.95 with another parameter together with a relative standard error above
10 % (a strong correlation alone is noted, not flagged), a value at a bound, or a standard
error larger than the value. The result writes a complete parameter set (``cell.toml``, loadable by
``hevsim cell``, the module, the FMU export and the vehicle's ``battery.model = "cell"``) with
its provenance, the tables as CSV, the parameter table with intervals and flags, and plots.
"""

from __future__ import annotations

import dataclasses
import datetime
import hashlib
import itertools
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from hevsim.battery import kernel as K
from hevsim.battery.calibrate import CellTestRecord
from hevsim.battery.params import (
    CapacitySection,
    CellParameters,
    ChargeTransferSection,
    ModelSection,
    ThermalSection,
    load_cell_parameters,
)
from hevsim.errors import InputError
from hevsim.io import atomic_directory, write_json
from hevsim.tables import FloatArray
from hevsim.threads import choose_threads

FIDELITY_MODEL = ModelSection(rc_mode="persistent", ocv_mode="step_consistent")
"""The model structure :func:`identify` fits by default (issue 14)."""
CORRELATION_LIMIT = 0.95
"""|correlation| above which two fitted parameters are flagged as not separable."""
RELATIVE_ERROR_LIMIT = 0.1
"""Relative standard error above which a strongly correlated parameter is flagged (below it the
correlation is only noted: the test separates the pair well enough)."""
CURRENT_BINS_C = (0.0, 0.5, 1.0, 2.0, 3.0, np.inf)
"""Current ranges [C-rate] of the validation error table: closed on the right, the first from
0 (``0-0.5C`` = [0, 0.5], ``0.5-1C`` = (0.5, 1], ..., ``>3C``), the bounds with a relative
tolerance of 1e-9 (a drive cycle scaled to a 3C peak has its peak in ``2-3C``, whatever the
rounding of current / capacity)."""


@dataclass
class Identification:
    """Result of :func:`identify`: the parameter set, the parameter table and the fits."""

    params: CellParameters
    parameters: pd.DataFrame
    rmse: dict[str, float]
    timeseries: pd.DataFrame
    validation: pd.DataFrame | None = None
    validation_errors: pd.DataFrame | None = None
    metadata: dict[str, Any] = field(default_factory=dict)
    r0_temperature: pd.DataFrame | None = None
    """R0 per (SOC, ambient) from the instantaneous steps (:func:`fit_temperature`)."""

    def flagged(self) -> pd.DataFrame:
        """Rows of the parameter table the test cannot identify."""
        return self.parameters[self.parameters["flag"] != ""]

    def save(self, out_dir: str | Path, force: bool = False) -> Path:
        """Write cell.toml, tables.csv, parameters.csv, fit.json, timeseries.csv, fit.png (and
        validation.csv, validation_errors.csv, validation.png; r0_temperature.csv) atomically."""
        with atomic_directory(out_dir, force=force) as tmp:
            (tmp / "cell.toml").write_text(parameter_toml(self.params, self.metadata))
            table_frame(self.params).to_csv(tmp / "tables.csv", index=False)
            self.parameters.to_csv(tmp / "parameters.csv", index=False)
            write_json(
                tmp / "fit.json",
                {
                    "rmse": self.rmse,
                    "parameters": self.parameters.to_dict(orient="records"),
                    **self.metadata,
                },
            )
            self.timeseries.to_csv(tmp / "timeseries.csv", index=False)
            plot_fit(self.timeseries, tmp / "fit.png", "calibration")
            if self.validation is not None and self.validation_errors is not None:
                self.validation.to_csv(tmp / "validation.csv", index=False)
                self.validation_errors.to_csv(tmp / "validation_errors.csv", index=False)
                plot_fit(self.validation, tmp / "validation.png", "validation")
            if self.r0_temperature is not None:
                self.r0_temperature.to_csv(tmp / "r0_temperature.csv", index=False)
        return Path(out_dir)


# --- steps 1 and 2 ----------------------------------------------------------------------------


def coulomb_soc(rec: CellTestRecord, soc_initial: float, capacity_c: float) -> FloatArray:
    """SOC [-] at each row (end of the row's step) by coulomb counting."""
    return soc_initial - np.cumsum(rec.current_a) * rec.dt_s / capacity_c


def find_rests(rec: CellTestRecord, band_a: float, min_rest_s: float) -> list[tuple[int, int]]:
    """Row ranges ``(first, last)`` (inclusive) of rests: ``|i| <= band_a`` for ``>= min_rest_s``."""
    still = np.abs(rec.current_a) <= band_a
    out = []
    k = 0
    n = still.size
    while k < n:
        if still[k]:
            j = k
            while j + 1 < n and still[j + 1]:
                j += 1
            if (j - k + 1) * rec.dt_s >= min_rest_s:
                out.append((k, j))
            k = j + 1
        else:
            k += 1
    return out


def relaxed_voltage(t_s: FloatArray, v: FloatArray) -> float:
    """Fully relaxed voltage [V] of a rest: ``OCV - d exp(-t/tau)`` fitted over the last three
    quarters (tau on a log grid, 5 s to 10x the rest); the step from the last sample is capped
    at the voltage change over the fitted part."""
    a = v.size // 4
    t, y = t_s[a:] - t_s[a], v[a:]
    best = (np.inf, float(y[-1]))
    for tau in np.geomspace(5.0, 10.0 * max(t[-1], 1.0), 60):
        basis = np.c_[np.ones_like(t), np.exp(-t / tau)]
        coef, *_ = np.linalg.lstsq(basis, y, rcond=None)
        ssr = float(np.sum((basis @ coef - y) ** 2))
        if ssr < best[0]:
            best = (ssr, float(coef[0]))
    cap = abs(float(y[-1] - y[0]))
    return float(y[-1] + np.clip(best[1] - y[-1], -cap, cap))


def ocv_points(
    rec: CellTestRecord, soc: FloatArray, rests: list[tuple[int, int]]
) -> tuple[FloatArray, FloatArray]:
    """(SOC [-], relaxed OCV [V]) per rest, merged where the SOC is within 0.01."""
    pts = sorted(
        (float(soc[j]), relaxed_voltage(rec.time_s[k : j + 1], rec.voltage_v[k : j + 1])) for k, j in rests
    )
    s_out: list[float] = []
    v_out: list[list[float]] = []
    for s, v in pts:
        if s_out and s - s_out[-1] < 0.01:
            v_out[-1].append(v)
        else:
            s_out.append(s)
            v_out.append([v])
    return np.array(s_out), np.array([float(np.mean(v)) for v in v_out])


def _steps(rec: CellTestRecord, min_step_a: float) -> tuple[np.ndarray, FloatArray]:
    """Rows ``k`` (the last row before the step) and resistances [ohm] ``-dV/dI`` over one
    sample of every current step larger than ``min_step_a`` [A] (positive ones only)."""
    di = np.diff(rec.current_a)
    dv = np.diff(rec.voltage_v)
    k = np.flatnonzero(np.abs(di) >= min_step_a)
    r = -dv[k] / di[k]
    ok = r > 0
    return k[ok], r[ok]


def step_resistances(
    rec: CellTestRecord, soc: FloatArray, min_step_a: float
) -> tuple[FloatArray, FloatArray]:
    """(SOC [-], resistance [ohm]) of every current step larger than ``min_step_a``: ``-dV/dI``
    over one sample."""
    k, r = _steps(rec, min_step_a)
    return soc[k], r


def step_charge_transfer(
    rec: CellTestRecord, soc: FloatArray, axis: FloatArray, min_step_a: float, temp_k: float
) -> tuple[FloatArray, float, float] | None:
    """Initial R_s [ohm] per SOC breakpoint and Butler-Volmer ``(i0 [A], scale [-])`` from the
    steps out of rest: ``-dV/dI = R_s(SOC) + scale (2RT/F) asinh(|I| / (2 i0)) / |I|``, linear
    in (R_s, scale) for a given ``i0``, which is searched on a grid. None without steps of
    different sizes (the curvature cannot be seen)."""
    i, v = rec.current_a, rec.voltage_v
    di = np.diff(i)
    still = np.abs(i) <= 1e-3 * min_step_a
    k = np.flatnonzero((np.abs(di) >= min_step_a) & still[:-1] & np.r_[False, still[:-2]])
    if k.size == 0:
        return None
    amp = np.abs(i[k + 1])
    # the voltage step, less the relaxation still under way (the slope of the sample before)
    r = -((v[k + 1] - v[k]) - (v[k] - v[k - 1])) / di[k]
    if np.ptp(amp) < 0.2 * amp.max():
        return None
    near = np.argmin(np.abs(soc[k][:, None] - axis[None, :]), axis=1)
    cols = np.unique(near)
    b_unit = 2.0 * K.R_GAS_J_PER_MOL_K * temp_k / K.FARADAY_C_PER_MOL
    best: tuple[float, FloatArray, float, float] | None = None
    for i0 in np.geomspace(0.002 * amp.max(), 20.0 * amp.max(), 100):
        a = np.zeros((k.size, cols.size + 1))
        a[np.arange(k.size), np.searchsorted(cols, near)] = 1.0
        a[:, -1] = b_unit * np.arcsinh(amp / (2.0 * i0)) / amp
        coef, *_ = np.linalg.lstsq(a, r, rcond=None)
        if coef[-1] <= 0 or np.any(coef[:-1] <= 0):
            continue
        ssr = float(np.sum((a @ coef - r) ** 2))
        if best is None or ssr < best[0]:
            best = (ssr, np.asarray(coef[:-1], dtype=float), float(i0), float(coef[-1]))
    if best is None:
        return None
    rs = np.interp(axis, axis[cols], best[1])
    return rs, best[2], best[3]


# --- step 3 and 4: least squares --------------------------------------------------------------


@dataclass(frozen=True)
class _Param:
    name: str
    unit: str
    log: bool
    lo: float
    hi: float


def _simulate(p: CellParameters, rec: CellTestRecord, soc_initial: float, port_k: float, t0_k: float):
    vec = p.vector(soc_initial)
    x = p.initial_state(t0_k)
    n = rec.time_s.size
    out = np.empty((n, len(K.RECORD)))
    K.run_cell(vec, *p.tables(), x, rec.current_a, rec.dt_s, np.full(n, port_k), out)  # type: ignore[call-arg]
    return out[:, K.RV], out[:, K.RTEMP]


def _sensitivities(
    p: CellParameters, rec: CellTestRecord, soc_initial: float, port_k: float
) -> tuple[FloatArray, FloatArray]:
    """d voltage / d p [V per unit] and d temperature / d p [K per unit] per row for the
    parameters of :func:`hevsim.battery.kernel.sensitivity_columns` (the structure
    :func:`identify` fits: persistent RC, one temperature column, equal directions)."""
    n = rec.time_s.size
    cols = K.sensitivity_columns(p.soc.size, p.n_rc)
    dv = np.empty((n, int(cols["n"])))
    dtemp = np.empty_like(dv)
    out = np.empty((n, len(K.RECORD)))
    rc = p.rc_discharge if p.n_rc else np.ones((1, 2))
    K.run_cell_sensitivity(
        p.vector(soc_initial),
        p.soc,
        p.temperature_k,
        p.ocv_discharge_v,
        p.rs_discharge_ohm,
        p.capacity_factor,
        rc,
        p.initial_state(port_k),
        rec.current_a,
        rec.dt_s,
        np.full(n, port_k),
        out,
        dv,
        dtemp,
    )
    return dv, dtemp


class _OcvMap:
    """The OCV table [V] on ``axis`` from the fitted values at the tested breakpoints ``idx``,
    and its Jacobian (piecewise linear): the tested values replace the initial guess, the
    ends outside the tested range follow the end segments (``extrapolate``), the table is
    clipped to the voltage limits and made non-decreasing."""

    def __init__(
        self,
        init: FloatArray,
        idx: np.ndarray,
        axis: FloatArray,
        v_min: float,
        v_max: float,
        extrapolate: bool,
    ) -> None:
        self.init, self.idx, self.axis = init, idx, axis
        self.v_min, self.v_max, self.extrapolate = v_min, v_max, extrapolate

    def _clip_rise(self, v: FloatArray, g: FloatArray) -> tuple[FloatArray, FloatArray]:
        c = np.clip(v, self.v_min, self.v_max)
        g = np.where((c != v)[:, None], 0.0, g)
        best = 0
        for k in range(c.size):  # running maximum: a row takes the gradient of its maximum
            if c[k] >= c[best]:
                best = k
            g[k] = g[best]
        return np.maximum.accumulate(c), g

    def __call__(self, theta: FloatArray) -> tuple[FloatArray, FloatArray]:
        """(table [V], d table / d theta [-])."""
        idx, ax = self.idx, self.axis
        v = self.init.copy()
        v[idx] = theta
        g = np.zeros((v.size, idx.size))
        g[idx, np.arange(idx.size)] = 1.0
        v, g = self._clip_rise(v, g)
        lo_i, hi_i = idx[0], idx[-1]
        if self.extrapolate and lo_i + 1 <= hi_i:  # keep the extrapolated ends on the end segments
            for end, nxt, sel in (
                (lo_i, lo_i + 1, slice(None, lo_i)),
                (hi_i, hi_i - 1, slice(hi_i + 1, None)),
            ):
                d_ax = ax[nxt] - ax[end]
                slope, g_slope = (v[nxt] - v[end]) / d_ax, (g[nxt] - g[end]) / d_ax
                off = ax[sel] - ax[end]
                v[sel] = v[end] + slope * off
                g[sel] = g[end] + off[:, None] * g_slope
            v, g = self._clip_rise(v, g)
        return v, g


REST_KEEP_S = 300.0
"""Rows of a rest kept one by one [s] from its start (:func:`_row_selection`)."""
REST_THIN = 10
"""Beyond :data:`REST_KEEP_S` into a rest, one row in this many is kept (:func:`_row_selection`)."""


def _row_selection(
    rec: CellTestRecord, keep_s: float = REST_KEEP_S, thin: int = REST_THIN
) -> tuple[np.ndarray, FloatArray]:
    """Rows of ``rec`` the least squares weighs and their weights [-] (multiplying the
    residual): every row under current and the first ``keep_s`` [s] of each rest one by one;
    later in a rest (a slow, smooth relaxation) one row in ``thin`` with weight sqrt(``thin``),
    so the sum of squares stands for the rows it skips. The simulation still runs every step;
    only the fit's residual and Jacobian rows are thinned (the trust-region SVDs and the
    Jacobian's chain rule scale with the rows). ``thin`` = 1 keeps every row."""
    n = rec.time_s.size
    if thin <= 1:
        return np.arange(n), np.ones(n)
    band = 1e-3 * max(float(np.max(np.abs(rec.current_a))), 1e-12)
    still = np.abs(rec.current_a) <= band
    # rows since the rest began, counting its first row as 1 (0 under current)
    k = np.arange(n)
    start = still & ~np.r_[False, still[:-1]]
    run = np.where(still, k - np.maximum.accumulate(np.where(start, k, 0)) + 1, 0)
    late = run * rec.dt_s > keep_s
    keep = ~late | ((run % thin) == 0)
    rows = np.flatnonzero(keep)
    w = np.where(late[rows], np.sqrt(thin), 1.0)
    return rows, w


def _longest_segment_s(rec: CellTestRecord) -> float:
    """Longest run of (nearly) constant current [s]."""
    i = rec.current_a
    tol = 1e-3 * max(float(np.max(np.abs(i))), 1e-9)
    change = np.flatnonzero(np.abs(np.diff(i)) > tol)
    edges = np.r_[-1, change, i.size - 1]
    return float(np.max(np.diff(edges)) * rec.dt_s)


def _stats(
    sol: Any, specs: list[_Param], longest_s: float, weights: FloatArray | None = None
) -> pd.DataFrame:
    """Parameter table with standard errors, 95 % intervals, correlations and flags.

    ``weights``: the factor each residual row carries (rests thinned by
    :func:`_row_selection`: sqrt(thin) on the rows kept late in a rest; default 1). The
    covariance is then the weighted least squares' sandwich s² (JᵀJ)⁻¹ Jᵀ W² J (JᵀJ)⁻¹ with
    s² from the unweighted residuals of the rows kept: a row standing for ``thin`` rows carries
    one row's information, so the parameters the late rests determine get the larger errors
    the thinned data give them (with unit weights: the usual s² (JᵀJ)⁻¹)."""
    n = len(specs)
    m = sol.fun.size
    w = np.ones(m) if weights is None else np.asarray(weights, dtype=float)
    fun = np.asarray(sol.fun, dtype=float)
    ss_raw = float(fun @ fun)
    robust = 2.0 * float(sol.cost) / ss_raw if ss_raw > 0 else 1.0  # < 1 with a robust loss
    s2 = robust * float(np.sum((fun / w) ** 2)) / max(m - n, 1)
    jac = sol.jac
    with np.errstate(all="ignore"):
        # covariance from the SVD of the Jacobian itself, not a pseudo-inverse of J^T J: that
        # squares the condition number and drops directions J barely sees (two nearly equal
        # time constants), which would report an unidentifiable pair with small errors; a
        # singular value below the rounding level counts as that level (a huge variance)
        try:
            u, sv, vt = np.linalg.svd(jac, full_matrices=False)
            floor = max(float(sv[0]), 1e-300) * max(m, n) * np.finfo(float).eps
            a = vt.T / np.maximum(sv, floor)  # V S^-1
            b = u * w[:, None]  # W U
            cov = a @ (b.T @ b) @ a.T * s2
        except np.linalg.LinAlgError:
            cov = np.full((n, n), np.nan)
        std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        corr = cov / np.outer(std, std)
    rows = []
    for k, s in enumerate(specs):
        th = float(sol.x[k])
        value = float(np.exp(th)) if s.log else th
        with np.errstate(over="ignore"):  # an unidentifiable log-parameter: infinite upper bound
            lo, hi = (
                (value * np.exp(-1.96 * std[k]), value * np.exp(1.96 * std[k]))
                if s.log
                else (th - 1.96 * std[k], th + 1.96 * std[k])
            )
        se = value * std[k] if s.log else std[k]
        reasons = []
        if s.name.endswith("tau_s") and value > longest_s:
            reasons.append(
                f"time constant {value:.4g} s longer than the longest pulse or rest ({longest_s:.4g} s)"
            )
        width = s.hi - s.lo
        if min(th - s.lo, s.hi - th) <= 1e-3 * width:
            reasons.append("at a bound of its search range")
        rel = std[k] if s.log else (se / abs(value) if value else np.inf)
        others = [(abs(corr[k, j]), specs[j].name) for j in range(n) if j != k and np.isfinite(corr[k, j])]
        note = ""
        if others:
            c, other = max(others)
            if c > CORRELATION_LIMIT:
                note = f"correlation {c:.3f} with {other}"
                if rel > RELATIVE_ERROR_LIMIT:  # correlated and poorly determined
                    reasons.append(note)
        if not np.isfinite(rel) or rel > 1.0:
            reasons.append("standard error larger than the value")
        rows.append(
            {
                "name": s.name,
                "value": value,
                "unit": s.unit,
                "std_error": float(se),
                "ci95_low": float(lo),
                "ci95_high": float(hi),
                "flag": "; ".join(reasons),
                "note": note,
            }
        )
    return pd.DataFrame(rows)


def _least_squares(*args: Any, **kw: Any) -> Any:
    """``scipy.optimize.least_squares`` with one BLAS thread: its trust-region steps take SVDs
    of the tall (rows x parameters) Jacobian, on which a multi-threaded BLAS is slower than one
    thread, and on a loaded machine several times slower (0.4 s against 0.08 s for
    43 200 x 26 with one other process busy)."""
    from scipy.optimize import least_squares
    from threadpoolctl import threadpool_limits

    with threadpool_limits(1, user_api="blas"):
        return least_squares(*args, **kw)


def _with(p: CellParameters, **kw: Any) -> CellParameters:
    return dataclasses.replace(p, **kw)


def identify(
    base: CellParameters | str | Path,
    record: CellTestRecord,
    soc_initial: float = 1.0,
    capacity_ah: float | None = None,
    port_temp_k: float | None = None,
    n_rc: int = 2,
    charge_transfer: bool = True,
    rest_band_a: float | None = None,
    min_rest_s: float = 300.0,
    sigma_v: float = 0.001,
    sigma_t: float = 0.1,
    model: ModelSection = FIDELITY_MODEL,
    jacobian: str = "auto",
    thin_rests: int = 1,
) -> Identification:
    """Identify a complete parameter set from ``record`` (module docstring).

    ``base`` supplies what the test does not: voltage limits, ageing factors, the initial
    thermal values and (unless ``capacity_ah`` [A h] is given) the capacity. ``soc_initial``
    is the SOC one step before the first row; ``port_temp_k`` (ambient) defaults to the first
    temperature sample. The record must hold rests for the OCV. ``model`` is the structure to
    fit; with ``rc_mode = "switched"`` (the thesis's) the charge and discharge RC sets are
    fitted separately (``rc_dis[j]``, ``rc_chg[j]``). ``jacobian``: ``"analytic"`` (forward
    sensitivities of the kernel, :func:`hevsim.battery.kernel.run_cell_sensitivity`: one
    extended run per Jacobian), ``"finite_difference"`` (one run per parameter, mapped over
    threads) or ``"auto"`` (analytic unless ``rc_mode = "switched"``). ``thin_rests`` > 1
    weighs one row in ``thin_rests`` after a rest's first :data:`REST_KEEP_S` (weight
    sqrt(thin_rests), :func:`_row_selection`): fewer rows for the trust-region SVDs and the
    Jacobian's chain rule (12 h HPPC: 0.55x the CPU with 10, parameters within 0.31 standard
    errors), at the price of the information those rows held (the covariance is the weighted
    sandwich: the OCV values of long rests up to 5x wider errors). Default 1: every row.
    """
    switched = model.rc_mode == "switched"
    if jacobian not in ("auto", "analytic", "finite_difference"):
        raise InputError(
            f"calibrate: jacobian {jacobian!r}: expected one of 'auto', 'analytic', 'finite_difference'."
        )
    if jacobian == "analytic" and switched:
        raise InputError(
            "calibrate: the analytic Jacobian needs rc_mode = 'persistent'; "
            "use jacobian='finite_difference' for the switched RC sets."
        )
    if jacobian == "auto":
        jacobian = "finite_difference" if switched else "analytic"
    p0 = base if isinstance(base, CellParameters) else load_cell_parameters(base)
    src = record.source
    if capacity_ah is not None:
        if not capacity_ah > 0:
            raise InputError(f"calibrate: --capacity-ah {capacity_ah!r}: expected a capacity > 0 A h.")
        p0 = _with(p0, capacity=dataclasses.replace(p0.capacity, c0_c=capacity_ah * 3600.0, k_cqabs=0.0))
    cap_c = p0.capacity.c0_c
    if not 0.0 <= soc_initial <= 1.0:
        raise InputError(f"calibrate: soc_initial {soc_initial!r} must be between 0 and 1.")
    i_max = float(np.max(np.abs(record.current_a)))
    if i_max <= 0:
        raise InputError(f"{src}: column 'current_a' is zero throughout; expected pulses to fit.")
    band = 1e-3 * i_max if rest_band_a is None else rest_band_a
    soc = coulomb_soc(record, soc_initial, cap_c)
    rests = find_rests(record, band, min_rest_s)
    if not rests:
        raise InputError(
            f"{src}: no rest periods (|current_a| <= {band:.3g} A for at least {min_rest_s:g} s): "
            "the OCV cannot be fitted; add rests to the test or give an OCV table with --fit."
        )
    s_pts, v_pts = ocv_points(record, soc, rests)
    s_r, r_pts = step_resistances(record, soc, 0.1 * i_max)
    if r_pts.size == 0:
        raise InputError(f"{src}: no current steps larger than {0.1 * i_max:.3g} A: R_s cannot be fitted.")
    # SOC axis: the rests' SOCs, plus 0 and 1 (extrapolated, not fitted)
    axis = np.unique(np.r_[0.0, np.clip(s_pts, 0.0, 1.0), 1.0])
    tested = (axis >= s_pts.min() - 1e-9) & (axis <= s_pts.max() + 1e-9)
    ocv_init = np.interp(axis, s_pts, v_pts)
    if s_pts.size >= 2:  # linear extrapolation of the end segments
        lo_slope = (v_pts[1] - v_pts[0]) / (s_pts[1] - s_pts[0])
        hi_slope = (v_pts[-1] - v_pts[-2]) / (s_pts[-1] - s_pts[-2])
        ocv_init = np.where(axis < s_pts[0], v_pts[0] + lo_slope * (axis - s_pts[0]), ocv_init)
        ocv_init = np.where(axis > s_pts[-1], v_pts[-1] + hi_slope * (axis - s_pts[-1]), ocv_init)
    lim = p0.limits
    ocv_init = np.maximum.accumulate(np.clip(ocv_init, lim.v_min_v, lim.v_max_v))
    r_init = np.array([float(np.median(r_pts[np.abs(s_r - s) == np.min(np.abs(s_r - s))])) for s in axis])
    ct_init = (
        step_charge_transfer(record, soc, axis, 0.1 * i_max, float(record.temp_k[0]))
        if charge_transfer
        else None
    )
    rs_init = 0.7 * r_init if ct_init is None else 0.9 * ct_init[0]
    i0_init, m_init = (10.0 * i_max, 1.0) if ct_init is None else ct_init[1:]
    t_meas = record.temp_k
    port_k = float(t_meas[0]) if port_temp_k is None else float(port_temp_k)
    longest = _longest_segment_s(record)

    # parameter vector: OCV and log R_s at tested breakpoints, log RC, log ct
    idx = np.flatnonzero(tested)
    specs: list[_Param] = []
    theta0: list[float] = []
    for k in idx:
        specs.append(_Param(f"ocv_v[soc={axis[k]:.3f}]", "V", False, lim.v_min_v, lim.v_max_v))
        theta0.append(float(ocv_init[k]))
    for k in idx:
        specs.append(_Param(f"rs_ohm[soc={axis[k]:.3f}]", "ohm", True, np.log(1e-5), np.log(10.0)))
        theta0.append(float(np.log(rs_init[k])))
    taus = np.geomspace(10.0, max(0.5 * longest, 20.0), n_rc) if n_rc > 1 else np.array([60.0])
    for label in ("rc_dis", "rc_chg") if switched else ("rc",):
        for j in range(n_rc):
            specs.append(_Param(f"{label}[{j}].r_ohm", "ohm", True, np.log(1e-6), np.log(1.0)))
            theta0.append(float(np.log(0.2 * np.median(r_init))))
            specs.append(_Param(f"{label}[{j}].tau_s", "s", True, np.log(0.5), np.log(1e5)))
            theta0.append(float(np.log(taus[j])))
    if charge_transfer:
        specs.append(_Param("ct_i0_a", "A", True, np.log(1e-3 * i_max), np.log(1e3 * i_max)))
        theta0.append(float(np.log(i0_init)))
        specs.append(_Param("ct_scale", "-", True, np.log(0.05), np.log(20.0)))
        theta0.append(float(np.log(m_init)))
    n_ocv = idx.size

    ocv_map = _OcvMap(ocv_init, idx, axis, lim.v_min_v, lim.v_max_v, extrapolate=s_pts.size >= 2)
    rs_weights = np.stack([np.interp(axis, axis[idx], e) for e in np.eye(n_ocv)], axis=1)

    def build(theta: FloatArray) -> CellParameters:
        ocv, _ = ocv_map(theta[:n_ocv])
        rs = np.interp(axis, axis[idx], np.exp(theta[n_ocv : 2 * n_ocv]))
        k0 = 2 * n_ocv
        rc = np.exp(theta[k0 : k0 + 2 * n_rc]).reshape(n_rc, 2) if n_rc else np.zeros((0, 2))
        rc_c = rc.copy()
        if switched and n_rc:
            rc_c = np.exp(theta[k0 + 2 * n_rc : k0 + 4 * n_rc]).reshape(n_rc, 2)
        ct = ChargeTransferSection()
        if charge_transfer:
            ct = ChargeTransferSection(i0_a=float(np.exp(theta[-2])), scale=float(np.exp(theta[-1])))
        return _with(
            p0,
            soc=axis,
            temperature_k=np.array([p0.capacity.t_ref_k]),
            ocv_charge_v=ocv[:, None].copy(),
            ocv_discharge_v=ocv[:, None].copy(),
            rs_charge_ohm=rs[:, None].copy(),
            rs_discharge_ohm=rs[:, None].copy(),
            capacity_factor=np.ones(1),
            rc_discharge=rc,
            rc_charge=rc_c,
            model=model,
            charge_transfer=ct,
            hysteresis=dataclasses.replace(p0.hysteresis, max_v=0.0),
            resistance=dataclasses.replace(p0.resistance, alpha_rs_per_k=0.0),
            capacity=dataclasses.replace(p0.capacity, alpha_c_per_k=0.0),
            source=f"calibrated from {src}",
        )

    rows, w_rows = _row_selection(record, thin=thin_rests)
    v_meas = record.voltage_v[rows]

    def res_v(theta: FloatArray) -> FloatArray:
        v, _ = _simulate(build(theta), record, soc_initial, port_k, port_k)
        return (v[rows] - v_meas) / sigma_v * w_rows  # w = 1: the unthinned residual bit for bit

    def jac_v(theta: FloatArray) -> FloatArray:
        """d res_v / d theta from the forward sensitivities (one extended run of the kernel)."""
        p = build(theta)
        dv = _sensitivities(p, record, soc_initial, port_k)[0][rows]
        cols = K.sensitivity_columns(axis.size, n_rc)
        jac = np.empty((dv.shape[0], len(specs)))
        jac[:, :n_ocv] = dv[:, cols["ocv"]] @ ocv_map(theta[:n_ocv])[1]
        jac[:, n_ocv : 2 * n_ocv] = dv[:, cols["rs"]] @ (rs_weights * np.exp(theta[n_ocv : 2 * n_ocv]))
        k0 = 2 * n_ocv
        for j in range(n_rc):  # log R_j, log tau_j
            jac[:, k0 + 2 * j] = dv[:, cols["rc_r"]][:, j] * p.rc_discharge[j, 0]
            jac[:, k0 + 2 * j + 1] = dv[:, cols["rc_tau"]][:, j] * p.rc_discharge[j, 1]
        if charge_transfer:
            jac[:, -2] = dv[:, cols["ct_i0_a"]] * p.charge_transfer.i0_a
            jac[:, -1] = dv[:, cols["ct_scale"]] * p.charge_transfer.scale
        return jac / sigma_v * w_rows[:, None]

    lo = np.array([s.lo for s in specs])
    hi = np.array([s.hi for s in specs])
    x0 = np.clip(np.array(theta0), lo + 1e-9 * (hi - lo), hi - 1e-9 * (hi - lo))
    threads = choose_threads().threads
    if jacobian == "analytic":
        sol_v = _least_squares(
            res_v, x0, jac=jac_v, bounds=(lo, hi), x_scale="jac", ftol=1e-10, xtol=1e-10, max_nfev=100
        )
    elif jacobian == "finite_difference":
        # the finite-difference Jacobian's columns are independent runs of the (nogil) cell
        # kernel: map them over threads, as many as cores are free (hevsim.threads)
        with ThreadPoolExecutor(max_workers=threads) as pool:
            workers = pool.map if threads > 1 else map
            sol_v = _least_squares(
                res_v,
                x0,
                bounds=(lo, hi),
                x_scale="jac",
                ftol=1e-10,
                xtol=1e-10,
                max_nfev=100,
                workers=workers,
            )
    p_el = build(sol_v.x)
    table = _stats(sol_v, specs, longest, weights=w_rows)

    # thermal: log C_heat, log R_skin with the electrical parameters fixed
    has_t = record.temperature_measured and bool(np.any(np.abs(t_meas - t_meas[0]) > 1e-9))
    nfev_t = 0
    p_fit = p_el
    if has_t:
        th = p0.thermal
        t_specs = [
            _Param("c_heat_j_per_k", "J/K", True, np.log(1e-2), np.log(1e6)),
            _Param("r_skin_k_per_w", "K/W", True, np.log(1e-3), np.log(1e4)),
        ]

        def with_thermal(theta: FloatArray) -> CellParameters:
            return _with(p_el, thermal=ThermalSection(float(np.exp(theta[0])), float(np.exp(theta[1]))))

        def res_t(theta: FloatArray) -> FloatArray:
            _, t = _simulate(with_thermal(theta), record, soc_initial, port_k, port_k)
            return (t - t_meas) / sigma_t

        t0 = np.log([th.c_heat_j_per_k, th.r_skin_k_per_w])
        with ThreadPoolExecutor(max_workers=threads) as pool:
            sol_t = _least_squares(
                res_t,
                t0,
                bounds=([s.lo for s in t_specs], [s.hi for s in t_specs]),
                x_scale="jac",
                workers=pool.map if threads > 1 else map,
            )
        nfev_t = int(sol_t.nfev)
        p_fit = with_thermal(sol_t.x)
        table = pd.concat([table, _stats(sol_t, t_specs, np.inf)], ignore_index=True)
    v, t = _simulate(p_fit, record, soc_initial, port_k, port_k)
    if not record.temperature_measured:
        t_meas = np.full_like(t, np.nan)
    ts = _fit_series(record, v, t, t_meas, soc=soc)
    rmse = {
        "voltage_v": float(np.sqrt(np.mean((v - record.voltage_v) ** 2))),
        "voltage_max_v": float(np.max(np.abs(v - record.voltage_v))),
        "temp_k": float(np.sqrt(np.mean((t - t_meas) ** 2))) if has_t else float("nan"),
    }
    meta = {
        "source_file": src,
        "source_sha256": _sha256(src),
        "date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "base_parameters": p0.source,
        "soc_initial": soc_initial,
        "capacity_ah": cap_c / 3600.0,
        "port_temp_k": port_k,
        "fitted_soc_range": [float(s_pts.min()), float(s_pts.max())],
        "fitted_current_range_a": [float(record.current_a.min()), float(record.current_a.max())],
        "fitted_temp_range_k": [float(np.min(record.temp_k)), float(np.max(record.temp_k))],
        "temperature_measured": record.temperature_measured,
        "rests": len(rests),
        "current_steps": int(r_pts.size),
        "nfev": int(sol_v.nfev) + nfev_t,
        "njev": int(sol_v.njev or 0),
        "jacobian": jacobian,
        "success": bool(sol_v.success),
    }
    return Identification(p_fit, table, rmse, ts, metadata=meta)


def _fit_series(
    record: CellTestRecord, v: FloatArray, t: FloatArray, t_meas: FloatArray, **extra: FloatArray
) -> pd.DataFrame:
    """The measured and simulated voltage [V] and temperature [K] of ``record`` and their
    errors per sample (``extra`` columns after the current)."""
    return pd.DataFrame(
        {
            "time_s": record.time_s,
            "current_a": record.current_a,
            **extra,
            "voltage_measured_v": record.voltage_v,
            "voltage_fitted_v": v,
            "voltage_error_v": v - record.voltage_v,
            "temp_measured_k": t_meas,
            "temp_fitted_k": t,
            "temp_error_k": t - t_meas,
        }
    )


def _sha256(path: str) -> str:
    p = Path(path)
    return hashlib.sha256(p.read_bytes()).hexdigest() if p.is_file() else ""


def validate(
    result: Identification,
    record: CellTestRecord,
    soc_initial: float | None = None,
    port_temp_k: float | None = None,
) -> Identification:
    """Simulate ``record`` with the identified set and tabulate the errors per current range.

    ``soc_initial`` defaults to the OCV inverse of the first voltage (the record should start
    at rest); ``port_temp_k`` to the first temperature sample.
    """
    p = result.params
    if soc_initial is None:
        ocv = p.ocv_discharge_v[:, 0]
        if np.any(np.diff(ocv) <= 0):
            raise InputError("calibrate --validate: the OCV is not strictly increasing; give --validate-soc.")
        soc_initial = float(np.clip(np.interp(record.voltage_v[0], ocv, p.soc), 0.0, 1.0))
    port_k = float(record.temp_k[0]) if port_temp_k is None else float(port_temp_k)
    v, t = _simulate(p, record, soc_initial, port_k, float(record.temp_k[0]))
    t_meas = record.temp_k if record.temperature_measured else np.full_like(t, np.nan)
    ts = _fit_series(record, v, t, t_meas)
    errors = error_table(ts, p.capacity.c0_c / 3600.0)
    meta = {
        **result.metadata,
        "validation_file": record.source,
        "validation_sha256": _sha256(record.source),
        "validation_soc_initial": soc_initial,
    }
    return dataclasses.replace(result, validation=ts, validation_errors=errors, metadata=meta)


def _reference_record(
    result: Any, t_amb_k: float, *, flag_unmeasured: bool = False
) -> tuple[CellTestRecord, np.ndarray]:
    """The identification's own test (its recorded time series) as a :class:`CellTestRecord`,
    the port temperature [K] where measured, else the ambient ``t_amb_k``; with
    ``flag_unmeasured`` the record says whether every temperature was measured. Also returns
    the measured temperatures as recorded (NaN where none) [K]."""
    ts = result.timeseries
    t_meas = ts["temp_measured_k"].to_numpy(dtype=float)
    extra = {"temperature_measured": bool(np.all(np.isfinite(t_meas)))} if flag_unmeasured else {}
    rec = CellTestRecord(
        ts["time_s"].to_numpy(dtype=float),
        ts["current_a"].to_numpy(dtype=float),
        ts["voltage_measured_v"].to_numpy(dtype=float),
        np.where(np.isfinite(t_meas), t_meas, t_amb_k),
        source=str(result.metadata.get("source_file", "<reference>")),
        **extra,
    )
    return rec, t_meas


def fit_temperature(
    result: Identification,
    records: list[CellTestRecord],
    min_step_fraction: float = 0.1,
) -> Identification:
    """R0(SOC, T) and an Arrhenius activation energy from pulse tests at other ambients.

    ``result`` is the identification at the reference ambient (its test's steps count too);
    each of ``records`` is a pulse test at one ambient (the temperature of its first row,
    which should be at rest; the column ``temp_k`` is required), starting at rest (its SOC is
    the fitted OCV's inverse of the first voltage, or the reference test's initial SOC where the
    fitted OCV is flat and has no inverse, e.g. on an LFP plateau). From every current step larger than
    ``min_step_fraction`` times the record's largest current: ``R0 = -dV/dI`` over one
    sample, the SOC and the cell temperature ``T`` [K] before the step. Then

    * the activation energy ``Ea`` [J/mol] by linear least squares on
      ``ln R0 = a(SOC bin) + Ea / R_gas (1/T - 1/T_ref)`` over all steps (one intercept per
      SOC breakpoint, ``T_ref`` the reference ambient), with its standard error;
    * R0 per (SOC breakpoint, ambient): the median of the steps nearest that breakpoint, with
      the standard error of the median (1.25 sigma / sqrt(n));
    * the parameter set's R_s tables over the ambients: the reference column (the least-squares
      R_s) times the measured ratio R0(SOC, T) / R0(SOC, T_ref) (the Arrhenius factor where a
      breakpoint has no step at that ambient), the OCV copied to every column (its temperature
      dependence is not fitted); the charge-transfer exchange current takes ``Ea`` (so its
      resistance follows the same law) and ``t_ref_k`` becomes the reference ambient. The RC
      resistances keep their reference values (the cell model has no temperature law for them).
    """
    p = result.params
    if p.temperature_k.size != 1:
        raise InputError("calibrate --data: the identification already has several temperature columns.")
    if not records:
        raise InputError("calibrate --data: no tests at other temperatures given.")
    ts = result.timeseries
    t_ref_amb = float(result.metadata.get("port_temp_k", p.capacity.t_ref_k))
    ref, _ = _reference_record(result, t_ref_amb)
    ocv = p.ocv_discharge_v[:, 0]
    cap_c = p.capacity.c0_c
    axis = p.soc
    rows: list[tuple[int, float, float, float]] = []  # (file, soc, temperature [K], R0 [ohm])
    ambients = [t_ref_amb]
    for j, rec in enumerate([ref, *records]):
        if j == 0:
            soc = ts["soc"].to_numpy(dtype=float)
        else:
            if not rec.temperature_measured:
                raise InputError(f"{rec.source}: column 'temp_k' is required for a test at another ambient.")
            if np.any(np.diff(ocv) <= 0):  # a flat OCV (LFP plateau) has no inverse: the reference's
                soc0 = float(result.metadata.get("soc_initial", 1.0))  # start SOC (refined jointly later)
            else:
                soc0 = float(np.clip(np.interp(rec.voltage_v[0], ocv, axis), 0.0, 1.0))
            soc = coulomb_soc(rec, soc0, cap_c)
            ambients.append(float(rec.temp_k[0]))
        i_max = float(np.max(np.abs(rec.current_a)))
        k, r = _steps(rec, min_step_fraction * i_max) if i_max > 0 else (np.zeros(0, int), np.zeros(0))
        if k.size == 0:
            raise InputError(f"{rec.source}: no current steps: R0 cannot be fitted at this temperature.")
        rows += [(j, float(soc[kk]), float(rec.temp_k[kk]), float(rr)) for kk, rr in zip(k, r, strict=True)]
    f_idx = np.array([r[0] for r in rows])
    s_st = np.array([r[1] for r in rows])
    t_st = np.array([r[2] for r in rows])
    r_st = np.array([r[3] for r in rows])
    amb = np.array(ambients)
    t_axis = np.unique(np.round(amb, 2))
    if t_axis.size < 2:
        raise InputError(
            f"calibrate --data: every test is at the ambient {amb[0]:.2f} K (its first temperature "
            "sample): R0(SOC, T) and the activation energy need tests at two ambients or more."
        )
    near = np.argmin(np.abs(s_st[:, None] - axis[None, :]), axis=1)
    bins = np.unique(near)
    a = np.zeros((r_st.size, bins.size + 1))
    a[np.arange(r_st.size), np.searchsorted(bins, near)] = 1.0
    a[:, -1] = 1.0 / t_st - 1.0 / t_ref_amb
    coef, *_ = np.linalg.lstsq(a, np.log(r_st), rcond=None)
    dof = max(r_st.size - a.shape[1], 1)
    s2 = float(np.sum((a @ coef - np.log(r_st)) ** 2)) / dof
    cov = np.linalg.pinv(a.T @ a) * s2
    ea = float(coef[-1]) * K.R_GAS_J_PER_MOL_K
    ea_se = float(np.sqrt(max(cov[-1, -1], 0.0))) * K.R_GAS_J_PER_MOL_K
    # R0 per (SOC breakpoint, ambient)
    col_of_file = np.searchsorted(t_axis, np.round(amb, 2))
    r0_rows = []
    med = np.full((axis.size, t_axis.size), np.nan)
    for c, t_c in enumerate(t_axis):
        for b in bins:
            sel = np.isin(f_idx, np.flatnonzero(col_of_file == c)) & (near == b)
            if not sel.any():
                continue
            vals = r_st[sel]
            med[b, c] = float(np.median(vals))
            se = 1.2533 * float(np.std(vals, ddof=1)) / np.sqrt(vals.size) if vals.size > 1 else float("nan")
            r0_rows.append(
                {"soc": float(axis[b]), "temp_k": float(t_c), "r0_ohm": med[b, c], "std_error_ohm": se,
                 "steps": int(vals.size)}
            )  # fmt: skip
    c_ref = int(col_of_file[0])
    arrhenius = np.exp(ea / K.R_GAS_J_PER_MOL_K * (1.0 / t_axis - 1.0 / t_ref_amb))
    ratio = med / med[:, [c_ref]]
    ratio = np.where(np.isfinite(ratio), ratio, arrhenius[None, :])
    rs_c = p.rs_charge_ohm[:, :1] * ratio
    rs_d = p.rs_discharge_ohm[:, :1] * ratio
    ct = p.charge_transfer
    if ct.i0_a > 0:
        ct = dataclasses.replace(ct, ea_j_per_mol=float(np.clip(ea, 0.0, 2e5)))
    n_t = t_axis.size
    params = _with(
        p,
        temperature_k=t_axis,
        ocv_charge_v=np.repeat(p.ocv_charge_v[:, :1], n_t, axis=1),
        ocv_discharge_v=np.repeat(p.ocv_discharge_v[:, :1], n_t, axis=1),
        rs_charge_ohm=rs_c,
        rs_discharge_ohm=rs_d,
        capacity_factor=np.ones(n_t),
        capacity=dataclasses.replace(p.capacity, t_ref_k=t_ref_amb),
        charge_transfer=ct,
    )
    flags = []
    if not ea > 0:
        flags.append("not positive: the resistance does not fall with temperature in these tests")
    if not ea_se < abs(ea):
        flags.append("standard error larger than the value")
    ea_row = {
        "name": "r0_ea_j_per_mol",
        "value": ea,
        "unit": "J/mol",
        "std_error": ea_se,
        "ci95_low": ea - 1.96 * ea_se,
        "ci95_high": ea + 1.96 * ea_se,
        "flag": "; ".join(flags),
        "note": f"Arrhenius fit of {r_st.size} step resistances at {n_t} ambients",
    }
    table = pd.concat([result.parameters, pd.DataFrame([ea_row])], ignore_index=True)
    meta = {
        **result.metadata,
        "temperature_files": [rec.source for rec in records],
        "temperature_sha256": [_sha256(rec.source) for rec in records],
        "ambient_temperatures_k": [float(t) for t in t_axis],
        "r0_activation_energy_j_per_mol": ea,
        "r0_activation_energy_std_j_per_mol": ea_se,
        "fitted_temp_range_k": [float(t_st.min()), float(t_st.max())],
    }
    return dataclasses.replace(
        result, params=params, parameters=table, metadata=meta, r0_temperature=pd.DataFrame(r0_rows)
    )


def _unfitted(name: str, unit: str, flag: str) -> dict[str, Any]:
    """A parameter-table row for a parameter the data cannot identify (not fitted)."""
    nan = float("nan")
    return {"name": name, "value": nan, "unit": unit, "std_error": nan, "ci95_low": nan, "ci95_high": nan,
            "flag": flag, "note": ""}  # fmt: skip


REST_SOC_COST_RATIO = 4.0
"""The rests' initial SOC replaces the OCV inverse's when it lays the rests this many times
better (mean square voltage error; :func:`_initial_soc_from_rests`)."""
REST_SOC_COST_FLOOR_V2 = 2.5e-7
"""... and by more than this mean square [V²] ((0.5 mV)²)."""


def _relaxed_curve(rec: CellTestRecord, soc: FloatArray, min_rest_s: float) -> tuple[FloatArray, FloatArray]:
    """(SOC [-], relaxed voltage [V]) at the rests of ``rec`` (SOC per row ``soc``), sorted by SOC."""
    band = 1e-3 * max(float(np.max(np.abs(rec.current_a))), 1e-9)
    rests = find_rests(rec, band, min_rest_s)
    if not rests:
        return np.zeros(0), np.zeros(0)
    return ocv_points(rec, soc, rests)


def _initial_soc_from_rests(
    rec: CellTestRecord,
    ref_curve: tuple[FloatArray, FloatArray],
    ocv_ref: FloatArray,
    axis: FloatArray,
    capacity_c: float,
    min_rest_s: float,
) -> float:
    """Initial SOC [-] of ``rec`` (the step before its first row): the shift of its rests'
    coulomb-counted SOCs (reference capacity ``capacity_c`` [C]) that best lays their relaxed
    voltages on the reference test's relaxed-voltage curve ``ref_curve`` (a grid search, then
    refined). The whole rest sequence pins the SOC where the first voltage alone cannot (a flat
    OCV, e.g. an LFP plateau, has no reliable inverse). The inverse of the reference OCV
    ``ocv_ref`` on ``axis`` at the first voltage is kept unless the rests' shift lays them
    clearly better (mean square below 1/:data:`REST_SOC_COST_RATIO` of the inverse's, beyond
    :data:`REST_SOC_COST_FLOOR_V2`), and always without two rests in both tests."""
    s_ref, v_ref = ref_curve
    q = coulomb_soc(rec, 0.0, capacity_c)  # -(charge removed) / C per row
    s_pts, v_pts = _relaxed_curve(rec, q, min_rest_s)  # SOCs relative to the start
    ocv_mono = np.maximum.accumulate(ocv_ref)
    s_inv = float(np.clip(np.interp(rec.voltage_v[0], ocv_mono, axis), 0.0, 1.0))
    if s_ref.size < 2 or s_pts.size < 2:
        return s_inv
    span = float(s_pts.max() - s_pts.min())

    def cost(s0: float) -> float:
        s = s0 + s_pts
        inside = (s >= s_ref[0] - 0.05 * span) & (s <= s_ref[-1] + 0.05 * span)
        if inside.sum() < 2:
            return np.inf
        return float(np.mean((np.interp(s[inside], s_ref, v_ref) - v_pts[inside]) ** 2)) / inside.mean()

    lo = float(np.clip(-s_pts.min(), 0.0, 1.0))
    hi = float(np.clip(1.0 - s_pts.max(), lo, 1.0))
    grid = np.linspace(lo, hi, 201) if hi > lo else np.array([lo])
    best = float(grid[int(np.argmin([cost(g) for g in grid]))])
    step = (grid[1] - grid[0]) if grid.size > 1 else 0.0
    for _ in range(3):  # refine on finer grids around the best
        if step <= 0:
            break
        fine = np.clip(np.linspace(best - step, best + step, 41), lo, hi)
        best = float(fine[int(np.argmin([cost(g) for g in fine]))])
        step = step / 20.0
    c_inv, c_best = cost(s_inv), cost(best)
    if np.isfinite(c_inv) and c_inv <= REST_SOC_COST_RATIO * c_best + REST_SOC_COST_FLOOR_V2:
        return s_inv  # the inverse lays the rests about as well
    return float(np.clip(best, 0.0, 1.0))


ROBUST_LOSSES = ("linear", "soft_l1", "huber", "cauchy", "arctan")
"""Losses of :func:`fit_temperature_laws` (``scipy.optimize.least_squares``)."""
MIN_AMBIENT_SPREAD_K = 5.0
"""Ambients closer than this [K] (highest minus lowest) cannot separate an activation energy:
:func:`fit_temperature_laws` then holds every activation energy at 0 and flags it."""
EA_BOUNDS_J_PER_MOL = (-5e4, 1.5e5)
"""Search range of the activation energies [J/mol] (:func:`fit_temperature_laws`)."""


def fit_temperature_laws(
    result: Identification,
    records: list[CellTestRecord],
    sigma_v: float = 0.001,
    sigma_t: float = 0.1,
    min_ambient_spread_k: float = MIN_AMBIENT_SPREAD_K,
    min_rest_s: float = 300.0,
    loss: str = "linear",
    f_scale: float = 1.0,
    thin_rests: int = 1,
    hysteresis: bool = False,
) -> Identification:
    """The temperature-dependent parameter set, fitted jointly to the reference test and the
    tests at other ambients (issue 27; ``hevsim calibrate --data``).

    ``result`` is :func:`identify` at the reference ambient (one temperature column; the
    result of :func:`fit_temperature` is accepted too: its step-resistance activation energy
    is the initial guess); each of ``records`` is a test at one ambient (its first
    ``temp_k`` sample; the column is required). One weighted least-squares fit over every
    record's voltage (``sigma_v`` [V]) and temperature (``sigma_t`` [K]) of:

    * the reference parameters at T_ref (the reference ambient): OCV and log R_s at the tested
      SOC breakpoints, log R and log tau of each RC pair, log i0 and log scale of the charge
      transfer (when the set has it);
    * the laws: Arrhenius activation energies of R_s, of each RC pair's R and tau and of i0
      [J/mol]; the entropic coefficient dU/dT [V/K] at the tested breakpoints when the other
      ambients have rests (at least ``min_rest_s``), giving OCV(SOC, T) = OCV_ref + dU/dT
      (T - T_ref) and the entropic heat; the capacity factor at each other ambient;
    * the lumped thermal parameters (log C_heat, log R_skin, when temperatures are measured)
      and the initial SOC of each other test.

    Every parameter is reported with its standard error and 95 % interval from the Jacobian
    and flagged as :func:`identify` does. Ambients spanning less than
    ``min_ambient_spread_k`` cannot separate an activation energy from the reference values:
    the activation energies are then held at 0, reported as NaN and flagged, not fitted.

    Each other test's initial SOC starts from its rests laid on the reference test's relaxed
    voltages (:func:`_initial_soc_from_rests`; the first voltage alone has no inverse on a flat
    OCV). ``loss`` / ``f_scale`` (in units of ``sigma_v`` / ``sigma_t``): a robust loss of
    ``scipy.optimize.least_squares`` (``"soft_l1"``: errors beyond ``f_scale`` weigh less), for
    tests with rows the model structure cannot follow (an LFP cell's low-SOC knee), which would
    otherwise drag the shared parameters; the standard errors then scale with the robust cost.
    ``thin_rests``: the rows weighed (:func:`_row_selection`; default every row; this fit's
    time goes to the finite-difference Jacobian's kernel runs, which thinning does not shorten).

    ``hysteresis`` (``calibrate --hysteresis``): fit the one-state hysteresis too — its
    amplitude M at T_ref [V], its rate gamma [-] and (ambients far enough apart) M's activation
    energy Ea_M [J/mol], M(T) = M A(Ea_M, T); every test starts with the hysteresis state at 0
    (a test begun after a long rest from a full charge), and the tests need charge and
    discharge to tell it from the OCV. Off (the default), the input set's hysteresis is kept
    as it is (:func:`identify` gives none).
    """
    p_in = result.params
    ts = result.timeseries
    if not records:
        raise InputError("calibrate --data: no tests at other temperatures given.")
    if loss not in ROBUST_LOSSES:
        raise InputError(f"calibrate --data: loss {loss!r}: expected one of {', '.join(ROBUST_LOSSES)}.")
    if not (np.isfinite(f_scale) and f_scale > 0):
        raise InputError(f"calibrate --robust-mv {f_scale!r}: expected a scale > 0 (in units of sigma_v).")
    if not np.array_equal(p_in.rc_discharge[:, :2], p_in.rc_charge[:, :2]):
        raise InputError(
            "calibrate --data: the temperature laws are fitted for one RC set (rc_mode = 'persistent', "
            "equal rc_discharge and rc_charge); this identification has two different sets."
        )
    t_ref = float(result.metadata.get("port_temp_k", p_in.capacity.t_ref_k))
    # the reference parameters: the identified set's column at the reference ambient
    c_ref = int(np.argmin(np.abs(p_in.temperature_k - t_ref)))
    ea0 = float(result.metadata.get("r0_activation_energy_j_per_mol", 0.0))
    if not np.isfinite(ea0):
        ea0 = 0.0
    ref, t_meas_ref = _reference_record(result, t_ref, flag_unmeasured=True)
    axis = p_in.soc
    ocv_ref = p_in.ocv_discharge_v[:, c_ref].copy()
    rs_ref = p_in.rs_discharge_ohm[:, c_ref].copy()
    lim = p_in.limits
    n_rc = p_in.n_rc
    ct_on = p_in.charge_transfer.i0_a > 0
    fitted = result.metadata.get("fitted_soc_range", [float(axis[0]), float(axis[-1])])
    idx = np.flatnonzero((axis >= fitted[0] - 1e-9) & (axis <= fitted[1] + 1e-9))
    if idx.size == 0:
        idx = np.arange(axis.size)
    ambients = []
    soc0 = []
    ref_rests = _relaxed_curve(ref, ts["soc"].to_numpy(dtype=float), min_rest_s)
    for rec in records:
        if not rec.temperature_measured:
            raise InputError(f"{rec.source}: column 'temp_k' is required for a test at another ambient.")
        ambients.append(float(rec.temp_k[0]))
        soc0.append(_initial_soc_from_rests(rec, ref_rests, ocv_ref, axis, p_in.capacity.c0_c, min_rest_s))
    amb = np.array(ambients)
    spread = float(max(amb.max(), t_ref) - min(amb.min(), t_ref))
    fit_ea = spread >= min_ambient_spread_k
    i_max = max(float(np.max(np.abs(r.current_a))) for r in records)
    has_rests = all(find_rests(r, 1e-3 * max(i_max, 1e-9), min_rest_s) for r in records)
    t_axis = np.unique(np.round(np.r_[t_ref, amb], 2))
    if t_axis.size < 2:
        raise InputError(
            f"calibrate --data: every test is at the ambient {t_ref:.2f} K: the temperature laws need "
            "tests at two ambients or more."
        )
    col_of = {float(t): k for k, t in enumerate(t_axis)}
    c_ref_new = col_of[float(np.round(t_ref, 2))]

    specs: list[_Param] = []
    theta0: list[float] = []

    def add(name: str, unit: str, log: bool, lo: float, hi: float, x0: float) -> slice:
        specs.append(_Param(name, unit, log, lo, hi))
        theta0.append(float(np.clip(x0, lo + 1e-9 * (hi - lo), hi - 1e-9 * (hi - lo))))
        return slice(len(specs) - 1, len(specs))

    def block(names: list[tuple[str, str, bool, float, float, float]]) -> slice:
        start = len(specs)
        for item in names:
            add(*item)
        return slice(start, len(specs))

    s_ocv = block(
        [(f"ocv_v[soc={axis[k]:.3f}]", "V", False, lim.v_min_v, lim.v_max_v, ocv_ref[k]) for k in idx]
    )
    s_rs = block(
        [
            (f"rs_ohm[soc={axis[k]:.3f}]", "ohm", True, np.log(1e-5), np.log(10.0), np.log(rs_ref[k]))
            for k in idx
        ]
    )
    rc0 = p_in.rc_discharge
    s_rc = block(
        [
            item
            for j in range(n_rc)
            for item in (
                (f"rc[{j}].r_ohm", "ohm", True, np.log(1e-6), np.log(1.0), np.log(rc0[j, 0])),
                (f"rc[{j}].tau_s", "s", True, np.log(0.5), np.log(1e5), np.log(rc0[j, 1])),
            )
        ]
    )
    ct = p_in.charge_transfer
    s_ct = (
        block(
            [
                ("ct_i0_a", "A", True, np.log(1e-3 * i_max), np.log(1e3 * i_max), np.log(ct.i0_a)),
                ("ct_scale", "-", True, np.log(0.05), np.log(20.0), np.log(ct.scale)),
            ]
        )
        if ct_on
        else slice(0, 0)
    )
    lo_ea, hi_ea = EA_BOUNDS_J_PER_MOL
    ea_names = ["rs_ea_j_per_mol"]
    ea_names += [f"rc[{j}].ea_{w}_j_per_mol" for j in range(n_rc) for w in ("r", "tau")]
    if ct_on:
        ea_names.append("ct_ea_j_per_mol")
    s_ea = (
        block(
            [
                (n, "J/mol", False, lo_ea, hi_ea, ea0 if not n.endswith("tau_j_per_mol") else 0.0)
                for n in ea_names
            ]
        )
        if fit_ea
        else slice(0, 0)
    )
    s_dudt = (
        block([(f"dudt_v_per_k[soc={axis[k]:.3f}]", "V/K", False, -2e-3, 2e-3, 0.0) for k in idx])
        if has_rests
        else slice(0, 0)
    )
    other_cols = [k for k in range(t_axis.size) if k != c_ref_new]
    s_cap = block(
        [
            (f"capacity_factor[T={t_axis[k]:.2f} K]", "-", True, np.log(0.5), np.log(1.5), 0.0)
            for k in other_cols
        ]
    )
    s_soc = block(
        [
            (f"soc_initial[{Path(r.source).name}]", "-", False, 0.0, 1.0, s0)
            for r, s0 in zip(records, soc0, strict=True)
        ]
    )
    all_meas = ref.temperature_measured and all(r.temperature_measured for r in records)
    th = p_in.thermal
    s_th = (
        block(
            [
                ("c_heat_j_per_k", "J/K", True, np.log(1e-2), np.log(1e6), np.log(th.c_heat_j_per_k)),
                ("r_skin_k_per_w", "K/W", True, np.log(1e-3), np.log(1e4), np.log(th.r_skin_k_per_w)),
            ]
        )
        if all_meas
        else slice(0, 0)
    )
    hy = p_in.hysteresis
    m0 = hy.max_v if hy.max_v > 0 else 5e-3  # start: 5 mV, rate 50
    g0 = hy.gamma if hy.gamma > 0 else 50.0
    s_hy = (
        block(
            [
                ("hyst_max_v", "V", True, np.log(1e-5), np.log(0.5), np.log(m0)),
                ("hyst_gamma", "-", True, np.log(1e-2), np.log(1e4), np.log(g0)),
            ]
            + ([("hyst_ea_j_per_mol", "J/mol", False, lo_ea, hi_ea, hy.ea_j_per_mol)] if fit_ea else [])
        )
        if hysteresis
        else slice(0, 0)
    )
    ocv_map = _OcvMap(ocv_ref, idx, axis, lim.v_min_v, lim.v_max_v, extrapolate=idx.size >= 2)

    def build(theta: FloatArray) -> CellParameters:
        ocv, _ = ocv_map(theta[s_ocv])
        rs = np.interp(axis, axis[idx], np.exp(theta[s_rs]))
        ea = dict(zip(ea_names, theta[s_ea], strict=True)) if fit_ea else dict.fromkeys(ea_names, 0.0)
        rc = np.zeros((n_rc, 4))
        if n_rc:
            rc[:, :2] = np.exp(theta[s_rc]).reshape(n_rc, 2)
            rc[:, 2] = [ea[f"rc[{j}].ea_r_j_per_mol"] for j in range(n_rc)]
            rc[:, 3] = [ea[f"rc[{j}].ea_tau_j_per_mol"] for j in range(n_rc)]
        dudt = np.zeros(axis.size)
        if has_rests:
            dudt = np.interp(axis, axis[idx], theta[s_dudt])
        ocv_t = np.clip(ocv[:, None] + dudt[:, None] * (t_axis[None, :] - t_ref), lim.v_min_v, lim.v_max_v)
        ocv_t = np.maximum.accumulate(ocv_t, axis=0)
        capf = np.ones(t_axis.size)
        capf[other_cols] = np.exp(theta[s_cap])
        thermal = p_in.thermal
        if all_meas:
            c_h, r_sk = np.exp(theta[s_th])
            thermal = dataclasses.replace(thermal, c_heat_j_per_k=float(c_h), r_skin_k_per_w=float(r_sk))
        if has_rests:
            thermal = dataclasses.replace(thermal, reversible_heat="ocv_table")
        ct_new = p_in.charge_transfer
        if ct_on:
            i0, m = np.exp(theta[s_ct])
            ct_new = dataclasses.replace(
                ct_new, i0_a=float(i0), scale=float(m), ea_j_per_mol=float(ea["ct_ea_j_per_mol"])
            )
        hyst = p_in.hysteresis
        if hysteresis:
            h = theta[s_hy]
            hyst = dataclasses.replace(
                hyst,
                max_v=float(np.exp(h[0])),
                gamma=float(np.exp(h[1])),
                ea_j_per_mol=float(h[2]) if fit_ea else 0.0,
            )
        n_t = t_axis.size
        rs_t = np.repeat(rs[:, None], n_t, axis=1)
        return _with(
            p_in,
            soc=axis,
            temperature_k=t_axis,
            ocv_charge_v=ocv_t.copy(),
            ocv_discharge_v=ocv_t,
            rs_charge_ohm=rs_t.copy(),
            rs_discharge_ohm=rs_t,
            capacity_factor=capf,
            rc_discharge=rc if n_rc else p_in.rc_discharge,
            rc_charge=rc.copy() if n_rc else p_in.rc_charge,
            charge_transfer=ct_new,
            hysteresis=hyst,
            thermal=thermal,
            capacity=dataclasses.replace(p_in.capacity, t_ref_k=t_ref, alpha_c_per_k=0.0),
            resistance=dataclasses.replace(
                p_in.resistance, alpha_rs_per_k=0.0, ea_j_per_mol=float(ea["rs_ea_j_per_mol"])
            ),
        )

    runs: list[tuple[CellTestRecord, float | None, float]] = [
        (ref, float(result.metadata.get("soc_initial", 1.0)), t_ref)
    ]
    runs += [(r, None, float(r.temp_k[0])) for r in records]

    def simulate_all(theta: FloatArray) -> list[tuple[FloatArray, FloatArray]]:
        p = build(theta)
        socs = theta[s_soc]
        out = []
        for k, (rec, s_ini, t_amb) in enumerate(runs):
            s0 = s_ini if s_ini is not None else float(socs[k - 1])
            out.append(_simulate(p, rec, s0, t_amb, float(rec.temp_k[0]) if k else t_ref))
        return out

    selection = [_row_selection(rec, thin=thin_rests) for rec, _, _ in runs]
    row_w = np.concatenate([np.r_[w, w] if all_meas else w for _, w in selection])

    def residuals(theta: FloatArray) -> FloatArray:
        parts = []
        for (rec, _, _), (v, t), (rows, w) in zip(runs, simulate_all(theta), selection, strict=True):
            parts.append((v[rows] - rec.voltage_v[rows]) / sigma_v * w)  # w = 1: bit for bit
            if all_meas:
                parts.append((t[rows] - rec.temp_k[rows]) / sigma_t * w)
        return np.concatenate(parts)

    lo = np.array([s.lo for s in specs])
    hi = np.array([s.hi for s in specs])
    threads = choose_threads().threads
    with ThreadPoolExecutor(max_workers=threads) as pool:
        sol = _least_squares(
            residuals,
            np.array(theta0),
            bounds=(lo, hi),
            x_scale="jac",
            ftol=1e-10,
            xtol=1e-10,
            max_nfev=200,
            loss=loss,
            f_scale=f_scale,
            workers=pool.map if threads > 1 else map,
        )
    longest = max(_longest_segment_s(r) for r, _, _ in runs)
    table = _stats(sol, specs, longest, weights=row_w)
    extra = []
    if not fit_ea:
        why = (
            f"ambients {min(amb.min(), t_ref):.2f}..{max(amb.max(), t_ref):.2f} K span {spread:.2f} K "
            f"< {min_ambient_spread_k:g} K: too close to separate an activation energy "
            "(held at 0, not fitted)"
        )
        extra += [_unfitted(n, "J/mol", why) for n in ea_names]
        if hysteresis:
            extra.append(_unfitted("hyst_ea_j_per_mol", "J/mol", why))
    if not has_rests:
        why = (
            f"no rests of {min_rest_s:g} s in every test at another ambient: the entropic coefficient is "
            "not identifiable (the OCV is kept the same at every temperature)"
        )
        extra.append(_unfitted("dudt_v_per_k", "V/K", why))
    if extra:
        table = pd.concat([table, pd.DataFrame(extra)], ignore_index=True)
    if result.parameters is not None and "name" in result.parameters:  # fit_temperature's step Ea
        table = pd.concat(
            [table, result.parameters[result.parameters["name"] == "r0_ea_j_per_mol"]], ignore_index=True
        )
    p_fit = build(sol.x)
    sims = simulate_all(sol.x)
    v, t = sims[0]
    ts_new = _fit_series(ref, v, t, t_meas_ref, soc=ts["soc"].to_numpy(dtype=float))
    err_all = np.concatenate([sv - r.voltage_v for (r, _, _), (sv, _) in zip(runs, sims, strict=True)])
    per_file = {
        r.source: float(np.sqrt(np.mean((sv - r.voltage_v) ** 2)))
        for (r, _, _), (sv, _) in zip(runs, sims, strict=True)
    }
    rmse = {
        "voltage_v": float(np.sqrt(np.mean((v - ref.voltage_v) ** 2))),
        "voltage_max_v": float(np.max(np.abs(v - ref.voltage_v))),
        "temp_k": float(np.sqrt(np.mean((t - t_meas_ref) ** 2)))
        if ref.temperature_measured
        else float("nan"),
        "all_tests_voltage_v": float(np.sqrt(np.mean(err_all**2))),
    }
    meta = {
        **result.metadata,
        "temperature_files": [rec.source for rec in records],
        "temperature_sha256": [_sha256(rec.source) for rec in records],
        "ambient_temperatures_k": [float(x) for x in t_axis],
        "temperature_laws": "joint fit over the ambients (issue 27)",
        "temperature_laws_nfev": int(sol.nfev),
        "temperature_laws_success": bool(sol.success),
        "hysteresis_fitted": bool(hysteresis),
        "voltage_rmse_per_file_v": per_file,
    }
    return dataclasses.replace(
        result, params=p_fit, parameters=table, rmse=rmse, timeseries=ts_new, metadata=meta
    )


def error_table(ts: pd.DataFrame, capacity_ah: float) -> pd.DataFrame:
    """Voltage RMSE / max error [V] per |current| range [C-rate] (:data:`CURRENT_BINS_C`) and
    overall, and the temperature RMSE [K] overall."""
    c_rate = np.abs(ts["current_a"].to_numpy()) / capacity_ah
    err = ts["voltage_error_v"].to_numpy()
    rows = []
    for a, b in itertools.pairwise(CURRENT_BINS_C):
        sel = c_rate <= b * (1.0 + 1e-9)
        if a > 0.0:
            sel &= c_rate > a * (1.0 + 1e-9)
        if sel.any():
            label = f"{a:g}-{b:g}C" if np.isfinite(b) else f">{a:g}C"
            rows.append(
                {
                    "range": label,
                    "samples": int(sel.sum()),
                    "rmse_v": float(np.sqrt(np.mean(err[sel] ** 2))),
                    "max_abs_v": float(np.max(np.abs(err[sel]))),
                    "mean_v": float(np.mean(err[sel])),
                }
            )
    t_err = ts["temp_error_k"].to_numpy()  # NaN without a measured temperature
    rows.append(
        {
            "range": "all",
            "samples": int(err.size),
            "rmse_v": float(np.sqrt(np.mean(err**2))),
            "max_abs_v": float(np.max(np.abs(err))),
            "mean_v": float(np.mean(err)),
            "temp_rmse_k": float(np.sqrt(np.mean(t_err**2))),
        }
    )
    return pd.DataFrame(rows)


# --- output -----------------------------------------------------------------------------------


def table_frame(p: CellParameters) -> pd.DataFrame:
    """The SOC tables (at the first temperature) as a frame with units in the column names."""
    return pd.DataFrame(
        {
            "soc": p.soc,
            "ocv_discharge_v": p.ocv_discharge_v[:, 0],
            "ocv_charge_v": p.ocv_charge_v[:, 0],
            "rs_discharge_ohm": p.rs_discharge_ohm[:, 0],
            "rs_charge_ohm": p.rs_charge_ohm[:, 0],
        }
    )


def _fmt(v: Any) -> str:
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, list | tuple | np.ndarray):
        return "[" + ", ".join(_fmt(x) for x in v) + "]"
    return repr(float(v))


def parameter_toml(p: CellParameters, meta: dict[str, Any]) -> str:
    """A complete parameter file (the format of ``hevsim/data/cells``) with provenance."""
    lines = [
        "# Cell parameter set identified by `hevsim calibrate` (hevsim.battery.identify)",
        f"name = {_fmt(p.name + '_calibrated')}",
        f"description = {_fmt('calibrated from ' + str(meta.get('source_file', '')))}",
        "",
        "[source]",
    ]
    for k, v in meta.items():
        if isinstance(v, str | int | float | bool | list):
            lines.append(f"{k} = {_fmt(v)}")
    sections: dict[str, Any] = {
        "capacity": p.capacity,
        "resistance": p.resistance,
        "thermal": p.thermal,
        "limits": p.limits,
        "ageing": p.ageing,
        "model": p.model,
        "charge_transfer": p.charge_transfer,
        "hysteresis": p.hysteresis,
    }
    for name, sec in sections.items():
        lines += ["", f"[{name}]"]
        lines += [f"{f.name} = {_fmt(getattr(sec, f.name))}" for f in dataclasses.fields(sec)]
    lines += ["", "[tables]", f"soc = {_fmt(list(p.soc))}", f"temperature_k = {_fmt(list(p.temperature_k))}"]
    lines.append(f"capacity_factor = {_fmt(list(p.capacity_factor))}")
    for key in ("ocv_discharge_v", "ocv_charge_v", "rs_discharge_ohm", "rs_charge_ohm"):
        z = getattr(p, key).T  # rows per temperature
        lines.append(f"{key} = [")
        lines += [f"    {_fmt(list(row))}," for row in z]
        lines.append("]")
    for key in ("rc_discharge", "rc_charge"):
        for row in getattr(p, key):
            lines += ["", f"[[{key}]]", f"r_ohm = {_fmt(row[0])}", f"tau_s = {_fmt(row[1])}"]
            if row.size > 2:  # Arrhenius laws (issue 27)
                lines += [f"ea_r_j_per_mol = {_fmt(row[2])}", f"ea_tau_j_per_mol = {_fmt(row[3])}"]
    return "\n".join(lines) + "\n"


def plot_fit(ts: pd.DataFrame, path: Path, title: str) -> Path:
    """Voltage fit and residual, temperature fit (measured vs model) as one PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from hevsim.io import save_png

    fig, ax = plt.subplots(3, 1, sharex=True, figsize=(9, 7))
    t = ts["time_s"].to_numpy()
    ax[0].plot(t, ts["voltage_measured_v"], "-", lw=0.8, label="measured")
    ax[0].plot(t, ts["voltage_fitted_v"], "-", lw=0.8, label="model")
    ax[0].set_ylabel("voltage [V]")
    ax[0].legend(loc="best")
    ax[0].set_title(title)
    ax[1].plot(t, 1e3 * ts["voltage_error_v"].to_numpy(), "-", lw=0.6)
    ax[1].set_ylabel("model - measured [mV]")
    ax[2].plot(t, ts["temp_measured_k"] - 273.15, "-", lw=0.8, label="measured")
    ax[2].plot(t, ts["temp_fitted_k"] - 273.15, "-", lw=0.8, label="model")
    ax[2].set_ylabel("temperature [°C]")
    ax[2].set_xlabel("time [s]")
    fig.tight_layout()
    save_png(fig, path, dpi=100)
    return path


__all__ = [
    "CapacitySection",
    "Identification",
    "error_table",
    "fit_temperature",
    "identify",
    "parameter_toml",
    "validate",
]
