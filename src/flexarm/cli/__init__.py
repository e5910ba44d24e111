"""The ``flexarm`` command line: thin wrappers over the library (typer + rich).

One module per command group; each command parses its options, calls the library and
prints or writes the result.  Shared pieces: :mod:`.common` (consoles, refusals, output
checks), :mod:`.parsing` (option text → values), :mod:`.options` (the shared option groups).
"""

from __future__ import annotations

import typer

from flexarm.cli import deploy, design, fit, frequency, reproduce, scenarios, simulate

app = typer.Typer(add_completion=False, no_args_is_help=True,
                  help="Model, identify, simulate and control flexible-link arms with joint friction.")

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
app.command("fit")(fit.fit)
app.command("validate")(fit.validate)
app.command("export-c")(deploy.export_c)
app.command("excite")(frequency.excite)
app.command("frf")(frequency.frf)
app.command("tfest")(frequency.tfest)
app.command("friction")(frequency.friction)


def main() -> None:  # pragma: no cover
    """The console script (``flexarm``) and ``python -m flexarm``."""
    app()
