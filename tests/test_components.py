"""Tier 1: analytic checks of the component physics and lookup tables."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hevsim.components.battery import BatteryPack, pack_ocv_r, pack_ocv_r_both
from hevsim.components.body import VehicleBody
from hevsim.components.driveline import Gear, Tire
from hevsim.components.electric_machine import ElectricMachine
from hevsim.components.engine import Engine
from hevsim.errors import InputError
from hevsim.sim.model import resolve_component
from hevsim.tables import Table1D, Table2D


def test_table1d_policies_and_shapes() -> None:
    t = Table1D([0.0, 1.0, 2.0], [0.0, 10.0, 30.0], "clamp")
    assert t([0.5, 1.5]).tolist() == [5.0, 20.0]
    assert t(-1.0) == 0.0 and t(5.0) == 30.0
    lin = Table1D([0.0, 1.0, 2.0], [0.0, 10.0, 30.0], "linear")
    assert lin(-1.0) == pytest.approx(-10.0) and lin(3.0) == pytest.approx(50.0)
    x = np.linspace(-1, 3, 24).reshape(2, 3, 4)
    assert lin(x).shape == (2, 3, 4)


def test_table2d_bilinear_exact_on_bilinear_function() -> None:
    x = np.array([0.0, 1.0, 3.0])
    y = np.array([-1.0, 2.0])
    z = 2 * x[:, None] + 3 * y[None, :] + x[:, None] * y[None, :]
    t = Table2D(x, y, z, "linear")
    xq = np.array([[0.3], [2.5], [4.0]])
    yq = np.array([-2.0, 0.0, 1.5])
    expect = 2 * xq + 3 * yq + xq * yq
    assert np.allclose(t(xq, yq), expect)


@pytest.mark.parametrize(
    ("x", "y", "fragment"),
    [
        ([0.0, 2.0, 1.0], [1.0, 2.0, 3.0], "not strictly increasing"),
        ([0.0, np.nan, 1.0], [1.0, 2.0, 3.0], "non-finite"),
        ([0.0, 1.0, 2.0], [1.0, np.nan, 3.0], "non-finite"),
        ([0.0, 1.0, 2.0], [1.0, 2.0], "expected equal sizes"),
    ],
)
def test_table_validation(x: list[float], y: list[float], fragment: str) -> None:
    with pytest.raises(InputError, match=fragment):
        Table1D(x, y, source="map.csv")


def test_unsorted_map_csv_names_file_and_value(tmp_path) -> None:  # type: ignore[no-untyped-def]
    p = tmp_path / "max_torque.csv"
    p.write_text("speed_rad_per_s,max_torque_N_m\n0,10\n20,12\n10,11\n")
    with pytest.raises(InputError) as err:
        Table1D.from_csv(p, "speed_rad_per_s", "max_torque_N_m")
    assert "max_torque.csv" in str(err.value) and "value 10 at position 2 follows 20" in str(err.value)


def test_nan_in_map_csv_names_line(tmp_path) -> None:  # type: ignore[no-untyped-def]
    p = tmp_path / "fuel.csv"
    p.write_text("speed_rad_per_s,torque_N_m,fuel_rate_g_per_s\n1,0,0.1\n1,10,nan\n2,0,0.2\n2,10,0.3\n")
    with pytest.raises(InputError, match=r"fuel.csv: line 3, column 'fuel_rate_g_per_s'"):
        Table2D.from_long_csv(p, "speed_rad_per_s", "torque_N_m", "fuel_rate_g_per_s")


def test_body_road_load_and_axle_loads() -> None:
    body = VehicleBody(mass_kg=1000.0, drag_coefficient=0.3, frontal_area_m2=2.0,
                       rolling_resistance=0.01, air_density_kgpm3=1.2)  # fmt: skip
    f = body.road_load_force(20.0, 0.5, 0.0)
    assert f == pytest.approx(1000 * 0.5 + 0.5 * 0.3 * 1.2 * 2.0 * 400 + 0.01 * 1000 * 9.81)
    fzf, fzr = body.axle_normal_loads(accel_mps2=1.0, v_mps=10.0, grade=0.05)
    alpha = np.arctan(0.05)
    assert body.wheels_per_axle * (fzf + fzr) == pytest.approx(1000 * 9.81 * np.cos(alpha))
    fzf0, fzr0 = body.axle_normal_loads(accel_mps2=0.0, v_mps=10.0, grade=0.05)
    assert fzr > fzr0 and fzf < fzf0  # acceleration shifts load to the rear axle
    # headwind raises the drag at the same ground speed
    windy = VehicleBody(mass_kg=1000.0, headwind_mps=-5.0)
    assert windy.road_load_force(10.0, 0.0) > VehicleBody(mass_kg=1000.0).road_load_force(10.0, 0.0)


def test_gear_efficiency_direction() -> None:
    g = Gear(ratio=3.0, efficiency=0.9)
    assert g.output_torque(10.0) == pytest.approx(27.0)  # motoring: loses torque
    assert g.output_torque(-10.0) == pytest.approx(-10.0 * 3.0 / 0.9)  # braking: wheels drive
    assert g.input_torque(g.output_torque(7.0)) == pytest.approx(7.0)


def test_magic_formula_is_odd_and_invertible() -> None:
    tire = Tire()
    k = np.array([-0.05, 0.05])
    f = tire.longitudinal_force(k, 4000.0)
    assert f[0] == pytest.approx(-f[1])
    assert tire.slip_for_force(f[1], 4000.0) == pytest.approx(0.05, abs=1e-3)
    assert tire.wheel_speed_radps(3.0) == pytest.approx(10.0)


def test_engine_no_fuel_at_zero_throttle_stall_and_redline() -> None:
    eng = Engine.from_directory(resolve_component("vw_1p9_tdi_ci67", "engine", Path("."), "e"))
    w = np.array([50.0, 150.0, 500.0])
    torque = eng.torque(0.5, w)
    assert torque[1] == pytest.approx(0.5 * float(eng.max_torque(150.0)))
    assert torque[0] <= 0 and torque[2] <= 0  # below stall / above redline: unfired drag
    assert eng.torque(0.0, 150.0) <= 0.0
    rate = eng.fuel_rate(100.0, 188.5)
    bsfc_g_per_kwh = rate * 1e3 * 3.6e6 / (100.0 * 188.5)
    assert 190 < bsfc_g_per_kwh < 300
    assert np.isnan(eng.fuel_rate(100.0, 20.0))  # below stall: infeasible for DP


def test_electric_machine_power_direction() -> None:
    m = ElectricMachine.constant_torque("m", 100.0, efficiency=0.8)
    assert m.electrical_power(10.0, 100.0) == pytest.approx(1000 / 0.8)
    assert m.electrical_power(-10.0, 100.0) == pytest.approx(-1000 * 0.8)
    pm = ElectricMachine.from_directory(resolve_component("honda_pm49", "motor", Path("."), "m"))
    hi, lo = pm.limits(np.array([0.0, 600.0]))
    assert hi[0] > hi[1] > 0 and lo[0] < 0
    assert 0.6 < float(pm.efficiency_at(100.0, 300.0)) <= 1.0


def test_electrical_power_is_the_closed_form_to_the_last_bit() -> None:
    """P_el = P_mech / eta motoring (one correctly rounded reciprocal, as LLVM folds a constant
    pow(x, -1); libm's pow(eta, -1) was off by an ulp for about 1 in 1000 efficiencies),
    P_mech eta generating, 0 at rest, for the scalar kernel every compiled loop calls."""
    from numba import njit

    from hevsim.components.electric_machine import electrical_power

    @njit(cache=False)
    def many(t, w, eta):  # type: ignore[no-untyped-def]
        out = np.empty(t.shape[0])
        for i in range(t.shape[0]):
            out[i] = electrical_power(t[i], w[i], eta[i])
        return out

    rng = np.random.default_rng(24)
    n = 200_000
    t, w, eta = rng.uniform(-300, 300, n), rng.uniform(0, 900, n), rng.uniform(0.05, 1, n)
    p = t * w
    assert np.array_equal(many(t, w, eta), np.where(p > 0, p * (1.0 / eta), p * eta))
    assert electrical_power(0.0, 100.0, 0.9) == 0.0 and electrical_power(5.0, 0.0, 0.9) == 0.0
    assert np.isnan(electrical_power(np.nan, 1.0, 0.9)) and np.isnan(electrical_power(1.0, 1.0, np.nan))


def test_gear_torques_are_the_closed_form_to_the_last_bit() -> None:
    """The compiled per-point gear: T i eta motoring, T i / eta braking (one correctly rounded
    reciprocal, as for the machines' power), T i at zero torque; arrays as before."""
    from numba import njit

    from hevsim.components.driveline import gear_input_torque, gear_output_torque

    @njit(cache=False)
    def many(t, eta):  # type: ignore[no-untyped-def]
        out, inp = np.empty(t.shape[0]), np.empty(t.shape[0])
        for i in range(t.shape[0]):
            out[i] = gear_output_torque(t[i], 3.9, eta[i])
            inp[i] = gear_input_torque(t[i], 3.9, eta[i])
        return out, inp

    rng = np.random.default_rng(11)
    t, eta = rng.uniform(-400, 400, 200_000), rng.uniform(0.5, 1.0, 200_000)
    t[:3] = 0.0
    factor = np.where(t > 0, eta, np.where(t < 0, 1.0 / eta, 1.0))
    out, inp = many(t, eta)
    assert np.array_equal(out, t * 3.9 * factor) and np.array_equal(inp, t / (3.9 * factor))
    arr = gear_output_torque(t[:50], 3.9, 0.9)  # arrays keep numpy's eta ** sign(T)
    assert np.array_equal(arr, t[:50] * 3.9 * 0.9 ** np.sign(t[:50]))


def test_grade_terms_on_level_road_and_slopes() -> None:
    """The compiled grade and rolling forces: sin/cos of atan(grade) (level road without libm
    calls: +-0 and exactly 1), scalar and array alike."""
    from hevsim.components.body import grade_force, rolling_force
    from hevsim.units import STANDARD_GRAVITY

    assert grade_force(1000.0, 0.0) == 0.0 and np.signbit(grade_force(1000.0, -0.0))
    assert rolling_force(1000.0, 0.0, 0.01, 0.0, 5.0) == 0.01 * 1000.0 * STANDARD_GRAVITY
    g = np.array([-0.1, -0.0, 0.0, 0.03, 0.2])
    expect = 1000.0 * STANDARD_GRAVITY * np.sin(np.arctan(g))
    assert np.array_equal(grade_force(1000.0, g), expect)
    assert [grade_force(1000.0, float(x)) for x in g] == expect.tolist()
    roll = [rolling_force(1000.0, float(x), 0.01, 0.001, 5.0) for x in g]
    assert roll == (0.015 * 1000.0 * STANDARD_GRAVITY * np.cos(np.arctan(g))).tolist()


def test_battery_levels_and_current() -> None:
    ideal = BatteryPack.constant("i", "ideal", 336.0, 8.5)
    assert float(ideal.current(3360.0, 0.7)) == pytest.approx(10.0)
    rint = BatteryPack.constant("r", "rint", 366.0, 8.5, 0.4)
    i = float(rint.current(20e3, 0.7))
    assert (366.0 - 0.4 * i) * i == pytest.approx(20e3)
    assert float(rint.soc_rate(8.5)) == pytest.approx(-1 / 3600)  # 1 C drains 1/h, eq (13)
    table = BatteryPack.from_directory(
        resolve_component("nimh_spiral_6ah_insight_prius_nimh6", "battery", Path("."), "b"),
        n_series=10, n_parallel=2,
    )  # fmt: skip
    assert table.capacity_ah == pytest.approx(12.0)
    r_dis = float(table.resistance(0.5, 1.0))
    r_chg = float(table.resistance(0.5, -1.0))
    assert r_dis > 0 and r_chg > 0
    assert float(table.ocv(0.9)) > float(table.ocv(0.1))


def test_one_ocv_lookup_gives_both_resistances_bit_for_bit() -> None:
    """pack_ocv_r_both (the forward loops' battery state: one OCV lookup) equals pack_ocv_r for
    a discharge and a charge current to the last bit, inside and outside the table axes."""
    pack = BatteryPack.from_directory(
        resolve_component("nimh_spiral_6ah_insight_prius_nimh6", "battery", Path("."), "b"),
        n_series=168, n_parallel=2, r_extra_ohm=0.05,
    )  # fmt: skip
    tab = pack.kernel_tables()
    assert tab.temperature_k.size > 1 and tab.soc.size > 2  # a 2-D table: both axes searched
    rng = np.random.default_rng(7)
    t_ax = tab.temperature_k
    socs = np.concatenate([rng.uniform(-0.2, 1.2, 300), tab.soc])
    temps = np.concatenate([rng.uniform(t_ax[0] - 20.0, t_ax[-1] + 20.0, 300), np.resize(t_ax, tab.soc.size)])
    for soc, temp in zip(socs, temps, strict=True):
        args = (float(soc), float(temp))
        ocv, r_dis, r_chg = pack_ocv_r_both(*args, 168.0, 2.0, 0.05, tab)
        ocv_d, r_d = pack_ocv_r(*args, 1.0, 168.0, 2.0, 0.05, tab)
        ocv_c, r_c = pack_ocv_r(*args, -1.0, 168.0, 2.0, 0.05, tab)
        assert (ocv, r_dis, r_chg) == (ocv_d, r_d, r_c) and ocv_c == ocv_d


def test_three_tables_on_one_bracket_equal_interp2_bit_for_bit() -> None:
    """interp2_three (the forward loops' battery lookup: OCV and both resistances inlined,
    one bracketing) equals interp2 table by table to the last bit, inside, outside (clamped)
    and on one-point axes; on bilinear data both reproduce the closed form a + bx + cy + dxy."""
    from hevsim.tables import interp2, interp2_three

    rng = np.random.default_rng(7)
    x = np.cumsum(rng.uniform(0.05, 0.3, 7))
    y = np.array([253.15, 278.15, 298.15, 318.15])
    gx, gy = np.meshgrid(x, y, indexing="ij")
    bilinear = 0.5 - 0.2 * gx + 1e-3 * gy + 0.03 * gx * gy
    tabs = [rng.normal(size=(7, 4)), bilinear, rng.uniform(0.01, 0.02, (7, 4))]
    pts = [(rng.uniform(x[0] - 0.2, x[-1] + 0.2), rng.uniform(240.0, 330.0)) for _ in range(300)]
    pts += [(x[0], y[0]), (x[-1], y[-1]), (x[3], y[2])]
    for xp, yp, fs in ((x, y, tabs), (x[:1], y, [t[:1] for t in tabs]), (x, y[:1], [t[:, :1] for t in tabs])):
        for linear in (False, True):
            for px, py in pts:
                got = interp2_three(xp, yp, fs[0], fs[1], fs[2], px, py, linear)
                want = tuple(interp2(xp, yp, f, px, py, linear) for f in fs)
                assert got == want, (px, py, linear, got, want)
    for px, py in pts:  # the closed form, inside the axes
        if x[0] <= px <= x[-1] and y[0] <= py <= y[-1]:
            exact = 0.5 - 0.2 * px + 1e-3 * py + 0.03 * px * py
            assert interp2_three(x, y, *tabs, px, py, False)[1] == pytest.approx(exact, rel=1e-13, abs=1e-13)
