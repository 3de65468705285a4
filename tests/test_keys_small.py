"""Issue 26, item 8: `hevsim rom build` writes under results/ by default; `load_config` loads
every architecture's file; `simulate` takes a path."""

from __future__ import annotations

from pathlib import Path

import pytest
from tests.keys_helpers import EXAMPLES, SHIPPED
from tests.thermal_helpers import COARSE_TOML

from hevsim import config as C
from hevsim.cli import main

TYPES = {
    "series": C.SeriesHEVConfig, "parallel": C.ParallelHEVConfig, "power_split": C.PowerSplitConfig,
    "conventional": C.ConventionalConfig, "bev": C.BEVConfig,
}  # fmt: skip


@pytest.mark.parametrize("name", SHIPPED)
def test_load_config_returns_the_architecture_type(name: str) -> None:
    path = EXAMPLES / f"{name}.toml"
    cfg = C.load_config(path)
    assert type(cfg) is TYPES[cfg.architecture]
    assert cfg == C.load_vehicle_config(path)


def test_simulate_takes_a_path() -> None:
    from hevsim.sim.simulator import simulate

    res = simulate(EXAMPLES / "conventional_sedan.toml", "nycc")
    assert res.metadata["architecture"] == "conventional" and res.value("mpgge") > 0


def test_rom_build_writes_under_results_by_default(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    src = tmp_path / "examples"
    src.mkdir()
    toml = src / "module_coarse.toml"
    toml.write_text(COARSE_TOML, encoding="utf-8")
    monkeypatch.chdir(tmp_path)
    assert main(["rom", "build", str(toml)]) == 0
    assert sorted(p.name for p in src.iterdir()) == ["module_coarse.toml"]
    out = tmp_path / "results" / "module_coarse.rom.npz"
    assert out.is_file()
    assert f"ROM written to {Path('results') / 'module_coarse.rom.npz'}" in capsys.readouterr().out
