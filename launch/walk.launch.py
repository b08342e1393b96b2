"""The walk scene over ROS: ``sim_node`` and the reference ``walk_controller``, both from one scene file.

    ros2 launch biped_sim walk.launch.py
    ros2 launch biped_sim walk.launch.py params_file:=/path/to/my_scene.yaml

The scene file (default: the installed ``msg_configs/walk.yaml``) has one section per node, keyed by
node name (``biped_sim`` and ``walk_controller``), so both nodes read the same file. The scene runs in
lockstep (the simulator advances one control period per command) and ends at its ``duration``; the
launch ends with it. Other scenes with a ``walk_controller`` section: slope, stance_fixed, drop.
"""
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, Shutdown
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare


def generate_launch_description():
    params_file = LaunchConfiguration("params_file")
    return LaunchDescription([
        DeclareLaunchArgument(
            "params_file",
            default_value=PathJoinSubstitution([FindPackageShare("biped_sim"), "msg_configs", "walk.yaml"]),
            description="scene file: ROS parameters of the nodes biped_sim and walk_controller"),
        # the names select the two sections of the scene file; the run ending ends the launch (the
        # controller would otherwise wait for states forever)
        Node(package="biped_sim", executable="sim_node", name="biped_sim", parameters=[params_file],
             output="screen", on_exit=Shutdown(reason="sim_node ended its run")),
        Node(package="biped_sim", executable="walk_controller", name="walk_controller", parameters=[params_file],
             output="screen"),
    ])
