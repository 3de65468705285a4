"""Supervisory controllers of the parallel HEV: electric assist (rule-based), ECMS, adaptive
ECMS and the replay of a control schedule (e.g. a DP optimum).

Every controller scores candidate controls with the architecture's one power flow
(:func:`hevsim.architectures.parallel.power_flow`, through ``step.evaluate``), the same
function the DP evaluates over its grid. The candidate grid is
:func:`hevsim.architectures.parallel.candidate_controls`: engine off, plus every gear x
``control_points - 1`` throttles in (0, 1].
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hevsim.architectures import parallel as P
from hevsim.errors import ConfigError
from hevsim.units import rpm_to_radps

HOLD_EQUIVALENCE_FACTOR = 10.0
"""Equivalence factor [-] of the electric assist's charge-hold below ``soc_low`` with an
auxiliary load: the ECMS score ``fuel power + s x battery chemical power`` of every candidate
with a factor so high that the engine charges as hard as its speed allows."""

Control = tuple[float, ...]
"""A control: (gear [1..G], throttle [-]) for the parallel HEV, (engine speed [rad/s],
throttle [-]) for the power split; throttle 0 is engine off."""


def _argmin_feasible(cost: np.ndarray, feasible: np.ndarray) -> int | None:
    if not feasible.any():
        return None
    c = np.where(feasible, cost, np.inf)
    return int(np.argmin(c))


class _GridController:
    """Shared part: the architecture's candidate grid (``candidate_controls`` of its module)
    and the ECMS score.

    An architecture whose controls cannot change freely from step to step (the fuel cell's ramp
    limits) gives its module ``control_state(model, stage=None)`` (what the limits start from:
    before a run, or after the ``stage`` applied) and ``reachable_controls(model, state, dt_s,
    controls)`` (the candidates moved into what is reachable in the step): the scored candidates
    of a step are then ``reachable_controls`` of the grid (:meth:`candidates`). Such an
    architecture also gives ``committed_energy_j(model, controls, dt_s)``: the energy [J] a
    candidate commits the battery to take after the step should the bus load fall at once (a
    fuel cell cannot drop to off faster than its ramp-down limit); the candidates that keep
    that room below ``battery.soc_max`` come first (:meth:`admissible`), else a full battery
    and a source still ramping down leave no feasible control even when stopping."""

    def __init__(self, hev: Any, control_points: int) -> None:
        from hevsim.architectures import architecture
        from hevsim.architectures._common import fuel_converter

        self.hev = hev
        module = architecture(hev.config.architecture).power_module()
        self.controls: tuple[np.ndarray, ...] = module.candidate_controls(hev, int(control_points))
        self.lhv = fuel_converter(hev).fuel_lhv_jpkg
        self._reachable = getattr(module, "reachable_controls", None)
        self._control_state = getattr(module, "control_state", None)
        self._committed = getattr(module, "committed_energy_j", None)
        self._shed = getattr(module, "shed_controls", None)
        self.ramp_down_overrides = 0
        self._shedding: dict[int, bool] = {}
        self.control_state: Any = None
        # plug-in hybrid ([plugin], hevsim.config.PluginSection): charge depleting above cd_soc,
        # where the EV rule admits wheel powers below cd_ev_power [W] at any speed and ECMS
        # takes the factor cd_s [-]; cd_soc = inf (never) for a charge-sustaining hybrid
        self.cd_soc, self.cd_ev_power, self.cd_s = charge_depleting(hev.config)

    @property
    def gears(self) -> np.ndarray:
        """First control of every candidate (the gear for the parallel HEV)."""
        return self.controls[0]

    @property
    def throttles(self) -> np.ndarray:
        """Last control of every candidate (the throttle)."""
        return self.controls[-1]

    def reset(self, soc_initial: float) -> None:
        """Before a run: the architecture's control state at the start (if it has one)."""
        if self._control_state is not None:
            self.control_state = self._control_state(self.hev)
        self.ramp_down_overrides = 0
        self._shedding = {}

    def update(self, step: Any, stage: Any) -> None:
        """After a step: the architecture's control state after it (if it has one); count a
        step whose control had to leave the reachable window (:meth:`shed`)."""
        if self._control_state is not None:
            self.control_state = self._control_state(self.hev, stage)
        self.ramp_down_overrides += int(self._shedding.get(id(step), False))
        self._shedding.clear()

    def shed(self, step: Any) -> Control | None:
        """Where no reachable candidate is feasible: the architecture's ``shed_controls(model,
        state, dt_s)`` (a fuel cell dropping faster than its ramp-down limit, ascending), the
        highest feasible one (the least shed), counted in ``ramp_down_overrides``; None if the
        architecture has none or none is feasible (the forward loop then lowers the end speed)."""
        if self._shed is None or self.control_state is None:
            return None
        controls = tuple(self._shed(self.hev, self.control_state, step.dt_s))
        _, feasible = step.evaluate(*controls)
        ok = np.flatnonzero(np.ravel(feasible))
        if ok.size == 0:
            return None
        self._shedding[id(step)] = True
        return self.pick(int(ok[-1]), controls)

    def candidates(self, step: Any) -> tuple[np.ndarray, ...]:
        """The candidate controls of ``step``: the grid, moved into what the architecture can
        reach from its control state within the step where it limits that."""
        if self._reachable is None:
            return self.controls
        return tuple(self._reachable(self.hev, self.control_state, step.dt_s, self.controls))

    def depleting(self, soc: float) -> bool:
        """Charge depleting at ``soc`` [-] (a plug-in hybrid above its ``plugin.cs_soc``)."""
        return bool(soc > self.cd_soc)

    def score(self, step: Any, s: float) -> tuple[np.ndarray, np.ndarray]:
        """(ECMS cost [W] = fuel power + s x battery chemical power, feasible) per candidate.

        The battery chemical power is ``-dSOC/dt x Q x OCV`` (the energy the DP's costate
        prices: ``s = -costate x LHV / (Q OCV)``). Candidates: :meth:`candidates`.
        """
        cost, feasible, _ = self._score(step, s, self.candidates(step))
        return cost, feasible

    def _score(self, step: Any, s: float, controls: tuple[np.ndarray, ...]) -> tuple[Any, np.ndarray, Any]:
        st, feasible = step.evaluate(*controls)
        p_fuel = st.cost_kg / step.dt_s * self.lhv
        p_chem = -st.d_soc / step.dt_s * step.energy_per_soc_j
        return p_fuel + s * p_chem, feasible, st

    def best(self, step: Any, s: float) -> Control | None:
        self._shedding[id(step)] = False  # (ids of steps gone are reused)
        controls = self.candidates(step)
        cost, feasible, st = self._score(step, s, controls)
        if not feasible.any():
            return self.shed(step)
        return self.pick(_argmin_feasible(cost, self.admissible(step, controls, feasible, st)), controls)

    def admissible(
        self, step: Any, controls: tuple[np.ndarray, ...], feasible: np.ndarray, stage: Any
    ) -> np.ndarray:
        """``feasible`` narrowed to the candidates (``controls``, their power flow ``stage``)
        whose SOC after the step leaves room below ``step.soc_max`` for the energy they commit
        the battery to (``committed_energy_j`` of the architecture; Q x OCV per unit SOC, an upper
        bound of what charging losses let in), when any feasible candidate does; else the
        feasible ones that overrun that room least (e.g. braking at the top of the window: the
        fuel cell off, regeneration alone over ``soc_max``, as every controller lets it)."""
        if self._committed is None or not feasible.any():
            return feasible
        room = (step.soc_max - step.soc - np.asarray(stage.d_soc)) * step.energy_per_soc_j
        excess = np.asarray(self._committed(self.hev, controls, step.dt_s)) - room
        ok = feasible & (excess <= 0.0)
        if ok.any():
            return ok
        least = float(np.min(excess[feasible]))
        return feasible & (excess <= least + 1e-9 * max(abs(least), 1.0))

    def pick(self, i: int | None, controls: tuple[np.ndarray, ...] | None = None) -> Control | None:
        """Candidate ``i`` of ``controls`` (default the grid) as a control tuple (None for None)."""
        grid = self.controls if controls is None else controls
        return None if i is None else tuple(float(c[i]) for c in grid)


class _RuleBased(_GridController):
    """Shared part of the rule-based baselines: the EV rule (low speed and power) and the
    charging power that ramps from 0 at ``soc_high`` to ``charge_power_w`` at ``soc_low``."""

    def __init__(self, hev: Any, soc_low: float, soc_high: float, ev_speed_mps: float, ev_power_w: float,
                 charge_power_w: float, control_points: int) -> None:  # fmt: skip
        super().__init__(hev, control_points)
        self.soc_low, self.soc_high = float(soc_low), float(soc_high)
        self.ev_speed, self.ev_power, self.charge_power = (
            float(ev_speed_mps),
            float(ev_power_w),
            float(charge_power_w),
        )

    def low_load(self, step: Any, p_dem: float) -> bool:
        """Below the EV speed and the EV power (wheel power ``p_dem`` [W]); charge depleting:
        below the CD EV power at any speed."""
        if self.depleting(step.soc):
            return bool(p_dem < self.cd_ev_power)
        return bool(step.v_mid_mps < self.ev_speed and p_dem < self.ev_power)

    def charge_fraction(self, soc: float) -> Any:
        """Share [-] of ``charge_power`` to add at ``soc``: 0 at ``soc_high`` (and charge
        depleting), 1 at ``soc_low``."""
        if self.depleting(soc):
            return 0.0
        return np.clip((self.soc_high - soc) / (self.soc_high - self.soc_low), 0.0, 1.0)

    def charging_power(self, soc: float) -> float:
        """Engine charging power [W] at ``soc`` [-]: ``charge_fraction x charge_power``, plus
        the auxiliary load (``[controller] aux_power_w``) once the SOC is below ``soc_low``:
        there the running engine carries the auxiliaries as well, so that they cannot drain
        the battery to the floor of its window (issue 26: a 5 kW load on the parallel HEV
        example ran it 0.11 below its floor with the charging power alone)."""
        p = float(self.charge_fraction(soc)) * self.charge_power
        return p + self.aux_w if soc < self.soc_low else p

    def holds(self, soc: float) -> bool:
        """Below ``soc_low`` with an auxiliary load: the electric assist holds the SOC (the
        engine carries the auxiliaries and charges; :data:`HOLD_EQUIVALENCE_FACTOR`)."""
        return soc < self.soc_low and self.aux_w > 0.0

    @property
    def aux_w(self) -> float:
        """The vehicle's electrical auxiliary load [W]."""
        return float(getattr(self.hev, "aux_power_w", 0.0) or 0.0)


class ECMS(_GridController):
    """Equivalent consumption minimisation with a constant equivalence factor ``s`` [-]."""

    name = "ecms"

    def __init__(self, hev: Any, equivalence_factor: float, control_points: int) -> None:
        super().__init__(hev, control_points)
        self.s = float(equivalence_factor)

    def choose(self, step: Any) -> Control | None:
        """The feasible candidate of least fuel power + s x battery chemical power (``cd_s``
        while charge depleting)."""
        return self.best(step, self.cd_s if self.depleting(step.soc) else self.s)


class AdaptiveECMS(_GridController):
    """ECMS whose factor follows the SOC: ``s = s0 + kp e + ki ∫ e dt``, ``e = SOC_ref - SOC``.

    Needs no knowledge of the cycle. The reference is the run's initial SOC lowered by the
    share ``aecms_kinetic_fraction`` of the vehicle's kinetic energy that braking can bring
    back, ``SOC_ref = SOC0 - f m_eff v^2 / 2 / (Q OCV)`` (a moving car keeps room for its
    regeneration, so the run ends charge-sustaining when it stops).
    """

    name = "aecms"

    def __init__(self, hev: Any, equivalence_factor: float, aecms_kp: float, aecms_ki: float,
                 aecms_kinetic_fraction: float, control_points: int) -> None:  # fmt: skip
        super().__init__(hev, control_points)
        self.s0 = float(equivalence_factor)
        self.kp = float(aecms_kp)
        self.ki = float(aecms_ki)
        self.kin = float(aecms_kinetic_fraction) * 0.5 * hev.body.mass_kg * hev.body.mass_factor
        self.soc_ref = 0.0
        self.integral = 0.0
        self.s = self.s0

    def reset(self, soc_initial: float) -> None:
        """Target the initial SOC (a plug-in hybrid: at most its ``cs_soc``); clear the integrator."""
        super().reset(soc_initial)
        self.soc_ref = float(min(soc_initial, self.cd_soc))
        self.integral = 0.0
        self.s = self.s0

    def choose(self, step: Any) -> Control | None:
        """ECMS with the current factor (floored at 0); ``cd_s`` while charge depleting."""
        if self.depleting(step.soc):
            self.s = self.cd_s
            return self.best(step, self.s)
        err = self.error(step)
        self.s = max(0.0, self.s0 + self.kp * err + self.ki * self.integral)
        return self.best(step, self.s)

    def error(self, step: Any) -> float:
        """SOC reference (initial SOC less the recoverable kinetic energy) - SOC [-]."""
        return self.soc_ref - self.kin * step.v_mid_mps**2 / step.energy_per_soc_j - step.soc

    def update(self, step: Any, stage: Any) -> None:
        """Integrate the SOC error over the step (not while charge depleting)."""
        super().update(step, stage)
        if not self.depleting(step.soc):
            self.integral += self.error(step) * step.dt_s


class ElectricAssist(_RuleBased):
    """ADVISOR-style electric-assist / load-following baseline.

    Gear: the shift schedule (up above ``upshift_rpm``, down below ``downshift_rpm`` of
    engine speed). Engine off (EV) when braking or coasting, with SOC above ``soc_high``, or
    below ``ev_speed_mps`` and ``ev_power_w`` with SOC above ``soc_low`` (the charge-sustaining
    band is ``soc_low``..``soc_high``). Above ``engine_on_speed_mps`` the engine is fired
    whatever the SOC and the demand (braking or coasting: at its smallest throttle, the machine
    regenerating the rest), as FASTSim's HEV forces its engine on above ``mph_fc_on``.
    Otherwise the engine
    follows the load in the scheduled gear, plus a charging power ramping from 0 at
    ``soc_high`` to ``charge_power_w`` at ``soc_low``, and gives at least
    ``engine_min_power_w`` [W] while the SOC is below ``soc_high`` (the surplus charges the
    battery); the machine assists beyond the engine's torque. If that control is infeasible
    (a component limit), the feasible candidate of least fuel is taken.
    """

    name = "electric_assist"

    def __init__(self, hev: P.ParallelHEV, soc_low: float, soc_high: float, ev_speed_mps: float,
                 ev_power_w: float, charge_power_w: float, upshift_rpm: float, downshift_rpm: float,
                 control_points: int, engine_on_speed_mps: float = 1000.0,
                 engine_min_power_w: float = 0.0) -> None:  # fmt: skip
        super().__init__(hev, soc_low, soc_high, ev_speed_mps, ev_power_w, charge_power_w, control_points)
        self.w_up, self.w_down = rpm_to_radps(upshift_rpm), rpm_to_radps(downshift_rpm)
        self.engine_on_speed = float(engine_on_speed_mps)
        self.engine_min_power = float(engine_min_power_w)
        self.thr_grid = np.linspace(0.0, 1.0, int(control_points))[1:]
        self.gear = 1

    def reset(self, soc_initial: float) -> None:
        """Start in first gear."""
        self.gear = 1

    def shift(self, w_fd: float) -> int:
        """Apply the shift schedule at final-drive speed ``w_fd`` [rad/s]; return the gear."""
        from hevsim.control.simple import shift_gear

        self.gear = shift_gear(self.gear, w_fd, self.hev.gear_ratios, self.w_up, self.w_down)
        return self.gear

    def choose(self, step: Any) -> Control | None:
        hev = self.hev
        w_fd = step.wheel_speed_radps * hev.final_drive.ratio
        g = self.shift(w_fd)
        p_dem = step.wheel_torque_nm * step.wheel_speed_radps
        soc = step.soc
        low_load = self.low_load(step, p_dem)
        if self.holds(soc):  # charge-hold: ECMS with a charging-biased factor, every candidate
            return self.best(step, HOLD_EQUIVALENCE_FACTOR)
        forced = step.v_mid_mps > self.engine_on_speed
        if self.depleting(soc):
            ev = not forced and (p_dem <= 0.0 or low_load)
        else:
            ev = not forced and (p_dem <= 0.0 or soc > self.soc_high or (soc > self.soc_low and low_load))
        control: Control = (float(g), 0.0)
        if not ev:
            w_e = w_fd * hev.gear_ratios[g - 1]
            t_fd = float(hev.final_drive.input_torque(step.wheel_torque_nm))
            t_req = float(hev.gears[g - 1].input_torque(t_fd)) + (
                self.charging_power(soc) / w_e if w_e > 0 else 0.0
            )
            if soc < self.soc_high and w_e > 0:
                t_req = max(t_req, self.engine_min_power / w_e)
            mech = P.mechanical(hev, step.wheel_speed_radps, 0.0, float(g), self.thr_grid)
            ok = ~mech["bad"]
            if ok.any():
                t_e = np.where(ok, mech["t_e"], -np.inf)
                above = np.flatnonzero(t_e >= t_req)
                i = int(above[0]) if above.size else int(np.argmax(t_e))
                control = (float(g), float(self.thr_grid[i]))
        _, feasible = step.evaluate(np.array([control[0]]), np.array([control[1]]))
        if feasible[0]:
            return control
        cost, feasible = self.score(step, 0.0)  # fallback: least fuel among the feasible
        return self.pick(_argmin_feasible(cost, feasible))


REPLAY_SEGMENT_POINTS = 65
"""Points per pass (two passes) along the segment from an infeasible scheduled control to the
closest feasible candidate: the replay's fallback lands within 1/4096 of that segment of the
feasibility boundary."""


def closest_feasible(step: Any, scheduled: Control, continuous: tuple[bool, ...]) -> Control | None:
    """The feasible control of ``step`` closest to ``scheduled`` (None if no candidate is).

    Candidates: the architecture's ``candidate_controls`` grid (``[controller] control_points``);
    the closest feasible one by the sum over controls of ``|c - scheduled| / range of c``. Then,
    when it differs from ``scheduled`` in ``continuous`` controls only (``continuous[j]``: control
    ``j`` varies continuously, e.g. a throttle or a power, not a gear), the feasible point of the
    straight segment between them nearest to ``scheduled`` (two passes of
    :data:`REPLAY_SEGMENT_POINTS`): where the BMS limits the battery below what the schedule
    needs, the fuel converter gives or takes only the difference (the friction brakes take the
    regeneration the battery may not)."""
    from hevsim.architectures import architecture

    model = step.model
    cfg = model.config
    module = architecture(cfg.architecture).power_module()
    grid = tuple(np.asarray(g, dtype=np.float64) for g in module.candidate_controls(
        model, int(getattr(cfg.controller, "control_points", 21))))  # fmt: skip
    _, feasible = step.evaluate(*grid)
    ok = np.ravel(feasible)
    if not ok.any():
        return None
    dist = np.zeros(ok.shape)
    for g, c in zip(grid, scheduled, strict=True):
        dist += np.abs(g - c) / max(float(np.ptp(g)), 1e-12)
    i = int(np.argmin(np.where(ok, dist, np.inf)))
    good = np.array([float(g[i]) for g in grid])
    bad = np.asarray(scheduled, dtype=np.float64)
    fixed = ~np.asarray(continuous, dtype=bool)
    if np.any(good[fixed] != bad[fixed]):
        return tuple(float(x) for x in good)
    lo, hi = 0.0, 1.0  # segment parameter: 0 = scheduled (infeasible), 1 = good (feasible)
    for _ in range(2):
        t = np.linspace(lo, hi, REPLAY_SEGMENT_POINTS)
        pts = bad[:, None] + (good - bad)[:, None] * t[None, :]
        _, f = step.evaluate(*pts)
        j = int(np.flatnonzero(np.ravel(f))[0]) if np.ravel(f).any() else t.size - 1
        lo, hi = (t[j - 1], t[j]) if j > 0 else (t[0], t[0])
    x = bad + (good - bad) * hi
    _, f = step.evaluate(*(np.array([v]) for v in x))
    return tuple(float(v) for v in (x if np.ravel(f)[0] else good))


class _Replay:
    """Shared part of the schedule replays: where the scheduled control is infeasible (a pack's
    BMS limits the battery below the nominal limits the DP saw, a derated or full pack) the
    replay takes the closest feasible control (:func:`closest_feasible`) instead of stopping,
    and counts those steps. :meth:`report` gives the run's metadata: the steps that deviated,
    and, for a schedule from a DP result, the fuel and final SOC differences to it."""

    reference: dict[str, float]
    deviated_steps: int
    deviated_first_s: float
    _deviated: dict[int, bool]

    def _clear(self) -> None:
        self.deviated_steps, self.deviated_first_s, self._deviated = 0, float("nan"), {}

    def reset(self, soc_initial: float) -> None:
        """Clear the count of deviated steps."""
        self._clear()

    def update(self, step: Any, stage: Any) -> None:
        """Count the step if its control was not the scheduled one (of the choices made this
        step, at the trial end speeds of a traction limit too, the one for ``step``)."""
        if self._deviated.get(id(step), False):
            if self.deviated_steps == 0:
                self.deviated_first_s = float(step.time_s)
            self.deviated_steps += 1
        self._deviated.clear()

    def follow(self, step: Any, scheduled: Control, continuous: tuple[bool, ...]) -> Control | None:
        """``scheduled`` where feasible, else :func:`closest_feasible` (None if nothing is)."""
        _, feasible = step.evaluate(*(np.array([c]) for c in scheduled))
        deviated = self._deviated[id(step)] = not bool(np.ravel(feasible)[0])
        return closest_feasible(step, scheduled, continuous) if deviated else scheduled

    def report(self, metrics: dict[str, Any]) -> dict[str, Any]:
        """``schedule_deviated_steps`` (steps whose scheduled control was infeasible and a
        closest feasible one was applied), ``schedule_deviated_first_s`` [s] (None: none) and,
        for a DP schedule, ``schedule_fuel_difference_kg``, ``schedule_soc_final_difference`` and
        ``schedule_soc_initial_difference`` (this run less the DP's)."""
        out: dict[str, Any] = {
            "schedule_deviated_steps": int(self.deviated_steps),
            "schedule_deviated_first_s": self.deviated_first_s if self.deviated_steps else None,
        }
        for key, name in (
            ("fuel_kg", "schedule_fuel_difference_kg"),
            ("soc_final", "schedule_soc_final_difference"),
            ("soc_initial", "schedule_soc_initial_difference"),  # a DP from another SOC: not a deviation
        ):
            if key in self.reference and key in metrics:
                out[name] = float(metrics[key]["value"]) - self.reference[key]
        return out


def _dp_reference(result: Any) -> dict[str, float]:
    keys = ("fuel_kg", "soc_final", "soc_initial")
    return {k: float(result.metrics[k]["value"]) for k in keys if k in result.metrics}


@dataclass
class ControlSchedule(_Replay):
    """Replay a control sequence: ``gear`` [1..G, 0 = engine off] (the engine speed [rad/s]
    for the power split) and ``throttle`` [-] per step starting at ``time_s`` [s] (each holds
    until the next time), e.g. a DP optimum. Where the scheduled control is infeasible the
    closest feasible one is applied and counted (:class:`_Replay`); ``reference``: the DP's
    ``fuel_kg`` and ``soc_final`` the report compares with."""

    time_s: np.ndarray
    gear: np.ndarray
    throttle: np.ndarray
    source: str = "schedule"
    name: str = "schedule"
    reference: dict[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        t, g, u = (np.asarray(a, dtype=np.float64) for a in (self.time_s, self.gear, self.throttle))
        if not (t.ndim == 1 and t.shape == g.shape == u.shape and t.size >= 1):
            raise ConfigError(f"{self.source}: time, gear and throttle must be 1-D arrays of equal length.")
        if np.any(~np.isfinite(u)) or np.any((u < 0) | (u > 1)):
            raise ConfigError(f"{self.source}: throttle must be finite and within 0..1.")
        self.time_s, self.gear, self.throttle = t, g, u
        self._clear()

    @classmethod
    def from_optimization(cls, result: Any) -> ControlSchedule | InputSchedule:
        """The optimal controls of a parallel, power-split or series
        :class:`~hevsim.optimal.OptimizationResult` (for the power split ``gear`` holds the
        engine speed [rad/s]; a series result gives an :class:`InputSchedule` of its genset
        electrical power)."""
        from hevsim.architectures import ARCHITECTURES

        if replayed_inputs(result.architecture):
            return InputSchedule.from_optimization(result)
        entry = ARCHITECTURES.get(result.architecture)  # its first control input (gear, engine speed)
        first = entry.controls[0] if entry is not None and entry.dp_formulation and entry.controls else None
        if first is None:
            raise ConfigError(
                f"a control schedule needs a parallel, power-split or series DP result, got "
                f"{result.architecture!r}."
            )
        ts = result.timeseries
        return cls(ts["time_s"].to_numpy(), ts[first].to_numpy(), ts["engine_throttle"].to_numpy(),
                   source=f"DP optimum on {result.cycle.name}", reference=_dp_reference(result))  # fmt: skip

    def choose(self, step: Any) -> Control | None:
        """The scheduled control at the step's start time; where infeasible, the closest
        feasible one (None if no control is feasible)."""
        i = int(np.clip(np.searchsorted(self.time_s, step.time_s + 1e-9, side="right") - 1, 0, None))
        u = float(self.throttle[i])
        g = float(self.gear[i]) if u > 0 else 1.0
        speed = step.model.config.architecture != "parallel"  # the power split's engine speed; a gear is not
        return self.follow(step, (max(g, 1.0), u), (speed, True))


def replayed_inputs(architecture: str) -> tuple[str, ...]:
    """The DP inputs of ``architecture`` that its ``power_flow`` takes as controls as they are
    (the module's ``DP_INPUTS``: the series HEV's genset electrical power, the fuel cell's net
    power; the time-series columns an :class:`InputSchedule` replays), () where it has none."""
    from hevsim.architectures import ARCHITECTURES

    entry = ARCHITECTURES.get(architecture)
    return tuple(getattr(entry.power_module(), "DP_INPUTS", ())) if entry is not None else ()


@dataclass
class InputSchedule(_Replay):
    """Replay the inputs of a DP optimum as the DP took them: ``controls`` holds one array per
    control of the architecture's ``power_flow`` (the series HEV: genset electrical power [W]),
    each value applying from ``time_s`` [s] until the next time. Where the scheduled control is
    infeasible the closest feasible one is applied and counted (:class:`_Replay`)."""

    time_s: np.ndarray
    controls: tuple[np.ndarray, ...]
    source: str = "schedule"
    name: str = "schedule"
    reference: dict[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        t = np.asarray(self.time_s, dtype=np.float64)
        cs = tuple(np.asarray(c, dtype=np.float64) for c in self.controls)
        if not (t.ndim == 1 and t.size >= 1 and cs and all(c.shape == t.shape for c in cs)):
            raise ConfigError(f"{self.source}: time and every control must be 1-D arrays of equal length.")
        if not all(np.isfinite(c).all() for c in cs):
            raise ConfigError(f"{self.source}: every control value must be finite.")
        self.time_s, self.controls = t, cs
        self._clear()

    @classmethod
    def from_optimization(cls, result: Any) -> InputSchedule:
        """The optimal inputs of a DP result of an architecture with :func:`replayed_inputs`."""
        columns = replayed_inputs(result.architecture)
        if not columns:
            raise ConfigError(
                f"an input schedule needs a DP result whose inputs are the power flow's controls (the "
                f"series HEV's, the fuel-cell vehicle's), got {result.architecture!r}."
            )
        ts = result.timeseries
        return cls(ts["time_s"].to_numpy(), tuple(ts[c].to_numpy() for c in columns),
                   source=f"DP optimum on {result.cycle.name}", reference=_dp_reference(result))  # fmt: skip

    def choose(self, step: Any) -> Control | None:
        """The scheduled control at the step's start time; where infeasible, the closest
        feasible one (None if no control is feasible)."""
        i = int(np.clip(np.searchsorted(self.time_s, step.time_s + 1e-9, side="right") - 1, 0, None))
        return self.follow(step, tuple(float(c[i]) for c in self.controls), (True,) * len(self.controls))


def ecms_from_dp(result: Any) -> dict[str, float]:
    """ECMS parameters from a DP result: ``equivalence_factor`` = the median of the DP's
    ``-costate x LHV / (Q OCV)`` along the optimal path (the ``equivalence_factor_median``
    metric of :func:`hevsim.optimal.optimize`)."""
    s = float(result.metrics["equivalence_factor_median"]["value"])
    if not np.isfinite(s) or s < 0:
        raise ConfigError(f"DP result: equivalence factor {s!r} is not usable; expected a finite value >= 0.")
    return {"equivalence_factor": s}


def ecms_from_costate_csv(path: Any) -> dict[str, float]:
    """ECMS parameters from the ``costate.csv`` of a saved DP result folder (or the file)."""
    from pathlib import Path

    import pandas as pd

    p = Path(path)
    f = p / "costate.csv" if p.is_dir() else p
    if not f.is_file():
        raise ConfigError(f"{p}: no costate.csv; expected a folder written by `hevsim optimize` or the file.")
    frame = pd.read_csv(f)
    if "equivalence_factor" not in frame:
        raise ConfigError(f"{f}: missing column 'equivalence_factor'; found {list(frame.columns)}.")
    s = frame["equivalence_factor"].to_numpy(float)
    s = s[np.isfinite(s)]
    if s.size == 0:
        raise ConfigError(f"{f}: column 'equivalence_factor' holds no finite value.")
    return {"equivalence_factor": float(np.median(s))}


class PowerFollower(_RuleBased):
    """Rule-based power follower of the power split, on the engine's optimal operating line.

    EV (engine off) when braking or coasting, below ``ev_speed_mps`` and ``ev_power_w`` with
    SOC above ``soc_low``, or below ``engine_min_power_w`` with SOC above ``soc_high``.
    Otherwise the engine gives the wheel power plus a charging power ramping from 0 at
    ``soc_high`` to ``charge_power_w`` at ``soc_low``, and at least ``engine_min_power_w``
    while the SOC is below ``soc_high`` (the surplus charges the battery). Of the feasible
    candidates within 10 % (at least 1 kW) of that engine power it takes the one of least fuel
    per unit of engine work (the most efficient: the optimal operating line the DP follows, on
    the candidate grid); if none, the one of engine power closest to it.
    """

    name = "power_follower"
    POWER_BAND = 0.1
    """Relative band around the target engine power [-]."""
    POWER_BAND_MIN_W = 1000.0
    """Smallest band around the target engine power [W]."""

    def __init__(self, hev: Any, soc_low: float, soc_high: float, ev_speed_mps: float, ev_power_w: float,
                 charge_power_w: float, control_points: int,
                 engine_min_power_w: float = 0.0) -> None:  # fmt: skip
        super().__init__(hev, soc_low, soc_high, ev_speed_mps, ev_power_w, charge_power_w, control_points)
        self.engine_min_power = float(engine_min_power_w)

    def electric(self, p_dem: float, soc: float, low_load: bool) -> bool:
        """Engine off: braking or coasting, low load above ``soc_low``, or (with the SOC above
        ``soc_high``) a wheel power ``p_dem`` [W] below ``engine_min_power_w``: the surplus the
        floor charged is spent instead of running the engine below its floor. Charge
        depleting: braking, coasting or low load (the CD EV rule)."""
        if self.depleting(soc):
            return p_dem <= 0.0 or low_load
        return (
            p_dem <= 0.0
            or (soc > self.soc_low and low_load)
            or (soc > self.soc_high and p_dem < self.engine_min_power)
        )

    def target_power(self, p_dem: float, soc: float) -> float:
        """Engine power [W] to give at wheel power ``p_dem`` [W] and state of charge ``soc`` [-]."""
        target = max(p_dem, 0.0) + self.charging_power(soc)
        floor = soc < self.soc_high and not self.depleting(soc)
        return max(target, self.engine_min_power) if floor else target

    def choose(self, step: Any) -> Control | None:
        """EV or the most efficient engine operating point near the target power."""
        p_dem = step.wheel_torque_nm * step.wheel_speed_radps
        soc = step.soc
        low_load = self.low_load(step, p_dem)
        st, feasible = step.evaluate(*self.controls)
        feasible = np.ravel(feasible)
        ev = np.ravel(np.asarray(self.controls[-1]) == 0.0)
        if self.electric(p_dem, soc, low_load) and (feasible & ev).any():
            return self.pick(int(np.flatnonzero(feasible & ev)[0]))
        target = self.target_power(p_dem, soc)
        p_eng = np.ravel(st.details["engine_power_w"]) if st.details else None
        if p_eng is None:
            st, _ = step.evaluate(*self.controls, detail=True)
            p_eng = np.ravel(st.details["engine_power_w"])
        fuel = np.ravel(np.broadcast_to(st.cost_kg, feasible.shape))
        band = max(self.POWER_BAND * target, self.POWER_BAND_MIN_W)
        near = feasible & ~ev & (np.abs(p_eng - target) <= band)
        if near.any():
            return self.pick(_argmin_feasible(specific_fuel(fuel, p_eng), near))
        return self.pick(_argmin_feasible(np.abs(p_eng - target), feasible))


def charge_depleting(cfg: Any) -> tuple[float, float, float]:
    """(SOC above which the vehicle runs charge depleting [-], wheel power below which the CD EV
    rule drives electrically [W], ECMS equivalence factor while depleting [-]) of a
    configuration's ``[plugin]`` section; (inf, inf, 0) for a charge-sustaining hybrid (never
    depleting). EV first: every power is EV (the engine only where the electric drive cannot),
    ECMS prices battery energy at 0; blended: the ``blended_*`` keys."""
    from hevsim.config import is_plugin

    if not is_plugin(cfg):
        return np.inf, np.inf, 0.0
    pl = cfg.plugin
    if pl.mode == "ev_first":
        return float(pl.cs_soc), np.inf, 0.0
    return float(pl.cs_soc), float(pl.blended_engine_power_w), float(pl.blended_equivalence_factor)


def specific_fuel(fuel: np.ndarray, engine_power_w: np.ndarray) -> np.ndarray:
    """Fuel per unit of engine power (``fuel`` [kg] over ``engine_power_w`` [W], inf where the
    engine gives no power): the power follower's ranking of candidates near its target."""
    p = np.asarray(engine_power_w, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(p > 0.0, np.asarray(fuel, dtype=np.float64) / np.where(p > 0.0, p, 1.0), np.inf)
