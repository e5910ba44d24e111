"""The front door of the time-domain fit: :func:`fit` (``flexarm.fit``).

    fit(scenario, logs, free=None, options=None) -> FitResult

``scenario`` is a :class:`~flexarm.specs.scenario.Scenario` (or a TOML path / built-in name)
or a :class:`~.presets.Preset`. Without ``free`` the preset's default free list runs
(:func:`~.presets.for_scenario`: the scenario's ``[notes.fit]``, the registered preset of a
built-in, e.g. ``quanser-two-link``'s 15 parameters, or the joints' friction) and the result
says which (:attr:`~.result.FitResult.free_source`). ``options`` is a grouped
:class:`~.options.FitOptions`; its groups override the preset's
(:meth:`~.options.FitOptions.resolved`: only the fields a group changes from its defaults),
and the general engine reads the resolved groups itself. The old flat
:class:`~.options.ScenarioFitOptions` is still accepted, deprecated: converted by
:meth:`~.options.FitOptions.from_flat` with a ``DeprecationWarning``, and used whole (no
preset options under it, as before).

Engines: ``"scenario"`` — the general engine (multiple shooting from the logged state,
priors, HAC std; :func:`~.general.fit_scenario`); ``"servo_rig"`` — the rotary servo's
data-sheet pipeline (:func:`~.fit.fit`, its estimates, delay search, global stage and
continuation), called through its keyword interface with the preset's data sheet and
``options.servo_rig``; its result (:class:`~.report.FitResult`) comes as the one
:class:`~.result.FitResult` (:func:`~.report.as_fit_result`: the rig's own record under
``stages["servo_rig"]``, the rig's result as ``engine_result``), as for every preset.

Which stage each engine offers (the servo rig reads ``options.servo_rig`` and ``windows``;
a group it does not read is a ``ValueError`` naming it, not dropped silently):

=============================  ======================  ===========================
stage                          ``scenario``            ``servo_rig``
=============================  ======================  ===========================
global (differential evol.)    ``GlobalDE``            ``ServoRig.global_seconds``
smooth-then-quantised          ``Cost(quantise=True)`` always
multiple shooting              ``Shooting(segment)``   ``ServoRig.segment``
priors (eq. (2))               ``Priors``              ``ServoRig.priors``
sensor-delay search            ``DelaySearch``         ``ServoRig.delay_search``
=============================  ======================  ===========================
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from flexarm.identification.fit_quality import fit_quality
from flexarm.identification.time_domain.options import (
    FitOptions,
    ScenarioFitOptions,
    as_fit_options,
)
from flexarm.identification.time_domain.presets import Preset, for_scenario
from flexarm.identification.time_domain.result import FitResult, Prediction

__all__ = ["fit"]


def fit(
    scenario: Any,
    logs: Sequence[Any],
    free: Sequence[str] | None = None,
    options: Any = None,
    *,
    progress: Callable[[str], None] | None = None,
) -> FitResult:
    """Fit ``scenario``'s free parameters to ``logs`` (module docstring). Paths in ``logs``
    are read by :func:`flexarm.io.logformat.load_log` (exchange format)."""
    from flexarm.identification.time_domain import general
    from flexarm.io.logformat import load_logs
    from flexarm.specs import Scenario, load_scenario
    from flexarm.specs.paths import scenario_with

    if isinstance(scenario, Preset):
        preset = scenario
    else:
        sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
        preset = for_scenario(sc) if free is None else Preset(sc.name, sc, list(free))
    if preset.engine == "servo_rig":
        return _servo_rig(preset, logs, options, progress)
    logs = load_logs(logs)
    # the preset's options under the given groups (a deprecated flat record: whole)
    base = preset.options if free is None and not isinstance(options, ScenarioFitOptions) else None
    opts = as_fit_options(options, "flexarm.fit").resolved(base)
    source = "given" if free is not None else f"preset {preset.name}"
    free_list = list(free) if free is not None else list(preset.free)
    template, estimates = preset.scenario, None
    if free is None and preset.starts is not None:
        wins = list(opts.windows or [])
        wins += [None] * (len(logs) - len(wins))
        fitted = [g if w is None else g.window(*w) for g, w in zip(logs, wins, strict=False)]
        starts, estimates = preset.starts(template, fitted)
        if starts:
            template = scenario_with(template, starts)
            free_list += [p for p in starts if p not in free_list]
        if progress is not None:
            progress(f"start estimates from the logs: {starts or 'none'}")
    own = _declared_laws(template, logs)  # servo-rig logs: each with the law it ran
    if own is not None:
        lab_law, (template, logs) = template, own
    res = general.fit_scenario(
        template, logs, free_list, opts, progress=progress, predict=opts.predict, plots=opts.plots
    )
    if own is not None:  # the scenario written keeps its own [controller] (design's start)
        _keep_controller(res, lab_law)
        res.stages["declared_laws"] = (
            "each log ran with the law it declares (its logged gains), as validate runs it"
        )
    res.free_source = source
    if estimates is not None:
        res.stages["estimates"] = estimates
    # a poor fit said plainly (the one rule, every preset), with the fit's own bounds
    ds = opts.delay_search
    res.warnings += fit_quality(
        res,
        bounds=opts.priors.bounds,
        bound_factor=opts.priors.bound_factor,
        max_delay=getattr(ds, "max_delay", None),
        max_moves=getattr(ds, "max_moves", None),
    )
    if opts.bootstrap is not None:
        with_bootstrap(res, logs, opts, None, progress)
    return res


def _declared_laws(scenario, logs) -> tuple | None:
    """Servo-rig logs that each declare the law they ran, on a single-link scenario: the
    scenario reading each log's gains per sample and the logs carrying them
    (:func:`~.logs.declared_laws`), as :func:`~.predict.predict` runs them, so the fit's
    figures are validate's; None for any other logs (the scenario's own controller)."""
    from flexarm.identification.time_domain.logs import declared_laws

    if scenario.arm.kind != "single_link" or not logs:
        return None
    if not all(
        getattr(g, "controller", None) is not None and "reference" in getattr(g, "signals", {})
        for g in logs
    ):
        return None
    out = declared_laws(scenario, list(logs))
    if out is None:
        raise ValueError(
            "the logs declare laws that differ in more than their gains (their rate "
            "filter): fit the logs of one law together, or give the scenario's own "
            "controller to every log (--controller FILE.toml)"
        )
    return out


def _keep_controller(res: FitResult, lab: Any) -> None:
    """The fitted scenarios with ``lab``'s controllers in place of the declared laws'
    per-sample gains (which read the logs' gain channels)."""
    ctl = {"controller": lab.controller, "controllers": lab.controllers}
    res.scenario = res.scenario.model_copy(update=ctl)
    res.session_scenarios = [sc.model_copy(update=ctl) for sc in res.session_scenarios]


def with_bootstrap(res: FitResult, logs, opts: FitOptions, model, progress) -> FitResult:
    """``FitOptions.bootstrap`` after the fit: the result's ``std`` and ``correlation``
    become the parametric bootstrap's (:func:`~.bootstrap.bootstrap`), the HAC ones kept
    in ``stages["hac"]``, the spread in ``stages["bootstrap"]`` and which std the result
    carries in ``stages["std_source"]``."""
    import numpy as np

    from flexarm.identification.time_domain.bootstrap import bootstrap

    b = opts.bootstrap
    if b is None:
        return res
    b.check()
    if res.scenario is None:
        return res
    spread = bootstrap(
        res,
        logs,
        b.n,
        seed=b.seed,
        noise=b.noise,
        progress=progress,
        options=opts,
        model=model,
        refit=fit,
    )
    res.stages["hac"] = {
        "std": dict(res.std),
        "correlation": np.round(np.asarray(res.correlation, float), 4).tolist(),
    }
    res.stages["bootstrap"] = spread.to_dict()
    res.std = {p: spread.std.get(p, float("nan")) for p in res.std}
    res.correlation = spread.correlation
    res.stages["std_source"] = (
        f"parametric bootstrap: {spread.n_ok} of {spread.n} refits ({b.noise} noise, "
        + (
            "fed through the loop"
            if b.noise == "declared"
            else "added to the simulated measurements"
        )
        + "); the HAC std in stages['hac']"
    )
    if spread.failed:
        res.warnings.append(
            f"bootstrap: {len(spread.failed)} of {spread.n} refits failed "
            f"(first: {spread.failed[0]}); the std is the spread of the {spread.n_ok} others"
        )
    return res


def _servo_rig(preset: Preset, logs, options, progress):
    from flexarm.identification.time_domain.fit import fit as rig_fit
    from flexarm.identification.time_domain.logs import as_rig_log
    from flexarm.identification.time_domain.options import ServoRig
    from flexarm.identification.time_domain.report import as_fit_result

    opts = options if isinstance(options, FitOptions) else FitOptions()
    unread = [
        g
        for g in (
            "cost",
            "shooting",
            "local",
            "global_de",
            "priors",
            "delay_search",
            "subset_search",
        )
        if getattr(opts, g)
    ]
    if unread or opts.continuous:
        raise ValueError(
            f"FitOptions.{', '.join(unread) or 'continuous'}: the rotary servo preset's engine "
            "reads only FitOptions.servo_rig and windows (its global stage, delay search and "
            "continuation: options.ServoRig); multiple shooting, priors and the other groups "
            "belong to the scenario engine: fit a scenario (flexarm.fit(scenario, logs, ...))"
        )
    rig = opts.servo_rig or ServoRig()
    kw = {**preset.sheet, **rig.keywords()}
    logs = [as_rig_log(g) if isinstance(g, (str, Path)) else g for g in logs]
    whole = list(logs)
    if opts.windows is not None:
        logs = [g if w is None else g.window(*w) for g, w in zip(logs, opts.windows, strict=False)]
    rig.check()
    if rig.local == "general":
        return _servo_general(preset, whole, logs, opts, kw, progress)
    res = as_fit_result(rig_fit(logs, progress=progress, **kw), free_source=f"preset {preset.name}")
    if rig.segment is not None:  # multiple shooting: the rig's result holds the pieces
        owner = res.engine_result.settings["piece_owner"]  # the log of each piece
        res.segment_fit_percent = _pieces_fit_percent(res.engine_result, logs, owner)
        res.stages["segments"] = len(owner)
    if res.scenario is not None:
        # what the fit reports is what `flexarm validate` of its written scenario gives:
        # the one prediction of the fitted logs (windows) by the fitted scenario, each
        # log's start state estimated as the fit estimates it; the rig loop's own figures
        # (its jointly estimated starts) stay in stages["servo_rig"]["loop_fit_percent"]
        if progress:
            progress("predicting the fitted logs with the written scenario")
        # the whole logs with the fit's windows, as `flexarm validate --window` reads them;
        # several sessions: each log by its session's scenario (its friction and bias)
        sess = list(rig.sessions) if rig.sessions is not None else [0] * len(whole)
        res.session_scenarios = session_scenarios(res, max(sess) + 1)
        if max(sess) > 0:  # the result says which parameters are per session (#47)
            from flexarm.identification.time_domain.result import session_path

            own = sorted({session_path(p) for p in res.params if p.startswith("sessions[")})
            signs = getattr(res.engine_result.space, "session_signs", ()) or ()
            res.stages["sessions"] = {
                "of_log": sess,
                "per_session": own,
                "shared": [p for p in res.params if "sessions[" not in p and p not in own],
                "tip_gauge_signs": list(signs) or [1] * (max(sess) + 1),
            }
        pred = _predict_sessions(res.session_scenarios, whole, sess, opts.windows)
        res.stages.setdefault("servo_rig", {})["loop_fit_percent"] = res.fit_percent
        res.stages["prediction"] = {"initial": "estimate", "notes": pred.notes}
        res.fit_percent = res.engine_result.fit_percent = pred.fit_percent
        res.rmse, res.nrmse = pred.rmse, pred.nrmse
        res.prediction = pred
        # the rig loop's "is low" warnings spoke of its own figures: the reported ones now
        kept = [w for w in res.warnings if not w.endswith(" is low")]
        res.warnings = list(dict.fromkeys([*kept, *pred.warnings]))
        res.warnings += fit_quality(res)  # a poor fit said plainly (the one rule, every preset)
        res.engine_result.warnings = list(res.warnings)
    if opts.plots is not None and isinstance(res.prediction, Prediction):
        from flexarm.identification.time_domain.figures import write_overlays

        res.plots = [str(p) for p in write_overlays(res.prediction, opts.plots, "fit")]
    elif opts.plots is not None:  # the rig's fit figures (FitOptions.plots)
        res.plots = [str(p) for p in res.engine_result.plots(opts.plots)]
    if opts.bootstrap is not None:  # the refits: the preset again, its servo_rig options
        with_bootstrap(res, whole, opts, preset, progress)
    return res


def _servo_general(preset: Preset, whole, fitted, opts: FitOptions, kw: dict, progress):
    """``ServoRig(local="general")``: the servo pipeline's estimates and global stage
    (:func:`~.fit.fit` with one local evaluation and no polish) start the one general
    engine (:func:`fit` on the global stage's scenario, every log with its declared law):
    the pipeline's data-derived box as bounds (:func:`~.presets.servo_bounds`), one
    segment per fitted log (window) with its start state estimated (so the written
    scenario's ``[notes.validate] initial`` is ``"estimate"``), each log weighed by its own
    spread (``Cost(spread="log")``, the pipeline's weighting), the smooth-then-quantised
    continuation, the sensor-delay search from the global stage's delays up to the
    pipeline's largest, and the friction re-search (:class:`~.options.SubsetSearch`).
    Several sessions (``ServoRig.sessions``): the general engine's, friction and bias (and
    a gauge read the other way) per session, each started at the global stage's own
    (:func:`_start_sessions`). The pipeline's record goes to ``stages["servo_rig_start"]``."""
    from flexarm.identification.time_domain.fit import fit as rig_fit
    from flexarm.identification.time_domain.options import (
        Cost,
        DelaySearch,
        Local,
        Priors,
        Shooting,
        SubsetSearch,
    )
    from flexarm.identification.time_domain.presets import servo_bounds
    from flexarm.identification.time_domain.report import as_fit_result

    if progress:
        progress("the servo rig's estimates and global stage")
    start = as_fit_result(
        rig_fit(fitted, progress=progress, **{**kw, "local_nfev": 1, "polish_iter": 0}),
        free_source=f"preset {preset.name}",
    )
    space = start.engine_result.space
    bounds = servo_bounds(space, start.scenario)
    free = list(bounds)
    sessions = _start_sessions(start, kw.get("sessions"), bounds)  # may drop the gain's box
    flexible = any(d.name == "link_frequency" for d in space.defs)
    longest = max(float(g.time[-1] - g.time[0]) for g in fitted)
    dt = float(start.scenario.sampling.period)
    general = FitOptions(
        windows=opts.windows,
        shooting=Shooting(segment=longest + 2 * dt),
        cost=Cost(quantise=True, spread="log"),
        local=Local(max_nfev=100),
        priors=Priors(bounds=bounds),
        # the tip's delay where there is a link to read (a rigid arm's tip column is empty)
        delay_search=DelaySearch(
            channels=["motor_angle"] + (["tip_deflection"] if flexible else []),
            max_delay=int(space.max_delay),
        ),
        subset_search=SubsetSearch() if kw.get("friction", True) else None,
        sessions=sessions,
        plots=opts.plots,
        predict=opts.predict,
        bootstrap=opts.bootstrap,  # each refit: the general engine with these options
    )
    res = fit(start.scenario, whole, free, general, progress=progress)
    res.free_source = (
        f"preset {preset.name} (its estimates and global stage, then the general engine)"
    )
    er = start.engine_result
    res.stages["servo_rig_start"] = {
        "delays": dict(er.delays),
        "loop_fit_percent": er.fit_percent,
        "seconds": round(float(er.seconds), 2),
    }
    return res


def _start_sessions(start: FitResult, sess, bounds: dict):
    """The general engine's :class:`~.options.Sessions` of the servo route's sessions
    (None: one session): each later session started at the servo global stage's own values
    (``sessions[s].PATH`` of its result: friction, bias, and the gauge gain where the
    session reads the gauge the other way, which makes the gain per session too; its box
    then is the engine's default around each session's start, as one signed box cannot
    hold both signs; ``bounds`` is changed so)."""
    from flexarm.identification.time_domain.options import Sessions
    from flexarm.identification.time_domain.result import session_key

    if sess is None or max(sess) == 0:
        return None
    starts: dict[int, dict[str, float]] = {}
    for s_ in range(1, max(sess) + 1):
        own = {
            p: start.params[session_key(s_, p)]
            for p in bounds
            if session_key(s_, p) in start.params
        }
        if own:
            starts[s_] = own
    gain = "sensors.tip_deflection.gain"
    if any(gain in own for own in starts.values()):
        bounds.pop(gain, None)
    return Sessions(list(sess), starts=starts or None)


def session_scenarios(res: FitResult, n: int) -> list:
    """The fitted scenario of each of ``n`` sessions: session 0's is the result's; a later
    session's is it with that session's own values (``sessions[s].PATH`` in the result's
    params: the servo rig's per-session friction and bias)."""
    from flexarm.identification.time_domain.result import session_key
    from flexarm.specs.paths import scenario_with

    out = [res.scenario]
    paths = [p for p in res.params if not p.startswith("sessions[")]
    for s_ in range(1, n):
        own = {p: res.params[session_key(s_, p)] for p in paths if session_key(s_, p) in res.params}
        out.append(scenario_with(res.scenario, own) if own else res.scenario)
    if n > 1:
        out = [
            sc.model_copy(update={"name": f"{sc.name}-session{s_}" if s_ else sc.name})
            for s_, sc in enumerate(out)
        ]
    return out


def _predict_sessions(scenarios: list, logs: list, sess: list[int], windows):
    """The one prediction of each log by its session's scenario, merged in the logs'
    order (one prediction when there is one session)."""
    from flexarm.identification.time_domain.options import PredictOptions
    from flexarm.identification.time_domain.predict import predict

    wins = list(windows) if windows is not None else [None] * len(logs)
    if len(set(sess)) <= 1:
        return predict(scenarios[sess[0] if sess else 0], logs, PredictOptions(windows=wins))
    from flexarm.io.logs import log_keys

    keys = log_keys(logs)
    parts = {}
    for s_ in sorted(set(sess)):
        idx = [i for i, x in enumerate(sess) if x == s_]
        pr = predict(
            scenarios[s_], [logs[i] for i in idx], PredictOptions(windows=[wins[i] for i in idx])
        )
        for i, k in zip(idx, pr.fit_percent, strict=True):
            parts[i] = (pr, k)
    first = parts[0][0]
    merged = Prediction(
        first.scenario,
        {keys[i]: parts[i][0].fit_percent[parts[i][1]] for i in range(len(logs))},
        {keys[i]: parts[i][0].traces[parts[i][1]] for i in range(len(logs))},
        warnings=list(dict.fromkeys(w for p, _ in parts.values() for w in p.warnings)),
        notes=list(dict.fromkeys(n for p, _ in parts.values() for n in p.notes))
        + [f"session {s_}: its own friction and bias" for s_ in sorted(set(sess))],
        diverged={keys[i]: parts[i][0].diverged.get(parts[i][1], False) for i in range(len(logs))},
        rmse={keys[i]: parts[i][0].rmse[parts[i][1]] for i in range(len(logs))},
        nrmse={keys[i]: parts[i][0].nrmse[parts[i][1]] for i in range(len(logs))},
    )
    return merged


def _pieces_fit_percent(rig_res, whole, owner) -> dict[str, dict[str, float | None]]:
    """fit % per whole log and signal over its pieces' samples together (each piece
    simulated from its own start: the multiple-shooting fit, as the general engine's
    ``segment_fit_percent``)."""
    import numpy as np

    from flexarm.io.logs import log_keys
    from flexarm.metrics import fit_percent

    skip = rig_res.space.max_delay + int(rig_res.settings["computation_delay"]) + 1
    out: dict[str, dict[str, float | None]] = {}
    for i, key in enumerate(log_keys(whole)):
        rows = [k for k, o in enumerate(owner) if o == i]
        d: dict[str, float | None] = {}
        for c, name in enumerate(("motor_angle", "tip_deflection")):
            if name not in rig_res.logs[rows[0]].columns:
                continue
            # the samples each piece's cost compares (after its first ``skip``)
            y = [rig_res.logs[k].columns[name][skip:] for k in rows]
            sim = [
                np.asarray(rig_res.traj[c][k])[skip : skip + len(a)]
                for k, a in zip(rows, y, strict=True)
            ]
            v = fit_percent(np.concatenate(y), np.concatenate(sim))
            d[name] = round(v, 3) if np.isfinite(v) else None
        out[key] = d
    return out
