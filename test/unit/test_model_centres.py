"""``model.c_leg`` and ``model.c_torso`` (the links' centres of mass from the hip) reach the model
from a scene override, a sweep and the node's parameters, like the other ``model.*`` (issue 33)."""
from biped_sim.analysis.sweep import check_sweep
from biped_sim.config import parameters as P
from biped_sim.config.scenes import load_scene


def test_model_c_leg_and_c_torso_reach_the_simulated_and_the_controllers_model():
    scene = load_scene("walk", overrides={"model.c_leg": 0.42, "model.c_torso": 0.2})
    assert scene.engine_arguments()["model"].parameters.c_leg == 0.42
    assert scene.engine_arguments()["model"].parameters.c_torso == 0.2
    controller_model = scene.controller().model.parameters
    assert (controller_model.c_leg, controller_model.c_torso) == (0.42, 0.2)
    assert {"model.c_leg", "model.c_torso"} <= set(P.BY_NAME)           # node parameters too


def test_their_default_is_half_the_link_also_when_the_link_changes():
    assert load_scene("walk").engine_arguments()["model"].parameters.c_leg == 0.5
    longer = load_scene("walk", overrides={"model.l_leg": 1.2}).engine_arguments()["model"].parameters
    assert longer.c_leg == 0.6 and longer.c_torso == 0.25


def test_a_sweep_takes_model_c_leg():
    assert len(check_sweep("walk", {"model.c_leg": [0.4, 0.5]}, duration=0.1)) == 2
