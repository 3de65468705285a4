"""Shared by the architecture tests: a bad configuration file makes ``hevsim simulate`` exit 2."""

from __future__ import annotations

from pathlib import Path

import pytest

from hevsim.cli import main


def assert_bad_config_exits_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], text: str, needles: list[str]
) -> None:
    """Write ``text`` to ``bad.toml``; ``hevsim simulate`` on it exits 2, its error names the
    file and every one of ``needles``, and it writes no output folder."""
    bad = tmp_path / "bad.toml"
    bad.write_text(text)
    out = tmp_path / "o"
    assert main(["simulate", str(bad), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "bad.toml" in err
    for n in needles:
        assert n in err, (n, err)
    assert not out.exists()
