"""A batch of simulations (one per candidate parameter vector) run as equal chunks on the
CPU's cores.

Why. XLA on CPU runs one call of a batched simulation (a ``scan`` over samples, ``vmap``
over candidates) on one core; JAX releases the GIL while it runs. Cutting the batch into
equal chunks, each padded to one shape (so one compiled program serves them all), and
running the chunks on threads uses every core. Measured on this project's 2-core AMD EPYC
(the two-link split's finite-difference Jacobian, 23 candidates × 25 segments of 3 s): one
call 4.2 s, two chunks of 12 on two threads 1.8 s; each candidate's results are the same
to the last bit (the batch is elementwise over candidates). The fit engines use it:
:mod:`~flexarm.identification.time_domain.general` (the general engine's candidates) and
:mod:`~flexarm.identification.time_domain.objective` (the servo rig engine's).

The fits' own small dense linear algebra is the opposite case: NumPy / SciPy hand each
call to OpenBLAS, whose default pool of one thread per core costs more in hand-offs than
it gains on matrices this small, and several times more when the cores are busy. The
servo rig's estimates stage (:mod:`~flexarm.identification.time_domain.estimates`: a
least-squares fit per lag of a model discretised by a 4 × 4 ``expm`` per evaluation) took
10.9 s on OpenBLAS's two threads and 3.2 s on one, on the rotary rig's hard session of
4/27 (two 10 s logs). :func:`one_blas_thread` runs a function on one BLAS thread
(``threadpoolctl``). The fit's later stages are left on the default pool: on one thread
they gained 2-3 s more but their least squares took other paths (one thread sums in
another order), and unit 7's held-out figures moved by up to 0.8 points.

**Very large batches in chunks, on an executor** (issue #43: the protocol defined here, low,
so that nothing below :mod:`flexarm.distributed` imports it). A :class:`BatchExecutor` is
anything with ``map_chunks(fn, args, *, shared, retries, workers) -> list``
(``[fn(*a, **shared) for a in args]`` in order, wherever it runs them);
:class:`flexarm.distributed.DaskExecutor` is the Dask one, ``None`` runs in-process. The
batch's callers take it as ``client=`` (:func:`flexarm.sim.sampled.simulate_batch`,
:func:`flexarm.design.compare.compare`, :func:`flexarm.design.tune.design_tune`); the CLI or
:mod:`flexarm.distributed` wires a Dask client in. The N rollouts are split into chunks of
:attr:`ChunkOptions.chunk`, fixed by N and the chunk size only (never by the number of
workers); each chunk is one ``vmap`` batch in one task, and only reductions come back
(:class:`BatchSummary`; the trajectories only with :attr:`ChunkOptions.trajectories`).
Chunk j of a lazily drawn batch draws with :func:`chunk_seed` (seed, j). So a chunked
result is the same, bit for bit, in-process and on any number of workers.
:func:`stack_loops` stacks prepared loops of one structure into one batched loop.
"""

from __future__ import annotations

import functools
import os
import warnings
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any, ParamSpec, Protocol, TypeVar, runtime_checkable

import numpy as np
from threadpoolctl import threadpool_limits

__all__ = [
    "THREADS_ENV",
    "BatchExecutor",
    "BatchSummary",
    "ChunkOptions",
    "as_executor",
    "chunk_bounds",
    "chunk_seed",
    "cpu_cores",
    "map_chunks",
    "one_blas_thread",
    "rollout_summary",
    "run_chunks",
    "simulate_chunked",
    "stack_loops",
]

T = TypeVar("T")
R = TypeVar("R")
P = ParamSpec("P")

#: The environment variable that caps the threads a batch is shared over: a local Dask
#: cluster's workers get 1 (:func:`flexarm.distributed.worker_environment`: one worker per
#: core, one thread each); unset, every core this process may use.
THREADS_ENV = "FLEXARM_THREADS"


def cpu_cores() -> int:
    """The threads a batch is shared over: ``$FLEXARM_THREADS`` where it is set, else the
    CPU cores this process may use (its affinity mask where the OS has one)."""
    given = os.environ.get(THREADS_ENV, "").strip()
    if given:
        if not given.isdigit() or int(given) < 1:
            raise ValueError(
                f"${THREADS_ENV} = {given!r}: give a whole number of threads >= 1, or unset "
                "it to use every core"
            )
        return int(given)
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not Linux
        return max(1, os.cpu_count() or 1)


def run_chunks(fn: Callable[[T], R], chunks: Sequence[T], threads: int) -> list[R]:
    """``[fn(c) for c in chunks]``, on at most ``threads`` threads at once (in order)."""
    if threads <= 1 or len(chunks) <= 1:
        return [fn(c) for c in chunks]
    with ThreadPoolExecutor(min(threads, len(chunks))) as pool:
        return list(pool.map(fn, chunks))


def one_blas_thread(fn: Callable[P, R]) -> Callable[P, R]:
    """``fn`` run with NumPy's and SciPy's BLAS on one thread (module docstring), the
    limit lifted on return (and on an exception). OpenBLAS lets only one Python thread set
    its pool at a time: called from another thread while one holds the limit, ``fn`` runs
    on the pool as it is, so its results may differ in round-off (enough to move a
    stick-slip fit's path, module docstring)."""

    @functools.wraps(fn)
    def inner(*args: P.args, **kwargs: P.kwargs) -> R:
        with threadpool_limits(limits=1, user_api="blas"):
            return fn(*args, **kwargs)

    return inner


def stack_loops(loops: list):
    """Prepared loops of one structure (e.g. one scenario with different numbers) stacked
    leaf by leaf into one batched loop (leading axis: the loop), for one ``vmap``-ed run."""
    import jax
    import jax.numpy as jnp

    try:
        return jax.tree.map(lambda *a: jnp.stack([jnp.asarray(x) for x in a]), *loops)
    except ValueError as exc:
        raise ValueError(
            "the free parameters change the structure of the loop (e.g. a "
            "friction model, a filter switched on or off), which cannot be "
            f"batched: {exc}"
        ) from None


# =============================================================================== executors
@runtime_checkable
class BatchExecutor(Protocol):
    """Where the chunks of a batch run (module docstring): ``map_chunks(fn, args, *,
    shared, retries, workers)`` returns ``[fn(*a, **shared) for a in args]`` in the order of
    ``args`` (``shared`` sent once to every worker; ``retries`` of a task that raised;
    ``workers``: only these worker addresses, None: any).
    :class:`flexarm.distributed.DaskExecutor` runs them on a Dask client."""

    def map_chunks(
        self,
        fn: Callable,
        args: Sequence[tuple],
        *,
        shared: Mapping[str, Any] | None = None,
        retries: int = 1,
        workers: Sequence[str] | None = None,
    ) -> list: ...


def as_executor(executor: Any) -> BatchExecutor | None:
    """``executor`` checked: None (in-process) or a :class:`BatchExecutor`; anything else
    (e.g. a bare Dask client) is refused with the fix."""
    if executor is None or isinstance(executor, BatchExecutor):
        return executor
    raise TypeError(
        f"client = {type(executor).__name__}: give a BatchExecutor (an object with "
        "map_chunks; flexarm.distributed.DaskExecutor(client) wraps a Dask client) or None "
        "to run in-process"
    )


def map_chunks(
    fn: Callable,
    args: Sequence[tuple],
    executor: BatchExecutor | None = None,
    *,
    shared: Mapping[str, Any] | None = None,
    retries: int = 1,
    workers: Sequence[str] | None = None,
) -> list:
    """``[fn(*a, **shared) for a in args]``: in-process (``executor`` None) or on the
    executor's workers (:meth:`BatchExecutor.map_chunks`), in the order of ``args``."""
    ex = as_executor(executor)
    if ex is None:
        sh = dict(shared or {})
        return [fn(*a, **sh) for a in args]
    return ex.map_chunks(fn, args, shared=shared, retries=retries, workers=workers)


# =============================================================================== chunks
def chunk_bounds(n: int, chunk: int) -> list[tuple[int, int]]:
    """[a, b) of each chunk of at most ``chunk`` of n items, in order."""
    if chunk < 1:
        raise ValueError(f"chunk = {chunk}: give a chunk size >= 1")
    return [(a, min(a + chunk, n)) for a in range(0, n, chunk)]


def chunk_seed(seed: int, j: int) -> int:
    """The seed of chunk j of a batch drawn with ``seed``: ``SeedSequence([seed, j])``'s
    first 32-bit word (independent streams per chunk, the same on every worker)."""
    return int(np.random.SeedSequence([int(seed), int(j)]).generate_state(1)[0])


@dataclass(frozen=True)
class ChunkOptions:
    """``chunk``: plants (rollouts) per chunk, one vmap batch in one task; ``trajectories``:
    bring the trajectories back too (large: N × samples × signals); ``quantiles`` of the
    per-plant reductions; ``retries`` of a chunk that raised; ``workers``: run the chunks
    on these worker addresses only (e.g. the GPU workers; None: any)."""

    chunk: int = 2000
    trajectories: bool = False
    quantiles: tuple[float, ...] = (0.05, 0.5, 0.95)
    retries: int = 1
    workers: tuple[str, ...] | None = None


@dataclass
class BatchSummary:
    """What comes back from a chunked batch: ``per_rollout`` name → (N, ...) reductions
    (:func:`rollout_summary` or the caller's ``reduce``), ``quantiles`` name → {q: value
    over the finite rollouts}, ``unstable`` (rollouts that diverged), ``chunks``, and the
    trajectories (as :func:`~flexarm.sim.sampled.simulate_batch` returns them) only when
    asked for."""

    per_rollout: dict[str, np.ndarray]
    quantiles: dict[str, dict[float, np.ndarray]]
    unstable: int
    chunks: int
    trajectories: dict[str, Any] | None = None


def rollout_summary(out: dict, limit: float = 1e6) -> dict[str, np.ndarray]:
    """Per rollout of a batch's output: ``diverged`` (non-finite or beyond ±``limit`` SI,
    :data:`flexarm.sim.sampled.DIVERGENCE_LIMIT`), ``final_signals`` (B, p),
    ``peak_abs_signals`` (B, p), ``rms_signals`` (B, p), ``peak_abs_command`` (B, m)."""
    s = np.asarray(out["signals"])
    u = np.asarray(out["command"])
    with np.errstate(invalid="ignore", over="ignore"):
        return {
            "diverged": ~np.all(np.isfinite(s) & (np.abs(s) <= limit), axis=(1, 2)),
            "final_signals": s[:, -1, :],
            "peak_abs_signals": np.max(np.abs(s), axis=1),
            "rms_signals": np.sqrt(np.mean(s**2, axis=1)),
            "peak_abs_command": np.max(np.abs(u), axis=1),
        }


def _batched_leaves(loop, in_axes):
    """The loop's leaves, each one's batch axis (None: shared), the tree and the size."""
    import equinox as eqx
    import jax

    def is_none(x):
        return x is None

    leaves, treedef = jax.tree.flatten(loop, is_leaf=is_none)
    axes = jax.tree.leaves(jax.tree.broadcast(in_axes, loop, is_leaf=is_none), is_leaf=is_none)
    axes = [
        a if a is not None and eqx.is_array(x) else None for x, a in zip(leaves, axes, strict=False)
    ]
    sizes = {int(x.shape[a]) for x, a in zip(leaves, axes, strict=False) if a is not None}
    if len(sizes) != 1:
        raise ValueError(
            f"the loop's batched leaves disagree on the batch size: {sorted(sizes)}"
            if sizes
            else "in_axes batches no leaf of the loop"
        )
    return leaves, axes, treedef, sizes.pop()


def _loop_chunk(leaves, axes, treedef, a: int, b: int):
    import jax

    return jax.tree.unflatten(
        treedef,
        [
            x if ax is None else np.take(np.asarray(x), np.arange(a, b), axis=ax)
            for x, ax in zip(leaves, axes, strict=False)
        ],
    )


def _simulate_chunk(
    loop, *, run, x0, references, n_samples, seed, in_axes, batch_size, reduce, trajectories
):
    # the batch itself, no chunks: the arrays
    out = run(
        loop,
        x0,
        references,
        n_samples,
        seed=seed,
        in_axes=in_axes,
        batch_size=batch_size,
        check=False,
    )
    red = reduce(out)
    return red, (out if trajectories else None)


def simulate_chunked(
    run: Callable[..., Any],
    loop,
    x0,
    references: dict[str, Any],
    n_samples: int,
    *,
    seed: int = 0,
    in_axes: Any = 0,
    batch_size: int | None = 512,
    executor: BatchExecutor | None = None,
    options: ChunkOptions | None = None,
    reduce: Callable[[dict], dict[str, np.ndarray]] | None = None,
    limit: float = 1e6,
) -> BatchSummary:
    """``run`` (:func:`~flexarm.sim.sampled.simulate_batch`, which calls this with
    ``client=`` or ``chunks=``) over chunks of ``options.chunk`` rollouts (the batched
    leaves of ``loop`` sliced), each chunk a task on ``executor`` (None: in-process), only
    ``reduce(out)`` (default :func:`rollout_summary` with ``limit``; a picklable function
    returning per-rollout arrays) coming back; the sensor noise's ``seed`` is the batch's in
    every chunk, so the result equals the unchunked batch's reductions. Diverged rollouts
    are counted, not raised."""
    o = options or ChunkOptions()
    leaves, axes, treedef, size = _batched_leaves(loop, in_axes)
    bounds = chunk_bounds(size, o.chunk)
    refs = {k: np.asarray(v) for k, v in references.items()}
    args = [(_loop_chunk(leaves, axes, treedef, a, b),) for a, b in bounds]
    parts = map_chunks(
        _simulate_chunk,
        args,
        executor,
        retries=o.retries,
        workers=o.workers,
        shared=dict(
            run=run,
            x0=np.asarray(x0, float),
            references=refs,
            n_samples=int(n_samples),
            seed=int(seed),
            in_axes=in_axes,
            batch_size=batch_size,
            reduce=reduce or functools.partial(rollout_summary, limit=float(limit)),
            trajectories=o.trajectories,
        ),
    )
    per = {k: np.concatenate([p[0][k] for p in parts]) for k in parts[0][0]}
    traj = None
    if o.trajectories:
        outs = [p[1] for p in parts]
        traj = {k: np.concatenate([d[k] for d in outs]) for k in outs[0] if k != "references"}
        traj["references"] = outs[0]["references"]
    bad = np.asarray(per.get("diverged", np.zeros(size, bool)), bool)
    return BatchSummary(per, quantiles(per, bad, o.quantiles), int(bad.sum()), len(bounds), traj)


def quantiles(
    per: dict[str, np.ndarray], bad: np.ndarray, qs: Sequence[float]
) -> dict[str, dict[float, np.ndarray]]:
    """name → {q: the q-quantile over the rollouts not ``bad``} of each per-rollout array
    (the flags and scalars left out)."""
    out = {}
    for k, v in per.items():
        v = np.asarray(v)
        if k == "diverged" or v.dtype == bool or v.ndim == 0:
            continue
        good = v[~bad] if v.shape[0] == bad.shape[0] else v
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            out[k] = {
                float(q): (
                    np.nanquantile(good.astype(float), q, axis=0)
                    if good.size
                    else np.full(v.shape[1:], np.nan)
                )
                for q in qs
            }
    return out
