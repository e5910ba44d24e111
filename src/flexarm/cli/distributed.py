"""``flexarm fit-many``: every row of a manifest fitted, on this machine or a Dask cluster
(:func:`flexarm.distributed.fit_many`)."""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

from flexarm.cli.common import (
    check_cluster,
    check_dir_option,
    console,
    enable_cache,
    err,
    fail,
    guarded_command,
    working,
)
from flexarm.cli.parsing import number


@guarded_command("manifest")
def fit_many(
    manifest: Annotated[
        Path, typer.Argument(help="manifest CSV: one fit a row (columns: docs/distributed.md)")
    ],
    out: Annotated[
        Path,
        typer.Option(
            "--out",
            help="folder of the results: <row id>/fit.json, fitted.toml, "
            "plots/, and summary.csv (a rerun skips finished rows)",
        ),
    ],
    scheduler: Annotated[
        str | None, typer.Option(help="a running Dask scheduler, e.g. tcp://host:8786")
    ] = None,
    workers: Annotated[
        int | None,
        typer.Option(
            help="start a local Dask cluster of N worker processes (default: run "
            "in-process, one fit after the other)",
            callback=number(ge=1, le=1024, example="4"),
        ),
    ] = None,
    no_figures: Annotated[
        bool, typer.Option("--no-figures", help="skip each fit's overlay figures")
    ] = False,
    overwrite: Annotated[
        bool,
        typer.Option(
            "--overwrite",
            help="write into a folder holding other files, and fit again a row whose "
            "folder holds another row's finished fit",
        ),
    ] = False,
) -> None:
    """Fit every row of MANIFEST (each row a task), write DIR/<id>/ and DIR/summary.csv;
    finished rows are skipped and failed ones retried when run again. Exit 1 when a row
    failed (the others still run).  A folder holding other files, or another row's
    finished fit, is written into only with --overwrite; the manifest is never written
    over."""
    import flexarm.distributed as fd

    check_cluster(scheduler, workers)
    check_dir_option("--out", out)
    enable_cache()
    try:  # a bad manifest: one line naming row and column
        rows = fd.read_manifest(manifest)
    except UnicodeDecodeError as exc:  # issue #45: a UTF-16 manifest named by its file
        fail(
            f"{manifest}: not UTF-8 text ({exc.reason} at byte {exc.start}); save the "
            "manifest as UTF-8 (a spreadsheet's 'CSV UTF-8')"
        )
    fd.fit_many_todo(rows, out, manifest, overwrite)  # the output policy, before any work

    beat: list = []  # the Working of the run, once it starts

    def progress(rec: dict) -> None:
        if beat:  # the elapsed time on stderr (each row, and every 5 s of work)
            beat[0].update(f"fit-many: {rec['id']} {rec['status']}")
        console.print(
            f"{rec['id']}: {rec['status']}"
            + (f" ({rec['seconds']:.1f} s)" if rec.get("seconds") else "")
            + (f" {rec['error']}" if rec.get("error") else ""),
            highlight=False,
        )

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with fd.session(scheduler, workers) as client:
            for w in caught:
                if str(w.message) == fd.NO_DASK:
                    err.print(str(w.message), highlight=False)
            with working(f"fit-many: {len(rows)} row(s)") as w:
                beat.append(w)
                recs = fd.fit_many(
                    rows,
                    client,
                    out,
                    options=fd.FitManyOptions(figures=not no_figures),
                    progress=progress,
                    overwrite=overwrite,
                )
    t = Table("row", "status", "seconds", title=f"fit-many: {out / 'summary.csv'}")
    for r in recs:
        t.add_row(r["id"], r["status"], "" if not r.get("seconds") else f"{r['seconds']:.1f}")
    console.print(t)
    if any(r["status"] == "failed" for r in recs):
        raise typer.Exit(1)
