"""Option values written as text (``START:STOP``, ``NAME=VALUE``, comma lists, poles,
weights) → Python values; a malformed one is refused as one line naming the option, the
value and an example (exit 2), never a traceback."""

from __future__ import annotations

import math

import typer

from flexarm.cli.common import fail


def window(text: str | None, option: str) -> tuple[float, float] | None:
    """``START:STOP`` (s from a log's first sample) → (start, stop)."""
    if not text:
        return None
    try:
        a, b = (float(x) for x in text.split(":"))
    except ValueError:
        fail(
            f"{option} {text!r}: expected START:STOP in seconds from the log's first "
            "sample, e.g. 0:5"
        )
    if not (math.isfinite(a) and math.isfinite(b) and b > a >= 0):
        fail(f"{option} {text!r}: need 0 <= START < STOP (s)")
    return a, b


def pairs(items: list[str] | None, what: str) -> dict[str, str]:
    """``NAME=VALUE`` options (repeated) → dict."""
    out = {}
    for it in items or []:
        if "=" not in it:
            fail(f"--{what} {it!r}: expected NAME=VALUE, e.g. --{what} current=i_m")
        k, v = it.split("=", 1)
        out[k.strip()] = v.strip()
    return out


def filters(items: list[str] | None) -> dict[str, float] | None:
    """``--filter CHANNEL=HZ`` → {channel: cutoff in Hz}."""
    out = {}
    for k, v in pairs(items, "filter").items():
        try:
            out[k] = float(v)
        except ValueError:
            fail(f"--filter {k}={v}: the cutoff must be a number in Hz, e.g. --filter {k}=50")
    return out or None


def floats(text: str | None, what: str) -> list[float]:
    """``"1,3,9"`` → [1.0, 3.0, 9.0] (rad/s)."""
    if not text:
        return []
    try:
        return [float(x) for x in text.replace(";", ",").split(",") if x.strip()]
    except ValueError:
        fail(f"{what} {text!r}: expected numbers separated by commas (rad/s)")


def ints(text: str, option: str, count: int | None = None, example: str = "2,4") -> tuple[int, ...]:
    """``"2,4"`` → (2, 4): whole numbers >= 0, ``count`` of them when given."""
    try:
        out = tuple(int(x) for x in text.replace(" ", "").split(","))
    except ValueError:
        out = ()
    if not out or (count is not None and len(out) != count) or min(out) < 0:
        n = f"{count} " if count is not None else ""
        fail(
            f"{option} {text!r}: expected {n}whole numbers >= 0 separated by commas, "
            f"e.g. {option} {example}"
        )
    return out


def int_list(text: str | None, option: str, example: str = "0,0,1") -> list[int] | None:
    """``"0,0,1"`` → [0, 0, 1] (one per log)."""
    if text is None:
        return None
    try:
        return [int(x) for x in text.replace(";", ",").split(",") if x.strip()]
    except ValueError:
        fail(f"{option} {text!r}: expected whole numbers, one per log, e.g. {example}")


def complex_list(text: str | None, option: str) -> list[complex] | None:
    """``"-20+15j,-20-15j,-30"`` → complex numbers; a clear error naming the option."""
    if text is None:
        return None
    out = []
    for item in text.replace(" ", "").split(","):
        try:
            out.append(complex(item.replace("i", "j")))
        except ValueError:
            fail(
                f"{option} {text!r}: {item!r} is not a number; give comma-separated poles, "
                f"e.g. {option} '-20+15j,-20-15j,-30'"
            )
    return out


def weights(text: str | None, option: str):
    """``"motor_angle=1e3,tip_deflection=10"`` → dict, or ``"1e3,10"`` → numbers."""
    if text is None:
        return None
    items = [t for t in text.replace(" ", "").split(",") if t]
    try:
        if all("=" in t for t in items):
            return {k: float(v) for k, v in (t.split("=", 1) for t in items)}
        return [float(t) for t in items]
    except ValueError:
        fail(
            f"{option} {text!r}: give numbers (one per channel) or CHANNEL=WEIGHT pairs, "
            f"e.g. {option} motor_angle=1e3,tip_deflection=10"
        )


def channels(channel: list[str] | None) -> dict | None:
    """``--channel NAME`` or ``NAME=WEIGHT`` (repeated) → {name: weight}."""
    if not channel:
        return None
    out = {}
    for c in channel:
        name, _, w = c.partition("=")
        try:
            out[name.strip()] = float(w) if w else 1.0
        except ValueError:
            fail(f"--channel {c!r}: expected NAME or NAME=WEIGHT (a number)")
    return out


def priors(prior: list[str] | None) -> dict:
    """``--prior PATH=REL_STD`` (repeated) → {path: relative std}."""
    out = {}
    for x in prior or []:
        path, _, v = x.rpartition("=")
        try:
            out[path.strip()] = float(v)
        except ValueError:
            path = ""
        if not path:
            fail(
                f"--prior {x!r}: expected PATH=REL_STD, e.g. "
                "'arm.joints[0].drive.torque_constant=0.3'"
            )
    return out


def session_starts(items: list[str] | None) -> dict[int, dict[str, float]]:
    """``--session-start S:PATH=VALUE`` (repeated) → {session: {path: start value (SI)}}."""
    out: dict[int, dict[str, float]] = {}
    for x in items or []:
        head, _, v = x.rpartition("=")
        s_, _, path = head.partition(":")
        try:
            k, val = int(s_), float(v)
        except ValueError:
            k, val, path = -1, math.nan, ""
        if k < 1 or not path.strip() or not math.isfinite(val):
            fail(
                f"--session-start {x!r}: expected S:PATH=VALUE, a later session (1, 2, ...), "
                "a per-session path and its start in SI, e.g. "
                "'1:sensors.tip_deflection.gain=0.655' (a gauge read with the other sign)"
            )
        out.setdefault(k, {})[path.strip()] = val
    return out


def positive_floats(text: str, option: str, count: int, example: str) -> list[float]:
    """``"0.94,1.2"`` → [0.94, 1.2]: ``count`` numbers > 0."""
    try:
        vals = [float(x) for x in text.split(",")]
    except ValueError:
        vals = []
    if len(vals) != count or not all(math.isfinite(v) and v > 0 for v in vals):
        fail(f"{option} {text!r}: give {count} positive numbers, e.g. {example}")
    return vals


def json_file(path, option: str, what: str = "a JSON object") -> dict:
    """A JSON file given on the command line → its data, a JSON object (``{...}``);
    unreadable, not a regular file (``/dev/zero``), over 1 GiB, malformed, nested beyond
    the recursion limit or another JSON value (a list) is one line naming the file."""
    import json

    from flexarm.errors import FlexarmError
    from flexarm.io.write import read_input

    try:
        d = json.loads(read_input(path, what="JSON file").decode("utf-8"))
    except FlexarmError as exc:
        fail(f"{option} {exc}" if option else str(exc))
    except RecursionError:
        fail(f"{option} {path}: nested too deeply to read; give {what}".strip())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        fail(f"{option} {path}: cannot read it as JSON ({exc})".strip())
    if not isinstance(d, dict):
        fail(f"{option} {path}: a JSON {type(d).__name__}, not {what}".strip())
    return d


def number(
    *,
    gt: float | None = None,
    ge: float | None = None,
    lt: float | None = None,
    le: float | None = None,
    example: str | None = None,
):
    """A parse-time check of a numeric option (typer ``callback=``): the value (or each of
    a repeated option's) must be finite and inside the bounds given (``gt``: > , ``ge``:
    >=, ``lt``: <, ``le``: <=); ``None`` (not given) passes. A value outside is refused by
    the parser as one line naming the option, the value and the range (exit 2), before
    any work: ``--fs 0``, ``--rms nan``, ``--gear-ratio inf``, ``--computation-delay -1``."""
    parts = []
    if gt is not None:
        parts.append(f"> {gt:g}")
    if ge is not None:
        parts.append(f">= {ge:g}")
    if lt is not None:
        parts.append(f"< {lt:g}")
    if le is not None:
        parts.append(f"<= {le:g}")
    want = "a finite number" + (" " + " and ".join(parts) if parts else "")

    def check(ctx: typer.Context, param: typer.CallbackParam, value):
        if value is None or (ctx is not None and getattr(ctx, "resilient_parsing", False)):
            return value
        for v in value if isinstance(value, (list, tuple)) else [value]:
            ok = isinstance(v, (int, float)) and math.isfinite(v)
            ok = ok and (gt is None or v > gt) and (ge is None or v >= ge)
            ok = ok and (lt is None or v < lt) and (le is None or v <= le)
            if not ok:
                opt = param.opts[0] if param is not None and param.opts else "the value"
                eg = f", e.g. {opt} {example}" if example else ""
                raise typer.BadParameter(f"{v!r}: give {want}{eg}")
        return value

    return check
