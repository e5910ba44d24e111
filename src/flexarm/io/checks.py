"""The readers' checks, one place for text and ``.mat`` logs (issue #25).

Every reader (:func:`flexarm.io.logs.read_log`, :func:`flexarm.io.matfile.read_mat`)
hands its arrays, in SI units, to :func:`check_signals`, which

1. unwraps a logger's sample counter that wraps (:func:`unwrap_counter`: a 16-bit counter
   goes 65535 → 0; the step mod 2¹⁶ is the regular one, so the wrap is no lost sample);
2. checks the time stamps (:func:`check_time`): finite, not all equal (all zero: time is
   not mapped to a clock), strictly increasing (a repeated stamp, a decrease; two
   neighbouring samples out of order are named as swapped), and uniform within
   ``max_jitter`` (relative deviation |Δt_k − median Δt| / median Δt);
3. checks the sampling rate 1 / median step against :data:`RATE_RANGE` (:func:`check_rate`):
   a log's clock read in the wrong unit (a ``.mat`` time in s where the format says µs;
   the lab logger's ms column read as s where no unit is stated) is refused with the
   unit that makes the rate a rig's;
4. refuses finite but absurd values (:func:`check_ranges`): |x| beyond the physical range
   of the signal's kind (:data:`RANGES`, by SI unit: an angle beyond 1e3 rad, a voltage
   beyond 1e5 V, anything beyond 1e15), naming the column and the row: such a number
   (1e308) would overflow the fit's squares or break an SVD far from the file.

Each failure is a :class:`flexarm.io.logs.LogError` (a :class:`flexarm.errors.FlexarmError`)
naming the file, the column, the row (the data row and file line of a text log, the sample
of a ``.mat`` file) and the value.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from flexarm.errors import FlexarmError, LogError, MatFileError
from flexarm.io.signals import signal_unit

__all__ = [
    "RANGES",
    "DEFAULT_RANGE",
    "MAT_MAX_JITTER",
    "COUNTER",
    "readable",
    "check_signals",
    "check_time",
    "check_rate",
    "RATE_RANGE",
    "check_ranges",
    "unwrap_counter",
    "signal_range",
]

#: the sample counter's flexarm name
COUNTER = "sample_counter"
#: largest |value| accepted per SI unit of a signal (beyond it the value is not physical)
RANGES: dict[str, float] = {
    "rad": 1e3,
    "rad/s": 1e6,
    "m": 1e3,
    "m/s": 1e6,
    "V": 1e5,
    "A": 1e5,
    "N*m": 1e6,
    "s": 1e11,  # a clock: Unix time in s is 1.8e9
    "": 2.0**53,  # counters: exact integers in a double
}
#: largest |value| for a signal of unknown kind (gains, extra columns)
DEFAULT_RANGE = 1e15
#: the sampling rates (Hz) of a rig's log: a median time step outside (5 µs to 0.5 s) is
#: a wrong time unit (issue #45: a ``.mat`` clock in s read as µs gave FRF lines at MHz),
#: refused by :func:`check_rate` with the unit that fits
RATE_RANGE = (2.0, 200e3)
#: the time units :func:`check_rate` proposes, in pint's spelling
TIME_UNITS = ("s", "ms", "us", "ns", "min")
#: the jitter accepted in a ``.mat`` log's time stamps (a text log's default,
#: :data:`flexarm.io.logs.MAX_JITTER`; a logger's clock repeats its period exactly)
MAT_MAX_JITTER = 1e-3


def _log_error(*args, **kw):
    return LogError(*args, **kw)


def signal_range(name: str) -> float:
    """The largest |value| accepted for signal ``name`` (:data:`RANGES` by its SI unit,
    :data:`DEFAULT_RANGE` for names flexarm does not know)."""
    unit = signal_unit(name)
    return RANGES.get(unit, DEFAULT_RANGE) if unit is not None else DEFAULT_RANGE


def _where(k: int, lines: Sequence[int] | None) -> str:
    """Row ``k`` (0-based sample) as a text log's ``data row k+1 (line n)`` or a
    ``sample k``."""
    if lines is not None:
        return f"data row {k + 1} (line {lines[k]})"
    return f"sample {k}"


def unwrap_counter(c: np.ndarray, bits: Sequence[int] = (16, 32)) -> np.ndarray:
    """A sample counter with its wraps undone: where the step is negative and the step
    modulo 2^b (b in ``bits``, the first that fits) equals the regular step (the median of
    the positive steps), 2^b is added from there on.  A counter without such wraps is
    returned as it is (a jump that is not a wrap stays for the caller to refuse)."""
    c = np.asarray(c, float)
    if c.size < 2:
        return c
    d = np.diff(c)
    neg = d < 0
    if not neg.any():
        return c
    pos = d[d > 0]
    if pos.size == 0:
        return c
    good = float(np.median(pos))
    for b in bits:
        m = 2.0**b
        if (
            np.all(np.abs(np.mod(d[neg], m) - good) < 1e-9 * m)
            and np.max(c) < m
            and np.min(c) >= -m / 2
        ):
            return c[0] + np.concatenate([[0.0], np.cumsum(np.where(neg, d + m, d))])
    return c


def check_time(
    t: np.ndarray,
    *,
    file: str | Path,
    column: str = "time",
    lines: Sequence[int] | None = None,
    max_jitter: float | None = None,
) -> None:
    """The time stamps ``t`` (s) of ``file``: finite, not all equal, strictly increasing,
    and (with ``max_jitter``) uniform: max_k |Δt_k − median Δt| / median Δt ≤ max_jitter.
    ``column``: the time column as the message names it; ``lines``: the file line of each
    sample (text logs)."""
    t = np.asarray(t, float)
    path = Path(file)
    bad = ~np.isfinite(t)
    if bad.any():
        k = int(np.argmax(bad))
        raise _log_error(
            f"{path}: time, column {column}, {_where(k, lines)}: {t[k]!r} is "
            "not a finite time stamp",
            file=path,
            field=column,
        )
    if t.size >= 2 and np.all(t == t[0]):
        raise _log_error(
            f"{path}: time, column {column}: all {t.size} time stamps are {t[0]:.9g} s: that "
            "is no clock; map the column or variable that holds the time (a log format's "
            "[columns] time = ...)",
            file=path,
            field=column,
            value=float(t[0]),
        )
    d = np.diff(t)
    if np.any(d <= 0):
        k = int(np.argmax(d <= 0))
        kind = "repeats" if d[k] == 0 else "decreases"
        swapped = ""
        if (
            d[k] < 0
            and 0 < k + 1 < len(d)
            and t[k + 1] > (t[k - 1] if k else -np.inf)
            and t[k] < t[k + 2]
        ):
            swapped = f"; the samples {_where(k, lines)} and {_where(k + 1, lines)} are swapped"
        at = (
            f"data row {k + 2} (line {lines[k + 1]}, column {column})"
            if lines is not None
            else f"sample {k + 1} (column {column})"
        )
        before = f" (line {lines[k]})" if lines is not None else ""
        raise _log_error(
            f"{path}: time {kind} at {at}: t = {t[k + 1]:.9g} s after t = {t[k]:.9g} s"
            f"{before}{swapped}; time must increase strictly (duplicated or unsorted rows?)",
            file=path,
            field=column,
        )
    if max_jitter is None or len(d) == 0:
        return
    med = float(np.median(d))
    rel = np.abs(d - med) / med
    k = int(np.argmax(rel))
    if rel[k] > max_jitter:
        rows = (
            f"data row {k + 1} to {k + 2} (lines {lines[k]}-{lines[k + 1]}, column {column}; "
            if lines is not None
            else f"sample {k} to {k + 1} (column {column}; "
        )
        raise _log_error(
            f"{path}: non-uniform sampling: the step from {rows}t = {t[k]:.9g} s) is "
            f"{d[k]:.6g} s against a median step of {med:.6g} s (relative deviation "
            f"{rel[k]:.3g} > {max_jitter:g}); resample the log to a uniform time grid, or, if "
            "the controller ran at a fixed period and only the time stamps jitter, accept it "
            "with max_jitter= (flexarm fit / validate --max-jitter): the samples are then "
            "taken as uniform at the median step",
            file=path,
            field=column,
        )


def check_rate(
    t: np.ndarray, *, file: str | Path, column: str = "time", unit: str | None = None
) -> None:
    """The sampling rate of the time stamps ``t`` (s, already converted from the file's
    stated ``unit``) within :data:`RATE_RANGE`: a median step below 5 µs or above 0.5 s is
    no rig's controller log but a time read in the wrong unit; refused (a
    :class:`flexarm.io.logs.LogError`, one line) naming the rate, the unit it was read in
    and the unit that gives a rig's rate, e.g. time in s where the format says ``us``:
    1 kHz read as 1 GHz.  A refusal, not a warning: every result downstream
    (FRF lines, delays, periods) would be off by the same factor of 1000.  Where no unit
    is stated (``unit`` None: the log format and the options say nothing, the numbers are
    taken as seconds) the same range holds (issue #45/#46: the lab logger's ms column under
    a header that says "(s)" read as a 1 Hz loop); the line then says the unit was not
    stated and names the field that states it (``[units] time``, ``--unit time=``)."""
    t = np.asarray(t, float)
    if t.size < 2:
        return
    d = np.diff(t)
    d = d[np.isfinite(d) & (d > 0)]
    if d.size == 0:
        return
    step = float(np.median(d))
    fs = 1.0 / step
    lo, hi = RATE_RANGE
    if lo <= fs <= hi:
        return
    stated = unit or "s"
    try:
        from flexarm.units import ureg

        per = {u: float(ureg.Quantity(1.0, u).to("s").magnitude) for u in TIME_UNITS}
        here = float(ureg.Quantity(1.0, stated).to("s").magnitude)
    except Exception:  # a unit pint does not know was refused before; no proposal then
        per, here = {}, 1.0
    fits = []
    for u, f in per.items():
        rate = fs * here / f  # the same numbers read in unit u
        if lo <= rate <= hi:
            fits.append((abs(np.log10(rate / 1e3)), u, rate))
    how = "fast" if fs > hi else "slowly"
    told = (
        f"[units] time = {stated!r}"
        if unit is not None
        else "seconds (no time unit stated: no [units] time, no --unit time=)"
    )
    verb = "set" if unit is not None else "state it:"
    if fits:
        _, u, rate = min(fits)  # the proposal nearest 1 kHz
        fix = (
            f"if the numbers are {u}, {verb} [units] time = '{u}' (--unit time={u}): {rate:.6g} Hz"
        )
    else:
        fix = "map the column that holds the time, or set [units] time to its unit"
    raise _log_error(
        f"{Path(file)}: time, column {column}: the median step is {step:.6g} s, a sampling "
        f"rate of {fs:.6g} Hz with the numbers read as {told}; no rig's controller logs "
        f"that {how} (a log's rate lies in {lo:g} Hz to {hi:g} Hz): the time unit is wrong; "
        f"{fix}",
        file=file,
        field=column,
    )


def check_ranges(
    signals: Mapping[str, np.ndarray],
    *,
    file: str | Path,
    lines: Sequence[int] | None = None,
    columns: Mapping[str, str] | None = None,
) -> None:
    """Every signal (SI units) within its physical range (:func:`signal_range`); the first
    value beyond it is named by column, row and value.  ``columns``: how the file names
    each signal (the format's spec), for the message."""
    path = Path(file)
    for name, x in signals.items():
        x = np.asarray(x)
        if x.dtype.kind not in "iufb" or x.size == 0:
            continue
        lim = signal_range(name)
        over = np.abs(np.asarray(x, float)) > lim
        if over.any():
            k = int(np.argmax(over.reshape(over.shape[0], -1).any(axis=1)))
            v = np.asarray(x[k], float).ravel()
            v = float(v[np.argmax(np.abs(v) > lim)])
            col = name if not columns or name not in columns else f"{name} ({columns[name]!r})"
            raise _log_error(
                f"{path}: column {col}, {_where(k, lines)}: {v:.6g} is beyond the physical "
                f"range of this signal (|x| <= {lim:g} in SI units); "
                f"{int(over.reshape(over.shape[0], -1).any(axis=1).sum())} such row(s); a "
                "corrupted value, or the wrong unit in the log format ([units])",
                file=path,
                field=name,
                value=v,
            )


def check_signals(
    file: str | Path,
    signals: dict[str, np.ndarray],
    *,
    time: np.ndarray | None = None,
    time_column: str | None = None,
    lines: Sequence[int] | None = None,
    max_jitter: float | None = None,
    columns: Mapping[str, str] | None = None,
    time_unit: str | None = None,
) -> dict[str, np.ndarray]:
    """The readers' hook (module doc): unwrap ``signals[COUNTER]`` in place, then
    :func:`check_time` on ``time`` (default ``signals["time"]``, if any; ``time_column`` its
    name in messages), :func:`check_rate` (``time_unit``: the unit the file's time was
    read in, None where none is stated: seconds assumed, checked too) and
    :func:`check_ranges` on all.  Returns ``signals``."""
    if COUNTER in signals:
        signals[COUNTER] = unwrap_counter(signals[COUNTER])
    t = signals.get("time") if time is None else time
    if t is not None:
        col = time_column or (
            f"time ({columns['time']!r})" if columns and "time" in columns else "time"
        )
        check_time(t, file=file, column=col, lines=lines, max_jitter=max_jitter)
        check_rate(t, file=file, column=col, unit=time_unit)
        check_ranges({"time": t}, file=file, lines=lines, columns=columns)
    check_ranges(signals, file=file, lines=lines, columns=columns)
    return signals


def readable(path: str | Path, load, what: str = "MATLAB v7.3 (HDF5) .mat file"):
    """``load(path)``, with the errors a damaged file raises inside a decoder (h5py's
    ``OSError`` "truncated file", ``KeyError``/``ValueError``/``RuntimeError`` of a broken
    object header) turned into one :class:`flexarm.io.matfile.MatFileError` naming the file;
    a :class:`flexarm.errors.FlexarmError` passes through."""
    try:
        return load(Path(path))
    except FlexarmError:
        raise
    except (OSError, KeyError, ValueError, RuntimeError, TypeError, IndexError) as exc:
        msg = " ".join(str(exc).split()) or type(exc).__name__
        raise MatFileError(
            f"{path}: not a readable {what} ({type(exc).__name__}: {msg}); "
            "the file is damaged or cut short: copy it again from the "
            "logger, or save it from MATLAB again",
            file=path,
        ) from None
