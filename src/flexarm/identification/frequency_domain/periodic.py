"""Nonparametric frequency response from periodic (multisine) records, with noise and
nonlinear-distortion levels and the best linear approximation (BLA).

Method (Pintelon & Schoukens, *System Identification: a Frequency Domain Approach*, 2nd ed.
2012, Secs. 2.4, 3.7, 4.3 "fast method"):

1. The record is cut into whole periods of P samples; a trailing partial period is
   discarded with a warning; leading transient periods (given, or found where a period's
   spectrum at the excited lines departs from the steady periods' mean by more than
   ``TRANSIENT_RATIO`` times the typical departure) are dropped; at least two steady periods
   are needed.  A linear drift (a free rigid-body angle) is removed per channel from the
   mean difference of consecutive periods, Y_{m+1}[n] − Y_m[n] = b P, which leaves the
   periodic part untouched.
2. Per period m the DFT X_m[k] = (1/P) Σ_n x_m[n] e^{−j2πkn/P}; over the M steady periods
   the means Ū_k, Ȳ_k, sample variances σ²_U, σ²_Y and covariance σ_YU (errors in
   variables: the measured input is noisy too).
3. FRF at the excited lines G_k = Ȳ_k/Ū_k with the variance of the estimate (first order)
       var G_k = |G_k|²/M · (σ²_Y/|Ȳ|² + σ²_U/|Ū|² − 2 Re(σ_YU / (Ȳ Ū*))).
   SIMO: the same per output.
4. Detection lines (non-excited lines inside the excited band): with an odd excitation
   (every excited line index odd), the odd non-excited lines carry the odd (symmetric)
   nonlinear distortion, the even ones the even distortion.  Per band (octaves from the
   lowest excited line) the rms of |Ȳ| at odd and even detection lines and the noise level
   (rms of σ_Y/√M, the std of the averaged spectrum) are given in dB relative to the rms
   output at the excited lines of that band.
5. BLA total variance: the stochastic nonlinear contributions at an excited line have the
   level of the neighbouring odd detection lines, σ²_S,k = max(|Ȳ_d|² − σ²_Y,d/M, 0)
   averaged over the ``NEIGHBOURS`` nearest odd detection lines; var_total G_k =
   var G_k + σ²_S,k/|Ū_k|².

Results: a python-control ``FrequencyResponseData`` (outputs × one input) in
:class:`PeriodicFRF` with ``noise_std``, ``total_std`` and the distortion table.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import control
import numpy as np

from flexarm.display import Table
from flexarm.identification.frequency_domain.harmonics import (
    IdentificationError,
    IdentificationWarning,
)

#: A leading period is transient when its departure is this many times the steady one's.
TRANSIENT_RATIO = 4.0
#: Excited lines found from the input: within this many dB of the strongest line.
LINES_DB = 20.0
#: Odd detection lines averaged for the nonlinear variance at an excited line.
NEIGHBOURS = 4
#: Largest accepted periodic_change of the input for a period (1 = as much noise as signal).
MAX_CHANGE = 1.0
#: Distortion counts as detected this many dB above the noise level.
DETECT_DB = 6.0


@dataclass
class Band:
    """Distortion levels of one output in one band, dB relative to the excited output."""

    band_hz: tuple[float, float]
    odd_db: float
    even_db: float
    noise_db: float


@dataclass
class PeriodicFRF:
    """FRF from periodic data; arrays are (outputs, excited lines)."""

    frd: control.FrequencyResponseData
    response: np.ndarray  # G at the excited lines, (outputs, lines)
    frequency_hz: np.ndarray
    lines: np.ndarray
    outputs: list[str]
    input: str
    noise_std: np.ndarray
    total_std: np.ndarray | None
    distortion: dict[str, list[Band]] | None
    period: int
    fs: float
    periods_used: int
    transient_periods: int
    spectra: dict = field(repr=False, default_factory=dict)
    warnings: list[str] = field(default_factory=list)

    def to_json(self) -> dict:
        """``frequency_hz`` and ``outputs.<name>``: ``re``, ``im``, ``noise_std`` (std of the
        FRF estimate per line) and, with detection lines, ``total_std`` and ``distortion``
        (``band_hz``, ``odd_db``, ``even_db``, ``noise_db`` per band, dB re the output at the
        excited lines)."""
        out = {}
        for j, name in enumerate(self.outputs):
            d = {
                "re": self.response[j].real.tolist(),
                "im": self.response[j].imag.tolist(),
                "noise_std": self.noise_std[j].tolist(),
            }
            if self.total_std is not None:
                d["total_std"] = self.total_std[j].tolist()
            if self.distortion is not None:
                bands = self.distortion[name]

                def nan(v):
                    return None if not math.isfinite(v) else float(v)

                d["distortion"] = {
                    "band_hz": [list(map(float, b.band_hz)) for b in bands],
                    "odd_db": [nan(b.odd_db) for b in bands],
                    "even_db": [nan(b.even_db) for b in bands],
                    "noise_db": [nan(b.noise_db) for b in bands],
                }
            out[name] = d
        sp = self.spectra
        spectra = (
            None
            if not sp
            else {
                "note": "mean DFT over the steady periods (1/P scaling) of input then outputs at "
                "every line 0..P/2, their variances, and the number of periods M",
                "re": sp["mean"].real.tolist(),
                "im": sp["mean"].imag.tolist(),
                "var": sp["var"].tolist(),
                "M": int(sp["M"]),
            }
        )
        return {
            "input": self.input,
            "frequency_hz": self.frequency_hz.tolist(),
            "lines": self.lines.tolist(),
            "period_samples": self.period,
            "fs_hz": self.fs,
            "periods_used": self.periods_used,
            "transient_periods": self.transient_periods,
            "outputs": out,
            "verdict": self.verdict(),
            "warnings": self.warnings,
            "spectra": spectra,
        }

    @classmethod
    def from_json(cls, d: dict, source: str = "FRF JSON") -> PeriodicFRF:
        """The result back from :meth:`to_json` (``spectra`` needed for the friction
        analysis of :mod:`.multisine_friction`)."""
        try:
            names = list(d["outputs"])
            G = np.array(
                [
                    np.asarray(d["outputs"][n]["re"]) + 1j * np.asarray(d["outputs"][n]["im"])
                    for n in names
                ]
            )
            f = np.asarray(d["frequency_hz"], float)
            nstd = np.array([d["outputs"][n]["noise_std"] for n in names], float)
            tstd = (
                np.array([d["outputs"][n]["total_std"] for n in names], float)
                if all("total_std" in d["outputs"][n] for n in names)
                else None
            )
            dist = None
            if all("distortion" in d["outputs"][n] for n in names):

                def fl(v):
                    return math.nan if v is None else float(v)

                dist = {
                    n: [
                        Band(tuple(b), fl(o), fl(e), fl(z))
                        for b, o, e, z in zip(
                            *(
                                d["outputs"][n]["distortion"][k]
                                for k in ("band_hz", "odd_db", "even_db", "noise_db")
                            ),
                            strict=False,
                        )
                    ]
                    for n in names
                }
            sp = d.get("spectra")
            spectra = (
                {}
                if not sp
                else {
                    "mean": np.asarray(sp["re"]) + 1j * np.asarray(sp["im"]),
                    "var": np.asarray(sp["var"], float),
                    "M": int(sp["M"]),
                    "lines": np.arange(len(sp["re"][0])),
                    "excited": np.asarray(d["lines"], int),
                }
            )
            if not names:
                raise ValueError("'outputs': no output")
            if f.ndim != 1 or f.size == 0 or not np.all(np.isfinite(f)):
                raise ValueError(
                    f"'frequency_hz': not a list of finite numbers ({f.ndim}-d, {f.size} values)"
                )
            for what, arr in (("re/im", G), ("noise_std", nstd), ("total_std", tstd)):
                if arr is not None and arr.shape != (len(names), f.size):
                    raise ValueError(
                        f"'outputs' {what}: shape {arr.shape}, expected "
                        f"{(len(names), f.size)} (one value per output and "
                        "frequency)"
                    )
            if len(np.asarray(d["lines"]).ravel()) != f.size:
                raise ValueError(
                    f"'lines': {len(np.asarray(d['lines']).ravel())} lines for {f.size} frequencies"
                )
            frd = control.FrequencyResponseData(
                G[:, None, :], 2 * np.pi * f, inputs=[d["input"]], outputs=names
            )
            return cls(
                frd,
                G,
                f,
                np.asarray(d["lines"], int),
                names,
                d["input"],
                nstd,
                tstd,
                dist,
                int(d["period_samples"]),
                float(d["fs_hz"]),
                int(d["periods_used"]),
                int(d["transient_periods"]),
                spectra,
                list(d.get("warnings", [])),
            )
        except (KeyError, TypeError, ValueError, IndexError, OverflowError, AttributeError) as exc:
            raise IdentificationError(
                f"{source}: not an FRF written by flexarm frf (missing or bad {exc})",
                file=source,
                fix="give the JSON flexarm frf --json wrote",
            ) from None

    def _table(self) -> Table:
        """One row per output: |G| range (dB), median noise and total std relative to |G|."""
        f = self.frequency_hz
        title = f"PeriodicFRF {self.input} → {', '.join(self.outputs)}: {len(self.lines)} lines" + (
            f", {f[0]:.4g}–{f[-1]:.4g} Hz" if len(f) else ""
        )
        rows = []
        with np.errstate(all="ignore"):
            for j, name in enumerate(self.outputs):
                mag = np.abs(self.response[j])
                db = 20 * np.log10(np.maximum(mag, 1e-300))

                def rel(sd, mag=mag):
                    return f"{100 * float(np.median(sd / mag)):.3g} %"

                rows.append(
                    (
                        name,
                        f"{db.min():.1f} … {db.max():.1f}",
                        rel(self.noise_std[j]),
                        None if self.total_std is None else rel(self.total_std[j]),
                    )
                )
        notes = [
            f"period {self.period} samples at {self.fs:g} Hz, {self.periods_used} periods "
            f"used ({self.transient_periods} transient)",
            self.verdict(),
            *self.warnings,
        ]
        return Table(
            title,
            rows,
            header=("output", "|G| (dB)", "noise std/|G|", "total std/|G|"),
            notes=notes,
        )

    def __repr__(self) -> str:
        return self._table().text()

    def _repr_html_(self) -> str:
        return self._table().html()

    def verdict(self) -> str:
        """A plain sentence per output about the nonlinear distortion."""
        if self.distortion is None:
            return (
                "no detection lines: the distortion cannot be told from the noise; "
                "excite a random-odd multisine to check linearity"
            )
        return " ".join(distortion_verdict(name, bands) for name, bands in self.distortion.items())


def distortion_verdict(name: str, bands: Sequence[Band]) -> str:
    """E.g. 'motor_angle: odd distortion 22 dB above the noise below 52 Hz: ...'."""
    odd = [b for b in bands if b.odd_db - b.noise_db > DETECT_DB]
    even = [b for b in bands if b.even_db - b.noise_db > DETECT_DB]
    parts = []
    if odd:
        top = max(b.odd_db - b.noise_db for b in odd)
        parts.append(
            f"odd distortion up to {top:.0f} dB above the noise in "
            f"{_span(odd)} (up to {max(b.odd_db for b in odd):.0f} dB re the excited "
            "output): a symmetric nonlinearity such as Coulomb friction; a linear "
            "model cannot fit to the noise level there"
        )
    if even:
        top = max(b.even_db - b.noise_db for b in even)
        parts.append(
            f"even distortion up to {top:.0f} dB above the noise in {_span(even)}: "
            "an asymmetric nonlinearity (an offset, a position-dependent load)"
        )
    if not parts:
        parts.append("no distortion above the noise: a linear model can fit to the noise level")
    return f"{name}: " + "; ".join(parts) + "."


def _span(bands: Sequence[Band]) -> str:
    return ", ".join(f"{b.band_hz[0]:.0f}–{b.band_hz[1]:.0f} Hz" for b in bands)


def detect_period(x: np.ndarray, *, min_period: int = 8, name: str = "input") -> int:
    """Shortest lag P (≥ ``min_period``, ≤ N/2) where the normalised autocorrelation of x is
    within 10 % of its largest value over those lags (a periodic signal repeats at P, 2P, ...)."""
    x = np.asarray(x, float) - np.mean(x)
    n = len(x)
    if n < 2 * min_period:
        raise IdentificationError(f"{name}: {n} samples are too few to find a period")
    f = np.fft.rfft(x, 2 * n)
    r = np.fft.irfft(np.abs(f) ** 2)[: n // 2 + 1] / (n - np.arange(n // 2 + 1))
    r = r / r[0]
    lags = np.arange(min_period, n // 2 + 1)
    rr = r[lags]
    best = rr.max()
    if best < 0.5:
        raise IdentificationError(
            f"{name}: no period found (autocorrelation at most "
            f"{best:.2f} for periods of {min_period}–{n // 2} samples); "
            "is the excitation periodic? give --period"
        )
    cand = lags[rr >= 0.9 * best]
    return int(cand[0] + np.argmax(r[cand[0] : cand[0] + max(cand[0] // 2, 2)]))


def _dft_periods(x: np.ndarray, P: int, M0: int) -> np.ndarray:
    return np.fft.rfft(x[..., : M0 * P].reshape(*x.shape[:-1], M0, P), axis=-1) / P


def check_live_channels(
    chans: Mapping[str, np.ndarray], input_name: str, source: str = "<data>"
) -> None:
    """Refuse a channel that does not change (issue #45): every sample of it the same
    value (to 1e-12 of its size).  A constant input carries no excitation (its spectrum is
    zero: no line, no period, G = Y/0); a constant output is a dead sensor or a wrong
    mapping (G = 0 at every line with a noise of 0, its distortion NaN, judged "no
    distortion").  One :class:`IdentificationError` naming the channel, its value and the
    fix."""
    for k, v in chans.items():
        v = np.asarray(v, float)
        if v.size < 2:
            continue
        lo, hi = float(v.min()), float(v.max())
        if hi - lo <= 1e-12 * max(abs(lo), abs(hi)):
            role = "input" if k == input_name else "reference" if k == "reference" else "output"
            why = (
                "it carries no excitation, so no frequency response can be estimated; "
                "record the run with the excitation on, or map the column that holds the "
                "excitation"
                if role != "output"
                else "a dead sensor or a wrong column: its FRF would be 0 with no noise and "
                "no distortion; check the sensor, or the mapping (--output, [columns])"
            )
            raise IdentificationError(
                f"{source}: the {role} {k!r} is constant (all {v.size} samples are {lo:.6g}): {why}"
            )


def periodic_frf(
    u: np.ndarray,
    y: Mapping[str, np.ndarray],
    fs: float,
    *,
    period: int | None = None,
    lines: Sequence[int] | np.ndarray | None = None,
    transient_periods: int | None = None,
    input_name: str = "input",
    source: str = "<data>",
    detrend: bool = True,
    require_distortion: bool = False,
) -> PeriodicFRF:
    """FRF, noise and distortion from one periodic record (see the module docstring).

    ``u``: input samples; ``y``: output name → samples (same length); ``fs``: sampling
    rate (Hz); ``period``: samples per period (None: detected from ``u``); ``lines``: excited
    DFT line indices of one period (None: lines within ``LINES_DB`` of the strongest input
    line); ``transient_periods``: leading periods to drop (None: detected);
    ``require_distortion``: raise if the excitation has no detection lines.
    """
    names = list(y)
    if not names:
        raise IdentificationError(f"{source}: no output signal given")
    chans = {input_name: np.asarray(u, float), **{k: np.asarray(v, float) for k, v in y.items()}}
    for k, v in chans.items():
        if v.ndim != 1:
            raise IdentificationError(f"{source}: signal {k!r} has shape {v.shape}; expected 1-D")
        bad = ~np.isfinite(v)
        if bad.any():
            raise IdentificationError(
                f"{source}: signal {k!r} has {int(bad.sum())} NaN/"
                f"infinite value(s), first at sample {int(np.argmax(bad))}"
            )
    lens = {k: len(v) for k, v in chans.items()}
    if len(set(lens.values())) > 1:
        raise IdentificationError(
            f"{source}: channels of different lengths: "
            + ", ".join(f"{k} {n}" for k, n in lens.items())
        )
    check_live_channels(chans, input_name, source)
    N = lens[input_name]
    notes: list[str] = []
    P = (
        detect_period(chans[input_name], name=f"{source}: {input_name}")
        if period is None
        else int(period)
    )
    M0 = N // P
    if P < 2 or M0 < 2:
        raise IdentificationError(
            f"{source}: {N} samples hold {M0} whole period(s) of {P} "
            "samples; the FRF and its noise level need at least two "
            "whole periods: record longer or give the right --period"
        )
    X = np.stack([chans[k] for k in [input_name] + names])  # (C, N)
    if N - M0 * P:
        msg = (
            f"{source}: {N - M0 * P} trailing sample(s) of a partial period discarded "
            f"({M0} whole periods of {P} samples kept)"
        )
        warnings.warn(msg, IdentificationWarning, stacklevel=2)
        notes.append(msg)
    Xp = X[:, : M0 * P].reshape(len(X), M0, P)
    if detrend:  # remove a linear drift b·n from the mean period-to-period difference
        half = Xp[:, M0 // 2 :]
        b = (
            (half[:, -1] - half[:, 0]).mean(axis=1) / (P * max(half.shape[1] - 1, 1))
            if half.shape[1] > 1
            else (Xp[:, -1] - Xp[:, 0]).mean(axis=1) / (P * (M0 - 1))
        )
        Xp = Xp - b[:, None, None] * np.arange(M0 * P).reshape(M0, P)[None]
    F = np.fft.rfft(Xp, axis=-1) / P  # (C, M0, P/2+1)

    if lines is None:
        Um = np.abs(F[0, M0 // 2 :].mean(axis=0))
        Um[0] = 0.0
        exc = np.nonzero(Um >= Um.max() * 10 ** (-LINES_DB / 20))[0]
    else:
        exc = np.unique(np.asarray(lines, int))
        if exc.size == 0 or exc.min() < 1 or exc.max() > P // 2:
            raise IdentificationError(
                f"{source}: excited lines must lie in 1..{P // 2} for a "
                f"period of {P} samples; got {exc.min()}..{exc.max()}"
            )
    change = periodic_change(Xp[0, M0 // 2 :] if M0 >= 4 else Xp[0])
    if change > MAX_CHANGE:
        raise IdentificationError(
            f"{source}: the period of {P} samples does not fit the data: consecutive periods "
            f"of the input {input_name!r} differ by {change:.2f} of its power (a periodic "
            f"input with fair noise: well below {MAX_CHANGE}); give the excitation's true "
            "period or --period auto"
        )

    # Transient periods: departure from the steady mean at the excited lines.
    ref = F[:, M0 // 2 :, :][:, :, exc].mean(axis=1)
    dev = (np.abs(F[:, :, exc] - ref[:, None]) ** 2).sum(axis=-1) / (np.abs(ref) ** 2).sum(-1)[
        :, None
    ]
    typical = np.median(dev[:, M0 // 2 :], axis=1)
    ratio = (dev / np.maximum(typical[:, None], 1e-300)).max(axis=0)
    if transient_periods is None:
        nt = 0
        while nt < M0 - 2 and ratio[nt] > TRANSIENT_RATIO:
            nt += 1
    else:
        nt = int(transient_periods)
        if nt < 0 or M0 - nt < 2:
            raise IdentificationError(
                f"{source}: {nt} transient period(s) of {M0} leave fewer than two steady periods"
            )
    F = F[:, nt:]
    M = M0 - nt

    mean = F.mean(axis=1)  # (C, K)
    d = F - mean[:, None]
    var = (np.abs(d) ** 2).sum(axis=1) / (M - 1)
    cov_yu = (d[1:] * np.conj(d[:1])).sum(axis=1) / (M - 1)
    U, Y = mean[0, exc], mean[1:, exc]
    G = Y / U
    varG = (
        np.abs(G) ** 2
        / M
        * (
            var[1:, exc] / np.abs(Y) ** 2
            + var[0, exc] / np.abs(U) ** 2
            - 2 * np.real(cov_yu[:, exc] / (Y * np.conj(U)))
        )
    )
    noise_std = np.sqrt(np.maximum(varG, 0.0))

    kmin, kmax = int(exc.min()), int(exc.max())
    inband = np.arange(kmin, kmax + 1)
    det = np.setdiff1d(inband, exc)
    odd_exc = bool(np.all(exc % 2 == 1))
    distortion = total_std = None
    if det.size:
        odd_det = det[det % 2 == 1] if odd_exc else det
        even_det = det[det % 2 == 0] if odd_exc else det[:0]
        distortion = {}
        edges = [kmin]
        while edges[-1] * 2 < kmax:
            edges.append(edges[-1] * 2)
        edges.append(kmax + 1)
        df = fs / P
        for j, name in enumerate(names):
            yy = np.abs(mean[1 + j]) ** 2
            noise_mean = var[1 + j] / M  # variance of the averaged spectrum per line
            bands = []
            for lo, hi in zip(edges[:-1], edges[1:], strict=True):

                def sel(ks, lo=lo, hi=hi):
                    return ks[(ks >= lo) & (ks < hi)]

                e, o, ev = sel(exc), sel(odd_det), sel(even_det)
                if not e.size:
                    continue
                refp = yy[e].mean()

                def db(p, refp=refp):
                    return 10 * math.log10(p / refp) if p > 0 else -math.inf

                bands.append(
                    Band(
                        (lo * df, (hi - 1) * df),
                        db(yy[o].mean()) if o.size else math.nan,
                        db(yy[ev].mean()) if ev.size else math.nan,
                        db(noise_mean[np.r_[e, o, ev]].mean()),
                    )
                )
            distortion[name] = bands
        if odd_det.size:
            s = np.maximum(np.abs(mean[1:, odd_det]) ** 2 - var[1:, odd_det] / M, 0.0)
            near = np.argsort(np.abs(odd_det[None, :] - exc[:, None]), axis=1)[:, :NEIGHBOURS]
            s_exc = s[:, near].mean(axis=-1)  # (ny, K)
            total_std = np.sqrt(noise_std**2 + s_exc / np.abs(U) ** 2)
    elif require_distortion:
        raise IdentificationError(
            f"{source}: every line from {kmin} to {kmax} (× {fs / P:g} Hz) is excited: no "
            "detection lines, so nonlinear distortion cannot be told from the output; use a "
            "random-odd multisine (flexarm excite --kind random-odd)"
        )

    freq = exc * fs / P
    frd = control.FrequencyResponseData(
        G[:, None, :], 2 * np.pi * freq, inputs=[input_name], outputs=names
    )
    spectra = {"lines": np.arange(F.shape[-1]), "mean": mean, "var": var, "M": M, "excited": exc}
    return PeriodicFRF(
        frd,
        G,
        freq,
        exc,
        names,
        input_name,
        noise_std,
        total_std,
        distortion,
        P,
        float(fs),
        M,
        nt,
        spectra,
        notes,
    )


def lpm_frf(
    u: np.ndarray,
    y: Mapping[str, np.ndarray],
    fs: float,
    *,
    order: int = 2,
    half_width: int = 5,
    f_min: float | None = None,
    f_max: float | None = None,
    max_lines: int = 2000,
    input_name: str = "input",
    reference: np.ndarray | None = None,
    source: str = "<data>",
) -> PeriodicFRF:
    """FRF of a record that is not periodic or not in steady state: the local polynomial
    method (LPM; Pintelon & Schoukens 2012). With the DFTs U(k), Y(k) of the whole record
    (N samples), around each line k and r = −n..n (n = ``half_width``),

        Y(k+r) = Σ_{s=0}^{R} g_s r^s U(k+r) + Σ_{s=0}^{R} t_s r^s + V(k+r),   R = ``order``,

    G(k) = g_0 (the FRF, θ-independent of the transient, which the smooth t-polynomial
    absorbs along with leakage), by least squares over the 2n+1 lines. The noise variance
    from the residual, σ̂²_V = ‖e‖²/q with q = 2n+1 − 2(R+1) degrees of freedom, and
    var Ĝ(k) = σ̂²_V [(KᴴK)⁻¹]_00 (K the local regressor matrix) give ``noise_std``. The
    input is taken as exact (noise on it biases G as in any direct estimate).

    Closed loop (``reference`` given, the indirect method): the same local model with the
    reference R as regressor, for the input and each output; G = G_yr/G_ur, and to first
    order var G = |G|² (var G_yr/|G_yr|² + var G_ur/|G_ur|² − 2 Re(cov/(G_yr G_ur*))),
    the covariance from the residuals' cross-product (the loop makes the input's and the
    output's noise correlated, which biases the direct estimate; this one is not biased
    by it). Lines in
    [f_min, f_max] (default the whole band the windows fit), at most ``max_lines`` of them
    evenly spread. Returned as a :class:`PeriodicFRF` with ``period`` = N, one "period"
    used, no distortion table (detection lines need a periodic excitation)."""
    names = list(y)
    chans = {input_name: np.asarray(u, float), **{k: np.asarray(v, float) for k, v in y.items()}}
    if reference is not None:
        chans["reference"] = np.asarray(reference, float)
    for k, v in chans.items():
        if v.ndim != 1 or not np.all(np.isfinite(v)):
            raise IdentificationError(f"{source}: signal {k!r} must be 1-D and finite")
    lens = {k: len(v) for k, v in chans.items()}
    if len(set(lens.values())) > 1:
        raise IdentificationError(
            f"{source}: channels of different lengths: "
            + ", ".join(f"{k} {n}" for k, n in lens.items())
        )
    check_live_channels(chans, input_name, source)
    R, n = int(order), int(half_width)
    q = 2 * n + 1 - 2 * (R + 1)
    if R < 0 or q < 1:
        raise IdentificationError(
            f"{source}: LPM order {R} with half_width {n} leaves {q} "
            "degrees of freedom; need 2·half_width + 1 > 2·(order + 1)"
        )
    N = lens[input_name]
    X = np.fft.rfft(np.stack(list(chans.values())), axis=-1) / np.sqrt(N)
    df = fs / N
    k0 = max(n + 1, int(np.ceil((f_min or 0) / df)))
    k1 = min(X.shape[-1] - n - 2, int(np.floor(f_max / df)) if f_max else X.shape[-1])
    if k1 < k0:
        raise IdentificationError(
            f"{source}: {N} samples give no line in the band with "
            f"{n} lines on each side; record longer or widen the band"
        )
    reg = X[-1] if reference is not None else X[0]  # the local regressor's signal
    ks = np.arange(k0, k1 + 1)
    # lines whose window carries input: the local input energy above 1e-8 of the largest
    # (an unexcited window makes the regressor singular; G is not observable there)
    e_loc = np.convolve(np.abs(reg) ** 2, np.ones(2 * n + 1), mode="same")[ks]
    ks = ks[e_loc > 1e-8 * e_loc.max()]
    if ks.size == 0:
        raise IdentificationError(
            f"{source}: the input {input_name!r} carries no power in "
            "the band: no FRF line can be estimated"
        )
    if ks.size > max_lines:
        ks = ks[np.round(np.linspace(0, ks.size - 1, max_lines)).astype(int)]
    r = np.arange(-n, n + 1)
    idx = ks[:, None] + r[None, :]  # (L, 2n+1)
    Uw = reg[idx]
    pw = r[None, :, None] ** np.arange(R + 1)[None, None, :]  # (1, 2n+1, R+1)
    K = np.concatenate([Uw[:, :, None] * pw, np.broadcast_to(pw, Uw.shape + (R + 1,))], axis=-1)
    KhK = np.einsum("lri,lrj->lij", K.conj(), K)
    # rank check: a window with too few excited lines (e.g. a periodic multisine, whose
    # record DFT is zero off the period's lines) leaves G undetermined there: dropped
    # (R + 1 lines with input above 1e-6 of the window's largest; then the conditioning
    # of the column-scaled normal matrix, its scaling floored so round-off columns stay small)
    au = np.abs(Uw)
    enough = np.sum(au > 1e-6 * au.max(axis=1, keepdims=True), axis=1) >= R + 1
    dd = np.einsum("lii->li", KhK).real
    dg = 1 / np.sqrt(np.maximum(dd, 1e-12 * dd.max(axis=1, keepdims=True)))
    ev = np.linalg.eigvalsh(KhK * dg[:, :, None] * dg[:, None, :])
    ok = enough & (ev[:, 0] > 1e-10 * ev[:, -1])
    if not ok.any():
        raise IdentificationError(
            f"{source}: no window of {2 * n + 1} lines holds enough excited lines for the "
            f"local polynomial of order {R}: the LPM needs a broadband input (noise, a sweep, "
            "a full multisine); for a periodic multisine use the periodic method"
        )
    ks, K, KhK, idx = ks[ok], K[ok], KhK[ok], idx[ok]
    KhK_inv = np.linalg.inv(KhK)
    G = np.empty((len(names), ks.size), complex)
    sd = np.empty((len(names), ks.size))

    def local(x):
        """g_0 and the residual of the local model for the channel x."""
        w = x[idx]
        theta = np.einsum("lij,lrj,lr->li", KhK_inv, K.conj(), w)
        return theta[:, 0], w - np.einsum("lri,li->lr", K, theta)

    p00 = KhK_inv[:, 0, 0].real
    if reference is not None:
        gu, eu = local(X[0])
    for j in range(len(names)):
        gy, ey = local(X[1 + j])
        if reference is None:
            G[j] = gy
            sd[j] = np.sqrt(np.sum(np.abs(ey) ** 2, axis=1) / q * p00)
            continue
        vy = np.sum(np.abs(ey) ** 2, axis=1) / q * p00
        vu = np.sum(np.abs(eu) ** 2, axis=1) / q * p00
        cyu = np.sum(ey * eu.conj(), axis=1) / q * p00
        G[j] = gy / gu
        sd[j] = np.abs(G[j]) * np.sqrt(
            np.maximum(
                vy / np.abs(gy) ** 2 + vu / np.abs(gu) ** 2 - 2 * np.real(cyu / (gy * gu.conj())), 0
            )
        )
    freq = ks * df
    frd = control.FrequencyResponseData(
        G[:, None, :], 2 * np.pi * freq, inputs=[input_name], outputs=names
    )
    return PeriodicFRF(
        frd,
        G,
        freq,
        ks,
        names,
        input_name,
        sd,
        None,
        None,
        N,
        float(fs),
        1,
        0,
        {},
        [
            f"{source}: local polynomial method (order {R}, {2 * n + 1} lines, "
            f"{q} dof per line"
            + (", indirect through the reference)" if reference is not None else ")")
        ],
    )


def combine_realisations(results: Sequence[PeriodicFRF], source: str = "<data>") -> PeriodicFRF:
    """The BLA over R ≥ 2 realisations (records with new random phases, same lines), the
    robust method (Pintelon & Schoukens 2012):

        G_BLA,k = (1/R) Σ_r G_r,k,
        var_noise G_BLA,k = (1/R²) Σ_r var_noise G_r,k,
        var_total G_BLA,k = Σ_r |G_r,k − G_BLA,k|² / (R (R − 1)),

    the last the sample variance of the mean over realisations: noise plus the stochastic
    nonlinear contributions, which change with the phases (no detection lines needed).
    The distortion table is the power mean of the realisations' levels per band. Raises
    :class:`IdentificationError` when the records disagree on lines, outputs or rate."""
    rs = list(results)
    if len(rs) < 2:
        raise IdentificationError(
            f"{source}: the robust BLA needs at least two realisations; got {len(rs)}"
        )
    first = rs[0]
    for k, r in enumerate(rs[1:], 2):
        if (
            r.outputs != first.outputs
            or r.fs != first.fs
            or r.period != first.period
            or not np.array_equal(r.lines, first.lines)
        ):
            raise IdentificationError(
                f"{source}: realisation {k} differs from the first in its excited lines, "
                f"outputs, period or sampling rate ({r.outputs} at {r.fs:g} Hz, {r.period} "
                f"samples, {len(r.lines)} lines vs {first.outputs} at {first.fs:g} Hz, "
                f"{first.period} samples, {len(first.lines)} lines): one design per call"
            )
    R = len(rs)
    G = np.stack([r.response for r in rs])  # (R, ny, K)
    Gm = G.mean(axis=0)
    noise = np.sqrt(np.sum(np.stack([r.noise_std for r in rs]) ** 2, axis=0)) / R
    total = np.sqrt(np.sum(np.abs(G - Gm) ** 2, axis=0) / (R * (R - 1)))
    dist = None
    dists = [r.distortion for r in rs]
    if all(d is not None for d in dists):

        def pmean(vals):
            v = [x for x in vals if math.isfinite(x)]
            return 10 * math.log10(np.mean([10 ** (x / 10) for x in v])) if v else math.nan

        dist = {
            n: [
                Band(
                    bs[0].band_hz,
                    pmean([b.odd_db for b in bs]),
                    pmean([b.even_db for b in bs]),
                    pmean([b.noise_db for b in bs]),
                )
                for bs in zip(*(d[n] for d in dists if d is not None), strict=False)
            ]
            for n in first.outputs
        }
    frd = control.FrequencyResponseData(
        Gm[:, None, :], 2 * np.pi * first.frequency_hz, inputs=[first.input], outputs=first.outputs
    )
    notes = [w for r in rs for w in r.warnings]
    notes.append(
        f"{source}: BLA over {R} realisations (robust method): total_std from their spread"
    )
    return PeriodicFRF(
        frd,
        Gm,
        first.frequency_hz,
        first.lines,
        first.outputs,
        first.input,
        noise,
        total,
        dist,
        first.period,
        first.fs,
        sum(r.periods_used for r in rs),
        first.transient_periods,
        {},
        notes,
    )


def periodic_change(xp: np.ndarray) -> float:
    """Power of the difference of consecutive periods over the power of the signal (rows =
    periods): 2σ²/(P_s + σ²) for a periodic signal with white noise σ², ≈ 2 when the period
    is wrong."""
    x = xp - xp.mean()
    return float(np.mean(np.diff(x, axis=0) ** 2) / max(np.mean(x**2), 1e-300))


def plot_distortion(res: PeriodicFRF, path=None):
    """The usual figure: output spectrum at excited lines, noise level, odd and even
    detection lines, in dB (one axis per output); returns the matplotlib
    :class:`~matplotlib.figure.Figure` (no pyplot, no backend switch)."""
    from matplotlib.figure import Figure

    sp = res.spectra
    if not sp:  # LPM or several realisations: the FRF with its standard deviations
        fig = Figure(figsize=(8, 3.2 * len(res.outputs)))
        axes = fig.subplots(len(res.outputs), 1, squeeze=False)

        def db(a):
            return 20 * np.log10(np.maximum(np.abs(a), 1e-300))

        for j, (ax, name) in enumerate(zip(axes[:, 0], res.outputs, strict=True)):
            ax.plot(res.frequency_hz, db(res.response[j]), "k+", label="FRF")
            ax.plot(res.frequency_hz, db(res.noise_std[j]), "g-", lw=0.8, label="noise std")
            if res.total_std is not None:
                ax.plot(res.frequency_hz, db(res.total_std[j]), "r-", lw=0.8, label="total std")
            _style(ax, name)
        return _finish(fig, axes, path)
    df = res.fs / res.period
    exc = res.lines
    kmax = int(exc.max())
    ks = np.arange(1, min(2 * kmax, len(sp["lines"]) - 1) + 1)
    other = np.setdiff1d(ks, exc)
    odd = bool(np.all(exc % 2 == 1))
    fig = Figure(figsize=(8, 3.2 * len(res.outputs)))
    axes = fig.subplots(len(res.outputs), 1, squeeze=False)
    for j, (ax, name) in enumerate(zip(axes[:, 0], res.outputs, strict=True)):
        y = sp["mean"][1 + j]
        n = np.sqrt(sp["var"][1 + j] / sp["M"])

        def db(a):
            return 20 * np.log10(np.maximum(np.abs(a), 1e-300))

        ax.plot(exc * df, db(y[exc]), "k+", label="output, excited lines")
        o = other[other % 2 == 1] if odd else other
        ax.plot(
            o * df, db(y[o]), "ro", ms=3, label="odd detection lines" if odd else "detection lines"
        )
        if odd:
            e = other[other % 2 == 0]
            ax.plot(e * df, db(y[e]), "bx", ms=3, label="even detection lines")
        ax.plot(ks * df, db(n[ks]), "g-", lw=0.8, label="noise (std of the mean)")
        _style(ax, name)
    return _finish(fig, axes, path)


def _style(ax, name: str) -> None:
    """One output's axes of the FRF figures: dB over a log frequency axis."""
    ax.set_ylabel(f"{name} (dB)")
    ax.set_xscale("log")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)


def _finish(fig, axes, path):
    """Label, lay out and (with ``path``) write the figure through the one writer."""
    axes[-1, 0].set_xlabel("frequency (Hz)")
    fig.tight_layout()
    if path is not None:
        from flexarm.io.write import save_figure

        save_figure(fig, path, overwrite=True, dpi=120)
    return fig


def plot_bode(res: PeriodicFRF, path=None, model=None):
    """The Bode figure of the FRF (:func:`.bode.bode_figure`): magnitude (dB) and phase (deg)
    of G at the excited lines with the ±2σ band (the BLA's total std where there are
    detection lines or several realisations, else the noise std), and ``model`` (ω in
    rad/s → {output: Ĝ(jω)}) when given. Written to ``path`` when given."""
    from flexarm.identification.frequency_domain.bode import bode_figure

    sd = res.total_std if res.total_std is not None else res.noise_std
    data = {n: res.response[j] for j, n in enumerate(res.outputs)}
    return bode_figure(
        res.frequency_hz,
        data,
        {n: sd[j] for j, n in enumerate(res.outputs)},
        model,
        title=f"FRF from {res.input} (±2σ: "
        f"{'total' if res.total_std is not None else 'noise'} std)",
        path=path,
    )
