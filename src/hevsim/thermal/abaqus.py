"""Import of Abaqus/Standard and CalculiX heat-transfer input decks (``.inp``).

A deck is read as Abaqus/CAE or CalculiX write it, and the importer never changes a model
silently: what it reads is applied, a keyword whose omission would change the heat-transfer
physics is refused (:class:`~hevsim.errors.InputError`, exit 2, with its line), and every
other keyword it does not use is listed in :attr:`AbaqusModel.unsupported` with its line.

Read and applied:

- geometry: *Node, *Element (C3D4 / DC3D4 / C3D4T linear tetrahedra), *Part ... *End Part
  (nodes and elements numbered locally from 1 in every part), *Assembly with *Instance
  (``part=``; first data line a translation, optional second line a rotation about the axis
  through points a and b by an angle in degrees, right-hand rule about a -> b, applied after
  the translation; Abaqus Keywords Reference, *INSTANCE). A part placed by several instances
  gives several copies. A flat deck (no *Part) and parts without any *Instance are placed
  once as they are. *Include, input= is read in place.
- sets and surfaces: *Nset / *Elset (``generate``, ``internal``, ``instance=`` at assembly
  level, members given by number or by set name), *Surface type=ELEMENT (faces S1-S4; a
  member is an element set or an element number). Names are case-insensitive (as in Abaqus);
  a part-level name is local to its part and reached from the assembly as ``INSTANCE.NAME``
  (``PLATE-1._BOT_S1``), an element of an instance as ``INSTANCE.12``.
- materials: *Solid Section (one thermal part per instance and section), *Material with
  *Conductivity (isotropic), *Density, *Specific Heat: constant, or tables of (value,
  temperature) rows, linear between rows and constant beyond them (Abaqus's interpolation;
  :class:`~hevsim.thermal.materials.Material` tables, temperatures in K). A deck with
  temperature-dependent properties runs with
  :class:`~hevsim.thermal.solver.NonlinearHeatModel`; the linear
  :class:`~hevsim.thermal.solver.HeatModel` refuses it. ``type=ORTHO/ANISO`` with unequal
  components are refused (the FEM solver is isotropic).
- contact: *Contact Pair, interaction=NAME (slave, master surfaces) with the *Surface
  Interaction's *Gap Conductance table of (conductance, clearance[, temperature]) rows (a blank
  field is zero, as in Abaqus). Surfaces that coincide node for node (parts meshed with
  matching faces) have their nodes merged and get the solver's consistent contact conductance
  at zero clearance; other surfaces get node-to-surface contact (:class:`SurfaceContact`):
  each slave node exchanges heat with the nearest point of the master surface with the
  table's conductance at that clearance (linear, constant beyond the ends). Pressure- or
  temperature-dependent conductance is refused.
- loads and conditions: *Initial Conditions, type=TEMPERATURE (node set or node number),
  *Dflux BF (body flux per element set or element; each becomes one heat-source "cell"; with
  ``amplitude=``), *Amplitude (tabular, linear between points, last value held),
  *Film (element faces F1-F4) and *Sfilm (surfaces) with a film coefficient and a sink
  temperature, each constant or scaled in time by an amplitude (Abaqus Keywords Reference,
  *FILM / *SFILM: ``amplitude=`` - ``sink amplitude=`` on *Sfilm in recent releases - scales
  the sink temperature as written in the deck, ``film amplitude=`` the film coefficient;
  CalculiX *FILM reads the same two), one *Step with *Heat Transfer (transient: initial
  increment and time period). :meth:`AbaqusModel.set_loads` applies the loads of a time to a
  :class:`~hevsim.thermal.solver.HeatModel`.

Refused (they change the physics and the solver has no equivalent here): *Boundary (fixed
temperature), *Cflux, *Dsflux, *Dflux face fluxes (S1-S4), *Radiate/*Sradiate, *Tie,
*Heat Generation, *Latent Heat, *Gap Conductance with pressure, films with a time delay,
*Step amplitude=RAMP, *Heat Transfer steady state, more than one *Step, elements other than linear tetrahedra.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hevsim.errors import ConfigError, InputError
from hevsim.thermal.materials import Material
from hevsim.thermal.mesh import DEGENERATE_RELATIVE_VOLUME, ThermalMesh, tet_volumes_m3

#: Node order of faces S1..S4 of a 4-node tetrahedron (Abaqus Analysis User's Guide).
TET_FACES = {"S1": (0, 1, 2), "S2": (0, 3, 1), "S3": (1, 3, 2), "S4": (2, 3, 0)}
_TET_TYPES = {"C3D4", "DC3D4", "C3D4T"}
#: Keywords that do not change a transient heat-transfer solution (output, descriptions).
_ACCEPTED = {
    "heading", "preprint", "output", "node output", "element output", "contact output",
    "energy output", "restart", "monitor", "node print", "el print", "node file", "el file",
    "contact print", "contact file", "print", "file format", "end step", "end part",
    "end assembly", "end instance", "diagnostics", "controls",
}  # fmt: skip
#: Keywords refused: ignoring them would change the heat-transfer physics.
_REFUSED = {
    "boundary": "fixed temperatures",
    "cflux": "concentrated heat fluxes",
    "dsflux": "distributed surface heat fluxes",
    "radiate": "radiation",
    "sradiate": "radiation",
    "tie": "tied surfaces",
    "heat generation": "heat generation",
    "latent heat": "latent heat",
    "coupled temperature-displacement": "a coupled analysis",
    "static": "a stress step",
    "clearance": "contact clearances",
    "contact clearance": "contact clearances",
    "gap radiation": "gap radiation",
    "thermal contact property": "contact properties",
}
#: Keywords the importer reads (see the module docstring).
_READ = {
    "node", "element", "elset", "nset", "part", "assembly", "instance", "solid section",
    "material", "conductivity", "density", "specific heat", "initial conditions", "surface",
    "surface interaction", "gap conductance", "contact pair", "dflux", "film", "sfilm",
    "amplitude", "step", "heat transfer", "include",
}  # fmt: skip


@dataclass(frozen=True)
class SurfaceContact:
    """A contact pair whose surfaces are not meshed node for node: every slave node exchanges
    ``h(d) a_s (T_s - T_m)`` with the point of the master surface nearest to it (``d``: the
    clearance to it, ``a_s``: the slave node's share of the slave area, ``T_m``: the master
    temperature interpolated there) - Abaqus's node-to-surface thermal contact."""

    name: str
    slave_tris: np.ndarray  # (K, 3) mesh nodes
    slave_part: np.ndarray  # (K,) part of each slave triangle
    master_tris: np.ndarray  # (M, 3)
    master_part: np.ndarray  # (M,)
    clearance_m: np.ndarray  # gap conductance table: clearance [m] (increasing) ...
    conductance_w_m2k: np.ndarray  # ... and conductance [W/(m^2 K)]

    def matrix(self, disc: Any, part_names: tuple[str, ...]) -> Any:
        """The contact conductance matrix [W/K] on the split nodes of ``disc``."""
        import scipy.sparse as sp

        from hevsim.thermal.mesh import triangle_areas_m2

        nparts = len(part_names)
        keys = disc.original_node.astype(np.int64) * nparts + disc.node_part
        s_split = np.searchsorted(keys, self.slave_tris * nparts + self.slave_part[:, None])
        m_split = np.searchsorted(keys, self.master_tris * nparts + self.master_part[:, None])
        pts = disc.points_m
        area = np.zeros(pts.shape[0])
        np.add.at(area, s_split.ravel(), np.repeat(triangle_areas_m2(pts, s_split) / 3.0, 3))
        nodes = np.unique(s_split)
        tri, bary, dist = _nearest_on_triangles(
            pts[nodes], pts[m_split[:, 0]], pts[m_split[:, 1]], pts[m_split[:, 2]]
        )
        h = np.interp(dist, self.clearance_m, self.conductance_w_m2k) * area[nodes]
        idx = np.column_stack([nodes, m_split[tri]])  # (S, 4)
        coef = np.column_stack([np.ones(nodes.size), -bary])  # (S, 4)
        rows = np.repeat(idx, 4, axis=1).ravel()
        cols = np.tile(idx, (1, 4)).ravel()
        vals = (h[:, None, None] * coef[:, :, None] * coef[:, None, :]).ravel()
        n = pts.shape[0]
        return sp.csr_matrix((vals, (rows, cols)), shape=(n, n))


def _nearest_on_triangles(
    p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray, candidates: int = 12
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For every point of ``p`` the nearest triangle (a, b, c) among the ``candidates`` with the
    nearest centroids: its index, the barycentric coordinates of the nearest point and the
    distance [m]."""
    from scipy.spatial import cKDTree

    k = min(candidates, a.shape[0])
    _, cand = cKDTree((a + b + c) / 3.0).query(p, k=k)
    cand = np.asarray(cand).reshape(p.shape[0], k)
    best_d = np.full(p.shape[0], np.inf)
    best_t = np.zeros(p.shape[0], dtype=np.int64)
    best_w = np.zeros((p.shape[0], 3))
    for col in range(k):
        t = cand[:, col]
        w, d = _closest_point(p, a[t], b[t], c[t])
        better = d < best_d
        best_d[better], best_t[better], best_w[better] = d[better], t[better], w[better]
    return best_t, best_w, best_d


def _closest_point(
    p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Barycentric coordinates (n, 3) of the point of each triangle nearest to ``p`` and the distance."""
    n = np.cross(b - a, c - a)
    nn = np.einsum("ij,ij->i", n, n)
    q = p - (np.einsum("ij,ij->i", p - a, n) / nn)[:, None] * n
    wa = np.einsum("ij,ij->i", np.cross(b - q, c - q), n) / nn
    wb = np.einsum("ij,ij->i", np.cross(c - q, a - q), n) / nn
    w = np.column_stack([wa, wb, 1.0 - wa - wb])
    inside = np.all(w >= -1e-12, axis=1)
    best_w = np.where(inside[:, None], np.clip(w, 0.0, 1.0), 0.0)
    best_w /= np.where(inside, best_w.sum(axis=1), 1.0)[:, None]
    best_d = np.where(inside, np.linalg.norm(p - q, axis=1), np.inf)
    for i0, i1 in ((0, 1), (1, 2), (2, 0)):
        e0, e1 = (a, b, c)[i0], (a, b, c)[i1]
        e = e1 - e0
        t = np.clip(np.einsum("ij,ij->i", p - e0, e) / np.einsum("ij,ij->i", e, e), 0.0, 1.0)
        d = np.linalg.norm(p - (e0 + t[:, None] * e), axis=1)
        better = ~inside & (d < best_d)
        we = np.zeros((p.shape[0], 3))
        we[:, i0], we[:, i1] = 1.0 - t, t
        best_w[better], best_d[better] = we[better], d[better]
    return best_w, best_d


@dataclass
class AbaqusModel:
    """What was read from a deck (SI units as in the deck; temperatures in °C).

    ``mesh``: nodes, tetrahedra, one part per instance and section, one "cell" per *Dflux set,
    named surfaces (deck surfaces by their upper-case name, films as ``FILM_<line>``).
    ``contact_w_m2k``: contact conductance per interface ``"partA|partB"`` from the contact
    pairs; ``bonded_interfaces``: interfaces where two sections share nodes (perfect contact in
    Abaqus). ``films``: surface -> (h [W/(m^2 K)], sink [°C]) as written in the deck (the
    reference values); ``film_amplitude``: surface -> (amplitude of the sink temperature,
    amplitude of the film coefficient), ``None`` where constant. ``node_temp_c``: initial
    temperature per mesh node (NaN where no *Initial Conditions). ``amplitudes``: name ->
    (time [s], factor) table; ``flux_amplitude``: *Dflux set -> amplitude name.
    """

    mesh: ThermalMesh
    materials: dict[str, Material]
    initial_temp_c: dict[str, float] = field(default_factory=dict)  # node set -> °C
    gap_conductance_w_m2k: float | None = None
    body_flux_w_m3: dict[str, float] = field(default_factory=dict)  # element set -> W/m^3
    unsupported: list[str] = field(default_factory=list)
    contact_w_m2k: dict[str, float] = field(default_factory=dict)
    bonded_interfaces: list[str] = field(default_factory=list)
    films: dict[str, tuple[float, float]] = field(default_factory=dict)
    node_temp_c: np.ndarray = field(default_factory=lambda: np.zeros(0))
    amplitudes: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    flux_amplitude: dict[str, str] = field(default_factory=dict)
    time_period_s: float | None = None
    initial_increment_s: float | None = None
    node_labels: list[str] = field(default_factory=list)
    element_labels: list[str] = field(default_factory=list)
    surface_contacts: list[SurfaceContact] = field(default_factory=list)
    film_amplitude: dict[str, tuple[str | None, str | None]] = field(default_factory=dict)
    deltmx_k: float | None = None  # automatic incrementation: largest change of an increment [K]
    min_increment_s: float | None = None
    max_increment_s: float | None = None
    heat_transfer_where: str = ""  # "file:line" of *Heat Transfer

    def check_increments(self) -> tuple[float, float, float, float]:
        """``(initial, period, minimum, maximum)`` increments [s] of the step (Abaqus's defaults:
        minimum ``min(initial, 1e-5 period)``, maximum the period); InputError naming the
        *Heat Transfer line when they are missing or inconsistent."""
        where = self.heat_transfer_where or self.mesh.source
        initial, period = self.initial_increment_s, self.time_period_s
        if initial is None or period is None:
            raise InputError(
                f"{where}: *Heat Transfer has no data line 'initial increment, time period'; expected "
                "both [s]."
            )
        lo = self.min_increment_s if self.min_increment_s is not None else min(initial, 1e-5 * period)
        hi = self.max_increment_s if self.max_increment_s is not None else period
        if not (0.0 < lo <= initial <= hi and 0.0 < period and np.isfinite(hi)):
            raise InputError(
                f"{where}: *Heat Transfer increments initial {initial:g} s, period {period:g} s, minimum "
                f"{lo:g} s, maximum {hi:g} s; expected 0 < minimum <= initial <= maximum and a positive "
                "period."
            )
        return initial, period, lo, hi

    def amplitude(self, name: str | None, time_s: float) -> float:
        """Factor of amplitude ``name`` at ``time_s`` (1 without amplitude)."""
        if name is None:
            return 1.0
        t, a = self.amplitudes[name]
        return float(np.interp(time_s, t, a))

    def cell_heat_w(self, cell_volume_m3: np.ndarray, time_s: float = 0.0) -> np.ndarray:
        """Heat of every *Dflux cell [W] at ``time_s``: body flux x meshed volume x amplitude."""
        flux = [
            self.body_flux_w_m3[s] * self.amplitude(self.flux_amplitude.get(s), time_s)
            for s in self.body_flux_w_m3
        ]
        return np.asarray(flux, dtype=float) * np.asarray(cell_volume_m3, dtype=float)

    def films_at(self, time_s: float) -> dict[str, tuple[float, float]]:
        """Every film at ``time_s``: surface -> (h [W/(m^2 K)], sink [°C]), the deck's values
        times their amplitudes (the sink temperature is scaled as written, in °C)."""
        out = {}
        for name, (h, sink) in self.films.items():
            a_sink, a_film = self.film_amplitude.get(name, (None, None))
            out[name] = (h * self.amplitude(a_film, time_s), sink * self.amplitude(a_sink, time_s))
        return out

    def set_loads(self, model: Any, time_s: float) -> None:
        """Give ``model`` (a :class:`~hevsim.thermal.solver.HeatModel` of :meth:`discretise`)
        the deck's loads at ``time_s`` [s]: the *Dflux heat of every cell and the films that
        have an amplitude. Call it with the time at the end of the next step (implicit Euler
        evaluates the loads there): ``set_loads(model, model.time_s + model.dt_s)``."""
        if self.body_flux_w_m3:
            model.set_cell_heat_w(self.cell_heat_w(model.disc.cell_volume_m3, time_s))
        now = self.films_at(time_s)
        for name in self.film_amplitude:
            h, sink_c = now[name]
            model.set_surface_film(name, h, sink_c + 273.15)

    def discretise(self, *, bonded_w_m2k: float | None = None, **kw: Any) -> Any:
        """:func:`hevsim.thermal.solver.discretise` of the deck: its materials, contact pairs,
        films (temperatures in K) and no film elsewhere (adiabatic, as in Abaqus).

        Abaqus conducts perfectly where two sections share nodes; the solver puts a contact
        conductance there: give it as ``bonded_w_m2k`` when the deck has such interfaces."""
        from hevsim.thermal.solver import discretise

        if self.bonded_interfaces and bonded_w_m2k is None:
            raise ConfigError(
                f"{self.mesh.source}: sections share nodes at {self.bonded_interfaces} (perfect "
                "contact in Abaqus); expected bonded_w_m2k, the conductance [W/(m^2 K)] to use there."
            )
        import dataclasses

        films = {k: (h, t + 273.15) for k, (h, t) in self.films_at(0.0).items()}
        disc = discretise(
            self.mesh,
            self.materials,
            gap_conductance_w_m2k=1.0 if bonded_w_m2k is None else bonded_w_m2k,
            interface_conductance_w_m2k=self.contact_w_m2k,
            film_w_m2k=0.0,
            surface_films=films,
            **kw,
        )
        for sc in self.surface_contacts:  # contact between surfaces not meshed node for node
            disc = dataclasses.replace(
                disc, stiffness=(disc.stiffness + sc.matrix(disc, self.mesh.part_names)).tocsr()
            )
        return disc

    def initial_temp_k(self, disc: Any) -> np.ndarray:
        """Initial temperature [K] of every node of ``disc`` (a discretisation of :attr:`mesh`)."""
        t = self.node_temp_c[disc.original_node]
        if np.isnan(t).any():
            first = self.node_labels[int(disc.original_node[np.flatnonzero(np.isnan(t))[0]])]
            raise InputError(
                f"{self.mesh.source}: {int(np.isnan(self.node_temp_c).sum())} nodes (first {first}) have "
                "no *Initial Conditions, type=TEMPERATURE; expected a temperature for every node."
            )
        return t + 273.15


# ---------------------------------------------------------------------------- reading
@dataclass
class _Line:
    src: str
    no: int
    text: str

    def where(self) -> str:
        return f"{self.src}: line {self.no}"


def _read_lines(path: Path, depth: int = 0) -> list[_Line]:
    """Lines of ``path`` with *Include files read in place."""
    if depth > 10:
        raise InputError(f"{path}: *Include nested more than 10 deep.")
    out: list[_Line] = []
    for no, raw in enumerate(path.read_text(encoding="utf-8", errors="replace").splitlines(), 1):
        line = raw.strip()
        if not line or line.startswith("**"):
            continue
        if line.startswith("*"):
            kw, opts = _options(line)
            if kw == "include":
                name = opts.get("INPUT", "")
                inc = (path.parent / name) if name else path.parent
                if not name or not inc.is_file():
                    raise InputError(
                        f"{path}: line {no}: *Include file {name!r} not found; "
                        "expected a file next to the deck."
                    )
                out.extend(_read_lines(inc, depth + 1))
                continue
        out.append(_Line(str(path), no, line))
    return out


def _options(line: str) -> tuple[str, dict[str, str]]:
    """Keyword (lower case) and options (upper-case keys, values as written, quotes removed)."""
    parts = [p.strip() for p in line[1:].split(",")]
    opts = {}
    for p in parts[1:]:
        if not p:
            continue
        k, _, v = p.partition("=")
        opts[k.strip().upper()] = v.strip().strip('"')
    return " ".join(parts[0].lower().split()), opts


def _fields(text: str) -> list[str]:
    """Data fields of a line; a trailing comma gives no field, a blank field inside is ''."""
    vals = [v.strip().strip('"') for v in text.split(",")]
    while vals and vals[-1] == "":
        vals.pop()
    return vals


def _num(v: str) -> float:
    """A numeric field; blank is zero (Abaqus)."""
    return 0.0 if v == "" else float(v)


def _is_int(v: str) -> bool:
    try:
        int(v)
    except ValueError:
        return False
    return True


def _rotate(points: np.ndarray, a: np.ndarray, b: np.ndarray, angle_deg: float) -> np.ndarray:
    """Rotate ``points`` about the axis a -> b by ``angle_deg`` (right-hand rule, Rodrigues)."""
    axis = b - a
    norm = float(np.linalg.norm(axis))
    if norm == 0.0:
        raise ValueError("rotation axis points a and b coincide")
    k = axis / norm
    th = np.radians(angle_deg)
    v = points - a
    rot = v * np.cos(th) + np.cross(k, v) * np.sin(th) + np.outer(v @ k, k) * (1.0 - np.cos(th))
    return rot + a


@dataclass
class _Scope:
    """A part (local numbering) or the assembly: its sets and surfaces by upper-case name."""

    name: str
    nodes: dict[int, tuple[float, float, float]] = field(default_factory=dict)
    elements: dict[int, tuple[int, int, int, int]] = field(default_factory=dict)
    element_line: dict[int, str] = field(default_factory=dict)
    # set name -> [(member, instance option or "", where)]
    elsets: dict[str, list[tuple[str, str, str]]] = field(default_factory=dict)
    nsets: dict[str, list[tuple[str, str, str]]] = field(default_factory=dict)
    surfaces: dict[str, list[tuple[str, str, str]]] = field(default_factory=dict)  # member, face
    sections: list[tuple[str, str, str]] = field(default_factory=list)  # elset, material, where
    display: dict[str, str] = field(default_factory=dict)


@dataclass
class _Instance:
    name: str  # as written
    part: _Scope
    data: list[list[float]]
    where: str
    auto: bool = False  # placed implicitly (flat deck or parts without *Instance)


class _Deck:
    """Parse state and name resolution."""

    def __init__(self, src: str) -> None:
        self.src = src
        self.parts: dict[str, _Scope] = {}
        self.top = _Scope("")  # flat deck: nodes, elements and sets outside *Part
        self.assembly = _Scope("assembly")
        self.instances: dict[str, _Instance] = {}
        self.node_index: dict[tuple[str, int], int] = {}
        self.elem_index: dict[tuple[str, int], int] = {}
        self.tets = np.zeros((0, 4), dtype=np.int64)

    # -- name resolution (after numbering) ------------------------------------------------------
    def _inst_of(self, scope: _Scope) -> list[str]:
        return [k for k, i in self.instances.items() if i.part is scope]

    def _local(self, scope: _Scope, kind: str, name: str, where: str, seen: frozenset[str]) -> set[int]:
        """Local labels of set ``name`` of ``scope`` (a part or the top level)."""
        table = scope.elsets if kind == "elset" else scope.nsets
        key = name.upper()
        if key in seen:
            raise InputError(f"{where}: {kind} '{name}' refers to itself.")
        if key not in table:
            raise InputError(
                f"{where}: {kind} '{name}' is not defined"
                + (f" in part '{scope.name}'" if scope.name else "")
                + f"; expected one of {sorted(scope.display.get(k, k) for k in table) or '(none)'}."
            )
        out: set[int] = set()
        for member, _, w in table[key]:
            if _is_int(member):
                out.add(int(member))
            else:
                out |= self._local(scope, kind, member, w, seen | {key})
        return out

    def _global(self, inst: str, kind: str, labels: set[int], where: str) -> list[int]:
        index = self.elem_index if kind == "elset" else self.node_index
        try:
            return sorted(index[(inst, lab)] for lab in labels)
        except KeyError as exc:
            what = "element" if kind == "elset" else "node"
            raise InputError(
                f"{where}: {what} {exc.args[0][1]} is not defined"
                + (f" in instance '{self.instances[inst].name}'" if inst in self.instances else "")
                + "."
            ) from exc

    def resolve(self, kind: str, ref: str, where: str, seen: frozenset[str] = frozenset()) -> list[int]:
        """Global element (``kind`` = "elset") or node ("nset") indices of a model-level
        reference: a set name, ``INSTANCE.SET``, a number or ``INSTANCE.NUMBER``."""
        key = ref.upper()
        inst, dot, rest = key.partition(".")
        if dot and inst in self.instances:
            scope = self.instances[inst].part
            labels = {int(rest)} if _is_int(rest) else self._local(scope, kind, rest, where, frozenset())
            return self._global(inst, kind, labels, where)
        if _is_int(key):
            flat = self._flat_instance(where, ref)
            return self._global(flat, kind, {int(key)}, where)
        table = self.assembly.elsets if kind == "elset" else self.assembly.nsets
        if key in table:
            if key in seen:
                raise InputError(f"{where}: {kind} '{ref}' refers to itself.")
            out: set[int] = set()
            for member, member_inst, w in table[key]:
                if member_inst:
                    mi = member_inst.upper()
                    if mi not in self.instances:
                        raise InputError(f"{w}: instance '{member_inst}' is not defined.")
                    scope = self.instances[mi].part
                    labels = (
                        {int(member)} if _is_int(member) else self._local(scope, kind, member, w, frozenset())
                    )
                    out |= set(self._global(mi, kind, labels, w))
                else:
                    out |= set(self.resolve(kind, member, w, seen | {key}))
            return sorted(out)
        # a flat deck, or parts placed without instances: their own names are visible
        owners = [k for k, i in self.instances.items() if key in getattr(i.part, kind + "s")]
        if len(owners) == 1:
            scope = self.instances[owners[0]].part
            return self._global(owners[0], kind, self._local(scope, kind, ref, where, frozenset()), where)
        if len(owners) > 1:
            raise InputError(
                f"{where}: {kind} '{ref}' is defined in several instances "
                f"({', '.join(self.instances[o].name for o in owners)}); expected INSTANCE.{ref}."
            )
        known = sorted(self.assembly.display.get(k, k) for k in table)
        raise InputError(
            f"{where}: {kind} '{ref}' is not defined; expected a set name "
            f"({', '.join(known) or 'none at assembly level'}), INSTANCE.NAME or a number."
        )

    def _flat_instance(self, where: str, ref: str) -> str:
        if len(self.instances) != 1:
            raise InputError(
                f"{where}: number {ref} is ambiguous with {len(self.instances)} instances; "
                "expected INSTANCE.NUMBER."
            )
        return next(iter(self.instances))

    def surface(self, ref: str, where: str) -> np.ndarray:
        """Triangles (K, 3) of global node indices of surface ``ref`` (model-level name or
        ``INSTANCE.SURFACE``)."""
        key = ref.upper()
        inst, dot, rest = key.partition(".")
        if dot and inst in self.instances:
            scope = self.instances[inst].part
            if rest not in scope.surfaces:
                raise InputError(f"{where}: surface '{ref}' is not defined in part '{scope.name}'.")
            return self._faces(scope.surfaces[rest], lambda m, w: self.resolve("elset", f"{inst}.{m}", w))
        if key in self.assembly.surfaces:
            return self._faces(self.assembly.surfaces[key], lambda m, w: self.resolve("elset", m, w))
        owners = [k for k, i in self.instances.items() if key in i.part.surfaces]
        if len(owners) == 1:
            return self.surface(f"{owners[0]}.{key}", where)
        known = sorted(self.assembly.display.get(k, k) for k in self.assembly.surfaces)
        raise InputError(
            f"{where}: surface '{ref}' is not defined; expected one of {known or '(none)'} or "
            "INSTANCE.SURFACE."
        )

    def _faces(self, entries: list[tuple[str, str, str]], elems: Any) -> np.ndarray:
        tris = []
        for member, face, w in entries:
            if face not in TET_FACES:
                raise InputError(
                    f"{w}: surface face {face!r} of '{member}'; expected one of S1-S4 (element faces)."
                )
            rows = np.asarray(elems(member, w), dtype=np.int64)
            tris.append(self.tets[rows][:, list(TET_FACES[face])])
        return np.vstack(tris) if tris else np.zeros((0, 3), dtype=np.int64)


def _property(
    rows: list[tuple[list[str], str]], what: str, material: str
) -> tuple[float, tuple[tuple[float, float], ...]]:
    """A material property: ``(value, ())`` for one row or rows that all give the same value,
    else ``(value at the lowest temperature, ((T [K], value), ...))`` from rows (value,
    temperature [°C]) - linear between rows and constant beyond them, as in Abaqus."""
    if not rows:
        raise ValueError(what)
    values = {_num(r[0]) for r, _ in rows}
    if len(values) == 1:
        return values.pop(), ()
    table: list[tuple[float, float]] = []
    for r, w in rows:
        if len(r) < 2 or r[1] == "":
            raise InputError(
                f"{w}: material '{material}' *{what} row {r} has no temperature; expected "
                "'value, temperature' on every row of a temperature-dependent table."
            )
        table.append((_num(r[1]) + 273.15, _num(r[0])))
    table.sort()
    temps = [t for t, _ in table]
    if len(set(temps)) < len(temps):
        raise InputError(
            f"{rows[0][1]}: material '{material}' *{what} lists a temperature twice; expected one "
            "value per temperature."
        )
    if any(v <= 0.0 for _, v in table):
        raise InputError(f"{rows[0][1]}: material '{material}' *{what} values {values}; expected > 0.")
    return table[0][1], tuple(table)


def read_abaqus_inp(path: str | Path, *, length_scale_m: float = 1.0) -> AbaqusModel:
    """Read an ``.inp`` deck; coordinates are multiplied by ``length_scale_m`` (1e-3 for mm decks)."""
    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: Abaqus input file not found.")
    src = str(p)
    deck = _Deck(src)
    materials: dict[str, dict[str, list[tuple[list[str], str]]]] = {}
    mat_display: dict[str, str] = {}
    interactions: dict[str, list[tuple[float, float, float | None, str]]] = {}
    pairs: list[tuple[str, str, str, str]] = []  # slave, master, interaction, where
    initial: list[tuple[str, float, str]] = []
    dflux: list[tuple[str, float, str | None, str]] = []
    # ref, face, sink, h, where, sink amplitude, film amplitude
    films: list[tuple[str, str, float, float, str, str | None, str | None]] = []
    amplitudes: dict[str, tuple[list[float], str]] = {}
    unsupported: list[str] = []
    steps: list[str] = []
    heat_transfer: list[float] = []
    heat_transfer_where = ""
    deltmx_k: float | None = None
    scope: _Scope = deck.top
    instance: _Instance | None = None
    opts: dict[str, str] = {}
    kw, material, interaction, amp = "", "", "", ""
    where = src
    for ln in _read_lines(p):
        where = ln.where()
        if ln.text.startswith("*"):
            kw, opts = _options(ln.text)
            title = ln.text[1:].split(",")[0].strip()
            if kw in _REFUSED:
                raise InputError(
                    f"{where}: *{title} ({_REFUSED[kw]}) is not supported; ignoring it would change "
                    "the heat-transfer solution: remove it or model it another way."
                )
            if kw not in _READ:
                if kw not in _ACCEPTED:
                    unsupported.append(f"line {ln.no}: *{title} (ignored)")
                if kw == "end part":
                    scope = deck.top
                elif kw == "end assembly":
                    scope = deck.top
                elif kw == "end instance":
                    instance = None
                    scope = deck.assembly
                continue
            if kw == "element" and opts.get("TYPE", "").upper() not in _TET_TYPES:
                raise InputError(
                    f"{where}: element type {opts.get('TYPE')!r} is not supported; "
                    f"expected one of {sorted(_TET_TYPES)} (linear tetrahedra)."
                )
            if kw in ("node", "element") and scope is deck.assembly:
                raise InputError(
                    f"{where}: *{title} at assembly level (reference points or instance meshes) "
                    "is not supported; expected nodes and elements inside *Part."
                )
            if kw == "part":
                name = opts.get("NAME", "")
                if name.upper() in deck.parts:
                    raise InputError(f"{where}: *Part '{name}' is defined twice.")
                scope = deck.parts[name.upper()] = _Scope(name)
            elif kw == "assembly":
                scope = deck.assembly
            elif kw == "instance":
                name, part_opt = opts.get("NAME", ""), opts.get("PART", "")
                if part_opt.upper() not in deck.parts:
                    raise InputError(
                        f"{where}: *Instance '{name}' places part '{part_opt}' which is not defined "
                        f"(before it); expected one of {[s.name for s in deck.parts.values()]}."
                    )
                if name.upper() in deck.instances:
                    raise InputError(f"{where}: *Instance '{name}' is defined twice.")
                instance = _Instance(name, deck.parts[part_opt.upper()], [], where)
                deck.instances[name.upper()] = instance
            elif kw in ("elset", "nset"):
                name = opts.get(kw.upper(), "")
                getattr(scope, kw + "s").setdefault(name.upper(), [])
                scope.display.setdefault(name.upper(), name)
                if "INSTANCE" in opts and scope is not deck.assembly:
                    raise InputError(f"{where}: *{title}, instance= outside *Assembly.")
            elif kw == "surface":
                if opts.get("TYPE", "ELEMENT").upper() != "ELEMENT":
                    raise InputError(
                        f"{where}: *Surface type={opts.get('TYPE')} is not supported; expected "
                        "type=ELEMENT (element faces S1-S4)."
                    )
                name = opts.get("NAME", "")
                scope.surfaces[name.upper()] = []
                scope.display.setdefault(name.upper(), name)
            elif kw == "solid section":
                scope.sections.append((opts.get("ELSET", ""), opts.get("MATERIAL", ""), where))
            elif kw == "material":
                material = opts.get("NAME", "").upper()
                materials[material] = {}
                mat_display[material] = opts.get("NAME", "")
            elif kw in ("conductivity", "density", "specific heat"):
                if not material:
                    raise InputError(f"{where}: *{title} outside a *Material.")
                if kw == "conductivity" and opts.get("TYPE", "ISO").upper() not in ("ISO", "ORTHO", "ANISO"):
                    raise InputError(f"{where}: *Conductivity type={opts.get('TYPE')}; expected ISO.")
                if opts.get("DEPENDENCIES", "0") not in ("", "0"):
                    raise InputError(
                        f"{where}: *{title} with dependencies= (field variables) is not supported; "
                        "expected constant properties."
                    )
                materials[material][kw] = []
            elif kw == "surface interaction":
                interaction = opts.get("NAME", "").upper()
                interactions.setdefault(interaction, [])
            elif kw == "gap conductance":
                if "PRESSURE" in opts:
                    raise InputError(
                        f"{where}: *Gap Conductance, pressure (conductance by contact pressure) is not "
                        "supported; expected conductance by clearance."
                    )
                if not interaction:
                    raise InputError(f"{where}: *Gap Conductance outside a *Surface Interaction.")
                if opts.get("DEPENDENCIES", "0") not in ("", "0") or "USER" in opts:
                    raise InputError(f"{where}: *Gap Conductance with dependencies/user is not supported.")
            elif kw == "contact pair":
                interaction_name = opts.get("INTERACTION", "")
                if not interaction_name:
                    raise InputError(f"{where}: *Contact Pair without interaction=.")
            elif kw == "amplitude":
                amp = opts.get("NAME", "").upper()
                definition = opts.get("DEFINITION", "TABULAR").upper()
                if definition != "TABULAR" or opts.get("TIME", "STEP TIME").upper() != "STEP TIME":
                    raise InputError(
                        f"{where}: *Amplitude '{opts.get('NAME')}' definition={definition} "
                        f"time={opts.get('TIME', 'STEP TIME')} is not supported; expected a TABULAR "
                        "amplitude in STEP TIME."
                    )
                if "VALUE" in opts and opts["VALUE"].upper() != "RELATIVE":
                    raise InputError(f"{where}: *Amplitude value=ABSOLUTE is not supported.")
                amplitudes[amp] = ([], where)
            elif kw == "step":
                steps.append(where)
                if opts.get("AMPLITUDE", "STEP").upper() != "STEP":
                    raise InputError(
                        f"{where}: *Step, amplitude={opts['AMPLITUDE']}: loads without their own "
                        "amplitude would ramp over the step from zero; expected amplitude=STEP (the "
                        "default of a transient *Heat Transfer: loads applied at the step's start) or "
                        "an *Amplitude on each load."
                    )
                if len(steps) > 1:
                    raise InputError(
                        f"{where}: a second *Step; expected one heat-transfer step (the loads of the "
                        "steps would be merged)."
                    )
            elif kw == "heat transfer":
                if "STEADY STATE" in opts:
                    raise InputError(
                        f"{where}: *Heat Transfer, steady state; expected a transient step "
                        "(use HeatModel.steady for a steady solution)."
                    )
                heat_transfer_where = where
                if opts.get("END", "PERIOD").upper() != "PERIOD":
                    raise InputError(
                        f"{where}: *Heat Transfer, end={opts['END']} (end at a steady state) is not "
                        "supported; expected end=PERIOD (the step runs its time period)."
                    )
                unknown = sorted(k for k in opts if k not in _HEAT_TRANSFER_OPTIONS)
                if unknown:
                    raise InputError(
                        f"{where}: *Heat Transfer, {unknown[0].lower()}= is not supported; expected "
                        f"only {', '.join(o.lower() for o in _HEAT_TRANSFER_OPTIONS)}."
                    )
                direct = "DIRECT" in opts
                if "DELTMX" in opts and not direct:
                    try:
                        deltmx = float(opts["DELTMX"].replace("d", "e").replace("D", "e"))
                    except ValueError:
                        deltmx = float("nan")
                    if not (np.isfinite(deltmx) and deltmx >= 0.0):
                        raise InputError(
                            f"{where}: *Heat Transfer, deltmx={opts['DELTMX']}; expected the largest "
                            "temperature change of an increment [K], a number >= 0."
                        )
                    deltmx_k = deltmx if deltmx > 0.0 else None  # 0: fixed increments, as Abaqus
            elif kw == "initial conditions" and opts.get("TYPE", "").upper() != "TEMPERATURE":
                unsupported.append(f"line {ln.no}: *Initial Conditions type={opts.get('TYPE')} (ignored)")
            elif kw in ("film", "sfilm"):
                delayed = sorted(k for k in opts if "TIME DELAY" in k)
                if delayed:
                    raise InputError(
                        f"{where}: *{title}, {delayed[0].lower()}= is not supported; expected the "
                        "amplitudes to start at the step's start."
                    )
            continue
        vals = _fields(ln.text)
        try:
            if kw == "node":
                label = int(vals[0])
                if label in scope.nodes:
                    raise InputError(
                        f"{where}: node {label} is defined twice"
                        + (f" in part '{scope.name}'" if scope.name else "")
                        + "; expected unique node numbers."
                    )
                scope.nodes[label] = (float(vals[1]), float(vals[2]), float(vals[3]))
                if "NSET" in opts:  # *Node, nset=NAME (as *Element, elset=)
                    name = opts["NSET"]
                    scope.nsets.setdefault(name.upper(), []).append((str(label), "", where))
                    scope.display.setdefault(name.upper(), name)
            elif kw == "instance":
                assert instance is not None
                if len(instance.data) >= 2:
                    raise ValueError("more than two data lines")
                expected = 3 if not instance.data else 7
                if len(vals) != expected:
                    raise ValueError(f"expected {expected} numbers, got {len(vals)}")
                instance.data.append([_num(v) for v in vals])
            elif kw == "element":
                e = [int(v) for v in vals]
                if len(e) != 5:
                    raise ValueError(f"expected an element number and 4 nodes, got {len(e)} numbers")
                if e[0] in scope.elements:
                    raise InputError(
                        f"{where}: element {e[0]} is defined twice"
                        + (f" in part '{scope.name}'" if scope.name else "")
                        + "; expected unique element numbers."
                    )
                scope.elements[e[0]] = (e[1], e[2], e[3], e[4])
                scope.element_line[e[0]] = where
                if "ELSET" in opts:
                    name = opts["ELSET"]
                    scope.elsets.setdefault(name.upper(), []).append((str(e[0]), "", where))
                    scope.display.setdefault(name.upper(), name)
            elif kw in ("elset", "nset"):
                target = getattr(scope, kw + "s")[opts.get(kw.upper(), "").upper()]
                inst_opt = opts.get("INSTANCE", "")
                if "GENERATE" in opts:
                    g0, g1, *step = (int(v) for v in vals)
                    target.extend(
                        (str(i), inst_opt, where) for i in range(g0, g1 + 1, step[0] if step else 1)
                    )
                else:
                    target.extend((v, inst_opt, where) for v in vals if v)
            elif kw in ("conductivity", "density", "specific heat"):
                if kw == "conductivity" and opts.get("TYPE", "ISO").upper() in ("ORTHO", "ANISO"):
                    n_comp = 3 if opts["TYPE"].upper() == "ORTHO" else 6
                    comp = [_num(v) for v in vals[:n_comp]]
                    off_diag = comp[3:]
                    if len(set(comp[:3])) != 1 or any(off_diag):
                        raise InputError(
                            f"{where}: material '{mat_display[material]}' *Conductivity, "
                            f"type={opts['TYPE']} {comp} is anisotropic; expected an isotropic "
                            "conductivity (the FEM solver is isotropic)."
                        )
                    vals = [vals[0], *vals[n_comp:]]
                materials[material][kw].append((vals, where))
            elif kw == "initial conditions" and opts.get("TYPE", "").upper() == "TEMPERATURE":
                initial.append((vals[0], float(vals[1]), where))
            elif kw == "surface":
                if len(vals) < 2:
                    raise InputError(
                        f"{where}: surface member {vals[0]!r} has no face; expected 'element set or "
                        "number, S1-S4'."
                    )
                scope.surfaces[opts.get("NAME", "").upper()].append((vals[0], vals[1].upper(), where))
            elif kw == "gap conductance":
                temp = _num(vals[2]) if len(vals) > 2 and vals[2] != "" else None
                interactions[interaction].append(
                    (_num(vals[0]), _num(vals[1]) if len(vals) > 1 else 0.0, temp, where)
                )
            elif kw == "contact pair":
                if len(vals) != 2:
                    raise ValueError("expected 'slave surface, master surface'")
                pairs.append((vals[0], vals[1], opts.get("INTERACTION", "").upper(), where))
            elif kw == "amplitude":
                amplitudes[amp][0].extend(_num(v) for v in vals)
            elif kw == "heat transfer":
                heat_transfer = [_num(v) for v in vals]
            elif kw == "dflux":
                load = vals[1].upper()
                if load != "BF":
                    raise InputError(
                        f"{where}: *Dflux load type {vals[1]} is not supported; expected BF (body flux "
                        "[W/m^3] over an element set or element)."
                    )
                amp_opt = opts.get("AMPLITUDE")
                dflux.append((vals[0], float(vals[2]), amp_opt.upper() if amp_opt else None, where))
            elif kw == "film":
                face = vals[1].upper()
                if face not in ("F1", "F2", "F3", "F4"):
                    raise InputError(
                        f"{where}: *Film load type {vals[1]}; expected F1-F4 (constant film on a face)."
                    )
                films.append((vals[0], "S" + face[1], _num(vals[2]), _num(vals[3]), where, *_film_amps(opts)))
            elif kw == "sfilm":
                if vals[1].upper() != "F":
                    raise InputError(f"{where}: *Sfilm load type {vals[1]}; expected F (constant film).")
                films.append((vals[0], "", _num(vals[2]), _num(vals[3]), where, *_film_amps(opts)))
        except (ValueError, IndexError) as exc:
            raise InputError(f"{where}: cannot read data line {ln.text!r} of *{kw} ({exc}).") from exc

    # ---- placement: every instance is a copy of its part ---------------------------------------
    explicit = bool(deck.instances)
    for key, prt in deck.parts.items():
        if not any(i.part is prt for i in deck.instances.values()):
            if explicit:
                unsupported.append(f"part '{prt.name}' has no *Instance (not in the model)")
            elif prt.nodes:
                deck.instances[key] = _Instance(prt.name, prt, [], src, auto=True)
    if deck.top.nodes or deck.top.elements:
        deck.instances[""] = _Instance("", deck.top, [], src, auto=True)
    points: list[np.ndarray] = []
    node_labels: list[str] = []
    elem_rows: list[tuple[str, int]] = []
    for ikey, inst in deck.instances.items():
        labels = sorted(inst.part.nodes)
        start = len(node_labels)
        xyz = np.array([inst.part.nodes[i] for i in labels], dtype=float).reshape(-1, 3)
        if inst.data:
            xyz = xyz + np.array(inst.data[0])
        if len(inst.data) == 2:
            r = inst.data[1]
            try:
                xyz = _rotate(xyz, np.array(r[0:3]), np.array(r[3:6]), r[6])
            except ValueError as exc:
                raise InputError(f"{inst.where}: *Instance '{inst.name}': {exc}.") from exc
        points.append(xyz)
        prefix = "" if inst.auto else f"{inst.name}."
        for j, lab in enumerate(labels):
            deck.node_index[(ikey, lab)] = start + j
            node_labels.append(f"{prefix}{lab}")
        for lab in sorted(inst.part.elements):
            elem_rows.append((ikey, lab))
    if not elem_rows:
        raise InputError(f"{src}: no *Element block of linear tetrahedra found.")
    pts = np.vstack(points) * length_scale_m
    tets = np.empty((len(elem_rows), 4), dtype=np.int64)
    element_labels: list[str] = []
    for row, (ikey, lab) in enumerate(elem_rows):
        inst = deck.instances[ikey]
        deck.elem_index[(ikey, lab)] = row
        prefix = "" if inst.auto else f"{inst.name}."
        element_labels.append(f"{prefix}{lab}")
        for c, nlab in enumerate(inst.part.elements[lab]):
            if (ikey, nlab) not in deck.node_index:
                raise InputError(
                    f"{inst.part.element_line[lab]}: element {lab} refers to node {nlab} which is not "
                    "defined" + (f" in part '{inst.part.name}'" if inst.part.name else "") + "."
                )
            tets[row, c] = deck.node_index[(ikey, nlab)]
    deck.tets = tets
    _check_orientation(src, pts, tets, element_labels, node_labels)

    # ---- sections -> thermal parts ---------------------------------------------------------------
    n_inst = sum(1 for i in deck.instances.values() if i.part.nodes)
    part = np.full(len(elem_rows), -1)
    part_names: list[str] = []
    mats: dict[str, Material] = {}
    jobs: list[tuple[str, str, str, str, _Instance | None]] = [
        (f"{ikey}.{elset}" if inst.part is not deck.top else elset, elset, mname, w, inst)
        for ikey, inst in deck.instances.items()
        for elset, mname, w in inst.part.sections
    ]
    if not any(i.part is deck.top for i in deck.instances.values()):
        jobs += [(elset, elset, mname, w, None) for elset, mname, w in deck.top.sections]
    for ref, elset, mname, w, owner in jobs:
        if mname.upper() not in materials:
            raise InputError(
                f"{w}: *Solid Section elset={elset} uses material '{mname}' which is not defined."
            )
        props = materials[mname.upper()]
        missing = [k for k in ("conductivity", "density", "specific heat") if not props.get(k)]
        if missing:
            raise InputError(
                f"{src}: material '{mname}' has no {', '.join(missing)}; expected *Conductivity, "
                "*Density and *Specific Heat for a transient heat analysis."
            )
        (k, cond_tab), (rho, rho_tab), (cp, cp_tab) = (
            _property(props[x], x.title(), mname) for x in ("conductivity", "density", "specific heat")
        )
        rows = np.asarray(deck.resolve("elset", ref, w), dtype=np.int64)
        if (part[rows] >= 0).any():
            raise InputError(f"{w}: *Solid Section elset={elset} overlaps another section.")
        shown = (owner.part if owner is not None else deck.top).display.get(elset.upper(), elset)
        if owner is None or n_inst == 1:
            name = shown
        elif len(owner.part.sections) == 1:
            name = owner.name
        else:
            name = f"{owner.name}.{shown}"
        if name in mats:
            raise InputError(f"{w}: thermal part name '{name}' is used twice; expected unique section sets.")
        part[rows] = len(part_names)
        part_names.append(name)
        mats[name] = Material(mat_display[mname.upper()], k, rho, cp, cond_tab, rho_tab, cp_tab)
    if (part < 0).any():
        first = element_labels[int(np.flatnonzero(part < 0)[0])]
        raise InputError(
            f"{src}: {int((part < 0).sum())} elements (first {first}) have no "
            "*Solid Section; expected every element to have a material."
        )

    # ---- loads --------------------------------------------------------------------------------------
    cell = np.full(len(elem_rows), -1)
    body_flux: dict[str, float] = {}
    flux_amp: dict[str, str] = {}
    for ref, value, a, w in dflux:
        rows = np.asarray(deck.resolve("elset", ref, w), dtype=np.int64)
        if ref in body_flux:
            raise InputError(f"{w}: *Dflux on '{ref}' a second time; expected one body flux per set.")
        if (cell[rows] >= 0).any():
            raise InputError(f"{w}: *Dflux set '{ref}' overlaps another *Dflux set; expected disjoint sets.")
        if a is not None:
            if a not in amplitudes:
                raise InputError(f"{w}: *Dflux amplitude '{a}' is not defined; expected an *Amplitude name.")
            flux_amp[ref] = a
        cell[rows] = len(body_flux)
        body_flux[ref] = value
    amps: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for name, (data, w) in amplitudes.items():
        arr = np.asarray(data, dtype=float)
        if arr.size < 2 or arr.size % 2 or np.any(np.diff(arr[0::2]) < 0):
            raise InputError(
                f"{w}: *Amplitude '{name}' has {arr.size} values; expected (time, value) pairs in "
                "increasing time."
            )
        amps[name] = (arr[0::2], arr[1::2])
    groups: dict[str, np.ndarray] = {}
    for skey in deck.assembly.surfaces:
        groups[deck.assembly.display.get(skey, skey)] = deck.surface(skey, src)
    for ikey, inst in deck.instances.items():
        for skey in inst.part.surfaces:
            shown = inst.part.display.get(skey, skey)
            gname = shown if n_inst == 1 else f"{inst.name}.{shown}"
            groups[gname] = deck.surface(f"{ikey}.{skey}" if ikey else skey, src)
    film_of: dict[str, tuple[float, float]] = {}
    film_amp: dict[str, tuple[str | None, str | None]] = {}
    for ref, face, sink, h, w, a_sink, a_film in films:
        for a in (a_sink, a_film):
            if a is not None and a not in amplitudes:
                raise InputError(f"{w}: film amplitude '{a}' is not defined; expected an *Amplitude name.")
        line = w.rsplit(" ", 1)[-1]
        if face:
            tris = deck.tets[np.asarray(deck.resolve("elset", ref, w), dtype=np.int64)][
                :, list(TET_FACES[face])
            ]
        else:
            tris = deck.surface(ref, w)
        gname = f"FILM_{line}_{len(film_of)}"
        groups[gname] = tris
        film_of[gname] = (h, sink)
        if a_sink is not None or a_film is not None:
            film_amp[gname] = (a_sink, a_film)
    node_temp = np.full(pts.shape[0], np.nan)
    initial_c: dict[str, float] = {}
    for ref, value, w in initial:
        node_temp[deck.resolve("nset", ref, w)] = value
        initial_c[ref] = value

    # ---- contact pairs: merge the coincident nodes of the two surfaces ----------------------------
    mesh_part = part.copy()
    contact: dict[str, float] = {}
    surface_contacts: list[SurfaceContact] = []
    merge = np.arange(pts.shape[0])
    first_gap: float | None = None
    for rows_ in interactions.values():
        if rows_ and first_gap is None:
            first_gap = _gap_at_zero(rows_)
    for slave, master, inter, w in pairs:
        if inter not in interactions:
            raise InputError(f"{w}: *Contact Pair interaction '{inter}' is not a *Surface Interaction.")
        if not interactions[inter]:
            unsupported.append(
                f"line {w.rsplit(' ', 1)[-1]}: *Contact Pair {slave}/{master} without *Gap Conductance "
                "(no heat crosses it, as in Abaqus)"
            )
            continue
        h = _gap_at_zero(interactions[inter])
        ts_, tm_ = deck.surface(slave, w), deck.surface(master, w)
        mapping = _match_surfaces(pts, ts_, tm_, w, slave, master)
        part_s, part_m = mesh_part[_tets_of_faces(tets, ts_)], mesh_part[_tets_of_faces(tets, tm_)]
        if mapping is None:  # not meshed node for node: node-to-surface contact by clearance
            d_tab, k_tab = _gap_table(interactions[inter])
            if set(part_s.tolist()) & set(part_m.tolist()):
                raise InputError(f"{w}: *Contact Pair {slave}/{master} within one part; expected two parts.")
            surface_contacts.append(
                SurfaceContact(f"{slave}/{master}", ts_, part_s, tm_, part_m, d_tab * length_scale_m, k_tab)
            )
            continue
        merge[list(mapping)] = list(mapping.values())
        parts_s, parts_m = set(part_s.tolist()), set(part_m.tolist())
        from hevsim.thermal.solver import interface_name

        for a in parts_s:
            for b in parts_m:
                if a == b:
                    raise InputError(
                        f"{w}: *Contact Pair {slave}/{master} within one part; expected two parts."
                    )
                nm = interface_name(part_names[a], part_names[b])
                if nm in contact and contact[nm] != h:
                    raise InputError(
                        f"{w}: interface {nm} gets gap conductance {h:g} and {contact[nm]:g}; expected one."
                    )
                contact[nm] = h
    tets = merge[tets]
    groups = {k: merge[v] for k, v in groups.items()}
    surface_contacts = [
        SurfaceContact(sc.name, merge[sc.slave_tris], sc.slave_part, merge[sc.master_tris], sc.master_part,
                       sc.clearance_m, sc.conductance_w_m2k)
        for sc in surface_contacts
    ]  # fmt: skip
    mesh = ThermalMesh(pts, tets, mesh_part, tuple(part_names), cell, groups, None, src).validate()
    bonded = _bonded(mesh, contact)
    model = AbaqusModel(
        mesh,
        mats,
        initial_c,
        first_gap,
        body_flux,
        unsupported,
        contact,
        bonded,
        film_of,
        node_temp,
        amps,
        flux_amp,
        heat_transfer[1] if len(heat_transfer) > 1 else None,
        heat_transfer[0] if heat_transfer else None,
        node_labels,
        element_labels,
        surface_contacts,
        film_amp,
        deltmx_k,
        heat_transfer[2] if len(heat_transfer) > 2 else None,
        heat_transfer[3] if len(heat_transfer) > 3 else None,
        heat_transfer_where,
    )
    if deltmx_k is not None:
        model.check_increments()
    return model


#: options of *Heat Transfer that are read (DELTMX: automatic incrementation; DIRECT: fixed
#: increments; END=PERIOD; MXDEM only limits radiation, which decks here cannot have)
_HEAT_TRANSFER_OPTIONS = ("DELTMX", "DIRECT", "END", "MXDEM")


def _film_amps(opts: dict[str, str]) -> tuple[str | None, str | None]:
    """(sink temperature amplitude, film coefficient amplitude) of a *Film / *Sfilm line:
    ``amplitude=`` (``sink amplitude=`` on *Sfilm) and ``film amplitude=``, upper case."""
    sink = opts.get("AMPLITUDE") or opts.get("SINK AMPLITUDE")
    film = opts.get("FILM AMPLITUDE")
    return (sink.upper() if sink else None, film.upper() if film else None)


def _gap_at_zero(rows: list[tuple[float, float, float | None, str]]) -> float:
    """Conductance of a *Gap Conductance table at zero clearance (constant beyond the ends)."""
    d, k = _gap_table(rows)
    h = float(np.interp(0.0, d, k))
    if not (np.isfinite(h) and h > 0.0):
        raise InputError(f"{rows[0][3]}: *Gap Conductance at zero clearance is {h!r}; expected > 0.")
    return h


def _gap_table(rows: list[tuple[float, float, float | None, str]]) -> tuple[np.ndarray, np.ndarray]:
    """(clearance, conductance) of a *Gap Conductance table, by increasing clearance."""
    temps = {t for _, _, t, _ in rows}
    if len(temps) > 1:
        raise InputError(
            f"{rows[0][3]}: *Gap Conductance depends on temperature ({sorted(t or 0.0 for t in temps)}); "
            "expected conductance by clearance only."
        )
    k = np.array([r[0] for r in rows])
    d = np.array([r[1] for r in rows])
    order = np.argsort(d, kind="stable")
    if np.any(np.diff(d[order]) == 0):
        raise InputError(f"{rows[0][3]}: *Gap Conductance lists a clearance twice; expected one value each.")
    if np.any(k < 0) or not np.all(np.isfinite(k)):
        raise InputError(f"{rows[0][3]}: *Gap Conductance values {k.tolist()}; expected finite values >= 0.")
    return d[order], k[order]


def _tets_of_faces(tets: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """Tetrahedra owning each triangle (by its node set)."""
    from hevsim.thermal.mesh import _FACES

    faces = np.sort(tets[:, _FACES].reshape(-1, 3), axis=1)
    lookup = {tuple(f): i // 4 for i, f in enumerate(faces.tolist())}
    return np.array([lookup[tuple(t)] for t in np.sort(tris, axis=1).tolist()], dtype=np.int64)


def _match_surfaces(
    pts: np.ndarray, slave: np.ndarray, master: np.ndarray, where: str, sname: str, mname: str
) -> dict[int, int] | None:
    """Slave node -> master node at the same position, every slave face being a master face;
    ``None`` when the surfaces are not meshed node for node."""
    from scipy.spatial import cKDTree

    if slave.size == 0 or master.size == 0:
        raise InputError(f"{where}: *Contact Pair {sname}/{mname}: a surface has no face.")
    s_nodes, m_nodes = np.unique(slave), np.unique(master)
    size = float(np.ptp(pts, axis=0).max()) or 1.0
    tol = 1e-8 * size
    dist, j = cKDTree(pts[m_nodes]).query(pts[s_nodes])
    if (dist > tol).any():
        return None
    mapping = dict(zip(s_nodes.tolist(), m_nodes[j].tolist(), strict=True))
    mapped = np.sort(np.vectorize(mapping.get)(slave), axis=1)
    master_set = {tuple(t) for t in np.sort(master, axis=1).tolist()}
    if any(tuple(t) not in master_set for t in mapped.tolist()):
        return None
    return mapping


def _bonded(mesh: ThermalMesh, contact: dict[str, float]) -> list[str]:
    """Interfaces between parts that share nodes without a contact pair."""
    from hevsim.thermal.mesh import mesh_faces
    from hevsim.thermal.solver import interface_name

    faces = mesh_faces(mesh.tets)
    inner = faces.other >= 0
    pa = mesh.part_of_tet[faces.owner[inner]]
    pb = mesh.part_of_tet[faces.other[inner]]
    names = {
        interface_name(mesh.part_names[a], mesh.part_names[b]) for a, b in zip(pa, pb, strict=True) if a != b
    }
    return sorted(names - set(contact))


def _check_orientation(
    src: str, pts: np.ndarray, tets: np.ndarray, element_labels: list[str], node_labels: list[str]
) -> None:
    """Refuse degenerate or inverted elements, naming the deck's element and node numbers."""
    vol = tet_volumes_m3(pts, tets)
    scale = float(np.mean(np.abs(vol))) if vol.size else 0.0
    for bad, what, expect in (
        (
            np.abs(vol) <= DEGENERATE_RELATIVE_VOLUME * max(scale, 1e-300),
            "degenerate (zero-volume)",
            "positive volumes",
        ),
        (vol < 0.0, "inverted", "right-handed node order (positive volume)"),
    ):
        idx = np.flatnonzero(bad)
        if idx.size:
            e = int(idx[0])
            raise InputError(
                f"{src}: {idx.size} {what} tetrahedra, first is element {element_labels[e]} with nodes "
                f"{[node_labels[n] for n in tets[e]]}; expected {expect}."
            )
