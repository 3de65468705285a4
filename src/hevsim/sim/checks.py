"""Run-time checks of a forward simulation: no impossible result leaves the simulator.

After the kernel returns, :func:`check_domain` stops a run whose recorded channels hold NaN
or infinity or whose state of charge left [0, 1] (:class:`~hevsim.errors.DomainError`, exit
status 2), and :func:`check_tracking` stops a run in which the vehicle could not follow the
cycle (:class:`~hevsim.errors.TrackingError`, exit status 3). Each message says what
happened, where (time and channel) and the likely cause.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from hevsim.battery.cell import SOC_TOLERANCE as SOC_TOLERANCE
from hevsim.battery.cell import soc_outside
from hevsim.errors import DomainError, SimulationError
from hevsim.sim import kernel as K
from hevsim.units import MPS_PER_MPH

# How far the state of charge may stray outside [0, 1] before a run stops [-]: the battery
# layer's bound, shared by every command that steps a battery. Covers the round-off of the
# charge integral, not a battery run dry: the kernel applies its SOC limits at the start of a
# step, so a pack allowed down to ``soc_min = 0`` can overshoot below zero by a whole step's
# charge, which is a physically impossible state. (SOC_TOLERANCE is re-exported here.)


@dataclass(frozen=True)
class TrackingBound:
    """The vehicle "could not follow" the cycle when the speed error ``|v_cycle - v|`` stays
    above ``error_mps`` [m/s] without a break for longer than ``duration_s`` [s]."""

    error_mps: float
    duration_s: float

    def __post_init__(self) -> None:
        for name in ("error_mps", "duration_s"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise SimulationError(f"TrackingBound.{name} = {value:g}; expected a finite number > 0.")


TRACKING_BOUND = TrackingBound(error_mps=5.0 * MPS_PER_MPH, duration_s=20.0)
"""Default bound: more than 5 mph off the cycle for more than 20 s in a row.

The US EPA driver's trace tolerance is ±2 mph, but the vehicle is allowed to fall behind
while it accelerates at full power (40 CFR 86.115-78), so a power-limited car may legitimately
lag during a long acceleration. The shipped ``examples/series_hev.toml`` on US06, the hardest
shipped cycle, lags by more than 5 mph for at most 9 s and the refinement levels 3-8 for at
most 10.5 s; 20 s leaves room for those full-power stretches while stopping a run whose car
is not driving the cycle (e.g. a drained battery: 60-70 s beyond 5 mph)."""


INFINITE_ALLOWED = ("bat_max_dis_a", "bat_max_chg_a")
"""Kernel parameters for which +inf is a valid value (no current limit)."""

CONFIG_KEYS = {
    "mass_kg": "body.mass_kg",
    "mass_factor": "body.mass_factor",
    "cd": "body.drag_coefficient",
    "area_m2": "body.frontal_area_m2",
    "rho_kgpm3": "body.air_density_kgpm3",
    "headwind_mps": "body.headwind_mps",
    "crr": "body.rolling_resistance",
    "crr_v": "body.rolling_resistance_speed_s_per_m",
    "tire_radius_m": "tire.radius_m",
    "gear_ratio": "gear.ratio",
    "gear_efficiency": "gear.efficiency",
    "max_brake_force_n": "brakes.max_decel_mps2",
    "driver_gain_per_mps": "driver.gain_per_mph",
    "motor_scale": "traction_motor.torque_scale",
    "gen_scale": "generator.torque_scale",
    "engine_scale": "engine.torque_scale",
    "bat_capacity_ah": "battery.capacity_ah",
    "bat_max_dis_a": "battery.max_discharge_current_a",
    "bat_max_chg_a": "battery.max_charge_current_a",
    "soc_initial": "simulation.soc_initial",
    "aux_power_w": "controller.aux_power_w",
}
"""Configuration key behind a kernel parameter, for messages (others are named as kernel
parameters)."""


def _key(key: str) -> str:
    """``key`` with its section under its current name (``[gear]`` became ``[final_drive]``)."""
    from hevsim import config

    section, _, rest = key.partition(".")
    renamed: dict[str, str] = getattr(config, "RENAMED_SECTIONS", {})
    return f"{renamed.get(section, section)}.{rest}"


def _param_name(name: str) -> str:
    return _key(CONFIG_KEYS[name]) if name in CONFIG_KEYS else f"kernel parameter '{name}'"


def _fmt(x: float) -> str:
    return f"{float(x):g}"


def check_domain(
    label: str,
    time_s: np.ndarray,
    out: np.ndarray,
    energy: np.ndarray,
    summary: np.ndarray,
    p: np.ndarray,
) -> None:
    """Raise :class:`DomainError` if the run left its physical domain.

    Args:
        label: "<vehicle> on <cycle>" for the message.
        time_s: the step times [s] (rows of ``out``).
        out: recorded channels, columns :data:`hevsim.sim.kernel.CHANNELS`.
        energy, summary: the kernel's energy accumulators [J] and scalar summaries.
        p: the parameter vector the kernel ran with.
    """
    bad = ~np.isfinite(out)
    if bad.any():
        row = int(np.flatnonzero(bad.any(axis=1))[0])
        cols = [K.CHANNELS[c] for c in np.flatnonzero(bad[row])]
        first = cols[0]
        value = out[row, K.C[first]]
        bad_params = [
            f"{_param_name(K.PARAMS[i])} = {_fmt(p[i])}"
            for i in np.flatnonzero(~np.isfinite(p))
            if not (K.PARAMS[i] in INFINITE_ALLOWED and p[i] == np.inf)
        ]
        cause = (
            f"{', '.join(bad_params)}: expected finite values"
            if bad_params
            else "a parameter outside its physical range (body, motor, battery or controller "
            "values) or a demand beyond the components' capability"
        )
        raise DomainError(
            f"{label}: the run left its physical domain at t = {_fmt(time_s[row])} s: channel "
            f"'{first}' is {_fmt(value)}"
            + (f" (also {', '.join(cols[1:4])}{' ...' if len(cols) > 4 else ''})" if len(cols) > 1 else "")
            + f"; likely cause: {cause}."
        )
    for name, arr, names in (("energy term", energy, K.ENERGY_TERMS), ("summary", summary, K.SUMMARY)):
        nf = np.flatnonzero(~np.isfinite(arr))
        if nf.size:
            i = int(nf[0])
            raise DomainError(
                f"{label}: {name} '{names[i]}' is {_fmt(arr[i])} at the end of the run; expected a "
                "finite number (a parameter is outside its physical range)."
            )
    soc = out[:, K.CH_SOC]
    where = soc_outside(soc)  # the battery layer's SOC domain (hevsim.battery.cell)
    if where is not None and soc[where[0]] < 0.0:
        k = where[0]
        source = (
            "the vehicle has no genset and the cycle needs more charge than the pack holds"
            if p[K.GSKIND] == K.GENSET_NONE
            else "the traction demand exceeds what the genset supplies"
        )
        raise DomainError(
            f"{label}: channel 'soc' fell to {soc[k]:.4g} at t = {_fmt(time_s[k])} s; expected a "
            f"state of charge in [0, 1]. Likely cause: the battery ran dry: {source}, and "
            f"battery.soc_min = {_fmt(p[K.SOCMIN])} lets the pack empty; raise battery.soc_min or "
            "controller.soc_low, or use a larger battery or genset."
        )
    if where is not None:
        k = where[0]
        raise DomainError(
            f"{label}: channel 'soc' rose to {soc[k]:.4g} at t = {_fmt(time_s[k])} s; expected a "
            f"state of charge in [0, 1]. Likely cause: the battery was overcharged: "
            f"battery.soc_max = {_fmt(p[K.SOCMAX])} lets regeneration or the genset charge past "
            "full; lower battery.soc_max or controller.soc_high."
        )


def check_metrics(label: str, metrics: dict[str, dict[str, Any]]) -> None:
    """Raise :class:`DomainError` for a NaN metric (an infinite MPG with no fuel burnt is
    allowed: it is the limit, and ``metrics.json`` writes it as null with a note)."""
    for name, m in metrics.items():
        value = float(m["value"])
        if np.isnan(value):
            raise DomainError(
                f"{label}: metric '{name}' is not a number (nan); expected a finite value "
                "(the vehicle did not move, so per-distance figures are undefined)."
            )


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) row ranges of consecutive true values of ``mask`` (stop exclusive)."""
    edges = np.diff(np.concatenate(([0], mask.astype(np.int8), [0])))
    starts = np.flatnonzero(edges == 1)
    stops = np.flatnonzero(edges == -1)
    return list(zip(starts.tolist(), stops.tolist(), strict=True))


def tracking_violation(
    time_s: np.ndarray, error_mps: np.ndarray, bound: TrackingBound
) -> tuple[int, int] | None:
    """First (start, stop) rows where ``|error_mps|`` stays above the bound for longer than
    ``bound.duration_s`` [s] (the run's time measured from its first to its last row plus one
    step), or None."""
    for start, stop in _runs(np.abs(error_mps) > bound.error_mps):
        end = stop if stop < time_s.size else time_s.size - 1
        if time_s[end] - time_s[start] > bound.duration_s:
            return start, stop
    return None


def _likely_tracking_cause(ts: Any, rows: slice, error: np.ndarray, p: np.ndarray) -> str:
    if float(np.mean(error[rows])) < 0.0:
        return (
            "the vehicle is faster than the cycle and cannot slow down: the friction brakes "
            "(brakes.max_decel_mps2) are too weak for the mass and grade"
        )
    soc = ts["soc"].to_numpy()[rows]
    if np.mean(soc <= p[K.SOCMIN] + 1e-3) > 0.5:
        return (
            f"the battery is empty (SOC at battery.soc_min = {_fmt(p[K.SOCMIN])}), so the motor gets "
            "only the genset's power: the genset (controller.soc_low, throttle, engine) cannot "
            "sustain this cycle"
        )
    if np.mean(ts["battery_limited"].to_numpy()[rows] > 0) > 0.5:
        return (
            "battery power-limited: the pack's current limits (battery.max_discharge_current_a = "
            f"{_fmt(p[K.BIDIS])} A) or its voltage sag cap the motor's power"
        )
    if np.mean(ts["driver_request"].to_numpy()[rows] >= 0.999) > 0.5:
        return (
            "motor-limited: the traction motor at full torque cannot accelerate the vehicle as the "
            f"cycle asks ({_key('traction_motor.max_torque_nm')} or "
            f"{_key('traction_motor.torque_scale')}, {_key('gear.ratio')}, body.mass_kg, road load)"
        )
    return "the driver reacts too slowly (driver.gain_per_mph) for this cycle and time step"


def tracking_message(label: str, ts: Any, p: np.ndarray, bound: TrackingBound) -> str | None:
    """The :class:`TrackingError` message for time series ``ts`` (the result's DataFrame),
    or None when the vehicle followed the cycle within ``bound``."""
    t = ts["time_s"].to_numpy()
    error = ts["speed_desired_mps"].to_numpy() - ts["speed_mps"].to_numpy()
    hit = tracking_violation(t, error, bound)
    if hit is None:
        return None
    start, stop = hit
    rows = slice(start, stop)
    k = start + int(np.argmax(np.abs(error[rows])))
    t_end = t[min(stop, t.size - 1)]
    return (
        f"{label}: could not follow the drive cycle: the speed error exceeded "
        f"{bound.error_mps / MPS_PER_MPH:.3g} mph from t = {_fmt(t[start])} s to t = {_fmt(t_end)} s "
        f"({_fmt(t_end - t[start])} s; allowed: {_fmt(bound.duration_s)} s), largest "
        f"{abs(error[k]) / MPS_PER_MPH:.3g} mph at t = {_fmt(t[k])} s (channels speed_desired_mps, "
        f"speed_mps). Likely cause: {_likely_tracking_cause(ts, rows, error, p)}."
    )


def stuck_error(
    model: Any, t_s: float, soc: float | None = None, soc_min: float | None = None
) -> DomainError:
    """The error of a step with no feasible control even when the car stops, with the reason
    when it can be named: a battery at the floor of its SOC window ``soc_min`` [-] at SOC
    ``soc`` [-] (the SOC of the last completed step) that still has to carry the auxiliary
    load (``[controller] aux_power_w``) the controller's charging does not cover."""
    msg = f"{model.name}: no feasible control at t = {t_s:g} s even when stopping"
    cfg = getattr(model, "config", None)
    ctl = getattr(cfg, "controller", None)
    aux_w = float(getattr(ctl, "aux_power_w", 0.0) or 0.0)
    if soc is not None and soc_min is not None and np.isfinite(soc) and soc <= soc_min + 0.005:
        msg += f": the battery ran down to SOC {soc:.4f} (window floor [battery] soc_min = {soc_min:g})"
        if aux_w > 0.0:
            msg += (
                f" and must still carry the {aux_w:g} W auxiliary load ([controller] aux_power_w), more "
                "than the engine could charge (the rule-based controllers charge it on top of their "
                "charging power below soc_low; a parallel HEV's engine cannot turn at a standstill): "
                "lower the auxiliary load"
            )
    return DomainError(msg + ".")
