"""Time-domain identification from closed-loop logs: the one fit
(:func:`~flexarm.identification.time_domain.engine.fit`, ``flexarm.fit``) with presets per rig
kind (:mod:`~flexarm.identification.time_domain.presets`), one result
(:class:`~flexarm.identification.time_domain.result.FitResult`), one prediction
(:func:`~flexarm.identification.time_domain.predict.predict`, ``flexarm.validate``).
``FitOptions`` is the one fit's grouped options
(:class:`~flexarm.identification.time_domain.options.FitOptions`), which the general engine
reads itself; ``ScenarioFitOptions``, the old flat record, is a deprecated input
(converted by ``FitOptions.from_flat`` with a ``DeprecationWarning``).

Deprecated aliases (a ``DeprecationWarning`` naming the replacement): ``fit`` here (the rotary
servo pipeline's keyword interface) and ``fit_scenario`` (the general engine's entry), both
replaced by ``flexarm.fit``; ``validate``, an alias of the one prediction returning a dict;
``general.refit_friction`` (``flexarm.fit(scenario, [log], general.friction_paths(scenario),
FitOptions(...))``). Kept: ``predict_scenario`` / ``ScenarioFit`` (the general engine's
prediction and the one result's old name), ``RigFitResult`` (the servo pipeline's result).
Logs are :class:`flexarm.io.logs.Log`, read by :func:`flexarm.io.logformat.load_log`
(:func:`load_rig_log` adds the servo rig's check)."""

from importlib import import_module

from flexarm.identification.time_domain.figures import overlay_figure
from flexarm.identification.time_domain.general import ScenarioFit, predict_scenario
from flexarm.identification.time_domain.logs import FitInputError, load_rig_log
from flexarm.identification.time_domain.options import (
    FitOptions,
    PredictOptions,
    ScenarioFitOptions,
)
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
# `fit` is then rebound to the deprecated alias below, `predict` is the one prediction
from flexarm.identification.time_domain.predict import predict

# the submodule `fit` imported now, so that importing it later cannot rebind the package's
# name `fit` from the deprecated alias below to the module
import_module(f"{__name__}.fit")


def fit(logs, **sheet_and_options):
    """Deprecated: the rotary servo pipeline's keyword interface. Use the one fit,
    ``flexarm.fit(presets.servo_rig(presets.DataSheet(...)), logs,
    options=FitOptions(servo_rig=ServoRig(...)))``, whose result is the one
    :class:`FitResult`; this alias returns the pipeline's own result (:class:`RigFitResult`)."""
    import warnings

    from flexarm.identification.time_domain.fit import fit as rig_fit

    warnings.warn(
        "flexarm.identification.time_domain.fit(logs, drive=..., ...) is deprecated: use "
        "flexarm.fit(presets.servo_rig(presets.DataSheet(...)), logs, options=FitOptions("
        "servo_rig=ServoRig(...)))",
        DeprecationWarning,
        stacklevel=2,
    )
    return rig_fit(logs, **sheet_and_options)


def fit_scenario(scenario, logs, free=None, options=None, **kw):
    """Deprecated: the general engine's entry point. Use the one fit, ``flexarm.fit(scenario,
    logs, free, FitOptions(...))`` (a :class:`ScenarioFitOptions` is still accepted there,
    deprecated: converted by ``FitOptions.from_flat``)."""
    import warnings

    from flexarm.identification.time_domain import general

    warnings.warn(
        "flexarm.identification.time_domain.fit_scenario is deprecated: use "
        "flexarm.fit(scenario, logs, free, FitOptions(...))",
        DeprecationWarning,
        stacklevel=2,
    )
    return general.fit_scenario(scenario, logs, free, options, **kw)
