"""Lab recordings in MATLAB ``.mat`` files → named 1-D signals in SI units.

A *variable spec* names where a signal lives in the file::

    "iq_adx"                  a variable (any shape with one non-singleton axis)
    "-theta_my"               the same, sign flipped (an encoder counting the other way)
    "logsout.speed"           a struct field path; a Simulink log struct (fields ``time`` and
                              ``signals.values``) at the end of the path gives its values
    "logsout.speed.time"      the struct's own time vector
    "meas[2]"                 column 2 (0-based) of a 2-D variable, rows = samples

Units (``{flexarm name: unit}``, pint text such as ``"us"``, ``"mA"``, ``"deg"``) convert to
SI through the project's one registry (``flexarm.units``): the factor of the known columns
comes from :mod:`flexarm.io.logs`; other names go to pint base units (rad, s, A, ...).

A logger's sample counter mapped as ``sample_counter`` drops irregular trailing rows (the
counter stops advancing; a warning names them); a jump anywhere else is an error.

Version 5 files are read by ``scipy.io.loadmat``; version 7.3 (HDF5) files by ``h5py``
(imported only then; HDF5 stores MATLAB arrays transposed, which is undone). Objects scipy
cannot decode (a ``tf`` object saved with the data, MATLAB's ``MatlabOpaque``) are skipped,
never fatal: they are only reported if a spec names them.

Errors (:class:`MatFileError`, a :class:`flexarm.io.logs.LogError`) name the file, the flexarm
name and the spec: a missing variable (with the list of what the file holds), a struct
without ``signals.values``, a column out of range, non-numeric data, NaN / infinite values
(with the first bad sample), channels of different lengths. The file is only read.
"""

from __future__ import annotations

import re
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import numpy as np

from flexarm.errors import MatFileError  # re-exported (flexarm.io.matfile.MatFileError)
from flexarm.io import checks as _checks  # the readers' checks (issue #25)
from flexarm.io.logs import Log, unit_factor
from flexarm.io.signals import known_names, signal_unit
from flexarm.units import ureg

_SPEC = re.compile(
    r"^\s*(?P<sign>[-+]?)\s*(?P<path>[A-Za-z_][\w.]*?)\s*(\[\s*(?P<col>\d+)\s*\])?\s*$"
)


#: The flexarm name of a logger's sample counter: used to drop irregular trailing rows, not
#: returned.
COUNTER = "sample_counter"


class MatFileWarning(UserWarning):
    """Something in a recording was dropped (e.g. an irregular last row)."""


@dataclass(frozen=True)
class VarSpec:
    """A parsed variable spec: struct path, optional column, sign (+1 / −1)."""

    path: tuple[str, ...]
    column: int | None
    sign: float
    text: str

    @classmethod
    def parse(cls, text: str, *, where: str = "") -> VarSpec:
        m = _SPEC.match(text) if isinstance(text, str) else None
        if m is None:
            raise MatFileError(
                f"{where}: cannot read the variable spec {text!r}; write "
                "'name', '-name', 'struct.field' or 'name[column]'"
            )
        return cls(
            tuple(m["path"].split(".")),
            None if m["col"] is None else int(m["col"]),
            -1.0 if m["sign"] == "-" else 1.0,
            text,
        )


#: Signals read from one ``.mat`` file are a :class:`flexarm.io.logs.Log` (one log type).
MatRecording = Log


# --- file access ----------------------------------------------------------------------


class _Opaque:
    """Stand-in for an object the reader cannot decode (kept only to be named)."""

    def __init__(self, kind: str):
        self.kind = kind


def _load_v5(path: Path) -> dict:
    import scipy.io as sio
    from scipy.io.matlab import MatlabOpaque

    raw = sio.loadmat(str(path), struct_as_record=False, squeeze_me=False)
    out = {}
    for k, v in raw.items():
        if isinstance(v, MatlabOpaque):  # e.g. a tf object; scipy may lose its name
            out[f"<opaque {k}>" if k in (None, "None") else k] = _Opaque("MatlabOpaque")
        elif k is not None and not k.startswith("__"):
            out[k] = v
    return out


def _load_v73(path: Path) -> dict:
    try:
        import h5py
    except ImportError:  # pragma: no cover - h5py is a dependency
        raise MatFileError(
            f"{path}: a MATLAB v7.3 (HDF5) file needs h5py; pip install h5py"
        ) from None

    def conv(node):
        if isinstance(node, h5py.Group):
            if "MATLAB_class" in node.attrs and not len(node.keys()):
                return _Opaque(str(node.attrs["MATLAB_class"]))
            return {k: conv(node[k]) for k in node.keys() if not k.startswith("#")}
        cls = node.attrs.get("MATLAB_class", b"double")
        cls = cls.decode() if isinstance(cls, bytes) else str(cls)
        if (
            "MATLAB_object_decode" in node.attrs
            or cls in ("cell", "function_handle")
            or node.dtype.kind not in "iufb"
        ):
            return _Opaque(cls)
        return np.asarray(node[()]).T  # HDF5 holds MATLAB arrays transposed

    with h5py.File(path, "r") as f:
        return {k: conv(f[k]) for k in f.keys() if not k.startswith("#")}


def load_mat(path: str | Path) -> dict:
    """All top-level variables of a v5 or v7.3 ``.mat`` file (opaque objects as stand-ins)."""
    path = Path(path)
    if not path.is_file():
        raise MatFileError(f"{path}: no such file")
    with open(path, "rb") as fh:
        head = fh.read(128)
    if head[:8] == b"\x89HDF\r\n\x1a\n" or b"MATLAB 7.3" in head[:116]:
        return _checks.readable(path, _load_v73)
    try:
        return _load_v5(path)
    except NotImplementedError:  # scipy's message for v7.3 without the HDF5 signature first
        return _checks.readable(path, _load_v73)
    except Exception as exc:
        raise MatFileError(f"{path}: not a readable MATLAB .mat file ({exc})") from None


def _fields(node) -> list[str]:
    if isinstance(node, dict):
        return list(node)
    if hasattr(node, "_fieldnames"):
        return list(node._fieldnames)
    return []


def _child(node, name: str):
    if isinstance(node, dict):
        return node.get(name)
    if isinstance(node, np.ndarray) and node.dtype == object and node.size == 1:
        node = node.flat[0]
    if hasattr(node, "_fieldnames") and name in cast(Any, node)._fieldnames:
        return getattr(node, name)
    return None


def _unwrap(node):
    while isinstance(node, np.ndarray) and node.dtype == object and node.size == 1:
        node = node.flat[0]
    return node


def _describe(variables: dict) -> str:
    parts = []
    for k, v in variables.items():
        if isinstance(v, _Opaque):
            parts.append(f"{k} (opaque {v.kind}, skipped)")
        elif isinstance(v, np.ndarray) and v.dtype != object:
            parts.append(f"{k} {'x'.join(map(str, v.shape))}")
        else:
            parts.append(f"{k} (struct: {', '.join(_fields(_unwrap(v)))})")
    return "; ".join(parts)


def resolve_variable(path: Path, variables: dict, name: str, spec: VarSpec) -> np.ndarray:
    where = (
        f"{path}: {name} = {spec.text!r}"
        if name.startswith("[")
        else f"{path}: [columns] {name} = {spec.text!r}"
    )
    node: object = variables
    for depth, part in enumerate(spec.path):
        nxt = _child(_unwrap(node) if depth else node, part)
        if nxt is None:
            if depth == 0:
                raise MatFileError(
                    f"{where}: the file has no variable {part!r}; it holds: {_describe(variables)}"
                )
            raise MatFileError(
                f"{where}: {'.'.join(spec.path[:depth])} has no field "
                f"{part!r}; fields: {', '.join(_fields(_unwrap(node))) or 'none'}"
            )
        node = nxt
    node = _unwrap(node)
    if isinstance(node, _Opaque):
        raise MatFileError(
            f"{where}: {'.'.join(spec.path)} is an opaque MATLAB object "
            f"({node.kind}) that cannot be read; name a numeric variable"
        )
    if _fields(node):  # a struct: a Simulink log gives its signals.values
        sig = _child(node, "signals")
        vals = _child(_unwrap(sig), "values") if sig is not None else None
        if vals is None:
            raise MatFileError(
                f"{where}: {'.'.join(spec.path)} is a struct without "
                f"signals.values (fields: {', '.join(_fields(node))}); name a "
                f"field, e.g. '{'.'.join(spec.path)}.{_fields(node)[0]}'"
            )
        node = _unwrap(vals)
    a = np.asarray(node)
    if a.dtype.kind not in "iufb":
        raise MatFileError(f"{where}: {'.'.join(spec.path)} holds {a.dtype} data, not numbers")
    a = np.asarray(a, dtype=float)
    if a.size == 0:
        raise MatFileError(
            f"{where}: {'.'.join(spec.path)} is empty ({' x '.join(map(str, a.shape)) or '0'}); "
            "name the variable that holds the recording"
        )
    if a.ndim <= 1:
        a2 = a.reshape(-1, 1)
    elif a.ndim == 2 and a.shape[0] == 1:  # a row vector
        a2 = a.T
    else:
        a2 = a.reshape(a.shape[0], -1)
    if spec.column is not None:
        if spec.column >= a2.shape[1]:
            raise MatFileError(
                f"{where}: column {spec.column} does not exist; "
                f"{'.'.join(spec.path)} has {a2.shape[1]} column(s) (0-based)"
            )
        x = a2[:, spec.column]
    elif a2.shape[1] != 1:
        raise MatFileError(
            f"{where}: {'.'.join(spec.path)} has {a2.shape[1]} columns; pick "
            f"one, e.g. '{spec.text}[0]'"
        )
    else:
        x = a2[:, 0]
    bad = ~np.isfinite(x)
    if bad.any():
        raise MatFileError(
            f"{where}: {int(bad.sum())} NaN/infinite value(s), first at sample "
            f"{int(np.argmax(bad))}; clean or trim the recording"
        )
    return spec.sign * x


def scalar(path: str | Path, variables: dict, text: str, where: str) -> float:
    """The number a variable spec names (a scalar variable such as a rig parameter ``KE_D2``);
    ``where`` says which field asked, for messages."""
    path = Path(path)
    spec = VarSpec.parse(text, where=f"{path}: {where}")
    x = resolve_variable(path, variables, where, spec)
    if x.size != 1:
        raise MatFileError(
            f"{path}: {where} = {text!r}: expected one number, {'.'.join(spec.path)} holds {x.size}"
        )
    return float(x[0])


def _factor(path: Path, name: str, unit: str) -> float:
    """Factor from the file's ``unit`` to the SI unit of ``name`` (its known unit, else pint's
    base units)."""
    si = signal_unit(name)
    if si is not None:
        return unit_factor(path, name, unit, {name: si})
    try:
        q = ureg.Quantity(1.0, unit)
        return float(q.to_base_units().magnitude)
    except Exception as exc:  # pint raises several exception types
        raise MatFileError(
            f"{path}: [units] {name} = {unit!r}: not a unit pint knows ({exc}); "
            f"signal names flexarm knows: {known_names()}"
        ) from None


def read_mat(
    path: str | Path,
    columns: Mapping[str, str],
    units: Mapping[str, str] | None = None,
    *,
    variables: dict | None = None,
    source: str = "",
) -> Log:
    """Read the signals ``columns`` (flexarm name → variable spec) from a ``.mat`` file.

    ``units`` (flexarm name → the file's unit) converts to SI; the name ``time`` becomes
    :attr:`Log.time` (``None`` when not mapped). All mapped channels must have the same
    length. ``variables``: the file's variables when already loaded (:func:`load_mat`);
    ``source``: the format file the mapping came from, for messages.
    """
    path = Path(path)
    units = dict(units or {})
    for name in units:
        if name not in columns:
            raise MatFileError(
                f"{path}: [units] names {name!r}, which [columns] does not "
                f"map; mapped: {', '.join(columns)}"
            )
    if variables is None:
        variables = load_mat(path)
    sig: dict[str, np.ndarray] = {}
    for name, text in columns.items():
        if not isinstance(text, str):
            raise MatFileError(
                f"{path}: {source + ': ' if source else ''}[columns] {name} = "
                f"{text!r}: a .mat file's signal is a variable spec (a string "
                "such as 'name', '-name', 'struct.field' or 'name[0]')"
            )
        spec = VarSpec.parse(text, where=f"{path}: [columns] {name}")
        x = resolve_variable(path, variables, name, spec)
        if name in units:
            x = x * _factor(path, name, units[name])
        sig[name] = x
    lengths = {k: len(v) for k, v in sig.items()}
    if len(set(lengths.values())) > 1:
        raise MatFileError(
            f"{path}: channels of different lengths: "
            + ", ".join(f"{k} {n}" for k, n in lengths.items())
            + "; map channels recorded together"
        )
    notes: list[str] = []
    if COUNTER in sig:
        sig[COUNTER] = _checks.unwrap_counter(
            sig[COUNTER]
        )  # a 16-bit counter's wrap is no lost sample
        _check_counter(path, sig, notes)
    _checks.check_signals(
        path,
        sig,
        columns=columns,
        max_jitter=_checks.MAT_MAX_JITTER,
        time_unit=units.get("time"),
    )
    t = sig.pop("time", None)
    skipped = [k for k, v in variables.items() if isinstance(v, _Opaque)]
    return Log(path, t, sig, skipped=skipped, notes=notes)


def _check_counter(path: Path, sig: dict[str, np.ndarray], notes: list[str]) -> None:
    """Drop trailing rows where the logger's sample counter stops advancing by one step
    (an irregular last row); an irregular row anywhere else is an error."""
    c = sig.pop(COUNTER)
    step = np.diff(c)
    good = np.median(step) if len(step) else 1.0
    bad = np.nonzero(step != good)[0]
    if not len(bad):
        return
    first = int(bad[0]) + 1  # first irregular row
    if np.all(step[first - 1 :] != good) or first >= len(c) - 1:
        n = len(c) - first
        msg = (
            f"{path}: the sample counter stops advancing at row {first} (of {len(c)}): "
            f"{n} irregular trailing row(s) dropped"
        )
        warnings.warn(msg, MatFileWarning, stacklevel=3)
        notes.append(msg)
        for k in sig:
            sig[k] = sig[k][:first]
        return
    raise MatFileError(
        f"{path}: [columns] {COUNTER}: the sample counter jumps at row {first} "
        f"(step {step[first - 1]:g}, expected {good:g}): samples were lost; "
        "cut the recording there"
    )
