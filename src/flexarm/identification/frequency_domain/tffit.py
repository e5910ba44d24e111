"""Fit a rational transfer function to frequency-response data.

Model, with k = ``integrators`` poles at the origin:

    H(s) = N(s) / (s^k D(s)),   deg N = n_zeros,  deg D = n_poles − k,  D monic.

Frequency scaling s̃ = s/ω_s with ω_s the geometric mean of the data frequencies keeps the
coefficient problem well conditioned; the coefficients are fitted in s̃ and converted at
the end.  Steps:

1. Levy's linear start: minimise Σ w_k² |N(s̃_k) − H_k s̃_k^k D(s̃_k)|² (linear in the
   coefficients).
2. Sanathanan–Koerner iterations: the same with each term divided by |D_prev(s̃_k)|, so the
   cost tends to Σ w_k² |N/D − H s̃^k|² (poles in the right half-plane are reflected).
3. Nonlinear weighted least squares (``scipy.optimize.least_squares``) on the complex
   log-ratio ln(Ĥ_k/H_k) = ln|Ĥ_k/H_k| + j∠(Ĥ_k/H_k): log-magnitude and phase errors with
   equal weight (the same measure as FRB eq. (6)); kept only if it lowers that cost and
   leaves D stable. Where a trial N or D vanishes on a datum the residual is a large
   finite penalty, not log 0; a refinement that hits its evaluation limit warns, and
   ``TFFit.message`` says how it ended.

Weights ``w_k`` (default 1) multiply the relative errors: step 1-2 use w_k/|H_k| (relative
error), step 3 w_k. Returned: a python-control ``TransferFunction`` (descending powers of
s, monic denominator) and the per-frequency relative error |Ĥ − H|/|H|.
"""

from __future__ import annotations

import warnings

from typing import NamedTuple

import control
import numpy as np
from scipy.optimize import least_squares
from flexarm.identification.frequency_domain.tfest import reflect_unstable_roots


class TFFit(NamedTuple):
    """Fitted transfer function and the relative error |Ĥ(jω) − H|/|H| at each datum."""

    tf: control.TransferFunction
    relative_error: np.ndarray
    # How the nonlinear refinement ended: least_squares' status message, or why the
    # Sanathanan–Koerner estimate was kept ("" when refine=False or nothing to refine).
    message: str = ""


# Log-ratio residual where the trial model's N or D vanishes on a datum (log 0): large
# (a factor e^50) and finite, so least_squares' Jacobian stays finite.
_PENALTY = 50.0


def _polyval_asc(c: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Σ c_i s^i (ascending coefficients)."""
    return np.polynomial.polynomial.polyval(s, c)


def _linear_step(s, Hr, w, nz, nd, d_prev):
    """Levy / SK step: unknowns b_0..b_nz, a_0..a_{nd-1} (D monic)."""
    wt = w / np.abs(d_prev)
    cols = [s**i for i in range(nz + 1)] + [-Hr * s**i for i in range(nd)]
    A = np.column_stack(cols) * wt[:, None]
    rhs = Hr * s**nd * wt
    Ar = np.vstack([A.real, A.imag])
    br = np.concatenate([rhs.real, rhs.imag])
    colscale = np.linalg.norm(Ar, axis=0)
    colscale[colscale == 0] = 1.0
    x = np.linalg.lstsq(Ar / colscale, br, rcond=None)[0] / colscale
    b = x[:nz + 1]
    a = np.concatenate([x[nz + 1:], [1.0]])
    return b, a


def fit_tf(omega, H, n_zeros: int, n_poles: int, integrators: int = 0, weights=None, *,
           sk_iterations: int = 30, refine: bool = True) -> TFFit:
    """Fit H(s) = N(s)/(s^k D(s)) to samples ``H`` at ``omega`` (rad/s); see module docstring.

    ``n_zeros``: degree of N; ``n_poles``: total number of poles (including the
    ``integrators`` at s = 0); ``weights``: optional per-frequency weights of the relative
    error.
    """
    omega = np.asarray(omega, dtype=float)
    H = np.asarray(H, dtype=complex)
    if omega.shape != H.shape or omega.ndim != 1:
        raise ValueError("omega and H must be 1-D arrays of the same length")
    nd = n_poles - integrators
    if integrators < 0 or nd < 0 or n_zeros < 0:
        raise ValueError(f"orders: n_zeros={n_zeros}, n_poles={n_poles}, "
                         f"integrators={integrators}: need 0 <= integrators <= n_poles")
    n_par = n_zeros + 1 + nd
    if 2 * len(omega) < n_par:
        raise ValueError(f"{len(omega)} frequencies give {2 * len(omega)} real equations, "
                         f"fewer than the {n_par} coefficients of a fit with {n_zeros} zeros "
                         f"and {n_poles} poles")
    if np.any(omega <= 0) or np.any(H == 0) or not np.all(np.isfinite(H)):
        raise ValueError("fit_tf needs omega > 0 and finite, nonzero H")
    w = np.ones_like(omega) if weights is None else np.asarray(weights, dtype=float)

    ws = float(np.exp(np.mean(np.log(omega))))
    s = 1j * omega / ws
    Hr = H * s**integrators  # N/D in the scaled variable
    wl = w / np.abs(Hr)

    d_prev = np.ones_like(s)
    b, a = _linear_step(s, Hr, wl, n_zeros, nd, d_prev)
    for _ in range(sk_iterations):
        a = reflect_unstable_roots(a)
        d_prev = _polyval_asc(a, s)
        b_new, a_new = _linear_step(s, Hr, wl, n_zeros, nd, d_prev)
        change = np.linalg.norm(np.concatenate([b_new - b, a_new - a])) / max(
            np.linalg.norm(np.concatenate([b_new, a_new])), 1e-300)
        b, a = b_new, a_new
        if change < 1e-10:
            break
    a = reflect_unstable_roots(a)
    # Rescale N for the best fit with the stabilised D (linear in b).
    dv = _polyval_asc(a, s)
    A = np.column_stack([s**i / dv for i in range(n_zeros + 1)]) * wl[:, None]
    b = np.linalg.lstsq(np.vstack([A.real, A.imag]),
                        np.concatenate([(Hr * wl).real, (Hr * wl).imag]), rcond=None)[0]

    def resid(p):
        bb = p[:n_zeros + 1]
        aa = np.concatenate([p[n_zeros + 1:], [1.0]])
        with np.errstate(all="ignore"):
            r = np.log(_polyval_asc(bb, s) / _polyval_asc(aa, s) / Hr) * w
            r = np.concatenate([r.real, r.imag])
        return np.where(np.isfinite(r), r, _PENALTY)

    p0 = np.concatenate([b, a[:-1]])
    best = p0
    message = ""
    if refine and n_par > 0:
        c0 = resid(p0)
        cost0 = float(c0 @ c0)
        sol = least_squares(resid, p0, method="trf", x_scale="jac", xtol=1e-14,
                            ftol=1e-14, gtol=1e-14, max_nfev=200 * (n_par + 1))
        c1 = resid(sol.x)
        cost1 = float(c1 @ c1)
        a1 = np.concatenate([sol.x[n_zeros + 1:], [1.0]])
        stable = nd == 0 or np.all(np.roots(a1[::-1]).real <= 0)
        if cost1 <= cost0 and stable:
            best = sol.x
            message = str(sol.message)
        else:
            message = ("Sanathanan–Koerner estimate kept: the refinement "
                       + ("left an unstable denominator" if not stable else "did not lower the cost"))
        if sol.status == 0:
            warnings.warn(
                f"fit_tf ({n_zeros} zeros, {n_poles} poles): the nonlinear refinement stopped "
                f"at its evaluation limit without converging ({sol.message}); the fit is "
                "usable but not a least-squares optimum: check the orders or pass refine=False",
                RuntimeWarning, stacklevel=2)
    b = best[:n_zeros + 1]
    a = np.concatenate([best[n_zeros + 1:], [1.0]])

    # Back to s: num coeff of s^i is b_i ws^(k+nd-i); den coeff of s^(i+k) is a_i ws^(nd-i).
    num = np.array([b[i] * ws ** (integrators + nd - i) for i in range(n_zeros + 1)])[::-1]
    den = np.concatenate([[a[i] * ws ** (nd - i) for i in range(nd + 1)][::-1],
                          np.zeros(integrators)])
    num = np.trim_zeros(num, "f") if np.any(num != 0) else np.array([0.0])
    tf = control.tf(num, den)
    Hhat = _polyval_asc(num[::-1], 1j * omega) / _polyval_asc(den[::-1], 1j * omega)
    return TFFit(tf, np.abs(Hhat - H) / np.abs(H), message)


def tf_coefficients(tf: control.TransferFunction) -> dict[str, list[float]]:
    """{num: [...], den: [...]} of a SISO transfer function, descending powers of s."""
    num = np.atleast_1d(np.squeeze(tf.num[0][0])).astype(float)
    den = np.atleast_1d(np.squeeze(tf.den[0][0])).astype(float)
    return {"num": [float(x) for x in num], "den": [float(x) for x in den]}


def tf_response(tf: control.TransferFunction, omega) -> np.ndarray:
    """H(jω) of a SISO transfer function at ``omega`` (rad/s)."""
    c = tf_coefficients(tf)
    s = 1j * np.asarray(omega, dtype=float)
    return np.polyval(c["num"], s) / np.polyval(c["den"], s)
