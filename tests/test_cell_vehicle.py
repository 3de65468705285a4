"""Integration point: the cell pack through the vehicle kernel's battery interface (item 8)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from numba import njit

from hevsim.battery import Module, load_cell_parameters
from hevsim.battery.vehicle import (
    battery_ecm,
    cell_bus_tables,
    cell_finish_current,
    quasi_static_pack,
    vehicle_parameter_values,
)
from hevsim.components.battery import current_for_power


@njit(cache=False)
def _loop(bat, power_w, v_out, i_out):
    """A vehicle bus's battery part: the step's pair of the power's direction, the current for
    the power, then the cells' step at that current."""
    for k in range(power_w.shape[0]):
        sgn = 1.0 if power_w[k] > 0.0 else -1.0
        ocv, r = battery_ecm(bat.sv, bat, 0.9, sgn)
        i = current_for_power(power_w[k], ocv, r)
        v_out[k] = ocv - r * i
        i_out[k] = i
        cell_finish_current(bat, i)


def test_ecm_kind_reproduces_the_module_model() -> None:
    rng = np.random.default_rng(2)
    power = np.repeat(rng.normal(100.0, 300.0, 60), 5)
    dt = 1.0
    bat = cell_bus_tables("thesis_table_4_1", 2, 6, 0.9, 298.15, dt, power.size)
    v = np.empty(power.size)
    i = np.empty(power.size)
    _loop(bat, power, v, i)
    np.testing.assert_allclose(v * i, power, rtol=1e-10)  # the power is delivered exactly
    m = Module("thesis_table_4_1", 2, 6, soc_initial=0.9, temp_k=298.15)
    r = m.simulate(i, dt, 298.15)
    np.testing.assert_allclose(r.timeseries["voltage_avg_v"], v, rtol=1e-9)
    assert bat.aux[6] == pytest.approx(r.cells[-1, 0, 2], rel=1e-12)  # cell temperature


def test_quasi_static_pack_values() -> None:
    p = load_cell_parameters("thesis_table_4_1")
    pack = quasi_static_pack(p, 2, 6, temp_k=313.0)
    r_dis = 0.014 * (1 + 0.013 * 0.0) + 0.005  # table temperature is T_ref (293 K): clamped
    assert float(pack.r_discharge_cell(0.5, 313.0)) == pytest.approx(r_dis)
    assert pack.capacity_cell_ah == pytest.approx(2880.0 * (1 - 1.6e-3 * 20) / 3600.0)
    vals = vehicle_parameter_values(p, 2, 6, 313.0)
    assert vals["bat_ns"] == 2.0 and vals["bat_capacity_ah"] == pytest.approx(pack.capacity_cell_ah)


def test_forward_simulator_with_dynamic_cell_pack(tmp_path: Path) -> None:
    """Issue 4 item 8: the series HEV runs on a pack of electro-thermal cells (battery kind
    "ecm") through the simulator's battery interface; the energy audit still closes and the
    result stays close to the same pack seen quasi-statically (no RC dynamics)."""
    import dataclasses

    from hevsim.config import load_config
    from hevsim.sim.model import build_series_hev
    from hevsim.sim.simulator import simulate, simulate_batch

    root = Path(__file__).resolve().parents[1]
    text = (root / "examples" / "series_hev.toml").read_text()
    start, end = text.index("[battery]"), text.index("[driver]")
    battery = (
        '[battery]\nmodel = "cell"\ndata = "saft_li_ion_6ah"\nn_series = 100\nn_parallel = 1\n'
        "max_discharge_current_a = 100.0\nmax_charge_current_a = 100.0\nsoc_min = 0.3\nsoc_max = 0.9\n\n"
    )
    (tmp_path / "car.toml").write_text(text[:start] + battery + text[end:])
    hev = build_series_hev(load_config(tmp_path / "car.toml"))
    assert hev.cell is not None
    dyn = simulate(hev, "udds")
    static = simulate(dataclasses.replace(hev, cell=None), "udds")
    assert dyn.value("energy_audit_residual_pct") < 1e-6
    assert dyn.value("fuel_equivalent_kg") == pytest.approx(static.value("fuel_equivalent_kg"), rel=0.05)
    assert 0.55 < dyn.value("soc_final") < 0.75
    again = simulate(hev, "udds")  # the cells' state is rebuilt per run: same inputs, same result
    assert again.value("fuel_kg") == dyn.value("fuel_kg")
    from hevsim.errors import ConfigError

    with pytest.raises(ConfigError, match="batch runs"):
        simulate_batch(hev, {"mass_kg": [1200.0, 1300.0]}, "fu505")
