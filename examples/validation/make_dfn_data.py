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

* ``python examples/validation/make_dfn_data.py ambients`` (issue 27): DFN data over ambients
  for an NMC/graphite cell (Chen2020) and an LFP/graphite cell (Prada2013): the pulse test at
  0, 25 and 45 degC (calibration) and one UDDS current at -10, 10, 35 and 45 degC (validation),
  ``dfn_<cell>_<pulse|udds>_<T>c.csv`` (``m10c`` = -10 degC), provenance in
  ``PROVENANCE_ambients.toml``.

The solver is asked only for what the files hold: the voltage and the temperature
(``output_variables``), at whole seconds interpolated from its own steps (``t_interp``; each
segment is one solver call from its start to its end). Stopping the solver at every second
instead (as the shipped ``dfn_pulse.csv`` / ``dfn_udds.csv`` were made) gives the same rows
within 0.002 mV and 1e-4 K at 20x the CPU (the first 20 segments of the pulse test: 28.6 s
against 1.4 s CPU).

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


OUTPUTS = ["Voltage [V]", "Volume-averaged cell temperature [K]"]
CELLS = {
    # name: (PyBaMM parameter set, capacity [A h], voltage cut-offs [V] wide enough for the pulses)
    "nmc": ("Chen2020", 5.0, (2.0, 4.6)),
    "lfp": ("Prada2013", 2.3, (2.0, 4.0)),  # with Chen2020's current collectors and thermal values
}
"""Cells of the ambient study (issue 27)."""


def _dfn(
    ambient_k: float = AMBIENT_K, pset: str = "Chen2020", cutoffs: tuple[float, float] = (2.0, 4.6)
) -> tuple[pybamm.BaseModel, pybamm.ParameterValues]:
    model = pybamm.lithium_ion.DFN(options={"thermal": "lumped"})
    pv = pybamm.ParameterValues(pset)
    if pset != "Chen2020":  # the lumped thermal model's values the set lacks: Chen2020's
        chen = pybamm.ParameterValues("Chen2020")
        pv.update({k: chen[k] for k in chen.keys() if k not in pv.keys()}, check_already_exists=False)
    pv["Current function [A]"] = "[input]"
    pv["Upper voltage cut-off [V]"] = cutoffs[1]  # pulses above the charge limit must not end the run
    pv["Lower voltage cut-off [V]"] = cutoffs[0]
    pv["Ambient temperature [K]"] = ambient_k
    pv["Initial temperature [K]"] = ambient_k
    return model, pv


def _at_seconds(sol: pybamm.Solution, name: str, dur: int) -> np.ndarray:
    """``name`` at the ends of the step's ``dur`` one-second intervals (the solution also holds
    the solver's internal points: interpolate on them, they are dense)."""
    t = sol["Time [s]"].entries
    y = sol[name].entries
    return np.interp(t[-1] - dur + np.arange(1, dur + 1), t, y)


def _step(sim: pybamm.Simulation, current: float, dur: int) -> pybamm.Solution:
    """One constant-current segment: the solver's own steps from start to end, the outputs
    interpolated at the whole seconds."""
    return sim.step(
        dt=float(dur),
        t_eval=[0.0, float(dur)],
        t_interp=np.arange(0.0, dur + 1.0),
        inputs={"Current function [A]": current},
        save=False,
    )


def run_segments(sim: pybamm.Simulation, segments: list[tuple[float, int]]) -> np.ndarray:
    """Rows (time [s], current [A], voltage [V], temperature [K]) at 1 s for segments
    ``(current [A], duration [s])``."""
    rows: list[tuple[float, float, float, float]] = []
    t0 = 0
    for current, dur in segments:
        sol = _step(sim, current, dur)
        v = _at_seconds(sol, "Voltage [V]", dur)
        temp = _at_seconds(sol, "Volume-averaged cell temperature [K]", dur)
        for k in range(dur):
            rows.append((t0 + k + 1, current, float(v[k]), float(temp[k])))
        t0 += dur
    return np.array(rows)


def _sim(initial_soc: float, ambient_k: float = AMBIENT_K, cell: str = "nmc") -> pybamm.Simulation:
    pset, _, cutoffs = CELLS[cell]
    model, pv = _dfn(ambient_k, pset, cutoffs)
    pv.set_initial_state(initial_soc)
    solver = pybamm.IDAKLUSolver(rtol=RTOL, atol=ATOL, output_variables=OUTPUTS)
    return pybamm.Simulation(model, parameter_values=pv, solver=solver)


def pulse_segments(rest_s: int = 900, capacity_ah: float = CAPACITY_AH) -> list[tuple[float, int]]:
    """HPPC-like test from SOC 0.95: at each level 10 s pulses (1C, 2C, 3C; discharge then
    charge, 40 s rests), a 1C discharge of 0.1 SOC (360 s) and a ``rest_s`` rest (900 s: the
    shipped test, 13080 s; 4665 s: the 12 h test of ``benchmarks/bench_calibrate.py``)."""
    c1 = capacity_ah
    seg: list[tuple[float, int]] = [(0.0, 600)]
    for _level in range(8):
        for rate in (1.0, 2.0, 3.0):
            seg += [(rate * c1, 10), (0.0, 40), (-rate * c1, 10), (0.0, 40)]
        seg += [(c1, 360), (0.0, rest_s)]
    return seg


def udds_current(repeats: int = 2, capacity_ah: float = CAPACITY_AH) -> np.ndarray:
    """Cell current [A] at 1 s from UDDS speed: a small car's road load, scaled to peak 3C
    discharge and 1.3C regen (regen only when braking)."""
    from hevsim.cycles import load_cycle

    cyc = load_cycle("udds")
    v = np.interp(np.arange(0.0, cyc.time_s[-1] + 1.0), cyc.time_s, cyc.speed_mps)
    a = np.gradient(v)
    mass, cda, crr, rho, g = 1500.0, 0.65, 0.009, 1.2, 9.81  # [kg], [m2], [-], [kg/m3], [m/s2]
    p = (mass * a + 0.5 * rho * cda * v**2 + mass * g * crr * (v > 0.1)) * v
    i = np.where(p > 0, p / p.max() * 3.0 * capacity_ah, p / -p.min() * 1.3 * capacity_ah)
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
    solver = pybamm.IDAKLUSolver(rtol=1e-10, atol=1e-12, output_variables=["Voltage [V]"])
    sim = pybamm.Simulation(model, parameter_values=pv, solver=solver)
    rows = []
    t0 = 0
    for current, dur in segments:
        sol = _step(sim, current, dur)
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


CAL_AMBIENTS_C = (0, 25, 45)
UDDS_REPEATS = 1  # one UDDS per validation ambient (every 1 s segment is one solver call)
VAL_AMBIENTS_C = (-10, 10, 35, 45)


def ambient_name(cell: str, kind: str, t_c: int) -> str:
    """File name of a test of the ambient study: ``dfn_<cell>_<kind>_<T>c.csv``."""
    return f"dfn_{cell}_{kind}_{'m' if t_c < 0 else ''}{abs(t_c)}c.csv"


def ambient_study(cells: tuple[str, ...] = tuple(CELLS), kinds: tuple[str, ...] = ("pulse", "udds")) -> None:
    """The DFN data over ambients (module docstring) of ``kinds`` and ``PROVENANCE_ambients.toml``
    (the hashes of every ambient-study file present, the CPU time of those made by this run)."""
    import time
    import tomllib

    prov = HERE / "PROVENANCE_ambients.toml"
    old = tomllib.loads(prov.read_text()) if prov.is_file() else {}
    cpu = dict(old.get("cpu_s", {}))
    for cell in cells:
        _, cap, _ = CELLS[cell]
        jobs = [("pulse", t, 0.95) for t in CAL_AMBIENTS_C] + [("udds", t, 0.8) for t in VAL_AMBIENTS_C]
        for kind, t_c, soc0 in (j for j in jobs if j[0] in kinds):
            c0 = time.process_time()
            sim = _sim(soc0, 273.15 + t_c, cell)
            seg = (
                pulse_segments(capacity_ah=cap)
                if kind == "pulse"
                else [(0.0, 60)] + [(float(x), 1) for x in udds_current(UDDS_REPEATS, cap)]
            )
            name = ambient_name(cell, kind, t_c)
            _write(HERE / name, run_segments(sim, seg))
            cpu[name] = time.process_time() - c0
            print(f"{name}: {cpu[name]:.1f} s CPU", flush=True)
    names = sorted(
        ambient_name(c, k, t)
        for c in CELLS
        for k, temps in (("pulse", CAL_AMBIENTS_C), ("udds", VAL_AMBIENTS_C))
        for t in temps
        if (HERE / ambient_name(c, k, t)).is_file()
    )
    hashes = {n: hashlib.sha256((HERE / n).read_bytes()).hexdigest() for n in names}
    lines = [
        "# Provenance of the DFN data over ambients (make_dfn_data.py ambients; issue 27)",
        'generator = "examples/validation/make_dfn_data.py ambients"',
        f'date = "{datetime.date.today().isoformat()}"',
        f'pybamm_version = "{pybamm.__version__}"',
        'pybamm_licence = "BSD-3-Clause (PyBaMM, https://github.com/pybamm-team/PyBaMM)"',
        "model = \"pybamm.lithium_ion.DFN(options={'thermal': 'lumped'})\"",
        f'solver = "IDAKLUSolver rtol={RTOL} atol={ATOL}, output_variables {OUTPUTS}, '
        'outputs at whole seconds by t_interp"',
        "cells = { "
        + ", ".join(f'{k} = "{v[0]}, {v[1]} A h, cut-offs {v[2]} V"' for k, v in CELLS.items())
        + " }",
        f"calibration_ambients_c = {list(CAL_AMBIENTS_C)}",
        f"validation_ambients_c = {list(VAL_AMBIENTS_C)}",
        'pulse = "pulse_segments(): HPPC from SOC 0.95, 1C/2C/3C pulses at 8 levels, 900 s rests"',
        f'udds = "udds_current({UDDS_REPEATS}): UDDS, peak 3C discharge, 1.3C regen, from SOC 0.8 '
        'after a 60 s rest"',
        "[cpu_s]",
        *(f'"{k}" = {v:.1f}' for k, v in cpu.items()),
        "[sha256]",
        *(f'"{k}" = "sha256:{v}"' for k, v in hashes.items()),
    ]
    prov.write_text("\n".join(lines) + "\n")


def main(parts: list[str]) -> None:
    """Generate ``parts`` (pulse, udds, thevenin; all by default) and the provenance file;
    ``hppc12`` writes the 12 h benchmark test ``dfn_hppc_12h.csv`` (not shipped) to the current
    directory."""
    if parts and parts[0] == "ambients":  # ambients [CELL ...] [pulse|udds ...]
        cells = tuple(p for p in parts[1:] if p in CELLS) or tuple(CELLS)
        kinds = tuple(p for p in parts[1:] if p in ("pulse", "udds")) or ("pulse", "udds")
        ambient_study(cells, kinds)
        return
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
