"""Scalar programs compiled into a few non-duplicating XLA kernels ("layers").

Why. A small closed-form model (a 6×6 mass matrix, its Cholesky solve, a few dozen
trigonometric and polynomial terms) traced scalar by scalar into JAX reaches XLA as one
large graph of scalar operations. XLA on CPU then does one of two costly things with a
scalar shared by several consumers: it computes it in its own kernel (≈ 13 ns per kernel
launch in a loop on this project's machine), or, when the scalar is cheap, it copies its
whole expression tree into every consumer kernel (the consumer of a ``jnp.stack`` computes
each element's tree independently). The multi-link plant lost most of its time to the
second: measured, 1.1–1.4 µs per right-hand side of the two-link arm, most of it duplicated
arithmetic and trigonometry.

What. :class:`Program` records the computation once on symbolic scalars (:class:`Sym`, with
+, −, ×, ÷, unary minus and :func:`sin`, :func:`cos`, :func:`sqrt`, :func:`rsqrt`), with
hash-consing (common subexpressions are one node) and folding of Python constants (structural
zeros and ones vanish). :meth:`Program.emit` then schedules the graph:

* the *inline cost* of a node is its weight (1 for +, −, ×; 8 for ÷, √, 1/√; 16 for sin, cos)
  plus the inline cost of the operands that are not materialised;
* a node is *materialised* (computed once, stored) when it has ≥ 2 uses and an inline cost
  above ``share`` (default 2) or is an expensive operation, or when its inline cost exceeds
  ``max_tree``; any other node is inlined into its single consumer (or, if cheap, duplicated);
* a materialised node goes into layer 1 + (the deepest layer its inline tree reads), as soon
  as possible; every layer is emitted as one ``jnp.stack`` of expression trees behind a
  ``jax.lax.optimization_barrier`` (so XLA computes it as one fused kernel and cannot
  re-inline it), and the outputs form a last stack.

The result is the same arithmetic, in the same order of operations per node, as the plain
scalar trace (results agree to round-off), with every shared value computed once and one
kernel per layer. Under ``jax.vmap`` each layer becomes one SIMD kernel over the batch.
Sine and cosine are emitted as :func:`flexarm.fastmath.sincos`'s arithmetic (within 2 ulp of
libm), since XLA:CPU's float64 ``sin``/``cos`` are scalar calls that no kernel vectorises.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Hashable, Iterable, Sequence
from typing import Any

import jax
import jax.numpy as jnp

from flexarm import fastmath

_WEIGHT = {
    "add": 1,
    "sub": 1,
    "mul": 1,
    "neg": 1,
    "div": 8,
    "sqrt": 8,
    "rsqrt": 8,
    "sin": 16,
    "cos": 16,
}
_EXPENSIVE = frozenset({"div", "sqrt", "rsqrt", "sin", "cos"})
_COMMUTATIVE = frozenset({"add", "mul"})

Number = (int, float)


def _is_num(a) -> bool:
    return isinstance(a, Number) and not isinstance(a, bool)


class Sym:
    """A symbolic scalar of a :class:`Program`; arithmetic with Syms and Python numbers."""

    __slots__ = ("prog", "id")

    def __init__(self, prog: Program, i: int):
        self.prog = prog
        self.id = i

    def __add__(self, o):
        return self.prog.binary("add", self, o)

    def __radd__(self, o):
        return self.prog.binary("add", o, self)

    def __sub__(self, o):
        return self.prog.binary("sub", self, o)

    def __rsub__(self, o):
        return self.prog.binary("sub", o, self)

    def __mul__(self, o):
        return self.prog.binary("mul", self, o)

    def __rmul__(self, o):
        return self.prog.binary("mul", o, self)

    def __truediv__(self, o):
        return self.prog.binary("div", self, o)

    def __rtruediv__(self, o):
        return self.prog.binary("div", o, self)

    def __neg__(self):
        return self.prog.unary("neg", self)

    def __repr__(self) -> str:
        return f"Sym({self.prog.ops[self.id]}#{self.id})"


def _unary_fn(op: str, pyfn: Callable, jfn: Callable):
    def f(a):
        if isinstance(a, Sym):
            return a.prog.unary(op, a)
        if _is_num(a):
            return float(pyfn(a))
        return jfn(a)

    f.__name__ = op
    f.__doc__ = f"{op}(a) for a Sym, a Python number or a JAX value."
    return f


sin = _unary_fn("sin", math.sin, jnp.sin)
cos = _unary_fn("cos", math.cos, jnp.cos)
sqrt = _unary_fn("sqrt", math.sqrt, jnp.sqrt)
rsqrt = _unary_fn("rsqrt", lambda a: 1.0 / math.sqrt(a), jax.lax.rsqrt)


class Program:
    """A recorded scalar computation (see module docstring)."""

    def __init__(self):
        self.ops: list[str] = []
        self.args: list[tuple] = []
        self.keys: dict[int, Hashable] = {}  # leaf id -> key
        self.const: dict[int, float] = {}  # const id -> value
        self._memo: dict[tuple, int] = {}

    # ------------------------------------------------------------ building
    def _new(self, op: str, args: tuple, memo_key: tuple) -> int:
        i = self._memo.get(memo_key)
        if i is None:
            i = len(self.ops)
            self.ops.append(op)
            self.args.append(args)
            self._memo[memo_key] = i
        return i

    def leaf(self, key: Hashable) -> Sym:
        """An input scalar, identified by ``key`` (its value is given to :meth:`emit`)."""
        i = self._new("leaf", (), ("leaf", key))
        self.keys[i] = key
        return Sym(self, i)

    def _id(self, a) -> int:
        if isinstance(a, Sym):
            if a.prog is not self:
                raise ValueError("Sym from another Program")
            return a.id
        if _is_num(a):
            v = float(a)
            i = self._new("const", (), ("const", v))
            self.const[i] = v
            return i
        raise TypeError(
            f"a symbolic program cannot take a {type(a).__name__} operand; "
            "only Sym and Python numbers"
        )

    def unary(self, op: str, a):
        if _is_num(a):
            return {
                "neg": lambda v: -v,
                "sin": math.sin,
                "cos": math.cos,
                "sqrt": math.sqrt,
                "rsqrt": lambda v: 1.0 / math.sqrt(v),
            }[op](float(a))
        ia = self._id(a)
        if op == "neg" and self.ops[ia] == "neg":
            return Sym(self, self.args[ia][0])
        return Sym(self, self._new(op, (ia,), (op, ia)))

    def binary(self, op: str, a, b):
        na, nb = _is_num(a), _is_num(b)
        if na and nb:
            a, b = float(a), float(b)
            return {"add": a + b, "sub": a - b, "mul": a * b, "div": a / b}[op]
        if op == "add":
            if na and a == 0:
                return b
            if nb and b == 0:
                return a
        elif op == "sub":
            if nb and b == 0:
                return a
            if na and a == 0:
                return self.unary("neg", b)
        elif op == "mul":
            for x, y, nx in ((a, b, na), (b, a, nb)):
                if nx and x == 0:
                    return 0.0
                if nx and x == 1:
                    return y
                if nx and x == -1:
                    return self.unary("neg", y)
        elif op == "div":
            if nb and b == 1:
                return a
            if na and a == 0:
                return 0.0
        ia, ib = self._id(a), self._id(b)
        key = (op, *sorted((ia, ib))) if op in _COMMUTATIVE else (op, ia, ib)
        args = (ia, ib) if op not in _COMMUTATIVE else tuple(sorted((ia, ib)))
        return Sym(self, self._new(op, args, key))

    # ------------------------------------------------------------ scheduling
    def schedule(self, outputs: Sequence, *, share: int = 2, max_tree: int = 400):
        """Materialisation and layers of the nodes the outputs need (module docstring).

        Returns (order, layer, mat): live node ids in topological order, the layer of each
        materialised node (dict), and the set of materialised ids."""
        out_ids = [o.id for o in outputs if isinstance(o, Sym)]
        live = set()
        stack = list(out_ids)
        while stack:
            i = stack.pop()
            if i in live:
                continue
            live.add(i)
            stack.extend(self.args[i])
        order = sorted(live)
        uses = dict.fromkeys(order, 0)
        for i in order:
            for j in self.args[i]:
                uses[j] += 1
        for i in out_ids:
            uses[i] += 1
        cost: dict[int, int] = {}
        need: dict[int, int] = {}
        layer: dict[int, int] = {}
        mat: set[int] = set()
        for i in order:
            op = self.ops[i]
            if op in ("leaf", "const"):
                cost[i], need[i] = 0, 0
                continue
            ch = self.args[i]
            c = _WEIGHT[op] + sum(cost[j] for j in ch)
            v = max((layer[j] if j in mat else need[j]) for j in ch)
            if (uses[i] >= 2 and (c > share or op in _EXPENSIVE)) or c > max_tree:
                mat.add(i)
                layer[i] = v + 1
                cost[i] = 0
            else:
                cost[i] = c
                need[i] = v
        return order, layer, mat

    def n_layers(self, outputs: Sequence, **kw) -> int:
        """How many layers (kernels, besides the output stack) :meth:`emit` would use."""
        _, layer, _ = self.schedule(outputs, **kw)
        return max(layer.values(), default=0)

    # ------------------------------------------------------------ emission
    def emit(
        self,
        outputs: Sequence,
        values: Callable[[Hashable], object],
        *,
        share: int = 2,
        max_tree: int = 400,
        barrier: bool = True,
    ) -> jax.Array:
        """The outputs as one JAX array of shape (len(outputs), *batch).

        ``values(key)`` gives the JAX value of each leaf (called once per leaf): scalars, or
        arrays of one common shape ``batch`` (every operation is elementwise, so a trailing
        batch needs no vmap; each layer is then one kernel over the batch, which XLA
        vectorises along the batch)."""
        _, layer, mat = self.schedule(outputs, share=share, max_tree=max_tree)
        n_layers = max(layer.values(), default=0)
        by_layer: list[list[int]] = [[] for _ in range(n_layers + 1)]
        for i in sorted(mat):
            by_layer[layer[i]].append(i)
        leaf_val: dict[int, object] = {}
        stored: dict[int, object] = {}  # materialised id -> JAX scalar (slice of its layer)

        def build(root_ids: Iterable[int]):
            memo: dict[int, object] = {}

            def ex(i: int, top: bool = False):
                if not top and i in stored:
                    return stored[i]
                if i in memo:
                    return memo[i]
                op = self.ops[i]
                if op == "leaf":
                    if i not in leaf_val:
                        leaf_val[i] = values(self.keys[i])
                    r = leaf_val[i]
                elif op == "const":
                    r = self.const[i]
                else:
                    a = [ex(j) for j in self.args[i]]
                    r = _apply(op, a)
                memo[i] = r
                return r

            return [ex(i, top=True) for i in root_ids]

        for ids in by_layer[1:]:
            vec, depth = _stack(build(ids))
            if barrier:
                vec = jax.lax.optimization_barrier(vec)
            for k, i in enumerate(ids):
                stored[i] = vec[_index(k, depth)]
        outs = []
        for o in outputs:
            if isinstance(o, Sym):
                outs.append(stored[o.id] if o.id in stored else build([o.id])[0])
            else:
                outs.append(float(o))
        vec, depth = _stack(outs)
        return _flat(vec, depth)[: len(outs)]


_FAN = 8  # XLA on CPU fuses a concatenate of at most 8 operands


def _stack(vals: list):
    """The scalars (or equally shaped arrays: a trailing batch) as one array, stacked in a
    tree of at most 8 per level, shape (…, 8, k, *batch), so that XLA fuses the whole layer
    into one kernel; returns (array, number of stacking dimensions)."""
    vals = [jnp.asarray(v, dtype=float) for v in vals]
    shape = jnp.broadcast_shapes(*(v.shape for v in vals))
    vals = [jnp.broadcast_to(v, shape) for v in vals]
    depth = 1
    rows = vals
    while True:
        if len(rows) <= _FAN:
            return jnp.stack(rows), depth
        pad = jnp.zeros_like(rows[0])
        rows = rows + [pad] * (-len(rows) % _FAN)
        rows = [jnp.stack(rows[k : k + _FAN]) for k in range(0, len(rows), _FAN)]
        depth += 1


def _flat(vec, depth: int):
    return vec.reshape((-1,) + vec.shape[depth:])


def _index(k: int, depth: int) -> tuple:
    """Index of the k-th stacked scalar in a stack tree of ``depth`` levels (see _stack)."""
    idx = []
    for _ in range(depth - 1):
        idx.append(k % _FAN)
        k //= _FAN
    idx.append(k)
    return tuple(reversed(idx))


def _apply(op: str, a: list):
    if op == "add":
        return a[0] + a[1]
    if op == "sub":
        return a[0] - a[1]
    if op == "mul":
        return a[0] * a[1]
    if op == "div":
        return a[0] / a[1]
    if op == "neg":
        return -a[0]
    if op == "sin":
        return fastmath.sin(a[0])
    if op == "cos":
        return fastmath.cos(a[0])
    if op == "sqrt":
        return jnp.sqrt(a[0])
    if op == "rsqrt":
        return jax.lax.rsqrt(a[0])
    raise ValueError(op)


# --------------------------------------------------------------------------- small SPD solve
def _adjugate(P: list) -> tuple[list, Any]:
    """Adjugate and determinant of a symmetric 1×1, 2×2 or 3×3 block (lists of scalars)."""
    b = len(P)
    if b == 1:
        return [[1.0]], P[0][0]
    if b == 2:
        (p00, p01), (_, p11) = P
        return [[p11, -p01], [-p01, p00]], p00 * p11 - p01 * p01
    if b == 3:
        (p00, p01, p02), (_, p11, p12), (_, _, p22) = P
        c00, c01, c02 = p11 * p22 - p12 * p12, p02 * p12 - p01 * p22, p01 * p12 - p02 * p11
        c11, c12, c22 = p00 * p22 - p02 * p02, p01 * p02 - p00 * p12, p00 * p11 - p01 * p01
        return (
            [[c00, c01, c02], [c01, c11, c12], [c02, c12, c22]],
            p00 * c00 + p01 * c01 + p02 * c02,
        )
    raise ValueError(f"block size {b} not in 1..3")


def _matvec(M: list, v: list) -> list:
    out = []
    for row in M:
        t = 0.0
        for m, x in zip(row, v, strict=False):
            t = t + m * x
        out.append(t)
    return out


def solve_spd(A: Sequence[Sequence], b: Sequence, block: int = 3) -> list:
    """y with A y = b for a small symmetric positive-definite A (lists of Sym or numbers;
    only the upper triangle is read) by block LDLᵀ elimination with pivot blocks of size
    ``block`` (≤ 3) inverted in closed form, P⁻¹ = adj(P)/det(P):

        forward, k = 1…K:   r_k = 1/det(S_kk),   S_ij ← S_ij − S_ik adj(S_kk) S_kj r_k,
                            b_i ← b_i − S_ik adj(S_kk) b_k r_k        (i, j > k),
        back, k = K…1:      y_k = adj(S_kk) (b_k − Σ_{j>k} S_kj y_j) r_k.

    Pivot blocks of a positive-definite matrix are positive definite, so no pivoting is
    needed. Its sequential depth is two layers per block step (the reciprocal, then the
    update), against two per column for an unrolled Cholesky."""
    n = len(b)
    if not 1 <= block <= 3:
        raise ValueError(f"block must be 1, 2 or 3; got {block}")
    S = [[A[min(i, j)][max(i, j)] for j in range(n)] for i in range(n)]
    f = list(b)
    blocks = [list(range(k, min(k + block, n))) for k in range(0, n, block)]
    inv_parts = []
    for kb, K in enumerate(blocks):
        adj, det = _adjugate([[S[i][j] for j in K] for i in K])
        r = 1.0 / det
        inv_parts.append((adj, r))
        rest = [i for blk in blocks[kb + 1 :] for i in blk]
        # G = adj(S_KK) S_K,rest and g = adj(S_KK) f_K (shared by every update below)
        G = {j: _matvec(adj, [S[i][j] for i in K]) for j in rest}
        g = _matvec(adj, [f[i] for i in K])
        for ii, i in enumerate(rest):
            for j in rest[ii:]:
                t = 0.0
                for e, k in enumerate(K):
                    t = t + S[i][k] * G[j][e]
                S[i][j] = S[i][j] - t * r
                S[j][i] = S[i][j]
            t = 0.0
            for e, k in enumerate(K):
                t = t + S[i][k] * g[e]
            f[i] = f[i] - t * r
    y = [0.0] * n
    for kb in reversed(range(len(blocks))):
        K = blocks[kb]
        adj, r = inv_parts[kb]
        later = [j for blk in blocks[kb + 1 :] for j in blk]
        rhs = []
        for i in K:
            t = f[i]
            for j in later:
                t = t - S[i][j] * y[j]
            rhs.append(t)
        for i, v in zip(K, _matvec(adj, rhs), strict=False):
            y[i] = v * r
    return y
