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
   residuals). Every configuration, the current one included, is evaluated with the node
   states read off the log (no estimated offsets: those are fitted to one delay; a start
   state absorbs an error of the start, not a shift of a whole segment in time).
3. Move to the lowest neighbour when it lowers the current cost C by more than the cost's
   resolution, ``COST_RESOLUTION`` · C / E[Σ r²] (the local stage's own stopping rule,
   :data:`~flexarm.identification.time_domain.general.COST_RESOLUTION`: a tenth of a
   standard deviation in units of the misfit's realised variance); repeat from the new
   delays until no neighbour does.
4. If a delay moved, the local stage runs again from z* at the chosen delays (node states
   estimated as before) and steps 2–4 repeat at its optimum (a round): z* fitted at wrong
   delays is biased (e.g. a viscous friction that shifts the phase to make up for a
   sensor's lag) and its cost can prefer a delay short of the truth; the rounds end when a
   round moves no delay, or after ``max_moves`` moves of one sample in all. The fit goes
   on (polish, covariance, prediction) with the scenario carrying the chosen delays.

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
) -> DelayFound:
    """Neighbours coordinate descent over the sensors' delays from ``scenario``'s and the
    local optimum ``z`` of ``eng`` (the fit's engine at those delays), the local stage
    again at the chosen delays, in rounds until the delays stay (module docstring).
    ``eng.options.delay_search`` is the :class:`DelaySearch`; ``engine(scenario)`` builds
    the fit's engine for a scenario (the same logs, free list and options) and ``local(eng,
    z0)`` runs the fit's local stage on it from z0, returning (res, r, J, info)
    (:func:`~flexarm.identification.time_domain.general.fit_scenario` passes both)."""
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

    def cost(d: dict[str, int], z: np.ndarray, costs: dict[str, float]) -> float:
        """Σ r² (eqs. (1)–(2)) of the delays ``d`` at ``z``, node states off the log."""
        key = _label(d, names)
        if key not in costs:
            r = engine_at(d).residuals(np.asarray(z)[None])[0]
            costs[key] = float(r @ r)
        return costs[key]

    resolution = COST_RESOLUTION / eng.expected_cost()  # relative, as the local stage's ftol
    cur, moves, found = dict(d0), 0, None
    rounds: list[dict[str, float]] = []
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
        info = found[3]
        say(
            f"local stage at delays {_label(cur, chans)}: cost {info['cost']:.4g} after "
            f"{info['nfev']} evaluations ({info['message']})"
        )
        if moves >= search.max_moves:
            break
    moved = [c for c in chans if cur[c] != d0[c]]
    record = {
        "channels": {c: {"from": d0[c], "to": cur[c]} for c in chans},
        "evaluations": sum(len(c) for c in rounds),
        "moves": moves,
        "costs": rounds,
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


def _label(d: dict[str, int], chans: Sequence[str]) -> str:
    return ", ".join(f"{c}={d[c]}" for c in chans)
