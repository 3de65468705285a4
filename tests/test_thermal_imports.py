"""The heavy optional dependencies are imported only where they are used."""

from __future__ import annotations

import subprocess
import sys


def test_import_hevsim_thermal_stays_light() -> None:
    code = (
        "import sys, hevsim, hevsim.thermal, hevsim.thermal.run, hevsim.thermal.solver\n"
        "import hevsim.thermal.coolant, hevsim.thermal.abaqus, hevsim.thermal.geometry\n"
        "heavy = [m for m in ('skfem', 'gmsh', 'meshio', 'matplotlib') if m in sys.modules]\n"
        "assert not heavy, heavy\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)
