"""Structured identification of the motor: J, V, C and C_f in one linear least squares.

Beyond FRB Sec. II. The paper estimates C_f from the ω0/3ω0 pairs (eqs. 4-6), corrects the
data (eq. 7) and fits a free transfer function. Where friction dominates the current (low
frequencies) any error left in C_f goes straight into the corrected response, and from
there into V and the low real pole of G_m (a 3 % error in C_f gave a 30-50 % error on that
pole in our tests). When the coupling torque is C_t = C (θm − θt) — a massless beam with
one pinned mass, FRB eq. (13) and (16) — eq. (1) at the fundamental of each experiment,

    K i(ω) = (−J ω² + j V ω + C (1 − G_b(jω))) θm(ω) + (4 C_f/π) j e^{j∠θm(ω)},

is linear in (J, V, C, C_f) (the last term: the friction shape's fundamental, measured from
the motor velocity by default, :meth:`HarmonicAnalysis.friction`), with G_b identified separately
(friction does not distort
θt/θm). Stacking real and imaginary parts of all experiments, each row weighted by
1/|K i(ω)| (relative error), gives them by one least squares; their spread comes from the
residual and (AᵀA)⁻¹. The implied G_m = K/(J s² + V s + C (1 − G_b)).

G_b is used with unit static gain (θt = θm at rest, so G_b(0) = 1 exactly): a fitted G_b
whose static gain is 1.0001 would otherwise leave C (1 − G_b) a DC term and move G_m's
integrator off the origin.
"""

from __future__ import annotations

from dataclasses import dataclass

import control
import numpy as np

from flexarm.identification.frequency_domain.harmonics import HarmonicAnalysis


@dataclass(frozen=True)
class PhysicalFit:
    inertia: float  # J, kg*m²
    viscous: float  # V, N*m*s/rad
    stiffness: float  # C, N*m/rad
    coulomb_current: float  # C_f / K, A
    std: dict[str, float]  # one-sigma from the residual
    relative_residual: float  # ‖residual‖ / ‖data‖ (weighted)
    motor_tf: control.TransferFunction

    def to_dict(self) -> dict:
        return {
            "inertia": self.inertia,
            "viscous": self.viscous,
            "stiffness": self.stiffness,
            "coulomb_current": self.coulomb_current,
            "std": dict(self.std),
            "relative_residual": self.relative_residual,
            "method": "linear least squares on K i = (J s^2 + V s + C (1 - G_b)) theta_m "
            "+ (4 C_f / pi) j exp(j angle theta_m) at every fundamental",
        }


def fit_physical(
    analyses: list[HarmonicAnalysis], beam_tf: control.TransferFunction, motor_constant: float
) -> PhysicalFit:
    """J, V, C, C_f from the fundamentals of all experiments (see module docstring)."""
    if len(analyses) < 2:
        raise ValueError("the structured fit needs at least two experiments")
    K = motor_constant
    nb = np.trim_zeros(np.asarray(beam_tf.num[0][0], float), "f")
    db = np.trim_zeros(np.asarray(beam_tf.den[0][0], float), "f")
    nb = nb * (db[-1] / nb[-1])  # G_b(0) = 1
    beam_tf = control.tf(nb, db)
    rows, rhs = [], []
    for an in analyses:
        w = an.omega0
        th = an.phasor("motor_angle")
        i = an.phasor("current")
        gb = complex(beam_tf(1j * w))
        wt = 1.0 / max(abs(K * i), 1e-300)
        rows.append(np.array([-(w**2) * th, 1j * w * th, (1 - gb) * th, an.friction(1)]) * wt)
        rhs.append(K * i * wt)
    A = np.array(rows)
    b = np.array(rhs)
    A2 = np.vstack([np.real(A), np.imag(A)])
    b2 = np.concatenate([np.real(b), np.imag(b)])
    x, *_ = np.linalg.lstsq(A2, b2, rcond=None)
    r = b2 - A2 @ x
    dof = max(len(b2) - 4, 1)
    cov = np.linalg.pinv(A2.T @ A2) * float(r @ r) / dof
    sd = np.sqrt(np.maximum(np.diag(cov), 0.0))
    J, V, C, cf = (float(v) for v in x)
    # G_m = K d_b / ((J s² + V s) d_b + C (d_b − n_b)); d_b − n_b has no constant term
    diff = np.polysub(db, nb)
    diff[-1] = 0.0
    den = np.polyadd(np.polymul([J, V, 0.0], db), C * diff)
    gm = control.tf(
        K * db / den[0], den / den[0], name="G_m", inputs=["current"], outputs=["motor_angle"]
    )
    return PhysicalFit(
        J,
        V,
        C,
        cf / K,
        {
            "inertia": float(sd[0]),
            "viscous": float(sd[1]),
            "stiffness": float(sd[2]),
            "coulomb_current": float(sd[3] / K),
        },
        float(np.linalg.norm(r) / np.linalg.norm(b2)),
        gm,
    )
