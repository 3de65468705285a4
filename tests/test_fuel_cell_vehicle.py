"""Fuel-cell vehicles (issue 25 item 3): the fcev architecture, its load follower, hydrogen and MPGe."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hevsim.architectures import ARCHITECTURES, build_vehicle
from hevsim.cli import main
from hevsim.components.fuel_cell import HYDROGEN_LHV_J_PER_KG, FuelCellSystem
from hevsim.config import config_from_dict, load_vehicle_config
from hevsim.errors import ConfigError
from hevsim.schema import read_toml
from hevsim.sim import label as L
from hevsim.sim.simulator import simulate
from hevsim.units import M_PER_MILE

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
FCEV = EXAMPLES / "fcev.toml"


@pytest.fixture(scope="module")
def fcev():
    return build_vehicle(load_vehicle_config(FCEV))


@pytest.fixture(scope="module")
def udds(fcev):
    return simulate(fcev, "udds")


def test_registered_with_its_controllers() -> None:
    arch = ARCHITECTURES["fcev"]
    assert arch.controllers == ("load_follower", "ecms", "aecms")  # DP and ECMS: test_fcev_energy_management
    assert arch.controls == ("fuel_cell_power_w",)


def test_efficiency_map_is_fastsims_h2fc_and_hydrogen_rate_is_p_over_eta_lhv(fcev) -> None:
    fc = fcev.fuel_cell
    assert fc.lhv_j_per_kg == HYDROGEN_LHV_J_PER_KG == 120e6
    # FASTSim's H2FC curve: 60 % at 20 % of the rating, 54 % at the rating
    assert float(fc.efficiency(0.2 * fc.max_power_w)) == pytest.approx(0.60)
    assert float(fc.efficiency(fc.max_power_w)) == pytest.approx(0.54)
    p = np.array([5e3, 30e3, 90e3])
    assert np.allclose(fc.hydrogen_rate_kgps(p), p / (fc.efficiency(p) * 120e6), rtol=1e-15)


def test_hydrogen_mass_times_lhv_is_fuel_cell_energy_over_efficiency(udds) -> None:
    ts = udds.timeseries
    dt = float(np.diff(ts["time_s"].to_numpy())[0])
    p = ts["fuel_cell_power_w"].to_numpy()[:-1]
    eta = ts["fuel_cell_efficiency"].to_numpy()[:-1]
    kg = float(udds.metrics["fuel_kg"]["value"])
    assert kg > 0.0
    assert kg * HYDROGEN_LHV_J_PER_KG == pytest.approx(float(np.sum(p / eta) * dt), rel=1e-12)
    assert udds.energy_audit["fuel"] == pytest.approx(kg * HYDROGEN_LHV_J_PER_KG, rel=1e-12)
    assert udds.energy_audit["fuel_cell_loss"] == pytest.approx(float(np.sum(p / eta - p) * dt), rel=1e-12)


def test_energy_audit_closes(udds) -> None:
    a = udds.energy_audit
    sources = a["fuel"] + abs(a["battery_chemical"])
    assert abs(a["residual"]) / sources < 1e-9
    assert udds.metrics["traction_limited_s"]["value"] == 0.0


def test_ramp_and_power_limits_hold_every_step(fcev, udds) -> None:
    fc = fcev.fuel_cell
    p = udds.timeseries["fuel_cell_power_w"].to_numpy()[:-1]
    dt = float(np.diff(udds.timeseries["time_s"].to_numpy())[0])
    prev = np.concatenate(([fcev.config.fuel_cell.initial_power_w], p[:-1]))
    dp = p - prev
    assert np.all(dp <= fc.ramp_up_w_per_s * dt * (1 + 1e-12))
    assert np.all(-dp <= fc.ramp_down_w_per_s * dt * (1 + 1e-12))
    assert np.all(p >= fc.min_power_w * (1 - 1e-12)) and np.all(p <= fc.max_power_w * (1 + 1e-12))
    assert dp.max() > 0.5 * fc.ramp_up_w_per_s * dt  # the load follower does reach its ramp


def test_slow_ramp_binds_and_still_holds(fcev) -> None:
    cfg = fcev.config.replace(**{"fuel_cell.ramp_up_w_per_s": 500.0, "fuel_cell.ramp_down_w_per_s": 500.0})
    res = simulate(build_vehicle(cfg), "udds")
    p = res.timeseries["fuel_cell_power_w"].to_numpy()[:-1]
    prev = np.concatenate(([cfg.fuel_cell.initial_power_w], p[:-1]))
    assert np.max(np.abs(p - prev)) <= 500.0 * (1 + 1e-12)
    assert np.max(np.abs(p - prev)) == pytest.approx(500.0)  # it binds
    a = res.energy_audit
    assert abs(a["residual"]) / (a["fuel"] + abs(a["battery_chemical"])) < 1e-9


def test_mpge_is_miles_per_kg_plus_battery_energy(udds) -> None:
    m = udds.metrics
    miles = m["distance_m"]["value"] / M_PER_MILE
    gge = m["hydrogen_kg"]["value"] + m["battery_energy_wh"]["value"] / 1000.0 / 33.705
    assert m["mpge"]["value"] == pytest.approx(miles / gge, rel=1e-12)
    assert m["mpg"]["value"] == pytest.approx(
        miles / m["hydrogen_kg"]["value"], rel=1e-9
    )  # 1 kg = 1 "gallon"


def test_label_is_soc_balanced_mpge(fcev) -> None:
    lab = L.label(fcev)
    assert lab.kind == "fuel_cell"
    f = lab.figures
    for t in ("city", "highway"):
        test = lab.tests[t]
        assert abs(test.balance) <= L.constants().soc_balance_tolerance
        assert f["unadjusted_mpge"][t] == pytest.approx(test.distance_m / M_PER_MILE / test.fuel_kg, rel=1e-9)
    assert 40.0 < f["adjusted_mpge"]["combined"] < 120.0
    assert "MPGe" in lab.text()


def _data(**sections: dict) -> dict:
    data = read_toml(FCEV)
    for sec, kv in sections.items():
        data[sec] = {**data.get(sec, {}), **kv}
    return data


@pytest.mark.parametrize(
    ("sections", "match"),
    [
        ({"fuel_cell": {"min_power_w": 200000.0}}, r"'fuel_cell.min_power_w' = 200000.0 must be below"),
        ({"fuel_cell": {"ramp_up_w_per_s": -1.0}}, r"fuel_cell.ramp_up_w_per_s"),
        ({"fuel_cell": {"data": "no_such_stack"}}, r"'fuel_cell.data' = 'no_such_stack'"),
        ({"controller": {"kind": "direct"}}, r"'controller.kind' = 'direct' is not defined for the fcev"),
        ({"plugin": {"mode": "ev_first"}}, r"\[plugin\]"),
    ],
)
def test_bad_input_names_key_and_value(sections: dict, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        build_vehicle(config_from_dict(_data(**sections), source="fcev-test", base_dir=EXAMPLES))


def test_bad_efficiency_map_is_refused(tmp_path: Path) -> None:
    folder = tmp_path / "stack"
    folder.mkdir()
    (folder / "efficiency.csv").write_text("net_power_fraction,efficiency\n0,0.1\n0.5,1.4\n1,0.5\n")
    with pytest.raises(ConfigError, match=r"column 'efficiency' holds 1.4"):
        FuelCellSystem.from_directory(folder, max_power_w=1e5, min_power_w=0.0, ramp_up_w_per_s=1.0,
                                      ramp_down_w_per_s=1.0)  # fmt: skip


def test_cli_simulate_prints_mpge_and_exit_2_on_bad_input(tmp_path: Path, capsys) -> None:
    assert main(["simulate", str(FCEV), "--out", str(tmp_path / "o"), "--no-plots"]) == 0
    out = capsys.readouterr().out
    assert "mpge" in out and "hydrogen_kg" in out
    bad = tmp_path / "bad.toml"
    bad.write_text(FCEV.read_text().replace("max_power_w = 114000.0", "max_power_w = 1000.0"))
    assert main(["simulate", str(bad), "--out", str(tmp_path / "b"), "--no-plots"]) == 2
    assert "fuel_cell.min_power_w" in capsys.readouterr().err


def test_gallon_equivalent_constant_is_the_labels() -> None:
    from hevsim.units import KWH_PER_GALLON_EQUIVALENT

    assert KWH_PER_GALLON_EQUIVALENT == L.constants().kwh_per_gallon_equivalent


def test_performance_envelope_spans_the_fuel_cell(fcev) -> None:
    from hevsim.sim.performance import performance

    res = performance(fcev)
    row = res.table[res.table["test"] == "0-60 mph"].iloc[0]
    # FASTSim's database gives the Mirai 9 s (val0_to60_mph); the fuel cell and the battery add up
    assert 7.5 < float(row["value"]) < 10.5
