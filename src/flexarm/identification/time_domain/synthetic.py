"""Synthetic bench logs from flexarm's own simulator (for tests, benchmarks and demos).

Each log: the scenario's arm and sensors (quantised encoder, noisy and delayed strain
gauge), the bench state-feedback law with the given gains, a square-wave reference, and
the link already ringing at t = 0 (initial tip deflection and rate). Columns: time,
reference, voltage, motor_angle, tip_deflection; a ``# controller:`` line.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from flexarm.control.state_feedback import state_feedback
from flexarm.io.logs import write_log
from flexarm.sim.build import prepare
from flexarm.sim.sampled import simulate_loop


def synthetic_log(
    scenario,
    gains: tuple[float, float, float, float],
    path: str | Path,
    *,
    duration: float = 4.0,
    amplitude: float | Sequence[float] = 0.5,
    period: float = 2.0,
    start: float = 0.3,
    tip0: float = 0.01,
    tip_rate0: float = 0.0,
    seed: int = 0,
    overwrite: bool = True,
) -> Path:
    """Simulate one closed-loop experiment and write it as a bench log. ``amplitude``: the
    square wave's step (rad), or a sequence of steps used in turn, one per period (moves
    of several sizes, so that viscous and Coulomb friction act at different speeds)."""
    sc = scenario.model_copy(
        update={"simulation": scenario.simulation.model_copy(update={"duration": duration})}
    )
    dt = sc.sampling.period
    ctrl = state_feedback(*gains, dt)
    p = prepare(sc, controller=ctrl)
    t = p.time
    tau = t - start
    amps = np.atleast_1d(np.asarray(amplitude, float))
    amp = amps[np.floor(np.maximum(tau, 0.0) / period).astype(int) % len(amps)]
    ref = amp * ((np.mod(tau, period) < period / 2) & (tau >= 0))
    x0 = p.model.initial_state(0.0, 0.0, tip0)
    shape = p.model.initial_state(0.0, 0.0, 1.0) - p.model.initial_state(0.0, 0.0, 0.0)
    nb = p.model.beam.mass_dofs
    x0[2 + nb : 2 + 2 * nb] += shape[2 : 2 + nb] * tip_rate0
    out = simulate_loop(p.loop, x0, {"reference": ref}, len(t), seed=seed)
    names = p.loop.sensors.names
    meas = {n: out["measured"][:, i] for i, n in enumerate(names)}
    k1, k2, k3, k4 = gains
    return write_log(
        path,
        t,
        {
            "reference": ref,
            "voltage": out["command"][:, 0],
            "motor_angle": meas["motor_angle"],
            "tip_deflection": meas["tip_deflection"],
        },
        comments=[
            f"controller: state_feedback K1={k1:g} K2={k2:g} K3={k3:g} K4={k4:g}",
            f"source: flexarm synthetic, scenario {scenario.name}",
        ],
        overwrite=overwrite,
        fmt="%.12g",
        required=("time",),
    )


def scenario_log(
    scenario,
    references: dict[str, np.ndarray] | None = None,
    *,
    seed: int = 0,
    name: str = "synthetic",
):
    """A synthetic closed-loop log of any scenario (:func:`flexarm.sim.build.prepare`: its
    sensors with noise and quantisation, its sampled controller, converters), as a
    :class:`flexarm.io.logs.Log` with the measured channels, the references and the
    command (``command`` or ``command_i``) as columns; ``references`` replaces reference
    channels (arrays at the sample instants)."""
    from flexarm.io.logs import Log

    p = prepare(scenario, references=references)
    out = simulate_loop(p.loop, p.x0, p.references, p.n_samples, seed=seed)
    sig = {n: out["measured"][:, i] for i, n in enumerate(p.loop.sensors.names)}
    sig.update({k: np.asarray(v, float) for k, v in p.references.items()})
    u = out["command"]
    for j in range(u.shape[1]):
        sig["command" if u.shape[1] == 1 else f"command_{j + 1}"] = u[:, j]
    return Log(Path(name), p.time, sig, meta={"scenario": scenario.name, "seed": str(seed)})
