"""C99 code of a scenario's controller for a real-time target (``flexarm export-c``).

The controller is built exactly as the simulator builds it
(:func:`flexarm.sim.build.prepare`: :func:`~flexarm.sim.build.controller_from_spec`, the
actuator's limit and D/A count), and written as two files with no dependencies (no
``<math.h>``, no allocation, no I/O):

* ``NAME.h``: the channel order of ``measured[]``, ``reference[]`` and ``u[]`` (names and SI
  units), the sample period, the constants' provenance (scenario, design method, flexarm
  version; no date, so the output is reproducible), ``NAME_real`` (``double`` or ``float``),
  the state struct ``NAME_state``, ``NAME_init`` and ``NAME_step``;
* ``NAME.c``: the constants and the law, one sample per ``NAME_step`` call::

      NAME_step(&s, measured, reference, u):
          y = controller(measured, reference)           (its state s updated)
          u = Q(sat(y))   sat(y) = min(max(y, −L), L),  Q(x) = q · round_half_even(x / q)

  L the actuator limit (V or A; none when infinite), q = 2 L / 2**bits the D/A count (none
  when ``[actuator] bits = 0``): the simulator's step 3 (:mod:`flexarm.sim.sampled`).

Every operation is the Python controller's, in the same order (a dot product as a loop from
the first term, ``e = r − y`` before it is used, rates as ``(x_k − x_{k−1}) / T``), so in
double the C output equals the Python ``step`` to the last few bits (the tests: 1e-12).

One function per controller kind (:data:`EXPORTERS`, keyed by class): each returns a
:class:`Part` (state members, constants, init and step statements) and may nest another part
(the friction compensation wraps any feedback). A kind without an exporter is refused by name
(:class:`ExportError`); a new kind is one more function registered with :func:`exporter`.

Kinds (equations in the generated comments):

* :class:`~flexarm.control.discrete.LinearController` (``pd``, ``pid``, ``lead``, ``tf``):
  x⁺ = A x + B e, y = C x + D e, e = r − y_m;
* :class:`~flexarm.control.lti.LTIController` (``lti``): e_i = s_i − y_i (s_i a reference
  channel or 0), or e the block's own ``signals`` vector (measured and reference channels,
  constants), v = C x + D e, x⁺ = A x + B e every ``every`` samples, output held between;
* :class:`~flexarm.control.lti.Blocks` (``[[controllers]]``): one step function schedules
  the blocks, each updating every ``every`` calls on its own phase counter and holding its
  output between; the blocks' outputs placed on their own commands (the header says so);
* :class:`~flexarm.control.state_feedback.StateFeedback` (``state_feedback``):
  y = K1 (r − θ) − K2 d − K3 θ̇ − K4 ḋ, rates by backward difference or the filtered one;
* :class:`~flexarm.control.friction_compensation.FrictionCompensated`: y = y_fb + c σ, σ
  Feliu's sign rule with its deadbands (FRB Sec. III-B);
* :class:`~flexarm.control.inner_loop.InnerLoop` (FRB Fig. 4: G_cm1, G_cm2, the coupling
  filter, the friction feedforward) and the combinators Feliu's nested loops are built of
  (:func:`~flexarm.control.outer_loop.tip_loop`): :class:`~flexarm.control.discrete.Sum`,
  :class:`~flexarm.control.discrete.Cascade` (the outer output becomes the inner loop's
  reference channel: a computed channel, :attr:`_Ctx.computed_references`, not an input),
  :class:`~flexarm.control.outer_loop.ReferenceChannel` (the feedforward θ̂_mr, an input),
  and ``MeasuredTip`` (θt = θm + s d from the gauge: a computed measured channel;
  :func:`measured_tip`, registered when :mod:`flexarm.control.nested` is present).

Not exportable (refused by name): a user's JAX law (``FunctionController``), continuous-time
laws, the multi-link ``JointPD``; a sensor's digital filter is not part of the controller
and is not exported (the header says so for each filtered channel).
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from flexarm.errors import FlexarmError  # the one error base (issue #25)

__all__ = [
    "CCode",
    "ExportError",
    "Part",
    "EXPORTERS",
    "exporter",
    "generate_c",
    "export_c",
    "load_design",
]

PRECISIONS = ("double", "float")

#: C99 keywords and names the generated code uses for itself: not accepted as NAME.
_C_RESERVED = {
    "auto",
    "break",
    "case",
    "char",
    "const",
    "continue",
    "default",
    "do",
    "double",
    "else",
    "enum",
    "extern",
    "float",
    "for",
    "goto",
    "if",
    "inline",
    "int",
    "long",
    "register",
    "restrict",
    "return",
    "short",
    "signed",
    "sizeof",
    "static",
    "struct",
    "switch",
    "typedef",
    "union",
    "unsigned",
    "void",
    "volatile",
    "while",
    "_Bool",
    "_Complex",
    "_Imaginary",
    "main",
}


class ExportError(FlexarmError, ValueError):
    """A controller or design that cannot be exported; the message names what and why."""


# ----------------------------------------------------------------------------- context
class _Ctx:
    """Shared state of one generation: channel order (first use), number formatting, the
    helpers the code needs."""

    def __init__(self, name: str, precision: str, n_u: int):
        self.name = name
        self.precision = precision
        self.real = f"{name}_real"
        self.n_u = n_u
        self.measured: list[str] = []
        self.references: list[str] = []
        self.helpers: set[str] = set()
        #: channels computed inside the controller (a cascade's inner reference, a tip
        #: angle formed from other channels): name → C expression, not inputs
        self.computed_measured: dict[str, str] = {}
        self.computed_references: dict[str, str] = {}
        #: the unit of a position: rad, or m on a linear axis (a prismatic joint)
        self.position = "rad"

    @staticmethod
    def _input(channel: str, computed: dict[str, str], inputs: list[str], prefix: str) -> str:
        """The C expression of ``channel``: its computed expression, else the input
        ``<prefix>_<i>`` in order of first use (registered here)."""
        if channel in computed:
            return computed[channel]
        if channel not in inputs:
            inputs.append(channel)
        return f"{prefix}_{inputs.index(channel)}"

    def meas(self, channel: str) -> str:
        """The C expression of measured channel ``channel`` (an input, registered on first
        use, unless computed inside the controller)."""
        return self._input(channel, self.computed_measured, self.measured, "m")

    def ref(self, channel: str) -> str:
        """The C expression of reference channel ``channel`` (as :meth:`meas`)."""
        return self._input(channel, self.computed_references, self.references, "r")

    def lit(self, v: float) -> str:
        """An exact literal of ``v`` in the precision (double: 17 significant digits round
        trip; float: the float32 value, 9 digits, suffix f)."""
        v = float(v)
        if not np.isfinite(v):
            raise ExportError(f"a constant of the controller is {v}; C constants must be finite")
        if self.precision == "float":
            with np.errstate(over="ignore"):
                f32 = np.float32(v)
            if not np.isfinite(f32):
                raise ExportError(
                    f"a constant of the controller, {v:.6g}, is beyond the "
                    "float range (3.4e38); export with --precision double"
                )
            s = format(float(f32), ".9g")  # 9 digits: float32 round trip
            return (s if any(ch in s for ch in ".e") else s + ".0") + "f"
        s = format(v, ".17g")
        return s if any(ch in s for ch in ".en") else s + ".0"

    def array(self, cname: str, a: np.ndarray, what: str) -> list[str]:
        """``static const NAME_real cname[..][..] = {...};`` with a comment ``what``."""
        a = np.asarray(a, float)
        dims = "".join(f"[{d}]" for d in a.shape)

        def body(x):
            if x.ndim == 1:
                return "{" + ", ".join(self.lit(v) for v in x) + "}"
            return "{\n    " + ",\n    ".join(body(r) for r in x) + "}"

        return [f"/* {c_comment(what)} */", f"static const {self.real} {cname}{dims} = {body(a)};"]

    def scalar(self, cname: str, v: float, what: str) -> list[str]:
        return [f"static const {self.real} {cname} = {self.lit(v)};  /* {c_comment(what)} */"]


@dataclass
class Part:
    """The C of one controller: ``members`` of the state struct, file-scope ``constants``,
    ``init`` and ``step`` statements (``s`` the state pointer; the step writes its m
    outputs into the array named by the caller), and a one-line ``law`` for the header."""

    members: list[str] = field(default_factory=list)
    constants: list[str] = field(default_factory=list)
    init: list[str] = field(default_factory=list)
    step: list[str] = field(default_factory=list)
    law: list[str] = field(default_factory=list)


#: controller class → its exporter ``fn(ctrl, ctx, prefix, out) -> Part``.
EXPORTERS: dict[type, Callable[..., Part]] = {}


def exporter(cls: type) -> Callable:
    """Register the exporter of controller class ``cls`` (a decorator)."""

    def deco(fn):
        EXPORTERS[cls] = fn
        return fn

    return deco


def _emit(ctrl, ctx: _Ctx, prefix: str, out: str) -> Part:
    """The part of ``ctrl`` (dispatch on its class, most specific first)."""
    for cls in type(ctrl).__mro__:
        if cls in EXPORTERS:
            return EXPORTERS[cls](ctrl, ctx, prefix, out)
    known = ", ".join(sorted(c.__name__ for c in EXPORTERS))
    raise ExportError(
        f"controller {type(ctrl).__name__} cannot be exported to C (the "
        f"exportable kinds are {known}); simulate it in flexarm, or write "
        "its exporter in flexarm/deploy/c_export.py (one function per kind)"
    )


def _np(a) -> np.ndarray:
    return np.asarray(a, dtype=float)


def _dot(acc: str, terms: list[tuple[str, str]], indent: str) -> list[str]:
    """``acc = a_0*b_0; acc += a_1*b_1; ...`` summed from the first term (the order of a
    sequential dot product)."""
    if not terms:
        return [f"{indent}{acc} = 0;"]
    lines = [f"{indent}{acc} = {terms[0][0]} * {terms[0][1]};"]
    lines += [f"{indent}{acc} += {a} * {b};" for a, b in terms[1:]]
    return lines


# ----------------------------------------------------------------------------- kinds
def _register_builtin() -> None:
    from flexarm.control.discrete import Cascade, LinearController, Sum
    from flexarm.control.friction_compensation import FrictionCompensated
    from flexarm.control.inner_loop import InnerLoop
    from flexarm.control.lti import LTIController
    from flexarm.control.outer_loop import ReferenceChannel
    from flexarm.control.state_feedback import StateFeedback

    exporter(LinearController)(_linear)
    exporter(LTIController)(_lti)
    exporter(StateFeedback)(_state_feedback)
    exporter(FrictionCompensated)(_friction)
    exporter(Sum)(_sum)
    from flexarm.control.lti import Blocks

    exporter(Blocks)(_blocks)
    exporter(Cascade)(_cascade)
    exporter(ReferenceChannel)(_reference_channel)
    exporter(InnerLoop)(_inner_loop)
    try:  # Feliu's nested loops on a strain-gauge rig (flexarm.control.nested)
        from flexarm.control.nested import MeasuredTip
    except ImportError:
        pass
    else:
        exporter(MeasuredTip)(measured_tip)


def _linear(ctrl, ctx: _Ctx, p: str, out: str) -> Part:
    """x⁺ = A x + B e, y = C x + D e, e = r − y_m (SISO; :class:`LinearController`)."""
    A, B, C = _np(ctrl.A), _np(ctrl.B).ravel(), _np(ctrl.C).ravel()
    D = float(_np(ctrl.D))
    n = B.size
    N = ctx.name.upper()
    P = f"{N}_{p.upper()}"
    e = f"{p}e"
    part = Part(
        law=[
            f"{type(ctrl).__name__}: x+ = A x + B e, y = C x + D e, e = "
            f"{ctrl.reference} - {ctrl.measured} ({n} state(s))"
        ]
    )
    part.constants += ctx.array(f"{P}A", A.reshape(n, n), "A: state matrix")
    part.constants += ctx.array(f"{P}B", B, "B: input vector (per unit error)")
    part.constants += ctx.array(f"{P}C", C, "C: output row")
    part.constants += ctx.scalar(f"{P}D", D, "D: feedthrough")
    part.members.append(f"{ctx.real} {p}x[{n}];  /* controller state x */")
    part.init += [f"for (i = 0; i < {n}; ++i) s->{p}x[i] = 0;"]
    x = f"s->{p}x"
    part.step += [
        "{",
        f"    const {ctx.real} {e} = {ctx.ref(ctrl.reference)} - {ctx.meas(ctrl.measured)};",
        f"    {ctx.real} xn[{n}], acc;",
        *_dot("acc", [(f"{P}C[{j}]", f"{x}[{j}]") for j in range(n)], "    "),
        f"    {out}[0] = acc + {P}D * {e};",
        f"    for (i = 0; i < {n}; ++i) {{",
        f"        acc = {P}A[i][0] * {x}[0];",
        *([f"        for (j = 1; j < {n}; ++j) acc += {P}A[i][j] * {x}[j];"] if n > 1 else []),
        f"        xn[i] = acc + {P}B[i] * {e};",
        "    }",
        f"    for (i = 0; i < {n}; ++i) {x}[i] = xn[i];",
        "}",
    ]
    part.step += [f"{out}[{i}] = 0;" for i in range(1, ctx.n_u)]
    return part


def _lti(ctrl, ctx: _Ctx, p: str, out: str) -> Part:
    """e_i = s_i − y_i; v = C x + D e, x⁺ = A x + B e every ``every`` samples, held
    between (:class:`LTIController`)."""
    A, B, C, D = (_np(getattr(ctrl, k)) for k in "ABCD")
    x0 = _np(ctrl.x0).ravel()
    n, (m, q) = A.shape[0], D.shape
    N = ctx.name.upper()
    P = f"{N}_{p.upper()}"
    every = int(ctrl.every)
    if ctrl.signals is not None:
        ins = [f"{v:.17g}" if kind == "constant" else str(v) for kind, v in ctrl.signals]
        form = f"e = the block's input vector ({', '.join(ins)})"
    else:
        ins = [f"{(s or '0')} - {i}" for i, s in zip(ctrl.inputs, ctrl.setpoints, strict=True)]
        form = f"e = setpoint - measured ({', '.join(ins)})"
    label = "" if ctrl.name in ("controller", "[controller]") else f" {ctrl.name}"
    part = Part(
        law=[
            f"LTIController{label}: {form}; "
            f"v = C x + D e, x+ = A x + B e; {n} state(s), {q} input(s), "
            f"{m} output(s) -> u[{', '.join(map(str, ctrl.outputs))}]"
            + (f"; runs every {every} samples, output held between" if every > 1 else "")
        ]
    )
    if n:
        part.constants += ctx.array(f"{P}A", A, f"A ({n} x {n})")
        part.constants += ctx.array(f"{P}B", B, f"B ({n} x {q}): columns e_0..e_{q - 1}")
        part.constants += ctx.array(f"{P}C", C, f"C ({m} x {n})")
        part.constants += ctx.array(f"{P}X0", x0, "x0: initial state")
        part.members.append(f"{ctx.real} {p}x[{n}];  /* controller state x */")
        part.init.append(f"for (i = 0; i < {n}; ++i) s->{p}x[i] = {P}X0[i];")
    part.constants += ctx.array(f"{P}D", D, f"D ({m} x {q})")
    if every > 1:
        part.members += [
            f"{ctx.real} {p}held[{ctx.n_u}];  /* output held between runs */",
            f"int {p}phase;  /* samples since the last run, 0..{every - 1} */",
        ]
        part.init += [f"for (i = 0; i < {ctx.n_u}; ++i) s->{p}held[i] = 0;", f"s->{p}phase = 0;"]
    x = f"s->{p}x"
    body = [f"{ctx.real} e[{q}], v[{m}], {'acc, ' if n else ''}acc2;"]
    if n:
        body.append(f"{ctx.real} xn[{n}];")
    if ctrl.signals is not None:
        for j, (kind, v) in enumerate(ctrl.signals):
            src = (
                ctx.meas(v)
                if kind == "measured"
                else ctx.ref(v)
                if kind == "reference"
                else ctx.lit(v)
            )
            note = f"{kind} {v}" if kind != "constant" else "constant"
            body.append(f"e[{j}] = {src};  /* {c_comment(note)} */")
    for j, (inp, sp) in enumerate(zip(ctrl.inputs, ctrl.setpoints, strict=True)):
        r = ctx.ref(sp) if sp is not None else "0"
        body.append(f"e[{j}] = {r} - {ctx.meas(inp)};  /* {c_comment(f'{sp or 0} - {inp}')} */")
    body.append(f"for (i = 0; i < {m}; ++i) {{")
    if n:
        body += [
            f"    acc = {P}C[i][0] * {x}[0];",
            *([f"    for (j = 1; j < {n}; ++j) acc += {P}C[i][j] * {x}[j];"] if n > 1 else []),
        ]
    body += [
        f"    acc2 = {P}D[i][0] * e[0];",
        *([f"    for (j = 1; j < {q}; ++j) acc2 += {P}D[i][j] * e[j];"] if q > 1 else []),
        f"    v[i] = {'acc + acc2' if n else 'acc2'};",
        "}",
    ]
    if n:
        body += [
            f"for (i = 0; i < {n}; ++i) {{",
            f"    acc = {P}A[i][0] * {x}[0];",
            *([f"    for (j = 1; j < {n}; ++j) acc += {P}A[i][j] * {x}[j];"] if n > 1 else []),
            f"    acc2 = {P}B[i][0] * e[0];",
            *([f"    for (j = 1; j < {q}; ++j) acc2 += {P}B[i][j] * e[j];"] if q > 1 else []),
            "    xn[i] = acc + acc2;",
            "}",
            f"for (i = 0; i < {n}; ++i) {x}[i] = xn[i];",
        ]
    dest = f"s->{p}held" if every > 1 else out
    body.append(f"for (i = 0; i < {ctx.n_u}; ++i) {dest}[i] = 0;")
    body += [f"{dest}[{o}] = v[{k}];" for k, o in enumerate(ctrl.outputs)]
    if every > 1:
        step = [
            "{",
            f"    if (s->{p}phase == 0) {{",
            *("        " + b for b in body),
            "    }",
            f"    for (i = 0; i < {ctx.n_u}; ++i) {out}[i] = s->{p}held[i];",
            f"    s->{p}phase = (s->{p}phase + 1 == {every}) ? 0 : s->{p}phase + 1;",
            "}",
        ]
    else:
        step = ["{", *("    " + b for b in body), "}"]
    part.step += step
    return part


def _state_feedback(ctrl, ctx: _Ctx, p: str, out: str) -> Part:
    """y = K1 (r − θ) − K2 d − K3 θ̇ − K4 ḋ (:class:`StateFeedback`), rates by backward
    difference (x_k − x_{k−1}) / T or filtered (τ ẋ_{k−1} + x_k − x_{k−1}) / (τ + T);
    x_{−1} = x_0."""
    K = _np(ctrl.gains)
    N = ctx.name.upper()
    P = f"{N}_{p.upper()}"
    R = ctx.real
    rate = ctrl.rate
    part = Part(
        law=[
            f"StateFeedback: y = K1 ({ctrl.reference} - {ctrl.angle}) - K2 "
            f"{ctrl.deflection or '0'} - K3 d/dt {ctrl.angle} - K4 d/dt "
            f"{ctrl.deflection or '0'}; rates: {rate}"
        ]
    )
    part.constants += ctx.array(f"{P}K", K, "K1..K4 (command per rad, per m, per rad/s, per m/s)")
    part.constants += ctx.scalar(f"{P}DT", float(_np(ctrl.dt)), "T: sample period, s")
    if rate == "filtered":
        part.constants += ctx.scalar(
            f"{P}TAU", float(_np(ctrl.tau)), "tau: rate filter time constant, s"
        )
    elif rate != "backward":
        raise ExportError(
            f"StateFeedback rate = {rate!r} cannot be exported (backward or filtered)"
        )
    part.members += [
        f"{R} {p}th_prev, {p}d_prev;  /* angle and deflection at k-1 */",
        f"{R} {p}th_dot, {p}d_dot;  /* their rates at k-1 */",
        f"int {p}started;  /* 0 before the first sample */",
    ]
    part.init += [
        f"s->{p}th_prev = 0; s->{p}d_prev = 0; s->{p}th_dot = 0; s->{p}d_dot = 0;",
        f"s->{p}started = 0;",
    ]
    th = ctx.meas(ctrl.angle)
    d = ctx.meas(ctrl.deflection) if ctrl.deflection else "0"
    sv = f"s->{p}"
    if rate == "backward":
        rates = [
            f"    const {R} th_dot = (th - th_prev) / {P}DT;",
            f"    const {R} d_dot = (d - d_prev) / {P}DT;",
        ]
    else:
        rates = [
            f"    const {R} th_dot = ({P}TAU * {sv}th_dot + th - th_prev) / ({P}TAU + {P}DT);",
            f"    const {R} d_dot = ({P}TAU * {sv}d_dot + d - d_prev) / ({P}TAU + {P}DT);",
        ]
    part.step += [
        "{",
        f"    const {R} th = {th};",
        f"    const {R} d = {d};",
        f"    const {R} th_prev = {sv}started ? {sv}th_prev : th;",
        f"    const {R} d_prev = {sv}started ? {sv}d_prev : d;",
        *rates,
        f"    {out}[0] = {P}K[0] * ({ctx.ref(ctrl.reference)} - th) - {P}K[1] * d"
        f" - {P}K[2] * th_dot - {P}K[3] * d_dot;",
        f"    {sv}th_prev = th; {sv}d_prev = d; {sv}th_dot = th_dot; {sv}d_dot = d_dot;",
        f"    {sv}started = 1;",
        "}",
    ]
    for i in range(1, ctx.n_u):
        part.step.append(f"{out}[{i}] = 0;")
    return part


def _friction(ctrl, ctx: _Ctx, p: str, out: str) -> Part:
    """y = y_fb + c σ, v̂ = (θ_k − θ_{k−1}) / T, σ = sgn v̂ if |v̂| > v_db, else sgn y_fb if
    |y_fb| > u_db, else 0 (FRB Sec. III-B;
    :func:`~flexarm.control.friction_compensation.friction_sign`)."""
    meas = tuple(ctrl.measured)
    m = len(meas)
    if m != ctx.n_u:
        raise ExportError(
            f"FrictionCompensated on {m} angle channel(s) ({', '.join(meas)}) "
            f"for {ctx.n_u} command(s) cannot be exported: give one channel "
            "per command"
        )
    inner = _emit(ctrl.feedback, ctx, p + "fb_", "u_fb")
    N = ctx.name.upper()
    P = f"{N}_{p.upper()}"
    R = ctx.real
    ctx.helpers.add("sign")
    part = Part(
        members=list(inner.members),
        constants=list(inner.constants),
        init=list(inner.init),
        law=inner.law
        + [
            f"FrictionCompensated: u = u_fb + c sigma on "
            f"{', '.join(meas)} (Feliu's sign rule with deadbands)"
        ],
    )
    part.constants += ctx.array(
        f"{P}LEVEL", _np(ctrl.level).ravel(), "c: Coulomb level per command, command units (V or A)"
    )
    part.constants += ctx.array(
        f"{P}VDB",
        _np(ctrl.velocity_deadband).ravel(),
        f"velocity deadband, {ctx.position}/s: at rest below it",
    )
    part.constants += ctx.array(
        f"{P}UDB",
        _np(ctrl.rest_deadband).ravel(),
        "rest deadband, command units: no push at rest below it",
    )
    part.constants += ctx.scalar(f"{P}DT", float(_np(ctrl.dt)), "T: sample period, s")
    part.members += [
        f"{R} {p}prev[{m}];  /* positions at k-1, {ctx.position} */",
        f"int {p}started;  /* 0 before the first sample */",
    ]
    part.init += [f"for (i = 0; i < {m}; ++i) s->{p}prev[i] = 0;", f"s->{p}started = 0;"]
    sv = f"s->{p}"
    step = ["{", f"    {R} u_fb[{ctx.n_u}], th[{m}];"]
    step += ["    " + line for line in inner.step]
    step += [f"    th[{j}] = {ctx.meas(c)};" for j, c in enumerate(meas)]
    step += [
        f"    for (i = 0; i < {m}; ++i) {{",
        f"        const {R} prev = {sv}started ? {sv}prev[i] : th[i];",
        f"        const {R} v = (th[i] - prev) / {P}DT;",
        f"        {out}[i] = u_fb[i] + {P}LEVEL[i] * "
        f"{N}_friction_sign(v, u_fb[i], {P}VDB[i], {P}UDB[i]);",
        f"        {sv}prev[i] = th[i];",
        "    }",
        f"    {sv}started = 1;",
        "}",
    ]
    part.step = step
    return part


def _nest(inner: Part, into: Part) -> None:
    """Add ``inner``'s members, constants, init and law to ``into``."""
    into.members += inner.members
    into.constants += inner.constants
    into.init += inner.init
    into.law += inner.law


def _sum(ctrl, ctx: _Ctx, p: str, out: str) -> Part:
    """y = Σ_i y_i, the parts in order (:class:`~flexarm.control.discrete.Sum`)."""
    part = Part(law=[f"Sum of {len(ctrl.parts)} controllers:"])
    step = ["{"]
    names = []
    for k, sub in enumerate(ctrl.parts):
        arr = f"{p}sum{k}"
        names.append(arr)
        inner = _emit(sub, ctx, f"{p}s{k}_", arr)
        _nest(inner, part)
        step += [f"    {ctx.real} {arr}[{ctx.n_u}];"]
        step += [f"    for (i = 1; i < {ctx.n_u}; ++i) {arr}[i] = 0;"] if ctx.n_u > 1 else []
        step += ["    " + ln for ln in inner.step]
    step += [
        f"    for (i = 0; i < {ctx.n_u}; ++i) {{",
        f"        {out}[i] = {names[0]}[i];",
        *(f"        {out}[i] += {a}[i];" for a in names[1:]),
        "    }",
        "}",
    ]
    part.step = step
    return part


def _blocks(ctrl, ctx: _Ctx, p: str, out: str) -> Part:
    """Several blocks at several rates (:class:`~flexarm.control.lti.Blocks`, a scenario's
    ``[[controllers]]``): one step function is the scheduler; it runs every block's code at
    each call, and a block with a period of k samples updates when its own phase counter is
    0 (every k-th call from init) and holds its output between; y = Σ of the blocks'
    outputs (each drives its own u entries, zeros on the others)."""
    part = _sum(ctrl, ctx, p, out)
    every = [int(getattr(b, "every", 1)) for b in ctrl.parts]
    part.law[0] = (
        f"{len(ctrl.parts)} controller blocks ([[controllers]]), scheduled by this "
        f"one step function: block i runs every k_i calls (k = "
        f"{', '.join(map(str, every))}; its first run at the first call after "
        "init) and holds its output between; u = the blocks' outputs, each on its "
        "own commands:"
    )
    return part


def _cascade(ctrl, ctx: _Ctx, p: str, out: str) -> Part:
    """Nested loops: the outer controller's y_0 is the inner one's reference channel
    ``via`` (:class:`~flexarm.control.discrete.Cascade`; FRB Fig. 3)."""
    arr = f"{p}outer"
    outer = _emit(ctrl.outer, ctx, f"{p}o_", arr)
    saved = ctx.computed_references.get(ctrl.via)
    ctx.computed_references[ctrl.via] = f"{arr}[0]"
    try:
        inner = _emit(ctrl.inner, ctx, f"{p}i_", out)
    finally:
        if saved is None:
            ctx.computed_references.pop(ctrl.via)
        else:
            ctx.computed_references[ctrl.via] = saved
    part = Part(law=[f"Cascade: the outer loop's output is the inner loop's {ctrl.via}:"])
    _nest(outer, part)
    _nest(inner, part)
    part.step = [
        "{",
        f"    {ctx.real} {arr}[{ctx.n_u}];",
        *(["    " + f"for (i = 1; i < {ctx.n_u}; ++i) {arr}[i] = 0;"] if ctx.n_u > 1 else []),
        *("    " + ln for ln in outer.step),
        *("    " + ln for ln in inner.step),
        "}",
    ]
    return part


def _reference_channel(ctrl, ctx: _Ctx, p: str, out: str) -> Part:
    """y = reference[channel] (a precomputed signal passed through: FRB's θ̂_mr)."""
    return Part(
        law=[f"ReferenceChannel: y = {ctrl.channel}"],
        step=[
            f"{out}[0] = {ctx.ref(ctrl.channel)};",
            *(f"{out}[{i}] = 0;" for i in range(1, ctx.n_u)),
        ],
    )


def measured_tip(ctrl, ctx: _Ctx, p: str, out: str) -> Part:
    """``ctrl.law`` with the tip angle formed from the hub encoder and the gauge,
    θt = θm + s d (s = ``ctrl.scale``, rad per unit of d): the measured ``tip_angle`` the law
    reads is a computed channel, not an input (``flexarm.control.nested.MeasuredTip``)."""
    N = ctx.name.upper()
    P = f"{N}_{p.upper()}"
    tip = f"{p}tip_angle"
    part = Part(law=["tip_angle = motor_angle + S tip_deflection (from the gauge), then:"])
    part.constants += ctx.scalar(
        f"{P}S", float(_np(ctrl.scale)), "s: rad of tip angle per unit of tip_deflection"
    )
    line = (
        f"const {ctx.real} {tip} = {ctx.meas('motor_angle')} + {P}S * {ctx.meas('tip_deflection')};"
    )
    saved = ctx.computed_measured.get("tip_angle")
    ctx.computed_measured["tip_angle"] = tip
    try:
        inner = _emit(ctrl.law, ctx, f"{p}l_", out)
    finally:
        if saved is None:
            ctx.computed_measured.pop("tip_angle")
        else:
            ctx.computed_measured["tip_angle"] = saved
    _nest(inner, part)
    part.step = ["{", "    " + line, *("    " + ln for ln in inner.step), "}"]
    return part


def _siso_ss(ctx: _Ctx, P: str, r, what: str) -> tuple[list[str], int]:
    """Constants ``P``A, B, C, D of a SISO realisation ``r`` = (A, B, C, D)."""
    A, B, C, D = (_np(a) for a in r)
    n = B.size
    consts = ctx.array(f"{P}A", A.reshape(n, n), f"{what}: A")
    consts += ctx.array(f"{P}B", B.ravel(), f"{what}: B")
    consts += ctx.array(f"{P}C", C.ravel(), f"{what}: C")
    consts += ctx.scalar(f"{P}D", float(D), f"{what}: D")
    return consts, n


def _siso_step(P: str, n: int, x: str, e: str, y: str, xn: str) -> list[str]:
    """xn = Σ_j A[i][j] x[j] + B[i] e (each row summed from j = 0), y = Σ_j C[j] x[j] + D e,
    the order of ``InnerLoop._lin``."""
    return [
        f"for (i = 0; i < {n}; ++i) {{",
        f"    acc = {P}A[i][0] * {x}[0];",
        *([f"    for (j = 1; j < {n}; ++j) acc += {P}A[i][j] * {x}[j];"] if n > 1 else []),
        f"    {xn}[i] = acc + {P}B[i] * {e};",
        "}",
        f"acc = {P}C[0] * {x}[0];",
        *([f"for (j = 1; j < {n}; ++j) acc += {P}C[j] * {x}[j];"] if n > 1 else []),
        f"{y} = acc + {P}D * {e};",
    ]


def _inner_loop(ctrl, ctx: _Ctx, p: str, out: str) -> Part:
    """FRB Fig. 4 (:class:`~flexarm.control.inner_loop.InnerLoop`): y2 = G_cm2 θm,
    u_fb = G_cm1 (θ_mr − y2), ĉ = H (θm − θt), v̂ = (θm − θm,k−1)/T,
    u = u_fb + (on_c ĉ + on_f C_f σ) / K, σ the friction sign rule."""
    N = ctx.name.upper()
    P = f"{N}_{p.upper()}"
    R = ctx.real
    ctx.helpers.add("sign")
    part = Part(
        law=[
            f"InnerLoop (FRB Fig. 4): u = G_cm1 ({ctrl.reference} - G_cm2 "
            "motor_angle) + (coupling H (motor_angle - tip_angle) + C_f sigma) / K"
        ]
    )
    ns = {}
    for key, r, what in (
        ("G1", ctrl.g1, "G_cm1"),
        ("G2", ctrl.g2, "G_cm2"),
        ("H", ctrl.coupling, "coupling filter H"),
    ):
        consts, ns[key] = _siso_ss(ctx, f"{P}{key}_", r, what)
        part.constants += consts
        part.members.append(f"{R} {p}{key.lower()}[{ns[key]}];  /* {c_comment(what)} state */")
        part.init.append(f"for (i = 0; i < {ns[key]}; ++i) s->{p}{key.lower()}[i] = 0;")
    for cname, val, what in (
        ("K", ctrl.torque_constant, "K: torque per unit command"),
        ("CF", ctrl.coulomb, "C_f: Coulomb level (torque units)"),
        ("ON_F", ctrl.friction_on, "friction compensation on (1) / off"),
        ("ON_C", ctrl.coupling_on, "coupling compensation on (1) / off"),
        ("VDB", ctrl.velocity_deadband, f"velocity deadband, {ctx.position}/s"),
        ("UDB", ctrl.rest_deadband, "rest deadband, command units"),
        ("DT", ctrl.dt, "T: sample period, s"),
        ("TH0", ctrl.initial_motor_angle, f"motor angle before t = 0, {ctx.position}"),
    ):
        part.constants += ctx.scalar(f"{P}{cname}", float(_np(val)), what)
    part.members.append(f"{R} {p}th_prev;  /* motor angle at k-1, {ctx.position} */")
    part.init.append(f"s->{p}th_prev = {P}TH0;")
    th, tip, ref = ctx.meas("motor_angle"), ctx.meas("tip_angle"), ctx.ref(ctrl.reference)
    sv = f"s->{p}"
    step = [
        "{",
        f"    {R} xn2[{ns['G2']}], xn1[{ns['G1']}], xnc[{ns['H']}], y2, u_fb, c_hat, acc;",
        f"    const {R} th = {th};",
    ]
    step += ["    " + ln for ln in _siso_step(f"{P}G2_", ns["G2"], f"{sv}g2", "th", "y2", "xn2")]
    step += [f"    {{ const {R} e1 = {ref} - y2;"]
    step += ["    " + ln for ln in _siso_step(f"{P}G1_", ns["G1"], f"{sv}g1", "e1", "u_fb", "xn1")]
    step += ["    }", f"    {{ const {R} ec = th - {tip};"]
    step += ["    " + ln for ln in _siso_step(f"{P}H_", ns["H"], f"{sv}h", "ec", "c_hat", "xnc")]
    step += [
        "    }",
        f"    {{ const {R} v = (th - {sv}th_prev) / {P}DT;",
        f"      const {R} sigma = {N}_friction_sign(v, u_fb, {P}VDB, {P}UDB);",
        f"      {out}[0] = u_fb + ({P}ON_C * c_hat + {P}ON_F * {P}CF * sigma) / {P}K; }}",
        *(
            f"    for (i = 0; i < {ns[k]}; ++i) {sv}{k.lower()}[i] = xn{c}[i];"
            for k, c in (("G1", "1"), ("G2", "2"), ("H", "c"))
        ),
        f"    {sv}th_prev = th;",
        "}",
    ]
    for i in range(1, ctx.n_u):
        step.insert(-1, f"    {out}[{i}] = 0;")
    part.step = step
    return part


_register_builtin()


# ----------------------------------------------------------------------------- assembly
@dataclass
class CCode:
    """The generated ``NAME.h`` and ``NAME.c`` and the channel order (name, unit)."""

    name: str
    precision: str
    header: str
    source: str
    measured: list[tuple[str, str]]
    references: list[tuple[str, str]]
    outputs: list[tuple[str, str]]

    def write(self, directory: str | Path, *, overwrite: bool = False) -> list[Path]:
        """Write ``NAME.h`` and ``NAME.c`` into ``directory`` (created) through the one
        atomic writer; an existing file is an error unless ``overwrite``."""
        from flexarm.io.write import OutputExistsError, write_text

        d = Path(directory)
        if d.exists() and not d.is_dir():
            raise ExportError(
                f"--out {d}: is a file, not a folder; give a folder for "
                f"{self.name}.h and {self.name}.c"
            )
        targets = [d / f"{self.name}.h", d / f"{self.name}.c"]
        if not overwrite:
            there = [str(t) for t in targets if t.exists()]
            if there:
                raise OutputExistsError(
                    f"{', '.join(there)}: exist(s) already; not "
                    "overwritten (pass --overwrite / overwrite=True)"
                )
        d.mkdir(parents=True, exist_ok=True)
        return [
            write_text(targets[0], self.header, overwrite=overwrite),
            write_text(targets[1], self.source, overwrite=overwrite),
        ]


def _unit(name: str, scenario) -> str:
    """The SI unit of channel ``name``: flexarm's unit of the name, else of the plant signal
    the channel reads (per second after a rate filter)."""
    from flexarm.io.logs import signal_unit

    u = signal_unit(name)
    if u is not None:
        return _linear_unit(u or "1", scenario)
    sens = (getattr(scenario, "sensors", {}) or {}).get(name)
    sig = sens.signal if sens is not None and sens.signal else name
    u = signal_unit(sig) or {"tip_deflection": "m", "coupling_torque": "N*m"}.get(sig)
    if u is None:
        return f"the unit of the plant signal {sig}"
    u = _linear_unit(u, scenario)
    if (
        sens is not None
        and sens.filter is not None
        and sens.filter.kind in ("lowpass2_rate", "derivative2")
    ):
        return f"{u}/s"
    return u


def _linear_unit(unit: str, scenario) -> str:
    """``unit`` on a linear axis (a prismatic joint: m for rad, m/s for rad/s, N for N·m,
    :data:`flexarm.io.logs.LINEAR_SI`); unchanged on a rotary arm."""
    from flexarm.io.logs import LINEAR_SI

    return LINEAR_SI.get(unit, unit) if getattr(scenario, "prismatic", False) else unit


#: the longest C prefix (``--name``) and the longest name text written into a comment
C_NAME_MAX = 64
COMMENT_TEXT_MAX = 200


def _c_name(name: str) -> str:
    """``name`` as the C prefix and file name (``--name``): an identifier (letters, digits
    and _, not starting with a digit, not a C keyword) of at most :data:`C_NAME_MAX`
    characters, else :class:`ExportError`: the one check every generated identifier and
    file name of the export goes through."""
    if not isinstance(name, str) or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", name):
        raise ExportError(
            f"--name {c_comment(repr(name))} is not a usable C identifier: give letters, "
            "digits and _ not starting with a digit, and not a C keyword "
            "(e.g. --name rotary_ctrl)"
        )
    if name in _C_RESERVED:
        raise ExportError(
            f"--name {name!r}: a C keyword; give another prefix (e.g. --name rotary_ctrl)"
        )
    if len(name) > C_NAME_MAX:
        raise ExportError(
            f"--name {name[:20]}... ({len(name)} characters): longer than {C_NAME_MAX}; "
            "give a shorter C prefix"
        )
    return name


def c_comment(text: Any, limit: int = COMMENT_TEXT_MAX) -> str:
    """``text`` (a scenario's name, a channel's, a file's) made safe inside a C ``/* */``
    comment: the one escaper of the export. Control characters (newline, NUL, C1 controls
    such as U+0085, the Unicode line separators) become spaces, ``*/`` and ``/*`` lose
    their meaning (``*_/``, ``/_*``), trigraph ``??`` becomes ``?_?``, a trailing
    backslash is dropped; longer than ``limit`` characters: cut, ``...`` added."""
    s = "".join(
        " " if (ch < " " or "\x7f" <= ch <= "\x9f" or ch in "\u2028\u2029") else ch
        for ch in str(text)
    )
    if len(s) > limit:
        s = s[:limit] + "..."
    while "*/" in s or "/*" in s or "??" in s:
        s = s.replace("*/", "*_/").replace("/*", "/_*").replace("??", "?_?")
    return s.rstrip("\\")


def c_string(text: Any, limit: int = 4 * COMMENT_TEXT_MAX) -> str:
    """``text`` made safe between the double quotes of a C string or ``#warning``: as
    :func:`c_comment`, and backslashes and double quotes replaced by ``/`` and ``'``."""
    return c_comment(str(text).replace("\\", "/").replace('"', "'"), limit)


def generate_c(
    scenario,
    *,
    name: str = "controller",
    precision: str = "double",
    method: str | None = None,
    source: str | None = None,
    controller=None,
) -> CCode:
    """The C99 code of ``scenario``'s controller, built as the simulator builds it (module
    docstring). ``method``: the design method (for the provenance comment); ``source``:
    where the scenario came from (a file name, no folder, so output does not depend on
    where it lies); ``controller``: a controller object to export instead of the
    scenario's ``[controller]`` (as :func:`flexarm.sim.build.prepare` takes it), with the
    scenario's period, actuator and sensors."""
    from flexarm.io.logs import signal_unit
    from flexarm.sim.build import prepare
    from flexarm.version import __version__

    name = _c_name(name)
    if precision not in PRECISIONS:
        raise ExportError(f"--precision {precision!r}: give double or float")
    if not scenario.controller_specs() and controller is None:
        raise ExportError(
            f"scenario {scenario.name!r} has no [controller]: nothing to "
            "export (add one, or export a design directory)"
        )
    if scenario.sampling is None:
        raise ExportError(
            f"scenario {scenario.name!r} has no [sampling]: a discrete "
            "controller needs its sample period"
        )
    prep = prepare(scenario, controller)
    loop = prep.loop
    ctrl = loop.controller
    n_u = int(loop.plant.n_inputs)
    input_names = list(loop.plant.input_names)
    ctx = _Ctx(name, precision, n_u)
    if getattr(scenario, "prismatic", False):
        ctx.position = "m"  # a linear axis: positions m, rates m/s, forces N
    N = name.upper()
    R = ctx.real
    try:
        part = _emit(ctrl, ctx, "", "y")
    except ExportError as exc:
        what = (
            "the controller given"
            if controller is not None
            else f"[controller] type = {getattr(scenario.controller, 'type', '?')!r}"
            if scenario.controllers is None
            else f"[[controllers]] ({len(scenario.controllers)} blocks)"
        )
        raise ExportError(f"scenario {scenario.name!r}, {what}: {exc}") from None

    limit = np.broadcast_to(_np(loop.actuator.limit), (n_u,))
    quantum = np.broadcast_to(_np(loop.actuator.quantum), (n_u,))
    act_consts: list[str] = []
    act_step: list[str] = []
    if np.any(np.isfinite(limit)):
        if not np.all(np.isfinite(limit)):
            raise ExportError(
                f"scenario {scenario.name!r}: the command limits "
                f"{limit.tolist()} are finite for some commands only; give "
                "[actuator] limit"
            )
        act_consts += ctx.array(
            f"{N}_LIMIT",
            limit,
            "actuator saturation L per command (V or A): u = min(max(y, -L), L)",
        )
        act_step.append(
            f"    for (i = 0; i < {N}_N_U; ++i) y[i] = y[i] < -{N}_LIMIT[i] ? "
            f"-{N}_LIMIT[i] : (y[i] > {N}_LIMIT[i] ? {N}_LIMIT[i] : y[i]);"
        )
    if np.any(quantum > 0):
        bits = getattr(scenario.actuator, "bits", 0)
        if bits > 31:
            raise ExportError(
                f"[actuator] bits = {bits}: the D/A count round-off is exported for at most 31 bits"
            )
        ctx.helpers.add("round")
        act_consts += ctx.array(
            f"{N}_QUANTUM",
            quantum,
            f"D/A count q = 2 L / 2^{bits} per command: u = q round(u / q), ties to even",
        )
        act_step.append(
            f"    for (i = 0; i < {N}_N_U; ++i) if ({N}_QUANTUM[i] > 0) "
            f"y[i] = {N}_round_even(y[i] / {N}_QUANTUM[i]) * {N}_QUANTUM[i];"
        )

    sc_sens = scenario.sensors or {}
    meas = [(c, _unit(c, scenario)) for c in ctx.measured]
    # reference channels: a scenario's [reference] / [references.X] are angles (rad; m on a
    # linear axis), as is the nested loops' feedforward; a known signal name keeps its unit
    refs = [
        (r, _unit(r, scenario) if signal_unit(r) is not None else ctx.position)
        for r in ctx.references
    ]
    outs = [
        (
            nm,
            "V"
            if nm.startswith("voltage")
            else "A"
            if nm.startswith("current")
            else _linear_unit("N*m", scenario)
            if nm.startswith("torque")
            else "command units",
        )
        for nm in input_names
    ]
    dt = float(scenario.sampling.period)
    delay = int(scenario.sampling.delay)

    def chan_lines(items, arr, extra=None):
        if not items:
            return [" *   (none: pass NULL)"]
        return [
            f" *   {arr}[{i}]  {c_comment(f'{n}  ({u}){(extra or {}).get(n, str())}')}"
            for i, (n, u) in enumerate(items)
        ]

    from flexarm.sim.build import sensor_quanta

    quanta = sensor_quanta(sc_sens)
    notes = {}
    for c in ctx.measured:
        s = sc_sens.get(c)
        if s is None:
            continue
        bits = []
        if s.gain != 1.0:
            bits.append(
                f"pass the reading as the sensor gives it, its gain {s.gain:g} (the "
                "scenario's) included: this code does not rescale it"
            )
        q = quanta[c]
        if q:
            bits.append(f"quantum {q:.6g}")
        if s.delay:
            bits.append(f"{s.delay} sample(s) sensor delay in the scenario")
        if s.filter is not None:
            bits.append(f"digital filter {s.filter.kind} in the scenario: NOT in this code")
        if s.bandwidth:
            bits.append(f"analog low-pass {s.bandwidth:g} Hz before the A/D")
        if bits:
            notes[c] = "; " + ", ".join(bits)

    provenance = [
        f" * Generated by flexarm {__version__} (flexarm export-c); do not edit by hand.",
        f" * Scenario: {scenario.name}"
        + (f" ({source})" if source and source != scenario.name else ""),
        f" * Design method: {method or 'none (the scenario file controller)'}",
        f" * Controllers: {len(scenario.controllers)} blocks ([[controllers]]: "
        + ", ".join(
            f"{b.name} every {b.every * scenario.sampling.period:g} s"
            for b in getattr(ctrl, "parts", ())
        )
        + ")"
        if controller is None and scenario.controllers is not None
        else (
            f" * Controller type: {getattr(scenario.controller, 'type', '?')}"
            + (
                " + friction_compensation"
                if getattr(scenario.controller, "friction_compensation", None)
                else ""
            )
        )
        if controller is None
        else f" * Controller: {type(ctrl).__name__} (given in Python)",
        f" * Precision: {precision} ({R})",
    ]
    provenance = [" * " + c_comment(line[3:], 10 * COMMENT_TEXT_MAX) for line in provenance]
    law = [f" *   {c_comment(line, 10 * COMMENT_TEXT_MAX)}" for line in part.law]
    act_text = []
    if np.all(np.isfinite(limit)):
        act_text.append(f" *   saturation at +-{', '.join(f'{v:g}' for v in limit)}")
    else:
        act_text.append(" *   no saturation (no finite limit in the scenario)")
    if np.any(quantum > 0):
        act_text.append(
            f" *   D/A count {', '.join(f'{v:.6g}' for v in quantum)} (round half to even)"
        )
    guard = f"{N}_H"
    header = "\n".join(
        [
            f"/* {name}.h: the {c_comment(scenario.name)} controller as C99, one call per sample.",
            " *",
            *provenance,
            " *",
            f" * Call {name}_init(&s) once, then {name}_step(&s, measured, reference, u) once",
            f" * per sample period T = {dt:.17g} s, with the readings of that sample.",
            f" * The scenario's computation delay: {delay} sample(s) (the target's own timing).",
            " *",
            " * Law:",
            *law,
            " *   then the actuator:",
            *act_text,
            " *",
            " * measured[] (the sensors' readings in SI units, as the simulator's sensors",
            " * deliver them):",
            *chan_lines(meas, "measured", notes),
            " * reference[]:",
            *chan_lines(refs, "reference"),
            " * u[] (the command to the D/A):",
            *chan_lines(outs, "u"),
            " */",
            f"#ifndef {guard}",
            f"#define {guard}",
            "",
            f"typedef {precision} {R};",
            "",
            f"#define {N}_N_MEASURED {len(meas)}",
            f"#define {N}_N_REFERENCE {len(refs)}",
            f"#define {N}_N_U {n_u}",
            f"#define {N}_PERIOD {dt:.17g}  /* s */",
            "",
            "/* The controller's state (memory between samples); set by init, updated by step. */",
            "typedef struct {",
            *(f"    {mem}" for mem in part.members),
            f"    int initialised;  /* 1 after {name}_init (keeps the struct non-empty) */",
            f"}} {name}_state;",
            "",
            f"/* Reset the state (call once before the first {name}_step). */",
            f"void {name}_init({name}_state *s);",
            "",
            "/* One sample: read measured[0..N_MEASURED-1] and reference[0..N_REFERENCE-1]",
            " * (orders above), write u[0..N_U-1], update *s. */",
            f"void {name}_step({name}_state *s, const double measured[], const double "
            "reference[], double u[]);",
            "",
            f"#endif /* {guard} */",
            "",
        ]
    )

    helpers = []
    if "sign" in ctx.helpers:
        helpers += [
            "/* sigma of Feliu's friction compensation: sgn v if |v| > vdb, else sgn u_fb if",
            " * |u_fb| > udb, else 0. */",
            f"static {R} {N}_sgn({R} x) {{ return x > 0 ? ({R})1 : (x < 0 ? ({R})-1 : ({R})0); }}",
            f"static {R} {N}_abs({R} x) {{ return x < 0 ? -x : x; }}",
            f"static {R} {N}_friction_sign({R} v, {R} u_fb, {R} vdb, {R} udb)",
            "{",
            f"    if ({N}_abs(v) > vdb) return {N}_sgn(v);",
            f"    if ({N}_abs(u_fb) > udb) return {N}_sgn(u_fb);",
            f"    return ({R})0;",
            "}",
            "",
        ]
    if "round" in ctx.helpers:
        helpers += [
            "/* x rounded to the nearest whole number, ties to even (as numpy and JAX round),",
            " * without <math.h>; |x| <= 2^30 here (the saturated command over the D/A count). */",
            f"static {R} {N}_round_even({R} x)",
            "{",
            "    long n = (long)x;               /* toward zero */",
            f"    const {R} f = x - ({R})n;       /* exact: the fraction, in (-1, 1) */",
            f"    if (f > ({R})0.5 || (f == ({R})0.5 && (n % 2) != 0)) n += 1;",
            f"    else if (f < ({R})-0.5 || (f == ({R})-0.5 && (n % 2) != 0)) n -= 1;",
            f"    return ({R})n;",
            "}",
            "",
        ]

    uses_ij = any(("[i]" in ln or "(i =" in ln) for ln in part.step + part.init + act_step)
    uses_j = any("(j =" in ln for ln in part.step)
    decl_ij = "    int i" + (", j" if uses_j else "") + ";" if (uses_ij or uses_j) else None
    init_ij = any("(i =" in ln for ln in part.init)
    conv = [
        f"    const {R} m_{i} = ({R})measured[{i}];  /* {c_comment(n)} */"
        for i, (n, _) in enumerate(meas)
    ]
    conv += [
        f"    const {R} r_{i} = ({R})reference[{i}];  /* {c_comment(n)} */"
        for i, (n, _) in enumerate(refs)
    ]
    source = "\n".join(
        [
            f"/* {name}.c: see {name}.h (generated by flexarm export-c; do not edit by hand).",
            *provenance,
            " */",
            f'#include "{name}.h"',
            "",
            *part.constants,
            *act_consts,
            "",
            *helpers,
            f"void {name}_init({name}_state *s)",
            "{",
            *(["    int i;"] if init_ij else []),
            *("    " + ln for ln in part.init),
            "    s->initialised = 1;",
            "}",
            "",
            f"void {name}_step({name}_state *s, const double measured[], const double "
            "reference[], double u[])",
            "{",
            *conv,
            *([decl_ij] if decl_ij else []),
            f"    {R} y[{N}_N_U];",
            *(["    (void)measured;"] if not meas else []),
            *(["    (void)reference;"] if not refs else []),
            *(
                ["    (void)s;  /* a static law: no state */"]
                if not any("s->" in ln for ln in part.step)
                else []
            ),
            *("    " + ln for ln in part.step),
            *act_step,
            *(
                [f"    for (i = 0; i < {N}_N_U; ++i) u[i] = (double)y[i];"]
                if uses_ij or uses_j
                else [f"    u[{i}] = (double)y[{i}];" for i in range(n_u)]
            ),
            "}",
            "",
        ]
    )
    return CCode(name, precision, header, source, meas, refs, outs)


# ----------------------------------------------------------------------------- files
def design_dir(design: str | Path) -> Path | None:
    """The design directory ``design`` names: the folder itself (holding ``design.toml``),
    or the folder of a ``design.toml`` / ``design.json`` given as a file; None for a
    scenario file or name."""
    p = Path(design)
    if p.is_dir():
        return p
    if p.name in ("design.toml", "design.json") and p.is_file():
        return p.parent
    return None


def load_design(design: str | Path) -> tuple[Any, str | None, str]:
    """The scenario of ``design`` (a design directory holding ``design.toml``, that
    ``design.toml`` or ``design.json`` itself, or a scenario file or built-in name), its
    design method (``design.json``, if any) and a source label (the file's name, no
    folder)."""
    from flexarm.specs import ScenarioError, load_scenario

    p = Path(design)
    method = None
    d = design_dir(p)
    if d is not None:
        toml = d / "design.toml"
        if not toml.is_file():
            raise ExportError(
                f"{d}: a folder without design.toml; give a design directory "
                "(written by flexarm design ... --out DIR) or a scenario file"
            )
        js = d / "design.json"
        if js.is_file():
            try:
                method = json.loads(js.read_text(encoding="utf-8")).get("method")
            except (OSError, ValueError, AttributeError) as exc:
                raise ExportError(f"{js}: not readable JSON ({exc})") from None
        path, label = toml, f"{d.name}/design.toml"
    else:
        path, label = design, p.name
    try:
        sc = load_scenario(path)
    except ScenarioError as exc:
        hint = "" if Path(path).exists() else "; or give a design directory holding design.toml"
        raise ExportError(f"{exc}{hint}") from None
    return sc, method, label


def export_c(
    design,
    out: str | Path,
    *,
    name: str = "controller",
    precision: str = "double",
    overwrite: bool = False,
    accept_unstable: bool = False,
    force: bool = False,
    check: bool = True,
) -> tuple[CCode, list[Path]]:
    """``flexarm export-c``: the controller of ``design`` (a design directory or its
    ``design.toml`` / ``design.json``, a scenario file or name, a
    :class:`~flexarm.design.result.Design`, or a scenario object) as ``out/NAME.h`` and
    ``out/NAME.c``. Returns the code and the paths written.

    The gate on every export (issue #45): the design's stored verdict (``Design.verdict``,
    or ``"verdict"`` in the design directory's ``design.json``, whichever of the design's
    files is given) and the nominal check of the sampled loop with its delays
    (:func:`flexarm.deploy.stability.nominal_check`, run on every design and scenario
    unless ``check=False``).  A failure of either is refused with
    :class:`flexarm.errors.UnstableDesignError` unless ``accept_unstable`` (``force`` is
    its older name; ``--accept-unstable``); then the header carries the verdict as a
    ``#warning`` (every compiler says it on each build)."""
    from flexarm.design.result import Design
    from flexarm.errors import UnstableDesignError

    name = _c_name(name)
    if isinstance(design, Design):
        sc, method, label = design.scenario, design.method, None
        verdict = design.verdict
    elif hasattr(design, "controller") and hasattr(design, "arm"):  # a Scenario
        sc, method, label, verdict = design, None, None, None
    else:
        sc, method, label = load_design(design)
        d = design_dir(design)
        verdict = _design_verdict(d) if d is not None else None
    what = label or method or (getattr(sc, "name", None) and f"scenario {sc.name!r}") or "design"
    what = c_comment(what)
    accept = accept_unstable or force
    code = generate_c(sc, name=name, precision=precision, method=method, source=label)
    failures = []
    if verdict is not None and verdict != "stable":
        failures.append(f"the design gate's verdict is not stable: {verdict}")
    if check:
        from flexarm.deploy.stability import nominal_check

        try:
            nc = nominal_check(sc)
        except (ValueError, TypeError, NotImplementedError) as exc:
            failures.append(f"the nominal stability check could not run ({exc})")
        else:
            if not nc.stable:
                failures.append(nc.verdict)
    if failures and not accept:
        text = "; ".join(failures)
        raise UnstableDesignError(
            f"{what}: not exported: {text}",
            value=verdict if verdict is not None and verdict != "stable" else None,
            fix="redesign (a design's design.json and compare.md say why), or pass "
            "accept_unstable=True (--accept-unstable) to export it with the verdict as a "
            "#warning in the header",
        )
    for f in failures:
        code = _with_warning(
            code,
            f"{what}: {f}".replace("the design gate's verdict is not stable", "design verdict"),
        )
    return code, code.write(out, overwrite=overwrite)


def _design_verdict(design) -> str | None:
    """The ``"verdict"`` of a design directory's ``design.json`` (None: none there)."""
    js = Path(design) / "design.json"
    if not js.is_file():
        return None
    try:
        v = json.loads(js.read_text(encoding="utf-8")).get("verdict")
    except (OSError, ValueError, AttributeError) as exc:
        raise ExportError(f"{js}: not readable JSON ({exc})") from None
    return None if v is None else str(v)


def _with_warning(code: CCode, text: str) -> CCode:
    """``code`` with ``#warning "flexarm: <text>"`` after the header's include guard."""
    from dataclasses import replace

    guard = f"#define {code.name.upper()}_H\n"
    head = code.header
    i = head.find(guard)
    line = f'#warning "flexarm: {c_string(text)}; exported with --accept-unstable"\n'
    head = head[: i + len(guard)] + line + head[i + len(guard) :] if i >= 0 else line + head
    return replace(code, header=head)
