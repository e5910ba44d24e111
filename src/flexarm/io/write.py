"""The one file writer: every file flexarm writes goes through here, atomically.

Method: the content is written to a temporary file in the target's own folder (so the
rename cannot cross file systems), flushed and ``fsync``-ed, then moved onto the target in
one step (``os.replace``; ``os.link`` when the target must not exist, which fails instead
of replacing a file that appeared meanwhile).  A reader therefore sees the old file or the
complete new one, never a half-written one, and on any exception, ``KeyboardInterrupt``
included, the temporary file is removed and the target is left as it was.

An existing target is replaced only with ``overwrite=True``; otherwise
:class:`flexarm.errors.OutputExistsError` (a ``FileExistsError``) names it.

Functions: :func:`atomic_open` (a file object), :func:`atomic_path` (a temporary path for
writers that take a path), :func:`write_text`, :func:`write_bytes`, :func:`write_json`,
:func:`write_toml`, :func:`save_figure`.  CSV logs are written by
:func:`flexarm.io.logs.write_log` through :func:`atomic_open`.
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from pathlib import Path
from typing import IO, Any, Callable, Iterator

from flexarm.errors import OutputExistsError

__all__ = ["atomic_open", "atomic_path", "write_text", "write_bytes", "write_json",
           "write_toml", "save_figure", "OutputExistsError"]


def _file_mode() -> int:
    """rw for whom the umask allows (what ``open(path, "w")`` would give; mkstemp gives 0600)."""
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


def _check_target(path: Path, overwrite: bool) -> None:
    if path.is_dir():
        raise IsADirectoryError(f"{path}: is a folder; give a file name to write")
    if path.exists() and not overwrite:
        raise OutputExistsError(f"{path}: exists already; not overwritten (pass overwrite=True)")
    parent = path.parent
    if not parent.is_dir():
        what = "is a file, not a folder" if parent.exists() else "does not exist"
        raise FileNotFoundError(f"{path}: cannot write: the folder {parent} {what}; "
                                "create the folder first")


def _commit(tmp: Path, path: Path, overwrite: bool) -> None:
    """Move the finished temporary file onto ``path`` in one step."""
    if overwrite:
        os.replace(tmp, path)
    else:
        try:
            os.link(tmp, path)  # fails if path exists: no race with another writer
        except FileExistsError:
            raise OutputExistsError(f"{path}: exists already; not overwritten "
                                    "(pass overwrite=True)") from None
        except OSError:  # a file system without hard links
            if path.exists():
                raise OutputExistsError(f"{path}: exists already; not overwritten "
                                        "(pass overwrite=True)") from None
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
def atomic_open(path: str | Path, mode: str = "w", *, overwrite: bool = False,
                encoding: str | None = None, newline: str | None = None) -> Iterator[IO]:
    """``open(path, mode)`` for writing (``"w"`` or ``"wb"``), atomically: the file
    appears complete when the block ends, or not at all."""
    if mode not in ("w", "wb"):
        raise ValueError(f"atomic_open: mode {mode!r}; use 'w' or 'wb'")
    if mode == "w" and encoding is None:
        encoding = "utf-8"
    with atomic_path(path, overwrite=overwrite) as tmp:
        with open(tmp, mode, encoding=encoding, newline=newline) as f:
            yield f
            f.flush()


def write_text(path: str | Path, text: str, *, overwrite: bool = False,
               encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``path`` atomically."""
    with atomic_open(path, "w", overwrite=overwrite, encoding=encoding) as f:
        f.write(text)
    return Path(path)


def write_bytes(path: str | Path, data: bytes, *, overwrite: bool = False) -> Path:
    """Write ``data`` to ``path`` atomically."""
    with atomic_open(path, "wb", overwrite=overwrite) as f:
        f.write(data)
    return Path(path)


def write_json(path: str | Path, data: Any, *, overwrite: bool = False, indent: int = 2,
               default: Callable[[Any], Any] | None = None) -> Path:
    """``json.dumps(data, indent=indent, default=default)`` plus a newline, atomically.
    Non-finite floats are written as ``json`` does (``NaN``, ``Infinity``); callers that
    want ``null`` convert them first (as :mod:`flexarm.identification.time_domain.report` does).  The text is
    built before the file is opened, so a value that cannot be serialised leaves no file."""
    return write_text(path, json.dumps(data, indent=indent, default=default) + "\n",
                      overwrite=overwrite)


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
    with atomic_path(path, overwrite=overwrite) as tmp:
        fig.savefig(tmp, **savefig_kw)
    return path
