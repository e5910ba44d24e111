"""Step-response metrics: settling time, overshoot, steady-state error, ripple.

Conventions (as the papers use them): the settling time is the first time after which
the response stays within ±band·|step| of the final value (band 2 % unless said; FRB's
two-mass inner loop uses 5 %); the final value is the reference unless ``final`` is given.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np


@dataclass(frozen=True)
class StepMetrics:
    step: float  # size of the step (signal units)
    final_value: float  # mean of the last 5 % of the record
    steady_state_error: float  # reference − final value
    settling_time: float | None  # s after the step; None if it never settles
    overshoot: float  # fraction of the step beyond the final target
    peak: float  # largest |value − initial|

    def to_dict(self) -> dict:
        return asdict(self)


def step_metrics(
    t: np.ndarray,
    y: np.ndarray,
    reference: np.ndarray,
    *,
    band: float = 0.02,
    target: float | None = None,
    t_step: float | None = None,
) -> StepMetrics:
    """Metrics of a response ``y`` to a step in ``reference`` (both sampled at ``t``)."""
    t, y, r = (np.asarray(a, float) for a in (t, y, reference))
    if t_step is None:
        jumps = np.nonzero(np.abs(np.diff(r)) > 0)[0]
        t_step = float(t[jumps[0] + 1] if jumps.size else t[0])
    y0 = float(y[np.searchsorted(t, t_step) - 1]) if np.searchsorted(t, t_step) > 0 else float(y[0])
    goal = float(r[-1]) if target is None else float(target)
    step = goal - y0
    tail = max(1, len(y) // 20)
    final = float(np.mean(y[-tail:]))
    tol = band * abs(step)
    after = t >= t_step
    outside = np.nonzero(after & (np.abs(y - goal) > tol))[0]
    if outside.size == 0:
        ts = 0.0
    elif outside[-1] == len(y) - 1:
        ts = None
    else:
        ts = float(t[outside[-1] + 1] - t_step)
    over = float(np.max((y[after] - goal) * np.sign(step)) / abs(step)) if step else 0.0
    return StepMetrics(step, final, goal - final, ts, max(over, 0.0), float(np.max(np.abs(y - y0))))


def ripple(t: np.ndarray, y: np.ndarray, *, after: float, goal: float) -> float:
    """Largest |y − goal| after time ``after``."""
    t, y = np.asarray(t), np.asarray(y)
    return float(np.max(np.abs(y[t >= after] - goal)))


def fit_percent(y: np.ndarray, y_hat: np.ndarray) -> float:
    """fit % = 100 (1 − ‖y − ŷ‖ / ‖y − mean y‖) (100: exact; 0: no better than the mean;
    NaN for a constant y)."""
    y, y_hat = np.asarray(y, float), np.asarray(y_hat, float)
    den = float(np.linalg.norm(y - y.mean()))
    return float(100 * (1 - np.linalg.norm(y - y_hat) / den)) if den > 0 else float("nan")
