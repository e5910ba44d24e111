"""flexarm.sim.batch: a batch's chunks on the CPU's cores, and the general fit engine's
candidates through it (equal to one call to the last bit)."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from flexarm.identification.time_domain.general import fit_scenario
from flexarm.identification.time_domain.options import FitOptions, Local, Shooting
from flexarm.identification.time_domain.synthetic import scenario_log
from flexarm.sim.batch import cpu_cores, one_blas_thread, run_chunks
from flexarm.specs.paths import scenario_with
from test_time_domain_general import staircase, two_mode_link


def test_chunks_run_at_once_and_come_back_in_order():
    """Two chunks that each wait for the other to have started finish only if they run at
    the same time (one after the other, the first would time out)."""
    started = [threading.Event(), threading.Event()]

    def fn(i):
        started[i].set()
        ok = started[1 - i].wait(timeout=10.0)
        return i, ok

    assert run_chunks(fn, [0, 1], threads=2) == [(0, True), (1, True)]
    assert run_chunks(lambda x: x * x, [3, 1, 2], threads=1) == [9, 1, 4]
    assert cpu_cores() >= 1


def _blas_threads() -> list[int]:
    from threadpoolctl import threadpool_info

    return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]


def test_one_blas_thread_inside_and_the_pool_restored_after():
    """Inside a function under :func:`one_blas_thread` every BLAS library NumPy and SciPy
    loaded runs one thread; on return, and on an exception, each gets its pool back; the
    rotary rig's estimates stage runs under it."""
    import importlib

    import scipy.linalg  # noqa: F401 - loads SciPy's own OpenBLAS

    rig = importlib.import_module("flexarm.identification.time_domain.fit")

    before = _blas_threads()
    assert before, "NumPy's BLAS is not visible to threadpoolctl"

    @one_blas_thread
    def inside(fail: bool) -> list[int]:
        if fail:
            raise RuntimeError("boom")
        return _blas_threads()

    assert inside(False) == [1] * len(before)
    assert _blas_threads() == before
    with pytest.raises(RuntimeError, match="boom"):
        inside(True)
    assert _blas_threads() == before
    # the servo rig's estimates stage runs under it (the decorator's functools.wraps)
    assert getattr(rig._estimates, "__wrapped__", None) is not None


def test_threads_capped_by_the_environment(monkeypatch):
    """$FLEXARM_THREADS (a Dask worker's one thread) caps the threads; a bad value is
    refused naming the variable, the value and the fix."""
    monkeypatch.setenv("FLEXARM_THREADS", "1")
    assert cpu_cores() == 1
    monkeypatch.setenv("FLEXARM_THREADS", "two")
    with pytest.raises(ValueError, match=r"FLEXARM_THREADS = 'two': give a whole number"):
        cpu_cores()


def test_fit_on_threads_equals_the_fit_in_one_call():
    """The general fit's candidates (the finite-difference Jacobian's columns, with the
    segments' start-state offsets) on two threads, as chunks padded to one shape, give the
    fit of one call bit for bit: each candidate's simulation is elementwise in the batch."""
    truth = two_mode_link()
    t = np.arange(3001) * 0.002  # the scenario's 6 s
    log = scenario_log(truth, {"reference": staircase(t, [0.0, 0.4, -0.1, 0.3], 1.5)}, seed=3)
    free = ["arm.joints[0].friction.coulomb", "arm.joints[0].viscous", "arm.hubs[0].inertia"]
    template = scenario_with(truth, {"arm.hubs[0].inertia": 0.025})
    res = {
        threads: fit_scenario(
            template,
            [log],
            free,
            FitOptions(
                shooting=Shooting(segment=1.0),
                local=Local(max_nfev=3, restarts=0, threads=threads),
            ),
            predict=False,
        )
        for threads in (1, 2)
    }
    assert res[1].nfev == res[2].nfev == 3
    assert res[1].params == res[2].params
    assert res[1].cost == res[2].cost
