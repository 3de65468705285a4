"""SOH (eqs 42-44) and the semi-empirical ageing model (issue 4, item 2)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hevsim.battery.ageing import (
    AgeingState,
    Stress,
    advance,
    age_cell,
    load_ageing_model,
    soh,
    soh_capacity,
    soh_impedance,
)
from hevsim.errors import ConfigError, InputError


def test_soh_equations() -> None:
    assert soh_capacity(2880.0, 2880.0, 0.8) == pytest.approx(1.0)
    assert soh_capacity(0.8 * 2880.0, 2880.0, 0.8) == pytest.approx(0.0)
    assert soh_capacity(0.9 * 2880.0, 2880.0, 0.8) == pytest.approx(0.5)
    assert soh_impedance(0.014, 0.014, 2.0) == pytest.approx(1.0)
    assert soh_impedance(0.028, 0.014, 2.0) == pytest.approx(0.0)
    assert soh(0.5, 0.8) == pytest.approx(0.4)


def _stress(**kw: float) -> Stress:
    base = dict(duration_s=3600.0, throughput_ah=2.2, c_rate=0.5, temp_k=298.15, mean_ocv_v=3.6, dod=0.8)
    base.update(kw)
    return Stress(**base)


def test_wang2011_cycle_fade_closed_form() -> None:
    """Constant stress: Q_loss = B exp(-(31700 - 370.3 C)/(R T)) Ah^0.55 [%] on the 2.2 A h cell."""
    m = load_ageing_model()
    st = AgeingState()
    advance(m, st, _stress(), nominal_capacity_ah=2.2, reps=500)  # 1100 A h
    expected = 31630.0 * math.exp(-(31700.0 - 370.3 * 0.5) / (8.314 * 298.15)) * 1100.0**0.55 / 100.0
    assert st.loss_cycle == pytest.approx(expected, rel=1e-12)
    # magnitude check: a few per cent after 500 equivalent full cycles at C/2 and 25 degC
    assert 0.02 < st.loss_cycle < 0.06


def test_virtual_throughput_accumulation_is_path_independent_at_constant_stress() -> None:
    m = load_ageing_model()
    a, b = AgeingState(), AgeingState()
    advance(m, a, _stress(), 6.0, reps=100)
    for _ in range(10):
        advance(m, b, _stress(), 6.0, reps=10)
    for k in ("loss_cycle", "loss_calendar", "growth_calendar", "growth_cycle", "throughput_ah", "time_s"):
        assert getattr(b, k) == pytest.approx(getattr(a, k), rel=1e-12)


def test_schmalstieg_calendar_closed_form_and_trends() -> None:
    m = load_ageing_model()
    st = AgeingState()
    s = _stress(duration_s=86400.0 * 100, throughput_ah=0.0, temp_k=313.15, mean_ocv_v=3.8)
    advance(m, st, s, 2.05)
    a_cap = (7.543 * 3.8 - 23.75) * 1e6 * math.exp(-6976.0 / 313.15)
    assert st.loss_calendar == pytest.approx(a_cap * 100.0**0.75, rel=1e-12)
    hot, cold = AgeingState(), AgeingState()
    advance(m, hot, _stress(temp_k=318.15), 2.2, reps=200)
    advance(m, cold, _stress(temp_k=288.15), 2.2, reps=200)
    assert hot.loss_cycle > cold.loss_cycle and hot.loss_calendar > cold.loss_calendar
    deep, shallow = AgeingState(), AgeingState()
    advance(m, deep, _stress(dod=0.9), 2.2, reps=200)
    advance(m, shallow, _stress(dod=0.1), 2.2, reps=200)
    assert deep.growth_cycle > shallow.growth_cycle


def test_age_cell_over_repeated_profile() -> None:
    prof = np.r_[np.full(600, 10.0), np.full(600, -10.0)]
    df = age_cell("saft_li_ion_6ah", prof, 1.0, 300, port_temperature=308.15, rest_s=3600.0)
    assert df["repetition"].iloc[-1] == 300
    assert np.all(np.diff(df["capacity_fraction"]) < 0) and np.all(np.diff(df["resistance_fraction"]) > 0)
    assert df["soh"].iloc[0] == 1.0 and 0.0 < df["soh"].iloc[-1] < 1.0
    np.testing.assert_allclose(df["soh"], df["soh_c"] * df["soh_z"])
    assert df["throughput_ah"].iloc[-1] == pytest.approx(300 * 10.0 * 600 / 3600.0, rel=1e-9)
    again = age_cell("saft_li_ion_6ah", prof, 1.0, 300, port_temperature=308.15, rest_s=3600.0)
    assert again.equals(df)
    hotter = age_cell("saft_li_ion_6ah", prof, 1.0, 300, port_temperature=318.15, rest_s=3600.0)
    assert hotter["capacity_fraction"].iloc[-1] < df["capacity_fraction"].iloc[-1]


def test_ageing_bad_input() -> None:
    with pytest.raises(InputError, match="repetitions"):
        age_cell("saft_li_ion_6ah", [1.0], 1.0, 0)
    with pytest.raises(ConfigError, match="not known"):
        load_ageing_model("nope")


def test_age_command(tmp_path, capsys) -> None:  # type: ignore[no-untyped-def]
    from pathlib import Path

    import pandas as pd

    from hevsim.cli import main

    root = Path(__file__).resolve().parents[1]
    out = tmp_path / "age"
    assert main(["age", str(root / "examples" / "cell.toml"), "--repetitions", "200", "--out", str(out)]) == 0
    table = pd.read_csv(out / "ageing.csv")
    assert table["capacity_fraction"].is_monotonic_decreasing
    assert table["resistance_fraction"].iloc[-1] > 1.0
    assert (out / "ageing.png").read_bytes()[:4] == b"\x89PNG"
    assert "SOH" in capsys.readouterr().out
