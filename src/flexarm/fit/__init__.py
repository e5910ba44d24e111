"""Time-domain identification of bench arms from closed-loop logs: :func:`fit`,
:func:`validate` (see :mod:`flexarm.fit.fit`, :mod:`flexarm.fit.validate`)."""

from flexarm.fit.fit import fit
from flexarm.fit.logs import BenchLog, FitInputError, parse_controller, read_bench_log
from flexarm.fit.report import FitResult
from flexarm.fit.validate import validate

__all__ = ["BenchLog", "FitInputError", "FitResult", "fit", "parse_controller",
           "read_bench_log", "validate"]
