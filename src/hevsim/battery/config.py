"""Cell and module simulation configurations (TOML, validated through :mod:`hevsim.schema`).

Example: ``examples/cell.toml``; run with :func:`run_config`. Temperatures are in degrees
Celsius in the files (``temp_c``, ``port_temp_c``) and in kelvin inside (the ``temp_k`` and
``port_temp_k`` properties); a file with the former kelvin keys gets a message saying what to
rename.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hevsim.battery.cell import Cell, CellResult
from hevsim.battery.module import Module, ModuleResult
from hevsim.battery.params import load_cell_parameters
from hevsim.battery.profiles import cycle_cell_current
from hevsim.errors import ConfigError
from hevsim.schema import build_config, read_toml
from hevsim.tables import FloatArray
from hevsim.units import c_to_k

_TEMP_C = {"bounds": (-120.0, 225.0), "unit": "degC"}
"""Range of the cell temperatures [degC] (150 K to about 500 K)."""
RENAMED_KEYS = {"cell.temp_k": "cell.temp_c", "thermal.port_temp_k": "thermal.port_temp_c"}
"""Former kelvin keys and their Celsius replacements."""


@dataclass(frozen=True)
class CellSection:
    """Which parameter set (shipped name or a path relative to the config) and initial state."""

    parameters: str = "thesis_table_4_1"
    soc_initial: float = field(default=1.0, metadata={"bounds": (0.0, 1.0), "unit": "-"})
    temp_c: float = field(default=25.0, metadata=_TEMP_C)

    @property
    def temp_k(self) -> float:
        """Initial cell temperature [K]."""
        return c_to_k(self.temp_c)


@dataclass(frozen=True)
class ModuleSection:
    """Arrangement and cell-to-cell spread (n_series = n_parallel = 1: a single cell)."""

    n_series: int = 1
    n_parallel: int = 1
    capacity_spread: float = 0.0
    resistance_spread: float = 0.0
    seed: int = 0


@dataclass(frozen=True)
class ProfileSection:
    """Load: constant current [A] (``kind = "constant"``) or a drive cycle's road-load current."""

    kind: str = "constant"
    current_a: float = 1.0
    cycle: str = "udds"
    duration_s: float = 3600.0
    dt_s: float = 1.0
    scale: float = 1.0


@dataclass(frozen=True)
class ThermalSection:
    """Heat-port temperature [degC]."""

    port_temp_c: float = field(default=25.0, metadata=_TEMP_C)

    @property
    def port_temp_k(self) -> float:
        """Heat-port temperature [K]."""
        return c_to_k(self.port_temp_c)


@dataclass(frozen=True)
class CellConfig:
    """A cell or module simulation."""

    name: str
    base_dir: str = "."
    cell: CellSection = field(default_factory=CellSection)
    module: ModuleSection = field(default_factory=ModuleSection)
    profile: ProfileSection = field(default_factory=ProfileSection)
    thermal: ThermalSection = field(default_factory=ThermalSection)


_CHOICES = {"profile.kind": ("constant", "cycle")}
_BOUNDS = {
    "module.n_series": (1, 10_000),
    "module.n_parallel": (1, 10_000),
    "module.capacity_spread": (0.0, 0.3),
    "module.resistance_spread": (0.0, 0.3),
    "profile.duration_s": (1e-9, 1e9),
    "profile.dt_s": (1e-9, 1e6),
}


def load_config(path: str | Path) -> CellConfig:
    """Read and validate a cell/module configuration file."""
    p = Path(path)
    data = read_toml(p)
    for old, new in RENAMED_KEYS.items():
        sec, _, key = old.partition(".")
        if isinstance(data.get(sec), dict) and key in data[sec]:
            raise ConfigError(
                f"{p}: key '{old}' = {data[sec][key]!r}: temperatures are in degrees Celsius in files; "
                f"rename it to '{new}' (value - 273.15)."
            )
    return build_config(CellConfig, data, str(p), p.parent, _CHOICES, _BOUNDS)


def profile_current(cfg: CellConfig) -> FloatArray:
    """The configured current profile [A], one value per step."""
    pr = cfg.profile
    n = round(pr.duration_s / pr.dt_s)
    if n < 1:
        raise ConfigError(
            f"{cfg.name}: profile.duration_s {pr.duration_s} is shorter than one step {pr.dt_s}."
        )
    if pr.kind == "constant":
        return np.full(n, pr.current_a * pr.scale)
    return cycle_cell_current(pr.cycle, pr.duration_s, pr.dt_s) * pr.scale


def run_config(path: str | Path) -> CellResult | ModuleResult:
    """Simulate the configuration at ``path``: a :class:`Cell` for 1s1p, else a :class:`Module`."""
    cfg = load_config(path)
    src = cfg.cell.parameters
    candidate = Path(cfg.base_dir) / src
    params = load_cell_parameters(candidate if candidate.suffix == ".toml" else src)
    current = profile_current(cfg)
    m = cfg.module
    if m.n_series == 1 and m.n_parallel == 1:
        cell = Cell(params, cfg.cell.soc_initial, cfg.cell.temp_k)
        return cell.simulate(current, cfg.profile.dt_s, cfg.thermal.port_temp_k)
    mod = Module(
        params,
        m.n_series,
        m.n_parallel,
        cfg.cell.soc_initial,
        cfg.cell.temp_k,
        m.capacity_spread,
        m.resistance_spread,
        m.seed,
    )
    return mod.simulate(current, cfg.profile.dt_s, cfg.thermal.port_temp_k)
