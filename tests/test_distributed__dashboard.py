"""The local Dask cluster serves no dashboard (issue #45): with ``dashboard_address=None``
dask's scheduler still started its HTTP server on :8787 (its default port); flexarm's
cluster binds that server to a free port on the loopback host, without the dashboard."""

from __future__ import annotations

import pytest

import flexarm.distributed as fd

pytest.importorskip("distributed")


def test_the_local_cluster_does_not_take_port_8787():
    c = fd.client_for(workers=1)
    try:
        port = c.run_on_scheduler(lambda dask_scheduler: dask_scheduler.http_server.port)
        routes = c.run_on_scheduler(
            lambda dask_scheduler: any(
                "status" in str(r.matcher.regex.pattern)
                for r in dask_scheduler.http_application.wildcard_router.rules
            )
        )
        assert port != 8787 and port > 0
        assert not routes  # no dashboard pages (/status) on it either
        assert c.submit(lambda x: x + 1, 1).result() == 2
    finally:
        fd.close(c)
