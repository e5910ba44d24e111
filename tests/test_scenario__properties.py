"""Property tests of scenario validation (issue #12, item 3): a scenario dict or TOML file
mutated at random (wrong types, units, signs, non-finite numbers, missing and unknown
keys) gives either a valid scenario whose numbers are all finite, or a ScenarioError
whose message names the mutated field; never another exception.

Inputs start from the built-in scenarios (every section and field of the schema that
they use) and change one or two leaves, so most examples reach the field validators
instead of failing on the first missing section.  Bounded examples, derandomised
(profile ``flexarm`` in conftest.py), so the suite is repeatable and fast.
"""

from __future__ import annotations

import math
import tomllib

import pytest

from flexarm.specs import builtin_scenarios, load_scenario
from flexarm.specs.scenario import MultiLinkScenario, Scenario, ScenarioError, scenario_from_dict

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import given, settings  # noqa: E402 - optional: after importorskip
from hypothesis import strategies as st  # noqa: E402 - optional: after importorskip

BASES = {name: tomllib.loads(p.read_text()) for name, p in sorted(builtin_scenarios().items())}


def _leaves(d, prefix=()):
    """Paths (tuples of keys / list indices) of every value in a parsed TOML tree."""
    out = []
    items = d.items() if isinstance(d, dict) else enumerate(d)
    for k, v in items:
        path = (*prefix, k)
        out.append(path)
        if isinstance(v, (dict, list)):
            out.extend(_leaves(v, path))
    return out


def _get(d, path):
    for k in path:
        d = d[k]
    return d


def _copy(d):
    return tomllib.loads(__import__("tomli_w").dumps(d))


# what a user may wrongly write for a quantity (TOML-representable, except that tomllib
# reads integers of any size): non-finite and extreme numbers get their own branch so
# that every field meets them within the bounded examples
specials = st.sampled_from(
    [
        math.nan,
        math.inf,
        -math.inf,
        0.0,
        -0.0,
        -1.0,
        -1e-300,
        1e308,
        10**400,
        -(10**400),
        2**63,
        0.5,
        1.5,
        3,
    ]
)
bad_values = st.one_of(
    specials,
    st.lists(specials, min_size=1, max_size=3),
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(),
    st.booleans(),
    st.sampled_from(
        [
            "",
            "abc",
            "1 kg",
            "-3 m",
            "2 in",
            "0.5 lbf*in",
            "400 mrad",
            "1e999 m",
            "nan",
            "inf s",
            "5 Hz",
            "100 rad/s",
            "3 ms",
            "1 kg*m**2",
            "7 V*s/rad",
            "12 bits",
            "1 / 0",
            "kg",
            "1 m m",
            "((",
            "1 degC",
            "current",
            "voltage",
            "lumped",
            "pd",
            "step",
            "coulomb",
            "motor_angle",
            "tip_angle",
            "1e400 kg",
            "10**400 m",
            "0 s",
            "-0.5",
        ]
    ),
    st.text(max_size=12),
    st.just({}),
    st.just({"x": 1}),
)
#: whole sections a user may write instead of the built-in ones: every controller type,
#: complete, with extreme or non-finite numbers
coeffs = st.lists(specials, min_size=1, max_size=3)
controllers = st.one_of(
    st.fixed_dictionaries({"type": st.just("pd"), "kp": specials, "kd": specials}),
    st.fixed_dictionaries({"type": st.just("pid"), "kp": specials, "ki": specials, "kd": specials}),
    st.fixed_dictionaries(
        {"type": st.just("lead"), "gain": specials, "zero": specials, "pole": specials}
    ),
    st.fixed_dictionaries({"type": st.just("tf"), "num": coeffs, "den": coeffs}),
    st.fixed_dictionaries(
        {
            "type": st.just("state_feedback"),
            "k1": specials,
            "k2": specials,
            "rate": st.sampled_from(["backward", "filtered"]),
            "rate_time_constant": specials,
        }
    ),
)


@st.composite
def mutated(draw):
    name = draw(st.sampled_from(sorted(BASES)))
    data = _copy(BASES[name])
    paths = _leaves(data)
    changed = []
    for _ in range(draw(st.integers(1, 2))):
        paths = _leaves(data)
        path = draw(st.sampled_from(paths))
        parent = _get(data, path[:-1])
        how = draw(
            st.sampled_from(["replace", "replace", "replace", "delete", "unknown", "controller"])
        )
        if how == "controller" and "arm" in data and data["arm"].get("kind") != "multi_link":
            data["controller"] = draw(controllers)
            path = ("controller",)
        elif how == "delete" and isinstance(parent, dict):
            del parent[path[-1]]
        elif how == "unknown" and isinstance(parent, dict):
            key = draw(st.sampled_from(["inertial", "lenght", "Kp", "extra", "units"]))
            parent[key] = draw(bad_values)
            path = (*path[:-1], key)
        elif isinstance(parent, list) and all(isinstance(v, (int, float)) for v in parent):
            parent[path[-1]] = draw(specials)  # one coefficient / entry of a number list
        else:
            parent[path[-1]] = draw(bad_values)
        changed.append(path)
    return name, data, changed


def _finite_numbers(x, where="") -> list[str]:
    """Paths of non-finite floats in a dumped spec."""
    if isinstance(x, float):
        return [] if math.isfinite(x) else [where]
    if isinstance(x, dict):
        return [p for k, v in x.items() for p in _finite_numbers(v, f"{where}.{k}")]
    if isinstance(x, (list, tuple)):
        return [p for i, v in enumerate(x) for p in _finite_numbers(v, f"{where}[{i}]")]
    return []


def _named(msg: str, path: tuple) -> bool:
    """The message names the field: its key (or, for a list item, the list's key; for a
    replaced controller section, the section)."""
    keys = [str(k) for k in path if isinstance(k, str)]
    return any(k in msg for k in keys[-1:])


def _check(data, changed, load):
    try:
        sc = load(data)
    except ScenarioError as exc:
        msg = str(exc)
        assert any(_named(msg, p) for p in changed), (changed, msg)
        return "error"
    assert isinstance(sc, (Scenario, MultiLinkScenario))
    bad = _finite_numbers(sc.model_dump())
    assert not bad, f"valid scenario with non-finite numbers at {bad} (changed {changed})"
    if sc.arm.kind == "single_link":
        # a valid arm gives a model, or a ValueError naming the beam (the model layer's
        # checks: proper and stable G_b, a non-singular flexibility); the CLI turns it
        # into a one-line error (tests/test_cli.py)
        from flexarm.models.single_link import SingleLinkModel

        try:
            SingleLinkModel.from_spec(sc.arm)
        except ValueError as exc:
            assert any(k in str(exc) for k in ("arm.beam", "tip_", "coupling_")), str(exc)
    return "valid"


@settings(max_examples=400)
@given(mutated())
def test_mutated_scenario_dicts_are_valid_or_name_the_field(case):
    _name, data, changed = case
    _check(data, changed, lambda d: scenario_from_dict(d, source="fuzz"))


@settings(max_examples=60)
@given(mutated())
def test_mutated_scenario_files_are_valid_or_name_the_field(tmp_path_factory, case):
    """The TOML path (load_scenario): the same dicts written as files."""
    import tomli_w

    _name, data, changed = case
    f = tmp_path_factory.mktemp("sc") / "s.toml"
    f.write_text(tomli_w.dumps(data))
    _check(data, changed, lambda d: load_scenario(f))


@settings(max_examples=80)
@given(st.binary(max_size=200) | st.text(max_size=200).map(str.encode))
def test_any_file_content_is_a_scenario_error_naming_the_file(tmp_path_factory, content):
    f = tmp_path_factory.mktemp("raw") / "raw.toml"
    f.write_bytes(content)
    with pytest.raises(ScenarioError, match="raw.toml"):
        load_scenario(f)


def test_a_folder_or_missing_file_is_a_scenario_error(tmp_path):
    with pytest.raises(ScenarioError, match="is a folder"):
        load_scenario(tmp_path)
    with pytest.raises(ScenarioError, match="no such file"):
        load_scenario(tmp_path / "nope.toml")
