"""Pydantic field types for physical quantities with units.

``Q("kg*m**2", gt=0)`` is a float field that accepts a bare number (SI) or a string with
units (``"0.005529 lbf*in*s**2"``), converts to SI, checks the dimension and the bound,
and says which value and unit were wrong.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Annotated, Any

from pydantic import (
    AfterValidator,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    FiniteFloat,
    PlainSerializer,
)

from flexarm.units import UnitError, to_si


@dataclass(frozen=True)
class Unit:
    """Metadata on a quantity field: its SI unit and bounds (read by the docs generator)."""

    unit: str
    bounds: str = ""
    what: str = ""


class Spec(BaseModel):
    """Base of every spec: unknown keys are errors, instances are immutable."""

    model_config = ConfigDict(extra="forbid", frozen=True, populate_by_name=True)


def Q(
    unit: str,
    *,
    gt: float | None = None,
    ge: float | None = None,
    le: float | None = None,
    what: str = "",
) -> Any:
    """A float field stored in SI ``unit``; optional bounds ``gt``, ``ge``, ``le`` (SI)."""

    def convert(v: object) -> float:
        try:
            x = to_si(v, unit, field="value")
        except UnitError as exc:
            raise ValueError(str(exc).removeprefix("value: ")) from None
        why = f" ({what})" if what else ""
        if gt is not None and not x > gt:
            raise ValueError(f"got {v!r} = {x:g} {unit}; must be > {gt:g} {unit}{why}")
        if ge is not None and not x >= ge:
            raise ValueError(f"got {v!r} = {x:g} {unit}; must be >= {ge:g} {unit}{why}")
        if le is not None and not x <= le:
            raise ValueError(f"got {v!r} = {x:g} {unit}; must be <= {le:g} {unit}{why}")
        return x

    bounds = ", ".join(
        f"{op} {v:g}" for op, v in ((">", gt), (">=", ge), ("<=", le)) if v is not None
    )
    return Annotated[
        float, BeforeValidator(convert), PlainSerializer(float), Unit(unit or "1", bounds, what)
    ]


def Count(*, ge: int = 0, le: int | None = None, what: str = "") -> Any:
    """A non-negative integer field (bits, samples, substeps)."""

    def convert(v: object) -> int:
        if (
            isinstance(v, bool)
            or not isinstance(v, (int, float))
            or (isinstance(v, float) and not math.isfinite(v))
            or int(v) != v
        ):
            raise ValueError(f"got {v!r}; expected a whole number")
        n = int(v)
        why = f" ({what})" if what else ""
        if n < ge or (le is not None and n > le):
            hi = f" and <= {le}" if le is not None else ""
            raise ValueError(f"got {n}; must be >= {ge}{hi}{why}")
        return n

    return Annotated[
        int,
        BeforeValidator(convert),
        Unit("count", f">= {ge}" + (f", <= {le}" if le is not None else ""), what),
    ]


def _leading_nonzero(c: list[float]) -> list[float]:
    if c and c[0] == 0.0:
        raise ValueError(
            f"got {c!r}: the leading coefficient (highest power) is 0; drop "
            "leading zeros (coefficients in descending powers)"
        )
    return c


def Coefficients(*, min_length: int = 1, denominator: bool = False) -> Any:
    """Polynomial coefficients in descending powers: finite numbers; for a denominator,
    a non-zero leading coefficient.  (TOML and Python accept ``nan`` and ``inf``, which a
    bare ``list[float]`` field lets through to break the model later.)"""
    t = Annotated[list[FiniteFloat], Field(min_length=min_length)]
    return Annotated[t, AfterValidator(_leading_nonzero)] if denominator else t
