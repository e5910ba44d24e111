"""Experiment logs: flexarm's CSV exchange format (what a lab log holds, what a simulation
writes with :meth:`flexarm.sim.result.SimulationResult.to_csv`, what ``identify`` and ``fit``
read). A bottom-level module: it knows only the unit registry.

Format (one file per sinusoidal experiment, FRB Sec. II-A, Fig. 1)::

    # optional comment lines, kept; lines "# key: value" are also read into Log.meta
    # omega: 4.3
    time,reference,current,motor_angle,tip_angle[,voltage,tip_deflection,...]
    0.000,0.0,0.012,0.0001,0.0
    ...

Required columns and their SI units: ``time`` (s), ``reference`` (rad, the motor-angle
reference r), ``current`` (A, motor current i), ``motor_angle`` (rad, θm), ``tip_angle``
(rad, θt).  Optional columns: ``voltage`` (V), ``tip_deflection`` (m), ``motor_velocity``
(rad/s), ``tip_velocity`` (m/s).  Any other column is kept as read (no unit conversion).

Logs as loggers write them are read too: the delimiter is sniffed on the first data row
(tab, semicolon, comma, else runs of whitespace), comment lines start with ``#`` or ``%``,
line ends may be CRLF, a UTF-8 byte-order mark is dropped (non-UTF-8 text is read as
Latin-1). The header is the first line that is neither blank nor a comment, unless that
line is all numbers: then the header is the last comment line before the data (e.g.
``%Time (ms)<TAB>Hub angle ...``), whose fields need not match the data's in number; a
file without any header is read by column numbers. The time column is kept as written
(it may start at any clock value; users of the log take ``time - time[0]``).

Files that name or scale columns differently are read with ``columns`` (our name → the
file's header text or 1-based column number; a leading ``-`` flips the sign) and
``units`` (our name → the unit of the file's numbers, parsed by pint), e.g.
``read_log(p, columns={"current": "i_m", "time": 1}, units={"current": "mA"})``; a
log-format file (:mod:`flexarm.io.logformat`) holds these once per logger.

Validation (every message starts with the file's path): missing columns (lists the found
and the expected names and how to map them), rows with another number of fields (a file
cut mid-line), empty / non-numeric / NaN / infinite values (column, data row and file
line), non-increasing or repeated time (line and column), non-uniform sampling (relative deviation
of a step from the median step above ``1e-3``; the worst step is named), too few samples.
Input files are only ever opened for reading.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, cast

import numpy as np

from flexarm.errors import LogError, OutputExistsError
from flexarm.io import checks as _checks  # the readers' checks (issue #25)
from flexarm.io.signals import KNOWN as KNOWN  # re-exported: the signal names, SI units
from flexarm.io.signals import OPTIONAL as OPTIONAL
from flexarm.io.signals import OTHER as OTHER
from flexarm.io.signals import PER_JOINT as PER_JOINT
from flexarm.io.signals import REQUIRED as REQUIRED
from flexarm.io.signals import known_names as known_names
from flexarm.io.signals import signal_unit as signal_unit
from flexarm.io.write import atomic_open
from flexarm.units import ureg

#: Largest accepted relative deviation of a time step from the median step.
MAX_JITTER = 1e-3
#: Fewest samples accepted in a log.
MIN_SAMPLES = 16


#: The linear counterparts of the rotary SI units: a linear axis (a prismatic joint) logs
#: its position in m (``motor_angle = "mm"``), its rate in m/s, its force in N.
LINEAR_SI: dict[str, str] = {"rad": "m", "rad/s": "m/s", "rad/s**2": "m/s**2", "N*m": "N"}


def column_unit(name: str, unit: str | None = None) -> str | None:
    """The SI unit a column ``name`` given in the file's ``unit`` is read in: the signal's
    own (:func:`signal_unit`), or its linear counterpart (:data:`LINEAR_SI`: m for an angle,
    N for a torque) where ``unit`` is a length, a speed or a force (a linear axis);
    ``None`` for a name flexarm does not know."""
    si = signal_unit(name)
    if si is None or unit is None:
        return si
    lin = LINEAR_SI.get(si)
    if lin is not None and not _converts(unit, si) and _converts(unit, lin):
        return lin
    return si


def _as_linear(known: Mapping[str, str], name: str, unit: str) -> Mapping[str, str]:
    """``known`` with ``name``'s SI unit its linear counterpart where ``unit`` is linear."""
    si = column_unit(name, unit)
    if si is None or si == known.get(name) or known.get(name) not in LINEAR_SI:
        return known
    return {**known, name: si}


def _converts(unit: str, si: str) -> bool:
    try:
        ureg.parse_expression(unit).to(si)
    except Exception:  # pint raises several exception types
        return False
    return True


class LogExistsError(LogError, OutputExistsError):
    """:func:`write_log` refused to replace an existing file (pass ``overwrite=True``)."""


#: The rig's outputs a servo-rig fit reads (hub encoder and strain gauge).
RIG_OUTPUTS = ("motor_angle", "tip_deflection")
#: The state-feedback gains in the order of :attr:`Log.gains`, with their SI units.
STATE_FEEDBACK_GAINS: dict[str, str] = {"K1": "V/rad", "K2": "V/m", "K3": "V*s/rad", "K4": "V*s/m"}


@dataclass
class Log:
    """One experiment log, in SI units: the one log type of flexarm (text and ``.mat``
    logs, simulation output, every fit's and prediction's input).

    ``signals`` maps column name → array (all columns except ``time``), ``comments`` holds
    the comment lines (without the leading ``#``), ``meta`` the ``key: value`` comments.
    Read from a ``.mat`` file (:func:`flexarm.io.matfile.read_mat`), ``time`` is ``None``
    when the format maps none, ``skipped`` names the objects of the file that could not be
    decoded and ``notes`` what was dropped (e.g. an irregular last row).

    The controller the lab ran, when the log or its format declares one
    (:func:`flexarm.io.logformat.load_log`): ``controller`` the declared law (a
    :class:`~flexarm.specs.controllers_bench.StateFeedbackController`, u = K1 (r − θ) − K2 d
    − K3 θ̇ − K4 ḋ; with gains that change inside the log, the law at the first sample),
    ``gains`` K1..K4 per sample (N, 4) in V/rad, V/m, V·s/rad, V·s/m (piecewise constant
    when the log changes them), ``voltage_limit`` (V, the amplifier's saturation) and
    ``rate`` (``"logged"``, ``"backward"``, ``"filtered"``: the rates the law used).
    ``disturbances``: the signals its format maps as logged disturbances.
    """

    path: Path | None
    time: np.ndarray | None
    signals: dict[str, np.ndarray]
    comments: list[str] = field(default_factory=list)
    meta: dict[str, str] = field(default_factory=dict)
    skipped: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    controller: Any = None
    gains: np.ndarray | None = None
    voltage_limit: float | None = None
    rate: str | None = None
    log_format: Any = field(default=None, repr=False)
    #: the signals the log's format maps as disturbances (its ``[disturbances]``): inputs
    #: that enter the loop from the log (a scenario's ``[[disturbances]]``)
    disturbances: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if self.path is not None and not isinstance(self.path, Path):
            self.path = Path(self.path)
        n = len(self)
        c = self.controller
        if self.gains is None and c is not None and hasattr(c, "k4"):
            self.gains = np.tile([c.k1, c.k2, c.k3, c.k4], (n, 1)).astype(float)
        if self.gains is not None:
            self.gains = np.asarray(self.gains, dtype=float)
            if self.gains.shape != (n, 4):
                raise LogError(
                    f"{self.where}: gains have shape {self.gains.shape}; expected "
                    f"({n}, 4): K1..K4 per sample"
                )
        if self.rate is None and c is not None:
            self.rate = getattr(c, "rate", None)

    @property
    def dt(self) -> float:
        """Sampling period (s): the median time step."""
        # (a log without time: numpy's error, as before)
        return float(np.median(np.diff(cast(np.ndarray, self.time))))

    @property
    def name(self) -> str:
        """The file's name (``"<log>"`` for a log not read from a file); results key logs
        by :func:`log_keys`, which keeps logs of one name in different folders apart."""
        return self.path.name if self.path is not None else "<log>"

    @property
    def where(self) -> str:
        """The file (its full path) for messages."""
        return str(self.path) if self.path is not None else "<log>"

    @property
    def columns(self) -> dict[str, np.ndarray]:
        """The signals (``signals``; the name the servo-rig pipeline reads them by)."""
        return self.signals

    @property
    def outputs(self) -> tuple[str, ...]:
        """The rig outputs (:data:`RIG_OUTPUTS`) present and usable (not constant)."""
        return tuple(c for c in RIG_OUTPUTS if c in self.signals and np.ptp(self.signals[c]) > 0)

    @property
    def gain_segments(self) -> list[tuple[int, int]]:
        """[start, stop) sample ranges over which the gains are constant (one range when
        they never change; none when no law is known)."""
        if self.gains is None:
            return []
        change = np.flatnonzero(np.any(np.diff(self.gains, axis=0) != 0, axis=1)) + 1
        edges = [0, *change.tolist(), len(self)]
        return list(zip(edges[:-1], edges[1:], strict=True))

    def __getitem__(self, column: str) -> np.ndarray:
        if column == "time":
            return cast(np.ndarray, self.time)  # None for a .mat log that maps no time
        try:
            return self.signals[column]
        except KeyError:
            raise KeyError(
                f"{self.where}: no column {column!r}; columns: time, {', '.join(self.signals)}"
            ) from None

    def __len__(self) -> int:
        if self.time is not None:
            return len(self.time)
        return len(next(iter(self.signals.values()))) if self.signals else 0

    def window(self, t0: float, t1: float, *, min_samples: int = 2) -> Log:
        """The samples with t0 <= time − time[0] < t1 (s from the log's first sample; a
        bound on the sample grid takes that sample whatever the time stamps' rounding: bounds
        are compared to within 1e-6 sample) as a new :class:`Log` (arrays copied); the
        declared ``controller`` is the law at the window's first sample."""
        where = f"{self.where}: window [{t0:g}, {t1:g}) s"
        if self.time is None:
            raise LogError(f"{where}: no time mapped; a window needs the log's time")
        if not (np.isfinite(t0) and np.isfinite(t1) and t1 > t0):
            raise LogError(f"{where}: give t0 < t1 (s from the log's first sample)")
        rel = self.time - self.time[0]
        dt = self.dt if len(self.time) > 1 else 1.0
        eps = 1e-6 * dt  # time stamps like 718.708 s carry ~1e-13 s of rounding
        keep = (rel >= t0 - eps) & (rel < t1 - eps)
        k = int(keep.sum())
        if k < min_samples:
            what = (
                "lies outside the log"
                if k == 0
                else f"holds only {k} sample(s), fewer than {min_samples}"
            )
            raise LogError(
                f"{where} {what}; the log spans [0, {float(rel[-1]) + dt:g}) s "
                f"from its first sample ({len(self.time)} samples of {dt:g} s); "
                "choose a window inside it"
            )
        gains = self.gains[keep].copy() if self.gains is not None else None
        ctrl = self.controller
        if ctrl is not None and gains is not None and hasattr(ctrl, "model_copy"):
            ctrl = ctrl.model_copy(
                update=dict(zip(("k1", "k2", "k3", "k4"), map(float, gains[0]), strict=True))
            )
        return replace(
            self,
            time=self.time[keep].copy(),
            signals={c: x[keep].copy() for c, x in self.signals.items()},
            comments=list(self.comments),
            meta=dict(self.meta),
            skipped=list(self.skipped),
            notes=list(self.notes),
            controller=ctrl,
            gains=gains,
        )


#: Default largest relative difference of a log's sampling period (its median time step)
#: from a scenario's period that :func:`on_sample_grid` reads on the scenario's grid: a
#: logger's clock that drifts (16 ppm, 8 ppm on a public benchmark's 1 kHz files) or
#: jitters, not another rate.
PERIOD_TOLERANCE = 1e-4
#: Below this relative difference the log's period is the scenario's (round-off of time
#: stamps such as 718.708 s): the log is used as it is, without a note.
SAME_PERIOD = 1e-6


class ClockError(LogError):
    """A log whose sampling period is too far from the scenario's (:func:`on_sample_grid`)."""


def on_sample_grid(
    log: Log,
    period: float,
    tol: float = PERIOD_TOLERANCE,
    *,
    option: str = "period_tolerance",
    what: str = "the scenario's [sampling] period",
) -> tuple[Log, str | None]:
    """``log`` read on the sample grid of ``period`` (s): the one check of a log's clock
    against a scenario's period (replay, fit, validate).

    The log's period T_log is the slope of its time stamps against the sample number (least
    squares: a drift measured over the whole log, stamp jitter averaged out, where a median
    step is off by the jitter's spread over √N); its relative difference r = |T_log − T| / T
    is the figure. r <= 1e-6 (:data:`SAME_PERIOD`, time-stamp round-off):
    the log as it is, no note. 1e-6 < r <= ``tol`` (default 1e-4, :data:`PERIOD_TOLERANCE`):
    a clock that drifts or jitters; the samples are taken as the scenario's, sample k at
    t_0 + k T (re-stamped, not interpolated), and the note (also appended to the returned
    log's ``notes``) says by how much the clock was off: r in ppm, T_log, and the largest
    distance of a time stamp from the grid (s). r > ``tol``: a :class:`ClockError` line
    naming the log, both periods, r and ``option`` (the option that widens ``tol``).
    A log without time is returned as it is. Returns (log, note or None)."""
    if log.time is None or len(log.time) < 2:
        return log, None
    if not (period > 0 and np.isfinite(period)):
        raise ClockError(f"{log.where}: sampling period {period!r} s: give a period > 0 s")
    if not (tol >= 0 and np.isfinite(tol)):
        raise ClockError(f"{option} = {tol!r}: give a relative tolerance >= 0 (e.g. 1e-4)")
    t = np.asarray(log.time, float)
    k = np.arange(len(t)) - (len(t) - 1) / 2
    step = float(np.dot(k, t - t.mean()) / np.dot(k, k))
    r = abs(step - period) / period
    if r <= SAME_PERIOD:
        return log, None
    if r > tol:
        raise ClockError(
            f"{log.where}: sampled every {step:.9g} s (its time stamps' slope), {what} is "
            f"{period:g} s: "
            f"{r:.3g} relative ({r * 1e6:.3g} ppm), beyond {option} = {tol:g}; if the "
            f"logger's clock drifts and its samples are the scenario's, give {option} >= "
            f"{_round_up(r):g}; else resample the log or change the period"
        )
    grid = t[0] + np.arange(len(t)) * period
    off = float(np.max(np.abs(t - grid)))
    note = (
        f"{log.where}: its clock is {r * 1e6:.3g} ppm off {what} (a step of {step:.9g} s "
        f"vs {period:g} s; the last time stamp {t[-1] - grid[-1]:+.3g} s from the grid, the "
        f"farthest {off:.3g} s): read on the scenario's grid, sample k at t_0 + k·{period:g} s"
    )
    out = replace(log, time=grid, notes=[*log.notes, note])
    return out, note


def _round_up(r: float) -> float:
    """r rounded up to 2 significant digits (a tolerance to suggest)."""
    e = math.floor(math.log10(r)) - 1
    return math.ceil(r / 10**e) * 10**e


def log_keys(logs: Sequence[Log]) -> list[str]:
    """One unique key per log for results (fit %, traces, figures), by the one rule of
    :func:`flexarm.io.write.unique_keys`: the file names when all differ (``"a.csv"``),
    paths relative to the logs' common folder when names repeat in different folders
    (``"unit6/run.csv"``, ``"unit7/run.csv"``), ``#2``, ``#3`` after a file given again; a
    log without a file is keyed by its ``name``."""
    from flexarm.io.write import unique_keys

    return unique_keys(
        [
            p
            if (p := getattr(g, "path", None)) is not None
            else (getattr(g, "name", "<log>") or "<log>")
            for g in logs
        ]
    )


def unit_factor(
    path: Path, column: str, unit: str, known: Mapping[str, str] = KNOWN, source: str = ""
) -> float:
    """Factor from the file's ``unit`` to the SI unit of ``column``."""
    si = known.get(column)
    if si is None:
        raise LogError(
            f"{path}: a unit was given for column {column!r}, which flexarm "
            f"does not know; known: {', '.join(known)}"
        )
    try:
        try:
            q = ureg.Quantity(1.0, unit)
        except Exception:  # a scaled unit, e.g. encoder counts as "turn/4096"
            q = ureg.parse_expression(unit)
        return float(q.to(si).magnitude)
    except Exception as exc:  # pint raises several exception types
        where = f" in {source}" if source else ""
        raise LogError(
            f"{path}: cannot convert column {column!r} from {unit!r} to {si} "
            f"({exc}); give{where} a unit of the same kind as {si}"
        ) from None


#: The longest line of a text log read, characters (a line is one sample's numbers, or a
#: header or comment line)
MAX_LINE = 100_000
#: Characters that start a comment line (the exchange format writes ``#``; many loggers ``%``).
COMMENT_CHARS = ("#", "%")
#: Delimiters tried, in this order, on the first data row: tab, semicolon, comma, then runs
#: of whitespace (``None``).
DELIMITERS = ("\t", ";", ",", None)


def _decode(path: Path) -> str:
    """The file's text: UTF-8 (a byte-order mark dropped), else Latin-1 (loggers on Windows
    write ``°`` or ``µ`` in headers); line ends ``\\r\\n`` and ``\\r`` read as ``\\n``."""
    from flexarm.io.write import InputFileError, read_input

    try:
        raw = read_input(path, what="text log")  # a regular file, at most 1 GiB
    except FileNotFoundError:
        raise LogError(f"{path}: no such file") from None
    except InputFileError as exc:
        raise LogError(str(exc)) from None
    except OSError as exc:
        raise LogError(f"{path}: cannot read the file ({exc})") from None
    if b"\x00" in raw:
        k = raw.index(b"\x00")
        line = raw[:k].count(b"\n") + 1
        raise LogError(
            f"{path}: line {line}: a NUL byte at byte {k}; this is a binary file, "
            "not a text log (export the log as text: CSV, tab- or space-separated)"
        )
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        text = raw.decode("latin-1")
    return text.replace("\r\n", "\n").replace("\r", "\n")


def _splitter(delimiter: str | None):
    """Field splitter: ``csv`` for a one-character delimiter (quotes honoured), ``str.split``
    for whitespace."""
    if delimiter is None:
        return str.split
    return lambda line: next(csv.reader([line], delimiter=delimiter))


def _sniff(line: str) -> str | None:
    """Delimiter of a data row: the first of tab, semicolon, comma found in it, else
    whitespace."""
    for d in DELIMITERS[:-1]:
        if d in line:
            return d
    return None


def _number(text: str) -> float:
    """A field as a float; Python's ``float`` but without its ``1_000`` digit grouping."""
    if "_" in text:
        raise ValueError(text)
    return float(text)


def _is_numeric_row(fields: list[str]) -> bool:
    try:
        for f in fields:
            _number(f)
    except ValueError:
        return False
    return bool(fields)


@dataclass
class _Layout:
    """Where things are in a log's text (line numbers 1-based)."""

    comments: list[str]
    header: list[str] | None  # the header's fields (None: no header)
    header_line: int | None
    header_is_comment: bool
    delimiter: str | None
    rows: list[tuple[int, list[str]]]  # (file line, fields) of each data row


def _layout(
    path: Path, text: str, delimiter: str | None, comment: Sequence[str], skip_rows: int
) -> _Layout:
    """Comment lines, header, delimiter and data rows of a log.

    The header is the first line that is neither blank nor a comment, unless that line is
    all numbers: then it is data, and the header is the last comment line before it (its
    comment character removed), or there is none (columns must then be given by number).
    """
    lines = text.split("\n")
    for k, ln in enumerate(lines):  # a text log's line is numbers and names, not megabytes
        if len(ln) > MAX_LINE:
            raise LogError(
                f"{path}: line {k + 1}: {len(ln)} characters, more than the {MAX_LINE} a "
                "text log's line may have; is it a log (one sample per line)?"
            )
    comments: list[str] = []
    comment_lines: list[int] = []
    sniff = delimiter == "auto" or delimiter is None
    k = skip_rows
    while k < len(lines):
        s = lines[k].strip()
        if s.startswith(tuple(comment)):
            comments.append(s[1:].removeprefix(" ").rstrip())
            comment_lines.append(k)
        elif s:
            break
        k += 1
    else:
        raise LogError(
            f"{path}: no header row and no data; expected a line "
            f"'{','.join(REQUIRED)}' after any '#' comment lines"
        )
    first = lines[k]
    header_is_comment = False
    if sniff:
        d = _sniff(first)
    else:  # one character; a space means runs of whitespace
        d = None if delimiter == " " else delimiter
    split = _splitter(d)
    fields = [f.strip() for f in split(first)]
    if _is_numeric_row(fields):
        data_from = k
        if comments:
            hl = comment_lines[-1]
            htext = lines[hl].strip()[1:]
            header = [f.strip() for f in split(htext)]
            header_line, header_is_comment = hl + 1, True
        else:
            header, header_line = None, None
    else:
        header, header_line, data_from = fields, k + 1, k + 1
        if sniff:  # sniff the delimiter on data, not on a header's free text
            for j in range(data_from, len(lines)):
                s = lines[j].strip()
                if s and not s.startswith(tuple(comment)):
                    d2 = _sniff(lines[j])
                    # a row without any delimiter (one field, e.g. a file cut mid-line)
                    # cannot overrule the header's: keep it, and the row's short count
                    # is then reported with its line
                    if d2 != d and (d2 is not None or d is None):
                        d, split = d2, _splitter(d2)
                        header = [f.strip() for f in split(first)]
                    break
    rows = []
    for j in range(data_from, len(lines)):
        s = lines[j].strip()
        if not s or s.startswith(tuple(comment)):
            continue
        rows.append((j + 1, [f.strip() for f in split(lines[j])]))
    return _Layout(comments, header, header_line, header_is_comment, d, rows)


def _norm(text: str) -> str:
    return " ".join(text.split())


def _resolve_column(
    path: Path, ours: str, spec: object, lay: _Layout, ncol: int, source: str
) -> tuple[int, float]:
    """(0-based index, sign) of the file column that ``spec`` (header text or 1-based
    number; a leading ``-`` flips the sign) names for our column ``ours``."""
    where = f"{source or 'columns'}: column {ours!r} = {spec!r}"
    have = f"the file has {ncol} field(s) per data row; header" + (
        f" (line {lay.header_line}): " + " | ".join(lay.header)
        if lay.header
        else f": none (give columns by number, 1 to {ncol})"
    )
    if isinstance(spec, bool) or not isinstance(spec, (int, str)):
        raise LogError(f"{path}: {where}: give the header text or the 1-based column number")
    if isinstance(spec, str):
        text = _norm(spec)
        names = [_norm(h) for h in lay.header or []][:ncol]
        for cand, sign in (
            (text, 1.0),
            (text[1:].strip(), -1.0) if text.startswith("-") else (None, 1.0),
        ):
            if cand is not None and cand in names:
                if names.count(cand) > 1:
                    raise LogError(
                        f"{path}: {where}: the header names {cand!r} "
                        f"{names.count(cand)} times; give the column's number"
                    )
                return names.index(cand), sign
        try:
            spec = int(text)
        except ValueError:
            raise LogError(f"{path}: {where}: no such column in the file; {have}") from None
    n = abs(spec)
    if not 1 <= n <= ncol:
        raise LogError(f"{path}: {where}: no column {n}; {have}")
    return n - 1, (-1.0 if spec < 0 else 1.0)


def _describe(names: list[str], lay: _Layout, j: int) -> str:
    """``'time' (file column 1, 'Time (ms)')``."""
    h = lay.header[j] if lay.header and j < len(lay.header) else None
    return f"{names[j]!r} (file column {j + 1}" + (f", {h!r})" if h and h != names[j] else ")")


def read_log(
    path: str | Path,
    columns: Mapping[str, str | int] | None = None,
    units: Mapping[str, str] | None = None,
    *,
    min_samples: int = MIN_SAMPLES,
    max_jitter: float = MAX_JITTER,
    required: Sequence[str] = tuple(REQUIRED),
    hint: str = "",
    delimiter: str | None = None,
    comment: Sequence[str] = COMMENT_CHARS,
    skip_rows: int = 0,
    extra: Mapping[str, str] | None = None,
    source: str = "",
) -> Log:
    """Read and validate one experiment log (see the module docstring for the format).

    Parameters
    ----------
    path:
        The text file (never modified).
    columns:
        Our column name → the file's column: its header text (``{"current": "i_m"}``) or
        its 1-based number (``{"time": 1}``, also as text ``"1"``); a leading ``-``
        (``"-theta"``, ``-2``) flips the column's sign.
    units:
        Our column name → unit of the file's numbers, e.g. ``{"current": "mA"}``;
        columns not named are taken as SI.
    min_samples, max_jitter:
        Fewest samples accepted; largest relative deviation of a time step from the
        median step.
    required, hint:
        The columns this use needs (default: the frequency experiments' five), and a
        sentence saying why, added to the message when one is missing.
    delimiter, comment, skip_rows:
        Field delimiter: one character, ``" "`` for runs of whitespace, or ``None`` /
        ``"auto"`` to sniff it on the first data row (see :data:`DELIMITERS`); the characters that
        start a comment line, and lines skipped at the top before anything is read.
    extra:
        Further column names ``columns`` and ``units`` may use, with their SI units
        (``{"K1": "V/rad"}``).
    source:
        Where ``columns`` / ``units`` came from, for messages (e.g. a format file).
    """
    path = Path(path)
    columns = dict(columns or {})
    units = dict(units or {})
    known = {**KNOWN, **(extra or {})}
    for ours in list(columns) + list(units):
        if ours not in known:
            raise LogError(
                f"{path}: {source or 'columns'}: {ours!r} is not a column name of the log "
                f"format; known: {', '.join(known)}"
            )
    text = _decode(path)
    lay = _layout(path, text, delimiter, comment, skip_rows)
    comments = lay.comments
    meta: dict[str, str] = {}
    for body in comments:
        key, sep, value = body.partition(":")
        if sep and key.strip() and " " not in key.strip():
            meta[key.strip()] = value.strip()
    plain_header = lay.header is not None and not lay.header_is_comment
    if plain_header:
        assert lay.header is not None
        ncol = len(lay.header)
    elif lay.rows:
        counts = np.bincount([len(f) for _, f in lay.rows])
        ncol = int(np.argmax(counts))
    else:
        ncol = 0

    # Our names for the file's columns.
    index: dict[str, tuple[int, float]] = {}
    for ours, spec in columns.items():
        index[ours] = _resolve_column(path, ours, spec, lay, ncol, source)
    taken: dict[int, str] = {}
    for ours, (j, _) in index.items():
        if j in taken:
            raise LogError(
                f"{path}: {source or 'columns'}: {taken[j]!r} and {ours!r} both name file "
                f"column {j + 1}; each column can be read once"
            )
        taken[j] = ours
    header = lay.header if lay.header is not None and len(lay.header) == ncol else None
    names = [
        taken.get(j, _norm(header[j]) if header is not None else f"col{j + 1}") for j in range(ncol)
    ]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise LogError(
            f"{path}: column(s) {', '.join(map(repr, dup))} appear more than once "
            f"in the header {lay.header}"
        )
    missing = [c for c in required if c not in names]
    if missing:
        found = (
            ", ".join(lay.header) if lay.header else f"(no header; {ncol} field(s) per data row)"
        )
        lines_msg = [
            f"{path}: missing column(s) {', '.join(map(repr, missing))}."
            + (f" {hint}" if hint else ""),
            f"  found:    {found}",
            f"  expected: {', '.join(required)} (optional: "
            f"{', '.join(c for c in KNOWN if c not in required)})",
            "  if the file names them differently, map them by header text or 1-based "
            "column number, e.g. "
            + " ".join(f"--column {c}=NAME" for c in missing)
            + " (read_log(..., columns={'"
            + missing[0]
            + "': 'NAME'}), or a log-format "
            "file's [columns])",
        ]
        raise LogError("\n".join(lines_msg))

    data = _parse_numbers(path, lay, ncol, names, plain_header)
    n = data.shape[0]
    if n < min_samples:
        raise LogError(f"{path}: too few samples: {n} data row(s), at least {min_samples} needed")
    for _ours, (j, sign) in index.items():
        if sign < 0:
            data[:, j] = -data[:, j]
    factors = {
        name: unit_factor(path, name, units[name], _as_linear(known, name, units[name]), source)
        for name in units
        if name in names
    }
    tj = names.index("time")
    time = data[:, tj] * factors.get("time", 1.0)
    signals: dict[str, np.ndarray] = {}
    for j, name in enumerate(names):
        if name == "time":
            continue
        x = data[:, j].copy()
        if name in factors:
            x *= factors[name]
        signals[name] = x
    _checks.check_signals(
        path,
        signals,
        time=time,
        time_column=_describe(names, lay, tj),
        lines=[ln for ln, _ in lay.rows],
        max_jitter=max_jitter,
        time_unit=units["time"] if "time" in factors else None,
    )
    return Log(path=path, time=time.copy(), signals=signals, comments=comments, meta=meta)


def _parse_numbers(
    path: Path, lay: _Layout, ncol: int, names: list[str], plain_header: bool
) -> np.ndarray:
    """The data rows as an (N, ncol) float array; a row with another number of fields, a
    field that is not a number, a NaN or an infinity is an error naming line and column."""
    out = np.empty((len(lay.rows), ncol))
    for r, (line, fields) in enumerate(lay.rows):
        if len(fields) != ncol:
            other = (
                f"the header (line {lay.header_line}) has {ncol}"
                if plain_header
                else f"most rows have {ncol}"
            )
            cut = ""
            if len(fields) < ncol:
                cut = (
                    f"; column {_describe(names, lay, len(fields))} onwards is missing "
                    "(is the file cut mid-line?)"
                )
            shown = f" ({', '.join(lay.header)})" if lay.header else ""
            raise LogError(
                f"{path}: data row {r + 1} (line {line}) has {len(fields)} "
                f"field(s); {other}{shown}{cut}"
            )
        try:
            out[r] = list(map(_number, fields))
        except ValueError:
            for j, f in enumerate(fields):
                try:
                    _number(f)
                except ValueError:
                    shown = repr(f) if f else "an empty field"
                    raise LogError(
                        f"{path}: column {_describe(names, lay, j)}, data row "
                        f"{r + 1} (line {line}): {shown} is not a number"
                    ) from None
    bad = ~np.isfinite(out)
    if bad.any():
        r, c = np.argwhere(bad)[0]
        what = "NaN" if math.isnan(out[r, c]) else "infinite"
        raise LogError(
            f"{path}: column {_describe(names, lay, c)}, data row {r + 1} (line "
            f"{lay.rows[r][0]}): value is {what}; {int(bad.sum())} non-finite "
            "value(s) in all"
        )
    return out


def _check_time(path: Path, t: np.ndarray, lay: _Layout, col: str, max_jitter: float) -> None:
    d = np.diff(t)
    if np.any(d <= 0):
        k = int(np.argmax(d <= 0))
        kind = "repeats" if d[k] == 0 else "decreases"
        raise LogError(
            f"{path}: time {kind} at data row {k + 2} (line {lay.rows[k + 1][0]}, "
            f"column {col}): t = {t[k + 1]:.9g} s after t = {t[k]:.9g} s (line "
            f"{lay.rows[k][0]}); time must increase strictly (duplicated or "
            "unsorted rows?)"
        )
    if len(d) == 0:
        return
    med = float(np.median(d))
    rel = np.abs(d - med) / med
    k = int(np.argmax(rel))
    if rel[k] > max_jitter:
        raise LogError(
            f"{path}: non-uniform sampling: the step from data row {k + 1} to "
            f"{k + 2} (lines {lay.rows[k][0]}-{lay.rows[k + 1][0]}, column {col}; "
            f"t = {t[k]:.9g} s) is {d[k]:.6g} s against a median step of "
            f"{med:.6g} s (relative deviation {rel[k]:.3g} > {max_jitter:g}); "
            "resample the log to a uniform time grid, or, if the controller ran "
            "at a fixed period and only the time stamps jitter, accept it with "
            "max_jitter= (flexarm fit / validate --max-jitter): the samples are "
            "then taken as uniform at the median step"
        )


def write_log(
    path: str | Path,
    time: Sequence[float] | np.ndarray,
    signals: Mapping[str, Sequence[float] | np.ndarray],
    *,
    comments: Sequence[str] | Mapping[str, object] = (),
    overwrite: bool = False,
    fmt: str = "%.12g",
    required: Sequence[str] = tuple(REQUIRED),
) -> Path:
    """Write a log in the exchange format (SI values).

    ``signals`` must hold the required columns other than ``time``; extra columns follow
    in the order given.  ``comments`` are lines written as ``# line`` before the header
    (a mapping is written as ``# key: value``).  An existing file is not replaced unless
    ``overwrite=True`` (:class:`LogExistsError`).  Written atomically
    (:func:`flexarm.io.write.atomic_open`): the file is complete or absent, never partial.
    """
    path = Path(path)
    t = np.asarray(time, dtype=float)
    missing = [c for c in required if c != "time" and c not in signals]
    if missing:
        raise LogError(f"{path}: cannot write: missing signal(s) {', '.join(missing)}")
    order = [c for c in required if c != "time"] + [c for c in signals if c not in required]
    cols = [t]
    for c in order:
        x = np.asarray(signals[c], dtype=float)
        if x.shape != t.shape:
            raise LogError(
                f"{path}: cannot write: signal {c!r} has shape {x.shape}, time has {t.shape}"
            )
        cols.append(x)
    if isinstance(comments, Mapping):
        comment_lines = [f"{k}: {v}" for k, v in comments.items()]
    else:
        comment_lines = list(comments)
    try:
        with atomic_open(path, "w", overwrite=overwrite, newline="") as f:
            for c in comment_lines:
                for line in str(c).splitlines() or [""]:
                    f.write(f"# {line}\n")
            f.write(",".join(["time", *order]) + "\n")
            np.savetxt(f, np.column_stack(cols), delimiter=",", fmt=fmt)
    except OutputExistsError:
        raise LogExistsError(
            f"{path}: exists already; not overwritten (pass overwrite=True)"
        ) from None
    return path
