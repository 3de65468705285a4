"""Import of Abaqus .inp decks (issue 5, item 2)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("skfem")

from hevsim.errors import InputError
from hevsim.thermal.abaqus import TET_FACES, read_abaqus_inp
from hevsim.thermal.solver import HeatModel, discretise


def write_deck(path: Path, *, drop: str = "", flip_first: bool = False) -> None:
    """A 2-part bar (x in mm) as Abaqus would write it, with loads and an unsupported keyword."""
    from skfem import MeshTet

    m = MeshTet.init_tensor(np.linspace(0, 12, 7), np.linspace(0, 4, 3), np.linspace(0, 4, 3))
    p, t = m.p.T, m.t.T.copy()
    v = np.einsum(
        "ij,ij->i", p[t[:, 1]] - p[t[:, 0]], np.cross(p[t[:, 2]] - p[t[:, 0]], p[t[:, 3]] - p[t[:, 0]])
    )
    t[v < 0] = t[v < 0][:, [1, 0, 2, 3]]
    if flip_first:
        t[0] = t[0][[1, 0, 2, 3]]
    xc = p[t].mean(axis=1)[:, 0]
    out = ["*Heading", "** test deck", "*Part, name=Bar", "*Node"]
    out += [f"{i + 1}, {x:.6f}, {y:.6f}, {z:.6f}" for i, (x, y, z) in enumerate(p)]
    out.append("*Element, type=DC3D4")
    out += [f"{e + 1}, " + ", ".join(str(n + 1) for n in row) for e, row in enumerate(t)]
    a = [str(e + 1) for e in np.flatnonzero(xc < 6)]
    b = [str(e + 1) for e in np.flatnonzero(xc > 6)]
    out += ["*Elset, elset=ALU", *[", ".join(a[i : i + 8]) for i in range(0, len(a), 8)]]
    out += ["*Elset, elset=CELL", *[", ".join(b[i : i + 8]) for i in range(0, len(b), 8)]]
    out += [f"*Nset, nset=ALL, generate\n1, {len(p)}, 1"]
    left = []
    for e, row in enumerate(t):
        for face, idx in TET_FACES.items():
            if np.all(np.abs(p[row[list(idx)], 0]) < 1e-9):
                left.append((e + 1, face))
    for e, face in left:
        out += [f"*Elset, elset=_L_{face}_{e}", str(e)]
    out += ["*Surface, type=ELEMENT, name=LEFT", *[f"_L_{face}_{e}, {face}" for e, face in left]]
    out += [
        "*Solid Section, elset=ALU, material=Aluminum",
        ",",
        "*Solid Section, elset=CELL, material=Plastic",
        ",",
    ]
    out += ["*End Part", "*Material, name=Aluminum", "*Conductivity", "167.,", "*Density", "2700.,"]
    out += [
        "*Specific Heat",
        "902.",
        "*Material, name=Plastic",
        "*Conductivity",
        "0.2,",
        "*Density",
        "2000.,",
    ]
    out += ["*Specific Heat", "1800.", "*Surface Interaction, name=Conduction", "1.,", "*Gap Conductance"]
    out += [
        "20000.,0.",
        "0.,2.",
        "*Initial Conditions, type=TEMPERATURE",
        "ALL, 30.",
        "*Node Print",
        "NT",
        "*Radiation View Factor",
    ]
    out += [
        "*Step, name=Co-simulation",
        "*Heat Transfer",
        "1., 300.",
        "*Dflux",
        "CELL, BF, 1000.",
        "*End Step",
    ]
    text = "\n".join(out) + "\n"
    if drop:
        text = text.replace(drop, "")
    path.write_text(text)


def test_read_deck_materials_surfaces_loads(tmp_path: Path) -> None:
    deck = tmp_path / "Standard.inp"
    write_deck(deck)
    model = read_abaqus_inp(deck, length_scale_m=1e-3)
    mesh = model.mesh
    assert mesh.part_names == ("ALU", "CELL")
    assert model.materials["ALU"].conductivity_w_mk == 167.0
    assert model.materials["CELL"].specific_heat_j_kgk == 1800.0
    assert model.initial_temp_c == {"ALL": 30.0}
    assert model.gap_conductance_w_m2k == 20000.0
    assert model.body_flux_w_m3 == {"CELL": 1000.0}
    assert mesh.n_cells == 1
    assert len(model.unsupported) == 1 and model.unsupported[0].endswith(": *Radiation View Factor (ignored)")
    left = mesh.facet_groups["LEFT"]
    assert left.shape == (8, 3) and np.all(mesh.points_m[left][:, :, 0] == 0.0)
    disc = discretise(mesh, model.materials, gap_conductance_w_m2k=model.gap_conductance_w_m2k)
    assert disc.interfaces["ALU|CELL"] == pytest.approx(16e-6)
    assert disc.cell_volume_m3[0] == pytest.approx(6e-3 * 16e-6)
    hm = HeatModel(disc, dt_s=1.0, initial_temp_k=model.initial_temp_c["ALL"] + 273.15)
    hm.set_cell_heat_w(model.body_flux_w_m3["CELL"] * disc.cell_volume_m3[0])
    hm.step()
    assert hm.report().stored_energy_j > 0


@pytest.mark.parametrize(
    ("drop", "match"),
    [
        ("*Density\n2000.,\n", "material 'Plastic' has no density"),
        ("*Solid Section, elset=CELL, material=Plastic\n,\n", "have no \\*Solid Section"),
    ],
)
def test_bad_decks(tmp_path: Path, drop: str, match: str) -> None:
    deck = tmp_path / "bad.inp"
    write_deck(deck, drop=drop)
    with pytest.raises(InputError, match=match):
        read_abaqus_inp(deck)


def test_inverted_element_in_deck(tmp_path: Path) -> None:
    deck = tmp_path / "inv.inp"
    write_deck(deck, flip_first=True)
    with pytest.raises(InputError, match=r"inv\.inp: 1 inverted tetrahedra"):
        read_abaqus_inp(deck)


def test_unsupported_element_type(tmp_path: Path) -> None:
    deck = tmp_path / "hex.inp"
    deck.write_text("*Node\n1,0,0,0\n*Element, type=DC3D8\n1,1,1,1,1,1,1,1,1\n")
    with pytest.raises(InputError, match="line 3: element type 'DC3D8' is not supported"):
        read_abaqus_inp(deck)


def _instance_deck(path: Path, instance_lines: list[str], second_instance: bool = False) -> None:
    """One unit tetrahedron in a part, placed by an *Instance with the given data lines."""
    text = [
        "*Part, name=P",
        "*Node",
        "1, 0., 0., 0.",
        "2, 1., 0., 0.",
        "3, 0., 1., 0.",
        "4, 0., 0., 1.",
        "*Element, type=DC3D4, elset=E",
        "1, 1, 2, 3, 4",
        "*Solid Section, elset=E, material=M",
        ",",
        "*End Part",
        "*Assembly, name=A",
        "*Instance, name=P-1, part=P",
        *instance_lines,
        "*End Instance",
    ]
    if second_instance:
        text += ["*Instance, name=P-2, part=P", "5., 0., 0.", "*End Instance"]
    text += ["*End Assembly", "*Material, name=M", "*Conductivity", "1.,", "*Density", "1.,"]
    text += ["*Specific Heat", "1."]
    path.write_text("\n".join(text) + "\n")


def test_instance_translation_and_rotation_are_applied(tmp_path: Path) -> None:
    unit = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)
    deck = tmp_path / "inst.inp"
    _instance_deck(deck, [])
    plain = read_abaqus_inp(deck)
    assert np.allclose(plain.mesh.points_m, unit) and not plain.unsupported
    _instance_deck(deck, ["10., 20., 30."])
    moved = read_abaqus_inp(deck, length_scale_m=1e-3)
    assert np.allclose(moved.mesh.points_m, (unit + np.array([10.0, 20.0, 30.0])) * 1e-3)
    assert not any("Instance" in u for u in moved.unsupported)
    # translate by (1, 0, 0), then rotate 90 degrees about the z axis through the origin
    _instance_deck(deck, ["1., 0., 0.", "0., 0., 0., 0., 0., 1., 90."])
    rot = read_abaqus_inp(deck).mesh.points_m
    expected = np.array([[0, 1, 0], [0, 2, 0], [-1, 1, 0], [0, 1, 1]], dtype=float)
    assert np.allclose(rot, expected, atol=1e-12)
    _instance_deck(deck, ["1., 0., 0."], second_instance=True)
    twice = read_abaqus_inp(deck)  # two copies of the part, each placed by its instance
    assert np.allclose(twice.mesh.points_m[:4], unit + np.array([1.0, 0.0, 0.0]))
    assert np.allclose(twice.mesh.points_m[4:], unit + np.array([5.0, 0.0, 0.0]))
    assert twice.mesh.part_names == ("P-1", "P-2") and not twice.unsupported
    _instance_deck(deck, ["1., 0."])
    with pytest.raises(InputError, match="expected 3 numbers"):
        read_abaqus_inp(deck)
    _instance_deck(deck, ["0., 0., 0.", "1., 1., 1., 1., 1., 1., 90."])
    with pytest.raises(InputError, match="rotation axis points a and b coincide"):
        read_abaqus_inp(deck)
