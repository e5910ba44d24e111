"""The output-error objective of a bench fit, evaluated for a whole population at once.

For parameters p the log's loop is closed in simulation
(:mod:`flexarm.sim.rig_loop`)
and compared with the log on the measured hub angle θ and tip deflection d:

    V(p) = Σ_logs Σ_{y ∈ {θ, d}} ‖y − ŷ(p)‖² / ‖y − mean(y)‖²  = Σ (1 − fit_y/100)²

(each signal weighted by its spread; the first ``skip`` samples, where the simulated
sensor delay lines still hold the initial value, are left out). fit % per log and signal
is 100 (1 − ‖y − ŷ‖/‖y − mean y‖). Sensor low-pass filters of known cutoff (``filters``,
Hz) are simulated in front of the converters
(:mod:`flexarm.sim.rig_loop`).

Each log's initial state: hub angle and rate from its first samples; the link's tip
deflection and rate (measured units) at t = 0 are those the log shows at sample k = (tip
delay), from a parabola through samples k ... k + 20 (fitted through the known tip filter,
:func:`flexarm.identification.time_domain.guesses.initial_tip_at`), divided by the tip gain g; the
local stage refines the latter two per log.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Any

import numpy as np

from flexarm.identification.time_domain import guesses
from flexarm.identification.time_domain.logs import FitInputError
from flexarm.identification.time_domain.params import ParamSpace
from flexarm.io.logs import Log
from flexarm.sim.batch import cpu_cores, run_chunks
from flexarm.sim.rig_loop import as_jax, closed_loop_cost, closed_loop_run
from flexarm.sim.sampled import FILTER_STEP_LIMIT, filter_substeps

BIG = 1e3  # cost of a diverged rollout (per log; a perfect fit scores 0, a zero model ~2)
#: λ and τ (s) that weigh a prior (eq. (2) of the general engine) against V: a fit of this
#: rig class leaves a misfit of about 0.2 of a signal's spread (fit 80 %), correlated over
#: about 50 ms (the link's period and the sensor filters)
PRIOR_RESIDUAL_LEVEL = 0.2
PRIOR_CORRELATION_TIME = 0.05


@dataclass
class Rig:
    """What the data sheet gives: drive gain k_u (N·m per V or A), back-EMF damping k_ω
    (N·m·s/rad), command limit, link length (m), and the spec fields to write back."""

    drive: str
    k_u: float
    k_omega: float
    limit: float
    length: float
    motor: dict
    encoder_quantum: float
    tip_quantum: float = 0.0
    vel_tol: float = 1e-3
    #: the stiffer clamp of a gear train pushed stuck (:func:`guesses.pushed_ringing`):
    #: the link's elastic terms (1 + s φ) times while the hub is stuck, φ rising from 0 to 1
    #: as k_u |u| goes from the threshold to the full push (N·m); 0: none
    push_stiffening: float = 0.0
    push_threshold: float = float("inf")
    push_full: float = float("inf")


FILTER_CHANNELS = ("motor_angle", "tip_deflection")


def check_filters(filters: Any, dt: float, substeps: int) -> dict[str, float]:
    """``fit(filters=...)``: known low-pass cutoffs (Hz) by channel, validated; every
    channel in the result (0 = no filter). Raises FitInputError naming field, value, fix."""
    if filters is None:
        return {c: 0.0 for c in FILTER_CHANNELS}
    if not isinstance(filters, dict):
        raise FitInputError(
            f"fit: field 'filters' = {filters!r}: give a dict of cutoffs in "
            "Hz by channel, e.g. {'tip_deflection': 50.0}"
        )
    out = {c: 0.0 for c in FILTER_CHANNELS}
    for ch, hz in filters.items():
        if ch not in FILTER_CHANNELS:
            raise FitInputError(
                f"fit: field 'filters' has channel {ch!r}, which is not "
                f"known; use {' or '.join(map(repr, FILTER_CHANNELS))}"
            )
        try:
            f = float(hz)
        except (TypeError, ValueError):
            f = float("nan")
        if not (np.isfinite(f) and f >= 0):
            raise FitInputError(
                f"fit: field 'filters[{ch!r}]' = {hz!r}: a cutoff must be a "
                "finite number of Hz >= 0 (the sensor's -3 dB frequency; "
                "0 = no filter)"
            )
        need = filter_substeps(f, dt)
        if substeps < need:
            raise FitInputError(
                f"fit: field 'filters[{ch!r}]' = {f:g} Hz is too fast for the integration "
                f"step T / substeps = {dt:g} s / {substeps} (2π f_c h = "
                f"{2 * np.pi * f * dt / substeps:.3g} > {FILTER_STEP_LIMIT}): pass "
                f"substeps >= {need}"
            )
        out[ch] = f
    return out


class Objective:
    """Cost of parameter populations on a set of logs (one compiled simulation per shape)."""

    def __init__(
        self,
        logs: list[Log],
        rig: Rig,
        space: ParamSpace,
        sessions: list[int],
        *,
        mode: str = "closed_loop",
        substeps: int = 2,
        comp_delay: int = 0,
        n_samples: int | None = None,
        chunk: int = 64,
        wc_guess: float = 20.0,
        filters: dict[str, float] | None = None,
    ):
        self.logs, self.rig, self.space, self.sessions = logs, rig, space, np.asarray(sessions)
        #: known low-pass cutoffs (Hz) of the channels, 0 = none (checked by fit())
        self.filters = {"motor_angle": 0.0, "tip_deflection": 0.0, **(filters or {})}
        self.mode, self.substeps, self.comp_delay, self.chunk = mode, substeps, comp_delay, chunk
        T = logs[0].dt
        N = max(len(g) for g in logs) if n_samples is None else n_samples
        L = len(logs)
        self.N, self.L, self.T = N, L, T
        self.skip = space.max_delay + comp_delay + 1

        def z():
            return np.zeros((L, N))

        ref, yt, yd, wt, wd, volt = z(), z(), z(), z(), z(), z()
        K, tau = np.zeros((L, N, 4)), np.zeros(L)
        self.sst = np.zeros((L, 2))
        for i, g in enumerate(logs):
            n = min(len(g), N)

            def pad(a, n=n):
                return np.concatenate([a[:n], np.full(N - n, a[n - 1])])

            ref[i] = pad(g.columns["reference"])
            if "voltage" in g.columns:
                volt[i] = pad(g.columns["voltage"])
            for j, (name, y, w) in enumerate((("motor_angle", yt, wt), ("tip_deflection", yd, wd))):
                if name in g.outputs:
                    y[i] = pad(g.columns[name])
                    seg = g.columns[name][self.skip : n]
                    sst = float(np.sum((seg - seg.mean()) ** 2)) if seg.size else 0.0
                    if not sst > 0:
                        from flexarm.identification.time_domain.logs import FitInputError

                        raise FitInputError(
                            f"{g.where}: {name} does not vary over the {n - self.skip} samples "
                            f"after the first {self.skip} ({n} in the log or window, one every "
                            f"{g.dt:g} s), so it cannot be fitted",
                            file=g.where,
                            field=name,
                            fix="give a longer window (the first samples are left out for the "
                            "delay search), or check the time unit of the log format",
                        )
                    self.sst[i, j] = sst
                    w[i, self.skip : n] = 1.0 / sst
            if g.controller is not None:
                c = g.controller
                gains = getattr(g, "gains", None)  # per sample (N, 4) where logged
                if gains is not None:
                    K[i] = np.concatenate([gains[:n], np.repeat(gains[n - 1 : n], N - n, 0)])
                else:
                    K[i] = (c.k1, c.k2, c.k3, c.k4)
                tau[i] = c.rate_time_constant if c.rate == "filtered" else 0.0
        self.data = as_jax(dict(ref=ref, y_th=yt, y_d=yd, w_th=wt, w_d=wd, volt=volt, K=K, tau=tau))
        self.const = as_jax(
            dict(
                dt=T,
                length=rig.length,
                k_u=rig.k_u,
                k_omega=rig.k_omega,
                q_th=rig.encoder_quantum,
                q_d=rig.tip_quantum,
                limit=rig.limit,
                vel_tol=rig.vel_tol,
                push_s=rig.push_stiffening,
                push_T=rig.push_threshold if rig.push_stiffening > 0 else 0.0,
                push_T1=rig.push_full if rig.push_stiffening > 0 else 0.0,
                omega_th=2 * np.pi * self.filters["motor_angle"],
                omega_d=2 * np.pi * self.filters["tip_deflection"],
            )
        )
        self.hub0 = np.array(
            [[guesses.initial_hub(g, k=k) for k in range(space.max_delay + 1)] for g in logs]
        )  # (L, max_delay + 1, 2)
        fd = self.filters["tip_deflection"]
        self.tip0 = np.array(
            [
                [guesses.initial_tip_at(g, k, cutoff=fd) for k in range(space.max_delay + 1)]
                for g in logs
            ]
        )  # (L, max_delay + 1, 2)
        self.wc_guess = wc_guess
        self.tip_scale = np.array(
            [max(np.std(g.columns.get("tip_deflection", [0.0])), 1e-9) for g in logs]
        )
        # scale of the hub-angle offsets: one encoder count (or 1 mrad unquantised)
        self.hub_scale = rig.encoder_quantum or 1e-3

    # ------------------------------------------------------------------ mapping
    def tip_initial(self, dd: np.ndarray, offsets: np.ndarray | None = None):
        """Measured-unit tip deflection and rate at t = dd·T, (P, L) each."""
        idx = np.asarray(dd, int)
        d0 = self.tip0[:, idx, 0].T  # (P, L)
        v0 = self.tip0[:, idx, 1].T
        w = self.wc_guess
        if offsets is not None:
            d0 = d0 + offsets[..., 0] * self.tip_scale[None]
            v0 = v0 + offsets[..., 1] * self.tip_scale[None] * w
        return d0, v0

    def hub_initial(self, P: int, offsets: np.ndarray | None = None, dth: np.ndarray | None = None):
        """Hub angle and rate at t = 0, (P, L) each: the log's reading at k = the hub
        delay ``dth`` (P,) (0 when not given); offsets[..., 2:4] (when given) shift them
        in units of ``hub_scale`` (rad) and ``hub_scale`` · ω_guess (rad/s)."""
        idx = np.zeros(P, int) if dth is None else np.broadcast_to(np.asarray(dth, int), (P,))
        th0 = self.hub0[:, idx, 0].T
        om0 = self.hub0[:, idx, 1].T
        if offsets is not None and offsets.shape[-1] >= 4:
            th0 = th0 + offsets[..., 2] * self.hub_scale
            om0 = om0 + offsets[..., 3] * self.hub_scale * self.wc_guess
        return th0, om0

    def model(self, U: np.ndarray, D: np.ndarray, offsets: np.ndarray | None = None) -> dict:
        """Unit coordinates U (P, n_cont), discrete D (P, 3) = (angle delay, tip delay,
        sign 0/1), optional per-log initial-state offsets (P, L, 2) (tip deflection and
        rate) or (P, L, 4) (and hub angle and rate) → model numbers (L, P)."""
        sp = self.space
        P = U.shape[0]
        ses = self.sessions

        def per(name):  # (L, P)
            return sp.session_values(U, name)[:, ses].T

        def glob(name):
            return np.broadcast_to(sp.value(U, name)[None], (self.L, P))

        sign = 2.0 * D[:, 2] - 1.0
        if sp.rigid:  # no link: an uncoupled (J_l = 0) dummy mode, read by no log
            wc, zeta = np.full((self.L, P), 10.0), np.full((self.L, P), 0.1)
            gain, JlL = np.broadcast_to(sign[None], (self.L, P)), np.zeros((self.L, P))
        else:
            wc = glob("link_frequency")
            zeta = glob("link_damping")
            gain = glob("tip_gain") * sign[None]
            if sp.session_signs:  # a gauge whose sign changed between sessions
                gain = gain * np.asarray(sp.session_signs, float)[ses][:, None]
            JlL = glob("link_inertia") / self.rig.length
        d0, v0 = self.tip_initial(D[:, 1], offsets)
        th0, om0 = self.hub_initial(P, offsets, D[:, 0])
        if sp.friction:
            Fc = per("coulomb")
            Fs = Fc + per("static_excess")
            bias = per("bias")
            B = per("viscous")
        else:
            Fc = Fs = bias = np.zeros((self.L, P))
            B = per("viscous")
        return as_jax(
            dict(
                J=glob("hub_inertia"),
                B=B,
                wc2=wc**2,
                c2z=2 * zeta * wc,
                JlL=JlL,
                Fc=Fc,
                Fs=Fs,
                bias=bias,
                gain=gain,
                dth=np.broadcast_to(D[:, 0][None], (self.L, P)),
                dd=np.broadcast_to(D[:, 1][None], (self.L, P)),
                th0=th0.T,
                om0=om0.T,
                w0=d0.T / gain,
                wd0=v0.T / gain,
            )
        )

    @property
    def quantised(self) -> bool:
        """Whether the simulated converters round (an encoder or tip-sensor quantum > 0)."""
        return bool(self.rig.encoder_quantum > 0 or self.rig.tip_quantum > 0)

    def unquantised(self) -> Objective:
        """The same objective with the simulated converters' rounding off (a shallow copy
        sharing the data). With rounding the controller in the simulated loop reads whole
        counts, so the cost jumps wherever a count flips: along any one parameter it is
        jagged at scales of 1e-3 of its search range, and least squares stops there on its
        step tolerance. Without it the cost is smooth and its minimum lies within those
        jags of the rounded cost's (the local stage's continuation, :mod:`.fit`)."""
        out = copy.copy(self)
        out.const = {**self.const, "q_th": self.const["q_th"] * 0.0, "q_d": self.const["q_d"] * 0.0}
        return out

    def _kw(self):
        return dict(
            substeps=self.substeps,
            n_buf=self.space.max_delay + 1,
            comp_delay=self.comp_delay,
            open_loop=self.mode == "open_loop",
            filters=(self.filters["motor_angle"] > 0, self.filters["tip_deflection"] > 0),
            pushed=self.rig.push_stiffening > 0,
        )

    # ------------------------------------------------------------------ evaluation
    def sse(self, U: np.ndarray, D: np.ndarray, offsets: np.ndarray | None = None):
        """Normalised squared errors (P, L, 2) and divergence flags (P, L), in chunks of
        ``chunk`` parameter vectors shared over the CPU's cores (``chunk`` / cores each,
        the last one padded: one compile for all chunks), run at once on as many threads
        (:func:`flexarm.sim.batch.run_chunks`; each vector's result is the same to the last
        bit as in one call)."""
        P = U.shape[0]
        threads = cpu_cores()
        c = max(1, self.chunk // threads)
        Pp = -(-P // c) * c

        def pad(a):
            return np.concatenate([a, np.repeat(a[-1:], Pp - P, axis=0)])

        U, D = pad(U), pad(D)
        offsets = None if offsets is None else pad(offsets)
        models = [
            self.model(U[k : k + c], D[k : k + c], None if offsets is None else offsets[k : k + c])
            for k in range(0, Pp, c)
        ]
        kw = self._kw()

        def go(m):
            et, ed, bad = closed_loop_cost(m, self.data, self.const, **kw)
            return np.stack([np.asarray(et), np.asarray(ed)], -1), np.asarray(bad)

        outs = run_chunks(go, models, threads)
        out_e, out_b = [o[0] for o in outs], [o[1] for o in outs]
        e = np.concatenate(out_e, axis=1)[:, :P].transpose(1, 0, 2)
        b = np.concatenate(out_b, axis=1)[:, :P].T
        return e, b

    def cost(self, U, D, offsets=None) -> np.ndarray:
        """V(p) for each of P parameter vectors; diverged rollouts cost ``BIG`` per log;
        plus the priors' Σ r_p² (:meth:`prior_rows`)."""
        e, bad = self.sse(U, D, offsets)
        per_log = np.where(bad | ~np.isfinite(e.sum(-1)), BIG, e.sum(-1))
        return per_log.sum(-1) + np.sum(self.prior_rows(np.asarray(U)) ** 2, -1)

    def prior_rows(self, U: np.ndarray) -> np.ndarray:
        """(P, n_priors) the priors' residuals in V's units: r_p (eq. (2) of the general
        engine) · :meth:`prior_scale`."""
        if not self.space.priors:
            return np.zeros((U.shape[0], 0))
        return self.space.prior_residuals(U[:, : self.space.n_cont]) * self.prior_scale()

    def prior_scale(self) -> float:
        """s = λ √(τ / (N̄ T)), N̄ the mean number of weighted samples of a signal: V's
        residual W^½ (ŷ − y) is eq. (1)'s times s (W = 1 / (N σ²)), so a prior row r_p · s
        weighs against V as r_p against the general engine's cost
        (:data:`PRIOR_RESIDUAL_LEVEL`, :data:`PRIOR_CORRELATION_TIME`)."""
        n = np.count_nonzero(self.weights() > 0, axis=-1)  # (2, L)
        nbar = float(np.mean(n[n > 0])) if np.any(n > 0) else 1.0
        return PRIOR_RESIDUAL_LEVEL * float(np.sqrt(PRIOR_CORRELATION_TIME / (nbar * self.T)))

    def run(self, U, D, offsets=None):
        """Trajectories (P, L, N) of measured θ, measured d, u, true θ, true w; and the
        normalised errors (P, L, 2), divergence flags (P, L)."""
        m = self.model(U, D, offsets)
        out, acc = closed_loop_run(m, self.data, self.const, **self._kw())
        tr = [np.asarray(a).transpose(2, 1, 0) for a in out]
        e = np.stack([np.asarray(acc[0]), np.asarray(acc[1])], -1).transpose(1, 0, 2)
        return tr, e, np.asarray(acc[2]).T

    def weights(self) -> np.ndarray:
        """Per-sample weights (2, L, N) = 1/‖y − mean y‖² inside the window, else 0."""
        return np.stack([np.asarray(self.data["w_th"]), np.asarray(self.data["w_d"])])

    def fit_percent(self, e: np.ndarray) -> np.ndarray:
        """fit % (…, L, 2) from normalised squared errors; NaN where a signal is absent."""
        fp = 100.0 * (1.0 - np.sqrt(np.maximum(e, 0.0)))
        return np.where(self.sst > 0, fp, np.nan)
