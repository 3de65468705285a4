"""Studies on Dask (issue 17): the in-process run, a LocalCluster and a real ``dask scheduler``
with two ``dask worker`` processes on 127.0.0.1 give the same Parquet rows; a worker killed in
the middle of a study leaves every case done exactly once.

The scheduler and workers are started and stopped by the fixture (workers import the test
solver of tests/test_study_run.py through PYTHONPATH).
"""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pandas as pd
import pytest

pytest.importorskip("distributed")

from hevsim.studies.runner import read_results, run_study
from hevsim.studies.solvers import FAILED
from hevsim.studies.spec import study_from_dict

TESTS = Path(__file__).resolve().parent
SERIES = str(TESTS.parent / "examples" / "series_hev.toml")
sys.path.insert(0, str(TESTS))
import test_study_run as slow  # noqa: E402


def _port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _dask_cli() -> list[str]:
    exe = Path(sys.executable).with_name("dask")
    return [str(exe)] if exe.is_file() else [shutil.which("dask") or "dask"]


class Cluster:
    """A scheduler and worker processes on 127.0.0.1 (no nanny: a killed worker stays dead)."""

    def __init__(self, workers: int) -> None:
        self.address = f"tcp://127.0.0.1:{_port()}"
        env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(TESTS), os.environ.get("PYTHONPATH", "")]),
               "NUMBA_NUM_THREADS": "1", "HEVSIM_THREADS": "1"}  # fmt: skip
        port = self.address.rsplit(":", 1)[1]
        quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
        self.scheduler = subprocess.Popen(
            [*_dask_cli(), "scheduler", "--host", "127.0.0.1", "--port", port, "--dashboard-address", ":0",
             "--no-show"], env=env, **quiet,
        )  # fmt: skip
        self.workers = [
            subprocess.Popen(
                [
                    *_dask_cli(),
                    "worker",
                    self.address,
                    "--nthreads",
                    "1",
                    "--no-nanny",
                    "--host",
                    "127.0.0.1",
                    "--no-dashboard",
                ],
                env=env,
                **quiet,
            )
            for _ in range(workers)
        ]
        self.wait_for(workers)

    def wait_for(self, n: int, timeout_s: float = 90.0) -> None:
        from distributed import Client

        deadline = time.monotonic() + timeout_s
        while True:
            try:
                with Client(self.address, timeout="5s", set_as_default=False) as c:
                    c.wait_for_workers(n, timeout=max(1.0, deadline - time.monotonic()))
                    return
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.5)

    def stop(self) -> None:
        for p in [*self.workers, self.scheduler]:
            if p.poll() is None:
                p.send_signal(signal.SIGTERM)
        for p in [*self.workers, self.scheduler]:
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()


@pytest.fixture(scope="module")
def cluster() -> Iterator[Cluster]:
    c = Cluster(2)
    try:
        yield c
    finally:
        c.stop()


def _same(a: pd.DataFrame, b: pd.DataFrame) -> None:
    cols = [c for c in a.columns if c != "wall_time_s"]
    pd.testing.assert_frame_equal(
        a[cols].reset_index(drop=True), b[cols].reset_index(drop=True), check_exact=True
    )


def _study() -> object:
    return study_from_dict({
        "name": "dask", "vehicle": SERIES, "cycles": ["udds", "hwfet"], "metrics": ["mpgge", "soc_final"],
        "sampling": {"method": "lhs", "samples": 6, "seed": 4}, "batch_size": 2,
        "parameters": {"body.mass_kg": {"min": 1100.0, "max": 1400.0},
                       "motor.torque_scale": {"min": 0.9, "max": 1.3},
                       "battery.n_parallel": {"min": 1, "max": 2}},
        "solvers": [{"name": "simulate"}],
    })  # fmt: skip


def test_in_process_local_cluster_and_real_scheduler_give_identical_parquet(
    cluster: Cluster, tmp_path: Path
) -> None:
    study = _study()
    ref = run_study(study, tmp_path / "inproc", scheduler="in-process", progress=False)
    local = run_study(study, tmp_path / "local", workers=2, progress=False)
    remote = run_study(study, tmp_path / "remote", scheduler=cluster.address, progress=False)
    assert len(ref) == 12 and (ref["status"] == "ok").all()
    for rows, folder in ((local, "local"), (remote, "remote")):
        _same(rows, ref)
        _same(read_results(tmp_path / folder), read_results(tmp_path / "inproc"))
    plan = pd.read_parquet(tmp_path / "remote" / "cases.parquet")
    assert plan.equals(pd.read_parquet(tmp_path / "inproc" / "cases.parquet"))


def test_killed_worker_leaves_every_case_done_exactly_once(cluster: Cluster, tmp_path: Path) -> None:
    study = slow.slow_study(8, 0.25)  # 24 cases of 0.25 s, one per task
    out = tmp_path / "out"
    killed: list[int] = []

    def kill_when_started() -> None:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            if len(list((out / "results").glob("part-*.parquet"))) >= 4:
                victim = cluster.workers[0]
                victim.kill()
                victim.wait()
                killed.append(len(list((out / "results").glob("part-*.parquet"))))
                return
            time.sleep(0.02)

    killer = threading.Thread(target=kill_when_started)
    killer.start()
    try:
        rows = run_study(study, out, scheduler=cluster.address, progress=False)
    finally:
        killer.join()
    assert killed and killed[0] < 24, killed  # the worker died in the middle of the study
    assert cluster.workers[0].poll() is not None
    assert rows["case_id"].tolist() == list(range(24))
    _same(rows, run_study(slow.slow_study(8, 0.0), scheduler="in-process", progress=False))
    parts = pd.concat([pd.read_parquet(p) for p in (out / "results").glob("part-*.parquet")])
    assert sorted(parts["case_id"]) == list(range(24))  # exactly once on disk, too
    assert (rows["status"] == FAILED).sum() == 3
    slow.SOLVERS.pop(slow.SLOW, None)


def test_a_scheduler_without_workers_is_a_clear_error(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from distributed import LocalCluster

    from hevsim.studies import runner
    from hevsim.studies.spec import StudyError

    monkeypatch.setattr(runner, "WORKER_WAIT_S", 1.0)
    with LocalCluster(n_workers=0, processes=False, dashboard_address=None) as empty:
        with pytest.raises(StudyError, match="no worker joined within 1 s") as exc:
            run_study(_study(), tmp_path / "out", scheduler=empty.scheduler_address, progress=False)
    assert "dask worker" in str(exc.value)
    assert not (tmp_path / "out").exists()
