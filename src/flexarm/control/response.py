r"""The response of a fixed SISO linear system to a sampled input, from rest: what
``control.forced_response(sys, t, u).outputs`` gives, without its per-sample Python loop.

python-control converts the system to state space on every call and steps it sample by
sample in Python (``scipy.signal.dlsim`` for a discrete system; its own loop for a
continuous one). A loop that simulates the same system many times (the nested design's
move sizing: one trial per bisection step, the feedforward on a grid 30 times finer than
the sampling) spends its time there. Here the system is converted once
(:func:`response_function`) and each call costs a few array operations:

Discrete transfer function G(z) = b(z)/a(z) (period T = the grid's step)
    ``scipy.signal.lfilter(b, a, u)``: the direct form of the same coefficients that
    python-control realises (``scipy.signal.tf2ss``, controller canonical form), from rest.

Continuous system (A, B, C, D) (transfer functions through ``control.ss``, the same
``tf2ss`` realisation python-control uses)
    the same first-order-hold discretisation as ``control.forced_response``: with
    h = (t[-1] − t[0])/(len(t) − 1) s and exp([[A h, B h, 0], [0, 0, I], [0, 0, 0]]) =
    [[A_d, Γ_0 + Γ_1, Γ_1], ...],

        x_0 = 0,   x_i = A_d x_{i−1} + Γ_0 u_{i−1} + Γ_1 u_i,   y_i = C x_i + D u_i

    (the input linear between samples). Discrete state space: A_d = A, Γ_0 = B, Γ_1 = 0.

The state recursion x_i = A_d x_{i−1} + v_i runs in blocks of L samples: within a block
x_{s+l} = A_d^{l+1} x_{s−1} + Σ_{m<=l} A_d^{l−m} v_{s+m}, the sums of every block at once as
one matrix product with the block-Toeplitz matrix of the powers A_d^0 .. A_d^{L−1}; only
the block ends are stepped in a loop (len(t)/L steps). The sums are those of the
sample-by-sample recursion in another order: the outputs agree with python-control's to
rounding (tests/test_control_response.py: 1e-9 relative, measured ~1e-14).

Units are the system's: u in its input's unit, y in its output's, t in s.
"""

from __future__ import annotations

from collections.abc import Callable

import control
import numpy as np
import scipy.linalg
import scipy.signal

__all__ = ["linear_response", "response_function"]

#: the block holds at most this many states × samples (the Toeplitz matrix is its square)
_BLOCK_STATES = 128


def _uniform_step(t: np.ndarray) -> float:
    """The grid's step as ``control.forced_response`` takes it: (t[-1] − t[0])/(n − 1)."""
    if t.ndim != 1 or t.size < 2:
        raise ValueError(f"t must be a 1-D array of at least 2 times; got shape {t.shape}")
    dt = float(t[-1] - t[0]) / (t.size - 1)
    if not np.allclose(np.diff(t), dt):
        raise ValueError("t must be uniformly spaced (the response is on a uniform grid)")
    return dt


def _recursion(ad: np.ndarray, v: np.ndarray) -> np.ndarray:
    """x_i = ad x_{i−1} + v_i for i = 0 .. N−1 from x_{−1} = 0; ``v`` (N, n) → x (N, n)."""
    big_n, n = v.shape
    if big_n == 0 or n == 0:
        return np.zeros((big_n, n))
    block = max(1, min(32, _BLOCK_STATES // n, big_n))
    nb = -(-big_n // block)
    vp = np.zeros((nb * block, n))
    vp[:big_n] = v
    powers = np.empty((block + 1, n, n))  # A_d^0 .. A_d^L
    powers[0] = np.eye(n)
    for k in range(1, block + 1):
        powers[k] = ad @ powers[k - 1]
    # the block-Toeplitz matrix: row block l, column block m holds A_d^(l−m) for m <= l
    kmat = np.zeros((block, n, block, n))
    for lag in range(block):
        for m in range(block - lag):
            kmat[m + lag, :, m, :] = powers[lag]
    kmat = kmat.reshape(block * n, block * n)
    forced = (vp.reshape(nb, block * n) @ kmat.T).reshape(nb, block, n)
    # the state before each block, x_{bL−1}: stepped block end to block end
    before = np.zeros((nb, n))
    ad_l = powers[block]
    for b in range(1, nb):
        before[b] = ad_l @ before[b - 1] + forced[b - 1, -1]
    x = np.einsum("lij,bj->bli", powers[1:], before) + forced
    return x.reshape(nb * block, n)[:big_n]


def response_function(sys, dt: float) -> Callable[[np.ndarray], np.ndarray]:
    """u ↦ y of the SISO ``sys`` (python-control transfer function or state space,
    continuous or discrete) on a uniform grid of step ``dt`` s from rest: the outputs of
    ``control.forced_response(sys, t, u)``, converted once (module docstring). A discrete
    ``sys`` needs ``dt`` equal to its period (within 1e-9 relative)."""
    if sys.ninputs != 1 or sys.noutputs != 1:
        raise ValueError(
            f"response_function: {sys.ninputs} inputs and {sys.noutputs} outputs; "
            "give a SISO system"
        )
    dt = float(dt)
    if not dt > 0:
        raise ValueError(f"response_function: dt = {dt!r} s; give a positive step")
    # as forced_response: continuous only for dt = 0; an unspecified period (None, True)
    # is the grid's
    discrete = not control.isctime(sys, strict=True)
    period = sys.dt if sys.dt not in (None, True) else dt
    if discrete and not np.isclose(dt, float(period), rtol=1e-9, atol=0.0):
        raise ValueError(
            f"response_function: the grid's step {dt:g} s differs from the system's "
            f"period {float(period):g} s; resample the input to the period"
        )
    if discrete and isinstance(sys, control.TransferFunction):
        num = np.atleast_1d(np.asarray(sys.num[0][0], float))
        den = np.atleast_1d(np.asarray(sys.den[0][0], float))
        # tf2ss's realisation: the numerator right-aligned with the denominator
        if num.size > den.size:
            lead = num[: num.size - den.size]
            if np.any(lead != 0):
                raise ValueError("response_function: the discrete transfer function is improper")
            num = num[num.size - den.size :]
        b = np.concatenate([np.zeros(den.size - num.size), num])

        def run_tf(u: np.ndarray) -> np.ndarray:
            return np.asarray(scipy.signal.lfilter(b, den, np.asarray(u, float)), float)

        return run_tf

    ss = control.ss(sys)
    a = np.asarray(ss.A, float)
    bm = np.asarray(ss.B, float).reshape(-1, 1)
    c = np.asarray(ss.C, float).reshape(1, -1)
    d = float(np.asarray(ss.D, float).reshape(-1)[0]) if np.size(ss.D) else 0.0
    n = a.shape[0]
    if discrete:
        ad, g0, g1 = a, bm[:, 0], np.zeros(n)
    else:  # control.forced_response's first-order hold
        m = np.zeros((n + 2, n + 2))
        m[:n, :n] = a * dt
        m[:n, n : n + 1] = bm * dt
        m[n, n + 1] = 1.0
        em = scipy.linalg.expm(m)
        ad = em[:n, :n]
        g1 = em[:n, n + 1]
        g0 = em[:n, n] - g1

    def run_ss(u: np.ndarray) -> np.ndarray:
        u = np.asarray(u, float)
        if n == 0:
            return d * u
        v = np.zeros((u.size, n))
        if u.size > 1:
            v[1:] = np.outer(u[:-1], g0) + np.outer(u[1:], g1)
        return _recursion(ad, v) @ c[0] + d * u

    return run_ss


def linear_response(sys, t, u) -> np.ndarray:
    """y(t) of the SISO ``sys`` driven by ``u`` on the uniform times ``t`` (s) from rest:
    ``control.forced_response(sys, t, u).outputs`` (:func:`response_function`)."""
    t = np.asarray(t, float)
    u = np.asarray(u, float)
    if u.shape != t.shape:
        raise ValueError(f"u has shape {u.shape}, t has shape {t.shape}; give one value per time")
    return response_function(sys, _uniform_step(t))(u)
