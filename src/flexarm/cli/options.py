"""The option groups several commands share, as ``Annotated`` types (one spelling, one
help text): a motor's data sheet, how a log is read, and where results are written.

A command declares ``json_out: JsonOut = None`` and gets ``--json`` with the shared help.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from typer.core import TyperCommand

from flexarm.cli.parsing import number

# --- the data sheet of a geared voltage (or current) servo (flexarm fit LOG...) -----------
Drive = Annotated[str, typer.Option(help="voltage or current")]
GearRatio = Annotated[float, typer.Option(help="K_g", callback=number(gt=0, example="70"))]
MotorConstant = Annotated[
    float | None,
    typer.Option(help="K_m, V*s/rad (voltage) or N*m/A (current)", callback=number(gt=0)),
]
ArmatureResistance = Annotated[float | None, typer.Option(help="R, ohm", callback=number(gt=0))]
LinkLength = Annotated[float | None, typer.Option(help="link length, m", callback=number(gt=0))]
GearEfficiency = Annotated[float, typer.Option(callback=number(gt=0, le=1))]
MotorEfficiency = Annotated[float, typer.Option(callback=number(gt=0, le=1))]
VoltageLimit = Annotated[
    float | None,
    typer.Option(
        help="amplifier limit, V (default: the log format's [controller] limit, else 10)",
        callback=number(gt=0, example="10"),
    ),
]
ComputationDelay = Annotated[
    int | None,
    typer.Option(
        help="samples between a sample and its command (default: where the declared law best "
        "explains the logged command)",
        callback=number(ge=0, le=1000, example="1"),
    ),
]

# --- the data sheet of a physical structure fitted to an FRF (tfest, friction) ------------
StructMotorConstant = Annotated[
    float | None,
    typer.Option(
        "--motor-constant",
        help="frb-single-mass: K (N·m/A); voltage-servo: K_m (V·s/rad)",
        callback=number(gt=0),
    ),
]
StructResistance = Annotated[
    float | None,
    typer.Option("--resistance", help="voltage-servo: R_m (ohm)", callback=number(gt=0)),
]
StructGearRatio = Annotated[
    float | None, typer.Option("--gear-ratio", help="voltage-servo: K_g", callback=number(gt=0))
]
StructEfficiency = Annotated[
    float | None,
    typer.Option(
        "--efficiency",
        help="voltage-servo: η = η_g η_m (gear times motor efficiency)",
        callback=number(gt=0, le=1),
    ),
]
StructLength = Annotated[
    float | None,
    typer.Option(
        "--length",
        help="voltage-servo: link length L (m), for a tip_deflection output",
        callback=number(gt=0),
    ),
]

# --- how a log is read ---------------------------------------------------------------------
LogFormats = Annotated[
    list[str] | None,
    typer.Option(
        "--log-format",
        help="the logger's log-format TOML (columns, units, gains); with a "
        "scenario: once per log, or PATTERN=FILE by file name",
    ),
]
LogFormatFile = Annotated[
    Path | None,
    typer.Option("--log-format", help="the logs' log-format TOML ([columns], [units]; examples/)"),
]
Column = Annotated[
    list[str] | None, typer.Option(help="map a column to the log's name: motor_angle=theta")
]
Unit = Annotated[
    list[str] | None,
    typer.Option(help="unit of a column's numbers: motor_angle=deg, tip_deflection=mm"),
]
Window = Annotated[
    str | None,
    typer.Option(
        help="use this part of every log only, START:STOP in s from its first sample, e.g. 0:5"
    ),
]
MaxJitter = Annotated[
    float,
    typer.Option(
        help="accepted relative deviation of a time step from the median step",
        callback=number(ge=0, lt=1),
    ),
]
Controller = Annotated[
    str | None,
    typer.Option(
        help="overrides the logs' '# controller:' line, e.g. "
        "'state_feedback K1=6 K2=-3 K3=0.2 K4=0'"
    ),
]
UseRegressedLaw = Annotated[
    bool,
    typer.Option(
        "--use-regressed-law",
        help="use the law regressed on the logged command where it disagrees with the declared one",
    ),
]
Channels = Annotated[
    list[str] | None,
    typer.Option(
        "--channel",
        help="a measured channel to fit or compare, NAME or NAME=WEIGHT (repeat; "
        "default: every logged sensor channel)",
    ),
]

# --- outputs -------------------------------------------------------------------------------
JsonOut = Annotated[Path | None, typer.Option("--json", help="write the result as JSON")]
JsonRequired = Annotated[Path, typer.Option("--json", help="JSON result")]
Plots = Annotated[Path | None, typer.Option(help="folder for figures")]
Report = Annotated[
    Path | None,
    typer.Option(
        "--report", help="write a self-contained HTML report (figures embedded), e.g. result.html"
    ),
]
ScenarioOut = Annotated[
    Path | None, typer.Option("--scenario-out", help="write the fitted (identified) scenario TOML")
]
Out = Annotated[Path, typer.Option("--out", help="output folder")]
Overwrite = Annotated[bool, typer.Option(help="replace existing output files")]
OverwriteOut = Annotated[bool, typer.Option(help="write into a non-empty --out folder")]

# --- inputs --------------------------------------------------------------------------------
ScenarioArg = Annotated[str, typer.Argument(help="scenario TOML file or built-in name")]


# --- help grouped by panel (issue #46: `fit --help` listed about 40 options flat) ---------
#: each option's panel in `fit --help` and `validate --help`, by parameter name (the
#: shared groups above: data sheet, log, outputs; the fit's own: search)
PANELS_BY_NAME = {
    "drive": "Data sheet",
    "gear_ratio": "Data sheet",
    "motor_constant": "Data sheet",
    "armature_resistance": "Data sheet",
    "link_length": "Data sheet",
    "gear_efficiency": "Data sheet",
    "motor_efficiency": "Data sheet",
    "voltage_limit": "Data sheet",
    "computation_delay": "Data sheet",
    "log_format": "Log",
    "column": "Log",
    "unit": "Log",
    "window": "Log",
    "max_jitter": "Log",
    "use_regressed_law": "Log",
    "channel": "Log",
    "json_out": "Outputs",
    "plots": "Outputs",
    "report": "Outputs",
    "scenario_out": "Outputs",
    "controller": "Log",
    "continuous": "Log",
    "sessions": "Log",
    "validate_window": "Log",
    "refit_window": "Log",
    "mode": "Search",
    "no_friction": "Search",
    "seconds": "Search",
    "compare_no_friction": "Search",
    "tip_sign": "Search",
    "encoder_counts": "Search",
    "filter": "Search",
    "delay_search": "Search",
    "polish_iter": "Search",
    "local": "Search",
    "bootstrap": "Search",
    "global_starts": "Search",
    "seed": "Search",
    "tip_after_hub": "Search",
    "free": "Search",
    "prior": "Search",
    "segment": "Search",
    "max_nfev": "Search",
    "refit": "Search",
    "bound": "Search",
    "overwrite": "Outputs",
}
#: the panels' titles, in the order shown (the routes each is for)
PANEL_TITLES = {
    "Data sheet": "Data sheet (LOG... alone, the servo route; needs --motor-constant, "
    "--armature-resistance)",
    "Log": "Log (how the logs are read, which part is used)",
    "Search": "Search (what is fitted, how; --free, --prior, --segment: SCENARIO LOG...)",
    "Outputs": "Outputs",
    "Options": "Other options",
}


class PanelCommand(TyperCommand):
    """A command whose plain-text ``--help`` (the app has no rich markup) lists its options
    in panels: each option's ``rich_help_panel`` where it has one, else
    :data:`PANELS_BY_NAME`, else "Other options"; titles from :data:`PANEL_TITLES`."""

    def format_options(self, ctx, formatter) -> None:
        args, groups = [], {k: [] for k in PANEL_TITLES}
        for param in self.get_params(ctx):
            rv = param.get_help_record(ctx)
            if rv is None:
                continue
            if param.param_type_name == "argument":
                args.append(rv)
                continue
            panel = getattr(param, "rich_help_panel", None) or PANELS_BY_NAME.get(
                param.name or "", "Options"
            )
            groups.setdefault(panel, []).append(rv)
        if args:
            with formatter.section("Arguments"):
                formatter.write_dl(args)
        for panel, rows in groups.items():
            if rows:
                with formatter.section(PANEL_TITLES.get(panel, panel)):
                    formatter.write_dl(rows)
