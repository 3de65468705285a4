"""Assemble a series-HEV model from a validated configuration.

The series architecture (thesis Fig. 2.3): engine coupled 1:1 to the generator, a DC bus
with the battery, the traction motor through the final drive to the wheels. The model holds
component objects (:mod:`hevsim.components`) and the driver and supervisory-controller
settings; :meth:`SeriesHEV.param_vector` packs every scalar into the kernel's vector.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hevsim.architectures._build import COMPONENT_KINDS as COMPONENT_KINDS  # re-exported below too
from hevsim.architectures._build import (  # re-exported: the component builders of every architecture
    build_battery,
    build_engine,
    build_machine,
)
from hevsim.architectures._build import resolve_component as resolve_component
from hevsim.architectures._build import shipped_components as shipped_components
from hevsim.components.battery import BatteryPack
from hevsim.components.body import VehicleBody
from hevsim.components.driveline import Gear, Tire
from hevsim.components.electric_machine import ElectricMachine
from hevsim.components.engine import Engine, EngineTables
from hevsim.config import SeriesHEVConfig
from hevsim.fuels import with_config_fuel
from hevsim.sim import kernel as K
from hevsim.tables import FloatArray
from hevsim.units import MPS_PER_MPH, rpm_to_radps


@dataclass(frozen=True, eq=False)
class SeriesHEV:
    """A series hybrid vehicle ready to simulate (components + control settings)."""

    config: SeriesHEVConfig
    body: VehicleBody
    tire: Tire
    gear: Gear
    traction_motor: ElectricMachine
    generator: ElectricMachine
    engine: Engine | None
    battery: BatteryPack
    cell: Any = None
    """Cell parameters (:class:`hevsim.battery.CellParameters`) of a ``"cell"`` battery."""
    aux_power_w: float | None = None
    """Electrical auxiliary load on the bus [W] of the quasi-static power flow (None: ``[controller]
    aux_power_w``; a pack's cooling power is added by :meth:`hevsim.battery.bms.PackRun.vehicle_step`)."""
    cell_port_temp_k: float | None = None
    """The heat-port (ambient) temperature [K] of a ``"cell"`` battery's cells (None: their
    initial temperature, ``[battery] temperature_c``)."""

    @property
    def name(self) -> str:
        """Configuration name."""
        return self.config.name

    def param_vector(self, soc_initial: float | None = None) -> FloatArray:
        """Scalar parameters in the kernel's layout (:data:`hevsim.sim.kernel.PARAMS`)."""
        c = self.config
        ctl = c.controller
        p = np.zeros(len(K.PARAMS))
        b = self.body
        eng = self.engine
        values: dict[str, float] = {
            "mass_kg": b.mass_kg,
            "mass_factor": b.mass_factor,
            "cd": b.drag_coefficient,
            "area_m2": b.frontal_area_m2,
            "rho_kgpm3": b.air_density_kgpm3,
            "headwind_mps": b.headwind_mps,
            "crr": b.rolling_resistance,
            "crr_v": b.rolling_resistance_speed_s_per_m,
            "tire_radius_m": self.tire.radius_m,
            "gear_ratio": self.gear.ratio,
            "gear_efficiency": self.gear.efficiency,
            "max_brake_force_n": c.brakes.max_decel_mps2 * b.mass_kg,
            "driver_gain_per_mps": c.driver.gain_per_mph / MPS_PER_MPH,
            "driver_feedforward": c.driver.feedforward,
            "motor_kind": self.traction_motor.kind_code,
            "motor_eff": self.traction_motor.efficiency,
            "motor_scale": self.traction_motor.torque_scale,
            "motor_inertia": self.traction_motor.inertia_kgm2,
            "gen_kind": self.generator.kind_code,
            "gen_eff": self.generator.efficiency,
            "gen_scale": self.generator.torque_scale,
            "gen_inertia": self.generator.inertia_kgm2,
            "engine_present": float(eng is not None),
            "engine_use_tmap": float(eng is not None and eng.torque_map is not None),
            "engine_use_fuel_map": float(eng is not None and eng.fuel_map is not None),
            "engine_stall_radps": eng.stall_speed_radps if eng else 0.0,
            "engine_redline_radps": eng.redline_radps if eng else 0.0,
            "engine_scale": eng.torque_scale if eng else 1.0,
            "engine_inertia": eng.inertia_kgm2 if eng else 0.0,
            "engine_lhv_jpkg": eng.fuel_lhv_jpkg if eng else 42.937e6,
            "bat_ns": self.battery.n_series,
            "bat_np": self.battery.n_parallel,
            "bat_r_extra": self.battery.r_extra_ohm,
            "bat_capacity_ah": self.battery.capacity_cell_ah,
            "bat_coulombic_eff": self.battery.coulombic_efficiency,
            "bat_max_dis_a": self.battery.max_discharge_current_a,
            "bat_max_chg_a": self.battery.max_charge_current_a,
            "bat_temp_k": self.battery.temperature_k,
            "soc_initial": c.simulation.soc_initial if soc_initial is None else soc_initial,
            "soc_min": self.config.battery.soc_min,
            "soc_max": self.config.battery.soc_max,
            "genset_kind": {
                "none": K.GENSET_NONE,
                "current_source": K.GENSET_CURRENT_SOURCE,
                "engine": K.GENSET_ENGINE,
            }[c.genset.kind],
            "soc_low": ctl.soc_low,
            "soc_high": ctl.soc_high,
            "soc_boost": ctl.soc_boost,
            "genset_speed_radps": rpm_to_radps(ctl.engine_speed_rpm),
            "genset_start_speed_radps": rpm_to_radps(ctl.start_speed_rpm),
            "throttle_run": ctl.throttle,
            "throttle_boost": ctl.throttle_boost,
            "genset_gain_per_radps": ctl.speed_gain_per_rpm / rpm_to_radps(1.0),
            "genset_current_a": c.genset.current_a,
            "regen_min_speed_mps": c.brakes.regen_min_speed_mps,
            "aux_power_w": ctl.aux_power_w,
            "pure_ice_band_w": ctl.pure_ice_band_w,
        }
        if self.cell is not None:
            from hevsim.battery.vehicle import vehicle_parameter_values

            values.update(
                vehicle_parameter_values(
                    self.cell, self.battery.n_series, self.battery.n_parallel, self.battery.temperature_k
                )
            )
        missing = set(K.PARAMS) - set(values) - {"driver_kind", "supervisor_kind", "battery_kind"}
        unknown = set(values) - set(K.PARAMS)
        if missing or unknown:  # a kernel parameter added or renamed on one side only
            raise KeyError(f"kernel parameters missing: {sorted(missing)}; unknown: {sorted(unknown)}")
        for name, value in values.items():
            p[K.P[name]] = value
        return p

    def kernel_tables(
        self, dt_s: float = 1.0, soc_initial: float | None = None
    ) -> tuple[tuple[FloatArray, ...], ...]:
        """(engine, motor, generator, battery) table tuples for the kernel.

        A ``"cell"`` battery's tuple holds the cells' state: build it fresh for every run
        (``dt_s`` [s] and ``soc_initial`` [-] set that state).
        """
        from hevsim.battery.vehicle import ecm_kernel_tables, pad_tables_kind

        if self.cell is not None:
            soc0 = self.config.simulation.soc_initial if soc_initial is None else soc_initial
            b = self.battery
            bat = ecm_kernel_tables(
                self.cell, b.n_series, b.n_parallel, soc0, b.temperature_k, dt_s, self.cell_port_temp_k,
                r_extra_ohm=b.r_extra_ohm,
            )  # fmt: skip
        else:
            bat = pad_tables_kind(self.battery.kernel_tables())
        if self.engine is not None:
            eng = self.engine.kernel_tables()
        else:
            z1, z2 = np.zeros(1), np.zeros((1, 1))
            eng = EngineTables(z1, z1, z1, z1, z1, z1, z2, z1, z1, z2)  # no engine: all dummies
        return (
            eng,
            self.traction_motor.kernel_tables(),
            self.generator.kernel_tables(),
            bat,
        )


def build_series_hev(cfg: SeriesHEVConfig) -> SeriesHEV:
    """Build the component objects of a series HEV from its configuration."""
    base = Path(cfg.base_dir)
    body = VehicleBody.from_section(cfg.body)
    engine = build_engine(cfg.engine, base) if cfg.genset.kind == "engine" else None
    battery, cell = build_battery(cfg.battery, base)
    return SeriesHEV(
        config=cfg,
        body=body,
        tire=Tire(radius_m=cfg.tire.radius_m),
        gear=Gear(ratio=cfg.final_drive.ratio, efficiency=cfg.final_drive.efficiency),
        traction_motor=build_machine(cfg.motor, "motor", base),
        generator=build_machine(cfg.generator, "generator", base),
        engine=None if engine is None else with_config_fuel(engine, cfg),  # [fuel] section
        battery=battery,
        cell=cell,
    )
