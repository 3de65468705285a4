"""Run a study: plan batches, execute them (in process or on Dask), stream rows to Parquet.

Executors (``scheduler``):

- ``None``: ``$HEVSIM_DASK_SCHEDULER`` if set, else a Dask ``LocalCluster`` on this machine
  (one single-threaded worker process per core, numba kernels at one thread in each);
- ``"tcp://HOST:PORT"`` (or ``tls://``): an existing Dask cluster (``dask scheduler`` +
  ``dask worker`` on any machines that can import hevsim and read the study's files);
- ``"in-process"``: no Dask; batches run one after the other in this process.

A task is a batch of cases of one solver and cycle whose vehicles share component data
(:meth:`hevsim.studies.solvers.Solver.group`), so the compiled batch kernels do the work; the
study (vehicle configuration, cycles, solver contexts) is shipped to every worker once.

Output folder (``out``)::

    study.json          the resolved study (its fingerprint identifies it for --resume)
    cases.parquet       the plan: case_id, sample_id, cycle, solver, every varied parameter
    results/part-RRR-BBBBBB.parquet   one file per finished batch (atomic rename), the dataset
    summary.json        counts and timing, written when the study completes

Rows: ``case_id``, ``sample_id``, ``cycle``, ``solver``, the varied parameters, ``status``
(``ok``/``failed``), ``error``, the kept metrics, ``wall_time_s``. Every column but
``wall_time_s`` is the same bit for bit for the same study and seed, whatever the executor,
the batch sizes or the interruptions. ``resume=True`` skips the cases already in ``results/``.
"""

from __future__ import annotations

import json
import logging
import math
import os
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from hevsim.errors import HevsimError
from hevsim.studies.solvers import SOLVERS, Outcome
from hevsim.studies.spec import Study, StudyError, load_study

SCHEDULER_ENV = "HEVSIM_DASK_SCHEDULER"
"""Environment variable naming a Dask scheduler address (``tcp://HOST:PORT``)."""
IN_PROCESS = "in-process"
"""``scheduler`` value: run the batches in this process, without Dask."""
CONNECT_TIMEOUT_S = 5.0
"""How long to try to reach a scheduler before giving up [s]."""
WORKER_WAIT_S = 10.0
"""How long to wait for a first worker on a cluster that has none [s]."""
TASKS_PER_WORKER = 4
"""Automatic batch size: aim at this many tasks per worker for each group of cases [-]."""
MAX_BATCH = 2048
"""Largest automatic batch [cases]."""
RESULTS = "results"
STUDY_JSON = "study.json"
PLAN = "cases.parquet"
SUMMARY = "summary.json"


@dataclass(frozen=True)
class Batch:
    """One task: cases of one solver and cycle that share a group key."""

    solver: int
    cycle: int
    case_ids: np.ndarray
    values: np.ndarray


@dataclass(frozen=True, eq=False)
class Payload:
    """What every worker receives once: run functions, solver contexts, cycles, the metrics
    each solver keeps."""

    runs: tuple[Any, ...]
    contexts: tuple[Any, ...]
    cycles: tuple[Any, ...]
    metrics: tuple[tuple[str, ...], ...]


def run_batch(payload: Payload, batch: Batch, threads: int | None) -> tuple[np.ndarray, list[Outcome]]:
    """Run one batch (on a worker); returns its case ids and one outcome per case."""
    run = payload.runs[batch.solver]
    outcomes = run(payload.contexts[batch.solver], payload.cycles[batch.cycle], batch.values,
                   payload.metrics[batch.solver], threads)  # fmt: skip
    if len(outcomes) != len(batch.case_ids):  # a solver bug, not a user error
        raise RuntimeError(f"solver returned {len(outcomes)} outcomes for {len(batch.case_ids)} cases")
    return batch.case_ids, outcomes


def plan_batches(study: Study, contexts: tuple[Any, ...], todo: np.ndarray, workers: int) -> list[Batch]:
    """Split the case ids ``todo`` into batches (deterministic for given inputs)."""
    samples, cycles, solvers = study.case_index()
    batches: list[Batch] = []
    for v, sc in enumerate(study.solvers):
        spec = SOLVERS[sc.name]
        n_cyc = len(study.cycles)  # a cycle-free solver: a vehicle's cases of every cycle in one task
        for cs in [list(range(n_cyc))] if spec.cycle_free else [[c] for c in range(n_cyc)]:
            c = cs[0]
            ids = todo[(solvers[todo] == v) & np.isin(cycles[todo], cs)]
            groups: dict[Any, list[int]] = {}
            for cid in ids.tolist():
                groups.setdefault(spec.group(contexts[v], study.values[samples[cid]]), []).append(cid)
            for members in groups.values():
                size = study.batch_size or spec.default_batch
                if size <= 0:
                    size = min(
                        MAX_BATCH, max(1, math.ceil(len(members) / (TASKS_PER_WORKER * max(1, workers))))
                    )
                size *= len(cs)  # ids are sample-major: a sample's cycles stay together
                for k in range(0, len(members), size):
                    chunk = np.asarray(members[k : k + size], dtype=np.int64)
                    batches.append(Batch(v, c, chunk, study.values[samples[chunk]]))
    return batches


def _rows(study: Study, plan: pd.DataFrame, case_ids: np.ndarray, outcomes: list[Outcome]) -> pd.DataFrame:
    frame = plan.iloc[case_ids].reset_index(drop=True)
    frame["status"] = [o.status for o in outcomes]
    frame["error"] = [o.error for o in outcomes]
    for m in study.metrics:
        frame[m] = np.array([o.metrics.get(m, np.nan) for o in outcomes], dtype=np.float64)
    frame["wall_time_s"] = np.array([o.wall_time_s for o in outcomes], dtype=np.float64)
    return frame


# ------------------------------------------------------------------------------------------
# The output folder
# ------------------------------------------------------------------------------------------
class StudyFolder:
    """A study's output folder: plan, parts written atomically, marker kept up to date."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.results = path / RESULTS

    def files(self) -> list[str]:
        """Every file in the folder (relative POSIX paths), marker excluded."""
        from hevsim.io import MARKER

        out = []
        for root, _, names in os.walk(self.path):
            for n in names:
                rel = (Path(root) / n).relative_to(self.path).as_posix()
                if rel != MARKER and not n.startswith("."):
                    out.append(rel)
        return sorted(out)

    def write_marker(self, extra: list[str] = ()) -> None:  # type: ignore[assignment]
        """Rewrite the hevsim marker listing every file (plus ``extra`` about to appear)."""
        import sys
        from datetime import UTC, datetime

        from hevsim import __version__
        from hevsim.io import MARKER, write_text_atomic

        data = {
            "hevsim_version": __version__,
            "command": [Path(sys.argv[0]).name, *sys.argv[1:]] if sys.argv else [],
            "created": datetime.now(UTC).isoformat(timespec="seconds"),
            "files": sorted(set(self.files()) | set(extra)),
        }
        write_text_atomic(self.path / MARKER, json.dumps(data, indent=2) + "\n")

    def add_file(self, rel: str, write: Any) -> None:
        """Write ``rel`` atomically through ``write(tmp_path)``, listed in the marker first."""
        target = self.path / rel
        tmp = target.parent / f".{target.name}.tmp-{os.getpid()}"
        try:
            write(tmp)
            self.write_marker([rel])
            os.replace(tmp, target)
        finally:
            tmp.unlink(missing_ok=True)

    def done_ids(self) -> np.ndarray:
        """Case ids already written."""
        parts = self.part_files()
        if not parts:
            return np.zeros(0, dtype=np.int64)
        ids = [pd.read_parquet(p, columns=["case_id"])["case_id"].to_numpy() for p in parts]
        return np.unique(np.concatenate(ids))

    def part_files(self) -> list[Path]:
        """The finished batch files, in name order."""
        return sorted(self.results.glob("part-*.parquet")) if self.results.is_dir() else []

    def next_run(self) -> int:
        """The run number for new part files (one more than any existing)."""
        runs = [int(p.name.split("-")[1]) for p in self.part_files()]
        return max(runs, default=0) + 1


def read_results(out: str | Path) -> pd.DataFrame:
    """Every finished case of the study folder ``out``, one row per case, by case id."""
    folder = StudyFolder(Path(out))
    if not (folder.path / STUDY_JSON).is_file():
        raise StudyError(
            f"{out}: not a study folder (no {STUDY_JSON}); expected the --out of `hevsim study`."
        )
    parts = folder.part_files()
    if not parts:
        plan = pd.read_parquet(folder.path / PLAN)
        return plan.iloc[:0]
    frame = pd.concat([pd.read_parquet(p) for p in parts], ignore_index=True)
    frame = frame.drop_duplicates("case_id", keep="first")
    return frame.sort_values("case_id", kind="stable").reset_index(drop=True)


# ------------------------------------------------------------------------------------------
# Executors
# ------------------------------------------------------------------------------------------
def default_workers() -> int:
    """Cores available to this process."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def _check_address(address: str) -> None:
    if not any(address.startswith(p) for p in ("tcp://", "tls://", "ucx://", "inproc://")):
        raise StudyError(
            f"scheduler {address!r}: expected 'tcp://HOST:PORT' (a running `dask scheduler`), "
            f"'{IN_PROCESS}', or nothing for a local cluster."
        )


@contextmanager
def _sigint_ignored() -> Iterator[None]:
    """SIGINT ignored while child processes start (they inherit the disposition, and Python
    then installs no KeyboardInterrupt in them): a Ctrl-C at the terminal reaches the whole
    process group, and only this process is to handle it (the finished cases are kept, the
    workers are closed by the cluster; no worker prints a traceback). Outside the main
    thread, where signal handlers cannot be set, nothing changes."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


@contextmanager
def _dask_client(scheduler: str | None, workers: int | None) -> Iterator[tuple[Any, int, str]]:
    """(client, workers, description); a LocalCluster when ``scheduler`` is None."""
    import dask
    from distributed import Client, LocalCluster

    if scheduler is not None:
        _check_address(scheduler)
        try:
            with dask.config.set({"distributed.comm.timeouts.connect": f"{CONNECT_TIMEOUT_S}s"}):
                client = Client(scheduler, timeout=f"{CONNECT_TIMEOUT_S}s", set_as_default=False)
        except (OSError, TimeoutError) as exc:
            raise StudyError(
                f"scheduler {scheduler}: cannot reach the Dask scheduler within {CONNECT_TIMEOUT_S:g} s "
                f"({type(exc).__name__}: {exc}); expected a running `dask scheduler` at that address "
                f"(check --scheduler / ${SCHEDULER_ENV})."
            ) from exc
        try:
            try:
                client.wait_for_workers(1, timeout=WORKER_WAIT_S)
            except (TimeoutError, OSError) as exc:
                raise StudyError(
                    f"scheduler {scheduler}: no worker joined within {WORKER_WAIT_S:g} s; expected "
                    f"workers started with `dask worker {scheduler} --nthreads 1`."
                ) from exc
            n = max(1, len(client.scheduler_info(n_workers=-1).get("workers", {})))
            yield client, n, f"Dask cluster at {scheduler}"
        finally:
            client.close()
        return
    n = workers or default_workers()
    try:
        import bokeh  # noqa: F401

        dashboard: str | None = ":0"
    except ImportError:
        dashboard = None
    with _sigint_ignored():  # the worker processes inherit it: Ctrl-C stops the study, not them
        cluster = LocalCluster(
            n_workers=n, threads_per_worker=1, processes=True, dashboard_address=dashboard,
            silence_logs=logging.ERROR, env={"NUMBA_NUM_THREADS": "1", "HEVSIM_THREADS": "1"},
        )  # fmt: skip
    try:
        client = Client(cluster, set_as_default=False)
        try:
            yield client, n, f"Dask LocalCluster, {n} worker(s) x 1 thread"
        finally:
            client.close()
    finally:
        cluster.close()


# ------------------------------------------------------------------------------------------
# run_study
# ------------------------------------------------------------------------------------------
def _prepare_folder(study: Study, out: Path, resume: bool, force: bool) -> tuple[StudyFolder, bool]:
    """Check ``out`` (before any work); returns (folder, whether it exists with our study)."""
    from hevsim.io import prepare_output

    folder = StudyFolder(out)
    if resume and (out / STUDY_JSON).is_file():
        try:
            old = json.loads((out / STUDY_JSON).read_text())
        except (OSError, ValueError) as exc:
            raise StudyError(f"--resume {out}: {STUDY_JSON} is unreadable ({exc}).") from exc
        if old.get("fingerprint") != study.fingerprint():
            raise StudyError(
                f"--resume {out}: the folder holds another study ({old.get('name')!r}, fingerprint "
                f"{str(old.get('fingerprint'))[:12]}); expected the same study file, vehicle and seed "
                "(or run without --resume to start over)."
            )
        return folder, True
    protect = [p for p in (study.source, study.vehicle_source) if Path(p).exists()]
    prepare_output(out, force=force, protect=protect)
    return folder, False


def _create_folder(study: Study, folder: StudyFolder, plan: pd.DataFrame) -> None:
    from hevsim.io import atomic_directory, write_json

    with atomic_directory(folder.path) as tmp:
        write_json(tmp / STUDY_JSON, {**study.describe(), "fingerprint": study.fingerprint()})
        plan.to_parquet(tmp / PLAN, index=False)
        (tmp / RESULTS).mkdir()


def run_study(
    study: Study | str | Path,
    out: str | Path | None = None,
    *,
    scheduler: str | None = None,
    workers: int | None = None,
    resume: bool = False,
    force: bool = False,
    progress: bool | None = None,
) -> pd.DataFrame:
    """Run every case of ``study`` (a :class:`Study` or a study TOML path); returns the rows.

    Args:
        out: results folder (None: keep rows in memory only). Checked before any work; an
            existing hevsim results folder is replaced unless ``resume``.
        scheduler: ``None`` (``$HEVSIM_DASK_SCHEDULER``, else a LocalCluster),
            ``"tcp://HOST:PORT"`` or ``"in-process"``.
        workers: LocalCluster workers (default: the cores of this machine).
        resume: continue the study in ``out``, skipping the cases already written.
        force: replace a folder at ``out`` that hevsim did not write.
        progress: progress bar / lines (None: bar on a terminal, lines otherwise).

    Returns:
        One row per case, by ``case_id`` (see the module docstring for the columns).

    Raises:
        StudyError: bad study, unreachable scheduler, ``out`` holding another study.
        OutputError: ``out`` cannot be written safely.
    """
    from hevsim import progress as prog

    if not isinstance(study, Study):
        study = load_study(study)
    if scheduler is None:
        scheduler = os.environ.get(SCHEDULER_ENV) or None
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
        raise StudyError(f"workers = {workers!r}: expected an integer >= 1.")
    if scheduler is not None and scheduler != IN_PROCESS:
        _check_address(scheduler)
    plan = study.plan()
    folder: StudyFolder | None = None
    existing = False
    if out is not None:
        folder, existing = _prepare_folder(study, Path(out), resume, force)
    contexts = tuple(SOLVERS[s.name].prepare(study, s) for s in study.solvers)
    payload = Payload(tuple(SOLVERS[s.name].run for s in study.solvers), contexts, study.cycle_objects,
                      tuple(s.kept_metrics(study.metrics, study.vehicle) for s in study.solvers))  # fmt: skip
    done = folder.done_ids() if (folder is not None and existing) else np.zeros(0, dtype=np.int64)
    todo = np.setdiff1d(np.arange(study.n_cases, dtype=np.int64), done)
    frames: list[pd.DataFrame] = []
    written: set[int] = set(done.tolist())
    t0 = time.perf_counter()
    failed = 0
    show = prog.enabled() if progress is None else bool(progress)

    with _executor(scheduler, workers) as (submit, n_workers, label, dashboard):
        if folder is not None and not existing:
            _create_folder(study, folder, plan)
        run_no = folder.next_run() if folder is not None else 1
        batches = plan_batches(study, contexts, todo, n_workers)
        if show:
            prog.stage(f"study '{study.name}': {len(todo)} of {study.n_cases} cases to run in "
                       f"{len(batches)} tasks on {label}")  # fmt: skip
            if dashboard:
                prog.stage(f"Dask dashboard: {dashboard}")
        with prog.task(f"study {study.name}", len(todo), unit="case", show=show) as bar:
            for seq, (case_ids, outcomes) in enumerate(submit(payload, batches)):
                keep = [i for i, c in enumerate(case_ids.tolist()) if c not in written]
                if not keep:
                    continue
                rows = _rows(study, plan, case_ids[keep], [outcomes[i] for i in keep])
                written.update(case_ids[keep].tolist())
                failed += int((rows["status"] != "ok").sum())
                if folder is not None:
                    name = f"{RESULTS}/part-{run_no:03d}-{seq:06d}.parquet"
                    folder.add_file(name, lambda p, r=rows: r.to_parquet(p, index=False))
                else:
                    frames.append(rows)
                bar.update(len(keep))
                if bar._bar is not None:
                    bar._bar.set_postfix(failed=failed)
    elapsed = time.perf_counter() - t0
    if folder is not None:
        from hevsim.io import write_json

        result = read_results(folder.path)
        summary = {
            "cases": study.n_cases, "done": len(result),
            "ok": int((result["status"] == "ok").sum()), "failed": int((result["status"] != "ok").sum()),
            "run_cases": len(todo), "run_time_s": elapsed, "executor": label,
        }  # fmt: skip
        folder.add_file(SUMMARY, lambda p: write_json(p, summary))
    else:
        result = (
            pd.concat(frames, ignore_index=True).sort_values("case_id", kind="stable").reset_index(drop=True)
            if frames
            else plan.iloc[:0]
        )
    if show:
        rate = len(todo) / elapsed if elapsed > 0 else float("inf")
        prog.stage(f"study '{study.name}': {len(todo)} cases in {elapsed:.1f} s ({rate:.3g} cases/s), "
                   f"{failed} failed")  # fmt: skip
    return result


@contextmanager
def _executor(scheduler: str | None, workers: int | None) -> Iterator[tuple[Any, int, str, str]]:
    """(submit(payload, batches) -> iterator of finished batches, workers, label, dashboard)."""
    if scheduler == IN_PROCESS:

        def serial(payload: Payload, batches: list[Batch]) -> Iterator[tuple[np.ndarray, list[Outcome]]]:
            for b in batches:
                yield run_batch(payload, b, None)

        yield serial, 1, "this process (no Dask)", ""
        return
    with _dask_client(scheduler, workers) as (client, n, label):
        dashboard = ""
        try:
            import bokeh  # noqa: F401

            dashboard = str(client.dashboard_link)
        except (ImportError, AttributeError, KeyError):
            dashboard = ""

        def distributed(payload: Payload, batches: list[Batch]) -> Iterator[tuple[np.ndarray, list[Outcome]]]:
            from distributed import as_completed

            if not batches:
                return
            shipped = client.scatter(payload, broadcast=True, hash=False)
            futures = [client.submit(run_batch, shipped, b, 1, pure=False, key=f"hevsim-batch-{i}-{id(b)}")
                       for i, b in enumerate(batches)]  # fmt: skip
            try:
                for fut in as_completed(futures, loop=client.loop):
                    yield fut.result()
            finally:
                client.cancel(futures)

        yield distributed, n, label, dashboard


def load_folder_study(out: str | Path) -> dict[str, Any]:
    """The ``study.json`` of a study folder (StudyError if absent)."""
    p = Path(out) / STUDY_JSON
    if not p.is_file():
        raise StudyError(
            f"{out}: not a study folder (no {STUDY_JSON}); expected the --out of `hevsim study`."
        )
    try:
        data: dict[str, Any] = json.loads(p.read_text())
    except (OSError, ValueError) as exc:
        raise StudyError(f"{p}: unreadable ({exc}).") from exc
    return data


__all__ = ["IN_PROCESS", "SCHEDULER_ENV", "HevsimError", "read_results", "run_study"]
