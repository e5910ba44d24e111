"""The ``flexarm`` command line: thin wrappers over the library (typer + rich)."""

from __future__ import annotations

import contextlib
import json
import math
import os
import tempfile
from pathlib import Path
from typing import Optional

import typer
from rich.console import Console
from rich.markup import escape
from rich.table import Table

app = typer.Typer(add_completion=False, no_args_is_help=True,
                  help="Model, identify, simulate and control flexible-link arms with joint friction.")
console = Console()
err = Console(stderr=True)


def _enable_cache() -> None:
    """JAX's persistent compilation cache, so repeated CLI runs skip recompiling."""
    import jax

    cache = os.environ.get("FLEXARM_JAX_CACHE", str(Path.home() / ".cache" / "flexarm-jax"))
    try:
        jax.config.update("jax_compilation_cache_dir", cache)
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)
    except Exception:  # an old jax without the option: run uncached
        pass


def _fail(msg: str) -> None:
    err.print(f"[bold red]error:[/] {escape(msg)}", highlight=False)
    raise typer.Exit(2)


def _load(scenario: str):
    from flexarm.specs import ScenarioError, load_scenario

    try:
        sc = load_scenario(scenario)
        if sc.arm.kind == "single_link":  # the model's own checks (a proper, stable G_b, ...)
            from flexarm.models.single_link import SingleLinkModel

            SingleLinkModel.from_spec(sc.arm)
    except ScenarioError as exc:
        _fail(str(exc))
    except ValueError as exc:
        _fail(f"{scenario}: {exc}")
    return sc


def _writable(option: str, path: Path, folder: Path) -> None:
    """``folder`` (where ``path`` will be made) must be a writable folder."""
    if not os.access(folder, os.W_OK | os.X_OK):
        _fail(f"{option} {path}: cannot write into {folder} (permission denied); choose a "
              "folder you can write to")


def _check_dir_option(option: str, path: Optional[Path]) -> None:
    """An output folder option: refuse, before any work, a path that is an existing file,
    lies below a file, or cannot be created or written (the folder itself may be missing:
    it is created with its parents)."""
    if path is None:
        return
    if path.exists() and not path.is_dir():
        _fail(f"{option} {path}: is a file, not a folder; give a folder name (flexarm writes "
              "several files into it), or move the file away")
    anc = path
    while not anc.exists():
        if anc.parent == anc:
            break
        anc = anc.parent
    if not anc.is_dir():
        _fail(f"{option} {path}: {anc} is a file, so the folder cannot be created there; "
              "give a path below a folder")
    _writable(option, path, anc)


def _check_file_option(option: str, path: Optional[Path], overwrite: bool,
                       example: str = "result.json") -> None:
    """An output file option: refuse, before any work, a folder, an existing file (unless
    --overwrite), a missing or non-folder parent, or a parent that cannot be written."""
    if path is None:
        return
    if path.is_dir():
        _fail(f"{option} {path}: is a folder, not a file; give a file name, e.g. "
              f"{path / example}")
    if path.exists() and not overwrite:
        _fail(f"{option} {path}: exists; pass --overwrite to replace it")
    parent = path.parent
    if not parent.exists():
        _fail(f"{option} {path}: the folder {parent} does not exist; create it first "
              f"(mkdir -p {parent})")
    if not parent.is_dir():
        _fail(f"{option} {path}: {parent} is a file, not a folder; give a path in a folder")
    _writable(option, path, parent)


def _command_line(ctx: typer.Context) -> str:
    """The running command as an equivalent ``flexarm ...`` line (for reports): its
    arguments and the options given on the command line (defaults left out), shell-quoted."""
    import shlex

    args, opts = [], []
    for prm in ctx.command.params:
        src = ctx.get_parameter_source(prm.name)
        if getattr(src, "name", None) != "COMMANDLINE":
            continue
        v = ctx.params[prm.name]
        vals = list(v) if isinstance(v, (list, tuple)) else [v]
        if prm.param_type_name == "argument":
            args += [str(x) for x in vals]
        elif getattr(prm, "is_flag", False):
            names = prm.opts if v else prm.secondary_opts
            opts += names[:1]
        else:
            for x in vals:
                opts += [prm.opts[0], str(x)]
    return shlex.join(["flexarm", str(ctx.info_name), *args, *opts])


@contextlib.contextmanager
def _figure_folder(plots: Optional[Path], report: Optional[Path]):
    """Where the figures go: --plots, else (a report needs them) a temporary folder removed
    after the report is written; None when neither is asked for."""
    if plots is not None or report is None:
        yield plots
    else:
        with tempfile.TemporaryDirectory(prefix="flexarm-report-") as d:
            yield Path(d)


def _write_report(rep, path: Optional[Path], overwrite: bool) -> None:
    """Write an :class:`flexarm.analysis.html_report.HtmlReport` to --report."""
    from flexarm.errors import OutputExistsError

    try:
        rep.write(path, overwrite=overwrite)
    except (OutputExistsError, OSError) as exc:
        _fail(f"--report {path}: {exc}")
    console.print(f"report: {escape(str(path))}")


def _outdir(out: Path, overwrite: bool, option: str = "--out") -> Path:
    _check_dir_option(option, out)
    if out.exists() and any(out.iterdir()) and not overwrite:
        _fail(f"{option} {out}: exists and is not empty; pass --overwrite to write into it")
    out.mkdir(parents=True, exist_ok=True)
    return out


@app.command()
def scenarios() -> None:
    """List the built-in scenarios."""
    from flexarm.specs import builtin_scenarios, load_scenario

    t = Table("name", "description")
    for name, path in sorted(builtin_scenarios().items()):
        t.add_row(name, load_scenario(path).description)
    console.print(t)


@app.command()
def info(scenario: str = typer.Argument(..., help="scenario TOML file or built-in name"),
         as_json: bool = typer.Option(False, "--json", help="print JSON")) -> None:
    """The arm's linear model: transfer functions, poles, zeros, frequencies, gains."""
    from flexarm.analysis.model_info import multilink_info, single_link_info
    from flexarm.models.single_link import SingleLinkModel

    sc = _load(scenario)
    if sc.arm.kind == "multi_link":
        data = {"scenario": sc.name, **multilink_info(sc)}
        if as_json:
            print(json.dumps(data, indent=2))
        else:
            _print_multilink(sc, data)
        return
    data = {"scenario": sc.name, **single_link_info(SingleLinkModel.from_spec(sc.arm))}
    if as_json:
        print(json.dumps(data, indent=2))
        return
    console.print(f"[bold]{sc.name}[/]: {sc.description}")
    for key, tf in data["transfer_functions"].items():
        console.print(f"\n[bold]{key}[/]: {escape(tf['description'])}")
        console.print(f"  num = {_fmt(tf['num'])}\n  den = {_fmt(tf['den'])}")
        for w in tf["natural_frequencies_rad_s"]:
            kind = "real pole" if w["damping_ratio"] >= 1 - 1e-12 else "pole pair"
            console.print(f"  {kind}: {w['wn_rad_s']:.5g} rad/s ({w['hz']:.4g} Hz), "
                          f"damping {w['damping_ratio']:.3g}")
        if tf["right_half_plane_zeros"]:
            console.print(f"  right-half-plane zeros: {[round(z['re'], 5) for z in tf['right_half_plane_zeros']]}")
        console.print(f"  static gain: {tf['static_gain']:.6g} ({tf['static_gain_note']})")


def _print_multilink(sc, data: dict) -> None:
    console.print(f"[bold]{sc.name}[/]: {escape(sc.description)}")
    for ln in data["links"]:
        console.print(f"\n[bold]link {ln['link']}[/] ({ln['modes']} {ln['mode_type']} modes)")
        console.print(f"  frequencies [Hz]: {_fmt(ln['frequencies_hz'])}", markup=False)
        console.print(f"  phi(l): {_fmt(ln['phi_end'])}   phi'(l) [1/m]: "
                      f"{_fmt(ln['phi_prime_end_per_m'])}", markup=False)
        console.print("  k_ij [N/m]: " + ", ".join(_fmt(r) for r in ln["stiffness_k_ij_N_per_m"]),
                      markup=False)
    tg = data.get("target")
    if tg:
        console.print(f"\ndelta_d [m] (eq. 9): {_fmt(tg['delta_d_m'])}", markup=False)
        console.print(f"alpha (eq. 6): {tg['alpha']['value']:.5g}")
        for k, c in tg["conditions"].items():
            console.print(f"({k}) {c['statement']}: {'holds' if c['holds'] else 'FAILS'} "
                          f"(margin {c['margin']:+.4g})")


def _fmt(c: list[float]) -> str:
    return "[" + ", ".join(f"{x:.6g}" for x in c) + "]"


@app.command()
def simulate(scenario: list[str] = typer.Argument(..., help="scenario TOML file(s) or built-in name(s)"),
             out: Path = typer.Option(..., "--out", help="folder for CSV, figures and summary"),
             overwrite: bool = typer.Option(False, help="write into a non-empty --out folder"),
             log: Optional[list[Path]] = typer.Option(
                 None, "--log", help="replay this log (.mat or text; repeat for several): its "
                                     "setpoints, initial state, fit % per logged channel"),
             log_format: Optional[Path] = typer.Option(
                 None, "--log-format", help="the logs' log-format TOML (examples/)"),
             window: Optional[str] = typer.Option(
                 None, help="replay this part of every log, START:STOP in s on its clock")) -> None:
    """Simulate a scenario's closed loop: CSV (exchange format), PNG figure, summary.json;
    with --log, replay logs on it and report fit % = 100 (1 − ‖y − ŷ‖/‖y − mean y‖).

    Several scenarios: each one's files, and for multi-link arms in the sampled loop one
    figure of all of them overlaid (joint errors in encoder counts, link deflections,
    commands), e.g. flexarm simulate deluca-two-link-geared deluca-two-link-geared-fc."""
    _enable_cache()
    from flexarm.analysis.summary import write_comparison, write_multilink, write_simulation

    scs = [_load(s) for s in scenario]
    out = _outdir(out, overwrite)
    if log:
        if len(scs) != 1:
            _fail("--log replays logs on one scenario; give exactly one SCENARIO")
        _replay_logs(scs[0], log, log_format, window, out)
        return
    if len(scs) == 1:
        console.print_json(json.dumps(write_simulation(scs[0], out, progress=True)))
        return
    summaries, results, multi = {}, {}, []
    for sc in scs:
        if sc.arm.kind == "multi_link" and sc.sampling is not None:
            summaries[sc.name], results[sc.name] = write_multilink(sc, out, progress=True)
            multi.append(sc)
        else:
            summaries[sc.name] = write_simulation(sc, out, progress=True)
    if len(multi) > 1:
        summaries["comparison_figure"] = write_comparison(multi, results, out).name
    console.print_json(json.dumps(summaries))


def _replay_logs(sc, logs: list[Path], log_format: Optional[Path], window: Optional[str],
                 out: Path) -> None:
    from flexarm.analysis.replay import plot_replay, replay
    from flexarm.io.logformat import LogFormat, load_log_format
    from flexarm.io.logs import LogError
    from flexarm.io.write import write_json
    from flexarm.errors import SimulationDiverged

    win = _window(window, "--window")
    results = {}
    try:
        fmt = load_log_format(log_format) if log_format is not None else LogFormat()
        for path in logs:
            g = fmt.read(path)
            rep = replay(sc, g, window=(g.time[0] + win[0], g.time[0] + win[1]) if win else None)
            results[str(path)] = {k: round(v, 2) for k, v in rep.fit_percent.items()}
            plot_replay(rep, out / f"replay-{path.stem}.png", overwrite=True)
    except (LogError, ValueError, SimulationDiverged) as exc:
        _fail(str(exc))
    names = sorted({k for d in results.values() for k in d})
    t = Table("fit %", *[Path(name).stem for name in results])
    for k in names:
        t.add_row(k, *(f"{d.get(k, float('nan')):.1f}" for d in results.values()))
    console.print(t)
    write_json(out / "replay.json", {"scenario": sc.name, "window": window,
                                     "fit_percent": results}, overwrite=True)


def _complex_list(text: str | None, option: str) -> list[complex] | None:
    """``"-20+15j,-20-15j,-30"`` → complex numbers; a clear error naming the option."""
    if text is None:
        return None
    out = []
    for item in text.replace(" ", "").split(","):
        try:
            out.append(complex(item.replace("i", "j")))
        except ValueError:
            _fail(f"{option} {text!r}: {item!r} is not a number; give comma-separated poles, "
                  "e.g. {option} '-20+15j,-20-15j,-30'".replace("{option}", option))
    return out


def _weights(text: str | None, option: str):
    """``"motor_angle=1e3,tip_deflection=10"`` → dict, or ``"1e3,10"`` → numbers."""
    if text is None:
        return None
    items = [t for t in text.replace(" ", "").split(",") if t]
    try:
        if all("=" in t for t in items):
            return {k: float(v) for k, v in (t.split("=", 1) for t in items)}
        return [float(t) for t in items]
    except ValueError:
        _fail(f"{option} {text!r}: give numbers (one per channel) or CHANNEL=WEIGHT pairs, "
              f"e.g. {option} motor_angle=1e3,tip_deflection=10")


def _plant_spread(sc, fit_json: Optional[Path], spread: Optional[str]) -> dict | None:
    """Scenario path → (mean, std) for the plant draws of ``design``: from the fit's JSON
    (:func:`flexarm.identification.time_domain.report.scenario_spread`) or ``--spread``."""
    if fit_json is not None:
        from flexarm.identification.time_domain.logs import FitInputError
        from flexarm.identification.time_domain.report import scenario_spread

        try:
            data = json.loads(Path(fit_json).read_text())
        except (OSError, json.JSONDecodeError) as exc:
            _fail(f"--fit-json {fit_json}: cannot read it as JSON ({exc})")
        try:
            return scenario_spread(data, sc)
        except (FitInputError, KeyError, TypeError) as exc:
            _fail(f"--fit-json {fit_json}: {exc}")
    if spread is None:
        return None
    from flexarm.identification.time_domain.general import _get, parse_path

    base = sc.model_dump(mode="json", exclude_none=True)
    out = {}
    for item in spread.split(","):
        path, eq, val = item.strip().partition("=")
        if not eq or not path:
            _fail(f"--spread {item!r}: write PATH=STD, e.g. arm.motor.inertia=10%")
        try:
            mean = float(_get(base, parse_path(path), path))
            std = (abs(mean) * float(val.strip()[:-1]) / 100 if val.strip().endswith("%")
                   else float(val))
        except (ValueError, TypeError) as exc:
            _fail(f"--spread {item!r}: {exc}")
        if not (math.isfinite(std) and std >= 0):
            _fail(f"--spread {item!r}: the std must be a finite number >= 0")
        out[path] = (mean, std)
    return out


@app.command("design")
def design_cmd(ctx: typer.Context, scenario: str = typer.Argument(..., help="scenario TOML file or built-in name (a fitted rig's scenario)"),
               method: str = typer.Option("lqr", "--method", help="lqr, place, nested (Feliu's two loops) or tune (the controller's gains over plants drawn from the fit's uncertainty)"),
               out: Path = typer.Option(..., "--out", help="folder for design.toml, design.json and the step figure"),
               q: Optional[str] = typer.Option(
                   None, "--q", help="lqr output weights, CHANNEL=W,... (int_CHANNEL for an "
                                     "integrator) or one number per channel; default Bryson"),
               r: Optional[str] = typer.Option(None, "--r", help="lqr command weight(s); default 1/limit²"),
               poles: Optional[str] = typer.Option(
                   None, "--poles", help="place: closed-loop poles of the arm's states (+ integrators), "
                                         "e.g. '-20+15j,-20-15j,-30,-40'"),
               observer_poles: Optional[str] = typer.Option(
                   None, "--observer-poles", help="observer poles of the arm's states (default: Kalman predictor)"),
               pole_domain: str = typer.Option("s", "--pole-domain", help="s (rad/s, z = exp(sT)) or z"),
               integral: bool = typer.Option(False, "--integral/--no-integral",
                                             help="integrators of the tracked channels' errors (LQI)"),
               disturbance: Optional[bool] = typer.Option(
                   None, "--disturbance/--no-disturbance",
                   help="estimate and cancel a constant input disturbance (integral action; "
                        "default: on unless --integral)"),
               friction_compensation: bool = typer.Option(
                   True, "--friction-compensation/--no-friction-compensation",
                   help="Coulomb feedforward C_f / k_u from the scenario's friction"),
               max_deflection: Optional[float] = typer.Option(
                   None, "--max-deflection", help="nested: limit of the link deflection |θm − θt| during the move, rad (default 0.1)"),
               distance: Optional[float] = typer.Option(
                   None, "--distance", help="nested: the tip move, rad (default the scenario's reference amplitude)"),
               fit_json: Optional[Path] = typer.Option(
                   None, "--fit-json", help="the fit's JSON (flexarm fit --json) of the rig whose "
                                            "--scenario-out is SCENARIO: plants drawn from its "
                                            "standard deviations (tune; and the comparison)"),
               spread: Optional[str] = typer.Option(
                   None, "--spread", help="plants drawn from PATH=STD,... (SI; STD may end in % of "
                                          "the scenario's value), e.g. "
                                          "'arm.motor.inertia=10%,arm.friction.coulomb=0.005'"),
               plants: int = typer.Option(200, "--plants", help="number of plants drawn"),
               seed: int = typer.Option(0, "--seed", help="seed of the plant draws"),
               encoder_counts: Optional[int] = typer.Option(
                   None, "--encoder-counts", help="counts per turn of the hub encoder, where the "
                                                  "scenario's hub sensor has no quantum (errors in counts)"),
               report: Optional[Path] = typer.Option(
                   None, "--report", help="write a self-contained HTML report (the designed "
                                          "controller, its figures, the step comparison)"),
               overwrite: bool = typer.Option(False, help="write into a non-empty --out folder")) -> None:
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
    compare.json / compare.md (the comparison) and its figures; --report an HTML page."""
    _enable_cache()
    from flexarm.design import METHODS, design

    if method not in METHODS:
        _fail(f"--method {method!r}: not known; choose one of {', '.join(METHODS)}")
    if pole_domain not in ("s", "z"):
        _fail(f"--pole-domain {pole_domain!r}: give s (continuous-time poles, rad/s) or z")
    if method == "place" and poles is None:
        _fail("--method place needs --poles (the closed-loop poles of the arm's states, "
              "e.g. --poles '-20+15j,-20-15j,-30,-40'; flexarm design ... --method lqr shows "
              "the model's states in design.json)")
    if method != "place" and poles is not None:
        _fail(f"--poles: only with --method place (got --method {method})")
    if method == "place" and (q is not None or r is not None):
        _fail("--q/--r: only with --method lqr (place takes --poles)")
    if method == "nested":
        given = [o for o, v in (("--q", q), ("--r", r), ("--observer-poles", observer_poles),
                                ("--integral", integral or None), ("--disturbance", disturbance))
                 if v is not None]
        if given:
            _fail(f"{', '.join(given)}: only with --method lqr or place (the nested loops take "
                  "--max-deflection and --distance)")
    elif max_deflection is not None or distance is not None:
        _fail("--max-deflection/--distance: only with --method nested")
    if method == "tune" and fit_json is None and spread is None:
        _fail("--method tune needs the plants' spread: --fit-json FIT.json (the rig's fit) or "
              "--spread PATH=STD,...")
    if fit_json is not None and spread is not None:
        _fail("--fit-json and --spread both give the plants' spread; choose one")
    if plants < 1:
        _fail(f"--plants {plants}: give at least 1 plant (200 for the issue's comparison)")
    if encoder_counts is not None and encoder_counts < 2:
        _fail(f"--encoder-counts {encoder_counts}: give the counts per turn (e.g. 4096)")
    _check_file_option("--report", report, overwrite, "design.html")
    sc = _load(scenario)
    spread_d = _plant_spread(sc, fit_json, spread)
    out = _outdir(out, overwrite)
    if integral and disturbance:
        _fail("--integral and --disturbance both give integral action; choose one")
    count = 2 * math.pi / encoder_counts if encoder_counts else None
    if method == "nested":
        opts = {k: v for k, v in (("max_deflection", max_deflection), ("distance", distance))
                if v is not None}
    elif method == "tune":
        opts = {}  # the plants below (tune needs --fit-json or --spread: checked above)
    else:
        opts = dict(integral=integral, disturbance=disturbance,
                    friction_compensation=friction_compensation, pole_domain=pole_domain,
                    observer_poles=_complex_list(observer_poles, "--observer-poles"))
    if method == "place":
        opts["poles"] = _complex_list(poles, "--poles")
    elif method == "lqr":
        opts.update(q=_weights(q, "--q"), r=_weights(r, "--r"))
    from flexarm.design.compare import compare
    from flexarm.design.plants import PlantBatch, from_paths

    with console.status(f"designing ({method})...") as status:
        try:  # the plants, drawn once: tuned over (tune), made robust over (lqr), compared on
            drawn = from_paths(sc, spread_d, plants, seed=seed) if spread_d else None
        except ValueError as exc:
            _fail(f"--fit-json/--spread: {exc}")
        if drawn is not None and method in ("lqr", "tune"):
            opts.update(plants=drawn, count=count)
        if method == "tune":
            opts["callback"] = lambda e: _progress(
                status, f"tuning: {e['nfev']} batch runs, best cost {e['best']:.4g}")
        try:
            des = design(sc, method, **opts)
        except ValueError as exc:
            _fail(f"{scenario}: {exc}")
        batch = drawn if drawn is not None else PlantBatch.nominal_only(sc)
        _progress(status, "the scenario's controller and the design on a reference step "
                          f"(nominal plant{f' and {plants} drawn' if spread_d else ''})...")
        side = None
        try:
            side = compare(batch, {method: des}, logged="scenario", count=count,
                           duration=max(3.0, float(sc.simulation.duration)))
        except (ValueError, KeyError) as exc:
            des.warnings.append(f"comparison not run: {exc}")
    if side is not None:
        des.info["comparison"] = side.to_dict()["rows"]
    files = des.write(out, overwrite=overwrite)
    if side is not None:
        from flexarm.io.write import write_json, write_text

        files += [write_json(out / "compare.json", side.to_dict(), overwrite=overwrite),
                  write_text(out / "compare.md", side.table("markdown") + "\n",
                             overwrite=overwrite),
                  *side.figures(out, overwrite=overwrite)]
        from flexarm.design.compare import METRICS, _fmt

        drawn = side.settings["n_plants"] > 0
        cols = ("nominal", "median", "worst") if drawn else ("nominal",)
        tab = Table(title=(f"a {side.settings['step_rad']:g} rad step: nominal / median / worst "
                           f"over {plants} drawn plants" if drawn else
                           f"a {side.settings['step_rad']:g} rad step on the nominal plant"))
        tab.add_column("controller")
        for title, unit, _ in METRICS.values():
            tab.add_column(f"{title} [{unit}]")
        if drawn:
            tab.add_column("unstable")
        tab.add_column("limit ok")
        for name, row in side.rows.items():
            tab.add_row(name, *[" / ".join(_fmt(row[k][m]) for k in cols) for m in METRICS],
                        *([f"{row['unstable']}/{row['n_plants']}"] if drawn else []),
                        "yes" if row["limit_respected"] else "NO")
        console.print(tab)
        des.warnings.extend(w for w in side.warnings if w not in des.warnings)
    info = des.info
    if "model" in info:
        console.print(f"augmented model: {info['model']['n_augmented']} states "
                      f"(arm {info['model']['n_arm']}); linear peak command "
                      f"{', '.join(f'{v:.3g}' for v in info['step']['peak_command'])}")
    for w in des.warnings:
        err.print(f"[yellow]warning:[/] {escape(w)}", highlight=False)
    console.print("wrote " + ", ".join(str(p) for p in files))
    if report is not None:
        from flexarm.analysis.html_report import design_report

        _write_report(design_report(des, figures=[p for p in files if str(p).endswith(".png")],
                                    comparison=side, command=_command_line(ctx),
                                    inputs=[scenario]), report, overwrite)


@app.command("scenario-from-mat")
def scenario_from_mat(workspace: Path = typer.Argument(..., help="the lab's MATLAB workspace (.mat) of a two-link flexible arm"),
                      out: Path = typer.Option(..., "--out", help="scenario TOML to write"),
                      current_limits: str = typer.Option(
                          "0.94,1.2", help="the amplifiers' current limits per joint, A (not in the file)"),
                      overwrite: bool = typer.Option(False, help="replace an existing --out file")) -> None:
    """A two-link scenario (quanser-two-link's layout) from a lab workspace's parameters."""
    from flexarm.io.logs import LogError
    from flexarm.io.workspace import scenario_from_workspace
    from flexarm.io.write import write_toml
    from flexarm.specs import ScenarioError, scenario_from_dict

    _check_file_option("--out", out, overwrite)
    try:
        lims = [float(x) for x in current_limits.split(",")]
    except ValueError:
        lims = []
    if len(lims) != 2 or not min(lims) > 0:
        _fail(f"--current-limits {current_limits!r}: give two positive currents in A, e.g. 0.94,1.2")
    try:
        data = scenario_from_workspace(workspace, current_limits=(lims[0], lims[1]))
        scenario_from_dict(data, source=str(workspace))
        write_toml(out, data, overwrite=overwrite)
    except (LogError, ScenarioError) as exc:
        _fail(str(exc))
    console.print(f"{out}: scenario {data['name']!r} from {workspace}")


REPRODUCTIONS = {"feliu": "Feliu, Rattan & Brown 1993, Figs. 11-19",
                 "deluca": "De Luca & Siciliano 1993, Fig. 2 and the example"}


def _reproduction(name: str):
    import importlib

    if name not in REPRODUCTIONS:
        _fail(f"reproduce {name!r}: choose one of {', '.join(REPRODUCTIONS)}")
    try:
        return importlib.import_module(f"flexarm.reproduce.{name}").run
    except ModuleNotFoundError:
        _fail(f"reproduce {name!r} is not available in this version")


def _run_reproduction(name: str, out: Path) -> dict:
    from rich.progress import Progress

    run = _reproduction(name)
    with Progress(console=err) as bar:
        task = bar.add_task(name, total=None)

        def progress(done, total=None, what=""):
            bar.update(task, completed=done, total=total, description=f"{name}: {what}")

        return run(out, progress=progress)


@app.command()
def reproduce(paper: str = typer.Argument(..., help=" | ".join(REPRODUCTIONS)),
              out: Path = typer.Option(..., "--out", help="folder for figures and the table"),
              overwrite: bool = typer.Option(False, help="write into a non-empty --out folder")) -> None:
    """Re-run a paper's experiments on the simulated arms: figures, and a table of each
    reported quantity, the paper's value, ours and the ratio."""
    _enable_cache()
    _reproduction(paper)
    out = _outdir(out, overwrite)
    res = _run_reproduction(paper, out)
    md = out / f"{paper}_table.md"
    if md.exists():
        console.print(md.read_text(), markup=False)
    console.print(f"wrote {out}/ ({len(res.get('figures', []))} figures)")


@app.command()
def demo(out: Path = typer.Option(Path("out/demo"), "--out", help="output folder (flexarm's own; rewritten)")) -> None:
    """The main job on the built-in default: model, simulations and figures into --out."""
    _enable_cache()
    from flexarm.analysis.summary import run_demo

    _check_dir_option("--out", out)
    out.mkdir(parents=True, exist_ok=True)
    import importlib.util

    reps = {n: (lambda d, n=n: _run_reproduction(n, d)) for n in REPRODUCTIONS
            if importlib.util.find_spec(f"flexarm.reproduce.{n}") is not None}
    run_demo(out, console, reproductions=reps)


def _pairs(items: list[str] | None, what: str) -> dict[str, str]:
    out = {}
    for it in items or []:
        if "=" not in it:
            _fail(f"--{what} {it!r}: expected NAME=VALUE, e.g. --{what} current=i_m")
        k, v = it.split("=", 1)
        out[k.strip()] = v.strip()
    return out


def _filters(items: list[str] | None) -> dict[str, float] | None:
    out = {}
    for k, v in _pairs(items, "filter").items():
        try:
            out[k] = float(v)
        except ValueError:
            _fail(f"--filter {k}={v}: the cutoff must be a number in Hz, e.g. --filter {k}=50")
    return out or None


def _progress(status, message: str) -> None:
    """A long job's stage: on the status line, and as a plain line on stderr when that is
    not a terminal (a log file or a pipe: the status line is not drawn there)."""
    status.update(message)
    if not err.is_terminal:
        err.print(message, highlight=False)


def _window(text: str | None, option: str) -> tuple[float, float] | None:
    """``START:STOP`` (s from a log's first sample) → (start, stop)."""
    if not text:
        return None
    try:
        a, b = (float(x) for x in text.split(":"))
    except ValueError:
        _fail(f"{option} {text!r}: expected START:STOP in seconds from the log's first "
              "sample, e.g. 0:5")
    if not (b > a >= 0):
        _fail(f"{option} {text!r}: need 0 <= START < STOP (s)")
    return a, b


def _bench_logs(paths: list[Path], column, unit, controller, max_jitter: float,
                log_format: Path | None = None, use_regressed: bool = False):
    """Bench logs read with the --column / --unit mappings (SI inside), --controller,
    --max-jitter and --log-format; the declared law is checked against each log's command
    (bench.controller_check) when it has one, and replaced by the regressed law with
    --use-regressed-law."""
    from flexarm.identification.time_domain.controller_check import check_controller
    from flexarm.identification.time_domain.logs import read_bench_log

    if not (max_jitter > 0):
        _fail(f"--max-jitter {max_jitter}: must be > 0 (a relative deviation, e.g. 0.05)")
    cols, units = _pairs(column, "column") or None, _pairs(unit, "unit") or None
    logs = [read_bench_log(p, columns=cols, units=units, controller=controller,
                           max_jitter=max_jitter, log_format=log_format) for p in paths]
    out = []
    for log in logs:
        if log.gains is None or "voltage" not in log.columns or "motor_angle" not in log.columns:
            out.append(log)
            continue
        chk = check_controller(log, use_regressed=use_regressed)
        err.print(escape(chk.summary()))
        out.append(chk.apply(log) if use_regressed else log)
    return out


def _floats(text: str | None, what: str) -> list[float]:
    if not text:
        return []
    try:
        return [float(x) for x in text.replace(";", ",").split(",") if x.strip()]
    except ValueError:
        _fail(f"{what} {text!r}: expected numbers separated by commas (rad/s)")


@app.command()
def experiment(scenario: str = typer.Argument(..., help="scenario TOML file or built-in name"),
               out: Path = typer.Option(..., "--out", help="folder for one CSV per experiment"),
               frequencies: Optional[str] = typer.Option(
                   None, help="excitation frequencies in rad/s, comma separated; give ω0 "
                   "and 3ω0 pairs (default: pairs chosen from the model)"),
               periods: int = typer.Option(20, help="whole periods recorded per experiment"),
               kp: Optional[float] = typer.Option(None, help="PD gain, command units per rad"),
               kd: Optional[float] = typer.Option(None, help="PD gain, command units*s/rad"),
               overwrite: bool = typer.Option(False, help="replace existing CSV files")) -> None:
    """Sine experiments on the simulated arm, as FRB Sec. II-A: one CSV per frequency."""
    _enable_cache()
    from rich.progress import Progress

    from flexarm.identification.frequency_domain.experiments import SineDesign, run_sine_experiments

    _check_dir_option("--out", out)
    sc = _load(scenario)
    design = SineDesign(frequencies=_floats(frequencies, "--frequencies"), periods=periods,
                        kp=kp, kd=kd)
    try:
        with Progress(console=err) as bar:
            task = bar.add_task("experiments", total=None)
            paths = run_sine_experiments(
                sc, out, design, overwrite=overwrite,
                progress=lambda label, d, tot: bar.update(task, description=label,
                                                          completed=d, total=tot))
    except (ValueError, FileExistsError) as exc:
        _fail(str(exc))
    console.print(f"wrote {len(paths)} experiment(s) into {out}/")


@app.command()
def identify(files: list[Path] = typer.Argument(..., help="CSV logs, or one folder of them"),
             motor_constant: str = typer.Option(..., "--motor-constant",
                                                help="K, e.g. 0.24676 (N*m/A) or '2.184 lbf*in/A'"),
             json_out: Optional[Path] = typer.Option(None, "--json", help="write the result as JSON"),
             plots: Optional[Path] = typer.Option(None, help="folder for the Bode figures"),
             scenario_out: Optional[Path] = typer.Option(
                 None, "--scenario-out", help="write the identified arm as a scenario TOML"),
             current_limit: Optional[str] = typer.Option(None, help="amplifier limit for the scenario"),
             column: Optional[list[str]] = typer.Option(None, help="map a column: current=i_m"),
             unit: Optional[list[str]] = typer.Option(None, help="a column's unit: current=mA"),
             motor_orders: str = typer.Option("2,4", help="zeros,poles of G_m (poles incl. the integrator)"),
             beam_orders: str = typer.Option("0,2", help="zeros,poles of G_b"),
             structured: Optional[bool] = typer.Option(
                 None, "--structured/--free",
                 help="G_m from the joint fit of J, V, C, C_f, or the paper's free fit to the "
                      "corrected data (default: joint fit for a one-mode beam)"),
             overwrite: bool = typer.Option(False, help="replace existing output files")) -> None:
    """Identify G_m, G_b and Coulomb friction from sine experiments (FRB Sec. II)."""
    import warnings

    from flexarm.identification.frequency_domain.identify import identify as run_identify
    from flexarm.identification.frequency_domain.harmonics import IdentificationError

    _check_file_option("--json", json_out, overwrite)
    _check_file_option("--scenario-out", scenario_out, overwrite, "arm.toml")
    _check_dir_option("--plots", plots)
    src = files[0] if len(files) == 1 else files
    mo = tuple(int(x) for x in motor_orders.split(","))
    bo = tuple(int(x) for x in beam_orders.split(","))
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            res = run_identify(src, motor_constant, motor_orders=mo, beam_orders=bo,
                               columns=_pairs(column, "column") or None,
                               units=_pairs(unit, "unit") or None, structured=structured)
    except (IdentificationError, ValueError) as exc:
        _fail(str(exc))
    for w in caught:
        err.print(f"[yellow]warning:[/] {escape(str(w.message))}")
    d = res.to_dict()
    if json_out is not None:
        res.to_json(json_out, overwrite=overwrite)
    if plots is not None:
        res.bode_figures(plots)
    if scenario_out is not None:
        from flexarm.io.write import write_toml

        write_toml(scenario_out, _scenario_file(res, current_limit), overwrite=overwrite)
    cf = d["coulomb_current"]
    console.print(f"Coulomb friction: {cf:.4g} A ({d['coulomb_torque']:.4g} N*m)" if cf is not None
                  else "Coulomb friction: not estimated (no ω0/3ω0 pair)")
    console.print(f"G_m num = {_fmt(d['motor_tf']['num'])}\n    den = {_fmt(d['motor_tf']['den'])}"
                  f"  ({d['motor_tf_method']})")
    console.print(f"G_b num = {_fmt(d['beam_tf']['num'])}\n    den = {_fmt(d['beam_tf']['den'])}")


@app.command()
def fit(ctx: typer.Context, logs: list[Path] = typer.Argument(
            ..., help="closed-loop CSV logs of one recording session; or SCENARIO LOG...: a "
                      "scenario (TOML file or built-in name) as the model template, then its "
                      "logs (the general fit: --free, --prior, --segment)"),
        drive: str = typer.Option("voltage", help="voltage or current"),
        gear_ratio: float = typer.Option(1.0, help="K_g"),
        motor_constant: Optional[float] = typer.Option(None, help="K_m, V*s/rad (voltage) or N*m/A (current)"),
        armature_resistance: Optional[float] = typer.Option(None, help="R, ohm"),
        link_length: Optional[float] = typer.Option(None, help="link length, m"),
        gear_efficiency: float = typer.Option(1.0), motor_efficiency: float = typer.Option(1.0),
        voltage_limit: float = typer.Option(10.0, help="amplifier limit, V"),
        controller: Optional[str] = typer.Option(
            None, help="overrides the logs' '# controller:' line, e.g. 'state_feedback K1=6 K2=-3 K3=0.2 K4=0'"),
        mode: str = typer.Option("closed_loop", help="closed_loop, or open_loop (replay the logged voltage)"),
        no_friction: bool = typer.Option(False, "--no-friction", help="fit without joint friction (for comparison)"),
        json_out: Optional[Path] = typer.Option(None, "--json", help="write the result as JSON"),
        scenario_out: Optional[Path] = typer.Option(None, "--scenario-out", help="write the fitted scenario TOML"),
        plots: Optional[Path] = typer.Option(None, help="folder for overlay figures"),
        seconds: float = typer.Option(5.0, help="time budget of the global stage, s"),
        compare_no_friction: bool = typer.Option(
            False, "--compare-no-friction",
            help="also fit without joint friction and report both fits side by side"),
        column: Optional[list[str]] = typer.Option(
            None, help="map a column to the log's name: motor_angle=theta"),
        unit: Optional[list[str]] = typer.Option(
            None, help="unit of a column's numbers: motor_angle=deg, tip_deflection=mm"),
        sessions: Optional[str] = typer.Option(
            None, help="recording session of each log, e.g. 0,0,1: mechanics shared, friction per session"),
        tip_sign: Optional[int] = typer.Option(None, help="sign of the strain gauge, +1 or -1, if known"),
        encoder_counts: Optional[int] = typer.Option(
            None, help="hub encoder counts per revolution (default: detected from the steps)"),
        filter: Optional[list[str]] = typer.Option(
            None, help="known analog low-pass cutoff of a sensor, Hz: tip_deflection=50"),
        max_jitter: float = typer.Option(
            1e-3, help="accepted relative deviation of a time step from the median step"),
        delay_search: str = typer.Option(
            "neighbours", help="how the tip delay is chosen: neighbours, profile, or both "
                               "(two starts, about twice the time: when it may be far off)"),
        polish_iter: int = typer.Option(
            8, help="generations of the friction polish (20 with --delay-search both)"),
        overwrite: bool = typer.Option(False, help="replace existing output files"),
        log_format: Optional[list[str]] = typer.Option(
            None, "--log-format", help="the logger's log-format TOML (columns, units, gains); "
                                       "with SCENARIO: once per log, or PATTERN=FILE by file name"),
        use_regressed_law: bool = typer.Option(
            False, "--use-regressed-law",
            help="use the law regressed on the logged command where it disagrees with the "
                 "declared one"),
        window: Optional[str] = typer.Option(
            None, help="fit on this part of every log only, START:STOP in s from its first "
                       "sample, e.g. 0:5"),
        free: Optional[list[str]] = typer.Option(
            None, "--free", help="with SCENARIO: a parameter to fit, as a path into the scenario "
                                 "(repeat), e.g. 'arm.joints[*].friction.coulomb'"),
        prior: Optional[list[str]] = typer.Option(
            None, "--prior", help="with SCENARIO: PATH=REL_STD, a data-sheet prior (the "
                                  "scenario's value, ± REL_STD relative), e.g. "
                                  "'arm.joints[0].drive.torque_constant=0.3'"),
        segment: Optional[float] = typer.Option(
            None, "--segment", help="with SCENARIO: multiple-shooting segment length, s"),
        channel: Optional[list[str]] = typer.Option(
            None, "--channel", help="with SCENARIO: a measured channel to fit, NAME or "
                                    "NAME=WEIGHT (repeat; default: every logged sensor channel)"),
        max_nfev: int = typer.Option(30, "--max-nfev", help="with SCENARIO: least-squares budget"),
        validate_window: Optional[str] = typer.Option(
            None, "--validate-window",
            help="then predict this held-out part of every log (START:STOP, s; each "
                 "part's initial state estimated from its own data) and report its fit %"),
        report: Optional[Path] = typer.Option(
            None, "--report", help="write a self-contained HTML report (parameters ± std, "
                                   "fit %, warnings, figures embedded), e.g. fit.html")
        ) -> None:
    """Fit a physical model with joint friction to closed-loop logs (time domain).

    With a scenario first (``flexarm fit SCENARIO LOG... --free PATH ...``): the general fit
    of any arm the scenario describes (identification.time_domain.fit_scenario)."""
    _enable_cache()
    from flexarm.specs.scenario import names_a_scenario

    if logs and names_a_scenario(str(logs[0])):
        _fit_scenario_cli(str(logs[0]), logs[1:], log_format, free, prior, segment, channel,
                          window, max_nfev, json_out, scenario_out, plots, overwrite, report,
                          ctx)
        return
    if free or prior or segment is not None or channel:
        _fail("--free, --prior, --segment and --channel belong to the general fit: give the "
              "scenario first, flexarm fit SCENARIO LOG... --free PATH")
    if log_format and len(log_format) > 1:
        _fail("--log-format is given once for the bench fit (every log has one format)")
    log_format = Path(log_format[0]) if log_format else None
    from flexarm.identification.time_domain import FitInputError
    from flexarm.identification.time_domain import fit as run_fit
    from flexarm.errors import FitInterrupted
    from flexarm.io.write import write_json

    _check_file_option("--json", json_out, overwrite)
    _check_file_option("--scenario-out", scenario_out, overwrite, "arm.toml")
    _check_file_option("--report", report, overwrite, "fit.html")
    _check_dir_option("--plots", plots)
    if tip_sign not in (None, 1, -1):
        _fail(f"--tip-sign {tip_sign}: expected +1 or -1 (or leave it out to fit it)")
    sess = None
    if sessions is not None:
        try:
            sess = [int(x) for x in sessions.replace(";", ",").split(",") if x.strip()]
        except ValueError:
            _fail(f"--sessions {sessions!r}: expected whole numbers, one per log, e.g. 0,0,1")
    kw = dict(drive=drive, gear_ratio=gear_ratio, motor_constant=motor_constant,
              armature_resistance=armature_resistance, link_length=link_length,
              gear_efficiency=gear_efficiency, motor_efficiency=motor_efficiency,
              voltage_limit=voltage_limit, mode=mode, global_seconds=seconds,
              sessions=sess, tip_sign=tip_sign, encoder_counts=encoder_counts,
              filters=_filters(filter), delay_search=delay_search, polish_iter=polish_iter)
    res = res0 = held = None
    win, vwin = _window(window, "--window"), _window(validate_window, "--validate-window")
    try:
        full = _bench_logs(logs, column, unit, controller, max_jitter, log_format,
                           use_regressed_law)
        blogs = [g.window(*win) for g in full] if win else full
        held_logs = [g.window(*vwin) for g in full] if vwin else []
        with console.status("fitting") as status:
            res = run_fit(blogs, friction=not no_friction,
                          progress=lambda m: _progress(status, m), **kw)
            if compare_no_friction and not no_friction:
                status.update("fitting again without joint friction")
                res0 = run_fit(blogs, friction=False, **kw)
            if held_logs:
                from flexarm.identification.time_domain import predict

                status.update("predicting the held-out windows")
                held = predict(res, held_logs)
    except (FitInputError, ValueError) as exc:
        _fail(str(exc))
    except FitInterrupted as exc:
        _fit_interrupted(json_out, overwrite, res, exc.result)
    except KeyboardInterrupt:
        _fit_interrupted(json_out, overwrite, res, None)
    console.print(escape(res.summary()))
    if res0 is not None:
        t = Table("log", "signal", "fit % with friction", "fit % without")
        for name, d in res.fit_percent.items():
            for sig, v in d.items():
                v0 = res0.fit_percent.get(name, {}).get(sig)
                t.add_row(name, sig, f"{v:.1f}" if v is not None else "-",
                          f"{v0:.1f}" if v0 is not None else "-")
        console.print(t)
    if held is not None:
        t = Table("held-out log " + (validate_window or ""), "motor_angle fit %",
                  "tip_deflection fit %")
        for name, d in held["fit_percent"].items():
            t.add_row(name, *(f"{d[k]:.1f}" if d.get(k) is not None else "-"
                              for k in ("motor_angle", "tip_deflection")))
        console.print(t)
    if json_out is not None:
        d = res.to_dict()
        if res0 is not None:
            d["without_friction"] = _without_friction(res0)
        if win:
            d["window_s"] = list(win)
        if held is not None:
            d["held_out"] = {"window_s": list(vwin), "fit_percent": held["fit_percent"],
                             "diverged": held["diverged"],
                             "initial_state": "estimated from each window's own data"}
        write_json(json_out, d, overwrite=overwrite)
    if scenario_out is not None:
        res.write_scenario(scenario_out, overwrite=overwrite)
    with _figure_folder(plots, report) as folder:
        if folder is None:
            return
        figs = res.plots(folder)
        if held is not None:
            from flexarm.identification.time_domain.report import overlay_plots

            figs += overlay_plots(folder, held["logs"], held["traj"], held["fit_percent"],
                                  "held-out")
        if report is not None:
            from flexarm.analysis.html_report import fit_report

            extra = {}
            if held is not None:
                extra[f"Fit % of the held-out windows {validate_window} s"] = held["fit_percent"]
            if res0 is not None:
                extra["Fit % of the fit without joint friction"] = res0.fit_percent
            _write_report(fit_report(res, figures=figs, command=_command_line(ctx),
                                     inputs=[*logs, *([log_format] if log_format else [])],
                                     extra_fit_percent=extra), report, overwrite)


@app.command()
def validate(ctx: typer.Context, scenario: str = typer.Argument(..., help="fitted scenario TOML"),
             logs: list[Path] = typer.Argument(..., help="CSV logs to replay"),
             json_out: Optional[Path] = typer.Option(None, "--json", help="write the fit % as JSON"),
             plots: Optional[Path] = typer.Option(None, help="folder for overlay figures"),
             controller: Optional[str] = typer.Option(None, help="overrides the logs' controller line"),
             column: Optional[list[str]] = typer.Option(
                 None, help="map a column to the log's name: motor_angle=theta"),
             unit: Optional[list[str]] = typer.Option(
                 None, help="unit of a column's numbers: motor_angle=deg"),
             max_jitter: float = typer.Option(
                 1e-3, help="accepted relative deviation of a time step from the median step"),
             overwrite: bool = typer.Option(False, help="replace an existing JSON file"),
             log_format: Optional[list[str]] = typer.Option(
                 None, "--log-format", help="the logger's log-format TOML (columns, units, "
                                            "gains); once per log, or PATTERN=FILE"),
             use_regressed_law: bool = typer.Option(
                 False, "--use-regressed-law",
                 help="use the law regressed on the logged command where it disagrees with "
                      "the declared one"),
             window: Optional[str] = typer.Option(
                 None, help="replay this part of every log only, START:STOP in s from its "
                            "first sample, e.g. 5:10"),
             refit: Optional[str] = typer.Option(
                 None, "--refit", help="'friction': re-estimate only the joints' friction on "
                                       "--refit-window of the first log, then validate with "
                                       "everything else fixed (reports both)"),
             refit_window: str = typer.Option(
                 "0:5", "--refit-window", help="the part of the first log the refit uses, "
                                               "START:STOP in s"),
             channel: Optional[list[str]] = typer.Option(
                 None, "--channel", help="measured channel to compare (repeat; default: every "
                                         "logged sensor channel)"),
             report: Optional[Path] = typer.Option(
                 None, "--report", help="write a self-contained HTML report (fit %, warnings, "
                                        "figures embedded), e.g. validate.html")) -> None:
    """Replay logs on a scenario and report fit % = 100 (1 − ‖y − ŷ‖/‖y − mean y‖).

    A multi-link scenario, or --refit, takes the general path (any arm, logs read by
    --log-format, the prediction from each log's logged state)."""
    _enable_cache()
    sc0 = _load(scenario)
    if sc0.arm.kind == "multi_link" or refit is not None:
        _validate_scenario_cli(sc0, logs, log_format, window, refit, refit_window, channel,
                               json_out, plots, overwrite, report, ctx)
        return
    if log_format and len(log_format) > 1:
        _fail("--log-format is given once for a bench scenario's logs")
    log_format = Path(log_format[0]) if log_format else None
    from flexarm.identification.time_domain import FitInputError
    from flexarm.identification.time_domain import validate as run_validate

    _check_file_option("--json", json_out, overwrite)
    _check_file_option("--report", report, overwrite, "validate.html")
    _check_dir_option("--plots", plots)
    sc = _load(scenario)
    with _figure_folder(plots, report) as folder:
        try:
            win = _window(window, "--window")
            blogs = _bench_logs(logs, column, unit, controller, max_jitter, log_format,
                                use_regressed_law)
            out = run_validate(sc, [g.window(*win) for g in blogs] if win else blogs,
                               plots=folder)
        except (FitInputError, ValueError) as exc:
            _fail(str(exc))
        if report is not None:
            from flexarm.analysis.html_report import validate_report

            _write_report(validate_report(out, scenario=scenario, figures=out["plots"],
                                          command=_command_line(ctx),
                                          inputs=[scenario, *logs,
                                                  *([log_format] if log_format else [])]),
                          report, overwrite)
        if plots is None:
            out["plots"] = []
    t = Table("log", "motor_angle fit %", "tip_deflection fit %")
    for name, d in out["fit_percent"].items():
        t.add_row(name, *(f"{d.get(k, float('nan')):.1f}" for k in ("motor_angle", "tip_deflection")))
    console.print(t)
    if json_out is not None:
        from flexarm.io.write import write_json

        write_json(json_out, out, overwrite=overwrite)


def _general_logs(paths: list[Path], log_format: Optional[list[str]]) -> list:
    """Read each log with its format: --log-format once per log (in order), one for all,
    or PATTERN=FILE (fnmatch on the file name; the first match wins)."""
    import fnmatch

    from flexarm.io.logformat import LogFormat, load_log_format

    if not paths:
        _fail("no logs given: flexarm fit SCENARIO LOG... (one or more log files)")
    specs = list(log_format or [])
    pats = [x.split("=", 1) for x in specs if "=" in x]
    plain = [x for x in specs if "=" not in x]
    if pats and plain:
        _fail("--log-format: give either one FILE per log (or one for all), or PATTERN=FILE "
              f"entries, not both (got {specs})")
    if plain and len(plain) not in (1, len(paths)):
        _fail(f"--log-format given {len(plain)} times for {len(paths)} logs: give it once for "
              "all, once per log in order, or as PATTERN=FILE")
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
                _fail(f"{p}: no --log-format PATTERN matches its name (patterns: "
                      f"{', '.join(pat for pat, _ in pats)})")
            f = hit[0]
        else:
            f = plain[0] if len(plain) == 1 else (plain[i] if plain else None)
        out.append(fmt(f).read(p))
    return out


def _channels(channel: Optional[list[str]]) -> dict | None:
    if not channel:
        return None
    out = {}
    for c in channel:
        name, _, w = c.partition("=")
        try:
            out[name.strip()] = float(w) if w else 1.0
        except ValueError:
            _fail(f"--channel {c!r}: expected NAME or NAME=WEIGHT (a number)")
    return out


def _priors(prior: Optional[list[str]]) -> dict:
    out = {}
    for x in prior or []:
        path, _, v = x.rpartition("=")
        try:
            out[path.strip()] = float(v)
        except ValueError:
            path = ""
        if not path:
            _fail(f"--prior {x!r}: expected PATH=REL_STD, e.g. "
                  "'arm.joints[0].drive.torque_constant=0.3'")
    return out


def _fit_scenario_cli(scenario: str, logs: list[Path], log_format, free, prior, segment,
                      channel, window, max_nfev, json_out, scenario_out, plots,
                      overwrite, report=None, ctx=None) -> None:
    from flexarm.identification.time_domain import FitOptions, fit_scenario, predict_scenario
    from flexarm.io.logs import LogError
    from flexarm.io.write import write_json

    _check_file_option("--json", json_out, overwrite)
    _check_file_option("--scenario-out", scenario_out, overwrite, "arm.toml")
    _check_file_option("--report", report, overwrite, "fit.html")
    _check_dir_option("--plots", plots)
    sc = _load(scenario)
    win = _window(window, "--window")
    figures = contextlib.ExitStack()
    folder = figures.enter_context(_figure_folder(plots, report))
    try:
        glogs = _general_logs(logs, log_format)
        opts = FitOptions(channels=_channels(channel), priors=_priors(prior), segment=segment,
                          max_nfev=max_nfev, windows=[win] * len(glogs) if win else None)
        with console.status("fitting") as status:
            res = fit_scenario(sc, glogs, free or None, opts,
                               progress=lambda m: _progress(status, m), predict=False)
            status.update("predicting the logs with the fitted parameters")
            pred = predict_scenario(res.scenario, glogs, opts,
                                    channels=list(opts.channels) if opts.channels else None,
                                    plots=folder, tag="fit")
    except (LogError, ValueError) as exc:
        figures.close()
        _fail(str(exc))
    t = Table("parameter", "template", "fitted", "std")
    for p in res.free:
        t.add_row(p, f"{res.template[p]:.5g}", f"{res.params[p]:.5g}", f"{res.std[p]:.3g}")
    console.print(t)
    console.print(escape(res.message))
    for w in res.warnings:
        console.print(f"[yellow]warning:[/yellow] {escape(w)}")
    _fit_table(pred["fit_percent"], "whole-log prediction")
    if json_out is not None:
        write_json(json_out, {**res.to_dict(), "fit_percent": pred["fit_percent"],
                              "plots": pred["plots"] if plots is not None else []},
                   overwrite=overwrite)
    if scenario_out is not None:
        res.write_scenario(scenario_out, overwrite=overwrite)
    with figures:
        if report is not None:
            from flexarm.analysis.html_report import fit_report

            _write_report(fit_report(res, figures=pred["plots"], command=_command_line(ctx),
                                     inputs=[scenario, *logs, *(log_format or [])],
                                     fit_percent=pred["fit_percent"]),
                          report, overwrite)


def _fit_table(fp: dict, title: str) -> None:
    names = sorted({k for d in fp.values() for k in d})
    t = Table(f"fit % ({title})", *names)
    for log, d in fp.items():
        t.add_row(Path(log).name, *(f"{d[k]:.1f}" if k in d else "-" for k in names))
    console.print(t)


def _validate_scenario_cli(sc, logs, log_format, window, refit, refit_window, channel,
                           json_out, plots, overwrite, report=None, ctx=None) -> None:
    from flexarm.identification.time_domain import FitOptions, fit_scenario, predict_scenario
    from flexarm.identification.time_domain.general import friction_paths
    from flexarm.io.logs import LogError
    from flexarm.io.write import write_json

    _check_file_option("--json", json_out, overwrite)
    _check_file_option("--report", report, overwrite, "validate.html")
    _check_dir_option("--plots", plots)
    if refit not in (None, "friction"):
        _fail(f"--refit {refit!r}: only 'friction' (the joints' Coulomb, breakaway and "
              "viscous friction) can be re-estimated")
    win = _window(window, "--window")
    rwin = _window(refit_window, "--refit-window")
    out: dict = {}
    figures = contextlib.ExitStack()
    plots = figures.enter_context(_figure_folder(plots, report))
    figs: list = []
    try:
        glogs = _general_logs(logs, log_format)
        ch = _channels(channel)
        opts = FitOptions(channels=ch, windows=[win] * len(glogs) if win else None)
        with console.status("predicting") as status:
            before = predict_scenario(sc, glogs, opts, channels=list(ch) if ch else None,
                                      plots=plots, tag="validate")
            out["fit_percent"] = before["fit_percent"]
            figs += before["plots"]
            if refit:
                status.update("re-estimating the joints' friction")
                free = friction_paths(sc)
                res = fit_scenario(sc, glogs[:1], free, FitOptions(channels=ch, windows=[rwin]),
                                   predict=False)
                after = predict_scenario(res.scenario, glogs, opts,
                                         channels=list(ch) if ch else None, plots=plots,
                                         tag="refit")
                figs += after["plots"]
                out["refit"] = {"window_s": list(rwin), "log": str(logs[0]),
                                "params": {p: res.params[p] for p in free},
                                "template": {p: res.template[p] for p in free},
                                "std": {p: res.std[p] for p in free},
                                "warnings": res.warnings,
                                "fit_percent": after["fit_percent"]}
    except (LogError, ValueError) as exc:
        figures.close()
        _fail(str(exc))
    _fit_table(out["fit_percent"], "scenario as given")
    if refit:
        t = Table("friction", "scenario", "refitted", "std")
        for p in out["refit"]["params"]:
            t.add_row(p, f"{out['refit']['template'][p]:.4g}",
                      f"{out['refit']['params'][p]:.4g}", f"{out['refit']['std'][p]:.3g}")
        console.print(t)
        _fit_table(out["refit"]["fit_percent"], f"friction refitted on {refit_window} s")
    if json_out is not None:
        write_json(json_out, out, overwrite=overwrite)
    with figures:
        if report is not None:
            from flexarm.analysis.html_report import validate_report

            _write_report(validate_report(out, scenario=sc.name, figures=figs,
                                          command=_command_line(ctx),
                                          inputs=[ctx.params["scenario"], *logs,
                                                  *(log_format or [])]),
                          report, overwrite)


def _without_friction(res0) -> dict:
    return {"fit_percent": res0.fit_percent, "params": res0.params, "message": res0.message}


def _fit_interrupted(json_out: Optional[Path], overwrite: bool, res, best) -> None:
    """Ctrl-C during ``fit``: write the best result so far to --json (atomically), marked
    ``"interrupted": true, "status": "interrupted"``, say so in one line, exit 130 (the
    shell's code for SIGINT).  ``res``: the friction fit if it had finished (the
    interrupted one was then the --compare-no-friction fit), ``best``: the interrupted
    fit's best result (``None`` if none)."""
    from flexarm.io.write import write_json

    mark = {"interrupted": True, "status": "interrupted"}
    if res is not None:
        d = res.to_dict()
        d["without_friction"] = ({**_without_friction(best), **mark} if best is not None
                                 else dict(mark))
    elif best is not None:
        d = best.to_dict()
    else:
        d = {"message": "interrupted before any model was evaluated"}
    d = {**mark, **d, **mark}
    if json_out is None:
        err.print("[yellow]fit interrupted[/]: nothing written (no --json given)")
    else:
        write_json(json_out, d, overwrite=overwrite)
        what = "best result so far" if (res is not None or best is not None) else "no result"
        err.print(f"[yellow]fit interrupted[/]: {what} written to {escape(str(json_out))}, "
                  "marked \"interrupted\": true", highlight=False)
    raise typer.Exit(130)


def _scenario_file(res, current_limit) -> dict:
    """An identified arm as a complete scenario (the rest from the FRB defaults)."""
    frag = res.to_scenario_dict(current_limit=current_limit)
    frag["notes"] = {k: str(v) for k, v in frag.get("notes", {}).items()}
    frag.update({"sampling": {"period": float(res.logs[0].dt), "delay": 1},
                 "simulation": {"duration": 2.0, "substeps": 10},
                 "reference": {"type": "step", "amplitude": 0.2},
                 "controller": {"type": "pd", "kp": 10.0, "kd": 0.2}})
    frag["arm"].pop("kind", None)
    return frag


def main() -> None:  # pragma: no cover
    app()


@app.command("export-c")
def export_c(design: str = typer.Argument(..., help="design directory (holding design.toml) or a scenario TOML / built-in name"),
             out: Path = typer.Option(..., "--out", help="folder for NAME.h and NAME.c"),
             precision: str = typer.Option("double", "--precision", help="double or float"),
             name: str = typer.Option("controller", "--name", help="C prefix and file name"),
             overwrite: bool = typer.Option(False, help="replace existing NAME.h / NAME.c")) -> None:
    """Write the [controller] of a design (or scenario) as C99 for a real-time target:
    NAME.h (state struct, NAME_init, NAME_step, channel order and units) and NAME.c (the
    law, friction feedforward, saturation and D/A count); no dependencies."""
    from flexarm.deploy.c_export import ExportError, export_c as _export_c
    from flexarm.errors import OutputExistsError

    _check_dir_option("--out", out)
    try:
        code, paths = _export_c(design, out, name=name, precision=precision,
                                overwrite=overwrite)
    except (ExportError, OutputExistsError) as exc:
        _fail(str(exc))
    except ValueError as exc:
        _fail(f"{design}: {exc}")
    console.print_json(json.dumps({
        "files": [str(p) for p in paths], "precision": code.precision,
        "measured": [f"{n} ({u})" for n, u in code.measured],
        "reference": [f"{n} ({u})" for n, u in code.references],
        "u": [f"{n} ({u})" for n, u in code.outputs]}))


# --- frequency-domain identification (issue #16): excite, frf, tfest -----------------

@app.command()
def excite(out: Path = typer.Argument(..., help="CSV to write (the signal a generator plays)"),
           fs: float = typer.Option(..., "--fs", help="sampling rate, Hz"),
           period: int = typer.Option(..., "--period", help="samples per period"),
           f_min: float = typer.Option(..., "--f-min", help="lowest line, Hz"),
           f_max: float = typer.Option(..., "--f-max", help="highest line, Hz"),
           kind: str = typer.Option("random-odd", help="full | odd | random-odd | prbs | sweep"),
           grid: str = typer.Option("linear", help="linear | log"),
           phases: str = typer.Option("random", help="schroeder | random | min-crest"),
           rms: float = typer.Option(1.0, help="rms of the signal (multisine)"),
           periods: int = typer.Option(2, help="periods to play"),
           realisations: int = typer.Option(1, help="realisations (new random phases)"),
           seed: int = typer.Option(0),
           overwrite: bool = typer.Option(False, help="replace existing files")) -> None:
    """Design an excitation: writes OUT and OUT-lines.csv (excited and detection lines)."""
    import numpy as np

    from flexarm.identification.frequency_domain import excitation as ex
    try:
        if kind == "sweep":
            e = ex.swept_sine(period, fs, f_min, f_max, amplitude=rms * np.sqrt(2), periods=periods)
        else:
            e = ex.multisine(period, fs, f_min, f_max, kind=kind, grid=grid, phases=phases,
                             rms=rms, periods=periods, realisations=realisations, seed=seed)
        log, lines = ex.write_excitation(out, e, overwrite=overwrite)
    except (ValueError, FileExistsError) as exc:
        _fail(str(exc))
    console.print(f"{log}: {e.signal.shape[1]} samples × {e.signal.shape[0]} realisation(s), "
                  f"{len(e.excited)} excited and {len(e.detection)} detection lines, crest "
                  f"factor {e.crest_factor:.3f}; lines in {lines}")


@app.command()
def frf(logs: list[Path] = typer.Argument(..., help="periodic recordings (.mat or CSV); several: one realisation each, robust BLA"),
        log_format: Optional[Path] = typer.Option(None, "--log-format", help="TOML with [columns] and [units]"),
        input: str = typer.Option("current", "--input", help="flexarm name of the input"),
        output: str = typer.Option("motor_angle", "--output", help="flexarm name(s) of the outputs, comma-separated"),
        period: str = typer.Option("auto", "--period", help="samples per period, or auto"),
        lines: str = typer.Option("auto", "--lines", help="CSV of lines (from excite), or auto"),
        reference: Optional[str] = typer.Option(
            None, "--reference", help="closed loop, with --method lpm: the reference's flexarm "
                                      "name; G = G_yr/G_ur (indirect). Periodic data need none: "
                                      "the ratio of period means is already Ȳ/Ū = (Ȳ/R̄)/(Ū/R̄)"),
        method: str = typer.Option("periodic", "--method",
                                   help="periodic (multisine over whole periods) or lpm "
                                        "(local polynomial method: non-periodic or transient records)"),
        json_out: Path = typer.Option(..., "--json", help="JSON result"),
        plots: Optional[Path] = typer.Option(None, "--plots", help="folder for figures")) -> None:
    """Nonparametric FRF, noise, odd/even distortion and the BLA of a periodic recording."""
    import warnings as _w

    from flexarm.identification.frequency_domain.harmonics import IdentificationError
    from flexarm.io.matfile import read_recording
    from flexarm.identification.frequency_domain.periodic import (combine_realisations, lpm_frf,
                                                                  periodic_frf, plot_distortion)
    if method not in ("periodic", "lpm"):
        _fail(f"--method {method!r}: choose periodic or lpm")
    from flexarm.io.logs import LogError
    try:
        with _w.catch_warnings(record=True) as caught:
            _w.simplefilter("always")
            ex_lines = None
            if lines != "auto":
                txt = Path(lines).read_text().splitlines()[1:]
                ex_lines = [int(r.split(",")[0]) for r in txt if r.strip().endswith("excited")]
            names = [n.strip() for n in output.split(",") if n.strip()]
            results = []
            for log in logs:  # one realisation per recording
                sig, fs = read_recording(log, log_format)
                for n in [input] + names + ([reference] if reference else []):
                    if n not in sig:
                        _fail(f"{log}: no signal {n!r}; mapped: {', '.join(sig)}")
                if method == "lpm":
                    results.append(lpm_frf(sig[input], {n: sig[n] for n in names}, fs,
                                           input_name=input, source=str(log),
                                           reference=sig[reference] if reference else None))
                    continue
                results.append(periodic_frf(
                    sig[input], {n: sig[n] for n in names}, fs,
                    period=None if period == "auto" else int(period), lines=ex_lines,
                    input_name=input, source=str(log)))
            res = results[0] if len(results) == 1 else combine_realisations(
                results, source=", ".join(map(str, logs)))
        for c in caught:
            err.print(f"[yellow]warning:[/] {escape(str(c.message))}")
    except (IdentificationError, LogError, OSError, ValueError) as exc:
        _fail(str(exc))
    data = {"source": [str(x) for x in logs] if len(logs) > 1 else str(logs[0]),
            "realisations": len(logs), **res.to_json()}
    from flexarm.io.write import write_json
    write_json(json_out, data, overwrite=True)
    if plots is not None:
        plots.mkdir(parents=True, exist_ok=True)
        plot_distortion(res, plots / "frf-distortion.png")
    if method == "lpm":
        console.print(f"LPM: {len(res.lines)} lines {res.frequency_hz[0]:g}–"
                      f"{res.frequency_hz[-1]:g} Hz from {res.period} samples; {res.verdict()}")
        return
    console.print(f"{len(res.lines)} excited lines {res.frequency_hz[0]:g}–{res.frequency_hz[-1]:g} Hz, "
                  f"period {res.period} samples, {res.periods_used} periods used "
                  f"({res.transient_periods} transient); {res.verdict()}")


def _structure_given(st, motor_constant, resistance, gear_ratio, efficiency, length) -> dict:
    """The known constants of a structure from the CLI's data-sheet options; a clear error
    for a missing or a foreign option."""
    given = {"motor_constant": motor_constant, "armature_resistance": resistance,
             "gear_ratio": gear_ratio, "efficiency": efficiency, "length": length}
    given = {k: v for k, v in given.items() if v is not None}
    opt = {"motor_constant": "--motor-constant", "armature_resistance": "--resistance",
           "gear_ratio": "--gear-ratio", "efficiency": "--efficiency", "length": "--length"}
    extra = [opt[k] for k in given if k not in st.given and k not in st.optional_given]
    if extra:
        _fail(f"--structure {st.name} takes no {', '.join(extra)}")
    missing = [f"{opt[k]} ({st.given[k]})" for k in st.given if k not in given]
    if missing:
        _fail(f"--structure {st.name} needs the data-sheet value(s) {'; '.join(missing)}")
    return given


@app.command()
def tfest(frf_json: Path = typer.Argument(..., help="JSON written by flexarm frf"),
          poles: Optional[int] = typer.Option(None, "--poles"),
          zeros: Optional[int] = typer.Option(None, "--zeros"),
          integrators: int = typer.Option(0, "--integrators"),
          delay: bool = typer.Option(False, "--delay", help="estimate a delay"),
          structure: Optional[str] = typer.Option(
              None, "--structure", help="physical structure: two-mass, frb-single-mass "
                                        "(needs --motor-constant) or voltage-servo (needs "
                                        "--motor-constant, --resistance, --gear-ratio, --efficiency)"),
          output: Optional[str] = typer.Option(
              None, "--output", help="output(s) to fit: one for a rational model; for a "
                                     "structure a comma list (default: every output of the "
                                     "FRF the structure has)"),
          free: Optional[str] = typer.Option(None, "--free", help="structure: comma list of "
                                             "the parameters fitted (default all)"),
          fixed: list[str] = typer.Option([], "--fix", help="structure: NAME=VALUE held "
                                          "(SI; with --free, the value of a parameter not fitted)"),
          motor_constant: Optional[float] = typer.Option(
              None, "--motor-constant", help="frb-single-mass: K (N·m/A); voltage-servo: K_m (V·s/rad)"),
          resistance: Optional[float] = typer.Option(None, "--resistance", help="voltage-servo: R_m (ohm)"),
          gear_ratio: Optional[float] = typer.Option(None, "--gear-ratio", help="voltage-servo: K_g"),
          efficiency: Optional[float] = typer.Option(
              None, "--efficiency", help="voltage-servo: η = η_g η_m (gear times motor efficiency)"),
          length: Optional[float] = typer.Option(
              None, "--length", help="voltage-servo: link length L (m), for a tip_deflection output"),
          coulomb: bool = typer.Option(True, "--coulomb/--no-coulomb",
                                       help="the Coulomb level from the odd distortion "
                                            "(simulates the fitted model; a few seconds)"),
          json_out: Path = typer.Option(..., "--json", help="JSON result"),
          plots: Optional[Path] = typer.Option(None, "--plots", help="folder for figures")) -> None:
    """Fit a transfer function or a physical structure (two-mass, frb-single-mass,
    voltage-servo) to an FRF, weighted by its variances; JSON parameters.<name> = {value, std}."""
    import control as ct
    import numpy as np

    from flexarm.identification.frequency_domain.multisine_friction import SIMULATORS
    from flexarm.identification.frequency_domain.structures import STRUCTURES, fit_structure
    from flexarm.identification.frequency_domain.tfest import TFEstError
    from flexarm.identification.frequency_domain.tfest import tfest as _tfest
    try:
        d = json.loads(frf_json.read_text())
        f = np.asarray(d["frequency_hz"], float)
        outs = d["outputs"]
    except (OSError, ValueError, KeyError) as exc:
        _fail(f"{frf_json}: not an FRF JSON from flexarm frf ({exc})")
    w = 2 * np.pi * f

    def chan(name):
        o = outs[name]
        sd = o.get("total_std") or o["noise_std"]
        return np.asarray(o["re"]) + 1j * np.asarray(o["im"]), np.asarray(sd, float)

    try:
        if structure is not None:
            if structure not in STRUCTURES:
                _fail(f"--structure {structure!r}: choose one of {', '.join(STRUCTURES)}")
            st = STRUCTURES[structure]
            names = ([n.strip() for n in output.split(",") if n.strip()] if output
                     else [n for n in st.outputs if n in outs])
            for n in names:
                if n not in outs:
                    _fail(f"{frf_json}: --output {n!r} is not in the FRF; outputs: {', '.join(outs)}")
            if not names:
                _fail(f"{frf_json}: none of the FRF's outputs ({', '.join(outs)}) is an output "
                      f"of the {structure} structure ({', '.join(st.outputs)}); name them with "
                      "flexarm frf --output")
            given = _structure_given(st, motor_constant, resistance, gear_ratio, efficiency, length)
            held = {}
            for item in fixed:
                k, _, v = item.partition("=")
                try:
                    held[k.strip()] = float(v)
                except ValueError:
                    _fail(f"--fix {item!r}: write NAME=VALUE with a number (SI units)")
            chans = {n: chan(n) for n in names}
            fit = fit_structure(st, w, {n: c[0] for n, c in chans.items()},
                                {n: c[1] for n, c in chans.items()},
                                free=[x.strip() for x in free.split(",")] if free else None,
                                initial=held or None, given=given)
            out = fit.to_json()  # structure, units, given, free, outputs, cost, parameters
            if structure in SIMULATORS and coulomb and d.get("spectra") and "motor_angle" in outs:
                import warnings as _w

                from flexarm.identification.frequency_domain.harmonics import IdentificationError
                from flexarm.identification.frequency_domain.multisine_friction import (
                    coulomb_from_distortion)
                from flexarm.identification.frequency_domain.periodic import PeriodicFRF
                err.print("Coulomb level from the odd distortion: simulating the fitted model ...")
                try:
                    with _w.catch_warnings(record=True) as caught:
                        _w.simplefilter("always")
                        cf = coulomb_from_distortion(
                            PeriodicFRF.from_json(d, str(frf_json)),
                            {**fit.given, **fit.values}, structure=structure,
                            progress=lambda i, n: err.print(f"  simulation {i}", end="\r"))
                    for c in caught:
                        if "IdentificationWarning" in type(c.message).__name__:
                            err.print(f"[yellow]warning:[/] {escape(str(c.message))}")
                    err.print("")
                    fit.parameters["coulomb_current" if cf.unit == "A" else "coulomb_torque"] = {
                        "value": cf.coulomb_current, "std": cf.std}
                    out["coulomb"] = cf.to_json()
                except IdentificationError as exc:
                    err.print(f"[yellow]warning:[/] no Coulomb level: {escape(str(exc))}")
                    out["coulomb"] = {"error": str(exc)}
            elif structure in SIMULATORS and coulomb and "motor_angle" in outs:
                err.print("note: no Coulomb level: the FRF JSON has no period spectra (LPM, "
                          "several realisations, or written by an older flexarm frf)")
        elif structure is None and poles is not None and zeros is not None:
            name = output or next(iter(outs))
            if name not in outs:
                _fail(f"{frf_json}: --output {name!r} is not in the FRF; outputs: {', '.join(outs)}")
            H, sd = chan(name)
            fit = _tfest(ct.frd(H, w), poles, zeros, integrators=integrators, delay=delay, std=sd)
            out = {"output": name, "num": fit.tf.num[0][0].tolist(), "den": fit.tf.den[0][0].tolist(),
                   "unstable_poles": [str(p) for p in fit.unstable_poles]}
        else:
            _fail(f"give --poles N --zeros M, or --structure ({', '.join(STRUCTURES)})")
    except TFEstError as exc:
        _fail(f"{frf_json}: {exc}")
    out.update({"cost": fit.cost, "expected_cost": fit.expected_cost, "cost_std": fit.cost_std,
                "verdict": fit.verdict, "parameters": fit.parameters})
    inflated = any("std_inflated" in v for v in fit.parameters.values())
    out["std_note"] = ("'std': from the noise (or BLA) variances alone; 'std_inflated': std × "
                       "sqrt(cost/expected_cost), the misfit counted as extra noise (the fit is "
                       "rejected)" if inflated else "'std': from the noise (or BLA) variances")
    from flexarm.io.write import write_json
    write_json(json_out, out, overwrite=True)
    if plots is not None:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        plots.mkdir(parents=True, exist_ok=True)
        fig, ax = plt.subplots(figsize=(7, 4))
        model = fit.response(w)
        model = model if isinstance(model, dict) else {out["output"]: model}
        for nm, g in model.items():
            if nm not in outs or (structure is not None and nm not in out["outputs"]):
                continue
            o = outs[nm]
            H = np.asarray(o["re"]) + 1j * np.asarray(o["im"])
            ax.semilogx(f, 20 * np.log10(np.abs(H)), ".", label=f"{nm} data")
            ax.semilogx(f, 20 * np.log10(np.abs(g)), "-", label=f"{nm} model")
            ax.semilogx(f, 20 * np.log10(np.abs(g - H)), ":", label=f"{nm} |error|")
        ax.set_xlabel("frequency (Hz)")
        ax.set_ylabel("dB")
        ax.legend(fontsize=7)
        fig.savefig(plots / "tfest.png", dpi=120)
        plt.close(fig)
    console.print(fit.verdict)
    for name, v in fit.parameters.items():
        extra = f", inflated ± {v['std_inflated']:.4g}" if "std_inflated" in v else ""
        kind = "line scatter" if name.startswith("coulomb_") else "noise"
        console.print(f"  {name} = {v['value']:.6g} ± {v['std']:.4g} ({kind}){extra}")


@app.command()
def friction(frf_json: list[Path] = typer.Argument(
                 ..., help="FRF JSONs written by flexarm frf, one per amplitude (same "
                           "excitation lines, different levels)"),
             structure: str = typer.Option("two-mass", "--structure",
                                           help="two-mass, frb-single-mass or voltage-servo"),
             motor_constant: Optional[float] = typer.Option(
                 None, "--motor-constant", help="frb-single-mass: K (N·m/A); voltage-servo: K_m (V·s/rad)"),
             resistance: Optional[float] = typer.Option(None, "--resistance", help="voltage-servo: R_m (ohm)"),
             gear_ratio: Optional[float] = typer.Option(None, "--gear-ratio", help="voltage-servo: K_g"),
             efficiency: Optional[float] = typer.Option(None, "--efficiency",
                                                        help="voltage-servo: η = η_g η_m"),
             length: Optional[float] = typer.Option(None, "--length",
                                                    help="voltage-servo: link length L (m)"),
             iterations: int = typer.Option(3, "--iterations",
                                            help="simulator corrections of the Bussgang start (0: none)"),
             json_out: Path = typer.Option(..., "--json", help="JSON result")) -> None:
    """Coulomb friction and viscous damping from the amplitude dependence of the BLA: the
    structure fitted to each record's BLA, its viscous damping regressed on 1/σ_v
    (Bussgang), then matched with flexarm's simulator of the fitted model with friction."""
    import warnings as _w

    import numpy as np

    from flexarm.identification.frequency_domain.harmonics import IdentificationError
    from flexarm.identification.frequency_domain.multisine_friction import (
        SIMULATORS, coulomb_from_bla_amplitudes)
    from flexarm.identification.frequency_domain.periodic import PeriodicFRF
    from flexarm.identification.frequency_domain.structures import STRUCTURES, fit_structure
    from flexarm.identification.frequency_domain.tfest import TFEstError

    if structure not in SIMULATORS:
        _fail(f"--structure {structure!r}: the friction match simulates {', '.join(SIMULATORS)}")
    if len(frf_json) < 2:
        _fail("flexarm friction needs two or more FRF JSONs at different amplitudes (one "
              "amplitude: flexarm tfest --structure ... gives C_f from the odd distortion)")
    st = STRUCTURES[structure]
    given = _structure_given(st, motor_constant, resistance, gear_ratio, efficiency, length)
    frfs, fits = [], []
    for path in frf_json:
        try:
            d = json.loads(path.read_text())
            frf = PeriodicFRF.from_json(d, str(path))
        except (OSError, ValueError, KeyError, IdentificationError) as exc:
            _fail(f"{path}: not an FRF JSON from flexarm frf ({exc})")
        if not frf.spectra:
            _fail(f"{path}: the FRF JSON has no period spectra (LPM or several realisations): "
                  "the record cannot be replayed by the simulator")
        names = [n for n in st.outputs if n in frf.outputs]
        if "motor_angle" not in names:
            _fail(f"{path}: no motor_angle output (outputs: {', '.join(frf.outputs)}); the "
                  "velocity rms and the friction are taken at the motor")
        idx = [frf.outputs.index(n) for n in names]
        try:
            fit = fit_structure(st, 2 * np.pi * frf.frequency_hz,
                                {n: frf.response[i] for n, i in zip(names, idx)},
                                {n: (frf.total_std if frf.total_std is not None
                                     else frf.noise_std)[i] for n, i in zip(names, idx)},
                                given=given)
        except TFEstError as exc:
            _fail(f"{path}: {exc}")
        frfs.append(frf)
        fits.append(fit)
        err.print(f"{path}: {structure} fit, {fit.verdict.split(':')[0]}")
    try:
        with _w.catch_warnings():
            _w.simplefilter("ignore")  # all of them are in res["warnings"]
            res = coulomb_from_bla_amplitudes(
                frfs, fits, structure, iterations=iterations,
                progress=lambda i, n: err.print(f"  simulation {i}", end="\r"))
        err.print("")
    except IdentificationError as exc:
        _fail(str(exc))
    for m in res["warnings"]:
        err.print(f"[yellow]warning:[/] {escape(m)}")
    res["sources"] = [str(p) for p in frf_json]
    res["fits"] = [f.to_json() for f in fits]
    from flexarm.io.write import write_json
    write_json(json_out, res, overwrite=True)
    c, v = res["coulomb"], res["viscous"]
    console.print(f"Coulomb {c['value']:.4g} ± {c['std']:.2g} {res['unit']}, viscous "
                  f"{v['value']:.4g} ± {v['std']:.2g} {res['damping_unit']} (correlation "
                  f"{res['correlation']:.2f}; Bussgang start {res['bussgang']['coulomb']['value']:.4g})")


if __name__ == "__main__":  # python -m flexarm.cli
    main()
