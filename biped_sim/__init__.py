"""biped_sim: exact hybrid dynamics of a planar three-link biped, with an rclpy node.

The tree is the architecture; each layer imports only from the layers before it:

    engine/      model, phases, guards, hybrid integrator (numpy + scipy; no ROS import anywhere)
    control/     reference controllers
    config/      parameters and scenes (msg_configs/*.yaml)
    analysis/    work-precision, stability suite, Poincare map and gait
    recording/   MCAP bags: messages, writer, reader, resim, inspect
    ros/         the nodes (sim_node, walk_controller) and the small tools
    cli/         ``biped-sim`` and its sub-commands

The public API is re-exported here: ``import biped_sim as bs; bs.load_scene("walk").simulate()``.
"""
__version__ = "0.1.0"

from biped_sim.analysis.sweep import sweep
from biped_sim.config.scenes import Scene, available_scenes, load_scene
from biped_sim.control.walking import PDWalkingController, WalkingController
from biped_sim.engine.dynamics import flight_dynamics, impact_map, relabel, stance_dynamics
from biped_sim.engine.hybrid import Event, HybridSimulator, Options, SimulationResult
from biped_sim.engine.model import BipedModel, BipedParameters
from biped_sim.engine.simulate import simulate, stance_state

__all__ = ["BipedModel", "BipedParameters", "stance_dynamics", "impact_map", "relabel", "flight_dynamics",
           "HybridSimulator", "Options", "Event", "SimulationResult", "simulate", "stance_state",
           "WalkingController", "PDWalkingController", "Scene", "load_scene", "available_scenes",
           "sweep"]
