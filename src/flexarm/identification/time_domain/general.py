"""One time-domain fit for every arm a scenario describes: :func:`fit_scenario`.

The scenario is the model template; ``free`` lists the parameters to estimate as paths into
it (``"arm.joints[0].friction.coulomb"``, ``"arm.links[1].torsional_stiffness"``,
``"sensors.deflection_1.gain"``; ``[*]`` expands to every element of a list). Every other
number stays at the template's value. The model is the one sampled-data loop
(:class:`flexarm.sim.sampled.SampledLoop`): plant, sensors (gains, filters, quantisation,
delays), the scenario's discrete controller, actuator limits.

Parameters and cost
-------------------
Parameters are positive (or sign-fixed) physical numbers, estimated in log space:
p_i = p0_i · exp(z_i), p0_i the template value, z_i ∈ [−ln f, ln f] (f =
``FitOptions.priors.bound_factor``; ``FitOptions.priors.bounds`` gives absolute bounds per
path). Signed parameters, which may be zero or change sign (a bias torque or force, an
offset: fields named in :data:`SIGNED_FIELDS`, a template value of 0, or paths listed in
``FitOptions.priors.linear``), are estimated in linear space, p_i = p0_i + s_i z_i, z_i ∈
[−f, f] or their ``bounds``, with the scale s_i = |p0_i|, else half the width of their
given bounds, else the Coulomb level beside a friction bias; a signed parameter starting
at 0 without any of these is refused, naming ``--bound``.
A candidate z becomes a scenario (``model_dump`` → set the paths → ``scenario_from_dict``),
then a loop (:func:`flexarm.sim.build.prepare`); a population of candidates is stacked leaf
by leaf into one batched loop and run by one ``vmap``-ed simulation.

The residuals stacked for least squares are, per measured channel c of ``options.cost.channels``
(weight w_c), segment s and sample k,

    r_c,s,k = √w_c · (ŷ_c,s,k − y_c,s,k) / (λ · σ_c) · √(T / τ)                       (1)

with σ_c the logged channel's spread (standard deviation over all fitted logs), λ =
``residual_level`` the expected misfit as a fraction of that spread and τ =
``correlation_time`` the residuals' correlation time (s), so that Σ r² counts independent
misfits in units of their expected size (fit % is :func:`flexarm.metrics.fit_percent`,
100 (1 − ‖y − ŷ‖/‖y − ȳ‖)); and per prior (path → relative std σ_p,
``options.priors.priors``; the mean is the template value, the data-sheet value)

    r_p = (ln p − ln p0) / σ_p                                                        (2)

(σ_p = 0.3 says "within ±30 % with 68 % probability"). Only the ratio of (1) to (2)
depends on λ and τ; the fitted values without priors do not.

Multiple shooting
-----------------
With ``options.shooting.segment`` = L seconds, each log (or its window) is cut into segments of L s,
each simulated from the logged state at its start, so that a stick-slip run, chaotic in the
parameters over 100 s (issue #17), yields a cost that is smooth enough for finite
differences. At a segment start k0 the loop's state is taken from the log:

* controller state and command buffer: the controller is run on the logged measured
  channels and references from the log's first sample to k0 (what the real controller did,
  up to its own quantisation: exact for a controller fed by logged channels);
* sensor delay buffers: the logged (delayed) values, shifted back by each channel's delay;
* analog sensor filters (first-order, ``sensors.X.bandwidth``): the filter's state is the
  logged value; the signal behind it is recovered by inverting the filter,
  g s = y + ẏ / ω_f;
* plant state x0: the least-squares (minimum-norm) solution of the linear conditions
  g_c ∂s_c/∂x · x0 = y_c(k0) (positions) and g_c ∂s_c/∂x · ∂f/∂x · x0 = ẏ_c(k0) (rates), the
  derivatives of the signals and right-hand side at x = 0 (:func:`jax.jacfwd` of the
  candidate's plant), ẏ a local quadratic (Savitzky–Golay) derivative of the log over
  ±``derivative_half_width`` samples (a straight line over as many samples at a log's
  end). What the channels do not observe (a second mode behind one tip sensor, friction
  states) starts at zero; ``burn_in`` seconds at the start of each segment can be left out
  of the cost while those transients decay;
* with ``estimate_states`` the start state of every segment is then refined as a nuisance
  parameter (offsets to the state read off the log: multiple shooting's node states), and
  so is each log's start state in the ``polish`` on whole logs.

With ``initial = "scenario"``, a segment starting at a log's first sample (no window)
starts from the scenario's own ``[initial]`` state instead (synthetic logs).

The whole-run prediction (:func:`predict_scenario`, validation) is one simulation per log.

Optimiser
---------
Optionally a global stage (SciPy ``differential_evolution``, whole generations as one
batch), then SciPy ``least_squares`` (trust-region reflective) with the finite-difference
Jacobian's columns simulated as one batch (step ``fd_step`` in z). Uncertainty: the
Newey–West (HAC) sandwich of :mod:`flexarm.identification.time_domain.uncertainty` per
segment, with the priors' information added: cov(z) = H⁻¹ (Ŝ + J_pᵀ J_p) H⁻¹,
H = J_dᵀ J_d + J_pᵀ J_p; std(p) = |p| std(z).
"""

from __future__ import annotations

import dataclasses
import math
import re
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from flexarm.identification.time_domain.options import (  # re-exported here
    COST_RESOLUTION,
    INITIAL_NFEV,
    INITIALS,
    Cost,
    FitOptions,
    ResolvedOptions,
    ScenarioFitOptions,
    as_fit_options,
)
from flexarm.identification.time_domain.result import FitResult, session_key, session_path
from flexarm.identification.time_domain.uncertainty import bandwidth, bartlett_meat
from flexarm.metrics import fit_percent as _fitpct
from flexarm.sim.batch import cpu_cores, run_chunks, stack_loops
from flexarm.sim.build import Prepared, prepare, reference_signal
from flexarm.sim.sampled import (
    _quantise,
    _scan,
    check_zeroing,
    initial_carry,
    logged_offset,
    with_depth,
    zeroing_start,
)

__all__ = [
    "ScenarioFitOptions",
    "ScenarioFit",
    "fit_scenario",
    "predict_scenario",
    "refit_friction",
    "expand_paths",
    "scenario_with",
]


# ----------------------------------------------------------------------------- paths
# the path language: flexarm.specs.paths
from flexarm.specs.paths import expand_paths, parse_path, scenario_with
from flexarm.specs.paths import get as _path_get


def _template_value(dump: dict, keys: list, path: str) -> float:
    v = _path_get(dump, path)
    if v is None and keys[-1] == "static" and "friction" in keys:
        v = _path_get(dump, keys[:-1]).get("coulomb", 0.0)  # breakaway defaults to coulomb
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ValueError(
            f"free parameter {path!r}: the scenario's value there is {v!r}, not "
            "a number; give it a number in the scenario (the template value)"
        )
    if not math.isfinite(v):
        raise ValueError(
            f"free parameter {path!r}: the template value is {v!r}; give a finite "
            "starting value in the scenario (e.g. the data-sheet value)"
        )
    return float(v)


#: scenario fields that may be zero or change sign (fitted in linear space)
SIGNED_FIELDS = frozenset({"bias", "offset"})


def _linear_scale(dump: dict, keys: list, path: str, p0: float, bounds, factor: float) -> float:
    """The scale s of a signed parameter, p = p0 + s z (module docstring)."""
    if p0 != 0.0:
        return abs(p0)
    if bounds is not None:
        a, b = (float(v) for v in bounds)
        return max(abs(b - a) / 2.0 / factor, 1e-300)
    if keys[-1] == "bias" and "friction" in keys:
        c = _path_get(dump, keys[:-1]).get("coulomb") or 0.0
        if c > 0:
            return float(c)
    raise ValueError(
        f"free parameter {path!r} starts at 0 and nothing gives its scale: give its "
        f"range, --bound {path}=LO:HI (FitOptions.priors.bounds "
        "{path: (lo, hi)}), or a non-zero starting value in the scenario"
    )


# ----------------------------------------------------------------------------- data
@dataclass
class _LogData:
    name: str
    t: np.ndarray  # (N,) from 0
    y: np.ndarray  # (N, C) in the loop's sensor order; NaN where a channel is absent
    refs: dict[str, np.ndarray]
    present: np.ndarray  # (C,) bool
    from_scenario: bool  # the (window) start is the log's first sample
    window: tuple[int, int]  # samples [k0, k1) fitted
    log: Any = None  # the whole log as a flexarm.io.logs.Log (time from 0)
    computed: tuple[str, ...] = ()  # channels computed from logged ones, not compared


def _with_command_channels(scenario, channels: list[str]):
    """``scenario`` with a sensor for every channel asked for that names the drive's
    command (``voltage``, ``current``, ``torque_1``, ... or ``..._applied``:
    :func:`flexarm.sim.sampled.command_signal`) and that it lacks, so that the command can
    be fitted and scored like any sensor channel (``--channel current``)."""
    from flexarm.sim.sampled import command_signal
    from flexarm.specs.scenario import scenario_from_dict

    missing = [c for c in channels if c not in scenario.sensors]
    if not missing:
        return scenario
    plant = prepare(scenario).loop.plant
    add = [c for c in missing if command_signal(plant, c) is not None]
    if not add:
        return scenario
    d = scenario.model_dump(mode="json", exclude_none=True)
    d.setdefault("sensors", {}).update({c: {} for c in add})
    return scenario_from_dict(d, source=f"scenario {scenario.name!r} with {', '.join(add)}")


def _log_arrays(log) -> tuple[str, np.ndarray, dict[str, np.ndarray]]:
    if hasattr(log, "signals") and hasattr(log, "time"):
        return getattr(log, "name", "<log>"), np.asarray(log.time, float), dict(log.signals)
    if isinstance(log, Mapping):
        d = dict(log)
        t = np.asarray(d.pop("time"), float)
        return str(d.pop("name", "<log>")), t, d
    raise TypeError(
        f"logs: got {type(log).__name__}; give flexarm.io.logs.Log objects (read_log) "
        "or dicts with 'time' and channel arrays"
    )


# ----------------------------------------------------------------------------- result
#: Deprecated name of :class:`~flexarm.identification.time_domain.result.FitResult`.
ScenarioFit = FitResult


# ----------------------------------------------------------------------------- engine
def _savgol_derivative(y: np.ndarray, k: int, h: int, dt: float) -> np.ndarray:
    """ẏ at sample k by a least-squares quadratic over samples k−h … k+h; where the log
    ends within h samples of k, a straight line over the 2h + 1 samples at that end (an
    end-point quadratic amplifies the noise several times)."""
    n = y.shape[0]
    lo, hi = max(0, k - h), min(n, k + h + 1)
    deg = 2
    if lo == 0 or hi == n:  # one-sided: a line over 2h + 1 samples
        lo, hi = (0, min(n, 2 * h + 1)) if lo == 0 else (max(0, n - 2 * h - 1), n)
        deg = 1
    tt = (np.arange(lo, hi) - k) * dt
    if hi - lo < 3:
        return np.zeros(y.shape[1:])
    V = np.stack([tt**j for j in range(deg + 1)], 1)
    coef, *_ = np.linalg.lstsq(V, np.nan_to_num(y[lo:hi]), rcond=None)
    return coef[1]


class _Engine:
    """Logs cut into segments, the batched run of candidate parameter vectors, residuals."""

    def __init__(
        self,
        scenario,
        logs: Sequence,
        free: Sequence[str],
        options: ResolvedOptions,
        segment: float | Literal["options"] | None = "options",
    ):
        options.check()  # resolved options (FitOptions.resolved): every engine group given
        substeps = options.cost.substeps
        if substeps is not None and scenario.simulation is not None:
            scenario = scenario.model_copy(
                update={
                    "simulation": scenario.simulation.model_copy(update={"substeps": int(substeps)})
                }
            )
        self.template = scenario
        self.options = options
        self.dump = scenario.model_dump()
        self.free = expand_paths(self.dump, list(free))
        if len(set(self.free)) != len(self.free):
            raise ValueError(f"free parameters listed twice: {self.free}")
        self.keys = [parse_path(p) for p in self.free]
        self.p0 = np.array(
            [_template_value(self.dump, k, p) for k, p in zip(self.keys, self.free, strict=True)]
        )
        # priors and bounds may name paths with [*] too: one entry per element
        pri = options.priors
        if any("[*]" in p for p in list(pri.priors) + list(pri.bounds)):
            pri = dataclasses.replace(
                pri,
                priors={q: v for p, v in pri.priors.items() for q in expand_paths(self.dump, [p])},
                bounds={q: v for p, v in pri.bounds.items() for q in expand_paths(self.dump, [p])},
            )
            options = dataclasses.replace(options, priors=pri)
            self.options = options
        for p in list(pri.priors) + list(pri.bounds):
            if p not in self.free:
                raise ValueError(
                    f"FitOptions.priors: {p!r} has a prior or bounds but is not free; "
                    f"free: {', '.join(self.free)}"
                )
        lin = set(pri.linear) | set(expand_paths(self.dump, list(pri.linear)))
        self.linear = np.array(
            [
                p in lin or self.p0[i] == 0.0 or k[-1] in SIGNED_FIELDS
                for i, (p, k) in enumerate(zip(self.free, self.keys, strict=True))
            ],
            bool,
        )
        self.pscale = np.ones(len(self.free))
        self.lo = np.zeros(len(self.free))
        self.hi = np.zeros(len(self.free))
        for i, p in enumerate(self.free):
            self.pscale[i], self.lo[i], self.hi[i] = self._coordinate(
                p, self.keys[i], self.p0[i], bool(self.linear[i]), pri
            )
        self.sigma = np.array([pri.priors.get(p, np.inf) for p in self.free])
        self._sessions(scenario, logs, options)
        self.tied = {}
        for p, master in pri.ties.items():
            if master not in self.free:
                raise ValueError(
                    f"FitOptions.priors.ties: {p!r} follows {master!r}, which is not "
                    f"free; free: {', '.join(self.free)}"
                )
            if self.linear[self.free.index(master)]:
                raise ValueError(
                    f"FitOptions.priors.ties: {p!r} follows {master!r}, a signed parameter "
                    "fitted in linear space; ties follow log-space (positive) parameters"
                )
            self.tied[p] = (self.free.index(master), _template_value(self.dump, parse_path(p), p))
        scenario = _with_command_channels(scenario, list(options.cost.channels or {}))
        self.template = scenario
        self.prep0 = prepare(scenario)
        loop = self.prep0.loop
        self.dt = float(loop.dt)
        self.names = loop.sensors.names
        self.delays = np.asarray(loop.sensors.delays, int)
        # the reading buffer's depth: with a delay search, its largest delay, so that every
        # delay configuration runs one compiled program (sim.sampled.with_depth)
        ds = options.delay_search
        self.depth = max(int(self.delays.max(initial=0)), int(ds.max_delay) if ds else 0)
        self.delay = int(loop.delay)
        # ---- logs
        wins = options.windows or [None] * len(logs)
        if len(wins) != len(logs):
            raise ValueError(f"FitOptions.windows has {len(wins)} entries for {len(logs)} logs")
        self.notes: list[str] = []  # channels computed from logged ones (_read)
        from flexarm.io.logs import log_keys

        keys = log_keys(logs)  # unique per log: same file names in other folders stay apart
        self.logs = [
            self._read(log, w, k if getattr(log, "path", None) is not None else None)
            for log, w, k in zip(logs, wins, keys, strict=True)
        ]
        from flexarm.sim.build import _measured_names

        read = _measured_names(loop.controller)
        for L in self.logs:
            if not L.present.any():
                raise ValueError(
                    f"{L.name}: none of scenario {self.template.name!r}'s sensor channels "
                    f"({', '.join(self.names)}) is a column of this log; name its columns so "
                    "(--column NAME=COLUMN, or a log format's [columns]) or give this rig's "
                    "scenario"
                )
        # by default every channel a log measures: present, not computed from others, and
        # not constant (a rigid arm's zero tip column measures nothing)
        chans = options.cost.channels or {
            n: 1.0
            for n in self.names
            if any(
                L.present[self.names.index(n)]
                and n not in L.computed
                and np.ptp(L.y[:, self.names.index(n)]) > 0
                for L in self.logs
            )
        }
        for c in chans:
            if c not in self.names:
                raise ValueError(
                    f"FitOptions.cost.channels: {c!r} is not a sensor channel of scenario "
                    f"{scenario.name!r}; channels: {', '.join(self.names)}"
                )
            if not any(L.present[self.names.index(c)] for L in self.logs):
                raise ValueError(
                    f"FitOptions.cost.channels: no log holds channel {c!r}; the logs hold "
                    f"{sorted({k for L in self.logs for k in _cols(L, self.names)})}"
                )
        self.channels = dict(chans)
        self.cidx = [self.names.index(c) for c in self.channels]
        allv = {
            c: np.concatenate(
                [L.y[:, self.names.index(c)] for L in self.logs if L.present[self.names.index(c)]]
            )
            for c in self.channels
        }
        self.spread = np.array([max(float(np.nanstd(allv[c])), 1e-300) for c in self.channels])
        self.scale = (
            np.sqrt(np.array(list(self.channels.values()), float))
            / (options.cost.residual_level * self.spread)
            * math.sqrt(self.dt / options.cost.correlation_time)
        )
        #: measurement noise (SI) in the loop per segment (S, M, C) (a prediction's
        #: ``noise``: the controller reads it); None: noise-free
        self.seg_noise: np.ndarray | None = None
        self.ctrl_inits = None  # per-log controller start states (continuous)
        self.starts = None
        if options.continuous:
            self._continuous()
        seg = options.shooting.segment if segment == "options" else segment
        self._segments(seg)
        # a segment after a log's first sample starts its controller from the controller
        # run over the logged channels before it: those channels must be logged (a log
        # simulated from its first sample needs none: the controller starts there)
        late = {li for li, k0, _ in self.seg if k0 > 0}
        for li, L in enumerate(self.logs):
            missing = sorted(
                n for n in read if n in self.names and not L.present[self.names.index(n)]
            )
            if missing and li in late:
                raise ValueError(
                    f"{L.name}: no column {', '.join(map(repr, missing))}, which "
                    f"the controller of scenario {self.template.name!r} reads; the "
                    "fit runs the controller on the logged channels from the log's "
                    "start: log them (or map them with a log format)"
                )

    def _coordinate(self, p: str, key: list, p0: float, linear: bool, pri) -> tuple:
        """(scale, lower, upper) of parameter ``p``'s coordinate z: p = p0 + s·z if
        ``linear`` (signed), else p = p0·exp(z); its bounds from ``pri.bounds`` (absolute
        values) or ±``pri.bound_factor`` (x bound_factor in log space)."""
        if linear:
            scale = _linear_scale(self.dump, key, p, p0, pri.bounds.get(p), pri.bound_factor)
            lo, hi = -pri.bound_factor, pri.bound_factor
            if p in pri.bounds:
                a, b = sorted(float(v) for v in pri.bounds[p])
                if not a <= p0 <= b:
                    raise ValueError(
                        f"FitOptions.priors.bounds[{p!r}] = ({a:g}, {b:g}) does not "
                        f"contain the template value {p0:g}; move one of them"
                    )
                lo, hi = (a - p0) / scale, (b - p0) / scale
            return scale, lo, hi
        lo, hi = -math.log(pri.bound_factor), math.log(pri.bound_factor)
        if p in pri.bounds:
            a, b = (float(v) for v in pri.bounds[p])
            if not (a / p0 > 0 and b / p0 > 0):
                raise ValueError(
                    f"FitOptions.priors.bounds[{p!r}] = ({a:g}, {b:g}): both bounds "
                    f"must have the sign of the template value {p0:g}"
                )
            za, zb = sorted((math.log(a / p0), math.log(b / p0)))
            if not za <= 0 <= zb:
                raise ValueError(
                    f"FitOptions.priors.bounds[{p!r}] = ({a:g}, {b:g}) does not contain "
                    f"the template value {p0:g}; move one of them"
                )
            lo, hi = za, zb
        return 1.0, lo, hi

    def _sessions(self, scenario, logs: Sequence, options) -> None:
        """Several sessions (``options.sessions``, :class:`Sessions`): each per-session
        path gets one more coordinate per later session s, named ``sessions[s].PATH``
        (:func:`~.result.session_key`), with the path's scale, bounds and prior, started
        at session 0's start or ``Sessions.starts[s][PATH]``. ``session_of[i]``: the session
        of coordinate i (0: shared or session 0's), ``base_of[i]``: its path's coordinate."""
        self.session_of = [0] * len(self.free)
        self.base_of = list(range(len(self.free)))
        self.n_sessions = 1
        self.log_session = np.zeros(len(logs), int)
        self.per_session: list[str] = []
        ses = options.sessions
        if ses is None:
            return
        ses.check(len(logs))
        if ses.per_session is not None:
            per = expand_paths(self.dump, list(ses.per_session))
        else:
            fr = _friction_set(scenario)  # none: only the signed paths
            per = [p for p, k in zip(self.free, self.keys, strict=True) if p in fr]
            per += [p for p, k in zip(self.free, self.keys, strict=True) if k[-1] in SIGNED_FIELDS]
            # a free path a later session starts elsewhere is per session too
            given = {p for st in (ses.starts or {}).values() for p in st}
            per += [p for p in self.free if p in given and p not in per]
        bad = [p for p in per if p not in self.free]
        if bad:
            raise ValueError(
                f"FitOptions.sessions.per_session: {', '.join(map(repr, bad))} not free; "
                f"free: {', '.join(self.free)}"
            )
        K = ses.count
        if K > 1 and not per:
            raise ValueError(
                "FitOptions.sessions: several sessions but no free parameter per session "
                "(the free joint friction levels, bias and offset paths by default); list "
                "them in FitOptions.sessions.per_session"
            )
        pri = self.options.priors
        for s_ in range(1, K):
            starts = dict((ses.starts or {}).get(s_, {}))
            unknown = [p for p in starts if p not in per]
            if unknown:
                raise ValueError(
                    f"FitOptions.sessions.starts[{s_}]: {', '.join(map(repr, unknown))} not "
                    f"per session; per session: {', '.join(per)}"
                )
            for p in per:
                i = self.free.index(p)
                p0 = float(starts.get(p, self.p0[i]))
                if not self.linear[i] and p0 == 0.0:
                    raise ValueError(
                        f"FitOptions.sessions.starts[{s_}][{p!r}] = 0: a parameter fitted in "
                        "log space cannot start at 0; give a non-zero start"
                    )
                sc, lo, hi = self._coordinate(p, self.keys[i], p0, bool(self.linear[i]), pri)
                self.free.append(session_key(s_, p))
                self.keys.append(self.keys[i])
                self.p0 = np.append(self.p0, p0)
                self.linear = np.append(self.linear, self.linear[i])
                self.pscale = np.append(self.pscale, sc)
                self.lo, self.hi = np.append(self.lo, lo), np.append(self.hi, hi)
                self.sigma = np.append(self.sigma, self.sigma[i])
                self.session_of.append(s_)
                self.base_of.append(i)
        self.n_sessions = K
        self.per_session = per
        self.log_session = np.asarray(list(ses.of_log), int)

    def coordinate_of(self, i: int, session: int) -> int:
        """The coordinate that holds base coordinate ``i``'s value in ``session``."""
        if session:
            for j, (s_, b) in enumerate(zip(self.session_of, self.base_of, strict=True)):
                if s_ == session and b == i:
                    return j
        return i

    def _continuous(self) -> None:
        """The logs as consecutive pieces of one run: each log's controller start state
        (stacked over logs, for :func:`_warm`) and digital-filter states, from
        :func:`flexarm.sim.filters.continuous_starts` run with the template's controller
        (a controller whose gains depend on the free parameters keeps the template's
        states)."""
        from flexarm.sim.filters import continuous_starts, start_piece

        loop = self.prep0.loop
        self.starts = continuous_starts(
            loop, self.template.sensors, [L.log for L in self.logs], self.dt
        )
        inits = [start_piece(loop, st).controller.init() for st in self.starts]
        self.ctrl_inits = jax.tree.map(lambda *a: jnp.stack([jnp.asarray(x) for x in a]), *inits)

    def _context(self, li: int):
        """The samples around log ``li``'s segment starts: (y (N, C), the log as a
        :class:`~flexarm.io.logs.Log`, the log's first sample's index in them). With
        ``continuous`` the logs joined in order, so that a log's start values, rates
        (±``derivative_half_width`` samples) and filter states read the pieces before it;
        else the log alone."""
        L = self.logs[li]
        if self.starts is None:
            return L.y, L.log, 0
        if getattr(self, "_joined", None) is None:
            from flexarm.io.logs import Log

            common = [
                k for k in self.logs[0].log.signals if all(k in M.log.signals for M in self.logs)
            ]
            n = sum(M.t.size for M in self.logs)
            whole = Log(
                None,
                np.arange(n) * self.dt,
                {
                    k: np.concatenate([np.asarray(M.log[k], float) for M in self.logs])
                    for k in common
                },
            )
            offs = np.concatenate([[0], np.cumsum([M.t.size for M in self.logs])])
            self._joined = (np.concatenate([M.y for M in self.logs]), whole, offs)
        Y, whole, offs = self._joined
        return Y, whole, int(offs[li])

    def assumed_starts(self) -> list[str]:
        """One warning per log and dynamic controller block that starts the log from its
        assumed ``initial_state`` (none with ``continuous``)
        (:func:`flexarm.sim.filters.warn_assumed_start`, which also issues them as
        :class:`~flexarm.sim.filters.ControllerStateWarning`)."""
        if self.options.continuous:
            return []
        from flexarm.sim.filters import warn_assumed_start

        return [m for L in self.logs for m in warn_assumed_start(self.prep0.loop, L.name)]

    # ------------------------------------------------------------------ logs, segments
    def _read(self, log, window, key: str | None = None) -> _LogData:
        from flexarm.io.logs import Log as _Log
        from flexarm.io.logs import on_sample_grid
        from flexarm.sim.build import disturbance_inputs

        if isinstance(log, _Log):
            # the one clock check: within period_tolerance the log is read on the
            # scenario's grid (a note says by how much its clock was off)
            log, note = on_sample_grid(
                log,
                self.dt,
                self.options.period_tolerance,
                what=f"scenario {self.template.name!r}'s [sampling] period",
            )
            if note:
                self.notes.append(note)
            # the scenario's [[disturbances]] from the log's columns (one line when missing)
            disturbance_inputs(self.template, log)
        name, t, sig = _log_arrays(log)
        name = key or name
        if t.size < 3:
            raise ValueError(f"{name}: {t.size} samples; a log needs at least 3")
        dt = float(np.median(np.diff(t)))
        tol = max(1e-6, float(self.options.period_tolerance))
        if abs(dt - self.dt) > tol * self.dt and not isinstance(log, _Log):
            raise ValueError(
                f"{name}: sampled every {dt:g} s, but scenario "
                f"{self.template.name!r} samples every {self.dt:g} s "
                "([sampling] period); resample the log or change the scenario"
            )
        check_zeroing(self.prep0.loop.sensors, t.size, self.dt, name)
        from flexarm.sim.filters import computed_channels

        extra, notes = computed_channels(self.template.sensors, sig, self.dt, name=name)
        sig = {**sig, **extra}
        self.notes += notes
        t = t - t[0]
        k0, k1 = 0, t.size
        if window is not None:
            a, b = window
            # the one window rule (flexarm.io.logs.Log.window): [a, b) s from the first sample
            k0 = max(0, int(math.ceil(a / dt - 1e-6)))
            k1 = min(t.size, int(math.ceil(b / dt - 1e-6)))
            if not 0 <= k0 < k1 - 2:
                raise ValueError(
                    f"{name}: window ({a:g}, {b:g}) s is outside the log (0 … {t[-1]:g} s)"
                )
        N = t.size
        y = np.full((N, len(self.names)), np.nan)
        present = np.zeros(len(self.names), bool)
        for j, n in enumerate(self.names):
            if n in sig:
                y[:, j] = np.asarray(sig[n], float)
                present[j] = True
        refs = {}
        for k, _v in self.prep0.references.items():
            if k in sig:
                refs[k] = np.asarray(sig[k], float)
            else:
                spec = (
                    self.template.reference if k == "reference" else self.template.references.get(k)
                )
                refs[k] = reference_signal(spec, t) if spec is not None else np.zeros(N)
        label = name if window is None else f"{name}[{window[0]:g}:{window[1]:g} s]"
        from flexarm.io.logs import Log

        whole = Log(None, t, {k: np.asarray(v, float) for k, v in sig.items()})
        return _LogData(
            label,
            t,
            y,
            refs,
            present,
            k0 == 0 and self.options.shooting.initial == "scenario",
            (k0, k1),
            whole,
            tuple(extra),
        )

    def _segments(self, seg: float | None) -> None:
        """Segment table: (log, k0, length) and the padded per-segment arrays."""
        rows = []
        for li, L in enumerate(self.logs):
            a, b = L.window
            n = b - a
            step = n if seg is None else max(3, int(round(seg / self.dt)))
            for k0 in range(a, b, step):
                ln = min(step, b - k0)
                if ln >= 3:
                    rows.append((li, k0, ln))
        self.seg = rows
        S = len(rows)
        M = max(r[2] for r in rows)
        self.M = M
        C = len(self.names)
        burn = int(round(self.options.shooting.burn_in / self.dt))
        y = np.zeros((S, M, C))
        mask = np.zeros((S, M, C), bool)
        refs = {k: np.zeros((S, M)) for k in self.prep0.references}
        for s, (li, k0, ln) in enumerate(rows):
            L = self.logs[li]
            idx = np.minimum(np.arange(k0, k0 + M), L.t.size - 1)
            yy = L.y[idx]
            y[s] = np.nan_to_num(yy)
            valid = np.arange(M) < ln
            if not (k0 == 0 and L.from_scenario):
                valid &= np.arange(M) >= burn
            mask[s] = valid[:, None] & L.present[None, :] & np.isfinite(yy)
            for k in refs:
                refs[k][s] = L.refs[k][idx]
        self.seg_y = y
        self.seg_mask = mask
        self.seg_refs = refs
        self._init_data()

    def _init_data(self) -> None:
        """Per segment: the delay-corrected logged values y(k0) and ẏ(k0), the sensor delay
        buffers, and the whole logs (padded) for the controller warm-up."""
        S, C = len(self.seg), len(self.names)
        dmax = self.depth
        h = self.options.shooting.derivative_half_width
        y0 = np.zeros((S, C))
        dy0 = np.zeros((S, C))
        sbuf = np.zeros((S, dmax + 1, C))
        for s, (li, k, _) in enumerate(self.seg):
            Y, _, off = self._context(li)
            N, k0 = Y.shape[0], k + off
            for c in range(C):
                d = int(self.delays[c])
                col = np.nan_to_num(Y[:, c])
                y0[s, c] = col[min(N - 1, k0 + d)]
                dy0[s, c] = _savgol_derivative(col[:, None], min(N - 1, k0 + d), h, self.dt)[0]
                for j in range(dmax + 1):
                    sbuf[s, j, c] = col[min(N - 1, max(0, k0 - 1 - j + d))]
        self.seg_xd = np.zeros((S, 0, 0))
        if self.prep0.loop.sensors.digital:
            self._digital_init(y0, dy0)  # (continuous: read on the joined logs, _context)
        self.y0, self.dy0, self.sbuf0 = y0, dy0, sbuf
        self.seg_log = np.array([r[0] for r in self.seg])
        self.seg_k0 = np.array([r[1] for r in self.seg])
        self.seg_scn = np.array([r[1] == 0 and self.logs[r[0]].from_scenario for r in self.seg])
        # eq. (1)'s 1 / (λ σ_c) per segment: pooled, or each log's own spread (Cost.spread)
        self.seg_scale = np.tile(self.scale, (S, 1))
        if self.options.cost.spread == "log":
            for li, L in enumerate(self.logs):
                for j, c in enumerate(self.channels):
                    col = self.names.index(c)
                    if L.present[col]:
                        sd = max(float(np.nanstd(L.y[:, col])), 1e-300)
                        self.seg_scale[self.seg_log == li, j] *= self.spread[j] / sd
        self._cache: dict = {}
        Nmax = max(1, int(self.seg_k0.max()) + 1)

        def fit_n(a):
            return (
                a[:Nmax]
                if a.shape[0] >= Nmax
                else np.pad(a, [(0, Nmax - a.shape[0])] + [(0, 0)] * (a.ndim - 1), mode="edge")
            )

        self.log_y = np.stack([fit_n(np.nan_to_num(L.y)) for L in self.logs])
        self.log_refs = {
            k: np.stack([fit_n(L.refs[k]) for L in self.logs]) for k in self.prep0.references
        }

    def _digital_init(self, y0: np.ndarray, dy0: np.ndarray) -> None:
        """Digitally filtered channels (``sensors.X.filter``): their states at each segment
        start from the log (:func:`flexarm.sim.filters.filter_state_from_log`: the logged
        output, its logged rate sibling or the filter run over the unfiltered reading), and
        the reading u behind the filter recovered by inverting it, B u_k = ξ_{k+1} − A ξ_k,
        over ±``derivative_half_width`` samples, for the plant-state rows (y0, ẏ0)."""
        from flexarm.sim.filters import filter_state_from_log

        sens = self.prep0.loop.sensors
        A, B = np.asarray(sens.fA), np.asarray(sens.fB)
        kmax = A.shape[-1]
        h = self.options.shooting.derivative_half_width
        S = len(self.seg)
        xd = np.full((S, len(sens.digital), kmax), np.nan)
        for s_, (li, kl, _) in enumerate(self.seg):
            L = self.logs[li]
            _, whole, off = self._context(li)
            N, k0 = len(whole), kl + off
            ks = list(range(max(0, k0 - h), min(N - 1, k0 + h + 1) + 1))
            st = {k: filter_state_from_log(self.template.sensors, whole, k, self.dt) for k in ks}
            for j, c in enumerate(sens.digital):
                name = self.names[c]
                if name not in st[k0]:
                    raise ValueError(
                        f"{L.name}: no column {name!r}: the state of its digital "
                        "filter at a segment start cannot be read off the log; "
                        "log it, or fit whole logs from rest (segment=None)"
                    )
                xd[s_, j, : len(st[k0][name])] = st[k0][name]
                us = []
                for k in ks[:-1]:
                    a, b = np.zeros(kmax), np.zeros(kmax)
                    a[: len(st[k][name])] = st[k][name]
                    b[: len(st[k + 1][name])] = st[k + 1][name]
                    rhs = b - A[j] @ a
                    us.append(float(B[j] @ rhs / max(B[j] @ B[j], 1e-300)))
                us = np.asarray(us)
                i0 = ks.index(k0) if k0 in ks[:-1] else len(us) - 1
                y0[s_, c] = us[i0]
                dy0[s_, c] = _savgol_derivative(us[:, None], i0, h, self.dt)[0]
        self.seg_xd = xd

    # ------------------------------------------------------------------ candidates
    def values(self, z: np.ndarray) -> dict[str, float]:
        """Every free value at ``z`` by its result key (a later session's own values as
        ``sessions[s].PATH``) and the tied paths."""
        out = {p: self.value_of(i, z[i]) for i, p in enumerate(self.free)}
        for s_ in range(self.n_sessions):
            for p, (i, v0) in self.tied.items():
                j = self.coordinate_of(i, s_)
                if s_ == 0 or j != i:
                    out[session_key(s_, p)] = float(v0 * np.exp(z[j]))
        return out

    def session_values(self, z: np.ndarray, session: int = 0) -> dict[str, float]:
        """Scenario path → value at ``z`` in ``session``: the shared values, the session's
        own per-session values, the tied paths following their master's session value."""
        out = {
            self.free[i]: self.value_of(i, z[i])
            for i in range(len(self.free))
            if self.session_of[i] == 0
        }
        if session:
            for i, (s_, b) in enumerate(zip(self.session_of, self.base_of, strict=True)):
                if s_ == session:
                    out[self.free[b]] = self.value_of(i, z[i])
        for p, (i, v0) in self.tied.items():
            out[p] = float(v0 * np.exp(z[self.coordinate_of(i, session)]))
        return out

    def value_of(self, i: int, zi: float) -> float:
        """Parameter ``i`` at coordinate ``zi``: p0·exp(z), or p0 + s·z if signed."""
        if self.linear[i]:
            return float(self.p0[i] + self.pscale[i] * zi)
        return float(self.p0[i] * np.exp(zi))

    def std_of(self, i: int, value: float, std_z: float) -> float:
        """Parameter ``i``'s std from its coordinate's: |p|·σ_z, or s·σ_z if signed."""
        return float((self.pscale[i] if self.linear[i] else abs(value)) * std_z)

    def prepared(self, z: np.ndarray, session: int = 0) -> Prepared:
        return prepare(scenario_with(self.template, self.session_values(z, session)))

    def loops(self, Z: np.ndarray):
        """The candidates' loops stacked (P, ...) and start states (P, n_x); with several
        sessions one loop per candidate and session, (P, K, ...) and (P, K, n_x)."""
        K = self.n_sessions
        preps = [self.prepared(z, s_) for z in Z for s_ in range(K)]
        loop = with_depth(stack_loops([p.loop for p in preps]), self.depth)
        if not self.options.cost.quantise:
            loop = eqx.tree_at(
                lambda lp: (lp.sensors.quantum, lp.actuator.quantum),
                loop,
                replace=(
                    jnp.zeros_like(loop.sensors.quantum),
                    jnp.zeros_like(loop.actuator.quantum),
                ),
            )
        if self.seg_noise is not None:  # the given noise in SI: the sensors' scale is 1
            loop = eqx.tree_at(
                lambda lp: lp.sensors.noise, loop, replace=jnp.ones_like(loop.sensors.noise)
            )
        x0 = np.stack([p.x0 for p in preps])
        if K > 1:
            P = Z.shape[0]
            loop = jax.tree.map(
                lambda a: a.reshape((P, K) + a.shape[1:]) if eqx.is_array(a) else a, loop
            )
            x0 = x0.reshape((P, K) + x0.shape[1:])
        return loop, x0

    def run(self, Z: np.ndarray, offsets: np.ndarray | None = None) -> np.ndarray:
        """Simulated measured channels (P, S, M, C) of the candidates ``Z`` (P, n), with the
        segments' plant states offset by ``offsets`` (P, S, n_x) (× :attr:`state_scale`)."""
        nx = self.prep0.loop.plant.n_states
        if offsets is None or not np.any(offsets):  # no offsets: the scale is not needed
            scaled = np.zeros((Z.shape[0], len(self.seg), nx))
        else:
            scaled = offsets * self.state_scale
        return self._simulate(Z, scaled)[0]

    def threads(self) -> int:
        """Threads a batch of candidates is shared over (``FitOptions.local.threads``;
        None: the CPU cores this process may use)."""
        if self.options.local.threads is not None:
            return max(1, int(self.options.local.threads))
        return cpu_cores()

    def _simulate(self, Z: np.ndarray, scaled: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(measured channels (P, S, M, C), the segments' log-derived plant start states
        before the offsets (P, S, n_x)) of the candidates ``Z`` with the start states
        offset by ``scaled`` (SI). The batch is cut into equal chunks (at most
        ``max_batch``, the last one padded, so that every chunk runs one compiled program),
        run at once on :meth:`threads` threads (:func:`flexarm.sim.batch.run_chunks`)."""
        P = Z.shape[0]
        workers = self.threads()
        chunk = max(1, min(self.options.local.max_batch, -(-P // workers)))
        common = (
            {k: jnp.asarray(v) for k, v in self.seg_refs.items()},
            jnp.asarray(self.y0),
            jnp.asarray(self.dy0),
            jnp.asarray(self.sbuf0),
            jnp.asarray(self.seg_xd),
            jnp.asarray(self.seg_scn),
            jnp.asarray(self.seg_k0, jnp.int32),
            jnp.asarray(self.log_session[self.seg_log], jnp.int32) if self.n_sessions > 1 else None,
            None if self.seg_noise is None else jnp.asarray(self.seg_noise),
        )
        jobs = []
        for a in range(0, P, chunk):
            Zc, Oc = Z[a : a + chunk], scaled[a : a + chunk]
            k = Zc.shape[0]
            if k < chunk:  # pad with copies of the last candidate: one shape for all chunks
                Zc = np.concatenate([Zc, np.repeat(Zc[-1:], chunk - k, axis=0)])
                Oc = np.concatenate([Oc, np.repeat(Oc[-1:], chunk - k, axis=0)])
            loop, x0s = self.loops(Zc)
            warm, shared = self._warm(loop)  # here, not in the threads: it fills a cache
            jobs.append((k, loop, jnp.asarray(x0s), jnp.asarray(Oc), warm, shared))

        def go(job):
            k, loop, x0s, Oc, warm, shared = job
            meas, starts = _run_segments(loop, x0s, Oc, warm, shared, *common)
            return np.asarray(meas)[:k], np.asarray(starts)[:k]

        outs = run_chunks(go, jobs, workers)
        return np.concatenate([o[0] for o in outs]), np.concatenate([o[1] for o in outs])

    def _warm(self, loop):
        """Controller states and command buffers at the segment starts (:func:`_warm`):
        computed once when every candidate has the same controller (its gains do not
        depend on the free parameters), else per candidate."""
        nd = self.delay + 1
        args = (
            jnp.asarray(self.log_y),
            {k: jnp.asarray(v) for k, v in self.log_refs.items()},
            jnp.asarray(self.seg_log),
            jnp.asarray(self.seg_k0),
            self.ctrl_inits,
        )
        leaves = [np.asarray(x) for x in jax.tree.leaves(eqx.filter(loop.controller, eqx.is_array))]
        K = self.n_sessions
        if K > 1:  # (P, K, ...): one controller per candidate and session
            leaves = [x.reshape((-1,) + x.shape[2:]) for x in leaves]
        same = all(np.array_equal(x, np.broadcast_to(x[:1], x.shape)) for x in leaves)
        if same:
            first = (lambda x: x[0, 0]) if K > 1 else (lambda x: x[0])
            ctrl0 = jax.tree.map(lambda x: first(x) if eqx.is_array(x) else x, loop.controller)
            key = "warm"
            if key not in self._cache or not all(
                np.array_equal(a, b) for a, b in zip(self._cache[key][0], leaves, strict=False)
            ):
                self._cache[key] = (
                    [x.copy() for x in leaves],
                    _warm_jit(ctrl0, self.names, nd, *args),
                )
            return self._cache[key][1], True
        if K > 1:  # per candidate and session, then each segment's session's
            w = eqx.filter_vmap(eqx.filter_vmap(lambda c: _warm(c, self.names, nd, *args)))(
                loop.controller
            )
            sel = jnp.asarray(self.log_session[self.seg_log])
            idx = jnp.arange(len(self.seg))
            return jax.tree.map(lambda a: a[:, sel, idx], w), False
        return eqx.filter_vmap(lambda c: _warm(c, self.names, nd, *args))(loop.controller), False

    @property
    def state_scale(self) -> np.ndarray:
        """Unit of the segment-state offsets per plant state: the RMS over segments of the
        template's log-derived start states (states the logs do not observe: the median
        of the others), so that offsets are O(1)."""
        if getattr(self, "_state_scale", None) is None:
            # the template's own start states (z = 0), from the fit's compiled program
            S, nx = len(self.seg), self.prep0.loop.plant.n_states
            x0 = self._simulate(np.zeros((1, len(self.free))), np.zeros((1, S, nx)))[1][0]
            rms = np.sqrt(np.mean(x0**2, axis=0))
            pos = rms[rms > 0]
            fill = float(np.median(pos)) if pos.size else 1.0
            self._state_scale = np.where(rms > 0, rms, fill)
        return self._state_scale

    def residuals(self, Z: np.ndarray, offsets: np.ndarray | None = None) -> np.ndarray:
        """Stacked residuals (P, m): data, eq. (1), segment by segment, then priors, eq. (2)."""
        sim = self.run(Z, offsets)[..., self.cidx]
        y = self.seg_y[..., self.cidx]
        m = self.seg_mask[..., self.cidx]
        r = np.where(m[None], (sim - y[None]) * self.seg_scale[None, :, None, :], 0.0)
        bad = ~np.isfinite(r)
        r = np.where(bad | (np.abs(r) > 1e6), 1e6, r)
        data = r[:, m].reshape(Z.shape[0], -1)
        pri = self.prior_residuals(Z)
        return np.concatenate([data, pri], axis=1)

    def segment_rows(self) -> np.ndarray:
        """Row offsets of each segment's data residuals (S + 1,)."""
        m = self.seg_mask[..., self.cidx]
        return np.concatenate([[0], np.cumsum(m.reshape(m.shape[0], -1).sum(1))])

    def expected_cost(self) -> float:
        """E[Σ r²] when the misfit is its expected size: Σ_c w_c n_c T / τ over the data
        rows (n_c rows of channel c, eq. (1)) plus one per prior (eq. (2))."""
        m = self.seg_mask[..., self.cidx]
        n_c = m.reshape(-1, m.shape[-1]).sum(0)
        w = np.array(list(self.channels.values()), float)
        data = float(w @ n_c) * self.dt / self.options.cost.correlation_time
        return data + float(np.isfinite(self.sigma).sum())

    def prior_residuals(self, Z: np.ndarray) -> np.ndarray:
        has = np.isfinite(self.sigma)
        return Z[:, has] / self.sigma[has]

    def fit_percent_segments(self, sim: np.ndarray) -> dict[str, dict[str, float | None]]:
        out: dict[str, dict[str, float | None]] = {}
        for li, L in enumerate(self.logs):
            rows = np.nonzero(self.seg_log == li)[0]
            d: dict[str, float | None] = {}
            for j, c in zip(self.cidx, self.channels, strict=True):
                m = self.seg_mask[rows, :, j]
                if not m.any():
                    continue
                v = _fitpct(self.seg_y[rows, :, j][m], sim[rows][:, :, j][m])
                d[c] = round(v, 3) if np.isfinite(v) else None
            out[L.name] = d
        return out


def _cols(L: _LogData, names) -> list[str]:
    return [n for n, p in zip(names, L.present, strict=False) if p]


# ----------------------------------------------------------------------------- JAX core
def _state_from_log(loop, y0, dy0):
    """Minimum-norm plant state x0 (and sensor-filter states) from the logged values y0 and
    rates dy0 (C,) at a segment start (module docstring)."""
    plant, sens = loop.plant, loop.sensors
    n = plant.n_states
    u0 = jnp.zeros((plant.n_inputs,))
    x = jnp.zeros((n,))
    Sj = jax.jacfwd(lambda xx: plant.signals(xx, u0))(x)
    F = jax.jacfwd(lambda xx: plant.rhs(xx, u0))(x)
    rows = jnp.stack([sens.gain[c] * Sj[i] for c, i in enumerate(sens.index)])  # (C, n)
    b_pos = y0 - logged_offset(sens)  # the readings' zero offsets (none on zeroed channels)
    vel_ok = jnp.ones_like(y0)
    if sens.filtered:
        for j, c in enumerate(sens.filtered):
            b_pos = b_pos.at[c].add(dy0[c] / sens.omega[j])
            vel_ok = vel_ok.at[c].set(0.0)
    A = jnp.concatenate([rows, (rows @ F) * vel_ok[:, None]])
    b = jnp.concatenate([b_pos, dy0 * vel_ok])
    x0 = jnp.linalg.pinv(A, rtol=1e-10) @ b
    return x0


def _warm(ctrl, names: tuple, nd: int, log_y, log_refs, seg_log, seg_k0, inits=None):
    """The controller run on the logged measured channels and references from each log's
    first sample: its state before each segment's first sample (S, ...) and the raw
    commands of the nd samples before it (S, nd, m), newest first (0 before the log).
    ``inits``: each log's controller state at its first sample, stacked over logs
    (``continuous``); None: ``ctrl.init()`` for every log."""

    def warm(ly, lr, c0):
        def step(cs, inp):
            m, r = inp
            cs2, u = ctrl.step(cs, {n: m[i] for i, n in enumerate(names)}, r)
            return cs2, (cs, u)

        _, (cs_all, u_all) = jax.lax.scan(step, ctrl.init() if c0 is None else c0, (ly, lr))
        return cs_all, u_all

    if inits is None:
        cs_all, u_all = jax.vmap(lambda ly, lr: warm(ly, lr, None))(log_y, log_refs)
    else:
        cs_all, u_all = jax.vmap(warm)(log_y, log_refs, inits)

    def one(s_log, k0):
        cs = jax.tree.map(lambda a: a[s_log, k0], cs_all)
        uc = u_all[s_log]
        ub = jnp.stack(
            [jnp.where(k0 - 1 - i >= 0, uc[jnp.maximum(k0 - 1 - i, 0)], 0.0) for i in range(nd)]
        )
        return cs, ub

    return jax.vmap(one)(seg_log, seg_k0)


_warm_jit = eqx.filter_jit(_warm)


def _one_candidate(
    loop,
    x0_scn,
    offsets,
    warm,
    seg_refs,
    y0,
    dy0,
    sbuf0,
    seg_xd,
    seg_scn,
    seg_k0,
    seg_sess,
    seg_noise,
):
    if seg_sess is not None:  # several sessions: each segment run by its session's loop
        return _by_session(
            loop,
            x0_scn,
            offsets,
            warm,
            seg_refs,
            y0,
            dy0,
            sbuf0,
            seg_xd,
            seg_scn,
            seg_k0,
            seg_sess,
            seg_noise,
        )
    act, sens = loop.actuator, loop.sensors
    cs_seg, ub_seg = warm
    scn_carry = initial_carry(loop, x0_scn)

    def seg_carry(cs, ub, y0s, dy0s, sb, xd, use_scn, off, k0):
        up = _quantise(jnp.clip(ub[-1], -act.limit, act.limit), act.quantum)
        x0 = _state_from_log(loop, y0s, dy0s)
        carry = (x0, cs, sb, ub, up)
        if sens.filtered:  # the analog filters' states, in gain·s units (offset removed)
            y0f = y0s - logged_offset(sens)
            carry += (jnp.stack([y0f[c] for c in sens.filtered]),)
        if sens.digital:
            carry += (xd,)
        if sens.zeroed:  # the logger's zeroing: a segment after its window reads the
            # logged (zeroed) values: the window's sum holds the offsets' part alone
            carry += (zeroing_start(sens, k0),)
        if len(carry) != len(scn_carry):
            raise RuntimeError(
                f"the sampled loop's carry has {len(scn_carry)} parts; the fit "
                f"builds {len(carry)} (flexarm.sim.sampled changed: update "
                "general._one_candidate)"
            )
        carry = jax.tree.map(lambda a, b: jnp.where(use_scn, a, b), scn_carry, carry)
        return (carry[0] + off,) + tuple(carry[1:]), x0

    carries, starts = jax.vmap(seg_carry)(
        cs_seg, ub_seg, y0, dy0, sbuf0, seg_xd, seg_scn, offsets, seg_k0
    )

    def one_seg(carry, refs, noise):
        _, (xs, sig, meas, us) = _scan(loop, carry, refs, noise, 1)
        return meas

    return jax.vmap(one_seg)(carries, seg_refs, seg_noise), starts


def _by_session(
    loop,
    x0_scn,
    offsets,
    warm,
    seg_refs,
    y0,
    dy0,
    sbuf0,
    seg_xd,
    seg_scn,
    seg_k0,
    seg_sess,
    seg_noise,
):
    """:func:`_one_candidate` with one loop per session (leaves (K, ...), start states
    (K, n_x)): each segment alone through its session's loop (``seg_sess``, (S,))."""

    def one(s_, cs, ub, refs, y0s, dy0s, sb, xd, use_scn, off, k0, nz):
        lp = jax.tree.map(lambda a: a[s_] if eqx.is_array(a) else a, loop)
        cs1, ub1, refs1, y01, dy01, sb1, xd1, nz1 = jax.tree.map(
            lambda a: a[None], (cs, ub, refs, y0s, dy0s, sb, xd, nz)
        )
        meas, start = _one_candidate(
            lp,
            x0_scn[s_],
            off[None],
            (cs1, ub1),
            refs1,
            y01,
            dy01,
            sb1,
            xd1,
            use_scn[None],
            k0[None],
            None,
            nz1,
        )
        return meas[0], start[0]

    cs_seg, ub_seg = warm
    return jax.vmap(one)(
        seg_sess,
        cs_seg,
        ub_seg,
        seg_refs,
        y0,
        dy0,
        sbuf0,
        seg_xd,
        seg_scn,
        offsets,
        seg_k0,
        seg_noise,
    )


@eqx.filter_jit
def _run_segments(
    loop,
    x0s,
    offsets,
    warm,
    shared_warm: bool,
    seg_refs,
    y0,
    dy0,
    sbuf0,
    seg_xd,
    seg_scn,
    seg_k0,
    seg_sess=None,
    seg_noise=None,
):
    if seg_noise is None:  # noise-free (the fit; a prediction): (S, M, C) zeros, once
        M = next(iter(seg_refs.values())).shape[1]
        seg_noise = jnp.zeros((len(seg_k0), M, y0.shape[-1]))

    def f(lp, x0, off, w):
        return _one_candidate(
            lp, x0, off, w, seg_refs, y0, dy0, sbuf0, seg_xd, seg_scn, seg_k0, seg_sess, seg_noise
        )

    return eqx.filter_vmap(f, in_axes=(0, 0, 0, None if shared_warm else 0))(
        loop, x0s, offsets, warm
    )


# ----------------------------------------------------------------------------- fit
def fit_scenario(
    scenario,
    logs: Sequence,
    free: Sequence[str] | None = None,
    options: FitOptions | None = None,
    *,
    progress=None,
    predict: bool = True,
    plots: str | Path | None = None,
) -> ScenarioFit:
    """Estimate the ``free`` parameters of ``scenario`` from closed-loop ``logs``
    (:class:`flexarm.io.logs.Log` with the scenario's sensor channels and references as
    columns, sampled at the scenario's period). See the module docstring. Without ``free``
    (and priors), the scenario's ``[notes.fit]`` table gives them (``free = [...]``,
    ``priors = {...}``). ``options``: :class:`FitOptions` (None: the defaults), resolved
    (:meth:`FitOptions.resolved`: every group filled) and read group by group by the engine
    (``options.cost``, ``options.shooting``, ``options.local``, ``options.global_de``,
    ``options.priors``, ``options.delay_search``); a deprecated
    :class:`ScenarioFitOptions` is converted (:meth:`FitOptions.from_flat`, with a
    ``DeprecationWarning``). ``predict``: also simulate each whole log (window) with the fitted
    values (fit % of the whole-run prediction; skip for long chaotic runs); ``plots``: a
    folder for that prediction's overlay figures (``NN_KEY_fit.png``, in the result's
    ``plots``)."""
    from flexarm.identification.time_domain.solvers import evolve

    # the engine reads the groups itself: every one filled (a deprecated flat record
    # converted, with a DeprecationWarning)
    options = as_fit_options(options, "fit_scenario").resolved()
    fit_notes = scenario_fit_notes(scenario)
    free = list(free if free is not None else fit_notes.get("free", []))
    if not options.priors.priors and fit_notes.get("priors"):
        options.priors.priors = dict(fit_notes["priors"])
    if not free:
        raise ValueError(
            "fit_scenario: no free parameters; list them (free=[...]) as paths "
            "into the scenario, e.g. 'arm.joints[0].friction.coulomb'"
        )
    t_start = time.perf_counter()
    eng = _Engine(scenario, logs, free, options)
    if options.delay_search is not None:  # bad input before the fit, not after it
        from flexarm.identification.time_domain.delays import searched_channels

        searched_channels(options.delay_search, eng)
    n = len(eng.free)
    say = progress or (lambda msg: None)
    z0 = np.zeros(n)
    stages: dict[str, Any] = {"segments": len(eng.seg), "segment_samples": eng.M}
    if eng.tied:  # path -> the free path it moves with (design.plants.from_fit reads it)
        stages["ties"] = {p: eng.free[i] for p, (i, _) in eng.tied.items()}
    if eng.linear.any():  # signed parameters, fitted as p0 + s·z (their std is s·σ_z)
        stages["linear"] = [p for i, p in enumerate(eng.free) if eng.linear[i]]
    if eng.notes:
        stages["computed_channels"] = list(eng.notes)
    if options.global_de is not None:
        t0 = time.perf_counter()

        def f(x):
            X = np.atleast_2d(np.asarray(x).T) if np.ndim(x) == 2 else np.asarray(x)[None]
            R = eng.residuals(X)
            return np.sum(R * R, axis=1)

        res = evolve(
            f,
            list(zip(eng.lo, eng.hi, strict=True)),
            x0=z0,
            popsize=options.global_de.popsize,
            maxiter=options.global_de.maxiter,
            seed=options.global_de.seed,
            tol=1e-3,
        )
        z0 = np.asarray(res.x)
        stages["global"] = {
            "cost": float(res.fun),
            "nfev": int(res.nfev),
            "generations": int(res.nit),
            "seconds": round(time.perf_counter() - t0, 2),
        }
        say(f"global stage: cost {res.fun:.4g} after {res.nit} generations")

    z0 = np.clip(z0, eng.lo, eng.hi)
    # with quantise and continuation, smooth first: the quantised cost is piecewise
    # constant at the scale of one count (finite differences stall on it); the smooth
    # loop's optimum starts the quantised local stage
    passes = [("local", "local stage", options)]
    if options.cost.quantise and options.cost.continuation:
        smooth = dataclasses.replace(
            options, cost=dataclasses.replace(options.cost, quantise=False)
        )
        passes.insert(0, ("smooth", "smooth stage (no quantisation)", smooth))
    for key, label, opts in passes:
        eng.options = opts
        res, r, J, info = _local(
            eng,
            z0,
            options,
            states=options.shooting.estimate_states and options.shooting.segment is not None,
            progress=progress,
        )
        stages[key] = info
        say(
            f"{label}: cost {info['cost']:.4g} after {info['nfev']} evaluations ({info['message']})"
        )
        z0 = np.clip(res.x, eng.lo, eng.hi)
    if options.delay_search is not None:  # the sensors' delays, then the local stage again
        from flexarm.identification.time_domain.delays import search_delays

        states = options.shooting.estimate_states and options.shooting.segment is not None
        found = search_delays(
            scenario,
            eng,
            z0,
            engine=lambda sc: _Engine(sc, logs, free, options),
            local=lambda e, z: _local(e, z, options, states=states, progress=progress),
            progress=progress,
            offsets=res.offsets if states else None,
            state_blocks=getattr(res, "state_blocks", None) if states else None,
        )
        stages["delay_search"] = found.record
        if found.local is not None:
            scenario, eng = found.scenario, found.engine
            res, r, J, stages["delay_local"] = found.local
    if options.subset_search is not None:  # friction (or other) coordinates re-searched
        from flexarm.identification.time_domain.subset import search_subset

        states = options.shooting.estimate_states and options.shooting.segment is not None
        paths = _subset_paths(eng, scenario, options.subset_search.paths)
        if paths:
            rec, loc = search_subset(
                eng,
                res.x,
                res.offsets if states else None,
                lambda z_, o_: _local(eng, z_, options, states=states, o0=o_, progress=progress),
                paths,
                progress=progress,
            )
            stages["subset_search"] = rec
            if loc is not None:
                res, r, J, stages["subset_local"] = loc
    if options.shooting.polish and options.shooting.segment is not None:
        eng = _Engine(scenario, logs, free, options, segment=None)
        # each log's start state stays a nuisance parameter (offsets to the logged state)
        res, r, J, info = _local(
            eng,
            res.x,
            options,
            progress=progress,
            states=options.shooting.estimate_states and not eng.seg_scn.all(),
        )
        stages["polish"] = info
        say(
            f"polish on whole logs: cost {info['cost']:.4g} after {info['nfev']} evaluations "
            f"({info['message']})"
        )
    z = res.x
    info_diag = np.einsum("ij,ij->j", J, J)
    det = info_diag > 1e-12 * max(float(info_diag.max()), 1e-300)
    cov = np.full((n, n), np.nan)
    if det.any():
        cov[np.ix_(det, det)] = _covariance(eng, r, J[:, det])
    # the fit reports its whole-run prediction from each log's logged state, or, where
    # each log (window) was one segment whose start state the fit estimated, from that
    # state estimated on the log: `validate` of the written scenario starts there too
    # ([notes.validate] initial, predict's default); several sessions: one scenario each
    # (session 0's is the result's scenario)
    one_each = len(eng.seg) == len(eng.logs) and bool(
        options.shooting.estimate_states and options.shooting.segment is not None
    )
    initial = "estimate" if one_each else "log"
    K = eng.n_sessions
    per_session = []
    for s_ in range(K):
        sc = scenario_with(scenario, eng.session_values(z, s_))
        upd: dict[str, Any] = {"notes": {**sc.notes, "validate": {"initial": initial}}}
        if K > 1 and s_:
            upd["name"] = f"{sc.name}-session{s_}"
        per_session.append(sc.model_copy(update=upd))
    fitted = per_session[0]
    dumps = [sc.model_dump() for sc in per_session]
    # the values in the fitted scenario (a breakaway below its Coulomb level is raised to it)
    values = {p: float(_path_get(dumps[_key_session(p)], session_path(p))) for p in eng.values(z)}
    std_z = np.sqrt(np.maximum(np.diag(cov), 0.0))
    std = {
        p: eng.std_of(i, values[p], std_z[i]) if det[i] else float("inf")
        for i, p in enumerate(eng.free)
    }
    d = np.sqrt(np.maximum(np.diag(cov), 1e-300))
    corr = cov / np.outer(d, d)
    warnings = []
    for i, p in enumerate(eng.free):
        if not det[i]:
            warnings.append(
                f"{p}: the fit does not depend on it at the optimum (e.g. a "
                "breakaway level below the Coulomb level, raised to it, or a "
                "joint that never sticks): its value is not determined by the data"
            )
    for i in range(n):
        for j in range(i + 1, n):
            if det[i] and det[j] and abs(corr[i, j]) > options.priors.corr_warn:
                warnings.append(
                    f"the data cannot tell {eng.free[i]} from {eng.free[j]} "
                    f"(correlation {corr[i, j]:+.3f}): fix one, give a prior, or "
                    "add an experiment that separates them"
                )
    for i, p in enumerate(eng.free):
        if z[i] <= eng.lo[i] + 1e-3 or z[i] >= eng.hi[i] - 1e-3:
            lo, hi = sorted((eng.value_of(i, eng.lo[i]), eng.value_of(i, eng.hi[i])))
            warnings.append(
                f"{p} = {values[p]:.4g} lies at a bound of [{lo:.4g}, {hi:.4g}]; "
                f"widen it with FitOptions.priors.bounds={{{p!r}: (lo, hi)}}"
            )
    sim = eng.run(z[None], res.offsets[None])[0]
    seg_fp = eng.fit_percent_segments(sim)
    if not predict:
        pred: dict[str, Any] = {"fit_percent": {}, "plots": []}
    elif K == 1:
        pred = predict_scenario(
            fitted,
            logs,
            options,
            channels=list(eng.channels),
            plots=plots,
            tag="fit",
            initial=initial,
        )
    else:
        pred = _predict_by_session(eng, per_session, logs, options, plots, initial)
    if K > 1:  # the result says which parameters are per session (#47)
        stages["sessions"] = {
            "of_log": [int(k) for k in eng.log_session],
            "per_session": list(eng.per_session),
            "shared": [
                p
                for i, p in enumerate(eng.free)
                if p not in eng.per_session and not eng.session_of[i]
            ],
        }
    converged = res.status > 0
    msg = ("converged" if converged else "NOT CONVERGED") + f" ({res.message})"
    return ScenarioFit(
        eng.free,
        values,
        dict(zip(eng.free, map(float, eng.p0), strict=True)),
        std,
        corr,
        warnings,
        pred["fit_percent"],
        seg_fp,
        fitted,
        converged,
        msg,
        int(res.nfev),
        float(2 * res.cost),
        time.perf_counter() - t_start,
        stages,
        pred,
        plots=list(pred["plots"]),
        rmse=dict(pred.get("rmse", {})),
        nrmse=dict(pred.get("nrmse", {})),
        session_scenarios=per_session if K > 1 else [],
    )


def _subset_paths(eng: _Engine, scenario, given: Sequence[str] | None) -> list[str]:
    """The coordinates :class:`SubsetSearch` searches: ``given`` paths (each must be free),
    or the free joint-friction paths (:func:`friction_paths`; none: nothing searched), each
    with its later sessions' coordinates."""
    if given is not None:
        bad = [p for p in given if p not in eng.free]
        if bad:
            raise ValueError(
                f"FitOptions.subset_search.paths: {', '.join(map(repr, bad))} not free; "
                f"free: {', '.join(eng.free)}"
            )
        base = set(given)
    else:
        base = _friction_set(scenario)
    return [p for i, p in enumerate(eng.free) if eng.free[eng.base_of[i]] in base]


def _friction_set(scenario) -> set[str]:
    """:func:`friction_paths` of ``scenario`` as a set, empty where it has no joint friction
    (the defaults of ``Sessions.per_session`` and ``SubsetSearch.paths``)."""
    try:
        return set(friction_paths(scenario))
    except ValueError:
        return set()


def _segment_noise(eng: _Engine, noise: Sequence) -> np.ndarray:
    """(S, M, C) noise per segment from ``noise``: per log a mapping channel → samples over
    the log's window (at least its length); channels not given are noise-free."""
    if len(noise) != len(eng.logs):
        raise ValueError(f"noise has {len(noise)} entries for {len(eng.logs)} logs")
    S = len(eng.seg)
    out = np.zeros((S, eng.M, len(eng.names)))
    for s_, (li, k0, ln) in enumerate(eng.seg):
        given = noise[li] or {}
        start = k0 - eng.seg[[i for i, (l2, _, _) in enumerate(eng.seg) if l2 == li][0]][1]
        for c, v in given.items():
            if c not in eng.names:
                raise ValueError(
                    f"noise: {c!r} is not a sensor channel of scenario "
                    f"{eng.template.name!r}; channels: {', '.join(eng.names)}"
                )
            v = np.asarray(v, float)
            if v.shape[0] < start + ln:
                raise ValueError(
                    f"noise[{li}][{c!r}] has {v.shape[0]} samples; the log (window) "
                    f"{eng.logs[li].name} has {start + ln}"
                )
            out[s_, :ln, eng.names.index(c)] = v[start : start + ln]
    return out


def _key_session(key: str) -> int:
    """The session of a result key: ``sessions[2].PATH`` → 2, a path → 0."""
    return int(key[len("sessions[") : key.index("]")]) if key.startswith("sessions[") else 0


def _predict_by_session(
    eng: _Engine, scenarios: list, logs: Sequence, options, plots, initial: str = "log"
) -> dict:
    """:func:`predict_scenario` of each session's logs by its session's scenario, merged
    in the logs' order under the fit's log names."""
    wins = list(options.windows or [None] * len(logs))
    out: dict[str, Any] = {}
    for s_, sc in enumerate(scenarios):
        idx = [i for i, k in enumerate(eng.log_session) if k == s_]
        opts = dataclasses.replace(options, windows=[wins[i] for i in idx], sessions=None)
        part = predict_scenario(
            sc,
            [logs[i] for i in idx],
            opts,
            channels=list(eng.channels),
            plots=plots,
            tag=f"fit-session{s_}",
            initial=initial,
        )
        for key in ("fit_percent", "rmse", "nrmse", "trajectories"):
            got = list(part.get(key, {}).values())
            out.setdefault(key, {}).update(
                {eng.logs[i].name: v for i, v in zip(idx, got, strict=True)}
            )
        out.setdefault("plots", []).extend(part["plots"])
        out.setdefault("warnings", []).extend(part.get("warnings", []))
        out.setdefault("notes", []).extend(part.get("notes", []))
    order = [L.name for L in eng.logs]
    for key in ("fit_percent", "rmse", "nrmse", "trajectories"):
        out[key] = {k: out[key][k] for k in order if k in out.get(key, {})}
    out["notes"] = list(dict.fromkeys(out["notes"])) + [
        f"session {s_}: its own {', '.join(eng.per_session)}" for s_ in range(len(scenarios))
    ]
    out["warnings"] = list(dict.fromkeys(out["warnings"]))
    return out


def _local(
    eng: _Engine,
    z0: np.ndarray,
    options: ResolvedOptions,
    states: bool = False,
    o0: np.ndarray | None = None,
    progress=None,
    state_index: Sequence[int] | None = None,
):
    """least_squares (trf) on the stacked residuals; the finite-difference Jacobian's
    columns are simulated with the point itself as one batch. With ``states``, each
    segment's start state is estimated too (multiple shooting's node states): offsets
    (S, n_x) in units of :attr:`_Engine.state_scale`; the segments are independent, so one
    simulation perturbing state i in every segment gives the S columns of state i (a
    block-sparse Jacobian, solved by LSMR). ``ftol`` None: :data:`COST_RESOLUTION` /
    :meth:`_Engine.expected_cost`."""
    from scipy import sparse

    from flexarm.identification.time_domain.solvers import trust_region

    n = len(eng.free)
    S = len(eng.seg)
    n_x = eng.prep0.loop.plant.n_states
    idx = np.arange(n_x) if state_index is None else np.asarray(state_index, int)
    nx = idx.size if states else 0
    local = options.local
    step = local.fd_step
    rows = eng.segment_rows()
    cache: dict = {}

    def split(v):
        z = v[:n]
        off = np.zeros((S, n_x))
        if nx:
            off[:, idx] = v[n:].reshape(S, nx)
        return z, off

    def point(v):
        key = v.tobytes()
        if key not in cache:
            z, off = split(v)
            # keep the last point whose Jacobian was simulated (a restart, and the result
            # below, start from it) beside the newest point
            for k in [k for k, c in cache.items() if "J" not in c]:
                del cache[k]
            cache[key] = {"r": eng.residuals(z[None], off[None])[0]}
        return cache[key]

    def jac(v):
        c = point(v)
        if "J" in c:
            return c["J"]
        z, off = split(v)
        h = np.where(z + step > eng.hi, -step, step)
        Z = np.tile(z, (n + nx, 1))
        Z[np.arange(n), np.arange(n)] += h
        OO = np.tile(off, (n + nx, 1, 1))
        for i in range(nx):
            OO[n + i, :, idx[i]] += step
        R = eng.residuals(Z, OO)
        r0 = c["r"]
        Jp = ((R[:n] - r0) / h[:, None]).T
        if nx:
            D = (R[n:] - r0) / step  # (nx, m)
            r_i, c_i, vals = [], [], []
            for s_ in range(S):
                a_, b_ = int(rows[s_]), int(rows[s_ + 1])
                for i in range(nx):
                    r_i.append(np.arange(a_, b_))
                    c_i.append(np.full(b_ - a_, s_ * nx + i))
                    vals.append(D[i, a_:b_])
            Jo = sparse.csr_matrix(
                (np.concatenate(vals), (np.concatenate(r_i), np.concatenate(c_i))),
                shape=(r0.size, S * nx),
            )
            c["J"] = sparse.hstack([sparse.csr_matrix(Jp), Jo]).tocsr()
        else:
            c["J"] = Jp
        for k in [k for k, e in cache.items() if "J" in e and e is not c]:
            del cache[k]  # one Jacobian kept
        if progress is not None:
            progress(f"  cost {float(r0 @ r0):.6g}")
        return c["J"]

    def batch(v):
        return point(v)["r"], jac(v)

    ftol = local.ftol if local.ftol is not None else COST_RESOLUTION / eng.expected_cost()
    v0 = np.concatenate([z0, np.zeros(S * nx) if o0 is None or not nx else np.ravel(o0[:, idx])])
    lo = np.concatenate([eng.lo, np.full(S * nx, -np.inf)])
    hi = np.concatenate([eng.hi, np.full(S * nx, np.inf)])
    t0 = time.perf_counter()
    res = trust_region(
        lambda v: point(v)["r"],
        jac,
        v0,
        lo,
        hi,
        max_nfev=local.max_nfev,
        ftol=ftol,
        xtol=local.xtol,
        gtol=1e-10,
        tr_solver="lsmr" if nx else "exact",
        # the stop rule "Σ r² fell by less than it resolves" where ftol is the engine's own
        resolution=local.ftol is None,
        restarts=local.restarts,
    )
    restarts = list(res.restarts)
    r, J = batch(res.x)
    J = J.toarray() if nx else J
    z, off = split(res.x)
    Jz = J[:, :n]
    blocks = []  # per segment: rows and an orthonormal basis of its state Jacobian
    if nx:  # profile the state offsets out (Frisch–Waugh), segment by segment
        Jz = Jz.copy()
        for s_ in range(S):
            a_, b_ = int(rows[s_]), int(rows[s_ + 1])
            Jo = J[a_:b_, n + s_ * nx : n + (s_ + 1) * nx]
            coef, *_ = np.linalg.lstsq(Jo, Jz[a_:b_], rcond=1e-10)
            Jz[a_:b_] -= Jo @ coef
            U, sv, _ = np.linalg.svd(Jo, full_matrices=False)
            keep = sv > 1e-10 * max(float(sv.max(initial=0.0)), 1e-300)
            blocks.append((a_, b_, U[:, keep]))
    info = {
        "cost": float(2 * res.cost),
        "nfev": int(res.nfev),
        "status": int(res.status),
        "message": str(res.message),
        "segments": S,
        "state_offsets": S * nx,
        "ftol": float(ftol),
        "restarts": restarts,
        "seconds": round(time.perf_counter() - t0, 2),
    }
    res.x = z
    res.offsets = off
    res.state_blocks = blocks
    return res, r, Jz, info


def friction_paths(scenario) -> list[str]:
    """The joints' friction parameters of a scenario that can be fitted (non-zero): per joint
    Coulomb, breakaway (where set apart from Coulomb) and viscous friction."""
    d = scenario.model_dump()
    arm = d["arm"]
    out = []
    if arm.get("kind") == "single_link":
        fr = arm.get("friction") or {}
        base = "arm.friction"
        groups = [(base, fr, "arm.motor.viscous", arm["motor"].get("viscous", 0.0))]
    else:
        groups = [
            (
                f"arm.joints[{j}].friction",
                jt.get("friction") or {},
                f"arm.joints[{j}].viscous",
                jt.get("viscous", 0.0),
            )
            for j, jt in enumerate(arm.get("joints") or [])
        ]
    for base, fr, vpath, v in groups:
        if fr.get("model", "none") != "none":
            if fr.get("coulomb"):
                out.append(f"{base}.coulomb")
            if fr.get("static"):
                out.append(f"{base}.static")
        if v:
            out.append(vpath)
    if not out:
        raise ValueError(
            f"scenario {scenario.name!r}: no joint friction to re-estimate (every "
            "friction level is 0 or its model is 'none'); give starting values "
            "in the scenario"
        )
    return out


def refit_friction(
    scenario,
    log,
    window: tuple[float, float] | None = None,
    channels: Mapping[str, float] | None = None,
) -> ScenarioFit:
    """Re-estimate only the joints' friction of ``scenario`` (:func:`friction_paths`:
    Coulomb, breakaway and viscous levels) on ``log`` (its ``window``, s), everything else
    fixed: the cost of eq. (1) on ``channels`` (None: every logged sensor channel), no
    prediction (``flexarm validate --refit friction``). The free list is ``res.free``.

    Deprecated: ``flexarm.fit(scenario, [log], friction_paths(scenario),
    FitOptions(cost=Cost(channels=...), windows=[window], predict=False))``."""
    import warnings

    warnings.warn(
        "refit_friction is deprecated: use flexarm.fit(scenario, [log], "
        "friction_paths(scenario), FitOptions(cost=Cost(channels=...), windows=[window], "
        "predict=False))",
        DeprecationWarning,
        stacklevel=2,
    )
    return fit_scenario(
        scenario,
        [log],
        friction_paths(scenario),
        FitOptions(cost=Cost(channels=channels), windows=[window]),
        predict=False,
    )


def scenario_fit_notes(scenario) -> dict:
    """The scenario's ``[notes.fit]`` table: ``free = [paths]`` and ``priors = {path =
    rel_std}``, used when the call gives none."""
    notes = getattr(scenario, "notes", {}) or {}
    fit = notes.get("fit") if isinstance(notes, dict) else None
    if fit is None:
        return {}
    if (
        not isinstance(fit, dict)
        or not isinstance(fit.get("free", []), list)
        or not isinstance(fit.get("priors", {}), dict)
    ):
        raise ValueError(
            f'scenario {scenario.name!r}: [notes.fit] must hold free = ["path", '
            f'...] and priors = {{"path" = rel_std}}; got {fit!r}'
        )
    return fit


def _covariance(eng: _Engine, r: np.ndarray, J: np.ndarray) -> np.ndarray:
    """H⁻¹ (Ŝ + J_pᵀJ_p) H⁻¹ (module docstring); Ŝ the Newey–West meat per segment."""
    n = J.shape[1]
    npri = int(np.isfinite(eng.sigma).sum())
    nd = r.size - npri
    rd, Jd = r[:nd], J[:nd]
    Jp = J[nd:]
    m = eng.seg_mask[..., eng.cidx]  # (S, M, C)
    # scatter back to (S, M, C) to form the per-segment score series
    Rfull = np.zeros(m.shape)
    Rfull[m] = rd
    Jfull = np.zeros(m.shape + (n,))
    Jfull[m] = Jd
    Smeat = np.zeros((n, n))
    for s in range(m.shape[0]):
        used = m[s].any(axis=1)
        if not used.any():
            continue
        rs, Js = Rfull[s][used], Jfull[s][used]  # (T, C), (T, C, n)
        M = bandwidth(rs.T)
        g = np.einsum("tc,tcp->tp", rs, Js)
        fb = M / rs.shape[0]
        Smeat += bartlett_meat(g, M) / (1.0 - fb + fb**2 / 3.0)
    H = Jd.T @ Jd + Jp.T @ Jp
    Hi = np.linalg.pinv(H)
    dof = nd / max(nd - n, 1)
    cov = Hi @ (Smeat * dof + Jp.T @ Jp) @ Hi
    return 0.5 * (cov + cov.T)


# ----------------------------------------------------------------------------- predict
def predict_scenario(
    scenario,
    logs: Sequence,
    options: FitOptions | None = None,
    *,
    channels: Sequence[str] | None = None,
    plots: str | Path | None = None,
    tag: str = "predict",
    initial: str = "log",
    initial_nfev: int = INITIAL_NFEV,
    noise: Sequence[Mapping[str, np.ndarray] | None] | None = None,
) -> dict:
    """Whole-run prediction of each log (or window) with the scenario's parameters fixed:
    one simulation per log (window) and channel fit % = 100 (1 − ‖y − ŷ‖/‖y − ȳ‖), the
    RMSE √(mean (y − ŷ)²) in the channel's SI unit and the NRMSE, the RMSE over the
    channel's range max y − min y (``rmse``, ``nrmse``), and the simulated channels.
    Where each starts (``initial``, :data:`INITIALS`):

    - ``"estimate"``: the state read off the log at the window's first sample (values and
      rates after each channel's delay, :func:`_state_from_log`), refined by least squares
      on the window itself over every plant state (offsets in units of
      :attr:`_Engine.state_scale`, at most ``initial_nfev`` evaluations; the parameters
      stay fixed): the fit's own treatment of a segment's start state (multiple
      shooting's node states), so that a scenario predicts a held-out window as its fit
      did. A link ringing at the first sample is normal on a real rig.
    - ``"log"``: the state read off the log, not refined (``options.shooting.initial =
      "scenario"``: a log's first sample from the scenario's ``[initial]`` state).
    - ``"rest"``: the positions read off the log, every rate zero.

    The returned ``notes`` say which. ``noise``: per log, channel → measurement noise in the
    channel's SI unit over the log (window), added where the sensor reads (before its A/D
    and delay) and read by the controller: the closed loop's response to it is simulated
    (a parametric bootstrap's replicate, :mod:`~.bootstrap`); None: noise-free. The start
    state is estimated (``"estimate"``) on the noise-free loop."""
    if initial not in INITIALS:
        raise ValueError(
            f"initial = {initial!r}: one of {', '.join(map(repr, INITIALS))} (estimate: the "
            "logged state refined on the log; log: as read off the log; rest: the logged "
            "positions at rest)"
        )
    # fresh groups (FitOptions.resolved): changing them leaves the caller's options alone
    opts = as_fit_options(options, "predict_scenario").resolved()
    opts.priors.priors, opts.priors.bounds, opts.priors.ties = {}, {}, {}
    opts.cost.quantise = True
    opts.cost.substeps = None  # the scenario's own integration step
    opts.local.max_nfev = int(initial_nfev)
    if channels is not None:
        opts.cost.channels = {c: 1.0 for c in channels}
    eng = _Engine(scenario, logs, [], opts, segment=None)
    if initial == "estimate" and len(logs) > 1 and not opts.continuous and not eng.seg_scn.all():
        # each log's start state estimated on that log alone (a least-squares budget spent
        # on several logs together ends elsewhere): a log's figure does not depend on the
        # logs predicted beside it, and a fit's report is `validate` of each log
        wins = list(opts.windows or [None] * len(logs))
        parts = [
            predict_scenario(
                scenario,
                [log],
                dataclasses.replace(opts, windows=[wins[i]], sessions=None),
                channels=channels,
                tag=tag,
                initial=initial,
                initial_nfev=initial_nfev,
                noise=None if noise is None else [noise[i]],
            )
            for i, log in enumerate(logs)
        ]
        out: dict[str, Any] = {"plots": [], "notes": list(parts[0]["notes"]), "warnings": []}
        for key in ("fit_percent", "rmse", "nrmse", "trajectories"):
            out[key] = {
                L.name: next(iter(part[key].values()))
                for L, part in zip(eng.logs, parts, strict=True)
            }
        out["warnings"] = list(dict.fromkeys(w for part in parts for w in part["warnings"]))
        return _with_overlays(out, plots, tag)
    state_warnings = eng.assumed_starts()
    notes: list[str] = []
    offsets = None
    if initial == "rest":
        eng.dy0 = np.zeros_like(eng.dy0)
        notes.append("initial state: the logged positions at rest (every rate zero)")
    elif initial == "estimate" and not eng.seg_scn.all():
        res, *_ = _local(eng, np.zeros(0), opts, states=True)
        offsets = res.offsets[None]
        notes.append(
            "initial state: read off each log (window) and refined by least squares on it "
            f"(the fit's start-state estimate, {res.nfev} evaluations); "
            "initial='log' (--initial log) takes it as read, 'rest' at rest"
        )
    else:
        notes.append("initial state: as read off each log (window), not refined")
    if noise is not None:
        eng.seg_noise = _segment_noise(eng, noise)
        notes.append("measurement noise given: added where each sensor reads, in the loop")
    sim = eng.run(np.zeros((1, 0)), offsets)[0]
    fp: dict[str, dict[str, float | None]] = {}
    rmse: dict[str, dict[str, float]] = {}
    nrmse: dict[str, dict[str, float | None]] = {}
    traj: dict[str, dict[str, Any]] = {}  # time, and the simulated / measured channels
    for s, (li, k0, ln) in enumerate(eng.seg):
        L = eng.logs[li]
        d, tr, e, ne = {}, {}, {}, {}
        for j, c in zip(eng.cidx, eng.channels, strict=True):
            tr[c] = sim[s, :ln, j]
            m = eng.seg_mask[s, :ln, j]
            if m.any():
                y, yh = eng.seg_y[s, :ln, j][m], sim[s, :ln, j][m]
                v = _fitpct(y, yh)
                # a constant channel (a rigid arm's zero tip column) measures nothing: None
                d[c] = round(v, 3) if np.isfinite(v) else None
                # the misfit in the channel's own unit, and over the channel's range
                e[c] = float(np.sqrt(np.mean((y - yh) ** 2)))
                span = float(np.ptp(y))
                ne[c] = e[c] / span if span > 0 else None
        fp[L.name] = d
        rmse[L.name], nrmse[L.name] = e, ne
        traj[L.name] = {
            "time": L.t[k0 : k0 + ln],
            "simulated": tr,
            "measured": {
                c: eng.seg_y[s, :ln, j] for j, c in zip(eng.cidx, eng.channels, strict=True)
            },
        }
    out = {
        "fit_percent": fp,
        "rmse": rmse,
        "nrmse": nrmse,
        "trajectories": traj,
        "plots": [],
        "notes": list(eng.notes) + notes,
        "warnings": state_warnings,
    }
    return _with_overlays(out, plots, tag)


def _with_overlays(out: dict, plots: str | Path | None, tag: str) -> dict:
    """``out`` (a :func:`predict_scenario` result) with its overlay figures drawn into the
    folder ``plots`` (the one overlay figure, :func:`~.figures.write_overlays`; file names
    ``NN_NAME_TAG.png``) and listed in ``out["plots"]``; None: none drawn."""
    if plots is None:
        return out
    from flexarm.identification.time_domain.figures import write_overlays
    from flexarm.identification.time_domain.result import Prediction

    fp, traj = out["fit_percent"], out["trajectories"]
    names = [
        f"{i:02d}_{re.sub(r'[^A-Za-z0-9_.-]+', '_', Path(n).name)}_{tag}.png"
        for i, n in enumerate(traj)
    ]
    pred = Prediction(tag, {k: dict[str, float | None](v) for k, v in fp.items()}, traj)
    out["plots"] = [str(p) for p in write_overlays(pred, plots, tag, names=names)]
    return out
