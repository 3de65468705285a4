"""One atomic PNG save (hevsim.report.save.save_png) behind the vehicle plots and the module's
temperature-field pictures (issue 18 item 5)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("matplotlib")

from hevsim import figures
from hevsim.report import plots
from hevsim.report.save import save_png
from hevsim.thermal import pictures

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"

SAVES: dict[str, Callable[[Any, Path], Path]] = {
    "save_png": lambda fig, path: save_png(fig, path, 72),
    "figures.save": figures.save,
    "report.plots._save": plots._save,
    "thermal.pictures._save": pictures._save,
}


class FailingFigure:
    """Writes half a picture, then fails (as a full disk or a drawing error would)."""

    cleared = False

    def savefig(self, path: Any, **kwargs: Any) -> None:
        Path(path).write_bytes(PNG_MAGIC + b"half")
        raise RuntimeError("drawing failed")

    def clear(self) -> None:
        self.cleared = True


@pytest.mark.parametrize("name", sorted(SAVES))
def test_save_writes_a_png_and_no_temporary_file(name: str, tmp_path: Path) -> None:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(2.0, 1.5))
    fig.add_subplot().plot([0, 1], [1, 0])
    out = SAVES[name](fig, tmp_path / "sub" / "picture.png")
    assert out == tmp_path / "sub" / "picture.png"
    assert out.read_bytes()[:8] == PNG_MAGIC
    assert [p.name for p in out.parent.iterdir()] == ["picture.png"]
    assert not fig.axes  # released


@pytest.mark.parametrize("name", sorted(SAVES))
def test_failed_save_keeps_the_old_picture(name: str, tmp_path: Path) -> None:
    target = tmp_path / "picture.png"
    target.write_bytes(b"old picture")
    fig = FailingFigure()
    with pytest.raises(RuntimeError, match="drawing failed"):
        SAVES[name](fig, target)
    assert target.read_bytes() == b"old picture"
    assert [p.name for p in tmp_path.iterdir()] == ["picture.png"]
    assert fig.cleared


def test_every_picture_goes_through_the_one_atomic_save() -> None:
    """No module of the package writes a figure itself: ``savefig`` is called only inside
    :func:`save_png` (a direct call would leave a half-written PNG behind on a failure)."""
    src = Path(__file__).resolve().parent.parent / "src" / "hevsim"
    direct = [
        f"{path.relative_to(src)}:{no}"
        for path in sorted(src.rglob("*.py"))
        if path.relative_to(src).as_posix() != "io.py"
        for no, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
        if ".savefig(" in line
    ]
    assert direct == [], direct
