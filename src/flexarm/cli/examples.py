"""``flexarm example-logs``: simulated lab logs with known true parameters, so the README's
chain runs without a rig (:mod:`flexarm.analysis.example_logs`)."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from flexarm.cli.common import check_dir_option, console, enable_cache, fail
from flexarm.cli.parsing import number


def example_logs(
    directory: Path = typer.Argument(..., help="folder to write the logs into (created)"),
    overwrite: bool = typer.Option(False, help="replace example files already in DIRECTORY"),
    seed: int = typer.Option(
        0, help="seed of the sensor noise", callback=number(ge=0, le=2**32 - 1)
    ),
    seconds: float = typer.Option(
        6.0,
        help="length of each rotary run, s (>= 3; steps at 0.5, 2, 3.5, 5 s)",
        callback=number(ge=3, le=3600, example="6"),
    ),
) -> None:
    """Write simulated logs of the built-in rigs with known "true" parameters, as the labs'
    loggers write them: a rotary servo with a flexible link and one with a rigid arm (the
    lab logger's tab-separated format, read with --log-format examples/quanser-rotflex.toml),
    a two-link run (CSV exchange format), a motor bench's odd multisine (motor-bench.mat, the
    lab's MATLAB layout: flexarm frf --log-format examples/motor-bench.toml),
    true-parameters.toml and a README.md."""
    from flexarm.analysis.example_logs import write_example_logs
    from flexarm.errors import OutputExistsError

    check_dir_option("DIRECTORY", directory)
    enable_cache()
    try:
        res = write_example_logs(directory, overwrite=overwrite, seed=seed, duration=seconds)
    except OutputExistsError as exc:
        fail(str(exc).replace("overwrite=True, on the command line ", ""))
    console.print_json(json.dumps(res.to_dict()))
