"""Reading any co-simulation configuration file by its suffix: :func:`load_system`."""

from __future__ import annotations

from pathlib import Path

from hevsim.cosim.ssd import Component, SystemDescription, read_ssd, read_ssp
from hevsim.errors import ConfigError


def load_system(path: str | Path, bindings: dict[str, Component] | None = None) -> SystemDescription:
    """Read ``.ssp``, ``.ssd`` or a CSE ``.xml`` (``bindings`` map CSE instances to components).

    An ``.ssp`` is extracted to a temporary folder the description owns: call its
    :meth:`~hevsim.cosim.ssd.SystemDescription.cleanup` (or use it in a ``with``) when done."""
    p = Path(path)
    if not p.exists():
        raise ConfigError(f"{p}: configuration file does not exist.")
    if p.suffix == ".ssp":
        return read_ssp(p)
    if p.suffix == ".ssd":
        return read_ssd(p)
    if p.suffix == ".xml":
        from hevsim.cosim.cse import read_cse  # (here: most runs read SSP)

        return read_cse(p, bindings)
    raise ConfigError(f"{p}: unknown configuration type {p.suffix!r}; valid: .ssp, .ssd, .xml (SIMULIA CSE).")
