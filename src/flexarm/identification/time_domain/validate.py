"""Deprecated: ``time_domain.validate.validate`` was the servo rig's own replay of a
scenario. Every prediction is now the one prediction,
:func:`flexarm.identification.time_domain.predict.predict` (``flexarm.validate``), which
runs servo-rig logs with the law each declares and estimates each log's start state as
the fit does; this name calls it and returns its old dict."""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any


def validate(
    scenario: Any,
    logs: Sequence[Any],
    *,
    controller: Any = None,
    plots: str | Path | None = None,
    traces: bool = False,
) -> dict:
    """Deprecated alias of :func:`flexarm.validate` returning ``{"scenario", "fit_percent",
    "plots"}`` (and ``"traces"``, a list in the logs' order, with ``traces``)."""
    from flexarm.identification.time_domain.options import PredictOptions
    from flexarm.identification.time_domain.predict import predict

    warnings.warn(
        "flexarm.identification.time_domain.validate.validate is deprecated: use "
        "flexarm.validate(scenario, logs, PredictOptions(...))",
        DeprecationWarning,
        stacklevel=2,
    )
    pred = predict(scenario, logs, PredictOptions(controller=controller, plots=plots))
    out: dict[str, Any] = {
        "scenario": pred.scenario,
        "fit_percent": pred.fit_percent,
        "plots": list(pred.plots),
    }
    if traces:
        out["traces"] = list(pred.traces.values())
    return out
