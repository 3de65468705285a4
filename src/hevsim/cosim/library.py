"""Small in-process participants, referenced from configurations as
``hevsim.cosim.library:<factory>`` (type ``application/x-hevsim-python``)."""

from __future__ import annotations

import math
from typing import Any

from hevsim.cosim.participant import FunctionParticipant


def linear_ode(name: str, a: float, b: float, x0: float, unit: str = "") -> FunctionParticipant:
    """Scalar ``dx/dt = a*x + b*u`` [1/s], input ``u`` held over the step, solved exactly;
    output ``x`` (unit ``unit``)."""

    def step(t: float, h: float, x: float, u: dict[str, float]) -> tuple[float, dict[str, float]]:
        if a == 0.0:
            xn = x + b * u["u"] * h
        else:
            e = math.exp(a * h)
            xn = e * x + (e - 1.0) / a * b * u["u"]
        return xn, {"x": xn}

    return FunctionParticipant(name, step, float(x0), {"x": float(x0)}, {"u": unit}, {"x": unit})


def thermal_mass(
    name: str,
    capacity_j_per_k: float,
    temp_initial_k: float,
    conductance_w_per_k: float = 0.0,
) -> FunctionParticipant:
    """A lumped thermal mass [J/K] at uniform temperature.

    With ``conductance_w_per_k`` > 0 it exchanges heat with the input temperature
    ``t_other_k`` [K] (exact exponential over the step) and outputs the step-average heat
    flow it gives away, ``heat_out_w`` [W]; with 0 it absorbs input ``heat_in_w`` [W].
    Outputs ``temp_k`` [K] and ``energy_j`` [J, heat gained since the start]."""
    c, g = float(capacity_j_per_k), float(conductance_w_per_k)
    if c <= 0:
        from hevsim.errors import ConfigError

        raise ConfigError(f"thermal mass {name!r}: capacity_j_per_k {c} must be > 0.")

    def step(t: float, h: float, x: tuple[float, float], u: dict[str, float]) -> tuple[Any, dict[str, float]]:
        temp, energy = x
        if g > 0:
            tn = u["t_other_k"] + (temp - u["t_other_k"]) * math.exp(-g * h / c)
            q_out = c * (temp - tn) / h
        else:
            tn = temp + u["heat_in_w"] * h / c
            q_out = 0.0
        en = energy + c * (tn - temp)
        return (tn, en), {"temp_k": tn, "heat_out_w": q_out, "energy_j": en}

    inputs = {"t_other_k": "K"} if g > 0 else {"heat_in_w": "W"}
    out0 = {"temp_k": float(temp_initial_k), "heat_out_w": 0.0, "energy_j": 0.0}
    return FunctionParticipant(
        name,
        step,
        (float(temp_initial_k), 0.0),
        out0,
        inputs,
        {"temp_k": "K", "heat_out_w": "W", "energy_j": "J"},
    )


def power_cycle(
    name: str, discharge_w: float, charge_w: float, period_s: float, duty: float = 0.5
) -> FunctionParticipant:
    """A square power cycle [W, discharge > 0]: ``discharge_w`` for ``duty * period_s``, then
    ``-charge_w`` for the rest of the period. Output ``power_w`` is the value for the coming
    step (taken at its start time), so a consumer stepping after it sees the right phase."""
    if not (period_s > 0 and 0 < duty < 1):
        from hevsim.errors import ConfigError

        raise ConfigError(f"power cycle {name!r}: period_s {period_s} must be > 0 and duty {duty} in (0, 1).")

    def value(t: float) -> float:
        return float(discharge_w) if (t % period_s) < duty * period_s - 1e-9 else -float(charge_w)

    def step(t: float, h: float, x: float, u: dict[str, float]) -> tuple[float, dict[str, float]]:
        return x, {"power_w": value(t + h)}

    return FunctionParticipant(name, step, 0.0, {"power_w": value(0.0)}, {}, {"power_w": "W"})
