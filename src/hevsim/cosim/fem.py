"""The FEM battery module (:mod:`hevsim.thermal`) as a co-simulation participant.

Builds the module mesh, the discretisation, the quasi-steady coolant channel and the
:class:`hevsim.thermal.solver.HeatModel` from a thermal configuration (the TOML of
``hevsim thermal``), then advances in sub-steps of the configuration's ``dt_s``.

Inputs: ``module_heat_w`` [W, shared equally by the cells], ``cell_heat_w`` [W, the same heat
in every cell] or ``cell<i>_heat_w`` [W] per cell (i = 0 .. n-1; a per-cell input, when
connected, overrides the common ones).
Outputs: ``cell<i>_temp_k`` [K, volume-mean temperature of each cell], ``cell_mean_temp_k``,
``cell_max_temp_k`` [K, hottest node in any cell], ``outlet_temp_k`` [K, coolant outlet],
``cooling_power_w`` [W, heat taken by the coolant] and ``stored_energy_j`` [J].
The coolant channel is solved inside the participant (it is quasi-steady and iterated with
the wall temperature every sub-step, ``coupling_iterations``).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from hevsim.cosim.participant import Participant
from hevsim.errors import ConfigError
from hevsim.units import KELVIN_OFFSET

KELVIN = KELVIN_OFFSET  # [K] at 0 degC


class FemModuleParticipant(Participant):
    """See the module docstring. ``config`` is a thermal TOML path (or a ``ThermalConfig``);
    ``mesh_size_m`` overrides the mesh size (coarser meshes for tests)."""

    def __init__(self, name: str, config: str | Path | Any, mesh_size_m: float | None = None):
        from dataclasses import replace

        from hevsim.thermal.run import load_thermal_config

        self.name = name
        cfg = load_thermal_config(config) if isinstance(config, str | Path) else config
        if mesh_size_m is not None:
            cfg = replace(cfg, geometry=replace(cfg.geometry, mesh_size_m=float(mesh_size_m)))
        self.cfg = cfg
        self.n_cells = cfg.geometry.rows * cfg.geometry.columns
        self.inputs = {
            "module_heat_w": "W",
            "cell_heat_w": "W",
            **{f"cell{i}_heat_w": "W" for i in range(self.n_cells)},
        }
        self.outputs = {f"cell{i}_temp_k": "K" for i in range(self.n_cells)}
        self.outputs.update(
            cell_mean_temp_k="K",
            cell_max_temp_k="K",
            outlet_temp_k="K",
            cooling_power_w="W",
            stored_energy_j="J",
        )
        self.model: Any = None
        self.terminate_requested = False

    def setup(self, t0: float) -> None:
        from hevsim.thermal.geometry import build_module_mesh
        from hevsim.thermal.run import module_model

        cfg = self.cfg
        mesh = build_module_mesh(cfg.geometry, source=f"{cfg.name}: geometry")
        disc, self.channel, self.model = module_model(cfg, mesh)
        self.mesh, self.disc = mesh, disc
        n = disc.points_m.shape[0]
        vol = np.bincount(disc.tets.ravel(), weights=np.repeat(disc.tet_volume_m3 / 4, 4), minlength=n)
        self.cell_nodes = []
        w = np.zeros((self.n_cells, n))
        for c in range(self.n_cells):
            nodes = np.unique(disc.tets[mesh.cell_of_tet == c].ravel())
            self.cell_nodes.append(nodes)
            w[c, nodes] = vol[nodes]
        self.cell_weights = w / w.sum(axis=1, keepdims=True)
        self.all_cell_nodes = np.unique(np.concatenate(self.cell_nodes))
        self.heat = np.zeros(self.n_cells)
        self.per_cell = np.zeros(self.n_cells, bool)
        self.common = 0.0

    def set_inputs(self, values: Mapping[str, float]) -> None:
        for k, v in values.items():
            if k == "cell_heat_w":
                self.common = float(v)
            elif k == "module_heat_w":
                self.common = float(v) / self.n_cells
            elif k in self.inputs:
                i = int(k[4:].split("_")[0])
                self.heat[i], self.per_cell[i] = float(v), True
            else:
                raise ConfigError(f"participant {self.name!r} has no input {k!r}.")

    def do_step(self, t: float, h: float) -> tuple[bool, float | None]:
        dt = self.model.dt_s
        n = round(h / dt)
        if n < 1 or abs(n * dt - h) > 1e-9 * max(h, 1.0):
            return False, dt * max(1, int(h / dt))
        self.model.set_cell_heat_w(np.where(self.per_cell, self.heat, self.common))
        for _ in range(n):
            self.model.step()
        return True, dt

    def get_outputs(self) -> dict[str, float]:
        t = self.model.temp_k
        cell_t = self.cell_weights @ t
        out = {f"cell{i}_temp_k": float(v) for i, v in enumerate(cell_t)}
        out.update(
            cell_mean_temp_k=float(cell_t.mean()),
            cell_max_temp_k=float(t[self.all_cell_nodes].max()),
            outlet_temp_k=float(self.channel.outlet_temp_k),
            cooling_power_w=float(self.channel.heat_w),
            stored_energy_j=float(np.sum(self.disc.capacity @ t)),
        )
        return out

    def get_state(self) -> Any:
        m, c = self.model, self.channel
        return {
            "temp_k": m.temp_k.copy(), "time_s": m.time_s, "f_old": m._f_old.copy(),
            "fluid_k": m.fluid_k.copy(), "heat_cell": m.cell_heat_w.copy(),
            "outlet": c.outlet_temp_k, "cool_w": c.heat_w,
            "heat": self.heat.copy(), "per_cell": self.per_cell.copy(), "common": self.common,
        }  # fmt: skip

    def set_state(self, s: Any) -> None:
        m, c = self.model, self.channel
        m.temp_k, m.time_s, m._f_old = s["temp_k"].copy(), s["time_s"], s["f_old"].copy()
        m.fluid_k, m.cell_heat_w = s["fluid_k"].copy(), s["heat_cell"].copy()
        c.outlet_temp_k, c.heat_w = s["outlet"], s["cool_w"]
        self.heat, self.per_cell, self.common = s["heat"].copy(), s["per_cell"].copy(), s["common"]

    def field_temp_k(self) -> np.ndarray:
        """Nodal temperatures [K] now (for pictures and hot spots)."""
        return np.asarray(self.model.temp_k).copy()
