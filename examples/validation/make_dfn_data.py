"""Generate the DFN reference data of the battery validation study (docs/battery.md).

Run once (needs the optional extra: ``pip install hevsim[validation]``)::

    python examples/validation/make_dfn_data.py

Writes, next to this script:

* ``dfn_pulse.csv``  — a pulse / HPPC test of PyBaMM's Doyle-Fuller-Newman model (lumped
  thermal) with the Chen2020 parameter set (LG M50, 5 A h): rests, 1C/2C/3C charge and
  discharge pulses of 10 s at eight SOC levels, 1C discharges of 0.1 SOC between them;
* ``dfn_udds.csv``   — the same cell on a current derived from two UDDS cycles
  (peak 3C discharge, 1.3C regen) from SOC 0.8;
* ``thevenin_pulse.csv`` — PyBaMM's Thevenin ECM (one RC, isothermal, matched parameters in
  ``thevenin_parameters.toml``) on a pulse train with reversals at 1C and 5C;
* ``PROVENANCE.toml`` — PyBaMM version, parameter set, solver tolerances, licence.

Every file uses hevsim's test-record row convention (:mod:`hevsim.battery.calibrate`): row k
holds the current over ``(t_k - 1 s, t_k]`` (discharge positive) and the voltage and
temperature at ``t_k``. The current is piecewise constant (each segment is one
``Simulation.step`` with the current as an input), so nothing is lost to interpolation.
"""

from __future__ import annotations

import datetime
import hashlib
from pathlib import Path

import numpy as np
import pybamm

HERE = Path(__file__).resolve().parent
CAPACITY_AH = 5.0  # Chen2020 nominal capacity [A h]
AMBIENT_K = 298.15
RTOL, ATOL = 1e-8, 1e-10


def _dfn() -> pybamm.Simulation:
    model = pybamm.lithium_ion.DFN(options={"thermal": "lumped"})
    pv = pybamm.ParameterValues("Chen2020")
    pv["Current function [A]"] = "[input]"
    pv["Upper voltage cut-off [V]"] = 4.6  # pulses above 4.2 V must not end the run
    pv["Lower voltage cut-off [V]"] = 2.0
    pv["Ambient temperature [K]"] = AMBIENT_K
    pv["Initial temperature [K]"] = AMBIENT_K
    return model, pv


def _at_seconds(sol: pybamm.Solution, name: str, dur: int) -> np.ndarray:
    """``name`` at the ends of the step's ``dur`` one-second intervals (the solution also holds
    the solver's internal points: interpolate on them, they are dense)."""
    t = sol["Time [s]"].entries
    y = sol[name].entries
    return np.interp(t[-1] - dur + np.arange(1, dur + 1), t, y)


def run_segments(sim: pybamm.Simulation, segments: list[tuple[float, int]]) -> np.ndarray:
    """Rows (time [s], current [A], voltage [V], temperature [K]) at 1 s for segments
    ``(current [A], duration [s])``."""
    rows: list[tuple[float, float, float, float]] = []
    t0 = 0
    for current, dur in segments:
        sol = sim.step(dt=float(dur), npts=dur + 1, inputs={"Current function [A]": current}, save=False)
        v = _at_seconds(sol, "Voltage [V]", dur)
        temp = _at_seconds(sol, "Volume-averaged cell temperature [K]", dur)
        for k in range(dur):
            rows.append((t0 + k + 1, current, float(v[k]), float(temp[k])))
        t0 += dur
    return np.array(rows)


def _sim(initial_soc: float) -> pybamm.Simulation:
    model, pv = _dfn()
    pv.set_initial_state(initial_soc)
    solver = pybamm.IDAKLUSolver(rtol=RTOL, atol=ATOL)
    return pybamm.Simulation(model, parameter_values=pv, solver=solver)


def pulse_segments(rest_s: int = 900) -> list[tuple[float, int]]:
    """HPPC-like test from SOC 0.95: at each level 10 s pulses (1C, 2C, 3C; discharge then
    charge, 40 s rests), a 1C discharge of 0.1 SOC (360 s) and a ``rest_s`` rest (900 s: the
    shipped test, 13080 s; 4665 s: the 12 h test of ``benchmarks/bench_calibrate.py``)."""
    c1 = CAPACITY_AH
    seg: list[tuple[float, int]] = [(0.0, 600)]
    for _level in range(8):
        for rate in (1.0, 2.0, 3.0):
            seg += [(rate * c1, 10), (0.0, 40), (-rate * c1, 10), (0.0, 40)]
        seg += [(c1, 360), (0.0, rest_s)]
    return seg


def udds_current(repeats: int = 2) -> np.ndarray:
    """Cell current [A] at 1 s from UDDS speed: a small car's road load, scaled to peak 3C
    discharge and 1.3C regen (regen only when braking)."""
    from hevsim.cycles import load_cycle

    cyc = load_cycle("udds")
    v = np.interp(np.arange(0.0, cyc.time_s[-1] + 1.0), cyc.time_s, cyc.speed_mps)
    a = np.gradient(v)
    mass, cda, crr, rho, g = 1500.0, 0.65, 0.009, 1.2, 9.81  # [kg], [m2], [-], [kg/m3], [m/s2]
    p = (mass * a + 0.5 * rho * cda * v**2 + mass * g * crr * (v > 0.1)) * v
    i = np.where(p > 0, p / p.max() * 3.0 * CAPACITY_AH, p / -p.min() * 1.3 * CAPACITY_AH)
    return np.round(np.tile(i[1:], repeats), 3)


def thevenin_rows(segments: list[tuple[float, int]], prm: dict[str, float]) -> np.ndarray:
    """PyBaMM's Thevenin ECM (one RC element, isothermal) on ``segments``."""
    model = pybamm.equivalent_circuit.Thevenin()
    pv = pybamm.ParameterValues("ECM_Example")
    soc_ax = np.array(prm["soc"])
    ocv_ax = np.array(prm["ocv_v"])

    def ocv(sto):
        return pybamm.Interpolant(soc_ax, ocv_ax, sto, interpolator="linear", extrapolate=False)

    pv.update(
        {
            "Current function [A]": "[input]",
            "Initial SoC": prm["soc_initial"],
            "Cell capacity [A.h]": prm["capacity_ah"],
            "Nominal cell capacity [A.h]": prm["capacity_ah"],
            "Open-circuit voltage [V]": ocv,
            "R0 [Ohm]": prm["r0_ohm"],
            "R1 [Ohm]": prm["r1_ohm"],
            "C1 [F]": prm["tau1_s"] / prm["r1_ohm"],
            "Entropic change [V/K]": 0.0,
            "Upper voltage cut-off [V]": 5.0,
            "Lower voltage cut-off [V]": 2.0,
            # an (effectively) isothermal cell: a huge thermal mass
            "Cell thermal mass [J/K]": 1e12,
            "Jig thermal mass [J/K]": 1e12,
        },
        check_already_exists=False,
    )
    sim = pybamm.Simulation(model, parameter_values=pv, solver=pybamm.IDAKLUSolver(rtol=1e-10, atol=1e-12))
    rows = []
    t0 = 0
    for current, dur in segments:
        sol = sim.step(dt=float(dur), npts=dur + 1, inputs={"Current function [A]": current}, save=False)
        v = _at_seconds(sol, "Voltage [V]", dur)
        for k in range(dur):
            rows.append((t0 + k + 1, current, float(v[k]), AMBIENT_K))
        t0 += dur
    return np.array(rows)


THEVENIN = {
    "capacity_ah": 5.0,
    "soc_initial": 0.8,
    "r0_ohm": 0.02,
    "r1_ohm": 0.015,
    "tau1_s": 60.0,
    "soc": [0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0],
    "ocv_v": [3.0, 3.45, 3.55, 3.62, 3.67, 3.73, 3.82, 3.92, 4.0, 4.08, 4.18],
}


def thevenin_segments() -> list[tuple[float, int]]:
    """Pulse train with reversals at 1C and 5C (5 A h cell)."""
    seg: list[tuple[float, int]] = [(0.0, 10)]
    for rate in (1.0, 5.0):
        i = rate * THEVENIN["capacity_ah"]
        seg += [(i, 30), (-i, 20), (i, 10), (-i, 30), (0.0, 60), (-i, 15), (i, 25), (0.0, 120)]
    return seg


def _write(path: Path, rows: np.ndarray) -> str:
    lines = ["time_s,current_a,voltage_v,temp_k"]
    lines += [f"{int(t)},{i:.4f},{v:.6f},{tk:.4f}" for t, i, v, tk in rows]
    text = "\n".join(lines) + "\n"
    path.write_text(text)
    return hashlib.sha256(text.encode()).hexdigest()


def main(parts: list[str]) -> None:
    """Generate ``parts`` (pulse, udds, thevenin; all by default) and the provenance file;
    ``hppc12`` writes the 12 h benchmark test ``dfn_hppc_12h.csv`` (not shipped) to the current
    directory."""
    parts = parts or ["pulse", "udds", "thevenin"]
    if "pulse" in parts:
        _write(HERE / "dfn_pulse.csv", run_segments(_sim(0.95), pulse_segments()))
    if "udds" in parts:
        i = udds_current()
        _write(HERE / "dfn_udds.csv", run_segments(_sim(0.8), [(0.0, 60)] + [(float(x), 1) for x in i]))
    if "hppc12" in parts:  # benchmark input, not shipped: written to the current directory
        _write(Path("dfn_hppc_12h.csv"), run_segments(_sim(0.95), pulse_segments(rest_s=4665)))
        parts = [p for p in parts if p != "hppc12"]
        if not parts:
            return
    if "thevenin" in parts:
        _write(HERE / "thevenin_pulse.csv", thevenin_rows(thevenin_segments(), THEVENIN))
    names = ("dfn_pulse.csv", "dfn_udds.csv", "thevenin_pulse.csv")
    hashes = {n: hashlib.sha256((HERE / n).read_bytes()).hexdigest() for n in names if (HERE / n).is_file()}
    prm_lines = [f"{k} = {v!r}" for k, v in THEVENIN.items()]
    (HERE / "thevenin_parameters.toml").write_text(
        "# Parameters of PyBaMM's Thevenin ECM run in thevenin_pulse.csv (make_dfn_data.py)\n"
        + "\n".join(prm_lines)
        + "\n"
    )
    files = "\n".join(f'"{k}" = "sha256:{v}"' for k, v in hashes.items())
    model = (
        "pybamm.lithium_ion.DFN(options={'thermal': 'lumped'}); "
        "Thevenin: pybamm.equivalent_circuit.Thevenin()"
    )
    pset = (
        "Chen2020 (Chen et al., J. Electrochem. Soc. 167 (2020) 080534; LG M50, 5 A h), voltage "
        "cut-offs widened to 2.0-4.6 V; ECM_Example with the values of thevenin_parameters.toml"
    )
    rows_doc = (
        "row k: current over (t_k - 1 s, t_k] (discharge > 0), voltage and volume-averaged temperature at t_k"
    )
    (HERE / "PROVENANCE.toml").write_text(
        "# Provenance of the DFN / ECM reference data (generated by make_dfn_data.py)\n"
        'generator = "examples/validation/make_dfn_data.py"\n'
        f'date = "{datetime.date.today().isoformat()}"\n'
        f'pybamm_version = "{pybamm.__version__}"\n'
        'pybamm_licence = "BSD-3-Clause (PyBaMM, https://github.com/pybamm-team/PyBaMM)"\n'
        f'model = "{model}"\n'
        f'parameter_set = "{pset}"\n'
        f'solver = "IDAKLUSolver rtol={RTOL} atol={ATOL} (Thevenin: rtol=1e-10 atol=1e-12)"\n'
        f"ambient_k = {AMBIENT_K}\n"
        f'row_convention = "{rows_doc}"\n'
        f"[sha256]\n{files}\n"
    )


if __name__ == "__main__":
    import sys

    main(sys.argv[1:])
