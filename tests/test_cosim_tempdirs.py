"""An ``.ssp`` is extracted to a temporary ``hevsim-ssp-*`` folder; running or checking it
leaves nothing behind in the temporary directory, also on error (issue 10 item 6)."""

from __future__ import annotations

import tempfile
import zipfile
from pathlib import Path

import pytest

from hevsim.cosim.datacheck import datacheck
from hevsim.cosim.master import Connection
from hevsim.cosim.ssd import PY_TYPE, Component, Connector, SystemDescription, read_ssp
from hevsim.cosim.ssp_write import write_ssp
from hevsim.cosim.system import run_cosim
from hevsim.errors import ConfigError

LIB = "hevsim.cosim.library:"


def two_masses(hot_source: str = LIB + "thermal_mass") -> SystemDescription:
    hot_params = {"capacity_j_per_k": 500.0, "temp_initial_k": 350.0, "conductance_w_per_k": 3.0}
    hot_conn = [Connector("t_other_k", "input", "K"), Connector("heat_out_w", "output", "W")]
    cold_conn = [Connector("heat_in_w", "input", "W"), Connector("temp_k", "output", "K")]
    cold_params = {"capacity_j_per_k": 200.0, "temp_initial_k": 290.0}
    comps = [
        Component("hot", PY_TYPE, hot_source, hot_conn, hot_params),
        Component("cold", PY_TYPE, LIB + "thermal_mass", cold_conn, cold_params),
    ]
    conns = [
        Connection("cold", "temp_k", "hot", "t_other_k"),
        Connection("hot", "heat_out_w", "cold", "heat_in_w"),
    ]
    master = {"algorithm": "gauss-seidel", "step_s": 5.0, "order": ["hot", "cold"]}
    return SystemDescription("two_masses", comps, conns, 0.0, 20.0, master)


@pytest.fixture
def tmpdir_root(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A fresh, empty system temporary directory (``tempfile.tempdir``)."""
    root = tmp_path / "systmp"
    root.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(root))
    return root


def test_run_and_datacheck_remove_the_extraction_folder(tmp_path: Path, tmpdir_root: Path) -> None:
    ssp = write_ssp(two_masses(), tmp_path / "sys.ssp")
    datacheck(ssp)
    assert list(tmpdir_root.iterdir()) == []
    res = run_cosim(ssp, tmp_path / "out")
    assert res.time_s[-1] == pytest.approx(20.0)
    assert (tmp_path / "out" / "results.csv").is_file()
    assert list(tmpdir_root.iterdir()) == []


def test_errors_remove_the_extraction_folder(tmp_path: Path, tmpdir_root: Path) -> None:
    bad_ref = two_masses()
    bad_ref.connections.append(Connection("nobody", "x", "cold", "heat_in_w"))
    ssp = write_ssp(bad_ref, tmp_path / "bad_ref.ssp")
    with pytest.raises(ConfigError, match="unknown component 'nobody'"):
        datacheck(ssp)
    assert list(tmpdir_root.iterdir()) == []
    with pytest.raises(ConfigError, match="unknown component 'nobody'"):
        run_cosim(ssp, tmp_path / "out")
    assert list(tmpdir_root.iterdir()) == []
    # passes the check, fails while building the participants
    ssp = write_ssp(two_masses(LIB + "no_such_factory"), tmp_path / "bad_factory.ssp")
    with pytest.raises(ConfigError, match="cannot import"):
        run_cosim(ssp, tmp_path / "out")
    assert list(tmpdir_root.iterdir()) == []
    # an archive whose system description is not well-formed (fails after extraction)
    with zipfile.ZipFile(tmp_path / "broken.ssp", "w") as z:
        z.writestr("SystemStructure.ssd", "<ssd:SystemStructureDescription")
    with pytest.raises(ConfigError, match="not well-formed XML"):
        run_cosim(tmp_path / "broken.ssp", tmp_path / "out")
    assert list(tmpdir_root.iterdir()) == []


def test_read_ssp_owns_its_folder_until_cleanup(tmp_path: Path, tmpdir_root: Path) -> None:
    ssp = write_ssp(two_masses(), tmp_path / "sys.ssp")
    with read_ssp(ssp) as desc:
        assert desc.scratch_dir is not None and desc.scratch_dir.parent == tmpdir_root
        assert desc.scratch_dir.name.startswith("hevsim-ssp-")
        assert (desc.base_dir / "SystemStructure.ssd").is_file()
    assert list(tmpdir_root.iterdir()) == []
    kept = read_ssp(ssp, tmp_path / "unpacked")  # an explicit folder belongs to the caller
    assert kept.scratch_dir is None
    kept.cleanup()
    assert (tmp_path / "unpacked" / "SystemStructure.ssd").is_file()


def test_out_dir_under_missing_folders(tmp_path: Path) -> None:
    """An ``out_dir`` whose parent folders do not exist yet: they are made (the checkpoint
    streams beside it used to raise FileNotFoundError from deep in the master)."""
    out = tmp_path / "not" / "yet" / "out"
    res = run_cosim(two_masses(), out)
    assert res.time_s[-1] == pytest.approx(20.0)
    assert (out / "results.csv").is_file()
    assert not list(out.parent.glob(".out.checkpoint*"))
