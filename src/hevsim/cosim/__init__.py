"""Co-simulation engine: participants (FMUs through FMPy, hevsim models in process), master
algorithms (Jacobi, Gauss-Seidel, fixed-point iteration), SSP and SIMULIA CSE configurations.

See ``docs/cosim.md``. Heavy imports (FMPy) happen only when an FMU participant is made.
"""

from hevsim.cosim.master import Connection, CosimFault, CosimResult, Master, Options, simulate
from hevsim.cosim.participant import (
    FunctionParticipant,
    ModuleCellsParticipant,
    Participant,
    StepperParticipant,
    ode_participant,
)

__all__ = [
    "Connection",
    "CosimFault",
    "CosimResult",
    "FunctionParticipant",
    "Master",
    "ModuleCellsParticipant",
    "Options",
    "Participant",
    "StepperParticipant",
    "ode_participant",
    "simulate",
]
