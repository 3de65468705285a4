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


class DomainError(SimulationError):
    """A run left the physical domain of its model (exit status 2).

    Raised when a recorded state becomes NaN or infinite, a state of charge leaves [0, 1], or
    a cell is driven outside the voltage/temperature range its model is defined for. The
    message names the time, the channel and the likely cause; no results are written.
    """


class TrackingError(SimulationError):
    """The run completed but the vehicle could not follow the drive cycle (exit status 3).

    The speed-tracking error stayed beyond the stated bound
    (:data:`hevsim.sim.simulator.TRACKING_BOUND`) for longer than allowed. The message names
    the time, the error and the likely cause (motor, battery or brake limits). ``result``
    holds the completed :class:`~hevsim.sim.simulator.SimulationResult` for inspection
    (Python API); the command line writes no results folder.
    """

    exit_code = 3

    def __init__(self, message: str, result: object | None = None) -> None:
        super().__init__(message)
        self.result = result


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
