"""The DC bus balance, written once for the forward kernel, the DP stage model and ECMS.

A traction machine, the rest of the bus load (generator, auxiliaries) and the battery meet on
the bus (thesis eqs 13, 21-22). Three steps, each one function:

1. :func:`battery_power_limits`: the largest discharge and charge powers at the pack's
   current limits, ``(OCV - R I) I`` (capped at the maximum deliverable ``OCV^2 / 4R``) and
   ``(OCV + R I) I``;
2. :func:`regen_torque` and :func:`limit_machine_torque`: the machine torque after the
   regeneration rules (generating limit, minimum speed) and scaled down so that the
   machine's electrical power keeps the battery within those powers;
3. :func:`bus_current`: the battery current that closes the balance, on the resistance of
   the current's direction, and whether the power is beyond ``OCV^2 / 4R``.

:func:`machine_request` (once per input) and :func:`bus_balance` (per state and input) are
steps 2-3 at one point (the compiled forward loops call them); :func:`machine_request_many`
and :func:`bus_balance_many` run them over flat arrays for the DP grid.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from hevsim.components.battery import current_for_power
from hevsim.components.electric_machine import limits_from_curves, machine_power, power_from_map

REGEN_ITERATIONS = 4
"""Fixed-point iterations that scale the machine torque to the battery power limits (exact
after one for ideal and constant-efficiency machines)."""
TORQUE_RTOL = 1e-12
"""Relative tolerance on the motoring torque limit (a request at the limit is feasible)."""


@njit(cache=True, inline="always")
def battery_power_limits(ocv_dis_v, r_dis_ohm, ocv_chg_v, r_chg_ohm, i_dis_max_a, i_chg_max_a):
    """(largest discharge power, largest charge power) at the battery terminals [W], >= 0.

    Discharge: ``(OCV - R I_max) I_max``, or the maximum deliverable ``OCV^2 / 4R`` when the
    current limit lies beyond the maximum-power current ``OCV / 2R``. Charge:
    ``(OCV + R I_max) I_max``; infinite without a charge-current limit.
    """
    if i_dis_max_a < ocv_dis_v / (2.0 * r_dis_ohm + 1e-300):
        p_dis = (ocv_dis_v - r_dis_ohm * i_dis_max_a) * i_dis_max_a
    else:
        p_dis = ocv_dis_v * ocv_dis_v / (4.0 * r_dis_ohm + 1e-300)
    p_chg = (ocv_chg_v + r_chg_ohm * i_chg_max_a) * i_chg_max_a if np.isfinite(i_chg_max_a) else np.inf
    return p_dis, p_chg


@njit(cache=True, inline="always")
def regen_torque(torque_req_nm, torque_min_nm, regen_ok):
    """Machine torque [N·m] for a request: motoring as asked; braking down to the generating
    limit ``torque_min_nm`` (<= 0) where ``regen_ok``, else none (friction brakes take it)."""
    if torque_req_nm >= 0.0:
        return torque_req_nm
    return max(torque_req_nm, torque_min_nm) if regen_ok else 0.0


@njit(cache=True, inline="always")
def limit_machine_torque(
    torque_nm, p_el, omega_radps, p_other_w, p_dis_max_w, p_chg_max_w, kind, const_eff,
    torque_scale, tab,
):  # fmt: skip
    """Scale the machine torque so the battery stays within its power limits.

    ``p_el`` [W] is the machine's electrical power at ``torque_nm`` [N·m] and ``omega_radps``
    [rad/s] (:func:`~hevsim.components.electric_machine.machine_power`; passed in because a
    grid evaluates it once for all states). The battery power is ``p_el`` plus
    ``p_other_w`` [W] (the rest of the bus, > 0 drawn); motoring torque is scaled down when
    it exceeds ``p_dis_max_w``, regenerative torque when it exceeds ``p_chg_max_w`` [W] (from
    :func:`battery_power_limits`). Machine: ``kind``, ``const_eff``, ``torque_scale`` and
    tables ``tab`` as in :func:`~hevsim.components.electric_machine.machine_power`.
    Returns (torque [N·m], electrical power [W] at that torque, limited [bool]).
    """
    hi = p_dis_max_w - p_other_w
    lo = -p_chg_max_w - p_other_w
    limited = False
    for _ in range(REGEN_ITERATIONS):
        if p_el > hi and torque_nm > 0.0 and p_el > 0.0:
            torque_nm *= max(hi, 0.0) / p_el
        elif p_el < lo and torque_nm < 0.0 and p_el < 0.0:
            torque_nm *= min(lo, 0.0) / p_el
        else:
            break
        limited = True
        p_el = machine_power(torque_nm, omega_radps, kind, const_eff, torque_scale, tab)
    return torque_nm, p_el, limited


@njit(cache=True, inline="always")
def needs_limit(torque_nm, p_el, p_other_w, p_dis_max_w, p_chg_max_w):
    """True when :func:`limit_machine_torque` would change the torque [N·m] (same tests).

    Hot loops call it first: passing the machine's tables to a function costs reference
    counting on every array (about 50 ns per call), and the limits rarely bind.
    """
    if p_el > p_dis_max_w - p_other_w and torque_nm > 0.0 and p_el > 0.0:
        return True
    return p_el < -p_chg_max_w - p_other_w and torque_nm < 0.0 and p_el < 0.0


@njit(cache=True, inline="always")
def bus_current(p_bat_w, ocv_dis_v, r_dis_ohm, ocv_chg_v, r_chg_ohm):
    """Battery current closing the bus at terminal power ``p_bat_w`` [W] (> 0 discharging).

    Picks the discharge or charge state by the sign of the power and solves eqs (21)-(22).
    Returns (current [A], OCV [V], R [ohm] used, beyond the deliverable ``OCV^2 / 4R``).
    """
    if p_bat_w > 0.0:
        ocv, r = ocv_dis_v, r_dis_ohm
    else:
        ocv, r = ocv_chg_v, r_chg_ohm
    current = current_for_power(p_bat_w, ocv, r)
    return current, ocv, r, p_bat_w > 0.0 and ocv * ocv < 4.0 * r * p_bat_w


@njit(cache=True, inline="always")
def machine_request(
    torque_req_nm, omega_radps, regen_ok, kind, const_eff, torque_scale, lim_x, lim_mot, lim_gen, eff_x,
    eff_y, eff_z,
):  # fmt: skip
    """The state-independent half of the bus balance at one point (scalar kernel).

    Required machine torque [N·m], speed [rad/s], regeneration allowed; machine as in
    :func:`~hevsim.components.electric_machine.limits_from_curves` and
    :func:`~hevsim.components.electric_machine.power_from_map`. Returns (the torque after
    :func:`regen_torque` [N·m], its electrical power [W], a motoring request beyond the
    machine's limit); motoring torque is not scaled here.
    """
    t_max, t_min = limits_from_curves(omega_radps, torque_scale, lim_x, lim_mot, lim_gen)
    over_torque = torque_req_nm > t_max * (1.0 + TORQUE_RTOL)
    t = regen_torque(torque_req_nm, t_min, regen_ok)
    return t, power_from_map(t, omega_radps, kind, const_eff, torque_scale, eff_x, eff_y, eff_z), over_torque


@njit(cache=True)
def machine_request_many(
    torque_req_nm, omega_radps, regen_ok, kind, const_eff, torque_scale, tab, torque_nm, p_el_w,
    over_torque,
):  # fmt: skip
    """:func:`machine_request` over flat arrays (the DP grid): fills the torque [N·m], its
    electrical power [W] and ``over_torque``."""
    lim_x, lim_mot, lim_gen = tab.lim_x, tab.lim_mot, tab.lim_gen  # unpacked once (see
    eff_x, eff_y, eff_z = tab.eff_x, tab.eff_y, tab.eff_z  # electric_machine.machine_power)
    for i in range(torque_req_nm.shape[0]):
        torque_nm[i], p_el_w[i], over_torque[i] = machine_request(
            torque_req_nm[i], omega_radps[i], regen_ok[i], kind, const_eff, torque_scale, lim_x, lim_mot,
            lim_gen, eff_x, eff_y, eff_z,
        )  # fmt: skip


@njit(cache=True, inline="always")
def bus_balance(
    torque_nm, p_el_w, omega_radps, p_other_w, ocv_v, r_dis_ohm, r_chg_ohm, p_chg_max_w, kind, const_eff,
    torque_scale, tab,
):  # fmt: skip
    """The battery half of the bus balance at one point (scalar kernel).

    Machine torque [N·m] and electrical power [W] from :func:`machine_request`, speed
    [rad/s], other bus power [W], battery OCV [V], discharge and charge resistance [ohm] and
    largest charge power [W]. Regeneration is scaled to the charge limit
    (:func:`limit_machine_torque`; discharge is not limited: callers flag ``over_power`` and
    the current limits instead). Returns (torque [N·m], machine electrical power [W], battery
    power [W], current [A] (:func:`bus_current`), beyond ``OCV^2 / 4R``).
    """
    t, p_el = torque_nm, p_el_w
    if needs_limit(t, p_el, p_other_w, np.inf, p_chg_max_w):
        t, p_el, _ = limit_machine_torque(
            t, p_el, omega_radps, p_other_w, np.inf, p_chg_max_w, kind, const_eff, torque_scale, tab
        )
    p_bat = p_el + p_other_w
    current, _, _, over_power = bus_current(p_bat, ocv_v, r_dis_ohm, ocv_v, r_chg_ohm)
    return t, p_el, p_bat, current, over_power


@njit(cache=True)
def bus_balance_many(
    torque_in_nm, p_el_in_w, omega_radps, p_other_w, ocv_v, r_dis_ohm, r_chg_ohm, p_chg_max_w,
    kind, const_eff, torque_scale, tab, torque_nm, p_el_w, p_bat_w, current_a, over_power,
):  # fmt: skip
    """:func:`bus_balance` over flat arrays (the DP grid): fills the torque [N·m], machine
    electrical power [W], battery power [W], current [A] and ``over_power``."""
    for i in range(torque_in_nm.shape[0]):
        torque_nm[i], p_el_w[i], p_bat_w[i], current_a[i], over_power[i] = bus_balance(
            torque_in_nm[i], p_el_in_w[i], omega_radps[i], p_other_w[i], ocv_v[i], r_dis_ohm[i], r_chg_ohm[i],
            p_chg_max_w[i], kind, const_eff, torque_scale, tab,
        )  # fmt: skip


@njit(cache=True)
def battery_power_limits_many(ocv_v, r_dis_ohm, r_chg_ohm, i_dis_max_a, i_chg_max_a):
    """:func:`battery_power_limits` over flat arrays of OCV [V] and resistances [ohm] (one
    OCV for both directions) -> (discharge, charge) power limits [W]."""
    p_dis = np.empty(ocv_v.shape[0])
    p_chg = np.empty(ocv_v.shape[0])
    for i in range(ocv_v.shape[0]):
        p_dis[i], p_chg[i] = battery_power_limits(
            ocv_v[i], r_dis_ohm[i], ocv_v[i], r_chg_ohm[i], i_dis_max_a, i_chg_max_a
        )
    return p_dis, p_chg
