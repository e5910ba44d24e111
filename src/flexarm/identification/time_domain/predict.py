"""One prediction of logs by a model with its parameters fixed: :func:`predict` →
:class:`Prediction`, and one overlay figure, :func:`overlay_figure` (as PNGs:
:func:`write_overlays`): the only code that draws measured against predicted signals; the
servo rig's fit and replay figures (:func:`~.report.overlay_plots`) and the general
engine's (:func:`~.general.predict_scenario`'s ``plots``) are drawn by it.

Each log (or its window, [t0, t1) s from its first sample) is simulated once with its own
references and the controller it ran, and compared per measured signal by

    fit % = 100 (1 − ‖y − ŷ‖ / ‖y − ȳ‖)                    (:func:`flexarm.metrics.fit_percent`)

The model is a scenario (any arm: the one engine's whole-run prediction,
:func:`flexarm.identification.time_domain.general.predict_scenario`, from the scenario's
initial state or, for a window, the logged state), a :class:`~.result.FitResult` (its fitted
scenario), or a rotary servo-rig fit (that engine's loop, each log's initial state
estimated on the log itself; :func:`flexarm.identification.time_domain.fit.predict`). A
single-link scenario predicting servo-rig logs (a declared state-feedback law, a
``reference`` column) runs the rig's replay
(:func:`flexarm.identification.time_domain.validate.validate`). Logs are keyed by
:func:`flexarm.io.logs.log_keys` (same file names in other folders stay apart).

``PredictOptions.controller`` as a controller file (a
:class:`~flexarm.specs.scenario.ControllerFile` from
:func:`~flexarm.specs.scenario.load_controllers`, or the path of such a ``.toml``) replaces
the scenario's controllers for the run (:meth:`~flexarm.specs.Scenario.with_controllers`);
any other value is the servo rig's text law overriding the logs' ``# controller:`` line.
``PredictOptions.continuous``: the logs, in order, are consecutive pieces of one run; each
starts from its logged plant state and every dynamic controller block (and digital
filter) from the state reached over the pieces before
(:func:`flexarm.sim.filters.continuous_starts`, in the general engine). Without it, each
log a dynamic controller starts from its assumed ``initial_state`` is a warning in
:attr:`Prediction.warnings` naming the block and ``--continuous``.

This replaces ``validate.validate``, ``fit.predict``, ``general.predict_scenario`` and
``analysis.replay.replay`` as the one entry (those stay as the engines behind it, or as
deprecated aliases).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from flexarm.identification.time_domain.figures import (  # re-exported (the figures' home)
    RIG_DISPLAY,
    overlay_figure,
    rig_trace,
    write_overlays,
)
from flexarm.identification.time_domain.options import PredictOptions

__all__ = [
    "Prediction",
    "predict",
    "controller_file",
    "overlay_figure",
    "write_overlays",
    "rig_trace",
    "RIG_DISPLAY",
]


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

    def to_dict(self) -> dict:
        """JSON-ready: scenario, fit %, divergence, warnings, notes, figures (no traces)."""
        from flexarm.identification.time_domain.result import finite

        return finite(
            {
                "scenario": self.scenario,
                "fit_percent": self.fit_percent,
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


def _is_rig_fit(x) -> bool:
    return hasattr(x, "rig") and hasattr(x, "space") and hasattr(x, "settings")


def _rig_logs(logs, controller) -> bool:
    return all(
        getattr(g, "controller", None) is not None or controller is not None for g in logs
    ) and all("reference" in getattr(g, "signals", {}) for g in logs)


def predict(model: Any, logs: Sequence[Any], options: PredictOptions | None = None) -> Prediction:
    """Predict ``logs`` with ``model`` (a scenario, its TOML path or built-in name, a
    :class:`~.result.FitResult`, or a rotary servo-rig fit) with its parameters fixed; see
    the module docstring. Paths in ``logs`` are read by :func:`flexarm.io.logformat.load_log`
    (exchange format)."""
    from flexarm.io.logformat import load_logs
    from flexarm.io.logs import log_keys
    from flexarm.specs import Scenario, load_scenario

    opts = options or PredictOptions()
    logs = load_logs(logs)
    if opts.windows is not None:
        if len(opts.windows) != len(logs):
            raise ValueError(
                f"PredictOptions.windows has {len(opts.windows)} entries for {len(logs)} logs"
            )
        if opts.continuous and any(w is not None for w in opts.windows):
            raise ValueError(
                "PredictOptions: continuous (consecutive pieces of one run) "
                "predicts whole logs; leave out windows (--window)"
            )
    keys = log_keys(logs)
    cfile = controller_file(opts.controller)
    if _is_rig_fit(getattr(model, "engine_result", None)):  # the one result of a rig fit
        model = model.engine_result
    if _is_rig_fit(model):
        if cfile is not None or opts.continuous:
            raise ValueError(
                "a servo-rig fit predicts with its own loop: a controller file "
                "and continuous need a scenario (flexarm validate SCENARIO ...)"
            )
        return _predict_rig_fit(model, logs, keys, opts)
    sc = getattr(model, "scenario", model)
    sc = sc if isinstance(sc, Scenario) else load_scenario(sc)
    if cfile is not None:
        sc = sc.with_controllers(cfile)
        opts = replace(opts, controller=None)
    elif opts.continuous and sc.arm.kind == "single_link" and _rig_logs(logs, opts.controller):
        raise ValueError(
            "continuous: the servo rig's replay runs each log alone; a "
            "scenario's own controller (or --controller FILE.toml) runs them "
            "as one run"
        )
    if cfile is None and sc.arm.kind == "single_link" and _rig_logs(logs, opts.controller):
        return _predict_rig_scenario(sc, logs, keys, opts)
    return _predict_scenario(sc, logs, keys, opts)


def controller_file(value: Any):
    """``value`` as a controller file: a :class:`~flexarm.specs.scenario.ControllerFile`
    as given, an existing ``.toml`` path read by
    :func:`~flexarm.specs.scenario.load_controllers`; None for anything else (the servo
    rig's text law, or nothing)."""
    from flexarm.specs.scenario import ControllerFile, load_controllers

    if isinstance(value, ControllerFile):
        return value
    if isinstance(value, (str, Path)) and str(value).lower().endswith(".toml"):
        p = Path(value)
        if p.is_file():
            return load_controllers(p)
        raise ValueError(
            f"controller {str(value)!r}: no such controller file (a TOML with "
            "[controller] or [[controllers]] tables); give an existing file"
        )
    return None


def _windowed(logs, opts):
    if opts.windows is None:
        return list(logs)
    return [g if w is None else g.window(*w) for g, w in zip(logs, opts.windows, strict=True)]


def _predict_scenario(sc, logs, keys, opts) -> Prediction:
    from flexarm.identification.time_domain.general import ScenarioFitOptions, predict_scenario

    fo = ScenarioFitOptions(
        windows=list(opts.windows) if opts.windows is not None else None,
        continuous=bool(opts.continuous),
    )
    out = predict_scenario(sc, logs, fo, channels=list(opts.channels) if opts.channels else None)
    # predict_scenario keys logs by log_keys (with a window suffix): back to plain keys
    fp = dict(zip(keys, out["fit_percent"].values(), strict=False))
    traces = {}
    for k, tr in zip(keys, out["trajectories"].values(), strict=False):
        t = np.asarray(tr["time"], float)
        traces[k] = {
            "time": t - t[0] if t.size else t,
            "measured": tr["measured"],
            "simulated": tr["simulated"],
        }
    pred = Prediction(
        sc.name,
        fp,
        traces,
        warnings=list(out.get("warnings", [])),
        notes=list(dict.fromkeys(out.get("notes", []))),
        diverged={k: False for k in keys},
    )
    if opts.continuous:
        pred.notes.append(
            f"continuous: the {len(keys)} logs replayed as consecutive pieces "
            "of one run (controller and filter states carried)"
        )
    if opts.plots is not None:
        pred.plots = [str(p) for p in write_overlays(pred, opts.plots, opts.tag)]
    return pred


def _predict_rig_scenario(sc, logs, keys, opts) -> Prediction:
    from flexarm.identification.time_domain.validate import validate

    fp, traces = {}, {}
    for k, g in zip(keys, _windowed(logs, opts), strict=True):
        out = validate(sc, [g], controller=opts.controller, traces=True)
        fp[k] = next(iter(out["fit_percent"].values()))
        traces[k] = out["traces"][0]
    pred = Prediction(sc.name, fp, traces, diverged={k: False for k in keys})
    if opts.plots is not None:
        pred.plots = [str(p) for p in write_overlays(pred, opts.plots, opts.tag)]
    return pred


def _predict_rig_fit(res, logs, keys, opts) -> Prediction:
    from flexarm.identification.time_domain.fit import predict as rig_predict

    # one call: the rig keys its results by log_keys, so logs of one name in other
    # folders stay apart (the order is the logs' order)
    out = rig_predict(
        res,
        _windowed(logs, opts),
        estimate_initial=opts.estimate_initial,
        controller=opts.controller,
    )
    fp = dict(zip(keys, out["fit_percent"].values(), strict=True))
    div = dict(zip(keys, out["diverged"].values(), strict=True))
    tr = out["traj"]
    traces = {
        k: rig_trace(g, [np.asarray(tr[r][j, : len(g)]) for r in range(3)])
        for j, (k, g) in enumerate(zip(keys, out["logs"], strict=True))
    }
    pred = Prediction(
        "fitted rig",
        fp,
        traces,
        diverged=div,
        warnings=[f"{k}: the simulated loop diverged" for k, d in div.items() if d],
        notes=["initial state estimated from each log's own data"] if opts.estimate_initial else [],
    )
    if opts.plots is not None:
        pred.plots = [str(p) for p in write_overlays(pred, opts.plots, opts.tag)]
    return pred
