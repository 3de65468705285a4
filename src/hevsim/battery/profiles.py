"""Cell current profiles from drive cycles (a simple road-load power model).

Used by the benchmark and the examples to drive a cell with a realistic, 1 Hz drive-cycle
current. The vehicle is a generic mid-size hybrid; the pack is 100 modules of 2s6p cells
(1200 cells), so the cell current is the battery power over 1200 cells at a nominal cell
voltage.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hevsim.components.body import VehicleBody
from hevsim.cycles import DriveCycle, load_cycle
from hevsim.tables import FloatArray


@dataclass(frozen=True)
class RoadLoadVehicle:
    """Generic mid-size car (illustrative values, SI) and its battery pack arrangement."""

    mass_kg: float = 1500.0
    cd: float = 0.30
    area_m2: float = 2.2
    rho_kgpm3: float = 1.2
    crr: float = 0.009
    drive_efficiency: float = 0.85  # battery to wheel, motoring [-]
    regen_fraction: float = 0.6  # share of braking power recovered to the battery [-]
    aux_power_w: float = 300.0
    n_cells: int = 1200  # 100 modules x 2s6p
    cell_voltage_v: float = 3.6  # nominal cell voltage [V]

    def body(self) -> VehicleBody:
        """The vehicle body whose road load (:func:`hevsim.components.body.road_load_force`,
        eq 32, level road, no headwind) the profile uses."""
        return VehicleBody(
            mass_kg=self.mass_kg,
            drag_coefficient=self.cd,
            frontal_area_m2=self.area_m2,
            rolling_resistance=self.crr,
            air_density_kgpm3=self.rho_kgpm3,
        )


def cycle_cell_current(
    cycle: DriveCycle | str = "udds",
    duration_s: float = 3600.0,
    dt_s: float = 1.0,
    vehicle: RoadLoadVehicle | None = None,
) -> FloatArray:
    """Per-cell current [A] (discharge > 0) over ``duration_s`` [s] at step ``dt_s`` [s].

    The cycle is repeated as needed and truncated; the wheel power is the road load
    ``(m a + ½ ρ C_d A v² + m g C_rr) v`` (the vehicle body's eq 32, at the mid-step speed,
    rolling resistance while moving), divided by the drive efficiency when positive and
    scaled by the regenerated fraction when negative, plus auxiliaries; the cell current is
    that power over ``n_cells x cell_voltage_v``.
    """
    veh = vehicle or RoadLoadVehicle()
    cyc = load_cycle(cycle) if isinstance(cycle, str) else cycle
    reps = max(1, math.ceil(duration_s / cyc.duration_s))
    cyc = cyc.repeated(reps) if reps > 1 else cyc
    n = round(duration_s / dt_s)
    t = cyc.time_s[0] + dt_s * np.arange(n + 1)
    v = cyc.speed_at(t)
    a = np.diff(v) / dt_s
    v_mid = 0.5 * (v[1:] + v[:-1])
    force = veh.body().road_load_force(v_mid, a)
    p_wheel = force * v_mid
    p_bat = (
        np.where(p_wheel > 0, p_wheel / veh.drive_efficiency, p_wheel * veh.regen_fraction) + veh.aux_power_w
    )
    return np.ascontiguousarray(p_bat / (veh.n_cells * veh.cell_voltage_v))
