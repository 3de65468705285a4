"""The ``hevsim`` command: one subcommand per job, each backed by the Python API.

Bad input (a :class:`hevsim.errors.HevsimError`) prints a one-paragraph message and exits 2
without writing a partial output folder. Exit statuses: 0 success; 2 bad input, or a run that
left its physical domain (:class:`~hevsim.errors.DomainError`: NaN/inf in a channel, SOC
outside [0, 1], a cell beyond its short-circuit current); 3 a run that completed but whose
vehicle could not follow the drive cycle (:class:`~hevsim.errors.TrackingError`, bound
:data:`hevsim.sim.checks.TRACKING_BOUND`). Messages say what, where (time, channel) and the
likely cause; no results are written on a non-zero exit.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, Literal

from hevsim.errors import HevsimError


def _prepare(
    args: argparse.Namespace,
    out: str | Path,
    *inputs: str | Path | None,
    kind: Literal["dir", "file"] = "dir",
    option: str = "--out",
    ours: Callable[[Path], bool] | None = None,
) -> Path:
    """Check the output path before any computation (:func:`hevsim.io.prepare_output`);
    ``inputs`` (the files the command reads) are never replaced nor a folder holding them."""
    from hevsim.io import prepare_output

    protect = [p for p in inputs if p is not None and Path(p).exists()]
    prepare_output(out, kind=kind, force=args.force, option=option, protect=protect, ours=ours)
    args.prepared_out = Path(out)  # named by the Ctrl-C line (main)
    return Path(out)


def _written(out: Path) -> str:
    """The files of the results folder ``out`` as its marker lists them, PNGs counted."""
    from hevsim.io import results_files

    files = results_files(out) or []
    png = [f for f in files if f.endswith(".png")]
    names = [f for f in files if not f.endswith(".png")]
    if png:
        names.append(f"{len(png)} PNG plot{'s' if len(png) > 1 else ''}")
    return ", ".join(names)


def _cmd_import_vehicle(args: argparse.Namespace) -> int:
    from hevsim.vehicle_import import run_command

    return run_command(args)


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
    from hevsim.config import SERIES_CONTROLLER_KEYS, SeriesHEVConfig, SimulationSection, load_vehicle_config
    from hevsim.cycles import load_cycle
    from hevsim.errors import ConfigError
    from hevsim.schema import check_option
    from hevsim.sim.simulator import simulate

    check_option("--dt", args.dt, SimulationSection, "dt_s")
    check_option("--soc-initial", args.soc_initial, SimulationSection, "soc_initial")
    cfg = load_vehicle_config(args.config)
    series = isinstance(cfg, SeriesHEVConfig)
    if series and args.schedule and (args.controller or args.ecms_from):
        used = ", ".join(
            k for k, v in {"--controller": args.controller, "--ecms-from": args.ecms_from}.items() if v
        )
        raise ConfigError(f"{args.config}: --schedule replaces the series HEV's supervisor; drop {used}.")
    if not series and args.schedule:
        raise ConfigError(f"{args.config}: --schedule replays a series-HEV genset schedule; this is a "
                          f"{cfg.architecture} HEV (use --controller).")  # fmt: skip
    overrides: dict[str, object] = {}
    if args.ecms_from:
        from hevsim.control.parallel import ecms_from_costate_csv

        overrides = dict(ecms_from_costate_csv(args.ecms_from))
    kind = args.controller or ("ecms" if args.ecms_from else None)  # whatever rule-based kind is configured
    if kind and kind != cfg.controller.kind:  # validated as a file with that kind (exit 2 if refused)
        option = f"--controller {args.controller}" if args.controller else f"--ecms-from {args.ecms_from}"
        try:
            cfg = cfg.replace(**{"controller.kind": kind})
        except ConfigError as exc:
            raise ConfigError(f"{args.config} with {option}: {exc}") from exc
    online = not series or cfg.controller.kind not in SERIES_CONTROLLER_KEYS  # hevsim.control's loop
    cycle = load_cycle(args.cycle or cfg.simulation.cycle)
    if args.replay and not args.schedule:
        raise ConfigError("--replay applies a genset schedule exactly as the DP took it; give the schedule "
                          "with --schedule DIR/timeseries.csv (from `hevsim optimize`).")  # fmt: skip
    out = Path(args.out) if args.out else Path("results") / f"{cfg.name}_{cycle.name}"
    _prepare(args, out, args.config, args.cycle, args.schedule)
    schedule = None
    if args.schedule:
        from hevsim.sim.simulator import GensetSchedule

        schedule = GensetSchedule.from_csv(args.schedule, quasi_static=args.replay)
    from hevsim.warmup import simulation_preflight

    pack_options = _pack_options(cfg, args)
    simulation_preflight(cfg, cycle, args.dt)  # memory refusal, long-run line, compile notice
    age = _age_state_option(cfg, args.age_state, bool(overrides))
    if "ambient_c" in pack_options:  # [battery] model = "cell" at another ambient
        result = simulate(cfg, cycle, dt_s=args.dt, soc_initial=args.soc_initial, schedule=schedule,
                          controller=kind, **pack_options)  # fmt: skip
    elif age is not None or pack_options:  # a pack that ages over the run, or at another ambient
        from hevsim.sim.pack_vehicle import simulate_pack_vehicle

        result = simulate_pack_vehicle(cfg, cycle, args.dt, args.soc_initial, controller=kind,
                                       schedule=schedule, age_state=age, **pack_options)  # fmt: skip
    elif not online or schedule is not None:  # the series HEV's kernel supervisors
        result = simulate(cfg, cycle, dt_s=args.dt, soc_initial=args.soc_initial, schedule=schedule)
    else:
        from hevsim.architectures import architecture

        arch = architecture(cfg.architecture, str(args.config))
        result = arch.simulate(
            cfg, cycle, dt_s=args.dt, soc_initial=args.soc_initial, controller=kind, **overrides
        )
        print(
            f"controller: {result.metadata['controller']}"
            + (f" (s = {overrides['equivalence_factor']:.4g} from {args.ecms_from})" if overrides else "")
        )
    result.save(out, plots=not args.no_plots, csv=True if args.csv else None)
    m = result.metrics
    print(f"{cfg.name} on {cycle.name}: {m['distance_mi']['value']:.2f} mi")
    for key in ("mpg", "mpgge", "l_per_100km", "co2_g_per_km", "soc_final",
                "speed_error_rms_mph", "energy_audit_residual_pct", "hydrogen_kg", "mpge"):  # fmt: skip
        if key in m:  # hydrogen_kg, mpge: a fuel-cell vehicle's (hevsim.sim.fcev)
            print(f"  {key:<28}{m[key]['value']:>12.4g} {m[key]['unit']}")
    if "pack_peak_cell_temp_c" in m:  # [battery] model = "pack"
        print(f"  pack: peak cell {m['pack_peak_cell_temp_c']['value']:.1f} degC, derated "
              f"{m['pack_derated_s']['value']:.0f} s, held back by the BMS "
              f"{m['pack_bms_limited_s']['value']:.0f} s, "
              f"cooling {m['pack_cooling_energy_j']['value'] / 3600:.1f} Wh, energy balance "
              f"{m['pack_energy_balance_relative']['value']:.1e}")  # fmt: skip
    if "battery_peak_cell_temp_c" in m:  # [battery] model = "cell" (forward architectures)
        print(f"  cell: peak {m['battery_peak_cell_temp_c']['value']:.1f} degC, final "
              f"{m['battery_final_cell_temp_c']['value']:.1f} degC, energy balance "
              f"{m['battery_cell_energy_balance_relative']['value']:.1e}")  # fmt: skip
    if age is not None:
        age.save(args.age_state)
        soh = age.soh(*_eol(cfg))
        print(f"age state written to {args.age_state} (weakest cell SOH {soh.min():.5f})")
    print(f"results written to {out}/ ({_written(out)})")
    return 0


def _age_state_option(cfg: Any, path: str | None, ecms_overrides: bool) -> Any:
    """The pack age state of ``--age-state FILE`` (new cells when the file does not exist yet)."""
    if not path:
        return None
    from hevsim.battery.life import load_or_new_age_state
    from hevsim.errors import ConfigError
    from hevsim.sim.life import _pack_config, require_pack

    require_pack(cfg, f"--age-state {path}")
    if ecms_overrides:
        raise ConfigError(f"--age-state {path}: ageing during the drive needs no --ecms-from.")
    return load_or_new_age_state(path, _pack_config(cfg).n_cells)


def _pack_options(cfg: Any, args: argparse.Namespace) -> dict[str, Any]:
    """``--ambient-c``/``--soak``/``--cooling-off`` of ``hevsim simulate`` as keywords of
    :func:`hevsim.sim.pack_vehicle.simulate_pack_vehicle` (ConfigError without a pack)."""
    from hevsim.battery.pack import PackSection
    from hevsim.errors import ConfigError
    from hevsim.schema import check_option

    given = {
        "--ambient-c": args.ambient_c is not None,
        "--soak": args.soak,
        "--cooling-off": args.cooling_off,
    }
    used = [k for k, v in given.items() if v]
    if not used:
        return {}
    battery = getattr(cfg, "battery", None)
    if battery is not None and battery.model == "cell" and not args.cooling_off:  # the cells' ambient
        if args.soak and args.ambient_c is None:
            raise ConfigError("--soak starts the cells at the ambient; give it with --ambient-c.")
        check_option("--ambient-c", args.ambient_c, PackSection, "ambient_temp_c")
        return {"ambient_c": args.ambient_c, "soak": args.soak}
    if battery is None or battery.model != "pack":
        got = "no [battery]" if battery is None else f"key 'battery.model' = {battery.model!r}"
        raise ConfigError(
            f"{args.config}: option {', '.join(used)} sets the pack's ambient and cooling; it needs "
            f"[battery] model = 'pack' (got {got})."
        )
    if args.soak and args.ambient_c is None:
        raise ConfigError("--soak starts the cells and the coolant at the ambient; give it with --ambient-c.")
    check_option("--ambient-c", args.ambient_c, PackSection, "ambient_temp_c")
    return {"ambient_temp_c": args.ambient_c, "soak": args.soak, "cooling_off": args.cooling_off}


def _eol(cfg: Any) -> tuple[float, float]:
    from hevsim.sim.life import _eol_fractions

    return _eol_fractions(cfg)


def _cmd_life(args: argparse.Namespace) -> int:
    from hevsim.battery.ageing import SOH_DEFINITION
    from hevsim.battery.life import PackAgeState
    from hevsim.config import load_vehicle_config
    from hevsim.io import atomic_directory, write_json
    from hevsim.sim.life import plot_life, run_life

    cfg = load_vehicle_config(args.config)
    cycle = args.cycle or cfg.simulation.cycle
    out = Path(args.out) if args.out else Path("results") / f"{cfg.name}_{Path(str(cycle)).stem}_life"
    _prepare(args, out, args.config, args.cycle)
    checkpoint = Path(f"{out}.checkpoint.json")
    start = _age_state_option(cfg, args.age_state, False) if args.age_state else None
    res = run_life(cfg, cycle, args.until_soh, soh_step=args.soh_step, max_blocks=args.max_blocks,
                   checkpoint=checkpoint, resume=args.resume, ambient_temp_c=args.ambient_c,
                   age_state=start)  # fmt: skip
    state: PackAgeState = res.state
    with atomic_directory(out) as tmp:
        res.table.to_csv(tmp / "life.csv", index=False, float_format="%.6g")
        state.save(tmp / "age_state.json")
        write_json(tmp / "summary.json", {"reached": res.reached, "metadata": res.metadata,
                                          "soh_definition": SOH_DEFINITION})  # fmt: skip
        if not args.no_plots:
            plot_life(res, tmp / "life.png")
    if args.age_state:
        state.save(args.age_state)
    checkpoint.unlink(missing_ok=True)
    last = res.table.iloc[-1]
    verb = "reached" if res.reached else "not reached"
    print(f"{cfg.name} on {cycle}: SOH {args.until_soh:g} {verb} after {last['distance_km']:.0f} km "
          f"({int(last['repetitions'])} cycles, {len(res.table)} simulated): weakest cell SOH "
          f"{last['soh_min']:.4f}, peak cell {last['peak_cell_temp_c']:.1f} degC, "
          f"{last['mpgge']:.1f} MPGGE")  # fmt: skip
    print(f"results written to {out}/ ({_written(out)})")
    return 0


def _cmd_performance(args: argparse.Namespace) -> int:
    from hevsim.config import load_vehicle_config
    from hevsim.errors import ConfigError
    from hevsim.sim.performance import performance
    from hevsim.units import MPS_PER_MPH

    cfg = load_vehicle_config(args.config)
    checks = (("--dt", args.dt, 1e-3, 10.0), ("--grade-speed-mph", args.grade_speed_mph, 0.0, 300.0),
              ("--soc", args.soc, 0.0, 1.0))  # fmt: skip
    for option, value, lo, hi in checks:
        if value is not None and not lo <= value <= hi:
            raise ConfigError(
                f"option {option} = {value:g} is out of range; expected a value between {lo:g} and {hi:g}."
            )
    out = Path(args.out) if args.out else Path("results") / f"{cfg.name}_performance"
    _prepare(args, out, args.config)
    res = performance(
        cfg, dt_s=args.dt or 0.2, soc=args.soc, grade_speed_mps=args.grade_speed_mph * MPS_PER_MPH
    )
    res.save(out, plots=not args.no_plots)
    print(f"{cfg.name} ({cfg.architecture}): performance")
    print(res.format())
    print(f"results written to {out}/ ({_written(out)})")
    return 0


def _cmd_lap(args: argparse.Namespace) -> int:
    from hevsim.config import SimulationSection, load_vehicle_config
    from hevsim.schema import check_option
    from hevsim.sim.lap import check_step, simulate_lap
    from hevsim.tracks import TRACK_NAMES

    cfg = load_vehicle_config(args.config)
    step = check_step(args.step)
    check_option("--soc", args.soc, SimulationSection, "soc_initial")
    track_name = Path(args.track).stem if args.track not in TRACK_NAMES else args.track
    out = Path(args.out) if args.out else Path("results") / f"{cfg.name}_{track_name}_lap"
    _prepare(args, out, args.config, None if args.track in TRACK_NAMES else args.track, args.deploy)
    if args.optimize:
        from hevsim.optimal.lap_deploy import run_cli

        opt = run_cli(
            cfg,
            args.track,
            method=args.optimize,
            budget_kj=args.budget_kj,
            fuel_budget_kg=args.fuel_budget_kg,
            window_kj=args.window_kj,
            step_m=step,
            deploy_step_m=check_step(args.deploy_step),
            soc=args.soc,
            out=out,
            plots=not args.no_plots,
            force=args.force,
        )
        print(f"{cfg.name} on {opt.problem.track}: optimal deployment ({args.optimize})")
        print("\n".join(f"{k:<40}{v!s:>16}" for k, v in opt.summary().items()))
        print(f"results written to {out}/ ({_written(out)})")
        return 0
    limit = None
    if args.deploy:
        from hevsim.optimal.lap_deploy import read_deploy_map
        from hevsim.tracks import load_track

        trk = load_track(args.track, step_m=step)
        limit = read_deploy_map(args.deploy, trk)
    res = simulate_lap(cfg, args.track, step_m=step, soc=args.soc, battery_power_max_w=limit)
    res.save(out, plots=not args.no_plots)
    print(f"{cfg.name} ({cfg.architecture}) on {res.track.name}: lap time {res.lap_time_s:.3f} s")
    print(res.format())
    print(f"results written to {out}/ ({_written(out)})")
    return 0


def _pack_changes(items: list[str]) -> dict[str, Any]:
    """``--pack-set section.key=VALUE`` options as dotted keys and values (VALUE read as a TOML
    value: ``0``, ``15.0``, ``"pi"``, ``true``; a bare word is a string)."""
    import tomllib

    from hevsim.errors import ConfigError

    out: dict[str, Any] = {}
    for item in items:
        key, sep, text = item.partition("=")
        if not sep or not key.strip() or not text.strip():
            raise ConfigError(
                f"option --pack-set = {item!r}; expected section.key=VALUE (e.g. cooling.chiller=0)."
            )
        try:
            value = tomllib.loads(f"v = {text.strip()}")["v"]
        except tomllib.TOMLDecodeError:
            value = text.strip()
        out[key.strip()] = value
    return out


def _cmd_stint(args: argparse.Namespace) -> int:
    from hevsim.config import SimulationSection, load_vehicle_config
    from hevsim.schema import check_option
    from hevsim.sim.lap import check_step
    from hevsim.sim.stint import check_laps, simulate_stint
    from hevsim.tracks import TRACK_NAMES

    cfg = load_vehicle_config(args.config)
    laps, step = check_laps(args.laps), check_step(args.step)
    check_option("--soc", args.soc, SimulationSection, "soc_initial")
    track_name = Path(args.track).stem if args.track not in TRACK_NAMES else args.track
    out = Path(args.out) if args.out else Path("results") / f"{cfg.name}_{track_name}_stint"
    _prepare(args, out, args.config, None if args.track in TRACK_NAMES else args.track)
    opts = {"ambient_temp_c": args.ambient, "soak": args.soak, "cooling_off": args.cooling_off}
    if args.pack_set:
        opts["pack_changes"] = _pack_changes(args.pack_set)
    if args.optimize:
        from hevsim.optimal.stint_deploy import simulate_stint_optimized

        res = simulate_stint_optimized(
            cfg,
            args.track,
            laps,
            method=args.optimize,
            budget_kj=args.budget_kj,
            reoptimize_rtol=args.reoptimize_rtol,
            deploy_step_m=check_step(args.deploy_step),
            window_kj=args.window_kj,
            step_m=step,
            dt_s=args.dt,
            soc_initial=args.soc,
            **opts,
        )
    else:
        res = simulate_stint(cfg, args.track, laps, step_m=step, dt_s=args.dt, soc_initial=args.soc, **opts)
    res.save(out, plots=not args.no_plots)
    print(f"{cfg.name} ({cfg.architecture}) on {res.summary['track']}: stint of {laps} laps")
    print(res.format())
    print(f"results written to {out}/ ({_written(out)})")
    return 0


def _cmd_label(args: argparse.Namespace) -> int:
    from hevsim.sim.label import label

    out = Path(args.out) if args.out else Path("results") / f"{Path(args.config).stem}_label"
    _prepare(args, out, args.config)
    res = label(args.config, model_year=args.model_year, charger_efficiency=args.charger_efficiency)
    res.save(out)
    print(res.text())
    print(f"results written to {out}/ ({_written(out)})")
    return 0


def _cmd_refinement(args: argparse.Namespace) -> int:
    from hevsim.refinement import format_energy_table, format_table, run_refinement

    if args.out:
        _prepare(args, args.out, args.cycle, kind="file", ours=_is_refinement_table)
    rows = run_refinement(args.cycle, calibration=args.calibration)
    text = format_table(rows, args.cycle, args.calibration)
    if args.energy:
        text += "\n\nEnergy per level [MJ] (hevsim energy audit)\n\n" + format_energy_table(rows)
    print(text)
    if args.out:
        from hevsim.io import write_text_atomic

        write_text_atomic(args.out, text + "\n")
    return 0


def _is_refinement_table(path: Path) -> bool:
    """True if ``path`` is a table written by ``hevsim refinement --out``."""
    from hevsim.refinement import format_table

    try:
        with open(path, encoding="utf-8") as fh:
            return fh.readline().startswith(format_table([], "").split(" on ")[0] + " on ")
    except (OSError, UnicodeDecodeError):
        return False


def _dp_options(args: argparse.Namespace) -> dict[str, Any]:
    from hevsim.config import OptimizationSection
    from hevsim.schema import check_option

    check_option("--soc-points", args.soc_points, OptimizationSection, "soc_grid_points")
    check_option("--input-points", args.input_points, OptimizationSection, "throttle_grid_points")
    check_option("--soc-initial", args.soc_initial, OptimizationSection, "soc_initial")
    opts: dict[str, Any] = {"final_constraint": args.final_constraint, "threads": args.threads}
    if args.soc_points is not None:
        opts["soc_grid_points"] = args.soc_points
    if args.input_points is not None:
        opts["input_grid_points"] = args.input_points
    if args.soc_initial is not None:
        opts["soc_initial"] = args.soc_initial
    if args.final_soc != "config":
        opts["final_soc"] = args.final_soc
    return opts


def _cmd_optimize(args: argparse.Namespace) -> int:
    from hevsim.cycles import load_cycle
    from hevsim.optimal.hev import optimize, resolve_model

    arch, hev = resolve_model(args.config)
    cycle = load_cycle(args.cycle or arch.settings(hev).cycle)
    name = str(hev.config.name)
    out = Path(args.out) if args.out else Path("results") / f"{name}_{cycle.name}_optimal"
    _prepare(args, out, args.config, args.cycle)
    res = optimize(hev, cycle, store_cost_to_go=not args.no_plots, progress=None, **_dp_options(args))
    res.save(out, plots=not args.no_plots)
    print(f"{name} ({res.architecture} HEV) on {res.cycle.name}: DP optimum")
    for key in ("mpg", "mpgge", "l_per_100km", "co2_g_per_km", "soc_initial", "soc_final",
                "engine_on_time_s", "compute_time_s"):  # fmt: skip
        print(f"  {key:<28}{res.metrics[key]['value']:>12.4g} {res.metrics[key]['unit']}")
    print(f"results written to {out}/ ({_written(out)})")
    return 0


def _cmd_compare(args: argparse.Namespace) -> int:
    from hevsim.io import atomic_directory
    from hevsim.optimal.compare import compare, format_table, write_table

    cycles = [c.strip() for c in args.cycles.split(",") if c.strip()]
    out = Path(args.out) if args.out else Path("results") / "comparison"
    _prepare(args, out, *args.configs)
    with atomic_directory(out) as tmp:
        table = compare(args.configs, cycles, out_dir=tmp if args.save_runs else None, **_dp_options(args))
        write_table(table, tmp)
    print(format_table(table))
    print(f"table written to {out}/comparison.csv and comparison.md")
    return 0


def _cmd_cell(args: argparse.Namespace) -> int:
    from hevsim.battery.config import run_config

    out = Path(args.out) if args.out else Path("results") / Path(args.config).stem
    _prepare(args, out, args.config)
    result = run_config(args.config)
    result.save(out)
    for key, m in result.metrics.items():
        value = m["value"] if isinstance(m, dict) else m
        print(f"  {key:<34}{value:>12.5g}")
    print(f"results written to {out}/")
    return 0


def _parse_fit(items: list[str]) -> dict[str, tuple[float, float, float]]:
    from hevsim.errors import ConfigError

    fit: dict[str, tuple[float, float, float]] = {}
    for item in items:
        name, _, rest = item.partition("=")
        try:
            init, lo, hi = (float(v) for v in rest.split(","))
        except ValueError as exc:
            raise ConfigError(
                f"--fit {item!r}: expected NAME=INITIAL,LOWER,UPPER, e.g. c_heat=90,10,1000."
            ) from exc
        fit[name.strip()] = (init, lo, hi)
    return fit


def _cmd_calibrate(args: argparse.Namespace) -> int:
    from hevsim.battery.calibrate import CellTestRecord, calibrate
    from hevsim.battery.config import CellSection
    from hevsim.schema import check_option
    from hevsim.units import c_to_k

    check_option("--soc-initial", args.soc_initial, CellSection, "soc_initial")
    check_option("--ambient-c", args.ambient_c, CellSection, "temp_c")

    out = Path(args.out) if args.out else Path("results") / f"calibration_{Path(args.test).stem}"
    _prepare(args, out, args.params, args.test, args.validate, *(args.data or []))
    if args.fit is not None and (args.validate is not None or args.data):
        from hevsim.errors import InputError

        opt = "--validate" if args.validate is not None else "--data"
        raise InputError(f"calibrate: {opt} needs the full calibration (leave out --fit).")
    if args.robust_mv is not None and not (args.data and args.robust_mv > 0):
        from hevsim.errors import InputError

        raise InputError(
            f"calibrate --robust-mv {args.robust_mv!r}: expected a scale > 0 mV, with --data (the joint fit)."
        )
    if args.hysteresis and not args.data:
        from hevsim.errors import InputError

        raise InputError("calibrate --hysteresis: needs --data (the hysteresis is fitted in the joint fit).")
    no_temp_ok = args.fit is None and args.ambient_c is not None  # full calibration: temp_k optional
    record = CellTestRecord.from_csv(args.test, temperature_k=c_to_k(args.ambient_c) if no_temp_ok else None)
    if args.fit is None:
        return _calibrate_full(args, record, out)
    result = calibrate(
        args.params,
        record,
        _parse_fit(args.fit),
        soc_initial=args.soc_initial,
        port_temp_k=c_to_k(args.ambient_c) if args.ambient_c is not None else None,
    )
    result.save(out)
    for name, value in result.values.items():
        print(f"  {name:<28}{value:>12.5g} +/- {result.std_errors[name]:.2g}")
    for sig, err in result.rmse.items():
        print(f"  RMSE {sig:<23}{err:>12.4g}")
    print(f"results written to {out}/ (fit.json, timeseries.csv, overlay.png)")
    return 0


def _calibrate_full(args: argparse.Namespace, record: Any, out: Path) -> int:
    """``hevsim calibrate`` without ``--fit``: OCV, R_s, RC, charge transfer and thermal
    (:func:`hevsim.battery.identify.identify`), optionally validated on ``--validate``."""
    from hevsim.battery.calibrate import CellTestRecord
    from hevsim.battery.identify import identify, validate
    from hevsim.units import c_to_k

    result = identify(
        args.params,
        record,
        soc_initial=args.soc_initial,
        capacity_ah=args.capacity_ah,
        port_temp_k=c_to_k(args.ambient_c) if args.ambient_c is not None else None,
        n_rc=args.n_rc,
        charge_transfer=not args.no_charge_transfer,
    )
    if args.data:  # tests at other ambients: R0(SOC, T), then the temperature laws jointly (issue 27)
        from hevsim.battery.identify import fit_temperature, fit_temperature_laws

        others = [CellTestRecord.from_csv(f) for f in args.data]
        robust: dict[str, Any] = {}
        if args.robust_mv is not None:
            robust = {"loss": "soft_l1", "f_scale": args.robust_mv}
        result = fit_temperature_laws(  # sigma_v = 1 mV
            fit_temperature(result, others), others, hysteresis=args.hysteresis, **robust
        )
    if args.validate is not None:
        ambient_k = c_to_k(args.ambient_c) if args.ambient_c is not None else None
        val = CellTestRecord.from_csv(args.validate, temperature_k=ambient_k)
        result = validate(result, val, soc_initial=args.validate_soc, port_temp_k=ambient_k)
    result.save(out)
    for row in result.parameters.to_dict(orient="records"):
        flag = f"  UNIDENTIFIABLE: {row['flag']}" if row["flag"] else ""
        ci = f"95% [{row['ci95_low']:.4g}, {row['ci95_high']:.4g}]"
        print(f"  {row['name']:<24}{row['value']:>12.5g} {row['unit']:<4} {ci}{flag}")
    rmse = result.rmse
    print(
        f"  RMSE voltage {1e3 * rmse['voltage_v']:.2f} mV (max {1e3 * rmse['voltage_max_v']:.1f} mV), "
        f"temperature {rmse['temp_k']:.3g} K"
    )
    if result.validation_errors is not None:
        print(f"validation on {args.validate}:")
        for r in result.validation_errors.to_dict(orient="records"):
            err = f"RMSE {1e3 * float(r['rmse_v']):6.2f} mV  max {1e3 * float(r['max_abs_v']):6.1f} mV"
            print(f"  {r['range']:<10}{r['samples']:>7} samples  {err}")
    print(f"results written to {out}/ (cell.toml: the parameter set; {_written(out)})")
    return 0


def _cmd_export_fmu(args: argparse.Namespace) -> int:
    from hevsim.battery.config import load_config as load_cell_config
    from hevsim.battery.fmu import export_fmu, is_hevsim_fmu
    from hevsim.battery.native import export_native_fmu, is_native_fmu
    from hevsim.battery.native.rom import export_rom_fmu, is_rom_file
    from hevsim.errors import ConfigError

    if args.fmi_version == 3 and args.pythonfmu:
        raise ConfigError("--fmi-version 3: FMI 3.0 FMUs are native only; drop --pythonfmu.")

    def ours(path: Path) -> bool:
        return is_hevsim_fmu(path) or is_native_fmu(path)

    _prepare(args, args.output, args.config, kind="file", option="-o", ours=ours)
    if is_rom_file(args.config):
        if args.pythonfmu:
            raise ConfigError(f"{args.config}: the thermal ROM FMU is native only; drop --pythonfmu.")
        out = export_rom_fmu(args.config, args.output, fmi_version=args.fmi_version)
        print(
            f"FMU of the thermal ROM {args.config} written to {out} (native C99, FMI {args.fmi_version}.0 "
            "co-simulation; inputs cell<c>_heat_w, segment<s>_fluid_temp_k, ambient_temp_k)"
        )
        return 0
    cfg = load_cell_config(args.config)
    m = cfg.module
    params = cfg.cell.parameters
    if (Path(cfg.base_dir) / params).is_file():
        params = str(Path(cfg.base_dir) / params)
    extra = {} if args.pythonfmu else {"fmi_version": args.fmi_version}
    out = (export_fmu if args.pythonfmu else export_native_fmu)(
        params,
        args.output,
        soc_initial=cfg.cell.soc_initial,
        temp_initial_k=cfg.cell.temp_k,
        n_series=m.n_series,
        n_parallel=m.n_parallel,
        capacity_spread=m.capacity_spread,
        resistance_spread=m.resistance_spread,
        seed=m.seed,
        **extra,
    )
    what = "cell" if m.n_series * m.n_parallel == 1 else f"{m.n_series}s{m.n_parallel}p module"
    kind = "pythonfmu, FMI 2.0" if args.pythonfmu else f"native C99, FMI {args.fmi_version}.0"
    print(f"FMU of the {what} written to {out} ({kind} co-simulation; inputs current_a, port_temp_k)")
    return 0


def _cmd_age(args: argparse.Namespace) -> int:
    from hevsim.battery.ageing import SOH_DEFINITION, age_cell
    from hevsim.battery.config import load_config as load_cell_config
    from hevsim.battery.config import profile_current
    from hevsim.figures import figure, grid, save
    from hevsim.io import atomic_directory
    from hevsim.schema import check_value

    check_value(args.repetitions, int, "", "", {}, {}, {"bounds": (1, 10**7)}, where="--repetitions")
    check_value(args.rest_h, float, "", "", {}, {}, {"bounds": (0.0, 1e6), "unit": "h"}, where="--rest-h")
    out = Path(args.out) if args.out else Path("results") / f"{Path(args.config).stem}_ageing"
    _prepare(args, out, args.config)
    cfg = load_cell_config(args.config)
    params = cfg.cell.parameters
    if (Path(cfg.base_dir) / params).is_file():
        params = str(Path(cfg.base_dir) / params)
    table = age_cell(
        params,
        profile_current(cfg),
        cfg.profile.dt_s,
        args.repetitions,
        port_temperature=cfg.thermal.port_temp_k,
        soc_initial=cfg.cell.soc_initial,
        rest_s=args.rest_h * 3600.0,
    )
    with atomic_directory(out) as tmp:
        table.to_csv(tmp / "ageing.csv", index=False, float_format="%.6g")
        (tmp / "soh_definition.txt").write_text(SOH_DEFINITION + "\n", encoding="utf-8")
        fig, (ax1, ax2) = figure(2, 1, figsize=(9.0, 6.0), sharex=True)
        ax1.plot(table["time_days"], 100 * table["capacity_fraction"], label="capacity")
        ax1.plot(table["time_days"], 100 * table["resistance_fraction"], label="resistance")
        ax1.set_ylabel("% of new")
        ax1.legend()
        ax2.plot(table["time_days"], table["soh"], color="k", label="SOH (eq 42), capacity at T_ref")
        ax2.set_ylabel("SOH [-] (1 new, 0 end of life)")
        ax2.set_xlabel("time [days]")
        for ax in (ax1, ax2):
            grid(ax)
        ax1.set_title(f"Ageing of {cfg.cell.parameters}: {args.repetitions} repetitions of the profile")
        save(fig, tmp / "ageing.png")
    last = table.iloc[-1]
    print(
        f"after {last['time_days']:.0f} days, {last['throughput_ah']:.0f} A·h: capacity "
        f"{100 * last['capacity_fraction']:.1f} %, resistance {100 * last['resistance_fraction']:.1f} %, "
        f"SOH {last['soh']:.3f}"
    )
    print(SOH_DEFINITION)
    print(f"results written to {out}/ (ageing.csv, ageing.png, soh_definition.txt)")
    return 0


def _cmd_cosim(args: argparse.Namespace) -> int:
    from hevsim.cosim.datacheck import datacheck
    from hevsim.cosim.system import run_cosim

    if args.check:
        datacheck(args.config)
        print(f"{args.config}: ok (well-formed, structure, references, connection pairing, units)")
        return 0
    out = Path(args.out) if args.out else Path("results") / Path(args.config).stem
    _prepare(args, out, args.config)
    bar: Any = None
    progress: Callable[[float, float], None] | None = None
    if sys.stderr.isatty():  # (tqdm and its locks are imported only for a terminal)
        from tqdm import tqdm

        bar = tqdm(total=1.0, unit="run", bar_format="{l_bar}{bar}| {elapsed}")

        def progress(t_s: float, stop_s: float) -> None:
            bar.n = min(t_s / stop_s, 1.0) if stop_s > 0 else 1.0
            bar.refresh()

    try:
        res = run_cosim(args.config, out, progress=progress, resume=args.resume, log_level=args.log_level,
                        fmu_log=args.fmu_log)  # fmt: skip
    finally:
        if bar is not None:
            bar.close()
    print(format_cosim_summary(res, out))
    return 0


def format_cosim_summary(res: Any, out: Path) -> str:
    """A few lines for the terminal: steps, wall time, stop reason, the temperatures and
    powers at the end (recognised by their names) and the hot spots of field participants."""
    import json

    from hevsim.units import KELVIN_OFFSET

    st = res.stats
    lines = [st[k] for k in ("resume", "step_from") if st.get(k)]  # where --resume went on from; the step
    lines += [
        f"{st['steps']} communication steps to t = {res.time_s[-1]:g} s in {st.get('wall_s', 0.0):.1f} s"
        + (f"; stopped: {res.stopped_by}" if res.stopped_by else "")
    ]
    shown = ("cell_max_temp_k", "plate_max_temp_k", "outlet_temp_k", "cooling_power_w", "voltage_v")
    for i, col in enumerate(res.columns):
        if col.split(".", 1)[1] in shown:
            v = float(res.data[-1, i])
            if col.endswith("_k"):  # shown in °C: drop the kelvin suffix from the name
                label, text = col[: -len("_k")], f"{v - KELVIN_OFFSET:.3f} °C"
            else:
                label, text = col, f"{v:.4g} {col[-1].upper()}"
            lines.append(f"  {label:28s} {text}")
    fields = json.loads((out / "summary.json").read_text()).get("fields", {})
    for name, f in fields.items():
        for h in f.get("hot_spots", [])[:3]:
            xyz = ", ".join(f"{h[k] * 1e3:.1f}" for k in ("x_m", "y_m", "z_m"))
            lines.append(f"  hot spot {h['rank']} ({name}, {h['part']}) at ({xyz}) mm: {h['temp_c']:.3f} °C")
    lines.append(f"results written to {out}/ (results.csv, summary.json, system.ssd, pictures/, fields)")
    return "\n".join(lines)


def _cmd_thermal(args: argparse.Namespace) -> int:
    from hevsim.errors import ConfigError
    from hevsim.thermal.run import format_summary, run_thermal

    out = Path(args.out) if args.out else Path("results") / Path(args.config).stem
    if Path(args.config).suffix.lower() == ".inp":  # an Abaqus / CalculiX deck
        from hevsim.thermal.deck import check_deck_options, format_deck, run_deck

        if args.boundary:
            raise ConfigError(
                f"{args.config}: --boundary applies to a module configuration (TOML); a deck's "
                "conditions are its own *Film / *Sfilm keywords."
            )
        check_deck_options(args.length_scale, args.bonded_w_m2k)
        _prepare(args, out, args.config)
        print(format_deck(run_deck(args.config, out, length_scale_m=args.length_scale,
                                   bonded_w_m2k=args.bonded_w_m2k)))  # fmt: skip
        return 0
    if args.length_scale != 1.0 or args.bonded_w_m2k is not None:
        raise ConfigError(
            f"{args.config}: --length-scale and --bonded-w-m2k apply to an Abaqus/CalculiX deck (.inp)."
        )
    _prepare(args, out, args.config)
    config: Any = args.config
    if args.boundary:  # fixed conditions given on the command line, after the file's [[boundary]]
        from hevsim.schema import read_toml
        from hevsim.thermal.run import boundary_from_option, thermal_config_from_dict

        data = read_toml(args.config)
        data["boundary"] = [*data.get("boundary", []), *(boundary_from_option(b) for b in args.boundary)]
        config = thermal_config_from_dict(data, str(args.config), Path(args.config).parent)
    print(format_summary(run_thermal(config, out, progress=True)))
    return 0


def _cmd_flow(args: argparse.Namespace) -> int:
    from hevsim.schema import read_toml
    from hevsim.thermal.flow import flow_config_from_dict, format_flow, run_flow

    out = Path(args.out) if args.out else Path("results") / (Path(args.config).stem + "_flow")
    _prepare(args, out, args.config)
    data = read_toml(args.config)
    if args.flow_l_min is not None:  # the operating point from the command line
        data["flow"] = {**data.get("flow", {}), "flow_l_min": args.flow_l_min}
    if args.model is not None:  # laminar / rans / auto from the command line
        data["flow"] = {**data.get("flow", {}), "model": args.model}
    cfg = flow_config_from_dict(data, str(args.config), Path(args.config).parent)
    res = run_flow(cfg, out, args.thermal, progress=True)
    print(format_flow(res))
    if res.cht is not None:
        from hevsim.thermal.cht import format_cht
        from hevsim.thermal.pictures import add_coolant_pictures

        print(format_cht(res.cht))
        add_coolant_pictures(res.cht, out)  # coolant temperature pictures (thesis figs 4.30-4.31)
    print(f"results written to {out}/ ({_written(out)})")
    return 0


def _cmd_pack(args: argparse.Namespace) -> int:
    from hevsim.battery.pack import format_pack, run_pack

    out = Path(args.out) if args.out else Path("results") / Path(args.config).stem
    _prepare(args, out, args.config)
    res = run_pack(
        args.config, out, cycle=args.cycle, duration_s=args.duration, current_scale=args.current_scale
    )
    print(format_pack(res))
    print(f"results written to {out}/ ({_written(out)})")
    return 0


def _cmd_rom_build(args: argparse.Namespace) -> int:
    from hevsim.thermal.rom import BuildOptions, build_rom_from_config, format_rom, load_rom

    def ours(path: Path) -> bool:  # only a ROM file is replaced without --force
        try:
            load_rom(path)
        except HevsimError:
            return False
        return True

    if args.output is None:  # results/<config stem>.rom.npz: never a file inside the checkout's examples
        args.output = str(Path("results") / f"{Path(args.config).stem}.rom.npz")
    _prepare(args, args.output, args.config, kind="file", option="-o", ours=ours)
    opts = BuildOptions(**({"tol_k": args.tol_k} if args.tol_k is not None else {}))
    rom, _ = build_rom_from_config(args.config, opts)
    rom.save(args.output)
    print(format_rom(rom))
    print(f"ROM written to {args.output}")
    return 0


def _cmd_rom_info(args: argparse.Namespace) -> int:
    from hevsim.thermal.rom import format_rom, load_rom

    print(format_rom(load_rom(args.rom)))
    return 0


def _cmd_study(args: argparse.Namespace) -> int:
    from hevsim.studies.runner import run_study
    from hevsim.studies.spec import load_study

    study = load_study(args.study)
    out = Path(args.out) if args.out else Path("results") / study.name
    args.prepared_out = out  # (run_study checks the folder itself) named by the Ctrl-C line (main)
    rows = run_study(study, out, scheduler=args.scheduler, workers=args.workers, resume=args.resume,
                     force=args.force)  # fmt: skip
    ok = int((rows["status"] == "ok").sum())
    print(f"study {study.name}: {len(rows)} of {study.n_cases} cases, {ok} ok, {len(rows) - ok} failed")
    if not args.no_report:
        _print_report(out)
    print(f"results written to {out}/ (results/*.parquet, cases.parquet, study.json)")
    return 0


def _cmd_study_report(args: argparse.Namespace) -> int:
    _print_report(Path(args.folder), plots=not args.no_plots)
    return 0


def _print_report(out: Path, plots: bool = True) -> None:
    from hevsim.studies.report import study_report

    rep = study_report(out, plots=plots)
    for name, front in rep["fronts"].items():
        print(f"Pareto front {name}: {len(front)} case(s)")
    sens = rep["sensitivity"]
    top = sens[sens["rank"] == 1]
    for row in top.itertuples(index=False):
        print(f"most influential on {row.metric} ({row.cycle}, {row.solver}): {row.parameter} ({row.method})")
    print(f"report: {out / 'report.md'} ({', '.join(rep['files'])})")


def _add_dp_options(p: argparse.ArgumentParser, final_soc: str) -> None:
    p.add_argument("--soc-initial", type=float, help="initial SOC [-] (default from the configuration)")
    p.add_argument(
        "--final-soc",
        default=final_soc,
        choices=("config", "sustain", "window", "deplete"),
        help="final SOC: as configured, charge sustaining (initial within the configured "
        "tolerance), the configured window or a plug-in hybrid's depletion target (plugin.cs_soc "
        f"within the tolerance) (default {final_soc})",
    )
    p.add_argument("--soc-points", type=int, help="SOC grid points (default per architecture)")
    p.add_argument("--input-points", type=int, help="control grid points (default per architecture)")
    p.add_argument(
        "--final-constraint",
        default="auto",
        choices=("auto", "boundary_line", "levelset", "wall", "penalty"),
        help="final-SOC constraint method (default: the accurate one)",
    )
    p.add_argument(
        "--threads",
        help="threads of the DP kernels: a number or 'auto' (default: HEVSIM_THREADS, else the "
        "cores not busy with other processes, from the 1-minute load average)",
    )


def _add_force(p: argparse.ArgumentParser, what: str) -> None:
    p.add_argument(
        "--force",
        action="store_true",
        help=f"replace an existing {what} that hevsim did not write (never the working "
        "directory or a folder holding an input)",
    )


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("hevsim")
    except PackageNotFoundError:  # pragma: no cover - running from a source tree
        from hevsim import __version__

        return __version__


class _VersionAction(argparse.Action):
    """``--version``: the version looked up only when asked (importlib.metadata costs ~10 ms
    of every command's start)."""

    def __init__(self, option_strings: Sequence[str], dest: str = argparse.SUPPRESS, **kw: Any):
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS,
                         help="show program's version number and exit", **kw)  # fmt: skip

    def __call__(self, parser: argparse.ArgumentParser, *args: Any) -> None:
        print(f"hevsim {_version()}")
        parser.exit()


def _cmd_compile(args: argparse.Namespace) -> int:
    from hevsim.warmup import GROUPS, compile_groups, format_groups

    if args.list:
        print(format_groups(GROUPS))
        return 0
    done = compile_groups(args.group or None, jobs=args.jobs, examples=args.examples)
    failed = [r.name for r in done if r.error]
    if failed:
        print(f"hevsim compile: {len(failed)} group(s) failed: {', '.join(failed)}", file=sys.stderr)
        return 1
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``hevsim`` command."""
    parser = argparse.ArgumentParser(prog="hevsim", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action=_VersionAction)
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("cycles", help="list the shipped drive cycles")
    p.set_defaults(func=_cmd_cycles)

    p = sub.add_parser("simulate", help="forward-simulate a vehicle over a drive cycle")
    p.add_argument("config", help="vehicle configuration (TOML)")
    p.add_argument("--cycle", help="cycle name (see `hevsim cycles`) or CSV file")
    p.add_argument("--out", help="results folder (default results/<config>_<cycle>)")
    _add_force(p, "folder at --out")
    p.add_argument("--dt", type=float, help="time step [s] (default from the configuration)")
    p.add_argument("--soc-initial", type=float, help="initial SOC [-]")
    p.add_argument("--no-plots", action="store_true", help="skip plots and report")
    p.add_argument(
        "--csv",
        action="store_true",
        help="also write timeseries.csv for long runs (default: CSV up to 50000 rows, Parquet always)",
    )
    p.add_argument(
        "--schedule",
        help="replay a genset schedule CSV (time_s, engine_speed_rpm|engine_speed_radps, "
        "engine_throttle), e.g. the timeseries.csv of `hevsim optimize` on a series HEV",
    )
    p.add_argument(
        "--replay",
        action="store_true",
        help="with --schedule: apply each step's engine speed and torque exactly as the DP's "
        "quasi-static model took them (no cranking or speed-loop dynamics; reproduces the DP's fuel)",
    )
    p.add_argument(
        "--controller",
        help="supervisory controller, overriding [controller] kind (series: thermostat, schedule, ecms, "
        "aecms; parallel: electric_assist, ecms, aecms; power split: power_follower, ecms, aecms; "
        "conventional: shift_schedule; BEV: direct; FCEV: load_follower, ecms, aecms)",
    )
    p.add_argument(
        "--ecms-from",
        metavar="DP_RESULT",
        help="ECMS tuned from a DP result: its folder (costate.csv of `hevsim optimize`) sets the "
        "equivalence factor (median of -costate*LHV/(Q*OCV)); the controller becomes ecms unless "
        "--controller says aecms",
    )
    p.add_argument(
        "--age-state",
        metavar="FILE",
        help="[battery] model = 'pack': the cells' ageing state, read (new cells when FILE does not exist), "
        "advanced by the run's stress and written back atomically",
    )
    p.add_argument(
        "--ambient-c",
        type=float,
        help="[battery] model = 'pack': ambient temperature [degC] (default the pack file's); 'cell': the "
        "cells' heat-port temperature (default [battery] temperature_c)",
    )
    p.add_argument(
        "--soak",
        action="store_true",
        help="with --ambient-c: the cells and the coolant start at the ambient (a car parked long)",
    )
    p.add_argument(
        "--cooling-off",
        action="store_true",
        help="[battery] model = 'pack': pump, radiator fan and chiller off",
    )
    p.set_defaults(func=_cmd_simulate)

    p = sub.add_parser(
        "life", help="drive a cycle again and again with the pack ageing: SOH, temperature, fuel economy"
    )
    p.add_argument("config", help="vehicle configuration with [battery] model = 'pack'")
    p.add_argument("--cycle", help="cycle name or CSV (default from the configuration)")
    p.add_argument("--until-soh", type=float, default=0.8, help="stop at this weakest-cell SOH (default 0.8)")
    p.add_argument("--soh-step", type=float, default=0.01, help="SOH lost per simulated block (default 0.01)")
    p.add_argument("--max-blocks", type=int, default=200, help="most simulated runs (default 200)")
    p.add_argument("--ambient-c", type=float, help="ambient temperature [degC] (default the pack file's)")
    p.add_argument("--age-state", metavar="FILE", help="start from this age state and write the final one")
    p.add_argument("--resume", action="store_true", help="continue from <out>.checkpoint.json")
    p.add_argument("--no-plots", action="store_true", help="skip life.png")
    p.add_argument("--out", help="results folder (default results/<config>_<cycle>_life)")
    _add_force(p, "folder at --out")
    p.set_defaults(func=_cmd_life)

    p = sub.add_parser(
        "performance",
        help="0-60 mph, 0-100 km/h, 50-80 mph, quarter mile, top speed, gradeability (binding limits)",
    )
    p.add_argument("config", help="vehicle configuration (TOML), any architecture")
    p.add_argument("--out", help="results folder (default results/<config>_performance)")
    _add_force(p, "folder at --out")
    p.add_argument("--dt", type=float, help="time step of the acceleration runs [s] (default 0.2)")
    p.add_argument("--soc", type=float, help="battery SOC [-] (default the configuration's initial SOC)")
    p.add_argument("--grade-speed-mph", type=float, default=30.0, help="speed of the gradeability test [mph]")
    p.add_argument("--no-plots", action="store_true", help="skip the speed/power plot")
    p.set_defaults(func=_cmd_performance)

    p = sub.add_parser("label", help="EPA label: UDDS + HWFET, adjusted city/highway/combined mpg or MPGe")
    p.add_argument("config", help="vehicle configuration (TOML), any architecture")
    p.add_argument("-o", "--out", help="results folder (default results/<config>_label)")
    _add_force(p, "folder at --out")
    p.add_argument(
        "--model-year", type=int, help="picks the derived 5-cycle coefficients (default: the newest set)"
    )
    p.add_argument(
        "--charger-efficiency",
        type=float,
        default=1.0,
        help="electric vehicles: energy counted from the wall = battery energy / this (default 1)",
    )
    p.set_defaults(func=_cmd_label)

    p = sub.add_parser(
        "lap", help="quasi-steady-state lap time, speed, g-g and energy per lap on a track (issue 29)"
    )
    p.add_argument(
        "config", help="vehicle configuration (TOML), any architecture with a performance envelope"
    )
    p.add_argument("track", help="shipped track (skidpad, oval, handling, monza) or track CSV")
    p.add_argument("--step", type=float, default=1.0, help="distance step [m] (default 1)")
    p.add_argument("--soc", type=float, help="battery SOC held for the lap [-] (default the initial SOC)")
    p.add_argument("--out", help="results folder (default results/<config>_<track>_lap)")
    p.add_argument(
        "--optimize",
        choices=("convex", "dp"),
        help="optimal deployment: minimum lap time under --budget-kj (writes deploy_map.csv, deploy.png)",
    )
    p.add_argument(
        "--budget-kj", type=float, default=0.0, help="net battery energy per lap [kJ] (0: charge-sustaining)"
    )
    p.add_argument("--fuel-budget-kg", type=float, help="fuel per lap [kg] (default: none)")
    p.add_argument("--window-kj", type=float, help="half-width of the cumulative battery-energy window [kJ]")
    p.add_argument(
        "--deploy-step", type=float, default=10.0, help="distance step of --optimize [m] (default 10)"
    )
    p.add_argument("--deploy", help="replay a deployment map CSV (distance_m, battery_power_w) in the lap")
    _add_force(p, "folder at --out")
    p.add_argument("--no-plots", action="store_true", help="skip the plots")
    p.set_defaults(func=_cmd_lap)

    p = sub.add_parser(
        "stint", help="N laps with the whole pack: lap time as the pack heats and derates (issue 29)"
    )
    p.add_argument("config", help="vehicle configuration (TOML) with [battery] model = 'pack'")
    p.add_argument("track", help="shipped track (skidpad, oval, handling, monza) or track CSV")
    p.add_argument("--laps", type=int, required=True, help="number of laps (>= 1)")
    p.add_argument("--step", type=float, default=1.0, help="distance step of the lap [m] (default 1)")
    p.add_argument("--dt", type=float, default=1.0, help="time step of the pack [s] (default 1)")
    p.add_argument("--soc", type=float, help="initial pack SOC [-] (default the file's initial SOC)")
    p.add_argument("--ambient", type=float, help="ambient temperature [degC] (default the pack file's)")
    p.add_argument("--soak", action="store_true", help="start the cells and coolant at --ambient")
    p.add_argument("--cooling-off", action="store_true", help="pump, fan and chiller off")
    p.add_argument(
        "--pack-set",
        action="append",
        default=[],
        metavar="SECTION.KEY=VALUE",
        help="set a key of the pack file for this stint, e.g. another cooling design: "
        "--pack-set cooling.chiller=0 --pack-set cooling.flow_l_min=15 (repeatable)",
    )
    p.add_argument(
        "--optimize",
        choices=("convex", "dp"),
        help="drive each lap's optimal deployment, re-solved with the BMS limits at the lap's start",
    )
    p.add_argument(
        "--budget-kj",
        type=float,
        default=0.0,
        help="--optimize: net battery energy per lap [kJ] (0: charge-sustaining)",
    )
    p.add_argument(
        "--reoptimize-rtol",
        type=float,
        default=0.02,
        help="--optimize: re-solve when a BMS power limit changed by more than this fraction "
        "(default 0.02; 0: before every lap; inf: once)",
    )
    p.add_argument("--window-kj", type=float, help="--optimize: half-width of the battery-energy window [kJ]")
    p.add_argument(
        "--deploy-step",
        type=float,
        default=10.0,
        help="--optimize: distance step of the problem [m] (default 10)",
    )
    p.add_argument("--out", help="results folder (default results/<config>_<track>_stint)")
    _add_force(p, "folder at --out")
    p.add_argument("--no-plots", action="store_true", help="skip the plots")
    p.set_defaults(func=_cmd_stint)

    p = sub.add_parser(
        "refinement", help="run the tutorial's sequential-refinement levels and tabulate MPGGE"
    )
    p.add_argument("--cycle", default="fu505", help="cycle name or CSV (default fu505, the thesis's cycle)")
    p.add_argument(
        "--calibration",
        choices=("public", "thesis"),
        default="public",
        help="level configurations: shipped public data (default) or the thesis's stated and inferred values",
    )
    p.add_argument("--energy", action="store_true", help="also print the energy audit of every level")
    p.add_argument("--out", help="also write the table (Markdown) to this file")
    _add_force(p, "file at --out")
    p.set_defaults(func=_cmd_refinement)

    p = sub.add_parser(
        "import-vehicle", help="import a FASTSim vehicle (fastsim-2 YAML/CSV, vehicle database CSV)"
    )
    p.add_argument("file", help="FASTSim vehicle file: fastsim-2 .yaml / .csv or the vehicle database CSV")
    which = p.add_mutually_exclusive_group()
    which.add_argument("--row", type=int, help="database row (its 'selection' number)")
    which.add_argument("--name", help="database vehicle by its scenario name")
    which.add_argument("--list", action="store_true", help="list the file's vehicles and exit")
    p.add_argument(
        "-o", "--out", help="hevsim vehicle TOML to write (maps beside it: <stem>_engine/, <stem>_motor/)"
    )
    _add_force(p, "file at -o")
    p.set_defaults(func=_cmd_import_vehicle)

    p = sub.add_parser("optimize", help="globally optimal energy management (dynamic programming)")
    p.add_argument("config", help="vehicle configuration (TOML): series or parallel HEV")
    p.add_argument("--cycle", help="cycle name or CSV (default from the configuration)")
    p.add_argument("--out", help="results folder (default results/<config>_<cycle>_optimal)")
    _add_force(p, "folder at --out")
    p.add_argument("--no-plots", action="store_true", help="skip plots (and the cost-to-go store)")
    _add_dp_options(p, "config")
    p.set_defaults(func=_cmd_optimize)

    p = sub.add_parser("compare", help="DP benchmark of several configurations over several cycles")
    p.add_argument("configs", nargs="+", help="vehicle configurations (TOML)")
    p.add_argument("--cycles", default="udds,hwfet,us06", help="comma-separated cycle names")
    p.add_argument("--out", help="folder for comparison.csv / .md (default results/comparison)")
    _add_force(p, "folder at --out")
    p.add_argument("--save-runs", action="store_true", help="also save each run's results folder")
    _add_dp_options(p, "sustain")
    p.set_defaults(func=_cmd_compare)

    p = sub.add_parser("cell", help="electro-thermal cell or module run (examples/cell.toml)")
    p.add_argument("config", help="cell/module configuration (TOML)")
    p.add_argument("--out", help="results folder (default results/<config>)")
    _add_force(p, "folder at --out")
    p.set_defaults(func=_cmd_cell)

    p = sub.add_parser("calibrate", help="fit cell parameters to a test file")
    p.add_argument("params", help="cell parameter set: shipped name or TOML file")
    p.add_argument("test", help="test CSV: time_s, current_a (discharge > 0), voltage_v, temp_k")
    p.add_argument(
        "--fit",
        nargs="+",
        metavar="NAME=INIT,LO,HI",
        help="fit only these parameters (initial value and bounds; see hevsim.battery.calibrate.FITTABLE); "
        "without --fit: the full calibration (OCV from rests, R_s from steps, RC, charge transfer, "
        "thermal) writing a complete parameter set cell.toml",
    )
    p.add_argument("--soc-initial", type=float, default=1.0, help="SOC at the start of the test")
    p.add_argument("--capacity-ah", type=float, help="full calibration: capacity [A h] (default: params)")
    p.add_argument("--n-rc", type=int, default=2, choices=(1, 2, 3), help="full calibration: RC pairs")
    p.add_argument(
        "--no-charge-transfer", action="store_true", help="full calibration: no Butler-Volmer term"
    )
    p.add_argument("--validate", metavar="FILE", help="full calibration: validation test CSV (drive cycle)")
    p.add_argument(
        "--data",
        action="append",
        metavar="FILE",
        help="full calibration: a pulse test at another ambient (repeatable; temp_k column required, "
        "first row at rest at the ambient): the temperature laws fitted jointly over the ambients "
        "(Arrhenius R_s, RC, charge transfer; entropic coefficient; capacity factor; thermal)",
    )
    p.add_argument(
        "--robust-mv",
        type=float,
        metavar="MV",
        help="with --data: robust (soft-L1) joint fit, voltage errors beyond MV [mV] weigh less "
        "(e.g. 2 for an LFP cell whose low-SOC knee the model cannot follow; default: least squares)",
    )
    p.add_argument(
        "--hysteresis",
        action="store_true",
        help="with --data: fit the one-state hysteresis too (amplitude, rate, activation energy of the "
        "amplitude); the tests need charge and discharge",
    )
    p.add_argument(
        "--validate-soc", type=float, help="SOC at the start of --validate (default: from its first voltage)"
    )
    p.add_argument("--ambient-c", type=float, help="heat-port temperature [degC] (default: first sample)")
    p.add_argument("--out", help="results folder")
    _add_force(p, "folder at --out")
    p.set_defaults(func=_cmd_calibrate)

    p = sub.add_parser("age", help="age a cell over repetitions of its configured load profile")
    p.add_argument("config", help="cell configuration (TOML), e.g. examples/cell.toml")
    p.add_argument("--repetitions", type=int, default=1000, help="profile repetitions (default 1000)")
    p.add_argument("--rest-h", type=float, default=0.0, help="calendar rest after each repetition [h]")
    p.add_argument("--out", help="results folder")
    _add_force(p, "folder at --out")
    p.set_defaults(func=_cmd_age)

    p = sub.add_parser(
        "export-fmu",
        help="FMI co-simulation FMU of a cell or module configuration, or of a module thermal ROM",
        description="Native FMUs (the default) are compiled C99: building one needs a C compiler (cc, gcc "
        "or clang; or set CC), running one needs nothing (no Python). --pythonfmu FMUs need no compiler but "
        "a host process with CPython and hevsim installed.",
    )
    p.add_argument(
        "config", help="cell configuration (TOML, e.g. examples/cell.toml) or thermal ROM (.rom.npz)"
    )
    p.add_argument("-o", "--output", required=True, help="FMU file to write")
    kind = p.add_mutually_exclusive_group()
    kind.add_argument(
        "--native",
        action="store_true",
        help="compiled C99 FMU that needs no Python (the default; built with the system C compiler)",
    )
    kind.add_argument(
        "--pythonfmu",
        action="store_true",
        help="pythonfmu FMU (FMI 2.0; no compiler needed, but the host must run CPython with hevsim)",
    )
    p.add_argument(
        "--fmi-version", type=int, choices=(2, 3), default=2, help="FMI version (3: native only; default 2)"
    )
    _add_force(p, "file at -o")
    p.set_defaults(func=_cmd_export_fmu)

    p = sub.add_parser("cosim", help="co-simulation of FMUs and hevsim models (SSP, SIMULIA CSE XML)")
    p.add_argument("config", help="system description: .ssp, .ssd or a CSE .xml (with --check)")
    p.add_argument("--out", help="results folder (default results/<config>)")
    _add_force(p, "folder at --out")
    p.add_argument("--resume", action="store_true", help="resume from the last checkpoint of --out")
    p.add_argument("--check", action="store_true", help="only run the datacheck of section 4.1.4")
    p.add_argument("--log-level", default="error",
                   choices=["all", "warning", "discard", "error", "fatal", "none"],
                   help="FMU log messages shown on stderr from this status up (default: error)")  # fmt: skip
    p.add_argument("--fmu-log", metavar="FILE", help="append every FMU log message to FILE")
    p.set_defaults(func=_cmd_cosim)

    p = sub.add_parser("thermal", help="3D FEM heat model of a battery module with cooling plate and coolant")
    p.add_argument(
        "config",
        help="module thermal configuration (TOML), e.g. examples/module_thermal.toml, or an "
        "Abaqus/CalculiX heat-transfer deck (.inp), run as written (docs/thermal.md)",
    )
    p.add_argument("--length-scale", type=float, default=1.0,
                   help="deck only: metres per deck length unit (1e-3 for mm; default 1)")  # fmt: skip
    p.add_argument("--bonded-w-m2k", type=float, default=None,
                   help="deck only: contact conductance where sections share nodes [W/(m^2 K)]")  # fmt: skip
    p.add_argument("--out", help="results folder (default results/<config>)")
    p.add_argument(
        "--boundary",
        action="append",
        metavar="SURFACE:KIND:KEY=VALUE,...",
        help="fixed condition on INTERFACE or EXTERNAL, as a [[boundary]] table: film (film_w_m2k, "
        "temp_c), temperature (temp_c) or heat_flux (heat_flux_w_m2); repeatable",
    )
    _add_force(p, "folder at --out")
    p.set_defaults(func=_cmd_thermal)

    p = sub.add_parser(
        "flow", help="coolant flow in the plate's channel: laminar (Navier-Stokes, FEM) or RANS (OpenFOAM)"
    )
    p.add_argument("config", help="module configuration (TOML) with an optional [flow] section")
    p.add_argument("--flow-l-min", type=float, help="inlet flow rate [L/min] (replaces flow.flow_l_min)")
    p.add_argument("--model", choices=("auto", "laminar", "rans"),
                   help="flow model (replaces flow.model; auto: RANS above Re 2300)")  # fmt: skip
    p.add_argument("--thermal", action="store_true",
                   help="also the coolant's heat transfer on the frozen flow (docs/flow.md)")  # fmt: skip
    p.add_argument("--out", help="results folder (default results/<config>_flow)")
    _add_force(p, "folder at --out")
    p.set_defaults(func=_cmd_flow)

    p = sub.add_parser("pack", help="battery pack: cells, module thermal ROMs and cooling loop over a cycle")
    p.add_argument("config", help="pack configuration (TOML), e.g. examples/pack.toml")
    p.add_argument("--cycle", default="udds", help="drive cycle of the road-load current (default udds)")
    p.add_argument(
        "--duration", type=float, default=1369.0, help="duration [s] (the cycle repeats; default 1369)"
    )
    p.add_argument(
        "--current-scale", type=float, default=1.0, help="factor on the cycle's current (default 1)"
    )
    p.add_argument("--out", help="results folder (default results/<config>)")
    _add_force(p, "folder at --out")
    p.set_defaults(func=_cmd_pack)

    p = sub.add_parser("rom", help="thermal reduced-order model of a module, projected from its 3D FEM")
    rom_sub = p.add_subparsers(dest="rom_command", required=True)
    p = rom_sub.add_parser("build", help="build a module's thermal ROM from its FEM (module_thermal TOML)")
    p.add_argument("config", help="module thermal configuration (TOML), e.g. examples/module_thermal.toml")
    p.add_argument(
        "-o", "--out", dest="output",
        help="ROM file to write (.npz; default results/<config stem>.rom.npz)",
    )  # fmt: skip
    p.add_argument("--tol-k", type=float, help="tolerance of the output error estimate [K] (default 0.05)")
    _add_force(p, "file at -o")
    p.set_defaults(func=_cmd_rom_build)
    p = rom_sub.add_parser("info", help="order, error estimate and provenance of a ROM file")
    p.add_argument("rom", help="ROM file (.npz) written by `hevsim rom build`")
    p.set_defaults(func=_cmd_rom_info)

    p = sub.add_parser(
        "compile",
        help="compile hevsim's numba kernels ahead of use (once per install or update), in parallel",
    )
    p.add_argument("--group", action="append", help="only this kernel group (repeatable; --list names them)")
    p.add_argument("--jobs", type=int, help="processes compiling at once (default: the cores)")
    p.add_argument("--examples", help="folder of the example vehicles the warm-up runs drive (default: the "
                   "repository's examples/)")  # fmt: skip
    p.add_argument("--list", action="store_true", help="list the kernel groups, their state and compile time")
    p.set_defaults(func=_cmd_compile)

    p = sub.add_parser("study", help="design-space study: sample parameters, run every case on Dask")
    p.add_argument("study", help="study file (TOML), e.g. examples/study_series_sizing.toml")
    p.add_argument("--out", help="results folder (default results/<study name>)")
    _add_force(p, "folder at --out")
    p.add_argument(
        "--scheduler",
        help="Dask scheduler tcp://HOST:PORT (default: $HEVSIM_DASK_SCHEDULER, else a local cluster); "
        "'in-process' runs without Dask",
    )
    p.add_argument("--workers", type=int, help="local-cluster worker processes (default: the cores)")
    p.add_argument("--resume", action="store_true", help="continue the study in --out (skip finished cases)")
    p.add_argument("--no-report", action="store_true", help="skip the analysis (`hevsim study-report` later)")
    p.set_defaults(func=_cmd_study)

    p = sub.add_parser("study-report", help="Pareto fronts, sensitivity ranking and plots of a study folder")
    p.add_argument("folder", help="the --out folder of `hevsim study`")
    p.add_argument("--no-plots", action="store_true", help="skip the scatter matrices")
    p.set_defaults(func=_cmd_study_report)
    return parser


RESUMABLE = {
    "life": "the finished blocks are in {out}.checkpoint.json",
    "cosim": "the run so far is in the checkpoint .{name}.checkpoint next to {out}",
    "study": "the finished cases are in {out}/results/",
}
"""Commands that keep their finished work on Ctrl-C, and where (continued with ``--resume``)."""


def interrupted_message(args: argparse.Namespace) -> str:
    """The one line a command ends with on Ctrl-C: what was kept and how to go on."""
    name = " ".join(str(getattr(args, k)) for k in ("command", "rom_command") if getattr(args, k, None))
    out: Path | None = getattr(args, "prepared_out", None)
    if out is None:
        return f"hevsim: {name} interrupted (Ctrl-C); nothing was written."
    if args.command in RESUMABLE:
        kept = RESUMABLE[args.command].format(out=out, name=out.name)
        return f"hevsim: {name} interrupted (Ctrl-C); {kept}: continue with the same command and --resume."
    return (f"hevsim: {name} interrupted (Ctrl-C); nothing was written to {out} (results are written "
            "only when a run completes; what was there is unchanged); run the command again.")  # fmt: skip


def _sigint(signum: int, frame: Any) -> None:
    """SIGINT (and its retry): KeyboardInterrupt, except inside a C library's callback into
    Python (llvmlite's object cache while numba compiles), where the exception would be
    "ignored" by ctypes and the Ctrl-C lost: retried 50 ms later (SIGALRM)."""
    import os
    import signal

    if frame is not None and f"{os.sep}llvmlite{os.sep}" in frame.f_code.co_filename:
        signal.signal(signal.SIGALRM, _sigint)
        signal.setitimer(signal.ITIMER_REAL, 0.05)
        return
    raise KeyboardInterrupt


def _catch_sigint() -> Callable[[], None]:
    """Install :func:`_sigint` where Python would raise KeyboardInterrupt (not when SIGINT is
    ignored, nor outside the main thread); returns the undo."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        return lambda: None
    if signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        return lambda: None
    alarm = signal.getsignal(signal.SIGALRM)
    signal.signal(signal.SIGINT, _sigint)

    def undo() -> None:
        signal.setitimer(signal.ITIMER_REAL, 0.0)
        signal.signal(signal.SIGINT, signal.default_int_handler)
        signal.signal(signal.SIGALRM, alarm)

    return undo


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the exit status (0 ok, 2 bad input or physical domain left, 3 the
    vehicle could not follow the cycle, 130 interrupted by Ctrl-C: one line, no traceback)."""
    from hevsim.io import output_session

    args = build_parser().parse_args(argv)
    undo = _catch_sigint()
    try:
        with output_session():
            return int(args.func(args))
    except HevsimError as exc:
        print(f"hevsim: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print(interrupted_message(args), file=sys.stderr)
        return 130
    except Exception as exc:
        if not _interrupted(exc):
            raise
        print(interrupted_message(args), file=sys.stderr)  # Ctrl-C inside a C callback (numba's cache)
        return 130
    finally:
        undo()


def _interrupted(exc: BaseException) -> bool:
    """Whether ``exc`` was caused by a Ctrl-C: a KeyboardInterrupt raised inside a C library's
    callback into Python comes back wrapped (numba's cache loader: ``SystemError: <function
    _numba_unpickle> returned a result with an exception set``); its cause chain holds it."""
    seen: set[int] = set()
    cur: BaseException | None = exc
    while cur is not None and id(cur) not in seen:
        if isinstance(cur, KeyboardInterrupt):
            return True
        seen.add(id(cur))
        cur = cur.__cause__ or cur.__context__
    return False


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
