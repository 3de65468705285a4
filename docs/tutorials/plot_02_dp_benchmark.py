"""
Architectures benchmarked by dynamic programming, ECMS tuned from it
====================================================================

A controller comparison says as much about the controllers as about the vehicles. Dynamic
programming (DP) removes the controller from the comparison: over a known cycle it finds the
globally optimal energy management of each architecture, under the same charge-sustaining and
component constraints, so the architectures compete on equal terms. The DP's costate then
tells a real-time controller, the equivalent consumption minimisation strategy (ECMS), what a
unit of battery charge is worth in fuel.

**Follows:** thesis chapter 3 (DP for HEV energy management: Bellman's recursion over a state
grid of SOC, the charge-sustaining final constraint, and the appendix's parallel HEV with its
5-speed gearbox), and the ECMS equivalence factor read from the DP's costate
(:doc:`/dp` explains the method and its accuracy). Command-line equivalents: ``hevsim compare``,
``hevsim optimize`` and ``hevsim simulate --ecms-from``.

To keep the build quick, the grids are coarse (41 SOC x 41 input points, against the
appendix's 400 x 400): fuel economy changes by about a percent, the ranking does not.
"""

# %%
# Three architectures, one cycle, the optimal controller for each
# ---------------------------------------------------------------
# :func:`hevsim.optimal.compare.compare` runs :func:`hevsim.optimal.optimize` for every
# configuration on the UDDS city cycle and tabulates the optimum. ``final_soc="sustain"``
# makes every run end with at least its initial charge, so fuel is comparable directly.

import matplotlib.pyplot as plt
import numpy as np

from hevsim.control.parallel import ecms_from_dp
from hevsim.optimal import optimize
from hevsim.optimal.compare import compare
from hevsim.sim.forward import simulate_parallel

GRID = {"soc_grid_points": 41, "input_grid_points": 41}
configs = [
    "examples/series_hev.toml",
    "examples/parallel_hev.toml",
    "examples/prius_like_power_split.toml",
]
table = compare(configs, ["udds"], progress=False, final_soc="sustain", **GRID)
print(table[["configuration", "architecture", "mpg", "mpgge", "soc_initial", "soc_final"]].to_string())

fig, ax = plt.subplots(figsize=(7, 3.2), layout="constrained")
bars = ax.barh(table["configuration"], table["mpgge"], color=["#2f6690", "#3a7ca5", "#81c3d7"])
ax.bar_label(bars, fmt="%.1f", padding=3)
ax.set_xlabel("MPGGE at the DP optimum [mi per gallon of gasoline equivalent]")
ax.set_title("Best achievable fuel economy on UDDS, charge-sustaining (DP)")
ax.set_xlim(0, 1.15 * float(table["mpgge"].max()))
ax.grid(axis="x", alpha=0.3)

# %%
# **Figure 1.** The fuel economy each architecture reaches with its optimal energy
# management on UDDS, ending at its initial SOC (to the SOC grid's resolution), in miles per
# gallon of gasoline equivalent (eqs 14-20) since the vehicles burn different fuels (the
# series and parallel HEVs diesel, the power split gasoline). What to see: this is a property of
# the vehicle, not of a controller - no controller of that vehicle can beat its bar on this
# cycle. The power split's two machines let its engine run near its best efficiency most of
# the time.
#
# The optimum of the parallel HEV
# -------------------------------
# The appendix's parallel HEV in detail: the DP result carries the optimal SOC trajectory, the
# gear and power split, and the costate (the marginal fuel cost of SOC) along the path.

dp = optimize("examples/parallel_hev.toml", "udds", final_soc="sustain", **GRID)
ts = dp.timeseries
fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(7, 4.6), sharex=True, layout="constrained")
ax1.plot(ts["time_s"], ts["soc"], color="#2f6690")
ax1.set_ylabel("battery SOC [-]")
ax1.set_title("Parallel HEV on UDDS: DP-optimal SOC and equivalence factor")
s_path = dp.costate["equivalence_factor"]
ax2.plot(dp.costate["time_s"], s_path, color="#d1495b", lw=0.8)
s_dp = float(dp.metrics["equivalence_factor_median"]["value"])
ax2.axhline(s_dp, color="k", ls="--", lw=1, label=f"median s = {s_dp:.2f}")
ax2.set_ylim(0.0, 2.0 * s_dp)
ax2.set_xlabel("time [s]")
ax2.set_ylabel("equivalence factor s [-]")
ax2.legend(loc="upper right")
for a in (ax1, ax2):
    a.grid(alpha=0.3)

# %%
# **Figure 2.** Top: the optimal SOC trajectory; it uses the battery as a buffer and returns
# to its initial charge at the end. Bottom: the equivalence factor along the optimal path,
# ``s = -costate x LHV / (Q x OCV)``. What to see: s is nearly constant - the DP prices
# battery charge almost uniformly over the cycle, which is exactly ECMS's assumption; its
# median (dashed) is the factor ECMS takes with ``--ecms-from``.
#
# ECMS tuned from the DP
# ----------------------
# ECMS chooses, at each step, the gear and throttle of least fuel power plus s times the
# battery's chemical power. We sweep s and mark the DP's value: too low and ECMS spends the
# battery (ending below its initial SOC), too high and it burns fuel to charge it.

s_from_dp = ecms_from_dp(dp)["equivalence_factor"]
soc0 = float(ts["soc"].iloc[0])  # start ECMS where the DP started
sweep = np.round(np.linspace(0.6, 1.4, 9) * s_from_dp, 3)
fuel_l100, soc_end = [], []
for s in sweep:
    run = simulate_parallel(
        "examples/parallel_hev.toml", "udds", controller="ecms", soc_initial=soc0, equivalence_factor=s
    )
    fuel_l100.append(run.value("l_per_100km"))
    soc_end.append(run.value("soc_final"))
tuned = simulate_parallel(
    "examples/parallel_hev.toml", "udds", controller="ecms", soc_initial=soc0, equivalence_factor=s_from_dp
)
print(
    f"DP: {dp.metrics['mpg']['value']:.1f} mpg (the bound); ECMS with s = {s_from_dp:.3f} from the DP: "
    f"{tuned.value('mpg'):.1f} mpg, final SOC {tuned.value('soc_final'):.3f} "
    f"(initial {soc0:.3f})"
)

fig, ax1 = plt.subplots(figsize=(7, 3.6), layout="constrained")
ax1.plot(sweep, fuel_l100, "o-", color="#d1495b", label="ECMS fuel")
ax1.axvline(s_from_dp, color="k", ls="--", lw=1, label="s from the DP")
ax1.set_xlabel("ECMS equivalence factor s [-]")
ax1.set_ylabel("fuel consumption [L/100 km]", color="#d1495b")
ax2 = ax1.twinx()
ax2.plot(sweep, soc_end, "s-", color="#2f6690", label="final SOC")
ax2.axhline(soc0, color="#2f6690", ls=":", lw=1)
ax2.set_ylabel("final SOC [-] (dotted: initial)", color="#2f6690")
ax1.set_title("ECMS on the parallel HEV: fuel and charge balance vs s")
ax1.legend(loc="upper left")
ax1.grid(alpha=0.3)

# %%
# **Figure 3.** ECMS fuel (red) and final SOC (blue) for a range of equivalence factors
# around the DP's (dashed). What to see: fuel rises with s while the final SOC goes from
# depleted to overcharged; the DP's value lands near the charge-sustaining crossing (dotted
# line), so ECMS tuned from one DP run needs no trial and error on this cycle.
