"""Quasi-steady-state (QSS) lap simulation: how fast a vehicle goes round a track.

The method of OpenLAP and the lap-time simulators it follows, over distance ``s`` on the
track's uniform step ``ds`` (:mod:`hevsim.tracks`):

1. **Grip**: a friction ellipse ``(F_x / (mu_x N))^2 + (F_y / (mu_y N))^2 <= 1`` on the total
   normal load ``N = m (g cos(theta) cos(beta) + v^2 kappa sin(beta)) + D`` (grade angle
   ``theta``, banking ``beta``, downforce ``D = 0.5 rho C_L A v^2`` of ``[aero]``), the lateral
   force ``F_y = m (v^2 kappa cos(beta) - g cos(theta) sin(beta))`` (``[tire]
   friction_coefficient_x`` / ``_y``). Constant friction coefficients make the lateral load
   transfer between the left and right wheels irrelevant (the sum of their limits is ``mu N``);
   the longitudinal load transfer (CG height ``h``, wheelbase ``L``) sets the driven axle's
   share of ``N`` and so the traction limit, as in the performance tests
   (:class:`hevsim.sim.performance.Adhesion`): on the driven axle ``F_x <= mu_x e (N_d0 +/-
   m a h / L)`` with ``e`` the ellipse's remaining longitudinal share and ``N_d0`` the axle's
   static share (weight, drag and grade pitch, its share of the downforce by
   ``front_downforce_fraction``). Braking uses all four wheels (ideal brake balance):
   ``F_b <= mu_x e N``.
2. **Apex speeds**: at each sample the largest speed whose lateral force alone fits the
   ellipse, ``v^2 = mu_y g R / (1 - mu_y rho C_L A R / (2 m))`` on a flat corner of radius
   ``R`` (no limit where the denominator is <= 0 or on a straight), capped at the highest speed
   of the powertrain envelope with a wheel force > 0 (:attr:`LapVehicle.speed_cap_mps`).
3. **Forward integration** from the slowest apex: ``v_{i+1}^2 = v_i^2 + 2 a_i ds`` with ``a_i``
   the smaller of the traction-limited and the power-limited acceleration, ``m delta a = F -
   F_road`` (``F_road`` drag, rolling resistance and grade, :mod:`hevsim.components.body`); the
   powertrain's largest wheel force at each speed is its **envelope**
   (:func:`hevsim.sim.performance.wheel_force_envelope`: the architecture's own power flow over
   every gear and control, engine + machine + battery limits at the held SOC), never a second
   powertrain model. **Backward integration** from the slowest apex under the braking limit.
   The speed is the smallest of the apex, forward and backward speeds (explicit Euler in
   ``v^2``: first order in ``ds``; the step convergence is in ``tests/test_lap.py``).
4. **Operating points**: each step's wheel force ``m delta a + F_road`` at its mid speed is
   given to the architecture's power flow over the same candidates; among the feasible ones
   the lap takes the one of least equivalent power, ECMS's score (fuel power ``m_f LHV`` plus
   ``s`` x the battery chemical power, ``s`` = ``[controller] equivalence_factor``, 2.5 by
   default; :class:`hevsim.control.parallel.ECMS`).

A **deployment** (``battery_power_max_w``: the largest battery chemical power [W] at each
sample, the input an optimal deployment over distance will set) limits the candidates of the
envelope (one envelope row per limit level, :data:`DEPLOYMENT_LEVELS`, interpolated linearly
between them along the lap) and of the operating points alike.

Where no candidate gives a step's demand (the envelope is linear between its speeds, and the
explicit scheme takes a step's force at its start speed) the demand is lowered by
:data:`SHORTFALL_STEPS` until one does, and, below :data:`SHORTFALL_FLAG`, the row is
flagged ``powertrain_shortfall``. The SOC is held at its initial value for the lap (energy
per lap by source is reported; a stint that carries the SOC over laps is another issue).

Kernel ``_qss_speed`` is compiled (numba): a 5 km lap at 1 m steps takes well under the
issue's 50 ms (``benchmarks/bench_lap.py``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from numba import njit

from hevsim.components.body import grade_force, rolling_force
from hevsim.errors import ConfigError, InputError
from hevsim.tracks import DEFAULT_STEP_M, Track, load_track
from hevsim.units import STANDARD_GRAVITY

ENVELOPE_SPEED_STEP_MPS = 0.5
"""Speed step of the powertrain envelope [m/s]."""
ENVELOPE_MAX_SPEED_MPS = 110.0
"""Top of the envelope's speed range [m/s] (396 km/h); also the cap of the apex speeds."""
SHORTFALL_STEPS = (0.999, 0.995, 0.98, 0.95, 0.9, 0.8, 0.6, 0.3, 0.0)
"""Fractions of a step's wheel force tried in turn where no candidate control gives it [-]."""
SHORTFALL_FLAG = 0.98
"""A step is flagged ``powertrain_shortfall`` when the wheel force given is below this share
of the demand [-]. The first steps of :data:`SHORTFALL_STEPS` absorb the explicit scheme's
own lag (a step's acceleration comes from the envelope at its start speed, the operating point
is taken at its mid speed, where the envelope is a little lower) and the envelope's linear
interpolation between its speeds."""
DEPLOYMENT_LEVELS = 5
"""Battery power limits (evenly from 0 to the largest asked) of the envelope rows a
deployment is interpolated between [-]."""
DRIVE_CODES = {"front": 0, "rear": 1, "all": 2}
"""Driven axle -> code of the compiled kernel."""


@dataclass(frozen=True)
class LapVehicle:
    """What the QSS kernel needs of a vehicle (SI): mass [kg], rotating-mass factor [-], drag
    area terms, rolling coefficient, CG height and axle distances [m], friction ellipse [-],
    downforce coefficient and balance [-], driven axle, minimum turning radius [m] and the
    powertrain's envelope (speed [m/s] -> largest wheel force [N])."""

    name: str
    mass_kg: float
    mass_factor: float
    drag_coefficient: float
    frontal_area_m2: float
    air_density_kgpm3: float
    rolling_resistance: float
    cg_height_m: float
    front_axle_to_cg_m: float
    rear_axle_to_cg_m: float
    mu_x: float
    mu_y: float
    downforce_coefficient: float
    front_downforce_fraction: float
    driven_axle: str
    min_turning_radius_m: float
    envelope_speed_mps: np.ndarray
    envelope_force_n: np.ndarray
    envelope: Any = None
    envelope_levels_w: np.ndarray | None = None
    rolling_resistance_speed_s_per_m: float = 0.0  # the coast-down form's B term [s/m]

    @property
    def force_table(self) -> tuple[np.ndarray, np.ndarray]:
        """(battery power limits [W] (k,), largest wheel force [N] (k, speeds)): one row
        per deployment limit, or the single unlimited row (limit ``inf``)."""
        f = np.atleast_2d(np.asarray(self.envelope_force_n, np.float64))
        levels = self.envelope_levels_w
        if levels is None:
            levels = np.full(f.shape[0], np.inf)
        return np.ascontiguousarray(levels, np.float64), np.ascontiguousarray(f)

    @property
    def speed_cap_mps(self) -> float:
        """Highest speed [m/s] of the envelope at which the powertrain still gives a wheel
        force > 0 (beyond it a machine or the engine leaves its map): the lap's speed cap."""
        ok = np.flatnonzero(self.force_table[1][-1] > 0.0)
        return float(self.envelope_speed_mps[ok[-1]]) if ok.size else 0.0

    def force_n(self, v_mps: np.ndarray, limit_w: np.ndarray | None = None) -> np.ndarray:
        """Largest wheel force [N] at speeds [m/s] under battery power limits [W] (None: the
        envelope's largest), as the kernel interpolates it."""
        levels, table = self.force_table
        v = np.asarray(v_mps, np.float64)
        lim = np.full(v.shape, np.inf) if limit_w is None else np.broadcast_to(limit_w, v.shape)
        return np.array(
            [
                _force(float(a), float(b), self.envelope_speed_mps, table, levels)
                for a, b in zip(v.ravel(), lim.ravel(), strict=True)
            ]
        ).reshape(v.shape)

    def params(self) -> tuple[float, ...]:
        """Scalars of the kernel, in its argument order."""
        return (
            self.mass_kg,
            self.mass_factor,
            0.5 * self.air_density_kgpm3 * self.drag_coefficient * self.frontal_area_m2,
            self.rolling_resistance,
            0.5 * self.air_density_kgpm3 * self.downforce_coefficient * self.frontal_area_m2,
            self.front_downforce_fraction,
            self.front_axle_to_cg_m,
            self.rear_axle_to_cg_m,
            self.cg_height_m,
            self.mu_x,
            self.mu_y,
            float(DRIVE_CODES[self.driven_axle]),
            self.rolling_resistance_speed_s_per_m,
        )


def lap_vehicle(model: Any, *, soc: float | None = None, battery_levels_w: Any = None) -> LapVehicle:
    """The :class:`LapVehicle` of a vehicle file, configuration or built model, with its
    powertrain envelope at ``soc`` [-] (default the configuration's initial SOC); with
    ``battery_levels_w`` (increasing battery power limits [W]), one envelope row per limit
    for a deployment (:func:`simulate_lap`'s ``battery_power_max_w``)."""
    from hevsim.config import load_vehicle_config
    from hevsim.sim.performance import Adhesion, wheel_force_envelope

    if isinstance(model, str | Path):
        model = load_vehicle_config(model)
    cfg = getattr(model, "config", model)
    speeds = np.arange(ENVELOPE_SPEED_STEP_MPS, ENVELOPE_MAX_SPEED_MPS + 1e-9, ENVELOPE_SPEED_STEP_MPS)
    env = wheel_force_envelope(model, speeds, soc)
    rows, levels = [env.force_n], None
    if battery_levels_w is not None:
        levels = np.asarray(battery_levels_w, np.float64)
        if levels.ndim != 1 or levels.size < 2 or np.any(np.diff(levels) <= 0) or levels[0] < 0:
            raise InputError(f"battery_levels_w = {levels!r}: expected at least 2 increasing powers >= 0 W.")
        rows = [wheel_force_envelope(env.model, speeds, env.soc, float(p)).force_n for p in levels]
    body = env.model.body
    Adhesion.of(cfg, body, env.model.tire.radius_m)  # refuses a car that would wheelie
    t = cfg.tire
    mu_x = t.friction_coefficient_x or t.friction_coefficient
    mu_y = t.friction_coefficient_y or t.friction_coefficient
    aero = cfg.aero
    # the envelope from standstill: the first speed's force below it
    v = np.concatenate([[0.0], env.speed_mps])
    f = np.array([np.concatenate([[r[0]], r]) for r in rows])
    return LapVehicle(
        cfg.name,
        body.mass_kg,
        body.mass_factor,
        body.drag_coefficient,
        body.frontal_area_m2,
        body.air_density_kgpm3,
        body.rolling_resistance,
        body.cg_height_m,
        body.front_axle_to_cg_m,
        body.rear_axle_to_cg_m,
        float(mu_x),
        float(mu_y),
        float(aero.downforce_coefficient),
        float(aero.front_downforce_fraction),
        str(t.driven_axle),
        float(cfg.body.min_turning_radius_m),
        v,
        f,
        env,
        levels,
        float(getattr(body, "rolling_resistance_speed_s_per_m", 0.0)),
    )


# ------------------------------------------------------------------------------------------
# Compiled kernel
# ------------------------------------------------------------------------------------------
@njit(cache=True)
def _road(v, theta, p):
    """Drag + rolling + grade force [N] at speed v [m/s] on grade angle theta [rad]."""
    m, cda, crr, crr_v = p[0], p[2], p[3], p[12]
    grade = math.tan(theta)
    return cda * v * v + rolling_force(m, grade, crr, crr_v, v) * (v > 0.0) + grade_force(m, grade)


@njit(cache=True)
def _loads(v, kappa, theta, beta, p):
    """(total normal load [N], remaining longitudinal share of the ellipse [-], static
    normal load of the driven axle [N], its load-transfer sign)."""
    m, cla, ffront, a, b, h, muy, drive = p[0], p[4], p[5], p[6], p[7], p[8], p[10], p[11]
    g = 9.80665
    v2 = v * v
    w = m * (g * math.cos(theta) * math.cos(beta) + v2 * kappa * math.sin(beta))
    down = cla * v2
    n_tot = w + down
    fy = m * (v2 * kappa * math.cos(beta) - g * math.cos(theta) * math.sin(beta))
    if n_tot <= 0.0:
        return 0.0, 0.0, 0.0, 0.0
    r = abs(fy) / (muy * n_tot)
    e = math.sqrt(1.0 - r * r) if r < 1.0 else 0.0
    wb = a + b
    pitch = h * (p[2] * v2 + m * g * math.sin(theta)) / wb
    if drive == 0.0:
        return n_tot, e, w * b / wb - pitch + down * ffront, -1.0
    if drive == 1.0:
        return n_tot, e, w * a / wb + pitch + down * (1.0 - ffront), 1.0
    return n_tot, e, n_tot, 0.0


@njit(cache=True)
def _force(v, limit, ev, table, levels):
    """Largest wheel force [N] at speed v [m/s] under battery power limit [W]: linear in
    speed along each row of ``table``, linear between the rows of the bracketing ``levels``
    (nearly exact where the battery's power binds: the force is then linear in it)."""
    nl = levels.size
    if nl == 1 or limit >= levels[nl - 1]:
        return np.interp(v, ev, table[nl - 1])
    if limit <= levels[0]:
        return np.interp(v, ev, table[0])
    j = np.searchsorted(levels, limit) - 1
    w = (limit - levels[j]) / (levels[j + 1] - levels[j])
    return (1.0 - w) * np.interp(v, ev, table[j]) + w * np.interp(v, ev, table[j + 1])


@njit(cache=True)
def _accel(v, kappa, theta, beta, p, ev, table, levels, limit):
    """Largest acceleration [m/s^2] (traction and powertrain limits) at speed v [m/s]."""
    m, delta, mux, h, wb = p[0], p[1], p[9], p[8], p[6] + p[7]
    _n_tot, e, nd0, sgn = _loads(v, kappa, theta, beta, p)
    road = _road(v, theta, p)
    a_trac = (mux * e * nd0 - road) / (m * delta - sgn * mux * e * m * h / wb)
    a_pow = (_force(v, limit, ev, table, levels) - road) / (m * delta)
    return min(a_trac, a_pow)


@njit(cache=True)
def _decel(v, kappa, theta, beta, p):
    """Largest deceleration [m/s^2] (> 0) under the braking limit at speed v [m/s]."""
    m, delta, mux = p[0], p[1], p[9]
    n_tot, e, _, _ = _loads(v, kappa, theta, beta, p)
    return (mux * e * n_tot + _road(v, theta, p)) / (m * delta)


@njit(cache=True)
def _apex(kappa, theta, beta, p, v_cap):
    """Largest speed [m/s] at which the lateral force alone fits the ellipse (<= v_cap)."""
    m, cla, muy = p[0], p[4], p[10]
    g = 9.80665
    k = abs(kappa)
    if k == 0.0:
        return v_cap
    b_in = beta if kappa > 0.0 else -beta
    coef = m * k * math.cos(b_in) - muy * m * k * math.sin(b_in) - muy * cla
    rhs = m * g * math.cos(theta) * (muy * math.cos(b_in) + math.sin(b_in))
    if coef <= 0.0:
        return v_cap
    if rhs <= 0.0:
        return 0.0
    return min(math.sqrt(rhs / coef), v_cap)


@njit(cache=True)
def _braking_speed(kappa, theta, beta, ds, p, v_cap):
    """(friction-limited speed [m/s] at each sample, apex-limit speed [m/s], index of the
    slowest apex) of a closed lap: the apex speeds and the backward (braking-limited)
    integration from the slowest apex (n samples, step ds [m])."""
    n = kappa.size
    vlim = np.empty(n)
    for i in range(n):
        vlim[i] = _apex(kappa[i], theta[i], beta[i], p, v_cap)
    i0 = int(np.argmin(vlim))
    bwd = np.empty(n)
    bwd[i0] = vlim[i0]
    for k in range(n - 1):
        j = (i0 - k) % n
        i = (j - 1) % n
        d = _decel(bwd[j], kappa[j], theta[j], beta[j], p)
        v2 = bwd[j] * bwd[j] + 2.0 * d * ds
        bwd[i] = min(math.sqrt(v2) if v2 > 0.0 else 0.0, vlim[i])
    return bwd, vlim, i0


@njit(cache=True)
def _qss_speed(kappa, theta, beta, ds, p, ev, table, levels, limit, v_cap):
    """Speed [m/s] at each sample of a closed lap (n samples, step ds [m]); ``limit`` [W]:
    the battery power limit of each sample (``inf``: none)."""
    n = kappa.size
    bwd, vlim, i0 = _braking_speed(kappa, theta, beta, ds, p, v_cap)
    fwd = np.empty(n)
    fwd[i0] = vlim[i0]
    for k in range(n - 1):
        i = (i0 + k) % n
        j = (i + 1) % n
        a = _accel(fwd[i], kappa[i], theta[i], beta[i], p, ev, table, levels, limit[i])
        v2 = fwd[i] * fwd[i] + 2.0 * a * ds
        fwd[j] = min(math.sqrt(v2) if v2 > 0.0 else 0.0, vlim[j])
    v = np.empty(n)
    for i in range(n):
        v[i] = min(fwd[i], bwd[i])
    return v, vlim


def qss_speed(
    vehicle: LapVehicle, track: Track, battery_power_max_w: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """(speed, apex-limit speed) [m/s] at each sample of ``track`` for ``vehicle``, with an
    optional battery power limit [W] at each sample (a deployment)."""
    levels, table = vehicle.force_table
    limit = np.full(track.distance_m.size, np.inf)
    if battery_power_max_w is not None:
        limit = np.ascontiguousarray(np.broadcast_to(battery_power_max_w, limit.shape), np.float64)
    return _qss_speed(
        np.ascontiguousarray(track.curvature_1pm, np.float64),
        np.arctan(track.grade),
        np.ascontiguousarray(track.banking_rad, np.float64),
        float(track.step_m),
        np.array(vehicle.params(), np.float64),
        np.ascontiguousarray(vehicle.envelope_speed_mps, np.float64),
        table,
        levels,
        limit,
        vehicle.speed_cap_mps,
    )


def lap_time_s(v_mps: np.ndarray, step_m: float) -> float:
    """Time [s] round a closed lap of speeds [m/s] at a distance step [m] (mean speed of
    each step)."""
    vm = 0.5 * (v_mps + np.roll(v_mps, -1))
    return float(np.sum(step_m / vm))


# ------------------------------------------------------------------------------------------
# The lap
# ------------------------------------------------------------------------------------------
@dataclass
class LapResult:
    """A QSS lap: ``timeseries`` (one row per track sample, columns with units), ``summary``
    (scalars with units in their names) and ``metadata``."""

    timeseries: pd.DataFrame
    summary: dict[str, Any]
    track: Track
    metadata: dict[str, Any] = field(default_factory=dict)
    search: tuple[np.ndarray, ...] | None = field(default=None, repr=False, compare=False)
    """The operating-point search per sample (its inputs: mid-step speed, wheel force, step
    time, deployment limit; its outcome: control index, force delivered, shortfall flag), for
    ``simulate_lap(..., reuse=)``."""

    @property
    def lap_time_s(self) -> float:
        """Lap time [s]."""
        return float(self.summary["lap_time_s"])

    def format(self) -> str:
        """The summary as aligned text."""
        lines = [
            f"{k:<34}{v:>14.6g}" if isinstance(v, float) else f"{k:<34}{v!s:>14}"
            for k, v in self.summary.items()
        ]
        return "\n".join(lines)

    def save(self, out_dir: str | Path, plots: bool = True, force: bool = False) -> Path:
        """Write lap.csv, summary.json, metadata.json and, with ``plots``, speed.png, gg.png,
        track_speed.png and track.png, atomically."""
        from hevsim.io import atomic_directory

        with atomic_directory(out_dir, force=force) as tmp:
            self.write(tmp, plots)
        return Path(out_dir)

    def write(self, folder: Path, plots: bool = True) -> None:
        """Write the files of :meth:`save` into ``folder`` as it is (a folder being written
        atomically: :meth:`save`, or a deployment's :meth:`~hevsim.optimal.lap_deploy.DeployResult.save`)."""
        from hevsim.io import write_json

        self.timeseries.to_csv(folder / "lap.csv", index=False, float_format="%.6g")
        write_json(folder / "summary.json", self.summary)
        write_json(folder / "metadata.json", self.metadata)
        if plots:
            self.plot(folder)

    def plot(self, folder: str | Path) -> None:
        """speed.png (speed and apex limit vs distance), gg.png (g-g diagram), track_speed.png
        (centreline coloured by speed) and track.png (:meth:`Track.plot`)."""
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        from hevsim.io import save_png

        ts, folder = self.timeseries, Path(folder)
        g = STANDARD_GRAVITY
        fig, ax = plt.subplots(figsize=(10, 4))
        ax.plot(ts["distance_m"], ts["speed_mps"] * 3.6, label="speed")
        ax.plot(
            ts["distance_m"],
            np.minimum(ts["apex_speed_mps"], ts["speed_mps"].max() * 1.2) * 3.6,
            ":",
            lw=0.8,
            label="apex limit",
        )
        ax.set_xlabel("distance [m]")
        ax.set_ylabel("speed [km/h]")
        ax.set_title(f"{self.summary['vehicle']} on {self.summary['track']}: {self.lap_time_s:.2f} s")
        ax.grid(True)
        ax.legend()
        fig.tight_layout()
        save_png(fig, folder / "speed.png", 100)
        plt.close(fig)
        fig, ax = plt.subplots(figsize=(5, 5))
        ax.scatter(ts["ay_mps2"] / g, ts["ax_mps2"] / g, s=2, c=ts["speed_mps"] * 3.6, cmap="viridis")
        ax.set_xlabel("lateral acceleration [g]")
        ax.set_ylabel("longitudinal acceleration [g]")
        ax.set_aspect("equal")
        ax.grid(True)
        ax.set_title("g-g diagram")
        fig.tight_layout()
        save_png(fig, folder / "gg.png", 100)
        plt.close(fig)
        fig, ax = plt.subplots(figsize=(6, 5))
        sc = ax.scatter(ts["x_m"], ts["y_m"], c=ts["speed_mps"] * 3.6, s=2, cmap="plasma")
        fig.colorbar(sc, ax=ax, label="speed [km/h]")
        ax.set_aspect("equal")
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
        fig.tight_layout()
        save_png(fig, folder / "track_speed.png", 100)
        plt.close(fig)
        self.track.plot(folder / "track.png")


def _operating_points(
    vehicle: LapVehicle,
    ts: pd.DataFrame,
    limit_w: np.ndarray,
    lhv_j_per_kg: float,
    equivalence_factor: float,
    reuse: tuple[np.ndarray, ...] | None = None,
) -> tuple[pd.DataFrame, dict[str, float], tuple[np.ndarray, ...]]:
    """Per-step operating points of the powertrain (module docstring, item 4) and the search's
    state (:attr:`LapResult.search`); ``reuse``: a previous lap's search state, whose outcome
    is taken at the samples with the same inputs bit for bit (each sample's search is its own)."""
    env = vehicle.envelope
    v_mid = ts["v_mid_mps"].to_numpy()
    dt = ts["dt_s"].to_numpy()
    force = ts["wheel_force_n"].to_numpy()
    n = v_mid.size
    ctl = tuple(c[None, :] for c in env.controls)
    chosen = np.full(n, -1)
    used = force.copy()
    short = np.zeros(n, bool)
    todo = np.arange(n)
    if reuse is not None and reuse[0].size == n:
        same = (reuse[0] == v_mid) & (reuse[1] == force) & (reuse[2] == dt) & (reuse[3] == limit_w)
        chosen[same], used[same], short[same] = reuse[4][same], reuse[5][same], reuse[6][same]
        todo = np.flatnonzero(~same)
    for frac in (1.0, *SHORTFALL_STEPS):
        if todo.size == 0:
            break
        f_try = np.where(force[todo] > 0.0, force[todo] * frac, force[todo])
        step = env.step(v_mid[todo, None], f_try[:, None], dt[todo, None])
        st, ok = step.evaluate(*ctl)
        ok = np.asarray(ok).reshape(todo.size, -1)
        e_soc = step.energy_per_soc_j
        p_fuel = np.broadcast_to(np.asarray(st.cost_kg), ok.shape) * lhv_j_per_kg / dt[todo, None]
        p_batt = -np.broadcast_to(np.asarray(st.d_soc), ok.shape) * e_soc / dt[todo, None]
        lim = limit_w[todo, None]
        ok = ok & (p_batt <= lim * (1.0 + 1e-9) + 1e-6)
        score = np.where(ok, p_fuel + equivalence_factor * p_batt, np.inf)
        best = np.argmin(score, axis=1)
        found = np.isfinite(score[np.arange(todo.size), best])
        chosen[todo[found]] = best[found]
        used[todo[found]] = f_try[found]
        short[todo[found]] = frac < SHORTFALL_FLAG
        todo = todo[~found]
    if todo.size:
        k = int(todo[0])
        raise InputError(
            f"lap of '{vehicle.name}': no control of the powertrain gives the wheel force {force[k]:.0f} N "
            f"(nor a smaller share of it) at distance {ts['distance_m'].iloc[k]:.1f} m, speed {v_mid[k]:.2f} "
            "m/s (a machine or the engine beyond its map?)."
        )
    picks = tuple(c[0, chosen] for c in ctl)
    st, _ = env.step(v_mid, used, dt).evaluate(*picks, detail=True)
    out: dict[str, np.ndarray] = {"wheel_force_delivered_n": used, "powertrain_shortfall": short}
    for name, val in (st.details or {}).items():
        out[name] = np.broadcast_to(np.asarray(val, np.float64), (n,)).copy()
    fuel_kg = np.broadcast_to(np.asarray(st.cost_kg, np.float64), (n,))
    d_soc = np.broadcast_to(np.asarray(st.d_soc, np.float64), (n,))
    out["fuel_kg"] = np.cumsum(fuel_kg)
    e_soc = (
        env.step(v_mid[:1], used[:1], dt[:1]).energy_per_soc_j if getattr(env.model, "battery", None) else 0.0
    )
    out["battery_chemical_power_w"] = -d_soc * e_soc / dt
    totals = {
        "fuel_kg": float(fuel_kg.sum()),
        "fuel_energy_j": float(fuel_kg.sum() * lhv_j_per_kg),
        "battery_chemical_energy_j": float(np.sum(-d_soc * e_soc)),
        "battery_energy_discharged_j": float(np.sum(np.maximum(-d_soc * e_soc, 0.0))),
        "battery_energy_charged_j": float(np.sum(np.maximum(d_soc * e_soc, 0.0))),
        "soc_change": float(d_soc.sum()),
        "powertrain_shortfall_steps": int(short.sum()),
    }
    search = (v_mid.copy(), force.copy(), dt.copy(), np.array(limit_w, np.float64), chosen, used, short)
    return pd.DataFrame(out), totals, search


def simulate_lap(
    model: Any,
    track: Track | str | Path,
    *,
    step_m: float = DEFAULT_STEP_M,
    soc: float | None = None,
    battery_power_max_w: Any = None,
    operating_points: bool = True,
    vehicle: LapVehicle | None = None,
    reuse: LapResult | None = None,
) -> LapResult:
    """QSS lap of a vehicle (file, configuration or built model) on a track (a :class:`Track`,
    shipped name or CSV path) at ``step_m`` [m].

    ``soc`` [-]: battery SOC held for the lap (default the configuration's initial SOC);
    ``battery_power_max_w``: optional deployment, the largest battery chemical power [W]
    (discharge > 0) at each sample (an array) or everywhere (a number): the envelope and the
    operating points keep to it (module docstring, item 4); ``operating_points``: False skips
    the power flow along the lap (speed profile only); ``vehicle``: a :class:`LapVehicle`
    already built for ``model``; ``reuse``: a lap of the same ``vehicle`` on the same track
    (e.g. one with another deployment) whose operating-point search is kept at the samples
    where speed, wheel force, step time and deployment limit are the same bit for bit (the
    same result, faster).
    """
    from hevsim.config import load_vehicle_config
    from hevsim.fuels import config_fuel

    if isinstance(model, str | Path):
        model = load_vehicle_config(model)
    cfg = getattr(model, "config", model)
    trk = track if isinstance(track, Track) else load_track(track, step_m=step_m)
    if isinstance(track, Track) and abs(track.step_m - step_m) > 1e-9 * step_m and step_m != DEFAULT_STEP_M:
        trk = track.resampled(step_m)
    limit = np.full(trk.distance_m.size, np.inf)
    if battery_power_max_w is not None:
        try:
            limit = np.array(np.broadcast_to(np.asarray(battery_power_max_w, np.float64), limit.shape))
        except ValueError:
            raise InputError(
                f"deployment battery_power_max_w: shape {np.shape(battery_power_max_w)}; expected a number "
                f"or one power [W] per track sample ({limit.size})."
            ) from None
        bad = np.flatnonzero(np.isnan(limit) | (limit < 0.0))
        if bad.size:
            raise InputError(
                f"deployment battery_power_max_w = {limit[bad[0]]!r} W at distance "
                f"{trk.distance_m[bad[0]]:.1f} m; expected a power >= 0 W (inf: no limit)."
            )
    veh = vehicle
    if veh is not None and battery_power_max_w is not None and veh.envelope_levels_w is None:
        raise InputError("a deployment needs a LapVehicle built with battery_levels_w (or vehicle=None).")
    if veh is None:
        top = float(np.max(limit[np.isfinite(limit)], initial=0.0))
        levels = None if np.all(np.isinf(limit)) else np.linspace(0.0, max(top, 1.0), DEPLOYMENT_LEVELS)
        veh = lap_vehicle(model, soc=soc, battery_levels_w=levels)
    trk.check_radius(veh.min_turning_radius_m, f"vehicle '{cfg.name}'")
    v, vlim = qss_speed(veh, trk, limit)
    if not np.all(v > 0.0):
        k = int(np.flatnonzero(~(v > 0.0))[0])
        raise InputError(
            f"lap of '{cfg.name}' on track '{trk.name}': the vehicle stops at distance "
            f"{trk.distance_m[k]:.1f} m "
            "(it cannot climb or hold the grip there); expected a track it can drive round."
        )
    ds = trk.step_m
    v_next = np.roll(v, -1)
    v_mid = 0.5 * (v + v_next)
    dt = ds / v_mid
    ax = (v_next**2 - v**2) / (2.0 * ds)
    p = veh.params()
    road = (
        p[2] * v_mid**2
        + rolling_force(
            veh.mass_kg, trk.grade, veh.rolling_resistance, veh.rolling_resistance_speed_s_per_m, v_mid
        )
        + grade_force(veh.mass_kg, trk.grade)
    )
    force = veh.mass_kg * veh.mass_factor * ax + road
    t = np.concatenate([[0.0], np.cumsum(dt)[:-1]])
    ts = pd.DataFrame(
        {
            "distance_m": trk.distance_m,
            "time_s": t,
            "x_m": trk.x_m,
            "y_m": trk.y_m,
            "curvature_1pm": trk.curvature_1pm,
            "speed_mps": v,
            "apex_speed_mps": vlim,
            "v_mid_mps": v_mid,
            "dt_s": dt,
            "ax_mps2": ax,
            "ay_mps2": v**2 * trk.curvature_1pm,
            "wheel_force_n": force,
            "wheel_power_w": force * v_mid,
        }
    )
    lap_t = float(dt.sum())
    summary: dict[str, Any] = {
        "vehicle": cfg.name,
        "architecture": cfg.architecture,
        "track": trk.name,
        "track_length_m": trk.length_m,
        "step_m": ds,
        "lap_time_s": lap_t,
        "mean_speed_kmh": trk.length_m / lap_t * 3.6,
        "max_speed_kmh": float(v.max() * 3.6),
        "min_speed_kmh": float(v.min() * 3.6),
        "max_lateral_g": float(np.max(np.abs(ts["ay_mps2"])) / STANDARD_GRAVITY),
        "max_longitudinal_g": float(ax.max() / STANDARD_GRAVITY),
        "max_braking_g": float(-ax.min() / STANDARD_GRAVITY),
        "full_power_fraction": 0.0,
    }
    f_env = veh.force_n(v_mid, limit)
    summary["full_power_fraction"] = float(np.sum(dt[force >= 0.98 * f_env]) / lap_t)
    search = None
    if operating_points:
        lhv = float(
            config_fuel(cfg, getattr(veh.envelope.model, "engine", None)).lower_heating_value_j_per_kg
        )
        prev = reuse.search if reuse is not None else None
        ops, totals, search = _operating_points(
            veh, ts, limit, lhv, float(cfg.controller.equivalence_factor), prev
        )
        ts = pd.concat([ts, ops], axis=1)
        summary.update(totals)
        if "gear" in ts:
            summary["gear_changes"] = int(np.count_nonzero(np.diff(ts["gear"].to_numpy())))
    meta = {
        "config": cfg.name,
        "track_source": trk.source,
        "soc": veh.envelope.soc,
        "deployment": "battery power limit" if battery_power_max_w is not None else "none",
        "equivalence_factor": float(cfg.controller.equivalence_factor),
        "mu_x": veh.mu_x,
        "mu_y": veh.mu_y,
        "downforce_coefficient": veh.downforce_coefficient,
    }
    return LapResult(ts, summary, trk, meta, search)


def check_step(step_m: float) -> float:
    """The distance step [m] of a lap, checked (0.05 to 50 m)."""
    if not (math.isfinite(step_m) and 0.05 <= step_m <= 50.0):
        raise ConfigError(
            f"option --step = {step_m!r} is out of range; expected a value between 0.05 and 50 m."
        )
    return float(step_m)


__all__ = ["LapResult", "LapVehicle", "lap_time_s", "lap_vehicle", "qss_speed", "simulate_lap"]
