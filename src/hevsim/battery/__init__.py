"""Electro-thermal battery cells and modules (thesis section 4.1.1), ageing and vehicle coupling.

Public API: :class:`Cell`, :class:`CellResult`, :class:`Module`, :class:`ModuleResult`,
:class:`CellParameters`, :func:`load_cell_parameters`, :func:`shipped_cells`,
:func:`simulate_cells` (vectorised batch of independent cells).
"""

from __future__ import annotations

from hevsim.battery.batch import simulate_cells
from hevsim.battery.cell import Cell, CellResult
from hevsim.battery.module import Module, ModuleResult
from hevsim.battery.params import CellParameters, load_cell_parameters, shipped_cells

__all__ = [
    "Cell",
    "CellParameters",
    "CellResult",
    "Module",
    "ModuleResult",
    "load_cell_parameters",
    "shipped_cells",
    "simulate_cells",
]
