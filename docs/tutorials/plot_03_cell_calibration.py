"""
A cell calibrated from a pulse test and validated
=================================================

The electro-thermal cell model (an equivalent circuit with a temperature-dependent series
resistance and RC pairs, coupled to a lumped thermal mass with a skin resistance to the heat
port) has parameters a data sheet does not give: the heat capacity, the skin resistance, the
RC pair's resistance and time constant. They come from a pulse test. This tutorial fits them
to the shipped test file ``examples/calibration_pulse.csv`` with
:func:`hevsim.battery.calibrate.calibrate`, checks the fit, and validates the calibrated cell
on a different load: the ten-minute 5C discharge of ``examples/cell.toml``.

**Follows:** thesis section 4.1.1 (the cell model, eqs 33-41, Tables 4.1 and 4.2) and its
calibration scenario. The test file was made by ``examples/make_calibration_pulse.py`` from the
Table 4.1 cell with known parameters (C_heat 96 J/K, R_skin 10 K/W, R_1 5 mOhm, tau_1 20 s)
plus 2 mV and 0.05 K of seeded noise, so the true answer is known. Command-line equivalent:
``hevsim calibrate`` (:doc:`/battery`, "Calibration", also the full identification of a whole
parameter set without ``--fit``).
"""

# %%
# The pulse test
# --------------
# Three repetitions of 60 s at 8 A discharge, 60 s at 4 A charge and 180 s rest, at 23 degC.

import dataclasses

import matplotlib.pyplot as plt
import numpy as np

from hevsim.battery import Cell
from hevsim.battery.calibrate import CellTestRecord, calibrate
from hevsim.battery.config import load_config, profile_current

record = CellTestRecord.from_csv("examples/calibration_pulse.csv")
fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(7, 4.2), sharex=True, layout="constrained")
ax1.plot(record.time_s, record.current_a, color="k", lw=1)
ax1.set_ylabel("current [A]\n(discharge > 0)")
ax1.set_title("Pulse test of the Table 4.1 cell (examples/calibration_pulse.csv)")
ax2.plot(record.time_s, record.voltage_v, ".", ms=2, color="#2f6690")
ax2.set_ylabel("terminal voltage [V]")
ax2.set_xlabel("time [s]")
for a in (ax1, ax2):
    a.grid(alpha=0.3)

# %%
# **Figure 1.** The test: current steps (top) and the measured terminal voltage (bottom).
# What to see: the instantaneous voltage step at each current step (series resistance), the
# slower relaxation after it (the RC pair, tens of seconds) and the drift of the rest voltage
# as charge is removed (the OCV curve).
#
# The fit
# -------
# Four parameters, each with a start value deliberately far from the truth and bounds;
# the initial SOC and the ambient are known from the test protocol.

fit = {
    "c_heat_j_per_k": (60.0, 10.0, 500.0),
    "r_skin_k_per_w": (5.0, 0.5, 50.0),
    "rc_discharge[0].r_ohm": (0.01, 1e-4, 0.1),
    "rc_discharge[0].tau_s": (40.0, 1.0, 300.0),
}
truth = {"c_heat_j_per_k": 96.0, "r_skin_k_per_w": 10.0, "rc_discharge[0].r_ohm": 0.005,
         "rc_discharge[0].tau_s": 20.0}  # fmt: skip
result = calibrate("thesis_table_4_1", record, fit, soc_initial=0.9, port_temp_k=296.15)
print(f"{'parameter':<24}{'start':>10}{'fitted':>12}{'std. error':>12}{'true':>10}")
for name, (start, _, _) in fit.items():
    print(f"{name:<24}{start:>10.4g}{result.values[name]:>12.4g}{result.std_errors[name]:>12.2g}"
          f"{truth[name]:>10.4g}")  # fmt: skip
print(f"RMSE: voltage {1e3 * result.rmse['voltage_v']:.2f} mV, temperature {result.rmse['temp_k']:.3f} K")

ts = result.timeseries
fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(7, 4.6), sharex=True, layout="constrained")
ax1.plot(ts["time_s"], ts["voltage_measured_v"], ".", ms=2, color="0.6", label="measured")
ax1.plot(ts["time_s"], ts["voltage_fitted_v"], color="#d1495b", lw=1, label="calibrated model")
ax1.set_ylabel("terminal voltage [V]")
ax1.set_title("Calibrated cell against the pulse test")
ax1.legend(loc="lower left")
ax2.plot(ts["time_s"], 1e3 * (ts["voltage_fitted_v"] - ts["voltage_measured_v"]), color="#2f6690", lw=0.6)
ax2.set_ylabel("model - measured [mV]")
ax2.set_xlabel("time [s]")
for a in (ax1, ax2):
    a.grid(alpha=0.3)

# %%
# **Figure 2.** Top: measured voltage (grey dots) and the calibrated model (red). Bottom: the
# residual. What to see: the residual is the test's 2 mV noise with no structure left around
# the steps - the RC pair's amplitude and time constant are identified; the table above shows
# each fitted value within a few standard errors of the truth.
#
# Validation on another load
# --------------------------
# A calibration is only as good as its prediction on data it did not see. We run the
# calibrated cell and the reference cell (the Table 4.1 set the test was made from) through
# the constant 4 A (5C) discharge of ``examples/cell.toml``, ten minutes with the heat port at
# 23 degC - a larger current and a longer heating than any pulse of the test.

# ``result.params`` is the set the fit started from; the calibrated set is that set with the
# fitted values put in:
base = result.params
rc_discharge = base.rc_discharge.copy()  # (n_rc, 2): resistance [ohm], time constant [s]
rc_discharge[0] = (result.values["rc_discharge[0].r_ohm"], result.values["rc_discharge[0].tau_s"])
calibrated = base.replace(
    thermal=dataclasses.replace(
        base.thermal,
        c_heat_j_per_k=result.values["c_heat_j_per_k"],
        r_skin_k_per_w=result.values["r_skin_k_per_w"],
    ),
    rc_discharge=rc_discharge,
)

cfg = load_config("examples/cell.toml")
current = profile_current(cfg)
runs = {}
for label, params in (("reference (Table 4.1)", "thesis_table_4_1"), ("calibrated", calibrated)):
    cell = Cell(params, cfg.cell.soc_initial, cfg.cell.temp_k)
    runs[label] = cell.simulate(current, cfg.profile.dt_s, cfg.thermal.port_temp_k).timeseries
ref, cal = runs["reference (Table 4.1)"], runs["calibrated"]
dv_mv = 1e3 * (cal["voltage_v"] - ref["voltage_v"])
dt_k = cal["temp_k"] - ref["temp_k"]
print(
    f"validation (4 A, 600 s): voltage error RMS {np.sqrt(np.mean(dv_mv**2)):.2f} mV, "
    f"max {np.max(np.abs(dv_mv)):.2f} mV; temperature error max {np.max(np.abs(dt_k)):.3f} K"
)

fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(7, 4.6), sharex=True, layout="constrained")
for (label, frame), style in zip(runs.items(), ("-", "--"), strict=True):
    ax1.plot(frame["time_s"], frame["voltage_v"], style, label=label)
    ax2.plot(frame["time_s"], frame["temp_k"] - 273.15, style, label=label)
ax1.set_ylabel("terminal voltage [V]")
ax1.set_title("Validation: 5C discharge of examples/cell.toml")
ax1.legend(loc="lower left")
ax2.set_ylabel("cell temperature [°C]")
ax2.set_xlabel("time [s]")
for a in (ax1, ax2):
    a.grid(alpha=0.3)

# %%
# **Figure 3.** The reference cell (solid) and the calibrated one (dashed) on a load the
# calibration never saw: voltage (top) and temperature (bottom). What to see: the two curves
# lie on each other; the printed errors quantify it - the heat capacity and skin resistance
# fitted from a few-kelvin pulse test predict a ten-minute heating correctly.
