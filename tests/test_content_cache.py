"""The parsed-input cache (issue 24, speed: ``simulate(path, cycle)`` no longer parses the
vehicle file, the component maps and the cycle again on every call): keyed on the file's
content, bounded, and copy-safe."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from hevsim import io as hio
from hevsim.cycles import load_cycle_csv
from hevsim.schema import read_toml
from hevsim.sim.simulator import simulate
from hevsim.tables import read_csv_columns, read_meta

ROOT = Path(__file__).resolve().parents[1]


def _write_cycle(path: Path, top_mps: float) -> None:
    t = np.arange(0.0, 121.0)
    v = top_mps * np.sin(np.pi * t / 120.0) ** 2
    path.write_text("time_s,speed_mps\n" + "".join(f"{a:5.1f},{b:6.3f}\n" for a, b in zip(t, v, strict=True)))


def _same_stamp(path: Path, stat: os.stat_result) -> None:
    """Give ``path`` back the size-independent time stamps of ``stat`` (a cache keyed on the
    time stamp would then miss the change)."""
    os.utime(path, ns=(stat.st_atime_ns, stat.st_mtime_ns))


def test_a_changed_cycle_file_is_read_again_even_with_the_same_size_and_time_stamp(tmp_path: Path) -> None:
    cyc = tmp_path / "pulse.csv"
    _write_cycle(cyc, 15.0)
    st = cyc.stat()
    first = simulate(ROOT / "examples/series_hev.toml", str(cyc))
    again = simulate(ROOT / "examples/series_hev.toml", str(cyc))
    _write_cycle(cyc, 16.0)  # same number of characters per line: the same size
    assert cyc.stat().st_size == st.st_size
    _same_stamp(cyc, st)
    changed = simulate(ROOT / "examples/series_hev.toml", str(cyc))
    assert again.value("distance_m") == first.value("distance_m")
    assert changed.value("distance_m") > first.value("distance_m") * 1.03


def test_a_changed_vehicle_file_is_read_again(tmp_path: Path) -> None:
    veh = tmp_path / "series.toml"
    shutil.copy(ROOT / "examples/series_hev.toml", veh)
    light = simulate(veh, "udds")
    text = veh.read_text()
    assert "mass_kg = 1200.0" in text
    st = veh.stat()
    veh.write_text(text.replace("mass_kg = 1200.0", "mass_kg = 1500.0"))
    _same_stamp(veh, st)
    heavy = simulate(veh, "udds")
    assert heavy.value("fuel_kg") > light.value("fuel_kg") * 1.05


def test_a_cached_call_gives_identical_results() -> None:
    hio.clear_content_cache()
    cold = simulate(ROOT / "examples/series_hev.toml", "udds")
    warm = simulate(ROOT / "examples/series_hev.toml", "udds")
    assert len(hio._CONTENT_CACHE) > 0
    num = cold.timeseries.select_dtypes("number")
    np.testing.assert_array_equal(num.to_numpy(), warm.timeseries.select_dtypes("number").to_numpy())
    assert cold.energy_audit == warm.energy_audit
    assert {k: cold.value(k) for k in ("fuel_kg", "soc_final", "mpg")} == {
        k: warm.value(k) for k in ("fuel_kg", "soc_final", "mpg")
    }


def test_callers_cannot_corrupt_the_cache(tmp_path: Path) -> None:
    csv = tmp_path / "map.csv"
    csv.write_text("speed_radps,torque_nm\n0,10\n100,20\n")
    a = read_csv_columns(csv, ["speed_radps", "torque_nm"])
    a["torque_nm"][:] = -1.0  # the caller's own copy
    a["extra"] = np.zeros(1)
    b = read_csv_columns(csv, ["speed_radps", "torque_nm"])
    np.testing.assert_array_equal(b["torque_nm"], [10.0, 20.0])
    assert set(b) == {"speed_radps", "torque_nm"}

    toml = tmp_path / "v.toml"
    shutil.copy(ROOT / "examples/series_hev.toml", toml)
    d = read_toml(toml)
    d["body"]["mass_kg"] = -5.0
    d.clear()
    assert read_toml(toml)["body"]["mass_kg"] == 1200.0

    folder = tmp_path / "comp"
    folder.mkdir()
    (folder / "meta.toml").write_text('name = "x"\n[limits]\nmax = 3.0\n')
    m = read_meta(folder, "test")
    m["limits"]["max"] = 0.0
    assert read_meta(folder, "test")["limits"]["max"] == 3.0

    cyc = tmp_path / "c.csv"
    _write_cycle(cyc, 10.0)
    c = load_cycle_csv(cyc)
    with pytest.raises(ValueError, match="read-only"):
        c.speed_mps[0] = 99.0
    assert load_cycle_csv(cyc).speed_mps[0] == 0.0


def test_the_cache_is_bounded(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(hio, "CONTENT_CACHE_ENTRIES", 3)
    hio.clear_content_cache()
    for j in range(6):
        p = tmp_path / f"m{j}.csv"
        p.write_text(f"x\n{j}\n")
        assert read_csv_columns(p, ["x"])["x"][0] == j
    assert len(hio._CONTENT_CACHE) == 3
    hio.clear_content_cache()


def test_a_missing_or_bad_file_still_names_the_file(tmp_path: Path) -> None:
    from hevsim.errors import ConfigError, InputError

    with pytest.raises(InputError, match=r"nope\.csv"):
        read_csv_columns(tmp_path / "nope.csv", ["x"])
    bad = tmp_path / "bad.toml"
    bad.write_text("a = [\n")
    with pytest.raises(ConfigError, match=r"bad\.toml"):
        read_toml(bad)
    bad.write_text("a = 1\n")  # fixed: read again, not the cached error
    assert read_toml(bad)["a"] == 1


# --------------------------------------------------------------------------- built components
# hevsim.io.cached_build: a component made from its data folder (maps parsed, tables checked)
# once per content of the files it read and the names in the folder.


def _engine_section(folder: Path) -> object:
    import dataclasses

    from hevsim.config import load_vehicle_config

    cfg = load_vehicle_config(ROOT / "examples/series_hev.toml")
    assert cfg.engine.model == "map"
    return dataclasses.replace(cfg.engine, data=str(folder))


def _engine_folder(tmp_path: Path) -> Path:
    folder = tmp_path / "engine"
    shutil.copytree(ROOT / "src/hevsim/data/components/engines/geo_1p0_si41", folder)
    return folder


def test_a_changed_component_map_is_built_again(tmp_path: Path) -> None:
    from hevsim.architectures._build import build_engine

    folder = _engine_folder(tmp_path)
    sec = _engine_section(folder)
    first = build_engine(sec, tmp_path)  # type: ignore[arg-type]
    again = build_engine(sec, tmp_path)  # type: ignore[arg-type]
    np.testing.assert_array_equal(again.max_torque.y, first.max_torque.y)
    csv = folder / "max_torque.csv"
    lines = csv.read_text().splitlines()
    st = csv.stat()
    head, rows = lines[0], lines[1:]
    scaled = []
    for row in rows:  # every torque x 1.1, written back in the same format
        x, y = row.split(",")
        scaled.append(f"{x},{float(y) * 1.1!r}")
    csv.write_text("\n".join([head, *scaled]) + "\n")
    _same_stamp(csv, st)
    changed = build_engine(sec, tmp_path)  # type: ignore[arg-type]
    np.testing.assert_allclose(changed.max_torque.y, first.max_torque.y * 1.1, rtol=1e-12)


def test_a_file_added_to_a_component_folder_rebuilds_it(tmp_path: Path) -> None:
    from hevsim.architectures._build import build_engine

    folder = _engine_folder(tmp_path)
    ct = folder / "closed_throttle_torque.csv"
    saved = ct.read_bytes()
    ct.unlink()  # optional file: without it the closed-throttle torque is zero
    sec = _engine_section(folder)
    without = build_engine(sec, tmp_path)  # type: ignore[arg-type]
    assert np.all(without.closed_throttle_torque.y == 0.0)
    ct.write_bytes(saved)
    with_file = build_engine(sec, tmp_path)  # type: ignore[arg-type]
    assert np.any(with_file.closed_throttle_torque.y != 0.0)


def test_a_built_component_is_a_copy(tmp_path: Path) -> None:
    from hevsim.architectures._build import build_engine

    sec = _engine_section(_engine_folder(tmp_path))
    first = build_engine(sec, tmp_path)  # type: ignore[arg-type]
    reference = first.max_torque.y.copy()
    first.max_torque.y[:] = -1.0  # a caller scribbling on its own component
    again = build_engine(sec, tmp_path)  # type: ignore[arg-type]
    assert again is not first
    np.testing.assert_array_equal(again.max_torque.y, reference)


# --------------------------------------------------------------------------- deferred result fields


def test_the_series_result_time_series_and_events_are_made_on_demand_and_agree() -> None:
    """The series run hands its DataFrame and events over unmade (simulator._Deferred); once
    read they are what the kernel recorded, and the events are the state changes of the time
    series (checked here with pandas, independently of the numpy code that makes them)."""
    import copy
    import pickle

    import pandas as pd

    from hevsim.sim import kernel as K

    res = simulate(ROOT / "examples/series_hev.toml", "udds")
    from hevsim.sim.simulator import _Later

    assert isinstance(res.__dict__["_timeseries_value"], _Later)  # not made yet
    assert isinstance(res.__dict__["_events_value"], _Later)
    ts, ev = res.timeseries, res.events
    assert res.timeseries is ts and res.events is ev  # made once
    rows = []
    for col, kind, names in (
        ("genset_state", "genset", K.GENSET_STATES),
        ("power_mode", "power_mode", K.POWER_MODES),
    ):
        s = ts[col]
        changed = s.ne(s.shift()) & s.shift().notna()
        for i in np.flatnonzero(changed.to_numpy()):
            rows.append((ts["time_s"].iat[i], kind, names[s.iat[i - 1]], names[s.iat[i]],
                         K.REASONS[ts["mode_reason"].iat[i]]))  # fmt: skip
    rows.sort(key=lambda r: (r[0], r[1]))
    assert len(ev) == len(rows) > 10
    assert list(ev.itertuples(index=False, name=None)) == rows
    back = pickle.loads(pickle.dumps(res))
    pd.testing.assert_frame_equal(back.timeseries, ts)
    pd.testing.assert_frame_equal(copy.deepcopy(res).events, ev)
    res.events = ev.iloc[0:0]  # still settable (tests and reports do this)
    assert len(res.events) == 0
