"""The servo rig's log check: what a servo-rig fit or prediction needs of a log.

Logs are read by the one loader, :func:`flexarm.io.logformat.load_log` (text or ``.mat``,
through a log-format file), into the one log type :class:`flexarm.io.logs.Log`, which
carries the controller the lab ran (``controller``, per-sample ``gains``, ``voltage_limit``,
``rate``). A servo-rig log holds ``time`` (s), ``reference`` (rad, the commanded hub angle)
and at least one output, ``motor_angle`` (rad) or ``tip_deflection`` (m); ``voltage`` (V,
the command) is needed for open-loop replay. :func:`load_rig_log` reads one and checks
that (:func:`check_rig_log`); :func:`check_closed_loop` checks what a closed-loop replay
needs (the law and the signals it reads); :func:`as_rig_log` takes a path or a log.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from flexarm.errors import FlexarmError
from flexarm.io import logformat as _lf
from flexarm.io.logformat import GAIN_UNITS, LogFormat
from flexarm.io.logs import MAX_JITTER, RIG_OUTPUTS, Log, LogError

#: Relative difference of two sampling periods taken as the same period (a logger's
#: rounding or time-stamp jitter, not another rate).
PERIOD_TOL = 1e-3

OUTPUTS = RIG_OUTPUTS
#: The state-feedback gains in the order of :attr:`Log.gains`, with their SI units.
GAINS: dict[str, str] = GAIN_UNITS["state_feedback"]
#: Fewest samples in a servo-rig log (and in a window of one).
MIN_BENCH_SAMPLES = 64


class FitInputError(FlexarmError, ValueError):
    """Input a fit or a validation cannot use; the message names the file, the field and
    what to do."""


def check_rig_log(log: Log) -> Log:
    """A servo-rig log needs a usable output: ``motor_angle`` and/or ``tip_deflection``,
    not constant. Returns the log; raises :class:`FitInputError` naming the file."""
    present = [c for c in OUTPUTS if c in log.signals]
    if not log.outputs:
        why = (
            f"column(s) {', '.join(present)} are constant"
            if present
            else f"no column {' or '.join(OUTPUTS)} (found: {', '.join(log.signals)})"
        )
        raise FitInputError(
            f"{log.where}: no usable output column: {why}; the fit needs the "
            "hub angle motor_angle (rad) and/or the tip deflection "
            "tip_deflection (m) as measured; map other names with columns="
        )
    return log


def load_rig_log(
    path: str | Path,
    log_format: str | Path | LogFormat | None = None,
    *,
    columns: Mapping[str, str | int] | None = None,
    units: Mapping[str, str] | None = None,
    controller: Any = None,
    max_jitter: float = MAX_JITTER,
    min_samples: int = MIN_BENCH_SAMPLES,
) -> Log:
    """One servo-rig log: :func:`flexarm.io.logformat.load_log` (``time`` and ``reference``
    required) and :func:`check_rig_log`; a problem is one :class:`FitInputError` line."""
    try:
        log = _lf.load_log(
            path,
            log_format,
            controller=controller,
            columns=columns,
            units=units,
            required=("time", "reference"),
            min_samples=min_samples,
            max_jitter=max_jitter,
            hint="A bench log needs time (s), reference (rad, the commanded "
            "hub angle) and motor_angle and/or tip_deflection.",
        )
    except LogError as exc:
        raise FitInputError(str(exc)) from None
    return check_rig_log(log)


def load_rig_logs(paths, formats=None, **kw) -> list[Log]:
    """:func:`load_rig_log` for each path with its format as
    :func:`flexarm.io.logformat.formats_for` chooses it (one for all, one per log, or
    ``PATTERN=FILE``); ``kw`` as there (``controller``, ``columns``, ``units``,
    ``max_jitter``, ``min_samples``)."""
    try:
        fmts = _lf.formats_for(paths, formats)
    except LogError as exc:
        raise FitInputError(str(exc)) from None
    return [load_rig_log(p, f, **kw) for p, f in zip(paths, fmts, strict=True)]


def controller_from_any(c: Any, source: str):
    """:func:`flexarm.io.logformat.controller_from_any` with errors as :class:`FitInputError`."""
    try:
        return _lf.controller_from_any(c, source)
    except LogError as exc:
        raise FitInputError(str(exc)) from None


def as_rig_log(x: Any, controller: Any = None, **kw) -> Log:
    """A path or a :class:`Log` (with ``controller`` overriding its declaration and its
    gains); ``kw`` go to :func:`load_rig_log` (``log_format=``, ``columns=``, ...)."""
    if isinstance(x, Log):
        if controller is not None:
            from dataclasses import replace

            return replace(
                x,
                controller=controller_from_any(controller, f"{x.where}: controller option"),
                gains=None,
                rate=None,
            )
        return x
    fmt = kw.pop("log_format", None)
    return load_rig_log(x, fmt, controller=controller, **kw)


def check_closed_loop(log: Log) -> None:
    """A closed-loop fit/validation needs the controller and the signals it reads."""
    c = log.controller
    if c is None:
        raise FitInputError(
            f"{log.where}: field 'controller': no controller declared; add a line "
            "'# controller: state_feedback K1=.. K2=.. K3=.. K4=..' (or 'pd KP=.. KD=..') "
            "before the header, pass controller=... (--controller), or fit in open-loop "
            "replay (mode='open_loop', needs a voltage column)"
        )
    if "motor_angle" not in log.signals:
        raise FitInputError(
            f"{log.where}: field 'motor_angle': the controller "
            "closes on the hub angle, but the log has no motor_angle column"
        )
    if (c.k2 != 0 or c.k4 != 0) and "tip_deflection" not in log.signals:
        raise FitInputError(
            f"{log.where}: field 'tip_deflection': the controller "
            f"uses the tip deflection (K2 = {c.k2:g}, K4 = {c.k4:g}) but the "
            "log has no tip_deflection column"
        )


def pieces(logs, seconds: float) -> tuple[list[Log], list[int]]:
    """Multiple shooting for the rotary servo's engine (``ServoRig.segment``): each log cut
    into consecutive windows [k L, (k + 1) L) s of ``seconds`` = L from its first sample
    (:meth:`flexarm.io.logs.Log.window`; a remainder shorter than L / 2 joins the piece
    before it). Each piece is then fitted as a log of its own, started from its own
    estimated state. Returns the pieces and, per piece, the index of its log."""
    if not (isinstance(seconds, (int, float)) and np.isfinite(seconds) and seconds > 0):
        raise FitInputError(
            f"ServoRig.segment = {seconds!r}: give the multiple-shooting segment in s > 0 "
            "(e.g. 2.5), or None for whole logs"
        )
    out: list[Log] = []
    owner: list[int] = []
    for i, g in enumerate(logs):
        span = len(g) * g.dt
        n = max(int(span // seconds), 1)
        if span - n * seconds >= seconds / 2:
            n += 1
        for k in range(n):
            t1 = (k + 1) * seconds if k < n - 1 else span + g.dt
            out.append(g.window(k * seconds, t1))
            owner.append(i)
    return out, owner


#: the input channels a declared state-feedback law's per-sample gains are read from
GAIN_SIGNALS = tuple(f"gain_K{i}" for i in range(1, 5))


def declared_laws(scenario, logs: list[Log]) -> tuple[Any, list[Log]] | None:
    """Servo-rig logs that each declare the law they ran (their own K1..K4, constant or
    a schedule in the file) as ONE closed loop: ``scenario`` with a state-feedback
    controller that reads its gains per sample from the input channels
    :data:`GAIN_SIGNALS`, and the logs carrying their gains in those channels (u =
    K1(r − θ) − K2 d − K3 θ̇ − K4 ḋ with each log's K of each sample). So a fit and a
    prediction run every log in one batch with the law it ran (the lab's gains differ
    between runs). None where the laws differ in more than their gains (the rate filter):
    each log then runs alone (:func:`flexarm.identification.time_domain.predict.predict`)."""
    from dataclasses import replace

    laws = []
    for g in logs:
        law = g.controller.model_dump(mode="json", exclude_none=True)
        for k in ("k1", "k2", "k3", "k4", "gain_signals"):
            law.pop(k, None)
        laws.append(law)
    if any(law != laws[0] for law in laws[1:]):
        return None
    out = []
    for g in logs:
        c = g.controller
        k = (
            np.asarray(g.gains, float)
            if g.gains is not None
            else np.tile(
                np.array([c.k1, c.k2, c.k3, c.k4], float), (len(g.signals["reference"]), 1)
            )
        )
        sig = dict(g.signals)
        sig.update({n: k[:, i].copy() for i, n in enumerate(GAIN_SIGNALS)})
        out.append(replace(g, signals=sig))
    law = logs[0].controller.model_dump(mode="json", exclude_none=True)
    law["gain_signals"] = list(GAIN_SIGNALS)
    return scenario.with_controllers({"controller": law}, source="the logs' declared laws"), out
