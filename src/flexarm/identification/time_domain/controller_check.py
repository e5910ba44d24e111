"""Check the declared control law against the logged command, before fitting anything.

The bench law (:mod:`flexarm.control.state_feedback`) computed from the logged signals,

    u_k = K1 (r − θ)_{k−m} − K2 d_{k−m} − K3 θ̇_{k−m} − K4 ḋ_{k−m},

is regressed on the logged command ``voltage`` for each computation delay m in ``delays``
(samples) and each constant-gain segment of the log (gains that change inside a log are
regressed per segment): the regressors are the law's terms x = (r − θ, −d, −θ̇, −ḋ), so the
coefficients are K1..K4 in SI (V/rad, V/m, V·s/rad, V·s/m). The rates are the logged
``motor_velocity`` / ``tip_velocity`` when the log has them (a logger's own derivatives),
else backward differences x_k − x_{k−1} over T. A term whose regressor is constant (a
rigid arm's tip) cannot be identified and is reported as NaN.

Samples left out: the ``glitch`` seconds after each reference step (loggers of this kind
write a short burst that the law does not produce: up to 12 samples at 1 kHz on the rig
logs, hence 20 ms), and the samples at the amplifier's limit. The fit is robust (Huber
loss, ``scipy.optimize.least_squares``, scale 1.4826·MAD of the least-squares
residuals, at least the logger's 1e-3 V rounding) and its standard errors are the
Newey–West (HAC) ones of :mod:`flexarm.identification.time_domain.uncertainty` (the residuals are
autocorrelated). R² = 1 − Σ res² / Σ (u − ū)² over the samples used; the best delay is the
one with the largest R².

Saturation is detected from the log: with a first fit's law û, samples where |û| exceeds
|u| by more than max(5 %, 0.05 V) with the same sign, and |u| above half its largest value,
are candidates; with at least 10 of them the limit is their median |u|, and every sample
with |u| ≥ 0.99 · limit is taken as saturated.

A gain disagrees with the declaration when the difference matters (it moves the command by
more than 1 % of the command's rms) and either its sign is opposite or it is off by more
than max(10 %, 4 σ); that is a :class:`~flexarm.identification.time_domain.logs.FitInputError`
naming the gain,
unless ``use_regressed=True`` (``--use-regressed-law``): then :meth:`ControllerCheck.apply`
gives the log with the regressed gains.

The rate filter: a logger's velocity columns are compared with the backward difference of
its positions, filtered by the first-order s/(τ s + 1) of ``rate="filtered"`` (backward
Euler, as the simulated controller); τ minimising the residual is reported per channel.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from scipy.optimize import least_squares, minimize_scalar
from scipy.signal import lfilter

from flexarm.identification.time_domain.logs import GAINS, FitInputError
from flexarm.identification.time_domain.uncertainty import hac_covariance
from flexarm.io.logs import Log

#: Seconds after a reference step left out (the logged command's glitch).
GLITCH_S = 0.02
#: Relative and absolute tolerances of a gain against its declaration, and the σ multiple.
REL_TOL, N_SIGMA = 0.10, 4.0
#: A difference matters when it moves the command by more than this fraction of its rms.
MATERIAL = 0.01
#: Fewest samples a segment needs to be regressed.
MIN_SEGMENT = 50
_RATES = (("motor_angle", "motor_velocity"), ("tip_deflection", "tip_velocity"))


@dataclass
class ControllerCheck:
    """What the logged command says about the law (see the module docstring).

    Per constant-gain segment s (``segments[s]`` = [start, stop) samples): ``declared[s]``,
    ``regressed[s]`` and ``stderr[s]`` (K1..K4, SI; NaN where a term is not identifiable),
    at the best ``delay`` (samples). ``r2_by_delay``: R² of each delay tried.
    """

    log: str
    segments: list[tuple[int, int]]
    declared: np.ndarray
    regressed: np.ndarray
    stderr: np.ndarray
    r2: float
    delay: int
    r2_by_delay: dict[int, float]
    rates: str
    saturation_limit: float | None
    saturation_fraction: float
    declared_limit: float | None
    glitch_samples: int
    samples_used: int
    rate_tau: dict[str, float] = field(default_factory=dict)
    rate_r2: dict[str, float] = field(default_factory=dict)
    disagreements: list[str] = field(default_factory=list)

    def to_dict(self) -> dict:
        """JSON-ready (NaN as null)."""

        def clean(x):
            a = np.asarray(x, float)
            return [[None if not np.isfinite(v) else float(v) for v in row] for row in a]

        return {
            "log": self.log,
            "segments": [list(s) for s in self.segments],
            "gains": list(GAINS),
            "declared": clean(self.declared),
            "regressed": clean(self.regressed),
            "stderr": clean(self.stderr),
            "r2": self.r2,
            "delay_samples": self.delay,
            "r2_by_delay": {str(k): v for k, v in self.r2_by_delay.items()},
            "rates": self.rates,
            "saturation_limit": self.saturation_limit,
            "saturation_fraction": self.saturation_fraction,
            "declared_limit": self.declared_limit,
            "glitch_samples": self.glitch_samples,
            "samples_used": self.samples_used,
            "rate_tau": self.rate_tau,
            "rate_r2": self.rate_r2,
            "disagreements": self.disagreements,
        }

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=2)

    def summary(self) -> str:
        lines = [
            f"{self.log}: controller check: R² {self.r2:.5f} at a computation delay of "
            f"{self.delay} sample(s) ("
            + ", ".join(f"{k}: {v:.5f}" for k, v in self.r2_by_delay.items())
            + f"); rates "
            f"{self.rates}; {self.samples_used} samples used, {self.glitch_samples} "
            "after reference steps left out"
        ]
        for s, (a, b) in enumerate(self.segments):
            terms = []
            for i, g in enumerate(GAINS):
                r, e, d = self.regressed[s, i], self.stderr[s, i], self.declared[s, i]
                reg = "n/a (term constant)" if not np.isfinite(r) else f"{r:.4g} ± {e:.2g}"
                terms.append(f"{g} {d:g} → {reg} {GAINS[g]}")
            lines.append(f"  samples {a}-{b}: " + "; ".join(terms))
        if self.saturation_limit is not None:
            lines.append(
                f"  saturation at ±{self.saturation_limit:.3g} V on "
                f"{100 * self.saturation_fraction:.2f} % of the samples"
                + (
                    f" (declared {self.declared_limit:g} V)"
                    if self.declared_limit is not None
                    else ""
                )
            )
        else:
            lines.append("  no saturation seen")
        for c, tau in self.rate_tau.items():
            lines.append(
                f"  {c}: the logged rate is the backward difference through "
                f"1/(τ s + 1) with τ = {1e3 * tau:.3g} ms (R² {self.rate_r2[c]:.3f})"
            )
        lines += [f"  disagrees: {d}" for d in self.disagreements]
        return "\n".join(lines)

    def apply(self, log: Log) -> Log:
        """``log`` with the regressed gains (declared ones where a term is not identifiable)."""
        g = np.array(log.gains, float)
        for s, (a, b) in enumerate(self.segments):
            reg = np.where(np.isfinite(self.regressed[s]), self.regressed[s], self.declared[s])
            g[a:b] = reg
        c = log.controller.model_copy(
            update=dict(zip(("k1", "k2", "k3", "k4"), map(float, g[0]), strict=True))
        )
        return replace(log, controller=c, gains=g)


def _terms(log: Log) -> tuple[np.ndarray, str]:
    """The law's regressors (N, 4): r − θ, −d, −θ̇, −ḋ, and where the rates came from."""
    c, T = log.columns, log.dt
    th = c["motor_angle"]
    d = c.get("tip_deflection", np.zeros_like(th))
    logged = all(v in c for _, v in _RATES if _ != "tip_deflection" or "tip_deflection" in c)
    if logged:
        thd = c["motor_velocity"]
        dd = c.get("tip_velocity", np.zeros_like(th))
    else:
        thd = np.diff(th, prepend=th[0]) / T
        dd = np.diff(d, prepend=d[0]) / T
    return np.column_stack([c["reference"] - th, -d, -thd, -dd]), (
        "logged" if logged else "backward"
    )


def _robust_fit(A: np.ndarray, y: np.ndarray):
    """Huber fit of y ≈ A b; returns b, residuals."""
    b0, *_ = np.linalg.lstsq(A, y, rcond=None)
    r0 = y - A @ b0
    scale = max(1.4826 * float(np.median(np.abs(r0 - np.median(r0)))), 1e-3)
    sol = least_squares(
        lambda b: A @ b - y,
        b0,
        loss="huber",
        f_scale=scale,
        jac=lambda b: A,  # pyright: ignore[reportArgumentType]  (scipy: jac is typed from its '2-point' default)
        method="trf",
    )
    return sol.x, y - A @ sol.x


def _rate_filter(log: Log) -> tuple[dict[str, float], dict[str, float]]:
    taus, r2s = {}, {}
    T = log.dt
    for pos, vel in _RATES:
        if pos not in log.columns or vel not in log.columns or np.ptp(log.columns[vel]) == 0:
            continue
        b = np.diff(log.columns[pos]) / T
        v = log.columns[vel][1:]

        def cost(tau, b=b, v=v):  # this iteration's b, v bound (B023)
            a = tau / (tau + T)
            f = lfilter([1 - a], [1, -a], b, zi=[a * v[0]])[0]
            return float(np.mean((v - f) ** 2))

        res: Any = minimize_scalar(
            cost, bounds=(0.0, 200 * T), method="bounded", options={"xatol": 1e-2 * T}
        )
        taus[vel] = float(res.x)
        r2s[vel] = 1.0 - res.fun / float(np.var(v))
    return taus, r2s


def check_controller(
    log: Log, *, delays=(0, 1, 2), use_regressed: bool = False, glitch: float = GLITCH_S
) -> ControllerCheck:
    """Regress the logged command on the declared law's terms (module docstring); raise
    :class:`FitInputError` naming the gain when it disagrees, unless ``use_regressed``."""
    where = log.path or log.name
    if "voltage" not in log.columns:
        raise FitInputError(
            f"{where}: field 'voltage': the controller check regresses the "
            "logged command, but the log has no voltage column; map it "
            "(log format [columns] voltage = ..., or --column voltage=NAME)"
        )
    if log.gains is None:
        raise FitInputError(
            f"{where}: field 'controller': no declared law to check; give the "
            "gains (log format [controller], a '# controller:' line, or "
            "--controller)"
        )
    if "motor_angle" not in log.columns:
        raise FitInputError(
            f"{where}: field 'motor_angle': the law closes on the hub angle, "
            "but the log has no motor_angle column"
        )
    delays = sorted({int(m) for m in delays})
    if not delays or delays[0] < 0:
        raise FitInputError(f"{where}: delays {delays}: give whole numbers of samples >= 0")
    u = log.columns["voltage"]
    X, rates = _terms(log)
    n = len(u)
    r = log.columns["reference"]
    dr = np.abs(np.diff(r))
    steps = np.flatnonzero(dr > max(10 * float(np.median(dr)), 0.0)) + 1
    G = max(int(round(glitch / log.dt)), 0)
    segs = [(a, b) for a, b in log.gain_segments]
    umax = float(np.max(np.abs(u)))

    best = None
    r2_by = {}
    for m in delays:
        glitch_mask = np.zeros(n, bool)
        for s in steps:
            glitch_mask[s : s + m + G] = True
        base = glitch_mask.copy()
        base[:m] = True  # no past signals for the first m samples
        Xm = np.vstack([np.zeros((m, 4)), X[: n - m]])
        # pass 1: the law with the declared gains' structure, fitted on all but glitches
        pred = np.zeros(n)
        for a, b in segs:
            rows = np.arange(a, b)[~base[a:b]]
            cols = np.ptp(Xm[rows], axis=0) > 0 if rows.size else np.zeros(4, bool)
            if rows.size >= MIN_SEGMENT and cols.any():
                coef, _ = _robust_fit(Xm[rows][:, cols], u[rows])
                pred[a:b] = Xm[a:b][:, cols] @ coef
        cand = (
            ~base
            & (np.sign(pred) == np.sign(u))
            & (np.abs(u) > 0.5 * umax)
            & (np.abs(pred) > np.abs(u) + np.maximum(0.05 * np.abs(u), 0.05))
        )
        limit = float(np.median(np.abs(u[cand]))) if cand.sum() >= 10 else None
        sat = np.abs(u) >= 0.99 * limit if limit is not None else np.zeros(n, bool)
        used = ~base & ~sat
        reg = np.full((len(segs), 4), np.nan)
        se = np.full((len(segs), 4), np.nan)
        res_all, y_all = [], []
        for s, (a, b) in enumerate(segs):
            rows = np.arange(a, b)[used[a:b]]
            if rows.size < MIN_SEGMENT:
                continue
            cols = np.ptp(Xm[rows], axis=0) > 0
            if not cols.any():
                continue
            A = Xm[rows][:, cols]
            coef, res = _robust_fit(A, u[rows])
            cov, _ = hac_covariance(res[None, None, :], A[None, None, :, :])
            reg[s, cols] = coef
            se[s, cols] = np.sqrt(np.maximum(np.diag(cov), 0.0))
            res_all.append(res)
            y_all.append(u[rows])
        if not res_all:
            raise FitInputError(
                f"{where}: too few samples to check the controller: no gain "
                f"segment keeps {MIN_SEGMENT} samples once the "
                f"{int(glitch_mask.sum())} after reference steps and the "
                f"{int(sat.sum())} saturated ones are left out"
            )
        res_c, y_c = np.concatenate(res_all), np.concatenate(y_all)
        r2 = 1.0 - float(res_c @ res_c) / max(float(np.sum((y_c - y_c.mean()) ** 2)), 1e-300)
        r2_by[m] = r2
        if best is None or r2 > best[0]:
            best = (r2, m, reg, se, limit, sat, glitch_mask, used, Xm)
    assert best is not None  # one delay at least (checked above)
    r2, m, reg, se, limit, sat, glitch_mask, used, Xm = best
    declared = np.array([log.gains[a] for a, _ in segs])
    taus, tr2 = _rate_filter(log)
    out = ControllerCheck(
        log=log.name,
        segments=segs,
        declared=declared,
        regressed=reg,
        stderr=se,
        r2=r2,
        delay=m,
        r2_by_delay=r2_by,
        rates=rates,
        saturation_limit=limit,
        saturation_fraction=float(sat.mean()),
        declared_limit=log.voltage_limit,
        glitch_samples=int(glitch_mask.sum()),
        samples_used=int(used.sum()),
        rate_tau=taus,
        rate_r2=tr2,
    )
    u_rms = float(np.sqrt(np.mean(u[used] ** 2)))
    for s, (a, b) in enumerate(segs):
        rows = np.arange(a, b)[used[a:b]]
        for i, g in enumerate(GAINS):
            d, rg, e = declared[s, i], reg[s, i], se[s, i]
            if not np.isfinite(rg):
                continue
            diff = abs(rg - d)
            x_rms = float(np.sqrt(np.mean(Xm[rows, i] ** 2))) if rows.size else 0.0
            if diff * x_rms <= MATERIAL * u_rms:
                continue
            opposite = d != 0 and np.sign(rg) != np.sign(d)
            tol = max(REL_TOL * abs(d), N_SIGMA * e)
            if not (opposite or diff > tol):
                continue
            why = (
                "opposite sign"
                if opposite
                else f"declared 0, but the term moves the command by {diff * x_rms:.3g} V rms"
                if d == 0
                else f"off by {100 * (rg - d) / abs(d):+.0f} %, more than "
                f"max(10 %, 4 σ = {N_SIGMA * e:.2g})"
            )
            seg = f" (samples {a}-{b})" if len(segs) > 1 else ""
            out.disagreements.append(
                f"{g}{seg}: declared {d:g} {GAINS[g]}, regressed "
                f"{rg:.4g} ± {e:.2g} {GAINS[g]}: {why}"
            )
    if out.disagreements and not use_regressed:
        raise FitInputError(
            f"{where}: the logged command disagrees with the declared law (R² {r2:.4f} at a "
            f"delay of {m} sample(s)):\n  " + "\n  ".join(out.disagreements) + "\n  fix the "
            "gains (their sign convention) in the log format's [controller] or the log's "
            "'# controller:' line, or pass use_regressed=True (--use-regressed-law) to use "
            "the regressed law"
        )
    return out


def checked_logs(
    logs: list[Log], *, use_regressed: bool = False
) -> tuple[list[Log], list[ControllerCheck]]:
    """The declared law of every log that carries one, a ``voltage`` and a ``motor_angle``
    column checked against its logged command (:func:`check_controller`); with
    ``use_regressed`` each such log comes back with the regressed law
    (:meth:`ControllerCheck.apply`). Logs without a law or those columns pass unchecked.
    Returns the logs and the checks made (in the logs' order)."""
    out, checks = [], []
    for log in logs:
        if log.gains is None or "voltage" not in log.columns or "motor_angle" not in log.columns:
            out.append(log)
            continue
        chk = check_controller(log, use_regressed=use_regressed)
        checks.append(chk)
        out.append(chk.apply(log) if use_regressed else log)
    return out, checks
