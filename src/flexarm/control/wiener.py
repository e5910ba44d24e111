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
* Repeated and shared roots (a reference pole that is also a plant pole or a reflected
  zero, u = 1/s², a triple plant pole): all factors are kept as root lists, each
  multiple root found once as such (``np.roots`` splits an m-fold root by ε^(1/m); the
  cluster's centroid is exact to O(ε)) and common factors are cancelled as multisets of
  roots: a factor F of both P and B̃_n is removed before the Bezout solve (it divides Q,
  N is unchanged), plant poles cancel against B̃_n and the reference's zeros, Q's roots
  against what is left of the denominator. No product with a repeated root is rooted
  again, so the shared-pole cases reach the rounding of the Sylvester solve (~1e-15)
  instead of √ε ≈ 1e-8.

N(s) is in general improper (numerator degree above denominator degree); a
python-control TransferFunction holds it. It acts on the trajectory as a polynomial part
(a weighted sum of the reference's derivatives) plus a strictly proper part. To apply it:

* :func:`feedforward_signal` — preferred: the polynomial part uses the trajectory's
  analytic derivatives (e.g. :class:`flexarm.control.trajectories.PointToPointTrajectory`),
  the proper part is simulated as ``control.forced_response`` does
  (:func:`flexarm.control.response.linear_response`, without its per-sample loop). A
  reference without the needed bounded derivatives (a parabolic one with a
  non-minimum-phase G_b) gives a clear error instead of an impulsive, sampling-dependent
  signal.
* :func:`discretize_feedforward` — a causal discrete filter N(s) F(s), F a unity-gain
  low-pass of just enough relative degree, for use on a running sample stream; it adds
  the lag of F.

Units: θ in rad, t in s; N(s) is dimensionless (rad of motor per rad of tip).
"""

from __future__ import annotations

from collections.abc import Callable

import control
import numpy as np

from flexarm.control.response import linear_response

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
    """Roots of a descending polynomial, multiple roots made exactly equal.

    Exact zeros (trailing zero coefficients) are exact. The rest come from ``np.roots``
    (eigenvalues of the companion matrix, backward stable), which spreads an m-fold root
    r into m roots about (ε‖p‖)^(1/m)·|r| apart (1.5e-8 |r| for a double, 6e-6 |r| for a
    triple root): a cancellation against one of them would leave an error of that size.
    Roots are therefore merged, closest first, into clusters whose spread stays within
    what rounding can cause for their size, :data:`_CLUSTER_SPREAD` · ε^(1/m) · |r|; a
    cluster stands for one root of multiplicity m at its centroid, which rounding
    perturbs by O(ε) only (the centroid of the m roots is the well-conditioned quantity).
    """
    p = np.trim_zeros(np.asarray(p, dtype=float), "f")
    k = p.size - np.trim_zeros(p, "b").size
    rest = np.roots(np.trim_zeros(p, "b")) if p.size - k > 1 else np.zeros(0, complex)
    return np.concatenate([np.zeros(k, complex), _merge_multiple(rest.astype(complex))])


# An m-fold root comes out of np.roots spread over ~ (ε κ)^(1/m)|r| (κ ≈ 1 to 10 for the
# small, frequency-scaled polynomials here; measured 1.5–1.8 ε^(1/m)|r| at κ ≈ 1); roots
# within 16 ε^(1/m)|r| of their centroid are taken as one m-fold root. Distinct roots that
# close cannot be told from a multiple root in float64 anyway.
_CLUSTER_SPREAD = 16.0
_EPS = float(np.finfo(float).eps)


def _merge_multiple(r: np.ndarray) -> np.ndarray:
    """Replace each cluster of a multiple root by its centroid, repeated (see _roots)."""
    clusters = [[z] for z in r]

    def spread_ok(c: list) -> tuple[bool, complex]:
        arr = np.asarray(c)
        mid = arr.mean()
        scale = max(abs(mid), np.max(np.abs(arr)))
        return (
            bool(np.max(np.abs(arr - mid)) <= _CLUSTER_SPREAD * _EPS ** (1 / arr.size) * scale),
            mid,
        )

    while True:
        best = None
        for i in range(len(clusters)):
            for j in range(i + 1, len(clusters)):
                merged = clusters[i] + clusters[j]
                ok, mid = spread_ok(merged)
                if ok:
                    d = abs(np.mean(clusters[i]) - np.mean(clusters[j]))
                    if best is None or d < best[0]:
                        best = (d, i, j)
        if best is None:
            break
        _, i, j = best
        clusters[i] = clusters[i] + clusters.pop(j)
    out = []
    for c in clusters:
        mid = complex(np.mean(c))
        if len(c) > 1 and abs(mid.imag) <= _EPS * abs(mid):
            mid = complex(mid.real, 0.0)  # a real multiple root split into a complex pair
        out += [mid] * len(c)
    return np.asarray(out, complex)


def _classify(r: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Split roots into (open LHP, imaginary axis, open RHP)."""
    tol = _AXIS_RTOL * np.maximum(1.0, np.abs(r))
    lhp = r[np.real(r) < -tol]
    rhp = r[np.real(r) > tol]
    axis = r[np.abs(np.real(r)) <= tol]
    return lhp, axis, rhp


def _poly_from_roots(r: np.ndarray) -> np.ndarray:
    """Monic real polynomial (descending) from roots closed under conjugation."""
    if r.size == 0:
        return np.ones(1)
    p = np.poly(r)
    return np.real(p)


def _cancel(a: np.ndarray, b: np.ndarray, rtol: float = 1e-7) -> tuple[np.ndarray, np.ndarray, int]:
    """Remove the roots two root lists share: (a less them, b less them, how many).

    Roots match when closer than ``rtol``·max(1, |b_j|), one for one (multiplicity
    counts: a double root of ``a`` cancels at most two of ``b``). Multiple roots from
    :func:`_roots` are exactly equal, so an m-fold common factor leaves nothing behind.
    """
    roots_a, rest = list(np.asarray(a, complex)), list(np.asarray(b, complex))
    keep, n = [], 0
    for z in roots_a:
        if rest:
            d = np.abs(np.asarray(rest) - z)
            j = int(np.argmin(d))
            if d[j] <= rtol * max(1.0, abs(rest[j])):
                rest.pop(j)
                n += 1
                continue
        keep.append(z)
    return np.asarray(keep, complex), np.asarray(rest, complex), n


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

    Multiple roots are found as such (:func:`_roots`), so a repeated common factor
    cancels to rounding, not to ε^(1/m). Polynomials are rebuilt from their remaining
    roots only when something cancels.
    Used for N(s) (a plant pole equal to a reflected zero) and for G_b(s)N(s), whose
    undamped poles cancel against zeros of N.
    """
    num, den = _siso_polys(sys, "transfer function")
    keep_z, keep_p, n = _cancel(_roots(num), _roots(den), rtol)
    if n == 0:
        return control.tf(num, den)
    new_num = num[0] * _poly_from_roots(keep_z)
    new_den = den[0] * _poly_from_roots(keep_p)
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
    # Everything below works on root lists (multiple roots exactly equal, _roots) and
    # cancels common factors there; no product with a repeated root is ever re-rooted.
    # A pole-zero pair of the input itself (a non-minimal G_b or u) cancels first.
    gzeros, gpoles, _ = _cancel(_roots(gnum), _roots(gden))
    uzeros, upoles, _ = _cancel(_roots(unum), _roots(uden))

    lhp, axis, rhp = _classify(gpoles)
    if rhp.size:
        raise ValueError(f"plant G_b(s) is unstable: poles in the right half-plane at {_fmt(rhp)}")
    if axis.size and not allow_marginal_poles:
        raise ValueError(
            f"plant G_b(s) is not strictly stable: poles on the imaginary axis at {_fmt(axis)}"
        )
    _, _, urhp = _classify(upoles)
    if urhp.size:
        raise ValueError(
            "reference u(s) grows without bound (poles in the right half-plane at "
            f"{_fmt(urhp)}): the ISE of eq. (10) is infinite for every N"
        )

    k_g = gnum[0] / gden[0]
    zl, zaxis, zr = _classify(gzeros)
    if zaxis.size:
        raise ValueError(
            f"plant G_b(s) has zeros on the imaginary axis at {_fmt(zaxis)}: "
            "no stable feedforward can invert them"
        )
    if zr.size == 0:  # minimum phase: N = 1/G_b exactly
        return control.tf(gden / gnum[0], gnum / gnum[0])

    # Spectral factors (module docstring): B_m, B_n, B̃_n as roots; U_m Ũ_n as roots.
    uzl, uzaxis, uzr = _classify(uzeros)
    u_roots = np.concatenate([uzl, uzaxis, -uzr])
    # A factor F that the reference's poles P share with B̃_n (a reference pole at a
    # reflected plant zero) divides Q: with P = F P', B̃_n = F B̃_n', the identity
    # R P' + Q' B_n = U_m Ũ_n B̃_n' gives Q = F Q' and the same N. Removing F first keeps
    # the Sylvester system small and Q free of a root that would cancel later.
    p_roots, bnr_roots, _ = _cancel(upoles, -zr)
    b_n = _poly_from_roots(zr)

    # Frequency scale: geometric mean of the plant's non-zero root magnitudes.
    mags = np.abs(np.concatenate([gpoles, gzeros]))
    mags = mags[mags > 0]
    w0 = float(np.exp(np.mean(np.log(mags)))) if mags.size else 1.0

    m_poly = _poly_from_roots(np.concatenate([u_roots, bnr_roots]))  # right-hand side, monic
    q_asc = _bezout(
        _scale_asc(_poly_from_roots(p_roots)[::-1], w0),
        _scale_asc(b_n[::-1], w0),
        _scale_asc(m_poly[::-1], w0),
    )
    # Drop numerically-zero leading coefficients of Qσ (deg Q below its bound); in σ the
    # coefficients are balanced, so 1e-13 of the largest is rounding of the solve.
    while q_asc.size > 1 and abs(q_asc[-1]) <= 1e-13 * np.max(np.abs(q_asc)):
        q_asc = q_asc[:-1]
    # Unscale: Q(s) = w0^(deg M − deg B_n) Qσ(s/w0).
    q_asc = q_asc * w0 ** (m_poly.size - b_n.size) * w0 ** (-np.arange(q_asc.size))
    q = q_asc[::-1]
    if not np.any(q):
        raise ValueError("the causal part of eq. (11) vanished: N(s) = 0")

    # N(s) = Q A / (k_G B_m B̃_n' U_m Ũ_n), cancelled in root form: a plant pole at a
    # reflected zero or at a reference zero, then a root of Q at any denominator root.
    # A factor that lost no root keeps its coefficients as given (exact zeros stay zero).
    a_roots, den_roots, n_a = _cancel(gpoles, np.concatenate([zl, bnr_roots, u_roots]))
    q_roots, den_roots, n_q = _cancel(_roots(q), den_roots)
    a_poly = (
        gden / gden[0] if n_a == 0 and a_roots.size == gden.size - 1 else _poly_from_roots(a_roots)
    )
    q_poly = q if n_q == 0 else q[0] * _poly_from_roots(q_roots)
    num = np.polymul(q_poly, a_poly)
    den = k_g * _poly_from_roots(den_roots)
    return control.tf(num / den[0], den / den[0])


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
    derivative = getattr(reference, "derivative", None)
    if derivative is not None and callable(derivative):
        return lambda k: np.asarray(derivative(t, k), dtype=float)
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


def feedforward_signal(n: control.TransferFunction, reference: object, t: np.ndarray) -> np.ndarray:
    r"""θ̂_mr(t) = N applied to the reference trajectory, N possibly improper (rad).

    N(s) = Σ_k π_k s^k + N_p(s) (:func:`split_improper`); the result is
    Σ_k π_k u^{(k)}(t) + (N_p * u)(t), the second term as ``control.forced_response``
    gives it from rest at t[0] (:func:`~flexarm.control.response.linear_response`).

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
        out += linear_response(proper, t, u0)
    return out


def _real_quadratics(roots: np.ndarray) -> list[np.ndarray]:
    """Group roots closed under conjugation into real monic factors of degree ≤ 2."""
    roots = np.asarray(roots, complex)
    tol = 1e-9 * np.maximum(1.0, np.abs(roots))
    cplx = roots[(np.imag(roots) > tol)]
    real = np.sort(np.real(roots[np.abs(np.imag(roots)) <= tol]))
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
    assert sys is not None  # one section at least: N(s)F(s) has poles
    return gain * sys
