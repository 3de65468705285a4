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


@pytest.fixture(scope="session")
def cosim_module_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A copy of ``examples/cosim_module`` (with ``../module_thermal.toml``) whose native module
    FMU (not in git) is built from scratch by the example's own build step."""
    import importlib.util
    import shutil

    root = tmp_path_factory.mktemp("examples")
    shutil.copytree(
        ROOT / "examples" / "cosim_module", root / "cosim_module", ignore=shutil.ignore_patterns("*.fmu")
    )
    shutil.copy(ROOT / "examples" / "module_thermal.toml", root / "module_thermal.toml")
    spec = importlib.util.spec_from_file_location("run_module_copy", root / "cosim_module" / "run_module.py")
    assert spec is not None and spec.loader is not None
    ex = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(ex)
    fmu, built = ex.build_fmu()
    assert built and fmu == root / "cosim_module" / ex.FMU
    return root / "cosim_module"
