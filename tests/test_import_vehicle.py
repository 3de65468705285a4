"""``hevsim import-vehicle`` (issue 25 item 1): FASTSim vehicles become hevsim vehicles.

Independent references: FASTSim's road-load equation with FASTSim's own coefficients
(``simdrive_impl.rs``: drag 0.5 rho Cd A v^3 and rolling m g crr v with rho = 1.2 kg/m^3,
g = 9.81 m/s^2) and FASTSim's computed vehicle mass (fastsim itself when installed, else
``RustVehicle::set_veh_mass`` worked by hand for one database row).
"""

from __future__ import annotations

import tomllib
from importlib import resources
from pathlib import Path

import numpy as np
import pytest
import yaml

from hevsim.cli import main
from hevsim.config import load_vehicle_config
from hevsim.cycles import DriveCycle
from hevsim.vehicle_import import fastsim_test_mass_kg, read_vehicle

DATA = Path(str(resources.files("hevsim") / "data" / "vehicles" / "fastsim"))
VEHDB = DATA / "vehdb"
DB = DATA / "FASTSim_py_veh_db.csv"
RHO_FASTSIM, G_FASTSIM = 1.2, 9.81


def _import(tmp_path: Path, src: Path, *extra: str, name: str = "veh") -> Path:
    out = tmp_path / f"{name}.toml"
    assert main(["import-vehicle", str(src), *extra, "-o", str(out)]) == 0
    return out


def _fastsim_road_power_w(v: dict, mass_kg: float, speed_mps: np.ndarray) -> np.ndarray:
    """FASTSim's drag + rolling power at constant speed on level road [W]."""
    drag = 0.5 * RHO_FASTSIM * v["drag_coef"] * v["frontal_area_m2"] * speed_mps**3
    rolling = mass_kg * G_FASTSIM * v["wheel_rr_coef"] * speed_mps
    return drag + rolling


@pytest.mark.parametrize(
    ("src", "args", "arch"),
    [
        (VEHDB / "2012_Ford_Focus.yaml", (), "conventional"),
        (VEHDB / "2016_TOYOTA_Prius_Two.yaml", (), "parallel"),
        (VEHDB / "2021_Cupra_Born.csv", (), "bev"),
        (DB, ("--row", "1"), "conventional"),  # no veh_override_kg: FASTSim's mass rule
    ],
)
def test_constant_speed_road_load_is_fastsims(tmp_path: Path, src: Path, args: tuple, arch: str) -> None:
    from hevsim.config import load_vehicle_config
    from hevsim.sim.simulator import simulate

    out = _import(tmp_path, src, *args)
    cfg = load_vehicle_config(out)
    assert cfg.architecture == arch
    v = read_vehicle(src, int(args[1]) if args else None)
    mass = fastsim_test_mass_kg(v)
    assert cfg.body.mass_kg == pytest.approx(mass, rel=0, abs=1e-6)
    speed = 22.0
    t = np.arange(0.0, 31.0)
    res = simulate(cfg, DriveCycle("cruise", t, np.full(t.size, speed)), dt_s=1.0, tracking=None)
    f = res.timeseries["road_load_force_n"].to_numpy()[:-1]
    ref = _fastsim_road_power_w(v, mass, np.array(speed))
    assert np.allclose(f * speed, ref, rtol=1e-9, atol=0.0)


def test_masses_follow_fastsims_rule_by_hand() -> None:
    """Row 1 of the database (2016 Corolla, no override): set_veh_mass worked by hand."""
    v = read_vehicle(DB, row=1)
    assert v["veh_override_kg"] is None
    m = 1.4  # comp_mass_multiplier
    by_hand = 136.0 + 1045.636 + 114.0 * m + (98.0 / 2.13 + 61.0) * m + (441.0 / 9.89) * m
    assert fastsim_test_mass_kg(v) == pytest.approx(by_hand, rel=0, abs=1e-6)


def test_masses_equal_fastsims_own(tmp_path: Path) -> None:
    """fastsim (3, converting the fastsim-2 file) computes the same test mass, override removed."""
    fs = pytest.importorskip("fastsim")
    import warnings

    for name in (
        "2012_Ford_Fusion",
        "2016_TOYOTA_Prius_Two",
        "2010_Mazda_3_i-Stop",
        "2016_EU_VW_Golf_1.4TSI",
    ):
        d = yaml.safe_load((VEHDB / f"{name}.yaml").read_text())
        d["veh_override_kg"] = None
        f = tmp_path / f"{name}.yaml"
        f.write_text(yaml.safe_dump(d))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            theirs = fs.Vehicle.from_f2_file(str(f)).to_dict()["mass_kilograms"]
        out = _import(tmp_path, f, name=name)
        ours = tomllib.loads(out.read_text())["body"]["mass_kg"]
        assert ours == pytest.approx(theirs, rel=0, abs=1e-6), name


def test_list(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["import-vehicle", "--list", str(DB)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 71  # header + 70 vehicles
    assert any("2016 Toyota Prius Two FWD" in ln and "HEV" in ln for ln in lines)
    assert main(["import-vehicle", "--list", str(VEHDB / "2016_TOYOTA_Prius_Two.yaml")]) == 0
    assert "2016 Toyota Prius Two FWD" in capsys.readouterr().out


def test_name_selects_a_database_row(tmp_path: Path) -> None:
    out = _import(tmp_path, DB, "--name", "2016 Toyota Prius Two FWD")
    assert tomllib.loads(out.read_text())["powertrain"]["architecture"] == "parallel"


def _refused(capsys: pytest.CaptureFixture[str], *argv: str) -> str:
    assert main(["import-vehicle", *argv]) == 2
    return capsys.readouterr().err


def test_bad_input_exits_2_naming_file_key_value(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    d = yaml.safe_load((VEHDB / "2012_Ford_Focus.yaml").read_text())
    d["veh_pt_type"] = "Hovercraft"
    bad = tmp_path / "hover.yaml"
    bad.write_text(yaml.safe_dump(d))
    err = _refused(capsys, str(bad), "-o", str(tmp_path / "x.toml"))
    assert "hover.yaml" in err and "'veh_pt_type'" in err and "'Hovercraft'" in err
    assert not (tmp_path / "x.toml").exists()
    err = _refused(capsys, str(DB), "--row", "999", "-o", str(tmp_path / "x.toml"))
    assert "FASTSim_py_veh_db.csv" in err and "--row 999" in err and "1..70" in err
    notveh = tmp_path / "cycle.yaml"
    notveh.write_text("name: udds\ntime_s: [0, 1]\n")
    err = _refused(capsys, str(notveh), "-o", str(tmp_path / "x.toml"))
    assert "cycle.yaml" in err and "'veh_pt_type'" in err
    d = yaml.safe_load((VEHDB / "2012_Ford_Focus.yaml").read_text())
    d["warp_drive_kw"] = 5.0
    odd = tmp_path / "odd.yaml"
    odd.write_text(yaml.safe_dump(d))
    err = _refused(capsys, str(odd), "-o", str(tmp_path / "x.toml"))
    assert "odd.yaml" in err and "'warp_drive_kw'" in err


def test_phev_and_fuel_cell_import_as_plugin_parallel_and_fcev(tmp_path: Path) -> None:
    from hevsim.vehicle_import import hevsim_architecture, read_vehicle

    prime = _import(tmp_path, DB, "--name", "2017 Prius Prime", name="prime")
    cfg = load_vehicle_config(prime)
    assert cfg.architecture == "parallel" and cfg.plugin.mode == "blended"
    assert (
        cfg.plugin.charger_efficiency == 0.86 and cfg.plugin.blended_engine_power_w == 68000.0
    )  # chg_eff, kw
    assert cfg.battery.soc_min < cfg.plugin.cs_soc < cfg.battery.soc_max
    mirai = _import(tmp_path, DB, "--name", "Toyota Mirai", name="mirai")
    cfg = load_vehicle_config(mirai)
    assert cfg.architecture == "fcev" and cfg.fuel_cell.max_power_w == 114000.0
    assert cfg.fuel_cell.ramp_up_w_per_s == pytest.approx(114000.0 / 5.0)  # fc_max_kw / fc_sec_to_peak_pwr
    assert (tmp_path / "mirai_fuel_cell" / "efficiency.csv").is_file()
    assert hevsim_architecture(read_vehicle(DB, name="Toyota Mirai")) == "fcev"
    assert hevsim_architecture(read_vehicle(DB, name="2017 Prius Prime")) == "parallel"


def test_written_file_comments_the_approximations(tmp_path: Path) -> None:
    text = _import(tmp_path, VEHDB / "2016_TOYOTA_Prius_Two.yaml").read_text()
    for needle in (
        "Apache License 2.0",
        "veh_override_kg",
        "mph_fc_on",
        "kw_demand_fc_on",
        "aux_kw",
        "min_soc",
    ):
        assert needle in text
    eng = (tmp_path / "veh_engine" / "fuel_rate_map.csv").read_text().splitlines()
    assert eng[0] == "speed_rad_per_s,torque_N_m,fuel_rate_g_per_s"


def test_every_efficiency_map_point_is_fastsims_curve(tmp_path: Path) -> None:
    """The written engine map burns P / eff(P / P_max) / LHV at every grid point (FASTSim's curve),
    and, this being an HEV, at least FASTSim's idle fuel power ``idle_fc_kw`` (its fired engine's floor)."""
    from hevsim.fuels import get_fuel

    _import(tmp_path, VEHDB / "2016_TOYOTA_Prius_Two.yaml")
    t = np.genfromtxt(tmp_path / "veh_engine" / "fuel_rate_map.csv", delimiter=",", names=True)
    p = t["speed_rad_per_s"] * t["torque_N_m"]
    frac = np.minimum(p / 71e3, 1.0)
    x = [0.0, 0.005, 0.015, 0.04, 0.06, 0.1, 0.14, 0.2, 0.4, 0.6, 0.8, 1.0]
    e = [0.08, 0.1, 0.26, 0.33, 0.355, 0.37, 0.38, 0.38, 0.35, 0.34, 0.33, 0.32]
    lhv = get_fuel("gasoline").lower_heating_value_j_per_kg
    idle_w = 4.3e3  # the file's idle_fc_kw
    expected = np.maximum(np.where(p > 0, p / np.interp(frac, x, e), 0.0), idle_w) / lhv * 1e3
    assert np.allclose(t["fuel_rate_g_per_s"], expected, rtol=1e-12, atol=0.0)
    assert (t["fuel_rate_g_per_s"] > 0).all()  # the old map burned nothing at zero torque


def _single_vehicle_files() -> list[Path]:
    return sorted(p for p in VEHDB.iterdir() if p.suffix in (".yaml", ".csv"))


def test_every_vehdb_vehicle_simulates_udds(tmp_path: Path) -> None:
    from hevsim.sim.simulator import simulate

    files = _single_vehicle_files()
    assert len(files) == 47
    for i, src in enumerate(files):
        out = _import(tmp_path, src, name=f"v{i}")
        res = simulate(out, "udds", tracking=None)
        assert res.metrics["distance_mi"]["value"] > 7.0, src.name


def test_docs_table_lists_every_key() -> None:
    from hevsim.vehicle_import import VAL_KEYS, key_treatment

    doc = (Path(__file__).resolve().parents[1] / "docs" / "import_vehicle.md").read_text()
    table = key_treatment()
    assert set(VAL_KEYS) <= set(table)
    for key, (treatment, _) in table.items():
        if key not in VAL_KEYS:
            assert f"| `{key}` | {treatment} |" in doc, key


@pytest.mark.parametrize("name", ["2012_Ford_Fusion", "2016_TOYOTA_Prius_Two"])
def test_fastsim3_file_gives_the_vehicle_of_its_fastsim2_file(tmp_path: Path, name: str) -> None:
    """fastsim 3's YAML of a vehicle (its bundled resource, as fastsim 3.1 writes it) imports to
    the same hevsim vehicle and maps as the fastsim-2 file it was converted from."""
    f3 = _import(tmp_path, DATA / "fastsim3" / f"{name}.yaml", name="f3")
    f2 = _import(tmp_path, VEHDB / f"{name}.yaml", name="f2")
    a, b = tomllib.loads(f3.read_text()), tomllib.loads(f2.read_text())
    for sec in a:
        if isinstance(a[sec], dict):
            for key, val in a[sec].items():
                if key == "data":
                    continue
                if isinstance(val, str):
                    assert val == b[sec][key], f"{sec}.{key}"
                else:
                    assert val == pytest.approx(b[sec][key], rel=1e-12, abs=0.0), f"{sec}.{key}"
    fa, fb = (
        np.genfromtxt(tmp_path / f"{w}_engine" / "fuel_rate_map.csv", delimiter=",") for w in ("f3", "f2")
    )
    # fastsim 3.1 converting a fastsim-2 file drops `idle_fc_kw` (its Prius has pwr_idle_fuel_watts 0,
    # the fastsim-2 file 4.3 kW): the maps agree once the fastsim-2 file's idle-fuel floor (HEV) is applied
    from hevsim.fuels import get_fuel

    v2 = read_vehicle(VEHDB / f"{name}.yaml")
    hev = str(v2["veh_pt_type"]).strip() == "HEV"
    floor = float(v2["idle_fc_kw"]) * 1e6 / get_fuel("gasoline").lower_heating_value_j_per_kg if hev else 0.0
    assert np.array_equal(fa[:, :2], fb[:, :2], equal_nan=True)
    assert np.array_equal(np.maximum(fa[1:, 2], floor), fb[1:, 2])
    if (tmp_path / "f3_motor").is_dir():
        ma, mb = (
            np.genfromtxt(tmp_path / f"{w}_motor" / "efficiency_map.csv", delimiter=",") for w in ("f3", "f2")
        )
        # fastsim 3 replaces FASTSim-2's efficiency at zero power (a placeholder) by the next point's: the
        # maps agree from the curve's second point (2 % of the motor's power) on
        frac = np.abs(ma[1:, 0] * ma[1:, 1]) / (read_vehicle(VEHDB / f"{name}.yaml")["mc_max_kw"] * 1e3)
        keep = frac >= 0.02
        assert np.array_equal(ma[1:][keep], mb[1:][keep])


def test_fastsim3_bev_road_load_and_list(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from hevsim.sim.simulator import simulate

    src = DATA / "fastsim3" / "2022_Renault_Zoe_ZE50_R135.yaml"
    assert main(["import-vehicle", "--list", str(src)]) == 0
    assert "BEV" in capsys.readouterr().out
    out = _import(tmp_path, src)
    d = yaml.safe_load(src.read_text())
    ch, mass = d["chassis"], d["mass_kilograms"]
    speed = 25.0
    t = np.arange(0.0, 21.0)
    res = simulate(out, DriveCycle("cruise", t, np.full(t.size, speed)), dt_s=1.0, tracking=None)
    f = res.timeseries["road_load_force_n"].to_numpy()[:-1]
    ref = 0.5 * RHO_FASTSIM * ch["drag_coef"] * ch["frontal_area_square_meters"] * speed**3
    ref += mass * G_FASTSIM * ch["wheel_rr_coef"] * speed
    assert np.allclose(f * speed, ref, rtol=1e-9, atol=0.0)
    assert simulate(out, "udds", tracking=None).metrics["distance_mi"]["value"] > 7.0


def test_output_into_a_new_folder(tmp_path: Path) -> None:
    out = tmp_path / "new" / "folder" / "focus.toml"
    assert main(["import-vehicle", str(VEHDB / "2012_Ford_Focus.yaml"), "-o", str(out)]) == 0
    assert out.is_file() and (out.parent / "focus_engine" / "fuel_rate_map.csv").is_file()


def test_hev_carries_fastsims_engine_on_rules(tmp_path: Path) -> None:
    """Issue 25: an imported HEV's controller carries FASTSim's forced-on speed (``mph_fc_on``) and
    the engine's peak-efficiency power (``fc_max_kw`` x the power fraction of ``fc_eff_map``'s
    maximum), its engine map FASTSim's idle fuel; a conventional map has no idle floor."""
    from hevsim.fuels import get_fuel

    db = DATA / "FASTSim_py_veh_db.csv"
    out = _import(tmp_path, db, "--row", "10", name="optima")  # 2016 Kia Optima Hybrid
    ctl = tomllib.loads(out.read_text())["controller"]
    v = read_vehicle(db, row=10)
    assert ctl["kind"] == "electric_assist"
    assert ctl["engine_on_speed_mps"] == pytest.approx(float(v["mph_fc_on"]) * 0.44704, rel=1e-12)
    # the row's curve (fastsim-2's default power fractions): efficiency 0.40 first reached at 14 % of 119 kW
    assert float(v["fc_max_kw"]) == 119.0
    assert ctl["engine_min_power_w"] == pytest.approx(119e3 * 0.14, rel=1e-12)
    lhv = get_fuel("gasoline").lower_heating_value_j_per_kg
    eng = np.genfromtxt(tmp_path / "optima_engine" / "fuel_rate_map.csv", delimiter=",", names=True)
    zero = eng["torque_N_m"] == 0.0
    assert np.allclose(eng["fuel_rate_g_per_s"][zero], 2.38e6 / lhv, rtol=1e-12)  # idle_fc_kw = 2.38
    _import(tmp_path, db, "--row", "1", name="corolla")  # conventional: no floor
    conv = np.genfromtxt(tmp_path / "corolla_engine" / "fuel_rate_map.csv", delimiter=",", names=True)
    assert (conv["fuel_rate_g_per_s"][conv["torque_N_m"] == 0.0] == 0.0).all()
