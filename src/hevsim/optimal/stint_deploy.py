"""A stint with the optimal deployment re-solved as the pack derates (issue 29 item 4 with item 3).

:func:`hevsim.sim.stint.simulate_stint` drives N laps with the whole pack; here each lap's
deployment is the optimal one of :mod:`hevsim.optimal.lap_deploy` (minimum lap time under a
battery energy budget per lap), solved for the pack's state at the start of the lap:

1. **The problem** is built once per stint (:func:`hevsim.optimal.lap_deploy.build_problem`
   at ``deploy_step_m``, the envelope at the stint's initial SOC).
2. **At the start of each lap** the pack's BMS gives its discharge and charge current limits
   (temperature derating at the hottest cell, SOC factors, the cells' voltage limits; none
   below ``soc_min`` / above ``soc_max``), which become battery chemical power limits
   ``P = OCV I`` (the nominal battery's OCV at the stint's initial SOC, as the stint's lap
   uses). In the problem they bound the machine's wheel power through the loss model
   (:meth:`~hevsim.optimal.lap_deploy.DeployProblem.with_battery`: the largest deploy and
   harvest power whose battery power is the limit). The pack's SOC sets the energy state: the
   lap's budget is at most the energy above ``soc_min`` (``budget_kj`` otherwise) and the
   cumulative battery energy stays between the energy to ``soc_max`` and to ``soc_min``.
3. **Re-optimise when they changed**: the problem is re-solved when either power limit differs
   from the one the deployment in use was solved for by more than ``reoptimize_rtol`` of it
   (or the budget or the energy window moved by more than ``reoptimize_rtol`` of the window's
   half-width); ``reoptimize_rtol = 0`` re-solves before every lap, ``inf`` solves once, before
   the first lap (a stint *without* re-optimisation).
4. **The lap** drives the map: its deploying battery power along the lap (the map's steps
   interpolated onto the lap's samples, as ``hevsim lap --deploy`` replays it), capped at the
   lap-start discharge limit, is the lap's ``battery_power_max_w``; the stint then steps the
   pack along it and lowers it where the pack heats further during the lap (its passes).

Per lap the table gains ``reoptimized`` (1 when solved before this lap), the limits the map in
use was solved for (``deploy_discharge_limit_kw``, ``deploy_charge_limit_kw``), the map's
largest battery power (``deploy_map_max_kw``), its budget, its own lap time
(``deploy_lap_time_s``) and the solver's time (``deploy_solve_s``).
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from hevsim.errors import ConfigError
from hevsim.optimal.lap_deploy import DeployProblem, DeployResult, build_problem
from hevsim.sim.stint import DeploymentPlan, StintResult, simulate_stint, stint_vehicle
from hevsim.tracks import DEFAULT_STEP_M, Track, load_track

REOPTIMIZE_RTOL = 0.02
"""Default relative change of a BMS power limit (or of the budget / energy window, relative to
the window's half-width) since the last solve that re-solves the deployment [-]."""
DEPLOY_STEP_M = 10.0
"""Default distance step of the deployment problem [m]."""
METHODS = ("convex", "dp")
"""Deployment solvers by name."""


def check_options(method: str, reoptimize_rtol: float) -> None:
    """ConfigError naming the option when ``method`` is not one of :data:`METHODS` or
    ``reoptimize_rtol`` is not a relative change >= 0."""
    if method not in METHODS:
        raise ConfigError(f"option --optimize = {method!r}: expected one of {', '.join(METHODS)}.")
    if math.isnan(reoptimize_rtol) or reoptimize_rtol < 0.0:
        raise ConfigError(
            f"option --reoptimize-rtol = {reoptimize_rtol!r}: expected a relative change >= 0 "
            "(0: before every lap, inf: once)."
        )


class StintDeployment:
    """The ``deployment`` callable of a stint (module docstring, items 2-4): called with the
    pack run at the start of a lap and the track, returns a
    :class:`~hevsim.sim.stint.DeploymentPlan`."""

    def __init__(
        self,
        problem: DeployProblem,
        method: str,
        *,
        ocv_v: float,
        capacity_ah: float,
        soc_min: float,
        soc_max: float,
        reoptimize_rtol: float = REOPTIMIZE_RTOL,
    ) -> None:
        check_options(method, reoptimize_rtol)
        self.problem = problem
        self.method = method
        self.ocv_v = float(ocv_v)
        self.energy_per_soc_j = float(capacity_ah) * 3600.0 * float(ocv_v)
        self.soc_min, self.soc_max = float(soc_min), float(soc_max)
        self.rtol = float(reoptimize_rtol)
        self.half_window_j = 0.5 * (problem.window_j[1] - problem.window_j[0] - abs(problem.budget_j))
        self.label = f"optimal ({method}), re-solved when the BMS limits change by > {self.rtol:g}"
        self.key: tuple[float, ...] | None = None
        self.result: DeployResult | None = None
        self.solves = 0

    def state(self, run: Any) -> tuple[float, float, float, float, float]:
        """(discharge and charge power limits [W], budget [J], energy window [J]) of the pack
        ``run`` at the start of a lap (module docstring, item 2)."""
        lim, soc = run.limits, float(run.soc)
        p_dis = self.ocv_v * float(lim.discharge_a) if soc > self.soc_min else 0.0
        p_chg = self.ocv_v * float(lim.charge_a) if soc < self.soc_max else 0.0
        deployable = max((soc - self.soc_min) * self.energy_per_soc_j, 0.0)
        storable = max((self.soc_max - soc) * self.energy_per_soc_j, 0.0)
        budget = max(min(self.problem.budget_j, deployable), -storable)
        lo = max(min(0.0, budget) - self.half_window_j, -storable)
        hi = min(max(0.0, budget) + self.half_window_j, deployable)
        return max(p_dis, 0.0), max(p_chg, 0.0), budget, lo, hi

    def changed(self, key: tuple[float, ...]) -> bool:
        """Whether the state ``key`` calls for a new solve (module docstring, item 3)."""
        if self.key is None or self.rtol == 0.0:
            return True
        for new, old in zip(key[:2], self.key[:2], strict=True):
            if new == old:
                continue
            if not (math.isfinite(new) and math.isfinite(old)) or abs(new - old) > self.rtol * old:
                return True
        scale = self.rtol * self.half_window_j
        return any(abs(new - old) > scale for new, old in zip(key[2:], self.key[2:], strict=True))

    def solve(self, key: tuple[float, ...]) -> DeployResult:
        from hevsim.optimal.lap_deploy import solve_convex, solve_dp

        p_dis, p_chg, budget, lo, hi = key
        prob = self.problem.with_battery(
            discharge_max_w=p_dis, charge_max_w=p_chg, budget_j=budget, window_j=(lo, hi)
        )
        return solve_convex(prob) if self.method == "convex" else solve_dp(prob)

    def __call__(self, run: Any, track: Track) -> DeploymentPlan:
        key = self.state(run)
        again = self.changed(key)
        t0 = time.perf_counter()
        if again:
            self.result = self.solve(key)
            self.key = key
            self.solves += 1
        res, used = self.result, self.key
        assert res is not None and used is not None
        df = res.frame()
        bp = df["battery_power_w"].to_numpy()
        lim = np.interp(
            track.distance_m, df["distance_m"].to_numpy(), np.maximum(bp, 0.0), period=track.length_m
        )
        lim = np.minimum(lim, key[0])  # the lap starts at this lap's BMS limit
        info = {
            "reoptimized": int(again),
            "deploy_discharge_limit_kw": used[0] / 1e3,
            "deploy_charge_limit_kw": used[1] / 1e3,
            "lap_start_discharge_limit_kw": key[0] / 1e3,
            "deploy_map_max_kw": float(bp.max()) / 1e3,
            "deploy_budget_kj": used[2] / 1e3,
            "deploy_lap_time_s": res.lap_time_s,
            "deploy_solve_s": time.perf_counter() - t0 if again else 0.0,
        }
        return DeploymentPlan(np.ascontiguousarray(lim), info)


def simulate_stint_optimized(
    model: Any,
    track: Track | str | Path,
    laps: int,
    *,
    method: str = "convex",
    budget_kj: float = 0.0,
    reoptimize_rtol: float = REOPTIMIZE_RTOL,
    deploy_step_m: float = DEPLOY_STEP_M,
    window_kj: float | None = None,
    step_m: float = DEFAULT_STEP_M,
    soc_initial: float | None = None,
    problem: DeployProblem | None = None,
    vehicle: tuple[Any, float, float] | None = None,
    **stint: Any,
) -> StintResult:
    """A stint (:func:`hevsim.sim.stint.simulate_stint`; ``stint``: its other options, e.g.
    ``dt_s``, ``ambient_temp_c``, ``soak``, ``cooling_off``) whose laps drive the optimal
    deployment (``method``: ``"convex"`` or ``"dp"``) with a net battery deployment of
    ``budget_kj`` [kJ] per lap (0: charge-sustaining), re-solved when the BMS's limits change
    by more than ``reoptimize_rtol`` (module docstring). ``deploy_step_m`` [m]: the problem's
    distance step; ``window_kj`` [kJ]: half-width of the cumulative battery-energy window;
    ``problem``: a problem already built for ``model`` and the track at the stint's initial
    SOC (several stints of one car share it; ``budget_kj`` and ``window_kj`` are then its own);
    ``vehicle``: a :func:`~hevsim.sim.stint.stint_vehicle` already built."""
    from hevsim.config import load_vehicle_config

    check_options(method, reoptimize_rtol)
    if method == "convex":
        from hevsim.optimal.lap_deploy import _require_cvxpy

        _require_cvxpy()
    if isinstance(model, str | Path):
        model = load_vehicle_config(model)
    cfg = getattr(model, "config", model)
    if getattr(getattr(cfg, "battery", None), "model", None) != "pack":
        # simulate_stint's own refusal (naming battery.model), before the problem is built
        simulate_stint(model, track, laps, step_m=step_m, soc_initial=soc_initial, **stint)
        raise ConfigError(f"{cfg.name}: a stint needs [battery] model = 'pack'.")
    trk = track if isinstance(track, Track) else load_track(track, step_m=step_m)
    soc0 = float(cfg.simulation.soc_initial if soc_initial is None else soc_initial)
    veh = vehicle if vehicle is not None else stint_vehicle(model, soc0)
    if problem is None:
        dtrk = (
            trk if abs(trk.step_m - deploy_step_m) <= 1e-9 * deploy_step_m else trk.resampled(deploy_step_m)
        )
        problem, _ = build_problem(
            model, dtrk, step_m=deploy_step_m, budget_kj=budget_kj, window_kj=window_kj, soc=soc0
        )
    bat = veh[0].envelope.model.battery
    plan = StintDeployment(
        problem,
        method,
        ocv_v=veh[1],
        capacity_ah=float(bat.capacity_ah),
        soc_min=float(cfg.battery.soc_min),
        soc_max=float(cfg.battery.soc_max),
        reoptimize_rtol=reoptimize_rtol,
    )
    res = simulate_stint(
        model, trk, laps, step_m=trk.step_m, soc_initial=soc0, deployment=plan, vehicle=veh, **stint
    )
    res.metadata.update(
        optimize=method,
        reoptimize_rtol=plan.rtol,
        deploy_budget_kj=problem.budget_j / 1e3,
        deploy_step_m=problem.step_m,
        deploy_solves=plan.solves,
    )
    res.summary["deploy_solves"] = plan.solves
    return res


__all__ = ["DEPLOY_STEP_M", "METHODS", "REOPTIMIZE_RTOL", "StintDeployment", "simulate_stint_optimized"]
