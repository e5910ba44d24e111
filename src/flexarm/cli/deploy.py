"""``flexarm export-c``: a design's (or scenario's) controller as C99."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from flexarm.cli.common import check_dir_option, console, fail, guarded


def export_c(
    design: str = typer.Argument(
        ..., help="design directory (holding design.toml) or a scenario TOML / built-in name"
    ),
    out: Path = typer.Option(..., "--out", help="folder for NAME.h and NAME.c"),
    precision: str = typer.Option("double", "--precision", help="double or float"),
    name: str = typer.Option("controller", "--name", help="C prefix and file name"),
    overwrite: bool = typer.Option(False, help="replace existing NAME.h / NAME.c"),
    accept_unstable: bool = typer.Option(
        False,
        "--accept-unstable",
        help="export a design or scenario that fails the gate (its verdict, or the nominal "
        "check of the sampled loop) anyway; the reason goes into NAME.h as a #warning",
    ),
    force: bool = typer.Option(False, "--force", hidden=True, help="old name of --accept-unstable"),
) -> None:
    """Write the [controller] of a design (or scenario) as C99 for a real-time target:
    NAME.h (state struct, NAME_init, NAME_step, channel order and units) and NAME.c (the
    law, friction feedforward, saturation and D/A count); no dependencies.  Every export
    is gated: a design whose stored verdict (design.json, whichever of its files is given)
    is not "stable", or a loop that the nominal check finds unstable (the sampled loop with
    its delays, linearised at rest), is refused (exit 2) unless --accept-unstable."""
    with guarded(design):
        _export(design, out, precision, name, overwrite, accept_unstable or force)


def _export(design, out, precision, name, overwrite, force) -> None:
    from flexarm.deploy.c_export import ExportError
    from flexarm.deploy.c_export import export_c as _export_c
    from flexarm.errors import OutputExistsError, UnstableDesignError

    check_dir_option("--out", out)
    try:
        code, paths = _export_c(
            design, out, name=name, precision=precision, overwrite=overwrite, accept_unstable=force
        )
    except UnstableDesignError as exc:
        fail(
            f"{exc.args[0] if exc.args else exc}; redesign (a design's "
            "design.json and compare.md say why), or pass --accept-unstable to export it "
            "with the reason as a #warning in the header"
        )
    except (ExportError, OutputExistsError) as exc:
        fail(str(exc))
    except ValueError as exc:
        fail(f"{design}: {exc}")
    console.print_json(
        json.dumps(
            {
                "files": [str(p) for p in paths],
                "precision": code.precision,
                "measured": [f"{n} ({u})" for n, u in code.measured],
                "reference": [f"{n} ({u})" for n, u in code.references],
                "u": [f"{n} ({u})" for n, u in code.outputs],
            }
        )
    )
