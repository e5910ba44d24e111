"""Discrete linear time-invariant systems in the loop: any discrete LTI controller (MIMO state
space or SISO transfer function, inline, from python-control or from a file) and the sensors'
digital filters.

Controller (:class:`LTIController`), run every ``every`` base periods T (its own period
T_c = every·T; the output is held in between)::

    w_k = s_k − y_k                      (the error form: setpoints s named reference
                                          channels or 0, y named measured channels)
    w_k = (z_1, ..., z_p)                (the block form, ``signals``: each z_i a measured
                                          channel, a reference channel or a constant)
    x_{k+1} = A x_k + B w_k,   v_k = C x_k + D w_k       (at t_k = j·T_c)
    u = v mapped to the plant's inputs (``outputs``), others 0; the loop's actuator
    saturates u at the drives' limits.

Several blocks at several rates (:class:`Blocks`, a scenario's ``[[controllers]]``): each
block runs at its own multiple of T and drives its own plant inputs; u is their sum (each
block's outputs are 0 on the inputs it does not drive, so the sum is a placement).

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

from flexarm.control.discrete import Controller, Sum
from flexarm.specs.scenario import ScenarioError

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
            raise ValueError(
                f"{where}: num = {list(num)}, den = {list(den)} is not a proper "
                "transfer function in z (numerator degree <= denominator's)"
            )
        if len(den) == 1:
            A, B, C, D = (
                np.zeros((0, 0)),
                np.zeros(0),
                np.zeros(0),
                float(num[-1] / den[0]) if len(num) else 0.0,
            )
        else:
            A, B, C, D = sps.tf2ss(num, den)
            A, B, C, D = A, B[:, 0], C[0], float(D[0, 0])
        filt = DigitalFilter(
            np.asarray(A, float), np.asarray(B, float), np.asarray(C, float), D, "tf", "none"
        )
    elif kind in FILTER_KINDS:
        if dt is None or not dt > 0:
            raise ValueError(
                f"{where}: a {kind!r} filter needs the sample period to be discretised"
            )
        w = 2 * math.pi * float(_get(spec, "cutoff"))
        z = float(_get(spec, "damping", 0.9))
        Ac = np.array([[0.0, 1.0], [-w * w, -2 * z * w]])
        Bc = np.array([0.0, w * w])
        C = np.eye(2)[FILTER_KINDS[kind]]
        how = _get(spec, "discretisation", "forward_euler")
        if how == "forward_euler":
            A, B, D = np.eye(2) + dt * Ac, dt * Bc, 0.0
        elif how in ("zoh", "tustin"):
            # (A, B, C, D, dt); scipy's return type is inferred from its branches
            ssd: Any = sps.cont2discrete(
                (Ac, Bc[:, None], C[None, :], np.zeros((1, 1))),
                dt,
                method="zoh" if how == "zoh" else "bilinear",
            )
            A, B2, C2, D2, _ = ssd
            B, C, D = B2[:, 0], C2[0], float(D2[0, 0])
        else:
            raise ValueError(
                f"{where}: discretisation = {how!r}; give forward_euler, zoh or tustin"
            )
        filt = DigitalFilter(
            np.asarray(A, float), np.asarray(B, float), np.asarray(C, float), float(D), kind, how
        )
    else:
        raise ValueError(
            f"{where}: kind = {kind!r}; give one of {', '.join([*FILTER_KINDS, 'tf'])}"
        )
    if filt.order:
        eig = np.linalg.eigvals(filt.A)
        j = int(np.argmax(np.abs(eig)))
        if abs(eig[j]) >= 1.0:
            hint = (
                f" (forward Euler needs ω·T small: 2π·{_get(spec, 'cutoff')} Hz·{dt:g} s "
                'is too large; use discretisation = "tustin")'
                if _get(spec, "discretisation", "forward_euler") == "forward_euler" and kind != "tf"
                else ""
            )
            raise ValueError(
                f"{where}: the discrete filter is not stable: eigenvalue "
                f"{eig[j]:.6g} of A has |z| = {abs(eig[j]):.6g} >= 1{hint}"
            )
    return filt


# ----------------------------------------------------------------------------- controller
class LTIController(Controller):
    """Any discrete LTI controller block (module docstring).

    ``A, B, C, D``: (n, n), (n, p), (m, n), (m, p); ``x0`` (n,). The input vector, one of:
    ``inputs`` (p measured channel names) with ``setpoints`` (p reference channel names or
    ``None`` for 0), w = s − y; or ``signals`` (p entries ``("measured", name)``,
    ``("reference", name)`` or ``("constant", value)``), w the entries in that order.
    ``outputs``: the plant input index of each of the m outputs; ``n_u``: the plant's
    inputs; ``every``: the controller period in base periods. ``u0`` (n_u,) and ``k0``
    (samples since the start of the run, for the phase of ``every``) start the block
    inside a run (:func:`flexarm.sim.filters.continuous_starts`); default a fresh start
    (output 0, phase 0). ``name``: how messages name the block."""

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
    signals: tuple[tuple[str, Any], ...] | None = eqx.field(static=True, default=None)
    u0: Array | None = None
    k0: Array | None = None
    name: str = eqx.field(static=True, default="controller")

    @property
    def measured_signals(self) -> tuple[str, ...]:
        """The measured channels it reads (the loop adds sensors for them)."""
        if self.signals is not None:
            return tuple(dict.fromkeys(v for kind, v in self.signals if kind == "measured"))
        return self.inputs

    @property
    def reference_signals(self) -> tuple[str, ...]:
        if self.signals is not None:
            return tuple(dict.fromkeys(v for kind, v in self.signals if kind == "reference"))
        return tuple(s for s in self.setpoints if s is not None)

    @property
    def dynamic(self) -> bool:
        """Whether the block has a state (n > 0)."""
        return self.A.shape[-1] > 0

    def init(self):
        u0 = jnp.zeros((self.n_u,)) if self.u0 is None else self.u0
        k0 = jnp.zeros((), dtype=jnp.int32) if self.k0 is None else self.k0
        return (self.x0, u0, k0)

    def input_vector(self, measured, reference):
        """w_k from the sample's measured and reference signals (dicts of scalars)."""
        if self.signals is not None:
            return jnp.stack(
                [
                    measured[v]
                    if kind == "measured"
                    else reference[v]
                    if kind == "reference"
                    else jnp.asarray(float(v))
                    for kind, v in self.signals
                ]
            )
        return jnp.stack(
            [
                (reference[s] if s is not None else 0.0) - measured[i]
                for i, s in zip(self.inputs, self.setpoints, strict=True)
            ]
        )

    def step(self, state, measured, reference):
        x, held, k = state
        e = self.input_vector(measured, reference)
        v = self.C @ x + self.D @ e
        x_new = self.A @ x + self.B @ e
        u_new = jnp.zeros((self.n_u,)).at[jnp.asarray(self.outputs)].set(v)
        if self.every == 1:
            return (x_new, u_new, k), u_new
        run = (k % self.every) == 0
        u = jnp.where(run, u_new, held)
        return (jnp.where(run, x_new, x), u, k + 1), u


class Blocks(Sum):
    """Several controller blocks, each at its own period (``every``) and driving its own
    plant inputs: u = Σ_i u_i (:class:`LTIController` blocks put zeros on the inputs they
    do not drive, so the sum places each block's outputs). A scenario's ``[[controllers]]``."""

    names: tuple[str, ...] = eqx.field(static=True, default=())

    def __init__(self, *parts: Controller, names=()):
        self.parts = tuple(parts)
        self.names = tuple(names) or tuple(
            getattr(p, "name", f"controllers[{i}]") for i, p in enumerate(parts)
        )


def _matrix(value: Any, name: str, where: str) -> np.ndarray:
    a = np.asarray(value, dtype=float)
    if a.ndim == 0:
        a = a.reshape(1, 1)
    elif a.ndim == 1:
        a = a.reshape(1, -1)
    if a.ndim != 2 or not np.all(np.isfinite(a)):
        raise ScenarioError(
            f"{where}: {name} must be a finite matrix (a list of rows); got shape {np.shape(value)}"
        )
    return a


def _struct(node: Any) -> dict[str, Any] | None:
    """The fields of a struct as a dict (a v7.3 / JSON dict, scipy's ``mat_struct``, or
    a 1×1 object array holding one), else ``None``."""
    while isinstance(node, np.ndarray) and node.dtype == object and node.size == 1:
        node = node.flat[0]
    if isinstance(node, Mapping):
        return dict(node)
    names = getattr(node, "_fieldnames", None)
    if names is not None:
        return {k: getattr(node, k) for k in names}
    if isinstance(node, np.ndarray) and node.dtype.names:  # a record array (a 1×1 struct)
        rec = node.reshape(-1)[0]
        return {k: rec[k] for k in node.dtype.names}
    return None


def _numeric(v: Any, key: str, where: str) -> np.ndarray:
    while isinstance(v, np.ndarray) and v.dtype == object and v.size == 1:
        v = v.flat[0]
    if v is None:
        raise ScenarioError(
            f"{where}: field {key} is null; give a number or a matrix of "
            "numbers (or leave the field out)"
        )
    try:
        a = np.asarray(v, dtype=float)
    except (TypeError, ValueError, OverflowError):
        raise ScenarioError(
            f"{where}: field {key} is not numeric ({type(v).__name__}); give "
            "A, B, C, D as matrices of numbers"
        ) from None
    return a


def read_lti_file(
    path: str | Path, variable: str | None = None, *, where: str = "[controller] file"
) -> dict[str, Any]:
    """A, B, C, D (and dt, from ``dt`` or ``Ts``, when present) from a ``.mat`` (v5 or
    v7.3, through :func:`flexarm.io.matfile.load_mat`), ``.npz`` or JSON file.

    ``variable``: the struct (``.mat``; ``a.b`` for a nested one), object (JSON) or key
    prefix (``.npz``: keys ``NAME.A`` or ``NAME_A``) holding the fields; ``None``: the
    file's top-level A, B, C, D. A MATLAB ``ss`` object cannot be read (it is opaque
    outside MATLAB): save ``struct('A', sys.A, 'B', sys.B, 'C', sys.C, 'D', sys.D,
    'Ts', sys.Ts)`` instead."""
    path = Path(path)
    at = f"{where} = {str(path)!r}" + (f", variable = {variable!r}" if variable else "")
    if not path.is_file():
        raise ScenarioError(
            f"{where} = {str(path)!r}: no such file (a relative file is read "
            "from the folder of the TOML that names it)"
        )
    suffix = path.suffix.lower()
    if suffix == ".mat":
        from flexarm.io.matfile import MatFileError, load_mat

        try:
            raw = load_mat(path)
        except MatFileError as exc:
            raise ScenarioError(f"{at}: {exc}") from None
    elif suffix == ".npz":
        with np.load(path, allow_pickle=False) as z:
            raw = {k: z[k] for k in z.files}
        if variable is not None:
            sub = {}
            for k, v in raw.items():
                for sep in (".", "_", "/"):
                    if k.startswith(variable + sep):
                        sub[k[len(variable) + 1 :]] = v
            if not sub:
                raise ScenarioError(
                    f"{at}: the file has no keys {variable}.A, {variable}.B, ... "
                    f"(it holds: {', '.join(raw) or 'nothing'}); give the "
                    "prefix of the block's keys, or no variable for top-level "
                    "A, B, C, D"
                )
            raw, variable = sub, None
    elif suffix == ".json":
        try:
            raw = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError, RecursionError) as exc:  # nested too deeply: one line
            raise ScenarioError(f"{where} = {str(path)!r}: not readable JSON ({exc})") from None
        if not isinstance(raw, dict):
            raise ScenarioError(
                f"{at}: the JSON is a {type(raw).__name__}; give an object with "
                "A, B, C, D (and dt or Ts)"
            )
    else:
        raise ScenarioError(
            f"{where} = {str(path)!r}: give a .mat, .npz or .json file holding "
            "A, B, C, D and dt (or Ts)"
        )
    if variable is not None:
        node: Any = raw
        for depth, part in enumerate(variable.split(".")):
            fields = _struct(node)
            if fields is None or part not in fields:
                have = ", ".join(map(str, fields or {})) or "nothing"
                what = "the file" if depth == 0 else ".".join(variable.split(".")[:depth])
                raise ScenarioError(
                    f"{at}: {what} has no {part!r} (it holds: {have}); give "
                    "variable = the name of the struct with fields A, B, C, D"
                )
            node = fields[part]
        fields = _struct(node)
        if fields is None:
            raise ScenarioError(
                f"{at}: {variable} is not a struct (a "
                f"{type(node).__name__}); give the struct with fields A, B, C, "
                "D (and Ts)"
            )
        raw = fields
    out: dict[str, Any] = {}
    for k in ("A", "B", "C", "D"):
        if k in raw:
            a = _numeric(raw[k], k, at)
            if a.size == 0 and k != "D":
                out[k] = None
                continue
            try:
                out[k] = _matrix(a, k, at)
            except (TypeError, ValueError, IndexError, OverflowError) as exc:
                raise ScenarioError(
                    f"{at}: field {k}: {exc}",
                    fix=("give A, B, C, D as finite matrices of numbers (a list of rows)"),
                ) from None
    for k in ("dt", "Ts"):
        if k in raw and "dt" not in out:
            ts = _numeric(raw[k], k, at).ravel()
            if ts.size != 1 or not math.isfinite(float(ts[0])):
                shown = (
                    "empty"
                    if ts.size == 0
                    else (f"{ts.size} numbers" if ts.size > 1 else f"{float(ts[0])!r}")
                )
                raise ScenarioError(
                    f"{at}: field {k} is {shown}; give the controller's "
                    "sampling period as one number in s (e.g. 0.002), or "
                    "leave it out to run at the loop's period"
                )
            # MATLAB writes Ts = 0 for a continuous system, -1 for an unspecified period
            if ts[0] == 0:
                raise ScenarioError(
                    f"{at}: {k} = 0: a continuous-time system; discretise it "
                    "(c2d) before exporting the block"
                )
            if ts[0] > 0:
                out["dt"] = float(ts[0])
    if "D" not in out:
        raise ScenarioError(
            f"{at}: no D (the {'struct' if variable else 'file'} holds: "
            f"{', '.join(map(str, raw)) or 'nothing'}); a controller block needs "
            "D (outputs × inputs) and A, B, C when it has states: add the "
            "field D (zeros for a strictly proper block)"
        )
    if all(out.get(k) is None for k in "ABC"):
        for k in "ABC":
            out.pop(k, None)
    return out


def lti_matrices(
    A=None, B=None, C=None, D=None, *, n_in: int, n_out: int, where: str = "[controller]"
) -> tuple[np.ndarray, ...]:
    """Check and complete (A, B, C, D) for ``n_in`` inputs and ``n_out`` outputs; missing
    A, B, C mean a static gain. Errors name the matrix, its shape and the expected one."""
    if D is None:
        raise ScenarioError(f"{where}: D is missing; give D ({n_out} × {n_in}: outputs × inputs)")
    D = _matrix(D, "D", where)
    if D.shape != (n_out, n_in):
        raise ScenarioError(
            f"{where}: D is {D.shape[0]} × {D.shape[1]}, but the controller has "
            f"{n_out} output(s) (outputs) and {n_in} input(s) (inputs): D must be "
            f"{n_out} × {n_in}"
        )
    if A is None and B is None and C is None:
        return np.zeros((0, 0)), np.zeros((0, n_in)), np.zeros((n_out, 0)), D
    if A is None or B is None or C is None:
        raise ScenarioError(
            f"{where}: give A, B and C together (or none of them for a static gain D)"
        )
    A = np.asarray(A, float)
    A = A.reshape(1, 1) if A.ndim == 0 else A
    n = A.shape[0]
    if A.ndim != 2 or A.shape != (n, n):
        raise ScenarioError(f"{where}: A is {A.shape}; it must be square (n × n)")
    B = np.asarray(B, float).reshape(n, -1) if np.size(B) == n * n_in else _matrix(B, "B", where)
    C = np.asarray(C, float).reshape(-1, n) if np.size(C) == n * n_out else _matrix(C, "C", where)
    for name, M, shape in (("B", B, (n, n_in)), ("C", C, (n_out, n))):
        if M.shape != shape:
            raise ScenarioError(
                f"{where}: {name} is {M.shape[0]} × {M.shape[1]}; with {n} "
                f"state(s), {n_in} input(s) and {n_out} output(s) it must be "
                f"{shape[0]} × {shape[1]}"
            )
    return A, B, C, D


def check_stable(
    A: np.ndarray, *, allow_unstable: bool = False, where: str = "[controller]"
) -> None:
    """Refuse a controller whose A has an eigenvalue outside the unit circle (|z| > 1 + 1e-9)."""
    if A.size == 0 or allow_unstable:
        return
    eig = np.linalg.eigvals(A)
    j = int(np.argmax(np.abs(eig)))
    if abs(eig[j]) > 1.0 + STABILITY_MARGIN:
        raise ScenarioError(
            f"{where}: the controller is unstable: eigenvalue {eig[j]:.6g} of A has "
            f"|z| = {abs(eig[j]):.6g} > 1; check A (a continuous-time A? "
            "discretise it), or set allow_unstable = true if it is meant"
        )


def controller_period(dt: float | None, base: float, *, where: str = "[controller]") -> int:
    """The controller period as a whole number of base periods (``None``: the base)."""
    if dt is None:
        return 1
    r = dt / base
    k = round(r)
    if k < 1 or abs(r - k) > 1e-9 * max(1.0, k):
        raise ScenarioError(
            f"{where}: dt = {dt:g} s is not a whole multiple of the loop's "
            f"sampling period {base:g} s (ratio {r:.9g}); give dt = k·{base:g} s "
            "(the controller runs every k samples, its output held in between)"
        )
    return int(k)


def _signal_entries(signals, *, references, measured, where: str):
    """``signals`` (channel names and numbers) as (kind, value) entries: a name in
    ``references`` is a reference channel, any other name a measured channel (checked
    against ``measured`` when given), a number a constant."""
    out = []
    for j, s in enumerate(signals):
        if isinstance(s, str):
            if references is not None and s in references:
                out.append(("reference", s))
            elif measured is None or s in measured:
                out.append(("measured", s))
            else:
                raise ScenarioError(
                    f"{where}: signals[{j}] = {s!r} is neither a channel nor a number: give "
                    f"a measured channel ({', '.join(sorted(measured))}), a reference "
                    f"channel ({', '.join(sorted(references or ()))}) or a number"
                )
        elif (
            isinstance(s, (int, float, np.integer, np.floating))
            and not isinstance(s, bool)
            and math.isfinite(float(s))
        ):
            out.append(("constant", float(s)))
        else:
            raise ScenarioError(
                f"{where}: signals[{j}] = {s!r} is neither a channel nor a "
                "number: give a channel name or a finite number"
            )
    return tuple(out)


def lti_controller(
    A=None,
    B=None,
    C=None,
    D=None,
    *,
    inputs=None,
    setpoints=None,
    outputs,
    input_names,
    dt: float | None = None,
    base_dt: float,
    x0=None,
    allow_unstable: bool = False,
    tf=None,
    signals=None,
    references=None,
    measured=None,
    name: str = "controller",
    where: str = "[controller]",
) -> LTIController:
    """Build an :class:`LTIController`.

    ``tf``: a python-control ``StateSpace`` / ``TransferFunction`` with ``dt`` instead of
    A..D (its dt is the controller period), or a (num, den) pair in z (SISO). The input
    vector: ``inputs`` (measured channel names) and ``setpoints`` (reference channel names,
    or 0 / ``None`` for no setpoint; default all 0), w = s − y; or ``signals`` (the block's
    own vector: channel names and numbers; a name in ``references`` is a reference channel,
    another a measured one, checked against ``measured`` when given). ``outputs``: names of
    the plant's inputs (``current_1``) or 1-based joint numbers; ``input_names``: the
    plant's input names."""
    if (inputs is None) == (signals is None):
        raise ScenarioError(f"{where}: give inputs (+ setpoints) or signals, one of them")
    if signals is not None:
        sig = _signal_entries(signals, references=references, measured=measured, where=where)
        inputs, sp, n_in = (), (), len(sig)
    else:
        sig = None
        assert inputs is not None  # one of inputs and signals (checked above)
        inputs = list(inputs)
        setpoints = [None] * len(inputs) if setpoints is None else list(setpoints)
        if len(setpoints) != len(inputs):
            raise ScenarioError(
                f"{where}: setpoints has {len(setpoints)} entries, inputs "
                f"{len(inputs)}: give one setpoint (a reference channel or 0) per "
                "input"
            )
        sp = []
        for s in setpoints:
            if s is None or (not isinstance(s, str) and float(s) == 0.0):
                sp.append(None)
            elif isinstance(s, str):
                sp.append(s)
            else:
                raise ScenarioError(f"{where}: setpoint {s!r}: give a reference channel name or 0")
        n_in = len(inputs)
    outs = []
    for o in outputs:
        if isinstance(o, str) and o in input_names:
            outs.append(input_names.index(o))
        elif (
            isinstance(o, (int, np.integer))
            and not isinstance(o, bool)
            and 1 <= o <= len(input_names)
        ):
            outs.append(int(o) - 1)
        else:
            raise ScenarioError(
                f"{where}: output {o!r} is not an input of the plant; give one of "
                f"{', '.join(input_names)} (or the joint number 1..{len(input_names)})"
            )
    if len(set(outs)) != len(outs):
        raise ScenarioError(f"{where}: outputs {list(outputs)} name a plant input twice")
    if tf is not None:
        import control

        if isinstance(tf, tuple):
            tf = control.tf(tf[0], tf[1], dt if dt is not None else True)
        if tf.isctime():
            raise ScenarioError(
                f"{where}: the system is continuous-time; discretise it first "
                "(e.g. sys.sample(T, method='tustin'))"
            )
        if dt is None and tf.dt is not True and tf.dt:
            dt = float(tf.dt)
        ss = control.ss(tf)
        A, B, C, D = ss.A, ss.B, ss.C, ss.D
        if ss.nstates == 0:
            A = B = C = None
    A, B, C, D = lti_matrices(A, B, C, D, n_in=n_in, n_out=len(outs), where=where)
    check_stable(A, allow_unstable=allow_unstable, where=where)
    every = controller_period(dt, base_dt, where=where)
    n = A.shape[0]
    x0 = np.zeros(n) if x0 is None else np.asarray(x0, float).ravel()
    if x0.shape != (n,):
        raise ScenarioError(
            f"{where}: initial_state has {x0.size} value(s); the controller has {n} state(s)"
        )

    def f(a):
        return jnp.asarray(np.asarray(a, float))

    return LTIController(
        f(A),
        f(B),
        f(C),
        f(D),
        f(x0),
        tuple(inputs),
        tuple(sp),
        tuple(outs),
        len(input_names),
        every,
        sig,
        name=name,
    )


def lti_from_spec(
    spec,
    *,
    base_dt: float,
    input_names,
    references=None,
    measured=None,
    where: str = "[controller]",
) -> LTIController:
    """The controller block a scenario's ``[controller] type = "lti"`` (or one of its
    ``[[controllers]]``) describes (:class:`flexarm.specs.experiment.LTIControllerSpec`);
    ``references``: the reference channels the run provides (a setpoint naming another is
    an error; in ``signals`` these names are the reference entries); ``measured``: the
    measured channels and plant signals a ``signals`` entry may name (``None``: any)."""
    name = getattr(spec, "name", None) or where
    A = B = C = D = tf = None
    dt = spec.dt
    if spec.file is not None:
        got = read_lti_file(spec.file, getattr(spec, "variable", None), where=f"{where} file")
        A, B, C, D = (got.get(k) for k in ("A", "B", "C", "D"))
        if dt is None:
            dt = got.get("dt")
        elif got.get("dt") is not None and abs(got["dt"] - dt) > 1e-9 * dt:
            raise ValueError(
                f"{where}: dt = {dt:g} s, but the file {spec.file!r} says "
                f"{got['dt']:g} s (Ts); drop dt, or fix the one that is wrong"
            )
        where = f"{where} file {spec.file!r}"
    elif spec.num is not None:
        tf = (list(spec.num), list(spec.den))
    else:
        A, B, C, D = spec.A, spec.B, spec.C, spec.D
    if references is not None:
        for s in spec.setpoints or []:
            if isinstance(s, str) and s not in references:
                raise ValueError(
                    f"{where} setpoint {s!r} is not a reference channel of "
                    f"the run; it has {', '.join(sorted(references))} (add "
                    f"[references.{s}] or pass it)"
                )
    return lti_controller(
        A,
        B,
        C,
        D,
        inputs=spec.inputs,
        setpoints=spec.setpoints,
        signals=getattr(spec, "signals", None),
        references=references,
        measured=measured,
        outputs=spec.outputs,
        input_names=list(input_names),
        dt=dt,
        base_dt=base_dt,
        x0=spec.initial_state,
        allow_unstable=spec.allow_unstable,
        tf=tf,
        name=name,
        where=where,
    )


def input_history(ctrl: LTIController, log) -> np.ndarray:
    """The block's input vectors w_k over a log (N, p): its measured and reference channels
    as logged, constants as given (the error form: s − y). Raises ValueError naming the
    channels the log lacks."""
    need = (*ctrl.measured_signals, *ctrl.reference_signals)
    missing = [c for c in need if c not in log.signals]
    if missing:
        raise ValueError(
            f"{log.name}: the state of {ctrl.name} is run over the log, which "
            f"has no {', '.join(missing)}"
        )
    n = len(log)
    if ctrl.signals is not None:
        cols = [
            np.asarray(log[v], float) if kind != "constant" else np.full(n, float(v))
            for kind, v in ctrl.signals
        ]
        return np.stack(cols, 1) if cols else np.zeros((n, 0))
    y = np.stack([log[c] for c in ctrl.inputs], 1)
    s = np.stack([log[c] if c is not None else np.zeros(n) for c in ctrl.setpoints], 1)
    return s - y


def run_state(
    ctrl: LTIController, w: np.ndarray, k: int, *, x0=None, k0: int = 0
) -> tuple[np.ndarray, np.ndarray, int]:
    """The block run over the inputs w_0..w_{k−1} (rows of ``w``) from state ``x0``
    (default its own) at phase ``k0`` (samples since the run's start): its state x_k, the
    output it holds at k (the last update's, in the plant's inputs) and the phase k0 + k.
    x⁺ = A x + B w and v = C x + D w at every sample whose phase is a multiple of
    ``every``."""
    A, B = np.asarray(ctrl.A, float), np.asarray(ctrl.B, float)
    C, D = np.asarray(ctrl.C, float), np.asarray(ctrl.D, float)
    x = np.asarray(ctrl.x0 if x0 is None else x0, float).copy()
    u = np.zeros(ctrl.n_u)
    for j in range(k):
        if (k0 + j) % ctrl.every:
            continue
        v = (C @ x if x.size else 0.0) + D @ w[j]
        u = np.zeros(ctrl.n_u)
        u[list(ctrl.outputs)] = v
        if x.size:
            x = A @ x + B @ w[j]
    return x, u, k0 + k


def state_from_log(ctrl: LTIController, log, k: int) -> np.ndarray:
    """The controller's state x_k at sample k of ``log`` (a :class:`flexarm.io.logs.Log`
    holding its input channels and setpoints): the controller run from its ``x0`` over the
    logged samples 0..k−1, updating at every ``every``-th sample from the first (the
    command it computed is not needed: x⁺ = A x + B w). Exact when the log holds what the
    controller read; for an observer-based controller this is its estimate before a
    window, not a guess."""
    if not ctrl.dynamic:
        return np.asarray(ctrl.x0, float).copy()
    return run_state(ctrl, input_history(ctrl, log), k)[0]
