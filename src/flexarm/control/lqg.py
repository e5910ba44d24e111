"""A discrete observer-based (LQG) controller for any arm, acting on the tracking error.

Design model: the arm's linear model ẋ = A x + B u, y = C x
(:func:`flexarm.models.linearize.linearize`,
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

The pieces, for designs on richer models (:mod:`flexarm.design.linear`): the loop's pure
delays as shift registers of the sampled model (:func:`augment_delays`), integrators of
tracking errors (LQI, :func:`integral_model`), the controller e → u of any gains K, L
(:func:`observer_controller`; with two degrees of freedom: the reference as a state),
its loop's poles (:func:`loop_poles`), and its
``[controller] type = "lti"`` scenario section (:func:`lti_controller_spec`).
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
        raise ValueError(
            f"lqg: {what} has shape {a.shape}; expected ({n}, {n}) (or {n} "
            "diagonal entries, or one number)"
        )
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
        raise ValueError(
            "lqg: give the continuous-time linear model (it is sampled here "
            "with a zero-order hold at dt)"
        )
    if not dt > 0:
        raise ValueError(f"lqg: dt = {dt!r}; give the controller period in s (> 0)")
    n, m, p = plant.nstates, plant.ninputs, plant.noutputs
    Q, R = _weight(Q, n, "Q"), _weight(R, m, "R")
    W, V = _weight(W, n, "W"), _weight(V, p, "V")
    cont = control.ss(
        plant.A,
        plant.B,
        plant.C,
        np.zeros((p, m)),
        states=list(plant.state_labels),
        inputs=list(plant.input_labels),
        outputs=list(plant.output_labels),
    )
    sysd = control.c2d(cont, dt, "zoh", name=f"{plant.name}, sampled")
    Ad, Bd, C = np.asarray(sysd.A), np.asarray(sysd.B), np.asarray(sysd.C)
    K, _, _ = control.dlqr(Ad, Bd, Q, R)
    L, _, _ = control.dlqe(Ad, np.eye(n), C, W, V)
    K, L = np.asarray(K), np.asarray(L)
    ctrl = observer_controller(
        control.ss(
            Ad,
            Bd,
            C,
            np.zeros((p, m)),
            dt,
            inputs=list(plant.input_labels),
            outputs=list(plant.output_labels),
        ),
        K,
        L,
        name="lqg",
    )
    return LQGDesign(
        ctrl, K, L, sysd, np.linalg.eigvals(Ad - Bd @ K), np.linalg.eigvals(Ad - L @ C)
    )


# ----------------------------------------------------------------- delays and integral action
def augment_delays(
    sysd: control.StateSpace, input_delay: int = 0, output_delays=None
) -> control.StateSpace:
    """The sampled model x⁺ = A x + B u, y = C x with the loop's pure delays as shift
    registers (states), as :mod:`flexarm.sim.sampled` applies them:

    * computation delay d_c (samples): the plant gets u_{k−d_c}; registers
      ρ_1 = u_{k−1}, …, ρ_{d_c} = u_{k−d_c}, ρ_1⁺ = u_k, ρ_j⁺ = ρ_{j−1}, x⁺ = A x + B ρ_{d_c};
    * sensor delay d_i of output i: registers o_i,1 = y_i,k−1, …, o_i,d_i = y_i,k−d_i,
      o_i,1⁺ = C_i x, o_i,j⁺ = o_i,j−1, and the output reads o_i,d_i.

    State order: x, the input registers (per input, oldest last), then each delayed output's
    registers. Inputs and outputs keep their names; the states are named ``u[k-j]`` /
    ``<output>[k-j]``. Size n + m d_c + Σ d_i."""
    if not sysd.isdtime(strict=True):
        raise ValueError("augment_delays: give the sampled (discrete-time) model")
    A, B, C = (np.asarray(a, float) for a in (sysd.A, sysd.B, sysd.C))
    n, m, p = A.shape[0], B.shape[1], C.shape[0]
    od = [0] * p if output_delays is None else [int(d) for d in output_delays]
    if len(od) != p or min(od, default=0) < 0 or int(input_delay) < 0:
        raise ValueError(
            f"augment_delays: input_delay = {input_delay!r} and output_delays = "
            f"{output_delays!r}; give whole samples >= 0, one delay per output ({p})"
        )
    dc = int(input_delay)
    N = n + m * dc + sum(od)
    Aa, Ba, Ca = np.zeros((N, N)), np.zeros((N, m)), np.zeros((p, N))
    names = list(sysd.state_labels)
    Aa[:n, :n] = A
    if dc == 0:
        Ba[:n] = B
    else:
        r0 = n  # register j (1-based) of input i at n + i dc + j − 1
        for i in range(m):
            base = r0 + i * dc
            Ba[base, i] = 1.0
            for j in range(1, dc):
                Aa[base + j, base + j - 1] = 1.0
            Aa[:n, base + dc - 1] = B[:, i]
            names += [f"{sysd.input_labels[i]}[k-{j}]" for j in range(1, dc + 1)]
    k = n + m * dc
    for i, d in enumerate(od):
        if d == 0:
            Ca[i, :n] = C[i]
            continue
        Aa[k, :n] = C[i]
        for j in range(1, d):
            Aa[k + j, k + j - 1] = 1.0
        Ca[i, k + d - 1] = 1.0
        names += [f"{sysd.output_labels[i]}[k-{j}]" for j in range(1, d + 1)]
        k += d
    return control.ss(
        Aa,
        Ba,
        Ca,
        np.zeros((p, m)),
        sysd.dt,
        states=names,
        inputs=list(sysd.input_labels),
        outputs=list(sysd.output_labels),
        name="augmented model",
    )


def integral_model(plant: control.StateSpace, integral) -> tuple[np.ndarray, np.ndarray]:
    """(A_r, B_r) of the sampled model with integrators of the tracking errors of the outputs
    ``integral`` (indices): q⁺ = q + T e_i, e = −y in the shifted coordinates of the
    module docstring, so A_r = [[A, 0], [−T S C, I]], B_r = [[B], [0]] (S selects the
    outputs). The state feedback u = −K_r (x, q) of this model is LQI."""
    A, B, C = (np.asarray(a, float) for a in (plant.A, plant.B, plant.C))
    n, m = B.shape
    idx = list(integral or ())
    ni = len(idx)
    T = float(plant.dt)
    Ar = np.block([[A, np.zeros((n, ni))], [-T * C[idx], np.eye(ni)]])
    Br = np.vstack([B, np.zeros((ni, m))])
    return Ar, Br


def observer_controller(
    plant: control.StateSpace, K, L, *, integral=(), reference=None, name: str = "lqg"
) -> control.StateSpace:
    """The observer-based controller e → u of the discrete model ``plant`` (x⁺ = A x + B u,
    y = C x): predictor x̂⁺ = A x̂ + B u + L (y − C x̂) on y = −e (module docstring), and,
    for the outputs ``integral`` (indices), integrators q⁺ = q + T e_i of the errors;
    u = −K (x̂, q) (K of shape (m, n + len(integral))):

        x̂⁺ = (A − L C − B K_x) x̂ − B K_q q − L e,   q⁺ = q + T S e,   u = −K_x x̂ − K_q q.

    Discrete, dt = T, inputs ``e_<output>``, outputs the plant's inputs, no feedthrough (u_k
    uses the errors up to k − 1). Its loop with ``plant`` has the eigenvalues of
    A_r − B_r K (:func:`integral_model`) and of A − L C (separation).

    ``reference = (tracked, Z)``: two degrees of freedom. The controller reads every output
    against 0 (e = −y: the observer estimates the state itself, not its shift) and, as
    extra inputs ``e_<output>_ref``, the tracked outputs against their references,
    e_r = r − y_t; so r = e_r + y_t is known and the reference enters as the state it
    asks for, Z r (Z: (n, len(tracked)), the state of a unit shift of each tracked output
    at rest), u = −K_x (x̂ − Z r) − K_q q; the integrators integrate e_r. A reference step is
    then a state error for the regulator, not a jump the observer has to explain; the loop's
    own dynamics (r = 0) are those of the one-input form."""
    A, B, C = (np.asarray(a, float) for a in (plant.A, plant.B, plant.C))
    n, m, p = A.shape[0], B.shape[1], C.shape[0]
    K, L = np.asarray(K, float), np.asarray(L, float)
    idx = list(integral or ())
    ni = len(idx)
    Kx, Kq = K[:, :n], K[:, n:]
    T = float(plant.dt)
    Ac = np.block([[A - L @ C - B @ Kx, -B @ Kq], [np.zeros((ni, n)), np.eye(ni)]])
    Cc = np.hstack([-Kx, -Kq])
    outs = list(plant.output_labels)
    if reference is None:
        S = np.eye(p)[idx].reshape(ni, p)
        return control.ss(
            Ac,
            np.vstack([-L, T * S]),
            Cc,
            np.zeros((m, p)),
            plant.dt,
            inputs=[f"e_{k}" for k in outs],
            outputs=list(plant.input_labels),
            name=name,
        )
    tracked, Z = list(reference[0]), np.asarray(reference[1], float)
    nt = len(tracked)
    Z = Z.reshape(n, nt)
    if not set(idx) <= set(tracked):
        raise ValueError(f"observer_controller: integral {idx} must be tracked outputs {tracked}")
    St = np.eye(p)[tracked].reshape(nt, p)
    KZ = Kx @ Z  # (m, nt): r = e_r − St e_y
    Sq = np.zeros((ni, nt))
    for j, i in enumerate(idx):
        Sq[j, tracked.index(i)] = 1.0
    Bc = np.vstack([np.hstack([-L - B @ KZ @ St, B @ KZ]), np.hstack([np.zeros((ni, p)), T * Sq])])
    Dc = np.hstack([-KZ @ St, KZ])
    return control.ss(
        Ac,
        Bc,
        Cc,
        Dc,
        plant.dt,
        inputs=[f"e_{k}" for k in outs] + [f"e_{outs[i]}_ref" for i in tracked],
        outputs=list(plant.input_labels),
        name=name,
    )


def input_rows(plant: control.StateSpace, controller: control.StateSpace) -> np.ndarray:
    """M: the controller's inputs as rows of the plant's outputs (e = r − M y): the identity
    for the one-input form, with the tracked outputs' rows appended for the two-degrees-of-
    freedom form (inputs ``e_<output>_ref``)."""
    outs = list(plant.output_labels)
    if not any(lab.endswith("_ref") for lab in controller.input_labels):
        return np.eye(len(outs))
    rows = []
    for lab in controller.input_labels:
        k = lab[2:-4] if lab.endswith("_ref") else lab[2:]
        rows.append(np.eye(len(outs))[outs.index(k)])
    return np.asarray(rows).reshape(len(rows), len(outs))


def loop_poles(plant: control.StateSpace, controller: control.StateSpace) -> np.ndarray:
    """Eigenvalues of the discrete ``plant`` (x⁺ = A x + B u, y = C x) in closed loop with
    ``controller`` (e → u) on e = −M y, references at 0 (M: :func:`input_rows`)."""
    Ad, Bd, C = (np.asarray(a) for a in (plant.A, plant.B, plant.C))
    Ac, Bc, Cc, Dc = (
        np.asarray(a) for a in (controller.A, controller.B, controller.C, controller.D)
    )
    MC = input_rows(plant, controller) @ C
    # u = Cc ξ − Dc M C x;  x⁺ = Ad x + Bd u ;  ξ⁺ = Ac ξ − Bc M C x
    top = np.hstack([Ad - Bd @ Dc @ MC, Bd @ Cc])
    bot = np.hstack([-Bc @ MC, Ac])
    return np.linalg.eigvals(np.vstack([top, bot]))


def closed_loop_poles(design: LQGDesign) -> np.ndarray:
    """Eigenvalues of the design model in closed loop with the controller (e = −y):
    should be the union of :attr:`LQGDesign.regulator_poles` and
    :attr:`LQGDesign.estimator_poles`."""
    return loop_poles(design.plant, design.controller)


def lti_controller_spec(controller: control.StateSpace, inputs, setpoints) -> dict:
    """The scenario's ``[controller]`` (``type = "lti"``) of a discrete controller e → u:
    ``inputs`` the measured channels (one per controller input), ``setpoints`` a reference
    channel or 0 per input; ``allow_unstable`` set when the controller's own A has an
    eigenvalue outside the unit circle (an observer-based controller may)."""
    A = np.asarray(controller.A)
    rho = float(np.abs(np.linalg.eigvals(A)).max()) if A.size else 0.0
    return {
        "type": "lti",
        "dt": float(controller.dt),
        "A": A.tolist(),
        "B": np.asarray(controller.B).tolist(),
        "C": np.asarray(controller.C).tolist(),
        "D": np.asarray(controller.D).tolist(),
        "inputs": list(inputs),
        "setpoints": [s if s else 0 for s in setpoints],
        "outputs": list(controller.output_labels),
        "allow_unstable": bool(rho > 1.0),
    }


def scenario_lqg(
    scenario, dt: float, *, measured: dict[str, str], setpoints: dict[str, str], Q, R, W, V, x0=None
):
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
        same = [
            s
            for s in sensors.values()
            if (s.get("signal") or "") == measured[c] and "filter" not in s
        ]
        sensors[c] = {
            "signal": measured[c],
            **({"quantum": same[0]["quantum"]} if same and "quantum" in same[0] else {}),
        }
    data["controller"] = lti_controller_spec(
        design.controller, chans, [setpoints.get(c, 0) for c in chans]
    )
    return design, scenario_from_dict(data, f"{scenario.name} with an LQG at {dt:g} s")
