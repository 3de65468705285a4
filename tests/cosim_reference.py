"""The Modelica Reference FMUs, compiled from their C sources in the tests.

``tests/reference_fmus/`` holds the sources of the Reference FMUs (models BouncingBall,
Dahlquist, VanDerPol, Stair, Resource, StateSpace and Clocks; the shared ``src/`` and
``include/``) copied unchanged from github.com/modelica/Reference-FMUs at commit 1258711
(2026-08-12), under their 2-clause BSD licence (``tests/reference_fmus/LICENSE.txt``; see
``tests/reference_fmus/README.md``). :func:`build_reference_fmu` compiles one model as the
project's CMake build does (``FMI_VERSION``, ``DISABLE_PREFIX``, the model's folder and
``include/`` on the include path, ``model.c`` + ``fmi<v>Functions.c`` + ``cosimulation.c``)
and packs it with its model description and, for Resource, ``resources/y.txt``.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import zipfile
from pathlib import Path

SOURCES = Path(__file__).resolve().parent / "reference_fmus"


def build_reference_fmu(model: str, fmi_version: int, out_dir: Path, me_only: bool = False) -> Path:
    """Compile Reference FMU ``model`` for FMI ``fmi_version`` (2 or 3) to
    ``out_dir/<model><fmi_version>.fmu`` (Linux x86-64 binary); ``me_only``: its model
    description without the ``<CoSimulation>`` element (``<model><fmi_version>ME.fmu``), so that
    hevsim runs it as a Model Exchange FMU."""
    cc = shutil.which("cc") or shutil.which("gcc")
    assert cc, "no C compiler"
    xml = SOURCES / model / f"FMI{fmi_version}.xml"
    assert xml.is_file(), f"no FMI {fmi_version} version of {model}"
    work = out_dir / f"{model}{fmi_version}_build"
    work.mkdir(parents=True, exist_ok=True)
    so = work / f"{model}.so"
    sources = [SOURCES / model / "model.c", SOURCES / "src" / f"fmi{fmi_version}Functions.c",
               SOURCES / "src" / "cosimulation.c"]  # fmt: skip
    proc = subprocess.run(
        [cc, "-shared", "-fPIC", "-O1", f"-DFMI_VERSION={fmi_version}", "-DDISABLE_PREFIX",
         f"-I{SOURCES / 'include'}", f"-I{SOURCES / model}", "-o", str(so), *map(str, sources), "-lm"],
        capture_output=True, text=True,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    platform = "x86_64-linux" if fmi_version == 3 else "linux64"
    out = out_dir / f"{model}{fmi_version}{'ME' if me_only else ''}.fmu"
    text = xml.read_text()
    if me_only:
        text = re.sub(r"<CoSimulation\b[^>]*(/>|>.*?</CoSimulation>)", "", text, flags=re.S)
        assert "<CoSimulation" not in text
    with zipfile.ZipFile(out, "w") as z:
        z.writestr("modelDescription.xml", text)
        z.write(so, f"binaries/{platform}/{model}.so")
        if (SOURCES / model / "y.txt").is_file():
            z.write(SOURCES / model / "y.txt", "resources/y.txt")
    return out
