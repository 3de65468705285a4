"""Plug-in hybrids (issue 25 item 3): the [plugin] section, charge depleting in the controllers,
the DP's depletion target, and the label's SAE J1711 / J2841 figures."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from hevsim.architectures import build_vehicle
from hevsim.cli import main
from hevsim.config import config_from_dict, is_plugin, load_vehicle_config
from hevsim.cycles import DriveCycle, load_cycle
from hevsim.errors import ConfigError
from hevsim.schema import read_toml
from hevsim.sim import label as L
from hevsim.sim import plugin_label as PL
from hevsim.sim.simulator import simulate
from hevsim.units import J_PER_WH, M_PER_MILE

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
PHEV = EXAMPLES / "phev_power_split.toml"

# FASTSim's tabulation of SAE J2841's fleet utility factor (NREL FASTSim, Apache-2.0,
# fastsim/resources/longparams.json, keys rechgFreqMiles / ufArray, in %): distance [mi] -> UF [%].
FASTSIM_FUF_PERCENT = {
    1: 2.455, 11: 24.401, 21: 41.188, 25: 46.652, 35: 57.771, 51: 69.897, 75: 80.476, 101: 86.716,
    151: 93.224, 201: 95.576,
}  # fmt: skip


def _data(path: Path = PHEV) -> dict:
    return read_toml(path)


def _cfg(changes: dict[str, dict]) -> object:
    data = _data()
    for sec, kv in changes.items():
        data[sec] = {**data.get(sec, {}), **kv}
    return config_from_dict(data, source="phev-test", base_dir=EXAMPLES)


@pytest.fixture(scope="module")
def phev():
    return build_vehicle(load_vehicle_config(PHEV))


def test_example_is_a_plugin_and_hybrids_default_to_charge_sustaining() -> None:
    cfg = load_vehicle_config(PHEV)
    assert is_plugin(cfg) and cfg.plugin.mode == "ev_first" and cfg.plugin.cs_soc == 0.3
    assert not is_plugin(load_vehicle_config(EXAMPLES / "prius_2016_like_power_split.toml"))


def test_fleet_utility_factor_matches_the_tabulated_j2841_curve() -> None:
    uf = PL.fleet_utility_factor()
    assert uf.norm_distance_mi == 399.0 and len(uf.coefficients) == 6
    for miles, percent in FASTSIM_FUF_PERCENT.items():
        assert float(uf(miles)) == pytest.approx(percent / 100.0, abs=0.0065), miles
    assert float(uf(0.0)) == 0.0
    assert np.all(np.diff(uf(np.linspace(0.0, 400.0, 401))) > 0.0)  # rises with the range
    with pytest.raises(ConfigError, match="distance"):
        uf(-1.0)


def test_uf_weighting_is_sae_j1711s_sum() -> None:
    uf = PL.fleet_utility_factor()
    d = 10.0 * M_PER_MILE
    runs = [
        PL.DepletingRun(0.9, 0.6, d, 0.0, 3.0e3 * J_PER_WH, None),  # 3 kWh DC, no fuel
        PL.DepletingRun(0.6, 0.3, d, 0.1, 2.0e3 * J_PER_WH, None),  # transition: 2 kWh, 0.1 kg fuel
    ]
    test = PL.DepletingTest("udds", 0.3, runs, 18.0 * M_PER_MILE, 2 * d)
    gal_per_kg = 0.35
    out = PL.uf_weighted(test, 0.02, lambda kg: gal_per_kg * kg, 0.8, uf)
    u10, u20 = float(uf(10.0)), float(uf(20.0))
    fuel = (u20 - u10) * 0.1 * gal_per_kg / 10.0 + (1.0 - u20) * 0.02
    elec = u10 * 3.0 / 0.8 / 10.0 + (u20 - u10) * 2.0 / 0.8 / 10.0
    assert out["fuel_gal_per_mi"] == pytest.approx(fuel, rel=1e-12)
    assert out["electricity_kwh_per_mi"] == pytest.approx(elec, rel=1e-12)
    assert out["uf_cdc"] == pytest.approx(u20, rel=1e-12)


def test_cd_range_on_repeated_udds_is_the_energy_bookkeeping_closed_form(phev) -> None:
    test = L.charge_depleting_test(phev, "udds")
    b = phev.config.battery
    usable_j = L.usable_energy_j(phev.battery, phev.config.plugin.cs_soc, b.soc_max)
    first = test.runs[0]
    closed_form_m = usable_j / first.dc_energy_j * first.distance_m  # usable energy / per-cycle DC energy
    assert abs(test.range_cda_m - closed_form_m) < first.distance_m  # within one cycle
    assert test.range_cda_m <= test.range_cdc_m <= test.range_cda_m + first.distance_m
    # the runs chain: each starts where the previous ended, from a full battery
    assert test.runs[0].soc_initial == pytest.approx(b.soc_max)
    for a, c in zip(test.runs, test.runs[1:], strict=False):
        assert c.soc_initial == pytest.approx(a.soc_final, abs=1e-12)
    # EV first: the depleting runs before the transition burn (almost) no fuel
    assert sum(r.fuel_kg for r in test.runs[:-1]) < 0.02 * test.runs[-1].distance_m / 1000.0


def test_plugin_label_figures(phev, tmp_path: Path) -> None:
    lab = L.label(phev)
    f = lab.figures
    assert lab.kind == "plug_in"
    r = f["charge_depleting_range_mi"]["actual_unadjusted"]
    assert 15.0 < r["city"] < 60.0 and 15.0 < r["highway"] < 60.0
    assert f["charge_depleting_range_mi"]["actual_adjusted"]["combined"] == pytest.approx(0.7 * r["combined"])
    # electricity from the wall = DC energy / charger efficiency over the actual range
    cd = L.charge_depleting_test(phev, "udds")
    kwh = cd.dc_energy_j / 0.86 / J_PER_WH / 1000.0 / (cd.range_cda_m / M_PER_MILE)
    assert f["charge_depleting_kwh_per_100mi"]["unadjusted"]["city"] == pytest.approx(100 * kwh, rel=1e-9)
    uf = f["uf_weighted"]
    for t in ("city", "highway", "combined"):
        assert uf["mpg"][t] > f["unadjusted_mpg"][t]  # weighting in electric miles raises mpg
    for t in ("city", "highway"):
        assert abs(lab.tests[t].balance) <= L.constants().soc_balance_tolerance
    out = lab.save(tmp_path / "label")
    assert "charge-depleting range" in (out / "label.txt").read_text()


def test_ev_first_blended_and_charge_sustaining_differ_in_cd(phev) -> None:
    cyc = load_cycle("udds")
    fuel = {}
    for mode in ("ev_first", "blended"):
        cfg = phev.config.replace(**{"plugin.mode": mode, "plugin.blended_engine_power_w": 8000.0})
        fuel[mode] = simulate(build_vehicle(cfg), cyc, soc_initial=0.9).metrics["fuel_kg"]["value"]
    cfg = phev.config.replace(**{"plugin.mode": "off", "optimization.final_soc": "sustain"})
    fuel["off"] = simulate(build_vehicle(cfg), cyc, soc_initial=0.9).metrics["fuel_kg"]["value"]
    assert fuel["ev_first"] < fuel["blended"]
    assert fuel["ev_first"] < 0.25 * fuel["off"]
    # ECMS: battery energy priced at 0 while depleting (EV first)
    ecms = simulate(phev, cyc, soc_initial=0.9, controller="ecms")
    assert ecms.metrics["fuel_kg"]["value"] < 0.25 * fuel["off"]


def test_dp_with_depletion_target_ends_at_cs_soc(phev) -> None:
    from hevsim.optimal.hev import optimize

    full = load_cycle("udds")
    n = 301
    cyc = DriveCycle(name="udds_300s", time_s=full.time_s[:n], speed_mps=full.speed_mps[:n])
    r = optimize(phev, cyc, soc_initial=0.33, soc_grid_points=61, input_grid_points=5, progress=False)
    soc = r.timeseries["soc"].to_numpy()
    tol = phev.config.optimization.soc_tolerance
    assert soc[0] == pytest.approx(0.33)
    assert abs(soc[-1] - phev.config.plugin.cs_soc) <= tol + 1e-9
    with pytest.raises(Exception, match="deplete"):
        plain = build_vehicle(load_vehicle_config(EXAMPLES / "prius_2016_like_power_split.toml"))
        optimize(plain, cyc, final_soc="deplete", soc_grid_points=21, input_grid_points=3, progress=False)


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        ({"plugin": {"cs_soc": 0.95}}, r"'plugin.cs_soc' = 0.95 lies outside the usable SOC window"),
        ({"plugin": {"cs_soc": 0.25}}, r"'plugin.cs_soc' = 0.25 lies outside"),
        ({"controller": {"soc_high": 0.5}}, r"'controller.soc_high' = 0.5 lies above 'plugin.cs_soc' = 0.3"),
        ({"plugin": {"mode": "sometimes"}}, r"plugin.mode"),
        ({"plugin": {"mode": "off"}}, r"'optimization.final_soc' = 'deplete' needs a plug-in hybrid"),
        ({"plugin": {"blended_engine_power_w": 5000.0}}, r"'plugin.blended_engine_power_w' does nothing"),
    ],
)
def test_bad_plugin_input_names_key_and_value(changes: dict, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        _cfg(changes)


def test_cli_exit_2_for_threshold_outside_window(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    text = PHEV.read_text().replace("cs_soc = 0.3 ", "cs_soc = 0.1 ")
    bad = tmp_path / "bad.toml"
    bad.write_text(text)
    assert main(["simulate", str(bad), "--out", str(tmp_path / "o"), "--no-plots"]) == 2
    err = capsys.readouterr().err
    assert "plugin.cs_soc" in err and "0.1" in err
    bev = tmp_path / "bev.toml"
    bev.write_text((EXAMPLES / "bev.toml").read_text() + '\n[plugin]\nmode = "ev_first"\n')
    assert main(["simulate", str(bev), "--out", str(tmp_path / "p"), "--no-plots"]) == 2
    assert "[plugin]" in capsys.readouterr().err


def test_series_blended_needs_a_power_rule() -> None:
    data = read_toml(EXAMPLES / "series_hev.toml")
    data["plugin"] = {"mode": "blended", "cs_soc": 0.75}
    data.setdefault("controller", {})
    with pytest.raises(ConfigError, match=r"'plugin\.mode' = 'blended' needs a controller with a power rule"):
        config_from_dict(data, source="series-phev", base_dir=EXAMPLES)


def test_plugin_dataclass_defaults_are_charge_sustaining() -> None:
    from hevsim.config import PluginSection

    assert PluginSection().mode == "off"
    assert {f.name for f in dataclasses.fields(PluginSection)} >= {"mode", "cs_soc", "charger_efficiency"}


def _hybrid(example: str, plugin: dict, controller: dict | None = None):
    data = read_toml(EXAMPLES / example)
    data["plugin"] = plugin
    if controller:
        data["controller"] = {**data["controller"], **controller}
    return build_vehicle(config_from_dict(data, source=example, base_dir=EXAMPLES))


@pytest.mark.parametrize("kind", ["electric_assist", "ecms", "aecms"])
def test_parallel_phev_depletes_first_then_sustains(kind: str) -> None:
    cs = 0.72  # the appendix's band 0.6..0.7 lies below it
    fuel, socs = {}, {}
    for mode in ("off", "ev_first", "blended"):
        plugin = {"mode": mode} if mode == "off" else {"mode": mode, "cs_soc": cs}
        if mode == "blended":
            plugin.update(blended_engine_power_w=5000.0, blended_equivalence_factor=2.0)
        r = simulate(_hybrid("parallel_hev.toml", plugin, {"kind": kind}), "udds", soc_initial=0.8)
        fuel[mode], socs[mode] = r.timeseries["fuel_kg"].to_numpy(), r.timeseries["soc"].to_numpy()
    assert socs["ev_first"].min() < cs  # it depleted to the threshold, then sustains
    k = int(np.flatnonzero(socs["ev_first"] <= cs)[0])  # the charge-depleting part of the EV-first run
    assert fuel["ev_first"][k] < fuel["blended"][k]  # blended starts the engine above 5 kW while depleting
    assert fuel["ev_first"][k] <= fuel["off"][k] * (1 + 1e-12) + 1e-12
    assert abs(socs["ev_first"][-1] - cs) < 0.15


def test_series_phev_thermostat_is_ev_first_and_ecms_blends() -> None:
    ev = _hybrid("series_hev.toml", {"mode": "ev_first", "cs_soc": 0.75})
    r = simulate(ev, "udds", soc_initial=0.9)
    soc = r.timeseries["soc"].to_numpy()
    fuel = r.timeseries["fuel_kg"].to_numpy()
    below = np.flatnonzero(soc < ev.config.controller.soc_low)
    start = int(below[0]) if below.size else soc.size - 1
    assert fuel[start] == 0.0  # no fuel before the SOC leaves the charge-depleting region and the band
    plugin = {"mode": "blended", "cs_soc": 0.75, "blended_equivalence_factor": 0.5}
    blended = _hybrid("series_hev.toml", plugin, {"kind": "ecms"})
    rb = simulate(blended, "udds", soc_initial=0.9)
    assert rb.metrics["soc_final"]["value"] < 0.9
