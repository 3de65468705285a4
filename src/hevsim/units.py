"""Unit conversions used at the edges (input files and reports). SI inside.

Each constant is exact by definition unless a source is given.
"""

from __future__ import annotations

import math

MPS_PER_MPH = 0.44704
"""Metres per second in one mile per hour [m/s / mph] (exact)."""
M_PER_MILE = 1609.344
"""Metres in one international mile [m] (exact)."""
M3_PER_US_GALLON = 3.785411784e-3
"""Cubic metres in one US liquid gallon [m^3] (exact)."""
KWH_PER_GALLON_EQUIVALENT = 33.705
"""Electricity [kWh] counted as one gallon of gasoline equivalent for MPGe (EPA/NHTSA fuel-economy
label rule, 76 FR 39478, 2011; the label's ``hevsim/data/epa_label.toml`` holds the same value)."""
J_PER_WH = 3600.0
"""Joules in one watt-hour [J] (exact)."""
BTU_PER_WH = 3.412
"""BTU per watt-hour, as used by the thesis eq (16) and tutorial lecture 7 [BTU/Wh]."""
RADPS_PER_RPM = math.pi / 30.0
"""rad/s in one revolution per minute."""
KELVIN_OFFSET = 273.15
"""Kelvin at 0 degrees Celsius [K]."""
STANDARD_GRAVITY = 9.81
"""Gravitational acceleration used by the thesis (Table 2.2) [m/s^2]."""


def mph_to_mps(v_mph: float) -> float:
    """Convert [mph] to [m/s]."""
    return v_mph * MPS_PER_MPH


def mps_to_mph(v_mps: float) -> float:
    """Convert [m/s] to [mph]."""
    return v_mps / MPS_PER_MPH


def rpm_to_radps(n_rpm: float) -> float:
    """Convert [rpm] to [rad/s]."""
    return n_rpm * RADPS_PER_RPM


def radps_to_rpm(omega_radps: float) -> float:
    """Convert [rad/s] to [rpm]."""
    return omega_radps / RADPS_PER_RPM


def c_to_k(temp_c: float) -> float:
    """Convert [degC] to [K]."""
    return temp_c + KELVIN_OFFSET
