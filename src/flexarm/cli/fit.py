"""``flexarm fit`` and ``flexarm validate``: time-domain identification from lab logs and
the prediction of logs by a (fitted) scenario.

The JSON documents these commands write are the library's: ``fit --json`` is the one
:meth:`~flexarm.identification.time_domain.result.FitResult.to_dict` of every rig (the
servo rig's through :func:`~flexarm.identification.time_domain.report.as_fit_result`, an
interrupted fit's through :func:`~flexarm.identification.time_domain.report.
interrupted_result`), ``validate --json`` the prediction's dictionary.

Both commands parse, call the library and print: ``fit`` calls the one fit
(:func:`flexarm.fit`) on the scenario given first or on the rotary-servo preset built
from the data-sheet options (:func:`~flexarm.identification.time_domain.presets.servo_rig`);
``validate`` calls the one prediction (:func:`flexarm.validate`), and ``--refit friction``
the one fit of the joints' friction (:func:`flexarm.fit` with ``general.friction_paths``).
Logs are read by
:func:`flexarm.io.logformat.load_logs` and their declared laws checked by
:func:`~flexarm.identification.time_domain.controller_check.checked_logs`."""

from __future__ import annotations

import contextlib
import dataclasses
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, NoReturn

import typer
from rich.markup import escape
from rich.table import Table

from flexarm.cli import options as o
from flexarm.cli import parsing
from flexarm.cli.common import (
    check_file_option,
    command_line,
    console,
    distinct_outputs,
    enable_cache,
    err,
    fail,
    figure_folder,
    guarded_command,
    load,
    output_folder,
    progress,
    warn,
    working,
    write_report,
)

#: ``--controller`` of ``fit`` and ``validate``: a controller file, or the servo rig's law
ControllerOrFile = Annotated[
    str | None,
    typer.Option(
        "--controller",
        help="an existing FILE.toml: a controller file ([controller] or [[controllers]] tables "
        "as in a scenario) replacing the scenario's controllers for this run; any other "
        "value overrides the servo-rig logs' '# controller:' line, e.g. "
        "'state_feedback K1=6 K2=-3 K3=0.2 K4=0'",
    ),
]
Continuous = Annotated[
    bool,
    typer.Option(
        "--continuous",
        help="the logs, in order, are consecutive pieces of one run: each dynamic controller's "
        "state (and the digital filters') carried from log to log; not with --window",
    ),
]


def controller_option(controller: str | None):
    """``--controller``: the controller file it names (library
    :func:`flexarm.identification.time_domain.predict.controller_file`), or None when the
    value is the servo rig's text law (or absent)."""
    from flexarm.identification.time_domain.predict import controller_file
    from flexarm.specs import ScenarioError

    try:
        return controller_file(controller)
    except (ScenarioError, ValueError) as exc:
        fail(f"--controller: {exc}")


def with_controller_file(sc, cfile):
    """The scenario with its controllers replaced by ``cfile`` (``--controller FILE.toml``)."""
    from flexarm.specs import ScenarioError

    if cfile is None:
        return sc
    try:
        return sc.with_controllers(cfile)
    except (ScenarioError, ValueError) as exc:
        fail(str(exc))


def check_continuous(continuous: bool, window: str | None) -> None:
    if continuous and window:
        fail(
            f"--continuous runs whole logs as one run; --window {window} cuts each log: "
            "give one or the other"
        )


@guarded_command("logs", "log_format")
def fit(
    ctx: typer.Context,
    logs: Annotated[
        list[Path],
        typer.Argument(
            help="closed-loop CSV logs of one recording session; or SCENARIO LOG...: a "
            "scenario (TOML file or built-in name) as the model template, then its "
            "logs (the general fit: --free, --prior, --segment)"
        ),
    ],
    drive: o.Drive = "voltage",
    gear_ratio: o.GearRatio = 1.0,
    motor_constant: o.MotorConstant = None,
    armature_resistance: o.ArmatureResistance = None,
    link_length: o.LinkLength = None,
    gear_efficiency: o.GearEfficiency = 1.0,
    motor_efficiency: o.MotorEfficiency = 1.0,
    voltage_limit: o.VoltageLimit = None,
    computation_delay: o.ComputationDelay = None,
    controller: ControllerOrFile = None,
    continuous: Continuous = False,
    mode: Annotated[
        str, typer.Option(help="closed_loop, or open_loop (replay the logged voltage)")
    ] = "closed_loop",
    no_friction: Annotated[
        bool, typer.Option("--no-friction", help="fit without joint friction (for comparison)")
    ] = False,
    json_out: o.JsonOut = None,
    scenario_out: o.ScenarioOut = None,
    plots: o.Plots = None,
    seconds: Annotated[
        float | None,
        typer.Option(
            "--global-seconds",
            "--seconds",
            help="seconds of each log the global stage fits (at least the log's length: "
            "whole logs, better on stick-slip runs with few moves) [default: 5 for a "
            "flexible link whose hub-to-tip estimate is trusted, else whole logs]",
            show_default=False,
            callback=parsing.number(gt=0, example="5"),
        ),
    ] = None,
    compare_no_friction: Annotated[
        bool,
        typer.Option(
            "--compare-no-friction",
            help="also fit without joint friction and report both fits side by side",
        ),
    ] = False,
    column: o.Column = None,
    unit: o.Unit = None,
    sessions: Annotated[
        str | None,
        typer.Option(
            help="recording session of each log, e.g. 0,0,1: mechanics shared, friction "
            "(and a scenario's free bias / offset paths) per session; --scenario-out then "
            "writes one scenario per session"
        ),
    ] = None,
    tip_sign: Annotated[
        int | None, typer.Option(help="sign of the strain gauge, +1 or -1, if known")
    ] = None,
    encoder_counts: Annotated[
        int | None,
        typer.Option(
            help="hub encoder counts per revolution (default: detected from the steps)",
            callback=parsing.number(ge=2, le=2**40, example="4096"),
        ),
    ] = None,
    filter: Annotated[
        list[str] | None,
        typer.Option(help="known analog low-pass cutoff of a sensor, Hz: tip_deflection=50"),
    ] = None,
    max_jitter: o.MaxJitter = 1e-3,
    delay_search: Annotated[
        str,
        typer.Option(
            help="how the tip delay is chosen: neighbours, profile, or both (two starts, "
            "about twice the time: when it may be far off)"
        ),
    ] = "neighbours",
    local: Annotated[
        str,
        typer.Option(
            help="after the servo route's estimates and global stage: 'servo', its own "
            "local stage and friction polish; 'general', the one general engine (the "
            "servo's bounds, each log's start state estimated, the delay search and "
            "friction re-search; the result and printing of SCENARIO LOG...)",
        ),
    ] = "servo",
    polish_iter: Annotated[
        int,
        typer.Option(
            help="generations of the friction polish (20 with --delay-search both)",
            callback=parsing.number(ge=0, le=10_000),
        ),
    ] = 8,
    global_starts: Annotated[
        int | None,
        typer.Option(
            min=1,
            help="run the global stage from this many seeds (--seed, --seed + 1, ...) and "
            "keep the lowest cost, at that many times the time: where the fit warns that "
            "nothing ties the sensor delays down (default: 3 for several sessions whose "
            "delays nothing ties down, else 1)",
            callback=parsing.number(ge=1, le=1000),
        ),
    ] = None,
    seed: Annotated[
        int,
        typer.Option(help="seed of the global stage", callback=parsing.number(ge=0, le=2**32 - 1)),
    ] = 0,
    tip_after_hub: Annotated[
        bool,
        typer.Option(
            "--tip-after-hub/--any-delay-order",
            help="search the tip sensor's delay at or above the hub's (an encoder reads "
            "at once, a strain gauge's conditioning only adds lag); --any-delay-order "
            "searches both freely",
        ),
    ] = True,
    overwrite: o.Overwrite = False,
    log_format: o.LogFormats = None,
    use_regressed_law: o.UseRegressedLaw = False,
    window: o.Window = None,
    free: Annotated[
        list[str] | None,
        typer.Option(
            "--free",
            help="with SCENARIO: a parameter to fit, as a path into the scenario "
            "(repeat), e.g. 'arm.joints[*].friction.coulomb'; without it the "
            "scenario's preset free list runs (printed)",
        ),
    ] = None,
    prior: Annotated[
        list[str] | None,
        typer.Option(
            "--prior",
            help="with SCENARIO: PATH=REL_STD, a data-sheet prior (the scenario's "
            "value, ± REL_STD relative), e.g. "
            "'arm.joints[0].drive.torque_constant=0.3'",
        ),
    ] = None,
    session_start: Annotated[
        list[str] | None,
        typer.Option(
            "--session-start",
            help="with SCENARIO and --sessions: S:PATH=VALUE, where a later session's own "
            "value of a per-session path starts (repeat), e.g. "
            "'1:sensors.tip_deflection.gain=0.655' for a gauge read with the other sign",
        ),
    ] = None,
    bound: Annotated[
        list[str] | None,
        typer.Option(
            "--bound",
            help="with SCENARIO: PATH=LO:HI, a free parameter's range in SI (repeat); a "
            "signed one (a bias, an offset, one starting at 0) is fitted in linear space "
            "and may change sign, e.g. 'arm.joints[0].friction.bias=-0.5:0.5'",
        ),
    ] = None,
    segment: Annotated[
        float | None,
        typer.Option(
            "--segment",
            help="with SCENARIO: multiple-shooting segment length, s",
            callback=parsing.number(gt=0, example="0.5"),
        ),
    ] = None,
    channel: o.Channels = None,
    max_nfev: Annotated[
        int | None,
        typer.Option(
            "--max-nfev",
            help="with SCENARIO: least-squares budget (default: the preset's, else 30)",
            callback=parsing.number(ge=1, le=10_000_000),
        ),
    ] = None,
    validate_window: Annotated[
        str | None,
        typer.Option(
            "--validate-window",
            help="then predict this held-out part of every log (START:STOP, s; each part's "
            "initial state estimated from its own data) and report its fit %",
        ),
    ] = None,
    report: o.Report = None,
    bootstrap: Annotated[
        int | None,
        typer.Option(
            "--bootstrap",
            help="then refit N replicates simulated by the fitted model with noise like the "
            "fit's residuals: the reported std and correlation are their spread (the HAC std "
            "kept in --json's stages.hac); N=20 takes about 20 refits' time",
            callback=parsing.number(ge=2, le=10_000),
        ),
    ] = None,
) -> None:
    """Fit a physical model with joint friction to closed-loop logs (time domain).

    With a scenario first (``flexarm fit SCENARIO LOG... --free PATH ...``): the general fit
    of any arm the scenario describes (identification.time_domain.fit_scenario)."""
    enable_cache()
    from flexarm.specs.scenario import names_a_scenario

    # the model the logs are fitted to: a scenario given first, else the rotary servo's
    # preset built from the data-sheet options; either way the one fit (flexarm.fit)
    cfile = controller_option(controller)
    check_continuous(continuous, window)
    if logs and names_a_scenario(str(logs[0])):
        _fit_scenario_cli(
            str(logs[0]),
            logs[1:],
            log_format,
            free,
            prior,
            bound,
            segment,
            channel,
            window,
            max_nfev,
            json_out,
            scenario_out,
            plots,
            overwrite,
            report,
            ctx,
            cfile=cfile,
            continuous=continuous,
            bootstrap=bootstrap,
            sessions=sessions,
            session_start=session_start,
        )
        return
    if cfile is not None or continuous:
        fail(
            "--controller FILE.toml and --continuous belong to the general fit: give the "
            "scenario first, flexarm fit SCENARIO LOG... --controller FILE.toml"
        )
    if free or prior or bound or segment is not None or channel or session_start:
        fail(
            "--free, --prior, --bound, --segment, --channel and --session-start belong to "
            "the general fit: give the scenario first, flexarm fit SCENARIO LOG... --free PATH"
        )
    if log_format and len(log_format) > 1:
        fail("--log-format is given once for the bench fit (every log has one format)")
    fmt_file = Path(log_format[0]) if log_format else None
    from flexarm.errors import FitInterrupted
    from flexarm.identification.time_domain import FitInputError, engine, presets
    from flexarm.identification.time_domain.options import (
        Bootstrap,
        FitOptions,
        PredictOptions,
        ServoRig,
    )
    from flexarm.identification.time_domain.predict import predict
    from flexarm.identification.time_domain.report import fit_extras
    from flexarm.io.write import write_each, write_json

    check_file_option("--json", json_out, overwrite)
    check_file_option("--scenario-out", scenario_out, overwrite, "arm.toml")
    check_file_option("--report", report, overwrite, "fit.html")
    distinct_outputs(("--json", json_out), ("--scenario-out", scenario_out), ("--report", report))
    output_folder("--plots", plots, overwrite)
    if tip_sign not in (None, 1, -1):
        fail(f"--tip-sign {tip_sign}: expected +1 or -1 (or leave it out to fit it)")

    def check_sheet() -> None:
        """The data sheet, every missing value named by its option, once the logs are read
        and before any work on them (the declared law's check, the fit; #46)."""
        sheet = [("--motor-constant", motor_constant, "K_m, V*s/rad or N*m/A")]
        if drive == "voltage":
            sheet.append(("--armature-resistance", armature_resistance, "R, ohm"))
        sheet.append(("--link-length", link_length, "m; a rigid arm's length too"))
        bad = [f"{opt} ({what})" for opt, v, what in sheet if v is None or not v > 0]
        if not gear_ratio > 0:
            bad.append(f"--gear-ratio > 0 (got {gear_ratio:g})")
        if bad:
            fail(
                "the rotary servo fit (LOG... without a scenario) needs the rig's data sheet: "
                f"give {', '.join(bad)}; or give a scenario first (flexarm fit SCENARIO LOG...)"
            )

    preset = presets.servo_rig(
        presets.DataSheet(
            drive=drive,
            gear_ratio=gear_ratio,
            motor_constant=motor_constant,
            armature_resistance=armature_resistance,
            link_length=link_length,
            gear_efficiency=gear_efficiency,
            motor_efficiency=motor_efficiency,
            voltage_limit=voltage_limit,
        )
    )
    rig = ServoRig(
        mode=mode,
        friction=not no_friction,
        global_seconds="auto" if seconds is None else seconds,
        delay_search=delay_search,
        polish_iter=polish_iter,
        local=local,
        global_starts="auto" if global_starts is None else global_starts,
        tip_after_hub=tip_after_hub,
        seed=seed,
        sessions=parsing.int_list(sessions, "--sessions"),
        tip_sign=tip_sign,
        encoder_counts=encoder_counts,
        filters=parsing.filters(filter),
        computation_delay=computation_delay,
    )
    res = res0 = held = None
    win, vwin = (
        parsing.window(window, "--window"),
        parsing.window(validate_window, "--validate-window"),
    )
    try:
        full = bench_logs(
            logs,
            column,
            unit,
            controller,
            max_jitter,
            log_format,
            use_regressed_law,
            rig=True,
            before_check=check_sheet,
        )
        opts = FitOptions(
            servo_rig=rig,
            windows=[win] * len(full) if win else None,
            bootstrap=Bootstrap(n=bootstrap) if bootstrap else None,
        )
        with working("fitting") as status:
            one = engine.fit(preset, full, options=opts, progress=lambda m: progress(status, m))
            # the servo pipeline's own result, or the one FitResult (--local general)
            res = one.engine_result if local == "servo" else one
            if compare_no_friction and not no_friction:
                status.update("fitting again without joint friction")
                no_fr = dataclasses.replace(rig, friction=False)
                res0 = engine.fit(
                    preset, full, options=dataclasses.replace(opts, servo_rig=no_fr, bootstrap=None)
                )
                res0 = res0.engine_result if local == "servo" else res0
            if vwin:
                status.update("predicting the held-out windows")
                held = predict(one, full, PredictOptions(windows=[vwin] * len(full)))
    except (FitInputError, ValueError) as exc:
        fail(str(exc))
    except FitInterrupted as exc:
        _fit_interrupted(json_out, overwrite, res, exc.result)
    except KeyboardInterrupt:
        _fit_interrupted(json_out, overwrite, res, None)
    if local == "servo":
        console.print(escape(one.engine_result.summary()))
    else:
        console.print(f"free parameters ({len(one.free)}): {one.free_source}", highlight=False)
        _print_general(one)
        _fit_table(one.fit_percent, "the fitted logs by the written scenario", one.rmse)
    for w in one.warnings:  # the one result's (the fit's findings) the rig's summary lacks
        if w not in res.warnings:
            console.print(f"[yellow]warning:[/yellow] {escape(w)}")
    if "bootstrap" in one.stages:  # the rig's summary above gives its HAC std
        _print_bootstrap(one)
    _print_bench_tables(res, res0, held, validate_window)
    one.extras.update(
        fit_extras(without_friction=res0, window=win, held_out=held, held_window=vwin)
    )
    write_each(
        *([lambda: write_json(json_out, one.to_dict(), overwrite=overwrite)] if json_out else []),
        *([lambda: one.write_scenario(scenario_out, overwrite=overwrite)] if scenario_out else []),
    )
    if scenario_out is not None:
        more = one.session_paths(scenario_out)[1:]
        if more:  # several sessions: one scenario each (validate a run with its session's)
            console.print(
                f"scenarios per session: {scenario_out} (session 0), "
                + ", ".join(f"{q} (session {k})" for k, q in enumerate(more, 1)),
                highlight=False,
            )
    with figure_folder(plots, report) as folder:
        if folder is not None:
            _bench_figures(
                ctx,
                folder,
                one,
                res0,
                held,
                validate_window,
                report,
                overwrite,
                [*logs, *([fmt_file] if fmt_file else [])],
            )


def _print_bench_tables(res, res0, held, validate_window: str | None) -> None:
    """The bench fit's tables: with and without friction, the held-out windows."""
    if res0 is not None:
        t = Table("log", "signal", "fit % with friction", "fit % without")
        for name, d in res.fit_percent.items():
            for sig, v in d.items():
                v0 = res0.fit_percent.get(name, {}).get(sig)
                t.add_row(
                    name,
                    sig,
                    f"{v:.1f}" if v is not None else "-",
                    f"{v0:.1f}" if v0 is not None else "-",
                )
        console.print(t)
    if held is not None:
        t = Table(
            "held-out log " + (validate_window or ""), "motor_angle fit %", "tip_deflection fit %"
        )
        for name, d in held["fit_percent"].items():
            t.add_row(
                name,
                *(
                    f"{d[k]:.1f}" if d.get(k) is not None else "-"
                    for k in ("motor_angle", "tip_deflection")
                ),
            )
        console.print(t)


def _bench_figures(
    ctx, folder: Path, one, res0, held, validate_window, report, overwrite, inputs: list
) -> None:
    """The bench fit's overlay figures into ``folder`` (``one``'s prediction of the fitted
    logs and ``held``, the held-out windows', both by the written scenario), and the HTML
    report from them (--report)."""
    from flexarm.identification.time_domain.predict import write_overlays
    from flexarm.identification.time_domain.report import figure_names
    from flexarm.identification.time_domain.result import Prediction

    figs = []
    for pred, tag in ((one.prediction, "fit"), (held, "held-out")):
        if isinstance(pred, dict) and pred.get("trajectories"):  # the general engine's record
            pred = Prediction(tag, pred["fit_percent"], pred["trajectories"])
        if isinstance(pred, Prediction):
            names = figure_names(list(pred.traces), tag)
            figs += write_overlays(pred, folder, tag, names=names)
    if report is not None:
        from flexarm.analysis.html_report import fit_report

        extra = {}
        if held is not None:
            extra[f"Fit % of the held-out windows {validate_window} s"] = held["fit_percent"]
        if res0 is not None:
            extra["Fit % of the fit without joint friction"] = res0.fit_percent
        write_report(
            fit_report(
                one.engine_result if one.stages.get("servo_rig") else one,
                figures=figs,
                command=command_line(ctx),
                inputs=inputs,
                extra_fit_percent=extra,
            ),
            report,
            overwrite,
        )


@guarded_command("scenario", "logs", "log_format")
def validate(
    ctx: typer.Context,
    scenario: Annotated[str, typer.Argument(help="fitted scenario TOML")],
    logs: Annotated[list[Path], typer.Argument(help="CSV logs to replay")],
    json_out: o.JsonOut = None,
    plots: o.Plots = None,
    controller: ControllerOrFile = None,
    continuous: Continuous = False,
    column: o.Column = None,
    unit: o.Unit = None,
    max_jitter: o.MaxJitter = 1e-3,
    overwrite: o.Overwrite = False,
    log_format: o.LogFormats = None,
    use_regressed_law: o.UseRegressedLaw = False,
    window: o.Window = None,
    refit: Annotated[
        str | None,
        typer.Option(
            "--refit",
            help="'friction': re-estimate only the joints' friction on "
            "--refit-window of the first log, then validate with "
            "everything else fixed (reports both)",
        ),
    ] = None,
    refit_window: Annotated[
        str,
        typer.Option(
            "--refit-window", help="the part of the first log the refit uses, START:STOP in s"
        ),
    ] = "0:5",
    channel: o.Channels = None,
    report: o.Report = None,
    initial: Annotated[
        str | None,
        typer.Option(
            "--initial",
            help="where each log (window) starts: 'estimate' (the logged state refined by "
            "least squares on the log), 'log' (as read off the log), 'rest' (the logged "
            "positions, every rate zero); default: as the fit that wrote the scenario did "
            "([notes.validate] initial; else estimate)",
        ),
    ] = None,
) -> None:
    """Replay logs on a scenario and report fit % = 100 (1 − ‖y − ŷ‖/‖y − mean y‖).

    The one prediction (flexarm.validate): any arm, each log with its own reference and
    controller (servo-rig logs: the law each declares), from its start state estimated as
    the fit estimates it (--initial); a fit's written scenario gives the fit's figures."""
    enable_cache()
    from flexarm.identification import fit as one_fit
    from flexarm.identification.time_domain.general import friction_paths
    from flexarm.identification.time_domain.options import Cost, FitOptions, PredictOptions
    from flexarm.identification.time_domain.predict import predict
    from flexarm.io.logs import LogError
    from flexarm.io.write import write_json

    cfile = controller_option(controller)
    check_continuous(continuous, window)
    sc = with_controller_file(load(scenario), cfile)
    check_file_option("--json", json_out, overwrite)
    check_file_option("--report", report, overwrite, "validate.html")
    distinct_outputs(("--json", json_out), ("--report", report))
    output_folder("--plots", plots, overwrite)
    if refit not in (None, "friction"):
        fail(
            f"--refit {refit!r}: only 'friction' (the joints' Coulomb, breakaway and "
            "viscous friction) can be re-estimated"
        )
    if initial not in (None, "estimate", "log", "rest"):
        fail(f"--initial {initial!r}: one of estimate, log, rest")
    win = parsing.window(window, "--window")
    rwin = parsing.window(refit_window, "--refit-window")
    ch = parsing.channels(channel)
    out: dict = {}  # the prediction's to_dict(), the refit's entry (FitResult.refit_entry)
    figures = contextlib.ExitStack()
    folder = figures.enter_context(figure_folder(plots, report))
    figs: list = []
    try:
        glogs = bench_logs(
            logs,
            column,
            unit,
            None if cfile is not None else controller,
            max_jitter,
            log_format,
            use_regressed_law,
        )
        popts = PredictOptions(
            channels=list(ch) if ch else None,
            windows=[win] * len(glogs) if win else None,
            continuous=continuous,
            controller=cfile,
            plots=folder,
            tag="validate",
            initial=initial,
        )
        with working("predicting") as status, _state_warnings_quiet():
            before = predict(sc, glogs, popts)
            out = before.to_dict()
            figs += before.plots
            if refit:
                status.update("re-estimating the joints' friction")
                res = one_fit(
                    sc,
                    [glogs[0]],
                    friction_paths(sc),
                    FitOptions(cost=Cost(channels=ch), windows=[rwin], predict=False),
                )
                after = predict(res.scenario, glogs, dataclasses.replace(popts, tag="refit"))
                figs += after.plots
                out["refit"] = res.refit_entry(res.free, rwin, logs[0], after)
    except (LogError, ValueError) as exc:
        figures.close()
        fail(str(exc))
    if plots is None:  # the figures went to a report's temporary folder
        out["plots"] = []
    _print_warnings(out["warnings"])
    for note in out.get("notes", []):
        console.print(escape(note), highlight=False)
    _fit_table(out["fit_percent"], "scenario as given", out.get("rmse"), _linear(sc))
    if refit:
        t = Table("friction", "scenario", "refitted", "std")
        for p in out["refit"]["params"]:
            t.add_row(
                p,
                f"{out['refit']['template'][p]:.4g}",
                f"{out['refit']['params'][p]:.4g}",
                f"{out['refit']['std'][p]:.3g}",
            )
        console.print(t)
        _fit_table(out["refit"]["fit_percent"], f"friction refitted on {refit_window} s")
    if json_out is not None:
        write_json(json_out, out, overwrite=overwrite)
    with figures:
        if report is not None:
            from flexarm.analysis.html_report import validate_report

            write_report(
                validate_report(
                    out,
                    scenario=scenario,
                    figures=figs,
                    command=command_line(ctx),
                    inputs=[scenario, *logs, *(log_format or [])],
                ),
                report,
                overwrite,
            )


def bench_logs(
    paths: list[Path],
    column,
    unit,
    controller,
    max_jitter: float,
    log_format=None,
    use_regressed: bool = False,
    *,
    rig: bool = False,
    before_check: Callable[[], None] | None = None,
):
    """The logs read with their --log-format (once for all, once per log, or
    PATTERN=FILE; :func:`flexarm.io.logformat.load_logs`; with ``rig``, as servo-rig
    logs: :func:`~flexarm.identification.time_domain.logs.load_rig_logs`), the --column /
    --unit mappings (SI inside), the --controller text law and --max-jitter; each declared
    law is checked against its log's command and replaced by the regressed one with
    --use-regressed-law (:func:`~flexarm.identification.time_domain.controller_check.
    checked_logs`); the checks are printed. ``before_check``: called once the logs are
    read, before the checks (the options' own check, e.g. the fit's data sheet)."""
    from flexarm.identification.time_domain.controller_check import checked_logs
    from flexarm.identification.time_domain.logs import load_rig_logs
    from flexarm.io.logformat import load_logs

    if not (max_jitter > 0):
        fail(f"--max-jitter {max_jitter}: must be > 0 (a relative deviation, e.g. 0.05)")
    if not paths:
        fail("no logs given: give one or more log files")
    cols, units = parsing.pairs(column, "column") or None, parsing.pairs(unit, "unit") or None
    load = load_rig_logs if rig else load_logs
    logs = load(
        paths, log_format, columns=cols, units=units, controller=controller, max_jitter=max_jitter
    )
    for lg in logs:
        slow = slow_clock(lg)
        if slow:
            warn(slow)
    if before_check is not None:
        before_check()
    logs, checks = checked_logs(logs, use_regressed=use_regressed)
    for chk in checks:
        console.print(escape(chk.summary()), highlight=False)
    return logs


#: the median time step (s) from which a closed-loop log's clock is suspect (a 2 Hz loop)
SLOW_STEP_S = 0.5


def slow_clock(log) -> str | None:
    """A warning where a log's median time step (after its units) is SLOW_STEP_S or more:
    a closed loop sampled at 2 Hz or slower is more likely a clock in ms read as s (the lab
    logger's headers say "(s)" over a ms column), which later shows as a law that disagrees
    with the logged command (#46); None otherwise."""
    import numpy as np

    t = None if log.time is None else np.asarray(log.time, float)
    if t is None or t.size < 3:
        return None
    step = float(np.median(np.diff(t)))
    if not step >= SLOW_STEP_S:
        return None
    return (
        f"{log.path}: the time column steps by {step:g} s (median), a {1 / step:.3g} Hz loop; "
        "if the logger writes ms (its header may say s), give --unit time=ms or a log "
        'format with [units] time = "ms"'
    )


def _fit_scenario_cli(
    scenario: str,
    logs: list[Path],
    log_format,
    free,
    prior,
    bound,
    segment,
    channel,
    window,
    max_nfev,
    json_out,
    scenario_out,
    plots,
    overwrite,
    report=None,
    ctx=None,
    *,
    cfile=None,
    continuous: bool = False,
    bootstrap: int | None = None,
    sessions: str | None = None,
    session_start: list[str] | None = None,
) -> None:
    from flexarm.identification.time_domain.engine import fit as fit_engine
    from flexarm.identification.time_domain.options import (
        Bootstrap,
        Cost,
        FitOptions,
        Local,
        Priors,
        Sessions,
        Shooting,
    )
    from flexarm.io.logformat import load_logs
    from flexarm.io.logs import LogError
    from flexarm.io.write import write_each, write_json

    check_file_option("--json", json_out, overwrite)
    check_file_option("--scenario-out", scenario_out, overwrite, "arm.toml")
    check_file_option("--report", report, overwrite, "fit.html")
    distinct_outputs(("--json", json_out), ("--scenario-out", scenario_out), ("--report", report))
    output_folder("--plots", plots, overwrite)
    win = parsing.window(window, "--window")
    of_log = parsing.int_list(sessions, "--sessions")
    starts = parsing.session_starts(session_start)
    if starts and not of_log:
        fail("--session-start needs --sessions (each log's session, e.g. 0,0,1,1)")
    chans, priors = parsing.channels(channel), parsing.priors(prior)
    bounds = _bounds(bound)
    sc = with_controller_file(load(scenario), cfile)
    figures = contextlib.ExitStack()
    folder = figures.enter_context(figure_folder(plots, report))
    try:
        if not logs:
            fail("no logs given: flexarm fit SCENARIO LOG... (one or more log files)")
        glogs = load_logs(logs, log_format)
        if cfile is not None:  # the given controller runs every log, not their declared laws
            glogs = [dataclasses.replace(g, controller=None, gains=None) for g in glogs]
        # the options given; the rest (and, without --free, the free list) are the preset's
        opts = FitOptions(
            cost=Cost(channels=chans) if chans else None,
            shooting=Shooting(segment=segment) if segment is not None else None,
            local=Local(max_nfev=max_nfev) if max_nfev is not None else None,
            priors=Priors(priors=priors, bounds=bounds) if priors or bounds else None,
            windows=[win] * len(glogs) if win else None,
            plots=folder,
            continuous=continuous,
            bootstrap=Bootstrap(n=bootstrap) if bootstrap else None,
            sessions=Sessions(of_log, starts=starts or None) if of_log else None,
        )
        with working("fitting") as status, _state_warnings_quiet():
            # the one FitResult of every rig (a scenario here: the general engine), with its
            # whole-log prediction and that prediction's figures (FitOptions.plots)
            res = fit_engine(sc, glogs, free or None, opts, progress=lambda m: progress(status, m))
            console.print(f"free parameters ({len(res.free)}): {res.free_source}", highlight=False)
    except (LogError, ValueError) as exc:
        figures.close()
        fail(str(exc))
    _print_general(res)
    _fit_table(res.fit_percent, "whole-log prediction", res.rmse, _linear(sc))
    figs = list(res.plots)
    if plots is None:  # the figures went to a report's temporary folder: not in --json
        res.plots = []
    write_each(
        *([lambda: write_json(json_out, res.to_dict(), overwrite=overwrite)] if json_out else []),
        *([lambda: res.write_scenario(scenario_out, overwrite=overwrite)] if scenario_out else []),
    )
    if scenario_out is not None and len(res.session_paths(scenario_out)) > 1:
        more = res.session_paths(scenario_out)[1:]
        console.print(
            f"scenarios per session: {scenario_out} (session 0), "
            + ", ".join(f"{q} (session {k})" for k, q in enumerate(more, 1)),
            highlight=False,
        )
    with figures:
        if report is not None:
            from flexarm.analysis.html_report import fit_report

            assert ctx is not None  # the command passes its context
            write_report(
                fit_report(
                    res,
                    figures=figs,
                    command=command_line(ctx),
                    inputs=[scenario, *logs, *(log_format or [])],
                    fit_percent=res.fit_percent,
                ),
                report,
                overwrite,
            )


def _print_general(res) -> None:
    """A general-engine fit's parameters (template, fitted, std), message, warnings and the
    prediction's warnings and notes."""
    boot = "bootstrap" in res.stages
    t = Table("parameter", "template", "fitted", "std (bootstrap)" if boot else "std")
    for p in res.free:
        t.add_row(p, f"{res.template[p]:.5g}", f"{res.params[p]:.5g}", f"{res.std[p]:.3g}")
    console.print(t)
    if boot:
        console.print(escape(res.stages["std_source"]), highlight=False)
    console.print(escape(res.message))
    for w in res.warnings:
        console.print(f"[yellow]warning:[/yellow] {escape(w)}")
    _print_warnings(res.prediction.get("warnings", []))
    for note in dict.fromkeys(
        [*res.stages.get("computed_channels", []), *res.prediction.get("notes", [])]
    ):
        console.print(escape(note), highlight=False)


def _print_bootstrap(res) -> None:
    t = Table("parameter", "fitted", "std (bootstrap)", "std (HAC)")
    hac = res.stages["hac"]["std"]
    for p in res.free:
        t.add_row(p, f"{res.params[p]:.5g}", f"{res.std[p]:.3g}", f"{hac.get(p, float('nan')):.3g}")
    console.print(t)
    console.print(escape(res.stages["std_source"]), highlight=False)


def _bounds(items: list[str] | None) -> dict[str, tuple[float, float]]:
    """``--bound PATH=LO:HI`` (repeated) → {path: (lo, hi)} in SI, finite, lo < hi."""
    import math

    out: dict[str, tuple[float, float]] = {}
    for x in items or []:
        path, _, rng = x.rpartition("=")
        lo, _, hi = rng.partition(":")
        try:
            a, b = float(lo), float(hi)
        except ValueError:
            a = b = float("nan")
        if not path.strip() or not (math.isfinite(a) and math.isfinite(b) and a < b):
            fail(
                f"--bound {x!r}: expected PATH=LO:HI with finite LO < HI in SI, e.g. "
                "'arm.joints[0].friction.bias=-0.5:0.5'"
            )
        out[path.strip()] = (a, b)
    return out


def _linear(sc) -> dict[str, str]:
    """A linear axis's channel units (its position is ``motor_angle``, in m)."""
    if getattr(sc, "prismatic", False):
        return {"motor_angle": "m", "motor_velocity": "m/s", "reference": "m"}
    return {}


def _fit_table(fp: dict, title: str, rmse: dict | None = None, units=None) -> None:
    """fit % per log and signal to 3 decimals (99.997 and 99.991 are different fits); given
    the RMSE, one row per log and signal with the RMSE in the signal's SI unit (3
    significant digits)."""
    from flexarm.io.logs import signal_unit

    names = sorted({k for d in fp.values() for k in d})
    if not rmse:
        t = Table(f"fit % ({title})", *names)
        for log, d in fp.items():
            t.add_row(str(log), *(f"{d[k]:.3f}" if d.get(k) is not None else "-" for k in names))
        console.print(t)
        return
    t = Table(f"prediction ({title})", "signal", "fit %", "RMSE", "unit")
    for log, d in fp.items():
        for k in names:
            if k not in d:
                continue
            e = (rmse.get(log) or {}).get(k)
            t.add_row(
                f"{log}",
                k,
                f"{d[k]:.3f}" if d[k] is not None else "-",
                f"{e:.3g}" if e is not None else "-",
                (units or {}).get(k) or signal_unit(k) or "SI",
            )
    console.print(t)


@contextlib.contextmanager
def _state_warnings_quiet():
    """The controllers' assumed-start warnings (ControllerStateWarning) are returned in the
    results and printed once by :func:`_print_warnings`, not also as Python warnings."""
    import warnings

    from flexarm.sim.filters import ControllerStateWarning

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ControllerStateWarning)
        yield


def _print_warnings(msgs) -> None:
    for w in msgs:
        err.print(f"[yellow]warning:[/yellow] {escape(w)}", highlight=False, soft_wrap=True)


def _fit_interrupted(json_out: Path | None, overwrite: bool, res, best) -> NoReturn:
    """Ctrl-C during ``fit``: write the best result so far to --json (atomically), marked
    ``"interrupted": true, "status": "interrupted"``, say so in one line, exit 130 (the
    shell's code for SIGINT).  ``res``: the friction fit if it had finished (the
    interrupted one was then the --compare-no-friction fit), ``best``: the interrupted
    fit's best result (``None`` if none)."""
    from flexarm.identification.time_domain.report import interrupted_result
    from flexarm.io.write import write_json

    d = interrupted_result(res, best).to_dict()
    if json_out is None:
        err.print("[yellow]fit interrupted[/]: nothing written (no --json given)")
    else:
        write_json(json_out, d, overwrite=overwrite)
        what = "best result so far" if (res is not None or best is not None) else "no result"
        err.print(
            f"[yellow]fit interrupted[/]: {what} written to {escape(str(json_out))}, "
            'marked "interrupted": true',
            highlight=False,
        )
    raise typer.Exit(130)
