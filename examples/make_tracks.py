"""Write the tracks hevsim builds from stated geometry as distance-curvature CSVs.

Run from the repository root::

    .venv/bin/python examples/make_tracks.py [--out examples/tracks]

The geometry is stated in ``hevsim.tracks`` (``skidpad``: a circle of radius 30.48 m, the
200 ft skidpad; ``oval``: two 800 m straights and two half circles of radius 200 m;
``handling``: the 2491 m circuit of straights and 90-degree corners of radius 30 to 80 m in
the docstring of ``hevsim.tracks.handling_circuit``). Each file has the columns
``distance_m, curvature_1pm`` (the layout ``hevsim lap CONFIG FILE`` reads, like a track of
your own): one row at the start of each straight or arc and one 1 micrometre before its end
(``hevsim.tracks.segment_rows``), plus a plot per track; every file is read back and checked
to close.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from hevsim import tracks


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="examples/tracks", help="folder to write into")
    a = ap.parse_args()
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    for name in ("skidpad", "oval", "handling"):
        t = tracks.load_track(name)
        d, k = tracks.segment_rows(tracks.geometry(name))
        path = out / f"{name}.csv"
        rows = "\n".join(f"{a:.10f},{b:.12g}" for a, b in zip(d, k, strict=True))
        path.write_text("distance_m,curvature_1pm\n" + rows + "\n", encoding="utf-8")
        back = tracks.load_track_csv(path, step_m=1.0)
        assert abs(back.length_m - t.length_m) < 1e-6
        t.plot(out / f"{name}.png")
        print(f"{path}: {t.length_m:.2f} m, {len(d)} rows, read back {back.length_m:.2f} m; {t.source}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
