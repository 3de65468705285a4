"""The one exception family of hevsim.

Every error a user can cause by bad input derives from :class:`HevsimError`. Messages name
the file, key, column or line, the offending value and what was expected, so the command
line can print them as one paragraph and exit with status 2.
"""

from __future__ import annotations

from pathlib import Path


class HevsimError(Exception):
    """Base class of every user-facing hevsim error."""

    exit_code = 2


class InputError(HevsimError):
    """A data file (cycle CSV, component map) is missing or malformed."""


class ConfigError(HevsimError):
    """A configuration file has an unknown key, a wrong type or an out-of-range value."""


class SimulationError(HevsimError):
    """A simulation cannot proceed (for example the vehicle cannot follow the cycle at all)."""


def where(file: str | Path | None = None, key: str | None = None, line: int | None = None) -> str:
    """Format a location prefix such as ``"vehicle.toml: key 'body.mass_kg'"``."""
    parts: list[str] = []
    if file is not None:
        parts.append(str(file))
    if line is not None:
        parts.append(f"line {line}")
    if key is not None:
        parts.append(f"key '{key}'")
    return ": ".join(parts) if parts else "input"


class DPSetupError(HevsimError):
    """A dynamic-programming problem or option is malformed (grid, target, memory limit)."""


class DPModelError(HevsimError):
    """A dynamic-programming model returned outputs of the wrong shape, NaN or -inf."""


class DPInfeasibleError(HevsimError):
    """No admissible input sequence leads from the initial state to the final-state target."""


class OutputError(HevsimError):
    """An output path cannot be written safely (it would replace the user's own files, the
    working directory or an input, or the location is not writable)."""
