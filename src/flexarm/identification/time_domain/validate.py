"""``flexarm.validate``: simulate each log with its own reference and controller on a
scenario's arm (flexarm's own sampled-data simulator) and report the fit

    fit % = 100 (1 − ‖y − ŷ‖ / ‖y − mean(y)‖)

per log and signal (measured hub angle and tip deflection; the first max-delay + 1
samples are left out). Sensor noise is switched off. The initial state comes from the
log itself: hub angle and rate from a parabola through the hub samples just after the hub
channel's delay, the link's tip
deflection and rate from a parabola through the tip samples just after the tip channel's
delay, divided by the sensor gain (a link ringing at t = 0 is normal).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from flexarm.control.state_feedback import from_spec
from flexarm.identification.time_domain import guesses
from flexarm.identification.time_domain.logs import (
    PERIOD_TOL,
    FitInputError,
    as_rig_log,
    check_closed_loop,
)
from flexarm.identification.time_domain.report import overlay_plots
from flexarm.sim.build import prepare
from flexarm.sim.sampled import SimulationDiverged, simulate_loop
from flexarm.specs import Scenario, load_scenario


def validate(
    scenario: Scenario | str | Path,
    logs: Sequence[Any],
    *,
    controller: Any = None,
    plots: str | Path | None = None,
    traces: bool = False,
) -> dict:
    """fit % per log and signal: ``{"fit_percent": {"<file name>": {"motor_angle": x,
    "tip_deflection": y}}, "scenario": ..., "plots": [...]}`` (with ``traces``, also
    ``"traces"``: per log ``time``, ``measured``, ``simulated``). The servo-rig replay
    behind :func:`flexarm.identification.time_domain.predict.predict`, the one entry."""
    sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
    # a single-link rig scenario: [sampling] and [simulation] (validated)
    assert sc.sampling is not None and sc.simulation is not None
    result: dict[str, Any] = {"scenario": sc.name, "fit_percent": {}, "plots": []}
    blogs, trajs = [], []
    for x in logs:
        log = as_rig_log(x, controller)
        check_closed_loop(log)
        T = sc.sampling.period
        if abs(log.dt - T) > PERIOD_TOL * T:
            raise FitInputError(
                f"{log.path}: field 'time': sampling period {log.dt:g} s, but "
                f"the scenario's sampling.period is {T:g} s"
            )
        sensors = {k: v.model_copy(update={"noise": 0.0}) for k, v in sc.sensors.items()}
        n = len(log)
        s2 = sc.model_copy(
            update={
                "sensors": sensors,
                "simulation": sc.simulation.model_copy(update={"duration": (n - 1) * T}),
            }
        )
        p = prepare(
            s2,
            controller=from_spec(log.controller, T),
            references={"reference": log.columns["reference"][: len(range(n))]},
        )
        # the state at t = 0 shows in each channel after its delay (as in the fit's
        # objective: Objective.hub_initial, Objective.tip_initial)
        hub = sc.sensors.get("motor_angle")
        th0, om0 = guesses.initial_hub(log, k=hub.delay if hub is not None else 0)
        tip = sc.sensors.get("tip_deflection")
        gain = tip.gain if tip is not None else 1.0
        kd = tip.delay if tip is not None else 0
        d0, v0 = guesses.initial_tip_at(log, kd, cutoff=tip.bandwidth if tip is not None else 0.0)
        x0 = p.model.initial_state(th0, om0, d0 / gain)
        nb = p.model.beam.mass_dofs
        if nb:
            shape = p.model.initial_state(0.0, 0.0, 1.0) - p.model.initial_state()
            x0[2 + nb : 2 + 2 * nb] += shape[2 : 2 + nb] * v0 / gain
        try:
            out = simulate_loop(p.loop, x0, p.references, p.n_samples)
        except SimulationDiverged as exc:
            c = log.controller
            raise FitInputError(
                f"{log.path}: field 'controller': with K1={c.k1:g} K2={c.k2:g} K3={c.k3:g} "
                f"K4={c.k4:g} the simulated loop on {sc.name} is unstable ({exc}); check the "
                "gains and their signs/units, and the tip sensor's gain sign"
            ) from None
        names = p.loop.sensors.names
        skip = max((s.delay for s in sc.sensors.values()), default=0) + sc.sampling.delay + 1
        fp = {}
        traj = [np.zeros((1, n)) for _ in range(3)]
        for j, sig in enumerate(("motor_angle", "tip_deflection")):
            if sig in names:
                traj[j][0] = out["measured"][:, names.index(sig)]
            if sig in log.outputs and sig in names:
                y, yh = log.columns[sig][skip:], traj[j][0, skip:]
                fp[sig] = round(
                    float(100 * (1 - np.linalg.norm(y - yh) / np.linalg.norm(y - y.mean()))), 3
                )
            else:
                fp[sig] = None
        traj[2][0] = out["command"][:, 0]
        lim = float(p.loop.actuator.limit[0])
        sat = float(np.mean(np.abs(traj[2][0]) >= 0.999 * lim))
        if fp.get("motor_angle") is not None and fp["motor_angle"] < -100 and sat > 0.3:
            c = log.controller
            raise FitInputError(
                f"{log.path}: field 'controller': with K1={c.k1:g} K2={c.k2:g} K3={c.k3:g} "
                f"K4={c.k4:g} the simulated loop on {sc.name} runs away (command saturated "
                f"{100 * sat:.0f} % of the time, hub-angle fit {fp['motor_angle']:.0f} %): "
                "the gains make the simulated loop unstable; check their signs and units "
                "(V/rad, V/m, V*s/rad, V*s/m) and the tip sensor's gain sign"
            )
        result["fit_percent"][log.name] = fp
        if traces:
            meas = {
                c: log.signals[c] for c in ("motor_angle", "tip_deflection") if c in log.signals
            }
            if "voltage" in log.signals:
                meas["command"] = log.signals["voltage"]
            sim = {
                c: traj[j][0] for j, c in enumerate(("motor_angle", "tip_deflection")) if c in names
            }
            sim["command"] = traj[2][0]
            assert log.time is not None  # a bench log has its time (as_rig_log)
            result.setdefault("traces", []).append(
                {"time": log.time - log.time[0], "measured": meas, "simulated": sim}
            )
        blogs.append(log)
        trajs.append(traj)
    if plots is not None:
        for log, tr in zip(blogs, trajs, strict=True):
            result["plots"] += [
                str(q) for q in overlay_plots(plots, [log], tr, result["fit_percent"], "validate")
            ]
    return result
