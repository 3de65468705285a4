"""Supervisory controllers of the forward simulator, looked up by name in one registry.

A controller is one more named role of the forward loop (:mod:`hevsim.sim.forward`): at every
step it receives a :class:`~hevsim.sim.forward.Step` (the wheel demand, the state, and
``step.evaluate(controls)``, the architecture's vectorised power flow over any candidate
controls) and returns the control to apply, or None when no candidate is feasible. Every
controller has the same signature::

    controller.reset(soc_initial)            # before a run
    controller.choose(step) -> control | None
    controller.update(step, stage)           # after the step (state of adaptive controllers)

:data:`CONTROLLERS` maps ``[controller] kind`` to a factory and the configuration keys it
reads; which kinds an architecture admits is in :data:`hevsim.architectures.ARCHITECTURES`.
The series HEV's controllers (thermostat, schedule) live in its compiled kernel
(:mod:`hevsim.sim.kernel`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from hevsim.config import CONTROLLER_KEYS
from hevsim.errors import ConfigError

__all__ = ["CONTROLLERS", "ControllerEntry", "make_controller"]


@dataclass(frozen=True)
class ControllerEntry:
    """A controller kind: ``factory(model, controller_section, **overrides)`` and the
    ``[controller]`` keys it reads (``parameters``)."""

    name: str
    factory: str
    parameters: tuple[str, ...]
    description: str


CONTROLLERS: dict[str, ControllerEntry] = {
    "electric_assist": ControllerEntry(
        "electric_assist", "hevsim.control.parallel:ElectricAssist",
        CONTROLLER_KEYS["electric_assist"],
        "rule-based: EV at low speed and power, engine load-following with machine assist",
    ),
    "ecms": ControllerEntry(
        "ecms", "hevsim.control.parallel:ECMS", CONTROLLER_KEYS["ecms"],
        "ECMS: minimise fuel power + s x battery chemical power over the admissible controls",
    ),
    "aecms": ControllerEntry(
        "aecms", "hevsim.control.parallel:AdaptiveECMS",
        CONTROLLER_KEYS["aecms"],
        "adaptive ECMS: s corrected by a PI loop on the SOC error",
    ),
    "shift_schedule": ControllerEntry(
        "shift_schedule", "hevsim.control.simple:ShiftSchedule", CONTROLLER_KEYS["shift_schedule"],
        "conventional: automatic gearbox shift schedule with kick-down",
    ),
    "power_follower": ControllerEntry(
        "power_follower", "hevsim.control.parallel:PowerFollower",
        CONTROLLER_KEYS["power_follower"],
        "power split, rule-based: EV at low load, else the engine's most efficient point at the demand",
    ),
    "direct": ControllerEntry(
        "direct", "hevsim.control.simple:Direct", CONTROLLER_KEYS["direct"],
        "BEV: the machine meets the demand",
    ),
    "load_follower": ControllerEntry(
        "load_follower", "hevsim.control.simple:LoadFollower", CONTROLLER_KEYS["load_follower"],
        "fuel-cell vehicle: the fuel cell follows the bus load with a SOC correction, within its ramp limits",
    ),
}  # fmt: skip
"""Online controllers by ``[controller] kind``."""


def make_controller(model: Any, kind: str | None = None, **overrides: Any) -> Any:
    """The controller ``kind`` (default: the configuration's) for a built vehicle model.

    ``overrides`` replace ``[controller]`` values (e.g. ``equivalence_factor=2.7``); an
    unknown kind, one the architecture does not admit, or an unknown parameter is a
    ConfigError naming the valid ones.
    """
    import importlib

    from hevsim.architectures import architecture

    cfg = model.config
    kind = kind or cfg.controller.kind
    arch = architecture(cfg.architecture, cfg.name)
    if kind not in arch.controllers or kind not in CONTROLLERS:
        raise ConfigError(
            f"{cfg.name}: key 'controller.kind' = {kind!r} is not defined for the {arch.name} "
            f"architecture; expected one of {', '.join(arch.controllers)}."
        )
    entry = CONTROLLERS[kind]
    unknown = sorted(set(overrides) - set(entry.parameters))
    if unknown:
        raise ConfigError(
            f"controller {kind!r}: parameter(s) {', '.join(unknown)} not known; it reads "
            f"{', '.join(entry.parameters)}."
        )
    params = {name: overrides.get(name, getattr(cfg.controller, name)) for name in entry.parameters}
    module, _, name = entry.factory.partition(":")
    return getattr(importlib.import_module(module), name)(model, **params)
