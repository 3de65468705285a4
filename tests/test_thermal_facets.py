"""The FEM's surface terms (external and named films, channel-wall film per coolant segment,
contact between parts) assembled through scikit-fem facet bases give the matrices of the
former hand-written assembly (issue 18 item 5).

The reference ``tests/data/thermal_surface_terms.npz`` holds a small three-part mesh and the
operators the hand-written assembly built on it (hevsim commit 2bebb97, before the facet
bases), written by ``python tests/test_thermal_facets.py --write-reference`` at that commit;
see ``tests/data/README.md``.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import scipy.sparse as sp

pytest.importorskip("skfem")

from hevsim.thermal.materials import Material
from hevsim.thermal.mesh import CHANNEL_WALL, ThermalMesh, tet_volumes_m3
from hevsim.thermal.solver import HeatModel, discretise

REFERENCE = Path(__file__).resolve().parent / "data" / "thermal_surface_terms.npz"
PART_NAMES = ("plate", "holder", "cell")
MATERIALS = {
    "plate": Material("aluminium", 200.0, 2700.0, 900.0),
    "holder": Material("plastic", 0.3, 1200.0, 1500.0),
    "cell": Material("cell", 3.0, 2500.0, 1000.0),
}
GAP_W_M2K = 800.0
CONTACT_W_M2K = {"cell|holder": 250.0}  # override on one of the two interfaces
FILM_W_M2K, AMBIENT_K = 7.5, 298.15
TOP_FILM = (40.0, 290.0)  # named surface film "TOP": h [W/(m^2 K)], T_inf [K]
WALL_H_W_M2K = np.array([1500.0, 900.0])  # per channel-wall segment
WALL_H_LATER = np.array([1200.0, 2100.0])  # set on the heat model afterwards


def build_mesh() -> dict[str, np.ndarray]:
    """A 6 x 3 x 3 box of tetrahedra with distorted nodes in three parts along x, two cells,
    the channel wall on x = 0 (two segments along y) and a named surface on top."""
    from skfem import MeshTet

    lx, ly, lz = 0.03, 0.012, 0.01
    m = MeshTet.init_tensor(np.linspace(0, lx, 7), np.linspace(0, ly, 4), np.linspace(0, lz, 4))
    p, t = m.p.T.copy(), m.t.T.copy()
    # deterministic distortion of the interior x-y positions (faces stay planar)
    inner = (p[:, 1] > 1e-9) & (p[:, 1] < ly - 1e-9)
    p[inner, 1] += 0.0011 * np.sin(37.0 * p[inner, 0] + 91.0 * p[inner, 2])
    p[:, 2] *= 1.0 + 0.3 * p[:, 1] / ly
    t[tet_volumes_m3(p, t) < 0] = t[tet_volumes_m3(p, t) < 0][:, [1, 0, 2, 3]]  # right-handed
    xc = p[t].mean(axis=1)
    part = np.digitize(xc[:, 0], [0.01, 0.02])  # 0 plate, 1 holder, 2 cell
    cell = np.where(part == 2, (xc[:, 1] > ly / 2).astype(int), -1)
    tol = 1e-9
    wall = m.facets[:, m.facets_satisfying(lambda x: x[0] < tol)].T
    top = m.facets[:, m.facets_satisfying(lambda x: x[2] > lz - tol)].T  # m.p is undistorted
    wall_segment = (p[wall].mean(axis=1)[:, 1] > ly / 2).astype(np.int64)
    return {"points_m": p, "tets": t, "part_of_tet": part, "cell_of_tet": cell, "wall": wall,
            "top": top, "wall_segment": wall_segment}  # fmt: skip


def mesh_of(d: dict[str, np.ndarray]) -> ThermalMesh:
    groups = {CHANNEL_WALL: d["wall"], "TOP": d["top"]}
    return ThermalMesh(d["points_m"], d["tets"], d["part_of_tet"], PART_NAMES, d["cell_of_tet"], groups)


def operators(d: dict[str, np.ndarray]) -> dict[str, Any]:
    """Everything the surface terms feed, from the current code."""
    disc = discretise(
        mesh_of(d), MATERIALS, gap_conductance_w_m2k=GAP_W_M2K, interface_conductance_w_m2k=CONTACT_W_M2K,
        film_w_m2k=FILM_W_M2K, ambient_k=AMBIENT_K, surface_films={"TOP": TOP_FILM},
        wall_segment_of_facet=d["wall_segment"], wall_h_w_m2k=WALL_H_W_M2K,
    )  # fmt: skip
    model = HeatModel(disc, dt_s=1.0)
    model.set_wall_film(WALL_H_LATER)
    return {
        "stiffness": disc.stiffness, "capacity": disc.capacity, "k_with_wall_film": model.k,
        "wall_weights": disc.wall_weights, "film_load_w": disc.film_load_w, "film_area": disc.film_area,
        "wall_area_m2": disc.wall_area_m2, "wall_tris": disc.wall_tris, "original_node": disc.original_node,
        "interface_names": np.array(sorted(disc.interfaces)),
        "interface_areas": np.array([disc.interfaces[k] for k in sorted(disc.interfaces)]),
    }  # fmt: skip


def write_reference(path: Path = REFERENCE) -> None:
    import subprocess

    d = build_mesh()
    out: dict[str, Any] = {f"mesh_{k}": v for k, v in d.items()}
    for k, v in operators(d).items():
        if sp.issparse(v):
            v = v.tocsr()
            v.sum_duplicates()
            v.sort_indices()
            out[f"{k}_data"], out[f"{k}_indices"], out[f"{k}_indptr"] = v.data, v.indices, v.indptr
            out[f"{k}_shape"] = np.array(v.shape)
        else:
            out[k] = v
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout
    out["provenance"] = np.array(f"hand-written surface assembly, hevsim commit {commit.strip()}")
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, **out)


def _sparse(ref: Any, name: str) -> sp.csr_matrix:
    shape = tuple(int(s) for s in ref[f"{name}_shape"])
    return sp.csr_matrix((ref[f"{name}_data"], ref[f"{name}_indices"], ref[f"{name}_indptr"]), shape=shape)


@pytest.fixture(scope="module")
def ref_and_new() -> tuple[Any, dict[str, Any]]:
    ref = np.load(REFERENCE)
    d = {k[len("mesh_") :]: ref[k] for k in ref.files if k.startswith("mesh_")}
    return ref, operators(d)


@pytest.mark.parametrize("name", ["stiffness", "k_with_wall_film", "capacity", "wall_weights"])
def test_matrices_equal_the_hand_written_assembly(ref_and_new: tuple[Any, dict[str, Any]], name: str) -> None:
    ref, new = ref_and_new
    a, b = _sparse(ref, name), new[name].tocsr()
    assert a.shape == b.shape
    scale = abs(a).max()
    assert scale > 0
    assert abs(a - b).max() <= 1e-12 * scale, (name, abs(a - b).max() / scale)
    # and the same sparsity pattern (no rounding-level entries between unrelated nodes)
    assert a.nnz == b.nnz and (a != 0).multiply(b != 0).nnz == a.nnz


@pytest.mark.parametrize("name", ["film_load_w", "film_area", "wall_area_m2", "interface_areas"])
def test_vectors_equal_the_hand_written_assembly(ref_and_new: tuple[Any, dict[str, Any]], name: str) -> None:
    ref, new = ref_and_new
    np.testing.assert_allclose(new[name], ref[name], rtol=1e-12, atol=1e-12 * np.abs(ref[name]).max())


def test_reference_case_exercises_every_surface_term(ref_and_new: tuple[Any, dict[str, Any]]) -> None:
    """The reference mesh has two contact interfaces (one overridden), ambient and named films,
    and a two-segment channel wall, so each term is compared, not just zero against zero."""
    ref, new = ref_and_new
    assert list(ref["interface_names"]) == ["cell|holder", "holder|plate"] == list(new["interface_names"])
    assert np.all(ref["interface_areas"] > 0)
    assert np.all(ref["wall_area_m2"] > 0) and ref["wall_area_m2"].size == 2
    assert ref["mesh_top"].shape[0] > 0 and ref["mesh_wall"].shape[0] > 0
    assert ref["film_area"].sum() > 0 and np.count_nonzero(ref["film_load_w"]) > 0
    np.testing.assert_array_equal(new["wall_tris"], ref["wall_tris"])
    np.testing.assert_array_equal(new["original_node"], ref["original_node"])
    # contact conductance appears off-diagonal between the two copies of an interface node
    k = _sparse(ref, "stiffness").tocoo()
    orig = ref["original_node"]
    assert np.any((orig[k.row] == orig[k.col]) & (k.row != k.col) & (k.data < 0))


if __name__ == "__main__" and "--write-reference" in sys.argv:
    write_reference()
    print(f"wrote {REFERENCE}")
