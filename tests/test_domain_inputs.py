"""No traceback reaches the user (issue 26 item 3): a configuration that is not UTF-8 or is a
binary file, and a study whose sample would not fit in memory, are refused with exit 2 and one
line naming the file and the byte offset / the count and the memory."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from hevsim.cli import main

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"


def _one_error(err: str) -> str:
    assert "Traceback" not in err, err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("hevsim: error: "), err
    return lines[0]


def _latin1(tmp_path: Path, example: str) -> tuple[Path, int]:
    """``example`` with a Latin-1 "°" in a comment on its first line; returns (file, offset)."""
    text = (EXAMPLES / example).read_text(encoding="utf-8")
    head = "# temperatures in "
    p = tmp_path / example
    p.write_bytes(head.encode() + "°C\n".encode("latin-1") + text.encode("utf-8"))
    return p, len(head)


@pytest.mark.parametrize(
    ("command", "example"),
    [
        (["simulate"], "conventional_sedan.toml"),
        (["optimize"], "series_hev.toml"),
        (["cell"], "cell.toml"),
        (["pack"], "pack_coolant.toml"),
        (["study"], "study_series_sizing.toml"),
        (["thermal"], "module_thermal.toml"),
        (["life"], "vehicle_pack.toml"),
        (["export-fmu"], "cell.toml"),
    ],
)
def test_latin1_config_is_refused_with_its_byte_offset(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], command: list[str], example: str
) -> None:
    """Today: exit 1 with a UnicodeDecodeError traceback."""
    path, offset = _latin1(tmp_path, example)
    out = ["-o", str(tmp_path / "x.fmu")] if command == ["export-fmu"] else ["--out", str(tmp_path / "out")]
    assert main([*command, str(path), *out]) == 2
    msg = _one_error(capsys.readouterr().err)
    assert f"{path}: is not UTF-8 text: byte 0xb0 at offset {offset} (line 1, column {offset + 1})" in msg


def test_binary_file_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "vehicle.toml"
    path.write_bytes(b"name = 'x'\n\x00\x01\x02\xff" * 4)
    assert main(["simulate", str(path)]) == 2
    msg = _one_error(capsys.readouterr().err)
    assert f"{path}: is a binary file: byte 0x00 at offset 11 (line 2, column 1)" in msg


HUGE = [("lhs", "100_000_000", "100,000,000"), ("sobol", "1_073_741_824", "1,073,741,824")]


@pytest.mark.parametrize(("method", "samples", "rows"), HUGE)
def test_huge_study_sample_is_refused_before_allocating(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], method: str, samples: str, rows: str
) -> None:
    """Today: numpy's MemoryError traceback after the allocation was tried (29.8 GiB for 1e9)."""
    text = (EXAMPLES / "study_series_sizing.toml").read_text()
    text = text.replace("samples = 64", f"samples = {samples}").replace(
        'method = "lhs"', f'method = "{method}"'
    )
    p = tmp_path / "study.toml"
    p.write_text(text.replace('vehicle = "series_hev.toml"', f'vehicle = "{EXAMPLES / "series_hev.toml"}"'))
    assert main(["study", str(p), "--out", str(tmp_path / "out")]) == 2
    msg = _one_error(capsys.readouterr().err)
    assert f"key 'sampling.samples' = {samples.replace('_', '')}: {rows} {method} sample rows" in msg
    assert re.search(r"would need about [\d,]+ MB", msg) and "at most 10,000,000 rows" in msg
    assert not (tmp_path / "out").exists()


def test_study_sample_beyond_free_memory_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Below the case limit but beyond the machine's free memory (here 500 MB): the guards'
    refusal (:func:`hevsim.guards.check_memory`), before sampling."""
    import hevsim.guards as guards

    monkeypatch.setattr(guards, "mem_available_bytes", lambda *a: 500_000_000)
    text = (EXAMPLES / "study_series_sizing.toml").read_text().replace("samples = 64", "samples = 5_000_000")
    p = tmp_path / "study.toml"
    p.write_text(text.replace('vehicle = "series_hev.toml"', f'vehicle = "{EXAMPLES / "series_hev.toml"}"'))
    assert main(["study", str(p), "--out", str(tmp_path / "out")]) == 2
    msg = _one_error(capsys.readouterr().err)
    assert "5,000,000 lhs sample rows of 4 parameters needs about 640 MB" in msg
    assert "450 MB this machine has free" in msg and "lower 'sampling.samples'" in msg
