"""A plain-Markdown report of a forward-simulation result (``report.md``).

The report holds a title (configuration and cycle), the run information from the metadata,
the metrics table, the energy-audit table, a summary of the mode-change events and the plots
embedded by relative links. No dependency beyond the standard library and pandas.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable, Mapping, Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import pandas as pd

from hevsim.report.plots import (
    GENSET_STATE_NAMES,
    J_PER_KWH,
    PLOT_FILES,
    POWER_MODE_NAMES,
    plot_all,
    power_mode_names,
    split_energy_audit,
)

REPORT_FILE = "report.md"
"""File name of the report inside the output folder."""
MAX_EVENT_ROWS = 20
"""Events listed in the report's events table; the rest are only counted."""
SIGNIFICANT_DIGITS = 4
"""Significant digits of numbers in the report tables."""

PLOT_CAPTIONS: dict[str, str] = {
    "speed_tracking": "Desired vs actual vehicle speed [mph] and the tracking error.",
    "soc": "Battery state of charge [%], genset starting/running spans shaded.",
    "currents": "Battery, motor and generator currents [A] (battery discharge > 0).",
    "engine": "Engine speed [rpm], torque [N·m] and throttle [%]; fuelled spans shaded.",
    "engine_operating_points": "Engine operating points on the BSFC map [g/kWh] with the max-torque curve.",
    "power_modes": "Supervisory power mode over time and the share of time in each mode.",
    "energy_audit": "Energy sources and sinks over the cycle [kWh] and the closing residual.",
}
"""Plot name (file stem) -> one-line caption."""
PLOT_TITLES: dict[str, str] = {
    "speed_tracking": "Speed tracking",
    "soc": "Battery state of charge",
    "currents": "Currents",
    "engine": "Engine",
    "engine_operating_points": "Engine operating points",
    "power_modes": "Power modes",
    "energy_audit": "Energy audit",
}
"""Plot name (file stem) -> section heading."""

_CONFIG_KEYS = ("config_name", "config", "vehicle", "name")
_CYCLE_KEYS = ("cycle_name", "cycle")


def format_number(value: Any, digits: int = SIGNIFICANT_DIGITS) -> str:
    """Format a number for a table: integers as such, others to ``digits`` significant digits.

    Large values keep all their integer digits (``12345.6`` -> ``12346``); very small or very
    large magnitudes use scientific notation. Non-numbers are returned as ``str(value)``.
    """
    if isinstance(value, bool) or not isinstance(value, int | float):
        try:
            value = float(value)
        except (TypeError, ValueError):
            return str(value)
    v = float(value)
    if not math.isfinite(v):
        return str(v)
    if v == 0.0:
        return "0"
    if v.is_integer() and abs(v) < 1e12:
        return str(int(v))
    mag = abs(v)
    if mag < 1e-3 or mag >= 1e9:
        mantissa, exponent = f"{v:.{digits - 1}e}".split("e")
        return f"{_strip_zeros(mantissa)}e{exponent}"
    decimals = max(0, digits - 1 - math.floor(math.log10(mag)))
    return _strip_zeros(f"{v:.{decimals}f}")


def _strip_zeros(text: str) -> str:
    """Drop trailing zeros after a decimal point (``"49.90"`` -> ``"49.9"``)."""
    return text.rstrip("0").rstrip(".") if "." in text else text


def _cell(value: Any) -> str:
    """A Markdown table cell: pipes escaped, line breaks flattened."""
    return str(value).replace("|", "\\|").replace("\n", " ").strip()


def _table(header: Sequence[str], rows: Iterable[Sequence[Any]], align: str = "") -> list[str]:
    """Markdown table lines; ``align`` holds one of 'l', 'r' per column (default left)."""
    marks = {"l": ":---", "r": "---:", "c": ":---:"}
    align = align.ljust(len(header), "l")
    lines = [
        "| " + " | ".join(_cell(h) for h in header) + " |",
        "| " + " | ".join(marks[a] for a in align) + " |",
    ]
    lines += ["| " + " | ".join(_cell(c) for c in row) + " |" for row in rows]
    return lines


def _first(meta: Mapping[str, Any], keys: Sequence[str]) -> str | None:
    for k in keys:
        v = meta.get(k)
        if isinstance(v, str) and v:
            return v
        if isinstance(v, Mapping):
            name = v.get("name")
            if isinstance(name, str) and name:
                return name
    return None


def _metadata_text(key: str, value: Any) -> str:
    """A metadata value as text: Unix times as UTC dates, numbers rounded."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return str(value)
    if key.endswith("unix_s"):
        stamp = datetime.fromtimestamp(float(value), tz=UTC)
        return stamp.strftime("%Y-%m-%d %H:%M:%S UTC")
    return format_number(value)


def _metadata_rows(meta: Mapping[str, Any]) -> list[tuple[str, str]]:
    """Flatten the metadata one level deep into (key, value) rows."""
    rows: list[tuple[str, str]] = []
    for key, value in meta.items():
        if isinstance(value, Mapping):
            for sub, v in value.items():
                rows.append((f"{key}.{sub}", _metadata_text(str(sub), v)))
        else:
            rows.append((str(key), _metadata_text(str(key), value)))
    return rows


def _metric_rows(metrics: Mapping[str, Any]) -> list[tuple[str, str, str, str]]:
    rows = []
    for name, entry in metrics.items():
        if isinstance(entry, Mapping):
            value = entry.get("value")
            unit = str(entry.get("unit", "") or "")
            desc = str(entry.get("description", "") or "")
        else:
            value, unit, desc = entry, "", ""
        rows.append((f"`{name}`", format_number(value), unit, desc))
    return rows


def _audit_lines(energy_audit: Mapping[str, float]) -> list[str]:
    sources, sinks, residual = split_energy_audit(energy_audit)
    total = sum(v for _, v in sources)

    def pct(v: float) -> str:
        return format_number(100.0 * v / total) if total else "n/a"

    rows: list[tuple[str, str, str, str]] = []
    rows += [(k, "source", format_number(v / J_PER_KWH), pct(v)) for k, v in sources]
    rows.append(("**total sources**", "", format_number(total / J_PER_KWH), pct(total)))
    rows += [(k, "sink", format_number(v / J_PER_KWH), pct(v)) for k, v in sinks]
    sink_total = sum(v for _, v in sinks)
    rows.append(("**total sinks**", "", format_number(sink_total / J_PER_KWH), pct(sink_total)))
    lines = _table(("term", "kind", "energy [kWh]", "% of sources"), rows, "llrr")
    if residual is not None:
        lines += [
            "",
            f"Residual (sources - sinks): {format_number(residual / J_PER_KWH)} kWh = "
            f"**{pct(residual)} %** of the total sources.",
        ]
    return lines


def _state_name(kind: str, state: Any, modes: Mapping[int, str]) -> str:
    """Readable name of an event state: genset and power-mode codes mapped to names."""
    if isinstance(state, str):
        return state
    try:
        code = int(state)
    except (TypeError, ValueError):
        return str(state)
    if code != state:
        return str(state)
    if kind == "genset" and 0 <= code < len(GENSET_STATE_NAMES):
        return GENSET_STATE_NAMES[code]
    if kind == "power_mode" and code in modes:
        return modes[code]
    return str(code)


def _time_text(value: Any) -> str:
    """Event time [s] with one decimal, or the value as text."""
    try:
        return f"{float(value):.1f}"
    except (TypeError, ValueError):
        return str(value)


def _event_lines(events: pd.DataFrame | None, modes: Mapping[int, str]) -> list[str]:
    if events is None or len(events) == 0:
        return ["No mode-change events."]
    counts = events["kind"].value_counts(sort=False) if "kind" in events.columns else None
    lines: list[str] = [f"{len(events)} events in total."]
    if counts is not None:
        lines += ["", *_table(("kind", "count"), counts.items(), "lr")]
    shown = events.head(MAX_EVENT_ROWS)
    rows = []
    for rec in shown.to_dict("records"):
        kind = str(rec.get("kind", ""))
        rows.append(
            (
                _time_text(rec.get("time_s", "")),
                kind,
                _state_name(kind, rec.get("from_state", ""), modes),
                _state_name(kind, rec.get("to_state", ""), modes),
                _cell(rec.get("reason", "")),
            )
        )
    title = f"First {len(shown)} of {len(events)} events:" if len(events) > len(shown) else "All events:"
    lines += ["", title, "", *_table(("time [s]", "kind", "from", "to", "reason"), rows, "rllll")]
    return lines


def _plot_lines(plots: Sequence[Path], out_dir: Path) -> list[str]:
    if not plots:
        return ["No plots."]
    lines: list[str] = []
    for p in plots:
        path = Path(p)
        rel = Path(os.path.relpath(path.resolve(), out_dir.resolve())).as_posix()
        caption = PLOT_CAPTIONS.get(path.stem, path.stem.replace("_", " "))
        heading = PLOT_TITLES.get(path.stem, path.stem.replace("_", " ").capitalize())
        lines += [f"### {heading}", "", f"![{caption}]({rel})"]
        lines += ["", f"*{caption}*", ""]
    return lines[:-1]


def render_report(result: Any, out_dir: str | Path, plots: Sequence[Path]) -> str:
    """The Markdown text of the report (see :func:`write_report`)."""
    out = Path(out_dir)
    meta: Mapping[str, Any] = getattr(result, "metadata", None) or {}
    metrics: Mapping[str, Any] = getattr(result, "metrics", None) or {}
    audit: Mapping[str, float] = getattr(result, "energy_audit", None) or {}
    events: pd.DataFrame | None = getattr(result, "events", None)
    ts: pd.DataFrame | None = getattr(result, "timeseries", None)
    modes = power_mode_names(ts) if ts is not None else dict(enumerate(POWER_MODE_NAMES))

    config = _first(meta, _CONFIG_KEYS) or "unnamed configuration"
    cycle = _first(meta, _CYCLE_KEYS)
    title = f"# hevsim report: {config}" + (f" on {cycle}" if cycle else "")
    lines: list[str] = [title, ""]
    meta_rows = _metadata_rows(meta)
    if meta_rows:
        lines += ["## Run information", "", *_table(("item", "value"), meta_rows), ""]
    lines += ["## Metrics", ""]
    if metrics:
        lines += _table(("metric", "value", "unit", "description"), _metric_rows(metrics), "lrll")
    else:
        lines.append("No metrics.")
    lines += ["", "## Energy audit", ""]
    lines += _audit_lines(audit) if audit else ["No energy audit."]
    lines += ["", "## Mode-change events", "", *_event_lines(events, modes), ""]
    lines += ["## Plots", "", *_plot_lines(plots, out)]
    return "\n".join(lines).rstrip() + "\n"


def write_report(result: Any, out_dir: str | Path, plots: Sequence[Path]) -> Path:
    """Write ``report.md`` for ``result`` into ``out_dir`` (atomically); return its path.

    ``result`` may carry ``metadata`` (dict: config/cycle names, versions, timings),
    ``metrics`` (name -> {"value", "unit", "description"}), ``energy_audit`` (term -> [J],
    with "residual"), ``events`` (DataFrame: time_s, kind, from_state, to_state, reason) and
    ``timeseries``. ``plots`` are PNG paths, linked relative to ``out_dir``.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    target = out / REPORT_FILE
    tmp = target.with_name(target.name + ".tmp")
    try:
        tmp.write_text(render_report(result, out, plots), encoding="utf-8")
        os.replace(tmp, target)
    finally:
        tmp.unlink(missing_ok=True)
    return target


def build_report(result: Any, out_dir: str | Path) -> Path:
    """Write every applicable plot and ``report.md`` into ``out_dir``; return the report path."""
    return write_report(result, out_dir, plot_all(result, out_dir))


__all__ = [
    "MAX_EVENT_ROWS",
    "PLOT_CAPTIONS",
    "PLOT_FILES",
    "REPORT_FILE",
    "build_report",
    "format_number",
    "render_report",
    "write_report",
]
