"""The capability matrix (issue 24 item 3): one short case per working cell, one refusal per
cell that is not meaningful, and the generated page.

The matrix is :func:`hevsim.capabilities.matrix` (derived from the architecture registry and
the file schema). Every *works* cell runs the first :data:`SECONDS` s of UDDS with the shipped
example of its architecture (``examples/*.toml``, found by ``[powertrain] architecture`` and
topology) through the public API or the CLI, and checks an invariant that can fail: finite
results, the vehicle's energy audit closing, the SOC inside its window, the pack's energy
balance, the DP replay giving the DP's fuel, the derating holding the BMS limit. Every *n/a*
cell is refused with exit 2 and a message naming the file, key and value and the reason.
A capability without a case here, a new gap (*missing*) or a stale docs/simulate.md fails.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import math
import tomllib
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import hevsim
from hevsim.capabilities import MISSING, NOT_MEANINGFUL, WORKS, Row, capabilities, markdown, rows, update_docs
from hevsim.cli import main
from hevsim.config import load_vehicle_config
from hevsim.cycles import DriveCycle, load_cycle

ROOT = Path(__file__).resolve().parents[1]
EX = ROOT / "examples"
SECONDS = 80.0
AUDIT_PCT = 1e-6  # energy-audit residual [% of traction energy]: round-off only

ROWS = {r.key: r for r in rows()}
CAPS = {c.key: c for c in capabilities()}
CELLS = [(r, c, c.status(ROWS[r])) for r in ROWS for c in CAPS.values()]

KNOWN_GAPS: set[tuple[str, str]] = set()
"""Cells meaningful but not working today (listed in the issue's closing note; a new gap adds a
line, a fix removes it). None left since the cell battery on every architecture."""


def _cycle() -> DriveCycle:
    c = load_cycle("udds")
    keep = np.asarray(c.time_s) <= SECONDS
    return DriveCycle(f"udds_{SECONDS:g}s", np.asarray(c.time_s)[keep], np.asarray(c.speed_mps)[keep],
                      np.asarray(c.grade)[keep])  # fmt: skip


CYCLE = _cycle()


def _examples() -> dict[tuple[str, bool], Path]:
    """(row key, pack?) -> the first shipped example of that architecture and topology."""
    out: dict[tuple[str, bool], Path] = {}
    for path in sorted(EX.glob("*.toml")):
        data = tomllib.loads(path.read_text(encoding="utf-8"))
        arch = data.get("powertrain", {}).get("architecture")
        if arch is None or data.get("plugin", {}).get("mode", "off") != "off":
            continue  # not a vehicle; a plug-in hybrid (its DP depletes: tests/test_plugin_hybrid.py)
        for row in ROWS.values():
            wanted = dict(row.overrides)
            got = {k: data.get(k.partition(".")[0], {}).get(k.partition(".")[2]) for k in wanted}
            defaults = {k: _schema_default(row, k) for k in wanted}
            if row.name == arch and all((got[k] or defaults[k]) == v for k, v in wanted.items()):
                out.setdefault((row.key, data.get("battery", {}).get("model") == "pack"), path)
    return out


def _schema_default(row: Row, key: str) -> Any:
    section, _, name = key.partition(".")
    from hevsim.config import ARCHITECTURES

    return getattr(getattr(ARCHITECTURES[row.name].config_type(), section), name)


EXAMPLES = _examples()


def base(row: str) -> Path:
    return EXAMPLES[(row, False)]


def pack(row: str) -> Path:
    path = EXAMPLES.get((row, True))
    assert path is not None, f"no shipped example of {row} with [battery] model = 'pack'"
    return path


def check(res: Any, soc_window: tuple[float, float] | None = None) -> None:
    """The invariants every run keeps: finite metrics and series, the energy audit closing,
    the SOC inside [0, 1] (and the battery window when given)."""
    assert all(math.isfinite(v) for v in res.energy_audit.values()), res.energy_audit
    assert abs(res.metrics["energy_audit_residual_pct"]["value"]) < AUDIT_PCT
    ts = res.timeseries
    assert len(ts) >= SECONDS / 1.0
    if "soc" in ts:
        soc = ts["soc"].to_numpy()
        assert np.all((soc >= 0) & (soc <= 1))
        if soc_window is not None:
            assert soc_window[0] - 1e-6 <= soc[0] <= soc_window[1] + 1e-6


def check_pack(res: Any) -> None:
    check(res)
    e = res.extra["pack_energy"]
    assert e["throughput_j"] > 0.0
    assert abs(e["residual_relative"]) < 1e-9


# ------------------------------------------------------------------------------------------
# the cases of the working cells
# ------------------------------------------------------------------------------------------
_DP: dict[str, Any] = {}


def dp(row: str) -> Any:
    """One small DP per row (cached for the module)."""
    if row not in _DP:
        from hevsim.optimal.hev import optimize

        _DP[row] = optimize(
            base(row), CYCLE, soc_grid_points=21, input_grid_points=21, progress=False, threads=1
        )
    return _DP[row]


def case_rule_based(row: str, tmp: Path) -> None:
    res = hevsim.simulate(base(row), CYCLE)
    check(res)
    from hevsim.config import ARCHITECTURES

    assert res.metadata.get("controller", "thermostat") == ARCHITECTURES[ROWS[row].name].controllers[0]


def case_ecms_dp(row: str, tmp: Path) -> None:
    from hevsim.control.parallel import ecms_from_dp

    s = ecms_from_dp(dp(row))
    res = hevsim.simulate(base(row), CYCLE, controller="ecms", **s)
    check(res)
    assert res.metadata["controller"] == "ecms"
    assert s["equivalence_factor"] > 0.0


def case_aecms(row: str, tmp: Path) -> None:
    res = hevsim.simulate(base(row), CYCLE, controller="aecms")
    check(res)
    assert res.metadata["controller"] == "aecms"
    assert math.isfinite(res.metadata["equivalence_factor_final"])


def case_dp(row: str, tmp: Path) -> None:
    r = dp(row)
    cfg = load_vehicle_config(base(row))
    assert r.value("fuel_kg") >= 0.0 and math.isfinite(r.value("fuel_kg"))
    assert cfg.battery.soc_min - 1e-9 <= r.value("soc_final") <= cfg.battery.soc_max + 1e-9


def case_dp_replay(row: str, tmp: Path) -> None:
    from hevsim.control.parallel import ControlSchedule

    r = dp(row)
    soc0 = float(r.timeseries["soc"].iloc[0])
    res = hevsim.simulate(base(row), CYCLE, soc_initial=soc0, controller=ControlSchedule.from_optimization(r))
    check(res)
    assert res.value("fuel_kg") == pytest.approx(r.value("fuel_kg"), rel=1e-9, abs=1e-12)  # the DP's fuel


def case_performance(row: str, tmp: Path) -> None:
    from hevsim.sim.performance import performance

    res = performance(base(row), dt_s=0.5)
    top = res.value("top speed")
    assert 20.0 < top < 400.0  # km/h or mph: a road vehicle
    assert res.value("0-60 mph") > 0.0


def case_battery_tables(row: str, tmp: Path) -> None:
    cfg = load_vehicle_config(base(row))
    fuel = []
    for model in ("ideal", "rint", "table"):
        res = hevsim.simulate(cfg.replace(**{"battery.model": model}), CYCLE)
        check(res, (cfg.battery.soc_min, cfg.battery.soc_max))
        fuel.append(res.metrics["soc_final"]["value"])
    assert len(set(fuel)) > 1  # the three models are different batteries


def case_battery_cell(row: str, tmp: Path) -> None:
    text = base(row).read_text()
    start = text.index("[battery]")
    end = text.index("\n[", start + 1) + 1
    cell = (
        '[battery]\nmodel = "cell"\ndata = "saft_li_ion_6ah"\nn_series = 100\nn_parallel = 1\n'
        "max_discharge_current_a = 100.0\nmax_charge_current_a = 100.0\nsoc_min = 0.3\nsoc_max = 0.9\n\n"
    )
    (tmp / "car.toml").write_text(text[:start] + cell + text[end:])
    _copy_data(base(row), tmp)
    check(hevsim.simulate(tmp / "car.toml", CYCLE))


def _copy_data(vehicle: Path, tmp: Path) -> None:
    """Make the example's relative data paths resolve from ``tmp`` (symbolic links)."""
    for p in EX.iterdir():
        if not (tmp / p.name).exists():
            (tmp / p.name).symlink_to(p)


def _pack_copy(row: str, tmp: Path, edits: dict[str, str]) -> Path:
    """A copy of the row's pack vehicle whose pack file has ``edits`` (text replacements)."""
    vehicle = pack(row)
    pack_file = tomllib.loads(vehicle.read_text())["battery"]["pack"]
    text = (EX / pack_file).read_text()
    for old, new in edits.items():
        assert old in text, old
        text = text.replace(old, new)
    (tmp / pack_file).write_text(text)
    (tmp / vehicle.name).write_text(vehicle.read_text())
    _copy_data(vehicle, tmp)
    return tmp / vehicle.name


def case_pack_cells_all(row: str, tmp: Path) -> None:
    res = hevsim.simulate(pack(row), CYCLE)
    check_pack(res)
    assert res.metadata["pack"]["n_cells"] > 1


def case_pack_cells_representative(row: str, tmp: Path) -> None:
    import re

    vehicle = pack(row)
    text = (EX / tomllib.loads(vehicle.read_text())["battery"]["pack"]).read_text()
    spreads = {m: re.sub(r"= [0-9.]+", "= 0.0", m) for m in re.findall(r"\n\w+_spread = [0-9.]+", text)}
    edits = {**spreads, "\n[module]\n": '\n[module]\ncells = "representative"\n'}
    res = hevsim.simulate(_pack_copy(row, tmp, edits), CYCLE)
    check_pack(res)


@pytest.fixture(scope="module")
def coarse_rom(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A module thermal ROM of the coarse test mesh (built once for the file)."""
    pytest.importorskip("skfem")
    pytest.importorskip("gmsh")
    try:
        from tests.thermal_helpers import COARSE_TOML
    except ImportError:  # pytest put tests/ itself on the path
        from thermal_helpers import COARSE_TOML  # type: ignore[no-redef]

    from hevsim.thermal.rom import BuildOptions, build_rom_from_config

    d = tmp_path_factory.mktemp("rom")
    (d / "module_coarse.toml").write_text(COARSE_TOML)
    rom, _ = build_rom_from_config(d / "module_coarse.toml", BuildOptions(tol_k=0.1))
    rom.save(d / "module.rom.npz")
    return d


def case_pack_thermal_rom(row: str, tmp: Path, rom_dir: Path) -> None:
    import re

    text = (EX / tomllib.loads(pack(row).read_text())["battery"]["pack"]).read_text()
    arrangement = {}  # the ROM's module: 2 x 6 cells
    for key, n in (("n_series", "2"), ("n_parallel", "6")):
        found = re.search(rf"\n{key} = \d+", text)
        assert found is not None, key
        arrangement[found[0]] = f"\n{key} = {n}"
    rom_keys = (
        f'\nthermal_config = "{rom_dir / "module_coarse.toml"}"\nrom_file = "{rom_dir / "module.rom.npz"}"'
    )
    edits = {
        **arrangement,
        '\nthermal = "coolant"': '\nthermal = "rom"',
        '\nthermal_config = "module_thermal.toml"': rom_keys,
    }
    res = hevsim.simulate(_pack_copy(row, tmp, edits), CYCLE)
    check_pack(res)
    assert res.metadata["pack"]["thermal"] == "rom"
    assert abs(res.extra["pack_energy"]["delta_modules_j"]) > 0.0  # the module ROMs store heat


def case_pack_thermal_coolant(row: str, tmp: Path) -> None:
    res = hevsim.simulate(pack(row), CYCLE)
    check_pack(res)
    assert res.metadata["pack"]["thermal"] == "coolant"


def case_pack_cooling(row: str, tmp: Path) -> None:
    on = hevsim.simulate(pack(row), CYCLE, ambient_c=40.0)
    off = hevsim.simulate(pack(row), CYCLE, ambient_c=40.0, cooling_off=True)
    check_pack(on)
    check_pack(off)
    assert on.metrics["pack_cooling_energy_j"]["value"] > 0.0
    assert off.metrics["pack_cooling_energy_j"]["value"] == 0.0


def case_pack_derating(row: str, tmp: Path) -> None:
    res = hevsim.simulate(pack(row), CYCLE, ambient_c=-10.0, soak=True)
    check_pack(res)
    ts = res.timeseries
    assert ts["derating_factor"].min() < 1.0  # cold cells: the BMS derates
    i = ts["pack_current_a"].to_numpy()
    lim_d, lim_c = ts["bms_discharge_limit_a"].to_numpy(), ts["bms_charge_limit_a"].to_numpy()
    n = min(len(i), len(lim_d))
    assert np.all(i[:n] <= lim_d[:n] * (1 + 0.08) + 1e-6)  # docs/pack.md "Known limit": up to 7 %
    assert np.all(-i[:n] <= lim_c[:n] * (1 + 0.08) + 1e-6)


def case_age_state(row: str, tmp: Path) -> None:
    from hevsim.battery.life import PackAgeState

    cfg = load_vehicle_config(pack(row))
    first = hevsim.simulate(cfg, CYCLE)
    state = PackAgeState(first.metadata["pack"]["n_cells"])
    res = hevsim.simulate(cfg, CYCLE, age_state=state)
    check_pack(res)
    fade = 1.0 - state.capacity_fraction()
    assert np.all(fade > 0.0) and np.all(fade < 0.01)  # one short drive ages every cell a little


def case_life(row: str, tmp: Path) -> None:
    CYCLE.to_csv(tmp / "short.csv") if hasattr(CYCLE, "to_csv") else _write_cycle(tmp / "short.csv")
    out = tmp / "life"
    code = main(["life", str(pack(row)), "--cycle", str(tmp / "short.csv"), "--max-blocks", "2",
                 "--until-soh", "0.5", "--no-plots", "--out", str(out)])  # fmt: skip
    assert code == 0
    assert any(out.iterdir())


def _write_cycle(path: Path) -> None:
    rows_ = "\n".join(f"{t:.6g},{v:.9g}" for t, v in zip(CYCLE.time_s, CYCLE.speed_mps, strict=True))
    path.write_text("time_s,speed_mps\n" + rows_ + "\n")


def case_ambient_soak(row: str, tmp: Path) -> None:
    res = hevsim.simulate(pack(row), CYCLE, ambient_c=40.0, soak=True)
    check_pack(res)
    assert res.timeseries["hottest_cell_temp_k"].iloc[0] == pytest.approx(273.15 + 40.0, abs=0.5)
    assert res.metadata["pack"]["ambient_temp_c"] == 40.0


def case_simulate_batch(row: str, tmp: Path) -> None:
    cfg = load_vehicle_config(base(row))
    key = "mass_kg" if cfg.architecture == "series" else "body.mass_kg"
    m = cfg.body.mass_kg
    b = hevsim.simulate_batch(cfg, {key: [m, m + 300.0]}, CYCLE)
    frame = b.frame if hasattr(b, "frame") else b.table
    assert len(frame) == 2
    assert np.all(np.isfinite(frame.select_dtypes("number").to_numpy(dtype=float)[:, :3]))


def _study(row: str, tmp: Path, solver: dict[str, Any]) -> Any:
    from hevsim.studies.runner import IN_PROCESS, run_study
    from hevsim.studies.spec import study_from_dict

    _write_cycle(tmp / "short.csv")
    cfg = load_vehicle_config(base(row))
    metrics = {"performance": "top_speed_mph"}.get(solver["name"], "soc_final")
    study = study_from_dict({
        "name": f"matrix_{row}", "vehicle": str(base(row)), "cycles": [str(tmp / "short.csv")],
        "metrics": [metrics], "parameters": {"body.mass_kg": [cfg.body.mass_kg]}, "solvers": [solver],
    }, base_dir=tmp)  # fmt: skip
    return run_study(study, scheduler=IN_PROCESS, progress=False)


def case_study_simulate(row: str, tmp: Path) -> None:
    out = _study(row, tmp, {"name": "simulate", "controller": "rule_based"})
    assert list(out["status"]) == ["ok"], out.to_dict("records")


def case_study_optimize(row: str, tmp: Path) -> None:
    out = _study(row, tmp, {"name": "optimize", "soc_grid_points": 21, "input_grid_points": 21})
    assert list(out["status"]) == ["ok"], out.to_dict("records")


def case_study_performance(row: str, tmp: Path) -> None:
    out = _study(row, tmp, {"name": "performance", "dt_s": 0.5})
    assert list(out["status"]) == ["ok"], out.to_dict("records")


CASES: dict[str, Callable[..., None]] = {
    name.removeprefix("case_"): f for name, f in globals().items() if name.startswith("case_")
}


# ------------------------------------------------------------------------------------------
# the refusals of the cells that are not meaningful
# ------------------------------------------------------------------------------------------
@contextlib.contextmanager
def _stderr() -> Iterator[io.StringIO]:
    buf = io.StringIO()
    with contextlib.redirect_stderr(buf):
        yield buf


def _cli(args: list[str]) -> tuple[int, str]:
    with _stderr() as err:
        try:
            code = main(args)
        except SystemExit as exc:  # argparse
            code = int(exc.code or 0)
    return code, err.getvalue()


def _with_battery(row: str, tmp: Path, model: str) -> Path:
    """The row's example with a ``[battery]`` section of ``model`` added."""
    text = (
        base(row).read_text()
        + f'\n[battery]\nmodel = "{model}"\n'
        + ('pack = "vehicle_pack.toml"\n' if model == "pack" else "")
    )
    _copy_data(base(row), tmp)
    (tmp / "car.toml").write_text(text)
    return tmp / "car.toml"


def refuse_battery(row: str, tmp: Path, model: str) -> tuple[int, str, tuple[str, ...]]:
    path = _with_battery(row, tmp, model)
    code, err = _cli(["simulate", str(path), "--cycle", "udds", "--no-plots", "--out", str(tmp / "o")])
    return code, err, ("car.toml", "battery", "traction battery")


def refuse_controller(kind: str) -> Callable[[str, Path], tuple[int, str, tuple[str, ...]]]:
    def refuse(row: str, tmp: Path) -> tuple[int, str, tuple[str, ...]]:
        code, err = _cli(
            ["simulate", str(base(row)), "--controller", kind, "--no-plots", "--out", str(tmp / "o")]
        )
        return code, err, (base(row).name.removesuffix(".toml"), "controller.kind", repr(kind), _reason(row))

    return refuse


def _reason(row: str) -> str:
    return (
        "no [battery]" if "battery" not in {f.name for f in dataclasses.fields(_spec(row))} else "no [engine]"
    )


def _spec(row: str) -> type:
    from hevsim.config import ARCHITECTURES

    return ARCHITECTURES[ROWS[row].name].config_type  # type: ignore[no-any-return]


def refuse_dp(row: str, tmp: Path) -> tuple[int, str, tuple[str, ...]]:
    code, err = _cli(["optimize", str(base(row)), "--cycle", "udds", "--no-plots", "--out", str(tmp / "o")])
    return code, err, (base(row).stem, "powertrain.architecture", repr(ROWS[row].name), "no DP formulation")


def refuse_dp_replay(row: str, tmp: Path) -> tuple[int, str, tuple[str, ...]]:
    (tmp / "schedule.csv").write_text("time_s,engine_speed_rpm,engine_throttle\n0,0,0\n")
    code, err = _cli(["simulate", str(base(row)), "--schedule", str(tmp / "schedule.csv"), "--no-plots",
                      "--out", str(tmp / "o")])  # fmt: skip
    return code, err, (base(row).name, "--schedule", "schedule")


def refuse_pack_option(row: str, tmp: Path, option: list[str]) -> tuple[int, str, tuple[str, ...]]:
    code, err = _cli(["simulate", str(base(row)), *option, "--no-plots", "--out", str(tmp / "o")])
    return code, err, (base(row).stem, "battery", "pack")


def refuse_life(row: str, tmp: Path) -> tuple[int, str, tuple[str, ...]]:
    code, err = _cli(["life", str(base(row)), "--no-plots", "--out", str(tmp / "o")])
    return code, err, (base(row).stem, "battery", "pack")


def refuse_study_optimize(row: str, tmp: Path) -> tuple[int, str, tuple[str, ...]]:
    from hevsim.errors import ConfigError

    try:
        case_study_optimize(row, tmp)
    except ConfigError as exc:
        return 2, str(exc), ("optimize", repr(ROWS[row].name), "supports")
    return 0, "", ()


REFUSALS: dict[str, Callable[[str, Path], tuple[int, str, tuple[str, ...]]]] = {
    "ecms_dp": refuse_controller("ecms"),
    "aecms": refuse_controller("aecms"),
    "dp": refuse_dp,
    "dp_replay": refuse_dp_replay,
    "battery_tables": lambda r, t: refuse_battery(r, t, "table"),
    "battery_cell": lambda r, t: refuse_battery(r, t, "cell"),
    "age_state": lambda r, t: refuse_pack_option(r, t, ["--age-state", str(t / "age.json")]),
    "life": refuse_life,
    "ambient_soak": lambda r, t: refuse_pack_option(r, t, ["--ambient-c", "-10", "--soak"]),
    "study_optimize": refuse_study_optimize,
}
REFUSALS.update({k: (lambda r, t: refuse_battery(r, t, "pack")) for k in CAPS if k.startswith("pack_")})


# ------------------------------------------------------------------------------------------
# the tests
# ------------------------------------------------------------------------------------------
def test_docs_hold_the_generated_matrix() -> None:
    page = ROOT / "docs" / "simulate.md"
    assert update_docs(page, write=False), (
        f"{page}: the capability matrix is stale; regenerate it with `python scripts/capability_matrix.py`"
    )


def test_every_capability_has_a_case_and_every_refusal_a_check() -> None:
    assert set(CASES) >= {c.key for _, c, s in CELLS if s.state == WORKS}
    assert set(REFUSALS) >= {c.key for _, c, s in CELLS if s.state == NOT_MEANINGFUL}
    gaps = {(r, c.key) for r, c, s in CELLS if s.state == MISSING}
    assert gaps == KNOWN_GAPS  # a new gap fails; a closed one removes its line


def test_a_registered_architecture_gets_its_column() -> None:
    """A new registry entry (as the PHEV/FCEV ones will be) appears in the matrix unasked."""
    from hevsim import architectures as A
    from hevsim import config as C

    spec = dataclasses.replace(C.ARCHITECTURES["bev"], name="bev_copy")
    entry = dataclasses.replace(A.ARCHITECTURES["bev"], name="bev_copy")
    C.register_architecture(spec)
    A.register(entry)
    try:
        keys = [r.key for r in rows()]
        assert "bev_copy" in keys
        assert "bev_copy" in markdown().splitlines()[0]
        assert CAPS["study_simulate"].status(Row("bev_copy", "bev_copy")).state == WORKS
        assert CAPS["dp"].status(Row("bev_copy", "bev_copy")).state == NOT_MEANINGFUL
    finally:
        del C.ARCHITECTURES["bev_copy"], A.ARCHITECTURES["bev_copy"]


WORKING = [(r, c.key) for r, c, s in CELLS if s.state == WORKS]
REFUSED = [(r, c.key) for r, c, s in CELLS if s.state == NOT_MEANINGFUL]


@pytest.mark.parametrize(("row", "cap"), WORKING, ids=[f"{r}-{c}" for r, c in WORKING])
def test_working_cell(row: str, cap: str, tmp_path: Path, request: pytest.FixtureRequest) -> None:
    case = CASES[cap]
    if cap == "pack_thermal_rom":
        case(row, tmp_path, request.getfixturevalue("coarse_rom"))
    else:
        case(row, tmp_path)


@pytest.mark.parametrize(("row", "cap"), REFUSED, ids=[f"{r}-{c}" for r, c in REFUSED])
def test_refused_cell(row: str, cap: str, tmp_path: Path) -> None:
    code, message, names = REFUSALS[cap](row, tmp_path)
    assert code == 2, message
    assert "Traceback" not in message
    for name in names:
        assert name in message, f"{name!r} not in {message!r}"


def test_series_pack_runs_the_online_controllers_and_the_dp_replay() -> None:
    """The series HEV with ``[battery] model = "pack"``: ECMS and the DP replay run on its
    quasi-static power flow with the pack stepped in the loop (were refused: "needs
    'battery.model' = ideal or rint or table"); the replay burns the DP's fuel, the pack's
    energy balance and the vehicle's audit close, the pack's cooling is the bus's auxiliary load."""
    from hevsim.control.parallel import ControlSchedule
    from hevsim.optimal.hev import optimize

    path = pack("series")
    ecms = hevsim.simulate(path, CYCLE, controller="ecms")
    check_pack(ecms)
    assert ecms.metadata["controller"] == "ecms"
    r = optimize(path, CYCLE, soc_grid_points=21, input_grid_points=21, progress=False, threads=1)
    soc0 = float(r.timeseries["soc"].iloc[0])
    replay = hevsim.simulate(path, CYCLE, soc_initial=soc0, controller=ControlSchedule.from_optimization(r))
    check_pack(replay)
    assert replay.value("fuel_kg") == pytest.approx(r.value("fuel_kg"), rel=1e-9)
    assert replay.energy_audit["aux"] == pytest.approx(
        replay.metrics["pack_cooling_energy_j"]["value"], rel=1e-9
    )
