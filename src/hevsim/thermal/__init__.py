"""3D finite-element thermal model of a battery module with cooling plate and coolant.

Thesis sections 4.1.2 (thermal-structural domain, Abaqus/Standard) and 4.1.3 (fluid domain,
Abaqus/CFD), rebuilt on scikit-fem (P1 tetrahedra), gmsh (geometry) and meshio (files).

The heavy optional dependencies (scikit-fem, gmsh, meshio, matplotlib) are imported inside
the submodules that use them, never when ``hevsim`` or ``hevsim.thermal`` is imported.

Public API (import from the submodules):

- :mod:`hevsim.thermal.materials`: :class:`Material`, ``TABLE_4_3``, ``DEFAULT_PART_MATERIALS``
- :mod:`hevsim.thermal.mesh`: :class:`ThermalMesh` (nodes, tets, parts, cells, facet groups)
- :mod:`hevsim.thermal.solver`: :class:`HeatModel` (theta-method transient solver)
- :mod:`hevsim.thermal.coolant`: :class:`Coolant`, :class:`ChannelModel`, ``nusselt``
- :mod:`hevsim.thermal.meshio_import`: :func:`read_mesh` (gmsh .msh, VTU, ... via meshio)
- :mod:`hevsim.thermal.geometry`: :class:`ModuleGeometry`, :func:`build_module_mesh`
- :mod:`hevsim.thermal.run`: :func:`load_thermal_config`, :func:`run_thermal`
"""

from __future__ import annotations

__all__: list[str] = []
