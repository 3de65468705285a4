"""FMU export (issue 4, item 6): FMPy validates it and it reproduces the in-process cell."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hevsim.battery import Cell
from hevsim.battery.fmu import simulate_fmu
from hevsim.cli import main

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def fmu(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("fmu") / "cell.fmu"
    assert main(["export-fmu", str(ROOT / "examples" / "cell.toml"), "-o", str(out)]) == 0
    return out


def test_fmu_passes_fmpy_validation(fmu: Path) -> None:
    from fmpy.validation import validate_fmu

    assert validate_fmu(str(fmu)) == []


def test_fmu_reproduces_in_process_model(fmu: Path) -> None:
    n, dt = 400, 2.0
    current = np.where(np.arange(n) < n // 2, 4.0, -2.0)  # discharge, then charge (switches RC sets)
    port = 296.15 + 0.02 * np.arange(n)
    got = simulate_fmu(fmu, current, port, dt)
    ref = Cell("thesis_table_4_1", soc_initial=1.0, temp_k=296.15).simulate(current, dt, port).timeseries
    for name in ("voltage_v", "soc", "temp_k", "port_heat_w"):
        np.testing.assert_allclose(got[name], ref[name].to_numpy(), rtol=1e-9, atol=1e-12, err_msg=name)
    assert got["soh"][-1] < got["soh"][0] <= 1.0  # capacity fades with transferred charge (eq 35)


def test_fmu_parameters_are_applied(fmu: Path) -> None:
    current = np.full(100, 4.0)
    base = simulate_fmu(fmu, current, 296.15, 1.0)
    heavy = simulate_fmu(fmu, current, 296.15, 1.0, parameters={"c_heat_j_per_k": 500.0, "soc_initial": 0.8})
    assert heavy["temp_k"][-1] < base["temp_k"][-1]  # more heat capacity, less temperature rise
    assert heavy["soc"][0] < base["soc"][0]


def test_export_rejects_modules(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["export-fmu", str(ROOT / "examples" / "module.toml"), "-o", str(tmp_path / "m.fmu")]) == 2
    assert "single-cell" in capsys.readouterr().err
    assert not (tmp_path / "m.fmu").exists()
