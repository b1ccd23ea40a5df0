"""ECAHD in simulation: sim_bridge (PyBullet maze, publishes map/odom/clock), global_planner,
local_refiner and bag_recorder, the same composition as `ecahd demo`.

    ros2 launch ecahd_ros ecahd_sim.launch.py [params_file:=my.yaml] [use_sim_time:=true]
        [record:=true]

Send goals with RViz's "2D Goal Pose" tool (goal_pose, frame map).
"""
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare

PACKAGE = "ecahd_ros"
# sim_bridge drives /clock, so it runs on wall time; the others follow the simulated clock
SIM_TIME_NODES = ("global_planner", "local_refiner")


def generate_launch_description() -> LaunchDescription:
    params_file = LaunchConfiguration("params_file")
    use_sim_time = LaunchConfiguration("use_sim_time")
    record = LaunchConfiguration("record")
    default_params = PathJoinSubstitution([FindPackageShare(PACKAGE), "config", "ecahd.yaml"])
    actions = [
        DeclareLaunchArgument("params_file", default_value=default_params,
                              description="ROS parameters of all nodes (config/ecahd.yaml)"),
        DeclareLaunchArgument("use_sim_time", default_value="true",
                              description="planner and refiner follow sim_bridge's /clock"),
        DeclareLaunchArgument("record", default_value="true",
                              description="record the default topics with bag_recorder"),
        Node(package=PACKAGE, executable="sim_bridge", name="sim_bridge", output="screen",
             parameters=[params_file]),
    ]
    for exe in SIM_TIME_NODES:
        actions.append(Node(package=PACKAGE, executable=exe, name=exe, output="screen",
                            parameters=[params_file, {"use_sim_time": use_sim_time}]))
    actions.append(Node(package=PACKAGE, executable="bag_recorder", name="bag_recorder",
                        output="screen", condition=IfCondition(record),
                        parameters=[params_file, {"use_sim_time": use_sim_time}]))
    return LaunchDescription(actions)
