"""flexarm: model, identify, simulate and control flexible-link robot arms with joint friction.

The public face (everything else lives in the sub-packages, named after what they hold):

* scenarios: :func:`load_scenario`, :func:`builtin_scenarios`, :class:`Scenario`
* models: :class:`SingleLinkModel` (FRB eqs. 1, 12-16), :func:`build_multilink` (De Luca)
* simulation: :func:`simulate` (sampled-data closed loop), :class:`SimulationResult`
* control: :func:`wiener_feedforward` (FRB eq. 11), trajectories, discrete controllers
* identification: :func:`identify` (FRB Sec. II), :func:`fit` and :func:`validate`
  (time-domain fit of bench logs), :func:`tfest` (frequency-domain transfer-function fit)
"""

import jax as _jax

_jax.config.update("jax_enable_x64", True)

from flexarm.identification.time_domain import fit, validate  # noqa: E402
from flexarm.control.trajectories import parabolic, quasi_parabolic  # noqa: E402
from flexarm.control.wiener import wiener_feedforward  # noqa: E402
from flexarm.identification.frequency_domain.identify import identify  # noqa: E402
from flexarm.identification.frequency_domain.tfest import tfest  # noqa: E402
from flexarm.models.multilink import build_multilink  # noqa: E402
from flexarm.models.single_link import SingleLinkModel  # noqa: E402
from flexarm.sim.build import simulate  # noqa: E402
from flexarm.sim.result import SimulationResult  # noqa: E402
from flexarm.specs import Scenario, builtin_scenarios, load_scenario  # noqa: E402

__version__ = "0.1.0"

__all__ = [
    "tfest", "Scenario", "SimulationResult", "SingleLinkModel", "build_multilink", "builtin_scenarios",
    "fit", "identify", "load_scenario", "parabolic", "quasi_parabolic", "simulate",
    "validate", "wiener_feedforward",
]
