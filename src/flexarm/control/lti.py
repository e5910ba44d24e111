"""Discrete linear time-invariant systems in the loop: any discrete LTI controller (MIMO state
space or SISO transfer function, inline, from python-control or from a file) and the sensors'
digital filters.

Controller (:class:`LTIController`), run every ``every`` base periods T (its own period
T_c = every·T; the output is held in between)::

    e_k = s_k − y_k                      (setpoints s: named reference channels or 0;
                                          y: named measured channels)
    x_{k+1} = A x_k + B e_k,   v_k = C x_k + D e_k       (at t_k = j·T_c)
    u = v mapped to the plant's inputs (``outputs``), others 0; the loop's actuator
    saturates u at the drives' limits.

A state-feedback law i = K (x_ref − x) is the static case D = K (A, B, C empty); two joints'
laws side by side are D = blockdiag(K_1, K_2). The state starts at ``x0`` (default 0). A
controller whose A has spectral radius > 1 + 1e-9 is refused unless ``allow_unstable``.

Digital filter of a sensor channel (:func:`digital_filter`), SISO, at the sample rate::

    ξ_{k+1} = A ξ_k + B y_k,   v_k = C ξ_k + D y_k

with the kinds (ω = 2π·cutoff rad/s, ζ = damping), all from the companion realisation of the
second-order low-pass, state ξ = (x₁, x₂), ẋ₁ = x₂, ẋ₂ = ω² (y − x₁) − 2ζω x₂:

* ``lowpass2``:       ω² / (s² + 2ζω s + ω²), output x₁ (the low-passed input);
* ``lowpass2_rate``:  ω² s / (s² + 2ζω s + ω²), output x₂ (its rate); ``derivative2`` is the
  same filter (the name the lab gives it on an encoder angle);
* ``tf``: explicit num/den in z (descending powers), realised by ``scipy.signal.tf2ss``;

discretised by ``forward_euler`` (s → (z − 1)/T: A = I + T A_c, B = T B_c, output C ξ_k, no
feedthrough: what the lab's code runs), ``zoh`` or ``tustin`` (``scipy.signal.cont2discrete``).
With forward Euler or zoh the state keeps its meaning (x₁ the low-passed input, x₂ its rate),
so a filter can start from logged outputs (:func:`filter_state_from_log`).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jax import Array

from flexarm.control.discrete import Controller

#: Largest accepted spectral radius of a controller's or filter's A (stable: <= 1).
STABILITY_MARGIN = 1e-9
#: The filter kinds and their output row of the companion state (x₁, x₂).
FILTER_KINDS = {"lowpass2": 0, "lowpass2_rate": 1, "derivative2": 1}


# ----------------------------------------------------------------------------- filters
@dataclass(frozen=True)
class DigitalFilter:
    """A discrete SISO state space ξ⁺ = A ξ + B y, v = C ξ + D y (arrays (n, n), (n,), (n,),
    scalar), with its kind and discretisation (for :func:`filter_state_from_log`)."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: float
    kind: str
    discretisation: str

    @property
    def order(self) -> int:
        return self.A.shape[0]

    def rest_state(self, y0: float) -> np.ndarray:
        """The state at rest under the constant input y0: ξ = (I − A)⁻¹ B y0."""
        n = self.order
        if n == 0:
            return np.zeros(0)
        return np.linalg.solve(np.eye(n) - self.A, self.B * y0)

    def run(self, y: np.ndarray, x0: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Outputs v_k and states ξ_k (k = 0..N−1; ξ_0 = ``x0``, default at rest on y_0)."""
        y = np.asarray(y, float)
        x = self.rest_state(y[0]) if x0 is None else np.asarray(x0, float)
        xs = np.empty((len(y), self.order))
        v = np.empty(len(y))
        for k, yk in enumerate(y):
            xs[k] = x
            v[k] = self.C @ x + self.D * yk
            x = self.A @ x + self.B * yk
        return v, xs


def _get(spec: Any, key: str, default: Any = None) -> Any:
    if isinstance(spec, Mapping):
        return spec.get(key, default)
    return getattr(spec, key, default)


def digital_filter(spec: Any, dt: float | None, *, where: str = "filter") -> DigitalFilter:
    """The discrete filter a ``filter`` spec describes (a mapping or
    :class:`flexarm.specs.experiment.DigitalFilterSpec`; see the module docstring) at the
    sample period ``dt`` (s). Raises ValueError naming ``where`` for an unstable result."""
    from scipy import signal as sps

    kind = _get(spec, "kind")
    if kind == "tf":
        num = np.atleast_1d(np.asarray(_get(spec, "num"), float))
        den = np.atleast_1d(np.asarray(_get(spec, "den"), float))
        num, den = np.trim_zeros(num, "f"), np.trim_zeros(den, "f")
        if len(den) == 0 or len(num) > len(den):
            raise ValueError(f"{where}: num = {list(num)}, den = {list(den)} is not a proper "
                             "transfer function in z (numerator degree <= denominator's)")
        if len(den) == 1:
            A, B, C, D = np.zeros((0, 0)), np.zeros(0), np.zeros(0), float(num[-1] / den[0]) if len(num) else 0.0
        else:
            A, B, C, D = sps.tf2ss(num, den)
            A, B, C, D = A, B[:, 0], C[0], float(D[0, 0])
        filt = DigitalFilter(np.asarray(A, float), np.asarray(B, float), np.asarray(C, float),
                             D, "tf", "none")
    elif kind in FILTER_KINDS:
        if dt is None or not dt > 0:
            raise ValueError(f"{where}: a {kind!r} filter needs the sample period to be "
                             "discretised")
        w = 2 * math.pi * float(_get(spec, "cutoff"))
        z = float(_get(spec, "damping", 0.9))
        Ac = np.array([[0.0, 1.0], [-w * w, -2 * z * w]])
        Bc = np.array([0.0, w * w])
        C = np.eye(2)[FILTER_KINDS[kind]]
        how = _get(spec, "discretisation", "forward_euler")
        if how == "forward_euler":
            A, B, D = np.eye(2) + dt * Ac, dt * Bc, 0.0
        elif how in ("zoh", "tustin"):
            A, B2, C2, D2, _ = sps.cont2discrete((Ac, Bc[:, None], C[None, :], np.zeros((1, 1))),
                                                 dt, method="zoh" if how == "zoh" else "bilinear")
            B, C, D = B2[:, 0], C2[0], float(D2[0, 0])
        else:
            raise ValueError(f"{where}: discretisation = {how!r}; give forward_euler, zoh or "
                             "tustin")
        filt = DigitalFilter(np.asarray(A, float), np.asarray(B, float), np.asarray(C, float),
                             float(D), kind, how)
    else:
        raise ValueError(f"{where}: kind = {kind!r}; give one of "
                         f"{', '.join([*FILTER_KINDS, 'tf'])}")
    if filt.order:
        eig = np.linalg.eigvals(filt.A)
        j = int(np.argmax(np.abs(eig)))
        if abs(eig[j]) >= 1.0:
            hint = (f" (forward Euler needs ω·T small: 2π·{_get(spec, 'cutoff')} Hz·{dt:g} s "
                    "is too large; use discretisation = \"tustin\")"
                    if _get(spec, "discretisation", "forward_euler") == "forward_euler"
                    and kind != "tf" else "")
            raise ValueError(f"{where}: the discrete filter is not stable: eigenvalue "
                             f"{eig[j]:.6g} of A has |z| = {abs(eig[j]):.6g} >= 1{hint}")
    return filt


# ----------------------------------------------------------------------------- controller
class LTIController(Controller):
    """Any discrete LTI controller on e = setpoint − measured (module docstring).

    ``A, B, C, D``: (n, n), (n, p), (m, n), (m, p); ``x0`` (n,). ``inputs``: p measured
    channel names; ``setpoints``: p reference channel names or ``None`` (0); ``outputs``: the
    plant input index of each of the m outputs; ``n_u``: the plant's inputs; ``every``: the
    controller period in base periods."""

    A: Array
    B: Array
    C: Array
    D: Array
    x0: Array
    inputs: tuple[str, ...] = eqx.field(static=True)
    setpoints: tuple[str | None, ...] = eqx.field(static=True)
    outputs: tuple[int, ...] = eqx.field(static=True)
    n_u: int = eqx.field(static=True)
    every: int = eqx.field(static=True, default=1)

    @property
    def measured_signals(self) -> tuple[str, ...]:
        """The measured channels it reads (the loop adds sensors for them)."""
        return self.inputs

    @property
    def reference_signals(self) -> tuple[str, ...]:
        return tuple(s for s in self.setpoints if s is not None)

    def init(self):
        return (self.x0, jnp.zeros((self.n_u,)), jnp.zeros((), dtype=jnp.int32))

    def step(self, state, measured, reference):
        x, held, k = state
        e = jnp.stack([(reference[s] if s is not None else 0.0) - measured[i]
                       for i, s in zip(self.inputs, self.setpoints)])
        v = self.C @ x + self.D @ e
        x_new = self.A @ x + self.B @ e
        u_new = jnp.zeros((self.n_u,)).at[jnp.asarray(self.outputs)].set(v)
        if self.every == 1:
            return (x_new, u_new, k), u_new
        run = (k % self.every) == 0
        u = jnp.where(run, u_new, held)
        return (jnp.where(run, x_new, x), u, k + 1), u


def _matrix(value: Any, name: str, where: str) -> np.ndarray:
    a = np.asarray(value, dtype=float)
    if a.ndim == 0:
        a = a.reshape(1, 1)
    elif a.ndim == 1:
        a = a.reshape(1, -1)
    if a.ndim != 2 or not np.all(np.isfinite(a)):
        raise ValueError(f"{where}: {name} must be a finite matrix (a list of rows); got shape "
                         f"{np.shape(value)}")
    return a


def read_lti_file(path: str | Path, *, where: str = "[controller] file") -> dict[str, Any]:
    """A, B, C, D (and dt when present) from a ``.mat``, ``.npz`` or JSON file."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{where} = {str(path)!r}: no such file")
    suffix = path.suffix.lower()
    if suffix == ".mat":
        from flexarm.io.matfile import load_mat

        raw = load_mat(path)
    elif suffix == ".npz":
        with np.load(path, allow_pickle=False) as z:
            raw = {k: z[k] for k in z.files}
    elif suffix == ".json":
        try:
            raw = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            raise ValueError(f"{where} = {str(path)!r}: not readable JSON ({exc})") from None
    else:
        raise ValueError(f"{where} = {str(path)!r}: give a .mat, .npz or .json file holding "
                         "A, B, C, D and dt")
    out = {}
    for k in ("A", "B", "C", "D", "dt"):
        if k in raw:
            out[k] = np.asarray(raw[k], dtype=float) if k != "dt" else float(np.asarray(raw[k]).ravel()[0])
    if "D" not in out:
        raise ValueError(f"{where} = {str(path)!r}: no D in the file (it holds: "
                         f"{', '.join(map(str, raw)) or 'nothing'}); a controller needs at "
                         "least D (and A, B, C when it has states)")
    return out


def lti_matrices(A=None, B=None, C=None, D=None, *, n_in: int, n_out: int,
                 where: str = "[controller]") -> tuple[np.ndarray, ...]:
    """Check and complete (A, B, C, D) for ``n_in`` inputs and ``n_out`` outputs; missing
    A, B, C mean a static gain. Errors name the matrix, its shape and the expected one."""
    if D is None:
        raise ValueError(f"{where}: D is missing; give D ({n_out} × {n_in}: outputs × inputs)")
    D = _matrix(D, "D", where)
    if D.shape != (n_out, n_in):
        raise ValueError(f"{where}: D is {D.shape[0]} × {D.shape[1]}, but the controller has "
                         f"{n_out} output(s) (outputs) and {n_in} input(s) (inputs): D must be "
                         f"{n_out} × {n_in}")
    if A is None and B is None and C is None:
        return np.zeros((0, 0)), np.zeros((0, n_in)), np.zeros((n_out, 0)), D
    if A is None or B is None or C is None:
        raise ValueError(f"{where}: give A, B and C together (or none of them for a static "
                         "gain D)")
    A = np.asarray(A, float)
    A = A.reshape(1, 1) if A.ndim == 0 else A
    n = A.shape[0]
    if A.ndim != 2 or A.shape != (n, n):
        raise ValueError(f"{where}: A is {A.shape}; it must be square (n × n)")
    B = np.asarray(B, float).reshape(n, -1) if np.size(B) == n * n_in else _matrix(B, "B", where)
    C = np.asarray(C, float).reshape(-1, n) if np.size(C) == n * n_out else _matrix(C, "C", where)
    for name, M, shape in (("B", B, (n, n_in)), ("C", C, (n_out, n))):
        if M.shape != shape:
            raise ValueError(f"{where}: {name} is {M.shape[0]} × {M.shape[1]}; with {n} "
                             f"state(s), {n_in} input(s) and {n_out} output(s) it must be "
                             f"{shape[0]} × {shape[1]}")
    return A, B, C, D


def check_stable(A: np.ndarray, *, allow_unstable: bool = False,
                 where: str = "[controller]") -> None:
    """Refuse a controller whose A has an eigenvalue outside the unit circle (|z| > 1 + 1e-9)."""
    if A.size == 0 or allow_unstable:
        return
    eig = np.linalg.eigvals(A)
    j = int(np.argmax(np.abs(eig)))
    if abs(eig[j]) > 1.0 + STABILITY_MARGIN:
        raise ValueError(f"{where}: the controller is unstable: eigenvalue {eig[j]:.6g} of A has "
                         f"|z| = {abs(eig[j]):.6g} > 1; check A (a continuous-time A? "
                         "discretise it), or set allow_unstable = true if it is meant")


def controller_period(dt: float | None, base: float, *, where: str = "[controller]") -> int:
    """The controller period as a whole number of base periods (``None``: the base)."""
    if dt is None:
        return 1
    r = dt / base
    k = round(r)
    if k < 1 or abs(r - k) > 1e-9 * max(1.0, k):
        raise ValueError(f"{where}: dt = {dt:g} s is not a whole multiple of the loop's "
                         f"sampling period {base:g} s (ratio {r:.9g}); give dt = k·{base:g} s "
                         "(the controller runs every k samples, its output held in between)")
    return int(k)


def lti_controller(A=None, B=None, C=None, D=None, *, inputs, setpoints=None, outputs,
                   input_names, dt: float | None = None, base_dt: float,
                   x0=None, allow_unstable: bool = False, tf=None,
                   where: str = "[controller]") -> LTIController:
    """Build an :class:`LTIController`.

    ``tf``: a python-control ``StateSpace`` / ``TransferFunction`` with ``dt`` instead of
    A..D (its dt is the controller period), or a (num, den) pair in z (SISO). ``inputs``:
    measured channel names; ``setpoints``: reference channel names, or 0 / ``None`` for no
    setpoint (default all 0); ``outputs``: names of the plant's inputs (``current_1``) or
    1-based joint numbers; ``input_names``: the plant's input names."""
    inputs = list(inputs)
    setpoints = [None] * len(inputs) if setpoints is None else list(setpoints)
    if len(setpoints) != len(inputs):
        raise ValueError(f"{where}: setpoints has {len(setpoints)} entries, inputs "
                         f"{len(inputs)}: give one setpoint (a reference channel or 0) per input")
    sp = []
    for s in setpoints:
        if s is None or (not isinstance(s, str) and float(s) == 0.0):
            sp.append(None)
        elif isinstance(s, str):
            sp.append(s)
        else:
            raise ValueError(f"{where}: setpoint {s!r}: give a reference channel name or 0")
    outs = []
    for o in outputs:
        if isinstance(o, str) and o in input_names:
            outs.append(input_names.index(o))
        elif isinstance(o, (int, np.integer)) and not isinstance(o, bool) and 1 <= o <= len(input_names):
            outs.append(int(o) - 1)
        else:
            raise ValueError(f"{where}: output {o!r} is not an input of the plant; give one of "
                             f"{', '.join(input_names)} (or the joint number 1..{len(input_names)})")
    if len(set(outs)) != len(outs):
        raise ValueError(f"{where}: outputs {list(outputs)} name a plant input twice")
    if tf is not None:
        import control

        if isinstance(tf, tuple):
            tf = control.tf(tf[0], tf[1], dt if dt is not None else True)
        if tf.isctime():
            raise ValueError(f"{where}: the system is continuous-time; discretise it first "
                             "(e.g. sys.sample(T, method='tustin'))")
        if dt is None and tf.dt is not True and tf.dt:
            dt = float(tf.dt)
        ss = control.ss(tf)
        A, B, C, D = ss.A, ss.B, ss.C, ss.D
        if ss.nstates == 0:
            A = B = C = None
    A, B, C, D = lti_matrices(A, B, C, D, n_in=len(inputs), n_out=len(outs), where=where)
    check_stable(A, allow_unstable=allow_unstable, where=where)
    every = controller_period(dt, base_dt, where=where)
    n = A.shape[0]
    x0 = np.zeros(n) if x0 is None else np.asarray(x0, float).ravel()
    if x0.shape != (n,):
        raise ValueError(f"{where}: initial_state has {x0.size} value(s); the controller has "
                         f"{n} state(s)")
    f = lambda a: jnp.asarray(np.asarray(a, float))  # noqa: E731
    return LTIController(f(A), f(B), f(C), f(D), f(x0), tuple(inputs), tuple(sp), tuple(outs),
                         len(input_names), every)


def lti_from_spec(spec, *, base_dt: float, input_names, references=None) -> LTIController:
    """The controller a scenario's ``[controller] type = "lti"`` describes
    (:class:`flexarm.specs.experiment.LTIControllerSpec`); ``references``: the reference
    channels the run provides (a setpoint naming another is an error)."""
    where = "[controller]"
    A = B = C = D = tf = None
    dt = spec.dt
    if spec.file is not None:
        got = read_lti_file(spec.file, where=f"{where} file")
        A, B, C, D = (got.get(k) for k in ("A", "B", "C", "D"))
        if dt is None:
            dt = got.get("dt")
        where = f"{where} file {spec.file!r}"
    elif spec.num is not None:
        tf = (list(spec.num), list(spec.den))
    else:
        A, B, C, D = spec.A, spec.B, spec.C, spec.D
    if references is not None:
        for s in spec.setpoints or []:
            if isinstance(s, str) and s not in references:
                raise ValueError(f"[controller] setpoint {s!r} is not a reference channel of "
                                 f"the run; it has {', '.join(sorted(references))} (add "
                                 f"[references.{s}] or pass it)")
    return lti_controller(A, B, C, D, inputs=spec.inputs, setpoints=spec.setpoints,
                          outputs=spec.outputs, input_names=list(input_names), dt=dt,
                          base_dt=base_dt, x0=spec.initial_state,
                          allow_unstable=spec.allow_unstable, tf=tf, where=where)


def state_from_log(ctrl: LTIController, log, k: int) -> np.ndarray:
    """The controller's state x_k at sample k of ``log`` (a :class:`flexarm.io.logs.Log`
    holding its input channels and setpoints): the controller run from its ``x0`` over the
    logged samples 0..k−1, updating at every ``every``-th sample from the first (the
    command it computed is not needed: x⁺ = A x + B e). Exact when the log holds what the
    controller read; for an observer-based controller this is its estimate before a
    window, not a guess."""
    missing = [c for c in (*ctrl.inputs, *ctrl.reference_signals) if c not in log.signals]
    if missing:
        raise ValueError(f"{log.name}: the controller's state is run over the log, which has no "
                         f"{', '.join(missing)}")
    A, B = np.asarray(ctrl.A, float), np.asarray(ctrl.B, float)
    x = np.asarray(ctrl.x0, float).copy()
    if A.size == 0:
        return x
    y = np.stack([log[c] for c in ctrl.inputs], 1)
    s = np.stack([log[c] if c is not None else np.zeros(len(y)) for c in ctrl.setpoints], 1)
    for j in range(0, k, ctrl.every):
        x = A @ x + B @ (s[j] - y[j])
    return x
