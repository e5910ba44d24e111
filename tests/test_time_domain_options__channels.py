"""``channels`` of the fit's options as names or as weights (a list was a raw "dictionary
update sequence" ValueError inside the engine before)."""

from __future__ import annotations

import pytest

from flexarm.identification.time_domain.options import Cost, FitOptions, ScenarioFitOptions


def test_channel_names_weigh_one_each_and_weights_are_kept():
    assert Cost(channels=["motor_angle", "current"]).channels == {
        "motor_angle": 1.0,
        "current": 1.0,
    }
    assert Cost(channels={"motor_angle": 2, "current": 0.5}).channels == {
        "motor_angle": 2.0,
        "current": 0.5,
    }
    assert FitOptions(cost=Cost(channels="current")).resolved().cost.channels == {"current": 1.0}
    # the deprecated flat record's names become weights on conversion (FitOptions.from_flat)
    flat = ScenarioFitOptions(channels=["tip_deflection"])
    assert FitOptions.from_flat(flat).cost.channels == {"tip_deflection": 1.0}


@pytest.mark.parametrize("bad", [[1, 2], {"a": -1.0}, {"a": float("nan")}, 3.0, {"a": True}])
def test_bad_channels_are_one_line_naming_the_field(bad):
    with pytest.raises(ValueError, match=r"Cost\.channels = .*give channel names"):
        Cost(channels=bad)
