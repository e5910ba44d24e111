"""From a validated :class:`~flexarm.specs.scenario.Scenario` to a runnable sampled loop.

:func:`simulate` is the one-call entry point (``flexarm simulate`` uses it):
scenario → model → plant, controller, sensors, actuator → :func:`simulate_loop` →
:class:`~flexarm.sim.result.SimulationResult`.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import Any

import jax.numpy as jnp
import numpy as np

from flexarm.control import discrete
from flexarm.errors import FlexarmError
from flexarm.models.single_link import SingleLinkModel
from flexarm.sim.result import SimulationResult
from flexarm.sim.sampled import Actuator, SampledLoop, Sensors, simulate_loop
from flexarm.specs.arm import SingleLinkArm
from flexarm.specs.experiment import LTIControllerSpec, Reference
from flexarm.specs.multilink import MultiLinkArm
from flexarm.specs.scenario import Scenario

#: the share of this machine's memory one simulation's result may take (the loop keeps the
#: state, the measured signals and the command of every sample, and JAX a few copies)
MEMORY_SHARE = 0.25
#: 8-byte values kept per sample and state variable or signal, with the run's copies
_BYTES_PER_VALUE = 8 * 4


def _physical_memory() -> float:
    """This machine's memory (bytes); 16 GiB where the OS does not say."""
    try:
        return float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):  # pragma: no cover - non-POSIX
        return 16.0 * 2**30


def sample_times(scenario: Scenario, dt: float, values_per_sample: int = 16) -> np.ndarray:
    """The sample instants 0, dt, ... ≤ ``[simulation] duration`` (s), checked first against
    this machine's memory: a run whose samples (``values_per_sample`` 8-byte values each,
    with the copies the loop makes) would take more than :data:`MEMORY_SHARE` of it is
    refused with one line naming the duration, the sample count and the fix, before any
    array is allocated."""
    assert scenario.simulation is not None  # [sampling] and [simulation] come together
    duration = float(scenario.simulation.duration)
    n = int(math.floor(duration / dt + 1e-9)) + 1
    need = float(n) * max(int(values_per_sample), 1) * _BYTES_PER_VALUE
    have = MEMORY_SHARE * _physical_memory()
    if need > have:
        longest = have / (max(int(values_per_sample), 1) * _BYTES_PER_VALUE) * dt
        raise FlexarmError(
            f"scenario {scenario.name!r}: {n:.3g} samples of {dt:g} s would need about "
            f"{need / 2**30:.3g} GiB, more than {MEMORY_SHARE:.0%} of this machine's "
            f"{have / MEMORY_SHARE / 2**30:.3g} GiB",
            field="[simulation] duration (s)",
            value=duration,
            fix=f"shorten it (at most about {longest:.3g} s here) or lengthen [sampling] period",
        )
    return np.arange(n) * dt


def reference_trajectory(ref: Reference):
    """The :class:`~flexarm.control.trajectories.PointToPointTrajectory` of a
    ``parabolic`` / ``quasi_parabolic`` reference (a move of ``amplitude`` from 0; the
    reference is ``offset`` + u(t − ``start``))."""
    from flexarm.control.trajectories import parabolic, quasi_parabolic

    sign = 1.0 if ref.amplitude > 0 else -1.0
    if ref.type == "parabolic":
        assert ref.acceleration is not None  # a moving reference has one (validated)
        traj = parabolic(abs(ref.amplitude), ref.acceleration)
    elif ref.type == "quasi_parabolic":
        assert ref.acceleration is not None
        traj = quasi_parabolic(abs(ref.amplitude), ref.acceleration, max_snap=ref.snap)
    else:
        raise ValueError(f"reference.type = {ref.type!r} is not a point-to-point move")
    if sign > 0:
        return traj
    from dataclasses import replace

    return replace(traj, distance=-traj.distance, states=-traj.states)


def reference_signal(ref: Reference, t: np.ndarray) -> np.ndarray:
    """The reference (rad) at the times ``t`` (s)."""
    if ref.type in ("parabolic", "quasi_parabolic"):
        return ref.offset + reference_trajectory(ref).position(t - ref.start)
    if ref.type == "constant":
        return np.full_like(t, ref.offset)
    if ref.type == "step":
        return ref.offset + ref.amplitude * (t >= ref.start - 1e-12)
    tau = t - ref.start
    if ref.type == "sine":
        return ref.offset + ref.amplitude * np.sin(2 * np.pi * tau / ref.period) * (tau >= 0)
    # square: offset for the first half period, offset + amplitude for the second
    phase = np.mod(tau, ref.period) / ref.period
    return ref.offset + ref.amplitude * ((phase >= 0.5) & (tau >= 0))


def scenario_controller(
    scenario: Scenario, dt: float, *, input_names, references=None, measured=None
) -> discrete.Controller:
    """The controller of a scenario: its ``[controller]`` (:func:`controller_from_spec`), or
    its ``[[controllers]]`` as :class:`~flexarm.control.lti.Blocks` (each block at its own
    period, driving its own inputs). ``measured``: the channels and plant signals a block's
    ``signals`` may name; ``references``: the run's reference channels."""
    if scenario.controllers is None:
        return controller_from_spec(
            scenario.controller,
            dt,
            input_names=input_names,
            references=references,
            measured=measured,
            quanta=sensor_quanta(scenario.sensors),
        )
    from flexarm.control.lti import Blocks, lti_from_spec

    blocks = []
    for i, spec in enumerate(scenario.controllers):
        assert isinstance(spec, LTIControllerSpec)  # [[controllers]]: lti blocks (validated)
        where = f"[[controllers]][{i}]" + (f" ({spec.name})" if spec.name else "")
        blocks.append(
            lti_from_spec(
                spec,
                base_dt=dt,
                input_names=tuple(input_names),
                references=references,
                measured=measured,
                where=where,
            )
        )
    driven: dict[int, str] = {}
    for b in blocks:
        for o in b.outputs:
            if o in driven:
                raise ValueError(
                    f"{b.name}: outputs: {input_names[o]!r} is driven by "
                    f"{driven[o]} already; two controllers cannot drive one "
                    "output (sum them in one block, or give each its own outputs)"
                )
            driven[o] = b.name
    return Blocks(*blocks)


def controller_from_spec(
    spec,
    dt: float,
    *,
    input_names=None,
    references=None,
    measured=None,
    quanta: dict[str, float] | None = None,
) -> discrete.Controller:
    """The discrete controller a scenario's ``[controller]`` section describes; an ``lti``
    controller needs the plant's ``input_names`` and checks its setpoints against the
    run's ``references`` (channel names). With ``[controller.friction_compensation]`` the
    feedback is wrapped in :class:`~flexarm.control.friction_compensation.FrictionCompensated`;
    ``quanta`` (channel → quantisation step) gives its default velocity deadband."""
    if getattr(spec, "type", None) == "nested":
        return _nested_from_spec(spec, dt, quanta or {})
    ctrl = _feedback_from_spec(
        spec, dt, input_names=input_names, references=references, measured=measured
    )
    fc = getattr(spec, "friction_compensation", None)
    if fc is None:
        return ctrl
    from flexarm.control.friction_compensation import friction_compensated

    return friction_compensated(
        ctrl,
        fc.level,
        dt=dt,
        measured=fc.measured,
        quantum=(quanta or {}).get(fc.measured, 0.0),
        velocity_deadband=fc.velocity_deadband,
        rest_deadband=fc.rest_deadband,
    )


def _nested_from_spec(spec, dt: float, quanta: dict[str, float]) -> discrete.Controller:
    """``[controller] type = "nested"`` (:mod:`flexarm.specs.nested`); its friction
    feedforward is the inner loop's own (on G_cm1's output, FRB Fig. 4), not the wrapper."""
    import control

    from flexarm.control.nested import nested_loops

    def tf(num, den):
        return control.tf(num, den, dt)

    fc = spec.friction_compensation
    if fc is not None and fc.measured != "motor_angle":
        raise ValueError(
            f"controller.friction_compensation.measured = {fc.measured!r}: the "
            "nested loops compensate the hub; use 'motor_angle'"
        )
    return nested_loops(
        tf(spec.gcm1_num, spec.gcm1_den),
        tf(spec.gcm2_num, spec.gcm2_den),
        tf(spec.gcb_num, spec.gcb_den),
        dt=dt,
        coupling_gain=spec.coupling_gain,
        friction_level=fc.level if fc is not None else 0.0,
        angle_resolution=quanta.get("motor_angle", 0.0),
        velocity_deadband=fc.velocity_deadband if fc is not None else None,
        rest_deadband=fc.rest_deadband if fc is not None else None,
        deflection_to_angle=(spec.deflection_to_angle if spec.tip == "tip_deflection" else None),
    )


def nested_feedforward(spec, ref: Reference, t: np.ndarray) -> np.ndarray:
    """The ``feedforward`` channel θ̂_mr(t) = (N θ_tr)(t + advance) of a nested controller
    (rad): N(s) = ``feedforward_num/den`` on the reference trajectory, sent
    ``feedforward_advance`` s early (:func:`flexarm.control.outer_loop.trajectory_references`).
    A static N (a number) acts on any reference; a dynamic one needs a parabolic or
    quasi-parabolic reference (its derivatives)."""
    import control

    from flexarm.control.outer_loop import trajectory_references

    n = control.tf(spec.feedforward_num, spec.feedforward_den)
    n0 = float(np.real(control.dcgain(n)))
    if len(spec.feedforward_num) == 1 and len(spec.feedforward_den) == 1:
        return n0 * reference_signal(ref, t)
    if ref.type not in ("parabolic", "quasi_parabolic"):
        raise ValueError(
            f"controller.feedforward_num/den is a dynamic N(s); it needs the "
            f"derivatives of the reference, so [reference] type must be "
            f"'parabolic' or 'quasi_parabolic', not {ref.type!r}"
        )
    ff = trajectory_references(
        n, reference_trajectory(ref), t, start=ref.start, advance=spec.feedforward_advance
    )["feedforward"]
    return n0 * ref.offset + ff


def sensor_quanta(sensors: dict) -> dict[str, float]:
    """Channel → quantisation step (signal units) of a scenario's ``[sensors]``: ``quantum``,
    or ``range / 2**bits``, or 0 (unquantised)."""
    return {
        k: float(s.quantum or (s.range / 2**s.bits if s.bits else 0.0)) for k, s in sensors.items()
    }


def _feedback_from_spec(
    spec, dt: float, *, input_names=None, references=None, measured=None
) -> discrete.Controller:
    if spec is None:
        return discrete.from_transfer_function(([0.0], [1.0]), dt)
    if spec.type == "lti":
        from flexarm.control.lti import lti_from_spec

        return lti_from_spec(
            spec,
            base_dt=dt,
            input_names=tuple(input_names or ("u",)),
            references=references,
            measured=measured,
        )
    m = spec.measured
    if spec.type == "pd":
        return discrete.pd(spec.kp, spec.kd, dt, measured=m)
    if spec.type == "pid":
        return discrete.pid(spec.kp, spec.ki, spec.kd, dt, measured=m)
    if spec.type == "lead":
        return discrete.lead(spec.gain, spec.zero, spec.pole, measured=m)
    if spec.type == "state_feedback":
        from flexarm.control.state_feedback import from_spec

        return from_spec(spec, dt)
    if spec.type == "tf":
        return discrete.from_transfer_function((spec.num, spec.den), dt, measured=m)
    raise ValueError(f"controller.type = {spec.type!r} is not known")


@dataclass
class Prepared:
    """A scenario ready to run (kept so callers can change pieces and re-run)."""

    scenario: Scenario
    model: Any  # SingleLinkModel or MultiLinkModel
    loop: SampledLoop
    x0: np.ndarray
    references: dict[str, np.ndarray]
    time: np.ndarray

    @property
    def n_samples(self) -> int:
        return len(self.time)


def _references(scenario: Scenario, t: np.ndarray, extra) -> dict[str, np.ndarray]:
    refs = {"reference": reference_signal(scenario.reference, t)}
    refs.update({k: reference_signal(r, t) for k, r in scenario.references.items()})
    if getattr(scenario.controller, "type", None) == "nested":
        refs["feedforward"] = nested_feedforward(scenario.controller, scenario.reference, t)
    c = scenario.controller
    gs = getattr(c, "gain_signals", None)
    if gs:  # a logged gain schedule: the declared gains where no array is given
        ks = tuple(getattr(c, f"k{i}") for i in range(1, 5))
        for name, k in zip(gs, ks, strict=True):
            refs[name] = np.full_like(t, float(k), dtype=float)
    refs.update(extra or {})
    for d in scenario.disturbances:  # no array given: the disturbance is 0
        refs.setdefault(d.name, np.zeros_like(t))
    return refs


class ReferenceLengthError(FlexarmError, ValueError):
    """Reference arrays whose length does not fit the run."""


def run_length(scenario: Scenario, t: np.ndarray, references) -> np.ndarray:
    """The sample instants of a run given reference arrays ``references`` (channel →
    values at the samples): the scenario's own ``t`` (from ``[simulation] duration``), or,
    where every array has one length within one sample of it (a duration rounded to the
    period: 24.84 s of a 24,841-sample log), that length. Arrays of other lengths are one
    :class:`~flexarm.errors.FlexarmError` line naming the channel, both counts and the fix."""
    dt = float(t[1] - t[0]) if len(t) > 1 else float(scenario.sampling.period)  # type: ignore[union-attr]
    lengths = {k: int(np.shape(v)[0]) for k, v in (references or {}).items() if np.ndim(v) == 1}
    for k, v in (references or {}).items():
        if np.ndim(v) > 1:
            raise ReferenceLengthError(
                f"scenario {scenario.name!r}: reference {k!r} has shape {np.shape(v)}",
                field=f"references[{k!r}]",
                value=np.shape(v),
                fix="give one value per sample (a 1-D array) or one number",
            )
    if not lengths:
        return t
    n = len(t)
    sizes = set(lengths.values())
    if len(sizes) == 1 and abs(next(iter(sizes)) - n) <= 1:
        return np.arange(next(iter(sizes))) * dt
    k, m = next((k, m) for k, m in lengths.items() if m != n)
    raise ReferenceLengthError(
        f"scenario {scenario.name!r}: reference {k!r} has {m} samples, but "
        f"[simulation] duration = {(n - 1) * dt:.9g} s at the period {dt:g} s makes {n}"
        + (f" (other arrays: {sorted(sizes)})" if len(sizes) > 1 else ""),
        field="[simulation] duration (s)",
        value=(n - 1) * dt,
        fix=f"give arrays of {n} samples, or duration = {(m - 1) * dt:.9g} s for {m}",
    )


def loop_disturbances(scenario: Scenario) -> tuple[tuple[str, str, int], ...]:
    """The scenario's ``[[disturbances]]`` as :attr:`SampledLoop.disturbances`: (name,
    ``"command"`` / ``"force"``, the joint 0-based: the plant input of its drive, or the
    joint the force acts on)."""
    return tuple((d.name, d.into, (d.joint or 1) - 1) for d in scenario.disturbances)


class DisturbanceError(FlexarmError, ValueError):
    """A log and a scenario that disagree on the logged disturbances."""


def disturbance_inputs(scenario: Scenario, log) -> dict[str, np.ndarray]:
    """The arrays of the scenario's ``[[disturbances]]`` from ``log`` (a
    :class:`flexarm.io.logs.Log`), to pass with the references (``references=`` of
    :func:`prepare` / :func:`simulate`, or the reference inputs of the sampled loop): one
    per declared name, taken from the log's column of that name. A declared disturbance the
    log lacks, or a column the log's format maps as a disturbance
    (:attr:`flexarm.io.logs.Log.disturbances`) that the scenario does not declare, is one
    :class:`DisturbanceError` line naming the log, the name and the fix."""
    where = getattr(log, "where", "<log>")
    declared = scenario.disturbance_names()
    sig = getattr(log, "signals", {})
    for name in declared:
        if name not in sig:
            raise DisturbanceError(
                f"{where}: no column {name!r}, which scenario {scenario.name!r} declares in "
                f"[[disturbances]] (into = {_into(scenario, name)!r}); map it in the log "
                f"format's [disturbances] ({name} = COLUMN), or drop it from the scenario"
            )
    for name in getattr(log, "disturbances", ()) or ():
        if name not in declared:
            raise DisturbanceError(
                f"{where}: the log's format maps a disturbance {name!r} that scenario "
                f"{scenario.name!r} does not declare; add [[disturbances]] name = {name!r} "
                'with into = "command" or "force" to the scenario, or drop it from the '
                "log format's [disturbances]"
            )
    return {name: np.asarray(sig[name], dtype=float) for name in declared}


def _into(scenario: Scenario, name: str) -> str:
    return next(d.into for d in scenario.disturbances if d.name == name)


def _prepare_multi(scenario: Scenario, controller, references) -> Prepared:
    """A multi-link arm in the sampled-data loop (see :func:`prepare`)."""
    from flexarm.control.joint_pd import joint_pd_from_spec
    from flexarm.control.regulation import residual_deflection
    from flexarm.models.assembly import multi_link_arm

    if scenario.sampling is None:
        raise ValueError(
            f"scenario {scenario.name!r}: no [sampling] and [simulation]; a "
            "multi-link arm without them runs its [regulation] law "
            "(flexarm.simulate runs it; prepare builds sampled loops only)"
        )
    assert scenario.simulation is not None  # [sampling] and [simulation] come together
    arm, model = multi_link_arm(scenario.arm)
    dt = scenario.sampling.period
    t = sample_times(scenario, dt, arm.n_states + 2 * arm.n_joints + len(scenario.sensors) + 8)
    t = run_length(scenario, t, references)
    spec = scenario.controller
    refs = _references(scenario, t, references)
    if controller is not None:
        ctrl = controller
    elif spec is not None and spec.type == "joint_pd":
        ctrl = joint_pd_from_spec(spec, arm, model, dt)
    else:
        if getattr(spec, "friction_compensation", None) is not None and arm.n_joints > 1:
            raise ValueError(
                f"scenario {scenario.name!r}: [controller.friction_compensation] "
                f"compensates one joint; this arm has {arm.n_joints}. Use "
                '[controller] type = "joint_pd" with friction_compensation = '
                "[C_f per joint] for a multi-link arm"
            )
        ctrl = scenario_controller(
            scenario,
            dt,
            input_names=arm.input_names,
            references=refs,
            measured=set(scenario.sensors) | set(arm.signal_names),
        )
    channels = {k: v.model_dump() for k, v in scenario.sensors.items()}
    for needed in _measured_names(ctrl):
        channels.setdefault(needed, {})
    if not channels:
        channels = {f"theta_{i + 1}": {} for i in range(arm.n_joints)}
    sensors = Sensors.make(arm, channels, dt)
    limit = np.asarray(arm.limit, float)
    if scenario.actuator.limit is not None:
        limit = np.minimum(limit, scenario.actuator.limit)
    bits = scenario.actuator.bits
    if bits and not np.all(np.isfinite(limit)):
        raise ValueError(
            f"scenario {scenario.name!r}: actuator.bits = {bits} needs a finite "
            "command limit (the D/A span); give actuator.limit or the drives' limits"
        )
    q = 2 * limit / 2**bits if bits else np.zeros_like(limit)
    loop = SampledLoop(
        arm,
        ctrl,
        sensors,
        Actuator(jnp.asarray(limit), jnp.asarray(q)),
        jnp.asarray(dt),
        scenario.simulation.substeps,
        scenario.sampling.delay,
        disturbances=loop_disturbances(scenario),
    )
    ini = scenario.initial
    nj = arm.n_joints
    th0 = np.zeros(nj) if ini.joint_angles is None else np.asarray(ini.joint_angles, float)
    om0 = np.zeros(nj) if ini.joint_velocities is None else np.asarray(ini.joint_velocities, float)
    d0 = residual_deflection(model, th0) if ini.equilibrium else None
    x0 = np.concatenate(
        [model.state(theta=th0, delta=d0, theta_dot=om0), np.zeros(arm.n_states - 2 * model.n_q)]
    )
    return Prepared(scenario, model, loop, x0, refs, t)


def prepare(
    scenario: Scenario,
    controller: discrete.Controller | None = None,
    references: dict[str, np.ndarray] | None = None,
) -> Prepared:
    """Build model, plant, loop, initial state and references of a scenario: any arm
    (:class:`flexarm.models.assembly.Arm`), one sampled-data loop.

    ``controller`` replaces the scenario's ``[controller]``; ``references`` adds or
    replaces reference channels (arrays at the sample instants)."""
    if scenario.arm.kind == "multi_link":
        return _prepare_multi(scenario, controller, references)
    # a single-link scenario has [sampling] and [simulation] and a single-link arm (validated)
    assert scenario.sampling is not None and scenario.simulation is not None
    assert isinstance(scenario.arm, SingleLinkArm)
    model = SingleLinkModel.from_spec(scenario.arm, hold_tip=scenario.simulation.hold_tip)
    plant = model.plant()
    dt = scenario.sampling.period
    t = sample_times(scenario, dt, plant.n_states + len(scenario.sensors) + 8)
    t = run_length(scenario, t, references)
    refs = _references(scenario, t, references)
    ctrl = (
        controller
        if controller is not None
        else scenario_controller(
            scenario,
            dt,
            input_names=plant.input_names,
            references=refs,
            measured=set(scenario.sensors) | set(plant.signal_names),
        )
    )
    channels = {k: v.model_dump() for k, v in scenario.sensors.items()}
    for needed in _measured_names(ctrl):
        channels.setdefault(needed, {})
    if not channels:
        channels["motor_angle"] = {}
    sensors = Sensors.make(plant, channels, dt)
    limit = scenario.actuator.limit or float(model.drive.limit)
    q = 2 * limit / 2**scenario.actuator.bits if scenario.actuator.bits else 0.0
    loop = SampledLoop(
        plant,
        ctrl,
        sensors,
        Actuator(jnp.asarray([limit]), jnp.asarray([q])),
        jnp.asarray(dt),
        scenario.simulation.substeps,
        scenario.sampling.delay,
        disturbances=loop_disturbances(scenario),
    )
    ini = scenario.initial
    x0 = model.initial_state(ini.motor_angle, ini.motor_velocity, ini.tip_deflection)
    return Prepared(scenario, model, loop, x0, refs, t)


def _measured_names(ctrl) -> set[str]:
    names = set()
    for leaf in _walk(ctrl):
        m = getattr(leaf, "measured", None)
        if isinstance(m, str):
            names.add(m)
        for attr in ("measured_signals",):
            names.update(getattr(leaf, attr, ()) or ())
    return names


def _walk(c):
    yield c
    for attr in ("parts", "outer", "inner", "sampled"):
        sub = getattr(c, attr, None)
        if sub is None:
            continue
        for s in sub if isinstance(sub, tuple) else (sub,):
            yield from _walk(s)


def run_prepared(p: Prepared) -> SimulationResult:
    """Simulate a prepared scenario."""
    assert p.scenario.simulation is not None  # a prepared scenario is a sampled-data one
    out = simulate_loop(p.loop, p.x0, p.references, p.n_samples, seed=p.scenario.simulation.seed)
    return to_result(p, out)


def to_result(p: Prepared, out: dict, index: int | None = None) -> SimulationResult:
    """Wrap raw simulator arrays: one rollout, rollout ``index`` of a batch, or (index None
    on :func:`~flexarm.sim.sampled.simulate_batch`'s arrays) the whole batch as one result."""
    pick = (lambda a: a) if index is None else (lambda a: a[index])
    assert p.scenario.sampling is not None  # a prepared scenario is a sampled-data one
    sig = pick(out["signals"])
    meas = pick(out["measured"])
    plant = p.loop.plant
    return SimulationResult(
        p.time,
        {n: sig[..., i] for i, n in enumerate(plant.signal_names)},
        {n: meas[..., i] for i, n in enumerate(p.loop.sensors.names)},
        out["references"],
        pick(out["command"]),
        plant.input_names,
        pick(out["states"]),
        plant.state_names,
        title=p.scenario.name,
        meta={"scenario": p.scenario.name, "sampling_period_s": p.scenario.sampling.period}
        | ({"joint": "prismatic"} if getattr(p.scenario, "prismatic", False) else {}),
    )


#: a scenario's ``[regulation] law`` → the law of :mod:`flexarm.control.regulation`
REGULATION_LAWS = {
    "constant": "law_pd_constant",
    "online": "law_pd_online",
    "quasistatic": "law_pd_quasistatic",
}


def regulation_run(scenario: Scenario) -> tuple:
    """The multi-link model, the law's parameters and the run (the summary writer draws
    from all three). A multi-link scenario's ``[regulation]``: the continuous-time law (DLS eq. (8)
    ``constant``, eq. (30) ``online`` / ``quasistatic``) u = sat(law(x, t)) on the arm from
    θ(0) = ``initial``, δ(0) = 0, θ̇(0) = 0, fixed-step RK4 (``step``), outputs every
    ``output_period`` over ``duration`` (:func:`flexarm.sim.continuous.simulate_continuous`)."""
    from flexarm.control import regulation as R
    from flexarm.models.multilink import build_multilink
    from flexarm.sim.continuous import simulate_continuous

    reg = scenario.regulation
    if reg is None:
        raise ValueError(
            f"scenario {scenario.name!r}: no [sampling] and [simulation] and no "
            "[regulation]; give a sampled loop ([sampling], [simulation], "
            "[controller]) or a [regulation] law to simulate"
        )
    assert isinstance(scenario.arm, MultiLinkArm)  # [regulation] is multi-link only (validated)
    model = build_multilink(scenario.arm)
    params = R.regulation_params(
        model,
        np.diag(reg.kp),
        np.diag(reg.kd),
        reg.target,
        theta_0=reg.initial,
        duration=reg.interpolation_time,
    )
    x0 = np.zeros(2 * model.n_q)
    x0[: model.n_links] = reg.initial
    run = simulate_continuous(
        model,
        getattr(R, REGULATION_LAWS[reg.law]),
        x0,
        reg.duration,
        reg.output_period,
        params=params,
        step=reg.step,
    )
    run.title = scenario.name
    return model, params, run


def simulate_regulation(scenario: Scenario) -> SimulationResult:
    """A multi-link scenario's ``[regulation]`` law in continuous time
    (:func:`regulation_run`'s run)."""
    return regulation_run(scenario)[2]


def simulate(
    scenario: Scenario,
    controller: discrete.Controller | None = None,
    references: dict[str, np.ndarray] | None = None,
) -> SimulationResult:
    """Simulate a scenario and return the result: the sampled-data loop
    (:func:`prepare`), or, for a multi-link scenario with ``[regulation]`` and no
    ``[sampling]``, its continuous-time law (:func:`simulate_regulation`)."""
    if (
        scenario.arm.kind == "multi_link"
        and scenario.sampling is None
        and scenario.regulation is not None
    ):
        if controller is not None or references:
            raise ValueError(
                f"scenario {scenario.name!r} runs its [regulation] law "
                "(continuous time); a controller or references apply to a "
                "sampled loop: give the scenario [sampling] and [simulation]"
            )
        return simulate_regulation(scenario)
    return run_prepared(prepare(scenario, controller, references))
