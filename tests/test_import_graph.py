"""The package's import graph (issue 24 items 5 and 6).

* No import cycle between modules of ``src/hevsim`` (:data:`KNOWN_CYCLES` is empty: a new
  cycle fails). The layers themselves are the import-linter contract in ``pyproject.toml``
  (``lint-imports``, run by ``make test``).
* One registry: only :data:`hevsim.architectures.ARCHITECTURES` maps ``[powertrain]
  architecture`` to a builder (no second ``"module:build_..."`` table, no dict or if-chain over
  architecture names that picks a builder).
"""

from __future__ import annotations

import ast
import re
from pathlib import Path
from typing import Any

import grimp
import pytest

SRC = Path(__file__).resolve().parents[1] / "src" / "hevsim"

KNOWN_CYCLES: set[frozenset[str]] = set()
# (the last three, sim/ forward-pack_vehicle-simulator, battery/ life-pack-pack_run and thermal/
# cht-flow-rans, went with issue 24 item 6: what the siblings share sits in a lower module)


def _cycles() -> set[frozenset[str]]:
    """Strongly connected sets of more than one module (a package importing its own
    submodules is not a cycle: importing ``hevsim.x.y`` runs ``hevsim.x`` first anyway)."""
    g = grimp.build_graph("hevsim")
    edges = {
        m: {t for t in g.find_modules_directly_imported_by(m) if not t.startswith(m + ".")} for m in g.modules
    }
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: set[frozenset[str]] = set()

    def visit(v: str) -> None:  # Tarjan, iterative enough for a graph of ~150 modules
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in edges.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = set()
            while True:
                w = stack.pop()
                on.discard(w)
                comp.add(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.add(frozenset(comp))

    for m in sorted(edges):
        if m not in index:
            visit(m)
    return out


def test_no_import_cycles_but_the_known_ones() -> None:
    found = _cycles()
    new = [sorted(c) for c in found - KNOWN_CYCLES]
    gone = [sorted(c) for c in KNOWN_CYCLES - found]
    assert not new, f"new import cycle(s) in src/hevsim: {new}"
    assert not gone, f"cycle(s) fixed: remove them from KNOWN_CYCLES: {gone}"


def test_the_layers_contract_ignores_no_import() -> None:
    """The import-linter contracts of pyproject.toml hold for every module: no ``ignore_imports``
    (the series architecture's imports of sim/model.py and sim/kernel.py were the last, until
    its model and point kernels moved below sim/, issue 24 item 2)."""
    import tomllib

    cfg = tomllib.loads((SRC.parents[1] / "pyproject.toml").read_text(encoding="utf-8"))
    contracts = cfg["tool"]["importlinter"]["contracts"]
    assert contracts and all(not c.get("ignore_imports") for c in contracts)


def test_battery_and_thermal_import_no_vehicle_layer() -> None:
    """``battery/`` and ``thermal/`` import nothing from sim/, optimal/, control/, architectures/
    (function-level imports included: grimp reads every import statement)."""
    g = grimp.build_graph("hevsim")
    bad = []
    for m in sorted(g.modules):
        if m.startswith(("hevsim.battery", "hevsim.thermal")):
            for t in g.find_modules_directly_imported_by(m):
                if t.startswith(("hevsim.sim", "hevsim.optimal", "hevsim.control", "hevsim.architectures")):
                    bad.append(f"{m} -> {t}")
    assert bad == []


def _layers_contract() -> dict[str, Any]:
    """The import-linter layers contract of pyproject.toml (its ``layers``: top first)."""
    import tomllib

    cfg = tomllib.loads((SRC.parents[1] / "pyproject.toml").read_text(encoding="utf-8"))
    (contract,) = [c for c in cfg["tool"]["importlinter"]["contracts"] if c["type"] == "layers"]
    return dict(contract)


def _layer_of(module: str, layers: list[str]) -> int:
    """Index (0 = top) of the layer holding ``module`` (siblings are split on ``|`` or ``:``)."""
    (i,) = [i for i, layer in enumerate(layers) if module in re.split(r"\s*[|:]\s*", layer.strip())]
    return i


BELOW_REPORT = ("sim", "optimal", "control", "architectures", "components", "battery", "thermal")


def test_report_sits_with_cosim_and_studies_above_sim_and_optimal() -> None:
    """DESIGN.md's picture and issue 24 item 6: ``cosim · studies · report`` over ``sim ·
    optimal``, under cli; and no module of a lower package reaches ``hevsim.report`` by any
    chain of imports (function-level ones included): a result saves its plots through the
    plotters of :mod:`hevsim.figures`, which report registers."""
    contract = _layers_contract()
    layers = contract["layers"]
    at = {m: _layer_of(f"hevsim.{m}", layers) for m in ("cli", "cosim", "studies", "report", *BELOW_REPORT)}
    assert at["cli"] < at["report"] == at["cosim"] == at["studies"]
    assert all(at["report"] < at[m] for m in BELOW_REPORT), at
    assert "sim, optimal < cosim, studies, report <" in contract["name"]  # its name says so too
    g = grimp.build_graph("hevsim")
    reach = [
        m
        for m in BELOW_REPORT
        if g.chain_exists(importer=f"hevsim.{m}", imported="hevsim.report", as_packages=True)
    ]
    assert reach == [], f"these packages import hevsim.report (directly or through others): {reach}"


def test_results_find_the_report_plotters_without_importing_report_first() -> None:
    """``import hevsim`` imports neither the report layer nor pandas/matplotlib; the first
    look-up of a plotter imports hevsim.report, whose registered functions draw the plots."""
    import json
    import subprocess
    import sys

    code = (
        "import sys, json, hevsim\n"
        "from hevsim.figures import plotter\n"
        "before = [m for m in ('hevsim.report', 'pandas', 'matplotlib') if m in sys.modules]\n"
        "p, q = plotter('simulation'), plotter('optimum')\n"
        "print(json.dumps([before, p.__module__ + '.' + p.__name__, q.__module__ + '.' + q.__name__]))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    before, sim_plotter, dp_plotter = json.loads(out.stdout)
    assert before == []
    assert sim_plotter == "hevsim.report.plot_simulation"
    assert dp_plotter == "hevsim.report.dp_plots.plot_optimum"


def test_an_unknown_plotter_is_named() -> None:
    from hevsim.figures import plotter

    with pytest.raises(LookupError, match=r"'no-such-kind'.*known: \[.*'optimum'.*'simulation'"):
        plotter("no-such-kind")


REGISTRY = SRC / "architectures" / "__init__.py"
BUILDER_REF = re.compile(r"^hevsim(\.\w+)+:build_\w+$")


def _names() -> tuple[set[str], set[str]]:
    from hevsim.architectures import ARCHITECTURES

    refs = [getattr(a, "builder", None) or a.spec.builder for a in ARCHITECTURES.values()]  # (older entries)
    return set(ARCHITECTURES), {r.partition(":")[2] for r in refs}


def _mentions(node: ast.AST, builders: set[str]) -> bool:
    for n in ast.walk(node):
        if (isinstance(n, ast.Name) and n.id in builders) or (
            isinstance(n, ast.Attribute) and n.attr in builders
        ):
            return True
        if isinstance(n, ast.Constant) and isinstance(n.value, str) and BUILDER_REF.match(n.value):
            return True
    return False


def second_registries(path: Path, source: str | None = None) -> list[str]:
    """Places in ``path`` (outside the registry) that map architecture names to builders: a
    ``"module:build_..."`` reference, a dict literal keyed by two or more architecture names
    whose values name builders, or an ``if``/``elif`` on an architecture name that calls a
    builder."""
    names, builders = _names()
    tree = ast.parse(source if source is not None else path.read_text(encoding="utf-8"))
    hits = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and BUILDER_REF.match(node.value):
            hits.append(f"{path.name}:{node.lineno}: builder reference {node.value!r}")
        elif isinstance(node, ast.Dict):
            keys = {k.value for k in node.keys if isinstance(k, ast.Constant)}
            if len(keys & names) >= 2 and any(_mentions(v, builders) for v in node.values):
                hits.append(f"{path.name}:{node.lineno}: dict from architecture names to builders")
        elif isinstance(node, ast.If):
            consts = {n.value for n in ast.walk(node.test) if isinstance(n, ast.Constant)}
            if consts & names and any(_mentions(s, builders) for s in node.body):
                hits.append(f"{path.name}:{node.lineno}: if on an architecture name picking a builder")
    return hits


def test_one_registry_maps_architectures_to_builders() -> None:
    hits = []
    for path in sorted(SRC.rglob("*.py")):
        if path != REGISTRY:
            hits += [f"{path.relative_to(SRC)}: {h}" for h in second_registries(path)]
    assert hits == []
    assert second_registries(REGISTRY) != []  # the registry itself is what the scan finds


@pytest.mark.parametrize(
    "source",
    [
        'SPECS = {"series": "hevsim.sim.model:build_series_hev"}',
        'B = {"parallel": build_parallel_hev, "bev": build_bev}',
        'if cfg.architecture == "bev":\n    m = build_bev(cfg)',
    ],
)
def test_the_scan_finds_a_second_registry(source: str) -> None:
    assert second_registries(Path("x.py"), source)


# every dict literal keyed by two or more architecture names, with why it is not a second
# registry (file, variable): a new one fails until it is folded into the registry or listed here
PER_ARCHITECTURE_TABLES = {
    # the file schema (ground layer): display names and the [controller] keys each architecture reads
    ("config.py", "ARCHITECTURE_LABELS"), ("config.py", "ARCHITECTURE_CONTROLLER_KEYS"),
    # kernel-group warm-ups (hevsim compile): groups named after architectures, not builders
    ("warmup.py", "WARM"),
}  # fmt: skip


def _builder_calls(path: Path, source: str | None = None) -> list[str]:
    """Calls of a registered builder by name outside the module that defines it (a model must be
    built through the registry: ``architecture(name).build(cfg)`` or ``build_vehicle(cfg)``)."""
    from hevsim.architectures import ARCHITECTURES

    own = {a.builder.partition(":")[2]: a.builder.partition(":")[0] for a in ARCHITECTURES.values()}
    module = "hevsim." + ".".join(path.relative_to(SRC).with_suffix("").parts).removesuffix(".__init__")
    hits = []
    for node in ast.walk(ast.parse(source if source is not None else path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Call):
            f = node.func
            name = f.id if isinstance(f, ast.Name) else f.attr if isinstance(f, ast.Attribute) else ""
            if name in own and own[name] != module:
                hits.append(
                    f"{path.relative_to(SRC)}:{node.lineno}: calls {name} (build through the registry)"
                )
    return hits


def _architecture_tables(path: Path, source: str | None = None) -> list[tuple[str, str, int]]:
    """(file, variable, line) of every assignment of a dict literal keyed by two or more
    architecture names."""
    names, _ = _names()
    out = []
    for node in ast.walk(ast.parse(source if source is not None else path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Assign | ast.AnnAssign) and isinstance(node.value, ast.Dict):
            keys = {k.value for k in node.value.keys if isinstance(k, ast.Constant)}
            if len(keys & names) >= 2:
                target = node.targets[0] if isinstance(node, ast.Assign) else node.target
                out.append((path.name, ast.unparse(target), node.lineno))
    return out


def test_no_builder_is_called_outside_the_registry() -> None:
    hits = []
    for path in sorted(SRC.rglob("*.py")):
        hits += _builder_calls(path)
    assert hits == []


def test_per_architecture_tables_are_the_known_ones() -> None:
    """A new table keyed by architecture names (a second registry in the making: a formulation,
    builder, kernel or controller per architecture) fails until folded into
    :data:`hevsim.architectures.ARCHITECTURES` or listed in :data:`PER_ARCHITECTURE_TABLES`."""
    found = {(f, v) for path in sorted(SRC.rglob("*.py")) if path != REGISTRY
             for f, v, _ in _architecture_tables(path)}  # fmt: skip
    assert found - PER_ARCHITECTURE_TABLES == set(), "fold these into the registry"
    assert PER_ARCHITECTURE_TABLES - found == set(), "gone: remove them from PER_ARCHITECTURE_TABLES"


def test_the_scans_find_a_builder_call_and_a_table() -> None:
    src = 'def f(cfg):\n    return build_bev(cfg)\nKERNELS = {"series": 1, "bev": 2}\n'
    probe = SRC / "sim" / "x_probe.py"  # a module path in the package (never written)
    assert _builder_calls(probe, src) == ["sim/x_probe.py:2: calls build_bev (build through the registry)"]
    assert _architecture_tables(probe, src) == [("x_probe.py", "KERNELS", 3)]
