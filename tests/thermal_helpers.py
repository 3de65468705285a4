"""Shared test inputs for the battery-module thermal tests (test_pack, test_rom)."""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: the example module on a coarse mesh (about 4 500 FEM nodes)
COARSE_TOML = (
    (ROOT / "examples" / "module_thermal.toml")
    .read_text()
    .replace("mesh_size_m = 0.005", "mesh_size_m = 0.008")
    .replace("curvature_elements = 12 ", "curvature_elements = 8 ")
)
