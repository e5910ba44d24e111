"""Bench logs: reading, checking, and the controller a log declares.

A bench log is the CSV exchange format of :mod:`flexarm.logs` with the columns of a
rig with a hub encoder and a strain gauge (SI units)::

    # controller: state_feedback K1=6 K2=-3 K3=0.213 K4=0
    time,reference,voltage,motor_angle,tip_deflection
    0.000,0.0,0.0,0.0,1.2e-3
    ...

``time`` (s) and ``reference`` (rad, the commanded hub angle) are required, and at least
one output: ``motor_angle`` (rad) or ``tip_deflection`` (m). ``voltage`` (V, the command)
is needed for open-loop replay. Other columns are kept and ignored.

The controller line (before the header) is ``# controller: state_feedback K1=.. K2=..
K3=.. K4=.. [rate=backward|filtered] [tau=..]`` or ``# controller: pd KP=.. KD=..
[rate=..] [tau=..]`` (PD on the measured hub angle, u = KP (r − θ) − KD θ̇). An explicit
``controller=`` argument overrides the log's line.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from flexarm.logs import MAX_JITTER, LogError, read_log, write_log

#: Relative difference of two sampling periods taken as the same period (a logger's
#: rounding or time-stamp jitter, not another rate).
PERIOD_TOL = 1e-3
from flexarm.specs.controllers_bench import StateFeedbackController

OUTPUTS = ("motor_angle", "tip_deflection")


class FitInputError(ValueError):
    """Input a fit or a validation cannot use; the message names the file, the field and
    what to do."""


@dataclass
class BenchLog:
    """One bench log in SI units. ``controller`` is the declared (or given) law, or None."""

    path: Path | None
    time: np.ndarray
    columns: dict[str, np.ndarray]
    meta: dict[str, str]
    controller: StateFeedbackController | None

    @property
    def name(self) -> str:
        return self.path.name if self.path is not None else "<log>"

    @property
    def dt(self) -> float:
        """The sampling period (s): the median step (within ``PERIOD_TOL`` of the nominal
        period also when the logger's time stamps jitter by a few %, logs read with a
        larger ``max_jitter``)."""
        return float(np.median(np.diff(self.time)))

    @property
    def outputs(self) -> tuple[str, ...]:
        """Output columns present and usable (not constant)."""
        return tuple(c for c in OUTPUTS if c in self.columns and np.ptp(self.columns[c]) > 0)

    def __len__(self) -> int:
        return len(self.time)


def parse_controller(text: str, source: str = "controller") -> StateFeedbackController:
    """``state_feedback K1=6 K2=-3 K3=0.213 K4=0 [rate=filtered tau=0.02]`` or
    ``pd KP=10 KD=0.3`` → the spec (a PD is the state feedback with K2 = K4 = 0)."""
    words = text.replace(",", " ").split()
    if not words:
        raise FitInputError(f"{source}: empty controller declaration; write e.g. "
                            "'state_feedback K1=6 K2=-3 K3=0.2 K4=0' or 'pd KP=10 KD=0.3'")
    kind = words[0].lower()
    vals: dict[str, Any] = {}
    for w in words[1:]:
        if "=" not in w:
            raise FitInputError(f"{source}: {w!r} in the controller declaration is not NAME=VALUE")
        k, _, v = w.partition("=")
        vals[k.strip().lower()] = v.strip()
    allowed = {"state_feedback": {"k1", "k2", "k3", "k4", "rate", "tau"},
               "pd": {"kp", "kd", "rate", "tau"}}
    if kind not in allowed:
        raise FitInputError(f"{source}: controller type {kind!r} is not known; the bench fit "
                            "takes 'state_feedback K1=.. K2=.. K3=.. K4=..' or 'pd KP=.. KD=..'")
    unknown = set(vals) - allowed[kind]
    if unknown:
        raise FitInputError(f"{source}: unknown controller field(s) {sorted(unknown)} for "
                            f"{kind}; allowed: {sorted(allowed[kind])}")
    num = {}
    for k, v in vals.items():
        if k == "rate":
            continue
        try:
            num[k] = float(v)
        except ValueError:
            raise FitInputError(f"{source}: controller field {k.upper()} = {v!r} is not a "
                                "number") from None
    rate = vals.get("rate", "filtered" if "tau" in num else "backward")
    if kind == "pd":
        if "kp" not in num:
            raise FitInputError(f"{source}: pd controller without KP")
        g = dict(k1=num["kp"], k2=0.0, k3=num.get("kd", 0.0), k4=0.0)
    else:
        if "k1" not in num:
            raise FitInputError(f"{source}: state_feedback controller without K1")
        g = {k: num.get(k, 0.0) for k in ("k1", "k2", "k3", "k4")}
    try:
        return StateFeedbackController(type="state_feedback", rate=rate,
                                       rate_time_constant=num.get("tau", 0.0), **g)
    except Exception as exc:
        raise FitInputError(f"{source}: controller declaration: {exc}") from None


def controller_from_any(c: Any, source: str) -> StateFeedbackController:
    """A spec, a dict of spec fields, or a declaration string."""
    if isinstance(c, StateFeedbackController):
        return c
    if isinstance(c, str):
        return parse_controller(c, source)
    if isinstance(c, Mapping):
        d = {"type": "state_feedback", **c}
        if d.get("type") == "pd":
            d = {"type": "state_feedback", "k1": d.get("kp"), "k3": d.get("kd", 0.0),
                 **{k: v for k, v in d.items() if k in ("rate", "rate_time_constant")}}
        try:
            return StateFeedbackController(**d)
        except Exception as exc:
            raise FitInputError(f"{source}: controller: {exc}") from None
    raise FitInputError(f"{source}: controller {c!r}: give a declaration string, a dict or a "
                        "StateFeedbackController")


def read_bench_log(path: str | Path, *, columns: Mapping[str, str] | None = None,
                   units: Mapping[str, str] | None = None, controller: Any = None,
                   max_jitter: float = MAX_JITTER, min_samples: int = 64) -> BenchLog:
    """Read and check one bench log (see the module docstring); ``columns`` maps our names
    to the file's, ``units`` gives the unit of a column's numbers (pint strings)."""
    path = Path(path)
    try:
        raw = read_log(path, columns, units, min_samples=min_samples, max_jitter=max_jitter,
                       required=("time", "reference"),
                       hint="A bench log needs time (s), reference (rad, the commanded hub "
                            "angle) and motor_angle and/or tip_deflection.")
    except LogError as exc:
        raise FitInputError(str(exc)) from None
    t, cols, meta = raw.time, raw.signals, raw.meta
    header = list(cols)
    ctrl = None
    if controller is not None:
        ctrl = controller_from_any(controller, f"{path}: controller option")
    elif "controller" in meta:
        ctrl = parse_controller(meta["controller"], f"{path}: '# controller:' line")
    log = BenchLog(path, t, cols, meta, ctrl)
    present = [c for c in OUTPUTS if c in cols]
    if not log.outputs:
        why = (f"column(s) {', '.join(present)} are constant" if present
               else f"no column {' or '.join(OUTPUTS)} (found: {', '.join(header)})")
        raise FitInputError(f"{path}: no usable output column: {why}; the fit needs the hub "
                            "angle motor_angle (rad) and/or the tip deflection tip_deflection "
                            "(m) as measured; map other names with columns=")
    return log


def as_bench_log(x: Any, controller: Any = None, **kw) -> BenchLog:
    """A path or a :class:`BenchLog` (with ``controller`` overriding its declaration)."""
    if isinstance(x, BenchLog):
        if controller is not None:
            return BenchLog(x.path, x.time, x.columns, x.meta,
                            controller_from_any(controller, f"{x.name}: controller option"))
        return x
    return read_bench_log(x, controller=controller, **kw)


def check_closed_loop(log: BenchLog) -> None:
    """A closed-loop fit/validation needs the controller and the signals it reads."""
    c = log.controller
    if c is None:
        raise FitInputError(
            f"{log.path or log.name}: field 'controller': no controller declared; add a line "
            "'# controller: state_feedback K1=.. K2=.. K3=.. K4=..' (or 'pd KP=.. KD=..') "
            "before the header, pass controller=... (--controller), or fit in open-loop "
            "replay (mode='open_loop', needs a voltage column)")
    if "motor_angle" not in log.columns:
        raise FitInputError(f"{log.path or log.name}: field 'motor_angle': the controller "
                            "closes on the hub angle, but the log has no motor_angle column")
    if (c.k2 != 0 or c.k4 != 0) and "tip_deflection" not in log.columns:
        raise FitInputError(f"{log.path or log.name}: field 'tip_deflection': the controller "
                            f"uses the tip deflection (K2 = {c.k2:g}, K4 = {c.k4:g}) but the "
                            "log has no tip_deflection column")


def write_bench_log(path: str | Path, time: np.ndarray, columns: Mapping[str, np.ndarray], *,
                    comments: list[str] = (), overwrite: bool = False,
                    fmt: str = "%.12g") -> Path:
    """Write a bench log (``time`` then ``columns`` in order, SI; ``# comment`` lines
    first, e.g. ``controller: state_feedback K1=..``). Refuses to overwrite unless asked."""
    try:
        return write_log(path, time, columns, comments=list(comments), overwrite=overwrite,
                         fmt=fmt, required=("time",))
    except LogError as exc:
        raise FitInputError(str(exc)) from None
