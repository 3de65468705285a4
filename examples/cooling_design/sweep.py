"""Cooling-design sweep of the battery pack (issue 12 item 5): coolant flow rate x chiller
set-point on a demanding profile, giving the peak cell temperature, the cell-to-cell spread
and the pump + chiller (+ radiator fan) electrical energy of every design, and the Pareto
front of the three.

    .venv/bin/python examples/cooling_design/sweep.py [STUDY.toml] [--out DIR] [--rom FILE]

The study file (``cooling_design.toml`` next to this script by default) names the pack
(``examples/pack.toml``: 8 modules of the thesis 2s6p module, thermal ROM, cooling loop), the
profile (the hot-lap cycle's road-load current by default), the grid and fixed overrides.
Each point is one :meth:`hevsim.battery.pack.Pack.simulate` run (the pack's public API; the
cooling loop is :class:`hevsim.battery.cooling.CoolingLoop`). The design variables are
``cooling.flow_l_min`` and ``cooling.chiller_min_supply_c`` (the chiller cools the coolant down
to that supply temperature whenever the controller runs it).

Objectives (all minimised): ``peak_cell_temp_c`` (hottest cell core over the run),
``max_spread_k`` (largest difference between the hottest and the coldest cell at one time) and
``cooling_energy_wh`` (pump + chiller + fan electrical energy). The non-dominated designs over
the study's ``pareto_objectives`` (default all three) are found with
:func:`hevsim.studies.analysis.pareto_mask`.

The module ROM is the one ``[module] rom_file`` of the pack names (``hevsim rom build
examples/module_thermal.toml -o examples/module.rom.npz``); if it is missing, it is built once
and cached at ``--rom`` (default ``results/cooling_design_module.rom.npz``).

Writes ``sweep.csv``, ``pareto.csv``, ``summary.md`` and ``pareto.png`` to ``--out``
(atomically). Runs in about 1 minute on 2 cores with the ROM built (36 designs x ~1.4 s).
"""

from __future__ import annotations

import argparse
import itertools
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

HERE = Path(__file__).resolve().parent
DEFAULT_STUDY = HERE / "cooling_design.toml"
DEFAULT_ROM_CACHE = Path("results") / "cooling_design_module.rom.npz"
STUDY_KEYS = {
    "name", "pack", "cycle", "duration_s", "current_scale", "flows_l_min", "setpoints_c", "overrides",
    "pareto_objectives",
}  # fmt: skip
OPTIONAL_KEYS = {"overrides", "pareto_objectives"}
OBJECTIVES = ("peak_cell_temp_c", "max_spread_k", "cooling_energy_wh")
J_PER_WH = 3600.0


@dataclass(frozen=True)
class Study:
    """A parsed study file (see ``cooling_design.toml``)."""

    name: str
    pack: Path
    cycle: str
    duration_s: float
    current_scale: float
    flows_l_min: tuple[float, ...]
    setpoints_c: tuple[float, ...]
    overrides: dict[str, Any] = field(default_factory=dict)
    pareto_objectives: tuple[str, ...] = OBJECTIVES


def load_study(path: str | Path) -> Study:
    """Read a study file; an unknown or missing key raises ConfigError naming it."""
    from hevsim.errors import ConfigError

    p = Path(path)
    data = tomllib.loads(p.read_text(encoding="utf-8"))
    unknown = set(data) - STUDY_KEYS
    missing = STUDY_KEYS - OPTIONAL_KEYS - set(data)
    if unknown or missing:
        raise ConfigError(
            f"{p}: unknown keys {sorted(unknown)} / missing keys {sorted(missing)}; "
            f"expected {sorted(STUDY_KEYS)}."
        )
    for key in ("flows_l_min", "setpoints_c"):
        if not data[key] or any(not isinstance(x, int | float) for x in data[key]):
            raise ConfigError(f"{p}: key '{key}' = {data[key]!r}; expected a non-empty list of numbers.")
    objectives = tuple(data.get("pareto_objectives", OBJECTIVES))
    if not objectives or not set(objectives) <= set(OBJECTIVES):
        raise ConfigError(
            f"{p}: key 'pareto_objectives' = {list(objectives)}; expected a non-empty subset of "
            f"{list(OBJECTIVES)}."
        )
    study = Study(
        name=str(data["name"]), pack=(p.parent / data["pack"]).resolve(), cycle=str(data["cycle"]),
        duration_s=float(data["duration_s"]), current_scale=float(data["current_scale"]),
        flows_l_min=tuple(float(x) for x in data["flows_l_min"]),
        setpoints_c=tuple(float(x) for x in data["setpoints_c"]),
        overrides=dict(data.get("overrides", {})), pareto_objectives=objectives,
    )  # fmt: skip
    pack_config(study, study.flows_l_min[0], study.setpoints_c[0])  # the pack and its overrides: checked now
    return study


def pack_config(study: Study, flow_l_min: float, setpoint_c: float, rom_file: Path | None = None) -> Any:
    """The pack configuration of one design (validated like a file)."""
    from hevsim.battery.pack import pack_config_from_dict
    from hevsim.schema import read_toml, with_changes

    changes = dict(study.overrides)
    changes.update({"cooling.flow_l_min": flow_l_min, "cooling.chiller_min_supply_c": setpoint_c})
    if rom_file is not None:
        changes["module.rom_file"] = str(rom_file)
    data = with_changes(read_toml(study.pack), changes)
    where = f"{study.pack} (flow {flow_l_min:g} L/min, set-point {setpoint_c:g} degC)"
    return pack_config_from_dict(data, where, study.pack.parent)


def module_rom(study: Study, cache: Path) -> tuple[Any, Path | None]:
    """(ROM object or None, ROM file to use): the pack's own file if present, else ``cache``
    (built once from the pack's module thermal configuration)."""
    from hevsim.battery.pack import load_pack_config
    from hevsim.thermal.rom import build_rom_from_config

    cfg = load_pack_config(study.pack)
    if cfg.module.thermal != "rom" or (study.pack.parent / cfg.module.rom_file).is_file():
        return None, None
    if not cache.is_file():
        print(f"building the module ROM once ({cfg.module.thermal_config}) -> {cache}")
        rom, _ = build_rom_from_config(study.pack.parent / cfg.module.thermal_config)
        cache.parent.mkdir(parents=True, exist_ok=True)
        rom.save(cache)
    return None, cache.resolve()


def run_design(
    study: Study, flow_l_min: float, setpoint_c: float, rom_file: Path | None = None
) -> dict[str, float]:
    """Objectives and energy terms of one design."""
    from hevsim.battery.pack import Pack, pack_current_from_cycle

    cfg = pack_config(study, flow_l_min, setpoint_c, rom_file)
    current = pack_current_from_cycle(cfg, study.cycle, study.duration_s, study.current_scale)
    res = Pack(cfg).simulate(current)
    temps_k = res.cells[:, :, 2]  # (steps, cells) cell temperature [K]
    e = res.energy
    return {
        "flow_l_min": flow_l_min,
        "setpoint_c": setpoint_c,
        "peak_cell_temp_c": float(temps_k.max()) - 273.15,
        "max_spread_k": float((temps_k.max(axis=1) - temps_k.min(axis=1)).max()),
        "cooling_energy_wh": (e["pump_work_j"] + e["chiller_electric_j"] + e["fan_electric_j"]) / J_PER_WH,
        "pump_energy_wh": e["pump_work_j"] / J_PER_WH,
        "chiller_energy_wh": e["chiller_electric_j"] / J_PER_WH,
        "fan_energy_wh": e["fan_electric_j"] / J_PER_WH,
        "derated_time_s": float(res.metrics["derated_time_s"]),
        "energy_balance_relative": float(res.metrics["energy_balance_relative"]),
    }


def pareto(table: pd.DataFrame, objectives: tuple[str, ...] = OBJECTIVES) -> pd.Series:
    """Non-dominated designs of ``table`` over ``objectives`` (columns, all minimised)."""
    from hevsim.studies.analysis import pareto_mask

    return pd.Series(pareto_mask(table[list(objectives)].to_numpy()), index=table.index, name="pareto")


def run_study(study: Study, rom_file: Path | None = None) -> pd.DataFrame:
    """Every design of the grid (flows x set-points), with its ``pareto`` flag."""
    rows = [
        run_design(study, q, t, rom_file) for q, t in itertools.product(study.flows_l_min, study.setpoints_c)
    ]
    table = pd.DataFrame(rows)
    table["pareto"] = pareto(table, study.pareto_objectives)
    return table


def plot_pareto(table: pd.DataFrame, path: Path, objectives: tuple[str, ...] = OBJECTIVES) -> Path:
    """Peak cell temperature against cooling energy, coloured by the spread; the front marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 5))
    x, y = table["cooling_energy_wh"], table["peak_cell_temp_c"]
    sc = ax.scatter(x, y, c=table["max_spread_k"], cmap="viridis", s=30 + 4 * table["flow_l_min"],
                    label="designs (size: flow)")  # fmt: skip
    front = table[table["pareto"]].sort_values("cooling_energy_wh")
    ax.plot(
        front["cooling_energy_wh"],
        front["peak_cell_temp_c"],
        "r.-",
        lw=1,
        label=f"Pareto set ({', '.join(objectives)})",
    )
    for row in front.drop_duplicates("setpoint_c").itertuples():  # the cheapest front design per set-point
        xy = (row.cooling_energy_wh, row.peak_cell_temp_c)
        ax.annotate(f"{row.flow_l_min:g} L/min, {row.setpoint_c:g} C", xy, fontsize=6, xytext=(3, 3),
                    textcoords="offset points")  # fmt: skip
    fig.colorbar(sc, ax=ax, label="max cell-to-cell spread [K]")
    ax.set_xlabel("pump + chiller + fan energy [Wh]")
    ax.set_ylabel("peak cell temperature [degC]")
    ax.grid(True)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def save(table: pd.DataFrame, study: Study, out: Path) -> Path:
    """sweep.csv, pareto.csv, summary.md and pareto.png, atomically."""
    from hevsim.io import atomic_directory

    front = table[table["pareto"]].sort_values("cooling_energy_wh")
    cols = ["flow_l_min", "setpoint_c", *OBJECTIVES, "pump_energy_wh", "chiller_energy_wh"]
    lines = [f"# {study.name}: {study.cycle}, {study.duration_s:g} s, pack {study.pack.name}", "",
             "| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]  # fmt: skip
    lines += ["| " + " | ".join(f"{getattr(r, c):.4g}" for c in cols) + " |" for r in front.itertuples()]
    with atomic_directory(out, force=False) as tmp:
        table.to_csv(tmp / "sweep.csv", index=False, float_format="%.6g")
        front.to_csv(tmp / "pareto.csv", index=False, float_format="%.6g")
        (tmp / "summary.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
        plot_pareto(table, tmp / "pareto.png", study.pareto_objectives)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("study", nargs="?", default=str(DEFAULT_STUDY), help="study TOML")
    ap.add_argument("--out", default=str(Path("results") / "cooling_design"), help="results folder")
    ap.add_argument(
        "--rom", default=str(DEFAULT_ROM_CACHE), help="ROM cache if the pack's ROM file is missing"
    )
    a = ap.parse_args(argv)
    study = load_study(a.study)
    _, rom_file = module_rom(study, Path(a.rom))
    table = run_study(study, rom_file)
    save(table, study, Path(a.out))
    front = table[table["pareto"]].sort_values("cooling_energy_wh")
    print(front[["flow_l_min", "setpoint_c", *OBJECTIVES]].to_string(index=False, float_format="%.3f"))
    print(f"{len(front)} of {len(table)} designs on the Pareto front; written to {a.out}/")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
