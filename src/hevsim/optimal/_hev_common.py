"""Pieces shared by the HEV energy-management formulations of :mod:`hevsim.optimal.hev`.

Everything here is quasi-static (backward-facing) and vectorised: the drive cycle fixes the
speed and acceleration of every step, the road load of eq (32) gives the wheel torque, and
each formulation maps its inputs to component operating points through the shared
component methods (:mod:`hevsim.components`). Step ``k`` runs from ``time_s[k]`` to
``time_s[k+1]``; speeds are evaluated at the mid-step speed and the acceleration is the
finite difference, so ``F v_mid dt`` closes the kinetic-energy balance exactly.
"""

from __future__ import annotations

import re
from abc import ABC, abstractmethod
from typing import Any, ClassVar, Protocol

import numpy as np

from hevsim.components.battery import BatteryPack
from hevsim.components.flow import (  # the point kernels, re-exported here for the formulations
    DETAIL_COLUMNS,
    LIMIT_RTOL,
    LIMITS,
    BatteryCache,
    BatteryState,
    BoolArray,
    CycleSteps,
    ElectricFlow,
    FloatArray,
    Stage,
    electric_flow,
    soc_invariant,
)
from hevsim.cycles import DriveCycle
from hevsim.errors import DPInfeasibleError
from hevsim.optimal._problem import DPProblem, FinalTarget
from hevsim.sim.metrics import MPGGE_DESCRIPTION, fuel_economy, metric
from hevsim.units import M3_PER_US_GALLON

__all__ = [
    "DETAIL_COLUMNS", "LIMITS", "LIMIT_RTOL", "BatteryCache", "BatteryState", "BoolArray", "CycleSteps",
    "ElectricFlow", "FloatArray", "FuelConverter", "HEVFormulation", "Stage", "electric_flow", "hev_metrics",
    "soc_invariant",
]  # fmt: skip


class FuelConverter(Protocol):
    """What the DP reads of a vehicle's fuel converter (an
    :class:`~hevsim.components.engine.Engine` or a fuel cell's
    :class:`~hevsim.components.fuel_cell.FuelCellSystem`): its name and fuel properties."""

    @property
    def name(self) -> str: ...
    @property
    def fuel_name(self) -> str: ...
    @property
    def fuel_lhv_jpkg(self) -> float: ...
    @property
    def fuel_density_kgpm3(self) -> float: ...
    @property
    def heating_value_btu_per_gal(self) -> float: ...
    @property
    def co2_kg_per_kg(self) -> float: ...


class HEVFormulation(ABC):
    """A vehicle architecture's energy-management problem on a drive cycle.

    Subclasses define the inputs and the vectorised stage model; this base class builds the
    :class:`~hevsim.optimal.DPProblem`, checks that the cycle can be followed at all, and
    evaluates the operating points along a trajectory.
    """

    architecture: ClassVar[str]
    input_names: tuple[str, ...]
    input_units: tuple[str, ...]
    discrete_inputs: tuple[int, ...] = ()
    limit_text: dict[str, str]

    def __init__(
        self,
        model: Any,
        steps: CycleSteps,
        soc_grid: FloatArray,
        input_grids: tuple[FloatArray, ...],
        soc_initial: float,
        target: FinalTarget,
        engine: FuelConverter,
        battery: BatteryPack,
        conversion_efficiency: float,
    ) -> None:
        self.model = model
        self.steps = steps
        self.soc_grid = soc_grid
        self.input_grids = input_grids
        self.soc_initial = soc_initial
        self.target = target
        self.engine = engine  # the fuel converter: an engine, or an FCEV's fuel-cell system
        self.battery = battery
        self.conversion_efficiency = conversion_efficiency
        self.soc_invariant = soc_invariant(battery, soc_grid)
        self.table: dict[str, np.ndarray] | None = None
        self.battery_at = BatteryCache(battery)
        self._grid_seen: Any = None

    # ----------------------------------------------------------------- construction
    @classmethod
    @abstractmethod
    def default_input_points(cls, model: Any) -> int:
        """The input grid size of ``model``'s problem when ``optimization.input_grid_points``
        is 0 (the configuration's own default) [-]."""

    @classmethod
    @abstractmethod
    def from_settings(
        cls, model: Any, cycle: DriveCycle, settings: Any, soc_grid: FloatArray, target: FinalTarget
    ) -> HEVFormulation:
        """The problem of ``model`` on ``cycle`` with resolved settings
        (:class:`hevsim.optimal.hev.Settings`: ``input_points``, ``soc_initial``), SOC grid
        ``soc_grid`` [-] and final target ``target``."""

    # ----------------------------------------------------------------- model
    @abstractmethod
    def mechanical(self, k: Any, inputs: tuple[Any, ...], *, grid_duplicates: bool = False) -> Any:
        """The state-independent part of the stage model (engine maps along the cycle, the
        machine torque the wheels need) for steps ``k`` (int array) and input values,
        broadcast together. ``grid_duplicates`` masks input combinations that duplicate
        another one on the DP grid (e.g. every gear with the engine declutched)."""

    @abstractmethod
    def electrical(self, mech: Any, soc: Any, *, detail: bool = False) -> Stage:
        """The SOC-dependent part: machine limits, battery and SOC change at ``soc`` [-]
        (broadcast against the mechanical part); ``detail`` adds the operating points."""

    def stage(
        self,
        k: Any,
        inputs: tuple[Any, ...],
        soc: Any,
        *,
        detail: bool = False,
        grid_duplicates: bool = False,
    ) -> Stage:
        """Stage model for steps ``k`` (int array), input values and SOC, broadcast together."""
        return self.electrical(
            self.mechanical(k, inputs, grid_duplicates=grid_duplicates), soc, detail=detail
        )

    @abstractmethod
    def max_wheel_force_n(self, k: int) -> float:
        """Largest tractive force the powertrain can give at step ``k`` [N] (diagnostics)."""

    def input_description(self) -> str:
        """Human list of the inputs for messages."""
        return " x ".join(f"{n} ({g.size})" for n, g in zip(self.input_names, self.input_grids, strict=True))

    # ------------------------------------------------------------------- DP
    @property
    def input_shape(self) -> tuple[int, ...]:
        """Sizes of the input grids."""
        return tuple(g.size for g in self.input_grids)

    def grid_inputs(self, lead: int) -> tuple[FloatArray, ...]:
        """Input grids shaped for broadcasting after ``lead`` leading axes."""
        q = len(self.input_grids)
        return tuple(
            g.reshape((1,) * (lead + j) + (g.size,) + (1,) * (q - 1 - j))
            for j, g in enumerate(self.input_grids)
        )

    def _is_grid(self, inputs: tuple[Any, ...]) -> bool:
        if inputs is self._grid_seen:
            return True
        q = len(self.input_grids)
        ok = len(inputs) == q and all(
            np.shape(a) == (1,) * (1 + j) + (g.size,) + (1,) * (q - 1 - j) and np.array_equal(np.ravel(a), g)
            for j, (a, g) in enumerate(zip(inputs, self.input_grids, strict=True))
        )
        if ok:
            self._grid_seen = inputs
        return ok

    def build_table(self, chunk_pairs: int = 1 << 19) -> None:
        """Evaluate the stage model for every step and input on the grid, once.

        Only when the battery does not depend on SOC (:func:`soc_invariant`): then the SOC
        change, the fuel cost and the infeasibility mask of a step do not depend on the
        state, and the DP model returns one ``(1, m1, .., mq)`` row per step (the solver's
        fastest path). Stored as float64 / bool arrays of shape (N, m1, .., mq).
        """
        N = self.steps.n_steps
        shape = (N, *self.input_shape)
        M = int(np.prod(self.input_shape))
        d_soc = np.empty(shape)
        cost = np.empty(shape)
        mask = np.empty(shape, dtype=np.bool_)
        step = max(1, chunk_pairs // M)
        ins = self.grid_inputs(1)
        soc = self.soc_grid[:1]
        for k0 in range(0, N, step):
            k = np.arange(k0, min(N, k0 + step)).reshape((-1,) + (1,) * len(ins))
            st = self.stage(k, ins, soc, grid_duplicates=True)
            bad = np.broadcast_to(st.infeasible, k.shape[:1] + self.input_shape)
            sl = slice(k0, k0 + k.shape[0])
            mask[sl] = bad
            d_soc[sl] = np.where(bad, 0.0, st.d_soc)
            cost[sl] = np.where(bad, 0.0, st.cost_kg)
        self.table = {"d_soc": d_soc, "cost": cost, "mask": mask}

    def check_followable(self) -> None:
        """Raise a clear :class:`DPInfeasibleError` if some step has no feasible input."""
        N = self.steps.n_steps
        M = int(np.prod(self.input_shape))
        if self.table is not None:
            self.feasible_steps(self.table["mask"].reshape(N, M))
            return
        dead = np.ones((N, M), dtype=np.bool_)
        step = max(1, (1 << 19) // M)
        ins = self.grid_inputs(1)
        for soc in self.probe_socs():
            for k0 in range(0, N, step):
                k = np.arange(k0, min(N, k0 + step)).reshape((-1,) + (1,) * len(ins))
                st = self.stage(k, ins, soc, grid_duplicates=True)
                bad = np.broadcast_to(st.infeasible, k.shape[:1] + self.input_shape).reshape(-1, M)
                dead[k0 : k0 + k.shape[0]] &= bad
        self.feasible_steps(dead)

    def dp_problem(self) -> DPProblem:
        """The :class:`DPProblem`: state SOC, the formulation's inputs, cost fuel mass [kg]."""
        from hevsim.optimal._problem import Increment

        def precompute(inputs: tuple[Any, ...], k: int, data: Any) -> Any:
            # once per step: a row of the stage table, or the state-independent part
            if self.table is not None and self._is_grid(inputs):
                return None
            return self.mechanical(np.asarray(k), tuple(inputs), grid_duplicates=True)

        def model(states: tuple[Any, ...], inputs: tuple[Any, ...], k: int, data: Any, mech: Any) -> Any:
            if mech is None and self.table is not None:
                t = self.table
                return (Increment(t["d_soc"][k][None]),), t["cost"][k][None], t["mask"][k][None]
            st = self.electrical(mech, states[0])
            bad = st.infeasible
            return (Increment(np.where(bad, 0.0, st.d_soc)),), np.where(bad, 0.0, st.cost_kg), bad

        return DPProblem(
            model,
            state_grids=[self.soc_grid],
            input_grids=list(self.input_grids),
            n_steps=self.steps.n_steps,
            precompute=precompute,
            target=self.target,
            discrete_inputs=self.discrete_inputs,
            state_names=["soc"],
            input_names=list(self.input_names),
        )

    # ------------------------------------------------------------ followability
    def probe_socs(self) -> FloatArray:
        """SOC values at which the cycle is checked for feasibility before the DP: one when
        the battery does not depend on SOC, else the two ends of the window (battery
        capability is monotone in SOC: discharge best at the top, charge at the bottom)."""
        if self.soc_invariant:
            return self.soc_grid[:1]
        return np.array([self.soc_grid[0], self.soc_grid[-1]])

    def feasible_steps(self, infeasible_by_step: BoolArray) -> None:
        """Raise :class:`DPInfeasibleError` at the first step where every input is infeasible.

        ``infeasible_by_step``: (N, M) True where an input is infeasible at every probe SOC.
        """
        dead = np.flatnonzero(infeasible_by_step.all(axis=1))
        if dead.size:
            raise self.unfollowable_error(int(dead[0]), int(dead.size))

    def unfollowable_error(self, k: int, n_dead: int) -> DPInfeasibleError:
        """A clear error for a step that no input can drive (names the step, time and limits)."""
        grids = np.meshgrid(*self.input_grids, indexing="ij")
        inputs = tuple(g.ravel() for g in grids)
        soc = self.probe_socs()[-1]
        st = self.stage(np.array([k]), inputs, soc)
        counts = {name: int(np.count_nonzero(st.flags[name])) for name in LIMITS if name in st.flags}
        total = int(np.prod([g.size for g in self.input_grids]))
        parts = [
            f"{self.limit_text.get(name, name)} ({n} of {total} choices)" for name, n in counts.items() if n
        ]
        more = f"; {n_dead - 1} later step(s) fail too" if n_dead > 1 else ""
        return DPInfeasibleError(
            f"the {self.architecture} HEV '{self.name}' cannot follow drive cycle "
            f"'{self.steps.cycle.name}' at {self.steps.describe(k)}: every choice of "
            f"{self.input_description()} violates a component limit: {'; '.join(parts)}{more}. "
            f"(By their torque limits alone, engine and motor could give up to "
            f"{self.max_wheel_force_n(k):.0f} N at the wheels there.) "
            "Use a cycle within the vehicle's capability (speed, acceleration, grade) or larger "
            "components."
        )

    @property
    def name(self) -> str:
        """Vehicle configuration name."""
        return str(getattr(self.model, "name", self.architecture))

    # -------------------------------------------------------------- trajectory
    def details(self, soc: FloatArray, inputs: FloatArray) -> Stage:
        """Operating points along a trajectory: ``soc`` (N+1,) and ``inputs`` (N, q)."""
        N = self.steps.n_steps
        return self.stage(
            np.arange(N), tuple(inputs[:, j] for j in range(inputs.shape[1])), soc[:N], detail=True
        )

    def energy_per_soc_j(self, soc: Any) -> FloatArray:
        """Battery energy per unit SOC at the open-circuit voltage, ``Q OCV`` [J]."""
        return np.asarray(self.battery.capacity_ah * 3600.0 * self.battery.ocv(soc), dtype=np.float64)

    def contextualise(self, exc: DPInfeasibleError) -> DPInfeasibleError:
        """Add the time of every step the solver's message names."""
        text = str(exc)
        steps = sorted({int(m) for m in re.findall(r"step (\d+)", text)})
        t = self.steps.time_s
        when = [f"step {k} starts at t = {t[k]:.6g} s" for k in steps if 0 <= k < t.size]
        extra = f" ({'; '.join(when)} of cycle '{self.steps.cycle.name}')" if when else ""
        return DPInfeasibleError(f"{self.architecture} HEV '{self.name}': {text}{extra}")


def hev_metrics(
    *,
    fuel_kg: float,
    distance_m: float,
    duration_s: float,
    soc_initial: float,
    soc_final: float,
    battery: BatteryPack,
    engine: FuelConverter,
    conversion_efficiency: float,
    engine_on_time_s: float,
    compute_time_s: float,
    dp_total_cost: float,
) -> dict[str, dict[str, Any]]:
    """Scalar metrics of an optimal run, with units (same definitions as the forward
    simulator's :func:`hevsim.sim.metrics.compute_metrics`, eqs 14-20)."""
    ocv_mean = float(np.asarray(battery.ocv(0.5 * (soc_initial + soc_final))))
    density = engine.fuel_density_kgpm3
    heating = engine.heating_value_btu_per_gal
    fe = fuel_economy(distance_m, fuel_kg, soc_initial, soc_final, battery.capacity_ah, ocv_mean, density,
                      heating, conversion_efficiency)  # fmt: skip
    km = distance_m / 1000.0
    liters = fuel_kg / density * 1000.0
    eq_fuel_kg = fe["e_total_btu"] / heating * M3_PER_US_GALLON * density
    co2 = engine.co2_kg_per_kg
    nan = float("nan")
    return {
        "distance_m": metric(distance_m, "m", "distance driven"),
        "distance_mi": metric(fe["miles"], "mi", "distance driven"),
        "duration_s": metric(duration_s, "s", "cycle duration"),
        "fuel_kg": metric(fuel_kg, "kg", "fuel burnt on the optimal trajectory"),
        "fuel_l": metric(liters, "L", "fuel burnt"),
        "fuel_gal": metric(fe["gallons"], "gal", "fuel burnt (US gallons)"),
        "mpg": metric(fe["mpg"], "mi/gal", f"miles per US gallon of {engine.fuel_name}, no SOC correction"),
        "l_per_100km": metric(
            liters / km * 100.0 if km > 0 else nan, "L/100km", "fuel consumption, no SOC correction"
        ),
        "mpgge": metric(fe["mpgge"], "mi/gal", MPGGE_DESCRIPTION),
        "fuel_equivalent_kg": metric(
            eq_fuel_kg, "kg", "fuel burnt plus the fuel equivalent of the SOC change"
        ),
        "co2_g_per_km": metric(
            fuel_kg * co2 * 1e3 / km if km > 0 else nan, "g/km", "tailpipe CO2 from fuel burnt"
        ),
        "co2_soc_corrected_g_per_km": metric(
            eq_fuel_kg * co2 * 1e3 / km if km > 0 else nan, "g/km", "CO2 of the SOC-corrected fuel equivalent"
        ),
        "soc_initial": metric(soc_initial, "-", "initial state of charge"),
        "soc_final": metric(soc_final, "-", "final state of charge"),
        "battery_energy_wh": metric(fe["e_battery_wh"], "Wh", "eq (15): energy drawn from the battery"),
        "engine_on_time_s": metric(engine_on_time_s, "s", "time with the engine fired"),
        "compute_time_s": metric(compute_time_s, "s", "wall time of the optimisation (setup, DP, results)"),
        "dp_total_cost": metric(dp_total_cost, "kg", "total cost returned by the DP solver (fuel mass)"),
    }
