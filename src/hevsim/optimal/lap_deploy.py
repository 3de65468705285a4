"""Optimal deployment over a lap (issue 29 item 3): minimum lap time under a battery energy
budget and a fuel budget, over distance, by DP and by convex optimisation on the SAME problem.

The problem (Ebbesen, Salazar, Elbert, Bussi & Onder, "Time-optimal control strategies for a
hybrid electric race car", IEEE TCST 26(1) 2018; Duhr et al. 2021) on the track's uniform
distance grid ``s_i = i ds``, ``i = 0..N-1``, closed (sample ``N`` is sample 0), started at
the slowest apex (the lap's speed there is its friction limit):

* state ``e_i = v_i^2 / 2`` [J/kg], the kinetic energy per unit mass, and the cumulative
  battery energy drawn ``E_i`` [J] (deployed > 0, harvested < 0);
* controls per step (wheel work [J] over ``ds``): engine ``W_e``, machine ``W_m`` (deploy > 0,
  harvest < 0) and brakes ``W_b >= 0``;
* dynamics ``m delta (e_{i+1} - e_i) = W_e + W_m - W_b - ds (c_d (e_i + e_{i+1}) + F_0,i)``
  (``c_d = 0.5 rho C_d A``: drag ``c_d v^2 = 2 c_d e`` at the mean of the step's two kinetic energies;
  ``F_0`` rolling resistance and grade at the sample);
* step time ``dt_i = ds / 2 (1 / v_i + 1 / v_{i+1})`` (trapezoid on the slowness); the lap
  time is ``sum dt_i``;
* limits: ``0 <= W_e <= P_e,i dt_i`` (engine's largest wheel power),
  ``|W_m| <= P_m,i dt_i`` (machine's largest wheel power added with the battery; both from the
  architecture's envelope at the speed of the QSS lap without the battery at sample i; with
  the battery's chemical power limits of :meth:`DeployProblem.with_battery`, ``P_m,i`` is also
  at most the machine power whose battery power under the loss model below is the discharge
  limit, and the harvest the one whose charge power is the charge limit),
  traction ``W_e + W_m <= ds (a_i + b_i e_i)`` (the chord in
  ``e`` of the friction ellipse's traction limit of :mod:`hevsim.sim.lap` between standstill and
  the friction-limited speed), friction-limited speed ``e_i <= v_max,i^2 / 2`` (the QSS apex
  speeds and the braking limit integrated backward from them: braking is free below it);
* battery energy of a step ``E_b,i = max(alpha W_m, W_m / alpha) + k W_m^2 / dt_i`` (a convex
  loss model: a linear efficiency ``alpha >= 1`` and a resistive term ``k`` [1/W], both fitted
  to the architecture's own power flow: the wheel power the envelope of
  :func:`hevsim.sim.performance.wheel_force_envelope` adds per battery power limit);
* budgets: ``sum E_b,i <= B`` (net deployment per lap; 0: charge-sustaining) and
  ``sum W_e / eta_e <= F`` (fuel energy per lap; ``eta_e`` the engine's mean wheel-to-fuel
  efficiency on the vehicle's QSS lap without the battery); the cumulative battery energy stays
  inside the window ``E_lo <= E_i <= E_hi``;
* objective ``sum dt_i + w_f sum W_e / eta_e`` (``w_f`` = :data:`FUEL_WEIGHT_S_PER_J`, a tie
  break between equally fast laps: 1 ms per MJ of fuel).

**Convex** (:func:`solve_convex`, cvxpy + Clarabel, the optional extra ``hevsim[lap]``): the
step time is relaxed to ``dt_i >= ds / 2 (u_i + u_{i+1})`` with ``u_i >= (2 e_i)^-1/2`` (a power
cone) and the battery energy to ``E_b,i >= ...`` (a quadratic-over-linear cone); both are
tight at the optimum (a longer step or a larger battery draw only costs). **DP**
(:func:`solve_dp`): two states on grids, the speed on per-step nodes between a lower and an
upper speed bound (the next speed is one of the next step's nodes: no interpolation in speed),
the cumulative battery energy on a uniform grid that holds the budget (linear interpolation of
the cost-to-go), the machine's work on ``n_p`` levels of ``P_m dt``; the engine takes the rest
of the wheel work (brakes when it is negative); the fuel budget by a multiplier (bisection)
when it binds. The compiled backward recursion is parallel over the speed nodes.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from numba import njit

from hevsim.errors import ConfigError, InputError
from hevsim.sim.lap import _accel, _braking_speed, _road
from hevsim.tracks import Track, load_track

FUEL_WEIGHT_S_PER_J = 1e-9
"""Objective weight of the fuel energy [s/J]: a tie break (1 ms per MJ of fuel)."""
FIT_LEVELS_W = (40e3, 120e3)
"""Battery power limits [W] at which the envelope's added wheel power fits the loss model."""
DEFAULT_WINDOW_J = 2.0e6
"""Default half-width of the cumulative battery-energy window around 0 and the budget [J]."""
BUDGET_TOL_J = 1.0
"""Tolerance of the battery budget [J] a solution is checked against (plus the DP's grid)."""
V_MIN_MPS = 1.0
"""Lowest speed of the problem [m/s] (the step time is 1/v)."""
CATCH_UP_S = 1.0
"""Forward replay: time [s] in which the supervisor catches up the battery energy by which
it is behind or ahead of the map."""


def _require_cvxpy() -> Any:
    try:
        import cvxpy as cp
    except ImportError:
        raise ConfigError(
            "--optimize convex needs cvxpy and Clarabel: install the optional extra "
            "`pip install 'hevsim[lap]'` (or use --optimize dp)."
        ) from None
    if "CLARABEL" not in cp.installed_solvers():
        raise ConfigError(
            "--optimize convex needs the Clarabel solver: install the optional extra "
            "`pip install 'hevsim[lap]'`."
        )
    return cp


# ------------------------------------------------------------------------------------------
# The problem
# ------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class DeployProblem:
    """One minimum-lap-time deployment problem (module docstring), SI; arrays per sample of
    the track rotated so that sample 0 is the slowest apex (``offset``: its index on the
    original track)."""

    vehicle: str
    track: str
    step_m: float
    offset: int
    distance_m: np.ndarray  # (N,) distance of each sample on the original track [m]
    e_max: np.ndarray  # (N,) friction-limited kinetic energy per mass [J/kg]
    trac_a_n: np.ndarray  # (N,) traction chord: force at standstill [N]
    trac_b_kg: np.ndarray  # (N,) its slope in e [N/(J/kg)] = [kg]
    road0_n: np.ndarray  # (N,) rolling + grade force [N]
    mass_eff_kg: float  # m * delta [kg]
    drag_kgpm: float  # 0.5 rho Cd A [kg/m]: drag force = drag_kgpm v^2 = 2 drag_kgpm e
    engine_power_w: float  # engine's largest wheel power [W]
    machine_power_w: float  # machine's largest wheel power [W]
    loss_alpha: float  # battery energy per wheel work, linear part [-] (>= 1)
    loss_k_per_w: float  # resistive part [1/W]
    engine_efficiency: float  # wheel work per fuel energy [-]
    budget_j: float  # net battery energy per lap [J]
    fuel_budget_j: float  # fuel energy per lap [J] (inf: none)
    window_j: tuple[float, float]  # cumulative battery energy window [J]
    engine_power_i_w: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0))
    machine_power_i_w: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0))
    v_lo: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0))  # DP speed band [m/s]
    v_hi: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0))
    battery_discharge_max_w: float = math.inf  # battery chemical power limit, discharge [W]
    battery_charge_max_w: float = math.inf  # battery chemical power limit, charge [W]

    @property
    def n(self) -> int:
        return int(self.e_max.size)

    @property
    def machine_deploy_i_w(self) -> np.ndarray:
        """Largest machine wheel power [W] per sample (deploy): the machine's own and the one
        whose battery power (the loss model) is the battery's discharge limit."""
        cap = machine_power_at_battery_limit(
            self.battery_discharge_max_w, self.loss_alpha, self.loss_k_per_w, charge=False
        )
        return np.minimum(self.machine_power_i_w, cap)

    @property
    def machine_harvest_i_w(self) -> np.ndarray:
        """Largest machine wheel power [W] per sample (harvest, > 0): the machine's own and the
        one whose battery charge power (the loss model) is the battery's charge limit."""
        cap = machine_power_at_battery_limit(
            self.battery_charge_max_w, self.loss_alpha, self.loss_k_per_w, charge=True
        )
        return np.minimum(self.machine_power_i_w, cap)

    def with_battery(
        self,
        *,
        discharge_max_w: float = math.inf,
        charge_max_w: float = math.inf,
        budget_j: float | None = None,
        window_j: tuple[float, float] | None = None,
    ) -> DeployProblem:
        """The same problem with the battery's chemical power limits [W] (discharge, charge;
        inf: none), and optionally another budget [J] and energy window [J] (a stint's pack
        state at the start of a lap)."""
        import dataclasses

        for key, val in (("discharge_max_w", discharge_max_w), ("charge_max_w", charge_max_w)):
            if math.isnan(val) or val < 0.0:
                raise ConfigError(f"battery {key} = {val!r} W: expected a power >= 0 W (inf: no limit).")
        return dataclasses.replace(
            self,
            battery_discharge_max_w=float(discharge_max_w),
            battery_charge_max_w=float(charge_max_w),
            budget_j=self.budget_j if budget_j is None else float(budget_j),
            window_j=self.window_j if window_j is None else (float(window_j[0]), float(window_j[1])),
        )

    def battery_energy_j(self, w_m: np.ndarray, dt: np.ndarray) -> np.ndarray:
        """Battery energy [J] of machine wheel work ``w_m`` [J] over steps ``dt`` [s]."""
        a = self.loss_alpha
        return np.maximum(a * w_m, w_m / a) + self.loss_k_per_w * w_m**2 / dt

    def describe(self) -> dict[str, Any]:
        return {
            "engine_wheel_power_kw": self.engine_power_w / 1e3,
            "machine_wheel_power_kw": self.machine_power_w / 1e3,
            "battery_loss_alpha": self.loss_alpha,
            "battery_loss_k_per_mw": self.loss_k_per_w * 1e6,
            "engine_wheel_efficiency": self.engine_efficiency,
            "budget_kj": self.budget_j / 1e3,
            "fuel_budget_kj": self.fuel_budget_j / 1e3,
            "window_kj": [w / 1e3 for w in self.window_j],
            "battery_discharge_max_kw": self.battery_discharge_max_w / 1e3,
            "battery_charge_max_kw": self.battery_charge_max_w / 1e3,
            "step_m": self.step_m,
            "samples": self.n,
        }


def machine_power_at_battery_limit(power_w: float, alpha: float, k_per_w: float, *, charge: bool) -> float:
    """Machine wheel power [W] (> 0) whose battery chemical power under the loss model
    (``alpha p + k p^2`` deploying, ``p / alpha + k p^2`` harvesting, ``p < 0``) is the limit
    ``power_w`` [W] (discharge, or charge with ``charge``); inf when the limit is inf or, when
    charging, beyond the model's largest charge power ``1 / (4 alpha^2 k)``."""
    if not math.isfinite(power_w):
        return math.inf
    if charge:
        lin = 1.0 / alpha
        disc = lin * lin - 4.0 * k_per_w * power_w
        if disc < 0.0:
            return math.inf
        return 2.0 * power_w / (lin + math.sqrt(disc))
    return 2.0 * power_w / (alpha + math.sqrt(alpha * alpha + 4.0 * k_per_w * power_w))


def _traction_force(veh: Any, trk: Track, v: np.ndarray) -> np.ndarray:
    """Traction-limited wheel force [N] at each sample at speeds ``v`` [m/s] (sim.lap's
    friction ellipse with load transfer; the powertrain left unlimited)."""
    p = np.array(veh.params(), np.float64)
    ev = np.array([0.0, 1e3])
    big = np.array([[1e12, 1e12]])
    lv = np.array([np.inf])
    th = np.arctan(trk.grade)
    out = np.empty(v.size)
    for i in range(v.size):
        a = _accel(v[i], trk.curvature_1pm[i], th[i], trk.banking_rad[i], p, ev, big, lv, np.inf)
        out[i] = p[0] * p[1] * a + _road(v[i], th[i], p)
    return out


def _fit_losses(speed: np.ndarray, rows: np.ndarray, levels: np.ndarray) -> tuple[float, float, float, float]:
    """(engine wheel power, machine wheel power [W], alpha [-], k [1/W]) from envelope rows:
    row 0 at battery limit 0, rows at :data:`FIT_LEVELS_W` and the unlimited last row."""
    pw = np.max(rows * speed[None, :], axis=1)
    p_e = float(pw[0])
    p_m = float(pw[-1] - pw[0])
    dp = pw[1:-1] - p_e
    lv = levels[1:-1]
    if p_m <= 0.0 or np.any(dp <= 0.0):
        raise InputError(
            "optimal deployment: the machine adds no wheel power with the battery (envelope rows "
            f"{pw.tolist()} W); expected a hybrid whose machine can deploy."
        )
    # L = alpha dP + k dP^2 through the two fit points
    a_mat = np.column_stack([dp, dp**2])
    alpha, k = np.linalg.solve(a_mat, lv)
    alpha = max(float(alpha), 1.0)
    k = max(float((lv[-1] - alpha * dp[-1]) / dp[-1] ** 2), 0.0)
    return p_e, p_m, alpha, k


def build_problem(
    model: Any,
    track: Track | str | Path,
    *,
    step_m: float = 10.0,
    budget_kj: float = 0.0,
    fuel_budget_kg: float | None = None,
    window_kj: float | None = None,
    soc: float | None = None,
) -> tuple[DeployProblem, Any]:
    """The :class:`DeployProblem` of a vehicle (file, configuration or model) on a track at
    ``step_m`` [m] with a net battery deployment ``budget_kj`` [kJ] per lap (0:
    charge-sustaining), an optional fuel budget [kg] per lap and the half-width of the
    cumulative battery-energy window [kJ] (default :data:`DEFAULT_WINDOW_J`, cut to the
    battery's SOC window). Returns the problem and the :class:`~hevsim.sim.lap.LapVehicle`
    (its envelope rows at battery limits 0, :data:`FIT_LEVELS_W` and unlimited, for replay)."""
    from hevsim.config import load_vehicle_config
    from hevsim.fuels import config_fuel
    from hevsim.sim.lap import lap_vehicle, simulate_lap

    if isinstance(model, str | Path):
        model = load_vehicle_config(model)
    cfg = getattr(model, "config", model)
    if not (math.isfinite(step_m) and 0.5 <= step_m <= 50.0):
        raise ConfigError(f"option --step = {step_m!r}: expected 0.5 to 50 m for an optimal deployment.")
    if not math.isfinite(budget_kj):
        raise ConfigError(f"option --budget-kj = {budget_kj!r}: expected a finite energy [kJ].")
    if fuel_budget_kg is not None and not (math.isfinite(fuel_budget_kg) and fuel_budget_kg > 0):
        raise ConfigError(f"option --fuel-budget-kg = {fuel_budget_kg!r}: expected a fuel mass > 0 kg.")
    trk = track if isinstance(track, Track) else load_track(track, step_m=step_m)
    if isinstance(track, Track) and abs(track.step_m - step_m) > 1e-9 * step_m:
        trk = track.resampled(step_m)
    if getattr(cfg, "battery", None) is None:
        raise ConfigError(f"vehicle '{cfg.name}': an optimal deployment needs a battery ([battery]).")
    levels = np.array([0.0, *FIT_LEVELS_W, 1e7])
    veh = lap_vehicle(model, soc=soc, battery_levels_w=levels)
    trk.check_radius(veh.min_turning_radius_m, f"vehicle '{cfg.name}'")
    lv, table = veh.force_table
    p_e, p_m, alpha, k = _fit_losses(veh.envelope_speed_mps, table, lv)
    # engine efficiency: the QSS lap without the battery
    ref = simulate_lap(model, trk, vehicle=veh, battery_power_max_w=0.0, step_m=trk.step_m)
    wheel = ref.timeseries["wheel_power_w"].to_numpy() * ref.timeseries["dt_s"].to_numpy()
    e_fuel = float(ref.summary.get("fuel_energy_j", 0.0))
    # engine and machine wheel power at each sample: the envelope at the reference lap's speed
    v_ref = ref.timeseries["speed_mps"].to_numpy()
    ev = veh.envelope_speed_mps
    p_e_i = np.interp(v_ref, ev, table[0]) * v_ref
    p_m_i = np.maximum(np.interp(v_ref, ev, table[-1]) * v_ref - p_e_i, 0.0)
    e_batt = float(ref.summary.get("battery_chemical_energy_j", 0.0))
    eta = (float(np.sum(np.maximum(wheel, 0.0))) - e_batt) / e_fuel if e_fuel > 0 else 0.3
    eta = float(min(max(eta, 0.05), 0.6))
    lhv = float(config_fuel(cfg, getattr(veh.envelope.model, "engine", None)).lower_heating_value_j_per_kg)
    fuel_j = math.inf if fuel_budget_kg is None else fuel_budget_kg * lhv

    p = np.array(veh.params(), np.float64)
    v_f, _, i0 = _braking_speed(
        np.ascontiguousarray(trk.curvature_1pm, np.float64),
        np.arctan(trk.grade),
        np.ascontiguousarray(trk.banking_rad, np.float64),
        float(trk.step_m),
        p,
        veh.speed_cap_mps,
    )
    if np.any(v_f <= V_MIN_MPS):
        j = int(np.flatnonzero(v_f <= V_MIN_MPS)[0])
        raise InputError(
            f"optimal deployment on '{trk.name}': the friction-limited speed is {v_f[j]:.2f} m/s at "
            f"distance {trk.distance_m[j]:.1f} m; expected a track the vehicle can drive round."
        )
    order = (np.arange(trk.distance_m.size) + i0) % trk.distance_m.size
    f_trac0 = _traction_force(veh, trk, np.full(v_f.size, 0.5))
    f_trac1 = _traction_force(veh, trk, v_f)
    e_max = 0.5 * v_f**2
    b = (f_trac1 - f_trac0) / (e_max - 0.125)
    a = f_trac0 - b * 0.125
    from hevsim.components.body import grade_force, rolling_force

    road0 = rolling_force(veh.mass_kg, trk.grade, veh.rolling_resistance, 0.0, 1.0) + grade_force(
        veh.mass_kg, trk.grade
    )
    if window_kj is not None and not (math.isfinite(window_kj) and window_kj > 0):
        raise ConfigError(f"option --window-kj = {window_kj!r}: expected an energy > 0 kJ.")
    half = DEFAULT_WINDOW_J if window_kj is None else window_kj * 1e3
    budget = budget_kj * 1e3
    lo, hi = min(0.0, budget) - half, max(0.0, budget) + half
    batt_j = _battery_window_j(veh, cfg)
    if batt_j is not None:
        lo, hi = max(lo, -batt_j[1]), min(hi, batt_j[0])
        if budget > batt_j[0] or budget < -batt_j[1]:
            raise ConfigError(
                f"option --budget-kj = {budget_kj:g}: the battery holds {batt_j[0] / 1e3:.0f} kJ to deploy "
                f"and {batt_j[1] / 1e3:.0f} kJ to store between its SOC limits; expected a budget inside."
            )
    prob = DeployProblem(
        vehicle=cfg.name,
        track=trk.name,
        step_m=float(trk.step_m),
        offset=int(i0),
        distance_m=trk.distance_m[order].copy(),
        e_max=e_max[order].copy(),
        trac_a_n=a[order].copy(),
        trac_b_kg=b[order].copy(),
        road0_n=np.broadcast_to(road0, v_f.shape)[order].astype(np.float64),
        mass_eff_kg=veh.mass_kg * veh.mass_factor,
        drag_kgpm=0.5 * veh.air_density_kgpm3 * veh.drag_coefficient * veh.frontal_area_m2,
        engine_power_w=p_e,
        machine_power_w=p_m,
        engine_power_i_w=np.maximum(p_e_i, 0.0)[order].copy(),
        machine_power_i_w=p_m_i[order].copy(),
        loss_alpha=alpha,
        loss_k_per_w=k,
        engine_efficiency=eta,
        budget_j=budget,
        fuel_budget_j=fuel_j,
        window_j=(float(lo), float(hi)),
    )
    pe_i, pm_i = prob.engine_power_i_w, prob.machine_power_i_w
    v_lo = _bound_profile(prob, pe_i - pm_i, lower=True)
    v_hi = _bound_profile(prob, pe_i + pm_i, lower=False)
    prob = DeployProblem(**{**prob.__dict__, "v_lo": v_lo, "v_hi": v_hi})
    return prob, veh


def _battery_window_j(veh: Any, cfg: Any) -> tuple[float, float] | None:
    """(energy to deploy, energy to store) [J] between the SOC limits and the lap's SOC."""
    b = cfg.battery
    model = veh.envelope.model
    batt = getattr(model, "battery", None)
    if batt is None:
        return None
    try:
        e_soc = float(batt.capacity_ah) * 3600.0 * float(batt.ocv(float(veh.envelope.soc)))
    except (AttributeError, TypeError):
        return None
    soc = float(veh.envelope.soc)
    return (soc - float(b.soc_min)) * e_soc, (float(b.soc_max) - soc) * e_soc


def _bound_profile(prob: DeployProblem, power_w: np.ndarray, *, lower: bool) -> np.ndarray:
    """Speed [m/s] of forward integration at a wheel power [W] (and the traction chord) from
    the first sample's friction speed, capped by the friction speed: the DP's speed band
    (lower: engine minus full harvest, widened by 5 %; upper: engine plus full deployment,
    widened by 2 %)."""
    n, ds, m = prob.n, prob.step_m, prob.mass_eff_kg
    e = np.empty(n)
    e[0] = prob.e_max[0]
    for i in range(n - 1):
        v = math.sqrt(2.0 * e[i])
        f = min(max(power_w[i], 0.0) / v, prob.trac_a_n[i] + prob.trac_b_kg[i] * e[i])
        de = (f - prob.drag_kgpm * 2.0 * e[i] - prob.road0_n[i]) * ds / m
        e[i + 1] = min(max(e[i] + de, 0.5 * V_MIN_MPS**2), prob.e_max[i + 1])
    vs = np.sqrt(2.0 * e)
    vmax = np.sqrt(2.0 * prob.e_max)
    if lower:
        out = np.maximum(0.95 * vs, V_MIN_MPS)
    else:
        out = np.minimum(1.02 * vs, vmax)
    out[0] = vmax[0]
    return out


# ------------------------------------------------------------------------------------------
# The result
# ------------------------------------------------------------------------------------------
@dataclass
class DeployResult:
    """An optimal deployment: per-sample speed [m/s] and per-step works [J] on the problem's
    (rotated) grid; ``lap_time_s`` from the speeds (trapezoid on the slowness)."""

    problem: DeployProblem
    method: str
    speed_mps: np.ndarray
    engine_work_j: np.ndarray
    machine_work_j: np.ndarray
    solve_time_s: float
    info: dict[str, Any] = field(default_factory=dict)

    @property
    def dt_s(self) -> np.ndarray:
        v = self.speed_mps
        return 0.5 * self.problem.step_m * (1.0 / v + 1.0 / np.roll(v, -1))

    @property
    def lap_time_s(self) -> float:
        return float(np.sum(self.dt_s))

    @property
    def battery_energy_j(self) -> np.ndarray:
        """Battery energy of each step [J] (the loss model)."""
        return self.problem.battery_energy_j(self.machine_work_j, self.dt_s)

    @property
    def battery_power_w(self) -> np.ndarray:
        return self.battery_energy_j / self.dt_s

    def summary(self) -> dict[str, Any]:
        eb = self.battery_energy_j
        p = self.problem
        return {
            "method": self.method,
            "vehicle": p.vehicle,
            "track": p.track,
            "lap_time_s": self.lap_time_s,
            "battery_net_energy_kj": float(eb.sum()) / 1e3,
            "battery_deployed_kj": float(np.sum(np.maximum(eb, 0))) / 1e3,
            "battery_harvested_kj": float(-np.sum(np.minimum(eb, 0))) / 1e3,
            "fuel_energy_kj": float(np.sum(self.engine_work_j) / p.engine_efficiency) / 1e3,
            "budget_kj": p.budget_j / 1e3,
            "solve_time_s": self.solve_time_s,
            **{k: v for k, v in self.info.items() if isinstance(v, int | float | str)},
        }

    def frame(self) -> pd.DataFrame:
        """The deployment map on the original track's distance (sorted): distance [m], speed
        [m/s], battery, machine and engine power [W] of the step starting there, battery energy
        used from the track's start to the end of the step [J], step time [s]."""
        p = self.problem
        dt = self.dt_s
        df = pd.DataFrame(
            {
                "distance_m": p.distance_m,
                "speed_mps": self.speed_mps,
                "battery_power_w": self.battery_power_w,
                "machine_power_w": self.machine_work_j / dt,
                "engine_power_w": self.engine_work_j / dt,
                "battery_energy_j": self.battery_energy_j,
                "dt_s": dt,
            }
        )
        df = df.sort_values("distance_m", kind="stable").reset_index(drop=True)
        df.insert(5, "battery_energy_used_j", np.cumsum(df.pop("battery_energy_j").to_numpy()))
        return df

    def save(
        self,
        out_dir: str | Path,
        *,
        plots: bool = True,
        force: bool = False,
        extra: dict[str, Any] | None = None,
        replay: Any = None,
    ) -> Path:
        """deploy_map.csv, deploy_summary.json and (plots) deploy.png, atomically; with
        ``replay`` (the :class:`~hevsim.sim.lap.LapResult` of the map replayed in the QSS lap)
        also its lap.csv, summary.json and metadata.json (and plots):
        :meth:`hevsim.sim.lap.LapResult.write`."""
        from hevsim.io import atomic_directory, write_json

        with atomic_directory(out_dir, force=force) as tmp:
            self.frame().to_csv(tmp / "deploy_map.csv", index=False, float_format="%.8g")
            summ = {**self.summary(), "problem": self.problem.describe()}
            if extra:
                summ.update(extra)
            write_json(tmp / "deploy_summary.json", summ)
            if plots:
                self.plot(tmp / "deploy.png")
            if replay is not None:
                replay.write(tmp, plots)
        return Path(out_dir)

    def plot(self, path: str | Path, soc_energy_j: float | None = None) -> Path:
        """Speed, battery/machine power and cumulative battery energy vs distance."""
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        from hevsim.io import save_png

        df = self.frame()
        fig, ax = plt.subplots(3, 1, figsize=(10, 7.5), sharex=True)
        ax[0].plot(df["distance_m"], df["speed_mps"] * 3.6, lw=1)
        ax[0].set_ylabel("speed [km/h]")
        ax[0].set_title(
            f"{self.problem.vehicle} on {self.problem.track}: {self.method}, {self.lap_time_s:.3f} s, "
            f"budget {self.problem.budget_j / 1e3:.0f} kJ"
        )
        ax[1].plot(df["distance_m"], df["battery_power_w"] / 1e3, lw=1, label="battery")
        ax[1].plot(df["distance_m"], df["machine_power_w"] / 1e3, lw=0.8, label="machine (wheel)")
        ax[1].set_ylabel("power [kW] (deploy > 0)")
        ax[1].legend(loc="lower right")
        ax[2].plot(df["distance_m"], df["battery_energy_used_j"] / 1e3, lw=1)
        ax[2].set_ylabel("battery energy used [kJ]")
        ax[2].set_xlabel("distance [m]")
        for a in ax:
            a.grid(True)
        fig.tight_layout()
        out = save_png(fig, Path(path), 100)
        plt.close(fig)
        return out


# ------------------------------------------------------------------------------------------
# Convex
# ------------------------------------------------------------------------------------------
def solve_convex(prob: DeployProblem, *, verbose: bool = False) -> DeployResult:
    """The problem as a second-order-cone/power-cone program (cvxpy + Clarabel)."""
    cp = _require_cvxpy()
    n, ds, m = prob.n, prob.step_m, prob.mass_eff_kg
    t0 = time.perf_counter()
    # scaled variables: kinetic energy per mass [kJ/kg], works and energies [kJ]
    kj = 1e3
    e = cp.Variable(n)
    u = cp.Variable(n)
    dt = cp.Variable(n)
    we = cp.Variable(n)
    wm = cp.Variable(n)
    wb = cp.Variable(n)
    eb = cp.Variable(n)
    q = cp.Variable(n)
    e1 = cp.hstack([e[1:], e[:1]])
    u1 = cp.hstack([u[1:], u[:1]])
    a = prob.loss_alpha
    pe, pm_d, pm_c = prob.engine_power_i_w / kj, prob.machine_deploy_i_w / kj, prob.machine_harvest_i_w / kj
    cons = [
        m * (e1 - e) == we + wm - wb - ds * (prob.drag_kgpm * (e + e1) + prob.road0_n / kj),
        u >= cp.power(2.0 * kj * e, -0.5),
        dt >= 0.5 * ds * (u + u1),
        e <= prob.e_max / kj,
        e >= 0.5 * V_MIN_MPS**2 / kj,
        e[0] == prob.e_max[0] / kj,
        we >= 0,
        we <= cp.multiply(pe, dt),
        wm <= cp.multiply(pm_d, dt),
        wm >= -cp.multiply(pm_c, dt),
        wb >= 0,
        we + wm <= ds * (prob.trac_a_n / kj + cp.multiply(prob.trac_b_kg, e)),
        # battery energy: linear part (deploy alpha, harvest 1/alpha) + resistive wm^2/dt, with
        # q_i >= wm_i^2 / dt_i as the rotated cone || (2 wm_i, q_i - dt_i) || <= q_i + dt_i
        cp.SOC(q + dt, cp.vstack([2 * wm, q - dt]), axis=0),
        eb >= a * wm + prob.loss_k_per_w * kj * q,
        eb >= wm / a + prob.loss_k_per_w * kj * q,
    ]
    cum = cp.cumsum(eb)
    cons += [cum[-1] <= prob.budget_j / kj, cum >= prob.window_j[0] / kj, cum <= prob.window_j[1] / kj]
    fuel = cp.sum(we) / prob.engine_efficiency
    if math.isfinite(prob.fuel_budget_j):
        cons.append(fuel <= prob.fuel_budget_j / kj)
    obj = cp.Minimize(cp.sum(dt) + FUEL_WEIGHT_S_PER_J * kj * fuel)
    problem = cp.Problem(obj, cons)
    try:
        problem.solve(solver="CLARABEL", verbose=verbose)
    except cp.error.SolverError as exc:
        raise InputError(f"optimal deployment (convex): the solver failed ({exc}).") from None
    if problem.status not in ("optimal", "optimal_inaccurate"):
        raise InputError(_infeasible_message(prob, "convex", problem.status))
    v = np.sqrt(2.0 * np.maximum(kj * np.asarray(e.value), 0.5 * V_MIN_MPS**2))
    res = DeployResult(
        prob,
        "convex",
        v,
        kj * np.asarray(we.value, np.float64),
        kj * np.asarray(wm.value, np.float64),
        time.perf_counter() - t0,
        {
            "status": str(problem.status),
            "objective_s": float(problem.value),
            "relaxation_gap_s": float(np.sum(dt.value))
            - float(np.sum(0.5 * ds * (1 / v + 1 / np.roll(v, -1)))),
        },
    )
    return res


# ------------------------------------------------------------------------------------------
# DP
# ------------------------------------------------------------------------------------------
@njit(cache=True)
def _split_cost(w, dt, trac, pe, pm, pmc, alpha, kl, eta, lam, wf):
    """Best machine work [J] for a step needing wheel work ``w`` [J] over ``dt`` [s]:
    minimises ``lam E_b(wm) + wf max(w - wm, 0) / eta`` (convex in wm) on the feasible interval
    (engine 0..pe dt, machine -pmc dt..pm dt, traction); returns (cost, wm, engine work) or
    (inf, 0, 0)."""
    if w > trac + 1e-9 or w > (pe + pm) * dt:
        return np.inf, 0.0, 0.0
    lower = max(-pmc * dt, w - pe * dt)
    upper = pm * dt
    if w > lower and w < upper:
        upper = max(w, 0.0) if w > 0.0 else upper
    has_k = kl > 0.0 and lam > 0.0
    r = wf / (eta * lam) if has_k else 0.0
    best = np.inf
    bw = 0.0
    for q in range(8):
        if q == 0:
            c = lower
        elif q == 1:
            c = upper
        elif q == 2:
            c = 0.0
        elif q == 3:
            c = w
        elif not has_k:
            break
        elif q == 4:
            c = (r - 1.0 / alpha) * dt / (2.0 * kl)
        elif q == 5:
            c = -dt / (2.0 * alpha * kl)
        elif q == 6:
            c = (r - alpha) * dt / (2.0 * kl)
        else:
            c = -alpha * dt / (2.0 * kl)
        wm = min(max(c, lower), upper)
        we = w - wm
        if we < 0.0:
            we = 0.0
        eb = max(alpha * wm, wm / alpha) + kl * wm * wm / dt
        cost = lam * eb + wf * we / eta
        if cost < best:
            best = cost
            bw = wm
    we = w - bw
    return best, bw, (we if we > 0.0 else 0.0)


@njit(cache=True)
def _backward(nodes, ds, m, cd, road0, ta, tb, pe, pm, pmc, alpha, kl, eta, lam, wf):
    """Cost-to-go (N+1, nv) [s] and arg-min next node (N, nv) over the per-step kinetic-energy
    nodes (N+1, nv) [J/kg]: cost = step time + lam x battery energy + wf x fuel energy."""
    n1, nv = nodes.shape
    n = n1 - 1
    J = np.full((n1, nv), np.inf)
    arg = np.full((n, nv), -1, np.int64)
    J[n, :] = 0.0
    for i in range(n - 1, -1, -1):
        for a in range(nv):
            e0 = nodes[i, a]
            trac = ds * (ta[i] + tb[i] * e0)
            best = np.inf
            bj = -1
            for j in range(nv):
                if not np.isfinite(J[i + 1, j]):
                    continue
                e1 = nodes[i + 1, j]
                dt = 0.5 * ds * (1.0 / math.sqrt(2.0 * e0) + 1.0 / math.sqrt(2.0 * e1))
                w = m * (e1 - e0) + ds * (cd * (e0 + e1) + road0[i])
                c, _, _ = _split_cost(w, dt, trac, pe[i], pm[i], pmc[i], alpha, kl, eta, lam, wf)
                c += dt + J[i + 1, j]
                if c < best:
                    best = c
                    bj = j
            J[i, a] = best
            arg[i, a] = bj
    return J, arg


def _dp_nodes(v_lo: np.ndarray, v_hi: np.ndarray, n_v: int) -> np.ndarray:
    """Per-step kinetic-energy nodes (N+1, n_v) [J/kg]: uniform in speed between ``v_lo``
    and ``v_hi`` [m/s] (N,) (the lap's end repeats sample 0)."""
    frac = np.linspace(0.0, 1.0, n_v)
    lo = np.append(v_lo, v_lo[0])
    hi = np.append(v_hi, v_hi[0])
    v = lo[:, None] + (hi - lo)[:, None] * frac[None, :]
    return np.ascontiguousarray(0.5 * v**2)


def _dp_nodes_around(prob: DeployProblem, v: np.ndarray, w: np.ndarray, n_v: int) -> np.ndarray:
    """Nodes (N+1, n_v) [J/kg] centred on the speeds ``v`` [m/s] (the middle node) +/- ``w``,
    clipped to the problem's band (repeated nodes where clipped)."""
    frac = np.linspace(-1.0, 1.0, n_v)
    vv = v[:, None] + w[:, None] * frac[None, :]
    vv = np.clip(vv, prob.v_lo[:, None], np.maximum(prob.v_hi, v)[:, None])
    vv[0, :] = v[0]
    vv = np.vstack([vv, vv[:1]])
    return np.ascontiguousarray(0.5 * vv**2)


def _dp_path(prob: DeployProblem, nodes: np.ndarray, lam: float, wf: float) -> tuple[np.ndarray, ...]:
    """(speed [m/s], engine work [J], machine work [J]) of the DP's optimal path at the
    multipliers ``lam`` [s/J] (battery) and ``wf`` [s/J] (fuel)."""
    pr = prob
    args = (
        pr.step_m,
        pr.mass_eff_kg,
        pr.drag_kgpm,
        np.ascontiguousarray(pr.road0_n),
        np.ascontiguousarray(pr.trac_a_n),
        np.ascontiguousarray(pr.trac_b_kg),
        np.ascontiguousarray(pr.engine_power_i_w),
        np.ascontiguousarray(pr.machine_deploy_i_w),
        np.ascontiguousarray(pr.machine_harvest_i_w),
        pr.loss_alpha,
        pr.loss_k_per_w,
        pr.engine_efficiency,
    )
    J, arg = _backward(nodes, *args, lam, wf)
    if not np.isfinite(J[0, 0]):
        raise InputError(_infeasible_message(prob, "dp", "no speed profile in the band"))
    n = prob.n
    idx = np.empty(n + 1, np.int64)
    idx[0] = 0
    for i in range(n):
        idx[i + 1] = arg[i, idx[i]]
    e = nodes[np.arange(n + 1), idx]
    dt = 0.5 * prob.step_m * (1.0 / np.sqrt(2.0 * e[:-1]) + 1.0 / np.sqrt(2.0 * e[1:]))
    w = prob.mass_eff_kg * (e[1:] - e[:-1]) + prob.step_m * (prob.drag_kgpm * (e[:-1] + e[1:]) + prob.road0_n)
    trac = prob.step_m * (prob.trac_a_n + prob.trac_b_kg * e[:-1])
    we = np.empty(n)
    wm = np.empty(n)
    for i in range(n):
        _, wm[i], we[i] = _split_cost(
            w[i],
            dt[i],
            trac[i],
            args[6][i],
            args[7][i],
            args[8][i],
            pr.loss_alpha,
            pr.loss_k_per_w,
            pr.engine_efficiency,
            lam,
            wf,
        )
    return np.sqrt(2.0 * e[:-1]), we, wm


def _dp_lambda(
    prob: DeployProblem, nodes: np.ndarray, wf: float, iters: int, guess: float = 0.0
) -> tuple[float, tuple[np.ndarray, ...]]:
    """Smallest battery multiplier [s/J] whose DP path meets the budget (bisection on a log
    scale) and that path."""

    def net(path: tuple[np.ndarray, ...]) -> float:
        v = path[0]
        dt = 0.5 * prob.step_m * (1 / v + 1 / np.roll(v, -1))
        return float(np.sum(prob.battery_energy_j(path[2], dt)))

    tol = BUDGET_TOL_J
    p0 = _dp_path(prob, nodes, 0.0, wf)
    if net(p0) <= prob.budget_j + tol:
        return 0.0, p0
    lo, hi = (guess / 2.0, guess * 2.0) if guess > 0.0 else (1e-9, 1e-5)
    p_hi = _dp_path(prob, nodes, hi, wf)
    if guess > 0.0 and net(p_hi) > prob.budget_j + tol:
        lo, hi = hi, hi * 10.0
        p_hi = _dp_path(prob, nodes, hi, wf)
    elif guess > 0.0 and net(_dp_path(prob, nodes, lo, wf)) <= prob.budget_j + tol:
        lo = 1e-9
    while net(p_hi) > prob.budget_j + tol:
        lo, hi = hi, hi * 10.0
        if hi > 1e-1:
            raise InputError(_infeasible_message(prob, "dp", "budget"))
        p_hi = _dp_path(prob, nodes, hi, wf)
    for _ in range(iters):
        mid = math.sqrt(lo * hi)
        p = _dp_path(prob, nodes, mid, wf)
        if net(p) <= prob.budget_j + tol:
            hi, p_hi = mid, p
        else:
            lo = mid
        if hi / lo < 1.0 + 1e-5:
            break
    return hi, p_hi


def solve_dp(
    prob: DeployProblem,
    *,
    n_v: int = 31,
    passes: int = 6,
    shrink: float = 0.4,
    iters: int = 30,
    fuel_multiplier: float | None = None,
) -> DeployResult:
    """The problem by DP over distance (module docstring): ``n_v`` speed nodes per step and
    ``passes`` of iterative band refinement (Luus's iterative DP: pass 1 spans the problem's
    speed band, each further pass a band ``shrink`` times as wide centred on the previous
    optimal speed, so
    the speed resolution shrinks by ``shrink`` per pass); the battery budget by its
    multiplier (``iters`` bisection steps), the fuel budget by a second one when it binds."""
    if n_v < 3 or passes < 1 or iters < 1 or not 0.0 < shrink < 1.0:
        raise ConfigError(
            f"DP grids n_v={n_v}, passes={passes}, iters={iters}: expected n_v >= 3, >= 1 pass."
        )
    t0 = time.perf_counter()
    n_v += 1 - n_v % 2  # odd: the previous path is the middle node of a refined pass
    lo, hi = prob.v_lo.copy(), prob.v_hi.copy()
    vmax = np.sqrt(2.0 * prob.e_max)
    lo[0] = hi[0] = vmax[0]
    nodes = _dp_nodes(lo, hi, n_v)
    w = (hi - lo) / (n_v - 1)
    info: dict[str, Any] = {"n_v": n_v}
    path: tuple[np.ndarray, ...] = ()
    lam = 0.0
    for k in range(passes):
        wf = FUEL_WEIGHT_S_PER_J if fuel_multiplier is None else fuel_multiplier
        lam, path = _dp_lambda(prob, nodes, wf, iters, lam)
        if fuel_multiplier is None and math.isfinite(prob.fuel_budget_j):
            wf, lam, path = _dp_fuel(prob, nodes, iters)
        info.update(passes=k + 1, speed_step_mps=float(np.max(w)), battery_multiplier_s_per_mj=lam * 1e6)
        info["fuel_multiplier_s_per_mj"] = wf * 1e6
        w = shrink * w
        nodes = _dp_nodes_around(prob, path[0], w * (n_v - 1) / 2, n_v)
    res = DeployResult(prob, "dp", path[0], path[1], path[2], time.perf_counter() - t0, info)
    cum = np.cumsum(res.battery_energy_j)
    tol = BUDGET_TOL_J
    if cum.min() < prob.window_j[0] - tol or cum.max() > prob.window_j[1] + tol:
        k = int(np.flatnonzero((cum < prob.window_j[0] - tol) | (cum > prob.window_j[1] + tol))[0])
        raise InputError(
            f"optimal deployment (dp) of '{prob.vehicle}' on '{prob.track}': the cumulative battery energy "
            f"{cum[k] / 1e3:.0f} kJ leaves the window [{prob.window_j[0] / 1e3:.0f}, "
            f"{prob.window_j[1] / 1e3:.0f}] kJ at distance {prob.distance_m[k]:.1f} m "
            "(the DP keeps the budget by a multiplier, not the window); "
            "widen --window-kj or use --optimize convex."
        )
    return res


def _dp_fuel(
    prob: DeployProblem, nodes: np.ndarray, iters: int
) -> tuple[float, float, tuple[np.ndarray, ...]]:
    """Fuel budget by a multiplier on the fuel energy [s/J], bisected on a log scale, the
    battery multiplier solved inside."""

    def fuel(path: tuple[np.ndarray, ...]) -> float:
        return float(np.sum(path[1])) / prob.engine_efficiency

    lam, p = _dp_lambda(prob, nodes, FUEL_WEIGHT_S_PER_J, iters)
    if fuel(p) <= prob.fuel_budget_j:
        return FUEL_WEIGHT_S_PER_J, lam, p
    lo, hi = FUEL_WEIGHT_S_PER_J, 1e-3
    best = None
    for _ in range(20):
        mid = math.sqrt(lo * hi)
        try:
            lam_m, p = _dp_lambda(prob, nodes, mid, iters // 2)
        except InputError:
            lo = mid
            continue
        if fuel(p) <= prob.fuel_budget_j:
            best, hi = (mid, lam_m, p), mid
        else:
            lo = mid
        if hi / lo < 1.01:
            break
    if best is None:
        raise InputError(_infeasible_message(prob, "dp", "fuel"))
    return best


def _infeasible_message(prob: DeployProblem, method: str, status: str, **kw: Any) -> str:
    """Where along the track the budget fails: the cumulative battery energy of the
    maximum-harvest lap (the engine at full power and the machine harvesting at full power
    wherever the speed stays at its friction limit) first leaves the window, or the lap's end
    where it cannot come back to the budget."""
    where = _failure_location(prob)
    return (
        f"optimal deployment of '{prob.vehicle}' on '{prob.track}' ({method}: {status}): no deployment meets "
        f"the battery budget {prob.budget_j / 1e3:.1f} kJ"
        + (
            f" and the fuel budget {prob.fuel_budget_j / 1e3:.0f} kJ"
            if math.isfinite(prob.fuel_budget_j)
            else ""
        )
        + f" within the energy window [{prob.window_j[0] / 1e3:.0f}, {prob.window_j[1] / 1e3:.0f}] kJ; "
        + where
    )


def _failure_location(prob: DeployProblem) -> str:
    """Text naming the distance [m] at which the most-harvesting lap still misses the budget."""
    v = prob.v_lo.copy()
    n, ds = prob.n, prob.step_m
    dt = 0.5 * ds * (1.0 / v + 1.0 / np.roll(v, -1))
    wm = -prob.machine_harvest_i_w * dt
    eb = prob.battery_energy_j(wm, dt)
    # the harvest that pays: the loss model's most-charging machine power
    p_best = 1.0 / (2.0 * prob.loss_alpha * max(prob.loss_k_per_w, 1e-30))
    wm2 = -np.minimum(prob.machine_harvest_i_w, p_best) * dt
    eb = np.minimum(eb, prob.battery_energy_j(wm2, dt))
    cum = np.cumsum(eb)
    out = np.flatnonzero(cum < prob.window_j[0])
    if out.size:
        k = int(out[0])
        return (
            f"harvesting at full power the cumulative battery energy leaves the window at distance "
            f"{prob.distance_m[k]:.1f} m; expected a budget reachable from the lap's harvest."
        )
    k = int(np.argmin(cum))
    return (
        f"the most the lap can harvest is {-cum[-1] / 1e3:.1f} kJ (its last harvest at distance "
        f"{prob.distance_m[min(k, n - 1)]:.1f} m); expected a budget >= {cum[-1] / 1e3:.1f} kJ."
    )


# ------------------------------------------------------------------------------------------
# Replay and rule-based deployments
# ------------------------------------------------------------------------------------------
def rule_based(prob: DeployProblem, rule: str, level: float) -> np.ndarray:
    """Machine power fraction [-] per sample of a rule-based deployment: ``"flat"`` (the same
    fraction ``level`` of P_m everywhere), ``"straights"`` (deploy ``level`` where the friction
    speed is above its median, harvest elsewhere) or ``"late"`` (deploy ``level`` in the second
    half of the lap)."""
    n = prob.n
    if rule == "flat":
        return np.full(n, level)
    if rule == "straights":
        vm = np.sqrt(2 * prob.e_max)
        return np.where(vm > np.median(vm), level, -level)
    if rule == "late":
        return np.where(np.arange(n) >= n // 2, level, -level)
    raise ConfigError(f"rule {rule!r}: expected flat, straights or late.")


def simulate_rule(prob: DeployProblem, fraction: np.ndarray) -> tuple[float, float]:
    """(lap time [s], net battery energy [J]) of the problem's model with the machine at
    ``fraction`` x P_m wherever the car accelerates (full engine, traction-limited), the
    friction speed as cap and braking below it: forward integration from sample 0, one lap.
    The same model and loss as the optimisation (a rule-based peer for the optimum)."""
    n, ds, m = prob.n, prob.step_m, prob.mass_eff_kg
    e = np.empty(n + 1)
    e[0] = prob.e_max[0]
    wm = np.zeros(n)
    p_dep, p_har = prob.machine_deploy_i_w, prob.machine_harvest_i_w
    for i in range(n):
        e_nxt = prob.e_max[(i + 1) % n]
        v = math.sqrt(2 * e[i])
        frac = float(fraction[i])
        pm_i = p_dep[i] if frac >= 0.0 else p_har[i]
        # largest e1 reachable: engine + machine (fixed point on the step time)
        e1 = e[i]
        for _ in range(4):
            dt = 0.5 * ds * (1 / v + 1 / math.sqrt(2 * max(e1, 0.5)))
            w_max = min(
                (prob.engine_power_i_w[i] + frac * pm_i) * dt,
                ds * (prob.trac_a_n[i] + prob.trac_b_kg[i] * e[i]),
            )
            e1 = (w_max - ds * (prob.drag_kgpm * e[i] + prob.road0_n[i]) + m * e[i]) / (
                m + ds * prob.drag_kgpm
            )
        e1 = min(max(e1, 0.5 * V_MIN_MPS**2), e_nxt)
        dt = 0.5 * ds * (1 / v + 1 / math.sqrt(2 * e1))
        wm[i] = frac * pm_i * dt
        e[i + 1] = e1
    vs = np.sqrt(2 * e[:n])
    dts = 0.5 * ds * (1 / vs + 1 / np.roll(vs, -1))
    if e[n] < prob.e_max[0] * (1 - 1e-9):
        dts[-1] = 0.5 * ds * (1 / vs[-1] + 1 / math.sqrt(2 * e[n]))
    return float(dts.sum()), float(np.sum(prob.battery_energy_j(wm, dts)))


def read_deploy_map(path: str | Path, track: Track) -> np.ndarray:
    """The battery power limit [W] at each sample of ``track`` from a deployment map CSV
    (columns ``distance_m``, ``battery_power_w``; deploy > 0): positive parts, linear in
    distance, periodic over the lap."""
    path = Path(path)
    try:
        df = pd.read_csv(path)
    except (OSError, ValueError) as exc:
        raise InputError(f"deployment map {path}: cannot read it ({exc}).") from None
    for col in ("distance_m", "battery_power_w"):
        if col not in df.columns:
            raise InputError(
                f"deployment map {path}: column '{col}' is missing; expected distance_m, battery_power_w."
            )
    d = pd.to_numeric(df["distance_m"], errors="coerce").to_numpy(np.float64)
    p = pd.to_numeric(df["battery_power_w"], errors="coerce").to_numpy(np.float64)
    bad = np.flatnonzero(~np.isfinite(d) | ~np.isfinite(p))
    if bad.size:
        k = int(bad[0])
        raise InputError(
            f"deployment map {path}: row {k + 2} has distance_m = {df['distance_m'].iloc[k]!r}, "
            f"battery_power_w = {df['battery_power_w'].iloc[k]!r}; expected finite numbers."
        )
    if d.size < 2 or np.any(np.diff(d) <= 0):
        raise InputError(
            f"deployment map {path}: column 'distance_m' must increase strictly (at least 2 rows)."
        )
    if d[0] < -1e-6 or d[-1] > track.length_m + 1e-6:
        raise InputError(
            f"deployment map {path}: distance_m spans {d[0]:.1f} to {d[-1]:.1f} m; expected inside the track "
            f"'{track.name}' (0 to {track.length_m:.1f} m)."
        )
    lim = np.interp(track.distance_m, d, np.maximum(p, 0.0), period=track.length_m)
    return np.ascontiguousarray(lim)


def replay_qss(model: Any, track: Track, res: DeployResult, *, step_m: float, vehicle: Any = None) -> Any:
    """The deployment map of ``res`` replayed in the QSS lap (:func:`hevsim.sim.lap.simulate_lap`)
    at ``step_m`` [m]: its positive battery power as the battery power limit along the lap."""
    from hevsim.sim.lap import simulate_lap

    df = res.frame()
    trk = track if abs(track.step_m - step_m) <= 1e-9 * step_m else track.resampled(step_m)
    lim = np.interp(
        trk.distance_m, df["distance_m"], np.maximum(df["battery_power_w"], 0.0), period=trk.length_m
    )
    return simulate_lap(model, trk, step_m=step_m, battery_power_max_w=lim, vehicle=vehicle)


def run_cli(
    cfg: Any,
    track_arg: str,
    *,
    method: str,
    budget_kj: float,
    fuel_budget_kg: float | None,
    window_kj: float | None,
    step_m: float,
    deploy_step_m: float,
    soc: float | None,
    out: Path,
    plots: bool,
    force: bool,
) -> DeployResult:
    """``hevsim lap CONFIG TRACK --optimize METHOD``: the optimal deployment at
    ``deploy_step_m`` [m], replayed in the QSS lap at ``step_m`` [m], written to ``out``."""
    if method == "convex":
        _require_cvxpy()
    trk = load_track(track_arg, step_m=deploy_step_m)
    prob, _ = build_problem(
        cfg,
        trk,
        step_m=deploy_step_m,
        budget_kj=budget_kj,
        fuel_budget_kg=fuel_budget_kg,
        window_kj=window_kj,
        soc=soc,
    )
    res = solve_convex(prob) if method == "convex" else solve_dp(prob)
    lap_trk = load_track(track_arg, step_m=step_m)
    replay = replay_qss(cfg, lap_trk, res, step_m=step_m)  # as `hevsim lap --deploy` replays it
    extra = {
        "qss_replay_lap_time_s": replay.lap_time_s,
        "qss_replay_battery_chemical_energy_kj": float(replay.summary.get("battery_chemical_energy_j", 0.0))
        / 1e3,
    }
    res.save(out, plots=plots, force=force, extra=extra, replay=replay)
    res.info.update(extra)
    return res


__all__ = [
    "DeployProblem",
    "DeployResult",
    "build_problem",
    "read_deploy_map",
    "replay_qss",
    "rule_based",
    "run_cli",
    "simulate_rule",
    "solve_convex",
    "solve_dp",
]


def _follower_class() -> Any:
    import dataclasses

    from hevsim.control.parallel import _argmin_feasible, _GridController

    class BatteryPowerFollower(_GridController):
        """Forward-model supervisor that follows a battery chemical power [W] schedule in time
        (a deployment map replayed along the optimal speed trace): the feasible candidate
        control whose battery power is nearest the scheduled one (ties: less fuel power).

        Its candidates (gear, throttle) set the engine; the machine takes the rest of the wheel
        demand, and when braking it regenerates up to its own and the battery's limits. The
        map harvests less than that (its loss model's largest harvest is ``1 / (4 alpha^2 k)``),
        so the follower blends the brakes as the map does: it lowers the step's battery charge
        power limit to the map's harvest (none where the map deploys) and the friction brakes
        take the rest of the braking torque."""

        name = "deploy_map"

        def __init__(self, hev: Any, time_s: np.ndarray, power_w: np.ndarray, control_points: int) -> None:
            super().__init__(hev, control_points)
            self.time_s = np.asarray(time_s, np.float64)
            self.power_w = np.asarray(power_w, np.float64)
            # the map's cumulative battery energy [J] at the step boundaries (its power holds
            # over each step: exact piecewise-linear interpolation in time)
            self.energy_j = np.concatenate([[0.0], np.cumsum(self.power_w[:-1] * np.diff(self.time_s))])
            self.done_j = 0.0

        def reset(self, soc_initial: float) -> None:
            self.done_j = 0.0

        def update(self, step: Any, stage: Any) -> None:
            self.done_j += -float(np.ravel(stage.d_soc)[0]) * step.energy_per_soc_j

        def choose(self, step: Any) -> Any:
            # the map's power over the step plus the energy behind or ahead of it, caught up
            # in CATCH_UP_S
            t0 = step.time_s
            e_end = float(np.interp(t0 + step.dt_s, self.time_s, self.energy_j))
            e_now = float(np.interp(t0, self.time_s, self.energy_j))
            target = (e_end - e_now) / step.dt_s + (e_now - self.done_j) / max(CATCH_UP_S, step.dt_s)
            bs = step.battery_state
            if bs is not None:  # the map's harvest [W, chemical] as the terminal charge limit
                ocv = np.asarray(bs.ocv_v, np.float64)
                i_a = max(-target, 0.0) / ocv  # charging current at the map's chemical power [A]
                cap = (ocv + np.asarray(bs.r_charge_ohm, np.float64) * i_a) * i_a
                cap = np.minimum(bs.p_charge_max_w, cap)
                step.battery_state = dataclasses.replace(bs, p_charge_max_w=cap)
            st, feasible = step.evaluate(*self.controls)
            p_fuel = st.cost_kg / step.dt_s * self.lhv
            p_chem = -st.d_soc / step.dt_s * step.energy_per_soc_j
            cost = np.abs(p_chem - target) + 1e-3 * p_fuel
            return self.pick(_argmin_feasible(np.broadcast_to(cost, np.shape(feasible)), feasible))

    return BatteryPowerFollower


def replay_forward(model: Any, res: DeployResult, *, dt_s: float = 0.1) -> dict[str, float]:
    """The optimal lap replayed in the forward vehicle model (:func:`hevsim.sim.simulate`):
    the driver follows the optimal speed trace in time, the supervisor follows the map's
    battery power in time (:func:`_follower_class`). Returns the optimum's and the forward
    run's lap time [s] (the time at which the forward run has covered the lap's length), net,
    deployed and harvested battery chemical energy [J] (``forward_battery_net_j`` and
    ``forward_battery_deployed_j``: the battery's terminal energy), traction-limited time [s]
    and fuel [kg]."""
    from hevsim.config import load_vehicle_config
    from hevsim.cycles import DriveCycle
    from hevsim.sim.performance import wheel_force_envelope
    from hevsim.sim.simulator import simulate

    if isinstance(model, str | Path):
        model = load_vehicle_config(model)
    cfg = getattr(model, "config", model)
    v = np.append(res.speed_mps, res.speed_mps[0])
    t = np.concatenate([[0.0], np.cumsum(res.dt_s)])
    cycle = DriveCycle("optimal_lap", t, v, source=f"optimal deployment on {res.problem.track}")
    hev = wheel_force_envelope(model, np.array([10.0, 20.0])).model
    p_b = np.append(res.battery_power_w, res.battery_power_w[0])
    ctl = _follower_class()(hev, t, p_b, int(cfg.controller.control_points))
    sim = simulate(model, cycle, dt_s=dt_s, controller=ctl)
    ts = sim.timeseries
    d = np.concatenate(
        [[0.0], np.cumsum(0.5 * (ts["speed_mps"].to_numpy()[1:] + ts["speed_mps"].to_numpy()[:-1]) * dt_s)]
    )
    length = res.problem.step_m * res.problem.n
    tt = ts["time_s"].to_numpy()
    lap_t = (
        float(np.interp(length, d, tt))
        if d[-1] >= length
        else float(tt[-1] + (length - d[-1]) / max(v[-1], 1.0))
    )
    pb = ts["battery_power_w"].to_numpy()
    eb = res.battery_energy_j
    # chemical energy of each step [J], as the run's energy audit counts it (-dSOC Q OCV at the
    # step's start): the quantity the map's loss model and the follower's target are in
    soc = ts["soc"].to_numpy()
    e_chem = -np.diff(soc) * float(hev.battery.capacity_ah) * 3600.0 * ts["battery_ocv_v"].to_numpy()[:-1]
    return {
        "optimal_lap_time_s": res.lap_time_s,
        "forward_lap_time_s": lap_t,
        "optimal_battery_net_j": float(eb.sum()),
        "forward_battery_net_j": float(sim.metrics["battery_energy_wh"]["value"]) * 3600.0,
        "forward_battery_chemical_net_j": float(e_chem.sum()),
        "optimal_battery_deployed_j": float(np.sum(np.maximum(eb, 0.0))),
        "optimal_battery_harvested_j": float(-np.sum(np.minimum(eb, 0.0))),
        "forward_battery_chemical_deployed_j": float(np.sum(np.maximum(e_chem, 0.0))),
        "forward_battery_chemical_harvested_j": float(-np.sum(np.minimum(e_chem, 0.0))),
        "forward_battery_deployed_j": float(np.sum(np.maximum(pb, 0.0)) * dt_s),
        "forward_traction_limited_s": float(sim.metrics["traction_limited_s"]["value"]),
        "forward_fuel_kg": float(sim.metrics["fuel_kg"]["value"]),
    }
