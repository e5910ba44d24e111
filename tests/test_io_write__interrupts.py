"""io/write.interruptible and the CLI's guarded run (issue #45 item 5): a Ctrl-C that
arrives where Python cannot raise it (a ``__del__``, a weakref callback, a garbage
collection: where JAX frees its buffers) is not swallowed: it is delivered again 50 ms
later in the code that runs on; and a command that ran through a signal never exits 0."""

from __future__ import annotations

import gc
import signal
import time

import pytest
import typer

from flexarm.io.write import interruptible


@pytest.fixture(autouse=True)
def _python_handles_sigint():
    """Python's own Ctrl-C handler during each test: a background job of a
    non-interactive shell inherits SIGINT ignored (``cmd &``), and these tests send it."""
    old = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, old)


class _SignalsInDel:
    """An object whose finaliser receives SIGINT (as a JAX buffer freed when Ctrl-C comes)."""

    def __del__(self):
        signal.raise_signal(signal.SIGINT)


def _run_on(seconds: float) -> float:
    t0 = time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        time.sleep(0.005)
    return time.perf_counter() - t0


def test_a_ctrl_c_in_a_finaliser_is_delivered_again_not_swallowed():
    with pytest.raises(KeyboardInterrupt):
        with interruptible() as run:
            obj = _SignalsInDel()
            del obj  # the handler runs inside __del__: a raise there would be dropped
            assert run.deferred == "SIGINT" and run.count == 0
            _run_on(2.0)  # the re-delivered signal ends this within ~50 ms
    assert run.signal == "SIGINT" and run.count == 1


def test_a_ctrl_c_during_a_garbage_collection_is_delivered_again():
    class Cycle:
        def __init__(self):
            self.me = self

        def __del__(self):
            signal.raise_signal(signal.SIGINT)

    t0 = time.perf_counter()
    with pytest.raises(KeyboardInterrupt):
        with interruptible() as run:
            Cycle()
            gc.collect()
            _run_on(2.0)
    assert run.deferred == "SIGINT" and time.perf_counter() - t0 < 1.5


def test_a_command_that_ran_through_a_signal_exits_128_plus_its_number(monkeypatch):
    """The guarded run (cli/common.guarded) of a command whose code caught the interrupt and
    returned normally: exit 130, not 0."""
    from flexarm.cli.common import guarded

    with pytest.raises(typer.Exit) as e:
        with guarded():
            try:
                signal.raise_signal(signal.SIGINT)
            except KeyboardInterrupt:
                pass  # a library that swallows it and goes on
    assert e.value.exit_code == 130
