"""The ROS 2 layer: the nodes (``sim_node``, ``walk_controller``) and the small tools.

The console scripts enter through :func:`entry_point`, so that a machine without rclpy (or one of
the message packages) gets one line saying what to install instead of an ImportError traceback, and
any other exception becomes one line and an exit code (:mod:`biped_sim.config.command_errors`: a
closed pipe on stdout, ``biped_echo | head``, ends the command quietly).
"""
import importlib
import sys

from biped_sim.config.command_errors import (
    STOPPED_AT_START,
    StoppedAtStart,
    explain,
    raise_on_stop_signals,
    run_command,
)


def entry_point(command, module):
    """The ``main`` of ``biped_sim.ros.<module>``, imported only when the command runs."""
    def main():
        raise_on_stop_signals()     # until startup.init catches them for the node's loop
        try:
            target = importlib.import_module(f"biped_sim.ros.{module}")
        except StoppedAtStart as exc:
            code, line = explain(command, exc)
            print(line, file=sys.stderr)
            return code
        except ImportError as exc:
            if STOPPED_AT_START:    # the signal's exception, raised inside an extension's initialisation
                code, line = explain(command, StoppedAtStart(STOPPED_AT_START[0]))
                print(line, file=sys.stderr)
                return code
            print(f"{command}: error: cannot import the ROS 2 Python packages ({exc}); install ROS 2 Jazzy's "
                  "rclpy and message packages (make venv does, from PyPI) or source a ROS 2 Jazzy install",
                  file=sys.stderr)
            return 2
        return run_command(command, target.main)
    return main


sim_node = entry_point("sim_node", "sim_node")
walk_controller = entry_point("walk_controller", "walk_controller")
torque_pub = entry_point("torque_pub", "torque_pub")
biped_echo = entry_point("biped_echo", "echo")
