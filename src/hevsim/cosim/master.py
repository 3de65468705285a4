"""The co-simulation master: Jacobi / Gauss-Seidel coupling, fixed-point iteration, step
negotiation, unit conversion on connections, checkpoints and fault reporting.

Algorithm per communication step from ``t`` by ``h`` (inputs held constant over the step):

* **Jacobi** (the default, as libcosim's fixed-step algorithm and FMPy's SSP runner): every
  participant receives the others' outputs at ``t`` and steps; each connection lags one step.
  Worker-process FMUs step at the same time (each is started before the master steps the
  participants in process, and collected in turn).
* **Gauss-Seidel**: participants step in ``order``; each receives the outputs of those
  already stepped to ``t + h`` and of the others at ``t``. Without an explicit ``order`` (or
  after the participants it names) the order comes from the connection graph
  (:func:`graph_order`: a participant after those feeding it, ties and loops broken by
  name), so the listing order of the participants never changes the results.
* **Initial values**: outputs propagate to the connected inputs in that dependency order,
  sweeping to a fixed point where direct feedthrough chains or loops need it.
* **Iteration** (``max_iterations > 1``): the step is redone from saved states with the new
  end-of-step outputs (under-relaxed by ``relaxation``) until every connected output changes
  by less than ``tolerance`` (relative to ``1 + |value|``). With ``hold="midpoint"`` (default)
  the value held over the step is the mean of the start and end values (trapezoidal
  coupling: second order once converged); ``hold="end"`` holds the end value (first order).
* **Step size**: fixed ``step_s``, or negotiated: the MIN or MAX of the participants'
  preferred steps (bounded by ``min_step_s`` and ``max_step_s``); a rejected step is
  redone with the participant's preferred (smaller) step.
* **Multi-rate** (``rates={"fem": 5}``, fixed steps only): participant ``fem`` exchanges
  every 5th communication step only. It steps once over its whole window (5 steps) on the
  window's last communication step, with the inputs of that moment (under Gauss-Seidel the
  newest values of the participants before it); between its exchanges the others see its
  outputs held from the window's start. Participants that are slow to step and change
  slowly (a thermal model) then cost a fraction while fast ones (electrics) keep a short
  step. The final window is shortened to end at the stop time.
"""

from __future__ import annotations

import json
import pickle
import struct
import time as _time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hevsim.cosim import units as U
from hevsim.cosim.fmi_vars import narrowing, type_conversion
from hevsim.cosim.participant import Participant
from hevsim.errors import ConfigError, HevsimError, SimulationError

ALGORITHMS = ("jacobi", "gauss-seidel")
Feed = tuple[str, str, str, float, float, "Callable[[Any], Any] | None"]
"""A connection into a participant: (input, source, output, factor, offset, type conversion)."""
Feeds = tuple[Feed, ...]
NEGOTIATION = ("fixed", "min", "max")


@dataclass(frozen=True)
class Connection:
    """Output ``src_var`` of ``src`` feeds input ``dst_var`` of ``dst``; units converted
    from ``src_unit`` to ``dst_unit`` (None: the participants' declared units)."""

    src: str
    src_var: str
    dst: str
    dst_var: str
    src_unit: str | None = None
    dst_unit: str | None = None


@dataclass
class Options:
    """Master settings (see the module docstring)."""

    stop_time_s: float
    step_s: float
    start_time_s: float = 0.0
    algorithm: str = "jacobi"
    order: Sequence[str] | None = None
    negotiation: str = "fixed"
    min_step_s: float | None = None
    max_step_s: float | None = None
    max_iterations: int = 1
    tolerance: float = 1e-8
    relaxation: float = 1.0
    hold: str = "midpoint"
    send_before_receive: dict[str, bool] = field(default_factory=dict)
    rates: dict[str, int] = field(default_factory=dict)
    checkpoint_path: str | Path | None = None
    checkpoint_every: int | None = None
    checkpoint_wall_s: float = 30.0
    record_every: int = 1

    def check(self) -> None:
        """Raise :class:`ConfigError` on an invalid option, listing valid values."""
        if self.algorithm not in ALGORITHMS:
            raise ConfigError(f"co-simulation algorithm {self.algorithm!r}; valid: {', '.join(ALGORITHMS)}.")
        if self.negotiation not in NEGOTIATION:
            raise ConfigError(f"negotiation method {self.negotiation!r}; valid: {', '.join(NEGOTIATION)}.")
        if not self.step_s > 0 or not self.stop_time_s > self.start_time_s:
            raise ConfigError(
                f"co-simulation needs step_s > 0 and stop_time_s > start_time_s "
                f"(got {self.step_s}, {self.start_time_s}..{self.stop_time_s})."
            )
        if not 0 < self.relaxation <= 1:
            raise ConfigError(f"relaxation {self.relaxation} must be in (0, 1].")
        if self.hold not in ("midpoint", "end"):
            raise ConfigError(f"iteration hold {self.hold!r}; valid: midpoint, end.")
        if self.max_iterations < 1:
            raise ConfigError(f"max_iterations {self.max_iterations} must be >= 1.")
        if self.checkpoint_every is not None and not (
            isinstance(self.checkpoint_every, int) and self.checkpoint_every >= 1
        ):
            raise ConfigError(
                f"checkpoint_every {self.checkpoint_every!r}; expected an integer number of steps >= 1 "
                "(or a wall-clock interval such as '30s' in an SSD)."
            )
        if not self.checkpoint_wall_s > 0:
            raise ConfigError(f"checkpoint wall-clock interval {self.checkpoint_wall_s!r} s must be > 0.")
        if not (isinstance(self.record_every, int) and self.record_every >= 1):
            raise ConfigError(f"record_every {self.record_every!r}; expected an integer >= 1.")
        for name, k in self.rates.items():
            if not (isinstance(k, int) and k >= 1):
                raise ConfigError(f"rates: participant {name!r} rate {k!r}; expected an integer >= 1.")
        if any(k > 1 for k in self.rates.values()) and self.negotiation != "fixed":
            raise ConfigError(
                "rates (multi-rate exchange) need negotiation 'fixed': the windows are whole steps."
            )


@dataclass
class CosimResult:
    """Time series of every participant output (``columns`` "participant.variable", the
    time in ``time_s``), plus step statistics (``stats``: steps, iterations, rejected steps,
    largest iteration residual, ``loop_s`` the wall time of the stepping loop [s] and, from
    :func:`simulate`, ``wall_s`` the whole run's [s]), why the run stopped and the participants
    (for what they keep beyond their outputs, e.g. temperature fields)."""

    time_s: np.ndarray
    columns: list[str]
    data: np.ndarray
    stats: dict[str, Any]
    stopped_by: str | None = None
    participants: dict[str, Participant] = field(default_factory=dict, repr=False)
    text: dict[str, list[str]] = field(default_factory=dict)
    """String outputs ("participant.variable" -> one value per row); ``data`` holds the
    numeric ones (Integer, Enumeration as numbers, Boolean as 0 / 1)."""
    integers: dict[str, list[int]] = field(default_factory=dict)
    """Integer and Enumeration outputs exactly (FMI 3.0 Int64 / UInt64 beyond 2**53 included;
    their ``data`` columns are the nearest float64); indexing and :meth:`write_csv` use these."""
    order: list[str] = field(default_factory=list)
    """Every output column ("participant.variable", numeric and String alike) in the order the
    participants are listed and, within one, the order it declares its outputs (an FMU: its
    model description): the columns of :meth:`write_csv` ([]: :attr:`columns`, then :attr:`text`)."""
    booleans: frozenset[str] = frozenset()
    """Boolean output columns (``data`` holds them as 0 / 1; :meth:`write_csv` writes
    ``true`` / ``false``)."""

    def __getitem__(self, key: str) -> np.ndarray:
        if key in self.text:
            return np.array(self.text[key], dtype=object)
        if key in self.integers:
            return _int_array(self.integers[key])
        try:
            return self.data[:, self.columns.index(key)]
        except ValueError:
            raise KeyError(f"no result column {key!r}; columns: {self.columns + list(self.text)}") from None

    def write_csv(self, path: str | Path) -> None:
        """Write the time series as CSV (atomically): ``time_s``, then the columns in
        :attr:`order`; floats as ``repr`` (round-trips), integers exactly, Booleans as
        ``true`` / ``false``, Strings (and Binary as hexadecimal text) quoted where needed."""
        from hevsim.io import write_text_atomic

        order = self.order or [*self.columns, *self.text]
        index = {c: j for j, c in enumerate(self.columns)}
        fields: list[list[str]] = [list(map(repr, np.asarray(self.time_s, float).tolist()))]
        for c in order:
            if c in self.text:
                fields.append([_csv_field(v) for v in self.text[c]])
            elif c in self.integers:  # exact integers, written as such
                fields.append(list(map(str, self.integers[c])))
            elif c in self.booleans:
                fields.append(["true" if v else "false" for v in self.data[:, index[c]].tolist()])
            else:
                fields.append(list(map(repr, self.data[:, index[c]].tolist())))
        lines = [",".join(["time_s", *order]), *map(",".join, zip(*fields, strict=True))]
        write_text_atomic(path, "\n".join(lines) + "\n")


def _int_array(values: list[int]) -> np.ndarray:
    """``values`` exactly: int64, else uint64 (all >= 0), else Python ints (object)."""
    if all(-(2**63) <= v < 2**63 for v in values):
        return np.array(values, dtype=np.int64)
    if all(0 <= v < 2**64 for v in values):
        return np.array(values, dtype=np.uint64)
    return np.array(values, dtype=object)


def _csv_field(s: str) -> str:
    return '"' + s.replace('"', '""') + '"' if any(c in s for c in ',"\n\r') or s != s.strip() else s


class CosimFault(SimulationError):
    """A participant failed: names the participant, the call and the time; ``partial`` holds
    the results up to the last completed communication point."""

    def __init__(self, message: str, partial: CosimResult | None = None):
        super().__init__(message)
        self.partial = partial


class Master:
    """Couples ``participants`` through ``connections`` under ``options``."""

    def __init__(
        self,
        participants: Sequence[Participant],
        connections: Sequence[Connection],
        options: Options,
        extra_units: dict[str, U.Unit] | None = None,
    ):
        options.check()
        self.p = {p.name: p for p in participants}
        if len(self.p) != len(participants):
            raise ConfigError("co-simulation participants must have distinct names.")
        self.opt = options
        for n in options.order or ():
            if n not in self.p:
                raise ConfigError(f"order names unknown participant {n!r}; participants: {sorted(self.p)}.")
        self.listing = [p.name for p in participants]
        self.order = sorted(self.p)  # until the connections are known (below)
        for n in options.rates:
            if n not in self.p:
                raise ConfigError(f"rates name unknown participant {n!r}; participants: {sorted(self.p)}.")
        self.rates = {n: int(options.rates.get(n, 1)) for n in self.order}
        no_state = [n for n in self.order if not self.p[n].can_save_state]
        # checkpoints replay the participants that cannot restore a state exactly
        self._stateless = [n for n in self.order if n in no_state or not self.p[n].exact_restore]
        needs = state_needs(options)
        if needs and no_state:
            n = no_state[0]
            raise ConfigError(
                f"participant {n!r} cannot save and restore its state ({self.p[n].state_note}), "
                f"which {needs} needs; use max_iterations=1 and negotiation 'fixed' with it."
            )
        self._window_start = {n: options.start_time_s for n in self.order}  # last exchange [s]
        # connections, grouped by destination: (dst_var, src, src_var, factor, offset)
        self.feeds: dict[str, list[Feed]] = {n: [] for n in self.p}
        seen: set[tuple[str, str]] = set()
        # clock connections by destination: (input clock, src, output clock, clocked data)
        self.clock_feeds: dict[str, list[tuple[str, str, str, list[tuple[str, str, Any]]]]] = {}
        clocked: list[tuple[Connection, str]] = []
        for c in connections:
            what = f"connection {c.src}.{c.src_var} -> {c.dst}.{c.dst_var}"
            if self._clock_connection(c, what, clocked):
                continue
            for part, var, kind in ((c.src, c.src_var, "outputs"), (c.dst, c.dst_var, "inputs")):
                if part not in self.p:
                    raise ConfigError(f"{what}: no participant {part!r}; participants: {sorted(self.p)}.")
                declared = getattr(self.p[part], kind)
                if var not in declared:
                    raise ConfigError(
                        f"{what}: participant {part!r} has no {kind[:-1]} {var!r}; "
                        f"{kind}: {sorted(declared)}."
                    )
            if (c.dst, c.dst_var) in seen:
                raise ConfigError(f"{what}: input {c.dst}.{c.dst_var} is already connected.")
            seen.add((c.dst, c.dst_var))
            st = self.p[c.src].types.get(c.src_var, "Real")
            dt = self.p[c.dst].types.get(c.dst_var, "Real")
            conv = type_conversion(
                st, dt, f"{what} ({c.src}.{c.src_var} is {st}, {c.dst}.{c.dst_var} is {dt})"
            )
            sf, df = self.p[c.src].fmi_types.get(c.src_var, ""), self.p[c.dst].fmi_types.get(c.dst_var, "")
            narrowing(sf, df, f"{what} ({c.src}.{c.src_var} is {sf}, {c.dst}.{c.dst_var} is {df})")
            f, o = 1.0, 0.0
            if st == dt == "Real":
                su = c.src_unit if c.src_unit is not None else self.p[c.src].outputs[c.src_var]
                du = c.dst_unit if c.dst_unit is not None else self.p[c.dst].inputs[c.dst_var]
                f, o = U.conversion(su, du, extra_units, what)
            elif conv is None:
                conv = _identity
            self.feeds[c.dst].append((c.dst_var, c.src, c.src_var, f, o, conv))
        self._clocked_data(clocked)
        fixed = list(options.order or ())
        deps = {
            n: [*f, *((None, src) for _, src, _, _ in self.clock_feeds.get(n, ()))]
            for n, f in self.feeds.items()
        }
        self.order = fixed + [n for n in graph_order(deps) if n not in fixed]
        for n, cf in self.clock_feeds.items():
            for _, src, _, _ in cf:
                if self.order.index(src) > self.order.index(n):
                    raise ConfigError(
                        f"clock connection {src} -> {n}: {src!r} must step before {n!r} (its ticks "
                        "are run in the receiver's step); the order or a feedback loop puts it after."
                    )
        self._jacobi = options.algorithm == "jacobi"
        self._multirate = [n for n in self.order if self.rates[n] > 1]
        self._plain = options.max_iterations == 1 and not self._multirate and not self.clock_feeds

    def _clock_connection(self, c: Connection, what: str, clocked: list[tuple[Connection, str]]) -> bool:
        """Take ``c`` if it connects FMI 3.0 clocks (an output clock to a triggered input clock)
        or a clocked input (kept in ``clocked`` for :meth:`_clocked_data`); False: an ordinary one."""
        if c.src not in self.p or c.dst not in self.p:
            return False
        sp, dp = self.p[c.src], self.p[c.dst]
        src_clock, dst_clock = c.src_var in sp.clock_outputs, c.dst_var in dp.clock_inputs
        if c.dst_var in dp.clocked_inputs:
            clocked.append((c, what))
            return True
        if not (src_clock or dst_clock):
            return False
        if not hasattr(dp, "deliver_ticks") or not hasattr(sp, "clock_ticks"):
            raise ConfigError(
                f"{what}: clock connections need both FMUs in process (fmu_process 'inprocess'); "
                f"{c.src if not hasattr(sp, 'clock_ticks') else c.dst!r} is not."
            )
        if not (src_clock and dst_clock):
            raise ConfigError(
                f"{what}: a clock connects only an output clock to an input clock "
                f"({c.src}.{c.src_var} is {'an output clock' if src_clock else 'not an output clock'}, "
                f"{c.dst}.{c.dst_var} is {'an input clock' if dst_clock else 'not an input clock'})."
            )
        iv = dp.clock_inputs[c.dst_var]
        if iv != "triggered":
            raise ConfigError(
                f'{what}: input clock {c.dst}.{c.dst_var} is periodic (intervalVariability="{iv}", '
                'ticked by its FMU\'s interval); only a "triggered" input clock can be connected.'
            )
        if any(int(self.opt.rates.get(n, 1)) > 1 for n in (c.src, c.dst)):
            raise ConfigError(f"{what}: clock connections between multi-rate participants are not supported.")
        for _, _, other, _ in self.clock_feeds.get(c.dst, ()):
            if other == c.dst_var:
                raise ConfigError(f"{what}: input clock {c.dst}.{c.dst_var} is already connected.")
        self.clock_feeds.setdefault(c.dst, []).append((c.dst_var, c.src, c.src_var, []))
        return True

    def _clocked_data(self, clocked: list[tuple[Connection, str]]) -> None:
        """Clocked inputs: delivered with the ticks of their clock, from an output of the same
        source clocked by the output clock connected to that clock."""
        for c, what in clocked:
            dp, clock = self.p[c.dst], self.p[c.dst].clocked_inputs[c.dst_var]
            feed = [f for f in self.clock_feeds.get(c.dst, ()) if f[0] == clock]
            src_clock = self.p[c.src].clocked_outputs.get(c.src_var) if c.src in self.p else None
            if not feed or feed[0][1] != c.src or src_clock != feed[0][2]:
                raise ConfigError(
                    f"{what}: {c.dst}.{c.dst_var} is clocked by input clock {clock!r}: it is set "
                    "only when that clock ticks, from an output of the participant whose output "
                    f"clock is connected to {c.dst}.{clock} and clocked by that output clock "
                    f"({c.src}.{c.src_var} is clocked by {src_clock!r})."
                )
            st = self.p[c.src].types.get(c.src_var, "Real")
            dt = dp.types.get(c.dst_var, "Real")
            conv = type_conversion(
                st, dt, f"{what} ({c.src}.{c.src_var} is {st}, {c.dst}.{c.dst_var} is {dt})"
            )
            sf, df = self.p[c.src].fmi_types.get(c.src_var, ""), dp.fmi_types.get(c.dst_var, "")
            narrowing(sf, df, f"{what} ({c.src}.{c.src_var} is {sf}, {c.dst}.{c.dst_var} is {df})")
            if any(d == c.dst_var for f in feed for d, _, _ in f[3]):
                raise ConfigError(f"{what}: input {c.dst}.{c.dst_var} is already connected.")
            feed[0][3].append((c.dst_var, c.src_var, conv or _identity))

    def _deliver_ticks(self, n: str) -> None:
        """Give participant ``n`` the ticks its connected output clocks had in this step."""
        for dst_clock, src, src_clock, data in self.clock_feeds[n]:
            ticks = self.p[src].clock_ticks.get(src_clock, [])  # type: ignore[attr-defined]
            self.p[n].deliver_ticks(  # type: ignore[attr-defined]
                dst_clock, [(tk, {d: conv(vals[s]) for d, s, conv in data}) for tk, vals in ticks]
            )

    # -- helpers ---------------------------------------------------------------------------
    def _call(self, name: str, call: str, t: float, fn: Callable[..., Any], *args: Any) -> Any:
        try:
            return fn(*args)
        except CosimFault:
            raise
        except Exception as exc:
            raise _fault(name, call, t, exc) from exc

    def _inputs_for(self, name: str, y: dict[str, dict[str, Any]]) -> dict[str, Any]:
        return _values(self.feeds[name], y)

    def _send(self, name: str, y: dict[str, dict[str, float]], t: float) -> None:
        vals = self._inputs_for(name, y)
        if vals:
            self._call(name, "set_inputs", t, self.p[name].set_inputs, vals)

    def _get(self, name: str, t: float) -> dict[str, float]:
        return dict(self._call(name, "get_outputs", t, self.p[name].get_outputs))

    def _save(self, t: float) -> dict[str, Any]:
        return {n: self._call(n, "get_state", t, self.p[n].get_state) for n in self.order}

    def _restore(self, states: dict[str, Any], t: float) -> None:
        for n, s in states.items():
            self._call(n, "set_state", t, self.p[n].set_state, s)

    def _step_once(
        self, t: float, h: float, y0: dict[str, dict[str, float]], guess: dict[str, dict[str, float]]
    ) -> tuple[dict[str, dict[str, float]], float | None, list[float]]:
        """One pass over the participants; returns (end outputs, reject-preferred h, preferred hs)."""
        if self._plain:
            return self._step_plain(t, h, y0)
        jacobi = self.opt.algorithm == "jacobi"
        mid = self.opt.max_iterations > 1 and self.opt.hold == "midpoint"
        cur = dict(guess)  # entries are replaced, never mutated
        new: dict[str, dict[str, float]] = {}
        prefs: list[float] = []
        for n in self.order:
            t_n, h_n = t, h
            if self.rates[n] > 1:
                if not self._exchanges(n, t + h):
                    new[n] = y0[n]  # held over its window
                    continue
                t_n = self._window_start[n]
                h_n = t + h - t_n
            if mid:
                sent = {s: {v: _mix(cur[s][v], y0[s][v], 0.5) for v in y0[s]} for s in y0}
                self._send(n, sent, t)
            else:
                self._send(n, cur, t)
            if n in self.clock_feeds:
                self._call(n, "set_inputs", t, self._deliver_ticks, n)
            ok, pref = self._call(n, "do_step", t_n, self.p[n].do_step, t_n, h_n)
            if not ok:
                return new, (pref if pref and pref < h else h / 2), prefs
            if pref:
                prefs.append(float(pref))
            new[n] = self._get(n, t + h)
            if not jacobi:
                cur[n] = new[n]
        return new, None, prefs

    def _step_plain(
        self, t: float, h: float, y0: dict[str, dict[str, float]]
    ) -> tuple[dict[str, dict[str, float]], float | None, list[float]]:
        """:meth:`_step_once` without iteration or multi-rate windows (the common case), with
        the feeds and the participants' calls resolved once (:attr:`_plan`): the same
        operations without the per-call wrappers. Under Jacobi, participants with a
        ``start_step(t, h)`` (worker-process FMUs) get their inputs and start first and are
        collected in order, so they step in parallel with each other and with the rest (their
        inputs are the outputs at ``t`` either way: same results)."""
        cur = y0 if self._jacobi else dict(y0)
        new: dict[str, dict[str, float]] = {}
        prefs: list[float] = []
        n, call, tc = "", "", t
        try:
            for n, set_inputs, start_step, feeds in self._early:  # noqa: B007 (n: for _fault)
                call = "set_inputs"
                if feeds:
                    set_inputs(_values(feeds, cur))
                call = "do_step"
                start_step(t, h)
            for n, set_inputs, do_step, get_outputs, feeds in self._plan:
                call, tc = "set_inputs", t
                if feeds:
                    set_inputs(_values(feeds, cur))
                call = "do_step"
                ok, pref = do_step(t, h)
                if not ok:
                    return new, (pref if pref and pref < h else h / 2), prefs
                if pref:
                    prefs.append(float(pref))
                call, tc = "get_outputs", t + h
                new[n] = out = dict(get_outputs())
                if cur is not y0:
                    cur[n] = out
        except CosimFault:
            raise
        except Exception as exc:
            raise _fault(n, call, tc, exc) from exc
        return new, None, prefs

    def _exchanges(self, n: str, t_end: float) -> bool:
        """Whether multi-rate participant ``n`` steps in the communication step ending at ``t_end``."""
        eps = 1e-9 * max(1.0, abs(self.opt.stop_time_s))
        window = self.rates[n] * self.opt.step_s
        return t_end >= self._window_start[n] + window - eps or t_end >= self.opt.stop_time_s - eps

    def _record(self, t: float, y: dict[str, dict[str, Any]]) -> None:
        row = [float(y[n][v]) for n, v in self._cols]
        if not self._tcols and self._replay is None:  # (the common case, per step)
            self._times.append(t)
            self._rows.append(row)
            if self._stream is not None:
                self._stream.write(self._pack(t, *row))
            return
        trow = [y[n][v] for n, v in self._tcols]  # String, then Integer / Enumeration: exact
        if len(trow) > self._ntext:
            trow[self._ntext :] = map(int, trow[self._ntext :])
        if self._replay is not None and len(self._rows) < len(self._replay):
            i = len(self._rows)
            ref = self._replay[i]
            same = np.array_equal(np.array(row, float), ref[1:], equal_nan=True)
            if t != ref[0] or not same or (self._tcols and trow != self._treplay[i]):
                names = ", ".join(repr(n) for n in self._stateless)
                raise CosimFault(
                    f"cannot resume: participant(s) {names} cannot save their state (or not restore it "
                    "exactly), so the run was "
                    f"replayed from the start, but the replay differs from the stored results at "
                    f"t = {t:g} s (row {i}): the participants are not deterministic. Run again "
                    "without resume."
                )
        self._times.append(t)
        self._rows.append(row)
        if self._tcols:
            self._trows.append(trow)
        if self._stream is not None:
            self._stream.write(self._pack(t, *row))
            if self._tcols:
                self._tstream.write((json.dumps(trow) + "\n").encode())

    def _result(self, stopped_by: str | None) -> CosimResult:
        cols = [f"{n}.{v}" for n, v in self._cols]
        data = np.array(self._rows, float).reshape(len(self._rows), len(cols))
        exact = {f"{n}.{v}": [r[i] for r in self._trows] for i, (n, v) in enumerate(self._tcols)}
        text = {c: exact[c] for c in list(exact)[: self._ntext]}
        ints = {c: exact[c] for c in list(exact)[self._ntext :]}
        return CosimResult(
            np.array(self._times), cols, data, dict(self.stats), stopped_by, dict(self.p), text, ints,
            list(self._order), self._booleans,
        )  # fmt: skip

    def _listed_outputs(self, n: str, y: Mapping[str, Any]) -> list[str]:
        """The outputs ``y`` of participant ``n`` in the order it declares them (then any
        others it reports, in their order)."""
        declared = self.p[n].outputs
        return [v for v in declared if v in y] + [v for v in y if v not in declared]

    # -- checkpoints: the state only; the rows stream append-only to <checkpoint>.rows ------
    def _rows_path(self) -> Path:
        ck = Path(self.opt.checkpoint_path)  # type: ignore[arg-type]
        return ck.with_name(ck.name + ".rows")

    def _checkpoint(self, t: float, h: float, y: dict[str, dict[str, float]], nsteps: int) -> None:
        """Write the checkpoint: O(state), independent of the steps so far."""
        path = Path(self.opt.checkpoint_path)  # type: ignore[arg-type]
        assert self._stream is not None
        self._stream.flush()
        self._tstream.flush()
        blob = {
            "version": 3,
            "t": t,
            "h": h,
            "y": y,
            "nsteps": nsteps,
            "window_start": self._window_start,
            "states": None if self._stateless else self._save(t),
            "stats": self.stats,
            "columns": self._cols,
            "text_columns": self._tcols,
            "rows": len(self._rows),
            "text_bytes": self._tstream.tell(),
        }
        tmp = path.with_name(f".{path.name}.tmp")
        tmp.write_bytes(pickle.dumps(blob))
        tmp.replace(path)
        self._last_ck = _time.monotonic()
        self._ck_step = nsteps

    def _load_checkpoint(self, ck: Path) -> dict[str, Any]:
        try:
            blob = pickle.loads(ck.read_bytes())
        except Exception as exc:
            raise ConfigError(f"{ck}: not a readable checkpoint ({type(exc).__name__}: {exc}).") from None
        if not isinstance(blob, dict) or blob.get("version") != 3:
            raise ConfigError(f"{ck}: checkpoint of an older hevsim version; run again without resume.")
        if blob["columns"] != self._cols or blob["text_columns"] != self._tcols:
            raise ConfigError(f"{ck}: checkpoint of a different system (other outputs); run without resume.")
        width = 1 + len(self._cols)
        rows_path = self._rows_path()
        raw = rows_path.read_bytes() if rows_path.is_file() else b""
        n = int(blob["rows"])
        if len(raw) < 8 * width * n:
            raise ConfigError(f"{rows_path}: holds fewer result rows than its checkpoint ({n}).")
        table = np.frombuffer(raw[: 8 * width * n], float).reshape(n, width)
        with open(rows_path, "r+b") as f:  # drop rows written after the checkpoint
            f.truncate(8 * width * n)
        blob["table"] = table
        tpath = rows_path.with_suffix(".text")
        nb = int(blob["text_bytes"])
        traw = tpath.read_bytes()[:nb] if tpath.is_file() else b""
        blob["text_table"] = [json.loads(line) for line in traw.decode().splitlines()]
        if len(traw) < nb or (self._tcols and len(blob["text_table"]) != n):
            raise ConfigError(f"{tpath}: holds fewer text rows than its checkpoint ({n}).")
        if tpath.is_file():
            with open(tpath, "r+b") as f:
                f.truncate(nb)
        return blob

    def _next_end(self, t: float) -> float | None:
        """End of the fixed step from ``t`` [s] (None: ``t`` is the stop time)."""
        return self._grid_fns()[1](t)

    def _grid(self, t: float, h: float) -> float:
        """End of the step from ``t`` by ``h``: snapped to ``t_start + n * step_s`` when it is
        that point up to rounding (no drift over long runs), and to the stop time."""
        return self._grid_fns()[0](t, h)

    def _grid_fns(self) -> tuple[Callable[[float, float], float], Callable[[float], float | None]]:
        """:meth:`_grid` and :meth:`_next_end` as functions of the current options with their
        constants computed once (called per step: a few attribute look-ups less each)."""
        o = self.opt
        start, step, stop = o.start_time_s, o.step_s, o.stop_time_s
        snap = 1e-9 * step
        last = stop - 1e-9 * max(1.0, abs(stop))

        def grid(t: float, h: float) -> float:
            t_end = t + h
            g = start + round((t_end - start) / step) * step
            if abs(t_end - g) <= snap:
                t_end = g
            if t_end >= last:
                t_end = stop
            return t_end

        def next_end(t: float) -> float | None:
            return None if t >= last else grid(t, step)

        return grid, next_end

    # -- run -------------------------------------------------------------------------------
    def run(
        self, progress: Callable[[float, float], None] | None = None, resume: bool = False
    ) -> CosimResult:
        """Run from start to stop time; ``progress(t, stop)`` is called per communication step.
        With ``resume`` and an existing checkpoint file, continue from the checkpoint (or,
        when a participant cannot save its state, replay from the start and check that the
        replay reproduces the stored rows)."""
        o = self.opt
        t, h = o.start_time_s, o.step_s
        self.stats: dict[str, Any] = {"steps": 0, "iterations": 0, "rejected": 0, "max_residual": 0.0}
        self._times: list[float] = []
        self._rows: list[list[float]] = []
        self._trows: list[list[Any]] = []  # String, Integer columns
        self._replay: np.ndarray | None = None
        self._treplay: list[list[Any]] = []
        self._stream: Any = None
        self._tstream: Any = None
        self._order: list[str] = []
        self._booleans: frozenset[str] = frozenset()
        for n in self.order:
            window = getattr(self.p[n], "run_window", None)  # (Model Exchange FMUs: the solver's)
            if window is not None:
                window(o.start_time_s, o.stop_time_s)
            self._call(n, "setup", t, self.p[n].setup, t)
        # A participant without inputs from others that can run ahead (worker FMUs) steps
        # several steps per exchange where steps are fixed and never redone (checkpoints
        # save the steps it ran ahead with its state)
        ahead: set[str] = set()
        fixed = o.negotiation == "fixed" and not o.min_step_s and not o.max_step_s
        if fixed and o.max_iterations == 1:
            for n in self.order:
                run_ahead = getattr(self.p[n], "run_ahead", None)
                if run_ahead is not None and not self.feeds[n] and self.rates[n] == 1:
                    run_ahead(self._grid_fns()[1])
                    ahead.add(n)
        # Jacobi: participants that can step in the background (start_step: worker FMUs) get
        # their inputs and start first, so they step while the others do
        self._early: list[tuple[str, Callable[..., Any], Callable[[float, float], None], Feeds]] = []
        self._plan: list[tuple[str, Callable[..., Any], Callable[..., Any], Callable[..., Any], Feeds]] = []
        for n in self.order:
            p, feeds = self.p[n], tuple(self.feeds[n])
            start = getattr(p, "start_step", None) if self._jacobi and n not in ahead else None
            if start is not None:
                self._early.append((n, p.set_inputs, start, feeds))
                feeds = ()  # sent before the start
            self._plan.append((n, p.set_inputs, p.do_step, p.get_outputs, feeds))
        y = self._initial_exchange(t)
        listed = [(n, v) for n in self.listing for v in self._listed_outputs(n, y[n])]
        self._order = [f"{n}.{v}" for n, v in listed]
        self._booleans = frozenset(f"{n}.{v}" for n, v in listed if self.p[n].types.get(v) == "Boolean")
        self._cols = [(n, v) for n, v in listed if not isinstance(y[n][v], str)]
        self._tcols = [(n, v) for n, v in listed if isinstance(y[n][v], str)]
        self._ntext = len(self._tcols)
        # Integer / Enumeration outputs are also kept exactly in the text rows (JSON: any int)
        self._tcols += [
            (n, v) for n, v in listed
            if self.p[n].types.get(v) in ("Integer", "Enumeration") and not isinstance(y[n][v], str)
        ]  # fmt: skip
        self._pack = struct.Struct(f"={1 + len(self._cols)}d").pack  # one row of the stream
        nsteps = 0
        ck = Path(o.checkpoint_path) if o.checkpoint_path else None
        blob = self._load_checkpoint(ck) if resume and ck is not None and ck.is_file() else None
        if ck is not None:
            self._stream = open(self._rows_path(), "ab" if blob is not None else "wb")
            self._tstream = open(self._rows_path().with_suffix(".text"), "ab" if blob is not None else "wb")
        self._last_ck = _time.monotonic()
        self._ck_step = -1  # the step of the last checkpoint written
        self._last_y = y
        stopped_by = None
        try:
            if resume and blob is None:
                self.stats["resume"] = f"no checkpoint {ck}: started from t = {t:g} s"
            if blob is not None and blob["states"] is None:
                self._refuse_replay(ck)  # type: ignore[arg-type]
                self._replay, self._treplay = blob["table"], blob["text_table"]
                self.stats["resume"] = (
                    f"replayed from t = {t:g} s (participants that cannot save their state or restore it "
                    "exactly), checked "
                    f"against the {len(self._replay)} rows stored up to t = {blob['t']:g} s "
                    f"(step {blob['nsteps']})"
                )
                # the replay rewrites the rows from the start
                for f in (self._stream, self._tstream):
                    f.seek(0)
                    f.truncate()
            if blob is not None and blob["states"] is not None:
                t, h, y, nsteps = blob["t"], blob["h"], blob["y"], blob["nsteps"]
                self._window_start = dict(blob["window_start"])
                self.stats = blob["stats"]
                self.stats["resume"] = f"resumed from the checkpoint at t = {t:g} s (step {nsteps})"
                table = blob["table"]
                self._times = [float(v) for v in table[:, 0]]
                self._rows = table[:, 1:].tolist()
                self._trows = blob["text_table"]
                self._restore(blob["states"], t)
                self._last_y = y
            else:
                self._record(t, y)
            t_loop = _time.perf_counter()
            stopped_by = self._loop(t, h, y, nsteps, ck, progress)
            self.stats["loop_s"] = _time.perf_counter() - t_loop
            if ck is not None and stopped_by is None and self._ck_step != self.stats["steps"]:
                # the end as a checkpoint too (a run shorter than the interval has one; resuming
                # a finished run gives its results without stepping)
                self._checkpoint(self._times[-1], self.opt.step_s, self._last_y, self.stats["steps"])
        except CosimFault as exc:
            exc.partial = self._result(f"fault: {exc}")
            self._terminate_all(t)
            self._close_stream()
            raise
        except BaseException:
            self._close_stream()
            raise
        self._terminate_all(self._times[-1] if self._times else t)
        self._close_stream()
        if ck is not None and stopped_by is not None:  # (no final checkpoint: nothing to resume)
            self._rows_path().unlink(missing_ok=True)
            self._rows_path().with_suffix(".text").unlink(missing_ok=True)
        return self._result(stopped_by)

    def _close_stream(self) -> None:
        for f in (self._stream, self._tstream):
            if f is not None:
                f.close()
        self._stream = self._tstream = None

    def _refuse_replay(self, ck: Path) -> None:
        bad = [n for n in self._stateless if not self.p[n].deterministic]
        if bad:
            raise CosimFault(
                f"{ck}: cannot resume: participant(s) {', '.join(repr(n) for n in bad)} can neither "
                "save their state nor be replayed (not deterministic); run again without resume."
            )

    def _loop(
        self,
        t: float,
        h: float,
        y: dict[str, dict[str, float]],
        nsteps: int,
        ck: Path | None,
        progress: Callable[[float, float], None] | None,
    ) -> str | None:
        o = self.opt
        eps = 1e-9 * max(1.0, abs(o.stop_time_s))
        need_state = o.max_iterations > 1 or o.negotiation != "fixed"
        fixed_h = o.negotiation == "fixed" and not o.min_step_s and not o.max_step_s
        parts = [self.p[n] for n in self.order]
        grid = self._grid_fns()[0]
        plain, step_plain = self._plain, self._step_plain
        while t < o.stop_time_s - eps:
            t_end = grid(t, h)
            h = t_end - t
            saved = self._save(t) if need_state else None
            guess = y
            it = 0
            while True:
                if plain:  # (the common case: one call less per step)
                    new, reject_h, prefs = step_plain(t, h, y)
                else:
                    new, reject_h, prefs = self._step_once(t, h, y, guess)
                if reject_h is not None:
                    self.stats["rejected"] += 1
                    if saved is None:
                        saved = self._save_for_reject(t)
                    self._restore(saved, t)
                    lo = o.min_step_s or 0.0
                    if reject_h <= lo or reject_h < 1e-12:
                        raise CosimFault(
                            f"step rejected at t = {t:g} s with h = {h:g} s below the minimum step."
                        )
                    h = reject_h
                    t_end = t + h
                    guess = y
                    it = 0
                    continue
                it += 1
                self.stats["iterations"] += 1
                if it >= o.max_iterations:
                    break
                res = max(
                    (abs(new[n][v] - guess[n][v]) / (1 + abs(new[n][v])) for n, v in self._cols),
                    default=0.0,
                )
                if res <= o.tolerance:
                    break
                self._restore(saved, t)  # type: ignore[arg-type]
                w = o.relaxation
                guess = {n: {v: _mix(new[n][v], guess[n][v], w) for v in new[n]} for n in new}
            if o.max_iterations > 1:
                res = max(
                    (abs(new[n][v] - guess[n][v]) / (1 + abs(new[n][v])) for n, v in self._cols),
                    default=0.0,
                )
                self.stats["max_residual"] = max(self.stats["max_residual"], res)
            for n in self._multirate:
                if self._exchanges(n, t_end):
                    self._window_start[n] = t_end
            y = self._last_y = new
            t = t_end
            nsteps += 1
            self.stats["steps"] = nsteps
            stop = False
            for p in parts:
                if p.terminate_requested:
                    stop = True
                    break
            if stop:
                term = [n for n in self.order if self.p[n].terminate_requested]
                ends = [self.p[n].terminate_time for n in term]
                t_stop = min((te for te in ends if te is not None and te < t), default=t)
                self._record(t_stop, y)
                who = term[ends.index(t_stop)] if t_stop in ends else term[0]
                return f"participant {who!r} requested termination at t = {t_stop:g} s"
            if nsteps % o.record_every == 0 or t >= o.stop_time_s - eps:
                self._record(t, y)
            h = o.step_s if fixed_h else self._next_h(h, prefs)
            if ck is not None and (
                nsteps % o.checkpoint_every == 0
                if o.checkpoint_every
                else _time.monotonic() - self._last_ck >= o.checkpoint_wall_s
            ):
                if self._replay is None or len(self._rows) >= len(self._replay):
                    self._replay = None
                    self._checkpoint(t, h, y, nsteps)
            if progress is not None:
                progress(t, o.stop_time_s)
        return None

    def _save_for_reject(self, t: float) -> dict[str, Any]:
        raise CosimFault(
            f"a participant rejected the step at t = {t:g} s; redoing it needs saved states: "
            "set max_iterations >= 2 or use participants that support get_state."
        )

    def _next_h(self, h: float, prefs: list[float]) -> float:
        o = self.opt
        if o.negotiation == "fixed":
            nh = o.step_s
        elif prefs:
            nh = min(prefs) if o.negotiation == "min" else max(prefs)
        else:
            nh = o.step_s
        if o.min_step_s:
            nh = max(nh, o.min_step_s)
        if o.max_step_s:
            nh = min(nh, o.max_step_s)
        return nh

    def _initial_exchange(self, t: float) -> dict[str, dict[str, float]]:
        """Initial values: outputs propagate to the connected inputs in dependency order
        (:attr:`order`; participants with ``send_before_receive`` false first), sweeping
        until no output changes (direct feedthrough loops are iterated to their fixed point;
        :data:`INIT_SWEEPS` at most, then a :class:`CosimFault` naming the participants)."""
        late = [n for n in self.order if not self.opt.send_before_receive.get(n, True)]
        sweep = late + [n for n in self.order if n not in late and self.feeds[n]]
        y = {n: self._get(n, t) for n in self.order}
        for _ in range(INIT_SWEEPS):
            changed = []
            for n in sweep:
                self._send(n, y, t)
                new = self._get(n, t)
                if not _same(new, y[n]):
                    changed.append(n)
                    y[n] = new
            if not changed:
                return y
        raise CosimFault(
            f"initial values at t = {t:g} s do not converge: the outputs of "
            f"{', '.join(repr(n) for n in changed)} still change after {INIT_SWEEPS} sweeps of "
            "propagating outputs to inputs (a direct-feedthrough loop without a fixed point?)."
        )

    def _terminate_all(self, t: float) -> None:
        for n in self.order:
            try:
                self.p[n].terminate()
            except Exception:
                pass


def _identity(v: Any) -> Any:
    return v


def _values(feeds: Sequence[Feed], y: Mapping[str, Mapping[str, Any]]) -> dict[str, Any]:
    """The input values ``feeds`` (of one participant) take from the outputs ``y``: unit
    conversion ``factor * value + offset`` for Real values, else the type conversion."""
    return {dv: f * y[s][sv] + o if cv is None else cv(y[s][sv]) for dv, s, sv, f, o, cv in feeds}


def _fault(name: str, call: str, t: float, exc: Exception) -> CosimFault:
    """``exc`` raised by participant ``name`` in ``call`` at ``t`` [s] as a :class:`CosimFault`
    naming them."""
    what = str(exc) if isinstance(exc, HevsimError) else f"{type(exc).__name__}: {exc}"
    call = getattr(exc, "call", None) or call  # (a worker sets inputs with the step: PhaseError)
    return CosimFault(f"participant {name!r} failed in {call} at t = {t:g} s: {what}")


def _mix(a: Any, b: Any, w: float) -> Any:
    """``w a + (1 - w) b`` for Real values; ``a`` for discrete ones (Integer, Boolean, String)."""
    return w * a + (1 - w) * b if isinstance(a, (float, np.floating)) else a


INIT_SWEEPS = 100
"""Sweeps of the initial propagation of outputs to inputs before giving up."""


def _same(a: dict[str, float], b: dict[str, float]) -> bool:
    return a.keys() == b.keys() and all(a[k] == b[k] or (a[k] != a[k] and b[k] != b[k]) for k in a)


def graph_order(feeds: Mapping[str, Sequence[tuple[Any, ...]]]) -> list[str]:
    """Participants in dependency order (a participant after those feeding it), whatever the
    order in which they were listed: repeatedly take, by name, the first participant none of
    the remaining ones feeds; in a feedback loop (none such) the first remaining by name."""
    deps = {n: {src for _, src, *_ in f if src != n} for n, f in feeds.items()}
    left = sorted(deps)
    out: list[str] = []
    while left:
        free = [n for n in left if not deps[n] & set(left)]
        n = free[0] if free else left[0]
        out.append(n)
        left.remove(n)
    return out


def state_needs(options: Options) -> str:
    """What in ``options`` needs participants that save and restore their state ("" none)."""
    if options.max_iterations > 1:
        return f"iterative coupling (max_iterations={options.max_iterations})"
    if options.negotiation != "fixed":
        return f"step negotiation {options.negotiation!r} (steps may be rejected and redone)"
    return ""


def simulate(
    participants: Sequence[Participant],
    connections: Sequence[Connection],
    progress: Callable[[float, float], None] | None = None,
    resume: bool = False,
    extra_units: dict[str, U.Unit] | None = None,
    **options: Any,
) -> CosimResult:
    """One call: build a :class:`Master` with :class:`Options` ``options`` and run it."""
    t0 = _time.perf_counter()
    m = Master(participants, connections, Options(**options), extra_units)
    res = m.run(progress=progress, resume=resume)
    res.stats["wall_s"] = _time.perf_counter() - t0
    return res


__all__ = ["Connection", "CosimFault", "CosimResult", "Master", "Options", "simulate"]
