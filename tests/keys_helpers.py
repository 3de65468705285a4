"""Helpers of tests/test_keys_*.py: perturb every key of a shipped example, one at a time, and
tell whether the key changes a short run or is refused as doing nothing."""

from __future__ import annotations

import dataclasses
import math
import tomllib
from pathlib import Path
from typing import Any

import numpy as np

from hevsim import config as C
from hevsim import schema
from hevsim.cycles import DriveCycle, load_cycle
from hevsim.errors import ConfigError, HevsimError, SimulationError

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
SHIPPED = (
    "series_hev", "parallel_hev", "high_performance_parallel_hev", "prius_2016_like_power_split",
    "prius_like_power_split", "conventional_sedan", "bev",
)  # fmt: skip
"""Every architecture's shipped example (issue 26, item 2)."""

SHORT_S = 200.0
"""Length of the short cycle [s]: the first 200 s of UDDS (launches, cruising, a stop)."""

FREE_STRINGS: dict[str, tuple[str, ...]] = {
    "engine.data": ("geo_1p0_si41", "saturn_1p9_dohc_si95"),
    "motor.data": ("westinghouse_ac75", "honda_pm49", "prius_1998_mg2_pm30"),
    "generator.data": ("prius_1998_mg1_gen15", "honda_pm49"),
    "battery.data": ("saft_li_ion_6ah_li7", "nimh_spiral_6ah_insight_prius_nimh6"),
    "fuel.name": ("gasoline", "diesel", "e85"),
    "controller.schedule": ("genset_schedule.csv",),
    "battery.pack": ("pack.toml",),
}
"""Alternative values of keys that name shipped data (tried in order)."""


BINDING: dict[str, Any] = {
    "battery.soc_min": lambda cfg: [cfg.simulation.soc_initial + d for d in (-1e-4, -1e-2)],
    "battery.soc_max": lambda cfg: [cfg.simulation.soc_initial + d for d in (1e-3, 1e-2, -1e-2)],
    "engine.redline_rpm": lambda cfg: [0.5 * (cfg.engine.stall_speed_rpm + cfg.controller.upshift_rpm)],
    "controller.engine_min_power_w": lambda cfg: [15000.0],
}
"""Values that make a limit bind within a short run, tried first: the SOC window's ends at
the initial SOC (the first discharge reaches the lower one; the upper one below it stops any
charging), the redline below the upshift speed, a power-split engine floor above the light
loads it otherwise runs at."""


def scenario(cfg: Any, key: str) -> dict[str, Any]:
    """Dotted overrides applied to the base and the perturbed file alike so that ``key`` can
    act in a short run: a controller key the file's kind does not read runs the admitted kind
    that reads it (``--controller`` would); the series thermostat's keys start with the SOC
    below ``soc_low`` (the engine starts at once); the parallel rule's shift speeds with no EV
    speed band (the engine drives from standstill)."""
    from hevsim.architectures import ARCHITECTURES
    from hevsim.control import CONTROLLERS

    sec, _, name = key.partition(".")
    arch = cfg.architecture
    if key in ("battery.soc_min", "battery.soc_max"):
        if arch == "series":  # the genset charges from just below soc_low
            return {"simulation.soc_initial": cfg.controller.soc_low - 0.005}
        if arch == "parallel":  # the DP's SOC settings stay inside a changed window
            soc0 = cfg.simulation.soc_initial
            return {"optimization.final_soc": "sustain", "optimization.soc_initial": soc0}
        return {}
    if sec != "controller":
        return {}
    if arch == "series" and name not in C.SERIES_CONTROLLER_KEYS.get(cfg.controller.kind, ()):
        for kind in C.SERIES_ONLINE_CONTROLLERS:  # a key of its online controllers: run one
            if name in CONTROLLERS[kind].parameters:
                return {"controller.kind": kind}
    if arch == "series":  # the genset starts at once; its cranking, at a step that resolves it
        fine = {"simulation.dt_s": 0.02} if name == "start_speed_rpm" else {}
        return {"simulation.soc_initial": cfg.controller.soc_low - 0.005, **fine}
    out: dict[str, Any] = {}
    entry = CONTROLLERS.get(cfg.controller.kind)
    if entry is not None and name not in entry.parameters:
        for kind in ARCHITECTURES[arch].controllers:
            if name in CONTROLLERS[kind].parameters:
                out["controller.kind"] = kind
                break
    if name in ("upshift_rpm", "downshift_rpm") and arch == "parallel":  # the engine drives
        out.update({"controller.ev_speed_mps": 0.0, "controller.ev_power_w": 0.0})
        out["controller.soc_high"] = 0.99
    return out


def short_cycle(name: str = "udds", seconds: float = SHORT_S) -> DriveCycle:
    """The first ``seconds`` of cycle ``name``."""
    c = load_cycle(name)
    keep = np.asarray(c.time_s) <= seconds
    return DriveCycle(f"{name}{seconds:g}", np.asarray(c.time_s)[keep], np.asarray(c.speed_mps)[keep])


def sawtooth() -> DriveCycle:
    """200 s between 8 and 25 m/s without stopping (shifts down and up again), then a stop."""
    t = np.arange(0.0, 201.0)
    v = 16.5 - 8.5 * np.cos(2 * np.pi * t / 50.0)
    v[0], v[-1] = 0.0, 0.0
    return DriveCycle("sawtooth", t, np.minimum(v, 2.0 * t))


def downhill() -> DriveCycle:
    """200 s at 15 m/s down a 6 % grade (regeneration charges the battery)."""
    t = np.arange(0.0, 201.0)
    return DriveCycle("downhill", t, np.minimum(15.0, 2.0 * t), -0.06 * np.ones_like(t))


CYCLES = (lambda: short_cycle("udds", SHORT_S), lambda: short_cycle("us06", 300.0), sawtooth, downhill)
"""The short cycles a key is tried on, in turn: a limit (a current, the redline, a torque
rating, the SOC window) acts only where the car reaches it, so a key with no effect on the
first 200 s of UDDS is tried again on the first 300 s of US06 (hard launches, 129 km/h), a
speed sawtooth without stops and a downhill run."""


def example_data(name: str) -> dict[str, Any]:
    """The parsed TOML of a shipped example (``name`` defaults to the stem, as on load)."""
    data = tomllib.loads((EXAMPLES / f"{name}.toml").read_text(encoding="utf-8"))
    data.setdefault("name", name)
    return data


def candidates(key: str, value: Any, f: dataclasses.Field[Any], tp: Any) -> list[Any]:
    """Valid values of ``key`` other than ``value``, the nearest first."""
    meta = f.metadata
    if key in FREE_STRINGS:
        return [v for v in FREE_STRINGS[key] if v != value]
    if "choices" in meta:
        return [c for c in meta["choices"] if c != value]
    if isinstance(value, tuple):
        return [tuple(v * s for v in value) for s in (1.05, 0.95)]
    if isinstance(value, str):
        return []
    lo, hi = meta.get("bounds", (-math.inf, math.inf))
    if isinstance(value, int) and not isinstance(value, bool):
        out = [value + 1, value - 1, value + 10, value * 2]
    elif math.isinf(value):
        out = [100.0, 300.0, 1000.0]
    elif value == 0.0:
        out = [0.05 * min(hi, 1.0), 1.0, 10.0, 100.0, 300.0]
    else:
        out = [value * 1.1, value * 0.9, value * 1.5, value * 0.5, value * 3.0]
    if isinstance(value, float) and math.isfinite(value):  # limits act only when they bind: extremes
        top = min(hi, 1e3 * max(abs(value), 1.0))
        out += [value + 0.9 * (top - value), lo + 0.1 * (value - lo), lo + 1e-3 * (value - lo)]
    return [v for v in out if lo <= v <= hi and v != value]


def section_keys(cls: type) -> list[tuple[str, dataclasses.Field[Any], Any]]:
    """(dotted key, field, type) of every key of every section of configuration class ``cls``."""
    out = []
    for f in dataclasses.fields(cls):
        tp = schema.type_hints(cls)[f.name]
        if isinstance(tp, type) and dataclasses.is_dataclass(tp):
            hints = schema.type_hints(tp)
            out.extend((f"{f.name}.{g.name}", g, hints[g.name]) for g in dataclasses.fields(tp))
    return out


def current(cfg: Any, key: str) -> Any:
    sec, _, name = key.partition(".")
    return getattr(getattr(cfg, sec), name)


def load(data: dict[str, Any], name: str) -> Any:
    """The configuration of a parsed file, exactly as ``hevsim simulate`` loads it."""
    return C.config_from_dict(data, source=f"{name}.toml", base_dir=EXAMPLES)


def with_key(data: dict[str, Any], key: str, value: Any) -> dict[str, Any]:
    out = {k: dict(v) if isinstance(v, dict) else v for k, v in data.items()}
    sec, _, name = key.partition(".")
    out.setdefault(sec, {})[name] = list(value) if isinstance(value, tuple) else value
    return out


def fingerprint(res: Any) -> tuple[np.ndarray, np.ndarray]:
    """(metric values, numeric time-series values) of a run."""
    metrics = np.array(
        [float(m["value"]) for m in res.metrics.values() if isinstance(m["value"], int | float)]
    )
    ts = res.timeseries.select_dtypes(include=[np.number, bool]).to_numpy(dtype=float)
    return metrics, ts


def differs(a: tuple[np.ndarray, np.ndarray], b: tuple[np.ndarray, np.ndarray]) -> bool:
    if a[0].shape != b[0].shape or a[1].shape != b[1].shape:
        return True
    return not (np.array_equal(a[0], b[0], equal_nan=True) and np.array_equal(a[1], b[1], equal_nan=True))


def run(cfg: Any, cycle: Any) -> Any:
    from hevsim.sim.simulator import simulate

    return simulate(cfg, cycle, tracking=None)


def _load_dropping(data: dict[str, Any], name: str, key: str) -> Any:
    """:func:`load`; a refusal of another key as doing nothing (the new value of ``key`` makes
    it inert, e.g. another machine model and its map folder) drops that key and tries again."""
    for _ in range(10):
        try:
            return load(data, name)
        except ConfigError as exc:
            other = str(exc).split("key '")[1].split("'")[0] if "does nothing" in str(exc) else None
            if other is None or other == key or "." not in other:
                raise
            sec, _, k = other.partition(".")
            data = {**data, sec: {kk: v for kk, v in data[sec].items() if kk != k}}
    return load(data, name)


def probe(name: str, keys: list[str] | None = None, skip: Any = None) -> dict[str, str]:
    """For every key of every section of example ``name`` (or only ``keys``):
    ``"refused: <message>"`` (a refusal naming the key as doing nothing), ``"changes"`` (some
    metric or time series changes on a cycle of :data:`CYCLES`), ``"no effect"`` or ``"no
    valid value"`` (no other value loads and runs). ``skip(key)`` true: not tried."""
    data = example_data(name)
    base_cfg = load(data, name)
    cycles = [make() for make in CYCLES]
    plain_bases: dict[int, Any] = {}  # fingerprints of the unmodified example, by cycle
    out: dict[str, str] = {}
    plain, plain_cfg = data, base_cfg
    for key, f, tp in section_keys(type(plain_cfg)):
        if (keys is not None and key not in keys) or (skip is not None and skip(key)):
            continue
        data, base_cfg, bases = plain, plain_cfg, plain_bases
        extra = scenario(plain_cfg, key)
        if extra:
            for k, v in extra.items():
                data = with_key(data, k, v)
            base_cfg, bases = load(data, name), {}
        value = current(base_cfg, key)
        verdict = "no valid value"
        cfgs = []
        near = BINDING[key](base_cfg) if key in BINDING else []
        for cand in near + candidates(key, value, f, tp):
            try:
                cfgs.append(_load_dropping(with_key(data, key, cand), name, key))
            except ConfigError as exc:
                if "does nothing" in str(exc) and f"key '{key}'" in str(exc):
                    verdict = f"refused: {exc}"
                    break
        if verdict.startswith("refused"):
            out[key] = verdict
            continue
        for j, cyc in enumerate(cycles):
            for cfg in cfgs:
                if j not in bases:
                    bases[j] = fingerprint(run(base_cfg, cyc))
                try:
                    res = run(cfg, cyc)
                except SimulationError:  # the unchanged file runs: the key stops the run
                    verdict = "changes"
                    break
                except HevsimError:
                    continue
                verdict = "changes" if differs(bases[j], fingerprint(res)) else "no effect"
                if verdict == "changes":
                    break
            if verdict == "changes":
                break
        out[key] = verdict
    return out
