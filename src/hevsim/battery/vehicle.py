"""Integration point with the forward vehicle simulator (:mod:`hevsim.sim.kernel`).

Three ways to put a pack into the vehicle (the first two: n_s x n_p identical cells):

1. :func:`quasi_static_pack` — a :class:`hevsim.components.battery.BatteryPack` (kind
   ``"table"``) whose OCV and charge/discharge resistances are the cell's OCV and its DC
   resistance ``R_s + Σ R_RC`` over (SOC, T). Usable today, through the existing ``"tables"``
   battery kind, with no kernel change (no RC dynamics, constant temperature).
2. The dynamic ECM kind: :func:`ecm_kernel_tables` builds the battery table tuple,
   :func:`battery_ecm` is the kernel's battery role ``(p, bat, soc, current_sign) -> (ocv,
   R)`` and :func:`battery_ecm_advance` steps the cells' RC, charge and thermal states once the
   step's pack current is known. Over one step of length ``dt`` the pack's step-average
   terminal voltage is exactly ``E - Z I`` (:func:`hevsim.battery.kernel.branch_affine`), so
   the kernel's existing ``OCV - R I`` power solution stays exact. The kernel needs a new
   battery kind and one call after the battery current is solved (see ``docs/battery.md``).

3. The pack kind (``[battery] model = "pack"``, :mod:`hevsim.sim.pack_vehicle`): a whole
   :class:`~hevsim.battery.pack.Pack` (cells with spread, module thermal ROM, cooling loop,
   BMS) run by a :class:`hevsim.battery.bms.PackRun`. The kernel's battery tuple is a
   :data:`PackKernelTables` holding the pack's arrays (:func:`pack_kernel_tables`), and the
   compiled kernel calls :func:`battery_pack_begin` at the start of each step's bus balance
   (the pack's compiled :func:`~hevsim.battery.pack_run.pack_begin`: the step's Thevenin pairs,
   the BMS current limits and the cooling load into the kernel's parameter vector ``p``),
   :func:`battery_pack` as its battery role, and :func:`battery_pack_advance` once the current
   is solved (:func:`~hevsim.battery.pack_run.pack_finish` steps the cells, the module ROMs and
   the cooling loop and returns the SOC): one compiled loop, no Python per step.

The kernel's battery tables are an :class:`EcmTables` named tuple (read by name in compiled
code); :func:`pad_tables_kind` extends a ``"tables"`` kind's
:class:`~hevsim.components.battery.PackTables` to the same types so one compiled dispatcher
serves both kinds.
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
from hevsim.components.battery import BatteryPack, PackTables, pack_resistance
from hevsim.components.bus import battery_power_limits
from hevsim.tables import FloatArray, Table2D

# aux vector of the ECM tuple (entry 11)
AUX = ("n_series", "n_parallel", "dt_s", "port_temp_k", "r_extra_ohm", "heat_w", "cell_temp_k")
A_NS, A_NP, A_DT, A_TPORT, A_REXT, A_HEAT, A_TCELL = range(len(AUX))


class EcmTables(NamedTuple):
    """The battery tables of the forward kernel, by name (both battery kinds).

    The first five entries are the cell's tables over (``soc`` [-], ``temperature_k`` [K]):
    discharge OCV [V], discharge and charge series resistance [ohm]; then the charge OCV [V],
    the capacity-vs-temperature factor [-], the RC pairs of each direction, the cell
    parameter vector (:data:`hevsim.battery.kernel.PARAMS`), the mutable cell state and the
    ``aux`` vector (:data:`AUX`). :func:`pack_tables` reads the first five as the ``"tables"``
    kind's :class:`PackTables`. (Flat on purpose: numba's parallel loops reject nested tuples.)
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


@njit(cache=True, inline="always")
def pack_tables(bat):
    """The ``"tables"`` kind's :class:`PackTables` held in an :class:`EcmTables`."""
    return PackTables(
        soc=bat.soc,
        temperature_k=bat.temperature_k,
        ocv=bat.ocv_discharge_v,
        r_discharge=bat.rs_discharge_ohm,
        r_charge=bat.rs_charge_ohm,
    )


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
    """The battery tables of the dynamic ECM kind (:class:`EcmTables`).

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


def pad_tables_kind(bat: PackTables) -> EcmTables:
    """Extend a ``"tables"`` kind's :class:`PackTables` to the ECM tuple's types (dummy
    entries beyond the pack's tables)."""
    one2 = np.ones((1, 2))
    return EcmTables(
        soc=bat.soc,
        temperature_k=bat.temperature_k,
        ocv_discharge_v=bat.ocv,
        rs_discharge_ohm=bat.r_discharge,
        rs_charge_ohm=bat.r_charge,
        ocv_charge_v=bat.ocv,
        capacity_factor=np.ones(1),
        rc_discharge=one2,
        rc_charge=one2.copy(),
        params=np.zeros(len(K.PARAMS)),
        state=np.zeros(K.N_FIXED_STATES),
        aux=np.zeros(len(AUX)),
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
    """Battery role of the ECM kind: pack ``(E [V], Z [ohm])`` for the step, for a direction.

    The kernel's ``soc`` and ``p`` are not needed (the cells carry their own charge state).
    """
    aux = bat.aux
    e, z = K.branch_affine(*cell_arguments(bat), aux[A_DT], current_sign)
    return aux[A_NS] * e, pack_resistance(z, aux[A_NS], aux[A_NP], aux[A_REXT])


ECM_STEP: dict[str, Any] = {"cache": True, "_nrt": True}
"""Options of :func:`battery_ecm_advance`: it allocates, so reference counting on, explicitly,
that the forward loops compiled without it (:mod:`hevsim.sim._loop`) can call it."""


@njit(**ECM_STEP)
def battery_ecm_advance(p, bat, i_pack, dt):
    """Step the pack's (identical) cells by ``dt`` [s] at pack current ``i_pack`` [A].

    Returns (pack heat [W], cell core temperature [K]); also stored in the aux vector.
    """
    aux = bat.aux
    rec = np.empty(len(K.RECORD))
    K.cell_step(*cell_arguments(bat), i_pack / aux[A_NP], dt, aux[A_TPORT], rec)
    aux[A_HEAT] = rec[K.RHEAT] * aux[A_NS] * aux[A_NP]
    aux[A_TCELL] = rec[K.RTEMP]
    return aux[A_HEAT], aux[A_TCELL]


# -- 3. the pack kind: the pack's compiled step inside the kernel ----------------------------------
PackKernelTables: Any = namedtuple("PackKernelTables", [*ECM_TUPLE, "pack"])  # type: ignore[misc]
"""The pack kind's battery tuple: the :class:`EcmTables` entries of the pack's cell (so that the
kernel's other battery kinds compile for it) and ``pack``, the
:class:`~hevsim.battery.pack_run.PackArrays` of the run's :class:`~hevsim.battery.pack.Pack`."""


def pack_kernel_tables(run: Any, p: FloatArray, dt_s: float) -> Any:
    """The battery tuple of the pack kind for one kernel run of ``run``
    (:class:`hevsim.battery.bms.PackRun`): its pack's arrays, with the kernel's auxiliary load
    ``p[PAUX]`` as the base the cooling adds to each step."""
    from hevsim.battery.pack_run import F_BASEAUX
    from hevsim.components.kernel_params import PAUX

    pack = run.pack
    m = pack.cfg.module
    bat = ecm_kernel_tables(pack.params, pack.cfg.pack.n_modules * m.n_series, m.n_parallel,
                            float(pack.prm[0, K.SOCINI]), float(pack.x[0, K.STEMP]), dt_s)  # fmt: skip
    pack._f[F_BASEAUX] = p[PAUX]
    return PackKernelTables(*bat, pack.arrays)  # type: ignore[call-arg]


def _is_pack_tuple(bat: Any) -> bool:
    return isinstance(bat, types.BaseNamedTuple) and getattr(bat, "instance_class", None) is PackKernelTables


def battery_pack_begin(p: FloatArray, bat: Any) -> None:
    """Pack kind: the BMS's step (:func:`hevsim.battery.pack_run.pack_begin`) sets the kernel's
    current limits ``p[BIDIS]``, ``p[BICHG]`` and its bus load ``p[PAUX]`` (the base + the
    cooling); nothing for the other kinds. (Compiled: a numba overload.)"""
    raise NotImplementedError("compiled only (numba overload)")


def battery_pack(p: FloatArray, bat: Any, soc: float, current_sign: float) -> tuple[float, float]:
    """Battery role of the pack kind: the step's ``(E [V], Z [ohm])`` for a direction."""
    raise NotImplementedError("compiled only (numba overload)")


def battery_pack_advance(p: FloatArray, bat: Any, i_pack: float, dt: float) -> float:
    """Pack kind: step the pack at the solved current ``i_pack`` [A]
    (:func:`hevsim.battery.pack_run.pack_finish`); returns its SOC [-]."""
    raise NotImplementedError("compiled only (numba overload)")


@overload(battery_pack_begin)
def _battery_pack_begin(p, bat):
    if not _is_pack_tuple(bat):
        return lambda p, bat: None
    from hevsim.battery.pack_run import F_BASEAUX, SV_COOLW, SV_LIMC, SV_LIMD, pack_begin
    from hevsim.components.kernel_params import BICHG, BIDIS, PAUX

    def impl(p, bat):
        s = bat.pack
        pack_begin(s)
        p[BIDIS] = s.sv[SV_LIMD]
        p[BICHG] = s.sv[SV_LIMC]
        p[PAUX] = s.f[F_BASEAUX] + s.sv[SV_COOLW]

    return impl


@overload(battery_pack)
def _battery_pack(p, bat, soc, current_sign):
    if not _is_pack_tuple(bat):
        return lambda p, bat, soc, current_sign: (0.0, 1.0)
    from hevsim.battery.pack_run import SV_ECHG, SV_EDIS, SV_ZCHG, SV_ZDIS

    def impl(p, bat, soc, current_sign):
        sv = bat.pack.sv
        if current_sign >= 0.0:
            return sv[SV_EDIS], sv[SV_ZDIS]
        return sv[SV_ECHG], sv[SV_ZCHG]

    return impl


@overload(battery_pack_advance)
def _battery_pack_advance(p, bat, i_pack, dt):
    if not _is_pack_tuple(bat):
        return lambda p, bat, i_pack, dt: 0.0
    from hevsim.battery.pack_run import pack_finish

    def impl(p, bat, i_pack, dt):
        return pack_finish(bat.pack, i_pack, i_pack)

    return impl


# -- 4. the cell kind in the forward loops of the other architectures -------------------------------
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
"""The ``"cell"`` battery of a forward loop (:mod:`hevsim.sim.forward` and its compiled loops):
the :class:`EcmTables` of the series HEV's ECM kind (one representative cell, its state, the
pack's ``n_series`` x ``n_parallel`` and heat-port temperature in ``aux``), the step vector
``sv`` (:data:`CELL_SV`), the records ``rec`` (steps x :data:`CELL_RECORD`) and ``f``
(:data:`CELL_F`). A step is :func:`cell_bus_state` (the pairs, as the ECM kind's
:func:`battery_ecm`) then :func:`cell_finish_power` (the cell step of :func:`battery_ecm_advance`)."""

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
def cell_finish_power(s, power_w):
    """End the step of the cell kind at the bus's terminal power ``power_w`` [W] (> 0
    discharging): the pack current from the pair of the direction the cells take
    (:func:`hevsim.battery.pack_run.pair_current_for_power`), the cells' step at its share
    (:func:`hevsim.battery.kernel.cell_step`, as :func:`battery_ecm_advance`), one record row;
    returns the cells' SOC [-] at the end of the step.

    The cells' direction (their OCV table and RC set) follows the current with a dead band
    (:func:`hevsim.battery.kernel.step_direction`): a cell current within ``switch_band_a``
    keeps the last direction. The current is solved with the power's direction's pair; when
    that current leaves the cells in the other direction and the other pair's current does
    too, that one is taken, so the pack's step-average power is the bus's exactly."""
    sv, aux, f = s.sv, s.aux, s.f
    pos = 1.0 if power_w > 0.0 else -1.0
    j, o = (CSV_EDIS, CSV_ECHG) if pos > 0.0 else (CSV_ECHG, CSV_EDIS)
    i_pack = pair_current_for_power(sv[j], sv[j + 1], power_w)
    band, last = s.params[K.IBAND], s.state[K.SDIR]
    if K.step_direction(i_pack / aux[A_NP], last, band) != pos:  # inside the dead band, kept the other way
        i_other = pair_current_for_power(sv[o], sv[o + 1], power_w)
        if K.step_direction(i_other / aux[A_NP], last, band) == -pos:
            i_pack = i_other
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


# -- 5. one battery step protocol for the forward loops: the pack and the cell kind -----------------
def vehicle_bus_begin(
    s: Any, soc: float, soc_max: float, i_dis_max_a: float, i_chg_max_a: float, aux_w: float,
    discharge_rtol: float, charge_rtol: float,
) -> tuple[float, float, float, float, float, float, float]:  # fmt: skip
    """Begin a step of the battery ``s`` of a compiled forward loop: (OCV [V], discharge and
    charge resistance [ohm], largest charge power [W], the step's discharge and charge current
    limits [A], the bus's other load [W]).

    ``s`` a pack's :class:`~hevsim.battery.pack_run.PackArrays`: the pack's step begins
    (:func:`~hevsim.battery.pack_run.pack_begin`: BMS limits, Thevenin pairs, cooling) and
    :func:`~hevsim.battery.pack_run.pack_bus_state` gives the rest (its limits divided by ``1 +
    rtol``, its base load plus the cooling). ``s`` a :data:`CellBusTables`:
    :func:`cell_bus_state` with the vehicle's limits ``i_dis_max_a``, ``i_chg_max_a`` and load
    ``aux_w``, unchanged. (Compiled only: a numba overload.)"""
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
            return ocv, r_dis, r_chg, p_chg, i_dis_max_a, i_chg_max_a, aux_w

        return cell_impl
    from hevsim.battery.pack_run import pack_begin, pack_bus_state

    def pack_impl(s, soc, soc_max, i_dis_max_a, i_chg_max_a, aux_w, discharge_rtol, charge_rtol):
        pack_begin(s)
        return pack_bus_state(s, soc, soc_max, discharge_rtol, charge_rtol)

    return pack_impl


@overload(vehicle_bus_finish_power)
def _vehicle_bus_finish_power(s, power_w):
    if _is_cell_bus(s):
        return lambda s, power_w: cell_finish_power(s, power_w)
    from hevsim.battery.pack_run import pack_finish_power

    return lambda s, power_w: pack_finish_power(s, power_w)
