"""Physically derived guesses and bounds from the logs themselves.

* Stuck intervals: the measured hub angle does not change (or, where those ranges are too
  short to hold the link's ringing, stays within one encoder step: a stuck hub dithers
  between two counts) for >= ``min_stuck`` s.
* Link frequency ω_c: peak of the summed periodograms of the detrended tip deflection over
  the stuck intervals (the link rings at its hub-clamped frequency while the hub sticks);
  without stuck intervals, of the whole tip signal.
* Tip gain and sign: the link obeys ẅ + 2ζω_c ẇ + ω_c² w = −L θ̈, so the measured
  d ≈ g · H(s)(−L θ̈) with H = 1/(s² + 2ζω_c s + ω_c²); g by least squares of d on the
  filtered hub acceleration (θ̈ from the encoder by double differences: H is a strong
  low-pass, so quantisation noise hardly matters).
* Hub inertia: after a reference step the hub starts with J θ̈ ≈ k_u u − F (the link has
  not yet reacted); θ̈ from a parabola fitted to the first 25 ms of motion, u the logged
  (or replayed) command: J ≈ k_u ū / θ̈ (an upper-biased estimate: friction slows it).
* Friction: a stuck hub at rest with a settled link holds k_u u + τ_bias within ±F_s, so
  F_s >= max |k_u u| over the ends of stuck intervals (the steady-state errors).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.signal

from flexarm.io.logs import Log


def controller_command(log: Log) -> np.ndarray:
    """The command the log's controller computed (replayed on the logged signals), or the
    logged voltage when present."""
    if "voltage" in log.columns:
        return log.columns["voltage"]
    c = log.controller
    th = log.columns.get("motor_angle", np.zeros(len(log)))
    d = log.columns.get("tip_deflection", np.zeros(len(log)))
    T = log.dt
    tau = c.rate_time_constant if c.rate == "filtered" else 0.0
    a, b = tau / (tau + T), 1.0 / (tau + T)
    dth = scipy.signal.lfilter([b], [1.0, -a], np.diff(th, prepend=th[0]))
    dd = scipy.signal.lfilter([b], [1.0, -a], np.diff(d, prepend=d[0]))
    return c.k1 * (log.columns["reference"] - th) - c.k2 * d - c.k3 * dth - c.k4 * dd


def stuck_intervals(
    log: Log, min_stuck: float = 0.25, dither: bool = False, counts: int = 1
) -> list[tuple[int, int]]:
    """Index ranges [i0, i1) where the measured hub angle stays constant (no change above
    q/4 from one sample to the next, q the encoder's or converter's step) or, with
    ``dither``, within one step: max − min ≤ q over the range. A stuck hub whose angle lies
    near a count boundary dithers between two adjacent counts (vibration, the ringing link's
    torque), so a range that stays exactly constant would cut a stuck phase into pieces
    shorter than one period of the link (on a rig with heavy gear friction, 4/27: stuck
    phases of 1-3 s cut into 0.26 s pieces, whose spectral peak was the drift's at 0.3 Hz
    instead of the link's 1.8 Hz). The link-frequency
    guess uses ``dither``; the friction guess and the rest reading keep the constant
    ranges (with ``dither`` the synthetic open-loop acceptance fit moved, ζ −6 %).
    ``counts``: with ``dither``, the range may span this many steps (max − min ≤ counts q)."""
    th = log.columns.get("motor_angle")
    if th is None:
        return []
    q = max(np.median(np.abs(np.diff(th)[np.diff(th) != 0])) if np.any(np.diff(th)) else 0, 0)
    n_min = int(min_stuck / log.dt)
    out, k = [], 0
    if dither and q > 0:
        th = np.asarray(th, float)
        n = len(th)
        while k < n - 1:
            lo = hi = th[k]
            j = k + 1
            while j < n:
                lo, hi = min(lo, th[j]), max(hi, th[j])
                if hi - lo > (counts + 0.01) * q:
                    break
                j += 1
            if j - k > n_min:
                out.append((k, j))
                k = j
            else:
                k += 1
        return out
    still = np.abs(np.diff(th)) <= 0.25 * q if q > 0 else np.diff(th) == 0
    n = len(still)
    while k < n:
        if still[k]:
            j = k
            while j < n and still[j]:
                j += 1
            if j - k >= n_min:
                out.append((k + 1, j + 1))
            k = j
        else:
            k += 1
    return out


def tip_rest_reading(log: Log, settle: float = 0.5) -> tuple[float, float] | None:
    """What the tip sensor reads with the link at rest: the median of tip_deflection over
    the second halves of the stuck intervals at least ``2 settle`` s long (the hub stuck,
    the ringing decayed), and its scale, the spread of the whole signal (its 1–99 %
    percentile range). A link free at its tip rests at zero deflection (horizontal arm),
    so a rest reading away from zero is a sensor offset (an unbalanced bridge), which the
    model does not have. None when the log has no such interval."""
    d = log.columns.get("tip_deflection")
    if d is None:
        return None
    rest = [d[(i0 + i1) // 2 : i1] for i0, i1 in stuck_intervals(log, 2 * settle)]
    if not rest:
        return None
    lo, hi = np.percentile(d, [1, 99])
    return float(np.median(np.concatenate(rest))), float(hi - lo)


def link_frequency(logs: list[Log], fmin: float = 0.3, fmax: float = 60.0, *, dither: bool = False):
    """(ω_c estimate in rad/s, how: 'stuck' or 'whole') from the tip deflection spectra.

    A stuck intervals' peak counts only where the longest interval holds at least
    :data:`MIN_PERIODS` periods of it: a periodogram of pieces shorter than a period peaks
    at the drift, not at the ringing. Where the hub's constant ranges are that short, the
    stuck hub dithers between two counts and cuts its stuck phases into pieces (4/27:
    1-3 s stuck phases cut into 0.26 s pieces, whose peak was the drift's 0.3 Hz instead of
    the link's 1.8 Hz), so the intervals are taken again within one count (``dither``,
    :func:`stuck_intervals`); where those do not hold the peak either, the whole signal's
    peak is used."""
    tips = [
        (log, d)
        for log in logs
        if (d := log.columns.get("tip_deflection")) is not None and np.ptp(d) > 0
    ]
    if not tips:
        return None, "none"
    for dith in (True,) if dither else (False, True):
        segs = [
            (scipy.signal.detrend(d[i0:i1]), log.dt)
            for log, d in tips
            for i0, i1 in stuck_intervals(log, dither=dith)
        ]
        if not segs:
            break
        wc = _peak(segs, fmin, fmax)
        if max(len(s) for s, _ in segs) * segs[0][1] * wc / (2 * np.pi) >= MIN_PERIODS:
            return wc, "stuck"
    return _peak([(scipy.signal.detrend(d), log.dt) for log, d in tips], fmin, fmax), "whole"


#: fewest periods of the ringing the longest stuck interval must hold for its peak to count
MIN_PERIODS = 2.0


def _peak(segs, fmin: float, fmax: float) -> float:
    """The frequency (rad/s) of the peak of the summed Hann-windowed periodograms of
    ``segs`` ((signal, dt) pairs) in [fmin, fmax] Hz (and below 0.4 / dt)."""
    T = segs[0][1]
    nfft = 1 << int(np.ceil(np.log2(max(16384, max(len(s) for s, _ in segs) * 4))))
    f = np.fft.rfftfreq(nfft, T)
    P = np.zeros_like(f)
    for s, _ in segs:
        P += np.abs(np.fft.rfft(s * np.hanning(len(s)), nfft)) ** 2
    band = (f >= fmin) & (f <= min(fmax, 0.4 / T))
    k = np.argmax(np.where(band, P, 0))
    return float(2 * np.pi * f[k])


def tip_gain(logs: list[Log], wc: float, length: float, zeta: float = 0.03):
    """(g estimate with sign, R²) from d ≈ g H(s)(−L θ̈)."""
    num = den = 0.0
    ss = 0.0
    for log in logs:
        d = log.columns.get("tip_deflection")
        th = log.columns.get("motor_angle")
        if d is None or th is None or np.ptp(d) == 0:
            continue
        T = log.dt
        acc = np.gradient(np.gradient(th, T), T)
        # (num, den, dt) and y alone here: scipy's return types are inferred from its branches
        sysd: Any = scipy.signal.cont2discrete(([1.0], [1.0, 2 * zeta * wc, wc**2]), T, "bilinear")
        x: Any = scipy.signal.lfilter(np.ravel(sysd[0]), sysd[1], -length * acc)
        x, dd = x - x.mean(), d - d.mean()
        num += x @ dd
        den += x @ x
        ss += dd @ dd
    if den == 0 or ss == 0:
        return None, 0.0
    g = num / den
    return g, (num * num / den) / ss


def session_signs(
    logs: list[Log], sessions: list[int], wc: float | None, length: float
) -> tuple[list[int], list[dict]]:
    """Each session's tip-gauge sign relative to session 0's (σ_0 = +1), from the signed
    gauge estimate of :func:`tip_gain` on the session's own logs, d ≈ g H(s)(−L θ̈): σ_s =
    sign(g_s g_0), which maximises the sessions' joint R², (Σ σ_s n_s)² / (Σ d_s Σ y_s)
    with n_s, d_s, y_s the sums of :func:`tip_gain` per session (a gauge re-wired or
    re-calibrated between days, as the rotary rig's 4/27 and 5/2 sessions: −0.33 and
    +0.57 m/m estimated). A session whose estimate explains little (R² < :data:`SIGN_R2`)
    keeps +1.
    Returns (σ per session, per-session ``{"gain", "r2"}``)."""
    n = max(sessions) + 1 if sessions else 1
    w = wc if wc else 2 * np.pi * 1.8
    est = []
    for s in range(n):
        g, r2 = tip_gain([lg for lg, k in zip(logs, sessions, strict=True) if k == s], w, length)
        est.append({"gain": None if g is None else float(g), "r2": float(r2)})
    g0 = est[0]["gain"] if est and est[0]["r2"] >= SIGN_R2 else None
    signs = [1] * n
    for s in range(1, n):
        gs = est[s]["gain"]
        if g0 is not None and gs is not None and est[s]["r2"] >= SIGN_R2 and gs * g0 < 0:
            signs[s] = -1
    return signs, est


#: the least R² of a session's gauge estimate (and of session 0's) that decides its sign:
#: below it the estimate's sign is not trusted and the session keeps session 0's (the
#: 4/27 and 5/2 sessions' estimates explain 44 % and 52 % of their tips)
SIGN_R2 = 0.1


def hub_inertia(logs: list[Log], k_u: float, window: float = 0.025):
    """Median of J ≈ k_u ū / θ̈ over the reference steps (None when no step is usable)."""
    est = []
    for log in logs:
        th = log.columns.get("motor_angle")
        if th is None or log.controller is None and "voltage" not in log.columns:
            continue
        u = controller_command(log)
        r = log.columns["reference"]
        T = log.dt
        steps = np.nonzero(np.abs(np.diff(r)) > 1e-9)[0] + 1
        n = max(int(window / T), 5)
        for s in steps:
            moved = np.nonzero(np.abs(th[s : s + 200] - th[s]) > 0)[0]
            if not moved.size:
                continue
            k0 = s + max(int(moved[0]) - 1, 0)
            if k0 + n >= len(th):
                continue
            t = np.arange(n) * T
            A = np.column_stack([np.ones(n), t, 0.5 * t * t])
            c = np.linalg.lstsq(A, th[k0 : k0 + n], rcond=None)[0]
            ubar = np.mean(u[k0 : k0 + n])
            if c[2] * ubar > 0:
                est.append(k_u * ubar / c[2])
    return float(np.median(est)) if est else None


def stick_torque(logs: list[Log], k_u: float) -> float | None:
    """Largest |k_u u| held by a stuck, settled hub (N·m), or None."""
    vals = []
    for log in logs:
        if log.controller is None and "voltage" not in log.columns:
            continue
        u = controller_command(log)
        for i0, i1 in stuck_intervals(log, 0.2):
            k = slice(max(i1 - int(0.05 / log.dt), i0), i1)
            vals.append(abs(k_u * float(np.median(u[k]))))
    return max(vals) if vals else None


def initial_tip(log: Log, wc: float, zeta: float = 0.03, max_periods: float = 1.5):
    """Damped sinusoid d(t) = e^{−σt}(a cos ω t + b sin ω t) fitted to the measured tip
    deflection before the first reference change (at most 1.5 periods): (a, b, σ, ω)."""
    d = log.columns.get("tip_deflection")
    if d is None or np.ptp(d) == 0:
        return (0.0, 0.0, 0.0, wc)
    r = log.columns["reference"]
    T = log.dt
    ch = np.nonzero(np.abs(np.diff(r)) > 1e-9)[0]
    n = int(max_periods * 2 * np.pi / wc / T)
    if ch.size:
        n = min(n, int(ch[0]) + 1)
    n = max(n, 8)
    wd = wc * np.sqrt(max(1 - zeta**2, 1e-6))
    s = zeta * wc
    t = np.arange(n) * T
    A = np.column_stack([np.exp(-s * t) * np.cos(wd * t), np.exp(-s * t) * np.sin(wd * t)])
    a, b = np.linalg.lstsq(A, d[:n], rcond=None)[0]
    return (float(a), float(b), float(s), float(wd))


def initial_hub(log: Log, n: int = 20, k: int = 0):
    """(θ0, ω0) at t = 0 when the hub channel is delayed by ``k`` samples: a parabola
    through samples k ... k + n − 1 of the measured hub angle (a line would read a hub
    that starts from rest and accelerates, e.g. pushed by a ringing link, as already
    moving at t = 0; the fit's local stage refines both)."""
    th = log.columns.get("motor_angle")
    if th is None:
        return 0.0, 0.0
    th = np.asarray(th[k : k + n], float)
    t = np.arange(len(th)) * log.dt
    if len(th) < 3 or np.ptp(th) == 0:
        return float(th[0]) if len(th) else 0.0, 0.0
    c = np.polyfit(t, th, 2)
    return float(c[2]), float(c[1])


def initial_tip_at(log: Log, k: int, n: int = 21, cutoff: float = 0.0) -> tuple[float, float]:
    """Tip deflection and rate (measured units, g w and g ẇ) at t = 0 when the tip channel
    is delayed by ``k`` samples: a parabola g w(t) = a + b t + c t²/2 fitted to samples
    k ... k + n − 1. With a known first-order sensor low-pass of ``cutoff`` Hz (ω = 2π f_c)
    the samples are the filter's output y, started at y(0) = g w(0) as the simulators
    start it, so the parabola is fitted through the filter: y = a + b (t − (1 − e^{−ωt})/ω)
    + c (t²/2 − t/ω + (1 − e^{−ωt})/ω²); a parabola through y itself would read the
    filter's lag as the link's state (y's rate is 0 at t = 0 whatever ẇ(0) is)."""
    d = log.columns.get("tip_deflection")
    if d is None or np.ptp(d) == 0:
        return (0.0, 0.0)
    t = np.arange(n) * log.dt
    y = np.asarray(d[k : k + n], float)
    t = t[: len(y)]
    if cutoff > 0:
        w = 2 * np.pi * cutoff
        e = -np.expm1(-w * t) / w  # (1 − e^{−ωt})/ω, exact for small ωt
        A = np.column_stack([np.ones_like(t), t - e, 0.5 * t * t - t / w + e / w])
    else:
        c = np.polyfit(t, y, 2)
        return (float(c[2]), float(c[1]))
    c = np.linalg.lstsq(A, y, rcond=None)[0]
    return (float(c[0]), float(c[1]))


#: shortest stuck phase (s) whose ringing frequency counts for :func:`pushed_ringing`
PUSH_MIN_STUCK = 0.8
#: smallest rise of the ringing frequency (pushed over light) that :func:`pushed_ringing`
#: takes for a stiffening: a phase of 0.8 s holds about 4 periods at 1.8 Hz, whose
#: mean period between zero crossings is good to about 1 %
PUSH_MIN_RISE = 1.03


def stuck_ringing(log: Log, min_stuck: float = PUSH_MIN_STUCK) -> list[tuple[float, float]]:
    """(mean command, ringing frequency Hz) of each stuck phase of ``log`` at least
    ``min_stuck`` s long (:func:`stuck_intervals` within three encoder steps: a hub pushed
    against stuck gears creeps by a count or two while the link rings): the tip's mean
    period between upward zero crossings of the 25-sample moving average of its detrended
    deflection; phases with fewer than three such crossings are left out."""
    d = log.columns.get("tip_deflection")
    if d is None or np.ptp(d) == 0 or (log.controller is None and "voltage" not in log.columns):
        return []
    u = controller_command(log)
    out = []
    for i0, i1 in stuck_intervals(log, min_stuck, dither=True, counts=3):
        x = np.convolve(scipy.signal.detrend(d[i0:i1]), np.ones(25) / 25, mode="valid")
        up = np.nonzero((x[:-1] < 0) & (x[1:] >= 0))[0]
        if up.size >= 3:
            out.append(
                (float(np.mean(u[i0:i1])), float((up.size - 1) / ((up[-1] - up[0]) * log.dt)))
            )
    return out


def pushed_ringing(logs: list[Log], k_u: float) -> dict | None:
    """Where a stuck gear train rings faster while the motor pushes it: the stiffening
    s = (f_pushed / f_light)² − 1 of the link's clamped stiffness and the push threshold
    (N·m of motor torque k_u |u|) where it starts and where it is full, from the stuck
    phases' ringing (:func:`stuck_ringing`). The phases sorted by |u| are split where every
    phase above rings faster than every phase below and the medians differ by at least
    :data:`PUSH_MIN_RISE` (the widest such gap in |u|); the stiffening starts at the
    largest light push and is full at the smallest pushed one, linear between (the logs say
    nothing there; a step in the middle turned a model whose hub stopped 20 mrad short, its
    controller pushing 0.22 V instead of 0.10 V, from tip 55 % to 11 %). None where no such
    split exists (no stuck phases, or their frequencies do not rise with the push).

    Found on a rotary servo with heavy gear friction (4/27, rotary-rig README): light stuck
    phases (|u| <= 0.14 V) ring at 1.78-1.80 Hz, phases where the controller pushes the
    stuck gears with 0.32-0.36 V at 1.92-1.97 Hz; a hub clamped at one stiffness cannot do
    this (a hub held by a spring rings lower than a clamped one, and the encoder shows no
    hub motion in those phases)."""
    phases = sorted(((abs(v), f) for g in logs for v, f in stuck_ringing(g)), key=lambda p: p[0])
    best = None
    for k in range(1, len(phases)):
        lo, hi = phases[:k], phases[k:]
        f_lo = float(np.median([f for _, f in lo]))
        f_hi = float(np.median([f for _, f in hi]))
        if (
            min(f for _, f in hi) > max(f for _, f in lo)
            and f_hi >= PUSH_MIN_RISE * f_lo
            and hi[0][0] > lo[-1][0]
        ):
            gap = hi[0][0] - lo[-1][0]
            if best is None or gap > best[0]:
                best = (gap, k, f_lo, f_hi)
    if best is None:
        return None
    _, k, f_lo, f_hi = best
    u_lo, u_hi = phases[k - 1][0], phases[k][0]
    return {
        "stiffening": float((f_hi / f_lo) ** 2 - 1.0),
        "threshold": float(k_u * u_lo),
        "threshold_command": float(u_lo),
        "full": float(k_u * u_hi),
        "full_command": float(u_hi),
        "light_hz": f_lo,
        "pushed_hz": f_hi,
        "phases": [[round(float(v), 4), round(float(f), 4)] for v, f in phases],
    }
