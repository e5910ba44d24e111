"""One prediction of logs by a model with its parameters fixed: :func:`predict` →
:class:`Prediction`, and one overlay figure, :func:`overlay_figure` (as PNGs:
:func:`write_overlays`): the only code that draws measured against predicted signals; the
servo rig's fit and replay figures (:func:`~.report.overlay_plots`) and the general
engine's (:func:`~.general.predict_scenario`'s ``plots``) are drawn by it.

Each log (or its window, [t0, t1) s from its first sample) is simulated once with its own
references and the controller it ran, and compared per measured signal by

    fit % = 100 (1 − ‖y − ŷ‖ / ‖y − ȳ‖)                    (:func:`flexarm.metrics.fit_percent`)

The model is a scenario (its TOML path or built-in name) or a :class:`~.result.FitResult`
(its fitted scenario, the file ``fit --scenario-out`` writes): every prediction is the one
engine's whole-run prediction,
:func:`flexarm.identification.time_domain.general.predict_scenario`, so that a fit's
figures and ``flexarm validate`` of its written scenario are one computation. Where each
log (window) starts (``PredictOptions.initial``): ``"estimate"``, the state read off it
refined by least squares on it, as the servo rig's fit does; ``"log"``, as read off it,
as the general engine's fit predicts; ``"rest"``, every rate zero; by default as the fit
that wrote the scenario did (:func:`initial_of`). Servo-rig logs that declare the law
they ran (a state-feedback law, a ``reference`` column) run with their own law on a
single-link scenario. Logs are keyed by
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

This is the one entry: the servo rig's own replay and its loop's prediction are gone.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any, cast

import numpy as np

from flexarm.identification.time_domain.figures import (  # re-exported (the figures' home)
    RIG_DISPLAY,
    overlay_figure,
    rig_trace,
    write_overlays,
)
from flexarm.identification.time_domain.options import FitOptions, PredictOptions
from flexarm.identification.time_domain.result import Prediction  # re-exported
from flexarm.io.logs import RIG_OUTPUTS

__all__ = [
    "Prediction",
    "predict",
    "controller_file",
    "overlay_figure",
    "write_overlays",
    "rig_trace",
    "RIG_DISPLAY",
]


def _rig_logs(logs, controller) -> bool:
    return all(
        getattr(g, "controller", None) is not None or controller is not None for g in logs
    ) and all("reference" in getattr(g, "signals", {}) for g in logs)


def predict(model: Any, logs: Sequence[Any], options: PredictOptions | None = None) -> Prediction:
    """Predict ``logs`` with ``model`` (a scenario, its TOML path or built-in name, or a
    :class:`~.result.FitResult`: its fitted scenario) with its parameters fixed; see the
    module docstring. Paths in ``logs`` are read by :func:`flexarm.io.logformat.load_log`
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
    sc = getattr(model, "scenario", model)
    if callable(sc) and not isinstance(sc, (Scenario, str, Path)):
        sc = sc()  # the servo rig pipeline's own result: its fitted scenario
    if sc is None:
        raise ValueError(
            "predict: this fit result has no fitted scenario (an interrupted fit); "
            "predict with a scenario"
        )
    sc = sc if isinstance(sc, Scenario) else load_scenario(cast("str | Path", sc))
    if cfile is not None:
        sc = sc.with_controllers(cfile)
        opts = replace(opts, controller=None)
    own_law = sc.arm.kind == "single_link" and cfile is None and _rig_logs(logs, opts.controller)
    if own_law and opts.continuous:
        raise ValueError(
            "continuous: the logs' own declared laws run each log alone; a "
            "scenario's own controller (or --controller FILE.toml) runs them "
            "as one run"
        )
    if opts.initial is None:
        opts = replace(opts, initial=initial_of(sc))
    return _predict_scenario(sc, logs, keys, opts, own_law)


def initial_of(scenario) -> str:
    """Where a prediction of ``scenario`` starts each log by default: its ``[notes.validate]
    initial`` (written by the fit that made it: the general engine's ``"log"``), else
    ``"estimate"`` (the logged state refined on the log, as the servo rig's fit does)."""
    from flexarm.identification.time_domain.general import INITIALS

    notes = getattr(scenario, "notes", None) or {}
    table = notes.get("validate") if isinstance(notes, dict) else None
    value = table.get("initial") if isinstance(table, dict) else None
    if value is None:
        return "estimate"
    if value not in INITIALS:
        raise ValueError(
            f"scenario {scenario.name!r}: [notes.validate] initial = {value!r}: one of "
            f"{', '.join(map(repr, INITIALS))}"
        )
    return str(value)


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


def _gain_note(key: str, log) -> list[str]:
    segs = log.gain_segments
    if len(segs) <= 1:
        return []
    t = [round(float(log.time[a] - log.time[0]), 3) for a, _ in segs[1:]]
    return [
        f"{key}: the logged gains change inside the log (at {', '.join(map(str, t))} s); "
        "the law ran with the logged gains of each sample"
    ]


def _predict_scenario(sc, logs, keys, opts, own_law: bool = False) -> Prediction:
    """The one engine's whole-run prediction (:func:`~.general.predict_scenario`). With
    ``own_law`` (servo-rig logs that declare the law they ran), each log runs with its own
    declared controller in place of the scenario's (the lab's gains differ between runs)."""
    from flexarm.identification.time_domain.general import predict_scenario

    wins = list(opts.windows) if opts.windows is not None else [None] * len(logs)
    chans = list(opts.channels) if opts.channels else None
    if own_law:
        from flexarm.identification.time_domain.logs import (
            as_rig_log,
            check_closed_loop,
            declared_laws,
        )

        logs = [as_rig_log(g, opts.controller) for g in logs]
        for g in logs:
            check_closed_loop(g)
        # each log alone with its own gains (of each sample): a log's figure does not
        # depend on the logs predicted beside it (its start state is refined on it alone)
        runs = []
        for g, w in zip(logs, wins, strict=True):
            one, (g1,) = cast("tuple", declared_laws(sc, [g]))
            runs.append((one, [g1], [w]))
    else:
        runs = [(sc, list(logs), wins)]
    noise = list(opts.noise) if opts.noise is not None else None
    if noise is not None and len(noise) != len(logs):
        raise ValueError(f"PredictOptions.noise has {len(noise)} entries for {len(logs)} logs")
    fp: dict[str, dict[str, float | None]] = {}
    rmse: dict[str, dict[str, float]] = {}
    nrmse: dict[str, dict[str, float | None]] = {}
    traces: dict[str, dict[str, Any]] = {}
    diverged: dict[str, bool] = {}
    warnings: list[str] = []
    notes: list[str] = []
    it = iter(keys)
    first = 0  # the index of each run's first log
    for scn, group, gw in runs:
        fo = FitOptions(windows=gw, continuous=bool(opts.continuous))
        nz = None if noise is None else noise[first : first + len(group)]
        first += len(group)
        out = predict_scenario(scn, group, fo, channels=chans, initial=opts.initial, noise=nz)
        warnings += list(out.get("warnings", []))
        notes += list(out.get("notes", []))
        # predict_scenario keys logs by log_keys (with a window suffix): back to plain keys
        for g, v, tr, e, ne in zip(
            group,
            out["fit_percent"].values(),
            out["trajectories"].values(),
            out["rmse"].values(),
            out["nrmse"].values(),
            strict=True,
        ):
            k = next(it)
            rmse[k], nrmse[k] = dict(e), dict(ne)
            # a sensor channel the log holds but does not measure (constant: a rigid
            # arm's zero tip column; a rig log's tip the scenario has no sensor for) is
            # listed, with no figure
            listed = set(scn.sensors) | (set(RIG_OUTPUTS) if own_law else set())
            fp[k] = {
                **{
                    c: None
                    for c in sorted(listed)
                    if chans is None and c in getattr(g, "signals", {})
                },
                **dict(v),
            }
            t = np.asarray(tr["time"], float)
            traces[k] = {
                "time": t - t[0] if t.size else t,
                "measured": tr["measured"],
                "simulated": tr["simulated"],
            }
            sims = [np.asarray(x, float) for x in tr["simulated"].values()]
            diverged[k] = not all(np.all(np.isfinite(x)) for x in sims)
            runaway = (fp[k].get("motor_angle") or 0.0) < -100.0
            if own_law and (diverged[k] or runaway):
                from flexarm.identification.time_domain.logs import FitInputError

                c = g.controller
                raise FitInputError(
                    f"{g.where}: field 'controller': with K1={c.k1:g} K2={c.k2:g} "
                    f"K3={c.k3:g} K4={c.k4:g} the simulated loop on {sc.name} is unstable "
                    f"({'it diverged' if diverged[k] else 'it runs away: hub-angle fit '}"
                    f"{'' if diverged[k] else format(fp[k]['motor_angle'], '.0f') + ' %'}); "
                    "check the gains and their signs and units (V/rad, V/m, V*s/rad, V*s/m) "
                    "and the tip sensor's gain sign"
                )
            if own_law:
                traces[k]["display"] = {
                    c: RIG_DISPLAY[c] for c in tr["simulated"] if c in RIG_DISPLAY
                }

    pred = Prediction(
        sc.name,
        fp,
        traces,
        warnings=warnings,
        notes=list(dict.fromkeys(notes)),
        diverged=diverged,
        rmse=rmse,
        nrmse=nrmse,
    )
    warnings += [f"{k}: the simulated loop diverged" for k, bad in diverged.items() if bad]
    if own_law:
        pred.notes.append("each log ran with the law it declares (its logged gains)")
        for k, g in zip(keys, logs, strict=True):
            pred.notes += _gain_note(k, g)
    if opts.continuous:
        pred.notes.append(
            f"continuous: the {len(keys)} logs replayed as consecutive pieces "
            "of one run (controller and filter states carried)"
        )
    if opts.plots is not None:
        pred.plots = [str(p) for p in write_overlays(pred, opts.plots, opts.tag)]
    return pred
