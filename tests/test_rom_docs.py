"""Issue 12 item 6: docs/rom.md's validation figure is made by examples/rom_validation_plot.py;
re-run its validation on the coarse mesh (60 s of each load) and write the figure."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

pytest.importorskip("skfem")
pytest.importorskip("gmsh")

ROOT = Path(__file__).resolve().parents[1]


def test_validation_figure_regenerates(tmp_path: Path) -> None:
    path = ROOT / "examples" / "rom_validation_plot.py"
    spec = importlib.util.spec_from_file_location("rom_validation_plot", path)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    rom, results = mod.validate(coarse=True, steps=60)
    assert [name[:3] for name, _ in results] == ["(a)", "(b)"]
    for _, c in results:
        assert c.mean_error_k < mod.BOUND_K and c.max_error_k < mod.BOUND_K
        assert c.fem_max_k.max() - c.fem_max_k[0].max() > 0.5  # the loads heat the cells
    out = mod.plot(rom, results, tmp_path / "rom_vs_fem.png")
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    shipped = ROOT / "docs" / "rom_vs_fem.png"
    assert shipped.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "(rom_vs_fem.png)" in (ROOT / "docs" / "rom.md").read_text(encoding="utf-8")
