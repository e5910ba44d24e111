"""``flexarm design``: a discrete controller for a scenario's rig, compared with the
scenario's own controller on a reference step over drawn plants."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer
from rich.markup import escape

from flexarm.cli import parsing
from flexarm.cli.common import (
    check_cluster,
    check_file_option,
    command_line,
    console,
    enable_cache,
    err,
    fail,
    guarded,
    load,
    outdir,
    progress,
    warn,
    working,
    write_report,
)

if TYPE_CHECKING:
    from flexarm.design.gate import GateOptions


def design_cmd(
    ctx: typer.Context,
    scenario: str = typer.Argument(
        ..., help="scenario TOML file or built-in name (a fitted rig's scenario)"
    ),
    method: str = typer.Option(
        "lqr",
        "--method",
        help="lqr, place, nested (Feliu's two loops) or tune (the controller's "
        "gains over plants drawn from the fit's uncertainty)",
    ),
    out: Path = typer.Option(
        ..., "--out", help="folder for design.toml, design.json and the step figure"
    ),
    q: str | None = typer.Option(
        None,
        "--q",
        help="lqr output weights, CHANNEL=W,... (int_CHANNEL for an "
        "integrator) or one number per channel; default Bryson",
    ),
    r: str | None = typer.Option(None, "--r", help="lqr command weight(s); default 1/limit²"),
    poles: str | None = typer.Option(
        None,
        "--poles",
        help="place: closed-loop poles of the arm's states (+ integrators), "
        "e.g. '-20+15j,-20-15j,-30,-40'",
    ),
    observer_poles: str | None = typer.Option(
        None,
        "--observer-poles",
        help="observer poles of the arm's states (default: Kalman predictor)",
    ),
    pole_domain: str = typer.Option("s", "--pole-domain", help="s (rad/s, z = exp(sT)) or z"),
    integral: bool = typer.Option(
        False, "--integral/--no-integral", help="integrators of the tracked channels' errors (LQI)"
    ),
    disturbance: bool | None = typer.Option(
        None,
        "--disturbance/--no-disturbance",
        help="estimate and cancel a constant input disturbance (integral action; "
        "default: on unless --integral)",
    ),
    friction_compensation: bool = typer.Option(
        True,
        "--friction-compensation/--no-friction-compensation",
        help="Coulomb feedforward C_f / k_u from the scenario's friction",
    ),
    max_deflection: float | None = typer.Option(
        None,
        "--max-deflection",
        help="nested: limit of the link deflection |θm − θt| during the move, rad (default 0.1)",
        callback=parsing.number(gt=0, example="0.1"),
    ),
    distance: float | None = typer.Option(
        None,
        "--distance",
        help="nested: the tip move, rad (default the scenario's reference amplitude)",
        callback=parsing.number(),
    ),
    fit_json: Path | None = typer.Option(
        None,
        "--fit-json",
        help="the fit's JSON (flexarm fit --json) of the rig whose "
        "--scenario-out is SCENARIO: plants drawn from its "
        "standard deviations (tune; and the comparison)",
    ),
    spread: str | None = typer.Option(
        None,
        "--spread",
        help="plants drawn from PATH=STD,... (SI; STD may end in % of "
        "the scenario's value), e.g. "
        "'arm.motor.inertia=10%,arm.friction.coulomb=0.005'",
    ),
    plants: int = typer.Option(
        200,
        "--plants",
        help="number of plants drawn",
        callback=parsing.number(ge=1, le=1_000_000, example="200"),
    ),
    seed: int = typer.Option(
        0, "--seed", help="seed of the plant draws", callback=parsing.number(ge=0, le=2**32 - 1)
    ),
    encoder_counts: int | None = typer.Option(
        None,
        "--encoder-counts",
        help="counts per turn of the hub encoder, where the "
        "scenario's hub sensor has no quantum (errors in counts)",
        callback=parsing.number(ge=2, le=2**40, example="4096"),
    ),
    report: Path | None = typer.Option(
        None,
        "--report",
        help="write a self-contained HTML report (the designed "
        "controller, its figures, the step comparison)",
    ),
    accept_unstable: bool = typer.Option(
        False,
        "--accept-unstable",
        help="keep (and exit 0 with) a design the gate finds unsafe: unstable on the "
        "nominal plant, or on more than --max-unstable-share of the drawn "
        "plants, or reaching the command limit (its verdict is still written)",
    ),
    max_unstable_share: float = typer.Option(
        0.01,
        "--max-unstable-share",
        help="the largest share (0..1) of drawn plants that may be unstable or reach "
        "the limit before the design is refused",
        callback=parsing.number(ge=0, le=1, example="0.01"),
    ),
    scheduler: str | None = typer.Option(
        None,
        "--scheduler",
        help="run the drawn plants on a running Dask scheduler, "
        "e.g. tcp://host:8786 (in chunks, one task each)",
    ),
    workers: int | None = typer.Option(
        None,
        "--workers",
        help="run the drawn plants on a local Dask cluster of N "
        "worker processes (default: in-process)",
        callback=parsing.number(ge=1, le=1024, example="4"),
    ),
    overwrite: bool = typer.Option(False, help="write into a non-empty --out folder"),
) -> None:
    """Design a discrete controller for a scenario's rig (linearised at rest, sampled at its
    period, its computation and sensor delays in the model): state feedback by LQR or pole
    placement with a Kalman (or placed) predictor, the reference as a state (two degrees of
    freedom), integral action (an estimated input disturbance, or --integral), and the
    Coulomb friction feedforward (lqr, place); or Feliu's nested loops (nested: inner hub
    loop with friction and coupling feedforward, outer tip loop with the Wiener feedforward
    of a deflection-limited quasi-parabolic move); or the controller's own gains and a
    friction feedforward tuned in simulation over plants drawn from the fit (tune).
    The scenario's controller and the design are then compared on a reference step (a
    nested design runs its own move of the same distance) with friction, delays,
    quantisation and saturation: on the nominal plant, and with --fit-json or --spread over
    --plants drawn plants (nominal / median / worst, unstable count, the limit).
    Writes design.toml (the scenario with the designed [controller]: flexarm simulate
    OUT/design.toml runs it), design.json (gains, poles, weights, figures, warnings),
    compare.json / compare.md (the comparison) and its figures; --report an HTML page.
    The design gate: a design unstable on the nominal plant or on more than
    --max-unstable-share of the drawn plants, or whose command reaches the limit, is written
    with its verdict, printed in red, and the command exits 2 unless --accept-unstable."""
    check_cluster(scheduler, workers)
    request = DesignRequest(
        scenario=scenario,
        method=method,
        out=out,
        q=q,
        r=r,
        poles=poles,
        observer_poles=observer_poles,
        pole_domain=pole_domain,
        integral=integral,
        disturbance=disturbance,
        friction_compensation=friction_compensation,
        max_deflection=max_deflection,
        distance=distance,
        fit_json=fit_json,
        spread=spread,
        plants=plants,
        seed=seed,
        encoder_counts=encoder_counts,
        report=report,
        accept_unstable=accept_unstable,
        max_unstable_share=max_unstable_share,
        overwrite=overwrite,
        scheduler=scheduler,
        workers=workers,
    )
    with guarded(scenario, fit_json):
        _design(ctx, request)


@dataclass(frozen=True, kw_only=True)
class DesignRequest:
    """The options of ``flexarm design`` as given on the command line, one field per option
    (the command's help says what each means; the defaults are the command's, so every
    field is given).

    Why here: a command-line record, not a library one: the library's
    :func:`flexarm.design.gate.design_checked` takes the method's own keyword arguments
    (:meth:`method_options`), the drawn plants, the encoder count, a Dask client and its
    own record :class:`flexarm.design.gate.GateOptions` (:meth:`gate_options`); the rest
    (file paths, the spread as text, the scheduler) is the command's."""

    scenario: str
    method: str
    out: Path
    q: str | None
    r: str | None
    poles: str | None
    observer_poles: str | None
    pole_domain: str
    integral: bool
    disturbance: bool | None
    friction_compensation: bool
    max_deflection: float | None
    distance: float | None
    fit_json: Path | None
    spread: str | None
    plants: int
    seed: int
    encoder_counts: int | None
    report: Path | None
    accept_unstable: bool
    max_unstable_share: float
    overwrite: bool
    scheduler: str | None
    workers: int | None

    def method_options(self) -> dict[str, Any]:
        """The method's own keyword arguments of :func:`flexarm.design.design` (the pole
        lists and weights parsed; a malformed one is refused here)."""
        poles_v = parsing.complex_list(self.poles, "--poles")
        observer_v = parsing.complex_list(self.observer_poles, "--observer-poles")
        q_v, r_v = parsing.weights(self.q, "--q"), parsing.weights(self.r, "--r")
        opts: dict[str, Any]
        if self.method == "nested":
            opts = {
                k: v
                for k, v in (("max_deflection", self.max_deflection), ("distance", self.distance))
                if v is not None
            }
        elif self.method == "tune":
            opts = {}  # the plants (tune needs --fit-json or --spread: checked before)
        else:
            opts = dict(
                integral=self.integral,
                disturbance=self.disturbance,
                friction_compensation=self.friction_compensation,
                pole_domain=self.pole_domain,
                observer_poles=observer_v,
            )
        if self.method == "place":
            opts["poles"] = poles_v
        elif self.method == "lqr":
            opts.update(q=q_v, r=r_v)
        return opts

    def gate_options(self) -> GateOptions:
        """The library's gate: the command keeps (accepts) every design, writes it with its
        verdict, and exits 2 itself unless ``--accept-unstable``."""
        from flexarm.design.gate import GateOptions

        return GateOptions(max_unstable_share=self.max_unstable_share, accept_unstable=True)

    @property
    def count(self) -> float | None:
        """The encoder count, rad, from ``--encoder-counts`` (None: the scenario's)."""
        return 2 * math.pi / self.encoder_counts if self.encoder_counts else None


def _design(ctx, o: DesignRequest) -> None:
    enable_cache()
    from flexarm.design import METHODS
    from flexarm.design.gate import design_checked
    from flexarm.errors import FlexarmError

    _check_options(o, METHODS)
    # the option values parsed before any work: a malformed one is refused first
    opts = o.method_options()  # each method's own keyword arguments
    check_file_option("--report", o.report, o.overwrite, "design.html")
    sc = load(o.scenario)
    if o.encoder_counts is not None and getattr(sc, "prismatic", False):
        fail(
            f"--encoder-counts {o.encoder_counts}: counts per turn of a rotary encoder, but "
            f"{o.scenario} is a linear axis (m); give its scale as quantum = <m per count> "
            "under [sensors.motor_angle] (e.g. 1e-6 for 1 µm)"
        )
    fit_doc = parsing.json_file(o.fit_json, "--fit-json") if o.fit_json is not None else None
    by_paths = fit_doc is not None and {"free", "params", "std"} <= set(fit_doc)
    spread_d = None if by_paths else plant_spread(sc, o.fit_json, o.spread)
    out = outdir(o.out, o.overwrite)
    method, plants, overwrite = o.method, o.plants, o.overwrite
    from flexarm.design.plants import from_fit, from_paths

    with working(f"designing ({method})...") as status:
        try:  # the plants, drawn once: tuned over (tune), made robust over (lqr), compared on
            if fit_doc is not None and by_paths:  # any fit's document: its covariance
                from flexarm.identification.time_domain.result import FitResult

                drawn = from_fit(FitResult.from_dict(fit_doc, scenario=sc), plants, seed=o.seed)
            else:
                drawn = from_paths(sc, spread_d, plants, seed=o.seed) if spread_d else None
        except ValueError as exc:
            fail(f"--fit-json/--spread: {exc}")
        if method == "tune":
            opts["callback"] = lambda e: progress(
                status, f"tuning: {e['nfev']} batch runs, best cost {e['best']:.4g}"
            )
        progress(
            status,
            f"designing ({method}) and checking it with the scenario's "
            "controller on a reference step (nominal plant"
            f"{f' and {plants} drawn' if drawn is not None else ''})...",
        )
        from flexarm.distributed import executor, session

        try:  # the gate runs the comparison (flexarm.design.gate.design_checked)
            with session(o.scheduler, o.workers) as client:  # None: in-process
                des = design_checked(
                    sc,
                    method,
                    plants=drawn,
                    count=o.count,
                    gate=o.gate_options(),
                    client=executor(client),  # the batches' executor (sim.batch protocol)
                    **opts,
                )
        except FlexarmError:
            raise
        except ValueError as exc:
            fail(f"{o.scenario}: {exc}")
    side = getattr(des, "comparison", None)
    files = des.write(out, overwrite=overwrite)
    if side is not None:
        from flexarm.io.write import write_json, write_text

        files += [
            write_json(out / "compare.json", side.to_dict(), overwrite=overwrite),
            write_text(out / "compare.md", side.table("markdown") + "\n", overwrite=overwrite),
            *side.figures(out, overwrite=overwrite),
        ]
        _print_comparison(side, plants)
    info = des.info
    if "model" in info:
        from flexarm.design.compare import units_of

        cmd_unit = units_of(sc)["command"]
        console.print(
            f"augmented model: {info['model']['n_augmented']} states "
            f"(arm {info['model']['n_arm']}); linear peak command "
            f"{', '.join(f'{v:.3g}' for v in info['step']['peak_command'])} {cmd_unit}"
        )
    for w in des.warnings:
        warn(w)
    console.print("wrote " + ", ".join(str(p) for p in files))
    if o.report is not None:
        from flexarm.analysis.html_report import design_report

        write_report(
            design_report(
                des,
                figures=[p for p in files if str(p).endswith(".png")],
                comparison=side,
                command=command_line(ctx),
                inputs=[o.scenario],
            ),
            o.report,
            overwrite,
        )
    if not des.stable:
        colour = "yellow" if o.accept_unstable else "bold red"
        err.print(f"[{colour}]{escape(des.summary())}[/]", highlight=False, soft_wrap=True)
        if not o.accept_unstable:
            from flexarm.design.gate import refusal

            msg, fix = refusal(method, des.gate or {"verdict": des.verdict})
            fail(
                f"{msg}; written to {out} with its verdict (design.json, compare.md say why); {fix}"
            )


def plant_spread(sc, fit_json: Path | None, spread: str | None) -> dict | None:
    """Scenario path → (mean, std) for the plant draws of ``design``: from ``--spread``, or
    from a fit document written before the one result (its ``parameters`` table:
    :func:`flexarm.identification.time_domain.report.scenario_spread`); a fit document with
    ``free``/``params``/``std`` is drawn by :func:`flexarm.design.plants.from_fit`."""
    if fit_json is not None:
        from flexarm.identification.time_domain.logs import FitInputError
        from flexarm.identification.time_domain.report import scenario_spread

        data = parsing.json_file(fit_json, "--fit-json")
        try:
            return scenario_spread(data, sc)
        except (FitInputError, KeyError, TypeError) as exc:
            fail(f"--fit-json {fit_json}: {exc}")
    if spread is None:
        return None
    from flexarm.specs.paths import get

    base = sc.model_dump(mode="json", exclude_none=True)
    out = {}
    for item in spread.split(","):
        path, eq, val = item.strip().partition("=")
        if not eq or not path:
            fail(f"--spread {item!r}: write PATH=STD, e.g. arm.motor.inertia=10%")
        try:
            mean = float(get(base, path, "--spread"))
            std = (
                abs(mean) * float(val.strip()[:-1]) / 100
                if val.strip().endswith("%")
                else float(val)
            )
        except (ValueError, TypeError) as exc:
            fail(f"--spread {item!r}: {exc}")
        if not (math.isfinite(std) and std >= 0):
            fail(f"--spread {item!r}: the std must be a finite number >= 0")
        out[path] = (mean, std)
    return out


def _check_options(o: DesignRequest, methods) -> None:
    """The option combinations ``design`` accepts (refused before any work).

    Why here: the library's ``design()`` checks its own arguments too; these checks name
    the command-line options."""
    method, poles, q, r = o.method, o.poles, o.q, o.r
    if method not in methods:
        fail(f"--method {method!r}: not known; choose one of {', '.join(methods)}")
    if o.pole_domain not in ("s", "z"):
        fail(f"--pole-domain {o.pole_domain!r}: give s (continuous-time poles, rad/s) or z")
    if method == "place" and poles is None:
        fail(
            "--method place needs --poles (the closed-loop poles of the arm's states, "
            "e.g. --poles '-20+15j,-20-15j,-30,-40'; flexarm design ... --method lqr shows "
            "the model's states in design.json)"
        )
    if method != "place" and poles is not None:
        fail(f"--poles: only with --method place (got --method {method})")
    if method == "place" and (q is not None or r is not None):
        fail("--q/--r: only with --method lqr (place takes --poles)")
    if method == "nested":
        given = [
            flag
            for flag, v in (
                ("--q", q),
                ("--r", r),
                ("--observer-poles", o.observer_poles),
                ("--integral", o.integral or None),
                ("--disturbance", o.disturbance),
            )
            if v is not None
        ]
        if given:
            fail(
                f"{', '.join(given)}: only with --method lqr or place (the nested loops take "
                "--max-deflection and --distance)"
            )
    elif o.max_deflection is not None or o.distance is not None:
        fail("--max-deflection/--distance: only with --method nested")
    if method == "tune" and o.fit_json is None and o.spread is None:
        fail(
            "--method tune needs the plants' spread: --fit-json FIT.json (the rig's fit) or "
            "--spread PATH=STD,..."
        )
    if o.fit_json is not None and o.spread is not None:
        fail("--fit-json and --spread both give the plants' spread; choose one")
    if o.plants < 1:
        fail(f"--plants {o.plants}: give at least 1 plant (200 for the issue's comparison)")
    if o.plants > 1_000_000:  # issue #45: 1e12 plants ran out of memory after the design
        fail(
            f"--plants {o.plants}: at most 1000000 plants are drawn (each one is simulated); "
            "give e.g. 200"
        )
    if o.encoder_counts is not None and o.encoder_counts < 2:
        fail(f"--encoder-counts {o.encoder_counts}: give the counts per turn (e.g. 4096)")
    if o.integral and o.disturbance:
        fail("--integral and --disturbance both give integral action; choose one")
    if not (0.0 <= o.max_unstable_share <= 1.0):
        fail(
            f"--max-unstable-share {o.max_unstable_share}: give a share in [0, 1], "
            "e.g. 0.01 for 1 %"
        )


def _print_comparison(side, plants: int) -> None:
    """The step comparison as a table within the terminal's width (one row per metric, one
    column per controller: nominal / median / worst; stacked, never cut, where the columns
    do not fit: :class:`flexarm.display.Table`)."""
    from flexarm.design.compare import format_metric, metric_titles
    from flexarm.display import Table as TextTable

    drawn = side.settings["n_plants"] > 0
    cols = ("nominal", "median", "worst") if drawn else ("nominal",)
    unit = (side.settings.get("units") or {}).get("position", "rad")  # m on a linear axis
    step = f"a {side.settings['step_rad']:g} {unit} step"
    title = (
        f"{step}: nominal / median / worst over {plants} drawn plants"
        if drawn
        else f"{step} on the nominal plant"
    )
    names = list(side.rows)
    rows: list[tuple] = [
        (
            f"{t} [{u}]",
            *(" / ".join(format_metric(side.rows[n][k][m]) for k in cols) for n in names),
        )
        for m, (t, u) in metric_titles(side.settings).items()
    ]
    if drawn:
        rows.append(
            ("unstable", *(f"{side.rows[n]['unstable']}/{side.rows[n]['n_plants']}" for n in names))
        )
    rows.append(("limit ok", *("yes" if side.rows[n]["limit_respected"] else "NO" for n in names)))
    text = TextTable(title, rows, header=("metric", *names)).text(console.width or 80)
    console.print(text, markup=False, highlight=False, soft_wrap=True)
