"""Errors shared across layers (kept at the bottom so every layer may raise them).

Every error flexarm raises on purpose is a :class:`FlexarmError`: a bad input, an output
it refuses to write, a design it refuses to export.  Each project error keeps a second,
standard base (``ValueError``, ``FileExistsError``, ``RuntimeError``) so code that catches
those still catches it.  A :class:`FlexarmError` may carry what the one-line message is
made of: ``file``, ``field``, ``value`` and ``fix``; :func:`one_line` writes it as the
single line the command line prints (exit code 2).  Anything else that escapes is a bug:
:func:`internal_error_report` writes its traceback to a log file and :func:`one_line`
names that file.

The signal handling shared by the CLI and long library runs (a fit) is
:func:`flexarm.io.write.interruptible`.
"""

from __future__ import annotations

import datetime as _dt
import os
import sys
import traceback
from pathlib import Path
from typing import Any

__all__ = [
    "FlexarmError",
    "SimulationDiverged",
    "OutputExistsError",
    "InputOverwriteError",
    "FitInterrupted",
    "Interrupted",
    "UnstableDesignError",
    "LogError",
    "MatFileError",
    "one_line",
    "internal_error_report",
]


class FlexarmError(Exception):
    """The base of every flexarm error.

    ``FlexarmError(message, file=..., field=..., value=..., fix=...)``: each keyword is
    optional; the message is what went wrong, the keywords where (the file, the field or
    column of it), what was found (the value) and what to do (the fix).  ``str(exc)`` is
    ``<file>: <field> = <value>: <message>; <fix>``, each part only where given and not
    already in the message; :func:`one_line` puts a message of several lines on one."""

    def __init__(
        self,
        *args: Any,
        file: str | os.PathLike | None = None,
        field: str | None = None,
        value: Any = None,
        fix: str | None = None,
    ):
        super().__init__(*args)
        self.file = None if file is None else str(file)
        self.field = field
        self.value = value
        self.fix = fix

    def __str__(self) -> str:
        return _compose(self, super().__str__())


class SimulationDiverged(FlexarmError, RuntimeError):
    """A closed loop whose state became non-finite or left the plausible range; the
    message says when and which signal or state variable."""


class OutputExistsError(FlexarmError, FileExistsError):
    """A writer (:mod:`flexarm.io.write`) refused to replace an existing file; the message
    names it (pass ``overwrite=True``, on the command line ``--overwrite``)."""


class InputOverwriteError(FlexarmError, PermissionError):
    """A writer refused to write over a file that is an input of the run
    (:func:`flexarm.io.write.inputs`), ``overwrite=True`` or not."""


class UnstableDesignError(FlexarmError, ValueError):
    """A controller design whose verdict (:attr:`flexarm.design.result.Design.verdict`) is
    not ``"stable"``, used where that is refused (``accept_unstable=False`` on the design,
    ``force=False`` on the C export).  ``.design`` is the design (``None`` where not known)."""

    def __init__(self, *args: Any, design: Any = None, **kw: Any):
        super().__init__(*args, **kw)
        self.design = design


class LogError(FlexarmError, ValueError):
    """A log file that cannot be used; the message names the file and the problem
    (raised by the log readers, :mod:`flexarm.io.logs`, and their checks)."""


class MatFileError(LogError):
    """A ``.mat`` file, or a spec into it, that cannot be used; names the file and the
    field (:mod:`flexarm.io.matfile`)."""


class Interrupted(KeyboardInterrupt):
    """A run stopped by a signal inside :func:`flexarm.io.write.interruptible` (SIGTERM, or
    SIGINT when the default handler is not Python's).  A ``KeyboardInterrupt`` (so code
    that keeps the best result on Ctrl-C keeps it on SIGTERM too), not a
    :class:`FlexarmError`: an ``except Exception`` does not swallow it.  ``.signal`` is the
    signal's name; the CLI exits 128 + its number (130 for SIGINT, 143 for SIGTERM)."""

    def __init__(self, *args: Any, signal: str = "SIGINT", number: int = 2):
        super().__init__(*args)
        self.signal = signal
        self.number = number


class FitInterrupted(FlexarmError):
    """A fit stopped by the user (Ctrl-C).  ``.result`` is the best result so far, with the
    normal fit result's writing methods (``to_dict``, ``to_json``, ``write_scenario``,
    ``plots``, ``summary``), or ``None`` when nothing was evaluated yet."""

    def __init__(self, result=None, message: str = "fit interrupted by the user"):
        super().__init__(message)
        self.result = result


def _shown(text: str, part: Any) -> bool:
    return part is not None and str(part) in text


def _compose(exc: FlexarmError, msg: str) -> str:
    """``<file>: <field> = <value>: <msg>; <fix>``, the parts ``msg`` does not show."""
    head = []
    if exc.file and not _shown(msg, exc.file):
        head.append(exc.file)
    if exc.field and not _shown(msg, exc.field):
        head.append(
            exc.field
            if exc.value is None or _shown(msg, exc.value)
            else f"{exc.field} = {exc.value!r}"
        )
    elif exc.value is not None and not _shown(msg, exc.value):
        head.append(f"got {exc.value!r}")
    text = ": ".join([*head, msg]) if msg else ": ".join(head)
    if exc.fix and not _shown(msg, exc.fix):
        text = f"{text}; {exc.fix}" if text else exc.fix
    return text


def one_line(exc: BaseException, log: str | os.PathLike | None = None) -> str:
    """The one line the command line prints for ``exc`` (no newline, no traceback).

    A :class:`FlexarmError`: ``str(exc)`` (``<file>: <field> = <value>: <message>; <fix>``,
    each part only where given and not already in the message), a message of several lines
    (a scenario's list of problems) joined with ``"; "``.  Any other exception:
    ``internal error: <Type>: <message>`` and, with ``log`` (the file
    :func:`internal_error_report` wrote), ``(traceback in <log>)``."""
    msg = "; ".join(s.strip() for s in str(exc).splitlines() if s.strip())
    if isinstance(exc, FlexarmError):
        return msg or type(exc).__name__
    text = (
        f"internal error: {type(exc).__name__}: {msg}"
        if msg
        else f"internal error: {type(exc).__name__}"
    )
    if log is not None:
        text += f" (traceback in {log})"
    return text


def internal_error_report(exc: BaseException, folder: str | os.PathLike) -> Path:
    """Write ``exc``'s traceback, the command line and the Python and flexarm versions
    to ``folder/flexarm-error-<UTC time>-<pid>.log`` (the folder is created) and return
    that path; the CLI names it in its one line (:func:`one_line` with ``log=``).  A
    folder that cannot be written falls back to the system's temporary folder."""
    stamp = _dt.datetime.now(_dt.UTC).strftime("%Y%m%dT%H%M%SZ")
    try:
        from importlib.metadata import version

        ver = version("flexarm")
    except Exception:  # a report must not fail on a missing distribution
        ver = "unknown"
    text = "".join(
        [
            f"flexarm {ver}, Python {sys.version.split()[0]}, {stamp}\n",
            "command: " + " ".join(sys.argv) + "\n\n",
            *traceback.format_exception(type(exc), exc, exc.__traceback__),
        ]
    )
    import tempfile

    for base in (Path(folder), Path(tempfile.gettempdir())):
        path = base / f"flexarm-error-{stamp}-{os.getpid()}.log"
        try:
            base.mkdir(parents=True, exist_ok=True)
            with open(path, "x", encoding="utf-8") as f:
                f.write(text)
            return path
        except OSError:
            continue
    raise OSError(f"cannot write the error report into {folder} or the temporary folder")
