"""The chunked batches take an executor through the protocol defined low
(``sim.batch.BatchExecutor``, issue #43): any object with ``map_chunks`` runs the chunks of
drawn plants (``design.plants.chunk_plants``), not only Dask's; a bare object is refused
with the fix."""

from __future__ import annotations

import numpy as np
import pytest

import flexarm
from flexarm.design import plants as pl
from flexarm.design.compare import compare
from flexarm.sim.batch import BatchExecutor, ChunkOptions, map_chunks

SPREAD = {"arm.friction.coulomb": (0.03, 0.006), "arm.motor.inertia": (2.08e-3, 2e-4)}


class Backwards:
    """A toy executor: runs the chunks last first (a pool finishing out of order), returns
    them in order, counts the tasks and keeps what was shared."""

    def __init__(self):
        self.tasks = 0
        self.shared: dict = {}

    def map_chunks(self, fn, args, *, shared=None, retries=1, workers=None):
        self.tasks += len(args)
        self.shared = dict(shared or {})
        out = {i: fn(*a, **self.shared) for i, a in reversed(list(enumerate(args)))}
        return [out[i] for i in range(len(args))]


def test_any_executor_runs_the_chunks_and_equals_one_batch():
    """4 drawn plants in chunks of 2 on the toy executor: 2 tasks, the same per-plant
    metrics as one in-process batch (1e-12 relative)."""
    ex = Backwards()
    assert isinstance(ex, BatchExecutor)
    b = pl.from_paths(flexarm.load_scenario("rotary-flexible-link"), SPREAD, 4, seed=1)
    one = compare(b, duration=0.8, step=0.3)
    chunked = compare(b, duration=0.8, step=0.3, client=ex, chunks=ChunkOptions(chunk=2))
    assert ex.tasks == 2 and chunked.settings["chunks"] == 2
    name = "logged controller"
    for k, v in one.per_plant[name].items():
        np.testing.assert_allclose(
            np.asarray(chunked.per_plant[name][k], float), np.asarray(v, float), rtol=1e-12
        )
    # chunk j of a drawn batch is its plants [a, b), the nominal kept
    part = pl.chunk_plants(b, 1, 2, 4)
    assert part.nominal is b.nominal and part.scenarios == b.scenarios[2:4]


def test_a_bare_client_is_refused_with_the_fix():
    with pytest.raises(TypeError, match=r"DaskExecutor\(client\)"):
        map_chunks(print, [(1,)], object())
    assert map_chunks(lambda a, k: a + k, [(1,), (2,)], None, shared={"k": 10}) == [11, 12]
