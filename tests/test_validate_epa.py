"""The EPA validation (hevsim.validation, benchmarks/validate_epa.py) on a few vehicles of each data set.

The full tables are the benchmark's; here a handful of vehicles, with their errors against the EPA
figures asserted (FASTSim database: the issue's median goal of 5 %; Test Car List: a deterministic
sample of the held-out half, HWY within the goal, FTP within what the full validation achieves,
docs/validation.md).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from hevsim.errors import ConfigError
from hevsim.validation import fastsim_db as F
from hevsim.validation import test_car_list as T

FASTSIM_ROWS = (1, 3, 20, 22)
"""2016 Corolla, 2016 Camry (conventional), 2016 Leaf 30 kWh, 2016 Tesla Model S60 (BEV)."""


def test_fastsim_database_rows_within_the_goal() -> None:
    rows = F.validate(only=list(FASTSIM_ROWS), with_fastsim=True)
    assert [r.row for r in rows] == list(FASTSIM_ROWS)
    errors = np.abs([r.error("hevsim") for r in rows])
    assert np.all(np.isfinite(errors))
    assert np.all(errors <= 0.05), [(r.name, r.hevsim, r.epa) for r in rows]
    theirs = np.array([r.fastsim for r in rows])
    if np.all(np.isfinite(theirs)):  # FASTSim installed (the bench extra): the peer, same vehicle file
        assert np.array([r.hevsim for r in rows]) == pytest.approx(theirs, rel=0.05)
    bev = rows[2]
    assert bev.unit == "kWh/mi" and 0.2 < bev.hevsim < 0.4


HEV_ROWS = (9, 10, 11)
"""2016 Ford C-MAX HEV, 2016 Kia Optima Hybrid, 2016 Toyota Highlander Hybrid: every database HEV."""


def test_fastsim_database_hybrids_within_the_class_goal() -> None:
    """Issue 25: no powertrain class median above 8 %. The imported HEV carries FASTSim's HEV
    rules (engine forced on above ``mph_fc_on``, peak-efficiency floor, idle fuel); with the old
    electric-assist mapping the Optima and the Highlander Hybrid were +18 % and +31 %."""
    rows = F.validate(only=list(HEV_ROWS), with_fastsim=True)
    assert [r.row for r in rows] == list(HEV_ROWS) and all(r.powertrain == "HEV" for r in rows)
    errors = np.abs([r.error("hevsim") for r in rows])
    assert np.all(np.isfinite(errors))
    assert np.median(errors) <= 0.05 and np.all(errors <= 0.08), [(r.name, r.hevsim, r.epa) for r in rows]
    theirs = np.abs([r.error("fastsim") for r in rows])
    if np.all(np.isfinite(theirs)):  # FASTSim installed: hevsim at least as close on the median
        assert np.median(errors) <= np.median(theirs)
    # the city figure, where the old mapping failed: the Optima's unadjusted UDDS within 5 % of FASTSim's
    optima = rows[1]
    if math.isfinite(optima.fastsim_unadjusted[0]):
        assert optima.hevsim_unadjusted[0] == pytest.approx(optima.fastsim_unadjusted[0], rel=0.05)


PLUGIN_FUEL_CELL_ROWS = (13, 14, 23, 24)
"""2016 Chevrolet Volt, 2016 Ford C-MAX Energi (PHEVs), 2016 Hyundai Tucson Fuel Cell and Toyota
Mirai (FCEVs)."""
TUCSON_BOUND = 0.08
"""The Tucson Fuel Cell's combined MPGe within 8 % of its EPA label (+7.4 %: FASTSim's
``mph_fc_on`` and ``idle_fc_kw`` carried by the import, +8.5 %, and the MPGe in the EPA's miles
per kg; +15.2 % before both, docs/validation.md)."""


def test_fastsim_database_plug_in_and_fuel_cell_rows_within_the_goal() -> None:
    """Issue 25: the database's PHEVs and FCEVs are labelled too, each figure within 10 % of the
    EPA label: the PHEVs' charge-sustaining combined mpg (``val_comb_mpgge``: Volt 42, C-MAX
    Energi 38), charge-depleting electricity from the wall (``val_comb_kwh_per_mile`` 0.31, 0.37)
    and CD range (``val_cd_range_mi`` 53, 20 mi), the Tucson's and the Mirai's combined MPGe (49,
    67; the Tucson within :data:`TUCSON_BOUND`: +15.2 % before the import carried ``mph_fc_on``
    and ``idle_fc_kw``). Known worse, in docs/validation.md: the Prius Prime (CS mpg -16 %, CD
    kWh/mi +19 %, CD range -13 %). The old module skipped these rows ("being added"): no figure,
    the test fails; with the import's former ``cs_soc`` 10 % into the SOC window (a tenth of it
    left unused) the C-MAX Energi's CD range was 17.3 mi, -13.7 %."""
    rows = F.validate(only=list(PLUGIN_FUEL_CELL_ROWS), with_fastsim=True)
    volt, cmax, tucson, mirai = rows
    assert (volt.powertrain, cmax.powertrain, tucson.powertrain, mirai.powertrain) == (
        "PHEV",
        "PHEV",
        "FCEV",
        "FCEV",
    )
    assert not any(r.skipped for r in rows)
    assert (volt.epa, cmax.epa, tucson.epa, mirai.epa) == (42.0, 38.0, 49.0, 67.0)
    for r in rows:
        assert abs(r.error("hevsim")) <= 0.10, (r.name, r.hevsim, r.epa)
    assert abs(tucson.error("hevsim")) <= TUCSON_BOUND, (tucson.hevsim, tucson.epa)
    assert volt.extra["cd_kwh_per_mi"][0] == 0.31 and volt.extra["cd_range_mi"][0] == 53.0
    for r in (volt, cmax):
        for key in ("cd_kwh_per_mi", "cd_range_mi"):
            assert abs(r.extra_error(key, "hevsim")) <= 0.10, (r.name, key, r.extra[key])
        # the CS figure is the charge-sustaining test's, not the UF-weighted one (about 100 mpg)
        assert 30.0 < r.hevsim < 50.0
    if math.isfinite(volt.fastsim):  # FASTSim installed: its CS and CD figures of the same file
        assert volt.fastsim == pytest.approx(volt.hevsim, rel=0.10)
        assert volt.extra["cd_kwh_per_mi"][2] == pytest.approx(volt.extra["cd_kwh_per_mi"][1], rel=0.10)
        assert volt.extra["cd_range_mi"][2] == pytest.approx(volt.extra["cd_range_mi"][1], rel=0.10)
        assert mirai.fastsim == pytest.approx(mirai.hevsim, rel=0.10)


def test_fastsim_database_goals_hold_over_every_row() -> None:
    """Issue 25 item 5a's goals on hevsim's figures of every labelled row (FASTSim's are the
    benchmark's): median |error| <= 5 %, 90th percentile <= 10 %, no powertrain class median above
    8 %. Measured: 4.4 / 7.4 %, worst class FCEV 6.9 % (docs/validation.md); before the FCEV import
    carried ``mph_fc_on`` and ``idle_fc_kw`` the FCEV median was 9.6 % and this test failed."""
    rows = [r for r in F.validate(with_fastsim=False) if not r.skipped]
    assert len(rows) == 25
    err = np.array([abs(r.error("hevsim")) for r in rows])
    assert np.isfinite(err).all(), [r.name for r in rows if not math.isfinite(r.error("hevsim"))]
    assert np.median(err) <= 0.05 and np.percentile(err, 90) <= 0.10, (np.median(err), np.percentile(err, 90))
    for cls in {r.powertrain for r in rows}:
        e = [abs(r.error("hevsim")) for r in rows if r.powertrain == cls]
        assert np.median(e) <= 0.08, (cls, e)


def test_fastsim_database_only_non_epa_rows_are_skipped() -> None:
    """Every row with an EPA figure in ``val_comb_*`` is labelled, whatever its powertrain
    (conventional, HEV, PHEV, BEV, FCEV), except the documented rows whose figures are not an EPA
    label (``fastsim_db_not_epa.toml``)."""
    bad = F.not_epa()
    rows = [r for r, _ in F.rows()]
    with_figure = [r for r in rows if r.epa is not None]
    for r in with_figure:
        if r.skipped:
            assert r.name in bad and r.skipped == f"not an EPA label: {bad[r.name]}", (r.row, r.skipped)
    assert sorted(r.row for r in with_figure if r.skipped) == [27, 28, 30, 32, 33, 39]
    labelled = {r.powertrain for r in with_figure if not r.skipped}
    assert labelled == {"Conv", "HEV", "PHEV", "BEV", "FCEV"}
    assert sorted(r.row for r in with_figure if r.powertrain in ("PHEV", "FCEV")) == [12, 13, 14, 16, 23, 24]
    assert all(r.skipped == "no EPA figure in val_comb_*" for r in rows if r.epa is None)


def _vehdb_lines(file: str) -> dict[str, tuple[str, str]]:
    """A fastsim-2 vehicle CSV of the shipped vehdb: parameter name -> (value, comment)."""
    import csv
    from importlib import resources

    p = resources.files("hevsim") / "data" / "vehicles" / "fastsim" / "vehdb" / file
    with open(str(p), newline="", encoding="utf-8") as fh:
        return {r[1]: (r[2], (r[3] if len(r) > 3 else "").strip()) for r in csv.reader(fh) if len(r) > 2}


def test_fastsim_database_carried_over_figures_are_another_rows() -> None:
    """The rows left out as carrying another row's ``val*`` figures (``[carried_over]``) do, and
    FASTSim's own file of each vehicle says so: its figures equal the named row's (the database),
    and in its fastsim-2 file (an independent record: FASTSim's authors') the ``val_*`` lines carry
    no comment while every value that differs from the named row's file carries one (a source,
    "legacy"), or the file states that uncommented values are carried over from that row."""
    keys = ("val_udds_mpgge", "val_hwy_mpgge", "val_comb_mpgge")
    rows = {r.name: v for r, v in F.rows()}
    carried = F.carried_over()
    assert sorted(carried) == ["2010 Mazda 3 i-Stop", "2012 Ford Focus", "2017 Toyota Highlander 3.5 L"]
    for name, (src, file) in carried.items():
        assert [rows[name][k] for k in keys] == [rows[src][k] for k in keys], name
        mine = _vehdb_lines(file)
        theirs = _vehdb_lines(src.replace(" ", "_") + ".csv")
        assert mine["Scenario name"][0] == name
        assert all(mine[k][1] == "" for k in keys), name
        said = f"carryover from {src}" in mine["Scenario name"][1]
        differ = [k for k in mine if k != "Scenario name" and k in theirs and mine[k][0] != theirs[k][0]]
        assert differ, name  # a different vehicle
        assert said or all(mine[k][1] for k in differ), (name, [k for k in differ if not mine[k][1]])
    # a row with genuine figures of its own is not flagged: the Fusion (the Highlander's source)
    assert "2012 Ford Fusion" not in F.not_epa() and "2016 TOYOTA Corolla 4cyl 2WD" not in F.not_epa()


def test_fastsim_database_skips_are_stated() -> None:
    rows = {r.row: r for r, _ in F.rows()}
    assert rows[12].skipped == "" and rows[12].unit == "CS mpg" and rows[12].epa == 54.0
    assert rows[23].skipped == "" and rows[23].powertrain == "FCEV" and rows[23].epa == 49.0
    assert rows[25].skipped == "no EPA figure in val_comb_*"  # a truck
    assert rows[39].skipped.startswith("not an EPA label")  # Maruti Swift: a copy of the Corolla's figures
    assert rows[1].skipped == "" and rows[1].epa == 31.0


def test_combined_label_is_the_label_equations() -> None:
    """FASTSim's own 2016 Prius figures (lab 63.41 / 70.21 mpg -> adj 46.99 combined, 2008 set)."""
    assert F.combined_label(63.41125821311937, 70.21424834754671, 2016, False, 1.0) == pytest.approx(
        46.9901361039704, rel=1e-9
    )
    assert F.model_year({"scenario_name": "2017 CHEVROLET Bolt", "veh_year": None}) == 2017


def test_label_units_are_the_labels_own() -> None:
    """FASTSim and the import count fuel in gallons of 33.7 kWh; the labels count a diesel car's
    gallons of diesel and a fuel-cell car's kilograms of hydrogen (the EPA's MPGe of an FCEV is its
    miles per kg): per unit of the label's fuel, 33.7 kWh / (hydrogen's LHV, 120 MJ/kg =
    33.33 kWh) = 1.0110 FASTSim gallons for hydrogen, 33.7 / 38.0 kWh (diesel LHV x density x
    gallon, hevsim's fuel table) for diesel, 1 for gasoline."""
    rows = {r.row: v for r, v in F.rows()}
    assert F._label_gallon_factor(rows[23]) == pytest.approx(33.7 * 3.6 / 120.0, rel=1e-12)  # Tucson FC
    assert F._label_gallon_factor(rows[24]) == pytest.approx(1.0110, abs=5e-5)  # Mirai
    assert F._label_gallon_factor(rows[37]) == pytest.approx(33.7 / 38.0, rel=0.01)  # Colorado diesel
    assert F._label_gallon_factor(rows[1]) == 1.0 and F._label_gallon_factor(rows[17]) == 1.0


def test_road_load_and_mass_are_the_lists_converted() -> None:
    vehicles, skipped = T.read_test_cars()
    v = next(x for x in vehicles if x.vehicle_id == "562TT5348")  # Aston Martin DB11 V8, first line
    assert v.a_n == pytest.approx(40.94 * 4.4482216152605, rel=1e-12)
    assert v.b_n_per_mps == pytest.approx(0.0169 * 4.4482216152605 / 0.44704, rel=1e-12)
    assert v.c_n_per_mps2 == pytest.approx(0.0271 * 4.4482216152605 / 0.44704**2, rel=1e-12)
    assert v.test_mass_kg == pytest.approx(4500 * 0.45359237, rel=1e-12)
    assert sorted(c for c, _, _ in v.tests) == ["FTP", "HWY"]
    g = T.generic()
    ratios = T.gear_ratios(v, g)
    assert len(ratios) == 8 and ratios[0] / ratios[-1] == pytest.approx(g.spread[8])
    # top gear: N/V (engine rpm per mph) = overall ratio x wheel rpm per mph
    wheel_rpm_per_mph = 0.44704 * 60 / (2 * math.pi * g.tire_radius_m)
    assert ratios[-1] * v.axle_ratio * wheel_rpm_per_mph == pytest.approx(22.2, rel=1e-12)
    assert skipped["analytically derived (not measured)"] > 0 and skipped["hybrid (model name)"] > 0
    assert not any(T.is_hybrid_name(x.model) for x in vehicles)
    assert T.is_hybrid_name("LC 500h") and not T.is_hybrid_name("IS 350")


def _list_rows(path: Path, rows: list[dict[str, str]]) -> Path:
    """A Test Car List CSV of the real header with ``rows`` (columns not given: the first
    conventional FTP row of the real list, the Aston Martin DB11 V8)."""
    import csv

    src = Path(T.__file__).parents[1] / T.TEST_CAR_LIST
    with src.open(newline="", encoding="utf-8-sig") as f:
        reader = csv.DictReader(f)
        base = next(r for r in reader if r["Test Vehicle ID"] == "562TT5348" and r["Test Category"] == "FTP")
        header = list(base)
    with path.open("w", newline="", encoding="utf-8") as f:
        w = csv.DictWriter(f, header)
        w.writeheader()
        for r in rows:
            w.writerow({**base, **r})
    return path


def test_a_test_counts_once_and_inconsistent_tests_are_left_out(tmp_path: Path) -> None:
    """The selection rules of the measurement side (T.read_test_cars), each on rows made for it: a
    test number on two rows counts once; an FTP whose RND_ADJ_FE is off the 0.43 / 0.57 composite of
    its own bags by more than 5 % is left out; a configuration whose repeats of one cycle differ by
    more than 10 % (highest / lowest) is left out whole, one within 10 % is kept."""
    hwy = {"Test Category": "HWY", "Test Procedure Description": "HWFE", "FE Bag 1": "", "FE Bag 2": "",
           "FE Bag 3": ""}  # fmt: skip
    bags = {"FE Bag 1": "20", "FE Bag 2": "20", "FE Bag 3": "20"}  # composite 20 mpg
    rows = [
        {"Test Vehicle ID": "A", "Test Number": "A1", "RND_ADJ_FE": "20.0", **bags},
        {"Test Vehicle ID": "A", "Test Number": "A1", "RND_ADJ_FE": "20.0", **bags},  # the same test again
        {"Test Vehicle ID": "A", "Test Number": "A2", "RND_ADJ_FE": "30.0", **hwy},
        {"Test Vehicle ID": "B", "Test Number": "B1", "RND_ADJ_FE": "21.2", **bags},  # 6 % off its bags
        {"Test Vehicle ID": "B", "Test Number": "B2", "RND_ADJ_FE": "20.9", **bags},  # 4.5 % off: kept
        {"Test Vehicle ID": "B", "Test Number": "B3", "RND_ADJ_FE": "30.0", **hwy},
        {"Test Vehicle ID": "C", "Test Number": "C1", "RND_ADJ_FE": "20.0", **bags},
        {"Test Vehicle ID": "C", "Test Number": "C2", "RND_ADJ_FE": "30.0", **hwy},
        {"Test Vehicle ID": "C", "Test Number": "C3", "RND_ADJ_FE": "33.3", **hwy},  # 11 % above C2
        {"Test Vehicle ID": "D", "Test Number": "D1", "RND_ADJ_FE": "30.0", **hwy},
        {"Test Vehicle ID": "D", "Test Number": "D2", "RND_ADJ_FE": "32.9", **hwy},  # 9.7 % above D1
    ]
    vehicles, skipped = T.read_test_cars(_list_rows(tmp_path / "list.csv", rows))
    tests = {v.vehicle_id: sorted(n for _, n, _ in v.tests) for v in vehicles}
    assert tests == {"A": ["A1", "A2"], "B": ["B2", "B3"], "D": ["D1", "D2"]}
    assert skipped["a repeated row of a test already counted (same test number)"] == 1
    assert skipped["FTP figure off its own bags' composite by more than 5 %"] == 1
    assert skipped["tested in several modes (repeats of one cycle more than 10 % apart)"] == 3
    # the real list: the Infiniti Q50 AWD's four tests are on eight rows; the Elantra N's two FTPs
    # (27.7 and 20.7 mpg, same fields) are two modes
    real, skipped = T.read_test_cars()
    q50 = next(v for v in real if v.vehicle_id == "HTE511")
    assert len(q50.tests) == len({n for _, n, _ in q50.tests}) == 4
    assert not any(v.vehicle_id == "CN7U1H0TD062F" for v in real)
    assert skipped["a repeated row of a test already counted (same test number)"] == 35


def test_split_is_deterministic_and_halves() -> None:
    vehicles, _ = T.read_test_cars()
    halves = [T.split(v.vehicle_id) for v in vehicles]
    assert halves == [T.split(v.vehicle_id) for v in vehicles]
    assert 0.4 < halves.count("train") / len(halves) < 0.6


def test_held_out_sample_and_the_fit_is_linear(tmp_path: Path) -> None:
    """Every 4th held-out vehicle (129 FTP, 129 HWY tests, 8 of the 122 configurations tested with
    a four-bag FTP): the simulated fuel equals the fitted weights times the run's energy integrals
    (the linearity the fit relies on), and the errors are the shipped models' (docs/validation.md).
    This sample gives FTP 4.5 % median / 12.7 % 90th percentile, HWY 3.5 % / 8.4 % (the whole
    held-out half: 4.5 / 11.5 and 3.1 / 8.6); the bounds are those figures rounded up. The models
    before the four-bag vehicles' stop-start give FTP 5.2 / 13.5 % on the same sample and fail
    both FTP bounds; their HWY is 3.4 / 8.3 % here (3.1 / 8.6 on the whole half, as now), so the
    HWY bounds cannot tell the two apart. Both medians are within the issue's 5 % goal."""
    vehicles, _ = T.read_test_cars()
    held = [v for v in vehicles if T.split(v.vehicle_id) == "test"][::4]
    g = T.generic()
    runs = T.run_all(held, tmp_path, g)
    assert len(runs) == 258 and sum(v.four_bag for v in held) == 8
    for r in runs:
        assert T.linear_mpg(r, g.fitted) == pytest.approx(r.predicted_mpg, rel=2e-3)
    for cat, median_max, p90_max in (("HWY", 0.035, 0.085), ("FTP", 0.046, 0.127)):
        e = np.abs([r.error for r in runs if r.category == cat])
        assert np.median(e) <= median_max, (cat, np.median(e))
        assert np.percentile(e, 90) <= p90_max, (cat, np.percentile(e, 90))
        assert np.median(e) <= 0.05  # the goal


def test_four_bag_vehicles_stop_their_engine(tmp_path: Path) -> None:
    """A Test Vehicle ID with a figure in ``FE Bag 4`` on any row (the four-bag FTP of vehicles with
    a rechargeable energy storage system) is marked ``four_bag``, whatever the figure; its
    configuration has stop-start, so on the UDDS its engine burns nothing while the car stands
    (with the generic file's switch off, or for a car without the fourth bag, it idles)."""
    bags = {"FE Bag 1": "20", "FE Bag 2": "20", "FE Bag 3": "20"}
    hwy = {"Test Category": "HWY", "Test Procedure Description": "HWFE", "FE Bag 1": "", "FE Bag 2": "",
           "FE Bag 3": "", "FE Bag 4": ""}  # fmt: skip
    rows = [
        {"Test Vehicle ID": "A", "Test Number": "A1", "RND_ADJ_FE": "20.0", **bags, "FE Bag 4": "21.5"},
        {"Test Vehicle ID": "A", "Test Number": "A2", "RND_ADJ_FE": "30.0", **hwy},
        {"Test Vehicle ID": "B", "Test Number": "B1", "RND_ADJ_FE": "20.0", **bags, "FE Bag 4": "0"},
        {"Test Vehicle ID": "B", "Test Number": "B2", "RND_ADJ_FE": "30.0", **hwy},
        {"Test Vehicle ID": "C", "Test Number": "C1", "RND_ADJ_FE": "20.0", **bags, "FE Bag 4": ""},
    ]
    vehicles, _ = T.read_test_cars(_list_rows(tmp_path / "list.csv", rows))
    assert {v.vehicle_id: v.four_bag for v in vehicles} == {"A": True, "B": False, "C": False}
    g = T.generic()
    assert g.four_bag_stop_start
    a, b = vehicles[0], vehicles[1]
    assert T.vehicle_config(a, tmp_path / "e", g).controller.stop_start == "on"
    assert T.vehicle_config(b, tmp_path / "e", g).controller.stop_start == "off"
    off = replace(g, four_bag_stop_start=False)
    assert T.vehicle_config(a, tmp_path / "e", off).controller.stop_start == "off"
    # the real list: the 48 V BMW M440i Coupe is marked, the Camry is not
    real, _ = T.read_test_cars()
    assert all(v.four_bag for v in real if v.model == "M440i Coupe")
    assert not any(v.four_bag for v in real if v.vehicle_id == "18-AV2A")
    assert sum(v.four_bag for v in real) == 83
    # simulated: no fuel at a standstill with stop-start, idle fuel without
    from hevsim.architectures import build_vehicle
    from hevsim.fuels import get_fuel
    from hevsim.sim.simulator import simulate

    T.write_engine(tmp_path / "e", a, g, g.fitted, get_fuel("gasoline").lower_heating_value_j_per_kg)
    for gg, idle in ((g, False), (off, True)):
        ts = simulate(
            build_vehicle(T.vehicle_config(a, tmp_path / "e", gg)), "udds", tracking=None
        ).timeseries
        stopped = ts["speed_mps"].to_numpy() < 0.01
        assert stopped.sum() > 200
        assert bool(np.all(ts["fuel_rate_gps"].to_numpy()[stopped] > 0)) is idle


def test_shift_rules_by_transmission_class(tmp_path: Path) -> None:
    """Every conventional car of the list has a transmission class whose fitted rule its gearbox
    can follow without hunting; :func:`T.shift_feasible` agrees with the configuration's own check."""
    vehicles, _ = T.read_test_cars()
    g = T.generic()
    camry = next(x for x in vehicles if x.vehicle_id == "18-AV2A")
    assert g.shift_rule(camry)[0] == "automatic, 8 gears"
    ten = next(x for x in vehicles if x.transmission_code in ("A", "SA") and x.gears == 10)
    assert g.shift_rule(ten)[0] == "automatic, 9 or 10 gears"
    assert g.shift_rule(next(v for v in vehicles if v.transmission_code == "M"))[0] == "manual"
    assert (
        g.shift_rule(next(v for v in vehicles if v.transmission_code == "CVT"))[0] == "continuously variable"
    )
    for v in vehicles:
        name, up, down = g.shift_rule(v)
        assert name != "other" and T.shift_feasible(v, g, up, down), (v.vehicle_id, name)
    six = next(v for v in vehicles if v.gears == 6 and v.transmission_code == "A")
    bad = g.with_shift("automatic, up to 7 gears", 1500.0, 1150.0)
    assert not T.shift_feasible(six, bad, 1500.0, 1150.0)
    with pytest.raises(ConfigError, match="hunt"):
        T.vehicle_config(six, tmp_path / "e", bad)
    assert T.shift_feasible(six, g, *g.shift_rule(six)[1:])
    T.vehicle_config(six, tmp_path / "e", g)


def test_search_shift_rules_fits_on_the_training_half(tmp_path: Path, monkeypatch: Any) -> None:
    """The search simulates training vehicles only and ends no worse (engine-fit loss) than it
    started; every rule it returns is from the grid or the start."""
    vehicles, _ = T.read_test_cars()
    g = T.generic()
    sample = []
    for name in ("automatic, 8 gears", "manual"):
        of = [v for v in vehicles if g.shift_rule(v)[0] == name]
        sample += [v for v in of if T.split(v.vehicle_id) == "train"][:4] + [
            v for v in of if T.split(v.vehicle_id) == "test"
        ][:2]
    seen: list[T.TestVehicle] = []
    real = T.run_all

    def spy(vs: list[T.TestVehicle], *a: Any, **k: Any) -> list[T.TestRun]:
        seen.extend(vs)
        return real(vs, *a, **k)

    monkeypatch.setattr(T, "run_all", spy)
    grid = ((1600.0, 1000.0), (2600.0, 1300.0))
    found, log = T.search_shift_rules(sample, tmp_path, g, grid=grid, rounds=1)
    monkeypatch.undo()
    assert seen and all(T.split(v.vehicle_id) == "train" for v in seen)
    start = {r.name: (r.upshift_rpm, r.downshift_rpm) for r in g.shift_rules}
    for r in found.shift_rules:
        assert (r.upshift_rpm, r.downshift_rpm) in (*grid, start[r.name])
    train = [v for v in sample if T.split(v.vehicle_id) == "train"]

    def loss(gg: T.Generic) -> float:
        runs = T.run_all(train, tmp_path / "check", gg)
        return T.fit_loss(runs, T.fit(runs))

    assert loss(found) <= loss(g) + 1e-12
    assert len(log) == 1 + len(g.shift_rules)


def test_bags_give_the_ftp_composite() -> None:
    """40 CFR 600.114: the FTP fuel economy is 1 / (0.43 / cold UDDS + 0.57 / hot UDDS), cold UDDS =
    bags 1 + 2, hot = bags 3 + 2 (by distance): the list's bag figures give its RND_ADJ_FE to rounding."""
    bags = T.ftp_bags()
    vehicles, _ = T.read_test_cars()
    d1, d2, d3 = T.BAG_MILES
    diff = []
    for v in vehicles[::10]:
        for cat, number, mpg in v.tests:
            if cat != "FTP" or number not in bags:
                continue
            b1, b2, b3 = bags[number]
            hot, cold_gal = T.bag_split(bags[number])
            cold = (d1 + d2) / (d1 / b1 + d2 / b2)
            assert hot == pytest.approx((d3 + d2) / (d3 / b3 + d2 / b2), rel=1e-12)
            assert cold_gal == pytest.approx((d1 + d2) / cold - (d3 + d2) / hot, rel=1e-9)
            diff.append(1 / (0.43 / cold + 0.57 / hot) / mpg - 1)
    assert len(diff) >= 50
    assert np.median(np.abs(diff)) <= 0.003 and np.percentile(np.abs(diff), 90) <= 0.01


def test_fit_recovers_known_weights() -> None:
    """NNLS on runs whose measured fuel is exactly a known weighting of their integrals."""
    rng = np.random.default_rng(1)
    true = T.EngineParams.from_weights(np.array([2.4, 3e4, 0, 9e3, 0, 0.1, 0, 0, 2500.0, 4e9]))
    runs = []
    for i in range(40):
        f = np.abs(rng.normal(size=len(T.FEATURES))) * np.array(
            [2e7, 300, 300, 300, 300, 50, 50, 2e7, 1000, 1e-3]
        )
        dist = 12000.0
        fuel_j = float(f @ true.weights())
        mpg = dist / 1609.344 / (fuel_j / T.gallon_energy_j())
        runs.append(T.TestRun(None, "FTP", str(i), mpg, mpg, f, dist, "train"))  # type: ignore[arg-type]
    got = T.fit(runs).weights()
    assert got == pytest.approx(true.weights(), rel=1e-6, abs=1e-6)


def _two_class_runs(seed: int, fuel_j: Callable[[str, np.ndarray], float]) -> list[Any]:
    """80 synthetic training runs over 12 km: the first 20 of transmission class "a", the rest
    "b"; random positive features (the generator seeded ``seed``), every other run a HWY run
    (no FTP feature); each one's measured mpg from ``fuel_j(class, features)`` [J]."""
    rng = np.random.default_rng(seed)
    runs = []
    for i in range(80):
        cls = "a" if i < 20 else "b"
        f = np.abs(rng.normal(size=len(T.FEATURES))) * np.array(
            [2e7, 300, 300, 300, 300, 50, 50, 2e7, 1000, 1e-3]
        )
        if i % 2:
            f[-1] = 0.0  # a HWY run
        dist = 12000.0
        mpg = dist / 1609.344 / (fuel_j(cls, f) / T.gallon_energy_j())
        runs.append(T.TestRun(None, "FTP" if f[-1] else "HWY", str(i), mpg, mpg, f, dist, "train", cls))  # type: ignore[arg-type]
    return runs


def test_fit_gives_each_transmission_class_its_ftp_term() -> None:
    """Runs of two transmission classes whose measured fuel carries different FTP terms (3e9 and
    5e9 J/m^3, the same map otherwise): the fit recovers both, the fallback ``cold_start`` is their
    mean weighted by FTP runs (10 and 30: 4.5e9), and the prediction of each run uses its own."""
    point = np.array([2.4, 3e4, 0, 9e3, 0, 0.1, 0, 0, 2500.0])
    term = {"a": 3e9, "b": 5e9}
    runs = _two_class_runs(2, lambda cls, f: float(f[:-1] @ point) + term[cls] * f[-1])
    got = T.fit(runs)
    assert got.weights()[:-1] == pytest.approx(point, rel=1e-6, abs=1e-6)
    assert got.cold_start("a") == pytest.approx(3e9, rel=1e-6)
    assert got.cold_start("b") == pytest.approx(5e9, rel=1e-6)
    assert got.cold_start("other") == pytest.approx((10 * 3e9 + 30 * 5e9) / 40, rel=1e-6)
    assert T.fit_loss(runs, got) == pytest.approx(0.0, abs=1e-6)
    assert all(T.linear_mpg(r, got) == pytest.approx(r.measured_mpg, rel=1e-6) for r in runs)


def test_fit_gives_each_transmission_class_its_brake_work_weight(tmp_path: Path) -> None:
    """Runs of two transmission classes whose measured fuel carries different brake-work weights
    (2.2 and 2.6: the same engine behind gearboxes 2.6 / 2.2 - 1 = 18 % apart in efficiency, the
    same map otherwise): the fit recovers both, the fallback ``brake_work`` is their mean weighted
    by runs (20 and 60: 2.5), each run's prediction uses its own, and the engine map written for
    a car of a class is the map of that class's weights."""
    rest = np.array([3e4, 0, 9e3, 0, 0.1, 0, 0, 2500.0])
    bw = {"a": 2.2, "b": 2.6}
    runs = _two_class_runs(3, lambda cls, f: bw[cls] * f[0] + float(f[1:-1] @ rest) + 4e9 * f[-1])
    got = T.fit(runs)
    assert got.brake_work("a") == pytest.approx(2.2, rel=1e-6)
    assert got.brake_work("b") == pytest.approx(2.6, rel=1e-6)
    assert got.brake_work("other") == pytest.approx((20 * 2.2 + 60 * 2.6) / 80, rel=1e-6)
    assert got.weights()[1:-1] == pytest.approx(rest, rel=1e-6, abs=1e-6)
    assert got.weights_for("a")[0] == pytest.approx(2.2, rel=1e-6)
    assert all(T.linear_mpg(r, got) == pytest.approx(r.measured_mpg, rel=1e-6) for r in runs)
    # classes of fewer than BRAKE_WORK_MIN_RUNS runs share one weight: "a" split in two of 10 runs
    split = [replace(r, shift_class="c") if i < 10 else r for i, r in enumerate(runs)]
    shared = T.fit(split)
    assert T.BRAKE_WORK_MIN_RUNS > 10
    assert shared.brake_work("a") == shared.brake_work("c") == pytest.approx(2.2, rel=1e-6)
    assert shared.brake_work("b") == pytest.approx(2.6, rel=1e-6)
    # the map of a car: its class's brake-work weight (a Camry: "automatic, 8 gears")
    g = T.generic()
    vehicles, _ = T.read_test_cars()
    camry = next(x for x in vehicles if x.vehicle_id == "18-AV2A")
    name = g.shift_rule(camry)[0]
    p = T.EngineParams(got.weights_by_name, got.cold_start_by_class, ((name, 2.2), ("b", 2.6)))
    t, w = np.array([50.0, 150.0]), np.array([150.0, 250.0])
    assert T.fuel_power_w(t, w, camry, g, p) == pytest.approx(
        T.point_terms(t, w, camry, g) @ p.weights_for(name)[: len(T.POINT_TERMS)], rel=1e-12
    )
    other = T.EngineParams(got.weights_by_name, got.cold_start_by_class, (("b", 2.6),))
    extra = (2.2 - got.brake_work("other")) * w * t  # the brake-work term alone differs
    assert T.fuel_power_w(t, w, camry, g, p) - T.fuel_power_w(t, w, camry, g, other) == pytest.approx(
        extra, rel=1e-9
    )
    assert g.fitted.brake_work(name) != g.fitted.brake_work("manual")  # the shipped file has them


def test_bad_generic_file_names_the_key(tmp_path: Path) -> None:
    src = Path(T.__file__).parents[1] / T.GENERIC_FILE
    bad = tmp_path / "g.toml"
    bad.write_text(src.read_text().replace("brake_work = ", "brake_wrok = "))
    with pytest.raises(ConfigError, match="brake_wrok"):
        T.generic(str(bad))
    bad.write_text(src.read_text().replace('codes = ["M"]', 'codes = "M"'))
    with pytest.raises(ConfigError, match="'codes' = 'M'"):
        T.generic(str(bad))
    bad.write_text(src.read_text().split("\n[[transmission.shift]]")[0] + '\nshift = "manual"\n')
    with pytest.raises(ConfigError, match="'shift' = 'manual'"):
        T.generic(str(bad))
    bad.write_text(src.read_text().replace('"manual" = ', '"manuel" = '))
    with pytest.raises(ConfigError, match=r"cold_start_by_class.*manuel"):
        T.generic(str(bad))
    text = src.read_text()
    at = text.index("[engine.fitted.brake_work_by_class]")
    bad.write_text(text[:at] + text[at:].replace('"manual" = ', '"manuel" = ', 1))
    with pytest.raises(ConfigError, match=r"brake_work_by_class.*manuel"):
        T.generic(str(bad))
    bad.write_text(text[:at] + text[at:].replace('"manual" = ', '"manual" = 0.0 #', 1))
    with pytest.raises(ConfigError, match="brake_work_by_class entry"):
        T.generic(str(bad))
    bad.write_text(text.replace("four_bag_stop_start = true", 'four_bag_stop_start = "yes"'))
    with pytest.raises(ConfigError, match="four_bag_stop_start' = 'yes'"):
        T.generic(str(bad))


def test_camry_example_within_ten_percent_of_its_epa_figures(tmp_path: Path) -> None:
    """examples/toyota_camry_2022_le.toml (issue 25 item 6): hevsim's unadjusted label within 10 % of
    the unadjusted figures behind the car's EPA label (28 city / 39 highway, 2017 coefficient set),
    and its engine folder is the generic map of its Test Car List entry with the shipped weights."""
    from hevsim.fuels import get_fuel
    from hevsim.sim import label as L

    root = Path(__file__).resolve().parents[1] / "examples"
    lab = L.label(root / "toyota_camry_2022_le.toml", model_year=2022)
    c = L.constants().for_model_year(2022)
    u = lab.figures["unadjusted_mpg"]
    assert u["city"] == pytest.approx(L.unadjusted_city(28, c), rel=0.10)
    assert u["highway"] == pytest.approx(L.unadjusted_highway(39, c), rel=0.10)
    vehicles, _ = T.read_test_cars()
    v = next(x for x in vehicles if x.vehicle_id == "18-AV2A" and x.a_n > 25.5 * T.N_PER_LBF)
    T.write_engine(
        tmp_path / "e", v, T.generic(), T.generic().fitted, get_fuel("gasoline").lower_heating_value_j_per_kg
    )
    for name in ("fuel_rate_map.csv", "max_torque.csv", "closed_throttle_torque.csv"):
        assert (tmp_path / "e" / name).read_text() == (
            root / "toyota_camry_2022_le_engine" / name
        ).read_text()
