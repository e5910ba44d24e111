"""Frequency responses of motor and beam from the sinusoidal experiments (FRB Sec. II-C).

From the fundamentals (phasors, x(t) = Re{X e^{jωt}}) of each experiment at ω:

* raw motor response:        G_raw(ω) = θm(ω) / i(ω)                          (rad/A)
* corrected motor response (FRB eq. (7)), C_f the Coulomb level as a current (A):

      G(ω) = θm(ω) / ( i(ω) − (4 C_f/π) e^{j(π/2 + ∠θm(ω))} )

  i.e. eq. (3) solved for G: the fundamental of the square wave C_f sign(θ̇m) leads θm
  by 90° (eq. (7) prints ∠θm(ω0); for the experiment at ω it is that experiment's own
  fundamental ∠θm(ω)).
* beam response:             G_b(ω) = θt(ω) / θm(ω)                           (rad/rad)
  (independent of the motor friction, FRB Sec. II-C).

Results are returned as arrays sorted by ω and as python-control
``FrequencyResponseData`` objects.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import control
import numpy as np

from flexarm.identification.frequency_domain.harmonics import HarmonicAnalysis


def corrected_motor_response(theta_m1, current1, coulomb_current: float, shape1):
    """FRB eq. (7): θm / (i − C_f S₁) (rad/A), elementwise, with S₁ the fundamental of the
    friction shape per unit C_f (:meth:`HarmonicAnalysis.friction`; the printed equation's
    (4/π) e^{j(π/2 + ∠θm)} for the ideal square wave)."""
    theta_m1 = np.asarray(theta_m1, dtype=complex)
    current1 = np.asarray(current1, dtype=complex)
    return theta_m1 / (current1 - coulomb_current * np.asarray(shape1, dtype=complex))


@dataclass
class FrequencyResponse:
    """Per-experiment fundamentals and responses, sorted by ``omega`` (rad/s).

    ``motor_corrected`` is None when no Coulomb level is known.
    """

    omega: np.ndarray
    names: list[str]
    theta_m: np.ndarray
    theta_t: np.ndarray
    current: np.ndarray
    motor_raw: np.ndarray
    motor_corrected: np.ndarray | None
    beam: np.ndarray
    coulomb_current: float | None

    def frd(self, which: str = "motor") -> control.FrequencyResponseData:
        """``which``: ``"motor"`` (corrected if available, else raw), ``"motor_raw"``,
        ``"motor_corrected"`` or ``"beam"``."""
        data = {
            "motor": self.motor_corrected if self.motor_corrected is not None else self.motor_raw,
            "motor_raw": self.motor_raw,
            "motor_corrected": self.motor_corrected,
            "beam": self.beam,
        }
        if which not in data:
            raise ValueError(f"which = {which!r}; choose one of {', '.join(data)}")
        if data[which] is None:
            raise ValueError("no corrected motor response: the Coulomb friction is unknown")
        return control.FrequencyResponseData(data[which], self.omega, name=which)


def frequency_response(
    analyses: Sequence[HarmonicAnalysis], coulomb_current: float | None = None
) -> FrequencyResponse:
    """Raw and corrected (eq. (7)) motor responses and beam response of all experiments.

    The correction subtracts C_f times the friction shape's fundamental of each experiment
    (:meth:`HarmonicAnalysis.friction`): the measured shape by default; with
    ``friction_shape="ideal"`` analyses it is eq. (7) as printed."""
    order = np.argsort([a.omega0 for a in analyses], kind="stable")
    an = [analyses[k] for k in order]
    w = np.array([a.omega0 for a in an])
    th = np.array([a.phasor("motor_angle", 1) for a in an])
    tt = np.array([a.phasor("tip_angle", 1) for a in an])
    cur = np.array([a.phasor("current", 1) for a in an])
    shape = np.array([a.friction(1) for a in an])
    corr = (
        None
        if coulomb_current is None
        else corrected_motor_response(th, cur, coulomb_current, shape)
    )
    return FrequencyResponse(
        omega=w,
        names=[a.name for a in an],
        theta_m=th,
        theta_t=tt,
        current=cur,
        motor_raw=th / cur,
        motor_corrected=corr,
        beam=tt / th,
        coulomb_current=coulomb_current,
    )
