"""The engine-generator pair (genset) of the series HEV on its fuel-optimal operating line.

For every delivered electrical power ``P_g > 0`` the engine runs at the fuel-optimal point the
generator can absorb: minimum of ``Engine.fuel_rate`` over the engine speed in stall..redline,
with the torque that makes the generator deliver ``P_g`` within its generating limit and the
engine's max torque. The series architecture's point kernels, its performance envelope and its
DP formulation (:mod:`hevsim.optimal._series_dp`, which re-exports these) all use it, so it lives
in the physics layer (issue 24).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from hevsim.components.electric_machine import ElectricMachine
from hevsim.components.engine import Engine
from hevsim.tables import FloatArray

OPLINE_SPEED_POINTS = 361
"""Engine speeds searched between stall and redline for the optimal operating line [-]."""
OPLINE_TORQUE_POINTS = 401
"""Torques per speed (0 .. the smaller of the engine and generator limits) [-]."""
GENSET_NEWTON_STEPS = 4
"""Newton steps refining the torque so the generator delivers the requested power [-]."""
GENSET_NEWTON_DT_NM = 1e-3
"""Torque step of the finite-difference slope in those Newton steps [N·m]."""
SERIES_POWER_POINTS = 101
"""Default genset-power grid size [-] (``optimization.input_grid_points`` = 0)."""


@dataclass(frozen=True)
class GensetPoints:
    """Fuel-optimal genset operating points, one per electrical power.

    Attributes: power_w: electrical power the generator delivers to the bus at the point
    (the requested power up to the Newton tolerance) [W]; speed_radps [rad/s]; torque_nm
    (engine brake torque) [N·m]; fuel_kgps [kg/s]; feasible (False above the genset's
    capability).
    """

    power_w: FloatArray
    speed_radps: FloatArray
    torque_nm: FloatArray
    fuel_kgps: FloatArray
    feasible: np.ndarray


def _speed_torque_grid(
    engine: Engine, generator: ElectricMachine
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Engine speeds (S,), torques (S, T) and generator electrical output (S, T) [W]."""
    w = np.linspace(engine.stall_speed_radps, engine.redline_radps, OPLINE_SPEED_POINTS)
    t_eng_max = engine.max_torque_nm(w)
    t_gen_min = np.asarray(generator.limits(w)[1], dtype=np.float64)  # most negative torque
    t_cap = np.minimum(t_eng_max, -t_gen_min)
    torque = t_cap[:, None] * np.linspace(0.0, 1.0, OPLINE_TORQUE_POINTS)[None, :]
    p_out = -np.asarray(generator.electrical_power(-torque, w[:, None]), dtype=np.float64)
    return w, torque, np.maximum.accumulate(p_out, axis=1)


def genset_max_power_w(engine: Engine, generator: ElectricMachine) -> float:
    """Largest electrical power the engine-generator pair can deliver [W]."""
    _, _, p_out = _speed_torque_grid(engine, generator)
    return float(p_out[:, -1].max())


def genset_operating_points(engine: Engine, generator: ElectricMachine, power_w: Any) -> GensetPoints:
    """Fuel-optimal engine operating points delivering ``power_w`` [W] to the bus.

    For each engine speed on a grid (stall..redline) the torque that makes the generator
    deliver the power is found on the monotone power-torque curve (within the engine's max
    torque and the generator's generating limit); ``Engine.fuel_rate`` is evaluated there and
    the speed with the least fuel is kept; a few Newton steps on the torque at that speed
    then make the generator deliver the power to round-off. ``power_w = 0`` means engine off
    (zero fuel).
    """
    p = np.atleast_1d(np.asarray(power_w, dtype=np.float64))
    w, torque, p_out = _speed_torque_grid(engine, generator)
    t_at = np.full((w.size, p.size), np.nan)
    for i in range(w.size):
        inside = p <= p_out[i, -1]
        t_at[i, inside] = np.interp(p[inside], p_out[i], torque[i])
    ww = np.broadcast_to(w[:, None], t_at.shape)
    valid = np.isfinite(t_at)
    fuel = np.full(t_at.shape, np.inf)
    if valid.any():
        fr = np.asarray(engine.fuel_rate(t_at[valid], ww[valid]), dtype=np.float64)
        fuel[valid] = np.where(np.isfinite(fr), fr, np.inf)
    best = np.argmin(fuel, axis=0)
    cols = np.arange(p.size)
    off = p <= 0.0
    feasible = np.isfinite(fuel[best, cols]) & ~off
    speed = np.where(feasible, w[best], 0.0)
    torque = np.where(feasible, t_at[best, cols], 0.0)
    if feasible.any():  # Newton on the torque at the chosen speed: the generator delivers p exactly
        ws, ts, ps = speed[feasible], torque[feasible], p[feasible]
        cap = np.minimum(engine.max_torque_nm(ws), -np.asarray(generator.limits(ws)[1]))
        for _ in range(GENSET_NEWTON_STEPS):
            p_act = -np.asarray(generator.electrical_power(-ts, ws), dtype=np.float64)
            h = GENSET_NEWTON_DT_NM
            slope = (-np.asarray(generator.electrical_power(-(ts + h), ws), dtype=np.float64) - p_act) / h
            ts = np.clip(ts + (ps - p_act) / np.where(slope > 0, slope, np.inf), 0.0, cap)
        torque[feasible] = ts
    fuel_best = np.zeros(p.size)
    if feasible.any():
        fuel_best[feasible] = np.asarray(
            engine.fuel_rate(torque[feasible], speed[feasible]), dtype=np.float64
        )
    delivered = np.where(
        feasible, -np.asarray(generator.electrical_power(-torque, speed), dtype=np.float64), 0.0
    )
    feasible = (feasible & np.isfinite(fuel_best)) | off
    return GensetPoints(
        power_w=delivered,
        speed_radps=speed,
        torque_nm=torque,
        fuel_kgps=np.where(np.isfinite(fuel_best), fuel_best, 0.0),
        feasible=feasible,
    )
