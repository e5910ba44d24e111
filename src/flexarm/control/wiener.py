r"""ISE-optimal (Wiener) feedforward for the outer tip loop, and its evaluation.

Feliu, Rattan & Brown (1993), Sec. V-A. With the inner (motor) loop fast enough to be
replaced by a unity block, the tip obeys θt(s) = G_b(s) θ̂_mr(s), and the feedforward
θ̂_mr(s) = N(s) u(s) is chosen to minimise the integral square error

    ISE = ∫_0^∞ e²(t) dt = 1/(2πj) ∫_{-j∞}^{j∞} e(s) e(−s) ds,   e = u − θt   (10)

over stable N(s). The Wiener solution is

    N(s) = [ G_b(−s) I_uu(s) / (G_b⁻(s) I_uu⁻(s)) ]_+  /  ( G_b⁺(s) I_uu⁺(s) )     (11)

with the spectral factorisations G_b(s) G_b(−s) = G_b⁺(s) G_b⁻(s) and
I_uu(s) = u(s) u(−s) = I_uu⁺(s) I_uu⁻(s), and [·]_+ the part of the partial-fraction
expansion whose poles are in the left half-plane ("causal" part).

Conventions used here (the paper leaves them implicit):

* Factorisation of G_b = k_G B_m(s) B_n(s) / A(s), with B_n the monic polynomial of the
  right-half-plane (RHP) zeros z_j, B_m the monic polynomial of the left-half-plane
  zeros and A the monic denominator. Then G_b⁺(s) = k_G B_m(s) B̃_n(s) / A(s) with
  B̃_n(s) = Π (s + z_j) (RHP zeros reflected into the LHP) and G_b⁻(s) = G_b⁺(−s).
  The poles of G_b — including undamped poles on the imaginary axis, which FRB eq. (14)
  has — are kept in G_b⁺; they cancel from G_b(−s)/G_b⁻(s) = B̃_n(s)/B_n(s) and so only
  reappear as zeros of N(s). The sign of k_G may be given to either factor: N is
  unchanged.
* Factorisation of I_uu, **rule for poles on the imaginary axis (notably s = 0)**:
  I_uu⁺(s) = u⁺(s) = k_u U_m(s) Ũ_n(s) / P(s), i.e. the reference's *own* poles P(s)
  (all of them, those at s = 0 included) and its LHP zeros form the + factor, its RHP
  zeros are reflected, and I_uu⁻(s) = u⁺(−s). For u = 1/s^k the 2k-fold pole of
  I_uu = (−1)^k / s^{2k} is thus split k/k: the k poles of u(s) are "causal", the k
  poles of u(−s) are "anti-causal". Assigning all 2k poles to the + factor would give
  a different (wrong) filter; the k/k rule is the one that reproduces the paper's
  N(s) of Sec. VI-C.3 for u = 1/s³ (see flexarm.control.trajectories).
* With these, the bracket of (11) is X(s) = B̃_n(s)/B_n(s) · u⁺(s); its "−" part is
  R(s)/B_n(s) (deg R < deg B_n, the terms of the RHP poles z_j), its "+" part
  k_u Q(s)/P(s), found from the polynomial (Bezout) identity

      R(s) P(s) + Q(s) B_n(s) = U_m(s) Ũ_n(s) B̃_n(s),

  solved as a linear (Sylvester) system in a frequency-scaled variable σ = s/ω0 with
  monic polynomials (ω0 = geometric mean of the plant's root magnitudes). Then

      N(s) = Q(s) A(s) / ( k_G B_m(s) B̃_n(s) U_m(s) Ũ_n(s) ).

  For a minimum-phase G_b (no RHP zero) this is N = 1/G_b exactly (returned directly).

N(s) is in general improper (numerator degree above denominator degree); a
python-control TransferFunction holds it. It acts on the trajectory as a polynomial part
(a weighted sum of the reference's derivatives) plus a strictly proper part. To apply it:

* :func:`feedforward_signal` — preferred: the polynomial part uses the trajectory's
  analytic derivatives (e.g. :class:`flexarm.control.trajectories.PointToPointTrajectory`),
  the proper part is simulated with ``control.forced_response``. A reference without the
  needed bounded derivatives (a parabolic one with a non-minimum-phase G_b) gives a
  clear error instead of an impulsive, sampling-dependent signal.
* :func:`discretize_feedforward` — a causal discrete filter N(s) F(s), F a unity-gain
  low-pass of just enough relative degree, for use on a running sample stream; it adds
  the lag of F.

Units: θ in rad, t in s; N(s) is dimensionless (rad of motor per rad of tip).
"""

from __future__ import annotations

from collections.abc import Callable

import control
import numpy as np

__all__ = [
    "wiener_feedforward",
    "feedforward_signal",
    "discretize_feedforward",
    "split_improper",
    "cancel_common_roots",
]

# Roots whose real part is within this fraction of max(1, |root|) of zero are taken to
# lie on the imaginary axis.
_AXIS_RTOL = 1e-7


# ----------------------------------------------------------------------------- helpers
def _siso_polys(sys: object, name: str) -> tuple[np.ndarray, np.ndarray]:
    """(num, den) of a continuous-time SISO LTI system, descending powers, trimmed."""
    if isinstance(sys, control.StateSpace):
        sys = control.ss2tf(sys)
    if not isinstance(sys, control.TransferFunction):
        raise TypeError(
            f"{name} must be a python-control TransferFunction (a rational function of s); "
            f"got {type(sys).__name__}"
        )
    if sys.ninputs != 1 or sys.noutputs != 1:
        raise ValueError(
            f"{name} must be SISO (1 input, 1 output); got {sys.noutputs} outputs × "
            f"{sys.ninputs} inputs"
        )
    if sys.dt not in (0, None):
        raise ValueError(f"{name} must be continuous-time (dt = 0); got dt = {sys.dt}")
    num = np.trim_zeros(np.atleast_1d(np.asarray(sys.num[0][0], dtype=float)), "f")
    den = np.trim_zeros(np.atleast_1d(np.asarray(sys.den[0][0], dtype=float)), "f")
    if num.size == 0 or not np.any(num):
        raise ValueError(f"{name} is identically zero")
    if den.size == 0:
        raise ValueError(f"{name} has a zero denominator")
    if not (np.all(np.isfinite(num)) and np.all(np.isfinite(den))):
        raise ValueError(f"{name} has non-finite coefficients")
    return num, den


def _roots(p: np.ndarray) -> np.ndarray:
    """Roots of a descending polynomial; exact zeros (trailing zero coefficients) exact."""
    p = np.trim_zeros(np.asarray(p, dtype=float), "f")
    k = p.size - np.trim_zeros(p, "b").size
    rest = np.roots(np.trim_zeros(p, "b")) if p.size - k > 1 else np.zeros(0, complex)
    return np.concatenate([np.zeros(k, complex), rest.astype(complex)])


def _classify(r: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Split roots into (open LHP, imaginary axis, open RHP)."""
    tol = _AXIS_RTOL * np.maximum(1.0, np.abs(r))
    lhp = r[r.real < -tol]
    rhp = r[r.real > tol]
    axis = r[np.abs(r.real) <= tol]
    return lhp, axis, rhp


def _poly_from_roots(r: np.ndarray) -> np.ndarray:
    """Monic real polynomial (descending) from roots closed under conjugation."""
    if r.size == 0:
        return np.ones(1)
    p = np.poly(r)
    return np.real(p)


def _fmt(r: np.ndarray) -> str:
    return ", ".join(f"{z.real:.6g}{z.imag:+.6g}j" for z in r)


def _scale_asc(c_asc: np.ndarray, w: float) -> np.ndarray:
    """p(s) → p(w σ)/w^deg, ascending coefficients (monic stays monic)."""
    n = c_asc.size - 1
    return c_asc * w ** (np.arange(c_asc.size) - n)


def _conv_matrix(p_asc: np.ndarray, ncols: int, nrows: int) -> np.ndarray:
    """Columns: p(σ)·σ^j for j = 0..ncols-1, ascending, padded to nrows."""
    m = np.zeros((nrows, ncols))
    for j in range(ncols):
        m[j : j + p_asc.size, j] = p_asc
    return m


def _bezout(p_asc: np.ndarray, b_asc: np.ndarray, m_asc: np.ndarray) -> np.ndarray:
    """Q (ascending) with R P + Q B = M, deg R < deg B, for coprime P, B (ascending)."""
    dp, db, dm = p_asc.size - 1, b_asc.size - 1, m_asc.size - 1
    dq = max(dm - db, dp - 1)
    nrows = max(dm + 1, dp + db)
    a = np.hstack([_conv_matrix(p_asc, db, nrows), _conv_matrix(b_asc, dq + 1, nrows)])
    rhs = np.zeros(nrows)
    rhs[: m_asc.size] = m_asc
    cond = np.linalg.cond(a)
    if not np.isfinite(cond) or cond > 1e12:
        raise ValueError(
            "spectral-factor split is ill-conditioned (condition number "
            f"{cond:.3g}): the reference's poles nearly coincide with the reflected "
            "right-half-plane zeros of G_b"
        )
    x = np.linalg.solve(a, rhs)
    return x[db:]


def cancel_common_roots(
    sys: control.TransferFunction, rtol: float = 1e-7
) -> control.TransferFunction:
    """Remove pole/zero pairs closer than ``rtol``·max(1, |pole|) from a SISO TF.

    Polynomials are rebuilt from their remaining roots only when something cancels.
    Used for N(s) (a plant pole equal to a reflected zero) and for G_b(s)N(s), whose
    undamped poles cancel against zeros of N.
    """
    num, den = _siso_polys(sys, "transfer function")
    zr, pr = list(_roots(num)), list(_roots(den))
    keep_z = []
    for z in zr:
        if pr:
            d = np.abs(np.asarray(pr) - z)
            j = int(np.argmin(d))
            if d[j] <= rtol * max(1.0, abs(pr[j])):
                pr.pop(j)
                continue
        keep_z.append(z)
    if len(keep_z) == len(zr):
        return control.tf(num, den)
    new_num = num[0] * _poly_from_roots(np.asarray(keep_z, complex))
    new_den = den[0] * _poly_from_roots(np.asarray(pr, complex))
    return control.tf(new_num / new_den[0], new_den / new_den[0])


# ------------------------------------------------------------------------- the filter
def wiener_feedforward(
    plant: control.TransferFunction,
    reference: control.TransferFunction,
    *,
    allow_marginal_poles: bool = True,
) -> control.TransferFunction:
    r"""ISE-optimal stable feedforward N(s) of FRB (1993) eq. (11).

    Parameters
    ----------
    plant:
        G_b(s) = θt(s)/θm(s) (rad/rad), continuous-time SISO, possibly non-minimum phase.
    reference:
        u(s), the Laplace transform of the nominal tip trajectory (rad·s), e.g. A/s³ for
        a step of acceleration A (rad/s²). Its gain does not affect N.
    allow_marginal_poles:
        G_b may have poles on the imaginary axis (undamped modes, as FRB eq. (14)); they
        cancel against zeros of N. Set False to require a strictly stable G_b.

    Returns
    -------
    control.TransferFunction
        N(s) with monic denominator; proper or improper. See the module docstring for
        the factorisation conventions (the reference's own poles, those at s = 0
        included, are assigned to I_uu⁺).

    Raises
    ------
    TypeError
        ``plant`` or ``reference`` is not a python-control LTI object.
    ValueError
        MIMO or discrete-time input; G_b with a pole in the open right half-plane (or on
        the imaginary axis with ``allow_marginal_poles=False``), G_b with a zero on the
        imaginary axis (no stable inverse), a reference with a pole in the open right
        half-plane (ISE not finite for any N).
    """
    gnum, gden = _siso_polys(plant, "plant G_b(s)")
    unum, uden = _siso_polys(reference, "reference u(s)")

    gpoles = _roots(gden)
    lhp, axis, rhp = _classify(gpoles)
    if rhp.size:
        raise ValueError(f"plant G_b(s) is unstable: poles in the right half-plane at {_fmt(rhp)}")
    if axis.size and not allow_marginal_poles:
        raise ValueError(
            f"plant G_b(s) is not strictly stable: poles on the imaginary axis at {_fmt(axis)}"
        )
    uroots_p = _roots(uden)
    _, _, urhp = _classify(uroots_p)
    if urhp.size:
        raise ValueError(
            "reference u(s) grows without bound (poles in the right half-plane at "
            f"{_fmt(urhp)}): the ISE of eq. (10) is infinite for every N"
        )

    k_g = gnum[0] / gden[0]
    a_mon = gden / gden[0]
    gzeros = _roots(gnum)
    zl, zaxis, zr = _classify(gzeros)
    if zaxis.size:
        raise ValueError(
            f"plant G_b(s) has zeros on the imaginary axis at {_fmt(zaxis)}: "
            "no stable feedforward can invert them"
        )
    if zr.size == 0:  # minimum phase: N = 1/G_b exactly
        return control.tf(gden / gnum[0], gnum / gnum[0])

    # Spectral factors (module docstring): B_m, B_n, B̃_n; U_m Ũ_n.
    b_m = _poly_from_roots(zl)
    b_n = _poly_from_roots(zr)
    b_nr = _poly_from_roots(-zr)
    uzeros = _roots(unum)
    uzl, uzaxis, uzr = _classify(uzeros)
    u_pl = _poly_from_roots(np.concatenate([uzl, uzaxis, -uzr]))  # U_m Ũ_n, monic
    p_mon = uden / uden[0]

    # Frequency scale: geometric mean of the plant's non-zero root magnitudes.
    mags = np.abs(np.concatenate([gpoles, gzeros]))
    mags = mags[mags > 0]
    w0 = float(np.exp(np.mean(np.log(mags)))) if mags.size else 1.0

    m_poly = np.polymul(u_pl, b_nr)  # right-hand side, monic
    q_asc = _bezout(
        _scale_asc(p_mon[::-1], w0), _scale_asc(b_n[::-1], w0), _scale_asc(m_poly[::-1], w0)
    )
    # Unscale: Q(s) = w0^(deg M − deg B_n) Qσ(s/w0).
    q_asc = q_asc * w0 ** (m_poly.size - b_n.size) * w0 ** (-np.arange(q_asc.size))
    q = np.trim_zeros(q_asc[::-1], "f")
    if q.size == 0:
        raise ValueError("the causal part of eq. (11) vanished: N(s) = 0")

    num = np.polymul(q, a_mon)
    den = k_g * np.polymul(np.polymul(b_m, b_nr), u_pl)
    num, den = num / den[0], den / den[0]
    # Drop numerically-zero leading numerator coefficients (e.g. when deg Q is short).
    scale = np.max(np.abs(num))
    while num.size > 1 and abs(num[0]) <= 1e-13 * scale:
        num = num[1:]
    # A plant pole may coincide with a reflected zero or a reference zero: cancel it.
    return cancel_common_roots(control.tf(num, den))


# ------------------------------------------------------------------ applying N(s)
def split_improper(n: control.TransferFunction) -> tuple[np.ndarray, control.TransferFunction]:
    """N(s) = Π(s) + N_p(s): polynomial part Π (descending coefficients, possibly [0])
    and strictly proper remainder N_p (a TransferFunction, possibly zero)."""
    num, den = _siso_polys(n, "N(s)")
    if num.size >= den.size:
        quot, rem = np.polydiv(num, den)
    else:
        quot, rem = np.zeros(1), num
    rem = np.trim_zeros(rem, "f") if np.any(rem) else np.zeros(1)
    if rem.size >= den.size:  # numerical leftovers of polydiv
        rem = rem[rem.size - den.size + 1 :]
    return np.atleast_1d(quot), control.tf(rem, den)


def _derivative_getter(reference: object, t: np.ndarray) -> Callable[[int], np.ndarray]:
    if hasattr(reference, "derivative") and callable(reference.derivative):
        return lambda k: np.asarray(reference.derivative(t, k), dtype=float)
    if callable(reference):
        return lambda k: np.asarray(reference(t, k), dtype=float)
    samples = np.asarray(reference, dtype=float)
    if samples.shape != t.shape:
        raise ValueError(
            f"reference samples have shape {samples.shape}, time grid has shape {t.shape}"
        )
    dt = t[1] - t[0]
    cache = [samples]

    def get(k: int) -> np.ndarray:
        while len(cache) <= k:
            cache.append(np.gradient(cache[-1], dt, edge_order=2))
        return cache[k]

    return get


def feedforward_signal(
    n: control.TransferFunction, reference: object, t: np.ndarray
) -> np.ndarray:
    r"""θ̂_mr(t) = N applied to the reference trajectory, N possibly improper (rad).

    N(s) = Σ_k π_k s^k + N_p(s) (:func:`split_improper`); the result is
    Σ_k π_k u^{(k)}(t) + (N_p * u)(t), the second term by ``control.forced_response``
    from rest at t[0].

    Parameters
    ----------
    n:
        N(s), e.g. from :func:`wiener_feedforward`.
    reference:
        either an object with ``derivative(t, order)`` (analytic derivatives, e.g. a
        :class:`~flexarm.control.trajectories.PointToPointTrajectory` — preferred), a
        callable ``f(t, order)``, or an array of samples u(t) on ``t``; samples are
        differentiated by repeated second-order finite differences (``np.gradient``), so
        a reference whose needed derivatives are not bounded gives a spike that grows
        as the grid is refined (FRB Sec. V-B).
    t:
        uniformly spaced increasing times (s); the reference must be at rest at t[0].
    """
    t = np.asarray(t, dtype=float)
    if t.ndim != 1 or t.size < 3:
        raise ValueError("t must be a 1-D array of at least 3 times")
    steps = np.diff(t)
    if np.any(steps <= 0) or np.ptp(steps) > 1e-6 * steps.mean():
        raise ValueError("t must be uniformly spaced and increasing")
    poly, proper = split_improper(n)
    get = _derivative_getter(reference, t)
    order = poly.size - 1
    out = np.zeros_like(t)
    for k, c in enumerate(poly[::-1]):
        if c == 0.0:
            continue
        try:
            out += c * get(k)
        except ValueError as exc:
            raise ValueError(
                f"N(s) has a polynomial part of degree {order}: the feedforward needs the "
                f"reference's derivatives up to order {order}, but order {k} is not "
                f"available as a bounded function ({exc})"
            ) from exc
    if np.any(proper.num[0][0]):
        u0 = get(0)
        out += np.asarray(control.forced_response(proper, t, u0).outputs, dtype=float)
    return out


def _real_quadratics(roots: np.ndarray) -> list[np.ndarray]:
    """Group roots closed under conjugation into real monic factors of degree ≤ 2."""
    roots = np.asarray(roots, complex)
    tol = 1e-9 * np.maximum(1.0, np.abs(roots))
    cplx = roots[(roots.imag > tol)]
    real = np.sort(roots[np.abs(roots.imag) <= tol].real)
    out = [np.array([1.0, -2.0 * z.real, abs(z) ** 2]) for z in cplx]
    for i in range(0, real.size - 1, 2):
        out.append(np.array([1.0, -(real[i] + real[i + 1]), real[i] * real[i + 1]]))
    if real.size % 2:
        out.append(np.array([1.0, -real[-1]]))
    return out


def discretize_feedforward(
    n: control.TransferFunction,
    dt: float,
    *,
    bandwidth_rad_s: float | None = None,
    method: str = "tustin",
) -> control.StateSpace:
    r"""Causal discrete realisation of N(s) for a running sample stream.

    An improper N(s) (relative degree −r < 0) is made proper by a unity-DC-gain low-pass
    F(s) = (ω_f/(s + ω_f))^r, and H(s) = N(s)F(s) is mapped root by root:

    * ``"tustin"``: s = (2/Δt)(z − 1)/(z + 1); each root ρ ↦ (2/Δt + ρ)/(2/Δt − ρ), gain
      k Π(2/Δt − z_i)/Π(2/Δt − p_j), extra zeros at z = −1 for a strictly proper H.
    * ``"matched"``: roots ρ ↦ e^{ρΔt}, gain set so that H(z = 1) = H(s = 0) (needs a
      finite, non-zero static gain).

    The result is a discrete-time ``control.StateSpace``: a cascade of first- and
    second-order sections. (A single expanded transfer function in z, or a companion
    realisation of N(s)F(s) in s, loses the static gain to rounding once the roots
    cluster near z = 1, e.g. Δt = 0.1 ms with ω_f ≈ 8000 rad/s.)

    F delays and smooths the feedforward (phase lag ≈ r·ω/ω_f at ω ≪ ω_f), so
    :func:`feedforward_signal` with analytic trajectory derivatives is preferred when
    the trajectory is known in advance, as in FRB.

    Parameters
    ----------
    n: N(s).
    dt: sampling period Δt (s), > 0.
    bandwidth_rad_s: ω_f (rad/s); default π/(4 Δt), a quarter of the Nyquist frequency.
    method: "tustin" (default) or "matched".
    """
    num, den = _siso_polys(n, "N(s)")
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be a positive sampling period in s; got {dt}")
    wf = np.pi / (4.0 * dt) if bandwidth_rad_s is None else float(bandwidth_rad_s)
    if not (np.isfinite(wf) and wf > 0):
        raise ValueError(f"bandwidth_rad_s must be positive; got {bandwidth_rad_s}")
    r = max(0, num.size - den.size)
    zeros = _roots(num)
    poles = np.concatenate([_roots(den), np.full(r, -wf, dtype=complex)])
    k = num[0] / den[0] * wf**r
    if method == "tustin":
        c = 2.0 / dt
        if np.any(np.isclose(poles, c)) or np.any(np.isclose(zeros, c)):
            raise ValueError("a root of N(s)F(s) sits at s = 2/dt: Tustin map undefined")
        gain = float(np.real(k * np.prod(c - zeros) / np.prod(c - poles)))
        zd = np.concatenate([(c + zeros) / (c - zeros), -np.ones(poles.size - zeros.size)])
        pd = (c + poles) / (c - poles)
    elif method == "matched":
        if np.any(zeros == 0) or np.any(poles == 0):
            raise ValueError("method='matched' needs a finite, non-zero static gain of N(s)")
        zd, pd = np.exp(zeros * dt), np.exp(poles * dt)
        dc = np.real(k * np.prod(-zeros) / np.prod(-poles))
        gain = float(dc / np.real(np.prod(1.0 - zd) / np.prod(1.0 - pd)))
    else:
        raise ValueError(f"method must be 'tustin' or 'matched'; got {method!r}")
    zq, pq = _real_quadratics(zd), _real_quadratics(pd)
    zq.sort(key=len, reverse=True)
    pq.sort(key=len, reverse=True)
    sys = None
    for i in range(max(len(zq), len(pq))):
        nz = zq[i] if i < len(zq) else np.ones(1)
        pz = pq[i] if i < len(pq) else np.ones(1)
        if nz.size > pz.size:  # more zeros than poles in this section: borrow a pole
            raise ValueError("discretised N(s)F(s) is improper; increase the filter order")
        sec = control.tf2ss(control.tf(nz, pz, dt))
        sys = sec if sys is None else control.series(sys, sec)
    return gain * sys
