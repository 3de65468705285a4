"""Vehicle body: longitudinal dynamics with grade and headwind, eqs (1)-(5) and (32) of the thesis.

Sign conventions: speed ``v_mps`` >= 0 forward; ``grade`` is rise/run (tan of the incline
angle); forces [N] resisting motion are positive.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from numba import njit, types
from numba.extending import overload

from hevsim.units import STANDARD_GRAVITY

AIR_DENSITY_KGPM3 = 1.18
"""Air density used by the thesis, Table 2.2 [kg/m^3]."""


@njit(cache=True)
def aero_force(v_mps, headwind_mps, cd, area_m2, rho_kgpm3):
    """Aerodynamic drag, eq (3): 0.5 Cd rho A (v - v_w)^2 sgn(v - v_w) [N]."""
    rel = v_mps - headwind_mps
    return 0.5 * cd * rho_kgpm3 * area_m2 * rel * np.abs(rel)


def sin_atan(grade):
    """sin(atan(grade)) [-]; compiled code skips the two libm calls on level road (a scalar
    grade of +-0 gives +-0 exactly, as the calls do)."""
    return np.sin(np.arctan(grade))


def cos_atan(grade):
    """cos(atan(grade)) [-]; compiled code skips the two libm calls on level road (exactly 1
    for a scalar grade of +-0, as the calls give)."""
    return np.cos(np.arctan(grade))


@overload(sin_atan)
def _sin_atan(grade):
    if isinstance(grade, types.Number):

        def scalar(grade):
            if grade == 0.0:
                return grade * 1.0
            return np.sin(np.arctan(grade))

        return scalar
    return lambda grade: np.sin(np.arctan(grade))


@overload(cos_atan)
def _cos_atan(grade):
    if isinstance(grade, types.Number):

        def scalar(grade):
            if grade == 0.0:
                return 1.0
            return np.cos(np.arctan(grade))

        return scalar
    return lambda grade: np.cos(np.arctan(grade))


@njit(cache=True)
def grade_force(mass_kg, grade):
    """Gravity along the road, m g sin(alpha) with alpha = atan(grade) [N]."""
    return mass_kg * STANDARD_GRAVITY * sin_atan(grade)


@njit(cache=True)
def rolling_force(mass_kg, grade, crr, crr_speed_s_per_m, v_mps):
    """Rolling resistance magnitude (crr + crr_v abs(v)) m g cos(alpha) for a moving vehicle [N].

    ``crr`` [-] is the constant coefficient, ``crr_speed_s_per_m`` [s/m] the speed-proportional
    one (zero for the physical form of a vehicle file; the coast-down form's B term, see
    :func:`coastdown_parameters`), ``v_mps`` [m/s] the speed.
    """
    return (crr + crr_speed_s_per_m * np.abs(v_mps)) * mass_kg * STANDARD_GRAVITY * cos_atan(grade)


@njit(cache=True)
def axle_normal_loads(mass_kg, accel_mps2, drag_n, grade, cg_height_m, a_m, b_m, wheels_per_axle):
    """Normal load on each front and rear wheel, eqs (4)-(5) [N].

    Returns ``(F_zf, F_zr)``; they satisfy ``n (F_zf + F_zr) = m g cos(alpha)``.
    """
    alpha = np.arctan(grade)
    g = STANDARD_GRAVITY
    pitch = cg_height_m * (drag_n + mass_kg * g * np.sin(alpha) + mass_kg * accel_mps2)
    denom = wheels_per_axle * (a_m + b_m)
    fzf = (-pitch + b_m * mass_kg * g * np.cos(alpha)) / denom
    fzr = (pitch + a_m * mass_kg * g * np.cos(alpha)) / denom
    return fzf, fzr


@njit(cache=True)
def road_load_force(
    v_mps,
    accel_mps2,
    grade,
    mass_kg,
    mass_factor,
    cd,
    area_m2,
    rho_kgpm3,
    headwind_mps,
    crr,
    crr_speed_s_per_m,
):
    """Tractive force needed at the wheels, the road-load form of eq (32) [N].

    F = delta m a + F_drag + F_roll + m g sin(alpha), with the rolling term
    (:func:`rolling_force`, coefficients ``crr`` [-] and ``crr_speed_s_per_m`` [s/m]) active
    only while moving (``v_mps > 0``) and ``delta`` the rotating-mass factor. On level road in
    still air this is delta m a + A + B v + C v^2 with A = crr m g, B = crr_v m g,
    C = rho Cd A_f / 2: the coast-down form (:func:`coastdown_parameters`).
    """
    moving = v_mps > 0.0
    return (
        mass_factor * mass_kg * accel_mps2
        + aero_force(v_mps, headwind_mps, cd, area_m2, rho_kgpm3)
        + rolling_force(mass_kg, grade, crr, crr_speed_s_per_m, v_mps) * moving
        + grade_force(mass_kg, grade)
    )


COASTDOWN_FRONTAL_AREA_M2 = 1.0
"""Frontal area [m^2] a coast-down vehicle's body carries: its drag coefficient is then the
drag area ``2 C / rho`` [m^2] (only the product Cd A_f enters the road load)."""


def coastdown_parameters(
    a_n: float, b_n_per_m_s: float, c_n_per_m2_s2: float, test_mass_kg: float, rho_kgpm3: float
) -> dict[str, float]:
    """The body parameters that make :func:`road_load_force` equal the coast-down road load
    F = A + B v + C v^2 (EPA target coefficients, 40 CFR 1066.301) of a vehicle of equivalent
    test weight ``test_mass_kg`` [kg] on level road in still air: A [N] and B [N/(m/s)] become
    the rolling coefficients A / (m g) [-] and B / (m g) [s/m] (so a grade scales them by
    cos alpha, as it scales a tire's normal load), C [N/(m/s)^2] the drag area 2 C / rho
    [m^2] at the body's air density ``rho_kgpm3`` [kg/m^3]."""
    weight_n = test_mass_kg * STANDARD_GRAVITY
    return {
        "mass_kg": test_mass_kg,
        "rolling_resistance": a_n / weight_n,
        "rolling_resistance_speed_s_per_m": b_n_per_m_s / weight_n,
        "drag_coefficient": 2.0 * c_n_per_m2_s2 / (rho_kgpm3 * COASTDOWN_FRONTAL_AREA_M2),
        "frontal_area_m2": COASTDOWN_FRONTAL_AREA_M2,
    }


@dataclass(frozen=True)
class VehicleBody:
    """Two-axle vehicle body in longitudinal motion (Simscape Vehicle Body, thesis Table 2.2).

    Attributes are SI: mass [kg], frontal area [m^2], lengths [m], air density [kg/m^3],
    headwind [m/s]; ``mass_factor`` (rotating-mass factor, delta of eq 32) and the drag and
    rolling coefficients are dimensionless (the speed-proportional rolling coefficient
    ``rolling_resistance_speed_s_per_m`` is in s/m).
    """

    mass_kg: float = 1200.0
    drag_coefficient: float = 0.4
    frontal_area_m2: float = 3.0
    rolling_resistance: float = 0.0
    rolling_resistance_speed_s_per_m: float = 0.0
    mass_factor: float = 1.0
    air_density_kgpm3: float = AIR_DENSITY_KGPM3
    headwind_mps: float = 0.0
    cg_height_m: float = 0.5
    front_axle_to_cg_m: float = 1.4
    rear_axle_to_cg_m: float = 1.6
    wheels_per_axle: int = 2

    @classmethod
    def from_section(cls, section: object) -> VehicleBody:
        """Body from any configuration section with some of these fields (others default).

        A section in the coast-down form (``test_mass_kg`` > 0 with ``road_load_a_n``,
        ``road_load_b_n_per_m_s``, ``road_load_c_n_per_m2_s2``) gets its mass and road-load
        coefficients from :func:`coastdown_parameters`: the one place that form becomes the
        body every architecture, the DP and the performance envelope use.
        """
        names = [f.name for f in dataclasses.fields(cls)]
        values = {n: getattr(section, n) for n in names if hasattr(section, n)}
        if float(getattr(section, "test_mass_kg", 0.0) or 0.0) > 0.0:
            values.update(
                coastdown_parameters(
                    float(section.road_load_a_n),  # type: ignore[attr-defined]
                    float(section.road_load_b_n_per_m_s),  # type: ignore[attr-defined]
                    float(section.road_load_c_n_per_m2_s2),  # type: ignore[attr-defined]
                    float(section.test_mass_kg),  # type: ignore[attr-defined]
                    float(values.get("air_density_kgpm3", AIR_DENSITY_KGPM3)),
                )
            )
        return cls(**values)

    def road_load_force(self, v_mps, accel_mps2, grade=0.0):
        """Vectorised eq (32) [N] for arrays of speed [m/s], acceleration [m/s^2], grade [-]."""
        return road_load_force(
            np.asarray(v_mps, np.float64),
            np.asarray(accel_mps2, np.float64),
            np.asarray(grade, np.float64),
            self.mass_kg,
            self.mass_factor,
            self.drag_coefficient,
            self.frontal_area_m2,
            self.air_density_kgpm3,
            self.headwind_mps,
            self.rolling_resistance,
            self.rolling_resistance_speed_s_per_m,
        )

    def axle_normal_loads(self, accel_mps2, v_mps=0.0, grade=0.0):
        """Per-wheel normal loads (front, rear) [N], eqs (4)-(5)."""
        drag = aero_force(
            np.asarray(v_mps, np.float64),
            self.headwind_mps,
            self.drag_coefficient,
            self.frontal_area_m2,
            self.air_density_kgpm3,
        )
        return axle_normal_loads(
            self.mass_kg,
            np.asarray(accel_mps2, np.float64),
            drag,
            np.asarray(grade, np.float64),
            self.cg_height_m,
            self.front_axle_to_cg_m,
            self.rear_axle_to_cg_m,
            self.wheels_per_axle,
        )
