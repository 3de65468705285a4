"""Generate multi-temperature pulse tests with a known activation energy (docs/battery.md,
"Resistance over temperature").

Run once (needs the optional extra: ``pip install hevsim[validation]``)::

    python examples/validation/make_arrhenius_data.py

Writes, next to this script, ``arrhenius_<T>c.csv`` for the ambients of :data:`AMBIENTS_C`:
PyBaMM's Thevenin ECM (``pybamm.equivalent_circuit.Thevenin``, one RC element, with its lumped
cell thermal model against a jig held at the ambient) whose resistances follow

    R0(SOC, T) = R0_ref (1 + 0.5 (SOC - 0.5)^2) exp(Ea / R_gas (1/T - 1/T_ref))
    R1(T)      = R1_ref exp(Ea / R_gas (1/T - 1/T_ref)),   tau1 = R1 C1 constant

with ``T`` the cell temperature (:data:`PARAMETERS`; ``Ea`` = 30 kJ/mol). Each test: 600 s
rest, then at three SOC levels from 0.9: 10 s pulses at 1C, 2C, 3C, discharge then charge,
40 s rests, a 1C discharge of 0.1 SOC (360 s) and a 400 s rest. Also writes
``arrhenius_parameters.toml`` (the values) and ``PROVENANCE_arrhenius.toml`` (PyBaMM version,
solver, hashes). Rows follow hevsim's test-record convention (row k: current over
``(t_k - 1 s, t_k]``, discharge positive; voltage and cell temperature at ``t_k``).
"""

from __future__ import annotations

import datetime
import hashlib
from pathlib import Path

import numpy as np
import pybamm

HERE = Path(__file__).resolve().parent
R_GAS = 8.314462618  # [J/(mol K)]
AMBIENTS_C = (10.0, 25.0, 40.0)
PARAMETERS = {
    "capacity_ah": 5.0,
    "soc_initial": 0.9,
    "ea_j_per_mol": 30000.0,
    "t_ref_k": 298.15,
    "r0_ref_ohm": 0.02,
    "r1_ref_ohm": 0.015,
    "tau1_s": 60.0,
    "cell_thermal_mass_j_per_k": 300.0,
    "cell_jig_w_per_k": 1.0,
    "soc": [0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0],
    "ocv_v": [3.0, 3.45, 3.55, 3.62, 3.67, 3.73, 3.82, 3.92, 4.0, 4.08, 4.18],
}


def segments() -> list[tuple[float, int]]:
    """(current [A], duration [s]) of one test."""
    c1 = float(PARAMETERS["capacity_ah"])  # type: ignore[arg-type]
    seg: list[tuple[float, int]] = [(0.0, 600)]
    for _level in range(3):
        for rate in (1.0, 2.0, 3.0):
            seg += [(rate * c1, 10), (0.0, 40), (-rate * c1, 10), (0.0, 40)]
        seg += [(c1, 360), (0.0, 400)]
    return seg


def _arrhenius(t_cell_c):
    prm = PARAMETERS
    return pybamm.exp(prm["ea_j_per_mol"] / R_GAS * (1.0 / (t_cell_c + 273.15) - 1.0 / prm["t_ref_k"]))


def run(ambient_c: float) -> np.ndarray:
    """Rows (time [s], current [A], voltage [V], cell temperature [K]) of one test."""
    prm = PARAMETERS
    soc_ax = np.array(prm["soc"])
    ocv_ax = np.array(prm["ocv_v"])

    def ocv(sto):
        return pybamm.Interpolant(soc_ax, ocv_ax, sto, interpolator="linear", extrapolate=False)

    def r0(t_cell_c, current, soc):
        return prm["r0_ref_ohm"] * (1.0 + 0.5 * (soc - 0.5) ** 2) * _arrhenius(t_cell_c)

    def r1(t_cell_c, current, soc):
        return prm["r1_ref_ohm"] * _arrhenius(t_cell_c)

    def c1(t_cell_c, current, soc):
        return prm["tau1_s"] / r1(t_cell_c, current, soc)

    pv = pybamm.ParameterValues("ECM_Example")
    t_amb = ambient_c + 273.15
    pv.update(
        {
            "Current function [A]": "[input]",
            "Initial SoC": prm["soc_initial"],
            "Cell capacity [A.h]": prm["capacity_ah"],
            "Nominal cell capacity [A.h]": prm["capacity_ah"],
            "Open-circuit voltage [V]": ocv,
            "R0 [Ohm]": r0,
            "R1 [Ohm]": r1,
            "C1 [F]": c1,
            "Entropic change [V/K]": 0.0,
            "Upper voltage cut-off [V]": 5.0,
            "Lower voltage cut-off [V]": 2.0,
            "Initial temperature [K]": t_amb,
            "Ambient temperature [K]": t_amb,
            "Cell thermal mass [J/K]": prm["cell_thermal_mass_j_per_k"],
            "Cell-jig heat transfer coefficient [W/K]": prm["cell_jig_w_per_k"],
            "Jig thermal mass [J/K]": 1e12,  # the jig stays at the ambient
        },
        check_already_exists=False,
    )
    model = pybamm.equivalent_circuit.Thevenin()
    sim = pybamm.Simulation(model, parameter_values=pv, solver=pybamm.IDAKLUSolver(rtol=1e-10, atol=1e-12))
    rows = []
    t0 = 0
    for current, dur in segments():
        sol = sim.step(dt=float(dur), npts=dur + 1, inputs={"Current function [A]": current}, save=False)
        t = sol["Time [s]"].entries
        grid = t[-1] - dur + np.arange(1, dur + 1)
        v = np.interp(grid, t, sol["Voltage [V]"].entries)
        temp = np.interp(grid, t, sol["Cell temperature [degC]"].entries) + 273.15
        rows += [(t0 + k + 1, current, float(v[k]), float(temp[k])) for k in range(dur)]
        t0 += dur
    return np.array(rows)


def main() -> None:
    hashes = {}
    for amb in AMBIENTS_C:
        name = f"arrhenius_{amb:g}c.csv"
        lines = ["time_s,current_a,voltage_v,temp_k"]
        lines += [f"{int(t)},{i:.4f},{v:.6f},{tk:.4f}" for t, i, v, tk in run(amb)]
        text = "\n".join(lines) + "\n"
        (HERE / name).write_text(text)
        hashes[name] = hashlib.sha256(text.encode()).hexdigest()
    (HERE / "arrhenius_parameters.toml").write_text(
        "# Parameters of PyBaMM's Thevenin ECM run in arrhenius_*.csv (make_arrhenius_data.py)\n"
        + "\n".join(f"{k} = {v!r}" for k, v in PARAMETERS.items())
        + f"\nambients_c = {list(AMBIENTS_C)!r}\n"
    )
    files = "\n".join(f'"{k}" = "sha256:{v}"' for k, v in hashes.items())
    (HERE / "PROVENANCE_arrhenius.toml").write_text(
        "# Provenance of the multi-temperature pulse tests (generated by make_arrhenius_data.py)\n"
        'generator = "examples/validation/make_arrhenius_data.py"\n'
        f'date = "{datetime.date.today().isoformat()}"\n'
        f'pybamm_version = "{pybamm.__version__}"\n'
        'pybamm_licence = "BSD-3-Clause (PyBaMM, https://github.com/pybamm-team/PyBaMM)"\n'
        'model = "pybamm.equivalent_circuit.Thevenin() (one RC element, lumped cell-jig thermal)"\n'
        'parameter_set = "ECM_Example with the values of arrhenius_parameters.toml (Arrhenius R0, R1)"\n'
        'solver = "IDAKLUSolver rtol=1e-10 atol=1e-12"\n'
        'row_convention = "row k: current over (t_k - 1 s, t_k] (discharge > 0), '
        'voltage and cell temperature at t_k"\n'
        f"[sha256]\n{files}\n"
    )


if __name__ == "__main__":
    main()
