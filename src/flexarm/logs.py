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

Files that name or scale columns differently are read with ``columns`` (our name → the
file's name) and ``units`` (our name → the unit of the file's numbers, parsed by pint),
e.g. ``read_log(p, columns={"current": "i_m"}, units={"current": "mA"})``.

Validation (every message starts with the file's path): missing columns (lists the found
and the expected names and how to map them), empty / non-numeric / NaN / infinite values
(column and row), non-increasing or repeated time, non-uniform sampling (relative deviation
of a step from the median step above ``1e-3``; the worst step is named), too few samples.
Input files are only ever opened for reading.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from flexarm.errors import OutputExistsError
from flexarm.units import ureg
from flexarm.write import atomic_open

#: Required columns and their SI units.
REQUIRED: dict[str, str] = {
    "time": "s",
    "reference": "rad",
    "current": "A",
    "motor_angle": "rad",
    "tip_angle": "rad",
}
#: Optional columns the format knows, with their SI units.
OPTIONAL: dict[str, str] = {
    "voltage": "V",
    "tip_deflection": "m",
    "motor_velocity": "rad/s",
    "tip_velocity": "m/s",
}
KNOWN: dict[str, str] = {**REQUIRED, **OPTIONAL}

#: Largest accepted relative deviation of a time step from the median step.
MAX_JITTER = 1e-3
#: Fewest samples accepted in a log.
MIN_SAMPLES = 16


class LogError(ValueError):
    """A log file that cannot be used; the message names the file and the problem."""


class LogExistsError(LogError, OutputExistsError):
    """:func:`write_log` refused to replace an existing file (pass ``overwrite=True``)."""


@dataclass
class Log:
    """One experiment log, in SI units.

    ``signals`` maps column name → array (all columns except ``time``), ``comments`` holds
    the comment lines (without the leading ``#``), ``meta`` the ``key: value`` comments.
    """

    path: Path | None
    time: np.ndarray
    signals: dict[str, np.ndarray]
    comments: list[str] = field(default_factory=list)
    meta: dict[str, str] = field(default_factory=dict)

    @property
    def dt(self) -> float:
        """Sampling period (s): the median time step."""
        return float(np.median(np.diff(self.time)))

    @property
    def name(self) -> str:
        return str(self.path) if self.path is not None else "<log>"

    def __getitem__(self, column: str) -> np.ndarray:
        if column == "time":
            return self.time
        try:
            return self.signals[column]
        except KeyError:
            raise KeyError(f"{self.name}: no column {column!r}; columns: "
                           f"time, {', '.join(self.signals)}") from None

    def __len__(self) -> int:
        return len(self.time)


def _unit_factor(path: Path, column: str, unit: str) -> float:
    """Factor from the file's ``unit`` to the SI unit of ``column``."""
    si = KNOWN.get(column)
    if si is None:
        raise LogError(f"{path}: a unit was given for column {column!r}, which flexarm "
                       f"does not know; known: {', '.join(KNOWN)}")
    try:
        try:
            q = ureg.Quantity(1.0, unit)
        except Exception:  # a scaled unit, e.g. encoder counts as "turn/4096"
            q = ureg.parse_expression(unit)
        return float(q.to(si).magnitude)
    except Exception as exc:  # pint raises several exception types
        raise LogError(f"{path}: cannot convert column {column!r} from {unit!r} to {si} "
                       f"({exc})") from None


def _parse_header(path: Path, text: str):
    """Comment lines and header row at the top of ``text``.

    Returns (comments, meta, header line, its 0-based line index, offset of the body).
    """
    comments: list[str] = []
    meta: dict[str, str] = {}
    pos, k = 0, 0
    while pos < len(text):
        end = text.find("\n", pos)
        end = len(text) if end < 0 else end
        line, pos = text[pos:end], end + 1
        stripped = line.strip()
        if stripped.startswith("#"):
            body = stripped[1:]
            body = body[1:] if body.startswith(" ") else body
            comments.append(body.rstrip())
            if ":" in body:
                key, _, value = body.partition(":")
                if key.strip() and " " not in key.strip():
                    meta[key.strip()] = value.strip()
        elif stripped:
            return comments, meta, line, k, pos
        k += 1
    raise LogError(f"{path}: no header row; expected a line "
                   f"'{','.join(REQUIRED)}' after any '#' comment lines")


def read_log(path: str | Path, columns: Mapping[str, str] | None = None,
             units: Mapping[str, str] | None = None, *,
             min_samples: int = MIN_SAMPLES, max_jitter: float = MAX_JITTER,
             required: Sequence[str] = tuple(REQUIRED), hint: str = "") -> Log:
    """Read and validate one experiment log (see the module docstring for the format).

    Parameters
    ----------
    path:
        The CSV file (never modified).
    columns:
        Our column name → the name used in the file, e.g. ``{"current": "i_m"}``.
    units:
        Our column name → unit of the file's numbers, e.g. ``{"current": "mA"}``;
        columns not named are taken as SI.
    min_samples, max_jitter:
        Fewest samples accepted; largest relative deviation of a time step from the
        median step.
    required, hint:
        The columns this use needs (default: the frequency experiments' five), and a
        sentence saying why, added to the message when one is missing.
    """
    path = Path(path)
    columns = dict(columns or {})
    units = dict(units or {})
    for ours in list(columns) + list(units):
        if ours not in KNOWN:
            raise LogError(f"{path}: {ours!r} is not a column name of the log format; "
                           f"known: {', '.join(KNOWN)}")
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise LogError(f"{path}: no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise LogError(f"{path}: cannot read the file ({exc})") from None
    comments, meta, header_line, h, body_start = _parse_header(path, text)
    header = [c.strip() for c in next(csv.reader([header_line]))]

    # Map the file's names to ours.
    file_to_ours = {v: k for k, v in columns.items()}
    names = [file_to_ours.get(c, c) for c in header]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise LogError(f"{path}: column(s) {', '.join(map(repr, dup))} appear more than once "
                       f"in the header {header}")
    missing = [c for c in required if c not in names]
    if missing:
        lines_msg = [
            f"{path}: missing column(s) {', '.join(map(repr, missing))}." + (f" {hint}" if hint else ""),
            f"  found:    {', '.join(header) if header else '(none)'}",
            f"  expected: {', '.join(required)} (optional: "
            f"{', '.join(c for c in KNOWN if c not in required)})",
        ]
        not_mapped = [c for c in missing if c in columns]
        if not_mapped:
            lines_msg.append("  the mapping " + ", ".join(
                f"{c}={columns[c]}" for c in not_mapped) + " names column(s) not in the file")
        lines_msg.append(
            "  if the file names them differently, map them, e.g. "
            + " ".join(f"--column {c}=NAME" for c in missing)
            + " (read_log(..., columns={'" + missing[0] + "': 'NAME'}))")
        raise LogError("\n".join(lines_msg))

    data = _parse_numbers(path, text, body_start, h, header, names)
    n = data.shape[0]
    if n < min_samples:
        raise LogError(f"{path}: too few samples: {n} data row(s), at least {min_samples} "
                       "needed")

    time = data[:, names.index("time")] * (_unit_factor(path, "time", units["time"])
                                           if "time" in units else 1.0)
    _check_time(path, time, h, max_jitter)
    signals: dict[str, np.ndarray] = {}
    for j, name in enumerate(names):
        if name == "time":
            continue
        x = data[:, j].copy()
        if name in units:
            x *= _unit_factor(path, name, units[name])
        signals[name] = x
    return Log(path=path, time=time.copy(), signals=signals, comments=comments, meta=meta)


def _parse_numbers(path: Path, text: str, body_start: int, h: int, header: list[str],
                   names: list[str]) -> np.ndarray:
    """Numbers below the header (line ``h``); on any problem, locate it by column and row."""
    body = text[body_start:]
    ncol = len(header)
    try:
        with np.errstate(all="ignore"):
            data = np.loadtxt(io.StringIO(body), delimiter=",", ndmin=2, comments="#",
                              dtype=float)
        ok = data.shape[1] == ncol if data.size else True
    except ValueError:
        ok = False
    if not ok:
        _locate_parse_error(path, text.splitlines(), h, header, names)
    if data.size == 0:
        data = np.zeros((0, ncol))
    bad = ~np.isfinite(data)
    if bad.any():
        r, c = np.argwhere(bad)[0]
        file_line = _data_line_numbers(text.splitlines(), h)[r]
        what = "NaN" if math.isnan(data[r, c]) else "infinite"
        raise LogError(f"{path}: column {names[c]!r} ({header[c]!r} in the file), data row "
                       f"{r + 1} (line {file_line}): value is {what}; "
                       f"{int(bad.sum())} non-finite value(s) in all")
    return data


def _data_line_numbers(lines: list[str], h: int) -> list[int]:
    """1-based file line numbers of the data rows (blank and comment lines skipped)."""
    return [k + 1 for k in range(h + 1, len(lines))
            if lines[k].strip() and not lines[k].lstrip().startswith("#")]


def _locate_parse_error(path, lines, h, header, names):
    ncol = len(header)
    row = 0
    for k in range(h + 1, len(lines)):
        line = lines[k]
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        row += 1
        fields = next(csv.reader([line]))
        if len(fields) != ncol:
            raise LogError(f"{path}: data row {row} (line {k + 1}) has {len(fields)} "
                           f"field(s); the header has {ncol} ({', '.join(header)})")
        for j, f in enumerate(fields):
            try:
                float(f)
            except ValueError:
                shown = repr(f.strip()) if f.strip() else "an empty field"
                raise LogError(f"{path}: column {names[j]!r} ({header[j]!r} in the file), "
                               f"data row {row} (line {k + 1}): {shown} is not a number"
                               ) from None
    raise LogError(f"{path}: cannot read the numbers below the header")


def _check_time(path: Path, t: np.ndarray, h: int, max_jitter: float) -> None:
    d = np.diff(t)
    if np.any(d <= 0):
        k = int(np.argmax(d <= 0))
        kind = "repeats" if d[k] == 0 else "decreases"
        raise LogError(f"{path}: time {kind} at data row {k + 2}: t = {t[k + 1]:.9g} s after "
                       f"t = {t[k]:.9g} s; time must increase strictly (duplicated or "
                       "unsorted rows?)")
    med = float(np.median(d))
    rel = np.abs(d - med) / med
    k = int(np.argmax(rel))
    if rel[k] > max_jitter:
        raise LogError(f"{path}: non-uniform sampling: the step from data row {k + 1} to "
                       f"{k + 2} (t = {t[k]:.9g} s) is {d[k]:.6g} s against a median step of "
                       f"{med:.6g} s (relative deviation {rel[k]:.3g} > {max_jitter:g}); "
                       "resample the log to a uniform time grid, or, if the controller ran "
                       "at a fixed period and only the time stamps jitter, accept it with "
                       "max_jitter= (flexarm fit / validate --max-jitter): the samples are "
                       "then taken as uniform at the median step")


def write_log(path: str | Path, time: Sequence[float] | np.ndarray,
              signals: Mapping[str, Sequence[float] | np.ndarray], *,
              comments: Sequence[str] | Mapping[str, object] = (),
              overwrite: bool = False, fmt: str = "%.12g",
              required: Sequence[str] = tuple(REQUIRED)) -> Path:
    """Write a log in the exchange format (SI values).

    ``signals`` must hold the required columns other than ``time``; extra columns follow
    in the order given.  ``comments`` are lines written as ``# line`` before the header
    (a mapping is written as ``# key: value``).  An existing file is not replaced unless
    ``overwrite=True`` (:class:`LogExistsError`).  Written atomically
    (:func:`flexarm.write.atomic_open`): the file is complete or absent, never partial.
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
            raise LogError(f"{path}: cannot write: signal {c!r} has shape {x.shape}, "
                           f"time has {t.shape}")
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
        raise LogExistsError(f"{path}: exists already; not overwritten (pass overwrite=True)"
                             ) from None
    return path
