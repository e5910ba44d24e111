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
"""

import jax as _jax

_jax.config.update("jax_enable_x64", True)

from flexarm.control.lqg import lqg  # noqa: E402
from flexarm.control.trajectories import parabolic, quasi_parabolic  # noqa: E402
from flexarm.control.wiener import wiener_feedforward  # noqa: E402
import flexarm.design as design  # noqa: E402  (callable: the front door)
from flexarm.identification import fit, predict, validate  # noqa: E402
from flexarm.identification.frequency_domain.identify import identify  # noqa: E402
from flexarm.identification.frequency_domain.periodic import periodic_frf  # noqa: E402
from flexarm.identification.frequency_domain.tfest import tfest  # noqa: E402
from flexarm.io.logformat import load_log  # noqa: E402
from flexarm.models.assembly import Arm  # noqa: E402
from flexarm.models.linearize import linearize  # noqa: E402
from flexarm.models.multilink import build_multilink  # noqa: E402
from flexarm.models.single_link import SingleLinkModel  # noqa: E402
from flexarm.sim.build import prepare, simulate  # noqa: E402
from flexarm.sim.result import SimulationResult  # noqa: E402
from flexarm.sim.sampled import simulate_batch  # noqa: E402
from flexarm.specs import Scenario, builtin_scenarios, load_scenario  # noqa: E402

__version__ = "0.1.0"

__all__ = [
    "Arm", "Scenario", "SimulationResult", "SingleLinkModel", "build_multilink",
    "builtin_scenarios", "design", "fit", "identify", "linearize", "load_scenario", "lqg",
    "parabolic", "periodic_frf", "predict", "prepare", "quasi_parabolic", "load_log", "simulate", "simulate_batch",
    "tfest", "validate", "wiener_feedforward",
]
