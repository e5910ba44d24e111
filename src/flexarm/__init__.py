"""flexarm: model, identify, simulate and control flexible-link robot arms with joint friction.

The public face (everything else lives in the sub-packages, named after what they hold):

* scenarios and logs: :func:`load_scenario`, :func:`builtin_scenarios`, :class:`Scenario`,
  :func:`load_log` (text or MATLAB logs through a log-format file)
* models: :class:`Arm` (the one plant of every arm: links, drives, joint friction),
  :class:`SingleLinkModel` (FRB eqs. 1, 12-16), :func:`build_multilink` (De Luca),
  :func:`linearize` (a named python-control ``StateSpace`` of any arm)
* simulation, one sampled-data loop for every arm: :func:`simulate`, :func:`prepare`,
  :func:`simulate_batch` (a ``vmap`` batch of a prepared loop), :class:`SimulationResult`
  (a python-control ``TimeResponseData``)
* control: :func:`wiener_feedforward` (FRB eq. 11), :func:`parabolic`,
  :func:`quasi_parabolic`, :func:`lqg` (discrete observer-based design), :func:`design`
  (a controller for a scenario's rig: ``lqr``, ``place``; a :class:`flexarm.design.Design`)
* identification: :func:`fit` (time domain, the one front door: a scenario or a rig preset,
  logs, an optional ``free`` list (default: the preset's), grouped options; returns the one
  :class:`~flexarm.identification.time_domain.result.FitResult`), :func:`validate` (=
  :func:`predict`: fit % per log and signal, a
  :class:`~flexarm.identification.time_domain.predict.Prediction`), :func:`identify` (FRB
  Sec. II), :func:`periodic_frf`, :func:`tfest` (frequency domain)

The data path, one way: a lab file → :func:`load_log` (one :class:`~flexarm.io.logs.Log`,
with the controller the lab ran) → :func:`fit` → ``FitResult`` (``to_dict()`` is the JSON)
→ :func:`validate` / :func:`predict` → design.

Importing flexarm is cheap: each public name loads its module on first use (PEP 562), so
``import flexarm`` does not import JAX, SciPy, python-control or matplotlib.

**Float64.** flexarm's models and simulations run JAX in float64. JAX has one, process-wide
switch for it (``jax_enable_x64``); flexarm turns it on when it is imported: before JAX is
imported, through JAX's own ``JAX_ENABLE_X64`` environment variable (an explicit value the
user set is kept), and, if JAX is already imported, by ``jax.config.update``. Set
``FLEXARM_ENABLE_X64=0`` to leave JAX's setting alone (flexarm's results then assume the
float64 you provide; with float32 its tolerances do not hold).
"""

import importlib as _importlib
import os as _os
import sys as _sys
from typing import TYPE_CHECKING

from flexarm.version import __version__ as __version__  # the re-export: flexarm.__version__

if TYPE_CHECKING:  # the lazy names below, for type checkers and editors (not run)
    from flexarm import design as design
    from flexarm.control.lqg import lqg as lqg
    from flexarm.control.trajectories import parabolic as parabolic
    from flexarm.control.trajectories import quasi_parabolic as quasi_parabolic
    from flexarm.control.wiener import wiener_feedforward as wiener_feedforward
    from flexarm.identification import fit as fit
    from flexarm.identification import predict as predict
    from flexarm.identification import validate as validate
    from flexarm.identification.frequency_domain.identify import identify as identify
    from flexarm.identification.frequency_domain.periodic import periodic_frf as periodic_frf
    from flexarm.identification.frequency_domain.tfest import tfest as tfest
    from flexarm.io.logformat import load_log as load_log
    from flexarm.models.assembly import Arm as Arm
    from flexarm.models.linearize import linearize as linearize
    from flexarm.models.multilink import build_multilink as build_multilink
    from flexarm.models.single_link import SingleLinkModel as SingleLinkModel
    from flexarm.sim.build import prepare as prepare
    from flexarm.sim.build import simulate as simulate
    from flexarm.sim.result import SimulationResult as SimulationResult
    from flexarm.sim.sampled import simulate_batch as simulate_batch
    from flexarm.specs import Scenario as Scenario
    from flexarm.specs import builtin_scenarios as builtin_scenarios
    from flexarm.specs import load_scenario as load_scenario


def _enable_x64() -> None:
    """Float64 in JAX, unless ``FLEXARM_ENABLE_X64=0`` (module docstring)."""
    if _os.environ.get("FLEXARM_ENABLE_X64", "1") == "0":
        return
    if "jax" in _sys.modules:
        _sys.modules["jax"].config.update("jax_enable_x64", True)
    else:
        _os.environ.setdefault("JAX_ENABLE_X64", "1")


_enable_x64()

#: public name -> the module that defines it (loaded on first use)
_LAZY = {
    "lqg": "flexarm.control.lqg",
    "parabolic": "flexarm.control.trajectories",
    "quasi_parabolic": "flexarm.control.trajectories",
    "wiener_feedforward": "flexarm.control.wiener",
    "fit": "flexarm.identification",
    "predict": "flexarm.identification",
    "validate": "flexarm.identification",
    "identify": "flexarm.identification.frequency_domain.identify",
    "periodic_frf": "flexarm.identification.frequency_domain.periodic",
    "tfest": "flexarm.identification.frequency_domain.tfest",
    "load_log": "flexarm.io.logformat",
    "Arm": "flexarm.models.assembly",
    "linearize": "flexarm.models.linearize",
    "build_multilink": "flexarm.models.multilink",
    "SingleLinkModel": "flexarm.models.single_link",
    "prepare": "flexarm.sim.build",
    "simulate": "flexarm.sim.build",
    "SimulationResult": "flexarm.sim.result",
    "simulate_batch": "flexarm.sim.sampled",
    "Scenario": "flexarm.specs",
    "builtin_scenarios": "flexarm.specs",
    "load_scenario": "flexarm.specs",
}


def __getattr__(name: str):
    if name == "design":  # the design package itself is callable (the front door)
        mod = _importlib.import_module("flexarm.design")
        globals()["design"] = mod
        return mod
    if name in _LAZY:
        value = getattr(_importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'flexarm' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted([*globals(), *_LAZY, "design"])


__all__ = [
    "Arm",
    "Scenario",
    "SimulationResult",
    "SingleLinkModel",
    "build_multilink",
    "builtin_scenarios",
    "design",
    "fit",
    "identify",
    "linearize",
    "load_scenario",
    "lqg",
    "parabolic",
    "periodic_frf",
    "predict",
    "prepare",
    "quasi_parabolic",
    "load_log",
    "simulate",
    "simulate_batch",
    "tfest",
    "validate",
    "wiener_feedforward",
]
