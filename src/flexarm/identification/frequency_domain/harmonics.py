"""Harmonic analysis of one sinusoidal experiment (FRB Sec. II-B).

Phasor convention: a real signal x(t) contains, at harmonic n of the excitation ω0,
the component Re{X_n e^{j n ω0 t}}, with t the log's own time column (so phasors of
different columns of one log share a time origin; ratios of phasors do not depend on it).

* Excitation frequency ω0 (rad/s): taken from the ``reference`` column, by the peak of a
  Hann-windowed, zero-padded FFT (refined by parabolic interpolation of the log magnitude)
  and then a nonlinear least-squares fit of r(t) ≈ c + A cos ω0 t + B sin ω0 t over
  (c, A, B, ω0) (Gauss–Newton with step halving).
* Analysis window: the largest whole number N of periods T = 2π/ω0 at the end of the
  record, after ``discard_periods`` periods at the start are dropped as transient
  (fewer kept only if the record is too short for that; fewer than two whole periods is an
  error).  The window is the last M = round(N T/Δt) samples.
* Phasors X_0 (mean), X_1, X_2, …, X_nmax by linear least squares on
  x_k ≈ X_0 + Σ_n (a_n cos nω0t_k + b_n sin nω0t_k), X_n = a_n − j b_n.  Over whole
  periods this equals the Fourier-series coefficient (2/NT)∫x e^{−jnω0t}dt up to the
  sampling; it is exact for a signal made of the fitted harmonics only, whatever the number
  of samples per period.
* Saturation: a "flat plateau" of the current at its extreme value, i.e. at least
  ``min_fraction`` of the samples within ``rel_tol``·max|x| of max(x) or of min(x).
  A saturated current breaks the model of eqs. (1)-(5) and is reported by a warning.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import cast

import numpy as np

from flexarm.errors import FlexarmError  # the one error base (issue #25)
from flexarm.io.logs import Log


class IdentificationError(FlexarmError, ValueError):
    """Experiments that cannot be used for identification (message names file and problem)."""


class IdentificationWarning(UserWarning):
    """A problem in the experiments that does not stop the identification."""


def _warn(message: str, sink: list[str] | None) -> None:
    if sink is not None:
        sink.append(message)
    warnings.warn(message, IdentificationWarning, stacklevel=3)


def estimate_frequency(t: np.ndarray, x: np.ndarray, *, name: str = "signal") -> float:
    """Frequency (rad/s) of the sinusoid in ``x`` sampled at times ``t`` (uniform).

    FFT peak (Hann window, zero padding ×4 or more, parabolic interpolation), refined by a
    least-squares sinusoid fit over the whole record.
    """
    t = np.asarray(t, dtype=float)
    x = np.asarray(x, dtype=float)
    n = len(x)
    dt = float(np.median(np.diff(t)))
    y = x - x.mean()
    scale = float(np.max(np.abs(y))) if n else 0.0
    if n < 4 or scale == 0.0 or not np.isfinite(scale):
        raise IdentificationError(
            f"{name}: the reference is constant; no sinusoid to find the excitation frequency from"
        )
    nfft = 1 << int(math.ceil(math.log2(4 * n)))
    spec = np.abs(np.fft.rfft(y * np.hanning(n), nfft))
    k = int(np.argmax(spec[1:])) + 1
    if 1 <= k < len(spec) - 1:
        la, lb, lc = np.log(spec[k - 1 : k + 2] + 1e-300)
        den = la - 2 * lb + lc
        delta = 0.5 * (la - lc) / den if den != 0 else 0.0
    else:
        delta = 0.0
    w_fft = 2 * math.pi * (k + delta) / (nfft * dt)

    # Gauss-Newton on r(t) ≈ c + A cos ωt + B sin ωt over (c, A, B, ω), time centred.
    tc = t - 0.5 * (t[0] + t[-1])
    w = w_fft
    co, si = np.cos(w * tc), np.sin(w * tc)
    basis = np.column_stack([np.ones(n), co, si])
    p = np.linalg.solve(basis.T @ basis, basis.T @ x)
    sse = float(np.sum((basis @ p - x) ** 2))
    for _ in range(30):
        jw = (-p[1] * si + p[2] * co) * tc
        jac = np.column_stack([basis, jw])
        r = x - basis @ p
        try:
            step = np.linalg.solve(jac.T @ jac, jac.T @ r)
        except np.linalg.LinAlgError:
            break
        lam = 1.0
        while lam > 1e-4:
            w_new = w + lam * step[3]
            co_n, si_n = np.cos(w_new * tc), np.sin(w_new * tc)
            b_new = np.column_stack([np.ones(n), co_n, si_n])
            p_new = p + lam * step[:3]
            sse_new = float(np.sum((b_new @ p_new - x) ** 2))
            if sse_new <= sse:
                break
            lam /= 2
        else:
            break
        done = abs(w_new - w) <= 1e-14 * abs(w)
        w, p, sse, co, si, basis = w_new, p_new, sse_new, co_n, si_n, b_new
        if done or sse == 0.0:
            break
    bin_w = 2 * math.pi / (n * dt)
    if not np.isfinite(w) or abs(w - w_fft) > 2 * bin_w or w <= 0:
        return float(w_fft)
    return float(w)


def whole_periods(
    t: np.ndarray, omega0: float, *, discard_periods: float = 1.0, name: str = "signal"
) -> tuple[int, int, int]:
    """(start, stop, N): the window of the last N whole periods of 2π/ω0 in ``t``.

    N is the largest whole number of periods that fits after ``discard_periods`` periods
    are dropped at the start (if that leaves fewer than two, the discard is reduced).
    """
    n = len(t)
    dt = float(np.median(np.diff(t)))
    T = 2 * math.pi / omega0
    total = n * dt / T
    N = int(math.floor(total - discard_periods + 1e-9))
    if N < 2:
        N = int(math.floor(total + 1e-9))
    if N < 2:
        raise IdentificationError(
            f"{name}: fewer than two whole periods of the excitation: the record is "
            f"{n * dt:.6g} s long, {total:.3g} periods of 2π/ω0 = {T:.6g} s "
            f"(ω0 = {omega0:.6g} rad/s); record at least two periods (more, to let transients "
            "die out)"
        )
    M = min(n, int(round(N * T / dt)))
    return n - M, n, N


def fourier_phasors(
    t: np.ndarray,
    x: np.ndarray | Sequence[np.ndarray],
    omega0: float,
    n_max: int,
    *,
    window: tuple[int, int] | None = None,
) -> np.ndarray:
    """Phasors X_0 … X_nmax of one signal (shape (n_max+1,)) or of several signals
    (shape (k, n_max+1)), by least squares over ``window`` = (start, stop) indices.

    X_0 is the mean; x(t) ≈ X_0 + Σ_n Re{X_n e^{jnω0t}}.
    """
    t = np.asarray(t, dtype=float)
    X = np.asarray(x, dtype=float)
    single = X.ndim == 1
    X = np.atleast_2d(X)
    a, b = window if window is not None else (0, len(t))
    tw = t[a:b]
    ph = omega0 * tw
    cols = [np.ones_like(tw)]
    for k in range(1, n_max + 1):
        cols += [np.cos(k * ph), np.sin(k * ph)]
    basis = np.column_stack(cols)
    # Normal equations: over (nearly) whole periods the basis is (nearly) orthogonal,
    # so B^T B is well conditioned (cond ≈ 2) and this is much faster than an SVD.
    coef = np.linalg.solve(basis.T @ basis, basis.T @ X[:, a:b].T).T  # (k, 2 n_max + 1)
    out = np.empty((X.shape[0], n_max + 1), dtype=complex)
    out[:, 0] = coef[:, 0]
    out[:, 1:] = coef[:, 1::2] - 1j * coef[:, 2::2]
    return out[0] if single else out


def saturation_level(
    x: np.ndarray, *, min_fraction: float = 0.02, rel_tol: float = 1e-6
) -> float | None:
    """The level |x| of a flat plateau at the extreme value of ``x``, or None.

    A plateau: at least ``min_fraction`` of the samples within ``rel_tol``·max|x| of
    max(x) (or of min(x)).  A sampled sinusoid has about √(2·rel_tol)/π of its samples
    that close to its peak, far below the default fraction.
    """
    x = np.asarray(x, dtype=float)
    if x.size == 0:
        return None
    top, bot = float(x.max()), float(x.min())
    big = max(abs(top), abs(bot))
    if big == 0.0:
        return None
    tol = rel_tol * big
    levels = []
    if np.count_nonzero(x >= top - tol) >= min_fraction * x.size:
        levels.append(abs(top))
    if np.count_nonzero(x <= bot + tol) >= min_fraction * x.size:
        levels.append(abs(bot))
    return max(levels) if levels else None


@dataclass
class HarmonicAnalysis:
    """Harmonic content of one experiment.

    ``phasors[column]`` is an array X_0 … X_nmax (complex, SI units of the column);
    ``omega0`` in rad/s; the analysis window holds ``n_periods`` whole periods, samples
    ``start:stop`` of the log.
    """

    name: str
    omega0: float
    n_periods: int
    start: int
    stop: int
    phasors: dict[str, np.ndarray]
    saturation: float | None = None
    warnings: list[str] = field(default_factory=list)
    friction_shape: np.ndarray | None = None
    friction_shape_kind: str = "ideal"

    def phasor(self, column: str, n: int = 1) -> complex:
        """Phasor of harmonic ``n`` of ``column`` (n = 0: the mean)."""
        return complex(self.phasors[column][n])

    def friction(self, n: int = 1) -> complex:
        """Phasor of harmonic ``n`` of the Coulomb friction per unit C_f, sign(θ̇m(t)):
        measured (the sign of the motor velocity rebuilt from θm's harmonics) or, for
        ``friction_shape_kind == "ideal"``, the square wave in phase with the velocity's
        fundamental, (4/(nπ)) e^{j(n∠θm + π/2)} for odd n (FRB eq. 2)."""
        if self.friction_shape is not None:
            return complex(self.friction_shape[n])
        return ideal_friction_phasor(self.phasor("motor_angle", 1), n)


HELD_COLUMNS = ("current", "voltage")


def zoh_factor(omega: np.ndarray | float, dt: float) -> np.ndarray | complex:
    """Fundamental of a zero-order-held sequence relative to its samples at ω:
    e^{−jωT/2}·sin(ωT/2)/(ωT/2). A command logged by a digital controller is the value
    held from its sample to the next; the continuous signal that drives the motor lags
    the logged samples by T/2 (2° at 23 rad/s for T = 3 ms, 6° at 69 rad/s)."""
    x = np.asarray(omega, float) * dt / 2
    return np.exp(-1j * x) * np.sinc(x / np.pi)


def ideal_friction_phasor(theta_m1: complex, n: int = 1) -> complex:
    """Harmonic n of sign(θ̇m) for θm = |θ1| cos(ω0 t + ∠θ1): (4/(nπ)) e^{j(n∠θ1 + π/2)},
    odd n; 0 for even n (FRB eq. 2, with the phase as derived in docs: eq. (4) prints
    ∠θm + π/2 where 3∠θm + π/2 is meant)."""
    if n % 2 == 0:
        return 0j
    return complex(4.0 / (n * np.pi) * np.exp(1j * (n * np.angle(theta_m1) + np.pi / 2)))


def measured_friction_shape(
    t: np.ndarray, theta_phasors: np.ndarray, omega0: float, n_max: int
) -> np.ndarray:
    """Phasors 0…n_max of sign(θ̇m(t)) with θ̇m rebuilt from θm's harmonics 1…n_max.

    FRB Sec. II: the high-gain loop "allows us to determine the velocity of the motor and,
    hence, the shape of the Coulomb friction". The motor's velocity is not a pure sinusoid
    (the loop reacts to the friction; the motor stops briefly at reversals), so its zero
    crossings, and with them the friction square wave, are shifted from the fundamental's:
    on our simulated arm the ideal square wave biased V by 4-6 % and the measured shape
    brought it within 2 %. Harmonics above n_max are left out: they carry mostly the A/D
    noise, whose sign flips near zero velocity."""
    ph = omega0 * np.asarray(t, float)
    v = np.zeros_like(ph)
    for n in range(1, n_max + 1):  # Re{jnω X_n e^{jnωt}} = −nω (Re X_n sin + Im X_n cos)
        x = theta_phasors[n]
        v -= n * omega0 * (x.real * np.sin(n * ph) + x.imag * np.cos(n * ph))
    return fourier_phasors(t, np.sign(v), omega0, n_max)


def analyse_log(
    log: Log,
    *,
    n_max: int = 5,
    columns: Iterable[str] | None = None,
    omega0: float | None = None,
    discard_periods: float = 1.0,
    saturation_fraction: float = 0.02,
    held: Iterable[str] = HELD_COLUMNS,
    friction_shape: str = "measured",
) -> HarmonicAnalysis:
    """Frequency, analysis window, phasors of harmonics 0…``n_max`` of ``columns``
    (default: all but time) and a saturation check of the current (warning).

    Columns named in ``held`` (default: the commands ``current`` and ``voltage``) are
    logged as zero-order-held samples: their phasors are those of the held, continuous
    signal (:func:`zoh_factor`). Pass ``held=()`` for a current measured by an A/D.

    ``friction_shape``: ``"measured"`` (default; :func:`measured_friction_shape`) or
    ``"ideal"`` (the square wave of FRB eq. 2 in phase with the velocity's fundamental).
    """
    if friction_shape not in ("measured", "ideal"):
        raise ValueError(f"friction_shape = {friction_shape!r}; choose 'measured' or 'ideal'")
    name, where = log.name, log.where  # messages name the file by its full path
    t = cast(np.ndarray, log.time)  # (a log without time: the error as before)
    if omega0 is None:
        omega0 = estimate_frequency(t, log["reference"], name=where)
    start, stop, N = whole_periods(t, omega0, discard_periods=discard_periods, name=where)
    cols = list(log.signals) if columns is None else list(columns)
    ph = fourier_phasors(t, np.stack([log[c] for c in cols]), omega0, n_max, window=(start, stop))
    held = set(held)
    hold = zoh_factor(omega0 * np.arange(n_max + 1), log.dt)
    res = HarmonicAnalysis(
        name=name,
        omega0=float(omega0),
        n_periods=N,
        start=start,
        stop=stop,
        phasors={c: ph[k] * (hold if c in held else 1.0) for k, c in enumerate(cols)},
    )
    if friction_shape == "measured" and "motor_angle" in res.phasors:
        res.friction_shape = measured_friction_shape(
            t[start:stop], res.phasors["motor_angle"], omega0, n_max
        )
        res.friction_shape_kind = "measured"
    if "current" in log.signals:
        level = saturation_level(log["current"], min_fraction=saturation_fraction)
        if level is not None:
            res.saturation = level
            frac = np.mean(np.abs(log["current"]) >= level * (1 - 1e-6))
            _warn(
                f"{where}: the current looks saturated: flat at ±{level:.6g} A for "
                f"{100 * frac:.1f} % of the samples; the model of FRB eqs. (1)-(5) does not "
                "hold there (lower the excitation amplitude)",
                res.warnings,
            )
    return res
