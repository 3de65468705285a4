"""Globally optimal energy management of hybrid vehicles over a known drive cycle (DP).

:func:`optimize` builds the architecture's energy-management problem on the shared
component models (state SOC, cost fuel mass, every component limit of eqs 29-31 as an
infeasibility mask, a charge-sustaining or windowed final SOC) and solves it with the
generic solver :func:`hevsim.optimal.solve_dp`. Architectures are looked up by name in
:data:`ARCHITECTURES`:

* ``"parallel"``: the thesis appendix's parallel HEV with a multi-speed gearbox
  (:mod:`hevsim.parallel`; inputs gear and engine throttle);
* ``"series"``: the chapter-2 series HEV (:class:`hevsim.config.SeriesHEVConfig`; input the
  genset electrical power, engine on its fuel-optimal operating line);
* ``"power_split"``: the THS-style power split (:mod:`hevsim.architectures.power_split`;
  inputs engine speed and throttle; SOC grid 201, charge-sustaining by default).
* ``"fcev"``: the fuel-cell vehicle (:mod:`hevsim.architectures.fcev`; input the fuel cell's
  net power, 0 = off; cost hydrogen; its ramp limits not modelled).

The result (:class:`OptimizationResult`) holds the optimal time series with operating
points, powers and the costate (the slope of the cost-to-go with respect to SOC and the
equivalent ECMS equivalence factor), fuel-economy metrics like the forward simulator's,
and metadata. See ``docs/dp.md``.
"""

from __future__ import annotations

import math
import platform
import time
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

import hevsim
from hevsim.components.engine import Engine
from hevsim.config import SOC_INITIAL_FROM_SIMULATION, is_plugin, load_vehicle_config
from hevsim.cycles import DriveCycle, load_cycle
from hevsim.errors import ConfigError, DPInfeasibleError, DPSetupError
from hevsim.figures import plotter
from hevsim.io import atomic_directory, write_json
from hevsim.optimal._feedback import dp_feedback
from hevsim.optimal._hev_common import DETAIL_COLUMNS, HEVFormulation, hev_metrics
from hevsim.optimal._problem import FinalTarget
from hevsim.optimal.dp import FINAL_CONSTRAINTS, DPResult, solve_dp

FINAL_SOC_MODES: tuple[str, ...] = ("sustain", "window", "deplete")
"""``final_soc`` choices: within ``soc_tolerance`` of the initial SOC, a window, or (a plug-in
hybrid's depletion target) within ``soc_tolerance`` of its ``plugin.cs_soc``."""
PENALTY_EQUIVALENCE_FACTOR = 100.0
"""Equivalence factor [-] of the default final-SOC penalty weight (``final_constraint=
"penalty"``): far above the optimum's 2-4, so the penalty is exact (the target is met)."""


@dataclass(frozen=True)
class Settings:
    """Resolved optimisation settings (defaults from the configuration, overridden by the call)."""

    cycle: str
    soc_min: float
    soc_max: float
    soc_points: int
    input_points: int
    soc_initial: float
    final_soc: str
    final_window: tuple[float, float]
    soc_tolerance: float
    final_constraint: str
    deplete_soc: float = math.nan
    """A plug-in hybrid's charge-sustaining threshold ``plugin.cs_soc`` [-] (the ``"deplete"``
    target); NaN for a charge-sustaining hybrid."""


def _section_settings(hev: Any, default_input_points: int) -> Settings:
    """Settings from the configuration's ``[optimization]`` section (every architecture): an
    empty cycle or the sustaining default initial SOC take the ``[simulation]`` values, the
    final window is clipped to the battery's SOC window, ``input_grid_points`` = 0 takes the
    formulation's ``default_input_points``."""
    c = hev.config
    b = c.battery
    o = c.optimization
    inherit = o.soc_initial == SOC_INITIAL_FROM_SIMULATION
    return Settings(
        cycle=o.cycle or c.simulation.cycle,
        soc_min=b.soc_min,
        soc_max=b.soc_max,
        soc_points=o.soc_grid_points,
        input_points=o.input_grid_points or default_input_points,
        soc_initial=c.simulation.soc_initial if inherit else o.soc_initial,
        final_soc=o.final_soc,
        final_window=(max(o.final_soc_min, b.soc_min), min(o.final_soc_max, b.soc_max)),
        soc_tolerance=o.soc_tolerance,
        final_constraint=o.final_constraint,
        deplete_soc=float(c.plugin.cs_soc) if is_plugin(c) else math.nan,
    )


@dataclass(frozen=True)
class Architecture:
    """An architecture of the registry :data:`hevsim.architectures.ARCHITECTURES` that has a DP
    formulation, as :func:`optimize` uses it: the registry ``entry`` (configuration type,
    builder) and the :class:`~hevsim.optimal._hev_common.HEVFormulation` it names, which
    declares its default input grid and how it is built from :class:`Settings`."""

    entry: Any

    @property
    def name(self) -> str:
        """The architecture's name (``[powertrain] architecture``)."""
        return str(self.entry.name)

    @property
    def formulation(self) -> type[HEVFormulation]:
        """Its DP formulation class."""
        cls: type[HEVFormulation] = self.entry.formulation()
        return cls

    def build(self, cfg: Any) -> Any:
        """The vehicle model of a configuration."""
        return self.entry.build(cfg)

    def settings(self, hev: Any) -> Settings:
        """The settings of ``hev``'s ``[optimization]`` section."""
        return _section_settings(hev, self.formulation.default_input_points(hev))

    def formulate(
        self, hev: Any, cycle: DriveCycle, s: Settings, grid: np.ndarray, target: FinalTarget
    ) -> HEVFormulation:
        """The formulation of ``hev`` on ``cycle`` (SOC grid ``grid`` [-], final ``target``)."""
        return self.formulation.from_settings(hev, cycle, s, grid, target)


class _DPArchitectures(Mapping[str, Architecture]):
    """The entries of :data:`hevsim.architectures.ARCHITECTURES` with a DP formulation, read
    from that registry on every access (an architecture registered later is found too)."""

    def _table(self) -> dict[str, Architecture]:
        from hevsim.architectures import ARCHITECTURES as REGISTRY

        return {name: Architecture(a) for name, a in REGISTRY.items() if a.dp_formulation}

    def __getitem__(self, name: str) -> Architecture:
        return self._table()[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._table())

    def __len__(self) -> int:
        return len(self._table())


ARCHITECTURES: Mapping[str, Architecture] = _DPArchitectures()
"""Architectures with a DP formulation, by the name used in configuration files
(``[powertrain] architecture = ...``): a view of :data:`hevsim.architectures.ARCHITECTURES`
(one registry: each entry declares its ``dp_formulation``)."""


def _parallel_settings(hev: Any) -> Settings:
    """The parallel HEV's settings (used by ``benchmarks/bench_dp.py``)."""
    return ARCHITECTURES["parallel"].settings(hev)


def resolve_model(config_or_model: Any) -> tuple[Architecture, Any]:
    """The architecture and built vehicle model for a config file path, config or model."""
    obj = config_or_model
    source = str(obj) if isinstance(obj, str | Path) else None
    if source is not None:
        obj = load_vehicle_config(Path(obj))
    cfg = getattr(obj, "config", obj)  # a built model holds its configuration
    name = getattr(cfg, "architecture", None) if hasattr(cfg, "powertrain") else None
    if not isinstance(name, str):
        raise ConfigError(
            f"optimize: cannot tell the architecture of {type(config_or_model).__name__}; expected a "
            "configuration file path, a vehicle configuration (hevsim.config) or a built vehicle model."
        )
    arch = ARCHITECTURES.get(name)
    if arch is None:
        raise ConfigError(
            f"{source or cfg.name}: key 'powertrain.architecture' = {name!r} has no DP formulation; "
            f"expected one of {', '.join(ARCHITECTURES)}."
        )
    return arch, (obj if cfg is not obj else arch.build(cfg))


def _final_target(s: Settings, soc_initial: float) -> tuple[FinalTarget, tuple[float, float]]:
    if s.final_soc == "sustain":
        lo = max(s.soc_min, soc_initial - s.soc_tolerance)
        hi = min(s.soc_max, soc_initial + s.soc_tolerance)
    elif s.final_soc == "deplete":
        if math.isnan(s.deplete_soc):
            raise DPSetupError(
                "final_soc 'deplete' needs a plug-in hybrid ([plugin] mode 'ev_first' or 'blended'); "
                "expected 'sustain', 'window' or a (low, high) window."
            )
        lo = max(s.soc_min, s.deplete_soc - s.soc_tolerance)
        hi = min(s.soc_max, s.deplete_soc + s.soc_tolerance)
    else:
        lo, hi = s.final_window
    if not (s.soc_min <= lo <= hi <= s.soc_max):
        raise DPSetupError(
            f"final SOC window [{lo:g}, {hi:g}] lies outside the SOC grid [{s.soc_min:g}, {s.soc_max:g}]."
        )
    return FinalTarget(lower=lo, upper=hi), (lo, hi)


@dataclass
class OptimizationResult:
    """Optimal energy management of one vehicle on one cycle.

    Attributes:
        timeseries: one row per cycle sample (N+1): ``time_s``, ``speed_mps``, ``soc`` and,
            for the step that starts there (zeros on the last row), the operating points
            (gear for the parallel HEV, engine speed/torque/throttle/power, fuel rate,
            motor torque and electrical power, battery current and power), the powers
            required at the wheels, from the engine and the battery and dissipated by the
            friction brakes, the cumulative ``fuel_kg``, ``costate_kg_per_soc`` (d cost-to-go
            / d SOC) and ``equivalence_factor`` (``-costate * LHV / (Q * OCV)``) [-].
        metrics: name -> {"value", "unit", "description"} (as the forward simulator's).
        metadata: architecture, configuration, cycle, grids, constraint, timings, versions.
        architecture: ``"parallel"`` or ``"series"``. model: the vehicle model. cycle: the cycle.
        soc_grid: SOC grid of the DP [-]. cost_to_go: (N+1, n_soc) [kg] if requested.
        dp: the solver's :class:`~hevsim.optimal.DPResult`.
        soc_window: (min, max) SOC allowed along the way [-]; soc_target: (low, high) final
            SOC target [-].
    """

    timeseries: pd.DataFrame
    metrics: dict[str, dict[str, Any]]
    metadata: dict[str, Any]
    architecture: str
    model: Any
    cycle: DriveCycle
    soc_grid: np.ndarray
    dp: DPResult
    soc_window: tuple[float, float] = (0.0, 1.0)
    soc_target: tuple[float, float] = (0.0, 1.0)
    cost_to_go: np.ndarray | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    def value(self, name: str) -> float:
        """Value of metric ``name`` (in its unit)."""
        return float(self.metrics[name]["value"])

    @property
    def engine(self) -> Engine | None:
        """The vehicle's engine (for operating-point plots on its fuel map)."""
        return getattr(self.model, "engine", None)

    @property
    def cost_to_go_time_s(self) -> np.ndarray:
        """Times of the rows of :attr:`cost_to_go` [s] (the cycle's samples)."""
        return self.timeseries["time_s"].to_numpy()

    def genset_schedule(self, quasi_static: bool = True) -> Any:
        """The optimal genset commands as a :class:`hevsim.sim.simulator.GensetSchedule`
        (engine speed, throttle and torque per step, speed 0 = off), to replay the optimum in
        the forward simulator. Series HEV only.

        ``quasi_static`` True: the forward simulator applies the DP's decisions exactly (the
        engine at the optimal point from its first step, no cranking or speed dynamics, which
        the DP does not model); False: the generator cranks the engine and its speed loop
        follows the schedule, with the genset's inertia.
        """
        if self.architecture != "series":
            raise DPSetupError(
                f"genset_schedule: the {self.architecture} HEV has no genset; a schedule needs a "
                "series-HEV result."
            )
        from hevsim.sim.simulator import GensetSchedule

        ts = self.timeseries
        return GensetSchedule(
            ts["time_s"].to_numpy(),
            ts["engine_speed_radps"].to_numpy(),
            ts["engine_throttle"].to_numpy(),
            source=f"DP optimum of {self.metadata.get('config', '')} on {self.cycle.name}",
            engine_torque_nm=ts["engine_torque_nm"].to_numpy(),
            quasi_static=quasi_static,
        )

    @property
    def costate(self) -> pd.DataFrame:
        """Costate along the optimal path: time_s, soc, costate_kg_per_soc, equivalence_factor."""
        return self.timeseries[["time_s", "soc", "costate_kg_per_soc", "equivalence_factor"]].copy()

    def save(self, out_dir: str | Path, plots: bool = False) -> Path:
        """Write the results folder atomically: timeseries.parquet / .csv, metrics.json,
        costate.csv, metadata.json, config.json and, when kept, cost_to_go.npz (time x SOC);
        with ``plots`` also the figures of :func:`hevsim.report.dp_plots.plot_optimum` (the
        ``"optimum"`` plotter of :mod:`hevsim.figures`, which :mod:`hevsim.report` registers).

        Files are written to a temporary sibling folder that is renamed into place, so an
        interrupted run leaves no partial folder. An existing folder is replaced.
        """
        with atomic_directory(out_dir) as tmp:
            self.timeseries.to_parquet(tmp / "timeseries.parquet", index=False)
            self.timeseries.to_csv(tmp / "timeseries.csv", index=False, float_format="%.9g")
            self.costate.to_csv(tmp / "costate.csv", index=False, float_format="%.9g")
            write_json(tmp / "metrics.json", self.metrics)
            write_json(tmp / "metadata.json", self.metadata)
            write_json(tmp / "config.json", self.model.config.to_dict())
            if self.cost_to_go is not None:
                np.savez_compressed(
                    tmp / "cost_to_go.npz",
                    cost_to_go_kg=self.cost_to_go,
                    soc=self.soc_grid,
                    time_s=self.timeseries["time_s"].to_numpy(),
                )
            if plots:  # the report layer's plotter (hevsim.report.dp_plots.plot_optimum)
                plotter("optimum")(self, tmp)
        return Path(out_dir)


def optimize(
    config_or_model: Any,
    cycle: DriveCycle | str | Path | None = None,
    *,
    soc_grid_points: int | None = None,
    input_grid_points: int | None = None,
    final_constraint: str = "auto",
    progress: bool | None = None,
    store_cost_to_go: bool = False,
    soc_initial: float | None = None,
    final_soc: str | tuple[float, float] | None = None,
    soc_tolerance: float | None = None,
    forward: str = "reoptimize",
    penalty_weight: float | None = None,
    threads: object = None,
) -> OptimizationResult:
    """Fuel-optimal energy management of a hybrid vehicle over a drive cycle, by DP.

    Args:
        config_or_model: a configuration file path (``[powertrain] architecture = "parallel"`` for the
            parallel HEV; series-HEV files have no such key), a configuration object
            (:class:`~hevsim.config.ParallelHEVConfig`, :class:`~hevsim.config.SeriesHEVConfig`)
            or a built model (:class:`~hevsim.parallel.ParallelHEV`,
            :class:`~hevsim.sim.model.SeriesHEV`). The architecture is looked up in
            :data:`ARCHITECTURES`.
        cycle: a :class:`DriveCycle`, a registered name or a CSV path; None = the
            configuration's cycle. The DP steps are the cycle's sample intervals.
        soc_grid_points: SOC grid size over the battery's SOC window (default: the
            configuration's, 400 for the appendix HEV; 201 for the series HEV).
        input_grid_points: throttle grid size (parallel, default 400) or genset-power grid
            size (series, default 101).
        final_constraint: the solver's final-state method (``"auto"``: the configuration's
            choice, else the boundary line), see :func:`hevsim.optimal.solve_dp`.
        progress: progress bar on stderr (None: only on a terminal for large problems).
        store_cost_to_go: keep the cost-to-go (time x SOC) in the result for a heat map.
        soc_initial: initial SOC [-] (default: the configuration's).
        final_soc: ``"sustain"`` (final SOC within ``soc_tolerance`` of the initial),
            ``"window"`` (the configuration's final window; the appendix's 0.7-0.8) or a
            ``(low, high)`` window [-]. Default: the configuration's (parallel) or
            ``"sustain"`` (series).
        soc_tolerance: charge-sustaining tolerance on the final SOC [-] (default 0.005).
        forward: the solver's forward pass, ``"reoptimize"`` or ``"policy"``.
        penalty_weight: cost of a unit of final SOC outside the target [kg per unit SOC],
            for ``final_constraint="penalty"`` only; default the fuel worth of the battery
            energy at an equivalence factor of :data:`PENALTY_EQUIVALENCE_FACTOR`.
        threads: threads of the DP kernels, a number or ``"auto"``; None = ``HEVSIM_THREADS``
            or the cores free of other processes (:mod:`hevsim.threads`). The memory check
            and the thread choice happen before the stage table is built.

    Returns:
        An :class:`OptimizationResult`.

    Raises:
        ConfigError: unreadable configuration or unknown architecture.
        DPSetupError: bad grids, options or a final window outside the SOC window.
        DPInfeasibleError: the vehicle cannot follow the cycle at some step (the message
            names the step, its time and the component limits), or the final SOC target
            cannot be reached.
    """
    t_start = time.perf_counter()
    arch, hev = resolve_model(config_or_model)
    s = arch.settings(hev)
    changes: dict[str, Any] = {}
    if soc_grid_points is not None:
        changes["soc_points"] = soc_grid_points
    if input_grid_points is not None:
        changes["input_points"] = input_grid_points
    if soc_initial is not None:
        changes["soc_initial"] = float(soc_initial)
    if soc_tolerance is not None:
        changes["soc_tolerance"] = float(soc_tolerance)
    if final_constraint != "auto":
        changes["final_constraint"] = final_constraint
    if isinstance(final_soc, tuple | list):
        if len(final_soc) != 2:
            raise DPSetupError(f"final_soc {final_soc!r}: expected 'sustain', 'window' or (low, high).")
        changes["final_soc"] = "window"
        changes["final_window"] = (float(final_soc[0]), float(final_soc[1]))
    elif final_soc is not None:
        if final_soc not in FINAL_SOC_MODES:
            raise DPSetupError(
                f"final_soc {final_soc!r} is not known; expected one of {', '.join(FINAL_SOC_MODES)} "
                "or a (low, high) window."
            )
        changes["final_soc"] = final_soc
    s = Settings(**{**s.__dict__, **changes})
    if s.final_constraint not in FINAL_CONSTRAINTS:
        raise DPSetupError(
            f"final_constraint {s.final_constraint!r} is not known; expected one of "
            f"{', '.join(FINAL_CONSTRAINTS)}."
        )
    for label, n, low in (("soc_grid_points", s.soc_points, 2), ("input_grid_points", s.input_points, 2)):
        if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < low:
            raise DPSetupError(f"{label} = {n!r}; expected an integer >= {low}.")
    if not s.soc_min <= s.soc_initial <= s.soc_max:
        raise DPSetupError(
            f"soc_initial = {s.soc_initial!r} lies outside the SOC window [{s.soc_min:g}, {s.soc_max:g}]."
        )
    cyc = cycle if isinstance(cycle, DriveCycle) else load_cycle(cycle if cycle is not None else s.cycle)
    grid = np.linspace(s.soc_min, s.soc_max, int(s.soc_points))
    target, window = _final_target(s, s.soc_initial)
    form = arch.formulate(hev, cyc, s, grid, target)
    feedback = dp_feedback(form, hev, cyc, s.final_constraint, forward, store_cost_to_go, threads, progress)
    t_setup = time.perf_counter()
    if form.soc_invariant:
        with feedback.timed("building the DP stage table"):
            form.build_table()
    form.check_followable()
    problem = form.dp_problem()
    t_table = time.perf_counter()
    weight = None
    if s.final_constraint == "penalty":
        e_soc = float(form.energy_per_soc_j(s.soc_initial))
        weight = penalty_weight or PENALTY_EQUIVALENCE_FACTOR * e_soc / form.engine.fuel_lhv_jpkg
    try:
        res = solve_dp(
            problem,
            [s.soc_initial],
            final_constraint=s.final_constraint,
            penalty_weight=weight,
            forward=forward,
            store_cost_to_go=store_cost_to_go,
            progress=progress,
        )
    except DPInfeasibleError as exc:
        raise form.contextualise(exc) from exc
    t_dp = time.perf_counter()
    result = _assemble(form, res, s, window, store_cost_to_go)
    t_end = time.perf_counter()
    timings = {
        "setup_s": t_setup - t_start,
        "stage_table_s": t_table - t_setup,
        "dp_backward_s": res.timings_s.get("backward", float("nan")),
        "dp_forward_s": res.timings_s.get("forward", float("nan")),
        "dp_total_s": t_dp - t_table,
        "results_s": t_end - t_dp,
        "total_s": t_end - t_start,
    }
    result.metadata["timings_s"] = timings
    result.metadata["threads"] = {"count": feedback.threads.threads, "reason": feedback.threads.reason}
    result.metrics["compute_time_s"]["value"] = timings["total_s"]
    return result


def _assemble(
    form: HEVFormulation, res: DPResult, s: Settings, window: tuple[float, float], keep_ctg: bool
) -> OptimizationResult:
    steps = form.steps
    N = steps.n_steps
    soc = res.states[:, 0]
    st = form.details(soc, res.inputs)
    det = st.details

    def pad(a: Any) -> np.ndarray:
        arr = np.broadcast_to(np.asarray(a, dtype=np.float64), (N,))
        return np.concatenate([arr, [0.0]])

    dt = steps.dt_s
    fuel_step = np.asarray(st.cost_kg, dtype=np.float64)
    cols: dict[str, np.ndarray] = {
        "time_s": steps.time_s,
        "speed_mps": steps.speed_mps,
        "dt_s": pad(dt),
        "accel_mps2": pad(steps.accel_mps2),
        "soc": soc,
    }
    if "gear" in det:
        cols["gear"] = pad(det["gear"]).astype(np.int64)
    for name in DETAIL_COLUMNS:
        cols[name] = pad(det[name])
    for name in sorted(set(det) - set(DETAIL_COLUMNS) - {"gear"}):
        cols[name] = pad(det[name])
    cols["engine_on"] = cols["engine_on"].astype(np.bool_)
    cols["power_required_w"] = pad(steps.power_required_w)
    cols["power_engine_w"] = cols["engine_power_w"].copy()
    cols["power_battery_w"] = cols["battery_power_w"].copy()
    cols["fuel_kg"] = np.concatenate([[0.0], np.cumsum(fuel_step)])
    lam = res.costate[:, 0]
    cols["costate_kg_per_soc"] = lam
    cols["equivalence_factor"] = -lam * form.engine.fuel_lhv_jpkg / form.energy_per_soc_j(soc)
    ts = pd.DataFrame(cols)
    fuel = float(np.sum(fuel_step))
    on_time = float(np.sum(dt * np.broadcast_to(det["engine_on"], (N,))))
    metrics = hev_metrics(
        fuel_kg=fuel,
        distance_m=steps.distance_m,
        duration_s=float(steps.time_s[-1] - steps.time_s[0]),
        soc_initial=float(soc[0]),
        soc_final=float(soc[-1]),
        battery=form.battery,
        engine=form.engine,
        conversion_efficiency=form.conversion_efficiency,
        engine_on_time_s=on_time,
        compute_time_s=float("nan"),
        dp_total_cost=res.total_cost,
    )
    lam_ok = lam[np.isfinite(lam)]
    s_ok = ts["equivalence_factor"].to_numpy()[np.isfinite(lam)]
    metrics["equivalence_factor_median"] = {
        "value": float(np.median(s_ok)) if s_ok.size else float("nan"),
        "unit": "-",
        "description": "median ECMS equivalence factor -costate*LHV/(Q*OCV) along the optimal path",
    }
    cyc = steps.cycle
    metadata: dict[str, Any] = {
        "architecture": form.architecture,
        "config": form.name,
        "cycle": cyc.name,
        "cycle_source": cyc.source,
        "n_steps": N,
        "soc_grid": {
            "min": float(form.soc_grid[0]),
            "max": float(form.soc_grid[-1]),
            "points": form.soc_grid.size,
        },
        "inputs": {
            name: {"points": int(g.size), "min": float(g.min()), "max": float(g.max()), "unit": unit}
            for name, g, unit in zip(form.input_names, form.input_grids, form.input_units, strict=True)
        },
        "soc_initial": float(s.soc_initial),
        "final_soc": s.final_soc,
        "final_soc_window": list(window),
        "final_constraint": res.final_constraint,
        "forward": res.forward,
        "n_fallback_steps": res.n_fallback_steps,
        "battery_soc_invariant": form.soc_invariant,
        "battery": form.battery.name,
        "engine": form.engine.name,
        "costate_finite_points": int(lam_ok.size),
        "memory_bytes": dict(res.memory_bytes),
        "hevsim_version": hevsim.__version__,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "created_unix_s": time.time(),
    }
    return OptimizationResult(
        timeseries=ts,
        metrics=metrics,
        metadata=metadata,
        architecture=form.architecture,
        model=form.model,
        cycle=cyc,
        soc_grid=form.soc_grid,
        dp=res,
        soc_window=(float(form.soc_grid[0]), float(form.soc_grid[-1])),
        soc_target=window,
        cost_to_go=res.cost_to_go if keep_ctg else None,
    )
