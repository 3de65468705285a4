"""Property tests: every vectorised component method is its scalar kernel, and both are the
physics written out independently here (issue 18).

For each component, random operating points (hypothesis) — including sizing factors
(``torque_scale``) away from 1, points on the map edges and beyond them (clamped
extrapolation), negative speeds and torques — are evaluated three ways: the numpy method on
an array, the compiled scalar kernel point by point, and a reference formula built from the
component's :class:`~hevsim.tables.Table2D` objects. All three agree to 1e-12.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hevsim.components.battery import (
    BatteryPack,
    current_for_power,
    pack_ocv_r,
    pack_resistance,
    soc_rate,
)
from hevsim.components.body import VehicleBody, road_load_force
from hevsim.components.bus import (
    battery_power_limits,
    bus_balance_many,
    bus_current,
    limit_machine_torque,
    machine_request_many,
    regen_torque,
)
from hevsim.components.driveline import Gear, gear_input_torque, gear_output_torque
from hevsim.components.electric_machine import (
    MIN_EFFICIENCY,
    ElectricMachine,
    machine_efficiency,
    machine_power,
    torque_limits,
)
from hevsim.components.engine import (
    Engine,
    engine_fuel_rate,
    engine_torque,
    fired_fuel_rate,
    scaled_max_torque,
)
from hevsim.sim.model import resolve_component
from hevsim.tables import Table1D, Table2D
from hevsim.units import STANDARD_GRAVITY

TOL = 1e-12
SETTINGS = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
N = 16  # points per example


def close(a: object, b: object) -> bool:
    """Equal to 1e-12 relative (absolute near zero), NaN where the other is NaN."""
    return bool(np.allclose(np.asarray(a, float), np.asarray(b, float), rtol=TOL, atol=TOL, equal_nan=True))


def shipped(name: str, kind: str) -> Path:
    return resolve_component(name, kind, Path("."), kind)


MOTORS = {
    n: ElectricMachine.from_directory(shipped(n, "motor")) for n in ("honda_pm49", "prius_1998_mg2_pm30")
}
ENGINES = {n: Engine.from_directory(shipped(n, "engine")) for n in ("vw_1p9_tdi_ci67", "geo_1p0_si41")}

scales = st.sampled_from([1.0, 0.7, 1.4]) | st.floats(0.3, 3.0)
seeds = st.integers(0, 2**32 - 1)


def points(rng: np.random.Generator, lo: float, hi: float, edges: np.ndarray) -> np.ndarray:
    """Random values over [lo, hi] plus exact map edges and points beyond them."""
    x = rng.uniform(lo, hi, N)
    k = rng.integers(0, edges.size, 4)
    x[:4] = edges[k]  # on the grid lines
    x[4] = edges[0] - abs(rng.normal(0.0, 50.0))  # below the map
    x[5] = edges[-1] + abs(rng.normal(0.0, 50.0))  # above the map
    return x


# ------------------------------------------------------------------ electric machine
@SETTINGS
@given(name=st.sampled_from(sorted(MOTORS)), scale=scales, seed=seeds)
def test_machine_methods_are_their_kernels(name: str, scale: float, seed: int) -> None:
    base = MOTORS[name]
    m = ElectricMachine(
        base.name, base.kind, base.max_motoring_torque, base.max_generating_torque,
        efficiency_map=base.efficiency_map, torque_scale=scale,
    )  # fmt: skip
    emap = m.efficiency_map
    assert emap is not None
    rng = np.random.default_rng(seed)
    w = points(rng, -emap.x[-1], emap.x[-1], emap.x)
    t = points(rng, scale * emap.y[0], scale * emap.y[-1], scale * emap.y)
    tab = m.kernel_tables()
    eff = m.efficiency_at(t, w)
    p_el = m.electrical_power(t, w)
    t_mot, t_gen = m.limits(w)
    for i in range(N):
        assert close(eff[i], machine_efficiency(t[i], w[i], m.kind_code, m.efficiency, scale, tab))
        assert close(p_el[i], machine_power(t[i], w[i], m.kind_code, m.efficiency, scale, tab))
        assert close((t_mot[i], t_gen[i]), torque_limits(w[i], scale, tab))
    # the physics: the map's torque axis scales with the machine (read at T / scale)
    ref_eff = np.maximum(emap(np.abs(w), t / scale), MIN_EFFICIENCY)
    assert close(eff, ref_eff)
    p_mech = t * w
    assert close(p_el, np.where(p_mech > 0, p_mech / ref_eff, p_mech * ref_eff))
    assert close(t_mot, scale * m.max_motoring_torque(np.abs(w)))
    assert close(t_gen, scale * m.max_generating_torque(np.abs(w)))


def test_scaled_machine_has_the_efficiency_of_the_base_machine_at_scaled_torque() -> None:
    """The fixed divergence: a 1.4x machine at 1.4 T is as efficient as the 1x machine at T."""
    base = MOTORS["honda_pm49"]
    big = ElectricMachine(
        base.name, base.kind, base.max_motoring_torque, base.max_generating_torque,
        efficiency_map=base.efficiency_map, torque_scale=1.4,
    )  # fmt: skip
    t = np.array([20.0, 60.0, -40.0])
    w = np.array([300.0, 150.0, 400.0])
    assert close(big.efficiency_at(1.4 * t, w), base.efficiency_at(t, w))
    assert not close(big.efficiency_at(t, w), base.efficiency_at(t, w))


@SETTINGS
@given(eff=st.floats(0.5, 1.0), scale=scales, seed=seeds)
def test_constant_efficiency_machine(eff: float, scale: float, seed: int) -> None:
    x = np.array([0.0])
    m = ElectricMachine(
        "c", "constant_efficiency", Table1D(x, np.array([150.0])), Table1D(x, np.array([-150.0])),
        efficiency=eff, torque_scale=scale,
    )  # fmt: skip
    rng = np.random.default_rng(seed)
    t = rng.uniform(-300, 300, N)
    w = rng.uniform(-100, 800, N)
    p_mech = t * w
    assert close(m.electrical_power(t, w), np.where(p_mech > 0, p_mech / eff, p_mech * eff))
    assert close(m.limits(w), (np.full(N, 150.0 * scale), np.full(N, -150.0 * scale)))


# ------------------------------------------------------------------------------ engine
@SETTINGS
@given(name=st.sampled_from(sorted(ENGINES)), scale=scales, seed=seeds)
def test_engine_methods_are_their_kernels(name: str, scale: float, seed: int) -> None:
    base = ENGINES[name]
    e = Engine(
        base.name, base.max_torque, base.closed_throttle_torque, fuel_map=base.fuel_map,
        stall_speed_radps=base.stall_speed_radps, redline_radps=base.redline_radps,
        fuel_lhv_jpkg=base.fuel_lhv_jpkg, torque_scale=scale,
    )  # fmt: skip
    fmap = e.fuel_map
    assert fmap is not None
    rng = np.random.default_rng(seed)
    w = points(rng, 0.0, 1.1 * e.redline_radps, fmap.x)
    t = points(rng, -20.0, scale * 1.1 * fmap.y[-1], scale * fmap.y)
    thr = rng.uniform(-0.1, 1.1, N)
    thr[:3] = (0.0, 1.0, 0.5)
    tab = e.kernel_tables()
    torque = e.torque(thr, w)
    fuel = e.fuel_rate(t, w)
    raw = e.fuel_map_rate(t, w)
    tmax = e.max_torque_nm(w)
    args = (e.stall_speed_radps, e.redline_radps, scale, tab)
    for i in range(N):
        assert close(torque[i], engine_torque(thr[i], w[i], False, *args))
        assert close(fuel[i], fired_fuel_rate(t[i], w[i], True, e.fuel_lhv_jpkg, *args))
        assert close(raw[i], engine_fuel_rate(t[i], w[i], True, True, e.fuel_lhv_jpkg, scale, tab))
    # the physics: torque and fuel flow scale together; NaN outside the operating range
    fired = (thr > 0) & (w >= e.stall_speed_radps) & (w <= e.redline_radps)
    drag = np.where(w > 0, scale * e.closed_throttle_torque(w), 0.0)
    assert close(torque, np.where(fired, thr * scale * e.max_torque(w), drag))
    ref_raw = scale * np.maximum(fmap(w, t / scale), 0.0)
    assert close(raw, ref_raw)
    assert close(tmax, scale * e.max_torque(w))
    assert close(scaled_max_torque(e.max_torque, scale, w), tmax)  # what the map plots draw
    bad = (w < e.stall_speed_radps) | (w > e.redline_radps) | (t > tmax * (1 + 1e-9))
    assert close(fuel, np.where(bad, np.nan, ref_raw))


def test_torque_scale_is_applied_only_in_the_component_kernels() -> None:
    """The sizing of a map (``torque_scale`` times a curve or map value) is written once, in
    ``hevsim.components``; every other module calls those kernels (the plots once drew the
    max-torque curve from their own ``torque_scale * max_torque(w)``)."""
    import re

    src = Path(__file__).resolve().parent.parent / "src" / "hevsim"
    scaling = re.compile(r"torque_scale\)?\s*\*|\*\s*(float\()?[\w.]*torque_scale\b")
    found = [
        f"{path.relative_to(src)}:{no}: {line.strip()}"
        for path in sorted(src.rglob("*.py"))
        if path.relative_to(src).parts[0] != "components"
        for no, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
        if scaling.search(line)
    ]
    assert found == [], found


def test_ideal_engine_burns_its_brake_power() -> None:
    x = np.array([0.0, 500.0])
    e = Engine("ideal", Table1D(x, np.array([200.0, 200.0])), Table1D(x, np.zeros(2)), torque_scale=1.3)
    t = np.array([-10.0, 0.0, 50.0, 250.0])
    w = np.full(4, 200.0)
    assert close(e.fuel_rate(t, w), np.maximum(t * w, 0.0) / e.fuel_lhv_jpkg)


# ------------------------------------------------------------------------------ battery
PACK = BatteryPack.from_directory(
    shipped("nimh_spiral_6ah_insight_prius_nimh6", "battery"),
    n_series=40, n_parallel=2, r_extra_ohm=0.03, coulombic_efficiency=0.97,
)  # fmt: skip


@SETTINGS
@given(seed=seeds, temp_k=st.floats(250.0, 330.0))
def test_battery_methods_are_their_kernels(seed: int, temp_k: float) -> None:
    b = PACK
    rng = np.random.default_rng(seed)
    soc = points(rng, -0.1, 1.1, b.ocv_cell.x)
    power = rng.uniform(-40e3, 40e3, N)
    current = rng.uniform(-80, 80, N)
    tab = b.kernel_tables()
    ocv = b.ocv(soc, temp_k)
    r = b.resistance(soc, current, temp_k)
    i = b.current(power, soc, temp_k)
    rate = b.soc_rate(current)
    cap_as = 3600.0 * b.capacity_ah
    for k in range(N):
        o, rk = pack_ocv_r(soc[k], temp_k, current[k], b.n_series, b.n_parallel, b.r_extra_ohm, tab)
        assert close(ocv[k], o) and close(r[k], rk)
        o, rk = pack_ocv_r(soc[k], temp_k, power[k], b.n_series, b.n_parallel, b.r_extra_ohm, tab)
        assert close(i[k], current_for_power(power[k], o, rk))
        assert close(rate[k], soc_rate(current[k], b.coulombic_efficiency, cap_as))
    # the physics: eq 21-22 and eq 13
    assert close(ocv, b.n_series * b.ocv_cell(soc, temp_k))
    r_cell = np.where(current > 0, b.r_discharge_cell(soc, temp_k), b.r_charge_cell(soc, temp_k))
    assert close(r, b.n_series / b.n_parallel * r_cell + b.r_extra_ohm)
    assert close(r, pack_resistance(r_cell, b.n_series, b.n_parallel, b.r_extra_ohm))
    r_p = b.resistance(soc, power, temp_k)
    ok = ocv * ocv >= 4 * r_p * power
    assert np.allclose(((ocv - r_p * i) * i)[ok], power[ok], rtol=1e-9)
    eff = np.where(current < 0, b.coulombic_efficiency, 1.0)
    assert close(rate, -current * eff / cap_as)


# --------------------------------------------------------------------- body, driveline
@SETTINGS
@given(seed=seeds, mass=st.floats(500.0, 5000.0), crr=st.floats(0.0, 0.02))
def test_body_and_gear_methods_are_their_kernels(seed: int, mass: float, crr: float) -> None:
    body = VehicleBody(mass_kg=mass, rolling_resistance=crr, mass_factor=1.05, headwind_mps=2.0)
    rng = np.random.default_rng(seed)
    v = np.abs(rng.normal(10.0, 10.0, N))
    v[0] = 0.0
    a = rng.normal(0.0, 1.5, N)
    g = rng.normal(0.0, 0.05, N)
    f = body.road_load_force(v, a, g)
    kargs = (mass, 1.05, body.drag_coefficient, body.frontal_area_m2, body.air_density_kgpm3, 2.0, crr, 0.0)
    for k in range(N):
        assert close(f[k], road_load_force(v[k], a[k], g[k], *kargs))
    alpha = np.arctan(g)
    rel = v - 2.0
    ref = (
        1.05 * mass * a
        + 0.5 * body.drag_coefficient * body.air_density_kgpm3 * body.frontal_area_m2 * rel * np.abs(rel)
        + crr * mass * STANDARD_GRAVITY * np.cos(alpha) * (v > 0)
        + mass * STANDARD_GRAVITY * np.sin(alpha)
    )
    assert np.allclose(f, ref, rtol=1e-12, atol=1e-9)
    gear = Gear(ratio=3.7, efficiency=0.95)
    t = rng.normal(0.0, 100.0, N)
    out = gear.output_torque(t)
    for k in range(N):
        assert close(out[k], gear_output_torque(t[k], 3.7, 0.95))
        assert close(gear.input_torque(out[k]), gear_input_torque(out[k], 3.7, 0.95))
    assert close(out, np.where(t > 0, t * 3.7 * 0.95, t * 3.7 / 0.95))
    assert close(gear.input_torque(out), t)


def test_cycle_current_profile_uses_the_body_road_load() -> None:
    """The drive-cycle cell current of the battery examples takes its road load from the
    vehicle body's eq 32 (it had its own copy with g = 9.80665 m/s^2, the body 9.81)."""
    from hevsim.battery.profiles import RoadLoadVehicle, cycle_cell_current
    from hevsim.cycles import load_cycle

    veh = RoadLoadVehicle()
    current = cycle_cell_current("udds", duration_s=300.0, dt_s=1.0, vehicle=veh)
    cyc = load_cycle("udds")
    v = cyc.speed_at(cyc.time_s[0] + np.arange(301.0))
    v_mid = 0.5 * (v[1:] + v[:-1])
    body = VehicleBody(
        mass_kg=veh.mass_kg, drag_coefficient=veh.cd, frontal_area_m2=veh.area_m2,
        rolling_resistance=veh.crr, air_density_kgpm3=veh.rho_kgpm3,
    )  # fmt: skip
    p_wheel = body.road_load_force(v_mid, np.diff(v)) * v_mid
    p_bat = np.where(p_wheel > 0, p_wheel / veh.drive_efficiency, p_wheel * veh.regen_fraction)
    expected = (p_bat + veh.aux_power_w) / (veh.n_cells * veh.cell_voltage_v)
    assert np.any(v_mid > 0) and np.any(p_wheel < 0)
    assert close(current, expected)


# --------------------------------------------------------------------------------- bus
@SETTINGS
@given(scale=scales, seed=seeds, i_chg=st.floats(5.0, 200.0), i_dis=st.floats(5.0, 400.0))
def test_bus_balance_grid_is_the_scalar_balance(scale: float, seed: int, i_chg: float, i_dis: float) -> None:
    """The DP's grid evaluation and the forward kernel's scalar calls give the same torques,
    powers and currents; regeneration never charges beyond the charge-current power."""
    base = MOTORS["honda_pm49"]
    m = ElectricMachine(
        base.name, base.kind, base.max_motoring_torque, base.max_generating_torque,
        efficiency_map=base.efficiency_map, torque_scale=scale,
    )  # fmt: skip
    tab = m.kernel_tables()
    rng = np.random.default_rng(seed)
    t_req = rng.uniform(-250.0 * scale, 250.0 * scale, N)
    w = rng.uniform(0.0, 900.0, N)
    p_other = rng.uniform(-30e3, 5e3, N)
    regen_ok = rng.random(N) > 0.2
    ocv = rng.uniform(150.0, 300.0, N)
    r_dis = rng.uniform(0.05, 0.5, N)
    r_chg = r_dis * rng.uniform(0.8, 1.2, N)
    p_chg = np.empty(N)
    for k in range(N):
        p_dis_k, p_chg[k] = battery_power_limits(ocv[k], r_dis[k], ocv[k], r_chg[k], i_dis, i_chg)
        assert close(p_chg[k], (ocv[k] + r_chg[k] * i_chg) * i_chg)
        i_star = ocv[k] / (2 * r_dis[k])
        assert close(p_dis_k, (ocv[k] - r_dis[k] * min(i_dis, i_star)) * min(i_dis, i_star))
    mach = (m.kind_code, m.efficiency, scale, tab)
    t_in, p_in, over_torque = np.empty(N), np.empty(N), np.empty(N, np.bool_)
    machine_request_many(t_req, w, regen_ok, *mach, t_in, p_in, over_torque)
    outs = [np.empty(N) for _ in range(4)] + [np.empty(N, np.bool_)]
    bus_balance_many(t_in, p_in, w, p_other, ocv, r_dis, r_chg, p_chg, *mach, *outs)
    torque, p_el, p_bat, current, over_power = outs
    for k in range(N):
        t_max, t_min = torque_limits(w[k], scale, tab)
        assert over_torque[k] == (t_req[k] > t_max * (1 + 1e-12))
        t0 = regen_torque(t_req[k], t_min, regen_ok[k])
        p0 = machine_power(t0, w[k], *mach)
        assert close((t_in[k], p_in[k]), (t0, p0))
        tk, pk, limited = limit_machine_torque(t0, p0, w[k], p_other[k], np.inf, p_chg[k], *mach)
        assert close((torque[k], p_el[k]), (tk, pk))
        assert close(p_el[k], machine_power(tk, w[k], m.kind_code, m.efficiency, scale, tab))
        i, o, rr, over = bus_current(p_bat[k], ocv[k], r_dis[k], ocv[k], r_chg[k])
        assert close(current[k], i) and over_power[k] == over
        assert close(p_bat[k], p_el[k] + p_other[k])
        if t0 < 0 and not limited:
            assert torque[k] == t0
        if limited:  # scaled toward the charge limit (a map makes it a fixed point, not exact:
            # the DP then flags the residual excess as a charge-current violation)
            assert torque[k] <= 0.0 and abs(torque[k]) < abs(t0)
            assert p_bat[k] > p0 + p_other[k]
        if not over:
            assert np.isclose((o - rr * i) * i, p_bat[k], rtol=1e-9, atol=1e-6)


@pytest.mark.parametrize("eff", [1.0, 0.9])
def test_regen_limit_is_exact_for_constant_efficiency(eff: float) -> None:
    x = np.array([0.0])
    m = ElectricMachine(
        "c", "constant_efficiency", Table1D(x, np.array([300.0])), Table1D(x, np.array([-300.0])), eff
    )
    tab = m.kernel_tables()

    def limit(t: float, p_dis: float) -> tuple[float, float, bool]:
        p0 = machine_power(t, 400.0, 1, eff, 1.0, tab)
        return limit_machine_torque(t, p0, 400.0, 1000.0, p_dis, 20e3, 1, eff, 1.0, tab)

    t, p_el, limited = limit(-200.0, np.inf)
    assert limited and p_el + 1000.0 == pytest.approx(-20e3, rel=1e-12)
    t, p_el, limited = limit(200.0, 50e3)
    assert limited and p_el + 1000.0 == pytest.approx(50e3, rel=1e-12)
    t, p_el, limited = limit(50.0, 50e3)
    assert not limited and t == 50.0


def test_table2d_edges_clamp_in_kernels() -> None:
    """Maps clamp beyond their edges in every kernel (the shared extrapolation policy)."""
    x = np.array([0.0, 100.0, 200.0])
    y = np.array([-50.0, 0.0, 50.0])
    z = np.array([[0.7, 0.8, 0.75], [0.85, 0.9, 0.88], [0.8, 0.86, 0.83]])
    lim = Table1D(x, np.array([50.0, 50.0, 30.0]))
    m = ElectricMachine(
        "m", "map", lim, Table1D(x, -lim.y), efficiency_map=Table2D(x, y, z), torque_scale=2.0
    )
    assert close(m.efficiency_at(200.0, 500.0), 0.83)  # beyond both edges: the corner
    assert close(m.efficiency_at(-200.0, -500.0), 0.8)
    assert close(m.limits(1e4), (60.0, -60.0))
