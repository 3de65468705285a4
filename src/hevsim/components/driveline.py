"""Tire and gear / final drive.

The tire rolls without slip (the thesis's assumption): ``v = r_w * omega_wheel``. An optional
longitudinal Magic-Formula (Pacejka) model gives the force for a given slip ratio and normal
load. The gear has a ratio and an efficiency applied in the direction of power flow: when the
motor drives the wheels the wheel torque is ``T_in * ratio * eta``; when the wheels drive the
motor (braking) it is ``T_in * ratio / eta``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit, types
from numba.extending import overload


def efficiency_factor(torque_nm, efficiency):
    """``efficiency ** sign(torque_nm)`` [-]: the efficiency in the direction of power flow."""
    return efficiency ** np.sign(torque_nm)


@overload(efficiency_factor)
def _efficiency_factor(torque_nm, efficiency):
    if isinstance(torque_nm, types.Number):

        def scalar(torque_nm, efficiency):
            # compiled per-point code: no libm pow call (eta^-1 as one reciprocal, as LLVM folds
            # a constant pow(x, -1); eta^1 and eta^0 exactly; a NaN torque gives NaN anyway)
            if torque_nm > 0.0:
                return efficiency * 1.0
            if torque_nm < 0.0:
                return 1.0 / efficiency
            return 1.0

        return scalar
    return lambda torque_nm, efficiency: efficiency ** np.sign(torque_nm)


@njit(cache=True)
def gear_output_torque(torque_in_nm, ratio, efficiency):
    """Output-shaft torque [N·m] for input torque [N·m] at positive speed.

    ``efficiency ** sign(T)``: multiplied when motoring (T > 0), divided when braking.
    """
    return torque_in_nm * ratio * efficiency_factor(torque_in_nm, efficiency)


@njit(cache=True)
def gear_input_torque(torque_out_nm, ratio, efficiency):
    """Input-shaft torque [N·m] needed for an output torque [N·m] at positive speed."""
    return torque_out_nm / (ratio * efficiency_factor(torque_out_nm, efficiency))


@njit(cache=True)
def magic_formula_force(slip, normal_load_n, b, c, d, e):
    """Longitudinal Pacejka Magic Formula: F = Fz D sin(C atan(B k - E (B k - atan(B k)))) [N]."""
    bk = b * slip
    return normal_load_n * d * np.sin(c * np.arctan(bk - e * (bk - np.arctan(bk))))


@dataclass(frozen=True)
class Tire:
    """Tire with rolling radius [m]; optional Magic-Formula coefficients (B, C, D, E).

    The defaults B=10, C=1.9, D=1, E=0.97 are the dry-tarmac coefficients of the Simscape
    Tire (Magic Formula) block the thesis uses.
    """

    radius_m: float = 0.3
    slip_model: str = "none"
    mf_b: float = 10.0
    mf_c: float = 1.9
    mf_d: float = 1.0
    mf_e: float = 0.97

    def wheel_speed_radps(self, v_mps):
        """Wheel speed [rad/s] for vehicle speed [m/s] without slip."""
        return np.asarray(v_mps, np.float64) / self.radius_m

    def longitudinal_force(self, slip, normal_load_n):
        """Magic-Formula longitudinal force [N] at slip ratio [-] and normal load [N]."""
        return magic_formula_force(
            np.asarray(slip, np.float64),
            np.asarray(normal_load_n, np.float64),
            self.mf_b,
            self.mf_c,
            self.mf_d,
            self.mf_e,
        )

    def slip_for_force(self, force_n, normal_load_n):
        """Slip ratio [-] that transmits ``force_n`` [N] (inverse on the stable branch).

        Forces beyond the peak return the peak slip (the tire saturates).
        """
        k = np.linspace(-0.3, 0.3, 6001)
        f_unit = magic_formula_force(k, 1.0, self.mf_b, self.mf_c, self.mf_d, self.mf_e)
        peak = int(np.argmax(f_unit))
        trough = int(np.argmin(f_unit))
        ks, fs = k[trough : peak + 1], f_unit[trough : peak + 1]
        ratio = np.asarray(force_n, np.float64) / np.asarray(normal_load_n, np.float64)
        return np.interp(ratio, fs, ks)


@dataclass(frozen=True)
class Gear:
    """Fixed-ratio gear or final drive: ratio [-] (input speed / output speed), efficiency [-]."""

    ratio: float = 2.0
    efficiency: float = 1.0

    def output_torque(self, torque_in_nm):
        """Output torque [N·m] for input torque [N·m] (efficiency in the power-flow direction)."""
        return gear_output_torque(np.asarray(torque_in_nm, np.float64), self.ratio, self.efficiency)

    def input_torque(self, torque_out_nm):
        """Input torque [N·m] for a required output torque [N·m]."""
        return gear_input_torque(np.asarray(torque_out_nm, np.float64), self.ratio, self.efficiency)
