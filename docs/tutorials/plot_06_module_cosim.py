"""
The battery module as a co-simulation: cells, finite elements and coolant
==========================================================================

The thesis's chapter 4 couples three tools at communication points: an electro-thermal cell
model exported as an FMU (Dymola), the module's 3-D heat conduction (Abaqus/Standard) and the
coolant in the cooling plate (Abaqus/CFD). hevsim does the same with open parts: twelve
electro-thermal cells (2 in series, 6 in parallel: eqs 33-41, Table 4.1), a finite-element
model of the module with its cooling plate (section 4.1.2, Table 4.3 materials), a 1-D coolant
channel (section 4.1.3) and a power cycle, exchanged every second by a Gauss-Seidel master
(section 4.1.4).

**Follows:** thesis sections 4.1.1-4.1.4 and 4.3. The full 300 s case, with the cells as a
native FMU in a worker process as the thesis exchanged them, is
``python examples/cosim_module/run_module.py`` or
``hevsim cosim examples/cosim_module/module.ssd``; the master, the FMU participants and the
validation against FMPy are in :doc:`/cosim`, the finite-element model in :doc:`/thermal`.
"""

# %%
# The coupled system
# ------------------
# ``module_system`` builds the system as an SSP description: which participant gives which
# variable to which. Each cell's heat goes to its own finite-element cell; that cell's mean
# temperature comes back to the cell's heat port. The plate's wall temperature per channel
# segment goes to the coolant, which returns the heat flux and film coefficient. Here the
# twelve cells run in process (``battery="inprocess"``: the same equations as the FMU, no C
# compiler needed) for 120 s of a 250 W discharge / 150 W charge square cycle, the module
# starting at 30 degC with 15 degC coolant.

import importlib.util

import matplotlib.pyplot as plt
import numpy as np

from hevsim.cosim.system import run_cosim

spec = importlib.util.spec_from_file_location("run_module", "examples/cosim_module/run_module.py")
run_module = importlib.util.module_from_spec(spec)
spec.loader.exec_module(run_module)

system = run_module.module_system(duration_s=120.0, battery="inprocess")
print(f"{len(system.components)} participants, {len(system.connections)} connections")
res = run_cosim(system, "results/tutorial_module_cosim")
print(f"{res.stats['steps']} communication steps in {res.stats['wall_s']:.1f} s")

# %%
# Temperatures: the cells' own view and the module's
# ---------------------------------------------------
# Each cell's lumped temperature (eq 41, the electro-thermal model) runs about 1 K above the
# mean of its finite-element cell: the cell model sees its core, the finite elements see the
# heat leave through the holder. The aluminium plate drops to the coolant's 15 degC within
# 20 s, first pouring the heat it stored into the coolant; the cells, behind the poorly
# conducting holder (0.2 W/(m K), Table 4.3), barely follow: their finite-element means fall
# by 0.6 K in two minutes while their cores warm with the cycle's heat (eq 40, R_s I^2).

t = res.time_s
fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4))
for c in (0, 11):
    ax1.plot(t, res[f"battery.cell{c}_temp_k"] - 273.15, label=f"cell {c}: electro-thermal (eq 41)")
    ax1.plot(t, res[f"fem.cell{c}_temp_k"] - 273.15, "--", label=f"cell {c}: finite-element mean")
ax1.plot(t, res["fem.plate_max_temp_k"] - 273.15, "k:", label="cooling plate, hottest point")
ax1.set(xlabel="time [s]", ylabel="temperature [°C]", title="Cell and plate temperatures")
ax1.legend(fontsize=8)
ax2.plot(t, res["battery.port_heat_w"], label="heat from the cells (eq 40)")
ax2.plot(t, res["coolant.cooling_power_w"], label="heat into the coolant")
ax2.set(xlabel="time [s]", ylabel="power [W]", title="Heat generated and removed", yscale="log")
ax2.legend(fontsize=8)
fig.suptitle("Module co-simulation, 250 W / 150 W square cycle, coolant at 15 °C")
fig.tight_layout()

# %%
# The temperature field
# ---------------------
# The run writes the finite-element field (``fields/*.vtu`` for ParaView) and its pictures.
# The sections through the two rows of cells show what a lumped model cannot: the cells are
# nearly uniform, the gradient is in the holder between cells and plate; the star marks each
# row's hottest point with its temperature.

img = plt.imread("results/tutorial_module_cosim/pictures/fem_cells_section.png")
fig, ax = plt.subplots(figsize=(11, 5))
ax.imshow(img)
ax.set_axis_off()
_ = ax.set_title("Temperature in vertical sections through the cell rows at the end of the run")

# %%
# The books close
# ---------------
# Energy crosses each interface once: the heat the cells give to the finite elements, minus
# what the plate gives to the coolant (and the small film loss to the air), equals the change
# of the heat stored in the module. A coupling error (a flux applied at the wrong time or
# twice) would show here.

dt = np.diff(t)
heat_in_j = float(np.sum(res["battery.port_heat_w"][1:] * dt))
heat_out_j = float(np.sum(res["fem.wall_heat_w"][1:] * dt))
stored_j = float(res["fem.stored_energy_j"][-1] - res["fem.stored_energy_j"][0])
gap_j = heat_in_j - heat_out_j - stored_j
print(f"cells -> module {heat_in_j:8.1f} J, plate -> coolant {heat_out_j:8.1f} J, stored {stored_j:8.1f} J")
share = 100 * gap_j / heat_out_j
print(f"unaccounted (film to the air, exchange error): {gap_j:.2f} J = {share:.3f} % of the cooling")
assert abs(gap_j) < 1e-3 * heat_out_j
