"""The FEM battery module (:mod:`hevsim.thermal`) as a co-simulation participant.

Builds the module mesh, the discretisation and the :class:`hevsim.thermal.solver.HeatModel`
from a thermal configuration (the TOML of ``hevsim thermal``), then advances in sub-steps of
the configuration's ``dt_s``.

Inputs: ``module_heat_w`` [W, shared equally by the cells], ``cell_heat_w`` [W, the same heat
in every cell] or ``cell<i>_heat_w`` [W] per cell (i = 0 .. n-1; a per-cell input, when
connected, overrides the common ones).
Outputs: ``cell<i>_temp_k`` [K, volume-mean temperature of each cell], ``cell_mean_temp_k``,
``cell_max_temp_k`` [K, hottest node in any cell], ``plate_max_temp_k`` [K, hottest node of
the cooling plate], ``wall_heat_w`` [W, heat through the channel wall into the coolant] and
``stored_energy_j`` [J].

Coolant, ``coolant="internal"`` (default): the quasi-steady 1-D channel is solved inside the
participant, coupled implicitly to the wall temperature every sub-step (``[simulation]
coupling``; ``"staggered"`` with ``coupling_iterations`` as before);
extra outputs ``outlet_temp_k`` [K] and ``cooling_power_w`` [W].
``coolant="external"``: the channel is another participant
(:class:`hevsim.cosim.coolant.CoolantChannelParticipant`, or any fluid model with the same
variables), as the thesis's Abaqus/CFD. Per configured channel segment j: outputs
``wall<j>_temp_k`` [K] and ``wall<j>_area_m2`` [m^2]; inputs ``wall<j>_heat_flux_w_m2``
[W/m^2, into the coolant], ``wall<j>_film_w_m2k`` [W/(m^2 K), d flux / d wall temperature]
and optionally ``wall<j>_fluid_temp_k`` [K]. The thesis's exchange (heat flux and lumped
heat capacitance): the plate applies ``q(T) = q* + h (T - T*)`` linearised around its
current wall temperature ``T*``, i.e. a film ``h`` to the sink temperature ``T* - q*/h`` (a
pure heat flux where h = 0); with the coolant stepped after the plate this reproduces the
internal staggered coupling (``coupling = "staggered"``, ``coupling_iterations = 1``) exactly.
With the fluid temperature connected the film acts towards it instead, which stays exact when
the master iterates a step (``max_iterations``) and so converges to the implicit plate-coolant
coupling (the internal default).

Temperature fields are kept every ``[output] field_every_s`` of the configuration and at the
end; :meth:`FemModuleParticipant.write_fields` writes them (VTU/PVD), the pictures of the
plate and cells (:func:`hevsim.thermal.pictures.plot_fields`) and the hot spots.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from hevsim.cosim.participant import Participant
from hevsim.errors import ConfigError, SimulationError
from hevsim.units import KELVIN_OFFSET

KELVIN = KELVIN_OFFSET  # [K] at 0 degC
COOLANT_MODES = ("internal", "external")


class FemModuleParticipant(Participant):
    """See the module docstring. ``config`` is a thermal TOML path (or a ``ThermalConfig``);
    ``mesh_size_m`` overrides the mesh size (coarser meshes for tests); ``coolant`` is
    ``"internal"`` or ``"external"``."""

    def __init__(
        self,
        name: str,
        config: str | Path | Any,
        mesh_size_m: float | None = None,
        coolant: str = "internal",
    ):
        from dataclasses import replace

        from hevsim.thermal.run import load_thermal_config

        self.name = name
        cfg = load_thermal_config(config) if isinstance(config, str | Path) else config
        if mesh_size_m is not None:
            cfg = replace(cfg, geometry=replace(cfg.geometry, mesh_size_m=float(mesh_size_m)))
        if coolant not in COOLANT_MODES:
            raise ConfigError(
                f"participant {name!r}: coolant = {coolant!r}; expected one of {', '.join(COOLANT_MODES)}."
            )
        self.cfg = cfg
        self.external = coolant == "external"
        self.n_cells = cfg.geometry.rows * cfg.geometry.columns
        self.n_segments = cfg.coolant.segments
        self.inputs = {
            "module_heat_w": "W",
            "cell_heat_w": "W",
            **{f"cell{i}_heat_w": "W" for i in range(self.n_cells)},
        }
        self.outputs = {f"cell{i}_temp_k": "K" for i in range(self.n_cells)}
        self.outputs.update(
            cell_mean_temp_k="K",
            cell_max_temp_k="K",
            plate_max_temp_k="K",
            wall_heat_w="W",
            stored_energy_j="J",
        )
        if self.external:
            n = self.n_segments
            self.inputs.update({f"wall{j}_heat_flux_w_m2": "W/m2" for j in range(n)})
            self.inputs.update({f"wall{j}_film_w_m2k": "W/(m2.K)" for j in range(n)})
            self.inputs.update({f"wall{j}_fluid_temp_k": "K" for j in range(n)})
            self.outputs.update({f"wall{j}_temp_k": "K" for j in range(n)})
            self.outputs.update({f"wall{j}_area_m2": "m2" for j in range(n)})
        else:
            self.outputs.update(outlet_temp_k="K", cooling_power_w="W")
        self.model: Any = None
        self.terminate_requested = False

    def setup(self, t0: float) -> None:
        from hevsim.thermal.geometry import build_module_mesh
        from hevsim.thermal.run import module_model
        from hevsim.thermal.solver import cell_nodes

        cfg = self.cfg
        mesh = build_module_mesh(cfg.geometry, source=f"{cfg.name}: geometry")
        disc, self.channel, self.model = module_model(cfg, mesh, external_coolant=self.external)
        self.mesh, self.disc = mesh, disc
        vol, self.cell_nodes = cell_nodes(mesh, disc)
        w = np.zeros((self.n_cells, vol.size))
        for c, nodes in enumerate(self.cell_nodes):
            w[c, nodes] = vol[nodes]
        self.cell_weights = w / w.sum(axis=1, keepdims=True)
        self.all_cell_nodes = np.unique(np.concatenate(self.cell_nodes))
        self.plate_nodes = np.flatnonzero(disc.node_part == mesh.part_names.index("plate"))
        self.segments = np.asarray(self.channel.configured_segments)  # configured index per wall segment
        self.heat = np.zeros(self.n_cells)
        self.per_cell = np.zeros(self.n_cells, bool)
        self.common = 0.0
        self.wall_flux = np.zeros(self.n_segments)
        self.wall_film = np.zeros(self.n_segments)
        self.wall_fluid = np.full(self.n_segments, np.nan)  # set when the fluid temperature is connected
        self.snapshots: dict[float, np.ndarray] = {float(t0): self._field_c()}
        self.t0 = float(t0)

    def set_inputs(self, values: Mapping[str, float]) -> None:
        for k, v in values.items():
            if k == "cell_heat_w":
                self.common = float(v)
            elif k == "module_heat_w":
                self.common = float(v) / self.n_cells
            elif k.startswith("wall") and k in self.inputs:
                j = int(k[4:].split("_")[0])
                kind = k.split("_", 1)[1]
                store = {"heat_flux_w_m2": self.wall_flux, "film_w_m2k": self.wall_film}.get(
                    kind, self.wall_fluid
                )
                store[j] = float(v)
            elif k in self.inputs:
                i = int(k[4:].split("_")[0])
                self.heat[i], self.per_cell[i] = float(v), True
            else:
                raise ConfigError(f"participant {self.name!r} has no input {k!r}.")

    def _apply_wall_exchange(self) -> None:
        """Film and sink temperature (or pure flux) per wall segment from the coolant's inputs:
        with the fluid temperature connected, a film to it; else the heat flux linearised
        around the current wall temperature with the film; with no film, the heat flux."""
        m, seg = self.model, self.segments
        flux, film, fluid = self.wall_flux[seg], self.wall_film[seg], self.wall_fluid[seg]
        if not (np.all(np.isfinite(flux)) and np.all(np.isfinite(film)) and film.min(initial=0.0) >= 0.0):
            raise SimulationError(
                f"participant {self.name!r}: wall heat flux {flux.tolist()} W/m^2 / film {film.tolist()} "
                "W/(m^2 K) from the coolant are not valid (finite flux, film >= 0 expected)."
            )
        wall_t = m.wall_temp_k()
        has_film = film > 0.0
        m.set_wall_film(film)
        sink = np.where(np.isfinite(fluid), fluid, wall_t - flux / np.where(has_film, film, 1.0))
        self.channel.fluid_k = np.where(has_film, sink, 0.0)
        m.fluid_k = self.channel.fluid_k.copy()
        m.wall_flux_w_m2 = np.where(has_film, 0.0, flux)

    def do_step(self, t: float, h: float) -> tuple[bool, float | None]:
        dt = self.model.dt_s
        n = round(h / dt)
        if n < 1 or abs(n * dt - h) > 1e-9 * max(h, 1.0):
            return False, dt * max(1, int(h / dt))
        self.model.set_cell_heat_w(np.where(self.per_cell, self.heat, self.common))
        if self.external:
            self._apply_wall_exchange()
        every = self.cfg.output.field_every_s
        for _ in range(n):
            self.model.step()
            tk = self.t0 + self.model.time_s
            if every > 0 and abs(tk / every - round(tk / every)) < 1e-9:
                self.snapshots[round(tk, 9)] = self._field_c()
        return True, dt

    def _field_c(self) -> np.ndarray:
        return np.asarray(self.model.temp_k - KELVIN, dtype=np.float32)

    def get_outputs(self) -> dict[str, float]:
        m = self.model
        t = m.temp_k
        cell_t = self.cell_weights @ t
        out = {f"cell{i}_temp_k": float(v) for i, v in enumerate(cell_t)}
        out.update(
            cell_mean_temp_k=float(cell_t.mean()),
            cell_max_temp_k=float(t[self.all_cell_nodes].max()),
            plate_max_temp_k=float(t[self.plate_nodes].max()),
            wall_heat_w=float(m.report().wall_w),
            stored_energy_j=float(np.sum(self.model.capacity @ t)),
        )
        if self.external:
            wall_t, area = m.wall_temp_k(), self.disc.wall_area_m2
            # segments no wall facet reaches (coarse meshes) have no area: no heat either way
            temps = np.full(self.n_segments, float(np.average(wall_t, weights=area)))
            areas = np.zeros(self.n_segments)
            temps[self.segments], areas[self.segments] = wall_t, area
            out.update({f"wall{j}_temp_k": float(temps[j]) for j in range(self.n_segments)})
            out.update({f"wall{j}_area_m2": float(areas[j]) for j in range(self.n_segments)})
        else:
            out.update(
                outlet_temp_k=float(self.channel.outlet_temp_k), cooling_power_w=float(self.channel.heat_w)
            )
        return out

    def get_state(self) -> Any:
        m, c = self.model, self.channel
        s = {
            "temp_k": m.temp_k.copy(), "time_s": m.time_s, "f_old": m._f_old.copy(),
            "fluid_k": m.fluid_k.copy(), "heat_cell": m.cell_heat_w.copy(), "wall_h": m.wall_h.copy(),
            "wall_flux_model": m.wall_flux_w_m2.copy(),
            "heat": self.heat.copy(), "per_cell": self.per_cell.copy(), "common": self.common,
            "wall_flux": self.wall_flux.copy(), "wall_film": self.wall_film.copy(),
            "wall_fluid": self.wall_fluid.copy(),
            "snapshots": dict(self.snapshots),
        }  # fmt: skip
        if not self.external:
            s.update(outlet=c.outlet_temp_k, cool_w=c.heat_w)
        return s

    def set_state(self, s: Any) -> None:
        m, c = self.model, self.channel
        m.temp_k, m.time_s, m._f_old = s["temp_k"].copy(), s["time_s"], s["f_old"].copy()
        m.fluid_k, m.cell_heat_w = s["fluid_k"].copy(), s["heat_cell"].copy()
        m.set_wall_film(s["wall_h"])
        m.wall_flux_w_m2 = s["wall_flux_model"].copy()
        self.heat, self.per_cell, self.common = s["heat"].copy(), s["per_cell"].copy(), s["common"]
        self.wall_flux, self.wall_film = s["wall_flux"].copy(), s["wall_film"].copy()
        self.wall_fluid = s["wall_fluid"].copy()
        self.snapshots = dict(s["snapshots"])
        if not self.external:
            c.outlet_temp_k, c.heat_w = s["outlet"], s["cool_w"]

    def field_temp_k(self) -> np.ndarray:
        """Nodal temperatures [K] now (for pictures and hot spots)."""
        return np.asarray(self.model.temp_k).copy()

    def write_fields(self, out_dir: Path) -> dict[str, Any]:
        """Write the kept temperature fields and the final one to ``out_dir``: ``fields/*.vtu``
        with ``temperature.pvd`` (ParaView), pictures of the plate, the cells and a section
        (``pictures/<name>_*.png``); returns the final hot spots and the file names."""
        from hevsim.thermal.pictures import plot_fields
        from hevsim.thermal.run import hot_spots, write_field_series

        if self.model is None:
            return {}
        t_end = self.t0 + self.model.time_s
        snaps = dict(self.snapshots)
        snaps[round(t_end, 9)] = self._field_c()
        series = [(t, np.asarray(v, float)) for t, v in sorted(snaps.items())]
        pvd = write_field_series(Path(out_dir), self.disc, self.mesh, series, prefix=f"{self.name}_")
        final_c = series[-1][1]
        pics = plot_fields(
            self.mesh,
            self.disc,
            self.cfg.geometry,
            final_c,
            t_end,
            Path(out_dir) / "pictures",
            prefix=f"{self.name}_",
        )
        parts = [self.mesh.part_names[i] for i in self.disc.node_part]
        spots = hot_spots(
            self.disc.points_m, final_c, parts, self.cfg.output.hot_spots, self.cfg.geometry.cell_pitch_m / 2
        )
        plate = final_c[self.plate_nodes]
        return {
            "time_s": t_end,
            "pvd": str(pvd.relative_to(out_dir)),
            "pictures": [str(p.relative_to(out_dir)) for p in pics],
            "hot_spots": spots,
            "plate_min_temp_c": float(plate.min()),
            "plate_max_temp_c": float(plate.max()),
        }
