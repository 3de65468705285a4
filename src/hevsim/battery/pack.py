"""Battery pack: modules of electro-thermal cells, each module with its thermal ROM, on a cooling loop.

Arrangement: ``n_modules`` modules in series, each ``n_series`` groups in series of
``n_parallel`` cells (cell ``c = s * n_parallel + b`` of a module, as :class:`~hevsim.battery.module.Module`;
pack cell ``m * n_series * n_parallel + c``). Every cell is today's electro-thermal cell (thesis
eqs 33-41, :func:`hevsim.battery.kernel.cell_step`) with its own capacity and resistance
spread; parallel cells share the current exactly (:func:`hevsim.battery.kernel.share_current`).

Thermal coupling per step ``dt`` (as the co-simulated module of thesis section 4.3, without
the co-simulation): every cell's heat port sits at the temperature the module thermal model
gave at the end of the previous step, and the heat the cell passes through its port during the
step is the module's input for the step. ``[module] thermal``:

* ``"rom"``: the module's reduced-order model (:mod:`hevsim.thermal.rom`, built by
  ``hevsim rom build`` from the module's thermal configuration, whose mesh hash it must match):
  port temperature = the ROM's cell mean temperature; the fluid temperature per channel
  segment comes from the 1-D quasi-steady channel (:mod:`hevsim.thermal.coolant`, the same
  equations as the FEM case) at the plate's inlet temperature and flow, and the wall film from
  the plate's flow;
* ``"coolant"``: no module model: every cell's port is at its plate's coolant inlet
  temperature and its port heat goes straight into the coolant (the limit of an ideal plate).

The cooling loop is :class:`hevsim.battery.cooling.CoolingLoop`. The BMS derates the pack
current by a factor of the hottest cell temperature (``[derating]`` table, data; it must cover
the cell parameter set's temperature range), applied to ``pack.max_current_a`` in both
directions.

Energy bookkeeping (every term exact for the discrete steps; :meth:`PackResult.energy`):
electrical out + chemical change + RC energy change + heat stored (cell cores, modules, loop)
+ heat to the ambient (module housings, radiator, loop pipes) + heat removed by the chiller
(or taken by an ideal reservoir) - pump work = 0 up to rounding.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from hevsim.battery.cooling import ControllerSection, CoolingLoop, CoolingSection, LoopStep, check_cooling
from hevsim.battery.kernel import (
    C0,
    CHEAT,
    CTI0,
    HMAX,
    NRC,
    OCVSTEP,
    RCPERS,
    RSCALE,
    STEMP,
    VMAX,
    VMIN,
    rc_energy,
)
from hevsim.battery.pack_kernels import (  # noqa: F401 (re-exported)
    NO_REFCOUNT,
    pack_pairs,
    pack_pass,
    pack_pass_linear,
    pack_step,
    pack_thevenin,
    rc_constants,
)
from hevsim.errors import ConfigError
from hevsim.schema import build_config, read_toml
from hevsim.units import c_to_k

THERMAL_KINDS = ("rom", "coolant")
#: ``[module] cells``: every cell simulated, or one representative cell per module
CELL_MODES = ("all", "representative")
#: channels of one pack step (:meth:`Pack.step`), the columns of :attr:`PackResult.timeseries`
STEP_CHANNELS = (
    "time_s", "current_request_a", "current_a", "voltage_v", "voltage_avg_v", "power_w", "derating_factor",
    "hottest_cell_temp_k", "hot_spot_temp_k", "min_soc", "max_soc", "loop_temp_k", "supply_temp_k",
    "plate_heat_w", "module_ambient_w", "radiator_w", "chiller_w", "chiller_power_w", "pump_power_w",
    "fan_power_w",
)  # fmt: skip
#: energy terms accumulated by :meth:`Pack.step` [J]
ENERGY_TERMS = (
    "electrical_out_j", "chemical_change_j", "cell_heat_j", "port_heat_j", "plate_heat_j", "module_ambient_j",
    "radiator_j", "chiller_j", "loop_ambient_in_j", "pump_work_j", "reservoir_j", "throughput_j",
    "chiller_electric_j", "fan_electric_j",
)  # fmt: skip
_T = {"bounds": (-60.0, 150.0), "unit": "degC"}


@dataclass(frozen=True)
class CellsSection:
    """``[cells]``: parameter set (shipped name or path), initial SOC, spread (relative std)."""

    parameters: str = "thesis_table_4_1"
    soc_initial: float = field(default=0.9, metadata={"bounds": (0.0, 1.0), "unit": "-"})
    capacity_spread: float = field(default=0.0, metadata={"bounds": (0.0, 0.3), "unit": "-"})
    resistance_spread: float = field(default=0.0, metadata={"bounds": (0.0, 0.3), "unit": "-"})
    seed: int = 0
    #: the cells' rated operating range [degC] (datasheet; the derating table must cover it)
    min_temp_c: float = field(default=-30.0, metadata=_T)
    max_temp_c: float = field(default=60.0, metadata=_T)


@dataclass(frozen=True)
class ModuleSection:
    """``[module]``: cell arrangement, thermal model and simulated cells (module docstring):
    ``cells = "all"`` simulates every cell; ``"representative"`` one cell per module standing
    for all its ``n_series x n_parallel`` cells (no cell-to-cell spread)."""

    n_series: int = field(default=2, metadata={"bounds": (1, 1000)})
    n_parallel: int = field(default=6, metadata={"bounds": (1, 1000)})
    thermal: str = field(default="rom", metadata={"choices": THERMAL_KINDS})
    cells: str = field(default="all", metadata={"choices": CELL_MODES})
    rom_file: str = ""
    thermal_config: str = ""
    #: the module hot spots' screening slack [K]: each reported hot spot is within this of the
    #: maximum of the ROM's reconstructed field over every node of the module's cells (0: that
    #: maximum exactly, several times slower); added to the ROM's own hot-spot error estimate
    hot_spot_slack_k: float = field(default=0.01, metadata={"bounds": (0.0, 1.0), "unit": "K"})


@dataclass(frozen=True)
class PackSection:
    """``[pack]``: modules in series, initial and ambient temperatures, current limit, step."""

    n_modules: int = field(default=4, metadata={"bounds": (1, 10000)})
    initial_temp_c: float = field(default=25.0, metadata=_T)
    ambient_temp_c: float = field(default=25.0, metadata=_T)
    max_current_a: float = field(default=300.0, metadata={"bounds": (0.0, 1e5), "unit": "A"})
    dt_s: float = field(default=1.0, metadata={"bounds": (1e-3, 3600.0), "unit": "s"})


@dataclass(frozen=True)
class DeratingSection:
    """``[derating]``: current factor [-] over the hottest cell temperature [degC] (increasing,
    linear interpolation; must cover the cell parameter set's temperature range), and in the
    vehicle (:mod:`hevsim.battery.bms`) the discharge factor over the lowest cell SOC and the
    charge factor over the highest (``soc`` increasing from 0 to 1)."""

    temp_c: tuple[float, ...] = (-40.0, 0.0, 45.0, 55.0, 60.0, 100.0)
    current_factor: tuple[float, ...] = (0.2, 1.0, 1.0, 0.5, 0.0, 0.0)
    soc: tuple[float, ...] = (0.0, 0.05, 0.15, 0.85, 0.95, 1.0)
    discharge_soc_factor: tuple[float, ...] = (0.0, 0.2, 1.0, 1.0, 1.0, 1.0)
    charge_soc_factor: tuple[float, ...] = (1.0, 1.0, 1.0, 1.0, 0.2, 0.0)


@dataclass(frozen=True)
class PackConfig:
    """A validated pack (see ``examples/pack.toml``)."""

    name: str = "pack"
    base_dir: str = "."
    cells: CellsSection = field(default_factory=CellsSection)
    module: ModuleSection = field(default_factory=ModuleSection)
    pack: PackSection = field(default_factory=PackSection)
    cooling: CoolingSection = field(default_factory=CoolingSection)
    controller: ControllerSection = field(default_factory=ControllerSection)
    derating: DeratingSection = field(default_factory=DeratingSection)


def pack_config_from_dict(
    data: dict[str, Any], source: str = "<dict>", base_dir: Path | None = None
) -> PackConfig:
    """Validate a parsed pack TOML mapping (keys, types, ranges, the loop, the derating table's
    shape; the table's coverage of the cells is checked by :class:`Pack`)."""
    cfg = build_config(PackConfig, data, source, base_dir, {}, {})
    check_cooling(cfg.cooling, cfg.controller, source)
    d = cfg.derating
    t, f = np.asarray(d.temp_c), np.asarray(d.current_factor)
    if t.size < 2 or t.size != f.size:
        raise ConfigError(
            f"{source}: keys 'derating.temp_c' ({t.size} values) and 'derating.current_factor' ({f.size}); "
            "expected two tables of the same length >= 2."
        )
    if np.any(np.diff(t) <= 0):
        raise ConfigError(f"{source}: key 'derating.temp_c' = {list(d.temp_c)}; expected increasing values.")
    if np.any((f < 0) | (f > 1)):
        raise ConfigError(
            f"{source}: key 'derating.current_factor' = {list(d.current_factor)}; expected 0..1."
        )
    _check_soc_tables(d, source)
    m = cfg.module
    if m.cells == "representative" and (cfg.cells.capacity_spread > 0.0 or cfg.cells.resistance_spread > 0.0):
        raise ConfigError(
            f"{source}: [module] cells = \"representative\" with 'cells.capacity_spread' = "
            f"{cfg.cells.capacity_spread:g} and 'cells.resistance_spread' = {cfg.cells.resistance_spread:g}; "
            'expected no cell-to-cell spread (one cell stands for its whole module) or cells = "all".'
        )
    if m.thermal == "rom" and not (m.rom_file and m.thermal_config):
        raise ConfigError(
            f"{source}: [module] thermal = \"rom\" needs 'module.rom_file' (from `hevsim rom build`) and "
            "'module.thermal_config' (the module thermal TOML it was built from)."
        )
    return cfg


def _check_soc_tables(d: DeratingSection, source: str) -> None:
    soc = np.asarray(d.soc, float)
    if soc.size < 2 or np.any(np.diff(soc) <= 0) or soc[0] > 0.0 or soc[-1] < 1.0:
        raise ConfigError(
            f"{source}: key 'derating.soc' = {list(d.soc)}; expected increasing values from 0 to 1 (>= 2)."
        )
    for key in ("discharge_soc_factor", "charge_soc_factor"):
        f = np.asarray(getattr(d, key), float)
        if f.size != soc.size or np.any((f < 0) | (f > 1)):
            raise ConfigError(
                f"{source}: key 'derating.{key}' = {list(f)}; expected {soc.size} values in 0..1 (one per "
                "'derating.soc')."
            )


def load_pack_config(path: str | Path) -> PackConfig:
    """Read and validate a pack TOML file."""
    p = Path(path)
    return pack_config_from_dict(read_toml(p), str(p), p.parent)


@lru_cache(maxsize=8)
def module_mesh_hash(geometry: Any, source: str) -> str:
    """Hash of the module mesh of a (frozen, hashable) module geometry
    (:func:`hevsim.thermal.rom.mesh_hash`), remembered: meshing takes about a second and every
    vehicle run of a ROM pack checks its ROM against it."""
    from hevsim.thermal.geometry import build_module_mesh
    from hevsim.thermal.rom import mesh_hash

    return str(mesh_hash(build_module_mesh(geometry, source=source)))


@lru_cache(maxsize=4)
def _cached_rom(path: str, mtime_ns: int, size: int, digest: str, where: str) -> Any:
    """A module ROM file loaded once per (file, modification time, size, mesh hash): every run
    of a ROM pack reads the same ROM (the packs using it do not modify its arrays)."""
    from hevsim.thermal.rom import load_rom

    return load_rom(path, expected_mesh_hash=digest, where=where)


@dataclass(frozen=True)
class PackStepStart:
    """What :meth:`Pack.begin_step` decided for a step: hottest cell core [K] at its start, the
    temperature derating factor [-], the cooling loop's step and the plates' inlets [K]."""

    hottest_k: float
    factor: float
    loop_step: LoopStep
    inlet_k: np.ndarray


@dataclass
class PackResult:
    """Time series (``timeseries``, one row per step end), per-cell arrays ``cells[k, c, :]``
    (current [A], SOC, core temperature [K], port heat [W], voltage [V]), energy terms [J] and
    metrics."""

    timeseries: pd.DataFrame
    cells: np.ndarray
    energy: dict[str, float]
    metrics: dict[str, float]
    metadata: dict[str, Any] = field(default_factory=dict)


class Pack:
    """A pack built from a :class:`PackConfig` (module docstring)."""

    def __init__(self, cfg: PackConfig, *, rom: Any = None, thermal_cfg: Any = None) -> None:
        from hevsim.battery.params import load_cell_parameters

        self.cfg = cfg
        src = cfg.name
        base = Path(cfg.base_dir)
        par = cfg.cells.parameters
        self.params = load_cell_parameters(str(base / par) if (base / par).is_file() else par)
        self._check_derating(src)
        m, p = cfg.module, cfg.pack
        self.cells_per_module = m.n_series * m.n_parallel
        self.representative = m.cells == "representative"
        #: simulated cells per module, and the physical cells each simulated cell stands for
        self.sim_per_module = 1 if self.representative else self.cells_per_module
        self.weight = self.cells_per_module // self.sim_per_module
        #: simulated cells (``prm``/``x`` rows); ``cells_represented`` the pack's physical cells
        self.n_cells = self.sim_per_module * p.n_modules
        self.cells_represented = self.cells_per_module * p.n_modules
        #: series groups simulated (one per module when representative) and cells in parallel in each
        self.n_groups_sim = p.n_modules * (1 if self.representative else m.n_series)
        self.n_p_sim = 1 if self.representative else m.n_parallel
        rng = np.random.default_rng(cfg.cells.seed)
        c0 = 1.0 + cfg.cells.capacity_spread * rng.standard_normal(self.n_cells)
        rs = 1.0 + cfg.cells.resistance_spread * rng.standard_normal(self.n_cells)
        self.prm = np.stack(
            [self.params.vector(cfg.cells.soc_initial, r, c) for r, c in zip(rs, c0, strict=True)]
        )
        t0 = c_to_k(p.initial_temp_c)
        self.x = np.stack([self.params.initial_state(t0) for _ in range(self.n_cells)])
        self.ambient_k = c_to_k(p.ambient_temp_c)
        # thermal configuration: coolant properties (Table 4.4 without one), channel, ROM
        from hevsim.thermal.coolant import Coolant

        self.coolant = Coolant()
        density, cp = self.coolant.density_kg_m3, self.coolant.specific_heat_j_kgk
        self.thermal_cfg = thermal_cfg
        if m.thermal_config and self.thermal_cfg is None:
            from hevsim.thermal.run import load_thermal_config

            self.thermal_cfg = load_thermal_config(base / m.thermal_config)
        if self.thermal_cfg is not None:
            from hevsim.thermal.run import coolant_from_section

            self.coolant = coolant_from_section(self.thermal_cfg.coolant)
            density, cp = self.coolant.density_kg_m3, self.coolant.specific_heat_j_kgk
        self.loop = CoolingLoop(cfg.cooling, cfg.controller, p.n_modules, density, cp, src)
        self.rom = None
        if m.thermal == "rom":
            self.rom = rom if rom is not None else self._load_rom(base)
            if self.rom.n_cells != self.cells_per_module:
                raise ConfigError(
                    f"{src}: the module ROM has {self.rom.n_cells} cells; [module] n_series x n_parallel = "
                    f"{m.n_series} x {m.n_parallel} = {self.cells_per_module}; expected the same number."
                )
            self.h_plate = self._wall_film(self.loop.plate_flow_m3_s)
        self.port_k = np.full(self.n_cells, t0)
        self._tabs = self.params.tables()
        self._energy_buf = np.zeros(4)
        self._cells = np.zeros((self.n_cells, 5))
        # the next step's affine pairs (pack_pass): per cell, per series group, the pack's
        self._ez = np.zeros((self.n_cells, 8))
        self._oc = np.zeros((self.n_cells, 6))
        self._pairs = np.zeros((self.n_groups_sim, 4))
        self._totals = np.zeros(4)
        self._is_linear: bool | None = None
        self._rcc = np.zeros((2, 1, 5))
        self._c0_new = self.prm[:, C0].copy()
        self._rscale_new = self.prm[:, RSCALE].copy()
        self._stress: Any = None
        self._arrays: Any = None
        self._init_run_arrays(t0)
        self._new_accounts()

    # -- construction helpers ----------------------------------------------------------------
    def _check_derating(self, src: str) -> None:
        """The table must cover the cells' temperature range: their rated operating range
        (``cells.min_temp_c`` .. ``cells.max_temp_c``) and the parameter set's table range."""
        t = np.asarray(self.cfg.derating.temp_c)
        tk = self.params.temperature_k
        lo = min(self.cfg.cells.min_temp_c, float(tk.min()) - 273.15)
        hi = max(self.cfg.cells.max_temp_c, float(tk.max()) - 273.15)
        if t[0] > lo or t[-1] < hi:
            raise ConfigError(
                f"{src}: key 'derating.temp_c' spans {t[0]:g} to {t[-1]:g} degC; expected it to cover the "
                f"cells' temperature range {lo:g} to {hi:g} degC (cells.min_temp_c .. cells.max_temp_c and "
                f"the tables of '{self.params.name}')."
            )

    def _load_rom(self, base: Path) -> Any:
        from hevsim.thermal.rom import load_rom

        m = self.cfg.module
        assert self.thermal_cfg is not None
        digest = module_mesh_hash(self.thermal_cfg.geometry, f"{m.thermal_config}: geometry")
        path = (base / m.rom_file).resolve()
        where = f"{self.cfg.name}: module.rom_file"
        if not path.is_file():  # load_rom names the missing file
            return load_rom(path, expected_mesh_hash=digest, where=where)
        st = path.stat()
        return _cached_rom(str(path), st.st_mtime_ns, st.st_size, digest, where)

    def _wall_film(self, plate_flow_m3_s: float) -> float:
        """Wall film [W/(m^2 K)] of one plate at its flow (the ROM's lowest film at zero flow)."""
        from hevsim.thermal.coolant import ChannelModel

        assert self.rom is not None and self.thermal_cfg is not None
        if plate_flow_m3_s <= 0.0:
            return self.rom.wall_h_range_w_m2k[0]
        g = self.thermal_cfg.geometry
        ch = ChannelModel(1, inlet_temp_k=300.0, flow_m3_s=plate_flow_m3_s, width_m=g.channel_width_m,
                          height_m=g.channel_height_m, coolant=self.coolant)  # fmt: skip
        lo, hi = self.rom.wall_h_range_w_m2k
        if not lo * (1 - 1e-9) <= ch.h_w_m2k <= hi * (1 + 1e-9):
            raise ConfigError(
                f"{self.cfg.name}: key 'cooling.flow_l_min' = {self.cfg.cooling.flow_l_min:g} gives a plate "
                f"wall film of {ch.h_w_m2k:.1f} W/(m^2 K), outside the ROM's range {lo:.1f} to {hi:.1f} "
                "W/(m^2 K); "
                "expected a flow the ROM was built for (rebuild it from a thermal config at this flow)."
            )
        return float(ch.h_w_m2k)

    def derating_factor(self, hottest_k: float) -> float:
        d = self.cfg.derating
        return float(np.interp(hottest_k - 273.15, d.temp_c, d.current_factor))

    # -- bookkeeping -------------------------------------------------------------------------------
    def _rc_energy_j(self) -> float:
        tabs = self.params.tables()
        return float(sum(rc_energy(self.prm[c], tabs[7], tabs[8], self.x[c]) for c in range(self.n_cells)))

    def stored_energy_j(self) -> dict[str, float]:
        """Stored energies [J]: RC capacitors, cell cores (``C_heat T``), module FEMs (ROM ``sum C T``),
        coolant loop (``M c_p T``); differences of two calls close the balance (:meth:`energy`)."""
        core = self.weight * float(np.sum(self.prm[:, CHEAT] * self.x[:, STEMP]))
        mod = float(np.sum(self._rom_w @ self._modal["energy"])) if self.rom is not None else 0.0
        return {
            "rc_j": self.weight * self._rc_energy_j(),
            "cores_j": core,
            "modules_j": mod,
            "loop_j": self.loop.stored_j(),
        }

    # -- simulation --------------------------------------------------------------------------------
    def _init_run_arrays(self, t0: float) -> None:
        """The scalars, ROM (modal) and record arrays of :class:`~hevsim.battery.pack_run.PackArrays`."""
        from hevsim.battery import pack_run as R
        from hevsim.battery.life import ACTIVATION_TEMPERATURE_K

        cfg, m, n_mod = self.cfg, self.cfg.module, self.cfg.pack.n_modules
        f = np.zeros(len(R.F_NAMES))
        f[R.F_DT], f[R.F_NG], f[R.F_NP] = cfg.pack.dt_s, self.n_groups_sim, self.n_p_sim
        f[R.F_REP], f[R.F_NS], f[R.F_NPAR] = float(self.representative), m.n_series, m.n_parallel
        f[R.F_WEIGHT], f[R.F_NMOD], f[R.F_SIMPM] = self.weight, n_mod, self.sim_per_module
        f[R.F_IMAX], f[R.F_AMB] = cfg.pack.max_current_a, self.ambient_k
        f[R.F_SOCMIN] = f[R.F_SOCMAX] = f[R.F_SOC] = cfg.cells.soc_initial
        f[R.F_VMIN], f[R.F_VMAX] = self.prm[0, VMIN], self.prm[0, VMAX]
        f[R.F_ACT] = ACTIVATION_TEMPERATURE_K
        f[R.F_HSREBASE] = R.HOT_SPOT_REBASE_K
        self._f = f
        d = cfg.derating
        tables = (d.temp_c, d.current_factor, d.soc, d.discharge_soc_factor, d.charge_soc_factor)
        self._derating = tuple(np.asarray(v, dtype=float) for v in tables)
        self._inlet = np.full(n_mod, self.loop.temp_k)
        self._plate_heat = np.zeros(n_mod)
        self._sv = np.zeros(len(R.SV_NAMES))
        self._acc = np.zeros(len(ENERGY_TERMS))
        self._rec = np.zeros((0, len(R.RECORD_CHANNELS)))
        self._hot = np.zeros((0, n_mod))
        if self.rom is None:
            e1, e2 = np.zeros(0), np.zeros((0, 0))
            self._modal: dict[str, np.ndarray]
            self._modal = {"rom_decay": e1, "rom_in": e2, "rom_out": e2, "rom_cand": e2, "hs_norm": e1,
                           "hs_unit": e1, "energy": e1, "hs_ub": e2, "hs_prev": e2, "hs_blk": e2,
                           "hs_block": e1, "hs_gmax": e1, "hs_g32": np.zeros((0, 0), np.float32),
                           "hs_d32": np.zeros((0, 0), np.float32), "hs_cand": np.zeros((0, 0), np.int64),
                           "hs_const": np.zeros(4), "hs_basis": e2, "hs_gb": e2,
                           "hs_gb32": np.zeros((0, 0), np.float32), "hs_gres": e1, "hs_cov": e2,
                           "hs_up": e2, "hs_gbt32": np.zeros((0, 0), np.float32), "hs_keep": e2,
                           "hs_hot": np.zeros((0, 0), np.int64)}  # fmt: skip
            self._rom_w, self._rom_u, self._rom_y = (np.zeros((n_mod, 0)) for _ in range(3))
            self._channel = (e1, e1, e1)
            return
        rom = self.rom
        f[R.F_ROM], f[R.F_H] = 1.0, self.h_plate
        f[R.F_BAMB], f[R.F_FCONST] = rom.b_amb_total, rom.f_const_total
        self._modal = R.modal_rom(rom, cfg.pack.dt_s, self.h_plate)
        self._modal["hs_ub"] = np.zeros((n_mod, self._modal["rom_cand"].shape[0]))
        self._modal["hs_prev"] = np.zeros((n_mod, rom.order + len(R.HP_NAMES)))
        self._modal["hs_blk"] = np.zeros((n_mod, self._modal["hs_gmax"].shape[0]))
        self._modal["hs_d32"] = np.zeros((n_mod, rom.order), np.float32)
        self._modal["hs_cand"] = np.zeros((n_mod, self._modal["rom_cand"].shape[0]), np.int64)
        # the slack screening's basis (R._module_hot_spots_within), shared by the modules
        kmax = R.HOT_SPOT_BASIS_MAX
        n_rows = self._modal["rom_cand"].shape[0]
        self._modal["hs_basis"] = np.zeros((kmax, rom.order))
        self._modal["hs_gb"] = np.zeros((kmax, n_rows))
        self._modal["hs_gb32"] = np.zeros((kmax, n_rows), np.float32)
        self._modal["hs_gres"] = np.zeros(n_rows)
        self._modal["hs_cov"] = np.zeros((kmax, kmax))
        self._modal["hs_up"] = np.zeros((n_mod, n_rows))
        self._modal["hs_gbt32"] = np.zeros((n_rows, kmax), np.float32)
        self._modal["hs_keep"] = np.zeros((n_mod, rom.order + len(R.KP_NAMES)))
        self._modal["hs_hot"] = np.zeros((n_mod, n_rows), np.int64)
        f[R.F_HSEPS] = cfg.module.hot_spot_slack_k
        f[R.F_HSLASTCUT] = -R.HOT_SPOT_CUT_EVERY
        w0 = t0 * (rom.unit_state @ self._modal["q"])
        self._rom_w = np.ascontiguousarray(np.repeat(w0[None, :], n_mod, axis=0))
        self._rom_u = np.zeros((n_mod, rom.n_cells + rom.n_segments + 2))
        self._rom_y = self._rom_w @ self._modal["rom_out"]
        cap = self.loop.rho_cp * self.loop.plate_flow_m3_s
        ntu = self.h_plate * rom.wall_area_m2 / cap if cap > 0.0 else np.zeros(rom.n_segments)
        decay = np.exp(-ntu)
        mean_factor = np.where(ntu > 1e-12, (1.0 - decay) / np.where(ntu > 1e-12, ntu, 1.0), 1.0)
        self._channel = (np.ascontiguousarray(mean_factor), decay, np.asarray(rom.wall_area_m2, dtype=float))

    @property
    def arrays(self) -> Any:
        """The pack's :class:`~hevsim.battery.pack_run.PackArrays` (views of its state; rebuilt
        after :meth:`state_changed`, a new stress accumulator or more record rows)."""
        if self._arrays is None:
            from hevsim.battery.pack_run import F_LINEAR, F_STRESS, PackArrays

            self._f[F_LINEAR] = float(self._linear())
            st = self._stress
            self._f[F_STRESS] = float(st is not None)
            md = self._modal
            self._arrays = PackArrays(  # type: ignore[call-arg]
                self._f, self.prm, self.x, *self._tabs, self._ez, self._oc, self._rcc, self._pairs,
                self._totals, self.port_k, self._cells, self._energy_buf, self.loop.lp, self.loop.ls,
                self._inlet, self._plate_heat, *self._derating, md["rom_decay"], md["rom_in"], md["rom_out"],
                md["rom_cand"], md["hs_norm"], md["hs_unit"], md["energy"], md["hs_ub"], md["hs_prev"],
                md["hs_blk"], md["hs_block"], md["hs_gmax"], md["hs_g32"], md["hs_d32"], md["hs_cand"],
                md["hs_const"], md["hs_basis"], md["hs_gb"], md["hs_gb32"], md["hs_gres"], md["hs_cov"],
                md["hs_up"], md["hs_gbt32"], md["hs_keep"], md["hs_hot"], self._rom_w, self._rom_u,
                self._rom_y, *self._channel, self._acc, self._sv, self._rec, self._hot,
                st.data if st is not None else np.zeros((8, 0)), st.counts if st is not None else np.zeros(2),
            )  # fmt: skip
        return self._arrays

    @property
    def stress(self) -> Any:
        """Per-cell ageing stress accumulator (:class:`hevsim.battery.life.CellStress`) or None."""
        return self._stress

    @stress.setter
    def stress(self, value: Any) -> None:
        self._stress = value
        self._arrays = None

    @property
    def acc(self) -> dict[str, float]:
        """The energy terms [J] accumulated since the last :meth:`simulate` began (:data:`ENERGY_TERMS`)."""
        return dict(zip(ENERGY_TERMS, (float(v) for v in self._acc), strict=True))

    @property
    def time_s(self) -> float:
        from hevsim.battery.pack_run import F_TIME

        return float(self._f[F_TIME])

    @property
    def steps_done(self) -> int:
        """Steps since the accounts were reset (rows of :attr:`records`)."""
        from hevsim.battery.pack_run import F_STEP

        return int(self._f[F_STEP])

    @property
    def _ez_valid(self) -> bool:
        from hevsim.battery.pack_run import F_EZVALID

        return bool(self._f[F_EZVALID])

    @_ez_valid.setter
    def _ez_valid(self, value: bool) -> None:
        from hevsim.battery.pack_run import F_EZVALID

        self._f[F_EZVALID] = float(value)

    def rom_state_z(self) -> np.ndarray:
        """The modules' ROM states ``z`` (n_modules, order) (:mod:`hevsim.thermal.rom`; the
        pack steps them in modal coordinates)."""
        assert self.rom is not None
        return np.asarray(self._rom_w @ self._modal["q"].T)

    def hot_spot_error(self) -> dict[str, float]:
        """The module hot spots' error against the full FEM [K] (issue 26 item 5):
        ``estimate_k`` = the ROM's own hot-spot error estimate
        (:attr:`~hevsim.thermal.rom.ThermalRom.hot_spot_error_k`, over every node of the cells)
        + the screening slack ``slack_k`` (``[module] hot_spot_slack_k``: each hot spot is within
        it of the reconstructed field's maximum); ``screening_gap_k`` = the largest gap the
        screening certified so far (<= the slack; 0 with the slack 0: exact). NaN without a ROM
        (the hot spot is then the hottest cell core)."""
        from hevsim.battery.pack_run import F_HSEPS, F_HSGAP

        if self.rom is None:
            nan = float("nan")
            return {"estimate_k": nan, "slack_k": nan, "screening_gap_k": nan}
        slack = float(self._f[F_HSEPS])
        return {
            "estimate_k": self.rom.hot_spot_error_k + slack,
            "slack_k": slack,
            "screening_gap_k": max(float(self._f[F_HSGAP]), 0.0),
        }

    def reserve(self, steps: int) -> None:
        """Room for ``steps`` more record rows (:attr:`records`)."""
        need = self.steps_done + int(steps)
        if need > self._rec.shape[0]:
            rows = max(need, 2 * self._rec.shape[0])
            rec, hot = np.zeros((rows, self._rec.shape[1])), np.zeros((rows, self._hot.shape[1]))
            rec[: self._rec.shape[0]], hot[: self._hot.shape[0]] = self._rec, self._hot
            self._rec, self._hot, self._arrays = rec, hot, None

    @property
    def records(self) -> tuple[np.ndarray, np.ndarray]:
        """Per step since the accounts were reset: the record rows
        (:data:`hevsim.battery.pack_run.RECORD_CHANNELS`) and the per-module hot spots [K]."""
        k = self.steps_done
        return self._rec[:k], self._hot[:k]

    def _new_accounts(self) -> None:
        from hevsim.battery.pack_run import F_STEP, F_TIME

        self._acc[:] = 0.0
        self._f[F_TIME] = 0.0
        self._f[F_STEP] = 0.0
        self._plate_heat[:] = 0.0

    def begin_step(self) -> PackStepStart:
        """The first half of a step: the BMS's temperature derating factor (hottest cell core at
        the start of the step) and the cooling loop's decision (pump, fan, chiller power [W],
        known before the cells' current: an auxiliary load the vehicle puts on its bus);
        :func:`hevsim.battery.pack_run.pack_begin` (which also forms the step's Thevenin pairs
        and BMS limits, :mod:`hevsim.battery.bms`)."""
        from hevsim.battery import pack_run as R

        R.pack_begin(self.arrays)
        sv = self._sv
        loop_step = LoopStep(float(sv[R.SV_SUPPLY]), self._inlet.copy(),
                             *(float(v) for v in sv[R.SV_PFLOW:]))  # fmt: skip
        return PackStepStart(float(sv[R.SV_HOT]), float(sv[R.SV_FACTOR]), loop_step, loop_step.inlet_k)

    def thevenin(self, direction: float, e_group: np.ndarray, z_group: np.ndarray) -> tuple[float, float]:
        """The pack's step-average terminal voltage as ``E - Z I`` [V, ohm] for a pack current
        of ``direction`` (+1 discharge, -1 charge) over the next step, from the cells' present
        state (:func:`pack_thevenin`); ``e_group``/``z_group`` (:attr:`n_groups_sim`,) receive each
        series group's own pair (its cells' voltage; representative cells: one group per module,
        its ``n_parallel`` identical cells in parallel)."""
        m = self.cfg.module
        if not self._ez_valid:
            linear = self._linear()  # (sets the RC constants)
            pack_pairs(  # type: ignore[call-arg]
                self.prm, *self._tabs, self.x, self.n_groups_sim, self.n_p_sim, self.cfg.pack.dt_s, self._ez,
                self._oc, self._rcc, linear, self._pairs, self._totals,
            )  # fmt: skip
            self._ez_valid = True
        k = 0 if direction > 0.0 else 2
        e_group[:] = self._pairs[:, k]
        z_group[:] = self._pairs[:, k + 1]
        e, z = float(self._totals[k]), float(self._totals[k + 1])
        if not self.representative:
            return e, z
        z_group /= m.n_parallel
        return m.n_series * e, m.n_series * z / m.n_parallel

    def finish_step(
        self, start: PackStepStart, current_a: float, current_request_a: float | None = None,
        cells_out: np.ndarray | None = None,
    ) -> tuple[dict[str, float], np.ndarray]:  # fmt: skip
        """The second half of a step at pack current ``current_a`` [A] (discharge > 0, already
        within the BMS limits) after :meth:`begin_step` (``start``): cells, module thermal model,
        cooling loop, energy terms (:func:`hevsim.battery.pack_run.pack_finish`). Returns the
        step's channels (:data:`STEP_CHANNELS`) and the per-module hot spots [K]; ``cells_out``
        (n_cells, 5) receives the per-cell record."""
        from hevsim.battery import pack_run as R

        self.reserve(1)
        i_a = float(current_a)
        req = i_a if current_request_a is None else float(current_request_a)
        k = self.steps_done
        R.pack_finish(self.arrays, i_a, req)
        if cells_out is not None:
            cells_out[:] = self._cells
        rec = self._rec[k]
        row = {name: float(rec[R.RECORD_CHANNELS.index(col)]) for name, col in R.STEP_TO_RECORD.items()}
        return row, self._hot[k].copy()

    def step(
        self, current_request_a: float, cells_out: np.ndarray | None = None
    ) -> tuple[dict[str, float], np.ndarray]:
        """Advance the pack one ``pack.dt_s`` at the requested pack current [A] (discharge > 0),
        derated by the BMS; returns the step's channels (:data:`STEP_CHANNELS`) and the
        per-module hot spots [K]. ``cells_out`` (n_cells, 5) receives the per-cell record
        (current [A], SOC, core temperature [K], port heat [W], voltage [V]). The energy terms
        accumulate in :attr:`acc` (:meth:`energy` closes the balance). The same as
        :meth:`begin_step` then :meth:`finish_step` at the derated current."""
        from hevsim.battery.pack_run import SV_LIMC, SV_LIMD

        start = self.begin_step()
        i_a = float(np.clip(current_request_a, -self._sv[SV_LIMC], self._sv[SV_LIMD]))
        return self.finish_step(start, i_a, current_request_a, cells_out)

    def cell_names(self) -> list[str]:
        """Names of the simulated cells for messages: "module m cell c" (c = series group *
        n_parallel + branch within the module), or "module m (representative cell)"."""
        spm = self.sim_per_module
        if self.representative:
            return [f"module {m} (representative cell)" for m in range(self.cfg.pack.n_modules)]
        return [f"module {k // spm} cell {k % spm}" for k in range(self.n_cells)]

    def apply_ageing(self, capacity_fraction: np.ndarray, resistance_fraction: np.ndarray) -> None:
        """Scale every cell's capacity C0 and resistances by its ageing state's fractions [-]
        (``C/C0``, ``R/R0``; arrays of ``n_cells``), from the new cells' (spread) values."""
        cf, rf = np.asarray(capacity_fraction, float), np.asarray(resistance_fraction, float)
        if cf.shape != (self.n_cells,) or rf.shape != (self.n_cells,):
            raise ConfigError(
                f"{self.cfg.name}: ageing state for {cf.size} cells; the pack has {self.n_cells} cells."
            )
        self.prm[:, C0] = self._c0_new * cf
        self.prm[:, RSCALE] = self._rscale_new * rf
        self.state_changed()

    def state_changed(self) -> None:
        """Call after editing :attr:`prm` or :attr:`x` directly: the stored affine pairs of the
        next step (:func:`pack_pass`) are recomputed."""
        self._ez_valid = False
        self._is_linear = None
        self._arrays = None

    def _linear(self) -> bool:
        """Every cell's step voltage is affine in its current (:func:`pack_pass_linear`)."""
        if self._is_linear is None:
            p = self.prm
            nonlinear = (p[:, OCVSTEP] > 0.0) | (p[:, CTI0] > 0.0) | (p[:, HMAX] > 0.0)
            same_rc = np.all(p[:, NRC] == p[0, NRC]) and np.all(p[:, RCPERS] == p[0, RCPERS])
            # temperature laws (issue 27): R_s, RC and entropic heat vary with each cell's temperature
            laws = self.params.has_temperature_laws
            self._is_linear = bool(same_rc and not nonlinear.any() and not laws)
            self._rcc = rc_constants(p[0], self._tabs[7], self._tabs[8], self.cfg.pack.dt_s)
        return self._is_linear

    def energy(self, start: dict[str, float]) -> dict[str, float]:
        """The energy terms [J] accumulated since the stored energies were ``start``
        (:meth:`stored_energy_j`), with the balance residual (module docstring)."""
        s1 = self.stored_energy_j()
        e = dict(self.acc)
        for key in start:
            e[f"delta_{key}"] = s1[key] - start[key]
        stored = e["delta_cores_j"] + e["delta_modules_j"] + e["delta_loop_j"]
        to_ambient = e["module_ambient_j"] + e["radiator_j"] - e["loop_ambient_in_j"]
        removed = e["chiller_j"] + e["reservoir_j"]
        e["heat_stored_j"] = stored
        e["heat_to_ambient_j"] = to_ambient
        e["heat_removed_j"] = removed
        e["residual_j"] = (
            e["electrical_out_j"] + e["chemical_change_j"] + e["delta_rc_j"] + stored + to_ambient + removed
            - e["pump_work_j"]
        )  # fmt: skip
        e["residual_relative"] = e["residual_j"] / max(e["throughput_j"], 1e-300)
        return e

    def simulate(self, current_a: Any, *, ambient_temp_c: float | None = None) -> PackResult:
        """Run the pack over the requested pack current [A] (discharge > 0), one value per
        ``pack.dt_s`` step (:meth:`step`); the BMS derates it (module docstring)."""
        from hevsim.battery.cell import check_cell_domain
        from hevsim.battery.pack_run import LIMIT_NAMES

        t_wall0 = time.perf_counter()
        req = np.asarray(current_a, dtype=float)
        if req.ndim != 1 or req.size == 0 or not np.all(np.isfinite(req)):
            raise ConfigError(f"{self.cfg.name}: current profile: expected a non-empty 1-D finite array [A].")
        if ambient_temp_c is not None:
            from hevsim.battery.pack_run import F_AMB

            self.ambient_k = c_to_k(ambient_temp_c)
            self._f[F_AMB] = self.ambient_k
        cfg = self.cfg
        steps, n_mod = req.size, cfg.pack.n_modules
        out_cells = np.empty((steps, self.n_cells, 5))
        self._new_accounts()
        s0 = self.stored_energy_j()
        from threadpoolctl import threadpool_limits

        from hevsim.battery.pack_run import RECORD_CHANNELS, STEP_TO_RECORD, pack_simulate

        self.reserve(steps)
        with threadpool_limits(1, user_api="blas"):  # small per-step ROM products (see pack_vehicle)
            pack_simulate(self.arrays, req, out_cells)
        rec, module_hot = self.records
        rows = {key: rec[:, RECORD_CHANNELS.index(STEP_TO_RECORD[key])].copy() for key in STEP_CHANNELS}
        check_cell_domain(
            f"pack {cfg.name}",
            rows["time_s"],
            rows["current_a"],
            rows["voltage_v"],
            out_cells[:, :, 2],
            soc=out_cells[:, :, 1],
            cell_names=self.cell_names(),
            remedy="the BMS limits the current by the lowest/highest cell SOC ([derating] soc, "
            "discharge_soc_factor, charge_soc_factor) and the cells' voltage limits: make these tables "
            "reach 0 before a cell empties or fills.",
        )
        e = self.energy(s0)
        hot_cols = pd.DataFrame(module_hot, columns=[f"module{j}_hot_spot_temp_k" for j in range(n_mod)])
        ts = pd.concat([pd.DataFrame(rows), hot_cols], axis=1)
        derated = rows["derating_factor"] < 1.0
        req, cur = rows["current_request_a"], rows["current_a"]
        held = np.abs(cur) < np.abs(req) * (1.0 - 1e-9)  # the BMS limited the request
        reason = np.where(req >= 0.0, rec[:, RECORD_CHANNELS.index("bms_discharge_reason")],
                          rec[:, RECORD_CHANNELS.index("bms_charge_reason")])  # fmt: skip
        by_soc_v = held & np.isin(reason, [LIMIT_NAMES.index("soc"), LIMIT_NAMES.index("voltage")])
        metrics = {
            "duration_s": steps * cfg.pack.dt_s,
            "peak_cell_temp_k": float(out_cells[:, :, 2].max()),
            "peak_hot_spot_temp_k": float(module_hot.max()),
            "final_soc_spread": float(rows["max_soc"][-1] - rows["min_soc"][-1]),
            "derated_time_s": float(derated.sum() * cfg.pack.dt_s),
            "first_derating_s": float(rows["time_s"][derated][0]) if derated.any() else float("nan"),
            "bms_limited_s": float(held.sum() * cfg.pack.dt_s),
            "first_bms_limit_s": float(rows["time_s"][held][0]) if held.any() else float("nan"),
            "bms_soc_voltage_limited_s": float(by_soc_v.sum() * cfg.pack.dt_s),
            "discharge_delivered_fraction": float(
                np.clip(cur, 0.0, None).sum() / max(np.clip(req, 0.0, None).sum(), 1e-300)
            ),
            "final_min_soc": float(rows["min_soc"][-1]),
            "cooling_energy_j": e["pump_work_j"] + e["chiller_electric_j"] + e["fan_electric_j"],
            "energy_balance_relative": e["residual_relative"],
        }
        hs = self.hot_spot_error()
        metrics["hot_spot_error_estimate_k"] = hs["estimate_k"]
        metrics["hot_spot_slack_k"] = hs["slack_k"]
        metrics["hot_spot_screening_gap_k"] = hs["screening_gap_k"]
        meta = {"name": cfg.name, "n_cells": self.n_cells, "thermal": cfg.module.thermal,
                "dt_s": cfg.pack.dt_s, "rom_order": None if self.rom is None else self.rom.order,
                "elapsed_s": time.perf_counter() - t_wall0}  # fmt: skip
        return PackResult(ts, out_cells, e, metrics, meta)


__all__ = [
    "Pack",
    "PackConfig",
    "PackResult",
    "PackStepStart",
    "load_pack_config",
    "pack_config_from_dict",
    "pack_pairs",
    "pack_pass",
    "pack_pass_linear",
    "pack_step",
    "pack_thevenin",
]


def pack_current_from_cycle(cfg: PackConfig, cycle: str, duration_s: float, scale: float = 1.0) -> np.ndarray:
    """Pack current [A] over a drive cycle: the road-load cell current of
    :func:`hevsim.battery.profiles.cycle_cell_current` times ``n_parallel`` times ``scale``."""
    from hevsim.battery.profiles import cycle_cell_current

    cell = cycle_cell_current(cycle, duration_s=duration_s, dt_s=cfg.pack.dt_s)
    return np.asarray(cell * cfg.module.n_parallel * scale, dtype=float)


def run_pack(config: str | Path | PackConfig, out_dir: str | Path | None, *, cycle: str = "udds",
             duration_s: float = 1369.0, current_scale: float = 1.0) -> PackResult:  # fmt: skip
    """Run a pack over a drive cycle's current; writes ``timeseries.csv`` and ``summary.json``
    (energy terms, metrics, metadata) atomically when ``out_dir`` is given."""
    from hevsim.io import atomic_directory, write_json

    cfg = config if isinstance(config, PackConfig) else load_pack_config(config)
    res = Pack(cfg).simulate(pack_current_from_cycle(cfg, cycle, duration_s, current_scale))
    res.metadata.update({"cycle": cycle, "duration_s": duration_s, "current_scale": current_scale})
    if out_dir is not None:
        with atomic_directory(out_dir) as tmp:
            res.timeseries.to_csv(tmp / "timeseries.csv", index=False)
            write_json(
                tmp / "summary.json",
                {"energy_j": res.energy, "metrics": res.metrics, "metadata": res.metadata},
            )
    return res


def format_pack(res: PackResult) -> str:
    """A few lines for the terminal."""
    m, e = res.metrics, res.energy
    return "\n".join(
        [
            f"pack {res.metadata['name']}: {res.metadata['n_cells']} cells, thermal {res.metadata['thermal']}"
            + (f" (ROM order {res.metadata['rom_order']})" if res.metadata.get("rom_order") else ""),
            f"  peak cell {m['peak_cell_temp_k'] - 273.15:.2f} degC, module hot spot "
            f"{m['peak_hot_spot_temp_k'] - 273.15:.2f} degC"
            + (
                f" (error estimate {m['hot_spot_error_estimate_k']:.3f} K: ROM + screening slack "
                f"{m['hot_spot_slack_k']:g} K)"
                if np.isfinite(m.get("hot_spot_error_estimate_k", float("nan")))
                else ""
            )
            + f", final SOC spread {m['final_soc_spread']:.4f}",
            f"  derated {m['derated_time_s']:g} s for temperature, cooling energy "
            f"{m['cooling_energy_j'] / 3.6e3:.2f} Wh",
            f"  BMS held the current below the request {m['bms_limited_s']:g} s"
            + (
                f" (first at t = {m['first_bms_limit_s']:g} s; {m['bms_soc_voltage_limited_s']:g} s by "
                f"low/high cell SOC or voltage), {100 * m['discharge_delivered_fraction']:.1f} % of the "
                f"requested discharge delivered; lowest cell SOC at the end {m['final_min_soc']:.4f}"
                if m["bms_limited_s"] > 0
                else ""
            ),
            f"  energy balance residual {e['residual_j']:.3e} J ({e['residual_relative']:.2e} of the "
            "throughput)",
        ]
    )
