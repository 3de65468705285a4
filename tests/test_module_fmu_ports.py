"""Module FMU with per-cell thermal ports: a drop-in replacement for ModuleCellsParticipant
(same variable names, same results), units in its model description, FMU state round trip.

FMUs run only in worker processes (in-process pythonfmu FMUs can abort the test process at
exit)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from hevsim.battery.fmu import export_fmu, simulate_fmu
from hevsim.cosim.participant import ModuleCellsParticipant
from hevsim.cosim.worker import WorkerFMUParticipant

N_S, N_P, SOC0, TEMP0 = 2, 6, 0.9, 303.15
N_CELLS = N_S * N_P
PARAMS = {"power_input": True, "per_cell_ports": True, "soc_initial": SOC0, "temp_initial_k": TEMP0}


@pytest.fixture(scope="module")
def module_fmu(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("module_fmu") / "module_2s6p.fmu"
    return export_fmu(
        "thesis_table_4_1", out, soc_initial=SOC0, temp_initial_k=TEMP0, n_series=N_S, n_parallel=N_P
    )


@pytest.fixture
def fmu_participant(module_fmu: Path) -> Iterator[WorkerFMUParticipant]:
    p = WorkerFMUParticipant("module", module_fmu, PARAMS)
    try:
        yield p
    finally:
        p.close()


def power_w(k: int) -> float:
    """A +-250 / 150 W square power (discharge > 0) switching every 5 s."""
    return 250.0 if (k // 5) % 2 == 0 else -150.0


def port_temps_k(k: int) -> dict[str, float]:
    """Port temperatures that differ per cell and in time."""
    return {f"cell{c}_port_temp_k": TEMP0 - 3.0 + 0.4 * c + 2.0 * np.sin(0.2 * k + c) for c in range(N_CELLS)}


def drive(p: object, n: int, h: float = 1.0, t0: float = 0.0, k0: int = 0) -> list[dict[str, float]]:
    """Step ``p`` (a participant) n steps; the outputs after each step."""
    rows = []
    for k in range(k0, k0 + n):
        p.set_inputs({"power_w": power_w(k), **port_temps_k(k)})  # type: ignore[attr-defined]
        ok, _ = p.do_step(t0 + (k - k0) * h, h)  # type: ignore[attr-defined]
        assert ok
        rows.append(p.get_outputs())  # type: ignore[attr-defined]
    return rows


def test_module_fmu_has_the_per_cell_interface(fmu_participant: WorkerFMUParticipant) -> None:
    ref = ModuleCellsParticipant("ref", "thesis_table_4_1", SOC0, TEMP0, N_S, N_P, power_input=True)
    assert set(ref.inputs) <= set(fmu_participant.inputs)
    assert set(ref.outputs) - set(fmu_participant.outputs) == {"current_a"}  # an FMU input, see below
    assert fmu_participant.outputs["terminal_current_a"] == "A"  # the drawn current as an output
    for name, unit in ref.outputs.items():
        if name in fmu_participant.outputs and unit != "1":
            assert fmu_participant.outputs[name] == unit, name
    for name, unit in ref.inputs.items():
        assert fmu_participant.inputs[name] == unit, name


def test_module_fmu_reproduces_module_cells_participant(fmu_participant: WorkerFMUParticipant) -> None:
    ref = ModuleCellsParticipant("ref", "thesis_table_4_1", SOC0, TEMP0, N_S, N_P, power_input=True)
    ref.setup(0.0)
    fmu_participant.setup(0.0)
    got0, ref0 = fmu_participant.get_outputs(), ref.get_outputs()
    same = {"terminal_current_a": "current_a"}  # FMU output -> participant output
    for name, value in got0.items():
        np.testing.assert_allclose(value, ref0[same.get(name, name)], rtol=1e-12, err_msg=f"initial {name}")
    n = 50
    got, want = drive(fmu_participant, n), drive(ref, n)
    for name in got[0]:
        np.testing.assert_allclose(
            [r[name] for r in got],
            [r[same.get(name, name)] for r in want],
            rtol=1e-9,
            atol=1e-12,
            err_msg=name,
        )
    cells_t = np.array([[r[f"cell{c}_temp_k"] for c in range(N_CELLS)] for r in got])
    assert np.ptp(cells_t[-1]) > 0.1  # the cells really see different port temperatures
    heat = np.array([[r[f"cell{c}_port_heat_w"] for c in range(N_CELLS)] for r in got])
    np.testing.assert_allclose(heat.sum(axis=1), [r["port_heat_w"] for r in got], rtol=1e-9, atol=1e-9)


def test_module_fmu_solved_current_is_readable(module_fmu: Path) -> None:
    """With power input the FMU's ``current_a`` (an input variable) reads as the solved current."""
    n = 20
    power = np.array([power_w(k) for k in range(n)])
    cells = np.array([list(port_temps_k(k).values()) for k in range(n)])
    got = simulate_fmu(
        module_fmu, None, TEMP0, 1.0, parameters={"soc_initial": SOC0}, power_w=power, cell_port_temps_k=cells
    )
    ref = ModuleCellsParticipant("ref", "thesis_table_4_1", SOC0, TEMP0, N_S, N_P, power_input=True)
    ref.setup(0.0)
    want = drive(ref, n)
    np.testing.assert_allclose(got["current_a"], [r["current_a"] for r in want], rtol=1e-9)
    np.testing.assert_allclose(got["voltage_v"], [r["voltage_v"] for r in want], rtol=1e-9)
    assert np.all(np.sign(got["current_a"]) == np.sign(power))


def test_module_fmu_lumped_port_is_default(module_fmu: Path) -> None:
    """per_cell_ports false (default): every cell uses port_temp_k; the cell inputs are ignored."""
    p = WorkerFMUParticipant("module", module_fmu, {"power_input": True})
    try:
        p.setup(0.0)
        p.set_inputs({"power_w": 250.0, "port_temp_k": 290.0, **port_temps_k(0)})
        p.do_step(0.0, 10.0)
        out = p.get_outputs()
    finally:
        p.close()
    ref = ModuleCellsParticipant("ref", "thesis_table_4_1", SOC0, TEMP0, N_S, N_P, power_input=True)
    ref.setup(0.0)
    ref.set_inputs({"power_w": 250.0, **{f"cell{c}_port_temp_k": 290.0 for c in range(N_CELLS)}})
    ref.do_step(0.0, 10.0)
    want = ref.get_outputs()
    want["terminal_current_a"] = want["current_a"]
    for name, value in out.items():
        np.testing.assert_allclose(value, want[name], rtol=1e-9, atol=1e-12, err_msg=name)


def test_module_fmu_declares_units(module_fmu: Path) -> None:
    from fmpy import read_model_description
    from fmpy.validation import validate_fmu

    assert validate_fmu(str(module_fmu)) == []
    md = read_model_description(str(module_fmu))
    units = {v.name: v.unit for v in md.modelVariables}
    assert units["cell0_port_temp_k"] == "K"
    assert units[f"cell{N_CELLS - 1}_port_heat_w"] == "W"
    assert units["cell3_temp_k"] == "K"
    assert units["voltage_v"] == "V"
    assert units["current_a"] == "A"
    assert units["power_w"] == "W"
    assert units["c_heat_j_per_k"] == "J/K"
    assert units["r_skin_k_per_w"] == "K/W"
    assert units["alpha_c_per_k"] == "1/K"
    assert units["soc"] is None and units["soh"] is None and units["soc_initial"] is None
    defs = {u.name: u.baseUnit for u in md.unitDefinitions}
    assert defs["K"].K == 1 and defs["W"].kg == 1 and defs["W"].m == 2 and defs["W"].s == -3
    assert (defs["V"].kg, defs["V"].m, defs["V"].s, defs["V"].A) == (1, 2, -3, -1)
    assert md.coSimulation.canGetAndSetFMUstate and md.coSimulation.canSerializeFMUstate


def test_module_fmu_state_round_trip_is_bit_identical(fmu_participant: WorkerFMUParticipant) -> None:
    p = fmu_participant
    p.setup(0.0)
    drive(p, 12)
    state = p.get_state()
    assert isinstance(state, bytes) and state
    first = drive(p, 15, t0=12.0, k0=12)
    p.set_state(state)
    second = drive(p, 15, t0=12.0, k0=12)
    assert first == second  # bit-identical: same floats, every output


def test_module_fmu_state_resumes_in_a_new_instance(module_fmu: Path) -> None:
    """Checkpoint/resume: a state serialised by one FMU instance continues in another."""
    a = WorkerFMUParticipant("a", module_fmu, PARAMS)
    b = WorkerFMUParticipant("b", module_fmu, {"soc_initial": 0.5})  # different start: overwritten
    try:
        a.setup(0.0)
        drive(a, 8)
        state = a.get_state()
        first = drive(a, 10, t0=8.0, k0=8)
        b.setup(0.0)
        b.set_state(state)
        assert drive(b, 10, t0=8.0, k0=8) == first
    finally:
        a.close()
        b.close()
