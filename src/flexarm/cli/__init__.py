"""The ``flexarm`` command line: thin wrappers over the library (typer + rich).

One module per command group; each command parses its options, calls the library and
prints or writes the result.  Shared pieces: :mod:`.common` (consoles, refusals, output
checks), :mod:`.parsing` (option text → values), :mod:`.options` (the shared option
groups), :mod:`.errors` (how an error ends a command, and the exit codes).

Every error ends in one line: a bad input (a project error, a refused option) exits 2, an
internal error exits 1 with the traceback in a log file (:mod:`flexarm.cli.errors`).
"""

from __future__ import annotations

import sys
from typing import Annotated, Any, cast

import typer
from typer.core import TyperGroup

from flexarm.cli import (
    deploy,
    design,
    distributed,
    errors,
    examples,
    fit,
    frequency,
    reproduce,
    scenarios,
    simulate,
)
from flexarm.cli.options import PanelCommand


class FlexarmGroup(TyperGroup):
    """The command group with the one top-level error handler (:mod:`flexarm.cli.errors`)."""

    def invoke(self, ctx: typer.Context) -> Any:
        try:
            return super().invoke(ctx)
        except (typer.Exit, typer.Abort, typer.TyperException):
            raise  # a refusal already printed (exit 2), --help, --version, parser errors
        except errors.project_errors() as exc:
            raise typer.Exit(errors.bad_input(exc)) from None
        except Exception as exc:
            raise typer.Exit(
                errors.internal_error(exc, " ".join(["flexarm", *sys.argv[1:]]) if sys.argv else "")
            ) from None

    def main(self, *args: Any, standalone_mode: bool = True, **kwargs: Any) -> Any:
        """Parser errors as one line too (typer prints a boxed usage panel)."""
        if not standalone_mode:
            return super().main(*args, standalone_mode=False, **kwargs)
        try:
            rv = super().main(*args, standalone_mode=False, **kwargs)
        except typer.TyperException as exc:
            if type(exc).__name__ == "NoArgsIsHelpError":  # bare `flexarm`: the help
                cast(Any, exc).show()  # click's UsageError.show; TyperException has none
                sys.exit(0)
            sys.exit(errors.usage_error(exc))
        except typer.Abort:
            errors.err.print("aborted", highlight=False)
            sys.exit(1)
        sys.exit(rv if isinstance(rv, int) else 0)


app = typer.Typer(
    cls=FlexarmGroup,
    add_completion=False,
    no_args_is_help=True,
    rich_markup_mode=None,  # help texts as written: rich markup ate [words]
    help="Model, identify, simulate and control flexible-link arms with joint friction.",
)


def _version(value: bool) -> None:
    if value:
        from flexarm.version import __version__

        print(f"flexarm {__version__}")
        raise typer.Exit(0)


@app.callback()
def _root(
    version: Annotated[
        bool,
        typer.Option(
            "--version", callback=_version, is_eager=True, help="print flexarm's version and exit"
        ),
    ] = False,
    no_jax_cache: Annotated[
        bool,
        typer.Option(
            "--no-jax-cache",
            help="do not keep JAX's compiled loops on disk (default: kept in the user's "
            "cache folder, or in $FLEXARM_JAX_CACHE; FLEXARM_JAX_CACHE=0 also turns it off)",
        ),
    ] = False,
) -> None:
    """Model, identify, simulate and control flexible-link arms with joint friction."""
    if no_jax_cache:
        import os

        os.environ["FLEXARM_JAX_CACHE"] = "0"


# the order of `flexarm --help`
app.command("scenarios")(scenarios.scenarios)
app.command("info")(scenarios.info)
app.command("simulate")(simulate.simulate)
app.command("design")(design.design_cmd)
app.command("scenario-from-mat")(reproduce.scenario_from_mat)
app.command("reproduce")(reproduce.reproduce)
app.command("demo")(reproduce.demo)
app.command("experiment")(frequency.experiment)
app.command("identify")(frequency.identify)
app.command("fit", cls=PanelCommand)(fit.fit)
app.command("validate", cls=PanelCommand)(fit.validate)
app.command("export-c")(deploy.export_c)
app.command("excite")(frequency.excite)
app.command("frf")(frequency.frf)
app.command("tfest")(frequency.tfest)
app.command("friction")(frequency.friction)
app.command("fit-many")(distributed.fit_many)
app.command("example-logs")(examples.example_logs)


def main() -> None:  # pragma: no cover
    """The console script (``flexarm``) and ``python -m flexarm``."""
    app()
