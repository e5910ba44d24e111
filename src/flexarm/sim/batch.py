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
"""

from __future__ import annotations

import functools
import os
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import ParamSpec, TypeVar

from threadpoolctl import threadpool_limits

__all__ = ["THREADS_ENV", "cpu_cores", "one_blas_thread", "run_chunks"]

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
