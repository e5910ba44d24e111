"""Paths into a scenario: the language the fit, the design tuner and the CLI name numbers in.

A path is dotted field names with ``[index]`` for list elements, read against the scenario's
``model_dump()`` (SI values)::

    "arm.joints[0].friction.coulomb"      →  ["arm", "joints", 0, "friction", "coulomb"]
    "arm.links[*].torsional_stiffness"    →  every link ("[*]" expands, :func:`expand_paths`)
    "sensors.theta_1.gain"

:func:`get` and :func:`set` read and write one number of a dumped scenario (a plain dict);
:func:`scenario_with` returns a validated scenario with numbers replaced.
"""

from __future__ import annotations

import copy
import re
from collections.abc import Mapping, Sequence
from typing import Any

__all__ = ["parse_path", "get", "set", "expand_paths", "format_path", "scenario_with"]

_TOKEN = re.compile(r"\.?([A-Za-z_][A-Za-z0-9_]*)|\[(\d+|\*)\]")

Keys = Sequence["str | int"]


def parse_path(path: str, what: str = "free parameter") -> list[str | int]:
    """``"arm.joints[0].friction.coulomb"`` → ``["arm", "joints", 0, "friction", "coulomb"]``
    (``[*]`` stays ``"*"``). ``what`` names the path in the error (``"free parameter"``,
    ``"tuned parameter"``, ``"--spread"``)."""
    keys: list[str | int] = []
    pos = 0
    for m in _TOKEN.finditer(path):
        if m.start() != pos:
            break
        keys.append(
            m.group(1) if m.group(1) else (m.group(2) if m.group(2) == "*" else int(m.group(2)))
        )
        pos = m.end()
    if pos != len(path) or not keys:
        raise ValueError(
            f"{what} {path!r}: not a path into the scenario; write it as "
            "dotted names with [index] for lists, e.g. "
            "'arm.joints[0].friction.coulomb' or 'sensors.theta_1.gain'"
        )
    return keys


def _keys(path: str | Keys, what: str) -> tuple[list, str]:
    if isinstance(path, str):
        return parse_path(path, what), path
    keys = list(path)
    return keys, format_path(keys)


def get(d: Any, path: str | Keys, what: str = "free parameter") -> Any:
    """The value at ``path`` (a string or parsed keys) in the dumped scenario ``d``; a
    missing key is one error line naming the path, where it stops and what is there."""
    keys, text = _keys(path, what)
    for i, k in enumerate(keys):
        try:
            d = d[k]
        except (KeyError, IndexError, TypeError):
            here = format_path(keys[:i]) or "the scenario"
            have = (
                ", ".join(map(str, d))
                if isinstance(d, dict)
                else f"{len(d)} entries"
                if isinstance(d, list)
                else type(d).__name__
            )
            raise ValueError(f"{what} {text!r}: {here} has no {k!r} (it has {have})") from None
    return d


def set(d: Any, path: str | Keys, value: Any, what: str = "free parameter") -> None:
    """Write ``value`` at ``path`` in the dumped scenario ``d`` (in place); the parent must
    exist (:func:`get`'s error otherwise)."""
    keys, text = _keys(path, what)
    parent = get(d, keys[:-1], what) if len(keys) > 1 else d
    try:
        parent[keys[-1]] = value
    except (IndexError, TypeError):
        raise ValueError(
            f"{what} {text!r}: cannot set {keys[-1]!r} in "
            f"{format_path(keys[:-1]) or 'the scenario'}"
        ) from None


def format_path(keys: Keys) -> str:
    """Parsed keys back to the path text (:func:`parse_path`'s inverse)."""
    s = ""
    for k in keys:
        s += f"[{k}]" if isinstance(k, int) or k == "*" else (f".{k}" if s else k)
    return s


def expand_paths(dump: dict, paths: Sequence[str], what: str = "free parameter") -> list[str]:
    """The paths with every ``[*]`` replaced by each index of that list."""
    out: list[str] = []
    for p in paths:
        keys = parse_path(p, what)
        if "*" not in keys:
            out.append(p)
            continue
        i = keys.index("*")
        lst = get(dump, keys[:i], what)
        if not isinstance(lst, list):
            raise ValueError(f"{what} {p!r}: [*] needs a list; found {type(lst).__name__}")
        out += expand_paths(
            dump,
            [format_path(list(keys[:i]) + [j] + list(keys[i + 1 :])) for j in range(len(lst))],
            what,
        )
    return out


def scenario_with(template, values: Mapping[str, float]):
    """The scenario with the numbers at ``values`` (path → SI value). A friction's breakaway
    ``static`` below its ``coulomb`` level is raised to it (Karnopp needs F_s ≥ F_c)."""
    from flexarm.specs.scenario import scenario_from_dict

    d = copy.deepcopy(template.model_dump())
    for path, v in values.items():
        set(d, path, float(v))
    _raise_breakaway(d)
    return scenario_from_dict(d, source=f"scenario {template.name!r} with fitted values")


def _raise_breakaway(d: dict) -> None:
    joints = (d.get("arm") or {}).get("joints") or []
    frs = [j.get("friction") for j in joints if isinstance(j, dict)]
    fr1 = (d.get("arm") or {}).get("friction")
    for fr in frs + [fr1]:
        if isinstance(fr, dict) and fr.get("static") is not None:
            fr["static"] = max(fr["static"], fr.get("coulomb", 0.0))
