"""JAX's persistent compilation cache is on by default for the command line, in the user's
cache folder (issue #46 item 5); FLEXARM_JAX_CACHE=DIR moves it, =0 or --no-jax-cache turn
it off."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import jax
import pytest
from typer.testing import CliRunner

from flexarm.cli import app
from flexarm.cli.common import cache_folder, enable_cache


@pytest.fixture
def restore_jax_cache():
    before = jax.config.jax_compilation_cache_dir
    yield
    jax.config.update("jax_compilation_cache_dir", before)


def test_the_default_folder_is_the_users_cache(monkeypatch, tmp_path):
    monkeypatch.delenv("FLEXARM_JAX_CACHE", raising=False)
    monkeypatch.setenv("HOME", str(tmp_path))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    got = cache_folder()
    assert got is not None and got.name == "jax" and got.parent.name == "flexarm"
    if "platformdirs" in sys.modules or _has("platformdirs"):
        assert got == tmp_path / "xdg" / "flexarm" / "jax"
    else:
        assert got == tmp_path / ".cache" / "flexarm" / "jax"


def _has(name: str) -> bool:
    import importlib.util

    return importlib.util.find_spec(name) is not None


@pytest.mark.parametrize("value", ["0", "off", "OFF", "false", "no"])
def test_zero_or_off_turns_it_off(monkeypatch, value):
    monkeypatch.setenv("FLEXARM_JAX_CACHE", value)
    assert cache_folder() is None


def test_a_named_folder_is_created_and_used(monkeypatch, tmp_path, restore_jax_cache):
    folder = tmp_path / "c" / "jax"
    monkeypatch.setenv("FLEXARM_JAX_CACHE", str(folder))
    enable_cache()
    assert folder.is_dir()
    assert Path(jax.config.jax_compilation_cache_dir) == folder
    assert jax.config.jax_enable_x64


def test_an_unwritable_folder_runs_uncached(monkeypatch, tmp_path, restore_jax_cache):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    monkeypatch.setenv("FLEXARM_JAX_CACHE", str(blocker / "jax"))  # below a file
    jax.config.update("jax_compilation_cache_dir", None)
    enable_cache()
    assert jax.config.jax_compilation_cache_dir is None
    assert os.environ["FLEXARM_JAX_CACHE"] == "0"


def test_the_no_jax_cache_option_turns_it_off(monkeypatch, tmp_path):
    monkeypatch.setenv("FLEXARM_JAX_CACHE", str(tmp_path / "jax"))
    r = CliRunner().invoke(app, ["--no-jax-cache", "scenarios"])
    assert r.exit_code == 0, r.output
    assert os.environ["FLEXARM_JAX_CACHE"] == "0" and cache_folder() is None
