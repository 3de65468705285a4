"""The pack's compiled step (:mod:`hevsim.battery.pack_run`, issue 12 speed): the module ROMs
stepped in modal coordinates against the dense implicit Euler of
:class:`~hevsim.thermal.rom.RomStepper` (the one the ROM-vs-FEM validation uses), the screened
hot spot against the maximum over every candidate row, the compiled cooling loop against its
closed-form steady state, and the series kernel's compiled pack step against the same pack
stepped from Python at the kernel's currents."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from tests.thermal_helpers import COARSE_TOML

from hevsim.battery import pack_run as R
from hevsim.battery.cooling import (
    AIR_SPECIFIC_HEAT_J_KGK,
    LITRE_PER_MIN_M3_S,
    ControllerSection,
    CoolingLoop,
    CoolingSection,
    counterflow_effectiveness,
)
from hevsim.battery.pack import Pack, pack_config_from_dict

ROOT = Path(__file__).resolve().parents[1]
EX = ROOT / "examples"


@pytest.fixture(scope="module")
def rom_pack(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    pytest.importorskip("skfem")
    pytest.importorskip("gmsh")
    from hevsim.thermal.rom import BuildOptions, build_rom_from_config

    d = tmp_path_factory.mktemp("pack_run")
    toml = d / "module_coarse.toml"
    toml.write_text(COARSE_TOML)
    rom, _ = build_rom_from_config(toml, BuildOptions(tol_k=0.1))
    rom.save(d / "module.rom.npz")
    data = {
        "name": "modal",
        "cells": {"soc_initial": 0.9, "capacity_spread": 0.03, "resistance_spread": 0.05, "seed": 5},
        "module": {"n_series": 2, "n_parallel": 6, "thermal": "rom", "rom_file": "module.rom.npz",
                   "thermal_config": "module_coarse.toml"},
        "pack": {"n_modules": 3, "initial_temp_c": 30.0, "ambient_temp_c": 35.0, "max_current_a": 300.0},
        "cooling": {"layout": "series", "flow_l_min": 10.0, "supply_temp_c": 28.0},
    }  # fmt: skip
    return {"cfg": pack_config_from_dict(data, "modal", d), "rom": rom}


def _current(steps: int) -> np.ndarray:
    """A US06 road-load pack current [A] (3C peaks on the 2s6p modules)."""
    from hevsim.battery.profiles import cycle_cell_current

    return 6.0 * 3.0 * cycle_cell_current("us06", duration_s=float(steps))[:steps]


@pytest.mark.parametrize(
    ("rebase_k", "slack_k"), [(R.HOT_SPOT_REBASE_K, 0.0), (0.3, 0.0), (R.HOT_SPOT_REBASE_K, 0.01)]
)
def test_modal_rom_and_hot_spot_equal_the_dense_stepper(
    rom_pack: dict[str, Any], rebase_k: float, slack_k: float
) -> None:
    """Step the pack; replay every module's inputs (cell port heats, fluid from the wall at the
    start of the step, ambient) through the dense RomStepper: the same states (1e-9 K on the
    cell means, reconstructed) and, every step, the screened hot spot equals the largest of all
    candidate rows of the dense state (1e-9 K) while evaluating fewer rows than all of them;
    also when the screening's running sums restart every few steps (``rebase_k`` 0.3 K). With
    the slack ``hot_spot_slack_k`` > 0 (the default, :func:`R._module_hot_spots_within`) the
    hot spot is within the slack below that maximum, never above it."""
    from hevsim.thermal.rom import RomStepper

    cfg, rom = rom_pack["cfg"], rom_pack["rom"]
    pack = Pack(cfg, rom=rom)
    assert pack._f[R.F_HSEPS] == cfg.module.hot_spot_slack_k == 0.01  # the default
    pack._f[R.F_HSREBASE] = rebase_k
    pack._f[R.F_HSEPS] = slack_k
    n_mod, dt = cfg.pack.n_modules, cfg.pack.dt_s
    dense = RomStepper(rom, dt, pack.h_plate, 30.0 + 273.15, n_modules=n_mod)
    cells = np.empty((pack.n_cells, 5))
    steps = 200
    for i_a in _current(steps):
        wall = rom.wall_temp_k(dense.z)  # the wall at the start of the step
        start = pack.begin_step()
        row, hot = pack.finish_step(start, float(np.clip(i_a, -300, 300)), cells_out=cells)
        port_w = cells[:, 3].reshape(n_mod, -1)
        fluid = pack._rom_u[:, rom.n_cells : rom.n_cells + rom.n_segments]
        # the pack's fluid is the channel march of the dense wall from the plates' inlets
        cap = pack.loop.rho_cp * pack.loop.plate_flow_m3_s
        ntu = pack.h_plate * rom.wall_area_m2 / cap
        for m in range(n_mod):
            t_in = start.inlet_k[m]
            for i in range(rom.n_segments):
                mean = wall[m, i] + (t_in - wall[m, i]) * (1 - np.exp(-ntu[i])) / ntu[i]
                assert fluid[m, i] == pytest.approx(mean, abs=1e-9)
                t_in = wall[m, i] + (t_in - wall[m, i]) * np.exp(-ntu[i])
        z = dense.step(port_w, fluid, pack.ambient_k)
        np.testing.assert_allclose(pack.rom_state_z() @ rom.out_mean.T, rom.cell_mean_k(z), rtol=0, atol=1e-9)
        brute = rom.cell_max_k(z).max(axis=1)
        assert np.all(hot <= brute + 1e-9), hot - brute
        assert np.all(hot >= brute - slack_k - 1e-9), hot - brute
        assert row["hot_spot_temp_k"] == pytest.approx(hot.max(), abs=1e-12)
    if slack_k > 0.0:  # one row in double per module step, and few more
        assert pack._f[R.F_HSROWS64] < 2 * steps * n_mod, pack._f[R.F_HSROWS64]
        assert 0.0 <= pack._f[R.F_HSGAP] <= slack_k
        return
    rows = pack._f[R.F_HSROWS] / (steps * n_mod)
    assert rows < rom.out_candidates.shape[0], rows  # the screening skips rows
    if rebase_k < 1.0:  # every row evaluated again after the first step at least once
        assert rows * steps >= 2 * pack.arrays.rom_cand.shape[0], rows
    assert pack.steps_done == steps


_BRUTE: list[Any] = []


def _all_rows_max(g: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Brute force: per module, the largest ``G_j . w`` over every row, each row by the kernel's
    own double product (:func:`hevsim.battery.pack_run._dot`)."""
    if not _BRUTE:  # compiled once per session
        from numba import njit

        @njit(cache=False)
        def run(g, w, out):  # type: ignore[no-untyped-def]
            for m in range(w.shape[0]):
                best = -np.inf
                for j in range(g.shape[0]):
                    best = max(best, R._dot(g[j], w[m]))
                out[m] = best

        _BRUTE.append(run)
    out = np.empty(w.shape[0])
    _BRUTE[0](g, w, out)
    return out


@pytest.mark.parametrize("rebase_k", [R.HOT_SPOT_REBASE_K, 0.3])
def test_hot_spot_screening_equals_all_rows_on_random_states(
    rom_pack: dict[str, Any], rebase_k: float
) -> None:
    """Property (issue 26): on random modal states of every kind the screened hot spot (time
    bounds, then single precision with its rounding bound, then double) equals the maximum over
    every row evaluated in double (1e-12 K; the same product): random walks with steps from
    1e-6 to 10 times the typical deviation, jumps, the exactly uniform field (every row equal
    to rounding: all ties), a field peaked on one node, and states far from the ROM's range.
    The modules are screened together, row by row: each module's hot spot and evaluated rows
    equal those of the module screened alone (bit for bit), and a row's single-precision
    coefficients are read once per step for all the modules that evaluate it."""
    from hevsim.battery.pack import Pack

    cfg, rom = rom_pack["cfg"], rom_pack["rom"]
    pack = Pack(cfg, rom=rom)
    pack._f[R.F_HSREBASE] = rebase_k
    s = pack.arrays
    g, unit = s.rom_cand, s.hs_unit
    n_mod, r = s.rom_w.shape
    rng = np.random.default_rng(26)
    scale = rng.lognormal(0.0, 1.0, r) / np.sqrt(r)  # per-mode deviation scale [K-ish]
    d = rng.standard_normal((n_mod, r)) * scale
    t_ref = 300.0 + 10.0 * rng.standard_normal(n_mod)
    hot = np.empty(n_mod)
    alone_hot = np.empty(n_mod)
    alone = [
        s._replace(f=s.f.copy(), hs_ub=s.hs_ub[m : m + 1].copy(), hs_prev=s.hs_prev[m : m + 1].copy(),
                   hs_blk=s.hs_blk[m : m + 1].copy(), hs_d32=s.hs_d32[m : m + 1].copy(),
                   hs_cand=s.hs_cand[m : m + 1].copy())
        for m in range(n_mod)
    ]  # fmt: skip
    worst, equal, steps = 0.0, 0, 0
    for k in range(600):
        kind = k % 100
        if kind == 0:  # the uniform field: every row ties to rounding
            w = t_ref[:, None] * unit
        elif kind == 1:  # one node's row direction: a sharp peak
            w = t_ref[:, None] * unit + 5.0 * g[rng.integers(0, g.shape[0], n_mod)]
        elif kind == 2:  # a jump far out (1000 x the scale)
            w = t_ref[:, None] * unit + 1e3 * rng.standard_normal((n_mod, r)) * scale
        else:  # a random walk with steps over seven decades
            d = d + 10.0 ** rng.uniform(-6, 1) * rng.standard_normal((n_mod, r)) * scale
            t_ref = t_ref + rng.standard_normal(n_mod) * 10.0 ** rng.uniform(-4, 0)
            w = t_ref[:, None] * unit + d
        w = np.ascontiguousarray(w)
        R._module_hot_spots(s, w, hot)
        for m in range(n_mod):
            R._module_hot_spots(alone[m], w[m : m + 1], alone_hot[m : m + 1])
        np.testing.assert_array_equal(hot, alone_hot)
        brute = _all_rows_max(g, w)
        worst = max(worst, float(np.abs(hot - brute).max()))
        equal += int(np.sum(hot == brute))
        steps += 1
    assert worst <= 1e-12, worst
    assert equal >= 0.99 * steps * n_mod, (equal, steps * n_mod)
    # few rows in double: the single-precision pass leaves a handful per module step
    assert s.f[R.F_HSROWS64] < 0.05 * steps * n_mod * g.shape[0], s.f[R.F_HSROWS64]
    # the same rows as alone; each read once for the modules together
    assert s.f[R.F_HSROWS] == sum(a.f[R.F_HSROWS] for a in alone)
    assert s.f[R.F_HSROWS64] == sum(a.f[R.F_HSROWS64] for a in alone)
    assert s.f[R.F_HSREAD] * n_mod >= s.f[R.F_HSROWS] - steps * n_mod
    assert s.f[R.F_HSREAD] < 0.8 * s.f[R.F_HSROWS], (s.f[R.F_HSREAD], s.f[R.F_HSROWS])


def _random_states(rng: np.random.Generator, g: np.ndarray, unit: np.ndarray, n_mod: int, steps: int):  # type: ignore[no-untyped-def]
    """Modal states of every kind (as in the exact screening's property test): random walks with
    steps over seven decades, the exactly uniform field, a field peaked on one node, far jumps."""
    r = unit.shape[0]
    scale = rng.lognormal(0.0, 1.0, r) / np.sqrt(r)
    d = rng.standard_normal((n_mod, r)) * scale
    t_ref = 300.0 + 10.0 * rng.standard_normal(n_mod)
    for k in range(steps):
        kind = k % 100
        if kind == 0:
            w = t_ref[:, None] * unit
        elif kind == 1:
            w = t_ref[:, None] * unit + 5.0 * g[rng.integers(0, g.shape[0], n_mod)]
        elif kind == 2:
            w = t_ref[:, None] * unit + 1e3 * rng.standard_normal((n_mod, r)) * scale
        else:
            d = d + 10.0 ** rng.uniform(-6, 1) * rng.standard_normal((n_mod, r)) * scale
            t_ref = t_ref + rng.standard_normal(n_mod) * 10.0 ** rng.uniform(-4, 0)
            w = t_ref[:, None] * unit + d
        yield np.ascontiguousarray(w)


def _validation_states(rom: Any, pack: Pack, n_mod: int):  # type: ignore[no-untyped-def]
    """Modal states of the ROM under the validation load families of
    :func:`hevsim.thermal.rom.validation_loads` (per-cell heat of both signs moving the hot spot
    inside the cells, multi-sine, travelling wave, chirp, inlet swing; the ROM was not built or
    tuned on them), a different seed and heat scale per module."""
    from hevsim.thermal.rom import RomStepper, validation_loads

    q = pack._modal["q"]
    loads = [validation_loads(rom.n_cells, heat_scale_w=5.0 * (1 + m), seed=m) for m in range(n_mod)]
    for name in loads[0]:
        st = RomStepper(rom, 1.0, pack.h_plate, 303.15, n_modules=n_mod)
        steps = min(loads[0][name][2], 300)
        for k in range(1, steps + 1):
            heat = np.array([loads[m][name][0](float(k)) for m in range(n_mod)])
            fluid = np.array([[loads[m][name][1](float(k))] * rom.n_segments for m in range(n_mod)])
            z = st.step(heat, fluid, 308.15)
            yield np.ascontiguousarray(z @ q)


@pytest.mark.parametrize("slack_k", [1e-4, 0.01, 0.1])
@pytest.mark.parametrize("states", ["random", "validation"])
def test_hot_spot_within_the_slack_of_all_rows(rom_pack: dict[str, Any], slack_k: float, states: str) -> None:
    """Property (issue 26 item 5): with the slack ``eps`` = ``f[F_HSEPS]`` > 0 the hot spot of
    :func:`R._module_hot_spots_within` is the double value of one row and within ``eps`` of the
    maximum over every row evaluated in double (brute force, the same product): ``max - eps <=
    hot <= max``, with no tolerance, on random modal states of every kind and on the states of
    the validation loads; the step's certified gap (``f[F_HSGAP]``) is within ``eps`` and at
    least the error seen; and every row left out is below its bound (``hs_up``), so this fails
    if a term of the bound is missing (checked: without the residual's term or the float32
    rounding's). A small slack fills the basis (rebuilds exercised)."""
    cfg, rom = rom_pack["cfg"], rom_pack["rom"]
    n_mod = cfg.pack.n_modules
    pack = Pack(cfg, rom=rom)
    pack._f[R.F_HSEPS] = slack_k
    s = pack.arrays
    g, unit = s.rom_cand, s.hs_unit
    gen = (
        _random_states(np.random.default_rng(5), g, unit, n_mod, 400)
        if states == "random"
        else (_validation_states(rom, pack, n_mod))
    )
    hot = np.empty(n_mod)
    worst, steps = 0.0, 0
    for w in gen:
        R._module_hot_spots_within(s, w, hot)
        # every row's bound holds: G_j . w <= T_ref + U_j (the rows evaluated are marked)
        excess = _bound_excess(s, w)
        assert excess <= 1e-10, excess
        brute = _all_rows_max(g, w)
        assert np.all(hot <= brute), (hot - brute).max()
        assert np.all(hot >= brute - slack_k), (brute - hot).max()
        worst = max(worst, float((brute - hot).max()))
        steps += 1
    assert steps >= 400
    assert worst <= s.f[R.F_HSGAP] + 1e-12 <= slack_k + 1e-12, (worst, s.f[R.F_HSGAP])
    assert 0 < s.f[R.F_HSK] <= R.HOT_SPOT_BASIS_MAX
    assert s.f[R.F_HSROWS64] < 0.2 * steps * n_mod * g.shape[0], s.f[R.F_HSROWS64]
    if slack_k <= 1e-4:  # the basis filled and was cut down
        assert s.f[R.F_HSREBUILDS] > 0
    # most module steps keep a full screen (the drift bound of the rows left out holds)
    assert s.f[R.F_HSREUSE] + s.f[R.F_HSSCREENS] == steps * n_mod
    assert s.f[R.F_HSREUSE] > (0.5 if states == "random" else 0.1) * steps * n_mod, s.f[R.F_HSREUSE]


def _bound_excess(s: Any, w: np.ndarray) -> float:
    """The largest ``G_j . w - bound_j`` over the rows the step of
    :func:`R._module_hot_spots_within` did not evaluate in double: the step's ``T_ref + U_j``
    (``hs_up``) after a full screen; with a kept screen the hot rows' (``hs_hot``) and, for the
    other rows, the drift bound ``hs_keep[m, KP_BOUND]``."""
    g = s.rom_cand
    t_ref = (w @ s.hs_energy) / (s.hs_energy @ s.hs_unit)
    rows = np.einsum("jr,mr->mj", g, w)
    bound = t_ref[:, None] + s.hs_up
    open_ = s.hs_up > R._EVALUATED
    for m in range(w.shape[0]):
        kept_bound = s.hs_keep[m, R.KP_BOUND]
        if not np.isnan(kept_bound):
            hot_rows = s.hs_hot[m, : int(s.hs_keep[m, R.KP_NHOT])]
            left_out = np.ones(g.shape[0], bool)
            left_out[hot_rows] = False
            bound[m, left_out] = kept_bound
            open_[m, left_out] = True
    return float(np.where(open_, rows - bound, -np.inf).max())


def test_hot_spot_kept_screen_covers_any_state(rom_pack: dict[str, Any]) -> None:
    """The kept screen of :func:`R._module_hot_spots_within` bounds the rows left out by their
    drift from the anchor state itself (not a sum of steps), so it holds for states in any
    order: the validation-load trajectory replayed forwards, then shuffled, then backwards
    (brute force over every row each step, and each left-out row below its bound)."""
    cfg, rom = rom_pack["cfg"], rom_pack["rom"]
    n_mod = cfg.pack.n_modules
    pack = Pack(cfg, rom=rom)
    s = pack.arrays
    eps = s.f[R.F_HSEPS]
    states = list(_validation_states(rom, pack, n_mod))[:600]
    order = list(range(len(states)))
    rng = np.random.default_rng(3)
    shuffled = [int(i) for i in rng.permutation(len(states))]
    hot = np.empty(n_mod)
    for i in order + shuffled + order[::-1]:
        w = states[i]
        R._module_hot_spots_within(s, w, hot)
        assert _bound_excess(s, w) <= 1e-10
        brute = _all_rows_max(s.rom_cand, w)
        assert np.all(hot <= brute) and np.all(hot >= brute - eps), (brute - hot).max()
    assert s.f[R.F_HSREUSE] > 0.05 * 3 * len(states) * n_mod, s.f[R.F_HSREUSE]


def test_cooling_loop_reaches_its_closed_form_steady_state() -> None:
    """Constant plate heat Q, chiller off: the compiled loop settles where the radiator, the
    pipes and the pump balance it: eps C_min (T - T_a) + UA_loop (T - T_a) = Q + P_pump."""
    cool = CoolingSection(
        flow_l_min=12.0, coolant_volume_l=0.5, chiller=0, radiator_bypass=0, loop_ua_w_k=3.0
    )
    loop = CoolingLoop(cool, ControllerSection(kind="off"), 4, 1070.0, 3300.0)
    amb, q = 300.0, 800.0
    for _ in range(4000):
        st = loop.begin_step(330.0, amb, 1.0)
        loop.end_step(st, q, 1.0)
    cap = 1070.0 * 3300.0 * 12.0 * LITRE_PER_MIN_M3_S
    c_air = cool.radiator_air_flow_kg_s * AIR_SPECIFIC_HEAT_J_KGK
    c_min, c_max = min(cap, c_air), max(cap, c_air)
    eps = counterflow_effectiveness(cool.radiator_ua_w_k / c_min, c_min / c_max)
    t_ss = amb + (q + st.pump_power_w) / (eps * c_min + cool.loop_ua_w_k)
    assert loop.temp_k == pytest.approx(t_ss, abs=1e-6)
    assert st.pump_power_w > 0 and st.chiller_w == 0.0


def test_kernel_pack_step_equals_python_steps() -> None:
    """The series kernel's compiled pack step (no Python per step) and the same pack stepped
    from Python (PackRun.begin / finish_current) at the kernel's pack currents: the same
    channels to rounding (1e-9) and the same energy terms."""
    from hevsim.config import load_vehicle_config
    from hevsim.cycles import load_cycle
    from hevsim.sim.pack_vehicle import make_pack_run, simulate_pack_vehicle

    cfg = load_vehicle_config(EX / "series_hev_pack.toml")
    cyc = load_cycle("us06")
    res = simulate_pack_vehicle(cfg, cyc, 1.0)
    current = res.timeseries["pack_current_a"].to_numpy()[:-1]
    run = make_pack_run(cfg, 1.0, float(cfg.simulation.soc_initial))
    for i_a in current:
        run.begin()
        run.finish_current(float(i_a))
    ref = run.frame(len(res.timeseries))
    for col in ref.columns:
        np.testing.assert_allclose(res.timeseries[col].to_numpy(), ref[col].to_numpy(), rtol=1e-9, atol=1e-9)
    e_kernel, e_py = res.extra["pack_energy"], run.energy()
    for key in ("electrical_out_j", "plate_heat_j", "chiller_j", "pump_work_j"):
        assert e_kernel[key] == pytest.approx(e_py[key], rel=1e-9, abs=1e-6)
    assert abs(e_kernel["residual_relative"]) < 1e-9
    # the step pair E - Z I is exact while every cell carries the pack's direction; below a few
    # amperes parallel cells with spread circulate current and the bus's pair is off by < 1 %
    # (documented in hevsim.battery.bms): the power mismatch stays below 1e-5 of the throughput
    ts = res.timeseries.iloc[:-1]
    i, v = ts["pack_current_a"].to_numpy(), ts["pack_voltage_v"].to_numpy()
    pair = ts["pack_ocv_v"].to_numpy() - ts["pack_resistance_ohm"].to_numpy() * i
    off = np.abs(v - pair) / v
    assert off[np.abs(i) > 3.0].max() < 1e-9
    assert off.max() < 0.01
    assert np.abs((v - pair) * i).sum() < 1e-5 * np.abs(v * i).sum()
