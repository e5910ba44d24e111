"""The ``flexarm`` command line: thin wrappers over the library (typer + rich)."""

from __future__ import annotations

import json
import os
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
        return load_scenario(scenario)
    except ScenarioError as exc:
        _fail(str(exc))


def _outdir(out: Path, overwrite: bool) -> Path:
    if out.exists() and any(out.iterdir()) and not overwrite:
        _fail(f"{out} exists and is not empty; pass --overwrite to write into it")
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
    from flexarm.analysis.model_info import single_link_info
    from flexarm.models.single_link import SingleLinkModel

    sc = _load(scenario)
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


def _fmt(c: list[float]) -> str:
    return "[" + ", ".join(f"{x:.6g}" for x in c) + "]"


@app.command()
def simulate(scenario: str = typer.Argument(..., help="scenario TOML file or built-in name"),
             out: Path = typer.Option(..., "--out", help="folder for CSV, figures and summary"),
             overwrite: bool = typer.Option(False, help="write into a non-empty --out folder")) -> None:
    """Simulate a scenario's closed loop: CSV (exchange format), PNG figure, summary.json."""
    _enable_cache()
    from flexarm.analysis.summary import write_simulation

    sc = _load(scenario)
    out = _outdir(out, overwrite)
    summary = write_simulation(sc, out, progress=True)
    console.print_json(json.dumps(summary))


@app.command()
def demo(out: Path = typer.Option(Path("out/demo"), "--out", help="output folder (flexarm's own; rewritten)")) -> None:
    """The main job on the built-in default: model, simulations and figures into --out."""
    _enable_cache()
    from flexarm.analysis.summary import run_demo

    out.mkdir(parents=True, exist_ok=True)
    run_demo(out, console)


def main() -> None:  # pragma: no cover
    app()
