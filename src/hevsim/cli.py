"""The ``hevsim`` command: one subcommand per job, each backed by the Python API.

Bad input (a :class:`hevsim.errors.HevsimError`) prints a one-paragraph message and exits 2
without writing a partial output folder.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from hevsim.errors import HevsimError


def _cmd_cycles(args: argparse.Namespace) -> int:
    from hevsim.cycles import list_cycles

    rows = list_cycles()
    print(f"{'name':<15}{'duration s':>11}{'distance mi':>13}{'max mph':>9}  description")
    for r in rows:
        print(
            f"{r['name']!s:<15}{float(r['duration_s']):>11.0f}{float(r['distance_mi']):>13.2f}"
            f"{float(r['max_speed_mph']):>9.1f}  {str(r['description'])[:70]}"
        )
    return 0


def _cmd_simulate(args: argparse.Namespace) -> int:
    from hevsim.config import load_config
    from hevsim.cycles import load_cycle
    from hevsim.sim.simulator import simulate

    cfg = load_config(args.config)
    cycle = load_cycle(args.cycle or cfg.simulation.cycle)
    result = simulate(cfg, cycle, dt_s=args.dt, soc_initial=args.soc_initial)
    out = Path(args.out) if args.out else Path("results") / f"{cfg.name}_{cycle.name}"
    result.save(out, plots=not args.no_plots)
    m = result.metrics
    print(f"{cfg.name} on {cycle.name}: {m['distance_mi']['value']:.2f} mi")
    for key in ("mpg", "mpgge", "l_per_100km", "co2_g_per_km", "soc_final",
                "speed_error_rms_mph", "energy_audit_residual_pct"):  # fmt: skip
        print(f"  {key:<28}{m[key]['value']:>12.4g} {m[key]['unit']}")
    print(f"results written to {out}/ (report.md, metrics.json, timeseries.parquet, plots)")
    return 0


def _cmd_refinement(args: argparse.Namespace) -> int:
    from hevsim.refinement import format_table, run_refinement

    rows = run_refinement(cycle=args.cycle)
    text = format_table(rows, args.cycle)
    print(text)
    if args.out:
        out = Path(args.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = out.with_name(f".{out.name}.tmp")
        tmp.write_text(text + "\n")
        tmp.replace(out)
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``hevsim`` command."""
    parser = argparse.ArgumentParser(prog="hevsim", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("cycles", help="list the shipped drive cycles")
    p.set_defaults(func=_cmd_cycles)

    p = sub.add_parser("simulate", help="forward-simulate a vehicle over a drive cycle")
    p.add_argument("config", help="vehicle configuration (TOML)")
    p.add_argument("--cycle", help="cycle name (see `hevsim cycles`) or CSV file")
    p.add_argument("--out", help="results folder (default results/<config>_<cycle>)")
    p.add_argument("--dt", type=float, help="time step [s] (default from the configuration)")
    p.add_argument("--soc-initial", type=float, help="initial SOC [-]")
    p.add_argument("--no-plots", action="store_true", help="skip plots and report")
    p.set_defaults(func=_cmd_simulate)

    p = sub.add_parser(
        "refinement", help="run the tutorial's sequential-refinement levels and tabulate MPGGE"
    )
    p.add_argument("--cycle", default="udds", help="cycle name or CSV (default udds)")
    p.add_argument("--out", help="also write the table (Markdown) to this file")
    p.set_defaults(func=_cmd_refinement)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the exit status (0 ok, 2 bad input)."""
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args))
    except HevsimError as exc:
        print(f"hevsim: error: {exc}", file=sys.stderr)
        return exc.exit_code


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
