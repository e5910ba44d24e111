"""Time-domain identification of bench arms from closed-loop logs: :func:`fit`,
:func:`validate` (see :mod:`flexarm.identification.time_domain.fit`, :mod:`flexarm.identification.time_domain.validate`)."""

from flexarm.identification.time_domain.fit import fit, predict
from flexarm.identification.time_domain.general import (FitOptions, ScenarioFit, fit_scenario,
                                                        predict_scenario)
from flexarm.identification.time_domain.logs import (BenchLog, FitInputError, load_rig_log,
                                                     parse_controller, read_bench_log)
from flexarm.identification.time_domain.report import FitResult
from flexarm.identification.time_domain.validate import validate

__all__ = ["BenchLog", "FitInputError", "FitOptions", "FitResult", "ScenarioFit", "fit",
           "fit_scenario", "load_rig_log", "parse_controller", "predict", "predict_scenario", "read_bench_log",
           "validate"]
