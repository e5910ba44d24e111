"""Identification: a model from measured data.

* :mod:`flexarm.identification.time_domain`: closed-loop (or open-loop replay) logs →
  physical parameters, by simulating the logged experiment (output error);
* :mod:`flexarm.identification.frequency_domain`: periodic or sinusoidal experiments →
  frequency responses, their noise and distortion, transfer functions and physical fits
  (FRB Sec. II, multisines, ``tfest``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from flexarm.specs.scenario import names_a_scenario

__all__ = ["fit", "validate", "predict"]


def fit(
    scenario: Any,
    logs: Sequence[Any] | None = None,
    free: Sequence[str] | None = None,
    options: Any = None,
    *,
    progress: Callable[[str], None] | None = None,
):
    """The one time-domain fit: ``fit(scenario, logs, free=None, options=None)`` →
    :class:`~flexarm.identification.time_domain.result.FitResult`
    (:func:`flexarm.identification.time_domain.engine.fit`). ``scenario``: a scenario (a
    :class:`flexarm.Scenario`, a TOML path or a built-in name) or a preset
    (:mod:`flexarm.identification.time_domain.presets`: ``servo_rig(DataSheet(...))`` for
    the rotary servo's logs, ``two_link()``); without ``free`` the preset's default free
    list runs; ``options``: :class:`~flexarm.identification.time_domain.options.FitOptions`."""
    from flexarm.identification.time_domain import engine
    from flexarm.identification.time_domain.presets import Preset

    if not (isinstance(scenario, Preset) or names_a_scenario(scenario)):
        raise TypeError(
            "fit(scenario, logs, free=None, options=None): the first argument is "
            "a scenario (flexarm.Scenario, TOML path or built-in name) or a preset "
            "(for servo-rig logs: presets.servo_rig(DataSheet(gear_ratio=..., "
            "motor_constant=..., ...))), then the logs"
        )
    if logs is None:
        raise TypeError("fit(scenario, logs, free=None, options=None): give the logs")
    return engine.fit(scenario, logs, free, options, progress=progress)


def predict(model: Any, logs: Sequence[Any], options: Any = None):
    """The one prediction (:func:`flexarm.identification.time_domain.predict.predict`): fit %
    per log and signal of ``model`` (a scenario, a fit result) with its parameters fixed."""
    from flexarm.identification.time_domain.predict import predict as _predict

    return _predict(model, logs, options)


#: ``flexarm.validate`` is the one prediction.
validate = predict
