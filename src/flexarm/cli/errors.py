"""How an error ends a command: the one place.

Exit codes of every ``flexarm`` command:

* 0: done;
* 1: an internal error (a bug of flexarm): one line ``internal error: ...`` naming a log
  file that holds the traceback (in ``$FLEXARM_LOG_DIR``, else the system's temporary
  folder);
* 2: a bad input: one line ``error: ...`` (the file or option, the value and the fix): a
  project error raised by the library, an option the command refuses, or an option or
  argument the parser refuses;
* 130: interrupted (Ctrl-C); ``fit`` writes its best result first.
"""

from __future__ import annotations

import datetime
import os
import sys
import tempfile
import traceback
from pathlib import Path

import typer
from rich.markup import escape

from flexarm.cli.common import err, fold

EXIT_INTERNAL = 1
EXIT_BAD_INPUT = 2


def project_errors() -> tuple[type[BaseException], ...]:
    """The project's own error classes: raised for bad input, printed as one line.

    MERGE: when ``flexarm.errors.FlexarmError`` (the ``safe`` work) is the base of every
    project error, this becomes ``return (FlexarmError,)``.  Until then, the classes the
    library raises for bad input, listed once here (imported on demand: an error path
    only, so the command line starts without them)."""
    from flexarm.control.regulation import RegulationError
    from flexarm.deploy.c_export import ExportError
    from flexarm.errors import OutputExistsError, SimulationDiverged
    from flexarm.identification.frequency_domain.excitation import ExcitationError
    from flexarm.identification.frequency_domain.harmonics import IdentificationError
    from flexarm.identification.frequency_domain.tfest import TFEstError
    from flexarm.identification.time_domain.logs import FitInputError
    from flexarm.io.logs import LogError  # LogFormatError, MatFileError, LogExistsError
    from flexarm.models.modes import ModeError
    from flexarm.specs.scenario import ScenarioError
    from flexarm.units import UnitError

    return (ScenarioError, LogError, FitInputError, IdentificationError, ExcitationError,
            TFEstError, ExportError, RegulationError, ModeError, UnitError,
            OutputExistsError, SimulationDiverged)


def one_line(exc: BaseException) -> str:
    """A project error as one line (its message with line breaks folded).

    MERGE: becomes ``flexarm.errors.one_line(exc)``."""
    return fold(str(exc)) or type(exc).__name__


def bad_input(exc: BaseException) -> int:
    """Print a project error as ``error: ...`` on one line; the exit code (2)."""
    err.print(f"[bold red]error:[/] {escape(one_line(exc))}", highlight=False, soft_wrap=True)
    return EXIT_BAD_INPUT


def log_dir() -> Path:
    """Where internal errors' tracebacks are written."""
    return Path(os.environ.get("FLEXARM_LOG_DIR") or tempfile.gettempdir())


def internal_error(exc: BaseException, command: str = "") -> int:
    """Any other exception: its traceback into a log file, one line naming that file on
    stderr; the exit code (1)."""
    from flexarm import __version__

    stamp = datetime.datetime.now(datetime.timezone.utc)
    text = (f"flexarm {__version__}, Python {sys.version.split()[0]}, "
            f"{stamp.isoformat(timespec='seconds')}\ncommand: {command or ' '.join(sys.argv)}\n\n"
            + "".join(traceback.format_exception(type(exc), exc, exc.__traceback__)))
    where = None
    try:
        folder = log_dir()
        folder.mkdir(parents=True, exist_ok=True)
        fd, name = tempfile.mkstemp(prefix=f"flexarm-error-{stamp:%Y%m%dT%H%M%S}-",
                                    suffix=".log", dir=folder)
        with os.fdopen(fd, "w") as f:
            f.write(text)
        where = name
    except OSError as exc2:
        where = None
        note = f"(the traceback could not be saved: {exc2}; it follows)"
    msg = fold(f"{type(exc).__name__}: {exc}")
    if where is not None:
        err.print(f"[bold red]internal error:[/] {escape(msg)} (a flexarm bug: the traceback "
                  f"is in {escape(where)}; please report it with that file)", highlight=False,
                  soft_wrap=True)
    else:
        err.print(f"[bold red]internal error:[/] {escape(msg)} {escape(note)}",
                  highlight=False, soft_wrap=True)
        err.print(text, markup=False, highlight=False)
    return EXIT_INTERNAL


def usage_error(exc: typer.TyperException) -> int:
    """An option or argument the parser refuses (a missing option, ``--plants abc``, an
    unknown option): one line with the command's ``--help``; the exit code (2)."""
    ctx = getattr(exc, "ctx", None)
    where = f" (see {ctx.command_path} --help)" if ctx is not None else ""
    err.print(f"[bold red]error:[/] {escape(fold(exc.format_message()))}{escape(where)}",
              highlight=False, soft_wrap=True)
    return exc.exit_code
