"""A discrete observer-based (LQG) controller for any arm, acting on the tracking error.

Design model: the arm's linear model ẋ = A x + B u, y = C x (:func:`flexarm.models.linearize.linearize`,
joint friction left out), sampled with a zero-order hold at the controller period T:
x⁺ = A_d x + B_d u, y = C x. Then

* the regulator gain K of ``control.dlqr(A_d, B_d, Q, R)``: u = −K x̂ minimises
  Σ xᵀQx + uᵀRu;
* the predictor Kalman gain L of ``control.dlqe(A_d, I, C, W, V)``:
  x̂⁺ = A_d x̂ + B_d u + L (y − C x̂), W and V the process and measurement noise covariances.

Tracking: for an arm without a stiffness to ground (a horizontal arm, or one whose gravity
is compensated) a constant shift of the joint angles is an equilibrium, A x_r = 0 for the
reference state x_r = (θ_r, 0, ...); so x̃ = x − x_r obeys the same model and the error
e = y_r − y = −C x̃ is all the controller needs (the form of a state feedback on
x_ref − x, as lab rigs run it). Substituting u = −K ξ (ξ the estimate of x̃),

    ξ⁺ = (A_d − B_d K − L C) ξ − L e,      u = −K ξ,

a discrete ``StateSpace`` from e (one input per measured output) to u (one per joint), with
``dt = T``; u_k uses the errors up to k − 1 (a predictor: one period to compute). Its closed
loop with the design model has the eigenvalues of A_d − B_d K and of A_d − L C (separation
principle), which :func:`lqg` returns for checking.
"""

from __future__ import annotations

from dataclasses import dataclass
import control
import numpy as np


@dataclass(frozen=True)
class LQGDesign:
    """An LQG design: the controller e → u, its gains and the design model's numbers."""

    controller: control.StateSpace  #: discrete, dt = T; inputs e_<output>, outputs the commands
    K: np.ndarray  #: regulator gain (n_u, n_x)
    L: np.ndarray  #: predictor Kalman gain (n_x, n_y)
    plant: control.StateSpace  #: the sampled design model (A_d, B_d, C, 0)
    regulator_poles: np.ndarray  #: eig(A_d − B_d K)
    estimator_poles: np.ndarray  #: eig(A_d − L C)


def _weight(w, n: int, what: str) -> np.ndarray:
    a = np.asarray(w, dtype=float)
    if a.ndim == 0:
        a = np.full(n, float(a))
    if a.ndim == 1:
        a = np.diag(a)
    if a.shape != (n, n):
        raise ValueError(f"lqg: {what} has shape {a.shape}; expected ({n}, {n}) (or {n} "
                         "diagonal entries, or one number)")
    if not np.all(np.isfinite(a)) or np.any(np.linalg.eigvalsh((a + a.T) / 2) < -1e-12):
        raise ValueError(f"lqg: {what} must be finite and positive semi-definite")
    return a


def lqg(plant: control.StateSpace, dt: float, Q, R, W, V) -> LQGDesign:
    """The LQG controller of the continuous linear model ``plant`` (e.g. from
    :func:`flexarm.models.linearize.linearize`) at the period ``dt`` (s).

    ``Q`` (n_x), ``R`` (n_u): regulator weights; ``W`` (n_x): process noise covariance
    (per state, in the state's units² per sample), ``V`` (n_y): measurement noise
    covariance (the sensors' variances: e.g. an encoder's q²/12). Each may be a matrix,
    its diagonal, or one number."""
    if not plant.isctime():
        raise ValueError("lqg: give the continuous-time linear model (it is sampled here "
                         "with a zero-order hold at dt)")
    if not dt > 0:
        raise ValueError(f"lqg: dt = {dt!r}; give the controller period in s (> 0)")
    n, m, p = plant.nstates, plant.ninputs, plant.noutputs
    Q, R = _weight(Q, n, "Q"), _weight(R, m, "R")
    W, V = _weight(W, n, "W"), _weight(V, p, "V")
    sysd = control.c2d(control.ss(plant.A, plant.B, plant.C, np.zeros((p, m))), dt, "zoh")
    Ad, Bd, C = np.asarray(sysd.A), np.asarray(sysd.B), np.asarray(sysd.C)
    K, _, _ = control.dlqr(Ad, Bd, Q, R)
    L, _, _ = control.dlqe(Ad, np.eye(n), C, W, V)
    K, L = np.asarray(K), np.asarray(L)
    Ac = Ad - Bd @ K - L @ C
    outs = list(plant.input_labels)
    ins = [f"e_{k}" for k in plant.output_labels]
    ctrl = control.ss(Ac, -L, -K, np.zeros((m, p)), dt, inputs=ins, outputs=outs,
                      name="lqg")
    return LQGDesign(ctrl, K, L, sysd, np.linalg.eigvals(Ad - Bd @ K),
                     np.linalg.eigvals(Ad - L @ C))


def closed_loop_poles(design: LQGDesign) -> np.ndarray:
    """Eigenvalues of the design model in closed loop with the controller (e = −y):
    should be the union of :attr:`LQGDesign.regulator_poles` and
    :attr:`LQGDesign.estimator_poles`."""
    P, Cn = design.plant, design.controller
    Ad, Bd, C = (np.asarray(a) for a in (P.A, P.B, P.C))
    Ac, Bc, Cc = (np.asarray(a) for a in (Cn.A, Cn.B, Cn.C))
    # x⁺ = Ad x + Bd Cc ξ ;  ξ⁺ = Ac ξ + Bc (−C x)
    top = np.hstack([Ad, Bd @ Cc])
    bot = np.hstack([-Bc @ C, Ac])
    return np.linalg.eigvals(np.vstack([top, bot]))



def scenario_lqg(scenario, dt: float, *, measured: dict[str, str], setpoints: dict[str, str],
                 Q, R, W, V, x0=None):
    """An LQG design (:func:`lqg`) for a multi-link scenario's arm, and the scenario with it as
    its ``[controller]`` (``type = "lti"``, period ``dt``) and the sensor channels it reads.

    ``measured``: channel name → plant signal the controller reads (e.g. ``{"theta_1":
    "theta_1", "alpha_1": "deflection_angle_1", ...}``; channels the scenario lacks are added
    as plain sensors: an encoder channel keeps the scenario's quantum where the same
    signal is read by an existing channel without a filter); ``setpoints``: channel name →
    reference channel (channels without one have setpoint 0). The design model is the
    arm linearised about ``x0`` (default: rest at zero), joint friction left out."""
    from flexarm.models.assembly import multi_link_arm
    from flexarm.models.linearize import linearize
    from flexarm.specs.scenario import scenario_from_dict

    arm, _ = multi_link_arm(scenario.arm)
    chans = list(measured)
    design = lqg(linearize(arm, x0, outputs=[measured[c] for c in chans]), dt, Q, R, W, V)
    data = scenario.model_dump(mode="json", exclude_none=True)
    sensors = data.setdefault("sensors", {})
    for c in chans:
        if c in sensors:
            continue
        same = [s for s in sensors.values() if (s.get("signal") or "") == measured[c]
                and "filter" not in s]
        sensors[c] = {"signal": measured[c], **({"quantum": same[0]["quantum"]}
                                                if same and "quantum" in same[0] else {})}
    K = design.controller
    data["controller"] = {
        "type": "lti", "dt": dt, "A": np.asarray(K.A).tolist(), "B": np.asarray(K.B).tolist(),
        "C": np.asarray(K.C).tolist(), "D": np.asarray(K.D).tolist(), "inputs": chans,
        "setpoints": [setpoints.get(c, 0) for c in chans], "outputs": list(K.output_labels),
        "allow_unstable": bool(np.abs(np.linalg.eigvals(np.asarray(K.A))).max() > 1.0)}
    return design, scenario_from_dict(data, f"{scenario.name} with an LQG at {dt:g} s")
