"""Beyond one machine: many fits and very large plant batches on Dask (issue #27).

The engine is ``dask.distributed`` (the optional extra ``pip install flexarm[distributed]``):
the local machine by default, the same code on an existing scheduler (``tcp://host:8786``)
or on a SLURM / PBS cluster through ``dask-jobqueue`` (docs/distributed.md). Without Dask
everything runs in-process, and :func:`client_for` says so.

**The client** (:func:`client_for`, :func:`session`): ``scheduler=None, workers=None``: no
client, in-process; ``workers=N``: a ``LocalCluster`` of N *spawned* (not forked) worker
processes, one thread each, on the loopback; ``scheduler="tcp://host:8786"``: that
scheduler's workers. Every worker gets :class:`JaxWorkerSetup` (a worker plugin, so that a
worker restarted after a crash gets it too): float64 and, where ``$FLEXARM_JAX_CACHE``
names a folder (one per machine; the CLI uses the same), JAX's persistent compilation cache,
so a loop compiles once per machine and the other workers load it. The cache is opt-in
(:data:`CACHE_NOTE`). A local cluster's workers start with the
environment of :func:`worker_environment`: one XLA / BLAS thread each
(``XLA_FLAGS=--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1``,
``OMP_NUM_THREADS=1``, ``FLEXARM_THREADS=1`` ...), and on a GPU no preallocation
(``XLA_PYTHON_CLIENT_PREALLOCATE=false``, ``XLA_PYTHON_CLIENT_MEM_FRACTION`` when set in
:class:`ClusterOptions`); the nanny restarts a worker above its ``memory_limit``
(``"auto"``: the machine's memory / workers).

**Large plant batches** (:func:`flexarm.sim.batch.simulate_chunked`,
:func:`flexarm.design.compare.compare_chunked`,
:class:`flexarm.design.tune.ChunkedTuneCost`, re-exported here; entered from
:func:`flexarm.sim.sampled.simulate_batch`, :func:`flexarm.design.compare.compare` and
:func:`flexarm.design.tune.design_tune` with ``client=`` an executor,
:class:`flexarm.sim.batch.BatchExecutor`: :class:`DaskExecutor` here, :func:`executor` wraps
a Dask client): the N plants are split into chunks of ``ChunkOptions.chunk`` plants, fixed
by N and the chunk size only (never by the number of workers); each chunk is one ``vmap``
batch on one worker, and only reductions come back (per-plant metrics, their quantiles, the
unstable count; trajectories only with ``ChunkOptions.trajectories``): 10^6 plants never
gather 10^6 trajectories. Seeds per chunk: chunk j of a lazily drawn batch
(:class:`PlantSource`) draws its plants with the seed :func:`chunk_seed` (seed, j)
(``numpy.random.SeedSequence([seed, j])``), the sensor noise keeps the batch's seed (one
noise sequence shared by every rollout, as in :func:`~flexarm.sim.sampled.simulate_batch`).
So the result is the same, bit for bit, in-process (``client=None``) and on 1 or 2 or any
number of workers: the same chunks run the same compiled code on the same machine.

**Many fits** (:func:`read_manifest`, :func:`fit_many`): one fit per manifest row, each fit
one task; under ``DIR/<row id>/``: ``fit.json`` (the fit's JSON, written last, atomically:
its presence marks the row finished), ``fitted.toml`` (the fitted scenario), ``plots/``
(overlay figures); and ``DIR/summary.csv``, one line per row. A rerun skips finished rows
and retries failed ones; a failing row is reported (``status = failed``, ``error``) and
does not stop the others; a worker killed under a task is replaced by its nanny and the
task rerun (Dask's ``allowed-failures``; ``retries=`` for exceptions).

The manifest (CSV, one header line; ``#`` lines are comments; paths resolve against the
manifest's folder; lists are ``;``-separated):

* ``id``: the row's name and output folder (letters, digits, ``._-``);
* ``preset``: ``servo_rig``, the data-sheet fit of a single-link servo rig (the one fit,
  :func:`flexarm.identification.fit`, with ``presets.servo_rig``; the default without
  ``scenario``);
* ``scenario``: a scenario (TOML path or built-in name) for the one fit of its free list;
* ``logs``: the run's log files (one session), ``a.txt;b.txt``;
* ``log_format``: the logger's log-format TOML (columns, units, gains);
* ``window``: the fit window ``START:STOP`` (s from each log's first sample);
* ``validate_window``: a held-out window ``START:STOP`` predicted after the fit (the one
  prediction of the fitted result, every row);
* ``sessions``: servo rig, a session index per log, ``0;0;1`` (default one session);
* ``free``: general fit, the free parameters (paths into the scenario);
* the servo rig's data sheet (SI): ``drive`` (``voltage`` or ``current``), ``gear_ratio``
  K_g, ``motor_constant`` K_m (V·s/rad or N·m/A), ``armature_resistance`` R (Ω),
  ``link_length`` L (m), ``voltage_limit`` (V), ``computation_delay`` (samples),
  ``tip_sign`` (+1 or -1 when known), ``encoder_counts`` (per revolution when known);
* ``options``: further fit keywords, ``key=value;...`` (e.g. ``seed=0;popsize=8``): a
  servo rig row's go to its engine; a scenario row's are the fit options' field names
  (``max_nfev``, ``segment``, ``residual_level``, ``global_stage``, ...), each to its
  group of :class:`~flexarm.identification.time_domain.options.FitOptions`
  (``FitOptions.from_fields``), over the preset's options when the row lists no free
  parameters.

Empty cells take the fit's defaults. ``summary.csv``: ``id, status, seconds, error,
n_warnings, warnings``, then per parameter ``<name>`` and ``<name>_std``, and per log and
signal ``fit%:<log>:<signal>`` (and ``held-out%:<log>:<signal>`` with a validate window).

Layering: this module is the orchestration layer between reproduce and the CLI (issue
#43): nothing below imports it. The batches below take an executor through the protocol
defined low (:class:`flexarm.sim.batch.BatchExecutor`); this module provides the Dask one
(:class:`DaskExecutor`), and the CLI wires it in (:func:`executor`).
"""

from __future__ import annotations

import csv
import dataclasses
import json
import math
import os
import re
import time as _time
import warnings as _warnings
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from flexarm.errors import FlexarmError
from flexarm.sim import batch as _batch
from flexarm.sim.batch import (  # the chunked batches' pieces, defined low (issue #43)
    THREADS_ENV,
    BatchExecutor,
    BatchSummary,
    ChunkOptions,
    chunk_bounds,
    chunk_seed,
)

__all__ = [
    "client_for",
    "fit_many_todo",
    "session",
    "close",
    "have_dask",
    "ClusterOptions",
    "ChunkOptions",
    "JaxWorkerSetup",
    "compilation_cache_dir",
    "worker_environment",
    "chunk_bounds",
    "chunk_seed",
    "map_chunks",
    "BatchExecutor",
    "DaskExecutor",
    "executor",
    "simulate_chunked",
    "BatchSummary",
    "compare_chunked",
    "FitRow",
    "read_manifest",
    "fit_row",
    "fit_many",
    "FitManyOptions",
    "ManifestError",
    "ClusterError",
]


# =============================================================================== the client
def have_dask() -> bool:
    """True when ``dask.distributed`` can be imported."""
    try:
        import distributed  # noqa: F401 - only whether it imports
    except ImportError:
        return False
    return True


NO_DASK = (
    "dask.distributed is not installed (pip install 'flexarm[distributed]'): running in-process"
)


#: why the persistent compilation cache is opt-in (docs/distributed.md says the same)
CACHE_NOTE = (
    "JAX's persistent compilation cache is off unless FLEXARM_JAX_CACHE names a "
    "folder: with jaxlib 0.10.2 on the CPU, writing some of flexarm's compiled "
    "loops to it aborts the process (XLA's executable serialisation, seen on the "
    "two-link LQG replay), which no Python code can catch"
)


def compilation_cache_dir() -> Path | None:
    """JAX's persistent compilation cache folder: ``$FLEXARM_JAX_CACHE`` (one folder per
    machine, e.g. ``~/.cache/flexarm-jax``); None (no cache) when it is unset, empty,
    ``0`` or ``off`` (:data:`CACHE_NOTE`: why it is opt-in)."""
    value = os.environ.get("FLEXARM_JAX_CACHE", "").strip()
    if value.lower() in ("", "0", "off", "false", "no"):
        return None
    return Path(value).expanduser()


def enable_compilation_cache(
    cache_dir: str | Path | None = None, min_compile_seconds: float = 0.5
) -> bool:
    """Float64 on, and this process's JAX pointed at the persistent compilation cache
    ``cache_dir`` (default :func:`compilation_cache_dir`; compilations longer than
    ``min_compile_seconds`` are stored). Returns whether a cache is in use: none when no
    folder is given or configured (:data:`CACHE_NOTE`)."""
    import jax

    jax.config.update("jax_enable_x64", True)
    folder = cache_dir if cache_dir is not None else compilation_cache_dir()
    if folder is None:
        return False
    try:
        jax.config.update("jax_compilation_cache_dir", str(folder))
        jax.config.update("jax_persistent_cache_min_compile_time_secs", min_compile_seconds)
    except Exception:  # an old jax without the options: run uncached
        return False
    return True


@dataclass(frozen=True)
class ClusterOptions:
    """How a local cluster's workers run (:func:`client_for`).

    ``threads_per_worker``: 1 (a JAX loop is one thread; more workers, not threads);
    ``memory_limit``: per worker, bytes or ``"4GiB"``, ``"auto"`` = machine memory /
    workers (the nanny restarts a worker above 95 %); ``host``: the address the scheduler
    and workers listen on (loopback by default: nothing leaves the machine);
    ``dashboard_address``: None = no dashboard (``":8787"`` to get one); ``cache_dir``: the
    compilation cache (default :func:`compilation_cache_dir`: none unless
    ``$FLEXARM_JAX_CACHE`` names a folder, :data:`CACHE_NOTE`); ``xla_memory_fraction``:
    on a GPU, each worker's share of the device memory (``XLA_PYTHON_CLIENT_MEM_FRACTION``;
    None: JAX's default without preallocation)."""

    threads_per_worker: int = 1
    memory_limit: str | int | float = "auto"
    host: str = "127.0.0.1"
    dashboard_address: str | None = None
    cache_dir: str | None = None
    xla_memory_fraction: float | None = None


def worker_environment(options: ClusterOptions | None = None) -> dict[str, str]:
    """The environment a local cluster's worker processes start with (module doc)."""
    o = options or ClusterOptions()
    threads = str(max(1, int(o.threads_per_worker)))
    env = {
        "JAX_ENABLE_X64": "1",
        "XLA_FLAGS": (
            os.environ.get("XLA_FLAGS", "") + " --xla_cpu_multi_thread_eigen=false"
            f" intra_op_parallelism_threads={threads}"
        ).strip(),
        "OMP_NUM_THREADS": threads,
        "OPENBLAS_NUM_THREADS": threads,
        "MKL_NUM_THREADS": threads,
        THREADS_ENV: threads,  # flexarm's own batches (flexarm.sim.batch) too
        "XLA_PYTHON_CLIENT_PREALLOCATE": "false",
        "MPLBACKEND": "Agg",
    }
    cache = o.cache_dir or compilation_cache_dir()
    env["FLEXARM_JAX_CACHE"] = str(cache) if cache is not None else "off"
    if o.xla_memory_fraction is not None:
        env["XLA_PYTHON_CLIENT_MEM_FRACTION"] = f"{float(o.xla_memory_fraction):g}"
    return env


if TYPE_CHECKING:  # the checker sees the one base class (dask is in the lock)
    from distributed.diagnostics.plugin import WorkerPlugin as _PluginBase
else:
    try:  # the plugin's base class, where dask is installed
        from distributed.diagnostics.plugin import WorkerPlugin as _PluginBase
    except ImportError:  # pragma: no cover - without dask no worker runs it
        _PluginBase = object


class JaxWorkerSetup(_PluginBase):
    """A Dask worker plugin: float64 and the shared persistent compilation cache in every
    worker (also one restarted after a crash, or one of an existing scheduler)."""

    name = "flexarm-jax-setup"

    def __init__(self, cache_dir: str | None = None):
        cache = cache_dir or compilation_cache_dir()
        self.cache_dir = str(cache) if cache is not None else None

    def setup(self, worker=None):
        os.environ.setdefault("MPLBACKEND", "Agg")
        enable_compilation_cache(self.cache_dir)


class ClusterError(FlexarmError, ValueError):
    """A scheduler address or worker count that cannot be used (the message says which)."""


def client_for(
    scheduler: str | None = None, workers: int | None = None, options: ClusterOptions | None = None
):
    """A Dask client, or None (in-process).

    ``scheduler`` and ``workers`` both None: None, no Dask needed. ``workers=N``: a
    ``LocalCluster`` of N spawned worker processes (:class:`ClusterOptions`; :func:`close`
    closes both). ``scheduler="tcp://host:8786"``: a client of that scheduler. Without Dask
    installed a warning says so and None is returned (the caller runs in-process)."""
    if scheduler is not None and workers is not None:
        raise ClusterError(
            f"scheduler = {scheduler!r} and workers = {workers}: give one (an "
            "existing scheduler's address, or the number of local workers)"
        )
    if scheduler is None and workers is None:
        return None
    if not have_dask():
        _warnings.warn(NO_DASK, RuntimeWarning, stacklevel=2)
        return None
    import dask.config
    from distributed import Client, LocalCluster

    o = options or ClusterOptions()
    if workers is not None:
        if int(workers) < 1:
            raise ClusterError(f"workers = {workers}: give 1 or more local worker processes")
        with dask.config.set(
            {
                "distributed.worker.multiprocessing-method": "spawn",
                "distributed.scheduler.allowed-failures": 3,
            }
        ):
            cluster = LocalCluster(
                n_workers=int(workers),
                threads_per_worker=o.threads_per_worker,
                processes=True,
                host=o.host,
                # dask: None means no dashboard (annotated str only)
                dashboard_address=o.dashboard_address,  # pyright: ignore[reportArgumentType]
                memory_limit=o.memory_limit,
                env=worker_environment(o),
                # dask's scheduler starts its HTTP server on :8787 even without a dashboard
                # (dashboard_address None falls back to that port): bind it to a free port
                # on the loopback host instead, with no dashboard (issue #45)
                scheduler_kwargs=(
                    {"dashboard": False, "dashboard_address": f"{o.host}:0"}
                    if o.dashboard_address is None
                    else None
                ),
            )
        client = Client(cluster, set_as_default=False)
        # close() closes the cluster too (a flag of flexarm's on dask's Client)
        client._flexarm_owns_cluster = True  # pyright: ignore[reportAttributeAccessIssue]
    else:
        if not re.match(r"^[a-z]+://", str(scheduler)):
            raise ClusterError(
                f"scheduler = {scheduler!r}: give the scheduler's address with "
                "its protocol, e.g. tcp://host:8786"
            )
        client = Client(scheduler, set_as_default=False)
    client.register_plugin(JaxWorkerSetup(o.cache_dir))
    return client


def close(client) -> None:
    """Close a client of :func:`client_for` and the local cluster it started (None: no-op)."""
    if client is None:
        return
    cluster = (
        getattr(client, "cluster", None)
        if getattr(client, "_flexarm_owns_cluster", False)
        else None
    )
    client.close()
    if cluster is not None:
        cluster.close()


@contextmanager
def session(
    scheduler: str | None = None, workers: int | None = None, options: ClusterOptions | None = None
) -> Iterator[Any]:
    """:func:`client_for` as a context: yields the client (or None) and closes it (and the
    local cluster it started) on exit."""
    client = client_for(scheduler, workers, options)
    try:
        yield client
    finally:
        close(client)


# =============================================================================== chunks
class DaskExecutor:
    """The Dask :class:`~flexarm.sim.batch.BatchExecutor`: each chunk one task on the
    client's workers (``shared`` scattered once to every worker; ``workers``: only these
    addresses; ``retries`` of a task that raised), the results gathered in order. The
    batches (:func:`flexarm.sim.sampled.simulate_batch`, :func:`flexarm.design.compare.compare`,
    :func:`flexarm.design.tune.design_tune`) take it as ``client=``; they do not import this
    module (issue #43)."""

    def __init__(self, client):
        if client is None or not all(hasattr(client, m) for m in ("submit", "gather", "scatter")):
            raise TypeError(
                f"DaskExecutor({type(client).__name__}): give a dask.distributed Client "
                "(flexarm.distributed.client_for(workers=N) or session(...))"
            )
        self.client = client

    def __repr__(self) -> str:
        return f"DaskExecutor({self.client!r})"

    def map_chunks(
        self,
        fn: Callable,
        args: Sequence[tuple],
        *,
        shared: Mapping[str, Any] | None = None,
        retries: int = 1,
        workers: Sequence[str] | None = None,
    ) -> list:
        client = self.client
        shared = dict(shared or {})
        where = list(workers) if workers else None
        if shared:
            # scattered as a list: each value gets a key of its own (a dict would be keyed by
            # its names, 'seed', 'references', ..., shared with the next call's, whose
            # release then cancels this call's tasks: "lost dependencies")
            names = list(shared)
            futs = client.scatter(
                [shared[k] for k in names], broadcast=True, hash=False, workers=where
            )
            shared = dict(zip(names, futs, strict=True))
        futures = [
            client.submit(
                fn,
                *a,
                **shared,
                pure=False,
                retries=retries,
                workers=where,
                allow_other_workers=False,
            )
            for a in args
        ]
        return client.gather(futures)


def executor(client) -> BatchExecutor | None:
    """A batch's ``client=`` from what the user holds: None (in-process), a
    :class:`~flexarm.sim.batch.BatchExecutor` as it is, a Dask client wrapped in
    :class:`DaskExecutor`."""
    if client is None or isinstance(client, BatchExecutor):
        return client
    return DaskExecutor(client)


def map_chunks(
    fn: Callable,
    args: Sequence[tuple],
    client=None,
    *,
    retries: int = 1,
    shared: Mapping[str, Any] | None = None,
    workers: Sequence[str] | None = None,
) -> list:
    """``[fn(*a, **shared) for a in args]``, in-process (``client`` None) or as one task per
    item on the client's workers (a Dask client or a
    :class:`~flexarm.sim.batch.BatchExecutor`; :func:`flexarm.sim.batch.map_chunks`)."""
    return _batch.map_chunks(
        fn, args, executor(client), shared=shared, retries=retries, workers=workers
    )


def rollout_summary(out: dict) -> dict[str, np.ndarray]:
    """:func:`flexarm.sim.batch.rollout_summary` at the simulator's
    :data:`~flexarm.sim.sampled.DIVERGENCE_LIMIT`."""
    from flexarm.sim.sampled import DIVERGENCE_LIMIT

    return _batch.rollout_summary(out, DIVERGENCE_LIMIT)


def simulate_chunked(
    loop,
    x0,
    references: dict[str, Any],
    n_samples: int,
    *,
    seed: int = 0,
    in_axes: Any = 0,
    batch_size: int | None = 512,
    client=None,
    options: ChunkOptions | None = None,
    reduce: Callable[[dict], dict[str, np.ndarray]] | None = None,
) -> BatchSummary:
    """:func:`flexarm.sim.batch.simulate_chunked` of
    :func:`~flexarm.sim.sampled.simulate_batch` on ``client`` (a Dask client or a
    :class:`~flexarm.sim.batch.BatchExecutor`; None: in-process)."""
    from flexarm.sim.sampled import DIVERGENCE_LIMIT, simulate_batch

    return _batch.simulate_chunked(
        simulate_batch,
        loop,
        x0,
        references,
        n_samples,
        seed=seed,
        in_axes=in_axes,
        batch_size=batch_size,
        executor=executor(client),
        options=options,
        reduce=reduce,
        limit=DIVERGENCE_LIMIT,
    )


def compare_chunked(plants, designs=None, *, client=None, options=None, **kwargs):
    """:func:`flexarm.design.compare.compare_chunked` on ``client`` (a Dask client or a
    :class:`~flexarm.sim.batch.BatchExecutor`; None: in-process)."""
    from flexarm.design.compare import compare_chunked as _compare_chunked

    return _compare_chunked(plants, designs, client=executor(client), options=options, **kwargs)


def __getattr__(name: str):
    """The plant and tuning halves of the chunked batches, which moved down into design
    (issue #43), still importable from here: ``PlantSource``, ``ChunkedTuneCost``."""
    if name == "PlantSource":
        from flexarm.design.plants import PlantSource

        return PlantSource
    if name == "ChunkedTuneCost":
        from flexarm.design.tune import ChunkedTuneCost

        return ChunkedTuneCost
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


# =============================================================================== many fits
class ManifestError(FlexarmError, ValueError):
    """A manifest file or row that cannot be read (the message names the file, the row,
    the column, the value and the fix)."""


#: the manifest's columns (module doc), in order
COLUMNS = (
    "id",
    "preset",
    "scenario",
    "logs",
    "log_format",
    "window",
    "validate_window",
    "sessions",
    "free",
    "drive",
    "gear_ratio",
    "motor_constant",
    "armature_resistance",
    "link_length",
    "voltage_limit",
    "computation_delay",
    "tip_sign",
    "encoder_counts",
    "options",
)
_FLOAT = ("gear_ratio", "motor_constant", "armature_resistance", "link_length", "voltage_limit")
_INT = ("computation_delay", "tip_sign", "encoder_counts")
PRESETS = ("servo_rig",)


@dataclass(frozen=True)
class FitRow:
    """One manifest row, paths absolute (module doc for the columns)."""

    id: str
    logs: tuple[str, ...]
    preset: str | None = None
    scenario: str | None = None
    log_format: str | None = None
    window: tuple[float, float] | None = None
    validate_window: tuple[float, float] | None = None
    sessions: tuple[int, ...] | None = None
    free: tuple[str, ...] | None = None
    data_sheet: dict[str, Any] = field(default_factory=dict)
    options: dict[str, Any] = field(default_factory=dict)


def _where(path, line, col) -> str:
    return f"{path}: row {line}, column {col!r}"


def _window(text: str, where: str) -> tuple[float, float] | None:
    if not text:
        return None
    try:
        a, b = (float(x) for x in text.split(":"))
    except ValueError:
        raise ManifestError(
            f"{where} = {text!r}: expected START:STOP in seconds from the "
            "log's first sample, e.g. 0:5"
        ) from None
    if not (b > a >= 0):
        raise ManifestError(f"{where} = {text!r}: need 0 <= START < STOP (s)")
    return a, b


def option_value(text: str):
    """A manifest option's value: true/false, none, an int, a float, else the text."""
    t = text.strip()
    if t.lower() in ("true", "false"):
        return t.lower() == "true"
    if t.lower() in ("none", "null"):
        return None
    for convert in (int, float):
        try:
            return convert(t)
        except ValueError:
            pass
    return t


def _resolve(base: Path, p: str) -> str:
    q = Path(p).expanduser()
    return str(q if q.is_absolute() else (base / q).resolve())


def read_manifest(path: str | Path) -> list[FitRow]:
    """The manifest's rows (module doc), paths resolved against its folder; raises
    :class:`ManifestError` naming the file, row and column of what is wrong."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ManifestError(
            f"{path}: cannot read the manifest ({exc.strerror}); give a "
            "CSV file with the columns of flexarm.distributed"
        ) from None
    base = path.resolve().parent
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        raise ManifestError(
            f"{path}: no header line; the first line names the columns, "
            f"e.g. {','.join(COLUMNS[:6])}"
        )
    reader = csv.DictReader(lines)
    head = [h.strip() for h in (reader.fieldnames or [])]
    unknown = [h for h in head if h not in COLUMNS]
    if unknown:
        raise ManifestError(
            f"{path}: unknown column(s) {', '.join(map(repr, unknown))}; the "
            f"columns are {', '.join(COLUMNS)}"
        )
    for need in ("id", "logs"):
        if need not in head:
            raise ManifestError(f"{path}: no column {need!r}; every manifest has id and logs")
    rows, seen = [], set()
    for i, raw in enumerate(reader, start=2):
        r = {(k or "").strip(): (v or "").strip() for k, v in raw.items() if k is not None}
        rid = r.get("id", "")
        if not _safe_id(rid):
            raise ManifestError(
                f"{_where(path, i, 'id')} = {rid[:40]!r}: give a folder name of "
                "letters, digits, '.', '_' or '-' (not starting with '.' or '-', at most "
                "100 characters, not summary.csv)"
            )
        rid_key = rid.lower()  # Rig and rig are one folder on some file systems
        if rid_key in seen:
            raise ManifestError(
                f"{_where(path, i, 'id')} = {rid!r}: used by an earlier row; "
                "give each row its own id"
            )
        seen.add(rid_key)
        logs = tuple(_resolve(base, x.strip()) for x in r.get("logs", "").split(";") if x.strip())
        if not logs:
            raise ManifestError(
                f"{_where(path, i, 'logs')} is empty: give the run's log files, ';'-separated"
            )
        for lg in logs:
            if not Path(lg).is_file():
                raise ManifestError(
                    f"{_where(path, i, 'logs')}: {lg} is not a file; paths "
                    f"resolve against the manifest's folder {base}"
                )
        preset = r.get("preset") or None
        scen = r.get("scenario") or None
        if preset and scen:
            raise ManifestError(
                f"{_where(path, i, 'preset')} = {preset!r} and scenario = "
                f"{scen!r}: give one (a preset, or a scenario for the general "
                "fit)"
            )
        if not preset and not scen:
            preset = "servo_rig"
        if preset and preset not in PRESETS:
            raise ManifestError(
                f"{_where(path, i, 'preset')} = {preset!r}: choose "
                f"{', '.join(PRESETS)}, or give a scenario"
            )
        if scen:
            from flexarm.specs.scenario import names_a_scenario

            if Path(scen).suffix == ".toml" or not names_a_scenario(scen):
                scen = _resolve(base, scen)
        sheet: dict[str, Any] = {}
        for k in _FLOAT + _INT + ("drive",):
            v = r.get(k, "")
            if not v:
                continue
            try:
                sheet[k] = float(v) if k in _FLOAT else int(v) if k in _INT else v
            except ValueError:
                raise ManifestError(
                    f"{_where(path, i, k)} = {v!r}: expected a "
                    f"{'number' if k in _FLOAT else 'whole number'}"
                ) from None
        opts = {}
        for item in (x for x in r.get("options", "").split(";") if x.strip()):
            if "=" not in item:
                raise ManifestError(
                    f"{_where(path, i, 'options')}: {item!r} is not "
                    "key=value; e.g. seed=0;popsize=8"
                )
            k, v = item.split("=", 1)
            opts[k.strip()] = option_value(v)
        sess = None
        if r.get("sessions"):
            try:
                sess = tuple(int(x) for x in r["sessions"].split(";") if x.strip())
            except ValueError:
                raise ManifestError(
                    f"{_where(path, i, 'sessions')} = {r['sessions']!r}: "
                    "expected one whole number per log, e.g. 0;0;1"
                ) from None
            if len(sess) != len(logs):
                raise ManifestError(
                    f"{_where(path, i, 'sessions')} = {r['sessions']!r}: "
                    f"{len(sess)} indices for {len(logs)} logs; give one per log"
                )
        free = tuple(x.strip() for x in r.get("free", "").split(";") if x.strip()) or None
        fmt = _resolve(base, r["log_format"]) if r.get("log_format") else None
        if fmt and not Path(fmt).is_file():
            raise ManifestError(
                f"{_where(path, i, 'log_format')}: {fmt} is not a file; paths "
                f"resolve against the manifest's folder {base}"
            )
        rows.append(
            FitRow(
                rid,
                logs,
                preset if not scen else None,
                scen,
                fmt,
                _window(r.get("window", ""), _where(path, i, "window")),
                _window(r.get("validate_window", ""), _where(path, i, "validate_window")),
                sess,
                free,
                sheet,
                opts,
            )
        )
    return rows


def fit_row(row: FitRow) -> tuple[Any, dict]:
    """One row → the one fit (:func:`flexarm.identification.fit`), as the command line runs
    it: a ``servo_rig`` row through the preset of its data sheet (the row's options that
    are :class:`~flexarm.identification.time_domain.options.ServoRig` fields go there, the
    pipeline's other keywords, e.g. ``popsize``, with the data sheet), a scenario row
    through its scenario; the result is the one
    :class:`~flexarm.identification.time_domain.result.FitResult` for every row. Extras for
    its JSON: the window and the held-out prediction (:func:`~flexarm.identification.
    predict` of the result on ``validate_window``)."""
    import dataclasses as dc

    from flexarm.identification import fit, predict
    from flexarm.identification.time_domain.options import FitOptions, PredictOptions, ServoRig

    extra: dict[str, Any] = {}
    if row.preset == "servo_rig":
        from flexarm.identification.time_domain.logs import load_rig_log
        from flexarm.identification.time_domain.presets import DataSheet, servo_rig

        full = [load_rig_log(p, log_format=row.log_format) for p in row.logs]
        kw = {**row.data_sheet, **row.options}
        if row.sessions is not None:
            kw["sessions"] = list(row.sessions)
        rig_fields = {f.name for f in dc.fields(ServoRig)}
        sheet_fields = {f.name for f in dc.fields(DataSheet)}
        preset = servo_rig(DataSheet(**{k: v for k, v in kw.items() if k in sheet_fields}))
        preset.sheet.update(
            {k: v for k, v in kw.items() if k not in rig_fields and k not in sheet_fields}
        )
        opts = FitOptions(
            servo_rig=ServoRig(**{k: v for k, v in kw.items() if k in rig_fields}),
            windows=[row.window] * len(full) if row.window else None,
        )
        res = fit(preset, full, options=opts)
    else:
        from flexarm.io.logformat import load_log
        from flexarm.specs import load_scenario

        assert row.scenario is not None  # a row without a preset names its scenario
        full = [load_log(p, row.log_format) for p in row.logs]
        # the row's options by the fit's field names (max_nfev, segment, ...), each to its
        # group; over the preset's options where the row lists no free parameters
        opts = FitOptions.from_fields(
            windows=[row.window] * len(full) if row.window else None, **row.options
        )
        res = fit(load_scenario(row.scenario), full, list(row.free) if row.free else None, opts)
    if row.window:
        extra["window_s"] = list(row.window)
    if row.validate_window:
        held = predict(res, full, PredictOptions(windows=[row.validate_window] * len(full)))
        extra["held_out"] = {
            "window_s": list(row.validate_window),
            "fit_percent": held.fit_percent,
        }
    return res, extra


@dataclass(frozen=True)
class FitManyOptions:
    """``figures``: write each fit's overlay figures; ``retries``: reruns of a task that
    raised outside the fit (a row's own error is caught and reported, not retried);
    ``fit``: the row → fit function (default :func:`fit_row`; picklable)."""

    figures: bool = True
    retries: int = 2
    fit: Callable[[FitRow], tuple[Any, dict]] | None = None


def _safe_id(rid: str) -> bool:
    """A row id that is a safe folder name in ``--out`` (:func:`flexarm.io.write.safe_name`
    leaves it unchanged: no ``..``, no path, no hidden name) and not one of fit-many's own
    files there."""
    from flexarm.errors import FlexarmError
    from flexarm.io.write import safe_name

    try:
        ok = bool(rid) and safe_name(rid, what="id") == rid
    except FlexarmError:
        return False
    return ok and rid.lower() not in ("summary.csv", "summary.csv.part", ".flexarm.lock")


def finished(directory: str | Path) -> dict | None:
    """A finished row's JSON (``fit.json`` there and valid), or None."""
    p = Path(directory) / "fit.json"
    try:
        d = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return (
        d if isinstance(d, dict) and d.get("flexarm_fit_many", {}).get("status") == "done" else None
    )


def _run_fit_task(row: FitRow, out: str, *, figures: bool, fit: Callable | None) -> dict:
    """One row on a worker: fit, write its files, return its summary record."""
    from flexarm.io.write import write_json

    folder = Path(out) / row.id
    folder.mkdir(parents=True, exist_ok=True)
    t0 = _time.perf_counter()
    try:
        res, extra = (fit or fit_row)(row)
        d = {**res.to_dict(), **extra}
    except Exception as exc:  # a failing row is reported, others go on
        msg = _first_line(exc)
        (folder / "error.txt").write_text(msg + "\n", encoding="utf-8")
        return {
            "id": row.id,
            "status": "failed",
            "seconds": _time.perf_counter() - t0,
            "error": msg,
        }
    # the fit stands even where its scenario or figures cannot be written (e.g. a rigid
    # arm's servo-rig fit has no link for the scenario): a warning says so
    notes = []
    try:
        res.write_scenario(folder / "fitted.toml", overwrite=True)
    except Exception as exc:
        notes.append(f"fitted scenario not written: {_first_line(exc)}")
    if figures and hasattr(getattr(res, "prediction", None), "traces"):
        try:  # the fit's prediction, overlaid on each fitted log (as fit --plots draws it)
            from flexarm.identification.time_domain.figures import write_overlays

            write_overlays(res.prediction, folder / "plots", "fit")
        except Exception as exc:
            notes.append(f"figures not written: {_first_line(exc)}")
    d["warnings"] = list(d.get("warnings") or []) + notes
    seconds = _time.perf_counter() - t0
    d["flexarm_fit_many"] = {
        "status": "done",
        "row": dataclasses.asdict(row),
        "seconds": seconds,
        "host": os.uname().nodename,
        "pid": os.getpid(),
    }
    tmp = folder / "fit.json.part"
    write_json(tmp, d, overwrite=True)
    os.replace(tmp, folder / "fit.json")  # atomic: fit.json present = row finished
    (folder / "error.txt").unlink(missing_ok=True)
    return summary_record(row.id, d)


def _first_line(exc: BaseException) -> str:
    return f"{type(exc).__name__}: {exc}".splitlines()[0]


def summary_record(rid: str, d: dict, status: str = "done") -> dict:
    """One summary line from a fit's JSON (the servo-rig fit's or the general fit's)."""
    rec: dict[str, Any] = {
        "id": rid,
        "status": status,
        "seconds": d.get("flexarm_fit_many", {}).get("seconds", d.get("seconds")),
        "error": "",
        "n_warnings": len(d.get("warnings", [])),
        "warnings": " | ".join(d.get("warnings", [])),
    }
    if "params" not in d and "parameters" in d:  # a servo-rig row written before the one
        # FitResult document (its {name: {value, std}} table): a finished row read back
        for k, p in d["parameters"].items():
            rec[k], rec[f"{k}_std"] = p.get("value"), p.get("std")
    else:  # FitResult.to_dict of every rig
        for k, v in d.get("params", {}).items():
            rec[k], rec[f"{k}_std"] = v, d.get("std", {}).get(k)
    for tag, fp in (
        ("fit%", d.get("fit_percent", {})),
        ("held-out%", d.get("held_out", {}).get("fit_percent", {})),
    ):
        for log, sig in (fp or {}).items():
            for s, v in (sig or {}).items():
                rec[f"{tag}:{Path(log).name}:{s}"] = v
    return rec


def write_summary(path: str | Path, records: Sequence[dict]) -> Path:
    """``summary.csv``: the fixed columns first, then every other column in first-seen
    order; empty where a row has none."""
    fixed = ["id", "status", "seconds", "error", "n_warnings", "warnings"]
    cols = fixed + list(dict.fromkeys(k for r in records for k in r if k not in fixed))
    path = Path(path)
    tmp = path.with_suffix(".csv.part")
    with tmp.open("w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, cols, restval="")
        w.writeheader()
        for r in records:
            w.writerow({k: _cell(v) for k, v in r.items()})
    os.replace(tmp, path)
    return path


def _cell(v):
    if isinstance(v, float):
        return "" if not math.isfinite(v) else repr(v)
    return "" if v is None else v


def fit_many_todo(rows, out: Path, manifest: Path | None, overwrite: bool = False) -> list:
    """The output policy of :func:`fit_many`, before any fit: the rows to run. ``out``
    must be a folder; a folder holding files is written into only when it is fit-many's
    own (it holds ``summary.csv`` and only row folders) or with ``overwrite``; a finished
    row is skipped only when its ``fit.json`` is a fit of the same row (same logs,
    scenario, options): another row's finished fit there is refused unless ``overwrite``
    (then it is fitted again); the manifest is never written over."""
    from flexarm.errors import InputOverwriteError, OutputExistsError
    from flexarm.io.write import LOCK_NAME, is_input

    summary = out / "summary.csv"
    if manifest is not None and (
        summary.resolve() == manifest.resolve() or (summary.exists() and summary.samefile(manifest))
    ):
        raise InputOverwriteError(
            f"--out {out}: its summary.csv is the manifest {manifest}; fit-many writes "
            "summary.csv there",
            fix="give another --out folder, or move the manifest",
        )
    if is_input(summary) is not None:
        raise InputOverwriteError(f"{summary}: is an input of this run; give another --out")
    if out.exists() and not out.is_dir():
        raise OutputExistsError(f"--out {out}: is a file, not a folder; give a folder name")
    ids = {r.id for r in rows}
    if out.is_dir() and not overwrite:
        entries = [p for p in out.iterdir() if p.name != LOCK_NAME]
        ours = summary.is_file() and all(
            p.name in ("summary.csv",) or (p.is_dir() and p.name in ids) for p in entries
        )
        if entries and not ours:
            raise OutputExistsError(
                f"--out {out}: the folder holds files that are not this manifest's fit-many "
                "results; not written into",
                fix="pass --overwrite (overwrite=True), or give an empty folder",
            )
    todo = []
    for r in rows:
        d = finished(out / r.id)
        if d is None:
            todo.append(r)
            continue
        own = d.get("flexarm_fit_many", {}).get("row")
        if own == json.loads(json.dumps(dataclasses.asdict(r), default=str)):
            continue
        if not overwrite:
            raise OutputExistsError(
                f"{out / r.id / 'fit.json'}: a finished fit of another row (its logs, "
                "scenario or options differ from the manifest's row id "
                f"{r.id!r}); not written over",
                fix="pass --overwrite (overwrite=True) to fit the row again, or give another --out",
            )
        todo.append(r)
    return todo


def fit_many(
    rows: Sequence[FitRow] | str | Path,
    client=None,
    out: str | Path = "fits",
    *,
    options: FitManyOptions | None = None,
    progress: Callable[[dict], None] | None = None,
    overwrite: bool = False,
) -> list[dict]:
    """Fit every row (a manifest path or :func:`read_manifest`'s rows), each fit a task on
    ``client``'s workers (None: one after the other in-process); finished rows (their
    ``fit.json`` there and valid) are skipped, failed ones run again. Writes
    ``out/<id>/...`` and ``out/summary.csv`` (module doc; rewritten as rows finish, so an
    interrupted run leaves a summary of what finished); ``progress(record)`` after each
    row. Returns the records in the manifest's order.  The output policy
    (:func:`fit_many_todo`, before any fit): a folder holding other files, or another row's
    finished fit, only with ``overwrite``; the manifest is never written over."""
    o = options or FitManyOptions()
    manifest = Path(rows) if isinstance(rows, (str, Path)) else None
    rows = read_manifest(manifest) if manifest is not None else list(cast(Sequence[FitRow], rows))
    out = Path(out)
    todo = fit_many_todo(rows, out, manifest, overwrite)
    out.mkdir(parents=True, exist_ok=True)
    from flexarm.io.write import lock_folder

    lock_folder(out)  # inside a command's run_scope: a second run into out is refused
    recs: dict[str, dict] = {}
    for r in rows:
        if r not in todo:
            d = finished(out / r.id)
            assert d is not None  # fit_many_todo kept it as finished
            recs[r.id] = summary_record(r.id, d, status="skipped (finished before)")
    order = [r.id for r in rows]

    def done(rec):
        recs[rec["id"]] = rec
        if progress is not None:
            progress(rec)
        write_summary(out / "summary.csv", [recs[i] for i in order if i in recs])

    if not todo:
        write_summary(out / "summary.csv", [recs[i] for i in order])
    if client is None:
        for r in todo:
            done(_run_fit_task(r, str(out), figures=o.figures, fit=o.fit))
    else:
        from distributed import as_completed

        futs = {
            client.submit(
                _run_fit_task,
                r,
                str(out),
                figures=o.figures,
                fit=o.fit,
                pure=False,
                retries=o.retries,
                key=f"fit-{r.id}-{_time.time_ns()}",
            ): r
            for r in todo
        }
        with client.as_current():  # as_completed looks for the current client
            for fut in as_completed(futs):
                try:
                    rec = fut.result()
                except Exception as exc:  # the task failed (e.g. killed 3 times)
                    rec = {
                        "id": futs[fut].id,
                        "status": "failed",
                        "seconds": None,
                        "error": _first_line(exc),
                    }
                done(rec)
    return [recs[i] for i in order]
