"""``flexarm fit`` and ``flexarm validate``: time-domain identification from lab logs and
the prediction of logs by a (fitted) scenario.

The JSON documents these commands write are the library's: ``fit --json`` is the one
:meth:`~flexarm.identification.time_domain.result.FitResult.to_dict` of every rig (the
servo rig's through :func:`~flexarm.identification.time_domain.report.as_fit_result`, an
interrupted fit's through :func:`~flexarm.identification.time_domain.report.
interrupted_result`), ``validate --json`` the prediction's dictionary."""

from __future__ import annotations

import contextlib
import dataclasses
from pathlib import Path
from typing import Annotated, Any, NoReturn

import typer
from rich.markup import escape
from rich.table import Table

from flexarm.cli import options as o
from flexarm.cli import parsing
from flexarm.cli.common import (
    check_dir_option,
    check_file_option,
    command_line,
    console,
    enable_cache,
    err,
    fail,
    figure_folder,
    guarded_command,
    load,
    progress,
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
    seconds: Annotated[float, typer.Option(help="time budget of the global stage, s")] = 5.0,
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
            help="recording session of each log, e.g. 0,0,1: mechanics shared, friction per session"
        ),
    ] = None,
    tip_sign: Annotated[
        int | None, typer.Option(help="sign of the strain gauge, +1 or -1, if known")
    ] = None,
    encoder_counts: Annotated[
        int | None,
        typer.Option(help="hub encoder counts per revolution (default: detected from the steps)"),
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
    polish_iter: Annotated[
        int, typer.Option(help="generations of the friction polish (20 with --delay-search both)")
    ] = 8,
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
    segment: Annotated[
        float | None,
        typer.Option("--segment", help="with SCENARIO: multiple-shooting segment length, s"),
    ] = None,
    channel: o.Channels = None,
    max_nfev: Annotated[
        int | None,
        typer.Option(
            "--max-nfev",
            help="with SCENARIO: least-squares budget (default: the preset's, else 30)",
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
) -> None:
    """Fit a physical model with joint friction to closed-loop logs (time domain).

    With a scenario first (``flexarm fit SCENARIO LOG... --free PATH ...``): the general fit
    of any arm the scenario describes (identification.time_domain.fit_scenario)."""
    enable_cache()
    from flexarm.specs.scenario import names_a_scenario

    # DECISION (issue #23 item 6: moves to the library): which fit runs. A scenario first
    # takes the general fit (fit_scenario), else the servo-rig data-sheet fit.
    cfile = controller_option(controller)
    check_continuous(continuous, window)
    if logs and names_a_scenario(str(logs[0])):
        _fit_scenario_cli(
            str(logs[0]),
            logs[1:],
            log_format,
            free,
            prior,
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
        )
        return
    if cfile is not None or continuous:
        fail(
            "--controller FILE.toml and --continuous belong to the general fit: give the "
            "scenario first, flexarm fit SCENARIO LOG... --controller FILE.toml"
        )
    if free or prior or segment is not None or channel:
        fail(
            "--free, --prior, --segment and --channel belong to the general fit: give the "
            "scenario first, flexarm fit SCENARIO LOG... --free PATH"
        )
    if log_format and len(log_format) > 1:
        fail("--log-format is given once for the bench fit (every log has one format)")
    fmt_file = Path(log_format[0]) if log_format else None
    from flexarm.errors import FitInterrupted
    from flexarm.identification.time_domain import FitInputError
    from flexarm.identification.time_domain import fit as run_fit
    from flexarm.io.write import write_json

    check_file_option("--json", json_out, overwrite)
    check_file_option("--scenario-out", scenario_out, overwrite, "arm.toml")
    check_file_option("--report", report, overwrite, "fit.html")
    check_dir_option("--plots", plots)
    if tip_sign not in (None, 1, -1):
        fail(f"--tip-sign {tip_sign}: expected +1 or -1 (or leave it out to fit it)")
    sess = parsing.int_list(sessions, "--sessions")
    kw: dict[str, Any] = dict(
        drive=drive,
        gear_ratio=gear_ratio,
        motor_constant=motor_constant,
        armature_resistance=armature_resistance,
        link_length=link_length,
        gear_efficiency=gear_efficiency,
        motor_efficiency=motor_efficiency,
        voltage_limit=voltage_limit,
        computation_delay=computation_delay,
        mode=mode,
        global_seconds=seconds,
        sessions=sess,
        tip_sign=tip_sign,
        encoder_counts=encoder_counts,
        filters=parsing.filters(filter),
        delay_search=delay_search,
        polish_iter=polish_iter,
    )
    res = res0 = held = None
    win, vwin = (
        parsing.window(window, "--window"),
        parsing.window(validate_window, "--validate-window"),
    )
    try:
        full = bench_logs(logs, column, unit, controller, max_jitter, fmt_file, use_regressed_law)
        blogs = [g.window(*win) for g in full] if win else full
        held_logs = [g.window(*vwin) for g in full] if vwin else []
        with console.status("fitting") as status:
            res = run_fit(
                blogs, friction=not no_friction, progress=lambda m: progress(status, m), **kw
            )
            if compare_no_friction and not no_friction:
                status.update("fitting again without joint friction")
                res0 = run_fit(blogs, friction=False, **kw)
            if held_logs:
                from flexarm.identification.time_domain.fit import predict

                status.update("predicting the held-out windows")
                held = predict(res, held_logs)
    except (FitInputError, ValueError) as exc:
        fail(str(exc))
    except FitInterrupted as exc:
        _fit_interrupted(json_out, overwrite, res, exc.result)
    except KeyboardInterrupt:
        _fit_interrupted(json_out, overwrite, res, None)
    console.print(escape(res.summary()))
    _print_bench_tables(res, res0, held, validate_window)
    one = res.result(without_friction=res0, window=win, held_out=held, held_window=vwin)
    if json_out is not None:
        write_json(json_out, one.to_dict(), overwrite=overwrite)
    if scenario_out is not None:
        one.write_scenario(scenario_out, overwrite=overwrite)
    with figure_folder(plots, report) as folder:
        if folder is not None:
            _bench_figures(
                ctx,
                folder,
                res,
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
    ctx, folder: Path, res, res0, held, validate_window, report, overwrite, inputs: list
) -> None:
    """The bench fit's overlay figures into ``folder`` (and the held-out windows'), and
    the HTML report from them (--report)."""
    figs = res.plots(folder)
    if held is not None:
        from flexarm.identification.time_domain.report import overlay_plots

        figs += overlay_plots(folder, held["logs"], held["traj"], held["fit_percent"], "held-out")
    if report is not None:
        from flexarm.analysis.html_report import fit_report

        extra = {}
        if held is not None:
            extra[f"Fit % of the held-out windows {validate_window} s"] = held["fit_percent"]
        if res0 is not None:
            extra["Fit % of the fit without joint friction"] = res0.fit_percent
        write_report(
            fit_report(
                res, figures=figs, command=command_line(ctx), inputs=inputs, extra_fit_percent=extra
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
) -> None:
    """Replay logs on a scenario and report fit % = 100 (1 − ‖y − ŷ‖/‖y − mean y‖).

    A multi-link scenario, or --refit, takes the general path (any arm, logs read by
    --log-format, the prediction from each log's logged state)."""
    enable_cache()
    cfile = controller_option(controller)
    check_continuous(continuous, window)
    sc0 = with_controller_file(load(scenario), cfile)
    # DECISION (moves to the library's one predict): which prediction runs.
    if sc0.arm.kind == "multi_link" or refit is not None or cfile is not None or continuous:
        _validate_scenario_cli(
            sc0,
            logs,
            log_format,
            window,
            refit,
            refit_window,
            channel,
            json_out,
            plots,
            overwrite,
            report,
            ctx,
            continuous=continuous,
            cfile=cfile,
        )
        return
    if log_format and len(log_format) > 1:
        fail("--log-format is given once for a bench scenario's logs")
    fmt_file = Path(log_format[0]) if log_format else None
    from flexarm.identification.time_domain import FitInputError
    from flexarm.identification.time_domain import validate as run_validate
    from flexarm.identification.time_domain.validate import document as validate_document

    check_file_option("--json", json_out, overwrite)
    check_file_option("--report", report, overwrite, "validate.html")
    check_dir_option("--plots", plots)
    sc = load(scenario)
    with figure_folder(plots, report) as folder:
        try:
            win = parsing.window(window, "--window")
            blogs = bench_logs(
                logs, column, unit, controller, max_jitter, fmt_file, use_regressed_law
            )
            out = run_validate(sc, [g.window(*win) for g in blogs] if win else blogs, plots=folder)
        except (FitInputError, ValueError) as exc:
            fail(str(exc))
        if report is not None:
            from flexarm.analysis.html_report import validate_report

            write_report(
                validate_report(
                    out,
                    scenario=scenario,
                    figures=out["plots"],
                    command=command_line(ctx),
                    inputs=[scenario, *logs, *([fmt_file] if fmt_file else [])],
                ),
                report,
                overwrite,
            )
        out = validate_document(out, with_plots=plots is not None)
    t = Table("log", "motor_angle fit %", "tip_deflection fit %")
    for name, d in out["fit_percent"].items():
        t.add_row(  # None: a signal the log or the scenario lacks (a rigid arm's tip)
            name,
            *(
                f"{d[k]:.1f}" if d.get(k) is not None else "-"
                for k in ("motor_angle", "tip_deflection")
            ),
        )
    console.print(t)
    if json_out is not None:
        from flexarm.io.write import write_json

        write_json(json_out, out, overwrite=overwrite)


def bench_logs(
    paths: list[Path],
    column,
    unit,
    controller,
    max_jitter: float,
    log_format: Path | None = None,
    use_regressed: bool = False,
):
    """Bench logs read with the --column / --unit mappings (SI inside), --controller,
    --max-jitter and --log-format; the declared law is checked against each log's command
    (bench.controller_check) when it has one, and replaced by the regressed law with
    --use-regressed-law."""
    # DECISION (moves to the library: io.logformat.load_log plus a rig check, target map
    # step 2): the declared law is checked against the logged command, and replaced by
    # the regressed one with --use-regressed-law.
    from flexarm.identification.time_domain.controller_check import check_controller
    from flexarm.identification.time_domain.logs import load_rig_log

    if not (max_jitter > 0):
        fail(f"--max-jitter {max_jitter}: must be > 0 (a relative deviation, e.g. 0.05)")
    cols, units = parsing.pairs(column, "column") or None, parsing.pairs(unit, "unit") or None
    logs = [
        load_rig_log(
            p,
            columns=cols,
            units=units,
            controller=controller,
            max_jitter=max_jitter,
            log_format=log_format,
        )
        for p in paths
    ]
    out = []
    for log in logs:
        if log.gains is None or "voltage" not in log.columns or "motor_angle" not in log.columns:
            out.append(log)
            continue
        chk = check_controller(log, use_regressed=use_regressed)
        console.print(escape(chk.summary()), highlight=False)
        out.append(chk.apply(log) if use_regressed else log)
    return out


def _general_logs(paths: list[Path], log_format: list[str] | None) -> list:
    """Read each log with its format: --log-format once per log (in order), one for all,
    or PATTERN=FILE (fnmatch on the file name; the first match wins)."""
    import fnmatch

    from flexarm.io.logformat import LogFormat, load_log_format

    if not paths:
        fail("no logs given: flexarm fit SCENARIO LOG... (one or more log files)")
    specs = list(log_format or [])
    pats = [x.split("=", 1) for x in specs if "=" in x]
    plain = [x for x in specs if "=" not in x]
    if pats and plain:
        fail(
            "--log-format: give either one FILE per log (or one for all), or PATTERN=FILE "
            f"entries, not both (got {specs})"
        )
    if plain and len(plain) not in (1, len(paths)):
        fail(
            f"--log-format given {len(plain)} times for {len(paths)} logs: give it once for "
            "all, once per log in order, or as PATTERN=FILE"
        )
    cache: dict = {}

    def fmt(f: str | None):
        if f is None:
            return LogFormat()
        if f not in cache:
            cache[f] = load_log_format(f)
        return cache[f]

    out = []
    for i, p in enumerate(paths):
        if pats:
            hit = [f for pat, f in pats if fnmatch.fnmatch(Path(p).name, pat)]
            if not hit:
                fail(
                    f"{p}: no --log-format PATTERN matches its name (patterns: "
                    f"{', '.join(pat for pat, _ in pats)})"
                )
            f = hit[0]
        else:
            f = plain[0] if len(plain) == 1 else (plain[i] if plain else None)
        out.append(fmt(f).read(p))
    return out


def _fit_scenario_cli(
    scenario: str,
    logs: list[Path],
    log_format,
    free,
    prior,
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
) -> None:
    from flexarm.identification.time_domain import predict_scenario
    from flexarm.identification.time_domain.engine import fit as fit_engine
    from flexarm.identification.time_domain.options import Cost, FitOptions, Local, Priors, Shooting
    from flexarm.io.logs import LogError
    from flexarm.io.write import write_json

    check_file_option("--json", json_out, overwrite)
    check_file_option("--scenario-out", scenario_out, overwrite, "arm.toml")
    check_file_option("--report", report, overwrite, "fit.html")
    check_dir_option("--plots", plots)
    win = parsing.window(window, "--window")
    chans, priors = parsing.channels(channel), parsing.priors(prior)
    sc = with_controller_file(load(scenario), cfile)
    figures = contextlib.ExitStack()
    folder = figures.enter_context(figure_folder(plots, report))
    try:
        glogs = _general_logs(logs, log_format)
        # the options given; the rest (and, without --free, the free list) are the preset's
        opts = FitOptions(
            cost=Cost(channels=chans) if chans else None,
            shooting=Shooting(segment=segment) if segment is not None else None,
            local=Local(max_nfev=max_nfev) if max_nfev is not None else None,
            priors=Priors(priors=priors) if priors else None,
            windows=[win] * len(glogs) if win else None,
            predict=False,
            continuous=continuous,
        )
        with console.status("fitting") as status, _state_warnings_quiet():
            # the one FitResult of every rig (a scenario here: the general engine)
            res = fit_engine(sc, glogs, free or None, opts, progress=lambda m: progress(status, m))
            status.update("predicting the logs with the fitted parameters")
            console.print(f"free parameters ({len(res.free)}): {res.free_source}", highlight=False)
            opts = opts.engine_options()
            pred = predict_scenario(
                res.scenario,
                glogs,
                opts,
                channels=list(opts.channels) if opts.channels else None,
                plots=folder,
                tag="fit",
            )
    except (LogError, ValueError) as exc:
        figures.close()
        fail(str(exc))
    t = Table("parameter", "template", "fitted", "std")
    for p in res.free:
        t.add_row(p, f"{res.template[p]:.5g}", f"{res.params[p]:.5g}", f"{res.std[p]:.3g}")
    console.print(t)
    console.print(escape(res.message))
    for w in res.warnings:
        console.print(f"[yellow]warning:[/yellow] {escape(w)}")
    _print_warnings(pred.get("warnings", []))
    _fit_table(pred["fit_percent"], "whole-log prediction")
    # the result carries the whole-log prediction and its figures: --json is res.to_dict()
    res.fit_percent, res.plots = pred["fit_percent"], (pred["plots"] if plots is not None else [])
    if json_out is not None:
        write_json(json_out, res.to_dict(), overwrite=overwrite)
    if scenario_out is not None:
        res.write_scenario(scenario_out, overwrite=overwrite)
    with figures:
        if report is not None:
            from flexarm.analysis.html_report import fit_report

            assert ctx is not None  # the command passes its context
            write_report(
                fit_report(
                    res,
                    figures=pred["plots"],
                    command=command_line(ctx),
                    inputs=[scenario, *logs, *(log_format or [])],
                    fit_percent=pred["fit_percent"],
                ),
                report,
                overwrite,
            )


def _fit_table(fp: dict, title: str) -> None:
    names = sorted({k for d in fp.values() for k in d})
    t = Table(f"fit % ({title})", *names)
    for log, d in fp.items():
        t.add_row(Path(log).name, *(f"{d[k]:.1f}" if d.get(k) is not None else "-" for k in names))
    console.print(t)


def _validate_scenario_cli(
    sc,
    logs,
    log_format,
    window,
    refit,
    refit_window,
    channel,
    json_out,
    plots,
    overwrite,
    report=None,
    ctx=None,
    *,
    continuous: bool = False,
    cfile=None,
) -> None:
    """The general path of ``validate`` (the one prediction,
    :func:`flexarm.identification.time_domain.predict.predict`); ``sc`` already carries
    ``cfile``'s controllers (for ``--refit``), and the prediction is given it too, so that
    servo-rig logs with a declared law do not take the rig's replay."""
    from flexarm.identification.time_domain import ScenarioFitOptions, fit_scenario
    from flexarm.identification.time_domain.general import friction_paths
    from flexarm.identification.time_domain.options import PredictOptions
    from flexarm.identification.time_domain.predict import predict
    from flexarm.io.logs import LogError
    from flexarm.io.write import write_json

    check_file_option("--json", json_out, overwrite)
    check_file_option("--report", report, overwrite, "validate.html")
    check_dir_option("--plots", plots)
    if refit not in (None, "friction"):
        fail(
            f"--refit {refit!r}: only 'friction' (the joints' Coulomb, breakaway and "
            "viscous friction) can be re-estimated"
        )
    win = parsing.window(window, "--window")
    rwin = parsing.window(refit_window, "--refit-window")
    out: dict = {}  # the prediction's to_dict(), the refit's entry (FitResult.refit_entry)
    figures = contextlib.ExitStack()
    plots = figures.enter_context(figure_folder(plots, report))
    figs: list = []
    ch = parsing.channels(channel)
    try:
        glogs = _general_logs(logs, log_format)
        popts = PredictOptions(
            channels=list(ch) if ch else None,
            windows=[win] * len(glogs) if win else None,
            continuous=continuous,
            controller=cfile,
            plots=plots,
            tag="validate",
        )
        with console.status("predicting") as status, _state_warnings_quiet():
            before = predict(sc, glogs, popts)
            out = before.to_dict()
            figs += before.plots
            if refit:
                status.update("re-estimating the joints' friction")
                free = friction_paths(sc)  # DECISION: what --refit friction frees
                res = fit_scenario(
                    sc,
                    glogs[:1],
                    free,
                    ScenarioFitOptions(channels=ch, windows=[rwin]),
                    predict=False,
                )
                after = predict(res.scenario, glogs, dataclasses.replace(popts, tag="refit"))
                figs += after.plots
                out["refit"] = res.refit_entry(free, rwin, logs[0], after)
    except (LogError, ValueError) as exc:
        figures.close()
        fail(str(exc))
    _print_warnings(out["warnings"])
    _fit_table(out["fit_percent"], "scenario as given")
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

            assert ctx is not None  # the command passes its context
            write_report(
                validate_report(
                    out,
                    scenario=sc.name,
                    figures=figs,
                    command=command_line(ctx),
                    inputs=[ctx.params["scenario"], *logs, *(log_format or [])],
                ),
                report,
                overwrite,
            )


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
