"""Shared builders for the tests."""

import tomllib

import jax.numpy as jnp

from flexarm.control.discrete import FunctionController
from flexarm.specs import builtin_scenarios, scenario_from_dict


def scenario_dict(name: str = "feliu-single-mass") -> dict:
    return tomllib.loads(builtin_scenarios()[name].read_text())


def scenario(name: str = "feliu-single-mass", **patch):
    """A built-in scenario with sections patched: patch(arm={'friction': {...}}) etc."""
    d = scenario_dict(name)
    for section, values in patch.items():
        _merge(d.setdefault(section, {}), values) if isinstance(values, dict) else d.__setitem__(
            section, values
        )
    return scenario_from_dict(d)


def _merge(d: dict, new: dict) -> None:
    for k, v in new.items():
        if (
            isinstance(v, dict)
            and isinstance(d.get(k), dict)
            and not {"model", "type", "drive"} & set(v)
        ):
            _merge(d[k], v)
        else:
            d[k] = v


def constant_command(u: float) -> FunctionController:
    """Open loop: the same command at every sample."""
    return FunctionController(
        lambda p, s, m, r: (s, jnp.reshape(p, (1,))), jnp.asarray(u), jnp.zeros(())
    )
