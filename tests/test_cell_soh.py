"""SOH is health, not temperature (issue 10, item 6): a new cell reports SOH 1 at any temperature.

SOH = SOH_C x SOH_Z (thesis eq 42) with SOH_C from the aged capacity at the reference
temperature (eq 43); the temperature's effect on the available capacity (eq 35) is not
ageing. Before, the FMU of a new Table 4.1 cell (T_ref = 293 K) reported 0.975 at 23 degC.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hevsim.battery import kernel as K
from hevsim.battery import load_cell_parameters
from hevsim.battery.ageing import SOH_DEFINITION, age_cell, soh_of_state
from hevsim.battery.fmu import CellStepper, ModuleStepper


@pytest.mark.parametrize("cell", ["thesis_table_4_1", "saft_li_ion_6ah"])
def test_new_cell_reports_soh_one_at_any_temperature(cell: str) -> None:
    p = load_cell_parameters(cell)
    t_ref = float(p.vector(1.0)[K.TREF])
    for temp_k in (t_ref, t_ref + 3.15, t_ref + 20.0):
        stepper = CellStepper(p, 1.0, temp_k)
        assert stepper.outputs["soh"] == pytest.approx(1.0, abs=1e-12), temp_k
        out = stepper.step(2.0, temp_k, 1.0)  # one second of discharge ages nothing (k_cqabs = 0)
        assert out["soh"] == pytest.approx(1.0, abs=1e-12), temp_k
        mod = ModuleStepper(p, 1.0, temp_k, 2, 3, capacity_spread=0.03, seed=1)
        assert mod.outputs["soh"] == pytest.approx(1.0, abs=1e-12), temp_k


def test_soh_falls_with_capacity_fade_of_eq_35() -> None:
    p = load_cell_parameters("thesis_table_4_1")
    vec = p.vector(1.0)
    vec[K.KCQ] = -1e-3  # capacity falls by 1 mC per C of throughput
    c0 = float(vec[K.C0])
    qabs = np.array([0.0, 1e4, 5e4])
    s = soh_of_state(vec, qabs, c0, p.ageing.x_c)
    assert s[0] == pytest.approx(1.0, abs=1e-12)
    assert s[1] == pytest.approx((1.0 - 10.0 / c0 - p.ageing.x_c) / (1.0 - p.ageing.x_c), rel=1e-12)
    assert np.all(np.diff(s) < 0)


def test_age_cell_soh_starts_at_one_and_decreases() -> None:
    p = load_cell_parameters("thesis_table_4_1")
    t_ref = float(p.vector(1.0)[K.TREF])
    profile = np.full(120, 4.0)
    df = age_cell(p, profile, 1.0, 40, port_temperature=t_ref, soc_initial=1.0, resimulate_every=10)
    assert df["soh"].iloc[0] == pytest.approx(1.0, abs=1e-12)
    assert np.all(np.diff(df["soh"].to_numpy()) < 0)
    assert 0.0 < df["soh"].iloc[-1] < 1.0


def test_age_command_defines_soh(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from hevsim.cli import main

    root = Path(__file__).resolve().parents[1]
    out = tmp_path / "age"
    assert main(["age", str(root / "examples" / "cell.toml"), "--repetitions", "2", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "SOH = SOH_C x SOH_Z (thesis eq 42)" in text and "reference temperature" in text
    assert (out / "soh_definition.txt").read_text(encoding="utf-8").strip() == SOH_DEFINITION
