"""Life of a vehicle's pack over many drives (``hevsim life``, issue 12 item 4): drive a cycle
again and again until the weakest cell's SOH reaches ``until_soh``; each simulated run stands
for a block of repetitions, chosen so a block lowers the SOH by about ``soh_step``; checkpoint
after every block, resume, a table and a plot of SOH, peak cell temperature and fuel economy
against distance.

The cells' ageing state and stress are the battery's (:mod:`hevsim.battery.life`); driving the
vehicle over and over is the simulator's, so this lives in :mod:`hevsim.sim` (issue 24: the
battery imports nothing from the simulator).
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd

from hevsim.battery.life import PackAgeState
from hevsim.errors import ConfigError

# -- hevsim life -------------------------------------------------------------------------------
LIFE_COLUMNS = (
    "block", "repetitions", "distance_km", "soh_min", "soh_mean", "capacity_fraction_min",
    "resistance_fraction_max", "peak_cell_temp_c", "mpgge", "fuel_economy_l_per_100km", "cooling_energy_wh",
    "derated_s",
)  # fmt: skip


@dataclass
class LifeResult:
    """The life study: one row per simulated block (:data:`LIFE_COLUMNS`) and the final state."""

    table: pd.DataFrame
    state: PackAgeState
    reached: bool
    metadata: dict[str, Any]


def _row(block: int, state: PackAgeState, res: Any, x_c: float, x_z: float) -> dict[str, float]:
    soh = state.soh(x_c, x_z)
    m = res.metrics
    dist_km = float(m["distance_m"]["value"]) / 1e3
    fuel_l = float(m["fuel_l"]["value"]) if "fuel_l" in m else math.nan
    return {
        "block": block,
        "repetitions": state.repetitions,
        "distance_km": state.distance_m / 1e3,
        "soh_min": float(soh.min()),
        "soh_mean": float(soh.mean()),
        "capacity_fraction_min": float(state.capacity_fraction().min()),
        "resistance_fraction_max": float(state.resistance_fraction().max()),
        "peak_cell_temp_c": float(m["pack_peak_cell_temp_c"]["value"]),
        "mpgge": float(m["mpgge"]["value"]) if "mpgge" in m else math.nan,
        "fuel_economy_l_per_100km": 100.0 * fuel_l / dist_km if dist_km > 0 else math.nan,
        "cooling_energy_wh": float(m["pack_cooling_energy_j"]["value"]) / 3600.0,
        "derated_s": float(m["pack_derated_s"]["value"]),
    }


def run_life(
    config: Any,
    cycle: str,
    until_soh: float,
    *,
    soh_step: float = 0.01,
    max_blocks: int = 200,
    checkpoint: str | Path | None = None,
    resume: bool = False,
    ambient_temp_c: float | None = None,
    age_state: PackAgeState | None = None,
) -> LifeResult:
    """Drive ``cycle`` again and again (module docstring) until the weakest cell's SOH <=
    ``until_soh`` or ``max_blocks`` simulated runs. Each block: simulate one run with the aged
    cells, then age every cell by ``n`` repetitions of that run's stress, ``n`` chosen from the
    previous block's SOH loss per repetition so one block costs about ``soh_step`` of SOH
    (the first block: one repetition). ``checkpoint``: a JSON file written atomically after
    every block (state + table), read back with ``resume``."""
    from hevsim.config import load_vehicle_config
    from hevsim.io import write_json
    from hevsim.progress import task
    from hevsim.sim.pack_vehicle import simulate_pack_vehicle

    if not 0.0 < until_soh < 1.0:
        raise ConfigError(f"--until-soh = {until_soh!r}; expected a value between 0 and 1.")
    if not 0.0 < soh_step < 0.5:
        raise ConfigError(f"--soh-step = {soh_step!r}; expected a value between 0 and 0.5.")
    cfg = load_vehicle_config(config) if isinstance(config, str | Path) else config
    require_pack(cfg, "hevsim life")
    rows: list[dict[str, float]] = []
    state = age_state
    if resume and checkpoint is not None and Path(checkpoint).is_file():
        data = json.loads(Path(checkpoint).read_text(encoding="utf-8"))
        state = PackAgeState.from_dict(data["state"], str(checkpoint))
        rows = list(data["table"])
    t0 = time.perf_counter()
    x_c = x_z = math.nan
    reached = False
    with task("life", max_blocks, "block") as bar:
        bar.update(len(rows))
        while len(rows) < max_blocks:
            if state is not None and rows and rows[-1]["soh_min"] <= until_soh:
                reached = True
                break
            per_rep = None
            if len(rows) >= 2:
                d_soh = rows[-2]["soh_min"] - rows[-1]["soh_min"]
                d_rep = rows[-1]["repetitions"] - rows[-2]["repetitions"]
                per_rep = d_soh / d_rep if d_rep > 0 and d_soh > 0 else None
            elif len(rows) == 1 and rows[0]["soh_min"] < 1.0:
                per_rep = (1.0 - rows[0]["soh_min"]) / rows[0]["repetitions"]
            if state is None:
                state = PackAgeState(_pack_config(cfg).n_cells)
            res_state = state
            left = rows[-1]["soh_min"] - until_soh if rows else 1.0 - until_soh
            reps = 1 if per_rep is None else max(1, int(min(soh_step, left) / per_rep))
            res_state.next_repetitions = reps
            res = simulate_pack_vehicle(cfg, cycle, ambient_temp_c=ambient_temp_c, age_state=res_state)
            x_c, x_z = _eol_fractions(cfg)
            rows.append(_row(len(rows) + 1, res_state, res, x_c, x_z))
            if checkpoint is not None:
                write_json(checkpoint, {"state": res_state.to_dict(), "table": rows})
            bar.update(1)
        else:
            reached = bool(rows and rows[-1]["soh_min"] <= until_soh)
    assert state is not None
    meta = {"config": cfg.name, "cycle": cycle, "until_soh": until_soh, "soh_step": soh_step,
            "ageing_model": state.model, "elapsed_s": time.perf_counter() - t0}  # fmt: skip
    return LifeResult(pd.DataFrame(rows, columns=list(LIFE_COLUMNS)), state, reached, meta)


@dataclass(frozen=True)
class _PackSize:
    n_cells: int
    params: Any


def require_pack(cfg: Any, what: str) -> None:
    """ConfigError unless the vehicle ``cfg`` has ``[battery] model = "pack"`` (the cells whose
    age ``what`` follows), naming the vehicle, the key and its value."""
    battery = getattr(cfg, "battery", None)
    if battery is not None and battery.model == "pack":
        return
    got = (
        "it has no [battery] section (no traction battery to age)"
        if battery is None
        else f"key 'battery.model' = {battery.model!r}"
    )
    raise ConfigError(f"{cfg.name}: {what} ages the cells of a [battery] model = 'pack'; {got}.")


def _pack_config(cfg: Any) -> _PackSize:
    """Cell count and cell parameters of a pack vehicle's pack file."""
    from hevsim.battery.pack import load_pack_config
    from hevsim.battery.params import load_cell_parameters
    from hevsim.sim.pack_vehicle import pack_file

    path = pack_file(cfg.battery, Path(cfg.base_dir))
    pc = load_pack_config(path)
    par = pc.cells.parameters
    params = load_cell_parameters(str(path.parent / par) if (path.parent / par).is_file() else par)
    return _PackSize(pc.pack.n_modules * pc.module.n_series * pc.module.n_parallel, params)


def _eol_fractions(cfg: Any) -> tuple[float, float]:
    """The cell set's end-of-life fractions (x_C, x_Z) of eqs 43-44."""
    a = _pack_config(cfg).params.ageing
    return float(a.x_c), float(a.x_z)


def plot_life(res: LifeResult, path: str | Path) -> None:
    """SOH (weakest and mean cell), peak cell temperature and fuel economy against distance."""
    from hevsim.figures import figure, grid, save

    t = res.table
    fig, axes = figure(3, 1, figsize=(9.0, 8.0), sharex=True)
    x = t["distance_km"]
    axes[0].plot(x, t["soh_min"], "o-", label="weakest cell")
    axes[0].plot(x, t["soh_mean"], "s--", label="mean of the cells")
    axes[0].axhline(res.metadata["until_soh"], color="k", lw=0.8, ls=":")
    axes[0].set_ylabel("SOH [-]")
    axes[0].legend()
    axes[1].plot(x, t["peak_cell_temp_c"], "o-", color="tab:red")
    axes[1].set_ylabel("peak cell temp. [degC]")
    axes[2].plot(x, t["mpgge"], "o-", color="tab:green")
    axes[2].set_ylabel("fuel economy [MPGGE]")
    axes[2].set_xlabel("distance driven [km]")
    for ax in axes:
        grid(ax)
    axes[0].set_title(f"{res.metadata['config']} on {res.metadata['cycle']}: life of the pack")
    save(fig, path)


__all__ = ["LIFE_COLUMNS", "LifeResult", "plot_life", "run_life"]
