"""Sequential refinement of the series HEV, as in the thesis's tutorial (lectures 2-9).

Each level adds one refinement to the previous one; the shipped configurations are in
``hevsim/data/refinement``. :func:`run_refinement` simulates them all over one cycle and
:func:`format_table` prints MPG and SOC-corrected MPGGE per level. Levels 1-4 have no fuel
model yet (ideal components and an ideal engine whose fuel energy equals its brake work);
their energy is counted at ideal conversion, so every level that adds a loss lowers MPGGE.
"""

from __future__ import annotations

import sys
from importlib import resources
from pathlib import Path
from typing import Any

from hevsim.config import load_config
from hevsim.cycles import load_cycle


def level_files() -> list[Path]:
    """The shipped refinement-level configurations, in order."""
    root = Path(str(resources.files("hevsim") / "data" / "refinement"))
    return sorted(root.glob("level*.toml"))


def run_refinement(cycle: str = "udds", progress: bool | None = None) -> list[dict[str, Any]]:
    """Simulate every level over ``cycle``; one row of metrics per level."""
    from tqdm import tqdm

    from hevsim.sim.simulator import simulate

    cyc = load_cycle(cycle)
    files = level_files()
    show = sys.stderr.isatty() if progress is None else progress
    rows: list[dict[str, Any]] = []
    for i, path in enumerate(tqdm(files, desc="refinement levels", disable=not show), start=1):
        cfg = load_config(path)
        r = simulate(cfg, cyc)
        rows.append({
            "level": i,
            "name": cfg.name,
            "description": cfg.description,
            "mpg": r.value("mpg"),
            "mpgge": r.value("mpgge"),
            "soc_final": r.value("soc_final"),
            "fuel_kg": r.value("fuel_kg"),
            "speed_error_rms_mph": r.value("speed_error_rms_mph"),
            "energy_audit_residual_pct": r.value("energy_audit_residual_pct"),
        })  # fmt: skip
    return rows


def format_table(rows: list[dict[str, Any]], cycle: str) -> str:
    """Markdown table of the refinement levels."""
    lines = [
        f"Sequential refinement on {cycle} (MPGGE with SOC correction, eqs 14-20)",
        "",
        "| level | configuration | MPG | MPGGE | final SOC | RMS speed error [mph] | audit residual [%] |",
        "|---:|---|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        mpg = f"{r['mpg']:.1f}" if r["mpg"] != float("inf") else "n/a (no fuel)"
        lines.append(
            f"| {r['level']} | {r['name']}: {r['description']} | {mpg} | "
            f"{r['mpgge']:.1f} | {r['soc_final']:.3f} | {r['speed_error_rms_mph']:.2f} | "
            f"{r['energy_audit_residual_pct']:.1e} |"
        )
    return "\n".join(lines)
