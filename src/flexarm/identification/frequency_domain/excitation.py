"""Excitation signals for frequency-domain identification.

* Periodic multisines u(t) = Σ_k A_k cos(2π k f0 t + φ_k), f0 = fs/P, built exactly on the
  DFT grid of one period (``numpy.fft.irfft``) so that every period holds whole cycles:
  ``full`` (every line of the grid), ``odd`` (odd lines only: even lines detect even
  nonlinear distortion), ``random-odd`` (odd lines, one of every ``block`` consecutive odd
  lines left out at random: detection lines for odd distortion; Pintelon & Schoukens 2012,
  Sec. 4.3); ``linear`` or ``log`` (lines ~ a geometric series, rounded to the grid) grids.
  Phases: ``schroeder`` φ_k = −π k(k−1)/K over the K lines (Schroeder 1970, low crest for
  flat spectra), ``random`` (uniform), ``min-crest`` (iterative clipping, Van der Ouderaa,
  Schoukens & Renneboog 1988: clip the time signal at a shrinking level, keep the clipped
  signal's phases and restore the amplitudes).  Amplitude per line or an rms.
* PRBS: maximum-length binary sequences (``scipy.signal.max_len_seq``), ±amplitude.
* Swept sine: ``scipy.signal.chirp`` (linear or logarithmic), one sweep per period.
* The FRB ω0/3ω0 stepped-sine plan: pairs (ω0, 3ω0) (FRB Sec. II-A; the experiments
  themselves are :func:`flexarm.identification.frequency_domain.experiments.run_sine_experiments`).

Crest factor = max|u| / rms(u).  :func:`write_excitation` writes the signal through
:func:`flexarm.io.logs.write_log` and the excited / detection lines to a CSV beside it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from flexarm.errors import FlexarmError  # the one error base (issue #25)

KINDS = ("full", "odd", "random-odd")
PHASES = ("schroeder", "random", "min-crest")


class ExcitationError(FlexarmError, ValueError):
    """An excitation design that cannot be built; names the field and the value."""


@dataclass
class Excitation:
    """Samples of all periods and realisations, and the design's lines (DFT indices of one
    period; frequency = line · fs / period)."""

    signal: np.ndarray  # (realisations, periods · period)
    fs: float
    period: int
    excited: np.ndarray
    detection: np.ndarray

    @property
    def time(self) -> np.ndarray:
        return np.arange(self.signal.shape[-1]) / self.fs

    @property
    def crest_factor(self) -> float:
        return crest_factor(self.signal)

    @property
    def excited_hz(self) -> np.ndarray:
        return self.excited * self.fs / self.period

    @property
    def detection_hz(self) -> np.ndarray:
        return self.detection * self.fs / self.period


def crest_factor(u: np.ndarray) -> float:
    """max|u| / rms(u) (the largest over realisations, each row a realisation)."""
    u = np.atleast_2d(u)
    return float(np.max(np.abs(u).max(axis=1) / np.sqrt((u**2).mean(axis=1))))


def multisine_lines(
    period: int,
    fs: float,
    f_min: float,
    f_max: float,
    *,
    kind: str = "odd",
    grid: str = "linear",
    n_lines: int | None = None,
    block: int = 3,
    rng: np.random.Generator | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Excited and detection lines (DFT indices) of a multisine design in [f_min, f_max]."""
    if kind not in KINDS:
        raise ExcitationError(f"kind={kind!r}: choose one of {', '.join(KINDS)}")
    df = fs / period
    k0, k1 = max(1, int(np.ceil(f_min / df - 1e-9))), int(np.floor(f_max / df + 1e-9))
    if k1 > period // 2 - 1 or k0 > k1:
        raise ExcitationError(
            f"band {f_min:g}–{f_max:g} Hz holds no line of the grid "
            f"{df:g} Hz below Nyquist ({fs / 2:g} Hz); widen it or change "
            "the period"
        )
    k = np.arange(k0, k1 + 1)
    if grid == "log":
        n = n_lines or max(2, int(np.ceil(10 * np.log10(k1 / k0))))
        k = np.unique(np.round(np.geomspace(k0, k1, n)).astype(int))
    elif grid != "linear":
        raise ExcitationError(f"grid={grid!r}: choose linear or log")
    if kind in ("odd", "random-odd"):
        k = np.unique(np.where(k % 2 == 0, k + 1, k))
        k = k[k <= max(k1, k0)]
    detection = np.setdiff1d(np.arange(k.min(), k.max() + 1), k)
    if kind == "random-odd":
        rng = rng or np.random.default_rng(0)
        drop = [
            g[rng.integers(len(g))]
            for g in np.array_split(k, max(1, len(k) // block))
            if len(g) > 1
        ]
        k = np.setdiff1d(k, drop)
        detection = np.setdiff1d(np.arange(k.min(), k.max() + 1), k)
    return k, detection


def _phases(k: np.ndarray, how: str, rng: np.random.Generator) -> np.ndarray:
    if how == "schroeder":
        i = np.arange(1, len(k) + 1)
        return -np.pi * i * (i - 1) / len(k)
    if how in ("random", "min-crest"):
        return rng.uniform(0, 2 * np.pi, len(k))
    raise ExcitationError(f"phases={how!r}: choose one of {', '.join(PHASES)}")


def _one_period(period: int, k: np.ndarray, amp: np.ndarray, phi: np.ndarray) -> np.ndarray:
    X = np.zeros(period // 2 + 1, complex)
    X[k] = amp * np.exp(1j * phi) * period / 2
    return np.fft.irfft(X, period)


def _min_crest(
    period: int, k: np.ndarray, amp: np.ndarray, phi: np.ndarray, iterations: int = 200
) -> np.ndarray:
    """Iterative clipping: clip at a level below the peak, keep the phases, restore |A|."""
    best, best_cf = phi, crest_factor(_one_period(period, k, amp, phi))
    for i in range(iterations):
        u = _one_period(period, k, amp, phi)
        level = np.abs(u).max() * (0.9 + 0.08 * i / iterations)
        phi = np.angle(np.fft.rfft(np.clip(u, -level, level))[k])
        cf = crest_factor(_one_period(period, k, amp, phi))
        if cf < best_cf:
            best, best_cf = phi, cf
    return best


def multisine(
    period: int,
    fs: float,
    f_min: float,
    f_max: float,
    *,
    kind: str = "odd",
    grid: str = "linear",
    phases: str = "random",
    rms: float | None = 1.0,
    amplitude: float | None = None,
    periods: int = 1,
    realisations: int = 1,
    n_lines: int | None = None,
    block: int = 3,
    seed: int = 0,
) -> Excitation:
    """A periodic multisine (see the module docstring). Give ``rms`` (of the signal) or
    ``amplitude`` (per line); each realisation draws new random phases (and, for
    random-odd, keeps the same lines)."""
    if period < 4 or periods < 1 or realisations < 1:
        raise ExcitationError(
            f"period={period}, periods={periods}, realisations={realisations}: "
            "need period >= 4 samples and at least one of each"
        )
    rng = np.random.default_rng(seed)
    k, det = multisine_lines(
        period, fs, f_min, f_max, kind=kind, grid=grid, n_lines=n_lines, block=block, rng=rng
    )
    rows = []
    for _ in range(realisations):
        a = np.ones(len(k))
        phi = _phases(k, phases, rng)
        if phases == "min-crest":
            phi = _min_crest(period, k, a, phi)
        u = _one_period(period, k, a, phi)
        if amplitude is not None:
            u = u * amplitude
        elif rms is not None:
            u = u * rms / np.sqrt(np.mean(u**2))
        else:
            raise ExcitationError("give rms or amplitude")
        rows.append(np.tile(u, periods))
    return Excitation(np.array(rows), float(fs), int(period), k, det)


def prbs(order: int, fs: float, *, amplitude: float = 1.0, periods: int = 1) -> Excitation:
    """Maximum-length PRBS of period 2^order − 1 samples, values ±amplitude (all lines excited)."""
    from scipy.signal import max_len_seq

    if not 2 <= order <= 32:
        raise ExcitationError(f"order={order}: a PRBS needs 2 <= order <= 32")
    seq = max_len_seq(order)[0].astype(float) * 2 - 1
    P = len(seq)
    return Excitation(
        np.tile(amplitude * seq, periods)[None],
        float(fs),
        P,
        np.arange(1, P // 2 + 1),
        np.array([], int),
    )


def swept_sine(
    period: int,
    fs: float,
    f_min: float,
    f_max: float,
    *,
    method: str = "logarithmic",
    amplitude: float = 1.0,
    periods: int = 1,
) -> Excitation:
    """One sweep f_min → f_max per period (``scipy.signal.chirp``), repeated ``periods`` times."""
    from scipy.signal import chirp

    t = np.arange(period) / fs
    u = amplitude * chirp(t, f_min, t[-1], f_max, method=method)
    k, _ = multisine_lines(period, fs, f_min, f_max, kind="full")
    return Excitation(np.tile(u, periods)[None], float(fs), int(period), k, np.array([], int))


def sine_pairs(omegas) -> list[tuple[float, float]]:
    """The FRB ω0/3ω0 stepped-sine plan: each ω0 (rad/s) and its third harmonic."""
    return [(float(w), 3.0 * float(w)) for w in omegas]


def write_excitation(
    path: str | Path, exc: Excitation, *, name: str = "reference", overwrite: bool = False
) -> tuple[Path, Path]:
    """The signal as a log (``time`` + one column per realisation) and ``<stem>-lines.csv``
    with ``line,frequency_hz,role`` (excited / detection); returns both paths."""
    from flexarm.io.logs import write_log

    path = Path(path)
    cols = {name if i == 0 else f"{name}_{i}": row for i, row in enumerate(exc.signal)}
    meta = {
        "period_samples": exc.period,
        "fs_hz": exc.fs,
        "crest_factor": f"{exc.crest_factor:.4f}",
        "excited_lines": len(exc.excited),
        "detection_lines": len(exc.detection),
    }
    out = write_log(path, exc.time, cols, comments=meta, overwrite=overwrite, required=("time",))
    lines = path.with_name(path.stem + "-lines.csv")
    if lines.exists() and not overwrite:
        raise FileExistsError(f"{lines}: exists; pass overwrite to replace it")
    rows = [(int(k), k * exc.fs / exc.period, "excited") for k in exc.excited] + [
        (int(k), k * exc.fs / exc.period, "detection") for k in exc.detection
    ]
    rows.sort()
    lines.write_text(
        "line,frequency_hz,role\n" + "".join(f"{k},{f:.12g},{r}\n" for k, f, r in rows)
    )
    return out, lines
