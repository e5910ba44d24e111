"""``flexarm scenarios`` and ``flexarm info``: the built-in arms and an arm's linear model."""

from __future__ import annotations

import json
from typing import Annotated

import typer
from rich.markup import escape
from rich.table import Table

from flexarm.cli.common import console, fmt, load
from flexarm.cli.options import ScenarioArg


def scenarios() -> None:
    """List the built-in scenarios."""
    from flexarm.specs import builtin_scenarios, load_scenario

    t = Table("name", "description")
    for name, path in sorted(builtin_scenarios().items()):
        t.add_row(name, escape(load_scenario(path).description))
    console.print(t)


def info(
    scenario: ScenarioArg,
    as_json: Annotated[bool, typer.Option("--json", help="print JSON")] = False,
) -> None:
    """The arm's linear model: transfer functions, poles, zeros, frequencies, gains."""
    from flexarm.analysis.model_info import multilink_info, single_link_info
    from flexarm.models.single_link import SingleLinkModel

    sc = load(scenario)
    if sc.arm.kind == "multi_link":
        data = {"scenario": sc.name, **multilink_info(sc)}
        if as_json:
            print(json.dumps(data, indent=2))
        else:
            print_multilink(sc, data)
        return
    data = {"scenario": sc.name, **single_link_info(SingleLinkModel.from_spec(sc.arm))}
    if as_json:
        print(json.dumps(data, indent=2))
        return
    console.print(f"[bold]{escape(sc.name)}[/]: {escape(sc.description)}")
    for key, tf in data["transfer_functions"].items():
        console.print(f"\n[bold]{key}[/]: {escape(tf['description'])}")
        console.print(f"  num = {fmt(tf['num'])}\n  den = {fmt(tf['den'])}", markup=False)
        for w in tf["natural_frequencies_rad_s"]:
            kind = "real pole" if w["damping_ratio"] >= 1 - 1e-12 else "pole pair"
            console.print(
                f"  {kind}: {w['wn_rad_s']:.5g} rad/s ({w['hz']:.4g} Hz), "
                f"damping {w['damping_ratio']:.3g}"
            )
        if tf["right_half_plane_zeros"]:
            console.print(
                "  right-half-plane zeros: "
                f"{[round(z['re'], 5) for z in tf['right_half_plane_zeros']]}",
                markup=False,
            )
        console.print(f"  static gain: {tf['static_gain']:.6g} ({escape(tf['static_gain_note'])})")


def print_multilink(sc, data: dict) -> None:
    """``info`` of a multi-link arm: modes per link, the regulation target, (14)-(15)."""
    console.print(f"[bold]{escape(sc.name)}[/]: {escape(sc.description)}")
    for ln in data["links"]:
        console.print(f"\n[bold]link {ln['link']}[/] ({ln['modes']} {ln['mode_type']} modes)")
        console.print(f"  frequencies [Hz]: {fmt(ln['frequencies_hz'])}", markup=False)
        console.print(
            f"  phi(l): {fmt(ln['phi_end'])}   phi'(l) [1/m]: {fmt(ln['phi_prime_end_per_m'])}",
            markup=False,
        )
        console.print(
            "  k_ij [N/m]: " + ", ".join(fmt(r) for r in ln["stiffness_k_ij_N_per_m"]), markup=False
        )
    tg = data.get("target")
    if tg:
        console.print(f"\ndelta_d [m] (eq. 9): {fmt(tg['delta_d_m'])}", markup=False)
        console.print(f"alpha (eq. 6): {tg['alpha']['value']:.5g}")
        for k, c in tg["conditions"].items():
            console.print(
                f"({k}) {c['statement']}: {'holds' if c['holds'] else 'FAILS'} "
                f"(margin {c['margin']:+.4g})",
                markup=False,
            )
