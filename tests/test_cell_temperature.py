"""Temperature laws of the cell model (issue 27, item 1): without temperature data the shipped
(thesis) sets give today's outputs to 1e-12 (reference saved from the tree before the laws);
the entropic heat follows the closed form -I T dU/dT; Arrhenius laws of R_s, the RC elements
and the hysteresis scale as the closed form; the module and the pack use the same laws;
temperature tables not covering a run warn (clamped); bad values are refused by key."""

from __future__ import annotations

import math
import re
import sys
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from hevsim.battery import Cell, Module, load_cell_parameters, shipped_cells

DATA = Path(__file__).resolve().parent / "data" / "cell_thesis_outputs.npz"
CHANNELS = ("voltage_v", "voltage_avg_v", "ocv_v", "soc", "temp_k", "heat_w", "port_heat_w", "rs_ohm")
OPTIONS = {
    "thesis": {},
    "options": {"rc_mode": "persistent", "ocv_mode": "step_consistent", "i0": 4.0, "ea": 3e4, "hyst": 0.01},
}


def _profile() -> tuple[np.ndarray, np.ndarray]:
    """A 600 s pulse profile (1 s steps) with rests and charge, and a port ramp 263 -> 318 K."""
    k = np.arange(600)
    i = np.where(k % 300 < 120, 6.0, np.where(k % 300 < 200, 0.0, -4.0)) * (1.0 + 0.3 * np.sin(k / 37.0))
    port = 263.15 + 55.0 * k / k.size
    return i, port


def _params(name: str, opt: str) -> Any:
    p = load_cell_parameters(name)
    o = OPTIONS[opt]
    if not o:
        return p
    from dataclasses import replace

    return p.replace(
        model=replace(p.model, rc_mode=o["rc_mode"], ocv_mode=o["ocv_mode"]),
        charge_transfer=replace(p.charge_transfer, i0_a=o["i0"], ea_j_per_mol=o["ea"]),
        hysteresis=replace(p.hysteresis, max_v=o["hyst"], gamma=20.0),
    )


def thesis_outputs() -> dict[str, np.ndarray]:
    """Outputs of every shipped set, thesis model and with the model options: a cell (all
    :data:`CHANNELS` and the energy metrics) and a 2s3p module with spread."""
    i, port = _profile()
    out: dict[str, np.ndarray] = {}
    for name in shipped_cells():
        for opt in OPTIONS:
            p = _params(name, opt)
            scale = p.capacity.c0_c / 25326.0
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                res = Cell(p, soc_initial=0.9, temp_k=283.15).simulate(scale * i, 1.0, port)
                mod = Module(p, 2, 3, 0.85, 290.0, 0.03, 0.05, seed=7).simulate(3 * scale * i, 1.0, port)
            for ch in CHANNELS:
                out[f"{name}/{opt}/cell/{ch}"] = res.timeseries[ch].to_numpy()
            m = res.metrics
            out[f"{name}/{opt}/cell/energy"] = np.array(
                [
                    m["electrical_energy_out_j"],
                    m["chemical_energy_change_j"],
                    m["heat_j"],
                    m["rc_energy_change_j"],
                ]
            )
            for ch in ("voltage_v", "voltage_avg_v", "heat_w", "port_heat_w", "max_cell_temp_k"):
                out[f"{name}/{opt}/module/{ch}"] = mod.timeseries[ch].to_numpy()
    return out


def test_shipped_sets_unchanged_without_temperature_data() -> None:
    ref = np.load(DATA)
    got = thesis_outputs()
    assert set(ref.files) == set(got)
    for key in ref.files:
        scale = max(1.0, float(np.max(np.abs(ref[key]))))
        err = float(np.max(np.abs(got[key] - ref[key])))
        assert err <= 1e-12 * scale, f"{key}: max |new - saved| = {err:.3g}"


T_REF = 298.15
T_AX = [263.15, 298.15, 318.15]
SOC = [0.0, 0.25, 0.5, 0.75, 1.0]


def laws_dict(
    entropic_slope: float = 0.0,
    ea_rs: float = 0.0,
    rc_ea: tuple[float, float] = (0.0, 0.0),
    hyst_ea: float = 0.0,
    reversible: str = "off",
    r_skin: float = 2.0,
    c_heat: float = 100.0,
) -> dict[str, Any]:
    """A cell whose OCV has the entropic coefficient dU/dT = slope (SOC - 0.5) [V/K] around
    T_REF (OCV tables at T_AX), R_s constant over the tables, one RC pair per direction."""
    base = [3.4 + 0.6 * s for s in SOC]
    ocv = [
        [u + entropic_slope * (s - 0.5) * (t - T_REF) for u, s in zip(base, SOC, strict=True)] for t in T_AX
    ]
    rs = [[0.01] * len(SOC) for _ in T_AX]
    return {
        "name": "laws",
        "capacity": {"c0_c": 3600.0 * 5, "t_ref_k": T_REF},
        "resistance": {"ea_j_per_mol": ea_rs},
        "thermal": {"c_heat_j_per_k": c_heat, "r_skin_k_per_w": r_skin, "reversible_heat": reversible},
        "limits": {"v_min_v": 2.5, "v_max_v": 4.2},
        "hysteresis": {"max_v": 0.02 if hyst_ea else 0.0, "gamma": 30.0, "ea_j_per_mol": hyst_ea},
        "tables": {
            "soc": SOC,
            "temperature_k": T_AX,
            "ocv_charge_v": ocv,
            "ocv_discharge_v": ocv,
            "rs_charge_ohm": rs,
            "rs_discharge_ohm": rs,
        },
        "rc_discharge": [
            {"r_ohm": 0.02, "tau_s": 30.0, "ea_r_j_per_mol": rc_ea[0], "ea_tau_j_per_mol": rc_ea[1]}
        ],
        "rc_charge": [
            {"r_ohm": 0.015, "tau_s": 12.0, "ea_r_j_per_mol": rc_ea[0], "ea_tau_j_per_mol": rc_ea[1]}
        ],
    }


def laws(**kw: Any) -> Any:
    from hevsim.battery.params import parameters_from_dict

    return parameters_from_dict(laws_dict(**kw), "laws.toml")


def arrh(ea: float, t: float) -> float:
    return math.exp(ea / 8.314462618 * (1.0 / t - 1.0 / T_REF))


def test_entropic_heat_follows_closed_form_through_sign_change() -> None:
    """Constant 1C discharge from SOC 0.95 to 0.05 at a fixed port temperature: dU/dT =
    a (SOC - 0.5) changes sign at SOC 0.5, so the reversible heat -I T dU/dT cools the cell
    above it and heats it below; the extra heat over the same cell without it is the closed
    form to 1e-9 of the reversible heat, and the energy balance (enthalpy) still closes."""
    a = 4e-4  # V/K per unit SOC: dU/dT from -0.2 to +0.2 mV/K
    i = np.full(3240, 5.0)
    on = Cell(laws(entropic_slope=a, reversible="ocv_table"), soc_initial=0.95, temp_k=T_REF)
    off = Cell(laws(entropic_slope=a), soc_initial=0.95, temp_k=T_REF)
    r_on = on.simulate(i, 1.0, T_REF)
    r_off = off.simulate(i, 1.0, T_REF)
    ts = r_on.timeseries
    t0 = np.r_[T_REF, ts["temp_k"].to_numpy()[:-1]]  # cell temperature at each step's start
    soc0 = np.r_[0.95, ts["soc"].to_numpy()[:-1]]
    q_rev = -i * t0 * a * (soc0 - 0.5)  # W, closed form
    extra = ts["heat_w"].to_numpy() - r_off.timeseries["heat_w"].to_numpy()
    assert q_rev.max() > 0 > q_rev.min()  # heats and cools
    assert np.max(np.abs(extra - q_rev)) <= 1e-9 * np.max(np.abs(q_rev))
    hot, cold = soc0 < 0.45, soc0 > 0.55
    d_temp = ts["temp_k"].to_numpy() - r_off.timeseries["temp_k"].to_numpy()
    assert d_temp[cold].min() < -1e-3 and d_temp[hot][-1] > d_temp[cold].min()
    m = r_on.metrics
    assert abs(m["energy_balance_residual_j"]) <= 1e-9 * m["heat_j"]
    assert m["heat_j"] != pytest.approx(r_off.metrics["heat_j"], rel=1e-6)


@pytest.mark.parametrize("temp", [263.15, 298.15, 318.15])
def test_arrhenius_laws_of_rs_rc_and_hysteresis(temp: float) -> None:
    """A current step from rest at a held temperature: V = OCV - R_s(T) I - R_1(T) I (1 -
    exp(-t / tau_1(T))) - M(T), with every law exp(Ea/R_gas (1/T - 1/T_ref))."""
    ea_rs, ea_r, ea_tau, ea_h = 3e4, 4e4, 2e4, 1.5e4
    p = laws(ea_rs=ea_rs, rc_ea=(ea_r, ea_tau), hyst_ea=ea_h, r_skin=1e-9, c_heat=1.0)
    cell = Cell(p, soc_initial=0.6, temp_k=temp)
    cur = 2.0
    n = 200
    res = cell.simulate(np.full(n, cur), 1.0, temp)
    ts = res.timeseries
    t = np.arange(1, n + 1, dtype=float)
    soc0 = np.r_[0.6, ts["soc"].to_numpy()[:-1]]
    ocv = 3.4 + 0.6 * soc0
    r1, tau1 = 0.02 * arrh(ea_r, temp), 30.0 * arrh(ea_tau, temp)
    m_t = 0.02 * arrh(ea_h, temp)
    k = 30.0 * cur / p.capacity.c0_c  # hysteresis decay rate [1/s]
    h = -m_t * (1.0 - np.exp(-k * t))
    v = ocv - 0.01 * arrh(ea_rs, temp) * cur - r1 * cur * (1.0 - np.exp(-t / tau1)) + h
    np.testing.assert_allclose(ts["voltage_v"].to_numpy(), v, rtol=0, atol=1e-9)
    np.testing.assert_allclose(ts["rs_ohm"].to_numpy(), 0.01 * arrh(ea_rs, temp), rtol=1e-9)


def test_module_of_parallel_cells_uses_the_same_laws() -> None:
    """Two equal cells in parallel, each with every temperature law: each carries half the
    current and behaves as one cell at half the current (the module kernel's laws are the
    cell's)."""
    p = laws(entropic_slope=4e-4, reversible="ocv_table", ea_rs=3e4, rc_ea=(4e4, 2e4))
    i = np.where(np.arange(900) % 200 < 120, 8.0, -3.0)
    port = np.linspace(268.15, 313.15, i.size)
    mod = Module(p, 1, 2, 0.8, 283.15).simulate(i, 1.0, port)
    one = Cell(p, soc_initial=0.8, temp_k=283.15).simulate(i / 2, 1.0, port).timeseries
    np.testing.assert_allclose(mod.timeseries["voltage_v"], one["voltage_v"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(mod.timeseries["heat_w"], 2 * one["heat_w"], rtol=0, atol=1e-11)
    np.testing.assert_allclose(mod.timeseries["max_cell_temp_k"], one["temp_k"], rtol=0, atol=1e-11)


def test_tables_not_covering_the_run_warn_and_clamp() -> None:
    from hevsim.battery import params as P
    from hevsim.battery.params import TemperatureRangeWarning

    P._WARNED.clear()
    p = laws(entropic_slope=4e-4, reversible="ocv_table")
    with pytest.warns(
        TemperatureRangeWarning, match=r"tables\.temperature_k.*263\.15\.\.318\.15 K.*253\.15 K"
    ):
        cold = Cell(p, soc_initial=0.6, temp_k=253.15).simulate(np.zeros(5), 1.0, 253.15).timeseries
    edge = Cell(p, soc_initial=0.6, temp_k=263.15).simulate(np.zeros(5), 1.0, 263.15).timeseries
    np.testing.assert_array_equal(cold["ocv_v"], edge["ocv_v"])  # clamped at the 263.15 K column
    with warnings.catch_warnings():  # once per set and side: a run repeated in a loop warns once
        warnings.simplefilter("error")
        Cell(p, soc_initial=0.6, temp_k=250.0).simulate(np.zeros(5), 1.0, 250.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        Cell("thesis_table_4_1").simulate(np.ones(3), 1.0, 233.15)  # one column: no temperature data


def _one_column(tables: dict[str, Any]) -> dict[str, Any]:
    """The tables at T_REF only."""
    keys = ("ocv_charge_v", "ocv_discharge_v", "rs_charge_ohm", "rs_discharge_ohm")
    return {**tables, "temperature_k": [T_REF], **{k: [tables[k][1]] for k in keys}}


@pytest.mark.parametrize(
    ("change", "key", "text"),
    [
        (
            lambda d: d["rc_discharge"][0].update(ea_r_j_per_mol=3e5),
            "rc_discharge[0].ea_r_j_per_mol",
            "300000",
        ),
        (lambda d: d["rc_charge"][0].update(ea_tau_j_per_mol="x"), "rc_charge[0].ea_tau_j_per_mol", "'x'"),
        (lambda d: d["rc_charge"][0].update(ea_j=1.0), "rc_charge[0]", "ea_r_j_per_mol"),
        (lambda d: d["resistance"].update(ea_j_per_mol=5e5), "resistance.ea_j_per_mol", "500000"),
        (lambda d: d["thermal"].update(reversible_heat="yes"), "thermal.reversible_heat", "yes"),
        (lambda d: d.update(tables=_one_column(d["tables"])), "thermal.reversible_heat", "one column"),
    ],
)
def test_bad_temperature_law_values_are_refused_by_key(change: Any, key: str, text: str) -> None:
    from hevsim.battery.params import parameters_from_dict
    from hevsim.errors import HevsimError

    d = laws_dict(reversible="ocv_table")
    change(d)
    with pytest.raises(HevsimError, match=rf"laws\.toml.*{re.escape(key)}.*({text})"):
        parameters_from_dict(d, "laws.toml")


@pytest.mark.parametrize("n_parallel", [1, 2])
def test_native_fmu_with_temperature_laws_equals_cell(tmp_path: Path, n_parallel: int) -> None:
    """The native FMU generated from a set with every temperature law (OCV and R_s over three
    temperatures, entropic heat, Arrhenius R_s, RC and hysteresis, charge transfer) equals
    Cell.simulate / Module.simulate to 1e-12 over a pulse profile through a port ramp."""
    import shutil

    pytest.importorskip("fmpy")
    if not (shutil.which("cc") or shutil.which("gcc")):
        pytest.skip("no C compiler")
    from dataclasses import replace

    from tests.test_native_fmu import Runner

    from hevsim.battery.native import export_native_fmu

    p = laws(entropic_slope=4e-4, reversible="ocv_table", ea_rs=3e4, rc_ea=(4e4, 2e4), hyst_ea=1.5e4)
    rs = np.array([[0.012, 0.01, 0.009, 0.01, 0.013]]).T * np.array([[1.6, 1.0, 0.8]])
    p = p.replace(
        rs_discharge_ohm=rs,
        rs_charge_ohm=1.1 * rs,
        charge_transfer=replace(p.charge_transfer, i0_a=3.0, ea_j_per_mol=2e4),
    )
    fmu = export_native_fmu(p, tmp_path / "laws.fmu", 0.8, 283.15, n_parallel=n_parallel)
    i = n_parallel * np.where(
        np.arange(1500) % 300 < 150, 6.0, np.where(np.arange(1500) % 300 < 220, 0.0, -4.0)
    )
    port = np.linspace(268.15, 313.15, i.size)
    r = Runner(fmu)
    got = r.run({"current_a": i, "port_temp_k": port}, 1.0, ("voltage_v", "temp_k"))
    r.close()
    if n_parallel == 1:
        ts = Cell(p, soc_initial=0.8, temp_k=283.15).simulate(i, 1.0, port).timeseries
        ref_v, ref_t = ts["voltage_v"].to_numpy(), ts["temp_k"].to_numpy()
    else:
        mt = Module(p, 1, n_parallel, 0.8, 283.15).simulate(i, 1.0, port).timeseries
        ref_v, ref_t = mt["voltage_v"].to_numpy(), mt["max_cell_temp_k"].to_numpy()
    assert np.max(np.abs(got[:, 0] - ref_v)) <= 1e-12 * np.max(np.abs(ref_v))
    assert np.max(np.abs(got[:, 1] - ref_t)) <= 1e-12 * np.max(np.abs(ref_t))
    assert ref_t.max() - ref_t.min() > 30.0  # the run crosses the tables' temperatures


if __name__ == "__main__" and "--write-reference" in sys.argv:
    np.savez_compressed(DATA, **thesis_outputs())
    print(f"written {DATA}")
