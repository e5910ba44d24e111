"""Fit a physical lumped beam to transfer functions (how the two-mass scenario was made).

FRB Sec. VI-C gives the two-mass arm only by its transfer functions, eq. (14)
θt/θm = −45.475 (s² − 1273.3)/(s⁴ + 1637.1 s² + 57903.3175), and the static coupling
of eq. (16), Ĉ_t = 1.941 lb·in/rad (θm − θt). With the masses at given fractions of the
length, the unknowns are EI, the length ℓ and the masses; the residuals are the log-ratios
of the non-zero coefficients of G_b (denominator monic, numerator relative to its leading
coefficient) and of the static coupling C_t/(θm − θt) at s = 0, solved by
:func:`scipy.optimize.least_squares` in log-parameters (positive by construction).
For two masses this is 4 equations in 4 unknowns, solved exactly.
"""

from __future__ import annotations

from dataclasses import dataclass

import control
import numpy as np
import scipy.optimize

from flexarm.models.lumped_beam import lumped_beam_block
from flexarm.specs.arm import LumpedBeam


@dataclass(frozen=True)
class LumpedBeamFit:
    flexural_rigidity: float  # N*m²
    length: float  # m
    masses: tuple[float, ...]  # kg
    positions: tuple[float, ...]  # m
    residuals: np.ndarray

    def wire_diameter(self, youngs_modulus: float) -> float:
        """Diameter (m) of a round wire of modulus E (Pa) with this EI."""
        return float((64 * self.flexural_rigidity / (np.pi * youngs_modulus)) ** 0.25)

    def spec(self, damping_ratio: float = 0.0) -> LumpedBeam:
        return LumpedBeam(length=self.length, flexural_rigidity=self.flexural_rigidity,
                          damping_ratio=damping_ratio,
                          masses=[{"mass": m, "position": p}
                                  for m, p in zip(self.masses, self.positions)])


def _coefs(tf: control.TransferFunction) -> tuple[np.ndarray, np.ndarray]:
    num = np.trim_zeros(np.asarray(tf.num[0][0], float), "f")
    den = np.trim_zeros(np.asarray(tf.den[0][0], float), "f")
    return num / num[0], den / den[0]


def fit_lumped_beam(tip_tf: control.TransferFunction, static_coupling: float,
                    fractions: tuple[float, ...], guess: tuple[float, float, float] = (0.02, 0.3, 0.05)
                    ) -> LumpedBeamFit:
    """Masses at ``fractions`` of the length; ``static_coupling`` in N*m/rad.

    ``guess`` = (EI N*m², length m, each mass kg) starts the search."""
    tnum, tden = _coefs(tip_tf)
    n = len(fractions)

    def build(p):
        EI, L, *ms = np.exp(p)
        return LumpedBeam(length=L, flexural_rigidity=EI, masses=[
            {"mass": m, "position": f * L} for m, f in zip(ms, fractions)])

    def residuals(p):
        beam = build(p)
        block = lumped_beam_block(beam)
        num, den = _coefs(block.transfer_functions()[0])
        if len(num) != len(tnum) or len(den) != len(tden):
            return np.full(len(tnum) + len(tden) - 1, 10.0)
        r = [np.log(abs(num[k] / tnum[k])) for k in range(1, len(tnum)) if tnum[k] != 0]
        r += [np.log(abs(den[k] / tden[k])) for k in range(1, len(tden)) if tden[k] != 0]
        c0 = float(np.real(block.coupling_tf()(0)))
        r.append(np.log(c0 / static_coupling))
        return np.asarray(r)

    p0 = np.log([guess[0], guess[1]] + [guess[2]] * n)
    sol = scipy.optimize.least_squares(residuals, p0, xtol=1e-15, ftol=1e-15, gtol=1e-15)
    EI, L, *ms = np.exp(sol.x)
    return LumpedBeamFit(float(EI), float(L), tuple(float(m) for m in ms),
                         tuple(float(f * L) for f in fractions), sol.fun)
