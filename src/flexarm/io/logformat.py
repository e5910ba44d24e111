"""Log-format files: how one logger writes its logs, written once per logger (TOML).

A log-format file tells :func:`load_log` (the one loader: text through
:func:`flexarm.io.logs.read_log`, ``.mat`` through :func:`flexarm.io.matfile.read_mat`) which
column holds what, in which unit, and which control law produced the logged command (the
:class:`~flexarm.io.logs.Log` it returns carries that law: ``controller``, per-sample
``gains``, ``voltage_limit``, ``rate``)::

    delimiter = "auto"          # or "tab", "comma", "semicolon", "whitespace", or the character
    comment = ["#", "%"]        # characters that start a comment line
    skip_rows = 0               # lines skipped at the top before anything is read

    [columns]                   # flexarm's name = header text, or 1-based column number
    time = 1                    # a leading "-" (or a negative number) flips the sign:
    motor_angle = 2             #   tip_deflection = "-tip" or tip_deflection = -3
    reference = "Position Reference (rad)"

    [units]                     # the unit of the file's numbers (pint); SI when not given
    time = "ms"

    [controller]
    kind = "state_feedback"     # u = K1 (r − θ) − K2 d − K3 θ̇ − K4 ḋ ; or "pd" (KP, KD)
    gain_columns = {K1 = 8, K2 = 9, K3 = 10, K4 = 11}   # per-sample gains from the log
    # gains = {K1 = 8, K2 = -8.5, K3 = 1.5, K4 = 1.5}   # or fixed gains (SI or "8 V/rad")
    rate = "logged"             # the rates the law used: "logged" (the logger's own
                                #   derivative columns), "backward" difference, "filtered"
    tau = 0.01                  # s, time constant of the "filtered" rate
    limit = 5                   # V, the amplifier's saturation

The same file describes a MATLAB ``.mat`` recording (the file's suffix picks the reader):
``[columns]`` then maps each flexarm name to a *variable spec* (:mod:`flexarm.io.matfile`:
``"name"``, ``"-name"``, ``"struct.field"``, ``"name[0]"`` a 0-based column; a Simulink log
struct gives its ``signals.values``), and ``delimiter``, ``comment``, ``skip_rows`` do not
apply. Besides the single-link exchange names, a format may map per-joint signals of a
multi-link arm (``theta_1``, ``alpha_f_2``, ``current_1``, ...; :data:`flexarm.io.logs.PER_JOINT`
lists them with their SI units) and ``[units]`` converts any of them.

One run saved as several files (one scope capture per signal) is one log: a ``[columns]``
entry may name its own file, the column in the format's own syntax::

    [columns]
    time = { file = "{stem}_th11.mat", column = "data_th11[0]" }
    theta_1 = { file = "{stem}_th11.mat", column = "data_th11[2]" }
    alpha_f_1 = { file = "{stem}_th12.mat", column = "data_th12[2]", time = "data_th12[0]" }

``{stem}`` is the path given to :meth:`LogFormat.read` (the command line's log argument)
without its suffix: ``read("runs/run01")`` reads ``runs/run01_th11.mat`` and
``runs/run01_th12.mat``. ``time`` may come from any of the files; every file must have the
log's number of samples, and a file's own ``time`` (optional) must equal the log's: an
error names both files.

A logged disturbance (an input that enters the loop from the log, not from the
controller: a pulse added to the command after the saturation, a load force) is mapped by
the name the scenario's ``[[disturbances]]`` gives it, in the same syntax as ``[columns]``;
``[units]`` converts it to SI (the command's unit, or N / N·m for a force)::

    [disturbances]
    pulse = "Pulse (mV)"
    [units]
    pulse = "mV"

The log then names them (:attr:`flexarm.io.logs.Log.disturbances`);
:func:`flexarm.sim.build.disturbance_inputs` takes them off the log for a scenario and
refuses a log without a declared one, or with one the scenario does not declare.

``[checks]`` guards against a mapping that names the wrong variable::

    [checks]
    quantum = {theta_2 = "KE_D2"}   # an encoder reading lies on its grid k·q (q a number in
                                    # the channel's SI unit, or a .mat variable holding it)
    zero = ["theta_ref_2"]          # ... or a column that must be all zeros

A measured angle off its encoder grid is a setpoint or a computed signal mapped as a
measurement: reading stops with an error naming the channel, the variable, the worst sample
and how far off the grid it is.

Every gain of the law must be found: in ``gains`` (fixed) or ``gain_columns`` (a column
per gain: gains that change inside a log are used as logged, piecewise constant); a
``[controller]`` without either takes the log's ``# controller:`` line. Gains are in SI:
K1 V/rad, K2 V/m, K3 V·s/rad, K4 V·s/m (KP V/rad, KD V·s/rad).

Problems are :class:`LogFormatError` naming the format file, the field, the value and the
fix. ``examples/quanser-rotflex.toml`` is a documented example.
"""

# Field types built by calls (Q("rad", gt=0), Count(...), Coefficients(...)) are what
# pydantic reads at runtime; a static checker cannot take a call as a type, so pyright's
# invalid-type-form check is off for this module (flexarm.specs.quantity).
# pyright: reportInvalidTypeForm=false

from __future__ import annotations

import tomllib
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Literal, cast

import numpy as np
from pydantic import PrivateAttr, ValidationError, field_validator, model_validator

from flexarm.io import matfile
from flexarm.io.logs import (
    COMMENT_CHARS,
    LINEAR_SI,
    STATE_FEEDBACK_GAINS,
    Log,
    LogError,
    column_unit,
    known_names,
    read_log,
    signal_unit,
)
from flexarm.specs.controllers_bench import StateFeedbackController
from flexarm.specs.quantity import Count, Q, Spec
from flexarm.units import UnitError, to_si, ureg

#: The gains of each law and their SI units.
GAIN_UNITS: dict[str, dict[str, str]] = {
    "state_feedback": dict(STATE_FEEDBACK_GAINS),
    "pd": {"KP": "V/rad", "KD": "V*s/rad"},
}
#: Names the ``delimiter`` field accepts for characters.
DELIMITER_NAMES = {
    "auto": None,
    "tab": "\t",
    "comma": ",",
    "semicolon": ";",
    "whitespace": " ",
    "space": " ",
}


class LogFormatError(LogError):
    """A log-format file that cannot be used; the message names the file and the field."""


def _column_ref(k: str, v: object) -> int | str:
    if isinstance(v, bool) or not isinstance(v, (int, str)):
        raise ValueError(
            f"{k} = {v!r}: give the header text (a string) or the 1-based column "
            "number (an integer; negative flips the sign)"
        )
    if isinstance(v, int) and v == 0:
        raise ValueError(f"{k} = 0: column numbers start at 1 (a negative number flips the sign)")
    if isinstance(v, str) and not v.strip(" -"):
        raise ValueError(f"{k} = {v!r}: give the column's header text or its number")
    return v


class ColumnInFile(Spec):
    """A ``[columns]`` entry read from another file of the same run (one scope capture per
    signal): ``theta_1 = { file = "{stem}_th11.mat", column = "data_th11[2]" }``.
    ``column``: the column in the format's own syntax (a ``.mat`` variable spec, or a text
    file's header text / 1-based number); ``file``: the file, ``{stem}`` standing for the
    path given to :meth:`LogFormat.read` without its suffix (a relative path without
    ``{stem}`` is taken in that path's folder); ``time`` (optional): that file's own time
    column, checked against the log's time (the files of one log share one time base)."""

    file: str
    column: int | str
    time: int | str | None = None

    @field_validator("file")
    @classmethod
    def _file(cls, v: str) -> str:
        if not v.strip():
            raise ValueError("file = '': give the file, e.g. file = \"{stem}_th11.mat\"")
        return v

    @field_validator("column", "time")
    @classmethod
    def _ref(cls, v: object, info) -> object:
        return v if v is None else _column_ref(info.field_name, v)

    def path(self, stem: str, folder: Path) -> Path:
        """The file for the log read as ``stem`` (module docstring)."""
        if "{stem}" in self.file:
            return Path(self.file.replace("{stem}", stem))
        f = Path(self.file)
        return f if f.is_absolute() else folder / f


class ControllerFormat(Spec):
    """``[controller]``: the law that produced the logged command."""

    kind: Literal["state_feedback", "pd"]
    gains: dict[str, Any] = {}
    gain_columns: dict[str, int | str] = {}
    rate: Literal["logged", "backward", "filtered"] = "backward"
    tau: Q("s", ge=0, what="time constant of the filtered rate") = 0.0
    limit: Q("V", gt=0, what="the amplifier's saturation") | None = None

    @field_validator("gain_columns")
    @classmethod
    def _refs(cls, v: dict) -> dict:
        return {k: _column_ref(k, x) for k, x in v.items()}

    @model_validator(mode="after")
    def _complete(self) -> ControllerFormat:
        units = GAIN_UNITS[self.kind]
        for where in ("gains", "gain_columns"):
            bad = [k for k in getattr(self, where) if k not in units]
            if bad:
                raise ValueError(
                    f"{where}: {', '.join(map(repr, bad))} is not a gain of "
                    f"{self.kind!r}; its gains are {', '.join(units)}"
                )
        both = sorted(set(self.gains) & set(self.gain_columns))
        if both:
            raise ValueError(f"{', '.join(both)} given both in gains and in gain_columns; keep one")
        if self.gains or self.gain_columns:
            missing = [k for k in units if k not in self.gains and k not in self.gain_columns]
            if missing:
                raise ValueError(
                    f"gain(s) {', '.join(missing)} of {self.kind!r} not found in "
                    "gains or gain_columns; give each (e.g. "
                    f"{missing[0]} = 0 in gains if the law has no such term)"
                )
        for k, v in self.gains.items():
            try:
                to_si(v, units[k], field=f"gains.{k}")
            except UnitError as exc:
                raise ValueError(str(exc)) from None
        if self.rate == "filtered" and not self.tau > 0:
            raise ValueError("rate = 'filtered' needs tau > 0 s (e.g. tau = 0.01)")
        return self

    def fixed_gains(self) -> dict[str, float]:
        """The fixed gains in SI, named K1..K4 (a PD's KP, KD as K1, K3)."""
        units = GAIN_UNITS[self.kind]
        g = {k: to_si(v, units[k], field=f"gains.{k}") for k, v in self.gains.items()}
        return _as_state_feedback(g, self.kind)

    def columns(self) -> dict[str, int | str]:
        """The gain columns, named K1..K4."""
        return _as_state_feedback(self.gain_columns, self.kind)


def _as_state_feedback(d: dict, kind: str) -> dict:
    if kind == "pd":
        return {{"KP": "K1", "KD": "K3"}[k]: v for k, v in d.items()}
    return dict(d)


class Checks(Spec):
    """``[checks]``: properties of the mapped channels that reading verifies."""

    quantum: dict[str, float | str] = {}
    zero: list[str] = []

    @field_validator("quantum")
    @classmethod
    def _positive(cls, v: dict) -> dict:
        for k, q in v.items():
            if isinstance(q, (int, float)) and not q > 0:
                raise ValueError(
                    f"{k} = {q!r}: an encoder quantum is > 0 (in the channel's "
                    "SI unit), or the name of a .mat variable holding it"
                )
        return v


#: Largest distance (in quanta) of an encoder reading from its grid (the rig's angles are
#: k·q to 1e-12 relative; a value converted from degrees keeps that to ~1e-10 quanta).
GRID_TOLERANCE = 1e-6


class LogFormat(Spec):
    """One logger's log format (see the module docstring)."""

    description: str = ""
    delimiter: str = "auto"
    comment: list[str] = list(COMMENT_CHARS)
    skip_rows: Count(what="lines skipped at the top") = 0
    columns: dict[str, int | str | ColumnInFile] = {}
    disturbances: dict[str, int | str | ColumnInFile] = {}
    units: dict[str, str] = {}
    controller: ControllerFormat | None = None
    checks: Checks = Checks()
    _source: str = PrivateAttr("log format")

    @field_validator("delimiter")
    @classmethod
    def _delimiter(cls, v: str) -> str:
        if v.lower() in DELIMITER_NAMES or len(v) == 1 and v not in "\"'\n\r":
            return v
        raise ValueError(f"got {v!r}; give one character or one of {', '.join(DELIMITER_NAMES)}")

    @field_validator("comment", mode="before")
    @classmethod
    def _comment(cls, v: object) -> object:
        v = [v] if isinstance(v, str) else v
        if isinstance(v, list) and any(not isinstance(c, str) or len(c) != 1 for c in v):
            raise ValueError(f"got {v!r}; give single characters, e.g. ['#', '%']")
        return v

    @field_validator("columns")
    @classmethod
    def _columns(cls, v: dict) -> dict:
        bad = [k for k in v if signal_unit(k) is None]
        if bad:
            raise ValueError(
                f"{', '.join(map(repr, bad))} is not one of flexarm's column "
                f"names; known: {known_names()} (gain columns go in "
                "[controller] gain_columns, a logged disturbance in [disturbances])"
            )
        return {k: x if isinstance(x, ColumnInFile) else _column_ref(k, x) for k, x in v.items()}

    @field_validator("disturbances")
    @classmethod
    def _disturbances(cls, v: dict, info) -> dict:
        for k in v:
            if signal_unit(k) is not None or not k.isidentifier():
                why = "map that signal in [columns]" if signal_unit(k) else "letters, digits, _"
                raise ValueError(
                    f"{k!r}: a disturbance's name is the scenario's [[disturbances]] name, "
                    "a plain name that is not one of flexarm's signal names "
                    f"({why})"
                )
            if k in (info.data.get("columns") or {}):
                raise ValueError(f"{k!r} is mapped in [columns] too; keep one")
        return {k: x if isinstance(x, ColumnInFile) else _column_ref(k, x) for k, x in v.items()}

    @field_validator("units")
    @classmethod
    def _units(cls, v: dict, info) -> dict:
        for k, u in v.items():
            if k in (info.data.get("disturbances") or {}):
                if disturbance_unit(u) is None:
                    raise ValueError(
                        f"{k} = {u!r} is not a unit (a disturbance's unit: the command's, "
                        'e.g. "mV", "mA", or a force\'s, "N", "N*m")'
                    )
                continue
            si = column_unit(k, u)
            if si is None:
                raise ValueError(
                    f"{k!r} is not one of flexarm's column names; known: {known_names()}"
                )
            try:
                ureg.parse_expression(u).to(si)
            except Exception as exc:  # pint raises several exception types
                raise ValueError(
                    f"{k} = {u!r} does not convert to {si} ({exc}); give a unit "
                    f"of the same kind as {si}, e.g. {k} = "
                    f'"{ {"s": "ms", "rad": "deg", "m": "mm", "V": "mV"}.get(si, si) }"'
                    + (f" (or, on a linear axis, {LINEAR_SI[si]})" if si in LINEAR_SI else "")
                ) from None
        return v

    @model_validator(mode="after")
    def _checked_are_mapped(self) -> LogFormat:
        for k in [*self.checks.quantum, *self.checks.zero]:
            if k not in self.columns:
                raise ValueError(
                    f"[checks] names {k!r}, which [columns] does not map; "
                    f"mapped: {', '.join(self.columns) or 'none'}"
                )
        return self

    def read(
        self,
        path: str | Path,
        *,
        required: tuple[str, ...] = ("time",),
        controller: Any = None,
        columns: Mapping[str, str | int] | None = None,
        units: Mapping[str, str] | None = None,
        **kw,
    ) -> Log:
        """Read one log with this format: a ``.mat`` file through
        :func:`flexarm.io.matfile.read_mat`, any other through
        :func:`flexarm.io.logs.read_log` (``kw`` passes on to it, e.g. ``max_jitter``,
        ``min_samples``, ``hint``); ``columns`` / ``units`` on top of the format's; then the
        ``[checks]`` and the declared controller (:meth:`declared_controller`). The result
        is a :class:`flexarm.io.logs.Log` in SI units."""
        path = Path(path)
        if any(
            isinstance(c, ColumnInFile)
            for c in [*self.columns.values(), *self.disturbances.values()]
        ):
            return self._marked(self._read_files(path, required, **kw))
        where = f"log format {self.source}"
        cols = {**self.columns, **self.disturbances, **dict(columns or {})}
        uts = {**self.units, **dict(units or {})}
        fc = self.controller if controller is None else None
        gain_cols = fc.columns() if fc is not None else {}
        if path.suffix.lower() == ".mat":
            if not cols:
                raise LogFormatError(
                    f"{path}: a .mat recording needs a log format with a "
                    "[columns] table (flexarm name = variable spec)"
                )
            missing = [c for c in required if c not in cols]
            if missing:
                raise LogFormatError(
                    f"{path}: {where}: [columns] maps no "
                    f"{', '.join(missing)}; map it to a variable (e.g. "
                    f'time = "logsout.time")'
                )
            variables = matfile.load_mat(path)
            # a .mat log's gain columns are variable specs (strings), as its [columns]
            mat_cols = cast("dict[str, str]", {**cols, **gain_cols})
            # a linear axis's lengths and forces (motor_angle = "mm"): converted here
            linear = {
                k: u for k, u in uts.items() if column_unit(k, u) not in (signal_unit(k), None)
            }
            log = matfile.read_mat(
                path,
                mat_cols,
                {k: u for k, u in uts.items() if k not in linear},
                variables=variables,
                source=self.source,
            )
            for k, u in linear.items():
                si = column_unit(k, u)
                assert si is not None  # a known name (linear)
                log.signals[k] = log.signals[k] * float(ureg.parse_expression(u).to(si).magnitude)
            quanta = {
                k: matfile.scalar(path, variables, q, f"[checks] quantum.{k}")
                if isinstance(q, str)
                else float(q)
                for k, q in self.checks.quantum.items()
            }
        else:
            extra = {k: si for k in [*cols, *uts] if (si := column_unit(k, uts.get(k))) is not None}
            extra.update(STATE_FEEDBACK_GAINS)
            extra.update({k: disturbance_unit(self.units.get(k)) or "" for k in self.disturbances})
            text: dict[str, Any] = dict(
                delimiter=self.delimiter_char,
                comment=self.comment,
                skip_rows=self.skip_rows,
                source=where,
            )
            text.update(kw)
            log = read_log(
                path,
                {**cols, **gain_cols} or None,
                uts or None,
                required=required,
                extra=extra,
                **text,
            )
            quanta = {}
            for k, q in self.checks.quantum.items():
                if isinstance(q, str):
                    raise LogFormatError(
                        f"{self.source}: [checks] quantum.{k} = {q!r}: a "
                        "text log has no variables; give the number"
                    )
                quanta[k] = float(q)
        self._check(log, quanta)
        return self._marked(self.declared_controller(log, controller))

    def _marked(self, log: Log) -> Log:
        """The log with its ``[disturbances]`` named (:attr:`flexarm.io.logs.Log.disturbances`)."""
        if self.disturbances:
            log.disturbances = tuple(self.disturbances)
        return log

    def declared_controller(self, log: Log, controller: Any = None) -> Log:
        """The log with the law that produced its command: ``controller`` if given (a
        declaration string, a dict or a spec), else the format's ``[controller]`` (fixed
        gains or gain columns, moved out of the signals into :attr:`Log.gains`), else the
        log's ``# controller:`` line, else none (a ``[controller]`` that names no gains and
        a log without the line is an error)."""
        fc = self.controller
        sig = log.signals
        n = len(log)
        ctrl, gains = None, None
        if controller is not None:
            ctrl = controller_from_any(controller, f"{log.where}: controller option")
        elif fc is not None and (fc.gains or fc.gain_columns):
            fixed = fc.fixed_gains()
            gcols = fc.columns()
            gains = np.column_stack(
                [
                    sig.pop(k) if k in gcols else np.full(n, fixed.get(k, 0.0))
                    for k in STATE_FEEDBACK_GAINS
                ]
            )
            try:
                ctrl = StateFeedbackController(
                    type="state_feedback",
                    rate="filtered" if fc.tau > 0 else "backward",
                    rate_time_constant=fc.tau,
                    **dict(zip(("k1", "k2", "k3", "k4"), map(float, gains[0]), strict=True)),
                )
            except Exception as exc:
                raise LogFormatError(f"{log.where}: gains at the first sample: {exc}") from None
        elif "controller" in log.meta:
            ctrl = parse_controller(log.meta["controller"], f"{log.where}: '# controller:' line")
        elif fc is not None:
            raise LogFormatError(
                f"{log.where}: the gains of the {fc.kind} law cannot be found: log format "
                f"{self.source} [controller] gives neither gains nor gain_columns, and the log "
                "has no '# controller:' line; add gain_columns = {K1 = .., ...} (the columns "
                "holding the gains) or gains = {K1 = .., ...} to the format's [controller], "
                "or pass controller= (--controller)"
            )
        log.controller, log.gains, log.rate = ctrl, None, None
        log.voltage_limit = fc.limit if fc is not None else None
        log.log_format = self
        log.__post_init__()  # gains from the law when not logged, rate from the law
        if gains is not None:
            log.gains = gains
        if fc is not None and controller is None:
            log.rate = fc.rate
        return log

    def _read_files(self, path: Path, required: tuple[str, ...], **kw) -> Log:
        """One run saved as several files (``[columns]`` entries with ``file``): each file
        read with its own columns (:class:`ColumnInFile`; plain entries from ``path``),
        then joined; the files must have the same number of samples and, where a file's
        own ``time`` is mapped, the same times as the log's (to 1e-6 of a step): an error
        names both files. ``path`` is the run's stem (module docstring)."""

        stem = str(path.with_suffix("")) if path.suffix else str(path)
        files: dict[Path, dict[str, int | str]] = {}
        own_time: dict[Path, tuple[str, int | str]] = {}
        for name, ref in {**self.columns, **self.disturbances}.items():
            f = ref.path(stem, path.parent) if isinstance(ref, ColumnInFile) else path
            files.setdefault(f, {})[name] = ref.column if isinstance(ref, ColumnInFile) else ref
            if isinstance(ref, ColumnInFile) and ref.time is not None:
                own_time.setdefault(f, (name, ref.time))
        missing = [c for c in required if c not in self.columns]
        if missing:
            raise LogFormatError(
                f"{path}: log format {self.source}: [columns] maps no "
                f"{', '.join(missing)}; map it (from any of the run's files)"
            )
        parts: dict[Path, Log] = {}
        for f, cols in files.items():
            cols = dict(cols)
            if f in own_time and "time" not in cols:
                cols["time"] = own_time[f][1]
            if not f.is_file():
                who = ", ".join(k for k in cols if k != "time" or f not in own_time)
                raise LogFormatError(
                    f"{f}: no such file ([columns] {who} in {self.source}, read for the log "
                    f"{path}); {{stem}} = {stem!r}: give the run's stem (the path the files' "
                    "names start with) or fix the 'file' entries"
                )
            sub = LogFormat.model_construct(
                **{
                    **{k: getattr(self, k) for k in type(self).model_fields},
                    "columns": {k: c for k, c in cols.items() if k not in self.disturbances},
                    "disturbances": {k: c for k, c in cols.items() if k in self.disturbances},
                    "checks": Checks(),
                    "controller": None,
                    "units": {k: u for k, u in self.units.items() if k in cols},
                }
            )
            sub._source = self.source
            parts[f] = sub.read(f, required=("time",) if "time" in cols else (), **kw)
        t_file = next(f for f, c in files.items() if "time" in c)
        time = parts[t_file].time
        assert time is not None  # read with required=("time",)
        n = len(time)
        for f, g in parts.items():
            if len(g) != n:
                raise LogFormatError(
                    f"{f}: {len(g)} samples, but {t_file} (the log's time, [columns] time in "
                    f"{self.source}) has {n}: the files of one log must share one time base; "
                    "give files captured together (same trigger, same length)"
                )
            if g.time is not None and f != t_file:
                step = float(np.median(np.diff(time))) if n > 1 else 1.0
                off = np.abs(g.time - time)
                j = int(np.argmax(off))
                if off[j] > 1e-6 * abs(step):
                    raise LogFormatError(
                        f"{f}: its time ({own_time[f][0]} time = {own_time[f][1]!r}) differs "
                        f"from the log's time in {t_file} at sample {j}: {g.time[j]:.9g} s vs "
                        f"{time[j]:.9g} s (step {step:g} s): the files of one log must share "
                        "one time base; give captures of the same run and window"
                    )
        signals = {k: v for g in parts.values() for k, v in g.signals.items()}
        log = Log(
            path,
            time,
            signals,
            skipped=[x for g in parts.values() for x in g.skipped],
            notes=[x for g in parts.values() for x in g.notes],
        )
        quanta = {}
        for k, q in self.checks.quantum.items():
            if isinstance(q, str):
                f = next(f for f, c in files.items() if k in c)
                if f.suffix.lower() != ".mat":
                    raise LogFormatError(
                        f"{self.source}: [checks] quantum.{k} = {q!r}: a "
                        "text log has no variables; give the number"
                    )
                q = matfile.scalar(f, matfile.load_mat(f), q, f"[checks] quantum.{k}")
            quanta[k] = float(q)
        self._check(log, quanta)
        return log

    def _check(self, log: Log, quanta: dict[str, float]) -> None:
        for k, q in quanta.items():
            x = log[k]
            if not q > 0 or not np.isfinite(q):
                raise LogFormatError(
                    f"{log.where}: [checks] quantum.{k} = {q!r}: not a positive number"
                )
            off = np.abs(x / q - np.round(x / q))
            j = int(np.argmax(off))
            if off[j] > GRID_TOLERANCE:
                at = f" (t = {log.time[j]:.6g} s)" if log.time is not None else ""
                raise LogFormatError(
                    f"{log.where}: {k} = {self.columns[k]!r} is not an encoder reading: sample "
                    f"{j}{at} = {x[j]:.9g} lies {off[j]:.3g} quanta off the grid k·{q:.6g} "
                    f"([checks] quantum.{k} in {self.source}); {int((off > GRID_TOLERANCE).sum())} "
                    f"of {len(x)} samples are off it. A measured angle lies on its encoder's "
                    "grid: is this variable a setpoint or a simulated signal? Map the "
                    "variable that holds the measurement (check the file's variables "
                    "against each other)"
                )
        for k in self.checks.zero:
            x = log[k]
            if np.any(x != 0):
                j = int(np.argmax(x != 0))
                raise LogFormatError(
                    f"{log.where}: {k} = {self.columns[k]!r} must be all zeros ([checks] zero "
                    f"in {self.source}); sample {j} is {x[j]:.6g} ({int((x != 0).sum())} "
                    "non-zero): the format maps another variable than the one meant"
                )

    @property
    def source(self) -> str:
        """Where the format came from (the file), for messages."""
        return self._source

    @property
    def delimiter_char(self) -> str | None:
        """The delimiter for :func:`flexarm.io.logs.read_log` (``None``: sniffed, ``" "``: runs
        of whitespace)."""
        return DELIMITER_NAMES.get(self.delimiter.lower(), self.delimiter)


def disturbance_unit(unit: str | None) -> str | None:
    """The SI unit (pint's base units) a logged disturbance given in ``unit`` is converted
    to (``"mV"`` → volts as base units); ``None`` when ``unit`` is not a unit."""
    if unit is None:
        return None
    try:
        return str(ureg.parse_expression(unit).to_base_units().units)
    except Exception:  # pint raises several exception types
        return None


def log_format_from_dict(data: dict[str, Any], source: str = "log format") -> LogFormat:
    """Validate a log format given as a dict (as parsed from TOML)."""
    from flexarm.specs.scenario import _format_errors

    try:
        fmt = LogFormat.model_validate(data)
    except ValidationError as err:
        raise LogFormatError(_format_errors(err, source, "log format")) from None
    fmt._source = source
    return fmt


def load_log_format(path: str | Path | LogFormat) -> LogFormat:
    """Read and validate a log-format TOML file (a :class:`LogFormat` is returned as is)."""
    if isinstance(path, LogFormat):
        return path
    path = Path(path)
    from flexarm.io.write import InputFileError, read_input

    try:  # a regular file of at most 1 MiB (not /dev/zero)
        text = read_input(path, limit=1 << 20, what="log-format file").decode("utf-8")
    except FileNotFoundError:
        raise LogFormatError(f"{path}: no such log-format file") from None
    except InputFileError as exc:
        raise LogFormatError(str(exc)) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise LogFormatError(f"{path}: cannot read the log-format file ({exc})") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise LogFormatError(f"{path}: not valid TOML: {exc}") from None
    except RecursionError:
        raise LogFormatError(
            f"{path}: nested too deeply to read (arrays or tables inside each other); "
            "a log format is a few flat tables"
        ) from None
    return log_format_from_dict(data, source=str(path))


def load_log(
    path: str | Path,
    log_format: str | Path | LogFormat | None = None,
    *,
    controller: Any = None,
    columns: Mapping[str, str | int] | None = None,
    units: Mapping[str, str] | None = None,
    **kw,
) -> Log:
    """One log as its logger wrote it (text or ``.mat``), read through a log-format file
    (``None``: a text log in flexarm's exchange format, SI units, named columns); returns
    the one :class:`flexarm.io.logs.Log` in SI units with the controller the lab ran
    (:meth:`LogFormat.declared_controller`). ``columns`` / ``units`` apply on top of the
    format's; ``kw`` passes on to :meth:`LogFormat.read` (``required``, ``max_jitter``,
    ``min_samples``, ``hint``)."""
    fmt = load_log_format(log_format) if log_format is not None else LogFormat()
    return fmt.read(path, controller=controller, columns=columns, units=units, **kw)


def load_logs(
    paths: Sequence[Any],
    formats: str | Path | LogFormat | Sequence[str | Path | LogFormat] | None = None,
    **kw,
) -> list[Log]:
    """:func:`load_log` for each path with its format (:func:`formats_for`: one for all,
    one per log in order, ``PATTERN=FILE`` entries, or none: the exchange format); logs
    already read (:class:`~flexarm.io.logs.Log`) pass through. ``kw`` passes on to
    :func:`load_log` (``controller``, ``columns``, ``units``, ``max_jitter``, ...)."""
    paths = list(paths)
    files = [p for p in paths if not isinstance(p, Log)]
    if not files:
        return paths
    fmts = iter(formats_for(files, formats))
    return [p if isinstance(p, Log) else load_log(p, next(fmts), **kw) for p in paths]


def formats_for(
    paths: Sequence[str | Path],
    formats: str | Path | LogFormat | Sequence[str | Path | LogFormat] | None = None,
) -> list[LogFormat | None]:
    """Each log's format (``None``: the exchange format) — ``flexarm fit/validate
    --log-format``: ``formats`` one per log (in order), one for all (a file or a
    :class:`LogFormat`), none, or ``PATTERN=FILE`` entries (fnmatch on the file name; the
    first match wins); each file read once. A mismatch is one :class:`LogError` line naming
    the log or the formats."""
    import fnmatch

    if not paths:
        raise LogError("no logs given: give one or more log files")
    if formats is None or isinstance(formats, (str, Path, LogFormat)):
        formats = [] if formats is None else [formats]
    entries = list(formats)
    text = [str(f) for f in entries if not isinstance(f, LogFormat)]
    pats = [x.split("=", 1) for x in text if "=" in x]
    plain = [
        f if isinstance(f, LogFormat) else str(f)
        for f in entries
        if isinstance(f, LogFormat) or "=" not in str(f)
    ]
    if pats and plain:
        raise LogError(
            "log format: give either one FILE per log (or one for all), or PATTERN=FILE "
            f"entries, not both (got {text})"
        )
    if plain and len(plain) not in (1, len(paths)):
        raise LogError(
            f"log format given {len(plain)} times for {len(paths)} logs: give it once for "
            "all, once per log in order, or as PATTERN=FILE"
        )
    cache: dict[str, LogFormat] = {}
    out: list[LogFormat | None] = []
    for i, p in enumerate(paths):
        if pats:
            hit = [f for pat, f in pats if fnmatch.fnmatch(Path(p).name, pat)]
            if not hit:
                raise LogError(
                    f"{p}: no log-format PATTERN matches its name (patterns: "
                    f"{', '.join(pat for pat, _ in pats)})"
                )
            f: str | LogFormat | None = hit[0]
        else:
            f = plain[0] if len(plain) == 1 else (plain[i] if plain else None)
        if isinstance(f, str) and f not in cache:
            cache[f] = load_log_format(f)
        out.append(cache[f] if isinstance(f, str) else f)
    return out


def sample_rate(log: Log) -> float:
    """The log's sampling rate (Hz): 1 / median step, rounded off the logger's float noise
    to 9 digits."""
    return float(f"{1 / log.dt:.9g}")


def read_recording(path: str | Path, log_format=None) -> tuple[dict[str, np.ndarray], float]:
    """Signals (flexarm name → SI samples) and the sampling rate (Hz) of a ``.mat`` or text
    recording, mapped by a log-format file (:func:`load_log`, :func:`sample_rate`)."""
    log = load_log(path, log_format)
    return log.signals, sample_rate(log)


# ----------------------------------------------------------------------------- controllers
def parse_controller(text: str, source: str = "controller") -> StateFeedbackController:
    """A ``# controller:`` line: ``state_feedback K1=6 K2=-3 K3=0.213 K4=0 [rate=filtered
    tau=0.02]`` or ``pd KP=10 KD=0.3`` → the spec (a PD is the state feedback with K2 = K4 =
    0: u = KP (r − θ) − KD θ̇)."""
    words = text.replace(",", " ").split()
    if not words:
        raise LogError(
            f"{source}: empty controller declaration; write e.g. "
            "'state_feedback K1=6 K2=-3 K3=0.2 K4=0' or 'pd KP=10 KD=0.3'"
        )
    kind = words[0].lower()
    vals: dict[str, Any] = {}
    for w in words[1:]:
        if "=" not in w:
            raise LogError(f"{source}: {w!r} in the controller declaration is not NAME=VALUE")
        k, _, v = w.partition("=")
        vals[k.strip().lower()] = v.strip()
    allowed = {
        "state_feedback": {"k1", "k2", "k3", "k4", "rate", "tau"},
        "pd": {"kp", "kd", "rate", "tau"},
    }
    if kind not in allowed:
        raise LogError(
            f"{source}: controller type {kind!r} is not known; a log declares "
            "'state_feedback K1=.. K2=.. K3=.. K4=..' or 'pd KP=.. KD=..'"
        )
    unknown = set(vals) - allowed[kind]
    if unknown:
        raise LogError(
            f"{source}: unknown controller field(s) {sorted(unknown)} for "
            f"{kind}; allowed: {sorted(allowed[kind])}"
        )
    num = {}
    for k, v in vals.items():
        if k == "rate":
            continue
        try:
            num[k] = float(v)
        except ValueError:
            raise LogError(
                f"{source}: controller field {k.upper()} = {v!r} is not a number"
            ) from None
    rate = vals.get("rate", "filtered" if "tau" in num else "backward")
    if kind == "pd":
        if "kp" not in num:
            raise LogError(f"{source}: pd controller without KP")
        g = dict(k1=num["kp"], k2=0.0, k3=num.get("kd", 0.0), k4=0.0)
    else:
        if "k1" not in num:
            raise LogError(f"{source}: state_feedback controller without K1")
        g: dict[str, Any] = {k: num.get(k, 0.0) for k in ("k1", "k2", "k3", "k4")}
    try:
        return StateFeedbackController(
            type="state_feedback", rate=rate, rate_time_constant=num.get("tau", 0.0), **g
        )
    except Exception as exc:
        raise LogError(f"{source}: controller declaration: {exc}") from None


def controller_from_any(c: Any, source: str) -> StateFeedbackController:
    """A spec, a dict of spec fields, or a declaration string (:func:`parse_controller`)."""
    if isinstance(c, StateFeedbackController):
        return c
    if isinstance(c, str):
        return parse_controller(c, source)
    if isinstance(c, Mapping):
        d = {"type": "state_feedback", **c}
        if d.get("type") == "pd":
            d = {
                "type": "state_feedback",
                "k1": d.get("kp"),
                "k3": d.get("kd", 0.0),
                **{k: v for k, v in d.items() if k in ("rate", "rate_time_constant")},
            }
        try:
            return StateFeedbackController(**d)
        except Exception as exc:
            raise LogError(f"{source}: controller: {exc}") from None
    raise LogError(
        f"{source}: controller {c!r}: give a declaration string, a dict or a "
        "StateFeedbackController"
    )
