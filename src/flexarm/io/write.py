"""The one file writer: every file flexarm writes goes through here, atomically.

Method: the content is written to a temporary file in the target's own folder (so the
rename cannot cross file systems), flushed and ``fsync``-ed, then moved onto the target in
one step (``os.replace``; ``os.link`` when the target must not exist, which fails instead
of replacing a file that appeared meanwhile).  A reader therefore sees the old file or the
complete new one, never a half-written one, and on any exception, ``KeyboardInterrupt``
included, the temporary file is removed and the target is left as it was.

The output policy (issue #25), one for every writer:

* an existing target is replaced only with ``overwrite=True``; otherwise
  :class:`flexarm.errors.OutputExistsError` (a ``FileExistsError``) names it; an output
  folder (figures) that holds files is written into only with ``overwrite=True``
  (:func:`output_folder`);
* a file that is an input of the run is never written over, ``overwrite=True`` or not:
  the run declares its inputs with :func:`inputs` (a context; the CLI wraps each command
  in it) and every write checks the target against them
  (:class:`flexarm.errors.InputOverwriteError`; the same file by another path or a hard
  link counts);
* result keys are unique per input (:func:`unique_keys`): the file names without
  extension where they differ, else every input's path relative to the inputs' common
  folder; the same file given twice is numbered (``name#2``);
* a write that fails after these checks (a full disk, a quota, an I/O error) keeps what
  it was to write: every writer here goes through one (``_write_kept``) that saves the
  content beside the target, else in the current folder, else in the system's temporary
  folder, and raises :class:`WriteFailedError` naming the copy (the command line: one
  ``error:`` line, exit 2; where no copy could be made, text is printed on stdout);
  :func:`save_or_rescue` also saves a result whose path the policy refuses (a file that
  appeared meanwhile, a folder that vanished) next to it and says where;
* SIGTERM and a second Ctrl-C do not lose the best result (:func:`interruptible`);
* names are data (issue #45): a scenario's ``name``, a manifest ``id`` or any other text
  becomes a file name only through :func:`safe_name` (letters, digits, ``._-``; never
  ``.``, ``..``, a path or an empty name; at most :data:`NAME_MAX` characters), and two
  outputs of one run never share a name (:func:`distinct_names`, :func:`check_outputs`:
  every output of a command checked before any work);
* a concurrent writer into the same output folder is detected, not raced: the folder is
  locked by a create-exclusive lock file (:func:`lock_folder`, released when the
  command's :func:`run_scope` ends).

Functions: :func:`atomic_open` (a file object), :func:`atomic_path` (a temporary path for
writers that take a path), :func:`write_text`, :func:`write_bytes`, :func:`write_json`,
:func:`write_toml`, :func:`save_figure`, :func:`output_folder`, :func:`inputs`,
:func:`unique_keys`, :func:`save_or_rescue`, :func:`interruptible`.  CSV logs are
written by :func:`flexarm.io.logs.write_log` through :func:`atomic_open`.
"""

from __future__ import annotations

import contextlib
import contextvars
import datetime as _dt
import json
import os
import signal
import tempfile
import threading
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

from flexarm.errors import FlexarmError, InputOverwriteError, Interrupted, OutputExistsError

__all__ = [
    "atomic_open",
    "atomic_path",
    "write_text",
    "write_bytes",
    "write_json",
    "write_toml",
    "write_each",
    "save_figure",
    "output_folder",
    "inputs",
    "is_input",
    "unique_keys",
    "save_or_rescue",
    "Saved",
    "interruptible",
    "Interruptible",
    "OutputExistsError",
    "InputOverwriteError",
    "NAME_MAX",
    "safe_name",
    "distinct_names",
    "check_outputs",
    "run_scope",
    "lock_folder",
    "LOCK_NAME",
    "read_input",
    "InputFileError",
    "MAX_TEXT_INPUT",
    "WriteFailedError",
    "rescue_path",
    "OutputFolderError",
    "OutputIsFolderError",
]


def _file_mode() -> int:
    """rw for whom the umask allows (what ``open(path, "w")`` would give; mkstemp gives 0600)."""
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


# ------------------------------------------------------------------ the run's inputs
#: the input files of the current run: (resolved path, (st_dev, st_ino) or None)
_INPUTS: contextvars.ContextVar[tuple[tuple[Path, tuple[int, int] | None], ...]] = (
    contextvars.ContextVar("flexarm_inputs", default=())
)


def _identity(path: Path) -> tuple[int, int] | None:
    try:
        st = path.stat()
    except OSError:
        return None
    return (st.st_dev, st.st_ino)


@contextlib.contextmanager
def inputs(paths: Iterable[str | os.PathLike | None]) -> Iterator[None]:
    """Declare ``paths`` the run's input files for the block (nested blocks add to the
    outer ones; ``None`` entries and folders' files are skipped: a folder given as an
    input protects the files in it when written to).  Every writer of this module then
    refuses to write over any of them, even with ``overwrite=True``."""
    items = []
    for p in paths:
        if p is None:
            continue
        q = Path(p).expanduser()
        items.append((q.resolve(), _identity(q)))
    token = _INPUTS.set(_INPUTS.get() + tuple(items))
    try:
        yield
    finally:
        _INPUTS.reset(token)


def is_input(path: str | os.PathLike) -> Path | None:
    """The declared input (:func:`inputs`) that ``path`` would write over, or None: the same
    resolved path, a path inside a declared input folder, or the same file (device and
    inode) by another name."""
    q = Path(path).expanduser()
    rq = q.resolve()
    ident = _identity(q)
    for p, pid in _INPUTS.get():
        if rq == p or (ident is not None and ident == pid):
            return p
        if pid is not None and p.is_dir() and p in rq.parents:
            return p
    return None


def _check_target(path: Path, overwrite: bool) -> None:
    src = is_input(path)
    if src is not None:
        raise InputOverwriteError(
            f"{path}: is an input of this run ({src}); flexarm never writes over an input, "
            "even with overwrite",
            file=path,
            fix="give another output path",
        )
    if path.is_dir():
        raise OutputIsFolderError(f"{path}: is a folder; give a file name to write", file=path)
    if path.exists() and not overwrite:
        raise OutputExistsError(f"{path}: exists already; not overwritten (pass overwrite=True)")
    parent = path.parent
    if not parent.is_dir():
        what = "is a file, not a folder" if parent.exists() else "does not exist"
        raise OutputFolderError(
            f"{path}: cannot write: the folder {parent} {what}; create the folder first",
            file=path,
        )


class OutputIsFolderError(FlexarmError, IsADirectoryError):
    """An output file path that is a folder (a project error: one line, exit 2)."""


class OutputFolderError(FlexarmError, FileNotFoundError):
    """An output file whose folder does not exist or is a file (a project error: one
    line, exit 2; issue #45: ``excite`` into a missing folder was an internal error)."""


def _commit(tmp: Path, path: Path, overwrite: bool) -> None:
    """Move the finished temporary file onto ``path`` in one step."""
    if overwrite:
        os.replace(tmp, path)
    else:
        try:
            os.link(tmp, path)  # fails if path exists: no race with another writer
        except FileExistsError:
            raise OutputExistsError(
                f"{path}: exists already; not overwritten (pass overwrite=True)"
            ) from None
        except OSError:  # a file system without hard links
            if path.exists():
                raise OutputExistsError(
                    f"{path}: exists already; not overwritten (pass overwrite=True)"
                ) from None
            os.replace(tmp, path)
        else:
            os.unlink(tmp)
    with contextlib.suppress(OSError):  # make the rename itself durable (POSIX)
        fd = os.open(path.parent, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


@contextlib.contextmanager
def atomic_path(path: str | Path, *, overwrite: bool = False) -> Iterator[Path]:
    """A temporary path beside ``path`` (same extension) for a writer that takes a path;
    moved onto ``path`` when the block ends without an exception, removed otherwise."""
    path = Path(path)
    _check_target(path, overwrite)
    fd, name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=path.suffix)
    os.close(fd)
    tmp = Path(name)
    try:
        yield tmp
        with open(tmp, "rb+") as f:
            os.fsync(f.fileno())
        os.chmod(tmp, _file_mode())
        _commit(tmp, path, overwrite)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


@contextlib.contextmanager
def atomic_open(
    path: str | Path,
    mode: str = "w",
    *,
    overwrite: bool = False,
    encoding: str | None = None,
    newline: str | None = None,
) -> Iterator[IO]:
    """``open(path, mode)`` for writing (``"w"`` or ``"wb"``), atomically: the file
    appears complete when the block ends, or not at all.  The target is checked when the
    block begins (the output policy); what the block writes is kept in memory and
    written when it ends, through the one writer (:func:`write_text`, :func:`write_bytes`),
    so a write that fails then (a full disk) keeps it (:class:`WriteFailedError`)."""
    import io

    if mode not in ("w", "wb"):
        raise ValueError(f"atomic_open: mode {mode!r}; use 'w' or 'wb'")
    path = Path(path)
    _check_target(path, overwrite)
    if mode == "w":
        text = io.StringIO()
        yield text
        write_text(
            path,
            text.getvalue(),
            overwrite=overwrite,
            encoding=encoding or "utf-8",
            newline=newline,
        )
    else:
        data = io.BytesIO()
        yield data
        write_bytes(path, data.getvalue(), overwrite=overwrite)


class WriteFailedError(FlexarmError, OSError):
    """A write that failed after the output policy's checks passed: a full disk (ENOSPC), a
    quota, an I/O error, a folder that vanished.  The content is not lost: it was written
    to :attr:`rescued` (beside the target, else in the current folder, else in the
    system's temporary folder; :func:`rescue_path`), or, when every one of those failed
    too, :attr:`rescued` is None and :attr:`content` holds it (text: the command line
    prints it on stdout).  :attr:`reason`: the failed write's own line; :attr:`path`: the
    target."""

    def __init__(
        self,
        message: str,
        *,
        path: Path,
        reason: str,
        rescued: Path | None,
        content: str | bytes | None = None,
        errno_: int | None = None,
    ):
        super().__init__(message, file=path)
        self.path = path
        self.reason = reason
        self.rescued = rescued
        self.content = content
        self.errno = errno_


def write_each(*writes):
    """Run every one of a job's final writes (callables) even where one before it failed on
    a full disk: each :class:`WriteFailedError` keeps its own content (rescued beside its
    target); the first is raised once all have run. Returns the writes' results. So a
    fit's ``--scenario-out`` is written where its ``--json`` met a full disk, and a
    design's ``design.json`` where its ``design.toml`` did."""
    failed: list[WriteFailedError] = []
    out = []
    for w in writes:
        try:
            out.append(w())
        except WriteFailedError as exc:
            failed.append(exc)
    if failed:
        raise failed[0]
    return out


def rescue_path(path: Path, folder: Path, stamp: str) -> Path:
    """``<stem>.rescued-<UTC stamp>[-k]<suffix>`` in ``folder``: a name no file has yet."""
    cand = folder / f"{path.stem}.rescued-{stamp}{path.suffix}"
    k = 1
    while cand.exists() or cand.is_symlink():
        k += 1
        cand = folder / f"{path.stem}.rescued-{stamp}-{k}{path.suffix}"
    return cand


def _produce(path: Path, overwrite: bool, produce: Callable[[Path], Any]) -> None:
    with atomic_path(path, overwrite=overwrite) as tmp:
        produce(tmp)


def _write_kept(
    path: str | Path,
    overwrite: bool,
    produce: Callable[[Path], Any],
    content: str | bytes | None,
) -> Path:
    """The one writer under every other (issue #45): the output policy's checks
    (:func:`_check_target`: their errors are raised as they are), then ``produce(tmp)``
    atomically onto ``path``.  When that fails with an ``OSError`` (a full disk at the
    final write), the content is produced again under a fresh name beside ``path``, else
    in the current folder, else in the system's temporary folder, and
    :class:`WriteFailedError` says where (it is a :class:`flexarm.errors.FlexarmError`:
    the command line ends with one ``error:`` line naming the saved copy, exit 2)."""
    path = Path(path)
    _check_target(path, overwrite)
    try:
        _produce(path, overwrite, produce)
        return path
    except FlexarmError:
        raise  # the policy (a file that appeared meanwhile), not the disk
    except OSError as exc:
        first = exc
    reason = " ".join(str(first).split()) or type(first).__name__
    stamp = _dt.datetime.now(_dt.UTC).strftime("%Y%m%dT%H%M%SZ")
    tried = []
    for folder in dict.fromkeys((path.parent, Path.cwd(), Path(tempfile.gettempdir()))):
        try:
            cand = rescue_path(path, folder, stamp)
            _produce(cand, False, produce)
        except OSError as exc2:
            tried.append(f"{folder}: {' '.join(str(exc2).split())}")
            continue
        raise WriteFailedError(
            f"{path}: could not write it ({reason}); what it holds is saved to {cand}: "
            "free space or choose another folder, then move it there",
            path=path,
            reason=reason,
            rescued=cand,
            errno_=first.errno,
        ) from None
    shown = "; it follows on stdout" if isinstance(content, str) else ""
    raise WriteFailedError(
        f"{path}: could not write it ({reason}), nor a copy anywhere else ("
        + "; ".join(tried)
        + f"){shown}; free space and run again",
        path=path,
        reason=reason,
        rescued=None,
        content=content,
        errno_=first.errno,
    ) from None


def write_text(
    path: str | Path,
    text: str,
    *,
    overwrite: bool = False,
    encoding: str = "utf-8",
    newline: str | None = None,
) -> Path:
    """Write ``text`` to ``path`` atomically; a write that fails keeps it
    (:class:`WriteFailedError` names the copy)."""

    def produce(tmp: Path) -> None:
        with open(tmp, "w", encoding=encoding, newline=newline) as f:
            f.write(text)
            f.flush()

    return _write_kept(path, overwrite, produce, text)


def write_bytes(path: str | Path, data: bytes, *, overwrite: bool = False) -> Path:
    """Write ``data`` to ``path`` atomically; a write that fails keeps it
    (:class:`WriteFailedError` names the copy)."""

    def produce(tmp: Path) -> None:
        with open(tmp, "wb") as f:
            f.write(data)
            f.flush()

    return _write_kept(path, overwrite, produce, data)


def write_json(
    path: str | Path,
    data: Any,
    *,
    overwrite: bool = False,
    indent: int = 2,
    default: Callable[[Any], Any] | None = None,
) -> Path:
    """``json.dumps(data, indent=indent, default=default)`` plus a newline, atomically.
    Non-finite floats are written as ``json`` does (``NaN``, ``Infinity``); callers that
    want ``null`` convert them first (as :mod:`flexarm.identification.time_domain.report` does).
    The text is
    built before the file is opened, so a value that cannot be serialised leaves no file."""
    return write_text(
        path, json.dumps(data, indent=indent, default=default) + "\n", overwrite=overwrite
    )


def write_toml(path: str | Path, data: dict, *, overwrite: bool = False) -> Path:
    """``tomli_w.dumps(data)`` to ``path`` atomically (no ``None`` values: TOML has none)."""
    import tomli_w

    return write_text(path, tomli_w.dumps(data), overwrite=overwrite)


def save_figure(fig, path: str | Path, *, overwrite: bool = False, **savefig_kw) -> Path:
    """``fig.savefig`` (matplotlib) to ``path`` atomically; the format follows the
    extension of ``path`` (``.png``, ``.pdf``, ``.svg``, ...) unless ``format=`` is given."""
    path = Path(path)
    if "format" not in savefig_kw and path.suffix:
        savefig_kw["format"] = path.suffix[1:].lower()
    return _write_kept(path, overwrite, lambda tmp: fig.savefig(tmp, **savefig_kw), None)


def output_folder(path: str | os.PathLike, *, overwrite: bool = False) -> Path:
    """The output folder ``path`` (figures, a design), created with its parents.  A folder
    that already holds files is used only with ``overwrite=True`` (then files of the same
    names are replaced; others stay); a file where the folder should be, or a folder inside
    a declared input folder, is refused.  Inside a command's :func:`run_scope` the folder is
    locked (:func:`lock_folder`): a second run writing there at the same time is refused."""
    d = Path(path)
    src = is_input(d)
    if src is not None:
        raise InputOverwriteError(
            f"{d}: is (inside) an input of this run ({src}); give another output folder", file=d
        )
    if d.exists() and not d.is_dir():
        raise OutputExistsError(
            f"{d}: is a file, not a folder; give a folder name", file=d, fix="give a folder name"
        )
    if d.is_dir():
        mine = lock_folder(d)  # another run's lock: refused here, by name
        if not overwrite and any(p.name != LOCK_NAME or mine is None for p in d.iterdir()):
            raise OutputExistsError(
                f"{d}: the folder holds files already; not written into "
                "(pass overwrite=True, on the command line --overwrite)",
                file=d,
            )
        return d
    d.mkdir(parents=True, exist_ok=True)
    lock_folder(d)
    return d


# ------------------------------------------------------------------ names are data
#: the longest file name stem :func:`safe_name` makes (the file systems' limit is 255 bytes,
#: with room for the extensions flexarm adds)
NAME_MAX = 100


def safe_name(name: Any, *, what: str = "name") -> str:
    """``name`` as a file name stem that cannot leave its folder: every character but
    letters, digits and ``._-`` becomes ``_`` (``/``, ``\\``, NUL, spaces, newlines,
    non-ASCII), and a leading ``.`` or ``-`` becomes ``_`` (no hidden file, no option look-alike;
    ``..`` and ``.`` cannot survive). Refused (:class:`flexarm.errors.FlexarmError`, one line naming
    ``what``) when nothing is left that is a letter or digit, or the name is longer than
    :data:`NAME_MAX` characters. The one sanitiser of every name that becomes a file."""
    from flexarm.errors import FlexarmError

    text = "" if name is None else str(name)
    shown = text if len(text) <= 40 else text[:40] + "..."
    if len(text) > NAME_MAX:
        raise FlexarmError(
            f"{what} is {len(text)} characters long; at most {NAME_MAX} become a file name",
            value=shown,
            fix=f"give a shorter {what}",
        )
    out = "".join(ch if (ch.isascii() and (ch.isalnum() or ch in "._-")) else "_" for ch in text)
    k = 0
    while k < len(out) and out[k] in ".-":
        k += 1
    out = "_" * k + out[k:]
    if not any(ch.isalnum() for ch in out):
        raise FlexarmError(
            f"{what} cannot be made a safe file name (it needs a letter or digit)",
            value=shown,
            fix=f"give a {what} of letters, digits and ._-",
        )
    return out


def distinct_names(names: Sequence[Any], *, what: str = "name") -> list[str]:
    """:func:`safe_name` of each of ``names``, made distinct: a repeated one (the same
    name, or names that sanitise alike, compared without case: ``Rig`` and ``rig`` share
    a file on some file systems) gets ``-2``, ``-3``, ... (the caller states the names it
    used)."""
    out: list[str] = []
    seen: set[str] = set()
    for n in names:
        base = safe_name(n, what=what)
        cand, k = base, 1
        while cand.lower() in seen:
            k += 1
            cand = f"{base}-{k}"
        seen.add(cand.lower())
        out.append(cand)
    return out


def check_outputs(
    outputs: Iterable[tuple[str, str | os.PathLike | None]], *, overwrite: bool = False
) -> None:
    """Check all of a command's output files before any work: ``outputs`` pairs
    (option or label, path; ``None`` skipped). Refused (:class:`flexarm.errors.FlexarmError`
    subclasses, one line naming the option): two outputs on one path, an output that is an
    input of the run (:func:`inputs`; never, even with ``overwrite``), an output that
    exists (unless ``overwrite``), an output that is a folder."""
    seen: dict[Path, str] = {}
    for opt, p in outputs:
        if p is None:
            continue
        q = Path(p).expanduser()
        r = q.resolve()
        if r in seen:
            raise OutputExistsError(
                f"{opt} {q}: the same path as {seen[r]}; two outputs of one run cannot "
                "share a file",
                file=q,
                fix="give each output its own path",
            )
        seen[r] = f"{opt} {q}"
        src = is_input(q)
        if src is not None:
            raise InputOverwriteError(
                f"{opt} {q}: is an input of this run ({src}); flexarm never writes over an "
                "input, even with --overwrite",
                file=q,
                fix="give another output path",
            )
        if q.is_dir():
            raise OutputExistsError(f"{opt} {q}: is a folder; give a file name", file=q)
        if q.exists() and not overwrite:
            raise OutputExistsError(
                f"{opt} {q}: exists already; not overwritten (pass --overwrite)", file=q
            )


# ------------------------------------------------------------------ one writer per folder
#: the lock file a command keeps in each output folder while it writes there
LOCK_NAME = ".flexarm.lock"

_LOCKS: contextvars.ContextVar[list[Path] | None] = contextvars.ContextVar(
    "flexarm_locks", default=None
)


@contextlib.contextmanager
def run_scope() -> Iterator[None]:
    """The lifetime of a command's folder locks (:func:`lock_folder`): released (the lock
    files removed) when the block ends, however it ends."""
    held: list[Path] = []
    token = _LOCKS.set(held)
    try:
        yield
    finally:
        _LOCKS.reset(token)
        for p in reversed(held):
            with contextlib.suppress(OSError):
                p.unlink()


def lock_folder(folder: str | os.PathLike) -> Path | None:
    """Take the output folder ``folder`` for this command: create ``folder/.flexarm.lock``
    exclusively (``O_CREAT | O_EXCL``: of two runs, exactly one gets it). Another run's
    lock there is refused (:class:`flexarm.errors.OutputExistsError`). The lock lasts until
    the enclosing :func:`run_scope` ends; outside one, nothing is locked (None)."""
    held = _LOCKS.get()
    if held is None:
        return None
    lock = Path(folder) / LOCK_NAME
    if lock in held:
        return lock
    try:
        fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
    except FileExistsError:
        try:
            who = lock.read_text(encoding="utf-8", errors="replace").strip()[:80]
        except OSError:
            who = "?"
        raise OutputExistsError(
            f"{folder}: another flexarm run is writing into this folder (lock file {lock}: "
            f"{who}); not written into",
            file=folder,
            fix="wait for that run, give another folder, or delete the lock file if no "
            "run is going",
        ) from None
    with os.fdopen(fd, "w", encoding="utf-8") as f:
        f.write(f"pid {os.getpid()}\n")
    held.append(lock)
    return lock


# ------------------------------------------------------------------ bounded reading
#: the largest text input (log, log format, manifest, JSON document) read, bytes
MAX_TEXT_INPUT = 1 << 30


def read_input(
    path: str | os.PathLike, *, limit: int = MAX_TEXT_INPUT, what: str = "file"
) -> bytes:
    """The bytes of the input file ``path``, read only when it is a regular file (not
    ``/dev/zero``, a pipe or a device, which could be read until memory runs out) of at
    most ``limit`` bytes; otherwise :class:`flexarm.errors.FlexarmError` (a ``ValueError``)
    naming the file. A missing file raises ``FileNotFoundError``."""
    import stat

    p = Path(path)
    st = p.stat()  # FileNotFoundError for a missing file
    if not stat.S_ISREG(st.st_mode):
        raise InputFileError(
            f"{p}: not a regular file (a device, pipe or folder); give the {what} itself",
            file=p,
        )
    if st.st_size > limit:
        raise InputFileError(
            f"{p}: {st.st_size} bytes, more than the {limit} bytes a {what} may have",
            file=p,
            fix="split it, or check that it is the right file",
        )
    with open(p, "rb") as f:
        data = f.read(limit + 1)
    if len(data) > limit:  # grew while read
        raise InputFileError(f"{p}: more than {limit} bytes; not read", file=p)
    return data


class InputFileError(FlexarmError, ValueError):
    """An input file that is not read (:func:`read_input`): not a regular file, or too large."""


# ------------------------------------------------------------------ unique result keys
def unique_keys(paths: Sequence[str | os.PathLike]) -> list[str]:
    """One key per input, in order, never two alike (result entries, figure names): the one
    rule every result keyed by input uses (:func:`flexarm.io.logs.log_keys` applies it to
    logs).

    Rule: the file names (``Path.name``, extension kept) when they are all different;
    otherwise each input's path relative to the inputs' common folder, ``/``-separated
    (``a/trial1.csv``, ``b/trial1.csv``); the same file given more than once gets ``#2``,
    ``#3``, ... after its key.  Strings that are not files (scenario names) follow the
    same rule."""
    ps = [Path(p) for p in paths]
    keys = [p.name or str(p) for p in ps]
    if len(set(keys)) < len(keys):
        res = [p.expanduser().resolve() for p in ps]
        try:
            common = Path(os.path.commonpath([str(r.parent) for r in res]))
        except ValueError:  # different drives
            common = None
        keys = []
        for r in res:
            if common is not None and r != common and r.is_relative_to(common):
                keys.append(r.relative_to(common).as_posix())
            else:
                keys.append(r.name)
    out, seen = [], {}
    for k in keys:
        seen[k] = seen.get(k, 0) + 1
        out.append(k if seen[k] == 1 else f"{k}#{seen[k]}")
    return out


# ------------------------------------------------------------------ rescue a final write
@dataclass(frozen=True)
class Saved:
    """Where :func:`save_or_rescue` wrote: ``path``; ``rescued`` True when that is not the
    requested path, ``reason`` then says why (the one line of the failed write)."""

    path: Path
    rescued: bool = False
    reason: str = ""

    def message(self, what: str = "result") -> str:
        """One line for the user."""
        if not self.rescued:
            return f"wrote {self.path}"
        return f"could not write the {what} where asked ({self.reason}); saved it to {self.path}"


def _write_any(path: Path, data: Any, overwrite: bool) -> Path:
    if isinstance(data, (bytes, bytearray)):
        return write_bytes(path, bytes(data), overwrite=overwrite)
    if isinstance(data, str):
        return write_text(path, data, overwrite=overwrite)
    if path.suffix.lower() == ".toml":
        return write_toml(path, data, overwrite=overwrite)
    return write_json(path, data, overwrite=overwrite)


def save_or_rescue(
    path: str | os.PathLike,
    data: Any,
    *,
    overwrite: bool = False,
    writer: Callable[[Path, bool], Any] | None = None,
) -> Saved:
    """Write ``data`` (text, bytes, or a dict: JSON, or TOML for a ``.toml`` path) to
    ``path``, or with ``writer(path, overwrite)``; when that fails (any ``OSError``: a full
    disk, a missing or read-only folder, a file that appeared meanwhile, an input of the
    run), write it to ``<stem>.rescued-<UTC time><suffix>`` next to ``path``, else in the
    current folder, else in the system's temporary folder, and say where.  Errors in the
    data itself (``TypeError``, ``ValueError`` of the serialiser) are raised: there is
    nothing to rescue."""
    path = Path(path)
    write = writer or (lambda p, ow: _write_any(p, data, ow))
    try:
        write(path, overwrite)
        return Saved(path)
    except WriteFailedError as exc:  # the one writer kept it already (a full disk)
        if exc.rescued is None:
            raise
        return Saved(exc.rescued, True, exc.reason)
    except OSError as exc:  # the policy refused the path: exists, no folder, an input
        reason = " ".join(str(exc).split()) or type(exc).__name__
        first = exc
    stamp = _dt.datetime.now(_dt.UTC).strftime("%Y%m%dT%H%M%SZ")
    tried = []
    for folder in (path.parent, Path.cwd(), Path(tempfile.gettempdir())):
        cand = rescue_path(path, folder, stamp)
        try:
            write(cand, False)
            return Saved(cand, True, reason)
        except WriteFailedError as exc:
            if exc.rescued is not None:
                return Saved(exc.rescued, True, reason)
            tried.append(f"{cand}: {exc.reason}")
        except OSError as exc:
            tried.append(f"{cand}: {exc}")
    content = data if isinstance(data, str) else None
    if content is None and writer is None and not isinstance(data, (bytes, bytearray)):
        with contextlib.suppress(Exception):
            content = json.dumps(data, indent=2) + "\n"
    raise WriteFailedError(
        f"{path}: {reason}; the rescue copies failed too: "
        + "; ".join(tried)
        + ("; it follows on stdout" if content is not None else ""),
        path=path,
        reason=reason,
        rescued=None,
        content=content,
        errno_=getattr(first, "errno", None),
    )


# ------------------------------------------------------------------ signals
class Interruptible:
    """The state of :func:`interruptible`: ``signal`` (the first signal's name, or None),
    ``count`` (signals received), ``deferred`` (a first signal delivered again, module
    doc), ``active`` (the block still runs)."""

    def __init__(self):
        self.signal: str | None = None
        self.count = 0
        #: a first signal that arrived where it could not be raised (module doc), and
        #: whether the block still runs (a deferred signal is delivered again only then)
        self.deferred: str | None = None
        self.active = True

    @property
    def interrupted(self) -> bool:
        return self.count > 0


_GC_DEPTH = [0]


def _gc_phase(phase: str, info: dict) -> None:
    _GC_DEPTH[0] += 1 if phase == "start" else -1 if _GC_DEPTH[0] > 0 else 0


def _unraisable_here(frame) -> bool:
    """Whether an exception raised at ``frame`` would be dropped by Python (printed as
    "Exception ignored in ...", never propagated): inside a ``__del__``, a weakref or
    ``weakref.finalize`` callback, or while the garbage collector runs."""
    if _GC_DEPTH[0] > 0:
        return True
    f, k = frame, 0
    while f is not None and k < 64:
        if f.f_code.co_name in ("__del__", "_remove_dead_weakref") or (
            f.f_code.co_name == "__call__" and "weakref" in f.f_code.co_filename
        ):
            return True
        f, k = f.f_back, k + 1
    return False


@contextlib.contextmanager
def interruptible(*, on_repeat: Callable[[str], None] | None = None) -> Iterator[Interruptible]:
    """The one place where flexarm handles SIGINT and SIGTERM (the CLI and the fit use it).

    Inside the block the first SIGINT (Ctrl-C) raises ``KeyboardInterrupt`` and the first
    SIGTERM raises :class:`flexarm.errors.Interrupted` (a ``KeyboardInterrupt``), so a run
    that keeps its best result on Ctrl-C (the fit: :class:`flexarm.errors.FitInterrupted`)
    keeps it on SIGTERM too.  Every later SIGINT or SIGTERM is not raised again: it only
    calls ``on_repeat(name)`` (e.g. to print "saving the best result first"), so a second
    Ctrl-C cannot break the writing of the best result.  SIGKILL still ends the process.
    A SIGINT that was ignored when the block began (a job started with ``nohup ... &``)
    stays ignored.  A first signal that arrives where Python would drop the exception (in a
    ``__del__``, a weakref callback, a garbage collection: JAX frees its buffers there) is
    delivered again 50 ms later (once; it then raises wherever it lands), so it is never
    swallowed.  Outside the main thread
    nothing is installed.  The previous handlers are restored when the block ends."""
    state = Interruptible()
    if threading.current_thread() is not threading.main_thread():
        yield state
        return

    def handler(signum, frame):
        name = signal.Signals(signum).name
        if state.count == 0 and state.deferred is None and _unraisable_here(frame):
            # a signal that arrives in a __del__ or a garbage-collector callback (JAX frees
            # buffers there) would be raised where Python prints and drops the exception:
            # delivered again a moment later, in the code that runs on (issue #45)
            state.deferred = name

            def again():
                if state.active and state.count == 0:
                    os.kill(os.getpid(), signum)

            threading.Timer(0.05, again).start()
            return
        state.count += 1
        if state.count > 1:
            if on_repeat is not None:
                on_repeat(name)
            return
        state.signal = name
        if signum == signal.SIGINT:
            raise KeyboardInterrupt
        raise Interrupted(f"stopped by {name}", signal=name, number=int(signum))

    import gc

    gc.callbacks.append(_gc_phase)
    old = {}
    for sig in (signal.SIGINT, signal.SIGTERM):
        prev = signal.getsignal(sig)
        if sig == signal.SIGINT and prev == signal.SIG_IGN:
            continue
        old[sig] = prev
        signal.signal(sig, handler)
    try:
        yield state
    finally:
        state.active = False
        with contextlib.suppress(ValueError):
            gc.callbacks.remove(_gc_phase)
        if _gc_phase not in gc.callbacks:  # no block left: no stale collection count
            _GC_DEPTH[0] = 0
        for sig, prev in old.items():
            signal.signal(sig, prev if prev is not None else signal.SIG_DFL)
