"""Bench logs: reading, checking, and the controller a log declares.

A bench log is the CSV exchange format of :mod:`flexarm.io.logs` with the columns of a
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

Logs as a logger writes them are read with a log-format file (``log_format=``, see
:mod:`flexarm.io.logformat`): its ``[columns]`` / ``[units]`` map and scale the columns, its
``[controller]`` gives the law with fixed gains or the columns holding them. The gains are
kept per sample (:attr:`BenchLog.gains`, piecewise constant when a log changes them).
"""

from __future__ import annotations

from flexarm.errors import FlexarmError  # the one error base (issue #25)

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from flexarm.io.logformat import GAIN_UNITS, LogFormat, load_log_format
from flexarm.io.logs import MAX_JITTER, LogError, read_log, write_log
from flexarm.specs.controllers_bench import StateFeedbackController

#: Relative difference of two sampling periods taken as the same period (a logger's
#: rounding or time-stamp jitter, not another rate).
PERIOD_TOL = 1e-3

OUTPUTS = ("motor_angle", "tip_deflection")
#: The state-feedback gains in the order of :attr:`BenchLog.gains`, with their SI units.
GAINS: dict[str, str] = GAIN_UNITS["state_feedback"]
#: Fewest samples in a bench log (and in a window of one).
MIN_BENCH_SAMPLES = 64


class FitInputError(FlexarmError, ValueError):
    """Input a fit or a validation cannot use; the message names the file, the field and
    what to do."""


@dataclass
class BenchLog:
    """One bench log in SI units. ``controller`` is the declared (or given) law, or None: with
    gains that change inside the log, the law at the first sample.

    ``gains`` holds K1..K4 per sample, shape (N, 4) (V/rad, V/m, V·s/rad, V·s/m), or None
    when no law is known; ``voltage_limit`` (V) and ``rate`` (``"logged"``, ``"backward"``,
    ``"filtered"``: the rates the law used) come from a log-format file's ``[controller]``.
    """

    path: Path | None
    time: np.ndarray
    columns: dict[str, np.ndarray]
    meta: dict[str, str]
    controller: StateFeedbackController | None
    gains: np.ndarray | None = None
    voltage_limit: float | None = None
    rate: str | None = None
    log_format: LogFormat | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        n = len(self.time)
        if self.gains is None and self.controller is not None:
            c = self.controller
            self.gains = np.tile([c.k1, c.k2, c.k3, c.k4], (n, 1)).astype(float)
        if self.gains is not None:
            self.gains = np.asarray(self.gains, dtype=float)
            if self.gains.shape != (n, 4):
                raise FitInputError(f"{self.path or self.name}: gains have shape "
                                    f"{self.gains.shape}; expected ({n}, 4): K1..K4 per sample")
        if self.rate is None and self.controller is not None:
            self.rate = self.controller.rate

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

    @property
    def gain_segments(self) -> list[tuple[int, int]]:
        """[start, stop) sample ranges over which the gains are constant (one range when
        they never change; none when no law is known)."""
        if self.gains is None:
            return []
        change = np.flatnonzero(np.any(np.diff(self.gains, axis=0) != 0, axis=1)) + 1
        edges = [0, *change.tolist(), len(self.time)]
        return list(zip(edges[:-1], edges[1:]))

    def window(self, t0: float, t1: float, *, min_samples: int = MIN_BENCH_SAMPLES
               ) -> "BenchLog":
        """The samples with ``t0 <= time - time[0] < t1`` (s, from the log's first sample)
        as a new BenchLog (bounds compared to within 1e-6 sample, so that a bound on the
        sample grid takes that sample whatever the time stamps' rounding); its
        ``controller`` is the law at the window's first sample."""
        rel = self.time - self.time[0]
        span = float(rel[-1]) + self.dt
        where = f"{self.path or self.name}: window [{t0:g}, {t1:g}) s"
        if not (np.isfinite(t0) and np.isfinite(t1) and t1 > t0):
            raise FitInputError(f"{where}: give t0 < t1 (s from the log's first sample)")
        eps = 1e-6 * self.dt  # time stamps like 718.708 s carry ~1e-13 s of rounding
        keep = (rel >= t0 - eps) & (rel < t1 - eps)
        k = int(keep.sum())
        if k < min_samples:
            what = ("lies outside the log" if k == 0 else f"holds only {k} sample(s), fewer "
                    f"than {min_samples}")
            raise FitInputError(f"{where} {what}; the log spans [0, {span:g}) s from its first "
                                f"sample ({len(self.time)} samples of {self.dt:g} s); choose a "
                                "window inside it")
        gains = self.gains[keep] if self.gains is not None else None
        ctrl = self.controller
        if ctrl is not None and gains is not None:
            ctrl = ctrl.model_copy(update=dict(zip(("k1", "k2", "k3", "k4"),
                                                   map(float, gains[0]))))
        return replace(self, time=self.time[keep], columns={c: x[keep] for c, x in
                                                            self.columns.items()},
                       meta=dict(self.meta), controller=ctrl, gains=gains)

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


def read_bench_log(path: str | Path, *, columns: Mapping[str, str | int] | None = None,
                   units: Mapping[str, str] | None = None, controller: Any = None,
                   max_jitter: float = MAX_JITTER, min_samples: int = MIN_BENCH_SAMPLES,
                   log_format: str | Path | LogFormat | None = None) -> BenchLog:
    """Read and check one bench log (see the module docstring); ``columns`` maps our names
    to the file's (header text or 1-based number), ``units`` gives the unit of a column's
    numbers (pint strings), both on top of ``log_format``'s (a log-format file or a
    :class:`~flexarm.io.logformat.LogFormat`). The law: ``controller`` if given, else the
    format's ``[controller]`` (fixed gains or gain columns), else the log's ``# controller:``
    line."""
    path = Path(path)
    fmt = None
    try:
        if log_format is not None:
            fmt = load_log_format(log_format)
    except LogError as exc:
        raise FitInputError(str(exc)) from None
    cols = dict(fmt.columns) if fmt else {}
    cols.update(columns or {})
    uts = dict(fmt.units) if fmt else {}
    uts.update(units or {})
    fc = fmt.controller if fmt else None
    gain_cols = fc.columns() if fc is not None and controller is None else {}
    cols.update(gain_cols)
    read_kw = {}
    if fmt is not None:
        read_kw = dict(delimiter=fmt.delimiter_char, comment=tuple(fmt.comment),
                       skip_rows=fmt.skip_rows, source=f"log format {fmt.source}")
    try:
        raw = read_log(path, cols, uts, min_samples=min_samples, max_jitter=max_jitter,
                       required=("time", "reference"), extra=GAINS,
                       hint="A bench log needs time (s), reference (rad, the commanded hub "
                            "angle) and motor_angle and/or tip_deflection.", **read_kw)
    except LogError as exc:
        raise FitInputError(str(exc)) from None
    t, cols_read, meta = raw.time, raw.signals, raw.meta
    header = list(cols_read)
    gains = None
    ctrl = None
    if controller is not None:
        ctrl = controller_from_any(controller, f"{path}: controller option")
    elif fc is not None and (fc.gains or fc.gain_columns):
        fixed = fc.fixed_gains()
        gains = np.column_stack([cols_read.pop(k) if k in gain_cols else
                                 np.full(len(t), fixed.get(k, 0.0)) for k in GAINS])
        try:
            ctrl = StateFeedbackController(
                type="state_feedback", rate="filtered" if fc.tau > 0 else "backward",
                rate_time_constant=fc.tau,
                **dict(zip(("k1", "k2", "k3", "k4"), map(float, gains[0]))))
        except Exception as exc:
            raise FitInputError(f"{path}: gains at the first sample: {exc}") from None
    elif "controller" in meta:
        ctrl = parse_controller(meta["controller"], f"{path}: '# controller:' line")
    elif fc is not None:
        raise FitInputError(
            f"{path}: the gains of the {fc.kind} law cannot be found: log format "
            f"{fmt.source} [controller] gives neither gains nor gain_columns, and the log has "
            "no '# controller:' line; add gain_columns = {K1 = .., ...} (the columns holding "
            "the gains) or gains = {K1 = .., ...} to the format's [controller], or pass "
            "controller= (--controller)")
    log = BenchLog(path, t, cols_read, meta, ctrl, gains=gains,
                   voltage_limit=fc.limit if fc is not None else None,
                   rate=fc.rate if fc is not None and controller is None else None,
                   log_format=fmt)
    present = [c for c in OUTPUTS if c in cols_read]
    if not log.outputs:
        why = (f"column(s) {', '.join(present)} are constant" if present
               else f"no column {' or '.join(OUTPUTS)} (found: {', '.join(header)})")
        raise FitInputError(f"{path}: no usable output column: {why}; the fit needs the hub "
                            "angle motor_angle (rad) and/or the tip deflection tip_deflection "
                            "(m) as measured; map other names with columns=")
    return log


def as_bench_log(x: Any, controller: Any = None, **kw) -> BenchLog:
    """A path or a :class:`BenchLog` (with ``controller`` overriding its declaration and
    its gains); ``kw`` go to :func:`read_bench_log` (``log_format=``, ``columns=``, ...)."""
    if isinstance(x, BenchLog):
        if controller is not None:
            return replace(x, controller=controller_from_any(
                controller, f"{x.name}: controller option"), gains=None, rate=None)
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
