"""Co-simulation benchmark (issue 13 item 11; issue 6 item 8): hevsim against FMPy, per-step
overhead and scaling with the run length.

A Van der Pol oscillator FMU (pythonfmu, RK4 with 4 sub-steps per communication step) is run
for N steps of 0.01 s by

* ``fmpy.simulate_fmu`` (the baseline, same process),
* ``hevsim.cosim.system.run_cosim`` on an SSD with the FMU in process (what ``hevsim cosim``
  runs after parsing its arguments: results.csv, summary.json, system.ssd, pictures), and the
  ``hevsim cosim`` command itself in a fresh process against ``python -c
  "fmpy.simulate_fmu(...)"`` in a fresh process (both pay interpreter start and imports),
* the master alone (``simulate``) with the FMU in process and in a worker process; the raw
  cost of the same FMI calls (set inputs, doStep, get outputs) made directly is subtracted
  to give the master's own overhead per step per FMU.

Targets: end to end within 1.5x of FMPy, master overhead <= 10 µs per step per FMU, worker
FMUs <= 60 µs per step, time linear in the number of steps (1k/2k/4k/8k table).

Run: ``.venv/bin/python benchmarks/bench_cosim.py [--steps 10000] [--skip-cli]``
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

H = 0.01
TARGET_RATIO = 1.5
TARGET_OVERHEAD_US = 10.0
TARGET_WORKER_US = 60.0

_VDP = """
from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real
from pythonfmu.enums import Fmi2Initial


class BenchVanDerPol(Fmi2Slave):
    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.x0 = 2.0
        self.x1 = 0.0
        self.mu = 1.0
        self.u = 0.0
        self.register_variable(Real("u", causality=Fmi2Causality.input))
        for n in ("x0", "x1"):
            self.register_variable(Real(n, causality=Fmi2Causality.output, initial=Fmi2Initial.exact))
        tunable = Fmi2Variability.tunable
        self.register_variable(Real("mu", causality=Fmi2Causality.parameter, variability=tunable))

    def do_step(self, t, h):
        mu, u = self.mu, self.u
        f = lambda a, b: (b, mu * (1 - a * a) * b - a + u)  # noqa: E731
        x0, x1, dt = self.x0, self.x1, h / 4
        for _ in range(4):
            k1 = f(x0, x1)
            k2 = f(x0 + dt / 2 * k1[0], x1 + dt / 2 * k1[1])
            k3 = f(x0 + dt / 2 * k2[0], x1 + dt / 2 * k2[1])
            k4 = f(x0 + dt * k3[0], x1 + dt * k3[1])
            x0 += dt / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
            x1 += dt / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
        self.x0, self.x1 = x0, x1
        return True
"""


def build_vdp(d: Path) -> Path:
    from pythonfmu import FmuBuilder

    script = d / "BenchVanDerPol.py"
    script.write_text(_VDP)
    return Path(FmuBuilder.build_FMU(script, dest=d))


def write_system(d: Path, fmu: Path, steps: int) -> Path:
    from hevsim.cosim.ssd import FMU_TYPE, Component, SystemDescription
    from hevsim.cosim.ssp_write import write_ssd

    desc = SystemDescription(
        "bench", [Component("vdp", FMU_TYPE, fmu.name)], [], stop_time_s=steps * H,
        master={"step_s": H, "fmu_process": "inprocess"}, base_dir=d,
    )  # fmt: skip
    return write_ssd(desc, d / f"bench_{steps}.ssd")


def t_fmpy(fmu: Path, steps: int) -> float:
    from fmpy import simulate_fmu

    t0 = time.perf_counter()
    simulate_fmu(str(fmu), stop_time=steps * H, step_size=H, output_interval=H)
    return time.perf_counter() - t0


def t_run_cosim(ssd: Path, out: Path) -> tuple[float, dict[str, float]]:
    from hevsim.cosim.system import run_cosim

    t0 = time.perf_counter()
    res = run_cosim(ssd, out)
    wall = time.perf_counter() - t0
    return wall, {"master_s": res.stats["wall_s"]}


def raw_cost_us(fmu: Path, steps: int) -> float:
    """Per-step cost [µs] of set + doStep + get through FMPy with no master."""
    from hevsim.cosim.participant import FMUParticipant

    p = FMUParticipant("raw", fmu)
    p.setup(0.0)
    t0 = time.perf_counter()
    for k in range(steps):
        p.set_inputs({"u": 0.0})
        p.do_step(k * H, H)
        p.get_outputs()
    dt = time.perf_counter() - t0
    p.terminate()
    return dt / steps * 1e6


def master_us(fmu: Path, steps: int, cls: type) -> float:
    from hevsim.cosim import FunctionParticipant, simulate
    from hevsim.cosim.master import Connection

    # a constant source feeds u, so the FMU gets set + doStep + get every step, like raw_cost_us
    src = FunctionParticipant("src", lambda t, h, x, u: (x, {"u": 0.0}), 0, {"u": 0.0}, {})
    res = simulate(
        [src, cls("vdp", fmu)], [Connection("src", "u", "vdp", "u")], stop_time_s=steps * H, step_s=H
    )
    return float(res.stats["wall_s"]) / steps * 1e6


def cli_ratio(d: Path, fmu: Path, ssd: Path, steps: int) -> tuple[float, float]:
    """Wall time [s] of ``hevsim cosim`` and of FMPy, each in a fresh process."""
    py = sys.executable
    t0 = time.perf_counter()
    hevsim = str(Path(py).with_name("hevsim"))
    subprocess.run([hevsim, "cosim", str(ssd), "--out", str(d / "cli_out"), "--force"],
                   check=True, capture_output=True)  # fmt: skip
    t_cli = time.perf_counter() - t0
    code = (f"from fmpy import simulate_fmu; simulate_fmu({str(fmu)!r}, stop_time={steps * H}, "
            f"step_size={H}, output_interval={H}); import os; os._exit(0)")  # fmt: skip
    t0 = time.perf_counter()
    subprocess.run([py, "-c", code], check=True, capture_output=True)
    return t_cli, time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--steps", type=int, default=10_000)
    ap.add_argument("--skip-cli", action="store_true", help="skip the fresh-process CLI comparison")
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        fmu = build_vdp(d)
        ssd = write_system(d, fmu, a.steps)
        t_fmpy(fmu, 100)  # warm up both paths (imports, extraction)
        t_run_cosim(write_system(d, fmu, 100), d / "warm")
        tf = min(t_fmpy(fmu, a.steps) for _ in range(2))
        th, extra = min((t_run_cosim(ssd, d / f"out{i}") for i in range(2)), key=lambda r: r[0])
        print(f"Van der Pol FMU (pythonfmu, in process), {a.steps} steps of {H} s")
        print(f"  fmpy.simulate_fmu              : {tf:7.3f} s")
        ms = extra["master_s"]
        print(
            f"  hevsim run_cosim (files, plots): {th:7.3f} s   ratio {th / tf:5.2f} (target {TARGET_RATIO})"
        )
        print(f"    of which the master loop     : {ms:7.3f} s   ratio {ms / tf:5.2f}")
        raw = raw_cost_us(fmu, a.steps)
        from hevsim.cosim.participant import FMUParticipant
        from hevsim.cosim.worker import WorkerFMUParticipant

        tot = master_us(fmu, a.steps, FMUParticipant)
        print(f"  raw FMI set+doStep+get per step: {raw:7.2f} µs")
        print(f"  master per step (in process)   : {tot:7.2f} µs; own overhead {tot - raw:6.2f} µs per step "
              f"per FMU (target {TARGET_OVERHEAD_US}; the source participant step included)")  # fmt: skip
        wsteps = max(a.steps // 5, 200)
        tw = master_us(fmu, wsteps, WorkerFMUParticipant)
        print(f"  worker-process FMU per step    : {tw:7.2f} µs (target <= {TARGET_WORKER_US})")
        print("  scaling (run_cosim, in process):")
        print("     steps   hevsim [s]   fmpy [s]   ratio   hevsim per 1k steps [s]")
        for n in (1000, 2000, 4000, 8000):
            s_n = write_system(d, fmu, n)
            h_n = min(t_run_cosim(s_n, d / f"s{n}_{i}")[0] for i in range(2))
            f_n = min(t_fmpy(fmu, n) for _ in range(2))
            print(f"    {n:6d}   {h_n:10.3f}   {f_n:8.3f}   {h_n / f_n:5.2f}   {h_n / n * 1000:10.3f}")
        if not a.skip_cli:
            t_cli, t_fp = cli_ratio(d, fmu, ssd, a.steps)
            print(f"  fresh process: hevsim cosim {t_cli:.2f} s, python -c simulate_fmu {t_fp:.2f} s, "
                  f"ratio {t_cli / t_fp:.2f}")  # fmt: skip


if __name__ == "__main__":
    main()
    # In-process pythonfmu FMUs can abort the interpreter at exit after correct results
    # (docs/cosim.md); leave without running the exit handlers.
    sys.stdout.flush()
    os._exit(0)
