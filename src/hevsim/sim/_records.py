"""What a forward loop returns before the time series is built (:class:`ForwardRecord`,
:class:`BatchRecord`) and the constants every loop shares: the records of the Python loop of
:mod:`hevsim.sim.forward` and of the compiled loops ``hevsim.sim._compiled_*``, here so the
compiled loops do not import the module that dispatches to them (issue 24)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from hevsim.units import MPS_PER_MPH, RADPS_PER_RPM

BISECTION_STEPS = 40
"""Bisection steps on the end speed when the powertrain cannot follow the trace [-]."""
REGEN_CURRENT_RTOL = 1e-3
"""Relative excess [-] of the charge current over its limit accepted while regenerating. The
shared bus balance scales regeneration to the charge limit by a fixed number of fixed-point
iterations (:data:`hevsim.components.bus.REGEN_ITERATIONS`), exact for ideal and
constant-efficiency machines but leaving ~1e-5 with a map machine and an SOC-dependent pack;
the DP marks those pairs infeasible (tolerance 1e-6), but for the forward driver that would
make "brake a little" infeasible while "brake hard" is not."""


@dataclass
class ForwardRecord:
    """Raw output of one forward run (Python loop or ``simulate_compiled``), before the
    time-series frame is built.

    Attributes:
        columns: name -> float64 array of ``n + 1`` rows, row ``k`` the step from ``t_k`` to
            ``t_k + dt`` (row ``n`` is overwritten by :func:`finish_record`), in this order:
            ``speed_desired_mps``, ``speed_mps`` (at ``t_k``) [m/s], ``accel_mps2`` [m/s²],
            ``wheel_force_n`` [N], ``wheel_power_w`` [W] (the audit's ``wheel`` term),
            ``road_load_force_n`` [N] (wheel force - m_eff a), ``fuel_kg`` (cumulative to
            ``t_k + dt``) [kg], ``soc`` (at ``t_k``) [-], then the power flow's ``details``
            in their order, ``power_mode`` (index in ``MODES``), ``traction_limited``
            (0/1), ``clutch_closed`` (0/1, parallel only: engine on), and with a battery
            ``battery_ocv_v``, ``battery_voltage_v`` [V]. Integer and boolean channels are
            floats here (:data:`INT_COLUMNS`, :data:`BOOL_COLUMNS`).
        audit: energy [J] per audit term over the run: the sources of :data:`SOURCES` and the
            sinks (``aero``, ``rolling``, ``grade``, ``kinetic_vehicle``, ``battery_loss``,
            the ``loss_powers`` terms x dt), without ``residual``.
        summary: float64 array indexed by :data:`hevsim.sim.kernel.SUMMARY` (distance [m],
            fuel [kg], final SOC, RMS and max speed error [m/s], engine-on time [s], engine
            starts, traction-limited time [s], duration [s]).
        speed_final_mps: speed at the end of the run [m/s].
    """

    columns: dict[str, np.ndarray]
    audit: dict[str, float]
    summary: np.ndarray
    speed_final_mps: float


@dataclass
class BatchRecord:
    """Raw output of ``simulate_batch_compiled`` for ``n`` variants.

    Attributes: audits: one :attr:`ForwardRecord.audit` dict per variant [J]; summary:
    ``(n, len(SUMMARY))`` float64 array as :attr:`ForwardRecord.summary`; traction_j: (n,)
    positive wheel energy [J] (sum over steps of ``max(wheel_power_w, 0) dt``).
    """

    audits: list[dict[str, float]]
    summary: np.ndarray
    traction_j: np.ndarray


def add_display_units(out: dict[str, Any], name: str, col: np.ndarray) -> None:
    """Add to a time series being built (``out``, column name -> values) the display-unit twin of
    channel ``name`` (values ``col``), right after it: ``speed_desired_mph`` / ``speed_mph`` of the
    speeds [m/s], ``engine_speed_rpm`` of ``engine_speed_radps``; nothing for other channels."""
    if name in ("speed_desired_mps", "speed_mps"):
        out[name.replace("_mps", "_mph")] = col / MPS_PER_MPH
    elif name == "engine_speed_radps":
        out["engine_speed_rpm"] = col / RADPS_PER_RPM
