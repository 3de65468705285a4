"""Which kernels a run compiles (the cold-cache notice) and ``hevsim compile`` (hevsim.warmup)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from hevsim import progress
from hevsim.architectures import ARCHITECTURES
from hevsim.cli import main
from hevsim.config import load_vehicle_config
from hevsim.cycles import load_cycle
from hevsim.warmup import GROUPS, cache_probe, group, run_groups, simulation_preflight, specialisation_probe

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"


def test_every_group_probes_cached_numba_kernels() -> None:
    """A renamed or uncached kernel would make the probe (and the notice) silently wrong; the
    probe made without importing a module finds numba's own cache index of the kernel."""
    from numba.core.dispatcher import Dispatcher

    for g in GROUPS:
        for ref, d in zip(g.entries, g.dispatchers(), strict=True):
            assert isinstance(d, Dispatcher), (g.name, d)
            index = d._cache._cache_file._index_path  # numba's cache of this kernel
            module, _, name = ref.partition(":")
            assert cache_probe(module, name)._cache._cache_file._index_path == index, ref
        assert g.cold_compile_s > 0.0


def _named_type(name: str) -> object:
    """A numba type printed as ``name`` (what a cache index key holds)."""
    from numba import types

    class Named(types.Type):
        def __init__(self) -> None:
            super().__init__(name=name)

    return Named()


def test_one_kernel_compiled_per_architecture_is_probed_per_architecture() -> None:
    """The one forward loop run_loop is compiled once per architecture, its plug-in first
    (ParallelPlug, PowerSplitPlug, BEVPlug): a cache holding only the parallel one is cold for
    the power split and the BEV."""
    from numba import types

    plug = _named_type("ParallelPlug(ParallelTables(array(float64, 1d, C)), none)")
    parallel_only = {((plug, types.float64, types.none), ("magic",)): "run_loop-1.nbc"}

    class CacheFile:
        _index_path = __file__  # exists

        @staticmethod
        def _load_index() -> dict[object, str]:
            return parallel_only

    class Dispatcher:
        class _cache:
            _cache_file = CacheFile

    assert not progress.cache_is_cold([specialisation_probe(Dispatcher, "ParallelPlug")])  # compiled
    assert progress.cache_is_cold([specialisation_probe(Dispatcher, "PowerSplitPlug")])  # power split: cold
    assert progress.cache_is_cold([specialisation_probe(Dispatcher, "BEVPlug")])
    loop = ("parallel", "power_split", "bev", "fcev")
    firsts = [group(a).first_arg for a in loop]
    assert len(set(firsts)) == len(firsts) and all(firsts), firsts  # one specialisation each
    assert {group(a).entries for a in loop} == {("hevsim.sim._loop:run_loop",)}


def test_every_architecture_has_its_forward_kernels() -> None:
    served = {s for g in GROUPS for s in g.serves}
    assert set(ARCHITECTURES) <= served


@pytest.mark.parametrize(
    ("example", "python_loop", "expected"),
    [
        ("series_hev.toml", False, ["series"]),
        ("parallel_hev.toml", False, ["parallel"]),
        ("prius_like_power_split.toml", False, ["power_split"]),
        ("conventional_sedan.toml", False, ["conventional"]),
        ("bev.toml", False, ["bev"]),
        ("parallel_hev.toml", True, ["power_flow"]),
        ("series_hev.toml", True, ["series"]),  # the series HEV has no Python loop
        ("series_hev_pack.toml", False, ["series", "pack"]),
        ("parallel_hev_pack.toml", False, ["parallel", "pack"]),  # the pack steps in the compiled loop
        ("bev_pack.toml", False, ["bev", "pack"]),
        ("fcev.toml", False, ["fcev"]),  # compiled since the one loop (issue 24)
        ("fcev.toml", True, ["power_flow"]),
        ("parallel_hev_pack.toml", True, ["power_flow", "pack"]),
    ],
)
def test_run_groups_follow_the_architecture_and_battery(
    example: str, python_loop: bool, expected: list[str]
) -> None:
    cfg = load_vehicle_config(EXAMPLES / example)
    assert [g.name for g in run_groups(cfg, python_loop=python_loop)] == expected


def test_a_pack_or_cell_battery_probes_its_own_version_of_the_loop() -> None:
    """run_loop compiles once more for a pack (PackArrays) or a cell (CellBusTables) battery: a
    cache holding only the table-battery version is cold for a cell run (before, the first
    cell run of an architecture compiled for 15-35 s without a notice)."""
    from numba import types

    plug = _named_type("ParallelPlug(ParallelTables(array(float64, 1d, C)), none)")
    cell = _named_type("CellBusTables(array(float64, 1d, C))")
    table_only = {((plug, types.float64, types.none), ("magic",)): "run_loop-1.nbc"}
    with_cell = {**table_only, ((plug, types.float64, cell), ("magic",)): "run_loop-2.nbc"}

    def dispatcher(index: dict[object, str]) -> object:
        cache_file = type(
            "CacheFile", (), {"_index_path": __file__, "_load_index": staticmethod(lambda: index)}
        )
        return type("Dispatcher", (), {"_cache": type("Cache", (), {"_cache_file": cache_file})})

    for index, cold in ((table_only, True), (with_cell, False)):
        assert (
            progress.cache_is_cold([specialisation_probe(dispatcher(index), "ParallelPlug", "CellBusTables")])
            is cold
        )
    assert not progress.cache_is_cold([specialisation_probe(dispatcher(table_only), "ParallelPlug", "none")])

    cfg = load_vehicle_config(EXAMPLES / "parallel_hev.toml")
    kinds = {}
    for model in ("table", "pack", "cell"):
        g = run_groups(_with_model(cfg, model))[0]
        kinds[model] = (g.name, g.last_arg, g.description)
    assert kinds["table"] == ("parallel", "none", "parallel HEV forward loop")
    assert kinds["pack"][:2] == ("parallel", "PackArrays") and "pack" in kinds["pack"][2]
    assert kinds["cell"][:2] == ("parallel", "CellBusTables") and "cell" in kinds["cell"][2]
    # the series HEV too: its plug-in runs the loop with the loop's battery step (issue 24 item 2)
    series = load_vehicle_config(EXAMPLES / "series_hev.toml")
    lasts = {model: run_groups(_with_model(series, model))[0].last_arg for model in ("table", "pack", "cell")}
    assert lasts == {"table": "none", "pack": "PackArrays", "cell": "CellBusTables"}


def _with_model(cfg: object, model: str) -> object:
    """``cfg`` as :func:`run_groups` reads it with ``[battery] model = model`` (no file checks)."""
    import types as pytypes

    return pytypes.SimpleNamespace(
        architecture=cfg.architecture, battery=pytypes.SimpleNamespace(model=model)
    )  # type: ignore[attr-defined]


@pytest.mark.parametrize(
    ("example", "kernels"),
    [
        ("parallel_hev.toml", ["run_loop"]),
        ("series_hev.toml", ["run_loop"]),
        ("bev.toml", ["run_loop"]),
        ("series_hev_pack.toml", ["run_loop", "pack_begin"]),
    ],
)
def test_notice_names_the_run_kernels_only_when_cold(
    example: str, kernels: list[str], monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    cfg = load_vehicle_config(EXAMPLES / example)
    cycle = load_cycle("udds")
    monkeypatch.delenv("HEVSIM_FORWARD", raising=False)
    monkeypatch.setenv("HEVSIM_PROGRESS", "1")
    monkeypatch.setattr(progress, "_noticed", set())
    monkeypatch.setattr(progress, "cache_is_cold", lambda dispatchers: False)
    simulation_preflight(cfg, cycle, None)
    assert "compiling" not in capsys.readouterr().err
    monkeypatch.setattr(progress, "cache_is_cold", lambda dispatchers: True)
    simulation_preflight(cfg, cycle, None)
    err = capsys.readouterr().err
    assert err.startswith("hevsim: compiling "), err
    for k in kernels:
        assert f"{k}" in err
    used = run_groups(cfg)
    names = {g.name for g in used}  # (a loop taking the battery step comes narrowed to its battery)
    mine = {e.partition(":")[2] for g in used for e in g.entries}
    others = {e.partition(":")[2] for g in GROUPS if g.name not in names for e in g.entries} - mine
    assert all(g.description in err for g in used)
    assert not [g.name for g in GROUPS if g.name not in names and f"compiling {g.description} " in err], err
    assert not [k for k in others if f"({k}" in err or f", {k}" in err], err
    expected_s = sum(g.cold_compile_s for g in used)
    assert f"about {progress.format_duration(expected_s)} " in err
    simulation_preflight(cfg, cycle, None)  # once per process
    assert "compiling" not in capsys.readouterr().err


def test_compile_options_are_checked(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["compile", "--group", "nonsense"]) == 2
    err = capsys.readouterr().err
    assert "nonsense" in err and "series" in err and "power_split" in err
    assert main(["compile", "--jobs", "0", "--group", "bev"]) == 2
    assert "--jobs = 0" in capsys.readouterr().err
    assert main(["compile", "--examples", str(ROOT / "docs"), "--group", "bev"]) == 2
    assert "series_hev.toml" in capsys.readouterr().err


def _hevsim(args: list[str], cache: Path, cwd: Path) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache), "HEVSIM_PROGRESS": "1"}
    env.pop("HEVSIM_FORWARD", None)
    code = "import sys; from hevsim.cli import main; sys.exit(main(sys.argv[1:]))"
    return subprocess.run(
        [sys.executable, "-c", code, *args], env=env, cwd=cwd, capture_output=True, text=True, timeout=1200
    )


def test_compile_fills_an_empty_cache_and_the_run_then_loads_it(tmp_path: Path) -> None:
    """On an empty cache the probe says cold; ``hevsim compile --group bev`` compiles it (one
    progress line); then the probe says compiled and a BEV run prints no compile notice."""
    cache = tmp_path / "numba"
    cache.mkdir()
    listed = _hevsim(["compile", "--list"], cache, tmp_path)
    assert listed.returncode == 0, listed.stderr
    row = {line.split()[0]: line.split()[1] for line in listed.stdout.splitlines()[1:]}
    assert row["bev"] == "cold" and set(row) == {g.name for g in GROUPS}
    done = _hevsim(["compile", "--group", "bev", "--jobs", "1"], cache, tmp_path)
    assert done.returncode == 0, done.stderr
    assert "[1/1] bev: compiled in " in done.stderr, done.stderr
    assert "kernel group(s) in 1 process(es): bev" in done.stderr
    listed = _hevsim(["compile", "--list"], cache, tmp_path)
    row = {line.split()[0]: line.split()[1] for line in listed.stdout.splitlines()[1:]}
    assert row["bev"] == "compiled" and row["parallel"] == "cold"
    run = _hevsim(
        [
            "simulate",
            str(EXAMPLES / "bev.toml"),
            "--cycle",
            "udds",
            "--out",
            str(tmp_path / "r"),
            "--no-plots",
        ],
        cache,
        tmp_path,
    )
    assert run.returncode == 0, run.stderr
    assert "compiling" not in run.stderr, run.stderr
    assert group("bev").cold_compile_s > 0.0
