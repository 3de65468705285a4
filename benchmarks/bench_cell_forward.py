"""Benchmark: ``[battery] model = "cell"`` against ``"table"`` on every architecture's forward
loop, one UDDS run each (issue 24 item 3), the table battery measured in the same run as the
ratio baseline.

Cases, for each architecture with a traction battery (series HEV: examples/series_hev.toml;
parallel P2: high_performance_parallel_hev.toml; parallel P3: parallel_hev.toml; power split:
prius_like_power_split.toml; BEV: bev.toml): the shipped file (its table battery) and the same
file with ``[battery]`` replaced by a ``cell`` pack of the thesis cell (one RC pair, lumped
thermal; 100 x 6 cells, 100 x 40 for the BEV). Every run builds its model from the loaded
configuration (not from the file) and uses the architecture's compiled loop (the series HEV its
kernel). ``--python`` adds the cell case through the Python reference loop.

Prints the median of ``--repeat`` runs after one warm-up (compilation) in ms, the ratio cell /
table, the other processes' load during the block and ``uptime``.

    python benchmarks/bench_cell_forward.py [--repeat 5] [--python]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import hevsim
from _machine import OtherLoad, median_time
from hevsim.config import load_vehicle_config
from hevsim.cycles import load_cycle

ROOT = Path(__file__).resolve().parents[1]
EX = ROOT / "examples"
CASES = {  # label: (example, cells in series, in parallel)
    "series HEV": ("series_hev.toml", 100, 6),
    "parallel P2": ("high_performance_parallel_hev.toml", 100, 6),
    "parallel P3": ("parallel_hev.toml", 100, 6),
    "power split": ("prius_like_power_split.toml", 60, 8),
    "BEV": ("bev.toml", 100, 40),
}


def cell_file(tmp: Path, example: str, n_s: int, n_p: int) -> Path:
    """``example`` with its ``[battery]`` replaced by a ``cell`` pack of the thesis cell."""
    text = (EX / example).read_text()
    start = text.index("[battery]")
    end = text.index("\n[", start + 1) + 1
    section = (
        f'[battery]\nmodel = "cell"\ndata = "thesis_table_4_1"\nn_series = {n_s}\nn_parallel = {n_p}\n'
        "max_discharge_current_a = 200.0\nmax_charge_current_a = 200.0\nsoc_min = 0.3\nsoc_max = 0.9\n\n"
    )
    for p in EX.iterdir():
        if not (tmp / p.name).exists():
            (tmp / p.name).symlink_to(p)
    out = tmp / f"cell_{example}"
    out.write_text(text[:start] + section + text[end:])
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--python", action="store_true", help="also the cell case through the Python loop")
    args = ap.parse_args()
    cycle = load_cycle("udds")
    print(f"uptime: {subprocess.run(['uptime'], capture_output=True, text=True).stdout.strip()}")
    print(f"{'architecture':<14}{'table ms':>10}{'cell ms':>10}{'cell/table':>12}"
          + (f"{'cell Python ms':>16}" if args.python else "") + f"{'other load':>12}")  # fmt: skip
    with tempfile.TemporaryDirectory() as d:
        for label, (example, n_s, n_p) in CASES.items():
            table = load_vehicle_config(EX / example)
            cell = load_vehicle_config(cell_file(Path(d), example, n_s, n_p))
            with OtherLoad() as load:
                t_tab = median_time(lambda c=table: hevsim.simulate(c, cycle), args.repeat, warm=True)
                t_cell = median_time(lambda c=cell: hevsim.simulate(c, cycle), args.repeat, warm=True)
                t_py = None
                if args.python and label != "series HEV":
                    os.environ["HEVSIM_FORWARD"] = "python"
                    try:
                        t_py = median_time(lambda c=cell: hevsim.simulate(c, cycle), max(1, args.repeat // 2))
                    finally:
                        del os.environ["HEVSIM_FORWARD"]
            py = f"{t_py * 1e3:>16.1f}" if t_py is not None else (f"{'-':>16}" if args.python else "")
            cores = f"{load.cores:.2f}" if load.cores is not None else "?"
            print(
                f"{label:<14}{t_tab * 1e3:>10.1f}{t_cell * 1e3:>10.1f}{t_cell / t_tab:>12.2f}{py}{cores:>12}"
            )
    print(f"uptime: {subprocess.run(['uptime'], capture_output=True, text=True).stdout.strip()}")


if __name__ == "__main__":
    main()
