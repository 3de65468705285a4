"""The ROM-vs-FEM validation figure of docs/rom.md (issue 12 item 6).

    .venv/bin/python examples/rom_validation_plot.py                 # default mesh -> docs/rom_vs_fem.png
    .venv/bin/python examples/rom_validation_plot.py --coarse --out /tmp/rom_vs_fem.png

Builds the module's thermal ROM from ``examples/module_thermal.toml`` (``--coarse``: the
~4 500-node mesh of the test suite, mesh size 8 mm) and runs the full FEM and the ROM side by
side (:func:`hevsim.thermal.rom.compare_with_fem`: both implicit Euler, the same 1-D coolant
channel) on the two loads of the validation table of docs/pack.md:

(a) square heat: per-cell heat 2 W / 0.8 W alternating every 5 s, cells spread +-20 %, coolant
    inlet 15 degC, 300 s;
(b) a 10 K step of the coolant inlet at 100 s under 1 W per cell, 300 s.

The figure shows, per load, the hottest cell's mean and hot-spot temperatures (FEM lines, ROM
markers) and the largest ROM - FEM error over all cells at each step against the 0.2 K bound
of the issue. It prints the ROM order and the errors, and writes the PNG atomically.
tests/test_rom_docs.py regenerates it on the coarse mesh.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "examples" / "module_thermal.toml"
OUT = ROOT / "docs" / "rom_vs_fem.png"
BOUND_K = 0.2
"""Acceptance bound of issue 12 on every per-cell mean and hot-spot temperature [K]."""
COARSE_MESH_SIZE_M = 0.008
"""Mesh size of the coarse test-suite mesh [m] (examples/module_thermal.toml: 0.005)."""
COARSE_CURVATURE_ELEMENTS = 8
STEPS = 300
"""Steps of each load (1 s each in the example) [-]."""


def loads() -> list[tuple[str, Any, Any]]:
    """(name, heat_w(t) -> (12,) [W], inlet_k(t) [K]) of loads (a) and (b)."""
    from hevsim.thermal.run import KELVIN

    spread = np.linspace(0.8, 1.2, 12)
    return [
        ("(a) square heat, inlet 15 degC", lambda t: spread * (2.0 if (t % 10.0) < 5.0 else 0.8),
         lambda t: KELVIN + 15.0),
        ("(b) 10 K inlet step at 100 s, 1 W per cell", lambda t: np.ones(12),
         lambda t: KELVIN + (15.0 if t < 100.0 else 25.0)),
    ]  # fmt: skip


def validate(coarse: bool = False, steps: int = STEPS) -> tuple[Any, list[tuple[str, Any]]]:
    """(ROM, [(load name, :class:`~hevsim.thermal.rom.RomComparison`)])."""
    from hevsim.thermal.rom import build_rom_from_config, compare_with_fem
    from hevsim.thermal.run import load_thermal_config

    cfg = load_thermal_config(CONFIG)
    if coarse:
        geo = dataclasses.replace(
            cfg.geometry, mesh_size_m=COARSE_MESH_SIZE_M, curvature_elements=COARSE_CURVATURE_ELEMENTS
        )
        cfg = dataclasses.replace(cfg, geometry=geo)
    rom, mesh = build_rom_from_config(cfg)
    return rom, [(name, compare_with_fem(cfg, mesh, rom, q, t_in, steps)) for name, q, t_in in loads()]


def plot(rom: Any, results: list[tuple[str, Any]], path: Path) -> Path:
    """Write the two-load figure to ``path`` (PNG, atomically)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from hevsim.io import atomic_file
    from hevsim.thermal.run import KELVIN

    fig, axes = plt.subplots(2, len(results), figsize=(11, 6.5), sharex="col")
    for j, (name, c) in enumerate(results):
        hot = int(np.argmax(c.fem_max_k[-1]))
        ax = axes[0, j]
        ax.plot(c.time_s, c.fem_mean_k[:, hot] - KELVIN, "C0-", label=f"FEM mean, cell {hot}")
        ax.plot(c.time_s, c.fem_max_k[:, hot] - KELVIN, "C3-", label=f"FEM hot spot, cell {hot}")
        ax.plot(c.time_s[::10], c.rom_mean_k[::10, hot] - KELVIN, "C0o", ms=3, mfc="none", label="ROM mean")
        ax.plot(
            c.time_s[::10], c.rom_max_k[::10, hot] - KELVIN, "C3s", ms=3, mfc="none", label="ROM hot spot"
        )
        ax.set_title(name, fontsize=9)
        ax.set_ylabel("temperature [degC]")
        ax.legend(fontsize=7)
        ax.grid(True)
        ax = axes[1, j]
        ax.semilogy(c.time_s, np.abs(c.rom_mean_k - c.fem_mean_k).max(axis=1) + 1e-9, "C0-",
                    label="max |ROM - FEM|, cell means")  # fmt: skip
        ax.semilogy(c.time_s, np.abs(c.rom_max_k - c.fem_max_k).max(axis=1) + 1e-9, "C3-",
                    label="max |ROM - FEM|, hot spots")  # fmt: skip
        ax.axhline(BOUND_K, color="k", ls="--", lw=1, label=f"bound {BOUND_K:g} K")
        ax.set_xlabel("time [s]")
        ax.set_ylabel("error over all 12 cells [K]")
        ax.legend(fontsize=7)
        ax.grid(True, which="both", alpha=0.4)
    nodes = rom.metadata.get("nodes", "?")
    fig.suptitle(f"Module thermal ROM (order {rom.order}) vs FEM ({nodes} nodes)", fontsize=10)
    fig.tight_layout()
    with atomic_file(path) as tmp:
        fig.savefig(tmp, dpi=100, format="png")
    plt.close(fig)
    return path


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--coarse", action="store_true", help="the coarse test-suite mesh (8 mm)")
    ap.add_argument("--out", type=Path, default=OUT, help=f"PNG to write (default {OUT})")
    a = ap.parse_args(argv)
    rom, results = validate(a.coarse)
    print(f"ROM order {rom.order} ({rom.metadata.get('nodes', '?')} FEM nodes)")
    for name, c in results:
        print(f"{name:<45} mean error {c.mean_error_k:.4f} K, hot-spot error {c.max_error_k:.4f} K")
    plot(rom, results, a.out)
    print(f"written to {a.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
