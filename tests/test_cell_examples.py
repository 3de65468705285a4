"""examples/cell.toml and examples/module.toml run (and their configs are validated)."""

from __future__ import annotations

from pathlib import Path

import pytest

from hevsim.battery import CellResult, ModuleResult
from hevsim.battery.config import load_config, run_config
from hevsim.errors import ConfigError

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def test_cell_example_runs() -> None:
    r = run_config(EXAMPLES / "cell.toml")
    assert isinstance(r, CellResult)
    assert r.metrics["duration_s"] == 600.0 and r.metrics["max_temp_k"] > 296.15
    assert abs(r.metrics["energy_balance_residual_j"]) < 1e-9 * r.metrics["electrical_energy_out_j"]


def test_module_example_runs() -> None:
    r = run_config(EXAMPLES / "module.toml")
    assert isinstance(r, ModuleResult)
    assert r.cells.shape == (3600, 12, 4)
    assert r.metrics["final_soc_spread"] > 0


def test_bad_config_is_named(tmp_path: Path) -> None:
    f = tmp_path / "bad.toml"
    f.write_text('[profile]\nkind = "sine"\n')
    with pytest.raises(ConfigError, match=r"bad.toml: key 'profile.kind' = 'sine' is not a valid choice"):
        load_config(f)
    f.write_text("[cell]\nsoc_initial = 1.5\n")
    with pytest.raises(ConfigError, match="out of range"):
        load_config(f)
