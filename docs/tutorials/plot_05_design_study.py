"""
A design study on Dask and its Pareto front
===========================================

Sizing is a trade: a stronger traction motor or a shorter final drive follows an aggressive
drive cycle better and usually costs fuel. A design study runs many variants of one vehicle and
keeps the non-dominated ones - the Pareto front - so the trade is a curve to choose from, not a
guess. Here we vary the series HEV's motor torque and final-drive ratio and simulate each
variant on the aggressive US06 cycle, on a local Dask cluster of two workers (the same study
runs on any Dask cluster: :doc:`/howto/cluster_study`).

**Follows:** thesis chapter 2's series HEV, its MPGGE (eqs 14-20) as the economy objective and
its driver's speed tracking (eqs 1-5) as the other;
the study machinery (samplers, Dask execution, Pareto fronts, sensitivities) is hevsim's
(:doc:`/studies`). Command-line equivalent: ``hevsim study STUDY.toml`` then ``hevsim
study-report DIR``. Kept small for the build: 3 x 3 = 9 vehicles.
"""

# %%
# The study
# ---------
# The same fields as a study TOML file, as a Python mapping: the vehicle, the cycles, the
# metrics to keep, the parameters and their values, the solvers, and the Pareto front to find.

import tempfile
from pathlib import Path

import matplotlib.pyplot as plt

from hevsim.studies import run_study
from hevsim.studies.report import fronts
from hevsim.studies.spec import study_from_dict

spec = {
    "name": "motor_and_final_drive",
    "vehicle": "examples/series_hev.toml",
    "cycles": ["us06"],
    "metrics": ["mpgge", "soc_final", "speed_error_rms_mph"],
    "parameters": {"motor.torque_scale": [0.6, 0.8, 1.0], "final_drive.ratio": [3.0, 4.0, 5.0]},
    "solvers": [{"name": "simulate"}],
    "pareto": [{"name": "economy_vs_tracking", "maximize": ["mpgge"], "minimize": ["speed_error_rms_mph"]}],
}
study = study_from_dict(spec)

# %%
# Run it on Dask
# --------------
# ``scheduler=None`` starts a local Dask cluster (``workers=2``: one per core); rows stream to
# Parquet in the results folder as the cases finish. (Dask starts its workers as new Python
# processes that import the main script: run this page as a notebook - download it below - or,
# as a script, put the study's code under ``if __name__ == "__main__":``.)

out = Path(tempfile.mkdtemp()) / "study"
rows = run_study(study, out, workers=2, progress=False)
assert (rows["status"] == "ok").all(), rows.loc[rows["status"] != "ok", "error"].tolist()
table = rows.set_index(["motor.torque_scale", "final_drive.ratio"])
table = table[["mpgge", "speed_error_rms_mph", "soc_final"]]
print(table.round(3).to_string())

# %%
# The Pareto front
# ----------------
# :func:`hevsim.studies.report.fronts` keeps the vehicles no other beats on both economy and
# speed tracking (the RMS difference between the cycle's speed and the car's).

info = {
    "parameters": [{"key": k} for k in spec["parameters"]],
    "solvers": [{"name": "simulate", "label": "simulate"}],
    "pareto": spec["pareto"],
}
front = fronts(info, rows)["economy_vs_tracking"]
print(front[["motor.torque_scale", "final_drive.ratio", "mpgge", "speed_error_rms_mph"]].round(3).to_string())

fig, ax = plt.subplots(figsize=(7, 4.2), layout="constrained")
sc = ax.scatter(
    table["speed_error_rms_mph"],
    table["mpgge"],
    c=[k[0] for k in table.index],
    s=[40 * k[1] - 90 for k in table.index],
    cmap="viridis",
    edgecolor="k",
    zorder=3,
)
f = front.sort_values("speed_error_rms_mph")
ax.plot(f["speed_error_rms_mph"], f["mpgge"], "-", color="#d1495b", lw=2, zorder=2, label="Pareto front")
fig.colorbar(sc, ax=ax, label="motor torque scale [-]")
for (_torque, ratio), r in table.iterrows():
    xy = (r["speed_error_rms_mph"], r["mpgge"])
    ax.annotate(f"{ratio:g}", xy, textcoords="offset points", xytext=(6, 4), fontsize=7)
ax.set_xlabel("RMS speed error on US06 [mph]")
ax.set_ylabel("MPGGE on US06 [mi/gal]")
ax.set_title("Series HEV sizing on US06: economy vs speed tracking (9 vehicles)")
ax.legend(loc="upper right")
ax.grid(alpha=0.3)

# %%
# **Figure 1.** Each dot is one vehicle: colour the motor torque scale, size and label the
# final-drive ratio. The red line joins the Pareto-optimal vehicles. What to see: following
# US06 more closely (to the left) costs economy, down the front - the small motor saves fuel
# by not delivering the cycle's accelerations; the vehicles off the front are beaten on both
# counts by one on it, so they need no further thought. ``hevsim study-report`` writes the
# same front, a sensitivity ranking and scatter matrices for a study of any size.

print(f"{len(front)} of {len(table)} vehicles on the front")
vehicles = {
    f"{t:g}/{fd:g}": (round(float(r["mpgge"]), 4), round(float(r["speed_error_rms_mph"]), 4))
    for (t, fd), r in table.iterrows()
}
on_front = sorted(
    f"{t:g}/{fd:g}" for t, fd in zip(front["motor.torque_scale"], front["final_drive.ratio"], strict=True)
)
print("vehicles (torque scale/final drive: MPGGE, RMS speed error mph):", vehicles)
print("on the front:", on_front)
