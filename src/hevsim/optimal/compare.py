"""Benchmark architectures on equal terms: DP over several configurations and cycles.

As the thesis did for its industrial partner (chapter 3): each vehicle is driven optimally
(dynamic programming, charge-sustaining) over each cycle, so differences come from the
architecture and components, not from a controller's tuning.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import pandas as pd

COLUMNS: tuple[tuple[str, str, str], ...] = (
    # (metric name, column header, format)
    ("mpg", "MPG", "{:.1f}"),
    ("mpgge", "MPGGE", "{:.1f}"),
    ("l_per_100km", "L/100 km", "{:.2f}"),
    ("co2_g_per_km", "CO2 g/km", "{:.0f}"),
    ("soc_initial", "initial SOC", "{:.3f}"),
    ("soc_final", "final SOC", "{:.3f}"),
    ("engine_on_time_s", "engine on [s]", "{:.0f}"),
    ("compute_time_s", "compute [s]", "{:.2f}"),
)


def compare(
    configs: Sequence[str | Path | Any],
    cycles: Sequence[str],
    progress: bool | None = None,
    out_dir: str | Path | None = None,
    **options: Any,
) -> pd.DataFrame:
    """Run :func:`hevsim.optimal.hev.optimize` for every configuration x cycle.

    ``options`` go to ``optimize`` (grid sizes, final constraint, threads...). With
    ``out_dir`` each run's results folder is written to ``out_dir/<config>_<cycle>``. Returns
    one row per run with the metrics of :data:`COLUMNS`.

    Every configuration and cycle is loaded and validated, the thread count chosen once
    (:mod:`hevsim.threads`) and every pair's DP size checked against the free memory
    (:func:`hevsim.optimal._feedback.check_dp_size`) before the first solve, so bad input is refused
    in about a second rather than after the earlier pairs are solved (issue 15.9).
    """
    from tqdm import tqdm

    from hevsim.cycles import DriveCycle, load_cycle
    from hevsim.errors import DPInfeasibleError
    from hevsim.optimal._feedback import check_dp_size
    from hevsim.optimal.hev import optimize, resolve_model
    from hevsim.threads import choose_threads

    show = sys.stderr.isatty() if progress is None else progress
    models = [resolve_model(c) for c in configs]
    loaded = {c: load_cycle(c) for c in dict.fromkeys(cycles)}
    for (arch, model), config in zip(models, configs, strict=True):
        s = arch.settings(model)
        soc_points = int(options.get("soc_grid_points") or s.soc_points)
        input_points = int(options.get("input_grid_points") or s.input_points)
        for name, cyc in loaded.items():
            label = f"{getattr(model, 'name', Path(str(config)).stem)} on {name}"
            n_steps = len(cyc.time_s) - 1 if isinstance(cyc, DriveCycle) else 0
            check_dp_size(label, n_steps, soc_points, input_points)
    options = {**options, "threads": choose_threads(options.get("threads")).threads}
    rows: list[dict[str, Any]] = []
    jobs = [(c, cyc) for c in configs for cyc in cycles]
    for config, cycle in tqdm(jobs, desc="DP runs", disable=not show):
        try:
            res = optimize(config, loaded[cycle], progress=False, **options)
        except DPInfeasibleError as exc:
            # a vehicle that cannot drive a cycle is a result of the benchmark, not a crash
            arch, model = resolve_model(config)
            row = {"configuration": getattr(model, "name", Path(str(config)).stem),
                   "architecture": arch.name, "cycle": cycle, "note": str(exc)}  # fmt: skip
            row.update({m: float("nan") for m, _, _ in COLUMNS})
            rows.append(row)
            continue
        name = str(res.metadata.get("config", Path(str(config)).stem))
        row = {"configuration": name, "architecture": res.architecture, "cycle": cycle, "note": ""}
        row.update({m: res.value(m) for m, _, _ in COLUMNS})
        rows.append(row)
        if out_dir is not None:
            save_with_plots(res, Path(out_dir) / f"{name}_{cycle}")
    return pd.DataFrame(rows)


def save_with_plots(result: Any, out: Path, plots: bool = True) -> Path:
    """Save an optimization result and, in the same atomic folder, its plots."""
    return Path(result.save(out, plots=plots))


def format_table(table: pd.DataFrame) -> str:
    """Markdown table of a :func:`compare` result."""
    heads = ["configuration", "architecture", "cycle", *(h for _, h, _ in COLUMNS)]
    lines = ["| " + " | ".join(heads) + " |", "|" + "---|" * 3 + "---:|" * len(COLUMNS)]
    notes: list[str] = []
    for row in table.to_dict("records"):
        cells = [str(row["configuration"]), str(row["architecture"]), str(row["cycle"])]
        if row.get("note"):
            notes.append(f"{len(notes) + 1}. {row['configuration']} on {row['cycle']}: {row['note']}")
            cells += [f"cannot follow the cycle ({len(notes)})"] + [""] * (len(COLUMNS) - 1)
        else:
            cells += [fmt.format(row[m]) for m, _, fmt in COLUMNS]
        lines.append("| " + " | ".join(cells) + " |")
    if notes:
        lines += ["", *notes]
    return "\n".join(lines)


def write_table(table: pd.DataFrame, out_dir: str | Path) -> list[Path]:
    """Write comparison.csv and comparison.md into ``out_dir`` (each atomically)."""
    from hevsim.io import write_text_atomic

    out = Path(out_dir)
    return [
        write_text_atomic(out / "comparison.csv", table.to_csv(index=False, float_format="%.6g")),
        write_text_atomic(out / "comparison.md", format_table(table) + "\n"),
    ]
