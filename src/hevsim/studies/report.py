"""``hevsim study-report``: Pareto fronts, sensitivity ranking, scatter matrices, Markdown.

Per (cycle, solver) of a study folder, from its finished ``ok`` cases:

- ``pareto_<front>.csv``: the non-dominated cases of each ``[[pareto]]`` front of the study;
- ``sensitivity.csv``: for every kept metric, each varied parameter's first-order and total
  Sobol indices (``saltelli`` sampling) or standardized regression coefficient and the fit's
  R^2 (other samplings), ranked (1 = most influential);
- ``scatter_<cycle>_<solver>.png``: scatter matrix of the varied parameters and the metrics;
- ``report.md``: all of the above in one page.

Files are added to the study folder atomically and listed in its marker.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from hevsim.studies.analysis import pareto_mask, regression_ranking, sobol_indices
from hevsim.studies.runner import StudyFolder, load_folder_study, read_results
from hevsim.studies.spec import StudyError

SCATTER_MAX_POINTS = 2000
"""Points drawn per scatter matrix (an evenly spaced subset beyond this) [-]."""
SCATTER_MAX_COLUMNS = 8
"""Columns of a scatter matrix: the varied parameters first, then the metrics [-]."""
TABLE_ROWS = 20
"""Rows of a front shown in report.md [-]."""


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text).strip("_") or "x"


def sensitivity(info: dict[str, Any], results: pd.DataFrame) -> pd.DataFrame:
    """The sensitivity table of a study's results (see the module docstring)."""
    keys = [p["key"] for p in info["parameters"]]
    rows: list[dict[str, Any]] = []
    ok = results[results["status"] == "ok"]
    for (cycle, solver), grp in results.groupby(["cycle", "solver"], sort=True):
        for metric in info["metrics"]:
            if grp[metric].isna().all():  # a metric this solver does not give
                continue
            if info["method"] == "saltelli":
                n, d = int(info["samples"]), len(keys)
                y = np.full(n * (d + 2), np.nan)
                good = grp[grp["status"] == "ok"]
                y[good["sample_id"].to_numpy()] = good[metric].to_numpy()
                fa, fb, fab = y[:n], y[n : 2 * n], y[2 * n :].reshape(d, n)
                keep = np.isfinite(fa) & np.isfinite(fb) & np.all(np.isfinite(fab), axis=0)
                table = sobol_indices(fa[keep], fb[keep], fab[:, keep])
                order = np.argsort(-table["ST"].to_numpy(), kind="stable")
                rank = np.empty(d, dtype=int)
                rank[order] = np.arange(1, d + 1)
                for j, key in enumerate(keys):
                    rows.append({"cycle": cycle, "solver": solver, "metric": metric, "parameter": key,
                                 "method": "sobol", "rank": int(rank[j]), "S1": table["S1"][j],
                                 "S1_se": table["S1_se"][j], "ST": table["ST"][j], "ST_se": table["ST_se"][j],
                                 "SRC": np.nan, "R2": np.nan, "cases": int(keep.sum())})  # fmt: skip
            else:
                g = ok[(ok["cycle"] == cycle) & (ok["solver"] == solver)]
                src, r2 = regression_ranking(g[keys].to_numpy(np.float64), g[metric].to_numpy(np.float64))
                mag = np.nan_to_num(np.abs(src), nan=-1.0)
                order = np.argsort(-mag, kind="stable")
                rank = np.empty(len(keys), dtype=int)
                rank[order] = np.arange(1, len(keys) + 1)
                for j, key in enumerate(keys):
                    rows.append({"cycle": cycle, "solver": solver, "metric": metric, "parameter": key,
                                 "method": "src", "rank": int(rank[j]), "S1": np.nan, "S1_se": np.nan,
                                 "ST": np.nan, "ST_se": np.nan, "SRC": src[j], "R2": r2,
                                 "cases": len(g)})  # fmt: skip
    return pd.DataFrame(rows)


def _with_objectives(ok: pd.DataFrame, grp: pd.DataFrame, cycle: Any, solver: Any,
                     metric_objs: list[str], vehicle_solvers: set[str]) -> pd.DataFrame | None:  # fmt: skip
    """``grp``'s rows with the objectives it lacks taken from the one cycle-free solver
    (``vehicle_solvers``: labels) that gives them, same sample; None when an objective has no
    single such source."""
    out = grp
    for o in metric_objs:
        if grp[o].notna().any():
            continue
        givers = sorted((set(ok.loc[ok[o].notna(), "solver"]) & vehicle_solvers) - {solver})
        if len(givers) != 1:
            return None
        other = ok[(ok["solver"] == givers[0]) & (ok["cycle"] == cycle)].set_index("sample_id")[o]
        out = out.assign(**{o: out["sample_id"].map(other).to_numpy(np.float64)})
    return out


def fronts(info: dict[str, Any], results: pd.DataFrame) -> dict[str, pd.DataFrame]:
    """Each ``[[pareto]]`` front: its non-dominated ok cases per (cycle, solver).

    An objective a solver does not give (e.g. ``time_0_100_kmh_s`` in the ``simulate`` rows)
    is taken from the one cycle-free solver that gives it (a property of the vehicle: the
    ``performance`` rows of the same sample); a (cycle, solver) group lacking an objective
    that no single cycle-free solver gives has no front.
    """
    from hevsim.studies.solvers import SOLVERS

    keys = [p["key"] for p in info["parameters"]]
    vehicle_solvers = {
        s["label"] for s in info.get("solvers", []) if s["name"] in SOLVERS and SOLVERS[s["name"]].cycle_free
    }
    out: dict[str, pd.DataFrame] = {}
    ok = results[results["status"] == "ok"]
    for p in info.get("pareto", []):
        objs = list(p["minimize"]) + list(p["maximize"])
        sense = np.array([False] * len(p["minimize"]) + [True] * len(p["maximize"]))
        metric_objs = [o for o in objs if o not in keys]
        parts = []
        for (cycle, solver), grp in ok.groupby(["cycle", "solver"], sort=True):
            full = _with_objectives(ok, grp, cycle, solver, metric_objs, vehicle_solvers)
            if full is None:
                continue
            mask = pareto_mask(full[objs].to_numpy(np.float64), sense)
            parts.append(full[mask])
        cols = ["case_id", "cycle", "solver", *dict.fromkeys([*keys, *objs])]
        front = pd.concat(parts) if parts else ok.iloc[:0]
        out[p["name"]] = (
            front[cols].sort_values(["cycle", "solver", objs[0], "case_id"]).reset_index(drop=True)
        )
    return out


def scatter_matrix(frame: pd.DataFrame, columns: list[str], title: str) -> Any:
    """A scatter-matrix figure (Agg canvas, no pyplot): histograms on the diagonal."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    k = len(columns)
    if len(frame) > SCATTER_MAX_POINTS:
        frame = frame.iloc[np.linspace(0, len(frame) - 1, SCATTER_MAX_POINTS).astype(int)]
    fig = Figure(figsize=(1.9 * k + 1, 1.9 * k + 1))
    FigureCanvasAgg(fig)
    axes = fig.subplots(k, k, squeeze=False)
    for i, yi in enumerate(columns):
        for j, xj in enumerate(columns):
            ax = axes[i][j]
            x = frame[xj].to_numpy(np.float64)
            if i == j:
                ax.hist(x[np.isfinite(x)], bins=20, color="0.5")
            else:
                ax.scatter(x, frame[yi].to_numpy(np.float64), s=4, alpha=0.6, linewidths=0)
            if i == k - 1:
                ax.set_xlabel(xj, fontsize=7)
            else:
                ax.set_xticklabels([])
            if j == 0:
                ax.set_ylabel(yi, fontsize=7)
            else:
                ax.set_yticklabels([])
            ax.tick_params(labelsize=6)
    fig.suptitle(title, fontsize=9)
    return fig


def _md_table(frame: pd.DataFrame) -> str:
    def fmt(v: Any) -> str:
        if isinstance(v, float | np.floating):
            return f"{v:.4g}"
        return str(v)

    head = "| " + " | ".join(frame.columns) + " |"
    sep = "|" + "---|" * len(frame.columns)
    body = ["| " + " | ".join(fmt(v) for v in row) + " |" for row in frame.itertuples(index=False)]
    return "\n".join([head, sep, *body])


def study_report(out: str | Path, plots: bool = True) -> dict[str, Any]:
    """Write the analysis files into the study folder ``out``; returns
    ``{"fronts": {name: DataFrame}, "sensitivity": DataFrame, "files": [...]}``."""
    info = load_folder_study(out)
    results = read_results(out)
    if results.empty:
        raise StudyError(f"{out}: the study has no finished case yet; run `hevsim study ... --resume` first.")
    folder = StudyFolder(Path(out))
    keys = [p["key"] for p in info["parameters"]]
    files: list[str] = []
    fr = fronts(info, results)
    for name, front in fr.items():
        rel = f"pareto_{_slug(name)}.csv"
        folder.add_file(rel, lambda p, f=front: f.to_csv(p, index=False, float_format="%.9g"))
        files.append(rel)
    sens = sensitivity(info, results)
    folder.add_file("sensitivity.csv", lambda p: sens.to_csv(p, index=False, float_format="%.6g"))
    files.append("sensitivity.csv")
    pictures: list[str] = []
    if plots:
        from hevsim.io import save_png

        cols = [*keys, *info["metrics"]][:SCATTER_MAX_COLUMNS]
        ok = results[results["status"] == "ok"]
        for (cycle, solver), grp in ok.groupby(["cycle", "solver"], sort=True):
            rel = f"scatter_{_slug(str(cycle))}_{_slug(str(solver))}.png"
            fig = scatter_matrix(grp, cols, f"{info['name']}: {cycle}, {solver} ({len(grp)} cases)")
            folder.add_file(rel, lambda p, f=fig: save_png(f, p, dpi=90))
            pictures.append(rel)
    files.extend(pictures)
    n_ok = int((results["status"] == "ok").sum())
    lines = [
        f"# Study {info['name']}",
        "",
        info.get("description") or "",
        "",
        f"- vehicle: `{info['vehicle']}` ({info['architecture']})",
        f"- sampling: {info['method']}, seed {info['seed']}, {info['n_samples']} samples x "
        f"{len(info['cycles'])} cycle(s) x {len(info['solvers'])} solver(s) = {info['n_cases']} cases",
        f"- finished: {len(results)} cases, {n_ok} ok, {len(results) - n_ok} failed",
        f"- varied: {', '.join(f'`{k}`' for k in keys)}",
        "",
    ]
    failed = results[results["status"] != "ok"]
    if len(failed):
        lines += [
            "## Failed cases (first 10)",
            "",
            _md_table(failed[["case_id", "cycle", "solver", "error"]].head(10)),
            "",
        ]
    for name, front in fr.items():
        lines += [f"## Pareto front `{name}` ({len(front)} cases)", "", _md_table(front.head(TABLE_ROWS)), ""]
    lines += ["## Sensitivity ranking", ""]
    if info["method"] == "saltelli":
        lines += [
            "Sobol indices (Saltelli design): S1 first order, ST total, with bootstrap standard errors.",
            "",
        ]
        show = ["cycle", "solver", "metric", "rank", "parameter", "S1", "S1_se", "ST", "ST_se"]
    else:
        lines += ["Standardized regression coefficients (meaningful when R2 is near 1).", ""]
        show = ["cycle", "solver", "metric", "rank", "parameter", "SRC", "R2"]
    lines += [_md_table(sens.sort_values(["cycle", "solver", "metric", "rank"])[show]), ""]
    for pic in pictures:
        lines += [f"![{pic}]({pic})", ""]
    text = "\n".join(lines)
    folder.add_file("report.md", lambda p: p.write_text(text))
    files.append("report.md")
    return {"fronts": fr, "sensitivity": sens, "files": files}
