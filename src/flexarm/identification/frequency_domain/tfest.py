"""Transfer-function estimation from frequency-response data: ``flexarm.tfest``.

Model, with k = ``integrators`` poles at the origin and an optional delay τ:

    H(s) = N(s) / (s^k D(s)) · e^{−sτ},   deg N = n_zeros,  deg D = n_poles − k,  D monic.

Frequencies are scaled, s̃ = s/ω_s (ω_s the geometric mean of the data's), while fitting.

1. Linear start: Levy's linear least squares, then Sanathanan–Koerner iterations (each
   equation divided by |D_prev|), weighted by 1/σ_k; unstable roots of D reflected. With
   ``delay=True`` the start is the best of a grid of delays in [0, π/ω_max].
2. Weighted nonlinear least squares (``scipy.optimize.least_squares``, analytic Jacobian)
   of V(θ) = Σ_k |Ĥ(jω_k, θ) − H_k|² / σ_k²: with σ_k² the variance of the FRF estimate
   (noise, or the BLA's total variance) this is the maximum-likelihood cost of the FRF
   (the sample-ML cost linearised in the FRF; Pintelon & Schoukens 2012, Secs. 9.11, 10.2).
   ``cost="log"`` fits instead the complex log-ratio

       V_log(θ) = Σ_k w_k² |ln(Ĥ(jω_k, θ)/H_k)|²,   ln z = ln|z| + j∠z,

   log-magnitude (neper) and phase (rad) errors with equal weight, the measure of FRB
   eq. (6); w_k = |H_k|/σ_k (to first order ln(Ĥ/H) ≈ (Ĥ − H)/H, so with known variances
   V_log has the same χ² law as V) or 1. It suits data spanning many decades of |H| with
   relative errors (the sine experiments of FRB Sec. II), where V without variances is
   dominated by the largest |H|. A trial model whose N or D vanishes at a datum gets a
   large finite residual (50 neper), not ln 0.
3. Stability: with ``stable=True`` unstable poles are reflected and the fit redone; any
   left are reported (``unstable_poles``).
4. With known variances E[V] = F − n_θ/2 and std(V) = √(F − n_θ/2) (V = ½ χ² with 2F − n_θ
   degrees of freedom); the verdict is a two-sided chi-square test at 1 %.  Parameter
   covariance ½ (JᵀJ)⁻¹ (J the Jacobian of the real-stacked weighted residuals); without
   variances, relative weights 1/|H_k| and the covariance scaled by the residual variance.
   A rejected fit (cost above its 99 % range) also reports ``std_inflated`` = std ·
   √(V/E[V]) per parameter: the spread if the misfit were noise of a larger variance (a
   common, optimistic correction; model errors are not noise).
5. Order selection (:func:`tfest_orders`): AIC = 2V + 2n_θ, BIC = 2V + n_θ ln 2F.

Physical structures (the two-mass drive, FRB's single-mass arm, the voltage-driven servo)
are fitted with the same cost by
:func:`flexarm.identification.frequency_domain.structures.fit_structure`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import control
import numpy as np
from scipy.optimize import least_squares
from scipy.stats import chi2

from flexarm.display import Table
from flexarm.errors import FlexarmError  # the one error base (issue #25)


class TFEstError(FlexarmError, ValueError):
    """Bad data or orders for a frequency-domain fit; the message names the field."""


@dataclass
class TFEstimate:
    """A frequency-domain fit: the model, its cost against the expected, parameters.

    ``parameters.<name>`` = ``{value, std}`` (std from the covariance, valid when the
    model fits to the noise level) and, when the χ² check rejects the fit, ``std_inflated``
    = std·√(cost/expected_cost) beside it. ``relative_error`` is |Ĥ(jω_k) − H_k|/|H_k| per
    datum; ``message`` how the nonlinear solver ended; ``cost_kind`` "ml" or "log"."""

    tf: control.TransferFunction
    delay: float
    cost: float
    expected_cost: float | None
    cost_std: float | None
    parameters: dict[str, dict[str, float]]
    covariance: np.ndarray
    n_frequencies: int
    n_parameters: int
    unstable_poles: list[complex] = field(default_factory=list)
    residual: np.ndarray | None = None  # weighted complex residuals (model − data)/σ
    relative_error: np.ndarray | None = None
    message: str = ""
    cost_kind: str = "ml"

    @property
    def aic(self) -> float:
        return 2 * self.cost + 2 * self.n_parameters

    @property
    def bic(self) -> float:
        return 2 * self.cost + self.n_parameters * np.log(2 * self.n_frequencies)

    @property
    def verdict(self) -> str:
        return cost_verdict(
            self.cost,
            self.n_frequencies,
            self.n_parameters,
            self.expected_cost,
            self.unstable_poles,
        )

    def _table(self) -> Table:
        """One row per parameter: value, std (and the inflated std of a rejected fit)."""
        nz, npo = len(self.tf.num[0][0]) - 1, len(self.tf.den[0][0]) - 1
        title = (
            f"TFEstimate: {npo} poles, {nz} zeros"
            + (f", delay {self.delay:.4g} s" if self.delay else "")
            + f", {self.n_frequencies} frequencies"
        )
        inflated = any("std_inflated" in v for v in self.parameters.values())
        rows = [
            (n, v.get("value"), v.get("std"), *((v.get("std_inflated"),) if inflated else ()))
            for n, v in self.parameters.items()
        ]
        header = ("parameter", "value", "std") + (("std inflated",) if inflated else ())
        cost = f"cost {self.cost:.4g}" + (
            f", expected {self.expected_cost:.4g} ± {self.cost_std:.3g}"
            if self.expected_cost
            else ""
        )
        return Table(title, rows, header=header, notes=[cost, self.verdict])

    def __repr__(self) -> str:
        return self._table().text()

    def _repr_html_(self) -> str:
        return self._table().html()

    def response(self, omega) -> np.ndarray:
        s = 1j * np.asarray(omega, float)
        num, den = self.tf.num[0][0], self.tf.den[0][0]
        return np.polyval(num, s) / np.polyval(den, s) * np.exp(-s * self.delay)


def plot_fit(fit, frequency_hz, data, std=None, *, path=None):
    """The Bode figure of a frequency-domain fit (:func:`.bode.bode_figure`): the data
    (``data``: output name → complex G at ``frequency_hz``, Hz; or one array for a single
    output named ``"G"``) with its ±2σ band (``std``, same layout) and the fit, magnitude (dB)
    and phase (deg), and |fit − data|. ``fit`` is a :class:`TFEstimate` or a structure fit
    (:func:`.structures.fit_structure`), whose ``response(ω)`` gives one array or a dict by
    output. Written to ``path`` when given (the CLI's ``tfest.png``)."""
    from flexarm.identification.frequency_domain.bode import bode_figure

    if not isinstance(data, dict):
        data = {"G": data}
        std = None if std is None else {"G": std}
    names = list(data)

    def model(w):
        r = fit.response(w)
        return {k: v for k, v in r.items() if k in names} if isinstance(r, dict) else {names[0]: r}

    title = f"fit: cost {fit.cost:.4g}" + (
        f", expected {fit.expected_cost:.4g}" if fit.expected_cost else ""
    )
    return bode_figure(frequency_hz, data, std, model, title=title, path=path)


def cost_rejected(cost, F, n_par, expected) -> bool:
    """True when the cost lies above the 99 % range of ½χ²(2F − n_θ) (the verdict's test)."""
    if expected is None:
        return False
    return bool(cost > chi2.ppf(0.995, 2 * F - n_par) / 2)


def inflate_std(parameters: dict, cost, F, n_par, expected) -> dict:
    """Add ``std_inflated`` = std·√(cost/expected) to every parameter when the χ² check
    rejects the fit: the usual correction when the residual is larger than the noise
    (the misfit treated as white noise of a larger variance); optimistic, since model
    errors are neither random nor independent from line to line."""
    if not cost_rejected(cost, F, n_par, expected):
        return parameters
    k = float(np.sqrt(cost / expected))
    return {n: {**v, "std_inflated": v["std"] * k} for n, v in parameters.items()}


def cost_verdict(cost, F, n_par, expected, unstable=()) -> str:
    """Chi-square test of the ML cost (2V ~ χ² with 2F − n_θ degrees of freedom)."""
    extra = f"; {len(unstable)} unstable pole(s) remain" if len(unstable) else ""
    if expected is None:
        return "no variances given: the cost cannot be tested" + extra
    dof = 2 * F - n_par
    lo, hi = chi2.ppf([0.005, 0.995], dof) / 2
    if cost > hi:
        return (
            f"rejected: the cost {cost:.4g} is {cost / expected:.3g} times its expected "
            f"value {expected:.4g} (99 % range {lo:.4g}–{hi:.4g}): the model does not fit "
            "to the noise level (model errors or nonlinear distortion); the standard "
            "deviations 'std' hold for noise only, 'std_inflated' "
            f"(× {np.sqrt(cost / expected):.3g}) "
            "treat the misfit as extra noise" + extra
        )
    if cost < lo:
        return (
            f"suspicious: the cost {cost:.4g} is below its 99 % range {lo:.4g}–{hi:.4g}: "
            "the variances are overestimated or the model overfits" + extra
        )
    return (
        f"accepted: the cost {cost:.4g} lies within the 99 % range {lo:.4g}–{hi:.4g} of "
        f"its expected value {expected:.4g}: the model fits to the noise level" + extra
    )


def _frd_data(frd, output: int, input: int, std):
    omega = np.asarray(frd.omega, float)
    data = frd.frequency_response(omega) if not hasattr(frd, "frdata") else None
    H = np.asarray(frd.frdata if data is None else data.complex, complex)
    H = H.reshape(frd.noutputs, frd.ninputs, -1)[output, input]
    if std is not None:
        std = np.asarray(std, float)
        if std.ndim == 2:
            std = std[output]
        if std.shape != H.shape:
            raise TFEstError(f"std has shape {std.shape}; the FRD has {H.shape[0]} frequencies")
        if np.any(~np.isfinite(std)) or np.any(std <= 0):
            raise TFEstError("std must be finite and positive at every frequency")
    if np.any(omega <= 0) or not np.all(np.isfinite(H)) or np.any(H == 0):
        raise TFEstError("tfest needs frequencies > 0 and finite, nonzero responses")
    return omega, H, std


def _levy_sk(s, Hr, w, nz, nd, iterations=30):
    """Levy then SK: minimise Σ |w (N − Hr D)/D_prev|² over b (nz+1) and a (nd, D monic);
    unstable roots of D reflected; N re-solved for the final (stable) D."""
    d_prev = np.ones_like(s)
    pw = np.vander(s, max(nz, nd) + 1, increasing=True)
    b = a = None
    for _ in range(iterations + 1):
        wt = w / np.abs(d_prev)
        A = np.column_stack([pw[:, : nz + 1], -Hr[:, None] * pw[:, :nd]]) * wt[:, None]
        rhs = Hr * pw[:, nd] * wt
        Ar = np.vstack([A.real, A.imag])
        sc = np.linalg.norm(Ar, axis=0)
        sc[sc == 0] = 1
        x = np.linalg.lstsq(Ar / sc, np.concatenate([rhs.real, rhs.imag]), rcond=None)[0] / sc
        b_new, a_new = x[: nz + 1], np.r_[x[nz + 1 :], 1.0]
        a_new = reflect_unstable_roots(a_new)
        done = a is not None and np.linalg.norm(a_new - a) < 1e-12 * np.linalg.norm(a_new)
        b, a = b_new, a_new
        if done:
            break
        d_prev = np.polynomial.polynomial.polyval(s, a)
    # N for the best fit with the stabilised D (linear in b): Σ |w (N/D − Hr)|²
    assert a is not None and b is not None  # one iteration at least
    dv = np.polynomial.polynomial.polyval(s, a)
    A = pw[:, : nz + 1] / dv[:, None] * w[:, None]
    b = np.linalg.lstsq(
        np.vstack([A.real, A.imag]), np.concatenate([(Hr * w).real, (Hr * w).imag]), rcond=None
    )[0]
    return b, a


def reflect_unstable_roots(a):
    """Reflect right-half-plane roots of the monic polynomial ``a`` (ascending) into the
    left half plane (the stable polynomial with the same magnitude response)."""
    if len(a) <= 1:
        return a
    r = np.roots(a[::-1])
    if np.all(r.real <= 0):
        return a
    r = np.where(r.real > 0, -r.real + 1j * r.imag, r)
    return np.real(np.poly(r))[::-1]


# Log-ratio residual where the trial model's N or D vanishes on a datum (ln 0): large (a
# factor e^50) and finite, so the solver's steps stay finite.
_LOG_PENALTY = 50.0


def tfest(
    frd,
    n_poles: int,
    n_zeros: int,
    *,
    integrators: int = 0,
    delay: bool | float = False,
    std=None,
    stable: bool = True,
    output: int = 0,
    input: int = 0,
    max_nfev: int = 200,
    cost: str = "ml",
) -> TFEstimate:
    """Fit H(s) = N/(s^k D) e^{−sτ} to one channel of a python-control FRD (module docstring).

    ``std``: standard deviation of the FRF estimate per frequency (a PeriodicFRF's
    ``noise_std`` or ``total_std``); ``delay``: False (none), True (estimated) or a fixed
    value in seconds; ``cost``: ``"ml"`` (Σ|Ĥ − H|²/σ², default) or ``"log"`` (the
    log-ratio of FRB eq. (6), weighted by |H|/σ when ``std`` is given).
    """
    if cost not in ("ml", "log"):
        raise TFEstError(f"cost = {cost!r}: choose 'ml' (Σ|Ĥ−H|²/σ²) or 'log' (FRB eq. (6))")
    omega, H, std = _frd_data(frd, output, input, std)
    nd = n_poles - integrators
    if integrators < 0 or nd < 0 or n_zeros < 0:
        raise TFEstError(
            f"orders: n_zeros={n_zeros}, n_poles={n_poles}, integrators="
            f"{integrators}: need 0 <= integrators <= n_poles and n_zeros >= 0"
        )
    n_par = n_zeros + 1 + nd + (delay is True)
    F = len(omega)
    if 2 * F <= n_par:
        raise TFEstError(
            f"{F} frequencies give {2 * F} real equations, not more than the "
            f"{n_par} parameters of {n_zeros} zeros and {n_poles} poles"
        )
    ws = float(np.exp(np.mean(np.log(omega))))
    s = 1j * omega / ws
    sig = std if std is not None else np.abs(H)
    w = 1.0 / sig  # weight of the error Ĥ − H
    w_log = np.abs(H) * w  # weight of ln(Ĥ/H) ≈ (Ĥ − H)/H
    use_log = cost == "log"

    def start(tau):
        # N − Hr D = s^k D (Ĥ − H) e^{jωτ}: weight w/|s^k| makes the SK cost Σ w²|Ĥ − H|²
        Hr = H * s**integrators * np.exp(1j * omega * tau)
        return _levy_sk(s, Hr, w / np.abs(s) ** integrators, n_zeros, nd)

    def model(b, a, tau):
        return (
            np.polynomial.polynomial.polyval(s, b)
            / (s**integrators * np.polynomial.polynomial.polyval(s, a))
            * np.exp(-1j * omega * tau)
        )

    def cresid(b, a, tau):
        """Weighted complex residual of the chosen cost."""
        Hm = model(b, a, tau)
        if not use_log:
            return (Hm - H) * w
        with np.errstate(all="ignore"):
            e = np.log(Hm / H) * w_log
        return np.where(np.isfinite(e), e, _LOG_PENALTY)

    if delay is True:
        grid = np.linspace(0, np.pi / omega.max(), 21)
        costs = []
        for tau in grid:
            b, a = start(tau)
            costs.append(np.sum(np.abs(cresid(b, a, tau)) ** 2))
        tau0 = float(grid[int(np.argmin(costs))])
    else:
        tau0 = float(delay) if delay else 0.0
    b, a = start(tau0)
    nb = n_zeros + 1
    fit_tau = delay is True

    def unpack(x):
        return x[:nb], np.r_[x[nb : nb + nd], 1.0], (x[-1] / ws if fit_tau else tau0)

    def resid(x):
        e = cresid(*unpack(x))
        return np.concatenate([np.real(e), np.imag(e)])

    def jac(x):
        bb, aa, tau = unpack(x)
        Nv = np.polynomial.polynomial.polyval(s, bb)
        Dv = np.polynomial.polynomial.polyval(s, aa)
        if use_log:  # ∂ ln Ĥ: s^i/N, −s^i/D, −jω
            with np.errstate(all="ignore"):
                cols = [s**i / Nv for i in range(nb)] + [-(s**i) / Dv for i in range(nd)]
            if fit_tau:
                cols.append(-1j * omega / ws + 0 * s)
            J = np.column_stack(cols) * w_log[:, None]
            J = np.where(np.isfinite(J), J, 0.0)
        else:
            Hm = model(bb, aa, tau)
            cols = [s**i / (s**integrators * Dv) * np.exp(-1j * omega * tau) for i in range(nb)]
            cols += [-Hm * s**i / Dv for i in range(nd)]
            if fit_tau:
                cols.append(-1j * omega * Hm / ws)
            J = np.column_stack(cols) * w[:, None]
        return np.vstack([np.real(J), np.imag(J)])

    # delay parameter in units of 1/ω_s (scaled like the coefficients)
    x0 = np.r_[b, a[:-1], [tau0 * ws] if fit_tau else []]
    unstable: list[complex] = []
    for _attempt in range(3):
        sol = least_squares(
            resid,
            x0,
            method="lm",
            x_scale="jac",
            max_nfev=max_nfev * len(x0),
            jac=jac,  # pyright: ignore[reportArgumentType]  (scipy: jac is typed from its '2-point' default)
            xtol=1e-15,
            ftol=1e-15,
            gtol=1e-15,
        )
        x = sol.x
        a_fit = np.r_[x[nb : nb + nd], 1.0]
        roots = np.roots(a_fit[::-1]) if nd else np.array([])
        unstable = [complex(r * ws) for r in roots if r.real > 0]
        if not unstable or not stable:
            break
        x0 = np.r_[x[:nb], reflect_unstable_roots(a_fit)[:-1], x[nb + nd :]]
    bb, aa, tau = unpack(x)
    cost_value = float(np.sum(sol.fun**2))
    Jm = jac(x)
    JtJ_inv = np.linalg.pinv(Jm.T @ Jm)
    dof = 2 * F - n_par
    # real residuals have variance 1/2 with known σ; else their sample variance
    cov_x = 0.5 * JtJ_inv if std is not None else JtJ_inv * cost_value / max(dof, 1)
    # scaled → physical coefficients: num_i = b_i ω_s^{nd+k−i}, den_i = a_i ω_s^{nd−i}
    scale = np.r_[
        ws ** (nd + integrators - np.arange(nb)),
        ws ** (nd - np.arange(nd)),
        [1 / ws] if fit_tau else [],
    ]
    cov = cov_x * np.outer(scale, scale)
    num = bb * ws ** (nd + integrators - np.arange(nb))
    den = np.r_[aa[:-1] * ws ** (nd - np.arange(nd)), 1.0]
    den_full = np.r_[np.zeros(integrators), den]
    tf = control.tf(num[::-1], den_full[::-1])
    sd = np.sqrt(np.maximum(np.diag(cov), 0))
    params = {f"b{i}": {"value": float(num[i]), "std": float(sd[i])} for i in range(nb)}
    params.update({f"a{i}": {"value": float(den[i]), "std": float(sd[nb + i])} for i in range(nd)})
    if fit_tau:
        params["delay_s"] = {"value": float(tau), "std": float(sd[-1])}
    exp = F - n_par / 2 if std is not None else None
    params = inflate_std(params, cost_value, F, n_par, exp)
    Hm = model(bb, aa, tau)
    message = str(sol.message) + (
        "" if not unstable else f"; {len(unstable)} unstable pole(s) left"
    )
    return TFEstimate(
        tf,
        float(tau),
        cost_value,
        exp,
        np.sqrt(exp) if exp is not None else None,
        params,
        cov,
        F,
        n_par,
        unstable,
        cresid(bb, aa, tau),
        np.abs(Hm - H) / np.abs(H),
        message,
        cost,
    )


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


def tfest_orders(frd, poles, *, relative_degree: int = 1, criterion: str = "aic", **kw):
    """Fit every number of poles in ``poles`` (zeros = poles − ``relative_degree``) and
    return (best, all fits) by ``criterion`` ('aic' or 'bic')."""
    fits = {}
    for n in poles:
        nz = n - relative_degree
        if nz < 0:
            continue
        fits[n] = tfest(frd, n, nz, **kw)
    if not fits:
        raise TFEstError(f"no order in {list(poles)} leaves n_zeros >= 0")
    best = min(fits, key=lambda n: getattr(fits[n], criterion))
    return fits[best], fits
