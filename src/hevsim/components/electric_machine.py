"""Electric machines: traction motor and generator (thesis sections 2.2 and 2.6, lecture 9).

Levels of fidelity: *ideal* (constant max torque, efficiency 1), *constant efficiency*, and
*map* (max motoring/generating torque vs speed and an efficiency map over speed x torque).
Electrical power is mechanical power / eta when motoring and x eta when generating:
``P_elec = T w eta^(-sign(T w))``. Torque > 0 motors, torque < 0 generates.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import NamedTuple

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
    # eta^(-sign(p_mech)) without a libm pow call (about 20 ns, 15 % of a forward run): the
    # same values, eta^-1 = 1 / eta as LLVM itself folds a constant pow(x, -1); eta^1 = eta
    # and eta^0 = 1 exactly (a NaN power falls through unchanged, as NaN^-NaN x NaN did)
    if p_mech > 0.0:
        return p_mech * (1.0 / efficiency)
    if p_mech < 0.0:
        return p_mech * efficiency
    return p_mech * 1.0


class MachineTables(NamedTuple):
    """A machine's tables for compiled code, by name (a swapped array is a name error).

    ``lim_x`` speed axis [rad/s] of ``lim_mot`` (max motoring torque >= 0 [N·m]) and
    ``lim_gen`` (max generating torque <= 0 [N·m]); ``eff_z`` efficiency [-] over ``eff_x``
    speed [rad/s] x ``eff_y`` torque [N·m] of the unscaled (``torque_scale`` = 1) machine.
    """

    lim_x: FloatArray
    lim_mot: FloatArray
    lim_gen: FloatArray
    eff_x: FloatArray
    eff_y: FloatArray
    eff_z: FloatArray


@njit(cache=True, inline="always")
def efficiency_from_map(torque_nm, omega_radps, kind, const_eff, torque_scale, eff_x, eff_y, eff_z):
    """Efficiency [-] (scalar kernel): kind 0 ideal, 1 constant, 2 map over ``|speed|`` x torque.

    A machine sized by ``torque_scale`` scales the torque axis of its map with it: the map is
    read at ``torque_nm / torque_scale`` (a machine twice as long has twice the torque at the
    same efficiency, the usual linear scaling of a machine map). Arrays as in
    :class:`MachineTables` (compiled loops unpack the tables once and call this).
    """
    if kind == 0:
        return 1.0
    if kind == 1:
        return const_eff
    eff = interp2(eff_x, eff_y, eff_z, abs(omega_radps), torque_nm / torque_scale, False)
    return max(eff, MIN_EFFICIENCY)


@njit(cache=True, inline="always")
def power_from_map(torque_nm, omega_radps, kind, const_eff, torque_scale, eff_x, eff_y, eff_z):
    """Electrical power [W] (> 0 drawn) at torque [N·m] and speed [rad/s] (scalar kernel)."""
    eta = efficiency_from_map(torque_nm, omega_radps, kind, const_eff, torque_scale, eff_x, eff_y, eff_z)
    return electrical_power(torque_nm, omega_radps, eta)


@njit(cache=True, inline="always")
def limits_from_curves(omega_radps, torque_scale, lim_x, lim_mot, lim_gen):
    """(max motoring torque >= 0, max generating torque <= 0) [N·m] at speed [rad/s]."""
    w = abs(omega_radps)
    return (
        torque_scale * interp1(lim_x, lim_mot, w, False),
        torque_scale * interp1(lim_x, lim_gen, w, False),
    )


# The same three kernels reading a :class:`MachineTables` by name. Passing the tuple costs
# reference counting on each of its arrays per call (about 50 ns): per-step code may use
# these, loops over many points unpack the tables once and call the kernels above.
@njit(cache=True, inline="always")
def machine_efficiency(torque_nm, omega_radps, kind, const_eff, torque_scale, tab):
    """:func:`efficiency_from_map` with the machine's :class:`MachineTables`."""
    return efficiency_from_map(
        torque_nm, omega_radps, kind, const_eff, torque_scale, eff_x=tab.eff_x, eff_y=tab.eff_y,
        eff_z=tab.eff_z,
    )  # fmt: skip


@njit(cache=True, inline="always")
def machine_power(torque_nm, omega_radps, kind, const_eff, torque_scale, tab):
    """:func:`power_from_map` with the machine's :class:`MachineTables`."""
    return power_from_map(
        torque_nm, omega_radps, kind, const_eff, torque_scale, eff_x=tab.eff_x, eff_y=tab.eff_y,
        eff_z=tab.eff_z,
    )  # fmt: skip


@njit(cache=True, inline="always")
def torque_limits(omega_radps, torque_scale, tab):
    """:func:`limits_from_curves` with the machine's :class:`MachineTables`."""
    return limits_from_curves(
        omega_radps, torque_scale, lim_x=tab.lim_x, lim_mot=tab.lim_mot, lim_gen=tab.lim_gen
    )


@njit(cache=True)
def _efficiency_many(torque_nm, omega_radps, kind, const_eff, torque_scale, tab):
    """:func:`efficiency_from_map` over flat arrays of torque [N·m] and speed [rad/s]."""
    eff_x, eff_y, eff_z = tab.eff_x, tab.eff_y, tab.eff_z
    out = np.empty(torque_nm.shape[0])
    for i in range(torque_nm.shape[0]):
        out[i] = efficiency_from_map(
            torque_nm[i], omega_radps[i], kind, const_eff, torque_scale, eff_x, eff_y, eff_z
        )
    return out


@njit(cache=True)
def _power_many(torque_nm, omega_radps, kind, const_eff, torque_scale, tab):
    """:func:`power_from_map` over flat arrays of torque [N·m] and speed [rad/s] -> [W]."""
    eff_x, eff_y, eff_z = tab.eff_x, tab.eff_y, tab.eff_z
    out = np.empty(torque_nm.shape[0])
    for i in range(torque_nm.shape[0]):
        out[i] = power_from_map(
            torque_nm[i], omega_radps[i], kind, const_eff, torque_scale, eff_x, eff_y, eff_z
        )
    return out


@njit(cache=True)
def _limits_many(omega_radps, torque_scale, tab):
    """:func:`limits_from_curves` over a flat array of speed [rad/s] -> two arrays [N·m]."""
    lim_x, lim_mot, lim_gen = tab.lim_x, tab.lim_mot, tab.lim_gen
    t_mot = np.empty(omega_radps.shape[0])
    t_gen = np.empty(omega_radps.shape[0])
    for i in range(omega_radps.shape[0]):
        t_mot[i], t_gen[i] = limits_from_curves(omega_radps[i], torque_scale, lim_x, lim_mot, lim_gen)
    return t_mot, t_gen


def _flat(*arrays: object) -> tuple[tuple[int, ...], list[FloatArray]]:
    """Broadcast arrays, return the shape and contiguous flat float64 copies."""
    b = np.broadcast_arrays(*(np.asarray(a, np.float64) for a in arrays))
    return b[0].shape, [np.ascontiguousarray(x.ravel()) for x in b]


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

    def kernel_tables(self) -> MachineTables:
        """The machine's tables for compiled code (:class:`MachineTables`; built once).

        The generating limit is resampled on the motoring limit's speed axis."""
        return self._tables

    @cached_property
    def _tables(self) -> MachineTables:
        if self.efficiency_map is not None:
            e = self.efficiency_map
        else:
            e = Table2D(np.array([0.0]), np.array([0.0]), np.ones((1, 1)))
        gen = self.max_generating_torque(self.max_motoring_torque.x)
        m = self.max_motoring_torque
        return MachineTables(lim_x=m.x, lim_mot=m.y, lim_gen=gen, eff_x=e.x, eff_y=e.y, eff_z=e.z)

    def limits(self, omega_radps):
        """Vectorised (max motoring, max generating) torque [N·m] at speed [rad/s]."""
        shape, (w,) = _flat(omega_radps)
        t_mot, t_gen = _limits_many(w, self.torque_scale, self.kernel_tables())
        return t_mot.reshape(shape), t_gen.reshape(shape)

    def efficiency_at(self, torque_nm, omega_radps):
        """Vectorised efficiency [-] at torque [N·m] and speed [rad/s] (the map read at
        ``torque / torque_scale``, see :func:`machine_efficiency`)."""
        shape, (t, w) = _flat(torque_nm, omega_radps)
        tab = self.kernel_tables()
        return _efficiency_many(t, w, self.kind_code, self.efficiency, self.torque_scale, tab).reshape(shape)

    def electrical_power(self, torque_nm, omega_radps):
        """Vectorised electrical power [W] (> 0 drawn) at torque [N·m] and speed [rad/s]."""
        shape, (t, w) = _flat(torque_nm, omega_radps)
        tab = self.kernel_tables()
        return _power_many(t, w, self.kind_code, self.efficiency, self.torque_scale, tab).reshape(shape)

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
        header = lim.read_text(encoding="utf-8").split("\n", 1)[0].split(",") if lim.is_file() else []
        if "max_torque_N_m" in header and f"max_motoring_torque_{rating}_N_m" not in header:
            # one symmetric curve (ADVISOR generator files, e.g. the Prius MG1): both directions
            mot = Table1D.from_csv(lim, "speed_rad_per_s", "max_torque_N_m")
            gen = Table1D(mot.x, -mot.y, source=mot.source)
        else:
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
