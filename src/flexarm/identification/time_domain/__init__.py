"""Time-domain identification from closed-loop logs: the one fit
(:func:`~flexarm.identification.time_domain.engine.fit`, ``flexarm.fit``) with presets per rig
kind (:mod:`~flexarm.identification.time_domain.presets`), one result
(:class:`~flexarm.identification.time_domain.result.FitResult`), one prediction
(:func:`~flexarm.identification.time_domain.predict.predict`, ``flexarm.validate``).
``FitOptions`` is the one fit's grouped options
(:class:`~flexarm.identification.time_domain.options.FitOptions`); ``ScenarioFitOptions``
the general engine's flat record (:func:`fit_scenario`'s).

Deprecated names kept until their callers move: ``fit`` here is the rotary servo
pipeline's (:mod:`~flexarm.identification.time_domain.fit`); ``predict`` is the one
prediction; ``validate`` a deprecated alias of it returning a dict;
``fit_scenario`` / ``predict_scenario`` / ``ScenarioFit`` the general engine's,
``RigFitResult`` the servo pipeline's result. Logs are :class:`flexarm.io.logs.Log`, read by
:func:`flexarm.io.logformat.load_log` (:func:`load_rig_log` adds the servo rig's check)."""

from flexarm.identification.time_domain.figures import overlay_figure
from flexarm.identification.time_domain.general import (
    ScenarioFit,
    ScenarioFitOptions,
    fit_scenario,
    predict_scenario,
)
from flexarm.identification.time_domain.logs import FitInputError, load_rig_log
from flexarm.identification.time_domain.options import FitOptions, PredictOptions
from flexarm.identification.time_domain.predict import Prediction
from flexarm.identification.time_domain.report import FitResult as RigFitResult
from flexarm.identification.time_domain.result import FitResult
from flexarm.identification.time_domain.validate import validate

__all__ = [
    "FitInputError",
    "FitOptions",
    "FitResult",
    "PredictOptions",
    "Prediction",
    "RigFitResult",
    "ScenarioFit",
    "ScenarioFitOptions",
    "fit",
    "fit_scenario",
    "load_rig_log",
    "overlay_figure",
    "predict",
    "predict_scenario",
    "validate",
]

# last, after __all__ (so that import sorting keeps it last): the submodules `fit` and
# `predict` share these names, and importing a submodule binds its name on the package;
# `fit` is the servo-rig pipeline's function, `predict` the one prediction
from flexarm.identification.time_domain.fit import fit
from flexarm.identification.time_domain.predict import predict
