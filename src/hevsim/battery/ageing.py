"""State of health (thesis eqs 42-44) and semi-empirical ageing over a repeated usage profile.

The ageing model (data file ``hevsim/data/cells/ageing/wang2011_schmalstieg2014.toml``, with
its sources) gives the capacity loss and the resistance growth as functions of time,
charge throughput, temperature (Arrhenius), C-rate, mean voltage and depth of discharge:

* cycle capacity fade, Wang et al. 2011: ``Q_loss = B(C_rate) exp(-(Ea - 370.3 C_rate)/(R T)) Ah^0.55`` [%];
* calendar capacity fade and resistance growth, Schmalstieg et al. 2014: ``α(V, T) t^0.75``;
* cycle resistance growth, Schmalstieg et al. 2014: ``β_res(V_mean, DOD) Q``.

:func:`age_cell` simulates the profile with the electro-thermal model, derives the stress
of one repetition, advances the ageing state with the virtual time/throughput method, feeds
the new capacity (C0 scale) and resistance (R scale) back into the cell, and repeats.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from hevsim.battery import kernel as K
from hevsim.battery.cell import Cell, CellResult
from hevsim.battery.params import CellParameters, load_cell_parameters
from hevsim.errors import ConfigError, InputError
from hevsim.schema import read_toml

SECONDS_PER_DAY = 86400.0
SECONDS_PER_HOUR = 3600.0


def soh_capacity(capacity_c: npt.ArrayLike, c0_c: float, x_c: float) -> Any:
    """SOH_C per eq (43): 1 at C = C0, 0 at C = x_C C0."""
    return np.asarray(capacity_c) / (c0_c * (1.0 - x_c)) - x_c / (1.0 - x_c)


def soh_impedance(z_ohm: npt.ArrayLike, z0_ohm: float, x_z: float) -> Any:
    """SOH_Z per eq (44): 1 at Z = Z0, 0 at Z = x_Z Z0."""
    return np.asarray(z_ohm) / (z0_ohm * (1.0 - x_z)) - x_z / (1.0 - x_z)


def soh(soh_c: npt.ArrayLike, soh_z: npt.ArrayLike) -> Any:
    """SOH = SOH_C x SOH_Z, eq (42)."""
    return np.asarray(soh_c) * np.asarray(soh_z)


SOH_DEFINITION = (
    "SOH = SOH_C x SOH_Z (thesis eq 42): SOH_C = (C/C0 - x_C)/(1 - x_C) (eq 43), C = aged capacity at the "
    "reference temperature T_ref, C0 = nominal capacity of the new cell; SOH_Z = (Z/Z0 - x_Z)/(1 - x_Z) "
    "(eq 44), Z/Z0 = resistance growth; 1 = new cell, 0 = end of life (C = x_C C0 or Z = x_Z Z0). "
    "The temperature's effect on the available capacity is not ageing and is not counted."
)
"""One-paragraph definition of the SOH that :func:`age_cell` and the FMUs report."""


def reference_capacity_c(prm: npt.ArrayLike, qabs_c: npt.ArrayLike) -> Any:
    """Capacity [C] at the reference temperature, eq (35) at T = T_ref: ``C0 + k_CQabs Q_abs``.

    ``prm``: parameter vector(s) of :mod:`hevsim.battery.kernel` (last axis); ``qabs_c`` [C]:
    absolute transferred charge. The temperature terms of eq (35) (``alpha_C`` and the
    capacity-factor table, normalised at T_ref) change the *available* capacity, not the
    health, so they are left out: a new cell has this capacity equal to C0 at any temperature.
    """
    p = np.asarray(prm, float)
    return p[..., K.C0] + p[..., K.KCQ] * np.asarray(qabs_c, float)


def soh_of_state(prm: npt.ArrayLike, qabs_c: npt.ArrayLike, c0_nominal_c: npt.ArrayLike, x_c: float) -> Any:
    """SOH_C (eq 43) of cell state(s): the capacity at T_ref (:func:`reference_capacity_c`) against
    the nominal capacity ``c0_nominal_c`` [C]; exactly 1 for a new cell at any temperature."""
    ratio = reference_capacity_c(prm, qabs_c) / np.asarray(c0_nominal_c, float)
    return soh_capacity(ratio, 1.0, x_c)


@dataclass(frozen=True)
class Stress:
    """Stress of one repetition of a profile (all for one cell)."""

    duration_s: float
    throughput_ah: float  # discharged charge [A h]
    c_rate: float  # mean |I| / capacity while current flows [1/h]
    temp_k: float  # Arrhenius-effective mean temperature [K]
    mean_ocv_v: float
    dod: float  # SOC range of the repetition [-]


@dataclass(frozen=True, eq=False)
class AgeingModel:
    """Parameters of the ageing model (see the module docstring and the data file)."""

    name: str
    data: dict[str, Any]
    source: str

    def _s(self, section: str, key: str) -> Any:
        try:
            return self.data[section][key]
        except KeyError as exc:
            raise ConfigError(f"{self.source}: key '{section}.{key}' is missing.") from exc

    def cycle_capacity_rate(self, s: Stress) -> float:
        """k in ``loss = k Ah_ref^z`` (fraction of C0) for a stress."""
        c_rates = np.asarray(self._s("cycle_capacity", "c_rate"), float)
        b = np.asarray(self._s("cycle_capacity", "b_percent"), float)
        bb = float(np.interp(s.c_rate, c_rates, b))
        ea = (
            self._s("cycle_capacity", "activation_energy_j_per_mol")
            - self._s("cycle_capacity", "c_rate_coefficient_j_per_mol") * s.c_rate
        )
        return bb / 100.0 * math.exp(-ea / (self._s("cycle_capacity", "gas_constant_j_per_molk") * s.temp_k))

    def calendar_rates(self, s: Stress) -> tuple[float, float]:
        """(α_cap, α_res) per day^0.75 at the mean voltage and temperature (>= 0)."""
        g = self.data["calendar"]
        a_cap = (g["cap_v_coefficient_per_v"] * s.mean_ocv_v + g["cap_offset"]) * g["cap_scale"]
        a_cap *= math.exp(-g["cap_temperature_k"] / s.temp_k)
        a_res = (g["res_v_coefficient_per_v"] * s.mean_ocv_v + g["res_offset"]) * g["res_scale"]
        a_res *= math.exp(-g["res_temperature_k"] / s.temp_k)
        return max(a_cap, 0.0), max(a_res, 0.0)

    def cycle_resistance_rate(self, s: Stress) -> float:
        """β_res per A h of the reference cell (>= 0)."""
        g = self.data["cycle_resistance"]
        b = (
            g["quadratic_per_v2"] * (s.mean_ocv_v - g["v_centre_v"]) ** 2
            + g["offset"]
            + g["dod_coefficient"] * s.dod
        )
        return max(b, 0.0)


def load_ageing_model(name_or_path: str | Path = "wang2011_schmalstieg2014") -> AgeingModel:
    """Load a shipped ageing model by name or a TOML file."""
    p = Path(name_or_path)
    if not p.suffix:
        folder = resources.files("hevsim") / "data" / "cells" / "ageing"
        names = sorted(f.name[:-5] for f in folder.iterdir() if f.name.endswith(".toml"))
        if str(name_or_path) not in names:
            raise ConfigError(
                f"ageing model {str(name_or_path)!r} is not known; shipped: {', '.join(names)}."
            )
        p = Path(str(folder / f"{name_or_path}.toml"))
    data = read_toml(p)
    for section in ("cycle_capacity", "calendar", "cycle_resistance"):
        if not isinstance(data.get(section), dict):
            raise ConfigError(f"{p}: section [{section}] is missing.")
    return AgeingModel(str(data.get("name", p.stem)), data, str(p))


@dataclass
class AgeingState:
    """Accumulated ageing: capacity loss parts (fractions of C0) and resistance growth."""

    time_s: float = 0.0
    throughput_ah: float = 0.0
    loss_cycle: float = 0.0
    loss_calendar: float = 0.0
    growth_calendar: float = 0.0
    growth_cycle: float = 0.0

    @property
    def capacity_fraction(self) -> float:
        """C / C0 [-]."""
        return max(1.0 - self.loss_cycle - self.loss_calendar, 0.0)

    @property
    def resistance_fraction(self) -> float:
        """R / R0 [-]."""
        return 1.0 + self.growth_calendar + self.growth_cycle


def _advance_power(loss: float, rate: float, exponent: float, dx: float) -> float:
    """Advance ``loss = rate x^exponent`` by dx with the virtual-x method."""
    if rate <= 0.0:
        return loss
    x_virtual = (loss / rate) ** (1.0 / exponent)
    return rate * (x_virtual + dx) ** exponent


def advance(
    model: AgeingModel, state: AgeingState, s: Stress, nominal_capacity_ah: float, reps: int = 1
) -> None:
    """Advance ``state`` by ``reps`` repetitions of stress ``s`` (in place)."""
    cc = model.data["cycle_capacity"]
    scale_w = cc["reference_capacity_ah"] / nominal_capacity_ah
    scale_s = model.data["cycle_resistance"]["reference_capacity_ah"] / nominal_capacity_ah
    k = model.cycle_capacity_rate(s)
    a_cap, a_res = model.calendar_rates(s)
    b_res = model.cycle_resistance_rate(s)
    z_cal = model.data["calendar"]["exponent"]
    dt_days = reps * s.duration_s / SECONDS_PER_DAY
    state.loss_cycle = _advance_power(state.loss_cycle, k, cc["exponent"], reps * s.throughput_ah * scale_w)
    state.loss_calendar = _advance_power(state.loss_calendar, a_cap, z_cal, dt_days)
    state.growth_calendar = _advance_power(state.growth_calendar, a_res, z_cal, dt_days)
    state.growth_cycle += b_res * reps * s.throughput_ah * scale_s
    state.time_s += reps * s.duration_s
    state.throughput_ah += reps * s.throughput_ah


def stress_of(result: CellResult, dt: float, activation_temperature_k: float = 31700.0 / 8.314) -> Stress:
    """Stress of one simulated repetition (Arrhenius-weighted mean temperature)."""
    ts = result.timeseries
    i = ts["current_a"].to_numpy()
    cap_ah = float(ts["capacity_c"].mean()) / SECONDS_PER_HOUR
    moving = np.abs(i) > 0
    c_rate = float(np.abs(i[moving]).mean() / cap_ah) if moving.any() else 0.0
    temp = ts["temp_k"].to_numpy()
    w = np.exp(-activation_temperature_k / temp).mean()
    t_eff = -activation_temperature_k / math.log(w)
    soc = ts["soc"].to_numpy()
    return Stress(
        duration_s=float(i.size * dt),
        throughput_ah=float(np.clip(i, 0, None).sum() * dt / SECONDS_PER_HOUR),
        c_rate=c_rate,
        temp_k=float(t_eff),
        mean_ocv_v=float(ts["ocv_v"].mean()),
        dod=float(np.ptp(np.r_[result.metadata.get("soc_initial", soc[0]), soc])),
    )


def age_cell(
    params: CellParameters | str | Path,
    current_profile: npt.ArrayLike,
    dt: float,
    repetitions: int,
    port_temperature: float = 298.15,
    soc_initial: float = 0.9,
    model: AgeingModel | str | None = None,
    resimulate_every: int = 0,
    rest_s: float = 0.0,
) -> pd.DataFrame:
    """Age one cell over ``repetitions`` of ``current_profile`` [A] at step ``dt`` [s].

    Each repetition starts at ``soc_initial`` (the cell is recharged in between) and is
    followed by ``rest_s`` [s] of calendar ageing. The electro-thermal simulation is redone
    with the aged capacity and resistance every ``resimulate_every`` repetitions (default:
    about 50 times over the run). Returns one row per simulated block: repetition, time,
    throughput, capacity and resistance fractions, SOH_C, SOH_Z, SOH (eqs 42-44).
    """
    p = params if isinstance(params, CellParameters) else load_cell_parameters(params)
    if repetitions < 1:
        raise InputError(f"age_cell: repetitions {repetitions!r} must be >= 1.")
    if rest_s < 0:
        raise InputError(f"age_cell: rest_s {rest_s!r} must be >= 0.")
    m = model if isinstance(model, AgeingModel) else load_ageing_model(model or "wang2011_schmalstieg2014")
    every = resimulate_every or max(1, repetitions // 50)
    state = AgeingState()
    z0 = 1.0
    rows = [_row(0, state, p, z0)]
    done = 0
    temp_k = port_temperature
    profile = np.asarray(current_profile, float)
    while done < repetitions:
        block = min(every, repetitions - done)
        cell = Cell(p, soc_initial=soc_initial, temp_k=temp_k)
        cell.p[K.C0] *= state.capacity_fraction
        cell.p[K.RSCALE] = state.resistance_fraction
        res = cell.simulate(profile, dt, port_temperature)
        s = stress_of(res, dt)
        if rest_s > 0:
            s = Stress(s.duration_s + rest_s, s.throughput_ah, s.c_rate, s.temp_k, s.mean_ocv_v, s.dod)
        advance(m, state, s, p.nominal_capacity_ah, block)
        done += block
        temp_k = float(res.timeseries["temp_k"].iloc[-1])
        rows.append(_row(done, state, p, z0))
    return pd.DataFrame(rows)


def _row(rep: int, state: AgeingState, p: CellParameters, z0: float) -> dict[str, float]:
    cf, rf = state.capacity_fraction, state.resistance_fraction
    sc = float(soh_capacity(cf * p.capacity.c0_c, p.capacity.c0_c, p.ageing.x_c))
    sz = float(soh_impedance(rf * z0, z0, p.ageing.x_z))
    return {
        "repetition": rep,
        "time_days": state.time_s / SECONDS_PER_DAY,
        "throughput_ah": state.throughput_ah,
        "equivalent_full_cycles": state.throughput_ah / p.nominal_capacity_ah,
        "capacity_ah": cf * p.nominal_capacity_ah,
        "capacity_fraction": cf,
        "resistance_fraction": rf,
        "loss_cycle": state.loss_cycle,
        "loss_calendar": state.loss_calendar,
        "soh_c": sc,
        "soh_z": sz,
        "soh": sc * sz,
    }
