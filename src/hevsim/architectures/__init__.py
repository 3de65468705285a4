"""Vehicle architectures: how the components connect and how power flows, in one registry.

Each architecture is a module here (:mod:`~hevsim.architectures.series`,
:mod:`~hevsim.architectures.parallel`, :mod:`~hevsim.architectures.conventional`,
:mod:`~hevsim.architectures.bev`, :mod:`~hevsim.architectures.power_split`,
:mod:`~hevsim.architectures.fcev`) and one
:class:`Architecture` entry in :data:`ARCHITECTURES`, the only place that says what a vehicle
file becomes: its builder, its control inputs, its forward simulation and its DP formulation
(:mod:`hevsim.optimal` looks it up here), with its configuration type, required sections and
admitted supervisory controllers read from the file schema :data:`hevsim.config.ARCHITECTURES`
(the ground layer: what a file may hold, not what it becomes). The power-flow function of an
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

__all__ = [
    "ARCHITECTURES", "Architecture", "architecture", "architecture_of", "build_vehicle", "check_controller",
    "register",
]  # fmt: skip


def _load(ref: str) -> Any:
    module, _, name = ref.partition(":")
    return getattr(importlib.import_module(module), name)


@dataclass(frozen=True)
class Architecture:
    """One registered architecture.

    Attributes:
        name: value of ``[powertrain] architecture``.
        module: the module holding its model and power flow.
        builder: ``"module:function"`` building the vehicle model from a configuration.
        controls: names of its control inputs (what a supervisory controller chooses).
        forward: ``"module:function"`` simulating a configuration or model forward,
            ``f(model, cycle, dt_s=..., soc_initial=..., ...) -> SimulationResult``.
        dp_formulation: ``"module:Class"`` of its DP problem (:mod:`hevsim.optimal`); empty
            when it has none (nothing to optimise: conventional, BEV).
    """

    name: str
    module: str
    builder: str
    controls: tuple[str, ...]
    forward: str
    dp_formulation: str

    @property
    def spec(self) -> Any:
        """Its :class:`hevsim.config.ArchitectureSpec` (config type, admitted controllers,
        required sections, cross-key checks)."""
        from hevsim.config import ARCHITECTURES as CONFIG_ARCHITECTURES

        return CONFIG_ARCHITECTURES[self.name]

    @property
    def config_type(self) -> type:
        """Its configuration class."""
        return self.spec.config_type

    @property
    def controllers(self) -> tuple[str, ...]:
        """The ``[controller] kind`` values it admits, the rule-based one first."""
        return tuple(self.spec.controllers)

    def build(self, cfg: Any) -> Any:
        """The vehicle model of a configuration (its ``builder``)."""
        return _load(self.builder)(cfg)

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
    name="series", module="hevsim.architectures.series",
    builder="hevsim.architectures.series:build_series_hev", controls=("genset_state", "engine_throttle"),
    forward="hevsim.sim.simulator:simulate",
    dp_formulation="hevsim.optimal._series_dp:SeriesFormulation",
))  # fmt: skip
register(Architecture(
    name="parallel", module="hevsim.architectures.parallel",
    builder="hevsim.architectures.parallel:build_parallel_hev", controls=("gear", "throttle"),
    forward="hevsim.sim.forward:simulate_parallel",
    dp_formulation="hevsim.optimal._parallel_dp:ParallelFormulation",
))  # fmt: skip


register(Architecture(
    name="conventional", module="hevsim.architectures.conventional",
    builder="hevsim.architectures.conventional:build_conventional", controls=("gear",),
    forward="hevsim.sim.forward:simulate_conventional", dp_formulation="",
))  # fmt: skip
register(Architecture(
    name="bev", module="hevsim.architectures.bev", builder="hevsim.architectures.bev:build_bev", controls=(),
    forward="hevsim.sim.forward:simulate_bev", dp_formulation="",
))  # fmt: skip


register(Architecture(
    name="power_split", module="hevsim.architectures.power_split",
    builder="hevsim.architectures.power_split:build_power_split", controls=("engine_speed_radps", "throttle"),
    forward="hevsim.sim.forward:simulate_power_split",
    dp_formulation="hevsim.optimal._power_split_dp:PowerSplitFormulation",
))  # fmt: skip


register(Architecture(
    name="fcev", module="hevsim.architectures.fcev", builder="hevsim.architectures.fcev:build_fcev",
    controls=("fuel_cell_power_w",), forward="hevsim.sim.forward:simulate_fcev",
    dp_formulation="hevsim.optimal._fcev_dp:FCEVFormulation",
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
    """ConfigError unless ``cfg.controller.kind`` is admitted by ``cfg``'s architecture (the
    check :func:`hevsim.config.load_vehicle_config` makes, for a configuration changed since)."""
    from hevsim.config import check_controller as check

    check(cfg, source)


def architecture_of(cfg: Any) -> Architecture:
    """The registered architecture of a configuration object (ConfigError naming the
    configuration types otherwise)."""
    from hevsim.config import architecture_of as spec_of

    return ARCHITECTURES[spec_of(cfg).name]


def build_vehicle(cfg: Any) -> Any:
    """Build the vehicle model of a configuration through its architecture's builder (formerly
    ``hevsim.config.build_vehicle``)."""
    return architecture_of(cfg).build(cfg)
