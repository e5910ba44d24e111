"""The public face: flexarm's top-level names, and fit / validate picking the general fit
for a scenario and the data-sheet pipeline for servo-rig logs."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import flexarm

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "two-link-rig"
EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def test_every_public_name_resolves():
    for name in flexarm.__all__:
        assert getattr(flexarm, name) is not None, name
    for name in (
        "Arm",
        "fit",
        "validate",
        "simulate",
        "simulate_batch",
        "load_log",
        "linearize",
        "lqg",
        "tfest",
        "periodic_frf",
        "identify",
        "load_scenario",
    ):
        assert name in flexarm.__all__


def test_fit_says_which_form_it_needs():
    with pytest.raises(TypeError, match="give the logs"):
        flexarm.fit("quanser-two-link")
    with pytest.raises(TypeError, match="fit\\(scenario, logs, free"):
        flexarm.fit(["log.csv"], free=["arm.hubs[0].inertia"])


def test_fit_options_is_one_name():
    """Issue #23: ``FitOptions`` is only the grouped options of flexarm.fit wherever it is
    reachable (the general engine reads it itself, issue #43); the old flat record is
    ``ScenarioFitOptions``, a deprecated input only (no ``engine_options`` builds one)."""
    from flexarm.identification import time_domain
    from flexarm.identification.time_domain import general, options

    assert time_domain.FitOptions is options.FitOptions is general.FitOptions
    assert time_domain.ScenarioFitOptions is general.ScenarioFitOptions
    assert time_domain.ScenarioFitOptions is options.ScenarioFitOptions
    assert "FitOptions" not in general.__all__
    assert not hasattr(options.FitOptions, "engine_options")


@pytest.mark.skipif(
    not DATA.is_dir(),
    reason=f"two-link rig data not found at {DATA} "
    "(../shared is absent in a user's clone; CI has it)",
)
def test_load_log_is_the_format_reader():
    """flexarm.load_log(path, format) returns exactly what the format's own reader does."""
    from flexarm.io.logformat import load_log_format

    path, fmt = DATA / "lqr-stair" / "lqr_step_5deg_run01.mat", EXAMPLES / "two-link-staircase.toml"
    a = flexarm.load_log(path, fmt)
    b = load_log_format(fmt).read(path)
    assert set(a.signals) == set(b.signals) and len(a) == len(b) > 100
    for k in a.signals:
        np.testing.assert_array_equal(a[k], b[k])
