"""Co-simulation benchmark (issue 13 item 11; issue 6 item 8): hevsim against FMPy, per-step
overhead and scaling with the run length.

A Van der Pol oscillator FMU (pythonfmu, RK4 with 4 sub-steps per communication step) is run
for N steps of 0.01 s by

* ``fmpy.simulate_fmu`` (the baseline, same process),
* ``hevsim.cosim.system.run_cosim`` on an SSD with the FMU in process (what ``hevsim cosim``
  runs after parsing its arguments: results.csv, summary.json, system.ssd, pictures), and the
  ``hevsim cosim`` command itself in a fresh process against ``python -c
  "fmpy.simulate_fmu(...)"`` in a fresh process (both pay interpreter start and imports),
* the master alone (``simulate``) with FMUs in process and in a worker process.

The master's own overhead per step per FMU is the CPU time per step of ``simulate`` minus
that of the same FMI calls (set inputs, doStep, get outputs) made in a plain loop, divided
by the number of FMUs: CPU time, because on a shared, loaded machine wall-clock differences
of a few µs drown in the waits for a core; per step from the difference of a run of 2N and
one of N steps, so the FMUs' one-off extraction and instantiation do not count. Two systems:
two FMUs feeding each other (x0 -> u both ways), and one FMU fed by a Python source
participant (the figure reported before, whose step counts as overhead). The raw cost is
also given for FMPy's ctypes functions called directly, without hevsim's participant.

A worker-process FMU is timed over the stepping loop only (wall clock, and the CPU time of
the master and of the worker process, from /proc on Linux), the worker's start excluded, 5
runs (min / median / max), with the steps in shared memory and polling (the default), in
shared memory without polling and as pickled frames (the protocol before), interleaved; then
the same while one busy-loop process (started and killed here) loads the machine.

The fresh-process comparison runs each command 5 times (interleaved; min and median) in two
settings: with Python's bytecode cache (a normal installation; ``PYTHONPYCACHEPREFIX`` in a
temporary folder, filled by a first run) and as the environment starts it (where
``PYTHONDONTWRITEBYTECODE`` is set, every hevsim module is compiled at each start).

Targets: end to end within 1.5x of FMPy, master overhead <= 10 µs per step per FMU, worker
FMUs <= 60 µs per step, time linear in the number of steps (1k/2k/4k/8k table). The load of
the machine is printed: compare figures of the same run only.

Run: ``.venv/bin/python benchmarks/bench_cosim.py [--steps 10000] [--skip-cli] [--worker-only]``
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from _machine import OtherLoad

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


def write_system(d: Path, fmu: Path, steps: int, process: str | None = None) -> Path:
    """The SSD of the benchmark: the default path (no ``fmu_process``: a forked worker
    process per FMU) unless ``process`` ("inprocess", "worker") is given."""
    from hevsim.cosim.ssd import FMU_TYPE, Component, SystemDescription
    from hevsim.cosim.ssp_write import write_ssd

    master: dict[str, Any] = {"step_s": H} | ({"fmu_process": process} if process else {})
    desc = SystemDescription(
        "bench", [Component("vdp", FMU_TYPE, fmu.name)], [], stop_time_s=steps * H, master=master, base_dir=d,
    )  # fmt: skip
    return write_ssd(desc, d / f"bench_{steps}_{process or 'default'}.ssd")


def start_rows(fmu: Path, runs: int = 5) -> None:
    """Print the start of a worker process (open the FMU, to the first reply), forked (the
    default) and spawned (a fresh interpreter)."""
    from hevsim.cosim.worker import WorkerFMUParticipant

    for method in ("fork", "spawn"):
        cls = type("Worker", (WorkerFMUParticipant,), {"start_method": method})
        times = []
        for _ in range(runs):
            t0 = time.perf_counter()
            w = cls("w", fmu)
            times.append(time.perf_counter() - t0)
            w.terminate()
        print(f"  worker start ({method}), {runs} runs: min {min(times):.3f} / median "
              f"{statistics.median(times):.3f} s (target <= 0.1 s for the default)")  # fmt: skip


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


def raw_cost_us(fmu: Path, steps: int, n_fmus: int = 1) -> float:
    """Per-step CPU time [µs] of set + doStep + get on ``n_fmus`` in-process FMU participants
    (each fed the previous one's ``x0``, as :func:`master_cpu_us` couples them), no master."""
    from hevsim.cosim.participant import FMUParticipant

    ps = [FMUParticipant(f"raw{i}", fmu) for i in range(n_fmus)]
    for p in ps:
        p.setup(0.0)
    y = [p.get_outputs() for p in ps]
    c0 = time.process_time()
    for k in range(steps):
        for i, p in enumerate(ps):
            p.set_inputs({"u": y[i - 1]["x0"] if n_fmus > 1 else 0.0})
        for p in ps:
            p.do_step(k * H, H)
        y = [p.get_outputs() for p in ps]
    dt = time.process_time() - c0
    for p in ps:
        p.terminate()
    return dt / steps * 1e6


def direct_cost_us(fmu: Path, steps: int) -> float:
    """Per-step CPU time [µs] of fmi2SetReal + fmi2DoStep + fmi2GetReal called through FMPy's
    ctypes functions directly (no participant), with the outputs put in a dict."""
    import ctypes

    from hevsim.cosim.participant import FMUParticipant

    p = FMUParticipant("direct", fmu)
    p.setup(0.0)
    sl = p.slave
    comp, fns = sl.component, sl._functions
    set_real, do_step, get_real = fns["fmi2SetReal"], fns["fmi2DoStep"], fns["fmi2GetReal"]
    vin, val = (ctypes.c_uint * 1)(p.vr["u"]), (ctypes.c_double * 1)(0.0)
    vout, buf = (ctypes.c_uint * 2)(p.vr["x0"], p.vr["x1"]), (ctypes.c_double * 2)()
    c0 = time.process_time()
    for k in range(steps):
        set_real(comp, vin, 1, val)
        do_step(comp, k * H, H, 1)
        get_real(comp, vout, 2, buf)
        dict(zip(("x0", "x1"), buf, strict=True))
    dt = time.process_time() - c0
    p.terminate()
    return dt / steps * 1e6


def _system(fmu: Path, cls: type, n_fmus: int) -> tuple[list[Any], list[Any]]:
    """``n_fmus`` FMUs in a ring (x0 -> u), or (0) one FMU fed by a constant source, or (-1)
    one FMU alone (its input at its start value)."""
    from hevsim.cosim import FunctionParticipant
    from hevsim.cosim.master import Connection

    if n_fmus == -1:
        return [cls("vdp", fmu)], []
    if n_fmus == 0:
        src = FunctionParticipant("src", lambda t, h, x, u: (x, {"u": 0.0}), 0, {"u": 0.0}, {})
        return [src, cls("vdp", fmu)], [Connection("src", "u", "vdp", "u")]
    conns = [Connection(f"v{i - 1 if i else n_fmus - 1}", "x0", f"v{i}", "u") for i in range(n_fmus)]
    return [cls(f"v{i}", fmu) for i in range(n_fmus)], conns


def master_cpu_us(fmu: Path, steps: int, n_fmus: int) -> float:
    """Per-step CPU time [µs] of ``simulate`` with in-process FMUs (:func:`_system`), from the
    difference of a run of 2 ``steps`` and one of ``steps`` (setup excluded)."""
    from hevsim.cosim import simulate
    from hevsim.cosim.participant import FMUParticipant

    cpu = []
    for n in (steps, 2 * steps):
        parts, conns = _system(fmu, FMUParticipant, n_fmus)
        c0 = time.process_time()
        simulate(parts, conns, stop_time_s=n * H, step_s=H)
        cpu.append(time.process_time() - c0)
    return (cpu[1] - cpu[0]) / steps * 1e6


def _proc_cpu_s(pid: int) -> float | None:
    """CPU time [s] (user + system) of process ``pid`` so far (Linux /proc; None elsewhere)."""
    try:
        f = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(f[11]) + int(f[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError):
        return None


WORKER_VARIANTS = {
    "shared memory, polling": {},
    "shared memory, no polling": {"spin_s": 0.0},
    "pickled frames (before)": {"shared_memory": False},
}
"""Worker protocols compared (class attributes of WorkerFMUParticipant)."""


def worker_us(
    fmu: Path, steps: int, n_fmus: int = 0, parallel: bool = True, variant: str = "shared memory, polling"
) -> tuple[float, float, float | None]:
    """Per step over the stepping loop of worker-process FMUs (:func:`_system`; Jacobi, the
    workers started together unless not ``parallel``; protocol ``variant`` of
    :data:`WORKER_VARIANTS`): (wall [µs], master CPU [µs], workers' CPU [µs] or None)."""
    from hevsim.cosim import simulate
    from hevsim.cosim.worker import WorkerFMUParticipant

    cls = type("BenchWorker", (WorkerFMUParticipant,), dict(WORKER_VARIANTS[variant]))
    parts, conns = _system(fmu, cls, n_fmus)
    workers = [p for p in parts if isinstance(p, WorkerFMUParticipant)]
    if not parallel:
        for p in workers:
            p.start_step = None  # type: ignore[assignment,method-assign]
    marks: list[tuple[float, float, float | None]] = []

    def mark(t: float, stop: float) -> None:  # at the end of the first and of the last step
        if not marks or t >= stop - H / 2:
            cpu = [_proc_cpu_s(p.proc.pid) for p in workers]
            total = None if None in cpu else sum(c for c in cpu if c is not None)
            marks.append((time.perf_counter(), time.process_time(), total))

    simulate(parts, conns, stop_time_s=steps * H, step_s=H, progress=mark)
    (w0, c0, p0), (w1, c1, p1) = marks[0], marks[-1]
    n = steps - 1
    wcpu = (p1 - p0) / n * 1e6 if p0 is not None and p1 is not None else None
    return (w1 - w0) / n * 1e6, (c1 - c0) / n * 1e6, wcpu


def cli_ratio(
    d: Path, fmu: Path, ssd: Path, steps: int, env: dict[str, str] | None = None
) -> tuple[float, float]:
    """Wall time [s] of ``hevsim cosim`` and of FMPy, each in a fresh process (environment
    ``env``; None: this one)."""
    py = sys.executable
    t0 = time.perf_counter()
    hevsim = str(Path(py).with_name("hevsim"))
    subprocess.run([hevsim, "cosim", str(ssd), "--out", str(d / "cli_out"), "--force"],
                   check=True, capture_output=True, env=env)  # fmt: skip
    t_cli = time.perf_counter() - t0
    code = (f"from fmpy import simulate_fmu; simulate_fmu({str(fmu)!r}, stop_time={steps * H}, "
            f"step_size={H}, output_interval={H}); import os; os._exit(0)")  # fmt: skip
    t0 = time.perf_counter()
    subprocess.run([py, "-c", code], check=True, capture_output=True, env=env)
    return t_cli, time.perf_counter() - t0


def cli_rows(d: Path, fmu: Path, ssd: Path, steps: int, runs: int = 5) -> None:
    """Print the fresh-process comparison, with and without a bytecode cache."""
    cached = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    cached["PYTHONPYCACHEPREFIX"] = str(d / "pycache")
    settings = [("bytecode cached (normal install)", cached)]
    if os.environ.get("PYTHONDONTWRITEBYTECODE"):
        settings.append(("as started here, PYTHONDONTWRITEBYTECODE=1 (no bytecode cache)", None))
    for what, env in settings:
        cli_ratio(d, fmu, ssd, steps, env)  # warm-up (fills the bytecode cache)
        r = [cli_ratio(d, fmu, ssd, steps, env) for _ in range(runs)]
        hv, fp = [x[0] for x in r], [x[1] for x in r]
        print(f"  fresh process, {what}, {runs} runs: hevsim cosim min {min(hv):.3f} / median "
              f"{statistics.median(hv):.3f} s, python -c simulate_fmu min {min(fp):.3f} / median "
              f"{statistics.median(fp):.3f} s; ratio of mins {min(hv) / min(fp):.2f}, of medians "
              f"{statistics.median(hv) / statistics.median(fp):.2f} (target {TARGET_RATIO})")  # fmt: skip


def worker_rows(fmu: Path, steps: int, runs: int = 5) -> None:
    """Print the worker-process FMU per step: each protocol of :data:`WORKER_VARIANTS`,
    ``runs`` interleaved runs, on the machine as it is and with one busy loop started here."""
    for busy in (False, True):
        loop = subprocess.Popen([sys.executable, "-c", "while 1: pass"]) if busy else None
        try:
            time.sleep(0.2 if busy else 0.0)
            rows: dict[str, list[tuple[float, float, float | None]]] = {v: [] for v in WORKER_VARIANTS}
            with OtherLoad() as other:
                for _ in range(runs):
                    for v in WORKER_VARIANTS:
                        rows[v].append(worker_us(fmu, steps, variant=v))
            load = os.getloadavg()[0]
        finally:
            if loop is not None:
                loop.kill()
                loop.wait()
        how = "with one busy-loop process running" if busy else "machine as it is"
        print(f"  worker-process FMU per step, {how} (load average {load:.2f}; {other.text()}), "
              f"{runs} runs (target <= {TARGET_WORKER_US} µs):")  # fmt: skip
        for v, rs in rows.items():
            w = sorted(r[0] for r in rs)
            cm = statistics.median(r[1] for r in rs)
            cws = [r[2] for r in rs if r[2] is not None]
            cpu = f"; CPU medians: master {cm:.1f} + worker {statistics.median(cws):.1f} µs" if cws else ""
            print(f"    {v:26s}: wall min {w[0]:6.1f} / median {statistics.median(w):6.1f} / "
                  f"max {w[-1]:6.1f} µs{cpu}")  # fmt: skip


def me_rows(d: Path, steps: int, runs: int = 5) -> None:
    """Model Exchange Van der Pol (the C FMU of tests/cosim_cme.py, CVODE BDF, rtol 1e-5) for
    ``steps`` communication steps of H: ``fmpy.simulate_fmu`` (output interval H, no event
    rows) against ``simulate`` with an in-process :class:`MEParticipant` and against
    ``run_cosim`` on the default path (a forked worker, files and plots), mins of ``runs``."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from fmpy import simulate_fmu
    from tests.cosim_cme import build_me_fmu

    from hevsim.cosim.master import simulate
    from hevsim.cosim.me import MEParticipant
    from hevsim.cosim.ssd import FMU_TYPE, Component, SystemDescription
    from hevsim.cosim.ssp_write import write_ssd

    fmu = build_me_fmu("VanDerPol", d / "me")
    stop = steps * H
    comps = [Component("vdp", FMU_TYPE, "VanDerPol.fmu")]
    desc = SystemDescription("me", comps, [], stop_time_s=stop, master={"step_s": H}, base_dir=fmu.parent)
    ssd = write_ssd(desc, fmu.parent / "me.ssd")

    def fmpy_s() -> float:
        t0 = time.perf_counter()
        simulate_fmu(
            str(fmu), stop_time=stop, output_interval=H, relative_tolerance=1e-5, record_events=False
        )
        return time.perf_counter() - t0

    def master_s() -> float:
        t0 = time.perf_counter()
        simulate([MEParticipant("vdp", fmu)], [], stop_time_s=stop, step_s=H)
        return time.perf_counter() - t0

    def cpu_s() -> float:  # this process and its reaped children (the forked workers)
        r, c = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
        return r.ru_utime + r.ru_stime + c.ru_utime + c.ru_stime

    def timed(fn: Any) -> tuple[float, float]:  # (wall [s], CPU [s])
        c0 = cpu_s()
        wall = fn()
        return wall, cpu_s() - c0

    fmpy_s(), master_s()  # warm up
    rows = [(timed(fmpy_s), timed(master_s), timed(lambda i=i: t_run_cosim(ssd, d / f"me_out{i}")[0]))
            for i in range(runs)]  # fmt: skip
    tf, tm, tr = (min(r[k][0] for r in rows) for k in range(3))
    cf, cm, cr = (statistics.median(r[k][1] for r in rows) for k in range(3))
    print(f"  Model Exchange Van der Pol (C, CVODE BDF rtol 1e-5), {steps} steps of {H} s, min of {runs}:")
    print(f"    fmpy.simulate_fmu: {tf:.3f} s; hevsim simulate (in process): {tm:.3f} s, ratio {tm / tf:.2f}")
    print(f"    run_cosim default path (forked worker, files, plots): {tr:.3f} s, ratio {tr / tf:.2f} "
          f"(target {TARGET_RATIO})")  # fmt: skip
    print(f"    CPU time, medians (master + worker): fmpy {cf:.3f} s, simulate {cm:.3f} s ({cm / cf:.2f}), "
          f"run_cosim {cr:.3f} s ({cr / cf:.2f})")  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--steps", type=int, default=10_000)
    ap.add_argument("--skip-cli", action="store_true", help="skip the fresh-process CLI comparison")
    ap.add_argument("--worker-only", action="store_true", help="only the worker-process FMU rows")
    ap.add_argument("--me-only", action="store_true", help="only the Model Exchange rows")
    a = ap.parse_args()
    print("load average at start: {:.2f} {:.2f} {:.2f}".format(*os.getloadavg()))
    with tempfile.TemporaryDirectory() as tmp, OtherLoad() as load:
        d = Path(tmp)
        fmu = build_vdp(d)
        ssd = write_system(d, fmu, a.steps)
        if a.me_only:
            me_rows(d, a.steps)
        elif a.worker_only:
            worker_us(fmu, 100)
            worker_rows(fmu, a.steps)
        else:
            run_all(d, fmu, ssd, a)
    print(load.text() + "; load average at end: {:.2f} {:.2f} {:.2f}".format(*os.getloadavg()))


def run_all(d: Path, fmu: Path, ssd: Path, a: argparse.Namespace) -> None:
    """Every row of the table (see the module docstring)."""
    t_fmpy(fmu, 100)  # warm up both paths (imports, extraction)
    t_run_cosim(write_system(d, fmu, 100), d / "warm")
    tf = min(t_fmpy(fmu, a.steps) for _ in range(2))
    th, extra = min((t_run_cosim(ssd, d / f"out{i}") for i in range(2)), key=lambda r: r[0])
    inproc = write_system(d, fmu, a.steps, "inprocess")
    ti, _ = min((t_run_cosim(inproc, d / f"in{i}") for i in range(2)), key=lambda r: r[0])
    print(f"Van der Pol FMU (pythonfmu), {a.steps} steps of {H} s")
    print(f"  fmpy.simulate_fmu              : {tf:7.3f} s")
    ms = extra["master_s"]
    print(f"  hevsim run_cosim, default path (forked worker; files, plots): {th:7.3f} s   ratio "
          f"{th / tf:5.2f} (target {TARGET_RATIO})")  # fmt: skip
    print(f"    of which the master          : {ms:7.3f} s   ratio {ms / tf:5.2f}")
    print(f'  hevsim run_cosim, fmu_process="inprocess": {ti:7.3f} s   ratio {ti / tf:5.2f}')
    start_rows(fmu)
    print("  master overhead (CPU time per step, setup excluded; medians of 5 interleaved runs):")
    for k, what in ((2, "2 FMUs feeding each other"), (0, "1 FMU fed by a Python source")):
        pairs = [(raw_cost_us(fmu, a.steps, max(k, 1)), master_cpu_us(fmu, a.steps, k)) for _ in range(5)]
        raw = statistics.median(r for r, _ in pairs)
        tot = statistics.median(m for _, m in pairs)
        per = max(k, 1)
        print(f"    {what:28s}: raw set+doStep+get {raw:6.2f} µs, master {tot:6.2f} µs, own overhead "
              f"{(tot - raw) / per:5.2f} µs per step per FMU (target {TARGET_OVERHEAD_US})")  # fmt: skip
    direct = statistics.median(direct_cost_us(fmu, a.steps) for _ in range(5))
    print(f"    FMI calls through FMPy's ctypes functions directly: {direct:6.2f} µs per step per FMU")
    worker_rows(fmu, a.steps)
    import hevsim.cosim.worker as worker

    batch = getattr(worker, "RUN_AHEAD_STEPS", None)
    most = getattr(worker, "RUN_AHEAD_MAX", batch)
    how = f"runs ahead, {batch} doubling to {most} steps per exchange" if batch else "one exchange per step"
    alone = min(worker_us(fmu, a.steps, -1)[0] for _ in range(2))
    print(f"  worker FMU without inputs ({how}): {alone:7.2f} µs per step")
    par = min(worker_us(fmu, a.steps // 2, 2)[0] for _ in range(2))
    seq = min(worker_us(fmu, a.steps // 2, 2, parallel=False)[0] for _ in range(2))
    print(f"  2 worker FMUs feeding each other (Jacobi): {par:7.2f} µs per step stepping together, "
          f"{seq:7.2f} µs one after the other")  # fmt: skip
    print("  scaling (run_cosim, default path):")
    print("     steps   hevsim [s]   fmpy [s]   ratio   hevsim per 1k steps [s]")
    for n in (1000, 2000, 4000, 8000):
        s_n = write_system(d, fmu, n)
        h_n = min(t_run_cosim(s_n, d / f"s{n}_{i}")[0] for i in range(2))
        f_n = min(t_fmpy(fmu, n) for _ in range(2))
        print(f"    {n:6d}   {h_n:10.3f}   {f_n:8.3f}   {h_n / f_n:5.2f}   {h_n / n * 1000:10.3f}")
    me_rows(d, a.steps)
    if not a.skip_cli:
        cli_rows(d, fmu, ssd, a.steps)


if __name__ == "__main__":
    main()
    # In-process pythonfmu FMUs can abort the interpreter at exit after correct results
    # (docs/cosim.md); leave without running the exit handlers.
    sys.stdout.flush()
    os._exit(0)
