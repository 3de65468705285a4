"""Performance tests of any forward-simulated architecture: 0-60 mph, 0-100 km/h, 50-80 mph
passing, quarter mile, top speed and gradeability, each with the limit that binds.

Everything runs through the architecture's one power flow (``power_flow`` of its module in
:mod:`hevsim.architectures`) over the candidate controls that span its capability
(``capability_controls``: every gear, full throttle included, for the engine vehicles):

* **Accelerations** are forward runs (:func:`hevsim.sim.forward.simulate_architecture`) on
  a trace the car cannot follow (a step to a speed far above its top speed): the driver gets,
  every step, the largest end speed some candidate can give. Times are interpolated
  linearly between steps; the quarter mile is the time at 402.336 m.
* **Top speed** is the largest speed at which some candidate still accelerates (by
  :data:`TOP_SPEED_ACCEL_MPS2`) on the level, and **gradeability** the largest grade at
  which some candidate holds the given speed (bisection on speed or grade).

**Tire adhesion** caps the tractive force at the wheels: ``F <= mu N`` with ``mu`` the
peak friction coefficient (``[tire] friction_coefficient``) and ``N`` the normal load on the
driven axle(s) (``[tire] driven_axle``): the static share of the weight plus the load transfer
of the acceleration, grade and drag at the CG height, eqs (4)-(5)
(:func:`hevsim.components.body.axle_normal_loads`, ``[body] cg_height_m``,
``front_axle_to_cg_m``, ``rear_axle_to_cg_m``). The rotating-mass share of the inertia
(``mass_factor`` - 1) is taken by the wheels' and shafts' own inertia and shifts no load. On
a level road without drag or rolling resistance a traction-limited launch has the constant
acceleration ``a = mu g (l / L) / (delta -/+ mu h / L)`` (rear- / front-wheel drive; ``l`` the
distance from the CG to the other axle, ``L`` the wheelbase, ``h`` the CG height) and
``a = mu g / delta`` with all wheels driven.

The **binding limit** of a test is the component limit that stops the candidates feasible
just below the limit when asked for a little more (tire adhesion, machine torque, engine
torque, engine speed, battery power or current, a series HEV's genset power); for an
acceleration, the most frequent one over its steps.

A **series HEV** runs on its quasi-static power flow (:mod:`hevsim.architectures.series`):
the candidates are genset electrical powers from the engine-generator's largest down to 0,
the genset already running on the DP's optimal operating line (no cranking: the figures are
those of a car whose genset is warm and on, as a series HEV is when it is driven hard). The
traction motor's rotor inertia counts in the effective mass as in the compiled kernel
(``quasi_static_model``). Where the battery reaches its power or current limit with the genset
at its largest power, the binding limit names both.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from hevsim.components.body import VehicleBody
from hevsim.cycles import DriveCycle
from hevsim.errors import ConfigError
from hevsim.sim.forward import Step, _battery_state, simulate_architecture
from hevsim.units import MPS_PER_MPH

QUARTER_MILE_M = 402.336
"""A quarter of a statute mile [m]."""
KMH_100_MPS = 100.0 / 3.6
"""100 km/h [m/s]."""
WALL_SPEED_MPS = 150.0
"""Trace speed of the acceleration runs [m/s]: above any road vehicle's top speed."""
TOP_SPEED_ACCEL_MPS2 = 1e-3
"""Acceleration [m/s^2] the powertrain must still give at its top speed (so that a vehicle
without road load has a top speed: the redline or the machine's last speed)."""
BISECTION_STEPS = 50
"""Bisection steps of the top-speed and gradeability searches [-]."""
LIMIT_NAMES = {
    "traction": "traction (tire adhesion)",
    "motor_torque": "machine torque",
    "engine_torque": "engine torque",
    "engine_speed": "engine speed (redline)",
    "motor_speed": "machine speed (end of its map)",
    "generator_torque": "generator (MG1) torque",
    "generator_speed": "generator (MG1) speed (end of its map)",
    "battery_power": "battery power (OCV^2/4R)",
    "battery_discharge_current": "battery discharge current",
    "battery_charge_current": "battery charge current",
    "genset_power": "genset power (at its maximum)",
}
"""Human names of the power-flow limit flags."""


@dataclass
class PerformanceResult:
    """Performance table (test, value, unit, binding limit) and the acceleration runs."""

    table: pd.DataFrame
    runs: dict[str, pd.DataFrame]
    metadata: dict[str, Any] = field(default_factory=dict)

    def value(self, test: str) -> float:
        """Value of ``test`` (in its unit)."""
        return float(self.table.set_index("test")["value"][test])

    def binding(self, test: str) -> str:
        """Binding limit of ``test``."""
        return str(self.table.set_index("test").loc[test, "binding_limit"])

    def format(self) -> str:
        """The table as aligned text."""
        lines = [f"{'test':<26}{'value':>10}  {'unit':<6} binding limit"]
        for row in self.table.itertuples():
            lines.append(f"{row.test:<26}{row.value:>10.4g}  {row.unit:<6} {row.binding_limit}")
        return "\n".join(lines)

    def save(self, out_dir: str | Path, plots: bool = True) -> Path:
        """Write performance.csv, performance.md, the acceleration runs (CSV) and, with
        ``plots``, speed_power.png, atomically."""
        from hevsim.io import atomic_directory, write_json

        with atomic_directory(out_dir) as tmp:
            self.table.to_csv(tmp / "performance.csv", index=False)
            (tmp / "performance.md").write_text("```\n" + self.format() + "\n```\n", encoding="utf-8")
            write_json(tmp / "metadata.json", self.metadata)
            for name, ts in self.runs.items():
                ts.to_csv(tmp / f"{name}.csv", index=False, float_format="%.6g")
            if plots:
                plot_speed_power(self.runs, tmp / "speed_power.png")
        return Path(out_dir)


def plot_speed_power(runs: dict[str, pd.DataFrame], path: Path) -> Path:
    """Speed [mph] and wheel power [kW] against time of the acceleration runs."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from hevsim.io import save_png

    fig, (ax1, ax2) = plt.subplots(2, 1, sharex=True, figsize=(7, 6))
    for name, ts in runs.items():
        ax1.plot(ts["time_s"], ts["speed_mph"], label=name)
        ax2.plot(ts["time_s"], ts["wheel_power_w"] / 1e3, label=name)
    ax1.set_ylabel("speed [mph]")
    ax2.set_ylabel("wheel power [kW]")
    ax2.set_xlabel("time [s]")
    ax1.legend()
    ax1.grid(True)
    ax2.grid(True)
    fig.tight_layout()
    save_png(fig, path, 100)
    plt.close(fig)
    return path


@dataclass(frozen=True)
class Adhesion:
    """Tire-road adhesion limit of the tractive force.

    ``friction_coefficient`` [-] (peak), ``driven_axle`` ("front" | "rear" | "all"), the body
    (mass, CG height and axle distances) and the tire radius [m].
    """

    friction_coefficient: float
    driven_axle: str
    body: VehicleBody
    radius_m: float

    @classmethod
    def of(cls, cfg: Any, body: VehicleBody, radius_m: float) -> Adhesion:
        """The limit of a vehicle configuration; a rear-wheel-drive car whose front wheels
        would lift before its rear tires slip (``mu h >= front_axle_to_cg_m + rear_axle_to_cg_m``,
        no adhesion limit left) raises ConfigError."""
        mu, axle = float(cfg.tire.friction_coefficient), str(cfg.tire.driven_axle)
        wheelbase = body.front_axle_to_cg_m + body.rear_axle_to_cg_m
        if wheelbase <= 0.0 or (axle == "rear" and mu * body.cg_height_m >= wheelbase):
            raise ConfigError(
                f"{cfg.name}: keys 'tire.friction_coefficient' = {mu:g}, 'body.cg_height_m' = "
                f"{body.cg_height_m:g}, wheelbase 'body.front_axle_to_cg_m' + 'body.rear_axle_to_cg_m'"
                f" = {wheelbase:g} m: expected a wheelbase > 0 and, for driven_axle = 'rear', "
                "friction_coefficient x cg_height_m < wheelbase (else the car wheelies)."
            )
        return cls(mu, axle, body, radius_m)

    def max_force_n(self, v_mps: float, accel_mps2: float, grade: float) -> float:
        """Largest tractive force [N] the driven tires carry at speed [m/s], acceleration
        [m/s^2] and grade [-]."""
        b = self.body
        fzf, fzr = (float(x) * b.wheels_per_axle for x in b.axle_normal_loads(accel_mps2, v_mps, grade))
        normal = {"front": fzf, "rear": fzr, "all": fzf + fzr}[self.driven_axle]
        return self.friction_coefficient * max(normal, 0.0)

    def allows(self, step: Any, grade: float) -> bool:
        """Whether the tires carry the wheel force of ``step`` (a :class:`Step`) on ``grade``."""
        force = step.wheel_torque_nm / self.radius_m
        if force <= 0.0:
            return True
        b = self.body
        accel = (force - float(b.road_load_force(step.v_mid_mps, 0.0, grade))) / (b.mass_kg * b.mass_factor)
        return force <= self.max_force_n(step.v_mid_mps, accel, grade) * (1.0 + 1e-12)


class _Capability:
    """Chooses any candidate that can give the demand (the powertrain's envelope) within the
    tire adhesion limit (``adhesion``, on ``grade`` [-]; None: no limit)."""

    name = "capability"

    def __init__(self, controls: tuple[np.ndarray, ...], adhesion: Adhesion | None = None,
                 grade: float = 0.0) -> None:  # fmt: skip
        self.controls = controls
        self.adhesion = adhesion
        self.grade = grade

    def reset(self, soc_initial: float) -> None:
        """Nothing to reset."""

    def update(self, step: Any, stage: Any) -> None:
        """Nothing to remember."""

    def choose(self, step: Any) -> tuple[float, ...] | None:
        """The first feasible candidate (None if none, or beyond the tires' adhesion)."""
        if self.adhesion is not None and not self.adhesion.allows(step, self.grade):
            return None
        _, feasible = step.evaluate(*self.controls)
        ok = np.flatnonzero(np.ravel(feasible))
        if ok.size == 0:
            return None
        return tuple(float(np.ravel(c)[ok[0]]) for c in self.controls)


def _step(model: Any, mod: Any, v0: float, v1: float, grade: float, dt: float, soc: float) -> Step:
    body, r = model.body, model.tire.radius_m
    v_mid = 0.5 * (v0 + v1)
    f = float(body.road_load_force(v_mid, (v1 - v0) / dt, grade)) if v_mid > 0 else 0.0
    battery: Any = getattr(model, "battery", None)
    bs, e_soc = None, 1.0
    if battery is not None:
        bs = _battery_state(model, soc, 1.0)
        e_soc = battery.capacity_ah * 3600.0 * float(np.asarray(bs.ocv_v))
    return Step(model, mod.power_flow, 0, 0.0, dt, v_mid, v_mid / r, f * r, soc, e_soc, bs, 0.0)


def _binding(lo_ctl: _Capability, lo: Step, hi_ctl: _Capability, hi: Step) -> str:
    """The limit flags that stop, at ``hi`` (grade of ``hi_ctl``), the candidates feasible at
    ``lo`` (grade of ``lo_ctl``); tire adhesion first, as it stops them all."""
    adhesion, controls = hi_ctl.adhesion, hi_ctl.controls
    if adhesion is not None and adhesion.allows(lo, lo_ctl.grade) and not adhesion.allows(hi, hi_ctl.grade):
        return LIMIT_NAMES["traction"]
    _, ok_lo = lo.evaluate(*controls)
    st, _ = hi.evaluate(*controls)
    was = np.ravel(ok_lo)
    hits: Counter[str] = Counter()
    for name, flag in st.flags.items():
        n = int(np.count_nonzero(np.ravel(np.broadcast_to(flag, np.shape(ok_lo)))[was]))
        if n:
            hits[name] = n
    if not hits:
        return "none found"
    return ", ".join(LIMIT_NAMES.get(n, n) for n, _ in hits.most_common(2))


def _steady_limit(model: Any, mod: Any, cap: _Capability, what: str, speed: float, soc: float,
                  dt: float) -> tuple[float, str]:  # fmt: skip
    """Largest speed [m/s] (``what = "speed"``) or grade [-] (``"grade"``) held steady."""

    def ctl(x: float) -> _Capability:
        return _Capability(cap.controls, cap.adhesion, x if what == "grade" else 0.0)

    def mk(x: float) -> Step:
        if what == "speed":  # still able to accelerate a little: the top speed is a powertrain limit
            return _step(model, mod, x, x + TOP_SPEED_ACCEL_MPS2 * dt, 0.0, dt, soc)
        return _step(model, mod, speed, speed, x, dt, soc)

    def ok(x: float) -> bool:
        return ctl(x).choose(mk(x)) is not None

    lo, hi = 0.0, (WALL_SPEED_MPS if what == "speed" else 1.0)
    if ok(hi):
        return hi, "none within the search range"
    for _ in range(BISECTION_STEPS):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if ok(mid) else (lo, mid)
    x_hi = hi + max(1e-6, 1e-3 * hi)
    return lo, _binding(ctl(lo), mk(lo), ctl(x_hi), mk(x_hi))


def _time_to(ts: pd.DataFrame, column: str, target: float) -> float:
    t, x = ts["time_s"].to_numpy(), ts[column].to_numpy()
    i = np.flatnonzero(x >= target)
    if i.size == 0:
        return float("nan")
    j = int(i[0])
    if j == 0:
        return float(t[0])
    return float(t[j - 1] + (target - x[j - 1]) / (x[j] - x[j - 1]) * (t[j] - t[j - 1]))


def _run_binding(model: Any, mod: Any, ctl: _Capability, ts: pd.DataFrame, dt: float, soc: float,
                 t_from: float, t_to: float) -> str:  # fmt: skip
    t, v, socs = (ts[c].to_numpy() for c in ("time_s", "speed_mps", "soc"))
    names: Counter[str] = Counter()
    for k in np.flatnonzero((t[:-1] >= t_from - 1e-9) & (t[:-1] < t_to)).tolist():
        lo = _step(model, mod, v[k], v[k + 1], 0.0, dt, socs[k])
        hi = _step(model, mod, v[k], v[k + 1] + 1e-3, 0.0, dt, socs[k])
        names[_binding(ctl, lo, ctl, hi)] += 1
    return names.most_common(1)[0][0] if names else "none found"


def performance(
    model: Any,
    *,
    dt_s: float = 0.2,
    soc: float | None = None,
    grade_speed_mps: float = 30.0 * MPS_PER_MPH,
    duration_s: float = 40.0,
) -> PerformanceResult:
    """Performance tests of a vehicle (file path, configuration or built model).

    ``dt_s`` [s]: step of the acceleration runs; ``soc`` [-]: battery SOC (default the
    configuration's initial SOC; held for the steady tests); ``grade_speed_mps`` [m/s]: speed
    of the gradeability test; ``duration_s`` [s]: length of the standing-start run.
    """
    from hevsim.architectures import architecture
    from hevsim.config import load_vehicle_config

    if isinstance(model, str | Path):
        model = load_vehicle_config(model)
    cfg = getattr(model, "config", model)
    arch = architecture(cfg.architecture)
    if not hasattr(arch.power_module(), "capability_controls"):
        from hevsim.architectures import ARCHITECTURES

        have = [n for n, a in ARCHITECTURES.items() if hasattr(a.power_module(), "capability_controls")]
        raise ConfigError(
            f"{cfg.name}: key 'powertrain.architecture' = {cfg.architecture!r} has no performance "
            f"envelope yet; the performance tests run for: {', '.join(have)}."
        )
    if model is cfg:
        model = arch.build(cfg)
    mod = arch.power_module()
    if hasattr(mod, "quasi_static_model"):  # series: the motor's rotor inertia in the effective mass
        model = mod.quasi_static_model(model)
    cap = _Capability(mod.capability_controls(model), Adhesion.of(cfg, model.body, model.tire.radius_m))
    soc0 = float(cfg.simulation.soc_initial if soc is None else soc)
    n = round(duration_s / dt_s)
    t = np.arange(n + 1, dtype=np.float64) * dt_s
    rows: list[dict[str, Any]] = []
    runs: dict[str, pd.DataFrame] = {}

    def run(name: str, v_start: float, t_end: float) -> pd.DataFrame:
        m = round(t_end / dt_s)
        tt = t[: m + 1]
        cyc = DriveCycle(name, tt, np.where(tt > 0, WALL_SPEED_MPS, v_start).astype(np.float64))
        res = simulate_architecture(cfg.architecture, model, cyc, dt_s=dt_s, soc_initial=soc0,
                                    controller=cap)  # fmt: skip
        ts = res.timeseries
        v = ts["speed_mps"].to_numpy()
        ts["distance_m"] = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * dt_s)])
        runs[name] = ts
        return ts

    def add(test: str, value: float, unit: str, binding: str) -> None:
        rows.append({"test": test, "value": value, "unit": unit, "binding_limit": binding})

    ts = run("standing_start", 0.0, duration_s)
    for test, target in (("0-60 mph", 60.0 * MPS_PER_MPH), ("0-100 km/h", KMH_100_MPS)):
        tt = _time_to(ts, "speed_mps", target)
        add(
            test,
            tt,
            "s",
            _run_binding(model, mod, cap, ts, dt_s, soc0, 0.0, tt) if np.isfinite(tt) else "not reached",
        )
    tq = _time_to(ts, "distance_m", QUARTER_MILE_M)
    add(
        "quarter mile",
        tq,
        "s",
        _run_binding(model, mod, cap, ts, dt_s, soc0, 0.0, tq) if np.isfinite(tq) else "not reached",
    )
    v_q = (
        float(np.interp(tq, ts["time_s"], ts["speed_mps"])) / MPS_PER_MPH if np.isfinite(tq) else float("nan")
    )
    add("quarter mile trap speed", v_q, "mph", "")
    ts2 = run("passing_50_80_mph", 50.0 * MPS_PER_MPH, duration_s)
    tp = _time_to(ts2, "speed_mps", 80.0 * MPS_PER_MPH)
    add(
        "50-80 mph",
        tp,
        "s",
        _run_binding(model, mod, cap, ts2, dt_s, soc0, 0.0, tp) if np.isfinite(tp) else "not reached",
    )
    v_top, why = _steady_limit(model, mod, cap, "speed", 0.0, soc0, dt_s)
    add("top speed", v_top / MPS_PER_MPH, "mph", why)
    g_max, why = _steady_limit(model, mod, cap, "grade", grade_speed_mps, soc0, dt_s)
    add(f"gradeability at {grade_speed_mps / MPS_PER_MPH:.0f} mph", 100.0 * g_max, "%", why)
    meta = {"config": cfg.name, "architecture": cfg.architecture, "dt_s": dt_s, "soc": soc0,
            "grade_speed_mps": grade_speed_mps}  # fmt: skip
    return PerformanceResult(pd.DataFrame(rows), runs, meta)


ENVELOPE_DT_S = 1.0
"""Step [s] of the power flow when the wheel-force envelope is evaluated (sets the SOC change
per step only; the limits are powers, torques and currents)."""
ENVELOPE_BISECTION_STEPS = 40
"""Bisection steps on the wheel force of :func:`wheel_force_envelope` [-]."""


@dataclass
class Envelope:
    """The powertrain's largest wheel force at each speed (no tire limit).

    Attributes: speed_mps [m/s], force_n [N] (largest feasible wheel force; 0 where none),
    the model the flow ran on (``model``, series: :func:`quasi_static_model`'s), its power
    module (``module``), the candidate controls (flat arrays, :func:`capability_controls`)
    and the SOC [-] it holds.
    """

    speed_mps: np.ndarray
    force_n: np.ndarray
    model: Any
    module: Any
    controls: tuple[np.ndarray, ...]
    soc: float

    def step(self, v_mid_mps: Any, wheel_force_n: Any, dt_s: Any) -> Step:
        """A :class:`Step` for arrays of mid speeds [m/s], wheel forces [N] and steps [s]
        (broadcast together); its ``evaluate`` broadcasts them against the candidates."""
        model = self.model
        r = model.tire.radius_m
        battery: Any = getattr(model, "battery", None)
        bs, e_soc = None, 1.0
        if battery is not None:
            bs = _battery_state(model, self.soc, 1.0)
            e_soc = battery.capacity_ah * 3600.0 * float(np.asarray(bs.ocv_v))
        v = np.asarray(v_mid_mps, np.float64)
        return Step(model, self.module.power_flow, 0, 0.0, dt_s, v, v / r,  # type: ignore[arg-type]
                    np.asarray(wheel_force_n, np.float64) * r, self.soc, e_soc, bs, 0.0)  # fmt: skip


def wheel_force_envelope(
    model: Any, speeds_mps: np.ndarray, soc: float | None = None, battery_power_max_w: float = np.inf
) -> Envelope:
    """Largest wheel force [N] the powertrain of ``model`` (file, configuration or built
    model) gives at each speed of ``speeds_mps`` [m/s > 0], over the same candidate controls
    as the performance tests (every gear, full throttle included): a bisection on the wheel
    force of the architecture's power flow, vectorised over speeds x candidates. With
    ``battery_power_max_w`` [W] only the candidates whose battery chemical power (``-dSOC x
    Q x OCV / dt``) stays at or below it count (a deployment limit)."""
    from hevsim.architectures import architecture
    from hevsim.config import load_vehicle_config

    if isinstance(model, str | Path):
        model = load_vehicle_config(model)
    cfg = getattr(model, "config", model)
    arch = architecture(cfg.architecture)
    mod = arch.power_module()
    if not hasattr(mod, "capability_controls"):
        raise ConfigError(
            f"{cfg.name}: key 'powertrain.architecture' = {cfg.architecture!r} has no performance "
            "envelope yet."
        )
    if model is cfg:
        model = arch.build(cfg)
    if hasattr(mod, "quasi_static_model"):
        model = mod.quasi_static_model(model)
    soc0 = float(cfg.simulation.soc_initial if soc is None else soc)
    controls = tuple(np.ravel(np.asarray(c, np.float64)) for c in mod.capability_controls(model))
    env = Envelope(np.asarray(speeds_mps, np.float64), np.zeros(len(speeds_mps)), model, mod, controls, soc0)
    v = env.speed_mps[:, None]
    ctl = tuple(c[None, :] for c in controls)
    weight = model.body.mass_kg * 9.80665

    def feasible(force: np.ndarray) -> np.ndarray:
        step = env.step(v, force[:, None], ENVELOPE_DT_S)
        st, ok = step.evaluate(*ctl)
        if np.isfinite(battery_power_max_w):
            p_batt = -np.asarray(st.d_soc) * step.energy_per_soc_j / ENVELOPE_DT_S
            ok = ok & (p_batt <= battery_power_max_w * (1.0 + 1e-9) + 1e-6)
        return np.asarray(np.asarray(ok).reshape(v.shape[0], -1).any(axis=1), bool)

    lo = np.zeros(v.shape[0])
    hi = np.full(v.shape[0], 4.0 * weight)
    ok0 = feasible(lo)
    for _ in range(ENVELOPE_BISECTION_STEPS):
        mid = 0.5 * (lo + hi)
        good = feasible(mid)
        lo = np.where(good, mid, lo)
        hi = np.where(good, hi, mid)
    env.force_n = np.where(ok0, lo, 0.0)
    return env
