"""Vehicle architectures: how the components connect and how power flows, in one registry.

Each architecture is a module here (:mod:`~hevsim.architectures.series`,
:mod:`~hevsim.architectures.parallel`, :mod:`~hevsim.architectures.conventional`,
:mod:`~hevsim.architectures.bev`) and one :class:`Architecture` entry in
:data:`ARCHITECTURES`, holding together its configuration type and builder (from
:data:`hevsim.config.ARCHITECTURES`), its control inputs, its forward simulation, its DP
formulation and the supervisory controllers it admits. The power-flow function of an
architecture is written once in its module and called by the forward simulator (one point
per step), by ECMS (the candidate controls of a step) and by the DP (the whole grid).

Everything is referenced by ``"module:name"`` and imported on use, so importing this package
loads no component code.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Any

from hevsim.errors import ConfigError

__all__ = ["ARCHITECTURES", "Architecture", "architecture", "check_controller", "register"]


def _load(ref: str) -> Any:
    module, _, name = ref.partition(":")
    return getattr(importlib.import_module(module), name)


@dataclass(frozen=True)
class Architecture:
    """One registered architecture.

    Attributes:
        name: value of ``[powertrain] architecture``.
        module: the module holding its model and power flow.
        controls: names of its control inputs (what a supervisory controller chooses).
        controllers: the ``[controller] kind`` values it admits, the rule-based one first.
        forward: ``"module:function"`` simulating a configuration or model forward,
            ``f(model, cycle, dt_s=..., soc_initial=..., ...) -> SimulationResult``.
        dp_formulation: ``"module:Class"`` of its DP problem (:mod:`hevsim.optimal`); empty
            when it has none (nothing to optimise: conventional, BEV).
    """

    name: str
    module: str
    controls: tuple[str, ...]
    controllers: tuple[str, ...]
    forward: str
    dp_formulation: str

    @property
    def spec(self) -> Any:
        """Its :class:`hevsim.config.ArchitectureSpec` (config type, builder, required sections)."""
        from hevsim.config import ARCHITECTURES as CONFIG_ARCHITECTURES

        return CONFIG_ARCHITECTURES[self.name]

    @property
    def config_type(self) -> type:
        """Its configuration class."""
        return self.spec.config_type

    def build(self, cfg: Any) -> Any:
        """The vehicle model of a configuration."""
        return self.spec.build(cfg)

    def simulate(self, model: Any, *args: Any, **kwargs: Any) -> Any:
        """Forward simulation (see ``forward``)."""
        return _load(self.forward)(model, *args, **kwargs)

    def formulation(self) -> type:
        """Its DP formulation class (ConfigError when it has none)."""
        if not self.dp_formulation:
            raise ConfigError(f"the {self.name} architecture has no DP formulation (no energy management).")
        return _load(self.dp_formulation)

    def power_module(self) -> Any:
        """The module with its model and power flow."""
        return importlib.import_module(self.module)


ARCHITECTURES: dict[str, Architecture] = {}
"""Registered architectures by name."""


def register(arch: Architecture) -> None:
    """Add (or replace) an architecture."""
    ARCHITECTURES[arch.name] = arch


register(Architecture(
    name="series", module="hevsim.architectures.series", controls=("genset_state", "engine_throttle"),
    controllers=("thermostat", "schedule"), forward="hevsim.sim.simulator:simulate",
    dp_formulation="hevsim.optimal._series_dp:SeriesFormulation",
))  # fmt: skip
register(Architecture(
    name="parallel", module="hevsim.architectures.parallel", controls=("gear", "throttle"),
    controllers=("electric_assist", "ecms", "aecms"), forward="hevsim.sim.forward:simulate_parallel",
    dp_formulation="hevsim.optimal._parallel_dp:ParallelFormulation",
))  # fmt: skip


register(Architecture(
    name="conventional", module="hevsim.architectures.conventional", controls=("gear",),
    controllers=("shift_schedule",), forward="hevsim.sim.forward:simulate_conventional", dp_formulation="",
))  # fmt: skip
register(Architecture(
    name="bev", module="hevsim.architectures.bev", controls=(), controllers=("direct",),
    forward="hevsim.sim.forward:simulate_bev", dp_formulation="",
))  # fmt: skip


register(Architecture(
    name="power_split", module="hevsim.architectures.power_split",
    controls=("engine_speed_radps", "throttle"),
    controllers=("power_follower", "ecms", "aecms"), forward="hevsim.sim.forward:simulate_power_split",
    dp_formulation="hevsim.optimal._power_split_dp:PowerSplitFormulation",
))  # fmt: skip


def architecture(name: str, source: str = "<config>") -> Architecture:
    """The registered architecture ``name``; ConfigError naming the valid ones otherwise."""
    arch = ARCHITECTURES.get(name)
    if arch is None:
        raise ConfigError(
            f"{source}: key 'powertrain.architecture' = {name!r} is not known; expected one of "
            f"{', '.join(ARCHITECTURES)}."
        )
    return arch


def check_controller(cfg: Any, source: str) -> None:
    """ConfigError unless ``cfg.controller.kind`` is admitted by ``cfg``'s architecture."""
    arch = ARCHITECTURES.get(cfg.architecture)
    kind = cfg.controller.kind
    if arch is not None and kind not in arch.controllers:
        raise ConfigError(
            f"{source}: key 'controller.kind' = {kind!r} is not defined for the {arch.name} "
            f"architecture; expected one of {', '.join(arch.controllers)}."
        )
