"""One fit result for every rig fitted by the one engine: :class:`FitResult`.

Values (SI, by scenario path), standard deviations (Newey–West HAC with the priors'
information, :mod:`flexarm.identification.time_domain.uncertainty`), the correlation matrix
of the log-parameters z_i = ln(p_i / p0_i), warnings (bounds, inseparable pairs, undetermined
parameters), fit % = 100 (1 − ‖y − ŷ‖ / ‖y − ȳ‖) per log and signal of the whole-run
prediction (:func:`flexarm.metrics.fit_percent`) and of the segments, the fitted scenario,
and the optimiser's record.

:meth:`FitResult.to_dict` is the ``--json`` document ``flexarm fit SCENARIO LOG...`` writes;
:meth:`FitResult.from_dict` reads it back; :meth:`FitResult.write_scenario` writes the fitted
scenario TOML (``--scenario-out``). The rotary servo rig's engine
(:func:`flexarm.identification.time_domain.fit.fit`) gives the same result through
:func:`flexarm.identification.time_domain.report.as_fit_result`: its own record (derived
values, sensor delays, initial states, settings, units) under ``stages["servo_rig"]``, its
live result as :attr:`FitResult.engine_result` (not in the document). Logs are keyed by
:func:`flexarm.io.logs.log_keys` (paths relative to the logs' common folder, so logs of one
name in different folders keep separate entries).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, cast

import numpy as np

__all__ = ["FitResult", "Prediction", "finite", "drop_none", "session_key", "session_path"]


def session_key(session: int, path: str) -> str:
    """The result's key of a later session's own value at scenario ``path``:
    ``sessions[1].arm.friction.coulomb`` (session 0's is the path itself)."""
    return f"sessions[{session}].{path}" if session else path


def session_path(path: str) -> str:
    """``sessions[1].arm.friction.coulomb`` → ``arm.friction.coulomb``."""
    return path.split("].", 1)[1] if path.startswith("sessions[") else path


@dataclass
class FitResult:
    """The result of :func:`flexarm.fit` (see the module docstring).

    ``free_source`` says where the free list came from (``"given"``, ``"preset
    quanser-two-link"``, ``"scenario [notes.fit]"``); ``extras`` holds what a caller adds to
    the document (``window_s``, ``held_out``, ``without_friction``, the interrupted marks),
    written by :meth:`to_dict` as top-level keys. ``engine_result``: the engine's own live
    result where it has one (the servo rig's
    :class:`~flexarm.identification.time_domain.report.FitResult`: its loop, logs and
    trajectories for figures and the prediction of other logs); not in the document, not
    compared."""

    free: list[str]
    params: dict[str, float]
    template: dict[str, float]
    std: dict[str, float]
    correlation: np.ndarray
    warnings: list[str]
    fit_percent: dict[str, dict[str, float | None]]  # None: not finite (a rig's absent tip)
    segment_fit_percent: dict[str, dict[str, float | None]]
    scenario: Any
    converged: bool
    message: str
    nfev: int
    cost: float
    seconds: float
    stages: dict[str, Any] = field(default_factory=dict)
    prediction: Any = field(default_factory=dict)
    free_source: str = "given"
    plots: list[str] = field(default_factory=list)
    extras: dict[str, Any] = field(default_factory=dict)
    engine_result: Any = field(default=None, repr=False, compare=False)
    #: per log and signal, beside ``fit_percent``: the RMSE in the signal's SI unit and the
    #: NRMSE (RMSE over the signal's range), of the same prediction
    rmse: dict[str, dict[str, float]] = field(default_factory=dict)
    nrmse: dict[str, dict[str, float | None]] = field(default_factory=dict)
    #: a fit over several sessions of one rig: each session's fitted scenario (session 0's
    #: is ``scenario``); :meth:`write_scenario` writes the later ones beside it
    session_scenarios: list[Any] = field(default_factory=list, repr=False, compare=False)

    def _table(self):
        from flexarm.display import Table, fit_percent_lines, parameter_rows

        state = "converged" if self.converged else "NOT converged"
        name = getattr(self.scenario, "name", "scenario")
        notes = [f"{state}: {self.message}", *fit_percent_lines(self.fit_percent)]
        notes += [f"warning: {w}" for w in self.warnings]
        notes.append(
            f"free list: {self.free_source}; {self.nfev} evaluations, {self.seconds:.1f} s"
        )
        std_head = "std (bootstrap)" if "bootstrap" in self.stages else "std (HAC)"
        if "std_source" in self.stages:
            notes.append(f"std: {self.stages['std_source']}")
        return Table(
            f"FitResult of {name}: {len(self.free)} free parameters (SI)",
            parameter_rows(self.params, self.std, self.stages.get("units")),
            header=("parameter", "value", std_head, "std %", "unit"),
            notes=notes,
        )

    def __repr__(self) -> str:
        return self._table().text()

    def _repr_html_(self) -> str:
        return self._table().html()

    def write_scenario(self, path: str | Path, *, overwrite: bool = False) -> Path:
        """Write the fitted scenario as TOML (SI values; it loads with load_scenario); the
        engine's own writer where it has one (the servo rig's commented TOML)."""
        from flexarm.io.write import write_toml

        for q in self.session_paths(path)[1:]:  # every output checked before any is written
            if Path(q).exists() and not overwrite:
                from flexarm.errors import OutputExistsError

                raise OutputExistsError(f"{q}: exists already; not overwritten (pass overwrite)")
        if self.engine_result is not None and hasattr(self.engine_result, "write_scenario"):
            out = self.engine_result.write_scenario(path, overwrite=overwrite)
        else:
            data = cast(dict, drop_none(self.scenario.model_dump()))
            out = write_toml(path, data, overwrite=overwrite)
        for q, sc in zip(self.session_paths(path)[1:], self.session_scenarios[1:], strict=True):
            more = cast(dict, drop_none(sc.model_dump()))
            write_toml(q, more, overwrite=overwrite)
        return out

    def session_paths(self, path: str | Path) -> list[Path]:
        """Where :meth:`write_scenario` writes each session's scenario: ``path`` for session
        0, ``STEM.session1.toml`` ... beside it for the later ones (one path without
        sessions)."""
        p = Path(path)
        n = max(1, len(self.session_scenarios))
        return [p] + [p.with_name(f"{p.stem}.session{s}{p.suffix}") for s in range(1, n)]

    def to_dict(self) -> dict:
        """The ``--json`` document (non-finite numbers, e.g. the std of an undetermined
        parameter, as null)."""
        d = {
            "free": self.free,
            "params": self.params,
            "template": self.template,
            "std": self.std,
            "correlation": np.round(np.asarray(self.correlation, float), 4).tolist(),
            "warnings": self.warnings,
            "fit_percent": self.fit_percent,
            "rmse": self.rmse,
            "nrmse": self.nrmse,
            "segment_fit_percent": self.segment_fit_percent,
            "converged": self.converged,
            "message": self.message,
            "nfev": self.nfev,
            "cost": self.cost,
            "seconds": round(self.seconds, 2),
            "stages": self.stages,
            "free_source": self.free_source,
            "plots": [str(p) for p in self.plots],
        }
        d.update(self.extras)
        return finite(d)

    def refit_entry(self, free: list[str], window, log, prediction) -> dict:
        """The ``refit`` entry of ``flexarm validate --refit friction --json``: this
        (friction) refit's values, template, std and warnings on ``free``, the ``window``
        (s) of ``log`` it used, and the fit % of ``prediction`` (the logs predicted with
        the refitted scenario)."""
        return finite(
            {
                "window_s": list(window),
                "log": str(log),
                "params": {p: self.params[p] for p in free},
                "template": {p: self.template[p] for p in free},
                "std": {p: self.std[p] for p in free},
                "warnings": self.warnings,
                "fit_percent": prediction["fit_percent"],
            }
        )

    @classmethod
    def from_dict(cls, d: dict, scenario: Any = None) -> FitResult:
        """A result read back from :meth:`to_dict`'s document (``scenario``: the fitted
        scenario, e.g. ``load_scenario`` of the ``--scenario-out`` file; the document does
        not hold it). Nulls read back as NaN (std) and the correlation as an array."""
        known = {
            "free",
            "params",
            "template",
            "std",
            "correlation",
            "warnings",
            "fit_percent",
            "segment_fit_percent",
            "converged",
            "message",
            "nfev",
            "cost",
            "seconds",
            "stages",
            "free_source",
            "plots",
            "rmse",
            "nrmse",
        }
        missing = [k for k in ("free", "params", "std") if k not in d]
        if missing:
            raise ValueError(
                f"fit document: no {', '.join(missing)}: not a document written "
                "by FitResult.to_dict (flexarm fit SCENARIO LOG... --json)"
            )
        nan = float("nan")
        corr = np.array(
            [[nan if v is None else v for v in row] for row in d.get("correlation", [])], float
        )
        return cls(
            list(d["free"]),
            dict(d["params"]),
            dict(d.get("template", {})),
            {k: nan if v is None else float(v) for k, v in d["std"].items()},
            corr,
            list(d.get("warnings", [])),
            dict(d.get("fit_percent", {})),
            dict(d.get("segment_fit_percent", {})),
            scenario,
            bool(d.get("converged", False)),
            str(d.get("message", "")),
            int(d.get("nfev", 0)),
            float(d.get("cost") or nan),
            float(d.get("seconds", 0.0)),
            dict(d.get("stages", {})),
            {},
            str(d.get("free_source", "given")),
            list(d.get("plots", [])),
            {k: v for k, v in d.items() if k not in known},
            rmse=dict(d.get("rmse", {})),
            nrmse=dict(d.get("nrmse", {})),
        )


def finite(x: Any) -> Any:
    """JSON-ready: non-finite floats as None, NumPy scalars as Python's, keys as strings
    (as JSON writes them: a document reads back equal), recursively."""
    if isinstance(x, dict):
        return {str(k): finite(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [finite(v) for v in x]
    if isinstance(x, (float, np.floating)):
        return None if not math.isfinite(float(x)) else float(x)
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    return x


def drop_none(d):
    """A model_dump without the unset (None) fields, which TOML cannot hold."""
    if isinstance(d, dict):
        return {k: drop_none(v) for k, v in d.items() if v is not None}
    if isinstance(d, (list, tuple)):
        return [drop_none(v) for v in d]
    return d


@dataclass
class Prediction:
    """fit % per log key and signal (None where the log lacks the signal), the traces
    (per key: ``time`` s from the log's first sample, ``measured`` and ``simulated`` per
    signal; optionally ``reference``, drawn in the first panel, and ``display``, signal →
    (unit, factor) for the figure's axis), warnings and notes, per-log divergence and any
    figures written."""

    scenario: str
    fit_percent: dict[str, dict[str, float | None]]
    traces: dict[str, dict[str, Any]] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    diverged: dict[str, bool] = field(default_factory=dict)
    plots: list[str] = field(default_factory=list)
    #: per log key and signal: RMSE in the signal's SI unit, and RMSE / (max − min)
    rmse: dict[str, dict[str, float]] = field(default_factory=dict)
    nrmse: dict[str, dict[str, float | None]] = field(default_factory=dict)

    def to_dict(self) -> dict:
        """JSON-ready: scenario, fit %, RMSE (SI), NRMSE, divergence, warnings, notes,
        figures (no traces)."""
        return finite(
            {
                "scenario": self.scenario,
                "fit_percent": self.fit_percent,
                "rmse": self.rmse,
                "nrmse": self.nrmse,
                "diverged": self.diverged,
                "warnings": self.warnings,
                "notes": self.notes,
                "plots": [str(p) for p in self.plots],
            }
        )

    def _table(self):
        from flexarm.display import Table

        sigs = list(dict.fromkeys(k for per in self.fit_percent.values() for k in per))
        rows = [(key, *(per.get(s) for s in sigs)) for key, per in self.fit_percent.items()]
        notes = [f"{k} diverged" for k, bad in self.diverged.items() if bad]
        notes += [f"warning: {w}" for w in self.warnings] + list(self.notes)
        return Table(
            f"Prediction by {self.scenario}: fit % per log and signal",
            rows,
            header=("log", *sigs),
            notes=notes,
        )

    def __repr__(self) -> str:
        return self._table().text()

    def _repr_html_(self) -> str:
        return self._table().html()

    def __getitem__(self, key: str):
        """Deprecated dict access (``validate(...)["fit_percent"]``), as the old
        validators returned dicts."""
        if key in ("fit_percent", "diverged", "warnings", "notes", "plots", "scenario", "traces"):
            return getattr(self, key)
        raise KeyError(key)
