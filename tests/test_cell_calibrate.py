"""Calibration recovers known parameters from noisy synthetic data (issue 4, item 5)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hevsim.battery import kernel as K
from hevsim.battery import load_cell_parameters
from hevsim.battery.calibrate import CellTestRecord, calibrate, simulate_record
from hevsim.errors import InputError


def _synthetic(noise: bool = True) -> CellTestRecord:
    """Thesis-like test: 20 A discharge for 300 s then 300 s rest, 23 degC ambient."""
    p = load_cell_parameters("thesis_table_4_1")
    t = np.arange(0.0, 601.0, 1.0)
    i = np.where((t > 0) & (t <= 300), 8.0, 0.0)  # 10 C on the 0.8 A h cell, then rest
    rec0 = CellTestRecord(t, i, np.zeros_like(t), np.full_like(t, 296.15))
    vec = p.vector(1.0)
    v, temp = simulate_record(p, vec, p.rc_discharge, p.rc_charge, rec0, 296.15)
    v[0] = p.ocv_discharge_v[-1, 0]
    if noise:
        rng = np.random.default_rng(0)
        v = v + rng.normal(0, 0.002, v.size)
        temp = temp + rng.normal(0, 0.05, v.size)
    return CellTestRecord(t, i, v, temp, "synthetic")


def test_recovers_known_parameters_from_noisy_data(tmp_path: Path) -> None:
    rec = _synthetic()
    fit = {
        "c_heat_j_per_k": (60.0, 10.0, 500.0),
        "r_skin_k_per_w": (5.0, 0.5, 50.0),
        "rc_discharge[0].r_ohm": (0.01, 1e-4, 0.1),
        "rc_discharge[0].tau_s": (40.0, 1.0, 300.0),
    }
    res = calibrate(
        "thesis_table_4_1", rec, fit, soc_initial=1.0, port_temp_k=296.15, sigma_v=0.002, sigma_t=0.05
    )
    truth = {"c_heat_j_per_k": 96.0, "r_skin_k_per_w": 10.0, "rc_discharge[0].r_ohm": 0.005,
             "rc_discharge[0].tau_s": 20.0}  # fmt: skip
    for k, v in truth.items():
        assert res.values[k] == pytest.approx(v, rel=0.05), k
        assert abs(res.values[k] - v) < 4 * res.std_errors[k] + 1e-12, k
    assert res.rmse["voltage_v"] < 0.003 and res.rmse["temp_k"] < 0.08
    out = res.save(tmp_path / "fit")
    assert {f.name for f in out.iterdir()} == {"fit.json", "timeseries.csv", "overlay.png", ".hevsim-results"}


def test_test_file_errors(tmp_path: Path) -> None:
    f = tmp_path / "t.csv"
    f.write_text("time_s,current_a,voltage_v\n0,1,3.7\n1,1,3.6\n2,1,3.6\n")
    with pytest.raises(InputError, match="temp_k"):
        CellTestRecord.from_csv(f)
    f.write_text("time_s,current_a,voltage_v,temp_k\n0,1,3.7,300\n1,1,3.6,300\n2,1,3.6,300\n7,1,3.6,300\n")
    with pytest.raises(InputError, match=r"not uniformly sampled: step 5\.0 s after 2\.0 s"):
        CellTestRecord.from_csv(f)
    rec = _synthetic(noise=False)
    with pytest.raises(InputError, match="not fittable"):
        calibrate("thesis_table_4_1", rec, {"colour": (1.0, 0.0, 2.0)})
    with pytest.raises(InputError, match="RC element"):
        calibrate("thesis_table_4_1", rec, {"rc_charge[3].r_ohm": (0.01, 0.0, 1.0)})
    with pytest.raises(InputError, match="lower < upper"):
        calibrate("thesis_table_4_1", rec, {"c_heat_j_per_k": (1.0, 5.0, 2.0)})


def test_calibrate_and_cell_commands(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    import json

    import pandas as pd

    from hevsim.cli import main

    rec = _synthetic(noise=False)
    csv = tmp_path / "test.csv"
    cols = {
        "time_s": rec.time_s,
        "current_a": rec.current_a,
        "voltage_v": rec.voltage_v,
        "temp_k": rec.temp_k,
    }
    pd.DataFrame(cols).to_csv(csv, index=False)
    out = tmp_path / "fit"
    args = ["calibrate", "thesis_table_4_1", str(csv), "--fit", "c_heat_j_per_k=60,10,500"]
    assert main([*args, "--ambient-c", "23", "--out", str(out)]) == 0
    fit = json.loads((out / "fit.json").read_text())
    assert fit["values"]["c_heat_j_per_k"] == pytest.approx(96.0, rel=1e-3)
    assert "RMSE" in capsys.readouterr().out
    assert main([*args[:-1], "c_heat=1,2", "--out", str(tmp_path / "bad")]) == 2
    assert "NAME=INITIAL,LOWER,UPPER" in capsys.readouterr().err
    root = Path(__file__).resolve().parents[1]
    assert main(["cell", str(root / "examples" / "cell.toml"), "--out", str(tmp_path / "cell")]) == 0
    assert (tmp_path / "cell" / "timeseries.csv").is_file()


# --- full calibration (issue 14): OCV and R_s tables, RC, charge transfer, thermal -------------

_AXIS = np.array([0.0, 0.65, 0.75, 0.85, 0.95, 1.0])
_OCV = np.array([3.3, 3.85, 3.93, 4.02, 4.10, 4.14])
_RS = np.array([0.024, 0.021, 0.020, 0.019, 0.018, 0.018])


def _true_cell(rc=((0.006, 12.0), (0.010, 200.0)), i0=4.0):
    from hevsim.battery.params import (
        CapacitySection,
        ChargeTransferSection,
        ModelSection,
        ThermalSection,
    )

    p = load_cell_parameters("thesis_table_4_1")
    rc_arr = np.array(rc, float)
    return p.replace(
        soc=_AXIS, temperature_k=np.array([298.15]), capacity_factor=np.ones(1),
        ocv_charge_v=_OCV[:, None].copy(), ocv_discharge_v=_OCV[:, None].copy(),
        rs_charge_ohm=_RS[:, None].copy(), rs_discharge_ohm=_RS[:, None].copy(),
        rc_discharge=rc_arr, rc_charge=rc_arr.copy(),
        capacity=CapacitySection(c0_c=5.0 * 3600.0, t_ref_k=298.15),
        resistance=p.resistance.__class__(alpha_rs_per_k=0.0),
        thermal=ThermalSection(70.0, 8.0),
        model=ModelSection(rc_mode="persistent", ocv_mode="step_consistent"),
        charge_transfer=ChargeTransferSection(i0_a=i0, scale=1.5) if i0 else ChargeTransferSection(),
    )  # fmt: skip


def _hppc(p, levels: int, seed: int = 1) -> CellTestRecord:
    """Pulses 1C/2C/3C both ways at each level, 0.1 SOC discharges, 900 s rests; noisy."""
    from hevsim.battery.identify import _simulate

    seg = [(0.0, 600)]
    for _ in range(levels):
        for rate in (1.0, 2.0, 3.0):
            seg += [(5 * rate, 10), (0.0, 40), (-5 * rate, 10), (0.0, 40)]
        seg += [(5.0, 360), (0.0, 900)]
    cur = np.concatenate([np.full(d, c) for c, d in seg])
    t = np.arange(1, cur.size + 1, dtype=float)
    v, temp = _simulate(p, CellTestRecord(t, cur, t * 0, t * 0 + 298.15), 0.95, 298.15, 298.15)
    rng = np.random.default_rng(seed)
    v = v + rng.normal(0, 0.5e-3, v.size)
    return CellTestRecord(t, cur, v, temp + rng.normal(0, 0.02, v.size), "synthetic")


@pytest.fixture(scope="module")
def identified():
    from hevsim.battery.identify import identify

    rec = _hppc(_true_cell(), levels=3)
    return rec, identify("thesis_table_4_1", rec, soc_initial=0.95, capacity_ah=5.0, port_temp_k=298.15)


def test_full_calibration_recovers_ocv_and_r_tables_rc_charge_transfer_thermal(identified) -> None:
    _, res = identified
    tab = res.parameters.set_index("name")
    for s, v in zip(_AXIS[1:-1], _OCV[1:-1], strict=True):
        assert tab.loc[f"ocv_v[soc={s:.3f}]", "value"] == pytest.approx(v, abs=0.5e-3)
    for s, r in zip(_AXIS[1:-1], _RS[1:-1], strict=True):
        assert tab.loc[f"rs_ohm[soc={s:.3f}]", "value"] == pytest.approx(r, rel=0.05)
    truth = {"rc[0].r_ohm": 0.006, "rc[0].tau_s": 12.0, "rc[1].r_ohm": 0.010, "rc[1].tau_s": 200.0,
             "ct_i0_a": 4.0, "ct_scale": 1.5, "c_heat_j_per_k": 70.0, "r_skin_k_per_w": 8.0}  # fmt: skip
    for name, v in truth.items():
        row = tab.loc[name]
        assert row["value"] == pytest.approx(v, rel=0.1 if name.startswith("ct") else 0.02), name
        assert row["flag"] == "", name
    # the intervals cover the truth (a 99.9 % margin: 3.3 standard errors)
    for name, v in truth.items():
        assert abs(tab.loc[name, "value"] - v) < 3.3 * tab.loc[name, "std_error"] + 1e-3 * v, name
    assert res.rmse["voltage_v"] < 0.6e-3 and res.rmse["temp_k"] < 0.025
    assert res.flagged().empty


def test_full_calibration_writes_a_loadable_parameter_set(identified, tmp_path: Path) -> None:
    from hevsim.battery.identify import _simulate
    from hevsim.battery.vehicle import ecm_kernel_tables

    rec, res = identified
    out = res.save(tmp_path / "cal")
    files = {f.name for f in out.iterdir()}
    assert {"cell.toml", "tables.csv", "parameters.csv", "fit.json", "timeseries.csv", "fit.png"} <= files
    p = load_cell_parameters(out / "cell.toml")
    assert p.model.rc_mode == "persistent" and p.charge_transfer.i0_a == res.params.charge_transfer.i0_a
    text = (out / "cell.toml").read_text()
    assert "source_sha256" in text and "fitted_soc_range" in text
    v, _ = _simulate(p, rec, 0.95, 298.15, 298.15)
    np.testing.assert_allclose(v, res.timeseries["voltage_fitted_v"], atol=1e-9)

    bat = ecm_kernel_tables(p, 96, 1, 0.8, 298.15, dt_s=1.0)  # the vehicle's cell pack takes it
    assert bat.params[K.RCPERS] == 1.0 and bat.params[K.CTI0] > 0


def test_full_calibration_flags_an_unidentifiable_parameter() -> None:
    """A third RC pair the data cannot tell from the second is flagged with the reason."""
    from hevsim.battery.identify import identify

    rec = _hppc(_true_cell(i0=0.0), levels=1, seed=2)
    res = identify(
        "thesis_table_4_1", rec, soc_initial=0.95, capacity_ah=5.0, port_temp_k=298.15, n_rc=3,
        charge_transfer=False,
    )  # fmt: skip
    flagged = res.flagged()
    assert not flagged.empty
    assert flagged["name"].str.startswith("rc[").all()
    assert flagged["flag"].str.contains("correlation|standard error|longer than|bound").all()


def test_full_calibration_bad_inputs_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    import pandas as pd

    from hevsim.cli import main

    t = np.arange(1.0, 401.0)
    i = np.where(t % 20 < 10, 5.0, -5.0)  # pulses, never a rest
    f = tmp_path / "norest.csv"
    pd.DataFrame({"time_s": t, "current_a": i, "voltage_v": 3.7 - 0.02 * i, "temp_k": 298.15}).to_csv(
        f, index=False
    )
    base = ["calibrate", "thesis_table_4_1"]
    assert main([*base, str(f), "--capacity-ah", "5", "--out", str(tmp_path / "o1")]) == 2
    assert "no rest periods" in capsys.readouterr().err
    g = tmp_path / "nocurrent.csv"
    g.write_text("time_s,voltage_v,temp_k\n1,3.7,298\n2,3.7,298\n3,3.7,298\n")
    assert main([*base, str(g), "--out", str(tmp_path / "o2")]) == 2
    assert "current_a" in capsys.readouterr().err
    h = tmp_path / "backwards.csv"
    h.write_text("time_s,current_a,voltage_v,temp_k\n1,0,3.7,298\n2,0,3.7,298\n3,0,3.7,298\n2,0,3.7,298\n")
    assert main([*base, str(h), "--out", str(tmp_path / "o3")]) == 2
    assert "time_s" in capsys.readouterr().err
    bad = tmp_path / "bad.toml"
    text = Path(load_cell_parameters("thesis_table_4_1").source).read_text()
    bad.write_text(text.replace("rs_charge_ohm", "rs_charge_ohm_missing"))
    assert main(["calibrate", str(bad), str(f), "--out", str(tmp_path / "o4")]) == 2
    assert "rs_charge_ohm" in capsys.readouterr().err
    assert main([*base, str(f), "--capacity-ah", "-1", "--out", str(tmp_path / "o5")]) == 2
    assert "capacity" in capsys.readouterr().err


def test_full_calibration_cli_with_validation(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """hevsim calibrate without --fit, validated on a second record of the same cell."""
    import pandas as pd

    from hevsim.battery.identify import _simulate
    from hevsim.cli import main

    p = _true_cell()
    rec = _hppc(p, levels=2, seed=4)
    files = {}
    t = np.arange(1.0, 601.0)
    cur = 12.0 * np.sin(t / 23.0) + 3.0 * np.sign(np.sin(t / 7.0))  # reversals, 0-3C
    val_v, val_t = _simulate(p, CellTestRecord(t, cur, t * 0, t * 0 + 298.15), 0.88, 298.15, 298.15)
    for name, (tt, i, v, temp) in {
        "pulse": (rec.time_s, rec.current_a, rec.voltage_v, rec.temp_k),
        "drive": (t, cur, val_v, val_t),
    }.items():
        files[name] = tmp_path / f"{name}.csv"
        cols = {"time_s": tt, "current_a": i, "voltage_v": v, "temp_k": temp}
        if name == "pulse":  # a test without a temperature signal: the ambient stands in
            del cols["temp_k"]
        pd.DataFrame(cols).to_csv(files[name], index=False)
    out = tmp_path / "cal"
    args = ["calibrate", "thesis_table_4_1", str(files["pulse"]), "--soc-initial", "0.95"]
    args += ["--capacity-ah", "5", "--ambient-c", "25", "--validate", str(files["drive"])]
    assert main([*args, "--validate-soc", "0.88", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "validation on" in text and "cell.toml" in text
    errors = pd.read_csv(out / "validation_errors.csv").set_index("range")
    assert errors.loc["all", "rmse_v"] < 2e-3  # the same cell: noise-level agreement
    assert (out / "validation.png").is_file()
    fitted = pd.read_csv(out / "parameters.csv")["name"]
    assert "c_heat_j_per_k" not in set(fitted)  # no temperature, no thermal fit
    assert '"temperature_measured": false' in (out / "fit.json").read_text()
    run = tmp_path / "run.toml"  # `hevsim cell` runs the written set as it is
    run.write_text(
        f'[cell]\nparameters = "{out / "cell.toml"}"\nsoc_initial = 0.8\ntemp_c = 25.0\n'
        '[profile]\nkind = "constant"\ncurrent_a = 10.0\nduration_s = 60.0\ndt_s = 1.0\n'
        "[thermal]\nport_temp_c = 25.0\n"
    )
    assert main(["cell", str(run), "--out", str(tmp_path / "x")]) == 0
    assert main([*args[:5], "--fit", "c_heat_j_per_k=60,10,500", "--validate", str(files["drive"]),
                 "--out", str(tmp_path / "y")]) == 2  # fmt: skip
    assert "--validate needs the full calibration" in capsys.readouterr().err


def test_written_parameter_set_is_accepted_by_export_fmu_the_vehicle_and_the_pack(
    identified, tmp_path: Path
) -> None:
    """The written cell.toml as it is (issue 14 item 2): `hevsim export-fmu` builds a native FMU of
    it that equals Cell.simulate, the series HEV's battery.model = "cell" runs UDDS on it with the
    energy audit closed, and a pack file's [cells] parameters takes it."""
    import dataclasses
    import shutil

    from hevsim.battery import Cell
    from hevsim.battery.pack import Pack, load_pack_config
    from hevsim.cli import main
    from hevsim.config import load_config
    from hevsim.sim.model import build_series_hev
    from hevsim.sim.simulator import simulate

    _, res = identified
    out = res.save(tmp_path / "cal")
    p = load_cell_parameters(out / "cell.toml")
    root = Path(__file__).resolve().parents[1]
    cur = np.concatenate([np.full(60, 10.0), np.full(30, -8.0), np.zeros(30), np.full(20, 15.0)])

    if shutil.which("cc") or shutil.which("gcc"):  # the native FMU (needs a C compiler and FMPy)
        pytest.importorskip("fmpy")
        from fmpy import extract, read_model_description
        from fmpy.fmi2 import FMU2Slave

        cfg = tmp_path / "run.toml"
        cfg.write_text(
            f'[cell]\nparameters = "{out / "cell.toml"}"\nsoc_initial = 0.8\ntemp_c = 25.0\n'
            '[profile]\nkind = "constant"\ncurrent_a = 10.0\nduration_s = 60.0\ndt_s = 1.0\n'
            "[thermal]\nport_temp_c = 25.0\n"
        )
        fmu = tmp_path / "cal.fmu"
        assert main(["export-fmu", str(cfg), "-o", str(fmu)]) == 0
        md = read_model_description(str(fmu))
        vr = {v.name: v.valueReference for v in md.modelVariables}
        slave = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(fmu)),
                          modelIdentifier=md.coSimulation.modelIdentifier, instanceName="cal")  # fmt: skip
        slave.instantiate()
        slave.setupExperiment(startTime=0.0)
        slave.enterInitializationMode()
        slave.exitInitializationMode()
        v_fmu = np.empty(cur.size)
        for k, i in enumerate(cur):
            slave.setReal([vr["current_a"], vr["port_temp_k"]], [float(i), 298.15])
            slave.doStep(float(k), 1.0)
            v_fmu[k] = slave.getReal([vr["voltage_v"]])[0]
        slave.terminate()
        slave.freeInstance()
        ref = Cell(p, soc_initial=0.8, temp_k=298.15).simulate(cur, 1.0, 298.15).timeseries["voltage_v"]
        np.testing.assert_allclose(v_fmu, ref.to_numpy(), rtol=0, atol=1e-12)

    text = (root / "examples" / "series_hev.toml").read_text()
    start, end = text.index("[battery]"), text.index("[driver]")
    battery = (
        f'[battery]\nmodel = "cell"\ndata = "{out / "cell.toml"}"\nn_series = 96\nn_parallel = 1\n'
        "max_discharge_current_a = 100.0\nmax_charge_current_a = 100.0\nsoc_min = 0.3\nsoc_max = 0.9\n\n"
    )
    (tmp_path / "car.toml").write_text(text[:start] + battery + text[end:])
    hev = build_series_hev(load_config(tmp_path / "car.toml"))
    assert hev.cell is not None and hev.cell.charge_transfer == p.charge_transfer
    run = simulate(hev, "udds")
    assert run.value("energy_audit_residual_pct") < 1e-6 and 0.3 < run.value("soc_final") < 0.9

    pack_cfg = load_pack_config(root / "examples" / "pack_coolant.toml")
    pack_cfg = dataclasses.replace(
        pack_cfg, cells=dataclasses.replace(pack_cfg.cells, parameters=str(out / "cell.toml"))
    )
    pack = Pack(pack_cfg)  # (a run compiles the pack's kernels: minutes on a cold cache)
    assert pack.params.model == p.model and pack.params.charge_transfer == p.charge_transfer
    np.testing.assert_array_equal(pack.params.ocv_discharge_v, p.ocv_discharge_v)
