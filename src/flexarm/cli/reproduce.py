"""``flexarm reproduce``, ``demo`` and ``scenario-from-mat``: the papers' experiments on
the simulated arms, the built-in demo, and a scenario from a lab's MATLAB workspace."""

from __future__ import annotations

from pathlib import Path

import typer

from flexarm.cli import parsing
from flexarm.cli.common import (
    check_file_option,
    console,
    enable_cache,
    err,
    fail,
    guarded_command,
    outdir,
)

REPRODUCTIONS = {
    "feliu": "Feliu, Rattan & Brown 1993, Figs. 11-19",
    "deluca": "De Luca & Siciliano 1993, Fig. 2 and the example",
}


def reproduction(name: str):
    import importlib

    if name not in REPRODUCTIONS:
        fail(f"reproduce {name!r}: choose one of {', '.join(REPRODUCTIONS)}")
    try:
        return importlib.import_module(f"flexarm.reproduce.{name}").run
    except ModuleNotFoundError:
        fail(f"reproduce {name!r} is not available in this version")


def run_reproduction(name: str, out: Path) -> dict:
    from rich.progress import Progress

    run = reproduction(name)
    with Progress(console=err) as bar:
        task = bar.add_task(name, total=None)

        def progress(done, total=None, what=""):
            bar.update(task, completed=done, total=total, description=f"{name}: {what}")

        return run(out, progress=progress)


@guarded_command()
def reproduce(
    paper: str = typer.Argument(..., help=" | ".join(REPRODUCTIONS)),
    out: Path = typer.Option(..., "--out", help="folder for figures and the table"),
    overwrite: bool = typer.Option(False, help="write into a non-empty --out folder"),
) -> None:
    """Re-run a paper's experiments on the simulated arms: figures, and a table of each
    reported quantity, the paper's value, ours and the ratio."""
    enable_cache()
    reproduction(paper)
    out = outdir(out, overwrite)
    res = run_reproduction(paper, out)
    md = out / f"{paper}_table.md"
    if md.exists():
        console.print(md.read_text(), markup=False)
    console.print(f"wrote {out}/ ({len(res.get('figures', []))} figures)")


@guarded_command()
def demo(
    out: Path = typer.Option(Path("out/demo"), "--out", help="output folder"),
    overwrite: bool = typer.Option(False, help="write into a non-empty --out folder"),
) -> None:
    """The main job on the built-in default: model, simulations and figures into --out
    (a folder holding files only with --overwrite)."""
    enable_cache()
    from flexarm.analysis.summary import run_demo

    out = outdir(out, overwrite)
    import importlib.util

    reps = {
        n: (lambda d, n=n: run_reproduction(n, d))
        for n in REPRODUCTIONS
        if importlib.util.find_spec(f"flexarm.reproduce.{n}") is not None
    }
    run_demo(out, console, reproductions=reps)


@guarded_command("workspace")
def scenario_from_mat(
    workspace: Path = typer.Argument(
        ..., help="the lab's MATLAB workspace (.mat) of a two-link flexible arm"
    ),
    out: Path = typer.Option(..., "--out", help="scenario TOML to write"),
    current_limits: str = typer.Option(
        "0.94,1.2", help="the amplifiers' current limits per joint, A (not in the file)"
    ),
    overwrite: bool = typer.Option(False, help="replace an existing --out file"),
) -> None:
    """A two-link scenario (quanser-two-link's layout) from a lab workspace's parameters."""
    from flexarm.io.logs import LogError
    from flexarm.io.workspace import scenario_from_workspace
    from flexarm.io.write import write_toml
    from flexarm.specs import ScenarioError, scenario_from_dict

    check_file_option("--out", out, overwrite)
    lims = parsing.positive_floats(current_limits, "--current-limits", 2, "0.94,1.2 (A)")
    try:
        data = scenario_from_workspace(workspace, current_limits=(lims[0], lims[1]))
        scenario_from_dict(data, source=str(workspace))
        write_toml(out, data, overwrite=overwrite)
    except (LogError, ScenarioError) as exc:
        fail(str(exc))
    console.print(f"{out}: scenario {data['name']!r} from {workspace}")
