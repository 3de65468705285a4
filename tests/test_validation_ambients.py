"""Validation at ambients the calibration never saw (issue 27, item 3): hevsim's cell calibrated
on PyBaMM DFN pulse tests (lumped thermal) at 0, 25 and 45 degC with the joint temperature
laws holds the targets on the DFN's UDDS current at -10, 10, 35 and 45 degC (<= 12 mV RMS,
<= 40 mV max, <= 0.5 K RMS), where the same cell calibrated at 25 degC alone does not.
Reduced data set: the first three SOC levels of each pulse test (SOC 0.95 -> 0.65; the UDDS
runs from SOC 0.8). The full table: ``python examples/validation/validate_dfn.py ambients``."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

DATA = Path(__file__).resolve().parents[1] / "examples" / "validation"
sys.path.insert(0, str(DATA))
import validate_dfn as V  # noqa: E402

ROWS = 600 + 3 * 1560  # the first rest and three SOC levels of the pulse test (make_dfn_data.py)
TARGET_RMS_MV, TARGET_MAX_MV, TARGET_TEMP_K = 12.0, 40.0, 0.5


@pytest.mark.parametrize("cell", ["nmc"])
def test_calibration_over_ambients_holds_the_targets_at_unseen_ambients(cell: str) -> None:
    fits = V.ambient_calibrations(cell, rows=ROWS)
    tab = V.ambient_table(cell, fits)
    after = tab[(tab["calibration"] == "after") & (tab["range"] == "all")]
    before = tab[(tab["calibration"] == "before") & (tab["range"] == "all")]
    assert sorted(after["ambient_c"]) == sorted(V.VAL_AMBIENTS_C)
    for _, row in after.iterrows():
        where = f"{cell} at {row['ambient_c']} degC: {row.to_dict()}"
        assert row["rmse_mv"] <= TARGET_RMS_MV, where
        assert row["max_abs_mv"] <= TARGET_MAX_MV, where
        assert row["temp_rmse_k"] <= TARGET_TEMP_K, where
    cold = before[before["ambient_c"] == -10].iloc[0]
    assert cold["rmse_mv"] > 3 * TARGET_RMS_MV  # the single-ambient calibration fails in the cold


TARGET_BIAS_MV = 5.0


def test_lfp_calibration_over_ambients_has_no_band_bias_at_unseen_ambients() -> None:
    """LFP (issue 27 item 3's bias target): calibrated over the three pulse tests, sampled every
    5 s (the tests' segments last multiples of 10 s, so the coarser record holds the same
    current; the whole SOC range, down to the low-SOC knee, at a fifth of the rows) with the
    robust joint fit (validate_dfn.ROBUST_F_SCALE), no current band of the UDDS at -10, 10, 35 or
    45 degC has a mean voltage error above 5 mV, besides the RMS, max and temperature targets.
    Plain least squares on the same data leaves +8 to +9 mV in every band at -10 degC (the knee's
    errors drag the capacity factors and initial SOCs: an OCV offset on the plateau)."""
    fits = V.ambient_calibrations("lfp", every=5)
    tab = V.ambient_table("lfp", fits)
    after = tab[tab["calibration"] == "after"]
    assert sorted(set(after["ambient_c"])) == sorted(V.VAL_AMBIENTS_C)
    for _, row in after.iterrows():
        where = f"lfp at {row['ambient_c']} degC: {row.to_dict()}"
        if row["range"] == "all":
            assert row["rmse_mv"] <= TARGET_RMS_MV, where
            assert row["max_abs_mv"] <= TARGET_MAX_MV, where
            assert row["temp_rmse_k"] <= TARGET_TEMP_K, where
        else:  # every band (the UDDS's 3C peak is in 2-3C; no row above 3C)
            assert abs(row["mean_mv"]) <= TARGET_BIAS_MV, where
    assert set(after["range"]) == {"0-0.5C", "0.5-1C", "1-2C", "2-3C", "all"}
    caps = fits["after"].parameters.set_index("name")["value"]
    assert caps.filter(like="capacity_factor").between(0.95, 1.06).all()  # 1.09 before the fix


def test_ambient_data_match_their_provenance() -> None:
    import hashlib
    import tomllib

    prov = tomllib.loads((DATA / "PROVENANCE_ambients.toml").read_text())["sha256"]
    assert len(prov) == 14  # two cells x (3 pulse tests + 4 drive cycles)
    for name, digest in prov.items():
        assert "sha256:" + hashlib.sha256((DATA / name).read_bytes()).hexdigest() == digest, name


def test_initial_soc_of_an_lfp_test_from_its_rests() -> None:
    """The joint fit's start for each other test's initial SOC: on the flat LFP OCV the first
    voltage has no inverse (the fitted OCV's inverse gave about 0.84 for a test that starts at
    0.95, and the joint fit then settled on a capacity factor of 1.08 with a shifted SOC); laying
    the test's rests on the reference test's relaxed-voltage curve gives the known 0.95."""
    import numpy as np

    from hevsim.battery import identify as ID
    from hevsim.battery.calibrate import CellTestRecord

    cap_c = V.AMBIENT_CELLS["lfp"] * 3600.0
    ref = CellTestRecord.from_csv(DATA / V._name("lfp", "pulse", 25))
    curve = ID._relaxed_curve(ref, ID.coulomb_soc(ref, V.SOC_INITIAL, cap_c), 300.0)
    soc_ax = np.array([0.0, 0.15, 0.5, 0.85, 1.0])
    ocv = np.interp(soc_ax, curve[0], curve[1])  # flat at the top: a poor inverse
    for t_c in (0, 45):
        rec = CellTestRecord.from_csv(DATA / V._name("lfp", "pulse", t_c))
        s0 = ID._initial_soc_from_rests(rec, curve, ocv, soc_ax, cap_c, 300.0)
        assert abs(s0 - V.SOC_INITIAL) < 2e-3, (t_c, s0)
        inverse = float(np.interp(rec.voltage_v[0], np.maximum.accumulate(ocv), soc_ax))
        assert abs(inverse - V.SOC_INITIAL) > 0.05  # what the OCV inverse alone gives


def test_error_bands_are_closed_on_the_right() -> None:
    """A 2.3 A h cell's 6.9 A peak (3C; 6.9 / 2.3 = 3.0000000000000004 in floating point) is in
    the 2-3C band, a rest in 0-0.5C, 3.1C in >3C."""
    import pandas as pd

    from hevsim.battery.identify import error_table

    ts = pd.DataFrame(
        {"current_a": [0.0, 1.15, 6.9, -6.9, 7.13], "voltage_error_v": [0.001, 0.002, 0.003, 0.005, 0.004],
         "temp_error_k": [0.0] * 5}
    )  # fmt: skip
    tab = error_table(ts, 2.3).set_index("range")
    assert list(tab.index) == ["0-0.5C", "2-3C", ">3C", "all"]
    assert tab.loc["0-0.5C", "samples"] == 2 and tab.loc["2-3C", "samples"] == 2
    assert tab.loc["2-3C", "mean_v"] == pytest.approx(0.004) and tab.loc[">3C", "samples"] == 1
