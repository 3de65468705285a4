"""Bad cell parameter files and inputs fail early with clear messages (issue 4, item 10)."""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from tests.test_cell_model import cell_dict

from hevsim.battery import Cell, Module, load_cell_parameters
from hevsim.battery.params import parameters_from_dict
from hevsim.errors import ConfigError, HevsimError, InputError


def _with(path: str, value: Any) -> dict[str, Any]:
    d = copy.deepcopy(cell_dict())
    *head, last = path.split(".")
    node = d
    for h in head:
        node = node[h]
    node[last] = value
    return d


@pytest.mark.parametrize(
    ("path", "value", "needle"),
    [
        ("tables.soc", [1.0, 0.0], "not strictly increasing"),
        ("tables.ocv_discharge_v", [[3.9, 3.6]], "OCV decreases with SOC"),
        ("tables.ocv_charge_v", [[3.7, 4.5]], "outside the voltage limits"),
        ("tables.ocv_discharge_v", [[2.0, 3.7]], "outside the voltage limits"),
        ("capacity.c0_c", -5.0, "out of range"),
        ("tables.rs_charge_ohm", [[0.01, -0.01]], "must be > 0"),
        ("rc_discharge", [{"r_ohm": -0.01, "tau_s": 3.0}], "both must be finite and > 0"),
        ("rc_charge", [{"r_ohm": 0.01, "tau_s": 0.0}], "both must be finite and > 0"),
        ("rc_charge", [], "same number in both sets"),
        ("tables.rs_discharge_ohm", [[0.01, 0.01, 0.01]], "expected 1 temperature rows of 2"),
        ("thermal.c_heat_j_per_k", 0.0, "must be > 0"),
        ("capacity.alpha_c_per_k", -1.6, "negative at"),
        ("limits.v_max_v", 2.0, "must be below"),
        ("thermal.r_skin_k_per_w", "big", "wrong type"),
        ("thermal.foo", 1.0, "'thermal.foo' is not known"),
        ("tables.capacity_factor", [0.0], "one positive factor"),
    ],
)
def test_bad_parameter_values_name_the_key(path: str, value: Any, needle: str) -> None:
    with pytest.raises(HevsimError) as exc:
        parameters_from_dict(_with(path, value), "bad.toml")
    msg = str(exc.value)
    assert needle in msg
    assert "bad.toml" in msg


def test_missing_section_and_unknown_top_key() -> None:
    d = cell_dict()
    del d["thermal"]
    with pytest.raises(ConfigError, match=r"section \[thermal\] is missing"):
        parameters_from_dict(d, "x.toml")
    with pytest.raises(ConfigError, match="'colour' is not known"):
        parameters_from_dict({**cell_dict(), "colour": "red"}, "x.toml")


def test_unknown_set_name_lists_shipped_sets(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="thesis_table_4_1"):
        load_cell_parameters("no_such_cell")
    bad = tmp_path / "cell.toml"
    bad.write_text("[capacity\n")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_cell_parameters(bad)


def test_file_round_trip_and_file_error_names_file(tmp_path: Path) -> None:
    import shutil
    from importlib import resources

    src = Path(str(resources.files("hevsim") / "data" / "cells" / "thesis_table_4_1.toml"))
    f = tmp_path / "mine.toml"
    shutil.copy(src, f)
    assert load_cell_parameters(f).capacity.c0_c == 2880.0
    f.write_text(src.read_text().replace("ocv_discharge_v = [[3.124,", "ocv_discharge_v = [[3.5,"))
    with pytest.raises(InputError, match=r"mine.toml: key 'tables.ocv_discharge_v': OCV decreases"):
        load_cell_parameters(f)


def test_bad_simulation_inputs() -> None:
    cell = Cell("thesis_table_4_1")
    with pytest.raises(InputError, match="step 2 is not finite"):
        cell.simulate([1.0, 2.0, np.nan], 1.0)
    with pytest.raises(InputError, match="dt"):
        cell.simulate([1.0], 0.0)
    with pytest.raises(InputError, match="port_temperature"):
        cell.simulate([1.0, 2.0], 1.0, [300.0])
    with pytest.raises(InputError, match="soc_initial"):
        Cell("thesis_table_4_1", soc_initial=1.5)
    with pytest.raises(InputError, match="n_series"):
        Module("thesis_table_4_1", n_series=0)
    with pytest.raises(InputError, match="capacity_spread"):
        Module("thesis_table_4_1", capacity_spread=-0.1)
