"""One pint registry for the whole package, and the conversion of scenario quantities to SI.

Scenario files may give a quantity as a bare number (taken in SI units) or as a string
with units, e.g. ``"0.005529 lbf*in*s**2"``, ``"7 in"``, ``"55 g"``, ``"400 mrad"``.
Everything inside flexarm is SI: kg, m, s, rad, A, V, N*m.
"""

from __future__ import annotations

import math
from typing import Any

import pint

from flexarm.errors import FlexarmError  # the one error base (issue #25)

ureg = pint.UnitRegistry()
ureg.define("count = []")

# Paper unit constants, exact by definition of the inch and the pound-force.
LBF_IN = 0.112984829027616  # N*m per lb*in
INCH = 0.0254  # m per in


class UnitError(FlexarmError, ValueError):
    """A quantity whose text cannot be parsed or whose unit does not fit the field."""


def to_si(value: object, unit: str, *, field: str = "value") -> float:
    """Convert ``value`` to a float in the SI unit ``unit``.

    Parameters
    ----------
    value:
        A number (already SI), or a string such as ``"7 in"``.
    unit:
        The SI unit the field is stored in, e.g. ``"kg*m**2"``, ``"N*m*s/rad"``.
        Radians are dimensionless, as in SI.
    field:
        Name used in error messages.
    """
    if isinstance(value, bool):
        raise UnitError(f"{field}: got {value!r}; expected a number or a quantity in {unit}")
    if isinstance(value, (int, float)):
        try:
            x = float(value)
        except OverflowError:  # an int beyond float range (Python and tomllib allow them)
            raise UnitError(f"{field}: got {value!r}, which is not a finite number") from None
    elif isinstance(value, str) and _is_number(value):
        x = float(value)
    elif isinstance(value, str):
        text = value.strip()
        try:
            q = ureg.Quantity(text)
        except Exception as exc:  # pint raises several exception types
            raise UnitError(
                f"{field}: cannot read {value!r} as a quantity ({exc}); write e.g. '1.5 {unit}'"
            ) from None
        target = ureg.Quantity(1.0, unit)
        if not isinstance(q, pint.Quantity):
            q = ureg.Quantity(float(q), "dimensionless")
        if q.dimensionality != target.dimensionality:
            raise UnitError(
                f"{field}: {value!r} has units of {q.units:~} "
                f"({_dims(q)}), but this field expects {unit} ({_dims(target)})"
            )
        x = float(q.to(unit).magnitude)
    else:
        raise UnitError(
            f"{field}: got {value!r} of type {type(value).__name__}; "
            f"expected a number (SI, {unit}) or a string with units"
        )
    if not math.isfinite(x):
        raise UnitError(f"{field}: got {value!r}, which is not a finite number")
    return x


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _dims(q: Any) -> str:  # a pint quantity (of one of pint's Quantity classes)
    d = str(q.dimensionality)
    return "dimensionless" if d == "dimensionless" else d
