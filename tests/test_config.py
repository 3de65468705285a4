"""One configuration model for every vehicle: shared sections, ranges with units, completeness,
layout and architecture errors, command-line options validated like files, and the shipped
examples' results unchanged by the move to the shared schema."""

from __future__ import annotations

import dataclasses
import math
import typing
from pathlib import Path
from typing import Any

import pytest

import hevsim.parallel
from hevsim import config as C
from hevsim import schema
from hevsim.cli import main
from hevsim.errors import ConfigError

ROOT = Path(__file__).resolve().parents[1]
SERIES = ROOT / "examples" / "series_hev.toml"
PARALLEL = ROOT / "examples" / "parallel_hev.toml"
CELL = ROOT / "examples" / "cell.toml"
EXAMPLES = {
    "series": SERIES,
    "parallel": PARALLEL,
    "conventional": ROOT / "examples" / "conventional_sedan.toml",
    "bev": ROOT / "examples" / "bev.toml",
    "power_split": ROOT / "examples" / "prius_like_power_split.toml",
    "fcev": ROOT / "examples" / "fcev.toml",
}
CONFIG_TYPES = {name: spec.config_type for name, spec in C.ARCHITECTURES.items()}
NUMERIC = (float, int)


def _is_numeric(tp: Any) -> bool:
    if typing.get_origin(tp) is tuple:
        return typing.get_args(tp)[0] in NUMERIC
    return tp in NUMERIC


def _section_types(cls: type) -> dict[str, type]:
    hints = typing.get_type_hints(cls)
    return {f.name: hints[f.name] for f in dataclasses.fields(cls) if dataclasses.is_dataclass(hints[f.name])}


def _numeric_fields() -> list[tuple[str, str, Any, dict[str, Any]]]:
    """(architecture, dotted key, type, metadata) of every numeric field, from the schema itself."""
    out = []
    for arch, cls in CONFIG_TYPES.items():
        for sec, sec_cls in _section_types(cls).items():
            hints = typing.get_type_hints(sec_cls)
            for f in dataclasses.fields(sec_cls):
                if _is_numeric(hints[f.name]):
                    out.append((arch, f"{sec}.{f.name}", hints[f.name], dict(f.metadata)))
    return out


NUMERIC_FIELDS = _numeric_fields()


def _with(arch: str, key: str, value: Any) -> dict[str, Any]:
    data = schema.read_toml(EXAMPLES[arch])
    sec, _, name = key.partition(".")
    data.setdefault(sec, {})[name] = value
    return data


# ---------------------------------------------------------------- one set of section types
def test_series_and_parallel_share_the_section_classes() -> None:
    s, p = _section_types(C.SeriesHEVConfig), _section_types(C.ParallelHEVConfig)
    shared = set(s) & set(p)
    assert shared >= {"powertrain", "body", "tire", "final_drive", "engine", "motor", "battery", "metrics"}
    for name in shared - {"optimization"}:
        assert s[name] is p[name], name
    # one [optimization] section type; the series' defaults are the charge-sustaining ones
    assert issubclass(s["optimization"], p["optimization"]) and p["optimization"] is C.OptimizationSection
    assert s["motor"] is s["generator"] is C.MachineSection
    assert p["final_drive"] is C.GearSection
    assert issubclass(p["motor_coupling"], C.GearSection)  # plus its position (P2 / P3)
    # the parallel module holds no section classes of its own any more
    for old in (
        "BodySection",
        "TireSection",
        "EngineSection",
        "BatterySection",
        "MetricsSection",
        "MotorSection",
    ):
        assert not hasattr(hevsim.parallel, old)
    assert hevsim.parallel.ParallelHEVConfig is C.ParallelHEVConfig


def test_torque_scale_is_kept_for_every_machine_model_in_both_builders() -> None:
    """One machine builder: an ideal or constant-efficiency machine keeps its torque_scale."""
    from hevsim.sim.model import build_series_hev

    for model in ("ideal", "constant_efficiency"):
        s = C.load_config(SERIES).replace(**{"motor.model": model, "motor.torque_scale": 2.0})
        p = hevsim.parallel.load_parallel_config(PARALLEL).replace(
            **{"motor.model": model, "motor.torque_scale": 2.0}
        )
        ms, mp = build_series_hev(s).traction_motor, hevsim.parallel.build_parallel_hev(p).motor
        assert ms.torque_scale == mp.torque_scale == 2.0
        assert ms.kind == mp.kind == model


# ---------------------------------------------------------------- ranges with units
def test_every_numeric_field_has_bounds_and_a_unit() -> None:
    missing = [key for _, key, _, meta in NUMERIC_FIELDS if "bounds" not in meta or "unit" not in meta]
    assert not missing, f"numeric fields without bounds/unit: {missing}"
    assert len(NUMERIC_FIELDS) > 60


def test_only_the_current_limits_allow_inf() -> None:
    allowed = {key for _, key, _, meta in NUMERIC_FIELDS if meta.get("allow_inf")}
    assert allowed == {"battery.max_discharge_current_a", "battery.max_charge_current_a"}
    cfg = C.config_from_dict(_with("parallel", "battery.max_charge_current_a", math.inf), "x.toml")
    assert cfg.battery.max_charge_current_a == math.inf


def _bad_values(tp: Any, meta: dict[str, Any]) -> list[Any]:
    lo, hi = meta["bounds"]
    item = typing.get_args(tp)[0] if typing.get_origin(tp) is tuple else tp
    bad: list[Any] = [lo - max(1, abs(lo))]
    if math.isfinite(hi):
        bad.append(hi + max(1, abs(hi)))
    if item is float:
        bad += [math.nan] + ([] if meta.get("allow_inf") else [math.inf, -math.inf])
    else:
        bad.append(1.5)  # not an integer
    if typing.get_origin(tp) is tuple:
        bad = [[v] for v in bad]
    return bad


@pytest.mark.parametrize(
    ("arch", "key", "tp", "meta"), NUMERIC_FIELDS, ids=[f"{a}:{k}" for a, k, _, _ in NUMERIC_FIELDS]
)
def test_each_bound_rejects_out_of_range_inf_and_nan(
    arch: str, key: str, tp: Any, meta: dict[str, Any]
) -> None:
    for value in _bad_values(tp, meta):
        with pytest.raises(ConfigError) as err:
            C.config_from_dict(_with(arch, key, value), "car.toml")
        assert f"car.toml: key '{key}'" in str(err.value), (value, str(err.value))


def test_out_of_range_message_gives_the_range_and_unit() -> None:
    with pytest.raises(ConfigError, match=r"key 'body.mass_kg' = -5.0 is out of range; expected a value "
                       r"between 1 and 1e\+06 kg\."):  # fmt: skip
        C.config_from_dict(_with("series", "body.mass_kg", -5.0), "car.toml")
    with pytest.raises(ConfigError, match=r"key 'body.drag_coefficient': value inf is not finite"):
        C.config_from_dict(_with("series", "body.drag_coefficient", math.inf), "car.toml")


def test_replace_validates_like_a_file() -> None:
    cfg = C.load_config(SERIES)
    with pytest.raises(ConfigError, match=r"motor\.torque_scale"):
        cfg.replace(**{"motor.torque_scale": -1.0})
    assert cfg.replace(**{"body.mass_kg": 1500.0}).body.mass_kg == 1500.0


# ---------------------------------------------------------------- command-line options
def _exit2(argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    assert main(argv) == 2
    return capsys.readouterr().err


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["simulate", str(SERIES), "--soc-initial", "1.5"],
         "--soc-initial = 1.5 is out of range; expected a value between 0 and 1"),
        (["simulate", str(SERIES), "--dt", "0"], "--dt = 0.0 is out of range"),
        (["simulate", str(SERIES), "--dt", "inf"], "--dt: value inf is not finite"),
        (["optimize", str(PARALLEL), "--soc-points", "0"], "--soc-points = 0 is out of range"),
        (["optimize", str(PARALLEL), "--input-points", "-3"], "--input-points = -3 is out of range"),
        (["optimize", str(SERIES), "--soc-initial", "-0.1"], "--soc-initial = -0.1 is out of range"),
        (["compare", str(SERIES), "--soc-points", "1"], "--soc-points = 1 is out of range"),
        (["calibrate", "thesis_table_4_1", "x.csv", "--fit", "c_heat_j_per_k=90,10,1000",
          "--soc-initial", "2"], "--soc-initial = 2.0 is out of range"),
        (["age", str(CELL), "--repetitions", "0"], "--repetitions = 0 is out of range"),
        (["age", str(CELL), "--rest-h", "-1"], "--rest-h = -1.0 is out of range"),
    ],
)  # fmt: skip
def test_cli_option_out_of_range_is_exit_2_naming_the_option(
    argv: list[str], needle: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    err = _exit2([*argv, "--out", str(tmp_path / "out")], capsys)
    assert needle in err


def test_simulate_on_a_parallel_config_refuses_a_genset_schedule(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Issue 11: the parallel HEV simulates forward; a series genset schedule is refused."""
    sched = tmp_path / "s.csv"
    sched.write_text("time_s,engine_speed_rpm,engine_throttle\n0,0,0\n")
    err = _exit2(["simulate", str(PARALLEL), "--schedule", str(sched), "--out", str(tmp_path / "o")], capsys)
    assert "parallel_hev.toml" in err and "--schedule" in err and "--controller" in err
    assert not (tmp_path / "o").exists()


# ---------------------------------------------------------------- completeness and presets
def test_empty_config_is_an_error_naming_powertrain(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    p = tmp_path / "empty.toml"
    p.write_text("")
    err = _exit2(["simulate", str(p), "--out", str(tmp_path / "o")], capsys)
    assert "empty.toml" in err and "[powertrain] is missing" in err
    assert "'series'" in err and "'parallel'" in err and "final_drive" in err


@pytest.mark.parametrize(
    ("arch", "sections"),
    [
        ("series", ["body", "tire", "final_drive", "motor", "battery", "engine", "generator"]),
        (
            "parallel",
            ["body", "tire", "final_drive", "gearbox", "engine", "motor", "motor_coupling", "battery"],
        ),
    ],
)
def test_missing_component_sections_are_all_listed(tmp_path: Path, arch: str, sections: list[str]) -> None:
    p = tmp_path / "car.toml"
    p.write_text(f'[powertrain]\narchitecture = "{arch}"\n[metrics]\nconversion_efficiency = 0.3\n')
    with pytest.raises(ConfigError) as err:
        C.load_vehicle_config(p)
    msg = str(err.value)
    assert "car.toml" in msg and "missing" in msg and 'preset = "defaults"' in msg
    for s in sections:
        assert f"[{s}]" in msg, s


def test_series_without_engine_genset_needs_no_engine(tmp_path: Path) -> None:
    data = schema.read_toml(SERIES)
    for s in ("engine", "generator"):
        del data[s]
    with pytest.raises(ConfigError, match=r"\[engine\], \[generator\]"):
        C.config_from_dict(dict(data), "car.toml")
    data["genset"] = {"kind": "none"}
    assert C.config_from_dict(data, "car.toml").genset.kind == "none"


def test_preset_defaults_and_tutorial_levels(tmp_path: Path) -> None:
    p = tmp_path / "toy.toml"
    p.write_text('preset = "defaults"\n[powertrain]\narchitecture = "series"\n')
    cfg = C.load_vehicle_config(p)
    assert cfg.body == C.BodySection() and cfg.preset == "defaults"
    p.write_text('preset = "tutorial_level_1"\n[motor]\nmax_torque_nm = 250.0\n')
    cfg = C.load_vehicle_config(p)
    assert cfg.architecture == "series" and cfg.genset.kind == "none"
    assert cfg.motor.max_torque_nm == 250.0 and cfg.body.rolling_resistance == 0.009
    assert cfg.name == "toy"
    p.write_text('preset = "tutorial_level_99"\n')
    with pytest.raises(ConfigError, match=r"key 'preset' = 'tutorial_level_99' is not known; expected one of "
                       r"defaults, tutorial_level_1, .*tutorial_level_8"):  # fmt: skip
        C.load_vehicle_config(p)


def test_refinement_levels_load() -> None:
    from hevsim.refinement import level_files

    files = level_files()
    assert len(files) == 8
    for f in files:
        assert C.load_config(f).architecture == "series"


# ---------------------------------------------------------------- layout and architecture
def test_old_series_layout_says_what_to_rename(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    text = SERIES.read_text()
    old = (text.replace("[final_drive]", "[gear]").replace("[motor]", "[traction_motor]")
           .replace('[powertrain]\narchitecture = "series"', ""))  # fmt: skip
    p = tmp_path / "old.toml"
    p.write_text(old)
    err = _exit2(["simulate", str(p), "--out", str(tmp_path / "o")], capsys)
    assert "old.toml: old configuration layout" in err
    assert "rename [gear] to [final_drive]" in err and "rename [traction_motor] to [motor]" in err
    assert 'add [powertrain] architecture = "series"' in err


def test_old_parallel_layout_says_what_to_move(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    text = PARALLEL.read_text()
    text = text.replace('[powertrain]\narchitecture = "parallel"', "")
    i = text.index("[motor_coupling]")
    text = text[:i] + text[text.index("\n\n", i) + 2 :]
    text = text.replace("[motor]", "[motor]\ncoupling_ratio = 1.0\ncoupling_efficiency = 1.0", 1)
    p = tmp_path / "old.toml"
    p.write_text('architecture = "parallel"\n' + text)
    err = _exit2(["optimize", str(p), "--out", str(tmp_path / "o")], capsys)
    assert "move the top-level key 'architecture' = 'parallel' into a [powertrain] section" in err
    assert "move 'motor.coupling_ratio' to [motor_coupling] ratio" in err


def test_unknown_architecture_lists_the_valid_names(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    p = tmp_path / "x.toml"
    p.write_text(SERIES.read_text().replace('architecture = "series"', 'architecture = "planetary"'))
    err = _exit2(["optimize", str(p), "--out", str(tmp_path / "o")], capsys)
    assert "key 'powertrain.architecture' = 'planetary' is not known; expected one of series, parallel" in err


def test_registry_builds_each_architecture() -> None:
    from hevsim.architectures import build_vehicle
    from hevsim.sim.model import SeriesHEV

    assert isinstance(build_vehicle(C.load_config(SERIES)), SeriesHEV)
    assert isinstance(build_vehicle(C.load_vehicle_config(PARALLEL)), hevsim.parallel.ParallelHEV)
    with pytest.raises(ConfigError, match="not a vehicle configuration"):
        build_vehicle(42)


def test_cell_files_use_celsius_and_reject_kelvin_keys(tmp_path: Path) -> None:
    from hevsim.battery.config import load_config as load_cell_config

    cfg = load_cell_config(ROOT / "examples" / "cell.toml")
    assert cfg.cell.temp_c == 23.0 and cfg.cell.temp_k == pytest.approx(296.15, abs=1e-12)
    p = tmp_path / "cell.toml"
    p.write_text("[cell]\ntemp_k = 296.15\n")
    with pytest.raises(
        ConfigError, match=r"cell.toml: key 'cell.temp_k' = 296.15: .* rename it to 'cell.temp_c'"
    ):
        load_cell_config(p)
    p.write_text("[thermal]\nport_temp_c = 900.0\n")
    with pytest.raises(ConfigError, match=r"key 'thermal.port_temp_c' = 900.0 is out of range.* degC"):
        load_cell_config(p)


# ---------------------------------------------------------------- shipped results unchanged
# Recorded with the code before the shared schema (commit 2a56d0c), same calls; 1e-9 relative.
SERIES_SIMULATE_UDDS = {"mpg": 64.83029227728271, "mpgge": 47.66257659054117,
                        "soc_final": 0.6136785338175018, "fuel_kg": 0.3633555775289579,
                        "speed_error_rms_mph": 0.3954560391609103}  # fmt: skip
PARALLEL_DP_UDDS300 = {"mpg": 55.786984524543506, "mpgge": 35.28365127000089,
                       "soc_final": 0.7000214341265454, "fuel_kg": 0.13542070363021874}  # fmt: skip
SERIES_DP_UDDS300 = {"mpg": 46.64681787067524, "mpgge": 39.3039513019036,
                     "soc_final": 0.6950614244481206, "fuel_kg": 0.16195558545208105}  # fmt: skip


def test_series_example_simulation_unchanged() -> None:
    from hevsim.sim.simulator import simulate

    r = simulate(C.load_config(SERIES), "udds")
    for key, value in SERIES_SIMULATE_UDDS.items():
        assert r.value(key) == pytest.approx(value, rel=1e-9, abs=0.0), key


@pytest.mark.parametrize(("path", "grid", "expected"), [(PARALLEL, (101, 51), PARALLEL_DP_UDDS300),
                                                        (SERIES, (41, 21), SERIES_DP_UDDS300)])  # fmt: skip
def test_example_dp_optimum_unchanged(path: Path, grid: tuple[int, int], expected: dict[str, float]) -> None:
    from hevsim.cycles import load_cycle
    from hevsim.optimal.hev import optimize

    cyc = load_cycle("udds").truncated(300.0)
    res = optimize(path, cyc, soc_grid_points=grid[0], input_grid_points=grid[1], progress=False)
    for key, value in expected.items():
        assert res.value(key) == pytest.approx(value, rel=1e-9, abs=0.0), key
