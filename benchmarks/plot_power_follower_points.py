"""The 2016 Prius example's engine operating points on UDDS over its efficiency map: the power
follower now (on the optimal operating line, 15 kW floor) and with the example's settings before
issue 25 (EV below 12.5 m/s, no floor; the selection rule is today's in both).

Run from the repository root::

    .venv/bin/python benchmarks/plot_power_follower_points.py [--out docs/power_follower_operating_points.png]

Prints the fuel-weighted engine efficiency and the share of engine-on time below 10 kW of both,
and writes the figure (used by docs/simulate.md).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OLD_SETTINGS = {"controller.ev_speed_mps": 12.5, "controller.engine_min_power_w": 0.0}


def main() -> int:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from hevsim.architectures import architecture
    from hevsim.config import load_vehicle_config, with_overrides
    from hevsim.io import save_png
    from hevsim.sim.forward import simulate_architecture
    from hevsim.units import RADPS_PER_RPM

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default=str(ROOT / "docs" / "power_follower_operating_points.png"))
    a = ap.parse_args()
    cfg = load_vehicle_config(ROOT / "examples" / "prius_2016_like_power_split.toml")
    engine = architecture("power_split").build(cfg).engine
    w = np.linspace(engine.stall_speed_radps, engine.redline_radps, 121)
    t_max = np.asarray(engine.max_torque_nm(w))
    frac = np.linspace(0.02, 1.0, 100)
    ww, tt = np.meshgrid(w, frac)
    tt = tt * t_max[None, :]
    eff = ww * tt / (np.asarray(engine.fuel_rate(tt, ww)) * engine.fuel_lhv_jpkg)
    fig, ax = plt.subplots(figsize=(7.5, 4.8))
    cs = ax.contour(ww / RADPS_PER_RPM, tt, eff, levels=[0.2, 0.25, 0.3, 0.33, 0.35, 0.37, 0.38, 0.39],
                    colors="0.6", linewidths=0.8)  # fmt: skip
    ax.clabel(cs, fmt=lambda v: f"{100 * v:.0f} %", fontsize=7)
    ax.plot(w / RADPS_PER_RPM, t_max, "k-", lw=1.2, label="max torque")
    for label, c, marker, color in (
        ("old settings (EV < 12.5 m/s, no floor)", with_overrides(cfg, OLD_SETTINGS), "x", "C3"),
        ("now (optimal operating line, 15 kW floor)", cfg, "o", "C0"),
    ):  # fmt: skip
        ts = simulate_architecture("power_split", c, "udds").timeseries
        on = ts["engine_on"].to_numpy().astype(bool)
        rpm, torque = ts["engine_speed_rpm"].to_numpy()[on], ts["engine_torque_nm"].to_numpy()[on]
        p = ts["engine_power_w"].to_numpy()[on]
        e = p.sum() / (ts["fuel_rate_gps"].to_numpy()[on].sum() * 1e-3 * engine.fuel_lhv_jpkg)
        print(f"{label}: engine on {on.sum()} s, fuel-weighted efficiency {100 * e:.1f} %, "
              f"below 10 kW {100 * np.mean(p < 10e3):.0f} % of engine-on time")  # fmt: skip
        jitter = np.random.default_rng(0).normal(0.0, 12.0, rpm.size)  # points share grid speeds
        ax.scatter(rpm + jitter, torque, s=9, marker=marker, color=color, alpha=0.5,
                   label=f"{label}: {100 * e:.1f} %")  # fmt: skip
    ax.set_xlabel("engine speed [rpm]")
    ax.set_ylabel("engine torque [N·m]")
    ax.set_title(
        "prius_2016_like_power_split on UDDS: engine operating points on its efficiency map", fontsize=9
    )
    ax.legend(fontsize=7, loc="lower right")
    save_png(fig, a.out, dpi=110)
    plt.close(fig)
    print(f"written {a.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
