"""Integration point with the forward vehicle simulator (:mod:`hevsim.sim.kernel`).

Two ways to put an n_s x n_p pack of identical cells into the vehicle:

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

The ECM table tuple has 12 entries; its first five have the meaning of the ``"tables"``
kind's tuple (SOC axis, temperature axis, OCV, R_dis, R_chg), and :func:`pad_tables_kind`
extends a ``"tables"`` tuple to the same types so one compiled dispatcher serves both kinds.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numba import njit

from hevsim.battery import kernel as K
from hevsim.battery.params import CellParameters, load_cell_parameters
from hevsim.components.battery import BatteryPack
from hevsim.tables import FloatArray, Table2D

# aux vector of the ECM tuple (entry 11)
AUX = ("n_series", "n_parallel", "dt_s", "port_temp_k", "r_extra_ohm", "heat_w", "cell_temp_k")
A_NS, A_NP, A_DT, A_TPORT, A_REXT, A_HEAT, A_TCELL = range(len(AUX))
ECM_TUPLE = (
    "soc",
    "temperature_k",
    "ocv_discharge_v",
    "rs_discharge_ohm",
    "rs_charge_ohm",
    "ocv_charge_v",
    "capacity_factor",
    "rc_discharge",
    "rc_charge",
    "params",
    "state",
    "aux",
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
    fac = 1.0 + p.resistance.alpha_rs_per_k * (t[None, :] - p.capacity.t_ref_k)
    r_d = p.rs_discharge_ohm * fac + p.rc_discharge[:, 0].sum()
    r_c = p.rs_charge_ohm * fac + p.rc_charge[:, 0].sum()
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
    """The battery table tuple of the dynamic ECM kind (layout :data:`ECM_TUPLE`).

    Holds mutable cell state (entry 10): build a fresh tuple for every simulation run.
    """
    p = _params(params)
    tabs = p.tables()  # (soc, T, ocv_c, ocv_d, rs_c, rs_d, capf, rc_d, rc_c)
    aux = np.zeros(len(AUX))
    aux[A_NS], aux[A_NP], aux[A_DT] = n_series, n_parallel, dt_s
    aux[A_TPORT] = temp_k if port_temp_k is None else port_temp_k
    aux[A_REXT] = r_extra_ohm
    aux[A_TCELL] = temp_k
    return (
        tabs[0],
        tabs[1],
        tabs[3],
        tabs[5],
        tabs[4],
        tabs[2],
        tabs[6],
        tabs[7],
        tabs[8],
        p.vector(soc_initial),
        p.initial_state(temp_k),
        aux,
    )


def pad_tables_kind(bat: tuple[FloatArray, ...]) -> tuple[FloatArray, ...]:
    """Extend a ``"tables"`` kind tuple (5 arrays) to the ECM tuple's types (dummy entries)."""
    one2 = np.ones((1, 2))
    return (
        *bat[:5],
        bat[2],
        np.ones(1),
        one2,
        one2.copy(),
        np.zeros(len(K.PARAMS)),
        np.zeros(K.N_FIXED_STATES),
        np.zeros(len(AUX)),
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
    aux = bat[11]
    e, z = K.branch_affine(
        bat[9],
        bat[0],
        bat[1],
        bat[5],
        bat[2],
        bat[4],
        bat[3],
        bat[6],
        bat[7],
        bat[8],
        bat[10],
        aux[A_DT],
        current_sign,
    )
    return aux[A_NS] * e, aux[A_NS] / aux[A_NP] * z + aux[A_REXT]


@njit(cache=True)
def battery_ecm_advance(p, bat, i_pack, dt):
    """Step the pack's (identical) cells by ``dt`` [s] at pack current ``i_pack`` [A].

    Returns (pack heat [W], cell core temperature [K]); also stored in the aux vector.
    """
    aux = bat[11]
    rec = np.empty(len(K.RECORD))
    K.cell_step(
        bat[9],
        bat[0],
        bat[1],
        bat[5],
        bat[2],
        bat[4],
        bat[3],
        bat[6],
        bat[7],
        bat[8],
        bat[10],
        i_pack / aux[A_NP],
        dt,
        aux[A_TPORT],
        rec,
    )
    aux[A_HEAT] = rec[K.RHEAT] * aux[A_NS] * aux[A_NP]
    aux[A_TCELL] = rec[K.RTEMP]
    return aux[A_HEAT], aux[A_TCELL]
