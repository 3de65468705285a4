"""Compare the series HEV's results of two hevsim trees: every time-series channel, metric,
energy-audit term and pack energy term with the ``table``, ``cell`` and ``pack`` batteries
(examples/series_hev.toml with a ``cell`` battery of thesis cells, examples/series_hev_pack.toml;
UDDS and US06).

Run each tree with its own numba cache, then compare::

    PYTHONPATH=OLD/src NUMBA_CACHE_DIR=/tmp/c_old python scripts/compare_series_batteries.py save old.npz
    PYTHONPATH=src NUMBA_CACHE_DIR=/tmp/c_new python scripts/compare_series_batteries.py save new.npz
    python scripts/compare_series_batteries.py compare old.npz new.npz [RTOL]

(``save`` runs whichever tree is first on ``PYTHONPATH``; ``compare`` prints every quantity that
differs by more than ``RTOL`` (default 1e-9) of its largest magnitude.)"""

import sys
from pathlib import Path

import numpy as np


def cell_car(example: str, n_s: int, n_p: int, temp_c: float = 25.0) -> Path:
    """This checkout's ``examples/example`` with a ``cell`` battery of thesis cells
    (``tests/test_cell_forward.cell_car``, in a folder of its own): the same file for both trees."""
    import tempfile

    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from tests.test_cell_forward import cell_car as make

    return make(Path(tempfile.mkdtemp()), example, n_s, n_p, temp_c=temp_c)


def save(out):
    import hevsim
    from hevsim.sim.simulator import simulate

    root = Path(hevsim.__file__).resolve().parents[2]
    ex = root / "examples"
    print("hevsim from", hevsim.__file__)
    cases = {
        "tables_udds": (ex / "series_hev.toml", "udds"),
        "cell_udds": (cell_car("series_hev.toml", 100, 6), "udds"),
        "cell_udds_np1": (cell_car("series_hev.toml", 100, 1), "udds"),
        "cell_us06": (cell_car("series_hev.toml", 100, 6), "us06"),
        "cell_hot_us06": (cell_car("series_hev.toml", 100, 3, temp_c=40.0), "us06"),
        "pack_udds": (ex / "series_hev_pack.toml", "udds"),
        "pack_us06": (ex / "series_hev_pack.toml", "us06"),
    }
    data = {}
    for name, (path, cyc) in cases.items():
        res = simulate(str(path), cyc)
        ts = res.timeseries
        for c in ts.columns:
            v = ts[c].to_numpy()
            if v.dtype.kind in "fiub":
                data[f"{name}|ts|{c}"] = v.astype(float)
        for k, m in res.metrics.items():
            try:
                data[f"{name}|m|{k}"] = np.array(float(m["value"]))
            except (TypeError, ValueError):
                pass
        for k, v in res.energy_audit.items():
            data[f"{name}|a|{k}"] = np.array(float(v))
        data[f"{name}|events"] = np.array(len(res.events))
        for k, v in (res.extra.get("pack_energy") or {}).items():
            data[f"{name}|pe|{k}"] = np.array(float(v))
        print(
            name, "fuel", res.value("fuel_kg") if "fuel_kg" in res.metrics else "", "socf", ts["soc"].iloc[-1]
        )
    np.savez(out, **data)


def compare(a, b, rtol=1e-9):
    A, B = np.load(a), np.load(b)
    ka, kb = set(A.files), set(B.files)
    print("only old:", sorted(ka - kb))
    print("only new:", sorted(kb - ka))
    bad = 0
    for k in sorted(ka & kb):
        x, y = A[k], B[k]
        if x.shape != y.shape:
            print("SHAPE", k, x.shape, y.shape)
            bad += 1
            continue
        scale = max(np.nanmax(np.abs(x)) if x.size else 0.0, 1e-300)
        d = np.nanmax(np.abs(x - y)) if x.size else 0.0
        if not np.array_equal(np.isnan(x), np.isnan(y)):
            print("NAN", k)
            bad += 1
            continue
        if d > rtol * scale:
            bad += 1
            idx = int(np.nanargmax(np.abs(x - y))) if x.ndim else 0
            print(f"DIFF {k}: max|d|={d:.3g} rel={d / scale:.3g} at {idx}")
    print("differences:", bad, "of", len(ka & kb))


if __name__ == "__main__":
    if sys.argv[1] == "save":
        save(sys.argv[2])
    else:
        compare(sys.argv[2], sys.argv[3], float(sys.argv[4]) if len(sys.argv) > 4 else 1e-9)
