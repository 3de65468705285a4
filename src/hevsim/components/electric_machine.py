"""Electric machines: traction motor and generator (thesis sections 2.2 and 2.6, lecture 9).

Levels of fidelity: *ideal* (constant max torque, efficiency 1), *constant efficiency*, and
*map* (max motoring/generating torque vs speed and an efficiency map over speed x torque).
Electrical power is mechanical power / eta when motoring and x eta when generating:
``P_elec = T w eta^(-sign(T w))``. Torque > 0 motors, torque < 0 generates.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numba import njit

from hevsim.errors import InputError
from hevsim.tables import FloatArray, Table1D, Table2D, interp1, interp2, read_meta

MIN_EFFICIENCY = 0.05
"""Floor applied to efficiency-map values (source maps hold placeholders at zero speed) [-]."""


@njit(cache=True)
def electrical_power(torque_nm, omega_radps, efficiency):
    """Electrical power [W] (> 0 drawn from the bus) for shaft torque [N·m] and speed [rad/s]."""
    p_mech = torque_nm * omega_radps
    return p_mech * efficiency ** (-np.sign(p_mech))


@njit(cache=True)
def machine_efficiency(
    torque_nm, omega_radps, kind, const_eff, eff_x, eff_y, eff_z
):  # fmt: skip
    """Efficiency [-] (scalar kernel): kind 0 ideal, 1 constant, 2 map over ``|speed|`` x torque."""
    if kind == 0:
        return 1.0
    if kind == 1:
        return const_eff
    return max(interp2(eff_x, eff_y, eff_z, abs(omega_radps), torque_nm, False), MIN_EFFICIENCY)


@njit(cache=True)
def torque_limits(omega_radps, lim_x, lim_mot, lim_gen, torque_scale):
    """(max motoring torque >= 0, max generating torque <= 0) [N·m] at speed [rad/s]."""
    w = abs(omega_radps)
    return (
        torque_scale * interp1(lim_x, lim_mot, w, False),
        torque_scale * interp1(lim_x, lim_gen, w, False),
    )


KINDS = {"ideal": 0, "constant_efficiency": 1, "map": 2}


@dataclass(frozen=True, eq=False)
class ElectricMachine:
    """Motor/generator with its controller (SI).

    Attributes:
        name: label. kind: "ideal", "constant_efficiency" or "map".
        max_motoring_torque: max torque >= 0 [N·m] vs speed [rad/s].
        max_generating_torque: most negative torque <= 0 [N·m] vs speed [rad/s].
        efficiency: constant efficiency [-] (kind "constant_efficiency").
        efficiency_map: efficiency [-] over speed [rad/s] x torque [N·m] (kind "map").
        inertia_kgm2: rotor inertia [kg·m^2]. torque_scale: sizing factor on torque [-].
    """

    name: str
    kind: str
    max_motoring_torque: Table1D
    max_generating_torque: Table1D
    efficiency: float = 1.0
    efficiency_map: Table2D | None = None
    inertia_kgm2: float = 0.0
    torque_scale: float = 1.0

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise InputError(
                f"electric machine '{self.name}': kind {self.kind!r} is not known; expected one "
                f"of {', '.join(KINDS)}."
            )
        if self.kind == "map" and self.efficiency_map is None:
            raise InputError(f"electric machine '{self.name}': kind 'map' needs an efficiency map.")
        if not 0.0 < self.efficiency <= 1.0:
            raise InputError(
                f"electric machine '{self.name}': efficiency {self.efficiency!r} must be in (0, 1]."
            )

    @classmethod
    def constant_torque(
        cls, name: str, max_torque_nm: float, efficiency: float = 1.0, inertia_kgm2: float = 0.0
    ) -> ElectricMachine:
        """Machine with a constant max torque [N·m] at every speed and no rpm limit."""
        x = np.array([0.0])
        return cls(
            name=name,
            kind="ideal" if efficiency == 1.0 else "constant_efficiency",
            max_motoring_torque=Table1D(x, np.array([max_torque_nm])),
            max_generating_torque=Table1D(x, np.array([-max_torque_nm])),
            efficiency=efficiency,
            inertia_kgm2=inertia_kgm2,
        )

    @property
    def kind_code(self) -> int:
        """Integer code of ``kind`` used by compiled loops."""
        return KINDS[self.kind]

    def kernel_tables(self) -> tuple[FloatArray, ...]:
        """(lim_x, lim_mot, lim_gen, eff_x, eff_y, eff_z) for compiled loops."""
        if self.efficiency_map is not None:
            e = self.efficiency_map
        else:
            e = Table2D(np.array([0.0]), np.array([0.0]), np.ones((1, 1)))
        gen = self.max_generating_torque(self.max_motoring_torque.x)
        return (self.max_motoring_torque.x, self.max_motoring_torque.y, gen, e.x, e.y, e.z)

    def limits(self, omega_radps):
        """Vectorised (max motoring, max generating) torque [N·m] at speed [rad/s]."""
        w = np.abs(np.asarray(omega_radps, float))
        return (
            self.torque_scale * self.max_motoring_torque(w),
            self.torque_scale * self.max_generating_torque(w),
        )

    def efficiency_at(self, torque_nm, omega_radps):
        """Vectorised efficiency [-] at torque [N·m] and speed [rad/s]."""
        t, w = np.broadcast_arrays(np.asarray(torque_nm, float), np.asarray(omega_radps, float))
        if self.kind == "ideal":
            return np.ones(t.shape)
        if self.kind == "constant_efficiency":
            return np.full(t.shape, self.efficiency)
        assert self.efficiency_map is not None
        return np.maximum(self.efficiency_map(np.abs(w), t / self.torque_scale), MIN_EFFICIENCY)

    def electrical_power(self, torque_nm, omega_radps):
        """Vectorised electrical power [W] (> 0 drawn) at torque [N·m] and speed [rad/s]."""
        t = np.asarray(torque_nm, float)
        w = np.asarray(omega_radps, float)
        return electrical_power(t, w, self.efficiency_at(t, w))

    @classmethod
    def from_directory(cls, path: str | Path, **overrides: object) -> ElectricMachine:
        """Load a shipped-format motor folder (meta.toml, torque_limits.csv, efficiency_map.csv).

        Uses the continuous torque curve unless ``rating="peak"`` is passed in ``overrides``.
        """
        d = Path(path)
        meta = read_meta(d, "electric machine")
        rating = str(overrides.pop("rating", "cont"))
        if rating not in ("cont", "peak"):
            raise InputError(f"{d}: rating {rating!r} is not known; expected 'cont' or 'peak'.")
        lim = d / "torque_limits.csv"
        mot = Table1D.from_csv(lim, "speed_rad_per_s", f"max_motoring_torque_{rating}_N_m")
        gen = Table1D.from_csv(lim, "speed_rad_per_s", f"max_generating_torque_{rating}_N_m")
        if mot.x[0] < 0:  # generator tables hold negative speeds: keep the positive half
            keep = mot.x >= 0
            mot = Table1D(mot.x[keep], mot.y[keep], source=mot.source)
            gen = Table1D(gen.x[keep], gen.y[keep], source=gen.source)
        if np.all(gen.y == 0):  # generating limits missing: mirror the motoring curve
            gen = Table1D(mot.x, -mot.y, source=mot.source)
        eff = Table2D.from_long_csv(d / "efficiency_map.csv", "speed_rad_per_s", "torque_N_m", "efficiency")
        if eff.x[0] < 0:
            keep = eff.x >= 0
            eff = Table2D(eff.x[keep], eff.y, eff.z[keep], source=eff.source)
        params = meta.get("parameters", {})
        kwargs: dict[str, object] = {
            "name": str(meta.get("name", d.name)),
            "kind": "map",
            "max_motoring_torque": mot,
            "max_generating_torque": gen,
            "efficiency_map": eff,
            "inertia_kgm2": float(params.get("rotor_inertia_kg_m2", 0.0)),
        }
        kwargs.update(overrides)
        return cls(**kwargs)  # type: ignore[arg-type]
