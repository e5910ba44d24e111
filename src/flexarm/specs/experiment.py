"""Specs of an experiment on an arm: sampling, sensors, actuator, reference, initial state.

Sensor channels are named after the signals of the plant (``motor_angle``, ``tip_angle``,
``tip_deflection``, ``motor_velocity``); see :mod:`flexarm.sim.sampled`.
"""

# Field types built by calls (Q("rad", gt=0), Count(...), Coefficients(...)) are what
# pydantic reads at runtime; a static checker cannot take a call as a type, so pyright's
# invalid-type-form check is off for this module (flexarm.specs.quantity).
# pyright: reportInvalidTypeForm=false

from __future__ import annotations

from typing import Literal

from pydantic import Field, FiniteFloat, field_validator, model_validator

from flexarm.specs.controllers_bench import StateFeedbackController
from flexarm.specs.friction_compensation import FrictionCompensationSpec
from flexarm.specs.nested import NestedController
from flexarm.specs.quantity import Coefficients, Count, Q, Spec


class Sampling(Spec):
    """Controller sampling: period T (s) and computation delay in whole samples."""

    period: Q("s", gt=0, what="sampling period")
    delay: Count(ge=0, le=100, what="computation delay in samples") = 0


def _not_angular(v: object, name: str) -> object:
    # pint takes the radian as 1, so "100 rad/s" would silently become 100 Hz
    if isinstance(v, str) and "rad" in v:
        from flexarm.units import to_si

        w = to_si(v, "Hz", field=name)
        raise ValueError(
            f"got {v!r}: an angular frequency; the cutoff is in Hz, "
            f'f_c = ω_c / 2π: write "{w / 6.283185307179586:.6g} Hz"'
        )
    return v


class DigitalFilterSpec(Spec):
    """A sensor channel's digital filter, run at the sample rate after gain, noise and
    quantisation (:func:`flexarm.control.lti.digital_filter`): ``kind`` ``lowpass2``
    ω²/(s² + 2ζω s + ω²), ``lowpass2_rate`` / ``derivative2`` ω² s/(s² + 2ζω s + ω²)
    (ω = 2π·``cutoff``, ζ = ``damping``), discretised by ``forward_euler`` (s → (z − 1)/T),
    ``zoh`` or ``tustin``; or ``kind = "tf"`` with ``num``/``den`` in z (descending powers).
    The filter starts at rest on the channel's first reading."""

    kind: Literal["lowpass2", "lowpass2_rate", "derivative2", "tf"]
    cutoff: Q("Hz", gt=0, what="cutoff frequency") | None = None
    damping: Q("", gt=0) = 0.9
    discretisation: Literal["forward_euler", "tustin", "zoh"] = "forward_euler"
    num: list[FiniteFloat] | None = None
    den: list[FiniteFloat] | None = None

    @field_validator("cutoff", mode="before")
    @classmethod
    def _cutoff_hz(cls, v: object) -> object:
        return _not_angular(v, "cutoff")

    @model_validator(mode="after")
    def _complete(self) -> DigitalFilterSpec:
        if self.kind == "tf":
            if self.num is None or self.den is None:
                raise ValueError("kind = 'tf' needs num and den (in z, descending powers)")
            if self.cutoff is not None:
                raise ValueError("kind = 'tf' takes num/den, not cutoff")
            if not any(self.den):
                raise ValueError(f"den = {self.den}: the denominator is zero")
        else:
            if self.cutoff is None:
                raise ValueError(f'kind = {self.kind!r} needs cutoff (Hz), e.g. cutoff = "2 Hz"')
            if self.num is not None or self.den is not None:
                raise ValueError(
                    f"kind = {self.kind!r} takes cutoff and damping; num/den belong to kind = 'tf'"
                )
        return self


class Sensor(Spec):
    """One measured channel: y = gain·x + offset + noise, then A/D quantisation, optional
    pure delay (samples). ``bits = 0`` means no quantisation; ``range`` is the full span
    of the converter (the count is range / 2**bits); ``quantum`` > 0 gives the count
    directly (an encoder's 2π / counts per turn, in the signal's unit) instead of
    range / 2**bits; ``noise`` is a standard deviation.
    ``bandwidth`` f_c > 0 puts an analog first-order low-pass in front of the A/D,
    y_f' = 2π f_c (gain·x − y_f) integrated with the plant between samples (y_f = gain·x
    at t = 0), and y = y_f + offset + noise (0: no filter); in Hz (angular units are
    refused), with 2π f_c T / simulation.substeps <= 0.5. ``offset``: the channel's constant
    zero offset (a strain-gauge bridge's or an encoder's zero, different per recording
    session), signed, in the channel's SI unit (that of gain·x: rad for an encoder, m for a
    gauge calibrated to tip deflection; an angle may carry its unit, "0.5 deg"), added after
    the analog low-pass and before quantisation; a ``zeroing`` window removes it as the
    lab's logger does (the window's mean includes it); 0 (the default): none.

    ``signal``: the plant signal the channel reads (default: the channel's own name), so
    several channels may read one signal (an angle, and its filtered rate). ``filter``: a
    digital filter (:class:`DigitalFilterSpec`) applied at the sample rate after
    quantisation, before the delay; its state starts at rest on the first reading.

    ``zeroing`` W > 0 (s): the logger's tare of the channel (lab loggers zero strain gauges
    over the first second, while the arm may already move): with n = round(W / T) samples,
    the quantised reading y_k is replaced by 0 for k < n and by y_k − (1/n) Σ_{i<n} y_i
    afterwards (the mean of the channel's own reading over the window), before the digital
    filter (the lab's filtered gauge leaves rest one sample after the window,
    ../shared/data/two-link-rig); 0: no zeroing."""

    bits: Count(ge=0, le=32) = 0
    range: Q("", gt=0) = 2 * 3.141592653589793
    quantum: Q("", ge=0, what="quantisation step; 0 = from bits and range") = 0.0
    noise: Q("", ge=0) = 0.0
    gain: Q("") = 1.0
    offset: Q("", what="constant added to the measured value, in the channel's unit") = 0.0
    delay: Count(ge=0, le=1000, what="sensor delay in samples") = 0
    bandwidth: Q("Hz", ge=0, what="first-order low-pass cutoff; 0 = no filter") = 0.0
    signal: str | None = None
    filter: DigitalFilterSpec | None = None
    zeroing: Q("s", ge=0, what="the logger's zeroing window; 0 = none") = 0.0

    @field_validator("bandwidth", mode="before")
    @classmethod
    def _bandwidth_hz(cls, v: object) -> object:
        return _not_angular(v, "bandwidth")

    @model_validator(mode="after")
    def _one_quantum(self) -> Sensor:
        if self.quantum > 0 and self.bits > 0:
            raise ValueError(
                f"give quantum ({self.quantum:g}) or bits ({self.bits}) and range, not both"
            )
        return self


class Actuator(Spec):
    """D/A conversion of the command and its saturation. ``limit`` defaults to the
    motor's current or voltage limit; the D/A spans [-limit, limit] with 2**bits levels."""

    bits: Count(ge=0, le=32) = 0
    limit: Q("", gt=0) | None = None


class Simulation(Spec):
    """Length of the run, integration substeps per sample, and options."""

    duration: Q("s", gt=0)
    substeps: Count(ge=1, le=10000) = 10
    hold_tip: bool = False
    seed: Count(ge=0) = 0


class Initial(Spec):
    """Initial state. A single link: motor angle and velocity, and a static tip deflection
    (m). Several links: ``joint_angles`` and ``joint_velocities`` (one per joint; the links
    start straight, or at their static deflection under gravity with ``equilibrium``)."""

    motor_angle: Q("rad") = 0.0
    motor_velocity: Q("rad/s") = 0.0
    tip_deflection: Q("m") = 0.0
    joint_angles: list[Q("rad")] | None = None
    joint_velocities: list[Q("rad/s")] | None = None
    equilibrium: bool = False


class Reference(Spec):
    """Reference for the controlled angle.

    type: ``step`` (amplitude after ``start``), ``square`` (between offset and
    offset + amplitude, period ``period``), ``sine`` (offset + amplitude·sin(2π t/period)),
    ``constant`` (offset); ``parabolic`` / ``quasi_parabolic``: a rest-to-rest move of
    ``amplitude`` from ``offset`` starting at ``start``, peak ``acceleration`` (rad/s²) and,
    quasi-parabolic, peak ``snap`` (rad/s⁴) (FRB Sec. V-B,
    :mod:`flexarm.control.trajectories`)."""

    type: Literal["step", "square", "sine", "constant", "parabolic", "quasi_parabolic"] = "step"
    amplitude: Q("rad") = 0.0
    offset: Q("rad") = 0.0
    start: Q("s", ge=0) = 0.0
    period: Q("s", gt=0) = 1.0
    acceleration: Q("rad/s**2", gt=0) | None = None
    snap: Q("rad/s**4", gt=0) | None = None

    @model_validator(mode="after")
    def _trajectory(self) -> Reference:
        moves = self.type in ("parabolic", "quasi_parabolic")
        if moves and (self.acceleration is None or self.amplitude == 0.0):
            raise ValueError(
                f"type = {self.type!r} needs amplitude (the move, rad, non-zero) "
                "and acceleration (rad/s**2)"
            )
        if (self.type == "quasi_parabolic") != (self.snap is not None):
            raise ValueError(
                "snap (rad/s**4) is given with type = 'quasi_parabolic' and only "
                f"then; type = {self.type!r}, snap = {self.snap!r}"
            )
        if not moves and self.acceleration is not None:
            raise ValueError(
                f"acceleration is read only by parabolic / quasi_parabolic "
                f"references; type = {self.type!r}"
            )
        return self


class Disturbance(Spec):
    """An input that enters the loop from the log (``[[disturbances]]``), not from the
    controller: a logged pulse, a load force. ``name``: its channel (a log format maps it to
    a column in its ``[disturbances]`` table; :func:`flexarm.sim.build.disturbance_inputs`
    takes it from a log); ``into``: ``"command"`` adds it to the drive command after the
    computation delay, the saturation and the D/A, in the command's unit (V for a voltage
    drive, A for a current drive, N·m for a torque source), ``"force"`` adds it to the
    joint's torque (N·m; N on a prismatic joint) beside the drive's. ``joint``: the joint
    (1-based, as in ``theta_1``), needed on an arm of several joints. Without a log the
    channel is 0, or the array given to :func:`flexarm.sim.build.simulate` as
    ``references={name: ...}``."""

    name: str
    into: Literal["command", "force"]
    joint: Count(ge=1, what="the joint, 1-based") | None = None

    @field_validator("name")
    @classmethod
    def _name(cls, v: str) -> str:
        if not v.isidentifier():
            raise ValueError(f'name = {v!r}: give a plain name (letters, digits, _), e.g. "pulse"')
        return v


class PDController(Spec):
    """u = kp·e + kd·(e_k − e_{k−1})/T with e = reference − measured (discrete PD)."""

    type: Literal["pd"]
    friction_compensation: FrictionCompensationSpec | None = None
    kp: Q("")
    kd: Q("") = 0.0
    measured: str = "motor_angle"


class PIDController(Spec):
    """u = kp·e + ki·T·Σe + kd·(e_k − e_{k−1})/T (discrete PID, backward rectangles)."""

    type: Literal["pid"]
    friction_compensation: FrictionCompensationSpec | None = None
    kp: Q("")
    ki: Q("") = 0.0
    kd: Q("") = 0.0
    measured: str = "motor_angle"


class LeadController(Spec):
    """u = gain·(z − zero)/(z − pole)·e (discrete lead/lag)."""

    type: Literal["lead"]
    friction_compensation: FrictionCompensationSpec | None = None
    gain: Q("")
    zero: FiniteFloat
    pole: FiniteFloat
    measured: str = "motor_angle"


class TFController(Spec):
    """u = C(z)·e with C(z) = num/den in descending powers of z, at the sampling period."""

    type: Literal["tf"]
    friction_compensation: FrictionCompensationSpec | None = None
    num: Coefficients()
    den: Coefficients(denominator=True)
    measured: str = "motor_angle"


class LTIControllerSpec(Spec):
    """Any discrete LTI controller block (:mod:`flexarm.control.lti`): x⁺ = A x + B v,
    u = C x + D v, run every ``dt`` (a whole multiple of the sampling period; default the
    sampling period, or the file's ``Ts``), output held in between and saturated at the
    drives' limits; v is ``setpoint − measured`` over ``inputs`` / ``setpoints``, or the
    block's own input vector ``signals`` (measured channels, reference channels, numbers);
    A, B, C, D inline, as ``num``/``den``, or from ``file`` (+ ``variable``: a struct in a
    ``.mat``, a key prefix in an ``.npz``, an object in JSON; a relative path is relative
    to the TOML's folder). Also each block of ``[[controllers]]`` (own ``dt`` and
    ``outputs``; no two blocks drive one output).

    The input vector v, one of two ways:

    * ``inputs`` (+ ``setpoints``): v_i = setpoint_i − measured_i (the tracking error; per
      input a reference channel or 0, default all 0);
    * ``signals``: the block's own input vector as exported (MATLAB, python-control), in
      its order; each entry a measured channel, a reference (setpoint) channel or a number
      (a constant input), e.g. ``["theta_1", "alpha_f_1", "theta_dot_f_1",
      "alpha_dot_f_1", "theta_ref_1", 0, 0, 0]``.

    The matrices: ``A, B, C, D`` inline (only ``D`` for a static gain, e.g. a state feedback
    K), or SISO ``num``/``den`` in z, or ``file`` (``.mat`` v5 / v7.3, ``.npz``, JSON) with
    ``variable`` naming the struct (``.mat``) / object (JSON) / key prefix (``.npz``:
    ``NAME.A`` or ``NAME_A``) holding fields A, B, C, D and, when present, ``Ts`` or ``dt``
    (s); without ``variable`` the file's top-level A, B, C, D. A relative ``file`` is
    relative to the folder of the TOML that names it. ``outputs``: the plant inputs driven
    (``current_1``, or joint numbers); ``initial_state`` (default 0); ``name``: how messages
    name the block (e.g. the warning that it starts a log from an assumed state). A
    controller with an eigenvalue of A outside the unit circle is refused unless
    ``allow_unstable = true``. Each block of a scenario's ``[[controllers]]`` is one of
    these, with its own ``dt`` and ``outputs`` (no two blocks drive one output)."""

    type: Literal["lti"]
    name: str | None = None
    friction_compensation: FrictionCompensationSpec | None = None
    A: list[list[FiniteFloat]] | None = None
    B: list[list[FiniteFloat]] | None = None
    C: list[list[FiniteFloat]] | None = None
    D: list[list[FiniteFloat]] | None = None
    num: list[FiniteFloat] | None = None
    den: list[FiniteFloat] | None = None
    file: str | None = None
    variable: str | None = None
    dt: Q("s", gt=0, what="controller period") | None = None
    inputs: list[str] | None = None
    setpoints: list[str | FiniteFloat] | None = None
    signals: list[str | FiniteFloat] | None = None
    outputs: list[str | int] = Field(min_length=1)
    initial_state: list[FiniteFloat] | None = None
    allow_unstable: bool = False

    @model_validator(mode="after")
    def _one_source(self) -> LTIControllerSpec:
        given = [
            name
            for name, on in (
                ("A..D", any(getattr(self, k) is not None for k in "ABCD")),
                ("num/den", self.num is not None or self.den is not None),
                ("file", self.file is not None),
            )
            if on
        ]
        if len(given) != 1:
            raise ValueError(
                "give the controller one way: A, B, C, D (D alone for a static "
                "gain), or num and den, or file; got " + (" and ".join(given) if given else "none")
            )
        if given == ["num/den"] and (self.num is None or self.den is None):
            raise ValueError("give num and den together")
        if given == ["A..D"] and self.D is None:
            raise ValueError("D is missing (outputs × inputs); A, B, C are optional together")
        for k in "ABCD":  # rectangular matrices (issue #45: a ragged D was a numpy error)
            rows = getattr(self, k)
            if rows is not None and len({len(r) for r in rows}) > 1:
                raise ValueError(
                    f"{k} is ragged: its rows have {', '.join(str(len(r)) for r in rows)} "
                    f"entries; give every row of {k} the same number of columns"
                )
        if self.variable is not None and self.file is None:
            raise ValueError(
                f"variable = {self.variable!r} selects a struct in a file: give "
                'file too (e.g. file = "ctrl.mat")'
            )
        if (self.inputs is None) == (self.signals is None):
            raise ValueError(
                "give the block's inputs one way: inputs (+ setpoints: v = "
                "setpoint − measured) or signals (the input vector in the "
                "block's order: channels and numbers); got "
                + ("both" if self.inputs is not None else "neither")
            )
        if self.signals is not None:
            if not self.signals:
                raise ValueError("signals is empty: list the block's inputs in its order")
            if self.setpoints is not None:
                raise ValueError(
                    "setpoints go with inputs; with signals, write the setpoint "
                    "channels into the vector itself"
                )
            for j, s in enumerate(self.signals):
                if isinstance(s, str) and not s.strip():
                    raise ValueError(f"signals[{j}] = {s!r}: give a channel name or a number")
            return self
        if not self.inputs:
            raise ValueError("inputs is empty: list the measured channels (one per column of D)")
        if self.setpoints is not None and len(self.setpoints) != len(self.inputs):
            raise ValueError(
                f"setpoints has {len(self.setpoints)} entries, inputs "
                f"{len(self.inputs)}: one setpoint (a reference channel or 0) "
                "per input"
            )
        for s in self.setpoints or []:
            if not isinstance(s, str) and s != 0:
                raise ValueError(f"setpoint {s!r}: give a reference channel name or 0")
        return self


ControllerSpec = (
    PDController
    | PIDController
    | LeadController
    | TFController
    | StateFeedbackController
    | LTIControllerSpec
    | NestedController
)
