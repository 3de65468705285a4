"""Shared fixtures."""

from __future__ import annotations

from pathlib import Path

import pytest

from hevsim.config import VehicleConfig, load_config

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="session")
def series_cfg() -> VehicleConfig:
    """The shipped default series HEV (examples/series_hev.toml)."""
    return load_config(ROOT / "examples" / "series_hev.toml")
