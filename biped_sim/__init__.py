"""biped_sim: exact hybrid dynamics of a planar three-link biped, with an rclpy node.

Layers, each importing only from those above it in this list: ``model`` (MODEL.md constants and
closed forms) -> ``dynamics`` (phases: stance, impact, relabeling, flight) -> ``integrators`` ->
``hybrid`` (guards, resets, ``simulate``) -> scenes, CLI, node, recorder, replay.
"""
__version__ = "0.1.0"
