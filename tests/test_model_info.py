"""``flexarm info``'s linear model (analysis/model_info.py)."""

from __future__ import annotations

import pytest

from flexarm.analysis.model_info import single_link_info
from flexarm.models.single_link import SingleLinkModel
from flexarm.specs.scenario import scenario_from_dict


@pytest.mark.parametrize("masses", [[], [{"mass": 0.1, "position": 0.3}]])
def test_info_on_a_rigid_link(masses):
    """Issue #44: a rigid link (without masses: "internal error: Input 1, output 1 has a
    zero denominator") has G_b = 1, a zero coupling, and G_m = K_t / (J s²) with J the hub's
    inertia plus the masses' m r²."""
    sc = scenario_from_dict(
        {
            "arm": {
                "motor": {
                    "drive": "current",
                    "inertia": 0.01,
                    "torque_constant": 0.5,
                    "current_limit": 10.0,
                },
                "friction": {"model": "none"},
                "beam": {"model": "rigid", "length": 0.3, "masses": masses},
            },
            "sampling": {"period": 0.001},
            "simulation": {"duration": 0.1},
        }
    )
    info = single_link_info(SingleLinkModel.from_spec(sc.arm))
    tfs = info["transfer_functions"]
    assert tfs["beam"]["static_gain"] == 1.0
    assert tfs["coupling"]["num"] == [0.0] and "rigid" in tfs["coupling"]["description"]
    J = 0.01 + sum(m["mass"] * m["position"] ** 2 for m in masses)
    assert tfs["motor"]["integrators"] == 2
    assert tfs["motor"]["static_gain"] == pytest.approx(0.5 / J, rel=1e-12)
