"""Integration point with the forward vehicle simulator: the battery models the one compiled
forward loop of every architecture steps (:func:`hevsim.sim._loop.battery_begin` /
:func:`~hevsim.sim._loop.battery_end`).

Three ways to put a pack into the vehicle (the first two: n_s x n_p identical cells):

1. :func:`quasi_static_pack` — a :class:`hevsim.components.battery.BatteryPack` (kind
   ``"table"``) whose OCV and charge/discharge resistances are the cell's OCV and its DC
   resistance ``R_s + Σ R_RC`` over (SOC, T): the loop's table battery (no RC dynamics,
   constant temperature).
2. The ``"cell"`` battery: one representative electro-thermal cell scaled to the pack, a
   :data:`CellBusTables` (:func:`cell_bus_tables`; :class:`hevsim.battery.cell_run.CellRun`
   holds one run's). Each step :func:`cell_bus_state` gives the pack's step pairs of both
   directions (:func:`battery_ecm`): over one step of length ``dt`` the pack's step-average
   terminal voltage is exactly ``E - Z I`` (:func:`hevsim.battery.kernel.branch_affine`), so
   the vehicle's ``OCV - R I`` power solution stays exact; :func:`cell_finish_power` then steps
   the cells' RC, charge and thermal states at the bus's terminal power
   (:func:`cell_finish_current` at a known pack current).
3. The pack kind (``[battery] model = "pack"``, :mod:`hevsim.sim.pack_vehicle`): a whole
   :class:`~hevsim.battery.pack.Pack` (cells with spread, module thermal ROM, cooling loop,
   BMS) run by a :class:`hevsim.battery.bms.PackRun` on its compiled arrays
   (:class:`~hevsim.battery.pack_run.PackArrays`, :mod:`hevsim.battery.pack_run`).

Section 5 is the one step protocol the loops call for the last two
(:func:`vehicle_bus_begin`, :func:`vehicle_bus_finish_power`, :func:`vehicle_bus_has_bms`);
the cell's tables are an :class:`EcmTables` named tuple (read by name in compiled code).
"""

from __future__ import annotations

from collections import namedtuple
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from numba import njit, types
from numba.extending import overload

from hevsim.battery import kernel as K
from hevsim.battery.pack_run import pair_current_for_power
from hevsim.battery.params import CellParameters, load_cell_parameters
from hevsim.components.battery import BatteryPack, pack_resistance
from hevsim.components.bus import battery_power_limits
from hevsim.tables import FloatArray, Table2D

# aux vector of the ECM tuple (entry 11)
AUX = ("n_series", "n_parallel", "dt_s", "port_temp_k", "r_extra_ohm", "heat_w", "cell_temp_k")
A_NS, A_NP, A_DT, A_TPORT, A_REXT, A_HEAT, A_TCELL = range(len(AUX))


class EcmTables(NamedTuple):
    """The tables and state of a ``"cell"`` battery's representative cell, by name.

    The first five entries are the cell's tables over (``soc`` [-], ``temperature_k`` [K]):
    discharge OCV [V], discharge and charge series resistance [ohm]; then the charge OCV [V],
    the capacity-vs-temperature factor [-], the RC pairs of each direction, the cell
    parameter vector (:data:`hevsim.battery.kernel.PARAMS`), the mutable cell state and the
    ``aux`` vector (:data:`AUX`). (Flat on purpose: numba's parallel loops reject nested tuples.)
    """

    soc: FloatArray
    temperature_k: FloatArray
    ocv_discharge_v: FloatArray
    rs_discharge_ohm: FloatArray
    rs_charge_ohm: FloatArray
    ocv_charge_v: FloatArray
    capacity_factor: FloatArray
    rc_discharge: FloatArray
    rc_charge: FloatArray
    params: FloatArray
    state: FloatArray
    aux: FloatArray


ECM_TUPLE = EcmTables._fields
"""Names of the ECM tuple's entries."""


CellArguments = tuple[
    FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray,
    FloatArray, FloatArray, FloatArray, FloatArray, FloatArray,
]  # fmt: skip
"""The type of :func:`cell_arguments` (11 arrays)."""


@njit(cache=True, inline="always")
def cell_arguments(bat: EcmTables) -> CellArguments:
    """The cell arguments ``prm .. x`` of :func:`hevsim.battery.kernel.branch_affine` and
    :func:`~hevsim.battery.kernel.cell_step` (parameters, tables, state) held in an
    :class:`EcmTables`."""
    return (
        bat.params,
        bat.soc,
        bat.temperature_k,
        bat.ocv_charge_v,
        bat.ocv_discharge_v,
        bat.rs_charge_ohm,
        bat.rs_discharge_ohm,
        bat.capacity_factor,
        bat.rc_discharge,
        bat.rc_charge,
        bat.state,
    )


def _params(params: CellParameters | str | Path) -> CellParameters:
    return params if isinstance(params, CellParameters) else load_cell_parameters(params)


def quasi_static_pack(
    params: CellParameters | str | Path,
    n_series: int,
    n_parallel: int,
    temp_k: float = 298.15,
    **kwargs: object,
) -> BatteryPack:
    """A table pack for the existing ``"tables"`` kind: OCV = mean of the charge and discharge
    OCV tables, R_dis / R_chg = R_s (eq 36 at each table temperature) + Σ R_RC, capacity
    C(temp_k) of eq 35 [A h]. ``kwargs`` go to :class:`BatteryPack` (current limits, ...)."""
    p = _params(params)
    t = p.temperature_k
    prm = p.vector(1.0)

    def r_s(table: FloatArray) -> FloatArray:  # eq 36 on the table's temperature axis
        r = K.series_resistance(table, prm[K.RSCALE], prm[K.ALPHARS], t[None, :], prm[K.TREF])
        if prm[K.EARS] != 0.0:  # its Arrhenius law (issue 27)
            r = r * np.array([K.arrhenius(prm[K.EARS], tk, prm[K.TREF]) for tk in t])[None, :]
        return r

    def r_rc(rc: FloatArray) -> FloatArray:  # sum of the RC resistances at each table temperature
        return np.array([sum(K.rc_values(rc, j, tk, prm[K.TREF])[0] for j in range(rc.shape[0])) for tk in t])

    r_d = r_s(p.rs_discharge_ohm) + r_rc(p.rc_discharge)[None, :]
    r_c = r_s(p.rs_charge_ohm) + r_rc(p.rc_charge)[None, :]
    ocv = 0.5 * (p.ocv_charge_v + p.ocv_discharge_v)
    cap_c = K.cell_capacity(p.vector(1.0), t, p.capacity_factor, 0.0, temp_k)

    def tab(z: FloatArray, name: str) -> Table2D:
        return Table2D(
            p.soc,
            t,
            np.ascontiguousarray(z),
            x_name="soc",
            y_name="temperature_k",
            z_name=name,
            source=f"{p.source} (quasi-static)",
        )

    return BatteryPack(
        name=p.name,
        kind="table",
        ocv_cell=tab(ocv, "ocv_v"),
        r_discharge_cell=tab(r_d, "r_dis_ohm"),
        r_charge_cell=tab(r_c, "r_chg_ohm"),
        capacity_cell_ah=float(cap_c) / 3600.0,
        n_series=n_series,
        n_parallel=n_parallel,
        temperature_k=temp_k,
        **kwargs,  # type: ignore[arg-type]
    )


def ecm_kernel_tables(
    params: CellParameters | str | Path,
    n_series: int,
    n_parallel: int,
    soc_initial: float,
    temp_k: float,
    dt_s: float,
    port_temp_k: float | None = None,
    r_extra_ohm: float = 0.0,
) -> tuple[FloatArray, ...]:
    """The cell tables and state of a ``"cell"`` battery (:class:`EcmTables`).

    Holds mutable cell state (entry 10): build a fresh tuple for every simulation run.
    """
    p = _params(params)
    rc_d, rc_c = p.tables()[7:]  # the RC pairs (a dummy pair without RC elements)
    aux = np.zeros(len(AUX))
    aux[A_NS], aux[A_NP], aux[A_DT] = n_series, n_parallel, dt_s
    aux[A_TPORT] = temp_k if port_temp_k is None else port_temp_k
    aux[A_REXT] = r_extra_ohm
    aux[A_TCELL] = temp_k
    return EcmTables(
        soc=p.soc,
        temperature_k=p.temperature_k,
        ocv_discharge_v=p.ocv_discharge_v,
        rs_discharge_ohm=p.rs_discharge_ohm,
        rs_charge_ohm=p.rs_charge_ohm,
        ocv_charge_v=p.ocv_charge_v,
        capacity_factor=p.capacity_factor,
        rc_discharge=rc_d,
        rc_charge=rc_c,
        params=p.vector(soc_initial),
        state=p.initial_state(temp_k),
        aux=aux,
    )


def vehicle_parameter_values(
    params: CellParameters | str | Path, n_series: int, n_parallel: int, temp_k: float = 298.15
) -> dict[str, float]:
    """Kernel scalar parameters (:data:`hevsim.sim.kernel.PARAMS` names) matching the pack."""
    p = _params(params)
    cap_c = K.cell_capacity(p.vector(1.0), p.temperature_k, p.capacity_factor, 0.0, temp_k)
    return {
        "bat_ns": float(n_series),
        "bat_np": float(n_parallel),
        "bat_capacity_ah": float(cap_c) / 3600.0,
        "bat_coulombic_eff": 1.0,
        "bat_temp_k": temp_k,
    }


@njit(cache=True)
def battery_ecm(p, bat, soc, current_sign):
    """The pack's step pair ``(E [V], Z [ohm])`` of a direction (``current_sign`` > 0:
    discharge) of the cells in ``bat`` (:class:`EcmTables`): exact for the step-average
    terminal voltage ``E - Z I`` over the step ``aux[A_DT]``. ``p`` and ``soc`` are not needed
    (the cells carry their own charge state)."""
    aux = bat.aux
    e, z = K.branch_affine(*cell_arguments(bat), aux[A_DT], current_sign)
    return aux[A_NS] * e, pack_resistance(z, aux[A_NS], aux[A_NP], aux[A_REXT])


# -- 4. the cell kind in the forward loop of every architecture -------------------------------------
CELL_SV = ("e_dis_v", "z_dis_ohm", "e_chg_v", "z_chg_ohm")
"""The step vector of a :data:`CellBusTables` (the pack's step pairs of both directions)."""
CSV_EDIS, CSV_ZDIS, CSV_ECHG, CSV_ZCHG = range(len(CELL_SV))
CELL_RECORD = ("current_a", *K.RECORD)
"""One record row per step of a :data:`CellBusTables`: the cell current [A], then the cell
kernel's record (:data:`hevsim.battery.kernel.RECORD`) of the step."""
CR_I = 0
CELL_F = ("step", "soc")
"""Scalars of a :data:`CellBusTables`: the next record row and the cells' SOC [-] after the last step."""
CF_STEP, CF_SOC = range(len(CELL_F))

CellBusTables: Any = namedtuple("CellBusTables", [*ECM_TUPLE, "sv", "rec", "f"])  # type: ignore[misc]
"""The ``"cell"`` battery of a forward loop (:mod:`hevsim.sim.forward` and its compiled loop):
the :class:`EcmTables` of one representative cell (its tables and state, the pack's
``n_series`` x ``n_parallel`` and heat-port temperature in ``aux``), the step vector ``sv``
(:data:`CELL_SV`), the records ``rec`` (steps x :data:`CELL_RECORD`) and ``f``
(:data:`CELL_F`). A step is :func:`cell_bus_state` (the pairs, :func:`battery_ecm`) then
:func:`cell_finish_power`."""

CELL_STEP: dict[str, Any] = {"cache": True, "_nrt": True}
"""Options of the cell kind's entry points: reference counting on, so that the forward loops
compiled without it can call them (as :data:`hevsim.battery.pack_run.PACK_STEP`)."""


def cell_bus_tables(
    params: CellParameters | str | Path,
    n_series: int,
    n_parallel: int,
    soc_initial: float,
    temp_k: float,
    dt_s: float,
    steps: int,
    port_temp_k: float | None = None,
    r_extra_ohm: float = 0.0,
) -> Any:
    """A fresh :data:`CellBusTables` for one run of ``steps`` steps of ``dt_s`` [s]: the cells
    start at ``soc_initial`` [-] and ``temp_k`` [K]; their heat port is at ``port_temp_k`` [K]
    (default ``temp_k``)."""
    bat = ecm_kernel_tables(params, n_series, n_parallel, soc_initial, temp_k, dt_s, port_temp_k, r_extra_ohm)
    f = np.zeros(len(CELL_F))
    f[CF_SOC] = soc_initial
    return CellBusTables(*bat, np.zeros(len(CELL_SV)), np.zeros((max(steps, 1), len(CELL_RECORD))), f)  # type: ignore[call-arg]


@njit(**CELL_STEP)
def cell_bus_state(s, soc, soc_max, i_dis_max_a, i_chg_max_a):
    """The bus side of a step of the cell kind (as :func:`hevsim.battery.pack_run.pack_bus_state`
    for a pack): fills ``s.sv`` with the pack's step pairs ``(E, Z)`` of each direction
    (:func:`battery_ecm`: exact step-average terminal voltage ``E - Z I``) and returns (OCV [V] =
    the discharge ``E``, discharge and charge resistance [ohm], largest charge power [W] at the
    current limits [A], 0 when the vehicle's SOC ``soc`` [-] is at ``soc_max``)."""
    sv = s.sv
    e_d, z_d = battery_ecm(sv, s, soc, 1.0)
    e_c, z_c = battery_ecm(sv, s, soc, -1.0)
    sv[CSV_EDIS], sv[CSV_ZDIS], sv[CSV_ECHG], sv[CSV_ZCHG] = e_d, z_d, e_c, z_c
    p_chg = battery_power_limits(e_d, z_d, e_d, z_c, i_dis_max_a, i_chg_max_a)[1]
    if soc >= soc_max:  # full: no charging (regeneration goes to the friction brakes)
        p_chg = 0.0
    return e_d, z_d, z_c, p_chg


@njit(**CELL_STEP)
def cell_finish_current(s, i_pack):
    """End the step of the cell kind at the pack current ``i_pack`` [A] (> 0 discharging): the
    cells' step at their share (:func:`hevsim.battery.kernel.cell_step`), one record row;
    returns the cells' SOC [-] at the end of the step."""
    aux, f = s.aux, s.f
    k = int(f[CF_STEP])
    row = s.rec[min(k, s.rec.shape[0] - 1)]
    i_cell = i_pack / aux[A_NP]
    K.cell_step(*cell_arguments(s), i_cell, aux[A_DT], aux[A_TPORT], row[1:])
    row[CR_I] = i_cell
    aux[A_HEAT] = row[1 + K.RHEAT] * aux[A_NS] * aux[A_NP]
    aux[A_TCELL] = row[1 + K.RTEMP]
    f[CF_STEP] = k + 1
    f[CF_SOC] = row[1 + K.RSOC]
    return f[CF_SOC]


@njit(**CELL_STEP)
def cell_finish_power(s, power_w):
    """End the step of the cell kind at the bus's terminal power ``power_w`` [W] (> 0
    discharging): the pack current from the pair of the direction the cells take
    (:func:`hevsim.battery.pack_run.pair_current_for_power`), then :func:`cell_finish_current`;
    returns the cells' SOC [-] at the end of the step.

    The cells' direction (their OCV table and RC set) follows the current with a dead band
    (:func:`hevsim.battery.kernel.step_direction`): a cell current within ``switch_band_a``
    keeps the last direction. The current is solved with the power's direction's pair; when
    that current leaves the cells in the other direction and the other pair's current does
    too, that one is taken, so the pack's step-average power is the bus's exactly."""
    sv, aux = s.sv, s.aux
    pos = 1.0 if power_w > 0.0 else -1.0
    j, o = (CSV_EDIS, CSV_ECHG) if pos > 0.0 else (CSV_ECHG, CSV_EDIS)
    i_pack = pair_current_for_power(sv[j], sv[j + 1], power_w)
    band, last = s.params[K.IBAND], s.state[K.SDIR]
    if K.step_direction(i_pack / aux[A_NP], last, band) != pos:  # inside the dead band, kept the other way
        i_other = pair_current_for_power(sv[o], sv[o + 1], power_w)
        if K.step_direction(i_other / aux[A_NP], last, band) == -pos:
            i_pack = i_other
    return cell_finish_current(s, i_pack)


# -- 5. one battery step protocol for the forward loops: the pack and the cell kind -----------------
def vehicle_bus_begin(
    s: Any, soc: float, soc_max: float, i_dis_max_a: float, i_chg_max_a: float, aux_w: float,
    discharge_rtol: float, charge_rtol: float,
) -> tuple[float, float, float, float, float, float, float, float]:  # fmt: skip
    """Begin a step of the battery ``s`` of a compiled forward loop: (OCV [V], discharge and
    charge resistance [ohm], largest charge power [W], the step's discharge and charge current
    limits [A], the bus's other load [W], the charge pair's OCV [V]).

    ``s`` a pack's :class:`~hevsim.battery.pack_run.PackArrays`: the pack's step begins
    (:func:`~hevsim.battery.pack_run.pack_begin`: BMS limits, Thevenin pairs, cooling) and
    :func:`~hevsim.battery.pack_run.pack_bus_state` gives the rest (its limits divided by ``1 +
    rtol``, its base load plus the cooling). ``s`` a :data:`CellBusTables`:
    :func:`cell_bus_state` with the vehicle's limits ``i_dis_max_a``, ``i_chg_max_a`` and load
    ``aux_w``, unchanged. The OCV is the discharge pair's ``E``; the last value is the charge
    pair's (a bus that solves a charging current with its own pair, as the series HEV's does).
    (Compiled only: a numba overload.)"""
    raise NotImplementedError("compiled only (numba overload)")


def vehicle_bus_finish_power(s: Any, power_w: float) -> float:
    """End the step of the battery ``s`` (as :func:`vehicle_bus_begin`) at the bus's terminal
    power ``power_w`` [W]; returns its SOC [-] (:func:`~hevsim.battery.pack_run.pack_finish_power`,
    :func:`cell_finish_power`). (Compiled only: a numba overload.)"""
    raise NotImplementedError("compiled only (numba overload)")


def _is_cell_bus(s: Any) -> bool:
    return isinstance(s, types.BaseNamedTuple) and getattr(s, "instance_class", None) is CellBusTables


@overload(vehicle_bus_begin)
def _vehicle_bus_begin(s, soc, soc_max, i_dis_max_a, i_chg_max_a, aux_w, discharge_rtol, charge_rtol):
    if _is_cell_bus(s):

        def cell_impl(s, soc, soc_max, i_dis_max_a, i_chg_max_a, aux_w, discharge_rtol, charge_rtol):
            ocv, r_dis, r_chg, p_chg = cell_bus_state(s, soc, soc_max, i_dis_max_a, i_chg_max_a)
            return ocv, r_dis, r_chg, p_chg, i_dis_max_a, i_chg_max_a, aux_w, s.sv[CSV_ECHG]

        return cell_impl
    from hevsim.battery.pack_run import SV_ECHG, pack_begin, pack_bus_state

    def pack_impl(s, soc, soc_max, i_dis_max_a, i_chg_max_a, aux_w, discharge_rtol, charge_rtol):
        pack_begin(s)
        state = pack_bus_state(s, soc, soc_max, discharge_rtol, charge_rtol)
        return (*state, s.sv[SV_ECHG])

    return pack_impl


def vehicle_bus_has_bms(s: Any) -> bool:
    """Whether the battery ``s`` of a compiled forward loop (None: a table battery, a
    :data:`CellBusTables` or a pack's :class:`~hevsim.battery.pack_run.PackArrays`) has a BMS
    whose current limits must hold on every step (issue 24 item 4): a pack's. A table or cell
    battery's limits are the ``[battery]`` section's, held at the step's start as the thesis
    does. (Compiled only: a numba overload, a constant of the type.)"""
    raise NotImplementedError("compiled only (numba overload)")


@overload(vehicle_bus_has_bms, inline="always")
def _vehicle_bus_has_bms(s):
    bms = not (s is None or isinstance(s, types.NoneType) or _is_cell_bus(s))
    return lambda s: bms


@overload(vehicle_bus_finish_power)
def _vehicle_bus_finish_power(s, power_w):
    if _is_cell_bus(s):
        return lambda s, power_w: cell_finish_power(s, power_w)
    from hevsim.battery.pack_run import pack_finish_power

    return lambda s, power_w: pack_finish_power(s, power_w)
