"""Road load as coast-down coefficients A, B, C and an equivalent test weight (issue 25 item 4).

Every architecture (and the DP) takes its body through
:meth:`hevsim.components.body.VehicleBody.from_section`, so a vehicle file in the coast-down
form must reproduce F = A + B v + C v^2 (the EPA's target road load, independent closed form)
at constant speed and while coasting down, to 1e-9 relative.
"""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest

from hevsim.components.body import VehicleBody
from hevsim.config import config_from_dict
from hevsim.cycles import DriveCycle
from hevsim.errors import ConfigError

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
A_N, B_N_PER_M_S, C_N_PER_M2_S2, TEST_MASS_KG = 130.0, 2.5, 0.42, 1600.0
"""Mid-size sedan coast-down targets (the order of the EPA Test Car List's) [N, N/(m/s), N/(m/s)^2, kg]."""
VEHICLES = {
    "series": "series_hev.toml",
    "parallel": "parallel_hev.toml",
    "power_split": "prius_2016_like_power_split.toml",
    "conventional": "conventional_sedan.toml",
    "bev": "bev.toml",
}
PHYSICAL = ("mass_kg", "drag_coefficient", "frontal_area_m2", "rolling_resistance")


def _road_load(v: np.ndarray) -> np.ndarray:
    return A_N + B_N_PER_M_S * v + C_N_PER_M2_S2 * v * v


def _coastdown_config(arch: str):
    data = tomllib.loads((EXAMPLES / VEHICLES[arch]).read_text())
    body = {k: v for k, v in data["body"].items() if k not in PHYSICAL}
    body.update(
        road_load_a_n=A_N,
        road_load_b_n_per_m_s=B_N_PER_M_S,
        road_load_c_n_per_m2_s2=C_N_PER_M2_S2,
        test_mass_kg=TEST_MASS_KG,
    )
    data["body"] = body
    return config_from_dict(data, f"{VEHICLES[arch]} (coast-down form)", EXAMPLES)


def _simulate(cfg, cycle: DriveCycle):
    from hevsim.sim.simulator import simulate

    return simulate(cfg, cycle, dt_s=1.0, tracking=None)


def _coastdown_trace(v0: float, m_eff: float, n: int, dt: float) -> np.ndarray:
    """Speeds [m/s] of a coast-down with no traction: each 1-s step solves
    m_eff (v1 - v0) / dt + A + B u + C u^2 = 0 with u = (v0 + v1) / 2 (the simulators' mid-step road load)."""
    v = [v0]
    for _ in range(n):
        b, c = B_N_PER_M_S + 2.0 * m_eff / dt, A_N - 2.0 * m_eff * v[-1] / dt
        u = (-b + np.sqrt(b * b - 4.0 * C_N_PER_M2_S2 * c)) / (2.0 * C_N_PER_M2_S2)
        v.append(2.0 * u - v[-1])
    return np.array(v)


@pytest.mark.parametrize("arch", [a for a in VEHICLES if a != "series"])
def test_constant_speed_and_coastdown_reproduce_a_b_c(arch: str) -> None:
    cfg = _coastdown_config(arch)
    body = VehicleBody.from_section(cfg.body)
    assert body.mass_kg == TEST_MASS_KG
    m_eff = body.mass_kg * body.mass_factor
    t = np.arange(0.0, 41.0)
    coast = _coastdown_trace(25.0, m_eff, t.size - 1, 1.0)
    assert coast[-1] > 10.0
    for coasting, v_trace in ((False, np.full(t.size, 20.0)), (True, coast)):  # cruise, coast-down
        res = _simulate(cfg, DriveCycle("abc", t, v_trace))
        ts = res.timeseries
        v_mid = 0.5 * (v_trace[1:] + v_trace[:-1])
        f = ts["road_load_force_n"].to_numpy()[: v_mid.size]  # row k: step k to k + 1
        assert np.allclose(f, _road_load(v_mid), rtol=1e-9, atol=0.0), arch
        if coasting:  # no traction: the wheel force is zero to 1e-9 of the road load
            wheel = ts["wheel_force_n"].to_numpy()[: v_mid.size]
            assert np.all(np.abs(wheel) <= 1e-9 * f), arch


def test_series_kernel_coasts_down_with_a_b_c() -> None:
    """The series HEV's forward kernel (a driver, not a trace): its vehicle step with no
    traction and no brake decelerates at exactly (A + B v + C v^2) / (delta m)."""
    from hevsim.sim import kernel as K
    from hevsim.sim.model import build_series_hev as build_model

    hev = build_model(_coastdown_config("series"))
    p = hev.param_vector()
    m_eff = TEST_MASS_KG * hev.body.mass_factor
    for v in (3.0, 12.0, 31.0):
        a = K.vehicle_step(p, v, 0.0, 0.0, 0.0, m_eff, 0.1)[0]
        assert -a * m_eff == pytest.approx(_road_load(np.array(v)), rel=1e-9)
    res = _simulate(
        _coastdown_config("series"), DriveCycle("cruise", np.arange(0.0, 31.0), np.full(31, 15.0))
    )
    ts = res.timeseries
    assert np.allclose(ts["road_load_force_n"].to_numpy()[5:], _road_load(ts["speed_mps"].to_numpy()[5:]),
                       rtol=1e-9, atol=0.0)  # fmt: skip


@pytest.mark.parametrize("arch", ["series", "parallel", "power_split"])
def test_dp_takes_the_coastdown_road_load(arch: str) -> None:
    from hevsim.components.flow import CycleSteps
    from hevsim.optimal import optimize

    cfg = _coastdown_config(arch)
    t = np.arange(0.0, 41.0)
    cycle = DriveCycle("abc", t, np.concatenate([np.linspace(0.0, 15.0, 31), np.full(10, 15.0)]))
    res = optimize(cfg, cycle, soc_grid_points=21, input_grid_points=21, progress=False)
    assert res.model.body == VehicleBody.from_section(cfg.body)
    assert res.model.body.mass_kg == TEST_MASS_KG
    steps = CycleSteps.from_cycle(cycle, res.model.body, res.model.tire)
    cruise = steps.accel_mps2 == 0.0
    assert cruise.sum() >= 9
    assert np.allclose(steps.force_n[cruise], _road_load(steps.v_mid_mps[cruise]), rtol=1e-9, atol=0.0)
    assert np.isfinite(res.timeseries["soc"].to_numpy()).all()


def _raw(arch: str) -> dict:
    return tomllib.loads((EXAMPLES / VEHICLES[arch]).read_text())


def test_mixing_the_two_forms_names_the_keys() -> None:
    data = _raw("conventional")
    data["body"]["road_load_a_n"] = A_N
    with pytest.raises(ConfigError, match=r"'body.mass_kg'.*'body.road_load_a_n'.*mix"):
        config_from_dict(data, "mixed.toml", EXAMPLES)


def test_partial_coastdown_form_names_the_missing_keys() -> None:
    data = _raw("bev")
    data["body"] = {"road_load_a_n": A_N, "road_load_c_n_per_m2_s2": C_N_PER_M2_S2}
    with pytest.raises(ConfigError, match=r"partial.toml.*'body.road_load_b_n_per_m_s', 'body.test_mass_kg'"):
        config_from_dict(data, "partial.toml", EXAMPLES)


def test_cli_refuses_mixed_forms_with_exit_2(tmp_path: Path) -> None:
    from hevsim.cli import main

    text = (EXAMPLES / VEHICLES["bev"]).read_text().replace("[body]\n", "[body]\ntest_mass_kg = 1500.0\n", 1)
    f = tmp_path / "mixed.toml"
    f.write_text(text)
    assert main(["simulate", str(f)]) == 2
