"""Independent simulation of FRB's identification experiment (test helper, not flexarm code).

Single-mass flexible arm of Feliu, Rattan & Brown (1993), Sec. VI-B, in SI:

    J θ̈m = K i − V θ̇m − C (θm − θt) − C_f·K·tanh(θ̇m / ε)        (eq. 1, C_t = C(θm − θt))
    θ̈t  = ω_b² (θm − θt) − b θ̇t                                    (G_b = ω_b²/(s² + b s + ω_b²))

under a continuous PD current loop i = sat(kp (r − θm) − kd θ̇m, ±i_max) with
r = a sin(ω0 t).  The Coulomb level is given as a current (``coulomb_current``, A), so the
friction torque is C_f·K.  Integrated with SciPy's ``solve_ivp`` (LSODA) and sampled at
``rate`` Hz.

Experiment-design choices (not given by the paper), all kept here:

* PD gains kp = 300 A/rad and kd for ζ = 0.7 on the rigid motor (ωn ≈ 345 rad/s): a high
  gain keeps the motor's stops at each reversal short, so that the friction square wave
  stays close to 90° ahead of θm, as FRB's eq. (3) assumes (with kp = 30 A/rad it lags
  by about 3°, and the correction of eq. (7) degrades where friction dominates).
* Amplitude per frequency (:func:`amplitude`): the linear part of the current about 0.6 A,
  but at most 2 rad of motor angle and at most 0.4 rad of beam deflection |θm − θt|
  (the paper's maximum deflection).
* Frequencies (``PAPER_PAIRS``): ω0 and 3ω0, 1.6 to 39 rad/s, none within 8 % of the
  beam frequency (the free beam mode, excited at the start, decays in ~30 s and would
  leak into the harmonics of a nearby experiment).
* ε = 2 % of the velocity amplitude a·ω0 (the smoothing of the sign function).
* The state starts on the frictionless linear periodic solution, so that the beam's
  very lightly damped free mode (decay rate b/2 = 0.03 1/s) is hardly excited.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from functools import cache
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp


@dataclass(frozen=True)
class Arm:
    J: float = 6.2469e-4  # kg m^2
    V: float = 1.3739e-3  # N m s/rad
    C: float = 0.076152  # N m/rad
    K: float = 0.24676  # N m/A
    wb2: float = 43.75  # 1/s^2
    b: float = 0.06  # 1/s
    coulomb_current: float = 0.132  # A
    i_max: float = 4.12  # A
    kp: float = 300.0  # A/rad
    zeta: float = 0.7  # damping ratio of the PD loop on the rigid motor; fixes kd

    @property
    def kd(self) -> float:
        """A·s/rad, for ζ of J s² + (V + K kd) s + K kp."""
        wn = math.sqrt(self.K * self.kp / self.J)
        return (2 * self.zeta * wn * self.J - self.V) / self.K

    def Gb(self, s):
        return self.wb2 / (s**2 + self.b * s + self.wb2)

    def Gm_inv(self, s):
        """i/θm of the linear part, A/rad."""
        return (self.J * s**2 + self.V * s + self.C * (1 - self.Gb(s))) / self.K

    def Gm(self, s):
        return 1.0 / self.Gm_inv(s)

    def Gm_tf(self):
        """(num, den) of G_m in descending powers of s."""
        J, V, C, w2, b = self.J, self.V, self.C, self.wb2, self.b
        num = self.K * np.array([1.0, b, w2])
        cubic = np.array([J, J * b + V, J * w2 + V * b + C, V * w2 + C * b])
        den = np.concatenate([cubic, [0.0]])
        return num, den


PAPER_ARM = Arm()
# A second, different arm: heavier hub, stiffer coupling, other beam frequency and friction.
SECOND_ARM = Arm(J=1.1e-3, V=2.5e-3, C=0.21, K=0.35, wb2=90.0, b=0.1, coulomb_current=0.08)


A_MAX = 2.0  # rad, largest motor-angle amplitude
DEFLECTION_MAX = 0.4  # rad, largest beam deflection |θm − θt| (FRB Sec. VI-B.3)
CURRENT_TARGET = 0.6  # A, linear part of the current aimed at


def amplitude(arm: Arm, w: float) -> float:
    """Reference amplitude (rad) for an experiment at w rad/s (see module docstring)."""
    s = 1j * w
    a = CURRENT_TARGET / abs(arm.Gm_inv(s))
    a = min(a, A_MAX, DEFLECTION_MAX / abs(1 - arm.Gb(s)))
    return a


def _linear_initial_state(arm: Arm, w: float, a: float) -> np.ndarray:
    """State at t = 0 on the frictionless, unsaturated linear periodic solution."""
    J, V, C, K = arm.J, arm.V, arm.C, arm.K
    A = np.array(
        [
            [0, 1, 0, 0],
            [-(K * arm.kp + C) / J, -(V + K * arm.kd) / J, C / J, 0],
            [0, 0, 0, 1],
            [arm.wb2, 0, -arm.wb2, -arm.b],
        ]
    )
    B = np.array([0, K * arm.kp / J, 0, 0])
    X = np.linalg.solve(1j * w * np.eye(4) - A, B * (-1j * a))  # r = Re{-j a e^{jwt}}
    return X.real


def simulate(
    arm: Arm,
    w: float,
    *,
    a: float | None = None,
    periods: int = 20,
    rate: float = 1000.0,
    coulomb_current: float | None = None,
    eps_fraction: float = 0.02,
):
    """Simulate one experiment; returns (t, dict of signals) sampled at ``rate``."""
    a = amplitude(arm, w) if a is None else a
    cf = arm.coulomb_current if coulomb_current is None else coulomb_current
    J, V, C, K = arm.J, arm.V, arm.C, arm.K
    kp, kd, imax, wb2, b = arm.kp, arm.kd, arm.i_max, arm.wb2, arm.b
    C_f = cf * K
    eps = eps_fraction * a * w
    tanh, sin = math.tanh, math.sin

    def current(t, th, om):
        i = kp * (a * sin(w * t) - th) - kd * om
        return imax if i > imax else (-imax if i < -imax else i)

    def rhs(t, x):
        th, om, tt, ot = x
        i = current(t, th, om)
        dom = (K * i - V * om - C * (th - tt) - C_f * tanh(om / eps)) / J
        return [om, dom, ot, wb2 * (th - tt) - b * ot]

    T = 2 * math.pi / w
    n = int(math.floor(periods * T * rate)) + 1
    t = np.arange(n) / rate
    sol = solve_ivp(
        rhs,
        (0.0, t[-1]),
        _linear_initial_state(arm, w, a),
        method="LSODA",
        t_eval=t,
        rtol=1e-7,
        atol=1e-10,
        max_step=T / 50,
    )
    if not sol.success:
        raise RuntimeError(sol.message)
    th, om, tt, ot = sol.y
    kpv = kp * (a * np.sin(w * t) - th) - kd * om
    i = np.clip(kpv, -imax, imax)
    return t, {"reference": a * np.sin(w * t), "current": i, "motor_angle": th, "tip_angle": tt}


def write_csv(path: Path, t, sig, comments=()):
    """Plain writer (independent of flexarm.io.logs)."""
    with open(path, "w") as f:
        for c in comments:
            f.write(f"# {c}\n")
        f.write("time,reference,current,motor_angle,tip_angle\n")
        data = np.column_stack(
            [t, sig["reference"], sig["current"], sig["motor_angle"], sig["tip_angle"]]
        )
        np.savetxt(f, data, delimiter=",", fmt="%.12g")


# Frequencies (rad/s): ω0 with their 3ω0 partners, ~1 to ~40 rad/s.
PAPER_PAIRS = ((1.6, 4.8), (2.4, 7.2), (3.5, 10.5), (4.4, 13.2), (13.0, 39.0))
SECOND_PAIRS = ((1.5, 4.5), (2.3, 6.9), (4.0, 12.0), (5.6, 16.8), (12.5, 37.5))


@cache
def experiment(arm: Arm, w: float, periods: int = 20):
    return simulate(arm, w, periods=periods)


def write_experiments(folder: Path, arm: Arm, pairs, periods: int = 20) -> list[Path]:
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for pair in pairs:
        for w in pair:
            t, sig = experiment(arm, w, periods)
            p = folder / f"sine_{w:06.2f}.csv"
            write_csv(p, t, sig, comments=(f"omega: {w}", "source: tests/_frb_sim.py"))
            paths.append(p)
    return paths


def with_coulomb(arm: Arm, cf: float) -> Arm:
    return replace(arm, coulomb_current=cf)


_DIRS: dict = {}


def experiment_dir(tmp_path_factory, which: str = "paper") -> Path:
    """A session-wide folder of simulated experiment CSVs (``paper`` or ``second`` arm),
    written once per test session (files are not to be modified by tests)."""
    if which not in _DIRS:
        arm, pairs = {"paper": (PAPER_ARM, PAPER_PAIRS), "second": (SECOND_ARM, SECOND_PAIRS)}[
            which
        ]
        folder = tmp_path_factory.mktemp(f"frb_{which}")
        write_experiments(folder, arm, pairs)
        _DIRS[which] = folder
    return _DIRS[which]


def file_hashes(folder: Path) -> dict[str, str]:
    import hashlib

    return {
        p.name: hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(Path(folder).iterdir())
        if p.is_file()
    }
