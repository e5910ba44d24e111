"""The real two-link rig (issue #17) through the general fit: the must-show split, the
default free parameters and the data-sheet priors for the built-in ``quanser-two-link``.

Split: fit on the first 50 s of the 102 s run (``lqr_full_10deg.mat``, log format
``examples/two-link-workspace.toml``) together with the staircase steps to 5°, −10°, 20°
and −30° (``lqr-stair/``, ``examples/two-link-staircase.toml``); hold out the last 52 s and
the other steps (−5°, 10°, −20°, 30° and the return to 0°).

Free by default (:data:`FREE`): per joint the friction (Coulomb, breakaway, viscous), per
link the torsional stiffness and damping, the strain gauges' gains (α_f and α̇_f read the
same gauge: :data:`TIES` moves the rate channel's gain with it), the drives' torque
constants and the elbow hub's inertia; and each joint's cable spring
(``arm.joints[i].cable_stiffness``, :class:`flexarm.specs.multilink.Joint`) where the
fitted logs' rests show one, started at its static estimate
(:func:`flexarm.identification.time_domain.estimates.cable_springs`, the preset's
``starts``). On this rig the shoulder gauge reads −2.3 mrad per rad of the shoulder at
rest (the fitted part's ten holds; the held-out part's fourteen: −2.28 ± 0.16), a
torque from the elbow's cables that the link's own spring cannot give; the elbow gauge's
slope is positive (no restoring spring), so joint 2 has none.

Priors (:data:`PRIORS`, relative standard deviations about the data sheet's values): torque
constants ±30 % (the sheet assumes an efficiency), beam-formula stiffnesses ±30 %, gauge
gains ±20 %, the elbow hub ±30 %, viscous ±50 %; friction levels and link damping have none
(the sheet gives none). Link 1's damping is 0 in the sheet (B12); the template starts it at
0.1 N·m·s/rad so that it can be fitted in log space.

The data term's scale (eq. (1) of :mod:`~flexarm.identification.time_domain.general`):
the misfit a model of this rig leaves is ~20 % of each channel's spread (λ = 0.2, the
independent fit's 80 % on the deflections) and correlated over ~0.5 s (the links ring at
1–3 Hz, the residuals follow the link's phase errors), so that the priors weigh against about
one independent misfit per half second.

Multiple shooting on 3 s segments (each from the logged state: encoder angles, the strain
gauges' raw angle recovered by inverting the 2 Hz filter, rates by local quadratic fits)
with per-segment start-state offsets, 2 integration substeps while fitting (the scenario's 4
for the held-out predictions).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from flexarm.identification.time_domain.general import predict_scenario
from flexarm.identification.time_domain.options import Cost, FitOptions, Local, Priors, Shooting
from flexarm.specs.paths import scenario_with

CHANNELS = ("theta_1", "alpha_f_1", "theta_2", "alpha_f_2")
#: the run's part the split fits, [t0, t1) s from its first sample: the first 50 s with the
#: sample at 50 s (25 001 samples at 2 ms, the samples the split was always fitted on)
FIT_WINDOW = (0.0, 50.002)
FIT_STEPS = ("5deg", "neg_10deg", "20deg", "neg_30deg")
HELD_STEPS = ("neg_5deg", "10deg", "neg_20deg", "30deg", "0deg_run02")
FREE = [
    "arm.joints[*].friction.coulomb",
    "arm.joints[*].friction.static",
    "arm.joints[*].viscous",
    "arm.links[*].torsional_stiffness",
    "arm.links[*].torsional_damping",
    "sensors.alpha_f_1.gain",
    "sensors.alpha_f_2.gain",
    "arm.joints[*].drive.torque_constant",
    "arm.hubs[1].inertia",
]
PRIORS = {
    "arm.joints[0].drive.torque_constant": 0.3,
    "arm.joints[1].drive.torque_constant": 0.3,
    "arm.links[0].torsional_stiffness": 0.3,
    "arm.links[1].torsional_stiffness": 0.3,
    "sensors.alpha_f_1.gain": 0.2,
    "sensors.alpha_f_2.gain": 0.2,
    "arm.hubs[1].inertia": 0.3,
    "arm.joints[0].viscous": 0.5,
    "arm.joints[1].viscous": 0.5,
}
TIES = {
    "sensors.alpha_dot_f_1.gain": "sensors.alpha_f_1.gain",
    "sensors.alpha_dot_f_2.gain": "sensors.alpha_f_2.gain",
}


def _step_file(data: Path, step: str) -> Path:
    name = step if step.endswith("_run02") else f"{step}_run01"
    return data / "lqr-stair" / f"lqr_step_{name}.mat"


def load_split(data: str | Path, examples: str | Path) -> dict:
    """The logs of the split: ``run`` (the 102 s workspace), ``fit_steps``, ``held_steps``."""
    from flexarm.io.logformat import load_log_format

    data, examples = Path(data), Path(examples)
    run = load_log_format(examples / "two-link-workspace.toml").read(data / "lqr_full_10deg.mat")
    st = load_log_format(examples / "two-link-staircase.toml")
    return {
        "run": run,
        "fit_steps": [st.read(_step_file(data, s)) for s in FIT_STEPS],
        "held_steps": {s: st.read(_step_file(data, s)) for s in HELD_STEPS},
    }


def template(friction: bool = True):
    """``quanser-two-link`` as the fit's template (link 1's damping started at 0.1 N·m·s/rad;
    without friction: the joints' friction model ``none``)."""
    from flexarm.specs.scenario import load_scenario

    sc = scenario_with(load_scenario("quanser-two-link"), {"arm.links[0].torsional_damping": 0.1})
    if not friction:
        d = sc.model_dump()
        for j in d["arm"]["joints"]:
            j["friction"] = {"model": "none"}
        from flexarm.specs.scenario import scenario_from_dict

        sc = scenario_from_dict(d, source="quanser-two-link without joint friction")
    return sc


#: the split's bounds (SI): link damping, joint friction levels
BOUNDS = {
    "arm.links[0].torsional_damping": (1e-3, 10.0),
    "arm.links[1].torsional_damping": (1e-3, 10.0),
    "arm.joints[0].friction.coulomb": (0.01, 5.0),
    "arm.joints[0].friction.static": (0.01, 5.0),
    "arm.joints[1].friction.coulomb": (1e-3, 0.5),
    "arm.joints[1].friction.static": (1e-3, 0.5),
}


def default_options() -> FitOptions:
    """The preset's :class:`~flexarm.identification.time_domain.options.FitOptions` (module
    docstring): the four channels, λ = 0.2 and τ = 0.5 s, 2 integration substeps; 3 s
    segments; 45 evaluations with ``ftol`` from the cost's resolution; bounds p0/4 … 4·p0 or
    :data:`BOUNDS`, :data:`PRIORS`, :data:`TIES`. A fresh object each call."""
    return FitOptions(
        cost=Cost(
            channels={c: 1.0 for c in CHANNELS},
            residual_level=0.2,
            correlation_time=0.5,
            substeps=2,
        ),
        shooting=Shooting(segment=3.0),
        # the default path converges (Σ r² resolved) after 42 evaluations (2026-11-30);
        # ftol None: stop when a step lowers Σ r² by less than general.COST_RESOLUTION (a
        # tenth of a standard deviation), relative to the cost's expected size
        local=Local(max_nfev=45, ftol=None),
        priors=Priors(bound_factor=4.0, bounds=dict(BOUNDS), priors=dict(PRIORS), ties=dict(TIES)),
    )


def split_fit_inputs(data: str | Path, examples: str | Path) -> tuple[list, Any]:
    """The split's fit through the one front door: ``(logs, options)`` for
    ``flexarm.fit(presets.two_link(), logs, options=options)`` (module docstring): the
    102 s run (its first :data:`FIT_WINDOW`) and the fitted steps (whole), windows in
    :class:`~flexarm.identification.time_domain.options.FitOptions`; no whole-run
    prediction at the end (``held_out_report`` predicts the held-out data). Replaces
    ``fit_two_link`` (the fit from inside the preset's module, an import circle)."""
    logs = load_split(data, examples)
    fitted = [logs["run"], *logs["fit_steps"]]
    wins = [FIT_WINDOW] + [None] * len(logs["fit_steps"])
    return fitted, FitOptions(windows=wins, predict=False)


def held_out_report(
    scenario, data: str | Path, examples: str | Path, *, plots: str | Path | None = None
) -> dict:
    """fit % per signal of the fitted scenario on the held-out data: the last 52 s of the
    run (one simulation from the logged state at 50 s) and each other step (from its
    file's first sample), with the steps' medians."""
    logs = load_split(data, examples)
    ch = list(CHANNELS)
    last = predict_scenario(
        scenario,
        [logs["run"]],
        FitOptions(windows=[(50.0, 102.0)]),
        channels=ch,
        plots=plots,
        tag="last52s",
    )
    steps = predict_scenario(
        scenario,
        list(logs["held_steps"].values()),
        FitOptions(),
        channels=ch,
        plots=plots,
        tag="steps",
    )
    per_step = dict(zip(logs["held_steps"], steps["fit_percent"].values(), strict=False))
    med = {c: float(np.median([d[c] for d in per_step.values() if c in d])) for c in ch}
    return {
        "last_52s": next(iter(last["fit_percent"].values())),
        "steps": per_step,
        "steps_median": {c: round(v, 2) for c, v in med.items()},
        "plots": last["plots"] + steps["plots"],
    }
