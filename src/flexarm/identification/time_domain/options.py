"""Typed, grouped options of the one fit and the one prediction.

:class:`FitOptions` groups what the general engine
(:mod:`flexarm.identification.time_domain.general`, eqs. (1)–(2) there) reads, and the
engine reads them itself (``options.cost.channels``, ``options.shooting.segment``,
``options.local.max_nfev``, ...) from :meth:`FitOptions.resolved` options, in which every
group is filled (a preset's groups overridden by the given ones); each group checks its own
fields (``FitOptions.shooting.segment = -1 s: ...``):

* :class:`Cost` — channels and weights w_c, residual level λ and correlation time τ of
  eq. (1), quantisation in the fitted loop, integration substeps;
* :class:`Shooting` — multiple-shooting segment length (s), burn-in (s), estimated node
  states, the start state (``"log"`` or ``"scenario"``), a polish on whole logs;
* :class:`Local` — the least-squares budget and tolerances, the finite-difference step in z;
* :class:`GlobalDE` — differential evolution first (population, generations, seed), or None;
* :class:`DelaySearch` — the sensors' pure delays (samples) searched after the local stage
  (:mod:`~flexarm.identification.time_domain.delays`), or None: the scenario's delays;
* :class:`Priors` — bounds p0/f … p0·f, absolute bounds, priors (relative std, eq. (2)),
  tied paths;
* :class:`ServoRig` — the options of the voltage-driven rotary servo's engine (its sensor
  delay search, global stage time budget, friction polish, sessions, tip sign, encoder
  counts, analog filters, mode), passed to that engine's keyword interface.

``windows`` (per log, (t0, t1) s from its first sample, [t0, t1)), ``continuous``,
``period_tolerance`` and ``plots`` (a folder for the fit's overlay figures) are common to all.
The old flat record :class:`ScenarioFitOptions` is a deprecated input only
(:meth:`FitOptions.from_flat`).

:class:`PredictOptions` are the prediction's (:mod:`~flexarm.identification.time_domain.predict`).
"""

from __future__ import annotations

import copy
import dataclasses
import math
import numbers
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

__all__ = [
    "COST_RESOLUTION",
    "ScenarioFitOptions",
    "FLAT_FIELDS",
    "as_fit_options",
    "Cost",
    "Shooting",
    "Local",
    "GlobalDE",
    "DelaySearch",
    "SubsetSearch",
    "Priors",
    "ServoRig",
    "Bootstrap",
    "Sessions",
    "FitOptions",
    "ResolvedOptions",
    "PredictOptions",
]


def channel_weights(value: Any, field_name: str) -> dict[str, float] | None:
    """``channels`` given as weights (name → w_c) or as names alone (a list: w_c = 1);
    anything else is one line naming the field, the value and the fix."""
    if value is None:
        return None
    if isinstance(value, str):
        value = [value]
    if isinstance(value, Mapping):
        items = list(value.items())
    elif isinstance(value, (list, tuple, set, frozenset)):
        items = [(c, 1.0) for c in value]
    else:
        items = None
    ok = all(
        isinstance(c, str)
        and isinstance(w, numbers.Real)
        and not isinstance(w, bool)
        and math.isfinite(float(w))
        and float(w) >= 0
        for c, w in items or [(None, None)]
    )
    if items is None or not ok:
        raise ValueError(
            f"{field_name} = {value!r}: give channel names (['motor_angle', 'current']) or "
            "name -> weight ({'motor_angle': 1.0, 'current': 0.5}), weights finite and >= 0"
        )
    return {c: float(w) for c, w in items}


def _positive(group, name: str, fields: Sequence[str]) -> None:
    """Each of ``fields`` of ``group`` (``FitOptions.<name>``) a finite number > 0."""
    for f in fields:
        v = getattr(group, f)
        if not (v > 0 and math.isfinite(v)):
            raise ValueError(f"FitOptions.{name}.{f} = {v!r}: must be a finite number > 0")


@dataclass
class Cost:
    """Eq. (1): ``channels`` measured channel → weight w_c (names alone: 1 each; None: every
    sensor channel the logs measure, 1); ``residual_level`` λ, the expected misfit as a
    fraction of each channel's spread; ``correlation_time`` τ (s), the residuals'
    correlation time. ``quantise``: keep the converters' quantisation in the fitted loop.
    Off by default: a quantiser inside the loop makes the cost piecewise constant in the
    parameters at the scale of one count, which stalls finite differences; its effect on
    the loop is a small noise-like error (the whole-run prediction keeps it).
    ``continuation``: with ``quantise``, the local stage runs first on the loop without the
    rounding, then on the rounded loop from its optimum (the servo rig engine's
    smooth-then-quantised continuation); without ``quantise`` it has no effect.
    ``substeps``: integration substeps per sample while fitting (None: the scenario's).
    ``spread``: σ_c of eq. (1), ``"pooled"`` one per channel over all fitted logs, or
    ``"log"`` one per channel and log (each log's channel weighed by its own spread, so
    that Σ r² is Σ over logs and channels of (1 − fit %)² in units of λ: a log with small
    moves counts as much as one with large ones; the rotary servo's weighting)."""

    channels: Mapping[str, float] | None = None
    residual_level: float = 0.05
    correlation_time: float = 0.05
    quantise: bool = False
    substeps: int | None = None
    continuation: bool = True
    spread: str = "pooled"

    def __post_init__(self) -> None:
        self.channels = channel_weights(self.channels, "Cost.channels")

    def check(self) -> None:
        self.channels = channel_weights(self.channels, "FitOptions.cost.channels")
        _positive(self, "cost", ("residual_level", "correlation_time"))
        if self.spread not in ("pooled", "log"):
            raise ValueError(
                f"FitOptions.cost.spread = {self.spread!r}: 'pooled' (one spread per channel "
                "over all logs) or 'log' (one per channel and log)"
            )


@dataclass
class Shooting:
    """Multiple shooting: ``segment`` length (s; None: each log or window is one segment);
    ``burn_in`` s at the start of each segment left out of the cost; ``estimate_states``:
    with segments, each segment's start state estimated too (offsets to the state read off
    the log: the node states); ``initial``: ``"log"``, every segment, a log's first
    included, starts from the state read off the log, ``"scenario"``, a segment at a log's
    first sample from the scenario's ``[initial]`` state (a synthetic log that starts where
    the scenario does); ``polish``: after the segment fit, refine on whole logs (one
    simulation per log from its start; not for stick-slip runs, whose whole-run cost is
    chaotic); ``derivative_half_width``: samples each side of the local quadratic fit
    for ẏ at segment starts."""

    segment: float | None = None
    burn_in: float = 0.0
    estimate_states: bool = True
    initial: str = "log"
    polish: bool = False
    derivative_half_width: int = 10

    def check(self) -> None:
        if self.initial not in ("log", "scenario"):
            raise ValueError(
                f"FitOptions.shooting.initial = {self.initial!r}: 'log' (segments start "
                "from the logged state) or 'scenario' (a log's first sample "
                "starts from the scenario's [initial] state)"
            )
        if self.segment is not None and not self.segment > 0:
            raise ValueError(
                f"FitOptions.shooting.segment = {self.segment!r} s: give a length > 0 s "
                "(e.g. 2–5 s) or None for whole logs"
            )


@dataclass
class Local:
    """SciPy ``least_squares`` (trf): ``max_nfev`` the budget of evaluations (restarts
    included); ``ftol``, ``xtol`` relative tolerances on the cost and on the step (``ftol``
    None: derived from the cost's own scale, :data:`COST_RESOLUTION` / E[Σ r²]: a step that
    lowers Σ r² by less than 0.01, a tenth of a standard deviation, ends the search);
    ``fd_step`` the finite-difference step in z (a relative step of p); ``restarts``: after
    the local stage converges, at most this many restarts from its optimum with a fresh
    trust region while budget is left, stopping at the first that lowers Σ r² by less than
    ``ftol`` of itself (stick-slip friction makes the cost non-smooth: trf's trust region
    can collapse on a kink far from the optimum; on the two-link split one machine stopped
    at Σ r² 534 against 453 on others, a restart went on to 479 in five). A batch of
    candidates (a Jacobian's columns, a generation) runs as chunks of at most ``max_batch``
    on ``threads`` threads at once (None: the CPU cores this process may use; 1: one
    call)."""

    max_nfev: int = 30
    ftol: float | None = 1e-6
    xtol: float = 1e-6
    fd_step: float = 1e-2
    max_batch: int = 64
    threads: int | None = None
    restarts: int = 2

    def check(self) -> None:
        _positive(self, "local", ("fd_step",))


@dataclass
class GlobalDE:
    """Differential evolution before the local stage (whole generations as one batch):
    ``popsize`` (× the free parameters), ``maxiter`` generations, ``seed``. Given: the
    global stage runs; None (``FitOptions.global_de``): it does not."""

    popsize: int = 6
    maxiter: int = 8
    seed: int = 0


@dataclass
class DelaySearch:
    """The sensor channels' pure delays (whole samples, ``sensors.NAME.delay``) searched
    after the local stage (:mod:`~flexarm.identification.time_domain.delays`: neighbours
    coordinate descent from the scenario's delays, d ± 1 on one channel at a time, compared
    by the cost of eq. (1) at the local optimum; then the local stage again at the chosen
    delays). ``channels``: the sensor channels whose delay is searched (None: every channel
    the fit compares); ``max_delay``: the largest delay tried (samples); ``max_moves``: the
    most moves of one sample, over all channels together."""

    channels: Sequence[str] | None = None
    max_delay: int = 20
    max_moves: int = 10


@dataclass
class SubsetSearch:
    """Differential evolution over a subset of the free coordinates around the local
    optimum, after the delay search (:mod:`~flexarm.identification.time_domain.subset`):
    stick-slip makes the cost jump where a simulated stop lands on another encoder count,
    so the finite-difference Jacobian of the friction levels is unreliable and least squares
    stalls there (the rotary servo's "friction polish"). ``paths``: the free paths searched
    (None: the free joint-friction paths, :func:`~.general.friction_paths`); ``width``: the
    box's half width as a fraction of each coordinate's bound range; ``popsize`` (× the
    paths), ``maxiter`` generations, ``seed``. The other coordinates and the segments' node
    states are held; the local stage runs again from the best point when it lowers the
    cost. None (``FitOptions.subset_search``): not run."""

    paths: Sequence[str] | None = None
    width: float = 0.12
    popsize: int = 8
    maxiter: int = 8
    seed: int = 0

    def check(self) -> None:
        w = self.width
        if not (isinstance(w, numbers.Real) and 0 < w <= 1):
            raise ValueError(
                f"FitOptions.subset_search.width = {w!r}: give the box's half width as a "
                "fraction of each coordinate's bound range, 0 < width <= 1 (e.g. 0.12)"
            )
        for name in ("popsize", "maxiter"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, numbers.Integral) or v < 1:
                raise ValueError(
                    f"FitOptions.subset_search.{name} = {v!r}: give a whole number >= 1"
                )


@dataclass
class Priors:
    """Bounds and priors in log space: p = p0·exp(z), z ∈ [−ln f, ln f] (f =
    ``bound_factor``) or ``bounds`` (path → (lo, hi) in SI, same sign as p0); ``priors``
    path → relative std σ_p of eq. (2) about the template value (log space); ``ties`` path
    → free path: the first is not free but moves with the second by the same factor (two
    channels reading one strain gauge share its gain); ``linear``: paths fitted in linear
    space, p = p0 + s·z (a linear parameter's prior is its std in units of s), besides the
    signed fields (bias, offset) and those starting at 0, which always are
    (:mod:`~flexarm.identification.time_domain.general`); ``corr_warn``: |correlation|
    above which a pair is reported as not separable. Paths may hold ``[*]``."""

    bound_factor: float = 3.0
    bounds: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    priors: Mapping[str, float] = field(default_factory=dict)
    ties: Mapping[str, str] = field(default_factory=dict)
    linear: Sequence[str] = ()
    corr_warn: float = 0.95

    def check(self) -> None:
        if not self.bound_factor > 1:
            raise ValueError(
                f"FitOptions.priors.bound_factor = {self.bound_factor!r}: must be > 1 "
                "(bounds p0/f … p0·f)"
            )
        for p, s in self.priors.items():
            if not (s > 0 and math.isfinite(s)):
                raise ValueError(
                    f"FitOptions.priors.priors[{p!r}] = {s!r}: the relative standard "
                    "deviation must be a finite number > 0 (e.g. 0.3 for ±30 %)"
                )


@dataclass
class ServoRig:
    """The rotary servo engine's own options (its keyword interface,
    :func:`flexarm.identification.time_domain.fit.fit`)."""

    mode: str = "closed_loop"
    friction: bool = True
    #: the global stage's window (s); None: whole logs; "auto": 5 s for a flexible link
    #: whose hub → tip estimate is trusted, whole logs for a rigid arm or an untrusted one
    #: (:func:`~flexarm.identification.time_domain.fit.fit`)
    global_seconds: float | None | str = "auto"
    delay_search: str = "neighbours"
    polish_iter: int = 8
    sessions: Sequence[int] | None = None
    tip_sign: int | None = None
    encoder_counts: int | None = None
    filters: Mapping[str, float] | None = None
    controller: Any = None
    seed: int = 0
    #: the global stage (and the delay starts, local stage, polish after it) from this
    #: many seeds, seed, seed + 1, ...: the lowest cost wins, at that many times the time
    #: (where no estimate ties the sensor delays down, one start's outcome depends on its
    #: seed: :func:`~flexarm.identification.time_domain.fit.fit`)
    global_starts: int | str = "auto"
    #: the tip sensor's delay searched at or above the hub's where nothing else orders
    #: them (``flexarm fit --tip-after-hub/--any-delay-order``)
    tip_after_hub: bool = True
    #: samples between a sample and its command; None: where the declared law best
    #: explains the logged command (``flexarm fit --computation-delay``)
    computation_delay: int | None = None
    #: parameter name (``hub_inertia``, ``coulomb``, ``coulomb[1]`` ...) → (mean in SI,
    #: relative std): eq. (2)'s priors in this engine
    priors: Mapping[str, tuple[float, float]] | None = None
    #: multiple shooting: each log cut into pieces of this many s, each fitted from its own
    #: estimated start state (:func:`~.logs.pieces`); fit % is then the whole logs'
    #: prediction and ``segment_fit_percent`` the pieces'; None: whole logs
    segment: float | None = None
    #: what follows the pipeline's estimates and global stage: ``"servo"``, its own local
    #: stage, continuation and friction polish; ``"general"``, the one general engine
    #: (:func:`~flexarm.identification.time_domain.engine.fit` on the global stage's
    #: scenario: the pipeline's data-derived bounds, one segment per log with its start
    #: state estimated, each log weighed by its own spread, the smooth-then-quantised
    #: continuation, the delay search and the friction re-search; issue #43)
    local: str = "servo"

    def check(self) -> None:
        if self.local not in ("servo", "general"):
            raise ValueError(
                f"FitOptions.servo_rig.local = {self.local!r}: 'servo' (the pipeline's own "
                "local stage) or 'general' (the general engine from its global stage)"
            )

    def keywords(self) -> dict:
        return dict(
            computation_delay=self.computation_delay,
            mode=self.mode,
            friction=self.friction,
            global_seconds=self.global_seconds,
            delay_search=self.delay_search,
            polish_iter=self.polish_iter,
            sessions=self.sessions,
            tip_sign=self.tip_sign,
            encoder_counts=self.encoder_counts,
            filters=dict(self.filters) if self.filters else None,
            controller=self.controller,
            seed=self.seed,
            global_starts=self.global_starts,
            tip_after_hub=self.tip_after_hub,
            priors=dict(self.priors) if self.priors else None,
            segment=self.segment,
        )


BOOTSTRAP_NOISES = ("residuals", "declared")


@dataclass
class Bootstrap:
    """A parametric bootstrap of the fit's uncertainty after the fit
    (:func:`~flexarm.identification.time_domain.bootstrap.bootstrap`): ``n`` replicates of
    the fitted logs simulated by the fitted scenario with fresh noise, each refitted; the
    result's ``std`` and ``correlation`` become the spread of the refits (the HAC ones kept
    in ``stages["hac"]``). ``noise``: ``"residuals"`` (a Gaussian AR(1) series per log and
    channel with the fit's residual std and lag-1 autocorrelation) or ``"declared"`` (the
    scenario's ``sensors.X.noise``, white). ``seed``: the replicates' seeds are
    :func:`flexarm.sim.batch.chunk_seed` ``(seed, k)``."""

    n: int = 20
    seed: int = 0
    noise: str = "residuals"

    def check(self) -> None:
        if isinstance(self.n, bool) or not isinstance(self.n, numbers.Integral) or self.n < 2:
            raise ValueError(
                f"FitOptions.bootstrap.n = {self.n!r}: give a whole number of replicates "
                ">= 2 (e.g. 20; --bootstrap N)"
            )
        if self.noise not in BOOTSTRAP_NOISES:
            raise ValueError(
                f"FitOptions.bootstrap.noise = {self.noise!r}: one of "
                f"{', '.join(map(repr, BOOTSTRAP_NOISES))}"
            )


@dataclass
class Sessions:
    """Several recording sessions of one rig in one fit (issue #47): ``of_log`` gives each
    log's session (0, 1, ...); the mechanics, sensor gains and delays are shared and the
    ``per_session`` paths are fitted once per session: session 0's value at the path
    itself, a later session s's at ``sessions[s].PATH`` in the result
    (:func:`~flexarm.identification.time_domain.result.session_key`). ``per_session`` None:
    the free joint-friction levels (:func:`~.general.friction_paths`), the free signed
    paths (``bias``, ``offset``) and the free paths ``starts`` names. ``starts``: session →
    {path: start value} where a session starts elsewhere than session 0 (e.g. a gauge's
    sign flipped: its gain's start negated; ``flexarm fit --session-start
    1:sensors.tip_deflection.gain=0.655``)."""

    of_log: Sequence[int]
    per_session: Sequence[str] | None = None
    starts: Mapping[int, Mapping[str, float]] | None = None

    @property
    def count(self) -> int:
        return max(self.of_log) + 1 if len(self.of_log) else 1

    def check(self, n_logs: int | None = None) -> None:
        s = list(self.of_log)
        if not s or any(
            isinstance(k, bool) or not isinstance(k, numbers.Integral) or k < 0 for k in s
        ):
            raise ValueError(
                f"FitOptions.sessions.of_log = {s!r}: give each log's session as a whole "
                "number >= 0 (e.g. [0, 0, 1, 1]; --sessions 0,0,1,1)"
            )
        missing = sorted(set(range(max(s) + 1)) - set(s))
        if missing:
            raise ValueError(
                f"FitOptions.sessions.of_log = {s!r}: session(s) {missing} have no log; "
                "number the sessions 0, 1, ... without gaps"
            )
        if n_logs is not None and len(s) != n_logs:
            raise ValueError(
                f"FitOptions.sessions.of_log has {len(s)} entries for {n_logs} logs: give "
                "one session per log"
            )
        for k in self.starts or {}:
            if k not in set(s) or k == 0:
                raise ValueError(
                    f"FitOptions.sessions.starts[{k!r}]: not a later session of the logs "
                    f"(sessions 1..{max(s)}); session 0 starts from the scenario"
                )


def _changed(group, over_base: bool):
    """The (field, value) pairs of ``group`` to set on the resolved options: every field,
    or, over a preset's options (``over_base``), only those changed from the group's
    defaults, so ``Local(max_nfev=60)`` keeps the preset's tolerances."""
    for f in dataclasses.fields(group):
        v = getattr(group, f.name)
        if not over_base:
            yield f.name, v
            continue
        default = (
            f.default
            if f.default is not dataclasses.MISSING
            else f.default_factory()
            if f.default_factory is not dataclasses.MISSING
            else dataclasses.MISSING
        )
        if default is dataclasses.MISSING or v != default:
            yield f.name, v


#: the groups the general engine reads, each always present in resolved options
#: (:meth:`FitOptions.resolved`)
ENGINE_GROUPS = {"cost": Cost, "shooting": Shooting, "local": Local, "priors": Priors}
#: the stages that run only when given (None: off)
OPTIONAL_GROUPS = {"global_de": GlobalDE, "delay_search": DelaySearch}

#: the deprecated flat record's fields (:class:`ScenarioFitOptions`) → (group, field) of
#: :class:`FitOptions` (group "": a field of FitOptions itself); ``global_stage`` is
#: ``global_de`` given or not
#: the groups' fields newer than the deprecated flat record (set through the groups only)
NOT_FLAT = frozenset({"spread"})
FLAT_FIELDS: dict[str, tuple[str, str]] = {
    **{
        f.name: (g, f.name)
        for g, cls in {**ENGINE_GROUPS, "global_de": GlobalDE}.items()
        for f in dataclasses.fields(cls)
        if f.name not in NOT_FLAT
    },
    "windows": ("", "windows"),
    "continuous": ("", "continuous"),
    "period_tolerance": ("", "period_tolerance"),
    "delay_search": ("", "delay_search"),
}


@dataclass
class FitOptions:
    """Options of :func:`flexarm.fit`, grouped (module docstring), read by the general
    engine itself (:func:`~flexarm.identification.time_domain.general.fit_scenario` reads
    ``options.cost.channels``, ``options.shooting.segment``, ``options.local.max_nfev`` ...
    of :meth:`resolved` options). ``None`` groups take the preset's (or the defaults); over a
    preset, a group's fields left at their defaults take the preset's too. ``global_de`` and
    ``delay_search`` None: that stage does not run."""

    cost: Cost | None = None
    shooting: Shooting | None = None
    local: Local | None = None
    global_de: GlobalDE | None = None
    priors: Priors | None = None
    servo_rig: ServoRig | None = None
    #: the sensors' delays searched after the local stage (general engine); None: as given
    delay_search: DelaySearch | None = None
    windows: Sequence[tuple[float, float] | None] | None = None
    predict: bool = True
    #: a folder for the fit's overlay figures (the whole-run prediction with the fitted
    #: values, one PNG a log, ``NN_KEY_fit.png``; the servo rig: its fit figures), listed in
    #: :attr:`FitResult.plots <flexarm.identification.time_domain.result.FitResult.plots>`;
    #: None: no figures
    plots: Any = None
    #: the logs, in order, are consecutive pieces of one run: controller and digital-filter
    #: states carried from log to log (the general engine; whole logs only)
    continuous: bool = False
    #: a log whose clock is off the scenario's period by at most this (relative) is read on
    #: the scenario's grid, with a note (:func:`flexarm.io.logs.on_sample_grid`); beyond it,
    #: one line naming the figure
    period_tolerance: float = 1e-4
    #: a parametric bootstrap after the fit (:class:`Bootstrap`): the result's std and
    #: correlation are the refits' spread; None: the HAC ones
    bootstrap: Bootstrap | None = None
    #: several recording sessions of one rig (:class:`Sessions`): friction and the signed
    #: paths per session, the rest shared; None: one session
    sessions: Sessions | None = None
    #: differential evolution over the friction (or other) coordinates around the local
    #: optimum (:class:`SubsetSearch`); None: not run
    subset_search: SubsetSearch | None = None

    def resolved(self, base: FitOptions | None = None) -> ResolvedOptions:
        """These options with every engine group filled (:class:`ResolvedOptions`, a
        FitOptions whose :data:`ENGINE_GROUPS` are never None: the engine reads
        ``options.<group>.<field>`` without None checks): ``base`` (a preset's
        options, copied) or the defaults, the groups given here overriding them; over a
        ``base`` only the fields changed from their group's defaults override (``_changed``:
        ``Local(max_nfev=60)`` keeps the preset's tolerances). ``global_de`` given over a
        base without one: the global stage runs with this group's settings. ``delay_search``,
        ``windows``, ``servo_rig`` given replace the base's; ``continuous`` True sets it;
        ``predict`` and ``plots`` are these options'. Groups are fresh objects (field values
        shared), so the result can be changed without changing ``self`` or ``base``."""
        over = base is not None
        start = copy.deepcopy(base) if base is not None else FitOptions()
        out = {f.name: getattr(start, f.name) for f in dataclasses.fields(FitOptions)}
        for name, cls in {**ENGINE_GROUPS, "global_de": GlobalDE}.items():
            mine, theirs = getattr(self, name), out[name]
            if theirs is None and (mine is not None or name in ENGINE_GROUPS):
                theirs = cls()
            elif theirs is not None:
                theirs = copy.copy(theirs)  # a fresh object, values shared
            if mine is not None:
                for k, v in _changed(mine, over):
                    setattr(theirs, k, v)
            out[name] = theirs
        if self.delay_search is not None:
            out["delay_search"] = self.delay_search
        if self.servo_rig is not None:
            out["servo_rig"] = self.servo_rig
        if self.bootstrap is not None:
            out["bootstrap"] = self.bootstrap
        if self.sessions is not None:
            out["sessions"] = self.sessions
        if self.subset_search is not None:
            out["subset_search"] = self.subset_search
        if self.windows is not None:
            out["windows"] = list(self.windows)
        if self.continuous:
            out["continuous"] = True
        if not over or self.period_tolerance != FitOptions.period_tolerance:
            out["period_tolerance"] = self.period_tolerance
        out["predict"], out["plots"] = self.predict, self.plots
        return ResolvedOptions(**out)

    def check(self) -> None:
        """One line naming the grouped field (``FitOptions.shooting.segment = -1 s: ...``),
        its value and the fix, for each group given and for the options together."""
        for name in ENGINE_GROUPS:
            g = getattr(self, name)
            if g is not None:
                g.check()
        if self.bootstrap is not None:
            self.bootstrap.check()
        if self.subset_search is not None:
            self.subset_search.check()
        if self.servo_rig is not None:
            self.servo_rig.check()
        if self.sessions is not None:
            self.sessions.check(len(self.windows) if self.windows is not None else None)
        if (
            self.continuous
            and self.windows is not None
            and any(w is not None for w in self.windows)
        ):
            raise ValueError(
                "FitOptions.continuous: consecutive pieces of one run are fitted as "
                "whole logs; leave out windows (FitOptions.windows, --window)"
            )
        pt = self.period_tolerance
        if not (isinstance(pt, numbers.Real) and pt >= 0 and math.isfinite(pt)):
            raise ValueError(
                f"FitOptions.period_tolerance = {pt!r}: give a finite relative tolerance "
                ">= 0 (e.g. 1e-4)"
            )

    @classmethod
    def from_fields(cls, **fields: Any) -> FitOptions:
        """Options from the deprecated flat record's field names (:data:`FLAT_FIELDS`,
        e.g. ``max_nfev=10, segment=3.0``: ``fit-many``'s row options): each name to its
        group, only the groups named are given; ``popsize``, ``maxiter``, ``seed`` set the
        global stage's settings, which runs only with ``global_stage=True``. An unknown name
        is one line naming it and the known ones."""
        unknown = sorted(k for k in fields if k not in FLAT_FIELDS and k != "global_stage")
        if unknown:
            raise ValueError(
                f"fit option {', '.join(map(repr, unknown))}: not an option of the fit; "
                f"options: {', '.join(sorted([*FLAT_FIELDS, 'global_stage']))}"
            )
        global_stage = bool(fields.pop("global_stage", False))
        groups: dict[str, dict[str, Any]] = {}
        top: dict[str, Any] = {}
        for k, v in fields.items():
            g, f = FLAT_FIELDS[k]
            if g:
                groups.setdefault(g, {})[f] = v
            else:
                top[f] = v
        de = groups.pop("global_de", {})
        made = {g: ENGINE_GROUPS[g](**kw) for g, kw in groups.items()}
        return cls(**made, global_de=GlobalDE(**de) if global_stage else None, **top)

    @classmethod
    def from_flat(cls, flat: ScenarioFitOptions) -> FitOptions:
        """The grouped options of a deprecated flat record: every group given (so that
        :meth:`resolved` without a base gives back exactly the record's values); its
        ``global_stage`` is ``global_de`` given or None."""
        return cls.from_fields(
            **{f.name: getattr(flat, f.name) for f in dataclasses.fields(ScenarioFitOptions)}
        )


@dataclass
class ResolvedOptions(FitOptions):
    """:class:`FitOptions` with every engine group present (:meth:`FitOptions.resolved`):
    what the general engine reads (``options.cost``, ``options.shooting``, ``options.local``,
    ``options.priors`` never None; ``global_de`` and ``delay_search`` None: that stage does
    not run)."""

    cost: Cost = field(default_factory=Cost)
    shooting: Shooting = field(default_factory=Shooting)
    local: Local = field(default_factory=Local)
    priors: Priors = field(default_factory=Priors)


def as_fit_options(options: Any, where: str) -> FitOptions:
    """``options`` as :class:`FitOptions`: None → the defaults; a deprecated
    :class:`ScenarioFitOptions` → :meth:`FitOptions.from_flat` with a
    ``DeprecationWarning`` naming ``FitOptions``; anything else one line naming ``where``."""
    if options is None:
        return FitOptions()
    if isinstance(options, FitOptions):
        return options
    if isinstance(options, ScenarioFitOptions):
        import warnings

        warnings.warn(
            f"{where}: ScenarioFitOptions (the flat record) is deprecated: give the grouped "
            "FitOptions (cost=Cost(...), shooting=Shooting(...), local=Local(...), "
            "priors=Priors(...), global_de=GlobalDE(...); FitOptions.from_flat converts)",
            DeprecationWarning,
            stacklevel=3,
        )
        return FitOptions.from_flat(options)
    raise ValueError(
        f"{where}: options = {type(options).__name__} {options!r}: give FitOptions(...) "
        "(flexarm.identification.time_domain.options.FitOptions)"
    )


@dataclass
class PredictOptions:
    """Options of :func:`flexarm.validate` /
    :func:`~flexarm.identification.time_domain.predict.predict`.

    ``channels``: the measured channels compared (None: every logged sensor channel);
    ``windows``: per log (t0, t1) s from its first sample, [t0, t1), or None;
    ``initial``: where each log (window) starts: ``"estimate"`` the state read off the
    log, refined by least squares on the log itself (the model is not refitted), ``"log"``
    as read off the log, ``"rest"`` the logged positions with every rate zero
    (:func:`~flexarm.identification.time_domain.general.predict_scenario`); None
    (default): as the fit that wrote the scenario did, its ``[notes.validate] initial``
    (the general engine's fits: ``"log"``), else ``"estimate"`` (the servo rig's);
    ``estimate_initial`` (deprecated): False is ``initial="log"``; ``continuous``: the
    logs, in order, are consecutive pieces of one run: controller and digital-filter
    states carried from piece to piece (whole logs only); ``controller``: a controller file
    (:class:`~flexarm.specs.scenario.ControllerFile` or the path of its ``.toml``) replacing
    the scenario's controllers, or else a servo-rig text law overriding the logs' declared
    law; ``plots``: a folder for overlay PNGs, ``tag`` their name."""

    channels: Sequence[str] | None = None
    windows: Sequence[tuple[float, float] | None] | None = None
    initial: str | None = None
    estimate_initial: bool | None = None
    continuous: bool = False
    controller: Any = None
    plots: Any = None
    tag: str = "predict"
    #: per log, channel → measurement noise (SI) over the log (window), read by the
    #: controller: the loop's response to it simulated (a bootstrap replicate); None:
    #: noise-free
    noise: Sequence[Mapping[str, Any] | None] | None = None

    def __post_init__(self) -> None:
        if self.estimate_initial is not None:
            import warnings

            warnings.warn(
                "PredictOptions.estimate_initial is deprecated: use initial='estimate' "
                "(default), 'log' or 'rest'",
                DeprecationWarning,
                stacklevel=3,
            )
            if not self.estimate_initial:
                self.initial = "log"


# ------------------------------------------------------ the engine's constants
#: The least change of Σ r² (eqs. (1)–(2)) the fit resolves: Σ r² counts independent misfits
#: in units of their expected size, so Δ(Σ r²) = 1 is a move of one standard deviation of
#: one parameter and 0.01 a tenth of one; a decrease below it is not statistically meaningful
#: (Press et al., Numerical Recipes, §15.5: stop when χ² falls by less than 0.01). With
#: ``Local.ftol`` None, SciPy's relative ftol is it over E[Σ r²]
#: (:meth:`_Engine.expected_cost`): the search stops when a step lowers Σ r² by less than
#: 0.01 · Σ r² / E[Σ r²], i.e. by less than 0.01 in units of the misfit's realised variance
#: (a misfit larger than λ assumes widens the parameters' spread in the same ratio).
COST_RESOLUTION = 0.01


#: where a prediction starts each log (window): :func:`predict_scenario`'s ``initial``
INITIALS = ("estimate", "log", "rest")
#: least-squares evaluations of a prediction's start-state estimate (``initial="estimate"``)
INITIAL_NFEV = 15


# ------------------------------------------------------ the deprecated flat record


@dataclass
class ScenarioFitOptions:
    """Deprecated: the general engine's old flat record, still accepted as input only.
    :func:`flexarm.fit` and
    :func:`~flexarm.identification.time_domain.general.fit_scenario` (and
    ``predict_scenario``) convert it with :meth:`FitOptions.from_flat` and a
    ``DeprecationWarning`` naming :class:`FitOptions`; nothing in flexarm builds one. Each
    field is a field of one of :class:`FitOptions`' groups, documented and checked there
    (:data:`FLAT_FIELDS`: ``segment`` → ``FitOptions.shooting.segment``, ``max_nfev`` →
    ``FitOptions.local.max_nfev``, ``bounds`` → ``FitOptions.priors.bounds``, ...);
    ``global_stage`` is ``FitOptions.global_de`` given, ``popsize``, ``maxiter``, ``seed``
    its fields."""

    channels: Mapping[str, float] | None = None
    bound_factor: float = 3.0
    bounds: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    priors: Mapping[str, float] = field(default_factory=dict)
    segment: float | None = None
    burn_in: float = 0.0
    windows: Sequence[tuple[float, float] | None] | None = None
    residual_level: float = 0.05
    correlation_time: float = 0.05
    max_nfev: int = 30
    fd_step: float = 1e-2
    global_stage: bool = False
    popsize: int = 6
    maxiter: int = 8
    seed: int = 0
    derivative_half_width: int = 10
    corr_warn: float = 0.95
    max_batch: int = 64
    threads: int | None = None
    ftol: float | None = 1e-6
    xtol: float = 1e-6
    polish: bool = False
    estimate_states: bool = True
    quantise: bool = False
    initial: str = "log"
    substeps: int | None = None
    ties: Mapping[str, str] = field(default_factory=dict)
    linear: Sequence[str] = ()
    period_tolerance: float = 1e-4
    continuous: bool = False
    continuation: bool = True
    delay_search: Any = None
    restarts: int = 2
