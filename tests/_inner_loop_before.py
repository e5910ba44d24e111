"""The inner-loop design's step evaluator and objective as they were before issue #46's
second speed-up (commit 1ee883f, ``control/inner_loop.py``), verbatim: the reference that
tests/test_control_inner_loop__speed_equivalence.py compares the new evaluation with."""

from __future__ import annotations

import numpy as np
import scipy.linalg

#: from this many samples of delay on, :class:`_StepEvaluator` runs a block of ``delay``
#: samples at a time (below, sample by sample is quicker)
BLOCK_DELAY = 8


class OldStepEvaluator:
    """Linear step response of Fig. 4 on eq. (9), sampled with ZOH, with ``delay``
    samples of delay; θm also between samples (``sub`` points per period)."""

    def __init__(self, J: float, V: float, K: float, dt: float, delay: int, n: int, sub: int = 10):
        A = np.array([[0.0, 1.0], [0.0, -V / J]])
        B = np.array([0.0, K / J])

        def zoh(h):
            m = np.zeros((3, 3))
            m[:2, :2], m[:2, 2] = A * h, B * h
            e = scipy.linalg.expm(m)
            return e[:2, :2], e[:2, 2]

        self.Ad, self.Bd = zoh(dt)
        fine = [zoh(dt * j / sub) for j in range(sub)]
        self.Phi = np.array([f[0][0] for f in fine])  # (sub, 2): θ row
        self.Gam = np.array([f[1][0] for f in fine])  # (sub,)
        self.delay, self.n, self.sub, self.dt = delay, n, sub, dt
        self.time = np.arange(n * sub) * dt / sub
        # a block of d samples (d the delay) has its motor inputs u_{k−d} from the block
        # before: the motor over the block is x_k = A_d^k x_0 + Σ_{j<k} A_d^{k−1−j} B_d u_a,j
        # (k = 0 ... d), these powers once for all candidates
        if delay >= BLOCK_DELAY:
            pw = [np.eye(2)]
            for _ in range(delay):
                pw.append(self.Ad @ pw[-1])
            self._M0 = np.array(pw)  # (d + 1, 2, 2)
            Mu = np.zeros((delay + 1, delay, 2))
            for k in range(delay + 1):
                for j in range(k):
                    Mu[k, j] = pw[k - 1 - j] @ self.Bd
            self._Mu = Mu
            kk, jj = np.meshgrid(np.arange(delay + 1), np.arange(delay), indexing="ij")
            self._E = np.where(jj < kk, kk - 1 - jj, 0)  # exponents k − 1 − j (j < k)
            self._lower = jj < kk

    def _blocks(self, X: np.ndarray, U: np.ndarray, c: tuple) -> None:
        """The recursion of :meth:`run` a block of d samples at a time (d >= 1 the delay):
        within a block the motor's inputs u_{k−d} are known (the block before's commands,
        0 before the first sample), so the motor's states over the block follow at once,
        and so do the compensators' s2 (a first-order filter of θm) and s1 (of e) and the
        commands. n / d steps of O(P d²) work instead of n steps."""
        c_th, c_s1, c_s2, k1, k2, e_s2, b1, b2 = c
        d, n, P = self.delay, self.n, X.shape[-1]
        # per candidate, b^(k−1−j) for j < k (0 elsewhere)
        ks = np.arange(d + 1)
        p1, p2 = b1[:, None] ** ks, b2[:, None] ** ks  # (P, d + 1): b^0 ... b^d
        pow1 = np.where(self._lower, p1[:, self._E], 0.0)  # (P, d + 1, d)
        pow2 = np.where(self._lower, p2[:, self._E], 0.0)
        x0, s1, s2 = np.zeros((2, P)), np.zeros(P), np.zeros(P)
        for k0 in range(0, n, d):
            m = min(d, n - k0)
            ua = U[k0 - d : k0 - d + m] if k0 >= d else np.zeros((m, P))
            # (θm, ω) at k0 + k, k = 0 ... m
            x = np.einsum("kab,bp->kap", self._M0[: m + 1], x0) + np.einsum(
                "kja,jp->kap", self._Mu[: m + 1, :m], ua
            )
            th = x[:, 0]
            sv2 = p2[:, : m + 1].T * s2 + (pow2[:, : m + 1, :m] @ th[:m].T[:, :, None])[..., 0].T
            e = -k2 * th[:m] + e_s2 * sv2[:m] + 1.0
            sv1 = p1[:, : m + 1].T * s1 + (pow1[:, : m + 1, :m] @ e.T[:, :, None])[..., 0].T
            X[k0 : k0 + m, 0:2] = x[:m]
            X[k0 : k0 + m, 2] = sv1[:m]
            X[k0 : k0 + m, 3] = sv2[:m]
            U[k0 : k0 + m] = c_th * th[:m] + c_s1 * sv1[:m] + c_s2 * sv2[:m] + k1
            x0, s1, s2 = x[m], sv1[m], sv2[m]

    def run(self, p: np.ndarray, gain: float):
        """θm per unit step on the fine grid (n·sub, ...) and the feedback current per
        unit step at the samples (n, ...), for p = (a1, b1, a2, b2) of shape (4,) or
        (4, P). The loop, sample by sample: u_k = k1 (b1 − a1) s1 + k1 e_k with
        e_k = 1 − k2 (b2 − a2) s2 − k2 θm (the compensators' states s1, s2:
        s1⁺ = b1 s1 + e_k, s2⁺ = b2 s2 + θm), the motor (θm, ω)⁺ = A_d (θm, ω) + B_d u_{k−d}
        (ZOH of eq. (9); u = 0 before the first sample)."""
        p = np.asarray(p, float)
        single = p.ndim == 1
        a1, b1, a2, b2 = p[:, None] if single else p
        k1 = gain * (1 - b1) / (1 - a1)
        k2 = (1 - b2) / (1 - a2)
        d, n = self.delay, self.n
        # u = k1 (b1 − a1) s1 + k1 e,  e = r − k2 (b2 − a2) s2 − k2 θ  (r = 1):
        # u = c_th θ + c_s1 s1 + c_s2 s2 + k1 and e = −k2 θ − k2 (b2 − a2) s2 + 1
        c_th, c_s1, c_s2 = -k1 * k2, k1 * (b1 - a1), -k1 * k2 * (b2 - a2)
        e_s2 = -k2 * (b2 - a2)
        (a00, a01), (a10, a11) = self.Ad
        g0, g1 = self.Bd
        # the recursion in its own variables, the delay line as the command history: per
        # sample O(P) work whatever the delay (the companion form's x⁺ = A_cl x + b_cl in
        # x = (θm, ω, s1, s2, u_{k−d}, ..., u_{k−1}) costs O(P (4 + d)²) a sample, which on a
        # fitted rig with an 86-sample loop delay made one design minutes long)
        X = np.empty((n, 4, a1.size))  # θm, ω, s1, s2 at each sample, before its update
        U = np.empty((n, a1.size))  # the command computed at each sample
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            if d >= BLOCK_DELAY:
                self._blocks(X, U, (c_th, c_s1, c_s2, k1, k2, e_s2, b1, b2))
            else:  # sample by sample
                th, om, s1, s2 = (np.zeros(a1.size) for _ in range(4))
                for k in range(n):
                    X[k, 0], X[k, 1], X[k, 2], X[k, 3] = th, om, s1, s2
                    u = c_th * th + c_s1 * s1 + c_s2 * s2 + k1
                    U[k] = u
                    ua = (U[k - d] if k >= d else 0.0) if d else u
                    e = -k2 * th + e_s2 * s2 + 1.0
                    th, om = a00 * th + a01 * om + g0 * ua, a10 * th + a11 * om + g1 * ua
                    s1, s2 = b1 * s1 + e, X[k, 0] + b2 * s2
        X = np.nan_to_num(X, nan=1e6, posinf=1e6, neginf=-1e6)
        U = np.nan_to_num(U, nan=1e6, posinf=1e6, neginf=-1e6)
        cs = c_th * X[:, 0] + c_s1 * X[:, 2] + c_s2 * X[:, 3] + k1
        if d:  # the applied command: the one computed d samples before (0 before that)
            ua = np.concatenate([np.zeros((min(d, n), a1.size)), U[: max(n - d, 0)]])
        else:
            ua = cs
        # θ(t_k + j T/sub) = Φ_j[0] (θ_k, ω_k) + Γ_j[0] u_a,k, all fine points at once
        theta = (
            np.einsum("jc,kcp->kjp", self.Phi, X[:, :2]) + np.einsum("j,kp->kjp", self.Gam, ua)
        ).reshape(n * self.sub, a1.size)
        if single:
            return theta[:, 0], cs[:, 0]
        return theta, cs


def old_settling(t: np.ndarray, y: np.ndarray, band: float) -> np.ndarray:
    """Last time |y − 1| leaves the band (y of shape (n,) or (n, P)), linearly
    interpolated between grid points; inf where it never settles."""
    err = np.abs(y - 1.0)
    if err.ndim == 1:
        return old_settling(t, y[:, None], band)[0]
    n = err.shape[0]
    outside = err > band
    any_out = outside.any(axis=0)
    last = n - 1 - np.argmax(outside[::-1], axis=0)
    nxt = np.minimum(last + 1, n - 1)
    cols = np.arange(err.shape[1])
    e0, e1 = err[last, cols], err[nxt, cols]
    frac = np.clip((e0 - band) / np.where(e0 > e1, e0 - e1, 1.0), 0.0, 1.0)
    ts = t[last] + frac * (t[nxt] - t[last])
    ts = np.where(last == n - 1, np.inf, ts)
    return np.where(any_out, ts, 0.0)


def old_cost(ev, p, dc_gain, band, horizon, max_overshoot):
    """Vectorised over candidates p (4, P): settling time plus penalties."""
    theta, cs = ev.run(p, dc_gain)
    ts = old_settling(ev.time, theta, band)
    ts = np.where(np.isfinite(ts), ts, horizon * (1.0 + np.abs(theta[-1] - 1.0)))
    excess = np.maximum(0.0, np.max(np.abs(cs), axis=0) / dc_gain - 1.0)
    over = np.maximum(0.0, np.max(theta, axis=0) - 1.0 - max_overshoot)
    ise = np.mean((theta - 1.0) ** 2, axis=0) * horizon
    c = ts + horizon * 10.0 * (excess + over) + 1e-3 * np.minimum(ise, 1.0)
    return np.where(np.isfinite(c), c, 100.0 * horizon)
