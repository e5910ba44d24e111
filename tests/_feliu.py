"""Shared, cached pieces of the FRB control tests (one inner-loop design per session)."""

from functools import cache

import equinox as eqx

from flexarm.control.inner_loop import design_inner_loop
from flexarm.models.single_link import SingleLinkModel
from flexarm.sim.build import prepare
from flexarm.specs import load_scenario

COUNT = 6.283185307179586 / 4096  # motor A/D count, rad (360° over 12 bits)
LBIN = 0.112984829027616  # N·m per lbf·in


def scenario(name: str, duration: float):
    sc = load_scenario(name)
    return sc.model_copy(
        update={"simulation": sc.simulation.model_copy(update={"duration": duration})}
    )


def model(name: str = "feliu-single-mass", hold_tip: bool = False) -> SingleLinkModel:
    return SingleLinkModel.from_spec(load_scenario(name).arm, hold_tip=hold_tip)


@cache
def design():
    """The inner-loop design of FRB Sec. VI-B.2: T = 3 ms, one sample of delay,
    G_cm1(1) = 15 A/rad, checked at the 200 mrad step of Fig. 11, no overshoot."""
    return design_inner_loop(
        model(hold_tip=True), 0.003, 1, dc_gain=15.0, step=0.2, band=0.02, max_overshoot=0.0, seed=0
    )


def held_prepared(name: str, controller, duration: float):
    """A prepared scenario whose plant has the tip held (FRB Fig. 11): the free arm is
    prepared (state at rest at 0, the same for both) and the held plant swapped in, so the
    held and free experiments share one state layout and one compiled loop."""
    p = prepare(scenario(name, duration), controller=controller)
    held = model(name, hold_tip=True)
    p.loop = eqx.tree_at(lambda lp: lp.plant, p.loop, held.plant())
    p.model = held
    return p
