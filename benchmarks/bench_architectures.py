"""Time one UDDS forward run of every shipped architecture and controller (issue 11).

Run from the repository root (or anywhere; paths are resolved from this file)::

    .venv/bin/python benchmarks/bench_architectures.py [--repeats 3] [--no-fastsim]

For each shipped example (parallel P3 and P2, conventional, BEV, power split) and each
controller it admits, the median of ``--repeats`` runs of
``hevsim.sim.forward.simulate_architecture(model, "udds")`` after one warm-up (loading and
model building excluded), the share of it spent in the architecture's power flow, and the
ratio to FASTSim 3's ``run_once()`` on its bundled 2016 Prius UDDS when FASTSim is installed
(issue 11 targets: rule-based <= 1/5, ECMS with >= 50 candidates <= 1/2). Rows ``(py)``
time the Python reference loop (``compiled=False``) of the architectures that have a
compiled run, as the same-run baseline of its speed-up. The script only reports: it always
exits 0.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

from _machine import OtherLoad

REPO = Path(__file__).resolve().parents[1]
EXAMPLES = {
    "parallel (P3)": ("examples/parallel_hev.toml", {}),
    "parallel (P2)": ("examples/parallel_hev.toml", {"motor_coupling.position": "p2"}),
    "conventional": ("examples/conventional_sedan.toml", {}),
    "bev": ("examples/bev.toml", {}),
    "power split": ("examples/prius_like_power_split.toml", {}),
}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--no-fastsim", action="store_true", help="skip FASTSim even if installed")
    a = ap.parse_args()
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from hevsim import config as C
    from hevsim.architectures import architecture
    from hevsim.control import make_controller
    from hevsim.cycles import load_cycle
    from hevsim.sim.forward import simulate_architecture

    fastsim_s = None
    if not a.no_fastsim:
        from bench_simulate import bench_fastsim

        f = bench_fastsim(max(a.repeats, 5))
        if f is not None:
            fastsim_s = statistics.median(f["run_once"])
            print(f"FASTSim {f['version']} Prius UDDS run_once(): {fastsim_s * 1e3:.2f} ms")
        else:
            print("FASTSim: not importable (pip install 'fastsim>=3'); ratios omitted")
    cyc = load_cycle("udds")
    print(f"{'vehicle':<16}{'controller':<17}{'candidates':>11}{'median s':>10}{'ratio':>9}")
    with OtherLoad() as load:
        for label, (path, changes) in EXAMPLES.items():
            cfg = C.load_vehicle_config(REPO / path)
            if changes:
                cfg = cfg.replace(**changes)
            arch = architecture(cfg.architecture)
            model = arch.build(cfg)
            for kind in arch.controllers:
                ctl = make_controller(model, kind)
                n = len(getattr(ctl, "controls", ((),))[0]) if hasattr(ctl, "controls") else 1
                simulate_architecture(cfg.architecture, model, cyc, controller=kind)  # warm-up
                times = []
                for _ in range(a.repeats):
                    t0 = time.perf_counter()
                    simulate_architecture(cfg.architecture, model, cyc, controller=kind)
                    times.append(time.perf_counter() - t0)
                med = statistics.median(times)
                ratio = f"{med / fastsim_s:9.1f}" if fastsim_s else f"{'-':>9}"
                print(f"{label:<16}{kind:<17}{n:>11}{med:>10.3f}{ratio}")
        # the Python reference loop of the architectures with a compiled run (same-run baseline)
        for label in ("conventional", "bev"):
            cfg = C.load_vehicle_config(REPO / EXAMPLES[label][0])
            model = architecture(cfg.architecture).build(cfg)
            simulate_architecture(cfg.architecture, model, cyc, compiled=False)  # warm-up
            times = []
            for _ in range(a.repeats):
                t0 = time.perf_counter()
                simulate_architecture(cfg.architecture, model, cyc, compiled=False)
                times.append(time.perf_counter() - t0)
            med = statistics.median(times)
            ratio = f"{med / fastsim_s:9.1f}" if fastsim_s else f"{'-':>9}"
            print(f"{label + '/py':<16}{cfg.controller.kind:<17}{1:>11}{med:>10.3f}{ratio}")
        _hev_rows(REPO, cyc, a.repeats, fastsim_s)
        _entry_rows(REPO, cyc, max(a.repeats, 5), fastsim_s)
    print(load.text())
    return 0


HEV_ROWS = (
    ("parallel (P3)", "examples/parallel_hev.toml", "electric_assist", {}),
    ("parallel (P3)", "examples/parallel_hev.toml", "ecms", {"control_points": 11}),
    ("power split", "examples/prius_like_power_split.toml", "power_follower", {}),
    ("power split", "examples/prius_like_power_split.toml", "ecms", {"control_points": 5}),
)
"""Parallel and power-split rows: the rule-based controller and ECMS over a grid of at least 50
candidates (P3: engine off + 5 gears x 10 throttles = 51; power split: engine off + 13 speeds x
4 throttles = 53), compiled and through the Python loop (``py``), wall and CPU time."""


def _hev_rows(repo: Path, cyc: object, repeats: int, fastsim_s: float | None) -> None:
    """Print the :data:`HEV_ROWS` (median wall and CPU seconds of ``repeats`` UDDS runs)."""
    from hevsim import config as C
    from hevsim.architectures import architecture
    from hevsim.control import make_controller
    from hevsim.sim.forward import simulate_architecture

    print(f"{'vehicle':<16}{'controller':<17}{'candidates':>11}{'median s':>10}{'CPU s':>9}{'ratio':>9}")
    for label, path, kind, params in HEV_ROWS:
        cfg = C.load_vehicle_config(repo / path)
        model = architecture(cfg.architecture).build(cfg)
        n = len(make_controller(model, kind, **params).controls[0])
        for compiled in (True, False):
            simulate_architecture(cfg.architecture, model, cyc, controller=kind, compiled=compiled, **params)
            wall, cpu = [], []
            for _ in range(repeats):
                c0, t0 = time.process_time(), time.perf_counter()
                simulate_architecture(
                    cfg.architecture, model, cyc, controller=kind, compiled=compiled, **params
                )
                wall.append(time.perf_counter() - t0)
                cpu.append(time.process_time() - c0)
            med = statistics.median(wall)
            ratio = f"{med / fastsim_s:9.2f}" if fastsim_s else f"{'-':>9}"
            name = kind if compiled else f"{kind} (py)"
            print(f"{label:<16}{name:<17}{n:>11}{med:>10.3f}{statistics.median(cpu):>9.3f}{ratio}")


ENTRY_ROWS = {
    "series": "examples/series_hev.toml",
    "parallel (P3)": "examples/parallel_hev.toml",
    "conventional": "examples/conventional_sedan.toml",
    "bev": "examples/bev.toml",
    "power split": "examples/prius_like_power_split.toml",
    "fcev": "examples/fcev.toml",
}
"""Vehicles timed through the one entry point ``hevsim.simulate`` (issue 24's speed goals)."""


def _entry_rows(repo: Path, cyc: object, repeats: int, fastsim_s: float | None) -> None:
    """Print, for each of :data:`ENTRY_ROWS` with its configured (rule-based) controller, the
    median wall time of ``hevsim.simulate`` on UDDS from a built model and loaded cycle, and
    from the file's path with the cycle's name (the parsed-file cache warm: the second call on),
    with their ratios to FASTSim's ``run_once()`` (issue 24: <= 0.1 and <= 0.2)."""
    import hevsim
    from hevsim import config as C
    from hevsim.architectures import architecture

    def median_s(call: object) -> float:
        call()  # type: ignore[operator]  # warm-up (compiled code, caches)
        times = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            call()  # type: ignore[operator]
            times.append(time.perf_counter() - t0)
        return statistics.median(times)

    print("hevsim.simulate, rule-based controller, UDDS (median ms; ratio to FASTSim run_once())")
    print(f"{'vehicle':<16}{'built model':>12}{'ratio':>8}{'from path':>11}{'ratio':>8}")
    for label, rel in ENTRY_ROWS.items():
        path = repo / rel
        cfg = C.load_vehicle_config(path)
        model = architecture(cfg.architecture).build(cfg)
        built = median_s(lambda m=model: hevsim.simulate(m, cyc))
        from_path = median_s(lambda p=str(path): hevsim.simulate(p, "udds"))
        r1 = f"{built / fastsim_s:8.3f}" if fastsim_s else f"{'-':>8}"
        r2 = f"{from_path / fastsim_s:8.3f}" if fastsim_s else f"{'-':>8}"
        print(f"{label:<16}{built * 1e3:>12.2f}{r1}{from_path * 1e3:>11.2f}{r2}")


if __name__ == "__main__":
    raise SystemExit(main())
