"""Replay a log on a scenario: the logged setpoints as references, the initial state and the
sensor filters' states from the log's first sample, and fit % per logged channel,
100 (1 − ‖y − ŷ‖ / ‖y − mean y‖) (:func:`flexarm.metrics.fit_percent`).

For a multi-link arm the initial state is read off the log where it holds the channels
(``theta_j``, else 0; the link deflection α_j from ``alpha_j`` or, when only the filtered
``alpha_f_j`` is logged, from it: the filter's output lags α, exact at rest; rates from
``theta_dot_j`` / ``theta_dot_f_j`` and ``alpha_dot_j`` / ``alpha_dot_f_j``, else 0), the
digital filters' states by :func:`flexarm.sim.filters.filter_state_from_log`. Reference
channels the scenario uses (its ``[references]`` and the controller's setpoints) are taken
from the log when it holds them. A dynamic LTI controller replayed from inside a log starts
from its state run over the log before the window (:func:`flexarm.control.lti.state_from_log`).
Filtered channels the log lacks but its signals define (the lab's rates of a logged angle)
are computed through the channel's filter (:func:`flexarm.sim.filters.computed_channels`)
for the start states, not compared; :attr:`Replay.notes` says which.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from flexarm.io.logs import PERIOD_TOLERANCE, Log, on_sample_grid
from flexarm.metrics import fit_percent
from flexarm.sim.build import disturbance_inputs, prepare, to_result
from flexarm.sim.filters import (
    PieceStart,
    computed_channels,
    continuous_starts,
    filter_state_from_log,
    start_piece,
    warn_assumed_start,
    with_filter_state,
)
from flexarm.sim.result import SimulationResult
from flexarm.sim.sampled import check_zeroing, logged_offset, simulate_loop


@dataclass
class Replay:
    """A replayed log: the simulation, the log (its window) and fit % per channel."""

    result: SimulationResult
    log: Log
    fit_percent: dict[str, float] = field(default_factory=dict)
    #: channels the log lacks, computed from logged ones (:func:`computed_channels`)
    notes: list[str] = field(default_factory=list)


def _first(log: Log, names: list[str], default: float = 0.0, off: dict | None = None) -> float:
    """The first logged value of the first of ``names`` the log holds, less the channel's
    zero offset (``off``: channel → the offset its reading carries), else ``default``."""
    for n in names:
        if n in log.signals:
            return float(log[n][0]) - (off or {}).get(n, 0.0)
    return float(default)


def initial_state_from_log(prepared, log: Log) -> np.ndarray:
    """The plant state at the log's first sample (module docstring). A single link: the
    hub's ``motor_angle`` and ``motor_velocity`` and the ``tip_deflection`` where the log
    holds them, else the scenario's ``[initial]`` values (the link at rest relative to the
    hub, statically bent to the tip deflection). The zero offset a channel's output carries
    (its ``offset``; 0 on a zeroed channel, times the DC gain of a digital filter: 0 for a
    rate: :func:`flexarm.sim.sampled.logged_offset`) is subtracted."""
    model, arm = prepared.model, prepared.loop.plant
    sens = prepared.loop.sensors
    off = dict(zip(sens.names, np.asarray(logged_offset(sens, True), float).tolist(), strict=True))
    if getattr(model, "n_links", None) is None:
        ini = prepared.scenario.initial
        return np.asarray(
            model.initial_state(
                _first(log, ["motor_angle"], ini.motor_angle, off),
                _first(log, ["motor_velocity"], ini.motor_velocity, off),
                _first(log, ["tip_deflection"], ini.tip_deflection, off),
            ),
            float,
        )
    n = model.n_links
    if any(m != 1 for m in model.n_modes):
        raise ValueError(
            "replay: the initial deflection is read as one angle α_j per link "
            f"(torsional links); this arm has modes {model.n_modes}"
        )
    th = [_first(log, [f"theta_{j}"], 0.0, off) for j in range(1, n + 1)]
    al = [_first(log, [f"alpha_{j}", f"alpha_f_{j}"], 0.0, off) for j in range(1, n + 1)]
    thd = [_first(log, [f"theta_dot_{j}", f"theta_dot_f_{j}"], 0.0, off) for j in range(1, n + 1)]
    ald = [_first(log, [f"alpha_dot_{j}", f"alpha_dot_f_{j}"], 0.0, off) for j in range(1, n + 1)]
    x = model.state(theta=th, delta=al, theta_dot=thd, delta_dot=ald)
    return np.concatenate([x, np.zeros(arm.n_states - len(x))])


def replay(
    scenario,
    log: Log,
    *,
    window: tuple[float, float] | None = None,
    start: PieceStart | None = None,
    period_tolerance: float = PERIOD_TOLERANCE,
) -> Replay:
    """Simulate ``scenario`` over ``log`` (or its ``window`` [t0, t1) in s from the log's
    first sample) and compare every measured channel the log holds. ``start``: the
    controllers' and filters' states at the log's first sample (:func:`replay_run`).
    A log whose clock is off the scenario's period by at most ``period_tolerance``
    (relative) is read on the scenario's grid, with a note
    (:func:`flexarm.io.logs.on_sample_grid`); beyond it, a one-line error."""
    if log.time is None:
        raise ValueError(f"{log.name}: replay needs the log's time")
    extra, notes = computed_channels(scenario.sensors, log, scenario.sampling.period)
    logged = set(log.signals)
    if extra:
        log = Log(
            log.path,
            log.time,
            {**log.signals, **extra},
            list(log.comments),
            dict(log.meta),
            list(log.skipped),
            list(log.notes) + notes,
        )
    full, k0 = log, 0
    assert full.time is not None  # checked above
    if window is not None:
        log = log.window(*window)
        assert log.time is not None  # a window of a log with time
        k0 = int(np.searchsorted(full.time, log.time[0] - 1e-6 * full.dt))
    dt = scenario.sampling.period
    log, clock = on_sample_grid(log, dt, period_tolerance)
    if clock is not None:
        notes = [*notes, clock]
    n = len(log)
    duration = (n - 1) * dt
    sim = scenario.simulation.model_copy(update={"duration": duration})
    sc = scenario.model_copy(update={"simulation": sim})
    # the logged setpoints: the channels the scenario's controllers read, and the
    # single link's ``reference`` column where the log holds it
    used = set(sc.references) | sc.controller_references() | {"reference"}
    refs = {k: log[k] for k in sorted(used) if k in log.signals}
    refs.update(disturbance_inputs(sc, log))
    p = prepare(sc, references=refs)
    assert p.n_samples == n, (p.n_samples, n)
    check_zeroing(p.loop.sensors, n, dt, log.name)
    x0 = initial_state_from_log(p, log)
    loop = p.loop
    if start is not None:
        loop = start_piece(loop, start)
    elif k0 > 0:  # the history before the window: filters and controllers run over it
        head = Log(full.path, full.time[:k0], {k: v[:k0] for k, v in full.signals.items()})
        loop = start_piece(loop, continuous_starts(loop, sc.sensors, [head, log], dt)[1])
    else:
        states = filter_state_from_log(sc.sensors, full, k0, dt)
        if states:
            loop = with_filter_state(loop, states)
        warn_assumed_start(loop, log.name)
    out = simulate_loop(loop, x0, p.references, n, seed=sc.simulation.seed)
    p.loop, p.x0 = loop, x0
    res = to_result(p, out)
    fp = {k: fit_percent(log[k], res.measured[k]) for k in res.measured if k in logged}
    return Replay(res, log, {k: v for k, v in fp.items() if not math.isnan(v)}, notes)


def replay_run(
    scenario,
    logs: list[Log],
    *,
    continuous: bool = False,
    period_tolerance: float = PERIOD_TOLERANCE,
) -> list[Replay]:
    """Replay each of ``logs``; with ``continuous`` they are consecutive pieces of one run, in
    order: each piece's plant starts from its logged state and its dynamic controllers and
    digital filters from the states run over the pieces before
    (:func:`flexarm.sim.filters.continuous_starts`). Without it, a dynamic controller
    starting a log from its assumed state is a warning naming it."""
    if not continuous:
        return [replay(scenario, lg, period_tolerance=period_tolerance) for lg in logs]
    dt = scenario.sampling.period
    logs = [on_sample_grid(lg, dt, period_tolerance)[0] for lg in logs]
    sim = scenario.simulation.model_copy(update={"duration": (len(logs[0]) - 1) * dt})
    sc = scenario.model_copy(update={"simulation": sim})
    used = set(sc.references) | sc.controller_references() | {"reference"}
    refs = {k: logs[0][k] for k in used if k in logs[0].signals}
    p = prepare(sc, references={**refs, **disturbance_inputs(sc, logs[0])})
    starts = continuous_starts(p.loop, sc.sensors, logs, dt)
    return [
        replay(scenario, lg, start=st, period_tolerance=period_tolerance)
        for lg, st in zip(logs, starts, strict=True)
    ]


def as_prediction(rep: Replay, scenario: str = "replay"):
    """The replay as a :class:`~flexarm.identification.time_domain.predict.Prediction` of one
    log (key: the log's name), so that it is drawn by the one overlay figure
    (:func:`~flexarm.identification.time_domain.predict.overlay_figure`)."""
    from flexarm.identification.time_domain.predict import Prediction

    names = list(rep.fit_percent)
    time = rep.log.time
    assert time is not None  # replay() refuses a log without time
    trace = {
        "time": time - time[0],
        "measured": {k: np.asarray(rep.log[k]) for k in names},
        "simulated": {k: np.asarray(rep.result.measured[k]) for k in names},
    }
    key = rep.log.name
    return Prediction(scenario, {key: dict(rep.fit_percent)}, {key: trace}, notes=list(rep.notes))


def plot_replay(rep: Replay, path, *, overwrite: bool = False, scenario: str = "replay"):
    """Overlay figure of the replay (the one overlay figure,
    :func:`~flexarm.identification.time_domain.predict.overlay_figure`): every compared
    channel, logged and simulated, with its fit %."""
    from flexarm.identification.time_domain.predict import overlay_figure
    from flexarm.io.write import save_figure

    pred = as_prediction(rep, scenario)
    fig = overlay_figure(pred, next(iter(pred.traces)))
    save_figure(fig, path, overwrite=overwrite, dpi=100)
