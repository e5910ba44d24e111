"""Time-domain identification of bench arms from closed-loop logs: :func:`fit`,
:func:`validate` (see :mod:`flexarm.bench.fit`, :mod:`flexarm.bench.validate`)."""

from flexarm.bench.fit import fit, predict
from flexarm.bench.logs import BenchLog, FitInputError, parse_controller, read_bench_log
from flexarm.bench.report import FitResult
from flexarm.bench.validate import validate

__all__ = ["BenchLog", "FitInputError", "FitResult", "fit", "parse_controller", "predict",
           "read_bench_log", "validate"]
