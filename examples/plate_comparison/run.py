"""Cooling-plate comparison (issue 19 item 4): the shipped 3-pass serpentine against other
channel layouts at equal coolant flow rate, each run through the thesis module case with the
3-D laminar coolant (conjugate heat transfer on the frozen flow) and with the 1-D channel.

The module case is ``examples/cosim_module``'s (``run_module_cht.py``): the 250 W / 150 W
square power cycle, the 2s6p module in process, the 3-D FEM module, Gauss-Seidel with 1 s
exchange, module at 30 degC, coolant inlet 15 degC. Only the plate's ``[geometry]`` changes
from layout to layout (``layouts.toml``: 2, 3 and 4 passes of the 8 x 4 mm channel).

Reported per layout and coolant model (``comparison.csv`` / ``.json`` / ``.md``):

* ``peak_cell_temp_c``: hottest node in any cell over the run [degC];
* ``hottest_cell_mean_c``: highest cell mean temperature at the end [degC];
* ``cell_spread_k``: hottest minus coldest cell mean temperature at the end [K];
* ``plate_spread_k``: hottest minus coldest node of the plate's top face at the end [K];
* ``pressure_drop_pa`` and ``pump_power_w`` (= pressure drop x flow rate): for the 3-D
  coolant from the Navier-Stokes solution; for the 1-D channel the developed-flow closed form
  ``2 (f Re) mu U L / D_h^2`` over the centre-line length (Shah & London's f Re of the
  rectangle, :func:`hevsim.thermal.flow.duct_fanning_re`; no bend or entrance losses);
* ``outlet_temp_c`` at the end [degC];
* ``heat_removed_j``: heat through the channel wall over the run [J], from the FEM module's
  ``wall_heat_w`` (the heat the plate actually gave: it closes the module's energy balance
  with its stored energy and the cells' heat); ``coolant_heat_j`` is the same integral of the
  coolant's reported ``cooling_power_w``, which the Gauss-Seidel exchange evaluates at the
  wall temperatures of the step's start (a few % higher while the plate cools fast).

Pictures: ``plate_comparison.png`` (the plates' top faces at the end, one colour scale;
thesis fig 4.30), ``comparison.png`` (bars of the figures above) and
``outlet_temperature.png`` (outlet temperature over time, thesis fig 4.31). Each co-simulation's
own results are kept in ``<layout>/<model>/`` (``results.csv``, fields, pictures).

Run:  .venv/bin/python examples/plate_comparison/run.py [OUT_DIR] [--study layouts.toml] [--jobs 2]
The output folder is created by hevsim and appears atomically (an existing folder is replaced
only if hevsim made it).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
import re
import sys
import textwrap
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "cosim_module"))

from run_module import N_CELLS  # noqa: E402
from run_module_cht import module_cht_system  # noqa: E402

from hevsim.errors import ConfigError  # noqa: E402

DEFAULT_STUDY = HERE / "layouts.toml"
#: Keys of the study file (``geometry`` and ``flow``: overrides common to every layout, e.g.
#: a coarser mesh).
STUDY_KEYS = ("name", "base", "flow_l_min", "grad_div", "duration_s", "geometry", "flow", "layout")
REQUIRED_KEYS = ("base", "flow_l_min", "duration_s", "layout")
LAYOUT_KEYS = ("name", "label", "geometry")
#: Coolant models compared, in table order, with their labels.
MODELS = {"cht": "3-D laminar", "1d": "1-D channel"}
#: Columns of the comparison table: key, label, format.
COLUMNS = (
    ("peak_cell_temp_c", "peak cell [°C]", "{:.3f}"),
    ("hottest_cell_mean_c", "hottest cell mean [°C]", "{:.3f}"),
    ("cell_spread_k", "cell spread [K]", "{:.3f}"),
    ("plate_spread_k", "plate spread [K]", "{:.3f}"),
    ("plate_max_c", "plate max [°C]", "{:.3f}"),
    ("pressure_drop_pa", "Δp [Pa]", "{:.0f}"),
    ("pump_power_w", "pump power [mW]", "{:.3f}"),
    ("outlet_temp_c", "outlet [°C]", "{:.3f}"),
    ("heat_removed_j", "heat removed [J]", "{:.0f}"),
)


@dataclasses.dataclass(frozen=True)
class Layout:
    """One plate layout: ``name`` (folder), ``label`` (tables, figures) and the ``[geometry]``
    keys it replaces."""

    name: str
    label: str
    geometry: dict[str, Any]


@dataclasses.dataclass(frozen=True)
class Study:
    """A validated comparison: the base module TOML, the flow rate [L/min], the flow's grad-div
    factor [-], the run length [s], overrides for every layout and the layouts."""

    source: str
    base: Path
    flow_l_min: float
    grad_div: float
    duration_s: float
    geometry: dict[str, Any]
    flow: dict[str, Any]
    layouts: tuple[Layout, ...]

    def module_data(self, layout: Layout) -> dict[str, Any]:
        """The base module TOML mapping with the layout's geometry (validated)."""
        from hevsim.schema import read_toml
        from hevsim.thermal.run import thermal_config_from_dict

        data = read_toml(self.base)
        data["geometry"] = {**data.get("geometry", {}), **self.geometry, **layout.geometry}
        data["name"] = f"{data.get('name', 'module')}_{layout.name}"
        where = f"{self.source}: layout '{layout.name}'"
        thermal_config_from_dict(data, where, self.base.parent).geometry.check(where)
        return data

    def coolant_data(self, layout: Layout) -> dict[str, Any]:
        """The layout's module mapping plus the ``[flow]`` section of the 3-D coolant."""
        from hevsim.thermal.flow import flow_config_from_dict

        data = self.module_data(layout)
        data["flow"] = {**self.flow, "flow_l_min": self.flow_l_min, "grad_div": self.grad_div}
        flow_config_from_dict(data, f"{self.source}: layout '{layout.name}'", self.base.parent)
        return data


def _number(data: dict[str, Any], key: str, source: str, low: float, default: float | None = None) -> float:
    value = data.get(key, default)
    if (
        isinstance(value, bool)
        or not isinstance(value, int | float)
        or not math.isfinite(value)
        or value < low
    ):
        raise ConfigError(f"{source}: key '{key}' = {value!r}; expected a number >= {low:g}.")
    return float(value)


def _table(data: dict[str, Any], key: str, source: str) -> dict[str, Any]:
    value = data.get(key, {})
    if not isinstance(value, dict):
        raise ConfigError(f"{source}: key '{key}' = {value!r}; expected a table of keys.")
    return dict(value)


def study_from_dict(data: dict[str, Any], source: str, base_dir: Path) -> Study:
    """Validate a study mapping (``layouts.toml``); every layout's geometry is checked."""
    for key in data:
        if key not in STUDY_KEYS:
            raise ConfigError(f"{source}: key '{key}' is not known; valid keys are: {', '.join(STUDY_KEYS)}.")
    for key in REQUIRED_KEYS:
        if key not in data:
            raise ConfigError(f"{source}: key '{key}' is missing.")
    flow = _number(data, "flow_l_min", source, 0.0)
    if flow <= 0.0:
        raise ConfigError(
            f"{source}: key 'flow_l_min' = {flow!r}; expected a positive laminar flow rate [L/min]."
        )
    raw = data["layout"]
    if not isinstance(raw, list) or not raw:
        raise ConfigError(f"{source}: key 'layout' = {raw!r}; expected one or more [[layout]] tables.")
    layouts = []
    for i, entry in enumerate(raw):
        where = f"{source}: layout {i + 1}"
        if not isinstance(entry, dict):
            raise ConfigError(f"{where}: expected a table, got {entry!r}.")
        for key in entry:
            if key not in LAYOUT_KEYS:
                raise ConfigError(
                    f"{where}: key '{key}' is not known; valid keys are: {', '.join(LAYOUT_KEYS)}."
                )
        name = entry.get("name")
        if not isinstance(name, str) or not re.fullmatch(r"[A-Za-z0-9_-]+", name):
            raise ConfigError(
                f"{where}: key 'name' = {name!r}; expected a folder name (letters, digits, _ or -)."
            )
        layouts.append(Layout(name, str(entry.get("label", name)), _table(entry, "geometry", where)))
    names = [lay.name for lay in layouts]
    if len(set(names)) != len(names):
        raise ConfigError(f"{source}: layout names {names} repeat; expected distinct names.")
    base = Path(str(data["base"]))
    base = base if base.is_absolute() else (base_dir / base).resolve()
    study = Study(
        source,
        base,
        flow,
        _number(data, "grad_div", source, 0.0, 0.0),
        _number(data, "duration_s", source, 1.0),
        _table(data, "geometry", source),
        _table(data, "flow", source),
        tuple(layouts),
    )
    for lay in layouts:
        study.coolant_data(lay)  # validates the module, the layout's geometry and [flow]
    return study


def load_study(path: str | Path) -> Study:
    """Read and validate a study file (``layouts.toml``)."""
    from hevsim.schema import read_toml

    p = Path(path)
    return study_from_dict(read_toml(p), str(p), p.resolve().parent)


def toml_text(data: dict[str, Any], prefix: str = "") -> str:
    """A mapping of scalars, lists of scalars and tables (a module TOML) as TOML text."""
    scalars = {k: v for k, v in data.items() if not isinstance(v, dict)}
    lines = [f"[{prefix}]"] if prefix and scalars else []

    def value(v: Any) -> str:
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, list):
            return "[" + ", ".join(value(x) for x in v) + "]"
        if isinstance(v, dict):  # inside a list: an inline table
            return "{ " + ", ".join(f'"{k}" = {value(x)}' for k, x in v.items()) + " }"
        if isinstance(v, str):
            return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
        return repr(v)

    lines += [f'"{k}" = {value(v)}' for k, v in scalars.items()]
    out = "\n".join(lines) + ("\n\n" if lines else "")
    for k, v in data.items():
        if isinstance(v, dict):
            out += toml_text(v, f'{prefix}."{k}"' if prefix else f'"{k}"')
    return out


def channel_length_m(geometry: Any) -> float:
    """Length of the channel's centre line [m]."""
    return float(np.linalg.norm(np.diff(geometry.channel_path_m(), axis=0), axis=1).sum())


def developed_pressure_drop_pa(geometry: Any, coolant: Any, flow_m3_s: float) -> float:
    """Pressure drop [Pa] of fully developed laminar flow along the channel's centre line:
    ``2 (f Re) mu U L / D_h^2`` (Fanning f Re of the rectangle, Shah & London 1978)."""
    from hevsim.thermal.flow import duct_fanning_re

    w, h = geometry.channel_width_m, geometry.channel_height_m
    dh = 2 * w * h / (w + h)
    u = flow_m3_s / (w * h)
    return 2 * duct_fanning_re(w, h) * coolant.viscosity_pa_s * u * channel_length_m(geometry) / dh**2


def layout_system(study: Study, model: str, module_toml: Path, coolant_toml: Path) -> Any:
    """The module co-simulation (``run_module_cht.module_cht_system``) with the coolant
    ``model`` (``cht`` or ``1d``) on the layout's configs (absolute paths)."""
    sys_ = module_cht_system(study.duration_s, model, "inprocess", study.flow_l_min)
    comps = []
    for c in sys_.components:
        if c.name == "fem":
            c = dataclasses.replace(c, parameters={**c.parameters, "config": str(module_toml)})
        elif c.name == "coolant":
            config = coolant_toml if model == "cht" else module_toml
            params = {**c.parameters, "config": str(config)}
            if model == "cht":
                params["grad_div"] = study.grad_div
            c = dataclasses.replace(c, parameters=params)
        comps.append(c)
    return dataclasses.replace(sys_, components=comps)


def run_case(study: Study, layout: Layout, model: str, folder: Path) -> dict[str, Any]:
    """One co-simulation into ``folder/<model>``; the figures of the table, the outlet
    temperature over time and the plate's top face at the end."""
    import time

    from hevsim.cosim.system import run_cosim
    from hevsim.thermal.pictures import plate_top_face
    from hevsim.units import KELVIN_OFFSET as C0

    cpu0 = time.process_time()
    res = run_cosim(
        layout_system(study, model, folder / "module.toml", folder / "coolant.toml"), folder / model
    )
    fem, cool = res.participants["fem"], res.participants["coolant"]
    final_c = fem.field_temp_k() - C0
    face = plate_top_face(fem.mesh, fem.disc, fem.cfg.geometry, final_c)
    cells = np.array([res[f"fem.cell{c}_temp_k"][-1] for c in range(N_CELLS)]) - C0
    t = np.asarray(res.time_s)
    flow_m3_s = study.flow_l_min * 1e-3 / 60.0
    if model == "cht":
        dp = float(cool.flow.metrics["pressure_drop_pa"])
        reynolds = float(cool.flow.metrics["reynolds"])
    else:
        dp = developed_pressure_drop_pa(fem.cfg.geometry, cool.channel.coolant, flow_m3_s)
        reynolds = float(cool.channel.reynolds)
    return {
        "layout": layout.name,
        "label": layout.label,
        "model": model,
        "passes": int(fem.cfg.geometry.channel_passes),
        "channel_length_m": channel_length_m(fem.cfg.geometry),
        "reynolds": reynolds,
        "peak_cell_temp_c": float(np.max(res["fem.cell_max_temp_k"])) - C0,
        "hottest_cell_mean_c": float(cells.max()),
        "cell_spread_k": float(cells.max() - cells.min()),
        "plate_spread_k": face.spread_k,
        "plate_max_c": float(face.temp_c.max()),
        "plate_min_c": float(face.temp_c.min()),
        "pressure_drop_pa": dp,
        "pump_power_w": dp * flow_m3_s,
        "outlet_temp_c": float(res["coolant.outlet_temp_k"][-1]) - C0,
        "heat_removed_j": _integral(t, res["fem.wall_heat_w"]),
        "coolant_heat_j": _integral(t, res["coolant.cooling_power_w"]),
        "stored_energy_change_j": float(res["fem.stored_energy_j"][-1] - res["fem.stored_energy_j"][0]),
        "cpu_s": time.process_time() - cpu0,
        "wall_s": float(res.stats["wall_s"]),
        "time_s": t,
        "outlet_temp_series_c": np.asarray(res["coolant.outlet_temp_k"]) - C0,
        "face": face,
    }


def _integral(t: np.ndarray, y: Any) -> float:
    """Trapezoidal integral of the samples ``y`` over the times ``t`` [s]."""
    v = np.asarray(y, dtype=float)
    return float(np.sum(0.5 * (v[1:] + v[:-1]) * np.diff(t)))


def _case(args: tuple[Study, Layout, str, Path]) -> dict[str, Any]:
    return run_case(*args)


def table_markdown(rows: list[dict[str, Any]]) -> str:
    """The comparison as a Markdown table (pump power in mW)."""
    head = "| layout | coolant | " + " | ".join(label for _, label, _ in COLUMNS) + " |"
    lines = [head, "|" + " --- |" * (len(COLUMNS) + 2)]
    for r in rows:
        vals = [fmt.format(r[k] * (1e3 if k == "pump_power_w" else 1.0)) for k, _, fmt in COLUMNS]
        lines.append(f"| {r['label']} | {MODELS[r['model']]} | " + " | ".join(vals) + " |")
    return "\n".join(lines) + "\n"


def plot_bars(rows: list[dict[str, Any]], path: Path) -> Path:
    """Grouped bars (layouts x coolant models) of the table's figures."""
    from matplotlib.figure import Figure

    from hevsim.report.save import save_png

    labels = list(dict.fromkeys(r["label"] for r in rows))
    fig = Figure(figsize=(11, 6), layout="constrained")
    axes = fig.subplots(2, math.ceil(len(COLUMNS) / 2)).ravel()
    width = 0.8 / len(MODELS)
    for ax, (key, label, _) in zip(axes, COLUMNS, strict=False):
        for j, model in enumerate(MODELS):
            vals = [next(r[key] for r in rows if r["label"] == lab and r["model"] == model) for lab in labels]
            vals = [v * 1e3 if key == "pump_power_w" else v for v in vals]
            ax.bar(np.arange(len(labels)) + (j - 0.5 * (len(MODELS) - 1)) * width, vals, width,
                   label=MODELS[model])  # fmt: skip
        ax.set_xticks(np.arange(len(labels)), [textwrap.fill(lab, 10) for lab in labels], fontsize=7)
        ax.set_title(label, fontsize=9)
        if key.endswith("_c"):  # temperatures: the differences, not the distance from 0 degC
            lo, hi = min(r[key] for r in rows), max(r[key] for r in rows)
            pad = 0.25 * (hi - lo) + 0.01
            ax.set_ylim(lo - pad, hi + pad)
    axes[0].legend(fontsize=8)
    for ax in axes[len(COLUMNS) :]:
        ax.set_visible(False)
    return save_png(fig, path, 120)


def plot_outlet(rows: list[dict[str, Any]], path: Path) -> Path:
    """Coolant outlet temperature over time per layout and model (thesis fig 4.31)."""
    from matplotlib.figure import Figure

    from hevsim.report.save import save_png

    fig = Figure(figsize=(7, 4), layout="constrained")
    ax = fig.add_subplot()
    for i, r in enumerate(rows):
        style = "-" if r["model"] == "cht" else "--"
        ax.plot(r["time_s"], r["outlet_temp_series_c"], style, color=f"C{i // len(MODELS)}",
                label=f"{r['label']}, {MODELS[r['model']]}")  # fmt: skip
    ax.set_xlabel("time [s]")
    ax.set_ylabel("coolant outlet temperature [°C]")
    ax.set_title("Coolant outlet temperature (inlet 15 °C, module from 30 °C)", fontsize=10)
    ax.legend(fontsize=8)
    return save_png(fig, path, 120)


def run_study(study: Study, out: str | Path, jobs: int = 1) -> list[dict[str, Any]]:
    """Run every layout with both coolant models (``jobs`` worker processes; 1 = in this
    process) and write the results folder ``out`` atomically; returns the table rows."""
    from hevsim.io import atomic_directory, write_json, write_text_atomic
    from hevsim.thermal.pictures import plot_plate_comparison

    with atomic_directory(out) as tmp:
        cases = []
        for lay in study.layouts:
            folder = tmp / lay.name
            folder.mkdir()
            write_text_atomic(folder / "module.toml", toml_text(study.module_data(lay)))
            write_text_atomic(folder / "coolant.toml", toml_text(study.coolant_data(lay)))
            cases += [(study, lay, model, folder) for model in MODELS]
        if jobs > 1:
            with ProcessPoolExecutor(max_workers=jobs) as pool:
                rows = list(pool.map(_case, cases))
        else:
            rows = [_case(c) for c in cases]
        scalar = [
            {k: v for k, v in r.items() if k not in ("time_s", "outlet_temp_series_c", "face")} for r in rows
        ]
        write_json(tmp / "comparison.json", {"study": _study_json(study), "rows": scalar})
        keys = list(scalar[0])
        csv = [",".join(keys)] + [",".join(str(r[k]) for k in keys) for r in scalar]
        write_text_atomic(tmp / "comparison.csv", "\n".join(csv) + "\n")
        write_text_atomic(tmp / "comparison.md", table_markdown(rows))
        cht = [r for r in rows if r["model"] == "cht"]
        plot_plate_comparison(
            [r["face"] for r in cht],
            [r["label"] for r in cht],
            tmp / "plate_comparison.png",
            f"Cooling plate at t = {study.duration_s:g} s, 3-D laminar coolant at {study.flow_l_min:g} L/min",
        )
        plot_bars(rows, tmp / "comparison.png")
        plot_outlet(rows, tmp / "outlet_temperature.png")
    return rows


def _study_json(study: Study) -> dict[str, Any]:
    d = dataclasses.asdict(study)
    d["base"] = str(study.base)
    return d


def main() -> None:
    ap = argparse.ArgumentParser(description="cooling-plate layouts compared in the module co-simulation")
    ap.add_argument("out", nargs="?", default="results/plate_comparison")
    ap.add_argument("--study", default=str(DEFAULT_STUDY), help="layouts file (default layouts.toml here)")
    ap.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1), help="worker processes")
    a = ap.parse_args()
    rows = run_study(load_study(a.study), a.out, max(1, a.jobs))
    print(table_markdown(rows))
    cpu = sum(r["cpu_s"] for r in rows)
    print(f"CPU {cpu:.1f} s in the co-simulations; results in {a.out}/")


if __name__ == "__main__":
    main()
