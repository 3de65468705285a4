"""Bad input of issue 19: "a channel that does not connect inlet to outlet" is refused (exit 2).

The parametric plate always joins its legs (each box overlaps the next), so the disconnected
channels here are constructed: two boxes with a gap between them, and two boxes that touch
only along an edge (no face for the flow to pass). The check runs on the channel's tetrahedral
mesh (a flood fill over face neighbours from the inlet), in the laminar solver, before
OpenFOAM runs (so it needs no OpenFOAM), at config load (naming the file and the geometry
keys) and through ``hevsim flow``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("skfem")

from hevsim.errors import ConfigError
from hevsim.thermal import channel as channel_mod
from hevsim.thermal.coolant import Coolant
from hevsim.thermal.flow import (
    Channel,
    FlowSection,
    channel_mesh,
    check_channel_mesh,
    duct_channel,
    plate_channel,
    solve_flow,
)
from hevsim.thermal.geometry import ModuleGeometry, check_channel_connected

MODULE_TOML = Path(__file__).resolve().parents[1] / "examples" / "module_thermal.toml"
W, H = 0.008, 0.004

#: Inlet leg x 0..20 mm, outlet leg x 30..50 mm: a 10 mm gap of solid between them.
GAP = Channel(
    ((0.0, 0.02, 0.0, W, 0.0, H), (0.03, 0.05, 0.0, W, 0.0, H)), (0.0, 0.0, W, 1), (0.05, 0.0, W, 1)
)
#: Inlet leg y 0..8 mm, outlet leg y 8..16 mm, shifted in x so they share only the edge
#: x = 20 mm, y = 8 mm (along z).
EDGE = Channel(
    ((0.0, 0.02, 0.0, W, 0.0, H), (0.02, 0.04, W, 2 * W, 0.0, H)), (0.0, 0.0, W, 1), (0.04, W, 2 * W, 1)
)


@pytest.mark.parametrize("channel", [GAP, EDGE], ids=["gap", "edge-only"])
def test_disconnected_channel_mesh_is_refused(channel: Channel) -> None:
    mesh = channel_mesh(channel, 2, 2, 0.005)
    with pytest.raises(
        ConfigError,
        match=r"mesh\.msh: the coolant channel does not connect the inlet to the outlet.*2 separate",
    ):
        check_channel_mesh(mesh, channel, "mesh.msh")


def test_connected_channels_pass_the_check() -> None:
    for ch in (duct_channel(0.05, W, H), plate_channel(ModuleGeometry())):
        check_channel_mesh(channel_mesh(ch, 2, 2, 0.004), ch, "ok")  # no error
    # the same two legs overlapping by one millimetre: one piece
    joined = Channel(
        ((0.0, 0.021, 0.0, W, 0.0, H), (0.02, 0.04, 0.0, W, 0.0, H)), (0.0, 0.0, W, 1), (0.04, 0.0, W, 1)
    )
    check_channel_mesh(channel_mesh(joined, 2, 2, 0.005), joined, "ok")


def test_flood_fill_on_a_constructed_tetrahedral_mesh() -> None:
    """Two tetrahedra sharing a face are one piece; sharing only an edge, two."""
    face = np.array([[0, 1, 2, 3], [1, 2, 3, 4]]).T
    check_channel_connected(face, np.array([0]), np.array([1]), "two tets")
    edge = np.array([[0, 1, 2, 3], [2, 3, 4, 5]]).T
    with pytest.raises(ConfigError, match=r"two tets: .*2 separate pieces"):
        check_channel_connected(edge, np.array([0]), np.array([1]), "two tets")


def test_laminar_solver_and_rans_refuse_before_solving(monkeypatch: pytest.MonkeyPatch) -> None:
    from hevsim.thermal import rans

    c = Coolant()
    with pytest.raises(ConfigError, match="does not connect the inlet to the outlet"):
        solve_flow(GAP, c, 1e-6, section=FlowSection(model="laminar", cells_across_width=2))

    def no_openfoam() -> None:  # the check comes first: OpenFOAM is never looked for
        raise AssertionError("OpenFOAM would have run")

    monkeypatch.setattr(rans, "find_openfoam", no_openfoam)
    with pytest.raises(ConfigError, match="does not connect the inlet to the outlet"):
        solve_flow(EDGE, c, 1.6e-4, section=FlowSection(model="rans"))


def test_cli_flow_exits_2_naming_the_file_and_the_geometry_keys(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The parametric geometry cannot produce a disconnected channel; a plate whose channel
    boxes have a gap (patched in) goes through the command line's config load."""
    from hevsim.cli import main

    monkeypatch.setattr(channel_mod, "plate_channel", lambda g: GAP)  # config_channel reads it there
    out = tmp_path / "res"
    assert main(["flow", str(MODULE_TOML), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "module_thermal.toml" in err and "channel_passes = 3" in err and "channel_width_m = 0.008" in err
    assert "does not connect the inlet to the outlet" in err
    assert not out.exists()
