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
