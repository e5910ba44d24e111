"""How an error ends a command: the one place.

Exit codes of every ``flexarm`` command:

* 0: done;
* 1: an internal error (a bug of flexarm): one line ``internal error: ...`` naming a log
  file that holds the traceback (in ``$FLEXARM_LOG_DIR``, else the system's temporary
  folder);
* 2: a bad input: one line ``error: ...`` (the file or option, the value and the fix): a
  project error raised by the library, an option the command refuses, or an option or
  argument the parser refuses;
* 128 + the signal's number: interrupted, 130 for Ctrl-C (SIGINT), 143 for SIGTERM
  (:func:`flexarm.cli.common.guarded`, which every command runs in); ``fit`` writes its best
  result first, and a second signal does not break that writing.
"""

from __future__ import annotations

import os
import tempfile
import traceback
from pathlib import Path

import typer
from rich.markup import escape

from flexarm.cli.common import err, fold

EXIT_INTERNAL = 1
EXIT_BAD_INPUT = 2


def project_errors() -> tuple[type[BaseException], ...]:
    """The project's own errors, printed as one line: every one is a
    :class:`flexarm.errors.FlexarmError` (issue #25)."""
    from flexarm.errors import FlexarmError

    return (FlexarmError,)


def one_line(exc: BaseException) -> str:
    """A project error as one line: :func:`flexarm.errors.one_line`."""
    from flexarm.errors import one_line as _library_one_line

    return _library_one_line(exc)


def bad_input(exc: BaseException) -> int:
    """Print a project error as ``error: ...`` on one line; the exit code (2).  A write
    that failed with no copy saved anywhere (:class:`flexarm.io.write.WriteFailedError`
    with text ``content``) prints that text on stdout first: the result is not lost."""
    content = getattr(exc, "content", None)
    if isinstance(content, str) and getattr(exc, "rescued", True) is None:
        import sys

        sys.stdout.write(content if content.endswith("\n") else content + "\n")
        sys.stdout.flush()
    err.print(f"[bold red]error:[/] {escape(one_line(exc))}", highlight=False, soft_wrap=True)
    return EXIT_BAD_INPUT


def log_dir() -> Path:
    """Where internal errors' tracebacks are written."""
    return Path(os.environ.get("FLEXARM_LOG_DIR") or tempfile.gettempdir())


#: modules whose RecursionError means a nested input, not a flexarm bug
_PARSERS = ("tomllib", "tomli", "json", "tomli_w", "scipy/io", "h5py")


def input_error(exc: BaseException) -> str | None:
    """The one line for an exception that is a bad or oversized input rather than a
    flexarm bug, or None (issue #45): a TOML or JSON document nested beyond Python's
    recursion limit (the RecursionError raised inside the parser), a text file that is not
    UTF-8 (a UTF-16 manifest), memory that ran out for the input's size (huge --plants,
    --periods or files), a full disk or a read-only file system at a write."""
    import errno

    if isinstance(exc, RecursionError):
        tb, frames = exc.__traceback__, []
        while tb is not None:
            frames.append(tb.tb_frame.f_code.co_filename.replace("\\", "/"))
            tb = tb.tb_next
        if any(any(f"/{m}" in f for m in _PARSERS) for f in frames[-50:]):
            return (
                "an input file is nested too deeply to read (arrays, tables or objects "
                "inside each other beyond Python's recursion limit); flatten it"
            )
        return None
    if isinstance(exc, UnicodeDecodeError):
        return (
            f"an input file is not UTF-8 text ({exc.reason} at byte {exc.start}, "
            f"{exc.encoding}); save it as UTF-8 (e.g. a spreadsheet's 'CSV UTF-8')"
        )
    if isinstance(exc, MemoryError):
        return (
            "not enough memory for this input (a very large option value such as --plants "
            "or --periods, or a very large file); give a smaller one"
        )
    if isinstance(exc, OSError) and exc.errno in (
        errno.ENOSPC,
        errno.EDQUOT,
        errno.EROFS,
        errno.ENAMETOOLONG,
    ):
        where = f" {exc.filename}" if getattr(exc, "filename", None) else ""
        return f"cannot write{where}: {exc.strerror}; free space or choose another folder"
    return None


def internal_error(exc: BaseException, command: str = "") -> int:
    """Any other exception: its traceback into a log file
    (:func:`flexarm.errors.internal_error_report`), one line naming that file on stderr;
    the exit code (1).  An exception that is a bad input (:func:`input_error`) is one
    ``error:`` line and exit 2 instead."""
    from flexarm.errors import internal_error_report

    line = input_error(exc)
    if line is not None:
        err.print(f"[bold red]error:[/] {escape(fold(line))}", highlight=False, soft_wrap=True)
        return EXIT_BAD_INPUT

    try:
        where = str(internal_error_report(exc, log_dir()))
    except OSError as exc2:
        err.print(
            f"[bold red]internal error:[/] {escape(fold(f'{type(exc).__name__}: {exc}'))}"
            f" (the traceback could not be saved: {escape(str(exc2))}; it follows)",
            highlight=False,
            soft_wrap=True,
        )
        err.print(
            "".join(traceback.format_exception(type(exc), exc, exc.__traceback__)),
            markup=False,
            highlight=False,
        )
        return EXIT_INTERNAL
    msg = fold(f"{type(exc).__name__}: {exc}")
    err.print(
        f"[bold red]internal error:[/] {escape(msg)} (a flexarm bug: the traceback "
        f"is in {escape(where)}; please report it with that file)",
        highlight=False,
        soft_wrap=True,
    )
    return EXIT_INTERNAL


def usage_error(exc: typer.TyperException) -> int:
    """An option or argument the parser refuses (a missing option, ``--plants abc``, an
    unknown option): one line with the command's ``--help``; the exit code (2)."""
    ctx = getattr(exc, "ctx", None)
    where = f" (see {ctx.command_path} --help)" if ctx is not None else ""
    err.print(
        f"[bold red]error:[/] {escape(fold(exc.format_message()))}{escape(where)}",
        highlight=False,
        soft_wrap=True,
    )
    return exc.exit_code
