"""Identification: a model from measured data.

* :mod:`flexarm.identification.time_domain`: closed-loop (or open-loop replay) logs →
  physical parameters, by simulating the logged experiment (output error);
* :mod:`flexarm.identification.frequency_domain`: periodic or sinusoidal experiments →
  frequency responses, their noise and distortion, transfer functions and physical fits
  (FRB Sec. II, multisines, ``tfest``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Sequence

from flexarm.specs.scenario import names_a_scenario


def _scenario(x: Any):
    from flexarm.specs import load_scenario

    return x if not isinstance(x, (str, Path)) else load_scenario(x)


def fit(model: Any, logs: Sequence[Any] | None = None, free: Sequence[str] | None = None,
        options: Any = None, **kw):
    """Fit a model to closed-loop logs in the time domain (output error).

    * ``fit(scenario, logs, free=[...], options=FitOptions(...))``: any arm a scenario
      describes (a :class:`flexarm.Scenario`, a TOML path or a built-in name) is the
      template; the parameters named by ``free`` (paths into the scenario, e.g.
      ``"arm.joints[0].friction.coulomb"``) are estimated
      (:func:`flexarm.identification.time_domain.general.fit_scenario`, returns a
      ``ScenarioFit``);
    * ``fit(logs, drive=..., gear_ratio=..., ...)``: the data-sheet pipeline for voltage- or
      current-driven single-link servo rigs with a strain gauge (cheap estimates first,
      sensor delays searched; :func:`flexarm.identification.time_domain.fit.fit`)."""
    from flexarm.identification.time_domain import fit as bench_fit
    from flexarm.identification.time_domain import fit_scenario

    if names_a_scenario(model):
        if logs is None:
            raise TypeError("fit(scenario, logs, free=..., options=...): give the logs")
        return fit_scenario(_scenario(model), logs, free, options, **kw)
    if logs is not None or free is not None or options is not None:
        raise TypeError("fit(logs, drive=..., ...) takes the rig's data sheet as keywords; "
                        "to fit a scenario's parameters call fit(scenario, logs, free=[...])")
    return bench_fit(model, **kw)


def validate(model: Any, logs: Sequence[Any], **kw) -> dict:
    """fit % of each log (or window) predicted by a model with its parameters fixed: a
    multi-link scenario through
    :func:`flexarm.identification.time_domain.general.predict_scenario`, a single-link rig
    through :func:`flexarm.identification.time_domain.validate.validate` (its logs' own
    references and controllers)."""
    from flexarm.identification.time_domain import predict_scenario
    from flexarm.identification.time_domain import validate as bench_validate

    sc = _scenario(model) if names_a_scenario(model) else model
    if getattr(getattr(sc, "arm", None), "kind", None) == "multi_link":
        return predict_scenario(sc, logs, **kw)
    return bench_validate(model, logs, **kw)
