"""The flexible link as a linear block driven by the hub: θm, θ̇m → θt, C_t, w_tip.

Two ways to obtain the block:

* :func:`lumped_beam_block`: a massless Euler–Bernoulli cantilever (clamped in the hub,
  flexural rigidity EI) carrying point masses (FRB Sec. VI). Each mass contributes a
  transverse degree of freedom; a ``clamped`` mass with rotary inertia also its slope.
  With y the absolute transverse positions (and absolute slopes), x̄ the positions
  (1 for slopes), w = y − x̄ θm the deflections, K the stiffness (inverse flexibility),
  M the masses and D modal damping,

      M ÿ + D (ẏ − x̄ θ̇m) + K (y − x̄ θm) = 0,
      C_t = x̄ᵀ K w̃ + x̄ᵀ D w̃̇ ,  w̃ = x̄ θm − y       (torque the link takes from the hub)
      θt = θm + w(ℓ)/ℓ ,         w(ℓ) = c_ℓᵀ K w    (tip angle seen from the hub)

  For the single-mass arm this gives C_t = C (θm − θt) with C = 3EI/ℓ and
  G_b(s) = ω²/(s² + 2ζω s + ω²), ω² = C/(m ℓ²): FRB eqs. (13), (16).

* :func:`transfer_function_block`: G_b(s) = θt/θm and C_t = H(s)(θm − θt) given as
  transfer functions (H = C a constant, or FRB eq. (15)).

The block is ``BeamBlock(A, B, C, D)`` with states z, inputs (θm, θ̇m) and outputs
(θt, C_t, w_tip):  ż = A z + B u,  y = C z + D u.
"""

from __future__ import annotations

from dataclasses import dataclass

import control
import numpy as np
import scipy.linalg
import scipy.signal

from flexarm.specs.arm import LumpedBeam, RigidBeam, TransferFunctionBeam

OUTPUTS = ("tip_angle", "coupling_torque", "tip_deflection")


@dataclass(frozen=True)
class BeamBlock:
    """ż = A z + B [θm, θ̇m];  [θt, C_t, w_tip] = C z + D [θm, θ̇m]. SI units."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    length: float | None = None
    mass_dofs: int = 0  # lumped beams: z = (y, ẏ), y of this length
    tip_dof: int | None = None  # index in y of the tip translation (lumped, mass at tip)
    exact: tuple | None = None  # (G_b, C_t/θm, C_t/(θm−θt)) when known exactly (TF beams)
    xbar: np.ndarray | None = None  # lumped: y = x̄ θm + w (positions; 1 for slopes)
    tip_shape: np.ndarray | None = None  # lumped: static w for a unit tip deflection

    @property
    def n_states(self) -> int:
        return self.A.shape[0]

    def transfer_functions(self) -> tuple[control.TransferFunction, control.TransferFunction]:
        """G_b(s) = θt/θm and C_t(s)/θm(s) as python-control transfer functions."""
        if self.exact is not None:
            return self.exact[0], self.exact[1]
        return _siso(self, 0), _siso(self, 1)

    def coupling_tf(self) -> control.TransferFunction:
        """C_t(s)/(θm(s) − θt(s)); 0 for a rigid link (θt = θm and C_t = 0: its masses are
        the hub's inertia, no torque couples the two)."""
        if self.exact is not None:
            return self.exact[2]
        gb, ct = self.transfer_functions()
        rel = _clean(control.minreal(1 - gb, tol=1e-6, verbose=False))
        if not np.any(np.asarray(rel.num[0][0], float)):
            return control.tf([0.0], [1.0])
        return _clean(control.minreal(ct / rel, tol=1e-6, verbose=False))

    def held(self) -> BeamBlock:
        """The block with the tip translation held fixed (FRB Fig. 11 experiment)."""
        if self.tip_dof is None:
            raise ValueError(
                "hold_tip needs a lumped beam with a mass at its tip; this beam has none"
            )
        n = self.mass_dofs
        A, B = self.A.copy(), self.B.copy()
        A[n + self.tip_dof, :] = 0.0
        B[n + self.tip_dof, :] = 0.0
        return BeamBlock(
            A,
            B,
            self.C,
            self.D,
            self.length,
            self.mass_dofs,
            self.tip_dof,
            xbar=self.xbar,
            tip_shape=self.tip_shape,
        )


def _siso(block: BeamBlock, row: int) -> control.TransferFunction:
    """Transfer function from θm to output ``row``, with θ̇m = s θm."""
    A, B, C, D = block.A, block.B, block.C[row : row + 1], block.D[row : row + 1]
    s = control.tf("s")
    if block.n_states == 0:
        return control.tf([D[0, 1], D[0, 0]], [1.0])
    # C (sI-A)^-1 (B0 + s B1) = C (sI-A)^-1 (B0 + A B1) + C B1
    b = (B[:, 0] + A @ B[:, 1]).reshape(-1, 1)
    num, den = scipy.signal.ss2tf(A, b, C, [[0.0]])
    g = control.tf(_trim(num[0]), den)
    g = g + float((C @ B[:, 1])[0]) + float(D[0, 0])
    if D[0, 1] != 0.0:
        g = g + float(D[0, 1]) * s
    return _clean(g)


def _trim(p: np.ndarray, tol: float = 1e-12) -> np.ndarray:
    p = np.atleast_1d(np.asarray(p, float))
    scale = max(np.max(np.abs(p)), 1e-300)
    nz = np.nonzero(np.abs(p) > tol * scale)[0]
    return p[nz[0] :] if nz.size else np.zeros(1)


def _clean(g: control.TransferFunction) -> control.TransferFunction:
    """Zero the round-off coefficients and make the denominator monic."""
    if len(np.trim_zeros(np.asarray(g.den[0][0], float), "f")) > 1:
        g = control.minreal(g, tol=1e-7, verbose=False)
    num = np.asarray(g.num[0][0], float)
    den = np.asarray(g.den[0][0], float)
    sc = max(np.max(np.abs(num)), np.max(np.abs(den)))
    num = np.where(np.abs(num) < 1e-11 * sc, 0.0, num)
    den = np.where(np.abs(den) < 1e-11 * sc, 0.0, den)
    num, den = _trim(num), _trim(den)
    return control.tf(num / den[0], den / den[0], 0)


def cantilever_flexibility(positions: np.ndarray, is_slope: np.ndarray, EI: float) -> np.ndarray:
    """Flexibility of a massless clamped-free beam between generalised DOFs.

    Entry (i, j): the deflection (or slope, if ``is_slope[i]``) at ``positions[i]`` due
    to a unit force (or moment, if ``is_slope[j]``) at ``positions[j]``. Units m/N,
    1/N, rad/(N*m).
    """
    n = len(positions)
    F = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            x, a = positions[i], positions[j]
            if not is_slope[j]:  # unit force at a
                if not is_slope[i]:
                    F[i, j] = x * x * (3 * a - x) / 6 if x <= a else a * a * (3 * x - a) / 6
                else:
                    F[i, j] = x * (2 * a - x) / 2 if x <= a else a * a / 2
            else:  # unit moment at a
                if not is_slope[i]:
                    F[i, j] = x * x / 2 if x <= a else a * (2 * x - a) / 2
                else:
                    F[i, j] = x if x <= a else a
    return F / EI


def lumped_beam_block(beam: LumpedBeam) -> BeamBlock:
    """The linear block of a massless beam with point masses (see module docstring)."""
    L = beam.length
    # merge masses at one position
    merged: dict[float, list[float]] = {}
    for m in beam.masses:
        pos = L if m.position is None else m.position
        entry = merged.setdefault(round(pos, 12), [0.0, 0.0])
        entry[0] += m.mass
        if m.joint == "clamped":
            entry[1] += m.rotary_inertia
    pos = np.array(sorted(merged))
    masses = np.array([merged[p][0] for p in pos])
    rot = np.array([merged[p][1] for p in pos])
    # generalised DOFs: translations at every mass, slopes where rotary inertia counts
    dof_pos = list(pos) + [p for p, j in zip(pos, rot, strict=True) if j > 0]
    dof_slope = [False] * len(pos) + [True] * int(np.sum(rot > 0))
    dof_mass = list(masses) + [j for j in rot if j > 0]
    dof_pos, dof_slope, dof_mass = np.array(dof_pos), np.array(dof_slope), np.array(dof_mass)
    n = len(dof_pos)
    F = cantilever_flexibility(dof_pos, dof_slope, beam.EI)
    if not np.all(np.isfinite(F)) or np.linalg.cond(F) > 1e12:
        # e.g. a length or EI off by many orders of magnitude (a unit slip), F then
        # under- or overflows; the stiffness K = F⁻¹ would be meaningless
        raise ValueError(
            f"arm.beam: length {L:g} m and flexural rigidity {beam.EI:g} N*m**2 "
            f"give a singular flexibility matrix (condition number "
            f"{np.linalg.cond(F):.3g}); check the values and their units"
        )
    K = np.linalg.inv(F)
    K = 0.5 * (K + K.T)
    M = np.diag(dof_mass)
    xbar = np.where(dof_slope, 1.0, dof_pos)
    # modal damping: D = M Φ diag(2 ζ ω) Φᵀ M with Φᵀ M Φ = I
    w2, Phi = scipy.linalg.eigh(K, M)
    D = M @ Phi @ np.diag(2 * beam.damping_ratio * np.sqrt(w2)) @ Phi.T @ M
    Minv = np.diag(1.0 / dof_mass)
    # tip deflection from the generalised forces K w
    c_tip = cantilever_flexibility(np.append(dof_pos, L), np.append(dof_slope, False), beam.EI)[
        -1, :n
    ]
    r_tip = c_tip @ K  # w(ℓ) = r_tip · w
    Z = np.zeros((n, n))
    A = np.block([[Z, np.eye(n)], [-Minv @ K, -Minv @ D]])
    B = np.block([[np.zeros((n, 2))], [np.column_stack([Minv @ K @ xbar, Minv @ D @ xbar])]])
    Cm = np.vstack(
        [
            np.concatenate([r_tip / L, np.zeros(n)]),
            np.concatenate([-xbar @ K, -xbar @ D]),
            np.concatenate([r_tip, np.zeros(n)]),
        ]
    )
    Dm = np.array(
        [
            [1.0 - r_tip @ xbar / L, 0.0],
            [xbar @ K @ xbar, xbar @ D @ xbar],
            [-r_tip @ xbar, 0.0],
        ]
    )
    tip = np.nonzero((np.abs(dof_pos - L) < 1e-12) & ~dof_slope)[0]
    # static shape under a tip force: by reciprocity, c_tip (deflections due to a unit tip
    # force), scaled to a unit tip deflection
    shape = c_tip / float(r_tip @ c_tip)
    return BeamBlock(
        A, B, Cm, Dm, L, n, int(tip[0]) if tip.size else None, xbar=xbar, tip_shape=shape
    )


def static_coupling(beam: LumpedBeam) -> float:
    """C_t/(θm − θt) at s = 0 (N*m/rad) of a lumped beam, in closed form.

    In a slow motion the masses follow the rigid acceleration, so the beam carries the
    inertial loads f = −M x̄ θ̈m: the hub torque is C_t = x̄ᵀ M x̄ θ̈m and the tip lags by
    θm − θt = −w(ℓ)/ℓ = c_ℓᵀ M x̄ θ̈m / ℓ (c_ℓ: tip deflection per unit generalised force).
    Hence C(0) = ℓ x̄ᵀ M x̄ / (c_ℓᵀ M x̄); a single tip mass gives 3EI/ℓ (FRB eq. (16)).
    Equal to the static gain of :meth:`BeamBlock.coupling_tf`, without its 0/0 at s = 0
    (C_t and θm − θt both vanish there to second order) or the cancellation it needs.
    """
    L = beam.length
    pos, is_slope, mass = [], [], []
    for m in beam.masses:
        p = L if m.position is None else m.position
        pos.append(p)
        is_slope.append(False)
        mass.append(m.mass)
        if m.joint == "clamped" and m.rotary_inertia > 0:
            pos.append(p)
            is_slope.append(True)
            mass.append(m.rotary_inertia)
    pos, is_slope, mass = np.array(pos), np.array(is_slope), np.array(mass)
    xbar = np.where(is_slope, 1.0, pos)
    c_tip = cantilever_flexibility(np.append(pos, L), np.append(is_slope, False), beam.EI)[-1, :-1]
    return float(L * (xbar * mass) @ xbar / (c_tip @ (mass * xbar)))


def transfer_function_block(beam: TransferFunctionBeam) -> BeamBlock:
    """The block of a beam given by G_b(s) and C or H(s) (FRB eqs. 13, 15)."""
    nb, db = np.asarray(beam.tip_num, float), np.asarray(beam.tip_den, float)
    if len(_trim(nb)) > len(_trim(db)):
        raise ValueError("tip_num/tip_den: G_b(s) must be proper (numerator degree <= denominator)")
    poles = np.roots(db)
    if np.any(poles.real >= 0):
        raise ValueError(
            f"tip_den: G_b(s) has poles {np.round(poles[poles.real >= 0], 4).tolist()} "
            "in the closed right half-plane; a beam model must be stable"
        )
    if beam.coupling_num is None:
        nh, dh = np.array([beam.stiffness]), np.array([1.0])
    else:
        nh, dh = np.asarray(beam.coupling_num, float), np.asarray(beam.coupling_den, float)
    # θt = G_b θm ;  C_t = H (1 − G_b) θm
    n_ct = np.polymul(nh, np.polysub(db, nb))
    d_ct = np.polymul(dh, db)
    A1, B1, C1, D1 = scipy.signal.tf2ss(nb, db)
    A2, B2, C2, D2 = scipy.signal.tf2ss(n_ct, d_ct)
    A = scipy.linalg.block_diag(A1, A2)
    n1, n2 = A1.shape[0], A2.shape[0]
    B = np.zeros((n1 + n2, 2))
    B[:n1, 0], B[n1:, 0] = B1[:, 0], B2[:, 0]
    L = beam.length
    C = np.zeros((3, n1 + n2))
    D = np.zeros((3, 2))
    C[0, :n1], D[0, 0] = C1[0], D1[0, 0]
    C[1, n1:], D[1, 0] = C2[0], D2[0, 0]
    if L is not None:  # w_tip = ℓ (θt − θm)
        C[2] = L * C[0]
        D[2, 0] = L * (D[0, 0] - 1.0)
    exact = (_clean(control.tf(nb, db)), _clean(control.tf(n_ct, d_ct)), _clean(control.tf(nh, dh)))
    return BeamBlock(A, B, C, D, L, exact=exact)


def rigid_beam_inertia(beam: RigidBeam) -> float:
    """Inertia (kg*m²) that a rigid link's masses add at the hub."""
    total = 0.0
    for m in beam.masses:
        pos = beam.length if m.position is None else m.position
        total += m.mass * pos**2 + (m.rotary_inertia if m.joint == "clamped" else 0.0)
    return total


def rigid_beam_block(beam: RigidBeam) -> BeamBlock:
    """No states: θt = θm, C_t = 0 (the masses go into the hub inertia), w_tip = 0."""
    return BeamBlock(
        np.zeros((0, 0)),
        np.zeros((0, 2)),
        np.zeros((3, 0)),
        np.array([[1.0, 0.0], [0.0, 0.0], [0.0, 0.0]]),
        beam.length,
    )


def beam_block(beam) -> BeamBlock:
    """Dispatch on the beam spec's model."""
    if isinstance(beam, LumpedBeam):
        return lumped_beam_block(beam)
    if isinstance(beam, TransferFunctionBeam):
        return transfer_function_block(beam)
    if isinstance(beam, RigidBeam):
        return rigid_beam_block(beam)
    raise TypeError(f"unknown beam spec {type(beam).__name__}")


def natural_frequencies(block: BeamBlock) -> np.ndarray:
    """Undamped-ish natural frequencies (rad/s) of the free beam block, ascending."""
    if block.n_states == 0:
        return np.zeros(0)
    ev = np.linalg.eigvals(block.A)
    w = np.abs(ev[ev.imag > 0])
    return np.sort(w) if w.size else np.sort(np.abs(ev))[::2]
