"""R0(SOC, T) and the Arrhenius activation energy from pulse tests at several ambients (issue 14),
against PyBaMM's Thevenin ECM with a known activation energy (examples/validation/
make_arrhenius_data.py: Ea = 30 kJ/mol on R0 and R1, lumped cell thermal model)."""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest

from hevsim.battery import load_cell_parameters
from hevsim.battery.calibrate import CellTestRecord
from hevsim.battery.identify import _simulate, fit_temperature, identify
from hevsim.cli import main
from hevsim.errors import InputError

DATA = Path(__file__).resolve().parents[1] / "examples" / "validation"
TRUE = tomllib.loads((DATA / "arrhenius_parameters.toml").read_text())
EA_TOLERANCE = 0.02  # relative: the 1 s step resistance holds a little of R1 (same Ea)


def _rec(c: int) -> CellTestRecord:
    return CellTestRecord.from_csv(DATA / f"arrhenius_{c}c.csv")


@pytest.fixture(scope="module")
def fitted():
    res = identify("thesis_table_4_1", _rec(25), soc_initial=0.9, capacity_ah=5.0, port_temp_k=298.15)
    return res, fit_temperature(res, [_rec(10), _rec(40)])


def test_recovers_the_activation_energy_within_2_percent(fitted) -> None:
    _, res = fitted
    row = res.parameters.set_index("name").loc["r0_ea_j_per_mol"]
    ea_true = TRUE["ea_j_per_mol"]
    assert abs(row["value"] - ea_true) <= EA_TOLERANCE * ea_true, row
    assert row["ci95_low"] < row["value"] < row["ci95_high"] and row["std_error"] > 0
    assert row["flag"] == ""
    assert res.params.charge_transfer.ea_j_per_mol == pytest.approx(row["value"])


def test_r0_per_soc_and_temperature_follows_the_reference(fitted) -> None:
    """Step R0 per (SOC, ambient) against the generator's R0 (at the ambient: the cell warms by
    well under a kelvin in a 10 s pulse) plus the R1 share seen in one second."""
    _, res = fitted
    tab = res.r0_temperature
    assert sorted(tab["temp_k"].unique()) == pytest.approx([283.15, 298.15, 313.15])
    r_gas = 8.314462618
    for _, row in tab[tab["steps"] > 5].iterrows():
        f = np.exp(TRUE["ea_j_per_mol"] / r_gas * (1 / row["temp_k"] - 1 / TRUE["t_ref_k"]))
        r0 = TRUE["r0_ref_ohm"] * (1 + 0.5 * (row["soc"] - 0.5) ** 2) * f
        r1_1s = TRUE["r1_ref_ohm"] * f * (1 - np.exp(-1.0 / TRUE["tau1_s"]))
        assert row["r0_ohm"] == pytest.approx(r0 + r1_1s, rel=0.03), row


def test_temperature_tables_improve_the_cold_test(fitted) -> None:
    """The 10 degC test simulated with the identified set: with the R_s tables over
    temperature the voltage error is several times smaller than with the 25 degC set alone."""
    single, multi = fitted
    cold = _rec(10)
    err = []
    for res in (single, multi):
        soc0 = float(np.interp(cold.voltage_v[0], res.params.ocv_discharge_v[:, 0], res.params.soc))
        v, _ = _simulate(res.params, cold, soc0, 283.15, 283.15)
        err.append(float(np.sqrt(np.mean((v - cold.voltage_v) ** 2))))
    assert err[1] < 0.4 * err[0], err


def test_needs_two_ambients(fitted) -> None:
    res, _ = fitted
    same = _rec(25)
    flat = CellTestRecord(same.time_s, same.current_a, same.voltage_v, np.full_like(same.temp_k, 298.15))
    with pytest.raises(InputError, match="two ambients"):
        fit_temperature(res, [flat])
    with pytest.raises(InputError, match="no tests at other temperatures"):
        fit_temperature(res, [])


def test_cli_data_writes_temperature_tables(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "cal"
    args = ["calibrate", "thesis_table_4_1", str(DATA / "arrhenius_25c.csv"), "--soc-initial", "0.9"]
    args += ["--capacity-ah", "5", "--n-rc", "1", "--out", str(out)]
    args += ["--data", str(DATA / "arrhenius_10c.csv"), "--data", str(DATA / "arrhenius_40c.csv")]
    assert main(args) == 0
    assert "r0_ea_j_per_mol" in capsys.readouterr().out
    p = load_cell_parameters(out / "cell.toml")
    assert p.temperature_k.size == 3 and p.rs_discharge_ohm.shape == (p.soc.size, 3)
    from hevsim.battery import kernel as K

    def r_s(c: int) -> np.ndarray:  # R_s at the column's temperature (tables times the law, issue 27)
        return p.rs_discharge_ohm[:, c] * K.arrhenius(
            p.resistance.ea_j_per_mol, p.temperature_k[c], p.capacity.t_ref_k
        )

    assert np.all(r_s(0) > 1.5 * r_s(1))  # 10 degC vs 25 degC
    assert (out / "r0_temperature.csv").is_file()
    meta = tomllib.loads((out / "cell.toml").read_text())["source"]
    assert len(meta["temperature_sha256"]) == 2 and meta["ambient_temperatures_k"][0] == pytest.approx(283.15)
    # without a temperature column a test at another ambient says what is missing: exit 2
    bad = tmp_path / "no_temp.csv"
    bad.write_text("time_s,current_a,voltage_v\n1,0,4.0\n2,5,3.9\n")
    args2 = [*args[:-4], "--out", str(tmp_path / "cal2"), "--data", str(bad)]
    assert main(args2) == 2
    assert "temp_k" in capsys.readouterr().err


def test_shipped_data_match_their_provenance() -> None:
    import hashlib

    prov = tomllib.loads((DATA / "PROVENANCE_arrhenius.toml").read_text())["sha256"]
    assert len(prov) == 3
    for name, digest in prov.items():
        assert "sha256:" + hashlib.sha256((DATA / name).read_bytes()).hexdigest() == digest, name


def test_cli_data_needs_the_full_calibration(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    args = ["calibrate", "thesis_table_4_1", str(DATA / "arrhenius_25c.csv"), "--out", str(tmp_path / "x")]
    args += ["--fit", "c_heat_j_per_k=60,10,500", "--data", str(DATA / "arrhenius_10c.csv")]
    assert main(args) == 2
    assert "--data needs the full calibration" in capsys.readouterr().err
