"""Cheap estimates from the logs, before the expensive closed-loop stages: the link's
clamped frequency, damping and the tip sensor's gain, sign, lag and low-pass from a linear
hub → tip model; the hub channel's delay from an integral equation-error regression of
the hub's equation of motion. They set the search ranges of the closed-loop fit (and are
reported in its JSON), so that the global stage searches where the data point, over
delays of up to ``MAX_DELAY_S`` (real rigs lag by tens of milliseconds at the hub and
several tens more at the tip).

**Hub → tip.** Relative to the hub, the link's tip deflection w (m) obeys

    ẅ + 2 ζ ω_c ẇ + ω_c² w = −L θ̈                                    (1)

(ω_c the hub-clamped frequency: what the link does while the hub moves as measured). The
measured tip d is g w, seen through the tip channel's extra lag of ``lag`` samples behind
the hub channel and a first-order low-pass of f_c Hz:

    d(s) = −g L s² / (s² + 2 ζ ω_c s + ω_c²) · 1 / (s / (2π f_c) + 1) · e^{−s lag T} θ_m(s)

driven by the measured hub angle θ_m. For every lag on a grid the output-error least
squares over (ω_c, ζ, g L, f_c) is solved with the model discretised by zero-order hold
(θ_m is piecewise constant between samples to within its resolution); the best lag wins.
Lag and cutoff trade off (both delay the tip), so the pair is reported together with
the profile of fit % over the lags. Stick-slip does not disturb (1): the hub's motion is
its input, whatever moved it. The search starts from the spectral peak of the whole tip
signals and, where the hub sticks, from the peak of the stuck phases' ringing (the clamped
frequency, :func:`~.guesses.link_frequency`), which the whole signal's peak misses where the
drift or a closed-loop mode dominates (4/27: 0.3 Hz drift against 1.8 Hz ringing).

**Hub delay.** The hub obeys J θ̈ = k_u u − (k_ω + B) θ̇ + (J_l/L)(ω_c² w + 2ζω_c ẇ) − F.
With the true hub θ(t) = θ_m(t + D T), integrated over windows [t_0, t_0 + W] (no second
derivative of a quantised signal is needed):

    θ̇_m(t_1 + D) − θ̇_m(t_0 + D) = a ∫u − b Δθ_m − c ∫sgn θ̇_m + e ∫d_m(· + D + lag)

a = k_u / J, b = (k_ω + B) / J, c = F_c / J. For every D on a grid the linear least
squares gives R²; the best D with physical coefficients (a > 0, b > 0) is the estimate,
trusted when its R² clears ``HUB_R2_MIN`` and beats the profile's median clearly. Rigid
arms with little motion give a flat profile: then the closed-loop stage searches all
delays.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
import scipy.signal
from scipy.optimize import least_squares

from flexarm.io.logs import Log

#: default largest sensor delay searched (s)
MAX_DELAY_S = 0.15
#: an R² of the hub regression below this is not trusted
HUB_R2_MIN = 0.3
#: a tip model with a fit % below this is not trusted
TIP_FIT_MIN = 50.0


@dataclass
class TipModel:
    """The hub → tip model (1): clamped frequency (rad/s), damping ratio, signed sensor
    gain (measured m per m of deflection), lag behind the hub channel (samples), low-pass
    cutoff (Hz), fit % of the measured tip, and fit % by lag."""

    omega_c: float
    zeta: float
    gain: float
    lag: int
    cutoff_hz: float
    fit_percent: float
    profile: dict[int, float] = field(default_factory=dict)

    @property
    def trusted(self) -> bool:
        return bool(np.isfinite(self.fit_percent) and self.fit_percent >= TIP_FIT_MIN)

    def to_dict(self) -> dict:
        d = asdict(self)
        d["trusted"] = self.trusted
        d["profile"] = {int(k): round(float(v), 3) for k, v in self.profile.items()}
        return d


@dataclass
class HubDelay:
    """The hub channel's delay (samples) from the integral regression, its R², the
    profile of R² by delay, whether it is trusted, and the implied J and B (N·m units)."""

    delay: int | None
    r2: float
    trusted: bool
    inertia: float | None
    viscous: float | None
    profile: dict[int, float] = field(default_factory=dict)

    def to_dict(self) -> dict:
        d = asdict(self)
        d["profile"] = {int(k): round(float(v), 4) for k, v in self.profile.items()}
        return d


def _fitpct(y: np.ndarray, yh: np.ndarray) -> float:
    den = np.linalg.norm(y - y.mean())
    return float(100 * (1 - np.linalg.norm(y - yh) / den)) if den > 0 else float("nan")


def _tip_filter(p, dt: float):
    """The model (1)'s ZOH discretisation (b, a) at the parameters p = (ω_c, ζ, g L, f_c)."""
    wc, z, gL, fc = p
    a = 2 * np.pi * fc
    num = [-gL * a, 0.0, 0.0]
    den = np.polymul([1.0, 2 * z * wc, wc * wc], [1.0, a])
    # scipy's return types are inferred from its branches: (num, den, dt)
    tfd: Any = scipy.signal.cont2discrete((num, den), dt, method="zoh")
    b, aa, _ = tfd
    return np.ravel(b), aa


def _tip_response(p, th: np.ndarray, lag: int, dt: float, filt=None) -> np.ndarray:
    """The model (1)'s tip response to the hub angle ``th`` delayed by ``lag`` samples;
    ``filt``: :func:`_tip_filter` of p where it is already computed (one per residual
    evaluation for all logs: the discretisation was 70 % of a log's response time)."""
    b, aa = _tip_filter(p, dt) if filt is None else filt
    x = np.concatenate([np.full(lag, th[0]), th[: len(th) - lag]]) - th[0]
    y: Any = scipy.signal.lfilter(b, aa, x)
    return y


def tip_model(
    logs: list[Log], length: float, *, max_lag: int | None = None, omega_guess: float | None = None
) -> TipModel | None:
    """The hub → tip model (1) fitted to every log with both channels (see the module
    docstring); None when no log has a moving tip channel."""
    pairs = [
        (g.columns["motor_angle"], g.columns["tip_deflection"], g.dt)
        for g in logs
        if "motor_angle" in g.columns and "tip_deflection" in g.outputs
    ]
    if not pairs:
        return None
    dt = pairs[0][2]
    max_lag = int(round(MAX_DELAY_S / dt)) if max_lag is None else int(max_lag)
    skip = max_lag + 10
    pairs = [(th, d) for th, d, _ in pairs if len(th) > skip + 50]
    if not pairs:
        return None
    # starting frequency: the spectral peak of the tip signals (2-60 rad/s band)
    if omega_guess is None:
        f, P = scipy.signal.welch(
            np.concatenate([d - d.mean() for _, d in pairs]),
            1 / dt,
            nperseg=min(4096, min(len(d) for _, d in pairs)),
        )
        band = (f > 0.3) & (f < 10)
        omega_guess = 2 * np.pi * float(f[band][np.argmax(P[band])]) if band.any() else 10.0
    # a second start: the link's ringing while the hub is stuck (its clamped frequency),
    # which the whole signal's peak misses where a closed-loop mode or the drift dominates
    from flexarm.identification.time_domain import guesses

    stuck, how = guesses.link_frequency(logs)
    omegas = [omega_guess] + (
        [float(stuck)]
        if how == "stuck" and stuck and 0.2 * omega_guess < stuck < 5 * omega_guess
        else []
    )

    def res(p, lag):
        filt = _tip_filter(p, dt)
        return np.concatenate(
            [(_tip_response(p, th, lag, dt, filt) - d)[skip:] / np.std(d[skip:]) for th, d in pairs]
        )

    def solve(lag, p0):
        lo, hi = (
            [0.2 * omega_guess, 0.0, -50 * length, 0.3],
            [5 * omega_guess, 0.7, 50 * length, 0.45 / dt],
        )
        p0 = np.clip(p0, np.add(lo, 1e-9), np.subtract(hi, 1e-9))
        r = least_squares(res, p0, args=(lag,), bounds=(lo, hi), x_scale="jac", max_nfev=60)
        return r.x, float(np.sum(r.fun**2))

    # every lag from the previous lag's optimum; the first from both gauge signs
    best = None
    step = max(1, int(round(0.005 / dt)))
    profile = {}
    p_prev = None
    for lag in range(0, max_lag + 1, step):
        starts = [p_prev] if p_prev is not None else []
        if p_prev is None:
            for w0 in omegas:
                for s in (1.0, -1.0):
                    starts.append(np.array([w0, 0.03, s * 0.2 * length, 20.0]))
        cand = [solve(lag, p0) for p0 in starts]
        p, c = min(cand, key=lambda t: t[1])
        p_prev = p
        profile[lag] = c
        if best is None or c < best[2]:
            best = (lag, p, c)
    # refine the lag around the best coarse one
    assert best is not None  # lag 0 at least was tried
    lag0, p0, c0 = best
    for lag in range(max(0, lag0 - step + 1), min(max_lag, lag0 + step - 1) + 1):
        if lag in profile:
            continue
        p, c = solve(lag, p0)
        profile[lag] = c
        if c < best[2]:
            best = (lag, p, c)
    lag, p, _ = best
    fits = [_fitpct(d[skip:], _tip_response(p, th, lag, dt)[skip:]) for th, d in pairs]
    n = sum(len(d) - skip for _, d in pairs)
    prof_fit = {k: float(100 * (1 - np.sqrt(v / n))) for k, v in sorted(profile.items())}
    return TipModel(
        float(p[0]),
        float(p[1]),
        float(p[2] / length),
        int(lag),
        float(p[3]),
        float(np.mean(fits)),
        prof_fit,
    )


def hub_delay(
    logs: list[Log],
    k_u: float,
    k_omega: float,
    *,
    max_delay: int | None = None,
    tip: TipModel | None = None,
    window: float = 0.04,
) -> HubDelay:
    """The hub channel's delay from the integral regression (module docstring)."""
    usable = [g for g in logs if "motor_angle" in g.columns and "voltage" in g.columns]
    if not usable:
        return HubDelay(None, float("nan"), False, None, None, {})
    dt = usable[0].dt
    max_delay = int(round(MAX_DELAY_S / dt)) if max_delay is None else int(max_delay)
    W = max(int(round(window / dt)), 5)
    use_tip = tip is not None and tip.trusted
    tip_lag = tip.lag if tip is not None and use_tip else 0
    # per log, once: hub angle and rate, the integrals of the command, of the rate's sign
    # and of the tip deflection (None without a tip channel)
    series = []
    for g in usable:
        th = g.columns["motor_angle"]
        N = len(th)
        w = np.gradient(th, dt)
        Iu = np.concatenate([[0.0], np.cumsum(g.columns["voltage"]) * dt])[:N]
        wmax = np.percentile(np.abs(w), 99)
        sg = np.cumsum(np.sign(w) * (np.abs(w) > 0.05 * wmax)) * dt
        Id = (
            np.cumsum(g.columns["tip_deflection"]) * dt
            if use_tip and "tip_deflection" in g.outputs
            else None
        )
        series.append((th, w, Iu, sg, Id))
    profile, coef = {}, {}
    for D in range(0, max_delay + 1):
        ys, Xs = [], []
        for th, w, Iu, sg, Id in series:
            N = len(th)
            k0 = np.arange(5, N - D - W - tip_lag - 5, max(W // 4, 1))
            if k0.size < 10:
                continue
            k1 = k0 + W
            ys.append(w[k1 + D] - w[k0 + D])
            cols = [Iu[k1] - Iu[k0], -(th[k1 + D] - th[k0 + D]), -(sg[k1 + D] - sg[k0 + D])]
            if Id is not None:
                cols.append(Id[k1 + D + tip_lag] - Id[k0 + D + tip_lag])
            elif use_tip:
                cols.append(np.zeros(k0.size))
            Xs.append(np.column_stack(cols))
        if not ys:
            break
        y, X = np.concatenate(ys), np.concatenate(Xs)
        c, *_ = np.linalg.lstsq(X, y, rcond=None)
        sst = float(np.sum((y - y.mean()) ** 2))
        r2 = 1 - float(np.sum((y - X @ c) ** 2)) / sst if sst > 0 else float("nan")
        profile[D] = r2
        coef[D] = c
    ok = {D: r for D, r in profile.items() if coef[D][0] > 0 and coef[D][1] > 0}
    if not ok:
        return HubDelay(None, float("nan"), False, None, None, profile)
    D = max(ok, key=lambda d: ok[d])
    r2 = ok[D]
    med = float(np.median(list(profile.values())))
    trusted = bool(r2 >= HUB_R2_MIN and r2 - med > 0.1 * max(r2, 1e-9))
    a, b = coef[D][0], coef[D][1]
    J = k_u / a
    return HubDelay(int(D), float(r2), trusted, float(J), float(b * J - k_omega), profile)


def link_frequency_estimates(logs: list[Log], tip: TipModel | None) -> dict:
    """Every estimate of the clamped link frequency (rad/s) the data give: the hub → tip
    model, the spectral peak while the hub is stuck (the link rings at its clamped
    frequency then), the spectral peak of the whole tip signal (a closed-loop mode,
    usually above the clamped one), and their agreement."""
    from flexarm.identification.time_domain import guesses

    out: dict = {}
    if tip is not None:
        out["hub_to_tip_model"] = {
            "value": tip.omega_c,
            "fit_percent": tip.fit_percent,
            "trusted": tip.trusted,
        }
    wc, how = guesses.link_frequency(logs)
    if wc:
        out["spectral_peak_" + how] = {"value": float(wc)}
    b = frequency_bounds(out)
    out["bounds"] = None if b is None else [float(b[0]), float(b[1])]
    return out


def frequency_bounds(est: dict, widen: float = 1.35) -> tuple[float, float] | None:
    """Search bounds for ω_c covering every trusted estimate, ±``widen``."""
    vals = []
    model = est.get("hub_to_tip_model", {})
    if model.get("trusted"):
        vals.append(model["value"])
    stuck = est.get("spectral_peak_stuck", {}).get("value")
    # the stuck-hub peak joins when it agrees with the model (a short stuck interval
    # holds a fraction of a period, and its peak is then the drift's, far below)
    if stuck and (not vals or 1 / widen < stuck / vals[0] < widen):
        vals.append(stuck)
    if not vals:
        return None
    return min(vals) / widen, max(vals) * widen


#: rest windows of the cable-spring estimate (s), and the most a joint angle may move in one
#: (rad, or 3 encoder counts where that is more)
REST_WINDOW_S = 0.5
REST_ANGLE_RANGE = 2e-4
#: a rest window's gauge may move by at most this fraction of the gauge's spread in its log
REST_GAUGE_RANGE = 0.1
#: an estimated cable spring is kept when its slope is this many standard deviations from 0
CABLE_T_MIN = 3.0
#: ... and when it moves the gauge at rest, over the angles held, by this fraction of the
#: gauge's spread over the logs at least (an exact model's round-off slope is no spring)
CABLE_RESOLVED = 0.1


@dataclass
class CableSpring:
    """The cable-spring estimate of one joint (:func:`cable_springs`): the static gauge
    slope (reading per rad of the joint), its standard deviation, the holds it is read
    from, k_c (N·m/rad; None: not estimated) and why not."""

    joint: int
    gauge: str | None
    angle: str | None
    slope: float | None = None
    slope_std: float | None = None
    holds: int = 0
    stiffness: float | None = None
    reason: str = ""

    def to_dict(self) -> dict:
        return asdict(self)


def _rest_holds(log: Log, angle_names: list[str], quanta: list[float], gauge: str) -> list:
    """(mean joint angle of ``angle_names[0]``, mean gauge reading) of each hold: runs of
    consecutive rest windows (every joint angle within max(3 counts, REST_ANGLE_RANGE),
    the gauge within REST_GAUGE_RANGE of its spread)."""
    if log.dt is None or any(n not in log.signals for n in angle_names + [gauge]):
        return []
    n = max(3, int(round(REST_WINDOW_S / log.dt)))
    g = np.asarray(log.signals[gauge], float)
    spread = float(np.nanstd(g))
    if not spread > 0:
        return []
    angles = [np.asarray(log.signals[a], float) for a in angle_names]
    still_range = [max(3 * q, REST_ANGLE_RANGE) for q in quanta]
    holds, cur = [], []
    for k in range(0, g.size - n + 1, n):
        sl = slice(k, k + n)
        still = (
            all(np.ptp(a[sl]) <= r for a, r in zip(angles, still_range, strict=True))
            and np.ptp(g[sl]) <= REST_GAUGE_RANGE * spread
        )
        if still:
            cur.append((float(np.mean(angles[0][sl])), float(np.mean(g[sl]))))
        elif cur:
            holds.append(tuple(np.mean(cur, axis=0)))
            cur = []
    if cur:
        holds.append(tuple(np.mean(cur, axis=0)))
    return holds


def cable_springs(scenario: Any, logs: list[Log]) -> list[CableSpring]:
    """The joints' cable springs (:class:`flexarm.specs.multilink.Joint`,
    ``cable_stiffness``) from the rests in the logs, for a multi-link arm with torsional
    links and a strain gauge per link.

    At rest (every joint still, the links not ringing) a torsional link i on the spring K_i
    under a cable spring k_c,i stands at α_i = −k_c,i θ_i / (K_i + k_c,i); its gauge, gain
    g_i, reads y_i = g_i α_i + c_i (c_i the logger's zero). Over the holds of all logs (runs
    of rest windows of ``REST_WINDOW_S``, one point each), the least-squares line
    y = c + s θ gives s and its standard deviation; then with σ = s / g_i

        k_c,i = −σ K_i / (1 + σ)                                                   (1)

    kept where s < 0 (a restoring spring) at ``CABLE_T_MIN`` standard deviations or more,
    moving the gauge over the angles held by ``CABLE_RESOLVED`` of its spread or more, from
    3 holds or more at 2 joint angles or more; otherwise ``stiffness`` None and
    ``reason`` says why. K_i and g_i are the scenario's (the data sheet's): the fit refines
    k_c with them. ../shared/data/two-link-rig: the shoulder gauge reads −2.26 ± 0.05 mrad
    per rad of the shoulder over the ten holds of the split's fitted part (−2.28 ± 0.16 over
    the held-out part's fourteen); the elbow gauge's slope is positive (no spring)."""
    arm = scenario.arm
    out: list[CableSpring] = []
    if getattr(arm, "kind", None) != "multi_link":
        return out
    sensors = scenario.sensors or {}

    def reading(signal: str, kinds: tuple) -> tuple[str | None, Any]:
        for name, s in sensors.items():
            if (s.signal or name) == signal and (s.filter is None or s.filter.kind in kinds):
                return name, s
        return None, None

    angles = [reading(f"theta_{i + 1}", ()) for i in range(len(arm.links))]
    for i, lk in enumerate(arm.links):
        gname, gs = reading(f"deflection_angle_{i + 1}", ("lowpass2",))
        aname = angles[i][0]
        rec = CableSpring(joint=i, gauge=gname, angle=aname)
        out.append(rec)
        if lk.model != "torsional" or gs is None or gname is None or aname is None:
            rec.reason = "needs a torsional link, its gauge and its joint angle as channels"
            continue
        if any(a[0] is None for a in angles):
            rec.reason = "needs every joint angle as a channel (to find the rests)"
            continue
        names = [aname] + [str(a[0]) for j, a in enumerate(angles) if j != i]
        quanta = [float(sensors[n].quantum or 0.0) for n in names]
        holds = [h for log in logs for h in _rest_holds(log, names, quanta, gname)]
        rec.holds = len(holds)
        th = np.array([h[0] for h in holds])
        y = np.array([h[1] for h in holds])
        if len(holds) < 3 or np.ptp(th) < 0.05:
            rec.reason = (
                f"{len(holds)} rests at joint angles spanning "
                f"{float(np.ptp(th)) if th.size else 0.0:.3g} rad: too few to read a slope"
            )
            continue
        X = np.c_[np.ones_like(th), th]
        coef, *_ = np.linalg.lstsq(X, y, rcond=None)
        r = y - X @ coef
        s2 = float(r @ r) / max(1, len(y) - 2)
        sd = float(np.sqrt(s2 / float(np.sum((th - th.mean()) ** 2))))
        rec.slope, rec.slope_std = float(coef[1]), sd
        if not (coef[1] < 0 and abs(coef[1]) >= CABLE_T_MIN * sd):
            rec.reason = (
                f"slope {coef[1]:.3g} ± {sd:.2g} per rad: not a restoring spring at "
                f"{CABLE_T_MIN:g} standard deviations"
            )
            continue
        spread = float(
            np.nanstd(
                np.concatenate(
                    [np.asarray(g.signals[gname], float) for g in logs if gname in g.signals]
                )
            )
        )
        if abs(coef[1]) * float(np.ptp(th)) < CABLE_RESOLVED * spread:
            rec.reason = (
                f"slope {coef[1]:.3g} per rad moves the gauge at rest by less than "
                f"{CABLE_RESOLVED:g} of its spread over the logs: nothing to fit"
            )
            continue
        sig = float(coef[1]) / float(gs.gain)
        rec.stiffness = -sig * float(lk.torsional_stiffness) / (1.0 + sig)
    return out
