"""Launch the backlash_identifier node with a parameters file.

    ros2 launch genbacklash_ros backlash_identifier.launch.py \
        params_file:=/path/to/params.yaml namespace:=arm \
        command:=/arm/command encoder:=/joint_states

Arguments: ``params_file`` (default: the installed config/params.yaml), ``namespace``, and the
topic remappings ``command``, ``encoder``, ``compensated_command``.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from launch import LaunchDescription


def generate_launch_description() -> LaunchDescription:
    default_params = os.path.join(
        get_package_share_directory("genbacklash_ros"), "config", "params.yaml"
    )
    arguments = [
        DeclareLaunchArgument(
            "params_file",
            default_value=default_params,
            description="ROS 2 parameters YAML for backlash_identifier",
        ),
        DeclareLaunchArgument("namespace", default_value="", description="node namespace"),
        DeclareLaunchArgument("command", default_value="command", description="command topic"),
        DeclareLaunchArgument("encoder", default_value="encoder", description="encoder topic"),
        DeclareLaunchArgument(
            "compensated_command",
            default_value="compensated_command",
            description="compensated command topic",
        ),
    ]
    node = Node(
        package="genbacklash_ros",
        executable="backlash_identifier",
        name="backlash_identifier",
        namespace=LaunchConfiguration("namespace"),
        parameters=[LaunchConfiguration("params_file")],
        remappings=[
            ("command", LaunchConfiguration("command")),
            ("encoder", LaunchConfiguration("encoder")),
            ("compensated_command", LaunchConfiguration("compensated_command")),
        ],
        output="screen",
        emulate_tty=True,
    )
    return LaunchDescription([*arguments, node])
