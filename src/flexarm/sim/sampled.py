"""The sampled-data closed loop: a continuous plant, a discrete controller, converters.

At each sample instant t_k = k T:

1. the plant's signals s_k are read by the sensors: y = gain·s + offset + noise (seeded
   Gaussian; ``offset`` the channel's constant zero offset, in its unit), quantised to the
   A/D count (range / 2**bits), delayed by the channel's delay (samples).
   A channel with a low-pass cutoff f_c > 0 reads y = y_f + offset + noise instead, y_f the
   output of an analog first-order filter in front of the A/D (its state in gain·s units,
   the offset added at its output),

       y_f' = ω_f (gain·s(x(t), u) − y_f),   ω_f = 2π f_c,   y_f(0) = gain·s(x_0, 0),

   whose state is integrated with the plant's between samples (step 4, same solver and
   substeps), so it sees the continuous signal, not its samples. The noise is added after
   the filter: it is a per-sample white sequence (its standard deviation at the
   converter), which has no continuous-time path through the filter. RK4 reproduces the
   filter's exp(−ω_f h) per substep to 4e-4 relative while ω_f h <= 0.5
   (:data:`FILTER_STEP_LIMIT`); :func:`check_filter_step` asks for more substeps beyond.
   A channel may read any plant signal (``signal``, several channels one signal), and a
   channel with a digital filter (:func:`flexarm.control.lti.digital_filter`) passes its
   quantised reading y_k through it at the sample rate, ξ_{k+1} = A ξ_k + B y_k,
   v_k = C ξ_k + D y_k, before the delay; ξ_0 at rest on the first reading,
   (I − A) ξ_0 = B y_0, or as set (:func:`flexarm.sim.filters.with_filter_state`).
   A channel with a ``zeroing`` window of n samples (the logger's tare) reads, after
   quantisation and before its digital filter, 0 for k < n and y_k − (1/n) Σ_{i<n} y_i
   afterwards (:func:`_zeroing_step`; the window's sum is carried in the loop), which
   removes the channel's offset as the lab's logger does;
2. the controller steps on the measured signals and the references at t_k;
3. the command is delayed by the computation delay (samples), saturated at the
   actuator limit and quantised to the D/A count (2·limit / 2**bits);
4. the plant (and the sensor filters' states) is integrated over [t_k, t_k + T] with the
   command held (zero-order hold).

A continuous-time law (:class:`~flexarm.control.continuous_law.ContinuousLaw`, e.g. De
Luca's (8) and (30)) is the same loop with the law evaluated at every integration stage:
in step 4 the plant sees u(t) = sat(u_k + law(x(t), t)), u_k the held command of the
law's optional sampled part (zero without one), sat the actuator limit
(:func:`flexarm.sim.integrate.integrate_law`); the record holds u(t_k). Loops without such
a law compile exactly as before.

:func:`simulate_loop` is jit-compiled once per loop structure; gains and plant parameters
are traced, so sweeps reuse the compiled code, and :func:`simulate_batch` ``vmap``-s over
any batched leaves of the loop (parameter or gain variations).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax import Array
from jax.typing import ArrayLike

from flexarm.control.continuous_law import ContinuousLaw
from flexarm.control.discrete import Controller
from flexarm.errors import SimulationDiverged  # re-exported
from flexarm.models.plant import Plant
from flexarm.sim.integrate import integrate_hold, integrate_law, solver_for

if TYPE_CHECKING:
    from flexarm.sim.batch import BatchSummary


class Sensors(eqx.Module):
    """Measured channels (names of plant signals) and their converters."""

    names: tuple[str, ...] = eqx.field(static=True)
    index: tuple[int, ...] = eqx.field(static=True)
    #: each channel's delay (whole samples, int32 (C,)): an array, so that loops that
    #: differ only in their delays run one compiled program (a delay search); the reading
    #: buffer holds ``depth`` + 1 samples, ``depth`` >= every delay (:func:`with_depth`)
    delays: Array
    gain: Array
    noise: Array
    quantum: Array  # 0 = no quantisation
    #: the channels' constant zero offsets (in each channel's unit), y = gain·s + offset;
    #: an array like ``gain`` (zeros: the loop as without), so loops stack and trace it
    offset: Array
    #: positions (in ``names``) of the channels with a low-pass filter, and their ω_f
    #: (rad/s); no filtered channel leaves the loop exactly as without filters
    filtered: tuple[int, ...] = eqx.field(static=True, default=())
    omega: Array | None = None
    #: positions of the channels with a digital filter, and the filters' discrete state
    #: spaces padded to one order k: A (n_d, k, k), B, C (n_d, k), D (n_d,); x0 (n_d, k) the
    #: initial states (NaN: at rest on the first reading); no digital filter leaves the loop
    #: exactly as without
    digital: tuple[int, ...] = eqx.field(static=True, default=())
    fA: Array | None = None
    fB: Array | None = None
    fC: Array | None = None
    fD: Array | None = None
    fx0: Array | None = None
    #: positions of the channels the logger zeroes, and their windows in samples (no
    #: zeroed channel leaves the loop exactly as without)
    zeroed: tuple[int, ...] = eqx.field(static=True, default=())
    zero_n: tuple[int, ...] = eqx.field(static=True, default=())
    #: positions of the channels that read the drive's command (:func:`command_signal`), the
    #: plant input each reads, and whether it reads the applied command (``_applied``: with
    #: the ``into = "command"`` disturbances); none leaves the loop exactly as without
    commands: tuple[int, ...] = eqx.field(static=True, default=())
    command_input: tuple[int, ...] = eqx.field(static=True, default=())
    command_applied: tuple[bool, ...] = eqx.field(static=True, default=())
    #: the command channels' gains (``gain`` holds 0 there, and ``index`` 0: a consumer
    #: that reads the channels as plant signals, e.g. a state estimate from a log's first
    #: sample, sees no plant signal in them)
    command_gain: Array | None = None
    #: samples the reading buffer holds beyond the newest (>= the largest delay)
    depth: int = eqx.field(static=True, default=0)

    @classmethod
    def make(
        cls, plant: Plant, channels: dict[str, dict[str, Any]], dt: float | None = None
    ) -> Sensors:
        """Channels (name → a :class:`flexarm.specs.experiment.Sensor` as a dict) of
        ``plant``; ``dt`` the sample period (needed by digital filters with a cutoff)."""
        names = tuple(channels)
        signal = {n: channels[n].get("signal") or n for n in names}
        cmd = {n: c for n in names if (c := command_signal(plant, signal[n])) is not None}
        for n in cmd:
            bad = [
                k
                for k in ("bandwidth", "filter", "zeroing", "delay")
                if channels[n].get(k) not in (None, 0, 0.0)
            ]
            if bad:
                raise ValueError(
                    f"sensor {n!r} reads the drive's command {signal[n]!r}, which has no "
                    f"{', '.join(bad)}: set {bad[0]} = 0 (a command channel takes gain, "
                    "offset, noise and quantisation only)"
                )
        for n in names:
            if n not in cmd and signal[n] not in plant.signal_names:
                raise ValueError(
                    f"sensor {n!r}: the plant has no signal {signal[n]!r}; it has "
                    f"{', '.join(plant.signal_names)} (and its commands "
                    f"{', '.join(plant.input_names)}, with _applied)"
                    + (
                        ""
                        if channels[n].get("signal")
                        else " (name the signal a channel reads with signal = ...)"
                    )
                )

        def get(key, d):
            return jnp.asarray([float(channels[n].get(key, d)) for n in names])

        quantum = [
            float(channels[n]["quantum"])
            if float(channels[n].get("quantum", 0) or 0) > 0
            else float(channels[n]["range"]) / 2 ** int(channels[n]["bits"])
            if int(channels[n].get("bits", 0)) > 0
            else 0.0
            for n in names
        ]
        bw = [float(channels[n].get("bandwidth", 0.0) or 0.0) for n in names]
        for n, f in zip(names, bw, strict=True):
            if not (f >= 0 and np.isfinite(f)):
                raise ValueError(
                    f"sensor {n!r}: bandwidth = {f!r} Hz; give the low-pass "
                    "cutoff as a finite number >= 0 Hz (0 = no filter)"
                )
        filtered = tuple(i for i, f in enumerate(bw) if f > 0)
        omega = jnp.asarray([2 * np.pi * bw[i] for i in filtered]) if filtered else None
        digital = tuple(i for i, n in enumerate(names) if channels[n].get("filter"))
        mats: dict[str, Any] = {}
        if digital:
            from flexarm.control.lti import digital_filter

            filts = [
                digital_filter(
                    channels[names[i]]["filter"], dt, where=f"sensor {names[i]!r}: filter"
                )
                for i in digital
            ]
            k = max(1, *(f.order for f in filts))
            A = np.zeros((len(filts), k, k))
            B, C = np.zeros((len(filts), k)), np.zeros((len(filts), k))
            for j, f in enumerate(filts):
                A[j, : f.order, : f.order], B[j, : f.order], C[j, : f.order] = f.A, f.B, f.C
            mats = dict(
                fA=jnp.asarray(A),
                fB=jnp.asarray(B),
                fC=jnp.asarray(C),
                fD=jnp.asarray([f.D for f in filts]),
                fx0=jnp.full((len(filts), k), jnp.nan),
            )
        zeroed, zero_n = zeroing_windows(channels, dt)
        gain = get("gain", 1.0)
        command_gain = None
        if cmd:
            pos = [i for i, n in enumerate(names) if n in cmd]
            command_gain = gain[jnp.asarray(pos)]
            gain = gain.at[jnp.asarray(pos)].set(0.0)
        offset = get("offset", 0.0)
        bad_off = [n for n, o in zip(names, np.asarray(offset), strict=True) if not np.isfinite(o)]
        if bad_off:
            raise ValueError(
                f"sensors.{bad_off[0]}.offset = {channels[bad_off[0]]['offset']!r}: give the "
                "channel's zero offset as a finite number in its unit (0 = none)"
            )
        return cls(
            names,
            tuple(0 if n in cmd else plant.signal_names.index(signal[n]) for n in names),
            jnp.asarray([int(channels[n].get("delay", 0)) for n in names], jnp.int32),
            gain,
            get("noise", 0.0),
            jnp.asarray(quantum),
            offset,
            filtered,
            omega,
            digital,
            **mats,
            zeroed=zeroed,
            zero_n=zero_n,
            depth=max((int(channels[n].get("delay", 0)) for n in names), default=0),
            commands=tuple(i for i, n in enumerate(names) if n in cmd),
            command_input=tuple(cmd[n][0] for n in names if n in cmd),
            command_applied=tuple(cmd[n][1] for n in names if n in cmd),
            command_gain=command_gain,
        )


def command_signal(plant: Plant, signal: str) -> tuple[int, bool] | None:
    """The plant input a command channel reads and whether it reads the applied command:
    ``signal`` a plant input name (``voltage``, ``current``, ``torque_1``, ...: the
    controller's command after the computation delay, the saturation and the D/A, as a lab's
    logger records its command) or that name + ``_applied`` (the command the drive receives:
    the ``into = "command"`` disturbances added); ``None`` for any other signal. A command
    channel records the command computed at the sample, y_k = gain·u_k + offset + noise,
    quantised; a controller reading it sees the command held over the period before."""
    base = signal.removesuffix("_applied")
    if signal in plant.signal_names or base not in plant.input_names:
        return None
    return plant.input_names.index(base), signal != base


def zeroing_windows(
    channels: dict[str, dict[str, Any]], dt: float | None
) -> tuple[tuple[int, ...], tuple[int, ...]]:
    """Positions (in ``channels``' order) of the channels with a ``zeroing`` window W > 0 s
    and its length n = round(W / dt) samples (:class:`flexarm.specs.experiment.Sensor`).
    A window shorter than half a sample is an error naming the channel."""
    pos, ns = [], []
    for i, (n, c) in enumerate(channels.items()):
        w = float(c.get("zeroing", 0.0) or 0.0)
        if w <= 0:
            continue
        if dt is None or not dt > 0:
            raise ValueError(f"sensor {n!r}: zeroing = {w:g} s needs the sample period")
        k = round(w / dt)
        if k < 1:
            raise ValueError(
                f"sensors.{n}.zeroing = {w:g} s is shorter than one sample "
                f"({dt:g} s): give a window of at least one sample, or 0 for none"
            )
        pos.append(i)
        ns.append(k)
    return tuple(pos), tuple(ns)


def check_zeroing(sensors: Sensors, n_samples: int, dt: float, where: str = "the run") -> None:
    """Raise ValueError naming ``where`` (a log file) and the channel when a zeroing window
    is not shorter than the run: the channel would read 0 throughout."""
    for c, k in zip(sensors.zeroed, sensors.zero_n, strict=True):
        if k >= n_samples:
            raise ValueError(
                f"{where}: sensors.{sensors.names[c]}.zeroing = {k * dt:g} s ({k} samples) is "
                f"not shorter than the {'run' if where == 'the run' else 'log'} ({n_samples} "
                f"samples, {(n_samples - 1) * dt:g} s): "
                "the channel would read 0 throughout; shorten the window, or set zeroing = 0 "
                "for a log that starts after the logger's tare (a later piece of a run)"
            )


#: Largest ω_f h (h the integration substep) :func:`check_filter_step` accepts: RK4's
#: decay over one substep, 1 − z + z²/2 − z³/6 + z⁴/24 at z = ω_f h = 0.5, is within
#: 4e-4 relative of exp(−z) (and RK4 is unstable on the filter beyond z = 2.79).
FILTER_STEP_LIMIT = 0.5


def filter_substeps(bandwidth_hz: float, dt: float) -> int:
    """Fewest substeps of the sample period dt that integrate a sensor filter of cutoff
    ``bandwidth_hz`` accurately: ω_f dt / substeps <= :data:`FILTER_STEP_LIMIT`."""
    return int(np.ceil(2 * np.pi * bandwidth_hz * dt / FILTER_STEP_LIMIT))


def check_filter_step(sensors: Sensors, dt: float | Array, substeps: int) -> None:
    """Raise ValueError naming the channel when a sensor filter is too fast for the
    integration substep dt / substeps (ω_f h > :data:`FILTER_STEP_LIMIT`)."""
    if not sensors.filtered:
        return
    omega = np.asarray(sensors.omega, dtype=float).reshape(-1, len(sensors.filtered))
    dt = float(np.max(np.asarray(dt, dtype=float)))
    for j, c in enumerate(sensors.filtered):
        w = float(np.max(omega[:, j]))
        need = filter_substeps(w / (2 * np.pi), dt)
        if substeps < need:
            raise ValueError(
                f"sensor {sensors.names[c]!r}: bandwidth = {w / (2 * np.pi):g} Hz is too fast "
                f"for the integration step {dt / substeps:g} s (T / substeps = {dt:g} s / "
                f"{substeps}): 2π·bandwidth·step = {w * dt / substeps:.3g} > "
                f"{FILTER_STEP_LIMIT}; raise simulation.substeps to >= {need}, or lower "
                "the bandwidth"
            )


class FilteredPlant(Plant):
    """The plant with the sensor filters' states appended, for the integrator only:
    z = (x, y_f), ż = (f(x, u), ω_f (gain·s(x, u) − y_f))."""

    plant: Plant
    index: tuple[int, ...] = eqx.field(static=True)  # plant signal of each filter
    gain: Array
    omega: Array

    @classmethod
    def around(cls, plant: Plant, index, gain: Array, omega: Array, labels) -> FilteredPlant:
        """``plant`` with one filter on each plant signal ``index[i]`` (gain ``gain[i]``,
        cutoff ``omega[i]`` rad/s), its state named ``filter_<labels[i]>``."""
        return cls(
            plant.state_names + tuple(f"filter_{lb}" for lb in labels),
            plant.signal_names,
            plant.input_names,
            plant,
            tuple(index),
            gain,
            omega,
        )

    def rhs(self, z: Array, u: Array) -> Array:
        n = self.plant.n_states
        x = z[:n]
        s = _pick(self.plant.signals(x, u), self.index)
        return jnp.concatenate([self.plant.rhs(x, u), self.omega * (self.gain * s - z[n:])])

    def signals(self, z: Array, u: Array) -> Array:
        return self.plant.signals(z[: self.plant.n_states], u)

    def project(self, z_prev: Array, z_next: Array, u: Array) -> Array:
        n = self.plant.n_states
        return jnp.concatenate([self.plant.project(z_prev[:n], z_next[:n], u), z_next[n:]])


def _with_filters(plant: Plant, sens: Sensors) -> FilteredPlant:
    assert sens.omega is not None  # set with the filtered channels (Sensors.make)
    return FilteredPlant.around(
        plant,
        [sens.index[c] for c in sens.filtered],
        jnp.stack([sens.gain[c] for c in sens.filtered]),
        sens.omega,
        [sens.names[c] for c in sens.filtered],
    )


class ForcedPlant(Plant):
    """The plant with external joint torques appended to its input, for the integrator
    only: u' = (u, τ_ext), ẋ = f(x, u, τ_ext) (``into = "force"`` disturbances; the plant
    takes them as :meth:`flexarm.models.assembly.Arm.rhs`'s ``tau_ext``)."""

    plant: Plant
    n_u: int = eqx.field(static=True)

    @classmethod
    def around(cls, plant: Plant, n_joints: int) -> ForcedPlant:
        return cls(
            plant.state_names,
            plant.signal_names,
            plant.input_names + tuple(f"external_torque_{j + 1}" for j in range(n_joints)),
            plant,
            plant.n_inputs,
        )

    @property
    def _arm(self) -> Any:
        """The wrapped plant, whose methods take the torques (an Arm's ``tau_ext``)."""
        return self.plant

    def rhs(self, x: Array, u: Array) -> Array:
        return self._arm.rhs(x, u[: self.n_u], u[self.n_u :])

    def signals(self, x: Array, u: Array) -> Array:
        return self._arm.signals(x, u[: self.n_u], u[self.n_u :])

    def project(self, x_prev: Array, x_next: Array, u: Array) -> Array:
        return self._arm.project(x_prev, x_next, u[: self.n_u], u[self.n_u :])


def _n_joints(plant: Plant) -> int:
    return len(getattr(plant, "frictions", ())) or 1


class Actuator(eqx.Module):
    """Saturation at ±limit and D/A quantisation (2·limit / 2**bits; 0 = none)."""

    limit: Array
    quantum: Array


class SampledLoop(eqx.Module):
    """Everything the sampled-data simulation needs, as one pytree."""

    plant: Plant
    controller: Controller
    sensors: Sensors
    actuator: Actuator
    dt: Array
    substeps: int = eqx.field(static=True, default=10)
    delay: int = eqx.field(static=True, default=0)
    solver: str = eqx.field(static=True, default="rk4")
    #: (rtol, atol) of the adaptive ``solver = "tsit5"`` (continuous-time laws)
    tolerances: tuple[float, float] = eqx.field(static=True, default=(1e-8, 1e-10))
    #: inputs from the log (``[[disturbances]]``): (name, ``"command"`` or ``"force"``,
    #: the plant input or the joint, 0-based), read from the reference-like input arrays
    #: by name each sample: a command disturbance is added to the command after the
    #: saturation and the D/A, a force to the joint's torque; none leaves the loop exactly
    #: as without
    disturbances: tuple[tuple[str, str, int], ...] = eqx.field(static=True, default=())


def _quantise(x: Array, q: Array) -> Array:
    return jnp.where(q > 0, jnp.round(x / jnp.where(q > 0, q, 1.0)) * q, x)


def _pick(v: Array, index: tuple[int, ...]) -> Array:
    """v[index] for a static index: slices that fuse, not a gather."""
    if not index:  # a loop without sensors (a continuous law alone)
        return jnp.zeros((0,), v.dtype)
    return jnp.stack([v[i] for i in index])


def _signals(plant: Plant, x: Array, u: Array) -> Array:
    """plant.signals(x, u); for a state carried batch-last, (n_x, B), vmapped over B."""
    if x.ndim == 1:
        return plant.signals(x, u)
    return jax.vmap(plant.signals, in_axes=(-1, -1), out_axes=-1)(x, u)


def with_depth(loop: SampledLoop, depth: int) -> SampledLoop:
    """``loop`` with its sensors' reading buffer ``depth`` + 1 samples long (at least its
    largest delay + 1): loops that differ only in their delays then share one compiled
    program (a search over the delays). Readings are the same for any depth that holds
    the delays."""
    sens = loop.sensors
    need = int(np.max(np.asarray(sens.delays))) if len(sens.names) else 0
    if depth < need:
        raise ValueError(f"with_depth: depth {depth} below the largest delay, {need} samples")
    return eqx.tree_at(lambda lp: lp.sensors, loop, replace=dataclasses.replace(sens, depth=depth))


def initial_carry(loop: SampledLoop, x0: Array) -> tuple:
    """The loop's state at t = 0: plant state, controller state, sensor and command
    buffers (sensors read the initial state; no command before t = 0), and with sensor
    filters their states (the unfiltered initial values)."""
    plant, sens = loop.plant, loop.sensors
    n_u = plant.n_inputs
    u0 = jnp.zeros((n_u,) + x0.shape[1:])  # x0 (n_x, B): a batch carried batch-last
    dmax = sens.depth
    raw = sens.gain * _pick(_signals(plant, x0, u0), sens.index)
    y0 = _quantise(_with_offset(sens, raw), sens.quantum)
    if sens.zeroed:  # the first sample lies in the window: it reads 0
        y0 = _zeroed_out(sens, y0, jnp.zeros((len(sens.zeroed),), y0.dtype))
    xd0 = None
    if sens.digital:
        xd0, y0 = _digital_initial(sens, y0)
    carry = (
        x0,
        loop.controller.init(),
        jnp.tile(y0, (dmax + 1, 1)),
        jnp.zeros((loop.delay + 1, n_u)),
        u0,
    )
    if sens.filtered:
        carry += (_pick(raw, sens.filtered),)
    if sens.digital:
        carry += (xd0,)
    if sens.zeroed:
        carry += (zeroing_start(sens),)
    return carry


def zeroing_start(sens: Sensors, k: int | Array = 0, total: Array | None = None) -> tuple:
    """The zeroing stage's state at sample k: (k, Σ of the zeroed channels' readings over
    the window so far), (0, 0) at a run's start. Without ``total`` the sum is the channels'
    offsets' part alone, offset · min(k, n) (the plant's part taken as 0: a segment that
    starts after the window then reads gain·s, the offset removed, as the log's zeroed
    values do)."""
    if total is None:
        n = jnp.asarray(sens.zero_n, jnp.int32)
        acc = _pick(sens.offset, sens.zeroed) * jnp.minimum(jnp.asarray(k, jnp.int32), n)
    else:
        acc = jnp.asarray(total)
    return (jnp.asarray(k, jnp.int32), acc)


def _with_offset(sens: Sensors, raw: Array) -> Array:
    """The readings gain·s (channels first; a batch carried batch-last) plus each channel's
    offset."""
    off = sens.offset.reshape(sens.offset.shape + (1,) * (raw.ndim - 1))
    return raw + off


def logged_offset(sens: Sensors, filtered: bool = False) -> Array:
    """Each channel's offset as its logged (or simulated) reading carries it, in the
    channel's unit: the sensor's ``offset``, 0 on the zeroed channels (the logger's tare
    removed it). A reading y of a channel, before its digital filter, maps back to gain·s
    as y − logged_offset (what a state read off a log subtracts). ``filtered``: the offset
    the channel's output carries after its digital filter, the reading's times the filter's
    DC gain C (I − A)⁻¹ B + D (1 for ``lowpass2``, 0 for the rate kinds)."""
    off = sens.offset
    if sens.zeroed:
        off = off.at[jnp.asarray(sens.zeroed)].set(0.0)
    if filtered and sens.digital:
        assert sens.fA is not None and sens.fB is not None
        assert sens.fC is not None and sens.fD is not None
        eye = jnp.eye(sens.fA.shape[-1])
        dc = jax.vmap(lambda A, B, C, D: C @ jnp.linalg.solve(eye - A, B) + D)(
            sens.fA, sens.fB, sens.fC, sens.fD
        )
        od = _pick(off, sens.digital)
        off = _put(off, sens.digital, jnp.where(od == 0, 0.0, od * dc))
    return off


def _put(y: Array, positions: tuple[int, ...], v: Array) -> Array:
    """y with the entries at the static ``positions`` replaced by v (in order)."""
    slot = {c: j for j, c in enumerate(positions)}
    return jnp.stack([v[slot[c]] if c in slot else y[c] for c in range(y.shape[0])])


def _zeroed_out(sens: Sensors, y: Array, v: Array) -> Array:
    """The readings y with the zeroed channels' replaced by v."""
    slot = {c: j for j, c in enumerate(sens.zeroed)}
    return jnp.stack([v[slot[c]] if c in slot else y[c] for c in range(len(sens.names))])


def _zeroing_step(sens: Sensors, z: tuple, y: Array) -> tuple[Array, tuple]:
    """One sample of the logger's zeroing (:class:`flexarm.specs.experiment.Sensor`):
    y_k → 0 while k < n (the window's sum accumulates y_k), then y_k − Σ/n."""
    k, acc = z
    yz = _pick(y, sens.zeroed)
    n = jnp.asarray(sens.zero_n, yz.dtype)
    inside = k < jnp.asarray(sens.zero_n)
    out = jnp.where(inside, 0.0, yz - acc / n)
    return _zeroed_out(sens, y, out), (k + 1, acc + jnp.where(inside, yz, 0.0))


def _digital_initial(sens: Sensors, y0: Array) -> tuple[Array, Array]:
    """The digital filters' initial states (at rest on the first reading y0 where not set)
    and the channels' first outputs."""
    # the digital filters' arrays are set with the digital channels (Sensors.make)
    assert sens.fA is not None and sens.fB is not None and sens.fx0 is not None
    ys = _pick(y0, sens.digital)
    k = sens.fA.shape[-1]
    rest = jax.vmap(lambda A, B, y: jnp.linalg.solve(jnp.eye(k) - A, B * y))(sens.fA, sens.fB, ys)
    xd0 = jnp.where(jnp.isnan(sens.fx0), rest, sens.fx0)
    return xd0, _digital_out(sens, xd0, y0)


def _digital_out(sens: Sensors, xd: Array, y: Array) -> Array:
    """The channels' readings with the digitally filtered ones replaced by v = C ξ + D y."""
    assert sens.fC is not None and sens.fD is not None  # set with the digital channels
    ys = _pick(y, sens.digital)
    v = jnp.sum(sens.fC * xd, axis=-1) + sens.fD * ys
    slot = {c: j for j, c in enumerate(sens.digital)}
    return jnp.stack([v[slot[c]] if c in slot else y[c] for c in range(len(sens.names))])


# XLA:CPU runs the kernels and copies of a loop body one after the other only when the
# body has at most 8 of them or touches no buffer over 512 bytes; otherwise it schedules
# them as a dataflow graph, which costs more per kernel than these tiny kernels take. The
# body of a loop over all samples reads and writes the whole-run input and record arrays,
# so single runs loop over blocks of samples whose arrays stay within 512 bytes
# (docs/performance.md: 2.37 -> 2.11 ms for the single-link benchmark).
_SMALL_BUFFER_BYTES = 512


def _block_size(loop: SampledLoop) -> int:
    """Samples per block: the widest per-sample record of a block fits in 512 bytes. A
    continuous law's sample is 10+ substeps of law and plant, so blocks gain nothing
    there (measured on the De Luca arm: the same run time) and cost ~10 % compile: 1."""
    if isinstance(loop.controller, ContinuousLaw):
        return 1
    widest = max(loop.plant.n_states, len(loop.sensors.names), loop.plant.n_inputs, 1)
    return max(1, _SMALL_BUFFER_BYTES // (8 * widest))


def _scan(loop: SampledLoop, carry: tuple, refs: dict[str, Array], noise: Array, block: int = 1):
    """The sample loop: final carry and the records (states, signals, measured, command)
    at the sample instants. The signals are evaluated after the loop, for all samples at
    once (one kernel instead of one per sample). With ``block`` > 1 the loop runs over
    blocks of that many samples (a padded last block leaves the carry unchanged)."""
    plant, ctrl, sens, act = loop.plant, loop.controller, loop.sensors, loop.actuator
    solver = solver_for(loop.solver)
    h = loop.dt / loop.substeps
    n_x = plant.n_states
    law = ctrl if isinstance(ctrl, ContinuousLaw) else None
    if loop.disturbances and law is not None:
        raise ValueError(
            f"disturbances {', '.join(d[0] for d in loop.disturbances)}: a continuous-time "
            "law cannot take logged disturbances; run them with a sampled controller"
        )
    pushes = tuple((d[0], d[2]) for d in loop.disturbances if d[1] == "command")
    forces = tuple((d[0], d[2]) for d in loop.disturbances if d[1] == "force")
    n_u = plant.n_inputs
    n_j = _n_joints(plant)
    base = ForcedPlant.around(plant, n_j) if forces else plant
    fplant = _with_filters(base, sens) if sens.filtered else None
    cpos = sens.commands

    def integrate(z, u, t_k):
        """Step 4 over one period from z (plant state, then any filter states)."""
        P = base if fplant is None else fplant
        if law is None:
            return integrate_hold(P, z, u, h, loop.substeps, solver), u
        # a continuous law: sat(u_held + law(x, t)) at every stage (control/continuous_law)

        def command(y, t):
            assert law is not None  # integrate returned above without a law
            uc = law.command(y[:n_x], t)
            trail = (1,) * (uc.ndim - 1)  # a batch carried batch-last: (m, B)
            lim = act.limit.reshape(act.limit.shape + trail)
            return jnp.clip(u.reshape(u.shape + trail) + uc, -lim, lim)

        return (
            integrate_law(P, z, command, t_k, h, loop.substeps, solver, loop.tolerances),
            command(z, t_k),
        )

    def sample(carry, inp):
        x, cstate, sbuf, ubuf, u_prev = carry[:5]
        ref_k, noise_k = inp
        # 1. sensors (a filtered channel reads its filter's output)
        s = _signals(plant, x, u_prev)
        raw = sens.gain * _pick(s, sens.index)
        if cpos:  # command channels: the command held over the period before
            assert sens.command_gain is not None  # set with the command channels
            held = jnp.stack([u_prev[i] for i in sens.command_input])
            raw = _put(raw, cpos, sens.command_gain * held)
        if fplant is not None:
            yf = carry[5]
            slot = {c: j for j, c in enumerate(sens.filtered)}
            raw = jnp.stack([yf[slot[c]] if c in slot else raw[c] for c in range(len(sens.names))])
        # the offset after the analog filters, before the noise and the A/D
        y = _quantise(raw + sens.offset + sens.noise * noise_k, sens.quantum)
        extra = ()
        pos = 6 if fplant is not None else 5  # the optional parts of the carry
        zpos = pos + (1 if sens.digital else 0)
        if sens.zeroed:  # the logger's zeroing, after quantisation, before the filters
            y, z_next = _zeroing_step(sens, carry[zpos], y)
        if sens.digital:  # digital filters at the sample rate, after quantisation
            xd = carry[pos]
            ys = _pick(y, sens.digital)
            y = _digital_out(sens, xd, y)
            assert sens.fA is not None and sens.fB is not None
            extra = (jnp.einsum("ijk,ik->ij", sens.fA, xd) + sens.fB * ys[:, None],)
        if sens.zeroed:
            extra += (z_next,)
        sbuf = jnp.concatenate([y[None], sbuf[:-1]], axis=0)
        meas_vec = sbuf[sens.delays, jnp.arange(len(sens.names))]
        meas = {n: meas_vec[i] for i, n in enumerate(sens.names)}
        # 2. controller, 3. computation delay, saturation, D/A
        t_k = law.time(cstate) if law is not None else None
        cstate, u_c = ctrl.step(cstate, meas, ref_k)
        ubuf = jnp.concatenate([u_c[None], ubuf[:-1]], axis=0)
        u = _quantise(jnp.clip(ubuf[-1], -act.limit, act.limit), act.quantum)
        u_ctrl = u
        for name, i in pushes:  # logged disturbances into the command, after the D/A
            u = u.at[i].add(ref_k[name])
        if cpos:  # command channels record the command computed at this sample
            vals = jnp.stack(
                [
                    (u if ap else u_ctrl)[i]
                    for i, ap in zip(sens.command_input, sens.command_applied, strict=True)
                ]
            )
            assert sens.command_gain is not None
            yc = (
                sens.command_gain * vals
                + _pick(sens.offset, cpos)
                + _pick(sens.noise, cpos) * _pick(noise_k, cpos)
            )
            meas_vec = _put(meas_vec, cpos, _quantise(yc, _pick(sens.quantum, cpos)))
        if forces:  # logged forces on the joints, beside the drives' torques
            f_ext = jnp.zeros((n_j,), u.dtype)
            for name, j in forces:
                f_ext = f_ext.at[j].add(ref_k[name])
            u = jnp.concatenate([u, f_ext])
        # 4. plant (and sensor filters) over one period, command held
        # (with a continuous law the record holds the command applied at t_k)
        if fplant is None:
            x_next, u_rec = integrate(x, u, t_k)
            held = u_rec[:n_u] if forces else u_rec
            return (x_next, cstate, sbuf, ubuf, held) + extra, (x, meas_vec, u_rec)
        z, u_rec = integrate(jnp.concatenate([x, yf]), u, t_k)
        held = u_rec[:n_u] if forces else u_rec
        return (z[:n_x], cstate, sbuf, ubuf, held, z[n_x:]) + extra, (x, meas_vec, u_rec)

    def sample_if_valid(carry, inp):
        valid, inp = inp
        new, rec = sample(carry, inp)
        return jax.tree.map(lambda a, b: jnp.where(valid, a, b), new, carry), rec

    n = noise.shape[0]
    if block <= 1 or block >= n:
        carry, (xs, meas, us) = jax.lax.scan(sample, carry, (refs, noise))
    else:
        nb = -(-n // block)
        pad = nb * block - n

        def blocked(a):
            a = jnp.pad(a, [(0, pad)] + [(0, 0)] * (a.ndim - 1))
            return a.reshape((nb, block) + a.shape[1:])

        inp, body = jax.tree.map(blocked, (refs, noise)), sample
        if pad:
            inp, body = (blocked(jnp.ones((n,), dtype=bool)), inp), sample_if_valid
        carry, recs = jax.lax.scan(lambda c, i: jax.lax.scan(body, c, i), carry, inp)
        xs, meas, us = (r.reshape((nb * block,) + r.shape[2:])[:n] for r in recs)
    sig = jax.vmap(lambda x, u: _signals(base, x, u))(xs, us)
    return carry, (xs, sig, meas, us[:, :n_u] if forces else us)


_run = eqx.filter_jit(_scan)


def _run_from_x0(loop: SampledLoop, x0: Array, refs, noise, block: int = 1):
    carry, recs = _scan(loop, initial_carry(loop, x0), refs, noise, block)
    return recs + (carry[0],)


def _sensor_noise(seed: ArrayLike, n_samples: int, n_channels: int) -> Array:
    return jax.random.normal(jax.random.PRNGKey(seed), (n_samples, n_channels))


def _run_seeded(loop: SampledLoop, x0: Array, refs: dict[str, Array], seed: Array):
    """A whole run in one compiled call: sensor noise, initial carry, the sample loop."""
    n = next(iter(refs.values())).shape[0]
    return _run_from_x0(
        loop, x0, refs, _sensor_noise(seed, n, len(loop.sensors.names)), _block_size(loop)
    )


# compiled; its callers pass NumPy arrays, which the jit turns into the Arrays above
_run_all: Callable[..., Any] = eqx.filter_jit(_run_seeded)


def simulate_loop(
    loop: SampledLoop,
    x0: Any,
    references: dict[str, Any],
    n_samples: int,
    *,
    seed: int = 0,
    progress: Callable[[int, int], None] | None = None,
    chunk: int = 5000,
) -> dict[str, np.ndarray]:
    """Run the loop for ``n_samples`` samples; return numpy arrays.

    ``references`` maps channel names to arrays of length ``n_samples`` (values at the
    sample instants). With ``progress``, the run goes in chunks of ``chunk`` samples
    (one compilation) and ``progress(done, total)`` is called after each. Raises
    :class:`SimulationDiverged` when the state blows up, ValueError when a sensor
    filter is too fast for the substep (:func:`check_filter_step`).
    """
    check_filter_step(loop.sensors, loop.dt, loop.substeps)
    check_zeroing(loop.sensors, n_samples, float(loop.dt))
    refs = _prepare_refs(references, n_samples)
    x0 = np.asarray(x0, dtype=float)
    if progress is None or n_samples <= chunk:
        *recs, xf = _run_all(loop, x0, refs, np.asarray(seed, dtype=np.int64))
        recs = [np.asarray(r) for r in recs]
        if progress is not None:
            progress(n_samples, n_samples)
    else:
        noise = _sensor_noise(np.asarray(seed, dtype=np.int64), n_samples, len(loop.sensors.names))
        carry = _init_jit(loop, jnp.asarray(x0))
        parts = []
        for k0 in range(0, n_samples, chunk):
            k1 = min(k0 + chunk, n_samples)
            pad = chunk - (k1 - k0)
            sl = {k: jnp.pad(v[k0:k1], (0, pad), mode="edge") for k, v in refs.items()}
            nz = jnp.pad(noise[k0:k1], ((0, pad), (0, 0)))
            carry_next, recs = _run(loop, carry, sl, nz, _block_size(loop))
            parts.append([np.asarray(r)[: k1 - k0] for r in recs])
            # a padded last chunk ran past the end: its state after sample k1 is the
            # recorded state at the start of the first padded sample
            carry = carry_next if pad == 0 else (recs[0][k1 - k0],) + tuple(carry_next[1:])
            progress(k1, n_samples)
            if not np.all(np.isfinite(parts[-1][1])):
                break
        recs = [np.concatenate([p[i] for p in parts]) for i in range(4)]
        if len(recs[0]) < n_samples:  # stopped early on divergence: pad with NaN
            recs = [
                np.concatenate([r, np.full((n_samples - len(r),) + r.shape[1:], np.nan)])
                for r in recs
            ]
        xf = carry[0]
    xs, sig, meas, us = recs
    out = {
        "states": xs,
        "signals": sig,
        "measured": meas,
        "command": us,
        "final_state": np.asarray(xf),
        "references": {k: np.asarray(v) for k, v in refs.items()},
    }
    check_divergence(out, loop, float(loop.dt))
    return out


_init_jit = eqx.filter_jit(initial_carry)


def simulate_batch(
    loop: SampledLoop,
    x0: Any,
    references: dict[str, Any],
    n_samples: int,
    *,
    seed: int = 0,
    in_axes: Any = 0,
    batch_size: int | None = 512,
    check: bool = True,
    client: Any = None,
    chunks: Any = None,
) -> dict[str, np.ndarray] | BatchSummary:
    """``vmap`` of :func:`simulate_loop` over the batched leaves of ``loop``.

    ``in_axes`` is a pytree prefix of ``loop`` telling which leaves carry a leading batch
    axis (the default 0 batches every array leaf; use e.g.
    ``eqx.tree_at(lambda l: l.controller.D, jax.tree.map(lambda _: None, loop), 0)``
    to batch only some). ``x0`` is shared. Batches larger than ``batch_size`` run as a
    loop over equal chunks of at most that many rollouts, each chunk vectorised
    (``None``: all rollouts at once); the results do not depend on it. ``check=False``
    returns diverged rollouts (non-finite or beyond ±:data:`DIVERGENCE_LIMIT`) as they are
    instead of raising :class:`SimulationDiverged` (a batch of uncertain plants flags them).
    With ``client``, a :class:`flexarm.sim.batch.BatchExecutor` (e.g.
    :class:`flexarm.distributed.DaskExecutor`; or ``chunks``, a
    :class:`flexarm.sim.batch.ChunkOptions`, for the same chunks in-process) the rollouts
    run in chunks, one task each, and only per-rollout reductions come back (a
    :class:`flexarm.sim.batch.BatchSummary`, the trajectories only with
    ``chunks.trajectories``; :func:`flexarm.sim.batch.simulate_chunked`)."""
    check_filter_step(loop.sensors, loop.dt, loop.substeps)
    if client is not None or chunks is not None:  # in chunks, on the executor given
        from flexarm.sim.batch import simulate_chunked

        return simulate_chunked(
            simulate_batch,
            loop,
            x0,
            references,
            n_samples,
            seed=seed,
            in_axes=in_axes,
            batch_size=batch_size,
            executor=client,
            options=chunks,
            limit=DIVERGENCE_LIMIT,
        )
    refs = _prepare_refs(references, n_samples)
    fn = _batched(in_axes, batch_size)
    xs, sig, meas, us, xf = fn(
        loop, np.asarray(x0, dtype=float), refs, np.asarray(seed, dtype=np.int64)
    )
    out = {
        "states": np.asarray(xs),
        "signals": np.asarray(sig),
        "measured": np.asarray(meas),
        "command": np.asarray(us),
        "final_state": np.asarray(xf),
        "references": {k: np.asarray(v) for k, v in refs.items()},
    }
    if check:
        check_divergence(out, loop, float(np.ravel(np.asarray(loop.dt))[0]), batched=True)
    return out


_BATCHED: dict = {}


def _is_none(x) -> bool:
    return x is None


def _batched(in_axes, batch_size: int | None):
    """One compiled vmap per batching pattern and chunk size (cached so sweeps compile
    once). Chunks of a few hundred rollouts keep each kernel's arrays in the core's
    caches: 0.20 -> 0.17 ms per rollout for the benchmark's batch of 1000 in two chunks
    (docs/performance.md)."""
    key = str(jax.tree.structure(in_axes)) + str(jax.tree.leaves(in_axes)) if in_axes != 0 else 0
    key = (key, batch_size)
    if key in _BATCHED:
        return _BATCHED[key]
    vmapped = eqx.filter_vmap(_run_from_x0, in_axes=(in_axes, None, None, None))

    def run(loop, x0, refs, seed):
        n = next(iter(refs.values())).shape[0]
        noise = _sensor_noise(seed, n, len(loop.sensors.names))
        if batch_size is None:
            return vmapped(loop, x0, refs, noise)
        # each leaf of the loop and its batch axis (None: shared by all rollouts)
        leaves, treedef = jax.tree.flatten(loop, is_leaf=_is_none)
        axes = jax.tree.leaves(
            jax.tree.broadcast(in_axes, loop, is_leaf=_is_none), is_leaf=_is_none
        )
        axes = [
            a if a is not None and eqx.is_array(x) else None
            for x, a in zip(leaves, axes, strict=False)
        ]
        sizes = {x.shape[a] for x, a in zip(leaves, axes, strict=False) if a is not None}
        if len(sizes) != 1 or max(sizes) <= batch_size:
            return vmapped(loop, x0, refs, noise)
        size = sizes.pop()
        n_chunks = -(-size // batch_size)
        per_chunk = -(-size // n_chunks)  # equal chunks, fewer than n_chunks padded rollouts
        pad = n_chunks * per_chunk - size

        def chunked(x, a):  # (n_chunks, per_chunk, ...), padded with the last rollout
            x = jnp.moveaxis(x, a, 0)
            x = jnp.concatenate([x, jnp.repeat(x[-1:], pad, axis=0)]) if pad else x
            return x.reshape((n_chunks, per_chunk) + x.shape[1:])

        axes0 = jax.tree.unflatten(treedef, [None if a is None else 0 for a in axes])
        vmapped0 = eqx.filter_vmap(_run_from_x0, in_axes=(axes0, None, None, None))

        def one_chunk(batched):
            it = iter(batched)
            chunk = [x if a is None else next(it) for x, a in zip(leaves, axes, strict=False)]
            return vmapped0(jax.tree.unflatten(treedef, chunk), x0, refs, noise)

        out = jax.lax.map(
            one_chunk, [chunked(x, a) for x, a in zip(leaves, axes, strict=False) if a is not None]
        )
        return jax.tree.map(
            lambda o: o.reshape((o.shape[0] * o.shape[1],) + o.shape[2:])[:size], out
        )

    _BATCHED[key] = eqx.filter_jit(run)
    return _BATCHED[key]


def simulate_law_batch(
    loop: SampledLoop, x0: Any, n_samples: int, axes: Any, *, chunk: int = 128
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A batch of a continuous law alone (a :class:`ContinuousLaw` without sampled part, no
    sensors) whose ``params`` hold the batch along axis 0 where the vmap-style prefix
    ``axes`` says 0: the loop of :func:`simulate_loop` with the plant's state carried
    batch-last, (n_x, chunk), so that every layer of a plant's right-hand side that takes
    trailing batch dimensions (:class:`~flexarm.models.multilink.MultiLinkPlant`) is one SIMD
    kernel over the chunk, and the law is vmapped over it. Chunks of ``chunk`` rollouts run
    one after the other (``lax.map``: a chunk's working set stays in cache); the batch is
    padded to a whole number of chunks with copies of the last rollout. The plant's
    parameters are shared; x0 is (n_x,), shared, or (N, n_x), one per rollout. This layout measured
    3.9 ms per rollout against
    13.4 ms for :func:`simulate_batch`'s vmap on the De Luca arm (docs/performance.md).

    Returns states (N, n, n_x), signals (N, n, p) and applied commands (N, n, m) at the
    samples; no divergence check (the caller flags rollouts)."""
    law = loop.controller
    if not isinstance(law, ContinuousLaw) or law.sampled is not None or loop.sensors.names:
        raise ValueError(
            "simulate_law_batch runs a ContinuousLaw alone (no sampled part, no "
            "sensors); batch other loops with simulate_batch"
        )
    leaves, treedef = jax.tree.flatten(law.params)
    full = jax.tree.map(
        lambda ax, sub: jax.tree.map(lambda _: _Axis(ax), sub),
        axes,
        law.params,
        is_leaf=lambda a: a is None,
    )
    leaf_axes = tuple(a.v for a in jax.tree.leaves(full, is_leaf=lambda a: isinstance(a, _Axis)))
    if any(a not in (None, 0) for a in leaf_axes):
        raise ValueError("axes must be 0 (batched along the first axis) or None")
    sizes = {int(x.shape[0]) for x, a in zip(leaves, leaf_axes, strict=False) if a is not None}
    if len(sizes) != 1:
        raise ValueError(
            f"the batched parameters disagree on the batch size: {sorted(sizes)}"
            if sizes
            else "axes batches no parameter (give 0 on the batched leaves)"
        )
    size = sizes.pop()
    x0 = jnp.asarray(x0, float)
    if x0.ndim == 2 and x0.shape[0] != size:
        raise ValueError(f"x0 holds {x0.shape[0]} initial states; the batch has {size}")
    chunk = max(1, min(int(chunk), size))
    pad = -size % chunk

    def padded(x):
        return x if pad == 0 else jnp.concatenate([x, jnp.repeat(x[-1:], pad, 0)])

    leaves = [x if a is None else padded(x) for x, a in zip(leaves, leaf_axes, strict=False)]
    x0 = padded(x0) if x0.ndim == 2 else x0
    batched = eqx.tree_at(
        lambda lp: lp.controller.params, loop, jax.tree.unflatten(treedef, leaves)
    )
    refs = _prepare_refs({}, n_samples)
    xs, sig, us = _run_law_batch(batched, x0, refs, leaf_axes, chunk)
    return np.asarray(xs)[:size], np.asarray(sig)[:size], np.asarray(us)[:size]


class _Axis:
    """A batch axis (0 or None) as an opaque pytree leaf."""

    def __init__(self, v):
        self.v = v


@eqx.filter_jit
def _run_law_batch(loop: SampledLoop, x0: Array, refs, leaf_axes: tuple, chunk: int):
    law = loop.controller
    assert isinstance(law, ContinuousLaw)  # simulate_law_batch's loop runs a continuous law
    leaves, treedef = jax.tree.flatten(law.params)
    size = next(x.shape[0] for x, a in zip(leaves, leaf_axes, strict=False) if a is not None)
    n = next(iter(refs.values())).shape[0]
    noise = jnp.zeros((n, 0))

    def one_chunk(c):
        lv = [
            x if a is None else jax.lax.dynamic_slice_in_dim(x, c * chunk, chunk, 0)
            for x, a in zip(leaves, leaf_axes, strict=False)
        ]
        ctrl = ContinuousLaw(
            law.law, jax.tree.unflatten(treedef, lv), law.dt, law.n_inputs, None, leaf_axes
        )
        xc = (
            jax.lax.dynamic_slice_in_dim(x0, c * chunk, chunk, 0).T
            if x0.ndim == 2
            else jnp.broadcast_to(x0[:, None], x0.shape + (chunk,))
        )
        xs, sig, _, us, _ = _run_from_x0(
            eqx.tree_at(lambda lp: lp.controller, loop, ctrl), xc, refs, noise
        )
        return tuple(jnp.moveaxis(a, -1, 0) for a in (xs, sig, us))  # (chunk, n, ·)

    out = jax.lax.map(one_chunk, jnp.arange(size // chunk))
    return tuple(a.reshape((a.shape[0] * a.shape[1],) + a.shape[2:]) for a in out)


def _prepare_refs(references: dict[str, Any], n: int) -> dict[str, np.ndarray]:
    refs = {}
    for k, v in references.items():
        a = np.asarray(v, dtype=float)
        if a.ndim == 0:
            a = np.full((n,), a)
        if a.shape != (n,):
            raise ValueError(f"reference {k!r}: expected {n} samples, got shape {a.shape}")
        refs[k] = a
    refs.setdefault("reference", np.zeros((n,)))
    return refs


DIVERGENCE_LIMIT = 1e6


def check_divergence(out: dict, loop: SampledLoop, dt: float, *, batched: bool = False) -> None:
    """Raise :class:`SimulationDiverged` naming the first sample and signal that blew up
    (non-finite, or beyond ±1e6 in SI units)."""
    sig = out["signals"]
    # fast path, two passes without temporaries (a NaN makes max() NaN, failing the test)
    if sig.size == 0 or (sig.max() <= DIVERGENCE_LIMIT and sig.min() >= -DIVERGENCE_LIMIT):
        return
    bad = ~np.isfinite(sig) | (np.abs(sig) > DIVERGENCE_LIMIT)
    if not bad.any():
        return
    names = loop.plant.signal_names
    if batched:
        rows = np.nonzero(bad.any(axis=(1, 2)))[0]
        b = int(rows[0])
        k, j = np.argwhere(bad[b])[0]
        where = f"rollout {b} of the batch ({len(rows)} rollouts diverged), "
    else:
        k, j = np.argwhere(bad)[0]
        where = ""
    raise SimulationDiverged(
        f"{where}the closed loop diverged at t = {k * dt:.4g} s (sample {k}): signal "
        f"{names[j]!r} = {sig[(b, k, j) if batched else (k, j)]:.3g}. The loop is unstable "
        "(gains too high for the plant, sampling period or delay), or the integration "
        "step is too coarse: lower the gains or raise simulation.substeps."
    )
