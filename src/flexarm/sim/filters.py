"""The sensors' digital filters started from a log: the filter states a segment of a real run
starts from, taken from the logged filter outputs (for a fit in segments started from the
logged state).

The filters of the kinds ``lowpass2``, ``lowpass2_rate`` / ``derivative2``
(:mod:`flexarm.control.lti`) have the state ξ = (x₁, x₂): x₁ the input low-passed at the
cutoff, x₂ its rate; ``lowpass2`` outputs x₁, the rate kinds x₂. From a log at sample k:

* a ``lowpass2`` channel c gives x₁ = c_k; x₂ is the logged output of a rate channel on the
  same signal with the same filter (the lab's α̇_f beside α_f), else, with forward Euler,
  x₂ = (c_{k+1} − c_k) / T exactly (x₁⁺ = x₁ + T x₂);
* a rate channel c gives x₂ = c_k; x₁ is a logged ``lowpass2`` sibling's output, else the
  filter run over the logged unfiltered reading u of the same signal (the encoder angle
  beside θ̇_f) from rest, far enough back that the start no longer shows (|z|ⁿ < 1e-12);
  with less history than that, x₁ = u_k − (2ζ/ω) x₂ (the low-pass's lag, exact on a ramp).

Consecutive files of one run (``continuous``, :func:`continuous_starts`): the logs, in order,
are pieces of one run, sample K_i the first of piece i. Every dynamic controller block
(:class:`~flexarm.control.lti.LTIController` with states, and the error-driven
:class:`~flexarm.control.discrete.LinearController` of ``pd``/``pid``/``lead``/``tf``) starts
piece i from the state reached by running it on the logged inputs of the pieces before,

    x_{K_i} = run of x⁺ = A x + B w_k over k = 0..K_i − 1 from x_0 (at the block's own
    phase: an update at every sample k with k ≡ 0 mod ``every``),

with the output it holds and its phase K_i mod ``every``; the digital filters start from
:func:`filter_state_from_log` at K_i on the pieces joined (their rate channels' history runs
across the file boundary). Not carried: the sensors' pure-delay buffers and the computation
delay's command buffer (they restart from the piece's first reading / 0); state-feedback
rates restart from the piece's first sample.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from flexarm.control.discrete import Controller, LinearController, Sum
from flexarm.control.friction_compensation import FrictionCompensated
from flexarm.control.lti import (
    FILTER_KINDS,
    Blocks,
    LTIController,
    digital_filter,
    input_history,
    run_state,
)
from flexarm.sim.sampled import SampledLoop, Sensors


def with_filter_state(loop: SampledLoop | Sensors, states: dict[str, Any]):
    """``loop`` (or its sensors) with the digital filters of the channels named in
    ``states`` (channel → state vector ξ_0) starting there; the others start at rest on
    their first reading."""
    sens = loop.sensors if isinstance(loop, SampledLoop) else loop
    if not sens.digital:
        raise ValueError("with_filter_state: no sensor channel has a digital filter")
    x0 = np.array(sens.fx0, dtype=float)
    k = x0.shape[1]
    for name, x in states.items():
        if name not in sens.names or sens.names.index(name) not in sens.digital:
            have = [sens.names[i] for i in sens.digital]
            raise ValueError(
                f"with_filter_state: channel {name!r} has no digital filter; "
                f"filtered channels: {', '.join(have)}"
            )
        j = sens.digital.index(sens.names.index(name))
        x = np.asarray(x, float).ravel()
        if x.size > k or not np.all(np.isfinite(x)):
            raise ValueError(
                f"with_filter_state: {name!r}: state {x} (the filter has at most "
                f"{k} states; finite values)"
            )
        x0[j] = 0.0
        x0[j, : x.size] = x
    new = eqx.tree_at(lambda s: s.fx0, sens, jnp.asarray(x0))
    if isinstance(loop, SampledLoop):
        return eqx.tree_at(lambda lp: lp.sensors, loop, new)
    return new


def _spec(sensors: dict, name: str) -> dict:
    s = sensors[name]
    return s.model_dump() if hasattr(s, "model_dump") else dict(s)


def _logged_offset(spec: dict) -> float:
    """The zero offset a channel's logged reading carries, in its unit: ``offset``, 0 where
    the logger zeroes the channel (its tare removed it;
    :func:`flexarm.sim.sampled.logged_offset`)."""
    if float(spec.get("zeroing") or 0.0) > 0:
        return 0.0
    return float(spec.get("offset") or 0.0)


def filter_state_from_log(sensors: dict, log, k: int, dt: float) -> dict[str, np.ndarray]:
    """States ξ_k of every digitally filtered channel of ``sensors`` (a scenario's
    ``[sensors]``: channel → :class:`flexarm.specs.experiment.Sensor`) that the log holds,
    at its sample k (module docstring). ``dt``: the sample period (s). A channel the rules
    cannot start from the log is an error naming it and what is missing."""
    chans = {n: _spec(sensors, n) for n in sensors}
    sig = {n: c.get("signal") or n for n, c in chans.items()}
    out: dict[str, np.ndarray] = {}

    def same_filter(a: dict, b: dict) -> bool:
        return all(a.get(x) == b.get(x) for x in ("cutoff", "damping", "discretisation"))

    for name, c in chans.items():
        f = c.get("filter")
        if not f or name not in log.signals:
            continue
        kind = f["kind"]
        if kind not in FILTER_KINDS or f.get("discretisation", "forward_euler") == "tustin":
            raise ValueError(
                f"sensor {name!r}: a {kind!r} filter"
                + (" discretised by tustin" if kind in FILTER_KINDS else "")
                + " has no state read off its outputs; set it with "
                "with_filter_state"
            )
        y = log[name]
        sib_kinds = ("lowpass2",) if FILTER_KINDS[kind] == 1 else ("lowpass2_rate", "derivative2")
        sibs = [
            n
            for n, o in chans.items()
            if n != name
            and sig[n] == sig[name]
            and o.get("filter")
            and o["filter"]["kind"] in sib_kinds
            and same_filter(o["filter"], f)
            and n in log.signals
        ]
        if FILTER_KINDS[kind] == 0:  # lowpass2: x1 logged
            x1 = y[k]
            if sibs:
                x2 = log[sibs[0]][k]
            elif f.get("discretisation", "forward_euler") == "forward_euler" and k + 1 < len(y):
                x2 = (y[k + 1] - y[k]) / dt
            else:
                raise ValueError(
                    f"sensor {name!r}: its rate is not logged (no rate channel on "
                    f"{sig[name]!r} with the same filter) and cannot be "
                    "differenced at the log's last sample"
                )
            out[name] = np.array([x1, x2])
            continue
        x2 = y[k]
        if sibs:  # the sibling's low-passed reading, moved from its offset to this one's
            x1 = log[sibs[0]][k] + (_logged_offset(c) - _logged_offset(chans[sibs[0]]))
            out[name] = np.array([x1, x2])
            continue
        raw = [
            n
            for n, o in chans.items()
            if sig[n] == sig[name]
            and not o.get("filter")
            and n in log.signals
            and float(o.get("gain", 1.0)) == float(c.get("gain", 1.0))
        ]
        if not raw:
            raise ValueError(
                f"sensor {name!r}: the log holds neither its low-passed signal "
                f"nor the unfiltered reading of {sig[name]!r}; log one, or set "
                "the state with with_filter_state"
            )
        filt = digital_filter(f, dt, where=f"sensor {name!r}: filter")
        rho = float(np.max(np.abs(np.linalg.eigvals(filt.A))))
        back = int(math.ceil(math.log(1e-12) / math.log(rho))) if 0 < rho < 1 else k + 1
        # the reading behind the filter carries this channel's offset, the log the raw one's
        u = np.asarray(log[raw[0]], float) + (_logged_offset(c) - _logged_offset(chans[raw[0]]))
        if k >= back:  # enough history: the filter's own state, its start forgotten
            _, xs = filt.run(u[k - back : k + 1])
            out[name] = np.array([xs[-1][0], x2])
        else:  # the low-passed input lags it by 2ζ/ω times its rate (exact on a ramp)
            w = 2 * math.pi * float(f["cutoff"])
            out[name] = np.array([u[k] - 2 * float(f.get("damping", 0.9)) / w * x2, x2])
    return out


# ----------------------------------------------------------------------------- consecutive files
class ControllerStateWarning(UserWarning):
    """A dynamic controller starts a log from an assumed state (its ``initial_state``)."""


@dataclass(frozen=True)
class PieceStart:
    """Where piece ``index`` of a run starts: its first sample's index in the run
    (``sample``), each dynamic controller block's (state x, held output u, phase k) by
    name, and the digital filters' states by channel."""

    index: int
    sample: int
    controllers: dict[str, tuple[np.ndarray, np.ndarray, int]] = field(default_factory=dict)
    filters: dict[str, np.ndarray] = field(default_factory=dict)


def _map_blocks(ctrl: Controller, fn: Callable[[Controller], Controller]) -> Controller:
    """``ctrl`` with each block (an :class:`LTIController` or a :class:`LinearController`)
    replaced by ``fn(block)``, through :class:`Blocks`, :class:`Sum` and
    :class:`FrictionCompensated`."""
    if isinstance(ctrl, (LTIController, LinearController)):
        return fn(ctrl)
    if isinstance(ctrl, Blocks):
        return Blocks(*(_map_blocks(p, fn) for p in ctrl.parts), names=ctrl.names)
    if isinstance(ctrl, Sum):
        return Sum(*(_map_blocks(p, fn) for p in ctrl.parts))
    if isinstance(ctrl, FrictionCompensated):
        return dataclasses.replace(ctrl, feedback=_map_blocks(ctrl.feedback, fn))
    return ctrl


def _block_name(block: Controller, i: int) -> str:
    return getattr(block, "name", None) or f"{type(block).__name__} #{i}"


def dynamic_blocks(ctrl: Controller) -> list[tuple[str, LTIController | LinearController]]:
    """The controller's blocks that have a state (name, block), in order."""
    found: list[LTIController | LinearController] = []

    def visit(b):
        if (isinstance(b, LTIController) and b.dynamic) or (
            isinstance(b, LinearController) and np.asarray(b.A).size
        ):
            found.append(b)
        return b

    _map_blocks(ctrl, visit)
    out, seen = [], set()
    for i, b in enumerate(found):
        name = _block_name(b, i)
        name = name if name not in seen else f"{name} #{i}"
        seen.add(name)
        out.append((name, b))
    return out


def _linear_history(block: LinearController, log) -> np.ndarray:
    missing = [c for c in (block.measured, block.reference) if c not in log.signals]
    if missing:
        raise ValueError(
            f"{log.name}: the state of the {block.measured} controller is run "
            f"over the logs, which have no {', '.join(missing)}"
        )
    return np.asarray(log[block.reference], float) - np.asarray(log[block.measured], float)


def _join(logs) -> Any:
    """The logs joined into one (the signals all of them hold; time re-based to one clock
    of the first log's step)."""
    from flexarm.io.logs import Log

    common = [k for k in logs[0].signals if all(k in lg.signals for lg in logs)]
    n = sum(len(lg) for lg in logs)
    dt = logs[0].dt if logs[0].time is not None and len(logs[0]) > 1 else 1.0
    return Log(
        None,
        np.arange(n) * dt,
        {k: np.concatenate([np.asarray(lg[k], float) for lg in logs]) for k in common},
    )


def continuous_starts(loop: SampledLoop, sensors: dict, logs, dt: float) -> list[PieceStart]:
    """The start of each of ``logs`` (consecutive pieces of one run, in order) for ``loop``:
    the dynamic controller blocks' states run over the pieces before (module docstring) and
    the digital filters' states from the joined logs. ``sensors``: the scenario's
    ``[sensors]``; ``dt``: the base sample period (s). A block whose inputs a log lacks is
    an error naming the log and the channels."""
    if not logs:
        return []
    blocks = dynamic_blocks(loop.controller)
    for name, b in blocks:
        need = (
            (*b.measured_signals, *b.reference_signals)
            if isinstance(b, LTIController)
            else (b.measured, b.reference)
        )
        for lg in logs:
            missing = [c for c in need if c not in lg.signals]
            if missing:
                raise ValueError(
                    f"{lg.name}: no {', '.join(missing)}, an input of {name}, "
                    "whose state is run over the logs (continuous): log the "
                    "block's inputs, or replay without continuous"
                )
    joined = _join(logs)
    hist = {}
    for name, b in blocks:
        if isinstance(b, LTIController):
            hist[name] = input_history(b, joined)
        else:
            hist[name] = _linear_history(b, joined)[:, None]
    starts, k = [], 0
    state = {
        name: (
            np.asarray(b.x0 if isinstance(b, LTIController) else b.init(), float),
            np.zeros(getattr(b, "n_u", 1)),
            0,
        )
        for name, b in blocks
    }
    for i, lg in enumerate(logs):
        filt = (
            filter_state_from_log(sensors, joined, k, dt)
            if i
            else filter_state_from_log(sensors, lg, 0, dt)
        )
        starts.append(
            PieceStart(i, k, {n: (x.copy(), u.copy(), ph) for n, (x, u, ph) in state.items()}, filt)
        )
        n = len(lg)
        for name, b in blocks:
            x, u, ph = state[name]
            w = hist[name][k : k + n]
            if isinstance(b, LTIController):
                state[name] = run_state(b, w, n, x0=x, k0=ph)
            else:
                A, B = np.asarray(b.A, float), np.asarray(b.B, float)
                for j in range(n):
                    x = A @ x + B * w[j, 0]
                state[name] = (x, u, ph + n)
        k += n
    return starts


def start_piece(loop: SampledLoop, start: PieceStart) -> SampledLoop:
    """``loop`` with its dynamic controller blocks and digital filters starting where
    ``start`` (from :func:`continuous_starts`) says."""
    names = dict(dynamic_blocks(loop.controller))
    by_id = {id(b): n for n, b in names.items()}

    def set_state(b):
        n = by_id.get(id(b))
        if n is None or n not in start.controllers:
            return b
        x, u, ph = start.controllers[n]
        if isinstance(b, LTIController):
            return dataclasses.replace(
                b,
                x0=jnp.asarray(x),
                u0=jnp.asarray(u),
                k0=jnp.asarray(ph % b.every, dtype=jnp.int32),
            )
        return _LinearStarted.around(b, x)

    ctrl = _map_blocks(loop.controller, set_state)
    loop = eqx.tree_at(lambda lp: lp.controller, loop, ctrl)
    if start.filters and loop.sensors.digital:
        loop = with_filter_state(loop, start.filters)
    return loop


class _LinearStarted(LinearController):
    """A :class:`LinearController` whose state starts at ``x_start`` instead of 0."""

    x_start: Any = None

    @classmethod
    def around(cls, b: LinearController, x) -> _LinearStarted:
        return cls(b.A, b.B, b.C, b.D, b.measured, b.reference, jnp.asarray(x, float))

    def init(self):
        return self.x_start


def warn_assumed_start(loop: SampledLoop, log_name: str, *, stacklevel: int = 2) -> list[str]:
    """Warn (:class:`ControllerStateWarning`) that each dynamic controller block of
    ``loop`` starts the log from an assumed state; returns the messages."""
    msgs = []
    for name, b in dynamic_blocks(loop.controller):
        n = int(np.asarray(b.A).shape[-1])
        msgs.append(
            f"{log_name}: controller {name!r} is dynamic ({n} state(s)) and starts "
            "this log from its initial_state (an assumption, 0 by default); if the "
            "logs are consecutive pieces of one run, pass --continuous "
            "(continuous=True) to carry its state from the pieces before"
        )
    for m in msgs:
        warnings.warn(m, ControllerStateWarning, stacklevel=stacklevel + 1)
    return msgs


# ----------------------------------------------------------------------------- computed inputs
def computed_channels(
    sensors: dict, log, dt: float, *, name: str | None = None
) -> tuple[dict[str, np.ndarray], list[str]]:
    """The digitally filtered channels of ``sensors`` (a scenario's ``[sensors]``) that the
    log does not hold but that its logged signals define, computed as the logger computed
    them (issue #24, item 5: a controller reading the lab's filtered rates from a log that
    holds only the angles). ``log``: a :class:`flexarm.io.logs.Log` or a mapping channel →
    samples; ``dt``: the sample period (s). Returns (channel → samples, notes: one line per
    computed channel saying from what).

    For a channel c with digital filter F (:func:`flexarm.control.lti.digital_filter`, the
    filter the simulator's sensor stage runs) reading plant signal s:

    * a logged rate sibling's rule: c of a rate kind (output ξ₂), forward Euler, and the log
      holds the ``lowpass2`` output ξ₁ of the same filter on s (same cutoff, damping, gain,
      delay, zeroing): ξ₂,k = (ξ₁,k+1 − ξ₁,k) / T exactly (ξ₁⁺ = ξ₁ + T ξ₂); the last
      sample extrapolated linearly;
    * the raw reading's rule: the log holds an unfiltered channel r of s with the same
      zeroing: c = F run on (g_c / g_r)(r − o_r) + o_c quantised to c's count (o the
      channels' offsets, 0 on a zeroed channel), from rest on its first
      sample (the simulator's start, (I − A) ξ₀ = B y₀), shifted by c's delay minus r's
      (samples; the ends held). Exact where the filter's start is forgotten (|z|ⁿ, e.g.
      ~30 ms for the lab's 40 Hz derivative, ~0.5 s for a 2 Hz low-pass); the first
      samples of a log that starts in motion read the filter's start-up transient.

    A rate channel (``lowpass2_rate``, ``derivative2``) need not share the zeroing of the
    channel it is computed from: zeroing subtracts a constant, which a rate does not see
    once the window and the filter's memory have passed; its window reads 0 in the zeroed
    channel, so there the computed rate is 0 (the note says so).

    Channels neither rule defines are left out (the caller's own error names them)."""
    from flexarm.control.lti import FILTER_KINDS, digital_filter

    sig = log.signals if hasattr(log, "signals") else log
    where = name or getattr(log, "name", "log")
    chans = {n: _spec(sensors, n) for n in sensors}
    src = {n: c.get("signal") or n for n, c in chans.items()}

    default = {"gain": 1.0, "delay": 0.0, "zeroing": 0.0, "cutoff": 0.0, "damping": 0.9}

    def same(a: dict, b: dict, keys) -> bool:
        return all(
            float(va if (va := a.get(k)) is not None else default[k])
            == float(vb if (vb := b.get(k)) is not None else default[k])
            for k in keys
        )

    out: dict[str, np.ndarray] = {}
    notes: list[str] = []
    for c, spec in chans.items():
        f = spec.get("filter")
        if not f or c in sig:
            continue
        fe = f.get("discretisation", "forward_euler") == "forward_euler"
        rate = FILTER_KINDS.get(f["kind"]) == 1
        # a rate does not see a constant: the zeroing need not match (docstring)
        matched = ("gain", "delay") if rate else ("gain", "delay", "zeroing")

        def zeroing_note(n: str, spec=spec, c=c) -> str:
            zc, zn = float(spec.get("zeroing") or 0.0), float(chans[n].get("zeroing") or 0.0)
            if zc == zn:
                return ""
            return (
                f"; {n!r} is zeroed over {zn:g} s and {c!r} over {zc:g} s: zeroing subtracts "
                "a constant, which leaves the rate as it is after the window (and the "
                "filter's memory); inside the window the zeroed channel reads 0"
            )

        if rate and fe:
            sib = [
                n
                for n, o in chans.items()
                if n in sig
                and src[n] == src[c]
                and o.get("filter")
                and o["filter"]["kind"] == "lowpass2"
                and same(o["filter"], f, ("cutoff", "damping"))
                and o["filter"].get("discretisation", "forward_euler") == "forward_euler"
                and same(o, spec, matched)
            ]
            if sib:
                x1 = np.asarray(sig[sib[0]], float)
                if x1.size >= 3:
                    v = np.empty_like(x1)
                    v[:-1] = np.diff(x1) / dt
                    v[-1] = 2 * v[-2] - v[-3]
                    out[c] = v
                    notes.append(
                        f"{where}: {c!r} is not logged: computed from the logged "
                        f"{sib[0]!r} (the rate state of its {f['kind']} filter, "
                        "ξ₂ = Δξ₁/T; the last sample extrapolated)" + zeroing_note(sib[0])
                    )
                    continue
        raw = [
            n
            for n, o in chans.items()
            if n in sig
            and src[n] == src[c]
            and not o.get("filter")
            and (rate or same(o, spec, ("zeroing",)))
            and float(o.get("gain", 1.0)) != 0.0
        ]
        if not raw:
            continue
        r = chans[raw[0]]
        u = (np.asarray(sig[raw[0]], float) - _logged_offset(r)) * (
            float(spec.get("gain", 1.0)) / float(r.get("gain", 1.0))
        ) + _logged_offset(spec)
        q = float(spec.get("quantum", 0.0) or 0.0)
        if q <= 0 and int(spec.get("bits", 0) or 0) > 0:
            q = float(spec["range"]) / 2 ** int(spec["bits"])
        if q > 0:
            u = np.round(u / q) * q
        shift = int(spec.get("delay", 0) or 0) - int(r.get("delay", 0) or 0)
        u = _shift(u, -int(r.get("delay", 0) or 0))
        v, _ = digital_filter(f, dt, where=f"sensor {c!r}: filter").run(u)
        out[c] = _shift(v, int(spec.get("delay", 0) or 0))
        notes.append(
            f"{where}: {c!r} is not logged: computed from the logged {raw[0]!r} "
            f"through its {f['kind']} filter (as the sensor stage runs it, from rest "
            "on the log's first sample"
            + (f"; delay {shift:+d} samples" if shift else "")
            + ")"
            + zeroing_note(raw[0])
        )
    return out, notes


def _shift(x: np.ndarray, d: int) -> np.ndarray:
    """x delayed by d samples (d < 0: advanced), the ends held."""
    if d == 0 or x.size == 0:
        return x
    if d > 0:
        return np.concatenate([np.full(min(d, x.size), x[0]), x[:-d]])[: x.size]
    d = -d
    return np.concatenate([x[d:], np.full(min(d, x.size), x[-1])])[: x.size]
