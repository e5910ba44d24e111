"""Fit a physical lumped beam to transfer functions (how the two-mass scenario was made).

FRB Sec. VI-C gives the two-mass arm only by its transfer functions, eq. (14)
θt/θm = −45.475 (s² − 1273.3)/(s⁴ + 1637.1 s² + 57903.3175), and the static coupling
of eq. (16), Ĉ_t = 1.941 lb·in/rad (θm − θt). With the masses at given fractions of the
length, the unknowns are EI, the length ℓ and the masses; the residuals are the log-ratios
of the non-zero coefficients of G_b (denominator monic, numerator relative to its leading
coefficient) and of the static coupling C_t/(θm − θt) at s = 0 (closed form,
:func:`flexarm.models.lumped_beam.static_coupling`), solved by
:func:`scipy.optimize.least_squares` in log-parameters (positive by construction).
For two masses this is 4 equations in 3 unknowns, consistent for FRB's data (the
residuals reach rounding), with a full-rank Jacobian.

The residuals are finite wherever the optimiser may step: a trial beam whose G_b has
another structure (a coefficient vanishing or missing) gets the finite penalty
:data:`PENALTY` in every residual instead of a log of zero. A search that stops without
converging, or with residuals above :data:`RESIDUAL_TOL`, warns (``RuntimeWarning``) and
says so in ``LumpedBeamFit.converged`` / ``message``.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import control
import numpy as np
import scipy.optimize

from flexarm.models.lumped_beam import lumped_beam_block
from flexarm.models.lumped_beam import static_coupling as static_coupling_of
from flexarm.specs.arm import LumpedBeam

# Log-ratio residual of a trial beam whose G_b has another structure: large (e^50) and
# finite, so least_squares' finite-difference Jacobian stays finite.
PENALTY = 50.0
# An exact fit (as many equations as unknowns) reaches rounding: the log-ratios of
# coefficients computed through ss2tf / minreal carry ~1e-12; 1e-8 leaves a margin.
RESIDUAL_TOL = 1e-8


@dataclass(frozen=True)
class LumpedBeamFit:
    flexural_rigidity: float  # N*m²
    length: float  # m
    masses: tuple[float, ...]  # kg
    positions: tuple[float, ...]  # m
    residuals: np.ndarray
    converged: bool = True  # least_squares stopped on a tolerance and residuals ≤ RESIDUAL_TOL
    message: str = ""  # least_squares' status message

    def wire_diameter(self, youngs_modulus: float) -> float:
        """Diameter (m) of a round wire of modulus E (Pa) with this EI."""
        return float((64 * self.flexural_rigidity / (np.pi * youngs_modulus)) ** 0.25)

    def spec(self, damping_ratio: float = 0.0) -> LumpedBeam:
        return LumpedBeam.model_validate(
            dict(
                length=self.length,
                flexural_rigidity=self.flexural_rigidity,
                damping_ratio=damping_ratio,
                masses=[
                    {"mass": m, "position": p}
                    for m, p in zip(self.masses, self.positions, strict=False)
                ],
            )
        )


def _coefs(tf: control.TransferFunction) -> tuple[np.ndarray, np.ndarray]:
    num = np.trim_zeros(np.asarray(tf.num[0][0], float), "f")
    den = np.trim_zeros(np.asarray(tf.den[0][0], float), "f")
    return num / num[0], den / den[0]


def fit_lumped_beam(
    tip_tf: control.TransferFunction,
    static_coupling: float,
    fractions: tuple[float, ...],
    length: float,
    guess: tuple[float, float] = (0.02, 0.05),
) -> LumpedBeamFit:
    """Masses at ``fractions`` of ``length`` (m); ``static_coupling`` in N*m/rad.

    ``guess`` = (EI N*m², each mass kg) starts the search."""
    tnum, tden = _coefs(tip_tf)
    n = len(fractions)
    L = float(length)
    if not (np.isfinite(L) and L > 0):
        raise ValueError(f"length must be the beam's positive length in m; got {length!r}")

    def build(p):
        EI, *ms = np.exp(p)
        return LumpedBeam.model_validate(
            dict(
                length=L,
                flexural_rigidity=EI,
                masses=[
                    {"mass": m, "position": f * L} for m, f in zip(ms, fractions, strict=False)
                ],
            )
        )

    n_res = len(tnum) + len(tden) - 1 - sum(1 for c in (*tnum[1:], *tden[1:]) if c == 0)

    def residuals(p):
        try:  # a step to exp(p) = 0 or inf is not a beam: penalised, not raised
            beam = build(p)
            num, den = _coefs(lumped_beam_block(beam).transfer_functions()[0])
        except (ValueError, np.linalg.LinAlgError):
            return np.full(n_res, PENALTY)
        if len(num) != len(tnum) or len(den) != len(tden):
            return np.full(n_res, PENALTY)
        with np.errstate(divide="ignore", invalid="ignore"):
            r = [np.log(abs(num[k] / tnum[k])) for k in range(1, len(tnum)) if tnum[k] != 0]
            r += [np.log(abs(den[k] / tden[k])) for k in range(1, len(tden)) if tden[k] != 0]
            r.append(np.log(static_coupling_of(beam) / static_coupling_target))
        r = np.asarray(r, dtype=float)
        return np.where(np.isfinite(r), r, PENALTY)

    static_coupling_target = float(static_coupling)
    if not (np.isfinite(static_coupling_target) and static_coupling_target > 0):
        raise ValueError(
            f"static_coupling must be a positive stiffness in N*m/rad; got {static_coupling!r}"
        )
    p0 = np.log([guess[0]] + [guess[1]] * n)
    sol = scipy.optimize.least_squares(residuals, p0, xtol=1e-15, ftol=1e-15, gtol=1e-15)
    worst = float(np.max(np.abs(sol.fun)))
    converged = bool(sol.status > 0 and worst <= RESIDUAL_TOL)
    if not converged:
        warnings.warn(
            f"fit_lumped_beam: least_squares stopped without an exact fit (status "
            f"{sol.status}: {sol.message}; largest log-ratio residual {worst:.3g}); try "
            f"another guess=(EI, mass) or other mass fractions",
            RuntimeWarning,
            stacklevel=2,
        )
    EI, *ms = np.exp(sol.x)
    return LumpedBeamFit(
        float(EI),
        float(L),
        tuple(float(m) for m in ms),
        tuple(float(f * L) for f in fractions),
        sol.fun,
        converged,
        str(sol.message),
    )
