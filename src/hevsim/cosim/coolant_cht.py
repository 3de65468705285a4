"""The coolant as a 3-D laminar conjugate-heat-transfer participant (frozen flow).

Same interface as :class:`hevsim.cosim.coolant.CoolantChannelParticipant` (the 1-D channel),
so the module co-simulation runs with either coolant model: inputs per segment
``wall<i>_temp_k`` [K] and ``wall<i>_area_m2`` [m^2, the segment's wetted area on the plate's
mesh], optionally ``inlet_temp_k`` [K]; outputs per segment ``wall<i>_heat_flux_w_m2``
[W/m^2, from the wall into the coolant], ``wall<i>_film_w_m2k`` [W/(m^2 K)] and
``wall<i>_fluid_temp_k`` [K], and ``outlet_temp_k`` [K], ``cooling_power_w`` [W].

Inside: the laminar flow in the plate's channel (:func:`hevsim.thermal.flow.solve_flow`,
solved once at construction and frozen: the coolant properties are constant, so the flow does
not depend on the temperatures) and heat advection-diffusion in it
(:class:`hevsim.thermal.cht.CoolantThermal`) with the plate's wall temperature per segment
imposed on the channel wall. The heat per segment [W] is divided by the plate mesh's segment
area, so the plate receives exactly the heat the coolant takes. The film is the segment's own
sensitivity ``d(heat_i)/d(T_wall,i) / A_i`` and the fluid temperature the sink
``T_wall - flux / film``, so the plate's film condition reproduces the coolant's heat at the
current wall temperature and linearises it around it.

Quasi-steady by default, like the 1-D channel (the outputs follow the current inputs through
the precomputed linear response: one small matrix product per exchange); ``transient=True``
keeps the coolant's temperature field as a state and advances it by implicit Euler over each
co-simulation step.

Above the laminar limit (``flow.model = "auto"``, the default) the flow is a RANS solution
from OpenFOAM (:mod:`hevsim.thermal.rans`, about a minute of CPU on the shipped plate at
10 L/min), frozen like the laminar one, and the coolant's wall layer is bridged by the
thermal wall function (``flow.thermal_wall``, :mod:`hevsim.thermal.wall_function`); the
example ``module_cht.ssd`` runs at a laminar flow rate, ``run_module_cht.py --flow-l-min 10``
at the thesis's (docs/flow.md).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from hevsim.cosim.coolant import CoolantChannelParticipant
from hevsim.errors import ConfigError


class CoolantCHTParticipant(CoolantChannelParticipant):
    """See the module docstring. ``config``: a module TOML (``hevsim thermal`` / ``hevsim
    flow``: ``[geometry]``, ``[coolant]``, optional ``[flow]`` for the mesh); keywords override
    ``segments``, ``inlet_temp_k`` [K], ``flow_l_min`` [L/min], ``grad_div`` [-] and
    ``streamline_diffusion`` [-] (the flow's stabilisations,
    :class:`~hevsim.thermal.flow.FlowSection`), the coolant mesh's ``cells_across_width`` and
    ``cells_across_height`` and its wall treatment ``thermal_wall`` (``[flow]`` keys, validated
    like them); ``transient``: implicit Euler coolant instead of quasi-steady."""

    def __init__(
        self,
        name: str,
        config: str | Path,
        segments: int | None = None,
        inlet_temp_k: float | None = None,
        flow_l_min: float | None = None,
        transient: bool = False,
        grad_div: float | None = None,
        streamline_diffusion: float | None = None,
        cells_across_width: int | None = None,
        cells_across_height: int | None = None,
        thermal_wall: str | None = None,
    ):
        from hevsim.schema import read_toml
        from hevsim.thermal.cht import CoolantThermal
        from hevsim.thermal.flow import L_MIN_TO_M3_S, flow_config_from_dict, plate_channel, solve_flow
        from hevsim.thermal.run import thermal_config_from_dict

        self.name = name
        path = Path(config)
        data = read_toml(path)
        if flow_l_min is not None:
            if not (math.isfinite(float(flow_l_min)) and float(flow_l_min) > 0.0):
                raise ConfigError(
                    f"participant {name!r}: flow_l_min = {flow_l_min!r}; expected a positive flow rate "
                    "[L/min]."
                )
            data["flow"] = {**data.get("flow", {}), "flow_l_min": float(flow_l_min)}
        overrides: dict[str, object] = {
            "grad_div": None if grad_div is None else float(grad_div),
            "streamline_diffusion": None if streamline_diffusion is None else float(streamline_diffusion),
            "cells_across_width": cells_across_width,
            "cells_across_height": cells_across_height,
            "thermal_wall": thermal_wall,
        }
        for key, value in overrides.items():
            if value is not None:
                data["flow"] = {**data.get("flow", {}), key: value}
        cfg = flow_config_from_dict(data, str(path), path.parent)
        thermal = thermal_config_from_dict(
            {k: v for k, v in data.items() if k != "flow"}, str(path), path.parent
        )
        # the interface (inputs, outputs, segments, initial inputs) and the 1-D channel at the
        # same flow rate, kept for comparison (``self.channel``)
        super().__init__(name, thermal, segments, inlet_temp_k, cfg.flow_m3_s / L_MIN_TO_M3_S)
        n, t_in = self.n_segments, self.u["inlet_temp_k"]
        self.config = cfg
        channel = plate_channel(cfg.geometry)
        where = f"participant {name!r}"
        self.flow = solve_flow(channel, cfg.coolant, cfg.flow_m3_s, section=cfg.flow, where=where)
        path_m = cfg.geometry.channel_path_m()
        self.model = CoolantThermal(
            self.flow, channel, cfg.coolant, path_m, n, where, thermal_wall=cfg.flow.thermal_wall
        )
        length_m = float(np.linalg.norm(np.diff(path_m, axis=0), axis=1).sum())
        self.resolution = self.model.check_resolution(length_m / n)
        self.transient = bool(transient)
        self.temp_k = np.full(self.model.basis.N, t_in)  # coolant field (transient state)
        self.heat_w = np.zeros(n)
        self._stepped, self._dt_s = False, math.inf

    def _inputs(self) -> tuple[np.ndarray, np.ndarray, float]:
        """Wall temperature [K] and area [m^2] per segment and the inlet temperature [K]."""
        wall, area = (
            np.array([self.u[f"wall{i}_{q}"] for i in range(self.n_segments)]) for q in ("temp_k", "area_m2")
        )
        bad = ~np.isfinite(wall) | (wall <= 0.0) | ~(area >= 0.0)
        if bad.any():
            i = int(np.argmax(bad))
            raise ConfigError(
                f"participant {self.name!r}: segment {i} has wall temperature {float(wall[i])!r} K and area "
                f"{float(area[i])!r} m^2; expected a temperature > 0 K and an area >= 0."
            )
        return wall, area, self.u["inlet_temp_k"]

    def do_step(self, t: float, h: float) -> tuple[bool, float | None]:
        if self.transient:
            wall, _, t_in = self._inputs()
            self.temp_k, self.heat_w = self.model.solve(wall, t_in, dt_s=h, previous_k=self.temp_k)
            self._stepped, self._dt_s = True, h
        return True, None

    def get_outputs(self) -> dict[str, float]:
        m = self.model
        wall, area, t_in = self._inputs()
        if self.transient:
            if not self._stepped:  # before the first step: the steady field at these inputs
                self.temp_k, self.heat_w = m.solve(wall, t_in)
            heat, sens = self.heat_w, np.diag(m.response(self._dt_s)[:, :-1])
            outlet = m.outlet_temp_k(self.temp_k)
        else:
            g = m.response()
            heat = g @ np.concatenate((wall, [t_in]))
            sens = np.diag(g[:, :-1])
            outlet = t_in + float(np.sum(heat)) / m.capacity_rate_w_k
        a = np.where(area > 0.0, area, m.wall_area_m2)  # no plate area yet: the coolant mesh's
        flux = heat / a
        film = sens / a
        fluid = wall - flux / film
        out = {f"wall{i}_heat_flux_w_m2": float(flux[i]) for i in range(self.n_segments)}
        out.update({f"wall{i}_film_w_m2k": float(film[i]) for i in range(self.n_segments)})
        out.update({f"wall{i}_fluid_temp_k": float(fluid[i]) for i in range(self.n_segments)})
        out.update(outlet_temp_k=float(outlet), cooling_power_w=float(np.sum(heat)))
        return out

    def get_state(self) -> Any:
        return {
            "u": dict(self.u),
            "temp_k": self.temp_k.copy(),
            "heat_w": self.heat_w.copy(),
            "dt_s": self._dt_s,
        }

    def set_state(self, state: Any) -> None:
        self.u = dict(state["u"])
        self.temp_k, self.heat_w = state["temp_k"].copy(), state["heat_w"].copy()
        self._dt_s = state["dt_s"]
        self._stepped = math.isfinite(self._dt_s)

    def write_fields(self, out_dir: Path) -> dict[str, Any]:
        """The coolant's temperature (at the last inputs) and velocity fields as
        ``<out_dir>/coolant_cht.vtu``; returns the flow's figures."""
        from hevsim.thermal.cht import write_cht_vtu

        wall, _, t_in = self._inputs()
        temp = self.temp_k if self.transient else self.model.solve(wall, t_in)[0]
        out_dir.mkdir(parents=True, exist_ok=True)
        write_cht_vtu(self.model, temp, out_dir / "coolant_cht.vtu")
        keys = ("flow_l_min", "reynolds", "pressure_drop_pa", "pump_power_w", "elements")
        return (
            {k: self.flow.metrics[k] for k in keys}
            | {"thermal_boundary_layer_m": self.resolution["boundary_layer_m"]}
            | self.model.wall_metrics()
        )
