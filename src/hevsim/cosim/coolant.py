"""The coolant channel as a co-simulation participant (the thesis's Abaqus/CFD fluid model).

A 1-D quasi-steady channel (:class:`hevsim.thermal.coolant.ChannelModel`) cut into
``segments`` pieces along the flow path. Exchange with the cooling plate, as in the thesis's
co-simulation (section 4.1.4: the plate's wall temperature to the fluid model, the fluid
model's heat flux and lumped heat capacitance back):

Inputs, per segment i = 0 .. segments-1: ``wall<i>_temp_k`` [K, mean wall temperature] and
``wall<i>_area_m2`` [m^2, wetted wall area of the segment on the plate's mesh]; optionally
``inlet_temp_k`` [K].
Outputs, per segment: ``wall<i>_heat_flux_w_m2`` [W/m^2, from the wall into the coolant],
``wall<i>_film_w_m2k`` [W/(m^2 K), the film coefficient: d(heat flux)/d(wall temperature)
at fixed fluid temperature, the "lumped heat capacitance" of the thesis's exchange] and
``wall<i>_fluid_temp_k`` [K, segment-mean fluid temperature]; and ``outlet_temp_k`` [K],
``cooling_power_w`` [W, m_dot c_p (T_out - T_in)].

The channel is quasi-steady (the coolant crosses the plate in well under a second), so the
outputs are a function of the current inputs: the heat flux out of the wall equals the
coolant's enthalpy rise exactly, segment by segment. Fluid properties are taken at the
configured inlet temperature.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from hevsim.cosim.participant import Participant, store_inputs
from hevsim.errors import ConfigError
from hevsim.units import KELVIN_OFFSET


class CoolantChannelParticipant(Participant):
    """See the module docstring. ``config`` is a thermal TOML (``hevsim thermal``) whose
    ``[coolant]`` section and channel cross-section are used; keywords override them:
    ``segments``, ``inlet_temp_k`` [K], ``flow_l_min`` [L/min]."""

    def __init__(
        self,
        name: str,
        config: str | Path | Any,
        segments: int | None = None,
        inlet_temp_k: float | None = None,
        flow_l_min: float | None = None,
    ):
        from hevsim.thermal.coolant import ChannelModel
        from hevsim.thermal.run import LITRE_PER_MIN_M3_S, coolant_from_section, load_thermal_config

        self.name = name
        cfg = load_thermal_config(config) if isinstance(config, str | Path) else config
        cool = cfg.coolant
        n = int(segments if segments is not None else cool.segments)
        if n < 1:
            raise ConfigError(f"participant {name!r}: segments = {n}; expected at least 1.")
        self.n_segments = n
        t_in = float(inlet_temp_k) if inlet_temp_k is not None else cool.inlet_temp_c + KELVIN_OFFSET
        flow = float(flow_l_min) if flow_l_min is not None else cool.flow_l_min
        self.channel = ChannelModel(
            n,
            inlet_temp_k=t_in,
            flow_m3_s=flow * LITRE_PER_MIN_M3_S,
            width_m=cfg.geometry.channel_width_m,
            height_m=cfg.geometry.channel_height_m,
            coolant=coolant_from_section(cool),
        )
        self.inputs = {
            "inlet_temp_k": "K",
            **{f"wall{i}_temp_k": "K" for i in range(n)},
            **{f"wall{i}_area_m2": "m2" for i in range(n)},
        }
        self.outputs = {
            **{f"wall{i}_heat_flux_w_m2": "W/m2" for i in range(n)},
            **{f"wall{i}_film_w_m2k": "W/(m2.K)" for i in range(n)},
            **{f"wall{i}_fluid_temp_k": "K" for i in range(n)},
            "outlet_temp_k": "K",
            "cooling_power_w": "W",
        }
        # before any wall temperature arrives the wall is at the inlet temperature (no heat)
        self.u: dict[str, float] = {k: t_in if k.endswith("_k") else 0.0 for k in self.inputs}

    def set_inputs(self, values: Mapping[str, float]) -> None:
        store_inputs(self, self.u, values)

    def do_step(self, t: float, h: float) -> tuple[bool, float | None]:
        return True, None  # quasi-steady: the outputs follow the inputs (see get_outputs)

    def get_outputs(self) -> dict[str, float]:
        n, u, ch = self.n_segments, self.u, self.channel
        wall = np.array([u[f"wall{i}_temp_k"] for i in range(n)])
        area = np.array([u[f"wall{i}_area_m2"] for i in range(n)])
        if not (np.all(np.isfinite(wall)) and np.all(wall > 0.0) and np.all(area >= 0.0)):
            raise ConfigError(
                f"participant {self.name!r}: wall temperatures {wall.tolist()} K / areas {area.tolist()} m^2 "
                "are not physical; expected temperatures > 0 K and areas >= 0."
            )
        ch.inlet_temp_k = u["inlet_temp_k"]
        fluid = ch.fluid_temperature_k(wall, area)
        h = ch.heat_transfer_coefficient_w_m2k()
        flux = h * (wall - fluid)
        out = {f"wall{i}_heat_flux_w_m2": float(flux[i]) for i in range(n)}
        out.update({f"wall{i}_film_w_m2k": float(h[i]) for i in range(n)})
        out.update({f"wall{i}_fluid_temp_k": float(fluid[i]) for i in range(n)})
        out.update(outlet_temp_k=float(ch.outlet_temp_k), cooling_power_w=float(ch.heat_w))
        return out

    def get_state(self) -> Any:
        return dict(self.u)

    def set_state(self, state: Any) -> None:
        self.u = dict(state)
