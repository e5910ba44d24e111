"""Say plainly when a fit is poor, for every preset (issue #44 item 7): :func:`fit_quality`
reads one :class:`~flexarm.identification.time_domain.result.FitResult` (the general
engine's or the servo rig's) and returns one line per finding, each with its figures:

* **fit % below a floor**: a log's signal predicted below :data:`LOW_FIT` % (below
  :data:`POOR_FIT` %: the model does not describe it), with its RMSE in the signal's unit
  (m, m/s, N on a linear axis);
* **residuals far from the noise level**: a signal's RMSE more than :data:`NOISE_FACTOR`
  times the sensor's own noise level sqrt(σ² + q²/12) (``sensors.X.noise`` σ and the
  quantum q of the fitted scenario; skipped where both are 0): the data say more than
  the model explains;
* **a parameter at a bound**: the given ``bounds`` (path → (lo, hi), SI), or, for the
  general engine's log-space parameters without one, the default ``bound_factor`` (×3)
  around the start;
* **a standard deviation larger than the value**: the data do not determine it (a signed
  parameter: not even its sign); an infinite std where the engine has not said so;
* **far from the start**: a parameter that ended more than :data:`FAR_FACTOR` times from
  its start (the data sheet and the logs' estimates): a mass read as an inertia, a log in
  other units, another kind of rig (the data-sheet route's 138 kg on a linear axis); a
  friction level or damping only when it grows;
* **a delay at the search's edge**: the general engine's sensor-delay search ended at
  ``max_delay`` or after ``max_moves`` moves (``stages["delay_search"]``); the servo rig's
  delay at the upper end of its searched range (``delay_ranges``).

A finding the engine has already written into ``res.warnings`` (the same parameter and
the same kind: "bound", "times its start", "not determined" / "does not depend"; the same
log and signal's fit %) is not repeated. Layer: identification (it reads a fit result and
imports nothing to its right): the one fit (:func:`flexarm.identification.time_domain.
engine.fit`) calls it on every preset's result, so ``res.warnings`` holds the findings.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from typing import Any

__all__ = [
    "FAR_FACTOR",
    "LOW_FIT",
    "NOISE_FACTOR",
    "POOR_FIT",
    "fit_quality",
]

#: fit % under which a signal's prediction is called low / not described by the model
LOW_FIT, POOR_FIT = 80.0, 50.0
#: a parameter that ends further than this factor from its start is named
FAR_FACTOR = 10.0
#: a signal whose RMSE exceeds this many times its sensor's noise level is named. 100: a
#: fit that describes its rig leaves the noise plus a model error of the same order (the
#: synthetic linear axis of tests/test_cli_fit__linear_axis.py, exact model, seed 3: RMSE
#: 2.6 µm, 13x its 0.2 µm noise, on the position (the noise-driven closed-loop motion a
#: noise-free prediction does not have), 5.06 mA, 1.01x its 5 mA, on the current); two
#: orders of magnitude above the noise is a model that misses the data's structure
NOISE_FACTOR = 100.0
#: relative distance from a bound (of the bound interval, or of ln(factor)) that counts
#: as "at" it
AT_BOUND = 1e-3


def fit_quality(
    res: Any,
    *,
    bounds: Mapping[str, tuple[float, float]] | None = None,
    bound_factor: float | None = 3.0,
    max_delay: int | None = None,
    max_moves: int | None = None,
    low: float = LOW_FIT,
    poor: float = POOR_FIT,
    far: float = FAR_FACTOR,
    noise_factor: float = NOISE_FACTOR,
) -> list[str]:
    """One warning line per finding on fit result ``res`` (module docstring), in the order
    fit %, noise, bounds, std, start, delays; [] for a fit with nothing to say.

    ``bounds``: the fit's explicit bounds (path → (lo, hi), SI; ``--bound``,
    ``Priors.bounds``); ``bound_factor``: the general engine's default ×f bound of a
    log-space parameter without an explicit one (None: not checked; not applied to the
    servo rig, whose bounds are its own); ``max_delay`` / ``max_moves``: the general
    engine's delay search limits (default :class:`DelaySearch`'s)."""
    said = list(getattr(res, "warnings", None) or [])
    out: list[str] = []
    out += _low_fit(res, low, poor, said)
    out += _noise(res, noise_factor)
    out += _bounds(res, bounds or {}, bound_factor, said)
    out += _std(res, said)
    out += _far(res, far, said)
    out += _delays(res, max_delay, max_moves)
    return list(dict.fromkeys(w for w in out if w not in said))


def _linear_axis(res) -> bool:
    return bool(getattr(getattr(res, "scenario", None), "prismatic", False))


def _unit(res, signal: str) -> str:
    """The SI unit of ``signal`` in the fit's arm (m / m/s / N on a linear axis)."""
    from flexarm.io.logs import LINEAR_SI, signal_unit

    u = signal_unit(signal) or ""
    return LINEAR_SI.get(u, u) if _linear_axis(res) else u


def _figures(res) -> Iterable[tuple[str, str, float, float | None]]:
    """(log, signal, fit %, RMSE or None) of every scored signal."""
    for log, per in (getattr(res, "fit_percent", None) or {}).items():
        for sig, v in (per or {}).items():
            if v is None or not math.isfinite(float(v)):
                continue
            e = ((getattr(res, "rmse", None) or {}).get(log) or {}).get(sig)
            yield log, sig, float(v), (None if e is None else float(e))


def _low_fit(res, low: float, poor: float, said: list[str]) -> list[str]:
    out = []
    for log, sig, v, e in _figures(res):
        if v >= low or any(w.startswith(f"{log}: fit ") and f" on {sig} " in w for w in said):
            continue
        rm = f"; RMSE {e:.3g} {_unit(res, sig)}".rstrip() if e is not None else ""
        what = (
            f"below {poor:g} %: the model does not describe it" if v < poor else f"below {low:g} %"
        )
        out.append(f"{log}: fit {v:.3f} % on {sig} ({what}{rm})")
    return out


def _noise_level(res, signal: str) -> float:
    """sqrt(σ² + q²/12) of the fitted scenario's sensor ``signal`` (0: unknown)."""
    sensors = getattr(getattr(res, "scenario", None), "sensors", None) or {}
    s = sensors.get(signal)
    if s is None:
        return 0.0
    from flexarm.sim.build import sensor_quanta

    q = float(sensor_quanta({signal: s}).get(signal, 0.0) or 0.0)
    sigma = float(getattr(s, "noise", 0.0) or 0.0)
    return math.sqrt(sigma**2 + q**2 / 12.0)


def _noise(res, factor: float) -> list[str]:
    out = []
    for log, sig, _v, e in _figures(res):
        n = _noise_level(res, sig)
        if e is None or not n > 0 or not e > factor * n:
            continue
        u = _unit(res, sig)
        out.append(
            f"{log}: the residual on {sig} (RMSE {e:.3g} {u}) is {e / n:.3g} times the "
            f"sensor's noise level ({n:.3g} {u}): the model misses structure in the data"
        )
    return out


def _names(said: list[str], path: str, *words: str) -> bool:
    """Whether a warning already said of ``path`` one of ``words``."""
    return any(path in w and any(x in w for x in words) for w in said)


def _bounds(res, bounds, factor, said) -> list[str]:
    out = []
    linear = set((getattr(res, "stages", None) or {}).get("linear") or [])
    servo = "servo_rig" in (getattr(res, "stages", None) or {})
    for p, v in (getattr(res, "params", None) or {}).items():
        if not math.isfinite(v) or _names(said, p, "bound"):
            continue
        if p in bounds:
            lo, hi = (float(x) for x in bounds[p])
            tol = AT_BOUND * (hi - lo)
            if v <= lo + tol or v >= hi - tol:
                out.append(
                    f"{p} = {v:.4g} lies at a bound of [{lo:.4g}, {hi:.4g}]: the data pull it "
                    "further; widen the bound (--bound PATH=LO:HI) or check the model"
                )
            continue
        t = (getattr(res, "template", None) or {}).get(p)
        if factor is None or servo or p in linear or t is None:
            continue
        if not (math.isfinite(t) and t > 0 and v > 0 and factor > 1):
            continue
        lf = math.log(factor)
        if abs(abs(math.log(v / t)) - lf) <= AT_BOUND * lf:
            out.append(
                f"{p} = {v:.4g} lies at the default x{factor:g} bound of its start {t:.4g}: "
                f"the data pull it further; widen it (--bound {p}=LO:HI) or check the model"
            )
    return out


def _std(res, said) -> list[str]:
    out = []
    std = getattr(res, "std", None) or {}
    for p, v in (getattr(res, "params", None) or {}).items():
        s = std.get(p)
        if s is None or not math.isfinite(v) or (isinstance(s, float) and math.isnan(s)):
            continue
        if math.isinf(s):
            if not _names(said, p, "not determined", "does not depend"):
                out.append(f"{p} = {v:.4g}: its std is infinite; the data do not determine it")
            continue
        if s > abs(v):
            sign = " (its sign included)" if v <= 0 or p in _signed(res) else ""
            out.append(
                f"{p} = {v:.4g} ± {s:.3g}: the std exceeds the value; the data do not "
                f"determine it{sign}: fix it, give a prior, or log an experiment that moves it"
            )
    return out


def _signed(res) -> set[str]:
    return set((getattr(res, "stages", None) or {}).get("linear") or [])


def _far(res, far: float, said) -> list[str]:
    out = []
    tmpl = getattr(res, "template", None) or {}
    for p, v in (getattr(res, "params", None) or {}).items():
        t = tmpl.get(p)
        if t is None or not (math.isfinite(t) and math.isfinite(v)) or t == 0 or v == 0:
            continue
        r = abs(v / t)
        # a friction level or damping that falls towards 0 is a finding (the back-EMF
        # damping or the Coulomb level carries it: viscous 8e-8 N*m*s/rad on the 4/27 +
        # 5/2 fit), not a sign of the wrong model; one that grows is
        shrinks_freely = any(k in p for k in ("viscous", "friction.", "damping"))
        if (r > far or (r < 1 / far and not shrinks_freely)) and not _names(
            said, p, "times its start"
        ):
            out.append(
                f"{p} ended at {v:.4g}, {r:.3g} times its start {t:.4g} (the data sheet and "
                "the logs' estimates): the model may not describe this rig; check the "
                "data-sheet options, the log's units and the rig's kind"
            )
    return out


def _find(d: Any, key: str) -> Any:
    """The first value under ``key`` anywhere in nested dicts ``d`` (None if absent)."""
    if isinstance(d, Mapping):
        if key in d:
            return d[key]
        for v in d.values():
            f = _find(v, key)
            if f is not None:
                return f
    return None


def _delays(res, max_delay: int | None, max_moves: int | None) -> list[str]:
    from flexarm.identification.time_domain.options import DelaySearch

    stages = getattr(res, "stages", None) or {}
    out = []
    rec = stages.get("delay_search")
    if isinstance(rec, Mapping):
        top = DelaySearch().max_delay if max_delay is None else int(max_delay)
        moves = DelaySearch().max_moves if max_moves is None else int(max_moves)
        for c, d in (rec.get("channels") or {}).items():
            to = int(d.get("to", 0))
            if to >= top:
                out.append(
                    f"the delay of {c} ended at {to} samples, the search's edge (max_delay "
                    f"{top}): the data want a longer one; widen DelaySearch.max_delay or check "
                    "the sensor's timing"
                )
        if int(rec.get("moves", 0)) >= moves:
            now = ", ".join(f"{c} {d.get('to')}" for c, d in (rec.get("channels") or {}).items())
            out.append(
                f"the delay search stopped after {moves} moves (max_moves): the delays "
                f"({now} samples) may still be short of the best; raise "
                "DelaySearch.max_moves"
            )
    delays = (stages.get("servo_rig") or {}).get("delays_samples")
    ranges = _find(stages, "delay_ranges")
    if isinstance(delays, Mapping) and isinstance(ranges, Mapping):
        for c, d in delays.items():
            rg = ranges.get(c)
            if d is None or rg is None or len(rg) != 2:
                continue
            lo, hi = int(rg[0]), int(rg[1])
            if lo < hi and int(d) >= hi:
                out.append(
                    f"the delay of {c} ended at {int(d)} samples, the upper edge of its "
                    f"searched range {lo}..{hi}: the data may want a longer one (max_delay)"
                )
    return out
