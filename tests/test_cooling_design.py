"""Issue 12 item 5: the cooling-design sweep example (examples/cooling_design/), reduced: a
3 x 2 grid on the coolant-port pack over 120 s of the hot lap."""

from __future__ import annotations

import dataclasses
import importlib.util
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from hevsim.battery.pack import load_pack_config
from hevsim.errors import ConfigError

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "cooling_design"


@pytest.fixture(scope="module")
def sweep() -> Any:
    spec = importlib.util.spec_from_file_location("cooling_design_sweep", EXAMPLE / "sweep.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def reduced(sweep: Any) -> tuple[Any, pd.DataFrame]:
    study = dataclasses.replace(
        sweep.load_study(EXAMPLE / "cooling_design.toml"),
        pack=ROOT / "examples" / "pack_coolant.toml", duration_s=120.0,
        flows_l_min=(1.0, 4.0, 10.0), setpoints_c=(15.0, 30.0),
    )  # fmt: skip
    return study, sweep.run_study(study)


def _brute_force_front(f: np.ndarray) -> np.ndarray:
    """Row i is on the front iff no row j is <= in every objective and < in one."""
    n = f.shape[0]
    return np.array([
        not any(np.all(f[j] <= f[i]) and np.any(f[j] < f[i]) for j in range(n) if j != i) for i in range(n)
    ])  # fmt: skip


def test_pareto_set_matches_brute_force(sweep: Any, reduced: tuple[Any, pd.DataFrame]) -> None:
    study, table = reduced
    assert len(table) == 6
    assert study.pareto_objectives == ("peak_cell_temp_c", "cooling_energy_wh")  # the example's choice
    front = _brute_force_front(table[list(study.pareto_objectives)].to_numpy())
    np.testing.assert_array_equal(table["pareto"].to_numpy(), front)
    assert 0 < front.sum() < len(table)  # not a trivial front on this grid
    all3 = _brute_force_front(table[list(sweep.OBJECTIVES)].to_numpy())
    np.testing.assert_array_equal(sweep.pareto(table).to_numpy(), all3)
    # a random table too: the front of the example's function is the brute-force one
    rng = np.random.default_rng(3)
    rnd = pd.DataFrame(rng.integers(0, 5, size=(40, 3)).astype(float), columns=list(sweep.OBJECTIVES))
    np.testing.assert_array_equal(sweep.pareto(rnd).to_numpy(), _brute_force_front(rnd.to_numpy()))


def test_pump_energy_is_the_closed_form(reduced: tuple[Any, pd.DataFrame]) -> None:
    """Pump work = t Q dp / eta with dp = (loop + n plates in series) x (Q / Q_ref)^2."""
    study, table = reduced
    cfg = load_pack_config(study.pack)
    c = cfg.cooling
    for row in table.itertuples():
        q = row.flow_l_min / 60000.0
        dp = (c.loop_pressure_drop_pa + cfg.pack.n_modules * c.plate_pressure_drop_pa) * (
            row.flow_l_min / c.flow_ref_l_min
        ) ** 2
        assert row.pump_energy_wh == pytest.approx(
            study.duration_s * q * dp / c.pump_efficiency / 3600.0, rel=1e-9
        )


def test_designs_are_physical(reduced: tuple[Any, pd.DataFrame]) -> None:
    _, table = reduced
    assert (table["energy_balance_relative"].abs() < 1e-9).all()
    assert (table["max_spread_k"] > 0.0).all()
    by = table.set_index(["flow_l_min", "setpoint_c"])
    for q in (1.0, 4.0, 10.0):  # a colder set-point costs chiller energy and lowers the peak
        assert by.loc[(q, 15.0), "chiller_energy_wh"] > by.loc[(q, 30.0), "chiller_energy_wh"]
        assert by.loc[(q, 15.0), "peak_cell_temp_c"] < by.loc[(q, 30.0), "peak_cell_temp_c"]


def test_outputs_are_written(sweep: Any, reduced: tuple[Any, pd.DataFrame], tmp_path: Path) -> None:
    study, table = reduced
    out = sweep.save(table, study, tmp_path / "cd")
    for name in ("sweep.csv", "pareto.csv", "summary.md", "pareto.png"):
        assert (out / name).is_file(), name
    assert len(pd.read_csv(out / "pareto.csv")) == int(table["pareto"].sum())


@pytest.mark.parametrize(
    ("prefix", "suffix", "key"),
    [("flow = 3\n", "", "flow"), ("", '"cooling.flow_l_minute" = 3.0\n', "flow_l_minute")],
)
def test_study_file_unknown_keys(sweep: Any, tmp_path: Path, prefix: str, suffix: str, key: str) -> None:
    bad = tmp_path / "s.toml"
    text = (EXAMPLE / "cooling_design.toml").read_text(encoding="utf-8")
    text = text.replace('"../pack.toml"', repr(str(ROOT / "examples" / "pack_coolant.toml")))
    bad.write_text(prefix + text + suffix, encoding="utf-8")
    with pytest.raises(ConfigError, match=key):
        sweep.load_study(bad)
