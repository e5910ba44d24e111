"""The sensors' pure delays searched by the general fit (:func:`search_delays`, option
:class:`~flexarm.identification.time_domain.options.DelaySearch`, issue #23).

Each sensor channel c reads the plant d_c whole samples late (``sensors.c.delay``). In the
simulated loop (:mod:`flexarm.sim.sampled`) the delays are static integers (the length of
each channel's delay buffer), so least squares cannot move them; they are searched apart,
after the local stage of :func:`~flexarm.identification.time_domain.general.fit_scenario`
(after the quantised pass of its continuation, where there is one), by neighbours
coordinate descent — the general engine's form of the servo-rig engine's
``delay_search="neighbours"``:

1. Start from the scenario's delays d and the local stage's optimum z*.
2. For each searched channel c and each neighbour d_c − 1, d_c + 1 in 0 … ``max_delay``:
   the engine of the scenario with that one delay changed (its segments' start states,
   rates and delay buffers read off the logs with that delay, ``_Engine._init_data``) and
   its cost Σ r² of eqs. (1)–(2) at z* (``_Engine.residuals``, the local stage's own
   residuals). Every configuration, the current one included, is evaluated from the same
   start states: on whole logs (and segments without estimated node states) those read
   off the log; where the local stage estimated the segments' node states, the optimum's
   offsets with each segment's residuals projected off the span of its state Jacobian
   (:func:`profiled`: each delay with its own best start states, to first order). The
   states read off a real log are far off (unit 6, 1 s segments: cost 11,900 against 319
   at the local optimum), so that a comparison from them drifted the tip delay 56 → 46
   samples; the optimum's offsets held as they are favour the current delays (a start
   state absorbs part of a segment's shift in time).
3. Move to the lowest neighbour when it lowers the current cost C by more than the cost's
   resolution, ``COST_RESOLUTION`` · C / E[Σ r²] (the local stage's own stopping rule,
   :data:`~flexarm.identification.time_domain.general.COST_RESOLUTION`: a tenth of a
   standard deviation in units of the misfit's realised variance); repeat from the new
   delays until no neighbour does.
4. If a delay moved, the local stage runs again from z* at the chosen delays (node states
   estimated as before) and steps 2–4 repeat at its optimum (a round): z* fitted at wrong
   delays is biased (e.g. a viscous friction that shifts the phase to make up for a
   sensor's lag) and its cost can prefer a delay short of the truth; the rounds end when a
   round moves no delay, or after ``max_moves`` moves of one sample in all. A round whose
   local stage ends no lower than the lowest so far (the fit's own optimum first) is
   undone, and the rounds end at those delays (``record["undone"]``): the comparison at a
   fixed z* can favour a delay that the refit does not (the 4/27 rotary session: tip 55 →
   54 samples raised the refitted cost 30,320 → 33,330).
5. Node states estimated: each moved channel's last move is checked by the local stage
   one sample back, kept back while that lowers the local stage's cost (a z fitted at the
   current delays can carry a compensating move of another channel: on the tests' two-mode
   link the hub's delay went 0 → 1 with the tip's 0 → 3 and came back to 0, the truth).
   The fit goes on (polish, covariance, prediction) with the scenario carrying the chosen
   delays.

One engine per delay configuration, cached by the tuple of every channel's delay (a new
configuration is a new compilation of the loop: 9–12 s each for the tests' two-mode link
on this machine, most of the search's time). A descent from d to d + k
costs about 2k + 2 evaluations per searched channel; the cost's neighbours need not be
unimodal in the delay (an oscillating channel's cost has local minima a period apart), so
start the scenario's delays within a few samples of the truth, or widen with ``max_delay``
only together with a sensible start.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from flexarm.identification.time_domain.options import COST_RESOLUTION

__all__ = ["DelayFound", "search_delays", "searched_channels"]


@dataclasses.dataclass
class DelayFound:
    """The outcome of :func:`search_delays`: ``record`` (``stages["delay_search"]``:
    per searched channel ``{"from": d0, "to": d}`` samples, the number of cost evaluations
    and of moves, ``costs``: per round the cost Σ r² of every delay configuration evaluated
    at that round's optimum, keyed ``"name=d, ..."`` over every sensor channel, seconds);
    where a delay moved, the ``scenario`` with the chosen delays, its ``engine`` and
    ``local``, the local stage's (res, r, J, info) rerun there; else ``local`` is None."""

    record: dict
    scenario: Any = None
    engine: Any = None
    local: tuple | None = None


def searched_channels(search, eng) -> list[str]:
    """The channels whose delay ``search`` (a :class:`DelaySearch`) moves, checked against
    the engine's sensor channels: ``search.channels``, or every channel the fit compares.
    Bad input is one ``ValueError`` naming the field, the value and the fix."""
    for name in ("max_delay", "max_moves"):
        v = getattr(search, name, None)
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
            raise ValueError(
                f"DelaySearch.{name} = {v!r}: give a whole number of samples >= 0 "
                f"(default {20 if name == 'max_delay' else 10})"
            )
    chans = getattr(search, "channels", None)
    if chans is None:
        return list(eng.channels)
    if isinstance(chans, str):
        raise ValueError(
            f"DelaySearch.channels = {chans!r}: give a list of channel names, e.g. [{chans!r}]"
        )
    out = list(chans)
    for c in out:
        if c not in eng.names:
            raise ValueError(
                f"DelaySearch.channels: {c!r} is not a sensor channel of scenario "
                f"{eng.template.name!r}; channels: {', '.join(eng.names)}"
            )
    if not out:
        raise ValueError(
            "DelaySearch.channels = []: name at least one sensor channel, or None for every "
            f"channel the fit compares ({', '.join(eng.channels)})"
        )
    return list(dict.fromkeys(out))


def _with_delays(scenario, delays: dict[str, int]):
    """``scenario`` with the sensors' ``delay`` (samples) set from ``delays``."""
    sensors = dict(scenario.sensors)
    for c, d in delays.items():
        if c not in sensors:  # a channel of the loop the scenario leaves at its defaults
            if int(d) == 0:
                continue
            raise ValueError(
                f"DelaySearch: channel {c!r} has no [sensors.{c}] table in scenario "
                f"{scenario.name!r} to carry a delay of {int(d)} samples; add the table, or "
                "leave the channel out of DelaySearch.channels"
            )
        sensors[c] = sensors[c].model_copy(update={"delay": int(d)})
    return scenario.model_copy(update={"sensors": sensors})


def search_delays(
    scenario,
    eng,
    z: np.ndarray,
    *,
    engine: Callable[[Any], Any],
    local: Callable[[Any, np.ndarray], tuple],
    progress=None,
    offsets: np.ndarray | None = None,
    state_blocks: list | None = None,
) -> DelayFound:
    """Neighbours coordinate descent over the sensors' delays from ``scenario``'s and the
    local optimum ``z`` of ``eng`` (the fit's engine at those delays), the local stage
    again at the chosen delays, in rounds until the delays stay (module docstring).
    ``eng.options.delay_search`` is the :class:`DelaySearch`; ``engine(scenario)`` builds
    the fit's engine for a scenario (the same logs, free list and options) and ``local(eng,
    z0)`` runs the fit's local stage on it from z0, returning (res, r, J, info)
    (:func:`~flexarm.identification.time_domain.general.fit_scenario` passes both).
    ``offsets``, ``state_blocks``: the segments' start-state offsets at ``z`` (multiple
    shooting with node states estimated, in units of ``eng.state_scale``) and, per segment,
    (first row, last row, Q) of its state Jacobian's orthonormal basis (``_local``'s
    ``res.state_blocks``): each delay is then compared with the start states profiled out
    (:func:`profiled`), not with the states read off the log, whose error on a real log
    outweighs a delay's (unit 6, 1 s segments: cost 11,900 against 319 at the local
    optimum, and the tip delay drifted 56 → 46 samples).
    """
    options = eng.options
    search = options.delay_search
    chans = searched_channels(search, eng)
    say = progress or (lambda msg: None)
    t0 = time.perf_counter()
    names = list(eng.names)
    d0 = {c: int(d) for c, d in zip(names, eng.delays, strict=True)}
    engines: dict[tuple, Any] = {tuple(d0[c] for c in names): eng}

    def engine_at(d: dict[str, int]):
        key = tuple(d[c] for c in names)
        if key not in engines:
            engines[key] = engine(_with_delays(scenario, d))
        return engines[key]

    # node states estimated (multiple shooting): each delay compared with the segments'
    # start states profiled out to first order around the local optimum's (``blocks``)
    held = [None if offsets is None or not np.any(offsets) else np.asarray(offsets), eng]

    def cost(d: dict[str, int], z: np.ndarray, costs: dict[str, float]) -> float:
        """Σ r² (eqs. (1)–(2)) of the delays ``d`` at ``z``: from the states read off the
        log, or (node states estimated) from the local optimum's offsets to that reading
        with the part of r that a change of the start states explains removed, segment
        by segment (r − Q_s Q_sᵀ r, Q_s an orthonormal basis of the optimum's state
        Jacobian's columns): the cost with each delay's own best start states, to first
        order."""
        key = _label(d, names)
        if key not in costs:
            e = engine_at(d)
            off, ref = held
            if off is None:
                r = e.residuals(np.asarray(z)[None])[0]
            else:
                r = e.residuals(np.asarray(z)[None], (off * ref.state_scale / e.state_scale)[None])[
                    0
                ]
                r = profiled(r, blocks[0])
            costs[key] = float(r @ r)
        return costs[key]

    blocks = [state_blocks]

    resolution = COST_RESOLUTION / eng.expected_cost()  # relative, as the local stage's ftol
    cur, moves, found = dict(d0), 0, None
    rounds: list[dict[str, float]] = []
    # the lowest local-stage cost so far (first: the fit's own optimum at the scenario's
    # delays): a round whose local stage ends higher is undone and the rounds end (the
    # descent at a fixed z can favour a delay that the refit does not)
    r0 = eng.residuals(np.asarray(z)[None], None if offsets is None else offsets[None])[0]
    kept: dict[str, Any] = {"cost": float(r0 @ r0), "cur": dict(d0), "found": None, "z": z}
    kept.update(held=list(held), blocks=state_blocks)
    undone: dict[str, Any] | None = None
    while True:  # rounds: a descent at the optimum z, then the local stage at its delays
        costs: dict[str, float] = {}
        start = dict(cur)
        c_cur = cost(cur, z, costs)
        while moves < search.max_moves:
            best, c_best = None, c_cur
            for c in chans:
                for step in (-1, 1):
                    if 0 <= cur[c] + step <= search.max_delay:
                        cand = {**cur, c: cur[c] + step}
                        if cost(cand, z, costs) < c_best:
                            best, c_best = cand, cost(cand, z, costs)
            if best is None or c_cur - c_best <= resolution * c_cur:
                break
            cur, c_cur = best, c_best
            moves += 1
            say(f"  delays {_label(cur, chans)}: cost {c_cur:.6g} at the local optimum")
        rounds.append(costs)
        if cur == start:
            break
        e = engine_at(cur)
        found = local(e, np.clip(z, e.lo, e.hi))
        z = np.clip(found[0].x, e.lo, e.hi)
        if held[0] is not None:
            held[:] = [np.asarray(found[0].offsets), e]
            blocks[0] = getattr(found[0], "state_blocks", None)
        info = found[3]
        say(
            f"local stage at delays {_label(cur, chans)}: cost {info['cost']:.4g} after "
            f"{info['nfev']} evaluations ({info['message']})"
        )
        if info["cost"] >= kept["cost"] * (1 - resolution):
            undone = {"delays": _label(cur, chans), "cost": float(info["cost"])}
            say(
                f"  undone: higher than {kept['cost']:.4g} at delays "
                f"{_label(kept['cur'], chans)}, where the search ends"
            )
            cur, found, z = dict(kept["cur"]), kept["found"], kept["z"]
            held[:], blocks[0] = kept["held"], kept["blocks"]
            break
        kept = {"cost": float(info["cost"]), "cur": dict(cur), "found": found, "z": z}
        kept.update(held=list(held), blocks=blocks[0])
        if moves >= search.max_moves:
            break
    # node states estimated: each moved channel's last move checked by the local stage
    # one sample back (z then fitted at that delay too): the descent compares delays at a
    # z fitted to the current ones, which can carry a compensating move of another channel
    # (the tests' two-mode link: the hub's delay 0 → 1 while its tip's went 0 → 3)
    confirmed: list[dict[str, Any]] = []
    if found is not None and held[0] is not None:
        for c in chans:
            back = -1 if cur[c] > d0[c] else 1
            while cur[c] != d0[c]:
                cand = {**cur, c: cur[c] + back}
                e = engine_at(cand)
                trial = local(e, np.clip(z, e.lo, e.hi))
                c_old, c_new = found[3]["cost"], trial[3]["cost"]
                confirmed.append({"delays": _label(cand, chans), "cost": c_new, "kept": c_old})
                if c_new >= c_old * (1 - resolution):
                    break
                cur, found = cand, trial
                z = np.clip(trial[0].x, e.lo, e.hi)
                say(f"local stage at delays {_label(cur, chans)}: cost {c_new:.4g}, lower")
    moved = [c for c in chans if cur[c] != d0[c]]
    record = {
        "channels": {c: {"from": d0[c], "to": cur[c]} for c in chans},
        "evaluations": sum(len(c) for c in rounds),
        "moves": moves,
        "costs": rounds,
        "confirmed": confirmed,
        "undone": undone,
        "seconds": round(time.perf_counter() - t0, 2),
    }
    say(
        "delay search: "
        + (", ".join(f"{c} {d0[c]} → {cur[c]}" for c in moved) or "the scenario's delays kept")
        + f" samples after {record['evaluations']} evaluations in {len(rounds)} round(s)"
    )
    if found is None:
        return DelayFound(record)
    return DelayFound(record, _with_delays(scenario, cur), engine_at(cur), found)


def profiled(r: np.ndarray, blocks: list | None) -> np.ndarray:
    """Residuals ``r`` with each segment's rows [a, b) projected off the span of its start
    states' Jacobian, Q (orthonormal): r − Q (Qᵀ r), the Gauss–Newton step on the states
    taken (their first-order best); ``blocks`` None or rows that no longer line up: ``r``."""
    if not blocks or blocks[-1][1] > r.shape[0]:
        return r
    r = r.copy()
    for a, b, Q in blocks:
        r[a:b] -= Q @ (Q.T @ r[a:b])
    return r


def _label(d: dict[str, int], chans: Sequence[str]) -> str:
    return ", ".join(f"{c}={d[c]}" for c in chans)
