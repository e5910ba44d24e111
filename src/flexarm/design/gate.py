"""The design gate: no controller leaves flexarm unflagged (issue #25).

A design is checked on the comparison's step (:func:`flexarm.design.compare.compare`:
friction, delays, encoder quantisation, saturation) on the nominal plant and on the drawn
plants, and gets a verdict (:attr:`flexarm.design.result.Design.verdict`):

* ``"stable"`` when all three hold;
* otherwise the failures, joined by ``"; "``:

  - ``unstable on the nominal plant``: the nominal plant's loop did not settle (the
    comparison's ``stable``: finite, tip settled, hub settled over the tail);
  - ``unstable on U of N drawn plants (p % > s %)``: the share U / N of drawn plants that
    are unstable exceeds ``max_unstable_share`` s (default 1 %);
  - ``the command reaches the ±L limit on the nominal plant`` or ``... on K of N drawn
    plants (p % > s %)``: the saturated command sat at the actuator limit L (V or A) for
    some time (``time_at_limit_s > 0``) on the nominal plant, or on more than the same share
    of the drawn plants: the law then leans on the amplifier's clipping, which the linear
    design did not plan for.

Against the lab's controller (the scenario's own, the comparison's ``logged`` row; issue
#46): where the comparison holds it, a design is refused for the drawn plants only where
it fails on more of them than the lab's controller does (and on more than the share), and
for the limit on the nominal plant only where its command sits at the limit longer than the
lab's: a design that beats the lab's controller on every figure passes. Each refusal names
its figure and threshold, and the option that changes it (``fixes``;
``--accept-unstable`` only for instability).

:func:`design_checked` is what ``flexarm design`` calls: it designs, compares the design
with the scenario's own controller, sets the verdict and the comparison, and raises
:class:`flexarm.errors.UnstableDesignError` (the design attached, so it can still be
written with its verdict) unless the verdict is ``"stable"`` or
``GateOptions.accept_unstable``.  The encoder count and the limit are the scenario's
(``sensors.motor_angle.quantum`` or ``range / 2**bits``; ``[actuator] limit`` and the
drive's limit, the smaller): a fitted scenario that carries them needs no extra option.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from flexarm.errors import FlexarmError, UnstableDesignError

__all__ = ["GateOptions", "STABLE", "assess", "refusal", "design_checked"]

#: the verdict of a design that passed the gate
STABLE = "stable"


@dataclass(frozen=True)
class GateOptions:
    """``max_unstable_share``: the largest share (0..1) of drawn plants that may be unstable
    or reach the limit (default 0.01, 1 %); ``accept_unstable``: return a design that fails
    the gate instead of raising (its verdict still says why; ``--accept-unstable``);
    ``check_limit``: count reaching the command limit as a failure (default True);
    ``duration``: the comparison step's length, s (None: the scenario's
    ``simulation.duration``, at least 3 s)."""

    max_unstable_share: float = 0.01
    accept_unstable: bool = False
    check_limit: bool = True
    duration: float | None = None

    def __post_init__(self):
        s = self.max_unstable_share
        if not (isinstance(s, (int, float)) and 0.0 <= s <= 1.0):
            raise FlexarmError(
                "the share of drawn plants allowed to fail must lie in [0, 1]",
                field="max_unstable_share",
                value=s,
                fix="give e.g. 0.01 for 1 %",
            )


#: what changes the threshold of a limit refusal on the nominal plant, by design method
LIMIT_OPTIONS = {
    "lqr": "a larger --r (the command weight)",
    "place": "slower --poles",
    "nested": "a smaller --max-deflection or --distance",
}


def _lab(comparison, reference: str | None) -> dict[str, Any] | None:
    """The lab's (the scenario's own) controller's figures in ``comparison``, or None."""
    if reference is None or reference not in comparison.rows:
        return None
    row = comparison.rows[reference]
    at = np.asarray(comparison.per_plant[reference]["time_at_limit_s"], float)
    return {
        "name": reference,
        "nominal_stable": bool(row["nominal_stable"]),
        "unstable": int(row["unstable"]),
        "nominal_time_at_limit_s": float(at[0]),
        "limit_reached": int(np.sum(at[1:] > 0)),
    }


def assess(
    comparison,
    name: str,
    options: GateOptions = GateOptions(),
    reference: str | None = None,
) -> dict[str, Any]:
    """The gate of controller ``name`` in ``comparison`` (a
    :class:`~flexarm.design.compare.Comparison`): a dict with ``verdict`` (``"stable"`` or
    the failures, module doc), ``reasons`` (the failures as a list), ``fixes`` (for each
    reason, the option that changes its threshold), ``stability`` (whether a reason is
    instability; only those are for ``--accept-unstable``), ``nominal_stable``, ``unstable``
    and ``n_plants`` (drawn plants), ``limit_reached`` (drawn plants whose command reached
    the limit), ``nominal_limit_reached``, ``nominal_time_at_limit_s``, ``limit``,
    ``max_unstable_share`` and ``lab`` (the reference controller's figures, or None).

    ``reference``: the row of the lab's own controller (the scenario's). With it, a design
    is refused for the drawn plants only where it fails on more of them than the lab's
    controller (and on more than ``max_unstable_share``), and for the limit on the nominal
    plant only where its command sits at the limit longer than the lab's: a design that
    beats the lab's controller on every figure passes. Without it, the shares and any time
    at the limit on the nominal plant count (module doc)."""
    row = comparison.rows[name]
    per = comparison.per_plant[name]
    n = int(row["n_plants"])
    unstable = int(row["unstable"])
    at_lim = np.asarray(per["time_at_limit_s"], float)
    nom_t = float(at_lim[0])
    nom_lim = bool(nom_t > 0)
    k_lim = int(np.sum(at_lim[1:] > 0))
    limit = comparison.settings.get("limit_V")
    unit = (comparison.settings.get("units") or {}).get("command")
    lim_txt = (
        "the limit"
        if limit is None
        else f"the ±{limit:g} limit"
        if unit is None
        else f"the ±{limit:g} {unit} limit"
    )
    s = options.max_unstable_share
    lab = _lab(comparison, reference)
    reasons: list[str] = []
    fixes: list[str] = []
    stability = False
    if not row["nominal_stable"]:
        reasons.append("unstable on the nominal plant")
        fixes.append("redesign (no option makes an unstable nominal loop acceptable)")
        stability = True
    share_fix = f"--max-unstable-share (now {s:g}) sets the share"
    if n and unstable / n > s and (lab is None or unstable > lab["unstable"]):
        tail = "" if lab is None else f"; the lab's controller: {lab['unstable']} of {n}"
        reasons.append(
            f"unstable on {unstable} of {n} drawn plants "
            f"({100 * unstable / n:.3g} % > {100 * s:g} %{tail})"
        )
        fixes.append(share_fix)
        stability = True
    if options.check_limit:
        worse = lab is None or nom_t > lab["nominal_time_at_limit_s"] + 1e-12
        if nom_lim and worse:
            if lab is None:
                reasons.append(f"the command reaches {lim_txt} on the nominal plant")
            else:
                reasons.append(
                    f"the command sits at {lim_txt} for {1000 * nom_t:.3g} ms on the nominal "
                    f"plant, longer than the lab's controller "
                    f"({1000 * lab['nominal_time_at_limit_s']:.3g} ms)"
                )
            fixes.append(
                "a design that asks for less: "
                + LIMIT_OPTIONS.get(name, "milder gains or a smaller step")
            )
        if n and k_lim / n > s and (lab is None or k_lim > lab["limit_reached"]):
            tail = "" if lab is None else f"; the lab's controller: {lab['limit_reached']} of {n}"
            reasons.append(
                f"the command reaches {lim_txt} on {k_lim} of {n} drawn "
                f"plants ({100 * k_lim / n:.3g} % > {100 * s:g} %{tail})"
            )
            fixes.append(share_fix)
    return {
        "verdict": "; ".join(reasons) if reasons else STABLE,
        "reasons": reasons,
        "fixes": fixes,
        "stability": stability,
        "nominal_stable": bool(row["nominal_stable"]),
        "unstable": unstable,
        "n_plants": n,
        "nominal_limit_reached": nom_lim,
        "nominal_time_at_limit_s": nom_t,
        "limit_reached": k_lim,
        "limit": None if limit is None else float(limit),
        "limit_unit": unit,
        "max_unstable_share": s,
        "lab": lab,
    }


def refusal(method: str, gate: dict[str, Any]) -> tuple[str, str]:
    """(message, fix) of a refused design: what failed, with its figure and threshold, and
    for each failure the option that changes it, and ``--accept-unstable`` where a failure
    is instability (only there)."""
    stability = bool(gate.get("stability"))
    what = "not safe to run" if stability else "refused by the gate"
    fixes = list(dict.fromkeys(gate.get("fixes") or ["look at compare.md and design.json"]))
    if stability:
        fixes.append("--accept-unstable keeps it (export-c then needs --force)")
    return f"the {method} design is {what}: {gate['verdict']}", "; ".join(fixes)


def design_checked(
    scenario,
    method: str = "lqr",
    *,
    plants=None,
    count: float | None = None,
    gate: GateOptions = GateOptions(),
    logged: str | None = "scenario",
    client: Any = None,
    **options,
):
    """Design ``scenario``'s controller by ``method`` (:func:`flexarm.design.design`, with
    ``options``), compare it with the scenario's own controller (named ``logged``; None
    leaves it out) on the nominal plant and ``plants`` (a
    :class:`~flexarm.design.plants.PlantBatch`; None: the nominal plant only), and gate it
    (module doc).  ``count``: the encoder count (rad) only where the scenario has none.
    Returns the :class:`~flexarm.design.result.Design` with ``verdict``, ``gate`` and
    ``comparison`` set (and the comparison's rows in ``info["comparison"]``); raises
    :class:`~flexarm.errors.UnstableDesignError` (``.design`` the design) when the verdict is
    not ``"stable"`` unless ``gate.accept_unstable``.  ``client``: a Dask client
    (:func:`flexarm.distributed.client_for`) on which the comparison (and a ``tune``'s
    cost) runs the plants in chunks, one task each; None: in-process."""
    from flexarm.design import design
    from flexarm.design.compare import compare, encoder_count
    from flexarm.design.plants import PlantBatch

    if isinstance(scenario, str) or hasattr(scenario, "__fspath__"):
        from flexarm.specs import load_scenario

        scenario = load_scenario(str(scenario))
    try:
        q = encoder_count(scenario, count)
    except ValueError:
        if getattr(scenario, "prismatic", False):  # a linear axis: a linear encoder, m
            raise FlexarmError(
                "the position encoder's count is not known, so the design cannot be checked "
                "against the axis's quantisation",
                field="sensors.motor_angle.quantum",
                fix="add quantum = <m per count> under [sensors.motor_angle] of the scenario "
                "(e.g. quantum = 1e-6 for a 1 µm linear scale: the axis is in m)",
            ) from None
        raise FlexarmError(
            "the hub encoder's count is not known, so the design cannot be checked against "
            "the rig's quantisation",
            field="sensors.motor_angle.quantum",
            fix="add quantum = <rad per count> under [sensors.motor_angle] of the scenario "
            "(a fit writes it when it finds the encoder step; 1 mrad for the rotary rig's "
            "logs), or give the encoder's counts per turn (--encoder-counts)",
        ) from None
    given = None if count is None else q
    if plants is not None and method in ("lqr", "tune"):
        options = {**options, "plants": plants, "count": given}
    if client is not None and method == "tune":
        options = {**options, "client": client}
    des = design(scenario, method, **options)
    batch = plants if plants is not None else PlantBatch.nominal_only(scenario)
    assert scenario.simulation is not None  # design needs a sampled-data scenario
    duration = (
        gate.duration
        if gate.duration is not None
        else max(3.0, float(scenario.simulation.duration))
    )
    c = compare(batch, {method: des}, logged=logged, count=given, duration=duration, client=client)
    des.comparison = c
    des.info["comparison"] = c.to_dict()["rows"]
    des.warnings.extend(w for w in c.warnings if w not in des.warnings)
    des.gate = assess(c, method, gate, reference=logged)
    des.verdict = des.gate["verdict"]
    if des.verdict != STABLE and not gate.accept_unstable:
        msg, fix = refusal(method, des.gate)
        raise UnstableDesignError(msg, design=des, fix=fix + " (accept_unstable=True in Python)")
    return des
