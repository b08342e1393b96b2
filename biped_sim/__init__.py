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

import importlib

#: the public API and where each name lives. Imported on first use (PEP 562), so that importing a
#: subpackage -- the bag writer process runs ``python -m biped_sim.recording.writer`` -- does not
#: pay for the engine and scipy (about 2.5 s here).
_PUBLIC = {
    "BipedModel": "biped_sim.engine.model", "BipedParameters": "biped_sim.engine.model",
    "stance_dynamics": "biped_sim.engine.dynamics", "impact_map": "biped_sim.engine.dynamics",
    "relabel": "biped_sim.engine.dynamics", "flight_dynamics": "biped_sim.engine.dynamics",
    "HybridSimulator": "biped_sim.engine.hybrid", "Options": "biped_sim.engine.options",
    "Event": "biped_sim.engine.results", "SimulationResult": "biped_sim.engine.results",
    "ControllerError": "biped_sim.engine.results",
    "simulate": "biped_sim.engine.simulate", "stance_state": "biped_sim.engine.simulate",
    "WalkingController": "biped_sim.control.walking", "PDWalkingController": "biped_sim.control.walking",
    "RabbitWalkingController": "biped_sim.control.rabbit_walking",
    "Scene": "biped_sim.config.scenes", "load_scene": "biped_sim.config.scenes",
    "available_scenes": "biped_sim.config.scenes", "sweep": "biped_sim.analysis.sweep",
    "torque_law": "biped_sim.control.compiled_laws", "TorqueLaw": "biped_sim.control.compiled_laws",
    "find_gait": "biped_sim.analysis.gait",
    "load_run": "biped_sim.recording.loaded_run", "RecordedRun": "biped_sim.recording.loaded_run",
    "load_model": "biped_sim.config.models", "RobotDescription": "biped_sim.engine.description",
    "GeneratedModel": "biped_sim.engine.generated_model",
}
__all__ = list(_PUBLIC)


def __getattr__(name):
    if name not in _PUBLIC:
        raise AttributeError(f"module 'biped_sim' has no attribute {name!r}")
    value = getattr(importlib.import_module(_PUBLIC[name]), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(_PUBLIC))
