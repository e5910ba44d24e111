"""Standard errors of a least-squares fit whose residuals are autocorrelated.

For residuals r (m,) and their Jacobian J (m, p) at the optimum of min ‖r(z)‖², the
linearised estimate is δz = −(JᵀJ)⁻¹ Jᵀ r, so

    cov(ẑ) = (JᵀJ)⁻¹ · cov(Jᵀ r) · (JᵀJ)⁻¹                          (sandwich)

With independent residuals of one variance s², cov(Jᵀ r) = s² JᵀJ and this is the usual
``s² (JᵀJ)⁻¹`` (:func:`iid_covariance`). Output-error residuals of a simulated loop are
nothing like independent: model error, filtered sensors, the encoder's quantisation
error of a hub at rest or moving slowly, all persist for tens to hundreds of samples, and
s² (JᵀJ)⁻¹ then understates the spread of ẑ by the square root of the residuals'
correlation time (in samples), easily 10-30×.

:func:`hac_covariance` estimates the middle factor by Newey–West (heteroscedasticity and
autocorrelation consistent, HAC): per log l the score series g_t = Σ_channels J_t r_t
(p,) over the samples t (both channels of one instant summed: their residuals share the
same model error), and

    Ŝ = Σ_l [ Γ_l,0 + Σ_{k=1}^{M_l} w_k (Γ_l,k + Γ_l,kᵀ) ],   Γ_l,k = Σ_t g_t g_{t+k}ᵀ,
    w_k = 1 − k / (M_l + 1)                                              (Bartlett)

logs being independent experiments. The Bartlett sum is computed exactly, in O(N p²), as
Ŝ_l = 1/(M+1) Σ_s B_s B_sᵀ with B_s = Σ_{t=s}^{s+M} g_t the moving sums of M + 1 scores
(zero beyond the log's ends); it is positive semi-definite by construction.

Bandwidth rule (per log): for each channel, the residual's correlation time τ_c = the
first lag at which its sample autocorrelation falls below 1/e (an AR(1) with coefficient
ρ has τ = −1/ln ρ); M_l = ``factor`` · max_c τ_c with factor 10, at least 1 and at most
N_l / 4. Why 10: for an exponential autocorrelation the Bartlett window of width M keeps
the fraction 1 − (τ/M)(1 − e^{−M/τ}) of the long-run variance, 90 % at M = 10 τ (57 % at
2 τ, which is what Andrews' MSE-optimal AR(1) plug-in gives for ρ → 1 on logs of a few
thousand samples: good MSE, too small std). Why N/4: at an optimum the scores sum to
zero (over all logs), so windows comparable to the log length cancel what they should
measure (the "fixed-b" bias, Kiefer & Vogelsang 2005: E Ŝ ≈ (1 − b + b²/3) S for
b = M/N, 0.77 at N/4); each log's Ŝ_l is divided by that factor.
"""

from __future__ import annotations

import numpy as np

BANDWIDTH_FACTOR = 10.0
MAX_FRACTION = 0.25


def correlation_time(x: np.ndarray) -> int:
    """First lag (samples, >= 1) at which the sample autocorrelation of ``x`` (zeros where
    unused are allowed: they only dilute it) falls below 1/e; ``len(x)`` if never."""
    x = np.asarray(x, float)
    n = x.size
    if n < 2 or not np.any(x):
        return 1
    nf = 1 << int(np.ceil(np.log2(2 * n)))
    f = np.fft.rfft(x, nf)
    ac = np.fft.irfft(f * np.conj(f), nf)[:n]
    ac = ac / ac[0]
    below = np.nonzero(ac < np.exp(-1.0))[0]
    return int(below[0]) if below.size else n


def bandwidth(
    r: np.ndarray, factor: float = BANDWIDTH_FACTOR, max_fraction: float = MAX_FRACTION
) -> int:
    """Bartlett bandwidth M (samples) of one log from its residuals ``r`` (C, N) (channels
    × samples): ``factor`` × the longest channel correlation time, in [1, max_fraction N]."""
    r = np.atleast_2d(r)
    tau = max(correlation_time(rc) for rc in r)
    n = r.shape[-1]
    return int(max(1, min(round(factor * tau), int(max_fraction * n))))


def bartlett_meat(g: np.ndarray, M: int) -> np.ndarray:
    """Σ_{|k|<=M} (1 − |k|/(M+1)) Σ_t g_t g_{t+k}ᵀ for a score series g (N, p), computed as
    1/(M+1) Σ_s B_s B_sᵀ over the moving sums B_s of M + 1 consecutive scores."""
    g = np.asarray(g, float)
    n, p = g.shape
    c = np.concatenate([np.zeros((1, p)), np.cumsum(g, axis=0)])  # c[t] = Σ_{u<t} g_u
    # window s covers t in [s, s+M] ∩ [0, n-1], s = -M ... n-1
    s = np.arange(-M, n)
    hi = np.minimum(s + M + 1, n)
    lo = np.maximum(s, 0)
    B = c[hi] - c[lo]
    return (B.T @ B) / (M + 1)


def iid_covariance(r: np.ndarray, J: np.ndarray) -> np.ndarray:
    """s² (JᵀJ)⁺ with s² = ‖r‖² / (m − p): independent residuals of one variance."""
    m, p = J.shape
    s2 = float(r @ r) / max(m - p, 1)
    return np.linalg.pinv(J.T @ J) * s2


def hac_covariance(
    r: np.ndarray,
    J: np.ndarray,
    *,
    factor: float = BANDWIDTH_FACTOR,
    max_fraction: float = MAX_FRACTION,
    prior_jac: np.ndarray | None = None,
) -> tuple[np.ndarray, list[int]]:
    """Newey–West sandwich covariance (JᵀJ)⁺ Ŝ (JᵀJ)⁺ · m/(m − p) (see the module doc).

    ``r``: residuals (C, L, N) (channels, logs, samples), 0 where a sample is not used;
    ``J``: their Jacobian (C, L, N, p); ``prior_jac``: the Jacobian (n_priors, p) of prior
    rows, whose information joins both: H = JᵀJ + J_pᵀJ_p, cov = H⁺ (Ŝ + J_pᵀJ_p) H⁺.
    Returns the covariance (p, p) and the bandwidth M_l (samples) used for each log."""
    C, L, N = r.shape
    p = J.shape[-1]
    Jf = J.reshape(-1, p)
    Ip = prior_jac.T @ prior_jac if prior_jac is not None else np.zeros((p, p))
    A = np.linalg.pinv(Jf.T @ Jf + Ip)
    S = Ip.copy()
    Ms = []
    for li in range(L):
        used = np.nonzero(np.any(r[:, li] != 0, axis=0) | np.any(J[:, li] != 0, axis=(0, 2)))[0]
        if used.size == 0:
            Ms.append(0)
            continue
        a, b = used[0], used[-1] + 1
        rl = r[:, li, a:b]
        M = bandwidth(rl, factor, max_fraction)
        g = np.einsum("ct,ctp->tp", rl, J[:, li, a:b])
        fb = M / (b - a)
        S += bartlett_meat(g, M) / (1.0 - fb + fb**2 / 3.0)
        Ms.append(M)
    m = int(np.count_nonzero(np.any(J != 0, axis=-1) | (r != 0)))
    cov = A @ S @ A * (m / max(m - p, 1))
    return 0.5 * (cov + cov.T), Ms
