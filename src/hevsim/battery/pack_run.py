"""One compiled step of a whole pack: BMS, cells, module thermal ROM, cooling loop, records.

:class:`~hevsim.battery.pack.Pack` keeps its state in the arrays of a :class:`PackArrays`
named tuple, and a step is two compiled calls on it (the same operations as the pack's
module docstring describes, in the same order):

* :func:`pack_begin`: the hottest cell core and the temperature derating factor, the cooling
  loop's decision for the step (:func:`loop_begin`: pump, radiator, chiller, the plates'
  inlets), the pack's step Thevenin pairs ``E - Z I`` for each direction and the BMS's current
  limits (:mod:`hevsim.battery.bms`), written into the step vector ``sv`` (``SV_*``);
* :func:`pack_finish`: the cells at the pack current (one compiled pass,
  :func:`~hevsim.battery.pack.pack_pass_linear`), the module ROMs in modal coordinates
  (:func:`rom_modal`) or the coolant ports, the loop's temperature (:func:`loop_end`), the
  energy terms (``acc``, :data:`~hevsim.battery.pack.ENERGY_TERMS`), the cells' ageing stress
  and one row of records (``rec``, :data:`RECORD_CHANNELS`; ``hot``: per-module hot spots).

The vehicle's compiled series kernel calls both directly (no Python per step,
:mod:`hevsim.battery.vehicle` section 3); :meth:`Pack.simulate
<hevsim.battery.pack.Pack.simulate>` runs :func:`pack_simulate`; the Python forward loop and
:meth:`Pack.step <hevsim.battery.pack.Pack.step>` call them one step at a time.

**ROM in modal coordinates.** The reduced matrix ``A_r = K_s,r + h K_w,r`` is symmetric (the
basis is C-orthonormal), so ``A_r = Q diag(lambda) Q^T`` with ``Q`` orthogonal and the
implicit-Euler step of :class:`~hevsim.thermal.rom.RomStepper` is, for ``w = Q^T z``,
``w_1 = (w_0 / dt + Q^T B_r(h) u_1) / (1 / dt + lambda)``: the same step (up to rounding)
at a fraction of the products (the inputs' ``r x 44`` instead of ``r x (r + 44)``), and the
outputs (cell means, wall temperatures, film heat) are one product with the output rows
times ``Q``. The hot spot of a module (the largest of its cells' candidate nodes) is exact to
rounding, with only the rows that can be the largest evaluated (:func:`_module_hot_spots`).
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np
from numba import njit

from hevsim.battery.cooling import LP_INF, LP_PFLOW, LP_RHOCP, LP_ZEROC, LS_TEMP, loop_begin, loop_end
from hevsim.battery.kernel import SOCINI, SQ, SQABS, STEMP, cell_capacity
from hevsim.battery.pack_kernels import NO_REFCOUNT, pack_pairs, pack_pass, pack_pass_linear
from hevsim.components.bus import battery_power_limits
from hevsim.tables import FloatArray

#: scalar entries of :attr:`PackArrays.f` (sizes, flags and the run's running values)
F_NAMES = (
    "dt_s", "n_groups_sim", "n_p_sim", "representative", "module_n_series", "module_n_parallel",
    "weight", "n_modules", "sim_per_module", "max_current_a", "ambient_k", "linear", "ez_valid", "rom",
    "h_plate", "time_s", "step", "soc", "soc_min", "soc_max", "stress", "v_min", "v_max", "base_aux_w",
    "rom_b_amb_w_k", "rom_f_const_w", "activation_k", "hot_spot_started",
    "hot_spot_rows", "hot_spot_rebase_k", "hot_spot_rows_double", "hot_spot_skip", "hot_spot_rows_read",
    "hot_spot_slack_k", "hot_spot_basis_size", "hot_spot_basis_adds", "hot_spot_basis_rebuilds",
    "hot_spot_row_residual_max", "hot_spot_gap_k", "hot_spot_calls", "hot_spot_last_cut",
    "hot_spot_kept", "hot_spot_screens", "hot_spot_basis_orth",
)  # fmt: skip
(F_DT, F_NG, F_NP, F_REP, F_NS, F_NPAR, F_WEIGHT, F_NMOD, F_SIMPM, F_IMAX, F_AMB, F_LINEAR, F_EZVALID,
 F_ROM, F_H, F_TIME, F_STEP, F_SOC, F_SOCMIN, F_SOCMAX, F_STRESS, F_VMIN, F_VMAX, F_BASEAUX, F_BAMB,
 F_FCONST, F_ACT, F_HSINIT, F_HSROWS, F_HSREBASE, F_HSROWS64, F_HSSKIP, F_HSREAD, F_HSEPS, F_HSK,
 F_HSADDS, F_HSREBUILDS, F_HSGRESMAX, F_HSGAP, F_HSCALLS, F_HSLASTCUT, F_HSREUSE,
 F_HSSCREENS, F_HSORTH) = range(len(F_NAMES))  # fmt: skip

#: the step vector :attr:`PackArrays.sv` that :func:`pack_begin` fills
SV_NAMES = (
    "hottest_k", "factor", "e_dis_v", "z_dis_ohm", "e_chg_v", "z_chg_ohm", "limit_dis_a", "limit_chg_a",
    "reason_dis", "reason_chg", "cooling_w", "supply_k", "plate_flow_m3_s", "radiator_w", "chiller_w",
    "chiller_power_w", "pump_power_w", "fan_power_w", "loop_ambient_w",
)  # fmt: skip
(SV_HOT, SV_FACTOR, SV_EDIS, SV_ZDIS, SV_ECHG, SV_ZCHG, SV_LIMD, SV_LIMC, SV_WHYD, SV_WHYC, SV_COOLW,
 SV_SUPPLY, SV_PFLOW, SV_RAD, SV_CH, SV_CHP, SV_PUMP, SV_FAN, SV_LAMB) = range(len(SV_NAMES))  # fmt: skip

LIMIT_NAMES = ("none", "temperature", "soc", "voltage")
"""What binds a BMS current limit (the ``bms_*_limit_reason`` channel codes)."""

#: per-step pack channels of a vehicle run (:data:`hevsim.battery.bms.CHANNELS`)
VEHICLE_CHANNELS = (
    "pack_current_a", "pack_voltage_v", "pack_power_w", "pack_ocv_v", "pack_resistance_ohm",
    "bms_discharge_limit_a", "bms_charge_limit_a", "bms_discharge_reason", "bms_charge_reason",
    "derating_factor", "hottest_cell_temp_k", "hot_spot_temp_k", "cell_soc_min", "cell_soc_max",
    "cell_soc_spread", "coolant_loop_temp_k", "coolant_supply_temp_k", "pump_power_w", "fan_power_w",
    "chiller_power_w", "chiller_heat_w", "cooling_power_w", "plate_heat_w",
)  # fmt: skip
#: one row of :attr:`PackArrays.rec` per step: :data:`VEHICLE_CHANNELS` then the rest of
#: :data:`hevsim.battery.pack.STEP_CHANNELS`
RECORD_CHANNELS = (
    *VEHICLE_CHANNELS,
    "time_s",
    "current_request_a",
    "voltage_end_v",
    "module_ambient_w",
    "radiator_w",
)
(R_I, R_V, R_P, R_E, R_Z, R_LIMD, R_LIMC, R_WHYD, R_WHYC, R_FACTOR, R_HOT, R_HOTSPOT, R_SOCMIN, R_SOCMAX,
 R_SPREAD, R_LOOP, R_SUPPLY, R_PUMP, R_FAN, R_CHP, R_CH, R_COOL, R_PLATE, R_TIME, R_REQ, R_VEND, R_MODAMB,
 R_RAD) = range(len(RECORD_CHANNELS))  # fmt: skip
#: :data:`hevsim.battery.pack.STEP_CHANNELS` -> the record column holding it
STEP_TO_RECORD = {
    "time_s": "time_s", "current_request_a": "current_request_a", "current_a": "pack_current_a",
    "voltage_v": "voltage_end_v", "voltage_avg_v": "pack_voltage_v", "power_w": "pack_power_w",
    "derating_factor": "derating_factor", "hottest_cell_temp_k": "hottest_cell_temp_k",
    "hot_spot_temp_k": "hot_spot_temp_k", "min_soc": "cell_soc_min", "max_soc": "cell_soc_max",
    "loop_temp_k": "coolant_loop_temp_k", "supply_temp_k": "coolant_supply_temp_k",
    "plate_heat_w": "plate_heat_w", "module_ambient_w": "module_ambient_w", "radiator_w": "radiator_w",
    "chiller_w": "chiller_heat_w", "chiller_power_w": "chiller_power_w", "pump_power_w": "pump_power_w",
    "fan_power_w": "fan_power_w",
}  # fmt: skip
#: energy terms (:data:`hevsim.battery.pack.ENERGY_TERMS` order) in :attr:`PackArrays.acc`
(A_EL, A_CHEM, A_CELLHEAT, A_PORT, A_PLATE, A_MODAMB, A_RAD, A_CH, A_LOOPAMB, A_PUMP, A_RES, A_THRU,
 A_CHEL, A_FANEL) = range(14)  # fmt: skip
#: ageing stress rows (:class:`hevsim.battery.life.CellStress`) and its two counters
ST_DIS, ST_ABS, ST_MOVING, ST_ARR, ST_SOC, ST_TEMP, ST_SOCMIN, ST_SOCMAX = range(8)


class PackArrays(NamedTuple):
    """A pack's arrays (SI), read by name in compiled code (module docstring).

    Cells: parameters ``prm``/state ``x`` (rows per simulated cell), the cell tables (as
    :meth:`hevsim.battery.params.CellParameters.tables`), the affine pairs ``ez``/``oc``/``pairs``/
    ``totals`` and RC constants ``rcc`` of :func:`~hevsim.battery.pack.pack_pass_linear`, port
    temperatures ``port_k`` [K], the last step's per-cell record ``cells`` (current [A], SOC,
    core temperature [K], port heat [W], voltage [V]) and energies ``energy`` [J]. Loop: ``lp``
    (``LP_*``), ``ls`` (``LS_*``), plate inlets ``inlet_k`` and last plate heats ``plate_heat_w``
    per module. Derating tables (``[derating]``). ROM (empty without one): modal decay
    ``1 / (1/dt + lambda)`` ``rom_decay`` (r,), inputs ``rom_in`` (m_in, r) (``(Q^T B_r(h))^T``),
    outputs ``rom_out`` (r, n_cells + n_seg + 1) (cell means, wall integrals, film row, times Q),
    candidate rows ``rom_cand`` (n_rows, r; each cell's distinct candidates) with the hot-spot
    screening's arrays (``hs_*``, :func:`_module_hot_spots`; ``hs_basis``, ``hs_gb``, ``hs_gb32``,
    ``hs_gres``, ``hs_cov``, ``hs_up``, ``hs_gbt32``, ``hs_keep``, ``hs_hot``:
    :func:`_module_hot_spots_within`), modal states ``rom_w``
    (n_modules, r), input rows ``rom_u`` (n_modules, m_in), last outputs ``rom_y``, the channel's
    segment mean and exit factors and the wall areas [m^2]. Records: ``acc``, ``sv``, ``rec``,
    ``hot``, ``stress`` (8, n_cells) and ``stress_n`` (steps, duration [s]).
    """

    f: FloatArray
    prm: FloatArray
    x: FloatArray
    soc_ax: FloatArray
    t_ax: FloatArray
    ocv_c: FloatArray
    ocv_d: FloatArray
    rs_c: FloatArray
    rs_d: FloatArray
    capf: FloatArray
    rc_d: FloatArray
    rc_c: FloatArray
    ez: FloatArray
    oc: FloatArray
    rcc: FloatArray
    pairs: FloatArray
    totals: FloatArray
    port_k: FloatArray
    cells: FloatArray
    energy: FloatArray
    lp: FloatArray
    ls: FloatArray
    inlet_k: FloatArray
    plate_heat_w: FloatArray
    d_temp_c: FloatArray
    d_factor: FloatArray
    d_soc: FloatArray
    d_dis: FloatArray
    d_chg: FloatArray
    rom_decay: FloatArray
    rom_in: FloatArray
    rom_out: FloatArray
    rom_cand: FloatArray
    hs_norm: FloatArray
    hs_unit: FloatArray
    hs_energy: FloatArray
    hs_ub: FloatArray
    hs_prev: FloatArray
    hs_blk: FloatArray
    hs_block: FloatArray
    hs_gmax: FloatArray
    hs_g32: FloatArray
    hs_d32: FloatArray
    hs_cand: FloatArray
    hs_const: FloatArray
    hs_basis: FloatArray
    hs_gb: FloatArray
    hs_gb32: FloatArray
    hs_gres: FloatArray
    hs_cov: FloatArray
    hs_up: FloatArray
    hs_gbt32: FloatArray
    hs_keep: FloatArray
    hs_hot: FloatArray
    rom_w: FloatArray
    rom_u: FloatArray
    rom_y: FloatArray
    ch_mean: FloatArray
    ch_decay: FloatArray
    wall_area_m2: FloatArray
    acc: FloatArray
    sv: FloatArray
    rec: FloatArray
    hot: FloatArray
    stress: FloatArray
    stress_n: FloatArray


EMPTY_STEP_FRACTION = 0.5
"""The BMS's hard SOC cut-off [-]: a step may take at most this share of the charge left in
the emptiest cell (or of the room left in the fullest), at the cell's mean share of the pack
current, so a cell approaches SOC 0 (1) without crossing it even when ``pack.max_current_a``
makes the ``[derating] soc`` factors ineffective. A cell of a parallel group carries up to
twice its mean share before the check (:func:`hevsim.battery.cell.check_cell_domain`) stops
the run."""


@njit(cache=True)
def _binding(i_max, a, b, c):
    """(smallest of ``i_max, a, b, c`` clipped at 0, its index; the first wins ties)."""
    best, why = i_max, 0
    if a < best:
        best, why = a, 1
    if b < best:
        best, why = b, 2
    if c < best:
        best, why = c, 3
    return max(best, 0.0), why


PACK_STEP: dict[str, Any] = {"cache": True, "_nrt": True}
"""Options of the pack step's entry points (:func:`pack_begin`, :func:`pack_finish`): numba's
reference counting on explicitly, so that the forward loops compiled without it (``_nrt=False``,
:mod:`hevsim.sim._loop`) can call them (a callee otherwise inherits its caller's option, and the
step's work arrays need it). The bus side (:func:`pack_bus_state`, :func:`pack_current_for_power`,
:func:`pack_finish_power`) allocates nothing and runs without it: counting the references of the
pack's 66 arrays on each call cost the loop about 3 us a step."""


@njit(**PACK_STEP)
def pack_begin(s):
    """The first half of a step (module docstring): fills ``s.sv``."""
    f, sv = s.f, s.sv
    dt = f[F_DT]
    hottest = -np.inf
    for c in range(s.x.shape[0]):
        hottest = max(hottest, s.x[c, STEMP])
    factor = np.interp(hottest - s.lp[LP_ZEROC], s.d_temp_c, s.d_factor)
    sv[SV_HOT] = hottest
    sv[SV_FACTOR] = factor
    loop_begin(s.lp, s.ls, hottest, f[F_AMB], dt, s.plate_heat_w, s.inlet_k, sv[SV_SUPPLY:])
    if f[F_ROM] == 0.0:
        spm = int(f[F_SIMPM])
        for c in range(s.port_k.shape[0]):
            s.port_k[c] = s.inlet_k[c // spm]
    if f[F_EZVALID] == 0.0:
        pack_pairs(s.prm, s.soc_ax, s.t_ax, s.ocv_c, s.ocv_d, s.rs_c, s.rs_d, s.capf, s.rc_d, s.rc_c, s.x,
                   int(f[F_NG]), int(f[F_NP]), dt, s.ez, s.oc, s.rcc, f[F_LINEAR] > 0.0, s.pairs,
                   s.totals)  # fmt: skip
        f[F_EZVALID] = 1.0
    rep = f[F_REP] > 0.0
    n_par = f[F_NPAR]
    i_max = f[F_IMAX]
    # the pack's pairs and the series groups' voltage limits (representative: n_parallel cells
    # in parallel in each of the module's n_series groups)
    i_v = np.empty(2)
    for d in range(2):
        e, z = s.totals[2 * d], s.totals[2 * d + 1]
        if rep:
            e, z = f[F_NS] * e, f[F_NS] * z / n_par
        sv[SV_EDIS + 2 * d] = e
        sv[SV_ZDIS + 2 * d] = z
        lim = np.inf
        for g in range(s.pairs.shape[0]):
            zg = s.pairs[g, 2 * d + 1] / n_par if rep else s.pairs[g, 2 * d + 1]
            eg = s.pairs[g, 2 * d]
            lim = min(lim, (eg - f[F_VMIN]) / zg if d == 0 else (f[F_VMAX] - eg) / zg)
        i_v[d] = lim
    f_dis = np.interp(f[F_SOCMIN], s.d_soc, s.d_dis)
    f_chg = np.interp(f[F_SOCMAX], s.d_soc, s.d_chg)
    # the hard SOC cut-off: at most EMPTY_STEP_FRACTION of the charge left in (or room left
    # in) the emptiest (fullest) cell per step, at the cell's mean share of the pack current
    q_out, q_in = np.inf, np.inf
    for c in range(s.x.shape[0]):
        cap = cell_capacity(s.prm[c], s.t_ax, s.capf, s.x[c, SQABS], s.x[c, STEMP])
        soc = s.prm[c, SOCINI] - s.x[c, SQ] / cap
        q_out = min(q_out, max(soc, 0.0) * cap)
        q_in = min(q_in, max(1.0 - soc, 0.0) * cap)
    share = n_par if rep else f[F_NP]
    i_dis_soc = min(f_dis * i_max, EMPTY_STEP_FRACTION * share * q_out / dt)
    i_chg_soc = min(f_chg * i_max, EMPTY_STEP_FRACTION * share * q_in / dt)
    sv[SV_LIMD], sv[SV_WHYD] = _binding(i_max, factor * i_max, i_dis_soc, i_v[0])
    sv[SV_LIMC], sv[SV_WHYC] = _binding(i_max, factor * i_max, i_chg_soc, i_v[1])
    sv[SV_COOLW] = sv[SV_PUMP] + sv[SV_FAN] + sv[SV_CHP]


#: absolute slack [K] added to the hot-spot bounds per step (the rounding of the products)
HOT_SPOT_SLACK_K = 1e-10
#: the bounds' running sums [K] beyond which every row is evaluated afresh and the sums restart
#: (their rounding, ~1e-16 of them, stays far below the slack): ``f[F_HSREBASE]``'s default
HOT_SPOT_REBASE_K = 1e3
#: columns of :attr:`PackArrays.hs_prev` after the modal deviation ``d`` (r columns): the
#: module's kept values (mean, hottest row, running sums) and the step's (rounding terms, lower
#: bound, hottest value, full scan, kept rows, block flag and top)
HP_NAMES = ("t_ref", "best", "rise", "grow", "big_e", "small_e", "low", "best_value", "full", "n_cand",
            "need", "top")  # fmt: skip
(HP_TREF, HP_BEST, HP_RISE, HP_GROW, HP_BIGE, HP_SMALLE, HP_LOW, HP_BESTV, HP_FULL, HP_NCAND, HP_NEED,
 HP_TOP) = range(len(HP_NAMES))  # fmt: skip


@njit(cache=True, fastmath=True)
def _dot(a, b):
    """``a . b`` (vectorised: the sum's order is the compiler's, a rounding of ~1e-16 relative)."""
    acc = 0.0
    for i in range(a.shape[0]):
        acc += a[i] * b[i]
    return acc


@njit(cache=True, fastmath=True)
def _deviation_change(wm, unit, t_ref, d_prev):
    """``|d - d_prev|^2`` for the deviation ``d = wm - t_ref unit`` (:func:`_module_hot_spots`),
    which replaces ``d_prev`` (vectorised, as :func:`_dot`: it only sizes a bound)."""
    acc = 0.0
    for i in range(wm.shape[0]):
        d = wm[i] - t_ref * unit[i]
        acc += (d - d_prev[i]) ** 2
        d_prev[i] = d
    return acc


@njit(cache=True, fastmath=True)
def _dot32(a, b):
    """``a . b`` of two float32 vectors, accumulated in float32 (vectorised: any summation order;
    the rounding bound of :func:`_module_hot_spots` holds for every order)."""
    acc = np.float32(0.0)
    for i in range(a.shape[0]):
        acc += a[i] * b[i]
    return acc


@njit(**NO_REFCOUNT)
def _module_hot_spots(s, w, hot):
    """Per-module hot spot [K]: the largest candidate-node temperature ``G_j w`` of each
    module's cells (``G = rom_cand``, modal; every node of the cells for a ROM built with
    ``candidates = 0``), exactly the largest of the rows evaluated in double (:func:`_dot`),
    with few rows evaluated in double.

    Every candidate row satisfies ``G_j u = 1`` (to ``eta``, ``hs_const``) for the modal state
    ``u`` of the uniform 1 K field, so with ``T_ref = e.w / e.u`` (the module's mean, ``e`` the
    stored-heat row) and ``d = w - T_ref u``, a row changes over a step by ``dT_ref + G_j dd``
    and ``|G_j dd| <= |G_j| |dd|``. With the running sums ``R`` of ``dT_ref`` (plus a slack for
    rounding) and ``S`` of ``|dd|`` since the module's last full evaluation, row ``j``
    evaluated to at most ``y`` keeps the offset ``a_j = y - R - |G_j| S`` and stays below
    ``a_j + R + |G_j| S`` (no per-step update). The rows come in blocks (one per cell,
    ``hs_block`` offsets) with the largest ``|G_j|`` of each (``hs_gmax``): a block keeps the
    offset ``b = B - R - gmax S`` of the largest row bound ``B`` when it was last scanned, so
    ``b + R + gmax S`` bounds all its rows.

    A row that the bounds cannot exclude is first evaluated in single precision (issue 26:
    the rows of all the cells' nodes lie within a few millikelvin of each other, so the bounds
    alone leave about half of them): ``T_ref + G32_j d32`` is within
    ``e_j = |G_j| E + c`` of the row's double value ``v_j = G_j . w`` (:func:`_dot`), with
    ``E = g32 |d| + g64 (|w| + |T_ref| |u|)`` (``g32 = gamma_{r+2}`` in single precision: the
    rounding of G and d to float32 and of the sum in any order; ``g64``: the double product
    and the rounding of ``d``) and ``c = |T_ref| 2 eta`` plus 1e-12 K. A step evaluates the
    row that was the hottest in double (the lower bound ``L`` of the maximum), then scans the
    blocks whose bound exceeds ``L`` and, in them, the rows whose own bound exceeds it, in
    single precision, raising ``L`` to ``y32 - e_j`` and keeping the rows with
    ``y32 + e_j >= L`` (``hs_cand``); at the end the kept rows whose ``y32 + e_j`` reaches the
    final ``L`` are evaluated in double, and the hot spot is the largest of those values: every
    row left out has ``v_j <= L <=`` that maximum, so it is the maximum of ``v_j`` over all rows
    (bit for bit). The first step (and one whose sums passed ``f[F_HSREBASE]``, by default
    :data:`HOT_SPOT_REBASE_K`) scans every row. With ``hs_const[0] = 0`` the scan evaluates
    in double (as before issue 26's single-precision pass; benchmarks compare the two).

    The modules are screened together, row by row (each module's own bounds, in the same
    order as one module alone, so the same rows and values): a row's single-precision
    coefficients are read once per step for every module that needs it, instead of once per
    module (the rows of all the cells, ``4 n r`` bytes, exceed the cache; reading them was the
    screening's cost; ``f[F_HSREAD]`` counts the rows read, ``f[F_HSROWS]`` the rows evaluated).
    Per-module values of the step live in ``hs_prev``'s columns ``HP_*``."""
    g, gn, unit, en = s.rom_cand, s.hs_norm, s.hs_unit, s.hs_energy
    a, prev, blk, start, gmax = s.hs_ub, s.hs_prev, s.hs_blk, s.hs_block, s.hs_gmax
    g32, d32, cand, hc = s.hs_g32, s.hs_d32, s.hs_cand, s.hs_const
    n_mod, r = w.shape
    n_blocks = gmax.shape[0]
    e_u = _dot(en, unit)
    first = s.f[F_HSINIT] == 0.0
    rebase = s.f[F_HSREBASE]
    single = hc[0] > 0.0
    evaluated = 0
    doubles = 0
    reads = 0
    for m in range(n_mod):
        wm = w[m]
        pm = prev[m]
        t_ref = _dot(en, wm) / e_u
        dd2 = _deviation_change(wm, unit, t_ref, pm[:r])
        rise = pm[r + HP_RISE] + (t_ref - pm[r + HP_TREF] + HOT_SPOT_SLACK_K)
        grow = pm[r + HP_GROW] + math.sqrt(dd2) * (1.0 + 1e-12)
        pm[r + HP_TREF] = t_ref
        d_norm2 = 0.0
        w_norm2 = 0.0
        for i in range(r):
            di = pm[i]
            d32[m, i] = np.float32(di)
            d_norm2 += di * di
            w_norm2 += wm[i] * wm[i]
        # e_j = |G_j| big_e + small_e (hs_const: g32, g64, eta, |u|); 1 % for these sums' rounding
        big_e = hc[0] * math.sqrt(d_norm2) + hc[1] * (math.sqrt(w_norm2) + abs(t_ref) * hc[3])
        pm[r + HP_BIGE] = 1.01 * big_e
        pm[r + HP_SMALLE] = 1.01 * abs(t_ref) * 2.0 * hc[2] + 1e-12
        pm[r + HP_NCAND] = 0.0
        full = first or grow > rebase or abs(rise) > rebase
        pm[r + HP_FULL] = 1.0 if full else 0.0
        if full:
            pm[r + HP_RISE] = pm[r + HP_GROW] = 0.0
            pm[r + HP_LOW] = pm[r + HP_BESTV] = -np.inf
        else:
            pm[r + HP_RISE], pm[r + HP_GROW] = rise, grow
            j_best = int(pm[r + HP_BEST])
            low = _dot(g[j_best], wm)
            pm[r + HP_LOW] = pm[r + HP_BESTV] = low
            a[m, j_best] = low - rise - gn[j_best] * grow
            doubles += 1
            evaluated += 1
    for k in range(n_blocks):
        need_any = False
        for m in range(n_mod):
            pm = prev[m]
            reach = blk[m, k] + pm[r + HP_RISE] + gmax[k] * pm[r + HP_GROW]
            need = pm[r + HP_FULL] > 0.0 or reach > pm[r + HP_LOW]
            pm[r + HP_NEED] = 1.0 if need else 0.0
            pm[r + HP_TOP] = -np.inf
            need_any = need_any or need
        if not need_any:
            continue
        for j in range(int(start[k]), int(start[k + 1])):
            read = False
            for m in range(n_mod):
                pm = prev[m]
                if pm[r + HP_NEED] == 0.0:
                    continue
                rise, grow, low = pm[r + HP_RISE], pm[r + HP_GROW], pm[r + HP_LOW]
                bound = a[m, j] + rise + gn[j] * grow
                if pm[r + HP_FULL] > 0.0 or (bound > low and j != int(pm[r + HP_BEST])):
                    if single:
                        e_j = gn[j] * pm[r + HP_BIGE] + pm[r + HP_SMALLE]
                        y = pm[r + HP_TREF] + _dot32(g32[j], d32[m])
                    else:  # hs_const[0] = 0: every row in double (the reference for benchmarks)
                        e_j = 0.0
                        y = _dot(g[j], w[m])
                    bound = y + e_j
                    a[m, j] = bound - rise - gn[j] * grow
                    evaluated += 1
                    read = True
                    if y - e_j > low:
                        low = y - e_j
                        pm[r + HP_LOW] = low
                    if bound >= low:
                        nc = int(pm[r + HP_NCAND])
                        cand[m, nc] = j
                        pm[r + HP_NCAND] = nc + 1
                if bound > pm[r + HP_TOP]:
                    pm[r + HP_TOP] = bound
            reads += read
        for m in range(n_mod):
            pm = prev[m]
            if pm[r + HP_NEED] > 0.0:
                blk[m, k] = pm[r + HP_TOP] + HOT_SPOT_SLACK_K - pm[r + HP_RISE] - gmax[k] * pm[r + HP_GROW]
    for m in range(n_mod):
        pm = prev[m]
        wm = w[m]
        rise, grow, low = pm[r + HP_RISE], pm[r + HP_GROW], pm[r + HP_LOW]
        best = pm[r + HP_BESTV]
        j_best = int(pm[r + HP_BEST])
        for c in range(int(pm[r + HP_NCAND])):
            j = cand[m, c]
            if a[m, j] + rise + gn[j] * grow >= low - 1e-12:  # (the offset's rounding)
                y = _dot(g[j], wm)
                a[m, j] = y - rise - gn[j] * grow
                doubles += 1
                if y > best:
                    best, j_best = y, j
        pm[r + HP_BEST] = j_best
        hot[m] = best
    s.f[F_HSROWS] += evaluated
    s.f[F_HSROWS64] += doubles
    s.f[F_HSREAD] += reads
    s.f[F_HSINIT] = 1.0


#: the slack screening (:func:`_module_hot_spots_within`): most directions of its basis [-]
HOT_SPOT_BASIS_MAX = 32
#: directions a full basis is cut down to (the leading ones of the recent states) [-]
HOT_SPOT_BASIS_KEEP = 20
#: per-step decay of the recent states' second moment that picks the directions kept [-]
HOT_SPOT_BASIS_DECAY = 0.99
#: share of the slack the residual's bound may take before the basis grows [-]
HOT_SPOT_RESIDUAL_SHARE = 1.0
#: rows a module may evaluate in double in a step (besides the first) before the basis grows [-]
HOT_SPOT_ROWS_PER_ADD = 8
#: fewest steps between two cuts of a full basis [-]: a run whose deviations span more
#: directions than the basis holds evaluates more rows in double instead of cutting every step
HOT_SPOT_CUT_EVERY = 10


@njit(cache=True, fastmath=True)
def _axpy32(acc, gt, i, a, n):
    """``acc[:n] += a * gt[i, :n]`` in float32 (vectorised; any order is within the bound of
    :func:`_module_hot_spots_within`)."""
    for j in range(n):
        acc[j] += gt[i, j] * a


#: marks a row evaluated in double in the bounds of :func:`_module_hot_spots_within` (finite:
#: the vectorised helpers assume no infinities)
_EVALUATED = -1e300


@njit(cache=True, fastmath=True)
def _bounds(acc, gn, gres, big, rn, small, up):
    """``up_j = acc_j + |G_j| big + gres_j rn + small`` (vectorised); returns their largest."""
    top = _EVALUATED
    for j in range(acc.shape[0]):
        u = np.float64(acc[j]) + gn[j] * big + gres[j] * rn + small
        up[j] = u
        top = max(top, u)
    return top


@njit(cache=True, fastmath=True)
def _project(basis, k, d, c, res):
    """Coefficients ``c = B d`` (``B = basis[:k]``, orthonormal rows) and residual
    ``res = d - B^T c``; returns ``(|res|, |B res|)`` (the second measures the residual's
    rounding out of ``span B``)."""
    r = d.shape[0]
    for i in range(r):
        res[i] = d[i]
    for q in range(k):
        acc = 0.0
        for i in range(r):
            acc += basis[q, i] * d[i]
        c[q] = acc
        for i in range(r):
            res[i] -= acc * basis[q, i]
    rn2 = 0.0
    for i in range(r):
        rn2 += res[i] * res[i]
    br2 = 0.0
    for q in range(k):
        acc = 0.0
        for i in range(r):
            acc += basis[q, i] * res[i]
        br2 += acc * acc
    return math.sqrt(rn2), math.sqrt(br2)


@njit(cache=True, fastmath=True)
def _coefficients(basis, k, d, c, orth):
    """Coefficients ``c = B d`` (``B = basis[:k]``) and upper bounds ``(|res|, |B res|)`` of the
    residual ``res = d - B^T c`` (for the coefficients as rounded) without forming it (one
    product instead of :func:`_project`'s three): with ``c = B d + dc``,
    ``|dc| <= sqrt(k) gamma_r |B_q| |d|`` (any summation order) and ``E = B B^T - I``
    (``|E| <= orth``, :func:`_basis_rows_changed`),
    ``|res|^2 = |d|^2 - |c|^2 + 2 c.dc + c^T E c`` and ``B res = -dc - E c``; the norms' own
    rounding (``gamma_r``, ``gamma_k``) included."""
    r = d.shape[0]
    u64 = 2.0**-53
    g_r = r * u64 / (1.0 - r * u64)
    g_k = (k + 1) * u64 / (1.0 - (k + 1) * u64)
    d2 = 0.0
    for i in range(r):
        d2 += d[i] * d[i]
    c2 = 0.0
    for q in range(k):
        acc = 0.0
        for i in range(r):
            acc += basis[q, i] * d[i]
        c[q] = acc
        c2 += acc * acc
    d_up = math.sqrt(d2 * (1.0 + g_r))
    c_up = math.sqrt(c2 * (1.0 + g_k))
    dc = math.sqrt(k) * g_r * math.sqrt(1.0 + orth) * d_up * (1.0 + 1e-12)
    rho = d2 * (1.0 + g_r) - c2 * (1.0 - g_k) + 2.0 * c_up * dc + orth * c_up * c_up
    rho += 4.0 * u64 * (d2 + c2)
    return math.sqrt(max(rho, 0.0)) * (1.0 + 1e-12), dc + orth * c_up


@njit(cache=True, fastmath=True)
def _deviation(wm, unit, t_ref, d):
    """``d = wm - t_ref unit``; returns ``|wm|^2`` (vectorised; only sized by the bounds)."""
    w2 = 0.0
    for i in range(wm.shape[0]):
        d[i] = wm[i] - t_ref * unit[i]
        w2 += wm[i] * wm[i]
    return w2


@njit(cache=True)
def _orthonormal_row(basis, k, v):
    """Orthogonalise ``v`` against ``basis[:k]`` twice (Gram-Schmidt) and normalise it; returns
    its norm before the normalisation (0: nothing left)."""
    r = v.shape[0]
    for _ in range(2):
        for q in range(k):
            acc = 0.0
            for i in range(r):
                acc += basis[q, i] * v[i]
            for i in range(r):
                v[i] -= acc * basis[q, i]
    nv = 0.0
    for i in range(r):
        nv += v[i] * v[i]
    nv = math.sqrt(nv)
    if nv > 0.0:
        for i in range(r):
            v[i] /= nv
    return nv


@njit(cache=True)
def _basis_rows_changed(s, k0, k):
    """After rows ``k0..k-1`` of ``hs_basis`` changed: their products with every row
    (``hs_gb[q] = G B_q``, BLAS), the float32 copies (``hs_gb32`` and its transpose
    ``hs_gbt32``), the rows' residual norms
    ``hs_gres_j = |G_j (I - B^T B)|`` and their largest (``f[F_HSGRESMAX]``)."""
    g, gb, gb32, gres, gn, gbt32 = s.rom_cand, s.hs_gb, s.hs_gb32, s.hs_gres, s.hs_norm, s.hs_gbt32
    n = g.shape[0]
    prod = np.ascontiguousarray(s.hs_basis[k0:k]) @ g.T  # (k - k0, n)
    top = 0.0
    for j in range(n):
        gb2 = 0.0
        for q in range(k):
            if q >= k0:
                gb[q, j] = prod[q - k0, j]
                gb32[q, j] = np.float32(prod[q - k0, j])
                gbt32[j, q] = gb32[q, j]
            gb2 += gb[q, j] * gb[q, j]
        gn2 = gn[j] * gn[j]
        # the subtraction's cancellation and the basis's departure from orthonormality (~1e-15)
        gres[j] = math.sqrt(max(gn2 - gb2, 0.0) + 1e-12 * gn2)
        top = max(top, gres[j])
    s.f[F_HSGRESMAX] = top
    # |B B^T - I| (Frobenius, an upper bound of the spectral norm) with its evaluation's rounding
    basis = s.hs_basis
    r = basis.shape[1]
    e2 = 0.0
    for p in range(k):
        for q in range(k):
            acc = 0.0
            for i in range(r):
                acc += basis[p, i] * basis[q, i]
            e2 += (acc - (1.0 if p == q else 0.0)) ** 2
    u64 = 2.0**-53
    s.f[F_HSORTH] = 1.01 * (math.sqrt(e2) + k * (r + 2) * u64 / (1.0 - (r + 2) * u64)) + 1e-15


@njit(cache=True)
def _basis_add(s, k, res):
    """Append the direction of the residual ``res`` to the basis (its first ``k`` rows);
    returns the new size."""
    v = res.copy()
    if _orthonormal_row(s.hs_basis, k, v) == 0.0:
        return k
    s.hs_basis[k, :] = v
    for q in range(k + 1):
        s.hs_cov[q, k] = 0.0
        s.hs_cov[k, q] = 0.0
    _basis_rows_changed(s, k, k + 1)
    s.f[F_HSADDS] += 1.0
    return k + 1


@njit(cache=True)
def _basis_shrink(s, k, keep):
    """A full basis cut down to its ``keep`` leading directions of the recent states (the
    eigenvectors of ``hs_cov``, the decayed sum of the coefficients' outer products),
    orthonormalised again and their products with every row computed afresh; returns ``keep``."""
    lam, vec = np.linalg.eigh(np.ascontiguousarray(s.hs_cov[:k, :k]))
    old = s.hs_basis[:k].copy()
    r = old.shape[1]
    kept = 0
    for p in range(keep):
        col = k - 1 - p  # eigh: ascending
        v = np.zeros(r)
        for q in range(k):
            a = vec[q, col]
            for i in range(r):
                v[i] += a * old[q, i]
        if _orthonormal_row(s.hs_basis, kept, v) > 0.5:  # a unit vector (up to rounding)
            s.hs_basis[kept, :] = v
            kept += 1
    s.hs_cov[:, :] = 0.0
    for p in range(kept):
        s.hs_cov[p, p] = max(lam[k - 1 - p], 0.0)
    _basis_rows_changed(s, 0, kept)
    s.f[F_HSREBUILDS] += 1.0
    return kept


#: the first columns of :attr:`PackArrays.hs_keep`, a module's kept screen
#: (:func:`_module_hot_spots_within`), before its anchor state ``w_s`` (r columns from ``KP_W``):
#: state (0 none, 1 anchored, 2 kept), ``T_ref`` and ``|w|`` of the anchor [K], the largest bound
#: of the rows left out (relative to ``T_ref``) and their largest ``|G_j|``, the hot rows' count,
#: the steps since the anchor, the drift per step (EMA) and the step's bound of the rows left out
#: [K] (NaN after a full screen)
KP_NAMES = ("state", "t_ref", "w_norm", "cold", "cold_gmax", "n_hot", "since", "rate", "bound")
(KP_STATE, KP_TREF, KP_WNORM, KP_COLD, KP_GMAX, KP_NHOT, KP_SINCE, KP_RATE, KP_BOUND) = range(len(KP_NAMES))
KP_W = len(KP_NAMES)
#: most steps a module keeps one full screen's bounds [-] (then it screens every row again)
HOT_SPOT_HOLD_MAX = 256
#: the holds (steps) among which a full screen picks its hot rows' threshold [-]
HOT_SPOT_HOLDS = (1, 2, 4, 8, 16, 32, 64, 128, 256)


@njit(cache=True, fastmath=True)
def _hot_rows_bounds(hl, nh, gbt32, c32, k, gn, gres, big, rn, small, up):
    """``up_j = (G B^T)_j c (float32) + |G_j| big + gres_j rn + small`` for the rows
    ``hl[:nh]`` (rows of ``gbt32`` gathered, two at a time; any summation order is within the
    bound of :func:`_module_hot_spots_within`); returns (the largest, its first row)."""
    top = _EVALUATED
    j_top = hl[0]
    for i in range(0, nh - 1, 2):
        ja, jb = hl[i], hl[i + 1]
        acc_a = np.float32(0.0)
        acc_b = np.float32(0.0)
        for p in range(k):
            acc_a += gbt32[ja, p] * c32[p]
            acc_b += gbt32[jb, p] * c32[p]
        u_a = np.float64(acc_a) + gn[ja] * big + gres[ja] * rn + small
        u_b = np.float64(acc_b) + gn[jb] * big + gres[jb] * rn + small
        up[ja] = u_a
        up[jb] = u_b
        if u_a > top:
            top, j_top = u_a, ja
        if u_b > top:
            top, j_top = u_b, jb
    if nh % 2 == 1:
        j = hl[nh - 1]
        acc = np.float32(0.0)
        for p in range(k):
            acc += gbt32[j, p] * c32[p]
        u = np.float64(acc) + gn[j] * big + gres[j] * rn + small
        up[j] = u
        if u > top:
            top, j_top = u, j
    return top, j_top


@njit(cache=True)
def _drift(wm, ws, unit, d_t, w_norm, ws_norm, u_norm):
    """An upper bound of ``|(w - w_s) - dT u|`` (the deviation's change since the anchor ``w_s``,
    ``dT`` = ``d_t`` the change of ``T_ref``), with the rounding of its evaluation."""
    acc = 0.0
    for i in range(wm.shape[0]):
        x = (wm[i] - ws[i]) - d_t * unit[i]
        acc += x * x
    return math.sqrt(acc) * (1.0 + 1e-12) + 4.0 * 2.0**-53 * (w_norm + ws_norm + abs(d_t) * u_norm)


@njit(cache=True, fastmath=True)
def _count_above(up, theta):
    """How many of ``up`` exceed ``theta`` (vectorised)."""
    count = 0
    for j in range(up.shape[0]):
        count += 1 if up[j] > theta else 0
    return count


@njit(cache=True)
def _pick_hot_rows(s, m, up, lo, eps, k, n_eval):
    """After a full screen of module ``m`` (bounds ``up``, relative to ``T_ref``; ``lo`` = the
    hot spot found - ``T_ref``): keep the rows whose bound is within ``mu`` of ``lo`` (and the
    rows evaluated) as the hot rows (``hs_hot[m]``), the others bounded together by their
    largest bound and largest ``|G_j|`` (``hs_keep[m]``), with the ``mu`` of the least expected
    cost per step among :data:`HOT_SPOT_HOLDS` (the hot rows each step + a full screen per hold,
    the hold ``(mu + eps) / (max_j |G_j| rate)`` at the module's recent drift ``rate`` per step).
    Returns the hot rows' count, or -1 when keeping none pays (screen every row next step)."""
    gn, kp, hl = s.hs_norm, s.hs_keep[m], s.hs_hot[m]
    n = up.shape[0]
    nh_opt = len(HOT_SPOT_HOLDS)
    g_all = 0.0
    for b in range(s.hs_gmax.shape[0]):
        g_all = max(g_all, s.hs_gmax[b])
    per = g_all * kp[KP_RATE]
    mus = np.empty(nh_opt)
    for h in range(nh_opt):
        mus[h] = per * HOT_SPOT_HOLDS[h] - eps
    best_cost = n * (k + 16.0)  # a full screen every step (nothing kept)
    mu = np.nan
    for h in range(nh_opt):
        within = n_eval + _count_above(up, lo - mus[h])
        if within * (k + 8.0) >= best_cost:  # the longer holds keep more rows: none is cheaper
            break
        cost = within * (k + 8.0) + n * (k + 16.0) / HOT_SPOT_HOLDS[h]
        if cost < best_cost and 2 * within <= n:
            best_cost, mu = cost, mus[h]
    if np.isnan(mu):
        kp[KP_NHOT] = 0.0
        return -1
    theta = lo - mu
    nh = 0
    cold = -np.inf
    g_cold = 0.0
    for j in range(n):
        u = up[j]
        if u <= _EVALUATED or u > theta:
            hl[nh] = j
            nh += 1
        else:
            cold = max(cold, u)
            g_cold = max(g_cold, gn[j])
    kp[KP_COLD], kp[KP_GMAX], kp[KP_NHOT] = cold, g_cold, nh
    return nh


@njit(cache=True, inline="always")
def _evaluate_above(g, wm, up, rows, count, j_top, top, t_ref, eps):
    """The exact part of one module's screen.

    Evaluates row ``j_top`` (the one of the largest bound ``top``), then every row
    (``rows[:count]``, or rows ``0 .. count-1`` when ``rows`` is None) whose bound ``up[j]``
    [K, relative to ``t_ref``] exceeds the best value so far minus ``t_ref`` plus the slack
    ``eps`` [K], and marks the evaluated rows :data:`_EVALUATED` in ``up``. Returns (the best
    row value [K], the largest bound of the rows not evaluated [K, relative to ``t_ref``;
    ``top`` when no other row was needed], the number of rows evaluated).
    """
    best = _dot(g[j_top], wm)
    evaluated = 1
    cut = best - t_ref + eps
    left = top  # bounds every row not evaluated (j_top's own bound included)
    if top > cut:
        left = _EVALUATED
        for i in range(count):
            if rows is None:
                j = i
            else:
                j = rows[i]
            if j == j_top:
                continue
            if up[j] > cut:
                y = _dot(g[j], wm)
                evaluated += 1
                up[j] = _EVALUATED
                if y > best:
                    best = y
                    cut = best - t_ref + eps
            else:
                left = max(left, up[j])
    up[j_top] = _EVALUATED
    return best, left, evaluated


@njit(cache=True)
def _module_hot_spots_within(s, w, hot):
    """Per-module hot spot [K] within the slack ``eps = f[F_HSEPS]`` (> 0) of the largest
    candidate-node temperature ``max_j G_j w`` of :func:`_module_hot_spots` (issue 26 item 5:
    the top of the field is flat, so the exact maximum costs hundreds of rows per step while
    the same value within ``eps`` costs one).

    With ``T_ref = e.w / e.u`` and the deviation ``d = w - T_ref u`` (:func:`_module_hot_spots`)
    and an orthonormal basis ``B`` (k rows, ``hs_basis``, shared by the modules and grown from
    their own deviations), ``d = B^T c + res`` with ``c = B d`` and

        G_j w = T_ref + (G B^T)_j c + G_j res,   |G_j res| <= |G_j (I - B^T B)| |res| + |G_j| |B res|

    (Cauchy-Schwarz on the residual). ``(G B^T)_j c`` is evaluated in single precision
    (``hs_gb32``, k multiply-adds per row instead of r), with the rounding bound
    ``gamma_{k+2}^{(32)} |G_j| |c|``, plus the rounding of ``d`` and of the double product
    (``hs_const``), so that ``U_j`` bounds the row's double value ``v_j = G_j . w``
    (:func:`_dot`). The row of the largest ``U_j`` is evaluated in double (``L``), then every
    other row with ``U_j > L + eps`` (raising ``L``); the hot spot is ``L``, the value of one row, so
    ``max_j v_j - eps <= L <= max_j v_j``; the step's certified gap ``max(U_j) - L`` over the
    rows not evaluated (<= eps) raises ``f[F_HSGAP]``.

    **A screen kept over steps.** A full screen bounds every row (the pass above, ``n k``
    multiply-adds); most rows are far below the top (the cells' cores are hottest), and a row
    moves by ``G_j (w_t - w_s) = dT (G_j u) + G_j (d_t - d_s)`` from the anchor state ``w_s``
    of the screen, so ``v_j(t) <= U_j(s) + dT + |dT| eta + |G_j| |d_t - d_s|`` plus the
    rounding of the two double products (``hs_const``; ``|G_j u - 1| <= eta``). The screen
    keeps the rows whose bound is within ``mu`` of the hot spot found (and the rows evaluated)
    as the module's hot rows (``hs_hot``) and the others' largest bound and ``|G_j|``
    (``hs_keep``, :func:`_pick_hot_rows`, which picks ``mu`` for the least expected cost); the
    next steps bound only the hot rows as above and the others together by that drift bound,
    which must be within ``L + eps`` (else, or after :data:`HOT_SPOT_HOLD_MAX` steps, every row
    is screened again). The drift is the norm of the change since the anchor (not a sum of
    steps), so a state set from outside (a trial run skipping hot spots, a restored state) is
    covered too. ``f[F_HSREUSE]`` counts the module steps that kept the screen,
    ``f[F_HSSCREENS]`` the full screens.

    The basis: the residual's direction is appended (one product with every row, ``n r``) before
    the pass when ``max_j |G_j (I - B^T B)| |res|`` exceeds :data:`HOT_SPOT_RESIDUAL_SHARE` x
    ``eps`` (the bounds would leave many rows), and after it when the module evaluated more than
    :data:`HOT_SPOT_ROWS_PER_ADD` rows besides the first (the residual cost rows); a full basis
    (:data:`HOT_SPOT_BASIS_MAX` rows) is first cut to the :data:`HOT_SPOT_BASIS_KEEP` leading
    directions of the recent coefficients, at most once in :data:`HOT_SPOT_CUT_EVERY` calls
    (else the rows the residual leaves are evaluated in double). The deviations of a run lie
    near a subspace of a few dozen directions, so the basis settles and grows rarely; how fast
    it settles decides the cost, never the bound (a 1-hour drive with 100 modules: a few hundred
    additions and a few dozen cuts). A change of the basis leaves the kept screens valid (they
    bound values, whatever basis bounded them)."""
    g, gn, unit, en, hc = s.rom_cand, s.hs_norm, s.hs_unit, s.hs_energy, s.hs_const
    f = s.f
    eps = f[F_HSEPS]
    n_mod, r = w.shape
    n = g.shape[0]
    kmax = s.hs_basis.shape[0]
    keep = min(HOT_SPOT_BASIS_KEEP, kmax - 1)
    e_u = _dot(en, unit)
    d = np.empty(r)
    res = np.empty(r)
    c = np.zeros(kmax)
    c32 = np.zeros(kmax, np.float32)
    acc = np.empty(n, np.float32)
    k = int(f[F_HSK])
    cov = s.hs_cov
    for p in range(k):
        for q in range(k):
            cov[p, q] *= HOT_SPOT_BASIS_DECAY
    doubles = 0
    singles = 0
    for m in range(n_mod):
        t_ref = _dot(en, w[m]) / e_u
        w_norm = math.sqrt(_deviation(w[m], unit, t_ref, d))
        rn, brn = _coefficients(s.hs_basis, k, d, c, f[F_HSORTH])
        if f[F_HSGRESMAX] * rn > HOT_SPOT_RESIDUAL_SHARE * eps or k == 0:
            rn, brn = _project(s.hs_basis, k, d, c, res)  # the residual itself
            if k >= kmax and f[F_HSCALLS] - f[F_HSLASTCUT] >= HOT_SPOT_CUT_EVERY:
                k = _basis_shrink(s, k, keep)
                f[F_HSLASTCUT] = f[F_HSCALLS]
                rn, brn = _project(s.hs_basis, k, d, c, res)
            if k < kmax and (k == 0 or f[F_HSGRESMAX] * rn > HOT_SPOT_RESIDUAL_SHARE * eps):
                k = _basis_add(s, k, res)
                rn, brn = _project(s.hs_basis, k, d, c, res)
        c_norm2 = 0.0
        for p in range(k):
            c_norm2 += c[p] * c[p]
            c32[p] = np.float32(c[p])
            for q in range(k):
                cov[p, q] += c[p] * c[q]
        c_norm = math.sqrt(c_norm2)
        # the rows' single-precision part, U_j - T_ref - gres_j |res| = acc_j + |G_j| big + small
        u32 = 2.0**-24
        g32 = (k + 2) * u32 / (1.0 - (k + 2) * u32)
        big = g32 * c_norm + hc[1] * (w_norm + abs(t_ref) * hc[3] + math.sqrt(k + 1.0) * c_norm)
        big = 1.01 * (big + brn)
        small = 1.01 * abs(t_ref) * 2.0 * hc[2] + 1e-9
        rnx = rn * (1.0 + 1e-9)
        before = doubles
        up = s.hs_up[m]  # kept: the step's bounds U_j - T_ref, _EVALUATED where evaluated
        kp = s.hs_keep[m]
        kp[KP_SINCE] += 1.0
        drift = 0.0
        if kp[KP_STATE] > 0.0:  # anchored: the drift since the last full screen
            drift = _drift(w[m], kp[KP_W:], unit, t_ref - kp[KP_TREF], w_norm, kp[KP_WNORM], hc[3])
        kept = False
        if kp[KP_STATE] > 1.0 and kp[KP_SINCE] <= HOT_SPOT_HOLD_MAX:
            # the kept screen: the hot rows bounded afresh, the others by their drift bound
            d_t = t_ref - kp[KP_TREF]
            cold = (t_ref + kp[KP_COLD] + abs(d_t) * hc[2]
                    + kp[KP_GMAX] * (drift + hc[1] * (w_norm + kp[KP_WNORM])) + 1e-9)  # fmt: skip
            hl = s.hs_hot[m]
            nh = int(kp[KP_NHOT])
            top, j_top = _hot_rows_bounds(hl, nh, s.hs_gbt32, c32, k, gn, s.hs_gres, big, rnx, small, up)
            singles += nh
            best, left, evaluated = _evaluate_above(g, w[m], up, hl, nh, j_top, top, t_ref, eps)
            doubles += evaluated
            if cold <= best + eps:
                kept = True
                f[F_HSGAP] = max(f[F_HSGAP], left + t_ref - best, cold - best)
                kp[KP_BOUND] = cold
                hot[m] = best
                f[F_HSREUSE] += 1.0
        if not kept:  # every row screened
            if kp[KP_STATE] > 0.0 and kp[KP_SINCE] > 0.0:  # the drift rate per step
                rate = drift / kp[KP_SINCE]
                kp[KP_RATE] = rate if kp[KP_RATE] == 0.0 else 0.5 * (kp[KP_RATE] + rate)
            screen_from = doubles
            acc[:] = 0.0
            for p in range(k):
                _axpy32(acc, s.hs_gb32, p, c32[p], n)
            top = _bounds(acc, gn, s.hs_gres, big, rnx, small, up)
            singles += n
            j_top = 0  # the row of the largest bound (the first of them)
            while j_top < n - 1 and up[j_top] < top:
                j_top += 1
            best, left, evaluated = _evaluate_above(g, w[m], up, None, n, j_top, top, t_ref, eps)
            doubles += evaluated
            f[F_HSGAP] = max(f[F_HSGAP], left + t_ref - best)
            hot[m] = best
            f[F_HSSCREENS] += 1.0
            # the anchor of the next steps
            nh = _pick_hot_rows(s, m, up, best - t_ref, eps, k, doubles - screen_from)
            for i in range(r):
                kp[KP_W + i] = w[m, i]
            kp[KP_TREF], kp[KP_WNORM], kp[KP_SINCE] = t_ref, w_norm, 0.0
            kp[KP_STATE] = 2.0 if nh >= 0 else 1.0
            kp[KP_BOUND] = np.nan
        if doubles - before > HOT_SPOT_ROWS_PER_ADD + 1 and rn > 0.0:  # the residual costs rows
            rn, brn = _project(s.hs_basis, k, d, c, res)
            if k >= kmax and f[F_HSCALLS] - f[F_HSLASTCUT] >= HOT_SPOT_CUT_EVERY:
                k = _basis_shrink(s, k, keep)
                f[F_HSLASTCUT] = f[F_HSCALLS]
                rn, brn = _project(s.hs_basis, k, d, c, res)
            if k < kmax and rn > 0.0:
                k = _basis_add(s, k, res)
    f[F_HSK] = k
    f[F_HSROWS64] += doubles
    f[F_HSROWS] += singles
    f[F_HSINIT] = 1.0
    f[F_HSCALLS] += 1.0


@njit(cache=True)
def rom_modal(s, port_w, hot):
    """The module ROMs' step in modal coordinates (module docstring) with the cells' port heat
    ``port_w`` (n_modules, n_cells) [W]: the channel's fluid temperatures from the wall at the
    start of the step and the plates' inlets, the step, then the outputs; returns (plate heat
    per module [W] in ``s.plate_heat_w``; returns the modules' heat to the ambient [W]); port temperatures
    -> ``s.port_k``, hot spots -> ``hot``."""
    f = s.f
    n_mod = port_w.shape[0]
    nc = port_w.shape[1]
    ns = s.wall_area_m2.shape[0]
    h = f[F_H]
    u, y, w = s.rom_u, s.rom_y, s.rom_w
    cap = s.lp[LP_RHOCP] * s.lp[LP_PFLOW]
    for m in range(n_mod):
        u[m, :nc] = port_w[m]
        t_in = s.inlet_k[m]
        for i in range(ns):
            tw = y[m, nc + i] / s.wall_area_m2[i]
            if cap <= 0.0:  # stagnant coolant follows the wall
                u[m, nc + i] = tw
            else:
                u[m, nc + i] = tw + (t_in - tw) * s.ch_mean[i]
                t_in = tw + (t_in - tw) * s.ch_decay[i]
        u[m, nc + ns] = f[F_AMB]
        u[m, nc + ns + 1] = 1.0
    bu = u @ s.rom_in
    dt = f[F_DT]
    for m in range(n_mod):
        for j in range(w.shape[1]):
            w[m, j] = (w[m, j] / dt + bu[m, j]) * s.rom_decay[j]
    y[:, :] = w @ s.rom_out
    to_amb = 0.0
    rep = f[F_REP] > 0.0
    for m in range(n_mod):
        q = 0.0
        for i in range(ns):
            q += h * (y[m, nc + i] - s.wall_area_m2[i] * u[m, nc + i])
        s.plate_heat_w[m] = q
        to_amb += y[m, nc + ns] - f[F_BAMB] * f[F_AMB] - f[F_FCONST]
        if rep:
            mean = 0.0
            for c in range(nc):
                mean += y[m, c]
            s.port_k[m] = mean / nc
        else:
            for c in range(nc):
                s.port_k[m * nc + c] = y[m, c]
    if f[F_HSSKIP] > 0.0:  # a trial run whose records are discarded: the hot spots drive nothing
        hot[:] = np.nan
    elif f[F_HSEPS] > 0.0:
        _module_hot_spots_within(s, w, hot)
    else:
        _module_hot_spots(s, w, hot)
    return to_amb


@njit(cache=True)
def _stress_add(st, st_n, cells, dt, activation_k):
    """One step of the cells' ageing stress (:meth:`hevsim.battery.life.CellStress.add`)."""
    st_n[0] += 1.0
    st_n[1] += dt
    for c in range(cells.shape[0]):
        i, soc, temp = cells[c, 0], cells[c, 1], cells[c, 2]
        st[ST_DIS, c] += max(i, 0.0) * dt
        st[ST_ABS, c] += abs(i)
        st[ST_MOVING, c] += 1.0 if abs(i) > 0.0 else 0.0
        st[ST_ARR, c] += math.exp(-activation_k / temp)
        st[ST_SOC, c] += soc
        st[ST_TEMP, c] += temp
        st[ST_SOCMIN, c] = min(st[ST_SOCMIN, c], soc)
        st[ST_SOCMAX, c] = max(st[ST_SOCMAX, c], soc)


@njit(**PACK_STEP)
def pack_finish(s, current_a, current_request_a):
    """The second half of a step at pack current ``current_a`` [A] (module docstring); returns
    the mean cell SOC [-]. The record row is ``rec[step]`` (skipped beyond its rows)."""
    f, sv, cells, energy, acc = s.f, s.sv, s.cells, s.energy, s.acc
    dt = f[F_DT]
    rep = f[F_REP] > 0.0
    n_mod = int(f[F_NMOD])
    spm = int(f[F_SIMPM])
    i_cells = current_a / f[F_NPAR] if rep else current_a  # a representative cell's share
    ng, n_p = int(f[F_NG]), int(f[F_NP])
    linear = f[F_LINEAR] > 0.0
    if f[F_EZVALID] > 0.0 and linear:
        v_end, v_avg = pack_pass_linear(s.prm, s.soc_ax, s.t_ax, s.ocv_c, s.ocv_d, s.rs_c, s.rs_d, s.capf,
                                        s.rc_d, s.rc_c, s.x, ng, n_p, i_cells, dt, s.port_k, cells, energy,
                                        s.ez, s.oc, s.rcc, s.pairs, s.totals)  # fmt: skip
    else:
        v_end, v_avg = pack_pass(s.prm, s.soc_ax, s.t_ax, s.ocv_c, s.ocv_d, s.rs_c, s.rs_d, s.capf, s.rc_d,
                                 s.rc_c, s.x, ng, n_p, i_cells, dt, s.port_k, cells, energy, s.ez,
                                 f[F_EZVALID] > 0.0, s.pairs, s.totals)  # fmt: skip
        if linear:  # the capacities, OCVs and resistances for pack_pass_linear
            pack_pairs(s.prm, s.soc_ax, s.t_ax, s.ocv_c, s.ocv_d, s.rs_c, s.rs_d, s.capf, s.rc_d, s.rc_c,
                       s.x, ng, n_p, dt, s.ez, s.oc, s.rcc, True, s.pairs, s.totals)  # fmt: skip
    f[F_EZVALID] = 1.0
    if rep:  # one cell for n_series groups of n_parallel cells
        v_end, v_avg = f[F_NS] * v_end, f[F_NS] * v_avg
        for j in range(4):
            energy[j] *= f[F_WEIGHT]
    k = int(f[F_STEP])
    hot = s.hot[k] if k < s.hot.shape[0] else np.empty(n_mod)
    mod_amb = 0.0
    if f[F_ROM] > 0.0:
        nc = s.rom_u.shape[1] - s.wall_area_m2.shape[0] - 2
        port_w = np.empty((n_mod, nc))
        for m in range(n_mod):
            for c in range(nc):
                port_w[m, c] = cells[m if rep else m * nc + c, 3]
        mod_amb = rom_modal(s, port_w, hot)
    else:
        for m in range(n_mod):
            q = 0.0
            t_hot = -np.inf
            for c in range(spm):
                q += cells[m * spm + c, 3]
                t_hot = max(t_hot, cells[m * spm + c, 2])
            s.plate_heat_w[m] = q * f[F_WEIGHT]
            hot[m] = t_hot
    plate_w = 0.0
    for m in range(n_mod):
        plate_w += s.plate_heat_w[m]
    loop_end(s.lp, s.ls, sv[SV_SUPPLY:], plate_w, dt)
    acc[A_EL] += energy[0]
    acc[A_CHEM] += energy[1]
    acc[A_CELLHEAT] += energy[2]
    acc[A_PORT] += energy[3]
    acc[A_PLATE] += dt * plate_w
    acc[A_MODAMB] += dt * mod_amb
    acc[A_THRU] += abs(energy[0])
    if s.lp[LP_INF] > 0.0:
        acc[A_RES] += dt * plate_w
    else:
        acc[A_RAD] += dt * sv[SV_RAD]
        acc[A_CH] += dt * sv[SV_CH]
        acc[A_LOOPAMB] += dt * sv[SV_LAMB]
        acc[A_PUMP] += dt * sv[SV_PUMP]
        acc[A_CHEL] += dt * sv[SV_CHP]
        acc[A_FANEL] += dt * sv[SV_FAN]
    f[F_TIME] += dt
    soc_sum = 0.0
    soc_min = np.inf
    soc_max = -np.inf
    t_max = -np.inf
    for c in range(cells.shape[0]):
        soc_sum += cells[c, 1]
        soc_min = min(soc_min, cells[c, 1])
        soc_max = max(soc_max, cells[c, 1])
        t_max = max(t_max, cells[c, 2])
    f[F_SOC] = soc_sum / cells.shape[0]
    f[F_SOCMIN], f[F_SOCMAX] = soc_min, soc_max
    if f[F_STRESS] > 0.0:
        _stress_add(s.stress, s.stress_n, cells, dt, f[F_ACT])
    if k < s.rec.shape[0]:
        r = s.rec[k]
        # the direction's pair; a current of round-off size (a zero power solved to -1e-15 A) is no charge
        d = 0 if current_a >= -1e-12 * max(1.0, f[F_IMAX]) else 2
        r[R_I] = current_a
        r[R_V] = v_avg
        r[R_P] = v_avg * current_a
        r[R_E] = sv[SV_EDIS + d]
        r[R_Z] = sv[SV_ZDIS + d]
        r[R_LIMD], r[R_LIMC] = sv[SV_LIMD], sv[SV_LIMC]
        r[R_WHYD], r[R_WHYC] = sv[SV_WHYD], sv[SV_WHYC]
        r[R_FACTOR] = sv[SV_FACTOR]
        r[R_HOT] = t_max
        r[R_HOTSPOT] = hot.max()
        r[R_SOCMIN], r[R_SOCMAX], r[R_SPREAD] = soc_min, soc_max, soc_max - soc_min
        r[R_LOOP] = s.ls[LS_TEMP]
        r[R_SUPPLY] = sv[SV_SUPPLY]
        r[R_PUMP], r[R_FAN], r[R_CHP], r[R_CH] = sv[SV_PUMP], sv[SV_FAN], sv[SV_CHP], sv[SV_CH]
        r[R_COOL] = sv[SV_COOLW]
        r[R_PLATE] = plate_w
        r[R_TIME] = f[F_TIME]
        r[R_REQ] = current_request_a
        r[R_VEND] = v_end
        r[R_MODAMB] = mod_amb
        r[R_RAD] = sv[SV_RAD]
    f[F_STEP] = k + 1
    return f[F_SOC]


@njit(cache=True)
def pack_simulate(s, request_a, cells_out):
    """:meth:`hevsim.battery.pack.Pack.simulate`'s loop: per step, :func:`pack_begin`, the
    request clipped to the BMS's current limits of the step (temperature, SOC and cell voltage,
    as in a vehicle: :mod:`hevsim.battery.bms`), :func:`pack_finish`; the cells' records ->
    ``cells_out[k]``."""
    for k in range(request_a.shape[0]):
        pack_begin(s)
        i_a = min(max(request_a[k], -s.sv[SV_LIMC]), s.sv[SV_LIMD])
        pack_finish(s, i_a, request_a[k])
        cells_out[k] = s.cells


# -- the pack as a vehicle's battery: the bus side of a step --------------------------------------
@njit(**NO_REFCOUNT)  # allocates nothing: no reference counting of the pack's arrays
def pack_bus_state(s, soc, soc_max, discharge_rtol, charge_rtol):
    """The bus side of a step begun by :func:`pack_begin` (the one place both the Python forward
    loop, :meth:`hevsim.battery.bms.PackRun.vehicle_step`, and the compiled forward loops of
    every architecture take it from): (OCV [V] = the discharge pair's ``E``, discharge and
    charge resistance [ohm] = each direction's ``Z``, largest charge power [W] (0 when the
    vehicle's SOC ``soc`` [-] is at ``soc_max``), the discharge and charge current limits [A]
    handed to the vehicle, the bus's other load [W] = ``f[F_BASEAUX]`` + the cooling loop).

    The current limits are the BMS's divided by ``1 + rtol`` (``discharge_rtol``,
    ``charge_rtol`` [-]: the relative excess over a limit the vehicle's feasibility test
    accepts), so that no accepted step exceeds the BMS's own limit (issue 24 item 4)."""
    sv = s.sv
    i_dis = sv[SV_LIMD] / (1.0 + discharge_rtol)
    i_chg = sv[SV_LIMC] / (1.0 + charge_rtol)
    ocv, r_dis, r_chg = sv[SV_EDIS], sv[SV_ZDIS], sv[SV_ZCHG]
    p_chg = battery_power_limits(ocv, r_dis, ocv, r_chg, i_dis, i_chg)[1]
    if soc >= soc_max:  # full: no charging (regeneration goes to the friction brakes)
        p_chg = 0.0
    return ocv, r_dis, r_chg, p_chg, i_dis, i_chg, s.f[F_BASEAUX] + sv[SV_COOLW]


@njit(**NO_REFCOUNT)  # allocates nothing: no reference counting of the pack's arrays
def pack_current_for_power(s, power_w):
    """Pack current [A] whose step-average terminal power is ``power_w`` [W] (> 0 discharging)
    over the step begun by :func:`pack_begin`, from the direction's ``E I - Z I^2 = P`` (the
    root nearer zero; the maximum-power current when ``P`` exceeds ``E^2 / 4Z``)."""
    sv = s.sv
    if power_w > 0.0:
        return pair_current_for_power(sv[SV_EDIS], sv[SV_ZDIS], power_w)
    return pair_current_for_power(sv[SV_ECHG], sv[SV_ZCHG], power_w)


@njit(cache=True, inline="always")
def pair_current_for_power(e_v, z_ohm, power_w):
    """Current [A] whose step-average terminal power over a step pair ``V = E - Z I`` (``e_v``
    [V], ``z_ohm`` [ohm]) is ``power_w`` [W] (> 0 discharging): the root of ``E I - Z I^2 = P``
    nearer zero; the maximum-power current ``E / 2Z`` when ``P`` exceeds ``E^2 / 4Z``."""
    if power_w == 0.0:
        return 0.0
    disc = e_v * e_v - 4.0 * z_ohm * power_w
    return 2.0 * power_w / (e_v + math.sqrt(disc)) if disc > 0.0 else e_v / (2.0 * z_ohm)


@njit(**NO_REFCOUNT)  # allocates nothing: no reference counting of the pack's arrays
def pack_finish_power(s, power_w):
    """End the step at the bus's terminal power ``power_w`` [W] (:func:`pack_current_for_power`,
    then :func:`pack_finish`); returns the mean cell SOC [-]."""
    i_a = pack_current_for_power(s, power_w)
    return pack_finish(s, i_a, i_a)


def hot_spot_rounding(cand: np.ndarray, unit: np.ndarray) -> np.ndarray:
    """The constants of :func:`_module_hot_spots`'s rounding bound for the rows ``cand``
    (n_rows, r) and the uniform state ``unit`` (r,): ``gamma_{r+2}`` in single precision
    (float32 rows and deviation, a sum of r products in any order), the double product's and
    the deviation's relative rounding, ``eta = max_j |G_j u - 1|`` and ``|u|``."""
    r = cand.shape[1]
    u32, u64 = 2.0**-24, 2.0**-53
    g32 = (r + 2) * u32 / (1.0 - (r + 2) * u32)
    g64 = 2.0 * (r + 4) * u64 / (1.0 - (r + 4) * u64)
    eta = float(np.abs(cand @ unit - 1.0).max()) + 1e-15 if cand.size else 0.0
    return np.array([g32, g64, eta, float(np.linalg.norm(unit))])


def modal_rom(rom, dt_s: float, wall_h_w_m2k: float) -> dict[str, np.ndarray]:
    """The modal arrays of a :class:`~hevsim.thermal.rom.ThermalRom` at step ``dt_s`` [s] and wall
    film ``wall_h_w_m2k`` [W/(m^2 K)] (module docstring): ``q`` (r, r) the eigenvectors, and the
    :class:`PackArrays` entries ``rom_decay``, ``rom_in``, ``rom_out``, ``rom_cand`` (each cell's
    candidate rows without repeats, in blocks from ``hs_block``), ``hs_norm``, ``hs_block``,
    ``hs_gmax``, ``hs_unit``, ``hs_g32`` (the rows in single precision) and ``hs_const``
    (:func:`hot_spot_rounding`); plus
    ``energy`` (r,) the stored-heat row and ``film`` the film row, both times ``q``."""
    h = rom.check_wall_h(float(wall_h_w_m2k))
    lam, q = np.linalg.eigh(rom.stiffness(h))
    # the candidate rows, each cell's block without the repeated rows that pad it
    per_cell = np.asarray(rom.out_candidates).reshape(rom.n_cells, -1, rom.order)
    blocks = [np.unique(rows, axis=0, return_index=True)[1] for rows in per_cell]
    cand = np.vstack([rows[np.sort(keep)] for rows, keep in zip(per_cell, blocks, strict=True)]) @ q
    norm = np.sqrt(np.einsum("ij,ij->i", cand, cand))
    unit = rom.unit_state @ q
    start = np.concatenate([[0], np.cumsum([b.size for b in blocks])])
    out_rows = np.vstack([rom.out_mean, rom.out_wall, rom.film_row[None, :]])
    return {
        "q": q,
        "rom_decay": 1.0 / (1.0 / dt_s + lam),
        "rom_in": np.ascontiguousarray((q.T @ rom.inputs(h)).T),
        "rom_out": np.ascontiguousarray((out_rows @ q).T),
        "rom_cand": np.ascontiguousarray(cand),
        "hs_norm": norm,
        "hs_block": start.astype(float),
        "hs_gmax": np.array([norm[start[k] : start[k + 1]].max() for k in range(rom.n_cells)]),
        "hs_unit": unit,
        "hs_g32": np.ascontiguousarray(cand.astype(np.float32)),
        "hs_const": hot_spot_rounding(cand, unit),
        "energy": rom.energy @ q,
    }


__all__ = [
    "F_NAMES",
    "RECORD_CHANNELS",
    "SV_NAMES",
    "PackArrays",
    "hot_spot_rounding",
    "modal_rom",
    "pack_begin",
    "pack_bus_state",
    "pack_current_for_power",
    "pack_finish",
    "pack_finish_power",
    "pack_simulate",
    "rom_modal",
]
