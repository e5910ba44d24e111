"""A design against the scenario's own controller: the same reference step on the scenario
(the nonlinear sampled loop, friction, delays, quantisation and saturation as the scenario
has them), figures of merit and an overlay figure.

Figures (single-link arm, :func:`flexarm.analysis.metrics.step_metrics`, 2 % band):
hub error at the end e = r − θ_m (rad, and in encoder counts of the hub channel's quantum),
hub and tip-angle settling times after the step, the tip's overshoot, the peak command.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from flexarm.analysis.metrics import step_metrics
from flexarm.io.write import save_figure

__all__ = ["step_comparison"]


def _step_scenario(scenario, amplitude: float | None, start: float):
    from flexarm.specs.scenario import scenario_from_dict

    if scenario.reference.type in ("parabolic", "quasi_parabolic"):
        return scenario  # a design that shapes its own move (nested) runs that move
    d = scenario.model_dump(mode="json", exclude_none=True)
    a = amplitude if amplitude is not None else float(scenario.reference.amplitude or 0.1)
    d["reference"] = {"type": "step", "amplitude": a,
                      "offset": float(scenario.initial.motor_angle or 0.0), "start": start}
    return scenario_from_dict(d, scenario.name)


def _figures(res, quantum: float) -> dict:
    t = np.asarray(res.time)
    y = {n: np.asarray(res.outputs)[i] for i, n in enumerate(res.output_labels)}
    r = np.asarray(res.references["reference"])
    hub = step_metrics(t, y["motor_angle"], r)
    tip = step_metrics(t, y["tip_angle"], r)
    e = float(r[-1] - y["motor_angle"][-1])
    return {"hub_error_rad": e, "hub_error_counts": e / quantum if quantum > 0 else None,
            "hub_settling_s": hub.settling_time, "tip_settling_s": tip.settling_time,
            "tip_overshoot": tip.overshoot,
            "peak_command": float(np.abs(np.asarray(res.inputs)).max())}


def step_comparison(scenario, design, path: str | Path | None = None, *,
                    amplitude: float | None = None, start: float = 0.1,
                    overwrite: bool = False) -> dict:
    """Simulate a reference step (``amplitude``, default the scenario's reference amplitude,
    from the initial hub angle at ``start`` s) with the scenario's controller and with
    ``design``'s (a :class:`~flexarm.design.result.Design`); the figures of the module
    docstring per controller, and with ``path`` the overlay figure (hub angle, tip angle,
    command). A design whose scenario carries its own move (``[reference] type =
    "parabolic"`` or ``"quasi_parabolic"``: the nested loops' shaped move of the same distance)
    runs that move instead of the step. Single-link arms only (None for others)."""
    import flexarm
    from flexarm.sim.build import sensor_quanta

    if scenario.arm.kind == "multi_link":
        return None
    runs = {}
    for label, sc in (("scenario", scenario), (design.method, design.scenario)):
        runs[label] = flexarm.simulate(_step_scenario(sc, amplitude, start))
    hub_chan = next((k for k, s in scenario.sensors.items()
                     if (s.signal or k) == "motor_angle"), "motor_angle")
    q = sensor_quanta(scenario.sensors).get(hub_chan, 0.0)
    out = {label: _figures(res, q) for label, res in runs.items()}
    if path is not None:
        from matplotlib.figure import Figure

        fig = Figure(figsize=(8, 8), layout="constrained")
        ax = fig.subplots(3, 1, sharex=True)
        for label, res in runs.items():
            y = {n: np.asarray(res.outputs)[i] for i, n in enumerate(res.output_labels)}
            ax[0].plot(res.time, y["motor_angle"], lw=1.2, label=label)
            ax[1].plot(res.time, y["tip_angle"], lw=1.2, label=label)
            ax[2].step(res.time, np.asarray(res.inputs).reshape(-1), where="post", lw=0.8,
                       label=label)
        ref = np.asarray(next(iter(runs.values())).references["reference"])
        for a in ax[:2]:
            a.plot(next(iter(runs.values())).time, ref, "k--", lw=0.8, label="reference")
        ax[0].set_ylabel("hub angle θ_m [rad]")
        ax[1].set_ylabel("tip angle θ_t [rad]")
        ax[2].set_ylabel(f"command [{'V' if 'voltage' in runs['scenario'].input_labels else 'A'}]")
        ax[2].set_xlabel("time [s]")
        for a in ax:
            a.grid(True, alpha=0.3)
            a.legend(loc="best", fontsize=8)
        fig.suptitle(f"{scenario.name}: the scenario's controller vs the {design.method} design")
        save_figure(fig, path, overwrite=overwrite, dpi=110)
    return out
