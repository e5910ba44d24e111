"""``flexarm simulate``: a scenario's closed loop, or logs replayed on it."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

from flexarm.cli import parsing
from flexarm.cli.common import console, enable_cache, fail, guarded_command, load, outdir
from flexarm.cli.options import LogFormatFile, OverwriteOut


@guarded_command("scenario", "log", "log_format")
def simulate(
    scenario: Annotated[
        list[str], typer.Argument(help="scenario TOML file(s) or built-in name(s)")
    ],
    out: Annotated[Path, typer.Option("--out", help="folder for CSV, figures and summary")],
    overwrite: OverwriteOut = False,
    log: Annotated[
        list[Path] | None,
        typer.Option(
            "--log",
            help="replay this log (.mat or text; repeat for several): its "
            "setpoints, initial state, fit % per logged channel",
        ),
    ] = None,
    log_format: LogFormatFile = None,
    window: Annotated[
        str | None, typer.Option(help="replay this part of every log, START:STOP in s on its clock")
    ] = None,
    controller: Annotated[
        Path | None,
        typer.Option(
            "--controller",
            help="with --log: a controller FILE.toml ([controller] or "
            "[[controllers]] tables as in a scenario) replacing "
            "the scenario's controllers for the replay",
        ),
    ] = None,
    continuous: Annotated[
        bool,
        typer.Option(
            "--continuous",
            help="with --log: the logs, in order, are consecutive "
            "pieces of one run; each dynamic controller's state "
            "(and the digital filters') carried from log to log; "
            "not with --window",
        ),
    ] = False,
) -> None:
    """Simulate a scenario's closed loop: CSV (exchange format), PNG figure, summary.json;
    with --log, replay logs on it and report fit % = 100 (1 − ‖y − ŷ‖/‖y − mean y‖).

    Several scenarios: each one's files, and for multi-link arms in the sampled loop one
    figure of all of them overlaid (joint errors in encoder counts, link deflections,
    commands), e.g. flexarm simulate deluca-two-link-geared deluca-two-link-geared-fc."""
    enable_cache()
    from flexarm.analysis.summary import write_comparison, write_multilink, write_simulation
    from flexarm.io.write import distinct_names

    scs = [load(s) for s in scenario]
    out = outdir(out, overwrite)
    if (controller is not None or continuous) and not log:
        fail("--controller and --continuous belong to the replay: give the logs with --log")
    if log:
        if len(scs) != 1:
            fail("--log replays logs on one scenario; give exactly one SCENARIO")
        replay_logs(
            scs[0], log, log_format, window, out, controller=controller, continuous=continuous
        )
        return
    # names are data: each scenario's files are <key>.*, its name made a safe file name and
    # distinct from the others' (a second "rig" becomes "rig-2"), said in the output
    keys = distinct_names([sc.name for sc in scs], what="scenario name")
    if len(scs) == 1:
        console.print_json(
            json.dumps(
                write_simulation(scs[0], out, progress=True, name=keys[0], overwrite=overwrite)
            )
        )
        return
    summaries, results, multi, mkeys = {}, {}, [], []
    for key, sc in zip(keys, scs, strict=True):
        if sc.arm.kind == "multi_link" and sc.sampling is not None:
            summaries[key], results[key] = write_multilink(
                sc, out, progress=True, name=key, overwrite=overwrite
            )
            multi.append(sc)
            mkeys.append(key)
        else:
            summaries[key] = write_simulation(sc, out, progress=True, name=key, overwrite=overwrite)
        if key != sc.name:
            summaries[key]["file_name_from"] = sc.name
    if len(multi) > 1:
        summaries["comparison_figure"] = write_comparison(
            multi, results, out, names=mkeys, overwrite=overwrite
        ).name
    console.print_json(json.dumps(summaries))


def replay_logs(
    sc,
    logs: list[Path],
    log_format: Path | None,
    window: str | None,
    out: Path,
    *,
    controller: Path | None = None,
    continuous: bool = False,
) -> None:
    """``simulate --log``: each log replayed on the scenario, fit % per channel, figures;
    ``controller``: a controller file replacing the scenario's controllers
    (:func:`flexarm.specs.scenario.load_controllers`, :meth:`Scenario.with_controllers`);
    ``continuous``: the logs as consecutive pieces of one run
    (:func:`flexarm.analysis.replay.replay_run`)."""
    from flexarm.analysis.replay import plot_replay, replay, replay_run
    from flexarm.errors import SimulationDiverged
    from flexarm.io.logformat import LogFormat, load_log_format
    from flexarm.io.logs import LogError
    from flexarm.io.write import write_json
    from flexarm.specs import ScenarioError
    from flexarm.specs.scenario import load_controllers

    if continuous and window:
        fail(
            f"--continuous replays whole logs as one run; --window {window} cuts each log: "
            "give one or the other"
        )
    win = parsing.window(window, "--window")
    results = {}
    try:
        if controller is not None:
            sc = sc.with_controllers(load_controllers(controller))
        fmt = load_log_format(log_format) if log_format is not None else LogFormat()
        glogs = [fmt.read(path) for path in logs]
        if continuous:
            reps = replay_run(sc, glogs, continuous=True)
        else:
            reps = [replay(sc, g, window=win) for g in glogs]  # [t0, t1) s from the first sample
        for path, rep in zip(logs, reps, strict=True):
            results[str(path)] = {k: round(v, 2) for k, v in rep.fit_percent.items()}
            if rep.fit_percent:  # a log where no channel moves has no fit % and no figure
                plot_replay(rep, out / f"replay-{path.stem}.png", overwrite=True, scenario=sc.name)
    except (LogError, ScenarioError, ValueError, SimulationDiverged) as exc:
        fail(str(exc))
    write_json(out / "replay.json", replay_document(sc, window, results), overwrite=True)
    names = sorted({k for d in results.values() for k in d})
    t = Table("fit %", *[Path(name).stem for name in results])
    for k in names:
        t.add_row(k, *(f"{d.get(k, float('nan')):.1f}" for d in results.values()))
    console.print(t)


def replay_document(sc, window: str | None, results: dict) -> dict:
    """JSON LAYOUT (to move into the library's prediction result's ``to_dict()``):
    ``replay.json`` of ``simulate --log``."""
    return {"scenario": sc.name, "window": window, "fit_percent": results}
